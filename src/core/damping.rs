//! Damping of a body as a whole, once a step in its first substep before the volume passes:
//! deformation damping (the mass-proportional half of Rayleigh damping, on the motion relative
//! to the body's rigid motion) and rolling resistance (what stops a body rocking or rolling on
//! what it rests on).
//!
//! The shape solve's damping is stiffness-proportional (`ElasticSettings::damping`): a mode of
//! angular frequency `w` gets the damping ratio `beta w / 2`, so a slow wobble of a long body
//! (a dragon's tail, a creature's neck) keeps swinging. Deformation damping at
//! rate `alpha` gives each mode `alpha / (2 w)` more, the slow ones most, as Rayleigh's
//! `alpha M + beta K` does; taken relative to the rigid motion, it leaves a body's flight and
//! spin alone and keeps its momentum and angular momentum (Müller et al. 2007, "Position Based
//! Dynamics", section 3.5, damps the same way). A stiff body resting on a curved underside
//! (a bunny, a creature on its side) rocks as a rigid body, which no internal damping touches;
//! a real one stops through the hysteresis of its contact patch, finer than the tets resolve,
//! which rolling resistance stands for: a torque `c N r` against the rolling, as for a wheel,
//! applied about the centre of mass (friction at the contact turns it into a slower roll).

use glam::{Mat3, Vec3};

use super::contacts::ContactState;
use super::material::SoftBodyMaterial;

/// The material's deformation damping and rolling resistance over a step of `h` for a body in
/// `gravity` whose particles are `(positions, velocities, masses, inv_masses)`; rolling is
/// resisted on the static colliders the substep's contacts touched (`contacts`). Before the
/// volume passes, which then restore what the damping took from a tet's volume.
pub(crate) fn damp_whole_body(
    material: &SoftBodyMaterial,
    gravity: Vec3,
    h: f32,
    (x, v, m, w): (&[Vec3], &mut [Vec3], &[f32], &[f32]),
    contacts: &ContactState,
) {
    let (alpha, rolling) = (material.deformation_damping, material.rolling_resistance);
    if alpha == 0.0 && rolling == 0.0 {
        return;
    }
    let Some(motion) = RigidMotion::of(x, v, m, w) else {
        return;
    };
    if alpha > 0.0 {
        motion.damp_deformation(x, v, w, alpha, h);
    }
    let resting = contacts.touching.iter().map(|&i| i as usize);
    let resting = resting.filter(|&i| contacts.anchors[i].is_finite());
    let resting = resting.map(|i| (i, contacts.normals[i]));
    motion.resist_rolling(x, v, m, w, resting, gravity, rolling, h);
}

/// Drag at `rate` (1/s, `SoftBodyMaterial::linear_damping`) over a substep of `h`: each free
/// particle keeps `1 / (1 + h rate)` of its velocity.
pub(crate) fn drag(velocities: &mut [Vec3], inv_masses: &[f32], rate: f32, h: f32) {
    if rate > 0.0 {
        let keep = 1.0 / (1.0 + h * rate);
        for (v, &w) in velocities.iter_mut().zip(inv_masses) {
            if w > 0.0 {
                *v *= keep;
            }
        }
    }
}

/// A body's rigid motion: the velocity field `velocity + spin x (x - centre)` closest to its
/// particles' velocities in the masses' norm (the free particles only; kinematic ones are
/// driven by the game).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct RigidMotion {
    /// Total mass of the free particles.
    pub(crate) mass: f32,
    /// Their centre of mass.
    pub(crate) centre: Vec3,
    /// Their centre of mass's velocity.
    pub(crate) velocity: Vec3,
    /// Their angular velocity.
    pub(crate) spin: Vec3,
    /// Their inertia tensor about `centre`.
    pub(crate) inertia: Mat3,
}

impl RigidMotion {
    /// The rigid motion of the particles of inverse mass `inv_masses > 0`; `None` if there are
    /// none or they lie on a line (no spin can be told).
    pub(crate) fn of(
        positions: &[Vec3],
        velocities: &[Vec3],
        masses: &[f32],
        inv_masses: &[f32],
    ) -> Option<RigidMotion> {
        let free = || {
            positions
                .iter()
                .zip(velocities)
                .zip(masses.iter().zip(inv_masses))
                .filter(|(_, (_, w))| **w > 0.0)
                .map(|((x, v), (m, _))| (*x, *v, *m))
        };
        let (mut mass, mut moment, mut momentum) = (0.0f32, Vec3::ZERO, Vec3::ZERO);
        for (x, v, m) in free() {
            mass += m;
            moment += m * x;
            momentum += m * v;
        }
        if mass <= 0.0 {
            return None;
        }
        let (centre, velocity) = (moment / mass, momentum / mass);
        let (mut angular, mut inertia) = (Vec3::ZERO, Mat3::ZERO);
        for (x, v, m) in free() {
            let r = x - centre;
            angular += m * r.cross(v - velocity);
            inertia += m
                * (Mat3::from_diagonal(Vec3::splat(r.length_squared()))
                    - Mat3::from_cols(r * r.x, r * r.y, r * r.z));
        }
        // A tensor this small against the body's own size has no inverse worth the name.
        let size = inertia.x_axis.x + inertia.y_axis.y + inertia.z_axis.z;
        if inertia.determinant().abs() <= (1e-6 * size).powi(3) || !size.is_finite() {
            return None;
        }
        let spin = inertia.inverse() * angular;
        spin.is_finite().then_some(RigidMotion {
            mass,
            centre,
            velocity,
            spin,
            inertia,
        })
    }

    /// The rigid motion's velocity at `x`.
    pub(crate) fn velocity_at(&self, x: Vec3) -> Vec3 {
        self.velocity + self.spin.cross(x - self.centre)
    }

    /// Deformation damping over `h` seconds at `rate` (1/s): each free particle's velocity
    /// relative to the rigid motion is scaled by `exp(-rate h)`. The rigid motion, and so the
    /// momentum and angular momentum, are kept.
    pub(crate) fn damp_deformation(
        &self,
        positions: &[Vec3],
        velocities: &mut [Vec3],
        inv_masses: &[f32],
        rate: f32,
        h: f32,
    ) {
        let keep = (-rate * h).exp();
        for ((&x, v), &w) in positions.iter().zip(velocities.iter_mut()).zip(inv_masses) {
            if w > 0.0 {
                let rigid = self.velocity_at(x);
                *v = rigid + (*v - rigid) * keep;
            }
        }
    }

    /// Rolling resistance over `h` seconds for a body resting on static colliders: the
    /// particles in `resting` (each with the outward normal of what it touches) are where it
    /// touches them.
    /// The spin about axes across their mean normal `n` is slowed by the torque
    /// `coefficient * N * r` (`N` the body's weight along `n` in `gravity`, `r` the distance of
    /// its centre of mass from the contacts' centre `p` across the axis, the body turning about
    /// `p`) until it stops. The torque acts about the centre of mass, so it changes no momentum:
    /// friction at the contact turns it into the slowing of a roll, and on ice the body only
    /// stops turning. A spin about `n` itself (a top) is not rolling and is left alone.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn resist_rolling(
        &self,
        positions: &[Vec3],
        velocities: &mut [Vec3],
        masses: &[f32],
        inv_masses: &[f32],
        resting: impl Iterator<Item = (usize, Vec3)>,
        gravity: Vec3,
        coefficient: f32,
        h: f32,
    ) {
        let (mut touch_mass, mut touch_moment, mut normal) = (0.0f32, Vec3::ZERO, Vec3::ZERO);
        for (i, n) in resting {
            touch_mass += masses[i];
            touch_moment += masses[i] * positions[i];
            normal += masses[i] * n;
        }
        let Some(n) = normal.try_normalize() else {
            return;
        };
        let support = -gravity.dot(n);
        let across = self.spin - n * self.spin.dot(n);
        let rate = across.length();
        if touch_mass <= 0.0 || support <= 0.0 || rate == 0.0 {
            return;
        }
        let pivot = touch_moment / touch_mass;
        let axis = across / rate;
        let lever = self.centre - pivot;
        let lever = (lever - axis * lever.dot(axis)).length();
        let inertia = axis.dot(self.inertia * axis) + self.mass * lever * lever;
        let slowing = coefficient * self.mass * support * lever / inertia;
        let cut = axis * (slowing * h).min(rate);
        for ((&x, v), &w) in positions.iter().zip(velocities.iter_mut()).zip(inv_masses) {
            if w > 0.0 {
                *v -= cut.cross(x - self.centre);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Eight particles at a cube's corners.
    fn cube() -> Vec<Vec3> {
        (0..8)
            .map(|k| Vec3::new((k & 1) as f32, (k >> 1 & 1) as f32, (k >> 2) as f32) - 0.5)
            .collect()
    }

    /// A spinning, flying body that also breathes: the breathing dies, the flight and spin
    /// (momentum and angular momentum) stay.
    #[test]
    fn deformation_damping_keeps_the_rigid_motion() {
        let x = cube();
        let masses: Vec<f32> = (0..8).map(|k| 1.0 + k as f32 * 0.25).collect();
        let w: Vec<f32> = masses.iter().map(|m| 1.0 / m).collect();
        let (flight, spin) = (Vec3::new(1.0, 2.0, -0.5), Vec3::new(0.3, -1.0, 2.0));
        let mut v: Vec<Vec3> = x
            .iter()
            .map(|&p| flight + spin.cross(p) + 0.7 * p)
            .collect();
        let before = RigidMotion::of(&x, &v, &masses, &w).unwrap();
        let deformation = |v: &[Vec3], motion: &RigidMotion| -> Vec<Vec3> {
            x.iter()
                .zip(v)
                .map(|(p, v)| *v - motion.velocity_at(*p))
                .collect()
        };
        let breathing = deformation(&v, &before);
        assert!(breathing.iter().all(|b| b.length() > 0.1));
        before.damp_deformation(&x, &mut v, &w, 5.0, 1.0);
        let after = RigidMotion::of(&x, &v, &masses, &w).unwrap();
        assert!((after.velocity - before.velocity).length() < 1e-5);
        let momentum = |v: &[Vec3]| v.iter().zip(&masses).map(|(v, m)| *v * *m).sum::<Vec3>();
        assert!((momentum(&v) - before.mass * before.velocity).length() < 1e-4);
        assert!((after.spin - before.spin).length() < 1e-4, "{}", after.spin);
        for (left, was) in deformation(&v, &after).iter().zip(&breathing) {
            assert!(
                (*left - *was * (-5.0f32).exp()).length() < 1e-5,
                "{left} {was}"
            );
        }
    }

    /// A body rocking on the ground stops rocking, its momentum kept (the torque acts about the
    /// centre of mass); a spin about the normal (a top) is left alone.
    #[test]
    fn rolling_resistance_stops_a_rocking_body_not_a_spinning_one() {
        let x: Vec<Vec3> = cube().iter().map(|p| *p + Vec3::Y * 0.5).collect();
        let masses = vec![1.0; 8];
        let w = vec![1.0; 8];
        let gravity = Vec3::new(0.0, -9.81, 0.0);
        let resting = || (0..8).filter(|&i| x[i].y == 0.0).map(|i| (i, Vec3::Y));
        let rocking = Vec3::Z * 0.5;
        let mut v: Vec<Vec3> = x.iter().map(|p| rocking.cross(*p)).collect();
        let mut steps = 0;
        while RigidMotion::of(&x, &v, &masses, &w).unwrap().spin.length() > 1e-6 {
            let motion = RigidMotion::of(&x, &v, &masses, &w).unwrap();
            motion.resist_rolling(&x, &mut v, &masses, &w, resting(), gravity, 0.1, 1.0 / 60.0);
            steps += 1;
            assert!(steps < 120, "still rocking after two seconds");
        }
        let motion = RigidMotion::of(&x, &v, &masses, &w).unwrap();
        let rocking_velocity = rocking.cross(Vec3::Y * 0.5);
        assert!((motion.velocity - rocking_velocity).length() < 1e-5);
        let spinning = Vec3::Y * 2.0;
        let mut v: Vec<Vec3> = x.iter().map(|p| spinning.cross(*p)).collect();
        let motion = RigidMotion::of(&x, &v, &masses, &w).unwrap();
        let before = v.clone();
        motion.resist_rolling(&x, &mut v, &masses, &w, resting(), gravity, 0.1, 1.0 / 60.0);
        assert_eq!(v, before);
    }
}
