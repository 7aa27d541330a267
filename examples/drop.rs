//! Drops any mesh on the ground at game scale, as a game would: "try your mesh".
//!
//! cargo run --release --all-features --example drop -- MESH [--preset jelly] [--size 1]
//!     [--hz 60] [--method clusters|paper|xpbd] [--tets N] [--seconds S] [--headless]
//!
//! `MESH` is an OBJ file (tetrahedralized to about `N` tets, default 6000) or a TetGen mesh
//! given by its `.node` file (the `.ele` beside it). The model is scaled so that its largest
//! side is `--size` metres (default 1; printed as `scale`) and dropped at Earth gravity in a
//! preset material (`jelly`, `flesh`, `rubber`, `hard_rubber`) from rest, its lowest point
//! 0.5 m above the ground, stepped at `--hz` (30 to 240) with the presets' method, XPBD with its
//! cluster volume correction (`clusters`), the paper's impulses (`paper`) or XPBD alone (10
//! substeps). Headless, it prints the
//! volume error after every simulated second, then one line as `bench` prints its own:
//! `mesh=NAME preset=NAME method=NAME hz=N tets=N mean_step_ms=X max_step_ms=X
//! peak_volume_error_pct=X final_inverted_tets=N asleep_s=X` (`-`: not asleep at the end). In a
//! window (feature `examples`) it shows the model's own surface (for TetGen input, the tet mesh's
//! boundary) embedded in the tets; `--screenshot PATH --frames N` saves a
//! picture and exits.

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
use clap::Parser;

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
    /// The material: jelly, flesh, rubber or hard_rubber
    #[arg(long, default_value = "jelly", value_parser = ["jelly", "flesh", "rubber", "hard_rubber"])]
    preset: String,
    /// Largest side of the model, metres
    #[arg(long, default_value_t = 1.0, value_parser = size)]
    size: f32,
    /// Steps a second
    #[arg(long, default_value_t = 60.0, value_parser = rate)]
    hz: f32,
    /// How the volume is kept: clusters (the presets' own: XPBD and its cluster correction),
    /// paper (the impulses) or xpbd (10 substeps)
    #[arg(long, default_value = "clusters", value_parser = ["clusters", "paper", "xpbd"])]
    method: String,
    /// Simulated seconds, headless
    #[arg(long, default_value_t = 3.0, value_parser = seconds)]
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

/// `value` as a number in `range`, or what it should have been.
fn within(value: &str, range: std::ops::RangeInclusive<f32>, what: &str) -> Result<f32, String> {
    value
        .parse()
        .ok()
        .filter(|s: &f32| range.contains(s))
        .ok_or(format!("`{value}` is not {what}"))
}

fn size(value: &str) -> Result<f32, String> {
    within(value, 0.01..=100.0, "a size from 0.01 to 100 m")
}

fn rate(value: &str) -> Result<f32, String> {
    within(value, 30.0..=240.0, "a rate from 30 to 240 Hz")
}

fn seconds(value: &str) -> Result<f32, String> {
    within(value, 0.001..=3600.0, "a duration up to 3600 s")
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

/// The material the command line asks for.
fn material(args: &Args) -> SoftBodyMaterial {
    let preset = SoftBodyMaterial::PRESETS
        .iter()
        .find(|(name, _)| *name == args.preset)
        .map_or(SoftBodyMaterial::JELLY, |p| p.1);
    let method = match args.method.as_str() {
        "xpbd" => VolumeMethod::XPBD,
        "paper" => VolumeMethod::PAPER_IMPULSES,
        _ => VolumeMethod::XPBD_CLUSTERS,
    };
    preset.with_method(method)
}

/// Spawns the model (scaled to `size`, lowest point [`LIFT`] above the ground at the origin)
/// and the ground, at Earth gravity (the plugin's default); returns the body and the scale.
fn spawn(
    commands: &mut Commands,
    mesh: Arc<TetMesh>,
    material: SoftBodyMaterial,
    size: f32,
) -> (Entity, f32) {
    let (lo, hi) = mesh.bounds();
    let scale = size / (hi - lo).max_element();
    let centre = (lo + hi) * 0.5 * scale;
    let place = Vec3::new(-centre.x, LIFT - lo.y * scale, -centre.z);
    let body = SoftBody::new(mesh, material).expect("the presets are valid");
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

fn headless(mesh: TetMesh, args: &Args) {
    let hz = args.hz as f64;
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, SoftBodyPlugin::default()))
        .insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
            Duration::from_secs_f64(1.0 / hz),
        ))
        .insert_resource(Time::<Fixed>::from_hz(hz))
        .insert_resource(SoftBodyThreads { max_threads: 1 });
    let tets = mesh.tet_count();
    let (body, scale) = {
        let world = app.world_mut();
        let mut commands = world.commands();
        let spawned = spawn(&mut commands, Arc::new(mesh), material(args), args.size);
        world.flush();
        spawned
    };
    println!("tets: {tets}");
    println!("scale: {scale:.4}");
    // The first update only starts the clock; after it, every update is one step.
    app.update();
    let steps = (args.seconds as f64 * hz).round() as u32;
    let (mut max_step_ms, mut asleep_from) = (0.0f64, None);
    for step in 1..=steps {
        app.update();
        let stats = app
            .world()
            .get::<SoftBodyStats>(body)
            .expect("spawned above");
        max_step_ms = max_step_ms.max(stats.step_ms);
        let t = step as f64 / hz;
        asleep_from = stats.sleeping.then(|| asleep_from.unwrap_or(t));
        if step % hz.round() as u32 == 0 || step == steps {
            println!(
                "second {t:.2}: volume_error_pct {:+.4} (inverted tets {})",
                stats.volume_error_pct, stats.inverted_tets
            );
        }
    }
    let stats = app
        .world()
        .get::<SoftBodyStats>(body)
        .expect("spawned above");
    let name = args
        .mesh
        .file_stem()
        .map_or("mesh".into(), |s| s.to_string_lossy());
    println!(
        "mesh={name} preset={} method={} hz={} tets={tets} mean_step_ms={:.3} max_step_ms={max_step_ms:.3} \
         peak_volume_error_pct={:.4} final_inverted_tets={} asleep_s={}",
        args.preset,
        args.method,
        args.hz,
        stats.mean_step_ms(),
        stats.peak_volume_error_pct,
        stats.inverted_tets,
        asleep_from.map_or("-".to_string(), |t| format!("{t:.2}")),
    );
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
    let (material, size) = (material(args), args.size);
    let mut app = common::example_app_with("bevy_soft_body: drop", None, options);
    let hz = args.hz as f64;
    app.insert_resource(Time::<Fixed>::from_hz(hz));
    if args.screenshot.is_some() {
        // One step a frame.
        app.insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
            Duration::from_secs_f64(1.0 / hz),
        ));
    }
    app.add_systems(
        Startup,
        move |mut commands: Commands,
              mut meshes: ResMut<Assets<Mesh>>,
              mut materials: ResMut<Assets<StandardMaterial>>,
              mut camera: Query<(&mut common::OrbitCamera, &mut Transform)>| {
            let (body, _) = spawn(&mut commands, mesh.clone(), material, size);
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
                let half = Vec3::new(size, 0.0, size) * 0.5;
                common::frame_camera(&mut orbit, -half, half + Vec3::Y * (size + LIFT));
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
    if !mesh.defects().is_empty() {
        eprintln!("warning: {}: {}", args.mesh.display(), mesh.defects());
    }
    if args.headless {
        headless(mesh, &args);
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
