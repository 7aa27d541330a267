//! The components and resources a game spawns and reads.

use std::sync::Arc;
use std::time::Duration;

use bevy::prelude::*;
use parry3d::shape::SharedShape;

use crate::core::{MaterialError, Runaway, SoftBodyMaterial, SoftBodyState, StepCounters, TetMesh};

/// A soft body. Spawn it with a [`Transform`] that places its tet mesh in the world (the mesh
/// is given in its own local frame); on its first step the plugin moves the particles there.
///
/// The particles are simulated in world space. After placement the entity's [`Transform`]
/// follows the body: its translation is the centre of mass, its rotation and scale identity,
/// so a camera or child entity can follow it. A scale in the spawn transform is baked into the
/// rest shape (the tet mesh is rebuilt at that scale).
///
/// A jelly cube dropped on the ground, stepped headless (a game adds `DefaultPlugins` instead
/// and lets the fixed clock run):
///
/// ```
/// use std::time::Duration;
///
/// use bevy::prelude::*;
/// use bevy::time::TimeUpdateStrategy;
/// use bevy_soft_body::{core::box_grid, prelude::*};
///
/// let mut app = App::new();
/// app.add_plugins((MinimalPlugins, SoftBodyPlugin::default()))
///     // Every update advances the clock by one step of the plugin's 10 ms.
///     .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(10)));
/// // A 0.5 m cube of 4 cells a side (320 tets), its lowest point 0.3 m up.
/// let mesh = box_grid(UVec3::splat(4), Vec3::splat(0.125), Vec3::ZERO).unwrap();
/// let jelly = SoftBody::new(mesh.into(), SoftBodyMaterial::JELLY).unwrap();
/// let jelly = app.world_mut().spawn((jelly, Transform::from_xyz(0.0, 0.3, 0.0))).id();
/// app.world_mut()
///     .spawn((StaticCollider::ground(0.8), Transform::default()));
/// for _ in 0..=100 {
///     app.update();
/// }
/// // A second later it has landed, squashed and kept its volume.
/// let stats = app.world().get::<SoftBodyStats>(jelly).unwrap();
/// assert!(stats.peak_volume_error_pct.abs() < 1.0);
/// let centre = app.world().get::<Transform>(jelly).unwrap().translation;
/// assert!(centre.y < 0.3 && centre.y > 0.1, "{centre}");
/// ```
#[derive(Component)]
#[require(Transform, SoftBodyStats)]
pub struct SoftBody {
    pub(crate) state: SoftBodyState,
    pub(crate) placed: bool,
    /// The scale of the spawn transform, baked into the rest shape at placement.
    pub(crate) rest_scale: Vec3,
    pub(crate) step_time: Duration,
    /// This body's copy of the rigid spheres during a stage that runs bodies in parallel.
    pub(crate) spheres: Vec<crate::core::RigidSphereState>,
}

impl SoftBody {
    /// A soft body of `mesh`, made of `material`.
    pub fn new(mesh: Arc<TetMesh>, material: SoftBodyMaterial) -> Result<Self, MaterialError> {
        Ok(SoftBody {
            state: SoftBodyState::new(mesh, material)?,
            placed: false,
            rest_scale: Vec3::ONE,
            step_time: Duration::ZERO,
            spheres: Vec::new(),
        })
    }

    /// The simulation state: particles, springs, material.
    pub fn state(&self) -> &SoftBodyState {
        &self.state
    }

    /// The simulation state, to change velocities or the material at run time.
    pub fn state_mut(&mut self) -> &mut SoftBodyState {
        &mut self.state
    }

    /// Whether the body has been placed at its spawn transform yet.
    pub fn is_placed(&self) -> bool {
        self.placed
    }

    /// The scale of the spawn transform, which the rest shape (`state().mesh()`) includes:
    /// a point of the mesh as given is at `point * rest_scale()` in the rest shape.
    pub fn rest_scale(&self) -> Vec3 {
        self.rest_scale
    }
}

/// Particles of the [`SoftBody`] on the same entity that do not move (the held end of the
/// twisted bar, a creature's anchor). Remove the component to let them go. An index past the
/// body's particles is reported once as a [`SoftBodyError`]; the others still hold.
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

/// Particles of the [`SoftBody`] on the same entity that follow the [`Transform`] of
/// `target`, keeping the offset they had from it when first seen (the turned end of the
/// twisted bar, a grabbed handle). Remove the component to release them.
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
    /// Offsets in the target's frame, captured on the first step.
    #[reflect(ignore)]
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

/// A dynamic rigid sphere, simulated by the plugin and two-way coupled to soft bodies by
/// contact impulses: a heavy sphere dents a body and is slowed by it. Its position is its
/// entity's [`Transform`] translation. It does not rotate, and spheres do not collide with
/// each other.
#[derive(Component, Clone, Debug, Reflect)]
#[reflect(Component)]
#[require(Transform)]
pub struct RigidSphere {
    /// Radius.
    pub radius: f32,
    /// Mass; `f32::INFINITY` makes an immovable (kinematic) sphere.
    pub mass: f32,
    /// Linear velocity.
    pub velocity: Vec3,
    /// Coulomb friction coefficient.
    pub friction: f32,
}

impl RigidSphere {
    /// A sphere at rest with friction 0.5.
    pub fn new(radius: f32, mass: f32) -> Self {
        RigidSphere {
            radius,
            mass,
            velocity: Vec3::ZERO,
            friction: 0.5,
        }
    }
}

/// A static collider of any parry shape, posed by its entity's [`Transform`] (translation and
/// rotation; parry shapes carry their own size, so scale is ignored).
#[derive(Component, Clone)]
#[require(Transform)]
pub struct StaticCollider {
    /// The shape.
    pub shape: SharedShape,
    /// Coulomb friction coefficient.
    pub friction: f32,
}

impl StaticCollider {
    /// An infinite ground plane through the entity's translation, facing its local +Y.
    pub fn ground(friction: f32) -> Self {
        StaticCollider {
            shape: SharedShape::halfspace(Vec3::Y),
            friction,
        }
    }

    /// Any parry shape.
    pub fn new(shape: SharedShape, friction: f32) -> Self {
        StaticCollider { shape, friction }
    }
}

/// Gravity for every soft body and rigid sphere.
#[derive(Resource, Clone, Copy, Debug, Reflect)]
#[reflect(Resource)]
pub struct SoftBodyGravity(pub Vec3);

impl Default for SoftBodyGravity {
    fn default() -> Self {
        SoftBodyGravity(Vec3::new(0.0, -9.81, 0.0))
    }
}

/// Per-body measurements, updated after every step.
#[derive(Component, Clone, Debug, Default, Reflect)]
#[reflect(Component)]
pub struct SoftBodyStats {
    /// Steps simulated.
    pub steps: u64,
    /// Signed total volume error in percent of the rest volume (the paper's Figure 2).
    pub volume_error_pct: f64,
    /// Largest absolute total volume error seen so far, in percent.
    pub peak_volume_error_pct: f64,
    /// Mean over tets of the absolute per-tet volume error, in percent.
    pub mean_abs_tet_error_pct: f64,
    /// Tets with negative volume now.
    pub inverted_tets: usize,
    /// Most inverted tets seen in one step so far.
    pub max_inverted_tets: usize,
    /// Solver time of the last step for this body, in milliseconds (every stage, contacts
    /// included).
    pub step_ms: f64,
    /// Sum of [`SoftBodyStats::step_ms`] over all steps.
    pub total_step_ms: f64,
    /// Particle contacts resolved in the last step (both contact passes).
    pub contacts: u32,
    /// What the volume passes did in the last step.
    #[reflect(ignore)]
    pub counters: StepCounters,
    /// Times the body ran away and was put back (see [`SoftBodyErrorKind::Runaway`]).
    pub runaway_resets: u32,
    /// The step of the last runaway, if any.
    pub last_runaway_step: Option<u64>,
    /// Whether the body is asleep (at rest, not stepped until disturbed; see
    /// `SoftBodyState::is_sleeping`).
    pub sleeping: bool,
}

impl SoftBodyStats {
    /// Mean solver time per step so far, in milliseconds.
    pub fn mean_step_ms(&self) -> f64 {
        if self.steps == 0 {
            0.0
        } else {
            self.total_step_ms / self.steps as f64
        }
    }
}

/// Something a game gave the plugin that it could not use. The plugin logs it as an error,
/// writes it as this message so that a game can react, and goes on with the rest.
#[derive(Message, Clone, Debug, PartialEq)]
pub struct SoftBodyError {
    /// The soft body concerned.
    pub body: Entity,
    /// What is wrong.
    pub kind: SoftBodyErrorKind,
}

/// What a [`SoftBodyError`] is about.
#[derive(Clone, Debug, PartialEq)]
pub enum SoftBodyErrorKind {
    /// A pinned or driven particle index is out of range; it is skipped.
    ParticleOutOfRange {
        /// The index given.
        index: u32,
        /// How many particles the body has.
        count: usize,
    },
    /// `DrivenParticles::target` has no `Transform`; the particles are not driven.
    MissingDriveTarget(Entity),
    /// The spawn transform's scale could not be applied; the body keeps its size.
    BadScale {
        /// The scale given.
        scale: Vec3,
        /// Why it could not be used.
        reason: String,
    },
    /// A soft body could not be built from an asset (feature `render`,
    /// `SoftBodyFromAsset`); the entity gets no body.
    Build {
        /// Why.
        reason: String,
    },
    /// The body ran away (a particle past `RunawayLimits::max_speed`, or the body stretched
    /// past `max_stretch` times its rest size: an unstable material or mesh for the step) and
    /// was put back in its rest shape, at rest, where it last was sane. Reported once per
    /// spell of runaways; `SoftBodyStats::runaway_resets` counts them all.
    Runaway(Runaway),
    /// A render surface (feature `render`) could not be bound to the body; it is not deformed.
    Surface {
        /// The entity of the surface.
        surface: Entity,
        /// Why.
        reason: String,
    },
}

impl std::fmt::Display for SoftBodyError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.kind {
            SoftBodyErrorKind::ParticleOutOfRange { index, count } => write!(
                f,
                "soft body {}: particle {index} does not exist (the body has {count}); skipped",
                self.body
            ),
            SoftBodyErrorKind::MissingDriveTarget(target) => write!(
                f,
                "soft body {}: driven particles follow {target}, which has no Transform",
                self.body
            ),
            SoftBodyErrorKind::BadScale { scale, reason } => write!(
                f,
                "soft body {}: cannot apply the scale {scale}: {reason}; the body keeps its size",
                self.body
            ),
            SoftBodyErrorKind::Build { reason } => write!(
                f,
                "soft body {}: cannot be built from its asset: {reason}",
                self.body
            ),
            SoftBodyErrorKind::Runaway(r) => write!(
                f,
                "soft body {}: ran away (fastest particle {:.3e} m/s, extent {:.3e} m against \
                 {:.3} m at rest) and was put back at rest at {}; its material is too stiff \
                 for its step or its mesh too poor",
                self.body, r.speed, r.extent, r.rest_extent, r.reset_to
            ),
            SoftBodyErrorKind::Surface { surface, reason } => write!(
                f,
                "soft body {}: surface {surface} cannot follow it: {reason}",
                self.body
            ),
        }
    }
}
