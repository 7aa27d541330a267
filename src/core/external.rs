//! What a game does to a body from outside the step: impulses (a punch, a kick, an
//! explosion), forces (wind, a thruster) and grabs, on the whole body or at a point of it, as
//! the rigid-body engines offer them (avian's `Forces`, rapier's `apply_impulse_at_point`).
//! The body lends its particles for them
//! ([`SoftBodyState::forces`](super::SoftBodyState::forces) gives a [`BodyForces`]).
//!
//! A point of a body is a [`BodyPoint`]: a tet and the point's barycentric weights in it, so
//! that a force bound to a point follows the material as the body deforms. An impulse `J` at a
//! point gives each of the tet's particles the impulse `w_k J`: the body's linear momentum
//! changes by `J` and its angular momentum by `p x J` (`p = sum w_k x_k`), exactly, whatever
//! the masses of the four particles.

use glam::{Mat3, Vec3};

use super::sleep::Sleep;
use super::tet_mesh::TetMesh;

/// A point of a body's material: tet `tet` and the weights of its four corners (non-negative,
/// summing to one). Where it is now: [`SoftBodyState::point_position`](super::SoftBodyState::point_position).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyPoint {
    /// The tet.
    pub tet: u32,
    /// The barycentric weights of its corners.
    pub weights: [f32; 4],
}

/// The point of the body of `mesh` at `positions` at `world` (see
/// [`SoftBodyState::body_point`](super::SoftBodyState::body_point)).
pub(crate) fn body_point(mesh: &TetMesh, positions: &[Vec3], world: Vec3) -> Option<BodyPoint> {
    let mut best: Option<(f32, BodyPoint)> = None;
    for (t, tet) in mesh.tets().iter().enumerate() {
        let x = tet.map(|i| positions[i as usize]);
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

/// Where `point` of the body of `mesh` at `positions` is.
pub(crate) fn point_position(mesh: &TetMesh, positions: &[Vec3], point: BodyPoint) -> Vec3 {
    let tet = mesh.tets()[point.tet as usize];
    (0..4)
        .map(|k| point.weights[k] * positions[tet[k] as usize])
        .sum()
}

/// A body's particles lent for the game's impulses, forces and grabs
/// ([`SoftBodyState::forces`](super::SoftBodyState::forces)). Each call that changes a
/// velocity wakes the body. Kinematic particles take none of it.
pub struct BodyForces<'a> {
    pub(crate) mesh: &'a TetMesh,
    pub(crate) positions: &'a [Vec3],
    pub(crate) velocities: &'a mut [Vec3],
    pub(crate) masses: &'a [f32],
    pub(crate) inv_masses: &'a [f32],
    pub(crate) sleep: &'a mut Sleep,
}

impl BodyForces<'_> {
    /// Gives the whole body the impulse `impulse` (N s): every particle's velocity changes by
    /// `impulse / M`.
    pub fn apply_impulse(&mut self, impulse: Vec3) {
        let mass: f32 = self.masses.iter().sum();
        let dv = impulse / mass;
        self.sleep.wake();
        for (v, &w) in self.velocities.iter_mut().zip(self.inv_masses) {
            if w > 0.0 {
                *v += dv;
            }
        }
    }

    /// Gives the body the impulse `impulse` (N s) at `point`: its four particles take `w_k J`
    /// each.
    pub fn apply_impulse_at(&mut self, point: BodyPoint, impulse: Vec3) {
        let tet = self.mesh.tets()[point.tet as usize];
        self.sleep.wake();
        for (k, &i) in tet.iter().enumerate() {
            let i = i as usize;
            self.velocities[i] += point.weights[k] * impulse * self.inv_masses[i];
        }
    }

    /// An explosion at `centre`: every particle within `radius` takes an impulse away from the
    /// centre of `impulse * (1 - d / radius)` times its share of the body's mass (`d` its
    /// distance), so that a body at the centre takes about `impulse` (N s) in all and a body at
    /// the edge nothing. Returns whether it touched the body.
    pub fn apply_radial_impulse(&mut self, centre: Vec3, radius: f32, impulse: f32) -> bool {
        if !(radius > 0.0 && impulse.is_finite()) {
            return false;
        }
        let within = |x: Vec3| x.distance_squared(centre) < radius * radius;
        if !self.positions.iter().copied().any(within) {
            return false;
        }
        let mass: f32 = self.masses.iter().sum();
        self.sleep.wake();
        let particles = self.positions.iter().zip(self.velocities.iter_mut());
        for ((x, v), &w) in particles.zip(self.inv_masses) {
            let d = x.distance(centre);
            if d >= radius || w == 0.0 {
                continue;
            }
            let away = (*x - centre).try_normalize().unwrap_or(Vec3::Y);
            *v += away * (impulse * (1.0 - d / radius) / mass);
        }
        true
    }

    /// The particles a grab at `point` (world) holds: those within `radius` of it, each
    /// weighted by `1 - d / radius`, or the nearest particle alone if none is within it.
    /// Kinematic particles are left out. Empty for a body without free particles.
    pub fn grab_patch(&self, point: Vec3, radius: f32) -> Vec<(u32, f32)> {
        let free = |i: &usize| self.inv_masses[*i] > 0.0;
        let mut patch: Vec<(u32, f32)> = (0..self.positions.len())
            .filter(free)
            .filter_map(|i| {
                let d = self.positions[i].distance(point);
                (d < radius).then(|| (i as u32, 1.0 - d / radius))
            })
            .collect();
        if patch.is_empty() {
            let nearest = (0..self.positions.len()).filter(free).min_by(|&a, &b| {
                let (da, db) = (self.positions[a], self.positions[b]);
                da.distance_squared(point)
                    .total_cmp(&db.distance_squared(point))
            });
            patch.extend(nearest.map(|i| (i as u32, 1.0)));
        }
        patch
    }

    /// Where a grab's `patch` ([`BodyForces::grab_patch`]) is now and how fast it moves: its
    /// particles' mean, weighted by their weights and masses.
    pub fn patch_motion(&self, patch: &[(u32, f32)]) -> (Vec3, Vec3) {
        let (mut x, mut v, mut sum) = (Vec3::ZERO, Vec3::ZERO, 0.0);
        for &(i, w) in patch {
            let wm = w * self.masses[i as usize];
            x += wm * self.positions[i as usize];
            v += wm * self.velocities[i as usize];
            sum += wm;
        }
        (x / sum, v / sum)
    }

    /// Pulls a grab's `patch` toward `target` for a step of `h` with a spring `[stiffness
    /// (N/m), damping (N s/m)]` on the whole body, at most `max_force` (N), as a hand does.
    /// The spring is integrated implicitly (backward Euler) for the body's mass, so it never
    /// overshoots however stiff; its impulse is shared by the patch's particles by their
    /// weights, and the patch is never given more speed than takes it to the target within
    /// the step, so that a heavy body on a stiff spring follows over several steps rather than
    /// having its grabbed part flung ahead.
    pub fn pull_patch(
        &mut self,
        patch: &[(u32, f32)],
        target: Vec3,
        spring: [f32; 2],
        max_force: f32,
        h: f32,
    ) {
        let [k, c] = spring;
        let valid = |&(i, w): &(u32, f32)| (i as usize) < self.positions.len() && w > 0.0;
        if patch.is_empty()
            || !patch.iter().all(valid)
            || !(k >= 0.0 && c >= 0.0 && max_force >= 0.0 && target.is_finite())
        {
            return;
        }
        let (x, v) = self.patch_motion(patch);
        let mass: f32 = self.masses.iter().sum();
        let v_next = (v + (h / mass) * k * (target - x)) / (1.0 + h * c / mass + h * h * k / mass);
        let impulse = (mass * (v_next - v)).clamp_length_max(max_force * h);
        let weighted_mass: f32 = patch
            .iter()
            .map(|&(i, w)| w * self.masses[i as usize])
            .sum();
        let reach = ((target - x) / h - v).length();
        let fastest = impulse.length() / weighted_mass;
        let scale = if fastest > reach {
            reach / fastest
        } else {
            1.0
        };
        self.sleep.wake();
        for &(i, w) in patch {
            self.velocities[i as usize] += impulse * (scale * w / weighted_mass);
        }
    }
}
