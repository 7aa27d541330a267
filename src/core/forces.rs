//! The forces of a step (the paper's section 3 and its springs): gravity, the springs with
//! their dampers, the baseline's volume forces, drag; and the plasticity of the springs
//! (section 6). A physical material has none of these but gravity: its shape is solved in
//! substeps (`substep/`, `deviatoric.rs`).

use glam::Vec3;

use super::body::SoftBodyState;
use super::geometry::{signed_volume, volume_gradients};
use super::material::{Elasticity, VolumeMethod};
use super::parallel::{Parallel, Phase, SharedSlice, run_phases};

impl SoftBodyState {
    /// The dampers of all springs, in index order, which is the blocks' (see [`damp_spring`]).
    pub(crate) fn damp_springs(&mut self, h: f32) {
        // SAFETY: used on this thread alone.
        let velocities = unsafe { SharedSlice::new(&mut self.velocities) };
        for (&edge, &damping) in self.mesh.edges().iter().zip(&self.edge_damping) {
            let dir = spring_direction(&self.positions, edge).0;
            damp_spring(edge, dir, &self.inv_masses, velocities, h, damping);
        }
    }

    /// Whether any spring has a damper.
    pub(crate) fn any_damping(&self) -> bool {
        match self.material.elasticity {
            Elasticity::Springs { damping, .. } => damping > 0.0,
            Elasticity::Elastic(e) => e.damping > 0.0,
        }
    }

    /// [`Stage::Forces`](crate::core::Stage::Forces): external, spring and (baseline) volume
    /// forces change the velocities.
    ///
    /// The mesh's blocks are run by `parallel`: the same result bit for bit on any number of
    /// threads (see `core::parallel`). Springs (and the
    /// baseline's tets) add their forces block by block in the blocks' order, then each
    /// particle's velocity takes its force, then the dampers act block by block, then drag.
    pub(crate) fn apply_forces(&mut self, h: f32, gravity: Vec3, parallel: &dyn Parallel) {
        self.gravity = gravity;
        if self.material.is_substepped() {
            // Gravity, springs, damping and drag act inside the substeps (`substep/`); only
            // the kinematic particles are set moving here.
            for &(i, target) in &self.kinematic {
                let i = i as usize;
                self.velocities[i] = (target - self.positions[i]) / h;
            }
            return;
        }
        let mesh = &*self.mesh;
        let blocks = mesh.blocks();
        let count = blocks.count();
        let any_damping = self.any_damping();
        let (edge_stiffness, edge_damping) = (&self.edge_stiffness[..], &self.edge_damping[..]);
        let drag = self.material.linear_damping;
        let volume_stiffness = match self.material.method {
            VolumeMethod::Baseline { volume_stiffness } => Some(volume_stiffness),
            _ => None,
        };
        let (x, inv_masses, spring_rest) = (
            &self.positions[..],
            &self.inv_masses[..],
            &self.spring_rest[..],
        );
        // SAFETY: a phase starts when the one before has ended; in the springs' and the
        // dampers' phases a block runs after every block it shares a particle with
        // (`waits_for`), and writes only its own edges' directions; in the particles' phases
        // each chunk touches its own particles.
        let forces = unsafe { SharedSlice::new(&mut self.scratch.per_particle) };
        let velocities = unsafe { SharedSlice::new(&mut self.velocities) };
        let directions = unsafe { SharedSlice::new(&mut self.scratch.spring_directions) };
        let n = x.len();
        let chunks = n.div_ceil(PARTICLE_CHUNK);
        let (springs_done, dampers_done) = self.scratch.block_done.split_at(count);
        let phases = [
            Phase {
                tasks: count,
                order: Some((&blocks.waits_for, springs_done)),
            },
            Phase {
                tasks: chunks,
                order: None,
            },
            Phase {
                tasks: if any_damping { count } else { 0 },
                order: Some((&blocks.waits_for, dampers_done)),
            },
            Phase {
                tasks: if drag > 0.0 { chunks } else { 0 },
                order: None,
            },
        ];
        run_phases(parallel, &phases, &|phase, task| {
            let particles = PARTICLE_CHUNK * task..(PARTICLE_CHUNK * (task + 1)).min(n);
            match phase {
                0 => {
                    for &e in blocks.edges.row(task) {
                        let e = e as usize;
                        let edge = mesh.edges()[e];
                        let (dir, length) = spring_direction(x, edge);
                        let [i, j] = edge.map(|i| i as usize);
                        let rest = spring_rest[e];
                        directions.set(e, dir);
                        if length <= f32::EPSILON * rest {
                            continue;
                        }
                        let f = dir * (edge_stiffness[e] * (length - rest) / (rest * rest));
                        forces.set(i, forces.get(i) + f);
                        forces.set(j, forces.get(j) - f);
                    }
                    if let Some(volume_stiffness) = volume_stiffness {
                        for &t in blocks.tets.row(task) {
                            let tet = mesh.tets()[t as usize];
                            let v0 = mesh.rest_volumes()[t as usize];
                            let p = tet.map(|i| x[i as usize]);
                            let c = (signed_volume(&p) - v0) / v0;
                            let g = volume_gradients(&p);
                            let scale = -volume_stiffness * c / v0;
                            for k in 0..4 {
                                let i = tet[k] as usize;
                                forces.set(i, forces.get(i) + g[k] * scale);
                            }
                        }
                    }
                }
                1 => {
                    for i in particles {
                        let w = inv_masses[i];
                        if w > 0.0 {
                            let dv = h * (gravity + forces.get(i) * w);
                            velocities.set(i, velocities.get(i) + dv);
                        }
                        forces.set(i, Vec3::ZERO);
                    }
                }
                2 => {
                    for &e in blocks.edges.row(task) {
                        let e = e as usize;
                        let (edge, dir) = (mesh.edges()[e], directions.get(e));
                        damp_spring(edge, dir, inv_masses, velocities, h, edge_damping[e]);
                    }
                }
                _ => {
                    let keep = 1.0 / (1.0 + h * drag);
                    for i in particles {
                        if inv_masses[i] > 0.0 {
                            velocities.set(i, velocities.get(i) * keep);
                        }
                    }
                }
            }
        });
        for &(i, target) in &self.kinematic {
            let i = i as usize;
            self.velocities[i] = (target - self.positions[i]) / h;
        }
    }

    /// [`Stage::Plasticity`](crate::core::Stage::Plasticity): plastic flow of the spring rest
    /// lengths (nothing without plasticity), driven by the strain of the positions the step
    /// started from: the strain the paper's springs' forces saw in the step (they act once, at
    /// its start), and one definition for every material whatever its substeps.
    pub(crate) fn apply_plasticity(&mut self, h: f32) {
        let Some(p) = self.material.plasticity else {
            return;
        };
        if self.sleep.asleep {
            return;
        }
        for (e, &[i, j]) in self.mesh.edges().iter().enumerate() {
            let x = &self.previous_positions;
            let length = x[i as usize].distance(x[j as usize]);
            let rest0 = self.spring_rest0[e];
            let strain = (length - rest0) / rest0;
            let plastic = &mut self.plastic_strain[e];
            let elastic = strain - *plastic;
            if elastic.abs() > p.yield_strain {
                *plastic += h * p.creep * elastic;
            }
            *plastic = plastic.clamp(-p.max_strain, p.max_strain);
            self.spring_rest[e] = rest0 * (1.0 + *plastic);
        }
    }
}

/// The unit direction from `i` to `j` at `x` (zero if they coincide) and their distance.
#[inline]
fn spring_direction(x: &[Vec3], [i, j]: [u32; 2]) -> (Vec3, f32) {
    let delta = x[j as usize] - x[i as usize];
    let length = delta.length();
    if length > f32::EPSILON {
        (delta / length, length)
    } else {
        (Vec3::ZERO, length)
    }
}

/// Spring damping, solved implicitly one spring at a time: the damper of each spring
/// removes the fraction `c h (w_i + w_j) / (1 + c h (w_i + w_j))` of the relative velocity
/// along it, which is the exact implicit step of that damper alone. An explicit damping
/// force overshoots on light particles (a grid corner weighs 1/40 of an interior particle)
/// as soon as the damping is strong enough to matter; this cannot, and it conserves
/// momentum.
fn damp_spring(
    [i, j]: [u32; 2],
    dir: Vec3,
    inv_masses: &[f32],
    velocities: SharedSlice<Vec3>,
    h: f32,
    damping: f32,
) {
    let (i, j) = (i as usize, j as usize);
    let w_sum = inv_masses[i] + inv_masses[j];
    // A spring of no length has no direction to damp along.
    if w_sum == 0.0 || dir == Vec3::ZERO {
        return;
    }
    let relative = (velocities.get(j) - velocities.get(i)).dot(dir);
    let k = damping * h;
    let impulse = relative * k / (1.0 + k * w_sum);
    velocities.set(i, velocities.get(i) + dir * (impulse * inv_masses[i]));
    velocities.set(j, velocities.get(j) - dir * (impulse * inv_masses[j]));
}

/// Particles per job of the per-particle parts of [`SoftBodyState::apply_forces`].
const PARTICLE_CHUNK: usize = 1024;
