//! Signed tet volumes, their gradients, and the volume of a tet whose vertices move along
//! directions as a cubic in the step length (the paper's Eq. for `V(k_V)`).

use glam::Vec3;
use wide::f32x4;

use super::lanes::Vec3x4;
use super::roots::Cubic;

/// `1 / 6`, multiplied by rather than divided by: a division costs several multiplications in
/// the hottest loops of the volume passes.
pub(crate) const SIXTH: f32 = 1.0 / 6.0;

/// `u . (v x w)`.
#[inline]
pub fn triple(u: Vec3, v: Vec3, w: Vec3) -> f32 {
    u.dot(v.cross(w))
}

/// Signed volume of the tet `(a, b, c, d)`: positive when `a` lies on the side of the
/// triangle `(b, c, d)` that its counter-clockwise normal points away from; the mesh orients
/// every tet so that its rest volume is positive.
#[inline]
pub fn signed_volume(p: &[Vec3; 4]) -> f32 {
    triple(p[0] - p[3], p[1] - p[3], p[2] - p[3]) * SIXTH
}

/// Gradients of [`signed_volume`] with respect to each vertex. They sum to zero, which is what
/// makes every volume impulse conserve momentum.
#[inline]
pub fn volume_gradients(p: &[Vec3; 4]) -> [Vec3; 4] {
    let (ea, eb, ec) = (p[0] - p[3], p[1] - p[3], p[2] - p[3]);
    let ga = eb.cross(ec) * SIXTH;
    let gb = ec.cross(ea) * SIXTH;
    let gc = ea.cross(eb) * SIXTH;
    [ga, gb, gc, -(ga + gb + gc)]
}

/// The smallest dihedral angle of the tet `p`, in degrees.
pub fn min_dihedral_deg(p: &[Vec3; 4]) -> f32 {
    let g = volume_gradients(p);
    let mut smallest = 180.0f32;
    // The face opposite vertex k has outward normal -g_k; the dihedral angle at the edge shared
    // by the faces opposite k and l is pi minus the angle between those normals.
    for k in 0..4 {
        for l in k + 1..4 {
            let cos = -g[k].normalize_or_zero().dot(g[l].normalize_or_zero());
            smallest = smallest.min(cos.clamp(-1.0, 1.0).acos().to_degrees());
        }
    }
    smallest
}

/// Coefficients of `V(s)`, the volume of the tet with vertices `p_i + s * d_i`.
/// A vertex that does not move has `d_i = 0`, which lowers the degree as the paper describes.
#[inline]
pub fn volume_polynomial(p: &[Vec3; 4], d: &[Vec3; 4]) -> Cubic {
    let (ea, eb, ec) = (p[0] - p[3], p[1] - p[3], p[2] - p[3]);
    let (fa, fb, fc) = (d[0] - d[3], d[1] - d[3], d[2] - d[3]);
    let c0 = triple(ea, eb, ec);
    let c1 = triple(fa, eb, ec) + triple(ea, fb, ec) + triple(ea, eb, fc);
    let c2 = triple(ea, fb, fc) + triple(fa, eb, fc) + triple(fa, fb, ec);
    let c3 = triple(fa, fb, fc);
    let sixth = 1.0 / 6.0;
    [
        c0 as f64 * sixth,
        c1 as f64 * sixth,
        c2 as f64 * sixth,
        c3 as f64 * sixth,
    ]
}

/// The linear, quadratic and cubic coefficients of [`volume_polynomial`], times 1, 6 and 6,
/// for four tets in SIMD lanes whose edge vectors `e = p_i - p_d` and gradients `g` of a, b and
/// c are already known, moving along edge directions `f = d_i - d_d`: the linear coefficient
/// then costs three dot products, and only the others need cross products. The volume passes
/// compute the edges and gradients anyway (for the volumes and directions), so this saves them
/// more than half the work of each polynomial. The constant coefficient is the volume.
#[inline(always)]
pub fn volume_polynomial_lanes(
    [ea, eb, ec]: [Vec3x4; 3],
    [ga, gb, gc]: [Vec3x4; 3],
    [fa, fb, fc]: [Vec3x4; 3],
) -> [f32x4; 3] {
    let c1 = ga.dot(fa) + gb.dot(fb) + gc.dot(fc);
    let fbc = fb.cross(fc);
    let c2 = ea.dot(fbc) + eb.dot(fc.cross(fa)) + ec.dot(fa.cross(fb));
    let c3 = fa.dot(fbc);
    [c1, c2, c3]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::roots::eval;

    fn rand_vec(seed: &mut u64) -> Vec3 {
        let mut next = || {
            *seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((*seed >> 40) as f32) / ((1u64 << 24) as f32) * 2.0 - 1.0
        };
        Vec3::new(next(), next(), next())
    }

    #[test]
    fn unit_tet_volume_and_gradients() {
        let p = [Vec3::X, Vec3::Y, Vec3::Z, Vec3::ZERO];
        assert!((signed_volume(&p) - 1.0 / 6.0).abs() < 1e-7);
        let g = volume_gradients(&p);
        let sum = g.iter().copied().sum::<Vec3>();
        assert!(sum.length() < 1e-7);
        // Moving a along its gradient grows the volume at the gradient's squared length.
        let eps = 1e-3;
        let mut q = p;
        q[0] += g[0] * eps;
        let dv = signed_volume(&q) - signed_volume(&p);
        assert!((dv - eps * g[0].length_squared()).abs() < 1e-6);
    }

    #[test]
    fn cubic_coefficients_match_direct_volume_evaluation() {
        let mut seed = 3;
        for _ in 0..500 {
            let p = [
                rand_vec(&mut seed),
                rand_vec(&mut seed),
                rand_vec(&mut seed),
                rand_vec(&mut seed),
            ];
            let mut d = [
                rand_vec(&mut seed),
                rand_vec(&mut seed),
                rand_vec(&mut seed),
                rand_vec(&mut seed),
            ];
            // Some vertices fixed, as for a neighbour that shares only part of its vertices.
            let fixed = (seed >> 20) as usize % 4;
            for v in d.iter_mut().take(fixed) {
                *v = Vec3::ZERO;
            }
            let c = volume_polynomial(&p, &d);
            let lanes = |v: [Vec3; 3]| v.map(Vec3x4::splat);
            let g = volume_gradients(&p);
            let [c1, c2, c3] = volume_polynomial_lanes(
                lanes([p[0] - p[3], p[1] - p[3], p[2] - p[3]]),
                lanes([g[0], g[1], g[2]]),
                lanes([d[0] - d[3], d[1] - d[3], d[2] - d[3]]),
            )
            .map(|c| c.to_array()[0] as f64);
            let from_gradients = [signed_volume(&p) as f64, c1, c2 / 6.0, c3 / 6.0];
            for (a, b) in c.iter().zip(&from_gradients) {
                assert!(
                    (a - b).abs() < 1e-5 * (1.0 + a.abs()),
                    "{c:?} vs {from_gradients:?}"
                );
            }
            if fixed == 3 {
                assert!(
                    c[2].abs() < 1e-6 && c[3].abs() < 1e-6,
                    "one moving vertex is linear"
                );
            }
            for s in [-1.5f32, -0.3, 0.0, 0.25, 0.7, 1.0, 2.0] {
                let moved = [
                    p[0] + d[0] * s,
                    p[1] + d[1] * s,
                    p[2] + d[2] * s,
                    p[3] + d[3] * s,
                ];
                let direct = signed_volume(&moved) as f64;
                let poly = eval(&c, s as f64);
                assert!(
                    (direct - poly).abs() < 1e-5 * (1.0 + direct.abs()),
                    "s={s}: {direct} vs {poly}"
                );
            }
        }
    }
}
