//! Runs the game-scale scenes (`bevy_soft_body::game_scenes`) with every method at 30, 60 and
//! 120 Hz, headless, and writes `summary.csv` (one row a run) into `--out`:
//!
//! cargo run --release --all-features --example game_figures -- --out out/game
//!
//! Columns: scene, method, hz, material, tets, peak and final volume error (percent), final
//! mean per-tet error, lowest and final height over rest height, most inverted tets, whether it
//! stayed finite, runaways caught, mean step ms (one thread, wall clock).

use std::io::Write;
use std::path::PathBuf;

use bevy_soft_body::core::{VolumeMethod, XpbdSettings};
use bevy_soft_body::game_scenes::GameScene;
use clap::Parser;

#[derive(Parser)]
#[command(about = "Game-scale scenes for every method and step rate")]
struct Args {
    /// Folder for summary.csv.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Only the scenes whose name contains this.
    #[arg(long)]
    only: Option<String>,
    /// Step rates, Hz.
    #[arg(long, value_delimiter = ',', default_values_t = [30.0, 60.0, 120.0])]
    hz: Vec<f32>,
    /// Methods: paper, baseline, xpbd.
    #[arg(long, value_delimiter = ',', default_values_t = ["paper".to_string(), "xpbd".to_string(), "baseline".to_string()])]
    methods: Vec<String>,
    /// XPBD's substeps.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..=1000))]
    xpbd_substeps: u32,
    /// Simulated seconds (default: each scene's own).
    #[arg(long)]
    seconds: Option<f32>,
}

fn main() -> Result<(), String> {
    let args = Args::parse();
    let mut rows = vec![
        "scene,method,hz,material,tets,peak_volume_error_pct,final_volume_error_pct,\
         final_mean_tet_error_pct,lowest_height,final_height,max_inverted_tets,finite,runaways,\
         mean_step_ms"
            .to_string(),
    ];
    println!("{}", rows[0]);
    for mut scene in GameScene::standard() {
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
                }),
                other => return Err(format!("--methods: unknown method `{other}`")),
            };
            for &hz in &args.hz {
                let r = scene.run(method, hz).map_err(|e| e.to_string())?;
                let row = format!(
                    "{},{},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{},{},{},{:.4}",
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
                    r.mean_step_ms
                );
                println!("{row}");
                rows.push(row);
            }
        }
    }
    if let Some(out) = args.out {
        std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;
        let path = out.join("summary.csv");
        let mut file =
            std::fs::File::create(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        for row in &rows {
            writeln!(file, "{row}").map_err(|e| format!("{}: {e}", path.display()))?;
        }
        println!("wrote {}", path.display());
    }
    Ok(())
}
