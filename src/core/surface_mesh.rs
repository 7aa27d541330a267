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

impl TriangleSurface {
    /// Adds `other`'s triangles (and vertices) to this surface, as a separate part.
    pub fn append(&mut self, other: &TriangleSurface) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.indices.extend(other.indices.iter().map(|i| i + base));
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// The volume the surface encloses, by the divergence theorem: exact for a closed,
    /// outward-oriented surface, meaningless for others. Accumulated in `f64`.
    pub fn enclosed_volume(&self) -> f64 {
        self.indices
            .chunks_exact(3)
            .filter_map(|t| {
                let p = [0, 1, 2].map(|k| self.positions.get(t[k] as usize).copied());
                let [Some(a), Some(b), Some(c)] = p else {
                    return None;
                };
                Some(a.as_dvec3().dot(b.as_dvec3().cross(c.as_dvec3())) / 6.0)
            })
            .sum()
    }
}

/// A closed, outward sphere of `radius` around `centre` with `segments` around and `rings`
/// from pole to pole: `2 * segments * (rings - 1)` triangles. For tests, examples and
/// benchmarks that need a round input of a chosen size.
pub fn uv_sphere(centre: Vec3, radius: f32, segments: u32, rings: u32) -> TriangleSurface {
    let (segments, rings) = (segments.max(3), rings.max(2));
    let mut s = TriangleSurface::default();
    s.positions.push(centre + Vec3::Y * radius);
    for r in 1..rings {
        let theta = std::f32::consts::PI * r as f32 / rings as f32;
        for k in 0..segments {
            let phi = std::f32::consts::TAU * k as f32 / segments as f32;
            s.positions.push(
                centre
                    + radius
                        * Vec3::new(
                            theta.sin() * phi.cos(),
                            theta.cos(),
                            -theta.sin() * phi.sin(),
                        ),
            );
        }
    }
    s.positions.push(centre - Vec3::Y * radius);
    let south = s.positions.len() as u32 - 1;
    let at = |r: u32, k: u32| 1 + (r - 1) * segments + k % segments;
    for k in 0..segments {
        s.indices.extend_from_slice(&[0, at(1, k), at(1, k + 1)]);
        s.indices
            .extend_from_slice(&[south, at(rings - 1, k + 1), at(rings - 1, k)]);
    }
    for r in 1..rings - 1 {
        for k in 0..segments {
            let (a, b, c, d) = (at(r, k), at(r + 1, k), at(r + 1, k + 1), at(r, k + 1));
            s.indices.extend_from_slice(&[a, b, c, a, c, d]);
        }
    }
    s
}

/// A closed, outward torus around the Y axis through `centre`: tube radius `minor` at distance
/// `major` from the axis, `segments` around the axis and `sides` around the tube.
pub fn torus(centre: Vec3, major: f32, minor: f32, segments: u32, sides: u32) -> TriangleSurface {
    let (segments, sides) = (segments.max(3), sides.max(3));
    let mut s = TriangleSurface::default();
    for i in 0..segments {
        let phi = std::f32::consts::TAU * i as f32 / segments as f32;
        let radial = Vec3::new(phi.cos(), 0.0, -phi.sin());
        for j in 0..sides {
            let theta = std::f32::consts::TAU * j as f32 / sides as f32;
            s.positions.push(
                centre + radial * (major + minor * theta.cos()) + Vec3::Y * minor * theta.sin(),
            );
        }
    }
    let at = |i: u32, j: u32| (i % segments) * sides + j % sides;
    for i in 0..segments {
        for j in 0..sides {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            s.indices.extend_from_slice(&[a, b, c, a, c, d]);
        }
    }
    s
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
    fn generated_shapes_enclose_their_volumes() {
        let sphere = uv_sphere(Vec3::ONE, 2.0, 64, 32);
        let exact = 4.0 / 3.0 * std::f64::consts::PI * 8.0;
        let v = sphere.enclosed_volume();
        assert!((v - exact).abs() < 0.01 * exact, "{v} vs {exact}");
        let t = torus(Vec3::ZERO, 1.0, 0.25, 64, 32);
        let exact = 2.0 * std::f64::consts::PI.powi(2) * 1.0 * 0.25 * 0.25;
        let v = t.enclosed_volume();
        assert!((v - exact).abs() < 0.01 * exact, "{v} vs {exact}");
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
