//! A soft punching bag hanging from a beam that swings on a hinge (avian3d): the middle of the
//! bag's top is attached to the beam's free end, the bag's weight swings the beam down and the
//! two swing together. T throws a crate at the bag; drag the bag with the left mouse button; R
//! starts again.

mod common;

use std::sync::Arc;

use avian3d::prelude::*;
use bevy::prelude::*;
use bevy_soft_body::avian::{SoftBodyAttachment, SoftBodyAvianPlugin};
use bevy_soft_body::core::{ParticleRegion, TetMesh, box_grid};
use bevy_soft_body::prelude::*;
use bevy_soft_body::surface_mesh;
use common::{
    ExampleOptions, ExtraHelp, Grab, OrbitCamera, SceneMember, ThrownCrate, grab, throw_crate,
};

/// The hinge, at the beam's left end.
const PIVOT: Vec3 = Vec3::new(-0.6, 2.0, 0.0);
/// The beam's length (a 30 kg steel beam; the bag weighs 33 kg).
const BEAM: f32 = 1.4;
/// The bag: width and height.
const BAG: Vec2 = Vec2::new(0.25, 0.5);

fn main() -> AppExit {
    let mut app = common::example_app_with(
        "bevy_soft_body: hanging bag",
        None,
        ExampleOptions::from_args(),
    );
    app.add_plugins((PhysicsPlugins::default(), SoftBodyAvianPlugin))
        .init_resource::<Grab>()
        .insert_resource(ExtraHelp(vec![
            "T: throw a crate at the bag   left drag: pull the bag",
        ]))
        .add_systems(Startup, spawn_scene)
        .add_systems(PostStartup, frame_scene)
        .insert_resource(ThrownCrate {
            size: 0.2,
            mass: 4.0,
            speed: 8.0,
        })
        .add_systems(
            Update,
            (throw_crate, grab, common::respawn_on_reset(spawn_scene)),
        );
    app.run()
}

fn spawn_scene(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    let grey = common::fixture_material(&mut materials);
    common::spawn_avian_ground(&mut commands, &mut meshes, grey.clone(), 10.0);
    // The post and the hinge at its top.
    let post = commands
        .spawn((
            RigidBody::Static,
            Collider::cuboid(0.12, PIVOT.y, 0.12),
            Mesh3d(meshes.add(Cuboid::new(0.12, PIVOT.y, 0.12))),
            MeshMaterial3d(grey),
            Transform::from_xyz(PIVOT.x - 0.1, PIVOT.y / 2.0, 0.0),
            SceneMember,
        ))
        .id();
    // The beam, level to start with, hinged at its left end.
    let beam_centre = PIVOT + Vec3::X * (BEAM / 2.0);
    let beam = commands
        .spawn((
            RigidBody::Dynamic,
            Collider::cuboid(BEAM, 0.08, 0.08),
            Mass(30.0),
            Mesh3d(meshes.add(Cuboid::new(BEAM, 0.08, 0.08))),
            MeshMaterial3d(materials.add(StandardMaterial {
                base_color: Color::srgb(0.72, 0.52, 0.3),
                ..default()
            })),
            Transform::from_translation(beam_centre),
            SceneMember,
        ))
        .id();
    commands.spawn((
        RevoluteJoint::new(post, beam).with_anchor(PIVOT),
        SceneMember,
    ));
    // The bag under the beam's free end.
    let cells = UVec3::new(5, 10, 5);
    let mesh: Arc<TetMesh> = box_grid(cells, Vec3::splat(BAG.x / 5.0), Vec3::ZERO)
        .expect("a box grid is a valid mesh")
        .into();
    // The particles around the middle of the top face: the bag hangs from them and dangles.
    let top = mesh.particles_in(ParticleRegion::Sphere {
        centre: Vec3::new(BAG.x / 2.0, BAG.y, BAG.x / 2.0),
        radius: 0.09,
    });
    let surface = mesh.boundary_surface();
    let body = SoftBody::new(mesh, SoftBodyMaterial::FLESH).expect("the flesh preset is valid");
    let corner = Vec3::new(
        PIVOT.x + BEAM - BAG.x / 2.0 - 0.08,
        PIVOT.y - 0.05 - BAG.y,
        -BAG.x / 2.0,
    );
    let bag = commands
        .spawn((
            body,
            Transform::from_translation(corner),
            SoftBodyAttachment::hard(beam, top),
            Name::new("bag"),
            SceneMember,
        ))
        .id();
    commands.entity(bag).insert((
        SoftBodySurface::new(bag),
        Mesh3d(meshes.add(surface_mesh(&surface))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::srgb(0.75, 0.15, 0.15),
            perceptual_roughness: 0.5,
            ..default()
        })),
    ));
}

fn frame_scene(mut camera: Query<(&mut OrbitCamera, &mut Transform)>) {
    if let Ok((mut orbit, mut transform)) = camera.single_mut() {
        orbit.focus = Vec3::new(0.2, 1.3, 0.0);
        orbit.distance = 4.0;
        orbit.pitch = 0.15;
        orbit.yaw = 0.0;
        *transform = orbit.transform();
    }
}
