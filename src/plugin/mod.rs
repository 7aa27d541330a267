//! [`SoftBodyPlugin`]: the systems that step every soft body, in ordered sets that mirror the
//! stages of a step, so that a game can put its own systems between them.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use bevy::ecs::batching::BatchingStrategy;
use bevy::ecs::schedule::{InternedScheduleLabel, ScheduleLabel};
use bevy::platform::time::Instant;
use bevy::prelude::*;
use parry3d::math::Pose;

use crate::components::{
    DrivenParticles, PinnedParticles, RigidSphere, SoftBody, SoftBodyError, SoftBodyErrorKind,
    SoftBodyGravity, SoftBodyStats, StaticCollider,
};
use crate::core::step::{Stage, spheres_after_bodies, spheres_before_bodies};
use crate::core::{
    ColliderInstance, CollisionFilter, Parallel, RigidBodyMotion, RigidSphereState, Serial,
    SoftBodyState, TetMesh,
};

mod groups;
mod systems;
mod threads;
mod timing;

use groups::*;
pub use systems::SolverSpheres;
use systems::*;
pub(crate) use systems::{gather_spheres, report};
#[cfg(test)]
pub(crate) use threads::test_compute_pool;
use threads::*;
pub use threads::{PARALLEL_PASS_MIN_TETS, SoftBodyThreads};
pub use timing::{SoftBodyStageTimes, SoftBodyStepTime};

/// The plugin's system sets, chained in this order: preparing, the stages of a step in the
/// core's order ([`Stage::ORDER`]; see `core::step` for what each does and why in this order),
/// writing back. A game puts its own systems between them.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SoftBodySystems {
    /// Place new bodies, clear last step's counters, apply pinned and driven particles, gather
    /// the rigid spheres and static colliders.
    Prepare,
    /// [`Stage::Forces`]: gravity, the paper's springs with damping, baseline volume forces;
    /// the spheres' gravity.
    Forces,
    /// [`Stage::Contacts`]: contacts on the predicted positions, so the volume passes see them;
    /// a shape solved in substeps (a physical material's, XPBD's whole step) is solved here,
    /// meeting the contacts in each substep.
    Contacts,
    /// [`Stage::OneRing`]: the one-ring volume impulses.
    OneRing,
    /// [`Stage::PerTet`]: the per-tet correction scaled by gamma.
    PerTet,
    /// [`Stage::Plasticity`]: plastic springs.
    Plasticity,
    /// [`Stage::Integrate`]: a last contact pass, then `x += h v` for particles and spheres.
    Integrate,
    /// The spheres' components follow the solver, metrics go into [`SoftBodyStats`], the
    /// bodies' transforms follow the bodies.
    Writeback,
}

impl From<Stage> for SoftBodySystems {
    fn from(stage: Stage) -> Self {
        match stage {
            Stage::Forces => SoftBodySystems::Forces,
            Stage::Contacts => SoftBodySystems::Contacts,
            Stage::OneRing => SoftBodySystems::OneRing,
            Stage::PerTet => SoftBodySystems::PerTet,
            Stage::Plasticity => SoftBodySystems::Plasticity,
            Stage::Integrate => SoftBodySystems::Integrate,
        }
    }
}

/// Adds soft-body simulation to an app.
///
/// By default the simulation runs in [`FixedUpdate`] and sets the fixed time step to the
/// paper's 10 ms; each run of the schedule is one step of `Time::delta` (the fixed step there).
/// Gravity is the [`SoftBodyGravity`] resource.
pub struct SoftBodyPlugin {
    /// The schedule the stages run in.
    pub schedule: InternedScheduleLabel,
    /// If set and the schedule is [`FixedUpdate`], the fixed time step to use. `None` leaves
    /// `Time<Fixed>` as the game configured it.
    pub time_step: Option<Duration>,
}

impl Default for SoftBodyPlugin {
    fn default() -> Self {
        SoftBodyPlugin {
            schedule: FixedUpdate.intern(),
            time_step: Some(Duration::from_millis(10)),
        }
    }
}

impl SoftBodyPlugin {
    /// Runs the stages in `schedule` instead of [`FixedUpdate`].
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        SoftBodyPlugin {
            schedule: schedule.intern(),
            time_step: None,
        }
    }
}

/// How the plugin was set up, for systems outside the step (the render surfaces).
#[derive(Resource, Clone, Copy, Debug)]
pub struct SoftBodyTiming {
    /// Whether the steps run in [`FixedUpdate`], so that frames fall between steps and are
    /// drawn interpolated.
    pub fixed: bool,
    /// The schedule the steps run in.
    pub schedule: InternedScheduleLabel,
}

impl Plugin for SoftBodyPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(SoftBodyTiming {
            fixed: self.schedule == FixedUpdate.intern(),
            schedule: self.schedule,
        });
        app.init_resource::<SoftBodyGravity>()
            .register_type::<SoftBodyGravity>()
            .register_type::<SoftBodyStats>()
            .register_type::<PinnedParticles>()
            .register_type::<DrivenParticles>()
            .register_type::<RigidSphere>()
            .init_resource::<SolverSpheres>()
            .init_resource::<SoftContactGroups>()
            .init_resource::<SoftBodyStepTime>()
            .init_resource::<SoftBodyThreads>()
            .register_type::<SoftBodyThreads>()
            .register_type::<SoftBodyStepTime>()
            .register_type::<SoftBodyStageTimes>()
            .add_message::<SoftBodyError>();
        if let Some(step) = self.time_step
            && self.schedule == FixedUpdate.intern()
        {
            app.insert_resource(Time::<Fixed>::from_duration(step));
        }
        // The sets in the core's order of a step, between preparing and writing back.
        let sets: Vec<SoftBodySystems> = std::iter::once(SoftBodySystems::Prepare)
            .chain(Stage::ORDER.map(SoftBodySystems::from))
            .chain([SoftBodySystems::Writeback])
            .collect();
        for pair in sets.windows(2) {
            app.configure_sets(self.schedule, pair[0].before(pair[1]));
        }
        app.add_systems(
            self.schedule,
            (prepare, gather_spheres)
                .chain()
                .in_set(SoftBodySystems::Prepare),
        );
        for stage in Stage::ORDER {
            app.add_systems(
                self.schedule,
                stage_system(stage).in_set(SoftBodySystems::from(stage)),
            );
        }
        app.add_systems(
            self.schedule,
            (finish_step, writeback)
                .chain()
                .in_set(SoftBodySystems::Writeback),
        );
    }
}
