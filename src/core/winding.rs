//! The generalized winding number of a triangle soup (Jacobson et al. 2013), made fast with a
//! bounding volume hierarchy whose far clusters are replaced by their dipole (Barill et al.
//! 2018, first order).
//!
//! For a closed, outward-oriented surface the winding number is 1 inside and 0 outside; for a
//! surface with holes it falls smoothly from 1 to 0 across the holes, so thresholding it at
//! 1/2 still gives a sensible inside; where parts overlap it adds up (2 in the overlap), so the
//! inside of several overlapping parts is their union.

use std::f32::consts::PI;

use glam::Vec3;

/// Triangles per BVH leaf.
const LEAF_SIZE: usize = 8;

/// A cluster is replaced by its dipole when the query point is at least this many cluster radii
/// from its centre. At 2 the dipole's error is a few percent of the cluster's contribution,
/// far from the 1/2 threshold the inside test uses.
const FAR: f32 = 2.0;

#[derive(Clone, Debug)]
struct Node {
    /// The cluster's area-weighted centre.
    centre: Vec3,
    /// Largest distance from `centre` to any of its triangles' vertices.
    radius: f32,
    /// Sum of its triangles' area vectors (`area * unit normal`).
    area_normal: Vec3,
    /// Leaf: `triangles[first..first + count]`; inner node: children `first` and `first + 1`
    /// in `nodes` (`count == 0`).
    first: u32,
    count: u32,
}

/// A triangle soup prepared for fast winding-number queries.
#[derive(Clone, Debug)]
pub struct WindingNumber {
    corners: Vec<[Vec3; 3]>,
    nodes: Vec<Node>,
}

impl WindingNumber {
    /// Prepares `triangles` (corner positions, counter-clockwise seen from outside) for
    /// queries. Degenerate triangles contribute nothing and may be included.
    pub fn new(triangles: Vec<[Vec3; 3]>) -> Self {
        let mut this = WindingNumber {
            corners: triangles,
            nodes: Vec::new(),
        };
        if !this.corners.is_empty() {
            let count = this.corners.len();
            this.nodes.push(Node {
                centre: Vec3::ZERO,
                radius: 0.0,
                area_normal: Vec3::ZERO,
                first: 0,
                count: 0,
            });
            this.build(0, 0, count);
        }
        this
    }

    /// Fills node `index` for `corners[start..end]`, splitting it at the median of the longest
    /// axis of its triangles' centroids until leaves hold at most [`LEAF_SIZE`].
    fn build(&mut self, index: usize, start: usize, end: usize) {
        let tris = &self.corners[start..end];
        let mut area_normal = Vec3::ZERO;
        let mut weighted = Vec3::ZERO;
        let mut area_sum = 0.0f32;
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for t in tris {
            let n = 0.5 * (t[1] - t[0]).cross(t[2] - t[0]);
            let a = n.length();
            area_normal += n;
            weighted += a * (t[0] + t[1] + t[2]) / 3.0;
            area_sum += a;
            let c = (t[0] + t[1] + t[2]) / 3.0;
            lo = lo.min(c);
            hi = hi.max(c);
        }
        let centre = if area_sum > 0.0 {
            weighted / area_sum
        } else {
            (lo + hi) * 0.5
        };
        let radius = tris
            .iter()
            .flat_map(|t| t.iter())
            .map(|p| p.distance(centre))
            .fold(0.0f32, f32::max);
        let node = &mut self.nodes[index];
        node.centre = centre;
        node.radius = radius;
        node.area_normal = area_normal;
        if end - start <= LEAF_SIZE {
            node.first = start as u32;
            node.count = (end - start) as u32;
            return;
        }
        let axis = (hi - lo).max_position();
        let mid = start + (end - start) / 2;
        let key = |t: &[Vec3; 3]| (t[0][axis] + t[1][axis] + t[2][axis]) / 3.0;
        self.corners[start..end]
            .select_nth_unstable_by(mid - start, |a, b| key(a).total_cmp(&key(b)));
        let left = self.nodes.len();
        let placeholder = Node {
            centre: Vec3::ZERO,
            radius: 0.0,
            area_normal: Vec3::ZERO,
            first: 0,
            count: 0,
        };
        self.nodes.push(placeholder.clone());
        self.nodes.push(placeholder);
        self.nodes[index].first = left as u32;
        self.nodes[index].count = 0;
        self.build(left, start, mid);
        self.build(left + 1, mid, end);
    }

    /// The winding number at `q`: about 1 inside a closed outward surface, 0 outside.
    pub fn at(&self, q: Vec3) -> f32 {
        if self.nodes.is_empty() {
            return 0.0;
        }
        let mut total = 0.0f32;
        let mut stack = [0u32; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top] as usize];
            let r = node.centre - q;
            let distance = r.length();
            if distance > FAR * node.radius {
                total += r.dot(node.area_normal) / (distance * distance * distance);
            } else if node.count > 0 {
                let first = node.first as usize;
                for t in &self.corners[first..first + node.count as usize] {
                    total += solid_angle(t, q);
                }
            } else if top + 2 <= stack.len() {
                stack[top] = node.first;
                stack[top + 1] = node.first + 1;
                top += 2;
            } else {
                // Deeper than any median-split tree of u32-indexed triangles can be; summed
                // exactly rather than dropped.
                total += self.exact_below(stack[top] as usize, q);
            }
        }
        total / (4.0 * PI)
    }

    fn exact_below(&self, index: usize, q: Vec3) -> f32 {
        let node = &self.nodes[index];
        if node.count > 0 {
            let first = node.first as usize;
            return self.corners[first..first + node.count as usize]
                .iter()
                .map(|t| solid_angle(t, q))
                .sum();
        }
        self.exact_below(node.first as usize, q) + self.exact_below(node.first as usize + 1, q)
    }

    /// The point of the surface closest to `q` (`None` without triangles). The hierarchy's
    /// bounding spheres prune clusters that cannot hold a closer point.
    pub fn closest_point(&self, q: Vec3) -> Option<Vec3> {
        if self.nodes.is_empty() {
            return None;
        }
        let mut best = (f32::INFINITY, q);
        let mut stack = vec![0u32];
        while let Some(index) = stack.pop() {
            let node = &self.nodes[index as usize];
            let reach = (node.centre.distance(q) - node.radius).max(0.0);
            if reach * reach >= best.0 {
                continue;
            }
            if node.count > 0 {
                let first = node.first as usize;
                for t in &self.corners[first..first + node.count as usize] {
                    let p = closest_on_triangle(t, q);
                    let d = p.distance_squared(q);
                    if d < best.0 {
                        best = (d, p);
                    }
                }
            } else {
                // Nearer child last, so it is searched first.
                let (a, b) = (node.first, node.first + 1);
                let da = self.nodes[a as usize].centre.distance_squared(q);
                let db = self.nodes[b as usize].centre.distance_squared(q);
                if da < db {
                    stack.extend([b, a]);
                } else {
                    stack.extend([a, b]);
                }
            }
        }
        best.0.is_finite().then_some(best.1)
    }

    /// The winding number at `q` summed over every triangle, without the hierarchy.
    pub fn exact_at(&self, q: Vec3) -> f32 {
        self.corners.iter().map(|t| solid_angle(t, q)).sum::<f32>() / (4.0 * PI)
    }
}

/// The point of triangle `t` closest to `q` (Ericson, Real-Time Collision Detection, 5.1.5).
fn closest_on_triangle(t: &[Vec3; 3], q: Vec3) -> Vec3 {
    let [a, b, c] = *t;
    let (ab, ac, ap) = (b - a, c - a, q - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = q - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = q - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    if !denom.is_finite() {
        // Degenerate triangle: its nearest corner.
        return [a, b, c]
            .into_iter()
            .min_by(|x, y| x.distance_squared(q).total_cmp(&y.distance_squared(q)))
            .unwrap_or(a);
    }
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// Signed solid angle of triangle `t` seen from `q` (Van Oosterom and Strackee 1983):
/// positive when `q` is behind the triangle (on the side its counter-clockwise normal points
/// away from).
fn solid_angle(t: &[Vec3; 3], q: Vec3) -> f32 {
    let (a, b, c) = (t[0] - q, t[1] - q, t[2] - q);
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let numerator = a.dot(b.cross(c));
    let denominator = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    2.0 * numerator.atan2(denominator)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::surface_mesh::subdivided_box;

    fn box_triangles(lo: Vec3, hi: Vec3, spacing: f32) -> Vec<[Vec3; 3]> {
        let s = subdivided_box(lo, hi, spacing);
        s.indices
            .chunks_exact(3)
            .map(|t| [0, 1, 2].map(|k| s.positions[t[k] as usize]))
            .collect()
    }

    #[test]
    fn one_inside_zero_outside_and_the_hierarchy_agrees() {
        let w = WindingNumber::new(box_triangles(Vec3::ZERO, Vec3::ONE, 0.05));
        assert!(w.corners.len() > 2000);
        for (q, expected) in [
            (Vec3::splat(0.5), 1.0),
            (Vec3::new(0.02, 0.5, 0.97), 1.0),
            (Vec3::splat(1.5), 0.0),
            (Vec3::new(-0.03, 0.5, 0.5), 0.0),
            (Vec3::new(5.0, -3.0, 2.0), 0.0),
        ] {
            let fast = w.at(q);
            let exact = w.exact_at(q);
            assert!((exact - expected).abs() < 1e-3, "{q}: exact {exact}");
            assert!(
                (fast - exact).abs() < 0.05,
                "{q}: fast {fast} exact {exact}"
            );
        }
    }

    #[test]
    fn closest_point_matches_brute_force() {
        let w = WindingNumber::new(box_triangles(Vec3::ZERO, Vec3::ONE, 0.1));
        for q in [
            Vec3::new(0.5, 0.5, 0.5),
            Vec3::new(0.3, 0.9, 0.2),
            Vec3::new(2.0, 0.5, -1.0),
            Vec3::new(-0.2, 1.3, 0.7),
        ] {
            let fast = w.closest_point(q).unwrap();
            let brute = w
                .corners
                .iter()
                .map(|t| closest_on_triangle(t, q))
                .min_by(|a, b| a.distance_squared(q).total_cmp(&b.distance_squared(q)))
                .unwrap();
            assert!((fast.distance(q) - brute.distance(q)).abs() < 1e-6, "{q}");
        }
        // Inside the unit box the nearest face is the nearest coordinate plane.
        let p = w.closest_point(Vec3::new(0.3, 0.9, 0.2)).unwrap();
        assert!((p - Vec3::new(0.3, 1.0, 0.2)).length() < 1e-5);
    }

    #[test]
    fn a_hole_keeps_the_inside_inside() {
        // The box without its top face's triangles near the centre.
        let tris: Vec<_> = box_triangles(Vec3::ZERO, Vec3::ONE, 0.1)
            .into_iter()
            .filter(|t| {
                let c = (t[0] + t[1] + t[2]) / 3.0;
                !(c.y > 0.99 && (c.x - 0.5).abs() < 0.2 && (c.z - 0.5).abs() < 0.2)
            })
            .collect();
        let w = WindingNumber::new(tris);
        assert!(w.at(Vec3::new(0.5, 0.3, 0.5)) > 0.8);
        assert!(w.at(Vec3::new(0.5, 1.3, 0.5)) < 0.2);
    }
}
