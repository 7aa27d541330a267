//! Bodies made the way a game makes them: Earth gravity, real sizes, physical materials, steps
//! of 1/30 to 1/120 s, the crate's own grids and irregular meshes (`game_scenes`).

use std::time::Duration;

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_soft_body::core::{Serial, VolumeMethod};
use bevy_soft_body::game_scenes::{BundledMesh, GameScene, GameShape, MeshStyle};
use bevy_soft_body::prelude::*;

const RATES: [f32; 3] = [30.0, 60.0, 120.0];

/// The presets' method and the paper's impulses: what the behaviour tests run.
const METHODS: [VolumeMethod; 2] = [VolumeMethod::XPBD_CLUSTERS, VolumeMethod::PAPER_IMPULSES];

fn scene(name: &str) -> GameScene {
    GameScene::standard()
        .into_iter()
        .find(|s| s.name == name)
        .unwrap_or_else(|| panic!("no scene {name}"))
}

/// Every scene, at every rate, on the crate's own grids and the irregular meshes: finite, never
/// caught running away, few tets inverted, and the volume within 1 % of its rest volume
/// throughout (the target).
#[test]
fn every_game_scene_stays_finite_and_keeps_its_volume_under_one_percent() {
    for scene in GameScene::standard() {
        for hz in RATES {
            let r = scene.run(VolumeMethod::PAPER_IMPULSES, hz).unwrap();
            assert!(r.finite, "{} at {hz} Hz: {r:?}", scene.name);
            assert_eq!(r.runaways, 0, "{} at {hz} Hz: {r:?}", scene.name);
            assert!(
                r.max_inverted_tets < r.tets / 20,
                "{} at {hz} Hz: {r:?}",
                scene.name
            );
            assert!(
                r.peak_volume_error_pct < 1.0,
                "{} at {hz} Hz: {r:?}",
                scene.name
            );
        }
    }
}

/// The meshes other tools made (`assets/meshes`), as a game brings them: each loads with the
/// tets its README lists, and dropped in every preset at 30 and at 60 Hz stays finite, is never
/// caught running away, keeps its volume within 1 % and ends with no tet inverted (their
/// slivers flip at a touch; the per-tet pass must flip them back).
#[test]
fn meshes_other_tools_made_keep_their_volume_under_one_percent() {
    let tets = [1351, 3840, 4182, 1856];
    for (mesh, tets) in BundledMesh::ALL.into_iter().zip(tets) {
        assert_eq!(mesh.load().unwrap().tet_count(), tets, "{mesh:?}");
    }
    for hz in [30.0, 60.0] {
        for scene in GameScene::bundled() {
            let r = scene.run(VolumeMethod::PAPER_IMPULSES, hz).unwrap();
            let name = format!("{} at {hz} Hz", scene.name);
            assert!(r.finite, "{name}: {r:?}");
            assert_eq!(r.runaways, 0, "{name}: {r:?}");
            assert!(r.peak_volume_error_pct < 1.0, "{name}: {r:?}");
            assert_eq!(r.final_inverted_tets, 0, "{name}: {r:?}");
        }
    }
}

#[test]
fn resting_and_stacked_bodies_keep_their_volume_under_one_percent() {
    let resting = GameScene {
        lift: 0.0,
        ..scene("jelly_cube_drop")
    };
    for scene in [resting, scene("sphere_on_soft_block")] {
        for (hz, method) in RATES.into_iter().flat_map(|hz| METHODS.map(|m| (hz, m))) {
            let r = scene.run(method, hz).unwrap();
            assert!(
                r.peak_volume_error_pct < 1.0,
                "{} at {hz} Hz, {}: {r:?}",
                scene.name,
                method.name()
            );
        }
    }
}

#[test]
fn stiff_bodies_rest_near_their_height_and_soft_ones_squash_and_recover() {
    for name in [
        "flesh_cube_drop",
        "rubber_cube_drop",
        "sphere_on_soft_block",
    ] {
        for (hz, method) in RATES.into_iter().flat_map(|hz| METHODS.map(|m| (hz, m))) {
            let r = scene(name).run(method, hz).unwrap();
            let name = format!("{name} at {hz} Hz, {}", method.name());
            assert!(r.final_height >= 0.95, "{name}: {r:?}");
        }
    }
    for (hz, method) in RATES.into_iter().flat_map(|hz| METHODS.map(|m| (hz, m))) {
        let r = scene("jelly_cube_drop").run(method, hz).unwrap();
        // Squashed to well under its height on landing, then back up most of the way.
        let name = format!("{hz} Hz, {}", method.name());
        assert!(r.lowest_height < 0.8, "{name}: {r:?}");
        assert!(r.final_height > 0.85, "{name}: {r:?}");
    }
}

/// A dropped body bounces lower than it fell: its lowest particle never climbs back to its
/// drop height (with the edges as the shape model, the graded hard rubber cube bounced from
/// 1 m to 2 m at 60 Hz; PERFORMANCE.md, stop 31).
#[test]
fn no_dropped_body_bounces_higher_than_it_fell() {
    for scene in GameScene::standard().into_iter().filter(|s| s.lift > 0.0) {
        for (hz, method) in RATES.into_iter().flat_map(|hz| METHODS.map(|m| (hz, m))) {
            let mut world = scene.world(method).unwrap();
            let lowest = |w: &bevy_soft_body::game_scenes::GameWorld| {
                w.body
                    .positions()
                    .iter()
                    .fold(f32::INFINITY, |m, p| m.min(p.y))
            };
            let (mut landed, mut highest_after) = (false, 0.0f32);
            for _ in 0..(scene.duration_secs * hz) as usize {
                world.step(1.0 / hz);
                let y = lowest(&world);
                landed |= y < 0.01;
                if landed {
                    highest_after = highest_after.max(y);
                }
            }
            assert!(
                highest_after < scene.lift,
                "{} at {hz} Hz, {}: dropped from {} m, back up to {highest_after} m",
                scene.name,
                method.name(),
                scene.lift
            );
        }
    }
}

#[test]
fn a_crushed_body_gets_its_volume_back_without_being_thrown() {
    // A jelly cube flattened to half its height on the ground (half its volume), at rest.
    let scene = GameScene {
        lift: 0.0,
        ..scene("jelly_cube_drop")
    };
    for method in METHODS {
        let mut world = scene.world(method).unwrap();
        world.body.map_positions(|p| Vec3::new(p.x, 0.5 * p.y, p.z));
        let start = world.body.volume_metrics().volume_error_pct;
        assert!(start < -49.0, "{start}");
        let rest_centre = 0.5 * world.rest_height;
        let mut highest = 0.0f32;
        for _ in 0..120 {
            world.step(1.0 / 60.0);
            highest = highest.max(world.body.centre_of_mass().y);
        }
        let end = world.body.volume_metrics();
        let name = method.name();
        assert!(end.volume_error_pct.abs() < 1.0, "{name}: {end:?}");
        // Restored in place: its centre of mass rises to about its rest height, not far above.
        assert!(
            highest < 1.3 * rest_centre,
            "{name}: thrown to {highest} (rest {rest_centre})"
        );
    }
}

#[test]
fn a_stiff_body_on_an_irregular_mesh_falls_without_deforming() {
    // Hard rubber on the graded grid (light particles on short, stiff edges), in free fall for
    // half a second at every rate: a falling body keeps its rest shape. Its edges' dampers, run
    // as a pass of their own after the projection, made it stretch and run away here.
    let scene = scene("hard_rubber_cube_graded");
    for (hz, method) in RATES.into_iter().flat_map(|hz| METHODS.map(|m| (hz, m))) {
        let mut world = scene.world(method).unwrap();
        world.colliders.clear();
        let name = format!("{hz} Hz, {}", method.name());
        for _ in 0..(hz / 2.0) as usize {
            world.step(1.0 / hz);
            assert!(world.body.runaway().is_none(), "{name}");
        }
        let height = world.height_ratio();
        let metrics = world.body.volume_metrics();
        assert!((height - 1.0).abs() < 1e-3, "{name}: height {height}");
        assert!(metrics.mean_abs_tet_error_pct < 0.01, "{name}: {metrics:?}");
    }
}

/// XPBD with its cluster volume correction (`VolumeMethod::XPBD_CLUSTERS`), on every game
/// scene and every mesh other tools made, at 30, 60 and 120 Hz: finite, never caught running
/// away, the volume within 1 % throughout, and no tet left inside out at the end but on the
/// TetGen creature's jelly (slivers that a jelly's load folds again each step: 0-3 left, the
/// paper's method none; PERFORMANCE.md); on the bundled meshes at 60 Hz, where plain XPBD at
/// the same substeps peaks at 0.8-3.3 %, at most a quarter of plain XPBD's peak.
#[test]
fn xpbd_with_clusters_keeps_every_scene_under_one_percent() {
    for scene in GameScene::standard()
        .into_iter()
        .chain(GameScene::bundled())
    {
        for hz in RATES {
            let r = scene.run(VolumeMethod::XPBD_CLUSTERS, hz).unwrap();
            let name = format!("{} at {hz} Hz", scene.name);
            assert!(r.finite, "{name}: {r:?}");
            assert_eq!(r.runaways, 0, "{name}: {r:?}");
            assert!(r.peak_volume_error_pct < 1.0, "{name}: {r:?}");
            if scene.name != "creature_tetgen_jelly" {
                assert_eq!(r.final_inverted_tets, 0, "{name}: {r:?}");
            }
        }
    }
    for scene in GameScene::bundled() {
        let plain = scene.run(VolumeMethod::XPBD, 60.0).unwrap();
        let clusters = scene.run(VolumeMethod::XPBD_CLUSTERS, 60.0).unwrap();
        assert!(
            clusters.peak_volume_error_pct < plain.peak_volume_error_pct / 4.0,
            "{}: {clusters:?} against {plain:?}",
            scene.name
        );
    }
}

/// Flesh, rubber and hard rubber bodies on the meshes other tools made, dropped with XPBD's
/// cluster correction at 30, 60 and 120 Hz, come to rest and fall asleep within 4.5 s of
/// landing (measured 1.6-3.9 s; the bouncy rubber bunny is the last). Without deformation
/// damping and rolling resistance none slept within 8 s: they rocked on their curved
/// undersides and their thin parts swung (PERFORMANCE.md, "Irregular bodies at rest").
#[test]
fn bodies_on_meshes_other_tools_made_come_to_rest() {
    for scene in GameScene::bundled() {
        if scene.material_name == "jelly" {
            continue;
        }
        let scene = GameScene {
            duration_secs: 8.0,
            ..scene
        };
        for hz in RATES {
            let r = scene.run(VolumeMethod::XPBD_CLUSTERS, hz).unwrap();
            let name = format!("{} at {hz} Hz", scene.name);
            let (Some(landed), Some(asleep)) = (r.landed_at, r.asleep_from) else {
                panic!("{name} never fell asleep: {r:?}");
            };
            assert!(asleep - landed < 4.5, "{name}: {r:?}");
        }
    }
}

#[test]
fn a_physical_body_conserves_momentum_in_free_flight() {
    for method in [VolumeMethod::PAPER_IMPULSES, VolumeMethod::XPBD_CLUSTERS] {
        conserves_momentum_in_free_flight(method);
    }
}

fn conserves_momentum_in_free_flight(method: VolumeMethod) {
    let scene = scene("jelly_cube_drop");
    let mut world = scene.world(method).unwrap();
    world.colliders.clear();
    world.gravity = Vec3::ZERO;
    // Squeezed from two sides while moving: every pass has work, nothing outside acts.
    let positions = world.body.positions().to_vec();
    for (p, v) in positions.iter().zip(world.body.velocities_mut()) {
        *v = Vec3::new(if p.x < 0.25 { 2.0 } else { -1.0 }, 0.5, 0.0);
    }
    let momentum = world.body.linear_momentum();
    for _ in 0..60 {
        world.step(1.0 / 60.0);
    }
    let after = world.body.linear_momentum();
    assert!(
        (after - momentum).length() < 1e-3 * momentum.length(),
        "{}: {momentum} -> {after}",
        method.name()
    );
    assert!(world.body.volume_metrics().volume_error_pct.abs() < 1.0);
}

fn app(hz: f64) -> App {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, SoftBodyPlugin::default()))
        .insert_resource(Time::<Fixed>::from_hz(hz))
        .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
            1.0 / hz,
        )));
    app.update();
    app
}

/// Spawns `scene` with the paper's method into `app`; returns its body.
fn spawn(app: &mut App, scene: &GameScene) -> Entity {
    let world = app.world_mut();
    let body = scene
        .spawn(
            &mut world.commands(),
            VolumeMethod::PAPER_IMPULSES,
            Vec3::ZERO,
        )
        .unwrap();
    world.flush();
    body
}

#[test]
fn the_plugin_steps_a_game_scene_as_the_core_does() {
    let scene = GameScene {
        duration_secs: 1.0,
        ..scene("flesh_cube_drop")
    };
    let core = scene.run(VolumeMethod::PAPER_IMPULSES, 60.0).unwrap();
    let mut app = app(60.0);
    let body = spawn(&mut app, &scene);
    while app.world().get::<SoftBodyStats>(body).unwrap().steps < 60 {
        app.update();
    }
    let stats = app.world().get::<SoftBodyStats>(body).unwrap();
    assert_eq!(stats.steps, 60);
    assert!(
        (stats.peak_volume_error_pct - core.peak_volume_error_pct).abs() < 1e-3,
        "plugin {} against core {}",
        stats.peak_volume_error_pct,
        core.peak_volume_error_pct
    );
    assert_eq!(stats.runaway_resets, 0);
}

#[test]
fn a_body_that_runs_away_is_reported_once_and_put_back() {
    let mut app = app(60.0);
    let mesh =
        bevy_soft_body::core::box_grid(UVec3::splat(4), Vec3::splat(0.05), Vec3::ZERO).unwrap();
    // The paper's explicit springs, far too stiff for a 1/60 s step: they explode.
    let material = SoftBodyMaterial::paper(1000.0, 1e5, 0.0);
    let mut soft_body = SoftBody::new(mesh.into(), material).unwrap();
    soft_body.velocities_mut()[0] = Vec3::new(1.0, 0.0, 0.0);
    let body = app
        .world_mut()
        .spawn((soft_body, Transform::from_xyz(0.0, 1.0, 0.0)))
        .id();
    app.world_mut()
        .spawn((StaticCollider::ground(0.5), Transform::default()));
    let mut reported = Vec::new();
    for _ in 0..120 {
        app.update();
        let messages = app.world().resource::<Messages<SoftBodyError>>();
        reported.extend(
            messages
                .iter_current_update_messages()
                .filter(|e| matches!(e.kind, SoftBodyErrorKind::Runaway(_)))
                .cloned(),
        );
        let transform = app.world().get::<Transform>(body).unwrap();
        assert!(
            transform.translation.length() < 10.0,
            "the body flew off to {}",
            transform.translation
        );
    }
    let stats = app.world().get::<SoftBodyStats>(body).unwrap();
    assert!(stats.runaway_resets >= 1, "{stats:?}");
    // It explodes again after each reset (on landing); a spell of runaways is reported once
    // per 100 steps at most, not once a step.
    assert!(
        (1..=2).contains(&reported.len()),
        "{} reports for {} resets",
        reported.len(),
        stats.runaway_resets
    );
    assert!(reported.iter().all(|e| e.body == body));
}

#[test]
fn a_resting_jelly_falls_asleep_and_a_sphere_dropped_on_it_wakes_it() {
    let mut app = app(60.0);
    let scene = GameScene {
        lift: 0.1,
        ..scene("jelly_cube_drop")
    };
    let body = spawn(&mut app, &scene);
    let stats = |app: &App| app.world().get::<SoftBodyStats>(body).unwrap().clone();
    while !stats(&app).sleeping {
        app.update();
        assert!(stats(&app).steps < 600, "not asleep after 10 s");
    }
    let asleep_at = stats(&app).steps;
    // Asleep: it costs nothing and stays where it is. `top`: the height of its top face's
    // middle, under where the sphere will land.
    let centre = app
        .world()
        .get::<SoftBody>(body)
        .unwrap()
        .state()
        .centre_of_mass();
    let top = |app: &App| {
        app.world()
            .get::<SoftBody>(body)
            .unwrap()
            .state()
            .positions()
            .iter()
            .filter(|p| (p.xz() - centre.xz()).length() < 0.05)
            .fold(f32::NEG_INFINITY, |top, p| top.max(p.y))
    };
    let resting_top = top(&app);
    for _ in 0..30 {
        app.update();
    }
    assert!(stats(&app).sleeping);
    assert_eq!(top(&app), resting_top);
    // A 20 kg sphere dropped on it wakes it and dents it.
    app.world_mut().spawn((
        RigidSphere::new(0.1, 20.0),
        Transform::from_xyz(centre.x, resting_top + 0.4, centre.z),
    ));
    let mut lowest_top = resting_top;
    for _ in 0..60 {
        app.update();
        lowest_top = lowest_top.min(top(&app));
    }
    let after = stats(&app);
    assert!(after.steps > asleep_at + 60);
    assert!(
        lowest_top < resting_top - 0.02,
        "{lowest_top} against {resting_top}"
    );
    assert!(after.peak_volume_error_pct < 2.0, "{after:?}");
}

/// How far, in metres, a 0.3 m cube of `material` (6^3 cells, as `style` lays them out) resting
/// on a half-space tilted by `degrees` with friction `friction` (the material's and the
/// ground's) moves down the slope between its first and its third second, stepped at `hz`.
fn slide_on_slope(
    material: SoftBodyMaterial,
    style: MeshStyle,
    degrees: f32,
    friction: f32,
    hz: f32,
) -> f32 {
    use bevy_soft_body::core::{ColliderInstance, SoftBodyState, TetMesh};
    use parry3d::math::Pose;
    use parry3d::shape::SharedShape;

    let tilt = Quat::from_rotation_z(-degrees.to_radians());
    let ground = [ColliderInstance::new(
        SharedShape::halfspace(tilt * Vec3::Y),
        Pose::IDENTITY,
        friction,
    )];
    let grid = GameScene {
        mesh: style,
        ..GameScene::new(
            "cube_on_slope",
            GameShape::Cube {
                size: 0.3,
                cells: 6,
            },
            ("", material),
            0.0,
        )
    }
    .tet_mesh()
    .unwrap();
    // On the tilted plane, 1 mm above it.
    let (lo, hi) = grid.bounds();
    let corner = Vec3::new(-0.5 * (hi.x - lo.x), 0.001, -0.5 * (hi.z - lo.z));
    let positions = grid
        .positions()
        .iter()
        .map(|&p| tilt * (p - lo + corner))
        .collect();
    let mesh = TetMesh::new(positions, grid.tets().to_vec()).unwrap();
    let material = SoftBodyMaterial {
        friction,
        ..material
    };
    let mut body = SoftBodyState::new(mesh.into(), material).unwrap();
    let (h, gravity, down) = (1.0 / hz, Vec3::new(0.0, -9.81, 0.0), tilt * Vec3::X);
    let steps = hz as usize;
    for _ in 0..steps {
        body.step_with_contacts(h, gravity, &mut [], &ground, &Serial);
    }
    let start = body.centre_of_mass();
    for _ in 0..2 * steps {
        body.step_with_contacts(h, gravity, &mut [], &ground, &Serial);
    }
    (body.centre_of_mass() - start).dot(down)
}

/// Friction holds a body on a slope it should hold: rubber and flesh cubes on 25 degrees
/// (tan 25 = 0.47) with friction 1.2 move less than 2 cm in two seconds at 30 to 120 Hz, and
/// the rubber one on 30 degrees at 60 and 120 Hz, on the crate's grid and on a jittered mesh.
/// The volume impulses carry much of a resting body's weight, and their share of the ground's
/// push gets its friction too (`SoftBodyState::support_friction`). (At 30 Hz, and for flesh on
/// 30 degrees, the cube still tips over its lower edge; see PERFORMANCE.md.) On friction 0.1 the
/// rubber cube slides as Coulomb says.
#[test]
fn friction_holds_a_body_on_a_slope_and_a_slippery_slope_lets_it_slide() {
    for hz in RATES {
        let mut cases = vec![
            ("rubber", SoftBodyMaterial::RUBBER, 25.0),
            ("flesh", SoftBodyMaterial::FLESH, 25.0),
        ];
        if hz >= 60.0 {
            cases.push(("rubber", SoftBodyMaterial::RUBBER, 30.0));
        }
        for (name, material, degrees) in cases {
            for style in [MeshStyle::Grid, MeshStyle::Jittered(0.3)] {
                let moved = slide_on_slope(material, style, degrees, 1.2, hz);
                println!(
                    "{name} ({style:?}) on {degrees} deg at {hz} Hz, friction 1.2: moved {moved:.4} m"
                );
                assert!(
                    moved.abs() < 0.02,
                    "{name} ({style:?}) on {degrees} deg at {hz} Hz slid {moved} m"
                );
            }
        }
        // From 1 s to 3 s at g (sin 30 - 0.1 cos 30) = 4.06 m/s^2: 4.06 (3^2 - 1^2) / 2 =
        // 16.2 m from rest; the landing and the anchors take a little.
        let slid = slide_on_slope(SoftBodyMaterial::RUBBER, MeshStyle::Grid, 30.0, 0.1, hz);
        println!("rubber on 30 deg at {hz} Hz, friction 0.1: slid {slid:.3} m");
        assert!(
            (13.0..16.3).contains(&slid),
            "at {hz} Hz the rubber cube slid {slid} m"
        );
    }
}

/// A fast impact: a 1 m jelly cube (8 cells a side) thrown at the ground at 8 m/s from just
/// above it, at 60 Hz, with the paper's method and with XPBD's cluster correction: its volume
/// within 1 % throughout and no tet inverted at the end.
#[test]
fn a_jelly_thrown_at_the_ground_keeps_its_volume() {
    for method in [VolumeMethod::PAPER_IMPULSES, VolumeMethod::XPBD_CLUSTERS] {
        thrown_at_the_ground(method);
    }
}

fn thrown_at_the_ground(method: VolumeMethod) {
    let scene = GameScene::new(
        "jelly_cube_thrown",
        GameShape::Cube {
            size: 1.0,
            cells: 8,
        },
        ("jelly", SoftBodyMaterial::JELLY),
        0.1,
    );
    let mut world = scene.world(method).unwrap();
    for v in world.body.velocities_mut() {
        *v = Vec3::new(0.0, -8.0, 0.0);
    }
    let mut peak = 0.0f64;
    for _ in 0..120 {
        world.step(1.0 / 60.0);
        let m = world.body.volume_metrics();
        assert!(m.volume.is_finite());
        peak = peak.max(m.volume_error_pct.abs());
    }
    let end = world.body.volume_metrics();
    let name = method.name();
    println!("{name}: peak {peak} %, end {end:?}");
    assert!(peak < 1.0, "{name}: peak {peak} %, end {end:?}");
    assert_eq!(end.inverted_tets, 0, "{name}: {end:?}");
}

/// Jellies on meshes other tools made placed deep in each other on the ground (a game spawning
/// two at one spot): the dragon 40 % into the other, the bunny and the fTetWild creature 80 %.
/// Nothing explodes: no body's volume is ever off by 3 %, none is caught running away, and they
/// are pushed apart (their centres end further apart than they started). The pass that ends a
/// step must leave a particle that deep to the substeps: moved out whole, it jumps through the
/// other body's thin parts.
#[test]
fn jellies_placed_deep_in_each_other_do_not_explode() {
    use bevy_soft_body::core::{ColliderInstance, SoftBodyState, step_bodies};
    use parry3d::math::Pose;
    use parry3d::shape::SharedShape;
    let ground = [ColliderInstance::new(
        SharedShape::halfspace(Vec3::Y),
        Pose::IDENTITY,
        0.8,
    )];
    for (name, overlap) in [
        ("dragon_tmp", 0.4),
        ("bunny_tmp", 0.8),
        ("creature_ftetwild", 0.8),
    ] {
        let scene = GameScene::bundled()
            .into_iter()
            .find(|s| s.name.starts_with(name) && s.material_name == "jelly")
            .unwrap();
        let mesh = std::sync::Arc::new(scene.tet_mesh().unwrap());
        let (lo, hi) = mesh.bounds();
        let mut bodies: Vec<SoftBodyState> = (0..2)
            .map(|k| {
                let mut body = SoftBodyState::new(mesh.clone(), scene.material).unwrap();
                let along = k as f32 * (hi.x - lo.x) * (1.0 - overlap);
                body.translate(Vec3::new(along, 0.3 + 0.1 * k as f32, 0.0));
                body
            })
            .collect();
        let apart = |bodies: &[SoftBodyState]| {
            let (a, b) = (bodies[0].centre_of_mass(), bodies[1].centre_of_mass());
            Vec2::new(b.x - a.x, b.z - a.z).length()
        };
        let start = apart(&bodies);
        let (mut peak, mut runaways) = (0.0f64, 0);
        for _ in 0..180 {
            step_bodies(&mut bodies, 1.0 / 60.0, Vec3::Y * -9.81, &ground, &Serial);
            for body in &bodies {
                peak = peak.max(body.volume_metrics().volume_error_pct.abs());
                runaways += body.runaway().is_some() as u32;
            }
        }
        let end = apart(&bodies);
        assert!(
            peak < 3.0 && runaways == 0 && end > start,
            "{name}: peak {peak:.2} %, {runaways} runaways, centres {start:.2} -> {end:.2} m apart"
        );
    }
}
