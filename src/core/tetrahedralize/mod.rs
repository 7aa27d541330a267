//! Any triangle mesh becomes a tet mesh: the cells of a regular 5-tets-per-cell grid whose
//! centres lie inside the mesh, by its generalized winding number.
//!
//! Why this way: game meshes are rarely watertight. They have holes, faces oriented every which
//! way, duplicated faces, several overlapping or disconnected parts and non-manifold edges. The
//! winding number gives a usable inside for all of these (see [`WindingNumber`]), and a grid
//! gives well-shaped tets (dihedral angles of 54.7 degrees and more) whatever the input. The
//! tets need not follow the surface exactly: the input surface is embedded in them and is what
//! the player sees (the paper does the same). Still, the grid's boundary vertices are moved onto
//! the surface as far as tet quality allows (no dihedral angle below [`FIT_MIN_DIHEDRAL_DEG`]),
//! so that the tets hold the surface's volume within a few percent.
//!
//! Before the inside test the input is cleaned, without changing what it describes: vertices at
//! the same position are welded (for adjacency only), repeated triangles are counted once, and
//! each patch of triangles connected through manifold edges is oriented consistently and so that
//! it encloses positive volume. The report says how many triangles each of these touched.

use std::collections::HashMap;

use glam::{UVec3, Vec3};

use super::geometry::{min_dihedral_deg, signed_volume};
use super::grid::{GridError, MAX_GRID_CELLS, grid_cells};
use super::tet_mesh::TetMesh;
use super::winding::WindingNumber;

/// How fine the tet mesh is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Resolution {
    /// About this many tets (within a few percent; five per grid cell).
    TargetTets(u32),
    /// Cubic cells of this edge length (metres, in the input's units).
    CellSize(f32),
}

impl Default for Resolution {
    /// About 6000 tets: the paper's armadillo has 6510, and a body of that size steps within
    /// a frame's physics budget on one core.
    fn default() -> Self {
        Resolution::TargetTets(6000)
    }
}

/// The most tets a tetrahedralization may make, whichever way the resolution is given.
pub const MAX_TARGET_TETS: u32 = 5_000_000;

/// The most grid cells the inside test may visit (the box around the input, at the cell size):
/// 4 M winding-number queries take a few seconds.
pub const MAX_TETRAHEDRALIZE_CELLS: u64 = 1 << 22;

/// What is wrong with a tetrahedralization request.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TetrahedralizeError {
    /// No triangles were given.
    #[error("the mesh has no triangles")]
    NoTriangles,
    /// The index list is not a whole number of triangles.
    #[error("{0} indices is not a whole number of triangles")]
    PartialTriangle(usize),
    /// A triangle refers to a vertex that does not exist.
    #[error("triangle {triangle} refers to vertex {vertex}, but there are only {vertices}")]
    IndexOutOfRange {
        /// The triangle.
        triangle: usize,
        /// The index it holds.
        vertex: u32,
        /// How many vertices there are.
        vertices: usize,
    },
    /// A vertex has a NaN or infinite coordinate.
    #[error("vertex {vertex} is not finite: {position}")]
    NonFiniteVertex {
        /// The vertex.
        vertex: usize,
        /// Its position.
        position: Vec3,
    },
    /// Every triangle has zero area: there is no surface.
    #[error("every triangle has zero area")]
    Degenerate,
    /// The resolution is zero, negative, not finite or absurdly large.
    #[error(
        "bad resolution {0:?}: ask for 1 to {MAX_TARGET_TETS} tets or a positive finite cell size"
    )]
    BadResolution(Resolution),
    /// The mesh encloses no cell centre at this resolution.
    #[error(
        "the mesh encloses no cell of {cell_size} m: it is open, flat or thinner than a cell; \
         ask for a finer resolution"
    )]
    NothingInside {
        /// The cell size used.
        cell_size: f32,
    },
    /// The cell size would make more than `MAX_TARGET_TETS` tets.
    #[error("{tets} tets at cell size {cell_size} is more than the limit of {MAX_TARGET_TETS}")]
    TooManyTets {
        /// Tets the cell size would make.
        tets: u64,
        /// The cell size.
        cell_size: f32,
    },
    /// The grid could not be built (too many cells for the chosen cell size, most often).
    #[error(transparent)]
    Grid(#[from] GridError),
}

/// A tet mesh built from a triangle mesh, and what was done to get it.
#[derive(Clone, Debug)]
pub struct Tetrahedralization {
    /// The tet mesh.
    pub mesh: TetMesh,
    /// Edge length of its cubic cells.
    pub cell_size: f32,
    /// Volume the cleaned input surface encloses (by the divergence theorem; meaningful for
    /// closed inputs).
    pub surface_volume: f64,
    /// Triangles that were turned around to agree with their neighbours or to make their patch
    /// enclose positive volume.
    pub flipped_triangles: usize,
    /// Triangles that repeat another one (same three vertices) and were counted once.
    pub duplicate_triangles: usize,
    /// Triangles of zero area (they bound nothing and were left out of the inside test).
    pub degenerate_triangles: usize,
    /// Connected parts of the input (triangles connected through shared vertices).
    pub input_parts: usize,
    /// Input parts inside whose bounds no cell was kept: thinner than a cell (a sheet, a thin
    /// strap) or open. They are not in the tet mesh; a finer resolution may keep them.
    pub parts_without_tets: Vec<usize>,
    /// Pieces of the tet mesh connected through shared tet faces.
    pub components: usize,
}

/// Builds a tet mesh of the inside of the triangle mesh `positions` / `indices` (three indices
/// per triangle) at `resolution`.
pub fn tetrahedralize(
    positions: &[Vec3],
    indices: &[u32],
    resolution: Resolution,
) -> Result<Tetrahedralization, TetrahedralizeError> {
    let cleaned = clean(positions, indices)?;
    let bounds_lo = cleaned
        .triangles
        .iter()
        .flatten()
        .fold(Vec3::splat(f32::INFINITY), |a, p| a.min(*p));
    let bounds_hi = cleaned
        .triangles
        .iter()
        .flatten()
        .fold(Vec3::splat(f32::NEG_INFINITY), |a, p| a.max(*p));
    let size = bounds_hi - bounds_lo;
    let surface_volume = cleaned.volume;
    let winding = WindingNumber::new(cleaned.triangles.clone());

    let mut cell = match resolution {
        Resolution::CellSize(c) if c.is_finite() && c > 0.0 => c,
        Resolution::TargetTets(n) if (1..=MAX_TARGET_TETS).contains(&n) => {
            // First guess from the enclosed volume (the box's, if the surface encloses less
            // than a tenth of it: open or inconsistent input), then one correction from the
            // cells actually found inside.
            let box_volume = (size.max(Vec3::splat(size.max_element() * 1e-3))).element_product();
            let volume = if surface_volume > 0.1 * box_volume as f64 {
                surface_volume as f32
            } else {
                box_volume
            };
            let cells = n as f32 / 5.0;
            let guess = (volume / cells).cbrt();
            let inside = count_inside(&winding, bounds_lo, bounds_hi, guess)?;
            if inside == 0 {
                guess
            } else {
                guess * (inside as f32 / cells).cbrt()
            }
        }
        _ => return Err(TetrahedralizeError::BadResolution(resolution)),
    };
    // A cell much smaller than the shape's size would overflow the grid: let `grid_cells`
    // report it, but never divide by zero for flat inputs.
    if !(cell.is_finite() && cell > 0.0) {
        cell = size.max_element().max(f32::MIN_POSITIVE);
    }

    // Far too many tets by the enclosed volume: say so before millions of inside queries.
    let estimate = 5.0 * surface_volume / (cell as f64).powi(3);
    if estimate > 1.5 * MAX_TARGET_TETS as f64 {
        return Err(TetrahedralizeError::TooManyTets {
            tets: estimate as u64,
            cell_size: cell,
        });
    }
    let (min, cells) = grid_frame(bounds_lo, bounds_hi, cell)?;
    let inside = inside_cells(&winding, min, cells, cell);
    let kept = inside.iter().filter(|&&b| b).count() as u64;
    if kept == 0 {
        return Err(TetrahedralizeError::NothingInside { cell_size: cell });
    }
    if 5 * kept > MAX_TARGET_TETS as u64 {
        return Err(TetrahedralizeError::TooManyTets {
            tets: 5 * kept,
            cell_size: cell,
        });
    }
    let index = |c: UVec3| ((c.z * cells.y + c.y) * cells.x + c.x) as usize;
    let grid = grid_cells(cells, Vec3::splat(cell), min, |c| inside[index(c)])?;
    let mesh = fit_boundary(&grid, &winding, cell).map_err(GridError::Mesh)?;

    // Which input parts got no cell: a part keeps some cell if a kept cell centre lies within
    // its bounds (a cheap test that errs towards "kept" for nested parts).
    let mut parts_without_tets = Vec::new();
    for (part, (lo, hi)) in cleaned.part_bounds.iter().enumerate() {
        let first = ((*lo - min) / cell - 0.5).ceil().max(Vec3::ZERO).as_uvec3();
        let last = ((*hi - min) / cell - 0.5)
            .floor()
            .min((cells - UVec3::ONE).as_vec3());
        let mut kept = false;
        if last.cmpge(first.as_vec3()).all() {
            let last = last.as_uvec3();
            'search: for z in first.z..=last.z {
                for y in first.y..=last.y {
                    for x in first.x..=last.x {
                        if inside[index(UVec3::new(x, y, z))] {
                            kept = true;
                            break 'search;
                        }
                    }
                }
            }
        }
        if !kept {
            parts_without_tets.push(part);
        }
    }

    Ok(Tetrahedralization {
        components: face_components(&mesh),
        mesh,
        cell_size: cell,
        surface_volume,
        flipped_triangles: cleaned.flipped,
        duplicate_triangles: cleaned.duplicates,
        degenerate_triangles: cleaned.degenerate,
        input_parts: cleaned.part_bounds.len(),
        parts_without_tets,
    })
}

/// A boundary vertex moves at most this many cells to reach the surface: further, the surface
/// it would reach is most likely another part's.
const FIT_REACH: f32 = 0.75;

/// No tet may get a dihedral angle below this (degrees) when the boundary is fitted. The grid's
/// own tets have 54.7 and more.
pub const FIT_MIN_DIHEDRAL_DEG: f32 = 30.0;

/// The least fraction of its grid volume a tet keeps when the boundary is fitted (it may grow
/// freely). Why 0.8: small tets are stiff, and an explicit step (the paper's baseline) is only
/// stable up to a stiffness; with 0.3 to 0.6 the baseline creature blew up on landing, and the
/// new method's error rose, while at 0.8 both behave as on the unfitted grid.
const FIT_MIN_VOLUME: f32 = 0.8;

/// Moves each boundary vertex of `grid` onto the boundary of the solid (where the inside test
/// flips, searched towards the nearest point of the surface), or half or a quarter of the way
/// if the full move would leave one of its tets worse than [`FIT_MIN_DIHEDRAL_DEG`] or
/// [`FIT_MIN_VOLUME`], or not at all.
///
/// Why: the grid's staircase misses up to half a cell along each face, which for a box that
/// does not line up with the grid is a volume error of 10 to 30 % at game resolutions. Fitted,
/// the tets hold the surface's volume within a few percent, and the embedded surface lies on
/// the tet boundary instead of up to half a cell off it.
fn fit_boundary(
    grid: &TetMesh,
    surface: &WindingNumber,
    cell: f32,
) -> Result<TetMesh, super::tet_mesh::TetMeshError> {
    let mut faces: HashMap<[u32; 3], u32> = HashMap::with_capacity(grid.tet_count() * 2);
    for tet in grid.tets() {
        for skip in 0..4 {
            let mut face = [
                tet[(skip + 1) % 4],
                tet[(skip + 2) % 4],
                tet[(skip + 3) % 4],
            ];
            face.sort_unstable();
            *faces.entry(face).or_insert(0) += 1;
        }
    }
    let mut on_boundary = vec![false; grid.vertex_count()];
    for (face, count) in &faces {
        if *count == 1 {
            for &v in face {
                on_boundary[v as usize] = true;
            }
        }
    }
    let mut positions = grid.positions().to_vec();
    let tets = grid.tets();
    for v in 0..positions.len() {
        if !on_boundary[v] {
            continue;
        }
        let start = positions[v];
        let Some(nearest) = surface.closest_point(start) else {
            continue;
        };
        let offset = nearest - start;
        let distance = offset.length();
        if distance > FIT_REACH * cell || distance == 0.0 {
            continue;
        }
        // The nearest triangle may lie inside the solid (an overlapping part's face, a
        // duplicate wall): the boundary is where the inside test flips, so look for that flip
        // between the vertex and a little past the nearest point, and go there.
        let past = nearest + offset * (0.1 * cell / distance);
        let inside_at = |p: Vec3| surface.at(p) >= 0.5;
        let start_inside = inside_at(start);
        if inside_at(past) == start_inside {
            continue;
        }
        let (mut near, mut far) = (0.0f32, 1.0f32);
        for _ in 0..12 {
            let mid = 0.5 * (near + far);
            if inside_at(start + (past - start) * mid) == start_inside {
                near = mid;
            } else {
                far = mid;
            }
        }
        let offset = (past - start) * (0.5 * (near + far));
        for fraction in [1.0, 0.5, 0.25] {
            positions[v] = start + offset * fraction;
            let acceptable = grid.one_ring(v).iter().all(|&t| {
                let p = tets[t as usize].map(|i| positions[i as usize]);
                signed_volume(&p) >= FIT_MIN_VOLUME * grid.rest_volumes()[t as usize]
                    && min_dihedral_deg(&p) >= FIT_MIN_DIHEDRAL_DEG
            });
            if acceptable {
                break;
            }
            positions[v] = start;
        }
    }
    TetMesh::new(positions, tets.to_vec())
}

/// The grid's minimum corner and cell counts covering `[lo, hi]` with half a cell of margin.
fn grid_frame(lo: Vec3, hi: Vec3, cell: f32) -> Result<(Vec3, UVec3), TetrahedralizeError> {
    let counts = ((hi - lo) / cell + 1.0).ceil();
    let total = counts.x as f64 * counts.y as f64 * counts.z as f64;
    let limit = MAX_TETRAHEDRALIZE_CELLS.min(MAX_GRID_CELLS);
    if !(total.is_finite() && total <= limit as f64) {
        return Err(GridError::TooManyCells {
            cells: if total.is_finite() {
                total as u64
            } else {
                u64::MAX
            },
            limit,
        }
        .into());
    }
    let cells = counts.as_uvec3().max(UVec3::ONE);
    let centre = (lo + hi) * 0.5;
    let min = centre - cells.as_vec3() * cell * 0.5;
    Ok((min, cells))
}

fn inside_cells(winding: &WindingNumber, min: Vec3, cells: UVec3, cell: f32) -> Vec<bool> {
    let mut inside = Vec::with_capacity((cells.x * cells.y * cells.z) as usize);
    for z in 0..cells.z {
        for y in 0..cells.y {
            for x in 0..cells.x {
                let centre = min + (UVec3::new(x, y, z).as_vec3() + 0.5) * cell;
                inside.push(winding.at(centre) >= 0.5);
            }
        }
    }
    inside
}

fn count_inside(
    winding: &WindingNumber,
    lo: Vec3,
    hi: Vec3,
    cell: f32,
) -> Result<usize, TetrahedralizeError> {
    let (min, cells) = grid_frame(lo, hi, cell)?;
    Ok(inside_cells(winding, min, cells, cell)
        .iter()
        .filter(|&&b| b)
        .count())
}

/// Number of pieces of `mesh` connected through shared tet faces.
pub fn face_components(mesh: &TetMesh) -> usize {
    let tets = mesh.tets();
    let mut parent: Vec<u32> = (0..tets.len() as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    let mut faces: HashMap<[u32; 3], u32> = HashMap::with_capacity(tets.len() * 2);
    for (t, tet) in tets.iter().enumerate() {
        for skip in 0..4 {
            let mut face = [0u32; 3];
            let mut k = 0;
            for (j, &v) in tet.iter().enumerate() {
                if j != skip {
                    face[k] = v;
                    k += 1;
                }
            }
            face.sort_unstable();
            if let Some(&other) = faces.get(&face) {
                let (a, b) = (find(&mut parent, t as u32), find(&mut parent, other));
                parent[a as usize] = b;
            } else {
                faces.insert(face, t as u32);
            }
        }
    }
    (0..tets.len() as u32)
        .filter(|&t| find(&mut parent, t) == t)
        .count()
}

/// The input after welding, deduplication and orientation.
struct Cleaned {
    triangles: Vec<[Vec3; 3]>,
    volume: f64,
    flipped: usize,
    duplicates: usize,
    degenerate: usize,
    part_bounds: Vec<(Vec3, Vec3)>,
}

fn clean(positions: &[Vec3], indices: &[u32]) -> Result<Cleaned, TetrahedralizeError> {
    check_input(positions, indices)?;
    let Welded {
        lo,
        hi,
        weld,
        positions: welded_positions,
    } = weld(positions);
    let (mut tris, duplicates, degenerate) = unique_triangles(indices, &weld, &welded_positions);
    if tris.is_empty() {
        return Err(TetrahedralizeError::Degenerate);
    }
    let Patches {
        patch,
        mut turned,
        count: patches,
    } = orient_patches(&mut tris);
    // Each patch encloses positive volume (turn it inside out otherwise). An open patch has a
    // volume that depends on where the origin is; measured from the mesh's centre, it is
    // positive for a surface facing outwards from there, the common case for a model.
    let centre = (lo + hi) * 0.5;
    let mut patch_volume = vec![0.0f64; patches as usize];
    for (t, tri) in tris.iter().enumerate() {
        let p = tri.map(|v| welded_positions[v as usize] - centre);
        patch_volume[patch[t] as usize] += p[0].dot(p[1].cross(p[2])) as f64 / 6.0;
    }
    for (t, tri) in tris.iter_mut().enumerate() {
        if patch_volume[patch[t] as usize] < 0.0 {
            tri.swap(1, 2);
            turned[t] = !turned[t];
        }
    }
    let flipped = turned.iter().filter(|&&t| t).count();
    let volume = patch_volume.iter().map(|v| v.abs()).sum();

    let part_bounds = part_bounds(&tris, &welded_positions);

    Ok(Cleaned {
        triangles: tris
            .iter()
            .map(|t| t.map(|v| welded_positions[v as usize]))
            .collect(),
        volume,
        flipped,
        duplicates,
        degenerate,
        part_bounds,
    })
}

/// Checks the triangle list: whole triangles, some, finite vertices, indices in range.
fn check_input(positions: &[Vec3], indices: &[u32]) -> Result<(), TetrahedralizeError> {
    if !indices.len().is_multiple_of(3) {
        return Err(TetrahedralizeError::PartialTriangle(indices.len()));
    }
    if indices.is_empty() {
        return Err(TetrahedralizeError::NoTriangles);
    }
    if let Some((vertex, &position)) = positions.iter().enumerate().find(|(_, p)| !p.is_finite()) {
        return Err(TetrahedralizeError::NonFiniteVertex { vertex, position });
    }
    for (i, &v) in indices.iter().enumerate() {
        if v as usize >= positions.len() {
            return Err(TetrahedralizeError::IndexOutOfRange {
                triangle: i / 3,
                vertex: v,
                vertices: positions.len(),
            });
        }
    }
    Ok(())
}

/// The input's vertices welded where they sit at the same position.
struct Welded {
    lo: Vec3,
    hi: Vec3,
    /// Per input vertex, its welded vertex.
    weld: Vec<u32>,
    positions: Vec<Vec3>,
}

/// Welds vertices that sit at the same position (up to a millionth of the mesh's size), so
/// that split vertices (UV seams, flat shading) still connect their triangles.
fn weld(positions: &[Vec3]) -> Welded {
    let (lo, hi) = positions.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(a, b), p| (a.min(*p), b.max(*p)),
    );
    let quantum = ((hi - lo).max_element() * 1e-6).max(f32::MIN_POSITIVE);
    let mut welded_of: HashMap<[i64; 3], u32> = HashMap::new();
    let mut weld = vec![0u32; positions.len()];
    let mut welded_positions = Vec::new();
    for (i, p) in positions.iter().enumerate() {
        let key = ((*p - lo) / quantum).round().as_i64vec3().to_array();
        weld[i] = *welded_of.entry(key).or_insert_with(|| {
            welded_positions.push(*p);
            welded_positions.len() as u32 - 1
        });
    }
    Welded {
        lo,
        hi,
        weld,
        positions: welded_positions,
    }
}

/// The triangles on the welded vertices, without degenerate or repeated ones, and how many of
/// each were dropped.
fn unique_triangles(
    indices: &[u32],
    weld: &[u32],
    welded_positions: &[Vec3],
) -> (Vec<[u32; 3]>, usize, usize) {
    let mut seen = HashMap::new();
    let mut tris: Vec<[u32; 3]> = Vec::with_capacity(indices.len() / 3);
    let (mut duplicates, mut degenerate) = (0, 0);
    for t in indices.chunks_exact(3) {
        let tri = [
            weld[t[0] as usize],
            weld[t[1] as usize],
            weld[t[2] as usize],
        ];
        let p = tri.map(|v| welded_positions[v as usize]);
        if tri[0] == tri[1]
            || tri[1] == tri[2]
            || tri[0] == tri[2]
            || (p[1] - p[0]).cross(p[2] - p[0]) == Vec3::ZERO
        {
            degenerate += 1;
            continue;
        }
        let mut key = tri;
        key.sort_unstable();
        if seen.insert(key, ()).is_some() {
            duplicates += 1;
            continue;
        }
        tris.push(tri);
    }
    (tris, duplicates, degenerate)
}

/// The triangles' orientation patches: per triangle its patch and whether it was turned.
struct Patches {
    patch: Vec<u32>,
    turned: Vec<bool>,
    count: u32,
}

/// Orients patches: breadth-first through manifold edges (two triangles), each neighbour made
/// to run their shared edge the other way.
fn orient_patches(tris: &mut [[u32; 3]]) -> Patches {
    // Edges and the triangles on them.
    let mut edge_tris: HashMap<[u32; 2], Vec<u32>> = HashMap::with_capacity(tris.len() * 2);
    for (t, tri) in tris.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            edge_tris
                .entry([a.min(b), a.max(b)])
                .or_default()
                .push(t as u32);
        }
    }
    let directed =
        |tri: &[u32; 3], a: u32, b: u32| (0..3).any(|k| tri[k] == a && tri[(k + 1) % 3] == b);

    let mut patch = vec![u32::MAX; tris.len()];
    let mut turned = vec![false; tris.len()];
    let mut patches = 0u32;
    let mut queue = std::collections::VecDeque::new();
    for seed in 0..tris.len() {
        if patch[seed] != u32::MAX {
            continue;
        }
        patch[seed] = patches;
        queue.push_back(seed as u32);
        while let Some(t) = queue.pop_front() {
            let tri = tris[t as usize];
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                let on_edge = &edge_tris[&[a.min(b), a.max(b)]];
                if on_edge.len() != 2 {
                    continue;
                }
                let other = if on_edge[0] == t {
                    on_edge[1]
                } else {
                    on_edge[0]
                };
                if patch[other as usize] != u32::MAX {
                    continue;
                }
                patch[other as usize] = patches;
                if directed(&tris[other as usize], a, b) {
                    tris[other as usize].swap(1, 2);
                    turned[other as usize] = true;
                }
                queue.push_back(other);
            }
        }
        patches += 1;
    }
    Patches {
        patch,
        turned,
        count: patches,
    }
}

/// Parts (triangles connected through shared vertices) and their bounds.
fn part_bounds(tris: &[[u32; 3]], welded_positions: &[Vec3]) -> Vec<(Vec3, Vec3)> {
    let mut parent: Vec<u32> = (0..welded_positions.len() as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    for tri in tris {
        for k in 1..3 {
            let (a, b) = (find(&mut parent, tri[0]), find(&mut parent, tri[k]));
            parent[a as usize] = b;
        }
    }
    let mut part_of_root = HashMap::new();
    let mut part_bounds: Vec<(Vec3, Vec3)> = Vec::new();
    for tri in tris {
        let root = find(&mut parent, tri[0]);
        let part = *part_of_root.entry(root).or_insert_with(|| {
            part_bounds.push((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)));
            part_bounds.len() - 1
        });
        for &v in tri {
            let p = welded_positions[v as usize];
            part_bounds[part].0 = part_bounds[part].0.min(p);
            part_bounds[part].1 = part_bounds[part].1.max(p);
        }
    }
    part_bounds
}

#[cfg(test)]
mod tests;
