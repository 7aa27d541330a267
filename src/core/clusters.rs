//! Cluster volume correction: at the end of a step, the body's volume put back region by
//! region, every region exactly and all of them together.
//!
//! XPBD's per-tet volume constraints, one Gauss-Seidel sweep a substep, hold each tet near its
//! volume but leave the body's smooth, low-frequency loss (a sag under gravity, a landing's
//! squash, what the contacts take back after the sweep) to later substeps that never catch up.
//! That part is what a few large regions see. The tets
//! are grouped into clusters (the cells of a grid over the rest shape, about
//! [`XpbdSettings::clusters`](super::material::XpbdSettings::clusters) of them); each cluster's
//! volume `C_c = sum of its tets' (V - V0)` is a constraint with gradient
//! `G_c = sum of its tets' volume gradients` (non-zero only on the cluster's boundary, the sums
//! cancelling inside; summed over the cluster's boundary faces, which is the same sum with the
//! cancelling terms left out: a third of each face's area vector at each of its corners), and
//! the positions move by `dx = W G^T q` with `G W G^T q = -C`: a small
//! dense system (one row per cluster), solved by Cholesky. As with the paper's impulses
//! (sections 4 and 5), each tet's gradients sum to zero, so `sum m dx = 0`: momentum is kept.
//! A particle touching something does not move into it (the push along its contact normal is
//! taken out of `W`, which keeps `G W G^T` symmetric; see `without_contact`).
//!
//! Before it, a tet left inside out is unfolded on its own (`inversion.rs`); the correction's
//! push can fold a sliver again, which is then unfolded and the clusters corrected once more,
//! and what that second push folds is unfolded last.
//!
//! It runs once a step, after the last substep, on the positions: the velocities keep what the
//! substeps gave them, so the correction adds no energy (it is a projection of where the step
//! ends, as XPBD's own constraints are), but for a tet turned back, whose corners lose what of
//! their velocities would fold it again. (Run before the last substep instead, that substep's
//! sweep gave much of the loss back.) Nothing moves what the body touches after it, so a
//! particle touching anything (the ground, a rigid body, another soft body, or whose triangle
//! another body's particle touches) is not pushed into it at all. Measured against the
//! alternatives (in every substep, on the velocities, with more clusters, the rings solved
//! together by conjugate gradients) in PERFORMANCE.md, "Cluster volume correction".

use glam::Vec3;

use super::contacts::ContactState;
use super::geometry::signed_volume;
use super::inversion::{TurnScratch, turn_inverted_tets_back};
use super::tet_mesh::TetMesh;

/// A body's clusters and the working memory of their correction (sized once, with the body or
/// when the number of clusters asked for changes).
#[derive(Clone, Debug, Default)]
pub(crate) struct ClusterVolumes {
    /// The number of clusters asked for (the grid's cells are sized for it).
    requested: u32,
    /// Per tet, its cluster.
    tet_cluster: Vec<u32>,
    /// Per particle, where its slots start in `slot_cluster` (one slot per cluster on whose
    /// boundary it lies), and one past the last particle's.
    slot_starts: Vec<u32>,
    /// The particles with slots, ascending: the only ones the correction moves (the gradients
    /// of a particle inside a cluster are zero).
    face_particles: Vec<u32>,
    /// Per slot, its cluster.
    slot_cluster: Vec<u32>,
    /// Each cluster's boundary faces (its tets' faces that no other tet of it shares, wound
    /// outward), and per face corner its particle's slot for the face's cluster.
    faces: Vec<[u32; 3]>,
    face_slots: Vec<[u32; 3]>,
    /// Per cluster, its rest volume.
    rest: Vec<f64>,
    /// Per slot, the cluster's volume gradient at the slot's particle.
    gradients: Vec<Vec3>,
    /// Per cluster, its volume now.
    volume: Vec<f64>,
    /// `G W G^T`, row-major, then its Cholesky factor.
    matrix: Vec<f64>,
    /// `-C`, then the solution `q`.
    rhs: Vec<f64>,
}

impl ClusterVolumes {
    /// About `requested` clusters of `mesh`: cubic cells of the rest shape, each of about
    /// `1 / requested` of its volume.
    pub(crate) fn new(mesh: &TetMesh, requested: u32) -> ClusterVolumes {
        let x = mesh.positions();
        let (lo, _) = mesh.bounds();
        let cell = (mesh.total_rest_volume() as f32 / requested.max(1) as f32)
            .cbrt()
            .max(f32::MIN_POSITIVE);
        // Cells numbered in the order their first tet comes.
        let mut cells = std::collections::HashMap::new();
        let tet_cluster: Vec<u32> = mesh
            .tets()
            .iter()
            .map(|tet| {
                let centre = tet.iter().map(|&i| x[i as usize]).sum::<Vec3>() / 4.0;
                let key = ((centre - lo) / cell).floor().as_ivec3();
                let next = cells.len() as u32;
                *cells.entry(key).or_insert(next)
            })
            .collect();
        let clusters = cells.len();
        let faces = boundary_faces(mesh, &tet_cluster);
        let mut per_particle: Vec<Vec<u32>> = vec![Vec::new(); mesh.vertex_count()];
        for &(c, face) in &faces {
            for i in face {
                if !per_particle[i as usize].contains(&c) {
                    per_particle[i as usize].push(c);
                }
            }
        }
        let face_particles = (0..per_particle.len() as u32)
            .filter(|&i| !per_particle[i as usize].is_empty())
            .collect();
        let mut slot_starts = Vec::with_capacity(per_particle.len() + 1);
        let mut slot_cluster = Vec::new();
        for list in &per_particle {
            slot_starts.push(slot_cluster.len() as u32);
            slot_cluster.extend_from_slice(list);
        }
        slot_starts.push(slot_cluster.len() as u32);
        let face_slots = faces
            .iter()
            .map(|&(c, face)| {
                face.map(|i| {
                    let i = i as usize;
                    let k = per_particle[i].iter().position(|&d| d == c).unwrap_or(0);
                    slot_starts[i] + k as u32
                })
            })
            .collect();
        let faces = faces.into_iter().map(|(_, face)| face).collect();
        let mut rest = vec![0.0; clusters];
        for (&c, &v0) in tet_cluster.iter().zip(mesh.rest_volumes()) {
            rest[c as usize] += v0 as f64;
        }
        ClusterVolumes {
            requested,
            tet_cluster,
            gradients: vec![Vec3::ZERO; slot_cluster.len()],
            slot_starts,
            face_particles,
            slot_cluster,
            faces,
            face_slots,
            rest,
            volume: vec![0.0; clusters],
            matrix: vec![0.0; clusters * clusters],
            rhs: vec![0.0; clusters],
        }
    }

    /// Moves `positions` so that every cluster has its rest volume (to first order), particles
    /// of inverse mass `inv_masses`, those touching something (`contacts`) not pushed into it.
    /// Tets left inside out are turned back first; if the correction's push folds one again, it
    /// is turned back and the clusters corrected once more (a sliver's turn changes its
    /// cluster's volume), and what that second push folds is turned back last (a sliver's
    /// volume, too small to correct for again).
    pub(crate) fn correct(
        &mut self,
        mesh: &TetMesh,
        positions: &mut [Vec3],
        velocities: &mut [Vec3],
        inv_masses: &[f32],
        (contacts, turns): (&ContactState, &mut TurnScratch),
    ) {
        let inside_out = self.measure(mesh, positions);
        for round in 0..2 {
            // The first round's turn only where `measure` met a tet inside out.
            let turned = if round == 0 && inside_out == 0 {
                0
            } else {
                turn_inverted_tets_back(mesh, (positions, velocities, inv_masses), turns)
            };
            if round > 0 && turned == 0 {
                return;
            }
            if turned > 0 {
                self.measure(mesh, positions);
            }
            self.assemble(inv_masses, contacts);
            if !solve_cholesky(&mut self.matrix, &mut self.rhs, self.rest.len()) {
                return;
            }
            self.push(positions, inv_masses, contacts);
        }
        turn_inverted_tets_back(mesh, (positions, velocities, inv_masses), turns);
    }

    /// Moves each particle by `w G^T q` (`q` the solution in `rhs`), not into what it touches.
    fn push(&self, positions: &mut [Vec3], inv_masses: &[f32], contacts: &ContactState) {
        for &i in &self.face_particles {
            let (i, x) = (i as usize, &mut positions[i as usize]);
            let w = inv_masses[i];
            if w == 0.0 {
                continue;
            }
            let mut push = Vec3::ZERO;
            for s in self.slots(i) {
                push += self.gradients[s] * self.rhs[self.slot_cluster[s] as usize] as f32;
            }
            let push = w * without_contact(contacts, i, push);
            if push.is_finite() {
                *x += push;
            }
        }
    }

    /// The slots of particle `i`.
    fn slots(&self, i: usize) -> std::ops::Range<usize> {
        self.slot_starts[i] as usize..self.slot_starts[i + 1] as usize
    }

    /// Each cluster's volume (the sum of its tets') and its gradient at each of its particles
    /// (over its boundary faces). Returns how many tets are inside out.
    fn measure(&mut self, mesh: &TetMesh, positions: &[Vec3]) -> u32 {
        self.volume.fill(0.0);
        let mut inside_out = 0;
        for (tet, &c) in mesh.tets().iter().zip(&self.tet_cluster) {
            let volume = signed_volume(&tet.map(|i| positions[i as usize]));
            self.volume[c as usize] += volume as f64;
            inside_out += (volume < 0.0) as u32;
        }
        self.gradients.fill(Vec3::ZERO);
        for (face, slots) in self.faces.iter().zip(&self.face_slots) {
            let [a, b, c] = face.map(|i| positions[i as usize]);
            let third = (b - a).cross(c - a) * (1.0 / 6.0);
            for &s in slots {
                self.gradients[s as usize] += third;
            }
        }
        inside_out
    }

    /// `G W G^T` and `-C`. A cluster no free particle can change (all of it kinematic) gets
    /// the row of the identity and no correction.
    fn assemble(&mut self, inv_masses: &[f32], contacts: &ContactState) {
        let k = self.rest.len();
        self.matrix.fill(0.0);
        for &i in &self.face_particles {
            let (i, w) = (i as usize, inv_masses[i as usize]);
            if w == 0.0 {
                continue;
            }
            for s in self.slots(i) {
                let row = self.slot_cluster[s] as usize * k;
                let weighted = w * without_contact(contacts, i, self.gradients[s]);
                for t in self.slots(i) {
                    let column = self.slot_cluster[t] as usize;
                    self.matrix[row + column] += weighted.dot(self.gradients[t]) as f64;
                }
            }
        }
        let largest = (0..k).map(|c| self.matrix[c * k + c]).fold(0.0, f64::max);
        for c in 0..k {
            self.rhs[c] = self.rest[c] - self.volume[c];
            if self.matrix[c * k + c] <= 1e-12 * largest {
                for d in 0..k {
                    self.matrix[c * k + d] = 0.0;
                    self.matrix[d * k + c] = 0.0;
                }
                self.matrix[c * k + c] = 1.0;
                self.rhs[c] = 0.0;
            }
        }
    }
}

/// The boundary faces of every cluster (`tet_cluster`: per tet of `mesh`, its cluster), each
/// with its cluster, wound outward (the face's normal `(b - a) x (c - a)` points out of the
/// tet whose face it is: every tet's rest volume is positive, `TetMesh::new` turns them so), in
/// the order their tets come.
fn boundary_faces(mesh: &TetMesh, tet_cluster: &[u32]) -> Vec<(u32, [u32; 3])> {
    // The outward faces of a tet `[0, 1, 2, 3]` of positive `signed_volume`, opposite each corner.
    const OUTWARD: [[usize; 3]; 4] = [[1, 3, 2], [0, 2, 3], [3, 1, 0], [2, 0, 1]];
    let mut faces: Vec<Option<(u32, [u32; 3])>> = Vec::with_capacity(4 * mesh.tet_count());
    let mut open = std::collections::HashMap::new();
    for (tet, &c) in mesh.tets().iter().zip(tet_cluster) {
        for corners in OUTWARD {
            let face = corners.map(|k| tet[k]);
            let mut key = face;
            key.sort_unstable();
            // A face two tets of the cluster share is inside it: both go.
            match open.remove(&(c, key)) {
                Some(k) => faces[k] = None,
                None => {
                    open.insert((c, key), faces.len());
                    faces.push(Some((c, face)));
                }
            }
        }
    }
    faces.into_iter().flatten().collect()
}

/// [`ClusterVolumes::correct`] with about `requested` clusters of `mesh`, made anew in
/// `clusters` first if they were made for another number or another mesh (a body's first step
/// with them; a torn body has new particles).
pub(crate) fn correct_cluster_volumes(
    clusters: &mut ClusterVolumes,
    requested: u32,
    mesh: &TetMesh,
    (positions, velocities, inv_masses): (&mut [Vec3], &mut [Vec3], &[f32]),
    (contacts, turns): (&ContactState, &mut TurnScratch),
) {
    if clusters.requested != requested
        || clusters.tet_cluster.len() != mesh.tet_count()
        || clusters.slot_starts.len() != positions.len() + 1
    {
        *clusters = ClusterVolumes::new(mesh, requested);
    }
    clusters.correct(mesh, positions, velocities, inv_masses, (contacts, turns));
}

/// `a` at particle `i` without what would push it into what it touches (`contacts`): all of
/// it for a particle that touched another body this step, soft or rigid (held where it is, as
/// the other soft body's particles that touch it are: pushed along that body's surface it goes
/// into the next triangle); else the part along the contact's normal, and along a second
/// static collider's (the edge or corner of a room): the particle slides along what it
/// touches. Nothing moves what it touches after the correction, so no share of a push into it
/// is kept. Both ways along the normals, not only into them as the impulses'
/// `constrained_push`: `W` must stay linear for `G W G^T` to be the system's matrix.
fn without_contact(contacts: &ContactState, i: usize, a: Vec3) -> Vec3 {
    if contacts.touched_a_body(i) {
        return Vec3::ZERO;
    }
    let n = contacts.normals[i];
    let a = a - n * a.dot(n);
    let second = contacts.second[i];
    match (second - n * second.dot(n)).try_normalize() {
        Some(u) => a - u * a.dot(u),
        None => a,
    }
}

/// Solves `m x = b` in place (`b` becomes `x`) for the symmetric positive definite `k x k`
/// matrix `m` (row-major), which becomes its Cholesky factor. `false` if `m` is not positive
/// definite (nothing is then to be applied).
fn solve_cholesky(m: &mut [f64], b: &mut [f64], k: usize) -> bool {
    for j in 0..k {
        let d = m[j * k + j] - (0..j).map(|p| m[j * k + p] * m[j * k + p]).sum::<f64>();
        if d <= 0.0 || !d.is_finite() {
            return false;
        }
        let d = d.sqrt();
        m[j * k + j] = d;
        for i in j + 1..k {
            let s = m[i * k + j] - (0..j).map(|p| m[i * k + p] * m[j * k + p]).sum::<f64>();
            m[i * k + j] = s / d;
        }
    }
    for i in 0..k {
        let s = b[i] - (0..i).map(|p| m[i * k + p] * b[p]).sum::<f64>();
        b[i] = s / m[i * k + i];
    }
    for i in (0..k).rev() {
        let s = b[i] - (i + 1..k).map(|p| m[p * k + i] * b[p]).sum::<f64>();
        b[i] = s / m[i * k + i];
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::box_grid;
    use glam::UVec3;

    /// A squashed box gets every cluster's volume back to first order, its momentum unmoved,
    /// and a particle pressed on the ground is not pushed into it.
    #[test]
    fn a_squashed_box_gets_its_clusters_volume_back() {
        let mesh = box_grid(UVec3::new(6, 6, 6), Vec3::splat(0.1), Vec3::ZERO).unwrap();
        let mut clusters = ClusterVolumes::new(&mesh, 8);
        assert!(
            (4..=16).contains(&clusters.rest.len()),
            "{}",
            clusters.rest.len()
        );
        let mut x: Vec<Vec3> = mesh
            .positions()
            .iter()
            .map(|p| Vec3::new(p.x * (1.0 + 0.1 * p.y), p.y * 0.9, p.z))
            .collect();
        let before: Vec<Vec3> = x.clone();
        let w: Vec<f32> = (0..x.len()).map(|i| 1.0 + (i % 3) as f32).collect();
        let mut contacts = ContactState::new(x.len());
        for (i, p) in x.iter().enumerate() {
            if p.y == 0.0 {
                contacts.record(i, Vec3::Y, 0.0, None);
            }
        }
        let mut v = vec![Vec3::ZERO; x.len()];
        let turns = &mut TurnScratch::default();
        for _ in 0..3 {
            clusters.correct(&mesh, &mut x, &mut v, &w, (&contacts, turns));
        }
        clusters.measure(&mesh, &x);
        for (v, v0) in clusters.volume.iter().zip(&clusters.rest) {
            assert!(((v - v0) / v0).abs() < 1e-4, "{v} against {v0}");
        }
        let momentum: Vec3 = x
            .iter()
            .zip(&before)
            .zip(&w)
            .map(|((a, b), w)| (*a - *b) / *w)
            .sum();
        // Without the ground's particles' normal pushes, which the ground takes.
        let ground: f32 = x
            .iter()
            .zip(&before)
            .zip(&w)
            .filter(|((_, b), _)| b.y == 0.0)
            .map(|((a, b), w)| (a.y - b.y) / w)
            .sum();
        assert_eq!(ground, 0.0);
        assert!(
            momentum.x.abs() < 1e-5 && momentum.z.abs() < 1e-5,
            "{momentum}"
        );
    }

    /// The clusters' gradients summed over their boundary faces are the sums of their tets'
    /// volume gradients, on a grid and on a mesh another tool made (its tets given either way
    /// round), bent out of shape; and their volumes are their tets'.
    #[test]
    fn the_boundary_faces_give_the_tets_gradients() {
        let grid = box_grid(UVec3::new(5, 4, 6), Vec3::splat(0.1), Vec3::ZERO).unwrap();
        let bunny = crate::game_scenes::BundledMesh::Bunny.load().unwrap();
        let turned = TetMesh::new(
            bunny.positions().to_vec(),
            bunny
                .tets()
                .iter()
                .map(|&[a, b, c, d]| [b, a, c, d])
                .collect(),
        );
        for mesh in [grid, bunny, turned.unwrap()] {
            let mut clusters = ClusterVolumes::new(&mesh, 8);
            let x: Vec<Vec3> = mesh
                .positions()
                .iter()
                .map(|p| *p + 0.03 * Vec3::new((7.0 * p.y).sin(), (5.0 * p.z).cos(), p.x * p.y))
                .collect();
            let inside_out = crate::core::inversion::inverted_tets(&mesh, &x);
            assert_eq!(clusters.measure(&mesh, &x) as usize, inside_out);
            // Per particle and cluster, the sum of the tets' gradients.
            let mut expected = std::collections::BTreeMap::new();
            let mut volume = vec![0.0f64; clusters.rest.len()];
            for (tet, &c) in mesh.tets().iter().zip(&clusters.tet_cluster) {
                let corners = tet.map(|i| x[i as usize]);
                volume[c as usize] += signed_volume(&corners) as f64;
                let g = crate::core::geometry::volume_gradients(&corners);
                for (&i, g) in tet.iter().zip(g) {
                    *expected.entry((i as usize, c)).or_insert(Vec3::ZERO) += g;
                }
            }
            let scale = expected.values().map(|g| g.length()).fold(0.0, f32::max);
            // A particle without a slot for a cluster (inside it) has no gradient there.
            for ((i, c), e) in expected {
                let g = clusters
                    .slots(i)
                    .find(|&s| clusters.slot_cluster[s] == c)
                    .map_or(Vec3::ZERO, |s| clusters.gradients[s]);
                assert!(
                    (g - e).length() < 1e-4 * scale,
                    "{i} in {c}: {g} against {e}"
                );
            }
            for (v, e) in clusters.volume.iter().zip(&volume) {
                assert!((v - e).abs() <= 1e-9 * e.abs(), "{v} against {e}");
            }
        }
    }

    /// A tet turned inside out (a corner pushed through its opposite face) is turned back.
    #[test]
    fn a_tet_inside_out_is_turned_back() {
        let mesh = box_grid(UVec3::new(3, 3, 3), Vec3::splat(0.1), Vec3::ZERO).unwrap();
        let mut x = mesh.positions().to_vec();
        let [a, b, c, d] = mesh.tets()[mesh.tet_count() / 2].map(|i| i as usize);
        let centre = (x[b] + x[c] + x[d]) / 3.0;
        x[a] = centre + 0.5 * (centre - x[a]);
        let inverted = |x: &[Vec3]| crate::core::inversion::inverted_tets(&mesh, x);
        assert!(inverted(&x) > 0);
        let w = vec![1.0; x.len()];
        let mut v = vec![Vec3::ZERO; x.len()];
        let mut clusters = ClusterVolumes::new(&mesh, 8);
        let contacts = ContactState::new(x.len());
        let turns = &mut TurnScratch::default();
        clusters.correct(&mesh, &mut x, &mut v, &w, (&contacts, turns));
        assert_eq!(inverted(&x), 0);
    }
}
