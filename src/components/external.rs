//! Forces and impulses a game gives soft bodies, in the style of the rigid-body engines: a
//! force for as long as its component is present ([`SoftBodyForces`]), an impulse applied once
//! ([`SoftBody::apply_impulse`](super::SoftBody::apply_impulse),
//! [`SoftBody::apply_impulse_at_point`](super::SoftBody::apply_impulse_at_point)), and an
//! explosion pushing every body within a sphere ([`SoftBodyRadialImpulse`]).

use bevy::prelude::*;

/// Forces on the [`SoftBody`](super::SoftBody) on the same entity, applied in every step for as
/// long as the component is present (N, world frame): wind, a thruster, a tractor beam. Each
/// step gives the body the impulse `h F` at its start.
///
/// ```
/// use bevy::prelude::*;
/// use bevy_soft_body::prelude::*;
///
/// // A 20 N wind along +x on the whole body, and a 5 N lift at a point of it.
/// let forces = SoftBodyForces {
///     force: Vec3::X * 20.0,
///     at_points: vec![PointForce::new(Vec3::new(0.1, 0.5, 0.0), Vec3::Y * 5.0)],
/// };
/// ```
#[derive(Component, Clone, Debug, Default, Reflect)]
#[reflect(Component)]
pub struct SoftBodyForces {
    /// On the whole body, spread over its particles by mass (every particle accelerated alike).
    pub force: Vec3,
    /// At points of the body, each following the material it was first applied to.
    pub at_points: Vec<PointForce>,
}

/// A force at a point of a soft body. The point is a world position when the force is first
/// applied; from then on it is the point of the material that was there (a tet and its
/// barycentric weights), so a thruster stays where it was mounted as the body turns and
/// deforms. A point outside the body acts at the nearest point of the tet it is least outside
/// of.
#[derive(Clone, Debug, Reflect)]
pub struct PointForce {
    /// Where it acts, in the world, when first applied.
    pub point: Vec3,
    /// The force, N, world frame.
    pub force: Vec3,
    /// The material point it was bound to on its first step: the tet and its weights
    /// (reflected, so that a saved game keeps it).
    pub(crate) bound: Option<(u32, [f32; 4])>,
}

impl PointForce {
    /// `force` at the body's point at `point` (world) when first applied.
    pub fn new(point: Vec3, force: Vec3) -> Self {
        PointForce {
            point,
            force,
            bound: None,
        }
    }
}

/// An explosion: every soft body with particles within `radius` of `centre` is pushed away
/// from it, in the next step. Each particle within the sphere takes an impulse away from the
/// centre of `impulse * (1 - d / radius)` times its share of its body's mass (`d` its
/// distance), so a body at the centre takes about `impulse` (N s) in all and one at the edge
/// nothing; a heavy body is thrown slower than a light one. Write it as a message:
///
/// ```
/// use bevy::prelude::*;
/// use bevy_soft_body::prelude::*;
///
/// fn explode(mut explosions: MessageWriter<SoftBodyRadialImpulse>) {
///     explosions.write(SoftBodyRadialImpulse {
///         centre: Vec3::ZERO,
///         radius: 2.0,
///         impulse: 50.0,
///     });
/// }
/// ```
#[derive(Message, Clone, Copy, Debug, PartialEq, Reflect)]
pub struct SoftBodyRadialImpulse {
    /// The centre, world frame.
    pub centre: Vec3,
    /// The radius, m.
    pub radius: f32,
    /// The impulse a body at the centre takes, N s.
    pub impulse: f32,
}

/// A grab: the [`SoftBody`](super::SoftBody) on the same entity pulled by a handful of its
/// material toward `target` with a spring, for as long as the component is present (a hand, a
/// hook, the mouse: with feature `picking`, `SoftBodyDraggable` inserts and moves it from the
/// pointer). The handful is the particles within `radius` of `point` when the grab is first
/// applied (nearer ones holding more); they then carry the grab as the body moves and
/// deforms. The spring pulls the whole body, integrated implicitly for its mass (any stiffness
/// is stable), up to `max_force`; what the body touches (the ground, avian's bodies) pushes
/// back as it is dragged into it.
///
/// ```
/// use bevy::prelude::*;
/// use bevy_soft_body::prelude::*;
///
/// // Pull the body's point at (0, 0.5, 0) up to (0, 2, 0), 300 N/m, at most 200 N.
/// let mut grab = SoftBodyGrab::new(Vec3::new(0.0, 0.5, 0.0), 300.0).with_target(Vec3::Y * 2.0);
/// grab.max_force = 200.0;
/// ```
#[derive(Component, Clone, Debug, Reflect)]
#[reflect(Component)]
pub struct SoftBodyGrab {
    /// The grabbed point, world frame, when first applied.
    pub point: Vec3,
    /// Where the spring pulls it, world frame; a game moves it.
    pub target: Vec3,
    /// The spring's stiffness, N/m.
    pub stiffness: f32,
    /// The spring's damper, N s/m.
    pub damping: f32,
    /// The largest force, N.
    pub max_force: f32,
    /// How far around `point` the grab holds the material, m; `None`: a tenth of the body's
    /// size (the diagonal of its rest shape's box).
    pub radius: Option<f32>,
    /// The particles held and their weights, found on the grab's first step (reflected, so
    /// that a saved game keeps them), and where `point` was from their weighted mean then.
    pub(crate) held: Vec<(u32, f32)>,
    pub(crate) offset: Vec3,
}

impl SoftBodyGrab {
    /// A grab of the body's point at `point` (world), held where it is until
    /// [`with_target`](Self::with_target) or a change of `target` moves it; a damper of a
    /// tenth of the stiffness, in N s/m; no largest force; the default radius.
    pub fn new(point: Vec3, stiffness: f32) -> Self {
        SoftBodyGrab {
            point,
            target: point,
            stiffness,
            damping: 0.1 * stiffness,
            max_force: f32::INFINITY,
            radius: None,
            held: Vec::new(),
            offset: Vec3::ZERO,
        }
    }

    /// The same grab pulling toward `target`.
    pub fn with_target(mut self, target: Vec3) -> Self {
        self.target = target;
        self
    }
}

/// A soft body tore in the last step (it has [`SoftBodyTearing`](super::SoftBodyTearing)):
/// where its particles were split and how many pieces it is in now.
#[derive(Message, Clone, Debug, PartialEq)]
pub struct SoftBodyTorn {
    /// The body.
    pub body: Entity,
    /// Where it was split, world frame, one point per particle split.
    pub points: Vec<Vec3>,
    /// The pieces its tets are in now (joined through shared particles).
    pub pieces: u32,
}
