//! Where soft bodies may meet each other: each body's boundary triangles hashed into a uniform
//! grid for one contact pass ([`prepare_soft_contacts`]), and, once a step, the particles
//! that may meet another body's triangles within the step with the triangles they may meet
//! ([`gather_soft_candidates`]), which every substep's contact pass then reads instead of a
//! grid of its own, as does the step's predicted pass where they cover the whole step.
//!
//! The grid has cells of about a triangle's size, and a particle looks only in the cells its
//! motion covers, so the cost grows with the boundary particles in the overlap of two bodies'
//! bounds, not with their product. A step's candidates are found within a radius of each
//! boundary particle (its motion over the step and a share of the longest boundary edge for
//! what the substeps add to it, [`gather_soft_candidates`]); while the particles stay within
//! their radii they miss nothing, and a particle past its radius has them found again.
//! Self contacts skip the triangles within two rest edges of the particle at rest: those are
//! its neighbours on the same surface, not a fold.

use std::ops::DerefMut;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicUsize, Ordering};

use glam::Vec3;
use parry3d::bounding_volume::{Aabb, BoundingVolume};

use super::body::SoftBodyState;
use super::boundary::closest_barycentric;
use super::parallel::{Parallel, SharedSlice, for_each_mut, wait_for};

/// How far a step's candidates reach past the straight paths, in the body's longest boundary
/// edges (on top of the contact gap).
const STEP_SLACK: f32 = 0.1;

/// The longest path a particle's candidates cover, in its body's longest boundary edges: a
/// particle that moves further (in a fast impact) has them found again within the step.
const MAX_PATH: f32 = 0.25;

/// The bounds of where `body`'s boundary particles are now and `ahead` seconds on.
pub(crate) fn boundary_bounds(body: &SoftBodyState, ahead: f32) -> Option<Aabb> {
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for &i in &body.boundary.particles {
        let (x, v) = (body.positions[i as usize], body.velocities[i as usize]);
        let end = x + ahead * v;
        lo = lo.min(x).min(end);
        hi = hi.max(x).max(end);
    }
    (lo.is_finite() && hi.is_finite()).then(|| Aabb::new(lo, hi))
}

/// Hashes the boundary triangles where they are and `ahead` seconds on, grown by `margin`,
/// for this pass. Returns the bounds of the boundary particles (`None`: the body takes no
/// part in soft contacts).
pub(crate) fn prepare_soft_contacts(
    body: &mut SoftBodyState,
    ahead: f32,
    margin: f32,
) -> Option<Aabb> {
    body.boundary.reach = None;
    body.soft_contacts?;
    let reach = boundary_bounds(body, ahead)?;
    let (positions, velocities) = (&body.positions, &body.velocities);
    let bounds = body.boundary.triangles.iter().map(|t| {
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for &i in t {
            let (x, v) = (positions[i as usize], velocities[i as usize]);
            lo = lo.min(x).min(x + ahead * v);
            hi = hi.max(x).max(x + ahead * v);
        }
        Aabb::new(lo, hi).loosened(margin)
    });
    let cell = body.boundary.longest_edge;
    body.boundary.grid.build(cell, bounds);
    body.boundary.reach = Some(reach);
    Some(reach)
}

/// Finds, for the `h` seconds ahead, each body's boundary particles that may meet another
/// body's triangles (or, for a body that meets itself, its own) and the triangles they may
/// meet, into each body's [`SoftCandidates`], listed by the partner's slot in `bodies`. Two
/// sleeping bodies, and bodies whose filters keep them apart, get no list.
///
/// Each boundary particle gets a radius: how far it moves in `h` at its velocity (at most
/// [`MAX_PATH`] boundary edges), and [`STEP_SLACK`] of its body's longest boundary edge. A triangle is listed for a particle if
/// it lies within the particle's radius, the largest of its corners' and the pair's contact gap
/// of it: while every particle stays within its radius of where it was
/// ([`candidates_hold`]), no triangle left out can come within the gap of it.
pub(crate) fn gather_soft_candidates<B: DerefMut<Target = SoftBodyState> + Send>(
    bodies: &mut [B],
    h: f32,
    rounds: &mut PairRounds,
    parallel: &dyn Parallel,
) {
    for_each_mut(bodies, parallel, &|body| start_paths(body, h));
    rounds.plan(bodies, |one, other, _| {
        overlap(one, other).is_some()
            && !(one.is_sleeping() && other.is_sleeping())
            && one.collision_filter.interacts_with(other.collision_filter)
    });
    rounds.run(bodies, parallel, &|one, other, [a, b]| {
        match other {
            None => gather_self(one, a),
            Some(other) => {
                if let Some(region) = overlap(one, other) {
                    gather_pair(one, other, &region, b);
                    gather_pair(other, one, &region, a);
                }
            }
        }
        0
    });
}

/// Where the prepared bounds (`Boundary::reach`) of two bodies overlap, if they do.
pub(crate) fn overlap(one: &SoftBodyState, other: &SoftBodyState) -> Option<Aabb> {
    let (ra, rb) = (one.boundary.reach?, other.boundary.reach?);
    ra.intersects(&rb)
        .then(|| Aabb::new(ra.mins.max(rb.mins), ra.maxs.min(rb.maxs)))
}

/// Whether every boundary particle of `body` moves at most [`MAX_PATH`] boundary edges in `h`
/// at its velocity: candidates found now then cover its whole motion over the step (no path
/// is cut short), as the step's predicted pass needs to read them.
pub(crate) fn paths_fit_the_step(body: &SoftBodyState, h: f32) -> bool {
    let fastest = MAX_PATH * body.boundary.longest_edge / h;
    body.soft_contacts.is_none()
        || body
            .boundary
            .particles
            .iter()
            .all(|&i| body.velocities[i as usize].length_squared() <= fastest * fastest)
}

/// Whether `body`'s candidates still hold: every boundary particle within its radius of where
/// it was when they were found (a body without soft contacts has none to hold).
pub(crate) fn candidates_hold(body: &SoftBodyState) -> bool {
    let c = &body.boundary.paths;
    body.soft_contacts.is_none()
        || body.boundary.particles.iter().all(|&i| {
            let i = i as usize;
            (body.positions[i] - c.start[i]).length_squared() <= c.radius[i] * c.radius[i]
        })
}

/// Forgets `body`'s candidates, gives its boundary particles their radii for `h` seconds
/// ahead, and hashes its triangles grown by their corners' largest radius. The body's reach
/// becomes its boundary's bounds grown by its largest radius.
fn start_paths(body: &mut SoftBodyState, h: f32) {
    let n = body.positions.len();
    let edge = body.boundary.longest_edge;
    let slack = STEP_SLACK * edge;
    let boundary = &mut body.boundary;
    boundary.reach = None;
    boundary.candidates.clear();
    let c = &mut boundary.paths;
    c.start.resize(n, Vec3::ZERO);
    c.radius.resize(n, 0.0);
    if body.soft_contacts.is_none() {
        return;
    }
    let (mut lo, mut hi, mut largest) = (Vec3::INFINITY, Vec3::NEG_INFINITY, 0.0f32);
    for &i in &boundary.particles {
        let i = i as usize;
        let x = body.positions[i];
        c.start[i] = x;
        c.radius[i] = (h * body.velocities[i].length()).min(MAX_PATH * edge) + slack;
        (lo, hi, largest) = (lo.min(x), hi.max(x), largest.max(c.radius[i]));
    }
    if !(lo.is_finite() && hi.is_finite() && largest.is_finite()) {
        return;
    }
    let (x, c) = (&body.positions, &boundary.paths);
    let bounds = boundary.triangles.iter().map(|t| {
        let [a, b, d] = t.map(|i| x[i as usize]);
        let grown = widest(*t, &c.radius);
        Aabb::new(a.min(b).min(d), a.max(b).max(d)).loosened(grown)
    });
    boundary.grid.build(boundary.longest_edge, bounds);
    boundary.reach = Some(Aabb::new(lo, hi).loosened(largest));
}

/// The pair's contact gap.
fn gap(one: &SoftBodyState, other: &SoftBodyState) -> f32 {
    let thickness = |b: &SoftBodyState| b.soft_contacts.map_or(0.0, |s| s.thickness);
    thickness(one).max(thickness(other))
}

/// `body`'s particles inside `region` that may meet `other`'s triangles (in slot `partner`).
fn gather_pair(body: &mut SoftBodyState, other: &SoftBodyState, region: &Aabb, partner: u32) {
    let gap = gap(body, other);
    let (x, grid, triangles) = (
        &other.positions,
        &other.boundary.grid,
        &other.boundary.triangles,
    );
    let radius = &other.boundary.paths.radius;
    let (out, paths) = (&mut body.boundary.candidates, &body.boundary.paths);
    out.begin(partner);
    for &i in &body.boundary.particles {
        let (at, reach) = (paths.start[i as usize], paths.radius[i as usize] + gap);
        let near = Aabb::new(at, at).loosened(reach);
        if !near.intersects(region) {
            continue;
        }
        out.push(i, triangles.len(), |listed| {
            grid.for_each_near(&near, |t| {
                let tri = triangles[t as usize];
                if listed.first_time(t)
                    && grid.bounds(t).intersects(&near)
                    && within(at, tri, x, reach + widest(tri, radius))
                {
                    listed.push(t);
                }
            })
        });
    }
}

/// The largest radius of `tri`'s corners.
fn widest(tri: [u32; 3], radius: &[f32]) -> f32 {
    tri.map(|j| radius[j as usize])
        .into_iter()
        .fold(0.0, f32::max)
}

/// Whether the triangle `tri` (corners in `x`) lies within `distance` of `at`.
fn within(at: Vec3, tri: [u32; 3], x: &[Vec3], distance: f32) -> bool {
    let [a, b, c] = tri.map(|j| x[j as usize]);
    let q = closest_barycentric(at, a, b, c);
    (a * q.x + b * q.y + c * q.z).distance_squared(at) <= distance * distance
}

/// `body`'s particles that may meet its own triangles, if it meets itself (in slot `slot`).
fn gather_self(body: &mut SoftBodyState, slot: u32) {
    if !body.soft_contacts.is_some_and(|s| s.self_contacts) {
        return;
    }
    let gap = gap(body, body);
    let rest = body.mesh.positions();
    let x = &body.positions;
    let boundary = &mut body.boundary;
    let (grid, triangles, out) = (
        &boundary.grid,
        &boundary.triangles,
        &mut boundary.candidates,
    );
    let (edge, paths) = (boundary.longest_edge, &boundary.paths);
    out.begin(slot);
    for &i in &boundary.particles {
        let (at, reach) = (paths.start[i as usize], paths.radius[i as usize] + gap);
        let near = Aabb::new(at, at).loosened(reach);
        // The triangles near the particle at rest are its neighbours on the same surface.
        let neighbour = |tri: [u32; 3]| {
            if tri.contains(&i) {
                return true;
            }
            let [a, b, c] = tri.map(|j| rest[j as usize]);
            let r = rest[i as usize];
            let q = closest_barycentric(r, a, b, c);
            (a * q.x + b * q.y + c * q.z).distance(r) < 2.0 * edge
        };
        out.push(i, triangles.len(), |listed| {
            grid.for_each_near(&near, |t| {
                let tri = triangles[t as usize];
                if listed.first_time(t)
                    && grid.bounds(t).intersects(&near)
                    && !neighbour(tri)
                    && within(at, tri, x, reach + widest(tri, &paths.radius))
                {
                    listed.push(t);
                }
            })
        });
    }
}

/// What a pass does with a pair: `job(one, other, [a, b])`, `other` `None` for a body with
/// itself; returns the contacts it made.
pub(crate) type PairJob<'a> =
    dyn Fn(&mut SoftBodyState, Option<&mut SoftBodyState>, [u32; 2]) -> u32 + Sync + 'a;

/// The pairs a soft-contact pass resolves (a body with itself as `[a, a]`), sorted into
/// rounds of pairs that share no body: each pair, in the order pushed, goes in the first round
/// that holds neither of its bodies yet (a greedy edge colouring), so that a round's pairs run
/// at the same time, and the rounds, hence the result, do not depend on the thread count.
/// Kept between passes so that they allocate nothing once grown.
#[derive(Debug, Default)]
pub(crate) struct PairRounds {
    /// Per body: the first 64 rounds that hold it, as bits.
    used: Vec<u64>,
    /// Per body: the round after the last one holding it so far (past the first 64).
    next: Vec<u32>,
    /// How many rounds there are.
    rounds: u32,
    /// Each pair with its round, in the order pushed.
    listed: Vec<(u32, [u32; 2])>,
    /// The pairs by round, and where each round starts in them (and their end).
    pairs: Vec<[u32; 2]>,
    starts: Vec<u32>,
    /// Scratch: the next free place in each round while sorting.
    fill: Vec<u32>,
    /// Per pair (by round): the last earlier pairs holding its bodies (`u32::MAX`: none),
    /// and whether it is done; per body, its last pair so far.
    after: Vec<[u32; 2]>,
    done: Vec<AtomicBool>,
    last: Vec<u32>,
}

impl PairRounds {
    /// Plans a pass over `bodies`: each body that meets itself, and each pair `a < b` for
    /// which `meet(a's body, b's body, [a, b])` holds.
    pub(crate) fn plan<B: DerefMut<Target = SoftBodyState>>(
        &mut self,
        bodies: &[B],
        meet: impl Fn(&SoftBodyState, &SoftBodyState, [usize; 2]) -> bool,
    ) {
        self.clear(bodies.len());
        for a in 0..bodies.len() {
            if bodies[a].soft_contacts.is_some_and(|s| s.self_contacts) {
                self.push(a, a);
            }
            for b in a + 1..bodies.len() {
                if meet(&bodies[a], &bodies[b], [a, b]) {
                    self.push(a, b);
                }
            }
        }
    }

    /// Forgets the pairs, for a pass over `bodies` bodies.
    fn clear(&mut self, bodies: usize) {
        self.used.clear();
        self.used.resize(bodies, 0);
        self.next.clear();
        self.next.resize(bodies, 0);
        self.listed.clear();
        self.rounds = 0;
    }

    /// Adds the pair `a`, `b` (`a == b` for a body with itself).
    fn push(&mut self, a: usize, b: usize) {
        let free = (self.used[a] | self.used[b]).trailing_ones();
        let round = if free < 64 {
            self.used[a] |= 1 << free;
            self.used[b] |= 1 << free;
            free
        } else {
            self.next[a].max(self.next[b]).max(64)
        };
        self.next[a] = self.next[a].max(round + 1);
        self.next[b] = self.next[b].max(round + 1);
        self.listed.push((round, [a as u32, b as u32]));
        self.rounds = self.rounds.max(round + 1);
    }

    /// Runs `job` on every pair pushed, round after round, on the threads of `parallel`, a
    /// pair as soon as the earlier pairs holding its bodies are done: `job(one, other, [a, b])`
    /// with `other` `None` for a body with itself. Returns the sum of what the jobs return.
    pub(crate) fn run<B: DerefMut<Target = SoftBodyState> + Send>(
        &mut self,
        bodies: &mut [B],
        parallel: &dyn Parallel,
        job: &PairJob<'_>,
    ) -> u32 {
        let rounds = self.rounds as usize;
        self.starts.clear();
        self.starts.resize(rounds + 1, 0);
        for &(round, _) in &self.listed {
            self.starts[round as usize + 1] += 1;
        }
        for r in 1..self.starts.len() {
            self.starts[r] += self.starts[r - 1];
        }
        self.pairs.clear();
        self.pairs.resize(self.listed.len(), [0; 2]);
        self.fill.clear();
        self.fill.extend_from_slice(&self.starts);
        for &(round, pair) in &self.listed {
            self.pairs[self.fill[round as usize] as usize] = pair;
            self.fill[round as usize] += 1;
        }
        // Each pair waits for the last earlier pair holding either of its bodies.
        let count = self.pairs.len();
        self.last.clear();
        self.last.resize(bodies.len(), u32::MAX);
        self.after.clear();
        for (k, &[a, b]) in self.pairs.iter().enumerate() {
            self.after
                .push([self.last[a as usize], self.last[b as usize]]);
            self.last[a as usize] = k as u32;
            self.last[b as usize] = k as u32;
        }
        if self.done.len() < count {
            self.done.resize_with(count, || AtomicBool::new(false));
        }
        for flag in &self.done[..count] {
            flag.store(false, Ordering::Relaxed);
        }
        let (pairs, after, done) = (&self.pairs, &self.after, &self.done);
        let (found, next) = (AtomicU32::new(0), AtomicUsize::new(0));
        // SAFETY: a pair runs only once every earlier pair holding either of its bodies is
        // done, so each job reaches its bodies alone.
        let shared = unsafe { SharedSlice::new(bodies) };
        // Threads take the pairs in order as they come free and only wait for pairs taken
        // before (as `run_phases` does), so any number of threads, one included, finishes.
        let worker = |_thread: usize| {
            loop {
                let k = next.fetch_add(1, Ordering::Relaxed);
                if k >= count {
                    return;
                }
                for &earlier in &after[k] {
                    if earlier != u32::MAX {
                        wait_for(&done[earlier as usize]);
                    }
                }
                let [a, b] = pairs[k];
                let one = unsafe { &mut **shared.get_mut(a as usize) };
                let other = (a != b).then(|| unsafe { &mut **shared.get_mut(b as usize) });
                found.fetch_add(job(one, other, [a, b]), Ordering::Relaxed);
                done[k].store(true, Ordering::Release);
            }
        };
        parallel.run(parallel.threads().clamp(1, count.max(1)), &worker);
        found.into_inner()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::material::SoftBodyMaterial;
    use glam::UVec3;

    /// A jelly cube of 0.3 m, 6 cells a side, its lowest corner at `corner`.
    fn jelly(corner: Vec3) -> SoftBodyState {
        let mesh =
            crate::core::box_grid(UVec3::splat(6), Vec3::splat(0.05), corner).expect("a grid");
        SoftBodyState::new(mesh.into(), SoftBodyMaterial::JELLY).expect("a jelly")
    }

    /// A repeatable pseudo-random vector in the unit ball, from `seed`.
    fn scatter(seed: u32) -> Vec3 {
        let mut s = seed.wrapping_mul(2_654_435_761) ^ 0x9e37_79b9;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            (s as f32 / u32::MAX as f32) * 2.0 - 1.0
        };
        let v = Vec3::new(next(), next(), next());
        v / v.length().max(1.0)
    }

    /// Two jellies moving into each other: after their candidates are found, every particle is
    /// moved anywhere within its radius, and every particle that then lies within the pair's
    /// gap of a triangle of the other body has that triangle among its candidates; a particle
    /// moved past its radius makes the candidates no longer hold.
    #[test]
    fn the_candidates_list_every_triangle_within_reach_while_they_hold() {
        let mut bodies = [jelly(Vec3::ZERO), jelly(Vec3::new(0.29, 0.02, 0.01))];
        for (k, v) in bodies[0].velocities.iter_mut().enumerate() {
            *v = Vec3::X * 1.5 + scatter(k as u32) * 0.5;
        }
        for (k, v) in bodies[1].velocities.iter_mut().enumerate() {
            *v = -Vec3::X * 1.5 + scatter(7_919 + k as u32) * 0.5;
        }
        let h = 1.0 / 60.0;
        let mut refs: Vec<&mut SoftBodyState> = bodies.iter_mut().collect();
        gather_soft_candidates(
            &mut refs,
            h,
            &mut PairRounds::default(),
            &crate::core::Serial,
        );
        let gap = gap(&bodies[0], &bodies[1]);
        for (b, body) in bodies.iter_mut().enumerate() {
            let paths = body.boundary.paths.clone();
            for (n, &i) in body.boundary.particles.iter().enumerate() {
                let i = i as usize;
                let out = scatter(31 * n as u32 + b as u32);
                body.positions[i] = paths.start[i] + out * (0.999 * paths.radius[i]);
            }
            assert!(candidates_hold(body));
        }
        let mut met = 0;
        for (a, b) in [(0, 1), (1, 0)] {
            let (one, other) = (&bodies[a], &bodies[b]);
            let listed = one.boundary.candidates.against(b as u32);
            for &i in &one.boundary.particles {
                let x = one.positions[i as usize];
                let entry = listed.iter().find(|p| p.particle == i);
                for (t, tri) in other.boundary.triangles.iter().enumerate() {
                    if within(x, *tri, &other.positions, gap) {
                        met += 1;
                        let found = entry.is_some_and(|e| {
                            one.boundary
                                .candidates
                                .triangles_of(e)
                                .contains(&(t as u32))
                        });
                        assert!(
                            found,
                            "body {a} particle {i} within the gap of triangle {t}, not listed"
                        );
                    }
                }
            }
        }
        assert!(
            met > 20,
            "only {met} particles came within the gap: the test moved too little"
        );
        let i = bodies[0].boundary.particles[0] as usize;
        let paths = bodies[0].boundary.paths.clone();
        bodies[0].positions[i] = paths.start[i] + Vec3::Y * (1.01 * paths.radius[i]);
        assert!(!candidates_hold(&bodies[0]));
    }
}
