//! Wavefront OBJ triangle meshes: reading the geometry (`v` and `f`), writing it back.
//!
//! Only what a surface to tetrahedralize needs is read: vertex positions and faces. Faces with
//! more than three corners are split into a fan; texture and normal indices (`v/t/n`) are
//! accepted and not used; relative (negative) indices are resolved. Statements that carry no
//! surface (`vn`, `vt`, `o`, `g`, `s`, `usemtl`, `mtllib`, lines, points, ...) are skipped.

use std::fmt::Write as _;

use glam::Vec3;

use super::surface_mesh::TriangleSurface;

/// What is wrong with an OBJ file, and on which line (1-based; 0 for the file as a whole).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("OBJ line {line}: {kind}")]
pub struct ObjError {
    /// The line, counting from 1; 0 when the problem is the file as a whole.
    pub line: usize,
    /// What is wrong.
    pub kind: ObjErrorKind,
}

/// The kinds of [`ObjError`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ObjErrorKind {
    /// The file is not UTF-8 text.
    #[error("not UTF-8 text")]
    NotText,
    /// A vertex has fewer than three coordinates or one that is not a number.
    #[error("a vertex needs three numbers, got `{0}`")]
    BadVertex(String),
    /// A vertex coordinate is NaN or infinite.
    #[error("vertex coordinate is not finite: `{0}`")]
    NonFinite(String),
    /// A face has fewer than three corners.
    #[error("a face needs at least three corners, got {0}")]
    ShortFace(usize),
    /// A face corner is not an index.
    #[error("`{0}` is not a vertex index")]
    BadIndex(String),
    /// A face corner refers to a vertex that does not exist (yet).
    #[error("index {index} refers to no vertex ({vertices} defined so far)")]
    IndexOutOfRange {
        /// The index as written.
        index: i64,
        /// Vertices defined before this line.
        vertices: usize,
    },
    /// The file has no faces.
    #[error("the file has no faces")]
    NoFaces,
}

/// Reads the triangles of an OBJ file.
pub fn parse_obj(bytes: &[u8]) -> Result<TriangleSurface, ObjError> {
    let text = std::str::from_utf8(bytes).map_err(|_| ObjError {
        line: 0,
        kind: ObjErrorKind::NotText,
    })?;
    let mut surface = TriangleSurface::default();
    let mut corners: Vec<u32> = Vec::new();
    for (n, raw) in text.lines().enumerate() {
        let line = n + 1;
        let fail = |kind| ObjError { line, kind };
        let content = raw.split('#').next().unwrap_or("").trim();
        let mut tokens = content.split_whitespace();
        match tokens.next() {
            Some("v") => {
                let mut xyz = [0.0f32; 3];
                for c in &mut xyz {
                    let token = tokens
                        .next()
                        .ok_or_else(|| fail(ObjErrorKind::BadVertex(content.to_string())))?;
                    *c = token
                        .parse()
                        .map_err(|_| fail(ObjErrorKind::BadVertex(content.to_string())))?;
                    if !c.is_finite() {
                        return Err(fail(ObjErrorKind::NonFinite(token.to_string())));
                    }
                }
                surface.positions.push(Vec3::from_array(xyz));
            }
            Some("f") => {
                corners.clear();
                for token in tokens {
                    let index_text = token.split('/').next().unwrap_or("");
                    let index: i64 = index_text
                        .parse()
                        .map_err(|_| fail(ObjErrorKind::BadIndex(token.to_string())))?;
                    let count = surface.positions.len();
                    let resolved = if index > 0 {
                        index - 1
                    } else {
                        count as i64 + index
                    };
                    if index == 0 || resolved < 0 || resolved >= count as i64 {
                        return Err(fail(ObjErrorKind::IndexOutOfRange {
                            index,
                            vertices: count,
                        }));
                    }
                    corners.push(resolved as u32);
                }
                if corners.len() < 3 {
                    return Err(fail(ObjErrorKind::ShortFace(corners.len())));
                }
                for k in 1..corners.len() - 1 {
                    surface
                        .indices
                        .extend_from_slice(&[corners[0], corners[k], corners[k + 1]]);
                }
            }
            _ => {}
        }
    }
    if surface.indices.is_empty() {
        return Err(ObjError {
            line: 0,
            kind: ObjErrorKind::NoFaces,
        });
    }
    Ok(surface)
}

/// Writes `surface` as OBJ text (`v` and `f` lines, 1-based indices).
pub fn write_obj(surface: &TriangleSurface) -> String {
    let mut out = String::with_capacity(surface.positions.len() * 32 + surface.indices.len() * 8);
    for p in &surface.positions {
        let _ = writeln!(out, "v {} {} {}", p.x, p.y, p.z);
    }
    for t in surface.indices.chunks_exact(3) {
        let _ = writeln!(out, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::surface_mesh::uv_sphere;

    #[test]
    fn round_trip() {
        let s = uv_sphere(Vec3::new(0.5, -1.0, 2.0), 1.25, 12, 6);
        let back = parse_obj(write_obj(&s).as_bytes()).unwrap();
        assert_eq!(back, s);
    }

    #[test]
    fn polygons_slashes_negative_indices_and_comments() {
        let text = "# a quad\nmtllib x.mtl\no quad\nv 0 0 0\nv 1 0 0\nv 1 1 0 # corner\nv 0 1 0\n\
                    vt 0 0\nvn 0 0 1\ns off\nf 1/1/1 2//1 3/1 -1\nl 1 2\n";
        let s = parse_obj(text.as_bytes()).unwrap();
        assert_eq!(s.positions.len(), 4);
        assert_eq!(s.indices, vec![0, 1, 2, 0, 2, 3]);
    }

    #[test]
    fn bad_files_give_errors_with_their_line() {
        type Check = fn(&ObjErrorKind) -> bool;
        let cases: [(&[u8], usize, Check); 9] = [
            (b"", 0, |k| *k == ObjErrorKind::NoFaces),
            (b"v 0 0 0\nv 1 0 0\n", 0, |k| *k == ObjErrorKind::NoFaces),
            (b"v 0 0\n", 1, |k| matches!(k, ObjErrorKind::BadVertex(_))),
            (b"v 0 x 0\n", 1, |k| matches!(k, ObjErrorKind::BadVertex(_))),
            (b"v 0 nan 0\n", 1, |k| {
                matches!(k, ObjErrorKind::NonFinite(_))
            }),
            (b"v 0 0 0\nv 1 0 0\nf 1 2\n", 3, |k| {
                *k == ObjErrorKind::ShortFace(2)
            }),
            (b"v 0 0 0\nf 1 2 3\n", 2, |k| {
                matches!(k, ObjErrorKind::IndexOutOfRange { index: 2, .. })
            }),
            (b"v 0 0 0\nv 0 0 0\nv 0 0 0\nf 0 1 2\n", 4, |k| {
                matches!(k, ObjErrorKind::IndexOutOfRange { index: 0, .. })
            }),
            (b"v 0 0 0\n\xff\xfe\n", 0, |k| *k == ObjErrorKind::NotText),
        ];
        for (text, line, kind) in cases {
            let e = parse_obj(text).unwrap_err();
            assert_eq!(e.line, line, "{e}");
            assert!(kind(&e.kind), "{e}");
            assert!(e.to_string().starts_with("OBJ line"));
        }
    }
}
