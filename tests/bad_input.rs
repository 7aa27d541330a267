//! Property tests of everything that reads outside data: mutated OBJ and TetGen files and
//! random triangle soups must give a result or an error, never a panic, an endless loop or an
//! unbounded allocation; whatever they give must be valid.

use bevy_soft_body::core::{
    ObjError, ObjErrorKind, Resolution, TetGenError, TetGenFile, parse_obj, parse_tetgen,
    tetrahedralize, uv_sphere, write_obj, write_tetgen,
};
use glam::Vec3;

/// A small deterministic generator (no dependency, same cases on every run).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 33
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
    fn unit(&mut self) -> f32 {
        self.next() as f32 / (1u64 << 31) as f32
    }
}

/// One random edit of `text`: delete, duplicate or replace a span, insert a troublesome token,
/// or cut the file short.
fn mutate(text: &[u8], rng: &mut Rng) -> Vec<u8> {
    const TOKENS: [&[u8]; 14] = [
        b"-1",
        b"0",
        b"4294967296",
        b"99999999999999999999",
        b"nan",
        b"inf",
        b"-inf",
        b"1e39",
        b"#",
        b"\n",
        b"/",
        b"f",
        b"v",
        b"\xff",
    ];
    let mut out = text.to_vec();
    let at = rng.below(out.len() + 1);
    let len = rng.below(16).min(out.len() - at.min(out.len()));
    match rng.below(5) {
        0 => {
            out.drain(at..at + len);
        }
        1 => {
            let span = out[at..at + len].to_vec();
            out.splice(at..at, span);
        }
        2 => {
            let token = TOKENS[rng.below(TOKENS.len())];
            out.splice(at..at + len, token.iter().copied());
        }
        3 => {
            let token = TOKENS[rng.below(TOKENS.len())];
            out.splice(at..at, token.iter().copied());
        }
        _ => out.truncate(at),
    }
    out
}

#[test]
fn mutated_obj_files_never_panic() {
    let sphere = uv_sphere(Vec3::ZERO, 1.0, 8, 4);
    let text = write_obj(&sphere).into_bytes();
    let mut rng = Rng(1);
    let (mut ok, mut err) = (0, 0);
    for _ in 0..3000 {
        let mut bytes = text.clone();
        for _ in 0..1 + rng.below(4) {
            bytes = mutate(&bytes, &mut rng);
        }
        match parse_obj(&bytes) {
            Ok(s) => {
                ok += 1;
                assert!(s.positions.iter().all(|p| p.is_finite()));
                assert!(s.indices.iter().all(|&i| (i as usize) < s.positions.len()));
                assert_eq!(s.indices.len() % 3, 0);
            }
            Err(e) => {
                err += 1;
                assert_error_points_at_the_fault(&bytes, &e);
            }
        }
    }
    // Both outcomes happen, so the mutations exercise the parser rather than always break it.
    assert!(ok > 100 && err > 100, "ok {ok} err {err}");
}

#[test]
fn mutated_tetgen_files_never_panic() {
    let mesh =
        bevy_soft_body::core::box_grid(glam::UVec3::new(2, 2, 1), Vec3::ONE, Vec3::ZERO).unwrap();
    let (node, ele) = write_tetgen(&mesh);
    let mut rng = Rng(2);
    let (mut ok, mut err) = (0, 0);
    for _ in 0..3000 {
        let (mut n, mut e) = (node.clone().into_bytes(), ele.clone().into_bytes());
        for _ in 0..1 + rng.below(3) {
            if rng.below(2) == 0 {
                n = mutate(&n, &mut rng);
            } else {
                e = mutate(&e, &mut rng);
            }
        }
        let (Ok(n), Ok(e)) = (std::str::from_utf8(&n), std::str::from_utf8(&e)) else {
            continue;
        };
        match parse_tetgen(n, e) {
            Ok(m) => {
                ok += 1;
                assert!(m.rest_volumes().iter().all(|&v| v > 0.0));
            }
            Err(error) => {
                err += 1;
                match &error {
                    // The line exists in the file named.
                    TetGenError::Syntax { file, line, .. } => {
                        let text = match file {
                            TetGenFile::Node => n,
                            TetGenFile::Ele => e,
                        };
                        assert!(
                            (1..=text.lines().count().max(1)).contains(line),
                            "{error}: the {file} file has {} lines",
                            text.lines().count()
                        );
                    }
                    TetGenError::Truncated {
                        expected, found, ..
                    } => assert!(found < expected, "{error}"),
                    TetGenError::Mesh(_) => {}
                }
            }
        }
    }
    assert!(ok > 100 && err > 100, "ok {ok} err {err}");
}

/// An OBJ error names the line at fault and quotes what is wrong there; a file-wide one (line
/// 0) is about the file as a whole.
fn assert_error_points_at_the_fault(bytes: &[u8], error: &ObjError) {
    let Ok(text) = std::str::from_utf8(bytes) else {
        assert_eq!(error.kind, ObjErrorKind::NotText, "{error}");
        return;
    };
    if error.line == 0 {
        assert_eq!(error.kind, ObjErrorKind::NoFaces, "{error}");
        return;
    }
    let line = text
        .lines()
        .nth(error.line - 1)
        .unwrap_or_else(|| panic!("{error}: the file has {} lines", text.lines().count()));
    match &error.kind {
        ObjErrorKind::BadVertex(quoted)
        | ObjErrorKind::NonFinite(quoted)
        | ObjErrorKind::BadIndex(quoted) => {
            assert!(line.contains(quoted.as_str()), "{error}: line `{line}`")
        }
        ObjErrorKind::ShortFace(_) | ObjErrorKind::IndexOutOfRange { .. } => {
            assert!(line.trim_start().starts_with('f'), "{error}: line `{line}`")
        }
        ObjErrorKind::NotText | ObjErrorKind::NoFaces => panic!("{error} on line {}", error.line),
    }
}

#[test]
fn random_triangle_soups_never_panic() {
    let mut rng = Rng(3);
    let mut built = 0;
    for case in 0..300 {
        let n = 3 + rng.below(40);
        let scale = [1e-3, 1.0, 1e3][case % 3];
        let mut positions: Vec<Vec3> = (0..n)
            .map(|_| Vec3::new(rng.unit(), rng.unit(), rng.unit()) * scale)
            .collect();
        if case % 7 == 0 {
            // Everything in a plane, or everything at one point.
            for p in &mut positions {
                p.z = 0.0;
                if case % 14 == 0 {
                    *p = Vec3::ONE;
                }
            }
        }
        let triangles = 1 + rng.below(60);
        let mut indices: Vec<u32> = (0..3 * triangles).map(|_| rng.below(n) as u32).collect();
        if case % 11 == 0 {
            indices.push(n as u32 + 5);
        }
        let resolution = if case % 2 == 0 {
            Resolution::TargetTets(1 + rng.below(3000) as u32)
        } else {
            Resolution::CellSize(scale * (0.01 + rng.unit()))
        };
        if let Ok(t) = tetrahedralize(&positions, &indices, resolution) {
            built += 1;
            assert!(t.mesh.rest_volumes().iter().all(|&v| v > 0.0));
            assert!(t.mesh.positions().iter().all(|p| p.is_finite()));
            assert!(t.components >= 1);
        }
    }
    assert!(built > 20, "only {built} soups gave a mesh");
}
