//! Jellies piled on each other: three slabs stacked on the ground and a jelly cube on top, all
//! meeting each other through their soft contacts (no physics engine needed). T throws another
//! jelly at the stack; drag a jelly with the left mouse button; R starts again.

mod common;

use std::sync::Arc;

use bevy::prelude::*;
use bevy_soft_body::core::{TetMesh, box_grid};
use bevy_soft_body::prelude::*;
use bevy_soft_body::surface_mesh;
use common::{ExtraHelp, Grab, OrbitCamera, SceneMember, grab};

/// The cells' edge, in metres.
const CELL: f32 = 0.05;

fn main() -> AppExit {
    let mut app = common::example_app("bevy_soft_body: jelly stack", None);
    app.init_resource::<Grab>()
        .insert_resource(ExtraHelp(vec![
            "T: throw a jelly at the stack   left drag: pull a jelly",
        ]))
        .add_systems(Startup, spawn_scene)
        .add_systems(PostStartup, frame_scene)
        .add_systems(
            Update,
            (throw_jelly, grab, common::respawn_on_reset(spawn_scene)),
        );
    app.run()
}

/// A jelly box of `cells` cells with its lowest corner at `corner`, drawn in `colour`.
fn spawn_jelly(
    commands: &mut Commands,
    meshes: &mut Assets<Mesh>,
    materials: &mut Assets<StandardMaterial>,
    (name, cells): (&'static str, UVec3),
    corner: Vec3,
    colour: Color,
) -> Entity {
    let mesh: Arc<TetMesh> = box_grid(cells, Vec3::splat(CELL), Vec3::ZERO)
        .expect("a box grid is a valid mesh")
        .into();
    let surface = mesh.boundary_surface();
    let body = SoftBody::new(mesh, SoftBodyMaterial::JELLY).expect("the jelly preset is valid");
    let entity = commands
        .spawn((
            body,
            Transform::from_translation(corner),
            Name::new(name),
            SceneMember,
        ))
        .id();
    commands.entity(entity).insert((
        SoftBodySurface::new(entity),
        Mesh3d(meshes.add(surface_mesh(&surface))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: colour,
            perceptual_roughness: 0.3,
            reflectance: 0.5,
            ..default()
        })),
    ));
    entity
}

fn spawn_scene(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    commands.spawn((
        StaticCollider::ground(0.8),
        Transform::default(),
        SceneMember,
    ));
    let slab = UVec3::new(6, 2, 6);
    let slabs = [
        ("red slab", Color::srgb(0.85, 0.2, 0.3)),
        ("orange slab", Color::srgb(0.95, 0.6, 0.15)),
        ("green slab", Color::srgb(0.3, 0.7, 0.35)),
    ];
    for (k, (name, colour)) in slabs.into_iter().enumerate() {
        let corner = Vec3::new(-0.15 + 0.01 * (k % 2) as f32, 0.11 * k as f32, -0.15);
        spawn_jelly(
            &mut commands,
            &mut meshes,
            &mut materials,
            (name, slab),
            corner,
            colour,
        );
    }
    // A small cube on top.
    spawn_jelly(
        &mut commands,
        &mut meshes,
        &mut materials,
        ("blue cube", UVec3::splat(3)),
        Vec3::new(-0.075, 0.34, -0.075),
        Color::srgb(0.3, 0.45, 0.9),
    );
}

fn frame_scene(mut camera: Query<(&mut OrbitCamera, &mut Transform)>) {
    if let Ok((mut orbit, mut transform)) = camera.single_mut() {
        // A little right of the stack: the panel covers the window's right side.
        orbit.focus = Vec3::new(0.2, 0.2, 0.0);
        orbit.distance = 1.6;
        orbit.pitch = 0.35;
        *transform = orbit.transform();
    }
}

/// T throws a jelly cube from the camera towards where it looks.
fn throw_jelly(
    keys: Res<ButtonInput<KeyCode>>,
    camera: Query<&Transform, With<Camera3d>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut commands: Commands,
) {
    if !keys.just_pressed(KeyCode::KeyT) {
        return;
    }
    let Ok(eye) = camera.single() else {
        return;
    };
    let forward = *eye.forward();
    let start = eye.translation + forward * 0.8;
    let cells = UVec3::splat(3);
    let half = 0.5 * CELL * cells.as_vec3();
    let thrown = spawn_jelly(
        &mut commands,
        &mut meshes,
        &mut materials,
        ("thrown jelly", cells),
        start - half,
        Color::srgb(0.7, 0.3, 0.85),
    );
    commands.queue(move |world: &mut World| {
        if let Some(mut body) = world.get_mut::<SoftBody>(thrown) {
            body.velocities_mut().fill(forward * 5.0);
        }
    });
}
