//! Results do not depend on the number of threads: the same scene, stepped with 1, 2 and 4
//! threads in Bevy's task pools (and on four held to one and to two by
//! `SoftBodyThreads::max_threads`), ends bit for bit the same, for several bodies sharing a
//! sphere (bodies in parallel), for one large body (its blocks in parallel) and for a pile of
//! jellies stepped together (their substeps in lockstep, bodies in parallel). The pools are
//! global to a process, so each thread count runs in a child process (this test binary again,
//! told by an environment variable what to do).

use std::process::Command;
use std::time::Duration;

use bevy::app::{TaskPoolOptions, TaskPoolPlugin};
use bevy::prelude::*;
use bevy_soft_body::core::{VolumeMethod, box_grid};
use bevy_soft_body::prelude::*;

const CHILD: &str = "BEVY_SOFT_BODY_THREADS_CHILD";

/// What a child process steps.
#[derive(Clone, Copy, PartialEq)]
enum Scene {
    /// Four bodies (two methods), a sphere landing across two of them, the ground.
    Bodies,
    /// One body of 8640 tets with a sphere landing on it.
    OneBody,
    /// Three jelly slabs and a jelly cube dropped in a stack: bodies stepped together, meeting
    /// each other.
    Pile,
}

/// Steps `scene` and returns every particle's and the sphere's final position and the last
/// step's contacts (in the order they came), as bits.
fn simulate(threads: usize, max_threads: usize, scene: Scene) -> Vec<u32> {
    let one_body = scene == Scene::OneBody;
    // `threads` threads in the compute pool, where the systems and the bodies run.
    let mut options = TaskPoolOptions::with_num_threads(threads + 2);
    options.compute.min_threads = threads;
    options.compute.max_threads = threads;
    let mut app = App::new();
    app.add_plugins((
        MinimalPlugins.set(TaskPoolPlugin {
            task_pool_options: options,
        }),
        SoftBodyPlugin::default(),
    ))
    .insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
        Duration::from_millis(10),
    ))
    .insert_resource(SoftBodyGravity(Vec3::new(0.0, -2.0, 0.0)))
    .insert_resource(SoftBodyThreads { max_threads });
    if one_body {
        let mesh = box_grid(UVec3::splat(12), Vec3::splat(0.05), Vec3::ZERO).unwrap();
        // Enough blocks for every thread.
        assert!(mesh.blocks().count() >= 16, "{}", mesh.blocks().count());
        let material = SoftBodyMaterial::paper(1000.0, 0.2, 1.0);
        app.world_mut().spawn((
            SoftBody::new(mesh.into(), material).unwrap(),
            Transform::from_xyz(0.0, 0.01, 0.0),
        ));
        app.world_mut().spawn((
            RigidSphere::new(0.25, 60.0),
            Transform::from_xyz(0.3, 0.9, 0.3),
        ));
    }
    let mesh: std::sync::Arc<_> = box_grid(UVec3::splat(4), Vec3::splat(0.1), Vec3::ZERO)
        .unwrap()
        .into();
    if scene == Scene::Pile {
        for (k, cells) in [UVec3::new(6, 2, 6); 3]
            .into_iter()
            .chain([UVec3::splat(3)])
            .enumerate()
        {
            let mesh = box_grid(cells, Vec3::splat(0.05), Vec3::ZERO).unwrap();
            let x = if k == 3 { 0.08 } else { 0.01 * (k % 2) as f32 };
            app.world_mut().spawn((
                SoftBody::new(mesh.into(), SoftBodyMaterial::JELLY).unwrap(),
                Transform::from_xyz(x, 0.11 * k as f32, x),
            ));
        }
    }
    for k in (0..4).filter(|_| scene == Scene::Bodies) {
        let method = if k % 2 == 0 {
            VolumeMethod::PAPER_IMPULSES
        } else {
            VolumeMethod::XPBD
        };
        let material = SoftBodyMaterial {
            method,
            ..Default::default()
        };
        app.world_mut().spawn((
            SoftBody::new(mesh.clone(), material).unwrap(),
            Transform::from_xyz(k as f32 * 0.45, 0.05, 0.0),
        ));
    }
    // Lands on the first two bodies at once.
    if scene == Scene::Bodies {
        app.world_mut().spawn((
            RigidSphere::new(0.2, 30.0),
            Transform::from_xyz(0.42, 0.75, 0.2),
        ));
    }
    app.world_mut()
        .spawn((StaticCollider::ground(0.6), Transform::default()));
    for _ in 0..120 {
        app.update();
    }
    let world = app.world_mut();
    let mut bits = Vec::new();
    for body in world.query::<&SoftBody>().iter(world) {
        for p in body.state().positions() {
            bits.extend(p.to_array().map(f32::to_bits));
        }
        // The particles in contact, in the order they came into contact.
        for (i, normal) in body.state().contacts() {
            bits.push(i as u32);
            bits.extend(normal.to_array().map(f32::to_bits));
        }
    }
    for (_, t) in world.query::<(&RigidSphere, &Transform)>().iter(world) {
        bits.extend(t.translation.to_array().map(f32::to_bits));
    }
    bits
}

/// Runs `test` in a child process per thread count (1, 2, 4, and 4 held to 1 and to 2) and
/// checks that all agree.
fn compare_thread_counts(test: &str, scene: Scene) {
    if let Ok(threads) = std::env::var(CHILD) {
        let (threads, max_threads) = match threads.split_once(" max ") {
            Some((threads, max)) => (threads, max.parse().unwrap()),
            None => (threads.as_str(), usize::MAX),
        };
        let bits = simulate(threads.parse().unwrap(), max_threads, scene);
        let hash = bits.iter().fold(0xcbf29ce484222325u64, |h, &b| {
            (h ^ b as u64).wrapping_mul(0x100000001b3)
        });
        println!("result {} {hash:016x}", bits.len());
        return;
    }
    let run = |threads: &str| {
        let out = Command::new(std::env::current_exe().unwrap())
            .args([test, "--exact", "--nocapture"])
            .env(CHILD, threads)
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(
            out.status.success(),
            "child with {threads} threads failed: {stdout}"
        );
        stdout
            .lines()
            .find_map(|l| l.strip_prefix("result ").map(str::to_owned))
            .unwrap_or_else(|| panic!("no result from the child with {threads} threads"))
    };
    let one = run("1");
    assert!(one.split(' ').next().unwrap().parse::<usize>().unwrap() > 1000);
    for threads in ["2", "4", "4 max 1", "4 max 2"] {
        assert_eq!(run(threads), one, "{threads} threads differ from one");
    }
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    compare_thread_counts("results_do_not_depend_on_the_thread_count", Scene::Bodies);
}

#[test]
fn a_pile_stepped_together_does_not_depend_on_the_thread_count() {
    compare_thread_counts(
        "a_pile_stepped_together_does_not_depend_on_the_thread_count",
        Scene::Pile,
    );
}

#[test]
fn one_body_in_blocks_does_not_depend_on_the_thread_count() {
    compare_thread_counts(
        "one_body_in_blocks_does_not_depend_on_the_thread_count",
        Scene::OneBody,
    );
}
