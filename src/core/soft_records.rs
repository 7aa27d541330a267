//! What a body remembers within a step run together with other soft bodies: the contacts its
//! volume impulses may push into ([`SoftSupport`]), the impulses it hands to the other bodies
//! ([`SoftReaction`]), and where static friction holds each particle ([`SoftAnchor`]). Plain records, kept in the body's
//! scratch (`soft_contacts.rs` writes them, `soft_lockstep.rs` reads them).

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
#[derive(Clone, Copy, Debug)]
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
