//! [`SoftBodyPlugin`]: the systems that step every soft body, in ordered sets that mirror the
//! stages of a step, so that a game can put its own systems between them.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use bevy::ecs::batching::BatchingStrategy;
use bevy::ecs::schedule::{InternedScheduleLabel, ScheduleLabel};
use bevy::platform::time::Instant;
use bevy::prelude::*;
use parry3d::math::Pose;

use crate::components::settings::{SettingsQuery, core_settings};
use crate::components::{
    DrivenParticles, PinnedParticles, RigidSphere, SoftBody, SoftBodyContacts,
    SoftBodyContactsDisabled, SoftBodyCutter, SoftBodyError, SoftBodyErrorKind, SoftBodyForces,
    SoftBodyGrab, SoftBodyGravity, SoftBodyRadialImpulse, SoftBodyRunawayLimits,
    SoftBodySleepThreshold, SoftBodySleepingDisabled, SoftBodyStats, SoftBodyTearing, SoftBodyTorn,
    StaticCollider,
};
use crate::core::substep_plan::{spheres_after_bodies, spheres_before_bodies};
use crate::core::{
    BodyPoint, ColliderInstance, CollisionFilter, Parallel, RigidBodyMotion, RigidSphereState,
    Serial, SoftBodyState,
};
use crate::core::{Stage, SubstepStage};

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
/// core's order ([`Stage::ORDER`]; `core/substep.rs` says what each does and why in this
/// order), writing back. A game puts its own systems between them. The stages of a substep
/// ([`SubstepStage::ORDER`]) run inside [`SoftBodySystems::Substeps`], body by body (as
/// avian's substeps run inside its solver set); [`SoftBodyStepTime`] books each of them.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SoftBodySystems {
    /// Place new bodies, clear last step's counters, apply pinned and driven particles, the
    /// settings components and the game's forces and impulses ([`SoftBodyForces`],
    /// [`SoftBodyRadialImpulse`]), gather the rigid spheres and static colliders.
    Prepare,
    /// [`Stage::Forces`]: the paper's springs with damping, gravity and the baseline's volume
    /// forces for bodies in one substep; kinematic particles set moving; the spheres' gravity.
    Forces,
    /// [`Stage::Substeps`]: every body's substeps (shape, contacts, one-ring and per-tet
    /// impulses, `x += h_s v`); bodies that may touch each other in lockstep.
    Substeps,
    /// [`Stage::Plasticity`]: plastic springs.
    Plasticity,
    /// [`Stage::Finish`]: the spheres' last contacts and motion, each body's sleep and runaway
    /// check, the last soft-contact pass of bodies stepped together.
    Finish,
    /// The spheres' components follow the solver, metrics go into [`SoftBodyStats`], the
    /// bodies' transforms follow the bodies.
    Writeback,
}

impl From<Stage> for SoftBodySystems {
    fn from(stage: Stage) -> Self {
        match stage {
            Stage::Forces => SoftBodySystems::Forces,
            Stage::Substeps => SoftBodySystems::Substeps,
            Stage::Plasticity => SoftBodySystems::Plasticity,
            Stage::Finish => SoftBodySystems::Finish,
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
            .register_type::<SoftBodyContacts>()
            .register_type::<SoftBodyContactsDisabled>()
            .register_type::<SoftBodySleepThreshold>()
            .register_type::<SoftBodySleepingDisabled>()
            .register_type::<SoftBodyRunawayLimits>()
            .init_resource::<SolverSpheres>()
            .init_resource::<SoftContactGroups>()
            .init_resource::<SoftBodyStepTime>()
            .init_resource::<SoftBodyThreads>()
            .register_type::<SoftBodyThreads>()
            .register_type::<SoftBodyStepTime>()
            .register_type::<SoftBodyStageTimes>()
            .register_type::<SoftBodyForces>()
            .register_type::<SoftBodyGrab>()
            .register_type::<SoftBodyRadialImpulse>()
            .add_message::<SoftBodyError>()
            .register_type::<SoftBodyTearing>()
            .register_type::<SoftBodyCutter>()
            .add_message::<SoftBodyRadialImpulse>()
            .add_message::<SoftBodyTorn>();
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
            (prepare, apply_settings, apply_external, gather_spheres)
                .chain()
                .in_set(SoftBodySystems::Prepare),
        );
        app.add_systems(
            self.schedule,
            (
                forces.in_set(SoftBodySystems::Forces),
                substeps.in_set(SoftBodySystems::Substeps),
                plasticity.in_set(SoftBodySystems::Plasticity),
                finish.in_set(SoftBodySystems::Finish),
            ),
        );
        app.add_systems(
            self.schedule,
            (finish_step, writeback)
                .chain()
                .in_set(SoftBodySystems::Writeback),
        );
    }
}
