//! Almost incompressible soft bodies for Bevy, after "Simulating Almost Incompressible
//! Deformable Objects" (Diziol, Bayer, Bender 2009).
//!
//! Add [`SoftBodyPlugin`], spawn a [`SoftBody`] from a [`TetMesh`](core::TetMesh) and a
//! [`SoftBodyMaterial`](core::SoftBodyMaterial), add a ground ([`StaticCollider::ground`]) and
//! perhaps a few [`RigidSphere`]s. The simulation core in [`core`] has no ECS types and can be
//! used on its own.
#![warn(missing_docs)]

pub mod components;
pub mod core;
pub mod plugin;
pub mod scenes;

pub use components::{
    DrivenParticles, PinnedParticles, RigidSphere, SoftBody, SoftBodyGravity, SoftBodyStats,
    StaticCollider,
};
pub use plugin::{SoftBodyPlugin, SoftBodySet};

/// Everything a game usually needs.
pub mod prelude {
    pub use crate::components::{
        DrivenParticles, PinnedParticles, RigidSphere, SoftBody, SoftBodyGravity, SoftBodyStats,
        StaticCollider,
    };
    pub use crate::core::{ImpulseSettings, Plasticity, SoftBodyMaterial, TetMesh, VolumeMethod};
    pub use crate::plugin::{SoftBodyPlugin, SoftBodySet};
}
