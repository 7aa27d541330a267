//! Runs the paper's five scenes with the baseline, the paper's method and XPBD (the peer most
//! games use; method `xpbd`, 10 substeps unless `--xpbd-substeps N`) through the plugin in a
//! headless app, and writes the paper's Figure 2 and the numbers behind it.
//!
//! ```text
//! cargo run --release --all-features --example paper_figures -- --out DIR [--scene NAME] [--without PARTS] [--tolerance X] [--ring-tet-tolerance X] [--xpbd-substeps N] [--xpbd-match] [--verbose]
//! ```
//! writes `DIR/summary.csv`, `DIR/<scene>.csv` (time series) and `DIR/volume_error.png`, and
//! prints the summary table. `--tolerance` and `--ring-tet-tolerance` set the paper's method's
//! `ImpulseSettings` of those names (relative errors, `0.003` for 0.3 %), to see what they trade.
//!
//! `--xpbd-match` also runs XPBD with 1, 2, 3, ... substeps (up to [`MATCH_MAX_SUBSTEPS`]) until
//! its peak volume error is at or under the paper's method's: the cheapest XPBD with the same
//! error (more substeps cost more). It writes `DIR/xpbd_match.csv` and prints one line per scene
//! comparing the two step times, the comparison the XPBD peer is there for. Those times come
//! from runs one after another; on a machine whose speed moves between minutes, time the
//! substeps it finds side by side with `bench --only NAME --xpbd-substeps N`.

mod figures;
mod measure_args;

use measure_args::{ToleranceArgs, substeps};

use clap::Parser;

use std::fmt::Write as _;
use std::path::PathBuf;

use bevy::prelude::Transform;
use bevy_soft_body::core::{VolumeMethod, XpbdSettings};
use bevy_soft_body::prelude::*;
use bevy_soft_body::scenes::{PaperScene, headless_scene_app};
use plotters::prelude::*;

struct Args {
    out: PathBuf,
    scenes: Vec<PaperScene>,
    verbose: bool,
    impulses: ImpulseSettings,
    xpbd_substeps: u32,
    xpbd_match: bool,
}

/// The most XPBD substeps `--xpbd-match` tries before it gives up on matching the paper's
/// method's error.
const MATCH_MAX_SUBSTEPS: u32 = 20;

/// Step times within this fraction of each other are called a tie by `--xpbd-match`: runs of
/// the same build differ by 10 % and more on a busy machine.
const MATCH_TIE: f64 = 0.05;

/// The command line (see the module's doc).
#[derive(Parser)]
#[command(about = "The paper's five scenes with every method: Figure 2 and the numbers")]
struct Cli {
    /// Folder for the figures and `summary.csv`
    #[arg(long)]
    out: PathBuf,
    /// Only these scenes (repeat for several; default: all five)
    #[arg(long = "scene", value_parser = scene)]
    scenes: Vec<PaperScene>,
    /// Print every method's volume error as it runs
    #[arg(long)]
    verbose: bool,
    #[command(flatten)]
    tolerances: ToleranceArgs,
    /// XPBD's substeps
    #[arg(long, default_value_t = 10, value_parser = substeps)]
    xpbd_substeps: u32,
    /// Also find, per scene, the fewest XPBD substeps at or under the paper's method's error
    #[arg(long)]
    xpbd_match: bool,
    /// Switch parts of the paper's method off, to see what each one does
    #[arg(long, value_delimiter = ',', value_parser = ["one-ring", "per-tet", "clamp"])]
    without: Vec<String>,
}

fn scene(name: &str) -> Result<PaperScene, String> {
    PaperScene::from_name(name).ok_or_else(|| {
        let names: Vec<_> = PaperScene::ALL.iter().map(|s| s.name()).collect();
        format!("unknown scene `{name}`; scenes: {}", names.join(", "))
    })
}

impl From<Cli> for Args {
    fn from(cli: Cli) -> Args {
        let mut impulses = cli.tolerances.settings();
        for part in &cli.without {
            match part.as_str() {
                "one-ring" => impulses.one_ring = false,
                "per-tet" => impulses.per_tet = false,
                _ => impulses.neighbour_clamp = false,
            }
        }
        Args {
            out: cli.out,
            scenes: if cli.scenes.is_empty() {
                PaperScene::ALL.to_vec()
            } else {
                cli.scenes
            },
            verbose: cli.verbose,
            impulses,
            xpbd_substeps: cli.xpbd_substeps,
            xpbd_match: cli.xpbd_match,
        }
    }
}

/// One run's time series and summary.
struct Run {
    method: &'static str,
    tets: usize,
    steps: u64,
    times: Vec<f64>,
    error: Vec<f64>,
    mean_abs: Vec<f64>,
    inverted: Vec<usize>,
    peak: f64,
    max_inverted: usize,
    mean_step_ms: f64,
}

fn run(scene: PaperScene, method: VolumeMethod, verbose: bool) -> Run {
    let (mut app, body) = headless_scene_app(scene, method);
    let steps = (scene.duration_secs() / 0.01).round() as u64;
    let tets = app
        .world()
        .get::<SoftBody>(body)
        .unwrap()
        .state()
        .mesh()
        .tet_count();
    let mut r = Run {
        method: method.name(),
        tets,
        steps,
        times: Vec::new(),
        error: Vec::new(),
        mean_abs: Vec::new(),
        inverted: Vec::new(),
        peak: 0.0,
        max_inverted: 0,
        mean_step_ms: 0.0,
    };
    for step in 1..=steps {
        app.update();
        let stats = app.world().get::<SoftBodyStats>(body).unwrap();
        r.times.push(step as f64 * 0.01);
        r.error.push(stats.volume_error_pct);
        r.mean_abs.push(stats.mean_abs_tet_error_pct);
        r.inverted.push(stats.inverted_tets);
        if verbose
            && step
                % std::env::var("EVERY")
                    .ok()
                    .and_then(|v| v.parse().ok())
                    .unwrap_or(50)
                == 0
        {
            let world = app.world_mut();
            let centre = world.get::<Transform>(body).unwrap().translation;
            let mut spheres = world.query::<(&RigidSphere, &Transform)>();
            let sphere_y: Vec<String> = spheres
                .iter(world)
                .map(|(_, t)| format!("{:.3}", t.translation.y))
                .collect();
            let stats = world.get::<SoftBodyStats>(body).unwrap();
            eprintln!(
                "{:>10} {:>8} t={:5.2} err={:+7.3}% meanabs={:6.2}% inv={:4} com_y={:.3} spheres_y={:?} step={:.2}ms {:?}",
                scene.name(),
                method.name(),
                step as f64 * 0.01,
                stats.volume_error_pct,
                stats.mean_abs_tet_error_pct,
                stats.inverted_tets,
                centre.y,
                sphere_y,
                stats.step_ms,
                stats.counters
            );
        }
    }
    let stats = app.world().get::<SoftBodyStats>(body).unwrap();
    r.peak = stats.peak_volume_error_pct;
    r.max_inverted = stats.max_inverted_tets;
    r.mean_step_ms = stats.mean_step_ms();
    r
}

fn main() {
    let args = Args::from(Cli::parse());
    if let Err(e) = std::fs::create_dir_all(&args.out) {
        eprintln!("cannot create {}: {e}", args.out.display());
        std::process::exit(1);
    }
    let methods = [
        VolumeMethod::PAPER_BASELINE,
        VolumeMethod::Impulses(args.impulses),
        VolumeMethod::Xpbd(XpbdSettings {
            substeps: args.xpbd_substeps,
            clusters: 0,
        }),
    ];
    let mut summary = String::from(
        "scene,method,tets,steps,peak_volume_error_pct,final_volume_error_pct,mean_abs_tet_error_pct,max_inverted_tets,mean_step_ms\n",
    );
    let mut all: Vec<(PaperScene, Vec<Run>)> = Vec::new();
    for &scene in &args.scenes {
        let runs: Vec<Run> = methods
            .iter()
            .map(|&m| run(scene, m, args.verbose))
            .collect();
        let mut series = String::from("time_s");
        for r in &runs {
            write!(
                series,
                ",{m}_volume_error_pct,{m}_mean_abs_tet_error_pct,{m}_inverted_tets",
                m = r.method
            )
            .unwrap();
        }
        series.push('\n');
        for k in 0..runs[0].times.len() {
            write!(series, "{:.2}", runs[0].times[k]).unwrap();
            for r in &runs {
                write!(
                    series,
                    ",{:.5},{:.5},{}",
                    r.error[k], r.mean_abs[k], r.inverted[k]
                )
                .unwrap();
            }
            series.push('\n');
        }
        let path = args.out.join(format!("{}.csv", scene.name()));
        std::fs::write(&path, series)
            .unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
        for r in &runs {
            writeln!(
                summary,
                "{},{},{},{},{:.4},{:.4},{:.4},{},{:.3}",
                scene.name(),
                r.method,
                r.tets,
                r.steps,
                r.peak,
                r.error.last().copied().unwrap_or(0.0),
                r.mean_abs.last().copied().unwrap_or(0.0),
                r.max_inverted,
                r.mean_step_ms
            )
            .unwrap();
        }
        all.push((scene, runs));
    }
    std::fs::write(args.out.join("summary.csv"), &summary).expect("cannot write summary.csv");
    print!("{}", table(&summary));
    if args.xpbd_match {
        let mut matches = String::from(
            "scene,paper_peak_pct,paper_step_ms,xpbd_substeps,xpbd_peak_pct,xpbd_step_ms,paper_over_xpbd,verdict\n",
        );
        for (scene, runs) in &all {
            let paper_name = VolumeMethod::Impulses(args.impulses).name();
            let paper = runs.iter().find(|r| r.method == paper_name).unwrap();
            writeln!(matches, "{}", xpbd_match(*scene, paper, args.verbose)).unwrap();
        }
        std::fs::write(args.out.join("xpbd_match.csv"), &matches)
            .expect("cannot write xpbd_match.csv");
        println!();
        print!("{}", table(&matches));
    }
    if let Err(e) = plot(&args.out.join("volume_error.png"), &all) {
        eprintln!("cannot draw volume_error.png: {e}");
        std::process::exit(1);
    }
}

/// The cheapest XPBD run of `scene` whose peak volume error is at or under `paper`'s, as a row
/// of `xpbd_match.csv`.
fn xpbd_match(scene: PaperScene, paper: &Run, verbose: bool) -> String {
    if !paper.peak.is_finite() {
        return format!(
            "{},{},{:.3},,,,,no match (the paper's method's error is not finite)",
            scene.name(),
            paper.peak,
            paper.mean_step_ms
        );
    }
    for substeps in 1..=MATCH_MAX_SUBSTEPS {
        let xpbd = run(
            scene,
            VolumeMethod::Xpbd(XpbdSettings {
                substeps,
                clusters: 0,
            }),
            verbose,
        );
        if xpbd.peak <= paper.peak {
            let ratio = paper.mean_step_ms / xpbd.mean_step_ms;
            let verdict = if ratio < 1.0 - MATCH_TIE {
                "paper faster"
            } else if ratio > 1.0 + MATCH_TIE {
                "xpbd faster"
            } else {
                "tie"
            };
            return format!(
                "{},{:.4},{:.3},{substeps},{:.4},{:.3},{ratio:.2},{verdict}",
                scene.name(),
                paper.peak,
                paper.mean_step_ms,
                xpbd.peak,
                xpbd.mean_step_ms
            );
        }
    }
    format!(
        "{},{:.4},{:.3},>{MATCH_MAX_SUBSTEPS},,,,paper faster (no xpbd run matched its error)",
        scene.name(),
        paper.peak,
        paper.mean_step_ms
    )
}

/// The summary CSV as an aligned table.
fn table(csv: &str) -> String {
    let rows: Vec<Vec<&str>> = csv.lines().map(|l| l.split(',').collect()).collect();
    let widths: Vec<usize> = (0..rows[0].len())
        .map(|c| rows.iter().map(|r| r[c].len()).max().unwrap_or(0))
        .collect();
    let mut out = String::new();
    for r in &rows {
        let cells: Vec<String> = r
            .iter()
            .zip(&widths)
            .map(|(c, w)| format!("{c:>w$}"))
            .collect();
        out.push_str(&cells.join("  "));
        out.push('\n');
    }
    out
}

/// The paper's Figure 2: volume error in % over time, both methods, one panel per scene.
fn plot(
    path: &std::path::Path,
    all: &[(PaperScene, Vec<Run>)],
) -> Result<(), Box<dyn std::error::Error>> {
    figures::register_font()?;
    let root = BitMapBackend::new(path, (1400, 300 * all.len().max(1) as u32)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((all.len().max(1), 1));
    for ((scene, runs), panel) in all.iter().zip(panels) {
        let t_max = runs[0].times.last().copied().unwrap_or(1.0);
        let lo = runs
            .iter()
            .flat_map(|r| r.error.iter().copied())
            .fold(-1.0f64, f64::min);
        let hi = runs
            .iter()
            .flat_map(|r| r.error.iter().copied())
            .fold(1.0f64, f64::max);
        let mut points: Vec<_> = runs
            .iter()
            .map(|r| r.times.iter().copied().zip(r.error.iter().copied()))
            .collect();
        let curves = runs
            .iter()
            .zip(points.iter_mut())
            .map(|(r, points)| figures::Curve {
                label: format!("{} (peak {:.2} %)", r.method, r.peak),
                points,
            })
            .collect();
        figures::volume_panel(
            &panel,
            &format!("{} (k_D = {})", scene.name(), scene.distance_stiffness()),
            t_max,
            (lo, hi),
            curves,
        )?;
    }
    root.present()?;
    Ok(())
}
