//! Writes the creature's detailed surface, `assets/creature.obj`, which the creature scene
//! tetrahedralizes and draws:
//!
//! cargo run --release --all-features --example creature_asset -- [--out assets/creature.obj]
//!
//! The surface is the zero level set of `scenes::creature_sdf`, extracted by surface nets on a
//! grid of `SPACING`, coordinates rounded to 0.1 mm to keep the file small. The output is
//! committed; run this again after changing the creature's shape.

use std::path::PathBuf;

use clap::Parser;

use bevy_soft_body::core::{surface_nets, write_obj};
use bevy_soft_body::scenes::{creature_bounds, creature_sdf};
use glam::Vec3;

/// Sampling step of the surface, metres: about a third of the tet cells' size at 6500 tets.
const SPACING: f32 = 0.038;

/// The command line.
#[derive(Parser)]
#[command(about = "Writes the creature's detailed surface as OBJ")]
struct Cli {
    /// Where to write it
    #[arg(long, default_value = "assets/creature.obj")]
    out: PathBuf,
}

fn main() {
    let out = Cli::parse().out;
    let (lo, hi) = creature_bounds();
    let margin = Vec3::splat(2.0 * SPACING);
    let mut surface = surface_nets(creature_sdf, lo - margin, hi + margin, SPACING);
    for p in &mut surface.positions {
        *p = (*p * 1e4).round() / 1e4;
    }
    let text = format!(
        "# The creature of bevy_soft_body's creature scene: surface nets of scenes::creature_sdf\n\
         # every {SPACING} m, written by examples/creature_asset.rs.\n{}",
        write_obj(&surface)
    );
    if let Err(e) = std::fs::write(&out, text) {
        eprintln!("cannot write {}: {e}", out.display());
        std::process::exit(1);
    }
    println!(
        "{}: {} vertices, {} triangles, encloses {:.4} m^3",
        out.display(),
        surface.positions.len(),
        surface.triangle_count(),
        surface.enclosed_volume()
    );
}
