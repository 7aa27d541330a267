//! The step of a soft body, written once: the core's whole-step functions
//! ([`SoftBodyState::step_with_contacts`], `soft_lockstep::step_bodies`) and the plugin's
//! systems run these stages in this order.
//!
//! A step ([`Stage::ORDER`]) is:
//! 1. [`Stage::Forces`]: the paper's section 3 for its explicit springs (gravity, springs with
//!    dampers, the baseline's volume forces, drag change the velocities); for a physical
//!    material or XPBD, whose gravity and shape act in the substeps, only the kinematic
//!    particles are set moving. The rigid spheres get their gravity.
//! 2. [`Stage::Substeps`]: `N` substeps of [`SubstepStage::ORDER`], `N` from the body's motion
//!    for a physical material ([`SoftBodyState::plan_substeps`]), XPBD's own count, and one
//!    substep of the whole step for the paper's springs. The spheres meet the static colliders
//!    before the substeps.
//! 3. [`Stage::Plasticity`]: the plastic springs' flow (section 6), driven by the strain of
//!    the positions the step started from.
//! 4. [`Stage::Finish`]: the spheres meet the static colliders again and move; each body's
//!    sleep is updated and a body that ran away is caught (`runaway.rs`); bodies stepped
//!    together get a last soft-contact pass.
//!
//! A substep ([`SubstepStage::ORDER`]) of length `h_s` is:
//! 1. [`SubstepStage::Shape`]: gravity, the predicted positions and the shape solve (the tets'
//!    shapes of `deviatoric.rs`, the edges, or XPBD's edges and volumes). Nothing for the
//!    paper's springs, whose forces the step's first stage applied.
//! 2. [`SubstepStage::Contacts`]: the velocities the shape solve gives, then the contacts with
//!    the spheres, the rigid bodies of another engine and the static colliders (last, so that
//!    no particle is left inside the ground by a body pushing it). Bodies stepped together
//!    meet each other between the shape solve and this stage (`soft_lockstep.rs`).
//! 3. [`SubstepStage::OneRing`] (section 5): damping (drag; in the first substep, the step's
//!    deformation damping and rolling resistance of `damping.rs`), then one impulse per vertex
//!    restoring its one-ring's volume on the predicted positions `x + h_s v`.
//! 4. [`SubstepStage::PerTet`] (sections 4 and 5): one impulse per tet scaled by gamma, with
//!    the neighbour clamp.
//! 5. [`SubstepStage::Advance`]: `x += h_s v`, the volume impulses' velocity change kept as
//!    far as it adds no energy, friction for what the supports pushed back; for the paper's
//!    springs a contact pass first (undoing what the volume impulses pushed into a collider).
//!    After the last substep, tets left inside out are turned back (`inversion.rs`; with
//!    XPBD's cluster correction, in it).

use std::collections::HashMap;
use std::sync::Arc;

use glam::Vec3;

use super::body::SoftBodyState;
use super::clusters::correct_cluster_volumes;
use super::colliders::{ColliderInstance, RigidSphereState};
use super::damping::{damp_whole_body, drag};
use super::deviatoric::{project_tet_shapes, refresh_shape_bundles};
use super::forces::{ForceBody, explicit_forces};
use super::inversion::turn_inverted_tets_back;
use super::lanes::Point4;
use super::material::{Elasticity, VolumeMethod};
use super::parallel::{Parallel, Serial};
use super::soft_records::{hand_soft_pushes, take_soft_pushes};
use super::substep_plan::{
    Stage, SubstepPlan, SubstepStage, spheres_after_bodies, spheres_before_bodies,
};
use super::tearing::{crack_crossed, largest_strain, split_particles, tear_mesh};
use super::xpbd::{
    EdgeConstraints, hold_back_volume_moves, project_edges, project_volume_bundles, volume_drifted,
};
use parry3d::bounding_volume::BoundingVolume;
use parry3d::query::Ray;

/// The longest substep of a physical material under the volume impulses that touched another
/// soft body in the last step. Such a body carries others or rests on them, and its volume
/// impulses take their contacts as supports; one sweep of the impulses a substep leaves a
/// loaded body short of its volume by more the longer the substep (a pile's bottom layer lost
/// over 1 % at its motion's 5 substeps of 1/300 s; `PERFORMANCE.md`, "Soft bodies in a
/// pile").
pub(crate) const TOUCHING_MAX_SUBSTEP: f32 = 1.0 / 600.0;

impl SoftBodyState {
    /// A whole step without colliders or spheres: for tests and benchmarks of the core.
    pub fn step_free(&mut self, h: f32, gravity: Vec3) {
        self.step_with_contacts(h, gravity, &mut [], &[], &Serial);
    }

    /// A whole step of this body among `spheres` and `colliders`, exactly as the plugin runs it
    /// for one body: for using the core without Bevy, and for benchmarks of what the plugin
    /// does per body.
    ///
    /// The body's blocks are run by `parallel` (`Serial`, or the plugin's threads): the same
    /// result bit for bit on any number of threads.
    pub fn step_with_contacts(
        &mut self,
        h: f32,
        gravity: Vec3,
        spheres: &mut [RigidSphereState],
        colliders: &[ColliderInstance],
        parallel: &dyn Parallel,
    ) {
        self.begin_step();
        spheres_before_bodies(Stage::Forces, h, gravity, spheres, colliders);
        self.apply_forces(h, gravity, parallel);
        spheres_before_bodies(Stage::Substeps, h, gravity, spheres, colliders);
        self.run_substeps(h, spheres, colliders, parallel);
        self.apply_plasticity(h);
        spheres_before_bodies(Stage::Finish, h, gravity, spheres, colliders);
        self.finish_step(h, spheres, colliders);
        spheres_after_bodies(Stage::Finish, h, spheres);
    }

    /// [`Stage::Substeps`] for a body stepped alone. Returns the contacts it resolved.
    pub(crate) fn run_substeps(
        &mut self,
        h: f32,
        spheres: &mut [RigidSphereState],
        colliders: &[ColliderInstance],
        parallel: &dyn Parallel,
    ) -> u32 {
        let Some(plan) = self.plan_substeps(h, spheres, colliders, None) else {
            return 0;
        };
        let mut contacts = 0;
        for k in 0..plan.substeps {
            for stage in SubstepStage::ORDER {
                contacts += self.substep_stage(stage, &plan, k, spheres, colliders, parallel);
            }
        }
        contacts
    }

    /// [`Stage::Finish`] for this body: its sleep (for a body that ran substeps, `h` the step,
    /// `spheres` and `colliders` what may wake it), then the runaway check.
    pub(crate) fn finish_step(
        &mut self,
        h: f32,
        spheres: &[RigidSphereState],
        colliders: &[ColliderInstance],
    ) {
        if self
            .scratch
            .substep_plan
            .take()
            .is_some_and(|p| !p.explicit)
        {
            self.update_sleep(h, spheres, colliders);
        }
        self.catch_runaway();
        self.tear_where_stretched(h, colliders);
    }

    /// The settings a game gives `other` (sleep, contacts, collision filter, runaway limits,
    /// tearing), for this body built anew in its place.
    pub(crate) fn take_settings(&mut self, other: &SoftBodyState) {
        self.sleep.settings = other.sleep.settings;
        (self.soft_contacts, self.collision_filter) = (other.soft_contacts, other.collision_filter);
        (self.runaway_limits, self.tearing) = (other.runaway_limits, other.tearing);
        self.scratch.substep_clock = other.scratch.substep_clock;
    }

    /// Splits the particles that edges stretched past the material's limit pull apart
    /// (`tearing.rs`): the body is built anew on the torn mesh, every particle's state carried
    /// over from the particle it came from. Allocates only when something tears.
    pub(crate) fn tear_where_stretched(&mut self, h: f32, colliders: &[ColliderInstance]) {
        self.tears.clear();
        let Some(settings) = self.tearing else { return };
        self.since_tear += h;
        let (mesh, rest) = (&self.mesh, &self.springs.rest);
        // Colliders that cut (`SoftBodyCutter`) and reach the body crack the faces they pass
        // between; then the stretch's own cracks, and the particles the cracks part split.
        let bounds = (colliders.iter().any(|c| c.cuts))
            .then(|| self.swept_bounds(0.0))
            .flatten();
        let cut = bounds.and_then(|bounds| {
            let crosses = |a: Vec3, b: Vec3| {
                let ray = Ray::new(a, b - a);
                colliders.iter().any(|c| {
                    c.cuts
                        && c.aabb.intersects(&bounds)
                        && c.shape.intersects_ray(&c.pose, &ray, 1.0)
                })
            };
            crack_crossed(mesh, &self.positions, &mut self.cracks, &crosses)
        });
        let strain = largest_strain(mesh, &self.positions, rest);
        let stretched =
            strain.partial_cmp(&settings.max_strain) == Some(std::cmp::Ordering::Greater);
        let (cracks, new_crack) = (&mut self.cracks, self.since_tear >= settings.min_interval);
        let torn = match (stretched, cut) {
            (true, _) => {
                match tear_mesh(mesh, &self.positions, rest, cracks, settings, new_crack) {
                    Ok(None) if cut.is_some() => {
                        split_particles(mesh, &self.positions, cracks, cut.unwrap_or(Vec3::X))
                    }
                    torn => torn,
                }
            }
            (false, Some(normal)) => split_particles(mesh, &self.positions, cracks, normal),
            (false, None) => return,
        };
        let Ok(Some(torn)) = torn else { return };
        let Ok(mut body) = SoftBodyState::new(Arc::new(torn.mesh), self.material) else {
            return;
        };
        let from = |i: usize| torn.origin[i] as usize;
        for i in 0..body.positions.len() {
            body.positions[i] = self.positions[from(i)];
            body.previous_positions[i] = self.previous_positions[from(i)];
            body.velocities[i] = self.velocities[from(i)];
            body.contacts.anchors[i] = self.contacts.anchors[from(i)];
        }
        // The springs of edges that were edges before keep their plastic rest lengths.
        let key = |[a, b]: [u32; 2]| [a.min(b), a.max(b)];
        let old: HashMap<[u32; 2], usize> = (self.mesh.edges().iter().enumerate())
            .map(|(k, &e)| (key(e), k))
            .collect();
        for (k, &[a, b]) in body.mesh.edges().iter().enumerate() {
            if let Some(&was) = old.get(&key([from(a as usize) as u32, from(b as usize) as u32])) {
                body.springs.rest[k] = self.springs.rest[was];
                body.springs.plastic_strain[k] = self.springs.plastic_strain[was];
            }
        }
        body.take_settings(self);
        body.origin = if self.origin.is_empty() {
            torn.origin
        } else {
            torn.origin
                .iter()
                .map(|&o| self.origin[o as usize])
                .collect()
        };
        (body.motion_tracked, body.sane_centre) = (self.motion_tracked, self.sane_centre);
        body.met_soft_bodies = self.met_soft_bodies;
        body.rigid = std::mem::take(&mut self.rigid);
        for &(i, target) in &self.kinematic {
            let _ = body.set_kinematic(i as usize, target);
        }
        body.tears = torn.tears;
        body.cracks = std::mem::take(&mut self.cracks);
        body.since_tear = 0.0;
        *self = body;
    }

    /// Sets up this step's substeps (`substeps` of them if given, for a body in substeps,
    /// else as many as the body's motion needs) and keeps the plan for the step's finish;
    /// `None` for a body asleep through the step.
    pub(crate) fn plan_substeps(
        &mut self,
        h: f32,
        spheres: &[RigidSphereState],
        colliders: &[ColliderInstance],
        substeps: Option<u32>,
    ) -> Option<SubstepPlan> {
        self.scratch.substep_plan = None;
        if !self.material.is_substepped() {
            let plan = SubstepPlan {
                substeps: 1,
                hs: h,
                explicit: true,
                volumes: false,
                shape_damping: 0.0,
                dampers: false,
                tet_compliance: None,
            };
            self.scratch.substep_plan = Some(plan);
            return Some(plan);
        }
        if self.stays_asleep(h, spheres, colliders) {
            return None;
        }
        let substeps = match substeps {
            Some(n) => n.max(1),
            None => self.substeps_needed(h, spheres, colliders, 0.0)?,
        };
        self.counters.substeps = substeps;
        let volumes = self.material.method.is_xpbd();
        let hs = h / substeps as f32;
        // Stiffness-proportional damping in the shape projection (physical materials), or
        // dampers on the velocities (the paper's springs).
        let (shape_damping, dampers) = match self.material.elasticity {
            Elasticity::Elastic(e) => (e.damping / hs, false),
            Elasticity::Springs { .. } => (0.0, self.material.any_damping()),
        };
        // A physical material under the impulses keeps its shape per tet, unless its plastic
        // springs are the edges (see `ElasticSettings`).
        let tet_compliance = match (self.material.elasticity, self.material.plasticity) {
            (Elasticity::Elastic(e), None) if !volumes => Some(e.tet_compliance()),
            _ => None,
        };
        // The tet shape model and XPBD's volume sweep take the inverse masses from the bundles.
        if tet_compliance.is_some() || volumes {
            refresh_shape_bundles(&mut self.scratch.shape_bundles, &self.inv_masses);
        }
        // Under the cluster correction the volume drifts only when something outside the
        // steps moved the particles.
        self.scratch.volume_drifted = volumes
            && !self.scratch.volume_corrected
            && volume_drifted(&self.mesh, &self.positions);
        // The rigid bodies of another engine get their gravity per substep too, and are
        // followed along their path within the step.
        for body in &mut self.rigid.bodies {
            body.linear_velocity -= h * body.gravity;
            body.position_correction = Vec3::ZERO;
            body.rotation_correction = Vec3::ZERO;
        }
        let plan = SubstepPlan {
            substeps,
            hs,
            explicit: false,
            volumes,
            shape_damping,
            dampers,
            tet_compliance,
        };
        self.scratch.substep_plan = Some(plan);
        Some(plan)
    }

    /// The substeps this step needs, for a body that other soft bodies approach at up to
    /// `approach` (m/s; zero for a body alone); `None` for a body not solved in substeps.
    pub(crate) fn substeps_needed(
        &self,
        h: f32,
        spheres: &[RigidSphereState],
        colliders: &[ColliderInstance],
        approach: f32,
    ) -> Option<u32> {
        match (self.material.method, self.material.elasticity) {
            (VolumeMethod::Xpbd(s), _) => Some(s.substeps_for(h)),
            (VolumeMethod::Impulses(_), Elasticity::Elastic(e)) => {
                let speed = self.substep_speed(h, spheres, colliders).max(approach);
                let for_motion = e.substeps(h, speed, self.shortest_edge);
                // A body among others carries them or rests on them: see
                // `TOUCHING_MAX_SUBSTEP`.
                let among = if self.last_relative_motion.is_some() {
                    (h / TOUCHING_MAX_SUBSTEP * (1.0 - 1e-4)).ceil() as u32
                } else {
                    0
                };
                Some(for_motion.max(among))
            }
            _ => None,
        }
    }

    /// The speed that sets a physical material's substeps (see
    /// [`ElasticSettings::max_motion`](super::material::ElasticSettings::max_motion)): the
    /// fastest particle relative to the body's mean motion, or its fastest in the world when a
    /// particle would meet a collider or sphere within the step: a body falling or flying as
    /// a whole needs no substeps for that, a landing does.
    ///
    /// For a body that touched other soft bodies in the last step, only the particles that
    /// meet something count their speed in the world, and the relative speed is the
    /// velocities' or, if less, how far a particle actually moved relative to the body in that
    /// step over `h`: a particle held between bodies (in a pile) ends each substep with the
    /// velocity of the push the other body handed it, which the next substep takes back;
    /// counted as motion, it asked for the most substeps of a pile that barely moved, and the
    /// smaller substeps' pushes then asked for fewer, step after step. An impact between
    /// bodies is counted apart (`substeps_together`'s `approach`).
    fn substep_speed(
        &self,
        h: f32,
        spheres: &[RigidSphereState],
        colliders: &[ColliderInstance],
    ) -> f32 {
        let (mut momentum, mut mass) = (Vec3::ZERO, 0.0);
        for (&v, &m) in self.velocities.iter().zip(&self.masses) {
            momentum += m * v;
            mass += m;
        }
        let mean = momentum / mass;
        let (mut relative, mut absolute) = (0.0f32, 0.0f32);
        for &v in &self.velocities {
            relative = relative.max((v - mean).length_squared());
            absolute = absolute.max(v.length_squared());
        }
        let (relative, absolute) = (relative.sqrt(), absolute.sqrt());
        let meets = |x: Vec3, v: Vec3| {
            let end = x + h * v;
            colliders.iter().any(|c| c.penetration(end).is_some())
                || self.rigid.meets(end, h)
                || spheres.iter().any(|s| {
                    (end - (s.position + h * s.velocity)).length_squared()
                        < (s.radius + h * (v - s.velocity).length()).powi(2)
                })
        };
        let particles = || self.positions.iter().zip(&self.velocities);
        let Some(moved) = self.last_relative_motion else {
            let approaching = absolute > relative && particles().any(|(&x, &v)| meets(x, v));
            return if approaching { absolute } else { relative };
        };
        let mut approaching = 0.0f32;
        for (&x, &v) in particles() {
            let speed = v.length_squared();
            if speed > approaching * approaching && meets(x, v) {
                approaching = speed.sqrt();
            }
        }
        relative.min(moved / h).max(approaching)
    }

    /// Stage `stage` of substep `k` of `plan`, the body's blocks run by `parallel`. Returns the
    /// contacts it resolved.
    pub(crate) fn substep_stage(
        &mut self,
        stage: SubstepStage,
        plan: &SubstepPlan,
        k: u32,
        spheres: &mut [RigidSphereState],
        colliders: &[ColliderInstance],
        parallel: &dyn Parallel,
    ) -> u32 {
        let started = self.scratch.substep_clock.start();
        let hs = plan.hs;
        let contacts = match stage {
            SubstepStage::Shape => {
                if !plan.explicit {
                    self.substep_shape(plan);
                }
                0
            }
            SubstepStage::Contacts if plan.explicit => {
                self.resolve_contacts(hs, spheres, colliders, parallel)
            }
            SubstepStage::Contacts => {
                self.substep_velocities(plan);
                self.substep_contacts(plan, k, spheres, colliders)
            }
            SubstepStage::OneRing => {
                if !plan.explicit {
                    self.substep_damping(plan, k);
                }
                if !plan.volumes {
                    self.one_ring_impulses(hs, spheres, parallel);
                }
                0
            }
            SubstepStage::PerTet => {
                if !plan.volumes {
                    self.per_tet_impulses(hs, spheres, parallel);
                }
                0
            }
            SubstepStage::Advance if plan.explicit => {
                let contacts = self.resolve_contacts(hs, spheres, colliders, parallel);
                self.integrate_positions(hs, parallel);
                contacts
            }
            SubstepStage::Advance => {
                self.substep_advance(plan);
                if k + 1 == plan.substeps {
                    self.last_substep_corrections();
                }
                0
            }
        };
        self.scratch.substep_clock.stop(stage as usize, started);
        contacts
    }

    /// After a step's last substep: XPBD's cluster correction (`clusters.rs`, which turns
    /// tets left inside out back), or for the paper's impulses the tets left inside out turned
    /// back (`inversion.rs`).
    fn last_substep_corrections(&mut self) {
        let (x, v, w) = (&mut self.positions, &mut self.velocities, &self.inv_masses);
        let turns = &mut self.scratch.turns;
        match self.material.method {
            VolumeMethod::Xpbd(s) if s.clusters > 0 => {
                let clusters = &mut self.scratch.clusters;
                let (mesh, contacts) = (&self.mesh, &self.contacts);
                correct_cluster_volumes(clusters, s.clusters, mesh, (x, v, w), (contacts, turns));
                self.scratch.volume_corrected = true;
            }
            VolumeMethod::Impulses(_) => {
                turn_inverted_tets_back(&self.mesh, (x, v, w), turns);
            }
            _ => {}
        }
    }

    /// The particles against the spheres, the rigid bodies of another engine, then the static
    /// colliders (last, so that no particle is left inside the ground by a body pushing it):
    /// the paper's springs' contact passes, on the predicted positions `x + h v`.
    fn resolve_contacts(
        &mut self,
        h: f32,
        spheres: &mut [RigidSphereState],
        colliders: &[ColliderInstance],
        parallel: &dyn Parallel,
    ) -> u32 {
        self.resolve_sphere_contacts(h, spheres)
            + self.resolve_rigid_contacts(h, 0.0)
            + self.resolve_static_contacts(h, colliders, parallel)
    }

    /// [`SubstepStage::Shape`] in substeps: gravity, the predicted positions, the shape solve
    /// (edges, or the tets' shapes; for XPBD the tets' volumes too). The particles are left
    /// where it takes them; [`SoftBodyState::substep_velocities`] turns that into velocities.
    pub(crate) fn substep_shape(&mut self, plan: &SubstepPlan) {
        let hs = plan.hs;
        let gravity = self.gravity;
        for body in &mut self.rigid.bodies {
            body.linear_velocity += hs * body.gravity;
        }
        // Predict: `predicted` holds where each particle started the substep, `shape_moves`
        // how far it has moved since, which the shape solve moves. Kept apart from the
        // positions, so that the velocities are the moves over `h_s`, exactly: taken from the
        // positions (`(x - start) / h_s` in `f32`), every constraint's write rounded into them,
        // more the further from the origin, and a body at rest on ice crept.
        let (start, moves) = (&mut self.scratch.predicted, &mut self.scratch.shape_moves);
        for i in 0..self.positions.len() {
            if self.inv_masses[i] > 0.0 {
                self.velocities[i] += hs * gravity;
            }
            start[i] = Point4::new(self.positions[i]);
            moves[i] = hs * self.velocities[i];
        }
        match plan.tet_compliance {
            Some(compliance) => {
                let bundles = &self.scratch.shape_bundles;
                let damping = plan.shape_damping;
                project_tet_shapes(bundles, moves, start, compliance, hs * hs, damping);
            }
            None => project_edges(
                moves,
                start,
                &self.mesh,
                &self.inv_masses,
                EdgeConstraints {
                    rest: &self.springs.rest,
                    compliance: &self.springs.compliance,
                },
                hs * hs,
                plan.shape_damping,
            ),
        }
        if plan.volumes {
            let (held, drifted) = (
                &mut self.scratch.volume_held_back,
                self.scratch.volume_drifted,
            );
            if drifted {
                held.copy_from_slice(moves);
            }
            project_volume_bundles(&self.scratch.shape_bundles, moves, start);
            if drifted {
                hold_back_volume_moves(held, moves, &self.masses, &self.inv_masses);
            }
        }
        for ((x, s), m) in self
            .positions
            .iter_mut()
            .zip(start.iter())
            .zip(moves.iter())
        {
            *x = s.vec3() + *m;
        }
    }

    /// The velocities the substep's shape solve gives (its moves, and where the contacts
    /// between bodies stepped together took the particles after it, less the part of XPBD's
    /// volume projection they do not take: `hold_back_volume_moves`), with the particles back
    /// where the substep started.
    fn substep_velocities(&mut self, plan: &SubstepPlan) {
        let hs = plan.hs;
        let (start, moves) = (&self.scratch.predicted, &self.scratch.shape_moves);
        let held_back = &self.scratch.volume_held_back;
        for i in 0..self.positions.len() {
            let start = start[i].vec3();
            // Zero but where a contact between bodies moved the particle.
            let contact = self.positions[i] - (start + moves[i]);
            let held = if plan.volumes && self.scratch.volume_drifted {
                held_back[i]
            } else {
                Vec3::ZERO
            };
            let v = (moves[i] + contact - held) / hs;
            if v.is_finite() {
                self.velocities[i] = v;
            } else {
                self.velocities[i] = Vec3::ZERO;
                self.counters.non_finite_velocities += 1;
            }
            self.positions[i] = start;
        }
    }

    /// Substep `k`'s contacts with the spheres, rigid bodies and static colliders. Returns
    /// the contacts.
    fn substep_contacts(
        &mut self,
        plan: &SubstepPlan,
        k: u32,
        spheres: &mut [RigidSphereState],
        colliders: &[ColliderInstance],
    ) -> u32 {
        let hs = plan.hs;
        // Each sphere where it is at this substep's start, then back exactly where it was.
        self.scratch.sphere_positions.clear();
        for s in spheres.iter_mut() {
            self.scratch.sphere_positions.push(s.position);
            s.position += (k as f32 * hs) * s.velocity;
        }
        let mut contacts = self.resolve_sphere_contacts(hs, spheres);
        for (s, &start) in spheres.iter_mut().zip(&self.scratch.sphere_positions) {
            s.position = start;
        }
        contacts += self.resolve_rigid_contacts(hs, k as f32 * hs);
        contacts + self.resolve_static_contacts(hs, colliders, &Serial)
    }

    /// A substep's damping (the paper's spring dampers, drag; in the first substep `k`, the
    /// step's deformation damping and rolling resistance, `damping.rs`), then, before the
    /// volume impulses, the velocities they start from (for [`SoftBodyState::substep_advance`]).
    fn substep_damping(&mut self, plan: &SubstepPlan, k: u32) {
        let hs = plan.hs;
        if plan.dampers {
            self.springs.damp(
                &self.mesh,
                &self.positions,
                &self.inv_masses,
                &mut self.velocities,
                hs,
            );
        }
        drag(
            &mut self.velocities,
            &self.inv_masses,
            self.material.linear_damping,
            hs,
        );
        if k == 0 {
            let (x, v, m) = (&self.positions, &mut self.velocities, &self.masses);
            let particles = (&x[..], &mut v[..], &m[..], &self.inv_masses[..]);
            let h = hs * plan.substeps as f32;
            damp_whole_body(&self.material, self.gravity, h, particles, &self.contacts);
        }
        if !plan.volumes {
            self.scratch
                .substep_velocities
                .copy_from_slice(&self.velocities);
            self.scratch.soft_removed.fill(Vec3::ZERO);
        }
    }

    /// [`SubstepStage::Advance`] in substeps: `x += h_s v` (XPBD), or, after the paper's
    /// impulses, with their energy kept in check: the positions take the impulses' whole change
    /// `dv`, the velocities `k dv` with the largest `k` in `[0, 1]` that adds no kinetic
    /// energy. An impulse that stops a compression (it takes away the velocity that compresses
    /// the tets) keeps all of it (`k` = 1 while `sum m v.dv <= -1/2 sum m |dv|^2`); what only
    /// restores drifted volume, a tet crushed by a landing or a tet inverted, moves the
    /// particles back without launching them (PERFORMANCE.md, "The step of a physical
    /// material"). One scale for the whole body, so momentum is conserved (the impulses'
    /// `sum m dv` is zero, and so is `k` times it) but for what the static colliders pushed
    /// back, whose friction comes last (`support_friction`).
    fn substep_advance(&mut self, plan: &SubstepPlan) {
        let hs = plan.hs;
        if plan.volumes {
            for (x, v) in self.positions.iter_mut().zip(&self.velocities) {
                *x += hs * *v;
            }
            if self.scratch.volume_drifted {
                // With what of XPBD's volume projection the velocities did not take, but into
                // nothing a particle touches: the contacts, after it, would throw the particle
                // out (a body crushed on the ground, its volume put back, leapt off it).
                let held_back = &self.scratch.volume_held_back;
                let normals = &self.contacts.normals;
                for ((x, &held), &n) in self.positions.iter_mut().zip(held_back).zip(normals) {
                    *x += held - n * held.dot(n).min(0.0);
                }
            }
            return;
        }
        // `push`: what the static colliders pushed back, which gets its friction
        // (`support_friction`). Pushes into another body come out here, to be handed to it
        // (`soft_support`).
        let soft_push = take_soft_pushes(
            &mut self.scratch.soft_supports,
            &mut self.scratch.soft_removed,
            &self.masses,
        );
        let (mut along, mut squared, mut push) = (0.0f64, 0.0f64, -soft_push);
        for ((&v, &before), &m) in self
            .velocities
            .iter()
            .zip(&self.scratch.substep_velocities)
            .zip(&self.masses)
        {
            let dv = v - before;
            along += (m * before.dot(dv)) as f64;
            squared += (m * dv.length_squared()) as f64;
            push += m * dv;
        }
        let k = if squared > 0.0 {
            (-2.0 * along / squared).clamp(0.0, 1.0) as f32
        } else {
            1.0
        };
        let weight = self.contacts.static_contact_weight(&self.masses);
        for i in 0..self.velocities.len() {
            let before = self.scratch.substep_velocities[i];
            let full = self.velocities[i];
            let v = before + k * (full - before);
            let friction = self.contacts.support_friction(push, weight, i, v);
            self.positions[i] += hs * (full + friction);
            self.velocities[i] = v + friction;
        }
        hand_soft_pushes(
            &mut self.scratch.soft_supports,
            &mut self.scratch.soft_reactions,
            k,
        );
    }

    /// [`Stage::Forces`] over a step of `h` under `gravity`: the paper's explicit springs'
    /// forces (`forces.rs`); for a body in substeps, whose gravity and shape act in them, only
    /// the kinematic particles set moving to their targets. The body's blocks are run by
    /// `parallel`.
    pub(crate) fn apply_forces(&mut self, h: f32, gravity: Vec3, parallel: &dyn Parallel) {
        self.gravity = gravity;
        if !self.material.is_substepped() {
            let body = ForceBody {
                mesh: &self.mesh,
                material: &self.material,
                positions: &self.positions,
                inv_masses: &self.inv_masses,
                velocities: &mut self.velocities,
                per_particle: &mut self.scratch.per_particle,
                block_done: &self.scratch.block_done,
                springs: &mut self.springs,
            };
            explicit_forces(body, h, gravity, parallel);
        }
        for &(i, target) in &self.kinematic {
            let i = i as usize;
            self.velocities[i] = (target - self.positions[i]) / h;
        }
    }

    /// [`Stage::Plasticity`]: plastic flow of the spring rest lengths (nothing without
    /// plasticity, or asleep), driven by the strain of the positions the step started from:
    /// the strain the paper's springs' forces saw in the step (they act once, at its start),
    /// and one definition for every material whatever its substeps.
    pub(crate) fn apply_plasticity(&mut self, h: f32) {
        let Some(p) = self.material.plasticity else {
            return;
        };
        if !self.sleep.asleep {
            self.springs
                .flow(&self.mesh, &self.previous_positions, p, h);
        }
    }

    /// [`SubstepStage::OneRing`]'s impulses over a substep of `h` (see
    /// `PassBody::one_ring_impulses`).
    pub(crate) fn one_ring_impulses(
        &mut self,
        h: f32,
        spheres: &mut [RigidSphereState],
        parallel: &dyn Parallel,
    ) {
        self.pass_body().one_ring_impulses(h, spheres, parallel);
    }

    /// [`SubstepStage::PerTet`]'s impulses over a substep of `h` (see
    /// `PassBody::per_tet_impulses`).
    pub(crate) fn per_tet_impulses(
        &mut self,
        h: f32,
        spheres: &mut [RigidSphereState],
        parallel: &dyn Parallel,
    ) {
        self.pass_body().per_tet_impulses(h, spheres, parallel);
    }

    /// Starts or stops timing this body's substep stages (the plugin times them).
    pub(crate) fn time_substeps(&mut self, on: bool) {
        self.scratch.substep_clock.on = on;
    }

    /// The seconds this body spent in each [`SubstepStage`] since the last call.
    pub(crate) fn take_substep_seconds(&mut self) -> [f64; 5] {
        std::mem::take(&mut self.scratch.substep_clock.seconds)
    }
}
