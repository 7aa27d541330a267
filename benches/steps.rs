//! `cargo bench`: one step of each paper scene's body with each method, timed by criterion,
//! from the state the scene has at its main event (the twist, the impact, the landing). Each
//! iteration steps a fresh copy of that state, so every sample times the same step.

use std::hint::black_box;

use bevy::prelude::*;
use bevy_soft_body::core::{
    ColliderInstance, RigidSphereState, Serial, SoftBodyState, VolumeMethod,
};
use bevy_soft_body::prelude::*;
use bevy_soft_body::scenes::{PaperScene, headless_scene_app};
use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use parry3d::math::Pose;

/// The body, spheres and colliders of `scene` after `seconds` of simulation.
fn snapshot(
    scene: PaperScene,
    method: VolumeMethod,
    seconds: f32,
) -> (SoftBodyState, Vec<RigidSphereState>, Vec<ColliderInstance>) {
    let (mut app, body) = headless_scene_app(scene, method);
    for _ in 0..(seconds * 100.0) as u32 {
        app.update();
    }
    let world = app.world_mut();
    let state = world.get::<SoftBody>(body).unwrap().state().clone();
    let spheres = world
        .query::<(&RigidSphere, &Transform)>()
        .iter(world)
        .map(|(s, t)| RigidSphereState {
            position: t.translation,
            velocity: s.velocity,
            radius: s.radius,
            inv_mass: if s.mass.is_finite() {
                1.0 / s.mass
            } else {
                0.0
            },
            friction: s.friction,
        })
        .collect();
    let colliders = world
        .query::<(&StaticCollider, &Transform)>()
        .iter(world)
        .map(|(c, t)| {
            ColliderInstance::new(
                c.shape.clone(),
                Pose::from_parts(t.translation, t.rotation),
                c.friction,
            )
        })
        .collect();
    (state, spheres, colliders)
}

fn steps(c: &mut Criterion) {
    // The moment of each scene's event: twisting, sphere landed, sphere in the cube, landing,
    // dent being made.
    let moments = [2.5, 1.0, 2.0, 1.5, 1.0];
    for (scene, seconds) in PaperScene::ALL.into_iter().zip(moments) {
        for method in [VolumeMethod::PAPER_BASELINE, VolumeMethod::PAPER_IMPULSES] {
            let (state, spheres, colliders) = snapshot(scene, method, seconds);
            let gravity = scene.gravity();
            c.bench_function(&format!("{}/{}", scene.name(), method.name()), |b| {
                b.iter_batched(
                    || (state.clone(), spheres.clone()),
                    |(mut state, mut spheres)| {
                        state.step_with_contacts(0.01, gravity, &mut spheres, &colliders, &Serial);
                        black_box(state)
                    },
                    BatchSize::LargeInput,
                )
            });
        }
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = steps
}
criterion_main!(benches);
