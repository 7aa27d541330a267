//! The components and resources a game spawns and reads.

mod body;
mod diagnostics;
mod external;
mod kinematics;
pub(crate) mod settings;
mod world;

pub use body::{SoftBody, SoftBodySnapshot};
pub use diagnostics::{SoftBodyError, SoftBodyErrorKind, SoftBodyStats};
pub use external::{PointForce, SoftBodyForces, SoftBodyGrab, SoftBodyRadialImpulse, SoftBodyTorn};
pub use kinematics::{DrivenParticles, PinnedParticles};
pub use settings::{
    SoftBodyContacts, SoftBodyContactsDisabled, SoftBodyRunawayLimits, SoftBodySleepThreshold,
    SoftBodySleepingDisabled, SoftBodyTearing,
};
pub use world::{RigidSphere, SoftBodyCutter, SoftBodyGravity, StaticCollider};
