//! XPBD's projections: the peer the paper's method is measured against (see
//! [`VolumeMethod::Xpbd`]), and the edges that are the shape solve of a physical material with
//! plastic springs. The substeps they run in are the step's (`substep.rs`).
//!
//! Each step is split into substeps. A substep predicts every particle's position from its
//! velocity and gravity, projects every edge constraint `C = (L - L0) / L0` with compliance
//! `1 / k_D` of that edge (so that its energy is the springs' `1/2 k_D C^2`) and every tet's volume
//! constraint `C = (V - V0) / V0` with zero compliance, once each in Gauss-Seidel order (one
//! iteration; with a fresh multiplier per substep, as "Small Steps" does), derives the velocities
//! from the motion, resolves contacts on them with the same code the other methods use, and
//! damps the springs. Momentum is conserved by every projection (the constraint gradients sum
//! to zero).
//!
//! A physical material's constraints are damped inside their projection, in XPBD's own form
//! (Macklin et al. 2016, eq. 26): with stiffness-proportional damping `beta` the damping term of
//! a constraint is `gamma = beta / h_s`, the same for every constraint, and the projection
//! solves the constraint and its damper together, implicitly. A separate pass of velocity
//! dampers after the projection (what the paper's explicit springs keep) is unstable for stiff
//! materials (PERFORMANCE.md).
//!
//! Decisions: gravity is applied per substep (stored by `apply_forces`, which adds no spring
//! forces for this method); kinematic particles move to their target in equal parts; a rigid
//! sphere is tested at its position advanced to each substep at its current velocity, and left
//! where it was for the plugin to integrate; damping and drag act per substep.
//!
//! [`VolumeMethod::Xpbd`]: super::material::VolumeMethod::Xpbd

use glam::Vec3;

use super::geometry::{signed_volume, volume_gradients};
use super::lanes::Point4;
use super::tet_mesh::TetMesh;

/// The edges as XPBD constraints: each edge's rest length and compliance (`1 / k_D`).
pub(crate) struct EdgeConstraints<'a> {
    pub(crate) rest: &'a [f32],
    pub(crate) compliance: &'a [f32],
}

/// One Gauss-Seidel pass over the edge constraints of `mesh` on the positions `x` (from
/// `start`, where the substep began), each of compliance `compliance / hs2` (`hs2` the squared
/// substep), in the blocks' order of the springs (see
/// [`Blocks::edges`](super::tet_mesh::Blocks::edges)): the same order the other methods'
/// dampers take, where consecutive constraints share no particle and do not wait for each
/// other's results. An edge of zero stiffness (infinite compliance) is skipped. `gamma` is
/// XPBD's damping term (see the module's doc): the projection is
/// `dlambda = -(C + gamma grad C . (x - x_start)) / ((1 + gamma) w / L0^2 + alpha)`, the
/// undamped one when it is zero.
pub(crate) fn project_edges(
    x: &mut [Vec3],
    start: &[Point4],
    mesh: &TetMesh,
    inv_masses: &[f32],
    edges: EdgeConstraints,
    hs2: f32,
    gamma: f32,
) {
    let pairs = mesh.edges();
    for &e in mesh.blocks().edges.items() {
        let e = e as usize;
        let [i, j] = pairs[e];
        let (i, j) = (i as usize, j as usize);
        let (wi, wj) = (inv_masses[i], inv_masses[j]);
        let alpha = edges.compliance[e] / hs2;
        if wi + wj == 0.0 || !alpha.is_finite() {
            continue;
        }
        let d = x[j] - x[i];
        let length = d.length();
        let rest = edges.rest[e];
        if length <= f32::EPSILON * rest {
            continue;
        }
        let n = d / length;
        let c = (length - rest) / rest;
        let lambda = if gamma > 0.0 {
            let rate = n.dot((x[j] - start[j].vec3()) - (x[i] - start[i].vec3())) / rest;
            -(c + gamma * rate) / ((1.0 + gamma) * (wi + wj) / (rest * rest) + alpha)
        } else {
            -c / ((wi + wj) / (rest * rest) + alpha)
        };
        let push = n * (lambda / rest);
        x[i] -= push * wi;
        x[j] += push * wj;
    }
}

/// One Gauss-Seidel pass over the tets' volume constraints of `mesh` (zero compliance) on the
/// positions `x`, in index order. The per-tet pass's bundle order (see
/// [`Blocks::tet_bundles`](super::tet_mesh::Blocks::tet_bundles)) made this pass twice as
/// fast, but a sweep in index order carries a correction across the mesh in one pass, and
/// without it the peer lost several times its accuracy (PERFORMANCE.md, "Against XPBD").
pub(crate) fn project_volumes(x: &mut [Vec3], mesh: &TetMesh, inv_masses: &[f32]) {
    for (tet, &v0) in mesh.tets().iter().zip(mesh.rest_volumes()) {
        let p = tet.map(|i| x[i as usize]);
        let c = (signed_volume(&p) - v0) / v0;
        if c == 0.0 {
            continue;
        }
        let g = volume_gradients(&p);
        let denominator: f32 = (0..4)
            .map(|k| inv_masses[tet[k] as usize] * g[k].length_squared())
            .sum::<f32>()
            / (v0 * v0);
        if denominator <= 0.0 {
            continue;
        }
        let lambda = -c / denominator;
        for k in 0..4 {
            let i = tet[k] as usize;
            x[i] += g[k] * (inv_masses[i] * lambda / v0);
        }
    }
}
