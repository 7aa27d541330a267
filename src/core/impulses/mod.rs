//! The paper's volume impulses (sections 4 and 5) and the neighbour clamp.
//!
//! Both passes work on predicted positions `xp = x + h v` and change velocities only, in
//! Gauss-Seidel order: each impulse sees every impulse applied before it in the same pass.
//!
//! Directions. For a tet `t` with volume error `C_t = vol(xp) - V0_t`, the paper's impulse of
//! magnitude `k` moves vertex `i` by `k * d_i` with `d_i = -h^2 w_i C_t grad_i`. Only the
//! direction matters (the step length is solved for), so the common factor `h^2` is dropped.
//! Because the gradients of a tet sum to zero, `sum m_i d_i = 0` among free particles, and so
//! every impulse conserves momentum whatever its size.
//!
//! Decisions where the paper is silent:
//! - Ring step limit: see [`RING_STEP_LIMIT`].
//! - Which root: the smallest positive one reached while the volume moves monotonically towards
//!   its target ([`monotone_root`]). The summed ring directions can point away from the ring's
//!   target (its tets disagree), and then the cubic's positive roots lie past a turning point,
//!   millions of times further than any sensible step: such a ring is left alone.
//! - Tets and rings within `ImpulseSettings::tolerance` of their rest volume get no impulse; a
//!   ring within it whose tets are each within `ImpulseSettings::ring_tet_tolerance` neither.
//! - Cubic without such a root: no impulse (counted in [`StepCounters`]); the next step
//!   tries again from new positions. Forcing a step there could only overshoot.
//! - All directions zero (ring at rest volume, or all its particles kinematic): skipped.
//! - A tet touched by an impulse that is already below `eps = V0 / 2` may lose at most
//!   [`CLAMP_SLACK`] of its rest volume per impulse. Forbidding it to shrink at all (the first
//!   rule tried) froze every impulse near a crushed region, including those that re-inflate it,
//!   and a soft cube under a heavy sphere lost much of its volume (PERFORMANCE.md).
//! - The per-tet correction is clamped at the step actually applied (`gamma * s*`), not at
//!   `s*`: only what is applied can harm a neighbour.
//!

use std::ops::Range;
use std::sync::atomic::{AtomicU32, Ordering};

use glam::Vec3;
use wide::{CmpEq, CmpGe, CmpGt, CmpLe, CmpLt, CmpNe, f32x4};

use super::colliders::RigidSphereState;
use super::geometry::{
    SIXTH, signed_volume, volume_gradients, volume_polynomial, volume_polynomial_lanes,
};
use super::lanes::{LANES, Point4, Vec3x4};
use super::material::{ImpulseSettings, VolumeMethod};
use super::parallel::{Parallel, Phase, SharedSlice, run_phases};
use super::roots::{Cubic, clear_of_zero, first_crossing, monotone_root};
use super::tet_mesh::{Csr, TetMesh};

mod bounds;
mod clamp;
mod passes;
mod ring;
#[cfg(test)]
pub(crate) mod tests;
mod tet;

use bounds::*;
pub(crate) use passes::{PassBody, VolumePassScratch};
use ring::RingWork;

/// What the volume passes did in the last step (for statistics and tests).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StepCounters {
    /// Rings whose impulse was applied.
    pub rings_corrected: u32,
    /// Rings whose cubic had no positive root: no impulse was applied to them.
    pub rings_without_root: u32,
    /// Rings whose impulse the neighbour clamp shortened.
    pub rings_clamped: u32,
    /// Tets whose per-tet cubic had no positive root.
    pub tets_without_root: u32,
    /// Tets whose per-tet impulse the neighbour clamp shortened.
    pub tets_clamped: u32,
    /// Impulses whose neighbour clamp was known to be moot from the pass's bounds, so its walk
    /// over the neighbours was skipped.
    pub clamps_skipped: u32,
    /// Rings whose tolerance check was answered by the pass's bounds (within, nothing to do)
    /// without computing their tets' volumes.
    pub ring_checks_skipped: u32,
    /// Particles whose new position would not have been finite: kept in place and stopped.
    pub non_finite_velocities: u32,
    /// Substeps the step took (0 for a body not solved in substeps, or asleep).
    pub substeps: u32,
}

/// What one impulse did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ImpulseOutcome {
    /// Nothing to do: no volume error, or no free particle to move.
    Skipped,
    /// The cubic had no positive root: nothing applied.
    NoRoot,
    /// The impulse was applied with this step length (after clamping and `gamma`).
    Applied {
        /// The step length `s` actually applied.
        step: f64,
        /// The root of the cubic: the step that restores the volume exactly.
        root: f64,
        /// Whether the neighbour clamp shortened it.
        clamped: bool,
    },
}

/// `contact_sphere` of a particle touching another soft body (no sphere has this index).
pub(crate) const SOFT_CONTACT: u32 = u32::MAX - 1;

/// What a volume pass does with one task's row of items (vertices or tet bundles; see
/// `PassBody::run_blocks`), given the row's place in the flat list of items.
type BlockImpulses<'a> = dyn Fn(&VolumePass, &mut PassWorker, &[u32], usize) + Sync + 'a;

/// Which clamp regions a pass uses.
#[derive(Clone, Copy, PartialEq, Eq)]
enum ClampRegions {
    /// One region per vertex: its one-ring and the tets bordering it.
    Rings,
    /// One region per tet: itself and the tets sharing a vertex with it.
    Tets,
}

/// A ring's step is at most this multiple of the smallest per-tet step of its tets, the step
/// `1 / sum_i w_i |grad_i|^2` at which a tet's own direction corrects that tet to first order.
///
/// Why: for an interior vertex the centre particle cannot change the volume of its ring (the
/// ring is a star around it), so the ring's root is set by the outer particles alone, while the
/// centre moves by the same step along the sum of its tets' directions. Where the ring's tets
/// disagree (some compressed, some stretched), the root is many times the per-tet step (in the
/// twisted bar: 1 to 3 times typically, over 100 times at worst) and the centre is thrown
/// through its neighbours; without this limit the paper's ring pass diverged within a second
/// in the twisted bar, clamp or no clamp. With it, the ring is corrected partly in such steps
/// and fully again once its tets agree.
pub const RING_STEP_LIMIT: f64 = 1.0;

/// The per-tet pass's `gamma` for a tet whose predicted volume is inverted: its whole
/// correction, not the paper's eighth. `gamma` keeps the per-tet pass from locking a body that
/// its rings let deform; a flipped tet is not such a deformation but a fold, which the paper
/// expects its impulses to repair (section 4). A sliver, nearly flat at rest, flips at a tiny
/// motion and an eighth of a correction a step may never flip it back (PERFORMANCE.md,
/// "Inverted tets get their whole per-tet correction"). The neighbour clamp still bounds it.
pub const INVERTED_TET_GAMMA: f64 = 1.0;

/// How much of its rest volume a tet that is already below `eps` may lose in one impulse.
pub const CLAMP_SLACK: f32 = 0.1;

/// Fraction of the rest volume below which the clamp does not let a touched tet go (`eps`).
pub const CLAMP_FRACTION: f32 = 0.5;

/// A tet at `eps`, up to this fraction of its rest volume above it, counts as below `eps`.
/// An impulse the clamp stopped at a tet's floor leaves the tet there up to the rounding of its
/// volume, which falls either side: by the rounding, the next impulse touching it was either
/// frozen (at `eps` a tet may lose nothing) or given a crushed tet's [`CLAMP_SLACK`] (the
/// reference passes, `reference.rs`, found it in the jelly cube's landing). Counted as below,
/// as crushed as the clamp lets a tet be, it keeps the slack, which lets the impulses that
/// re-inflate it go on (PERFORMANCE.md).
pub const CLAMP_ROUNDING: f32 = 1e-4;

/// The least volume the neighbour clamp lets a tet of rest volume `v0`, now of `volume`, reach:
/// `eps = V0 / 2`, or for a tet already below it (or at it, see [`CLAMP_ROUNDING`]), its volume
/// less [`CLAMP_SLACK`] of its rest volume.
#[inline]
pub(crate) fn clamp_floor(volume: f32, v0: f32) -> f32 {
    let eps = CLAMP_FRACTION * v0;
    if volume >= eps + CLAMP_ROUNDING * v0 {
        eps
    } else {
        volume - CLAMP_SLACK * v0
    }
}

/// `d`, a volume impulse's direction at a particle touching a surface of outward unit normal
/// `n` (zero: none), with its push into that surface reduced to the share `kept` the particle
/// keeps, and its push into a second static surface `second` (zero: none) taken out; a push
/// still into the first, hard surface after that (a wedge sharper than a right angle) is
/// left along their common edge.
#[inline]
pub(crate) fn constrained_push(d: Vec3, n: Vec3, kept: f32, second: Vec3) -> Vec3 {
    let into = d.dot(n);
    let d = if into < 0.0 {
        d - n * (into * (1.0 - kept))
    } else {
        d
    };
    let into_second = d.dot(second);
    if into_second >= 0.0 {
        return d;
    }
    let d = d - second * into_second;
    if kept == 0.0 && d.dot(n) < 0.0 {
        let edge = n.cross(second).normalize_or_zero();
        return edge * d.dot(edge);
    }
    d
}

/// What the jobs of a pass share: the body's read-only data, and the arrays they write, each
/// element by one job at a time (see [`super::parallel`]).
pub(crate) struct VolumePass<'a> {
    mesh: &'a TetMesh,
    h: f32,
    inv_masses: &'a [f32],
    contact_normals: &'a [Vec3],
    contact_kept: &'a [f32],
    /// `contact_second`, if any particle touches two static colliders.
    contact_second: Option<&'a [Vec3]>,
    contact_sphere: &'a [u32],
    /// What `constrain_direction` took from each particle touching another soft body.
    removed: SharedSlice<'a, Vec3>,
    any_touching: bool,
    bounds: PassRadii<'a>,
    velocities: SharedSlice<'a, Vec3>,
    /// Predicted positions `x + h v`, kept up to date with every velocity change.
    predicted: SharedSlice<'a, Point4>,
    /// Impulse directions by particle, for the clamp walk (zero outside a walk).
    scratch: SharedSlice<'a, Vec3>,
    drift: SharedSlice<'a, f32>,
    move_len: SharedSlice<'a, f32>,
    walks: WalkMarks<'a>,
    far: FarDriftMarks<'a>,
    /// Per vertex, whether its ring was past its tolerance when last checked (see
    /// `VolumePassScratch::ring_corrected`); read and written by that ring's impulse only.
    ring_corrected: SharedSlice<'a, bool>,
}

impl VolumePass<'_> {
    #[inline(always)]
    fn predicted_position(&self, i: u32) -> Vec3 {
        self.predicted.get(i as usize).vec3()
    }

    /// `d` with its push into what particle `i` touches reduced to the part the particle keeps:
    /// a volume impulse cannot move a particle into the ground at all, and moves a particle
    /// pressed against a heavy sphere only as far as the pair moves together. The cubic is then
    /// solved for the motion the particle can make, so the last contact pass does not undo it.
    #[inline]
    fn constrain_direction(&self, i: usize, d: Vec3) -> Vec3 {
        let second = self.contact_second.map_or(Vec3::ZERO, |second| second[i]);
        constrained_push(d, self.contact_normals[i], self.contact_kept[i], second)
    }

    /// Adds `dv` to particle `i`'s velocity; if `i` is pressed against a sphere and `dv` pushes
    /// into it, the sphere moves along with the particle (the push was already reduced to the
    /// pair's share by `constrain_direction`), so momentum is conserved.
    #[inline(always)]
    /// `removed` is what `constrain_direction` took out of this change (kept for a particle
    /// touching another soft body, which is handed it; see `soft_contacts.rs`).
    fn apply_velocity_change(&self, worker: &mut PassWorker, i: usize, dv: Vec3, removed: Vec3) {
        self.velocities.set(i, self.velocities.get(i) + dv);
        let predicted_position = self.predicted.get(i).vec3() + self.h * dv;
        self.predicted.set(i, Point4::new(predicted_position));
        if self.bounds.active {
            let drift = (predicted_position - self.bounds.start.get(i)).length();
            if !self.bounds.is_far(i, drift) {
                worker.max_moved = larger(worker.max_moved, drift);
            } else if !self.bounds.is_far(i, self.drift.get(i)) {
                self.far.mark(self.mesh, i);
            }
            self.drift.set(i, drift);
        }
        let k = self.contact_sphere[i];
        if k == SOFT_CONTACT {
            self.removed.set(i, self.removed.get(i) + removed);
        }
        if k != u32::MAX
            && let Some(sphere_dv) = worker.sphere_dv.get_mut(k as usize)
        {
            let n = self.contact_normals[i];
            let into = dv.dot(n);
            if into < 0.0 {
                *sphere_dv += n * into;
            }
        }
    }
}
