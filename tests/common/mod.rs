//! Helpers shared by the integration tests: run a paper scene through the plugin headless.

#![allow(dead_code)]

use bevy::prelude::*;
use bevy_soft_body::core::VolumeMethod;
use bevy_soft_body::prelude::*;
use bevy_soft_body::scenes::{PaperScene, headless_scene_app};

/// What a test wants to know about a scene run, sampled every step.
pub struct SceneRun {
    pub app: App,
    pub body: Entity,
    pub peak_error_pct: f64,
    /// Centre of mass height per step.
    pub com_y: Vec<f32>,
    /// Deepest particle below the ground (y < 0) over all steps, as a positive number.
    pub deepest_below_ground: f32,
}

/// Runs `scene` with `method` for `seconds` (its full duration if `None`).
pub fn run_scene(scene: PaperScene, method: VolumeMethod, seconds: Option<f32>) -> SceneRun {
    let (mut app, body) = headless_scene_app(scene, method);
    let steps = (seconds.unwrap_or(scene.duration_secs()) / 0.01).round() as usize;
    let mut com_y = Vec::with_capacity(steps);
    let mut deepest_below_ground = 0.0f32;
    for _ in 0..steps {
        app.update();
        let b = app.world().get::<SoftBody>(body).unwrap();
        com_y.push(b.state().centre_of_mass().y);
        let lowest = b
            .state()
            .positions()
            .iter()
            .map(|p| p.y)
            .fold(f32::INFINITY, f32::min);
        deepest_below_ground = deepest_below_ground.max(-lowest);
    }
    let stats = app.world().get::<SoftBodyStats>(body).unwrap();
    assert_eq!(stats.steps as usize, steps, "every update must be one step");
    assert_eq!(stats.counters.non_finite_velocities, 0);
    let peak_error_pct = stats.peak_volume_error_pct;
    SceneRun {
        app,
        body,
        peak_error_pct,
        com_y,
        deepest_below_ground,
    }
}

/// The rigid spheres of the app: (centre, radius, velocity).
pub fn spheres(app: &mut App) -> Vec<(Vec3, f32, Vec3)> {
    let world = app.world_mut();
    let mut q = world.query::<(&RigidSphere, &Transform)>();
    q.iter(world)
        .map(|(s, t)| (t.translation, s.radius, s.velocity))
        .collect()
}
