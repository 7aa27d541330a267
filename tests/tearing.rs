//! Tearing (`TearSettings`): a jelly bar pulled from both ends past its limit splits into two
//! pieces, each keeping its volume, sharing no particle, with no surface triangle across the
//! cut (nor in a render surface bound to it, whose torn triangles are taken out and whose
//! opened faces are drawn); a body that may tear but is not stretched that far does not.

use std::sync::Arc;

use bevy_soft_body::core::{
    SoftBodyMaterial, SoftBodyState, SurfaceBinding, TearSettings, TetMesh, box_grid, cut_faces,
    pieces,
};
use glam::{UVec3, Vec3};

/// A 0.6 m jelly bar along x, 0.1 m thick.
fn bar() -> SoftBodyState {
    let mesh = box_grid(UVec3::new(12, 2, 2), Vec3::splat(0.05), Vec3::ZERO).unwrap();
    let mut body = SoftBodyState::new(Arc::new(mesh), SoftBodyMaterial::JELLY).unwrap();
    body.set_tearing(Some(TearSettings::default()));
    body
}

/// Steps `body` at 60 Hz without gravity for `steps` steps, the material within 0.12 m of
/// its end faces' middles grabbed (`pull_patch`, 400 N/m) and pulled apart along x at
/// `speed` m/s each for the first `pulled` steps. Returns the largest volume error of any
/// piece, in percent, over the steps after the first tear.
fn pull(body: &mut SoftBodyState, steps: usize, pulled: usize, speed: f32) -> f64 {
    let h = 1.0 / 60.0;
    let ends = [Vec3::new(0.0, 0.05, 0.05), Vec3::new(0.6, 0.05, 0.05)];
    let patches = ends.map(|p| body.forces().grab_patch(p, 0.12));
    let mut worst = 0.0f64;
    let mut torn = false;
    for step in 1..=steps {
        for (k, patch) in patches.iter().enumerate().filter(|_| step <= pulled) {
            let side = if k == 0 { -1.0 } else { 1.0 };
            let target = ends[k] + Vec3::X * (side * speed * h * step as f32);
            body.forces()
                .pull_patch(patch, target, [400.0, 40.0], f32::INFINITY, h);
        }
        body.step_free(h, Vec3::ZERO);
        torn |= !body.tears().is_empty();
        if torn {
            let (errors, _) = piece_volumes(body);
            worst = errors.iter().fold(worst, |w, e| w.max(e.abs()));
        }
    }
    worst
}

/// Per piece: its volume error in percent (signed volume of its tets against their rest
/// volumes), and the piece of each particle (`None` for one in no tet).
fn piece_volumes(body: &SoftBodyState) -> (Vec<f64>, Vec<Option<u32>>) {
    let mesh: &TetMesh = body.mesh();
    let labels = pieces(mesh);
    let count = labels.iter().max().map_or(0, |&m| m as usize + 1);
    let (mut volume, mut rest) = (vec![0.0f64; count], vec![0.0f64; count]);
    let mut owner: Vec<Option<u32>> = vec![None; mesh.vertex_count()];
    let signed = |x: [glam::DVec3; 4]| (x[1] - x[0]).dot((x[2] - x[0]).cross(x[3] - x[0])) / 6.0;
    for (tet, &piece) in mesh.tets().iter().zip(&labels) {
        let x = tet.map(|i| body.positions()[i as usize].as_dvec3());
        let x0 = tet.map(|i| mesh.positions()[i as usize].as_dvec3());
        volume[piece as usize] += signed(x);
        rest[piece as usize] += signed(x0);
        for &i in tet {
            let was = owner[i as usize].replace(piece);
            assert!(was.is_none_or(|w| w == piece), "particle {i} in two pieces");
        }
    }
    let errors = volume
        .iter()
        .zip(&rest)
        .map(|(v, r)| 100.0 * (v - r) / r)
        .collect();
    (errors, owner)
}

#[test]
fn a_bar_pulled_past_its_limit_tears_in_two_pieces_that_keep_their_volume() {
    let mut body = bar();
    let particles = body.positions().len();
    // 1 m/s each way for 1 s: the bar would be stretched to more than four times its length.
    let worst = pull(&mut body, 120, 60, 1.0);
    assert!(body.positions().len() > particles, "nothing tore");
    let (errors, owner) = piece_volumes(&body);
    assert_eq!(errors.len(), 2, "{} pieces", errors.len());
    // The two ends are in different pieces.
    let rest = body.mesh().positions();
    let end = |x: f32| {
        let i = (0..rest.len())
            .find(|&i| (rest[i].x - x).abs() < 1e-4)
            .unwrap();
        owner[i].unwrap()
    };
    assert_ne!(end(0.0), end(0.6), "the ends are still joined");
    // Each piece kept its volume from the tear on.
    assert!(worst < 1.0, "a piece's volume error reached {worst} %");
    // The surface: every boundary triangle within one piece.
    for t in body.boundary().triangles() {
        let p = t.map(|i| owner[i as usize].unwrap());
        assert!(
            p[0] == p[1] && p[1] == p[2],
            "triangle {t:?} spans pieces {p:?}"
        );
    }
    assert!(body.velocities().iter().all(|v| v.is_finite()));
}

#[test]
fn a_bar_stretched_within_its_limit_does_not_tear() {
    let mut body = bar();
    let particles = body.positions().len();
    // 0.1 m/s each way for 1 s: 0.2 m longer at most.
    pull(&mut body, 60, 60, 0.1);
    assert_eq!(body.positions().len(), particles);
    assert!(body.tears().is_empty());
    assert_eq!(pieces(body.mesh()).iter().max(), Some(&0));
}

#[test]
fn the_surface_bound_to_a_torn_bar_has_no_triangle_across_the_cut() {
    let mut body = bar();
    let bound = body.mesh().clone();
    // The bar's own boundary as a render surface, bound to its tets at rest.
    let surface = bound.boundary_surface();
    let mut binding = SurfaceBinding::new(&bound, &surface.positions).unwrap();
    pull(&mut body, 120, 60, 1.0);
    let now = body.mesh().clone();
    let labels = pieces(&now);
    assert_eq!(labels.iter().max(), Some(&1), "two pieces");
    let kept: Vec<[u32; 3]> = (surface.indices.chunks_exact(3))
        .map(|t| [t[0], t[1], t[2]])
        .filter(|&t| !binding.spans_cut(&bound, &now, &labels, t))
        .collect();
    let dropped = surface.indices.len() / 3 - kept.len();
    assert!(dropped > 0, "no triangle was across the cut");
    // The faces the tear opened, drawn on their tets.
    let opened = cut_faces(&bound, &now);
    assert!(!opened.is_empty());
    let first_new = binding.len() as u32;
    for &(tet, corners) in &opened {
        for k in corners {
            let mut weights = [0.0; 4];
            weights[k] = 1.0;
            binding.push(tet, weights);
        }
    }
    let mut points = vec![Vec3::ZERO; binding.len()];
    binding.deform(&now, body.positions(), &mut points);
    // Every drawn triangle lies within one piece and is no longer than the bar's cells allow.
    let tets = binding.tets();
    let drawn = kept
        .iter()
        .copied()
        .chain((0..opened.len() as u32).map(|f| [0, 1, 2].map(|j| first_new + 3 * f + j)));
    for t in drawn {
        let p = t.map(|i| labels[tets[i as usize] as usize]);
        assert!(
            p[0] == p[1] && p[1] == p[2],
            "triangle {t:?} in pieces {p:?}"
        );
        let [a, b, c] = t.map(|i| points[i as usize]);
        let longest = a.distance(b).max(b.distance(c)).max(c.distance(a));
        assert!(longest < 0.2, "triangle {t:?} stretched to {longest} m");
    }
}

#[test]
fn a_blade_through_a_block_that_may_tear_cuts_it_in_two() {
    use bevy_soft_body::core::ColliderInstance;
    // A flesh block 0.3 m across, and a blade 2 mm thin standing across its middle.
    let mesh = box_grid(UVec3::splat(6), Vec3::splat(0.05), Vec3::ZERO).unwrap();
    let mut block = SoftBodyState::new(Arc::new(mesh), SoftBodyMaterial::FLESH).unwrap();
    block.set_tearing(Some(TearSettings::default()));
    let blade = parry3d::shape::SharedShape::cuboid(0.001, 0.5, 0.5);
    let at = parry3d::math::Pose::from_parts(Vec3::new(0.151, 0.15, 0.15), glam::Quat::IDENTITY);
    let mut blade = ColliderInstance::new(blade, at, 0.0);
    // Not a cutter: it only pushes.
    block.step_with_contacts(
        1.0 / 60.0,
        Vec3::ZERO,
        &mut [],
        &[blade.clone()],
        &bevy_soft_body::core::Serial,
    );
    assert_eq!(pieces(block.mesh()).iter().max(), Some(&0));
    blade.cuts = true;
    block.step_with_contacts(
        1.0 / 60.0,
        Vec3::ZERO,
        &mut [],
        &[blade],
        &bevy_soft_body::core::Serial,
    );
    let (errors, owner) = piece_volumes(&block);
    assert_eq!(errors.len(), 2, "{} pieces", errors.len());
    // The halves are the two sides of the blade.
    let rest = block.mesh().positions();
    for (i, p) in rest.iter().enumerate() {
        if p.x < 0.1 || p.x > 0.2 {
            let side = owner[i].unwrap();
            let other = (0..rest.len())
                .find(|&j| rest[j].x < 0.1)
                .map(|j| owner[j].unwrap());
            assert_eq!(side == other.unwrap(), p.x < 0.1, "particle {i} at {p}");
        }
    }
    for _ in 0..60 {
        block.step_free(1.0 / 60.0, Vec3::ZERO);
    }
    let (errors, _) = piece_volumes(&block);
    for e in errors {
        assert!(e.abs() < 1.0, "a half's volume error {e} %");
    }
}
