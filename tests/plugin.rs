//! The plugin's contract, headless with `MinimalPlugins`: momentum, contacts, bad input.

use std::sync::Arc;
use std::time::Duration;

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_soft_body::core::{Elasticity, TetMesh, TetMeshError, VolumeMethod, box_grid};
use bevy_soft_body::prelude::*;
use bevy_soft_body::{SoftBodyStageTimes, SoftBodyStepTime};
use glam::UVec3;

fn app(gravity: Vec3) -> App {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, SoftBodyPlugin::default()))
        .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(
            10,
        )))
        .insert_resource(SoftBodyGravity(gravity));
    app.update();
    app
}

/// Every `SoftBodyError` sent, in order.
#[derive(Resource, Default)]
struct SeenErrors(Vec<SoftBodyError>);

fn record_errors(app: &mut App) {
    app.init_resource::<SeenErrors>().add_systems(
        Update,
        |mut r: MessageReader<SoftBodyError>, mut seen: ResMut<SeenErrors>| {
            seen.0.extend(r.read().cloned());
        },
    );
}

fn cube(cells: u32) -> Arc<TetMesh> {
    Arc::new(box_grid(UVec3::splat(cells), Vec3::splat(0.1), Vec3::ZERO).unwrap())
}

fn material(method: VolumeMethod) -> SoftBodyMaterial {
    SoftBodyMaterial {
        method,
        ..SoftBodyMaterial::paper(1000.0, 1.0, 1.0)
    }
}

#[test]
fn free_body_conserves_momentum_with_every_method() {
    for method in [
        VolumeMethod::PAPER_IMPULSES,
        VolumeMethod::PAPER_BASELINE,
        VolumeMethod::XPBD,
    ] {
        let mut app = app(Vec3::ZERO);
        let mut body = SoftBody::new(cube(4), material(method)).unwrap();
        // A jumble of velocities: springs, damping and volume passes all act.
        for (i, v) in body.velocities_mut().iter_mut().enumerate() {
            let k = i as f32;
            *v = Vec3::new((k * 0.37).sin(), (k * 0.91).cos(), (k * 1.7).sin()) * 0.5;
        }
        let before = body.state().linear_momentum();
        let entity = app.world_mut().spawn(body).id();
        for _ in 0..100 {
            app.update();
        }
        let body = app.world().get::<SoftBody>(entity).unwrap();
        let after = body.state().linear_momentum();
        let stats = app.world().get::<SoftBodyStats>(entity).unwrap();
        assert_eq!(stats.steps, 100);
        assert!(
            (after - before).length() < 1e-3 * body.state().total_mass(),
            "{}: momentum {before} -> {after}",
            method.name()
        );
    }
}

#[test]
fn the_step_clock_times_each_stage_that_has_work_within_the_updates() {
    // The paper's springs (one substep a step) and a preset material (many substeps) on the
    // ground, so that every substep stage has work.
    for material in [
        material(VolumeMethod::PAPER_IMPULSES),
        SoftBodyMaterial::JELLY,
    ] {
        let mut app = app(Vec3::new(0.0, -9.81, 0.0));
        app.world_mut()
            .spawn((StaticCollider::ground(0.5), Transform::default()));
        app.world_mut().spawn((
            SoftBody::new(cube(4), material).unwrap(),
            Transform::from_xyz(0.0, 0.05, 0.0),
        ));
        assert_eq!(
            app.world().resource::<SoftBodyStepTime>().mean_stage_ms(),
            SoftBodyStageTimes::default()
        );
        let start = std::time::Instant::now();
        for _ in 0..20 {
            app.update();
        }
        // The clock times the stages as they run, once each: no more than the updates that
        // ran them took on the wall clock.
        let updates_ms = start.elapsed().as_secs_f64() * 1e3;
        let clock = app.world().resource::<SoftBodyStepTime>();
        assert_eq!(clock.steps, 20);
        let stages = clock.stages_total;
        assert!(
            clock.total_ms <= updates_ms,
            "the step clock says {} ms, the 20 updates took {updates_ms} ms",
            clock.total_ms
        );
        assert!((stages.sum_ms() - clock.total_ms).abs() < 1e-6 * clock.total_ms.max(1.0));
        // The stages that have work take time; the plasticity stage has none without plastic
        // bodies and returns before it starts its clock.
        for (name, ms) in [
            ("forces", stages.forces_ms),
            ("shape", stages.shape_ms),
            ("contacts", stages.contacts_ms),
            ("one-ring", stages.one_ring_ms),
            ("per-tet", stages.per_tet_ms),
            ("advance", stages.advance_ms),
            ("finish", stages.finish_ms),
        ] {
            assert!(ms > 0.0, "{name}: {ms} ms");
        }
        assert_eq!(stages.plasticity_ms, 0.0);
    }
}

/// What a system between two of the plugin's sets saw of the step in the last update.
#[derive(Resource, Default)]
struct SeenBetweenSets {
    /// The body's particles before the step's stages.
    before: Vec<Vec3>,
    /// Whether the particles had moved after the substeps, before the finish.
    moved_after_substeps: bool,
    /// The body's step count after the substeps (the finish counts the step).
    steps_after_substeps: u64,
    /// The body's step count after the finish.
    steps_after_finish: u64,
}

#[test]
fn a_system_between_two_sets_sees_the_first_and_not_the_second() {
    let mut app = app(Vec3::new(0.0, -9.81, 0.0));
    app.init_resource::<SeenBetweenSets>();
    app.add_systems(
        FixedUpdate,
        (
            (|bodies: Query<&SoftBody>, mut seen: ResMut<SeenBetweenSets>| {
                seen.before = bodies.single().unwrap().state().positions().to_vec();
            })
            .after(SoftBodySystems::Prepare)
            .before(SoftBodySystems::Forces),
            (|bodies: Query<(&SoftBody, &SoftBodyStats)>, mut seen: ResMut<SeenBetweenSets>| {
                let (body, stats) = bodies.single().unwrap();
                seen.moved_after_substeps = body.state().positions() != seen.before.as_slice();
                seen.steps_after_substeps = stats.steps;
            })
            .after(SoftBodySystems::Substeps)
            .before(SoftBodySystems::Finish),
            (|stats: Query<&SoftBodyStats>, mut seen: ResMut<SeenBetweenSets>| {
                seen.steps_after_finish = stats.single().unwrap().steps;
            })
            .after(SoftBodySystems::Finish)
            .before(SoftBodySystems::Writeback),
        ),
    );
    app.world_mut().spawn((
        SoftBody::new(cube(4), SoftBodyMaterial::JELLY).unwrap(),
        Transform::from_xyz(0.0, 1.0, 0.0),
    ));
    for step in 1..=5 {
        app.update();
        let seen = app.world().resource::<SeenBetweenSets>();
        assert!(
            seen.moved_after_substeps,
            "step {step}: the substeps moved nothing"
        );
        assert_eq!(seen.steps_after_substeps, step - 1, "step {step}");
        assert_eq!(seen.steps_after_finish, step, "step {step}");
    }
}

#[test]
fn no_particle_ends_a_step_inside_the_ground_or_a_tilted_box() {
    for method in [VolumeMethod::PAPER_IMPULSES, VolumeMethod::XPBD] {
        lands_without_penetrating(method);
    }
}

fn lands_without_penetrating(method: VolumeMethod) {
    let mut app = app(Vec3::new(0.0, -2.0, 0.0));
    let body = app
        .world_mut()
        .spawn((
            SoftBody::new(cube(4), material(method)).unwrap(),
            Transform::from_xyz(-0.2, 0.6, -0.2),
        ))
        .id();
    app.world_mut()
        .spawn((StaticCollider::ground(0.5), Transform::default()));
    // A box lying on the ground, tilted, that the body lands partly on.
    let tilt = Quat::from_rotation_z(0.3);
    app.world_mut().spawn((
        StaticCollider::new(parry3d::shape::SharedShape::cuboid(0.3, 0.1, 0.3), 0.5),
        Transform::from_xyz(0.3, 0.1, 0.0).with_rotation(tilt),
    ));
    let box_shape = parry3d::shape::Cuboid::new(Vec3::new(0.3, 0.1, 0.3));
    let pose = parry3d::math::Pose::from_parts(Vec3::new(0.3, 0.1, 0.0), tilt);
    let mut touched = 0;
    let mut inside_box_at_all = 0;
    for _ in 0..200 {
        app.update();
        let state = app.world().get::<SoftBody>(body).unwrap().state();
        for &p in state.positions() {
            assert!(p.y > -1e-4, "a particle is {} below the ground", -p.y);
            use parry3d::query::PointQuery;
            if box_shape.contains_point(&pose, p) {
                let depth = box_shape.project_point(&pose, p, false).point.distance(p);
                assert!(depth < 1e-3, "a particle is {depth} inside the box");
                inside_box_at_all += 1;
            }
        }
        touched += app.world().get::<SoftBodyStats>(body).unwrap().contacts;
    }
    assert!(touched > 0, "the body never touched anything");
    // Particles resting on the box's surface count as contained (within rounding): the body did
    // land on the box, which is what makes the check above mean something.
    assert!(inside_box_at_all > 0, "the body never reached the box");
}

#[test]
fn a_heavy_sphere_is_slowed_by_the_body_it_hits() {
    let mut app = app(Vec3::ZERO);
    app.world_mut()
        .spawn(SoftBody::new(cube(4), material(VolumeMethod::PAPER_IMPULSES)).unwrap());
    let mut sphere = RigidSphere::new(0.15, 20.0);
    sphere.velocity = Vec3::new(0.0, -1.0, 0.0);
    let s = app
        .world_mut()
        .spawn((sphere, Transform::from_xyz(0.2, 0.6, 0.2)))
        .id();
    for _ in 0..60 {
        app.update();
    }
    let v = app.world().get::<RigidSphere>(s).unwrap().velocity;
    assert!(v.y > -0.9, "the sphere went through unslowed: {v}");
}

#[test]
fn bad_input_gives_errors_not_panics() {
    // Bad meshes.
    let e = TetMesh::new(vec![Vec3::ZERO; 3], vec![[0, 1, 2, 3]]).unwrap_err();
    assert!(matches!(e, TetMeshError::IndexOutOfRange { .. }), "{e}");
    // Bad materials.
    let bad = SoftBodyMaterial {
        density: -1.0,
        ..Default::default()
    };
    assert!(SoftBody::new(cube(1), bad).is_err());
    let bad = SoftBodyMaterial {
        elasticity: Elasticity::Springs {
            distance_stiffness: 1.0,
            damping: f32::NAN,
        },
        ..Default::default()
    };
    assert!(SoftBody::new(cube(1), bad).is_err());
    let mut bad = SoftBodyMaterial::JELLY;
    if let Elasticity::Elastic(e) = &mut bad.elasticity {
        e.youngs_modulus = -1.0;
    }
    assert!(SoftBody::new(cube(1), bad).is_err());
    let mut bad = SoftBodyMaterial::JELLY;
    if let Elasticity::Elastic(e) = &mut bad.elasticity {
        e.max_substep = 0.0;
    }
    assert!(SoftBody::new(cube(1), bad).is_err());
    let bad = SoftBodyMaterial {
        method: VolumeMethod::Impulses(ImpulseSettings {
            gamma: 2.0,
            ..Default::default()
        }),
        ..Default::default()
    };
    assert!(SoftBody::new(cube(1), bad).is_err());
    let bad = SoftBodyMaterial {
        method: VolumeMethod::Impulses(ImpulseSettings {
            ring_tet_tolerance: f32::NAN,
            ..Default::default()
        }),
        ..Default::default()
    };
    assert!(SoftBody::new(cube(1), bad).is_err());
    // Out-of-range pinned particles and a driven target that does not exist: logged, the game
    // goes on, and the valid indices still apply.
    let mut app = app(Vec3::new(0.0, -1.0, 0.0));
    record_errors(&mut app);
    let missing = app.world_mut().spawn_empty().id();
    app.world_mut().despawn(missing);
    let body = app
        .world_mut()
        .spawn((
            SoftBody::new(cube(2), material(VolumeMethod::PAPER_IMPULSES)).unwrap(),
            PinnedParticles(vec![0, 10_000]),
            DrivenParticles::new(missing, vec![1]),
        ))
        .id();
    let start = app
        .world()
        .get::<SoftBody>(body)
        .unwrap()
        .state()
        .positions()[0];
    for _ in 0..20 {
        app.update();
    }
    let state = app.world().get::<SoftBody>(body).unwrap().state();
    assert_eq!(
        state.positions()[0],
        start,
        "the valid pinned particle moved"
    );
    assert!(
        state.centre_of_mass().y < 0.1,
        "the rest of the body did not fall"
    );
    // Each problem is reported once, as a message a game can read, not once per step.
    let seen = &app.world().resource::<SeenErrors>().0;
    let count = state.positions().len();
    assert_eq!(
        seen,
        &vec![
            SoftBodyError {
                body,
                kind: SoftBodyErrorKind::ParticleOutOfRange {
                    index: 10_000,
                    count
                }
            },
            SoftBodyError {
                body,
                kind: SoftBodyErrorKind::MissingDriveTarget(missing)
            },
        ]
    );
}

#[test]
fn velocities_given_before_a_scaled_spawn_are_kept() {
    let mut app = app(Vec3::ZERO);
    let mut soft = SoftBody::new(cube(2), material(VolumeMethod::PAPER_IMPULSES)).unwrap();
    for v in soft.velocities_mut() {
        *v = Vec3::new(1.0, 0.0, 0.0);
    }
    let body = app
        .world_mut()
        .spawn((soft, Transform::from_scale(Vec3::splat(3.0))))
        .id();
    for _ in 0..5 {
        app.update();
    }
    let state = app.world().get::<SoftBody>(body).unwrap().state();
    for v in state.velocities() {
        assert!(v.distance(Vec3::X) < 1e-3, "{v}");
    }
}

#[test]
fn spawn_transform_places_rotates_and_scales_the_body() {
    let mut app = app(Vec3::ZERO);
    let mesh = cube(2);
    let rest_volume = mesh.total_rest_volume();
    let rotation = Quat::from_rotation_y(0.7);
    let body = app
        .world_mut()
        .spawn((
            SoftBody::new(mesh, material(VolumeMethod::PAPER_IMPULSES)).unwrap(),
            Transform::from_xyz(3.0, 1.0, -2.0)
                .with_rotation(rotation)
                .with_scale(Vec3::new(2.0, 1.0, 1.0)),
        ))
        .id();
    app.update();
    let state = app.world().get::<SoftBody>(body).unwrap().state();
    // The scale is baked into the rest shape: twice the volume, and nothing to restore.
    let scaled = state.mesh().total_rest_volume();
    assert!(
        (scaled - 2.0 * rest_volume).abs() < 1e-6 * scaled,
        "{scaled} vs {rest_volume}"
    );
    assert!(state.volume_metrics().volume_error_pct.abs() < 1e-3);
    // Particle 0 sits where the transform puts the rest vertex 0.
    let local = state.mesh().positions()[0];
    let expected = Vec3::new(3.0, 1.0, -2.0) + rotation * local;
    assert!(
        state.positions()[0].distance(expected) < 1e-4,
        "{} vs {expected}",
        state.positions()[0]
    );
    // From then on the entity's transform follows the body's centre of mass.
    let transform = app.world().get::<Transform>(body).unwrap();
    assert!(transform.translation.distance(state.centre_of_mass()) < 1e-4);
    assert_eq!(transform.rotation, Quat::IDENTITY);
    assert_eq!(transform.scale, Vec3::ONE);
}

#[test]
fn a_mesh_whose_tets_fold_is_reported_once_when_placed() {
    // A cube whose inner vertex is moved most of a cell towards the opposite corner: the tets on
    // that side turn inside out and fold over their neighbours. The body is still simulated,
    // and said to be broken once.
    let grid = cube(3);
    let mut positions = grid.positions().to_vec();
    let tets = grid.tets().to_vec();
    let centre = positions
        .iter()
        .position(|p| p.distance(Vec3::splat(0.1)) < 1e-6)
        .unwrap();
    positions[centre] += Vec3::splat(0.09);
    let broken = Arc::new(TetMesh::new(positions, tets).unwrap());
    assert!(broken.defects().folded_count > 0, "{}", broken.defects());

    let mut app = app(Vec3::ZERO);
    record_errors(&mut app);
    let material = material(VolumeMethod::PAPER_IMPULSES);
    let folded = app
        .world_mut()
        .spawn(SoftBody::new(broken.clone(), material).unwrap())
        .id();
    let clean = app
        .world_mut()
        .spawn(SoftBody::new(cube(3), material).unwrap())
        .id();
    for _ in 0..10 {
        app.update();
    }
    let seen = &app.world().resource::<SeenErrors>().0;
    assert_eq!(
        seen,
        &vec![SoftBodyError {
            body: folded,
            kind: SoftBodyErrorKind::MeshDefects(broken.defects().clone()),
        }]
    );
    assert!(!seen.iter().any(|e| e.body == clean));
    let message = seen[0].to_string();
    for &[a, b] in &broken.defects().folded {
        assert!(message.contains(&format!("{a}/{b}")), "{message}");
    }
    assert_eq!(app.world().get::<SoftBodyStats>(folded).unwrap().steps, 10);
}

/// The plugin group, every feature on, fits a headless app (`MinimalPlugins`, as the README
/// teaches for servers and tests): the parts that need assets or meshes stay out of an app that
/// has none, and a jelly dropped at Earth gravity lands and keeps its volume.
#[test]
fn the_plugin_group_steps_a_jelly_headless() {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, SoftBodyPlugins))
        .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(
            10,
        )));
    record_errors(&mut app);
    app.update();
    let mesh = Arc::new(box_grid(UVec3::splat(6), Vec3::splat(0.5 / 6.0), Vec3::ZERO).unwrap());
    let body = app
        .world_mut()
        .spawn((
            SoftBody::new(mesh, SoftBodyMaterial::JELLY).unwrap(),
            Transform::from_xyz(-0.25, 0.3, -0.25),
        ))
        .id();
    app.world_mut()
        .spawn((StaticCollider::ground(0.8), Transform::default()));
    let mut touched = 0;
    for _ in 0..200 {
        app.update();
        touched += app.world().get::<SoftBodyStats>(body).unwrap().contacts;
    }
    let stats = app.world().get::<SoftBodyStats>(body).unwrap();
    assert!(stats.steps >= 190, "{} steps in 2 s", stats.steps);
    assert!(touched > 0, "the jelly never landed");
    assert!(
        stats.peak_volume_error_pct < 1.0,
        "peak volume error {} %",
        stats.peak_volume_error_pct
    );
    assert!(app.world().resource::<SeenErrors>().0.is_empty());
}

/// A body's settings are components: they show in the type registry (an inspector), and
/// inserting, changing or removing one changes the body from the next step.
#[test]
fn settings_components_apply_live_and_are_reflected() {
    let mut app = app(Vec3::new(0.0, -9.81, 0.0));
    {
        let registry = app.world().resource::<AppTypeRegistry>().read();
        for (name, id) in [
            ("contacts", std::any::TypeId::of::<SoftBodyContacts>()),
            (
                "no contacts",
                std::any::TypeId::of::<SoftBodyContactsDisabled>(),
            ),
            ("sleep", std::any::TypeId::of::<SoftBodySleepThreshold>()),
            (
                "no sleep",
                std::any::TypeId::of::<SoftBodySleepingDisabled>(),
            ),
            ("runaway", std::any::TypeId::of::<SoftBodyRunawayLimits>()),
        ] {
            let registered = registry.get(id);
            assert!(
                registered.is_some_and(|r| r.data::<ReflectComponent>().is_some()),
                "{name} is not a reflected component"
            );
        }
    }
    record_errors(&mut app);
    app.world_mut()
        .spawn((StaticCollider::ground(0.8), Transform::default()));
    // A rubber cube resting on the ground sleeps only once its component allows it.
    let body = app
        .world_mut()
        .spawn((
            SoftBody::new(cube(4), SoftBodyMaterial::RUBBER).unwrap(),
            Transform::from_xyz(0.0, 0.01, 0.0),
            SoftBodySleepingDisabled,
        ))
        .id();
    let sleeping = |app: &App| app.world().get::<SoftBodyStats>(body).unwrap().sleeping;
    for _ in 0..300 {
        app.update();
        assert!(!sleeping(&app), "asleep although sleeping is disabled");
    }
    app.world_mut()
        .entity_mut(body)
        .remove::<SoftBodySleepingDisabled>();
    let mut asleep = false;
    for _ in 0..300 {
        app.update();
        asleep |= sleeping(&app);
    }
    assert!(asleep, "the resting cube never fell asleep once allowed to");
    // Limits a thrown body passes: it is caught and reported; with the default limits back,
    // the same throw is not.
    app.world_mut()
        .entity_mut(body)
        .insert(SoftBodyRunawayLimits {
            max_speed: 2.0,
            ..default()
        });
    let throw = |app: &mut App| {
        let mut soft = app.world_mut().get_mut::<SoftBody>(body).unwrap();
        soft.velocities_mut().fill(Vec3::new(3.0, 3.0, 0.0));
    };
    throw(&mut app);
    app.update();
    let runaways = |app: &App| {
        let seen = &app.world().resource::<SeenErrors>().0;
        seen.iter()
            .filter(|e| matches!(e.kind, SoftBodyErrorKind::Runaway(_)))
            .count()
    };
    assert_eq!(runaways(&app), 1);
    app.world_mut()
        .entity_mut(body)
        .insert(SoftBodyRunawayLimits::default());
    for _ in 0..200 {
        app.update();
    }
    throw(&mut app);
    for _ in 0..10 {
        app.update();
    }
    assert_eq!(runaways(&app), 1);
}

/// A platform the game moves in `FixedUpdate` before the soft bodies' step (as it should:
/// `SoftBodySystems::Prepare` reads it), 0.5 m/s along x.
#[derive(Component)]
struct Platform;

fn move_platform(time: Res<Time>, mut platforms: Query<&mut Transform, With<Platform>>) {
    for mut t in &mut platforms {
        t.translation.x += 0.5 * time.delta_secs();
    }
}

#[test]
fn driven_particles_follow_their_target_without_a_step_of_lag() {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, SoftBodyPlugin::default()))
        .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(
            10,
        )))
        .add_systems(FixedUpdate, move_platform.before(SoftBodySystems::Prepare));
    let mesh = box_grid(UVec3::new(8, 2, 2), Vec3::splat(0.05), Vec3::ZERO).unwrap();
    let left: Vec<u32> = (0..mesh.positions().len() as u32)
        .filter(|&i| mesh.positions()[i as usize].x < 0.01)
        .collect();
    let rest: Vec<Vec3> = mesh.positions().to_vec();
    let platform = app
        .world_mut()
        .spawn((Platform, Transform::from_xyz(0.0, 1.0, 0.0)))
        .id();
    let bar = SoftBody::new(mesh.into(), SoftBodyMaterial::JELLY).unwrap();
    let body = app
        .world_mut()
        .spawn((
            bar,
            DrivenParticles::new(platform, left.clone()),
            Transform::from_xyz(0.0, 1.0, 0.0),
        ))
        .id();
    let _ = rest;
    let mut last: Option<(Vec3, Vec<Vec3>)> = None;
    for _ in 0..50 {
        app.update();
        if !app.world().get::<SoftBody>(body).unwrap().is_placed() {
            continue;
        }
        // In each step the held particles move as the platform moved before it, not as it
        // moved a step earlier.
        let target = app.world().get::<Transform>(platform).unwrap().translation;
        let state = app.world().get::<SoftBody>(body).unwrap().state();
        let held: Vec<Vec3> = left
            .iter()
            .map(|&i| state.positions()[i as usize])
            .collect();
        if let Some((last_target, last_held)) = &last {
            for (at, was) in held.iter().zip(last_held) {
                let moved = *at - *was;
                assert!((moved - (target - *last_target)).length() < 1e-5, "{moved}");
            }
        }
        last = Some((target, held));
    }
    assert!(
        app.world()
            .get::<Transform>(platform)
            .unwrap()
            .translation
            .x
            > 0.2
    );
}
