//! Soft bodies that may touch each other, stepped together: the substeps of such a group
//! ([`substeps_together`]) run in lockstep, as many as the most any of them needs, with a two-way soft-contact pass in each (`soft_contacts.rs`),
//! and hands what each body's volume impulses pushed into another to that body, with friction.
//! Whether bodies run together is the caller's decision (the plugin's groups of bodies whose
//! bounds overlap, `plugin/groups.rs`); [`step_bodies`] steps a slice of bodies as the plugin
//! does, for use without Bevy.

use std::ops::DerefMut;

use glam::Vec3;

use super::body::SoftBodyState;
use super::colliders::{ColliderInstance, RigidSphereState};
use super::parallel::{Parallel, Serial, for_each_mut};
use super::soft_broad_phase::{
    PairRounds, candidates_hold, gather_soft_candidates, paths_fit_the_step,
};
use super::soft_contacts::{SoftContactPhase, soft_contact_pass};
use super::substep_plan::SubstepPlan;
use super::substep_plan::SubstepStage;

/// Applies the pushes every body's volume impulses handed on this substep to the other bodies'
/// triangles, each with Coulomb friction for its normal part on the particle's slip over the
/// triangle (their velocities now, both ways): the volume impulses carry much of the weight a
/// body rests on another with, and friction counted on the contact pass's push alone would let
/// a pile slide apart. Bodies in slice order, reactions in the order they were made.
pub(crate) fn apply_soft_reactions<B: DerefMut<Target = SoftBodyState>>(bodies: &mut [B]) {
    for b in 0..bodies.len() {
        let reactions = std::mem::take(&mut bodies[b].scratch.soft_reactions);
        for r in &reactions {
            let (i, p) = (r.particle as usize, r.partner as usize);
            let point = |body: &SoftBodyState| -> Vec3 {
                (0..3)
                    .map(|k| r.weights[k] * body.velocities[r.corners[k] as usize])
                    .sum()
            };
            let w_p = bodies[b].inv_masses[i];
            let rel = bodies[b].velocities[i] - point(&bodies[p]);
            let slip = rel - r.normal * rel.dot(r.normal);
            let (slip_speed, w) = (slip.length(), w_p + r.inv_mass);
            let mut impulse = r.impulse;
            let normal = -impulse.dot(r.normal);
            if slip_speed > 0.0 && w > 0.0 && normal > 0.0 {
                let jt = (slip_speed / w).min(r.friction * normal) / slip_speed;
                bodies[b].velocities[i] -= slip * (jt * w_p);
                impulse += slip * jt;
            }
            let partner = &mut bodies[p];
            for k in 0..3 {
                let j = r.corners[k] as usize;
                let w = partner.inv_masses[j];
                partner.velocities[j] += impulse * (r.weights[k] * w);
            }
        }
        bodies[b].scratch.soft_reactions = reactions;
        bodies[b].scratch.soft_reactions.clear();
    }
}

/// A body stepped in lockstep with others, with its own copy of the rigid spheres (which it
/// pushes as it would alone; the plugin merges every body's pushes after the stage).
pub(crate) struct LockstepBody<'a> {
    /// The body.
    pub(crate) state: &'a mut SoftBodyState,
    /// Its copy of the rigid spheres.
    pub(crate) spheres: &'a mut [RigidSphereState],
    /// The contacts its particles made in the stage (soft, static, spheres, rigid bodies).
    pub(crate) contacts: u32,
}

impl<'a> LockstepBody<'a> {
    /// The body's plan if it runs substep `k`.
    fn plan_for(&self, k: u32) -> Option<SubstepPlan> {
        self.state.scratch.substep_plan.filter(|p| k < p.substeps)
    }

    /// `state` with its copy of the spheres, no contacts counted yet.
    pub(crate) fn new(state: &'a mut SoftBodyState, spheres: &'a mut [RigidSphereState]) -> Self {
        LockstepBody {
            state,
            spheres,
            contacts: 0,
        }
    }
}

/// A soft-contact pass of `phase` among `bodies` (on the step's candidates if `listed`), each
/// body's contacts counted on it.
fn counted_pass(
    bodies: &mut [LockstepBody],
    phase: (SoftContactPhase, bool),
    rounds: &mut PairRounds,
    parallel: &dyn Parallel,
) -> u32 {
    let contacts = soft_contact_pass(bodies, phase, rounds, parallel);
    for body in bodies.iter_mut() {
        body.contacts += std::mem::take(&mut body.state.scratch.soft_count);
    }
    contacts
}

impl std::ops::Deref for LockstepBody<'_> {
    type Target = SoftBodyState;
    fn deref(&self) -> &SoftBodyState {
        self.state
    }
}

impl DerefMut for LockstepBody<'_> {
    fn deref_mut(&mut self) -> &mut SoftBodyState {
        self.state
    }
}

/// [`Stage::Substeps`](super::Stage::Substeps) for bodies that may touch each other (the plugin's groups of bodies
/// whose bounds overlap): a soft-contact pass on the predicted positions `x + h v`, then the
/// substeps in lockstep, as many as the most any body in substeps needs (the paper's springs
/// run their one substep with the first). The particles that may meet another body within the
/// step are found once (`soft_broad_phase.rs`): before the first pass, which then reads them,
/// where they cover the whole step, else after it; again within the step for a particle past
/// its radius. In each substep every body's shape solve runs, then one two-way soft-contact
/// pass on the predicted positions over those candidates (when a body is in substeps), then
/// each body's other substep stages, then what the volume impulses pushed into other bodies is
/// handed to them. The bodies run one per job of `parallel` (their blocks on one thread each)
/// wherever they do not touch each other's data, and the contact passes in order, so the
/// result does not depend on it. `rounds` is the passes' scratch, kept by the caller.
/// Returns the contacts.
pub(crate) fn substeps_together(
    bodies: &mut [LockstepBody],
    h: f32,
    colliders: &[ColliderInstance],
    parallel: &dyn Parallel,
    rounds: &mut PairRounds,
) -> u32 {
    let counted = |bodies: &[LockstepBody]| bodies.iter().map(|b| b.contacts).sum::<u32>();
    let before = counted(bodies);
    // The step's candidates, found from where the particles start and how fast they move,
    // serve its substeps' passes, and its predicted pass too where they cover the whole step's
    // motion (no particle fast enough for its path to be cut short); else they are found after
    // it, from the velocities it leaves.
    let listed = bodies.iter().any(|b| !b.state.is_sleeping())
        && bodies.iter().all(|b| paths_fit_the_step(b, h));
    if listed {
        gather_soft_candidates(bodies, h, rounds, parallel);
    }
    counted_pass(
        bodies,
        (SoftContactPhase::Predicted(h), listed),
        rounds,
        parallel,
    );
    // Bodies meeting each other meet at up to the spread of their mean velocities (the
    // diagonal of the box around them): an impact between two bodies is met a fraction of a
    // cell a substep, as a landing on a collider is.
    let (mut low, mut high) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for body in bodies.iter() {
        let mass = body.state.total_mass();
        if mass > 0.0 {
            let mean = body.state.linear_momentum() / mass;
            (low, high) = (low.min(mean), high.max(mean));
        }
    }
    let approach = if low.x <= high.x {
        (high - low).length()
    } else {
        0.0
    };
    let most = bodies
        .iter()
        .filter_map(|b| b.state.substeps_needed(h, b.spheres, colliders, approach))
        .max();
    for body in bodies.iter_mut() {
        let b = &mut *body;
        b.state.plan_substeps(h, b.spheres, colliders, most);
    }
    if most.is_some() && !listed {
        gather_soft_candidates(bodies, h, rounds, parallel);
    }
    for k in 0..most.unwrap_or(1).max(1) {
        for_each_mut(bodies, parallel, &|body| {
            if let Some(plan) = body.plan_for(k) {
                body.contacts += body.state.substep_stage(
                    SubstepStage::Shape,
                    &plan,
                    k,
                    body.spheres,
                    colliders,
                    &Serial,
                );
            }
        });
        if let Some(n) = most {
            // The step's candidates hold while every boundary particle stays within its
            // radius; past it (a fast impact), they are found again for the rest of the step.
            if !bodies.iter().all(|b| candidates_hold(b)) {
                gather_soft_candidates(bodies, h * (n - k) as f32 / n as f32, rounds, parallel);
            }
            let substep = (SoftContactPhase::Substep(h / n as f32), true);
            counted_pass(bodies, substep, rounds, parallel);
        }
        for_each_mut(bodies, parallel, &|body| {
            if let Some(plan) = body.plan_for(k) {
                for stage in &SubstepStage::ORDER[1..] {
                    body.contacts += body.state.substep_stage(
                        *stage,
                        &plan,
                        k,
                        body.spheres,
                        colliders,
                        &Serial,
                    );
                }
            }
        });
        apply_soft_reactions(bodies);
    }
    counted(bodies) - before
}

/// The soft-contact pass that ends a step of bodies stepped together (the last part of
/// [`Stage::Finish`](super::Stage::Finish)): on the positions the step ended at, moving
/// penetrating particles apart and stopping their approach, so that no particle ends a step
/// inside another body but one already deep in it, which the substeps ease out. Returns the
/// contacts. `rounds` is the passes' scratch, kept by the caller.
pub(crate) fn final_contacts_together(
    bodies: &mut [LockstepBody],
    parallel: &dyn Parallel,
    rounds: &mut PairRounds,
) -> u32 {
    counted_pass(bodies, (SoftContactPhase::Final, false), rounds, parallel)
}

/// A whole step of several bodies that meet each other, in the plugin's order
/// ([`Stage::ORDER`](super::Stage::ORDER)): each body's forces, the substeps together ([`substeps_together`]), each
/// body's plasticity and finish, then the final soft-contact pass. For using the core without
/// Bevy, and for tests and benchmarks of piles. Returns the contacts.
pub fn step_bodies(
    bodies: &mut [SoftBodyState],
    h: f32,
    gravity: Vec3,
    colliders: &[ColliderInstance],
    parallel: &dyn Parallel,
) -> u32 {
    let mut bodies: Vec<LockstepBody> = bodies
        .iter_mut()
        .map(|state| LockstepBody::new(state, &mut []))
        .collect();
    for body in bodies.iter_mut() {
        body.state.begin_step();
        body.state.apply_forces(h, gravity, &Serial);
    }
    let rounds = &mut PairRounds::default();
    let mut contacts = substeps_together(&mut bodies, h, colliders, parallel, rounds);
    for body in bodies.iter_mut() {
        body.state.apply_plasticity(h);
        body.state.finish_step(h, &[], colliders);
    }
    contacts += final_contacts_together(&mut bodies, parallel, rounds);
    contacts
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::boundary::closest_barycentric;
    use crate::core::geometry::signed_volume;
    use crate::core::material::{SoftBodyMaterial, VolumeMethod};
    use crate::core::parallel::Serial;
    use glam::UVec3;
    use parry3d::math::Pose;
    use parry3d::shape::SharedShape;

    /// A jelly cube of `side` metres, 6 cells a side, its lowest corner at `corner`.
    fn jelly(side: f32, corner: Vec3) -> SoftBodyState {
        let mesh = crate::core::box_grid(UVec3::splat(6), Vec3::splat(side / 6.0), corner).unwrap();
        SoftBodyState::new(mesh.into(), SoftBodyMaterial::JELLY).unwrap()
    }

    /// How deep `x` is inside `body` (zero outside): its distance to the body's boundary when
    /// it lies in one of its tets.
    pub(super) fn depth_inside(x: Vec3, body: &SoftBodyState) -> f32 {
        let p = body.positions();
        let inside = body.mesh().tets().iter().any(|t| {
            let [a, b, c, d] = t.map(|i| p[i as usize]);
            let whole = signed_volume(&[a, b, c, d]);
            let parts = [
                signed_volume(&[x, b, c, d]),
                signed_volume(&[a, x, c, d]),
                signed_volume(&[a, b, x, d]),
                signed_volume(&[a, b, c, x]),
            ];
            parts.iter().all(|&v| v * whole.signum() >= 0.0)
        });
        if !inside {
            return 0.0;
        }
        body.boundary()
            .triangles()
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| p[i as usize]);
                let q = closest_barycentric(x, a, b, c);
                (a * q.x + b * q.y + c * q.z).distance(x)
            })
            .fold(f32::INFINITY, f32::min)
    }

    /// The deepest any particle of one body is inside another.
    pub(super) fn deepest(bodies: &[SoftBodyState]) -> f32 {
        let mut deepest = 0.0f32;
        for (a, body) in bodies.iter().enumerate() {
            for (b, other) in bodies.iter().enumerate() {
                if a != b {
                    for &x in body.positions() {
                        deepest = deepest.max(depth_inside(x, other));
                    }
                }
            }
        }
        deepest
    }

    fn momentum(bodies: &[SoftBodyState]) -> Vec3 {
        bodies
            .iter()
            .flat_map(|b| b.velocities().iter().zip(b.masses()))
            .map(|(&v, &m)| m * v)
            .sum()
    }

    /// Two jellies thrown at each other in space (4 m/s each, off-centre) bounce apart: they
    /// end moving away from each other, no particle of one ends a step more than a millimetre
    /// inside the other, and their linear momentum is what it was. With the paper's method and
    /// with XPBD's cluster correction (whose impact leaves particles behind the dents' edges,
    /// which the final pass must meet, and whose correction must not push into the other body),
    /// at 60 and 120 Hz (what an impact leaves behind the last substep does not shrink with the
    /// step).
    #[test]
    fn two_jellies_thrown_at_each_other_bounce_apart() {
        for method in [VolumeMethod::PAPER_IMPULSES, VolumeMethod::XPBD_CLUSTERS] {
            for hz in [60.0, 120.0] {
                thrown_at_each_other(method, hz);
            }
        }
    }

    fn thrown_at_each_other(method: VolumeMethod, hz: f32) {
        let mut bodies = [
            jelly(0.3, Vec3::new(-0.5, 0.0, 0.0)),
            jelly(0.3, Vec3::new(0.25, 0.08, 0.05)),
        ];
        for body in &mut bodies {
            body.set_material(SoftBodyMaterial::JELLY.with_method(method))
                .unwrap();
        }
        bodies[0].velocities_mut().fill(Vec3::X * 4.0);
        bodies[1].velocities_mut().fill(-Vec3::X * 4.0);
        let before = momentum(&bodies);
        let mut worst = 0.0f32;
        let mut contacts = 0;
        for _ in 0..(hz / 2.0) as usize {
            contacts += step_bodies(&mut bodies, 1.0 / hz, Vec3::ZERO, &[], &Serial);
            worst = worst.max(deepest(&bodies));
        }
        assert!(contacts > 50, "{contacts} contacts");
        let after = momentum(&bodies);
        // Momentum is conserved by every contact up to rounding: the substeps' contacts between
        // bodies move positions, whose change becomes velocity in `f32` (a rounding of 3e-8 m
        // at half a metre is 7e-6 m/s at 240 Hz), so the sum drifts by a few parts in 1e4.
        let carried = 2.0 * 4.0 * bodies[0].masses().iter().sum::<f32>();
        let name = format!("{} at {hz} Hz", method.name());
        assert!(
            (after - before).length() < 5e-4 * carried,
            "{name}: momentum {before} -> {after}"
        );
        let apart = bodies[1].centre_of_mass().x - bodies[0].centre_of_mass().x;
        let closing = (bodies[1].velocities().iter().sum::<Vec3>()
            - bodies[0].velocities().iter().sum::<Vec3>())
        .x;
        assert!(
            apart > 0.3 && closing > 0.0,
            "{name}: apart {apart} m, closing {closing}"
        );
        assert!(
            worst < 1e-3,
            "{name}: a particle ended a step {worst} m inside the other body"
        );
    }

    /// Two jellies placed 2 cm into each other, at rest in space, are eased apart rather than
    /// shot apart: no particle is faster than twice the contacts' depenetration speed after
    /// the first step, and after half a second they no longer overlap.
    #[test]
    fn jellies_placed_overlapping_are_eased_apart() {
        let mut bodies = [
            jelly(0.3, Vec3::ZERO),
            jelly(0.3, Vec3::new(0.28, 0.01, -0.01)),
        ];
        step_bodies(&mut bodies, 1.0 / 60.0, Vec3::ZERO, &[], &Serial);
        let fastest = bodies
            .iter()
            .flat_map(|b| b.velocities())
            .map(|v| v.length())
            .fold(0.0f32, f32::max);
        let bound = 2.0 * crate::core::contacts::MAX_DEPENETRATION_SPEED;
        assert!(
            fastest < bound,
            "a particle left the first step at {fastest} m/s"
        );
        for _ in 0..30 {
            step_bodies(&mut bodies, 1.0 / 60.0, Vec3::ZERO, &[], &Serial);
        }
        let worst = deepest(&bodies);
        assert!(
            worst < 1e-3,
            "a particle is still {worst} m inside the other body"
        );
    }

    /// Sixteen jelly cubes of 0.3 m dropped in two layers into a 1 m square box: from the
    /// second second on no body's volume is off by 1 %, the bottom layer carrying the top one
    /// included (at the substeps their motion asks for, the bottom layer lost over 1 %), and
    /// after 8 s the pile is asleep (with room to spare: when a pile settles moves with any
    /// change to its contacts). It never slept while a body's foot wedged under its neighbour
    /// was pushed into the ground every substep, and a sleeping body that its neighbours'
    /// substeps pushed lost volume in the step it woke.
    #[test]
    fn a_pile_of_jellies_keeps_every_body_volume_and_falls_asleep() {
        let mut colliders = vec![ColliderInstance::new(
            SharedShape::halfspace(Vec3::Y),
            Pose::IDENTITY,
            0.8,
        )];
        for (centre, half) in [
            (Vec3::new(-0.55, 0.3, 0.0), Vec3::new(0.05, 0.3, 0.6)),
            (Vec3::new(0.55, 0.3, 0.0), Vec3::new(0.05, 0.3, 0.6)),
            (Vec3::new(0.0, 0.3, -0.55), Vec3::new(0.6, 0.3, 0.05)),
            (Vec3::new(0.0, 0.3, 0.55), Vec3::new(0.6, 0.3, 0.05)),
        ] {
            colliders.push(ColliderInstance::new(
                SharedShape::cuboid(half.x, half.y, half.z),
                Pose::from_translation(centre),
                0.8,
            ));
        }
        let mut bodies: Vec<SoftBodyState> = (0..16)
            .map(|k| {
                let (i, j, layer) = (k % 3, (k / 3) % 3, k / 9);
                let nudge = 0.01 * ((k * 7) % 5) as f32 - 0.02;
                jelly(
                    0.3,
                    Vec3::new(
                        -0.45 + 0.3 * i as f32 + nudge,
                        0.01 + 0.4 * layer as f32,
                        -0.45 + 0.3 * j as f32 - nudge,
                    ),
                )
            })
            .collect();
        let g = Vec3::new(0.0, -9.81, 0.0);
        let mut worst = (0.0f64, 0);
        for step in 0..480 {
            step_bodies(&mut bodies, 1.0 / 60.0, g, &colliders, &Serial);
            if step >= 60 {
                for (k, body) in bodies.iter().enumerate() {
                    let error = body.volume_metrics().volume_error_pct.abs();
                    if error > worst.0 {
                        worst = (error, k);
                    }
                }
            }
        }
        assert!(
            worst.0 < 1.0,
            "jelly {} off its volume by {} %",
            worst.1,
            worst.0
        );
        let awake = bodies.iter().filter(|b| !b.is_sleeping()).count();
        assert!(awake == 0, "{awake} jellies still awake after 8 s");
    }

    /// A jelly slab: 0.3 m square, 0.1 m thick (6 x 2 x 6 cells), its lowest corner at `corner`,
    /// its volume kept by `method`.
    fn slab(corner: Vec3, method: VolumeMethod) -> SoftBodyState {
        let mesh = crate::core::box_grid(UVec3::new(6, 2, 6), Vec3::splat(0.05), corner).unwrap();
        SoftBodyState::new(mesh.into(), SoftBodyMaterial::JELLY.with_method(method)).unwrap()
    }

    /// Three jelly slabs dropped in a stack on the ground (a centimetre off each other's
    /// centres) stay stacked and come to rest: over the last two of six seconds no centre of
    /// mass moves more than 3 mm, every body keeps its volume within 1 %, and no particle ends
    /// inside another body by more than 2 mm. Slabs, not cubes: a column of this jelly taller
    /// than about 0.5 m buckles under its own weight (Greenhill), so a stack of three 0.3 m
    /// cubes falls over in reality too. With the paper's method at 60 Hz and XPBD's cluster
    /// correction at 30 and 60 Hz: the bodies fall asleep together, and the step they do ends
    /// with its contacts between them (with the correction's push at 30 Hz, two particles
    /// stayed 2 mm inside the body below while they slept).
    #[test]
    fn a_stack_of_three_jellies_stays_stacked() {
        for (method, hz) in [
            (VolumeMethod::PAPER_IMPULSES, 60),
            (VolumeMethod::XPBD_CLUSTERS, 30),
            (VolumeMethod::XPBD_CLUSTERS, 60),
        ] {
            stack_of_three_stays_stacked(method, hz);
        }
    }

    fn stack_of_three_stays_stacked(method: VolumeMethod, hz: u32) {
        let ground = [ColliderInstance::new(
            SharedShape::halfspace(Vec3::Y),
            Pose::IDENTITY,
            0.8,
        )];
        let mut bodies = [
            slab(Vec3::ZERO, method),
            slab(Vec3::new(0.01, 0.11, -0.01), method),
            slab(Vec3::new(0.0, 0.22, 0.01), method),
        ];
        let g = Vec3::new(0.0, -9.81, 0.0);
        let (h, steps) = (1.0 / hz as f32, 6 * hz);
        let mut worst = 0.0f32;
        let mut settled = [Vec3::ZERO; 3];
        for step in 0..steps {
            step_bodies(&mut bodies, h, g, &ground, &Serial);
            if step % 10 == 9 {
                worst = worst.max(deepest(&bodies));
            }
            if step == steps - 2 * hz {
                settled = bodies.each_ref().map(|b| b.centre_of_mass());
            }
        }
        let case = format!("{} at {hz} Hz", method.name());
        worst = worst.max(deepest(&bodies));
        assert!(
            worst < 2e-3,
            "{case}: a particle ended a step {worst} m inside another body"
        );
        for (k, body) in bodies.iter().enumerate() {
            let centre = body.centre_of_mass();
            assert!(
                (centre.y - (0.05 + 0.1 * k as f32)).abs() < 0.03,
                "{case}: jelly {k} at {centre}"
            );
            let drift = centre.distance(settled[k]);
            assert!(
                drift < 3e-3,
                "{case}: jelly {k} moved {drift} m in the last 2 s"
            );
            let error = body.volume_metrics().volume_error_pct;
            assert!(
                error.abs() < 1.0,
                "{case}: jelly {k}: volume error {error} %"
            );
        }
    }
}
