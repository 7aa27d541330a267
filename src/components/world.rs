//! What soft bodies meet: gravity, the plugin's rigid spheres and static colliders.

use bevy::prelude::*;
use parry3d::shape::SharedShape;

/// A dynamic rigid sphere, simulated by the plugin and two-way coupled to soft bodies by
/// contact impulses: a heavy sphere dents a body and is slowed by it. Its position is its
/// entity's [`Transform`] translation. It does not rotate, and spheres do not collide with
/// each other.
#[derive(Component, Clone, Debug, Reflect)]
#[reflect(Component)]
#[require(Transform)]
pub struct RigidSphere {
    /// Radius.
    pub radius: f32,
    /// Mass; `f32::INFINITY` makes an immovable (kinematic) sphere.
    pub mass: f32,
    /// Linear velocity.
    pub velocity: Vec3,
    /// Coulomb friction coefficient.
    pub friction: f32,
}

impl RigidSphere {
    /// A sphere at rest with friction 0.5.
    pub fn new(radius: f32, mass: f32) -> Self {
        RigidSphere {
            radius,
            mass,
            velocity: Vec3::ZERO,
            friction: 0.5,
        }
    }
}

/// A static collider of any parry shape, posed by its entity's [`Transform`] (translation and
/// rotation; parry shapes carry their own size, so scale is ignored).
#[derive(Component, Clone)]
#[require(Transform)]
pub struct StaticCollider {
    /// The shape.
    pub shape: SharedShape,
    /// Coulomb friction coefficient.
    pub friction: f32,
}

impl StaticCollider {
    /// An infinite ground plane through the entity's translation, facing its local +Y.
    pub fn ground(friction: f32) -> Self {
        StaticCollider {
            shape: SharedShape::halfspace(Vec3::Y),
            friction,
        }
    }

    /// Any parry shape.
    pub fn new(shape: SharedShape, friction: f32) -> Self {
        StaticCollider { shape, friction }
    }
}

/// Marks a [`StaticCollider`] (a blade, a wire) that cuts the soft bodies that may tear
/// (`SoftBodyTearing`): the faces between two of their tets whose centres lie on either side of
/// it crack, and the body comes apart along it, as a knife parts flesh rather than pushing it
/// aside. Move the collider's transform to slice.
#[derive(Component, Clone, Copy, Debug, Default, Reflect)]
#[reflect(Component)]
#[require(StaticCollider::new(SharedShape::cuboid(0.001, 0.1, 0.1), 0.0))]
pub struct SoftBodyCutter;

/// Gravity for every soft body and rigid sphere.
#[derive(Resource, Clone, Copy, Debug, Reflect)]
#[reflect(Resource)]
pub struct SoftBodyGravity(pub Vec3);

impl Default for SoftBodyGravity {
    fn default() -> Self {
        SoftBodyGravity(Vec3::new(0.0, -9.81, 0.0))
    }
}
