//! The embedded render surface follows the tets (feature `render`): headless, with
//! `MinimalPlugins` plus the asset and mesh plugins.
#![cfg(feature = "render")]

use bevy::mesh::{MeshPlugin, VertexAttributeValues};
use bevy::prelude::*;
use bevy_soft_body::core::{VolumeMethod, box_grid, subdivided_box};
use bevy_soft_body::prelude::*;
use bevy_soft_body::surface_mesh;

/// `MinimalPlugins` with assets, meshes, the simulation and the surfaces.
fn surface_app() -> App {
    let mut app = App::new();
    app.add_plugins((
        MinimalPlugins,
        AssetPlugin::default(),
        MeshPlugin,
        SoftBodyPlugin::default(),
        SoftBodySurfacePlugin,
    ));
    app
}

#[test]
fn surface_vertices_are_the_barycentric_combination_of_their_tets_particles() {
    let mut app = surface_app();
    // Frames of 7 ms against 10 ms steps: most frames fall between two steps.
    app.insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
        std::time::Duration::from_millis(7),
    ))
    .insert_resource(SoftBodyGravity(Vec3::new(0.0, -9.81, 0.0)));
    let tets = box_grid(UVec3::new(4, 3, 5), Vec3::splat(0.1), Vec3::ZERO).unwrap();
    let (lo, hi) = tets.bounds();
    // A surface finer than the tets, part of it outside them (extrapolated).
    let mut fine = subdivided_box(lo, hi, 0.025);
    fine.positions.push(hi + Vec3::splat(0.03));
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(surface_mesh(&fine));
    let material = SoftBodyMaterial {
        method: VolumeMethod::PAPER_IMPULSES,
        ..Default::default()
    };
    let body = app
        .world_mut()
        .spawn((
            SoftBody::new(tets.into(), material).unwrap(),
            // Placed, rotated and scaled: the surface must follow all of it.
            Transform::from_xyz(0.0, 0.5, 0.0)
                .with_rotation(Quat::from_rotation_z(0.4))
                .with_scale(Vec3::splat(1.5)),
        ))
        .id();
    app.world_mut()
        .entity_mut(body)
        .insert((SoftBodySurface::new(body), Mesh3d(mesh.clone())));
    app.world_mut()
        .spawn((StaticCollider::ground(0.5), Transform::default()));

    let mut checked = 0;
    for frame in 0..60 {
        app.update();
        let world = app.world();
        let soft = world.get::<SoftBody>(body).unwrap();
        let surface = world.get::<SoftBodySurface>(body).unwrap();
        let Some(binding) = surface.binding() else {
            continue;
        };
        let alpha = world.resource::<Time<Fixed>>().overstep_fraction();
        let state = soft.state();
        let particle = |i: u32| {
            state.previous_positions()[i as usize].lerp(state.positions()[i as usize], alpha)
        };
        let translation = world.get::<Transform>(body).unwrap().translation;
        let Some(VertexAttributeValues::Float32x3(vertices)) = world
            .resource::<Assets<Mesh>>()
            .get(&mesh)
            .unwrap()
            .attribute(Mesh::ATTRIBUTE_POSITION)
        else {
            panic!("no positions");
        };
        assert_eq!(vertices.len(), fine.positions.len());
        for ((v, &t), w) in vertices.iter().zip(binding.tets()).zip(binding.weights()) {
            let tet = state.mesh().tets()[t as usize];
            let expected = (0..4).map(|k| particle(tet[k]) * w[k]).sum::<Vec3>() - translation;
            assert!(
                Vec3::from(*v).distance(expected) < 1e-4,
                "frame {frame}: {v:?} vs {expected}"
            );
        }
        checked += 1;
    }
    assert!(
        checked > 40,
        "the surface was bound too late: {checked} frames checked"
    );
    // It fell and deformed: the body is no longer where it started, and the mesh moved with it.
    let state = app.world().get::<SoftBody>(body).unwrap().state();
    let lowest = state
        .positions()
        .iter()
        .map(|p| p.y)
        .fold(f32::INFINITY, f32::min);
    assert!(lowest < 0.05, "the body did not reach the ground: {lowest}");
    // Bounds for culling follow the mesh.
    let aabb = app
        .world()
        .get::<bevy::camera::primitives::Aabb>(body)
        .unwrap();
    assert!(aabb.half_extents.length() > 0.3);
}

#[test]
fn a_surface_without_a_body_is_reported_not_a_panic() {
    let mut app = surface_app();
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(surface_mesh(&subdivided_box(Vec3::ZERO, Vec3::ONE, 0.5)));
    let nobody = app.world_mut().spawn_empty().id();
    app.world_mut()
        .spawn((SoftBodySurface::new(nobody), Mesh3d(mesh)));
    app.update();
    app.update();
    let errors = app.world().resource::<Messages<SoftBodyError>>();
    let mut cursor = errors.get_cursor();
    let seen: Vec<_> = cursor.read(errors).collect();
    assert_eq!(seen.len(), 1, "reported once: {seen:?}");
    assert!(matches!(seen[0].kind, SoftBodyErrorKind::Surface { .. }));
}
