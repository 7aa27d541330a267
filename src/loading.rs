//! Soft bodies from assets (feature `render`): from any render [`Mesh`] (a glTF primitive, an
//! OBJ file through [`ObjMeshLoader`], a mesh built in code), tetrahedralized off the main
//! thread, or from a TetGen `.node`/`.ele` pair loaded as a [`TetMeshAsset`].
//!
//! Spawn [`SoftBodyFromAsset`] with a [`Transform`] (and, to see the model deform, the same
//! mesh as [`Mesh3d`] with a material). When the asset has loaded, [`SoftBodyAssetPlugin`]
//! builds the tet mesh on the [`AsyncComputeTaskPool`], so a large model does not stall the
//! game, then inserts the [`SoftBody`] on the entity, and a [`SoftBodySurface`] if the entity
//! shows the same mesh, and removes [`SoftBodyFromAsset`]. A model that cannot become a body is
//! reported as a [`SoftBodyError`] (kind [`SoftBodyErrorKind::Build`]) and the component is
//! removed; input parts too thin to get tets are logged as a warning.

use std::sync::Arc;

use bevy::asset::io::Reader;
use bevy::asset::{AssetLoader, AssetPath, LoadContext};
use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
use bevy::prelude::*;
use bevy::tasks::{AsyncComputeTaskPool, Task, futures::check_ready};

use crate::components::{SoftBody, SoftBodyError, SoftBodyErrorKind};
use crate::core::{
    Resolution, SoftBodyMaterial, TetGenError, TetMesh, Tetrahedralization, tetrahedralize,
};
use crate::surface::SoftBodySurface;

/// A tet mesh loaded from TetGen files: load the `.node` file; the `.ele` file beside it (same
/// name) is read with it.
#[derive(Asset, TypePath, Clone, Debug)]
pub struct TetMeshAsset(pub Arc<TetMesh>);

/// Loads [`TetMeshAsset`]s from `.node` files and the `.ele` files beside them.
#[derive(Default, TypePath)]
pub struct TetGenLoader;

/// Why a TetGen asset could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum TetGenLoadError {
    /// A file could not be read.
    #[error("cannot read {path}: {reason}")]
    Read {
        /// The file.
        path: String,
        /// Why.
        reason: String,
    },
    /// A file is not UTF-8 text.
    #[error("{0} is not UTF-8 text")]
    NotText(String),
    /// The files do not hold a valid mesh.
    #[error(transparent)]
    TetGen(#[from] TetGenError),
}

impl AssetLoader for TetGenLoader {
    type Asset = TetMeshAsset;
    type Settings = ();
    type Error = TetGenLoadError;

    async fn load(
        &self,
        reader: &mut dyn Reader,
        _settings: &(),
        load_context: &mut LoadContext<'_>,
    ) -> Result<TetMeshAsset, TetGenLoadError> {
        let node_path = load_context.path().clone_owned();
        let mut node = Vec::new();
        reader
            .read_to_end(&mut node)
            .await
            .map_err(|e| TetGenLoadError::Read {
                path: node_path.to_string(),
                reason: e.to_string(),
            })?;
        let ele_path = AssetPath::from_path_buf(node_path.path().with_extension("ele"))
            .with_source(node_path.source().clone_owned());
        let ele = load_context
            .read_asset_bytes(ele_path.clone())
            .await
            .map_err(|e| TetGenLoadError::Read {
                path: ele_path.to_string(),
                reason: e.to_string(),
            })?;
        let node =
            String::from_utf8(node).map_err(|_| TetGenLoadError::NotText(node_path.to_string()))?;
        let ele =
            String::from_utf8(ele).map_err(|_| TetGenLoadError::NotText(ele_path.to_string()))?;
        // Parsing validates the whole mesh; it is linear in the file size, fine on the loader's
        // task.
        let mesh = crate::core::parse_tetgen(&node, &ele)?;
        if !mesh.defects().is_empty() {
            // The body made of it reports them again, as a `SoftBodyError`, when it is placed.
            warn!("{node_path}: {}", mesh.defects());
        }
        Ok(TetMeshAsset(Arc::new(mesh)))
    }

    fn extensions(&self) -> &[&str] {
        &["node"]
    }
}

/// Loads Wavefront `.obj` files as [`Mesh`]es (positions, triangles and smooth normals; kept
/// in the main world so that a [`SoftBodySurface`] can deform them), so that an OBJ model can be
/// both drawn and made a soft body. Registered by [`SoftBodyAssetPlugin`] unless
/// `obj_loader` is off (for games that load OBJ files with another plugin).
#[derive(Default, TypePath)]
pub struct ObjMeshLoader;

/// Why an OBJ asset could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ObjLoadError {
    /// The file could not be read.
    #[error("cannot read the OBJ file: {0}")]
    Read(#[from] std::io::Error),
    /// The file is not a usable OBJ mesh.
    #[error(transparent)]
    Obj(#[from] crate::core::ObjError),
}

impl AssetLoader for ObjMeshLoader {
    type Asset = Mesh;
    type Settings = ();
    type Error = ObjLoadError;

    async fn load(
        &self,
        reader: &mut dyn Reader,
        _settings: &(),
        _load_context: &mut LoadContext<'_>,
    ) -> Result<Mesh, ObjLoadError> {
        let mut bytes = Vec::new();
        reader.read_to_end(&mut bytes).await?;
        let surface = crate::core::parse_obj(&bytes)?;
        Ok(crate::surface::surface_mesh(&surface))
    }

    fn extensions(&self) -> &[&str] {
        &["obj"]
    }
}

/// Where a [`SoftBodyFromAsset`] gets its tet mesh.
#[derive(Clone, Debug)]
pub enum SoftBodySource {
    /// A triangle mesh (its `TriangleList` positions and indices), tetrahedralized at
    /// `resolution`.
    Mesh {
        /// The mesh.
        mesh: Handle<Mesh>,
        /// How fine the tets are.
        resolution: Resolution,
    },
    /// A tet mesh loaded from TetGen files.
    TetMesh(Handle<TetMeshAsset>),
}

/// Becomes a [`SoftBody`] of `material` once `source` has loaded (see the module docs).
#[derive(Component)]
#[require(Transform)]
pub struct SoftBodyFromAsset {
    /// Where the tet mesh comes from.
    pub source: SoftBodySource,
    /// What the body is made of.
    pub material: SoftBodyMaterial,
    task: Option<Task<Result<Tetrahedralization, String>>>,
}

impl SoftBodyFromAsset {
    /// A body of `material` from `source`.
    pub fn new(source: SoftBodySource, material: SoftBodyMaterial) -> Self {
        SoftBodyFromAsset {
            source,
            material,
            task: None,
        }
    }

    /// Whether the tet mesh is being built.
    pub fn is_building(&self) -> bool {
        self.task.is_some()
    }
}

/// System set of the asset-to-body builds, in [`Update`].
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SoftBodyAssetSystems;

/// Registers [`TetMeshAsset`] with its loader (and, by default, [`ObjMeshLoader`]) and builds
/// [`SoftBodyFromAsset`]s. Needs the asset and mesh plugins (part of `DefaultPlugins`) and
/// [`crate::SoftBodyPlugin`].
pub struct SoftBodyAssetPlugin {
    /// Register [`ObjMeshLoader`] for `.obj` files.
    pub obj_loader: bool,
}

impl Default for SoftBodyAssetPlugin {
    fn default() -> Self {
        SoftBodyAssetPlugin { obj_loader: true }
    }
}

/// The plugin needs Bevy's asset and mesh plugins (both in `DefaultPlugins`). Added after them,
/// it registers in `build`; added before them, in `finish` (which `App::run` calls). An app
/// without them (`MinimalPlugins`, a headless server) gets no asset loading and a log line
/// saying so, not a panic: `SoftBody::new` needs no assets.
impl Plugin for SoftBodyAssetPlugin {
    fn build(&self, app: &mut App) {
        self.register(app);
    }

    fn finish(&self, app: &mut App) {
        if !self.register(app) {
            info!(
                "SoftBodyAssetPlugin: the app has no AssetServer or Assets<Mesh> (Bevy's \
                 AssetPlugin and MeshPlugin, part of DefaultPlugins), so bodies are not built \
                 from assets (SoftBodyFromAsset); SoftBody::new works without them"
            );
        }
    }
}

impl SoftBodyAssetPlugin {
    /// Registers the assets, loaders and system once, where the app has the asset server and
    /// mesh assets; whether they are registered.
    fn register(&self, app: &mut App) -> bool {
        let world = app.world();
        if world.contains_resource::<Assets<TetMeshAsset>>() {
            return true;
        }
        if !world.contains_resource::<AssetServer>() || !world.contains_resource::<Assets<Mesh>>() {
            return false;
        }
        app.init_asset::<TetMeshAsset>()
            .init_asset_loader::<TetGenLoader>()
            .add_systems(Update, build_bodies.in_set(SoftBodyAssetSystems));
        if self.obj_loader {
            app.init_asset_loader::<ObjMeshLoader>();
        }
        true
    }
}

/// The triangles of a render mesh, or why it has none that can be used.
fn mesh_triangles(mesh: &Mesh) -> Result<(Vec<Vec3>, Vec<u32>), String> {
    if mesh.primitive_topology() != PrimitiveTopology::TriangleList {
        return Err(format!(
            "the mesh is a {:?}, not a triangle list",
            mesh.primitive_topology()
        ));
    }
    let positions: Vec<Vec3> = match mesh.try_attribute(Mesh::ATTRIBUTE_POSITION) {
        Ok(VertexAttributeValues::Float32x3(v)) => v.iter().map(|&p| Vec3::from(p)).collect(),
        Ok(_) => return Err("the mesh's positions are not Float32x3".into()),
        Err(e) => return Err(format!("the mesh's positions cannot be read: {e}")),
    };
    let indices = match mesh.try_indices() {
        Ok(Indices::U16(i)) => i.iter().map(|&i| i as u32).collect(),
        Ok(Indices::U32(i)) => i.clone(),
        // Unindexed: every three vertices are a triangle.
        Err(bevy::mesh::MeshAccessError::NotFound) => (0..positions.len() as u32).collect(),
        Err(e) => return Err(format!("the mesh's indices cannot be read: {e}")),
    };
    Ok((positions, indices))
}

fn build_bodies(
    mut pending: Query<(
        Entity,
        &mut SoftBodyFromAsset,
        Option<&Mesh3d>,
        Option<&SoftBodySurface>,
    )>,
    meshes: Res<Assets<Mesh>>,
    tet_meshes: Res<Assets<TetMeshAsset>>,
    assets: Res<AssetServer>,
    mut commands: Commands,
    mut errors: MessageWriter<SoftBodyError>,
) {
    for (entity, mut from, mesh3d, surface) in &mut pending {
        let SoftBodyFromAsset {
            source,
            material,
            task,
        } = &mut *from;
        // What this frame brings: nothing yet, a tet mesh, or the reason there will be none.
        let outcome: Result<Option<Arc<TetMesh>>, String> = match source {
            SoftBodySource::TetMesh(handle) => match tet_meshes.get(&*handle) {
                Some(asset) => Ok(Some(asset.0.clone())),
                None if assets.load_state(&*handle).is_failed() => {
                    Err(format!("the tet mesh {handle:?} failed to load"))
                }
                None => Ok(None),
            },
            SoftBodySource::Mesh { mesh, resolution } => match task {
                None => match meshes.get(&*mesh) {
                    Some(source) => mesh_triangles(source).map(|(positions, indices)| {
                        let resolution = *resolution;
                        *task = Some(AsyncComputeTaskPool::get().spawn(async move {
                            tetrahedralize(&positions, &indices, resolution)
                                .map_err(|e| e.to_string())
                        }));
                        None
                    }),
                    None if assets.load_state(&*mesh).is_failed() => {
                        Err(format!("the mesh {mesh:?} failed to load"))
                    }
                    None => Ok(None),
                },
                Some(running) => match check_ready(running) {
                    None => Ok(None),
                    Some(Err(reason)) => Err(reason),
                    Some(Ok(t)) => {
                        if !t.parts_without_tets.is_empty() {
                            warn!(
                                "soft body {entity}: parts {:?} of {mesh:?} are thinner than a \
                                 cell ({} m) and got no tets; ask for more tets to keep them",
                                t.parts_without_tets, t.cell_size
                            );
                        }
                        let shown = mesh3d.is_some_and(|m| m.0.id() == mesh.id());
                        if shown && surface.is_none() {
                            commands.entity(entity).insert(SoftBodySurface::new(entity));
                        }
                        Ok(Some(Arc::new(t.mesh)))
                    }
                },
            },
        };
        let outcome = outcome.and_then(|mesh| match mesh {
            Some(mesh) => SoftBody::new(mesh, *material)
                .map(Some)
                .map_err(|e| e.to_string()),
            None => Ok(None),
        });
        match outcome {
            Ok(None) => {}
            Ok(Some(body)) => {
                commands
                    .entity(entity)
                    .insert(body)
                    .remove::<SoftBodyFromAsset>();
            }
            Err(reason) => {
                let error = SoftBodyError {
                    body: entity,
                    kind: SoftBodyErrorKind::Build { reason },
                };
                error!("{error}");
                errors.write(error);
                commands.entity(entity).remove::<SoftBodyFromAsset>();
            }
        }
    }
}
