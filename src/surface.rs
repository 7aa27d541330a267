//! Embedded render surfaces: a detailed Bevy [`Mesh`] that follows a soft body's coarse tet
//! mesh, as in the paper, where the simulation runs on tets and the player sees a fine surface.
//!
//! Put [`SoftBodySurface`] next to a [`Mesh3d`] (and a material) on a top-level entity, often
//! the soft body's own entity, and add [`SoftBodySurfacePlugin`]. The mesh is given in the same
//! frame as the body's tet mesh (the model's own coordinates, before the spawn transform). The
//! first frame both the body is placed and the mesh asset is loaded, each vertex is bound to a
//! tet ([`SurfaceBinding`]); every frame after that the vertices follow the particles, the
//! normals are recomputed and the entity's [`Aabb`] is set to the new bounds, so culling follows
//! the body. The mesh must keep [`RenderAssetUsages::MAIN_WORLD`] (the default for meshes built
//! in code) so that it can be edited.
//!
//! Physics runs at a fixed 100 Hz; frames come at any rate. The surface is drawn between the
//! last two physics states, interpolated by how far the frame is into the next step
//! ([`Time<Fixed>::overstep_fraction`]), so motion does not stutter at 60, 144 or 45 Hz. This
//! costs one step of latency, which is the usual price of interpolation.
//!
//! [`RenderAssetUsages::MAIN_WORLD`]: bevy::asset::RenderAssetUsages::MAIN_WORLD

use std::sync::Arc;

use bevy::camera::primitives::Aabb;
use bevy::camera::visibility::VisibilitySystems;
use bevy::mesh::VertexAttributeValues;
use bevy::prelude::*;

use crate::components::{SoftBody, SoftBodyError, SoftBodyErrorKind};
use crate::core::{SurfaceBinding, TetMesh};
use crate::plugin::SoftBodyTiming;

/// Deforms the [`Mesh3d`] of its entity to follow the particles of the soft body `body`.
/// The mesh is given in the tet mesh's rest frame, usually finer than the tets; each vertex is
/// bound to the tet holding it (or the nearest one) when first seen.
///
/// ```
/// use bevy::prelude::*;
/// use bevy_soft_body::core::{box_grid, subdivided_box};
/// use bevy_soft_body::prelude::*;
/// use bevy_soft_body::surface_mesh;
///
/// fn spawn_jelly(mut commands: Commands, mut meshes: ResMut<Assets<Mesh>>) {
///     // A 0.5 m cube of 4 x 4 x 4 cells drawn as a box with 2.5 cm faces.
///     let tets = box_grid(UVec3::splat(4), Vec3::splat(0.125), Vec3::ZERO).unwrap();
///     let jelly = SoftBody::new(tets.into(), SoftBodyMaterial::JELLY).unwrap();
///     let body = commands.spawn((jelly, Transform::from_xyz(0.0, 1.0, 0.0))).id();
///     let detail = subdivided_box(Vec3::ZERO, Vec3::splat(0.5), 0.025);
///     commands
///         .entity(body)
///         .insert((SoftBodySurface::new(body), Mesh3d(meshes.add(surface_mesh(&detail)))));
/// }
/// # let mut app = App::new();
/// # app.add_plugins((MinimalPlugins, AssetPlugin::default(), bevy::mesh::MeshPlugin));
/// # app.add_plugins((SoftBodyPlugin::default(), SoftBodySurfacePlugin));
/// # app.add_systems(Startup, spawn_jelly);
/// # app.update();
/// ```
#[derive(Component, Debug)]
#[require(Transform)]
pub struct SoftBodySurface {
    /// The soft body entity (may be this entity).
    pub body: Entity,
    binding: Option<SurfaceBinding>,
    /// The tet mesh it was bound to, and the one it was last drawn on: when the body tears
    /// (`SoftBodyTearing`) the two differ, and triangles across the cut are taken out.
    bound_to: Option<Arc<TetMesh>>,
    drawn_on: Option<Arc<TetMesh>>,
    /// Interpolated particle positions, then surface points: reused every frame.
    particles: Vec<Vec3>,
    points: Vec<Vec3>,
    /// An error was reported; the surface is left as it is.
    failed: bool,
}

impl SoftBodySurface {
    /// A surface following the soft body `body`.
    pub fn new(body: Entity) -> Self {
        SoftBodySurface {
            body,
            binding: None,
            bound_to: None,
            drawn_on: None,
            particles: Vec::new(),
            points: Vec::new(),
            failed: false,
        }
    }

    /// The binding of the mesh's vertices to tets, once made.
    pub fn binding(&self) -> Option<&SurfaceBinding> {
        self.binding.as_ref()
    }
}

/// A Bevy mesh of `surface`, editable in the main world (as [`SoftBodySurface`] needs), with
/// normals.
pub fn surface_mesh(surface: &crate::core::TriangleSurface) -> Mesh {
    use bevy::asset::RenderAssetUsages;
    use bevy::mesh::{Indices, PrimitiveTopology};
    let positions: Vec<[f32; 3]> = surface.positions.iter().map(|p| p.to_array()).collect();
    Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::MAIN_WORLD | RenderAssetUsages::RENDER_WORLD,
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
    .with_inserted_indices(Indices::U32(surface.indices.clone()))
    .with_computed_smooth_normals()
}

/// System set of the surface update, in [`PostUpdate`] before bounds are computed.
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SoftBodySurfaceSystems;

/// Updates every [`SoftBodySurface`]. Needs the mesh assets (Bevy's asset and mesh plugins,
/// part of `DefaultPlugins`) and [`crate::SoftBodyPlugin`]. Added after the mesh plugin, its
/// system is added in `build`; added before it, in `finish` (which `App::run` calls). An app
/// without mesh assets (`MinimalPlugins`, a headless server) draws nothing, so the plugin adds
/// nothing there and logs why.
pub struct SoftBodySurfacePlugin;

/// Marks that [`SoftBodySurfacePlugin`] added its system.
#[derive(Resource)]
struct SurfacesFollow;

impl Plugin for SoftBodySurfacePlugin {
    fn build(&self, app: &mut App) {
        app.configure_sets(
            PostUpdate,
            SoftBodySurfaceSystems.before(VisibilitySystems::CalculateBounds),
        );
        add_surface_system(app);
    }

    fn finish(&self, app: &mut App) {
        if !add_surface_system(app) {
            info!(
                "SoftBodySurfacePlugin: the app has no Assets<Mesh> (Bevy's MeshPlugin, part of \
                 DefaultPlugins), so no surface follows its body"
            );
        }
    }
}

/// Adds the surfaces' system once, where the app has mesh assets; whether it is added.
fn add_surface_system(app: &mut App) -> bool {
    if app.world().contains_resource::<SurfacesFollow>() {
        return true;
    }
    if !app.world().contains_resource::<Assets<Mesh>>() {
        return false;
    }
    app.insert_resource(SurfacesFollow)
        .add_systems(PostUpdate, deform_surfaces.in_set(SoftBodySurfaceSystems));
    true
}

fn deform_surfaces(
    fixed: Res<Time<Fixed>>,
    timing: Option<Res<SoftBodyTiming>>,
    bodies: Query<&SoftBody>,
    mut surfaces: Query<(
        Entity,
        &mut SoftBodySurface,
        &Mesh3d,
        &Transform,
        Option<&mut Aabb>,
    )>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut commands: Commands,
    mut errors: MessageWriter<SoftBodyError>,
) {
    let interpolate = timing.is_none_or(|t| t.fixed);
    let alpha = if interpolate {
        fixed.overstep_fraction().clamp(0.0, 1.0)
    } else {
        1.0
    };
    for (entity, mut surface, mesh3d, transform, aabb) in &mut surfaces {
        let surface = &mut *surface;
        if surface.failed {
            continue;
        }
        let mut fail = |surface: &mut SoftBodySurface, reason: String| {
            surface.failed = true;
            let error = SoftBodyError {
                body: surface.body,
                kind: SoftBodyErrorKind::Surface {
                    surface: entity,
                    reason,
                },
            };
            error!("{error}");
            errors.write(error);
        };
        let Ok(body) = bodies.get(surface.body) else {
            fail(surface, "its soft body entity has no SoftBody".into());
            continue;
        };
        if !body.is_placed() {
            continue;
        }
        if surface.binding.is_none() {
            match bind(surface, body, &meshes, &mesh3d.0) {
                Ok(true) => {}
                // Not loaded yet: try again next frame.
                Ok(false) => continue,
                Err(reason) => {
                    fail(surface, reason);
                    continue;
                }
            }
        }
        let Some(mut mesh) = meshes.get_mut(&mesh3d.0) else {
            continue;
        };
        let vertex_count = match mesh.try_attribute(Mesh::ATTRIBUTE_POSITION) {
            Ok(values) => values.len(),
            Err(_) => 0,
        };
        if vertex_count != surface.points.len() {
            // The asset was replaced by one with another vertex count: bind again.
            surface.binding = None;
            continue;
        }
        let state = body.state();
        if surface
            .drawn_on
            .as_ref()
            .is_some_and(|m| !Arc::ptr_eq(m, state.mesh()))
        {
            cut_torn_triangles(surface, state.mesh(), &mut mesh);
        }
        let SoftBodySurface {
            binding,
            particles,
            points,
            ..
        } = surface;
        let binding = binding.as_ref().expect("bound above");
        for ((p, &a), &b) in particles
            .iter_mut()
            .zip(state.previous_positions())
            .zip(state.positions())
        {
            *p = a.lerp(b, alpha);
        }
        binding.deform(state.mesh(), particles, points);
        // Vertices are written in the entity's own frame (a top-level entity: its transform is
        // its world transform).
        let to_local = transform.compute_affine().inverse();
        let Some(bounds) = write_vertices(&mut mesh, points, to_local) else {
            continue;
        };
        match aabb {
            Some(mut aabb) => *aabb = bounds,
            None => {
                commands.entity(entity).insert(bounds);
            }
        }
    }
}

/// Binds `surface` to its body's tets once its mesh `handle` is loaded: `Ok(false)` while it
/// is not, the reason if it cannot be bound.
fn bind(
    surface: &mut SoftBodySurface,
    body: &SoftBody,
    meshes: &Assets<Mesh>,
    handle: &Handle<Mesh>,
) -> Result<bool, String> {
    let Some(mesh) = meshes.get(handle) else {
        return Ok(false);
    };
    let Ok(VertexAttributeValues::Float32x3(vertices)) =
        mesh.try_attribute(Mesh::ATTRIBUTE_POSITION)
    else {
        return Err("the mesh has no Float32x3 vertex positions in the main world".into());
    };
    let state = body.state();
    let scale = body.rest_scale();
    let rest: Vec<Vec3> = vertices.iter().map(|&v| Vec3::from(v) * scale).collect();
    let binding = SurfaceBinding::new(state.mesh(), &rest).map_err(|e| e.to_string())?;
    surface.points = vec![Vec3::ZERO; binding.len()];
    surface.particles = vec![Vec3::ZERO; state.positions().len()];
    surface.binding = Some(binding);
    surface.bound_to = Some(state.mesh().clone());
    surface.drawn_on = Some(state.mesh().clone());
    Ok(true)
}

/// After the body tore (its tet mesh is another than the one last drawn on): the particles'
/// buffer follows their number, the triangles of `mesh` across the cut are taken out, and the
/// faces the tear opened are drawn: three new vertices each, bound to the corners of their tet
/// (with the mesh's other attributes copied from its first vertex).
fn cut_torn_triangles(surface: &mut SoftBodySurface, now: &Arc<TetMesh>, mesh: &mut Mesh) {
    surface.particles.resize(now.vertex_count(), Vec3::ZERO);
    let previous = surface.drawn_on.replace(now.clone());
    let (Some(binding), Some(bound), Some(previous)) =
        (&surface.binding, &surface.bound_to, previous)
    else {
        return;
    };
    let pieces = crate::core::pieces(now);
    let mut kept: Vec<u32> = match mesh.indices() {
        Some(indices) => {
            let all: Vec<u32> = indices.iter().map(|i| i as u32).collect();
            (all.chunks_exact(3))
                .filter(|t| !binding.spans_cut(bound, now, &pieces, [t[0], t[1], t[2]]))
                .flatten()
                .copied()
                .collect()
        }
        None => return,
    };
    // The faces opened since the last frame: those of the torn mesh against the last drawn.
    let opened = crate::core::cut_faces(&previous, now);
    let Some(binding) = surface.binding.as_mut() else {
        return;
    };
    let drawn = binding.len();
    let mut added = 0u32;
    for &(tet, corners) in &opened {
        let already = (drawn as u32..drawn as u32 + added)
            .step_by(3)
            .any(|_| false);
        let _ = already;
        for k in corners {
            let mut weights = [0.0; 4];
            weights[k] = 1.0;
            binding.push(tet, weights);
        }
        kept.extend([0, 1, 2].map(|j| drawn as u32 + added + j));
        added += 3;
    }
    let total = binding.len();
    surface.points.resize(total, Vec3::ZERO);
    for (_, values) in mesh.attributes_mut() {
        extend_attribute(values, total);
    }
    mesh.insert_indices(bevy::mesh::Indices::U32(kept));
}

/// Grows a vertex attribute to `len` values, copying its first (positions and normals are
/// written each frame anyway).
fn extend_attribute(values: &mut VertexAttributeValues, len: usize) {
    macro_rules! grow {
        ($($variant:ident),*) => {
            match values {
                $(VertexAttributeValues::$variant(v) => {
                    let first = v.first().copied().unwrap_or_default();
                    v.resize(len, first);
                })*
                _ => {}
            }
        };
    }
    grow!(
        Float32, Float32x2, Float32x3, Float32x4, Uint32, Uint32x2, Uint32x3, Uint32x4
    );
}

/// Writes `points` (in the world) as `mesh`'s vertices in the frame `to_local`, with fresh
/// normals; their bounds, or `None` for a mesh without Float32x3 positions.
fn write_vertices(
    mesh: &mut Mesh,
    points: &[Vec3],
    to_local: bevy::math::Affine3A,
) -> Option<Aabb> {
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    let Ok(VertexAttributeValues::Float32x3(vertices)) =
        mesh.try_attribute_mut(Mesh::ATTRIBUTE_POSITION)
    else {
        return None;
    };
    for (v, &p) in vertices.iter_mut().zip(points.iter()) {
        let local = to_local.transform_point3(p);
        lo = lo.min(local);
        hi = hi.max(local);
        *v = local.to_array();
    }
    if mesh.try_indices().is_ok() {
        let _ = mesh.try_compute_smooth_normals();
    } else {
        let _ = mesh.try_compute_flat_normals();
    }
    Some(Aabb::from_min_max(lo, hi))
}
