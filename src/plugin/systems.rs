//! The plugin's systems: one per stage of a step, each running the core's stage on every
//! body, and the conversions between the ECS and the core.

use super::*;

/// The body's rest mesh scaled by `scale`, or the error that makes that impossible.
pub(super) fn scaled_mesh(
    mesh: &TetMesh,
    scale: Vec3,
) -> Result<TetMesh, crate::core::TetMeshError> {
    TetMesh::new(
        mesh.positions().iter().map(|&p| p * scale).collect(),
        mesh.tets().to_vec(),
    )
}

/// A body with its transform and its optional pinned and driven particles.
pub(super) type PreparedBody<'a> = (
    Entity,
    &'a mut SoftBody,
    &'a mut Transform,
    Option<Ref<'a, PinnedParticles>>,
    Option<&'a mut DrivenParticles>,
);

/// Logs `error` and writes it as a message.
pub(super) fn report(errors: &mut MessageWriter<SoftBodyError>, error: SoftBodyError) {
    error!("{error}");
    errors.write(error);
}

pub(super) fn prepare(
    mut bodies: Query<PreparedBody>,
    targets: Query<&Transform, Without<SoftBody>>,
    mut errors: MessageWriter<SoftBodyError>,
    threads: Res<SoftBodyThreads>,
) {
    if threads.keep_awake {
        // First, so that the crew is awake by the first parallel section.
        muster_crew(
            &ComputePool::new(&threads),
            bodies
                .iter()
                .map(|(_, body, ..)| body.state.mesh().tet_count()),
        );
    }
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
/// once in [`SoftBodySystems::Forces`]. The spheres are changed by the contact and volume passes
/// (particles pressed against a sphere move it) and written back in [`SoftBodySystems::Integrate`];
/// the colliders do not move within a step. Also the bodies' entities, scratch for the parallel
/// stages ([`for_each_body`]). The buffers are reused, so a step does not allocate.
#[derive(Resource, Default)]
pub struct SolverSpheres {
    pub(super) entities: Vec<Entity>,
    pub(super) states: Vec<RigidSphereState>,
    /// The spheres as they were before the stage running now (see [`par_with_spheres`]).
    pub(super) before: Vec<RigidSphereState>,
    pub(super) colliders: Vec<ColliderInstance>,
    /// The bodies' entities, in query order (scratch of [`for_each_body`]).
    pub(super) bodies: Vec<Entity>,
}

pub(super) fn sphere_state(sphere: &RigidSphere, transform: &Transform) -> RigidSphereState {
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

// A system takes one parameter per resource and query it reads.
#[allow(clippy::too_many_arguments)]
pub(super) fn apply_forces(
    time: Res<Time>,
    gravity: Res<SoftBodyGravity>,
    mut solver_spheres: ResMut<SolverSpheres>,
    mut clock: ResMut<SoftBodyStepTime>,
    mut bodies: Bodies,
    spheres: Query<(Entity, &RigidSphere, &Transform)>,
    collider_query: Query<(&StaticCollider, &Transform), Without<RigidSphere>>,
    threads: Res<SoftBodyThreads>,
) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    let start = Instant::now();
    let g = gravity.0;
    let compute = ComputePool::new(&threads);
    let few = few_bodies(&bodies, &compute);
    let solver_spheres = &mut *solver_spheres;
    par_bodies(&mut bodies, &mut solver_spheres.bodies, &compute, |s, _| {
        s.apply_forces_on(h, g, pass_parallelism(few, s, &compute))
    });
    solver_spheres.entities.clear();
    solver_spheres.states.clear();
    for (entity, sphere, transform) in &spheres {
        let mut state = sphere_state(sphere, transform);
        state.apply_forces(h, g);
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
    clock.add_stage(start, |s| &mut s.forces_ms);
}

/// One contact pass over everything: spheres against static colliders, then particles against
/// spheres, then particles against static colliders (last, so that no particle is left inside
/// the ground by a sphere pushing it), then `after` on each body in the same task (one parallel
/// section instead of two: waking a thread for each costs more than a small body's stage).
/// A large body alone has its particles against the static colliders, and `after`, in
/// chunks on the threads (the parallelism `after` gets); against the spheres they go one
/// after another (each push moves the sphere the next particle meets).
/// Bodies stepped in substeps meet the colliders there (`SoftBodyState::shape_pass`, which
/// the first pass's `after` runs), not in these passes.
pub(super) fn contact_pass(
    h: f32,
    solver: &mut SolverSpheres,
    bodies: &mut Bodies,
    compute: &ComputePool,
    after: impl Fn(
        &mut SoftBodyState,
        &mut SoftBodyStats,
        &mut [RigidSphereState],
        &[ColliderInstance],
        &dyn Parallel,
    ) + Send
    + Sync,
) {
    for sphere in solver.states.iter_mut() {
        sphere.resolve_static_contacts(h, &solver.colliders);
    }
    let few = few_bodies(bodies, compute);
    par_with_spheres(bodies, solver, compute, |s, stats, spheres, colliders| {
        let parallel = pass_parallelism(few, s, compute);
        if !s.material().is_substepped() {
            stats.contacts += s.resolve_sphere_contacts(h, spheres)
                + s.resolve_static_contacts_on(h, colliders, parallel);
        }
        after(s, stats, spheres, colliders, parallel);
    });
}

pub(super) fn resolve_contacts(
    time: Res<Time>,
    mut solver: ResMut<SolverSpheres>,
    mut clock: ResMut<SoftBodyStepTime>,
    mut bodies: Bodies,
    threads: Res<SoftBodyThreads>,
) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    let start = Instant::now();
    for (_, _, mut stats) in &mut bodies {
        stats.contacts = 0;
    }
    contact_pass(
        h,
        &mut solver,
        &mut bodies,
        &ComputePool::new(&threads),
        |s, stats, spheres, colliders, parallel| {
            stats.contacts += s.shape_pass(h, spheres, colliders, parallel)
        },
    );
    clock.add_stage(start, |s| &mut s.contacts_ms);
}

pub(super) fn one_ring(
    time: Res<Time>,
    solver: ResMut<SolverSpheres>,
    clock: ResMut<SoftBodyStepTime>,
    bodies: Bodies,
    threads: Res<SoftBodyThreads>,
) {
    let pass = SoftBodyState::one_ring_pass_on;
    volume_pass(time, solver, clock, bodies, threads, pass, |s| {
        &mut s.one_ring_ms
    });
}

pub(super) fn per_tet(
    time: Res<Time>,
    solver: ResMut<SolverSpheres>,
    clock: ResMut<SoftBodyStepTime>,
    bodies: Bodies,
    threads: Res<SoftBodyThreads>,
) {
    let pass = SoftBodyState::per_tet_pass_on;
    volume_pass(time, solver, clock, bodies, threads, pass, |s| {
        &mut s.per_tet_ms
    });
}

/// One of the volume passes on every body, a large body's in blocks when there are threads to
/// spare, timed as `stage`.
fn volume_pass(
    time: Res<Time>,
    mut solver: ResMut<SolverSpheres>,
    mut clock: ResMut<SoftBodyStepTime>,
    mut bodies: Bodies,
    threads: Res<SoftBodyThreads>,
    pass: fn(&mut SoftBodyState, f32, &mut [RigidSphereState], &dyn Parallel),
    stage: fn(&mut SoftBodyStageTimes) -> &mut f64,
) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    let start = Instant::now();
    let compute = ComputePool::new(&threads);
    let few = few_bodies(&bodies, &compute);
    par_with_spheres(&mut bodies, &mut solver, &compute, |s, _, spheres, _| {
        pass(s, h, spheres, pass_parallelism(few, s, &compute));
    });
    clock.add_stage(start, stage);
}

pub(super) fn plasticity(
    time: Res<Time>,
    mut solver: ResMut<SolverSpheres>,
    mut clock: ResMut<SoftBodyStepTime>,
    mut bodies: Bodies,
    threads: Res<SoftBodyThreads>,
) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    // Without plastic bodies, not even a parallel section (waking threads for nothing).
    if bodies
        .iter()
        .all(|(_, body, _)| body.state.material().plasticity.is_none())
    {
        return;
    }
    let start = Instant::now();
    let compute = ComputePool::new(&threads);
    par_bodies(&mut bodies, &mut solver.bodies, &compute, |s, _| {
        s.apply_plasticity(h)
    });
    clock.add_stage(start, |s| &mut s.plasticity_ms);
}

pub(super) fn integrate(
    time: Res<Time>,
    mut solver_spheres: ResMut<SolverSpheres>,
    mut clock: ResMut<SoftBodyStepTime>,
    mut bodies: Bodies,
    mut spheres: Query<(&mut RigidSphere, &mut Transform), Without<StaticCollider>>,
    threads: Res<SoftBodyThreads>,
) {
    // The crew stays while the last section (below) runs: dismissed members finish the
    // posting they are in, and take no other.
    let _dismiss = DismissCrew;
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    let start = Instant::now();
    let solver_spheres = &mut *solver_spheres;
    let compute = ComputePool::new(&threads);
    contact_pass(
        h,
        solver_spheres,
        &mut bodies,
        &compute,
        |s, stats, _, _, parallel| {
            s.integrate_positions_on(h, parallel);
            stats.steps += 1;
        },
    );
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
    clock.add_stage(start, |s| &mut s.integrate_ms);
    clock.last_ms = clock.current.as_secs_f64() * 1e3;
    clock.total_ms += clock.last_ms;
    clock.steps += 1;
    clock.current = Duration::ZERO;
}

pub(super) fn writeback(
    mut bodies: Query<(Entity, &SoftBody, &mut SoftBodyStats, &mut Transform)>,
    threads: Res<SoftBodyThreads>,
    mut errors: MessageWriter<SoftBodyError>,
) {
    type Written<'a> = (
        Entity,
        &'a SoftBody,
        Mut<'a, SoftBodyStats>,
        Mut<'a, Transform>,
    );
    let write = |(_, body, mut stats, mut transform): Written| {
        if !body.placed {
            return;
        }
        stats.step_ms = body.step_time.as_secs_f64() * 1e3;
        stats.total_step_ms += stats.step_ms;
        stats.counters = body.state.counters();
        // A body that slept through the step has not moved since its metrics were taken.
        let slept = stats.sleeping && body.state.is_sleeping();
        stats.sleeping = body.state.is_sleeping();
        if slept {
            return;
        }
        let m = body.state.volume_metrics();
        stats.volume_error_pct = m.volume_error_pct;
        stats.peak_volume_error_pct = stats.peak_volume_error_pct.max(m.volume_error_pct.abs());
        stats.mean_abs_tet_error_pct = m.mean_abs_tet_error_pct;
        stats.inverted_tets = m.inverted_tets;
        stats.max_inverted_tets = stats.max_inverted_tets.max(m.inverted_tets);
        transform.translation = body.state.centre_of_mass();
    };
    // A single body on this thread, as in the stages (`for_each_body`): a parallel query hands
    // it to a pool thread, which may have to wake up and has little of the body in its caches
    // (the soft cube's writeback, two threads, four runs: 50-78 us a step, inline 39-42; one
    // thread 33-39). So do bodies kept to one thread.
    if bodies.iter().len() < 2 || ComputePool::new(&threads).threads < 2 {
        bodies.iter_mut().for_each(write);
    } else {
        bodies
            .par_iter_mut()
            .batching_strategy(ONE_BODY_PER_TASK)
            .for_each(write);
    }
    for (entity, body, mut stats, _) in &mut bodies {
        let Some(runaway) = body.state.runaway() else {
            continue;
        };
        // Reported once per spell: a body that runs away again within a second of steps of
        // the last time is counted, not reported again.
        let quiet = stats
            .last_runaway_step
            .is_none_or(|last| stats.steps >= last + RUNAWAY_REPORT_GAP_STEPS);
        stats.runaway_resets += 1;
        stats.last_runaway_step = Some(stats.steps);
        if quiet {
            report(
                &mut errors,
                SoftBodyError {
                    body: entity,
                    kind: SoftBodyErrorKind::Runaway(runaway),
                },
            );
        }
    }
}

/// Steps without a runaway after which a body's next runaway is reported again.
pub(super) const RUNAWAY_REPORT_GAP_STEPS: u64 = 100;
