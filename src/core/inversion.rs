//! Tets left inside out at the end of a step, turned back: a sliver flips at a touch, and the
//! substeps' passes (XPBD's sweep, the paper's per-tet correction held by the neighbour clamp)
//! can leave it flipped, and the render mesh embedded in it with it.

use glam::Vec3;

use super::geometry::{signed_volume, volume_gradients};
use super::tet_mesh::TetMesh;

/// The share of its rest volume a tet is turned back to: just unfolded, the rest left to the
/// volume constraints of the substeps that follow, so that a sliver's corners do not jump
/// (PERFORMANCE.md, "Irregular bodies at rest").
const UNFOLDED: f32 = 0.1;

/// The most sweeps [`turn_inverted_tets_back`] makes: a first-order turn can leave a sliver
/// still inside out, or fold a neighbour that shares its corners.
const SWEEPS: usize = 8;

/// Turns each tet left inside out back to a tenth of its rest volume ([`UNFOLDED`]), one at a
/// time (a projection of that tet alone), sweeping the tets again while a sweep turned any (at
/// most [`SWEEPS`]), and returns how many turns it made. Its particles are moved as the tet
/// needs, even into what they touch (the next substep's contacts push them out): a tet lying on
/// the ground must be able to lift its corners off it (PERFORMANCE.md, "Cluster volume
/// correction"). What of their velocities would fold it again is taken out, as a contact takes
/// out a velocity into what it touches, so that the next substeps do not fold it again.
pub(crate) fn turn_inverted_tets_back(
    mesh: &TetMesh,
    positions: &mut [Vec3],
    velocities: &mut [Vec3],
    inv_masses: &[f32],
) -> u32 {
    let mut turned = 0;
    for _ in 0..SWEEPS {
        let sweep = turn_sweep(mesh, positions, velocities, inv_masses);
        turned += sweep;
        if sweep == 0 {
            break;
        }
    }
    turned
}

/// One sweep of [`turn_inverted_tets_back`] over the tets.
fn turn_sweep(
    mesh: &TetMesh,
    positions: &mut [Vec3],
    velocities: &mut [Vec3],
    inv_masses: &[f32],
) -> u32 {
    let mut turned = 0;
    for (tet, &v0) in mesh.tets().iter().zip(mesh.rest_volumes()) {
        let x = tet.map(|i| positions[i as usize]);
        let volume = signed_volume(&x);
        if volume >= 0.0 {
            continue;
        }
        let w = tet.map(|i| inv_masses[i as usize]);
        let Some(step) = tet_projection(&x, &w, UNFOLDED * v0 - volume) else {
            continue;
        };
        for (k, g) in step.into_iter().enumerate() {
            positions[tet[k] as usize] += g;
        }
        let x = tet.map(|i| positions[i as usize]);
        let v = tet.map(|i| velocities[i as usize]);
        let rate: f32 = volume_gradients(&x)
            .iter()
            .zip(&v)
            .map(|(g, v)| g.dot(*v))
            .sum();
        if rate < 0.0
            && let Some(step) = tet_projection(&x, &w, -rate)
        {
            for (k, g) in step.into_iter().enumerate() {
                velocities[tet[k] as usize] += g;
            }
        }
        turned += 1;
    }
    turned
}

/// The change of a tet's corners `x` (inverse masses `w`) along its volume gradients that
/// changes its volume by `change` to first order, the least in the masses' norm; `None` if no
/// corner can move.
fn tet_projection(x: &[Vec3; 4], w: &[f32; 4], change: f32) -> Option<[Vec3; 4]> {
    let g = volume_gradients(x);
    let denominator: f32 = (0..4).map(|k| w[k] * g[k].length_squared()).sum();
    if denominator <= 0.0 || !denominator.is_finite() {
        return None;
    }
    let step = change / denominator;
    Some(std::array::from_fn(|k| (step * w[k]) * g[k]))
}

/// How many tets of `mesh` are inside out at `positions` (for tests).
#[cfg(test)]
pub(crate) fn inverted_tets(mesh: &TetMesh, positions: &[Vec3]) -> usize {
    mesh.tets()
        .iter()
        .filter(|tet| signed_volume(&tet.map(|i| positions[i as usize])) < 0.0)
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::grid::box_grid;
    use glam::UVec3;

    /// A tet turned inside out (a corner pushed through its opposite face, still moving on
    /// through it) is turned back, and the corner's velocity that would push it through again
    /// is taken out, momentum kept.
    #[test]
    fn a_tet_inside_out_is_turned_back_and_stops_folding() {
        let mesh = box_grid(UVec3::new(3, 3, 3), Vec3::splat(0.1), Vec3::ZERO).unwrap();
        let mut x = mesh.positions().to_vec();
        let tet = mesh.tets()[mesh.tet_count() / 2];
        let [a, b, c, d] = tet.map(|i| i as usize);
        let centre = (x[b] + x[c] + x[d]) / 3.0;
        let through = centre - x[a];
        x[a] = centre + 0.5 * through;
        let mut v = vec![Vec3::ZERO; x.len()];
        v[a] = 2.0 * through;
        let folding = |x: &[Vec3], v: &[Vec3]| {
            let g = volume_gradients(&tet.map(|i| x[i as usize]));
            (0..4).map(|k| g[k].dot(v[tet[k] as usize])).sum::<f32>()
        };
        let before = folding(mesh.positions(), &v);
        assert!(before < 0.0);
        let inverted = |x: &[Vec3]| inverted_tets(&mesh, x);
        assert!(inverted(&x) > 0);
        let w = vec![1.0; x.len()];
        assert_eq!(turn_inverted_tets_back(&mesh, &mut x, &mut v, &w), 1);
        assert_eq!(inverted(&x), 0);
        let after = folding(&x, &v);
        assert!(
            after >= 1e-5 * before,
            "still folding it at {after} ({before} before)"
        );
        let momentum: Vec3 = v.iter().sum();
        assert!((momentum - 2.0 * through).length() < 1e-5, "{momentum}");
    }
}
