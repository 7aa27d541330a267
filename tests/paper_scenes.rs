//! The paper's five scenes through the plugin, headless: the new method keeps the volume, the
//! baseline loses it as the paper reports, and each scene shows its event.

mod common;

use bevy::math::Vec3;
use bevy_soft_body::core::VolumeMethod;
use bevy_soft_body::prelude::*;
use bevy_soft_body::scenes::PaperScene;
use common::{run_scene, spheres};

const PAPER: VolumeMethod = VolumeMethod::PAPER_IMPULSES;
const BASELINE: VolumeMethod = VolumeMethod::PAPER_BASELINE;

/// The paper's method keeps the total volume error under 1 % (its claim), and the baseline loses
/// at least half of what the paper reports for it.
/// Returns the new method's run.
fn check_volumes(scene: PaperScene, paper_reports_baseline_pct: f64) -> common::SceneRun {
    let paper = run_scene(scene, PAPER, None);
    let baseline = run_scene(scene, BASELINE, None);
    println!(
        "{}: paper {:.3} %, baseline {:.3} %",
        scene.name(),
        paper.peak_error_pct,
        baseline.peak_error_pct
    );
    assert!(
        paper.peak_error_pct < 1.0,
        "{}: paper method peak {:.3} %",
        scene.name(),
        paper.peak_error_pct
    );
    assert!(
        baseline.peak_error_pct >= paper_reports_baseline_pct / 2.0,
        "{}: the baseline lost only {:.3} %, the paper reports {paper_reports_baseline_pct} %",
        scene.name(),
        baseline.peak_error_pct
    );
    paper
}

#[test]
fn bar_twist_keeps_volume() {
    check_volumes(PaperScene::BarTwist, 7.0);
}

#[test]
fn bar_twist_returns_to_rest_shape() {
    // Turned one and a half turns by 3 s, released at 4 s; by the end it must have untwisted
    // and come to rest close to its rest shape.
    let mut run = run_scene(PaperScene::BarTwist, PAPER, Some(3.0));
    let twisted = rms_from_rest(&mut run);
    let mut run = run_scene(PaperScene::BarTwist, PAPER, None);
    let end = rms_from_rest(&mut run);
    let body = run.app.world().get::<SoftBody>(run.body).unwrap();
    let speed = rms_speed(body.state().velocities());
    println!(
        "bar twist: rms distance from rest {twisted:.3} m twisted, {end:.3} m at the end; rms speed {speed:.4} m/s"
    );
    assert!(twisted > 0.2, "the bar was not twisted: {twisted}");
    assert!(
        end < 0.15 * twisted,
        "the bar did not return to its rest shape: {end} m vs {twisted} m"
    );
    assert!(
        speed < 0.02,
        "the bar is still swinging: rms speed {speed} m/s"
    );
}

fn rms_speed(velocities: &[Vec3]) -> f32 {
    (velocities.iter().map(|v| v.length_squared()).sum::<f32>() / velocities.len() as f32).sqrt()
}

fn rms_from_rest(run: &mut common::SceneRun) -> f32 {
    let body = run.app.world().get::<SoftBody>(run.body).unwrap();
    let rest = body.state().mesh().positions();
    let sum: f32 = body
        .state()
        .positions()
        .iter()
        .zip(rest)
        .map(|(p, r)| p.distance_squared(*r))
        .sum();
    (sum / rest.len() as f32).sqrt()
}

#[test]
fn sphere_on_bar_keeps_volume() {
    check_volumes(PaperScene::SphereOnBar, 3.5);
}

#[test]
fn soft_cube_keeps_volume_and_holds_the_sphere_in_a_dent() {
    let mut paper = check_volumes(PaperScene::SoftCube, 50.0);
    assert!(
        paper.deepest_below_ground < 1e-3,
        "a particle is {} m below the ground",
        paper.deepest_below_ground
    );

    let (centre, radius, velocity) = spheres(&mut paper.app)[0];
    let body = paper.app.world().get::<SoftBody>(paper.body).unwrap();
    let positions = body.state().positions();
    let top_at_rest = body.state().mesh().bounds().1.y;
    // A dent: the sphere's bottom is below the cube's rest top, but well above the ground.
    let bottom = centre.y - radius;
    println!(
        "soft cube: sphere bottom {bottom:.3} m, rest top {top_at_rest:.3} m, speed {:.3}",
        velocity.length()
    );
    assert!(
        bottom < top_at_rest - 0.05,
        "no dent: sphere bottom at {bottom}"
    );
    assert!(
        bottom > 0.25 * top_at_rest,
        "the sphere sank through the cube: bottom at {bottom}"
    );
    assert!(
        velocity.length() < 0.05,
        "the sphere is not resting: {velocity}"
    );
    // Resting on it, not inside it: no particle deeper than a few cm inside the sphere.
    let deepest = positions
        .iter()
        .map(|p| radius - p.distance(centre))
        .fold(f32::NEG_INFINITY, f32::max);
    assert!(
        deepest < 0.03,
        "a particle is {deepest} m inside the sphere"
    );
    // Particles below the sphere carry it: some are right under it.
    assert!(
        positions
            .iter()
            .any(|p| p.distance(centre) < radius + 0.05 && p.y < centre.y)
    );
}

#[test]
fn creature_keeps_volume_and_stays_above_the_ground() {
    check_volumes(PaperScene::Creature, 12.0);
    let run = run_scene(PaperScene::Creature, PAPER, None);
    assert!(
        run.deepest_below_ground < 1e-3,
        "a particle is {} m below the ground",
        run.deepest_below_ground
    );
}

#[test]
fn creature_jumps_up_again() {
    let run = run_scene(PaperScene::Creature, PAPER, None);
    let (landing, lowest) =
        run.com_y.iter().enumerate().fold(
            (0, f32::INFINITY),
            |a, (i, &y)| if y < a.1 { (i, y) } else { a },
        );
    let rise = run.com_y[landing..]
        .iter()
        .copied()
        .fold(f32::NEG_INFINITY, f32::max)
        - lowest;
    println!(
        "creature: centre of mass lowest {lowest:.3} m at step {landing}, rises {rise:.3} m after"
    );
    assert!(
        rise > 0.1,
        "the creature did not rise again after landing: {rise} m"
    );
    assert!(
        run.deepest_below_ground < 1e-3,
        "a particle is {} m below the ground",
        run.deepest_below_ground
    );
}

#[test]
fn plastic_block_keeps_volume_and_its_dent() {
    check_volumes(PaperScene::Plastic, 6.0);
    let run = run_scene(PaperScene::Plastic, PAPER, None);
    let body = run.app.world().get::<SoftBody>(run.body).unwrap();
    let rest_height = body.state().mesh().bounds().1.y;
    let height = body
        .state()
        .positions()
        .iter()
        .map(|p| p.y)
        .fold(f32::NEG_INFINITY, f32::max);
    println!(
        "plastic: height {height:.3} m of {rest_height:.3} m, five seconds after the sphere left"
    );
    assert!(
        height < 0.85 * rest_height,
        "no permanent deformation: height {height} of {rest_height}"
    );
}

#[test]
fn the_shipped_creature_is_closed_and_becomes_about_6500_tets() {
    use bevy_soft_body::scenes::{CREATURE_TETS, creature_surface};
    let surface = creature_surface();
    // Closed: every edge is shared by exactly two triangles, running it in opposite directions.
    let mut edges = std::collections::HashMap::new();
    for t in surface.indices.chunks_exact(3) {
        for k in 0..3 {
            *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
        }
    }
    for (&(a, b), &n) in &edges {
        assert_eq!(n, 1, "edge {a}-{b} used {n} times in one direction");
        assert_eq!(edges.get(&(b, a)), Some(&1), "edge {a}-{b} has no twin");
    }
    let tets = PaperScene::Creature.tet_mesh();
    let ratio = tets.tet_count() as f64 / CREATURE_TETS as f64;
    assert!((ratio - 1.0).abs() < 0.05, "{} tets", tets.tet_count());
    let volume = tets.total_rest_volume() / surface.enclosed_volume();
    assert!((volume - 1.0).abs() < 0.03, "volume ratio {volume}");
}
