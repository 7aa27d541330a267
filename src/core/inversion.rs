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
/// still inside out, or fold a neighbour that shares its corners (one a later sweep meets, as
/// the sweeps after the first look only around what the last one moved).
const SWEEPS: usize = 32;

/// The tets a sweep of [`turn_inverted_tets_back`] looks at after its first: those around the
/// corners the sweep before moved, the only ones it can have folded. Sized for a mesh at its
/// first use, then reused (no step allocates).
#[derive(Clone, Debug, Default)]
pub(crate) struct TurnScratch {
    /// Per tet, the sweep that last listed it.
    listed: Vec<u32>,
    sweep: u32,
    /// The tets the next sweep looks at, ascending, and the tets the current one turned.
    tets: Vec<u32>,
    turned: Vec<u32>,
}

impl TurnScratch {
    /// Lists the tets around the corners of those just turned, in index order (a sweep's own).
    fn list_around_turned(&mut self, mesh: &TetMesh) {
        if self.sweep == u32::MAX {
            self.listed.fill(0);
            self.sweep = 0;
        }
        self.sweep += 1;
        self.tets.clear();
        for &t in &self.turned {
            for &i in &mesh.tets()[t as usize] {
                for &u in mesh.one_ring(i as usize) {
                    if self.listed[u as usize] != self.sweep {
                        self.listed[u as usize] = self.sweep;
                        self.tets.push(u);
                    }
                }
            }
        }
        self.tets.sort_unstable();
        self.turned.clear();
    }
}

/// Turns each tet left inside out back to a tenth of its rest volume ([`UNFOLDED`]), one at a
/// time (a projection of that tet alone), sweeping again while a sweep turned any (at most
/// [`SWEEPS`]; after the first, over the tets around the corners the last sweep moved), and
/// returns how many turns it made. Its particles are moved as the tet needs, even into what
/// they touch (the next substep's contacts push them out): a tet lying on the ground must be
/// able to lift its corners off it (PERFORMANCE.md, "Cluster volume correction"). What of their
/// velocities would fold it again is taken out, as a contact takes out a velocity into what it
/// touches, so that the next substeps do not fold it again.
pub(crate) fn turn_inverted_tets_back(
    mesh: &TetMesh,
    (positions, velocities, inv_masses): (&mut [Vec3], &mut [Vec3], &[f32]),
    scratch: &mut TurnScratch,
) -> u32 {
    if scratch.listed.len() != mesh.tet_count() {
        *scratch = TurnScratch {
            listed: vec![0; mesh.tet_count()],
            sweep: 0,
            tets: Vec::with_capacity(mesh.tet_count()),
            turned: Vec::with_capacity(mesh.tet_count()),
        };
    }
    scratch.turned.clear();
    for t in 0..mesh.tet_count() {
        if turn_if_inside_out(mesh, t, (positions, velocities, inv_masses)) {
            scratch.turned.push(t as u32);
        }
    }
    let mut turned = scratch.turned.len() as u32;
    for _ in 1..SWEEPS {
        if scratch.turned.is_empty() {
            break;
        }
        scratch.list_around_turned(mesh);
        for k in 0..scratch.tets.len() {
            let t = scratch.tets[k] as usize;
            if turn_if_inside_out(mesh, t, (positions, velocities, inv_masses)) {
                scratch.turned.push(t as u32);
            }
        }
        turned += scratch.turned.len() as u32;
    }
    turned
}

/// Whether tet `t` is inside out and was turned back: the check inline in the sweeps' loops,
/// the turn ([`turn_tet`]) a call for the few that need it.
#[inline(always)]
fn turn_if_inside_out(
    mesh: &TetMesh,
    t: usize,
    (positions, velocities, inv_masses): (&mut [Vec3], &mut [Vec3], &[f32]),
) -> bool {
    let volume = signed_volume(&mesh.tets()[t].map(|i| positions[i as usize]));
    volume < 0.0 && turn_tet(mesh, t, volume, (positions, velocities, inv_masses))
}

/// Turns tet `t`, inside out at `volume`, back (see [`turn_inverted_tets_back`]); whether it
/// could (false if no corner can move).
fn turn_tet(
    mesh: &TetMesh,
    t: usize,
    volume: f32,
    (positions, velocities, inv_masses): (&mut [Vec3], &mut [Vec3], &[f32]),
) -> bool {
    let tet = mesh.tets()[t];
    let x = tet.map(|i| positions[i as usize]);
    let w = tet.map(|i| inv_masses[i as usize]);
    let Some(step) = tet_projection(&x, &w, UNFOLDED * mesh.rest_volumes()[t] - volume) else {
        return false;
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
    true
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
        let scratch = &mut TurnScratch::default();
        assert_eq!(
            turn_inverted_tets_back(&mesh, (&mut x, &mut v, &w), scratch),
            1
        );
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
