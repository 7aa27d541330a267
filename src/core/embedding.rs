//! A detailed surface embedded in the coarse tet mesh (the paper's render meshes): each surface
//! point is bound once to a tet by barycentric coordinates, and from then on follows that tet's
//! four particles.
//!
//! Points inside the tet mesh bind to the tet that contains them. Points outside every tet (a
//! tet grid does not follow a curved surface exactly) bind to the nearest tet, with barycentric
//! coordinates extrapolated past its faces, so that they move with it rigidly and stretch with
//! it. "Nearest" is measured to the tet's closest point, approximated by how far the point lies
//! outside the tet's faces in units of the tet's size; among tets that contain the point the
//! first found wins.

use glam::{Mat3, Vec3};

use super::tet_mesh::TetMesh;

/// How far outside a tet (in barycentric units) a point may be and still count as inside:
/// points on shared faces would otherwise fall between two tets by rounding.
const INSIDE_TOLERANCE: f32 = 1e-4;

/// Each surface point's tet and barycentric weights.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceBinding {
    tets: Vec<u32>,
    weights: Vec<[f32; 4]>,
}

/// Why a surface cannot be embedded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EmbeddingError {
    /// A surface point has a NaN or infinite coordinate.
    #[error("surface point {index} is not finite: {point}")]
    NonFinitePoint {
        /// Index of the point.
        index: usize,
        /// The point.
        point: Vec3,
    },
}

/// A uniform grid over the tets' bounding boxes, to find the tets near a point without looking
/// at all of them.
struct TetGrid {
    origin: Vec3,
    cell: f32,
    dims: [i32; 3],
    offsets: Vec<u32>,
    items: Vec<u32>,
}

impl TetGrid {
    fn new(mesh: &TetMesh) -> TetGrid {
        let (lo, hi) = mesh.bounds();
        let mean_volume = mesh.rest_volumes().iter().sum::<f32>() / mesh.tet_count() as f32;
        // About one tet edge per cell, and no more than ~64 cells per side.
        let extent = (hi - lo).max_element().max(f32::EPSILON);
        let cell = (mean_volume * 6.0).cbrt().max(extent / 64.0);
        let dims = ((hi - lo) / cell).floor().as_ivec3() + 1;
        let dims = [dims.x, dims.y, dims.z];
        let cell_count = (dims[0] * dims[1] * dims[2]) as usize;
        let mut counts = vec![0u32; cell_count + 1];
        let mut grid = TetGrid {
            origin: lo,
            cell,
            dims,
            offsets: Vec::new(),
            items: Vec::new(),
        };
        let ranges: Vec<([i32; 3], [i32; 3])> = mesh
            .tets()
            .iter()
            .map(|tet| {
                let p = tet.map(|i| mesh.positions()[i as usize]);
                let a = p[0].min(p[1]).min(p[2]).min(p[3]);
                let b = p[0].max(p[1]).max(p[2]).max(p[3]);
                (grid.coords(a), grid.coords(b))
            })
            .collect();
        for (a, b) in &ranges {
            grid.for_cells(*a, *b, |c| counts[c + 1] += 1);
        }
        for c in 0..cell_count {
            counts[c + 1] += counts[c];
        }
        let mut fill = counts.clone();
        let mut items = vec![0u32; counts[cell_count] as usize];
        for (t, (a, b)) in ranges.iter().enumerate() {
            grid.for_cells(*a, *b, |c| {
                items[fill[c] as usize] = t as u32;
                fill[c] += 1;
            });
        }
        grid.offsets = counts;
        grid.items = items;
        grid
    }

    fn coords(&self, p: Vec3) -> [i32; 3] {
        let c = ((p - self.origin) / self.cell).floor().as_ivec3();
        [
            c.x.clamp(0, self.dims[0] - 1),
            c.y.clamp(0, self.dims[1] - 1),
            c.z.clamp(0, self.dims[2] - 1),
        ]
    }

    fn for_cells(&self, a: [i32; 3], b: [i32; 3], mut f: impl FnMut(usize)) {
        for z in a[2].max(0)..=b[2].min(self.dims[2] - 1) {
            for y in a[1].max(0)..=b[1].min(self.dims[1] - 1) {
                for x in a[0].max(0)..=b[0].min(self.dims[0] - 1) {
                    f(((z * self.dims[1] + y) * self.dims[0] + x) as usize);
                }
            }
        }
    }

    fn cell_items(&self, c: usize) -> &[u32] {
        &self.items[self.offsets[c] as usize..self.offsets[c + 1] as usize]
    }
}

/// Barycentric coordinates of `x` in the tet `p`.
fn barycentric(p: &[Vec3; 4], x: Vec3) -> [f32; 4] {
    let m = Mat3::from_cols(p[0] - p[3], p[1] - p[3], p[2] - p[3]);
    let w = m.inverse() * (x - p[3]);
    [w.x, w.y, w.z, 1.0 - w.x - w.y - w.z]
}

/// How far outside the tet a point with weights `w` lies (0 inside).
fn outside(w: &[f32; 4]) -> f32 {
    w.iter().map(|&x| (-x).max(0.0)).sum()
}

impl SurfaceBinding {
    /// Binds every point of `points` (in the tet mesh's rest frame) to a tet of `mesh`.
    pub fn new(mesh: &TetMesh, points: &[Vec3]) -> Result<SurfaceBinding, EmbeddingError> {
        if let Some((index, &point)) = points.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            return Err(EmbeddingError::NonFinitePoint { index, point });
        }
        let grid = TetGrid::new(mesh);
        let corners = |t: u32| mesh.tets()[t as usize].map(|i| mesh.positions()[i as usize]);
        let mut binding = SurfaceBinding {
            tets: Vec::with_capacity(points.len()),
            weights: Vec::with_capacity(points.len()),
        };
        for &x in points {
            let centre = grid.coords(x);
            let mut best: Option<(u32, [f32; 4], f32)> = None;
            // Rings of cells around the point's cell, until a tet is found and the next ring
            // cannot hold a closer one (one more ring after the first hit).
            let max_radius = grid.dims.iter().copied().max().unwrap_or(1);
            let mut found_at = None;
            for r in 0..=max_radius {
                if let Some(f) = found_at
                    && r > f + 1
                {
                    break;
                }
                let a = [centre[0] - r, centre[1] - r, centre[2] - r];
                let b = [centre[0] + r, centre[1] + r, centre[2] + r];
                grid.for_cells(a, b, |c| {
                    for &t in grid.cell_items(c) {
                        let w = barycentric(&corners(t), x);
                        let d = outside(&w);
                        if best.is_none_or(|(_, _, bd)| d < bd) {
                            best = Some((t, w, d));
                        }
                    }
                });
                if best.is_some() && found_at.is_none() {
                    found_at = Some(r);
                }
                if best.is_some_and(|(_, _, d)| d <= INSIDE_TOLERANCE) {
                    break;
                }
            }
            // A tet mesh is never empty, so some tet was found.
            let (t, w, _) = best.expect("a tet mesh has at least one tet");
            binding.tets.push(t);
            binding.weights.push(w);
        }
        Ok(binding)
    }

    /// Number of bound points.
    pub fn len(&self) -> usize {
        self.tets.len()
    }

    /// Whether no point is bound.
    pub fn is_empty(&self) -> bool {
        self.tets.is_empty()
    }

    /// The tet each point is bound to.
    pub fn tets(&self) -> &[u32] {
        &self.tets
    }

    /// Binds one more surface point: to tet `tet` with barycentric `weights`.
    pub fn push(&mut self, tet: u32, weights: [f32; 4]) {
        self.tets.push(tet);
        self.weights.push(weights);
    }

    /// Whether the triangle of surface points `triangle` spans a tear of the tet mesh, bound
    /// when the mesh was `bound` and torn into `now` (whose tets' pieces are `pieces`,
    /// `tearing::pieces`): two of its points' tets are in different pieces, or shared a
    /// particle in `bound` and share none in `now` (the crack runs between them). A tear keeps
    /// tet indices, so the binding holds for both.
    pub fn spans_cut(
        &self,
        bound: &TetMesh,
        now: &TetMesh,
        pieces: &[u32],
        triangle: [u32; 3],
    ) -> bool {
        let tet = |k: usize| self.tets[triangle[k] as usize] as usize;
        let joined = |mesh: &TetMesh, a: usize, b: usize| {
            a == b || mesh.tets()[a].iter().any(|i| mesh.tets()[b].contains(i))
        };
        [(0, 1), (1, 2), (2, 0)].iter().any(|&(p, q)| {
            let (a, b) = (tet(p), tet(q));
            pieces[a] != pieces[b] || (joined(bound, a, b) && !joined(now, a, b))
        })
    }

    /// Each point's barycentric weights in its tet (negative outside it).
    pub fn weights(&self) -> &[[f32; 4]] {
        &self.weights
    }

    /// Writes into `out` where each point is when the particles are at `particles`.
    pub fn deform(&self, mesh: &TetMesh, particles: &[Vec3], out: &mut [Vec3]) {
        for ((o, &t), w) in out.iter_mut().zip(&self.tets).zip(&self.weights) {
            let tet = mesh.tets()[t as usize];
            *o = particles[tet[0] as usize] * w[0]
                + particles[tet[1] as usize] * w[1]
                + particles[tet[2] as usize] * w[2]
                + particles[tet[3] as usize] * w[3];
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::UVec3;

    use super::*;
    use crate::core::grid::box_grid;

    #[test]
    fn points_inside_bind_inside_and_reproduce_themselves() {
        let mesh = box_grid(UVec3::new(3, 2, 4), Vec3::splat(0.1), Vec3::ZERO).unwrap();
        let mut points = Vec::new();
        for i in 0..200 {
            let f = i as f32;
            points.push(Vec3::new(
                (f * 0.137).fract() * 0.3,
                (f * 0.291).fract() * 0.2,
                (f * 0.533).fract() * 0.4,
            ));
        }
        let binding = SurfaceBinding::new(&mesh, &points).unwrap();
        let mut out = vec![Vec3::ZERO; points.len()];
        binding.deform(&mesh, mesh.positions(), &mut out);
        for ((p, o), w) in points.iter().zip(&out).zip(binding.weights()) {
            assert!(outside(w) <= INSIDE_TOLERANCE, "{p} bound outside: {w:?}");
            assert!(p.distance(*o) < 1e-5, "{p} -> {o}");
        }
    }

    #[test]
    fn points_outside_follow_the_nearest_tet_rigidly() {
        let mesh = box_grid(UVec3::splat(2), Vec3::splat(0.1), Vec3::ZERO).unwrap();
        let points = [Vec3::new(0.25, 0.1, 0.1), Vec3::new(-0.02, 0.21, 0.05)];
        let binding = SurfaceBinding::new(&mesh, &points).unwrap();
        // Rest: exactly where they were. Rotated and moved: rotated and moved with the body.
        let rotation = glam::Quat::from_rotation_y(0.7);
        let shift = Vec3::new(1.0, 2.0, 3.0);
        let moved: Vec<Vec3> = mesh
            .positions()
            .iter()
            .map(|&p| rotation * p + shift)
            .collect();
        let mut out = [Vec3::ZERO; 2];
        binding.deform(&mesh, mesh.positions(), &mut out);
        for (p, o) in points.iter().zip(&out) {
            assert!(p.distance(*o) < 1e-5);
        }
        binding.deform(&mesh, &moved, &mut out);
        for (p, o) in points.iter().zip(&out) {
            assert!((rotation * *p + shift).distance(*o) < 1e-4);
        }
    }

    #[test]
    fn non_finite_points_are_an_error() {
        let mesh = box_grid(UVec3::splat(1), Vec3::splat(0.1), Vec3::ZERO).unwrap();
        let err = SurfaceBinding::new(&mesh, &[Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 0.0)]);
        assert!(matches!(
            err,
            Err(EmbeddingError::NonFinitePoint { index: 1, .. })
        ));
    }
}
