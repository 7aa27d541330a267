//! The paper's volume impulses written plainly, as the oracle of the fast passes: the
//! one-ring correction of section 5 and the per-tet correction of section 4 with its neighbour
//! clamp, one vertex and one tet after another, every cubic summed and solved in `f64`, with
//! none of the fast path's machinery (no clamp bounds, no ring checks, no SIMD lanes, no
//! shortcuts in the root search). It is slow: the clamp solves the cubic of every tet an
//! impulse touches. Tests hold `one_ring_impulses` and `per_tet_impulses` to it.
//!
//! Where the paper leaves a choice open, this is the crate's choice, the same as the fast
//! path's, each named where the fast path documents it: the tolerances below which a ring or
//! a tet needs no impulse ([`ImpulseSettings::tolerance`]), the ring step limit
//! ([`RING_STEP_LIMIT`]), the root a step may use (the one reached while the volume moves
//! monotonically towards its rest value, [`super::roots::monotone_root`]), directions reduced
//! where a particle presses into a contact, and the clamp's floor (`clamp_floor`). The
//! volumes are rounded as the fast passes round them (`f32`, from a ring's centre), since a
//! ring's error is a small difference of large volumes. The paper fixes no order of the
//! vertices and tets: this one takes them in the order the fast passes do (the mesh's
//! [`Blocks`]), so that the two can be compared.
//!
//! [`Blocks`]: super::tet_mesh::Blocks

use glam::{DVec3, Vec3};

use super::blocks::NO_TET;
use super::body::SoftBodyState;
use super::colliders::RigidSphereState;
use super::geometry::{SIXTH, signed_volume};
use super::impulses::{INVERTED_TET_GAMMA, RING_STEP_LIMIT, clamp_floor, constrained_push};
use super::material::{ImpulseSettings, VolumeMethod};
use super::roots::Cubic;

/// A tet's signed volume, `(x_a - x_d) . grad_a`, in `f32` from its last corner (see the
/// module's doc).
fn volume(p: [Vec3; 4]) -> f32 {
    (p[0] - p[3]).dot(gradients(p)[0])
}

/// The gradients of [`volume`] by corner.
fn gradients(p: [Vec3; 4]) -> [Vec3; 4] {
    let (a, b, c) = (p[0] - p[3], p[1] - p[3], p[2] - p[3]);
    let ga = b.cross(c) * SIXTH;
    let gb = c.cross(a) * SIXTH;
    let gc = a.cross(b) * SIXTH;
    [ga, gb, gc, -(ga + gb + gc)]
}

/// The volume of a tet whose corners move from `p` to `p + s d`, as a cubic in `s` (the
/// paper's expansion of the determinant; `[u, v, w] = u . (v x w)`).
fn moved_volume(p: [Vec3; 4], d: [Vec3; 4]) -> Cubic {
    let e = [0, 1, 2].map(|j| (p[j] - p[3]).as_dvec3());
    let f = [0, 1, 2].map(|j| (d[j] - d[3]).as_dvec3());
    let t = |u: DVec3, v: DVec3, w: DVec3| u.dot(v.cross(w));
    let [ea, eb, ec] = e;
    let [fa, fb, fc] = f;
    [
        t(ea, eb, ec) / 6.0,
        (t(fa, eb, ec) + t(ea, fb, ec) + t(ea, eb, fc)) / 6.0,
        (t(ea, fb, fc) + t(fa, eb, fc) + t(fa, fb, ec)) / 6.0,
        t(fa, fb, fc) / 6.0,
    ]
}

fn eval(c: &Cubic, s: f64) -> f64 {
    c[0] + s * (c[1] + s * (c[2] + s * c[3]))
}

/// The zeros of the derivative of `c` in `(0, hi)`, sorted: `c` is monotone between them.
fn turning_points(c: &Cubic, hi: f64) -> Vec<f64> {
    let (a, b, k) = (3.0 * c[3], 2.0 * c[2], c[1]);
    let mut points = Vec::new();
    if a == 0.0 {
        if b != 0.0 {
            points.push(-k / b);
        }
    } else {
        let disc = b * b - 4.0 * a * k;
        if disc >= 0.0 {
            let r = disc.sqrt();
            points.push((-b - r) / (2.0 * a));
            points.push((-b + r) / (2.0 * a));
        }
    }
    points.retain(|&s| s > 0.0 && s < hi);
    points.sort_by(f64::total_cmp);
    points
}

/// The zero of `c` in `[lo, hi]`, where `c` is monotone and changes sign, by bisection to the
/// last bit.
fn bisect(c: &Cubic, mut lo: f64, mut hi: f64) -> f64 {
    let low_sign = eval(c, lo) > 0.0;
    loop {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            return mid;
        }
        let v = eval(c, mid);
        if v == 0.0 {
            return mid;
        }
        if (v > 0.0) == low_sign {
            lo = mid;
        } else {
            hi = mid;
        }
    }
}

/// The step an impulse may use: the zero of `c` reached from `s = 0` while `c` moves
/// monotonically towards it (`c(0)` and `c'(0)` of opposite signs, no turning point before
/// the zero); `None` if there is none.
fn monotone_root(c: &Cubic) -> Option<f64> {
    if !c.iter().all(|x| x.is_finite()) || c[0] == 0.0 || c[1] == 0.0 {
        return None;
    }
    if (c[0] > 0.0) == (c[1] > 0.0) {
        return None;
    }
    // Past every zero: Cauchy's bound on the roots' size.
    let degree = (1..4).rev().find(|&i| c[i] != 0.0)?;
    let bound = 1.0
        + (0..degree)
            .map(|i| (c[i] / c[degree]).abs())
            .fold(0.0, f64::max);
    let end = turning_points(c, bound).first().copied().unwrap_or(bound);
    let at_end = eval(c, end);
    if at_end == 0.0 {
        return Some(end);
    }
    ((at_end > 0.0) != (c[0] > 0.0)).then(|| bisect(c, 0.0, end))
}

/// The first `s` in `[0, hi]` at which `c`, not negative at zero, becomes negative: `0` if it
/// decreases from a zero at once, `None` if it stays at or above zero up to `hi`.
fn first_below_zero(c: &Cubic, hi: f64) -> Option<f64> {
    if c[0] == 0.0 {
        // The sign just after zero is that of the first coefficient that is not zero.
        match c[1..].iter().find(|&&x| x != 0.0) {
            Some(&x) if x < 0.0 => return Some(0.0),
            None => return None,
            _ => {}
        }
    }
    let mut lo = 0.0;
    for end in turning_points(c, hi).into_iter().chain([hi]) {
        if eval(c, end) < 0.0 {
            return Some(if eval(c, lo) > 0.0 {
                bisect(c, lo, end)
            } else {
                lo
            });
        }
        lo = end;
    }
    None
}

/// A reference pass's working state: its step, the predicted positions it moves along with the
/// velocities, and the spheres' velocity changes, added to the spheres at its end.
struct Pass<'a> {
    h: f32,
    /// The predicted positions `x + h v`, moved along with every velocity change.
    predicted: Vec<Vec3>,
    sphere_dv: &'a mut [Vec3],
}

impl SoftBodyState {
    /// Section 5: the one-ring impulse of every vertex in turn, over a step (or substep) of
    /// `h`. `spheres` as for [`SoftBodyState::one_ring_impulses`]. Does nothing unless the body's
    /// method is the paper's with its one-ring pass on.
    pub(crate) fn reference_one_ring_pass(&mut self, h: f32, spheres: &mut [RigidSphereState]) {
        let VolumeMethod::Impulses(settings) = self.material.method else {
            return;
        };
        if !settings.one_ring {
            return;
        }
        let mesh = self.mesh.clone();
        let rows = &mesh.blocks().vertices;
        let order = (0..rows.len()).flat_map(|r| rows.row(r).iter().copied());
        self.reference_pass(h, spheres, |body, pass| {
            for p in order {
                body.reference_ring_impulse(pass, p as usize, &settings);
            }
        });
    }

    /// Section 4: every tet's own impulse in turn, scaled by `gamma`. Does nothing unless the
    /// body's method is the paper's with its per-tet pass on.
    pub(crate) fn reference_per_tet_pass(&mut self, h: f32, spheres: &mut [RigidSphereState]) {
        let VolumeMethod::Impulses(settings) = self.material.method else {
            return;
        };
        if !settings.per_tet || settings.gamma == 0.0 {
            return;
        }
        let mesh = self.mesh.clone();
        let rows = &mesh.blocks().tet_bundles;
        let order = (0..rows.len())
            .flat_map(|r| rows.row(r).iter().copied())
            .filter(|&t| t != NO_TET);
        self.reference_pass(h, spheres, |body, pass| {
            for t in order {
                body.reference_tet_impulse(pass, t as usize, &settings);
            }
        });
    }

    fn reference_pass(
        &mut self,
        h: f32,
        spheres: &mut [RigidSphereState],
        impulses: impl FnOnce(&mut SoftBodyState, &mut Pass),
    ) {
        let mut sphere_dv = vec![Vec3::ZERO; spheres.len()];
        let mut pass = Pass {
            h,
            predicted: self
                .positions
                .iter()
                .zip(&self.velocities)
                .map(|(&x, &v)| x + h * v)
                .collect(),
            sphere_dv: &mut sphere_dv,
        };
        impulses(self, &mut pass);
        for (sphere, dv) in spheres.iter_mut().zip(&sphere_dv) {
            sphere.velocity += *dv;
        }
    }

    /// The ring of `p`: each of its tets `t` gives its corners the directions
    /// `d_i = -w_i C_t grad_i`, summed per particle; all move by `s D_i`, `s` the root of the
    /// ring's volume, at most the ring step limit, shortened by the neighbour clamp.
    fn reference_ring_impulse(&mut self, pass: &mut Pass, p: usize, settings: &ImpulseSettings) {
        let mesh = self.mesh.clone();
        let ring = mesh.one_ring(p);
        let vertices = mesh.ring_vertices(p);
        // The ring's tets with `p` as their last corner (their volumes from the centre).
        let tets: Vec<[u32; 4]> = mesh
            .ring_corners(p)
            .iter()
            .map(|c| c.map(|k| vertices[k as usize]))
            .collect();
        let corners = |tet: [u32; 4]| tet.map(|i| pass.predicted[i as usize]);
        let rest = |t: u32| mesh.rest_volumes()[t as usize];
        let errors: Vec<f32> = ring
            .iter()
            .zip(&tets)
            .map(|(&t, &tet)| volume(corners(tet)) - rest(t))
            .collect();
        let ring_rest = mesh.ring_rest_volume(p);
        let ring_error: f64 = errors.iter().map(|&e| e as f64).sum();
        let tets_within = ring.iter().zip(&errors).all(|(&t, e)| {
            mesh.is_sliver(t as usize) || e.abs() <= settings.ring_tet_tolerance * rest(t)
        });
        if ring_error.abs() <= settings.tolerance as f64 * ring_rest && tets_within {
            return;
        }
        // The directions, by particle of the ring (zero elsewhere), and the stiffest tet's
        // `sum_i w_i |grad_i|^2`, which sets the ring step limit.
        let mut directions = vec![Vec3::ZERO; self.positions.len()];
        let mut stiffest = 0.0f32;
        let mut moves = false;
        for (&tet, &error) in tets.iter().zip(&errors) {
            if error == 0.0 {
                continue;
            }
            let g = gradients(corners(tet));
            let mut stiffness = 0.0;
            for (&i, g) in tet.iter().zip(g) {
                let w = self.inv_masses[i as usize];
                stiffness += w * g.length_squared();
                let d = -w * error * g;
                moves |= d != Vec3::ZERO;
                directions[i as usize] += d;
            }
            stiffest = stiffest.max(stiffness);
        }
        if !moves {
            return;
        }
        for &i in vertices {
            directions[i as usize] = self.reference_constrained(i as usize, directions[i as usize]);
        }
        let mut cubic = [-ring_rest, 0.0, 0.0, 0.0];
        for &tet in &tets {
            let moved = moved_volume(corners(tet), tet.map(|i| directions[i as usize]));
            // The volume as the tolerance check saw it.
            cubic[0] += volume(corners(tet)) as f64;
            for (c, m) in cubic[1..].iter_mut().zip(&moved[1..]) {
                *c += m;
            }
        }
        let Some(root) = monotone_root(&cubic) else {
            return;
        };
        let mut step = root.min(RING_STEP_LIMIT / stiffest as f64);
        if settings.neighbour_clamp {
            let touched = ring.iter().chain(mesh.ring_border_tets(p));
            step = self.reference_clamp(pass, touched, &directions, step);
        }
        for &i in vertices {
            let dv = (step / pass.h as f64) as f32 * directions[i as usize];
            self.reference_velocity_change(pass, i as usize, dv);
        }
    }

    /// The tet `t` alone: its corners move by `gamma s d_i`, `s` the root of its volume,
    /// shortened by the neighbour clamp.
    fn reference_tet_impulse(&mut self, pass: &mut Pass, t: usize, settings: &ImpulseSettings) {
        let mesh = self.mesh.clone();
        let tet = mesh.tets()[t];
        let p = tet.map(|i| pass.predicted[i as usize]);
        let rest = mesh.rest_volumes()[t];
        let error = volume(p) - rest;
        if error.abs() * settings.gamma <= settings.tolerance * rest {
            return;
        }
        let g = gradients(p);
        let mut directions = vec![Vec3::ZERO; self.positions.len()];
        for (&i, g) in tet.iter().zip(g) {
            let d = -self.inv_masses[i as usize] * error * g;
            directions[i as usize] = self.reference_constrained(i as usize, d);
        }
        if tet.iter().all(|&i| directions[i as usize] == Vec3::ZERO) {
            return;
        }
        let mut cubic = moved_volume(p, tet.map(|i| directions[i as usize]));
        cubic[0] -= rest as f64;
        let Some(root) = monotone_root(&cubic) else {
            return;
        };
        let gamma = if volume(p) <= 0.0 {
            INVERTED_TET_GAMMA
        } else {
            settings.gamma as f64
        };
        let mut step = gamma * root;
        if settings.neighbour_clamp {
            let itself = t as u32;
            let touched = std::iter::once(&itself).chain(mesh.tet_neighbours(t));
            step = self.reference_clamp(pass, touched, &directions, step);
        }
        for &i in &tet {
            let dv = (step / pass.h as f64) as f32 * directions[i as usize];
            self.reference_velocity_change(pass, i as usize, dv);
        }
    }

    /// The neighbour clamp (section 4): the largest step up to `step` along `directions` for
    /// which no tet of `touched` falls below its floor anywhere on the way (`eps = V0 / 2`, or
    /// for a tet already below it its volume now less `CLAMP_SLACK V0`; see `clamp_floor`).
    fn reference_clamp<'a>(
        &self,
        pass: &Pass,
        touched: impl Iterator<Item = &'a u32>,
        directions: &[Vec3],
        mut step: f64,
    ) -> f64 {
        for &t in touched {
            let tet = self.mesh.tets()[t as usize];
            let d = tet.map(|i| directions[i as usize]);
            if d.iter().all(|&d| d == Vec3::ZERO) {
                continue;
            }
            let p = tet.map(|i| pass.predicted[i as usize]);
            let rest = self.mesh.rest_volumes()[t as usize];
            let now = signed_volume(&p);
            let floor = clamp_floor(now, rest);
            let mut cubic = moved_volume(p, d);
            // From the volume the floor was chosen from; a tet at its floor may sit a rounding
            // error below it: it starts there.
            cubic[0] = (now as f64 - floor as f64).max(0.0);
            if let Some(s) = first_below_zero(&cubic, step) {
                step = s;
            }
        }
        step
    }

    /// `d` with its push into a contact reduced to the share the particle keeps (see
    /// `contact_kept`): the cubic is solved for the motion the particle can make.
    fn reference_constrained(&self, i: usize, d: Vec3) -> Vec3 {
        let n = self.contacts.normals[i];
        constrained_push(d, n, self.contacts.kept[i], self.contacts.second[i])
    }

    /// Adds `dv` to particle `i`'s velocity and predicted position; a push into a sphere the particle
    /// presses on moves the sphere along.
    fn reference_velocity_change(&mut self, pass: &mut Pass, i: usize, dv: Vec3) {
        self.velocities[i] += dv;
        pass.predicted[i] += pass.h * dv;
        let k = self.contacts.sphere[i];
        if let Some(sphere_dv) = pass.sphere_dv.get_mut(k as usize) {
            let n = self.contacts.normals[i];
            let into = dv.dot(n);
            if into < 0.0 {
                *sphere_dv += n * into;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::components::SoftBody;
    use crate::core::impulses::tests::shaken_body;
    use crate::core::parallel::Serial;
    use crate::game_scenes::GameScene;
    use crate::scenes::{PaperScene, headless_scene_app};

    /// The largest difference between two bodies' velocities (and spheres'), and the largest
    /// change `after` made from `before`.
    fn differences(
        before: &SoftBodyState,
        (fast, fast_spheres): (&SoftBodyState, &[RigidSphereState]),
        (reference, reference_spheres): (&SoftBodyState, &[RigidSphereState]),
    ) -> (f32, f32) {
        let mut apart = 0.0f32;
        let mut change = 0.0f32;
        for ((f, r), b) in fast
            .velocities
            .iter()
            .zip(&reference.velocities)
            .zip(&before.velocities)
        {
            apart = apart.max((*f - *r).length());
            change = change.max((*r - *b).length());
        }
        for (f, r) in fast_spheres.iter().zip(reference_spheres) {
            apart = apart.max((f.velocity - r.velocity).length());
        }
        (apart, change)
    }

    /// Runs the fast one-ring pass and the reference one from `body`, then the fast per-tet
    /// pass and the reference one from the fast ring pass's result; returns, per pass, how far
    /// apart their velocities end and the largest velocity change of the pass.
    fn both_passes(body: &SoftBodyState, spheres: &[RigidSphereState], h: f32) -> [(f32, f32); 2] {
        let run = |body: &SoftBodyState, fast: bool, ring: bool| {
            let (mut body, mut spheres) = (body.clone(), spheres.to_vec());
            match (fast, ring) {
                (true, true) => body.one_ring_impulses(h, &mut spheres, &Serial),
                (true, false) => body.per_tet_impulses(h, &mut spheres, &Serial),
                (false, true) => body.reference_one_ring_pass(h, &mut spheres),
                (false, false) => body.reference_per_tet_pass(h, &mut spheres),
            }
            (body, spheres)
        };
        let (ring_fast, ring_fast_spheres) = run(body, true, true);
        let (ring_reference, ring_reference_spheres) = run(body, false, true);
        let ring = differences(
            body,
            (&ring_fast, &ring_fast_spheres),
            (&ring_reference, &ring_reference_spheres),
        );
        let (tet_fast, tet_fast_spheres) = run(&ring_fast, true, false);
        let (tet_reference, tet_reference_spheres) = run(&ring_fast, false, false);
        let tet = differences(
            &ring_fast,
            (&tet_fast, &tet_fast_spheres),
            (&tet_reference, &tet_reference_spheres),
        );
        [ring, tet]
    }

    /// How far apart the fast and the reference passes may end, as a fraction of the pass's
    /// largest velocity change. Positions in `f32` round a tet's volume at about 1e-7 of it,
    /// and the Gauss-Seidel order carries each impulse's rounding into the next rings'
    /// (measured: 4e-4 at worst over these states, most under 1e-5). A skip or bound that does
    /// not hold moves velocities by the order of the change itself: the clamp's floor taken
    /// from a rounding error below `eps` (`CLAMP_ROUNDING`) put them 1.2 times it apart.
    const APART: f32 = 1e-3;

    fn check(name: &str, passes: [(f32, f32); 2]) {
        for (pass, (apart, change)) in ["one-ring", "per-tet"].iter().zip(passes) {
            assert!(
                apart <= APART * change,
                "{name}, {pass} pass: the fast and reference velocities {apart} apart, the \
                 pass's largest change {change}"
            );
        }
    }

    #[test]
    fn the_fast_passes_give_the_reference_impulses() {
        // A small cube with a jumble of velocities: predicted tets far from their rest volume,
        // some below half of it, so that the clamp works hard.
        for (strength, exact) in [(1.0, false), (3.0, false), (3.0, true)] {
            let mut body = shaken_body(strength);
            if exact {
                let mut material = *body.material();
                material.method = VolumeMethod::Impulses(ImpulseSettings {
                    tolerance: 0.0,
                    ring_tet_tolerance: 0.0,
                    ..ImpulseSettings::PAPER
                });
                body.set_material(material).unwrap();
            }
            check(
                &format!("shaken {strength}, exact {exact}"),
                both_passes(&body, &[], 0.01),
            );
        }
        // The game scenes under load: landing, a sphere on a jelly, irregular meshes.
        for name in [
            "jelly_cube_drop",
            "heavy_sphere_on_jelly",
            "jelly_cube_graded",
            "creature_landing",
        ] {
            let scene = GameScene::standard()
                .into_iter()
                .find(|s| s.name == name)
                .unwrap();
            let mut world = scene.world(VolumeMethod::PAPER_IMPULSES).unwrap();
            for step in 1..=60 {
                world.step(1.0 / 60.0);
                if step % 15 == 0 {
                    let passes = both_passes(&world.body, &world.spheres, 1.0 / 240.0);
                    check(&format!("{name}, step {step}"), passes);
                }
            }
        }
        // The paper's scenes, in headless apps (on the tests' pool).
        crate::plugin::test_compute_pool();
        for scene in [
            PaperScene::BarTwist,
            PaperScene::SoftCube,
            PaperScene::Creature,
        ] {
            let (mut app, entity) = headless_scene_app(scene, VolumeMethod::PAPER_IMPULSES);
            for step in 1..=200 {
                app.update();
                if step % 50 == 0 {
                    let body = app.world().get::<SoftBody>(entity).unwrap();
                    let passes = both_passes(&body.state, &body.spheres, 0.01);
                    check(&format!("{}, step {step}", scene.name()), passes);
                }
            }
        }
    }
}
