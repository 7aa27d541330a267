//! The components and resources a game spawns and reads.

mod body;
mod diagnostics;
mod kinematics;
mod world;

pub use body::SoftBody;
pub use diagnostics::{SoftBodyError, SoftBodyErrorKind, SoftBodyStats};
pub use kinematics::{DrivenParticles, PinnedParticles};
pub use world::{RigidSphere, SoftBodyGravity, StaticCollider};
