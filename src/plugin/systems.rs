//! The plugin's systems: one per stage of a step ([`Stage::ORDER`]), each running the core's
//! stage on every body, and the conversions between the ECS and the core.

use super::*;

/// A body with its transform and its optional pinned and driven particles.
pub(super) type PreparedBody<'a> = (
    Entity,
    &'a mut SoftBody,
    &'a mut Transform,
    Option<Ref<'a, PinnedParticles>>,
    Option<&'a mut DrivenParticles>,
);

/// Logs `error` and writes it as a message.
pub(crate) fn report(errors: &mut MessageWriter<SoftBodyError>, error: SoftBodyError) {
    error!("{error}");
    errors.write(error);
}

pub(super) fn prepare(
    mut bodies: Query<PreparedBody>,
    targets: Query<&Transform, Without<SoftBody>>,
    mut errors: MessageWriter<SoftBodyError>,
) {
    for (entity, mut body, mut transform, pinned, driven) in &mut bodies {
        let body = &mut *body;
        if !body.placed {
            let defects = body.state.mesh().defects();
            if !defects.is_empty() {
                report(
                    &mut errors,
                    SoftBodyError {
                        body: entity,
                        kind: SoftBodyErrorKind::MeshDefects(defects.clone()),
                    },
                );
            }
            let placement = *transform;
            if placement.scale != Vec3::ONE {
                match body
                    .state
                    .mesh()
                    .scaled(placement.scale)
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
            body.state.time_substeps(true);
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

/// Applies each body's settings components (`components/settings.rs`), or the defaults where
/// one is absent, to its state; a setting that did not change is left alone (changing the
/// sleep settings wakes a body).
pub(super) fn apply_settings(
    mut bodies: Query<(&mut SoftBody, SettingsQuery, Option<&SoftBodyTearing>)>,
) {
    for (mut body, settings, tearing) in &mut bodies {
        let state = &mut body.state;
        let tearing = tearing.map(SoftBodyTearing::settings);
        if state.tearing() != tearing {
            state.set_tearing(tearing);
        }
        let (contacts, sleep, runaway) = core_settings(settings, state.shortest_edge);
        if state.soft_contact_settings() != contacts {
            state.set_soft_contact_settings(contacts);
        }
        if state.sleep_settings() != sleep {
            state.set_sleep_settings(sleep);
        }
        if state.runaway_limits() != runaway {
            state.set_runaway_limits(runaway);
        }
    }
}

/// A body with the game's forces and grab, if it has them.
pub(super) type PushedBody<'a> = (
    &'a mut SoftBody,
    Option<Mut<'a, SoftBodyForces>>,
    Option<Mut<'a, SoftBodyGrab>>,
);

/// The game's forces, grabs and explosions for this step: each body's [`SoftBodyForces`] as
/// the impulse `h F` and its [`SoftBodyGrab`]'s spring (points bound to the material on their
/// first step), and every [`SoftBodyRadialImpulse`] written since the last step. Nothing
/// without a step.
pub(super) fn apply_external(
    time: Res<Time>,
    mut explosions: MessageReader<SoftBodyRadialImpulse>,
    mut read: Local<Vec<SoftBodyRadialImpulse>>,
    mut bodies: Query<PushedBody>,
) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    read.clear();
    read.extend(explosions.read().copied());
    for (mut body, forces, grab) in &mut bodies {
        let state = &mut body.state;
        for e in read.iter() {
            state
                .forces()
                .apply_radial_impulse(e.centre, e.radius, e.impulse);
        }
        if let Some(mut grab) = grab {
            body.pull(&mut grab, h);
        }
        let state = &mut body.state;
        let Some(mut forces) = forces else { continue };
        if forces.force != Vec3::ZERO {
            state.forces().apply_impulse(h * forces.force);
        }
        let tets = state.mesh().tets().len();
        // The binding is the plugin's bookkeeping, not a change the game made.
        let at_points = &mut forces.bypass_change_detection().at_points;
        for f in at_points.iter_mut().filter(|f| f.force != Vec3::ZERO) {
            // Bound on first use, and again if a mesh change left it on no tet.
            if f.bound.is_none_or(|(tet, _)| tet as usize >= tets) {
                f.bound = state.body_point(f.point).map(|p| (p.tet, p.weights));
            }
            if let Some((tet, weights)) = f.bound {
                let point = BodyPoint { tet, weights };
                state.forces().apply_impulse_at(point, h * f.force);
            }
        }
    }
}

/// The rigid spheres and static colliders as the solver sees them during one step, gathered
/// once in [`SoftBodySystems::Prepare`]. The spheres are changed by the contact and volume passes
/// (particles pressed against a sphere move it) and written back in [`SoftBodySystems::Writeback`];
/// the colliders do not move within a step. Also the bodies' entities, scratch for the parallel
/// stages (`for_each_body`). The buffers are reused, so a step does not allocate.
#[derive(Resource, Default)]
pub struct SolverSpheres {
    pub(super) entities: Vec<Entity>,
    pub(super) states: Vec<RigidSphereState>,
    /// The spheres as they were before the stage running now (see [`par_with_spheres`]).
    pub(super) before: Vec<RigidSphereState>,
    pub(crate) colliders: Vec<ColliderInstance>,
    /// Rigid bodies another engine simulates (avian's, with the `avian` feature): their motion
    /// as the contacts change it during the step; a soft body's `RigidContacts` holds copies of
    /// those near it (`SoftBody::rigid_ids`).
    pub(crate) rigid: Vec<RigidBodyMotion>,
    /// The rigid bodies as they were before the stage running now.
    pub(super) rigid_before: Vec<RigidBodyMotion>,
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

/// Gathers the rigid spheres and static colliders as the solver sees them during the step.
pub(crate) fn gather_spheres(
    mut solver: ResMut<SolverSpheres>,
    spheres: Query<(Entity, &RigidSphere, &Transform)>,
    colliders: Query<(&StaticCollider, &Transform, Has<SoftBodyCutter>), Without<RigidSphere>>,
) {
    let solver = &mut *solver;
    solver.entities.clear();
    solver.states.clear();
    for (entity, sphere, transform) in &spheres {
        solver.entities.push(entity);
        solver.states.push(sphere_state(sphere, transform));
    }
    solver.colliders.clear();
    for (collider, transform, cuts) in &colliders {
        let pose = Pose::from_parts(transform.translation, transform.rotation);
        let mut instance = ColliderInstance::new(collider.shape.clone(), pose, collider.friction);
        instance.cuts = cuts;
        solver.colliders.push(instance);
    }
}

/// The resources every stage's system reads and writes.
#[derive(bevy::ecs::system::SystemParam)]
pub(super) struct StageParams<'w> {
    time: Res<'w, Time>,
    gravity: Res<'w, SoftBodyGravity>,
    solver: ResMut<'w, SolverSpheres>,
    clock: ResMut<'w, SoftBodyStepTime>,
    threads: Res<'w, SoftBodyThreads>,
}

impl StageParams<'_> {
    /// The step's length, `None` when no time passed (no step).
    fn step(&self) -> Option<f32> {
        let h = self.time.delta_secs();
        (h > 0.0).then_some(h)
    }
}

/// [`SoftBodySystems::Forces`]: the spheres' gravity, then every body's forces in parallel
/// (one body per job; a large body's blocks in parallel too when there are fewer bodies than
/// threads).
pub(super) fn forces(mut p: StageParams, mut bodies: Bodies) {
    let Some(h) = p.step() else { return };
    let start = Instant::now();
    let g = p.gravity.0;
    let solver = &mut *p.solver;
    spheres_before_bodies(Stage::Forces, h, g, &mut solver.states, &solver.colliders);
    let compute = ComputePool::new(&p.threads);
    let few = few_bodies(&bodies, &compute);
    par_with_spheres(&mut bodies, solver, &compute, false, |s, stats, _, _| {
        stats.contacts = 0;
        s.apply_forces(h, g, pass_parallelism(few, s, &compute));
    });
    p.clock.add_stage(start, Stage::Forces);
}

/// [`SoftBodySystems::Substeps`]: the spheres meet the static colliders, the bodies that may
/// touch each other run their substeps together (group after group), every other body its
/// own, in parallel. The wall-clock time is booked to the substep stages in the proportion
/// the bodies spent in each.
pub(super) fn substeps(
    mut p: StageParams,
    mut bodies: Bodies,
    mut groups: ResMut<SoftContactGroups>,
) {
    let Some(h) = p.step() else { return };
    let start = Instant::now();
    let g = p.gravity.0;
    let solver = &mut *p.solver;
    spheres_before_bodies(Stage::Substeps, h, g, &mut solver.states, &solver.colliders);
    let compute = ComputePool::new(&p.threads);
    let few = few_bodies(&bodies, &compute);
    find_groups(&mut bodies, h, g, &mut groups);
    substeps_of_groups(&mut bodies, &mut groups, solver, &compute, h);
    par_with_spheres(
        &mut bodies,
        solver,
        &compute,
        true,
        |s, stats, spheres, colliders| {
            let parallel = pass_parallelism(few, s, &compute);
            stats.contacts += s.run_substeps(h, spheres, colliders, parallel);
        },
    );
    let mut seconds = [0.0; 5];
    for (_, mut body, _) in bodies.iter_mut() {
        let taken = body.state.take_substep_seconds();
        for (total, s) in seconds.iter_mut().zip(taken) {
            *total += s;
        }
    }
    p.clock.add_substeps(start, seconds);
}

/// [`SoftBodySystems::Plasticity`]: the plastic bodies' flow; nothing (and no time) without
/// plastic bodies.
pub(super) fn plasticity(mut p: StageParams, mut bodies: Bodies) {
    let Some(h) = p.step() else { return };
    let plastic = |body: &SoftBody| body.state.material().plasticity.is_some();
    if !bodies.iter().any(|(_, body, _)| plastic(body)) {
        return;
    }
    let start = Instant::now();
    let compute = ComputePool::new(&p.threads);
    par_with_spheres(&mut bodies, &mut p.solver, &compute, false, |s, _, _, _| {
        s.apply_plasticity(h);
    });
    p.clock.add_stage(start, Stage::Plasticity);
}

/// [`SoftBodySystems::Finish`]: the spheres meet the static colliders, each body's sleep and
/// runaway check, the last soft-contact pass of the bodies stepped together, the spheres move.
pub(super) fn finish(
    mut p: StageParams,
    mut bodies: Bodies,
    mut groups: ResMut<SoftContactGroups>,
) {
    let Some(h) = p.step() else { return };
    let start = Instant::now();
    let g = p.gravity.0;
    let solver = &mut *p.solver;
    spheres_before_bodies(Stage::Finish, h, g, &mut solver.states, &solver.colliders);
    let compute = ComputePool::new(&p.threads);
    par_with_spheres(
        &mut bodies,
        solver,
        &compute,
        false,
        |s, stats, spheres, colliders| {
            s.finish_step(h, spheres, colliders);
            stats.steps += 1;
        },
    );
    final_pass_of_groups(&mut bodies, &mut groups, &compute);
    spheres_after_bodies(Stage::Finish, h, &mut solver.states);
    p.clock.add_stage(start, Stage::Finish);
}

/// Ends a step: the spheres' components follow the solver's spheres, the step's time is
/// closed.
pub(super) fn finish_step(
    time: Res<Time>,
    solver: Res<SolverSpheres>,
    mut clock: ResMut<SoftBodyStepTime>,
    mut spheres: Query<(&mut RigidSphere, &mut Transform), Without<StaticCollider>>,
) {
    if time.delta_secs() <= 0.0 {
        return;
    }
    for (entity, state) in solver.entities.iter().zip(&solver.states) {
        if let Ok((mut sphere, mut transform)) = spheres.get_mut(*entity) {
            sphere.velocity = state.velocity;
            transform.translation = state.position;
        }
    }
    clock.last_ms = clock.current.as_secs_f64() * 1e3;
    clock.total_ms += clock.last_ms;
    clock.max_ms = clock.max_ms.max(clock.last_ms);
    clock.steps += 1;
    clock.current = Duration::ZERO;
}

pub(super) fn writeback(
    mut bodies: Query<(Entity, &SoftBody, &mut SoftBodyStats, &mut Transform)>,
    threads: Res<SoftBodyThreads>,
    mut errors: MessageWriter<SoftBodyError>,
    mut torn: MessageWriter<SoftBodyTorn>,
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
    // (slower than inline for the soft cube). So do bodies kept to one thread.
    if bodies.iter().len() < 2 || ComputePool::new(&threads).threads < 2 {
        bodies.iter_mut().for_each(write);
    } else {
        bodies
            .par_iter_mut()
            .batching_strategy(ONE_BODY_PER_TASK)
            .for_each(write);
    }
    for (entity, body, _, _) in &bodies {
        let tears = body.state.tears();
        if !tears.is_empty() {
            let pieces = crate::core::pieces(body.state.mesh());
            torn.write(SoftBodyTorn {
                body: entity,
                points: tears.iter().map(|t| t.point).collect(),
                pieces: pieces.iter().max().map_or(0, |&p| p + 1),
            });
        }
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
