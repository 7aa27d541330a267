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
use wide::f32x4;

use super::deviatoric::ShapeBundle;
use super::geometry::signed_volume;
use super::lanes::Point4;
use super::lanes::{LANES, Vec3x4};
use super::tet_mesh::TetMesh;

/// The edges as XPBD constraints: each edge's rest length and compliance (`1 / k_D`).
pub(crate) struct EdgeConstraints<'a> {
    pub(crate) rest: &'a [f32],
    pub(crate) compliance: &'a [f32],
}

/// One Gauss-Seidel pass over the edge constraints of `mesh` on the positions
/// `start + moves` (`start` where the substep began, `moves` what the pass moves), each of compliance `compliance / hs2` (`hs2` the squared
/// substep), in the blocks' order of the springs (see
/// [`Blocks::edges`](super::tet_mesh::Blocks::edges)): the same order the other methods'
/// dampers take, where consecutive constraints share no particle and do not wait for each
/// other's results. An edge of zero stiffness (infinite compliance) is skipped. `gamma` is
/// XPBD's damping term (see the module's doc): the projection is
/// `dlambda = -(C + gamma grad C . moves) / ((1 + gamma) w / L0^2 + alpha)`, the
/// undamped one when it is zero.
pub(crate) fn project_edges(
    moves: &mut [Vec3],
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
        let d = (start[j].vec3() - start[i].vec3()) + (moves[j] - moves[i]);
        let length = d.length();
        let rest = edges.rest[e];
        if length <= f32::EPSILON * rest {
            continue;
        }
        let n = d / length;
        let c = (length - rest) / rest;
        let lambda = if gamma > 0.0 {
            let rate = n.dot(moves[j] - moves[i]) / rest;
            -(c + gamma * rate) / ((1.0 + gamma) * (wi + wj) / (rest * rest) + alpha)
        } else {
            -c / ((wi + wj) / (rest * rest) + alpha)
        };
        let push = n * (lambda / rest);
        moves[i] -= push * wi;
        moves[j] += push * wj;
    }
}

/// A body whose volume at a step's start is this far off its rest volume (a fraction of it)
/// has drifted (crushed, squashed by the game, or what a landing left to XPBD alone), and its
/// volume projections in that step's substeps are held back from the velocities
/// (`hold_back_volume_moves`). A body within it is left alone: its projections stop the
/// substeps' own compression (a landing, an impact), whose velocity they must keep whole.
pub(crate) const VOLUME_DRIFT: f64 = 0.02;

/// Whether `mesh` at `positions` has drifted off its rest volume (`VOLUME_DRIFT`).
pub(crate) fn volume_drifted(mesh: &TetMesh, positions: &[Vec3]) -> bool {
    let volume: f64 = (mesh.tets().iter())
        .map(|tet| f64::from(signed_volume(&tet.map(|i| positions[i as usize]))))
        .sum();
    let rest = mesh.total_rest_volume();
    (volume - rest).abs() > VOLUME_DRIFT * rest
}

/// What of XPBD's volume projection in a substep the velocities do not take: its whole move
/// `dx` goes to the positions, `k dx / h_s` to the velocities, with the largest `k` in `[0, 1]`
/// that adds no kinetic energy (the rule the paper's impulses keep, `substep_advance`). A
/// projection that stops a compression keeps all of it; one that only puts back volume lost
/// before (a body crushed flat, what a landing's squash left) moves the particles without
/// throwing them (PERFORMANCE.md, stop 58). `held` comes in as the moves before the
/// projection, `moves` as those after; `held` leaves as `(1 - k) dx`. One `k` for the whole
/// body, so momentum is kept.
pub(crate) fn hold_back_volume_moves(
    held: &mut [Vec3],
    moves: &[Vec3],
    masses: &[f32],
    inv_masses: &[f32],
) {
    // In moves, not velocities: both sums carry the same `h_s^2`.
    let (mut along, mut squared) = (0.0f64, 0.0f64);
    for (((held, &after), &m), &w) in held.iter_mut().zip(moves).zip(masses).zip(inv_masses) {
        let dx = if w > 0.0 { after - *held } else { Vec3::ZERO };
        along += f64::from(m * held.dot(dx));
        squared += f64::from(m * dx.length_squared());
        *held = dx;
    }
    // `KE(k) - KE(0) = (2 k along + k^2 squared) / 2`.
    let k = if squared > 0.0 {
        (-2.0 * along / squared).clamp(0.0, 1.0) as f32
    } else {
        1.0
    };
    for held in held.iter_mut() {
        *held *= 1.0 - k;
    }
}

/// One pass over every tet's volume constraint `C = (V - V0) / V0` (zero compliance), four
/// tets at a time: the tets of a bundle share no particle, so each lane is its tet's own
/// projection, and the bundles come in index order (each takes the next tets free of its first
/// one's particles; `deviatoric::shape_bundles`), so the sweep is Gauss-Seidel in nearly index
/// order, on the positions `start + moves`, moving `moves`. Needs `refresh_shape_bundles`
/// this step (the inverse masses).
pub(crate) fn project_volume_bundles(
    bundles: &[ShapeBundle],
    moves: &mut [Vec3],
    start: &[Point4],
) {
    let sixth = f32x4::splat(1.0 / 6.0);
    for b in bundles {
        // Written out rather than as nested `map`s, which the compiler may leave as calls in
        // this loop (PERFORMANCE.md, "The cluster correction's cost").
        let at = |i: usize| start[i].vec3() + moves[i];
        let corner = |k: usize| {
            let l = &b.corners[k];
            Vec3x4::from_vecs([at(l[0]), at(l[1]), at(l[2]), at(l[3])])
        };
        let [a, bb, c, d] = [corner(0), corner(1), corner(2), corner(3)];
        let g_a = (bb - d).cross(c - d).scale(sixth);
        let g_b = (c - d).cross(a - d).scale(sixth);
        let g_c = (a - d).cross(bb - d).scale(sixth);
        let g_d = -(g_a + g_b + g_c);
        let g = [g_a, g_b, g_c, g_d];
        let volume = (a - d).dot(g_a);
        let w = b.inv_masses;
        let denominator = (0..4).fold(f32x4::ZERO, |s, k| s + w[k] * g[k].length_squared());
        // `dx_k = -w_k g_k (V - V0) / sum w |g|^2`: the constraint `(V - V0) / V0` solved to
        // first order. Zero in an empty lane or a tet no free particle can move.
        let step = (b.rest_volume - volume) / denominator;
        let step = step.is_finite().blend(step, f32x4::ZERO);
        for k in 0..4 {
            let corrections = g[k].scale(w[k] * step).to_vecs();
            for l in 0..LANES {
                if b.filled[l] {
                    moves[b.corners[k][l]] += corrections[l];
                }
            }
        }
    }
}
