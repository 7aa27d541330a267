//! The tetrahedral mesh a soft body is simulated on: rest positions, tets, rest volumes,
//! edges (the springs), and the adjacency the volume passes walk, in compact arrays.

use glam::Vec3;

pub use super::blocks::{Blocks, Csr};
use super::geometry::{min_dihedral_deg, signed_volume};
use super::mesh_check::{MeshDefects, find_defects};

/// What is wrong with a tet mesh given to [`TetMesh::new`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TetMeshError {
    /// No vertices were given.
    #[error("the tet mesh has no vertices")]
    NoVertices,
    /// No tets were given.
    #[error("the tet mesh has no tets")]
    NoTets,
    /// More vertices than a `u32` index can address.
    #[error("the tet mesh has {0} vertices, more than a u32 index can address")]
    TooManyVertices(usize),
    /// A coordinate is NaN or infinite.
    #[error("vertex {vertex} has a non-finite coordinate {position:?}")]
    NonFiniteVertex {
        /// The vertex.
        vertex: usize,
        /// Its coordinates as given.
        position: Vec3,
    },
    /// A tet names a vertex that does not exist.
    #[error("tet {tet} refers to vertex {index}, but there are only {vertex_count} vertices")]
    IndexOutOfRange {
        /// The tet.
        tet: usize,
        /// The index it holds.
        index: u32,
        /// How many vertices there are.
        vertex_count: usize,
    },
    /// A tet names the same vertex twice.
    #[error("tet {tet} uses vertex {vertex} more than once")]
    RepeatedVertex {
        /// The tet.
        tet: usize,
        /// The repeated vertex.
        vertex: u32,
    },
    /// A tet is flat (its volume is negligible against its longest edge cubed).
    #[error("tet {tet} is degenerate: volume {volume:e} for a longest edge of {longest_edge}")]
    DegenerateTet {
        /// The tet.
        tet: usize,
        /// Its signed volume.
        volume: f32,
        /// Its longest edge.
        longest_edge: f32,
    },
    /// A vertex's one-ring touches more vertices than the ring impulse can number locally.
    #[error("vertex {vertex} has {ring_vertices} vertices in its one-ring, more than 65536")]
    RingTooLarge {
        /// The vertex.
        vertex: usize,
        /// How many vertices its one-ring has.
        ring_vertices: usize,
    },
    /// A vertex belongs to no tet: it would be a particle without volume, which is almost
    /// certainly a mistake in the input.
    #[error("vertex {vertex} belongs to no tet")]
    UnreferencedVertex {
        /// The vertex.
        vertex: usize,
    },
}

/// A tet whose volume is below this fraction of its longest edge cubed is degenerate.
/// A regular tet has about 0.118; slivers below 1e-6 carry no usable volume gradient in `f32`.
const DEGENERATE_RATIO: f32 = 1e-6;

/// A tet whose rest volume is below this fraction of its longest edge cubed is a sliver (a
/// regular tet has 0.118, the grids' 0.059 and 0.118): a motion a small fraction of its edges
/// flattens or flips it, and no ring impulse around it can hold its volume within a percent.
/// Its ring does not count it against `ImpulseSettings::ring_tet_tolerance`; its own volume is
/// left to the per-tet pass and the shape solve.
pub const SLIVER_RATIO: f32 = 3e-3;

/// A validated tetrahedral mesh with the adjacency the solver needs. Immutable once built;
/// share it between bodies with an `Arc`.
#[derive(Clone, Debug)]
pub struct TetMesh {
    positions: Vec<Vec3>,
    tets: Vec<[u32; 4]>,
    rest_volumes: Vec<f32>,
    /// The rest volumes summed in `f64`, in tet order: read every frame by
    /// `SoftBodyState::volume_metrics`, so summed once.
    total_rest_volume: f64,
    edges: Vec<[u32; 2]>,
    one_rings: Csr,
    ring_vertices: Csr,
    ring_border_tets: Csr,
    /// For each tet of each one-ring (in the order of `one_rings`), the positions of its four
    /// vertices in that ring's `ring_vertices`: the ring impulse works on the ring's particles
    /// gathered in one small array, not on the whole body's.
    ring_corners: Vec<[u16; 4]>,
    /// The rest volume of each tet of each one-ring, in the order of `one_rings`: read with
    /// the ring's corners, without going through the tet's index.
    ring_rest_volumes: Vec<f32>,
    /// Each one-ring's rest volume, its tets' rest volumes summed in `f64` in ring order.
    ring_rest_totals: Vec<f64>,
    /// For each tet of each one-ring, the rest volume its ring's check holds it to within
    /// `ring_tet_tolerance`: its rest volume, or infinity for a sliver (see [`SLIVER_RATIO`]).
    ring_check_volumes: Vec<f32>,
    /// Per tet, whether it is a sliver.
    slivers: Vec<bool>,
    /// Per vertex, whether its one-ring holds a sliver.
    ring_slivers: Vec<bool>,
    tet_neighbours: Csr,
    blocks: Blocks,
    reoriented_tets: usize,
    defects: MeshDefects,
}

impl TetMesh {
    /// Validates `positions` and `tets` and builds the adjacency. Tets given with negative
    /// orientation are reoriented (two vertices swapped) so that every rest volume is positive;
    /// [`TetMesh::reoriented_tets`] says how many were.
    pub fn new(positions: Vec<Vec3>, mut tets: Vec<[u32; 4]>) -> Result<Self, TetMeshError> {
        if positions.is_empty() {
            return Err(TetMeshError::NoVertices);
        }
        if tets.is_empty() {
            return Err(TetMeshError::NoTets);
        }
        check_vertices(&positions)?;
        let n = positions.len();
        let RestTets {
            rest_volumes,
            slivers,
            reoriented_tets,
        } = rest_tets(&positions, &mut tets)?;
        let edges = unique_edges(&tets);
        let pairs: Vec<(u32, u32)> = tets
            .iter()
            .enumerate()
            .flat_map(|(t, tet)| tet.map(|i| (i, t as u32)))
            .collect();
        let one_rings = Csr::from_pairs(n, &pairs);
        let (ring_vertices, ring_border_tets) = ring_vertices_and_borders(&tets, &one_rings);
        let ring_corners = ring_corners(&tets, &one_rings, &ring_vertices)?;

        let ring_slivers: Vec<bool> = (0..n)
            .map(|p| one_rings.row(p).iter().any(|&t| slivers[t as usize]))
            .collect();
        let ring_check_volumes: Vec<f32> = (0..n)
            .flat_map(|p| one_rings.row(p))
            .map(|&t| {
                if slivers[t as usize] {
                    f32::INFINITY
                } else {
                    rest_volumes[t as usize]
                }
            })
            .collect();
        let ring_rest_volumes: Vec<f32> = (0..n)
            .flat_map(|p| one_rings.row(p))
            .map(|&t| rest_volumes[t as usize])
            .collect();
        let ring_rest_totals = (0..n)
            .map(|p| {
                one_rings
                    .row(p)
                    .iter()
                    .fold(0.0f64, |sum, &t| sum + rest_volumes[t as usize] as f64)
            })
            .collect();
        let tet_neighbours = tet_neighbours(&tets, &one_rings);
        let mut blocks = Blocks::new(&positions, &tets, &rest_volumes, &edges, &ring_vertices);
        // The springs numbered in the blocks' order, so that the passes over them (forces,
        // dampers, XPBD's edges) read every per-spring array front to back instead of jumping
        // across it; the order the springs are taken in is the same.
        let edges: Vec<[u32; 2]> = blocks
            .edges
            .items()
            .iter()
            .map(|&e| edges[e as usize])
            .collect();
        blocks.edges.number_items();

        let mut mesh = TetMesh {
            positions,
            tets,
            total_rest_volume: rest_volumes.iter().map(|&v| v as f64).sum(),
            rest_volumes,
            edges,
            one_rings,
            ring_vertices,
            ring_border_tets,
            ring_corners,
            ring_rest_volumes,
            ring_rest_totals,
            ring_check_volumes,
            ring_slivers,
            slivers,
            tet_neighbours,
            blocks,
            reoriented_tets,
            defects: MeshDefects::default(),
        };
        mesh.defects = find_defects(&mesh.positions, &mesh.tets, &mesh.rest_volumes);
        Ok(mesh)
    }

    /// This mesh with every rest position multiplied by `scale` (a spawn transform's scale
    /// baked into the rest shape), or the error that makes that impossible (a zero scale).
    pub fn scaled(&self, scale: Vec3) -> Result<TetMesh, TetMeshError> {
        let positions = self.positions.iter().map(|&p| p * scale).collect();
        TetMesh::new(positions, self.tets.clone())
    }

    /// Rest positions of the vertices.
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// The tets, each positively oriented at rest.
    pub fn tets(&self) -> &[[u32; 4]] {
        &self.tets
    }

    /// Rest volume `V0` of each tet (all positive).
    pub fn rest_volumes(&self) -> &[f32] {
        &self.rest_volumes
    }

    /// Sum of the rest volumes.
    pub fn total_rest_volume(&self) -> f64 {
        self.total_rest_volume
    }

    /// Unique edges `[i, j]` with `i < j`: the springs, numbered in the order of the mesh's
    /// blocks ([`Blocks::edges`]: each block's springs one after another).
    pub fn edges(&self) -> &[[u32; 2]] {
        &self.edges
    }

    /// The tets that contain vertex `p`: its one-ring `T_p`.
    #[inline]
    pub fn one_ring(&self, p: usize) -> &[u32] {
        self.one_rings.row(p)
    }

    /// All vertices of the one-ring of `p` (the particles its ring impulse moves), `p` first.
    #[inline]
    pub fn ring_vertices(&self, p: usize) -> &[u32] {
        self.ring_vertices.row(p)
    }

    /// For each tet of [`TetMesh::one_ring`]`(p)`, the indices of its four vertices in
    /// [`TetMesh::ring_vertices`]`(p)`, reordered so that `p` (index 0) comes last with the
    /// tet's orientation kept (an even permutation: the same signed volume). The ring impulse
    /// then reads the centre once for all its tets instead of gathering it for each.
    #[inline]
    pub fn ring_corners(&self, p: usize) -> &[[u16; 4]] {
        &self.ring_corners[self.one_rings.range(p)]
    }

    /// The rest volumes of the tets of vertex `p`'s one-ring, in the order of
    /// [`TetMesh::one_ring`].
    pub fn ring_rest_volumes(&self, p: usize) -> &[f32] {
        &self.ring_rest_volumes[self.one_rings.range(p)]
    }

    /// The rest volume of vertex `p`'s one-ring: its tets' rest volumes summed in `f64`, in
    /// the order of [`TetMesh::one_ring`].
    pub fn ring_rest_volume(&self, p: usize) -> f64 {
        self.ring_rest_totals[p]
    }

    /// The largest number of vertices in any one-ring.
    pub fn max_ring_vertices(&self) -> usize {
        (0..self.vertex_count())
            .map(|p| self.ring_vertices(p).len())
            .max()
            .unwrap_or(0)
    }

    /// The largest number of tets in any one-ring.
    pub fn max_one_ring(&self) -> usize {
        (0..self.vertex_count())
            .map(|p| self.one_ring(p).len())
            .max()
            .unwrap_or(0)
    }

    /// Tets outside the one-ring of `p` that share a vertex with it: their volume changes when
    /// the ring's particles move, so the neighbour clamp watches them.
    #[inline]
    pub fn ring_border_tets(&self, p: usize) -> &[u32] {
        self.ring_border_tets.row(p)
    }

    /// Tets that share at least one vertex with tet `t` (not `t` itself).
    #[inline]
    pub fn tet_neighbours(&self, t: usize) -> &[u32] {
        self.tet_neighbours.row(t)
    }

    /// The blocks the volume passes and the forces run in, in their order (see [`Blocks`]).
    pub fn blocks(&self) -> &Blocks {
        &self.blocks
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Number of tets.
    pub fn tet_count(&self) -> usize {
        self.tets.len()
    }

    /// The rest volumes each tet of `p`'s one-ring is held to by the ring's check (see
    /// `ring_check_volumes`).
    pub(crate) fn ring_check_volumes(&self, p: usize) -> &[f32] {
        &self.ring_check_volumes[self.one_rings.range(p)]
    }

    /// Whether one of the tets of `p`'s one-ring is a sliver.
    pub(crate) fn ring_has_sliver(&self, p: usize) -> bool {
        self.ring_slivers[p]
    }

    /// Whether tet `t` is a sliver: its rest volume is under `SLIVER_RATIO` (3e-3) of its
    /// longest edge cubed (a regular tet has 0.118), so that a motion a small fraction of its
    /// edges flattens or flips it. Its ring does not count it against
    /// `ImpulseSettings::ring_tet_tolerance`.
    pub fn is_sliver(&self, t: usize) -> bool {
        self.slivers[t]
    }

    /// How many input tets had negative orientation and were reoriented.
    pub fn reoriented_tets(&self) -> usize {
        self.reoriented_tets
    }

    /// The tets that fold over a neighbour or overlap another (see `mesh_check.rs`): found
    /// when the mesh is built, reported by the loaders, `drop` and the plugin as a warning.
    pub fn defects(&self) -> &MeshDefects {
        &self.defects
    }

    /// The particles whose rest positions lie in `region` (mesh coordinates), in index order:
    /// how a game picks the particles to pin, drive or attach without knowing indices.
    pub fn particles_in(&self, region: ParticleRegion) -> Vec<u32> {
        (0..self.positions.len() as u32)
            .filter(|&i| region.contains(self.positions[i as usize]))
            .collect()
    }

    /// Axis-aligned bounds of the rest positions.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.positions.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        )
    }

    /// The faces that belong to one tet only, oriented outwards, over the rest positions
    /// (vertex indices are the mesh's): the surface to show for a mesh that has no finer one.
    pub fn boundary_surface(&self) -> super::surface_mesh::TriangleSurface {
        let face_of = |tet: &[u32; 4], k: usize| {
            let face = [tet[(k + 1) % 4], tet[(k + 2) % 4], tet[(k + 3) % 4]];
            let mut key = face;
            key.sort_unstable();
            (face, key)
        };
        let mut count: std::collections::HashMap<[u32; 3], u32> =
            std::collections::HashMap::with_capacity(self.tets.len() * 2);
        for tet in &self.tets {
            for k in 0..4 {
                *count.entry(face_of(tet, k).1).or_insert(0) += 1;
            }
        }
        let mut surface = super::surface_mesh::TriangleSurface {
            positions: self.positions.clone(),
            indices: Vec::new(),
        };
        for tet in &self.tets {
            for k in 0..4 {
                let (face, key) = face_of(tet, k);
                if count[&key] != 1 {
                    continue;
                }
                let [a, b, c] = face.map(|v| self.positions[v as usize]);
                let away = (a + b + c) / 3.0 - self.positions[tet[k] as usize];
                if (b - a).cross(c - a).dot(away) >= 0.0 {
                    surface.indices.extend_from_slice(&face);
                } else {
                    surface
                        .indices
                        .extend_from_slice(&[face[0], face[2], face[1]]);
                }
            }
        }
        surface
    }

    /// The smallest dihedral angle of any tet at rest, in degrees: the usual measure of tet
    /// quality (a regular tet has 70.5, the grids' tets 45 and more; slivers approach 0).
    pub fn min_dihedral_deg(&self) -> f32 {
        self.tets
            .iter()
            .map(|tet| min_dihedral_deg(&tet.map(|i| self.positions[i as usize])))
            .fold(180.0, f32::min)
    }
}

/// A region of a mesh's rest shape (mesh coordinates), to pick particles by
/// ([`TetMesh::particles_in`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ParticleRegion {
    /// An axis-aligned box.
    Box {
        /// Its lowest corner.
        min: Vec3,
        /// Its highest corner.
        max: Vec3,
    },
    /// A ball.
    Sphere {
        /// Its centre.
        centre: Vec3,
        /// Its radius.
        radius: f32,
    },
}

impl ParticleRegion {
    /// Whether `p` lies in the region (its boundary included).
    pub fn contains(self, p: Vec3) -> bool {
        match self {
            ParticleRegion::Box { min, max } => p.cmpge(min).all() && p.cmple(max).all(),
            ParticleRegion::Sphere { centre, radius } => {
                p.distance_squared(centre) <= radius * radius
            }
        }
    }
}

/// Checks the vertices: not too many to index, all finite.
fn check_vertices(positions: &[Vec3]) -> Result<(), TetMeshError> {
    if positions.len() > u32::MAX as usize {
        return Err(TetMeshError::TooManyVertices(positions.len()));
    }
    if let Some((vertex, &position)) = positions.iter().enumerate().find(|(_, p)| !p.is_finite()) {
        return Err(TetMeshError::NonFiniteVertex { vertex, position });
    }
    Ok(())
}

/// What checking the tets finds: their rest volumes, which are slivers, how many were turned.
struct RestTets {
    rest_volumes: Vec<f32>,
    slivers: Vec<bool>,
    reoriented_tets: usize,
}

/// Checks every tet (indices in range, four distinct vertices, not degenerate), turns those
/// given with negative orientation, and checks that every vertex is in a tet.
fn rest_tets(positions: &[Vec3], tets: &mut [[u32; 4]]) -> Result<RestTets, TetMeshError> {
    let n = positions.len();
    let mut rest_volumes = Vec::with_capacity(tets.len());
    let mut slivers = Vec::with_capacity(tets.len());
    let mut reoriented_tets = 0;
    let mut used = vec![false; n];
    for (t, tet) in tets.iter_mut().enumerate() {
        for (k, &i) in tet.iter().enumerate() {
            if i as usize >= n {
                return Err(TetMeshError::IndexOutOfRange {
                    tet: t,
                    index: i,
                    vertex_count: n,
                });
            }
            if tet[..k].contains(&i) {
                return Err(TetMeshError::RepeatedVertex { tet: t, vertex: i });
            }
            used[i as usize] = true;
        }
        let p = tet.map(|i| positions[i as usize]);
        let mut volume = signed_volume(&p);
        let longest_edge = (0..4)
            .flat_map(|a| (a + 1..4).map(move |b| (a, b)))
            .map(|(a, b)| p[a].distance(p[b]))
            .fold(0.0f32, f32::max);
        // Written so that a NaN volume (impossible for finite input) also counts as degenerate.
        if volume
            .abs()
            .partial_cmp(&(DEGENERATE_RATIO * longest_edge.powi(3)))
            != Some(std::cmp::Ordering::Greater)
        {
            return Err(TetMeshError::DegenerateTet {
                tet: t,
                volume,
                longest_edge,
            });
        }
        if volume < 0.0 {
            tet.swap(1, 2);
            volume = -volume;
            reoriented_tets += 1;
        }
        rest_volumes.push(volume);
        slivers.push(volume < SLIVER_RATIO * longest_edge.powi(3));
    }
    if let Some(vertex) = used.iter().position(|&u| !u) {
        return Err(TetMeshError::UnreferencedVertex { vertex });
    }

    Ok(RestTets {
        rest_volumes,
        slivers,
        reoriented_tets,
    })
}

/// Every vertex pair of every tet, once, sorted.
fn unique_edges(tets: &[[u32; 4]]) -> Vec<[u32; 2]> {
    let mut edges: Vec<[u32; 2]> = tets
        .iter()
        .flat_map(|t| {
            [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)].map(|(a, b)| {
                let (i, j) = (t[a], t[b]);
                [i.min(j), i.max(j)]
            })
        })
        .collect();
    edges.sort_unstable();
    edges.dedup();
    edges
}

/// Per vertex, its ring's vertices (all vertices of the ring's tets, the centre first) and the
/// tets that touch the ring from outside, which the neighbour clamp must also watch.
fn ring_vertices_and_borders(tets: &[[u32; 4]], one_rings: &Csr) -> (Csr, Csr) {
    let n = one_rings.len();
    let mut stamp_v = vec![u32::MAX; n];
    let mut stamp_t = vec![u32::MAX; tets.len()];
    let mut ring_pairs = Vec::new();
    let mut border_pairs = Vec::new();
    for p in 0..n {
        let key = p as u32;
        let start = ring_pairs.len();
        stamp_v[p] = key;
        ring_pairs.push((key, key));
        for &t in one_rings.row(p) {
            stamp_t[t as usize] = key;
            for &i in &tets[t as usize] {
                if stamp_v[i as usize] != key {
                    stamp_v[i as usize] = key;
                    ring_pairs.push((key, i));
                }
            }
        }
        for &(_, i) in &ring_pairs[start..] {
            for &t in one_rings.row(i as usize) {
                if stamp_t[t as usize] != key {
                    stamp_t[t as usize] = key;
                    border_pairs.push((key, t));
                }
            }
        }
    }
    (
        Csr::from_pairs(n, &ring_pairs),
        Csr::from_pairs(n, &border_pairs),
    )
}

/// Each ring's tets as corners in the ring's own vertex numbering (`ring_vertices`), the centre
/// last; an error if a ring has more vertices than that numbering holds.
fn ring_corners(
    tets: &[[u32; 4]],
    one_rings: &Csr,
    ring_vertices: &Csr,
) -> Result<Vec<[u16; 4]>, TetMeshError> {
    let n = one_rings.len();
    let mut local = vec![0u16; n];
    let mut ring_corners = Vec::with_capacity(4 * tets.len());
    for p in 0..n {
        let row = ring_vertices.row(p);
        if row.len() > u16::MAX as usize + 1 {
            return Err(TetMeshError::RingTooLarge {
                vertex: p,
                ring_vertices: row.len(),
            });
        }
        for (k, &i) in row.iter().enumerate() {
            local[i as usize] = k as u16;
        }
        for &t in one_rings.row(p) {
            let [a, b, c, d] = tets[t as usize].map(|i| local[i as usize]);
            // The centre (local 0) last, by an even permutation (the same orientation).
            ring_corners.push(if a == 0 {
                [d, c, b, a]
            } else if b == 0 {
                [c, d, a, b]
            } else if c == 0 {
                [b, a, d, c]
            } else {
                [a, b, c, d]
            });
        }
    }
    Ok(ring_corners)
}

/// Per tet, the tets that share at least one vertex with it.
fn tet_neighbours(tets: &[[u32; 4]], one_rings: &Csr) -> Csr {
    let mut stamp_t = vec![u32::MAX; tets.len()];
    let mut neighbour_pairs = Vec::new();
    for (t, tet) in tets.iter().enumerate() {
        let key = t as u32;
        stamp_t[t] = key;
        for &i in tet {
            for &u in one_rings.row(i as usize) {
                if stamp_t[u as usize] != key {
                    stamp_t[u as usize] = key;
                    neighbour_pairs.push((key, u));
                }
            }
        }
    }
    Csr::from_pairs(tets.len(), &neighbour_pairs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::grid::box_grid;
    use glam::UVec3;

    fn unit_tet() -> (Vec<Vec3>, Vec<[u32; 4]>) {
        (
            vec![Vec3::X, Vec3::Y, Vec3::Z, Vec3::ZERO],
            vec![[0, 1, 2, 3]],
        )
    }

    #[test]
    fn valid_tet_and_reorientation() {
        let (p, t) = unit_tet();
        let m = TetMesh::new(p.clone(), t).unwrap();
        assert_eq!(m.reoriented_tets(), 0);
        assert_eq!(m.edges().len(), 6);
        let m = TetMesh::new(p, vec![[1, 0, 2, 3]]).unwrap();
        assert_eq!(m.reoriented_tets(), 1);
        assert!(m.rest_volumes()[0] > 0.0);
        let tet = m.tets()[0].map(|i| m.positions()[i as usize]);
        assert!(signed_volume(&tet) > 0.0);
    }

    #[test]
    fn bad_meshes_give_errors() {
        let (p, t) = unit_tet();
        assert_eq!(
            TetMesh::new(vec![], t.clone()).unwrap_err(),
            TetMeshError::NoVertices
        );
        assert_eq!(
            TetMesh::new(p.clone(), vec![]).unwrap_err(),
            TetMeshError::NoTets
        );
        assert!(matches!(
            TetMesh::new(p.clone(), vec![[0, 1, 2, 9]]),
            Err(TetMeshError::IndexOutOfRange {
                tet: 0,
                index: 9,
                vertex_count: 4
            })
        ));
        assert!(matches!(
            TetMesh::new(p.clone(), vec![[0, 1, 1, 3]]),
            Err(TetMeshError::RepeatedVertex { tet: 0, vertex: 1 })
        ));
        let mut nan = p.clone();
        nan[2].y = f32::NAN;
        assert!(matches!(
            TetMesh::new(nan, t.clone()),
            Err(TetMeshError::NonFiniteVertex { vertex: 2, .. })
        ));
        let mut inf = p.clone();
        inf[0].x = f32::INFINITY;
        assert!(matches!(
            TetMesh::new(inf, t.clone()),
            Err(TetMeshError::NonFiniteVertex { vertex: 0, .. })
        ));
        let flat = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 0.0)];
        assert!(matches!(
            TetMesh::new(flat, t.clone()),
            Err(TetMeshError::DegenerateTet { tet: 0, .. })
        ));
        let mut extra = p.clone();
        extra.push(Vec3::ONE);
        assert_eq!(
            TetMesh::new(extra, t).unwrap_err(),
            TetMeshError::UnreferencedVertex { vertex: 4 }
        );
        // Every error says what is wrong in words.
        let e = TetMesh::new(p, vec![[0, 1, 2, 7]]).unwrap_err();
        assert!(e.to_string().contains("vertex 7"));
    }

    #[test]
    fn boundary_surface_of_a_grid_is_its_box() {
        let m = crate::core::grid::box_grid(
            UVec3::new(3, 2, 4),
            Vec3::splat(0.5),
            Vec3::new(1.0, 2.0, 3.0),
        )
        .unwrap();
        let s = m.boundary_surface();
        // Two triangles per cell face on the box's surface, enclosing the box outwards.
        assert_eq!(s.triangle_count(), 2 * 2 * (3 * 2 + 2 * 4 + 3 * 4));
        assert!((s.enclosed_volume() - 1.5 * 1.0 * 2.0).abs() < 1e-4);
    }

    #[test]
    fn dihedral_angles_of_known_tets() {
        let (p, t) = unit_tet();
        // The corner tet: 90 degrees at the corner's three edges, acos(1/sqrt(3)) = 54.7 where
        // the slanted face meets the others.
        let m = TetMesh::new(p, t).unwrap();
        let expected = (1.0f32 / 3.0f32.sqrt()).acos().to_degrees();
        assert!((m.min_dihedral_deg() - expected).abs() < 1e-3);
        let regular = vec![
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(1.0, -1.0, -1.0),
            Vec3::new(-1.0, 1.0, -1.0),
            Vec3::new(-1.0, -1.0, 1.0),
        ];
        let m = TetMesh::new(regular, vec![[0, 1, 2, 3]]).unwrap();
        assert!((m.min_dihedral_deg() - (1.0f32 / 3.0).acos().to_degrees()).abs() < 1e-3);
    }

    #[test]
    fn ring_corners_put_the_centre_last_and_keep_each_tets_volume() {
        let m = box_grid(UVec3::new(3, 3, 2), Vec3::splat(0.5), Vec3::ZERO).unwrap();
        for p in 0..m.vertex_count() {
            let ring = m.ring_vertices(p);
            for (&t, corners) in m.one_ring(p).iter().zip(m.ring_corners(p)) {
                assert_eq!(corners[3], 0, "vertex {p}, tet {t}");
                let mut mine = corners.map(|k| ring[k as usize]);
                let mut tet = m.tets()[t as usize];
                let volume = signed_volume(&mine.map(|i| m.positions()[i as usize]));
                let rest = m.rest_volumes()[t as usize];
                // Rounding differs with the corner measured from; an odd permutation would
                // flip the sign.
                assert!((volume - rest).abs() <= 1e-5 * rest, "vertex {p}, tet {t}");
                mine.sort();
                tet.sort();
                assert_eq!(mine, tet);
            }
        }
    }

    #[test]
    fn adjacency_of_two_tets() {
        // Two tets sharing the face (0, 1, 2).
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z, -Vec3::Z];
        let m = TetMesh::new(p, vec![[0, 1, 2, 3], [0, 2, 1, 4]]).unwrap();
        assert_eq!(m.one_ring(0), &[0, 1]);
        assert_eq!(m.one_ring(3), &[0]);
        assert_eq!(m.ring_vertices(3).len(), 4);
        assert_eq!(m.ring_vertices(3)[0], 3);
        assert_eq!(m.ring_border_tets(3), &[1]);
        assert!(m.ring_border_tets(0).is_empty());
        assert_eq!(m.tet_neighbours(0), &[1]);
        assert_eq!(m.edges().len(), 9);
    }

    // What `mesh_check.rs` finds, through the mesh that reports it.

    #[test]
    fn a_grid_has_no_defects() {
        let mesh = box_grid(UVec3::new(4, 3, 5), Vec3::splat(0.1), Vec3::ZERO).unwrap();
        assert_eq!(mesh.defects(), &MeshDefects::default());
    }

    #[test]
    fn a_tet_folded_over_its_neighbour_is_named() {
        // Two tets on the face (0, 1, 2), their apexes 3 and 4 on the same side of it.
        let positions = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::new(0.2, 0.2, 1.0),
            Vec3::new(0.3, 0.3, 0.5),
        ];
        let mesh = TetMesh::new(positions, vec![[0, 1, 2, 3], [0, 1, 2, 4]]).unwrap();
        let defects = mesh.defects();
        assert_eq!(defects.folded, vec![[0, 1]]);
        assert_eq!(defects.folded_count, 1);
        assert_eq!(defects.overlapping_count, 0, "{defects}");
        assert!(defects.to_string().contains("tets 0/1"), "{defects}");
    }

    #[test]
    fn tets_that_overlap_without_sharing_a_face_are_named() {
        // A grid and a separate tet placed inside one of its cells.
        let grid = box_grid(UVec3::splat(2), Vec3::splat(1.0), Vec3::ZERO).unwrap();
        let mut positions = grid.positions().to_vec();
        let mut tets = grid.tets().to_vec();
        let n = positions.len() as u32;
        let c = Vec3::splat(0.5);
        positions.extend([c, c + Vec3::X * 0.2, c + Vec3::Y * 0.2, c + Vec3::Z * 0.2]);
        tets.push([n, n + 1, n + 2, n + 3]);
        let mesh = TetMesh::new(positions, tets).unwrap();
        let defects = mesh.defects();
        assert_eq!(defects.folded_count, 0);
        assert!(defects.overlapping_count >= 1, "{defects}");
        let added = grid.tet_count() as u32;
        assert!(
            defects.overlapping.iter().all(|p| p.contains(&added)),
            "{defects}"
        );
    }
}
