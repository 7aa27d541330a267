use std::sync::Arc;

use glam::{UVec3, Vec3};

use super::*;
use crate::core::Serial;
use crate::core::body::SoftBodyState;
use crate::core::geometry::volume_gradients;
use crate::core::grid::box_grid;
use crate::core::material::SoftBodyMaterial;

const H: f32 = 0.01;

/// Settings with every impulse applied, however small its tet's error.
fn exact(gamma: f32, neighbour_clamp: bool) -> ImpulseSettings {
    ImpulseSettings {
        gamma,
        neighbour_clamp,
        tolerance: 0.0,
        ring_tet_tolerance: 0.0,
        ..ImpulseSettings::PAPER
    }
}

/// A small cube with a deterministic jumble of velocities: strong enough that predicted
/// tets are far from their rest volume, some below half of it.
pub(crate) fn shaken_body(strength: f32) -> SoftBodyState {
    let mesh = Arc::new(box_grid(UVec3::splat(4), Vec3::splat(0.1), Vec3::ZERO).unwrap());
    let material = SoftBodyMaterial::paper(1000.0, 1.0, 1.0);
    let mut body = SoftBodyState::new(mesh, material).unwrap();
    let mut seed = 12345u64;
    for v in body.velocities_mut() {
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 40) as f32) / ((1u64 << 24) as f32) * 2.0 - 1.0
        };
        *v = Vec3::new(next(), next(), next()) * strength;
    }
    body.refresh_predicted(H);
    body
}

/// Switches `body` to the paper's method with `settings`.
fn use_impulses(body: &mut SoftBodyState, settings: ImpulseSettings) {
    let mut material = *body.material();
    material.method = VolumeMethod::Impulses(settings);
    body.set_material(material).unwrap();
}

fn predicted_volume(body: &SoftBodyState, t: usize) -> f32 {
    signed_volume(&body.mesh.tets()[t].map(|i| body.predicted_position(i)))
}

#[test]
fn every_impulse_conserves_momentum() {
    let mut body = shaken_body(3.0);
    let mut applied = 0;
    for p in 0..body.positions.len() {
        let before = body.linear_momentum();
        let outcome = body
            .pass_body()
            .ring_impulse(p, H, &exact(0.125, true), &mut []);
        let after = body.linear_momentum();
        if let ImpulseOutcome::Applied { .. } = outcome {
            applied += 1;
        }
        assert!(
            (after - before).length() < 1e-4,
            "ring {p}: {before} -> {after}"
        );
    }
    for t in 0..body.mesh.tet_count() {
        let before = body.linear_momentum();
        body.pass_body()
            .tet_impulse(t, H, &exact(0.125, true), &mut []);
        let after = body.linear_momentum();
        assert!(
            (after - before).length() < 1e-4,
            "tet {t}: {before} -> {after}"
        );
    }
    assert!(applied > 50, "only {applied} ring impulses were applied");
    // The scratch directions are left clean.
    assert!(body.scratch.per_particle.iter().all(|&d| d == Vec3::ZERO));
}

#[test]
fn ring_impulse_restores_the_ring_volume() {
    let mut body = shaken_body(1.0);
    let mut checked = 0;
    let mut limited = 0;
    for p in 0..body.positions.len() {
        let ring: Vec<u32> = body.mesh.one_ring(p).to_vec();
        let rest: f32 = ring
            .iter()
            .map(|&t| body.mesh.rest_volumes()[t as usize])
            .sum();
        if let ImpulseOutcome::Applied { step, root, .. } =
            body.pass_body()
                .ring_impulse(p, H, &exact(0.125, false), &mut [])
        {
            if step < root {
                limited += 1;
                continue;
            }
            let now: f32 = ring
                .iter()
                .map(|&t| predicted_volume(&body, t as usize))
                .sum();
            assert!(
                (now - rest).abs() < 1e-4 * rest,
                "ring {p}: {now} vs {rest}"
            );
            checked += 1;
        }
    }
    assert!(checked > 50, "{checked} rings restored, {limited} limited");
}

#[test]
fn tet_impulse_with_gamma_one_restores_the_tet_volume() {
    let mut body = shaken_body(1.0);
    for t in 0..body.mesh.tet_count() {
        if let ImpulseOutcome::Applied { .. } =
            body.pass_body()
                .tet_impulse(t, H, &exact(1.0, false), &mut [])
        {
            // gamma = 1 applies the whole root.
            let v0 = body.mesh.rest_volumes()[t];
            let v = predicted_volume(&body, t);
            assert!((v - v0).abs() < 1e-3 * v0, "tet {t}: {v} vs {v0}");
        }
    }
}

#[test]
fn clamp_keeps_touched_tets_at_or_above_half_their_rest_volume() {
    let mut body = shaken_body(6.0);
    let tets = body.mesh.tet_count();
    let mut clamped = 0;
    let mut below_at_start = 0;
    for p in 0..body.positions.len() {
        let before: Vec<f32> = (0..tets).map(|t| predicted_volume(&body, t)).collect();
        if let ImpulseOutcome::Applied { clamped: c, .. } =
            body.pass_body()
                .ring_impulse(p, H, &exact(0.125, true), &mut [])
        {
            clamped += c as usize;
        }
        for (t, &before_t) in before.iter().enumerate() {
            let v0 = body.mesh.rest_volumes()[t];
            // `eps`, or for a tet below it (or at it by rounding) its volume less the slack.
            let floor = clamp_floor(before_t, v0);
            below_at_start += (floor < CLAMP_FRACTION * v0) as usize;
            let after = predicted_volume(&body, t);
            assert!(
                after >= floor - 1e-4 * v0,
                "ring {p}, tet {t}: {before_t} -> {after} (floor {floor})"
            );
        }
    }
    for t in 0..tets {
        let before: Vec<f32> = (0..tets).map(|u| predicted_volume(&body, u)).collect();
        body.pass_body()
            .tet_impulse(t, H, &exact(0.125, true), &mut []);
        for (u, &before_u) in before.iter().enumerate() {
            let v0 = body.mesh.rest_volumes()[u];
            let floor = clamp_floor(before_u, v0);
            let after = predicted_volume(&body, u);
            assert!(
                after >= floor - 1e-4 * v0,
                "tet {t}, neighbour {u}: {before_u} -> {after} (floor {floor})"
            );
        }
    }
    // The scenario must exercise the clamp, or this test proves nothing.
    assert!(clamped > 0, "no ring impulse was clamped");
    assert!(below_at_start > 0, "no tet started below its floor");
}

#[test]
fn passes_keep_every_tet_above_its_floor_with_the_fast_clamp() {
    // Gentle enough that the pass bounds skip most clamps, strong enough that some do not.
    for strength in [0.05, 0.5, 4.0] {
        let mut body = shaken_body(strength);
        body.begin_step();
        let above = |body: &SoftBodyState| -> Vec<bool> {
            (0..body.mesh.tet_count())
                .map(|t| predicted_volume(body, t) >= CLAMP_FRACTION * body.mesh.rest_volumes()[t])
                .collect()
        };
        let check = |body: &SoftBodyState, was_above: &[bool], pass: &str| {
            for (t, &was) in was_above.iter().enumerate() {
                let v0 = body.mesh.rest_volumes()[t];
                let v = predicted_volume(body, t);
                assert!(
                    !was || v >= CLAMP_FRACTION * v0 - 1e-4 * v0,
                    "strength {strength}, {pass} pass: tet {t} fell to {v} below V0/2 = {}",
                    CLAMP_FRACTION * v0
                );
            }
        };
        let before = above(&body);
        body.one_ring_impulses(H, &mut [], &Serial);
        check(&body, &before, "ring");
        let before = above(&body);
        body.per_tet_impulses(H, &mut [], &Serial);
        check(&body, &before, "per-tet");
        let c = body.counters();
        if strength < 0.1 {
            assert!(c.clamps_skipped > 0, "the fast path was never taken: {c:?}");
        }
        if strength > 1.0 {
            assert!(
                c.rings_clamped + c.tets_clamped > 0,
                "the slow path never clamped: {c:?}"
            );
        }
    }
}

/// The bounds the clamp shortcuts rely on hold for arbitrary tets, including flat and
/// inverted ones, and moves up to and beyond the tet's size.
#[test]
fn drift_bound_bounds_every_volume_change() {
    let mut seed = 99u64;
    let mut next = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 40) as f32) / ((1u64 << 24) as f32) * 2.0 - 1.0
    };
    let mut tightest = 0.0f32;
    for case in 0..20_000 {
        let scale = [0.01, 1.0, 30.0][case % 3];
        let xp: [Vec3; 4] = std::array::from_fn(|_| Vec3::new(next(), next(), next()) * scale);
        let m = scale * [0.001, 0.05, 0.5, 2.0][case % 4] * next().abs();
        let g = volume_gradients(&xp);
        // Every other case moves each particle its full `m` along its gradient (the worst
        // case to first order), the others in random directions by random amounts.
        let sign = next().signum();
        let moved: [Vec3; 4] = std::array::from_fn(|k| {
            if case % 2 == 0 {
                xp[k] + g[k].normalize_or_zero() * m * sign
            } else {
                let dir = Vec3::new(next(), next(), next()).normalize_or_zero();
                xp[k] + dir * m * next().abs()
            }
        });
        let grad: f32 = g.iter().map(|g| g.length()).sum();
        let reach = (0..3).map(|k| (xp[k] - xp[3]).length()).fold(0.0, f32::max);
        let change = (signed_volume(&moved) - signed_volume(&xp)).abs();
        let [bound, ..] =
            drift_bound(f32x4::splat(m), f32x4::splat(grad), f32x4::splat(reach)).to_array();
        // f32 rounding of the two volumes, relative to the tet's own size.
        let rounding = 1e-5 * (reach + m).powi(3);
        assert!(
            change <= bound + rounding,
            "case {case}: change {change} > bound {bound}"
        );
        assert!(bound <= volume_bound(2.0 * m, reach) * 1.0001 + rounding);
        if bound > 0.0 {
            tightest = tightest.max(change / bound);
        }
    }
    // The bound is not vacuous: moves along the gradients reach it to first order.
    assert!(tightest > 0.9, "tightest ratio {tightest}");
}

/// A safe radius keeps `drift_bound` within the slack, and gives away little of it.
#[test]
fn safe_radius_is_within_the_slack_and_close_to_it() {
    let mut seed = 7u64;
    let mut next = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 40) as f64) / ((1u64 << 24) as f64)
    };
    let mut loosest = 1.0f64;
    for case in 0..20_000 {
        let l = 10f64.powf(4.0 * next() - 3.0);
        // Gradient sums from flat to regular tets, slacks from a sliver to a whole tet.
        let grad = l * l * [0.0, 0.01, 0.6, 2.0][case % 4] * next();
        let slack = l * l * l * 10f64.powf(-6.0 * next());
        let radius = safe_radius(
            f32x4::splat(slack as f32),
            f32x4::splat(grad as f32),
            f32x4::splat(l as f32),
        )
        .to_array()[0] as f64;
        let f = |m: f64| m * grad + 2.0 * l * m * m + 4.0 / 3.0 * m * m * m;
        assert!(f(radius) <= slack, "case {case}: {} > {slack}", f(radius));
        let (mut lo, mut hi) = (0.0, l + slack / grad.max(1e-30));
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if f(mid) <= slack { lo = mid } else { hi = mid }
        }
        loosest = loosest.min(radius / lo);
    }
    assert!(
        loosest > 0.9,
        "a radius of {loosest} of the largest safe one"
    );
    for slack in [0.0, -1.0, f32::NAN, f32::NEG_INFINITY] {
        let one = f32x4::ONE;
        let radius = safe_radius(f32x4::splat(slack), one, one).to_array()[0];
        assert_eq!(radius, f32::NEG_INFINITY, "slack {slack}");
    }
}

/// A step's one-ring and per-tet passes with every `every`-th particle pushed between them
/// by `strength`: the per-tet pass goes on from the ring pass's bounds, so velocities
/// changed in between must count in its drifts.
fn passes_with_a_push_between(body: &mut SoftBodyState, every: usize, strength: f32) {
    body.begin_step();
    body.one_ring_impulses(H, &mut [], &Serial);
    for v in body.velocities.iter_mut().step_by(every) {
        *v += Vec3::new(0.3, -1.0, 0.2) * strength;
    }
    body.per_tet_impulses(H, &mut [], &Serial);
}

/// Whether a ring was past its tolerance when last checked only decides how its next
/// check is computed: guessing every ring past it, or none, gives the same passes bit for
/// bit, over several passes (where the guesses are then the rings' own).
#[test]
fn the_guess_of_which_rings_are_corrected_changes_nothing() {
    for strength in [0.05, 0.5, 4.0] {
        let mut none = shaken_body(strength);
        let mut all = shaken_body(strength);
        all.volume_passes.ring_corrected.fill(true);
        for body in [&mut none, &mut all] {
            for _ in 0..3 {
                passes_with_a_push_between(body, 7, strength);
            }
        }
        assert_eq!(none.velocities, all.velocities, "strength {strength}");
        assert_eq!(
            none.volume_passes.ring_corrected,
            all.volume_passes.ring_corrected
        );
        let corrected = none
            .volume_passes
            .ring_corrected
            .iter()
            .filter(|&&c| c)
            .count();
        assert!(corrected > 0 && corrected < none.volume_passes.ring_corrected.len());
    }
}

#[test]
fn the_clamp_shortcut_changes_nothing() {
    for strength in [0.05, 0.5, 4.0] {
        let mut fast = shaken_body(strength);
        let mut exact = shaken_body(strength);
        exact.volume_passes.clamp_bounds.disabled = true;
        for body in [&mut fast, &mut exact] {
            passes_with_a_push_between(body, 7, strength);
        }
        assert_eq!(fast.velocities, exact.velocities, "strength {strength}");
        assert_eq!(exact.counters().clamps_skipped, 0);
        if strength < 0.1 {
            assert!(fast.counters().clamps_skipped > 0);
        }
    }
}

/// The per-tet pass goes on from the clamp bounds its step's one-ring pass took: with
/// velocities changed in between, and impulses big enough (`gamma = 1`) to be clamped, it
/// still clamps exactly as the walk without bounds does.
#[test]
fn the_per_tet_pass_going_on_from_the_ring_passs_bounds_changes_nothing() {
    let mut clamped = 0;
    for strength in [0.3, 3.0, 4.0, 6.0] {
        let mut fast = shaken_body(strength);
        use_impulses(
            &mut fast,
            ImpulseSettings {
                gamma: 1.0,
                ..ImpulseSettings::PAPER
            },
        );
        let mut exact = fast.clone();
        exact.volume_passes.clamp_bounds.disabled = true;
        for body in [&mut fast, &mut exact] {
            passes_with_a_push_between(body, 5, strength);
        }
        assert_eq!(fast.velocities, exact.velocities, "strength {strength}");
        if strength < 1.0 {
            assert!(
                fast.counters().clamps_skipped > 0,
                "the bounds were never used"
            );
        }
        clamped += exact.counters().tets_clamped;
    }
    assert!(clamped > 0, "no per-tet impulse was clamped");
}

/// A one-ring pass may go on from an earlier step's bounds (see `CARRY_DRIFT`): made to
/// do so every step, however far the particles have moved, over steps of bodies shaken
/// gently and hard with pushes now and then, the passes clamp exactly as the walk without
/// bounds does; and by the rule, a body shaken gently goes on from earlier bounds, one
/// shaken hard takes new ones.
#[test]
fn one_ring_passes_going_on_from_earlier_steps_bounds_change_nothing() {
    let (mut carried, mut clamped) = (0, 0);
    for strength in [0.02, 0.2, 2.0, 6.0] {
        let mut fast = shaken_body(strength);
        let mut exact = fast.clone();
        let mut by_rule = fast.clone();
        fast.volume_passes.clamp_bounds.always_carry = true;
        exact.volume_passes.clamp_bounds.disabled = true;
        for step in 0..8 {
            for body in [&mut fast, &mut exact, &mut by_rule] {
                body.begin_step();
                body.one_ring_impulses(H, &mut [], &Serial);
                body.per_tet_impulses(H, &mut [], &Serial);
                body.integrate_positions(H, &Serial);
                if step % 4 == 3 {
                    for v in body.velocities.iter_mut().step_by(5) {
                        *v += Vec3::new(0.3, -1.0, 0.2) * strength;
                    }
                }
            }
            for body in [&fast, &by_rule] {
                assert_eq!(body.velocities, exact.velocities, "{strength}, step {step}");
                assert_eq!(body.positions, exact.positions, "{strength}, step {step}");
            }
            clamped += exact.counters().rings_clamped + exact.counters().tets_clamped;
        }
        carried += fast.volume_passes.clamp_bounds.carried_passes;
        let by_rule = by_rule.volume_passes.clamp_bounds.carried_passes;
        if strength < 0.1 {
            assert!(by_rule > 0, "{strength}: a gentle body never went on");
        } else if strength > 1.0 {
            assert!(
                by_rule < 7,
                "{strength}: a body shaken hard went on {by_rule} times"
            );
        }
    }
    assert!(
        carried >= 28,
        "{carried} passes went on from an earlier step's bounds"
    );
    assert!(clamped > 0, "no impulse was clamped");
}

/// A body that moves as a whole, fast, while it shakes gently goes on from its earlier
/// bounds (their start follows it, see `SafeRadii::follow_translation`), and clamps
/// exactly as the walk without bounds does; without following, its drifts (the distance
/// it travelled) ask for new bounds every pass.
#[test]
fn a_body_moving_as_a_whole_goes_on_from_its_bounds() {
    let mut by_rule = shaken_body(0.02);
    for v in by_rule.velocities_mut() {
        *v += Vec3::new(1.5, -4.0, 0.5);
    }
    let mut exact = by_rule.clone();
    exact.volume_passes.clamp_bounds.disabled = true;
    for step in 0..8 {
        for body in [&mut by_rule, &mut exact] {
            body.begin_step();
            body.one_ring_impulses(H, &mut [], &Serial);
            body.per_tet_impulses(H, &mut [], &Serial);
            body.integrate_positions(H, &Serial);
        }
        assert_eq!(by_rule.velocities, exact.velocities, "step {step}");
        assert_eq!(by_rule.positions, exact.positions, "step {step}");
    }
    // Eight passes: the first takes the bounds, the others may go on from them.
    let carried = by_rule.volume_passes.clamp_bounds.carried_passes;
    assert!(carried >= 5, "{carried} of 7 passes went on");
    assert!(
        by_rule.counters().clamps_skipped > 0,
        "the bounds were never used"
    );
}

/// A body at rest and moving as a whole, three particles of one corner kicked now and
/// then, gently enough for the body to stay quiet (see `QUIET_DRIFT`) and the bounds to
/// go on, hard enough to put the rings around them past their tolerances: most rings are
/// known to be within their tolerances from the bounds (`RingErrorBound`), the kicked ones
/// are not, and the passes give exactly what they give checking every ring (the walk
/// without bounds checks every ring). Taking every ring found within at its last check as
/// known fails here (checked).
#[test]
fn rings_known_within_their_tolerances_change_nothing() {
    const KICK: Vec3 = Vec3::new(0.05, 0.1, -0.07);
    // A kick that throws particles far past their radius (`FAR_DRIFT`) and smaller ones
    // that do not: rings near those are known or not from the block's largest drift.
    for (moving, kick) in [Vec3::ZERO, Vec3::new(1.5, -4.0, 0.5)]
        .into_iter()
        .flat_map(|m| [1.0, 0.3, 0.1, 0.03].map(|k| (m, k * KICK)))
    {
        let mut fast = shaken_body(0.0);
        for v in fast.velocities_mut() {
            *v += moving;
        }
        let mut exact = fast.clone();
        exact.volume_passes.clamp_bounds.disabled = true;
        let (mut known, mut checked, mut kicked_rings) = (0, 0, 0);
        for step in 0..16 {
            for body in [&mut fast, &mut exact] {
                body.begin_step();
                if step % 4 == 2 {
                    for v in body.velocities.iter_mut().take(3) {
                        *v += kick;
                    }
                }
                body.one_ring_impulses(H, &mut [], &Serial);
                body.per_tet_impulses(H, &mut [], &Serial);
                body.integrate_positions(H, &Serial);
            }
            assert_eq!(
                fast.velocities, exact.velocities,
                "{moving}, {kick}, step {step}"
            );
            assert_eq!(
                fast.positions, exact.positions,
                "{moving}, {kick}, step {step}"
            );
            assert_eq!(exact.counters().ring_checks_skipped, 0);
            known += fast.counters().ring_checks_skipped;
            checked += fast.positions.len() as u32;
            if step % 4 == 2 {
                kicked_rings += exact.counters().rings_corrected;
            }
        }
        assert!(
            known > checked / 10,
            "{moving}, {kick}: {known} of {checked} rings known within"
        );
        assert!(
            known < checked,
            "{moving}, {kick}: every ring was known within"
        );
        assert!(
            kicked_rings > 0,
            "{moving}, {kick}: the kicks put no ring past its tolerance"
        );
    }
}

/// The rings' checks belong to one set of clamp bounds: a pass that goes on from the bounds
/// in a body that is not quiet computes none and must not leave the next quiet pass to use
/// checks of earlier bounds, or none at all, as if they were these bounds'.
#[test]
fn ring_checks_are_ready_only_once_computed_for_their_bounds() {
    let mut body = shaken_body(0.3);
    body.volume_passes.clamp_bounds.always_carry = true;
    let first = (body.positions.clone(), body.velocities.clone());
    for step in 0..7 {
        body.begin_step();
        if step == 6 {
            // Back where the bounds were taken: no particle has drifted, the body is quiet.
            (body.positions, body.velocities) = first.clone();
        }
        let carried_before = body.volume_passes.clamp_bounds.carried_passes;
        body.one_ring_impulses(H, &mut [], &Serial);
        body.per_tet_impulses(H, &mut [], &Serial);
        body.integrate_positions(H, &Serial);
        let carried = body.volume_passes.clamp_bounds.carried_passes > carried_before;
        assert!(
            step == 0 || carried,
            "step {step}: the bounds were taken again"
        );
        let ready = body.volume_passes.clamp_bounds.ring_checks_ready;
        if step < 6 {
            assert_eq!(body.counters().ring_checks_skipped, 0, "step {step}");
            assert!(
                !ready,
                "step {step}: the rings' checks ready, none computed"
            );
        } else {
            assert!(ready, "the quiet pass did not compute the rings' checks");
        }
    }
}

/// Bounds are carried with up to one particle in `CARRY_STRAYS` past `CARRY_DRIFT` of its
/// radius, not with one more, and never with a broken predicted position or a radius at zero.
#[test]
fn bounds_are_carried_past_a_few_strays_only() {
    let n = 3 * CARRY_STRAYS + 17;
    let bounds = SafeRadii {
        start: vec![Vec3::ZERO; n],
        vertex_radius: vec![1.0; n],
        ..Default::default()
    };
    let within = Point4::new(Vec3::X * (0.99 * CARRY_DRIFT));
    let past = Point4::new(Vec3::Y * (1.01 * CARRY_DRIFT));
    let mut predicted = vec![within; n];
    assert!(bounds.near_start(&predicted).0);
    for stray in predicted.iter_mut().step_by(7).take(n / CARRY_STRAYS) {
        *stray = past;
    }
    assert!(
        bounds.near_start(&predicted).0,
        "3 strays of {n} are allowed"
    );
    *predicted.last_mut().unwrap() = past;
    assert!(!bounds.near_start(&predicted).0, "a fourth is not");
    let mut broken = vec![within; n];
    broken[5] = Point4::new(Vec3::NAN);
    assert!(!bounds.near_start(&broken).0, "a NaN predicted position");
    let mut flat = bounds.clone();
    flat.vertex_radius[9] = 0.0;
    assert!(
        !flat.near_start(&vec![within; n]).0,
        "a vertex without a radius"
    );
}

/// A body at rest with one interior particle thrown, before the one-ring pass or between
/// the passes: it and its neighbours drift far while the rest of the body does not move,
/// so impulses near it are clamped and those far from it skip the clamp. The far drifts
/// must not raise the bound the rest is checked against, and must still send the impulses
/// near them to the walk (see `FAR_DRIFT`): without the marks, both cases differ from the
/// walk without bounds (checked).
#[test]
fn impulses_near_a_far_drift_are_clamped_as_without_bounds() {
    let (mut skipped, mut clamped) = (0, 0);
    for (throw, between_passes) in [(Vec3::X * 6.0, true), (Vec3::Y * 48.0, false)] {
        let mut fast = shaken_body(0.0);
        use_impulses(
            &mut fast,
            ImpulseSettings {
                gamma: 1.0,
                ..ImpulseSettings::PAPER
            },
        );
        // The middle particle of the 5 x 5 x 5 grid.
        let thrown = 2 + 5 * (2 + 5 * 2);
        if !between_passes {
            fast.velocities[thrown] += throw;
        }
        let mut exact = fast.clone();
        exact.volume_passes.clamp_bounds.disabled = true;
        for body in [&mut fast, &mut exact] {
            body.begin_step();
            body.one_ring_impulses(H, &mut [], &Serial);
            if between_passes {
                body.velocities[thrown] += throw;
            }
            body.per_tet_impulses(H, &mut [], &Serial);
        }
        assert_eq!(fast.velocities, exact.velocities, "throw {throw}");
        let (f, e) = (fast.counters(), exact.counters());
        skipped += f.clamps_skipped;
        clamped += e.rings_clamped + e.tets_clamped;
    }
    assert!(skipped > 0, "the bounds were never used");
    assert!(clamped > 0, "nothing was clamped");
}

#[test]
fn kinematic_particles_are_not_moved() {
    let mut body = shaken_body(3.0);
    let v_before = body.velocities[0];
    body.set_kinematic(0, body.positions[0]).unwrap();
    body.refresh_predicted(H);
    for p in 0..body.positions.len() {
        body.pass_body()
            .ring_impulse(p, H, &exact(0.125, true), &mut []);
    }
    for t in 0..body.mesh.tet_count() {
        body.pass_body()
            .tet_impulse(t, H, &exact(0.125, true), &mut []);
    }
    assert_eq!(body.velocities[0], v_before);
}

#[test]
fn a_ring_within_tolerance_is_corrected_only_for_a_tet_past_the_ring_tet_tolerance() {
    // Moving an interior vertex alone changes its tets' volumes but not its ring's: the
    // tets gain on one side what they lose on the other.
    let ring_with_centre_moved = |by: f32| {
        let mut body = shaken_body(0.0);
        let centre = body.positions.iter().sum::<Vec3>() / body.positions.len() as f32;
        let p = (0..body.positions.len())
            .min_by(|&a, &b| {
                let (a, b) = (body.positions[a], body.positions[b]);
                a.distance(centre).total_cmp(&b.distance(centre))
            })
            .unwrap();
        body.velocities[p] = Vec3::new(1.0, 0.6, 0.3).normalize() * (by / H);
        body.refresh_predicted(H);
        let (mut ring, mut rest, mut worst) = (0.0, 0.0, 0.0f32);
        for &t in body.mesh.one_ring(p) {
            let v0 = body.mesh.rest_volumes()[t as usize];
            let v = predicted_volume(&body, t as usize);
            (ring, rest) = (ring + v, rest + v0);
            worst = worst.max((v - v0).abs() / v0);
        }
        (body, p, (ring - rest).abs() / rest, worst)
    };
    let paper = ImpulseSettings::PAPER;
    assert!(paper.tolerance < paper.ring_tet_tolerance);
    let (mut body, p, ring_error, worst) = ring_with_centre_moved(0.0003);
    assert!(ring_error < 0.1 * paper.tolerance, "{ring_error}");
    assert!(
        worst > paper.tolerance && worst < paper.ring_tet_tolerance,
        "{worst}"
    );
    let outcome = body.pass_body().ring_impulse(p, H, &paper, &mut []);
    assert!(matches!(outcome, ImpulseOutcome::Skipped), "{outcome:?}");
    // The rule before the ring tet tolerance: any tet past the tolerance.
    let before = ImpulseSettings {
        ring_tet_tolerance: paper.tolerance,
        ..paper
    };
    let outcome = body.pass_body().ring_impulse(p, H, &before, &mut []);
    assert!(!matches!(outcome, ImpulseOutcome::Skipped), "{outcome:?}");

    let (mut body, p, ring_error, worst) = ring_with_centre_moved(0.002);
    assert!(ring_error < 0.1 * paper.tolerance, "{ring_error}");
    assert!(worst > paper.ring_tet_tolerance, "{worst}");
    let outcome = body.pass_body().ring_impulse(p, H, &paper, &mut []);
    assert!(!matches!(outcome, ImpulseOutcome::Skipped), "{outcome:?}");
}

#[test]
fn tolerance_skips_small_errors_and_only_those() {
    let largest_error = |body: &SoftBodyState| {
        (0..body.mesh.tet_count())
            .map(|t| {
                let v0 = body.mesh.rest_volumes()[t];
                (predicted_volume(body, t) - v0).abs() / v0
            })
            .fold(0.0f32, f32::max)
    };
    let tolerance = ImpulseSettings::PAPER.tolerance;
    let mut gentle = shaken_body(0.0005);
    let error = largest_error(&gentle);
    assert!(error > 0.0 && error < tolerance, "{error}");
    let before = gentle.velocities().to_vec();
    gentle.one_ring_impulses(H, &mut [], &Serial);
    gentle.per_tet_impulses(H, &mut [], &Serial);
    assert_eq!(
        gentle.velocities(),
        &before[..],
        "errors within tolerance were corrected"
    );

    // The same body with no tolerance is corrected.
    use_impulses(&mut gentle, exact(0.125, true));
    gentle.one_ring_impulses(H, &mut [], &Serial);
    assert_ne!(gentle.velocities(), &before[..]);

    // The per-tet pass skips a tet whose correction, gamma times its error, is within the
    // tolerance: errors up to eight times the tolerance with the paper's gamma = 1/8.
    for (gamma, corrected) in [(0.125, false), (1.0, true)] {
        let mut body = shaken_body(0.01);
        let error = largest_error(&body);
        assert!(error > tolerance && error < 8.0 * tolerance, "{error}");
        let per_tet_only = ImpulseSettings {
            one_ring: false,
            gamma,
            ..ImpulseSettings::PAPER
        };
        use_impulses(&mut body, per_tet_only);
        let before = body.velocities().to_vec();
        body.per_tet_impulses(H, &mut [], &Serial);
        assert_eq!(body.velocities() != &before[..], corrected, "gamma {gamma}");
    }

    // Errors above the tolerance are corrected with it.
    let mut shaken = shaken_body(0.05);
    assert!(largest_error(&shaken) > tolerance);
    let before = shaken.velocities().to_vec();
    shaken.one_ring_impulses(H, &mut [], &Serial);
    shaken.per_tet_impulses(H, &mut [], &Serial);
    assert_ne!(shaken.velocities(), &before[..]);
    assert!(largest_error(&shaken) < largest_error(&shaken_body(0.05)));
}
