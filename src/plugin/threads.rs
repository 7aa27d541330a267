//! How a step uses the threads of Bevy's compute task pool: bodies in parallel, a large
//! body's passes in blocks, each parallel section a `scope` of the pool's tasks.
//!
//! A step has no threads of its own and keeps none awake. An earlier design kept the pool's
//! other threads spinning through a step (a "crew") so that no section waited for a thread to
//! wake up; it was measured no faster than plain scopes (PERFORMANCE.md, "Threads") and burned
//! a core a game could use, so it was removed.

use super::*;

/// Runs independent jobs (bodies, or the blocks of a volume pass, see `core::parallel`) on at
/// most `threads` threads of Bevy's compute task pool (see [`SoftBodyThreads::max_threads`]),
/// as tasks of one `scope`.
pub(super) struct ComputePool {
    /// The threads a step may use: the pool's, at most [`SoftBodyThreads::max_threads`], at
    /// least one (the system's own).
    pub(super) threads: usize,
}

impl ComputePool {
    pub(super) fn new(settings: &SoftBodyThreads) -> ComputePool {
        let pool = bevy::tasks::ComputeTaskPool::try_get().map_or(1, |pool| pool.thread_num());
        ComputePool {
            threads: pool.min(settings.max_threads).max(1),
        }
    }
}

impl Parallel for ComputePool {
    fn run(&self, jobs: usize, job: &(dyn Fn(usize) + Sync)) {
        if jobs < 2 || self.threads < 2 {
            return Serial.run(jobs, job);
        }
        match bevy::tasks::ComputeTaskPool::try_get() {
            Some(pool) if pool.thread_num() > 1 => {
                // One task per thread the step may use, each taking the next job as it comes
                // free (the thread calling `scope` may run one of them itself).
                let next = AtomicUsize::new(0);
                let next = &next;
                pool.scope(|scope| {
                    for _ in 0..self.threads.min(jobs) {
                        scope.spawn(async move {
                            loop {
                                let i = next.fetch_add(1, Ordering::Relaxed);
                                if i >= jobs {
                                    break;
                                }
                                job(i);
                            }
                        });
                    }
                });
            }
            _ => Serial.run(jobs, job),
        }
    }

    fn threads(&self) -> usize {
        // The thread calling `scope` (a pool thread, when a system runs on one) works too;
        // asking for more jobs than there are threads would only make them take turns.
        self.threads
    }
}

/// How the steps use the threads of Bevy's compute task pool.
#[derive(Resource, Clone, Copy, Debug, Reflect)]
#[reflect(Resource)]
pub struct SoftBodyThreads {
    /// The most threads of the compute pool a step uses, the system's own included: a game
    /// that wants cores left for its other systems sets it lower. `1` runs every stage on
    /// the system's thread; `0` is taken as `1` (a step always has its thread). The default,
    /// `usize::MAX`, uses the whole pool. A result does not depend on it (see
    /// `core::parallel`). It also lets a benchmark time one and two threads side by side in one
    /// process (the pool is one per process): `bench --threads 1,2`.
    pub max_threads: usize,
}

impl Default for SoftBodyThreads {
    fn default() -> Self {
        SoftBodyThreads {
            max_threads: usize::MAX,
        }
    }
}

/// Bodies with fewer tets than this run their volume passes on one thread: their blocks are
/// too small to pay for waking another (about 50 microseconds here), measured with the
/// `bench` example's 1k-tet box.
pub const PARALLEL_PASS_MIN_TETS: usize = 2000;

/// How the stages of each body use the threads: with fewer bodies than threads
/// (`few_bodies`), each large body's blocks (and chunks of particles) run in parallel too; with
/// more, the bodies alone keep the threads busy. The result is the same either way (see
/// `core::parallel`).
pub(super) fn pass_parallelism<'a>(
    few_bodies: bool,
    body: &SoftBodyState,
    compute: &'a ComputePool,
) -> &'a dyn Parallel {
    if few_bodies && body.mesh().tet_count() >= PARALLEL_PASS_MIN_TETS {
        compute
    } else {
        &Serial
    }
}

/// One body per task of [`writeback`]'s parallel query (the stages of a step run one body per
/// job through [`for_each_body`] instead). Bevy's default splits the bodies into one batch per
/// thread, which assumes they cost the same; they do not (a body resting on the ground costs
/// about twice what a falling one does).
pub(super) const ONE_BODY_PER_TASK: BatchingStrategy = BatchingStrategy::fixed(1);

/// The bodies as the stages of a step see them.
pub(super) type Bodies<'w, 's> =
    Query<'w, 's, (Entity, &'static mut SoftBody, &'static mut SoftBodyStats)>;

/// Whether there are fewer bodies than threads for the step.
pub(super) fn few_bodies(bodies: &Bodies, compute: &ComputePool) -> bool {
    bodies.iter().count() < compute.threads
}

/// Runs `run` on every body: one body per job on the compute task pool's threads, or a single
/// body on this thread (not handed to another, which may first
/// have to wake up). `order` is scratch for the bodies' entities.
pub(super) fn for_each_body(
    bodies: &mut Bodies,
    order: &mut Vec<Entity>,
    compute: &ComputePool,
    run: impl Fn((Mut<SoftBody>, Mut<SoftBodyStats>)) + Send + Sync,
) {
    order.clear();
    order.extend(bodies.iter().map(|(entity, _, _)| entity));
    if order.len() == 1 {
        bodies
            .iter_mut()
            .for_each(|(_, body, stats)| run((body, stats)));
        return;
    }
    let bodies = &*bodies;
    let order = &*order;
    compute.run(order.len(), &|i| {
        // SAFETY: each job reaches its own entity (`order` lists each body once), and this
        // function borrows the query mutably while the jobs run, so nothing else reaches it.
        if let Ok((_, body, stats)) = unsafe { bodies.get_unchecked(order[i]) } {
            run((body, stats));
        }
    });
}

/// Runs `pass` on every body in parallel, each against its own copy of the spheres as they were
/// before the stage, then gives each sphere the changes of its velocity that the bodies made, in
/// query order (the first body's result as it is, the others' as differences). Every body sees
/// the same spheres whatever ran before it, so the result does not depend on the number of
/// threads; with one body it is exactly the serial result. `pass` adds its contacts to the
/// stats.
pub(super) fn par_with_spheres(
    bodies: &mut Bodies,
    solver: &mut SolverSpheres,
    compute: &ComputePool,
    skip_stepped_together: bool,
    pass: impl Fn(&mut SoftBodyState, &mut SoftBodyStats, &mut [RigidSphereState], &[ColliderInstance])
    + Send
    + Sync,
) {
    solver.before.clear();
    solver.before.extend_from_slice(&solver.states);
    solver.rigid_before.clear();
    solver.rigid_before.extend_from_slice(&solver.rigid);
    let (before, colliders) = (&solver.before, &solver.colliders);
    let rigid_before = &solver.rigid_before;
    let run = |(mut body, mut stats): (Mut<SoftBody>, Mut<SoftBodyStats>)| {
        let body = &mut *body;
        let start = Instant::now();
        body.spheres.clear();
        body.spheres.extend_from_slice(before);
        let rigid = body.state.rigid_contacts_mut();
        for (mine, &id) in rigid.bodies.iter_mut().zip(&body.rigid_ids) {
            *mine = rigid_before[id as usize];
        }
        if skip_stepped_together && body.stepped_together {
            return;
        }
        pass(&mut body.state, &mut stats, &mut body.spheres, colliders);
        body.step_time += start.elapsed();
    };
    for_each_body(bodies, &mut solver.bodies, compute, run);
    // The rigid bodies get every soft body's changes, as differences (they start from the
    // same velocities), in query order.
    for (_, body, _) in bodies.iter() {
        let mine = &body.state.rigid_contacts().bodies;
        for (motion, &id) in mine.iter().zip(&body.rigid_ids) {
            let (all, old) = (&mut solver.rigid[id as usize], &rigid_before[id as usize]);
            all.linear_velocity += motion.linear_velocity - old.linear_velocity;
            all.angular_velocity += motion.angular_velocity - old.angular_velocity;
            all.position_correction += motion.position_correction - old.position_correction;
            all.rotation_correction += motion.rotation_correction - old.rotation_correction;
        }
    }
    if solver.states.is_empty() {
        return;
    }
    for (k, (_, body, _)) in bodies.iter().enumerate() {
        for ((sphere, mine), old) in solver.states.iter_mut().zip(&body.spheres).zip(before) {
            if k == 0 {
                sphere.velocity = mine.velocity;
            } else {
                sphere.velocity += mine.velocity - old.velocity;
            }
        }
    }
}

/// The compute task pool of this crate's unit tests: four threads, whichever test sets it up
/// first (the pool is process-wide, and a headless app's `TaskPoolPlugin` keeps a pool that
/// exists).
#[cfg(test)]
pub(crate) fn test_compute_pool() -> &'static bevy::tasks::ComputeTaskPool {
    bevy::tasks::ComputeTaskPool::get_or_init(|| {
        bevy::tasks::TaskPoolBuilder::new().num_threads(4).build()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;
    use std::sync::Mutex;
    use std::thread::ThreadId;

    /// The distinct threads that ran `jobs` jobs of a millisecond each through `compute`.
    fn threads_used(compute: &ComputePool, jobs: usize) -> usize {
        let seen = Mutex::new(HashSet::<ThreadId>::new());
        compute.run(jobs, &|_| {
            seen.lock().unwrap().insert(std::thread::current().id());
            // Long enough for every free thread to come and take a job.
            std::thread::sleep(Duration::from_millis(1));
        });
        seen.into_inner().unwrap().len()
    }

    #[test]
    fn a_step_uses_no_more_threads_than_max_threads() {
        let pool = test_compute_pool();
        assert_eq!(pool.thread_num(), 4);
        let limited = |max_threads| ComputePool::new(&SoftBodyThreads { max_threads });
        assert_eq!(limited(0).threads, 1);
        assert_eq!(limited(1).threads, 1);
        assert_eq!(limited(usize::MAX).threads, 4);
        // Without a limit the jobs spread over more than two threads (so the checks below can
        // fail), with one they stay on this thread, with two on at most two.
        // (256 jobs: at least 64 ms a thread, so that the pool's threads come in time even
        // while other tests keep both cores busy.)
        assert!(threads_used(&limited(usize::MAX), 256) > 2);
        assert_eq!(threads_used(&limited(1), 64), 1);
        assert!(threads_used(&limited(2), 64) <= 2);
    }
}
