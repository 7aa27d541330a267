//! Soft bodies in an avian3d world (feature `avian`): particles meet every avian [`Collider`],
//! and dynamic rigid bodies get the contacts' impulses back.
//!
//! What each side simulates: avian moves its rigid bodies (gravity, their contacts with each
//! other, joints); this crate moves the soft bodies and their contacts with avian's colliders.
//! A soft body is not an avian collider: avian's own queries (ray casts, its contact events)
//! do not see it.
//!
//! Order within one fixed tick: the soft-body step runs first (in [`FixedUpdate`] by default,
//! or before [`PhysicsSystems::First`] when both run in one schedule), then avian's step (in
//! [`FixedPostUpdate`] by default). The soft step reads each rigid body's pose and velocity as
//! avian left them, predicts a dynamic body's velocity with the gravity avian is about to give
//! it (so a crate resting on a jelly is held up in the same tick, with no lag), exchanges
//! impulses with the bodies as particles touch their colliders (`core::contacts`), and adds the
//! resulting change of each body's linear and angular velocity to its [`LinearVelocity`] and
//! [`AngularVelocity`] before avian steps. Both use `Time<Fixed>`: the plugin's
//! [`SoftBodyPlugin::time_step`](crate::SoftBodyPlugin::time_step) sets avian's rate too.
//!
//! Static colliders (on a [`RigidBody::Static`] or on no body) are met as the plugin's own
//! static colliders (with static friction); dynamic and kinematic bodies' colliders near a soft
//! body are copied into its `RigidContacts` each step. Avian's [`CollisionLayers`] on a soft
//! body's entity filter what it meets, as for avian's colliders; sensors and disabled colliders
//! and bodies are left out. Friction is the collider's [`Friction`] (dynamic coefficient, or
//! avian's [`DefaultFriction`]) combined with the soft material's. Soft bodies fall with avian's
//! [`Gravity`] when avian's plugins are present.

use avian3d::prelude::*;
use bevy::ecs::schedule::{InternedScheduleLabel, ScheduleLabel};
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use glam::Mat3;
use parry3d::bounding_volume::{Aabb, BoundingVolume};
use parry3d::math::Pose;

use crate::components::{SoftBody, SoftBodyGravity};
use crate::core::{ColliderInstance, CollisionFilter, RigidBodyMotion, RigidCollider};
use crate::plugin::{SoftBodySystems, SoftBodyTiming, SolverSpheres};

/// A sleeping avian body is woken only by a change of its velocity above this (m/s, or rad/s):
/// smaller pushes from a soft body at rest beneath it are rounding, not a disturbance.
pub const WAKE_SPEED: f32 = 1e-2;

/// The avian rigid bodies of the current step, by the index `SolverSpheres::rigid` uses.
#[derive(Resource, Default)]
pub struct AvianBodies {
    /// Their entities.
    entities: Vec<Entity>,
    /// Their motion as the step started (a dynamic body's velocity with this step's gravity).
    start: Vec<RigidBodyMotion>,
    /// Whether each was asleep.
    sleeping: Vec<bool>,
    /// The dynamic and kinematic bodies' colliders, with their world bounds over the step.
    colliders: Vec<(RigidCollider, Aabb)>,
    /// Body entity to index, rebuilt each step.
    index: HashMap<Entity, u32>,
}

/// Soft bodies among avian's rigid bodies (see the module's documentation). In
/// [`SoftBodyPlugins`](crate::SoftBodyPlugins) when the `avian` feature is on; it goes after
/// [`SoftBodyPlugin`](crate::SoftBodyPlugin), whose schedule it runs in.
pub struct SoftBodyAvianPlugin;

impl Plugin for SoftBodyAvianPlugin {
    fn build(&self, app: &mut App) {
        let schedule = app
            .world()
            .get_resource::<SoftBodyTiming>()
            .map_or(FixedUpdate.intern(), |timing| timing.schedule);
        build(app, schedule);
    }
}

/// Adds the avian systems to `schedule`, the soft bodies' schedule.
fn build(app: &mut App, schedule: InternedScheduleLabel) {
    app.init_resource::<AvianBodies>();
    app.configure_sets(
        schedule,
        SoftBodySystems::Writeback.before(PhysicsSystems::First),
    );
    app.add_systems(
        schedule,
        (follow_avian_gravity, gather_avian)
            .chain()
            .in_set(SoftBodySystems::Prepare)
            .after(crate::plugin::gather_spheres),
    );
    app.add_systems(
        schedule,
        write_back_to_avian.in_set(SoftBodySystems::Writeback),
    );
}

/// Soft bodies fall with avian's gravity.
fn follow_avian_gravity(gravity: Option<Res<Gravity>>, mut ours: ResMut<SoftBodyGravity>) {
    if let Some(gravity) = gravity
        && ours.0 != gravity.0
    {
        ours.0 = gravity.0;
    }
}

/// The filter of avian's collision layers.
fn filter_of(layers: Option<&CollisionLayers>) -> CollisionFilter {
    let layers = layers.copied().unwrap_or_default();
    CollisionFilter {
        memberships: layers.memberships.0,
        filters: layers.filters.0,
    }
}

type AvianRigidBody<'a> = (
    Entity,
    &'a RigidBody,
    &'a Position,
    &'a Rotation,
    &'a LinearVelocity,
    &'a AngularVelocity,
    &'a ComputedMass,
    &'a ComputedAngularInertia,
    &'a ComputedCenterOfMass,
    Option<&'a GravityScale>,
    Has<Sleeping>,
);

type AvianCollider<'a> = (
    &'a Collider,
    Option<&'a ColliderOf>,
    Option<&'a ColliderTransform>,
    Option<&'a CollisionLayers>,
    Option<&'a Friction>,
    &'a GlobalTransform,
);

/// The colliders a soft body can meet: not sensors, not disabled, not a soft body's.
type MetColliders = (
    Without<Sensor>,
    Without<ColliderDisabled>,
    Without<SoftBody>,
);

/// Gathers avian's colliders for the step: static ones into the solver's static colliders,
/// dynamic and kinematic bodies into `SolverSpheres::rigid`, and into each soft body's
/// `RigidContacts` the colliders near it that its layers meet.
#[allow(clippy::too_many_arguments)]
fn gather_avian(
    time: Res<Time>,
    gravity: Option<Res<Gravity>>,
    default_friction: Option<Res<DefaultFriction>>,
    mut avian: ResMut<AvianBodies>,
    mut solver: ResMut<SolverSpheres>,
    rigid_bodies: Query<AvianRigidBody, Without<RigidBodyDisabled>>,
    colliders: Query<AvianCollider, MetColliders>,
    mut soft: Query<(&mut SoftBody, Option<&CollisionLayers>)>,
) {
    let h = time.delta_secs();
    let avian = &mut *avian;
    avian.entities.clear();
    avian.start.clear();
    avian.sleeping.clear();
    avian.colliders.clear();
    avian.index.clear();
    solver.rigid.clear();
    let g = gravity.map_or(Vec3::ZERO, |g| g.0);
    for (entity, kind, position, rotation, v, w, mass, inertia, com, scale, sleeping) in
        &rigid_bodies
    {
        if kind.is_static() {
            continue;
        }
        let dynamic = kind.is_dynamic();
        let turn = Mat3::from_quat(rotation.0);
        let mut motion = RigidBodyMotion::kinematic(position.0 + rotation.0 * com.0, v.0, w.0);
        if dynamic {
            motion.inv_mass = mass.inverse();
            motion.inv_inertia = turn * inertia.inverse().to_mat3() * turn.transpose();
            if !sleeping {
                motion.gravity = g * scale.map_or(1.0, |s| s.0);
                motion.linear_velocity += h * motion.gravity;
            }
        }
        avian.index.insert(entity, avian.entities.len() as u32);
        avian.entities.push(entity);
        avian.start.push(motion);
        avian.sleeping.push(sleeping);
    }
    solver.rigid.extend_from_slice(&avian.start);
    let default_friction = default_friction.map_or(0.5, |f| f.dynamic_coefficient);
    for (collider, of, local, layers, friction, global) in &colliders {
        let friction = friction.map_or(default_friction, |f| f.dynamic_coefficient);
        let filter = filter_of(layers);
        let shape = collider.shape_scaled().clone();
        let on_body = of.and_then(|of| Some((*avian.index.get(&of.body)?, of.body)));
        match (on_body, local) {
            (Some((k, body)), Some(local)) => {
                let Ok((_, _, position, rotation, ..)) = rigid_bodies.get(body) else {
                    continue;
                };
                let pose = Pose::from_parts(
                    position.0 + rotation.0 * local.translation,
                    (rotation.0 * local.rotation.0).normalize(),
                );
                let motion = &avian.start[k as usize];
                let end = motion.advance(&pose, h).0;
                let bounds = shape.compute_aabb(&pose).merged(&shape.compute_aabb(&end));
                avian.colliders.push((
                    RigidCollider {
                        body: k,
                        shape,
                        pose,
                        friction,
                        filter,
                    },
                    bounds,
                ));
            }
            _ => {
                let (_, rotation, translation) = global.to_scale_rotation_translation();
                let pose = Pose::from_parts(translation, rotation);
                solver
                    .colliders
                    .push(ColliderInstance::new(shape, pose, friction).with_filter(filter));
            }
        }
    }
    for (mut body, layers) in &mut soft {
        let body = &mut *body;
        let filter = filter_of(layers);
        body.state.set_collision_filter(filter);
        // Room for the speed the step's gravity and contacts may add.
        let reach = body.state.swept_bounds(h).map(|b| b.loosened(h * 5.0));
        let rigid = body.state.rigid_contacts_mut();
        rigid.clear();
        body.rigid_ids.clear();
        let Some(reach) = reach.filter(|_| body.placed && !avian.colliders.is_empty()) else {
            continue;
        };
        for (collider, bounds) in &avian.colliders {
            if !filter.interacts_with(collider.filter) || !bounds.intersects(&reach) {
                continue;
            }
            let local = match body.rigid_ids.iter().position(|&id| id == collider.body) {
                Some(local) => local,
                None => {
                    body.rigid_ids.push(collider.body);
                    rigid.bodies.push(avian.start[collider.body as usize]);
                    rigid.bodies.len() - 1
                }
            };
            let mut collider = collider.clone();
            collider.body = local as u32;
            rigid.colliders.push(collider);
        }
    }
}

/// Adds each dynamic body's change of velocity over the soft step to avian's velocities.
fn write_back_to_avian(
    time: Res<Time>,
    avian: Res<AvianBodies>,
    solver: Res<SolverSpheres>,
    mut velocities: Query<(&mut LinearVelocity, &mut AngularVelocity)>,
) {
    if time.delta_secs() <= 0.0 {
        return;
    }
    for (k, &entity) in avian.entities.iter().enumerate() {
        let (start, end) = (&avian.start[k], &solver.rigid[k]);
        if start.inv_mass == 0.0 {
            continue;
        }
        let dv = end.linear_velocity - start.linear_velocity;
        let dw = end.angular_velocity - start.angular_velocity;
        if dv == Vec3::ZERO && dw == Vec3::ZERO {
            continue;
        }
        if avian.sleeping[k] && dv.length() < WAKE_SPEED && dw.length() < WAKE_SPEED {
            continue;
        }
        if let Ok((mut v, mut w)) = velocities.get_mut(entity) {
            v.0 += dv;
            w.0 += dw;
        }
    }
}
