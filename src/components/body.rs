//! The soft body component: a tet mesh, a material and the simulation state they make.

use std::sync::Arc;
use std::time::Duration;

use bevy::prelude::*;

use super::{SoftBodyGrab, SoftBodyStats};
use crate::core::{
    MaterialError, SnapshotError, SoftBodyMaterial, SoftBodyState, StateSnapshot, TetMesh,
};

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
    /// For each rigid body in the body's `RigidContacts`, its index among the step's rigid
    /// bodies ([`SolverSpheres`](crate::plugin::SolverSpheres)'s `rigid`).
    pub(crate) rigid_ids: Vec<u32>,
    /// Whether this step's contact stage runs the body with others that may touch it
    /// (`plugin::groups`).
    pub(crate) stepped_together: bool,
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
            rigid_ids: Vec::new(),
            stepped_together: false,
        })
    }

    /// The simulation state to read: particles, velocities, material, volume metrics. A game
    /// changes a body through the methods below and the settings components
    /// (`components/settings.rs`).
    pub fn state(&self) -> &SoftBodyState {
        &self.state
    }

    /// The particles' velocities, m/s in world space, to set: throw a body, stop it. Wakes
    /// the body.
    pub fn velocities_mut(&mut self) -> &mut [Vec3] {
        self.state.wake_up();
        self.state.velocities_mut()
    }

    /// Moves every particle by `offset` (metres): before spawning, in the mesh's frame, or to
    /// teleport a placed body, in the world.
    pub fn translate(&mut self, offset: Vec3) {
        self.state.translate(offset);
    }

    /// Changes the body's material, from its next step; an invalid material is refused and
    /// changes nothing.
    pub fn set_material(&mut self, material: SoftBodyMaterial) -> Result<(), MaterialError> {
        self.state.set_material(material)
    }

    /// Wakes the body if it sleeps.
    pub fn wake_up(&mut self) {
        self.state.wake_up();
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

    /// Gives the whole body the impulse `impulse` (N s, world frame) now: every particle's
    /// velocity changes by `impulse / M` (a kick, a jump). Wakes the body.
    pub fn apply_impulse(&mut self, impulse: Vec3) {
        self.state.forces().apply_impulse(impulse);
    }

    /// Gives the body the impulse `impulse` (N s, world frame) now, at its point at `point`
    /// (world frame; for a body not placed yet, the mesh's own): the particles of the tet there
    /// take it by their barycentric weights, so the body's momentum changes by `impulse` and
    /// its angular momentum by `point x impulse` (a punch, a bullet). A point outside the body
    /// acts at the nearest point of the tet it is least outside of. Wakes the body. Returns
    /// false (and does nothing) for a mesh without a tet of any volume.
    pub fn apply_impulse_at_point(&mut self, impulse: Vec3, point: Vec3) -> bool {
        let Some(at) = self.state.body_point(point) else {
            return false;
        };
        self.state.forces().apply_impulse_at(at, impulse);
        true
    }

    /// Applies `grab`'s spring for a step of `h` seconds now (what the plugin does each step
    /// for the [`SoftBodyGrab`] component; a game holding a body with more hands than one
    /// applies the others so, before the step). Binds the grab to the material around its
    /// point on first use.
    pub fn pull(&mut self, grab: &mut SoftBodyGrab, h: f32) {
        let state = &mut self.state;
        if grab.held.is_empty() {
            let radius = grab.radius.unwrap_or(0.1 * state.rest_extent);
            let held = state.forces().grab_patch(grab.point, radius);
            if !held.is_empty() {
                grab.offset = grab.point - state.forces().patch_motion(&held).0;
            }
            grab.held = held;
        }
        // Particles the grab held may have been split by a tear: their indices stay valid.
        let target = grab.target - grab.offset;
        let spring = [grab.stiffness, grab.damping];
        state
            .forces()
            .pull_patch(&grab.held, target, spring, grab.max_force, h);
    }

    /// The body's state now (see [`SoftBodySnapshot`]).
    pub fn snapshot(&self) -> SoftBodySnapshot {
        SoftBodySnapshot {
            state: self.state.snapshot(),
            placed: self.placed,
            rest_scale: self.rest_scale,
        }
    }

    /// Puts the body back in the state `snapshot` holds: this body or one spawned anew from the
    /// same mesh (and, if it is not placed yet, with the same spawn scale or none). A snapshot
    /// of another mesh, another version or a damaged one is an error and changes nothing.
    pub fn restore(&mut self, snapshot: &SoftBodySnapshot) -> Result<(), SnapshotError> {
        if self.placed || !snapshot.placed || snapshot.rest_scale == self.rest_scale {
            self.state.restore(&snapshot.state)?;
        } else {
            // Spawned anew and not placed: its mesh is the one given, the snapshot's the one
            // placement scaled (`plugin::prepare`).
            let damaged = |e: String| SnapshotError::Damaged(format!("rest scale: {e}"));
            let mesh = (self.state.mesh().scaled(snapshot.rest_scale))
                .map_err(|e| damaged(e.to_string()))?;
            let mut state = SoftBodyState::new(mesh.into(), *self.state.material())?;
            state.set_soft_contact_settings(self.state.soft_contact_settings());
            state.set_sleep_settings(self.state.sleep_settings());
            state.set_runaway_limits(self.state.runaway_limits());
            state.set_collision_filter(self.state.collision_filter());
            state.restore(&snapshot.state)?;
            self.state = state;
        }
        if snapshot.placed && !self.placed {
            self.state.time_substeps(true);
        }
        self.placed = snapshot.placed;
        self.rest_scale = snapshot.rest_scale;
        Ok(())
    }
}

/// A [`SoftBody`] between two steps, to save and restore: its simulation state
/// ([`StateSnapshot`]: particles, velocities, plasticity, friction, sleep, material) and its
/// placement. Restoring it into a body of the same mesh and stepping gives bit for bit the
/// steps the body would have taken (on any number of threads). The components a game puts
/// beside a body (settings, [`PinnedParticles`](super::PinnedParticles),
/// [`DrivenParticles`](super::DrivenParticles) with their captured offsets, the rigid
/// spheres) are reflected and saved as a game saves its other components. With the feature
/// `serialize` it is serde data.
///
/// ```
/// use bevy::prelude::*;
/// use bevy_soft_body::{core::box_grid, prelude::*};
///
/// let mesh: std::sync::Arc<_> = box_grid(UVec3::splat(2), Vec3::splat(0.1), Vec3::ZERO)
///     .unwrap()
///     .into();
/// let mut jelly = SoftBody::new(mesh.clone(), SoftBodyMaterial::JELLY).unwrap();
/// jelly.velocities_mut()[0] = Vec3::X;
/// let saved = jelly.snapshot();
/// // Later, or in another app: a body of the same mesh takes the saved state.
/// let mut again = SoftBody::new(mesh, SoftBodyMaterial::JELLY).unwrap();
/// again.restore(&saved).unwrap();
/// assert_eq!(again.state().velocities()[0], Vec3::X);
/// // Another mesh is refused.
/// let other = box_grid(UVec3::splat(3), Vec3::splat(0.1), Vec3::ZERO).unwrap();
/// let mut other = SoftBody::new(other.into(), SoftBodyMaterial::JELLY).unwrap();
/// assert!(matches!(other.restore(&saved), Err(SnapshotError::OtherMesh { .. })));
/// ```
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub struct SoftBodySnapshot {
    /// The simulation state.
    pub state: StateSnapshot,
    /// Whether the body had been placed at its spawn transform.
    pub placed: bool,
    /// The spawn scale baked into its rest shape.
    pub rest_scale: Vec3,
}
