//! Catching a body that runs away: particles far faster than any game motion, or a body
//! stretched to many times its size, is an unstable simulation (an explicit spring too stiff
//! for its step, a mesh the solver cannot hold), not physics. Such a body is put back in its
//! rest shape where it last was sane, at rest, and the step says so, so that the plugin can
//! report it (`SoftBodyErrorKind::Runaway`) instead of leaving it flying off to 1e13 m.

use glam::Vec3;

/// When a body counts as running away.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunawayLimits {
    /// Fastest particle speed, m/s. Default: 500 (faster than anything a soft body does in a
    /// game; an exploding body passes it within a few steps).
    pub max_speed: f32,
    /// Largest extent (the diagonal of the particles' bounding box) as a multiple of the rest
    /// shape's. Default: 10.
    pub max_stretch: f32,
}

impl Default for RunawayLimits {
    fn default() -> Self {
        RunawayLimits {
            max_speed: 500.0,
            max_stretch: 10.0,
        }
    }
}

/// What a step found when it caught a body running away, and where it put the body back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Runaway {
    /// The fastest particle's speed, m/s.
    pub speed: f32,
    /// The body's extent (bounding-box diagonal), m.
    pub extent: f32,
    /// Its rest extent, m.
    pub rest_extent: f32,
    /// Where its centre of mass was put back (its last sane centre).
    pub reset_to: Vec3,
}

/// What the runaway check reads of a body after a step: its fastest particle's speed, its
/// extent (bounding-box diagonal) and its centre of mass.
pub(crate) struct BodyMotion {
    pub(crate) speed: f32,
    pub(crate) extent: f32,
    pub(crate) centre: Vec3,
}

impl BodyMotion {
    /// Measures the particles at `positions` with `velocities` and `masses`.
    pub(crate) fn measure(positions: &[Vec3], velocities: &[Vec3], masses: &[f32]) -> Self {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        let mut max_speed2 = 0.0f32;
        let (mut weighted, mut mass) = (Vec3::ZERO, 0.0);
        for ((&x, &v), &m) in positions.iter().zip(velocities).zip(masses) {
            lo = lo.min(x);
            hi = hi.max(x);
            max_speed2 = max_speed2.max(v.length_squared());
            weighted += m * x;
            mass += m;
        }
        BodyMotion {
            speed: max_speed2.sqrt(),
            extent: (hi - lo).length(),
            centre: weighted / mass,
        }
    }
}

impl RunawayLimits {
    /// Whether a body of rest extent `rest_extent` moving as `motion` is within the limits.
    pub(crate) fn allow(&self, motion: &BodyMotion, rest_extent: f32) -> bool {
        motion.speed <= self.max_speed
            && motion.extent <= self.max_stretch * rest_extent
            && motion.centre.is_finite()
    }
}

/// Puts the particles back in their `rest` shape, translated so that the centre of mass is at
/// `sane_centre` (the rest shape's own centre if the body never was sane). Returns that centre.
pub(crate) fn put_back_at_rest(
    rest: &[Vec3],
    masses: &[f32],
    sane_centre: Option<Vec3>,
    positions: &mut [Vec3],
) -> Vec3 {
    let mass: f32 = masses.iter().sum();
    let rest_centre = rest.iter().zip(masses).map(|(&x, &m)| m * x).sum::<Vec3>() / mass;
    let reset_to = sane_centre.unwrap_or(rest_centre);
    for (x, &x0) in positions.iter_mut().zip(rest) {
        *x = x0 - rest_centre + reset_to;
    }
    reset_to
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use glam::{UVec3, Vec3};

    use crate::core::body::SoftBodyState;
    use crate::core::{SoftBodyMaterial, box_grid};

    #[test]
    fn an_exploding_body_is_put_back_at_rest_where_it_was_sane() {
        let mesh = Arc::new(box_grid(UVec3::splat(3), Vec3::splat(0.1), Vec3::ZERO).unwrap());
        // The paper's explicit springs far too stiff for the step: they explode.
        let material = SoftBodyMaterial::paper(100.0, 1e4, 0.0);
        let mut body = SoftBodyState::new(mesh, material).unwrap();
        body.translate(Vec3::new(5.0, 2.0, 0.0));
        let start = body.centre_of_mass();
        // A kick to start it.
        body.velocities_mut()[0] = Vec3::new(0.5, 0.0, 0.0);
        let mut caught = None;
        for step in 0..500 {
            body.step_free(0.01, Vec3::ZERO);
            let extent = body
                .positions()
                .iter()
                .fold(0.0f32, |a, p| a.max(p.length()));
            assert!(extent < 100.0, "step {step}: a particle is {extent} m out");
            if let Some(r) = body.runaway() {
                caught = Some(r);
                break;
            }
        }
        let r = caught.expect("the explosion was not caught");
        assert!(r.speed > 500.0 || r.extent > 10.0 * r.rest_extent, "{r:?}");
        // Back in its rest shape, at rest, near where it started (it drifts only while sane).
        assert!(body.velocities().iter().all(|v| *v == Vec3::ZERO));
        assert!(body.centre_of_mass().distance(start) < 0.5, "{r:?}");
        assert!(body.volume_metrics().volume_error_pct.abs() < 1e-3);
        // A sane step after it reports nothing.
        body.set_material(SoftBodyMaterial::JELLY).unwrap();
        body.step_free(0.01, Vec3::ZERO);
        assert_eq!(body.runaway(), None);
    }

    #[test]
    fn a_fast_but_sane_body_is_left_alone() {
        let mesh = Arc::new(box_grid(UVec3::splat(3), Vec3::splat(0.1), Vec3::ZERO).unwrap());
        let mut body = SoftBodyState::new(mesh, SoftBodyMaterial::RUBBER).unwrap();
        body.velocities_mut().fill(Vec3::new(200.0, 0.0, 0.0));
        for _ in 0..10 {
            body.step_free(1.0 / 60.0, Vec3::new(0.0, -9.81, 0.0));
            assert_eq!(body.runaway(), None);
        }
        assert!(body.centre_of_mass().x > 30.0);
    }
}
