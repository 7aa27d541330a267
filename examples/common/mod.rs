//! What every windowed example shares: the window and plugins, an orbit camera, light and
//! ground, the paper's scenes dressed with their detailed surfaces, the controls listed on
//! screen, and `--screenshot PATH --frames N`.

#![allow(dead_code)]

use std::path::PathBuf;
use std::time::Duration;

use bevy::input::mouse::{AccumulatedMouseMotion, AccumulatedMouseScroll};
use bevy::light::GlobalAmbientLight;
use bevy::prelude::*;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured, save_to_disk};
use bevy::window::PrimaryWindow;
use bevy_soft_body::core::VolumeMethod;
use bevy_soft_body::debug::{SoftBodyDebugGizmos, SoftBodyDebugPlugin};
use bevy_soft_body::inspector::SoftBodyInspectorPlugin;
use bevy_soft_body::prelude::*;
use bevy_soft_body::scenes::{PaperScene, PaperScenesPlugin};
use bevy_soft_body::surface_mesh;

/// Command-line options every example accepts.
#[derive(Resource, Clone, Debug, Default, clap::Parser)]
#[command(about = "A bevy_soft_body example")]
pub struct ExampleOptions {
    /// Save a PNG of the window here after `--frames` frames, then exit
    #[arg(long)]
    pub screenshot: Option<PathBuf>,
    /// Frames before the screenshot. With `--screenshot`, each frame is exactly one 10 ms step,
    /// so the picture does not depend on how fast the machine renders
    #[arg(long, default_value_t = 300)]
    pub frames: u32,
    /// The paper's scene to show first (the playground and compare)
    #[arg(long, value_parser = paper_scene)]
    pub scene: Option<PaperScene>,
    /// Start with the debug gizmos on
    #[arg(long)]
    pub gizmos: bool,
}

fn paper_scene(name: &str) -> Result<PaperScene, String> {
    PaperScene::from_name(name).ok_or_else(|| {
        let names: Vec<_> = PaperScene::ALL.iter().map(|s| s.name()).collect();
        format!("unknown scene `{name}`; scenes: {}", names.join(", "))
    })
}

impl ExampleOptions {
    /// Reads the options from the command line; exits with a message on anything else.
    pub fn from_args() -> Self {
        <Self as clap::Parser>::parse()
    }
}

/// What an example shows.
#[derive(Resource, Clone, Copy, Debug, PartialEq)]
pub enum Layout {
    /// One scene with the paper's method.
    Single(PaperScene),
    /// The scene twice, baseline left and the paper's method right.
    Compare(PaperScene),
}

/// The orbit camera: right mouse drag or arrow keys turn it, the wheel zooms.
#[derive(Component, Clone, Copy, Debug)]
pub struct OrbitCamera {
    pub focus: Vec3,
    pub yaw: f32,
    pub pitch: f32,
    pub distance: f32,
}

impl OrbitCamera {
    pub fn transform(&self) -> Transform {
        let rotation = Quat::from_euler(EulerRot::YXZ, self.yaw, -self.pitch, 0.0);
        let eye = self.focus + rotation * Vec3::new(0.0, 0.0, self.distance);
        let mut transform = Transform::from_translation(eye).looking_at(self.focus, Vec3::Y);
        // The panel covers the right quarter of the window: aim so that the focus sits in the
        // middle of what is left.
        transform.translation += transform.right() * (self.distance * 0.16);
        transform
    }
}

/// Entities that a reset despawns.
#[derive(Component)]
pub struct SceneMember;

/// Set to respawn the layout's scene at the next update (what R does).
#[derive(Resource, Default)]
pub struct ResetScene(pub bool);

/// A pending single step.
#[derive(Resource, Default)]
struct StepOnce(bool);

/// Frames drawn so far (for `--screenshot`).
#[derive(Resource, Default)]
struct FrameCount(u32);

/// Extra help lines an example adds to the on-screen controls.
#[derive(Resource, Default, Clone)]
pub struct ExtraHelp(pub Vec<&'static str>);

/// The app every example runs: window, plugins, camera, light, ground and controls. The example
/// adds its own systems and calls `run`.
pub fn example_app(title: &str, layout: Option<Layout>) -> App {
    example_app_with(title, layout, ExampleOptions::from_args())
}

/// [`example_app`] with options the example parsed itself (it has options of its own).
pub fn example_app_with(title: &str, layout: Option<Layout>, options: ExampleOptions) -> App {
    let mut app = App::new();
    app.add_plugins(DefaultPlugins.set(WindowPlugin {
        primary_window: Some(Window {
            title: title.into(),
            resolution: (1280u32, 720u32).into(),
            ..default()
        }),
        ..default()
    }))
    .add_plugins((
        SoftBodyPlugin::default(),
        PaperScenesPlugin,
        SoftBodySurfacePlugin,
        SoftBodyAssetPlugin::default(),
        SoftBodyDebugPlugin,
        SoftBodyInspectorPlugin,
    ))
    .insert_resource(ClearColor(Color::srgb(0.62, 0.72, 0.82)))
    .insert_resource(GlobalAmbientLight {
        brightness: 300.0,
        ..default()
    })
    .init_resource::<StepOnce>()
    .init_resource::<ResetScene>()
    .init_resource::<FrameCount>()
    .init_resource::<ExtraHelp>()
    .add_systems(Startup, (setup_world, setup_help))
    .add_systems(
        Update,
        (
            controls,
            orbit_camera,
            dress_spheres,
            dress_ground,
            count_frames_and_screenshot,
            update_help,
        ),
    )
    .add_systems(FixedPostUpdate, finish_single_step);
    if options.screenshot.is_some() {
        // One step per frame, whatever the frame rate: the picture shows a known moment.
        app.insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
            Duration::from_millis(10),
        ));
    }
    if let Some(layout) = layout {
        app.insert_resource(layout)
            .add_systems(Startup, spawn_layout.after(setup_world))
            .add_systems(Update, reset_layout);
    }
    if options.gizmos {
        app.insert_resource(SoftBodyDebugGizmos {
            enabled: true,
            ..default()
        });
    }
    app.insert_resource(options);
    app
}

fn setup_world(mut commands: Commands) {
    commands.spawn((
        DirectionalLight {
            illuminance: 9000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::from_xyz(4.0, 10.0, 6.0).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    let orbit = OrbitCamera {
        focus: Vec3::new(0.0, 0.5, 0.0),
        yaw: 0.35,
        pitch: 0.3,
        distance: 5.0,
    };
    commands.spawn((Camera3d::default(), orbit.transform(), orbit));
}

/// Frames the camera on the box from `lo` to `hi`.
pub fn frame_camera(camera: &mut OrbitCamera, lo: Vec3, hi: Vec3) {
    camera.focus = (lo + hi) / 2.0;
    // Leave room for the panel on the right: look a little right of centre.
    camera.distance = (hi - lo).length() * 1.3 + 1.2;
}

/// Spawns `scene` with `method` at `offset`, dressed with its detailed surface and a material.
pub fn spawn_dressed_scene(
    commands: &mut Commands,
    meshes: &mut Assets<Mesh>,
    materials: &mut Assets<StandardMaterial>,
    scene: PaperScene,
    method: VolumeMethod,
    offset: Vec3,
    colour: Color,
) -> Entity {
    let body = scene.spawn(commands, method, offset);
    let mesh = meshes.add(surface_mesh(&scene.render_surface()));
    commands.entity(body).insert((
        SoftBodySurface::new(body),
        Mesh3d(mesh),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: colour,
            perceptual_roughness: 0.35,
            reflectance: 0.4,
            ..default()
        })),
        SceneMember,
    ));
    body
}

fn spawn_layout(
    mut commands: Commands,
    layout: Res<Layout>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut camera: Query<(&mut OrbitCamera, &mut Transform)>,
) {
    let jelly = Color::srgb(0.85, 0.25, 0.35);
    let baseline_colour = Color::srgb(0.35, 0.5, 0.9);
    let (scene, bodies) = match *layout {
        Layout::Single(scene) => {
            let body = spawn_dressed_scene(
                &mut commands,
                &mut meshes,
                &mut materials,
                scene,
                VolumeMethod::PAPER_IMPULSES,
                Vec3::ZERO,
                jelly,
            );
            (scene, vec![(body, Vec3::ZERO)])
        }
        Layout::Compare(scene) => {
            let (lo, hi) = scene.tet_mesh().bounds();
            let shift = Vec3::X * ((hi.x - lo.x).max(hi.z - lo.z) * 1.4 + 0.5);
            let left = spawn_dressed_scene(
                &mut commands,
                &mut meshes,
                &mut materials,
                scene,
                VolumeMethod::PAPER_BASELINE,
                -shift * 0.5,
                baseline_colour,
            );
            let right = spawn_dressed_scene(
                &mut commands,
                &mut meshes,
                &mut materials,
                scene,
                VolumeMethod::PAPER_IMPULSES,
                shift * 0.5,
                jelly,
            );
            commands.entity(left).insert(Name::new("baseline (forces)"));
            commands.entity(right).insert(Name::new("paper (impulses)"));
            (scene, vec![(left, -shift * 0.5), (right, shift * 0.5)])
        }
    };
    let (lo, mut hi) = scene.tet_mesh().bounds();
    let params = scene.params();
    hi.y += params.lift;
    if let Some(sphere) = params.sphere {
        hi.y += 0.5 * sphere.radius;
    }
    let (mut lo_all, mut hi_all) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for (_, offset) in &bodies {
        lo_all = lo_all.min(lo + *offset);
        hi_all = hi_all.max(hi + *offset);
    }
    if let Ok((mut orbit, mut transform)) = camera.single_mut() {
        frame_camera(&mut orbit, lo_all, hi_all);
        // From above where the event is on top (the dents), lower for the bar and creature.
        orbit.pitch = match scene {
            PaperScene::Plastic => 0.75,
            PaperScene::SoftCube => 0.4,
            _ => 0.3,
        };
        *transform = orbit.transform();
    }
}

/// Everything a scene spawns: bodies, spheres, colliders, drivers, and what the examples add.
pub type SceneEntities<'w, 's> = Query<
    'w,
    's,
    Entity,
    Or<(
        With<SceneMember>,
        With<SoftBody>,
        With<RigidSphere>,
        With<StaticCollider>,
        With<bevy_soft_body::scenes::TwistDriver>,
    )>,
>;

/// Despawns everything a scene spawned (bodies, spheres, colliders, drivers).
pub fn despawn_scene(commands: &mut Commands, members: &SceneEntities<'_, '_>) {
    for entity in members {
        commands.entity(entity).despawn();
    }
}

#[allow(clippy::too_many_arguments)]
fn reset_layout(
    keys: Res<ButtonInput<KeyCode>>,
    mut reset: ResMut<ResetScene>,
    mut commands: Commands,
    members: SceneEntities<'_, '_>,
    layout: Res<Layout>,
    meshes: ResMut<Assets<Mesh>>,
    materials: ResMut<Assets<StandardMaterial>>,
    camera: Query<(&mut OrbitCamera, &mut Transform)>,
) {
    if keys.just_pressed(KeyCode::KeyR) || reset.0 {
        reset.0 = false;
        despawn_scene(&mut commands, &members);
        spawn_layout(commands, layout, meshes, materials, camera);
    }
}

fn dress_spheres(
    mut commands: Commands,
    spheres: Query<(Entity, &RigidSphere), Without<Mesh3d>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    for (entity, sphere) in &spheres {
        commands.entity(entity).insert((
            Mesh3d(meshes.add(Sphere::new(sphere.radius).mesh().uv(48, 24))),
            MeshMaterial3d(materials.add(StandardMaterial {
                base_color: Color::srgb(0.75, 0.75, 0.78),
                metallic: 0.6,
                perceptual_roughness: 0.3,
                ..default()
            })),
        ));
    }
}

fn dress_ground(
    mut commands: Commands,
    grounds: Query<Entity, (With<StaticCollider>, Without<Mesh3d>)>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    for entity in &grounds {
        commands.entity(entity).insert((
            Mesh3d(meshes.add(Plane3d::default().mesh().size(40.0, 40.0))),
            MeshMaterial3d(materials.add(StandardMaterial {
                base_color: Color::srgb(0.42, 0.45, 0.4),
                perceptual_roughness: 0.9,
                ..default()
            })),
        ));
    }
}

fn controls(
    keys: Res<ButtonInput<KeyCode>>,
    mut time: ResMut<Time<Virtual>>,
    mut step_once: ResMut<StepOnce>,
    mut gizmos: ResMut<SoftBodyDebugGizmos>,
    mut inspector: ResMut<bevy_soft_body::inspector::SoftBodyInspector>,
) {
    if keys.just_pressed(KeyCode::Space) {
        if time.is_paused() {
            time.unpause();
        } else {
            time.pause();
        }
    }
    if keys.just_pressed(KeyCode::KeyN) && time.is_paused() {
        step_once.0 = true;
        time.unpause();
    }
    if keys.just_pressed(KeyCode::KeyG) {
        gizmos.enabled = !gizmos.enabled;
    }
    if keys.just_pressed(KeyCode::KeyP) {
        inspector.visible = !inspector.visible;
    }
}

fn finish_single_step(mut step_once: ResMut<StepOnce>, mut time: ResMut<Time<Virtual>>) {
    if step_once.0 {
        step_once.0 = false;
        time.pause();
    }
}

fn orbit_camera(
    keys: Res<ButtonInput<KeyCode>>,
    buttons: Res<ButtonInput<MouseButton>>,
    motion: Res<AccumulatedMouseMotion>,
    scroll: Res<AccumulatedMouseScroll>,
    real: Res<Time<Real>>,
    mut cameras: Query<(&mut OrbitCamera, &mut Transform)>,
) {
    let dt = real.delta_secs();
    for (mut orbit, mut transform) in &mut cameras {
        if buttons.pressed(MouseButton::Right) {
            orbit.yaw -= motion.delta.x * 0.005;
            orbit.pitch += motion.delta.y * 0.005;
        }
        let turn = 1.5 * dt;
        if keys.pressed(KeyCode::ArrowLeft) {
            orbit.yaw -= turn;
        }
        if keys.pressed(KeyCode::ArrowRight) {
            orbit.yaw += turn;
        }
        if keys.pressed(KeyCode::ArrowUp) {
            orbit.pitch += turn;
        }
        if keys.pressed(KeyCode::ArrowDown) {
            orbit.pitch -= turn;
        }
        orbit.pitch = orbit.pitch.clamp(-0.2, 1.5);
        orbit.distance = (orbit.distance * (1.0 - scroll.delta.y * 0.1)).clamp(0.5, 60.0);
        *transform = orbit.transform();
    }
}

#[derive(Component)]
struct HelpText;

fn setup_help(mut commands: Commands) {
    commands.spawn((
        Text::new(""),
        TextFont {
            font_size: FontSize::Px(15.0),
            ..default()
        },
        TextColor(Color::srgb(0.05, 0.05, 0.1)),
        Node {
            position_type: PositionType::Absolute,
            left: Val::Px(12.0),
            top: Val::Px(10.0),
            ..default()
        },
        HelpText,
    ));
}

fn update_help(
    time: Res<Time<Virtual>>,
    fixed: Res<Time<Fixed>>,
    gizmos: Res<SoftBodyDebugGizmos>,
    extra: Res<ExtraHelp>,
    stats: Query<(Option<&Name>, &SoftBodyStats)>,
    mut text: Query<&mut Text, With<HelpText>>,
) {
    let Ok(mut text) = text.single_mut() else {
        return;
    };
    let mut s = format!(
        "t = {:.2} s{}\nright drag / arrows: orbit   wheel: zoom\nSpace: pause   N: single step   R: reset\nG: gizmos ({})   P: panel\n",
        fixed.elapsed_secs(),
        if time.is_paused() { "  (paused)" } else { "" },
        if gizmos.enabled { "on" } else { "off" },
    );
    for line in &extra.0 {
        s.push_str(line);
        s.push('\n');
    }
    for (name, st) in &stats {
        s.push_str(&format!(
            "{}: volume error {:+.2} % (peak {:.2} %)\n",
            name.map_or("body", |n| n.as_str()),
            st.volume_error_pct,
            st.peak_volume_error_pct
        ));
    }
    text.0 = s;
}

fn count_frames_and_screenshot(
    mut commands: Commands,
    options: Res<ExampleOptions>,
    mut frames: ResMut<FrameCount>,
) {
    frames.0 += 1;
    let Some(path) = options.screenshot.clone() else {
        return;
    };
    if frames.0 == options.frames {
        if let Some(dir) = path.parent() {
            let _ = std::fs::create_dir_all(dir);
        }
        commands
            .spawn(Screenshot::primary_window())
            .observe(save_to_disk(path))
            .observe(
                |captured: On<ScreenshotCaptured>, mut exit: MessageWriter<AppExit>| {
                    // A picture of one colour means nothing was drawn: fail loudly.
                    let data = captured.image.data.as_deref().unwrap_or(&[]);
                    let first = data.get(..4);
                    let blank = data.chunks(4).all(|px| Some(px) == first);
                    if blank {
                        error!("the screenshot is a single colour");
                        exit.write(AppExit::error());
                    } else {
                        exit.write(AppExit::Success);
                    }
                },
            );
    }
}

/// Grabbing a soft body with the left mouse button ([`grab`]): particles within this distance
/// of the grabbed point move with the cursor.
const GRAB_RADIUS: f32 = 0.12;

/// The grab in progress: the body, the handle entity its particles follow, and the distance
/// from the camera of the plane the handle moves in.
#[derive(Resource, Default)]
pub struct Grab(pub Option<(Entity, Entity, f32)>);

#[allow(clippy::too_many_arguments)]
pub fn grab(
    buttons: Res<ButtonInput<MouseButton>>,
    window: Query<&Window, With<PrimaryWindow>>,
    camera: Query<(&Camera, &GlobalTransform)>,
    mut bodies: Query<(Entity, &SoftBody, Option<&DrivenParticles>)>,
    mut handles: Query<&mut Transform>,
    mut state: ResMut<Grab>,
    mut commands: Commands,
) {
    let (Ok(window), Ok((camera, eye))) = (window.single(), camera.single()) else {
        return;
    };
    let ray = window
        .cursor_position()
        .and_then(|c| camera.viewport_to_world(eye, c).ok());
    if buttons.just_released(MouseButton::Left) {
        if let Some((body, handle, _)) = state.0.take() {
            if let Ok(mut b) = commands.get_entity(body) {
                b.remove::<DrivenParticles>();
            }
            commands.entity(handle).despawn();
        }
        return;
    }
    let Some(ray) = ray else {
        return;
    };
    if let Some((_, handle, depth)) = state.0 {
        if let Ok(mut t) = handles.get_mut(handle) {
            t.translation = ray.origin + *ray.direction * depth;
        }
        return;
    }
    if !buttons.just_pressed(MouseButton::Left) {
        return;
    }
    // The particle nearest the cursor's ray (within a few cm of it), nearest the eye first.
    let mut best: Option<(Entity, Vec3, f32)> = None;
    for (entity, body, driven) in &mut bodies {
        if driven.is_some() || !body.is_placed() {
            continue;
        }
        for &p in body.state().positions() {
            let along = (p - ray.origin).dot(*ray.direction);
            let off = (ray.origin + *ray.direction * along).distance(p);
            if along > 0.0 && off < 0.08 && best.is_none_or(|(_, _, d)| along < d) {
                best = Some((entity, p, along));
            }
        }
    }
    let Some((entity, at, depth)) = best else {
        return;
    };
    let Ok((_, body, _)) = bodies.get(entity) else {
        return;
    };
    let particles: Vec<u32> = body
        .state()
        .positions()
        .iter()
        .enumerate()
        .filter(|(_, p)| p.distance(at) < GRAB_RADIUS)
        .map(|(i, _)| i as u32)
        .collect();
    let handle = commands
        .spawn((Transform::from_translation(at), SceneMember))
        .id();
    commands
        .entity(entity)
        .insert(DrivenParticles::new(handle, particles));
    state.0 = Some((entity, handle, depth));
}

/// Whether R was pressed (or a reset asked for): then every [`SceneMember`] is despawned and
/// any grab let go, and the example spawns its scene again.
pub fn clear_scene_on_reset(
    keys: &ButtonInput<KeyCode>,
    reset: &mut ResetScene,
    members: &Query<Entity, With<SceneMember>>,
    grab: &mut Grab,
    commands: &mut Commands,
) -> bool {
    if !(keys.just_pressed(KeyCode::KeyR) || reset.0) {
        return false;
    }
    reset.0 = false;
    grab.0 = None;
    for entity in members {
        commands.entity(entity).despawn();
    }
    true
}

/// What an example spawns its scene with (for [`respawn_on_reset`]).
pub type SpawnScene = fn(Commands, ResMut<Assets<Mesh>>, ResMut<Assets<StandardMaterial>>);

/// A system that spawns the scene anew with `spawn` when R is pressed (or a reset asked for).
#[allow(clippy::type_complexity)]
pub fn respawn_on_reset(
    spawn: SpawnScene,
) -> impl FnMut(
    Res<ButtonInput<KeyCode>>,
    ResMut<ResetScene>,
    Query<Entity, With<SceneMember>>,
    ResMut<Grab>,
    Commands,
    ResMut<Assets<Mesh>>,
    ResMut<Assets<StandardMaterial>>,
) {
    move |keys, mut reset, members, mut grab, mut commands, meshes, materials| {
        if clear_scene_on_reset(&keys, &mut reset, &members, &mut grab, &mut commands) {
            spawn(commands, meshes, materials);
        }
    }
}

/// The grey of the avian examples' static ground and fixtures.
#[cfg(feature = "avian")]
pub fn fixture_material(materials: &mut Assets<StandardMaterial>) -> Handle<StandardMaterial> {
    materials.add(StandardMaterial {
        base_color: Color::srgb(0.55, 0.57, 0.6),
        perceptual_roughness: 0.8,
        ..default()
    })
}

/// An avian ground (a static half-space), drawn as a `size` metre square of `material`.
#[cfg(feature = "avian")]
pub fn spawn_avian_ground(
    commands: &mut Commands,
    meshes: &mut Assets<Mesh>,
    material: Handle<StandardMaterial>,
    size: f32,
) {
    use avian3d::prelude::{Collider, RigidBody};
    commands.spawn((
        RigidBody::Static,
        Collider::half_space(Vec3::Y),
        Mesh3d(meshes.add(Plane3d::default().mesh().size(size, size))),
        MeshMaterial3d(material),
        Transform::default(),
        SceneMember,
    ));
}

/// The crate T throws from the camera in the avian examples: edge (m), mass (kg), speed (m/s).
#[cfg(feature = "avian")]
#[derive(Resource, Clone, Copy)]
pub struct ThrownCrate {
    pub size: f32,
    pub mass: f32,
    pub speed: f32,
}

/// T throws a [`ThrownCrate`] (an avian body) from the camera.
#[cfg(feature = "avian")]
pub fn throw_crate(
    keys: Res<ButtonInput<KeyCode>>,
    thrown: Res<ThrownCrate>,
    camera: Query<&Transform, With<Camera3d>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut commands: Commands,
) {
    use avian3d::prelude::{AngularVelocity, Collider, LinearVelocity, Mass, RigidBody};
    if !keys.just_pressed(KeyCode::KeyT) {
        return;
    }
    let Ok(eye) = camera.single() else {
        return;
    };
    let size = thrown.size;
    commands.spawn((
        RigidBody::Dynamic,
        Collider::cuboid(size, size, size),
        Mass(thrown.mass),
        Mesh3d(meshes.add(Cuboid::from_length(size))),
        MeshMaterial3d(materials.add(StandardMaterial::from_color(Color::srgb(0.72, 0.52, 0.3)))),
        Transform::from_translation(eye.translation + eye.forward() * 0.8),
        LinearVelocity(eye.forward() * thrown.speed),
        AngularVelocity(Vec3::new(1.0, 2.0, 0.5)),
        SceneMember,
    ));
}
