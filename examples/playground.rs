//! Play with the paper's scenes: grab any point of a soft body with the left mouse button and
//! drag it, throw rigid spheres with T, switch scenes with 1 to 5, reset with R.
//! `--scene NAME` picks the first scene.

mod common;

use bevy::prelude::*;
use bevy_soft_body::prelude::*;
use bevy_soft_body::scenes::PaperScene;
use common::{ExampleOptions, ExtraHelp, Grab, Layout, ResetScene, SceneMember, grab};

fn main() -> AppExit {
    let scene = ExampleOptions::from_args()
        .scene
        .unwrap_or(PaperScene::SoftCube);
    let mut app = common::example_app("bevy_soft_body: playground", Some(Layout::Single(scene)));
    app.init_resource::<Grab>()
        .insert_resource(ExtraHelp(vec![
            "left drag: grab and pull   T: throw a sphere",
            "1-5: bar twist, sphere on bar, soft cube, creature, plastic",
        ]))
        .add_systems(Update, (switch_scene, throw_sphere, grab));
    app.run()
}

fn switch_scene(
    keys: Res<ButtonInput<KeyCode>>,
    mut layout: ResMut<Layout>,
    mut reset: ResMut<ResetScene>,
    mut grab: ResMut<Grab>,
) {
    let keys_to_scenes = [
        (KeyCode::Digit1, PaperScene::BarTwist),
        (KeyCode::Digit2, PaperScene::SphereOnBar),
        (KeyCode::Digit3, PaperScene::SoftCube),
        (KeyCode::Digit4, PaperScene::Creature),
        (KeyCode::Digit5, PaperScene::Plastic),
    ];
    for (key, scene) in keys_to_scenes {
        if keys.just_pressed(key) {
            *layout = Layout::Single(scene);
            reset.0 = true;
            grab.0 = None;
        }
    }
}

fn throw_sphere(
    keys: Res<ButtonInput<KeyCode>>,
    camera: Query<&Transform, With<Camera3d>>,
    mut commands: Commands,
) {
    if !keys.just_pressed(KeyCode::KeyT) {
        return;
    }
    let Ok(eye) = camera.single() else {
        return;
    };
    let mut sphere = RigidSphere::new(0.2, 150.0);
    sphere.velocity = eye.forward() * 6.0;
    commands.spawn((
        sphere,
        Transform::from_translation(eye.translation + eye.forward() * 0.5),
        SceneMember,
    ));
}
