//! Play with the paper's scenes: grab any point of a soft body with the left mouse button and
//! drag it, throw rigid spheres with T, switch scenes with 1 to 5, reset with R.
//! `--scene NAME` picks the first scene.
//!
//! Grabbing is the crate's picking (feature `picking`): `SoftBodyPickingPlugin` makes the
//! pointer's ray hit the bodies' deformed surfaces, and `SoftBodyDraggable` on a body lets the
//! pointer drag it by the point pressed. With `--screenshot`, a scripted pointer (the same
//! picking input a mouse gives) grabs the body and pulls it up, so the picture shows a grab.

mod common;

use bevy::camera::NormalizedRenderTarget;
use bevy::picking::pointer::{Location, PointerAction, PointerButton, PointerId, PointerInput};
use bevy::prelude::*;
use bevy::window::{PrimaryWindow, WindowRef};
use bevy_soft_body::picking::{SoftBodyDraggable, SoftBodyPickingPlugin};
use bevy_soft_body::prelude::*;
use bevy_soft_body::scenes::PaperScene;
use common::{ExampleOptions, ExtraHelp, Layout, ResetScene, SceneMember};

fn main() -> AppExit {
    let options = ExampleOptions::from_args();
    let scene = options.scene.unwrap_or(PaperScene::SoftCube);
    let scripted = options.screenshot.is_some();
    let mut app = common::example_app_with(
        "bevy_soft_body: playground",
        Some(Layout::Single(scene)),
        options,
    );
    app.add_plugins(SoftBodyPickingPlugin)
        .insert_resource(ExtraHelp(vec![
            "left drag: grab and pull   T: throw a sphere",
            "1-5: bar twist, sphere on bar, soft cube, creature, plastic",
        ]))
        .add_systems(Update, (switch_scene, throw_sphere, make_draggable));
    if scripted {
        app.add_systems(Update, scripted_drag);
    }
    app.run()
}

/// Every soft body the scenes spawn can be dragged. The paper's scenes are metres across
/// under a gravity of 0.01 to 0.2 m/s^2: the pull is gentler than the default, made for
/// Earth's.
fn make_draggable(
    bodies: Query<Entity, (Added<SoftBody>, Without<SoftBodyDraggable>)>,
    mut commands: Commands,
) {
    for body in &bodies {
        commands.entity(body).insert(SoftBodyDraggable {
            frequency: 2.0,
            max_acceleration: 5.0,
            ..default()
        });
    }
}

fn switch_scene(
    keys: Res<ButtonInput<KeyCode>>,
    mut layout: ResMut<Layout>,
    mut reset: ResMut<ResetScene>,
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

/// For `--screenshot`: the mouse pointer, driven as the window would drive it, presses the
/// first body at its top corner nearest the eye from frame 10 and moves up and left until
/// frame 50, then holds.
fn scripted_drag(
    mut frame: Local<u32>,
    mut at: Local<Option<Vec2>>,
    window: Query<Entity, With<PrimaryWindow>>,
    camera: Query<(&Camera, &GlobalTransform), With<Camera3d>>,
    bodies: Query<&SoftBody>,
    mut input: MessageWriter<PointerInput>,
) {
    *frame += 1;
    let (Ok(window), Ok((camera, eye))) = (window.single(), camera.single()) else {
        return;
    };
    let Some(window) = WindowRef::Primary.normalize(Some(window)) else {
        return;
    };
    let location = |position| Location {
        target: NormalizedRenderTarget::Window(window),
        position,
    };
    let send = |input: &mut MessageWriter<PointerInput>, position, action| {
        input.write(PointerInput::new(
            PointerId::Mouse,
            location(position),
            action,
        ));
    };
    match *frame {
        10 => {
            let Some(body) = bodies.iter().find(|b| b.is_placed()) else {
                return;
            };
            // The top corner nearest the eye, a little inside the body.
            let positions = body.state().positions();
            let top = positions
                .iter()
                .map(|p| p.y)
                .fold(f32::NEG_INFINITY, f32::max);
            let eye_at = eye.translation();
            let corner = (positions.iter())
                .filter(|p| p.y > top - 0.01 * top.abs().max(1.0))
                .min_by(|a, b| a.distance(eye_at).total_cmp(&b.distance(eye_at)))
                .copied()
                .unwrap_or(top * Vec3::Y);
            let point = corner.lerp(body.state().centre_of_mass(), 0.1);
            let Ok(position) = camera.world_to_viewport(eye, point) else {
                return;
            };
            send(
                &mut input,
                position,
                PointerAction::Move { delta: Vec2::ZERO },
            );
            send(
                &mut input,
                position,
                PointerAction::Press(PointerButton::Primary),
            );
            *at = Some(position);
        }
        11..=50 => {
            let Some(position) = at.as_mut() else { return };
            let delta = Vec2::new(-4.0, -5.0);
            *position += delta;
            send(&mut input, *position, PointerAction::Move { delta });
        }
        _ => {}
    }
}
