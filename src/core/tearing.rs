//! Tearing: a body whose material is stretched past its limit cracks along the faces of its
//! tets and comes apart, as game fracture does it on element boundaries (Parker and O'Brien,
//! "Real-time deformation and fracture in a game environment", 2009). In a step whose most
//! stretched edge passes [`TearSettings::max_strain`], the crack starts at the tet of that
//! edge: the faces between tets on either side of the plane through it across the edge, from
//! that tet outward over the tets the plane crosses, are cracked (at most
//! [`TearSettings::max_faces_per_step`] a step, so a crack runs through a body over a few
//! steps, following where the stretch gathers). A particle whose tets the cracked faces part
//! into several sets is split, one copy for each set: the cracked faces become surface. The
//! mesh's one-rings, blocks, colours and the passes' data are then built anew for the body,
//! which stays one body however many pieces it has (see `SoftBodyTorn`). A step that tears
//! nothing allocates nothing.
//!
//! Tet indices do not change in a tear, only which particles their corners are: anything bound
//! to tets (the embedded render surface, forces at points) follows the pieces.

use glam::Vec3;

use super::tet_mesh::{TetMesh, TetMeshError};

/// When a body tears.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub struct TearSettings {
    /// The strain `l / l0 - 1` of an edge past which the material cracks (1: twice as long
    /// as at rest). Squashing stretches edges across the squash: a limit much under 1 cracks
    /// a soft body where it lands.
    pub max_strain: f32,
    /// The most faces cracked in one step: a crack runs through a body over a few steps
    /// rather than shattering it in one.
    pub max_faces_per_step: u32,
    /// How long, s, a body that has just come apart waits before it starts another crack. A
    /// tear unloads the rest of the body only as fast as its snap-back travels through it;
    /// a body stretched past its limit everywhere at once would otherwise break in several
    /// places in successive steps. Cracks already started run on meanwhile.
    pub min_interval: f32,
}

impl Default for TearSettings {
    /// Tears past twice its rest length, 64 faces a step at most, a tenth of a second between
    /// cracks.
    fn default() -> Self {
        TearSettings {
            max_strain: 1.0,
            max_faces_per_step: 64,
            min_interval: 0.1,
        }
    }
}

/// Where a body tore: particle `particle` was split, some of its tets taking its new copy
/// `new_particle`; the crack ran across `normal` (the stretched edge's direction) there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tear {
    /// The particle split.
    pub particle: u32,
    /// Its new copy.
    pub new_particle: u32,
    /// Where, world frame.
    pub point: Vec3,
    /// The crack's normal (the stretched edge's direction).
    pub normal: Vec3,
}

/// A body's mesh after tears: the new mesh, for each of its particles the particle it came
/// from, and the tears.
pub(crate) struct TornMesh {
    pub(crate) mesh: TetMesh,
    pub(crate) origin: Vec<u32>,
    pub(crate) tears: Vec<Tear>,
}

/// The most stretched edge's strain in `mesh` at `positions` (`rest` the edges' rest lengths):
/// the test a step makes, without allocating, before it tears anything.
pub(crate) fn largest_strain(mesh: &TetMesh, positions: &[Vec3], rest: &[f32]) -> f32 {
    let strain = |(&[i, j], &l0): (&[u32; 2], &f32)| {
        positions[i as usize].distance(positions[j as usize]) / l0 - 1.0
    };
    mesh.edges()
        .iter()
        .zip(rest)
        .map(strain)
        .fold(f32::NEG_INFINITY, f32::max)
}

/// The centre of the tet of corners `tet` among `positions`.
fn tet_centre(tet: [u32; 4], positions: &[Vec3]) -> Vec3 {
    tet.iter().map(|&k| positions[k as usize]).sum::<Vec3>() / 4.0
}

/// The mesh after this step's cracks at `positions` (`rest` the edges' rest lengths), given
/// the faces cracked before (`cracks`, pairs of face-neighbouring tets, added to), or `None`
/// if no particle splits. Without `new_crack` only a crack already started runs on: the seed
/// must be a tet with a cracked face.
pub(crate) fn tear_mesh(
    mesh: &TetMesh,
    positions: &[Vec3],
    rest: &[f32],
    cracks: &mut Vec<[u32; 2]>,
    settings: TearSettings,
    new_crack: bool,
) -> Result<Option<TornMesh>, TetMeshError> {
    let tets = mesh.tets();
    let centre = |t: u32| tet_centre(tets[t as usize], positions);
    // The crack's seed: the most stretched edge, its tet, and the plane across it.
    let strain = |e: usize| {
        let [i, j] = mesh.edges()[e];
        positions[i as usize].distance(positions[j as usize]) / rest[e] - 1.0
    };
    let worst = (0..rest.len()).max_by(|&a, &b| strain(a).total_cmp(&strain(b)));
    let Some(worst) = worst.filter(|&e| strain(e) > settings.max_strain) else {
        return Ok(None);
    };
    let [i, j] = mesh.edges()[worst];
    let normal = (positions[j as usize] - positions[i as usize]).normalize_or_zero();
    let Some(&seed) = mesh
        .one_ring(i as usize)
        .iter()
        .find(|&&t| tets[t as usize].contains(&j))
    else {
        return Ok(None);
    };
    let cracked = |t: u32| cracks.iter().any(|p| p.contains(&t));
    if !new_crack && !cracked(seed) {
        return Ok(None);
    }
    let origin = centre(seed);
    let side = |t: u32| (centre(t) - origin).dot(normal) > 0.0;
    let crossed = |t: u32| {
        let d = tets[t as usize].map(|k| (positions[k as usize] - origin).dot(normal));
        d.iter().any(|&d| d > 0.0) && d.iter().any(|&d| d <= 0.0)
    };
    // Outward from the seed over the tets the plane crosses, cracking the faces between the
    // two sides.
    let mut visited = vec![false; tets.len()];
    let mut queue = std::collections::VecDeque::from([seed]);
    visited[seed as usize] = true;
    let mut added = 0;
    while let Some(t) = queue.pop_front() {
        for &n in face_neighbours(mesh, t).iter() {
            if side(t) != side(n) {
                let pair = [t.min(n), t.max(n)];
                if !cracks.contains(&pair) && added < settings.max_faces_per_step {
                    cracks.push(pair);
                    added += 1;
                }
            }
            if !visited[n as usize] && crossed(n) {
                visited[n as usize] = true;
                queue.push_back(n);
            }
        }
    }
    split_particles(mesh, positions, cracks, normal)
}

/// Cracks the faces between tets whose centres `crosses` separates (a blade between them),
/// adding them to `cracks`; the direction across the last one, if any was added.
pub(crate) fn crack_crossed(
    mesh: &TetMesh,
    positions: &[Vec3],
    cracks: &mut Vec<[u32; 2]>,
    crosses: &dyn Fn(Vec3, Vec3) -> bool,
) -> Option<Vec3> {
    let tets = mesh.tets();
    let centre = |t: u32| tet_centre(tets[t as usize], positions);
    let mut normal = None;
    for t in 0..tets.len() as u32 {
        for n in face_neighbours(mesh, t).into_iter().filter(|&n| n > t) {
            let (a, b) = (centre(t), centre(n));
            if crosses(a, b) && !cracks.contains(&[t, n]) {
                cracks.push([t, n]);
                normal = Some((b - a).normalize_or_zero());
            }
        }
    }
    normal
}

/// The tets sharing a face with tet `t`.
fn face_neighbours(mesh: &TetMesh, t: u32) -> Vec<u32> {
    let tet = mesh.tets()[t as usize];
    mesh.tet_neighbours(t as usize)
        .iter()
        .copied()
        .filter(|&n| {
            mesh.tets()[n as usize]
                .iter()
                .filter(|k| tet.contains(k))
                .count()
                == 3
        })
        .collect()
}

/// Splits every particle whose tets the cracked faces part: its tets joined through faces not
/// cracked form sets, and each set but the first takes a new copy of it.
pub(crate) fn split_particles(
    mesh: &TetMesh,
    positions: &[Vec3],
    cracks: &mut Vec<[u32; 2]>,
    normal: Vec3,
) -> Result<Option<TornMesh>, TetMeshError> {
    let mut tets = mesh.tets().to_vec();
    let mut rest_positions = mesh.positions().to_vec();
    let mut origin: Vec<u32> = (0..positions.len() as u32).collect();
    let mut tears = Vec::new();
    let mut touched: Vec<u32> = cracks
        .iter()
        .flat_map(|&[a, b]| {
            let tb = mesh.tets()[b as usize];
            mesh.tets()[a as usize]
                .into_iter()
                .filter(move |k| tb.contains(k))
        })
        .collect();
    touched.sort_unstable();
    touched.dedup();
    for v in touched {
        let ring = mesh.one_ring(v as usize);
        // Sets of the ring's tets joined through faces (with `v`) not cracked.
        let mut set: Vec<u32> = vec![u32::MAX; ring.len()];
        let mut sets = 0;
        for start in 0..ring.len() {
            if set[start] != u32::MAX {
                continue;
            }
            set[start] = sets;
            let mut stack = vec![start];
            while let Some(a) = stack.pop() {
                for b in 0..ring.len() {
                    let (ta, tb) = (ring[a], ring[b]);
                    let shared = mesh.tets()[ta as usize]
                        .iter()
                        .filter(|k| mesh.tets()[tb as usize].contains(k))
                        .count();
                    let pair = [ta.min(tb), ta.max(tb)];
                    if set[b] == u32::MAX && shared == 3 && !cracks.contains(&pair) {
                        set[b] = sets;
                        stack.push(b);
                    }
                }
            }
            sets += 1;
        }
        for copy_set in 1..sets {
            let copy = rest_positions.len() as u32;
            for (k, &t) in ring.iter().enumerate().filter(|&(k, _)| set[k] == copy_set) {
                let _ = k;
                for corner in tets[t as usize].iter_mut().filter(|c| **c == v) {
                    *corner = copy;
                }
            }
            rest_positions.push(rest_positions[v as usize]);
            origin.push(v);
            tears.push(Tear {
                particle: v,
                new_particle: copy,
                point: positions[v as usize],
                normal,
            });
        }
    }
    // Faces now apart are no longer cracks to keep.
    cracks.retain(|&[a, b]| {
        let tb = tets[b as usize];
        tets[a as usize].iter().filter(|k| tb.contains(k)).count() == 3
    });
    if tears.is_empty() {
        return Ok(None);
    }
    let mesh = TetMesh::new(rest_positions, tets)?;
    Ok(Some(TornMesh {
        mesh,
        origin,
        tears,
    }))
}

/// The pieces of `mesh`: for each tet, the index of the set of tets joined to it through
/// shared particles (its connected component), numbered from 0 in tet order.
pub fn pieces(mesh: &TetMesh) -> Vec<u32> {
    let n = mesh.vertex_count();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn find(parent: &mut [u32], mut i: u32) -> u32 {
        while parent[i as usize] != i {
            parent[i as usize] = parent[parent[i as usize] as usize];
            i = parent[i as usize];
        }
        i
    }
    for tet in mesh.tets() {
        for &k in &tet[1..] {
            let (a, b) = (find(&mut parent, tet[0]), find(&mut parent, k));
            parent[b as usize] = a;
        }
    }
    let mut label = vec![u32::MAX; n];
    let mut next = 0;
    mesh.tets()
        .iter()
        .map(|tet| {
            let root = find(&mut parent, tet[0]) as usize;
            if label[root] == u32::MAX {
                label[root] = next;
                next += 1;
            }
            label[root]
        })
        .collect()
}

/// The faces a tear opened: faces of tets that are surface in `now` (the torn mesh) and were
/// not in `bound` (the same tets before), each as its tet and the tet's three corners (0 to 3)
/// in outward order.
pub fn cut_faces(bound: &TetMesh, now: &TetMesh) -> Vec<(u32, [usize; 3])> {
    let surface = |mesh: &TetMesh| {
        let mut count: std::collections::HashMap<[u32; 3], u32> = Default::default();
        for tet in mesh.tets() {
            for k in 0..4 {
                *count.entry(face_key(tet, k)).or_insert(0) += 1;
            }
        }
        count
    };
    let (before, after) = (surface(bound), surface(now));
    let mut faces = Vec::new();
    for (t, (old, new)) in bound.tets().iter().zip(now.tets()).enumerate() {
        for k in 0..4 {
            if after[&face_key(new, k)] == 1 && before[&face_key(old, k)] != 1 {
                let corners = [(k + 1) % 4, (k + 2) % 4, (k + 3) % 4];
                // Outward: away from the corner not on the face (in the rest shape).
                let x = new.map(|i| now.positions()[i as usize]);
                let [a, b, c] = corners.map(|j| x[j]);
                let away = (a + b + c) / 3.0 - x[k];
                let outward = (b - a).cross(c - a).dot(away) >= 0.0;
                let corners = if outward {
                    corners
                } else {
                    [corners[0], corners[2], corners[1]]
                };
                faces.push((t as u32, corners));
            }
        }
    }
    faces
}

/// Face `k` of `tet` (the one without corner `k`), its particles sorted.
fn face_key(tet: &[u32; 4], k: usize) -> [u32; 3] {
    let mut key = [tet[(k + 1) % 4], tet[(k + 2) % 4], tet[(k + 3) % 4]];
    key.sort_unstable();
    key
}
