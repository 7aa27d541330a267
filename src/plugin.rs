//! [`SoftBodyPlugin`]: the systems that step every soft body, in ordered sets that mirror the
//! stages of a step, so that a game can put its own systems between them.

use std::time::Duration;

use bevy::ecs::schedule::{InternedScheduleLabel, ScheduleLabel};
use bevy::platform::time::Instant;
use bevy::prelude::*;
use parry3d::math::Pose;

use crate::components::{
    DrivenParticles, PinnedParticles, RigidSphere, SoftBody, SoftBodyError, SoftBodyErrorKind,
    SoftBodyGravity, SoftBodyStats, StaticCollider,
};
use crate::core::{ColliderInstance, RigidSphereState, SoftBodyState, TetMesh};

/// The stages of a step, run in this order in the plugin's schedule (see `core::body` for what
/// each does and why in this order).
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SoftBodySet {
    /// Place new bodies, clear last step's counters, apply pinned and driven particles.
    Prepare,
    /// Gravity, springs with damping, baseline volume forces; the velocities of spheres.
    Forces,
    /// Contacts on the previewed positions, so the volume passes see them.
    Contacts,
    /// The one-ring volume impulses (for the XPBD method, its whole substepped solve).
    OneRing,
    /// The per-tet correction scaled by gamma.
    PerTet,
    /// Plastic springs.
    Plasticity,
    /// A last contact pass, then `x += h v` for particles and spheres.
    Integrate,
    /// Metrics into [`SoftBodyStats`], transforms follow the bodies.
    Writeback,
}

/// Adds soft-body simulation to an app.
///
/// By default the simulation runs in [`FixedUpdate`] and sets the fixed time step to the
/// paper's 10 ms; each run of the schedule is one step of `Time::delta` (the fixed step there).
/// Gravity is the [`SoftBodyGravity`] resource.
pub struct SoftBodyPlugin {
    /// The schedule the stages run in.
    pub schedule: InternedScheduleLabel,
    /// If set and the schedule is [`FixedUpdate`], the fixed time step to use. `None` leaves
    /// `Time<Fixed>` as the game configured it.
    pub time_step: Option<Duration>,
}

impl Default for SoftBodyPlugin {
    fn default() -> Self {
        SoftBodyPlugin {
            schedule: FixedUpdate.intern(),
            time_step: Some(Duration::from_millis(10)),
        }
    }
}

impl SoftBodyPlugin {
    /// Runs the stages in `schedule` instead of [`FixedUpdate`].
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        SoftBodyPlugin {
            schedule: schedule.intern(),
            time_step: None,
        }
    }
}

/// How the plugin was set up, for systems outside the step (the render surfaces).
#[derive(Resource, Clone, Copy, Debug)]
pub struct SoftBodyTiming {
    /// Whether the steps run in [`FixedUpdate`], so that frames fall between steps and are
    /// drawn interpolated.
    pub fixed: bool,
}

impl Plugin for SoftBodyPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(SoftBodyTiming {
            fixed: self.schedule == FixedUpdate.intern(),
        });
        app.init_resource::<SoftBodyGravity>()
            .register_type::<SoftBodyGravity>()
            .register_type::<SoftBodyStats>()
            .register_type::<PinnedParticles>()
            .register_type::<DrivenParticles>()
            .register_type::<RigidSphere>()
            .init_resource::<SolverSpheres>()
            .add_message::<SoftBodyError>();
        if let Some(step) = self.time_step
            && self.schedule == FixedUpdate.intern()
        {
            app.insert_resource(Time::<Fixed>::from_duration(step));
        }
        app.configure_sets(
            self.schedule,
            (
                SoftBodySet::Prepare,
                SoftBodySet::Forces,
                SoftBodySet::Contacts,
                SoftBodySet::OneRing,
                SoftBodySet::PerTet,
                SoftBodySet::Plasticity,
                SoftBodySet::Integrate,
                SoftBodySet::Writeback,
            )
                .chain(),
        );
        app.add_systems(
            self.schedule,
            (
                prepare.in_set(SoftBodySet::Prepare),
                apply_forces.in_set(SoftBodySet::Forces),
                resolve_contacts.in_set(SoftBodySet::Contacts),
                one_ring.in_set(SoftBodySet::OneRing),
                per_tet.in_set(SoftBodySet::PerTet),
                plasticity.in_set(SoftBodySet::Plasticity),
                integrate.in_set(SoftBodySet::Integrate),
                writeback.in_set(SoftBodySet::Writeback),
            ),
        );
    }
}

/// Runs `f` on the body's state and adds the time it took to the body's step time.
fn timed(body: &mut SoftBody, f: impl FnOnce(&mut SoftBodyState)) {
    let start = Instant::now();
    f(&mut body.state);
    body.step_time += start.elapsed();
}

/// The body's rest mesh scaled by `scale`, or the error that makes that impossible.
fn scaled_mesh(mesh: &TetMesh, scale: Vec3) -> Result<TetMesh, crate::core::TetMeshError> {
    TetMesh::new(
        mesh.positions().iter().map(|&p| p * scale).collect(),
        mesh.tets().to_vec(),
    )
}

/// A body with its transform and its optional pinned and driven particles.
type PreparedBody<'a> = (
    Entity,
    &'a mut SoftBody,
    &'a mut Transform,
    Option<Ref<'a, PinnedParticles>>,
    Option<&'a mut DrivenParticles>,
);

/// Logs `error` and writes it as a message.
fn report(errors: &mut MessageWriter<SoftBodyError>, error: SoftBodyError) {
    error!("{error}");
    errors.write(error);
}

fn prepare(
    mut bodies: Query<PreparedBody>,
    targets: Query<&Transform, Without<SoftBody>>,
    mut errors: MessageWriter<SoftBodyError>,
) {
    for (entity, mut body, mut transform, pinned, driven) in &mut bodies {
        let body = &mut *body;
        if !body.placed {
            let placement = *transform;
            if placement.scale != Vec3::ONE {
                match scaled_mesh(body.state.mesh(), placement.scale)
                    .map_err(|e| e.to_string())
                    .and_then(|m| {
                        SoftBodyState::new(m.into(), *body.state.material())
                            .map_err(|e| e.to_string())
                    }) {
                    Ok(mut state) => {
                        // Velocities given before the spawn are kept (world frame, like the
                        // simulation); only the rest shape changes.
                        state
                            .velocities_mut()
                            .copy_from_slice(body.state.velocities());
                        body.state = state;
                        body.rest_scale = placement.scale;
                    }
                    Err(reason) => report(
                        &mut errors,
                        SoftBodyError {
                            body: entity,
                            kind: SoftBodyErrorKind::BadScale {
                                scale: placement.scale,
                                reason,
                            },
                        },
                    ),
                }
            }
            body.state
                .map_positions(|p| placement.rotation * p + placement.translation);
            body.placed = true;
            *transform = Transform::from_translation(body.state.centre_of_mass());
        }
        body.step_time = Duration::ZERO;
        body.state.begin_step();
        body.state.clear_kinematic();
        let count = body.state.positions().len();
        let out_of_range = |index: u32| SoftBodyError {
            body: entity,
            kind: SoftBodyErrorKind::ParticleOutOfRange { index, count },
        };
        if let Some(pinned) = pinned {
            for &i in &pinned.0 {
                match body.state.positions().get(i as usize).copied() {
                    Some(here) => {
                        let _ = body.state.set_kinematic(i as usize, here);
                    }
                    // Reported once, when the component is added or changed.
                    None if pinned.is_changed() => report(&mut errors, out_of_range(i)),
                    None => {}
                }
            }
        }
        if let Some(mut driven) = driven {
            let Ok(target) = targets.get(driven.target) else {
                if !driven.target_missing {
                    driven.target_missing = true;
                    let target = driven.target;
                    report(
                        &mut errors,
                        SoftBodyError {
                            body: entity,
                            kind: SoftBodyErrorKind::MissingDriveTarget(target),
                        },
                    );
                }
                continue;
            };
            driven.target_missing = false;
            let to_world = target.to_matrix();
            if driven.offsets.len() != driven.particles.len() {
                let to_local = to_world.inverse();
                let mut offsets = Vec::with_capacity(driven.particles.len());
                for &i in &driven.particles {
                    match body.state.positions().get(i as usize) {
                        Some(&p) => offsets.push(to_local.transform_point3(p)),
                        None => {
                            // Reported once, when the offsets are captured; kept as a
                            // placeholder so that indices and offsets stay paired.
                            report(&mut errors, out_of_range(i));
                            offsets.push(Vec3::ZERO);
                        }
                    }
                }
                driven.offsets = offsets;
            }
            for (&i, &offset) in driven.particles.iter().zip(&driven.offsets) {
                if (i as usize) < count {
                    let _ = body
                        .state
                        .set_kinematic(i as usize, to_world.transform_point3(offset));
                }
            }
        }
    }
}

/// The rigid spheres and static colliders as the solver sees them during one step, gathered
/// once in [`SoftBodySet::Forces`]. The spheres are changed by the contact and volume passes
/// (particles pressed against a sphere move it) and written back in [`SoftBodySet::Integrate`];
/// the colliders do not move within a step. The buffers are reused, so a step does not allocate.
#[derive(Resource, Default)]
pub struct SolverSpheres {
    entities: Vec<Entity>,
    states: Vec<RigidSphereState>,
    colliders: Vec<ColliderInstance>,
}

fn sphere_state(sphere: &RigidSphere, transform: &Transform) -> RigidSphereState {
    let inv_mass = if sphere.mass.is_finite() && sphere.mass > 0.0 {
        1.0 / sphere.mass
    } else {
        0.0
    };
    RigidSphereState {
        position: transform.translation,
        velocity: sphere.velocity,
        radius: sphere.radius,
        inv_mass,
        friction: sphere.friction,
    }
}

fn apply_forces(
    time: Res<Time>,
    gravity: Res<SoftBodyGravity>,
    mut solver_spheres: ResMut<SolverSpheres>,
    mut bodies: Query<&mut SoftBody>,
    spheres: Query<(Entity, &RigidSphere, &Transform)>,
    collider_query: Query<(&StaticCollider, &Transform), Without<RigidSphere>>,
) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    for mut body in &mut bodies {
        timed(&mut body, |s| s.apply_forces(h, gravity.0));
    }
    let solver_spheres = &mut *solver_spheres;
    solver_spheres.entities.clear();
    solver_spheres.states.clear();
    for (entity, sphere, transform) in &spheres {
        let mut state = sphere_state(sphere, transform);
        state.apply_forces(h, gravity.0);
        solver_spheres.entities.push(entity);
        solver_spheres.states.push(state);
    }
    solver_spheres.colliders.clear();
    for (collider, transform) in &collider_query {
        let pose = Pose::from_parts(transform.translation, transform.rotation);
        solver_spheres.colliders.push(ColliderInstance::new(
            collider.shape.clone(),
            pose,
            collider.friction,
        ));
    }
}

/// One contact pass over everything: spheres against static colliders, then particles against
/// spheres, then particles against static colliders (last, so that no particle is left inside
/// the ground by a sphere pushing it).
fn contact_pass(
    h: f32,
    colliders: &[ColliderInstance],
    spheres: &mut [RigidSphereState],
    bodies: &mut Query<(&mut SoftBody, &mut SoftBodyStats)>,
) {
    for sphere in spheres.iter_mut() {
        sphere.resolve_static_contacts(h, colliders);
    }
    for (mut body, mut stats) in bodies.iter_mut() {
        if body.state.material().method.is_xpbd() {
            // Its contacts are resolved inside its substeps (`xpbd_pass`).
            continue;
        }
        let mut contacts = 0;
        timed(&mut body, |s| {
            contacts += s.resolve_sphere_contacts(h, spheres);
            contacts += s.resolve_static_contacts(h, colliders);
        });
        stats.contacts += contacts;
    }
}

fn resolve_contacts(
    time: Res<Time>,
    mut solver: ResMut<SolverSpheres>,
    mut bodies: Query<(&mut SoftBody, &mut SoftBodyStats)>,
) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    for (_, mut stats) in &mut bodies {
        stats.contacts = 0;
    }
    let solver = &mut *solver;
    contact_pass(h, &solver.colliders, &mut solver.states, &mut bodies);
}

fn one_ring(
    time: Res<Time>,
    mut spheres: ResMut<SolverSpheres>,
    mut bodies: Query<(&mut SoftBody, &mut SoftBodyStats)>,
) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    let spheres = &mut *spheres;
    for (mut body, mut stats) in &mut bodies {
        timed(&mut body, |s| {
            stats.contacts += s.xpbd_pass(h, &mut spheres.states, &spheres.colliders);
            s.one_ring_pass(h, &mut spheres.states);
        });
    }
}

fn per_tet(time: Res<Time>, mut spheres: ResMut<SolverSpheres>, mut bodies: Query<&mut SoftBody>) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    for mut body in &mut bodies {
        timed(&mut body, |s| s.per_tet_pass(h, &mut spheres.states));
    }
}

fn plasticity(time: Res<Time>, mut bodies: Query<&mut SoftBody>) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    for mut body in &mut bodies {
        timed(&mut body, |s| s.apply_plasticity(h));
    }
}

fn integrate(
    time: Res<Time>,
    mut solver_spheres: ResMut<SolverSpheres>,
    mut bodies: Query<(&mut SoftBody, &mut SoftBodyStats)>,
    mut spheres: Query<(&mut RigidSphere, &mut Transform), Without<StaticCollider>>,
) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    let solver_spheres = &mut *solver_spheres;
    contact_pass(
        h,
        &solver_spheres.colliders,
        &mut solver_spheres.states,
        &mut bodies,
    );
    for (mut body, mut stats) in &mut bodies {
        timed(&mut body, |s| s.integrate_positions(h));
        stats.steps += 1;
    }
    for (entity, state) in solver_spheres
        .entities
        .iter()
        .zip(&mut solver_spheres.states)
    {
        state.integrate_position(h);
        if let Ok((mut sphere, mut transform)) = spheres.get_mut(*entity) {
            sphere.velocity = state.velocity;
            transform.translation = state.position;
        }
    }
}

fn writeback(mut bodies: Query<(&SoftBody, &mut SoftBodyStats, &mut Transform)>) {
    for (body, mut stats, mut transform) in &mut bodies {
        if !body.placed {
            continue;
        }
        let m = body.state.volume_metrics();
        stats.volume_error_pct = m.volume_error_pct;
        stats.peak_volume_error_pct = stats.peak_volume_error_pct.max(m.volume_error_pct.abs());
        stats.mean_abs_tet_error_pct = m.mean_abs_tet_error_pct;
        stats.inverted_tets = m.inverted_tets;
        stats.max_inverted_tets = stats.max_inverted_tets.max(m.inverted_tets);
        stats.step_ms = body.step_time.as_secs_f64() * 1e3;
        stats.total_step_ms += stats.step_ms;
        stats.counters = body.state.counters();
        transform.translation = body.state.centre_of_mass();
    }
}
