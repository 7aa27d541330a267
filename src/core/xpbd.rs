//! Substepped XPBD: the peer the paper's method is measured against (see
//! [`VolumeMethod::Xpbd`]), and the substeps of a physical material under the paper's
//! impulses, whose shape solve is the tets' shape constraints of `deviatoric.rs` (or these
//! edges, for plastic springs; see [`SoftBodyState::shape_pass`]).
//!
//! Each step is split into substeps. A substep predicts every particle's position from its
//! velocity and gravity, projects every edge constraint `C = (L - L0) / L0` with compliance
//! `1 / k_D` of that edge (so that its energy is the springs' `1/2 k_D C^2`) and every tet's volume
//! constraint `C = (V - V0) / V0` with zero compliance, once each in Gauss-Seidel order (one
//! iteration; with a fresh multiplier per substep, as "Small Steps" does), derives the velocities
//! from the motion, resolves contacts on them with the same code the other methods use, and
//! damps the springs. Momentum is conserved by every projection (the constraint gradients sum
//! to zero).
//!
//! A physical material's constraints are damped inside their projection, in XPBD's own form
//! (Macklin et al. 2016, eq. 26): with stiffness-proportional damping `beta` the damping term of
//! a constraint is `gamma = beta / h_s`, the same for every constraint, and the projection
//! solves the constraint and its damper together, implicitly. A separate pass of velocity
//! dampers after the projection (what the paper's explicit springs keep) is unstable for stiff
//! materials (PERFORMANCE.md).
//!
//! Decisions: gravity is applied per substep (stored by `apply_forces`, which adds no spring
//! forces for this method); kinematic particles move to their target in equal parts; a rigid
//! sphere is tested at its position advanced to each substep at its current velocity, and left
//! where it was for the plugin to integrate; damping and drag act per substep.
//!
//! [`VolumeMethod::Xpbd`]: super::material::VolumeMethod::Xpbd

use glam::Vec3;

use super::body::SoftBodyState;
use super::colliders::{ColliderInstance, RigidSphereState};
use super::deviatoric::{project_tet_shapes, refresh_shape_bundles};
use super::geometry::{signed_volume, volume_gradients};
use super::lanes::Point4;
use super::material::{Elasticity, VolumeMethod};
use super::parallel::{Parallel, Serial};
use super::soft_records::SubstepPlan;

impl SoftBodyState {
    /// The step in substeps (see [`SoftBodyMaterial::is_substepped`]); nothing for a body
    /// integrated explicitly in one step. Returns the contacts it resolved (summed over the
    /// substeps). It moves the particles itself, so `integrate_positions` leaves them where
    /// they are, and the plugin's contact passes skip the body.
    ///
    /// For [`VolumeMethod::Xpbd`] each substep projects the edges and the tets' volume
    /// constraints. For a physical material under the paper's impulses each substep is the
    /// paper's step at the substep's length, with the tets' shape constraints (`deviatoric.rs`;
    /// the edges for plastic springs) in place of its explicit springs: gravity, the shape
    /// constraints, the contacts and damping give the velocities (the predicted positions
    /// `x + h_s v` are where the shape solve puts the particles), then the one-ring and per-tet
    /// impulses restore the volume on those predicted positions, then `x += h_s v`. The volume passes run
    /// in every substep, not once a step: a body crushed within a step by a landing cannot be
    /// restored after it.
    ///
    /// Bodies that touch each other run their substeps in lockstep instead
    /// (`soft_contacts::shape_pass_together`), with [`SoftBodyState::plan_substeps`] and the
    /// three parts of a substep below.
    ///
    /// [`SoftBodyMaterial::is_substepped`]: super::material::SoftBodyMaterial::is_substepped
    /// [`VolumeMethod::Xpbd`]: super::material::VolumeMethod::Xpbd
    pub fn shape_pass(
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
            self.substep_motion(&plan, k);
            self.substep_velocities(&plan);
            contacts += self.substep_contacts(&plan, k, spheres, colliders);
            self.substep_finish(&plan, spheres, parallel);
        }
        self.update_sleep(h, spheres, colliders);
        contacts
    }

    /// Sets up this step's substeps (`substeps` of them if given, else as many as the body's
    /// motion needs); `None` for a body not solved in substeps, or asleep through the step.
    pub(crate) fn plan_substeps(
        &mut self,
        h: f32,
        spheres: &[RigidSphereState],
        colliders: &[ColliderInstance],
        substeps: Option<u32>,
    ) -> Option<SubstepPlan> {
        if !self.material.is_substepped() || self.stays_asleep(h, spheres, colliders) {
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
            Elasticity::Springs { .. } => (0.0, self.any_damping()),
        };
        // A physical material under the impulses keeps its shape per tet, unless its plastic
        // springs are the edges (see `ElasticSettings`).
        let tet_compliance = match (self.material.elasticity, self.material.plasticity) {
            (Elasticity::Elastic(e), None) if !volumes => Some(e.tet_compliance()),
            _ => None,
        };
        if tet_compliance.is_some() {
            refresh_shape_bundles(&mut self.scratch.shape_bundles, &self.inv_masses);
        }
        // The rigid bodies of another engine get their gravity per substep too.
        for body in &mut self.rigid.bodies {
            body.linear_velocity -= h * body.gravity;
        }
        Some(SubstepPlan {
            substeps,
            hs,
            volumes,
            shape_damping,
            dampers,
            tet_compliance,
        })
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
            (VolumeMethod::Xpbd(s), _) => Some(s.substeps.max(1)),
            (VolumeMethod::Impulses(_), Elasticity::Elastic(e)) => {
                let speed = self.substep_speed(h, spheres, colliders).max(approach);
                Some(e.substeps(h, speed, self.shortest_edge))
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
    /// bodies is counted apart (`contact_stage_together`'s `approach`).
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

    /// Substep `k`'s motion: gravity, the predicted positions, the shape solve (edges, or the
    /// tets' shapes; for XPBD the tets' volumes too). The particles are left where it takes
    /// them; [`SoftBodyState::substep_velocities`] turns that into velocities.
    pub(crate) fn substep_motion(&mut self, plan: &SubstepPlan, k: u32) {
        let _ = k;
        let hs = plan.hs;
        let gravity = self.gravity;
        for body in &mut self.rigid.bodies {
            body.linear_velocity += hs * body.gravity;
        }
        // Predict; `predicted` holds where each particle started the substep.
        for i in 0..self.positions.len() {
            if self.inv_masses[i] > 0.0 {
                self.velocities[i] += hs * gravity;
            }
            self.scratch.predicted[i] = Point4::new(self.positions[i]);
            self.positions[i] += hs * self.velocities[i];
        }
        match plan.tet_compliance {
            Some(compliance) => project_tet_shapes(
                &self.scratch.shape_bundles,
                &mut self.positions,
                &self.scratch.predicted,
                compliance,
                hs * hs,
                plan.shape_damping,
            ),
            None => self.project_edges(hs * hs, plan.shape_damping),
        }
        if plan.volumes {
            self.project_volumes();
        }
    }

    /// The velocities substep `k`'s motion gives (where the shape solve, and the contacts
    /// between bodies in lockstep, took the particles), with the particles back where the
    /// substep started.
    pub(crate) fn substep_velocities(&mut self, plan: &SubstepPlan) {
        let hs = plan.hs;
        // Velocities from the motion, then contacts on them from the substep's start.
        for i in 0..self.positions.len() {
            let v = (self.positions[i] - self.scratch.predicted[i].vec3()) / hs;
            if v.is_finite() {
                self.velocities[i] = v;
            } else {
                self.velocities[i] = Vec3::ZERO;
                self.counters.non_finite_velocities += 1;
            }
            self.positions[i] = self.scratch.predicted[i].vec3();
        }
    }

    /// Substep `k`'s contacts with the spheres, rigid bodies and static colliders. Returns
    /// the contacts.
    pub(crate) fn substep_contacts(
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

    /// The end of a substep: damping, then the paper's volume impulses and `x += h_s v` (or,
    /// for XPBD, `x += h_s v` alone).
    pub(crate) fn substep_finish(
        &mut self,
        plan: &SubstepPlan,
        spheres: &mut [RigidSphereState],
        parallel: &dyn Parallel,
    ) {
        let hs = plan.hs;
        if plan.dampers {
            self.damp_springs(hs);
        }
        let drag = self.material.linear_damping;
        if drag > 0.0 {
            let keep = 1.0 / (1.0 + hs * drag);
            for (v, &w) in self.velocities.iter_mut().zip(&self.inv_masses) {
                if w > 0.0 {
                    *v *= keep;
                }
            }
        }
        if plan.volumes {
            for (x, v) in self.positions.iter_mut().zip(&self.velocities) {
                *x += hs * *v;
            }
        } else {
            self.volume_impulses_in_substep(hs, spheres, parallel);
        }
    }

    /// The paper's one-ring and per-tet impulses in a substep of `hs`, on the predicted positions
    /// `x + hs v`, then `x += hs v`, with the impulses' energy kept in check: the positions
    /// take the impulses' whole change `dv`, the velocities `k dv` with the largest `k` in
    /// `[0, 1]` that adds no kinetic energy. An impulse that stops a compression (it takes
    /// away the velocity that compresses the tets) keeps all of it (`k` = 1 while
    /// `sum m v.dv <= -1/2 sum m |dv|^2`); what only restores drifted volume, a tet crushed by
    /// a landing or a tet inverted, moves the particles back without launching them (the
    /// measurements are in PERFORMANCE.md, "The step of a physical material"). One scale for the whole body, so
    /// momentum is conserved (the impulses' `sum m dv` is zero, and so is `k` times it) but for
    /// what the static colliders pushed back, whose friction comes last (`support_friction`).
    fn volume_impulses_in_substep(
        &mut self,
        hs: f32,
        spheres: &mut [RigidSphereState],
        parallel: &dyn Parallel,
    ) {
        self.scratch
            .substep_velocities
            .copy_from_slice(&self.velocities);
        self.scratch.soft_removed.fill(Vec3::ZERO);
        self.one_ring_impulses(hs, spheres, parallel);
        self.per_tet_impulses(hs, spheres, parallel);
        // `push`: what the static colliders pushed back, which gets its friction
        // (`support_friction`).
        // Pushes into another body come out here, to be handed to it (`soft_support`).
        let soft_push = self.take_soft_pushes();
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
        let weight = self.static_contact_weight();
        for i in 0..self.velocities.len() {
            let before = self.scratch.substep_velocities[i];
            let full = self.velocities[i];
            let v = before + k * (full - before);
            let friction = self.support_friction(push, weight, i, v);
            self.positions[i] += hs * (full + friction);
            self.velocities[i] = v + friction;
        }
        self.hand_soft_pushes(k);
    }

    /// One Gauss-Seidel pass over the edge constraints, each of compliance
    /// `edge_compliance / hs2` (`hs2` the squared substep), in the blocks' order of the springs
    /// (see [`Blocks::edges`](super::tet_mesh::Blocks::edges)): the same order the other
    /// methods' dampers take, where consecutive constraints share no particle and do not wait
    /// for each other's results. An edge of zero stiffness (infinite compliance) is skipped.
    /// `gamma` is XPBD's damping term (see the module's doc): the projection is
    /// `dlambda = -(C + gamma grad C . (x - x_start)) / ((1 + gamma) w / L0^2 + alpha)`, the
    /// undamped one when it is zero.
    fn project_edges(&mut self, hs2: f32, gamma: f32) {
        let x = &mut self.positions;
        let start = &self.scratch.predicted;
        let edges = self.mesh.edges();
        for &e in self.mesh.blocks().edges.items() {
            let e = e as usize;
            let [i, j] = edges[e];
            let (i, j) = (i as usize, j as usize);
            let (wi, wj) = (self.inv_masses[i], self.inv_masses[j]);
            let alpha = self.edge_compliance[e] / hs2;
            if wi + wj == 0.0 || !alpha.is_finite() {
                continue;
            }
            let d = x[j] - x[i];
            let length = d.length();
            let rest = self.spring_rest[e];
            if length <= f32::EPSILON * rest {
                continue;
            }
            let n = d / length;
            let c = (length - rest) / rest;
            let lambda = if gamma > 0.0 {
                let rate = n.dot((x[j] - start[j].vec3()) - (x[i] - start[i].vec3())) / rest;
                -(c + gamma * rate) / ((1.0 + gamma) * (wi + wj) / (rest * rest) + alpha)
            } else {
                -c / ((wi + wj) / (rest * rest) + alpha)
            };
            let push = n * (lambda / rest);
            x[i] -= push * wi;
            x[j] += push * wj;
        }
    }

    /// One Gauss-Seidel pass over the tets' volume constraints (zero compliance), in index
    /// order. The per-tet pass's bundle order (see
    /// [`Blocks::tet_bundles`](super::tet_mesh::Blocks::tet_bundles)) made this pass twice as
    /// fast, but a sweep in index order carries a correction across the mesh in one pass, and
    /// without it the peer lost several times its accuracy (PERFORMANCE.md, "Against XPBD").
    fn project_volumes(&mut self) {
        let x = &mut self.positions;
        for (tet, &v0) in self.mesh.tets().iter().zip(self.mesh.rest_volumes()) {
            let p = tet.map(|i| x[i as usize]);
            let c = (signed_volume(&p) - v0) / v0;
            if c == 0.0 {
                continue;
            }
            let g = volume_gradients(&p);
            let denominator: f32 = (0..4)
                .map(|k| self.inv_masses[tet[k] as usize] * g[k].length_squared())
                .sum::<f32>()
                / (v0 * v0);
            if denominator <= 0.0 {
                continue;
            }
            let lambda = -c / denominator;
            for k in 0..4 {
                let i = tet[k] as usize;
                x[i] += g[k] * (self.inv_masses[i] * lambda / v0);
            }
        }
    }
}
