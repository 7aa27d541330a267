//! Runs the game-scale scenes (`bevy_soft_body::game_scenes`) with every method at 30, 60 and
//! 120 Hz, headless, and writes `summary.csv` (one row a run) into `--out`:
//!
//! cargo run --release --all-features --example game_figures -- --out out/game
//!
//! Columns: scene, method, hz, material, tets, peak and final volume error (percent), final
//! mean per-tet error, lowest and final height over rest height, most inverted tets, whether it
//! stayed finite, runaways caught, mean and slowest step ms (one thread, wall clock), inverted
//! tets at the end, when it landed and when it fell asleep for good (s, `-` for never).
//! `--bundled` runs the meshes other tools made (`GameScene::bundled`) instead. `volume_error.png`
//! beside it: each scene's volume error over time, every method, at the first rate.

use std::io::Write;
use std::path::PathBuf;

use bevy_soft_body::core::{VolumeMethod, XpbdSettings};
use bevy_soft_body::game_scenes::GameScene;
use clap::Parser;

mod figures;

#[derive(Parser)]
#[command(about = "Game-scale scenes for every method and step rate")]
struct Args {
    /// Folder for summary.csv.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Only the scenes whose name contains this.
    #[arg(long)]
    only: Option<String>,
    /// The meshes other tools made (`GameScene::bundled`: each in every preset) instead of
    /// the standard scenes.
    #[arg(long)]
    bundled: bool,
    /// Step rates, Hz.
    #[arg(long, value_delimiter = ',', default_values_t = [30.0, 60.0, 120.0])]
    hz: Vec<f32>,
    /// Methods: paper, baseline, xpbd, clusters (XPBD with its cluster volume correction).
    #[arg(long, value_delimiter = ',', default_values_t = ["paper".to_string(), "xpbd".to_string(), "baseline".to_string()])]
    methods: Vec<String>,
    /// XPBD's substeps.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..=1000))]
    xpbd_substeps: u32,
    /// Simulated seconds (default: each scene's own).
    #[arg(long)]
    seconds: Option<f32>,
    /// Also write each scene's tet mesh (TetGen `.node`/`.ele` under `DIR/meshes`) and
    /// `DIR/scenes.csv` (its material, placement and sphere), for the rapier peer
    /// (`peers/rapier`), and run no method.
    #[arg(long)]
    export: Option<PathBuf>,
    /// Also find, per scene at the first rate, the fewest XPBD substeps (of 1, 2, 3, 4, 6, 8,
    /// 12, 16, 24, 32, 48, 64) whose peak volume error is at or under the paper's method's with
    /// no runaway, and compare their step times (`xpbd_match.csv` in `--out`).
    #[arg(long)]
    xpbd_match: bool,
}

/// The XPBD substeps `--xpbd-match` tries, in order.
const MATCH_SUBSTEPS: [u32; 12] = [1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64];

/// `--xpbd-match` for one scene at `hz`: the paper's run, then XPBD with more and more
/// substeps until it is as accurate; one CSV row.
fn xpbd_match(scene: &GameScene, hz: f32) -> Result<String, String> {
    let paper = scene
        .run(VolumeMethod::PAPER_IMPULSES, hz)
        .map_err(|e| e.to_string())?;
    for substeps in MATCH_SUBSTEPS {
        let xpbd = scene
            .run(
                VolumeMethod::Xpbd(XpbdSettings {
                    substeps,
                    clusters: 0,
                }),
                hz,
            )
            .map_err(|e| e.to_string())?;
        if xpbd.runaways == 0 && xpbd.peak_volume_error_pct <= paper.peak_volume_error_pct {
            let ratio = paper.mean_step_ms / xpbd.mean_step_ms;
            // Runs one after another differ by more than 5 % here: closer is a tie.
            let verdict = if ratio < 0.95 {
                "paper faster"
            } else if ratio > 1.05 {
                "xpbd faster"
            } else {
                "tie"
            };
            return Ok(format!(
                "{},{hz},{:.4},{:.4},{substeps},{:.4},{:.4},{ratio:.3},{verdict}",
                scene.name,
                paper.peak_volume_error_pct,
                paper.mean_step_ms,
                xpbd.peak_volume_error_pct,
                xpbd.mean_step_ms
            ));
        }
    }
    Ok(format!(
        "{},{hz},{:.4},{:.4},,,,,xpbd never as accurate (64 substeps)",
        scene.name, paper.peak_volume_error_pct, paper.mean_step_ms
    ))
}

/// Writes the scenes' meshes and `scenes.csv` into `dir` (see `Args::export`).
fn export(dir: &std::path::Path, scenes: &[GameScene]) -> Result<(), String> {
    use bevy_soft_body::core::{Elasticity, write_tetgen};
    let meshes = dir.join("meshes");
    std::fs::create_dir_all(&meshes).map_err(|e| format!("{}: {e}", meshes.display()))?;
    let mut csv = String::from(
        "scene,material,density,youngs_modulus,friction,lift,sphere_radius,sphere_mass,sphere_gap,\
         duration_secs\n",
    );
    for scene in scenes {
        let mesh = scene.tet_mesh().map_err(|e| e.to_string())?;
        let (node, ele) = write_tetgen(&mesh);
        for (ext, text) in [("node", node), ("ele", ele)] {
            let path = meshes.join(format!("{}.{ext}", scene.name));
            std::fs::write(&path, text).map_err(|e| format!("{}: {e}", path.display()))?;
        }
        let youngs = match scene.material.elasticity {
            Elasticity::Elastic(e) => e.youngs_modulus,
            Elasticity::Springs { .. } => 0.0,
        };
        let (radius, mass, gap) = scene
            .sphere
            .map_or((0.0, 0.0, 0.0), |s| (s.radius, s.mass, s.gap));
        csv += &format!(
            "{},{},{},{},{},{},{},{},{},{}\n",
            scene.name,
            scene.material_name,
            scene.material.density,
            youngs,
            scene.material.friction,
            scene.lift,
            radius,
            mass,
            gap,
            scene.duration_secs
        );
    }
    let path = dir.join("scenes.csv");
    std::fs::write(&path, csv).map_err(|e| format!("{}: {e}", path.display()))?;
    println!("wrote {} scenes into {}", scenes.len(), dir.display());
    Ok(())
}

fn main() -> Result<(), String> {
    let args = Args::parse();
    let all = || {
        if args.bundled {
            GameScene::bundled()
        } else {
            GameScene::standard()
        }
    };
    if let Some(dir) = &args.export {
        let scenes: Vec<GameScene> = all()
            .into_iter()
            .filter(|s| {
                args.only
                    .as_ref()
                    .is_none_or(|o| s.name.contains(o.as_str()))
            })
            .collect();
        return export(dir, &scenes);
    }
    let mut rows = vec![
        "scene,method,hz,material,tets,peak_volume_error_pct,final_volume_error_pct,\
         final_mean_tet_error_pct,lowest_height,final_height,max_inverted_tets,finite,runaways,\
         mean_step_ms,max_step_ms,final_inverted_tets,landed_s,asleep_s,mean_substeps"
            .to_string(),
    ];
    println!("{}", rows[0]);
    // Per scene and method, at the first rate: the volume error over time, for the figure.
    let mut curves: Vec<Curve> = Vec::new();
    for mut scene in all() {
        if args
            .only
            .as_ref()
            .is_some_and(|o| !scene.name.contains(o.as_str()))
        {
            continue;
        }
        if let Some(s) = args.seconds {
            scene.duration_secs = s;
        }
        for name in &args.methods {
            let method = match name.as_str() {
                "paper" => VolumeMethod::PAPER_IMPULSES,
                "baseline" => VolumeMethod::PAPER_BASELINE,
                "xpbd" => VolumeMethod::Xpbd(XpbdSettings {
                    substeps: args.xpbd_substeps,
                    clusters: 0,
                }),
                "clusters" => VolumeMethod::Xpbd(XpbdSettings {
                    substeps: args.xpbd_substeps,
                    ..XpbdSettings::CLUSTERS
                }),
                other => return Err(format!("--methods: unknown method `{other}`")),
            };
            for &hz in &args.hz {
                let mut series = Vec::new();
                let r = scene
                    .run_recording(method, hz, |t, e| series.push((t, e)))
                    .map_err(|e| e.to_string())?;
                if hz == args.hz[0] {
                    curves.push((
                        scene.name.clone(),
                        name.clone(),
                        r.peak_volume_error_pct,
                        series,
                    ));
                }
                let time = |t: Option<f32>| t.map_or("-".to_string(), |t| format!("{t:.2}"));
                let row = format!(
                    "{},{},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{},{},{},{:.4},{:.4},{},{},{},{:.1}",
                    scene.name,
                    name,
                    hz,
                    scene.material_name,
                    r.tets,
                    r.peak_volume_error_pct,
                    r.final_volume_error_pct,
                    r.final_mean_tet_error_pct,
                    r.lowest_height,
                    r.final_height,
                    r.max_inverted_tets,
                    r.finite,
                    r.runaways,
                    r.mean_step_ms,
                    r.max_step_ms,
                    r.final_inverted_tets,
                    time(r.landed_at),
                    time(r.asleep_from),
                    r.mean_substeps
                );
                println!("{row}");
                rows.push(row);
            }
        }
    }
    let mut matches = vec![
        "scene,hz,paper_peak_pct,paper_ms,xpbd_substeps,xpbd_peak_pct,xpbd_ms,paper_over_xpbd,verdict"
            .to_string(),
    ];
    if args.xpbd_match {
        println!("{}", matches[0]);
        for scene in all() {
            if args
                .only
                .as_ref()
                .is_some_and(|o| !scene.name.contains(o.as_str()))
            {
                continue;
            }
            let row = xpbd_match(&scene, args.hz[0])?;
            println!("{row}");
            matches.push(row);
        }
    }
    if let Some(out) = args.out {
        if args.xpbd_match {
            let path = out.join("xpbd_match.csv");
            std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;
            std::fs::write(&path, matches.join("\n") + "\n")
                .map_err(|e| format!("{}: {e}", path.display()))?;
        }
        std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;
        let path = out.join("summary.csv");
        let mut file =
            std::fs::File::create(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        for row in &rows {
            writeln!(file, "{row}").map_err(|e| format!("{}: {e}", path.display()))?;
        }
        println!("wrote {}", path.display());
        let figure = out.join("volume_error.png");
        plot(&figure, &curves, args.hz[0]).map_err(|e| format!("{}: {e}", figure.display()))?;
        println!("wrote {}", figure.display());
    }
    Ok(())
}

/// A scene's name, a method's, its peak, and its volume error over time.
type Curve = (String, String, f64, Vec<(f32, f64)>);

/// The volume error in % over time, every method, one panel per scene (as `paper_figures`'
/// Figure 2), at `hz`.
fn plot(
    path: &std::path::Path,
    curves: &[Curve],
    hz: f32,
) -> Result<(), Box<dyn std::error::Error>> {
    use plotters::prelude::*;
    figures::register_font()?;
    let mut scenes: Vec<&str> = Vec::new();
    for (scene, ..) in curves {
        if !scenes.contains(&scene.as_str()) {
            scenes.push(scene);
        }
    }
    let root =
        BitMapBackend::new(path, (1400, 240 * scenes.len().max(1) as u32)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((scenes.len().max(1), 1));
    // Clipped to +-5 %: a method that runs away would hide the others.
    fn clipped(c: &Curve) -> impl Iterator<Item = (f64, f64)> + '_ {
        c.3.iter().map(|p| (p.0 as f64, p.1.clamp(-5.0, 5.0)))
    }
    for (scene, panel) in scenes.iter().zip(panels) {
        let mine: Vec<&Curve> = curves.iter().filter(|c| c.0 == *scene).collect();
        let t_max = mine
            .iter()
            .filter_map(|c| c.3.last().map(|p| p.0 as f64))
            .fold(1.0, f64::max);
        let values = || mine.iter().flat_map(|c| clipped(c).map(|p| p.1));
        let range = (
            values().fold(-1.0f64, f64::min),
            values().fold(1.0f64, f64::max),
        );
        let mut points: Vec<_> = mine.iter().map(|c| clipped(c)).collect();
        let panel_curves = mine
            .iter()
            .zip(points.iter_mut())
            .map(|(c, points)| figures::Curve {
                label: format!("{} (peak {:.2} %)", c.1, c.2),
                points,
            })
            .collect();
        figures::volume_panel(
            &panel,
            &format!("{scene} ({hz} Hz, g = 9.81)"),
            t_max,
            range,
            panel_curves,
        )?;
    }
    root.present()?;
    Ok(())
}
