//! Four tets at a time: 3-vectors whose components are SIMD lanes (`wide::f32x4`, SSE on any
//! x86-64, NEON on aarch64, plain arrays elsewhere), for the arithmetic of the one-ring impulse.
//!
//! Every operation is the one glam's scalar `Vec3` does, in the same order (no fused
//! multiply-add), so a lane holds bit for bit what the scalar code computes for its tet: the
//! results of the volume passes do not depend on whether they run in lanes.

use glam::Vec3;
use wide::f32x4;

/// A position kept as four numbers (the fourth unused), sixteen bytes aligned: four of them
/// go into lanes with one load each and a transpose ([`Vec3x4::gather_points`]), and a load
/// never reaches into the next particle.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(16))]
pub struct Point4([f32; 4]);

impl Point4 {
    /// The position `v`.
    #[inline(always)]
    pub fn new(v: Vec3) -> Point4 {
        Point4([v.x, v.y, v.z, 0.0])
    }

    /// The position as a `Vec3`.
    #[inline(always)]
    pub fn vec3(self) -> Vec3 {
        Vec3::new(self.0[0], self.0[1], self.0[2])
    }

    /// The four numbers in lanes.
    #[inline(always)]
    pub fn row(self) -> f32x4 {
        f32x4::new(self.0)
    }
}

/// Number of tets handled together.
pub const LANES: usize = 4;

/// Four 3-vectors, one per lane, stored by component.
#[derive(Clone, Copy, Debug, Default)]
pub struct Vec3x4 {
    /// The x components.
    pub x: f32x4,
    /// The y components.
    pub y: f32x4,
    /// The z components.
    pub z: f32x4,
}

impl Vec3x4 {
    /// All lanes zero.
    pub const ZERO: Vec3x4 = Vec3x4 {
        x: f32x4::ZERO,
        y: f32x4::ZERO,
        z: f32x4::ZERO,
    };

    /// `v` in every lane.
    #[inline(always)]
    pub fn splat(v: Vec3) -> Vec3x4 {
        Vec3x4 {
            x: f32x4::splat(v.x),
            y: f32x4::splat(v.y),
            z: f32x4::splat(v.z),
        }
    }

    /// The four vectors `v`, lane `l` holding `v[l]`.
    #[inline(always)]
    pub fn from_vecs(v: [Vec3; LANES]) -> Vec3x4 {
        Vec3x4 {
            x: f32x4::new([v[0].x, v[1].x, v[2].x, v[3].x]),
            y: f32x4::new([v[0].y, v[1].y, v[2].y, v[3].y]),
            z: f32x4::new([v[0].z, v[1].z, v[2].z, v[3].z]),
        }
    }

    /// The four vectors, lane by lane.
    #[inline(always)]
    pub fn to_vecs(self) -> [Vec3; LANES] {
        let (x, y, z) = (self.x.to_array(), self.y.to_array(), self.z.to_array());
        std::array::from_fn(|l| Vec3::new(x[l], y[l], z[l]))
    }

    /// `values[at[l]]` in lane `l`, each read as four numbers (the vector and the next one's
    /// `x`, dropped) and the four transposed: four loads and a few shuffles, where gathering
    /// component by component takes twelve loads and as many shuffles. `values` needs one
    /// vector more than the indices reach (the last index read is `values.len() - 2`).
    #[inline(always)]
    pub fn gather_padded(values: &[Vec3], at: [usize; LANES]) -> Vec3x4 {
        // SAFETY: `Vec3` is `repr(C)`, three `f32` and no padding (size 12, align 4), so the
        // vectors are `3 * len` numbers one after another.
        let flat: &[f32] =
            unsafe { std::slice::from_raw_parts(values.as_ptr().cast::<f32>(), 3 * values.len()) };
        Vec3x4::from_rows(at.map(|i| {
            let four: [f32; 4] = flat[3 * i..3 * i + 4].try_into().expect("four numbers");
            f32x4::new(four)
        }))
    }

    /// The positions `points[at[l]]` in lane `l`: four loads and a transpose.
    #[inline(always)]
    pub fn gather_points(points: &[Point4], at: [usize; LANES]) -> Vec3x4 {
        Vec3x4::from_rows(at.map(|i| points[i].row()))
    }

    /// Lane `l` from the first three numbers of `rows[l]` ([`Point4::row`]).
    #[inline(always)]
    pub fn from_rows(rows: [f32x4; LANES]) -> Vec3x4 {
        let [x, y, z, _] = f32x4::transpose(rows);
        Vec3x4 { x, y, z }
    }

    /// Cross product per lane, as [`Vec3::cross`].
    #[inline(always)]
    pub fn cross(self, rhs: Vec3x4) -> Vec3x4 {
        Vec3x4 {
            x: self.y * rhs.z - rhs.y * self.z,
            y: self.z * rhs.x - rhs.z * self.x,
            z: self.x * rhs.y - rhs.x * self.y,
        }
    }

    /// Dot product per lane, as [`Vec3::dot`].
    #[inline(always)]
    pub fn dot(self, rhs: Vec3x4) -> f32x4 {
        (self.x * rhs.x) + (self.y * rhs.y) + (self.z * rhs.z)
    }

    /// Squared length per lane, as [`Vec3::length_squared`].
    #[inline(always)]
    pub fn length_squared(self) -> f32x4 {
        self.dot(self)
    }

    /// Each lane scaled by its own factor, as `Vec3 * f32`.
    #[inline(always)]
    pub fn scale(self, s: f32x4) -> Vec3x4 {
        Vec3x4 {
            x: self.x * s,
            y: self.y * s,
            z: self.z * s,
        }
    }
}

impl std::ops::Add for Vec3x4 {
    type Output = Vec3x4;
    #[inline(always)]
    fn add(self, rhs: Vec3x4) -> Vec3x4 {
        Vec3x4 {
            x: self.x + rhs.x,
            y: self.y + rhs.y,
            z: self.z + rhs.z,
        }
    }
}

impl std::ops::Sub for Vec3x4 {
    type Output = Vec3x4;
    #[inline(always)]
    fn sub(self, rhs: Vec3x4) -> Vec3x4 {
        Vec3x4 {
            x: self.x - rhs.x,
            y: self.y - rhs.y,
            z: self.z - rhs.z,
        }
    }
}

impl std::ops::Neg for Vec3x4 {
    type Output = Vec3x4;
    #[inline(always)]
    fn neg(self) -> Vec3x4 {
        Vec3x4 {
            x: -self.x,
            y: -self.y,
            z: -self.z,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vecs(seed: f32) -> [Vec3; LANES] {
        std::array::from_fn(|l| {
            let s = seed + l as f32;
            Vec3::new(
                s.sin() * 3.1,
                (1.7 * s).cos() - 0.2,
                (0.3 * s).sin() * 1e-3 + s,
            )
        })
    }

    #[test]
    fn lanes_compute_bit_for_bit_what_glam_computes() {
        let (a, b) = (vecs(0.37), vecs(5.2));
        let (la, lb) = (Vec3x4::from_vecs(a), Vec3x4::from_vecs(b));
        let cross = la.cross(lb).to_vecs();
        let dot = la.dot(lb).to_array();
        let sum = (la + lb).to_vecs();
        let diff = (la - lb).to_vecs();
        let neg = (-la).to_vecs();
        let scaled = la.scale(lb.y).to_vecs();
        for l in 0..LANES {
            assert_eq!(cross[l], a[l].cross(b[l]));
            assert_eq!(dot[l].to_bits(), a[l].dot(b[l]).to_bits());
            assert_eq!(sum[l], a[l] + b[l]);
            assert_eq!(diff[l], a[l] - b[l]);
            assert_eq!(neg[l], -a[l]);
            assert_eq!(scaled[l], a[l] * b[l].y);
        }
    }

    #[test]
    fn point_gather_reads_the_points_asked_for() {
        let values: Vec<Vec3> = (0..9).map(|k| vecs(k as f32)[k % LANES]).collect();
        let points: Vec<Point4> = values.iter().map(|&v| Point4::new(v)).collect();
        let at = [7, 0, 3, 8];
        let lanes = Vec3x4::gather_points(&points, at).to_vecs();
        for l in 0..LANES {
            assert_eq!(lanes[l], values[at[l]]);
            assert_eq!(points[at[l]].vec3(), values[at[l]]);
        }
    }

    #[test]
    fn padded_gather_reads_the_vectors_asked_for() {
        let mut values: Vec<Vec3> = (0..9).map(|k| vecs(k as f32)[k % LANES]).collect();
        values.push(Vec3::NAN);
        let at = [7, 0, 3, 8];
        let lanes = Vec3x4::gather_padded(&values, at).to_vecs();
        for l in 0..LANES {
            assert_eq!(lanes[l], values[at[l]]);
        }
    }
}
