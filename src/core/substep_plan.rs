//! What the substep loop (`substep.rs`) keeps in a body between its stages: the step's plan
//! and the clock of its stages. Apart from the loop so that the body can hold them.

use std::time::Instant;

/// A step's substeps, as `SoftBodyState::plan_substeps` set them up.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SubstepPlan {
    /// How many.
    pub(crate) substeps: u32,
    /// Their length.
    pub(crate) hs: f32,
    /// The paper's explicit springs: one substep of the whole step, its shape stage empty
    /// (the springs acted in the step's forces).
    pub(crate) explicit: bool,
    /// XPBD: the tets' volumes are projected in the shape solve, no volume impulses.
    pub(crate) volumes: bool,
    /// The shape projection's damping term (physical materials).
    pub(crate) shape_damping: f32,
    /// Whether the paper's spring dampers act on the velocities.
    pub(crate) dampers: bool,
    /// The tets' shape compliances, for a physical material under the impulses.
    pub(crate) tet_compliance: Option<[f32; 2]>,
}

/// Seconds a body spent in each stage of a substep (`SubstepStage`, by index) since they were last taken, when timed (the
/// plugin's [`SoftBodyStepTime`](crate::SoftBodyStepTime)); not timed, a substep reads no clock.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct SubstepClock {
    pub(crate) on: bool,
    pub(crate) seconds: [f64; 5],
}

impl SubstepClock {
    pub(crate) fn start(&self) -> Option<Instant> {
        self.on.then(Instant::now)
    }

    pub(crate) fn stop(&mut self, stage: usize, started: Option<Instant>) {
        if let Some(started) = started {
            self.seconds[stage] += started.elapsed().as_secs_f64();
        }
    }
}
