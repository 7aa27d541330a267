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
//! `1 / (K V0)`. They are projected in turn within the tet (Gauss-Seidel; projecting the five
//! together from one `F` is cheaper but overshoots on flat tets: a graded hard rubber cube ran
//! away). Five constraints rather than one on `|dev E|`: that one has no gradient at zero
//! strain, which stiff materials keep crossing. The gradient of a constraint on `F` is a
//! matrix `A` (`F B_k` for `c_k`, the cofactor of `F` for `det F`), its part on corner `i` is
//! `A g_i` (`g_i` the corner's row of `Dm^-1`, `g_0` minus their sum), and a projection moves
//! `F` by `dlambda A S` with `S = sum w_i g_i g_i^T`: `F` is kept current without re-reading
//! the positions.
//!
//! Why not the edges: a spring network has a Poisson's ratio of 1/4, so under a load the
//! edges pull the volume towards their own equilibrium, every substep, against the impulses,
//! and on an irregular mesh their stiffness is as irregular as the mesh (a graded jelly cube
//! peaked at 3-13 % with them, 0.6-0.9 % with this model). The deviatoric stress is traceless:
//! it does no work on a change of volume, so it leaves the volume where the impulses put it
//! (its projection, weighted by the corners' masses, still moves a tet's volume a little); the
//! hydrostatic one pulls only towards the rest volume.
//!
//! Damping is XPBD's (Macklin et al. 2016, eq. 26), `gamma = beta / h_s`, on every constraint.

use glam::{Mat3, Vec3};

use super::body::SoftBodyState;
#[cfg(doc)]
use super::material::ElasticSettings;

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

/// `F B_k`, the gradient of the deviatoric constraint `k` on `F`, written out by the basis'
/// structure (see `DEVIATORIC_BASIS`).
#[inline]
fn deviatoric_gradient(f: &Mat3, k: usize) -> Mat3 {
    const S2: f32 = std::f32::consts::FRAC_1_SQRT_2;
    const S6: f32 = 0.408_248_3;
    let (fx, fy, fz) = (f.x_axis, f.y_axis, f.z_axis);
    match k {
        0 => Mat3::from_cols(fx * S2, fy * -S2, Vec3::ZERO),
        1 => Mat3::from_cols(fx * S6, fy * S6, fz * (-2.0 * S6)),
        2 => Mat3::from_cols(fy * S2, fx * S2, Vec3::ZERO),
        3 => Mat3::from_cols(fz * S2, Vec3::ZERO, fx * S2),
        _ => Mat3::from_cols(Vec3::ZERO, fz * S2, fy * S2),
    }
}

/// The Frobenius inner product.
#[inline]
fn frobenius(a: &Mat3, b: &Mat3) -> f32 {
    a.x_axis.dot(b.x_axis) + a.y_axis.dot(b.y_axis) + a.z_axis.dot(b.z_axis)
}

/// Each tet's `Dm^-1` (its rest edges from vertex 0 as columns, inverted); the identity for a
/// degenerate tet, which the mesh does not hold.
pub(crate) fn rest_inverses(positions: &[Vec3], tets: &[[u32; 4]]) -> Vec<Mat3> {
    tets.iter()
        .map(|t| {
            let p = t.map(|i| positions[i as usize]);
            let dm = Mat3::from_cols(p[1] - p[0], p[2] - p[0], p[3] - p[0]);
            let inverse = dm.inverse();
            if inverse.is_finite() {
                inverse
            } else {
                Mat3::IDENTITY
            }
        })
        .collect()
}

/// A symmetric 3x3 matrix by its six entries: `[xx, yy, zz, xy, xz, yz]`.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Sym3([f32; 6]);

impl Sym3 {
    /// `sum w_i g_i g_i^T` over a tet's corners: the Gram matrix a projection's `F` moves by.
    fn gram(g: &[Vec3; 4], w: &[f32; 4]) -> Sym3 {
        let mut s = [0.0; 6];
        for (g, &w) in g.iter().zip(w) {
            s[0] += w * g.x * g.x;
            s[1] += w * g.y * g.y;
            s[2] += w * g.z * g.z;
            s[3] += w * g.x * g.y;
            s[4] += w * g.x * g.z;
            s[5] += w * g.y * g.z;
        }
        Sym3(s)
    }

    fn mat3(&self) -> Mat3 {
        let [xx, yy, zz, xy, xz, yz] = self.0;
        Mat3::from_cols(
            Vec3::new(xx, xy, xz),
            Vec3::new(xy, yy, yz),
            Vec3::new(xz, yz, zz),
        )
    }
}

/// A tet's `g_i` (see the module's doc) from its `Dm^-1`.
#[inline]
fn corner_gradients(dm_inv: &Mat3) -> [Vec3; 4] {
    let gt = dm_inv.transpose();
    [
        -(gt.x_axis + gt.y_axis + gt.z_axis),
        gt.x_axis,
        gt.y_axis,
        gt.z_axis,
    ]
}

impl SoftBodyState {
    /// Each tet's Gram matrix `S` for this step's inverse masses (kinematic particles have none).
    pub(crate) fn refresh_tet_grams(&mut self) {
        let w = &self.inv_masses;
        for ((gram, tet), dm_inv) in self
            .tet_grams
            .iter_mut()
            .zip(self.mesh.tets())
            .zip(&self.tet_rest_inverses)
        {
            let wt = tet.map(|i| w[i as usize]);
            *gram = Sym3::gram(&corner_gradients(dm_inv), &wt);
        }
    }

    /// One pass over the tets' shape constraints (see the module's doc), in index order: per
    /// tet the five deviatoric ones in turn, then the hydrostatic one. `compliance` is theirs
    /// per unit volume (see [`ElasticSettings::tet_compliance`]), `hs2` the squared substep,
    /// `gamma` XPBD's damping term. Each tet's
    /// `Dm^-1` and Gram matrix are from `refresh_tet_grams`, this step.
    pub(crate) fn project_tet_shapes(&mut self, compliance: [f32; 2], hs2: f32, gamma: f32) {
        let x = &mut self.positions;
        let start = &self.previews;
        let w = &self.inv_masses;
        for (((tet, &v0), dm_inv), gram) in self
            .mesh
            .tets()
            .iter()
            .zip(self.mesh.rest_volumes())
            .zip(&self.tet_rest_inverses)
            .zip(&self.tet_grams)
        {
            let corners = tet.map(|i| i as usize);
            let wt = corners.map(|i| w[i]);
            if wt == [0.0; 4] {
                continue;
            }
            let deformation =
                |p: [Vec3; 4]| Mat3::from_cols(p[1] - p[0], p[2] - p[0], p[3] - p[0]) * *dm_inv;
            let mut f = deformation(corners.map(|i| x[i]));
            let f_start = deformation(corners.map(|i| start[i].vec3()));
            let s = gram.mat3();
            // `total` is the sum of `lambda` times each constraint's gradient on `F`: the
            // corners move by `w_i total g_i` at the end.
            let mut total = Mat3::ZERO;
            let mut project = |grad: Mat3, constraint: f32, f: &mut Mat3, compliance: f32| {
                let gs = grad * s;
                let denominator = frobenius(&gs, &grad);
                let rate = frobenius(&grad, &(*f - f_start));
                let lambda =
                    -(constraint + gamma * rate) / ((1.0 + gamma) * denominator + compliance / hs2);
                if lambda.is_finite() {
                    total += grad * lambda;
                    *f += gs * lambda;
                }
            };
            let [deviatoric, hydrostatic] = compliance.map(|c| c / v0);
            for k in 0..5 {
                let grad = deviatoric_gradient(&f, k);
                // `<B_k, E>` = `<F B_k, F> / 2` (`B_k` is traceless).
                let constraint = 0.5 * frobenius(&grad, &f);
                project(grad, constraint, &mut f, deviatoric);
            }
            let cofactor = Mat3::from_cols(
                f.y_axis.cross(f.z_axis),
                f.z_axis.cross(f.x_axis),
                f.x_axis.cross(f.y_axis),
            );
            project(cofactor, f.determinant() - 1.0, &mut f, hydrostatic);
            for ((&i, g), w) in corners.iter().zip(corner_gradients(dm_inv)).zip(wt) {
                x[i] += total * g * w;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::core::material::SoftBodyMaterial;
    use crate::core::tet_mesh::TetMesh;

    fn basis(k: usize) -> Mat3 {
        Mat3::from_cols_array_2d(&DEVIATORIC_BASIS[k])
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
        for (p, &x) in body.previews.iter_mut().zip(&body.positions) {
            *p = super::super::lanes::Point4::new(x);
        }
        body.refresh_tet_grams();
        let before = body.volume_metrics().volume as f32;
        body.project_tet_shapes(compliance, 1e-4, 0.0);
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
            let x = body.mesh.tets()[0].map(|i| body.positions[i as usize]);
            Mat3::from_cols(x[1] - x[0], x[2] - x[0], x[3] - x[0]) * body.tet_rest_inverses[0]
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
