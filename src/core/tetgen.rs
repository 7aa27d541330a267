//! TetGen's `.node` / `.ele` tet mesh files: reading (0- or 1-based, comments, attributes,
//! boundary markers, 4- or 10-node tets, either orientation) and writing.
//!
//! `.node`: a header `<points> <dimension = 3> <attributes> <boundary markers 0|1>`, then one
//! line per point `<index> <x> <y> <z> [attributes] [marker]`. `.ele`: a header
//! `<tets> <nodes per tet = 4|10> <attributes>`, then `<index> <n1> ... <nk> [attributes]`.
//! `#` starts a comment anywhere. The first point's index sets the numbering (0 or 1); every
//! further index must follow on. A 10-node (quadratic) tet is read as its 4 corners. Attributes
//! and markers are read and checked, then not used: a soft body has no place for them.

use std::fmt::Write as _;

use glam::Vec3;

use super::tet_mesh::{TetMesh, TetMeshError};

/// Which of the two files a [`TetGenError`] is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TetGenFile {
    /// The `.node` file.
    Node,
    /// The `.ele` file.
    Ele,
}

impl std::fmt::Display for TetGenFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            TetGenFile::Node => ".node",
            TetGenFile::Ele => ".ele",
        })
    }
}

/// What is wrong with a TetGen mesh.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TetGenError {
    /// A line of one of the files is malformed.
    #[error("{file} line {line}: {message}")]
    Syntax {
        /// The file.
        file: TetGenFile,
        /// The line, counting from 1.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A file ends before the header's count of entries.
    #[error("{file}: the header announces {expected} entries, the file has {found}")]
    Truncated {
        /// The file.
        file: TetGenFile,
        /// Entries announced.
        expected: u64,
        /// Entries found.
        found: u64,
    },
    /// The tets do not make a valid mesh (index out of range, degenerate tet, ...).
    #[error("the tets do not make a valid mesh: {0}")]
    Mesh(#[from] TetMeshError),
}

/// The significant lines of a file: comments stripped, blank lines skipped, numbered from 1.
fn lines(text: &str) -> impl Iterator<Item = (usize, Vec<&str>)> {
    text.lines().enumerate().filter_map(|(n, raw)| {
        let content = raw.split('#').next().unwrap_or("");
        let tokens: Vec<&str> = content.split_whitespace().collect();
        (!tokens.is_empty()).then_some((n + 1, tokens))
    })
}

fn syntax(file: TetGenFile, line: usize, message: impl Into<String>) -> TetGenError {
    TetGenError::Syntax {
        file,
        line,
        message: message.into(),
    }
}

fn number<T: std::str::FromStr>(
    file: TetGenFile,
    line: usize,
    token: Option<&&str>,
    what: &str,
) -> Result<T, TetGenError> {
    let token = token.ok_or_else(|| syntax(file, line, format!("missing {what}")))?;
    token.parse().map_err(|_| {
        syntax(
            file,
            line,
            format!("{what} `{token}` is not a valid number"),
        )
    })
}

/// Reads a TetGen mesh from the text of its `.node` and `.ele` files and validates it.
pub fn parse_tetgen(node: &str, ele: &str) -> Result<TetMesh, TetGenError> {
    let (positions, base) = parse_node(node)?;
    let tets = parse_ele(ele, base, positions.len())?;
    Ok(TetMesh::new(positions, tets)?)
}

fn parse_node(text: &str) -> Result<(Vec<Vec3>, u64), TetGenError> {
    let file = TetGenFile::Node;
    let mut lines = lines(text);
    let (line, header) = lines.next().ok_or_else(|| syntax(file, 1, "no header"))?;
    let count: u64 = number(file, line, header.first(), "point count")?;
    let dimension: u64 = number(file, line, header.get(1), "dimension")?;
    if dimension != 3 {
        return Err(syntax(file, line, format!("dimension {dimension}, not 3")));
    }
    let attributes: u64 = match header.get(2) {
        Some(_) => number(file, line, header.get(2), "attribute count")?,
        None => 0,
    };
    let markers: u64 = match header.get(3) {
        Some(_) => number(file, line, header.get(3), "boundary marker flag")?,
        None => 0,
    };
    if markers > 1 {
        return Err(syntax(
            file,
            line,
            "the boundary marker flag must be 0 or 1",
        ));
    }
    // Never trust the header for the allocation: a line holds at least 8 bytes.
    let mut positions = Vec::with_capacity((count as usize).min(text.len() / 8));
    let mut base = 0;
    for (line, tokens) in lines {
        if positions.len() as u64 == count {
            return Err(syntax(
                file,
                line,
                format!("more points than the header's {count}"),
            ));
        }
        let index: u64 = number(file, line, tokens.first(), "point index")?;
        if positions.is_empty() {
            if index > 1 {
                return Err(syntax(file, line, "the first point must be 0 or 1"));
            }
            base = index;
        } else if index != base + positions.len() as u64 {
            return Err(syntax(
                file,
                line,
                format!(
                    "point index {index} out of sequence (expected {})",
                    base + positions.len() as u64
                ),
            ));
        }
        let expected = 4 + attributes + markers;
        if tokens.len() as u64 != expected {
            return Err(syntax(
                file,
                line,
                format!(
                    "{} fields, the header says {expected} (index, x, y, z, {attributes} attributes, {markers} markers)",
                    tokens.len()
                ),
            ));
        }
        let mut xyz = [0.0f32; 3];
        for (k, c) in xyz.iter_mut().enumerate() {
            *c = number(file, line, tokens.get(1 + k), "coordinate")?;
        }
        for k in 4..tokens.len() {
            let _: f64 = number(file, line, tokens.get(k), "attribute or marker")?;
        }
        positions.push(Vec3::from_array(xyz));
    }
    if (positions.len() as u64) < count || count == 0 {
        return Err(TetGenError::Truncated {
            file,
            expected: count,
            found: positions.len() as u64,
        });
    }
    Ok((positions, base))
}

fn parse_ele(text: &str, base: u64, points: usize) -> Result<Vec<[u32; 4]>, TetGenError> {
    let file = TetGenFile::Ele;
    let mut lines = lines(text);
    let (line, header) = lines.next().ok_or_else(|| syntax(file, 1, "no header"))?;
    let count: u64 = number(file, line, header.first(), "tet count")?;
    let per_tet: u64 = match header.get(1) {
        Some(_) => number(file, line, header.get(1), "nodes per tet")?,
        None => 4,
    };
    if per_tet != 4 && per_tet != 10 {
        return Err(syntax(
            file,
            line,
            format!("{per_tet} nodes per tet; only 4 and 10 exist"),
        ));
    }
    let attributes: u64 = match header.get(2) {
        Some(_) => number(file, line, header.get(2), "attribute count")?,
        None => 0,
    };
    let mut tets = Vec::with_capacity((count as usize).min(text.len() / 10));
    let mut first_index = None;
    for (line, tokens) in lines {
        if tets.len() as u64 == count {
            return Err(syntax(
                file,
                line,
                format!("more tets than the header's {count}"),
            ));
        }
        let index: u64 = number(file, line, tokens.first(), "tet index")?;
        let first = *first_index.get_or_insert(index);
        if index != first + tets.len() as u64 || first > 1 {
            return Err(syntax(
                file,
                line,
                format!("tet index {index} out of sequence"),
            ));
        }
        let expected = 1 + per_tet + attributes;
        if tokens.len() as u64 != expected {
            return Err(syntax(
                file,
                line,
                format!(
                    "{} fields, the header says {expected} (index, {per_tet} nodes, {attributes} attributes)",
                    tokens.len()
                ),
            ));
        }
        let mut tet = [0u32; 4];
        for (k, v) in tet.iter_mut().enumerate() {
            let node: u64 = number(file, line, tokens.get(1 + k), "node index")?;
            if node < base || node - base >= points as u64 {
                return Err(syntax(
                    file,
                    line,
                    format!(
                        "node {node} does not exist (points are numbered from {base}, {points} of them)"
                    ),
                ));
            }
            *v = (node - base) as u32;
        }
        for k in 5..tokens.len() {
            let _: f64 = number(file, line, tokens.get(k), "node or attribute")?;
        }
        tets.push(tet);
    }
    if (tets.len() as u64) < count || count == 0 {
        return Err(TetGenError::Truncated {
            file,
            expected: count,
            found: tets.len() as u64,
        });
    }
    Ok(tets)
}

/// Writes `mesh` as the text of a `.node` and an `.ele` file, numbered from 1 (TetGen's
/// default), no attributes, no markers.
pub fn write_tetgen(mesh: &TetMesh) -> (String, String) {
    let mut node = String::with_capacity(mesh.vertex_count() * 40);
    let _ = writeln!(node, "# written by bevy_soft_body");
    let _ = writeln!(node, "{} 3 0 0", mesh.vertex_count());
    for (i, p) in mesh.positions().iter().enumerate() {
        let _ = writeln!(node, "{} {} {} {}", i + 1, p.x, p.y, p.z);
    }
    let mut ele = String::with_capacity(mesh.tet_count() * 30);
    let _ = writeln!(ele, "# written by bevy_soft_body");
    let _ = writeln!(ele, "{} 4 0", mesh.tet_count());
    for (t, tet) in mesh.tets().iter().enumerate() {
        let _ = writeln!(
            ele,
            "{} {} {} {} {}",
            t + 1,
            tet[0] + 1,
            tet[1] + 1,
            tet[2] + 1,
            tet[3] + 1
        );
    }
    (node, ele)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::grid::box_grid;
    use glam::UVec3;

    #[test]
    fn round_trip() {
        let m = box_grid(
            UVec3::new(2, 3, 1),
            Vec3::splat(0.5),
            Vec3::new(1.0, 0.0, -2.0),
        )
        .unwrap();
        let (node, ele) = write_tetgen(&m);
        let back = parse_tetgen(&node, &ele).unwrap();
        assert_eq!(back.positions(), m.positions());
        assert_eq!(back.tets(), m.tets());
    }

    #[test]
    fn zero_based_comments_attributes_markers_quadratic_and_either_orientation() {
        let node = "# unit tet and its mirror\n5 3 1 1\n0 0 0 0 7.5 1\n1 1 0 0 0 0 # x\n\
                    2 0 1 0 0 1\n3 0 0 1 0 1\n4 0 0 -1 0 1\n";
        // The first tet is positively oriented, the second negatively; 10 nodes each.
        let ele = "2 10 1\n0 0 1 2 3 0 0 0 0 0 0 3.0\n1 0 1 2 4 0 0 0 0 0 0 3.0\n";
        let m = parse_tetgen(node, ele).unwrap();
        assert_eq!(m.vertex_count(), 5);
        assert_eq!(m.tet_count(), 2);
        assert_eq!(m.reoriented_tets(), 1);
        assert!(
            m.rest_volumes()
                .iter()
                .all(|&v| (v - 1.0 / 6.0).abs() < 1e-6)
        );
    }

    #[test]
    fn bad_files_give_errors() {
        let node = "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n";
        let ele = "1 4 0\n1 1 2 3 4\n";
        assert!(parse_tetgen(node, ele).is_ok());
        let bad: [(&str, &str, &str); 14] = [
            ("", ele, "no header"),
            ("4 2 0 0\n", ele, "dimension"),
            ("4 3 0 0\n1 0 0 0\n", ele, "announces 4"),
            (
                "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n5 0 0 1\n",
                ele,
                "out of sequence",
            ),
            ("4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0\n", ele, "fields"),
            (
                "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 z\n",
                ele,
                "not a valid number",
            ),
            (
                "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n",
                ele,
                "more points",
            ),
            ("4 3 0 0\n7 0 0 0\n", ele, "first point"),
            (node, "1 4 0\n1 1 2 3 5\n", "does not exist"),
            (node, "1 4 0\n1 0 2 3 4\n", "does not exist"),
            (node, "2 4 0\n1 1 2 3 4\n", "announces 2"),
            (node, "1 6 0\n1 1 2 3 4 1 1\n", "only 4 and 10"),
            (node, "1 4 0\n1 1 2 3 3\n", "valid mesh"),
            ("99999999999 3 0 0\n1 0 0 0\n", ele, "announces 99999999999"),
        ];
        for (node, ele, expected) in bad {
            let e = parse_tetgen(node, ele).unwrap_err().to_string();
            assert!(e.contains(expected), "`{e}` should say `{expected}`");
        }
    }
}
