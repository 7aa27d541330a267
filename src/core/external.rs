//! What a game does to a body from outside the step: impulses (a punch, a kick, an
//! explosion) and forces (wind, a thruster), on the whole body or at a point of it, as the
//! rigid-body engines offer them (avian's `apply_linear_impulse_at_point`, rapier's
//! `apply_impulse_at_point`).
//!
//! A point of a body is a [`BodyPoint`]: a tet and the point's barycentric weights in it, so
//! that a force bound to a point follows the material as the body deforms. An impulse `J` at a
//! point gives each of the tet's particles the impulse `w_k J`: the body's linear momentum
//! changes by `J` and its angular momentum by `p x J` (`p = sum w_k x_k`), exactly, whatever
//! the masses of the four particles.

use glam::{Mat3, Vec3};

use super::body::SoftBodyState;

/// A point of a body's material: tet `tet` and the weights of its four corners (non-negative,
/// summing to one). Where it is now: [`SoftBodyState::point_position`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyPoint {
    /// The tet.
    pub tet: u32,
    /// The barycentric weights of its corners.
    pub weights: [f32; 4],
}

impl SoftBodyState {
    /// The point of the body at `world` now: in the tet that contains it, or, for a point
    /// outside the body, the nearest point of the tet it is least outside of (its weights
    /// clamped to the tet). `None` for a body of no tets with volume.
    pub fn body_point(&self, world: Vec3) -> Option<BodyPoint> {
        let mut best: Option<(f32, BodyPoint)> = None;
        for (t, tet) in self.mesh.tets().iter().enumerate() {
            let x = tet.map(|i| self.positions[i as usize]);
            let edges = Mat3::from_cols(x[1] - x[0], x[2] - x[0], x[3] - x[0]);
            let det = edges.determinant();
            if det.abs() <= f32::EPSILON * edges.col(0).length_squared().powf(1.5) {
                continue;
            }
            let l = edges.inverse() * (world - x[0]);
            let weights = [1.0 - l.x - l.y - l.z, l.x, l.y, l.z];
            let inside = weights.iter().copied().fold(f32::INFINITY, f32::min);
            if best.is_none_or(|(b, _)| inside > b) {
                let point = BodyPoint {
                    tet: t as u32,
                    weights,
                };
                best = Some((inside, point));
                if inside >= 0.0 {
                    break;
                }
            }
        }
        let (_, mut point) = best?;
        let clamped = point.weights.map(|w| w.max(0.0));
        let sum: f32 = clamped.iter().sum();
        point.weights = clamped.map(|w| w / sum);
        Some(point)
    }

    /// Where `point` of the body is now.
    pub fn point_position(&self, point: BodyPoint) -> Vec3 {
        let tet = self.mesh.tets()[point.tet as usize];
        (0..4)
            .map(|k| point.weights[k] * self.positions[tet[k] as usize])
            .sum()
    }

    /// Gives the whole body the impulse `impulse` (N s): every particle's velocity changes by
    /// `impulse / M`. Wakes the body.
    pub fn apply_impulse(&mut self, impulse: Vec3) {
        let mass: f32 = self.masses.iter().sum();
        let dv = impulse / mass;
        self.wake_up();
        for (v, &w) in self.velocities.iter_mut().zip(&self.inv_masses) {
            if w > 0.0 {
                *v += dv;
            }
        }
    }

    /// Gives the body the impulse `impulse` (N s) at `point`: its four particles take `w_k J`
    /// each. Wakes the body. A kinematic particle takes none of it.
    pub fn apply_impulse_at(&mut self, point: BodyPoint, impulse: Vec3) {
        let tet = self.mesh.tets()[point.tet as usize];
        self.wake_up();
        for (k, &i) in tet.iter().enumerate() {
            let i = i as usize;
            self.velocities[i] += point.weights[k] * impulse * self.inv_masses[i];
        }
    }

    /// An explosion at `centre`: every particle within `radius` takes an impulse away from the
    /// centre of `impulse * (1 - d / radius)` times its share of the body's mass (`d` its
    /// distance), so that a body at the centre takes about `impulse` (N s) in all and a body at
    /// the edge nothing. Returns whether it touched the body (which then wakes).
    pub fn apply_radial_impulse(&mut self, centre: Vec3, radius: f32, impulse: f32) -> bool {
        if !(radius > 0.0 && impulse.is_finite()) {
            return false;
        }
        let within = |x: Vec3| x.distance_squared(centre) < radius * radius;
        if !self.positions.iter().copied().any(within) {
            return false;
        }
        let mass: f32 = self.masses.iter().sum();
        self.wake_up();
        for ((x, v), &w) in self
            .positions
            .iter()
            .zip(&mut self.velocities)
            .zip(&self.inv_masses)
        {
            let d = x.distance(centre);
            if d >= radius || w == 0.0 {
                continue;
            }
            let away = (*x - centre).try_normalize().unwrap_or(Vec3::Y);
            *v += away * (impulse * (1.0 - d / radius) / mass);
        }
        true
    }
}
