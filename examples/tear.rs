//! Tearing and cutting. A jelly bar pulled apart: two hands (`SoftBodyGrab`) hold its ends and
//! draw them apart until the jelly tears (`SoftBodyTearing`) and the two pieces hang from the
//! hands, each keeping its volume; the cut faces are drawn. Beside it a flesh block on the
//! ground is cut by a fast thin blade (a `StaticCollider` with `SoftBodyCutter`, moved down
//! through it at 3 m/s). The message `SoftBodyTorn` is logged. R starts again.

mod common;

use std::sync::Arc;

use bevy::prelude::*;
use bevy_soft_body::core::{TetMesh, box_grid};
use bevy_soft_body::prelude::*;
use bevy_soft_body::surface_mesh;
use common::{ExtraHelp, Grab, OrbitCamera, SceneMember};
use parry3d::shape::SharedShape;

/// The bar's cells: 0.6 m long, 0.15 m square.
const CELLS: UVec3 = UVec3::new(12, 3, 3);
const CELL: f32 = 0.05;
/// Where the bar's lowest corner starts.
const CORNER: Vec3 = Vec3::new(-0.3, 0.6, -0.075);
/// How fast each hand moves out, m/s, after the first fifth of a second.
const PULL_SPEED: f32 = 0.5;

/// The hands: each grab's starting point, and when the scene started.
#[derive(Resource, Default)]
struct Hands {
    started: Option<f32>,
}

fn main() -> AppExit {
    let mut app = common::example_app("bevy_soft_body: tear", None);
    app.init_resource::<Hands>()
        .init_resource::<Grab>()
        .insert_resource(ExtraHelp(vec!["two hands pull a jelly bar apart"]))
        .add_systems(Startup, spawn_scene)
        .add_systems(PostStartup, frame_scene)
        .add_systems(Update, (common::respawn_on_reset(spawn_scene), log_tears))
        .add_systems(
            FixedUpdate,
            (move_hands, move_blade).before(SoftBodySystems::Prepare),
        );
    app.run()
}

fn spawn_scene(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    commands.insert_resource(Hands::default());
    commands.spawn((
        StaticCollider::ground(0.8),
        Transform::default(),
        SceneMember,
    ));
    let mesh: Arc<TetMesh> = box_grid(CELLS, Vec3::splat(CELL), Vec3::ZERO)
        .expect("a box grid is a valid mesh")
        .into();
    let surface = mesh.boundary_surface();
    let body = SoftBody::new(mesh, SoftBodyMaterial::JELLY).expect("the jelly preset is valid");
    let size = CELLS.as_vec3() * CELL;
    let ends = [0.0, size.x].map(|x| CORNER + Vec3::new(x, size.y / 2.0, size.z / 2.0));
    let grab = |at: Vec3| {
        // 1.5 kN/m on the 14 kg bar: it holds it up and stretches it past its limit.
        let mut grab = SoftBodyGrab::new(at, 1500.0);
        grab.radius = Some(0.15);
        grab
    };
    let entity = commands
        .spawn((
            body,
            SoftBodyTearing::default(),
            grab(ends[0]),
            Transform::from_translation(CORNER),
            Name::new("jelly bar"),
            SceneMember,
        ))
        .id();
    // A flesh block on the ground and a blade above it.
    let block: Arc<TetMesh> = box_grid(UVec3::new(6, 4, 4), Vec3::splat(CELL), Vec3::ZERO)
        .expect("a box grid is a valid mesh")
        .into();
    let block_surface = block.boundary_surface();
    let block = SoftBody::new(block, SoftBodyMaterial::FLESH).expect("the flesh preset is valid");
    let block = commands
        .spawn((
            block,
            SoftBodyTearing::default(),
            Transform::from_xyz(1.0, 0.0, -0.1),
            Name::new("flesh block"),
            SceneMember,
        ))
        .id();
    commands.entity(block).insert((
        SoftBodySurface::new(block),
        Mesh3d(meshes.add(surface_mesh(&block_surface))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::srgb(0.85, 0.45, 0.45),
            perceptual_roughness: 0.5,
            cull_mode: None,
            ..default()
        })),
    ));
    let blade = Vec3::new(0.003, 0.25, 0.3);
    commands.spawn((
        StaticCollider::new(SharedShape::cuboid(blade.x, blade.y, blade.z), 0.0),
        SoftBodyCutter,
        Blade,
        Transform::from_xyz(1.151, 0.6, 0.0),
        Mesh3d(meshes.add(Cuboid::from_size(2.0 * blade))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::srgb(0.75, 0.77, 0.8),
            metallic: 0.9,
            perceptual_roughness: 0.2,
            ..default()
        })),
        SceneMember,
    ));
    // The second hand: a grab is one component a body, so it sits on a child body-less entity
    // that `move_hands` applies through the core.
    commands.spawn((
        Hand {
            end: ends[1],
            grab: grab(ends[1]),
            body: entity,
        },
        SceneMember,
    ));
    commands.entity(entity).insert((
        SoftBodySurface::new(entity),
        Mesh3d(meshes.add(surface_mesh(&surface))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::srgb(0.3, 0.75, 0.35),
            perceptual_roughness: 0.3,
            reflectance: 0.5,
            cull_mode: None,
            ..default()
        })),
    ));
}

/// The second hand's grab (see `spawn_scene`).
#[derive(Component)]
struct Hand {
    end: Vec3,
    grab: SoftBodyGrab,
    body: Entity,
}

/// Moves both hands out along the bar after the first fifth of a second.
fn move_hands(
    time: Res<Time>,
    mut hands: ResMut<Hands>,
    mut grabs: Query<&mut SoftBodyGrab>,
    mut second: Query<&mut Hand>,
    mut bodies: Query<&mut SoftBody>,
) {
    let now = time.elapsed_secs();
    let started = *hands.started.get_or_insert(now);
    let out = PULL_SPEED * (now - started - 0.2).max(0.0);
    for mut grab in &mut grabs {
        grab.target = grab.point - Vec3::X * out;
    }
    let h = time.delta_secs();
    for mut hand in &mut second {
        let target = hand.end + Vec3::X * out;
        hand.grab.target = target;
        let Ok(mut body) = bodies.get_mut(hand.body) else {
            continue;
        };
        if h > 0.0 && body.is_placed() {
            body.pull(&mut hand.grab, h);
        }
    }
}

/// The blade.
#[derive(Component)]
struct Blade;

/// Brings the blade down through the block at 3 m/s after half a second, to below the ground's
/// surface, then back up.
fn move_blade(time: Res<Time>, hands: Res<Hands>, mut blades: Query<&mut Transform, With<Blade>>) {
    let Some(started) = hands.started else { return };
    let t = time.elapsed_secs() - started;
    for mut blade in &mut blades {
        let down = (3.0 * (t - 0.5)).clamp(0.0, 0.55);
        let up = (3.0 * (t - 1.0)).clamp(0.0, 0.55);
        blade.translation.y = 0.6 - down + up;
    }
}

fn log_tears(mut torn: MessageReader<SoftBodyTorn>) {
    for t in torn.read() {
        info!(
            "{} tore at {} points: {} pieces",
            t.body,
            t.points.len(),
            t.pieces
        );
    }
}

fn frame_scene(mut camera: Query<(&mut OrbitCamera, &mut Transform)>) {
    if let Ok((mut orbit, mut transform)) = camera.single_mut() {
        orbit.focus = Vec3::new(0.5, 0.45, 0.0);
        orbit.distance = 2.9;
        orbit.pitch = 0.2;
        *transform = orbit.transform();
    }
}
