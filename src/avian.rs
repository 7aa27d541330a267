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
use glam::{Mat3, Quat};
use parry3d::bounding_volume::{Aabb, BoundingVolume};
use parry3d::math::Pose;

use crate::components::{SoftBody, SoftBodyError, SoftBodyErrorKind, SoftBodyGravity};
use crate::core::{
    ColliderInstance, CollisionFilter, RigidAttachment, RigidBodyMotion, RigidCollider,
};
use crate::plugin::{SoftBodySystems, SoftBodyTiming, SolverSpheres, report};

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
    /// Whether each is static (its colliders are met as static colliders; it is listed for
    /// attachments).
    fixed: Vec<bool>,
    /// Each body's origin and rotation (avian's `Position` and `Rotation`).
    poses: Vec<(Vec3, Quat)>,
    /// The dynamic and kinematic bodies' colliders, with their world bounds over the step.
    colliders: Vec<(RigidCollider, Aabb)>,
    /// Body entity to index, rebuilt each step.
    index: HashMap<Entity, u32>,
}

impl AvianBodies {
    /// Empties every list, for the next step's gathering.
    fn clear(&mut self) {
        self.entities.clear();
        self.start.clear();
        self.sleeping.clear();
        self.fixed.clear();
        self.poses.clear();
        self.colliders.clear();
        self.index.clear();
    }
}

/// Soft bodies among avian's rigid bodies (see the module's documentation). In
/// [`SoftBodyPlugins`](crate::SoftBodyPlugins) when the `avian` feature is on; it goes after
/// [`SoftBodyPlugin`](crate::SoftBodyPlugin), whose schedule it runs in.
///
/// A jelly bag hung from an avian beam by its top layer (the README's example), headless:
///
/// ```
/// use avian3d::prelude::*;
/// use bevy::prelude::*;
/// use bevy_soft_body::avian::{SoftBodyAttachment, SoftBodyAvianPlugin};
/// use bevy_soft_body::core::{ParticleRegion, box_grid};
/// use bevy_soft_body::prelude::*;
///
/// fn setup(mut commands: Commands) {
///     commands.spawn((RigidBody::Static, Collider::half_space(Vec3::Y)));
///     let beam = (RigidBody::Static, Collider::cuboid(1.0, 0.1, 0.1), Transform::from_xyz(0.0, 2.0, 0.0));
///     let beam = commands.spawn(beam).id();
///     let mesh = box_grid(UVec3::splat(6), Vec3::splat(0.05), Vec3::new(-0.15, 1.6, -0.15)).unwrap();
///     let top = mesh.particles_in(ParticleRegion::Box { min: Vec3::new(-1.0, 1.89, -1.0), max: Vec3::splat(3.0) });
///     let bag = SoftBody::new(mesh.into(), SoftBodyMaterial::JELLY).unwrap();
///     commands.spawn((bag, SoftBodyAttachment::hard(beam, top)));
/// }
///
/// let mut app = App::new();
/// app.add_plugins((MinimalPlugins, TransformPlugin, PhysicsPlugins::default()))
///     .add_plugins((SoftBodyPlugin::default(), SoftBodyAvianPlugin))
///     .add_systems(Startup, setup);
/// app.finish();
/// app.cleanup();
/// for _ in 0..5 {
///     app.update();
/// }
/// ```
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
    mut soft: Query<(
        Entity,
        &mut SoftBody,
        Option<&CollisionLayers>,
        Option<&mut SoftBodyAttachment>,
    )>,
    mut errors: MessageWriter<SoftBodyError>,
) {
    let h = time.delta_secs();
    let avian = &mut *avian;
    avian.clear();
    solver.rigid.clear();
    let g = gravity.map_or(Vec3::ZERO, |g| g.0);
    for (entity, kind, position, rotation, v, w, mass, inertia, com, scale, sleeping) in
        &rigid_bodies
    {
        let dynamic = kind.is_dynamic();
        let turn = Mat3::from_quat(rotation.0);
        let (v, w) = if kind.is_static() {
            (Vec3::ZERO, Vec3::ZERO)
        } else {
            (v.0, w.0)
        };
        let mut motion = RigidBodyMotion::kinematic(position.0 + rotation.0 * com.0, v, w);
        motion.asleep = sleeping;
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
        avian.fixed.push(kind.is_static());
        avian.poses.push((position.0, rotation.0));
    }
    solver.rigid.extend_from_slice(&avian.start);
    let default_friction = default_friction.map_or(0.5, |f| f.dynamic_coefficient);
    for (collider, of, local, layers, friction, global) in &colliders {
        let friction = friction.map_or(default_friction, |f| f.dynamic_coefficient);
        let filter = filter_of(layers);
        let shape = collider.shape_scaled().clone();
        let on_body = of
            .and_then(|of| Some((*avian.index.get(&of.body)?, of.body)))
            .filter(|&(k, _)| !avian.fixed[k as usize]);
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
                let end = motion.advance(&pose, 0.0, h).0;
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
    for (entity, mut body, layers, attachment) in &mut soft {
        let body = &mut *body;
        let filter = filter_of(layers);
        body.state.set_collision_filter(filter);
        // Room for the speed the step's gravity and contacts may add.
        let reach = body.state.swept_bounds(h).map(|b| b.loosened(h * 5.0));
        body.state.rigid_contacts_mut().clear();
        body.rigid_ids.clear();
        if !body.placed {
            continue;
        }
        if let Some(reach) = reach {
            for (collider, bounds) in &avian.colliders {
                if !filter.interacts_with(collider.filter) || !bounds.intersects(&reach) {
                    continue;
                }
                let local = local_body(body, avian, collider.body);
                let mut collider = collider.clone();
                collider.body = local;
                body.state.rigid_contacts_mut().colliders.push(collider);
            }
        }
        if let Some(mut attachment) = attachment {
            attach(entity, body, &mut attachment, avian, &mut errors);
        }
    }
}

/// The index in `body`'s `RigidContacts` of avian body `k`, added if it is not there yet.
fn local_body(body: &mut SoftBody, avian: &AvianBodies, k: u32) -> u32 {
    if let Some(local) = body.rigid_ids.iter().position(|&id| id == k) {
        return local as u32;
    }
    body.rigid_ids.push(k);
    let rigid = body.state.rigid_contacts_mut();
    rigid.bodies.push(avian.start[k as usize]);
    rigid.bodies.len() as u32 - 1
}

/// Gives `body` its attachment to an avian body for this step, capturing where each particle
/// sits on the body the first time (or after the particles changed).
fn attach(
    entity: Entity,
    body: &mut SoftBody,
    attachment: &mut SoftBodyAttachment,
    avian: &AvianBodies,
    errors: &mut MessageWriter<SoftBodyError>,
) {
    let Some(&k) = avian.index.get(&attachment.body) else {
        if !attachment.reported {
            attachment.reported = true;
            let kind = SoftBodyErrorKind::MissingDriveTarget(attachment.body);
            report(errors, SoftBodyError { body: entity, kind });
        }
        return;
    };
    let (origin, rotation) = avian.poses[k as usize];
    let count = body.state.positions().len();
    if attachment.anchors.len() != attachment.particles.len() {
        attachment.anchors.clear();
        for &i in &attachment.particles {
            match body.state.positions().get(i as usize) {
                Some(&x) => attachment.anchors.push(rotation.inverse() * (x - origin)),
                None => {
                    let kind = SoftBodyErrorKind::ParticleOutOfRange { index: i, count };
                    report(errors, SoftBodyError { body: entity, kind });
                    attachment.anchors.push(Vec3::ZERO);
                }
            }
        }
    }
    let local = local_body(body, avian, k);
    let centre = avian.start[k as usize].centre_of_mass;
    let rigid = body.state.rigid_contacts_mut();
    for (&i, &anchor) in attachment.particles.iter().zip(&attachment.anchors) {
        if (i as usize) < count {
            rigid.attachments.push(RigidAttachment {
                particle: i,
                body: local,
                offset: origin + rotation * anchor - centre,
                compliance: attachment.compliance,
            });
        }
    }
}

/// Particles of a soft body attached to an avian rigid body (put it on the soft body): held on
/// the body where they are when the attachment starts, or pulled there by springs; two-way for
/// a dynamic body, which the soft body pulls back (a bag hanging from a beam swings it). Pick
/// the particles by index, or by a region of the rest shape with
/// [`TetMesh::particles_in`](crate::core::TetMesh::particles_in).
///
/// The coupling is partitioned: the soft step pulls the body, then avian solves the body's own
/// joints and contacts. A dynamic body much lighter than the soft mass it carries by a few
/// particles can then oscillate and blow up: give such a body a realistic mass, or attach more
/// particles. A body that runs away is caught and reported as any other.
#[derive(Component, Clone, Debug)]
pub struct SoftBodyAttachment {
    /// The avian rigid body (dynamic, kinematic or static).
    pub body: Entity,
    /// The attached particles.
    pub particles: Vec<u32>,
    /// Compliance, metres per newton (the inverse of each particle's spring stiffness); zero
    /// holds the particles on the body.
    pub compliance: f32,
    /// Where each particle is attached, in the body's frame (captured at the first step).
    anchors: Vec<Vec3>,
    /// Whether a missing body was reported.
    reported: bool,
}

impl SoftBodyAttachment {
    /// `particles` held on `body` where they are when the attachment starts.
    pub fn hard(body: Entity, particles: Vec<u32>) -> Self {
        SoftBodyAttachment {
            body,
            particles,
            compliance: 0.0,
            anchors: Vec::new(),
            reported: false,
        }
    }

    /// `particles` pulled toward where they were on `body` when the attachment started, each by
    /// a spring of `stiffness` newtons per metre.
    pub fn springs(body: Entity, particles: Vec<u32>, stiffness: f32) -> Self {
        SoftBodyAttachment {
            compliance: if stiffness > 0.0 {
                1.0 / stiffness
            } else {
                0.0
            },
            ..SoftBodyAttachment::hard(body, particles)
        }
    }
}

/// Adds each dynamic body's change of velocity over the soft step to avian's velocities, and
/// moves the body by its `position_correction` and `rotation_correction` (about its centre of
/// mass): avian then moves it at its new velocity over the step to where the soft step's
/// contacts had it (see [`RigidBodyMotion::position_correction`]).
fn write_back_to_avian(
    time: Res<Time>,
    avian: Res<AvianBodies>,
    solver: Res<SolverSpheres>,
    mut bodies: Query<(
        &mut LinearVelocity,
        &mut AngularVelocity,
        &mut Position,
        &mut Rotation,
    )>,
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
        if let Ok((mut v, mut w, mut position, mut rotation)) = bodies.get_mut(entity) {
            v.0 += dv;
            w.0 += dw;
            let centre = start.centre_of_mass;
            let turn = Quat::from_scaled_axis(end.rotation_correction);
            position.0 = centre + turn * (position.0 - centre) + end.position_correction;
            rotation.0 = (turn * rotation.0).normalize();
        }
    }
}
