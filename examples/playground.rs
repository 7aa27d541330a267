//! Play with the paper's scenes: grab any point of a soft body with the left mouse button and
//! drag it, throw rigid spheres with T, switch scenes with 1 to 5, reset with R.
//! `--scene NAME` picks the first scene.

mod common;

use bevy::prelude::*;
use bevy::window::PrimaryWindow;
use bevy_soft_body::prelude::*;
use bevy_soft_body::scenes::PaperScene;
use common::{ExampleOptions, ExtraHelp, Layout, ResetScene, SceneMember};

/// Particles within this distance of the grabbed point move with the cursor.
const GRAB_RADIUS: f32 = 0.12;

/// The grab in progress: the body, the handle entity its particles follow, and the distance
/// from the camera of the plane the handle moves in.
#[derive(Resource, Default)]
struct Grab(Option<(Entity, Entity, f32)>);

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

#[allow(clippy::too_many_arguments)]
fn grab(
    buttons: Res<ButtonInput<MouseButton>>,
    window: Query<&Window, With<PrimaryWindow>>,
    camera: Query<(&Camera, &GlobalTransform)>,
    mut bodies: Query<(Entity, &SoftBody, Option<&DrivenParticles>)>,
    mut handles: Query<&mut Transform>,
    mut state: ResMut<Grab>,
    mut commands: Commands,
) {
    let (Ok(window), Ok((camera, eye))) = (window.single(), camera.single()) else {
        return;
    };
    let ray = window
        .cursor_position()
        .and_then(|c| camera.viewport_to_world(eye, c).ok());
    if buttons.just_released(MouseButton::Left) {
        if let Some((body, handle, _)) = state.0.take() {
            if let Ok(mut b) = commands.get_entity(body) {
                b.remove::<DrivenParticles>();
            }
            commands.entity(handle).despawn();
        }
        return;
    }
    let Some(ray) = ray else {
        return;
    };
    if let Some((_, handle, depth)) = state.0 {
        if let Ok(mut t) = handles.get_mut(handle) {
            t.translation = ray.origin + *ray.direction * depth;
        }
        return;
    }
    if !buttons.just_pressed(MouseButton::Left) {
        return;
    }
    // The particle nearest the cursor's ray (within a few cm of it), nearest the eye first.
    let mut best: Option<(Entity, Vec3, f32)> = None;
    for (entity, body, driven) in &mut bodies {
        if driven.is_some() || !body.is_placed() {
            continue;
        }
        for &p in body.state().positions() {
            let along = (p - ray.origin).dot(*ray.direction);
            let off = (ray.origin + *ray.direction * along).distance(p);
            if along > 0.0 && off < 0.08 && best.is_none_or(|(_, _, d)| along < d) {
                best = Some((entity, p, along));
            }
        }
    }
    let Some((entity, at, depth)) = best else {
        return;
    };
    let Ok((_, body, _)) = bodies.get(entity) else {
        return;
    };
    let particles: Vec<u32> = body
        .state()
        .positions()
        .iter()
        .enumerate()
        .filter(|(_, p)| p.distance(at) < GRAB_RADIUS)
        .map(|(i, _)| i as u32)
        .collect();
    let handle = commands
        .spawn((Transform::from_translation(at), SceneMember))
        .id();
    commands
        .entity(entity)
        .insert(DrivenParticles::new(handle, particles));
    state.0 = Some((entity, handle, depth));
}
