//! Soft bodies from assets (feature `render`): a render mesh tetrahedralized off the main
//! thread, and TetGen files loaded through the asset server. Headless, with `MinimalPlugins`
//! plus the asset and mesh plugins.
#![cfg(feature = "render")]

use std::path::PathBuf;
use std::time::Duration;

use bevy::mesh::MeshPlugin;
use bevy::prelude::*;
use bevy_soft_body::core::{Resolution, box_grid, uv_sphere, write_tetgen};
use bevy_soft_body::prelude::*;
use bevy_soft_body::surface_mesh;

fn loading_app(asset_dir: Option<&PathBuf>) -> App {
    let mut app = App::new();
    let assets = match asset_dir {
        Some(dir) => AssetPlugin {
            file_path: dir.to_string_lossy().into_owned(),
            ..default()
        },
        None => AssetPlugin::default(),
    };
    app.add_plugins((
        MinimalPlugins,
        assets,
        MeshPlugin,
        SoftBodyPlugin::default(),
        SoftBodySurfacePlugin,
        SoftBodyAssetPlugin::default(),
    ))
    .init_resource::<Seen>()
    .add_systems(
        PostUpdate,
        |mut reader: MessageReader<SoftBodyError>, mut seen: ResMut<Seen>| {
            seen.0.extend(reader.read().cloned());
        },
    );
    app
}

/// Every [`SoftBodyError`] written so far.
#[derive(Resource, Default)]
struct Seen(Vec<SoftBodyError>);

/// Updates until `done` holds, for at most 20 s of wall time (the build runs on other threads).
fn update_until(app: &mut App, done: impl Fn(&World) -> bool) {
    for _ in 0..4000 {
        app.update();
        if done(app.world()) {
            return;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    panic!("not done after 20 s");
}

fn build_errors(app: &App) -> Vec<SoftBodyError> {
    app.world().resource::<Seen>().0.clone()
}

#[test]
fn a_render_mesh_becomes_a_body_built_off_the_main_thread() {
    let mut app = loading_app(None);
    let sphere = uv_sphere(Vec3::ZERO, 0.5, 48, 24);
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(surface_mesh(&sphere));
    let entity = app
        .world_mut()
        .spawn((
            SoftBodyFromAsset::new(
                SoftBodySource::Mesh {
                    mesh: mesh.clone(),
                    resolution: Resolution::TargetTets(2000),
                },
                SoftBodyMaterial::default(),
            ),
            Mesh3d(mesh),
            Transform::from_xyz(0.0, 1.0, 0.0),
        ))
        .id();
    app.update();
    // The first frame starts the build and returns: the body comes on a later frame.
    let from = app.world().get::<SoftBodyFromAsset>(entity).unwrap();
    assert!(from.is_building());
    assert!(app.world().get::<SoftBody>(entity).is_none());
    update_until(&mut app, |w| w.get::<SoftBody>(entity).is_some());
    let body = app.world().get::<SoftBody>(entity).unwrap();
    let tets = body.state().mesh().tet_count();
    assert!((1700..=2300).contains(&tets), "{tets} tets");
    assert!(app.world().get::<SoftBodySurface>(entity).is_some());
    assert!(app.world().get::<SoftBodyFromAsset>(entity).is_none());
    assert!(build_errors(&app).is_empty());
}

#[test]
fn a_mesh_that_cannot_be_a_body_is_reported() {
    let mut app = loading_app(None);
    // A flat square: encloses nothing.
    let square = bevy_soft_body::core::TriangleSurface {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.0, 1.0), Vec3::Z],
        indices: vec![0, 1, 2, 0, 2, 3],
    };
    let mesh = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(surface_mesh(&square));
    let entity = app
        .world_mut()
        .spawn(SoftBodyFromAsset::new(
            SoftBodySource::Mesh {
                mesh,
                resolution: Resolution::default(),
            },
            SoftBodyMaterial::default(),
        ))
        .id();
    update_until(&mut app, |w| w.get::<SoftBodyFromAsset>(entity).is_none());
    assert!(app.world().get::<SoftBody>(entity).is_none());
    let errors = build_errors(&app);
    assert_eq!(errors.len(), 1);
    assert_eq!(errors[0].body, entity);
    assert!(matches!(errors[0].kind, SoftBodyErrorKind::Build { .. }));
    assert!(
        errors[0].to_string().contains("encloses no cell"),
        "{}",
        errors[0]
    );
}

#[test]
fn tetgen_and_obj_files_load_as_assets() {
    let dir = std::env::temp_dir().join(format!("bevy_soft_body_loading_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cube = box_grid(UVec3::new(3, 2, 2), Vec3::splat(0.1), Vec3::ZERO).unwrap();
    let (node, ele) = write_tetgen(&cube);
    std::fs::write(dir.join("cube.node"), &node).unwrap();
    std::fs::write(dir.join("cube.ele"), &ele).unwrap();
    std::fs::write(dir.join("broken.node"), &node).unwrap();
    std::fs::write(dir.join("broken.ele"), "1 4 0\n1 1 2 3\n").unwrap();
    let sphere = uv_sphere(Vec3::ZERO, 0.5, 24, 12);
    std::fs::write(
        dir.join("sphere.obj"),
        bevy_soft_body::core::write_obj(&sphere),
    )
    .unwrap();

    let mut app = loading_app(Some(&dir));
    let server = app.world().resource::<AssetServer>().clone();
    let good = app
        .world_mut()
        .spawn(SoftBodyFromAsset::new(
            SoftBodySource::TetMesh(server.load("cube.node")),
            SoftBodyMaterial::default(),
        ))
        .id();
    let bad = app
        .world_mut()
        .spawn(SoftBodyFromAsset::new(
            SoftBodySource::TetMesh(server.load("broken.node")),
            SoftBodyMaterial::default(),
        ))
        .id();
    // An OBJ file loads as a render mesh, drawn and made a body.
    let obj: Handle<Mesh> = server.load("sphere.obj");
    let from_obj = app
        .world_mut()
        .spawn((
            SoftBodyFromAsset::new(
                SoftBodySource::Mesh {
                    mesh: obj.clone(),
                    resolution: Resolution::TargetTets(1000),
                },
                SoftBodyMaterial::default(),
            ),
            Mesh3d(obj),
        ))
        .id();
    update_until(&mut app, |w| {
        [good, bad, from_obj]
            .iter()
            .all(|&e| w.get::<SoftBodyFromAsset>(e).is_none())
    });
    let obj_body = app.world().get::<SoftBody>(from_obj).unwrap();
    assert!(obj_body.state().mesh().tet_count() > 800);
    assert!(app.world().get::<SoftBodySurface>(from_obj).is_some());
    let body = app.world().get::<SoftBody>(good).unwrap();
    assert_eq!(body.state().mesh().tets(), cube.tets());
    assert!(app.world().get::<SoftBody>(bad).is_none());
    let errors = build_errors(&app);
    assert_eq!(errors.len(), 1);
    assert_eq!(errors[0].body, bad);
    std::fs::remove_dir_all(&dir).ok();
}

/// Added before the asset and mesh plugins, the loading registers once every plugin is in
/// (`App::finish`, which `App::run` calls), and only once.
#[test]
fn the_asset_plugin_added_before_the_asset_plugin_registers_at_finish() {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, SoftBodyPlugins));
    assert!(!app.world().contains_resource::<Assets<TetMeshAsset>>());
    app.add_plugins((AssetPlugin::default(), MeshPlugin));
    app.finish();
    app.cleanup();
    assert!(app.world().contains_resource::<Assets<TetMeshAsset>>());
    app.update();
}
