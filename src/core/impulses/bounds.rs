//! The clamp bounds: what the start of a pass proves about how far each tet is from its
//! floor, so that most impulses need not walk their neighbours (see [`SafeRadii`]).

use super::*;

/// Bounds computed at the start of a volume pass that let most impulses skip the neighbour
/// clamp without looking at their neighbours.
///
/// Every tet's volume can change from its value at the start of the pass only through the
/// motion of its vertices; if each of them moves by at most `m` from where it was at the start,
/// the volume moves by at most `drift_bound(m, G, L)`, with `G` the sum of the lengths of the
/// tet's volume gradients and `L` its longest edge from its last vertex, both at the start. A
/// particle's drift is the distance of its predicted position from where it was at the start of the pass.
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
/// A tet already below `eps` at the start (or at it, see `CLAMP_ROUNDING`) gets as slack half
/// of `CLAMP_SLACK` (the drift before an impulse and the impulse itself each count once), and
/// no more than its distance to that boundary, so that it cannot climb past it unseen, where
/// the exact rule would no longer let it drop.
#[derive(Clone, Debug, Default)]
pub(crate) struct SafeRadii {
    /// Whether the bounds describe the current pass.
    pub(crate) active: bool,
    /// Never use the bounds (to compare against the exact walk in tests).
    #[cfg(test)]
    pub(crate) disabled: bool,
    /// Whether the bounds were taken in this step (by its one-ring pass), for the per-tet
    /// pass to go on from (see `PassBody::per_tet_impulses`); cleared by `begin_step`.
    pub(crate) taken_this_step: bool,
    /// Whether the next bounds taken (by a one-ring pass) are to cover the tets' regions too,
    /// for the per-tet pass after it.
    pub(super) keep_for_tets: bool,
    /// Whether the bounds were last taken by a one-ring pass, so that a later step's one-ring
    /// pass may go on from them (see [`SafeRadii::still_hold`]), and whether they cover the
    /// tets' regions too.
    pub(super) kept: bool,
    pub(super) kept_tet_regions: bool,
    /// One-ring passes that went on from an earlier step's bounds (for tests).
    #[cfg(test)]
    pub(crate) carried_passes: u32,
    /// Go on from an earlier step's bounds however far the particles are from their start (to
    /// test that the result does not depend on it).
    #[cfg(test)]
    pub(crate) always_carry: bool,
    pub(super) tet_radius: Vec<f32>,
    pub(super) vertex_radius: Vec<f32>,
    /// The radius of each vertex's ring region ([`ClampRegions::Rings`]).
    pub(super) ring_region_radius: Vec<f32>,
    /// The radius of each tet's region ([`ClampRegions::Tets`]).
    pub(super) tet_region_radius: Vec<f32>,
    /// Each tet's volume error, gradient sum and longest edge from its last vertex at the
    /// start, for the rings' [`RingErrorBound`]s.
    pub(super) tet_shape: Vec<TetShape>,
    /// Each vertex's ring at the start (see [`RingErrorBound`]), computed by the first pass
    /// that goes on from these bounds: a body that takes new bounds every pass (one that
    /// changes its shape) would pay for them without a pass to use them in.
    pub(super) ring_check: Vec<RingErrorBound>,
    /// Whether `ring_check` describes these bounds.
    pub(super) ring_checks_ready: bool,
    /// Previews when the bounds were taken: a particle's drift is its distance from here.
    pub(super) start: Vec<Vec3>,
}

/// A tet at the start of the bounds: what [`RingErrorBound`] is made of.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct TetShape {
    pub(super) error: f32,
    pub(super) grad: f32,
    pub(super) reach: f32,
}

/// What a ring's tolerance check (see `VolumePass::ring_impulse`) found at the bounds' start, in
/// a form that bounds how far its drifts can have moved it since: the ring's volume error, the
/// sums over its tets of their gradient sums and reaches (the terms of [`drift_bound`] summed),
/// the largest relative error of one of its tets, its smallest rest volume, and its largest
/// gradient sum and reach. With each particle of the ring within `d` of its start, each tet's
/// volume is within `drift_bound(d, grad, reach)` of its volume there, so a ring whose error
/// and tets stay within the tolerances by these bounds is within them now, and its check
/// (a tet volume per tet of the ring) is skipped: the answer is known. Used in quiet bodies
/// only (see [`QUIET_DRIFT`]), where it saves about a fifth of a resting body's instructions
/// (PERFORMANCE.md, "The fast path's skips").
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct RingErrorBound {
    pub(super) error: f32,
    pub(super) grad_sum: f32,
    pub(super) reach_sum: f32,
    pub(super) tets: f32,
    pub(super) largest_relative_error: f32,
    pub(super) smallest_rest_volume: f32,
    pub(super) largest_grad: f32,
    pub(super) largest_reach: f32,
}

/// A ring is known to be within its tolerances when the bounds of [`RingErrorBound`] keep it
/// within this fraction of them: the rest covers the rounding of the `f32` volumes, the
/// check's and the bounds' own (about a millionth of a tet's volume for a well-shaped tet,
/// hundreds of times less than this margin of the ring tet tolerance, 5e-4 of the tet's
/// volume), so the shortcut never skips a ring that the check would correct.
pub(super) const RING_CHECK_MARGIN: f32 = 0.95;

/// A one-ring pass uses the rings' [`RingErrorBound`]s only when at least [`QUIET_SHARE`] of
/// the body's particles have drifted less than this fraction of their vertex radius since the
/// bounds' start (counted by `SafeRadii::near_start`). A tet's radius is about where it loses half its
/// volume, so a ring's tolerance (0.3 %) allows a small fraction of it, less its error. In a
/// body that is not this still, few rings are known and the bounds cost more than they save
/// (most rings fail the test, and the bounds are made again for each short-lived set of clamp
/// bounds).
pub const QUIET_DRIFT: f32 = 0.005;

/// See [`QUIET_DRIFT`].
pub const QUIET_SHARE: f32 = 0.75;

impl RingErrorBound {
    /// Whether a ring with this bound, each of whose particles is within `drift` of its start,
    /// is within `tolerance` of its rest volume `rest` and each of its tets within
    /// `ring_tet_tolerance` of theirs. False for a broken (NaN) drift or bound.
    #[inline]
    pub(super) fn within(
        &self,
        drift: f32,
        tolerance: f32,
        ring_tet_tolerance: f32,
        rest: f32,
    ) -> bool {
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
/// with the body, see `SafeRadii::follow_translation`) by more than this fraction of its
/// vertex radius: a body at rest, or nearly, whose particles come back to about the same
/// predicted positions step after step, or one that moves as a whole (falling, thrown, carried). The
/// bounds hold however far the particles have gone (drifts are measured from their start, as
/// for the per-tet pass), but the further they start from it, the fewer impulses they clear at
/// once, so a body that changes its shape takes them afresh. 0.5 leaves half of each radius to
/// the pass itself; taking the bounds is about a fifth of a resting body's step (PERFORMANCE.md,
/// "The fast path's skips").
pub const CARRY_DRIFT: f32 = 0.5;

/// A one-ring pass goes on from an earlier step's bounds with up to one particle in this many
/// past [`CARRY_DRIFT`] (see [`SafeRadii::still_hold`]): in a body at rest under a load a few
/// particles move more than the rest from step to step (over the soft cube's first 8 s, 59 of
/// its 2 197 particles a step on average were past half their radius, and 119 of 899 one-ring
/// passes went on). The strays are checked as any particle that drifted (their blocks' largest
/// drift, or marked far past their radius), so the result is the same either way. Bodies under
/// 200 particles still wait for every one.
pub const CARRY_STRAYS: usize = 200;

impl SafeRadii {
    /// Whether the kept bounds still hold for a one-ring pass from `predicted` (the tets'
    /// regions too if `need_tet_regions`): see [`CARRY_DRIFT`] and [`CARRY_STRAYS`]. A vertex
    /// without a positive radius, or a broken predicted position, asks for new bounds. Also how many
    /// particles are quiet (see [`SafeRadii::near_start`]).
    pub(super) fn still_hold(&self, need_tet_regions: bool, predicted: &[Point4]) -> (bool, usize) {
        if !self.kept || (need_tet_regions && !self.kept_tet_regions) {
            return (false, 0);
        }
        let (near, quiet) = self.near_start(predicted);
        #[cfg(test)]
        let near = near || self.always_carry;
        (near, quiet)
    }

    /// Moves the bounds' start by the particles' mean drift from it (`predicted` against
    /// `start`), so that drifts measure how the body changed its shape since the bounds were
    /// taken, not how far it went. A tet's volume does not change when all its particles move
    /// by the same vector, nor do its slack, gradients and edges, so every radius holds about
    /// the moved start as it did about the old one (any common move would do; the mean leaves
    /// the smallest drifts on the whole). A body falling, thrown or carried without changing
    /// its shape much then goes on from its bounds step after step instead of taking them
    /// afresh each time (see [`CARRY_DRIFT`]).
    pub(super) fn follow_translation(&mut self, predicted: &[Point4]) {
        if predicted.is_empty() || predicted.len() != self.start.len() {
            return;
        }
        let sum = predicted
            .iter()
            .zip(&self.start)
            .fold(Vec3::ZERO, |sum, (p, &start)| sum + (p.vec3() - start));
        let shift = sum / predicted.len() as f32;
        // A broken predicted position makes the shift NaN, and the start with it: `near_start` then asks
        // for new bounds, which set the start again.
        for start in &mut self.start {
            *start += shift;
        }
    }

    /// Whether the particles are within [`CARRY_DRIFT`] of their vertex radius of the bounds'
    /// start, all but at most one in [`CARRY_STRAYS`]; and, if they are, how many are within
    /// [`QUIET_DRIFT`] of it (zero if not).
    pub(super) fn near_start(&self, predicted: &[Point4]) -> (bool, usize) {
        let mut strays = predicted.len() / CARRY_STRAYS;
        let mut quiet = 0;
        for ((p, &start), &radius) in predicted.iter().zip(&self.start).zip(&self.vertex_radius) {
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

    /// The arrays, for the jobs of a pass to fill and then read (see [`PassRadii`]).
    ///
    /// # Safety
    /// The promise of [`SharedSlice::new`], for every array: the jobs that use the view split
    /// its elements between them or order their accesses.
    pub(super) unsafe fn view(&mut self, regions: ClampRegions) -> PassRadii<'_> {
        PassRadii {
            active: self.active,
            ring_checks: false,
            regions,
            // SAFETY: this function's caller's promise.
            tet_radius: unsafe { SharedSlice::new(&mut self.tet_radius) },
            vertex_radius: unsafe { SharedSlice::new(&mut self.vertex_radius) },
            ring_region_radius: unsafe { SharedSlice::new(&mut self.ring_region_radius) },
            tet_region_radius: unsafe { SharedSlice::new(&mut self.tet_region_radius) },
            tet_shape: unsafe { SharedSlice::new(&mut self.tet_shape) },
            ring_check: unsafe { SharedSlice::new(&mut self.ring_check) },
            start: unsafe { SharedSlice::new(&mut self.start) },
        }
    }

    /// Sizes the arrays for passes over `mesh` in `blocks` tasks (allocates only the first
    /// time).
    pub(super) fn reserve(&mut self, mesh: &TetMesh, blocks: usize, motion: &mut DriftTracking) {
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
        self.ring_check.resize(n, RingErrorBound::default());
        motion.walked.0.resize_with(tets, || AtomicU32::new(0));
        motion.far_nearby.0.resize_with(n, || AtomicU32::new(0));
        self.start.resize(n, Vec3::ZERO);
    }
}

/// [`SafeRadii`] during a pass: computed by the pass's first jobs, each writing its own
/// range of tets, vertices or regions, then only read.
#[derive(Clone, Copy)]
pub(crate) struct PassRadii<'a> {
    pub(super) active: bool,
    /// Whether the rings' [`RingErrorBound`]s hold in this pass (a one-ring pass going on from
    /// earlier bounds).
    pub(super) ring_checks: bool,
    /// The regions of the pass's impulses.
    pub(super) regions: ClampRegions,
    pub(super) tet_radius: SharedSlice<'a, f32>,
    pub(super) vertex_radius: SharedSlice<'a, f32>,
    pub(super) ring_region_radius: SharedSlice<'a, f32>,
    pub(super) tet_region_radius: SharedSlice<'a, f32>,
    pub(super) tet_shape: SharedSlice<'a, TetShape>,
    pub(super) ring_check: SharedSlice<'a, RingErrorBound>,
    pub(super) start: SharedSlice<'a, Vec3>,
}

/// Tets, vertices or regions per job of the clamp bounds' computation.
pub(super) const BOUNDS_CHUNK: usize = 512;

impl PassRadii<'_> {
    /// The radius of `tets` at `predicted` from their slack, gradient sum and reach, four tets
    /// at a time (see `lanes`).
    pub(super) fn compute_tets(
        &self,
        mesh: &TetMesh,
        predicted: SharedSlice<Point4>,
        tets: Range<usize>,
    ) {
        let (all, rest_volumes) = (mesh.tets(), mesh.rest_volumes());
        for start in tets.clone().step_by(LANES) {
            let n = LANES.min(tets.end - start);
            // Lanes past the tail repeat the last tet (computed, not stored).
            let corner = |k: usize| {
                predicted.gather(std::array::from_fn(|l| {
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
            // A broken predicted position: no bound is safe; every region holding it walks.
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
    /// the pass (`predicted`, zero `drift`). Needs every tet's radius.
    pub(super) fn compute_vertices(
        &self,
        mesh: &TetMesh,
        predicted: SharedSlice<Point4>,
        drift: SharedSlice<f32>,
        vertices: Range<usize>,
    ) {
        for v in vertices {
            self.vertex_radius
                .set(v, smallest(mesh.one_ring(v), self.tet_radius));
            self.start.set(v, predicted.get(v).vec3());
            drift.set(v, 0.0);
        }
    }

    /// Each tet's [`TetShape`] at the bounds' start, for `tets`.
    #[inline(never)]
    pub(super) fn compute_tet_shapes(&self, mesh: &TetMesh, tets: Range<usize>) {
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

    /// Each vertex's [`RingErrorBound`], for `vertices`. Needs every tet's shape.
    #[inline(never)]
    pub(super) fn compute_ring_checks(&self, mesh: &TetMesh, vertices: Range<usize>) {
        let rest_volumes = mesh.rest_volumes();
        for v in vertices {
            let ring = mesh.one_ring(v);
            let mut check = RingErrorBound {
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
    pub(super) fn compute_regions(
        &self,
        mesh: &TetMesh,
        regions: ClampRegions,
        range: Range<usize>,
    ) {
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
    pub(super) fn region_radius(&self, r: usize) -> f32 {
        match self.regions {
            ClampRegions::Rings => self.ring_region_radius.get(r),
            ClampRegions::Tets => self.tet_region_radius.get(r),
        }
    }

    /// For a pass that goes on from bounds taken earlier: the drift of the `vertices` of one
    /// block from their predicted positions, and the largest of them but the far ones (see
    /// [`FAR_DRIFT`]), which are marked instead.
    pub(super) fn carry_drift(
        &self,
        mesh: &TetMesh,
        predicted: SharedSlice<Point4>,
        drift: SharedSlice<f32>,
        far: FarDriftMarks,
        vertices: &[u32],
    ) -> f32 {
        let mut largest = 0.0f32;
        for &v in vertices {
            let v = v as usize;
            let d = (predicted.get(v).vec3() - self.start.get(v)).length();
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
    pub(super) fn is_far(&self, i: usize, drift: f32) -> bool {
        let limit = FAR_DRIFT * self.vertex_radius.get(i);
        drift > limit || drift.is_nan()
    }
}

/// The smallest of `values` at `items`: the radius of their union.
#[inline]
pub(super) fn smallest(items: &[u32], values: SharedSlice<f32>) -> f32 {
    items
        .iter()
        .map(|&i| values.get(i as usize))
        .fold(f32::INFINITY, smaller)
}

/// What the clamp bounds track while a pass runs, per particle.
#[derive(Clone, Debug, Default)]
pub(crate) struct DriftTracking {
    /// Each particle's drift so far in the pass: the distance of its predicted position from
    /// [`SafeRadii`]' start.
    pub(super) drift: Vec<f32>,
    /// During a clamp walk, the length of each particle's direction (zero for particles the
    /// impulse does not move), so the walk reads one number per vertex.
    pub(super) move_len: Vec<f32>,
    /// For each tet, the number of the last clamp walk that looked at it past its radius (see
    /// [`VolumePass::clamp_unclear`]): one-rings of the walked vertices overlap, and a tet the
    /// radius does not clear is looked at once per walk.
    pub(super) walked: PassMarks,
    /// The number of the last clamp walk (from 1), shared by the tasks of a pass.
    pub(super) walks: WalkCount,
    /// For a pass that goes on from bounds taken earlier, the largest drift among each block's
    /// vertices at its start.
    pub(super) block_drift: Vec<f32>,
    /// For each particle, the number of the last pass in which a particle within one edge of
    /// it (itself included) drifted far (see [`FAR_DRIFT`]).
    pub(super) far_nearby: PassMarks,
    /// The number of the running pass with clamp bounds, for `far_nearby` (from 1).
    pub(super) pass_number: u32,
}

/// A particle whose drift in a pass passes this fraction of its vertex radius (see
/// [`SafeRadii`]) drifts far: instead of raising the largest drift of its block, which every
/// impulse of the block and of the blocks after it is checked against, it marks the particles
/// within one edge of it, and impulses that move a marked particle go to the per-vertex checks
/// (which a particle past its own radius fails anyway). A few particles a pass drift that far
/// while the mean drift is a small fraction of the radius; without the marks they would send
/// most of their blocks' impulses to the checks (PERFORMANCE.md, "The fast path's skips").
pub(super) const FAR_DRIFT: f32 = 1.0;

/// One number per particle or tet, the pass or walk that last marked it (see
/// [`DriftTracking::far_nearby`] and [`DriftTracking::walked`]), written by the tasks of a pass at
/// once (two tasks can mark the same one), hence atomic. A clone starts unmarked.
#[derive(Debug, Default)]
pub(crate) struct PassMarks(pub(super) Vec<AtomicU32>);

impl Clone for PassMarks {
    fn clone(&self) -> PassMarks {
        PassMarks((0..self.0.len()).map(|_| AtomicU32::new(0)).collect())
    }
}

/// The number of the last clamp walk ([`DriftTracking::walks`]); a clone starts at zero, as its
/// marks do.
#[derive(Debug, Default)]
pub(crate) struct WalkCount(pub(super) AtomicU32);

impl Clone for WalkCount {
    fn clone(&self) -> WalkCount {
        WalkCount::default()
    }
}

impl DriftTracking {
    /// Starts the marks of a new pass with clamp bounds.
    pub(super) fn next_pass(&mut self) {
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

/// Which tets the running clamp walk has looked at ([`DriftTracking::walked`]). Tasks that run
/// at the same time can walk the same tet (their clamp regions can touch), so the marks are
/// atomic; each walk has its own number, so a walk only skips a tet it marked itself.
#[derive(Clone, Copy)]
pub(super) struct WalkMarks<'a> {
    pub(super) walked: &'a [AtomicU32],
    pub(super) walks: &'a AtomicU32,
}

impl WalkMarks<'_> {
    /// A number for a new walk, never used before in this pass or since the marks were clear.
    pub(super) fn start(&self) -> u32 {
        self.walks.fetch_add(1, Ordering::Relaxed) + 1
    }

    /// Marks tet `t` for `walk`; whether it was unmarked.
    #[inline(always)]
    pub(super) fn first_visit(&self, walk: u32, t: u32) -> bool {
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
pub(super) struct FarDriftMarks<'a> {
    pub(super) marks: &'a [AtomicU32],
    pub(super) pass: u32,
}

impl FarDriftMarks<'_> {
    /// Marks the particles within one edge of particle `i`, which drifted far.
    pub(super) fn mark(&self, mesh: &TetMesh, i: usize) {
        for &v in mesh.ring_vertices(i) {
            self.marks[v as usize].store(self.pass, Ordering::Relaxed);
        }
    }

    /// Whether a particle within one edge of any of `vertices` drifted far.
    #[inline]
    pub(super) fn near(&self, vertices: &[u32]) -> bool {
        vertices.iter().any(|&v| self.marked(v as usize))
    }

    /// Whether a particle within one edge of particle `v` drifted far.
    #[inline]
    pub(super) fn marked(&self, v: usize) -> bool {
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
/// time.
#[derive(Clone, Debug, Default)]
#[repr(align(128))]
pub(crate) struct PassWorker {
    pub(super) ring_work: RingWork,
    pub(super) counters: StepCounters,
    /// The largest drift of any particle this task reads: the largest of the tasks it waited
    /// for (the only ones that moved those particles before it), then its own moves (drifts can
    /// shrink again; this cannot).
    pub(super) max_moved: f32,
    pub(super) sphere_dv: Vec<Vec3>,
    /// The neighbour clamp's working list.
    pub(super) clamp: ClampWork,
}

/// A task's working data for the neighbour clamp.
#[derive(Clone, Debug, Default)]
pub(crate) struct ClampWork {
    /// The vertices of the impulse being clamped whose one-rings the bounds could not clear:
    /// the clamp walks only their one-rings.
    /// Sized for the largest clamp region's vertices up front (a clone of a `Vec` with spare
    /// capacity has none, and the step must not allocate).
    pub(super) unclear: Vec<u32>,
    /// How far each ring vertex of the vertex being walked can get from its start (its drift
    /// plus its own move), by the ring's local index; sized like `unclear`.
    pub(super) reach: Vec<f32>,
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
/// A NaN `b` is ignored; the bounds guard against broken predicted positions through the slack instead.
#[inline(always)]
pub(super) fn larger(a: f32, b: f32) -> f32 {
    if b > a { b } else { a }
}

/// `max(a, b)`, but NaN once either is: for bounds that a broken value must void.
#[inline(always)]
pub(super) fn larger_or_nan(a: f32, b: f32) -> f32 {
    if b > a || b.is_nan() { b } else { a }
}

/// `min(a, b)` as one instruction; see [`larger`].
#[inline(always)]
pub(super) fn smaller(a: f32, b: f32) -> f32 {
    if b < a { b } else { a }
}

/// Largest change of a tet's volume when each of its edge vectors (from its last vertex, of
/// length at most `l`) changes by at most `delta`.
#[inline]
pub(super) fn volume_bound(delta: f32, l: f32) -> f32 {
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
pub(super) fn drift_bound(m: f32x4, grad: f32x4, l: f32x4) -> f32x4 {
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
pub(super) fn safe_radius(slack: f32x4, grad: f32x4, l: f32x4) -> f32x4 {
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
