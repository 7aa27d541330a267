//! Rays against a body's deformed surface (its boundary triangles where the particles are
//! now): what picking, a gun or a line of sight asks of a soft body.

use glam::Vec3;

/// Where a ray met a body's surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    /// How far along the ray (in units of its direction's length).
    pub distance: f32,
    /// The point, world frame.
    pub point: Vec3,
    /// The surface's outward unit normal there.
    pub normal: Vec3,
    /// The boundary triangle's particles.
    pub triangle: [u32; 3],
    /// The point's barycentric weights in the triangle.
    pub weights: Vec3,
    /// The triangle's particle nearest the point.
    pub particle: u32,
}

/// The first point of the surface of `triangles` at `positions` that a ray from `origin` along
/// `direction` meets within `max_distance` (see
/// [`SoftBodyState::ray_cast`](super::SoftBodyState::ray_cast)).
pub(crate) fn ray_cast(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    origin: Vec3,
    direction: Vec3,
    max_distance: f32,
) -> Option<SurfaceHit> {
    if !ray_meets_bounds(positions, origin, direction, max_distance) {
        return None;
    }
    let mut best: Option<SurfaceHit> = None;
    for &triangle in triangles {
        let [a, b, c] = triangle.map(|i| positions[i as usize]);
        let Some((t, u, v)) = ray_triangle(origin, direction, a, b, c) else {
            continue;
        };
        if t > max_distance || best.is_some_and(|h| h.distance <= t) {
            continue;
        }
        let weights = Vec3::new(1.0 - u - v, u, v);
        let corner = if weights.x >= weights.y && weights.x >= weights.z {
            0
        } else if weights.y >= weights.z {
            1
        } else {
            2
        };
        best = Some(SurfaceHit {
            distance: t,
            point: origin + t * direction,
            normal: (b - a).cross(c - a).normalize_or_zero(),
            triangle,
            weights,
            particle: triangle[corner],
        });
    }
    best
}

/// Whether the ray can meet the box around `positions` (slab test).
fn ray_meets_bounds(positions: &[Vec3], origin: Vec3, direction: Vec3, max_distance: f32) -> bool {
    let (lo, hi) = positions
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        });
    let inv = direction.recip();
    let (t0, t1) = ((lo - origin) * inv, (hi - origin) * inv);
    let near = t0.min(t1).max_element().max(0.0);
    let far = t0.max(t1).min_element().min(max_distance);
    // A NaN (a ray along a face of the box) keeps the triangles in play.
    near.partial_cmp(&far) != Some(std::cmp::Ordering::Greater)
}

/// Möller-Trumbore: the distance `t` along the ray and the barycentric `u`, `v` of its meeting
/// with triangle `abc`, if it meets it at `t >= 0`.
fn ray_triangle(
    origin: Vec3,
    direction: Vec3,
    a: Vec3,
    b: Vec3,
    c: Vec3,
) -> Option<(f32, f32, f32)> {
    let (e1, e2) = (b - a, c - a);
    let p = direction.cross(e2);
    let det = e1.dot(p);
    if det.abs() <= f32::EPSILON * e1.length_squared() * direction.length() {
        return None;
    }
    let inv = 1.0 / det;
    let s = origin - a;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = direction.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t >= 0.0).then_some((t, u, v))
}
