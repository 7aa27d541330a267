//! Writes the triangle meshes the tetrahedralizer is tested on as OBJ files, for the
//! `tetrahedralize` and `drop` examples:
//!
//! cargo run --release --all-features --example shapes -- --out DIR
//!
//! `sphere.obj`, `torus.obj`, `holed_box.obj` (a box with an opening in its top),
//! `overlapping_boxes.obj` (two boxes through each other), `flipped_sphere.obj` (every third
//! triangle turned around, some repeated) and `sphere_100k.obj` (100 000 triangles, to time).

use std::path::PathBuf;

use clap::Parser;

use bevy_soft_body::core::{TriangleSurface, subdivided_box, torus, uv_sphere, write_obj};
use glam::Vec3;

/// The command line.
#[derive(Parser)]
#[command(about = "Writes the tetrahedralizer's test shapes as OBJ files")]
struct Cli {
    /// Folder for the OBJ files
    #[arg(long)]
    out: PathBuf,
}

fn main() {
    let out = Cli::parse().out;
    if let Err(e) = std::fs::create_dir_all(&out) {
        eprintln!("cannot create {}: {e}", out.display());
        std::process::exit(1);
    }

    let sphere = uv_sphere(Vec3::ZERO, 0.5, 64, 32);
    let box_surface = subdivided_box(Vec3::ZERO, Vec3::new(1.0, 0.6, 0.8), 0.05);
    let mut holed = box_surface.clone();
    holed.indices = box_surface
        .indices
        .chunks_exact(3)
        .filter(|t| {
            let c = t
                .iter()
                .map(|&i| box_surface.positions[i as usize])
                .sum::<Vec3>()
                / 3.0;
            !(c.y > 0.59 && (c.x - 0.5).abs() < 0.2 && (c.z - 0.4).abs() < 0.15)
        })
        .flatten()
        .copied()
        .collect();
    let mut overlapping = subdivided_box(Vec3::ZERO, Vec3::new(1.0, 0.5, 0.5), 0.05);
    overlapping.append(&subdivided_box(
        Vec3::new(0.55, 0.27, 0.05),
        Vec3::new(1.3, 0.77, 0.45),
        0.05,
    ));
    let mut flipped = sphere.clone();
    for (i, t) in flipped.indices.chunks_exact_mut(3).enumerate() {
        if i % 3 == 0 {
            t.swap(1, 2);
        }
    }
    let repeated: Vec<u32> = sphere.indices[..600].to_vec();
    flipped.indices.extend(repeated);
    // 2 * 224 * 223 = 99 904 triangles.
    let big = uv_sphere(Vec3::ZERO, 0.5, 224, 224);

    let files: [(&str, &TriangleSurface); 6] = [
        ("sphere.obj", &sphere),
        ("torus.obj", &torus(Vec3::ZERO, 0.5, 0.18, 96, 48)),
        ("holed_box.obj", &holed),
        ("overlapping_boxes.obj", &overlapping),
        ("flipped_sphere.obj", &flipped),
        ("sphere_100k.obj", &big),
    ];
    for (name, surface) in files {
        let path = out.join(name);
        if let Err(e) = std::fs::write(&path, write_obj(surface)) {
            eprintln!("cannot write {}: {e}", path.display());
            std::process::exit(1);
        }
        println!(
            "{}: {} triangles, encloses {:.6} m^3",
            path.display(),
            surface.triangle_count(),
            surface.enclosed_volume()
        );
    }
}
