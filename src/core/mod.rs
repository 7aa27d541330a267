//! The simulation core: plain Rust on glam, no ECS types. Data lives in flat arrays indexed by
//! particle, tet and edge; a step allocates nothing.

pub mod blocks;
pub mod body;
pub(crate) mod chunks;
pub mod colliders;
pub mod contacts;
pub mod deviatoric;
pub mod embedding;
pub mod forces;
pub mod geometry;
pub mod grid;
pub mod impulses;
pub mod lanes;
pub mod material;
pub mod obj;
pub mod parallel;
pub mod reference;
pub mod roots;
pub mod runaway;
pub mod sleep;
pub mod step;
pub mod surface_mesh;
pub mod tet_mesh;
pub mod tetgen;
pub mod tetrahedralize;
pub mod winding;
pub mod xpbd;

pub use body::{ParticleIndexError, SoftBodyState, VolumeMetrics};
pub use colliders::{ColliderInstance, RigidSphereState};
pub use embedding::{EmbeddingError, SurfaceBinding};
pub use grid::{GridError, box_grid, sdf_grid};
pub use impulses::{ImpulseOutcome, StepCounters};
pub use material::{
    ElasticSettings, Elasticity, ImpulseSettings, MaterialError, Plasticity, SoftBodyMaterial,
    VolumeMethod, XpbdSettings,
};
pub use obj::{ObjError, ObjErrorKind, parse_obj, write_obj};
pub use parallel::{Parallel, Serial};
pub use runaway::{Runaway, RunawayLimits};
pub use sleep::SleepSettings;
pub use step::Stage;
pub use surface_mesh::{TriangleSurface, subdivided_box, surface_nets, torus, uv_sphere};
pub use tet_mesh::{Blocks, TetMesh, TetMeshError};
pub use tetgen::{TetGenError, TetGenFile, parse_tetgen, write_tetgen};
pub use tetrahedralize::{
    Resolution, Tetrahedralization, TetrahedralizeError, face_components, tetrahedralize,
};
pub use winding::WindingNumber;
