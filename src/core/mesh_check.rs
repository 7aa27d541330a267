//! What is wrong with a valid tet mesh's geometry: tets that fold over a neighbour or overlap
//! another. Such a mesh loads and simulates, but its tets' rest volumes add up to more than
//! the body holds, and the volume passes, which restore every tet to its own rest volume, push
//! the overlapping tets apart: the body swells there and its volume error spikes. Nothing in the
//! solver can tell which of two overlapping tets is the wrong one, so the mesh is reported when
//! it is built (`TetMesh::defects`), with the tets named, and left as it is: the fix is to
//! re-mesh.

use std::collections::HashMap;

use glam::{IVec3, Vec3};

use super::geometry::signed_volume;

/// A point counts as inside a tet when each of its barycentric coordinates is above this: a
/// vertex lying on a neighbour's face (as every vertex of a conforming mesh lies on its own
/// tets' faces) is not an overlap.
const INSIDE: f32 = 1e-4;

/// At most this many tet pairs of each kind are listed; the counts are complete.
pub const LISTED_DEFECTS: usize = 32;

/// The folds and overlaps of a tet mesh (see `TetMesh::defects`). Empty for a mesh a
/// tetrahedralizer made correctly.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MeshDefects {
    /// Pairs of tets that share a face and lie on the same side of it (the mesh folds over
    /// itself there), up to [`LISTED_DEFECTS`] of them.
    pub folded: Vec<[u32; 2]>,
    /// How many such pairs there are.
    pub folded_count: usize,
    /// Pairs of tets that share no face but overlap (a vertex or the centroid of one strictly
    /// inside the other), up to [`LISTED_DEFECTS`] of them.
    pub overlapping: Vec<[u32; 2]>,
    /// How many such pairs there are.
    pub overlapping_count: usize,
}

impl MeshDefects {
    /// Whether the mesh has neither folds nor overlaps.
    pub fn is_empty(&self) -> bool {
        self.folded_count == 0 && self.overlapping_count == 0
    }
}

impl std::fmt::Display for MeshDefects {
    /// One line naming the tets, and what the solver will do with them.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.is_empty() {
            return write!(f, "no folded or overlapping tets");
        }
        let list = |pairs: &[[u32; 2]], count: usize| {
            let mut s: Vec<String> = pairs.iter().map(|[a, b]| format!("{a}/{b}")).collect();
            if count > pairs.len() {
                s.push(format!("and {} more", count - pairs.len()));
            }
            s.join(", ")
        };
        if self.folded_count > 0 {
            write!(
                f,
                "{} pairs of tets fold over their shared face (tets {}); ",
                self.folded_count,
                list(&self.folded, self.folded_count)
            )?;
        }
        if self.overlapping_count > 0 {
            write!(
                f,
                "{} pairs of tets overlap (tets {}); ",
                self.overlapping_count,
                list(&self.overlapping, self.overlapping_count)
            )?;
        }
        write!(
            f,
            "the volume passes restore each tet to its own rest volume and will push these apart: \
             expect the body to swell there and its volume error to spike; re-mesh the model"
        )
    }
}

/// Finds the folds and overlaps of the tets `tets` on the vertices `x` (every vertex in some
/// tet, every tet of positive volume `rest_volumes`, as `TetMesh::new` has checked): the shared
/// faces from the tets' sorted face keys, the overlaps from every vertex and centroid tested
/// against the tets whose bounding boxes hold it (a uniform grid of the mean tet's size).
/// Linear in the tets for a mesh of even size.
pub(crate) fn find_defects(x: &[Vec3], tets: &[[u32; 4]], rest_volumes: &[f32]) -> MeshDefects {
    let mut defects = MeshDefects::default();

    // Folds: two tets across a face, their opposite vertices on the same side of it.
    let mut faces: Vec<([u32; 3], u32, u32)> = Vec::with_capacity(4 * tets.len());
    for (t, tet) in tets.iter().enumerate() {
        for k in 0..4 {
            let mut face = [tet[(k + 1) % 4], tet[(k + 2) % 4], tet[(k + 3) % 4]];
            face.sort_unstable();
            faces.push((face, t as u32, tet[k]));
        }
    }
    faces.sort_unstable();
    for group in faces.chunk_by(|a, b| a.0 == b.0) {
        for (a, &(face, ta, oa)) in group.iter().enumerate() {
            for &(_, tb, ob) in &group[a + 1..] {
                let p = face.map(|i| x[i as usize]);
                let side = |o: u32| signed_volume(&[x[o as usize], p[0], p[1], p[2]]);
                if side(oa) * side(ob) > 0.0 {
                    defects.folded_count += 1;
                    if defects.folded.len() < LISTED_DEFECTS {
                        defects.folded.push([ta, tb]);
                    }
                }
            }
        }
    }

    // Overlaps: a point of one tet strictly inside another that does not hold it as a vertex.
    let (lo, hi) = x
        .iter()
        .fold((x[0], x[0]), |(lo, hi), &p| (lo.min(p), hi.max(p)));
    let total: f64 = rest_volumes.iter().map(|&v| v as f64).sum();
    let mean_size = (total / tets.len() as f64).cbrt() as f32;
    let cell = (2.0 * mean_size).max((hi - lo).max_element() / 1024.0);
    let key = |p: Vec3| ((p - lo) / cell).floor().as_ivec3();
    let mut grid: HashMap<IVec3, Vec<u32>> = HashMap::new();
    for (t, tet) in tets.iter().enumerate() {
        let p = tet.map(|i| x[i as usize]);
        let (a, b) = (key(p.iter().copied().fold(p[0], Vec3::min)), {
            key(p.iter().copied().fold(p[0], Vec3::max))
        });
        for cx in a.x..=b.x {
            for cy in a.y..=b.y {
                for cz in a.z..=b.z {
                    grid.entry(IVec3::new(cx, cy, cz))
                        .or_default()
                        .push(t as u32);
                }
            }
        }
    }
    // The tets other than `own` and those with a corner in `skip` that hold `point`.
    let holding = |point: Vec3, own: u32, skip: u32, out: &mut Vec<u32>| {
        out.clear();
        for &t in grid.get(&key(point)).map_or(&[][..], Vec::as_slice) {
            let tet = tets[t as usize];
            if t != own
                && !tet.contains(&skip)
                && strictly_inside(point, tet.map(|i| x[i as usize]))
            {
                out.push(t);
            }
        }
    };
    let (mut pairs, mut found): (Vec<[u32; 2]>, Vec<u32>) = (Vec::new(), Vec::new());
    for (t, tet) in tets.iter().enumerate() {
        let p = tet.map(|i| x[i as usize]);
        holding(
            (p[0] + p[1] + p[2] + p[3]) * 0.25,
            t as u32,
            u32::MAX,
            &mut found,
        );
        pairs.extend(found.iter().map(|&u| [t as u32, u]));
    }
    // A vertex inside a tet it is not a corner of: the pair is that tet and one of the vertex's.
    let mut a_tet_of = vec![u32::MAX; x.len()];
    for (t, tet) in tets.iter().enumerate() {
        for &i in tet {
            a_tet_of[i as usize] = t as u32;
        }
    }
    for (v, &point) in x.iter().enumerate() {
        holding(point, u32::MAX, v as u32, &mut found);
        pairs.extend(found.iter().map(|&u| [a_tet_of[v], u]));
    }
    for pair in &mut pairs {
        pair.sort_unstable();
    }
    pairs.sort_unstable();
    pairs.dedup();
    // A folded pair overlaps too; it is reported once, as folded.
    let mut folded: Vec<[u32; 2]> = defects.folded.clone();
    for pair in &mut folded {
        pair.sort_unstable();
    }
    pairs.retain(|p| !folded.contains(p) && !shares_face(tets[p[0] as usize], tets[p[1] as usize]));
    defects.overlapping_count = pairs.len();
    pairs.truncate(LISTED_DEFECTS);
    defects.overlapping = pairs;
    defects
}

/// Whether two tets share three vertices.
fn shares_face(a: [u32; 4], b: [u32; 4]) -> bool {
    a.iter().filter(|v| b.contains(v)).count() >= 3
}

/// Whether `point` lies inside the tet `p` by more than [`INSIDE`] in each barycentric
/// coordinate.
fn strictly_inside(point: Vec3, p: [Vec3; 4]) -> bool {
    let volume = signed_volume(&p);
    if volume == 0.0 {
        return false;
    }
    (0..4).all(|k| {
        let mut q = p;
        q[k] = point;
        signed_volume(&q) / volume > INSIDE
    })
}
