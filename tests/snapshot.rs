//! Save and restore (`SoftBodySnapshot`, feature `serialize`): a scene saved mid-run and
//! restored into a new app steps bit for bit as the scene that was never stopped, on 1, 2 and
//! 4 threads; a snapshot of another mesh, of another version or damaged is an error that
//! changes nothing, never a panic.

use std::process::Command;
use std::sync::Arc;
use std::time::Duration;

use bevy::app::{TaskPoolOptions, TaskPoolPlugin};
use bevy::prelude::*;
use bevy_soft_body::core::{SNAPSHOT_VERSION, SoftBodyState, box_grid};
use bevy_soft_body::prelude::*;

const CHILD: &str = "BEVY_SOFT_BODY_SNAPSHOT_CHILD";

/// Steps before the snapshot and after it.
const BEFORE: usize = 150;
const AFTER: usize = 200;

/// A scene with every state a step carries to the next: a jelly cube (spawned scaled) falling
/// on a flesh slab (soft contacts and their friction), a plastic bar dented by a rigid sphere,
/// a hard rubber cube resting alone on the ground (asleep when the snapshot is taken).
fn scene(threads: usize) -> App {
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
    ));
    let grid = |cells: UVec3| box_grid(cells, Vec3::splat(0.05), Vec3::ZERO).unwrap();
    let world = app.world_mut();
    let slab = SoftBody::new(grid(UVec3::new(6, 2, 6)).into(), SoftBodyMaterial::FLESH);
    world.spawn((slab.unwrap(), Transform::default()));
    let jelly = SoftBody::new(grid(UVec3::splat(3)).into(), SoftBodyMaterial::JELLY);
    world.spawn((
        jelly.unwrap(),
        Transform::from_xyz(0.08, 0.15, 0.08).with_scale(Vec3::splat(1.2)),
    ));
    let plastic = SoftBodyMaterial {
        plasticity: Some(Plasticity {
            yield_strain: 0.01,
            creep: 5.0,
            max_strain: 0.3,
        }),
        ..SoftBodyMaterial::paper(1000.0, 0.2, 1.0)
    };
    let bar = SoftBody::new(grid(UVec3::new(6, 2, 2)).into(), plastic);
    world.spawn((bar.unwrap(), Transform::from_xyz(0.6, 0.0, 0.0)));
    world.spawn((
        RigidSphere::new(0.06, 3.0),
        Transform::from_xyz(0.75, 0.3, 0.05),
    ));
    let cube = SoftBody::new(grid(UVec3::splat(2)).into(), SoftBodyMaterial::HARD_RUBBER);
    world.spawn((cube.unwrap(), Transform::from_xyz(-0.5, 0.0, 0.0)));
    world.spawn((StaticCollider::ground(0.8), Transform::default()));
    app
}

/// Every body's particles and the sphere's position, as bits.
fn positions(app: &mut App) -> Vec<u32> {
    let world = app.world_mut();
    let mut bits = Vec::new();
    for body in world.query::<&SoftBody>().iter(world) {
        for p in body.state().positions() {
            bits.extend(p.to_array().map(f32::to_bits));
        }
    }
    for (_, t) in world.query::<(&RigidSphere, &Transform)>().iter(world) {
        bits.extend(t.translation.to_array().map(f32::to_bits));
    }
    bits
}

/// Runs the scene, saves it after [`BEFORE`] steps (through postcard's bytes), restores it
/// into a new app and checks both run the same [`AFTER`] steps. Returns the positions.
fn save_and_restore(threads: usize) -> Vec<u32> {
    let mut first = scene(threads);
    for _ in 0..BEFORE {
        first.update();
    }
    let world = first.world_mut();
    let saved: Vec<Vec<u8>> = (world.query::<&SoftBody>().iter(world))
        .map(|b| postcard::to_allocvec(&b.snapshot()).unwrap())
        .collect();
    let sleeping = (world.query::<&SoftBody>().iter(world))
        .filter(|b| b.state().is_sleeping())
        .count();
    assert!(sleeping >= 1, "the resting cube should sleep by now");
    let (sphere, sphere_at) = world
        .query::<(&RigidSphere, &Transform)>()
        .single(world)
        .map(|(s, t)| (s.clone(), *t))
        .unwrap();
    for _ in 0..AFTER {
        first.update();
    }
    let expected = positions(&mut first);

    // A new app: the same entities spawned, the first update places them, then the save.
    let mut second = scene(threads);
    second.update();
    let world = second.world_mut();
    let mut bodies = world.query::<&mut SoftBody>();
    for (mut body, bytes) in bodies.iter_mut(world).zip(&saved) {
        let snapshot: SoftBodySnapshot = postcard::from_bytes(bytes).unwrap();
        body.restore(&snapshot).unwrap();
    }
    let (mut s, mut t) = world
        .query::<(&mut RigidSphere, &mut Transform)>()
        .single_mut(world)
        .unwrap();
    (*s, *t) = (sphere, sphere_at);
    for _ in 0..AFTER {
        second.update();
    }
    let restored = positions(&mut second);
    assert_eq!(restored.len(), expected.len());
    let differ = expected.iter().zip(&restored).filter(|(a, b)| a != b);
    assert_eq!(differ.count(), 0, "the restored scene took other steps");
    expected
}

#[test]
fn a_restored_scene_steps_as_the_one_never_stopped_on_any_thread_count() {
    if let Ok(threads) = std::env::var(CHILD) {
        let bits = save_and_restore(threads.parse().unwrap());
        let hash = bits.iter().fold(0xcbf29ce484222325u64, |h, &b| {
            (h ^ b as u64).wrapping_mul(0x100000001b3)
        });
        println!("result {} {hash:016x}", bits.len());
        return;
    }
    let run = |threads: &str| {
        let out = Command::new(std::env::current_exe().unwrap())
            .args([
                "a_restored_scene_steps_as_the_one_never_stopped_on_any_thread_count",
                "--exact",
                "--nocapture",
            ])
            .env(CHILD, threads)
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(
            out.status.success(),
            "child with {threads} threads failed: {stdout}{stderr}"
        );
        stdout
            .lines()
            .find_map(|l| l.strip_prefix("result ").map(str::to_owned))
            .unwrap_or_else(|| panic!("no result from the child with {threads} threads"))
    };
    let one = run("1");
    for threads in ["2", "4"] {
        assert_eq!(run(threads), one, "{threads} threads differ from one");
    }
}

/// A small jelly that has fallen on the ground for a while, and its snapshot.
fn jelly_on_ground() -> (SoftBodyState, bevy_soft_body::core::StateSnapshot) {
    let mesh = box_grid(UVec3::splat(2), Vec3::splat(0.1), Vec3::ZERO).unwrap();
    let mut body = SoftBodyState::new(Arc::new(mesh), SoftBodyMaterial::JELLY).unwrap();
    body.translate(Vec3::Y * 0.2);
    let ground = [bevy_soft_body::core::ColliderInstance::new(
        parry3d::shape::SharedShape::halfspace(Vec3::Y),
        parry3d::math::Pose::IDENTITY,
        0.8,
    )];
    for _ in 0..30 {
        body.step_with_contacts(
            1.0 / 60.0,
            Vec3::new(0.0, -9.81, 0.0),
            &mut [],
            &ground,
            &bevy_soft_body::core::Serial,
        );
    }
    let snapshot = body.snapshot();
    (body, snapshot)
}

#[test]
fn a_snapshot_of_another_mesh_or_version_is_refused_and_changes_nothing() {
    let (_, snapshot) = jelly_on_ground();
    let other = box_grid(UVec3::splat(3), Vec3::splat(0.1), Vec3::ZERO).unwrap();
    let mut other = SoftBodyState::new(Arc::new(other), SoftBodyMaterial::FLESH).unwrap();
    other.translate(Vec3::X);
    let before = (other.positions().to_vec(), *other.material());
    let refused = other.restore(&snapshot);
    assert!(
        matches!(refused, Err(SnapshotError::OtherMesh { .. })),
        "{refused:?}"
    );
    assert_eq!((other.positions().to_vec(), *other.material()), before);

    // The same particles and tets, one rest position moved: another mesh all the same.
    let mut moved = box_grid(UVec3::splat(2), Vec3::splat(0.1), Vec3::ZERO)
        .unwrap()
        .positions()
        .to_vec();
    moved[4].x += 0.01;
    let tets = box_grid(UVec3::splat(2), Vec3::splat(0.1), Vec3::ZERO)
        .unwrap()
        .tets()
        .to_vec();
    let moved = TetMesh::new(moved, tets).unwrap();
    let mut moved = SoftBodyState::new(Arc::new(moved), SoftBodyMaterial::JELLY).unwrap();
    assert!(matches!(
        moved.restore(&snapshot),
        Err(SnapshotError::OtherMesh { .. })
    ));

    let (mut body, mut snapshot) = jelly_on_ground();
    let before = body.positions().to_vec();
    snapshot.version = SNAPSHOT_VERSION + 1;
    assert_eq!(
        body.restore(&snapshot),
        Err(SnapshotError::Version {
            found: SNAPSHOT_VERSION + 1,
            expected: SNAPSHOT_VERSION
        })
    );
    assert_eq!(body.positions(), &before[..]);
}

#[test]
fn a_damaged_snapshot_is_an_error_not_a_panic() {
    let (body, snapshot) = jelly_on_ground();
    let bytes = postcard::to_allocvec(&snapshot).unwrap();
    // Every truncation: the format refuses it (or, cut in a way that still decodes, the
    // restore refuses what does not fit).
    let mut refused = 0;
    for len in 0..bytes.len() {
        let decoded: Result<bevy_soft_body::core::StateSnapshot, _> =
            postcard::from_bytes(&bytes[..len]);
        if let Ok(s) = decoded {
            let mut target = body.clone();
            if target.restore(&s).is_err() {
                refused += 1;
            }
        } else {
            refused += 1;
        }
    }
    assert_eq!(refused, bytes.len(), "a truncated snapshot was restored");
    // Bytes changed at random (a fixed sequence): decoded or not, restored or not, then
    // stepped, never a panic; and a restore that is refused changes nothing.
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    let (mut decoded, mut restored) = (0, 0);
    for _ in 0..400 {
        let mut damaged = bytes.clone();
        for _ in 0..1 + next() % 4 {
            let at = (next() % damaged.len() as u64) as usize;
            damaged[at] = next() as u8;
        }
        let Ok(s) = postcard::from_bytes::<bevy_soft_body::core::StateSnapshot>(&damaged) else {
            continue;
        };
        decoded += 1;
        let mut target = body.clone();
        let before = target.snapshot();
        match target.restore(&s) {
            Ok(()) => {
                restored += 1;
                for _ in 0..5 {
                    target.step_free(1.0 / 60.0, Vec3::new(0.0, -9.81, 0.0));
                }
            }
            Err(_) => assert_eq!(target.snapshot(), before),
        }
    }
    println!("400 damaged: {decoded} decoded, {restored} restored");
    assert!(decoded > 0);
}

#[test]
fn a_snapshot_survives_a_text_format() {
    let (mut body, snapshot) = jelly_on_ground();
    let json = serde_json::to_string(&snapshot).unwrap();
    let back: bevy_soft_body::core::StateSnapshot = serde_json::from_str(&json).unwrap();
    assert_eq!(back, snapshot);
    body.restore(&back).unwrap();
}

#[test]
fn a_torn_body_restored_into_a_body_made_anew_steps_as_the_one_never_stopped() {
    use bevy_soft_body::core::{TearSettings, pieces};
    let mesh: Arc<TetMesh> = box_grid(UVec3::new(12, 2, 2), Vec3::splat(0.05), Vec3::ZERO)
        .unwrap()
        .into();
    let bar = || {
        let mut body = SoftBodyState::new(mesh.clone(), SoftBodyMaterial::JELLY).unwrap();
        body.set_tearing(Some(TearSettings::default()));
        body
    };
    let h = 1.0 / 60.0;
    // The ends held by the core's grabs and drawn apart until the bar is in two pieces.
    let ends = [Vec3::new(0.0, 0.05, 0.05), Vec3::new(0.6, 0.05, 0.05)];
    let mut first = bar();
    let patches = ends.map(|p| first.forces().grab_patch(p, 0.12));
    let pull = |body: &mut SoftBodyState, step: usize| {
        for (k, patch) in patches.iter().enumerate() {
            let side = if k == 0 { -1.0 } else { 1.0 };
            let target = ends[k] + Vec3::X * (side * h * step as f32);
            body.forces()
                .pull_patch(patch, target, [400.0, 40.0], f32::INFINITY, h);
        }
        body.step_free(h, Vec3::ZERO);
    };
    let mut step = 0;
    while pieces(first.mesh()).iter().max() == Some(&0) {
        step += 1;
        assert!(step < 200, "the bar never tore");
        pull(&mut first, step);
    }
    let saved = first.snapshot();
    let json = serde_json::to_string(&saved).unwrap();
    let mut second = bar();
    second
        .restore(&serde_json::from_str(&json).unwrap())
        .unwrap();
    assert_eq!(second.mesh().tets(), first.mesh().tets());
    for k in 1..=100 {
        pull(&mut first, step + k);
        pull(&mut second, step + k);
    }
    assert_eq!(first.positions(), second.positions());
    // Into a body of another mesh (the same grid, longer cells): refused, nothing changed.
    let other = box_grid(
        UVec3::new(12, 2, 2),
        Vec3::new(0.06, 0.05, 0.05),
        Vec3::ZERO,
    )
    .unwrap();
    let mut other = SoftBodyState::new(Arc::new(other), SoftBodyMaterial::JELLY).unwrap();
    let before = other.positions().to_vec();
    let refused = other.restore(&saved);
    assert!(
        matches!(refused, Err(SnapshotError::OtherMesh { .. })),
        "{refused:?}"
    );
    assert_eq!(other.positions(), &before[..]);
}
