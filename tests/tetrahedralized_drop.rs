//! A mesh the crate tetrahedralized itself behaves like the paper's scenes: dropped on the
//! ground with the new method, it keeps its volume within 1 %.

use std::sync::Arc;
use std::time::Duration;

use bevy::prelude::*;
use bevy_soft_body::core::{Resolution, VolumeMethod, tetrahedralize, torus};
use bevy_soft_body::prelude::*;
use bevy_soft_body::scenes::PaperScene;

#[test]
fn a_dropped_tetrahedralized_torus_keeps_its_volume() {
    // A torus lying flat, tilted a little so it does not land on its whole underside at once.
    let surface = torus(Vec3::ZERO, 1.0, 0.35, 64, 32);
    let t = tetrahedralize(
        &surface.positions,
        &surface.indices,
        Resolution::TargetTets(5000),
    )
    .unwrap();
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, SoftBodyPlugin::default()))
        .insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
            Duration::from_millis(10),
        ));
    let scene = PaperScene::Creature;
    app.insert_resource(SoftBodyGravity(scene.gravity()));
    let mut body = SoftBody::new(
        Arc::new(t.mesh),
        scene.material(VolumeMethod::PAPER_IMPULSES),
    )
    .unwrap();
    for v in body.velocities_mut() {
        v.y = -1.0;
    }
    let body = app
        .world_mut()
        .spawn((
            body,
            Transform::from_xyz(0.0, 0.6, 0.0).with_rotation(Quat::from_rotation_x(0.2)),
        ))
        .id();
    app.world_mut()
        .spawn((StaticCollider::ground(0.8), Transform::default()));
    let mut lowest_centre = f32::INFINITY;
    for _ in 0..400 {
        app.update();
        let centre = app.world().get::<Transform>(body).unwrap().translation;
        lowest_centre = lowest_centre.min(centre.y);
    }
    let stats = app.world().get::<SoftBodyStats>(body).unwrap();
    // It landed (the centre came down to the tube's radius, about) and kept its volume.
    assert!(lowest_centre < 0.45, "lowest centre {lowest_centre}");
    assert!(
        stats.peak_volume_error_pct < 1.0,
        "{}",
        stats.peak_volume_error_pct
    );
    assert_eq!(stats.max_inverted_tets, 0);
    let state = app.world().get::<SoftBody>(body).unwrap().state();
    assert!(state.positions().iter().all(|p| p.y > -0.01));
}
