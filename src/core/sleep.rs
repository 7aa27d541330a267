//! Sleeping: a body that has come to rest stops being stepped until something disturbs it, as
//! rigid bodies do in every physics engine (avian, rapier, Jolt). A jelly resting on the
//! ground then costs nothing a step, where stepping it would cost as much as a moving one.
//!
//! A body stepped in substeps (a physical material, or XPBD) falls asleep once every particle
//! has stayed within `speed * time` of where it stood for [`SleepSettings::time`] (its mean
//! speed over that time under [`SleepSettings::speed`]); its velocities are then zero and its
//! positions stay as they are. The test is on positions, not on the particles' velocities: a
//! resting body under the paper's impulses keeps small velocities that come and go (each
//! substep's volume correction against the edges' sag) while its particles stay within a
//! fraction of a millimetre (PERFORMANCE.md). It wakes when a step finds it disturbed:
//! gravity changed, a kinematic particle asked to move, a rigid sphere within reach of its
//! bounds, a collider near it moved, appeared or went away; or when the game touches it
//! (`SoftBodyState::velocities_mut`, `translate`, `map_positions`, `set_material`,
//! `wake_up`). A sphere in reach keeps it
//! awake: a sleeping body would not hold a sphere up. The paper's explicit springs never sleep,
//! so its scenes run as published.

use std::hash::{Hash, Hasher};

use glam::Vec3;
use parry3d::bounding_volume::{Aabb, BoundingVolume};

use super::colliders::{ColliderInstance, RigidSphereState};
use super::snapshot::SleepSnapshot;

/// When a body falls asleep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SleepSettings {
    /// The mean speed, m/s, under which every particle must stay: it may not move further
    /// than `speed * time` from where it stood. Default: 0.01 (5 mm in half a second, so a
    /// visible wobble is not frozen).
    pub speed: f32,
    /// How long, s, every particle must stay that still. Default: 0.5 (Jolt's
    /// `mTimeBeforeSleep`).
    pub time: f32,
}

impl Default for SleepSettings {
    fn default() -> Self {
        SleepSettings {
            speed: 0.01,
            time: 0.5,
        }
    }
}

/// A body's sleep: how long it has been quiet, and while asleep what it was asleep in.
#[derive(Clone, Debug, Default)]
pub(crate) struct Sleep {
    /// `None`: the body never sleeps.
    pub(crate) settings: Option<SleepSettings>,
    /// Seconds every particle has stayed near its place in `still_at`.
    quiet_for: f32,
    /// Where the particles stood when the body's quiet time began (sized once, with the body).
    still_at: Vec<Vec3>,
    /// Whether the body is asleep.
    pub(crate) asleep: bool,
    /// Whether it fell asleep at the end of the last step: the step's last contacts between
    /// bodies still meet it (`soft_contacts.rs`), or what that step's end pushed into a
    /// neighbour falling asleep with it would stay there.
    pub(crate) fell_asleep_now: bool,
    /// While asleep: its bounds grown by the reach, the gravity it fell asleep in, and a
    /// fingerprint of the colliders within the bounds (`None` for a body restored asleep from
    /// a snapshot: the colliders it meets at its first step are the ones it sleeps among, as
    /// the fingerprint holds the shapes' addresses, which no save keeps).
    bounds: Option<Aabb>,
    gravity: Vec3,
    colliders: Option<u64>,
}

impl Sleep {
    /// Awake, sleeping by `settings`, for a body of `particles` particles.
    pub(crate) fn new(settings: Option<SleepSettings>, particles: usize) -> Sleep {
        Sleep {
            settings,
            still_at: vec![Vec3::NAN; particles],
            ..Default::default()
        }
    }

    /// Wakes the body (or keeps it awake) and restarts its quiet time.
    pub(crate) fn wake(&mut self) {
        self.asleep = false;
        self.quiet_for = 0.0;
        self.bounds = None;
    }

    /// Wakes the body but keeps its quiet time: for a body touched by an awake one, so that
    /// bodies resting on each other fall asleep together, in the step the last of them has
    /// been quiet long enough (as rigid-body engines put an island to sleep), instead of each
    /// waking the others with a quiet time begun anew (a pile then never slept).
    pub(crate) fn stir(&mut self) {
        self.asleep = false;
        self.bounds = None;
    }
}

/// A fingerprint of the colliders whose bounds touch `bounds`: their number, shapes' addresses,
/// poses and friction. Any of them moving, changing, appearing or going away changes it.
fn colliders_near(bounds: &Aabb, colliders: &[ColliderInstance]) -> u64 {
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    for c in colliders.iter().filter(|c| c.aabb.intersects(bounds)) {
        (std::sync::Arc::as_ptr(&c.shape.0) as *const () as usize).hash(&mut hasher);
        let (t, r) = (c.pose.translation, c.pose.rotation);
        for v in [t.x, t.y, t.z, r.x, r.y, r.z, r.w, c.friction] {
            v.to_bits().hash(&mut hasher);
        }
        0xffu8.hash(&mut hasher);
    }
    hasher.finish()
}

impl Sleep {
    /// The mean speed under which the body counts as still (0 if it never sleeps).
    pub(crate) fn speed_or_zero(&self) -> f32 {
        self.settings.map_or(0.0, |s| s.speed)
    }

    /// At the start of a substepped step of `h`, for a body in `gravity` (`moved_kinematic`:
    /// a kinematic particle asked to move further than the sleep speed allows): wakes it if
    /// asleep and the step disturbs it. Returns whether it still sleeps (the step then leaves
    /// it alone, its velocities zero).
    pub(crate) fn stays_asleep(
        &mut self,
        h: f32,
        moved_kinematic: bool,
        gravity: Vec3,
        spheres: &[RigidSphereState],
        colliders: &[ColliderInstance],
    ) -> bool {
        self.fell_asleep_now = false;
        if !self.asleep {
            return false;
        }
        let Some(bounds) = self.bounds else {
            self.wake();
            return false;
        };
        let sphere_near = spheres.iter().any(|s| {
            let reach = s.radius + h * s.velocity.length();
            bounds.contains_local_point(s.position)
                || Aabb::new(
                    s.position - Vec3::splat(reach),
                    s.position + Vec3::splat(reach),
                )
                .intersects(&bounds)
        });
        let disturbed = gravity != self.gravity
            || moved_kinematic
            || sphere_near
            || *self
                .colliders
                .get_or_insert_with(|| colliders_near(&bounds, colliders))
                != colliders_near(&bounds, colliders);
        if disturbed {
            self.wake();
            return false;
        }
        true
    }

    /// At the end of a substepped step of `h`, for a body of rest extent `rest_extent` at
    /// `positions` in `gravity`: counts the time every particle has stayed within reach of
    /// where it stood when the quiet time began (starting it anew from here when one has not),
    /// and puts the body to sleep once that is long enough and no sphere is within reach.
    /// Returns whether it fell asleep now (its velocities are then to be zeroed).
    pub(crate) fn update(
        &mut self,
        h: f32,
        positions: &[Vec3],
        rest_extent: f32,
        gravity: Vec3,
        spheres: &[RigidSphereState],
        colliders: &[ColliderInstance],
    ) -> bool {
        let Some(settings) = self.settings else {
            return false;
        };
        let reach = settings.speed * settings.time;
        let moved = self.quiet_for == 0.0
            || positions
                .iter()
                .zip(&self.still_at)
                .any(|(x, still)| x.distance_squared(*still) > reach * reach);
        if moved {
            self.still_at.copy_from_slice(positions);
            self.quiet_for = h;
            return false;
        }
        self.quiet_for += h;
        if self.quiet_for < settings.time {
            return false;
        }
        let bounds = reach_bounds(positions, rest_extent);
        let sphere_near = spheres.iter().any(|s| {
            Aabb::new(
                s.position - Vec3::splat(s.radius),
                s.position + Vec3::splat(s.radius),
            )
            .intersects(&bounds)
        });
        if sphere_near {
            return false;
        }
        self.asleep = true;
        self.fell_asleep_now = true;
        self.bounds = Some(bounds);
        self.gravity = gravity;
        self.colliders = Some(colliders_near(&bounds, colliders));
        true
    }

    /// What a snapshot keeps of it (`snapshot.rs`).
    pub(crate) fn snapshot(&self) -> SleepSnapshot {
        SleepSnapshot {
            asleep: self.asleep,
            quiet_for: self.quiet_for,
            still_at: if self.quiet_for > 0.0 {
                self.still_at.clone()
            } else {
                Vec::new()
            },
            bounds: self.bounds.map(|b| [b.mins, b.maxs]),
            gravity: self.gravity,
        }
    }

    /// Back to what `snapshot` kept; its settings stay. `snapshot` was checked to fit.
    pub(crate) fn restore(&mut self, snapshot: &SleepSnapshot) {
        self.asleep = snapshot.asleep;
        self.quiet_for = snapshot.quiet_for;
        if snapshot.still_at.is_empty() {
            self.still_at.fill(Vec3::NAN);
            self.quiet_for = 0.0;
        } else {
            self.still_at.copy_from_slice(&snapshot.still_at);
        }
        self.bounds = snapshot.bounds.map(|[lo, hi]| Aabb::new(lo, hi));
        self.gravity = snapshot.gravity;
        self.colliders = None;
    }
}

/// The bounds of `positions` grown by how far a sphere or collider may be and still disturb
/// the body: a tenth of its rest extent.
fn reach_bounds(positions: &[Vec3], rest_extent: f32) -> Aabb {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for &x in positions {
        lo = lo.min(x);
        hi = hi.max(x);
    }
    Aabb::new(lo, hi).loosened(0.1 * rest_extent)
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use glam::{UVec3, Vec3};
    use parry3d::math::Pose;
    use parry3d::shape::SharedShape;

    use super::*;
    use crate::core::{Serial, SoftBodyMaterial, SoftBodyState, box_grid};

    fn ground() -> ColliderInstance {
        ColliderInstance::new(SharedShape::halfspace(Vec3::Y), Pose::IDENTITY, 0.8)
    }

    /// A 0.3 m jelly cube resting on the ground, stepped at 60 Hz until it sleeps (at most
    /// `seconds`); returns the steps it took, if it fell asleep.
    fn settle(
        body: &mut SoftBodyState,
        seconds: f32,
        colliders: &[ColliderInstance],
    ) -> Option<u32> {
        let g = Vec3::new(0.0, -9.81, 0.0);
        for step in 0..(seconds * 60.0) as u32 {
            body.step_with_contacts(1.0 / 60.0, g, &mut [], colliders, &Serial);
            if body.is_sleeping() {
                return Some(step);
            }
        }
        None
    }

    fn jelly() -> SoftBodyState {
        let mesh = box_grid(UVec3::splat(4), Vec3::splat(0.075), Vec3::ZERO).unwrap();
        let mut body = SoftBodyState::new(Arc::new(mesh), SoftBodyMaterial::JELLY).unwrap();
        body.translate(Vec3::Y * 0.05);
        body
    }

    #[test]
    fn a_resting_jelly_falls_asleep_and_stays_where_it_is() {
        let colliders = [ground()];
        let mut body = jelly();
        let steps = settle(&mut body, 10.0, &colliders).expect("asleep within 10 s");
        assert!(
            steps > 30,
            "asleep after {steps} steps: before it landed and settled"
        );
        let before = body.positions().to_vec();
        for _ in 0..60 {
            body.step_with_contacts(
                1.0 / 60.0,
                Vec3::new(0.0, -9.81, 0.0),
                &mut [],
                &colliders,
                &Serial,
            );
        }
        assert!(body.is_sleeping());
        assert_eq!(body.positions(), &before[..]);
        assert!(body.velocities().iter().all(|v| *v == Vec3::ZERO));
    }

    #[test]
    fn a_sleeping_jelly_wakes_when_disturbed() {
        let g = Vec3::new(0.0, -9.81, 0.0);
        let colliders = [ground()];
        // A push from the game.
        let mut body = jelly();
        settle(&mut body, 10.0, &colliders).expect("asleep");
        body.velocities_mut()[0] = Vec3::X;
        assert!(!body.is_sleeping());
        // Gravity turned sideways.
        let mut body = jelly();
        settle(&mut body, 10.0, &colliders).expect("asleep");
        body.step_with_contacts(
            1.0 / 60.0,
            Vec3::new(3.0, -9.81, 0.0),
            &mut [],
            &colliders,
            &Serial,
        );
        assert!(!body.is_sleeping());
        // The ground taken away: it falls.
        let mut body = jelly();
        settle(&mut body, 10.0, &colliders).expect("asleep");
        let y = body.centre_of_mass().y;
        body.step_with_contacts(1.0 / 60.0, g, &mut [], &[], &Serial);
        assert!(!body.is_sleeping());
        assert!(body.centre_of_mass().y < y);
        // A sphere dropped on it.
        let mut body = jelly();
        settle(&mut body, 10.0, &colliders).expect("asleep");
        let mut sphere = [RigidSphereState {
            position: body.centre_of_mass() + Vec3::Y * 0.25,
            velocity: Vec3::new(0.0, -2.0, 0.0),
            radius: 0.05,
            inv_mass: 1.0,
            friction: 0.5,
        }];
        body.step_with_contacts(1.0 / 60.0, g, &mut sphere, &colliders, &Serial);
        assert!(!body.is_sleeping());
        // A pinned particle moved by the game.
        let mut body = jelly();
        settle(&mut body, 10.0, &colliders).expect("asleep");
        let target = body.positions()[0] + Vec3::Y * 0.1;
        body.set_kinematic(0, target).unwrap();
        body.step_with_contacts(1.0 / 60.0, g, &mut [], &colliders, &Serial);
        assert!(!body.is_sleeping());
    }

    #[test]
    fn sleeping_can_be_switched_off() {
        let colliders = [ground()];
        let mut body = jelly();
        body.set_sleep_settings(None);
        assert_eq!(settle(&mut body, 4.0, &colliders), None);
    }
}
