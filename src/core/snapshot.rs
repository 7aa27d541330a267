//! Save and restore: a [`StateSnapshot`] holds everything of a soft body that carries from one
//! step to the next (particles, velocities, the plastic rest lengths, the friction anchors,
//! sleep, the material), so that restoring it and stepping gives, bit for bit, the steps the
//! body would have taken had it not been stopped: a save file, a rollback buffer, a replay.
//!
//! What is not in it, and why:
//! - the tet mesh: a snapshot names its mesh by a [`MeshFingerprint`] and is restored into a
//!   body made of the same mesh (a save file holds the level's assets apart, as a game's does);
//!   a torn body's snapshot holds how its mesh was torn, and is restored into a body made of
//!   the mesh it was made with;
//! - the caches of the volume passes and the step's working memory (`StepScratch`,
//!   `VolumePassScratch`): they decide how much work a step does, never what it computes;
//! - what the game sets every step: kinematic particles, the rigid bodies it touches, and the
//!   settings the plugin takes from components (sleep threshold, contacts, collision filter,
//!   runaway limits), which a game saves with its components;
//! - the last step's contacts (normals, which sphere): a step forgets them when it begins.
//!
//! With the feature `serialize` the snapshot is serde data in any format. It holds no NaN
//! (unset values are `None`), so text formats (JSON, RON) can carry it. A snapshot of another
//! mesh, of another version or whose arrays do not fit is a [`SnapshotError`], and the body is
//! left as it was.

use glam::Vec3;

use super::contacts::RigidAnchor;
use super::material::{MaterialError, SoftBodyMaterial};
use super::soft_records::SoftAnchor;
use super::tet_mesh::TetMesh;

/// The version of [`StateSnapshot`]'s layout; a snapshot of another is refused.
pub const SNAPSHOT_VERSION: u32 = 3;

/// What a snapshot says of its body's tet mesh: its size and a hash of its tets and rest
/// positions (FNV-1a over their bits: the same on every machine and Rust version, which the
/// standard library's hasher does not promise).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub struct MeshFingerprint {
    /// Particles.
    pub vertices: u32,
    /// Tets.
    pub tets: u32,
    /// FNV-1a of the tets' indices and the rest positions' bits.
    pub hash: u64,
}

impl MeshFingerprint {
    /// The fingerprint of `mesh`.
    pub fn of(mesh: &TetMesh) -> Self {
        const PRIME: u64 = 0x0000_0100_0000_01b3;
        let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
        let mut add = |word: u32| {
            for byte in word.to_le_bytes() {
                hash = (hash ^ byte as u64).wrapping_mul(PRIME);
            }
        };
        for tet in mesh.tets() {
            tet.iter().for_each(|&i| add(i));
        }
        for p in mesh.positions() {
            p.to_array().iter().for_each(|c| add(c.to_bits()));
        }
        MeshFingerprint {
            vertices: mesh.vertex_count() as u32,
            tets: mesh.tets().len() as u32,
            hash,
        }
    }
}

/// A soft body's state between two steps; see the module's documentation.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub struct StateSnapshot {
    /// [`SNAPSHOT_VERSION`] when it was taken.
    pub version: u32,
    /// The mesh it was taken of.
    pub mesh: MeshFingerprint,
    pub(crate) material: SoftBodyMaterial,
    pub(crate) positions: Vec<Vec3>,
    pub(crate) previous_positions: Vec<Vec3>,
    pub(crate) velocities: Vec<Vec3>,
    pub(crate) motion_tracked: bool,
    pub(crate) met_soft_bodies: bool,
    pub(crate) sane_centre: Option<Vec3>,
    /// Per edge: the rest length and plastic strain (plasticity's state).
    pub(crate) spring_rest: Vec<f32>,
    pub(crate) plastic_strain: Vec<f32>,
    /// Per particle: where static friction holds it on a static collider.
    pub(crate) friction_anchors: Vec<Option<Vec3>>,
    /// Per particle: the last contact pass's depth and friction in a static collider.
    pub(crate) static_contact: Vec<[f32; 2]>,
    /// Per particle: the outward normal of the static collider it touched in that pass.
    pub(crate) static_normals: Vec<Vec3>,
    /// Per particle: where static friction holds it on another soft body.
    pub(crate) soft_anchors: Vec<SoftAnchor>,
    /// Per particle: where static friction holds it on a rigid body's collider (the collider
    /// named by its index among those the game gives the step).
    pub(crate) rigid_anchors: Vec<RigidAnchor>,
    pub(crate) soft_pass: u32,
    pub(crate) sleep: SleepSnapshot,
    /// The faces cracked but not yet apart, and the time since the body last came apart
    /// (`None`: never).
    pub(crate) cracks: Vec<[u32; 2]>,
    pub(crate) since_tear: Option<f32>,
    /// For a body that has torn: its torn mesh, as its tets and each particle's particle in
    /// the mesh it was made with, so that a body made anew of that mesh takes it back.
    pub(crate) torn: Option<TornTopology>,
}

/// A torn body's mesh in a snapshot (see [`StateSnapshot`]).
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub(crate) struct TornTopology {
    pub(crate) tets: Vec<[u32; 4]>,
    pub(crate) origin: Vec<u32>,
}

impl TornTopology {
    /// The torn mesh, rebuilt from `made_with` (the mesh the body was made with); an error if
    /// it does not fit it or is not the mesh the snapshot names.
    pub(crate) fn mesh(
        &self,
        made_with: &TetMesh,
        named: MeshFingerprint,
    ) -> Result<TetMesh, SnapshotError> {
        let other = || SnapshotError::OtherMesh {
            found: named,
            expected: MeshFingerprint::of(made_with),
        };
        let rest = made_with.positions();
        if self.origin.iter().any(|&o| o as usize >= rest.len()) {
            return Err(other());
        }
        let positions = self.origin.iter().map(|&o| rest[o as usize]).collect();
        // Tets that do not make a mesh on these rest positions, or another mesh than the one
        // named: the body was made of another mesh (or the file is damaged).
        let mesh = TetMesh::new(positions, self.tets.clone()).map_err(|_| other())?;
        if MeshFingerprint::of(&mesh) != named {
            return Err(other());
        }
        Ok(mesh)
    }
}

/// A body's sleep in a snapshot (`sleep.rs`); its settings are the game's.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub(crate) struct SleepSnapshot {
    pub(crate) asleep: bool,
    pub(crate) quiet_for: f32,
    /// Where the particles stood when the quiet time began; empty while it has not begun.
    pub(crate) still_at: Vec<Vec3>,
    /// While asleep: its bounds (lowest and highest corner) and the gravity it fell asleep in.
    pub(crate) bounds: Option<[Vec3; 2]>,
    pub(crate) gravity: Vec3,
}

/// Why a snapshot could not be restored; the body is left as it was.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SnapshotError {
    /// Taken by another version of the crate's layout.
    #[error("snapshot version {found}, this build reads version {expected}")]
    Version {
        /// The snapshot's version.
        found: u32,
        /// [`SNAPSHOT_VERSION`].
        expected: u32,
    },
    /// Taken of another tet mesh.
    #[error(
        "snapshot of another mesh ({} particles, {} tets, hash {:016x}); this body's has {} particles, {} tets, hash {:016x}",
        found.vertices, found.tets, found.hash, expected.vertices, expected.tets, expected.hash
    )]
    OtherMesh {
        /// The snapshot's mesh.
        found: MeshFingerprint,
        /// This body's.
        expected: MeshFingerprint,
    },
    /// Its arrays or values do not fit the body (a damaged or hand-edited file).
    #[error("snapshot damaged: {0}")]
    Damaged(String),
    /// Its material is not a valid material.
    #[error("snapshot's material: {0}")]
    Material(#[from] MaterialError),
}

impl StateSnapshot {
    /// The particles' positions when it was taken.
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// The particles' velocities when it was taken.
    pub fn velocities(&self) -> &[Vec3] {
        &self.velocities
    }

    /// Everything [`SoftBodyState::restore`](super::SoftBodyState::restore) checks before it
    /// changes anything, for a body of `mesh` with `edges` springs.
    pub(crate) fn check(&self, mesh: &TetMesh, edges: usize) -> Result<(), SnapshotError> {
        if self.version != SNAPSHOT_VERSION {
            return Err(SnapshotError::Version {
                found: self.version,
                expected: SNAPSHOT_VERSION,
            });
        }
        let expected = MeshFingerprint::of(mesh);
        if self.mesh != expected {
            return Err(SnapshotError::OtherMesh {
                found: self.mesh,
                expected,
            });
        }
        self.material.validate()?;
        let damaged = |what: &str| Err(SnapshotError::Damaged(what.to_string()));
        let n = mesh.vertex_count();
        let per_particle = [
            self.positions.len(),
            self.previous_positions.len(),
            self.velocities.len(),
            self.friction_anchors.len(),
            self.static_contact.len(),
            self.static_normals.len(),
            self.soft_anchors.len(),
            self.rigid_anchors.len(),
        ];
        if per_particle.iter().any(|&len| len != n) {
            return damaged("a per-particle array has the wrong length");
        }
        if self.spring_rest.len() != edges || self.plastic_strain.len() != edges {
            return damaged("a per-edge array has the wrong length");
        }
        let finite = |v: &[Vec3]| v.iter().all(|x| x.is_finite());
        if !finite(&self.positions) || !finite(&self.previous_positions) {
            return damaged("a position is not finite");
        }
        if !finite(&self.velocities) {
            return damaged("a velocity is not finite");
        }
        if !finite(&self.static_normals) {
            return damaged("a contact normal is not finite");
        }
        if !self.spring_rest.iter().all(|l| l.is_finite() && *l >= 0.0) {
            return damaged("a spring's rest length is not a length");
        }
        let anchor_fits =
            |a: &SoftAnchor| a.partner == u32::MAX || a.corners.iter().all(|&c| c != u32::MAX);
        if !self.soft_anchors.iter().all(anchor_fits) {
            return damaged("a soft-contact anchor names no triangle");
        }
        if !self.rigid_anchors.iter().all(|a| a.local.is_finite()) {
            return damaged("a rigid-contact anchor is not finite");
        }
        let sleep = &self.sleep;
        if !(sleep.still_at.is_empty() || sleep.still_at.len() == n) {
            return damaged("the sleep's positions have the wrong length");
        }
        if sleep.asleep && sleep.bounds.is_none() {
            return damaged("asleep without bounds");
        }
        Ok(())
    }
}
