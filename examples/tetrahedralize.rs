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

struct Args {
    input: PathBuf,
    resolution: Resolution,
    out: PathBuf,
}

fn parse_args() -> Result<Args, String> {
    let mut args = std::env::args().skip(1);
    let (mut input, mut out, mut resolution) = (None, None, Resolution::default());
    while let Some(a) = args.next() {
        match a.as_str() {
            "--tets" => {
                let n = args.next().ok_or("--tets needs a number")?;
                resolution = Resolution::TargetTets(
                    n.parse()
                        .map_err(|_| format!("--tets: `{n}` is not a count"))?,
                );
            }
            "--cell" => {
                let c = args.next().ok_or("--cell needs a size")?;
                resolution = Resolution::CellSize(
                    c.parse()
                        .map_err(|_| format!("--cell: `{c}` is not a size"))?,
                );
            }
            "--out" => out = Some(PathBuf::from(args.next().ok_or("--out needs a path")?)),
            "-h" | "--help" => {
                return Err(
                    "usage: tetrahedralize IN.obj [--tets N | --cell SIZE] --out OUT".into(),
                );
            }
            other if other.starts_with("--") => {
                return Err(format!("unknown option `{other}` (try --help)"));
            }
            other => input = Some(PathBuf::from(other)),
        }
    }
    Ok(Args {
        input: input.ok_or("an input OBJ file is required (try --help)")?,
        resolution,
        out: out.ok_or("--out OUT is required")?,
    })
}

fn main() {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let fail = |message: String| -> ! {
        eprintln!("{message}");
        std::process::exit(1);
    };
    let bytes = std::fs::read(&args.input)
        .unwrap_or_else(|e| fail(format!("cannot read {}: {e}", args.input.display())));
    let surface =
        parse_obj(&bytes).unwrap_or_else(|e| fail(format!("{}: {e}", args.input.display())));
    let start = Instant::now();
    let result = tetrahedralize(&surface.positions, &surface.indices, args.resolution)
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
