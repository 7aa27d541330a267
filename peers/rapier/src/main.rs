//! The game-scale scenes of bevy_soft_body in rapier3d 0.36's soft bodies, side by side.
//!
//! cargo run --release --all-features --example game_figures -- --export out/scenes
//! cargo run --release --manifest-path peers/rapier/Cargo.toml -- out/scenes [HZ,...] [MODELS] [SUBSTEPS,...] [POISSON]
//!
//! Reads `scenes.csv` and the TetGen meshes that `game_figures --export` wrote, builds each body
//! as a rapier soft body of the same tets and particle masses (a quarter of each tet's mass to
//! each corner), on a fixed ground with the same friction, with the same rigid sphere, at
//! g = 9.81, and steps it at each rate (default 60 Hz) with each cell model (`volume`,
//! `corotational`, `neohookean`; default all) in rapier's default settings (one thread), with
//! each count of substeps (`IntegrationParameters::num_solver_iterations`; default rapier's
//! own, 4): more substeps is how a rapier user buys accuracy, so a list finds what rapier needs
//! to reach a given volume error and what it then costs. Prints the columns of `game_figures`'
//! summary.csv (method `rapier-MODEL`, or `rapier-MODEL-N` for N substeps other than the
//! default) and writes them to `rapier.csv` beside the scenes. The elastic cells take the scene's
//! Young's modulus and Poisson's ratio `POISSON` (default 0.45; rapier clamps it to 0.499): a
//! rapier user who wants the volume kept raises it.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use rapier3d::prelude::*;

struct Scene {
    name: String,
    material: String,
    density: f32,
    youngs_modulus: f32,
    lift: f32,
    sphere: Option<(f32, f32, f32)>,
    duration_secs: f32,
}

/// The scenes of `scenes.csv` (its friction column is left to rapier's own defaults for the soft
/// body's particles; the ground's is 0.8 as in the main crate's scenes).
fn read_scenes(dir: &Path) -> Result<Vec<Scene>, String> {
    let path = dir.join("scenes.csv");
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut scenes = Vec::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let num = |i: usize| -> Result<f32, String> {
            f.get(i).and_then(|v| v.parse().ok()).ok_or(format!(
                "{}:{}: column {} is not a number",
                path.display(),
                n + 1,
                i + 1
            ))
        };
        let (radius, mass, gap) = (num(6)?, num(7)?, num(8)?);
        scenes.push(Scene {
            name: f[0].to_string(),
            material: f.get(1).unwrap_or(&"").to_string(),
            density: num(2)?,
            youngs_modulus: num(3)?,
            lift: num(5)?,
            sphere: (radius > 0.0).then_some((radius, mass, gap)),
            duration_secs: num(9)?,
        });
    }
    Ok(scenes)
}

/// A TetGen pair as bevy_soft_body writes it (1-based, no attributes).
fn read_tetgen(dir: &Path, name: &str) -> Result<(Vec<Vector>, Vec<[u32; 4]>), String> {
    let read = |ext: &str| {
        let path = dir.join("meshes").join(format!("{name}.{ext}"));
        std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))
    };
    let rows = |text: String| -> Vec<Vec<f64>> {
        text.lines()
            .filter(|l| !l.trim_start().starts_with('#') && !l.trim().is_empty())
            .skip(1)
            .map(|l| {
                l.split_whitespace()
                    .filter_map(|v| v.parse().ok())
                    .collect()
            })
            .collect()
    };
    let nodes: Vec<Vector> = rows(read("node")?)
        .iter()
        .map(|r| Vector::new(r[1] as f32, r[2] as f32, r[3] as f32))
        .collect();
    let tets: Vec<[u32; 4]> = rows(read("ele")?)
        .iter()
        .map(|r| [r[1], r[2], r[3], r[4]].map(|i| i as u32 - 1))
        .collect();
    Ok((nodes, tets))
}

fn signed_volume(p: [Vector; 4]) -> f32 {
    (p[0] - p[3]).dot((p[1] - p[3]).cross(p[2] - p[3])) / 6.0
}

#[derive(Default)]
struct Run {
    peak: f64,
    last: f64,
    lowest: f32,
    final_height: f32,
    inverted: usize,
    finite: bool,
    ms: f64,
}

fn run(
    scene: &Scene,
    dir: &Path,
    model: SoftBodyCellModel,
    hz: f32,
    substeps: usize,
    poisson: f32,
) -> Result<Run, String> {
    let (rest, tets) = read_tetgen(dir, &scene.name)?;
    let rest_volumes: Vec<f32> = tets
        .iter()
        .map(|t| signed_volume(t.map(|i| rest[i as usize])))
        .collect();
    let rest_total: f64 = rest_volumes.iter().map(|&v| v as f64).sum();
    let mut masses = vec![0.0f32; rest.len()];
    for (t, &v) in tets.iter().zip(&rest_volumes) {
        for &i in t {
            masses[i as usize] += 0.25 * scene.density * v;
        }
    }
    let rest_height = rest.iter().fold(0.0f32, |a, p| a.max(p.y));
    let positions: Vec<Vector> = rest
        .iter()
        .map(|p| *p + Vector::new(0.0, scene.lift, 0.0))
        .collect();

    let mut bodies = RigidBodySet::new();
    let mut colliders = ColliderSet::new();
    let mut soft_bodies = SoftBodySet::new();
    let ground = bodies.insert(RigidBodyBuilder::fixed().translation(Vector::new(0.0, -0.5, 0.0)));
    colliders.insert_with_parent(
        ColliderBuilder::cuboid(50.0, 0.5, 50.0).friction(0.8),
        ground,
        &mut bodies,
    );
    if let Some((radius, mass, gap)) = scene.sphere {
        let ball = bodies.insert(RigidBodyBuilder::dynamic().translation(Vector::new(
            0.0,
            scene.lift + rest_height + gap + radius,
            0.0,
        )));
        let density = mass / (4.0 / 3.0 * std::f32::consts::PI * radius.powi(3));
        colliders.insert_with_parent(
            ColliderBuilder::ball(radius).density(density).friction(0.5),
            ball,
            &mut bodies,
        );
    }
    let mut material = SoftBodyMaterial::default();
    if scene.youngs_modulus > 0.0 {
        material.young_modulus = scene.youngs_modulus;
        material.poisson_ratio = poisson;
    }
    let handle = soft_bodies.insert(
        SoftBodyBuilder::new(positions)
            .cells(tets.clone())
            .masses(masses)
            .cell_model(model)
            .material(material),
        &mut bodies,
        &mut colliders,
    );

    let parameters = IntegrationParameters {
        dt: 1.0 / hz,
        num_solver_iterations: substeps,
        ..Default::default()
    };
    let mut pipeline = PhysicsPipeline::new();
    let mut islands = IslandManager::new();
    let mut broad_phase = BroadPhaseBvh::new();
    let mut narrow_phase = NarrowPhase::new();
    let mut impulse_joints = ImpulseJointSet::new();
    let mut multibody_joints = MultibodyJointSet::new();
    let mut ccd = CCDSolver::new();
    let gravity = Vector::new(0.0, -9.81, 0.0);
    let steps = (scene.duration_secs * hz).round() as usize;
    let mut r = Run {
        lowest: f32::INFINITY,
        finite: true,
        ..Default::default()
    };
    let mut elapsed = 0.0f64;
    for _ in 0..steps {
        let start = Instant::now();
        pipeline.step(
            gravity,
            &parameters,
            &mut islands,
            &mut broad_phase,
            &mut narrow_phase,
            &mut bodies,
            &mut colliders,
            &mut impulse_joints,
            &mut multibody_joints,
            &mut soft_bodies,
            &mut ccd,
            &(),
            &(),
        );
        elapsed += start.elapsed().as_secs_f64();
        let body = &soft_bodies[handle];
        let x: Vec<Vector> = body.particle_positions().collect();
        let mut volume = 0.0f64;
        let mut inverted = 0;
        for t in &tets {
            let v = signed_volume(t.map(|i| x[i as usize]));
            volume += v as f64;
            inverted += (v < 0.0) as usize;
        }
        let error = 100.0 * (volume - rest_total) / rest_total;
        r.finite &= error.is_finite();
        r.peak = r.peak.max(error.abs());
        r.last = error;
        r.inverted = r.inverted.max(inverted);
        let (lo, hi) = x
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p.y), hi.max(p.y))
            });
        let height = (hi - lo) / rest_height;
        r.lowest = r.lowest.min(height);
        r.final_height = height;
    }
    r.ms = elapsed * 1e3 / steps.max(1) as f64;
    Ok(r)
}

fn main() -> Result<(), String> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(
        args.next()
            .ok_or("usage: rapier_peer DIR [HZ,...] [MODELS] [SUBSTEPS,...] [POISSON]")?,
    );
    let rates: Vec<f32> = match args.next() {
        Some(list) => list
            .split(',')
            .map(|v| v.parse().map_err(|_| format!("`{v}` is not a rate")))
            .collect::<Result<_, _>>()?,
        None => vec![60.0],
    };
    let all = "volume,corotational,neohookean".to_string();
    let models: Vec<(String, SoftBodyCellModel)> = args
        .next()
        .unwrap_or(all)
        .split(',')
        .map(|m| match m {
            "volume" => Ok((m.to_string(), SoftBodyCellModel::Volume)),
            "corotational" => Ok((m.to_string(), SoftBodyCellModel::Corotational)),
            "neohookean" => Ok((m.to_string(), SoftBodyCellModel::NeoHookean)),
            other => Err(format!("unknown cell model `{other}`")),
        })
        .collect::<Result<_, _>>()?;
    let default_substeps = IntegrationParameters::default().num_solver_iterations;
    let substeps: Vec<usize> = match args.next() {
        Some(list) => list
            .split(',')
            .map(|v| match v.parse() {
                Ok(n) if n > 0 => Ok(n),
                _ => Err(format!("`{v}` is not a count of substeps")),
            })
            .collect::<Result<_, _>>()?,
        None => vec![default_substeps],
    };
    let poisson: f32 = match args.next() {
        Some(v) => v
            .parse()
            .ok()
            .filter(|p| (0.0..0.5).contains(p))
            .ok_or(format!("`{v}` is not a Poisson's ratio in [0, 0.5)"))?,
        None => 0.45,
    };
    let header = "scene,method,hz,material,tets,peak_volume_error_pct,final_volume_error_pct,\
                  final_mean_tet_error_pct,lowest_height,final_height,max_inverted_tets,finite,\
                  runaways,mean_step_ms";
    println!("{header}");
    let mut rows = vec![header.to_string()];
    for scene in read_scenes(&dir)? {
        let tets = read_tetgen(&dir, &scene.name)?.1.len();
        for (label, model) in &models {
            for (&hz, &n) in rates
                .iter()
                .flat_map(|hz| substeps.iter().map(move |n| (hz, n)))
            {
                let r = run(&scene, &dir, *model, hz, n, poisson)?;
                let mut method = format!("rapier-{label}");
                if n != default_substeps {
                    method += &format!("-{n}");
                }
                if poisson != 0.45 && *model != SoftBodyCellModel::Volume {
                    method += &format!("-nu{poisson}");
                }
                let row = format!(
                    "{},{method},{hz},{},{tets},{:.4},{:.4},,{:.4},{:.4},{},{},,{:.4}",
                    scene.name,
                    scene.material,
                    r.peak,
                    r.last,
                    r.lowest,
                    r.final_height,
                    r.inverted,
                    r.finite,
                    r.ms
                );
                println!("{row}");
                rows.push(row);
            }
        }
    }
    let path = dir.join("rapier.csv");
    let mut file = std::fs::File::create(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    for row in rows {
        writeln!(file, "{row}").map_err(|e| format!("{}: {e}", path.display()))?;
    }
    Ok(())
}
