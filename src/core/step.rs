//! The order of a step, written once: [`Stage::ORDER`]. The core's whole-step functions run
//! it for one body, and the Bevy plugin runs it with one system set per stage (its sets are
//! chained in this order), each system calling [`SoftBodyState::run_stage`] on every body.
//!
//! A step starts with [`SoftBodyState::begin_step`], then, for every method:
//! 1. [`Stage::Forces`] (the paper's section 3, and the prediction): gravity, springs with
//!    damping and, for the baseline, the per-tet volume forces change the velocities;
//!    kinematic particles get the velocity that takes them to their target.
//! 2. [`Stage::Contacts`]: velocities change so that the predicted positions `x + h v` lie
//!    outside every collider and sphere, so that the volume passes see the contacts. A body
//!    solved in substeps (a physical material's shape constraints, XPBD) is solved here,
//!    meeting the contacts and running its volume passes in every substep (`xpbd.rs`).
//! 3. [`Stage::OneRing`] (section 5) and 4. [`Stage::PerTet`] (section 4): the paper's volume
//!    impulses on the predicted positions.
//! 5. [`Stage::Plasticity`] (section 6): plastic springs.
//! 6. [`Stage::Integrate`]: contacts again (undoing whatever the volume impulses pushed into a
//!    collider, so that no particle ends a step inside one), then `x += h v`, then a body that
//!    ran away is caught (`runaway.rs`).
//!
//! Rigid spheres take part in the same stages ([`spheres_before_bodies`],
//! [`spheres_after_bodies`]): their gravity in the forces, their contacts with the static
//! colliders before the bodies' contacts, their motion after the bodies'.

use glam::Vec3;

use super::body::SoftBodyState;
use super::colliders::{ColliderInstance, RigidSphereState};
use super::parallel::{Parallel, Serial};

/// A stage of a step. See the module's documentation for what each does and why in this order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stage {
    /// Gravity, springs and damping, the baseline's volume forces, kinematic particles.
    Forces,
    /// Contacts on the predicted positions; the shape of a body solved in substeps.
    Contacts,
    /// The one-ring volume impulses (the paper's section 5).
    OneRing,
    /// The per-tet volume correction scaled by gamma, with the neighbour clamp (section 4).
    PerTet,
    /// Plastic springs (section 6).
    Plasticity,
    /// A last contact pass, then `x += h v`, then the runaway check.
    Integrate,
}

impl Stage {
    /// The stages in the order a step runs them.
    pub const ORDER: [Stage; 6] = [
        Stage::Forces,
        Stage::Contacts,
        Stage::OneRing,
        Stage::PerTet,
        Stage::Plasticity,
        Stage::Integrate,
    ];
}

impl SoftBodyState {
    /// Whether `stage` can change this body (a stage no body has work in need not be run).
    pub fn has_work_in(&self, stage: Stage) -> bool {
        match stage {
            Stage::Plasticity => self.material().plasticity.is_some(),
            _ => true,
        }
    }

    /// This body's part of `stage` in a step of `h` among `spheres` (which the body's contacts
    /// and volume impulses push) and `colliders`, its blocks (or particle chunks) run by
    /// `parallel`: the same result bit for bit on any number of threads. Returns the contacts
    /// the stage resolved.
    pub fn run_stage(
        &mut self,
        stage: Stage,
        h: f32,
        gravity: Vec3,
        spheres: &mut [RigidSphereState],
        colliders: &[ColliderInstance],
        parallel: &dyn Parallel,
    ) -> u32 {
        match stage {
            Stage::Forces => {
                self.apply_forces(h, gravity, parallel);
                0
            }
            Stage::Contacts => {
                let contacts = self.resolve_contacts_on(h, spheres, colliders, parallel);
                contacts + self.shape_pass(h, spheres, colliders, parallel)
            }
            Stage::OneRing => {
                self.one_ring_pass(h, spheres, parallel);
                0
            }
            Stage::PerTet => {
                self.per_tet_pass(h, spheres, parallel);
                0
            }
            Stage::Plasticity => {
                self.apply_plasticity(h);
                0
            }
            Stage::Integrate => {
                let contacts = self.resolve_contacts_on(h, spheres, colliders, parallel);
                self.integrate_positions(h, parallel);
                contacts
            }
        }
    }

    /// The particles against the spheres, the rigid bodies of another engine, then the static
    /// colliders (last, so that no particle is left inside the ground by a body pushing it). A
    /// body solved in substeps meets them in its substeps instead: this is what
    /// [`Stage::Contacts`] does besides `shape_pass`.
    pub(crate) fn resolve_contacts_on(
        &mut self,
        h: f32,
        spheres: &mut [RigidSphereState],
        colliders: &[ColliderInstance],
        parallel: &dyn Parallel,
    ) -> u32 {
        if self.material().is_substepped() {
            return 0;
        }
        self.resolve_sphere_contacts(h, spheres)
            + self.resolve_rigid_contacts(h, 0.0)
            + self.resolve_static_contacts(h, colliders, parallel)
    }

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
        for stage in Stage::ORDER {
            spheres_before_bodies(stage, h, gravity, spheres, colliders);
            self.run_stage(stage, h, gravity, spheres, colliders, parallel);
            spheres_after_bodies(stage, h, spheres);
        }
    }
}

/// The spheres' part of `stage` that comes before the bodies': their gravity in the forces,
/// their contacts with the static colliders before the particles meet them.
pub fn spheres_before_bodies(
    stage: Stage,
    h: f32,
    gravity: Vec3,
    spheres: &mut [RigidSphereState],
    colliders: &[ColliderInstance],
) {
    for sphere in spheres {
        match stage {
            Stage::Forces => sphere.apply_forces(h, gravity),
            Stage::Contacts | Stage::Integrate => {
                sphere.resolve_static_contacts(h, colliders);
            }
            Stage::OneRing | Stage::PerTet | Stage::Plasticity => {}
        }
    }
}

/// The spheres' part of `stage` that comes after the bodies': `x += h v` when the particles
/// have moved.
pub fn spheres_after_bodies(stage: Stage, h: f32, spheres: &mut [RigidSphereState]) {
    if stage == Stage::Integrate {
        for sphere in spheres {
            sphere.integrate_position(h);
        }
    }
}
