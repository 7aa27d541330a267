//! What a soft body collides with: static colliders (any parry shape) and the dynamic rigid
//! spheres the plugin simulates, with the spheres' own motion (gravity, contacts with static
//! colliders) and the Coulomb friction both use (the combined friction of two surfaces is
//! the geometric mean of their coefficients). The particles' contacts with them are in
//! `contacts.rs`.

use glam::Vec3;
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
        }
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
    pub fn resolve_static_contacts(&mut self, h: f32, colliders: &[ColliderInstance]) -> u32 {
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
