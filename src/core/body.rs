//! The state of one soft body: particles, springs, contacts and the caches of the volume
//! passes, with what reads and sets them from outside a step (kinematic particles, metrics,
//! momentum). The stages of a step are in their own files; their order is in `substep.rs`.

use std::sync::Arc;

use glam::Vec3;

use super::boundary::{Boundary, SoftContactSettings};
use super::chunks::in_particle_chunks;
use super::colliders::{ColliderInstance, CollisionFilter, RigidContacts, RigidSphereState};
use super::contacts::{ContactBody, ContactState};
use super::external::{BodyForces, BodyPoint, body_point, point_position};
use super::forces::Springs;
use super::geometry::signed_volume;
use super::impulses::{PassBody, StepCounters, VolumePassScratch};
use super::material::{MaterialError, SoftBodyMaterial};
use super::parallel::{Parallel, SharedSlice};
use super::ray_cast::{SurfaceHit, ray_cast};
use super::runaway::{BodyMotion, Runaway, RunawayLimits, put_back_at_rest};
use super::sleep::{Sleep, SleepSettings};
use super::snapshot::{
    MeshFingerprint, SNAPSHOT_VERSION, SnapshotError, StateSnapshot, TornTopology,
};
use super::step_scratch::StepScratch;
use super::tearing::{Tear, TearSettings};
use super::tet_mesh::TetMesh;

/// A particle index that does not exist in the body's mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("particle {index} does not exist: the body has {count} particles")]
pub struct ParticleIndexError {
    /// The index given.
    pub index: usize,
    /// How many particles there are.
    pub count: usize,
}

/// Volume measurements of a body in its current state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VolumeMetrics {
    /// Sum of the signed tet volumes.
    pub volume: f64,
    /// Sum of the rest volumes.
    pub rest_volume: f64,
    /// `100 * (volume - rest_volume) / rest_volume`: signed, the paper's Figure 2.
    pub volume_error_pct: f64,
    /// Mean over tets of `100 * |V - V0| / V0`: a body crushed in one place and inflated in
    /// another has a small total error but a large mean.
    pub mean_abs_tet_error_pct: f64,
    /// Tets with negative volume.
    pub inverted_tets: usize,
}

/// One soft body: the particles of its tet mesh, the springs on its edges, its material and
/// what it touches; a step's working memory is apart, in `StepScratch`.
#[derive(Clone, Debug)]
pub struct SoftBodyState {
    pub(crate) mesh: Arc<TetMesh>,
    pub(crate) positions: Vec<Vec3>,
    /// Positions at the start of the last step: to interpolate between steps when rendering,
    /// and the strain plasticity flows from (`forces.rs`).
    pub(crate) previous_positions: Vec<Vec3>,
    /// Whether `previous_positions` is where the last step started (not a placement's reset).
    pub(crate) motion_tracked: bool,
    /// Whether the body touched another soft body (or itself) since the step began.
    pub(crate) met_soft_bodies: bool,
    /// For a body that touched another soft body in the last step, how far its particles
    /// moved in it relative to the body's mean motion (the largest distance): what the
    /// substeps count as its deformation (see `substep.rs`, `substep_speed`). `None` otherwise.
    pub(crate) last_relative_motion: Option<f32>,
    pub(crate) velocities: Vec<Vec3>,
    pub(crate) masses: Vec<f32>,
    /// Inverse masses as used in this step: zero for kinematic particles.
    pub(crate) inv_masses: Vec<f32>,
    /// This step's kinematic particles and where they must be at its end.
    pub(crate) kinematic: Vec<(u32, Vec3)>,
    /// The springs on the mesh's edges (`forces.rs`).
    pub(crate) springs: Springs,
    pub(crate) material: SoftBodyMaterial,
    /// What it touches and where friction holds it (`contacts.rs`).
    pub(crate) contacts: ContactState,
    pub(crate) counters: StepCounters,
    /// This step's gravity, kept by `apply_forces` for the substeps.
    pub(crate) gravity: Vec3,
    /// When the body counts as running away (see `runaway.rs`).
    pub(crate) runaway_limits: RunawayLimits,
    /// The runaway caught in this step, if any.
    pub(crate) runaway: Option<Runaway>,
    /// The centre of mass at the end of the last step that was not a runaway.
    pub(crate) sane_centre: Option<Vec3>,
    /// The diagonal of the rest shape's bounding box.
    pub(crate) rest_extent: f32,
    /// The shortest rest edge, for the substeps a fast body needs.
    pub(crate) shortest_edge: f32,
    /// Whether the body sleeps, and for how long it has been quiet (see `sleep.rs`).
    pub(crate) sleep: Sleep,
    /// The colliders (static and rigid bodies') this body meets.
    pub(crate) collision_filter: CollisionFilter,
    /// The rigid bodies of another engine it may touch this step (`contacts.rs`).
    pub(crate) rigid: RigidContacts,
    /// How it meets other soft bodies (`soft_contacts.rs`); `None`: it passes through them.
    pub(crate) soft_contacts: Option<SoftContactSettings>,
    /// Its boundary triangles and particles, for soft contacts.
    pub(crate) boundary: Boundary,
    /// What the volume passes keep between passes and steps (`impulses/`).
    pub(crate) volume_passes: VolumePassScratch,
    /// When it tears (`tearing.rs`); `None`: never.
    pub(crate) tearing: Option<TearSettings>,
    /// Where it tore in the last step.
    pub(crate) tears: Vec<Tear>,
    /// The faces cracked but not yet come apart, as pairs of tets, and the time since the
    /// body last came apart (`tearing.rs`).
    pub(crate) cracks: Vec<[u32; 2]>,
    pub(crate) since_tear: f32,
    /// After a tear: each particle's particle in the mesh the body was made with.
    pub(crate) origin: Vec<u32>,
    /// A step's working memory and the caches that only save it work (see [`StepScratch`]).
    pub(crate) scratch: StepScratch,
}

impl SoftBodyState {
    /// A body at the mesh's rest positions, at rest.
    pub fn new(mesh: Arc<TetMesh>, material: SoftBodyMaterial) -> Result<Self, MaterialError> {
        material.validate()?;
        let n = mesh.vertex_count();
        let springs = Springs::new(&mesh, material.elasticity);
        let shortest_edge = springs.rest0.iter().copied().fold(f32::INFINITY, f32::min);
        let mut body = SoftBodyState {
            positions: mesh.positions().to_vec(),
            previous_positions: mesh.positions().to_vec(),
            motion_tracked: false,
            met_soft_bodies: false,
            last_relative_motion: None,
            velocities: vec![Vec3::ZERO; n],
            masses: vec![0.0; n],
            inv_masses: vec![0.0; n],
            // Room for every particle up front, so that no later step allocates (tests/no_alloc.rs).
            kinematic: Vec::with_capacity(n),
            springs,
            material,
            contacts: ContactState::new(n),
            counters: StepCounters::default(),
            gravity: Vec3::ZERO,
            sleep: Sleep::new(Some(Default::default()), n),
            collision_filter: CollisionFilter::ALL,
            rigid: RigidContacts::default(),
            soft_contacts: Some(SoftContactSettings::for_edge(shortest_edge)),
            boundary: Boundary::of(&mesh),
            runaway_limits: Default::default(),
            runaway: None,
            sane_centre: None,
            shortest_edge,
            rest_extent: {
                let (lo, hi) = mesh.bounds();
                (hi - lo).length()
            },
            volume_passes: VolumePassScratch::for_mesh(&mesh),
            tearing: None,
            tears: Vec::new(),
            cracks: Vec::new(),
            since_tear: f32::INFINITY,
            origin: Vec::new(),
            scratch: StepScratch::for_mesh(&mesh, material.method),
            mesh,
        };
        body.update_masses();
        Ok(body)
    }

    fn update_masses(&mut self) {
        self.masses.iter_mut().for_each(|m| *m = 0.0);
        for (tet, &v0) in self.mesh.tets().iter().zip(self.mesh.rest_volumes()) {
            for &i in tet {
                self.masses[i as usize] += 0.25 * self.material.density * v0;
            }
        }
        for (w, &m) in self.inv_masses.iter_mut().zip(&self.masses) {
            *w = 1.0 / m;
        }
        for &(i, _) in &self.kinematic {
            self.inv_masses[i as usize] = 0.0;
        }
    }

    /// The tet mesh.
    pub fn mesh(&self) -> &Arc<TetMesh> {
        &self.mesh
    }

    /// Particle positions.
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// The particles that touched a collider or sphere in the last step, with the outward
    /// normal of what they touched.
    pub fn contacts(&self) -> impl Iterator<Item = (usize, Vec3)> + '_ {
        let c = &self.contacts;
        c.touching
            .iter()
            .map(|&i| (i as usize, c.normals[i as usize]))
    }

    /// Particle positions at the start of the last step (equal to [`Self::positions`] before
    /// the first). A renderer drawing between two steps interpolates from these.
    pub fn previous_positions(&self) -> &[Vec3] {
        &self.previous_positions
    }

    /// Particle velocities.
    pub fn velocities(&self) -> &[Vec3] {
        &self.velocities
    }

    /// Particle velocities, to push a body around (it wakes if asleep).
    pub fn velocities_mut(&mut self) -> &mut [Vec3] {
        self.sleep.wake();
        &mut self.velocities
    }

    /// Particle masses.
    pub fn masses(&self) -> &[f32] {
        &self.masses
    }

    /// Moves every particle by `offset` (the rest state is unchanged).
    pub fn translate(&mut self, offset: Vec3) {
        self.sleep.wake();
        self.positions.iter_mut().for_each(|p| *p += offset);
        self.previous_positions.copy_from_slice(&self.positions);
        self.motion_tracked = false;
    }

    /// Maps every particle through `f` (for placing a body); the rest state is unchanged, so a
    /// map that is not a rigid motion is a deformation the body will undo.
    pub fn map_positions(&mut self, f: impl Fn(Vec3) -> Vec3) {
        self.sleep.wake();
        self.scratch.volume_corrected = false;
        self.positions.iter_mut().for_each(|p| *p = f(*p));
        self.previous_positions.copy_from_slice(&self.positions);
        self.motion_tracked = false;
    }

    /// The material.
    pub fn material(&self) -> &SoftBodyMaterial {
        &self.material
    }

    /// Replaces the material (live edits); masses follow a change of density.
    pub fn set_material(&mut self, material: SoftBodyMaterial) -> Result<(), MaterialError> {
        material.validate()?;
        if material != self.material {
            self.sleep.wake();
        }
        let density_changed = material.density != self.material.density;
        let elasticity_changed = material.elasticity != self.material.elasticity;
        self.scratch.volume_corrected &= material.method == self.material.method;
        self.material = material;
        if density_changed {
            self.update_masses();
        }
        if elasticity_changed {
            self.springs
                .update_elasticity(&self.mesh, self.material.elasticity);
        }
        Ok(())
    }

    /// What the volume passes did in the last step.
    pub fn counters(&self) -> StepCounters {
        self.counters
    }

    /// Current rest length of each spring (one per mesh edge), after plasticity.
    pub fn spring_rest_lengths(&self) -> &[f32] {
        &self.springs.rest
    }

    /// This step's kinematic particles and their targets.
    pub(crate) fn kinematic_targets(&self) -> impl Iterator<Item = (usize, Vec3)> + '_ {
        self.kinematic.iter().map(|&(i, x)| (i as usize, x))
    }

    /// Frees every particle made kinematic for the last step (the plugin does so before each
    /// step; a game stepping the core does so before setting the next step's targets).
    pub fn clear_kinematic(&mut self) {
        for &(i, _) in &self.kinematic {
            self.inv_masses[i as usize] = 1.0 / self.masses[i as usize];
        }
        self.kinematic.clear();
    }

    /// Makes particle `index` kinematic for the coming step: it ignores forces, impulses and
    /// contacts and moves to `target` by the end of the step. Pinned particles use their own
    /// position as target; driven particles a moving one.
    pub fn set_kinematic(&mut self, index: usize, target: Vec3) -> Result<(), ParticleIndexError> {
        if index >= self.positions.len() {
            return Err(ParticleIndexError {
                index,
                count: self.positions.len(),
            });
        }
        self.inv_masses[index] = 0.0;
        self.kinematic.push((index as u32, target));
        Ok(())
    }

    /// Starts a step: clears the counters and last step's contacts.
    pub(crate) fn begin_step(&mut self) {
        self.counters = StepCounters::default();
        self.runaway = None;
        let met = std::mem::take(&mut self.met_soft_bodies);
        self.last_relative_motion = (self.motion_tracked && met).then(|| self.relative_motion());
        self.motion_tracked = true;
        self.previous_positions.copy_from_slice(&self.positions);
        self.volume_passes.begin_step();
        self.contacts.begin_step();
    }

    /// The largest distance a particle moved since `previous_positions`, relative to the
    /// body's mean (mass-weighted) motion.
    fn relative_motion(&self) -> f32 {
        let (mut moved, mut mass) = (Vec3::ZERO, 0.0);
        for ((&x, &x0), &m) in self
            .positions
            .iter()
            .zip(&self.previous_positions)
            .zip(&self.masses)
        {
            moved += m * (x - x0);
            mass += m;
        }
        if mass <= 0.0 {
            return 0.0;
        }
        let mean = moved / mass;
        let farthest = self
            .positions
            .iter()
            .zip(&self.previous_positions)
            .map(|(&x, &x0)| (x - x0 - mean).length_squared())
            .fold(0.0f32, f32::max);
        farthest.sqrt()
    }

    /// `x += h v` for the paper's springs (their substep's advance). A particle whose new
    /// position would not be finite (only an unstable explicit baseline gets there) keeps its
    /// position, loses its velocity and is counted, so that one bad particle cannot turn the
    /// body, the spheres it touches and the game's transforms into NaN.
    ///
    /// The particles are run in chunks by `parallel` (each particle on its own: the same
    /// result on any number of threads).
    pub(crate) fn integrate_positions(&mut self, h: f32, parallel: &dyn Parallel) {
        let n = self.positions.len();
        // SAFETY: each job reads and writes only its own chunk's particles.
        let positions = unsafe { SharedSlice::new(&mut self.positions) };
        let velocities = unsafe { SharedSlice::new(&mut self.velocities) };
        in_particle_chunks(
            parallel,
            &mut self.scratch.chunk_findings,
            n,
            |found, particles| {
                for i in particles {
                    let next = positions.get(i) + h * velocities.get(i);
                    if next.is_finite() {
                        positions.set(i, next);
                    } else {
                        // The particle stays where it is (still finite) and stops.
                        velocities.set(i, Vec3::ZERO);
                        found.non_finite += 1;
                    }
                }
            },
        );
        for found in &mut self.scratch.chunk_findings {
            self.counters.non_finite_velocities += std::mem::take(&mut found.non_finite);
        }
    }

    /// Predicted position of particle `i` (valid after `refresh_predicted`, during the volume
    /// passes): where it ends the step with its current velocity.
    #[cfg(test)]
    #[inline]
    pub(crate) fn predicted_position(&self, i: u32) -> Vec3 {
        self.scratch.predicted[i as usize].vec3()
    }

    /// Sets every predicted position to `x + h v`.
    #[cfg(test)]
    pub(crate) fn refresh_predicted(&mut self, h: f32) {
        self.pass_body().refresh_predicted(h);
    }

    /// When the body tears (see [`TearSettings`]); `None` (the default): never.
    pub fn set_tearing(&mut self, settings: Option<TearSettings>) {
        self.tearing = settings;
    }

    /// When the body tears.
    pub fn tearing(&self) -> Option<TearSettings> {
        self.tearing
    }

    /// Where the body tore in its last step (see `tearing.rs`).
    pub fn tears(&self) -> &[Tear] {
        &self.tears
    }

    /// The particles lent for the game's impulses, forces and grabs (see [`BodyForces`]).
    pub fn forces(&mut self) -> BodyForces<'_> {
        BodyForces {
            mesh: &self.mesh,
            positions: &self.positions,
            velocities: &mut self.velocities,
            masses: &self.masses,
            inv_masses: &self.inv_masses,
            sleep: &mut self.sleep,
        }
    }

    /// The point of the body at `world` now: in the tet that contains it, or, for a point
    /// outside the body, the nearest point of the tet it is least outside of. `None` for a
    /// body without a tet of any volume.
    pub fn body_point(&self, world: Vec3) -> Option<BodyPoint> {
        body_point(&self.mesh, &self.positions, world)
    }

    /// Where `point` of the body is now.
    pub fn point_position(&self, point: BodyPoint) -> Vec3 {
        point_position(&self.mesh, &self.positions, point)
    }

    /// The first point of the body's deformed surface (its boundary triangles where the
    /// particles are now) that a ray from `origin` along `direction` meets within
    /// `max_distance` (in units of `direction`'s length), from either side.
    pub fn ray_cast(&self, origin: Vec3, direction: Vec3, max_distance: f32) -> Option<SurfaceHit> {
        let triangles = &self.boundary.triangles;
        ray_cast(&self.positions, triangles, origin, direction, max_distance)
    }

    /// The body's state now, to restore later into this body or another of the same mesh
    /// (see `snapshot.rs`).
    pub fn snapshot(&self) -> StateSnapshot {
        let anchors = self.contacts.anchors.iter();
        StateSnapshot {
            version: SNAPSHOT_VERSION,
            mesh: MeshFingerprint::of(&self.mesh),
            material: self.material,
            positions: self.positions.clone(),
            previous_positions: self.previous_positions.clone(),
            velocities: self.velocities.clone(),
            motion_tracked: self.motion_tracked,
            met_soft_bodies: self.met_soft_bodies,
            sane_centre: self.sane_centre,
            spring_rest: self.springs.rest.clone(),
            plastic_strain: self.springs.plastic_strain.clone(),
            friction_anchors: anchors.map(|a| a.is_finite().then_some(*a)).collect(),
            static_contact: self.contacts.static_contact.clone(),
            static_normals: self.contacts.static_normals.clone(),
            soft_anchors: self.scratch.soft_anchors.clone(),
            rigid_anchors: self.contacts.rigid_anchors.clone(),
            soft_pass: self.scratch.soft_pass,
            sleep: self.sleep.snapshot(),
            cracks: self.cracks.clone(),
            since_tear: self.since_tear.is_finite().then_some(self.since_tear),
            torn: (!self.origin.is_empty()).then(|| TornTopology {
                tets: self.mesh.tets().to_vec(),
                origin: self.origin.clone(),
            }),
        }
    }

    /// Puts the body back in the state `snapshot` holds. It must be of this body's mesh and of
    /// this build's [`SNAPSHOT_VERSION`]; anything that does not fit is an error and leaves
    /// the body as it was. The settings a game gives (sleep threshold, contacts, collision
    /// filter, runaway limits) stay this body's.
    pub fn restore(&mut self, snapshot: &StateSnapshot) -> Result<(), SnapshotError> {
        let s = snapshot;
        if let Some(torn) = &s.torn
            && MeshFingerprint::of(&self.mesh) != s.mesh
        {
            let mesh = torn.mesh(&self.mesh, s.mesh)?;
            let mut body = SoftBodyState::new(Arc::new(mesh), s.material)?;
            body.take_settings(self);
            body.origin.clone_from(&torn.origin);
            body.restore(s)?;
            *self = body;
            return Ok(());
        }
        s.check(&self.mesh, self.springs.rest.len())?;
        self.set_material(s.material)?;
        self.scratch.volume_corrected = false;
        self.positions.copy_from_slice(&s.positions);
        self.previous_positions
            .copy_from_slice(&s.previous_positions);
        self.velocities.copy_from_slice(&s.velocities);
        (self.motion_tracked, self.met_soft_bodies) = (s.motion_tracked, s.met_soft_bodies);
        self.sane_centre = s.sane_centre;
        self.springs.rest.copy_from_slice(&s.spring_rest);
        self.springs
            .plastic_strain
            .copy_from_slice(&s.plastic_strain);
        for (a, s) in self.contacts.anchors.iter_mut().zip(&s.friction_anchors) {
            *a = s.unwrap_or(Vec3::NAN);
        }
        self.contacts
            .static_contact
            .copy_from_slice(&s.static_contact);
        self.contacts
            .static_normals
            .copy_from_slice(&s.static_normals);
        self.scratch.soft_anchors.copy_from_slice(&s.soft_anchors);
        self.contacts.restore_rigid_anchors(&s.rigid_anchors);
        self.scratch.soft_pass = s.soft_pass;
        self.sleep.restore(&s.sleep);
        self.cracks.clone_from(&s.cracks);
        self.since_tear = s.since_tear.unwrap_or(f32::INFINITY);
        self.clear_kinematic();
        self.runaway = None;
        Ok(())
    }

    /// The body as its contact passes see it (see [`ContactBody`]).
    pub(crate) fn contact_body(&mut self) -> ContactBody<'_> {
        ContactBody {
            positions: &self.positions,
            velocities: &mut self.velocities,
            inv_masses: &self.inv_masses,
            friction: self.material.friction,
            filter: self.collision_filter,
            contacts: &mut self.contacts,
            chunk_findings: &mut self.scratch.chunk_findings,
        }
    }

    /// Pushes predicted positions out of static colliders (see
    /// [`ContactBody::resolve_static`]). Returns the number of contacts.
    pub(crate) fn resolve_static_contacts(
        &mut self,
        h: f32,
        colliders: &[ColliderInstance],
        parallel: &dyn Parallel,
    ) -> u32 {
        self.contact_body().resolve_static(h, colliders, parallel)
    }

    /// Pushes predicted positions out of the rigid spheres, pushing them back (see
    /// [`ContactBody::resolve_spheres`]). Returns the number of contacts.
    pub(crate) fn resolve_sphere_contacts(
        &mut self,
        h: f32,
        spheres: &mut [RigidSphereState],
    ) -> u32 {
        self.contact_body().resolve_spheres(h, spheres)
    }

    /// Pushes predicted positions out of the rigid bodies of another engine where they are
    /// `elapsed` seconds into the step plus `h` (see [`ContactBody::resolve_rigid`]).
    pub(crate) fn resolve_rigid_contacts(&mut self, h: f32, elapsed: f32) -> u32 {
        let mut rigid = std::mem::take(&mut self.rigid);
        let contacts = self.contact_body().resolve_rigid(h, elapsed, &mut rigid);
        self.rigid = rigid;
        contacts
    }

    /// The rigid bodies this body meets in its next step (see [`RigidContacts`]): set them
    /// before the step, read their changed velocities after it.
    pub(crate) fn rigid_contacts_mut(&mut self) -> &mut RigidContacts {
        &mut self.rigid
    }

    /// The rigid bodies this body meets, with the velocities its contacts left them.
    pub(crate) fn rigid_contacts(&self) -> &RigidContacts {
        &self.rigid
    }

    /// The body as its volume passes see it (see [`PassBody`]).
    pub(crate) fn pass_body(&mut self) -> PassBody<'_> {
        PassBody {
            mesh: &self.mesh,
            method: self.material.method,
            positions: &self.positions,
            inv_masses: &self.inv_masses,
            velocities: &mut self.velocities,
            contact_normals: &self.contacts.normals,
            contact_second: &self.contacts.second,
            contact_kept: &self.contacts.kept,
            contact_sphere: &self.contacts.sphere,
            touching: &self.contacts.touching,
            counters: &mut self.counters,
            predicted: &mut self.scratch.predicted,
            per_particle: &mut self.scratch.per_particle,
            soft_removed: &mut self.scratch.soft_removed,
            block_done: &self.scratch.block_done,
            passes: &mut self.volume_passes,
        }
    }

    /// Volume error, mean per-tet error and inverted tets of the current positions. The plugin
    /// measures every body every frame (`SoftBodyStats`), outside the step.
    pub fn volume_metrics(&self) -> VolumeMetrics {
        let mut volume = 0.0f64;
        let mut abs_err = 0.0f64;
        let mut inverted_tets = 0;
        for (tet, &v0) in self.mesh.tets().iter().zip(self.mesh.rest_volumes()) {
            let v = signed_volume(&tet.map(|i| self.positions[i as usize]));
            volume += v as f64;
            abs_err += ((v - v0) / v0).abs() as f64;
            inverted_tets += (v < 0.0) as usize;
        }
        let rest_volume = self.mesh.total_rest_volume();
        VolumeMetrics {
            volume,
            rest_volume,
            volume_error_pct: 100.0 * (volume - rest_volume) / rest_volume,
            mean_abs_tet_error_pct: 100.0 * abs_err / self.mesh.tet_count() as f64,
            inverted_tets,
        }
    }

    /// Total mass.
    pub fn total_mass(&self) -> f32 {
        self.masses.iter().sum()
    }

    /// Centre of mass of the particles.
    pub fn centre_of_mass(&self) -> Vec3 {
        let m: f32 = self.total_mass();
        self.positions
            .iter()
            .zip(&self.masses)
            .map(|(&p, &mi)| p * mi)
            .sum::<Vec3>()
            / m
    }

    /// Linear momentum of the particles.
    pub fn linear_momentum(&self) -> Vec3 {
        self.velocities
            .iter()
            .zip(&self.masses)
            .map(|(&v, &m)| v * m)
            .sum()
    }

    /// When the body falls asleep; `None` if it never does.
    pub fn sleep_settings(&self) -> Option<SleepSettings> {
        self.sleep.settings
    }

    /// Sets when the body falls asleep (`None`: never; it wakes if asleep). Bodies stepped in
    /// substeps sleep by default; the paper's explicit springs never do.
    pub fn set_sleep_settings(&mut self, settings: Option<SleepSettings>) {
        self.sleep.settings = settings;
        self.sleep.wake();
    }

    /// The bounds of where the particles are and where they would be after `h` at their
    /// velocities; `None` for a body whose positions are not finite.
    pub(crate) fn swept_bounds(&self, h: f32) -> Option<parry3d::bounding_volume::Aabb> {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for (&x, &v) in self.positions.iter().zip(&self.velocities) {
            let end = x + h * v;
            lo = lo.min(x).min(end);
            hi = hi.max(x).max(end);
        }
        (lo.is_finite() && hi.is_finite()).then(|| parry3d::bounding_volume::Aabb::new(lo, hi))
    }

    /// How this body meets other soft bodies (`None`: it passes through them).
    pub fn soft_contact_settings(&self) -> Option<SoftContactSettings> {
        self.soft_contacts
    }

    /// Sets how this body meets other soft bodies (`None`: it passes through them).
    pub fn set_soft_contact_settings(&mut self, settings: Option<SoftContactSettings>) {
        self.soft_contacts = settings;
    }

    /// The body's boundary triangles and particles.
    pub fn boundary(&self) -> &Boundary {
        &self.boundary
    }

    /// Which colliders this body meets (all by default).
    pub fn collision_filter(&self) -> CollisionFilter {
        self.collision_filter
    }

    /// Sets which colliders this body meets.
    pub fn set_collision_filter(&mut self, filter: CollisionFilter) {
        self.collision_filter = filter;
    }

    /// Whether the body is asleep: at rest, not stepped until something disturbs it.
    pub fn is_sleeping(&self) -> bool {
        self.sleep.asleep
    }

    /// Wakes the body if it sleeps, and restarts the time it must be quiet to fall asleep.
    pub fn wake_up(&mut self) {
        self.sleep.wake();
    }

    /// At the start of a substepped step, for a sleeping body: wakes it if the step disturbs
    /// it (see [`Sleep::stays_asleep`]). Returns whether it still sleeps (the step then leaves
    /// it alone: kinematic particles stay where they are, nothing moves).
    pub(crate) fn stays_asleep(
        &mut self,
        h: f32,
        spheres: &[RigidSphereState],
        colliders: &[ColliderInstance],
    ) -> bool {
        if !self.sleep.asleep {
            return false;
        }
        let reach = self.sleep.speed_or_zero() * h;
        // A rigid body of another engine that moves or can be pushed wakes it, as a sphere does.
        let moved_kinematic = self.rigid.any_moving()
            || self
                .kinematic_targets()
                .any(|(i, target)| (target - self.positions[i]).length() > reach);
        let still = self
            .sleep
            .stays_asleep(h, moved_kinematic, self.gravity, spheres, colliders);
        if still {
            self.velocities.fill(Vec3::ZERO);
        }
        still
    }

    /// At the end of a substepped step of `h`: counts the body's quiet time and puts it to
    /// sleep once it is long enough (see [`Sleep::update`]).
    pub(crate) fn update_sleep(
        &mut self,
        h: f32,
        spheres: &[RigidSphereState],
        colliders: &[ColliderInstance],
    ) {
        if self.rigid.any_moving() {
            self.sleep.wake();
            return;
        }
        let fell_asleep = self.sleep.update(
            h,
            &self.positions,
            self.rest_extent,
            self.gravity,
            spheres,
            colliders,
        );
        if fell_asleep {
            self.velocities.fill(Vec3::ZERO);
        }
    }

    /// The limits past which a body is caught running away.
    pub fn runaway_limits(&self) -> RunawayLimits {
        self.runaway_limits
    }

    /// Sets the limits past which a body is caught running away.
    pub fn set_runaway_limits(&mut self, limits: RunawayLimits) {
        self.runaway_limits = limits;
    }

    /// The runaway caught in the last step, if any.
    pub fn runaway(&self) -> Option<Runaway> {
        self.runaway
    }

    /// Checks the body after its positions moved (the end of a step): past the limits, it is
    /// put back in its rest shape (translated so that its centre of mass is at the last sane
    /// one, at rest), and the step records a [`Runaway`]; otherwise this centre becomes the
    /// last sane one.
    pub(crate) fn catch_runaway(&mut self) {
        let motion = BodyMotion::measure(&self.positions, &self.velocities, &self.masses);
        if self.runaway_limits.allow(&motion, self.rest_extent) {
            self.sane_centre = Some(motion.centre);
            return;
        }
        let reset_to = put_back_at_rest(
            self.mesh.positions(),
            &self.masses,
            self.sane_centre,
            &mut self.positions,
        );
        self.previous_positions.copy_from_slice(&self.positions);
        self.motion_tracked = false;
        self.velocities.fill(Vec3::ZERO);
        self.runaway = Some(Runaway {
            speed: motion.speed,
            extent: motion.extent,
            rest_extent: self.rest_extent,
            reset_to,
        });
    }
}

#[cfg(test)]
mod tests {
    use crate::core::Serial;
    use crate::core::material::Elasticity;
    use std::sync::Arc;

    use glam::Vec3;

    use super::*;
    use crate::core::material::VolumeMethod;

    fn single_tet(damping: f32) -> SoftBodyState {
        let mesh = TetMesh::new(
            vec![Vec3::X, Vec3::Y, Vec3::Z, Vec3::ZERO],
            vec![[0, 1, 2, 3]],
        )
        .unwrap();
        let material = SoftBodyMaterial {
            elasticity: Elasticity::Springs {
                distance_stiffness: 0.0,
                damping,
            },
            method: VolumeMethod::Baseline {
                volume_stiffness: 0.0,
            },
            ..SoftBodyMaterial::default()
        };
        SoftBodyState::new(Arc::new(mesh), material).unwrap()
    }

    #[test]
    fn a_non_finite_velocity_does_not_reach_the_positions() {
        let mut body = single_tet(1.0);
        body.velocities_mut()[1] = Vec3::new(f32::NAN, 0.0, 0.0);
        body.velocities_mut()[2] = Vec3::splat(f32::MAX);
        body.step_free(0.01, Vec3::new(0.0, -9.81, 0.0));
        assert!(body.positions().iter().all(|p| p.is_finite()));
        assert!(body.velocities().iter().all(|v| v.is_finite()));
        assert!(body.counters().non_finite_velocities >= 1);
        assert!(body.volume_metrics().volume.is_finite());
    }

    #[test]
    fn spring_damping_is_stable_for_any_value_and_conserves_momentum() {
        for damping in [0.5, 50.0, 5e6] {
            let mut body = single_tet(damping);
            body.velocities_mut()[0] = Vec3::new(3.0, -1.0, 0.5);
            body.velocities_mut()[3] = Vec3::new(-1.0, 0.0, 2.0);
            let momentum = body.linear_momentum();
            let mut last_energy = f32::INFINITY;
            for _ in 0..50 {
                body.apply_forces(0.01, Vec3::ZERO, &Serial);
                let energy: f32 = body
                    .velocities()
                    .iter()
                    .zip(body.masses())
                    .map(|(v, m)| 0.5 * m * v.length_squared())
                    .sum();
                // Damping only ever removes kinetic energy, whatever its size.
                assert!(
                    energy <= last_energy * (1.0 + 1e-5),
                    "damping {damping}: {last_energy} -> {energy}"
                );
                last_energy = energy;
                assert!(
                    (body.linear_momentum() - momentum).length()
                        < 1e-4 * momentum.length().max(1.0)
                );
            }
            // With a damper far stiffer than the masses (c h w >> 1), the relative motion along
            // the edges dies out; positions do not move here, so the edges keep their directions.
            if damping >= 1e6 {
                let v = body.velocities();
                for &[i, j] in body.mesh().edges() {
                    let (i, j) = (i as usize, j as usize);
                    let dir = (body.positions()[j] - body.positions()[i]).normalize();
                    assert!(
                        (v[j] - v[i]).dot(dir).abs() < 1e-2,
                        "damping {damping}: edge {i}-{j} still moving"
                    );
                }
            }
        }
    }
}
