//! A step's working memory, kept in the body so that a step allocates nothing.

use glam::Vec3;

use super::chunks::ChunkFindings;
use super::clusters::ClusterVolumes;
use super::deviatoric::{ShapeBundle, shape_bundles};
use super::inversion::TurnScratch;
use super::lanes::Point4;
use super::material::VolumeMethod;
use super::parallel::BlockFlags;
use super::soft_records::{SoftAnchor, SoftReaction, SoftSupport};
use super::substep_plan::{SubstepClock, SubstepPlan};
use super::tet_mesh::TetMesh;

/// A step's working memory, and what a step keeps from the last only to save work (clamp
/// bounds, the guess of which rings need correcting, the shape model's bundles): none of it is
/// the body's physical state; what it carries between steps decides how much work a step does,
/// not what it computes (the tests hold every shortcut to the plain passes). Kept in the body
/// so that a step allocates nothing.
#[derive(Clone, Debug)]
pub(crate) struct StepScratch {
    /// Per-particle scratch: forces in `apply_forces`, impulse directions in the volume
    /// passes. Kept zero between uses so that the passes never clear the whole array.
    pub(crate) per_particle: Vec<Vec3>,
    /// Predicted positions `x + h v` during the volume passes, kept in step with every velocity
    /// change there (`apply_velocity_change`), so the passes read one array, not two.
    /// Four numbers each, so that four are gathered into SIMD lanes with a load each.
    pub(crate) predicted: Vec<Point4>,
    /// One per block and phase: whether its job in the running pass is done.
    pub(crate) block_done: BlockFlags,
    /// Sphere positions saved during a substep's contacts (reused, so steps do not allocate).
    pub(crate) sphere_positions: Vec<Vec3>,
    /// One per chunk of particles: what each job of the contacts and the integration found.
    pub(crate) chunk_findings: Vec<ChunkFindings>,
    /// Velocities before a substep's volume impulses (see `substep.rs`).
    pub(crate) substep_velocities: Vec<Vec3>,
    /// How far each particle moved in a substep's shape solve, from its start (`predicted`);
    /// see `SoftBodyState::substep_shape`.
    pub(crate) shape_moves: Vec<Vec3>,
    /// What of XPBD's volume projection in a substep the velocities do not take
    /// (`xpbd::hold_back_volume_moves`).
    pub(crate) volume_held_back: Vec<Vec3>,
    /// Whether this step's substeps hold any back (the body's volume had drifted at the step's
    /// start; `xpbd::VOLUME_DRIFT`).
    pub(crate) volume_drifted: bool,
    /// The tets in SIMD bundles, for the tet shape model (see `deviatoric.rs`).
    pub(crate) shape_bundles: Vec<ShapeBundle>,
    /// This step's substeps, from their plan to the step's finish (`substep.rs`).
    pub(crate) substep_plan: Option<SubstepPlan>,
    /// The time spent in each stage of the substeps, when the plugin times them.
    pub(crate) substep_clock: SubstepClock,
    /// The particles the last soft-contact pass touched and their normals (`soft_contacts.rs`).
    pub(crate) soft_touched: Vec<(u32, Vec3)>,
    /// This substep's soft contacts of this body's particles (`soft_contacts.rs`).
    pub(crate) soft_supports: Vec<SoftSupport>,
    /// What this body's volume impulses handed to other bodies this substep.
    pub(crate) soft_reactions: Vec<SoftReaction>,
    /// Per particle, where static friction holds it on another body (`soft_contacts.rs`).
    pub(crate) soft_anchors: Vec<SoftAnchor>,
    /// The number of substep soft-contact passes so far: which anchors are current.
    pub(crate) soft_pass: u32,
    /// Per particle, the velocity the volume impulses' pushes into another soft body lost to
    /// `constrain_direction` in this substep: what is handed to that body.
    pub(crate) soft_removed: Vec<Vec3>,
    /// The soft contacts of this body's particles since the count was last taken.
    pub(crate) soft_count: u32,
    /// Whether the positions are where the last step's cluster correction left them (nothing
    /// outside a step moved them since): the body's volume is then its rest volume, and the
    /// next step need not measure it for `volume_drifted`.
    pub(crate) volume_corrected: bool,
    /// The tets the sweeps that turn tets back look at after their first (`inversion.rs`).
    pub(crate) turns: TurnScratch,
    /// The clusters of XPBD's cluster volume correction (`clusters.rs`): made with the body
    /// for its material's method, or at the first step of another that uses them.
    pub(crate) clusters: ClusterVolumes,
}

impl StepScratch {
    /// The working memory of a body of `mesh` whose volume is kept by `method`.
    pub(crate) fn for_mesh(mesh: &TetMesh, method: VolumeMethod) -> Self {
        let n = mesh.vertex_count();
        StepScratch {
            per_particle: vec![Vec3::ZERO; n],
            predicted: vec![Point4::default(); n],
            block_done: BlockFlags::new(2 * mesh.blocks().count()),
            sphere_positions: Vec::new(),
            chunk_findings: ChunkFindings::for_particles(n),
            substep_plan: None,
            substep_clock: SubstepClock::default(),
            soft_touched: Vec::new(),
            soft_supports: Vec::new(),
            soft_reactions: Vec::new(),
            soft_anchors: vec![SoftAnchor::NONE; n],
            soft_pass: 1,
            soft_removed: vec![Vec3::ZERO; n],
            soft_count: 0,
            volume_corrected: false,
            turns: TurnScratch::default(),
            clusters: match method {
                VolumeMethod::Xpbd(s) if s.clusters > 0 => ClusterVolumes::new(mesh, s.clusters),
                _ => ClusterVolumes::default(),
            },
            substep_velocities: vec![Vec3::ZERO; n],
            shape_moves: vec![Vec3::ZERO; n],
            volume_held_back: vec![Vec3::ZERO; n],
            volume_drifted: false,
            shape_bundles: shape_bundles(mesh),
        }
    }
}
