//! The stages a step and a substep run in (`substep.rs` runs them; the plugin's systems
//! follow [`Stage::ORDER`]), the spheres' part of each, and what the substep loop keeps in a
//! body between its stages: the step's plan and the clock of its stages. Apart from the loop
//! so that the body can hold them.

use std::time::Instant;

use glam::Vec3;

use super::colliders::{ColliderInstance, RigidSphereState};

/// A stage of a step, in the order [`Stage::ORDER`]; see the module's documentation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stage {
    /// The explicit springs' forces and gravity; kinematic particles set moving.
    Forces,
    /// The substeps: shape, contacts, the volume passes, `x += h_s v`.
    Substeps,
    /// The plastic springs' flow.
    Plasticity,
    /// Sleep, the runaway check, the spheres' last contacts and motion.
    Finish,
}

impl Stage {
    /// The stages in the order a step runs them.
    pub const ORDER: [Stage; 4] = [
        Stage::Forces,
        Stage::Substeps,
        Stage::Plasticity,
        Stage::Finish,
    ];
}

/// A stage of a substep, in the order [`SubstepStage::ORDER`]; see the module's documentation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SubstepStage {
    /// Gravity, the predicted positions, the shape solve.
    Shape,
    /// The velocities from the shape solve, then the contacts.
    Contacts,
    /// Damping, then the one-ring volume impulses (section 5).
    OneRing,
    /// The per-tet volume impulses scaled by gamma, with the neighbour clamp (section 4).
    PerTet,
    /// `x += h_s v`.
    Advance,
}

impl SubstepStage {
    /// The stages in the order a substep runs them.
    pub const ORDER: [SubstepStage; 5] = [
        SubstepStage::Shape,
        SubstepStage::Contacts,
        SubstepStage::OneRing,
        SubstepStage::PerTet,
        SubstepStage::Advance,
    ];
}

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

/// The spheres' part of `stage` that comes before the bodies': their gravity with the
/// forces, their contacts with the static colliders before the substeps and again at the
/// finish (after the particles pushed them).
pub fn spheres_before_bodies(
    stage: Stage,
    h: f32,
    gravity: Vec3,
    spheres: &mut [RigidSphereState],
    colliders: &[ColliderInstance],
) {
    for sphere in spheres {
        match stage {
            Stage::Forces => sphere.apply_forces(h, gravity),
            Stage::Substeps | Stage::Finish => {
                sphere.resolve_static_contacts(h, colliders);
            }
            Stage::Plasticity => {}
        }
    }
}

/// The spheres' part of `stage` that comes after the bodies': `x += h v` at the finish.
pub fn spheres_after_bodies(stage: Stage, h: f32, spheres: &mut [RigidSphereState]) {
    if stage == Stage::Finish {
        for sphere in spheres {
            sphere.integrate_position(h);
        }
    }
}
