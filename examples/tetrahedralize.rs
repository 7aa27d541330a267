//! Tetrahedralizes a triangle mesh (OBJ) and writes it as TetGen files:
//!
//! cargo run --release --all-features --example tetrahedralize -- IN.obj [--tets N | --cell SIZE] --out OUT
//!
//! writes `OUT.node` and `OUT.ele` and prints one `key: value` a line: `tets`, `vertices`,
//! `tet_volume`, `surface_volume`, `volume_ratio`, `min_dihedral_deg`, `seconds` (reading
//! excluded), then what the cleaning did and how many pieces came out.

use std::path::PathBuf;
use std::time::Instant;

use bevy_soft_body::core::{Resolution, parse_obj, tetrahedralize, write_tetgen};
use clap::Parser;

/// The command line (see the module's doc).
#[derive(Parser)]
#[command(about = "Tetrahedralizes a triangle mesh (OBJ) and writes it as TetGen files")]
struct Cli {
    /// The OBJ file
    input: PathBuf,
    /// About this many tets (default: 6000)
    #[arg(long, conflicts_with = "cell")]
    tets: Option<u32>,
    /// Cells of this size, in the mesh's units
    #[arg(long)]
    cell: Option<f32>,
    /// Writes `OUT.node` and `OUT.ele`
    #[arg(long)]
    out: PathBuf,
}

impl Cli {
    fn resolution(&self) -> Resolution {
        match (self.tets, self.cell) {
            (Some(n), _) => Resolution::TargetTets(n),
            (None, Some(size)) => Resolution::CellSize(size),
            (None, None) => Resolution::default(),
        }
    }
}

fn main() {
    let args = Cli::parse();
    let fail = |message: String| -> ! {
        eprintln!("{message}");
        std::process::exit(1);
    };
    let bytes = std::fs::read(&args.input)
        .unwrap_or_else(|e| fail(format!("cannot read {}: {e}", args.input.display())));
    let surface =
        parse_obj(&bytes).unwrap_or_else(|e| fail(format!("{}: {e}", args.input.display())));
    let start = Instant::now();
    let result = tetrahedralize(&surface.positions, &surface.indices, args.resolution())
        .unwrap_or_else(|e| fail(format!("{}: {e}", args.input.display())));
    let seconds = start.elapsed().as_secs_f64();
    let (node, ele) = write_tetgen(&result.mesh);
    for (ext, text) in [("node", node), ("ele", ele)] {
        let path = args.out.with_extension(ext);
        std::fs::write(&path, text)
            .unwrap_or_else(|e| fail(format!("cannot write {}: {e}", path.display())));
    }
    let mesh = &result.mesh;
    let tet_volume = mesh.total_rest_volume();
    println!("tets: {}", mesh.tet_count());
    println!("vertices: {}", mesh.vertex_count());
    println!("tet_volume: {tet_volume:.6}");
    println!("surface_volume: {:.6}", result.surface_volume);
    println!("volume_ratio: {:.4}", tet_volume / result.surface_volume);
    println!("min_dihedral_deg: {:.1}", mesh.min_dihedral_deg());
    println!("seconds: {seconds:.3}");
    println!("input_triangles: {}", surface.triangle_count());
    println!("cell_size: {:.5}", result.cell_size);
    println!("flipped_triangles: {}", result.flipped_triangles);
    println!("duplicate_triangles: {}", result.duplicate_triangles);
    println!("degenerate_triangles: {}", result.degenerate_triangles);
    println!("input_parts: {}", result.input_parts);
    println!("components: {}", result.components);
    if !result.parts_without_tets.is_empty() {
        println!(
            "parts_without_tets: {:?} (thinner than a cell: try more tets)",
            result.parts_without_tets
        );
    }
}
