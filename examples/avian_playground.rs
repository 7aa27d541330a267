//! Soft bodies in an avian3d world: crates, capsules and jellies fall on a ramp and on each
//! other. Grab a jelly with the left mouse button and drag it; T throws a crate from the
//! camera; R starts again.

mod common;

use std::sync::Arc;

use avian3d::prelude::*;
use bevy::prelude::*;
use bevy_soft_body::avian::SoftBodyAvianPlugin;
use bevy_soft_body::core::{TetMesh, box_grid};
use bevy_soft_body::prelude::*;
use bevy_soft_body::surface_mesh;
use common::{
    ExampleOptions, ExtraHelp, Grab, OrbitCamera, SceneMember, ThrownCrate, grab, throw_crate,
};

fn main() -> AppExit {
    let mut app = common::example_app_with(
        "bevy_soft_body: avian playground",
        None,
        ExampleOptions::from_args(),
    );
    app.add_plugins((PhysicsPlugins::default(), SoftBodyAvianPlugin))
        .init_resource::<Grab>()
        .insert_resource(ExtraHelp(vec![
            "left drag: grab and pull a jelly   T: throw a crate",
        ]))
        .add_systems(Startup, spawn_scene)
        .add_systems(PostStartup, frame_scene)
        .insert_resource(ThrownCrate {
            size: 0.3,
            mass: 8.0,
            speed: 7.0,
        })
        .add_systems(
            Update,
            (throw_crate, grab, common::respawn_on_reset(spawn_scene)),
        );
    app.run()
}

/// A crate's colour.
const WOOD: Color = Color::srgb(0.72, 0.52, 0.3);

fn spawn_scene(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    let grey = common::fixture_material(&mut materials);
    // The ground and a ramp, avian's static colliders.
    common::spawn_avian_ground(&mut commands, &mut meshes, grey.clone(), 12.0);
    let ramp = Vec3::new(2.4, 0.15, 1.4);
    commands.spawn((
        RigidBody::Static,
        Collider::cuboid(ramp.x, ramp.y, ramp.z),
        Mesh3d(meshes.add(Cuboid::from_size(ramp))),
        MeshMaterial3d(grey),
        Transform::from_xyz(-1.6, 0.55, 0.0).with_rotation(Quat::from_rotation_z(-0.4)),
        SceneMember,
    ));
    // Jellies: one at the top of the ramp, two on the ground with a crate dropped on each.
    let jellies = [
        (
            "red jelly",
            Vec3::new(-2.35, 1.15, -0.2),
            Color::srgb(0.85, 0.25, 0.35),
        ),
        (
            "green jelly",
            Vec3::new(0.6, 0.0, -0.2),
            Color::srgb(0.3, 0.75, 0.4),
        ),
        (
            "blue jelly",
            Vec3::new(1.6, 0.0, -0.2),
            Color::srgb(0.35, 0.5, 0.9),
        ),
    ];
    for (name, corner, colour) in jellies {
        let jelly = spawn_jelly(&mut commands, &mut meshes, &mut materials, corner, colour);
        commands.entity(jelly).insert(Name::new(name));
    }
    let wood = materials.add(StandardMaterial {
        base_color: WOOD,
        perceptual_roughness: 0.7,
        ..default()
    });
    for (at, turn) in [
        (Vec3::new(0.8, 0.9, 0.0), 0.3),
        (Vec3::new(1.75, 1.4, -0.05), -0.6),
    ] {
        commands.spawn((
            crate_bundle(&mut meshes, wood.clone()),
            Transform::from_translation(at).with_rotation(Quat::from_rotation_y(turn)),
        ));
    }
    // Capsules rolling down the ramp and onto the jellies.
    let capsule = meshes.add(Capsule3d::new(0.08, 0.3));
    let metal = materials.add(StandardMaterial {
        base_color: Color::srgb(0.8, 0.8, 0.85),
        metallic: 0.6,
        perceptual_roughness: 0.3,
        ..default()
    });
    for k in 0..3 {
        commands.spawn((
            RigidBody::Dynamic,
            Collider::capsule(0.08, 0.3),
            Mesh3d(capsule.clone()),
            MeshMaterial3d(metal.clone()),
            Transform::from_xyz(-2.2 + 0.25 * k as f32, 1.8 + 0.3 * k as f32, 0.35)
                .with_rotation(Quat::from_rotation_x(std::f32::consts::FRAC_PI_2)),
            SceneMember,
        ));
    }
}

/// A 0.36 m jelly cube of 6 cells a side with its lowest corner at `corner`, drawn with its tet
/// mesh's boundary.
fn spawn_jelly(
    commands: &mut Commands,
    meshes: &mut Assets<Mesh>,
    materials: &mut Assets<StandardMaterial>,
    corner: Vec3,
    colour: Color,
) -> Entity {
    let mesh: Arc<TetMesh> = box_grid(UVec3::splat(6), Vec3::splat(0.06), Vec3::ZERO)
        .expect("a 6-cell box is a valid mesh")
        .into();
    let surface = mesh.boundary_surface();
    let body = SoftBody::new(mesh, SoftBodyMaterial::JELLY).expect("the jelly preset is valid");
    let entity = commands
        .spawn((body, Transform::from_translation(corner), SceneMember))
        .id();
    commands.entity(entity).insert((
        SoftBodySurface::new(entity),
        Mesh3d(meshes.add(surface_mesh(&surface))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: colour,
            perceptual_roughness: 0.35,
            reflectance: 0.4,
            ..default()
        })),
    ));
    entity
}

/// A 0.3 m, 8 kg crate (transform to be added).
fn crate_bundle(meshes: &mut Assets<Mesh>, material: Handle<StandardMaterial>) -> impl Bundle {
    (
        RigidBody::Dynamic,
        Collider::cuboid(0.3, 0.3, 0.3),
        Mass(8.0),
        Mesh3d(meshes.add(Cuboid::from_length(0.3))),
        MeshMaterial3d(material),
        SceneMember,
    )
}

fn frame_scene(mut camera: Query<(&mut OrbitCamera, &mut Transform)>) {
    if let Ok((mut orbit, mut transform)) = camera.single_mut() {
        orbit.focus = Vec3::new(0.0, 0.5, 0.0);
        orbit.distance = 5.5;
        orbit.pitch = 0.35;
        orbit.yaw = 0.2;
        *transform = orbit.transform();
    }
}
