//! Contacts of particles with static colliders (any parry shape) and with dynamic rigid
//! spheres, at the velocity level.
//!
//! A contact is resolved on the predicted position `xp = x + h v`: when `xp` is inside a
//! collider, the velocity gets the normal change that puts `xp` on the surface, and friction
//! removes tangential velocity up to `mu` times that normal change (Coulomb). Against a sphere
//! the change is shared by inverse mass, so the sphere is pushed back (two-way coupling) and
//! momentum is conserved. Kinematic particles (inverse mass zero) are not touched.
//!
//! A particle in contact remembers the contact normal until the next step, and the volume passes
//! keep only the share of a push into the contact that the particle would keep after the last
//! contact pass (see `constrain_direction`): none against a static collider,
//! `w_s / (w_p + w_s)` against a sphere, whose push back on the particle is what lets a soft
//! body carry it.
//!
//! Rigid bodies that another engine simulates (see [`RigidContacts`]) are met the same way, at
//! their colliders' poses along their paths within the step (`RigidBodyMotion::advance`): each
//! push is an impulse shared by the particle and the body through their effective inverse
//! masses (the body's includes its inverse inertia at the contact point), so linear and angular
//! momentum are conserved, and so is each friction impulse (`rigid_friction`). The volume
//! passes keep the whole of a push into such a body (removing it, as against the ground, would
//! take momentum from the pair that the body never gets): the next contact pass (the next
//! substep's, or the one that ends the step) hands it to the body. A jelly squashed under a
//! crate thus holds the crate up with its volume too.
//!
//! Friction against a static collider holds a particle where it stands, not only its velocity
//! (see `static_friction`): with velocity-only friction the volume impulses' small pushes at
//! a resting body's base, each stopped by friction only while it pressed into the ground, made
//! the body walk across the ground and never come to rest (PERFORMANCE.md). Against a rigid
//! body of another engine it holds the particle on a point of the body's collider, in the
//! collider's frame (`rigid_friction`): with Coulomb's friction on velocities a crate resting
//! on a jelly crept across it. Against a sphere, friction is Coulomb's on the relative
//! velocity. The ground's push that the volume impulses meet (their pushes into it that
//! `constrain_direction` takes out) is a normal force too, and gets its friction after them
//! (`support_friction`).

use glam::Vec3;
use parry3d::bounding_volume::Aabb;
use parry3d::math::Pose;

use super::chunks::{ChunkFindings, in_particle_chunks};
use super::colliders::{
    ColliderInstance, CollisionFilter, RigidBodyMotion, RigidContacts, RigidSphereState,
    combined_friction, friction_change,
};
use super::impulses::SOFT_CONTACT;
use super::parallel::{Parallel, SharedSlice};

/// Two static colliders a particle touches at once count as two contacts (the volume impulses
/// may push into neither) when the cosine between their normals is below this; nearly parallel
/// surfaces (two boxes making one floor) are one.
const DISTINCT_NORMALS: f32 = 0.9;

/// Fastest speed, in m/s, at which a particle already inside a sphere is pushed out of it.
pub const MAX_DEPENETRATION_SPEED: f32 = 1.0;

/// Coulomb friction for a particle whose predicted position was pushed `depth` out of a static
/// collider along `normal`, with velocity `v` (the push included), at `x`: sticking at the
/// position level, sliding at the velocity level. A particle already anchored (`anchor`
/// finite: it touched the collider in the last contact pass) whose predicted tangential offset
/// from its anchor is at most `mu * depth` is put back on the anchor (static friction, the
/// position-based form of Macklin et al.'s "Detailed Rigid Body Simulation with Extended
/// Position Based Dynamics", 2020); otherwise its tangential velocity loses at most
/// `mu * depth / h` and it is anchored where its predicted position ends. Returns the velocity and the
/// anchor.
#[inline]
fn static_friction(
    x: Vec3,
    v: Vec3,
    normal: Vec3,
    depth: f32,
    mu: f32,
    h: f32,
    anchor: Vec3,
) -> (Vec3, Vec3) {
    if anchor.is_finite() {
        let offset = x + h * v - anchor;
        let tangential = offset - normal * offset.dot(normal);
        if tangential.length_squared() <= (mu * depth).powi(2) {
            let v = v - tangential / h;
            return (v, x + h * v);
        }
    }
    let vt = v - normal * v.dot(normal);
    let v = v + friction_change(vt, mu * depth / h);
    (v, x + h * v)
}

/// Where static friction holds a particle on a rigid body's collider: a point in the frame of
/// collider `collider` (its index in [`RigidContacts::colliders`]), set in the last rigid
/// contact pass that found the particle inside it.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub struct RigidAnchor {
    pub(crate) collider: u32,
    pub(crate) local: Vec3,
}

impl RigidAnchor {
    /// No anchor.
    pub(crate) const NONE: RigidAnchor = RigidAnchor {
        collider: u32::MAX,
        local: Vec3::ZERO,
    };
}

/// Coulomb friction between a particle of inverse mass `w` at `x` with velocity `v` and
/// collider `collider` of `body`, at the contact point `r` from the body's centre of mass,
/// the collider at `pose` where the particle is predicted (`x + h v`), as `static_friction`
/// has it against the ground: the normal push (`depth` along `normal`, impulse `lambda`) is in
/// `v`. A particle whose predicted position is at most `mu * depth` from its anchor
/// (tangentially) is put back on it, the pair sharing the impulse by their inverse masses (the
/// body's at `r`); otherwise the friction impulse on the relative velocity is at most
/// `mu * lambda`. Returns the particle's velocity and its anchor, where it is predicted now.
fn rigid_friction(
    (x, v, w): (Vec3, Vec3, f32),
    body: &mut RigidBodyMotion,
    (collider, pose, r): (u32, &Pose, Vec3),
    (normal, depth, lambda): (Vec3, f32, f32),
    mu: f32,
    (h, elapsed): (f32, f32),
    anchor: RigidAnchor,
) -> (Vec3, RigidAnchor) {
    let tangential = |d: Vec3| d - normal * d.dot(normal);
    let held = (anchor.collider == collider)
        .then(|| tangential(x + h * v - pose.transform_point(anchor.local)))
        .filter(|offset| offset.length_squared() <= (mu * depth).powi(2));
    // The relative tangential velocity to take out, and the bound on the impulse doing it.
    let (slip, bound) = match held {
        Some(offset) => (offset / h, f32::INFINITY),
        None => (tangential(v - body.velocity_at(r)), mu * lambda),
    };
    let mut v = v;
    let slip_speed = slip.length();
    if slip_speed > 0.0 {
        let t = slip / slip_speed;
        let impulse = (slip_speed / (w + body.inv_mass_along(r, t))).min(bound);
        v -= t * (impulse * w);
        body.apply_impulse(t * impulse, r, elapsed);
    }
    let local = pose.inverse_transform_point(x + h * v);
    (v, RigidAnchor { collider, local })
}

/// What a body remembers of its contacts with colliders, spheres, rigid bodies and other
/// soft bodies: what the volume passes must not push into, and where friction holds it.
#[derive(Clone, Debug)]
pub(crate) struct ContactState {
    /// Per particle, the outward unit normal of what it touches this step (zero if nothing).
    pub(crate) normals: Vec<Vec3>,
    /// Per particle touching two static colliders at once (on the edge or in the corner of a
    /// room), the outward normal of the other one (zero otherwise): the volume impulses may
    /// push it into neither, or they pump it into the one not recorded and the contacts throw
    /// it back every substep.
    pub(crate) second: Vec<Vec3>,
    /// Per particle in contact, the share `f` of a push into the contact that the particle
    /// keeps: 0 against a static collider, `w_s / (w_p + w_s)` against a sphere.
    pub(crate) kept: Vec<f32>,
    /// Per particle, where static friction holds it on the static collider it touches (NaN:
    /// touching none); see `static_friction`.
    pub(crate) anchors: Vec<Vec3>,
    /// Per particle in contact with a sphere, that sphere's index in the slice the passes get;
    /// `u32::MAX` otherwise.
    pub(crate) sphere: Vec<u32>,
    /// The particles with a non-zero entry in `normals`, to clear them cheaply.
    pub(crate) touching: Vec<u32>,
    /// Per particle, how deep its predicted position was in a static collider in the last
    /// contact pass (zero when it touched none) and the pair's friction: what
    /// `support_friction` shares the ground's push out by.
    pub(crate) static_contact: Vec<[f32; 2]>,
    /// Per particle, the outward normal of the static collider it touched in the last contact
    /// pass (zero: none): a soft contact does not push it into that collider
    /// (`soft_contacts.rs`).
    pub(crate) static_normals: Vec<Vec3>,
    /// Per particle, where static friction holds it on a rigid body's collider (see
    /// `rigid_friction`); `RigidAnchor::NONE` if it touched none in the last rigid contact pass.
    pub(crate) rigid_anchors: Vec<RigidAnchor>,
    /// The particles with a rigid anchor, to forget those a pass finds touching no collider.
    pub(crate) rigid_held: Vec<u32>,
    /// Per particle, whether the rigid contact pass under way found it inside a collider.
    rigid_touched: Vec<bool>,
}

impl ContactState {
    /// No contacts, for `n` particles.
    pub(crate) fn new(n: usize) -> Self {
        ContactState {
            normals: vec![Vec3::ZERO; n],
            second: vec![Vec3::ZERO; n],
            kept: vec![0.0; n],
            anchors: vec![Vec3::NAN; n],
            sphere: vec![u32::MAX; n],
            touching: Vec::with_capacity(n),
            static_contact: vec![[0.0; 2]; n],
            static_normals: vec![Vec3::ZERO; n],
            rigid_anchors: vec![RigidAnchor::NONE; n],
            rigid_held: Vec::with_capacity(n),
            rigid_touched: vec![false; n],
        }
    }

    /// At a step's start: last step's contacts forgotten (the friction anchors kept).
    pub(crate) fn begin_step(&mut self) {
        for &i in &self.touching {
            self.normals[i as usize] = Vec3::ZERO;
            self.second[i as usize] = Vec3::ZERO;
            self.sphere[i as usize] = u32::MAX;
        }
        self.touching.clear();
    }

    /// Records that particle `i` touches a surface with outward unit `normal`, keeping the
    /// share `kept` of pushes into it; `sphere` is the sphere's index, if it is one.
    #[inline]
    pub(crate) fn record(&mut self, i: usize, normal: Vec3, kept: f32, sphere: Option<usize>) {
        if self.normals[i] == Vec3::ZERO {
            self.touching.push(i as u32);
        }
        self.normals[i] = normal;
        self.kept[i] = kept;
        self.sphere[i] = sphere.map_or(u32::MAX, |k| k as u32);
    }

    /// Coulomb friction for the push the static colliders gave a substep's volume impulses:
    /// `push` is the impulses' net change of momentum, which is not zero only because
    /// `constrain_direction` took out their pushes into what the particles touch. The volume
    /// impulses carry much of a resting body's weight that way, so friction counted on the
    /// contact pass's push alone lets a body slide down a slope its friction should hold.
    /// `push` is shared out over the particles in static contact in proportion to their
    /// contact pass's push (mass times depth), and each loses tangential velocity `v` up to
    /// its friction coefficient times its share over its mass. Returns the change of velocity.
    pub(crate) fn support_friction(
        &self,
        push: Vec3,
        total_weight: f32,
        i: usize,
        v: Vec3,
    ) -> Vec3 {
        let [depth, mu] = self.static_contact[i];
        if depth <= 0.0 || total_weight <= 0.0 {
            return Vec3::ZERO;
        }
        let n = self.normals[i];
        let share = push.dot(n).max(0.0) * depth / total_weight;
        friction_change(v - n * v.dot(n), mu * share)
    }

    /// Whether particle `i` touched another body in this step: another soft body (or its
    /// triangle was touched by one; the substeps' soft-contact passes record the last one's as
    /// `SOFT_CONTACT`, the earlier ones' kept whole, `soft_contacts.rs`) or a rigid body of
    /// another engine (recorded kept whole: the next contact pass hands the push to it).
    pub(crate) fn touched_a_body(&self, i: usize) -> bool {
        self.normals[i] != Vec3::ZERO && (self.sphere[i] == SOFT_CONTACT || self.kept[i] == 1.0)
    }

    /// The weight `support_friction` shares the push out by: the particles' mass times depth
    /// in the static colliders, summed (`masses` the body's).
    pub(crate) fn static_contact_weight(&self, masses: &[f32]) -> f32 {
        self.static_contact
            .iter()
            .zip(masses)
            .map(|(&[depth, _], &m)| m * depth)
            .sum()
    }

    /// The rigid anchors of a snapshot (`anchors`, one per particle) taken back.
    pub(crate) fn restore_rigid_anchors(&mut self, anchors: &[RigidAnchor]) {
        self.rigid_anchors.copy_from_slice(anchors);
        self.rigid_held.clear();
        let held = anchors
            .iter()
            .enumerate()
            .filter(|(_, a)| a.collider != u32::MAX);
        self.rigid_held.extend(held.map(|(i, _)| i as u32));
    }

    /// After a rigid contact pass: the anchors of the particles it found touching no collider
    /// forgotten.
    fn forget_rigid_anchors(&mut self) {
        let (anchors, touched) = (&mut self.rigid_anchors, &mut self.rigid_touched);
        self.rigid_held.retain(|&i| {
            let i = i as usize;
            let keep = std::mem::take(&mut touched[i]);
            if !keep {
                anchors[i] = RigidAnchor::NONE;
            }
            keep
        });
    }
}

/// A body as its contact passes see it; the body lends its parts
/// (`SoftBodyState::contact_body`).
pub(crate) struct ContactBody<'a> {
    pub(crate) positions: &'a [Vec3],
    pub(crate) velocities: &'a mut [Vec3],
    pub(crate) inv_masses: &'a [f32],
    /// The material's friction coefficient.
    pub(crate) friction: f32,
    /// Which colliders the body meets.
    pub(crate) filter: CollisionFilter,
    pub(crate) contacts: &'a mut ContactState,
    pub(crate) chunk_findings: &'a mut [ChunkFindings],
}

impl ContactBody<'_> {
    /// Pushes predicted positions out of static colliders. Returns the number of contacts.
    ///
    /// The particles are run in chunks by `parallel`: each particle's contacts depend on that
    /// particle alone, and the particles
    /// newly in contact are listed in index order as one after another would, so the result
    /// is the same on any number of threads.
    pub(crate) fn resolve_static(
        &mut self,
        h: f32,
        colliders: &[ColliderInstance],
        parallel: &dyn Parallel,
    ) -> u32 {
        if colliders.is_empty() {
            return 0;
        }
        let (friction, filter) = (self.friction, self.filter);
        let n = self.positions.len();
        let (positions, inv_masses) = (self.positions, self.inv_masses);
        // SAFETY: each job reads and writes only its own chunk's particles.
        let velocities = unsafe { SharedSlice::new(self.velocities) };
        let normals = unsafe { SharedSlice::new(&mut self.contacts.normals) };
        let second = unsafe { SharedSlice::new(&mut self.contacts.second) };
        let kept = unsafe { SharedSlice::new(&mut self.contacts.kept) };
        let sphere = unsafe { SharedSlice::new(&mut self.contacts.sphere) };
        let anchors = unsafe { SharedSlice::new(&mut self.contacts.anchors) };
        let static_contact = unsafe { SharedSlice::new(&mut self.contacts.static_contact) };
        let static_normals = unsafe { SharedSlice::new(&mut self.contacts.static_normals) };
        in_particle_chunks(parallel, self.chunk_findings, n, |found, particles| {
            for i in particles {
                if inv_masses[i] == 0.0 {
                    continue;
                }
                let mut touched = false;
                // The deepest other collider the particle touches in this pass, if its
                // surface faces another way than the last one's.
                let mut other = (0.0f32, Vec3::ZERO);
                static_contact.set(i, [0.0; 2]);
                static_normals.set(i, Vec3::ZERO);
                for c in colliders {
                    if !filter.interacts_with(c.filter) {
                        continue;
                    }
                    let x = positions[i];
                    let xp = x + h * velocities.get(i);
                    let Some((depth, normal)) = c.penetration(xp) else {
                        continue;
                    };
                    if touched {
                        let [last_depth, _] = static_contact.get(i);
                        let last = normals.get(i);
                        if last.dot(normal) < DISTINCT_NORMALS && last_depth >= other.0 {
                            other = (last_depth, last);
                        }
                    }
                    touched = true;
                    let v = velocities.get(i) + normal * (depth / h);
                    let mu = combined_friction(friction, c.friction);
                    let (v, anchor) = static_friction(x, v, normal, depth, mu, h, anchors.get(i));
                    velocities.set(i, v);
                    anchors.set(i, anchor);
                    static_contact.set(i, [depth, mu]);
                    static_normals.set(i, normal);
                    // As `ContactState::record`, with the new ones listed by the job.
                    if normals.get(i) == Vec3::ZERO {
                        found.new_touching.push(i as u32);
                    }
                    normals.set(i, normal);
                    kept.set(i, 0.0);
                    sphere.set(i, u32::MAX);
                    found.contacts += 1;
                }
                if touched {
                    second.set(i, other.1);
                } else {
                    anchors.set(i, Vec3::NAN);
                }
            }
        });
        let mut contacts = 0;
        for found in self.chunk_findings.iter_mut() {
            self.contacts
                .touching
                .extend_from_slice(&found.new_touching);
            found.new_touching.clear();
            contacts += std::mem::take(&mut found.contacts);
        }
        contacts
    }

    /// Pushes predicted positions out of the (predicted) rigid spheres, pushing the spheres
    /// back. Returns the number of contacts.
    pub(crate) fn resolve_spheres(&mut self, h: f32, spheres: &mut [RigidSphereState]) -> u32 {
        let mut contacts = 0;
        let friction = self.friction;
        for (k, s) in spheres.iter_mut().enumerate() {
            let reach = s.radius + h * s.velocity.length();
            let centre_now = s.position;
            for i in 0..self.positions.len() {
                let w = self.inv_masses[i];
                if w == 0.0
                    || self.positions[i].distance_squared(centre_now)
                        > (reach + h * self.velocities[i].length()).powi(2)
                {
                    continue;
                }
                let xp = self.positions[i] + h * self.velocities[i];
                let cp = s.position + h * s.velocity;
                let offset = xp - cp;
                let dist = offset.length();
                if dist >= s.radius {
                    continue;
                }
                let n = if dist > 0.0 { offset / dist } else { Vec3::Y };
                let w_sum = w + s.inv_mass;
                // Remove the approach fully, but push out penetration that is already there at
                // a bounded speed: a particle squeezed between a sphere and the ground cannot
                // satisfy both, and full-speed push-outs would pump energy into it each step.
                let existing = (s.radius - self.positions[i].distance(s.position)).max(0.0);
                let correction =
                    (s.radius - dist).min(s.radius - dist - existing + MAX_DEPENETRATION_SPEED * h);
                let lambda = correction / h / w_sum;
                self.velocities[i] += n * (lambda * w);
                s.velocity -= n * (lambda * s.inv_mass);
                let rel = self.velocities[i] - s.velocity;
                let vt = rel - n * rel.dot(n);
                let vt_len = vt.length();
                if vt_len > 0.0 {
                    let jt = (vt_len / w_sum).min(combined_friction(friction, s.friction) * lambda);
                    let t = vt / vt_len;
                    self.velocities[i] -= t * (jt * w);
                    s.velocity += t * (jt * s.inv_mass);
                }
                self.contacts.record(i, n, s.inv_mass / w_sum, Some(k));
                contacts += 1;
            }
        }
        contacts
    }

    /// Pushes predicted positions out of the rigid bodies' colliders where they are `elapsed`
    /// seconds into the step (a substep's start) plus `h`, pushing the bodies (`rigid`) back. Returns the
    /// number of contacts.
    pub(crate) fn resolve_rigid(&mut self, h: f32, elapsed: f32, rigid: &mut RigidContacts) -> u32 {
        if rigid.colliders.is_empty() && rigid.attachments.is_empty() {
            self.contacts.forget_rigid_anchors();
            return 0;
        }
        // Attached particles first: each is taken to its point of the body where both are
        // predicted to be, sharing the impulse by inverse mass (the body's at that point), or
        // pulled there by its spring (XPBD's compliance over the step's length). A body holding
        // `n` particles shows each of them `n` times its inverse mass (mass splitting): one
        // pass of `n` constraints that each took the body for theirs alone would move it `n`
        // times too far, and a light beam holding a heavy bag would spin up.
        for body in rigid.bodies.iter_mut() {
            body.attached = 0;
        }
        for a in &rigid.attachments {
            rigid.bodies[a.body as usize].attached += 1;
        }
        for a in &rigid.attachments {
            let i = a.particle as usize;
            let w = self.inv_masses[i];
            let body = &mut rigid.bodies[a.body as usize];
            let split = body.attached as f32;
            let (target, r) = body.point_at(a.offset, elapsed, h);
            let xp = self.positions[i] + h * self.velocities[i];
            let gap = target - xp;
            let distance = gap.length();
            if distance <= 0.0 || !distance.is_finite() {
                continue;
            }
            let n = gap / distance;
            let inv_mass = w + split * body.inv_mass_along(r, n) + a.compliance / (h * h);
            if inv_mass <= 0.0 {
                continue;
            }
            let lambda = distance / h / inv_mass;
            self.velocities[i] += n * (lambda * w);
            body.apply_impulse(-n * lambda, r, elapsed);
        }
        let (friction, filter) = (self.friction, self.filter);
        let mut contacts = 0;
        for (k, c) in rigid.colliders.iter().enumerate() {
            if !filter.interacts_with(c.filter) {
                continue;
            }
            let body = &mut rigid.bodies[c.body as usize];
            let (pose, centre) = body.advance(&c.pose, elapsed, h);
            let bounds: Aabb = c.shape.compute_aabb(&pose);
            let mu = combined_friction(friction, c.friction);
            for i in 0..self.positions.len() {
                let w = self.inv_masses[i];
                if w == 0.0 {
                    continue;
                }
                let xp = self.positions[i] + h * self.velocities[i];
                if !bounds.contains_local_point(xp) {
                    continue;
                }
                let projection = c.shape.project_point(&pose, xp, false);
                if !projection.is_inside {
                    continue;
                }
                let push = projection.point - xp;
                let depth = push.length();
                if depth <= 0.0 {
                    continue;
                }
                let n = push / depth;
                let r = projection.point - centre;
                // The normal impulse that takes the predicted particle to the surface.
                let lambda = depth / h / (w + body.inv_mass_along(r, n));
                self.velocities[i] += n * (lambda * w);
                body.apply_impulse(-n * lambda, r, elapsed);
                let state = &mut *self.contacts;
                let particle = (self.positions[i], self.velocities[i], w);
                let anchor = state.rigid_anchors[i];
                let (v, anchor_now) = rigid_friction(
                    particle,
                    body,
                    (k as u32, &pose, r),
                    (n, depth, lambda),
                    mu,
                    (h, elapsed),
                    anchor,
                );
                self.velocities[i] = v;
                if anchor.collider == u32::MAX {
                    state.rigid_held.push(i as u32);
                }
                state.rigid_anchors[i] = anchor_now;
                state.rigid_touched[i] = true;
                // The volume passes keep the whole of a push into the body: the next contact
                // pass hands it to the body, so momentum stays conserved.
                state.record(i, n, 1.0, None);
                contacts += 1;
            }
        }
        self.contacts.forget_rigid_anchors();
        contacts
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::Serial;
    use crate::core::body::SoftBodyState;
    use crate::core::colliders::RigidCollider;
    use crate::core::material::SoftBodyMaterial;
    use crate::core::parallel::Threads;
    use glam::{Mat3, Quat, UVec3};
    use parry3d::shape::{Ball, Cuboid, SharedShape};

    /// A rubber cube (1 MPa, 0.5 m) and a jelly cube resting on the ground at 60 Hz stay where
    /// they are: with velocity-only friction the rubber cube crept along, pushed by its own
    /// volume impulses (PERFORMANCE.md). On ice (no friction) nothing pushes it
    /// either: the volume passes and the shape solve conserve momentum, with either volume
    /// method, and 100 m from the origin too, where `f32` positions round coarsest (the shape
    /// solve's velocities are its moves, not differences of positions).
    #[test]
    fn a_resting_body_does_not_walk_across_the_ground() {
        let (near, far) = (Vec3::ZERO, Vec3::new(100.0, 0.0, -100.0));
        let paper = SoftBodyMaterial::RUBBER.with_method(crate::core::VolumeMethod::PAPER_IMPULSES);
        for (material, friction, at) in [
            (SoftBodyMaterial::RUBBER, 0.8, near),
            (SoftBodyMaterial::JELLY, 0.8, near),
            (SoftBodyMaterial::RUBBER, 0.0, near),
            (SoftBodyMaterial::RUBBER, 0.0, far),
            (paper, 0.0, near),
            (paper, 0.0, far),
        ] {
            let ground = [ColliderInstance::new(
                SharedShape::halfspace(Vec3::Y),
                Pose::IDENTITY,
                friction,
            )];
            let mesh = crate::core::box_grid(UVec3::splat(8), Vec3::splat(0.0625), Vec3::ZERO);
            let mut body = SoftBodyState::new(mesh.unwrap().into(), material).unwrap();
            body.set_sleep_settings(None);
            body.translate(at + Vec3::Y * 0.01);
            let g = Vec3::new(0.0, -9.81, 0.0);
            let mut settled = Vec3::ZERO;
            for step in 0..600 {
                body.step_with_contacts(1.0 / 60.0, g, &mut [], &ground, &Serial);
                if step == 119 {
                    settled = body.centre_of_mass();
                }
            }
            let crept = (body.centre_of_mass() - settled).length();
            assert!(
                crept < 2e-3,
                "{material:?} on friction {friction} at {at}: crept {crept} m in 8 s"
            );
        }
    }

    /// A jelly cube resting on the ground against a wall: the particles on the edge between
    /// the two stay put. Its volume impulses may push them into neither surface; with only the
    /// last surface recorded they pushed them into the ground, the ground threw them back and
    /// they kept a vertical velocity of about 0.4 m/s while resting.
    #[test]
    fn particles_on_the_edge_of_two_colliders_rest() {
        let colliders = [Vec3::Y, Vec3::X]
            .map(|n| ColliderInstance::new(SharedShape::halfspace(n), Pose::IDENTITY, 0.8));
        let mesh = crate::core::box_grid(UVec3::splat(6), Vec3::splat(0.05), Vec3::ZERO);
        let mut body = SoftBodyState::new(mesh.unwrap().into(), SoftBodyMaterial::JELLY).unwrap();
        body.set_sleep_settings(None);
        let g = Vec3::new(0.0, -9.81, 0.0);
        let mut fastest = 0.0f32;
        for step in 0..120 {
            body.step_with_contacts(1.0 / 60.0, g, &mut [], &colliders, &Serial);
            if step < 30 {
                continue;
            }
            let edge = body
                .positions()
                .iter()
                .zip(body.velocities())
                .filter(|(x, _)| x.x < 2e-3 && x.y < 2e-3);
            for (_, v) in edge {
                fastest = fastest.max(v.y.abs());
            }
        }
        assert!(fastest < 0.05, "an edge particle moved at {fastest} m/s");
    }

    /// A volume impulse's push at a particle between two surfaces goes into neither: between
    /// a floor and a wall, and in a wedge sharper than a right angle, where taking each push
    /// out in turn leaves one into the first surface.
    #[test]
    fn a_push_between_two_surfaces_goes_into_neither() {
        let floor = Vec3::Y;
        for wall in [Vec3::X, Vec3::new(0.8, -0.6, 0.0)] {
            for d in [
                Vec3::new(-1.0, -1.0, 0.3),
                Vec3::new(-1.0, 0.2, 0.0),
                Vec3::new(0.5, -2.0, -1.0),
            ] {
                let c = crate::core::impulses::constrained_push(d, floor, 0.0, wall);
                assert!(
                    c.dot(floor) >= -1e-6 && c.dot(wall) >= -1e-6,
                    "{d} between {floor} and {wall} became {c}"
                );
            }
        }
    }

    /// Particles in chunks on several threads meet the static colliders as on one thread:
    /// the same velocities, contact normals, order in which particles came into contact, and
    /// positions after integration, bit for bit.
    #[test]
    fn contacts_and_integration_in_chunks_do_not_depend_on_the_threads() {
        let mesh = crate::core::box_grid(
            UVec3::new(20, 2, 20),
            Vec3::splat(0.1),
            Vec3::new(-1.0, -0.05, -1.0),
        )
        .unwrap();
        let n = mesh.vertex_count();
        assert!(
            n > 4 * crate::core::chunks::PARTICLE_CHUNK,
            "several chunks: {n} particles"
        );
        let colliders = [
            ColliderInstance::new(SharedShape::halfspace(Vec3::Y), Pose::IDENTITY, 0.5),
            ColliderInstance::new(
                SharedShape::new(Ball::new(0.4)),
                Pose::from_parts(Vec3::new(0.3, 0.3, -0.2), Quat::IDENTITY),
                0.8,
            ),
        ];
        let mesh: std::sync::Arc<_> = mesh.into();
        let run = |parallel: &dyn Parallel| {
            let mut body = SoftBodyState::new(mesh.clone(), SoftBodyMaterial::default()).unwrap();
            let mut contacts = Vec::new();
            for step in 0..3 {
                body.begin_step();
                for (i, v) in body.velocities_mut().iter_mut().enumerate() {
                    let k = (i * 7 + step * 3) % 11;
                    *v = Vec3::new(k as f32 - 5.0, 3.0 - k as f32, 0.5 * k as f32 - 2.0);
                }
                contacts.push(body.resolve_static_contacts(0.01, &colliders, parallel));
                // Listed in index order, as one particle after another finds them.
                let listed: Vec<usize> = body.contacts().map(|(i, _)| i).collect();
                assert!(listed.is_sorted(), "{listed:?}");
                contacts.push(body.resolve_static_contacts(0.01, &colliders, parallel));
                body.integrate_positions(0.01, parallel);
            }
            let touching: Vec<(usize, Vec3)> = body.contacts().collect();
            (
                body.positions().to_vec(),
                body.velocities().to_vec(),
                touching,
                contacts,
            )
        };
        let serial = run(&Serial);
        assert!(serial.3.iter().all(|&c| c > 50), "contacts: {:?}", serial.3);
        // The ball is met too, not only the ground.
        assert!(serial.2.iter().any(|(_, normal)| normal.y < 0.99));
        assert_eq!(run(&Threads), serial);
    }

    /// The half-space shortcut answers what parry's point projection answers, for a ground
    /// turned and moved away from the origin.
    #[test]
    fn a_half_space_is_answered_as_parry_answers_it() {
        let pose = Pose::from_parts(
            Vec3::new(0.3, -1.2, 2.0),
            Quat::from_rotation_x(0.4) * Quat::from_rotation_z(-0.7),
        );
        let plane = ColliderInstance::new(SharedShape::halfspace(Vec3::Y), pose, 0.5);
        assert!(plane.plane.is_some());
        let mut seed = 5u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 40) as f32) / ((1u64 << 24) as f32) * 8.0 - 4.0
        };
        let mut inside = 0;
        for _ in 0..2000 {
            let point = Vec3::new(next(), next(), next());
            let projection = plane.shape.project_point(&plane.pose, point, false);
            // The push out of the collider: parry's normal is its push divided by the depth,
            // which rounding bends for shallow points; the push itself is what the contact uses.
            let from_parry = projection.is_inside.then(|| projection.point - point);
            match (plane.penetration(point), from_parry) {
                (Some((depth, normal)), Some(push)) => {
                    inside += 1;
                    assert!(
                        (normal * depth).distance(push) < 1e-5,
                        "{point}: {} vs {push}",
                        normal * depth
                    );
                }
                (None, None) => {}
                // A point within rounding of the plane may fall either way.
                (ours, parry) => assert!(
                    ours.map(|(depth, _)| depth)
                        .or(parry.map(Vec3::length))
                        .is_some_and(|depth| depth < 1e-5),
                    "{point}: {ours:?} vs {parry:?}"
                ),
            }
        }
        assert!(inside > 500, "{inside} points inside");
    }

    /// The momentum of a soft body and a rigid crate (linear, and angular about the origin)
    /// before and after one contact pass with an off-centre, tilted, spinning crate pressed into
    /// the body: the pass only moves momentum between them. The angular part is kept up to the
    /// distance between a particle and its contact point times the impulse (the impulse acts on
    /// the particle where it is, on the crate at its surface).
    #[test]
    fn contacts_with_a_rigid_body_conserve_momentum() {
        let mesh = crate::core::box_grid(UVec3::splat(4), Vec3::splat(0.1), Vec3::ZERO).unwrap();
        let mut body = SoftBodyState::new(mesh.into(), SoftBodyMaterial::JELLY).unwrap();
        body.velocities_mut().fill(Vec3::new(0.1, 0.5, 0.0));
        let half = Vec3::new(0.2, 0.1, 0.15);
        let mass = 3.0;
        let inertia = Vec3::new(
            half.y * half.y + half.z * half.z,
            half.x * half.x + half.z * half.z,
            half.x * half.x + half.y * half.y,
        ) * (mass / 3.0);
        let rotation = Quat::from_rotation_z(0.3) * Quat::from_rotation_x(0.2);
        let rot = Mat3::from_quat(rotation);
        let centre = Vec3::new(0.3, 0.45, 0.2);
        let crate_motion = RigidBodyMotion {
            linear_velocity: Vec3::new(0.0, -2.0, 0.3),
            angular_velocity: Vec3::new(1.0, 0.0, -2.0),
            inv_mass: 1.0 / mass,
            inv_inertia: rot * Mat3::from_diagonal(inertia.recip()) * rot.transpose(),
            ..RigidBodyMotion::kinematic(centre, Vec3::ZERO, Vec3::ZERO)
        };
        let rigid = body.rigid_contacts_mut();
        rigid.bodies.push(crate_motion);
        rigid.colliders.push(RigidCollider {
            body: 0,
            shape: SharedShape::new(Cuboid::new(half)),
            pose: Pose::from_parts(centre, rotation),
            friction: 0.6,
            filter: CollisionFilter::ALL,
        });
        let momentum = |body: &SoftBodyState| {
            let motion = body.rigid_contacts().bodies[0];
            let inertia_world = motion.inv_inertia.inverse();
            let mut linear = motion.linear_velocity * mass;
            let mut angular = inertia_world * motion.angular_velocity
                + motion.centre_of_mass.cross(motion.linear_velocity * mass);
            for ((&x, &v), &m) in body
                .positions()
                .iter()
                .zip(body.velocities())
                .zip(body.masses())
            {
                linear += m * v;
                angular += x.cross(m * v);
            }
            (linear, angular)
        };
        let (linear0, angular0) = momentum(&body);
        let h = 0.01;
        let contacts = body.resolve_rigid_contacts(h, 0.0);
        assert!(contacts > 5, "{contacts} contacts");
        let (linear1, angular1) = momentum(&body);
        let motion = body.rigid_contacts().bodies[0];
        let transferred = (motion.linear_velocity - crate_motion.linear_velocity).length() * mass;
        assert!(
            transferred > 0.5,
            "the crate was slowed by {transferred} N s"
        );
        assert!(
            (linear1 - linear0).length() < 1e-4 * transferred,
            "linear momentum {linear0} -> {linear1}"
        );
        let turned = (motion.angular_velocity - crate_motion.angular_velocity).length();
        assert!(turned > 0.1, "the crate's spin changed by {turned} rad/s");
        // Particle-to-contact distance: at most the depth plus the particle's motion in h.
        let lever = 0.1 + h * 2.5;
        assert!(
            (angular1 - angular0).length() < lever * transferred,
            "angular momentum {angular0} -> {angular1}"
        );
    }
}
