//! The paper's five scenes (its section 6) as reusable builders, shared by the tests, the
//! examples and the `paper_figures` command.
//!
//! The paper gives stiffnesses (`k_V = 1.4` for the baseline, `k_D` per scene) but no sizes,
//! masses or gravity. Its stiffnesses are energies with scale-invariant normalisation
//! (`E_D = 1/2 k_D ((L - D0) / D0)^2`), which are weak: with 10 cm cells of water density the
//! springs of the soft cube (`k_D = 0.2`) cannot carry the cube's weight under 9.81 m/s^2, and
//! lighter bodies make the explicit baseline diverge at `h = 10 ms`. So every scene uses 10 cm
//! cells (about, for the creature) and density 1000 kg/m^3 (particles of about 1 kg) and a
//! weaker gravity chosen per scene; the table in `README.md` lists every choice. The scenes
//! are calibrated so that the baseline loses about the volume the paper reports for it.

use std::sync::Arc;

use bevy::prelude::*;
use glam::UVec3;

use crate::components::{
    DrivenParticles, PinnedParticles, RigidSphere, SoftBody, SoftBodyGravity,
    SoftBodySleepingDisabled, StaticCollider,
};
use crate::core::{
    Elasticity, Plasticity, Resolution, SoftBodyMaterial, TetMesh, TriangleSurface, VolumeMethod,
    box_grid, parse_obj, tetrahedralize,
};
use crate::plugin::{SoftBodyPlugin, SoftBodySystems};

/// One of the paper's scenes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Reflect)]
pub enum PaperScene {
    /// A 4320-tet bar, one end held, the other turned one and a half times about the bar's axis,
    /// then released.
    BarTwist,
    /// A rigid sphere dropped onto the same bar, held at both ends.
    SphereOnBar,
    /// A heavy rigid sphere falls onto a very soft 8640-tet cube on the ground.
    SoftCube,
    /// A procedural creature (body, legs, arms, head; about 6500 tets like the paper's
    /// armadillo) falls onto the ground, squashes its feet and jumps up again.
    Creature,
    /// A heavy sphere dents a block with plastic springs and is then taken away: the dent stays.
    Plastic,
}

/// Cell size of the box grids, in metres.
pub const CELL: f32 = 0.1;

/// Cell size of the soft cube, in metres (a 2.4 m cube). Why larger cells: with the paper's
/// normalised stiffnesses a body's natural time scale grows with its cells as `L^(5/2)`, so
/// the explicit baseline stays stable through the sphere's impact at `h = 10 ms`; with 10 cm
/// cells it diverges under any impact that costs it more than a few percent, whereas the same
/// scene simulated with a time step small enough to converge loses nearly half its volume, as
/// the paper reports.
pub const SOFT_CUBE_CELL: f32 = 0.2;

/// The rigid sphere of a scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneSphere {
    /// Radius, m.
    pub radius: f32,
    /// Mass, kg.
    pub mass: f32,
    /// Downward speed at spawn, m/s.
    pub speed: f32,
    /// Gap between the sphere and the top of the body at spawn, m.
    pub gap: f32,
    /// Despawned after this many seconds (the plastic scene takes its sphere away).
    pub remove_after: Option<f32>,
}

/// Everything the paper leaves open about a scene, chosen here (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneParams {
    /// Body density, kg/m^3.
    pub density: f32,
    /// Spring damping.
    pub damping: f32,
    /// Drag on the particles' velocities, 1/s (see [`SoftBodyMaterial::linear_damping`]).
    pub linear_damping: f32,
    /// Gravity, m/s^2 (downwards).
    pub gravity: f32,
    /// Height of the body's lowest point above the ground at spawn, m.
    pub lift: f32,
    /// Downward speed of the body at spawn, m/s (the creature is thrown down: under a gravity
    /// strong enough to give it that speed by falling, it slumps instead of standing).
    pub speed: f32,
    /// The sphere, if the scene has one.
    pub sphere: Option<SceneSphere>,
    /// Simulated seconds.
    pub duration_secs: f32,
}

impl PaperScene {
    /// All five, in the paper's order.
    pub const ALL: [PaperScene; 5] = [
        PaperScene::BarTwist,
        PaperScene::SphereOnBar,
        PaperScene::SoftCube,
        PaperScene::Creature,
        PaperScene::Plastic,
    ];

    /// Name used in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            PaperScene::BarTwist => "bar_twist",
            PaperScene::SphereOnBar => "sphere_on_bar",
            PaperScene::SoftCube => "soft_cube",
            PaperScene::Creature => "creature",
            PaperScene::Plastic => "plastic",
        }
    }

    /// The scene called `name`.
    pub fn from_name(name: &str) -> Option<PaperScene> {
        PaperScene::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The paper's `k_D` for the scene.
    pub fn distance_stiffness(self) -> f32 {
        match self {
            PaperScene::BarTwist => 0.4,
            PaperScene::SphereOnBar => 0.8,
            PaperScene::SoftCube => 0.2,
            PaperScene::Creature => 1.5,
            PaperScene::Plastic => 8.0,
        }
    }

    /// Sizes, masses, gravity and timing of the scene. Why these: the module documentation and
    /// `README.md`. Denser bodies (soft cube, plastic) keep the explicit baseline stable under
    /// their loads; their gravity is weaker in proportion, so that they carry their own weight.
    pub fn params(self) -> SceneParams {
        match self {
            PaperScene::BarTwist => SceneParams {
                density: 1000.0,
                damping: 4.0,
                linear_damping: 0.6,
                gravity: 0.0,
                lift: 0.0,
                speed: 0.0,
                sphere: None,
                duration_secs: 16.0,
            },
            PaperScene::SphereOnBar => SceneParams {
                density: 1000.0,
                damping: 1.0,
                linear_damping: 0.0,
                gravity: 0.2,
                lift: 1.0,
                speed: 0.0,
                sphere: Some(SceneSphere {
                    radius: 0.3,
                    mass: 250.0,
                    speed: 1.0,
                    gap: 0.5,
                    remove_after: None,
                }),
                duration_secs: 6.0,
            },
            PaperScene::SoftCube => SceneParams {
                density: 1000.0,
                damping: 100.0,
                linear_damping: 1.5,
                gravity: 0.01,
                lift: 0.0,
                speed: 0.0,
                sphere: Some(SceneSphere {
                    radius: 1.6,
                    mass: 10000.0,
                    speed: 1.8,
                    gap: 0.6,
                    remove_after: None,
                }),
                duration_secs: 20.0,
            },
            PaperScene::Creature => SceneParams {
                density: 1000.0,
                damping: 1.0,
                linear_damping: 0.0,
                gravity: 0.1,
                lift: 0.5,
                speed: 0.7,
                sphere: None,
                duration_secs: 8.0,
            },
            PaperScene::Plastic => SceneParams {
                density: 4000.0,
                damping: 2.0,
                linear_damping: 0.0,
                gravity: 1.0,
                lift: 0.0,
                speed: 0.0,
                sphere: Some(SceneSphere {
                    radius: 0.35,
                    mass: 800.0,
                    speed: 0.5,
                    gap: 0.2,
                    remove_after: Some(3.0),
                }),
                duration_secs: 8.0,
            },
        }
    }

    /// Simulated seconds the scene runs for.
    pub fn duration_secs(self) -> f32 {
        self.params().duration_secs
    }

    /// Gravity of the scene.
    pub fn gravity(self) -> Vec3 {
        Vec3::new(0.0, -self.params().gravity, 0.0)
    }

    /// The body's material with `method`.
    pub fn material(self, method: VolumeMethod) -> SoftBodyMaterial {
        let params = self.params();
        SoftBodyMaterial {
            density: params.density,
            elasticity: Elasticity::Springs {
                distance_stiffness: self.distance_stiffness(),
                damping: params.damping,
            },
            linear_damping: params.linear_damping,
            // The paper's scenes as published: no damping but theirs.
            deformation_damping: 0.0,
            friction: 0.6,
            rolling_resistance: 0.0,
            method,
            plasticity: (self == PaperScene::Plastic).then_some(Plasticity {
                yield_strain: 0.03,
                creep: 4.0,
                max_strain: 0.5,
            }),
        }
    }

    /// The scene's tet mesh in its own frame (minimum corner or feet at the origin).
    pub fn tet_mesh(self) -> Arc<TetMesh> {
        let mesh = match self {
            PaperScene::BarTwist | PaperScene::SphereOnBar => {
                box_grid(UVec3::new(24, 6, 6), Vec3::splat(CELL), Vec3::ZERO)
            }
            PaperScene::SoftCube => {
                box_grid(UVec3::splat(12), Vec3::splat(SOFT_CUBE_CELL), Vec3::ZERO)
            }
            PaperScene::Creature => {
                // Tetrahedralized once per process (a tenth of a second), then shared.
                static CREATURE: std::sync::OnceLock<Arc<TetMesh>> = std::sync::OnceLock::new();
                return CREATURE
                    .get_or_init(|| {
                        Arc::new(creature_tet_mesh().expect("the shipped creature tetrahedralizes"))
                    })
                    .clone();
            }
            PaperScene::Plastic => box_grid(UVec3::new(12, 5, 12), Vec3::splat(CELL), Vec3::ZERO),
        };
        Arc::new(mesh.expect("the built-in scene meshes are valid"))
    }

    /// The detailed surface drawn for the scene's body, in the tet mesh's frame: a box
    /// subdivided four times finer than its cells, or the creature's shipped surface
    /// ([`creature_surface`]).
    pub fn render_surface(self) -> TriangleSurface {
        match self {
            PaperScene::Creature => creature_surface().clone(),
            _ => {
                let (lo, hi) = self.tet_mesh().bounds();
                let cell = if self == PaperScene::SoftCube {
                    SOFT_CUBE_CELL
                } else {
                    CELL
                };
                crate::core::subdivided_box(lo, hi, cell / 4.0)
            }
        }
    }

    /// Spawns the scene with its body simulated by `method`, shifted by `offset` (to put two
    /// copies side by side). Sets the gravity resource. Returns the body entity.
    pub fn spawn(self, commands: &mut Commands, method: VolumeMethod, offset: Vec3) -> Entity {
        commands.insert_resource(SoftBodyGravity(self.gravity()));
        let params = self.params();
        let mesh = self.tet_mesh();
        let mut body =
            SoftBody::new(mesh.clone(), self.material(method)).expect("scene materials are valid");
        for v in body.velocities_mut() {
            v.y = -params.speed;
        }
        let (lo, hi) = mesh.bounds();
        let size = hi - lo;
        let place = offset + Vec3::new(0.0, params.lift, 0.0);
        let body_entity = commands
            .spawn((
                body,
                Transform::from_translation(place),
                Name::new(self.name()),
                // The paper's scenes run as published, without sleeping (XPBD would sleep
                // otherwise).
                SoftBodySleepingDisabled,
            ))
            .id();
        if self != PaperScene::BarTwist {
            commands.spawn((
                StaticCollider::ground(0.8),
                Transform::from_translation(offset),
                Name::new("ground"),
            ));
        }
        if let Some(s) = params.sphere {
            let mut sphere = RigidSphere::new(s.radius, s.mass);
            sphere.velocity = Vec3::new(0.0, -s.speed, 0.0);
            let centre = place + Vec3::new(size.x / 2.0, size.y + s.radius + s.gap, size.z / 2.0);
            let mut entity = commands.spawn((
                sphere,
                Transform::from_translation(centre),
                Name::new("sphere"),
            ));
            if let Some(t) = s.remove_after {
                entity.insert(RemoveAfter(t));
            }
        }
        match self {
            PaperScene::BarTwist => {
                let end = particles_where(&mesh, |p| p.x >= hi.x - 1e-4);
                let held = particles_where(&mesh, |p| p.x <= lo.x + 1e-4);
                let centre = place + Vec3::new(hi.x, size.y / 2.0, size.z / 2.0);
                let handle = commands
                    .spawn((
                        Transform::from_translation(centre),
                        TwistDriver {
                            body: body_entity,
                            turns: 1.5,
                            ramp_secs: 3.0,
                            hold_secs: 1.0,
                            axis: Vec3::X,
                            elapsed: 0.0,
                        },
                        Name::new("twist handle"),
                    ))
                    .id();
                commands
                    .entity(body_entity)
                    .insert((PinnedParticles(held), DrivenParticles::new(handle, end)));
            }
            PaperScene::SphereOnBar => {
                let ends = particles_where(&mesh, |p| p.x <= lo.x + 1e-4 || p.x >= hi.x - 1e-4);
                commands.entity(body_entity).insert(PinnedParticles(ends));
            }
            PaperScene::SoftCube | PaperScene::Creature | PaperScene::Plastic => {}
        }
        body_entity
    }
}

/// Indices of the rest positions that satisfy `keep`.
pub fn particles_where(mesh: &TetMesh, keep: impl Fn(Vec3) -> bool) -> Vec<u32> {
    (0..mesh.vertex_count() as u32)
        .filter(|&i| keep(mesh.positions()[i as usize]))
        .collect()
}

/// Turns its entity about `axis` (through its translation) by `turns` full turns over
/// `ramp_secs`, holds `hold_secs`, then releases the body's driven particles (the held end
/// stays held, as in the paper).
#[derive(Component, Clone, Debug, Reflect)]
#[reflect(Component)]
pub struct TwistDriver {
    /// The body whose particles follow this entity.
    pub body: Entity,
    /// Full turns.
    pub turns: f32,
    /// Seconds to turn.
    pub ramp_secs: f32,
    /// Seconds to hold before release.
    pub hold_secs: f32,
    /// The axis of the turn.
    pub axis: Vec3,
    /// Simulated seconds since the twist began (counted here, so a scene spawned again later
    /// starts from the beginning).
    pub elapsed: f32,
}

/// Despawns its entity after this many more seconds of simulated time (the plastic scene's
/// sphere).
#[derive(Component, Clone, Copy, Debug, Reflect)]
#[reflect(Component)]
pub struct RemoveAfter(pub f32);

/// The systems that drive the scenes (the twist, the sphere taken away). Runs in
/// [`FixedUpdate`] before [`SoftBodySystems::Prepare`].
pub struct PaperScenesPlugin;

impl Plugin for PaperScenesPlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<TwistDriver>()
            .register_type::<RemoveAfter>()
            .add_systems(
                FixedUpdate,
                (drive_twist, remove_after).before(SoftBodySystems::Prepare),
            );
    }
}

fn drive_twist(
    time: Res<Time>,
    mut commands: Commands,
    mut drivers: Query<(Entity, &mut TwistDriver, &mut Transform)>,
) {
    for (entity, mut driver, mut transform) in &mut drivers {
        driver.elapsed += time.delta_secs();
        // A step ahead: the particles reach the target during the coming step.
        let t = driver.elapsed + time.delta_secs();
        let progress = (t / driver.ramp_secs).min(1.0);
        // Smooth start and stop, so the twist does not kick the bar.
        let eased = progress * progress * (3.0 - 2.0 * progress);
        transform.rotation =
            Quat::from_axis_angle(driver.axis, eased * driver.turns * std::f32::consts::TAU);
        if t > driver.ramp_secs + driver.hold_secs {
            commands.entity(driver.body).remove::<DrivenParticles>();
            commands.entity(entity).remove::<TwistDriver>();
        }
    }
}

fn remove_after(
    time: Res<Time>,
    mut commands: Commands,
    mut items: Query<(Entity, &mut RemoveAfter)>,
) {
    for (entity, mut remaining) in &mut items {
        remaining.0 -= time.delta_secs();
        // Half a step of slack against rounding: "after 3 s" means at the step that ends at 3 s.
        if remaining.0 <= 0.5 * time.delta_secs() {
            commands.entity(entity).despawn();
        }
    }
}

/// Signed distance of the procedural creature (metres, feet on `y = 0`, facing +Z): a torso,
/// a head, two legs with feet, two arms and a tail, blended with a smooth union. Also the
/// source of its detailed render surface.
pub fn creature_sdf(p: Vec3) -> f32 {
    fn ellipsoid(p: Vec3, c: Vec3, r: Vec3) -> f32 {
        let q = (p - c) / r;
        (q.length() - 1.0) * r.min_element()
    }
    fn capsule(p: Vec3, a: Vec3, b: Vec3, r: f32) -> f32 {
        let (pa, ba) = (p - a, b - a);
        let h = (pa.dot(ba) / ba.length_squared()).clamp(0.0, 1.0);
        (pa - ba * h).length() - r
    }
    fn smooth_union(a: f32, b: f32, k: f32) -> f32 {
        let h = (0.5 + 0.5 * (b - a) / k).clamp(0.0, 1.0);
        b + (a - b) * h - k * h * (1.0 - h)
    }
    let s = 2.0;
    let p = p / s;
    let torso = ellipsoid(p, Vec3::new(0.0, 0.78, 0.0), Vec3::new(0.33, 0.36, 0.27));
    let head = ellipsoid(p, Vec3::new(0.0, 1.25, 0.08), Vec3::new(0.2, 0.19, 0.2));
    let legs = capsule(
        p,
        Vec3::new(-0.17, 0.55, 0.0),
        Vec3::new(-0.2, 0.14, 0.02),
        0.12,
    )
    .min(capsule(
        p,
        Vec3::new(0.17, 0.55, 0.0),
        Vec3::new(0.2, 0.14, 0.02),
        0.12,
    ));
    let feet = ellipsoid(p, Vec3::new(-0.2, 0.07, 0.08), Vec3::new(0.13, 0.07, 0.2)).min(
        ellipsoid(p, Vec3::new(0.2, 0.07, 0.08), Vec3::new(0.13, 0.07, 0.2)),
    );
    let arms = capsule(
        p,
        Vec3::new(-0.28, 0.95, 0.05),
        Vec3::new(-0.5, 0.62, 0.2),
        0.08,
    )
    .min(capsule(
        p,
        Vec3::new(0.28, 0.95, 0.05),
        Vec3::new(0.5, 0.62, 0.2),
        0.08,
    ));
    let tail = capsule(
        p,
        Vec3::new(0.0, 0.6, -0.2),
        Vec3::new(0.0, 0.3, -0.55),
        0.07,
    );
    let mut d = smooth_union(torso, head, 0.06);
    d = smooth_union(d, legs, 0.06);
    d = smooth_union(d, feet, 0.04);
    d = smooth_union(d, arms, 0.05);
    d = smooth_union(d, tail, 0.05);
    d * s
}

/// Bounds of [`creature_sdf`]'s shape, with a margin.
pub fn creature_bounds() -> (Vec3, Vec3) {
    (Vec3::new(-1.3, -0.02, -1.3), Vec3::new(1.3, 2.95, 1.0))
}

/// The creature's detailed surface (24 872 triangles), shipped in `assets/creature.obj` and
/// built into the crate. `examples/creature_asset.rs` writes it from [`creature_sdf`].
pub fn creature_surface() -> &'static TriangleSurface {
    static SURFACE: std::sync::OnceLock<TriangleSurface> = std::sync::OnceLock::new();
    SURFACE.get_or_init(|| {
        parse_obj(include_bytes!("../assets/creature.obj"))
            .expect("the shipped creature surface is valid OBJ (tested)")
    })
}

/// Tets of the creature scene: about the 6510 of the paper's armadillo.
pub const CREATURE_TETS: u32 = 6500;

/// The creature's tet mesh: [`creature_surface`] tetrahedralized to about [`CREATURE_TETS`].
pub fn creature_tet_mesh() -> Result<TetMesh, crate::core::TetrahedralizeError> {
    let surface = creature_surface();
    tetrahedralize(
        &surface.positions,
        &surface.indices,
        Resolution::TargetTets(CREATURE_TETS),
    )
    .map(|t| t.mesh)
}

/// A headless app (`MinimalPlugins`, time advancing exactly one 10 ms step per update) with the
/// plugin, the scene drivers and `scene` spawned with `method`. Returns the app and the body.
pub fn headless_scene_app(scene: PaperScene, method: VolumeMethod) -> (App, Entity) {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, SoftBodyPlugin::default(), PaperScenesPlugin))
        .insert_resource(bevy::time::TimeUpdateStrategy::ManualDuration(
            std::time::Duration::from_millis(10),
        ));
    let body = {
        let world = app.world_mut();
        let mut commands = world.commands();
        let body = scene.spawn(&mut commands, method, Vec3::ZERO);
        world.flush();
        body
    };
    // The first update only starts the clock; after it, every update is one step.
    app.update();
    (app, body)
}
