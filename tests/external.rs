//! Forces and impulses from the game: an impulse at a point changes a body's momentum by `J`
//! and its angular momentum by `p x J`; an explosion pushes every body within its sphere away
//! from its centre and leaves the others alone; a force held on a body for a second gives it
//! the momentum `F t`.

use std::sync::Arc;
use std::time::Duration;

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_soft_body::core::{SoftBodyState, box_grid, parse_tetgen};
use bevy_soft_body::prelude::*;

/// The Ten Minute Physics bunny (an irregular mesh another tool made), scaled to about 1 m.
fn bunny() -> TetMesh {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/assets/meshes/bunny_tmp");
    let node = std::fs::read_to_string(format!("{dir}.node")).unwrap();
    let ele = std::fs::read_to_string(format!("{dir}.ele")).unwrap();
    parse_tetgen(&node, &ele).unwrap()
}

/// Linear and angular momentum (about the origin), in f64.
fn momenta(body: &SoftBodyState) -> (glam::DVec3, glam::DVec3) {
    let (mut p, mut l) = (glam::DVec3::ZERO, glam::DVec3::ZERO);
    for ((x, v), &m) in body
        .positions()
        .iter()
        .zip(body.velocities())
        .zip(body.masses())
    {
        let mv = v.as_dvec3() * m as f64;
        p += mv;
        l += x.as_dvec3().cross(mv);
    }
    (p, l)
}

#[test]
fn an_impulse_at_a_point_gives_the_momentum_and_the_angular_momentum_it_should() {
    let mut body = SoftBodyState::new(Arc::new(bunny()), SoftBodyMaterial::RUBBER).unwrap();
    body.translate(Vec3::new(0.3, 1.0, -0.2));
    // Tumbling, so that the angular momentum before is not zero.
    let c = body.centre_of_mass();
    let positions = body.positions().to_vec();
    for (v, x) in body.velocities_mut().iter_mut().zip(positions) {
        *v = Vec3::new(0.5, 1.0, 0.0) + Vec3::new(0.3, -2.0, 1.0).cross(x - c);
    }
    let (lo, hi) = body
        .positions()
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        });
    let impulse = Vec3::new(-3.0, 4.0, 12.0);
    // A point inside (the centre of mass of a bunny is inside it) and one well outside.
    for point in [c, hi + (hi - lo)] {
        let at = body.body_point(point).expect("a mesh with tets");
        let acts_at = body.point_position(at);
        if point == c {
            assert!(acts_at.distance(c) < 1e-5, "{acts_at} for {c}");
        } else {
            // Outside: it acts on the body's surface, nearer the point than the body's middle.
            assert!(acts_at.distance(point) < c.distance(point));
        }
        let (p0, l0) = momenta(&body);
        body.forces().apply_impulse_at(at, impulse);
        let (p1, l1) = momenta(&body);
        let j = impulse.as_dvec3();
        let dp = p1 - p0 - j;
        assert!(dp.length() < 1e-5 * j.length(), "momentum off by {dp}");
        let expected = acts_at.as_dvec3().cross(j);
        let dl = l1 - l0 - expected;
        // f32 velocities of particles ~1 m from the origin: a few 1e-6 of |r| |J|.
        let tolerance = 1e-5 * acts_at.as_dvec3().length() * j.length();
        assert!(
            dl.length() < tolerance,
            "angular momentum off by {dl} (tolerance {tolerance})"
        );
    }
    // The whole body: every particle the same change, `J / M`.
    let before = body.velocities().to_vec();
    let mass: f32 = body.masses().iter().sum();
    body.forces().apply_impulse(impulse);
    for (v, v0) in body.velocities().iter().zip(before) {
        assert!((*v - v0 - impulse / mass).length() < 1e-5);
    }
}

/// An app without gravity, stepping 10 ms an update.
fn weightless() -> App {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, SoftBodyPlugin::default()))
        .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_millis(
            10,
        )))
        .insert_resource(SoftBodyGravity(Vec3::ZERO));
    app
}

fn cube() -> SoftBody {
    let mesh = box_grid(UVec3::splat(3), Vec3::splat(0.1), Vec3::splat(-0.15)).unwrap();
    SoftBody::new(mesh.into(), SoftBodyMaterial::RUBBER).unwrap()
}

#[test]
fn an_explosion_pushes_every_body_in_its_sphere_away_from_its_centre() {
    let mut app = weightless();
    let centre = Vec3::new(0.0, 0.2, 0.0);
    let placed = [
        Vec3::new(0.6, 0.0, 0.0),
        Vec3::new(-0.4, 0.5, 0.3),
        Vec3::new(0.0, 0.1, -0.7),
        // Out of reach.
        Vec3::new(3.0, 0.0, 0.0),
    ];
    let bodies: Vec<Entity> = placed
        .iter()
        .map(|&at| {
            let world = app.world_mut();
            world.spawn((cube(), Transform::from_translation(at))).id()
        })
        .collect();
    // Until the first step has placed them (the first update runs none).
    for _ in 0..3 {
        app.update();
    }
    let placed_all = bodies
        .iter()
        .all(|&e| app.world().get::<SoftBody>(e).unwrap().is_placed());
    assert!(placed_all);
    let (impulse, radius) = (20.0, 1.2);
    // What each body should take: every particle within reach its share of the impulse,
    // scaled down with its distance, away from the centre.
    let expected: Vec<Vec3> = bodies
        .iter()
        .map(|&entity| {
            let state = app.world().get::<SoftBody>(entity).unwrap().state();
            let mass: f32 = state.masses().iter().sum();
            let before: Vec3 = (state.velocities().iter())
                .zip(state.masses())
                .map(|(v, m)| *v * *m)
                .sum();
            before
                + (state.positions().iter())
                    .zip(state.masses())
                    .filter(|(x, _)| x.distance(centre) < radius)
                    .map(|(x, m)| {
                        let d = x.distance(centre);
                        (*x - centre) / d * (impulse * (1.0 - d / radius) * m / mass)
                    })
                    .sum::<Vec3>()
        })
        .collect();
    app.world_mut().write_message(SoftBodyRadialImpulse {
        centre,
        radius,
        impulse,
    });
    app.update();
    for ((&entity, &at), expected) in bodies.iter().zip(&placed).zip(expected) {
        let state = app.world().get::<SoftBody>(entity).unwrap().state();
        let momentum: Vec3 = (state.velocities().iter())
            .zip(state.masses())
            .map(|(v, m)| *v * *m)
            .sum();
        // Its momentum is what it had and what the explosion gave (the step keeps it), pointing
        // away from the centre; out of reach, what it had.
        assert!(
            (momentum - expected).length() < 1e-4 * impulse,
            "{entity}: {momentum}, expected {expected}"
        );
        if at.x > 2.0 {
            assert!(expected.length() < 1e-4 * impulse);
            continue;
        }
        let away = (state.centre_of_mass() - centre).normalize();
        assert!(
            momentum.dot(away) > 0.8 * momentum.length(),
            "{momentum} vs {away}"
        );
        assert!(momentum.length() > 0.05 * impulse, "{momentum}");
    }
}

#[test]
fn a_force_held_for_a_second_gives_its_momentum_and_a_force_off_centre_spins_the_body() {
    let mut app = weightless();
    let force = Vec3::new(0.0, 30.0, 0.0);
    let body = app
        .world_mut()
        .spawn((
            cube(),
            Transform::default(),
            SoftBodyForces {
                force,
                at_points: vec![],
            },
        ))
        .id();
    // Lifted at its +x face: it rises and turns about +z.
    let lifted = app
        .world_mut()
        .spawn((
            cube(),
            Transform::from_xyz(2.0, 0.0, 0.0),
            SoftBodyForces {
                force: Vec3::ZERO,
                at_points: vec![PointForce::new(Vec3::new(2.14, 0.0, 0.0), force)],
            },
        ))
        .id();
    let momenta = |app: &App, entity: Entity| {
        let state = app.world().get::<SoftBody>(entity).unwrap().state();
        let c = state.centre_of_mass();
        let (mut p, mut l) = (Vec3::ZERO, Vec3::ZERO);
        for ((x, v), &m) in state
            .positions()
            .iter()
            .zip(state.velocities())
            .zip(state.masses())
        {
            p += *v * m;
            l += (*x - c).cross(*v * m);
        }
        (p, l)
    };
    // Until the steps run one an update (the first update runs none).
    for _ in 0..5 {
        app.update();
    }
    let before = [body, lifted].map(|e| momenta(&app, e));
    for _ in 0..100 {
        app.update();
    }
    for (entity, (p0, _)) in [body, lifted].into_iter().zip(before) {
        let (p, l) = momenta(&app, entity);
        // 100 steps of 10 ms: F t = 30 N s.
        let gained = p - p0;
        assert!(
            (gained - force).length() < 1e-3 * force.length(),
            "{gained}"
        );
        if entity == body {
            assert!(
                l.length() < 1e-3,
                "a force spread by mass spins nothing: {l}"
            );
        } else {
            assert!(l.z > 0.5, "the lifted side turns up: {l}");
        }
    }
}
