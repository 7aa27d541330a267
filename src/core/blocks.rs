//! The thread schedule of a mesh's passes: the mesh cut into blocks that can run at the same
//! time ([`Blocks`]), the order that gives the serial result, and the compressed rows ([`Csr`])
//! the schedule and the mesh's adjacency are kept in.

use glam::Vec3;

use super::lanes::LANES;

/// Compressed rows: row `i` is `items[offsets[i]..offsets[i + 1]]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Csr {
    offsets: Vec<u32>,
    items: Vec<u32>,
}

impl Csr {
    /// Builds rows from a list of `(row, item)` pairs; items keep their order within a row.
    pub(crate) fn from_pairs(rows: usize, pairs: &[(u32, u32)]) -> Self {
        let mut offsets = vec![0u32; rows + 1];
        for &(r, _) in pairs {
            offsets[r as usize + 1] += 1;
        }
        for i in 0..rows {
            offsets[i + 1] += offsets[i];
        }
        let mut fill = offsets.clone();
        let mut items = vec![0u32; pairs.len()];
        for &(r, item) in pairs {
            items[fill[r as usize] as usize] = item;
            fill[r as usize] += 1;
        }
        Csr { offsets, items }
    }

    /// Where row `i` lies in the flat list of items.
    #[inline]
    pub(crate) fn range(&self, i: usize) -> std::ops::Range<usize> {
        self.offsets[i] as usize..self.offsets[i + 1] as usize
    }

    /// Row `i`.
    #[inline]
    pub fn row(&self, i: usize) -> &[u32] {
        &self.items[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Whether there are no rows.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Total number of items over all rows.
    pub fn total(&self) -> usize {
        self.items.len()
    }

    /// All items, row after row.
    pub fn items(&self) -> &[u32] {
        &self.items
    }

    /// Makes each item its own place in the flat list (`0, 1, 2, ...` row after row), for
    /// items renumbered in this order.
    pub(crate) fn number_items(&mut self) {
        for (k, item) in self.items.iter_mut().enumerate() {
            *item = k as u32;
        }
    }
}

/// The mesh cut into blocks for passes that run on several threads, and the order of the
/// blocks in a pass.
///
/// Each vertex has two layer numbers, its graph distance (in edges) from each of two opposite
/// faces of the mesh's bounding box, across two axes; a block holds [`Blocks::width`] layers of
/// each. Blocks that are not neighbours (in either layer count) are at least `width + 1 >= 4`
/// edges apart, which is what lets them run at the same time: a ring impulse moves the
/// particles one edge from its centre and reads those up to two edges further, a tet impulse
/// moves its corners and reads one edge further, a spring moves its two ends. Blocks run in
/// four colours (the parities of their two block numbers), so neighbours never share a colour.
/// The result is that of running the tasks (blocks) one after another in their order; a task
/// need only wait for its neighbours earlier in that order ([`Blocks::waits_for`]), and no
/// task touches what another task it does not wait for (and which does not wait for it)
/// writes (tested for every kind of job in `tests`).
#[derive(Clone, Debug)]
pub struct Blocks {
    /// Vertices of each task, in index order: the ring impulses' centres.
    pub vertices: Csr,
    /// Tets of each task (the block of their lowest layers), in index order.
    pub tets: Csr,
    /// The same tets of each task in bundles of `LANES` that share no vertex, padded with
    /// `NO_TET` (see `bundle_disjoint`): the per-tet pass computes a bundle's tets side by side
    /// in SIMD lanes, and since no impulse of a bundle moves a particle of another, that is
    /// exactly the four impulses one after another.
    pub tet_bundles: Csr,
    /// The corners of each item of [`Blocks::tet_bundles`], in the same order (`[0; 4]` for
    /// `NO_TET`), and their rest volumes (0 for `NO_TET`): the per-tet pass reads them
    /// front to back instead of looking each tet up across the mesh's arrays.
    pub bundle_corners: Vec<[u32; 4]>,
    /// See [`Blocks::bundle_corners`].
    pub bundle_rest_volumes: Vec<f32>,
    /// Springs (indices into [`TetMesh::edges`](super::tet_mesh::TetMesh::edges)) of each task, in the order of their bundles
    /// of `LANES` that share no vertex (see `bundle_disjoint`), without the padding. The
    /// mesh numbers its edges in this order, so the rows hold `0, 1, 2, ...` one after another.
    pub edges: Csr,
    /// For each task, the earlier tasks it must wait for: its neighbouring blocks of earlier
    /// colours.
    pub waits_for: Csr,
    /// For each task, its neighbouring blocks (of earlier and later colours): the only ones
    /// whose particles its jobs read.
    pub neighbours: Csr,
    /// Layers per block, in each of the two layer counts.
    pub width: [u32; 2],
}

/// The padding of [`Blocks::tet_bundles`]: no tet.
pub const NO_TET: u32 = u32::MAX;

/// How far ahead in a task's tets [`bundle_disjoint`] looks for a bundle's other tets.
const BUNDLE_LOOK_AHEAD: usize = 128;

/// `row`'s tets (or springs: `tets` holds the vertices of each item) in bundles of [`LANES`]
/// that share no vertex, padded with [`NO_TET`]. The row is cut into [`LANES`] parts, which
/// are interleaved (the first tet of each part, then the second of each, ...), so that a
/// bundle's tets come from parts of the block far apart; then each bundle starts with the
/// first tet not yet bundled and takes the next ones that share no vertex with it, looking at
/// most `BUNDLE_LOOK_AHEAD` tets ahead. Each lane walks its part in order (neighbouring tets
/// share cache lines), and few lanes stay empty, even at the end.
pub fn bundle_disjoint<const N: usize>(tets: &[[u32; N]], row: &[u32]) -> Vec<u32> {
    let part = row.len().div_ceil(LANES);
    let row: Vec<u32> = (0..part)
        .flat_map(|k| (0..LANES).filter_map(move |p| row.get(p * part + k).copied()))
        .collect();
    let mut bundles = Vec::with_capacity(row.len() + row.len() / 8 + LANES);
    let mut taken = vec![false; row.len()];
    for first in 0..row.len() {
        if taken[first] {
            continue;
        }
        taken[first] = true;
        let mut bundle = vec![row[first]];
        let ahead = (first + 1..row.len()).take(BUNDLE_LOOK_AHEAD);
        for next in ahead {
            if bundle.len() == LANES {
                break;
            }
            let corners = tets[row[next] as usize];
            let shares = bundle
                .iter()
                .any(|&t| tets[t as usize].iter().any(|i| corners.contains(i)));
            if !taken[next] && !shares {
                taken[next] = true;
                bundle.push(row[next]);
            }
        }
        bundles.extend(&bundle);
        bundles.extend(std::iter::repeat_n(NO_TET, LANES - bundle.len()));
    }
    bundles
}

/// Blocks are at least this many layers wide: see [`Blocks`].
pub const MIN_BLOCK_WIDTH: u32 = 3;

/// Particles per 64-byte cache line of a `Vec3` array, about.
const PARTICLES_PER_LINE: usize = 5;

/// A mesh is cut into at most about this many blocks along each of its two axes.
pub const MAX_BLOCKS_PER_AXIS: u32 = 16;

impl Blocks {
    /// Number of tasks (blocks).
    pub fn count(&self) -> usize {
        self.vertices.len()
    }

    /// Each vertex's graph distance (in edges) from the vertices at or below `reach` along
    /// `axis`, and the number of layers; each further connected part starts after the layers
    /// so far (any numbering is safe between parts: nothing connects them).
    fn layers(positions: &[Vec3], ring_vertices: &Csr, axis: usize, reach: f32) -> (Vec<u32>, u32) {
        let n = positions.len();
        let mut layer = vec![u32::MAX; n];
        let mut queue = std::collections::VecDeque::new();
        for (i, p) in positions.iter().enumerate() {
            if p[axis] <= reach {
                layer[i] = 0;
                queue.push_back(i as u32);
            }
        }
        let mut layers = 0;
        loop {
            while let Some(v) = queue.pop_front() {
                let l = layer[v as usize];
                layers = layers.max(l + 1);
                for &u in ring_vertices.row(v as usize) {
                    if layer[u as usize] == u32::MAX {
                        layer[u as usize] = l + 1;
                        queue.push_back(u);
                    }
                }
            }
            let Some(seed) = (0..n)
                .filter(|&i| layer[i] == u32::MAX)
                .min_by(|&a, &b| positions[a][axis].total_cmp(&positions[b][axis]))
            else {
                break;
            };
            layer[seed] = layers;
            queue.push_back(seed as u32);
        }
        (layer, layers)
    }

    /// The blocks along the best pair of axes: each particle's block along each, the blocks'
    /// counts and widths in layers.
    fn block_axes(positions: &[Vec3], edges: &[[u32; 2]], ring_vertices: &Csr) -> BlockAxes {
        let n = positions.len();
        let lo = positions.iter().fold(Vec3::INFINITY, |lo, &p| lo.min(p));
        let mean_edge = edges
            .iter()
            .map(|&[i, j]| positions[i as usize].distance(positions[j as usize]) as f64)
            .sum::<f64>()
            / edges.len().max(1) as f64;
        // Layers from the low face of each axis (within half a mean edge, so that the layers
        // of a box are planes and not shells around a corner).
        let layers: [(Vec<u32>, u32); 3] = std::array::from_fn(|axis| {
            Self::layers(
                positions,
                ring_vertices,
                axis,
                lo[axis] + 0.5 * mean_edge as f32,
            )
        });
        let block_of = |(layer, count): &(Vec<u32>, u32)| {
            let width = MIN_BLOCK_WIDTH.max(count.div_ceil(MAX_BLOCKS_PER_AXIS));
            let blocks: Vec<u32> = layer.iter().map(|&l| l / width).collect();
            (blocks, count.div_ceil(width), width)
        };
        // Of the three pairs of axes, the one with the most blocks, then the one whose blocks
        // least share cache lines of the particle arrays: threads writing the same line slow
        // each other down many times over (a grid numbered x first, cut across x, had every
        // line written by two blocks at once and ran slower on two threads than on one).
        type Choice = (
            (std::cmp::Reverse<u32>, usize),
            Vec<u32>,
            Vec<u32>,
            [u32; 2],
            [u32; 2],
        );
        let mut best: Option<Choice> = None;
        for (a, b) in [(0, 1), (0, 2), (1, 2)] {
            let (ba, ca, wa) = block_of(&layers[a]);
            let (bb, cb, wb) = block_of(&layers[b]);
            let block: Vec<u32> = (0..n).map(|i| ba[i] + ca * bb[i]).collect();
            let shared = block
                .chunks(PARTICLES_PER_LINE)
                .filter(|line| line.iter().any(|&k| k != line[0]))
                .count();
            let key = (std::cmp::Reverse((ca * cb).min(64)), shared);
            if best.as_ref().is_none_or(|(k, ..)| key < *k) {
                best = Some((key, ba, bb, [ca, cb], [wa, wb]));
            }
        }
        let Some((_, ba, bb, counts, width)) = best else {
            unreachable!("three pairs of axes were tried")
        };
        BlockAxes {
            ba,
            bb,
            counts,
            width,
        }
    }

    pub(crate) fn new(
        positions: &[Vec3],
        tets: &[[u32; 4]],
        rest_volumes: &[f32],
        edges: &[[u32; 2]],
        ring_vertices: &Csr,
    ) -> Blocks {
        let n = positions.len();
        let BlockAxes {
            ba,
            bb,
            counts: [ca, cb],
            width,
        } = Self::block_axes(positions, edges, ring_vertices);
        // Tasks: blocks by colour, then row, then column.
        let colour = |x: u32, y: u32| x % 2 + 2 * (y % 2);
        let mut order: Vec<(u32, u32, u32)> = (0..cb)
            .flat_map(|y| (0..ca).map(move |x| (colour(x, y), y, x)))
            .collect();
        order.sort_unstable();
        let mut task_of = vec![0u32; (ca * cb) as usize];
        for (task, &(_, y, x)) in order.iter().enumerate() {
            task_of[(x + ca * y) as usize] = task as u32;
        }
        let task = |x: u32, y: u32| task_of[(x + ca * y) as usize];
        let count = order.len();
        let vertex_pairs: Vec<(u32, u32)> =
            (0..n).map(|i| (task(ba[i], bb[i]), i as u32)).collect();
        let lowest = |vertices: &[u32]| {
            let x = vertices.iter().map(|&i| ba[i as usize]).min().unwrap_or(0);
            let y = vertices.iter().map(|&i| bb[i as usize]).min().unwrap_or(0);
            task(x, y)
        };
        let tet_pairs: Vec<(u32, u32)> = tets
            .iter()
            .enumerate()
            .map(|(t, tet)| (lowest(tet), t as u32))
            .collect();
        let edge_pairs: Vec<(u32, u32)> = edges
            .iter()
            .enumerate()
            .map(|(e, edge)| (lowest(edge), e as u32))
            .collect();
        // Each task's springs in the order of their bundles (see `bundle_disjoint`): consecutive
        // springs of one vertex made the dampers a chain, each waiting for the velocity the
        // last one stored; four that share no vertex run side by side.
        let block_edges = Csr::from_pairs(count, &edge_pairs);
        let edge_pairs: Vec<(u32, u32)> = (0..count)
            .flat_map(|task| {
                bundle_disjoint(edges, block_edges.row(task))
                    .into_iter()
                    .filter(|&e| e != NO_TET)
                    .map(move |e| (task as u32, e))
            })
            .collect();
        let mut wait_pairs = Vec::new();
        for &(c, y, x) in &order {
            for ny in y.saturating_sub(1)..(y + 2).min(cb) {
                for nx in x.saturating_sub(1)..(x + 2).min(ca) {
                    if colour(nx, ny) < c {
                        wait_pairs.push((task(x, y), task(nx, ny)));
                    }
                }
            }
        }
        let block_tets = Csr::from_pairs(count, &tet_pairs);
        let bundle_pairs: Vec<(u32, u32)> = (0..count)
            .flat_map(|task| {
                bundle_disjoint(tets, block_tets.row(task))
                    .into_iter()
                    .map(move |t| (task as u32, t))
            })
            .collect();
        let mut neighbour_pairs: Vec<(u32, u32)> = wait_pairs
            .iter()
            .flat_map(|&(late, early)| [(late, early), (early, late)])
            .collect();
        neighbour_pairs.sort_unstable();
        let bundled = |t: u32| (t != NO_TET).then_some(t as usize);
        let bundle_corners = (bundle_pairs.iter())
            .map(|&(_, t)| bundled(t).map_or([0; 4], |t| tets[t]))
            .collect();
        let bundle_rest_volumes = (bundle_pairs.iter())
            .map(|&(_, t)| bundled(t).map_or(0.0, |t| rest_volumes[t]))
            .collect();
        Blocks {
            vertices: Csr::from_pairs(count, &vertex_pairs),
            tets: block_tets,
            tet_bundles: Csr::from_pairs(count, &bundle_pairs),
            bundle_corners,
            bundle_rest_volumes,
            edges: Csr::from_pairs(count, &edge_pairs),
            waits_for: Csr::from_pairs(count, &wait_pairs),
            neighbours: Csr::from_pairs(count, &neighbour_pairs),
            width,
        }
    }
}

/// The pair of axes the blocks are cut along (see `Blocks::block_axes`).
struct BlockAxes {
    /// Each particle's block along the first axis, and along the second.
    ba: Vec<u32>,
    bb: Vec<u32>,
    /// Blocks along each axis.
    counts: [u32; 2],
    /// Layers a block spans along each axis.
    width: [u32; 2],
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::tet_mesh::TetMesh;

    /// Whether every two tasks of which one writes what the other reads or writes are ordered:
    /// the later waits for the earlier. `access(item)` gives what one job writes and reads.
    fn tasks_are_ordered(
        mesh: &TetMesh,
        items: &Csr,
        waits_for: &Csr,
        access: impl Fn(u32) -> (Vec<u32>, Vec<u32>),
    ) -> bool {
        let n = mesh.vertex_count();
        let mut writers: Vec<Vec<u32>> = vec![Vec::new(); n];
        let mut touchers: Vec<Vec<u32>> = vec![Vec::new(); n];
        for task in 0..items.len() {
            for &item in items.row(task) {
                let (written, read) = access(item);
                for &v in &written {
                    writers[v as usize].push(task as u32);
                }
                for v in written.into_iter().chain(read) {
                    touchers[v as usize].push(task as u32);
                }
            }
        }
        for v in 0..n {
            for &w in &writers[v] {
                for &t in &touchers[v] {
                    let (early, late) = (w.min(t), w.max(t));
                    if early != late && !waits_for.row(late as usize).contains(&early) {
                        return false;
                    }
                }
            }
        }
        true
    }

    /// Meshes to cut into blocks: the paper's bar and cube, a thin rod, a tetrahedralized torus.
    fn block_test_meshes() -> [TetMesh; 4] {
        use crate::core::grid::box_grid;
        use crate::core::surface_mesh::torus;
        use crate::core::tetrahedralize::{Resolution, tetrahedralize};
        use glam::UVec3;
        let ring = torus(Vec3::ZERO, 1.0, 0.4, 48, 24);
        [
            box_grid(UVec3::new(6, 6, 24), Vec3::splat(0.1), Vec3::ZERO).unwrap(),
            box_grid(UVec3::splat(12), Vec3::splat(0.1), Vec3::ZERO).unwrap(),
            box_grid(UVec3::new(40, 2, 2), Vec3::splat(0.1), Vec3::ZERO).unwrap(),
            tetrahedralize(&ring.positions, &ring.indices, Resolution::TargetTets(4000))
                .unwrap()
                .mesh,
        ]
    }

    #[test]
    fn tet_bundles_hold_each_tasks_tets_once_and_share_no_vertex() {
        for (m, mesh) in block_test_meshes().iter().enumerate() {
            let blocks = mesh.blocks();
            let mut padding = 0;
            for task in 0..blocks.count() {
                let bundles = blocks.tet_bundles.row(task);
                assert_eq!(bundles.len() % LANES, 0);
                for bundle in bundles.chunks(LANES) {
                    let corners: Vec<u32> = bundle
                        .iter()
                        .filter(|&&t| t != NO_TET)
                        .flat_map(|&t| mesh.tets()[t as usize])
                        .collect();
                    let mut distinct = corners.clone();
                    distinct.sort_unstable();
                    distinct.dedup();
                    assert_eq!(
                        distinct.len(),
                        corners.len(),
                        "bundle {bundle:?} shares a vertex"
                    );
                }
                // The bundles' own copies of their corners and rest volumes are the tets'.
                for (k, &t) in blocks.tet_bundles.range(task).zip(bundles) {
                    let (corners, rest) = match t {
                        NO_TET => ([0; 4], 0.0),
                        t => (mesh.tets()[t as usize], mesh.rest_volumes()[t as usize]),
                    };
                    assert_eq!(blocks.bundle_corners[k], corners);
                    assert_eq!(blocks.bundle_rest_volumes[k], rest);
                }
                let mut bundled: Vec<u32> =
                    bundles.iter().copied().filter(|&t| t != NO_TET).collect();
                padding += bundles.len() - bundled.len();
                bundled.sort_unstable();
                assert_eq!(bundled, blocks.tets.row(task), "task {task}");
            }
            // Empty lanes are wasted work: in the bar and the cube few of them, besides those
            // that round each task up to whole bundles. (A block of the 2x2 rod is three cells
            // along it, and any two tets share a vertex unless their cells are two apart: two
            // to a bundle at most. Some tasks of the torus hold 56 tets, half of them around
            // one vertex: two to a bundle at most there too.)
            assert!(
                m >= 2 || padding <= LANES * blocks.count() + mesh.tet_count() / 100,
                "{padding} empty lanes for {} tets",
                mesh.tet_count()
            );
        }
    }

    #[test]
    fn tasks_that_share_particles_wait_for_each_other() {
        let meshes = block_test_meshes();
        for mesh in &meshes {
            let blocks = mesh.blocks();
            assert!(blocks.count() >= 6, "{} tasks", blocks.count());
            let n2 = |vertices: &[u32]| -> Vec<u32> {
                vertices
                    .iter()
                    .flat_map(|&v| mesh.ring_vertices(v as usize).iter().copied())
                    .collect()
            };
            let ring = |p: u32| {
                let moved = mesh.ring_vertices(p as usize).to_vec();
                let read = n2(&moved);
                (moved, read)
            };
            let tet = |t: u32| {
                let moved = mesh.tets()[t as usize].to_vec();
                let read = n2(&moved);
                (moved, read)
            };
            let edge = |e: u32| (mesh.edges()[e as usize].to_vec(), vec![]);
            let waits = &blocks.waits_for;
            assert!(tasks_are_ordered(mesh, &blocks.vertices, waits, ring));
            assert!(tasks_are_ordered(mesh, &blocks.tets, waits, tet));
            assert!(tasks_are_ordered(mesh, &blocks.edges, waits, edge));
            // A task's jobs touch only the vertices of its own block and its neighbours.
            let mut block_of = vec![u32::MAX; mesh.vertex_count()];
            for task in 0..blocks.count() {
                for &v in blocks.vertices.row(task) {
                    block_of[v as usize] = task as u32;
                }
            }
            for (items, access) in [
                (
                    &blocks.vertices,
                    &ring as &dyn Fn(u32) -> (Vec<u32>, Vec<u32>),
                ),
                (&blocks.tets, &tet),
            ] {
                for task in 0..blocks.count() {
                    for &item in items.row(task) {
                        let (written, read) = access(item);
                        for v in written.into_iter().chain(read) {
                            let owner = block_of[v as usize];
                            assert!(
                                owner == task as u32
                                    || blocks.neighbours.row(task).contains(&owner),
                                "task {task} touches vertex {v} of block {owner}"
                            );
                        }
                    }
                }
            }
            // Tasks only wait for earlier ones, and some run without waiting at all.
            for task in 0..blocks.count() {
                assert!(waits.row(task).iter().all(|&w| (w as usize) < task));
            }
            assert!(waits.row(1).is_empty());
            // Every vertex, tet and spring in exactly one task.
            assert_eq!(blocks.vertices.total(), mesh.vertex_count());
            assert_eq!(blocks.tets.total(), mesh.tet_count());
            assert_eq!(blocks.edges.total(), mesh.edges().len());
            // The springs are numbered in the blocks' order, and they are the tets' edges, each
            // once.
            let springs = blocks.edges.items();
            assert!(springs.iter().enumerate().all(|(k, &e)| k == e as usize));
            let mut edges = mesh.edges().to_vec();
            edges.sort_unstable();
            let mut tet_edges: Vec<[u32; 2]> = (mesh.tets().iter())
                .flat_map(|t| {
                    [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
                        .map(|(a, b)| [t[a].min(t[b]), t[a].max(t[b])])
                })
                .collect();
            tet_edges.sort_unstable();
            tet_edges.dedup();
            assert_eq!(edges, tet_edges);
        }
        // And the check finds what is wrong: tasks one layer wide, none waiting.
        let mesh = &meshes[0];
        let pairs: Vec<(u32, u32)> = (0..mesh.vertex_count() as u32)
            .map(|v| ((mesh.positions()[v as usize].z / 0.1).round() as u32, v))
            .collect();
        let one_layer = Csr::from_pairs(25, &pairs);
        let ring = |p: u32| (mesh.ring_vertices(p as usize).to_vec(), vec![]);
        assert!(!tasks_are_ordered(
            mesh,
            &one_layer,
            &Csr::from_pairs(25, &[]),
            ring
        ));
    }
}
