//! Fine triangle surfaces for the paper's bodies, to embed in their tet meshes: a subdivided
//! box for the box scenes, and a smooth surface extracted from a signed distance function
//! (surface nets) for the creature.

use glam::{IVec3, Vec3};

/// An indexed triangle list with counter-clockwise (outward) triangles.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriangleSurface {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Three vertex indices per triangle.
    pub indices: Vec<u32>,
}

/// The surface of the box from `lo` to `hi`, each face split into squares of about `spacing`.
/// Faces do not share vertices, so edges stay sharp.
pub fn subdivided_box(lo: Vec3, hi: Vec3, spacing: f32) -> TriangleSurface {
    let size = hi - lo;
    let mut surface = TriangleSurface::default();
    // (origin, u, v): u x v points out of the box.
    let faces = [
        (lo, Vec3::Z * size.z, Vec3::Y * size.y),
        (
            Vec3::new(hi.x, lo.y, lo.z),
            Vec3::Y * size.y,
            Vec3::Z * size.z,
        ),
        (lo, Vec3::X * size.x, Vec3::Z * size.z),
        (
            Vec3::new(lo.x, hi.y, lo.z),
            Vec3::Z * size.z,
            Vec3::X * size.x,
        ),
        (lo, Vec3::Y * size.y, Vec3::X * size.x),
        (
            Vec3::new(lo.x, lo.y, hi.z),
            Vec3::X * size.x,
            Vec3::Y * size.y,
        ),
    ];
    let spacing = spacing.max(f32::EPSILON);
    for (origin, u, v) in faces {
        let nu = ((u.length() / spacing).round() as u32).max(1);
        let nv = ((v.length() / spacing).round() as u32).max(1);
        let base = surface.positions.len() as u32;
        for j in 0..=nv {
            for i in 0..=nu {
                surface
                    .positions
                    .push(origin + u * (i as f32 / nu as f32) + v * (j as f32 / nv as f32));
            }
        }
        let at = |i: u32, j: u32| base + j * (nu + 1) + i;
        for j in 0..nv {
            for i in 0..nu {
                let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                surface.indices.extend_from_slice(&[a, b, c, a, c, d]);
            }
        }
    }
    surface
}

/// The zero level set of `sdf` (negative inside) between `lo` and `hi`, sampled every `spacing`,
/// by surface nets: one vertex per grid cell the surface crosses, at the mean of the crossings
/// on the cell's edges, and one quad per grid edge the surface crosses. Smooth, watertight where
/// the surface stays inside the box, and oriented outwards (along the gradient of `sdf`).
pub fn surface_nets(
    sdf: impl Fn(Vec3) -> f32,
    lo: Vec3,
    hi: Vec3,
    spacing: f32,
) -> TriangleSurface {
    let spacing = spacing.max(f32::EPSILON);
    let n = ((hi - lo) / spacing).ceil().as_ivec3() + 1;
    let corner = |c: IVec3| lo + c.as_vec3() * spacing;
    let index = |c: IVec3| ((c.z * n.y + c.y) * n.x + c.x) as usize;
    let mut values = vec![0.0f32; (n.x * n.y * n.z) as usize];
    for z in 0..n.z {
        for y in 0..n.y {
            for x in 0..n.x {
                let c = IVec3::new(x, y, z);
                values[index(c)] = sdf(corner(c));
            }
        }
    }
    // One vertex per cell (cells are indexed by their lowest corner).
    let cells = n - 1;
    let cell_index = |c: IVec3| ((c.z * cells.y + c.y) * cells.x + c.x) as usize;
    let mut vertex_of = vec![u32::MAX; (cells.x * cells.y * cells.z).max(0) as usize];
    let mut surface = TriangleSurface::default();
    const EDGES: [(IVec3, IVec3); 12] = [
        (IVec3::new(0, 0, 0), IVec3::new(1, 0, 0)),
        (IVec3::new(0, 1, 0), IVec3::new(1, 1, 0)),
        (IVec3::new(0, 0, 1), IVec3::new(1, 0, 1)),
        (IVec3::new(0, 1, 1), IVec3::new(1, 1, 1)),
        (IVec3::new(0, 0, 0), IVec3::new(0, 1, 0)),
        (IVec3::new(1, 0, 0), IVec3::new(1, 1, 0)),
        (IVec3::new(0, 0, 1), IVec3::new(0, 1, 1)),
        (IVec3::new(1, 0, 1), IVec3::new(1, 1, 1)),
        (IVec3::new(0, 0, 0), IVec3::new(0, 0, 1)),
        (IVec3::new(1, 0, 0), IVec3::new(1, 0, 1)),
        (IVec3::new(0, 1, 0), IVec3::new(0, 1, 1)),
        (IVec3::new(1, 1, 0), IVec3::new(1, 1, 1)),
    ];
    for z in 0..cells.z {
        for y in 0..cells.y {
            for x in 0..cells.x {
                let c = IVec3::new(x, y, z);
                let (mut sum, mut count) = (Vec3::ZERO, 0);
                for (a, b) in EDGES {
                    let (va, vb) = (values[index(c + a)], values[index(c + b)]);
                    if (va < 0.0) != (vb < 0.0) {
                        let t = va / (va - vb);
                        sum += corner(c + a).lerp(corner(c + b), t);
                        count += 1;
                    }
                }
                if count > 0 {
                    vertex_of[cell_index(c)] = surface.positions.len() as u32;
                    surface.positions.push(sum / count as f32);
                }
            }
        }
    }
    // A quad around every crossed grid edge, from the four cells that share it.
    let axes = [IVec3::X, IVec3::Y, IVec3::Z];
    for (axis, &dir) in axes.iter().enumerate() {
        let (u, v) = (axes[(axis + 1) % 3], axes[(axis + 2) % 3]);
        for z in 0..n.z {
            for y in 0..n.y {
                for x in 0..n.x {
                    let c = IVec3::new(x, y, z);
                    let end = c + dir;
                    if end.cmpge(n).any() {
                        continue;
                    }
                    let (va, vb) = (values[index(c)], values[index(end)]);
                    if (va < 0.0) == (vb < 0.0) {
                        continue;
                    }
                    let around = [c - u - v, c - v, c, c - u];
                    if around
                        .iter()
                        .any(|q| q.cmplt(IVec3::ZERO).any() || q.cmpge(cells).any())
                    {
                        continue;
                    }
                    let q = around.map(|q| vertex_of[cell_index(q)]);
                    if q.contains(&u32::MAX) {
                        continue;
                    }
                    // Inside to outside along the edge: the quad faces the edge's direction.
                    let quad = if va < 0.0 {
                        [q[0], q[1], q[2], q[3]]
                    } else {
                        [q[0], q[3], q[2], q[1]]
                    };
                    surface
                        .indices
                        .extend_from_slice(&[quad[0], quad[1], quad[2], quad[0], quad[2], quad[3]]);
                }
            }
        }
    }
    surface
}

#[cfg(test)]
mod tests {
    use super::*;

    fn triangle_normal(s: &TriangleSurface, t: usize) -> (Vec3, Vec3) {
        let [a, b, c] = [0, 1, 2].map(|k| s.positions[s.indices[3 * t + k] as usize]);
        ((b - a).cross(c - a), (a + b + c) / 3.0)
    }

    /// Closed and outward: the signed volume from the divergence theorem is the solid's.
    fn enclosed_volume(s: &TriangleSurface) -> f32 {
        s.indices
            .chunks(3)
            .map(|t| {
                let [a, b, c] = [0, 1, 2].map(|k| s.positions[t[k] as usize]);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    #[test]
    fn subdivided_box_is_closed_and_outward() {
        let s = subdivided_box(Vec3::ZERO, Vec3::new(0.6, 0.3, 0.9), 0.1);
        assert!((enclosed_volume(&s) - 0.6 * 0.3 * 0.9).abs() < 1e-5);
        let centre = Vec3::new(0.3, 0.15, 0.45);
        for t in 0..s.indices.len() / 3 {
            let (n, at) = triangle_normal(&s, t);
            assert!(n.dot(at - centre) > 0.0);
        }
    }

    #[test]
    fn surface_nets_of_a_sphere_are_outward_and_keep_its_volume() {
        let r = 0.5;
        let s = surface_nets(
            |p| p.length() - r,
            Vec3::splat(-0.7),
            Vec3::splat(0.7),
            0.05,
        );
        let exact = 4.0 / 3.0 * std::f32::consts::PI * r * r * r;
        let v = enclosed_volume(&s);
        assert!((v - exact).abs() < 0.03 * exact, "{v} vs {exact}");
        for p in &s.positions {
            assert!((p.length() - r).abs() < 0.05);
        }
        for t in 0..s.indices.len() / 3 {
            let (n, at) = triangle_normal(&s, t);
            assert!(n.dot(at) > 0.0);
        }
    }
}
