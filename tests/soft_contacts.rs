//! Soft bodies meeting each other through `SoftBodyPlugin`, headless (`MinimalPlugins`, a manual
//! time step): a stack of jellies comes to rest, a jelly thrown at another bounces off it with
//! the momentum kept, and a body can be told to pass through the others.

use std::sync::Arc;
use std::time::Duration;

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_soft_body::core::{TetMesh, box_grid};
use bevy_soft_body::game_scenes::{GameScene, GameShape, MeshStyle};
use bevy_soft_body::prelude::*;
use glam::UVec3;

fn app(gravity: Vec3, step: Duration) -> App {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, SoftBodyPlugin::default()))
        .insert_resource(Time::<Fixed>::from_duration(step))
        .insert_resource(TimeUpdateStrategy::ManualDuration(step))
        .insert_resource(SoftBodyGravity(gravity));
    app.update();
    app
}

/// A jelly box of `cells` cells of 5 cm, its lowest corner at `corner`.
fn jelly(cells: UVec3, corner: Vec3) -> SoftBody {
    let mesh: Arc<TetMesh> = box_grid(cells, Vec3::splat(0.05), Vec3::ZERO)
        .unwrap()
        .into();
    let mut body = SoftBody::new(mesh, SoftBodyMaterial::JELLY).unwrap();
    body.translate(corner);
    body
}

/// Every body's centre of mass and volume error, in spawn order.
fn bodies(app: &mut App, order: &[Entity]) -> Vec<(Vec3, f64)> {
    order
        .iter()
        .map(|&e| {
            let s = app.world().get::<SoftBody>(e).unwrap().state();
            (s.centre_of_mass(), s.volume_metrics().volume_error_pct)
        })
        .collect()
}

/// Whether `x` lies inside the tet `t` of the particles `p`.
fn in_tet(x: Vec3, p: &[Vec3], t: &[u32; 4]) -> bool {
    let [a, b, c, d] = t.map(|i| p[i as usize]);
    let volume = |a: Vec3, b: Vec3, c: Vec3, d: Vec3| (b - a).dot((c - a).cross(d - a));
    let whole = volume(a, b, c, d).signum();
    [
        volume(x, b, c, d),
        volume(a, x, c, d),
        volume(a, b, x, d),
        volume(a, b, c, x),
    ]
    .iter()
    .all(|&v| v * whole > 0.0)
}

/// Whether `x` lies inside one of `body`'s tets.
fn inside(x: Vec3, body: &SoftBody) -> bool {
    let p = body.state().positions();
    body.state().mesh().tets().iter().any(|t| in_tet(x, p, t))
}

/// How many particles of one body lie deeper than `depth` inside another (tested by moving
/// each particle `depth` along every axis: deeper means inside in all six).
fn particles_inside(app: &mut App, depth: f32) -> usize {
    let world = app.world_mut();
    let all: Vec<&SoftBody> = world.query::<&SoftBody>().iter(world).collect();
    let mut count = 0;
    for (a, body) in all.iter().enumerate() {
        for (b, other) in all.iter().enumerate() {
            if a == b {
                continue;
            }
            for &x in body.state().positions() {
                let offsets = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
                if offsets.iter().all(|&o| inside(x + depth * o, other)) {
                    count += 1;
                }
            }
        }
    }
    count
}

/// A jelly slab, 0.3 x 0.1 x 0.3 m in cells of 5 cm, on the crate's grid or on a jittered mesh
/// (as other tools make), its lowest corner at `corner`.
fn slab(style: MeshStyle, corner: Vec3) -> SoftBody {
    let scene = GameScene {
        shape: GameShape::Block {
            size: Vec3::new(0.3, 0.1, 0.3),
            cell: 0.05,
        },
        mesh: style,
        ..GameScene::standard()
            .into_iter()
            .find(|s| s.name == "jelly_cube_drop")
            .unwrap()
    };
    let mesh = scene.tet_mesh().unwrap();
    let mut body = SoftBody::new(mesh.into(), SoftBodyMaterial::JELLY).unwrap();
    body.translate(corner);
    body
}

/// An app stepping at `hz` with the ground and three jelly slabs (`slab`) stacked a centimetre
/// apart, a little off each other; the slabs in stack order.
fn stack_of_three(style: MeshStyle, hz: f64) -> (App, Vec<Entity>) {
    let mut app = app(
        Vec3::new(0.0, -9.81, 0.0),
        Duration::from_secs_f64(1.0 / hz),
    );
    app.world_mut()
        .spawn((StaticCollider::ground(0.8), Transform::default()));
    let order = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(0.01, 0.11, -0.01),
        Vec3::new(0.0, 0.22, 0.01),
    ]
    .into_iter()
    .map(|corner| {
        app.world_mut()
            .spawn((slab(style, corner), Transform::default()))
            .id()
    })
    .collect();
    (app, order)
}

/// Three jelly slabs dropped a centimetre apart in a stack on the ground come to rest, at 30,
/// 60 and 120 Hz, on the crate's grid and on a jittered mesh: over the last two of six seconds
/// no centre of mass moves more than 3 mm, each body keeps its volume within 1 %, and no
/// particle of one lies more than 2 mm inside another. Slabs, not cubes: a column of this jelly
/// taller than about 0.5 m buckles under its own weight (Greenhill), so a stack of three 0.3 m
/// cubes would fall over in reality too.
#[test]
fn a_stack_of_three_jellies_comes_to_rest() {
    for hz in [30.0, 60.0, 120.0] {
        for style in [MeshStyle::Grid, MeshStyle::Jittered(0.3)] {
            let (mut app, order) = stack_of_three(style, hz);
            let steps = |seconds: f64| (seconds * hz).round() as usize;
            for _ in 0..steps(4.0) {
                app.update();
            }
            let settled = bodies(&mut app, &order);
            for _ in 0..steps(2.0) {
                app.update();
            }
            let end = bodies(&mut app, &order);
            let case = format!("{hz} Hz, {style:?}");
            for (k, ((before, _), (after, error))) in settled.iter().zip(&end).enumerate() {
                assert!(
                    (after.y - (0.05 + 0.1 * k as f32)).abs() < 0.03,
                    "{case}: jelly {k} at {after}"
                );
                let drift = after.distance(*before);
                println!("{case}: jelly {k} drifted {drift:.4} m, volume error {error:.2} %");
                assert!(
                    drift < 3e-3,
                    "{case}: jelly {k} moved {drift} m in the last 2 s"
                );
                assert!(
                    error.abs() < 1.0,
                    "{case}: jelly {k}: volume error {error} %"
                );
            }
            assert_eq!(particles_inside(&mut app, 2e-3), 0, "{case}");
        }
    }
}

/// Bodies resting on each other fall asleep together, as an island of rigid bodies does: the
/// stack of three jelly slabs above, at 60 Hz on the grid and on a jittered mesh, is asleep as
/// a whole within 8 s and stays asleep for the next second, where each body waking the others
/// kept it awake for ever (the one that fell asleep first was woken by its neighbour with its
/// quiet time begun anew, and so on, turn by turn).
#[test]
fn a_stack_of_jellies_falls_asleep_together() {
    for style in [MeshStyle::Grid, MeshStyle::Jittered(0.3)] {
        let hz = 60.0;
        let (mut app, order) = stack_of_three(style, hz);
        let asleep = |app: &App| {
            order
                .iter()
                .map(|&e| {
                    app.world()
                        .get::<SoftBody>(e)
                        .unwrap()
                        .state()
                        .is_sleeping()
                })
                .collect::<Vec<bool>>()
        };
        let mut all_asleep_at = None;
        for step in 0..(8.0 * hz) as usize {
            app.update();
            if asleep(&app).iter().all(|&a| a) {
                all_asleep_at = Some(step as f64 / hz);
                break;
            }
        }
        println!("{style:?}: the stack is asleep at {all_asleep_at:?} s");
        assert!(
            all_asleep_at.is_some(),
            "{style:?}: the stack is not asleep after 8 s: {:?}",
            asleep(&app)
        );
        let before = bodies(&mut app, &order);
        for _ in 0..hz as usize {
            app.update();
            assert!(
                asleep(&app).iter().all(|&a| a),
                "{style:?}: {:?}",
                asleep(&app)
            );
        }
        assert_eq!(before, bodies(&mut app, &order), "{style:?}");
    }
}

/// Two jellies thrown at each other at 4 m/s each (off-centre, no gravity) bounce apart: they
/// end moving away from each other, with their linear momentum kept to rounding, and no
/// particle of one ends more than 2 mm inside the other.
#[test]
fn jellies_thrown_at_each_other_bounce_apart() {
    let mut app = app(Vec3::ZERO, Duration::from_secs_f64(1.0 / 60.0));
    let cells = UVec3::splat(6);
    let mut a = jelly(cells, Vec3::new(-0.5, 0.0, 0.0));
    a.velocities_mut().fill(4.0 * Vec3::X);
    let mut b = jelly(cells, Vec3::new(0.25, 0.08, 0.05));
    b.velocities_mut().fill(-4.0 * Vec3::X);
    let carried = 4.0 * a.state().total_mass();
    let a = app.world_mut().spawn((a, Transform::default())).id();
    let b = app.world_mut().spawn((b, Transform::default())).id();
    let momentum = |app: &App| {
        [a, b]
            .map(|e| {
                app.world()
                    .get::<SoftBody>(e)
                    .unwrap()
                    .state()
                    .linear_momentum()
            })
            .iter()
            .sum::<Vec3>()
    };
    let start = momentum(&app);
    for _ in 0..30 {
        app.update();
        assert_eq!(particles_inside(&mut app, 2e-3), 0);
    }
    let end = momentum(&app);
    // Rounding: the substeps derive velocities from `f32` positions (see the core's test).
    assert!(
        (end - start).length() < 1e-3 * carried,
        "momentum {start} -> {end}"
    );
    let state = |e| app.world().get::<SoftBody>(e).unwrap().state();
    let (pa, pb) = (state(a).linear_momentum(), state(b).linear_momentum());
    assert!(pa.x < 0.0 && pb.x > 0.0, "still closing: {pa} {pb}");
    assert!(state(b).centre_of_mass().x > state(a).centre_of_mass().x + 0.3);
}

/// A body whose soft contacts are off passes through another.
#[test]
fn a_body_without_soft_contacts_passes_through() {
    let mut app = app(Vec3::ZERO, Duration::from_secs_f64(1.0 / 60.0));
    let cells = UVec3::splat(4);
    let mut a = jelly(cells, Vec3::new(-0.5, 0.0, 0.0));
    a.velocities_mut().fill(4.0 * Vec3::X);
    let b = jelly(cells, Vec3::new(0.25, 0.0, 0.0));
    let a = app
        .world_mut()
        .spawn((a, Transform::default(), SoftBodyContactsDisabled))
        .id();
    app.world_mut().spawn((b, Transform::default()));
    for _ in 0..30 {
        app.update();
    }
    let x = app
        .world()
        .get::<SoftBody>(a)
        .unwrap()
        .state()
        .centre_of_mass()
        .x;
    assert!(x > 0.9, "stopped at {x}");
}

/// How many particles of `particles` lie deeper than `depth` inside the tets `tets` of `body`
/// (deeper: inside when moved `depth` along each axis both ways).
fn inside_part(body: &SoftBody, particles: &[usize], tets: &[[u32; 4]], depth: f32) -> usize {
    let p = body.state().positions();
    let offsets = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
    particles
        .iter()
        .filter(|&&i| {
            offsets
                .iter()
                .all(|&o| tets.iter().any(|t| in_tet(p[i] + depth * o, p, t)))
        })
        .count()
}

/// A jelly bar (1.2 x 0.1 x 0.1 m, cells of 5 cm) hung by the plane of particles at its middle
/// folds down on both sides under its own weight, its halves swinging into each other: with self
/// contacts no particle of the left half ends a step more than 1 cm (a fifth of a cell) inside
/// the right half's tets over 3 s at 60 Hz; without them the halves pass into each other (so the
/// check can fail). Self contacts are looser than contacts between bodies: a few particles of
/// the tight fold sink 2-10 mm.
#[test]
fn a_bar_folding_under_its_weight_meets_itself_with_self_contacts() {
    let run = |self_contacts: bool| {
        let mut app = app(
            Vec3::new(0.0, -9.81, 0.0),
            Duration::from_secs_f64(1.0 / 60.0),
        );
        let mesh: Arc<TetMesh> = box_grid(UVec3::new(24, 2, 2), Vec3::splat(0.05), Vec3::ZERO)
            .unwrap()
            .into();
        let rest = mesh.positions().to_vec();
        let middle: Vec<u32> = (0..rest.len() as u32)
            .filter(|&i| (rest[i as usize].x - 0.6).abs() < 1e-4)
            .collect();
        let left: Vec<usize> = (0..rest.len()).filter(|&i| rest[i].x < 0.45).collect();
        let right: Vec<[u32; 4]> = mesh
            .tets()
            .iter()
            .filter(|t| t.iter().all(|&i| rest[i as usize].x > 0.6))
            .copied()
            .collect();
        let mut body = SoftBody::new(mesh, SoftBodyMaterial::JELLY).unwrap();
        body.translate(Vec3::Y);
        let contacts = SoftBodyContacts {
            self_contacts,
            ..default()
        };
        let bar = app
            .world_mut()
            .spawn((
                body,
                PinnedParticles(middle),
                Transform::default(),
                contacts,
            ))
            .id();
        let mut worst = 0;
        for _ in 0..180 {
            app.update();
            let body = app.world().get::<SoftBody>(bar).unwrap();
            worst = worst.max(inside_part(body, &left, &right, 0.01));
        }
        worst
    };
    assert_eq!(run(true), 0, "with self contacts");
    assert!(run(false) > 0, "the halves never met without self contacts");
}
