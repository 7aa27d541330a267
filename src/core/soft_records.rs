//! What a body remembers within a step run together with other soft bodies: the contacts its
//! volume impulses may push into ([`SoftSupport`]), the impulses it hands to the other bodies
//! ([`SoftReaction`], [`take_soft_pushes`], [`hand_soft_pushes`]), and where static friction
//! holds each particle ([`SoftAnchor`]). Plain records, kept in the body's scratch
//! (`soft_contacts.rs` writes them, the substeps hand them, `soft_lockstep.rs` applies them).

use glam::Vec3;

/// A particle's contact with another body's triangle in a substep: where the volume impulses'
/// pushes into that body are handed.
#[derive(Clone, Copy, Debug)]
pub struct SoftSupport {
    /// The particle, of this body.
    pub(crate) particle: u32,
    /// The triangle's outward normal.
    pub(crate) normal: Vec3,
    /// The other body's place among the bodies stepped together.
    pub(crate) partner: u32,
    /// The triangle's particles, of the other body.
    pub(crate) corners: [u32; 3],
    /// The barycentric weights of the particle's nearest point on the triangle.
    pub(crate) weights: Vec3,
    /// The triangle point's inverse mass, `sum b_j^2 w_j`.
    pub(crate) inv_mass: f32,
    /// The pair's friction coefficient.
    pub(crate) friction: f32,
    /// The impulse the triangle gave the particle by stopping the volume impulses' push into
    /// it (`take_soft_pushes`).
    pub(crate) pushed: Vec3,
}

/// An impulse one body's volume impulses hand to another's triangle (split over its corners by
/// `weights`), applied with its friction once every body has finished the substep.
#[derive(Clone, Copy, Debug)]
pub struct SoftReaction {
    /// The particle that pushed, of the body that made the reaction.
    pub(crate) particle: u32,
    /// The triangle's outward normal.
    pub(crate) normal: Vec3,
    pub(crate) partner: u32,
    pub(crate) corners: [u32; 3],
    pub(crate) weights: Vec3,
    /// The impulse on the triangle.
    pub(crate) impulse: Vec3,
    /// The triangle point's inverse mass, `sum b_j^2 w_j`.
    pub(crate) inv_mass: f32,
    /// The pair's friction coefficient.
    pub(crate) friction: f32,
}

/// Where a particle's static friction holds it on another body's surface: a point of one of
/// its triangles, set in soft-contact pass `pass`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub struct SoftAnchor {
    pub(crate) partner: u32,
    pub(crate) corners: [u32; 3],
    pub(crate) weights: Vec3,
    pub(crate) pass: u32,
}

impl SoftAnchor {
    /// No anchor.
    pub(crate) const NONE: SoftAnchor = SoftAnchor {
        partner: u32::MAX,
        corners: [0; 3],
        weights: Vec3::ZERO,
        pass: 0,
    };
}

/// The impulses the other bodies gave a substep's volume impulses: what `constrain_direction`
/// took out of their pushes into another body (`removed`, per particle of `masses`), recorded
/// on the particle's support (its first, if it has several); returns their sum.
pub(crate) fn take_soft_pushes(
    supports: &mut [SoftSupport],
    removed: &mut [Vec3],
    masses: &[f32],
) -> Vec3 {
    let mut total = Vec3::ZERO;
    for s in supports.iter_mut() {
        let i = s.particle as usize;
        s.pushed = -masses[i] * removed[i];
        removed[i] = Vec3::ZERO;
        total += s.pushed;
    }
    total
}

/// Hands the pushes `take_soft_pushes` took out (scaled by the substep's energy scale `k`) to
/// the other bodies' triangles; they wait in `reactions` until every body has finished the
/// substep (`apply_soft_reactions`).
pub(crate) fn hand_soft_pushes(
    supports: &mut Vec<SoftSupport>,
    reactions: &mut Vec<SoftReaction>,
    k: f32,
) {
    for s in supports.iter() {
        if s.pushed == Vec3::ZERO {
            continue;
        }
        reactions.push(SoftReaction {
            particle: s.particle,
            normal: s.normal,
            partner: s.partner,
            corners: s.corners,
            weights: s.weights,
            impulse: -k * s.pushed,
            inv_mass: s.inv_mass,
            friction: s.friction,
        });
    }
    supports.clear();
}
