//! Tet meshes on a regular grid: boxes (the paper's bar and cube) and shapes given by a signed
//! distance function (the procedural creature).

use glam::{IVec3, UVec3, Vec3};

use super::geometry::signed_volume;
use super::tet_mesh::{TetMesh, TetMeshError};

/// What is wrong with a grid request.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GridError {
    /// A cell count is zero.
    #[error("a grid needs at least one cell along each axis, got {0:?}")]
    NoCells(UVec3),
    /// Too many cells to build (the limit keeps a typo from allocating gigabytes).
    #[error("{cells} cells is more than the limit of {limit}")]
    TooManyCells {
        /// Cells requested.
        cells: u64,
        /// The limit.
        limit: u64,
    },
    /// The cell size is not a positive finite number.
    #[error("the cell size must be positive and finite, got {0:?}")]
    BadCellSize(Vec3),
    /// The signed distance function is negative in no cell.
    #[error("the shape covers no cell of the grid")]
    EmptyShape,
    /// The resulting mesh is invalid (cannot happen for finite input, reported rather than hidden).
    #[error(transparent)]
    Mesh(#[from] TetMeshError),
}

/// The most cells a grid may have: 16 million cells are 80 million tets.
pub const MAX_GRID_CELLS: u64 = 1 << 24;

/// The 5-tet split of a cube, as corner offsets. Corner `(0,0,0)`-type cells use `EVEN`; their
/// neighbours use the mirrored `ODD`, so that the face diagonals of neighbouring cells agree and
/// the mesh is conforming.
const EVEN: [[[u32; 3]; 4]; 5] = [
    [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
    [[1, 1, 0], [0, 1, 0], [1, 0, 0], [1, 1, 1]],
    [[1, 0, 1], [1, 0, 0], [0, 0, 1], [1, 1, 1]],
    [[0, 1, 1], [0, 0, 1], [0, 1, 0], [1, 1, 1]],
    [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]],
];
const ODD: [[[u32; 3]; 4]; 5] = [
    [[1, 0, 0], [0, 0, 0], [1, 1, 0], [1, 0, 1]],
    [[0, 1, 0], [1, 1, 0], [0, 0, 0], [0, 1, 1]],
    [[0, 0, 1], [1, 0, 1], [0, 1, 1], [0, 0, 0]],
    [[1, 1, 1], [0, 1, 1], [1, 0, 1], [1, 1, 0]],
    [[0, 0, 0], [1, 1, 0], [1, 0, 1], [0, 1, 1]],
];

fn check(cells: UVec3, cell_size: Vec3) -> Result<(), GridError> {
    if cells.min_element() == 0 {
        return Err(GridError::NoCells(cells));
    }
    let total = cells.x as u64 * cells.y as u64 * cells.z as u64;
    if total > MAX_GRID_CELLS {
        return Err(GridError::TooManyCells {
            cells: total,
            limit: MAX_GRID_CELLS,
        });
    }
    if !(cell_size.is_finite() && cell_size.min_element() > 0.0) {
        return Err(GridError::BadCellSize(cell_size));
    }
    Ok(())
}

/// Builds tets for the chosen cells of a grid, keeping only the vertices they use.
pub(crate) fn grid_cells(
    cells: UVec3,
    cell_size: Vec3,
    min_corner: Vec3,
    keep: impl Fn(UVec3) -> bool,
) -> Result<TetMesh, GridError> {
    let dims = cells + UVec3::ONE;
    let lattice_index = |c: UVec3| (c.z * dims.y + c.y) * dims.x + c.x;
    let mut vertex_of = vec![u32::MAX; (dims.x * dims.y * dims.z) as usize];
    let mut positions = Vec::new();
    let mut tets = Vec::new();
    for k in 0..cells.z {
        for j in 0..cells.y {
            for i in 0..cells.x {
                let cell = UVec3::new(i, j, k);
                if !keep(cell) {
                    continue;
                }
                let pattern = if (i + j + k) % 2 == 0 { &EVEN } else { &ODD };
                for corners in pattern {
                    let mut tet = [0u32; 4];
                    for (slot, corner) in tet.iter_mut().zip(corners) {
                        let c = cell + UVec3::from(*corner);
                        let l = lattice_index(c) as usize;
                        if vertex_of[l] == u32::MAX {
                            vertex_of[l] = positions.len() as u32;
                            positions.push(min_corner + c.as_vec3() * cell_size);
                        }
                        *slot = vertex_of[l];
                    }
                    let p = tet.map(|v| positions[v as usize]);
                    if signed_volume(&p) < 0.0 {
                        tet.swap(1, 2);
                    }
                    tets.push(tet);
                }
            }
        }
    }
    if tets.is_empty() {
        return Err(GridError::EmptyShape);
    }
    Ok(TetMesh::new(positions, tets)?)
}

/// A box of `cells.x * cells.y * cells.z` cells of `cell_size`, five tets per cell, with its
/// minimum corner at `min_corner`. 6 x 6 x 24 cells give the paper's 4320-tet bar, 12^3 its
/// 8640-tet cube.
pub fn box_grid(cells: UVec3, cell_size: Vec3, min_corner: Vec3) -> Result<TetMesh, GridError> {
    check(cells, cell_size)?;
    if !min_corner.is_finite() {
        return Err(GridError::Mesh(TetMeshError::NonFiniteVertex {
            vertex: 0,
            position: min_corner,
        }));
    }
    grid_cells(cells, cell_size, min_corner, |_| true)
}

/// A tet mesh of the cubic cells (edge `cell`) whose centre lies inside `sdf` (negative inside),
/// within the box `[min, max]`. Cells touching only along an edge or a corner still share those
/// particles, so the body is one piece wherever the shape is thicker than a cell.
pub fn sdf_grid(
    sdf: impl Fn(Vec3) -> f32,
    min: Vec3,
    max: Vec3,
    cell: f32,
) -> Result<TetMesh, GridError> {
    let size = Vec3::splat(cell);
    check(UVec3::ONE, size)?;
    if !(min.is_finite() && max.is_finite()) || max.cmple(min).any() {
        return Err(GridError::BadCellSize(max - min));
    }
    let cells = ((max - min) / cell)
        .ceil()
        .as_ivec3()
        .max(IVec3::ONE)
        .as_uvec3();
    check(cells, size)?;
    grid_cells(cells, size, min, |c| {
        sdf(min + (c.as_vec3() + 0.5) * cell) < 0.0
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_grids_have_the_paper_tet_counts() {
        let bar = box_grid(UVec3::new(6, 6, 24), Vec3::splat(0.1), Vec3::ZERO).unwrap();
        assert_eq!(bar.tet_count(), 4320);
        assert_eq!(bar.vertex_count(), 7 * 7 * 25);
        let cube = box_grid(UVec3::splat(12), Vec3::splat(0.1), Vec3::ZERO).unwrap();
        assert_eq!(cube.tet_count(), 8640);
        assert!((cube.total_rest_volume() - 1.2f64.powi(3)).abs() < 1e-4);
    }

    #[test]
    fn grid_is_conforming() {
        // In a conforming mesh every interior triangle is shared by exactly two tets and the
        // boundary triangles add up to the box surface: 2 per cell face.
        let m = box_grid(UVec3::new(3, 2, 4), Vec3::ONE, Vec3::ZERO).unwrap();
        let mut faces = std::collections::HashMap::new();
        for t in m.tets() {
            for f in [
                [t[0], t[1], t[2]],
                [t[0], t[1], t[3]],
                [t[0], t[2], t[3]],
                [t[1], t[2], t[3]],
            ] {
                let mut f = f;
                f.sort();
                *faces.entry(f).or_insert(0) += 1;
            }
        }
        assert!(faces.values().all(|&c| c <= 2));
        let boundary = faces.values().filter(|&&c| c == 1).count();
        assert_eq!(boundary, 2 * 2 * (3 * 2 + 2 * 4 + 3 * 4));
    }

    #[test]
    fn bad_grid_requests_give_errors() {
        assert!(matches!(
            box_grid(UVec3::new(0, 1, 1), Vec3::ONE, Vec3::ZERO),
            Err(GridError::NoCells(_))
        ));
        assert!(matches!(
            box_grid(UVec3::splat(100_000), Vec3::ONE, Vec3::ZERO),
            Err(GridError::TooManyCells { .. })
        ));
        assert!(matches!(
            box_grid(UVec3::ONE, Vec3::new(1.0, -1.0, 1.0), Vec3::ZERO),
            Err(GridError::BadCellSize(_))
        ));
        assert!(matches!(
            box_grid(UVec3::ONE, Vec3::splat(f32::NAN), Vec3::ZERO),
            Err(GridError::BadCellSize(_))
        ));
        assert!(matches!(
            sdf_grid(
                |p| p.length() - 0.01,
                Vec3::splat(-1.0),
                Vec3::splat(1.0),
                0.5
            ),
            Err(GridError::EmptyShape)
        ));
        assert!(matches!(
            sdf_grid(
                |p| p.length() - 1.0,
                Vec3::splat(-1.0),
                Vec3::splat(1.0),
                1e-6
            ),
            Err(GridError::TooManyCells { .. })
        ));
    }

    #[test]
    fn sdf_sphere_volume() {
        let m = sdf_grid(
            |p| p.length() - 1.0,
            Vec3::splat(-1.0),
            Vec3::splat(1.0),
            0.1,
        )
        .unwrap();
        let v = m.total_rest_volume();
        let exact = 4.0 / 3.0 * std::f64::consts::PI;
        assert!((v - exact).abs() / exact < 0.05, "{v} vs {exact}");
    }
}
