//! Contacts between soft bodies, and of a body with itself: the boundary particles of one body
//! against the boundary triangles of another, two-way. The bodies that may touch run their
//! substeps together (`soft_lockstep.rs`); this file is the narrow phase and its passes.
//!
//! A particle past a triangle of another body (the nearest one, within reach of it) is pushed
//! out along the triangle's outward normal, and the triangle's three particles the opposite
//! way, split by the particle's barycentric weights `b_j`: the pair's inverse mass is
//! `w_p + sum b_j^2 w_j`, so linear momentum is conserved. A step meets other bodies in three
//! kinds of pass ([`SoftContactPhase`]):
//! - before the contact stage, on the predicted positions `x + h v`, changing velocities (as
//!   the contacts with colliders do), so that no body's own passes start by driving it into
//!   another (for the paper's springs, which are not substepped, the contacts that matter);
//! - in every substep, on the positions the shape solve predicted, moving particles apart, as
//!   XPBD meets contacts, with static friction that holds a particle where it is on the other
//!   body's triangle (an anchor in that triangle's barycentric coordinates, kept while the
//!   particle stays within `mu` times its push of it: the position-based friction the ground's
//!   contacts use, `contacts.rs`), sliding friction beyond;
//! - after integration, on the positions the step ended at, moving penetrating particles
//!   apart and stopping their approach, so that no particle ends a step inside another body;
//!   but one deeper in another body than a fast impact leaves (bodies placed overlapping),
//!   which the substeps' passes ease out.
//!
//! The volume impulses of a substep see these contacts as they see the ground's: a push into
//! the other body is taken out of the impulse before its cubic is solved
//! (`constrain_direction`), and the momentum taken out is handed to the other body with its
//! Coulomb friction (`soft_lockstep.rs`), so a squashed jelly in a pile keeps its volume and
//! holds up the one above it.
//!
//! The broad phase (`soft_broad_phase.rs`): the substeps' passes read the candidates found
//! once a step, and so does the predicted pass when they cover the whole step's motion (no
//! particle so fast that its path was cut short); otherwise it, and always the final pass,
//! search each body's grid of triangles.

use std::ops::DerefMut;

use glam::Vec3;
use parry3d::bounding_volume::{Aabb, BoundingVolume};

use super::body::SoftBodyState;
use super::boundary::{
    Boundary, CandidateParticle, SoftCandidates, TriangleGrid, closest_barycentric, faces_into,
    nearest_triangle, outside_of, surface_distance,
};
use super::colliders::combined_friction;
use super::contacts::{ContactState, MAX_DEPENETRATION_SPEED};
use super::impulses::SOFT_CONTACT;
use super::lanes::Point4;
use super::material::VolumeMethod;
use super::parallel::SharedSlice;
use super::parallel::{Parallel, for_each_mut};
use super::soft_broad_phase::{PairRounds, boundary_bounds, overlap, prepare_soft_contacts};
use super::soft_records::{SoftAnchor, SoftSupport};

/// Which of a step's two soft-contact passes runs (see the module's documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum SoftContactPhase {
    /// Before the contact stage of a step of `h`: on `x + h v`, changing velocities.
    Predicted(f32),
    /// After integration: on `x`, moving particles apart and stopping their approach.
    Final,
    /// Inside a substep of the given length, on the positions the shape solve predicted
    /// (before they become velocities): moving particles apart, with friction on their
    /// relative motion since the substep's start, as XPBD meets contacts.
    Substep(f32),
}

impl SoftContactPhase {
    /// The time the positions are predicted ahead.
    fn ahead(self) -> f32 {
        match self {
            SoftContactPhase::Predicted(h) => h,
            SoftContactPhase::Final | SoftContactPhase::Substep(_) => 0.0,
        }
    }

    /// Whether this is the pass that ends a step.
    fn is_final(self) -> bool {
        self == SoftContactPhase::Final
    }
}

/// Records the particles the last soft-contact pass touched for the volume passes, which
/// keep none of a push into the other body, as against the ground: pushes into it that the
/// next contact pass would turn into velocity pump energy into a pile.
fn record_soft_contacts(body: &mut SoftBodyState) {
    body.scratch.soft_count += body.scratch.soft_touched.len() as u32;
    body.met_soft_bodies |= !body.scratch.soft_touched.is_empty();
    for k in 0..body.scratch.soft_touched.len() {
        let (i, n) = body.scratch.soft_touched[k];
        body.contacts.record(i as usize, n, 0.0, None);
        body.contacts.sphere[i as usize] = SOFT_CONTACT;
    }
}

/// Records, for XPBD's cluster correction, the corners of the triangles that `supports` (a
/// substep pass's new ones) met as touching the other body's particle, in `contacts` (the
/// triangles' body, of volume method `method`): the correction, which runs on the positions
/// after the last substep, pushes neither side of a contact into the other (what it pushes
/// in, the step's final pass, one particle at a time, may not undo). The paper's
/// impulses keep their own rule (only the particle side is constrained; its push is handed to
/// the triangle, `soft_records.rs`).
fn record_soft_corners(
    supports: &[SoftSupport],
    contacts: &mut ContactState,
    method: VolumeMethod,
) {
    if !matches!(method, VolumeMethod::Xpbd(s) if s.clusters > 0) {
        return;
    }
    for s in supports {
        for (&c, &b) in s.corners.iter().zip(s.weights.as_ref()) {
            if b > 0.0 {
                contacts.record(c as usize, -s.normal, 0.0, None);
                contacts.sphere[c as usize] = SOFT_CONTACT;
            }
        }
    }
}

/// A body's particles as the narrow phase reads and writes them; for a self contact both
/// sides are the same arrays (hence shared slices, read and written one element at a time on
/// this thread).
struct Arrays<'a> {
    x: SharedSlice<'a, Vec3>,
    v: SharedSlice<'a, Vec3>,
    inv_masses: &'a [f32],
    /// Whether the body stands still in this pass (see [`frozen`]): its particles then
    /// weigh as a static collider's.
    frozen: bool,
    /// Where each particle started the substep (for [`SoftContactPhase::Substep`]).
    start: &'a [Point4],
    anchors: SharedSlice<'a, SoftAnchor>,
    pass: u32,
    /// Per particle, the outward normal of the static collider it rests on (zero: none).
    resting_on: &'a [Vec3],
}

impl<'a> Arrays<'a> {
    /// Particle `i`'s inverse mass in this pass.
    fn w(&self, i: usize) -> f32 {
        if self.frozen { 0.0 } else { self.inv_masses[i] }
    }

    fn new(
        x: &'a mut [Vec3],
        v: &'a mut [Vec3],
        (inv_masses, frozen): (&'a [f32], bool),
        start: &'a [Point4],
        anchors: &'a mut [SoftAnchor],
        pass: u32,
        resting_on: &'a [Vec3],
    ) -> Self {
        // SAFETY: the narrow phase runs on this thread alone, reading and writing one element
        // at a time and holding no reference into the slices.
        unsafe {
            Arrays {
                x: SharedSlice::new(x),
                v: SharedSlice::new(v),
                inv_masses,
                frozen,
                start,
                anchors: SharedSlice::new(anchors),
                pass,
                resting_on,
            }
        }
    }
}

/// One pass of soft contacts among `bodies` (every pair whose bounds overlap, and each body
/// with itself where it asks for it), pairs that share no body at the same time on the
/// threads of `parallel` (`PairRounds`: the result does not depend on them). A `listed` pass
/// reads the step's candidates
/// ([`gather_soft_candidates`](super::soft_broad_phase::gather_soft_candidates), which must
/// have run this step and cover the pass: a substep's pass always, the predicted one when
/// they cover the whole step); the others search a grid. Returns the contacts.
pub(crate) fn soft_contact_pass<B: DerefMut<Target = SoftBodyState> + Send>(
    bodies: &mut [B],
    (phase, listed): (SoftContactPhase, bool),
    rounds: &mut PairRounds,
    parallel: &dyn Parallel,
) -> u32 {
    // A listed pass's preparation is a few flags; the others hash each body's triangles.
    if listed {
        bodies
            .iter_mut()
            .for_each(|b| prepare_soft_pass(b, phase, listed));
    } else {
        for_each_mut(bodies, parallel, &|body| {
            prepare_soft_pass(body, phase, listed)
        });
    }
    rounds.plan(bodies, |one, other, [a, b]| {
        if listed {
            let met = |body: &SoftBodyState, partner: usize| {
                !body.boundary.candidates.against(partner as u32).is_empty()
            };
            met(one, b) || met(other, a)
        } else {
            overlap(one, other).is_some()
        }
    });
    rounds.run(bodies, parallel, &|one, other, slots| match other {
        None => resolve_self(one, phase, listed, slots[0]),
        Some(other) => {
            let region = if listed { None } else { overlap(one, other) };
            resolve_pair(one, other, phase, region, slots)
        }
    })
}

/// Prepares `body` for a pass of `phase` (its triangle grid, but for a `listed` pass, which
/// reads the step's candidates). The pass then resolves the overlapping pairs and each body
/// with itself.
fn prepare_soft_pass(body: &mut SoftBodyState, phase: SoftContactPhase, listed: bool) {
    if !phase.is_final() {
        body.scratch.soft_supports.clear();
    }
    if let SoftContactPhase::Substep(_) = phase {
        body.scratch.soft_pass += 1;
        // Only this substep's soft contacts constrain its volume impulses (an earlier one
        // keeps its normal, so that the particle stays listed once, but constrains nothing).
        for &i in &body.contacts.touching {
            if body.contacts.sphere[i as usize] == SOFT_CONTACT {
                body.contacts.kept[i as usize] = 1.0;
                body.contacts.sphere[i as usize] = u32::MAX;
            }
        }
        return;
    }
    if !listed {
        let margin = body.soft_contacts.map_or(0.0, |s| s.thickness);
        prepare_soft_contacts(body, phase.ahead(), margin);
    }
}

/// Which particles of one body a pass looks at, and where it finds the triangles of the other
/// body near each.
enum Near<'a> {
    /// The particles of `particles` whose motion reaches into `region`, against the triangles
    /// `grid` lists near that motion; for a self contact, `rest` holds the rest positions,
    /// and the triangles within two longest boundary edges of the particle at rest are
    /// skipped (its neighbours on the same surface).
    Grid {
        particles: &'a [u32],
        grid: &'a TriangleGrid,
        region: Aabb,
        rest: Option<&'a [Vec3]>,
    },
    /// The step's candidates against the other body.
    Listed {
        candidates: &'a SoftCandidates,
        list: &'a [CandidateParticle],
    },
}

/// Contacts between two different bodies (both ways: `a`'s particles against `b`'s triangles,
/// then `b`'s against `a`'s), found in the overlap `region` of their prepared bounds, or from
/// the step's candidates (`None`).
fn resolve_pair(
    a: &mut SoftBodyState,
    b: &mut SoftBodyState,
    phase: SoftContactPhase,
    region: Option<Aabb>,
    slots: [u32; 2],
) -> u32 {
    let (Some(sa), Some(sb)) = (a.soft_contacts, b.soft_contacts) else {
        return 0;
    };
    // Two bodies asleep are left alone, but for the pass that ends the step they fell asleep
    // in; so are two standing still.
    let dozing = |body: &SoftBodyState| body.is_sleeping() && !body.sleep.fell_asleep_now;
    if (dozing(a) && dozing(b))
        || (frozen(a, phase) && frozen(b, phase))
        || !a.collision_filter.interacts_with(b.collision_filter)
    {
        return 0;
    }
    let thickness = sa.thickness.max(sb.thickness);
    let mu = combined_friction(a.material.friction, b.material.friction);
    let (frozen_a, frozen_b) = (frozen(a, phase), frozen(b, phase));
    let pa = Arrays::new(
        &mut a.positions,
        &mut a.velocities,
        (&a.inv_masses, frozen_a),
        &a.scratch.predicted,
        &mut a.scratch.soft_anchors,
        a.scratch.soft_pass,
        &a.contacts.static_normals,
    );
    let pb = Arrays::new(
        &mut b.positions,
        &mut b.velocities,
        (&b.inv_masses, frozen_b),
        &b.scratch.predicted,
        &mut b.scratch.soft_anchors,
        b.scratch.soft_pass,
        &b.contacts.static_normals,
    );
    let (ba, bb) = (&a.boundary, &b.boundary);
    let (ta, tb) = (&mut a.scratch.soft_touched, &mut b.scratch.soft_touched);
    ta.clear();
    tb.clear();
    let new_supports = (a.scratch.soft_supports.len(), b.scratch.soft_supports.len());
    let contact_a = Contact {
        phase,
        thickness,
        friction: mu,
        final_reach: FINAL_PASS_DEPTH,
        partner: slots[1],
        supports: std::mem::take(&mut a.scratch.soft_supports).into(),
    };
    let contact_b = Contact {
        phase,
        thickness,
        friction: mu,
        final_reach: FINAL_PASS_DEPTH,
        partner: slots[0],
        supports: std::mem::take(&mut b.scratch.soft_supports).into(),
    };
    // `a`'s particles (listed in `a`'s candidates, or all of `a`'s in the region) against
    // `b`'s triangles (hashed in `b`'s grid), then the other way.
    let contacts = contact_a.particles_against_triangles(
        &pa,
        &bb.triangles,
        &pb,
        near_of(ba, bb, region, thickness, slots[1]),
        bb.longest_edge,
        ta,
    ) + contact_b.particles_against_triangles(
        &pb,
        &ba.triangles,
        &pa,
        near_of(bb, ba, region, thickness, slots[0]),
        ba.longest_edge,
        tb,
    );
    a.scratch.soft_supports = contact_a.supports.into_inner();
    b.scratch.soft_supports = contact_b.supports.into_inner();
    record_soft_contacts(a);
    record_soft_contacts(b);
    let (method_a, method_b) = (a.material.method, b.material.method);
    record_soft_corners(
        &a.scratch.soft_supports[new_supports.0..],
        &mut b.contacts,
        method_b,
    );
    record_soft_corners(
        &b.scratch.soft_supports[new_supports.1..],
        &mut a.contacts,
        method_a,
    );
    // A sleeping body touched by an awake one is stirred (it wakes, its quiet time kept: if
    // it stays still, it sleeps again with the last of its neighbours; see `Sleep::stir`);
    // two sleeping ones stay as they are.
    if contacts > 0 {
        if a.is_sleeping() && !b.is_sleeping() {
            a.sleep.stir();
        } else if b.is_sleeping() && !a.is_sleeping() {
            b.sleep.stir();
        }
    }
    contacts
}

/// Whether `body` stands still in a pass of `phase`, as a static collider would: in a substep's
/// pass, a body that does not run this step's substeps (it was asleep when they were planned;
/// moved by the others' contacts with no solve of its own, it would lose volume); in the pass
/// that ends a step, a body asleep but for the one it fell asleep in (whose last contacts that
/// pass still meets). Two such bodies are left alone; one touched by a body that moves is
/// stirred, and runs the next step.
fn frozen(body: &SoftBodyState, phase: SoftContactPhase) -> bool {
    match phase {
        SoftContactPhase::Substep(_) => body.scratch.substep_plan.is_none(),
        SoftContactPhase::Final => body.is_sleeping() && !body.sleep.fell_asleep_now,
        SoftContactPhase::Predicted(_) => false,
    }
}

/// How a pair's pass finds `from`'s particles near `to`'s triangles (in slot `partner`): in
/// `to`'s grid within the pair's overlap `region` grown by `thickness`, or, without a region,
/// from `from`'s candidates.
fn near_of<'a>(
    from: &'a Boundary,
    to: &'a Boundary,
    region: Option<Aabb>,
    thickness: f32,
    partner: u32,
) -> Near<'a> {
    match region {
        Some(region) => Near::Grid {
            particles: &from.particles,
            grid: &to.grid,
            region: region.loosened(thickness),
            rest: None,
        },
        None => Near::Listed {
            candidates: &from.candidates,
            list: from.candidates.against(partner),
        },
    }
}

/// Contacts of a body with itself, if it asks for them (from its candidates if `listed`).
fn resolve_self(body: &mut SoftBodyState, phase: SoftContactPhase, listed: bool, slot: u32) -> u32 {
    let Some(settings) = body.soft_contacts.filter(|s| s.self_contacts) else {
        return 0;
    };
    let Some(reach) = boundary_bounds(body, phase.ahead()) else {
        return 0;
    };
    let arrays = Arrays::new(
        &mut body.positions,
        &mut body.velocities,
        (&body.inv_masses, false),
        &body.scratch.predicted,
        &mut body.scratch.soft_anchors,
        body.scratch.soft_pass,
        &body.contacts.static_normals,
    );
    let contact = Contact {
        phase,
        thickness: settings.thickness,
        friction: body.material.friction,
        final_reach: f32::INFINITY,
        partner: slot,
        supports: std::mem::take(&mut body.scratch.soft_supports).into(),
    };
    let boundary = &body.boundary;
    let near = if listed {
        Near::Listed {
            candidates: &boundary.candidates,
            list: boundary.candidates.against(slot),
        }
    } else {
        Near::Grid {
            particles: &boundary.particles,
            grid: &boundary.grid,
            region: reach.loosened(settings.thickness),
            rest: Some(body.mesh.positions()),
        }
    };
    let touched = &mut body.scratch.soft_touched;
    touched.clear();
    let new_supports = body.scratch.soft_supports.len();
    let contacts = contact.particles_against_triangles(
        &arrays,
        &boundary.triangles,
        &arrays,
        near,
        boundary.longest_edge,
        touched,
    );
    body.scratch.soft_supports = contact.supports.into_inner();
    record_soft_contacts(body);
    let supports = &body.scratch.soft_supports[new_supports..];
    record_soft_corners(supports, &mut body.contacts, body.material.method);
    contacts
}

/// A particle found inside a triangle: what both passes' responses need.
#[derive(Clone, Copy)]
struct Touch {
    /// The particle and its inverse mass.
    i: usize,
    w_p: f32,
    /// The triangle's corners, and the barycentric weights of the particle's nearest point.
    corners: [usize; 3],
    q: Vec3,
    /// The triangle's outward normal, and how far the particle is past it.
    n: Vec3,
    depth: f32,
    /// The pair's inverse mass along the normal, and the triangle's share of it.
    w: f32,
    w_t: f32,
}

/// How deep in another body the pass that ends a step still moves a particle out whole: what
/// a fast impact leaves behind a step's last substep (10 m/s over XPBD's substep of 1/600 s),
/// at any step rate. A particle deeper was inside before the step ended (bodies placed
/// overlapping, a particle a pile squeezed in), and the substeps ease it out; moved out whole,
/// it would jump through the other body's thin parts and turn tets inside out, and a resting
/// pile would flicker.
const FINAL_PASS_DEPTH: f32 = 10.0 / 600.0;

/// The part of a predicted penetration `depth` to remove within a step of `h`: all that the
/// motion adds, and the penetration `existing` before it at most at
/// [`MAX_DEPENETRATION_SPEED`], so that a particle already deep in a body is eased out rather
/// than shot out (as against a sphere, `contacts.rs`).
fn bounded_correction(depth: f32, existing: f32, h: f32) -> f32 {
    let existing = existing.max(0.0);
    depth
        .min(depth - existing + MAX_DEPENETRATION_SPEED * h)
        .max(0.0)
}

/// A pass's contact rule.
struct Contact {
    phase: SoftContactPhase,
    thickness: f32,
    friction: f32,
    /// How deep a particle the final pass moves out whole: [`FINAL_PASS_DEPTH`] between two
    /// bodies, any depth in a body's own contacts (a body is never placed in itself; what its
    /// substeps missed of a fold is met here).
    final_reach: f32,
    /// The slot of the triangles' body, and the supports found (substep phase).
    partner: u32,
    supports: std::cell::RefCell<Vec<SoftSupport>>,
}

impl Contact {
    /// The narrow phase: the particles of `p` that `near` lists against the triangles
    /// `triangles` (of `t`, whose longest boundary edge is `reach`) near each.
    fn particles_against_triangles(
        &self,
        p: &Arrays,
        triangles: &[[u32; 3]],
        t: &Arrays,
        near: Near,
        reach: f32,
        touched: &mut Vec<(u32, Vec3)>,
    ) -> u32 {
        let ahead = self.phase.ahead();
        let corner = |j: usize| t.x.get(j) + ahead * t.v.get(j);
        // Triangles facing into the collider a particle rests on are skipped in the passes
        // that ease a particle out at a bounded speed; the final pass, which moves it out
        // whole, would move it through the next triangle, maybe across the other body's thin
        // part: it leaves it.
        let eases_out = !self.phase.is_final();
        let mut contacts = 0;
        // The nearest triangle decides, as a signed distance would: a particle over the top
        // face near its edge is outside the body, whatever the side face's plane says.
        let mut meet = |i: usize, corners: Option<[usize; 3]>| {
            if let Some(corners) = corners
                && let Some(n) = self.resolve(i, p.w(i), p, corners, t, reach)
            {
                touched.push((i as u32, n));
                contacts += 1;
            }
        };
        match near {
            Near::Listed { candidates, list } => {
                for particle in list {
                    let i = particle.particle as usize;
                    let xp = p.x.get(i) + ahead * p.v.get(i);
                    let listed = candidates.triangles_of(particle);
                    let near = |visit: &mut dyn FnMut(u32)| listed.iter().for_each(|&k| visit(k));
                    let blocked =
                        |tri: [u32; 3]| eases_out && faces_into(p.resting_on[i], tri, corner);
                    meet(i, nearest_triangle(xp, near, triangles, corner, blocked));
                }
            }
            Near::Grid {
                particles,
                grid,
                region,
                rest,
            } => {
                for &i in particles {
                    let i = i as usize;
                    let x = p.x.get(i);
                    let xp = x + ahead * p.v.get(i);
                    let swept = Aabb::new(x.min(xp), x.max(xp)).loosened(self.thickness);
                    if !swept.intersects(&region) {
                        continue;
                    }
                    let skip = |tri: [u32; 3]| {
                        (eases_out && faces_into(p.resting_on[i], tri, corner))
                            || rest.is_some_and(|rest| {
                                if tri.contains(&(i as u32)) {
                                    return true;
                                }
                                let [a, b, c] = tri.map(|j| rest[j as usize]);
                                let q = closest_barycentric(rest[i], a, b, c);
                                (a * q.x + b * q.y + c * q.z).distance(rest[i]) < 2.0 * reach
                            })
                    };
                    let near = |visit: &mut dyn FnMut(u32)| grid.for_each_near(&swept, visit);
                    let found = nearest_triangle(xp, near, triangles, corner, skip);
                    // The final pass leaves alone a particle whose nearest triangle faces
                    // into its collider: the substeps ease it out through another.
                    let into =
                        |c: &[usize; 3]| faces_into(p.resting_on[i], c.map(|j| j as u32), corner);
                    meet(i, found.filter(|c| eases_out || !into(c)));
                }
            }
        }
        contacts
    }

    /// Particle `i` of `p` (inverse mass `w_p`) against the triangle `corners` of `t`. Returns
    /// whether they touched.
    fn resolve(
        &self,
        i: usize,
        w_p: f32,
        p: &Arrays,
        corners: [usize; 3],
        t: &Arrays,
        reach: f32,
    ) -> Option<Vec3> {
        let ahead = self.phase.ahead();
        let thickness = self.thickness;
        let (x, v) = (p.x.get(i), p.v.get(i));
        let xp = x + ahead * v;
        let now = corners.map(|j| t.x.get(j));
        let end = corners.map(|j| t.x.get(j) + ahead * t.v.get(j));
        let was_outside = outside_of(x, now, thickness);
        let (d, n, q) = surface_distance(xp, end, self.phase.is_final())?;
        if d >= thickness || (d < -reach && !was_outside) {
            return None;
        }
        let w_t: f32 = (0..3).map(|k| q[k] * q[k] * t.w(corners[k])).sum();
        let w = w_p + w_t;
        if w == 0.0 {
            return None;
        }
        // The predicted pass keeps the gap; the final pass only undoes penetration (moving
        // particles apart within the gap, with no friction to hold them, would let a pile walk).
        // The gap only finds contacts early; a contact takes the particle to the surface, as
        // the ground does (pushing it out to the gap would bounce a resting pile).
        if d >= 0.0 {
            return None;
        }
        let mut depth = -d;
        if let SoftContactPhase::Substep(hs) = self.phase {
            // A particle that started the substep deeper than the gap inside the other body
            // (bodies placed overlapping) is eased out at a bounded speed, as the predicted
            // pass does, not shot out at its depth over the substep; what the substep's
            // impulses left within the gap is undone whole.
            let start = corners.map(|j| t.start[j].vec3());
            let existing = surface_distance(p.start[i].vec3(), start, false)
                .map_or(0.0, |(d0, ..)| -d0 - thickness);
            depth = bounded_correction(depth, existing, hs);
        }
        if self.phase.is_final() && depth > self.final_reach {
            return None;
        }
        let touch = Touch {
            i,
            w_p,
            corners,
            q,
            n,
            depth,
            w,
            w_t,
        };
        if let SoftContactPhase::Substep(_) = self.phase {
            self.substep_contact(&touch, p, t);
        } else {
            self.velocity_contact(&touch, p, t, x, now);
        }
        Some(n)
    }

    /// A substep's contact: the particle and the triangle apart along the normal, then friction
    /// on their relative motion since the substep started: held (static) if it is within `mu`
    /// times the push, else slowed by it; recorded as a support for the volume impulses.
    fn substep_contact(&self, touch: &Touch, p: &Arrays, t: &Arrays) {
        let Touch {
            i,
            w_p,
            corners,
            q,
            n,
            depth,
            w,
            w_t,
        } = *touch;
        let shift = depth / w;
        let moved = |k_shift: Vec3| {
            p.x.set(i, p.x.get(i) + k_shift * w_p);
            for k in 0..3 {
                let j = corners[k];
                t.x.set(j, t.x.get(j) - k_shift * (q[k] * t.w(j)));
            }
        };
        moved(n * shift);
        let travel = |a: &Arrays, j: usize| a.x.get(j) - a.start[j].vec3();
        let relative_motion =
            travel(p, i) - (0..3).map(|k| q[k] * travel(t, corners[k])).sum::<Vec3>();
        let slip = relative_motion - n * relative_motion.dot(n);
        let slip_length = slip.length();
        let anchor = p.anchors.get(i);
        // The corners are checked: an anchor may come from a restored snapshot.
        let anchored = anchor.partner == self.partner
            && anchor.pass.saturating_add(1) >= p.pass
            && anchor
                .corners
                .iter()
                .all(|&c| (c as usize) < t.inv_masses.len());
        let mut held_fully = false;
        if anchored {
            // Static friction: back on the anchor if it is within reach.
            let point: Vec3 = (0..3)
                .map(|k| anchor.weights[k] * t.x.get(anchor.corners[k] as usize))
                .sum();
            let offset = p.x.get(i) - point;
            let tangential = offset - n * offset.dot(n);
            if tangential.length_squared() <= (self.friction * depth).powi(2) {
                moved(-tangential / w);
                held_fully = true;
                p.anchors.set(
                    i,
                    SoftAnchor {
                        pass: p.pass,
                        ..anchor
                    },
                );
            }
        }
        if !held_fully {
            if slip_length > 0.0 {
                let held = (self.friction * depth / slip_length).min(1.0);
                moved(-slip * (held / w));
            }
            let q_end = closest_barycentric(
                p.x.get(i),
                t.x.get(corners[0]),
                t.x.get(corners[1]),
                t.x.get(corners[2]),
            );
            p.anchors.set(
                i,
                SoftAnchor {
                    partner: self.partner,
                    corners: corners.map(|j| j as u32),
                    weights: q_end,
                    pass: p.pass,
                },
            );
        }
        self.supports.borrow_mut().push(SoftSupport {
            particle: i as u32,
            normal: n,
            partner: self.partner,
            corners: corners.map(|j| j as u32),
            weights: q,
            inv_mass: w_t,
            friction: self.friction,
            pushed: Vec3::ZERO,
        });
    }

    /// The predicted or final pass's contact: an impulse on the relative velocity along the
    /// normal (the predicted pass bounded by how deep the pair already was at `x`, the final
    /// pass after undoing the penetration), then Coulomb friction.
    fn velocity_contact(&self, touch: &Touch, p: &Arrays, t: &Arrays, x: Vec3, now: [Vec3; 3]) {
        let Touch {
            i,
            w_p,
            corners,
            q,
            n,
            depth,
            w,
            ..
        } = *touch;
        // An impulse (per unit mass of the pair) on the particle, and its opposite shared by
        // the triangle's corners.
        let push = |impulse: Vec3| {
            p.v.set(i, p.v.get(i) + impulse * w_p);
            for k in 0..3 {
                let j = corners[k];
                t.v.set(j, t.v.get(j) - impulse * (q[k] * t.w(j)));
            }
        };
        let relative = || p.v.get(i) - (0..3).map(|k| q[k] * t.v.get(corners[k])).sum::<Vec3>();
        let normal_impulse = match self.phase {
            SoftContactPhase::Predicted(h) => {
                let existing = surface_distance(x, now, false).map_or(0.0, |(d_now, ..)| -d_now);
                let lambda = bounded_correction(depth, existing, h) / h / w;
                push(n * lambda);
                lambda
            }
            SoftContactPhase::Substep(_) => unreachable!("handled above"),
            SoftContactPhase::Final => {
                let shift = depth / w;
                p.x.set(i, p.x.get(i) + n * (shift * w_p));
                for k in 0..3 {
                    let j = corners[k];
                    t.x.set(j, t.x.get(j) - n * (shift * q[k] * t.w(j)));
                }
                let approach = relative().dot(n);
                let lambda = (-approach / w).max(0.0);
                push(n * lambda);
                lambda
            }
        };
        // Coulomb friction on the relative tangential velocity.
        let rel = relative();
        let slip = rel - n * rel.dot(n);
        let slip_speed = slip.length();
        if slip_speed > 0.0 && normal_impulse > 0.0 {
            let jt = (slip_speed / w).min(self.friction * normal_impulse);
            push(-slip * (jt / slip_speed));
        }
    }
}
