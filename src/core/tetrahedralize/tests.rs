use super::*;
use crate::core::surface_mesh::{TriangleSurface, subdivided_box, torus, uv_sphere};

fn run(s: &TriangleSurface) -> Tetrahedralization {
    tetrahedralize(&s.positions, &s.indices, Resolution::default()).unwrap()
}

/// Checks every property a tetrahedralization of a solid input must have, and that its
/// volume is within 3 % of `expected`.
fn check(t: &Tetrahedralization, expected: f64, components: usize) {
    let ratio = t.mesh.total_rest_volume() / expected;
    assert!((ratio - 1.0).abs() < 0.03, "volume ratio {ratio}");
    assert_eq!(t.components, components);
    assert!(t.parts_without_tets.is_empty());
    assert!(t.mesh.rest_volumes().iter().all(|&v| v > 0.0));
    let quality = t.mesh.min_dihedral_deg();
    assert!(quality >= FIT_MIN_DIHEDRAL_DEG - 1e-3, "{quality}");
    let tets = t.mesh.tet_count() as f64;
    assert!((tets / 6000.0 - 1.0).abs() < 0.15, "{tets} tets");
}

fn merged(parts: &[TriangleSurface]) -> TriangleSurface {
    let mut out = TriangleSurface::default();
    for p in parts {
        out.append(p);
    }
    out
}

#[test]
fn sphere() {
    let s = uv_sphere(Vec3::new(3.0, 1.0, -2.0), 0.8, 64, 32);
    let t = run(&s);
    check(&t, s.enclosed_volume(), 1);
    assert_eq!(t.flipped_triangles, 0);
    assert!((t.surface_volume / s.enclosed_volume() - 1.0).abs() < 1e-6);
}

#[test]
fn torus_keeps_its_hole() {
    let s = torus(Vec3::ZERO, 1.0, 0.35, 64, 32);
    let t = run(&s);
    check(&t, s.enclosed_volume(), 1);
    // No tet covers the axis through the hole.
    for tet in t.mesh.tets() {
        let c = tet
            .iter()
            .map(|&i| t.mesh.positions()[i as usize])
            .sum::<Vec3>()
            / 4.0;
        assert!(Vec3::new(c.x, 0.0, c.z).length() > 0.5, "tet at {c}");
    }
}

#[test]
fn flipped_and_duplicated_faces_change_nothing() {
    let s = uv_sphere(Vec3::ZERO, 1.0, 48, 24);
    let clean = run(&s);
    let mut messy = s.clone();
    for (i, tri) in messy.indices.chunks_exact_mut(3).enumerate() {
        if i % 3 == 0 {
            tri.swap(1, 2);
        }
    }
    // Repeat some triangles, some of them turned around.
    let extra: Vec<u32> = s.indices[..300].to_vec();
    messy
        .indices
        .extend(extra.chunks_exact(3).flat_map(|t| [t[0], t[2], t[1]]));
    let t = run(&messy);
    assert_eq!(t.duplicate_triangles, 100);
    assert_eq!(t.flipped_triangles, s.triangle_count().div_ceil(3));
    assert_eq!(t.mesh.tets(), clean.mesh.tets());
    // Inside out as a whole: turned back.
    let mut inside_out = s.clone();
    for tri in inside_out.indices.chunks_exact_mut(3) {
        tri.swap(1, 2);
    }
    let t = run(&inside_out);
    assert_eq!(t.flipped_triangles, s.triangle_count());
    assert_eq!(t.mesh.tets(), clean.mesh.tets());
}

#[test]
fn a_box_with_a_hole_punched_in_it() {
    let s = subdivided_box(Vec3::ZERO, Vec3::new(2.0, 1.0, 1.5), 0.1);
    let mut holed = s.clone();
    holed.indices = s
        .indices
        .chunks_exact(3)
        .filter(|t| {
            let c = t.iter().map(|&i| s.positions[i as usize]).sum::<Vec3>() / 3.0;
            // A 0.6 x 0.4 opening in the top.
            !(c.y > 0.99 && (c.x - 1.0).abs() < 0.3 && (c.z - 0.75).abs() < 0.2)
        })
        .flatten()
        .copied()
        .collect();
    assert!(holed.indices.len() < s.indices.len());
    let t = run(&holed);
    check(&t, 2.0 * 1.0 * 1.5, 1);
}

#[test]
fn two_overlapping_boxes_become_their_union() {
    let a = subdivided_box(Vec3::ZERO, Vec3::new(2.0, 1.0, 1.0), 0.25);
    let b = subdivided_box(Vec3::new(1.1, 0.55, 0.1), Vec3::new(2.6, 1.55, 0.9), 0.25);
    let t = run(&merged(&[a, b]));
    assert_eq!(t.input_parts, 2);
    let union = 2.0 + 1.5 * 1.0 * 0.8 - 0.9 * 0.45 * 0.8;
    check(&t, union, 1);
}

#[test]
fn disconnected_parts_stay_apart_and_a_part_too_thin_is_reported() {
    let a = uv_sphere(Vec3::ZERO, 1.0, 32, 16);
    let b = uv_sphere(Vec3::new(4.0, 0.0, 0.0), 1.0, 32, 16);
    let t = run(&merged(&[a.clone(), b.clone()]));
    assert_eq!(t.input_parts, 2);
    check(&t, 2.0 * a.enclosed_volume(), 2);
    // A tiny third sphere, far smaller than a cell.
    let c = uv_sphere(Vec3::new(0.0, 4.0, 0.0), 0.01, 8, 4);
    let t = run(&merged(&[a, b, c]));
    assert_eq!(t.input_parts, 3);
    assert_eq!(t.parts_without_tets, vec![2]);
}

#[test]
fn boxes_meeting_at_a_non_manifold_edge() {
    // Two cubes sharing one edge (welded): four triangles meet on it, so orientation cannot
    // be carried across it; each cube is oriented on its own.
    let a = subdivided_box(Vec3::ZERO, Vec3::ONE, 0.25);
    // b meets a only along the edge x = 1, y = 1 (z from 0 to 1).
    let b = subdivided_box(Vec3::new(1.0, 1.0, 0.0), Vec3::new(2.0, 2.0, 1.0), 0.25);
    let mut inside_out = b.clone();
    for t in inside_out.indices.chunks_exact_mut(3) {
        t.swap(1, 2);
    }
    let t = run(&merged(&[a, inside_out]));
    assert_eq!(t.input_parts, 1, "welded along the shared edge");
    // b's triangles were turned back outwards.
    assert_eq!(t.flipped_triangles, b.triangle_count());
    let ratio = t.mesh.total_rest_volume() / 2.0;
    assert!((ratio - 1.0).abs() < 0.03, "volume ratio {ratio}");
    assert!(t.mesh.rest_volumes().iter().all(|&v| v > 0.0));
    assert!(t.mesh.min_dihedral_deg() >= FIT_MIN_DIHEDRAL_DEG - 1e-3);
}

#[test]
fn cell_size_resolution() {
    let s = uv_sphere(Vec3::ZERO, 1.0, 48, 24);
    let t = tetrahedralize(&s.positions, &s.indices, Resolution::CellSize(0.2)).unwrap();
    assert_eq!(t.cell_size, 0.2);
    let cells = t.mesh.tet_count() / 5;
    let expected = s.enclosed_volume() / 0.008;
    assert!((cells as f64 / expected - 1.0).abs() < 0.1);
}

#[test]
fn bad_input_gives_errors() {
    use TetrahedralizeError as E;
    let s = uv_sphere(Vec3::ZERO, 1.0, 16, 8);
    let r = Resolution::default();
    assert_eq!(
        tetrahedralize(&s.positions, &[], r).unwrap_err(),
        E::NoTriangles
    );
    assert_eq!(tetrahedralize(&[], &[], r).unwrap_err(), E::NoTriangles);
    assert_eq!(
        tetrahedralize(&s.positions, &s.indices[..4], r).unwrap_err(),
        E::PartialTriangle(4)
    );
    assert!(matches!(
        tetrahedralize(&s.positions, &[0, 1, 9999], r),
        Err(E::IndexOutOfRange {
            triangle: 0,
            vertex: 9999,
            ..
        })
    ));
    let mut nan = s.positions.clone();
    nan[3].y = f32::NAN;
    assert!(matches!(
        tetrahedralize(&nan, &s.indices, r),
        Err(E::NonFiniteVertex { vertex: 3, .. })
    ));
    let line = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0];
    assert_eq!(
        tetrahedralize(&line, &[0, 1, 2], r).unwrap_err(),
        E::Degenerate
    );
    for bad in [
        Resolution::TargetTets(0),
        Resolution::TargetTets(u32::MAX),
        Resolution::CellSize(0.0),
        Resolution::CellSize(-1.0),
        Resolution::CellSize(f32::NAN),
        Resolution::CellSize(f32::INFINITY),
    ] {
        assert!(matches!(
            tetrahedralize(&s.positions, &s.indices, bad),
            Err(E::BadResolution(_))
        ));
    }
    for cell in [1e-5, 0.0128] {
        assert!(matches!(
            tetrahedralize(&s.positions, &s.indices, Resolution::CellSize(cell)),
            Err(E::TooManyTets { .. })
        ));
    }
    // A surface enclosing nothing gives no estimate; its box is too big to query.
    let quad = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.0, 1.0), Vec3::Z];
    assert!(matches!(
        tetrahedralize(&quad, &[0, 1, 2, 0, 2, 3], Resolution::CellSize(1e-5)),
        Err(E::Grid(GridError::TooManyCells { .. }))
    ));
    // A single flat square encloses nothing.
    let quad = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.0, 1.0), Vec3::Z];
    assert!(matches!(
        tetrahedralize(&quad, &[0, 1, 2, 0, 2, 3], r),
        Err(E::NothingInside { .. })
    ));
    // Every error says what is wrong in words.
    let e = tetrahedralize(&s.positions, &[0, 1, 9999], r).unwrap_err();
    assert!(e.to_string().contains("vertex 9999"));
}
