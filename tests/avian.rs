//! Soft bodies among avian3d's rigid bodies (feature `avian`), headless: `MinimalPlugins`,
//! avian's `PhysicsPlugins` and the soft-body plugins, stepped at a manual 10 ms.

use std::sync::Arc;
use std::time::Duration;

use avian3d::prelude::*;
use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_soft_body::avian::{SoftBodyAttachment, SoftBodyAvianPlugin};
use bevy_soft_body::core::{ParticleRegion, TetMesh, box_grid};
use bevy_soft_body::prelude::*;
use bevy_soft_body::{SoftBodyError, SoftBodyErrorKind};
use glam::{Mat3, UVec3};

fn app(gravity: Vec3, max_threads: usize) -> App {
    let mut app = App::new();
    app.add_plugins((
        MinimalPlugins,
        TransformPlugin,
        PhysicsPlugins::default(),
        SoftBodyPlugin::default(),
        SoftBodyAvianPlugin,
    ))
    .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(
        10,
    )))
    .insert_resource(Gravity(gravity))
    .insert_resource(SoftBodyThreads { max_threads });
    // Avian sets some of its resources up in `finish`, which `App::run` calls.
    app.finish();
    app.cleanup();
    app.update();
    app
}

/// A jelly cube of `side` metres in 6 cells a side, its lowest corner at `corner`.
fn jelly(side: f32, corner: Vec3) -> SoftBody {
    let mesh: Arc<TetMesh> = box_grid(UVec3::splat(6), Vec3::splat(side / 6.0), Vec3::ZERO)
        .unwrap()
        .into();
    let mut body = SoftBody::new(mesh, SoftBodyMaterial::JELLY).unwrap();
    body.translate(corner);
    body
}

/// A dynamic crate of half extents `half` and mass `mass` at `at`.
fn crate_body(half: Vec3, mass: f32, at: Vec3) -> impl Bundle {
    (
        RigidBody::Dynamic,
        Collider::cuboid(2.0 * half.x, 2.0 * half.y, 2.0 * half.z),
        Mass(mass),
        Transform::from_translation(at),
    )
}

/// Linear momentum, and angular momentum about the origin, of every soft body and avian body.
fn momentum(app: &mut App) -> (Vec3, Vec3) {
    let (mut linear, mut angular) = (Vec3::ZERO, Vec3::ZERO);
    let world = app.world_mut();
    for body in world.query::<&SoftBody>().iter(world) {
        let s = body.state();
        for ((&x, &v), &m) in s.positions().iter().zip(s.velocities()).zip(s.masses()) {
            linear += m * v;
            angular += x.cross(m * v);
        }
    }
    for (position, rotation, v, w, mass, inertia, com) in world
        .query::<(
            &Position,
            &Rotation,
            &LinearVelocity,
            &AngularVelocity,
            &ComputedMass,
            &ComputedAngularInertia,
            &ComputedCenterOfMass,
        )>()
        .iter(world)
    {
        let p = mass.value() * v.0;
        let turn = Mat3::from_quat(rotation.0);
        let inertia = turn * inertia.inverse().to_mat3().inverse() * turn.transpose();
        linear += p;
        angular += inertia * w.0 + (position.0 + rotation.0 * com.0).cross(p);
    }
    (linear, angular)
}

/// A spinning crate thrown off-centre at a jelly floating in space: the jelly dents and is
/// pushed and turned, the crate is slowed and turned, and the momentum of the two, linear and
/// angular, is what it was. Tolerances: linear momentum within 0.5 % of what the crate carried
/// in; angular within 3 % of the crate's (a contact's impulse acts on the particle where it is
/// and on the crate at its surface, a lever of up to a particle's depth in the crate).
#[test]
fn a_soft_rigid_impact_conserves_momentum() {
    let mut app = app(Vec3::ZERO, usize::MAX);
    let soft = app.world_mut().spawn(jelly(0.3, Vec3::ZERO)).id();
    let half = Vec3::new(0.1, 0.06, 0.08);
    let rigid = app
        .world_mut()
        .spawn((
            crate_body(half, 4.0, Vec3::new(0.22, 0.45, 0.12)),
            LinearVelocity(Vec3::new(0.2, -3.0, 0.1)),
            AngularVelocity(Vec3::new(2.0, 0.5, -3.0)),
        ))
        .id();
    app.update();
    let (linear0, angular0) = momentum(&mut app);
    let crate_p0 = 4.0 * 3.0f32.hypot(0.2);
    for _ in 0..40 {
        app.update();
    }
    let (linear1, angular1) = momentum(&mut app);
    let v = app.world().get::<LinearVelocity>(rigid).unwrap().0;
    assert!(v.y > -2.0, "the crate was not slowed: {v}");
    let soft_v = {
        let s = app.world().get::<SoftBody>(soft).unwrap().state();
        s.velocities().iter().sum::<Vec3>() / s.velocities().len() as f32
    };
    assert!(soft_v.y < -0.3, "the jelly was not pushed: {soft_v}");
    assert!(
        (linear1 - linear0).length() < 5e-3 * crate_p0,
        "linear momentum {linear0} -> {linear1}"
    );
    assert!(
        (angular1 - angular0).length() < 0.03 * angular0.length().max(crate_p0 * 0.3),
        "angular momentum {angular0} -> {angular1}"
    );
    println!(
        "linear momentum {linear0} -> {linear1}, angular {angular0} -> {angular1}, crate's {crate_p0}"
    );
}

/// How deep `x` is inside the box of half extents `half` at `position`, `rotation` (zero
/// outside).
fn depth_inside_box(x: Vec3, half: Vec3, position: Vec3, rotation: Quat) -> f32 {
    let local = rotation.inverse() * (x - position);
    (half - local.abs()).min_element().max(0.0)
}

/// A 2 kg crate dropped on a jelly on avian's ground comes to rest on it within 5 s, under
/// each volume method: over the next 3 s it moves less than 2 mm and turns less than a degree
/// (its velocity within a step is not zero: each step it presses the jelly's top down by about
/// `g h^2 / 2` and the jelly pushes it back), held up by the jelly, with no particle inside it,
/// and the jelly keeps its volume under it. Without static friction on the crate, or with the
/// crate moved at its velocity after each step rather than along its path within it (see
/// `RigidBodyMotion::position_correction`), it crept across the jelly (PERFORMANCE.md, stop 58).
#[test]
fn a_crate_comes_to_rest_on_a_jelly() {
    for method in [
        VolumeMethod::PAPER_IMPULSES,
        VolumeMethod::XPBD,
        VolumeMethod::XPBD_CLUSTERS,
    ] {
        crate_comes_to_rest_on_a_jelly(method);
    }
}

fn crate_comes_to_rest_on_a_jelly(method: VolumeMethod) {
    let mut app = app(Vec3::new(0.0, -9.81, 0.0), usize::MAX);
    app.world_mut().spawn((
        RigidBody::Static,
        Collider::half_space(Vec3::Y),
        Transform::default(),
    ));
    let mut jelly = jelly(0.3, Vec3::new(-0.15, 0.0, -0.15));
    jelly
        .set_material(SoftBodyMaterial::JELLY.with_method(method))
        .unwrap();
    let soft = app.world_mut().spawn(jelly).id();
    let half = Vec3::new(0.1, 0.05, 0.1);
    let rigid = app
        .world_mut()
        .spawn(crate_body(half, 2.0, Vec3::new(0.02, 0.45, -0.01)))
        .id();
    let pose = |app: &App| {
        let world = app.world();
        (
            world.get::<Position>(rigid).unwrap().0,
            world.get::<Rotation>(rigid).unwrap().0,
        )
    };
    for _ in 0..500 {
        app.update();
    }
    let (position5, rotation5) = pose(&app);
    let mut max_inside = 0.0f32;
    for _ in 0..300 {
        app.update();
        let (position, rotation) = pose(&app);
        let body = app.world().get::<SoftBody>(soft).unwrap().state();
        for &x in body.positions() {
            max_inside = max_inside.max(depth_inside_box(x, half, position, rotation));
        }
    }
    let (position, rotation) = pose(&app);
    let moved = position.distance(position5);
    let turned = rotation.angle_between(rotation5).to_degrees();
    assert!(
        moved < 2e-3 && turned < 1.0,
        "{method:?}: moved {moved} m, turned {turned} deg"
    );
    // Resting on the jelly (its top is at 0.3 m, pressed down a little), not on the ground.
    assert!(
        position.y > 0.25 + half.y && position.y < 0.31 + half.y,
        "{method:?}: crate at {position}"
    );
    assert!(
        max_inside < 2e-3,
        "{method:?}: a particle {max_inside} m inside the crate"
    );
    let body = app.world().get::<SoftBody>(soft).unwrap().state();
    let error = body.volume_metrics().volume_error_pct;
    assert!(error.abs() < 1.0, "{method:?}: volume error {error} %");
    println!(
        "{method:?}: moved {moved} m, turned {turned} deg in 3 s, deepest particle {max_inside} m, \
         volume {error} %"
    );
}

/// The same scene on one thread and on every thread of the pool ends in the same state, bit for
/// bit: two jellies under one crate, so that both push it in the same stages.
#[test]
fn results_do_not_depend_on_the_threads() {
    let run = |max_threads| {
        let mut app = app(Vec3::new(0.0, -9.81, 0.0), max_threads);
        app.world_mut().spawn((
            RigidBody::Static,
            Collider::half_space(Vec3::Y),
            Transform::default(),
        ));
        for x in [-0.32, 0.02] {
            app.world_mut().spawn(jelly(0.3, Vec3::new(x, 0.0, -0.15)));
        }
        let rigid = app
            .world_mut()
            .spawn(crate_body(
                Vec3::new(0.3, 0.05, 0.1),
                3.0,
                Vec3::new(0.0, 0.4, 0.0),
            ))
            .id();
        for _ in 0..60 {
            app.update();
        }
        let world = app.world_mut();
        let mut positions: Vec<Vec3> = Vec::new();
        for body in world.query::<&SoftBody>().iter(world) {
            positions.extend_from_slice(body.state().positions());
        }
        (positions, world.get::<Position>(rigid).unwrap().0)
    };
    let one = run(1);
    assert!(one.1.y < 0.39, "the crate fell onto the jellies: {}", one.1);
    assert_eq!(run(usize::MAX), one);
}

/// Angle of `rotation` about the z axis, radians.
fn angle_about_z(rotation: Quat) -> f32 {
    let (axis, angle) = rotation.to_axis_angle();
    axis.z.signum() * angle
}

/// A 1 m beam balanced on a hinge at its middle, with a 0.2 m jelly bag hung from its right
/// end by the bag's top layer of particles (picked by a region of the rest shape): the bag
/// pulls that end down and swings the beam, and the top layer stays on the beam. Without the
/// bag the beam stays level.
#[test]
fn a_hanging_bag_swings_the_beam() {
    let swing = |with_bag: bool| {
        let mut app = app(Vec3::new(0.0, -9.81, 0.0), usize::MAX);
        let pivot = Vec3::new(0.0, 2.0, 0.0);
        let anchor = app
            .world_mut()
            .spawn((RigidBody::Static, Transform::from_translation(pivot)))
            .id();
        let beam = app
            .world_mut()
            .spawn((
                RigidBody::Dynamic,
                Collider::cuboid(1.0, 0.1, 0.1),
                Mass(2.0),
                Transform::from_translation(pivot),
            ))
            .id();
        app.world_mut()
            .spawn(RevoluteJoint::new(anchor, beam).with_anchor(pivot));
        let mut bag = None;
        if with_bag {
            let mesh: Arc<TetMesh> = box_grid(UVec3::splat(6), Vec3::splat(0.2 / 6.0), Vec3::ZERO)
                .unwrap()
                .into();
            let top = mesh.particles_in(ParticleRegion::Box {
                min: Vec3::new(-1.0, 0.2 - 1e-4, -1.0),
                max: Vec3::splat(1.0),
            });
            assert_eq!(top.len(), 49);
            let mut body = SoftBody::new(mesh, SoftBodyMaterial::JELLY).unwrap();
            body.translate(Vec3::new(0.3, 1.74, -0.1));
            bag = Some(
                app.world_mut()
                    .spawn((body, SoftBodyAttachment::hard(beam, top.clone())))
                    .id(),
            );
        }
        app.update();
        let start: Vec<Vec3> = bag.map_or(Vec::new(), |bag| {
            let state = app.world().get::<SoftBody>(bag).unwrap().state();
            state.positions().to_vec()
        });
        let beam_start = *app.world().get::<Rotation>(beam).unwrap();
        for _ in 0..20 {
            app.update();
        }
        let world = app.world();
        let rotation = world.get::<Rotation>(beam).unwrap();
        let turned = angle_about_z(rotation.0) - angle_about_z(beam_start.0);
        // How far the top layer drifted from where it hangs on the beam.
        let mut drift = 0.0f32;
        if let Some(bag) = bag {
            let state = world.get::<SoftBody>(bag).unwrap().state();
            let turn = rotation.0 * beam_start.0.inverse();
            for (i, &x) in state.positions().iter().enumerate() {
                if start[i].y > 1.94 - 1e-3 {
                    let held = pivot + turn * (start[i] - pivot);
                    drift = drift.max(x.distance(held));
                }
            }
        }
        let spin = world.get::<AngularVelocity>(beam).unwrap().0.length();
        (turned, drift, spin)
    };
    let (level, ..) = swing(false);
    assert!(level.abs() < 0.01, "the bare beam turned {level} rad");
    let (turned, drift, spin) = swing(true);
    // The bag's end (+x) goes down: a clockwise turn about z. Free of the beam's hinge
    // friction, a 8.4 kg bag on a 0.45 m arm turns beam and bag (about 1.9 kg m^2) at about
    // 20 rad/s^2: some 0.4 rad in 0.2 s.
    assert!(
        turned < -0.2 && turned > -0.8,
        "the beam turned {turned} rad"
    );
    // Avian moves the beam after the soft step has held the particles where the beam was
    // predicted to go: they lag it by at most one step of its motion at the 0.5 m tip.
    let lag = spin * 0.01 * 0.5;
    assert!(
        drift < lag + 1e-3,
        "the top layer drifted {drift} m from the beam (lag {lag} m)"
    );
    println!(
        "beam turned {turned} rad in 0.2 s; top layer within {drift} m of the beam (one step: {lag} m)"
    );
}

/// The centre of mass of a soft body.
fn centre(app: &App, body: Entity) -> Vec3 {
    app.world()
        .get::<SoftBody>(body)
        .unwrap()
        .state()
        .centre_of_mass()
}

/// A rubber cube on an avian box tilted by 30 degrees slides down it when the pair's friction
/// (avian's `Friction` on the collider combined with the material's, geometric mean) is below
/// tan 30 = 0.58: from rest it gains about `g (sin 30 - 0.1 cos 30) = 4.06 m/s^2`, some 2 m in
/// the second (from 60 % to 120 % of that). With friction 1.2 it stays.
#[test]
fn a_rubber_cube_slides_down_a_slippery_tilted_box_and_stays_on_a_rough_one() {
    let slide = |friction: f32| {
        let mut app = app(Vec3::new(0.0, -9.81, 0.0), usize::MAX);
        let tilt = Quat::from_rotation_z(-30f32.to_radians());
        app.world_mut().spawn((
            RigidBody::Static,
            Collider::cuboid(4.0, 0.2, 1.0),
            Friction::new(friction),
            Transform::from_translation(Vec3::new(0.0, 1.0, 0.0)).with_rotation(tilt),
        ));
        let cube = SoftBody::new(
            box_grid(UVec3::splat(4), Vec3::splat(0.05), Vec3::ZERO)
                .unwrap()
                .into(),
            SoftBodyMaterial {
                friction,
                ..SoftBodyMaterial::RUBBER
            },
        )
        .unwrap();
        // On the box's top face, tilted with it, 5 mm above it.
        let top = Vec3::new(0.0, 1.0, 0.0) + tilt * Vec3::new(0.0, 0.1, 0.0);
        let placement = Transform::from_translation(top + tilt * Vec3::new(-0.1, 0.005, -0.1))
            .with_rotation(tilt);
        let body = app.world_mut().spawn((cube, placement)).id();
        app.update();
        let start = centre(&app, body);
        for _ in 0..100 {
            app.update();
        }
        let moved = centre(&app, body) - start;
        // Down the slope: the slope's direction is the box's +x turned by the tilt (down to
        // the right).
        moved.dot(tilt * Vec3::X)
    };
    let icy = slide(0.1);
    assert!(
        (1.2..2.4).contains(&icy),
        "on a slippery box the cube slid {icy} m in 1 s"
    );
    let rough = slide(1.2);
    assert!(
        rough.abs() < 0.02,
        "on a rough box the cube slid {rough} m in 1 s"
    );
    println!("slid {icy} m in 1 s (friction 0.1), {rough} m (friction 1.2)");
}

/// A jelly on a kinematic avian platform that starts at 1 m/s slides on it until friction has
/// brought its base up to speed (a rigid block would slide `v^2 / (2 mu g)`, 10 cm at friction
/// 0.5), then rides along: over the last second of 2.4 s its base moves with the platform
/// (under 2 mm of slip) and so does the jelly (its centre within 2 cm), its base has slid at
/// most 1.5 times the rigid block's slide, and it is still on the platform. The soft jelly keeps wobbling on its base for a second or two after the start, its
/// centre swinging several centimetres about the base: a shorter window measures where in that
/// swing it ends, not whether it rides.
#[test]
fn a_jelly_rides_a_moving_platform() {
    let mut app = app(Vec3::new(0.0, -9.81, 0.0), usize::MAX);
    let platform = app
        .world_mut()
        .spawn((
            RigidBody::Kinematic,
            Collider::cuboid(6.0, 0.2, 1.0),
            LinearVelocity(Vec3::new(1.0, 0.0, 0.0)),
            Transform::from_xyz(0.0, 0.5, 0.0),
        ))
        .id();
    let jelly = jelly(0.2, Vec3::new(-0.1, 0.6, -0.1));
    // The jelly's base: its lowest layer of particles.
    let base: Vec<usize> = (jelly.state().positions().iter().enumerate())
        .filter(|(_, x)| x.y < 0.6 + 1e-4)
        .map(|(i, _)| i)
        .collect();
    let body = app.world_mut().spawn(jelly).id();
    // The base's and the centre's offsets from the platform, along the motion.
    let offsets = |app: &App| {
        let state = app.world().get::<SoftBody>(body).unwrap().state();
        let x = app.world().get::<Position>(platform).unwrap().0.x;
        let base_x = base.iter().map(|&i| state.positions()[i].x).sum::<f32>() / base.len() as f32;
        (base_x - x, state.centre_of_mass().x - x)
    };
    for _ in 0..140 {
        app.update();
    }
    let (base_before, centre_before) = offsets(&app);
    for _ in 0..100 {
        app.update();
    }
    let (base_after, centre_after) = offsets(&app);
    let (slip, drift) = (base_after - base_before, centre_after - centre_before);
    println!(
        "base {:.1} cm behind the platform after 1.4 s; in the last second it slipped {:.2} mm, \
         the centre {:.2} cm",
        -100.0 * base_before,
        1000.0 * slip,
        100.0 * drift
    );
    assert!(
        slip.abs() < 2e-3,
        "the base slipped {slip} m in the last second"
    );
    assert!(
        drift.abs() < 0.02,
        "the centre drifted {drift} m in the last second"
    );
    // 1.5 times the rigid block's slide.
    assert!(
        base_after.abs() < 0.15,
        "the base is {base_after} m from where it started"
    );
    assert!(centre(&app, body).y > 0.6, "the jelly fell off or sank");
}

/// An attachment to an entity that is not an avian body, and one naming a particle the body
/// does not have, are reported once each as errors naming what is wrong; nothing panics and
/// the bodies go on (the valid particles of the second stay attached).
#[test]
fn bad_attachments_are_reported_not_panicked() {
    let mut app = app(Vec3::new(0.0, -9.81, 0.0), usize::MAX);
    let not_a_body = app.world_mut().spawn(Transform::default()).id();
    let hook = app
        .world_mut()
        .spawn((RigidBody::Static, Transform::from_xyz(0.0, 2.0, 0.0)))
        .id();
    let lost = app
        .world_mut()
        .spawn((
            jelly(0.2, Vec3::new(-2.0, 1.0, 0.0)),
            SoftBodyAttachment::hard(not_a_body, vec![0]),
        ))
        .id();
    let hung = app
        .world_mut()
        .spawn((
            jelly(0.2, Vec3::new(2.0, 1.8, 0.0)),
            SoftBodyAttachment::hard(hook, vec![0, 1_000_000]),
        ))
        .id();
    let mut reported = Vec::new();
    for _ in 0..30 {
        app.update();
        let messages = app.world().resource::<Messages<SoftBodyError>>();
        reported.extend(messages.iter_current_update_messages().cloned());
    }
    assert_eq!(reported.len(), 2, "{reported:?}");
    assert!(reported.iter().any(|e| e.body == lost
        && matches!(e.kind, SoftBodyErrorKind::MissingDriveTarget(t) if t == not_a_body)));
    assert!(reported.iter().any(|e| e.body == hung
        && matches!(
            e.kind,
            SoftBodyErrorKind::ParticleOutOfRange {
                index: 1_000_000,
                ..
            }
        )));
    // Particle 0 of the hung jelly is still where it was attached; the lost one fell.
    let held = app
        .world()
        .get::<SoftBody>(hung)
        .unwrap()
        .state()
        .positions()[0];
    assert!(
        held.distance(Vec3::new(2.0, 1.8, 0.0)) < 1e-2,
        "particle 0 at {held}"
    );
    assert!(
        centre(&app, lost).y < 0.9,
        "the unattached jelly did not fall"
    );
}
