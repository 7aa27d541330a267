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
#![warn(missing_docs)]

pub mod components;
pub mod core;
#[cfg(feature = "render")]
pub mod debug;
pub mod game_scenes;
#[cfg(feature = "egui")]
pub mod inspector;
#[cfg(feature = "render")]
pub mod loading;
pub mod plugin;
pub mod scenes;
#[cfg(feature = "render")]
pub mod surface;

pub use components::{
    DrivenParticles, PinnedParticles, RigidSphere, SoftBody, SoftBodyError, SoftBodyErrorKind,
    SoftBodyGravity, SoftBodyStats, StaticCollider,
};
#[cfg(feature = "render")]
#[allow(deprecated)]
pub use loading::SoftBodyAssetSet;
#[cfg(feature = "render")]
pub use loading::{
    ObjMeshLoader, SoftBodyAssetPlugin, SoftBodyAssetSystems, SoftBodyFromAsset, SoftBodySource,
    TetGenLoader, TetMeshAsset,
};
#[allow(deprecated)]
pub use plugin::SoftBodySet;
pub use plugin::{
    SoftBodyPlugin, SoftBodyPlugins, SoftBodyStageTimes, SoftBodyStepTime, SoftBodySystems,
    SoftBodyThreads, SoftBodyTiming,
};
#[cfg(feature = "render")]
#[allow(deprecated)]
pub use surface::SoftBodySurfaceSet;
#[cfg(feature = "render")]
pub use surface::{SoftBodySurface, SoftBodySurfacePlugin, SoftBodySurfaceSystems, surface_mesh};

/// Everything a game usually needs.
pub mod prelude {
    pub use crate::components::{
        DrivenParticles, PinnedParticles, RigidSphere, SoftBody, SoftBodyError, SoftBodyErrorKind,
        SoftBodyGravity, SoftBodyStats, StaticCollider,
    };
    pub use crate::core::{
        ElasticSettings, Elasticity, ImpulseSettings, Plasticity, SoftBodyMaterial, TetMesh,
        VolumeMethod,
    };
    #[cfg(feature = "render")]
    pub use crate::loading::{
        SoftBodyAssetPlugin, SoftBodyFromAsset, SoftBodySource, TetMeshAsset,
    };
    pub use crate::plugin::{SoftBodyPlugin, SoftBodyPlugins, SoftBodySystems, SoftBodyThreads};
    #[cfg(feature = "render")]
    pub use crate::surface::{SoftBodySurface, SoftBodySurfacePlugin};
}
