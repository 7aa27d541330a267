//! A soft body's boundary as other soft bodies meet it (`soft_contacts.rs`): its outward
//! triangles and the particles on them, a uniform grid that hashes the triangles for a contact
//! pass, how the body meets others, and what a contact pass asks of the triangles (the nearest
//! one to a particle, how far the particle is past it).

use glam::{IVec3, Vec3};
use parry3d::bounding_volume::Aabb;

use super::tet_mesh::TetMesh;

/// How a body meets other soft bodies.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SoftContactSettings {
    /// The gap kept between a particle and another body's surface, in metres; the pair uses
    /// the larger of the two bodies'.
    pub thickness: f32,
    /// Whether the body also meets itself (a long body that folds, a tail that touches).
    pub self_contacts: bool,
}

impl SoftContactSettings {
    /// The default for a mesh whose shortest rest edge is `shortest_edge`: a tenth of it, and
    /// no self contacts.
    pub fn for_edge(shortest_edge: f32) -> Self {
        SoftContactSettings {
            thickness: 0.1 * shortest_edge,
            self_contacts: false,
        }
    }
}

/// A body's boundary: its outward triangles, the particles on them, and a grid of the
/// triangles rebuilt in each pass. Built once from the mesh.
#[derive(Clone, Debug, Default)]
pub struct Boundary {
    /// Outward boundary triangles (particle indices).
    pub(crate) triangles: Vec<[u32; 3]>,
    /// The particles on the boundary, in index order.
    pub(crate) particles: Vec<u32>,
    /// The longest boundary edge at rest: the grid's cell size, and how far two boundary
    /// particles must be apart at rest to meet in a self contact.
    pub(crate) longest_edge: f32,
    /// The triangles hashed by cell for the current pass.
    pub(crate) grid: TriangleGrid,
    /// The bounds of the boundary particles over the current pass (`None`: the body takes no
    /// part in it).
    pub(crate) reach: Option<Aabb>,
    /// This body's particles that may meet another body's triangles within the step, found
    /// once a step for its substeps' contact passes (`soft_broad_phase.rs`).
    pub(crate) candidates: SoftCandidates,
    /// Where the boundary particles were when the candidates were found, and how far they hold.
    pub(crate) paths: CandidatePaths,
}

impl Boundary {
    /// The boundary of `mesh`.
    pub fn of(mesh: &TetMesh) -> Self {
        let indices = mesh.boundary_surface().indices;
        let triangles: Vec<[u32; 3]> = indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect();
        let mut on = vec![false; mesh.vertex_count()];
        let mut longest_edge = 0.0f32;
        for t in &triangles {
            for k in 0..3 {
                on[t[k] as usize] = true;
                let (a, b) = (t[k] as usize, t[(k + 1) % 3] as usize);
                longest_edge = longest_edge.max(mesh.positions()[a].distance(mesh.positions()[b]));
            }
        }
        let particles: Vec<u32> = (0..on.len() as u32).filter(|&i| on[i as usize]).collect();
        let grid = TriangleGrid::with_capacity(triangles.len());
        Boundary {
            triangles,
            particles,
            longest_edge,
            grid,
            reach: None,
            candidates: SoftCandidates::default(),
            paths: CandidatePaths::default(),
        }
    }

    /// The boundary triangles, as indices of the body's particles.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }
}

/// Triangles hashed into the cells of a uniform grid they overlap, counting-sorted by bucket.
#[derive(Clone, Debug, Default)]
pub struct TriangleGrid {
    cell: f32,
    /// Bucket count minus one (a power of two minus one).
    mask: u32,
    /// For each bucket, where its triangles start in `items` (`mask + 2` entries).
    starts: Vec<u32>,
    /// Triangle indices by bucket.
    items: Vec<u32>,
    /// Scratch: (bucket, triangle) pairs before sorting.
    pairs: Vec<(u32, u32)>,
    /// Each triangle's bounds as hashed.
    bounds: Vec<Aabb>,
}

impl TriangleGrid {
    fn with_capacity(triangles: usize) -> Self {
        TriangleGrid {
            cell: 1.0,
            mask: 0,
            starts: Vec::with_capacity(16 * triangles + 1),
            items: Vec::with_capacity(8 * triangles),
            pairs: Vec::with_capacity(8 * triangles),
            bounds: Vec::with_capacity(triangles),
        }
    }

    #[inline]
    fn cell_of(&self, p: Vec3) -> IVec3 {
        (p / self.cell).floor().as_ivec3()
    }

    #[inline]
    fn hash(c: IVec3) -> u32 {
        (c.x as u32).wrapping_mul(73_856_093)
            ^ (c.y as u32).wrapping_mul(19_349_663)
            ^ (c.z as u32).wrapping_mul(83_492_791)
    }

    #[inline]
    fn bucket(&self, c: IVec3) -> u32 {
        Self::hash(c) & self.mask
    }

    /// Hashes `bounds[t]` of every triangle `t` into cells of size `cell`.
    pub(crate) fn build(&mut self, cell: f32, bounds: impl Iterator<Item = Aabb>) {
        self.cell = cell.max(1e-6);
        self.pairs.clear();
        self.bounds.clear();
        self.bounds.extend(bounds);
        let cell = self.cell;
        let cell_of = |p: Vec3| (p / cell).floor().as_ivec3();
        for (t, b) in self.bounds.iter().enumerate() {
            let (lo, hi) = (cell_of(b.mins), cell_of(b.maxs));
            for x in lo.x..=hi.x {
                for y in lo.y..=hi.y {
                    for z in lo.z..=hi.z {
                        self.pairs.push((Self::hash(IVec3::new(x, y, z)), t as u32));
                    }
                }
            }
        }
        // Twice as many buckets as entries, so that few cells share one.
        let buckets = (2 * self.pairs.len()).next_power_of_two().max(16);
        self.mask = buckets as u32 - 1;
        self.starts.clear();
        self.starts.resize(buckets + 1, 0);
        for &(hash, _) in &self.pairs {
            self.starts[(hash & self.mask) as usize + 1] += 1;
        }
        for k in 1..self.starts.len() {
            self.starts[k] += self.starts[k - 1];
        }
        self.items.clear();
        self.items.resize(self.pairs.len(), 0);
        // Place each pair at its bucket's next free slot (`starts` is shifted back after).
        for &(hash, t) in &self.pairs {
            let slot = &mut self.starts[(hash & self.mask) as usize];
            self.items[*slot as usize] = t;
            *slot += 1;
        }
        for k in (1..self.starts.len()).rev() {
            self.starts[k] = self.starts[k - 1];
        }
        self.starts[0] = 0;
    }

    /// Triangle `t`'s bounds as hashed.
    pub(crate) fn bounds(&self, t: u32) -> &Aabb {
        &self.bounds[t as usize]
    }

    /// Calls `visit` with the triangles hashed into the cells `bounds` overlaps (a triangle may
    /// come more than once, and hash collisions bring triangles from elsewhere: the narrow phase
    /// decides).
    pub(crate) fn for_each_near(&self, bounds: &Aabb, mut visit: impl FnMut(u32)) {
        if self.items.is_empty() {
            return;
        }
        let (lo, hi) = (self.cell_of(bounds.mins), self.cell_of(bounds.maxs));
        for x in lo.x..=hi.x {
            for y in lo.y..=hi.y {
                for z in lo.z..=hi.z {
                    let bucket = self.bucket(IVec3::new(x, y, z)) as usize;
                    let (from, to) = (self.starts[bucket], self.starts[bucket + 1]);
                    for &t in &self.items[from as usize..to as usize] {
                        visit(t);
                    }
                }
            }
        }
    }
}

/// One body's candidates against one other body (or itself): a run of [`SoftCandidates`]'s
/// particles.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CandidateList {
    /// The slot of the body whose triangles the particles may meet.
    pub(crate) partner: u32,
    /// The list's particles, a range of [`SoftCandidates::particles`].
    pub(crate) start: u32,
    pub(crate) end: u32,
}

/// A particle that may meet another body's triangles within the step, and which: a range of
/// [`SoftCandidates`]'s triangles.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CandidateParticle {
    pub(crate) particle: u32,
    pub(crate) start: u32,
    pub(crate) end: u32,
}

/// The particles of a body that may meet other bodies' triangles within a step, each with the
/// triangles it may meet, listed by partner: found once a step from where the particles and
/// the triangles move in it (`soft_broad_phase.rs`), so that a substep's contact pass looks
/// only at these, without a grid. Reused from step to step.
#[derive(Clone, Debug, Default)]
pub(crate) struct SoftCandidates {
    pub(crate) lists: Vec<CandidateList>,
    pub(crate) particles: Vec<CandidateParticle>,
    pub(crate) triangles: Vec<u32>,
    /// Per triangle of the body searched, the search (one a particle) that last met it: the
    /// grid brings a triangle once for each cell it overlaps, and each is tested once.
    seen: Vec<u32>,
    search: u32,
}

/// The triangles one particle's search lists (see [`SoftCandidates::push`]).
pub(crate) struct Listed<'a> {
    triangles: &'a mut Vec<u32>,
    seen: &'a mut [u32],
    search: u32,
}

impl Listed<'_> {
    /// Whether this search meets triangle `t` for the first time.
    #[inline]
    pub(crate) fn first_time(&mut self, t: u32) -> bool {
        let seen = &mut self.seen[t as usize];
        let first = *seen != self.search;
        *seen = self.search;
        first
    }

    /// Lists triangle `t`.
    #[inline]
    pub(crate) fn push(&mut self, t: u32) {
        self.triangles.push(t);
    }
}

/// Per particle (boundary particles only): where it was when the step's candidates were found,
/// and how far from there they hold for it (`soft_broad_phase.rs`).
#[derive(Clone, Debug, Default)]
pub(crate) struct CandidatePaths {
    pub(crate) start: Vec<Vec3>,
    pub(crate) radius: Vec<f32>,
}

impl SoftCandidates {
    /// Forgets the last step's candidates.
    pub(crate) fn clear(&mut self) {
        self.lists.clear();
        self.particles.clear();
        self.triangles.clear();
    }

    /// Starts the list of candidates against `partner`.
    pub(crate) fn begin(&mut self, partner: u32) {
        let at = self.particles.len() as u32;
        self.lists.push(CandidateList {
            partner,
            start: at,
            end: at,
        });
    }

    /// Adds `particle` to the current list with the triangles `near` lists, of a body of
    /// `triangles` triangles (each listed once: see [`Listed::first_time`]), in ascending
    /// order; a particle with none is left out.
    pub(crate) fn push(&mut self, particle: u32, triangles: usize, near: impl FnOnce(&mut Listed)) {
        if self.seen.len() < triangles {
            self.seen.resize(triangles, 0);
        }
        if self.search == u32::MAX {
            self.seen.fill(0);
            self.search = 0;
        }
        self.search += 1;
        let start = self.triangles.len();
        near(&mut Listed {
            triangles: &mut self.triangles,
            seen: &mut self.seen,
            search: self.search,
        });
        if self.triangles.len() == start {
            return;
        }
        self.triangles[start..].sort_unstable();
        self.particles.push(CandidateParticle {
            particle,
            start: start as u32,
            end: self.triangles.len() as u32,
        });
        if let Some(list) = self.lists.last_mut() {
            list.end = self.particles.len() as u32;
        }
    }

    /// The candidates against `partner` (empty if none).
    pub(crate) fn against(&self, partner: u32) -> &[CandidateParticle] {
        self.lists
            .iter()
            .find(|l| l.partner == partner)
            .map_or(&[], |l| &self.particles[l.start as usize..l.end as usize])
    }

    /// The triangles `particle` may meet.
    pub(crate) fn triangles_of(&self, particle: &CandidateParticle) -> &[u32] {
        &self.triangles[particle.start as usize..particle.end as usize]
    }
}

/// The signed distance of `xp` past the triangle `corners` (negative inside), the direction
/// that takes it out, and the barycentric weights of its nearest point; `None` for a
/// degenerate triangle. Over the triangle, the distance along its outward normal. Nearest to
/// one of its edges or corners, the particle is outside (infinitely far: another triangle
/// decides) unless it lies behind the triangle's plane: then it is inside a dent (a concave
/// edge or corner, as an impact leaves) or under the edge between two triangles of a flat
/// face, and comes out to that nearest point. Only with `dents` (the final pass): the
/// substeps, which ease a particle placed inside another body out at a bounded speed, let such
/// particles out faster than that.
pub(crate) fn surface_distance(
    xp: Vec3,
    corners: [Vec3; 3],
    dents: bool,
) -> Option<(f32, Vec3, Vec3)> {
    let [a, b, c] = corners;
    let n = (b - a).cross(c - a).try_normalize()?;
    let q = closest_barycentric(xp, a, b, c);
    let offset = xp - (a * q.x + b * q.y + c * q.z);
    let distance = offset.length();
    let over = (offset - n * offset.dot(n)).length_squared() <= 1e-12 * (1.0 + distance);
    if over {
        return Some((offset.dot(n), n, q));
    }
    if dents && offset.dot(n) < 0.0 {
        return Some((-distance, -offset / distance, q));
    }
    Some((f32::INFINITY, n, q))
}

/// Whether `x` is outside the plane of the triangle `corners` (or within `thickness` of it):
/// where a particle was before it moved decides whether a deep one came through the surface
/// or lies past the far side of a thin part.
pub(crate) fn outside_of(x: Vec3, corners: [Vec3; 3], thickness: f32) -> bool {
    let [a, b, c] = corners;
    (x - a).dot((b - a).cross(c - a).normalize_or_zero()) > -thickness
}

/// How squarely a triangle may face the static collider a particle rests on and still push
/// it out (the cosine of the angle between the triangle's outward normal and the collider's
/// inward one).
const FACING_COLLIDER: f32 = 0.5;

/// Whether the triangle `tri` (corners at `corner(j)`) faces into the static collider whose
/// outward normal is `resting_on` (zero: none): a particle on the ground can be past such a
/// triangle only when it is wedged inside the triangle's body from the side (two bodies
/// pressed together at their feet), and pushing it out through that triangle drives it into
/// the ground, which throws it back every substep: it must leave through another triangle
/// (in the passes that ease it out; the final pass leaves it, `soft_contacts.rs`).
pub(crate) fn faces_into(resting_on: Vec3, tri: [u32; 3], corner: impl Fn(usize) -> Vec3) -> bool {
    if resting_on == Vec3::ZERO {
        return false;
    }
    let [a, b, c] = tri.map(|j| corner(j as usize));
    (b - a).cross(c - a).normalize_or_zero().dot(resting_on) < -FACING_COLLIDER
}

/// The triangle of `triangles` (corners at `corner(j)`) that `near` lists and is nearest
/// `xp`, skipping those `skip` rejects.
pub(crate) fn nearest_triangle(
    xp: Vec3,
    near: impl FnOnce(&mut dyn FnMut(u32)),
    triangles: &[[u32; 3]],
    corner: impl Fn(usize) -> Vec3,
    mut skip: impl FnMut([u32; 3]) -> bool,
) -> Option<[usize; 3]> {
    // Nearest first; among triangles as near (sharing the nearest edge or corner), the one
    // the particle lies most squarely over, so that a particle over the top face next to its
    // edge is met by the top face, not by the side face below the same edge, whichever the
    // grid lists first.
    // How squarely `xp` lies over the triangle with corners `end` whose closest point is at
    // `offset` from it: computed only where two triangles are as near.
    let squarely = |end: &[Vec3; 3], offset: Vec3| {
        let normal = (end[1] - end[0]).cross(end[2] - end[0]).normalize_or_zero();
        offset.normalize_or_zero().dot(normal).abs()
    };
    let mut nearest: Option<([usize; 3], [Vec3; 3], Vec3, f32)> = None;
    near(&mut |k| {
        let tri = triangles[k as usize];
        if skip(tri) {
            return;
        }
        let corners = tri.map(|j| j as usize);
        let end = corners.map(&corner);
        // Bounds further than the nearest so far (past the tie margin): neither nearer nor tied.
        if nearest.is_some_and(|(.., best)| bounds_beyond(xp, &end, best)) {
            return;
        }
        let q = closest_barycentric(xp, end[0], end[1], end[2]);
        let offset = xp - (end[0] * q.x + end[1] * q.y + end[2] * q.z);
        let distance = offset.length_squared();
        let better = nearest.is_none_or(|(_, best_end, best_offset, best)| {
            let tie = 1e-6 * best.max(distance) + 1e-14;
            distance < best - tie
                || (distance <= best + tie
                    && squarely(&end, offset) > squarely(&best_end, best_offset))
        });
        if better {
            nearest = Some((corners, end, offset, distance));
        }
    });
    nearest.map(|(corners, ..)| corners)
}

/// Whether the bounds of the triangle with corners `end` are further from `x` than `best`
/// (a squared distance) by more than a nearest-triangle search's tie margin: then no point of
/// it is nearer, nor as near.
#[inline]
pub(crate) fn bounds_beyond(x: Vec3, end: &[Vec3; 3], best: f32) -> bool {
    let (lo, hi) = (
        end[0].min(end[1]).min(end[2]),
        end[0].max(end[1]).max(end[2]),
    );
    let outside = (lo - x).max(x - hi).max(Vec3::ZERO).length_squared();
    outside * (1.0 - 1e-5) > best + 1e-14
}

/// The point of triangle `abc` closest to `p`, as barycentric weights (Ericson, "Real-Time
/// Collision Detection", 5.1.5).
pub(crate) fn closest_barycentric(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return Vec3::X;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return Vec3::Y;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return Vec3::new(1.0 - v, v, 0.0);
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return Vec3::Z;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return Vec3::new(1.0 - w, 0.0, w);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return Vec3::new(0.0, 1.0 - w, w);
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    Vec3::new(1.0 - v - w, v, w)
}
