//! [`SoftBodyPlugin`]: the systems that step every soft body, in ordered sets that mirror the
//! stages of a step, so that a game can put its own systems between them.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use bevy::app::PluginGroupBuilder;
use bevy::ecs::batching::BatchingStrategy;
use bevy::ecs::schedule::{InternedScheduleLabel, ScheduleLabel};
use bevy::platform::time::Instant;
use bevy::prelude::*;
use parry3d::math::Pose;

use crate::components::{
    DrivenParticles, PinnedParticles, RigidSphere, SoftBody, SoftBodyError, SoftBodyErrorKind,
    SoftBodyGravity, SoftBodyStats, StaticCollider,
};
use crate::core::{ColliderInstance, Parallel, RigidSphereState, Serial, SoftBodyState, TetMesh};
use crate::crew;

/// The old name of [`SoftBodySystems`].
#[deprecated(
    since = "0.2.0",
    note = "renamed `SoftBodySystems` (Bevy's naming of system sets)"
)]
pub type SoftBodySet = SoftBodySystems;

/// The stages of a step, run in this order in the plugin's schedule (see `core::body` for what
/// each does and why in this order).
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SoftBodySystems {
    /// Place new bodies, clear last step's counters, apply pinned and driven particles.
    Prepare,
    /// Gravity, the paper's springs with damping, baseline volume forces; the velocities of
    /// spheres.
    Forces,
    /// Contacts on the previewed positions, so the volume passes see them; a shape solved in
    /// substeps (a physical material's edges, XPBD's whole step) is solved here, meeting the
    /// contacts in each substep.
    Contacts,
    /// The one-ring volume impulses.
    OneRing,
    /// The per-tet correction scaled by gamma.
    PerTet,
    /// Plastic springs.
    Plasticity,
    /// A last contact pass, then `x += h v` for particles and spheres.
    Integrate,
    /// Metrics into [`SoftBodyStats`], transforms follow the bodies.
    Writeback,
}

/// The crate's plugins a game adds in one go: [`SoftBodyPlugin`] (the simulation), and with
/// feature `render` [`SoftBodySurfacePlugin`](crate::SoftBodySurfacePlugin) (render meshes that
/// follow the bodies) and [`SoftBodyAssetPlugin`](crate::SoftBodyAssetPlugin) (bodies from
/// meshes and files; it needs Bevy's asset and mesh plugins, as in `DefaultPlugins`). Each part
/// can be replaced or left out, as in any plugin group:
///
/// ```
/// use bevy::prelude::*;
/// use bevy_soft_body::prelude::*;
///
/// // The simulation in `FixedPostUpdate`, at the game's fixed rate.
/// let plugins = SoftBodyPlugins.set(SoftBodyPlugin::new(FixedPostUpdate));
/// // A headless server has no meshes to draw or assets to build bodies from.
/// #[cfg(feature = "render")]
/// let plugins = plugins
///     .disable::<SoftBodySurfacePlugin>()
///     .disable::<SoftBodyAssetPlugin>();
/// App::new().add_plugins((MinimalPlugins, plugins)).update();
/// ```
///
/// The debug gizmos ([`SoftBodyDebugPlugin`](crate::debug::SoftBodyDebugPlugin)) and the
/// inspector panel are not in the group: a game adds them while it needs them.
pub struct SoftBodyPlugins;

impl PluginGroup for SoftBodyPlugins {
    fn build(self) -> PluginGroupBuilder {
        let group = PluginGroupBuilder::start::<Self>().add(SoftBodyPlugin::default());
        #[cfg(feature = "render")]
        let group = group
            .add(crate::SoftBodySurfacePlugin)
            .add(crate::SoftBodyAssetPlugin::default());
        group
    }
}

/// Adds soft-body simulation to an app.
///
/// By default the simulation runs in [`FixedUpdate`] and sets the fixed time step to the
/// paper's 10 ms; each run of the schedule is one step of `Time::delta` (the fixed step there).
/// Gravity is the [`SoftBodyGravity`] resource.
pub struct SoftBodyPlugin {
    /// The schedule the stages run in.
    pub schedule: InternedScheduleLabel,
    /// If set and the schedule is [`FixedUpdate`], the fixed time step to use. `None` leaves
    /// `Time<Fixed>` as the game configured it.
    pub time_step: Option<Duration>,
}

impl Default for SoftBodyPlugin {
    fn default() -> Self {
        SoftBodyPlugin {
            schedule: FixedUpdate.intern(),
            time_step: Some(Duration::from_millis(10)),
        }
    }
}

impl SoftBodyPlugin {
    /// Runs the stages in `schedule` instead of [`FixedUpdate`].
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        SoftBodyPlugin {
            schedule: schedule.intern(),
            time_step: None,
        }
    }
}

/// How the plugin was set up, for systems outside the step (the render surfaces).
#[derive(Resource, Clone, Copy, Debug)]
pub struct SoftBodyTiming {
    /// Whether the steps run in [`FixedUpdate`], so that frames fall between steps and are
    /// drawn interpolated.
    pub fixed: bool,
}

impl Plugin for SoftBodyPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(SoftBodyTiming {
            fixed: self.schedule == FixedUpdate.intern(),
        });
        app.init_resource::<SoftBodyGravity>()
            .register_type::<SoftBodyGravity>()
            .register_type::<SoftBodyStats>()
            .register_type::<PinnedParticles>()
            .register_type::<DrivenParticles>()
            .register_type::<RigidSphere>()
            .init_resource::<SolverSpheres>()
            .init_resource::<SoftBodyStepTime>()
            .init_resource::<SoftBodyThreads>()
            .register_type::<SoftBodyThreads>()
            .register_type::<SoftBodyStepTime>()
            .register_type::<SoftBodyStageTimes>()
            .add_message::<SoftBodyError>();
        if let Some(step) = self.time_step
            && self.schedule == FixedUpdate.intern()
        {
            app.insert_resource(Time::<Fixed>::from_duration(step));
        }
        app.configure_sets(
            self.schedule,
            (
                SoftBodySystems::Prepare,
                SoftBodySystems::Forces,
                SoftBodySystems::Contacts,
                SoftBodySystems::OneRing,
                SoftBodySystems::PerTet,
                SoftBodySystems::Plasticity,
                SoftBodySystems::Integrate,
                SoftBodySystems::Writeback,
            )
                .chain(),
        );
        app.add_systems(
            self.schedule,
            (
                prepare.in_set(SoftBodySystems::Prepare),
                apply_forces.in_set(SoftBodySystems::Forces),
                resolve_contacts.in_set(SoftBodySystems::Contacts),
                one_ring.in_set(SoftBodySystems::OneRing),
                per_tet.in_set(SoftBodySystems::PerTet),
                plasticity.in_set(SoftBodySystems::Plasticity),
                integrate.in_set(SoftBodySystems::Integrate),
                writeback.in_set(SoftBodySystems::Writeback),
            ),
        );
    }
}

/// The body's rest mesh scaled by `scale`, or the error that makes that impossible.
fn scaled_mesh(mesh: &TetMesh, scale: Vec3) -> Result<TetMesh, crate::core::TetMeshError> {
    TetMesh::new(
        mesh.positions().iter().map(|&p| p * scale).collect(),
        mesh.tets().to_vec(),
    )
}

/// A body with its transform and its optional pinned and driven particles.
type PreparedBody<'a> = (
    Entity,
    &'a mut SoftBody,
    &'a mut Transform,
    Option<Ref<'a, PinnedParticles>>,
    Option<&'a mut DrivenParticles>,
);

/// Logs `error` and writes it as a message.
fn report(errors: &mut MessageWriter<SoftBodyError>, error: SoftBodyError) {
    error!("{error}");
    errors.write(error);
}

fn prepare(
    mut bodies: Query<PreparedBody>,
    targets: Query<&Transform, Without<SoftBody>>,
    mut errors: MessageWriter<SoftBodyError>,
    threads: Res<SoftBodyThreads>,
) {
    if threads.keep_awake {
        // First, so that the crew is awake by the first parallel section.
        muster_crew(
            &ComputePool::new(&threads),
            bodies
                .iter()
                .map(|(_, body, ..)| body.state.mesh().tet_count()),
        );
    }
    for (entity, mut body, mut transform, pinned, driven) in &mut bodies {
        let body = &mut *body;
        if !body.placed {
            let placement = *transform;
            if placement.scale != Vec3::ONE {
                match scaled_mesh(body.state.mesh(), placement.scale)
                    .map_err(|e| e.to_string())
                    .and_then(|m| {
                        SoftBodyState::new(m.into(), *body.state.material())
                            .map_err(|e| e.to_string())
                    }) {
                    Ok(mut state) => {
                        // Velocities given before the spawn are kept (world frame, like the
                        // simulation); only the rest shape changes.
                        state
                            .velocities_mut()
                            .copy_from_slice(body.state.velocities());
                        body.state = state;
                        body.rest_scale = placement.scale;
                    }
                    Err(reason) => report(
                        &mut errors,
                        SoftBodyError {
                            body: entity,
                            kind: SoftBodyErrorKind::BadScale {
                                scale: placement.scale,
                                reason,
                            },
                        },
                    ),
                }
            }
            body.state
                .map_positions(|p| placement.rotation * p + placement.translation);
            body.placed = true;
            *transform = Transform::from_translation(body.state.centre_of_mass());
        }
        body.step_time = Duration::ZERO;
        body.state.begin_step();
        body.state.clear_kinematic();
        let count = body.state.positions().len();
        let out_of_range = |index: u32| SoftBodyError {
            body: entity,
            kind: SoftBodyErrorKind::ParticleOutOfRange { index, count },
        };
        if let Some(pinned) = pinned {
            for &i in &pinned.0 {
                match body.state.positions().get(i as usize).copied() {
                    Some(here) => {
                        let _ = body.state.set_kinematic(i as usize, here);
                    }
                    // Reported once, when the component is added or changed.
                    None if pinned.is_changed() => report(&mut errors, out_of_range(i)),
                    None => {}
                }
            }
        }
        if let Some(mut driven) = driven {
            let Ok(target) = targets.get(driven.target) else {
                if !driven.target_missing {
                    driven.target_missing = true;
                    let target = driven.target;
                    report(
                        &mut errors,
                        SoftBodyError {
                            body: entity,
                            kind: SoftBodyErrorKind::MissingDriveTarget(target),
                        },
                    );
                }
                continue;
            };
            driven.target_missing = false;
            let to_world = target.to_matrix();
            if driven.offsets.len() != driven.particles.len() {
                let to_local = to_world.inverse();
                let mut offsets = Vec::with_capacity(driven.particles.len());
                for &i in &driven.particles {
                    match body.state.positions().get(i as usize) {
                        Some(&p) => offsets.push(to_local.transform_point3(p)),
                        None => {
                            // Reported once, when the offsets are captured; kept as a
                            // placeholder so that indices and offsets stay paired.
                            report(&mut errors, out_of_range(i));
                            offsets.push(Vec3::ZERO);
                        }
                    }
                }
                driven.offsets = offsets;
            }
            for (&i, &offset) in driven.particles.iter().zip(&driven.offsets) {
                if (i as usize) < count {
                    let _ = body
                        .state
                        .set_kinematic(i as usize, to_world.transform_point3(offset));
                }
            }
        }
    }
}

/// The rigid spheres and static colliders as the solver sees them during one step, gathered
/// once in [`SoftBodySystems::Forces`]. The spheres are changed by the contact and volume passes
/// (particles pressed against a sphere move it) and written back in [`SoftBodySystems::Integrate`];
/// the colliders do not move within a step. Also the bodies' entities, scratch for the parallel
/// stages ([`for_each_body`]). The buffers are reused, so a step does not allocate.
#[derive(Resource, Default)]
pub struct SolverSpheres {
    entities: Vec<Entity>,
    states: Vec<RigidSphereState>,
    /// The spheres as they were before the stage running now (see [`par_with_spheres`]).
    before: Vec<RigidSphereState>,
    colliders: Vec<ColliderInstance>,
    /// The bodies' entities, in query order (scratch of [`for_each_body`]).
    bodies: Vec<Entity>,
}

/// Wall-clock time of the plugin's stages for all bodies together: what a frame pays for the
/// physics. Bodies are stepped in parallel on Bevy's compute task pool, so with several bodies
/// and threads this is less than the sum of the bodies' own [`SoftBodyStats::step_ms`].
#[derive(Resource, Clone, Copy, Debug, Default, Reflect)]
#[reflect(Resource)]
pub struct SoftBodyStepTime {
    /// The last step, in milliseconds.
    pub last_ms: f64,
    /// All steps so far, in milliseconds.
    pub total_ms: f64,
    /// Steps so far.
    pub steps: u64,
    /// All steps so far, stage by stage: where the time goes. The stages add up to
    /// `total_ms` (see [`SoftBodyStepTime::mean_stage_ms`] for the means per step).
    pub stages_total: SoftBodyStageTimes,
    /// The step being timed.
    #[reflect(ignore)]
    current: Duration,
}

/// Milliseconds spent in each timed stage of the step (see [`SoftBodySystems`]), all bodies
/// together. [`SoftBodySystems::Prepare`] and [`SoftBodySystems::Writeback`] are outside the step
/// and not timed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Reflect)]
pub struct SoftBodyStageTimes {
    /// [`SoftBodySystems::Forces`].
    pub forces_ms: f64,
    /// [`SoftBodySystems::Contacts`]: the first contact pass, and the substepped shape solves
    /// (XPBD's whole step, a physical material's edges), which meet the contacts.
    pub contacts_ms: f64,
    /// [`SoftBodySystems::OneRing`]: the one-ring pass, with its clamp bounds.
    pub one_ring_ms: f64,
    /// [`SoftBodySystems::PerTet`].
    pub per_tet_ms: f64,
    /// [`SoftBodySystems::Plasticity`].
    pub plasticity_ms: f64,
    /// [`SoftBodySystems::Integrate`]: the last contact pass and the positions.
    pub integrate_ms: f64,
}

impl SoftBodyStageTimes {
    /// The sum of all stages.
    pub fn sum_ms(&self) -> f64 {
        self.forces_ms
            + self.contacts_ms
            + self.one_ring_ms
            + self.per_tet_ms
            + self.plasticity_ms
            + self.integrate_ms
    }

    /// Adds `other`'s time in each stage to this one's: the stages of runs taken together.
    pub fn add(&mut self, other: &SoftBodyStageTimes) {
        self.forces_ms += other.forces_ms;
        self.contacts_ms += other.contacts_ms;
        self.one_ring_ms += other.one_ring_ms;
        self.per_tet_ms += other.per_tet_ms;
        self.plasticity_ms += other.plasticity_ms;
        self.integrate_ms += other.integrate_ms;
    }

    /// Each stage divided by `n`.
    fn divided_by(&self, n: f64) -> SoftBodyStageTimes {
        SoftBodyStageTimes {
            forces_ms: self.forces_ms / n,
            contacts_ms: self.contacts_ms / n,
            one_ring_ms: self.one_ring_ms / n,
            per_tet_ms: self.per_tet_ms / n,
            plasticity_ms: self.plasticity_ms / n,
            integrate_ms: self.integrate_ms / n,
        }
    }
}

impl SoftBodyStepTime {
    /// Mean wall-clock time per step so far, in milliseconds.
    pub fn mean_ms(&self) -> f64 {
        if self.steps == 0 {
            0.0
        } else {
            self.total_ms / self.steps as f64
        }
    }

    /// Mean wall-clock time per step of each stage so far (zero before the first step).
    pub fn mean_stage_ms(&self) -> SoftBodyStageTimes {
        if self.steps == 0 {
            SoftBodyStageTimes::default()
        } else {
            self.stages_total.divided_by(self.steps as f64)
        }
    }

    /// Adds the time since `start` to the step being timed and to its stage.
    fn add_stage(&mut self, start: Instant, stage: fn(&mut SoftBodyStageTimes) -> &mut f64) {
        let elapsed = start.elapsed();
        self.current += elapsed;
        *stage(&mut self.stages_total) += elapsed.as_secs_f64() * 1e3;
    }
}

fn sphere_state(sphere: &RigidSphere, transform: &Transform) -> RigidSphereState {
    let inv_mass = if sphere.mass.is_finite() && sphere.mass > 0.0 {
        1.0 / sphere.mass
    } else {
        0.0
    };
    RigidSphereState {
        position: transform.translation,
        velocity: sphere.velocity,
        radius: sphere.radius,
        inv_mass,
        friction: sphere.friction,
    }
}

/// Runs independent jobs (bodies, or the blocks of a volume pass, see `core::parallel`) on at
/// most `threads` threads of Bevy's compute task pool (see [`SoftBodyThreads::max_threads`]):
/// the crew's when it is on duty (see [`crate::crew`]), else as tasks of the pool.
struct ComputePool {
    /// The threads a step may use: the pool's, at most [`SoftBodyThreads::max_threads`], at
    /// least one (the system's own).
    threads: usize,
}

impl ComputePool {
    fn new(settings: &SoftBodyThreads) -> ComputePool {
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
        if crew::BOARD.run(jobs, job) {
            return;
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
    /// Keep the pool's other threads awake through each step that has work for them (several
    /// bodies, or a body large enough for its passes to run in parallel): they wait for the
    /// step's parallel sections spinning instead of asleep, so no section waits for a thread to
    /// wake up (see `crew.rs`). On by default; off, the threads sleep between the sections:
    /// less CPU time spent, a longer step when there are several threads.
    pub keep_awake: bool,
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
            keep_awake: true,
            max_threads: usize::MAX,
        }
    }
}

/// Puts the crew on duty for this step if it has parallel work: two bodies or more, or one of
/// at least [`PARALLEL_PASS_MIN_TETS`] tets; every thread the step may use but one (the step's
/// own systems need one) becomes a member.
fn muster_crew(compute: &ComputePool, tet_counts: impl Iterator<Item = usize>) {
    let Some(pool) = bevy::tasks::ComputeTaskPool::try_get() else {
        return;
    };
    if compute.threads < 2 {
        return;
    }
    let (mut bodies, mut largest) = (0, 0);
    for tets in tet_counts {
        bodies += 1;
        largest = largest.max(tets);
    }
    if bodies < 2 && largest < PARALLEL_PASS_MIN_TETS {
        return;
    }
    for _ in 0..crew::BOARD.muster(compute.threads - 1) {
        pool.spawn(crew::BOARD.member()).detach();
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
fn pass_parallelism<'a>(
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
const ONE_BODY_PER_TASK: BatchingStrategy = BatchingStrategy::fixed(1);

/// The bodies as the stages of a step see them.
type Bodies<'w, 's> = Query<'w, 's, (Entity, &'static mut SoftBody, &'static mut SoftBodyStats)>;

/// Whether there are fewer bodies than threads for the step.
fn few_bodies(bodies: &Bodies, compute: &ComputePool) -> bool {
    bodies.iter().count() < compute.threads
}

/// Runs `run` on every body: one body per job on the compute task pool's threads (the crew's,
/// see [`crate::crew`]), or a single body on this thread (not handed to another, which may first
/// have to wake up). `order` is scratch for the bodies' entities.
fn for_each_body(
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

/// Runs `stage` on every body, in parallel on the compute task pool, timing each body.
fn par_bodies(
    bodies: &mut Bodies,
    order: &mut Vec<Entity>,
    compute: &ComputePool,
    stage: impl Fn(&mut SoftBodyState, &mut SoftBodyStats) + Send + Sync,
) {
    let run = |(mut body, mut stats): (Mut<SoftBody>, Mut<SoftBodyStats>)| {
        let body = &mut *body;
        let start = Instant::now();
        stage(&mut body.state, &mut stats);
        body.step_time += start.elapsed();
    };
    for_each_body(bodies, order, compute, run);
}

/// Runs `pass` on every body in parallel, each against its own copy of the spheres as they were
/// before the stage, then gives each sphere the changes of its velocity that the bodies made, in
/// query order (the first body's result as it is, the others' as differences). Every body sees
/// the same spheres whatever ran before it, so the result does not depend on the number of
/// threads; with one body it is exactly the serial result. `pass` adds its contacts to the
/// stats.
fn par_with_spheres(
    bodies: &mut Bodies,
    solver: &mut SolverSpheres,
    compute: &ComputePool,
    pass: impl Fn(&mut SoftBodyState, &mut SoftBodyStats, &mut [RigidSphereState], &[ColliderInstance])
    + Send
    + Sync,
) {
    solver.before.clear();
    solver.before.extend_from_slice(&solver.states);
    let (before, colliders) = (&solver.before, &solver.colliders);
    let run = |(mut body, mut stats): (Mut<SoftBody>, Mut<SoftBodyStats>)| {
        let body = &mut *body;
        let start = Instant::now();
        body.spheres.clear();
        body.spheres.extend_from_slice(before);
        pass(&mut body.state, &mut stats, &mut body.spheres, colliders);
        body.step_time += start.elapsed();
    };
    for_each_body(bodies, &mut solver.bodies, compute, run);
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

// A system takes one parameter per resource and query it reads.
#[allow(clippy::too_many_arguments)]
fn apply_forces(
    time: Res<Time>,
    gravity: Res<SoftBodyGravity>,
    mut solver_spheres: ResMut<SolverSpheres>,
    mut clock: ResMut<SoftBodyStepTime>,
    mut bodies: Bodies,
    spheres: Query<(Entity, &RigidSphere, &Transform)>,
    collider_query: Query<(&StaticCollider, &Transform), Without<RigidSphere>>,
    threads: Res<SoftBodyThreads>,
) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    let start = Instant::now();
    let g = gravity.0;
    let compute = ComputePool::new(&threads);
    let few = few_bodies(&bodies, &compute);
    let solver_spheres = &mut *solver_spheres;
    par_bodies(&mut bodies, &mut solver_spheres.bodies, &compute, |s, _| {
        s.apply_forces_on(h, g, pass_parallelism(few, s, &compute))
    });
    solver_spheres.entities.clear();
    solver_spheres.states.clear();
    for (entity, sphere, transform) in &spheres {
        let mut state = sphere_state(sphere, transform);
        state.apply_forces(h, g);
        solver_spheres.entities.push(entity);
        solver_spheres.states.push(state);
    }
    solver_spheres.colliders.clear();
    for (collider, transform) in &collider_query {
        let pose = Pose::from_parts(transform.translation, transform.rotation);
        solver_spheres.colliders.push(ColliderInstance::new(
            collider.shape.clone(),
            pose,
            collider.friction,
        ));
    }
    clock.add_stage(start, |s| &mut s.forces_ms);
}

/// One contact pass over everything: spheres against static colliders, then particles against
/// spheres, then particles against static colliders (last, so that no particle is left inside
/// the ground by a sphere pushing it), then `after` on each body in the same task (one parallel
/// section instead of two: waking a thread for each costs more than a small body's stage).
/// A large body alone has its particles against the static colliders, and `after`, in
/// chunks on the threads (the parallelism `after` gets); against the spheres they go one
/// after another (each push moves the sphere the next particle meets).
/// Bodies stepped in substeps meet the colliders there (`SoftBodyState::shape_pass`, which
/// the first pass's `after` runs), not in these passes.
fn contact_pass(
    h: f32,
    solver: &mut SolverSpheres,
    bodies: &mut Bodies,
    compute: &ComputePool,
    after: impl Fn(
        &mut SoftBodyState,
        &mut SoftBodyStats,
        &mut [RigidSphereState],
        &[ColliderInstance],
        &dyn Parallel,
    ) + Send
    + Sync,
) {
    for sphere in solver.states.iter_mut() {
        sphere.resolve_static_contacts(h, &solver.colliders);
    }
    let few = few_bodies(bodies, compute);
    par_with_spheres(bodies, solver, compute, |s, stats, spheres, colliders| {
        let parallel = pass_parallelism(few, s, compute);
        if !s.material().is_substepped() {
            stats.contacts += s.resolve_sphere_contacts(h, spheres)
                + s.resolve_static_contacts_on(h, colliders, parallel);
        }
        after(s, stats, spheres, colliders, parallel);
    });
}

fn resolve_contacts(
    time: Res<Time>,
    mut solver: ResMut<SolverSpheres>,
    mut clock: ResMut<SoftBodyStepTime>,
    mut bodies: Bodies,
    threads: Res<SoftBodyThreads>,
) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    let start = Instant::now();
    for (_, _, mut stats) in &mut bodies {
        stats.contacts = 0;
    }
    contact_pass(
        h,
        &mut solver,
        &mut bodies,
        &ComputePool::new(&threads),
        |s, stats, spheres, colliders, parallel| {
            stats.contacts += s.shape_pass(h, spheres, colliders, parallel)
        },
    );
    clock.add_stage(start, |s| &mut s.contacts_ms);
}

fn one_ring(
    time: Res<Time>,
    mut solver: ResMut<SolverSpheres>,
    mut clock: ResMut<SoftBodyStepTime>,
    mut bodies: Bodies,
    threads: Res<SoftBodyThreads>,
) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    let start = Instant::now();
    let compute = ComputePool::new(&threads);
    let few = few_bodies(&bodies, &compute);
    par_with_spheres(&mut bodies, &mut solver, &compute, |s, _, spheres, _| {
        s.one_ring_pass_on(h, spheres, pass_parallelism(few, s, &compute));
    });
    clock.add_stage(start, |s| &mut s.one_ring_ms);
}

fn per_tet(
    time: Res<Time>,
    mut solver: ResMut<SolverSpheres>,
    mut clock: ResMut<SoftBodyStepTime>,
    mut bodies: Bodies,
    threads: Res<SoftBodyThreads>,
) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    let start = Instant::now();
    let compute = ComputePool::new(&threads);
    let few = few_bodies(&bodies, &compute);
    par_with_spheres(&mut bodies, &mut solver, &compute, |s, _, spheres, _| {
        s.per_tet_pass_on(h, spheres, pass_parallelism(few, s, &compute));
    });
    clock.add_stage(start, |s| &mut s.per_tet_ms);
}

fn plasticity(
    time: Res<Time>,
    mut solver: ResMut<SolverSpheres>,
    mut clock: ResMut<SoftBodyStepTime>,
    mut bodies: Bodies,
    threads: Res<SoftBodyThreads>,
) {
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    // Without plastic bodies, not even a parallel section (waking threads for nothing).
    if bodies
        .iter()
        .all(|(_, body, _)| body.state.material().plasticity.is_none())
    {
        return;
    }
    let start = Instant::now();
    let compute = ComputePool::new(&threads);
    par_bodies(&mut bodies, &mut solver.bodies, &compute, |s, _| {
        s.apply_plasticity(h)
    });
    clock.add_stage(start, |s| &mut s.plasticity_ms);
}

fn integrate(
    time: Res<Time>,
    mut solver_spheres: ResMut<SolverSpheres>,
    mut clock: ResMut<SoftBodyStepTime>,
    mut bodies: Bodies,
    mut spheres: Query<(&mut RigidSphere, &mut Transform), Without<StaticCollider>>,
    threads: Res<SoftBodyThreads>,
) {
    // The crew stays while the last section (below) runs: dismissed members finish the
    // posting they are in, and take no other.
    let _dismiss = DismissCrew;
    let h = time.delta_secs();
    if h <= 0.0 {
        return;
    }
    let start = Instant::now();
    let solver_spheres = &mut *solver_spheres;
    let compute = ComputePool::new(&threads);
    contact_pass(
        h,
        solver_spheres,
        &mut bodies,
        &compute,
        |s, stats, _, _, parallel| {
            s.integrate_positions_on(h, parallel);
            stats.steps += 1;
        },
    );
    for (entity, state) in solver_spheres
        .entities
        .iter()
        .zip(&mut solver_spheres.states)
    {
        state.integrate_position(h);
        if let Ok((mut sphere, mut transform)) = spheres.get_mut(*entity) {
            sphere.velocity = state.velocity;
            transform.translation = state.position;
        }
    }
    clock.add_stage(start, |s| &mut s.integrate_ms);
    clock.last_ms = clock.current.as_secs_f64() * 1e3;
    clock.total_ms += clock.last_ms;
    clock.steps += 1;
    clock.current = Duration::ZERO;
}

/// Dismisses the crew when dropped: at the end of a step, however it ends.
struct DismissCrew;

impl Drop for DismissCrew {
    fn drop(&mut self) {
        crew::BOARD.dismiss();
    }
}

fn writeback(
    mut bodies: Query<(Entity, &SoftBody, &mut SoftBodyStats, &mut Transform)>,
    threads: Res<SoftBodyThreads>,
    mut errors: MessageWriter<SoftBodyError>,
) {
    type Written<'a> = (
        Entity,
        &'a SoftBody,
        Mut<'a, SoftBodyStats>,
        Mut<'a, Transform>,
    );
    let write = |(_, body, mut stats, mut transform): Written| {
        if !body.placed {
            return;
        }
        stats.step_ms = body.step_time.as_secs_f64() * 1e3;
        stats.total_step_ms += stats.step_ms;
        stats.counters = body.state.counters();
        // A body that slept through the step has not moved since its metrics were taken.
        let slept = stats.sleeping && body.state.is_sleeping();
        stats.sleeping = body.state.is_sleeping();
        if slept {
            return;
        }
        let m = body.state.volume_metrics();
        stats.volume_error_pct = m.volume_error_pct;
        stats.peak_volume_error_pct = stats.peak_volume_error_pct.max(m.volume_error_pct.abs());
        stats.mean_abs_tet_error_pct = m.mean_abs_tet_error_pct;
        stats.inverted_tets = m.inverted_tets;
        stats.max_inverted_tets = stats.max_inverted_tets.max(m.inverted_tets);
        transform.translation = body.state.centre_of_mass();
    };
    // A single body on this thread, as in the stages (`for_each_body`): a parallel query hands
    // it to a pool thread, which may have to wake up and has little of the body in its caches
    // (the soft cube's writeback, two threads, four runs: 50-78 us a step, inline 39-42; one
    // thread 33-39). So do bodies kept to one thread.
    if bodies.iter().len() < 2 || ComputePool::new(&threads).threads < 2 {
        bodies.iter_mut().for_each(write);
    } else {
        bodies
            .par_iter_mut()
            .batching_strategy(ONE_BODY_PER_TASK)
            .for_each(write);
    }
    for (entity, body, mut stats, _) in &mut bodies {
        let Some(runaway) = body.state.runaway() else {
            continue;
        };
        // Reported once per spell: a body that runs away again within a second of steps of
        // the last time is counted, not reported again.
        let quiet = stats
            .last_runaway_step
            .is_none_or(|last| stats.steps >= last + RUNAWAY_REPORT_GAP_STEPS);
        stats.runaway_resets += 1;
        stats.last_runaway_step = Some(stats.steps);
        if quiet {
            report(
                &mut errors,
                SoftBodyError {
                    body: entity,
                    kind: SoftBodyErrorKind::Runaway(runaway),
                },
            );
        }
    }
}

/// Steps without a runaway after which a body's next runaway is reported again.
const RUNAWAY_REPORT_GAP_STEPS: u64 = 100;

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
        let limited = |max_threads| {
            ComputePool::new(&SoftBodyThreads {
                max_threads,
                ..Default::default()
            })
        };
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
        // The same through the crew: one member for two threads, beside this thread.
        let two = limited(2);
        muster_crew(&two, [PARALLEL_PASS_MIN_TETS].into_iter());
        let used = threads_used(&two, 64);
        crew::BOARD.dismiss();
        assert!(used <= 2, "{used} threads");
    }
}
