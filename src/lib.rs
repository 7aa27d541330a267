//! Almost incompressible soft bodies for Bevy, after "Simulating Almost Incompressible
//! Deformable Objects" (Diziol, Bayer, Bender 2009).
//!
//! Add [`SoftBodyPlugins`] (or just [`SoftBodyPlugin`]), spawn a [`SoftBody`] from a [`TetMesh`](core::TetMesh) and a
//! [`SoftBodyMaterial`](core::SoftBodyMaterial), add a ground ([`StaticCollider::ground`]) and
//! perhaps a few [`RigidSphere`]s. The simulation core in [`core`] has no ECS types and can be
//! used on its own.
//!
//! ```
//! use bevy_soft_body::core::{SoftBodyMaterial, SoftBodyState, VolumeMethod, box_grid};
//! use glam::{UVec3, Vec3};
//!
//! // A 4x4x4-cell cube, squeezed from two sides, keeps its volume with the paper's method.
//! let mesh = box_grid(UVec3::splat(4), Vec3::splat(0.1), Vec3::ZERO).unwrap();
//! let material = SoftBodyMaterial::JELLY.with_method(VolumeMethod::PAPER_IMPULSES);
//! let mut body = SoftBodyState::new(mesh.into(), material).unwrap();
//! for (p, v) in body.positions().to_vec().iter().zip(body.velocities_mut()) {
//!     v.x = if p.x < 0.2 { 1.0 } else { -1.0 };
//! }
//! for _ in 0..20 {
//!     body.step_free(0.01, Vec3::ZERO);
//! }
//! assert!(body.volume_metrics().volume_error_pct.abs() < 1.0);
//! ```
#![deny(missing_docs)]

/// The README's code, compiled (and, where it can run headless, run) by `cargo test`.
#[cfg(all(
    doctest,
    feature = "render",
    feature = "avian",
    feature = "serialize",
    feature = "picking"
))]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

#[cfg(feature = "avian")]
pub mod avian;
pub mod components;
pub mod core;
#[cfg(feature = "render")]
pub mod debug;
#[cfg(any(test, feature = "scenes"))]
pub mod game_scenes;
#[cfg(feature = "egui")]
pub mod inspector;
#[cfg(feature = "render")]
pub mod loading;
#[cfg(feature = "picking")]
pub mod picking;
pub mod plugin;
#[cfg(any(test, feature = "scenes"))]
pub mod scenes;
#[cfg(feature = "render")]
pub mod surface;

pub use components::{
    DrivenParticles, PinnedParticles, PointForce, RigidSphere, SoftBody, SoftBodyContacts,
    SoftBodyContactsDisabled, SoftBodyCutter, SoftBodyError, SoftBodyErrorKind, SoftBodyForces,
    SoftBodyGrab, SoftBodyGravity, SoftBodyRadialImpulse, SoftBodyRunawayLimits,
    SoftBodySleepThreshold, SoftBodySleepingDisabled, SoftBodySnapshot, SoftBodyStats,
    SoftBodyTearing, SoftBodyTorn, StaticCollider,
};
#[cfg(feature = "render")]
pub use loading::{
    ObjMeshLoader, SoftBodyAssetPlugin, SoftBodyAssetSystems, SoftBodyFromAsset, SoftBodySource,
    TetGenLoader, TetMeshAsset,
};
pub use plugin::{
    SoftBodyPlugin, SoftBodyStageTimes, SoftBodyStepTime, SoftBodySystems, SoftBodyThreads,
    SoftBodyTiming,
};
#[cfg(feature = "render")]
pub use surface::{SoftBodySurface, SoftBodySurfacePlugin, SoftBodySurfaceSystems, surface_mesh};

/// The crate's plugins a game adds in one go: [`SoftBodyPlugin`] (the simulation), with
/// feature `avian` [`SoftBodyAvianPlugin`](crate::avian::SoftBodyAvianPlugin) (soft bodies
/// among avian's rigid bodies), and with feature `render` [`SoftBodySurfacePlugin`] (render meshes that
/// follow the bodies) and [`SoftBodyAssetPlugin`] (bodies from
/// meshes and files). The last two need Bevy's asset and mesh plugins, as in `DefaultPlugins`; in
/// an app without them (`MinimalPlugins`, a headless server) they add nothing and log why, so the
/// group fits any app. Each part can be replaced or left out, as in any plugin group:
///
/// ```
/// use bevy::prelude::*;
/// use bevy_soft_body::prelude::*;
///
/// // The simulation in `FixedPostUpdate`, at the game's fixed rate.
/// let plugins = SoftBodyPlugins.set(SoftBodyPlugin::new(FixedPostUpdate));
/// // A headless server has no meshes to draw: leaving the render parts out says so.
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

impl bevy::app::PluginGroup for SoftBodyPlugins {
    fn build(self) -> bevy::app::PluginGroupBuilder {
        let group = bevy::app::PluginGroupBuilder::start::<Self>().add(SoftBodyPlugin::default());
        #[cfg(feature = "avian")]
        let group = group.add(avian::SoftBodyAvianPlugin);
        #[cfg(feature = "render")]
        let group = group
            .add(SoftBodySurfacePlugin)
            .add(SoftBodyAssetPlugin::default());
        #[cfg(feature = "picking")]
        let group = group.add(picking::SoftBodyPickingPlugin);
        group
    }
}

/// Everything a game usually needs.
pub mod prelude {
    pub use crate::SoftBodyPlugins;
    pub use crate::components::{
        DrivenParticles, PinnedParticles, PointForce, RigidSphere, SoftBody, SoftBodyContacts,
        SoftBodyContactsDisabled, SoftBodyCutter, SoftBodyError, SoftBodyErrorKind, SoftBodyForces,
        SoftBodyGrab, SoftBodyGravity, SoftBodyRadialImpulse, SoftBodyRunawayLimits,
        SoftBodySleepThreshold, SoftBodySleepingDisabled, SoftBodySnapshot, SoftBodyStats,
        SoftBodyTearing, SoftBodyTorn, StaticCollider,
    };
    pub use crate::core::{
        ElasticSettings, Elasticity, ImpulseSettings, Plasticity, SnapshotError, SoftBodyMaterial,
        TetMesh, VolumeMethod,
    };
    #[cfg(feature = "render")]
    pub use crate::loading::{
        SoftBodyAssetPlugin, SoftBodyFromAsset, SoftBodySource, TetMeshAsset,
    };
    #[cfg(feature = "picking")]
    pub use crate::picking::{SoftBodyDraggable, SoftBodyHit, SoftBodyPickingPlugin};
    pub use crate::plugin::{SoftBodyPlugin, SoftBodySystems, SoftBodyThreads};
    #[cfg(feature = "render")]
    pub use crate::surface::{SoftBodySurface, SoftBodySurfacePlugin};
}
