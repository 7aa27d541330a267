//! What a game reads back: per-body statistics and the errors the plugin reports.

use bevy::prelude::*;

use crate::core::{Runaway, StepCounters};

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
    /// The body's tet mesh has tets that fold over a neighbour or overlap another (see
    /// [`TetMesh::defects`](crate::core::TetMesh::defects)); reported when the body is placed.
    /// It is simulated as given: the volume passes push those tets apart, and its volume error
    /// spikes there. Re-mesh the model.
    MeshDefects(crate::core::MeshDefects),
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
            SoftBodyErrorKind::MeshDefects(defects) => {
                write!(
                    f,
                    "soft body {}: its tet mesh is broken: {defects}",
                    self.body
                )
            }
            SoftBodyErrorKind::Surface { surface, reason } => write!(
                f,
                "soft body {}: surface {surface} cannot follow it: {reason}",
                self.body
            ),
        }
    }
}
