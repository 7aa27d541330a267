//! Particles a game holds still or moves: pinned and driven particles.

use bevy::prelude::*;

/// Particles of the [`SoftBody`](super::SoftBody) on the same entity that do not move (the held end of the
/// twisted bar, a creature's anchor). Remove the component to let them go. An index past the
/// body's particles is reported once as a [`SoftBodyError`](super::SoftBodyError); the others still hold.
///
/// ```
/// use bevy::prelude::*;
/// use bevy_soft_body::{core::box_grid, prelude::*};
///
/// // A soft bar hanging from its top: the particles of its top face are pinned.
/// let mesh = box_grid(UVec3::new(2, 8, 2), Vec3::splat(0.05), Vec3::ZERO).unwrap();
/// let top: Vec<u32> = (0..mesh.positions().len() as u32)
///     .filter(|&i| mesh.positions()[i as usize].y > 0.39)
///     .collect();
/// let bar = SoftBody::new(mesh.into(), SoftBodyMaterial::RUBBER).unwrap();
/// # let mut world = World::new();
/// # let mut commands = world.commands();
/// commands.spawn((bar, PinnedParticles(top), Transform::from_xyz(0.0, 1.0, 0.0)));
/// ```
#[derive(Component, Clone, Debug, Default, Reflect)]
#[reflect(Component)]
pub struct PinnedParticles(pub Vec<u32>);

/// Particles of the [`SoftBody`](super::SoftBody) on the same entity that follow the [`Transform`] of
/// `target`, keeping the offset they had from it when first seen (the turned end of the
/// twisted bar, a grabbed handle). Remove the component to release them. The step reads the
/// target in `SoftBodySystems::Prepare`: a game that moves it in `FixedUpdate` before that set
/// has the particles follow in the same step, without a step of lag.
///
/// ```
/// use bevy::prelude::*;
/// use bevy_soft_body::{core::box_grid, prelude::*};
///
/// # let mut world = World::new();
/// # let mut commands = world.commands();
/// // A jelly bar whose left end rides a platform the game moves.
/// let mesh = box_grid(UVec3::new(8, 2, 2), Vec3::splat(0.05), Vec3::ZERO).unwrap();
/// let left: Vec<u32> = (0..mesh.positions().len() as u32)
///     .filter(|&i| mesh.positions()[i as usize].x < 0.01)
///     .collect();
/// let platform = commands.spawn(Transform::from_xyz(0.0, 1.0, 0.0)).id();
/// let bar = SoftBody::new(mesh.into(), SoftBodyMaterial::JELLY).unwrap();
/// commands.spawn((bar, DrivenParticles::new(platform, left), Transform::from_xyz(0.0, 1.0, 0.0)));
/// ```
#[derive(Component, Clone, Debug, Reflect)]
#[reflect(Component)]
pub struct DrivenParticles {
    /// The entity whose transform the particles follow. Its `Transform` is read as a world
    /// transform: use a top-level entity.
    pub target: Entity,
    /// The particle indices.
    pub particles: Vec<u32>,
    /// Offsets in the target's frame, captured on the first step (reflected, so that a saved
    /// game keeps them).
    pub(crate) offsets: Vec<Vec3>,
    /// Whether a missing target has been reported (once, until it is back).
    #[reflect(ignore)]
    pub(crate) target_missing: bool,
}

impl DrivenParticles {
    /// `particles` follow `target`.
    pub fn new(target: Entity, particles: Vec<u32>) -> Self {
        DrivenParticles {
            target,
            particles,
            offsets: Vec::new(),
            target_missing: false,
        }
    }
}
