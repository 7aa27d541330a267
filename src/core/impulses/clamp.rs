//! The neighbour clamp (section 4): an impulse shortened so that no tet it touches falls below
//! its floor, answered from the clamp bounds where they suffice.

use super::*;

impl VolumePass<'_> {
    /// Volume polynomial of `tet` when its particles move from their predicted positions along
    /// the directions held in `scratch` (zero for particles that do not move).
    #[inline]
    pub(super) fn moved_volume(&self, tet: [u32; 4]) -> Cubic {
        let xp = tet.map(|i| self.predicted_position(i));
        let d = tet.map(|i| self.scratch.get(i as usize));
        volume_polynomial(&xp, &d)
    }

    /// The neighbour clamp of an impulse that moves `vertices` by `step` times `directions` (in
    /// the same order; `largest_move` the longest of them), whose clamp region `region` is
    /// `whole_region`: the step shortened so that no tet of the region falls below its floor.
    /// The [`SafeRadii`] answer first, with the largest drift seen in the pass, which costs
    /// nothing; if that is not enough, one vertex at a time; only the one-rings of the vertices
    /// that still are not clear are walked.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn clamp<'a>(
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
    pub(super) fn find_unclear<'u>(
        &self,
        vertices: &[u32],
        step: f32,
        unclear: &'u mut [u32],
    ) -> &'u [u32] {
        let (b, mesh) = (self.bounds, self.mesh);
        let mut count = 0;
        for &v in vertices {
            let reach = mesh
                .ring_vertices(v as usize)
                .iter()
                .map(|&i| self.drift.get(i as usize) + step * self.move_len.get(i as usize))
                .fold(0.0f32, larger);
            let v = v as usize;
            // A broken (NaN) predicted position clears nothing.
            if reach >= b.vertex_radius.get(v) || reach.is_nan() {
                unclear[count] = v as u32;
                count += 1;
            }
        }
        &unclear[..count]
    }

    /// The neighbour clamp over the one-rings of the `unclear` vertices of
    /// [`VolumePass::find_unclear`], each tet once (the one-rings overlap; see [`WalkMarks`]).
    ///
    /// Each tet is first held against its radius with the reach of its four particles, taken
    /// from the ring's reaches (`reach`, one per ring vertex, computed once per vertex): the
    /// same test `neighbour_clamp` starts with, but on data gathered for the ring instead of
    /// from the body's arrays through each tet's vertex indices, and before the tet is marked
    /// walked. Most tets of a walk pass it (nine in ten under the cube's sphere). The reaches
    /// are taken with the step as it was when the vertex's walk began; a shorter step only
    /// shortens them, and `neighbour_clamp` tests again with the current one, so the tets that
    /// reach the cubics, and the result, are those of walking every tet.
    pub(super) fn clamp_unclear(&self, unclear: &[u32], mut step: f64, reach: &mut [f32]) -> f64 {
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
    pub(super) fn neighbour_clamp<'a>(
        &self,
        tets: impl Iterator<Item = &'a u32>,
        mut step: f64,
    ) -> f64 {
        let mesh = self.mesh;
        let b = self.bounds;
        for &t in tets {
            let tet = mesh.tets()[t as usize];
            // This tet alone, against its own start-of-pass bounds (see [`SafeRadii`]), with
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
            let xp = tet.map(|i| self.predicted_position(i));
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
    pub(super) fn set_move_lengths(&self, vertices: &[u32], set: bool) {
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

    pub(super) fn clear_directions(&self, vertices: &[u32]) {
        for &i in vertices {
            self.scratch.set(i as usize, Vec3::ZERO);
        }
    }
}
