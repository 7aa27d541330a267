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

/// Milliseconds spent in each timed stage of the step (see [`SoftBodySystems`]) and of its
/// substeps (see [`SubstepStage`]), all bodies together. [`SoftBodySystems::Prepare`] and
/// [`SoftBodySystems::Writeback`] are outside the step and not timed. The substep stages share
/// [`SoftBodySystems::Substeps`]' wall-clock time in the proportion the bodies spent in each
/// (they run in parallel, body by body).
#[derive(Clone, Copy, Debug, Default, PartialEq, Reflect)]
pub struct SoftBodyStageTimes {
    /// [`SoftBodySystems::Forces`].
    pub forces_ms: f64,
    /// [`SubstepStage::Shape`]: the shape solve, with planning the substeps.
    pub shape_ms: f64,
    /// [`SubstepStage::Contacts`]: the contacts, with the soft contacts between bodies.
    pub contacts_ms: f64,
    /// [`SubstepStage::OneRing`]: the one-ring pass, with its clamp bounds.
    pub one_ring_ms: f64,
    /// [`SubstepStage::PerTet`].
    pub per_tet_ms: f64,
    /// [`SubstepStage::Advance`]: `x += h_s v`.
    pub advance_ms: f64,
    /// [`SoftBodySystems::Plasticity`].
    pub plasticity_ms: f64,
    /// [`SoftBodySystems::Finish`]: sleep, runaway, the last soft contacts, the spheres.
    pub finish_ms: f64,
}

impl SoftBodyStageTimes {
    /// Every stage's time, in the order of a step: forces, the substep stages, plasticity,
    /// finish.
    pub fn as_array(&self) -> [f64; 8] {
        [
            self.forces_ms,
            self.shape_ms,
            self.contacts_ms,
            self.one_ring_ms,
            self.per_tet_ms,
            self.advance_ms,
            self.plasticity_ms,
            self.finish_ms,
        ]
    }

    fn from_array(a: [f64; 8]) -> SoftBodyStageTimes {
        SoftBodyStageTimes {
            forces_ms: a[0],
            shape_ms: a[1],
            contacts_ms: a[2],
            one_ring_ms: a[3],
            per_tet_ms: a[4],
            advance_ms: a[5],
            plasticity_ms: a[6],
            finish_ms: a[7],
        }
    }

    /// The time of a step's `stage` (for [`Stage::Substeps`], its substep stages together).
    pub fn stage(&self, stage: Stage) -> f64 {
        let a = self.as_array();
        match stage {
            Stage::Forces => a[0],
            Stage::Substeps => a[1..6].iter().sum(),
            Stage::Plasticity => a[6],
            Stage::Finish => a[7],
        }
    }

    /// The time of the substeps' `stage`.
    pub fn substep_stage(&self, stage: SubstepStage) -> f64 {
        self.as_array()[1 + stage as usize]
    }

    /// The sum of all stages.
    pub fn sum_ms(&self) -> f64 {
        self.as_array().iter().sum()
    }

    /// Adds `other`'s time in each stage to this one's: the stages of runs taken together.
    pub fn add(&mut self, other: &SoftBodyStageTimes) {
        let (mut a, b) = (self.as_array(), other.as_array());
        for (a, b) in a.iter_mut().zip(b) {
            *a += b;
        }
        *self = SoftBodyStageTimes::from_array(a);
    }

    /// Each stage divided by `n`.
    pub(super) fn divided_by(&self, n: f64) -> SoftBodyStageTimes {
        SoftBodyStageTimes::from_array(self.as_array().map(|a| a / n))
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

    /// Adds the time since `start` to the step being timed and to `stage` (not
    /// [`Stage::Substeps`], which [`SoftBodyStepTime::add_substeps`] books).
    pub(super) fn add_stage(&mut self, start: Instant, stage: Stage) {
        let elapsed = start.elapsed();
        self.current += elapsed;
        let ms = elapsed.as_secs_f64() * 1e3;
        let t = &mut self.stages_total;
        match stage {
            Stage::Forces => t.forces_ms += ms,
            Stage::Substeps => t.shape_ms += ms,
            Stage::Plasticity => t.plasticity_ms += ms,
            Stage::Finish => t.finish_ms += ms,
        }
    }

    /// Adds the time since `start` to the step being timed, shared among the substep stages
    /// in the proportion of `seconds` (the bodies' own time in each; all to the shape stage,
    /// which plans the substeps, when the bodies ran none).
    pub(super) fn add_substeps(&mut self, start: Instant, seconds: [f64; 5]) {
        let elapsed = start.elapsed();
        self.current += elapsed;
        let ms = elapsed.as_secs_f64() * 1e3;
        let spent: f64 = seconds.iter().sum();
        let mut a = self.stages_total.as_array();
        if spent > 0.0 {
            for (stage, s) in a[1..6].iter_mut().zip(seconds) {
                *stage += ms * s / spent;
            }
        } else {
            a[1] += ms;
        }
        self.stages_total = SoftBodyStageTimes::from_array(a);
    }
}
