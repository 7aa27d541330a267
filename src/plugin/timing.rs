//! The step's wall-clock time, stage by stage: what a frame pays for the physics.

use super::*;

/// Wall-clock time of the plugin's stages for all bodies together: what a frame pays for the
/// physics. Bodies are stepped in parallel on Bevy's compute task pool, so with several bodies
/// and threads this is less than the sum of the bodies' own [`SoftBodyStats::step_ms`].
#[derive(Resource, Clone, Copy, Debug, Default, Reflect)]
#[reflect(Resource)]
pub struct SoftBodyStepTime {
    /// The last step, in milliseconds.
    pub last_ms: f64,
    /// All steps so far, in milliseconds.
    pub total_ms: f64,
    /// The slowest step so far, in milliseconds.
    pub max_ms: f64,
    /// Steps so far.
    pub steps: u64,
    /// All steps so far, stage by stage: where the time goes. The stages add up to
    /// `total_ms` (see [`SoftBodyStepTime::mean_stage_ms`] for the means per step).
    pub stages_total: SoftBodyStageTimes,
    /// The step being timed.
    #[reflect(ignore)]
    pub(super) current: Duration,
}

/// Milliseconds spent in each timed stage of the step (see [`SoftBodySystems`]), all bodies
/// together. [`SoftBodySystems::Prepare`] and [`SoftBodySystems::Writeback`] are outside the step
/// and not timed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Reflect)]
pub struct SoftBodyStageTimes {
    /// [`SoftBodySystems::Forces`].
    pub forces_ms: f64,
    /// [`SoftBodySystems::Contacts`]: the first contact pass, and the substepped shape solves
    /// (XPBD's whole step, a physical material's edges), which meet the contacts.
    pub contacts_ms: f64,
    /// [`SoftBodySystems::OneRing`]: the one-ring pass, with its clamp bounds.
    pub one_ring_ms: f64,
    /// [`SoftBodySystems::PerTet`].
    pub per_tet_ms: f64,
    /// [`SoftBodySystems::Plasticity`].
    pub plasticity_ms: f64,
    /// [`SoftBodySystems::Integrate`]: the last contact pass and the positions.
    pub integrate_ms: f64,
}

impl SoftBodyStageTimes {
    /// The time of `stage`.
    pub fn stage(&self, stage: Stage) -> f64 {
        let mut times = *self;
        *times.stage_mut(stage)
    }

    fn stage_mut(&mut self, stage: Stage) -> &mut f64 {
        match stage {
            Stage::Forces => &mut self.forces_ms,
            Stage::Contacts => &mut self.contacts_ms,
            Stage::OneRing => &mut self.one_ring_ms,
            Stage::PerTet => &mut self.per_tet_ms,
            Stage::Plasticity => &mut self.plasticity_ms,
            Stage::Integrate => &mut self.integrate_ms,
        }
    }

    /// The sum of all stages.
    pub fn sum_ms(&self) -> f64 {
        self.forces_ms
            + self.contacts_ms
            + self.one_ring_ms
            + self.per_tet_ms
            + self.plasticity_ms
            + self.integrate_ms
    }

    /// Adds `other`'s time in each stage to this one's: the stages of runs taken together.
    pub fn add(&mut self, other: &SoftBodyStageTimes) {
        self.forces_ms += other.forces_ms;
        self.contacts_ms += other.contacts_ms;
        self.one_ring_ms += other.one_ring_ms;
        self.per_tet_ms += other.per_tet_ms;
        self.plasticity_ms += other.plasticity_ms;
        self.integrate_ms += other.integrate_ms;
    }

    /// Each stage divided by `n`.
    pub(super) fn divided_by(&self, n: f64) -> SoftBodyStageTimes {
        SoftBodyStageTimes {
            forces_ms: self.forces_ms / n,
            contacts_ms: self.contacts_ms / n,
            one_ring_ms: self.one_ring_ms / n,
            per_tet_ms: self.per_tet_ms / n,
            plasticity_ms: self.plasticity_ms / n,
            integrate_ms: self.integrate_ms / n,
        }
    }
}

impl SoftBodyStepTime {
    /// Mean wall-clock time per step so far, in milliseconds.
    pub fn mean_ms(&self) -> f64 {
        if self.steps == 0 {
            0.0
        } else {
            self.total_ms / self.steps as f64
        }
    }

    /// Mean wall-clock time per step of each stage so far (zero before the first step).
    pub fn mean_stage_ms(&self) -> SoftBodyStageTimes {
        if self.steps == 0 {
            SoftBodyStageTimes::default()
        } else {
            self.stages_total.divided_by(self.steps as f64)
        }
    }

    /// Adds the time since `start` to the step being timed and to `stage`.
    pub(super) fn add_stage(&mut self, start: Instant, stage: Stage) {
        let elapsed = start.elapsed();
        self.current += elapsed;
        *self.stages_total.stage_mut(stage) += elapsed.as_secs_f64() * 1e3;
    }
}
