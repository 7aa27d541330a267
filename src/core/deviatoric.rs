//! The tet shape model of a physical material: per tet, Saint Venant-Kirchhoff's deviatoric
//! energy and a compressible hydrostatic one, solved as XPBD constraints in the substeps, so
//! that the shape solve holds the shape, resists volume change as the real material does, and
//! leaves the rest of the volume to the paper's impulses.
//!
//! Each tet's deformation gradient is `F = Ds Dm^-1` (`Ds` its edges from vertex 0 now, `Dm`
//! at rest), its Green strain `E = (F^T F - I) / 2`. The energy is
//! `V0 (mu |dev E|^2 + K/2 (det F - 1)^2)` with the shear and bulk moduli of the material's
//! Young's modulus and Poisson's ratio. In an orthonormal basis `B_k` of the symmetric
//! traceless matrices, `mu |dev E|^2` is the sum of five squares `c_k = <B_k, E>`, each an
//! XPBD constraint of compliance `1 / (2 mu V0)`; `det F - 1` is one of compliance
//! `1 / (K V0)`. They are projected in turn within the tet (Gauss-Seidel: projecting the five
//! together from one `F` is cheaper but overshoots on flat tets). Five constraints rather than one on `|dev E|`: that one has no gradient at zero
//! strain, which stiff materials keep crossing. The gradient of a constraint on `F` is a
//! matrix `A` (`F B_k` for `c_k`, the cofactor of `F` for `det F`), its part on corner `i` is
//! `A g_i` (`g_i` the corner's row of `Dm^-1`, `g_0` minus their sum), and a projection moves
//! `F` by `dlambda A S` with `S = sum w_i g_i g_i^T`: `F` is kept current without re-reading
//! the positions.
//!
//! The tets are projected four at a time in SIMD lanes (`ShapeBundle`: four tets that share
//! no vertex, the same result as one after another), in bundles taken in index order: a sweep
//! in index order carries a correction across the mesh in one pass, which the volume passes'
//! blocks' order does not (PERFORMANCE.md).
//!
//! Why not the edges: a spring network has a Poisson's ratio of 1/4, so under a load the
//! edges pull the volume towards their own equilibrium, every substep, against the impulses,
//! and on an irregular mesh their stiffness is as irregular as the mesh (PERFORMANCE.md).
//! The deviatoric stress is traceless:
//! it does no work on a change of volume, so it leaves the volume where the impulses put it
//! (its projection, weighted by the corners' masses, still moves a tet's volume a little); the
//! hydrostatic one pulls only towards the rest volume.
//!
//! Damping is XPBD's (Macklin et al. 2016, eq. 26), `gamma = beta / h_s`, on every constraint.

use std::f32::consts::FRAC_1_SQRT_2;

use glam::{Mat3, Vec3};
use wide::f32x4;

use super::lanes::{LANES, Point4, Vec3x4};
#[cfg(doc)]
use super::material::ElasticSettings;
use super::tet_mesh::TetMesh;

/// The basis `B_k` of the deviatoric constraints, orthonormal under the Frobenius product:
/// `(e_x e_x - e_y e_y) / sqrt 2`, `(e_x e_x + e_y e_y - 2 e_z e_z) / sqrt 6`, and
/// `(e_a e_b + e_b e_a) / sqrt 2` for the pairs xy, xz, yz. `project_tet_shapes` writes
/// `F B_k` out by this structure; the test checks it against these matrices.
#[cfg(test)]
const DEVIATORIC_BASIS: [[[f32; 3]; 3]; 5] = {
    const S2: f32 = std::f32::consts::FRAC_1_SQRT_2;
    const S6: f32 = 0.408_248_3;
    [
        [[S2, 0.0, 0.0], [0.0, -S2, 0.0], [0.0, 0.0, 0.0]],
        [[S6, 0.0, 0.0], [0.0, S6, 0.0], [0.0, 0.0, -2.0 * S6]],
        [[0.0, S2, 0.0], [S2, 0.0, 0.0], [0.0, 0.0, 0.0]],
        [[0.0, 0.0, S2], [0.0, 0.0, 0.0], [S2, 0.0, 0.0]],
        [[0.0, 0.0, 0.0], [0.0, 0.0, S2], [0.0, S2, 0.0]],
    ]
};

/// Three columns of [`Vec3x4`]: a 3x3 matrix per lane.
#[derive(Clone, Copy, Debug)]
struct Mat3x4([Vec3x4; 3]);

impl Mat3x4 {
    const ZERO: Mat3x4 = Mat3x4([Vec3x4::ZERO; 3]);

    /// `sum_k x_k g_k^T`: a tet's `F` from its corners and their gradients.
    #[inline(always)]
    fn deformation(x: &[Vec3x4; 4], g: &[Vec3x4; 4]) -> Mat3x4 {
        let column = |c: fn(&Vec3x4) -> f32x4| {
            (x[0].scale(c(&g[0])) + x[1].scale(c(&g[1])))
                + (x[2].scale(c(&g[2])) + x[3].scale(c(&g[3])))
        };
        Mat3x4([column(|v| v.x), column(|v| v.y), column(|v| v.z)])
    }

    /// The Frobenius inner product, per lane.
    #[inline(always)]
    fn frobenius(&self, other: &Mat3x4) -> f32x4 {
        self.0[0].dot(other.0[0]) + self.0[1].dot(other.0[1]) + self.0[2].dot(other.0[2])
    }

    #[inline(always)]
    fn mul_vec(&self, v: Vec3x4) -> Vec3x4 {
        self.0[0].scale(v.x) + self.0[1].scale(v.y) + self.0[2].scale(v.z)
    }

    /// `self S` for a symmetric `S` given by its six entries (see [`ShapeBundle::gram`]).
    #[inline(always)]
    fn mul_sym(&self, s: &[f32x4; 6]) -> Mat3x4 {
        let [xx, yy, zz, xy, xz, yz] = *s;
        Mat3x4([
            self.mul_vec(Vec3x4 {
                x: xx,
                y: xy,
                z: xz,
            }),
            self.mul_vec(Vec3x4 {
                x: xy,
                y: yy,
                z: yz,
            }),
            self.mul_vec(Vec3x4 {
                x: xz,
                y: yz,
                z: zz,
            }),
        ])
    }

    #[inline(always)]
    fn add_scaled(&mut self, other: &Mat3x4, s: f32x4) {
        for (a, b) in self.0.iter_mut().zip(&other.0) {
            *a = *a + b.scale(s);
        }
    }

    #[inline(always)]
    fn sub(&self, other: &Mat3x4) -> Mat3x4 {
        Mat3x4(std::array::from_fn(|c| self.0[c] - other.0[c]))
    }

    /// The cofactor matrix, `det F F^-T`: the gradient of `det F`.
    #[inline(always)]
    fn cofactor(&self) -> Mat3x4 {
        let [x, y, z] = self.0;
        Mat3x4([y.cross(z), z.cross(x), x.cross(y)])
    }

    /// `F B_k`, the gradient of the deviatoric constraint `k` on `F`, written out by the
    /// basis' structure (see `DEVIATORIC_BASIS`).
    #[inline(always)]
    fn deviatoric_gradient(&self, k: usize) -> Mat3x4 {
        let (s2, s6) = (f32x4::splat(FRAC_1_SQRT_2), f32x4::splat(INV_SQRT_6));
        let [x, y, z] = self.0;
        let zero = Vec3x4::ZERO;
        Mat3x4(match k {
            0 => [x.scale(s2), y.scale(-s2), zero],
            1 => [x.scale(s6), y.scale(s6), z.scale(f32x4::splat(-2.0) * s6)],
            2 => [y.scale(s2), x.scale(s2), zero],
            3 => [z.scale(s2), zero, x.scale(s2)],
            _ => [zero, z.scale(s2), y.scale(s2)],
        })
    }
}

const INV_SQRT_6: f32 = 0.408_248_3;

/// [`LANES`] tets that share no vertex, with what the shape projection reads of them in lanes:
/// no projection of a bundle moves a particle another of its tets reads, so the four are
/// projected at once and the result is that of projecting them one after another.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ShapeBundle {
    /// The corners by corner and lane: `[k][l]` is corner `k` of lane `l` (0 in a lane holding
    /// no tet).
    pub(crate) corners: [[usize; LANES]; 4],
    /// Whether each lane holds a tet.
    pub(crate) filled: [bool; LANES],
    /// Each corner's `g_k` (see the module's doc); zero in an empty lane.
    gradients: [Vec3x4; 4],
    /// Rest volumes (0 in an empty lane).
    pub(crate) rest_volume: f32x4,
    /// Each corner's inverse mass this step (0 in an empty lane).
    pub(crate) inv_masses: [f32x4; 4],
    /// `S = sum w_k g_k g_k^T` this step, as `[xx, yy, zz, xy, xz, yz]`.
    gram: [f32x4; 6],
}

/// The mesh's tets in bundles (see [`ShapeBundle`]), their inverse masses and Gram matrices
/// left for [`refresh_shape_bundles`].
pub(crate) fn shape_bundles(mesh: &TetMesh) -> Vec<ShapeBundle> {
    let x = mesh.positions();
    let tets = mesh.tets();
    // Bundles in index order: each takes the first tet not yet taken and the next ones (at
    // most `LOOK_AHEAD` further) that share no vertex with it.
    const LOOK_AHEAD: usize = 64;
    let mut taken = vec![false; tets.len()];
    let mut bundles: Vec<[Option<usize>; LANES]> = Vec::new();
    for first in 0..tets.len() {
        if taken[first] {
            continue;
        }
        let mut bundle = [None; LANES];
        let mut count = 0;
        for t in first..tets.len().min(first + LOOK_AHEAD) {
            if count == LANES {
                break;
            }
            let shares =
                |u: &Option<usize>| u.is_some_and(|u| tets[u].iter().any(|i| tets[t].contains(i)));
            if !taken[t] && !bundle.iter().any(shares) {
                bundle[count] = Some(t);
                taken[t] = true;
                count += 1;
            }
        }
        bundles.push(bundle);
    }
    bundles
        .into_iter()
        .map(|bundle| {
            let filled = bundle.map(|t| t.is_some());
            let corners: [[u32; 4]; LANES] = bundle.map(|t| t.map_or([0; 4], |t| tets[t]));
            let volumes: [f32; LANES] = bundle.map(|t| t.map_or(0.0, |t| mesh.rest_volumes()[t]));
            let g: [[Vec3; 4]; LANES] = std::array::from_fn(|l| {
                if !filled[l] {
                    return [Vec3::ZERO; 4];
                }
                let p = corners[l].map(|i| x[i as usize]);
                let dm = Mat3::from_cols(p[1] - p[0], p[2] - p[0], p[3] - p[0]);
                // The mesh holds no degenerate tet; a broken inverse would only stop this one.
                let inverse = dm.inverse();
                let gt = if inverse.is_finite() {
                    inverse.transpose()
                } else {
                    Mat3::ZERO
                };
                [
                    -(gt.x_axis + gt.y_axis + gt.z_axis),
                    gt.x_axis,
                    gt.y_axis,
                    gt.z_axis,
                ]
            });
            ShapeBundle {
                corners: std::array::from_fn(|k| corners.map(|c| c[k] as usize)),
                filled,
                gradients: std::array::from_fn(|k| Vec3x4::from_vecs(g.map(|g| g[k]))),
                rest_volume: f32x4::new(volumes),
                inv_masses: [f32x4::ZERO; 4],
                gram: [f32x4::ZERO; 6],
            }
        })
        .collect()
}

/// Each bundle's inverse masses and Gram matrices for this step's inverse masses `w` by
/// particle (kinematic particles have none).
pub(crate) fn refresh_shape_bundles(bundles: &mut [ShapeBundle], w: &[f32]) {
    for b in bundles {
        b.inv_masses = std::array::from_fn(|k| {
            f32x4::new(std::array::from_fn(|l| {
                if b.filled[l] { w[b.corners[k][l]] } else { 0.0 }
            }))
        });
        let mut s = [f32x4::ZERO; 6];
        for (g, &w) in b.gradients.iter().zip(&b.inv_masses) {
            let wg = g.scale(w);
            s[0] += wg.x * g.x;
            s[1] += wg.y * g.y;
            s[2] += wg.z * g.z;
            s[3] += wg.x * g.y;
            s[4] += wg.x * g.z;
            s[5] += wg.y * g.z;
        }
        b.gram = s;
    }
}

/// One pass over the tets' shape constraints (see the module's doc), bundle by bundle: per
/// tet the five deviatoric ones in turn, then the hydrostatic one. `compliance` is theirs
/// per unit volume (see [`ElasticSettings::tet_compliance`]), `hs2` the squared substep,
/// `gamma` XPBD's damping term; `start` the positions at the substep's start and `moves` how
/// far each particle has moved since, which the projection moves (a particle's position is
/// `start + moves`; see `SoftBodyState::substep_shape` for why it is kept apart). Needs
/// `refresh_shape_bundles` this step.
pub(crate) fn project_tet_shapes(
    bundles: &[ShapeBundle],
    moves: &mut [Vec3],
    start: &[Point4],
    compliance: [f32; 2],
    hs2: f32,
    gamma: f32,
) {
    let gamma = f32x4::splat(gamma);
    let one_plus_gamma = f32x4::ONE + gamma;
    let half = f32x4::splat(0.5);
    for b in bundles {
        let g = &b.gradients;
        // Written out, not mapped: a closure per lane was not inlined.
        let moved = |[a, b, c, d]: [usize; LANES]| {
            Vec3x4::from_vecs([moves[a], moves[b], moves[c], moves[d]])
        };
        let start_corner = |[a, b, c, d]: [usize; LANES]| {
            Vec3x4::from_rows([
                start[a].row(),
                start[b].row(),
                start[c].row(),
                start[d].row(),
            ])
        };
        let [l0, l1, l2, l3] = b.corners;
        let f_start = Mat3x4::deformation(
            &[
                start_corner(l0),
                start_corner(l1),
                start_corner(l2),
                start_corner(l3),
            ],
            g,
        );
        // `F` is linear in the corners: the start's plus the moves'.
        let mut f = f_start;
        let f_moves = Mat3x4::deformation(&[moved(l0), moved(l1), moved(l2), moved(l3)], g);
        f.add_scaled(&f_moves, f32x4::ONE);
        // Each constraint's compliance over `h_s^2`; infinite in an empty lane, whose
        // multipliers are then zero (and its corners have no mass).
        let scaled = b.rest_volume * f32x4::splat(hs2);
        let [deviatoric, hydrostatic] = compliance.map(|c| f32x4::splat(c) / scaled);
        // `total` is the sum of `lambda` times each constraint's gradient on `F`: the
        // corners move by `w_k total g_k` at the end.
        let mut total = Mat3x4::ZERO;
        let mut project = |grad: Mat3x4, constraint: f32x4, f: &mut Mat3x4, alpha: f32x4| {
            let gs = grad.mul_sym(&b.gram);
            let denominator = gs.frobenius(&grad);
            let rate = grad.frobenius(&f.sub(&f_start));
            let lambda = -(constraint + gamma * rate) / (one_plus_gamma * denominator + alpha);
            let lambda = lambda.is_finite().blend(lambda, f32x4::ZERO);
            total.add_scaled(&grad, lambda);
            f.add_scaled(&gs, lambda);
        };
        for k in 0..5 {
            let grad = f.deviatoric_gradient(k);
            // `<B_k, E>` = `<F B_k, F> / 2` (`B_k` is traceless).
            let constraint = half * grad.frobenius(&f);
            project(grad, constraint, &mut f, deviatoric);
        }
        let cofactor = f.cofactor();
        let det = f.0[0].dot(cofactor.0[0]);
        project(cofactor, det - f32x4::ONE, &mut f, hydrostatic);
        let corrections: [[Vec3; LANES]; 4] =
            std::array::from_fn(|k| total.mul_vec(g[k]).scale(b.inv_masses[k]).to_vecs());
        for (corners, corrections) in b.corners.iter().zip(&corrections) {
            let each = corners.iter().zip(corrections).zip(b.filled);
            for ((&i, &dx), _) in each.filter(|(_, f)| *f) {
                moves[i] += dx;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::core::body::SoftBodyState;
    use crate::core::material::SoftBodyMaterial;
    use crate::core::tet_mesh::TetMesh;

    fn basis(k: usize) -> Mat3 {
        Mat3::from_cols_array_2d(&DEVIATORIC_BASIS[k])
    }

    fn frobenius(a: &Mat3, b: &Mat3) -> f32 {
        a.x_axis.dot(b.x_axis) + a.y_axis.dot(b.y_axis) + a.z_axis.dot(b.z_axis)
    }

    /// `F B_k` as the projection computes it, in lane 0.
    fn deviatoric_gradient(f: &Mat3, k: usize) -> Mat3 {
        let lanes = Mat3x4([f.x_axis, f.y_axis, f.z_axis].map(Vec3x4::splat));
        let [x, y, z] = lanes.deviatoric_gradient(k).0.map(|c| c.to_vecs()[0]);
        Mat3::from_cols(x, y, z)
    }

    #[test]
    fn the_basis_is_orthonormal_symmetric_traceless_and_its_gradients_match_it() {
        let f = Mat3::from_cols(
            Vec3::new(1.1, 0.2, -0.3),
            Vec3::new(0.4, 0.9, 0.1),
            Vec3::new(-0.2, 0.5, 1.3),
        );
        for k in 0..5 {
            let b = basis(k);
            assert_eq!(b, b.transpose());
            assert!((b.x_axis.x + b.y_axis.y + b.z_axis.z).abs() < 1e-6);
            for l in 0..5 {
                let expected = if k == l { 1.0 } else { 0.0 };
                assert!(
                    (frobenius(&b, &basis(l)) - expected).abs() < 1e-6,
                    "{k} {l}"
                );
            }
            let (got, want) = (deviatoric_gradient(&f, k), f * b);
            assert!(
                (got - want).abs_diff_eq(Mat3::ZERO, 1e-6),
                "{k}: {got} {want}"
            );
        }
    }

    /// One tet, its corners moved by `deform`, projected once with no damping.
    fn project_once(deform: impl Fn(Vec3) -> Vec3, compliance: [f32; 2]) -> (SoftBodyState, f32) {
        let rest = vec![Vec3::ZERO, Vec3::X, Vec3::Y * 0.8, Vec3::new(0.2, 0.3, 1.1)];
        let mesh = Arc::new(TetMesh::new(rest, vec![[0, 1, 2, 3]]).unwrap());
        let mut body = SoftBodyState::new(mesh, SoftBodyMaterial::JELLY).unwrap();
        body.masses = vec![1.0, 2.0, 3.0, 4.0];
        body.inv_masses = body.masses.iter().map(|m| 1.0 / m).collect();
        body.map_positions(&deform);
        for (p, &x) in body.scratch.predicted.iter_mut().zip(&body.positions) {
            *p = super::super::lanes::Point4::new(x);
        }
        refresh_shape_bundles(&mut body.scratch.shape_bundles, &body.inv_masses);
        let before = body.volume_metrics().volume as f32;
        let mut moves = vec![Vec3::ZERO; 4];
        project_tet_shapes(
            &body.scratch.shape_bundles,
            &mut moves,
            &body.scratch.predicted,
            compliance,
            1e-4,
            0.0,
        );
        for (x, dx) in body.positions.iter_mut().zip(&moves) {
            *x += *dx;
        }
        (body, before)
    }

    fn momentum(body: &SoftBodyState, deform: impl Fn(Vec3) -> Vec3) -> Vec3 {
        body.positions
            .iter()
            .zip(body.mesh.positions().iter().map(|&r| deform(r)))
            .zip(&body.masses)
            .map(|((&x, r), &m)| m * (x - r))
            .sum()
    }

    #[test]
    fn a_rotated_tet_is_left_alone() {
        let rotation = glam::Quat::from_euler(glam::EulerRot::XYZ, 0.7, -1.2, 2.1);
        let deform = |p: Vec3| rotation * p + Vec3::new(3.0, -1.0, 2.0);
        let (body, _) = project_once(deform, [1e-6, 1e-6]);
        for (x, r) in body.positions.iter().zip(body.mesh.positions()) {
            assert!(x.distance(deform(*r)) < 1e-5, "{x} {}", deform(*r));
        }
    }

    #[test]
    fn a_sheared_tet_is_sheared_back_keeping_its_momentum() {
        // A small shear: one pass of the deviatoric constraints alone (no hydrostatic
        // stiffness), nearly rigid, removes more than half of it (the five are coupled through
        // the corners' unequal masses, so one Gauss-Seidel pass does not remove all) and moves
        // the centre of mass nowhere.
        let shear = |p: Vec3| p + Vec3::X * (0.02 * p.y);
        let (body, _) = project_once(shear, [1e-6, f32::INFINITY]);
        assert!(momentum(&body, shear).length() < 1e-6);
        let f = |body: &SoftBodyState| {
            let tet = body.mesh.tets()[0];
            let [x, r] = [&body.positions, body.mesh.positions()]
                .map(|p| tet.map(|i| p[i as usize]))
                .map(|x| Mat3::from_cols(x[1] - x[0], x[2] - x[0], x[3] - x[0]));
            x * r.inverse()
        };
        // |dev E|: about 0.02 / sqrt 2 for the shear.
        let deviatoric_strain = |f: Mat3| {
            let e = (f.transpose() * f - Mat3::IDENTITY) * 0.5;
            (0..5)
                .map(|k| frobenius(&basis(k), &e).powi(2))
                .sum::<f32>()
                .sqrt()
        };
        let sheared = deviatoric_strain(Mat3::from_cols_array(&[
            1.0, 0.0, 0.0, 0.02, 1.0, 0.0, 0.0, 0.0, 1.0,
        ]));
        assert!(
            (sheared - 0.02 * std::f32::consts::FRAC_1_SQRT_2).abs() < 1e-4,
            "{sheared}"
        );
        let after = deviatoric_strain(f(&body));
        assert!(after < 0.5 * sheared, "{sheared} -> {after}");
    }

    #[test]
    fn a_compressed_tet_is_pushed_back_towards_its_rest_volume() {
        let squash = |p: Vec3| p * 0.9;
        let (body, before) = project_once(squash, [1e-6, 1e-6]);
        assert!(momentum(&body, squash).length() < 1e-6);
        let rest = body.mesh.total_rest_volume() as f32;
        let after = body.volume_metrics().volume as f32;
        assert!(
            (after - rest).abs() < 0.1 * (before - rest).abs(),
            "{before} -> {after}"
        );
    }
}
