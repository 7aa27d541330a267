//! The tetrahedral mesh a soft body is simulated on: rest positions, tets, rest volumes,
//! edges (the springs), and the adjacency the volume passes walk, in compact arrays.

use glam::Vec3;

use super::geometry::{min_dihedral_deg, signed_volume};
use super::lanes::LANES;

/// Compressed rows: row `i` is `items[offsets[i]..offsets[i + 1]]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Csr {
    offsets: Vec<u32>,
    items: Vec<u32>,
}

impl Csr {
    /// Builds rows from a list of `(row, item)` pairs; items keep their order within a row.
    fn from_pairs(rows: usize, pairs: &[(u32, u32)]) -> Self {
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
    fn number_items(&mut self) {
        for (k, item) in self.items.iter_mut().enumerate() {
            *item = k as u32;
        }
    }
}

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
    tet_neighbours: Csr,
    blocks: Blocks,
    reoriented_tets: usize,
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
    /// The same tets of each task in bundles of [`LANES`] that share no vertex, padded with
    /// [`NO_TET`] (see [`bundle_disjoint`]): the per-tet pass computes a bundle's tets side by side
    /// in SIMD lanes, and since no impulse of a bundle moves a particle of another, that is
    /// exactly the four impulses one after another.
    pub tet_bundles: Csr,
    /// The corners of each item of [`Blocks::tet_bundles`], in the same order (`[0; 4]` for
    /// [`NO_TET`]), and their rest volumes (0 for [`NO_TET`]): the per-tet pass reads them
    /// front to back instead of looking each tet up across the mesh's arrays.
    pub bundle_corners: Vec<[u32; 4]>,
    /// See [`Blocks::bundle_corners`].
    pub bundle_rest_volumes: Vec<f32>,
    /// Springs (indices into [`TetMesh::edges`]) of each task, in the order of their bundles
    /// of [`LANES`] that share no vertex (see [`bundle_disjoint`]), without the padding. The
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
/// most [`BUNDLE_LOOK_AHEAD`] tets ahead. Each lane walks its part in order (neighbouring tets
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

    fn new(
        positions: &[Vec3],
        tets: &[[u32; 4]],
        rest_volumes: &[f32],
        edges: &[[u32; 2]],
        ring_vertices: &Csr,
    ) -> Blocks {
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
        let Some((_, ba, bb, [ca, cb], width)) = best else {
            unreachable!("three pairs of axes were tried")
        };
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
        if positions.len() > u32::MAX as usize {
            return Err(TetMeshError::TooManyVertices(positions.len()));
        }
        if let Some((vertex, &position)) =
            positions.iter().enumerate().find(|(_, p)| !p.is_finite())
        {
            return Err(TetMeshError::NonFiniteVertex { vertex, position });
        }
        let n = positions.len();
        let mut rest_volumes = Vec::with_capacity(tets.len());
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
        }
        if let Some(vertex) = used.iter().position(|&u| !u) {
            return Err(TetMeshError::UnreferencedVertex { vertex });
        }

        // Edges: every vertex pair of every tet, once.
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

        let pairs: Vec<(u32, u32)> = tets
            .iter()
            .enumerate()
            .flat_map(|(t, tet)| tet.map(|i| (i, t as u32)))
            .collect();
        let one_rings = Csr::from_pairs(n, &pairs);

        // Ring vertices (all vertices of the ring's tets, the centre first) and the tets that
        // touch the ring from outside, which the neighbour clamp must also watch.
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
        let ring_vertices = Csr::from_pairs(n, &ring_pairs);
        let ring_border_tets = Csr::from_pairs(n, &border_pairs);
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

        // Tets sharing at least one vertex with each tet.
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
        let tet_neighbours = Csr::from_pairs(tets.len(), &neighbour_pairs);
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

        Ok(TetMesh {
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
            tet_neighbours,
            blocks,
            reoriented_tets,
        })
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

    /// How many input tets had negative orientation and were reoriented.
    pub fn reoriented_tets(&self) -> usize {
        self.reoriented_tets
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

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_tet() -> (Vec<Vec3>, Vec<[u32; 4]>) {
        (
            vec![Vec3::X, Vec3::Y, Vec3::Z, Vec3::ZERO],
            vec![[0, 1, 2, 3]],
        )
    }

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
            glam::UVec3::new(3, 2, 4),
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
        let m =
            crate::core::grid::box_grid(glam::UVec3::new(3, 3, 2), Vec3::splat(0.5), Vec3::ZERO)
                .unwrap();
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
}
