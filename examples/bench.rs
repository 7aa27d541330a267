//! Step times of every scene and method, headless through the plugin:
//!
//! cargo run --release --all-features --example bench -- [--threads N[,N...]] [--only NAME]
//!
//! prints one line per run, `scene=NAME method=NAME threads=N tets=N mean_step_ms=X
//! max_step_ms=X awake_bodies=X` (the slowest step; the bodies awake, hence stepped, after
//! a step, on average: a scene whose bodies fall asleep costs less per step): the five
//! paper scenes with the three methods (`baseline`, `paper`, `xpbd` with 10 substeps unless
//! `--xpbd-substeps N`) over their whole duration, boxes of 1 000 to 200 000 tets
//! settling on the ground (100 steps; the small ones again from the start, 18 and 2 times),
//! and 16 bodies of 1080 tets dropped side by side on the ground; then, at 60 Hz and Earth
//! gravity, every game scene (`game_scenes`) and 16 jelly cubes of 2 560 tets dropped from
//! 0.3 m, over their first 3 s (`jellies_16`) and over 10 s, in which they settle and fall
//! asleep (`jellies_16_10s`), and the meshes other tools made (`GameScene::bundled`, named
//! `MESH_PRESET`), and the jelly cube drop with `SoftBodyTearing` (`jelly_cube_drop_tearing`:
//! what a body that may tear but does not costs), with the paper's method and XPBD. `mean_step_ms` is the
//! wall-clock time of the plugin's stages per step, all bodies together
//! (`SoftBodyStepTime`; bodies run in parallel when there are threads), so Bevy's own overhead
//! between the stages is not in it. A scene's three methods run side by side, in turns of 50
//! steps, so that their ratios come from the same minutes of the machine. `--threads N` sizes
//! Bevy's task pools; a list, `--threads 1,2`, runs every method once per
//! count side by side in the same turns, in one pool of the largest count, each app held to its
//! own count by `SoftBodyThreads::max_threads` (so a speed-up compares the same minutes too);
//! `--only NAME` runs the scenes whose name contains NAME, `--method NAME` only that method
//! (`baseline`, `paper` or `xpbd`: for a profiler that should see one method's code alone);
//! `--stages` adds a line per run with the mean time of each stage of the step
//! and of its substeps (`SoftBodyStepTime::mean_stage_ms`): `scene=NAME method=NAME threads=N
//! stages forces_ms=X shape_ms=X contacts_ms=X one_ring_ms=X per_tet_ms=X advance_ms=X
//! plasticity_ms=X finish_ms=X`; `--tolerance X` and
//! `--ring-tet-tolerance X` set the paper's method's `ImpulseSettings` of those names.
//! Timings are for comparing runs on one machine; the criterion benches (`cargo bench`) time
//! single steps with statistics.

mod measure_args;

use measure_args::{ToleranceArgs, substeps};

use clap::Parser;

use std::time::Duration;

use bevy::app::{TaskPoolOptions, TaskPoolPlugin};
use bevy::prelude::*;
use bevy_soft_body::SoftBodyStepTime;
use bevy_soft_body::core::{ImpulseSettings, VolumeMethod, XpbdSettings, box_grid};
use bevy_soft_body::game_scenes::{GameScene, GameShape};
use bevy_soft_body::prelude::*;
use bevy_soft_body::scenes::{PaperScene, PaperScenesPlugin};
use parry3d::shape::SharedShape;

struct Args {
    /// The thread counts to run side by side (`--threads 1,2`), each at most the pool's.
    threads: Vec<usize>,
    only: Option<String>,
    /// Run only this method (`--method paper`).
    method: Option<String>,
    xpbd_substeps: u32,
    /// Print each run's stage times too (`--stages`).
    stages: bool,
    /// The paper's method's settings (`--tolerance X`, `--ring-tet-tolerance X`).
    impulses: ImpulseSettings,
}

/// The command line (see the module's doc).
#[derive(Parser)]
#[command(about = "Step times of every scene and method, headless through the plugin")]
struct Cli {
    /// Thread counts to run side by side, each at most the pool's (`--threads 1,2`)
    #[arg(long, value_delimiter = ',', default_value = "1", value_parser = thread_count)]
    threads: Vec<usize>,
    /// Only the scenes whose name contains this
    #[arg(long)]
    only: Option<String>,
    /// Only this method
    #[arg(long, value_parser = ["baseline", "paper", "xpbd", "clusters"])]
    method: Option<String>,
    /// XPBD's substeps
    #[arg(long, default_value_t = 10, value_parser = substeps)]
    xpbd_substeps: u32,
    /// A line per run with each stage's mean time
    #[arg(long)]
    stages: bool,
    #[command(flatten)]
    tolerances: ToleranceArgs,
    /// Passed by `cargo bench`-style runners; ignored
    #[arg(long, hide = true)]
    bench: bool,
}

fn thread_count(value: &str) -> Result<usize, String> {
    value
        .trim()
        .parse()
        .ok()
        .filter(|&n| n >= 1)
        .ok_or(format!("`{value}` is not a thread count"))
}

impl From<Cli> for Args {
    fn from(cli: Cli) -> Args {
        let impulses = cli.tolerances.settings();
        Args {
            threads: cli.threads,
            only: cli.only,
            method: cli.method,
            xpbd_substeps: cli.xpbd_substeps,
            stages: cli.stages,
            impulses,
        }
    }
}

/// A headless app with `pool` threads in Bevy's compute task pool (where the systems and the
/// bodies run; the IO and async pools get one each besides; the pools are one per process, so
/// the first app sets them), stepping `1 / hz` s per update (the paper's scenes 100 Hz, the
/// game scenes 60), its steps held to `threads` of them.
fn app(pool: usize, threads: usize, hz: f64) -> App {
    let mut options = TaskPoolOptions::with_num_threads(pool + 2);
    options.compute.min_threads = pool;
    options.compute.max_threads = pool;
    let mut app = App::new();
    app.add_plugins((
        MinimalPlugins.set(TaskPoolPlugin {
            task_pool_options: options,
        }),
        SoftBodyPlugin::default(),
        PaperScenesPlugin,
    ))
    .insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
        Duration::from_secs_f64(1.0 / hz),
    ))
    .insert_resource(Time::<Fixed>::from_hz(hz))
    .insert_resource(SoftBodyThreads {
        max_threads: threads,
    });
    app
}

/// Steps taken by one method before the next method of the same scene takes its turn.
const TURN: u32 = 50;

/// Steps every app (one per method of a scene) `steps` times and returns each one's tets and
/// its step times (`SoftBodyStepTime`, whose mean is the wall-clock time of its plugin's stages per step: all bodies
/// together, in parallel when there are threads for it). The apps take turns of [`TURN`] steps: a shared machine's slower or faster
/// spells (here the same build's step times move by 30 % and more between minutes) then fall
/// on all methods alike, so their ratios within a run mean something. Each turn is long enough
/// (0.1 ms to 5 ms a step) for a body's data to be back in the caches after its first step.
fn run_in_turns(apps: &mut [App], steps: u32) -> Vec<(usize, SoftBodyStepTime, u64)> {
    // The first update only starts the clock.
    for app in apps.iter_mut() {
        app.update();
    }
    let mut awake = vec![0u64; apps.len()];
    let mut done = 0;
    while done < steps {
        let turn = TURN.min(steps - done);
        for (app, awake) in apps.iter_mut().zip(&mut awake) {
            for _ in 0..turn {
                app.update();
                let world = app.world_mut();
                *awake += world
                    .query::<&SoftBody>()
                    .iter(world)
                    .filter(|b| !b.state().is_sleeping())
                    .count() as u64;
            }
        }
        done += turn;
    }
    apps.iter_mut()
        .zip(awake)
        .map(|(app, awake)| {
            let world = app.world_mut();
            let tets = world
                .query::<&SoftBody>()
                .iter(world)
                .map(|b| b.state().mesh().tet_count())
                .sum();
            (tets, *world.resource::<SoftBodyStepTime>(), awake)
        })
        .collect()
}

/// Adds `more`'s steps and times to `clock`'s.
fn add_clock(clock: &mut SoftBodyStepTime, more: &SoftBodyStepTime) {
    clock.total_ms += more.total_ms;
    clock.max_ms = clock.max_ms.max(more.max_ms);
    clock.steps += more.steps;
    clock.stages_total.add(&more.stages_total);
}

/// Runs `spawn` in a new app for each thread count and method, steps them in turns and prints
/// their lines; `repeats` times over, each time from a new app, the means taken over all.
fn bench(
    args: &Args,
    name: &str,
    methods: &[VolumeMethod],
    (steps, repeats, hz): (u32, u32, f64),
    spawn: impl Fn(&mut World, VolumeMethod),
) {
    let pool = args.threads.iter().copied().max().unwrap_or(1);
    let runs: Vec<(usize, VolumeMethod)> = args
        .threads
        .iter()
        .flat_map(|&threads| methods.iter().map(move |&method| (threads, method)))
        .collect();
    let mut results: Vec<(usize, SoftBodyStepTime, u64)> = Vec::new();
    for repeat in 0..repeats.max(1) {
        let mut apps: Vec<App> = runs
            .iter()
            .map(|&(threads, method)| {
                let mut app = app(pool, threads, hz);
                spawn(app.world_mut(), method);
                app.world_mut().flush();
                app
            })
            .collect();
        let clocks = run_in_turns(&mut apps, steps);
        if repeat == 0 {
            results = clocks;
        } else {
            for ((_, clock, awake), (_, more, more_awake)) in results.iter_mut().zip(&clocks) {
                add_clock(clock, more);
                *awake += more_awake;
            }
        }
    }
    for (&(threads, method), (tets, clock, awake)) in runs.iter().zip(results) {
        report(name, method.name(), threads, tets, &clock, awake);
        if args.stages {
            let s = clock.mean_stage_ms();
            println!(
                "scene={name} method={} threads={threads} stages forces_ms={:.3} shape_ms={:.3} contacts_ms={:.3} one_ring_ms={:.3} per_tet_ms={:.3} advance_ms={:.3} plasticity_ms={:.3} finish_ms={:.3}",
                method.name(),
                s.forces_ms,
                s.shape_ms,
                s.contacts_ms,
                s.one_ring_ms,
                s.per_tet_ms,
                s.advance_ms,
                s.plasticity_ms,
                s.finish_ms
            );
        }
    }
}

fn report(
    scene: &str,
    method: &str,
    threads: usize,
    tets: usize,
    clock: &SoftBodyStepTime,
    awake: u64,
) {
    println!(
        "scene={scene} method={method} threads={threads} tets={tets} mean_step_ms={:.3} max_step_ms={:.3} awake_bodies={:.2}",
        clock.mean_ms(),
        clock.max_ms,
        awake as f64 / clock.steps.max(1) as f64
    );
}

fn main() {
    let args = Args::from(Cli::parse());
    let wanted = |name: &str| args.only.as_deref().is_none_or(|o| name.contains(o));
    let methods: Vec<VolumeMethod> = [
        VolumeMethod::PAPER_BASELINE,
        VolumeMethod::Impulses(args.impulses),
        VolumeMethod::Xpbd(XpbdSettings {
            substeps: args.xpbd_substeps,
            clusters: 0,
        }),
        VolumeMethod::Xpbd(XpbdSettings {
            substeps: args.xpbd_substeps,
            ..XpbdSettings::CLUSTERS
        }),
    ]
    .into_iter()
    .filter(|m| args.method.as_deref().is_none_or(|n| n == m.name()))
    .collect();

    for scene in PaperScene::ALL {
        if !wanted(scene.name()) {
            continue;
        }
        let steps = (scene.duration_secs() * 100.0).round() as u32;
        bench(
            &args,
            scene.name(),
            &methods,
            (steps, 1, 100.0),
            |world, method| {
                scene.spawn(&mut world.commands(), method, Vec3::ZERO);
            },
        );
    }

    // Boxes from 1 000 to 200 000 tets settling on the ground under the creature scene's
    // material and gravity, 100 steps each: the cost per tet as a body grows. The smaller ones
    // run their 100 steps again from the start until they have stepped about 2 million tets
    // (the 1k box 18 times, the 9k box twice): the 1k box's 100 steps took 6 ms, short
    // enough for a busy machine's noise to move its time per tet by a third from run to run.
    let boxes = [
        ("box_1k", UVec3::splat(6)),
        ("box_9k", UVec3::splat(12)),
        ("box_29k", UVec3::splat(18)),
        ("box_69k", UVec3::splat(24)),
        ("box_200k", UVec3::new(40, 25, 40)),
    ];
    for (name, cells) in boxes {
        if !wanted(name) {
            continue;
        }
        let mesh: std::sync::Arc<_> = box_grid(cells, Vec3::splat(0.1), Vec3::ZERO)
            .expect("a valid grid")
            .into();
        let repeats = (20_000 / (5 * cells.element_product())).clamp(1, 20);
        bench(
            &args,
            name,
            &methods,
            (100, repeats, 100.0),
            |world, method| {
                let material = PaperScene::Creature.material(method);
                world.insert_resource(SoftBodyGravity(PaperScene::Creature.gravity()));
                world.spawn((
                    SoftBody::new(mesh.clone(), material).expect("a valid material"),
                    Transform::from_xyz(0.0, 0.05, 0.0),
                ));
                world.spawn((StaticCollider::ground(0.8), Transform::default()));
            },
        );
    }

    // Many bodies: 16 cubes of 6^3 cells side by side (bodies do not collide with each other).
    if wanted("bodies_16") {
        let mesh: std::sync::Arc<_> = box_grid(UVec3::splat(6), Vec3::splat(0.1), Vec3::ZERO)
            .expect("a valid grid")
            .into();
        bench(
            &args,
            "bodies_16",
            &methods,
            (300, 1, 100.0),
            |world, method| {
                let material = PaperScene::Creature.material(method);
                world.insert_resource(SoftBodyGravity(PaperScene::Creature.gravity()));
                for k in 0..16 {
                    let (i, j) = (k % 4, k / 4);
                    world.spawn((
                        SoftBody::new(mesh.clone(), material).expect("a valid material"),
                        Transform::from_xyz(
                            i as f32 * 0.75,
                            0.2 + 0.05 * k as f32,
                            j as f32 * 0.75,
                        ),
                    ));
                }
                world.spawn((StaticCollider::ground(0.8), Transform::default()));
            },
        );
    }

    // Game scale at 60 Hz (`bevy_soft_body::game_scenes`, Earth gravity, physical materials):
    // every game scene, and 16 jelly cubes of 2 560 tets dropped side by side from 0.3 m, for
    // the paper's method and XPBD (the explicit baseline cannot hold a physical material).
    let game_methods: Vec<VolumeMethod> = methods
        .iter()
        .copied()
        .filter(|m| !matches!(m, VolumeMethod::Baseline { .. }))
        .collect();
    // Then the meshes other tools made, 1 m across, in every preset, dropped from 0.5 m
    // (`GameScene::bundled`): what a game's own mesh costs.
    for scene in GameScene::standard()
        .into_iter()
        .chain(GameScene::bundled())
    {
        if !wanted(&scene.name) {
            continue;
        }
        let steps = (scene.duration_secs * 60.0).round() as u32;
        bench(
            &args,
            &scene.name,
            &game_methods,
            (steps, 1, 60.0),
            |world, method| {
                scene
                    .spawn(&mut world.commands(), method, Vec3::ZERO)
                    .expect("the standard and bundled scenes build");
            },
        );
    }
    // The jelly cube drop again with `SoftBodyTearing` (a drop stretches it nowhere near its
    // limit): what a body that may tear but does not costs, against `jelly_cube_drop`.
    if wanted("jelly_cube_drop_tearing") {
        let scene = GameScene::standard()
            .into_iter()
            .find(|s| s.name == "jelly_cube_drop")
            .expect("a standard scene");
        let steps = (scene.duration_secs * 60.0).round() as u32;
        bench(
            &args,
            "jelly_cube_drop_tearing",
            &game_methods,
            (steps, 1, 60.0),
            |world, method| {
                let body = scene
                    .spawn(&mut world.commands(), method, Vec3::ZERO)
                    .expect("a standard scene");
                world
                    .commands()
                    .entity(body)
                    .insert(SoftBodyTearing::default());
            },
        );
    }
    // The same 16 jellies for their first 3 s (the drop, the landing, the wobble) and for
    // 10 s (they settle and fall asleep: a resting body is not stepped).
    // And 16 coarse ones (4 cells a side, 320 tets), the resolution a game gives a prop.
    for (name, steps, cells) in [
        ("jellies_16", 180, 8),
        ("jellies_16_10s", 600, 8),
        ("jellies_16_coarse", 180, 4),
    ] {
        if !wanted(name) {
            continue;
        }
        let jelly = jelly_cube(0.5, cells, 0.3);
        bench(
            &args,
            name,
            &game_methods,
            (steps, 1, 60.0),
            |world, method| {
                for k in 0..16 {
                    let (i, j) = (k % 4, k / 4);
                    let offset = Vec3::new(i as f32 * 0.8, 0.02 * k as f32, j as f32 * 0.8);
                    jelly
                        .spawn_body(&mut world.commands(), method, offset)
                        .expect("a standard scene");
                }
                world.spawn((StaticCollider::ground(0.8), Transform::default()));
            },
        );
    }
    // 16 jelly cubes of 0.3 m and 2 560 tets piled in a box (a 1 m square, walls 0.6 m
    // high), dropped in two layers, over their first 3 s: meeting each other
    // (`jellies_16_pile`), and passing through each other (`jellies_16_pile_apart`, their soft
    // contacts off), which is what the contacts cost.
    // Over 10 s too (`_10s`): the pile settles (whether it falls asleep shows in
    // `awake_bodies`).
    for (name, contacts, steps) in [
        ("jellies_16_pile", true, 180),
        ("jellies_16_pile_apart", false, 180),
        ("jellies_16_pile_10s", true, 600),
        ("jellies_16_pile_apart_10s", false, 600),
    ] {
        if !wanted(name) {
            continue;
        }
        let jelly = jelly_cube(0.3, 8, 0.0);
        bench(
            &args,
            name,
            &game_methods,
            (steps, 1, 60.0),
            |world, method| {
                for k in 0..16 {
                    let (i, j, layer) = (k % 3, (k / 3) % 3, k / 9);
                    // A few centimetres off a grid, so that the pile is not a stack of towers.
                    let nudge = 0.02 * ((k * 7) % 5) as f32 - 0.04;
                    // Centres 0.3 m apart about the box's centre: 3 cm or more from each wall.
                    let offset = Vec3::new(
                        -0.3 + 0.3 * i as f32 + 0.5 * nudge,
                        0.02 + 0.4 * layer as f32 + 0.03 * (k % 3) as f32,
                        -0.3 + 0.3 * j as f32 - 0.5 * nudge,
                    );
                    let body = jelly
                        .spawn_body(&mut world.commands(), method, offset)
                        .expect("a standard scene");
                    world.flush();
                    if !contacts {
                        world.entity_mut(body).insert(SoftBodyContactsDisabled);
                    }
                }
                world.spawn((StaticCollider::ground(0.8), Transform::default()));
                // The walls, 10 cm thick, around the 1 m square.
                for (centre, half) in [
                    (Vec3::new(-0.55, 0.3, 0.0), Vec3::new(0.05, 0.3, 0.6)),
                    (Vec3::new(0.55, 0.3, 0.0), Vec3::new(0.05, 0.3, 0.6)),
                    (Vec3::new(0.0, 0.3, -0.55), Vec3::new(0.6, 0.3, 0.05)),
                    (Vec3::new(0.0, 0.3, 0.55), Vec3::new(0.6, 0.3, 0.05)),
                ] {
                    world.spawn((
                        StaticCollider::new(SharedShape::cuboid(half.x, half.y, half.z), 0.8),
                        Transform::from_translation(centre),
                    ));
                }
            },
        );
    }
}

/// The standard jelly cube drop's material with a cube of `size` metres in `cells` cells a side,
/// lifted `lift` metres.
fn jelly_cube(size: f32, cells: u32, lift: f32) -> GameScene {
    GameScene {
        lift,
        shape: GameShape::Cube { size, cells },
        ..GameScene::standard()
            .into_iter()
            .find(|s| s.name == "jelly_cube_drop")
            .expect("a standard scene")
    }
}
