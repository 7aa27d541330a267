//! Game-scale scenes in a window (`bevy_soft_body::game_scenes`): at Earth gravity and 60 Hz,
//! a jelly cube, a flesh cube and a hard rubber cube of 0.5 m dropped from 1 m, a rubber ball
//! dropped from 2 m and a 100 kg sphere landing on a jelly block, side by side, with the
//! presets' method (XPBD and its cluster volume correction). Controls are listed on screen; `--screenshot PATH --frames N` saves a picture after N
//! steps of 1/60 s and exits.

mod common;

use std::time::Duration;

use bevy::prelude::*;
use bevy_soft_body::core::VolumeMethod;
use bevy_soft_body::game_scenes::GameScene;
use bevy_soft_body::prelude::*;
use bevy_soft_body::surface_mesh;

/// The scenes shown, left to right, and their colours.
const SHOWN: [(&str, [f32; 3]); 5] = [
    ("jelly_cube_drop", [0.85, 0.25, 0.35]),
    ("flesh_cube_drop", [0.9, 0.6, 0.5]),
    ("hard_rubber_cube_drop", [0.2, 0.2, 0.22]),
    ("rubber_ball", [0.95, 0.75, 0.1]),
    ("heavy_sphere_on_jelly", [0.3, 0.7, 0.4]),
];

/// Metres between the scenes.
const SPACING: f32 = 1.3;

fn main() -> AppExit {
    let options = common::ExampleOptions::from_args();
    let screenshot = options.screenshot.is_some();
    let mut app = common::example_app_with("bevy_soft_body: game scale", None, options);
    app.insert_resource(Time::<Fixed>::from_hz(60.0))
        .add_systems(Startup, spawn_scenes)
        // After the common setup has spawned the camera.
        .add_systems(PostStartup, frame_scenes);
    if screenshot {
        // One 1/60 s step per frame, whatever the frame rate.
        app.insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
            Duration::from_secs_f64(1.0 / 60.0),
        ));
    }
    app.run()
}

fn spawn_scenes(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    let scenes = GameScene::standard();
    let count = SHOWN.len() as f32;
    for (k, (name, [r, g, b])) in SHOWN.into_iter().enumerate() {
        let Some(scene) = scenes.iter().find(|s| s.name == name) else {
            error!("no game scene {name}");
            continue;
        };
        let offset = Vec3::X * (k as f32 - 0.5 * (count - 1.0)) * SPACING;
        let body = match scene.spawn_body(&mut commands, VolumeMethod::default(), offset) {
            Ok(body) => body,
            Err(e) => {
                error!("{e}");
                continue;
            }
        };
        // The tet mesh's own boundary as the surface drawn.
        let surface = match scene.tet_mesh() {
            Ok(mesh) => mesh.boundary_surface(),
            Err(e) => {
                error!("{e}");
                continue;
            }
        };
        commands.entity(body).insert((
            Name::new(name),
            SoftBodySurface::new(body),
            Mesh3d(meshes.add(surface_mesh(&surface))),
            MeshMaterial3d(materials.add(StandardMaterial {
                base_color: Color::srgb(r, g, b),
                perceptual_roughness: 0.35,
                reflectance: 0.4,
                ..default()
            })),
        ));
    }
    commands.spawn((StaticCollider::ground(0.8), Transform::default()));
}

/// Frames the camera on the row of scenes, from the front.
fn frame_scenes(mut camera: Query<(&mut common::OrbitCamera, &mut Transform)>) {
    let count = SHOWN.len() as f32;
    if let Ok((mut orbit, mut transform)) = camera.single_mut() {
        let half = 0.5 * (count - 1.0) * SPACING + 0.4;
        common::frame_camera(
            &mut orbit,
            Vec3::new(-half, 0.0, -0.5),
            Vec3::new(half, 1.2, 0.5),
        );
        orbit.yaw = 0.0;
        orbit.pitch = 0.3;
        orbit.distance *= 0.72;
        *transform = orbit.transform();
    }
}
