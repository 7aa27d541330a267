//! The paper's volume impulses (sections 4 and 5) and the neighbour clamp.
//!
//! Both passes work on previewed positions `xp = x + h v` and change velocities only, in
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
//!   rule tried) froze every impulse near a crushed region, including those that re-inflate it:
//!   under a heavy sphere the soft cube then lost 38 % of its volume instead of under 2 %.
//! - The per-tet correction is clamped at the step actually applied (`gamma * s*`), not at
//!   `s*`: only what is applied can harm a neighbour.
//!
//! [`StepCounters`]: super::body::StepCounters

use std::ops::Range;
use std::sync::atomic::{AtomicU32, Ordering};

use glam::Vec3;
use wide::{CmpGe, CmpGt, CmpLe, CmpNe, f32x4};

use super::body::{SoftBodyState, StepCounters};
use super::contacts::RigidSphereState;
use super::geometry::{
    SIXTH, signed_volume, volume_gradients, volume_polynomial, volume_polynomial_lanes,
};
use super::lanes::{LANES, Point4, Vec3x4};
use super::material::{ImpulseSettings, VolumeMethod};
use super::parallel::{Parallel, Phase, Serial, SharedSlice, run_phases};
use super::roots::{Cubic, clear_of_zero, first_crossing, monotone_root};
use super::tet_mesh::{Csr, TetMesh};

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

/// Bounds computed at the start of a volume pass that let most impulses skip the neighbour
/// clamp without looking at their neighbours.
///
/// Every tet's volume can change from its value at the start of the pass only through the
/// motion of its vertices; if each of them moves by at most `m` from where it was at the start,
/// the volume moves by at most `drift_bound(m, G, L)`, with `G` the sum of the lengths of the
/// tet's volume gradients and `L` its longest edge from its last vertex, both at the start. A
/// particle's drift is the distance of its preview from where it was at the start of the pass.
/// Each tet's slack (its volume above its floor at the start) gives it a radius
/// ([`safe_radius`]): while each of its particles stays within it of its start, the tet stays
/// above its floor. A vertex's radius is the smallest of its one-ring's, a clamp region's the
/// smallest of its vertices'.
///
/// An impulse whose own largest move is `m` cannot bring any tet of its clamp region to its
/// floor when `drift + m` is within the region's radius; then the clamp's answer is known (no
/// shortening) and its walk over the neighbours is skipped. There `drift` is
/// the largest drift any particle the impulse's block can reach has had in the pass
/// (`PassWorker::max_moved`, free to check). If that is not enough, the region is checked one
/// impulse vertex at a time, each vertex's one-ring against its own radius with the
/// farthest any of its ring vertices can be from its start (its drift plus its own move), and
/// only the one-rings of the vertices this does not clear are walked (in the soft cube under its
/// sphere, walks of whole regions looked at 113 000 tets per step, about 130 per walk, to
/// shorten 15 impulses). In a walk, each tet is checked against its own radius with how far
/// each of its own four particles can be from its start. One radius per tet, vertex and region
/// replaced a slack, a gradient sum and a reach each (their extremes over a region came from
/// different tets, so the bound was looser, and there were three times as many to compute).
///
/// A tet already below `eps` at the start gets as slack half of `CLAMP_SLACK` (the drift before
/// an impulse and the impulse itself each count once), and no more than its distance to `eps`,
/// so that it cannot climb above `eps` unseen, where the exact rule would no longer let it drop.
#[derive(Clone, Debug, Default)]
pub(crate) struct ClampBounds {
    /// Whether the bounds describe the current pass.
    pub(crate) active: bool,
    /// Never use the bounds (to compare against the exact walk in tests).
    pub(crate) disabled: bool,
    /// Whether the bounds were taken in this step (by its one-ring pass), for the per-tet
    /// pass to go on from (see [`SoftBodyState::per_tet_pass_on`]); cleared by `begin_step`.
    pub(crate) taken_this_step: bool,
    /// Whether the next bounds taken (by a one-ring pass) are to cover the tets' regions too,
    /// for the per-tet pass after it.
    keep_for_tets: bool,
    /// Whether the bounds were last taken by a one-ring pass, so that a later step's one-ring
    /// pass may go on from them (see [`ClampBounds::still_hold`]), and whether they cover the
    /// tets' regions too.
    kept: bool,
    kept_tet_regions: bool,
    /// One-ring passes that went on from an earlier step's bounds (for tests).
    pub(crate) carried_passes: u32,
    /// Go on from an earlier step's bounds however far the particles are from their start (to
    /// test that the result does not depend on it).
    pub(crate) always_carry: bool,
    tet_radius: Vec<f32>,
    vertex_radius: Vec<f32>,
    /// The radius of each vertex's ring region ([`ClampRegions::Rings`]).
    ring_region_radius: Vec<f32>,
    /// The radius of each tet's region ([`ClampRegions::Tets`]).
    tet_region_radius: Vec<f32>,
    /// Each tet's volume error, gradient sum and longest edge from its last vertex at the
    /// start, for the rings' [`RingCheckBound`]s.
    tet_shape: Vec<TetShape>,
    /// Each vertex's ring at the start (see [`RingCheckBound`]), computed by the first pass
    /// that goes on from these bounds: a body that takes new bounds every pass (one that
    /// changes its shape) would pay for them without a pass to use them in.
    ring_check: Vec<RingCheckBound>,
    /// Whether `ring_check` describes these bounds.
    ring_checks_ready: bool,
    /// Previews when the bounds were taken: a particle's drift is its distance from here.
    start: Vec<Vec3>,
}

/// A tet at the start of the bounds: what [`RingCheckBound`] is made of.
#[derive(Clone, Copy, Debug, Default)]
struct TetShape {
    error: f32,
    grad: f32,
    reach: f32,
}

/// What a ring's tolerance check (see `PassView::ring_impulse`) found at the bounds' start, in
/// a form that bounds how far its drifts can have moved it since: the ring's volume error, the
/// sums over its tets of their gradient sums and reaches (the terms of [`drift_bound`] summed),
/// the largest relative error of one of its tets, its smallest rest volume, and its largest
/// gradient sum and reach. With each particle of the ring within `d` of its start, each tet's
/// volume is within `drift_bound(d, grad, reach)` of its volume there, so a ring whose error
/// and tets stay within the tolerances by these bounds is within them now, and its check
/// (a tet volume per tet of the ring) is skipped: the answer is known. Used in quiet bodies
/// only (see [`QUIET_DRIFT`]). Instructions of whole `bench` runs (callgrind, the paper's
/// method alone): the boxes settling on the ground (box_29k) 2.45 -> 1.90 billion, the 16
/// bodies 4.57 -> 3.62, the creature 13.87 -> 13.81, the soft cube 27.34 -> 27.27 (under its
/// sphere few particles are that still).
#[derive(Clone, Copy, Debug, Default)]
struct RingCheckBound {
    error: f32,
    grad_sum: f32,
    reach_sum: f32,
    tets: f32,
    largest_relative_error: f32,
    smallest_rest_volume: f32,
    largest_grad: f32,
    largest_reach: f32,
}

/// A ring is known to be within its tolerances when the bounds of [`RingCheckBound`] keep it
/// within this fraction of them: the rest covers the rounding of the `f32` volumes, the
/// check's and the bounds' own (about a millionth of a tet's volume for a well-shaped tet,
/// hundreds of times less than this margin of the ring tet tolerance, 5e-4 of the tet's
/// volume), so the shortcut never skips a ring that the check would correct.
const RING_CHECK_MARGIN: f32 = 0.95;

/// A one-ring pass uses the rings' [`RingCheckBound`]s only when at least [`QUIET_SHARE`] of
/// the body's particles have drifted less than this fraction of their vertex radius since the
/// bounds' start (counted by `ClampBounds::near_start`). A tet's radius is about where it loses half its
/// volume, so a ring's tolerance (0.3 %) allows a small fraction of it, less its error. In a
/// body that is not this still, few rings are known and the bounds cost more than they save:
/// the soft cube under its resting sphere, with the rings' bounds on every carried pass, took
/// 6 % more instructions, most rings failing the test and the bounds made again for each
/// short-lived set of clamp bounds.
pub const QUIET_DRIFT: f32 = 0.005;

/// See [`QUIET_DRIFT`].
pub const QUIET_SHARE: f32 = 0.75;

impl RingCheckBound {
    /// Whether a ring with this bound, each of whose particles is within `drift` of its start,
    /// is within `tolerance` of its rest volume `rest` and each of its tets within
    /// `ring_tet_tolerance` of theirs. False for a broken (NaN) drift or bound.
    #[inline]
    fn within(&self, drift: f32, tolerance: f32, ring_tet_tolerance: f32, rest: f32) -> bool {
        let (d, d2, d3) = (drift, drift * drift, drift * drift * drift);
        let ring = d * self.grad_sum + 2.0 * d2 * self.reach_sum + 4.0 / 3.0 * d3 * self.tets;
        let tet = d * self.largest_grad + 2.0 * d2 * self.largest_reach + 4.0 / 3.0 * d3;
        self.error.abs() + ring <= RING_CHECK_MARGIN * tolerance * rest
            && self.largest_relative_error + tet / self.smallest_rest_volume
                <= RING_CHECK_MARGIN * ring_tet_tolerance
    }
}

/// A one-ring pass goes on from the bounds an earlier step's one-ring pass took when no particle
/// (but a few strays, see [`CARRY_STRAYS`]) has drifted from where they were taken (moved along
/// with the body, see `ClampBounds::follow_translation`) by more than this fraction of its
/// vertex radius: a body at rest, or nearly, whose particles come back to about the same
/// previews step after step, or one that moves as a whole (falling, thrown, carried). The
/// bounds hold however far the particles have gone (drifts are measured from their start, as
/// for the per-tet pass), but the further they start from it, the fewer impulses they clear at
/// once, so a body that changes its shape takes them afresh.
///
/// Taking the bounds was about a fifth of the step of a 1080-tet box resting on the ground. In
/// that box, over 600 steps, 0.125 / 0.25 / 0.5 / 1 of the radius let 68 / 241 / 400 / 491 passes
/// go on, and the ring pass took 43-49 / 43 / 40-42 / 38-40 us against 48 (each run twice or
/// more, interleaved); the soft cube under its sphere, the creature and the plastic block took
/// as long with 0.5 or 1 as without; `bench`'s 16 bodies 0.92-1.04 -> 0.78-0.81 ms and its
/// 8640-tet box 0.39-0.40 -> 0.30-0.31 with 0.5 (one thread, three runs each). 0.5 leaves half of
/// each radius to the pass itself.
pub const CARRY_DRIFT: f32 = 0.5;

/// A one-ring pass goes on from an earlier step's bounds with up to one particle in this many
/// past [`CARRY_DRIFT`] (see [`ClampBounds::still_hold`]): in a body at rest under a load a few
/// particles move more than the rest from step to step (over the soft cube's first 8 s, 59 of
/// its 2 197 particles a step on average were past half their radius, and 119 of 899 one-ring
/// passes went on). The strays are checked as any particle that drifted (their blocks' largest
/// drift, or marked far past their radius), so the result is the same either way. Core alone,
/// one thread, six interleaved runs each (fastest to slowest): the soft cube from 8 s
/// 0.685-0.722 -> 0.664-0.702 ms a step, the plastic block from 5 s 0.486-0.511 -> 0.477-0.535;
/// under the cube's sphere (from 1.5 s) and the sphere on the bar from 4 s, the same within the
/// noise (three runs each). Bodies under 200 particles still wait for every one.
pub const CARRY_STRAYS: usize = 200;

impl ClampBounds {
    /// Whether the kept bounds still hold for a one-ring pass from `previews` (the tets'
    /// regions too if `need_tet_regions`): see [`CARRY_DRIFT`] and [`CARRY_STRAYS`]. A vertex
    /// without a positive radius, or a broken preview, asks for new bounds. Also how many
    /// particles are quiet (see [`ClampBounds::near_start`]).
    fn still_hold(&self, need_tet_regions: bool, previews: &[Point4]) -> (bool, usize) {
        if !self.kept || (need_tet_regions && !self.kept_tet_regions) {
            return (false, 0);
        }
        let (near, quiet) = self.near_start(previews);
        (self.always_carry || near, quiet)
    }

    /// Moves the bounds' start by the particles' mean drift from it (`previews` against
    /// `start`), so that drifts measure how the body changed its shape since the bounds were
    /// taken, not how far it went. A tet's volume does not change when all its particles move
    /// by the same vector, nor do its slack, gradients and edges, so every radius holds about
    /// the moved start as it did about the old one (any common move would do; the mean leaves
    /// the smallest drifts on the whole). A body falling, thrown or carried without changing
    /// its shape much then goes on from its bounds step after step instead of taking them
    /// afresh each time (see [`CARRY_DRIFT`]).
    fn follow_translation(&mut self, previews: &[Point4]) {
        if previews.is_empty() || previews.len() != self.start.len() {
            return;
        }
        let sum = previews
            .iter()
            .zip(&self.start)
            .fold(Vec3::ZERO, |sum, (p, &start)| sum + (p.vec3() - start));
        let shift = sum / previews.len() as f32;
        // A broken preview makes the shift NaN, and the start with it: `near_start` then asks
        // for new bounds, which set the start again.
        for start in &mut self.start {
            *start += shift;
        }
    }

    /// Whether the particles are within [`CARRY_DRIFT`] of their vertex radius of the bounds'
    /// start, all but at most one in [`CARRY_STRAYS`]; and, if they are, how many are within
    /// [`QUIET_DRIFT`] of it (zero if not).
    fn near_start(&self, previews: &[Point4]) -> (bool, usize) {
        let mut strays = previews.len() / CARRY_STRAYS;
        let mut quiet = 0;
        for ((p, &start), &radius) in previews.iter().zip(&self.start).zip(&self.vertex_radius) {
            let limit = CARRY_DRIFT * radius;
            let drift_squared = (p.vec3() - start).length_squared();
            let usable = limit > 0.0 && !drift_squared.is_nan();
            if !usable {
                return (false, 0);
            }
            if drift_squared > limit * limit {
                if strays == 0 {
                    return (false, 0);
                }
                strays -= 1;
            }
            let still = QUIET_DRIFT / CARRY_DRIFT * limit;
            quiet += (drift_squared <= still * still) as usize;
        }
        (true, quiet)
    }

    /// The arrays, for the jobs of a pass to fill and then read (see [`BoundsView`]).
    fn view(&mut self, regions: ClampRegions) -> BoundsView<'_> {
        BoundsView {
            active: self.active,
            ring_checks: false,
            regions,
            tet_radius: SharedSlice::new(&mut self.tet_radius),
            vertex_radius: SharedSlice::new(&mut self.vertex_radius),
            ring_region_radius: SharedSlice::new(&mut self.ring_region_radius),
            tet_region_radius: SharedSlice::new(&mut self.tet_region_radius),
            tet_shape: SharedSlice::new(&mut self.tet_shape),
            ring_check: SharedSlice::new(&mut self.ring_check),
            start: SharedSlice::new(&mut self.start),
        }
    }

    /// Sizes the arrays for passes over `mesh` in `blocks` tasks (allocates only the first
    /// time).
    fn reserve(&mut self, mesh: &TetMesh, blocks: usize, motion: &mut ClampMotion) {
        let (n, tets) = (mesh.vertex_count(), mesh.tet_count());
        for (array, len) in [
            (&mut self.tet_radius, tets),
            (&mut self.vertex_radius, n),
            (&mut self.ring_region_radius, n),
            (&mut self.tet_region_radius, tets),
            (&mut motion.drift, n),
            (&mut motion.move_len, n),
            (&mut motion.block_drift, blocks),
        ] {
            array.resize(len, 0.0);
        }
        self.tet_shape.resize(tets, TetShape::default());
        self.ring_check.resize(n, RingCheckBound::default());
        motion.walked.0.resize_with(tets, || AtomicU32::new(0));
        motion.far_nearby.0.resize_with(n, || AtomicU32::new(0));
        self.start.resize(n, Vec3::ZERO);
    }
}

/// [`ClampBounds`] during a pass: computed by the pass's first jobs, each writing its own
/// range of tets, vertices or regions, then only read.
#[derive(Clone, Copy)]
pub(crate) struct BoundsView<'a> {
    active: bool,
    /// Whether the rings' [`RingCheckBound`]s hold in this pass (a one-ring pass going on from
    /// earlier bounds).
    ring_checks: bool,
    /// The regions of the pass's impulses.
    regions: ClampRegions,
    tet_radius: SharedSlice<'a, f32>,
    vertex_radius: SharedSlice<'a, f32>,
    ring_region_radius: SharedSlice<'a, f32>,
    tet_region_radius: SharedSlice<'a, f32>,
    tet_shape: SharedSlice<'a, TetShape>,
    ring_check: SharedSlice<'a, RingCheckBound>,
    start: SharedSlice<'a, Vec3>,
}

/// Tets, vertices or regions per job of the clamp bounds' computation.
const BOUNDS_CHUNK: usize = 512;

impl BoundsView<'_> {
    /// The radius of `tets` at `previews` from their slack, gradient sum and reach, four tets
    /// at a time (see `lanes`).
    fn compute_tets(&self, mesh: &TetMesh, previews: SharedSlice<Point4>, tets: Range<usize>) {
        let (all, rest_volumes) = (mesh.tets(), mesh.rest_volumes());
        for start in tets.clone().step_by(LANES) {
            let n = LANES.min(tets.end - start);
            // Lanes past the tail repeat the last tet (computed, not stored).
            let corner = |k: usize| {
                previews.gather(std::array::from_fn(|l| {
                    all[start + l.min(n - 1)][k] as usize
                }))
            };
            let xd = corner(3);
            let e = [corner(0) - xd, corner(1) - xd, corner(2) - xd];
            let sixth = f32x4::splat(SIXTH);
            let ga = e[1].cross(e[2]).scale(sixth);
            let gb = e[2].cross(e[0]).scale(sixth);
            let gc = e[0].cross(e[1]).scale(sixth);
            let gd = -(ga + gb + gc);
            let volume = e[0].dot(ga);
            let grad = ga.length_squared().sqrt()
                + gb.length_squared().sqrt()
                + gc.length_squared().sqrt()
                + gd.length_squared().sqrt();
            let reach = e[0]
                .length_squared()
                .max(e[1].length_squared())
                .max(e[2].length_squared())
                .sqrt();
            let v0 = f32x4::new(std::array::from_fn(|l| rest_volumes[start + l.min(n - 1)]));
            let eps = f32x4::splat(CLAMP_FRACTION) * v0;
            // A tet below eps may lose half the slack over the pass, and must not get back
            // above eps within the bound either: above eps, the exact rule would hold it there.
            // One at eps, up to `CLAMP_ROUNDING` above it, counts as below (see `clamp_floor`).
            let at_eps = eps + f32x4::splat(CLAMP_ROUNDING) * v0;
            let below = (f32x4::splat(0.5 * CLAMP_SLACK) * v0).min(at_eps - volume);
            let slack = volume.cmp_ge(at_eps).blend(volume - eps, below);
            // A broken preview: no bound is safe; every region holding it walks.
            let radius = volume.is_finite().blend(
                safe_radius(slack, grad, reach),
                f32x4::splat(f32::NEG_INFINITY),
            );
            let radius = radius.to_array();
            for (l, &radius) in radius.iter().enumerate().take(n) {
                self.tet_radius.set(start + l, radius);
            }
        }
    }

    /// The smallest tet radius of each vertex's one-ring, for `vertices`; and their start of
    /// the pass (`previews`, zero `drift`). Needs every tet's radius.
    fn compute_vertices(
        &self,
        mesh: &TetMesh,
        previews: SharedSlice<Point4>,
        drift: SharedSlice<f32>,
        vertices: Range<usize>,
    ) {
        for v in vertices {
            self.vertex_radius
                .set(v, smallest(mesh.one_ring(v), self.tet_radius));
            self.start.set(v, previews.get(v).vec3());
            drift.set(v, 0.0);
        }
    }

    /// Each tet's [`TetShape`] at the bounds' start, for `tets`.
    #[inline(never)]
    fn compute_tet_shapes(&self, mesh: &TetMesh, tets: Range<usize>) {
        let (all, rest_volumes) = (mesh.tets(), mesh.rest_volumes());
        for t in tets {
            let x = all[t].map(|i| self.start.get(i as usize));
            let shape = TetShape {
                error: signed_volume(&x) - rest_volumes[t],
                grad: volume_gradients(&x).iter().map(|g| g.length()).sum(),
                reach: x[..3]
                    .iter()
                    .map(|&xi| (xi - x[3]).length_squared())
                    .fold(0.0f32, f32::max)
                    .sqrt(),
            };
            self.tet_shape.set(t, shape);
        }
    }

    /// Each vertex's [`RingCheckBound`], for `vertices`. Needs every tet's shape.
    #[inline(never)]
    fn compute_ring_checks(&self, mesh: &TetMesh, vertices: Range<usize>) {
        let rest_volumes = mesh.rest_volumes();
        for v in vertices {
            let ring = mesh.one_ring(v);
            let mut check = RingCheckBound {
                tets: ring.len() as f32,
                smallest_rest_volume: f32::INFINITY,
                ..Default::default()
            };
            for &t in ring {
                let shape = self.tet_shape.get(t as usize);
                let v0 = rest_volumes[t as usize];
                check.error += shape.error;
                check.grad_sum += shape.grad;
                check.reach_sum += shape.reach;
                // A broken (NaN) error stays: the ring is then never known.
                let relative = shape.error.abs() / v0;
                check.largest_relative_error =
                    larger_or_nan(check.largest_relative_error, relative);
                check.smallest_rest_volume = smaller(check.smallest_rest_volume, v0);
                check.largest_grad = larger(check.largest_grad, shape.grad);
                check.largest_reach = larger(check.largest_reach, shape.reach);
            }
            self.ring_check.set(v, check);
        }
    }

    /// The smallest vertex radius of each region of kind `regions` in `range`. A region is a
    /// union of one-rings: a ring's tets and border tets are the one-rings of its ring
    /// vertices, a tet and its neighbours the one-rings of its four vertices. Needs every
    /// vertex's radius.
    fn compute_regions(&self, mesh: &TetMesh, regions: ClampRegions, range: Range<usize>) {
        for r in range {
            let (vertices, radius): (&[u32], _) = match regions {
                ClampRegions::Rings => (mesh.ring_vertices(r), self.ring_region_radius),
                ClampRegions::Tets => (&mesh.tets()[r], self.tet_region_radius),
            };
            radius.set(r, smallest(vertices, self.vertex_radius));
        }
    }

    /// The radius of the pass's region `r`.
    #[inline]
    fn region_radius(&self, r: usize) -> f32 {
        match self.regions {
            ClampRegions::Rings => self.ring_region_radius.get(r),
            ClampRegions::Tets => self.tet_region_radius.get(r),
        }
    }

    /// For a pass that goes on from bounds taken earlier: the drift of the `vertices` of one
    /// block from their previews, and the largest of them but the far ones (see
    /// [`FAR_DRIFT`]), which are marked instead.
    fn carry_drift(
        &self,
        mesh: &TetMesh,
        previews: SharedSlice<Point4>,
        drift: SharedSlice<f32>,
        far: FarDrift,
        vertices: &[u32],
    ) -> f32 {
        let mut largest = 0.0f32;
        for &v in vertices {
            let v = v as usize;
            let d = (previews.get(v).vec3() - self.start.get(v)).length();
            drift.set(v, d);
            if self.is_far(v, d) {
                far.mark(mesh, v);
            } else {
                largest = larger(largest, d);
            }
        }
        largest
    }

    /// Whether `drift` of particle `i` is far (see [`FAR_DRIFT`]); a broken (NaN) one is.
    #[inline]
    fn is_far(&self, i: usize, drift: f32) -> bool {
        let limit = FAR_DRIFT * self.vertex_radius.get(i);
        drift > limit || drift.is_nan()
    }
}

/// The smallest of `values` at `items`: the radius of their union.
#[inline]
fn smallest(items: &[u32], values: SharedSlice<f32>) -> f32 {
    items
        .iter()
        .map(|&i| values.get(i as usize))
        .fold(f32::INFINITY, smaller)
}

/// What the clamp bounds track while a pass runs, per particle.
#[derive(Clone, Debug, Default)]
pub(crate) struct ClampMotion {
    /// Each particle's drift so far in the pass: the distance of its preview from
    /// [`ClampBounds`]' start.
    drift: Vec<f32>,
    /// During a clamp walk, the length of each particle's direction (zero for particles the
    /// impulse does not move), so the walk reads one number per vertex.
    move_len: Vec<f32>,
    /// For each tet, the number of the last clamp walk that looked at it past its radius (see
    /// [`PassView::clamp_unclear`]): one-rings of the walked vertices overlap, and a tet the
    /// radius does not clear is looked at once per walk.
    walked: PassMarks,
    /// The number of the last clamp walk (from 1), shared by the tasks of a pass.
    walks: WalkCount,
    /// For a pass that goes on from bounds taken earlier, the largest drift among each block's
    /// vertices at its start.
    block_drift: Vec<f32>,
    /// For each particle, the number of the last pass in which a particle within one edge of
    /// it (itself included) drifted far (see [`FAR_DRIFT`]).
    far_nearby: PassMarks,
    /// The number of the running pass with clamp bounds, for `far_nearby` (from 1).
    pass_number: u32,
}

/// A particle whose drift in a pass passes this fraction of its vertex radius (see
/// [`ClampBounds`]) drifts far: instead of raising the largest drift of its block, which every
/// impulse of the block and of the blocks after it is checked against, it marks the particles
/// within one edge of it, and impulses that move a marked particle go to the per-vertex checks
/// (which a particle past its own radius fails anyway).
///
/// In the soft cube the mean drift at the end of a one-ring pass is an eightieth of the mean
/// vertex radius, but a few particles a pass (1.5 past their radius, 15 past a quarter of it)
/// raised their blocks' largest drift past the radius of every region: 1 260 of 2 757 clamps
/// a step went to the per-vertex checks, 1 104 of them to be cleared there. With the marks,
/// 520 go and 390 are cleared; the step is 5 to 7 % shorter (cube, creature; 0.25, 0.6 and 1
/// tried: 1 is as fast as 0.6 and faster than 0.25, whose marks send more impulses to the
/// checks than the drifts they keep out of the bound).
const FAR_DRIFT: f32 = 1.0;

/// One number per particle or tet, the pass or walk that last marked it (see
/// [`ClampMotion::far_nearby`] and [`ClampMotion::walked`]), written by the tasks of a pass at
/// once (two tasks can mark the same one), hence atomic. A clone starts unmarked.
#[derive(Debug, Default)]
pub(crate) struct PassMarks(Vec<AtomicU32>);

impl Clone for PassMarks {
    fn clone(&self) -> PassMarks {
        PassMarks((0..self.0.len()).map(|_| AtomicU32::new(0)).collect())
    }
}

/// The number of the last clamp walk ([`ClampMotion::walks`]); a clone starts at zero, as its
/// marks do.
#[derive(Debug, Default)]
pub(crate) struct WalkCount(AtomicU32);

impl Clone for WalkCount {
    fn clone(&self) -> WalkCount {
        WalkCount::default()
    }
}

impl ClampMotion {
    /// Starts the marks of a new pass with clamp bounds.
    fn next_pass(&mut self) {
        if self.pass_number == u32::MAX {
            for mark in &self.far_nearby.0 {
                mark.store(0, Ordering::Relaxed);
            }
            self.pass_number = 0;
        }
        self.pass_number += 1;
        // A pass has fewer walks than impulses, far fewer than half the numbers: starting
        // again from zero between passes, no walk can find a mark a later walk left.
        if *self.walks.0.get_mut() > u32::MAX / 2 {
            for mark in &self.walked.0 {
                mark.store(0, Ordering::Relaxed);
            }
            *self.walks.0.get_mut() = 0;
        }
    }
}

/// Which tets the running clamp walk has looked at ([`ClampMotion::walked`]). Tasks that run
/// at the same time can walk the same tet (their clamp regions can touch), so the marks are
/// atomic; each walk has its own number, so a walk only skips a tet it marked itself.
#[derive(Clone, Copy)]
struct WalkMarks<'a> {
    walked: &'a [AtomicU32],
    walks: &'a AtomicU32,
}

impl WalkMarks<'_> {
    /// A number for a new walk, never used before in this pass or since the marks were clear.
    fn start(&self) -> u32 {
        self.walks.fetch_add(1, Ordering::Relaxed) + 1
    }

    /// Marks tet `t` for `walk`; whether it was unmarked.
    #[inline(always)]
    fn first_visit(&self, walk: u32, t: u32) -> bool {
        let mark = &self.walked[t as usize];
        if mark.load(Ordering::Relaxed) == walk {
            return false;
        }
        mark.store(walk, Ordering::Relaxed);
        true
    }
}

/// The particles near a far drift in the running pass (see [`FAR_DRIFT`]).
///
/// A task marks only particles within two edges of its blocks' vertices (within one edge of a
/// particle it moves) and reads the marks of particles within one edge of them: tasks that run
/// at the same time are at least four edges apart (see [`Blocks`](super::tet_mesh::Blocks)),
/// so a task reads only marks written by itself and by the tasks it waits for.
#[derive(Clone, Copy)]
struct FarDrift<'a> {
    marks: &'a [AtomicU32],
    pass: u32,
}

impl FarDrift<'_> {
    /// Marks the particles within one edge of particle `i`, which drifted far.
    fn mark(&self, mesh: &TetMesh, i: usize) {
        for &v in mesh.ring_vertices(i) {
            self.marks[v as usize].store(self.pass, Ordering::Relaxed);
        }
    }

    /// Whether a particle within one edge of any of `vertices` drifted far.
    #[inline]
    fn near(&self, vertices: &[u32]) -> bool {
        vertices.iter().any(|&v| self.marked(v as usize))
    }

    /// Whether a particle within one edge of particle `v` drifted far.
    #[inline]
    fn marked(&self, v: usize) -> bool {
        self.marks[v].load(Ordering::Relaxed) == self.pass
    }
}

/// What one block's task owns during a pass (see [`super::parallel`]): its working arrays, its
/// counters, and the velocity changes it gives the spheres, added to them after the pass in
/// block order so that the sum does not depend on which task finished first.
///
/// Aligned to two cache lines (the prefetcher pulls lines in pairs): the workers of tasks that
/// run at the same time are neighbours in one array, and each writes its counters and largest
/// drift with every impulse; sharing a line, two threads would take it from each other each
/// time (about 2 % of the two-thread step in the soft cube, within the noise of one run).
#[derive(Clone, Debug, Default)]
#[repr(align(128))]
pub(crate) struct PassWorker {
    ring_work: RingWork,
    counters: StepCounters,
    /// The largest drift of any particle this task reads: the largest of the tasks it waited
    /// for (the only ones that moved those particles before it), then its own moves (drifts can
    /// shrink again; this cannot).
    max_moved: f32,
    sphere_dv: Vec<Vec3>,
    /// The neighbour clamp's working list.
    clamp: ClampWork,
}

/// A task's working data for the neighbour clamp.
#[derive(Clone, Debug, Default)]
pub(crate) struct ClampWork {
    /// The vertices of the impulse being clamped whose one-rings the bounds could not clear:
    /// the clamp walks only their one-rings.
    /// Sized for the largest clamp region's vertices up front (a clone of a `Vec` with spare
    /// capacity has none, and the step must not allocate).
    unclear: Vec<u32>,
    /// How far each ring vertex of the vertex being walked can get from its start (its drift
    /// plus its own move), by the ring's local index; sized like `unclear`.
    reach: Vec<f32>,
}

impl PassWorker {
    /// A worker for passes over `mesh`.
    pub(crate) fn for_mesh(mesh: &TetMesh) -> PassWorker {
        PassWorker {
            ring_work: RingWork::for_mesh(mesh),
            clamp: ClampWork {
                unclear: vec![0; mesh.max_ring_vertices()],
                reach: vec![0.0; mesh.max_ring_vertices()],
            },
            ..Default::default()
        }
    }
}

/// `max(a, b)` as one instruction (`f32::max`'s NaN rules cost several in the hot gathers).
/// A NaN `b` is ignored; the bounds guard against broken previews through the slack instead.
#[inline(always)]
fn larger(a: f32, b: f32) -> f32 {
    if b > a { b } else { a }
}

/// `max(a, b)`, but NaN once either is: for bounds that a broken value must void.
#[inline(always)]
fn larger_or_nan(a: f32, b: f32) -> f32 {
    if b > a || b.is_nan() { b } else { a }
}

/// `min(a, b)` as one instruction; see [`larger`].
#[inline(always)]
fn smaller(a: f32, b: f32) -> f32 {
    if b < a { b } else { a }
}

/// Largest change of a tet's volume when each of its edge vectors (from its last vertex, of
/// length at most `l`) changes by at most `delta`.
#[inline]
fn volume_bound(delta: f32, l: f32) -> f32 {
    (3.0 * delta * l * l + 3.0 * delta * delta * l + delta * delta * delta) / 6.0
}

/// Largest change of a tet's volume when each of its particles moves by at most `m`, given the
/// sum `grad` of the lengths of its four volume gradients and its longest edge `l` from its last
/// vertex, both before the move.
///
/// The volume is a cubic in the moves: its first-order term is exactly `sum_i grad_i . dx_i`,
/// at most `m * grad`; the edge vectors change by at most `2 m`, so the second- and third-order
/// terms are at most those of [`volume_bound`]. Tighter than `volume_bound(2 m, l)` alone by a
/// factor of about two to three for well-shaped tets (`grad` is about `0.6 l^2` for them), which
/// lets that many more impulses skip the clamp walk.
/// Four tets at a time.
#[inline]
fn drift_bound(m: f32x4, grad: f32x4, l: f32x4) -> f32x4 {
    m * grad + f32x4::splat(2.0) * l * m * m + f32x4::splat(4.0 / 3.0) * m * m * m
}

/// A little less than the largest `m` with `drift_bound(m, grad, l) <= slack`, four tets at a
/// time: how far each particle of a tet with that slack, gradient sum and reach may move before
/// the tet can reach its floor. Negative infinity without slack (nothing is safe).
///
/// Each term of `drift_bound` alone reaches `slack` no earlier than the sum, so the smallest of
/// their roots is at or past the true one (for the cubic term a cruder point past it, to do
/// without a cube root: only a tet collapsed to a point needs it), and so is a Newton step from
/// there (the bound is convex); the bound is zero at zero, so scaling that point back by
/// `slack / drift_bound(point)` (a chord) lands at or before the root: a few operations
/// instead of solving the cubic, and within a tenth of it everywhere (tested). The margin
/// covers `f32` rounding.
#[inline]
fn safe_radius(slack: f32x4, grad: f32x4, l: f32x4) -> f32x4 {
    let (two, four) = (f32x4::splat(2.0), f32x4::splat(4.0));
    let cubic_past = (f32x4::splat(0.75) * slack).max(f32x4::ONE);
    let past = (slack / grad)
        .min((slack / (two * l)).sqrt())
        .min(cubic_past);
    let bound = |m: f32x4| drift_bound(m, grad, l);
    let slope = grad + four * l * past + four * past * past;
    let past = past - (bound(past) - slack).max(f32x4::ZERO) / slope;
    let chord = (slack / bound(past)).min(f32x4::ONE);
    let radius = past * chord * f32x4::splat(1.0 - 1e-4);
    slack
        .cmp_gt(f32x4::ZERO)
        .blend(radius, f32x4::splat(f32::NEG_INFINITY))
}

/// Working arrays of one ring impulse, sized for the mesh's largest one-ring so that steps do
/// not allocate: the ring's particles in the order of [`TetMesh::ring_vertices`], and its tets
/// four to an entry.
#[derive(Clone, Debug, Default)]
pub(crate) struct RingWork {
    previews: Vec<Point4>,
    inv_masses: Vec<f32>,
    /// The summed directions `D_i`.
    directions: Vec<Vec3>,
    tets: Vec<RingLanes>,
}

impl RingWork {
    /// Arrays for the largest one-ring of `mesh`.
    pub(crate) fn for_mesh(mesh: &TetMesh) -> RingWork {
        let n = mesh.max_ring_vertices();
        RingWork {
            previews: vec![Point4::default(); n],
            inv_masses: vec![0.0; n],
            directions: vec![Vec3::ZERO; n + 1],
            tets: vec![RingLanes::default(); mesh.max_one_ring().div_ceil(LANES)],
        }
    }
}

/// Corner `k` of four ring tets, from the ring's gathered `values` (padded, see
/// [`Vec3x4::gather_padded`]).
#[inline(always)]
fn gather(values: &[Vec3], corners: &[[u16; 4]; LANES], k: usize) -> Vec3x4 {
    Vec3x4::gather_padded(values, corners.map(|c| c[k] as usize))
}

/// [`gather`] for numbers.
#[inline(always)]
fn gather_f32(values: &[f32], corners: &[[u16; 4]; LANES], k: usize) -> [f32; LANES] {
    [
        values[corners[0][k] as usize],
        values[corners[1][k] as usize],
        values[corners[2][k] as usize],
        values[corners[3][k] as usize],
    ]
}

/// The edges `x_i - x_d` (i = a, b, c) of the ring's tets `4 group` to `4 group + 3` at the
/// ring's gathered `previews`, and their rest volumes. Lanes past the ring hold a tet collapsed
/// onto the centre: zero edges, volume and error. Every tet's last corner is the centre (see
/// `TetMesh::ring_corners`). A function always inlined rather than a closure: the compiler kept
/// the closure out of line when the code around the ring impulse grew, at a few percent of the
/// pass.
#[inline(always)]
fn ring_group_edges(
    previews: &[Point4],
    ring_v0: &[f32],
    corners: &[[u16; 4]],
    group: usize,
) -> ([Vec3x4; 3], f32x4) {
    let mut v0 = [0.0f32; LANES];
    let mut tet_corners = [[0u16; 4]; LANES];
    for l in 0..LANES {
        let j = LANES * group + l;
        if j < corners.len() {
            v0[l] = ring_v0[j];
            tet_corners[l] = corners[j];
        }
    }
    let x = |k: usize| Vec3x4::gather_points(previews, tet_corners.map(|c| c[k] as usize));
    let xd = Vec3x4::splat(previews[0].vec3());
    ([x(0) - xd, x(1) - xd, x(2) - xd], f32x4::new(v0))
}

/// A group's edges ([`ring_group_edges`]), gradients, volume and error, kept for what follows
/// the ring's check, and the group's rest volumes.
#[inline(always)]
fn ring_group_lanes(
    previews: &[Point4],
    ring_v0: &[f32],
    corners: &[[u16; 4]],
    group: usize,
) -> (RingLanes, f32x4) {
    let sixth = f32x4::splat(SIXTH);
    let (edges, v0) = ring_group_edges(previews, ring_v0, corners, group);
    let gradients = [
        edges[1].cross(edges[2]).scale(sixth),
        edges[2].cross(edges[0]).scale(sixth),
        edges[0].cross(edges[1]).scale(sixth),
    ];
    let volume = edges[0].dot(gradients[0]);
    let lanes = RingLanes {
        edges,
        gradients,
        volume,
        error: volume - v0,
    };
    (lanes, v0)
}

/// What a ring impulse knows of four tets of its ring at the current previews.
#[derive(Clone, Copy, Debug, Default)]
struct RingLanes {
    /// Edge vectors `x_i - x_d`, i = a, b, c.
    edges: [Vec3x4; 3],
    /// Volume gradients of a, b and c (d's is minus their sum).
    gradients: [Vec3x4; 3],
    volume: f32x4,
    /// The volume error `C_t`.
    error: f32x4,
}

/// What a volume pass does with one task's row of items (vertices or tet bundles; see
/// `SoftBodyState::run_blocks`), given the row's place in the flat list of items.
type BlockImpulses<'a> = dyn Fn(&PassView, &mut PassWorker, &[u32], usize) + Sync + 'a;

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
/// re-inflate it go on (PERFORMANCE.md, stop 33).
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

impl SoftBodyState {
    /// Stage 3: one impulse per vertex restoring the volume of its one-ring (section 5).
    /// Does nothing for the baseline or when the one-ring switch is off.
    /// `spheres` are the rigid spheres of the last contact pass, in the same order: particles
    /// pressed against one move it along.
    pub fn one_ring_pass(&mut self, h: f32, spheres: &mut [RigidSphereState]) {
        self.one_ring_pass_on(h, spheres, &Serial);
    }

    /// [`SoftBodyState::one_ring_pass`] with the mesh's blocks run by `parallel`: the same
    /// result bit for bit on any number of threads (see [`super::parallel`]).
    pub fn one_ring_pass_on(
        &mut self,
        h: f32,
        spheres: &mut [RigidSphereState],
        parallel: &dyn Parallel,
    ) {
        // A body stepped in substeps has its impulses in every substep (`shape_pass`).
        if !self.material.is_substepped() {
            self.one_ring_impulses(h, spheres, parallel);
        }
    }

    /// The one-ring pass over a step (or substep) of `h`.
    pub(crate) fn one_ring_impulses(
        &mut self,
        h: f32,
        spheres: &mut [RigidSphereState],
        parallel: &dyn Parallel,
    ) {
        let VolumeMethod::Impulses(settings) = self.material.method else {
            return;
        };
        if !settings.one_ring {
            return;
        }
        self.refresh_previews(h);
        let regions = settings.neighbour_clamp.then_some(ClampRegions::Rings);
        let mesh = self.mesh.clone();
        // The per-tet pass, if it runs, goes on from this pass's clamp bounds.
        self.clamp_bounds.keep_for_tets = settings.per_tet && settings.gamma != 0.0;
        self.run_blocks(
            h,
            spheres,
            parallel,
            regions,
            &mesh.blocks().vertices,
            &|view, worker, centres, _| {
                for &p in centres {
                    let known = view.bounds.ring_checks
                        && view.ring_known_within(worker, p as usize, &settings);
                    if !known {
                        view.ring_impulse(worker, p as usize, &settings);
                    }
                }
            },
        );
    }

    /// Stage 4: one impulse per tet towards its own rest volume, scaled by `gamma` (section 4,
    /// end of section 5). Does nothing for the baseline or when the per-tet switch is off.
    /// `spheres` as for [`SoftBodyState::one_ring_pass`].
    pub fn per_tet_pass(&mut self, h: f32, spheres: &mut [RigidSphereState]) {
        self.per_tet_pass_on(h, spheres, &Serial);
    }

    /// [`SoftBodyState::per_tet_pass`] with the mesh's blocks run by `parallel`, as
    /// [`SoftBodyState::one_ring_pass_on`].
    pub fn per_tet_pass_on(
        &mut self,
        h: f32,
        spheres: &mut [RigidSphereState],
        parallel: &dyn Parallel,
    ) {
        if !self.material.is_substepped() {
            self.per_tet_impulses(h, spheres, parallel);
        }
    }

    /// The per-tet pass over a step (or substep) of `h`.
    pub(crate) fn per_tet_impulses(
        &mut self,
        h: f32,
        spheres: &mut [RigidSphereState],
        parallel: &dyn Parallel,
    ) {
        let VolumeMethod::Impulses(settings) = self.material.method else {
            return;
        };
        if !settings.per_tet || settings.gamma == 0.0 {
            return;
        }
        self.refresh_previews(h);
        let regions = settings.neighbour_clamp.then_some(ClampRegions::Tets);
        let mesh = self.mesh.clone();
        self.run_blocks(
            h,
            spheres,
            parallel,
            regions,
            &mesh.blocks().tet_bundles,
            &|view, worker, bundles, first| {
                let blocks = mesh.blocks();
                for (k, bundle) in bundles.chunks(LANES).enumerate() {
                    let at = first + LANES * k..first + LANES * k + bundle.len();
                    let corners = &blocks.bundle_corners[at.clone()];
                    let rest = &blocks.bundle_rest_volumes[at];
                    view.tet_bundle(worker, bundle, corners, rest, &settings);
                }
            },
        );
    }

    /// Runs `impulse` on each task's row of `items` (the mesh's [`Blocks`]' vertices or tet
    /// bundles; with the row's place in the flat list of items), which it works through in
    /// order, with the result of running the tasks one after another (see
    /// [`super::parallel`]): the threads of `parallel` take tasks in order as they come free,
    /// each waiting for the earlier tasks it shares particles with. A thread only ever waits
    /// for tasks a running thread has already taken, so any number of threads, one included,
    /// finishes. Then adds up the tasks' counters and sphere velocity
    /// changes in task order.
    ///
    /// [`Blocks`]: super::tet_mesh::Blocks
    fn run_blocks(
        &mut self,
        h: f32,
        spheres: &mut [RigidSphereState],
        parallel: &dyn Parallel,
        clamp_regions: Option<ClampRegions>,
        items: &Csr,
        impulse: &BlockImpulses<'_>,
    ) {
        for worker in &mut self.pass_workers {
            worker.counters = StepCounters::default();
            worker.max_moved = 0.0;
            worker.sphere_dv.clear();
            worker.sphere_dv.resize(spheres.len(), Vec3::ZERO);
        }
        let clamp_regions = clamp_regions.filter(|_| !self.clamp_bounds.disabled);
        let take_tet_regions =
            clamp_regions == Some(ClampRegions::Tets) || self.clamp_bounds.keep_for_tets;
        self.clamp_bounds.keep_for_tets = false;
        // A per-tet pass after its step's one-ring pass goes on from the bounds that pass took
        // (they hold as long as drifts are measured from where they were taken): it only
        // measures each particle's drift again. Taking them costs about as much as the
        // per-tet pass's impulses in the soft cube. A one-ring pass goes on from an earlier
        // step's while the body has hardly moved since (see `CARRY_DRIFT`).
        // Whether the body is quiet (see `QUIET_DRIFT`), known only when a one-ring pass checks
        // whether it can go on from earlier bounds.
        let mut quiet_body = false;
        let carry = match clamp_regions {
            Some(ClampRegions::Tets) => self.clamp_bounds.taken_this_step,
            Some(ClampRegions::Rings) => {
                if self.clamp_bounds.kept {
                    self.clamp_bounds.follow_translation(&self.previews);
                }
                let (carry, quiet) = self
                    .clamp_bounds
                    .still_hold(take_tet_regions, &self.previews);
                quiet_body = quiet as f32 >= QUIET_SHARE * self.previews.len() as f32;
                carry
            }
            None => false,
        };
        // A one-ring pass going on from earlier bounds knows most rings of a body at rest to be
        // within their tolerances (see `RingCheckBound`); the first such pass computes what it
        // needs from the bounds' start, in the bounds' first two phases.
        let ring_checks = carry && clamp_regions == Some(ClampRegions::Rings) && quiet_body;
        let shapes = ring_checks && !self.clamp_bounds.ring_checks_ready;
        let blocks = self.mesh.blocks();
        if clamp_regions.is_some() {
            self.clamp_bounds
                .reserve(&self.mesh, blocks.count(), &mut self.clamp_motion);
            self.clamp_bounds.active = true;
            self.clamp_motion.next_pass();
        }
        {
            let mesh = &*self.mesh;
            let (inv_masses, contact_normals) = (&self.inv_masses[..], &self.contact_normals[..]);
            let (contact_kept, contact_sphere) = (&self.contact_kept[..], &self.contact_sphere[..]);
            let any_touching = !self.touching.is_empty();
            let mut bounds = self
                .clamp_bounds
                .view(clamp_regions.unwrap_or(ClampRegions::Rings));
            bounds.ring_checks = ring_checks;
            let velocities = SharedSlice::new(&mut self.velocities);
            let previews = SharedSlice::new(&mut self.previews);
            let scratch = SharedSlice::new(&mut self.scratch);
            let drift = SharedSlice::new(&mut self.clamp_motion.drift);
            let move_len = SharedSlice::new(&mut self.clamp_motion.move_len);
            let walks = WalkMarks {
                walked: &self.clamp_motion.walked.0,
                walks: &self.clamp_motion.walks.0,
            };
            let block_drift = SharedSlice::new(&mut self.clamp_motion.block_drift);
            let ring_corrected = SharedSlice::new(&mut self.ring_corrected);
            let far = FarDrift {
                marks: &self.clamp_motion.far_nearby.0,
                pass: self.clamp_motion.pass_number,
            };
            let workers = SharedSlice::new(&mut self.pass_workers);
            let waits_for = &mesh.blocks().waits_for;
            let count = items.len();
            // The clamp bounds are computed first, in chunks: the tets', then the vertices'
            // (which need all tets'), then the regions' (which need all vertices'): the rings'
            // for a one-ring pass, the tets' for a per-tet pass or to keep; threads that join
            // late (waking one takes longer than a chunk) find the work going. A pass going on
            // from bounds taken earlier only measures the drifts, block by block.
            let (n, tet_count) = (mesh.vertex_count(), mesh.tet_count());
            let fresh = clamp_regions.is_some() && !carry;
            let chunks = |items: usize| {
                if fresh {
                    items.div_ceil(BOUNDS_CHUNK)
                } else {
                    0
                }
            };
            let ring_chunks = match clamp_regions {
                Some(ClampRegions::Rings) => chunks(n),
                _ => 0,
            };
            let tet_chunks = if take_tet_regions {
                chunks(tet_count)
            } else {
                0
            };
            let chunk_phase = |tasks: usize| Phase { tasks, order: None };
            let shape_chunks = |items: usize| {
                if shapes {
                    items.div_ceil(BOUNDS_CHUNK)
                } else {
                    0
                }
            };
            let phases = [
                chunk_phase(chunks(tet_count) + shape_chunks(tet_count)),
                chunk_phase(chunks(n) + shape_chunks(n)),
                chunk_phase(if carry {
                    count
                } else {
                    ring_chunks + tet_chunks
                }),
                Phase {
                    tasks: count,
                    order: Some((waits_for, &self.block_done[..count])),
                },
            ];
            run_phases(parallel, &phases, &|phase, task| {
                let range =
                    |items: usize| BOUNDS_CHUNK * task..(BOUNDS_CHUNK * (task + 1)).min(items);
                match phase {
                    0 if shapes => bounds.compute_tet_shapes(mesh, range(tet_count)),
                    0 => bounds.compute_tets(mesh, previews, range(tet_count)),
                    1 if shapes => bounds.compute_ring_checks(mesh, range(n)),
                    1 => bounds.compute_vertices(mesh, previews, drift, range(n)),
                    2 if carry => {
                        let vertices = blocks.vertices.row(task);
                        let largest = bounds.carry_drift(mesh, previews, drift, far, vertices);
                        block_drift.set(task, largest);
                    }
                    2 => {
                        if task < ring_chunks {
                            bounds.compute_regions(mesh, ClampRegions::Rings, range(n));
                        } else {
                            let task = task - ring_chunks;
                            let range =
                                BOUNDS_CHUNK * task..(BOUNDS_CHUNK * (task + 1)).min(tet_count);
                            bounds.compute_regions(mesh, ClampRegions::Tets, range);
                        }
                    }
                    _ => {
                        let view = PassView {
                            mesh,
                            h,
                            inv_masses,
                            contact_normals,
                            contact_kept,
                            contact_sphere,
                            any_touching,
                            bounds,
                            velocities,
                            previews,
                            scratch,
                            drift,
                            move_len,
                            walks,
                            far,
                            ring_corrected,
                        };
                        // The particles this task reads were last moved by the tasks it
                        // waits for (done by now): their largest drift bounds those
                        // particles' drift; going on from earlier bounds, so does the largest
                        // drift at the start in this block and its neighbours (a block's
                        // impulses read no further).
                        let mut start_drift = 0.0f32;
                        if carry {
                            start_drift = block_drift.get(task);
                            for &near in blocks.neighbours.row(task) {
                                start_drift = larger(start_drift, block_drift.get(near as usize));
                            }
                        }
                        for &earlier in waits_for.row(task) {
                            // Safety: that task is done; nothing writes its worker now.
                            let moved = unsafe { workers.get_mut(earlier as usize) }.max_moved;
                            start_drift = larger(start_drift, moved);
                        }
                        // Safety: each task is run by one thread only.
                        let worker = unsafe { workers.get_mut(task) };
                        worker.max_moved = start_drift;
                        impulse(&view, worker, items.row(task), items.range(task).start);
                    }
                }
            });
        }
        self.clamp_bounds.active = false;
        let bounds = &mut self.clamp_bounds;
        match (clamp_regions, carry) {
            (Some(ClampRegions::Rings), false) => {
                bounds.taken_this_step = take_tet_regions;
                (bounds.kept, bounds.kept_tet_regions) = (true, take_tet_regions);
                bounds.ring_checks_ready = false;
            }
            (Some(ClampRegions::Rings), true) => {
                bounds.taken_this_step = bounds.kept_tet_regions;
                bounds.carried_passes = bounds.carried_passes.saturating_add(1);
                // Only a pass that computed the rings' checks makes them ready: a carried pass
                // in a body not quiet enough computes none, and the next quiet one must.
                bounds.ring_checks_ready |= shapes;
            }
            // Taken by a per-tet pass, without the rings' regions.
            (Some(ClampRegions::Tets), false) => {
                bounds.taken_this_step = true;
                bounds.kept = false;
                bounds.ring_checks_ready = false;
            }
            _ => {}
        }
        let c = &mut self.counters;
        for worker in &self.pass_workers {
            let w = &worker.counters;
            c.rings_corrected += w.rings_corrected;
            c.rings_without_root += w.rings_without_root;
            c.rings_clamped += w.rings_clamped;
            c.tets_without_root += w.tets_without_root;
            c.tets_clamped += w.tets_clamped;
            c.clamps_skipped += w.clamps_skipped;
            c.ring_checks_skipped += w.ring_checks_skipped;
            for (sphere, dv) in spheres.iter_mut().zip(&worker.sphere_dv) {
                sphere.velocity += *dv;
            }
        }
    }

    /// The one-ring impulse of vertex `p` alone, outside a pass (no clamp bounds). Needs
    /// `refresh_previews` first.
    #[cfg(test)]
    pub(crate) fn ring_impulse(
        &mut self,
        _mesh: &TetMesh,
        p: usize,
        h: f32,
        settings: &ImpulseSettings,
        spheres: &mut [RigidSphereState],
    ) -> ImpulseOutcome {
        let mut worker = PassWorker::for_mesh(&self.mesh);
        worker.sphere_dv.resize(spheres.len(), Vec3::ZERO);
        let outcome = self.single_view(h).ring_impulse(&mut worker, p, settings);
        self.finish_single(worker, spheres);
        outcome
    }

    /// The per-tet impulse of tet `t` alone, outside a pass (no clamp bounds). Needs
    /// `refresh_previews` first.
    #[cfg(test)]
    pub(crate) fn tet_impulse(
        &mut self,
        _mesh: &TetMesh,
        t: usize,
        h: f32,
        settings: &ImpulseSettings,
        spheres: &mut [RigidSphereState],
    ) -> ImpulseOutcome {
        let mut worker = PassWorker::for_mesh(&self.mesh);
        worker.sphere_dv.resize(spheres.len(), Vec3::ZERO);
        let (corners, rest) = (self.mesh.tets()[t], self.mesh.rest_volumes()[t]);
        let [outcome, ..] =
            self.single_view(h)
                .tet_bundle(&mut worker, &[t as u32], &[corners], &[rest], settings);
        self.finish_single(worker, spheres);
        outcome
    }

    #[cfg(test)]
    fn finish_single(&mut self, worker: PassWorker, spheres: &mut [RigidSphereState]) {
        self.counters = worker.counters;
        for (sphere, dv) in spheres.iter_mut().zip(&worker.sphere_dv) {
            sphere.velocity += *dv;
        }
    }

    #[cfg(test)]
    fn single_view(&mut self, h: f32) -> PassView<'_> {
        self.clamp_motion.drift.resize(self.previews.len(), 0.0);
        self.clamp_motion.move_len.resize(self.previews.len(), 0.0);
        let tets = self.mesh.tet_count();
        self.clamp_motion
            .walked
            .0
            .resize_with(tets, || AtomicU32::new(0));
        PassView {
            mesh: &self.mesh,
            h,
            inv_masses: &self.inv_masses,
            contact_normals: &self.contact_normals,
            contact_kept: &self.contact_kept,
            contact_sphere: &self.contact_sphere,
            any_touching: !self.touching.is_empty(),
            bounds: self.clamp_bounds.view(ClampRegions::Rings),
            velocities: SharedSlice::new(&mut self.velocities),
            previews: SharedSlice::new(&mut self.previews),
            scratch: SharedSlice::new(&mut self.scratch),
            drift: SharedSlice::new(&mut self.clamp_motion.drift),
            move_len: SharedSlice::new(&mut self.clamp_motion.move_len),
            walks: WalkMarks {
                walked: &self.clamp_motion.walked.0,
                walks: &self.clamp_motion.walks.0,
            },
            far: FarDrift {
                marks: &self.clamp_motion.far_nearby.0,
                pass: self.clamp_motion.pass_number,
            },
            ring_corrected: SharedSlice::new(&mut self.ring_corrected),
        }
    }
}

/// What the jobs of a pass share: the body's read-only data, and the arrays they write, each
/// element by one job at a time (see [`super::parallel`]).
pub(crate) struct PassView<'a> {
    mesh: &'a TetMesh,
    h: f32,
    inv_masses: &'a [f32],
    contact_normals: &'a [Vec3],
    contact_kept: &'a [f32],
    contact_sphere: &'a [u32],
    any_touching: bool,
    bounds: BoundsView<'a>,
    velocities: SharedSlice<'a, Vec3>,
    /// Previewed positions `x + h v`, kept up to date with every velocity change.
    previews: SharedSlice<'a, Point4>,
    /// Impulse directions by particle, for the clamp walk (zero outside a walk).
    scratch: SharedSlice<'a, Vec3>,
    drift: SharedSlice<'a, f32>,
    move_len: SharedSlice<'a, f32>,
    walks: WalkMarks<'a>,
    far: FarDrift<'a>,
    /// Per vertex, whether its ring was past its tolerance when last checked (see
    /// [`SoftBodyState::ring_corrected`]); read and written by that ring's impulse only.
    ring_corrected: SharedSlice<'a, bool>,
}

impl PassView<'_> {
    #[inline(always)]
    fn preview(&self, i: u32) -> Vec3 {
        self.previews.get(i as usize).vec3()
    }

    /// `d` with its push into what particle `i` touches reduced to the part the particle keeps:
    /// a volume impulse cannot move a particle into the ground at all, and moves a particle
    /// pressed against a heavy sphere only as far as the pair moves together. The cubic is then
    /// solved for the motion the particle can make, so the last contact pass does not undo it.
    #[inline]
    fn constrain_direction(&self, i: usize, d: Vec3) -> Vec3 {
        let n = self.contact_normals[i];
        let into = d.dot(n);
        if into < 0.0 {
            d - n * (into * (1.0 - self.contact_kept[i]))
        } else {
            d
        }
    }

    /// Adds `dv` to particle `i`'s velocity; if `i` is pressed against a sphere and `dv` pushes
    /// into it, the sphere moves along with the particle (the push was already reduced to the
    /// pair's share by `constrain_direction`), so momentum is conserved.
    #[inline(always)]
    fn apply_velocity_change(&self, worker: &mut PassWorker, i: usize, dv: Vec3) {
        self.velocities.set(i, self.velocities.get(i) + dv);
        let preview = self.previews.get(i).vec3() + self.h * dv;
        self.previews.set(i, Point4::new(preview));
        if self.bounds.active {
            let drift = (preview - self.bounds.start.get(i)).length();
            if !self.bounds.is_far(i, drift) {
                worker.max_moved = larger(worker.max_moved, drift);
            } else if !self.bounds.is_far(i, self.drift.get(i)) {
                self.far.mark(self.mesh, i);
            }
            self.drift.set(i, drift);
        }
        let k = self.contact_sphere[i];
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

    /// Whether the ring of `p`, within its tolerances when last checked, is known to be within
    /// them still because its particles have not drifted far enough since the bounds' start to
    /// leave them (see [`RingCheckBound`]): then its check, and its impulse, are skipped.
    /// Kept out of line: it runs only in a quiet body's passes (see [`QUIET_DRIFT`]), and the
    /// pass's loop around `ring_impulse` stays as small as it was without it.
    #[inline(never)]
    fn ring_known_within(
        &self,
        worker: &mut PassWorker,
        p: usize,
        settings: &ImpulseSettings,
    ) -> bool {
        if self.ring_corrected.get(p) {
            return false;
        }
        let bound = self.bounds.ring_check.get(p);
        let within = |drift: f32| {
            bound.within(
                drift,
                settings.tolerance,
                settings.ring_tet_tolerance,
                self.mesh.ring_rest_volume(p) as f32,
            )
        };
        // The largest drift the block can reach bounds the ring's unless one of its particles
        // drifted far (and then `p`, one edge from it, is marked): most rings of a quiet body
        // are known from it without reading their particles' drifts. The answer is the same
        // either way (`within` only grows stricter with the drift), so this only saves time.
        if !self.far.marked(p) && within(worker.max_moved) {
            worker.counters.ring_checks_skipped += 1;
            return true;
        }
        let drift = self
            .mesh
            .ring_vertices(p)
            .iter()
            .map(|&i| self.drift.get(i as usize))
            .fold(0.0f32, larger_or_nan);
        let known = within(drift);
        worker.counters.ring_checks_skipped += known as u32;
        known
    }

    /// The one-ring impulse of vertex `p`: every particle of the ring moves by `s * D_i`, where
    /// `D_i` sums the directions of the ring's tets that contain it, and `s` is the smallest
    /// positive root of `sum_t V_t(s) = sum_t V0_t`. Needs `refresh_previews` first.
    ///
    /// The ring's particles are gathered into [`RingWork`] first and its tets are computed four
    /// at a time in SIMD lanes ([`Vec3x4`]), each lane with the scalar code's operations in the
    /// scalar code's order; the polynomial is summed lane by lane, then over the lanes.
    fn ring_impulse(
        &self,
        worker: &mut PassWorker,
        p: usize,
        settings: &ImpulseSettings,
    ) -> ImpulseOutcome {
        let (tolerance, clamp) = (settings.tolerance, settings.neighbour_clamp);
        let mesh = self.mesh;
        let ring = mesh.one_ring(p);
        let corners = mesh.ring_corners(p);
        let vertices = mesh.ring_vertices(p);

        let work = &mut worker.ring_work;
        for (k, &i) in vertices.iter().enumerate() {
            work.previews[k] = self.previews.get(i as usize);
        }
        let groups = ring.len().div_ceil(LANES);
        let ring_v0 = mesh.ring_rest_volumes(p);
        let rest = mesh.ring_rest_volume(p);
        let sixth = f32x4::splat(SIXTH);
        // The check against the tolerances (see `ImpulseSettings::ring_tet_tolerance`); a
        // broken (NaN) volume is not within them. A ring found past them when last checked
        // (most of a moving body's, pass after pass) is computed in full at once; any other
        // (most of a resting body's) first from its tets' volumes alone, with nothing stored,
        // and again in full only if it is corrected after all. Both give the same numbers:
        // the volume is `ea . ga` with the gradient `ga = eb x ec / 6` either way.
        let mut tet_outside_tolerance = f32x4::ZERO;
        let mut ring_error = f32x4::ZERO;
        let ring_tet_tolerance = f32x4::splat(settings.ring_tet_tolerance);
        let computed = self.ring_corrected.get(p);
        if computed {
            for (group, lanes) in work.tets[..groups].iter_mut().enumerate() {
                let (full, v0) = ring_group_lanes(&work.previews, ring_v0, corners, group);
                *lanes = full;
                tet_outside_tolerance |= full.error.abs().cmp_gt(ring_tet_tolerance * v0);
                ring_error += full.error;
            }
        } else {
            for group in 0..groups {
                let (edges, v0) = ring_group_edges(&work.previews, ring_v0, corners, group);
                let error = edges[0].dot(edges[1].cross(edges[2]).scale(sixth)) - v0;
                tet_outside_tolerance |= error.abs().cmp_gt(ring_tet_tolerance * v0);
                ring_error += error;
            }
        }
        let ring_within = ring_error.reduce_add().abs() <= tolerance * rest as f32;
        let within = ring_within && !tet_outside_tolerance.any();
        self.ring_corrected.set(p, !within);
        if within {
            return ImpulseOutcome::Skipped;
        }
        if !computed {
            for (group, lanes) in work.tets[..groups].iter_mut().enumerate() {
                *lanes = ring_group_lanes(&work.previews, ring_v0, corners, group).0;
            }
        }
        for (k, &i) in vertices.iter().enumerate() {
            work.inv_masses[k] = self.inv_masses[i as usize];
            work.directions[k] = Vec3::ZERO;
        }
        // Each tet's directions `d_i = -w_i C_t grad_i`, summed per particle in ring order; the
        // stiffest tet sets the ring's step limit: `1 / max(stiffness)`, one division.
        let mut stiffest = f32x4::ZERO;
        let mut moves = f32x4::ZERO;
        // The centre is every tet's last corner: its direction is summed here, not in memory
        // (one add after another into the same element waited on each other's store).
        let mut centre = Vec3::ZERO;
        let centre_inv_mass = f32x4::splat(work.inv_masses[0]);
        for (group, lanes) in work.tets[..groups].iter().enumerate() {
            let tet_corners: [[u16; 4]; LANES] =
                std::array::from_fn(|l| corners.get(LANES * group + l).copied().unwrap_or([0; 4]));
            let [ga, gb, gc] = lanes.gradients;
            let g = [ga, gb, gc, -(ga + gb + gc)];
            let mut stiffness = f32x4::ZERO;
            let mut d = [Vec3x4::ZERO; 4];
            // Tets at their rest volume exactly (and unused lanes) take no part.
            let counts = lanes.error.cmp_ne(f32x4::ZERO);
            for k in 0..4 {
                let w = if k == 3 {
                    centre_inv_mass
                } else {
                    f32x4::new(gather_f32(&work.inv_masses, &tet_corners, k))
                };
                stiffness += w * g[k].length_squared();
                d[k] = g[k].scale(-w * lanes.error);
                let zero = f32x4::ZERO;
                moves |= counts & (d[k].x.cmp_ne(zero) | d[k].y.cmp_ne(zero) | d[k].z.cmp_ne(zero));
            }
            stiffest = stiffest.max(counts & stiffness);
            let errors = lanes.error.to_array();
            let d = d.map(Vec3x4::to_vecs);
            for l in 0..LANES {
                if errors[l] == 0.0 {
                    continue;
                }
                for k in 0..3 {
                    work.directions[tet_corners[l][k] as usize] += d[k][l];
                }
                centre += d[3][l];
            }
        }
        work.directions[0] = centre;
        let stiffest = stiffest.to_array().into_iter().fold(0.0f32, f32::max);
        let tet_step = 1.0 / stiffest as f64;
        if !moves.any() {
            return ImpulseOutcome::Skipped;
        }
        if self.any_touching {
            for (k, &i) in vertices.iter().enumerate() {
                work.directions[k] = self.constrain_direction(i as usize, work.directions[k]);
            }
        }
        // The ring's volume polynomial, summed in `f64` lane by lane over the ring's groups of
        // tets, then over the lanes (four short sums instead of one long chain of additions,
        // each waiting for the last).
        let mut sums = [[0.0f64; LANES]; 4];
        let sixth = 1.0 / 6.0;
        for (group, lanes) in work.tets[..groups].iter().enumerate() {
            let tet_corners: [[u16; 4]; LANES] =
                std::array::from_fn(|l| corners.get(LANES * group + l).copied().unwrap_or([0; 4]));
            let dir = |k: usize| gather(&work.directions, &tet_corners, k);
            let dd = Vec3x4::splat(work.directions[0]);
            let (fa, fb, fc) = (dir(0) - dd, dir(1) - dd, dir(2) - dd);
            let [c1, c2, c3] = volume_polynomial_lanes(lanes.edges, lanes.gradients, [fa, fb, fc]);
            // Unused lanes hold collapsed tets: zero volume and coefficients.
            for (sum, c) in sums.iter_mut().zip([lanes.volume, c1, c2, c3]) {
                for (s, c) in sum.iter_mut().zip(c.to_array()) {
                    *s += c as f64;
                }
            }
        }
        let total = |k: usize| sums[k].iter().sum::<f64>();
        let poly: Cubic = [
            total(0) - rest,
            total(1),
            total(2) * sixth,
            total(3) * sixth,
        ];
        let Some(root) = monotone_root(&poly) else {
            worker.counters.rings_without_root += 1;
            return ImpulseOutcome::NoRoot;
        };
        let limited = root.min(RING_STEP_LIMIT * tet_step);
        let mut step = limited;
        if clamp {
            let largest = work.directions[..vertices.len()]
                .iter()
                .map(|d| d.length_squared())
                .fold(0.0f32, larger);
            step = self.clamp(
                &mut worker.clamp,
                &mut worker.counters,
                worker.max_moved,
                p,
                vertices,
                &worker.ring_work.directions[..vertices.len()],
                largest.sqrt(),
                step,
                ring.iter().chain(mesh.ring_border_tets(p)),
            );
        }
        let clamped = step < limited;
        worker.counters.rings_corrected += 1;
        worker.counters.rings_clamped += clamped as u32;
        let scale = (step / self.h as f64) as f32;
        for (k, &i) in vertices.iter().enumerate() {
            let dv = scale * worker.ring_work.directions[k];
            self.apply_velocity_change(worker, i as usize, dv);
        }
        ImpulseOutcome::Applied {
            step,
            root,
            clamped,
        }
    }

    /// The per-tet impulses of a bundle of [`LANES`] tets that share no vertex (see
    /// [`Blocks::tet_bundles`]; [`NO_TET`] marks an empty lane), one after another: each tet's
    /// four particles move by `gamma * s * d_i`, `s` being the smallest positive root of
    /// `V_t(s) = V0_t`. `corners` and `rest_volumes` are the bundle's tets' (see
    /// [`Blocks::bundle_corners`]). Needs `refresh_previews` first.
    ///
    /// No impulse of the bundle moves a particle another of its tets reads, so the volumes,
    /// directions and cubics of all four are computed at once in SIMD lanes ([`Vec3x4`]) from
    /// the previews as they are before the first; only the roots, the clamps (whose regions
    /// overlap) and the velocity changes go lane by lane, in order.
    ///
    /// [`Blocks::tet_bundles`]: super::tet_mesh::Blocks::tet_bundles
    /// [`Blocks::bundle_corners`]: super::tet_mesh::Blocks::bundle_corners
    /// [`NO_TET`]: super::tet_mesh::NO_TET
    fn tet_bundle(
        &self,
        worker: &mut PassWorker,
        bundle: &[u32],
        corners: &[[u32; 4]],
        rest_volumes: &[f32],
        settings: &ImpulseSettings,
    ) -> [ImpulseOutcome; LANES] {
        let mut outcomes = [ImpulseOutcome::Skipped; LANES];
        let mesh = self.mesh;
        let (gamma, tolerance, clamp) = (
            settings.gamma as f64,
            settings.tolerance,
            settings.neighbour_clamp,
        );
        // An empty lane holds a tet collapsed onto particle 0 with no rest volume: no error.
        let tets: [[u32; 4]; LANES] =
            std::array::from_fn(|l| corners.get(l).copied().unwrap_or([0; 4]));
        let v0 = f32x4::new(std::array::from_fn(|l| {
            rest_volumes.get(l).copied().unwrap_or(0.0)
        }));
        let corner = |k: usize| self.previews.gather(tets.map(|t| t[k] as usize));
        let xd = corner(3);
        let (ea, eb, ec) = (corner(0) - xd, corner(1) - xd, corner(2) - xd);
        let sixth = f32x4::splat(SIXTH);
        // The signed volume, keeping the cross product that is also a's gradient.
        let ebc = eb.cross(ec);
        let volume = ea.dot(ebc) * sixth;
        let c = volume - v0;
        // A correction within tolerance (or a tet exactly at rest): no impulse (see
        // `ImpulseSettings::tolerance`). A broken (NaN) volume is not within tolerance; its
        // cubic has no root and it is counted.
        let correction = c.abs() * f32x4::splat(settings.gamma);
        let within = correction.cmp_le(f32x4::splat(tolerance) * v0);
        let act = (!within).move_mask();
        if act == 0 {
            return outcomes;
        }
        let ga = ebc.scale(sixth);
        let gb = ec.cross(ea).scale(sixth);
        let gc = ea.cross(eb).scale(sixth);
        let g = [ga, gb, gc, -(ga + gb + gc)];
        let mut d: [Vec3x4; 4] = std::array::from_fn(|k| {
            let w = f32x4::new(std::array::from_fn(|l| {
                self.inv_masses[tets[l][k] as usize]
            }));
            g[k].scale(-w * c)
        });
        if self.any_touching {
            // `constrain_direction` in lanes: a particle touching nothing has a zero normal.
            for (k, dk) in d.iter_mut().enumerate() {
                let normal = Vec3x4::from_vecs(std::array::from_fn(|l| {
                    self.contact_normals[tets[l][k] as usize]
                }));
                let kept = f32x4::new(std::array::from_fn(|l| {
                    self.contact_kept[tets[l][k] as usize]
                }));
                let into = dk.dot(normal).min(f32x4::ZERO);
                *dk = *dk - normal.scale(into * (f32x4::ONE - kept));
            }
        }
        let f = [d[0] - d[3], d[1] - d[3], d[2] - d[3]];
        let [c1, c2, c3] = volume_polynomial_lanes([ea, eb, ec], [ga, gb, gc], f);
        let (volume, v0) = (volume.to_array(), v0.to_array());
        let (c1, c2, c3) = (c1.to_array(), c2.to_array(), c3.to_array());
        let d = d.map(Vec3x4::to_vecs);
        for l in 0..LANES {
            if act & (1 << l) == 0 {
                continue;
            }
            let tet = tets[l];
            let dl: [Vec3; 4] = std::array::from_fn(|k| d[k][l]);
            if dl.iter().all(|&x| x == Vec3::ZERO) {
                continue;
            }
            let sixth = 1.0 / 6.0;
            let poly: Cubic = [
                volume[l] as f64 - v0[l] as f64,
                c1[l] as f64,
                c2[l] as f64 * sixth,
                c3[l] as f64 * sixth,
            ];
            let Some(root) = monotone_root(&poly) else {
                worker.counters.tets_without_root += 1;
                outcomes[l] = ImpulseOutcome::NoRoot;
                continue;
            };
            let full = gamma * root;
            let mut step = full;
            if clamp {
                let t = bundle[l];
                let largest = dl.iter().map(|x| x.length_squared()).fold(0.0f32, larger);
                step = self.clamp(
                    &mut worker.clamp,
                    &mut worker.counters,
                    worker.max_moved,
                    t as usize,
                    &tet,
                    &dl,
                    largest.sqrt(),
                    step,
                    std::iter::once(&t).chain(mesh.tet_neighbours(t as usize)),
                );
            }
            let clamped = step < full;
            worker.counters.tets_clamped += clamped as u32;
            let scale = (step / self.h as f64) as f32;
            for k in 0..4 {
                self.apply_velocity_change(worker, tet[k] as usize, scale * dl[k]);
            }
            outcomes[l] = ImpulseOutcome::Applied {
                step,
                root,
                clamped,
            };
        }
        outcomes
    }

    /// Volume polynomial of `tet` when its particles move from their previewed positions along
    /// the directions held in `scratch` (zero for particles that do not move).
    #[inline]
    fn moved_volume(&self, tet: [u32; 4]) -> Cubic {
        let xp = tet.map(|i| self.preview(i));
        let d = tet.map(|i| self.scratch.get(i as usize));
        volume_polynomial(&xp, &d)
    }

    /// The neighbour clamp of an impulse that moves `vertices` by `step` times `directions` (in
    /// the same order; `largest_move` the longest of them), whose clamp region `region` is
    /// `whole_region`: the step shortened so that no tet of the region falls below its floor.
    /// The [`ClampBounds`] answer first, with the largest drift seen in the pass, which costs
    /// nothing; if that is not enough, one vertex at a time; only the one-rings of the vertices
    /// that still are not clear are walked.
    #[allow(clippy::too_many_arguments)]
    fn clamp<'a>(
        &self,
        work: &mut ClampWork,
        counters: &mut StepCounters,
        max_moved: f32,
        region: usize,
        vertices: &[u32],
        directions: &[Vec3],
        largest_move: f32,
        step: f64,
        whole_region: impl Iterator<Item = &'a u32>,
    ) -> f64 {
        let b = self.bounds;
        // Particles that drifted far are not in `max_moved`: the impulse's own particles are
        // marked if one within an edge of them did.
        if b.active
            && max_moved + step as f32 * largest_move < b.region_radius(region)
            && !self.far.near(vertices)
        {
            counters.clamps_skipped += 1;
            return step;
        }
        // The walk reads directions by particle: lend them to `scratch` for it.
        for (&i, &d) in vertices.iter().zip(directions) {
            self.scratch.set(i as usize, d);
        }
        self.set_move_lengths(vertices, true);
        let clamped = if b.active {
            let unclear = self.find_unclear(vertices, step as f32, &mut work.unclear);
            if unclear.is_empty() {
                counters.clamps_skipped += 1;
                step
            } else {
                self.clamp_unclear(unclear, step, &mut work.reach)
            }
        } else {
            self.neighbour_clamp(whole_region, step)
        };
        self.set_move_lengths(vertices, false);
        self.clear_directions(vertices);
        clamped
    }

    /// The impulse `vertices` whose one-rings the bounds do not clear (written into `unclear`,
    /// which has room for all of them). Every tet the impulse touches is in the one-ring of one
    /// of `vertices`, and its particles are ring vertices of that vertex; each of those is at
    /// most its drift plus its own move from where it was at the start of the pass, so a
    /// one-ring whose vertex bounds allow the largest such distance among its ring vertices is
    /// safe. Needs `set_move_lengths`.
    fn find_unclear<'u>(&self, vertices: &[u32], step: f32, unclear: &'u mut [u32]) -> &'u [u32] {
        let (b, mesh) = (self.bounds, self.mesh);
        let mut count = 0;
        for &v in vertices {
            let reach = mesh
                .ring_vertices(v as usize)
                .iter()
                .map(|&i| self.drift.get(i as usize) + step * self.move_len.get(i as usize))
                .fold(0.0f32, larger);
            let v = v as usize;
            // A broken (NaN) preview clears nothing.
            if reach >= b.vertex_radius.get(v) || reach.is_nan() {
                unclear[count] = v as u32;
                count += 1;
            }
        }
        &unclear[..count]
    }

    /// The neighbour clamp over the one-rings of the `unclear` vertices of
    /// [`PassView::find_unclear`], each tet once (the one-rings overlap; see [`WalkMarks`]).
    ///
    /// Each tet is first held against its radius with the reach of its four particles, taken
    /// from the ring's reaches (`reach`, one per ring vertex, computed once per vertex): the
    /// same test `neighbour_clamp` starts with, but on data gathered for the ring instead of
    /// from the body's arrays through each tet's vertex indices, and before the tet is marked
    /// walked. Most tets of a walk pass it (nine in ten under the cube's sphere). The reaches
    /// are taken with the step as it was when the vertex's walk began; a shorter step only
    /// shortens them, and `neighbour_clamp` tests again with the current one, so the tets that
    /// reach the cubics, and the result, are those of walking every tet.
    fn clamp_unclear(&self, unclear: &[u32], mut step: f64, reach: &mut [f32]) -> f64 {
        let (mesh, b) = (self.mesh, self.bounds);
        let walk = self.walks.start();
        for &v in unclear {
            let v = v as usize;
            let along = step as f32;
            for (r, &i) in reach.iter_mut().zip(mesh.ring_vertices(v)) {
                let i = i as usize;
                *r = self.drift.get(i) + along * self.move_len.get(i);
            }
            for (&t, corners) in mesh.one_ring(v).iter().zip(mesh.ring_corners(v)) {
                let tet_reach = corners
                    .iter()
                    .map(|&k| reach[k as usize])
                    .fold(0.0f32, larger);
                if tet_reach < b.tet_radius.get(t as usize) || !self.walks.first_visit(walk, t) {
                    continue;
                }
                step = self.neighbour_clamp(std::iter::once(&t), step);
                if step == 0.0 {
                    return step;
                }
            }
        }
        step
    }

    /// The neighbour clamp: the largest `s' <= step` such that every tet in `tets` keeps at
    /// least `eps = V0 / 2` (or, if it is already below, its current volume less
    /// [`CLAMP_SLACK`] of its rest volume) for every step in
    /// `[0, s']` along the directions in `scratch`. A bound on each tet's volume change from
    /// its own longest direction skips tets that cannot come near their floor without solving
    /// their cubic.
    fn neighbour_clamp<'a>(&self, tets: impl Iterator<Item = &'a u32>, mut step: f64) -> f64 {
        let mesh = self.mesh;
        let b = self.bounds;
        for &t in tets {
            let tet = mesh.tets()[t as usize];
            // This tet alone, against its own start-of-pass bounds (see [`ClampBounds`]), with
            // how far each of its own four particles can get from its start: most tets of a
            // walk are cleared here (nine in ten under the cube's sphere), so this comes first.
            if b.active {
                let t = t as usize;
                let reach = tet
                    .iter()
                    .map(|&i| {
                        self.drift.get(i as usize) + step as f32 * self.move_len.get(i as usize)
                    })
                    .fold(0.0f32, larger);
                if reach < b.tet_radius.get(t) {
                    continue;
                }
            }
            let max_move = if b.active {
                tet.iter()
                    .map(|&i| self.move_len.get(i as usize))
                    .fold(0.0f32, larger)
            } else {
                tet.iter()
                    .map(|&i| self.scratch.get(i as usize).length_squared())
                    .fold(0.0f32, larger)
                    .sqrt()
            };
            if max_move == 0.0 {
                continue;
            }
            let xp = tet.map(|i| self.preview(i));
            let v0 = mesh.rest_volumes()[t as usize];
            let volume = signed_volume(&xp);
            let floor = clamp_floor(volume, v0);
            // Each edge vector from vertex d changes by at most 2 * delta; bound the change of
            // the determinant from that, and skip the cubic when the floor is out of reach.
            let delta = 2.0 * step as f32 * max_move;
            let l = (xp[0] - xp[3])
                .length()
                .max((xp[1] - xp[3]).length())
                .max((xp[2] - xp[3]).length());
            let bound = volume_bound(delta, l);
            if volume - bound > floor {
                continue;
            }
            let mut c = self.moved_volume(tet);
            if c[1] == 0.0 && c[2] == 0.0 && c[3] == 0.0 {
                continue;
            }
            // Measured from the volume its floor was chosen from (the cubic's own constant
            // term rounds differently); a tet at its floor may sit a rounding error below it:
            // start it exactly there.
            c[0] = (volume as f64 - floor as f64).max(0.0);
            // The cubic's own bound over `[0, step]`: most tets the cheaper bounds above could
            // not clear are still far from their floor along this impulse (in the soft cube,
            // one in a hundred and fifty of the cubics solved here shortened the step), and the
            // root search costs many times this.
            if clear_of_zero(&c, step) {
                continue;
            }
            if let Some(s) = first_crossing(&c, step) {
                step = s;
                if step == 0.0 {
                    break;
                }
            }
        }
        step
    }

    /// Records (`set`) or clears the lengths of the directions of `vertices` for a clamp walk.
    fn set_move_lengths(&self, vertices: &[u32], set: bool) {
        if !self.bounds.active {
            return;
        }
        for &i in vertices {
            let i = i as usize;
            let len = if set {
                self.scratch.get(i).length()
            } else {
                0.0
            };
            self.move_len.set(i, len);
        }
    }

    fn clear_directions(&self, vertices: &[u32]) {
        for &i in vertices {
            self.scratch.set(i as usize, Vec3::ZERO);
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use std::sync::Arc;

    use glam::{UVec3, Vec3};

    use super::*;
    use crate::core::geometry::volume_gradients;
    use crate::core::grid::box_grid;
    use crate::core::material::SoftBodyMaterial;

    const H: f32 = 0.01;

    /// Settings with every impulse applied, however small its tet's error.
    fn exact(gamma: f32, neighbour_clamp: bool) -> ImpulseSettings {
        ImpulseSettings {
            gamma,
            neighbour_clamp,
            tolerance: 0.0,
            ring_tet_tolerance: 0.0,
            ..ImpulseSettings::PAPER
        }
    }

    /// A small cube with a deterministic jumble of velocities: strong enough that previewed
    /// tets are far from their rest volume, some below half of it.
    pub(crate) fn shaken_body(strength: f32) -> SoftBodyState {
        let mesh = Arc::new(box_grid(UVec3::splat(4), Vec3::splat(0.1), Vec3::ZERO).unwrap());
        let material = SoftBodyMaterial::paper(1000.0, 1.0, 1.0);
        let mut body = SoftBodyState::new(mesh, material).unwrap();
        let mut seed = 12345u64;
        for v in body.velocities_mut() {
            let mut next = || {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((seed >> 40) as f32) / ((1u64 << 24) as f32) * 2.0 - 1.0
            };
            *v = Vec3::new(next(), next(), next()) * strength;
        }
        body.refresh_previews(H);
        body
    }

    /// Switches `body` to the paper's method with `settings`.
    fn use_impulses(body: &mut SoftBodyState, settings: ImpulseSettings) {
        let mut material = *body.material();
        material.method = VolumeMethod::Impulses(settings);
        body.set_material(material).unwrap();
    }

    fn previewed_volume(body: &SoftBodyState, t: usize) -> f32 {
        signed_volume(&body.mesh.tets()[t].map(|i| body.preview(i)))
    }

    #[test]
    fn every_impulse_conserves_momentum() {
        let mut body = shaken_body(3.0);
        let mut applied = 0;
        for p in 0..body.positions.len() {
            let before = body.linear_momentum();
            let outcome = body.ring_impulse(&body.mesh.clone(), p, H, &exact(0.125, true), &mut []);
            let after = body.linear_momentum();
            if let ImpulseOutcome::Applied { .. } = outcome {
                applied += 1;
            }
            assert!(
                (after - before).length() < 1e-4,
                "ring {p}: {before} -> {after}"
            );
        }
        for t in 0..body.mesh.tet_count() {
            let before = body.linear_momentum();
            body.tet_impulse(&body.mesh.clone(), t, H, &exact(0.125, true), &mut []);
            let after = body.linear_momentum();
            assert!(
                (after - before).length() < 1e-4,
                "tet {t}: {before} -> {after}"
            );
        }
        assert!(applied > 50, "only {applied} ring impulses were applied");
        // The scratch directions are left clean.
        assert!(body.scratch.iter().all(|&d| d == Vec3::ZERO));
    }

    #[test]
    fn ring_impulse_restores_the_ring_volume() {
        let mut body = shaken_body(1.0);
        let mut checked = 0;
        let mut limited = 0;
        for p in 0..body.positions.len() {
            let ring: Vec<u32> = body.mesh.one_ring(p).to_vec();
            let rest: f32 = ring
                .iter()
                .map(|&t| body.mesh.rest_volumes()[t as usize])
                .sum();
            if let ImpulseOutcome::Applied { step, root, .. } =
                body.ring_impulse(&body.mesh.clone(), p, H, &exact(0.125, false), &mut [])
            {
                if step < root {
                    limited += 1;
                    continue;
                }
                let now: f32 = ring
                    .iter()
                    .map(|&t| previewed_volume(&body, t as usize))
                    .sum();
                assert!(
                    (now - rest).abs() < 1e-4 * rest,
                    "ring {p}: {now} vs {rest}"
                );
                checked += 1;
            }
        }
        assert!(checked > 50, "{checked} rings restored, {limited} limited");
    }

    #[test]
    fn tet_impulse_with_gamma_one_restores_the_tet_volume() {
        let mut body = shaken_body(1.0);
        for t in 0..body.mesh.tet_count() {
            if let ImpulseOutcome::Applied { .. } =
                body.tet_impulse(&body.mesh.clone(), t, H, &exact(1.0, false), &mut [])
            {
                // gamma = 1 applies the whole root.
                let v0 = body.mesh.rest_volumes()[t];
                let v = previewed_volume(&body, t);
                assert!((v - v0).abs() < 1e-3 * v0, "tet {t}: {v} vs {v0}");
            }
        }
    }

    #[test]
    fn clamp_keeps_touched_tets_at_or_above_half_their_rest_volume() {
        let mut body = shaken_body(6.0);
        let tets = body.mesh.tet_count();
        let mut clamped = 0;
        let mut below_at_start = 0;
        for p in 0..body.positions.len() {
            let before: Vec<f32> = (0..tets).map(|t| previewed_volume(&body, t)).collect();
            if let ImpulseOutcome::Applied { clamped: c, .. } =
                body.ring_impulse(&body.mesh.clone(), p, H, &exact(0.125, true), &mut [])
            {
                clamped += c as usize;
            }
            for (t, &before_t) in before.iter().enumerate() {
                let v0 = body.mesh.rest_volumes()[t];
                // `eps`, or for a tet below it (or at it by rounding) its volume less the slack.
                let floor = clamp_floor(before_t, v0);
                below_at_start += (floor < CLAMP_FRACTION * v0) as usize;
                let after = previewed_volume(&body, t);
                assert!(
                    after >= floor - 1e-4 * v0,
                    "ring {p}, tet {t}: {before_t} -> {after} (floor {floor})"
                );
            }
        }
        for t in 0..tets {
            let before: Vec<f32> = (0..tets).map(|u| previewed_volume(&body, u)).collect();
            body.tet_impulse(&body.mesh.clone(), t, H, &exact(0.125, true), &mut []);
            for (u, &before_u) in before.iter().enumerate() {
                let v0 = body.mesh.rest_volumes()[u];
                let floor = clamp_floor(before_u, v0);
                let after = previewed_volume(&body, u);
                assert!(
                    after >= floor - 1e-4 * v0,
                    "tet {t}, neighbour {u}: {before_u} -> {after} (floor {floor})"
                );
            }
        }
        // The scenario must exercise the clamp, or this test proves nothing.
        assert!(clamped > 0, "no ring impulse was clamped");
        assert!(below_at_start > 0, "no tet started below its floor");
    }

    #[test]
    fn passes_keep_every_tet_above_its_floor_with_the_fast_clamp() {
        // Gentle enough that the pass bounds skip most clamps, strong enough that some do not.
        for strength in [0.05, 0.5, 4.0] {
            let mut body = shaken_body(strength);
            body.begin_step();
            let above = |body: &SoftBodyState| -> Vec<bool> {
                (0..body.mesh.tet_count())
                    .map(|t| {
                        previewed_volume(body, t) >= CLAMP_FRACTION * body.mesh.rest_volumes()[t]
                    })
                    .collect()
            };
            let check = |body: &SoftBodyState, was_above: &[bool], pass: &str| {
                for (t, &was) in was_above.iter().enumerate() {
                    let v0 = body.mesh.rest_volumes()[t];
                    let v = previewed_volume(body, t);
                    assert!(
                        !was || v >= CLAMP_FRACTION * v0 - 1e-4 * v0,
                        "strength {strength}, {pass} pass: tet {t} fell to {v} below V0/2 = {}",
                        CLAMP_FRACTION * v0
                    );
                }
            };
            let before = above(&body);
            body.one_ring_pass(H, &mut []);
            check(&body, &before, "ring");
            let before = above(&body);
            body.per_tet_pass(H, &mut []);
            check(&body, &before, "per-tet");
            let c = body.counters();
            if strength < 0.1 {
                assert!(c.clamps_skipped > 0, "the fast path was never taken: {c:?}");
            }
            if strength > 1.0 {
                assert!(
                    c.rings_clamped + c.tets_clamped > 0,
                    "the slow path never clamped: {c:?}"
                );
            }
        }
    }

    /// The bounds the clamp shortcuts rely on hold for arbitrary tets, including flat and
    /// inverted ones, and moves up to and beyond the tet's size.
    #[test]
    fn drift_bound_bounds_every_volume_change() {
        let mut seed = 99u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 40) as f32) / ((1u64 << 24) as f32) * 2.0 - 1.0
        };
        let mut tightest = 0.0f32;
        for case in 0..20_000 {
            let scale = [0.01, 1.0, 30.0][case % 3];
            let xp: [Vec3; 4] = std::array::from_fn(|_| Vec3::new(next(), next(), next()) * scale);
            let m = scale * [0.001, 0.05, 0.5, 2.0][case % 4] * next().abs();
            let g = volume_gradients(&xp);
            // Every other case moves each particle its full `m` along its gradient (the worst
            // case to first order), the others in random directions by random amounts.
            let sign = next().signum();
            let moved: [Vec3; 4] = std::array::from_fn(|k| {
                if case % 2 == 0 {
                    xp[k] + g[k].normalize_or_zero() * m * sign
                } else {
                    let dir = Vec3::new(next(), next(), next()).normalize_or_zero();
                    xp[k] + dir * m * next().abs()
                }
            });
            let grad: f32 = g.iter().map(|g| g.length()).sum();
            let reach = (0..3).map(|k| (xp[k] - xp[3]).length()).fold(0.0, f32::max);
            let change = (signed_volume(&moved) - signed_volume(&xp)).abs();
            let [bound, ..] =
                drift_bound(f32x4::splat(m), f32x4::splat(grad), f32x4::splat(reach)).to_array();
            // f32 rounding of the two volumes, relative to the tet's own size.
            let rounding = 1e-5 * (reach + m).powi(3);
            assert!(
                change <= bound + rounding,
                "case {case}: change {change} > bound {bound}"
            );
            assert!(bound <= volume_bound(2.0 * m, reach) * 1.0001 + rounding);
            if bound > 0.0 {
                tightest = tightest.max(change / bound);
            }
        }
        // The bound is not vacuous: moves along the gradients reach it to first order.
        assert!(tightest > 0.9, "tightest ratio {tightest}");
    }

    /// A safe radius keeps `drift_bound` within the slack, and gives away little of it.
    #[test]
    fn safe_radius_is_within_the_slack_and_close_to_it() {
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 40) as f64) / ((1u64 << 24) as f64)
        };
        let mut loosest = 1.0f64;
        for case in 0..20_000 {
            let l = 10f64.powf(4.0 * next() - 3.0);
            // Gradient sums from flat to regular tets, slacks from a sliver to a whole tet.
            let grad = l * l * [0.0, 0.01, 0.6, 2.0][case % 4] * next();
            let slack = l * l * l * 10f64.powf(-6.0 * next());
            let radius = safe_radius(
                f32x4::splat(slack as f32),
                f32x4::splat(grad as f32),
                f32x4::splat(l as f32),
            )
            .to_array()[0] as f64;
            let f = |m: f64| m * grad + 2.0 * l * m * m + 4.0 / 3.0 * m * m * m;
            assert!(f(radius) <= slack, "case {case}: {} > {slack}", f(radius));
            let (mut lo, mut hi) = (0.0, l + slack / grad.max(1e-30));
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if f(mid) <= slack { lo = mid } else { hi = mid }
            }
            loosest = loosest.min(radius / lo);
        }
        assert!(
            loosest > 0.9,
            "a radius of {loosest} of the largest safe one"
        );
        for slack in [0.0, -1.0, f32::NAN, f32::NEG_INFINITY] {
            let one = f32x4::ONE;
            let radius = safe_radius(f32x4::splat(slack), one, one).to_array()[0];
            assert_eq!(radius, f32::NEG_INFINITY, "slack {slack}");
        }
    }

    /// A step's one-ring and per-tet passes with every `every`-th particle pushed between them
    /// by `strength`: the per-tet pass goes on from the ring pass's bounds, so velocities
    /// changed in between must count in its drifts.
    fn passes_with_a_push_between(body: &mut SoftBodyState, every: usize, strength: f32) {
        body.begin_step();
        body.one_ring_pass(H, &mut []);
        for v in body.velocities.iter_mut().step_by(every) {
            *v += Vec3::new(0.3, -1.0, 0.2) * strength;
        }
        body.per_tet_pass(H, &mut []);
    }

    /// Whether a ring was past its tolerance when last checked only decides how its next
    /// check is computed: guessing every ring past it, or none, gives the same passes bit for
    /// bit, over several passes (where the guesses are then the rings' own).
    #[test]
    fn the_guess_of_which_rings_are_corrected_changes_nothing() {
        for strength in [0.05, 0.5, 4.0] {
            let mut none = shaken_body(strength);
            let mut all = shaken_body(strength);
            all.ring_corrected.fill(true);
            for body in [&mut none, &mut all] {
                for _ in 0..3 {
                    passes_with_a_push_between(body, 7, strength);
                }
            }
            assert_eq!(none.velocities, all.velocities, "strength {strength}");
            assert_eq!(none.ring_corrected, all.ring_corrected);
            let corrected = none.ring_corrected.iter().filter(|&&c| c).count();
            assert!(corrected > 0 && corrected < none.ring_corrected.len());
        }
    }

    #[test]
    fn the_clamp_shortcut_changes_nothing() {
        for strength in [0.05, 0.5, 4.0] {
            let mut fast = shaken_body(strength);
            let mut exact = shaken_body(strength);
            exact.clamp_bounds.disabled = true;
            for body in [&mut fast, &mut exact] {
                passes_with_a_push_between(body, 7, strength);
            }
            assert_eq!(fast.velocities, exact.velocities, "strength {strength}");
            assert_eq!(exact.counters().clamps_skipped, 0);
            if strength < 0.1 {
                assert!(fast.counters().clamps_skipped > 0);
            }
        }
    }

    /// The per-tet pass goes on from the clamp bounds its step's one-ring pass took: with
    /// velocities changed in between, and impulses big enough (`gamma = 1`) to be clamped, it
    /// still clamps exactly as the walk without bounds does.
    #[test]
    fn the_per_tet_pass_going_on_from_the_ring_passs_bounds_changes_nothing() {
        let mut clamped = 0;
        for strength in [0.3, 3.0, 4.0, 6.0] {
            let mut fast = shaken_body(strength);
            use_impulses(
                &mut fast,
                ImpulseSettings {
                    gamma: 1.0,
                    ..ImpulseSettings::PAPER
                },
            );
            let mut exact = fast.clone();
            exact.clamp_bounds.disabled = true;
            for body in [&mut fast, &mut exact] {
                passes_with_a_push_between(body, 5, strength);
            }
            assert_eq!(fast.velocities, exact.velocities, "strength {strength}");
            if strength < 1.0 {
                assert!(
                    fast.counters().clamps_skipped > 0,
                    "the bounds were never used"
                );
            }
            clamped += exact.counters().tets_clamped;
        }
        assert!(clamped > 0, "no per-tet impulse was clamped");
    }

    /// A one-ring pass may go on from an earlier step's bounds (see `CARRY_DRIFT`): made to
    /// do so every step, however far the particles have moved, over steps of bodies shaken
    /// gently and hard with pushes now and then, the passes clamp exactly as the walk without
    /// bounds does; and by the rule, a body shaken gently goes on from earlier bounds, one
    /// shaken hard takes new ones.
    #[test]
    fn one_ring_passes_going_on_from_earlier_steps_bounds_change_nothing() {
        let (mut carried, mut clamped) = (0, 0);
        for strength in [0.02, 0.2, 2.0, 6.0] {
            let mut fast = shaken_body(strength);
            let mut exact = fast.clone();
            let mut by_rule = fast.clone();
            fast.clamp_bounds.always_carry = true;
            exact.clamp_bounds.disabled = true;
            for step in 0..8 {
                for body in [&mut fast, &mut exact, &mut by_rule] {
                    body.begin_step();
                    body.one_ring_pass(H, &mut []);
                    body.per_tet_pass(H, &mut []);
                    body.integrate_positions(H);
                    if step % 4 == 3 {
                        for v in body.velocities.iter_mut().step_by(5) {
                            *v += Vec3::new(0.3, -1.0, 0.2) * strength;
                        }
                    }
                }
                for body in [&fast, &by_rule] {
                    assert_eq!(body.velocities, exact.velocities, "{strength}, step {step}");
                    assert_eq!(body.positions, exact.positions, "{strength}, step {step}");
                }
                clamped += exact.counters().rings_clamped + exact.counters().tets_clamped;
            }
            carried += fast.clamp_bounds.carried_passes;
            let by_rule = by_rule.clamp_bounds.carried_passes;
            if strength < 0.1 {
                assert!(by_rule > 0, "{strength}: a gentle body never went on");
            } else if strength > 1.0 {
                assert!(
                    by_rule < 7,
                    "{strength}: a body shaken hard went on {by_rule} times"
                );
            }
        }
        assert!(
            carried >= 28,
            "{carried} passes went on from an earlier step's bounds"
        );
        assert!(clamped > 0, "no impulse was clamped");
    }

    /// A body that moves as a whole, fast, while it shakes gently goes on from its earlier
    /// bounds (their start follows it, see `ClampBounds::follow_translation`), and clamps
    /// exactly as the walk without bounds does; without following, its drifts (the distance
    /// it travelled) ask for new bounds every pass.
    #[test]
    fn a_body_moving_as_a_whole_goes_on_from_its_bounds() {
        let mut by_rule = shaken_body(0.02);
        for v in by_rule.velocities_mut() {
            *v += Vec3::new(1.5, -4.0, 0.5);
        }
        let mut exact = by_rule.clone();
        exact.clamp_bounds.disabled = true;
        for step in 0..8 {
            for body in [&mut by_rule, &mut exact] {
                body.begin_step();
                body.one_ring_pass(H, &mut []);
                body.per_tet_pass(H, &mut []);
                body.integrate_positions(H);
            }
            assert_eq!(by_rule.velocities, exact.velocities, "step {step}");
            assert_eq!(by_rule.positions, exact.positions, "step {step}");
        }
        // Eight passes: the first takes the bounds, the others may go on from them.
        let carried = by_rule.clamp_bounds.carried_passes;
        assert!(carried >= 5, "{carried} of 7 passes went on");
        assert!(
            by_rule.counters().clamps_skipped > 0,
            "the bounds were never used"
        );
    }

    /// A body at rest and moving as a whole, three particles of one corner kicked now and
    /// then, gently enough for the body to stay quiet (see `QUIET_DRIFT`) and the bounds to
    /// go on, hard enough to put the rings around them past their tolerances: most rings are
    /// known to be within their tolerances from the bounds (`RingCheckBound`), the kicked ones
    /// are not, and the passes give exactly what they give checking every ring (the walk
    /// without bounds checks every ring). Taking every ring found within at its last check as
    /// known fails here (checked).
    #[test]
    fn rings_known_within_their_tolerances_change_nothing() {
        const KICK: Vec3 = Vec3::new(0.05, 0.1, -0.07);
        // A kick that throws particles far past their radius (`FAR_DRIFT`) and smaller ones
        // that do not: rings near those are known or not from the block's largest drift.
        for (moving, kick) in [Vec3::ZERO, Vec3::new(1.5, -4.0, 0.5)]
            .into_iter()
            .flat_map(|m| [1.0, 0.3, 0.1, 0.03].map(|k| (m, k * KICK)))
        {
            let mut fast = shaken_body(0.0);
            for v in fast.velocities_mut() {
                *v += moving;
            }
            let mut exact = fast.clone();
            exact.clamp_bounds.disabled = true;
            let (mut known, mut checked, mut kicked_rings) = (0, 0, 0);
            for step in 0..16 {
                for body in [&mut fast, &mut exact] {
                    body.begin_step();
                    if step % 4 == 2 {
                        for v in body.velocities.iter_mut().take(3) {
                            *v += kick;
                        }
                    }
                    body.one_ring_pass(H, &mut []);
                    body.per_tet_pass(H, &mut []);
                    body.integrate_positions(H);
                }
                assert_eq!(
                    fast.velocities, exact.velocities,
                    "{moving}, {kick}, step {step}"
                );
                assert_eq!(
                    fast.positions, exact.positions,
                    "{moving}, {kick}, step {step}"
                );
                assert_eq!(exact.counters().ring_checks_skipped, 0);
                known += fast.counters().ring_checks_skipped;
                checked += fast.positions.len() as u32;
                if step % 4 == 2 {
                    kicked_rings += exact.counters().rings_corrected;
                }
            }
            assert!(
                known > checked / 10,
                "{moving}, {kick}: {known} of {checked} rings known within"
            );
            assert!(
                known < checked,
                "{moving}, {kick}: every ring was known within"
            );
            assert!(
                kicked_rings > 0,
                "{moving}, {kick}: the kicks put no ring past its tolerance"
            );
        }
    }

    /// The rings' checks belong to one set of clamp bounds: a pass that goes on from the bounds
    /// in a body that is not quiet computes none and must not leave the next quiet pass to use
    /// checks of earlier bounds, or none at all, as if they were these bounds'.
    #[test]
    fn ring_checks_are_ready_only_once_computed_for_their_bounds() {
        let mut body = shaken_body(0.3);
        body.clamp_bounds.always_carry = true;
        let first = (body.positions.clone(), body.velocities.clone());
        for step in 0..7 {
            body.begin_step();
            if step == 6 {
                // Back where the bounds were taken: no particle has drifted, the body is quiet.
                (body.positions, body.velocities) = first.clone();
            }
            let carried_before = body.clamp_bounds.carried_passes;
            body.one_ring_pass(H, &mut []);
            body.per_tet_pass(H, &mut []);
            body.integrate_positions(H);
            let carried = body.clamp_bounds.carried_passes > carried_before;
            assert!(
                step == 0 || carried,
                "step {step}: the bounds were taken again"
            );
            let ready = body.clamp_bounds.ring_checks_ready;
            if step < 6 {
                assert_eq!(body.counters().ring_checks_skipped, 0, "step {step}");
                assert!(
                    !ready,
                    "step {step}: the rings' checks ready, none computed"
                );
            } else {
                assert!(ready, "the quiet pass did not compute the rings' checks");
            }
        }
    }

    /// Bounds are carried with up to one particle in `CARRY_STRAYS` past `CARRY_DRIFT` of its
    /// radius, not with one more, and never with a broken preview or a radius at zero.
    #[test]
    fn bounds_are_carried_past_a_few_strays_only() {
        let n = 3 * CARRY_STRAYS + 17;
        let bounds = ClampBounds {
            start: vec![Vec3::ZERO; n],
            vertex_radius: vec![1.0; n],
            ..Default::default()
        };
        let within = Point4::new(Vec3::X * (0.99 * CARRY_DRIFT));
        let past = Point4::new(Vec3::Y * (1.01 * CARRY_DRIFT));
        let mut previews = vec![within; n];
        assert!(bounds.near_start(&previews).0);
        for stray in previews.iter_mut().step_by(7).take(n / CARRY_STRAYS) {
            *stray = past;
        }
        assert!(
            bounds.near_start(&previews).0,
            "3 strays of {n} are allowed"
        );
        *previews.last_mut().unwrap() = past;
        assert!(!bounds.near_start(&previews).0, "a fourth is not");
        let mut broken = vec![within; n];
        broken[5] = Point4::new(Vec3::NAN);
        assert!(!bounds.near_start(&broken).0, "a NaN preview");
        let mut flat = bounds.clone();
        flat.vertex_radius[9] = 0.0;
        assert!(
            !flat.near_start(&vec![within; n]).0,
            "a vertex without a radius"
        );
    }

    /// A body at rest with one interior particle thrown, before the one-ring pass or between
    /// the passes: it and its neighbours drift far while the rest of the body does not move,
    /// so impulses near it are clamped and those far from it skip the clamp. The far drifts
    /// must not raise the bound the rest is checked against, and must still send the impulses
    /// near them to the walk (see `FAR_DRIFT`): without the marks, both cases differ from the
    /// walk without bounds (checked).
    #[test]
    fn impulses_near_a_far_drift_are_clamped_as_without_bounds() {
        let (mut skipped, mut clamped) = (0, 0);
        for (throw, between_passes) in [(Vec3::X * 6.0, true), (Vec3::Y * 48.0, false)] {
            let mut fast = shaken_body(0.0);
            use_impulses(
                &mut fast,
                ImpulseSettings {
                    gamma: 1.0,
                    ..ImpulseSettings::PAPER
                },
            );
            // The middle particle of the 5 x 5 x 5 grid.
            let thrown = 2 + 5 * (2 + 5 * 2);
            if !between_passes {
                fast.velocities[thrown] += throw;
            }
            let mut exact = fast.clone();
            exact.clamp_bounds.disabled = true;
            for body in [&mut fast, &mut exact] {
                body.begin_step();
                body.one_ring_pass(H, &mut []);
                if between_passes {
                    body.velocities[thrown] += throw;
                }
                body.per_tet_pass(H, &mut []);
            }
            assert_eq!(fast.velocities, exact.velocities, "throw {throw}");
            let (f, e) = (fast.counters(), exact.counters());
            skipped += f.clamps_skipped;
            clamped += e.rings_clamped + e.tets_clamped;
        }
        assert!(skipped > 0, "the bounds were never used");
        assert!(clamped > 0, "nothing was clamped");
    }

    #[test]
    fn kinematic_particles_are_not_moved() {
        let mut body = shaken_body(3.0);
        let v_before = body.velocities[0];
        body.set_kinematic(0, body.positions[0]).unwrap();
        body.refresh_previews(H);
        for p in 0..body.positions.len() {
            body.ring_impulse(&body.mesh.clone(), p, H, &exact(0.125, true), &mut []);
        }
        for t in 0..body.mesh.tet_count() {
            body.tet_impulse(&body.mesh.clone(), t, H, &exact(0.125, true), &mut []);
        }
        assert_eq!(body.velocities[0], v_before);
    }

    #[test]
    fn a_ring_within_tolerance_is_corrected_only_for_a_tet_past_the_ring_tet_tolerance() {
        // Moving an interior vertex alone changes its tets' volumes but not its ring's: the
        // tets gain on one side what they lose on the other.
        let ring_with_centre_moved = |by: f32| {
            let mut body = shaken_body(0.0);
            let centre = body.positions.iter().sum::<Vec3>() / body.positions.len() as f32;
            let p = (0..body.positions.len())
                .min_by(|&a, &b| {
                    let (a, b) = (body.positions[a], body.positions[b]);
                    a.distance(centre).total_cmp(&b.distance(centre))
                })
                .unwrap();
            body.velocities[p] = Vec3::new(1.0, 0.6, 0.3).normalize() * (by / H);
            body.refresh_previews(H);
            let (mut ring, mut rest, mut worst) = (0.0, 0.0, 0.0f32);
            for &t in body.mesh.one_ring(p) {
                let v0 = body.mesh.rest_volumes()[t as usize];
                let v = previewed_volume(&body, t as usize);
                (ring, rest) = (ring + v, rest + v0);
                worst = worst.max((v - v0).abs() / v0);
            }
            (body, p, (ring - rest).abs() / rest, worst)
        };
        let paper = ImpulseSettings::PAPER;
        assert!(paper.tolerance < paper.ring_tet_tolerance);
        let (mut body, p, ring_error, worst) = ring_with_centre_moved(0.0003);
        assert!(ring_error < 0.1 * paper.tolerance, "{ring_error}");
        assert!(
            worst > paper.tolerance && worst < paper.ring_tet_tolerance,
            "{worst}"
        );
        let outcome = body.ring_impulse(&body.mesh.clone(), p, H, &paper, &mut []);
        assert!(matches!(outcome, ImpulseOutcome::Skipped), "{outcome:?}");
        // The rule before the ring tet tolerance: any tet past the tolerance.
        let before = ImpulseSettings {
            ring_tet_tolerance: paper.tolerance,
            ..paper
        };
        let outcome = body.ring_impulse(&body.mesh.clone(), p, H, &before, &mut []);
        assert!(!matches!(outcome, ImpulseOutcome::Skipped), "{outcome:?}");

        let (mut body, p, ring_error, worst) = ring_with_centre_moved(0.002);
        assert!(ring_error < 0.1 * paper.tolerance, "{ring_error}");
        assert!(worst > paper.ring_tet_tolerance, "{worst}");
        let outcome = body.ring_impulse(&body.mesh.clone(), p, H, &paper, &mut []);
        assert!(!matches!(outcome, ImpulseOutcome::Skipped), "{outcome:?}");
    }

    #[test]
    fn tolerance_skips_small_errors_and_only_those() {
        let largest_error = |body: &SoftBodyState| {
            (0..body.mesh.tet_count())
                .map(|t| {
                    let v0 = body.mesh.rest_volumes()[t];
                    (previewed_volume(body, t) - v0).abs() / v0
                })
                .fold(0.0f32, f32::max)
        };
        let tolerance = ImpulseSettings::PAPER.tolerance;
        let mut gentle = shaken_body(0.0005);
        let error = largest_error(&gentle);
        assert!(error > 0.0 && error < tolerance, "{error}");
        let before = gentle.velocities().to_vec();
        gentle.one_ring_pass(H, &mut []);
        gentle.per_tet_pass(H, &mut []);
        assert_eq!(
            gentle.velocities(),
            &before[..],
            "errors within tolerance were corrected"
        );

        // The same body with no tolerance is corrected.
        use_impulses(&mut gentle, exact(0.125, true));
        gentle.one_ring_pass(H, &mut []);
        assert_ne!(gentle.velocities(), &before[..]);

        // The per-tet pass skips a tet whose correction, gamma times its error, is within the
        // tolerance: errors up to eight times the tolerance with the paper's gamma = 1/8.
        for (gamma, corrected) in [(0.125, false), (1.0, true)] {
            let mut body = shaken_body(0.01);
            let error = largest_error(&body);
            assert!(error > tolerance && error < 8.0 * tolerance, "{error}");
            let per_tet_only = ImpulseSettings {
                one_ring: false,
                gamma,
                ..ImpulseSettings::PAPER
            };
            use_impulses(&mut body, per_tet_only);
            let before = body.velocities().to_vec();
            body.per_tet_pass(H, &mut []);
            assert_eq!(body.velocities() != &before[..], corrected, "gamma {gamma}");
        }

        // Errors above the tolerance are corrected with it.
        let mut shaken = shaken_body(0.05);
        assert!(largest_error(&shaken) > tolerance);
        let before = shaken.velocities().to_vec();
        shaken.one_ring_pass(H, &mut []);
        shaken.per_tet_pass(H, &mut []);
        assert_ne!(shaken.velocities(), &before[..]);
        assert!(largest_error(&shaken) < largest_error(&shaken_body(0.05)));
    }
}
