//! The per-tet impulse (section 4), four tets that share no vertex at once.

use super::*;

impl VolumePass<'_> {
    /// The per-tet impulses of a bundle of [`LANES`] tets that share no vertex (see
    /// [`Blocks::tet_bundles`]; [`NO_TET`] marks an empty lane), one after another: each tet's
    /// four particles move by `gamma * s * d_i`, `s` being the smallest positive root of
    /// `V_t(s) = V0_t`. `corners` and `rest_volumes` are the bundle's tets' (see
    /// [`Blocks::bundle_corners`]). Needs `refresh_predicted` first.
    ///
    /// No impulse of the bundle moves a particle another of its tets reads, so the volumes,
    /// directions and cubics of all four are computed at once in SIMD lanes ([`Vec3x4`]) from
    /// the predicted positions as they are before the first; only the roots, the clamps (whose regions
    /// overlap) and the velocity changes go lane by lane, in order.
    ///
    /// [`Blocks::tet_bundles`]: super::tet_mesh::Blocks::tet_bundles
    /// [`Blocks::bundle_corners`]: super::tet_mesh::Blocks::bundle_corners
    /// [`NO_TET`]: super::tet_mesh::NO_TET
    pub(super) fn tet_bundle(
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
        let corner = |k: usize| self.predicted.gather(tets.map(|t| t[k] as usize));
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
        let original = d;
        if self.any_touching {
            self.constrain_directions_in_lanes(&tets, &mut d);
        }
        let f = [d[0] - d[3], d[1] - d[3], d[2] - d[3]];
        let [c1, c2, c3] = volume_polynomial_lanes([ea, eb, ec], [ga, gb, gc], f);
        let (volume, v0) = (volume.to_array(), v0.to_array());
        let (c1, c2, c3) = (c1.to_array(), c2.to_array(), c3.to_array());
        let d = d.map(Vec3x4::to_vecs);
        let original = original.map(Vec3x4::to_vecs);
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
            // An inverted tet gets its whole correction (see `INVERTED_TET_GAMMA`).
            let full = if volume[l] <= 0.0 {
                INVERTED_TET_GAMMA
            } else {
                gamma
            } * root;
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
                let removed = scale * (original[k][l] - dl[k]);
                self.apply_velocity_change(worker, tet[k] as usize, scale * dl[k], removed);
            }
            outcomes[l] = ImpulseOutcome::Applied {
                step,
                root,
                clamped,
            };
        }
        outcomes
    }

    /// `constrain_direction` in lanes, on the four corners' directions `d` of the bundle's
    /// `tets`: a particle touching nothing has a zero normal, so its direction is unchanged.
    #[inline(always)]
    fn constrain_directions_in_lanes(&self, tets: &[[u32; 4]; LANES], d: &mut [Vec3x4; 4]) {
        for (k, dk) in d.iter_mut().enumerate() {
            let normal = Vec3x4::from_vecs(std::array::from_fn(|l| {
                self.contact_normals[tets[l][k] as usize]
            }));
            let kept = f32x4::new(std::array::from_fn(|l| {
                self.contact_kept[tets[l][k] as usize]
            }));
            let into = dk.dot(normal).min(f32x4::ZERO);
            *dk = *dk - normal.scale(into * (f32x4::ONE - kept));
            if let Some(second) = self.contact_second {
                // `constrained_push`'s second surface, in lanes.
                let second =
                    Vec3x4::from_vecs(std::array::from_fn(|l| second[tets[l][k] as usize]));
                let into = dk.dot(second);
                let pushed = *dk - second.scale(into.min(f32x4::ZERO));
                let edge = normal.cross(second);
                let along = edge.scale(
                    pushed.dot(edge) / edge.length_squared().max(f32x4::splat(f32::MIN_POSITIVE)),
                );
                let back_in = into.cmp_lt(f32x4::ZERO)
                    & pushed.dot(normal).cmp_lt(f32x4::ZERO)
                    & kept.cmp_eq(f32x4::ZERO);
                *dk = Vec3x4 {
                    x: back_in.blend(along.x, pushed.x),
                    y: back_in.blend(along.y, pushed.y),
                    z: back_in.blend(along.z, pushed.z),
                };
            }
        }
    }
}
