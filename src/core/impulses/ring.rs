//! The one-ring impulse (section 5): a vertex's ring gathered into lanes, its cubic, its
//! root and clamp.

use super::*;

/// Working arrays of one ring impulse, sized for the mesh's largest one-ring so that steps do
/// not allocate: the ring's particles in the order of [`TetMesh::ring_vertices`], and its tets
/// four to an entry.
#[derive(Clone, Debug, Default)]
pub(crate) struct RingWork {
    predicted: Vec<Point4>,
    inv_masses: Vec<f32>,
    /// The summed directions `D_i`.
    directions: Vec<Vec3>,
    /// The directions before `constrain_direction`.
    original: Vec<Vec3>,
    tets: Vec<RingLanes>,
}

impl RingWork {
    /// Arrays for the largest one-ring of `mesh`.
    pub(crate) fn for_mesh(mesh: &TetMesh) -> RingWork {
        let n = mesh.max_ring_vertices();
        RingWork {
            predicted: vec![Point4::default(); n],
            inv_masses: vec![0.0; n],
            directions: vec![Vec3::ZERO; n + 1],
            original: vec![Vec3::ZERO; n + 1],
            tets: vec![RingLanes::default(); mesh.max_one_ring().div_ceil(LANES)],
        }
    }
}

/// Corner `k` of four ring tets, from the ring's gathered `values` (padded, see
/// [`Vec3x4::gather_padded`]).
#[inline(always)]
pub(super) fn gather(values: &[Vec3], corners: &[[u16; 4]; LANES], k: usize) -> Vec3x4 {
    Vec3x4::gather_padded(values, corners.map(|c| c[k] as usize))
}

/// [`gather`] for numbers.
#[inline(always)]
pub(super) fn gather_f32(values: &[f32], corners: &[[u16; 4]; LANES], k: usize) -> [f32; LANES] {
    [
        values[corners[0][k] as usize],
        values[corners[1][k] as usize],
        values[corners[2][k] as usize],
        values[corners[3][k] as usize],
    ]
}

/// The edges `x_i - x_d` (i = a, b, c) of the ring's tets `4 group` to `4 group + 3` at the
/// ring's gathered `predicted`, and their rest volumes. Lanes past the ring hold a tet collapsed
/// onto the centre: zero edges, volume and error. Every tet's last corner is the centre (see
/// `TetMesh::ring_corners`). A function always inlined rather than a closure: the compiler kept
/// the closure out of line when the code around the ring impulse grew, at a few percent of the
/// pass.
#[inline(always)]
pub(super) fn ring_group_edges(
    predicted: &[Point4],
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
    let x = |k: usize| Vec3x4::gather_points(predicted, tet_corners.map(|c| c[k] as usize));
    let xd = Vec3x4::splat(predicted[0].vec3());
    ([x(0) - xd, x(1) - xd, x(2) - xd], f32x4::new(v0))
}

/// A group's edges ([`ring_group_edges`]), gradients, volume and error, kept for what follows
/// the ring's check, and the group's rest volumes.
#[inline(always)]
pub(super) fn ring_group_lanes(
    predicted: &[Point4],
    ring_v0: &[f32],
    corners: &[[u16; 4]],
    group: usize,
) -> (RingLanes, f32x4) {
    let sixth = f32x4::splat(SIXTH);
    let (edges, v0) = ring_group_edges(predicted, ring_v0, corners, group);
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

/// What a ring impulse knows of four tets of its ring at the current predicted positions.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct RingLanes {
    /// Edge vectors `x_i - x_d`, i = a, b, c.
    edges: [Vec3x4; 3],
    /// Volume gradients of a, b and c (d's is minus their sum).
    gradients: [Vec3x4; 3],
    volume: f32x4,
    /// The volume error `C_t`.
    error: f32x4,
}

impl VolumePass<'_> {
    /// Whether the ring of `p`, within its tolerances when last checked, is known to be within
    /// them still because its particles have not drifted far enough since the bounds' start to
    /// leave them (see [`RingErrorBound`]): then its check, and its impulse, are skipped.
    /// Kept out of line: it runs only in a quiet body's passes (see [`QUIET_DRIFT`]), and the
    /// pass's loop around `ring_impulse` stays as small as it was without it.
    #[inline(never)]
    pub(super) fn ring_known_within(
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
    /// positive root of `sum_t V_t(s) = sum_t V0_t`. Needs `refresh_predicted` first.
    ///
    /// The ring's particles are gathered into [`RingWork`] first and its tets are computed four
    /// at a time in SIMD lanes ([`Vec3x4`]), each lane with the scalar code's operations in the
    /// scalar code's order; the polynomial is summed lane by lane, then over the lanes.
    pub(super) fn ring_impulse(
        &self,
        worker: &mut PassWorker,
        p: usize,
        settings: &ImpulseSettings,
    ) -> ImpulseOutcome {
        let clamp = settings.neighbour_clamp;
        let mesh = self.mesh;
        let ring = mesh.one_ring(p);
        let corners = mesh.ring_corners(p);
        let vertices = mesh.ring_vertices(p);

        let work = &mut worker.ring_work;
        for (k, &i) in vertices.iter().enumerate() {
            work.predicted[k] = self.predicted.get(i as usize);
        }
        let groups = ring.len().div_ceil(LANES);
        if !self.ring_outside_tolerance(work, p, groups, settings) {
            return ImpulseOutcome::Skipped;
        }
        let Some(tet_step) = self.ring_directions(work, p, groups) else {
            return ImpulseOutcome::Skipped;
        };
        if self.any_touching {
            for (k, &i) in vertices.iter().enumerate() {
                work.original[k] = work.directions[k];
                work.directions[k] = self.constrain_direction(i as usize, work.directions[k]);
            }
        }
        let poly = ring_polynomial(work, corners, groups, mesh.ring_rest_volume(p));
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
            let work = &worker.ring_work;
            let dv = scale * work.directions[k];
            let removed = if self.any_touching {
                scale * (work.original[k] - work.directions[k])
            } else {
                Vec3::ZERO
            };
            self.apply_velocity_change(worker, i as usize, dv, removed);
        }
        ImpulseOutcome::Applied {
            step,
            root,
            clamped,
        }
    }

    /// Checks ring `p` (its tets in `groups` of lanes) against the tolerances (see
    /// `ImpulseSettings::ring_tet_tolerance`), its particles' predicted positions gathered in
    /// `work`; a broken (NaN) volume is not within them. Returns whether it is outside them,
    /// its tets then computed in full in `work.tets`.
    #[inline(always)]
    fn ring_outside_tolerance(
        &self,
        work: &mut RingWork,
        p: usize,
        groups: usize,
        settings: &ImpulseSettings,
    ) -> bool {
        let tolerance = settings.tolerance;
        let mesh = self.mesh;
        let corners = mesh.ring_corners(p);
        let ring_v0 = mesh.ring_rest_volumes(p);
        let rest = mesh.ring_rest_volume(p);
        let sixth = f32x4::splat(SIXTH);
        // A ring found past them when last checked
        // (most of a moving body's, pass after pass) is computed in full at once; any other
        // (most of a resting body's) first from its tets' volumes alone, with nothing stored,
        // and again in full only if it is corrected after all. Both give the same numbers:
        // the volume is `ea . ga` with the gradient `ga = eb x ec / 6` either way.
        let mut tet_outside_tolerance = f32x4::ZERO;
        let mut ring_error = f32x4::ZERO;
        let ring_tet_tolerance = f32x4::splat(settings.ring_tet_tolerance);
        // A ring with a sliver holds its tets to `ring_check_volumes` (the sliver's infinite);
        // any other to their rest volumes, read with them.
        let checked = mesh.ring_has_sliver(p).then(|| mesh.ring_check_volumes(p));
        let check_volume = |group: usize, v0: f32x4| match checked {
            None => v0,
            Some(checked) => f32x4::new(std::array::from_fn(|l| {
                checked.get(LANES * group + l).copied().unwrap_or(0.0)
            })),
        };
        let computed = self.ring_corrected.get(p);
        if computed {
            for (group, lanes) in work.tets[..groups].iter_mut().enumerate() {
                let (full, v0) = ring_group_lanes(&work.predicted, ring_v0, corners, group);
                *lanes = full;
                tet_outside_tolerance |= full
                    .error
                    .abs()
                    .cmp_gt(ring_tet_tolerance * check_volume(group, v0));
                ring_error += full.error;
            }
        } else {
            for group in 0..groups {
                let (edges, v0) = ring_group_edges(&work.predicted, ring_v0, corners, group);
                let error = edges[0].dot(edges[1].cross(edges[2]).scale(sixth)) - v0;
                tet_outside_tolerance |= error
                    .abs()
                    .cmp_gt(ring_tet_tolerance * check_volume(group, v0));
                ring_error += error;
            }
        }
        let ring_within = ring_error.reduce_add().abs() <= tolerance * rest as f32;
        let within = ring_within && !tet_outside_tolerance.any();
        self.ring_corrected.set(p, !within);
        if within {
            return false;
        }
        if !computed {
            for (group, lanes) in work.tets[..groups].iter_mut().enumerate() {
                *lanes = ring_group_lanes(&work.predicted, ring_v0, corners, group).0;
            }
        }
        true
    }

    /// Each tet's directions `d_i = -w_i C_t grad_i`, summed per particle of ring `p` into
    /// `work.directions` in ring order. Returns the ring's step limit from its stiffest tet,
    /// or `None` if no particle would move.
    #[inline(always)]
    fn ring_directions(&self, work: &mut RingWork, p: usize, groups: usize) -> Option<f64> {
        let corners = self.mesh.ring_corners(p);
        let vertices = self.mesh.ring_vertices(p);
        for (k, &i) in vertices.iter().enumerate() {
            work.inv_masses[k] = self.inv_masses[i as usize];
            work.directions[k] = Vec3::ZERO;
        }
        // The stiffest tet sets the ring's step limit: `1 / max(stiffness)`, one division.
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
        moves.any().then_some(tet_step)
    }
}

/// A ring's volume polynomial along its directions in `work`, as a cubic in the step `s`:
/// `sum_t V_t(s) - rest`.
#[inline(always)]
fn ring_polynomial(work: &RingWork, corners: &[[u16; 4]], groups: usize, rest: f64) -> Cubic {
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
    [
        total(0) - rest,
        total(1),
        total(2) * sixth,
        total(3) * sixth,
    ]
}
