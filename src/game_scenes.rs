//! Scenes at game scale, beside the paper's: Earth gravity, bodies of 0.2 to 2 m, materials
//! from jelly to hard rubber, the crate's own grids and irregular meshes. `game_figures` runs
//! them for every method and step rate; the tests hold the paper's method to them.
//!
//! A scene is built on the simulation core ([`GameScene::world`]): the body, the ground and
//! any rigid sphere, stepped by [`GameWorld::step`] exactly as the plugin steps one body
//! (`SoftBodyState::step_with_contacts`), so that a table of hundreds of runs takes seconds.
//! [`GameScene::spawn`] puts the same scene in a Bevy app.

use std::sync::Arc;

use bevy::prelude::*;
use glam::UVec3;
use parry3d::math::Pose;
use parry3d::shape::SharedShape;

use crate::components::{RigidSphere, SoftBody, StaticCollider};
use crate::core::{
    ColliderInstance, Resolution, RigidSphereState, Serial, SoftBodyMaterial, SoftBodyState,
    TetMesh, VolumeMethod, box_grid, tetrahedralize, uv_sphere,
};

/// Earth's gravity, m/s^2.
pub const EARTH_GRAVITY: f32 = 9.81;

/// The shape of a scene's body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GameShape {
    /// A cube of this side, m, of `cells` grid cells a side.
    Cube {
        /// Side, m.
        size: f32,
        /// Cells a side.
        cells: u32,
    },
    /// A box of these sides, m, of cells of about `cell` m.
    Block {
        /// Sides, m.
        size: Vec3,
        /// Cell size, m.
        cell: f32,
    },
    /// A sphere of this diameter, m, tetrahedralized from a triangle surface to about `tets`.
    Sphere {
        /// Diameter, m.
        diameter: f32,
        /// Tets wanted.
        tets: u32,
    },
    /// The paper scenes' creature, scaled to this height, m, tetrahedralized to about `tets`.
    Creature {
        /// Height, m.
        height: f32,
        /// Tets wanted.
        tets: u32,
    },
    /// A tet mesh made by another tool, as it is, scaled so that its largest side is `size`, m.
    Bundled {
        /// The mesh.
        mesh: BundledMesh,
        /// Largest side, m.
        size: f32,
    },
}

/// Tet meshes made by other tools, shipped with the crate (`assets/meshes/`, each with its
/// source and licence in that folder's README): the irregular meshes (slivers, short edges,
/// tets of very different sizes side by side) that games bring, as the bench and the tests run
/// them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BundledMesh {
    /// The Stanford bunny as Ten Minute Physics tetrahedralized it (1 351 tets).
    Bunny,
    /// The dragon of Ten Minute Physics' skinning demo (3 840 tets).
    Dragon,
    /// The creature's surface (`assets/creature.obj`) tetrahedralized by TetGen.
    CreatureTetgen,
    /// The creature's surface tetrahedralized by fTetWild.
    CreatureFtetwild,
}

impl BundledMesh {
    /// Every bundled mesh.
    pub const ALL: [BundledMesh; 4] = [
        BundledMesh::Bunny,
        BundledMesh::Dragon,
        BundledMesh::CreatureTetgen,
        BundledMesh::CreatureFtetwild,
    ];

    /// Its name in tables and file names.
    pub fn name(self) -> &'static str {
        match self {
            BundledMesh::Bunny => "bunny_tmp",
            BundledMesh::Dragon => "dragon_tmp",
            BundledMesh::CreatureTetgen => "creature_tetgen",
            BundledMesh::CreatureFtetwild => "creature_ftetwild",
        }
    }

    /// Its TetGen files, `.node` and `.ele`.
    pub fn tetgen_files(self) -> (&'static str, &'static str) {
        macro_rules! files {
            ($name:literal) => {
                (
                    include_str!(concat!("../assets/meshes/", $name, ".node")),
                    include_str!(concat!("../assets/meshes/", $name, ".ele")),
                )
            };
        }
        match self {
            BundledMesh::Bunny => files!("bunny_tmp"),
            BundledMesh::Dragon => files!("dragon_tmp"),
            BundledMesh::CreatureTetgen => files!("creature_tetgen"),
            BundledMesh::CreatureFtetwild => files!("creature_ftetwild"),
        }
    }

    /// The mesh, as its files give it.
    pub fn load(self) -> Result<TetMesh, crate::core::TetGenError> {
        let (node, ele) = self.tetgen_files();
        crate::core::parse_tetgen(node, ele)
    }
}

/// How a grid body's mesh is distorted, to stand for the irregular meshes other tools write.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MeshStyle {
    /// The crate's own regular grid.
    Grid,
    /// Every vertex moved by up to this fraction of a cell along each axis (not off the
    /// box's faces), seeded: slivers with dihedral angles down to a few degrees.
    Jittered(f32),
    /// Cells graded along every axis so that the widest is this many times the narrowest:
    /// edge lengths spread over that ratio, short edges on light particles.
    Graded(f32),
}

/// A rigid sphere dropped on the body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GameSphere {
    /// Radius, m.
    pub radius: f32,
    /// Mass, kg.
    pub mass: f32,
    /// Height of its lowest point above the body's top, m (0: resting on it).
    pub gap: f32,
}

/// A scene at game scale.
#[derive(Clone, Debug, PartialEq)]
pub struct GameScene {
    /// Name for tables (`jelly_cube_drop`, ...).
    pub name: String,
    /// The body's shape.
    pub shape: GameShape,
    /// How its mesh is distorted.
    pub mesh: MeshStyle,
    /// Name of its material.
    pub material_name: &'static str,
    /// Its material (the method is set per run).
    pub material: SoftBodyMaterial,
    /// Height of its lowest point above the ground at the start, m.
    pub lift: f32,
    /// A rigid sphere on it, if any.
    pub sphere: Option<GameSphere>,
    /// Simulated seconds.
    pub duration_secs: f32,
}

/// What can go wrong building a scene's mesh.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("scene `{scene}`: {reason}")]
pub struct GameSceneError {
    /// The scene.
    pub scene: String,
    /// Why.
    pub reason: String,
}

impl GameScene {
    /// A scene of `shape` made of `material` (a name for tables, and the material: one of
    /// [`SoftBodyMaterial::PRESETS`] or any other), dropped from `lift`, for 3 s.
    pub fn new(
        name: &str,
        shape: GameShape,
        (material_name, material): (&'static str, SoftBodyMaterial),
        lift: f32,
    ) -> Self {
        GameScene {
            name: name.to_string(),
            shape,
            mesh: MeshStyle::Grid,
            material_name,
            material,
            lift,
            sphere: None,
            duration_secs: 3.0,
        }
    }

    /// The scenes `game_figures` runs and the tests check: every game situation the issue
    /// names, a cube in every preset, and the same cube on irregular meshes.
    pub fn standard() -> Vec<GameScene> {
        let cube = |size, cells| GameShape::Cube { size, cells };
        let mut scenes = vec![
            GameScene::new(
                "jelly_cube_small",
                cube(0.2, 6),
                ("jelly", SoftBodyMaterial::JELLY),
                0.3,
            ),
            GameScene::new(
                "jelly_cube_large",
                cube(2.0, 10),
                ("jelly", SoftBodyMaterial::JELLY),
                3.0,
            ),
            // The resolution a game gives a prop: 4 cells a side, 320 tets.
            GameScene::new(
                "jelly_cube_coarse",
                cube(0.5, 4),
                ("jelly", SoftBodyMaterial::JELLY),
                0.3,
            ),
            GameScene::new(
                "jelly_sphere",
                GameShape::Sphere {
                    diameter: 0.6,
                    tets: 2500,
                },
                ("jelly", SoftBodyMaterial::JELLY),
                1.0,
            ),
            GameScene::new(
                "rubber_ball",
                GameShape::Sphere {
                    diameter: 0.3,
                    tets: 1500,
                },
                ("rubber", SoftBodyMaterial::RUBBER),
                2.0,
            ),
            GameScene {
                sphere: Some(GameSphere {
                    radius: 0.2,
                    mass: 100.0,
                    gap: 1.0,
                }),
                ..GameScene::new(
                    "heavy_sphere_on_jelly",
                    GameShape::Block {
                        size: Vec3::new(1.0, 0.4, 1.0),
                        cell: 0.1,
                    },
                    ("jelly", SoftBodyMaterial::JELLY),
                    0.0,
                )
            },
            GameScene::new(
                "creature_landing",
                GameShape::Creature {
                    height: 1.2,
                    tets: 2500,
                },
                ("flesh", SoftBodyMaterial::FLESH),
                1.0,
            ),
            GameScene {
                sphere: Some(GameSphere {
                    radius: 0.3,
                    mass: 60.0,
                    gap: 0.0,
                }),
                ..GameScene::new(
                    "sphere_on_soft_block",
                    GameShape::Block {
                        size: Vec3::new(1.0, 0.5, 1.0),
                        cell: 0.1,
                    },
                    ("flesh", SoftBodyMaterial::FLESH),
                    0.0,
                )
            },
        ];
        for preset in SoftBodyMaterial::PRESETS {
            scenes.push(GameScene::new(
                &format!("{}_cube_drop", preset.0),
                cube(0.5, 8),
                preset,
                1.0,
            ));
        }
        for (style, label) in [
            (MeshStyle::Jittered(0.3), "jittered"),
            (MeshStyle::Graded(10.0), "graded"),
        ] {
            for preset in [
                ("jelly", SoftBodyMaterial::JELLY),
                ("hard_rubber", SoftBodyMaterial::HARD_RUBBER),
            ] {
                scenes.push(GameScene {
                    mesh: style,
                    ..GameScene::new(
                        &format!("{}_cube_{label}", preset.0),
                        cube(0.5, 8),
                        preset,
                        1.0,
                    )
                });
            }
        }
        scenes
    }

    /// The meshes other tools made ([`BundledMesh`]), each 1 m across in every preset, dropped
    /// from 0.5 m: what a game that brings its own mesh gets. Named `MESH_PRESET`.
    pub fn bundled() -> Vec<GameScene> {
        let mut scenes = Vec::new();
        for mesh in BundledMesh::ALL {
            for preset in SoftBodyMaterial::PRESETS {
                scenes.push(GameScene::new(
                    &format!("{}_{}", mesh.name(), preset.0),
                    GameShape::Bundled { mesh, size: 1.0 },
                    preset,
                    0.5,
                ));
            }
        }
        scenes
    }

    /// The body's tet mesh in its own frame, its lowest point at y = 0, centred in x and z.
    pub fn tet_mesh(&self) -> Result<TetMesh, GameSceneError> {
        let error = |reason: String| self.error(reason);
        let mesh = match self.shape {
            GameShape::Cube { size, cells } => box_grid(
                UVec3::splat(cells),
                Vec3::splat(size / cells as f32),
                Vec3::ZERO,
            )
            .map_err(|e| error(e.to_string()))?,
            GameShape::Block { size, cell } => {
                let cells = (size / cell).round().max(Vec3::ONE).as_uvec3();
                box_grid(cells, size / cells.as_vec3(), Vec3::ZERO)
                    .map_err(|e| error(e.to_string()))?
            }
            GameShape::Sphere { diameter, tets } => {
                let surface = uv_sphere(Vec3::ZERO, 0.5 * diameter, 48, 24);
                tetrahedralize(
                    &surface.positions,
                    &surface.indices,
                    Resolution::TargetTets(tets),
                )
                .map_err(|e| error(e.to_string()))?
                .mesh
            }
            GameShape::Creature { height, tets } => {
                let surface = crate::scenes::creature_surface();
                let (lo, hi) = crate::scenes::creature_bounds();
                let scale = height / (hi.y - lo.y);
                let positions: Vec<Vec3> = surface.positions.iter().map(|p| *p * scale).collect();
                tetrahedralize(&positions, &surface.indices, Resolution::TargetTets(tets))
                    .map_err(|e| error(e.to_string()))?
                    .mesh
            }
            GameShape::Bundled { mesh, size } => {
                let mesh = mesh.load().map_err(|e| error(e.to_string()))?;
                let (lo, hi) = mesh.bounds();
                let scale = size / (hi - lo).max_element();
                let positions = mesh.positions().iter().map(|p| *p * scale).collect();
                TetMesh::new(positions, mesh.tets().to_vec()).map_err(|e| error(e.to_string()))?
            }
        };
        let mesh = distort(mesh, self.mesh).map_err(|e| error(e.to_string()))?;
        // Lowest point at y = 0, centred in x and z.
        let (lo, hi) = mesh.bounds();
        let shift = Vec3::new(-0.5 * (lo.x + hi.x), -lo.y, -0.5 * (lo.z + hi.z));
        let positions = mesh.positions().iter().map(|p| *p + shift).collect();
        TetMesh::new(positions, mesh.tets().to_vec()).map_err(|e| error(e.to_string()))
    }

    /// The scene on the simulation core, with the body's material under `method`.
    pub fn world(&self, method: VolumeMethod) -> Result<GameWorld, GameSceneError> {
        let mesh = Arc::new(self.tet_mesh()?);
        let mut body = SoftBodyState::new(mesh.clone(), self.material.with_method(method))
            .map_err(|e| self.error(e.to_string()))?;
        body.translate(Vec3::Y * self.lift);
        let ground = ColliderInstance::new(SharedShape::halfspace(Vec3::Y), Pose::IDENTITY, 0.8);
        Ok(GameWorld {
            rest_height: mesh.bounds().1.y,
            spheres: self.spheres(&mesh),
            body,
            colliders: vec![ground],
            gravity: Vec3::new(0.0, -EARTH_GRAVITY, 0.0),
        })
    }

    /// The scene's rigid spheres, above `mesh` (the body's rest shape) lifted by `lift`.
    fn spheres(&self, mesh: &TetMesh) -> Vec<RigidSphereState> {
        let top = self.lift + mesh.bounds().1.y;
        self.sphere
            .iter()
            .map(|s| RigidSphereState {
                position: Vec3::new(0.0, top + s.gap + s.radius, 0.0),
                velocity: Vec3::ZERO,
                radius: s.radius,
                inv_mass: 1.0 / s.mass,
                friction: 0.5,
            })
            .collect()
    }

    /// An error about this scene.
    fn error(&self, reason: String) -> GameSceneError {
        GameSceneError {
            scene: self.name.clone(),
            reason,
        }
    }

    /// Spawns the scene in a Bevy app (the body, a ground, the sphere), with the body's material
    /// under `method`, shifted by `offset`. Returns the body's entity.
    pub fn spawn(
        &self,
        commands: &mut Commands,
        method: VolumeMethod,
        offset: Vec3,
    ) -> Result<Entity, GameSceneError> {
        let body = self.spawn_body(commands, method, offset)?;
        commands.spawn((
            StaticCollider::ground(0.8),
            Transform::from_translation(offset),
        ));
        Ok(body)
    }

    /// [`GameScene::spawn`] without the ground (for several scenes on one ground).
    pub fn spawn_body(
        &self,
        commands: &mut Commands,
        method: VolumeMethod,
        offset: Vec3,
    ) -> Result<Entity, GameSceneError> {
        let mesh = Arc::new(self.tet_mesh()?);
        let spheres = self.spheres(&mesh);
        let body = SoftBody::new(mesh, self.material.with_method(method))
            .map_err(|e| self.error(e.to_string()))?;
        let entity = commands
            .spawn((
                body,
                Transform::from_translation(offset + Vec3::Y * self.lift),
            ))
            .id();
        for s in &spheres {
            commands.spawn((
                RigidSphere {
                    friction: s.friction,
                    ..RigidSphere::new(s.radius, 1.0 / s.inv_mass)
                },
                Transform::from_translation(offset + s.position),
            ));
        }
        Ok(entity)
    }
}

/// Applies `style` to a grid mesh (other meshes are returned as they are).
fn distort(mesh: TetMesh, style: MeshStyle) -> Result<TetMesh, crate::core::TetMeshError> {
    let (lo, hi) = mesh.bounds();
    let size = hi - lo;
    let positions: Vec<Vec3> = match style {
        MeshStyle::Grid => return Ok(mesh),
        MeshStyle::Jittered(amount) => {
            // The grid's cell, from its shortest edge.
            let cell = mesh
                .edges()
                .iter()
                .map(|&[i, j]| mesh.positions()[i as usize].distance(mesh.positions()[j as usize]))
                .fold(f32::INFINITY, f32::min);
            let mut seed = 0x9e37_79b9_7f4a_7c15u64;
            let mut next = move || {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                (seed >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
            };
            let on_face = |p: f32, lo: f32, hi: f32| {
                (p - lo).abs() < 1e-4 * (hi - lo) || (p - hi).abs() < 1e-4 * (hi - lo)
            };
            mesh.positions()
                .iter()
                .map(|&p| {
                    let offset = Vec3::new(next(), next(), next()) * (amount * cell);
                    Vec3::new(
                        if on_face(p.x, lo.x, hi.x) {
                            p.x
                        } else {
                            p.x + offset.x
                        },
                        if on_face(p.y, lo.y, hi.y) {
                            p.y
                        } else {
                            p.y + offset.y
                        },
                        if on_face(p.z, lo.z, hi.z) {
                            p.z
                        } else {
                            p.z + offset.z
                        },
                    )
                })
                .collect()
        }
        MeshStyle::Graded(ratio) => {
            // u in [0, 1] -> ((1 + a)^u - 1) / a: cell widths grow by `ratio` end to end.
            let a = ratio - 1.0;
            let grade = |u: f32| ((1.0 + a).powf(u) - 1.0) / a;
            mesh.positions()
                .iter()
                .map(|&p| {
                    let u = (p - lo) / size;
                    lo + Vec3::new(grade(u.x), grade(u.y), grade(u.z)) * size
                })
                .collect()
        }
    };
    TetMesh::new(positions, mesh.tets().to_vec())
}

/// A scene on the simulation core: one body, the ground, any rigid spheres.
pub struct GameWorld {
    /// The body.
    pub body: SoftBodyState,
    /// The rigid spheres.
    pub spheres: Vec<RigidSphereState>,
    /// The ground.
    pub colliders: Vec<ColliderInstance>,
    /// Gravity.
    pub gravity: Vec3,
    /// The body's rest height, m.
    pub rest_height: f32,
}

impl GameWorld {
    /// One step of `h` seconds, as the plugin runs it for one body.
    pub fn step(&mut self, h: f32) {
        self.body
            .step_with_contacts(h, self.gravity, &mut self.spheres, &self.colliders, &Serial);
    }

    /// The body's height (top minus bottom) over its rest height.
    pub fn height_ratio(&self) -> f32 {
        let (lo, hi) = self
            .body
            .positions()
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p.y), hi.max(p.y))
            });
        (hi - lo) / self.rest_height
    }
}

/// What one run of a scene measured.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GameRun {
    /// Largest absolute total volume error, percent.
    pub peak_volume_error_pct: f64,
    /// Total volume error at the end, percent (signed).
    pub final_volume_error_pct: f64,
    /// Mean absolute per-tet error at the end, percent.
    pub final_mean_tet_error_pct: f64,
    /// Lowest height over rest height.
    pub lowest_height: f32,
    /// Height over rest height at the end.
    pub final_height: f32,
    /// Most inverted tets in a step.
    pub max_inverted_tets: usize,
    /// Whether every position stayed finite.
    pub finite: bool,
    /// Steps in which the body ran away and was put back.
    pub runaways: u32,
    /// Mean wall-clock time of a step, ms.
    pub mean_step_ms: f64,
    /// Slowest step, ms.
    pub max_step_ms: f64,
    /// Mean substeps a step.
    pub mean_substeps: f64,
    /// Tets of the body.
    pub tets: usize,
    /// Inverted tets at the end.
    pub final_inverted_tets: usize,
    /// When a particle first touched a collider, s.
    pub landed_at: Option<f32>,
    /// When the body fell asleep for the rest of the run, s.
    pub asleep_from: Option<f32>,
}

impl GameScene {
    /// Runs the scene with `method` at `hz` steps a second for its duration.
    pub fn run(&self, method: VolumeMethod, hz: f32) -> Result<GameRun, GameSceneError> {
        self.run_recording(method, hz, |_, _| {})
    }

    /// [`GameScene::run`], handing `record` the time and the total volume error (percent) after
    /// every step.
    pub fn run_recording(
        &self,
        method: VolumeMethod,
        hz: f32,
        mut record: impl FnMut(f32, f64),
    ) -> Result<GameRun, GameSceneError> {
        let mut world = self.world(method)?;
        let h = 1.0 / hz;
        let steps = (self.duration_secs * hz).round() as usize;
        let mut run = GameRun {
            lowest_height: f32::INFINITY,
            finite: true,
            tets: world.body.mesh().tet_count(),
            ..Default::default()
        };
        let mut elapsed = std::time::Duration::ZERO;
        for step in 0..steps {
            let start = std::time::Instant::now();
            world.step(h);
            let took = start.elapsed();
            elapsed += took;
            run.max_step_ms = run.max_step_ms.max(took.as_secs_f64() * 1e3);
            run.mean_substeps += world.body.counters().substeps as f64 / steps as f64;
            let t = (step + 1) as f32 * h;
            if run.landed_at.is_none() && world.body.contacts().next().is_some() {
                run.landed_at = Some(t);
            }
            run.asleep_from = world
                .body
                .is_sleeping()
                .then(|| run.asleep_from.unwrap_or(t));
            let m = world.body.volume_metrics();
            record(t, m.volume_error_pct);
            run.finite &= m.volume.is_finite();
            run.peak_volume_error_pct = run.peak_volume_error_pct.max(m.volume_error_pct.abs());
            run.max_inverted_tets = run.max_inverted_tets.max(m.inverted_tets);
            run.runaways += world.body.runaway().is_some() as u32;
            run.lowest_height = run.lowest_height.min(world.height_ratio());
            run.final_volume_error_pct = m.volume_error_pct;
            run.final_mean_tet_error_pct = m.mean_abs_tet_error_pct;
            run.final_inverted_tets = m.inverted_tets;
        }
        run.final_height = world.height_ratio();
        run.mean_step_ms = elapsed.as_secs_f64() * 1e3 / steps.max(1) as f64;
        Ok(run)
    }
}
