//! What a soft body collides with: static colliders (any parry shape), rigid bodies another
//! engine simulates (avian3d's, through the `avian` feature: [`RigidContacts`]), and the dynamic rigid
//! spheres the plugin simulates, with the spheres' own motion (gravity, contacts with static
//! colliders) and the Coulomb friction both use (the combined friction of two surfaces is
//! the geometric mean of their coefficients). The particles' contacts with them are in
//! `contacts.rs`.

use glam::{Mat3, Quat, Vec3};
use parry3d::bounding_volume::Aabb;
use parry3d::math::Pose;
use parry3d::query::contact;
use parry3d::shape::{Ball, SharedShape};

/// A static collider as the contact stage sees it.
#[derive(Clone)]
pub struct ColliderInstance {
    /// Its shape.
    pub shape: SharedShape,
    /// Its pose in the world.
    pub pose: Pose,
    /// Its world bounds (from [`ColliderInstance::new`]), to skip far particles cheaply.
    pub aabb: Aabb,
    /// Its friction coefficient.
    pub friction: f32,
    /// For a half-space (the usual ground), its world outward normal `n` and offset `n . o`
    /// of its plane: its bounds hold every particle, and a dot product answers what a
    /// point projection through `dyn Shape` answers at several times the cost.
    pub(crate) plane: Option<(Vec3, f32)>,
    /// The soft bodies it meets.
    pub filter: CollisionFilter,
    /// Whether it cuts the bodies that may tear: the faces between two of their tets whose
    /// centres lie on either side of it crack (`tearing.rs`).
    pub cuts: bool,
}

/// Which soft bodies a collider meets, as avian's collision layers: two interact when each
/// one's memberships meet the other's filters. [`CollisionFilter::ALL`] meets everything.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CollisionFilter {
    /// The layers it belongs to (a bit each).
    pub memberships: u32,
    /// The layers it meets.
    pub filters: u32,
}

impl CollisionFilter {
    /// In every layer, meeting every layer.
    pub const ALL: CollisionFilter = CollisionFilter {
        memberships: u32::MAX,
        filters: u32::MAX,
    };

    /// Whether `self` and `other` meet.
    #[inline]
    pub fn interacts_with(self, other: CollisionFilter) -> bool {
        self.memberships & other.filters != 0 && other.memberships & self.filters != 0
    }
}

impl Default for CollisionFilter {
    fn default() -> Self {
        CollisionFilter::ALL
    }
}

impl ColliderInstance {
    /// A collider of `shape` at `pose`.
    pub fn new(shape: SharedShape, pose: Pose, friction: f32) -> Self {
        let plane = shape.as_halfspace().map(|half_space| {
            let normal = pose.rotation * half_space.normal;
            (normal, normal.dot(pose.translation))
        });
        ColliderInstance {
            aabb: shape.compute_aabb(&pose),
            shape,
            pose,
            friction,
            plane,
            filter: CollisionFilter::ALL,
            cuts: false,
        }
    }

    /// This collider meeting only the soft bodies that `filter` meets.
    pub fn with_filter(mut self, filter: CollisionFilter) -> Self {
        self.filter = filter;
        self
    }

    /// How far `point` is inside this collider and the outward normal there, if it is inside.
    #[inline]
    pub(crate) fn penetration(&self, point: Vec3) -> Option<(f32, Vec3)> {
        if let Some((normal, offset)) = self.plane {
            let depth = offset - normal.dot(point);
            return (depth > 0.0).then_some((depth, normal));
        }
        if !self.aabb.contains_local_point(point) {
            return None;
        }
        let projection = self.shape.project_point(&self.pose, point, false);
        if !projection.is_inside {
            return None;
        }
        let delta = projection.point - point;
        let depth = delta.length();
        (depth > 0.0).then(|| (depth, delta / depth))
    }
}

/// A dynamic rigid sphere as the solver sees it: it does not rotate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidSphereState {
    /// Centre.
    pub position: Vec3,
    /// Velocity of the centre.
    pub velocity: Vec3,
    /// Radius.
    pub radius: f32,
    /// Inverse mass (zero: immovable).
    pub inv_mass: f32,
    /// Friction coefficient.
    pub friction: f32,
}

#[inline]
pub(crate) fn combined_friction(a: f32, b: f32) -> f32 {
    (a * b).sqrt()
}

/// Removes tangential velocity `vt` up to `limit`.
#[inline]
pub(crate) fn friction_change(vt: Vec3, limit: f32) -> Vec3 {
    let len = vt.length();
    if len > 0.0 {
        -vt * (limit.min(len) / len)
    } else {
        Vec3::ZERO
    }
}

impl RigidSphereState {
    /// Gravity on the sphere (stage 1).
    pub fn apply_forces(&mut self, h: f32, gravity: Vec3) {
        if self.inv_mass > 0.0 {
            self.velocity += h * gravity;
        }
    }

    /// Pushes the predicted sphere out of static colliders. Returns the number of contacts.
    pub(crate) fn resolve_static_contacts(
        &mut self,
        h: f32,
        colliders: &[ColliderInstance],
    ) -> u32 {
        if self.inv_mass == 0.0 {
            return 0;
        }
        let ball = Ball::new(self.radius);
        let mut contacts = 0;
        for c in colliders {
            let pose = Pose::from_translation(self.position + h * self.velocity);
            // Unsupported shape pairs cannot occur for a ball against parry's shapes; if one
            // does, the sphere passes through that collider rather than stopping the game.
            let Ok(Some(hit)) = contact(&c.pose, &*c.shape, &pose, &ball, 0.0) else {
                continue;
            };
            if hit.dist >= 0.0 {
                continue;
            }
            let n = hit.normal1;
            let dvn = -hit.dist / h;
            let mut v = self.velocity + n * dvn;
            let vt = v - n * v.dot(n);
            v += friction_change(vt, combined_friction(self.friction, c.friction) * dvn);
            self.velocity = v;
            contacts += 1;
        }
        contacts
    }

    /// `x += h v`.
    pub fn integrate_position(&mut self, h: f32) {
        self.position += h * self.velocity;
    }
}

/// How a rigid body moves during a step, as the contacts see it: at its centre of mass, in the
/// world frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidBodyMotion {
    /// Centre of mass at the start of the step.
    pub centre_of_mass: Vec3,
    /// Velocity of the centre of mass.
    pub linear_velocity: Vec3,
    /// Angular velocity (radians per second about the world axes).
    pub angular_velocity: Vec3,
    /// Inverse mass; zero for a body nothing pushes (static, kinematic).
    pub inv_mass: f32,
    /// Inverse inertia tensor in the world frame; zero for a body nothing turns.
    pub inv_inertia: Mat3,
    /// The acceleration the other engine gives the body over this step (its gravity), already
    /// in `linear_velocity`: a soft body solved in substeps hands it out per substep, as to
    /// its particles, so that a body resting on it is held by the same substeps.
    pub gravity: Vec3,
    /// Whether the other engine has put the body to sleep: it wakes if a contact changes its
    /// velocity enough, but does not keep a soft body under it awake.
    pub asleep: bool,
    /// Set by the step: where the body's path within the step, as the contacts moved it, ends
    /// against where its velocity after the step takes it (`h v`). A change of velocity `dv`
    /// at `t` seconds into the step moves the body `(h - t) dv` by the end, where `h v` counts
    /// `h dv`: this is `-t dv` summed over the contacts' impulses (the body's gravity, which
    /// the engine moving it gives it its own way, left out). Whoever moves the body over the
    /// step adds it (`x += h v + position_correction`; the avian glue does): the particles
    /// that touched the body were moved along that path, and with `x += h v` alone a crate
    /// resting on a jelly crept across it.
    pub position_correction: Vec3,
    /// The same for its rotation (a scaled axis, in radians, about the centre of mass).
    pub rotation_correction: Vec3,
    /// How many particles are attached to the body in this pass (scratch of the contacts).
    pub(crate) attached: u32,
}

impl RigidBodyMotion {
    /// A body that moves at `linear_velocity` and `angular_velocity` whatever touches it.
    pub fn kinematic(centre_of_mass: Vec3, linear_velocity: Vec3, angular_velocity: Vec3) -> Self {
        RigidBodyMotion {
            centre_of_mass,
            linear_velocity,
            angular_velocity,
            inv_mass: 0.0,
            inv_inertia: Mat3::ZERO,
            gravity: Vec3::ZERO,
            asleep: false,
            position_correction: Vec3::ZERO,
            rotation_correction: Vec3::ZERO,
            attached: 0,
        }
    }

    /// Velocity of the body's point at offset `r` from its centre of mass.
    #[inline]
    pub fn velocity_at(&self, r: Vec3) -> Vec3 {
        self.linear_velocity + self.angular_velocity.cross(r)
    }

    /// The inverse mass the body shows to an impulse along unit `direction` at offset `r`.
    #[inline]
    pub(crate) fn inv_mass_along(&self, r: Vec3, direction: Vec3) -> f32 {
        let arm = r.cross(direction);
        self.inv_mass + arm.dot(self.inv_inertia * arm)
    }

    /// Applies `impulse` at offset `r` from the centre of mass, `elapsed` seconds into the
    /// step (see `position_correction`).
    #[inline]
    pub(crate) fn apply_impulse(&mut self, impulse: Vec3, r: Vec3, elapsed: f32) {
        let linear = self.inv_mass * impulse;
        let angular = self.inv_inertia * r.cross(impulse);
        self.linear_velocity += linear;
        self.angular_velocity += angular;
        self.position_correction -= elapsed * linear;
        self.rotation_correction -= elapsed * angular;
    }

    /// The body's turn and the centre of mass's offset at the end of a substep of `h` that
    /// starts `elapsed` seconds into the step, on its path within the step: its velocity now
    /// over the whole time, less what the contacts' impulses and the substeps' gravity (`h
    /// gravity` at each substep's start, `j h` seconds into the step) would have moved it
    /// before they came.
    #[inline]
    fn moved(&self, elapsed: f32, h: f32) -> (Quat, Vec3) {
        let t = elapsed + h;
        let turn = Quat::from_scaled_axis(self.angular_velocity * t + self.rotation_correction);
        let gravity_lag = self.gravity * (elapsed * t / 2.0);
        (
            turn,
            t * self.linear_velocity + self.position_correction - gravity_lag,
        )
    }

    /// Where the body's point at `offset` from its centre of mass at the step's start is `h`
    /// seconds after `elapsed` (a substep's start), and its offset from the centre of mass then.
    #[inline]
    pub(crate) fn point_at(&self, offset: Vec3, elapsed: f32, h: f32) -> (Vec3, Vec3) {
        let (turn, moved) = self.moved(elapsed, h);
        let turned = turn * offset;
        (self.centre_of_mass + moved + turned, turned)
    }

    /// Where a frame at `pose` at the step's start is `h` seconds after `elapsed` (a substep's
    /// start), and where the centre of mass is then.
    #[inline]
    pub(crate) fn advance(&self, pose: &Pose, elapsed: f32, h: f32) -> (Pose, Vec3) {
        let (turn, moved) = self.moved(elapsed, h);
        let centre = self.centre_of_mass + moved;
        let translation = centre + turn * (pose.translation - self.centre_of_mass);
        let pose = Pose::from_parts(translation, (turn * pose.rotation).normalize());
        (pose, centre)
    }
}

/// A collider on a [`RigidBodyMotion`].
#[derive(Clone)]
pub struct RigidCollider {
    /// Index of its body in [`RigidContacts::bodies`].
    pub body: u32,
    /// Its shape (scaled).
    pub shape: SharedShape,
    /// Its pose in the world at the start of the step.
    pub pose: Pose,
    /// Its friction coefficient.
    pub friction: f32,
    /// The soft bodies it meets.
    pub filter: CollisionFilter,
}

/// The rigid bodies a soft body may touch in a step and their colliders: given by the game or
/// the avian glue before the step (`SoftBodyState::rigid_contacts_mut`), their velocities read
/// back after it.
#[derive(Clone, Default)]
pub struct RigidContacts {
    /// The bodies' motions; the contacts change their velocities.
    pub bodies: Vec<RigidBodyMotion>,
    /// Their colliders.
    pub colliders: Vec<RigidCollider>,
    /// Particles attached to the bodies.
    pub attachments: Vec<RigidAttachment>,
}

/// A particle attached to a point of a rigid body: held there (`compliance` zero) or pulled
/// there by a spring of stiffness `1 / compliance`, two-way: the body is pulled back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidAttachment {
    /// The particle.
    pub particle: u32,
    /// Index of the body in [`RigidContacts::bodies`].
    pub body: u32,
    /// The point it is attached to, from the body's centre of mass at the start of the step
    /// (world axes).
    pub offset: Vec3,
    /// Compliance (metres per newton); zero holds the particle on the point.
    pub compliance: f32,
}

impl RigidContacts {
    /// Removes every body, collider and attachment (keeping the buffers).
    pub fn clear(&mut self) {
        self.bodies.clear();
        self.colliders.clear();
        self.attachments.clear();
    }

    /// Whether any body here could push the soft body or be pushed by it (a sleeping one
    /// cannot, until something wakes it).
    pub(crate) fn any_moving(&self) -> bool {
        self.bodies.iter().any(|b| {
            !b.asleep
                && (b.inv_mass > 0.0
                    || b.linear_velocity != Vec3::ZERO
                    || b.angular_velocity != Vec3::ZERO)
        })
    }

    /// Whether `end` lies inside a collider where it is `t` seconds into the step.
    pub(crate) fn meets(&self, end: Vec3, t: f32) -> bool {
        self.colliders.iter().any(|c| {
            let (pose, _) = self.bodies[c.body as usize].advance(&c.pose, 0.0, t);
            c.shape.compute_aabb(&pose).contains_local_point(end)
                && c.shape.project_point(&pose, end, false).is_inside
        })
    }
}

impl std::fmt::Debug for RigidContacts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RigidContacts")
            .field("bodies", &self.bodies)
            .field("colliders", &self.colliders.len())
            .field("attachments", &self.attachments)
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Within a step the contacts see a rigid body where its path takes it: each substep's
    /// gravity and each contact impulse moves it on from then, not from the step's start
    /// (`RigidBodyMotion::position_correction`). A body given its gravity per substep and an
    /// impulse in every substep is met, substep after substep, where moving it `h_s v` at a
    /// time puts it, turned as turning it `h_s w` at a time does.
    #[test]
    fn a_rigid_body_is_met_along_its_path_within_the_step() {
        let (h, substeps) = (1.0 / 60.0, 10);
        let hs = h / substeps as f32;
        let start = Pose::from_parts(Vec3::new(0.3, 1.0, -0.2), Quat::from_rotation_y(0.4));
        let mut body = RigidBodyMotion {
            inv_mass: 0.5,
            inv_inertia: Mat3::from_diagonal(Vec3::new(3.0, 2.0, 4.0)),
            gravity: Vec3::new(0.0, -9.81, 0.0),
            ..RigidBodyMotion::kinematic(start.translation, Vec3::new(1.0, 2.0, 0.5), Vec3::Y)
        };
        // As the step plans its substeps: the step's gravity taken back, to hand out per substep.
        body.linear_velocity -= h * body.gravity;
        let (mut centre, mut turn) = (start.translation, start.rotation);
        for k in 0..substeps {
            let elapsed = k as f32 * hs;
            body.linear_velocity += hs * body.gravity;
            let (pose, at) = body.advance(&start, elapsed, hs);
            let (path, path_turn) = (
                centre + hs * body.linear_velocity,
                Quat::from_scaled_axis(hs * body.angular_velocity) * turn,
            );
            assert!(
                at.distance(path) < 1e-5,
                "substep {k}: met at {at}, on its path at {path}"
            );
            assert!(
                pose.rotation.angle_between(path_turn) < 1e-3,
                "substep {k}: turned {:?}, on its path {path_turn:?}",
                pose.rotation
            );
            let impulse = Vec3::new(0.3, 1.0 + k as f32, -0.2 * k as f32);
            body.apply_impulse(impulse, Vec3::new(0.1, -0.2, 0.05), elapsed);
            centre += hs * body.linear_velocity;
            turn = Quat::from_scaled_axis(hs * body.angular_velocity) * turn;
        }
    }
}
