//! The simulation core: plain Rust on glam, no ECS types. Data lives in flat arrays indexed by
//! particle, tet and edge; a step allocates nothing.

pub(crate) mod blocks;
pub(crate) mod body;
pub(crate) mod boundary;
pub(crate) mod chunks;
pub(crate) mod clusters;
pub(crate) mod colliders;
pub(crate) mod contacts;
pub(crate) mod damping;
pub(crate) mod deviatoric;
pub(crate) mod embedding;
pub(crate) mod external;
pub(crate) mod forces;
pub(crate) mod geometry;
pub(crate) mod grid;
pub(crate) mod impulses;
pub(crate) mod inversion;
pub(crate) mod lanes;
pub(crate) mod material;
pub(crate) mod mesh_check;
pub(crate) mod obj;
pub(crate) mod parallel;
pub(crate) mod ray_cast;
#[cfg(test)]
pub(crate) mod reference;
pub(crate) mod roots;
pub(crate) mod runaway;
pub(crate) mod sleep;
pub(crate) mod snapshot;
pub(crate) mod soft_broad_phase;
pub(crate) mod soft_contacts;
pub(crate) mod soft_lockstep;
pub(crate) mod soft_records;
pub(crate) mod step_scratch;
pub(crate) mod substep;
pub(crate) mod substep_plan;
pub(crate) mod surface_mesh;
pub(crate) mod tearing;
pub(crate) mod tet_mesh;
pub(crate) mod tetgen;
pub(crate) mod tetrahedralize;
pub(crate) mod winding;
pub(crate) mod xpbd;

pub use body::{ParticleIndexError, SoftBodyState, VolumeMetrics};
pub use boundary::{Boundary, SoftContactSettings};
pub use colliders::{
    ColliderInstance, CollisionFilter, RigidAttachment, RigidBodyMotion, RigidCollider,
    RigidContacts, RigidSphereState,
};
pub use embedding::{EmbeddingError, SurfaceBinding};
pub use external::{BodyForces, BodyPoint};
pub use grid::{GridError, box_grid, sdf_grid};
pub use impulses::{ImpulseOutcome, StepCounters};
pub use material::{
    ElasticSettings, Elasticity, ImpulseSettings, MaterialError, Plasticity, SoftBodyMaterial,
    VolumeMethod, XpbdSettings,
};
pub use mesh_check::{LISTED_DEFECTS, MeshDefects};
pub use obj::{ObjError, ObjErrorKind, parse_obj, write_obj};
pub use parallel::{Parallel, Serial};
pub use ray_cast::SurfaceHit;
pub use runaway::{Runaway, RunawayLimits};
pub use sleep::SleepSettings;
pub use snapshot::{MeshFingerprint, SNAPSHOT_VERSION, SnapshotError, StateSnapshot};
pub(crate) use soft_broad_phase::PairRounds;
pub use soft_lockstep::step_bodies;
pub(crate) use soft_lockstep::{LockstepBody, final_contacts_together, substeps_together};
pub use substep_plan::{Stage, SubstepStage};
pub use surface_mesh::{TriangleSurface, subdivided_box, surface_nets, torus, uv_sphere};
pub use tearing::{Tear, TearSettings, cut_faces, pieces};
pub use tet_mesh::{Blocks, ParticleRegion, TetMesh, TetMeshError};
pub use tetgen::{TetGenError, TetGenFile, parse_tetgen, write_tetgen};
pub use tetrahedralize::{
    Resolution, Tetrahedralization, TetrahedralizeError, face_components, tetrahedralize,
};
pub use winding::WindingNumber;
