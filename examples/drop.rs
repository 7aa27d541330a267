//! Drops any mesh on the ground with the paper's method:
//!
//! cargo run --release --all-features --example drop -- MESH [--tets N] [--seconds S] [--headless]
//!
//! `MESH` is an OBJ file (tetrahedralized to about `N` tets, default 6000) or a TetGen mesh
//! given by its `.node` file (the `.ele` beside it). The model is scaled so that its largest
//! side is 2 m (the size of the paper's creature; printed as `scale`) and dropped with the
//! creature scene's material, gravity and speed, its lowest point 0.5 m above the ground.
//! Headless, it prints the volume error after every simulated second, then
//! `peak_volume_error_pct: X` and `mean_step_ms: Y`. In a window (feature `examples`) it shows
//! the model's own surface (for TetGen input, the tet mesh's boundary) embedded in the tets;
//! `--screenshot PATH --frames N` saves a picture and exits.

#[cfg(feature = "examples")]
mod common;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use bevy::prelude::*;
use bevy_soft_body::core::{
    Resolution, TetMesh, TriangleSurface, VolumeMethod, parse_obj, parse_tetgen, tetrahedralize,
};
use bevy_soft_body::prelude::*;
use bevy_soft_body::scenes::PaperScene;
use clap::Parser;

/// Largest side of the dropped model, metres.
const SIZE: f32 = 2.0;
/// Height of the model's lowest point above the ground when dropped, metres.
const LIFT: f32 = 0.5;

/// The command line (see the module's doc).
#[derive(Parser)]
#[command(about = "Drops any OBJ or TetGen mesh as a soft body and reports its volume error")]
struct Args {
    /// `MESH.obj` (tetrahedralized first) or `MESH.node` (with its `.ele`)
    mesh: PathBuf,
    /// Tets for an OBJ mesh
    #[arg(long, default_value_t = 6000)]
    tets: u32,
    /// Simulated seconds, headless
    #[arg(long, default_value_t = 6.0, value_parser = seconds)]
    seconds: f32,
    /// No window: print the volume error every second
    #[arg(long)]
    headless: bool,
    /// Save a PNG of the window here after `--frames` frames, then exit
    #[arg(long)]
    screenshot: Option<PathBuf>,
    /// Frames before the screenshot
    #[arg(long, default_value_t = 300)]
    frames: u32,
    /// Start with the debug gizmos on
    #[arg(long)]
    gizmos: bool,
}

fn seconds(value: &str) -> Result<f32, String> {
    value
        .parse()
        .ok()
        .filter(|s: &f32| s.is_finite() && *s > 0.0 && *s <= 3600.0)
        .ok_or(format!("`{value}` is not a duration up to 3600"))
}

/// The tet mesh and the surface to show, read from `path`.
fn load(path: &Path, tets: u32) -> Result<(TetMesh, TriangleSurface), String> {
    let read = |p: &Path| std::fs::read(p).map_err(|e| format!("cannot read {}: {e}", p.display()));
    let text =
        |p: &Path| String::from_utf8(read(p)?).map_err(|_| format!("{} is not text", p.display()));
    match path.extension().and_then(|e| e.to_str()) {
        Some("node") => {
            let mesh = parse_tetgen(&text(path)?, &text(&path.with_extension("ele"))?)
                .map_err(|e| format!("{}: {e}", path.display()))?;
            let surface = mesh.boundary_surface();
            Ok((mesh, surface))
        }
        Some("obj") => {
            let surface =
                parse_obj(&read(path)?).map_err(|e| format!("{}: {e}", path.display()))?;
            let t = tetrahedralize(
                &surface.positions,
                &surface.indices,
                Resolution::TargetTets(tets),
            )
            .map_err(|e| format!("{}: {e}", path.display()))?;
            if !t.parts_without_tets.is_empty() {
                eprintln!(
                    "warning: parts {:?} are thinner than a cell and got no tets",
                    t.parts_without_tets
                );
            }
            Ok((t.mesh, surface))
        }
        _ => Err(format!(
            "{}: give an .obj or a TetGen .node file",
            path.display()
        )),
    }
}

/// Spawns the model (scaled to [`SIZE`], lowest point [`LIFT`] above the ground at the origin),
/// the ground and the gravity; returns the body and the scale.
fn spawn(commands: &mut Commands, mesh: Arc<TetMesh>) -> (Entity, f32) {
    let scene = PaperScene::Creature;
    commands.insert_resource(SoftBodyGravity(scene.gravity()));
    let (lo, hi) = mesh.bounds();
    let scale = SIZE / (hi - lo).max_element();
    let centre = (lo + hi) * 0.5 * scale;
    let place = Vec3::new(-centre.x, LIFT - lo.y * scale, -centre.z);
    let mut body = SoftBody::new(mesh, scene.material(VolumeMethod::PAPER_IMPULSES))
        .expect("the creature's material is valid");
    for v in body.state_mut().velocities_mut() {
        v.y = -scene.params().speed;
    }
    let entity = commands
        .spawn((
            body,
            Transform::from_translation(place).with_scale(Vec3::splat(scale)),
            Name::new("dropped model"),
        ))
        .id();
    commands.spawn((
        StaticCollider::ground(0.8),
        Transform::default(),
        Name::new("ground"),
    ));
    (entity, scale)
}

fn headless(mesh: TetMesh, seconds: f32) {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, SoftBodyPlugin::default()))
        .insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
            Duration::from_millis(10),
        ));
    let tets = mesh.tet_count();
    let (body, scale) = {
        let world = app.world_mut();
        let mut commands = world.commands();
        let spawned = spawn(&mut commands, Arc::new(mesh));
        world.flush();
        spawned
    };
    println!("tets: {tets}");
    println!("scale: {scale:.4}");
    // The first update only starts the clock; after it, every update is one 10 ms step.
    app.update();
    let steps = (seconds * 100.0).round() as u32;
    for step in 1..=steps {
        app.update();
        if step % 100 == 0 || step == steps {
            let stats = app
                .world()
                .get::<SoftBodyStats>(body)
                .expect("spawned above");
            println!(
                "second {:.2}: volume_error_pct {:+.4} (inverted tets {})",
                step as f32 / 100.0,
                stats.volume_error_pct,
                stats.inverted_tets
            );
        }
    }
    let stats = app
        .world()
        .get::<SoftBodyStats>(body)
        .expect("spawned above");
    println!("peak_volume_error_pct: {:.4}", stats.peak_volume_error_pct);
    println!("mean_step_ms: {:.3}", stats.mean_step_ms());
}

#[cfg(feature = "examples")]
fn windowed(mesh: TetMesh, surface: TriangleSurface, args: &Args) -> AppExit {
    use bevy_soft_body::surface_mesh;
    let mesh = Arc::new(mesh);
    let options = common::ExampleOptions {
        screenshot: args.screenshot.clone(),
        frames: args.frames,
        scene: None,
        gizmos: args.gizmos,
    };
    let mut app = common::example_app_with("bevy_soft_body: drop", None, options);
    app.add_systems(
        Startup,
        move |mut commands: Commands,
              mut meshes: ResMut<Assets<Mesh>>,
              mut materials: ResMut<Assets<StandardMaterial>>,
              mut camera: Query<(&mut common::OrbitCamera, &mut Transform)>| {
            let (body, _) = spawn(&mut commands, mesh.clone());
            commands.entity(body).insert((
                SoftBodySurface::new(body),
                Mesh3d(meshes.add(surface_mesh(&surface))),
                MeshMaterial3d(materials.add(StandardMaterial {
                    base_color: Color::srgb(0.85, 0.25, 0.35),
                    perceptual_roughness: 0.35,
                    reflectance: 0.4,
                    ..default()
                })),
                common::SceneMember,
            ));
            if let Ok((mut orbit, mut transform)) = camera.single_mut() {
                let half = Vec3::new(SIZE, 0.0, SIZE) * 0.5;
                common::frame_camera(&mut orbit, -half, half + Vec3::Y * (SIZE + LIFT));
                *transform = orbit.transform();
            }
        },
    );
    app.run()
}

fn main() -> AppExit {
    let args = Args::parse();
    let (mesh, surface) = match load(&args.mesh, args.tets) {
        Ok(loaded) => loaded,
        Err(e) => {
            eprintln!("{e}");
            return AppExit::from_code(1);
        }
    };
    if args.headless {
        headless(mesh, args.seconds);
        return AppExit::Success;
    }
    #[cfg(feature = "examples")]
    {
        windowed(mesh, surface, &args)
    }
    #[cfg(not(feature = "examples"))]
    {
        let _ = (surface, args.screenshot, args.frames, args.gizmos);
        eprintln!(
            "the window needs the `examples` feature (run with --all-features); \
             or pass --headless"
        );
        AppExit::from_code(2)
    }
}
