//! A step allocates nothing once the first step has sized its buffers: the core's promise
//! ("no allocation in the step"), checked with a counting global allocator. Only the test's own
//! thread is counted, where the steps run (on one thread, `Serial`): the test harness's thread
//! allocates for its bookkeeping while the test runs, and counted too, it made the test fail
//! about one run in ten (4 allocations, whichever method was being stepped then).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

use bevy_soft_body::core::{
    ColliderInstance, RigidSphereState, Serial, SoftBodyMaterial, SoftBodyState, VolumeMethod,
    box_grid,
};
use glam::{UVec3, Vec3};
use parry3d::math::Pose;
use parry3d::shape::SharedShape;

struct Counting;

thread_local! {
    /// Whether this thread's allocations are counted.
    static COUNTING: Cell<bool> = const { Cell::new(false) };
}
static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn steps_allocate_nothing_after_the_first() {
    // The paper's springs and a physical material (its shape in substeps), every method.
    let materials = [
        SoftBodyMaterial::paper(1000.0, 1.0, 1.0),
        SoftBodyMaterial::JELLY,
    ];
    for (base, method) in materials.into_iter().flat_map(|m| {
        [
            VolumeMethod::PAPER_BASELINE,
            VolumeMethod::PAPER_IMPULSES,
            VolumeMethod::XPBD,
            VolumeMethod::XPBD_CLUSTERS,
        ]
        .map(|method| (m, method))
    }) {
        let mesh = box_grid(UVec3::new(6, 4, 5), Vec3::splat(0.1), Vec3::ZERO).unwrap();
        let material = SoftBodyMaterial {
            method,
            plasticity: Some(bevy_soft_body::core::Plasticity {
                yield_strain: 0.01,
                creep: 4.0,
                max_strain: 0.5,
            }),
            ..base
        };
        let mut body = SoftBodyState::new(mesh.into(), material).unwrap();
        // Squeezed and falling on the ground with a sphere landing on it: every pass has work.
        for (p, v) in body.positions().to_vec().iter().zip(body.velocities_mut()) {
            *v = Vec3::new(if p.x < 0.3 { 1.0 } else { -1.0 }, -1.0, 0.0);
        }
        let mut spheres = vec![RigidSphereState {
            position: Vec3::new(0.3, 0.55, 0.25),
            velocity: Vec3::new(0.0, -1.0, 0.0),
            radius: 0.2,
            inv_mass: 1.0 / 20.0,
            friction: 0.5,
        }];
        let colliders = vec![ColliderInstance::new(
            SharedShape::halfspace(Vec3::Y),
            Pose::from_parts(Vec3::new(0.0, -0.05, 0.0), glam::Quat::IDENTITY),
            0.8,
        )];
        let gravity = Vec3::new(0.0, -9.81, 0.0);
        body.step_with_contacts(0.01, gravity, &mut spheres, &colliders, &Serial);
        ALLOCATIONS.store(0, Ordering::Relaxed);
        COUNTING.with(|c| c.set(true));
        for _ in 0..50 {
            body.step_with_contacts(0.01, gravity, &mut spheres, &colliders, &Serial);
        }
        COUNTING.with(|c| c.set(false));
        let contacts = body.contacts().count();
        let allocations = ALLOCATIONS.load(Ordering::Relaxed);
        assert_eq!(
            allocations,
            0,
            "{} allocated {allocations} times",
            method.name()
        );
        // The steps did meet the ground and the sphere.
        assert!(contacts > 0);
    }
}
