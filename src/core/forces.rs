//! The forces of a step (the paper's section 3 and its springs): gravity, the springs with
//! their dampers, the baseline's volume forces, drag; and the plasticity of the springs
//! (section 6). A physical material has none of these but gravity: its shape is solved in
//! substeps (`substep.rs`, `deviatoric.rs`).

use glam::Vec3;

use super::geometry::{signed_volume, volume_gradients};
use super::material::{Elasticity, Plasticity, SoftBodyMaterial, VolumeMethod};
use super::parallel::{BlockFlags, Parallel, Phase, SharedSlice, run_phases};
use super::tet_mesh::TetMesh;

/// The springs on the mesh's edges: the paper's distance constraints, or a physical
/// material's edges (XPBD's, and plastic springs' shape solve). Their rest lengths (at creation
/// and after plastic flow), stiffness, compliance and dampers.
#[derive(Clone, Debug)]
pub(crate) struct Springs {
    /// Rest lengths at creation (`D0`).
    pub(crate) rest0: Vec<f32>,
    /// Current rest lengths (differ from `rest0` only through plasticity).
    pub(crate) rest: Vec<f32>,
    /// Plastic strain `e_p` of each spring.
    pub(crate) plastic_strain: Vec<f32>,
    /// Each spring's `k_D` (J) from the material's [`Elasticity`]: the same for every spring
    /// with the paper's springs, `E` times the volume of the tets around it for a physical
    /// material.
    pub(crate) stiffness: Vec<f32>,
    /// `1 / stiffness`: each edge constraint's compliance in the substepped solvers.
    pub(crate) compliance: Vec<f32>,
    /// Each spring's damper (N s/m).
    pub(crate) damping: Vec<f32>,
    /// Each spring's unit direction this step (zero for a spring of no length), from its force
    /// to its damper: one root and one division per spring instead of two.
    pub(crate) directions: Vec<Vec3>,
}

impl Springs {
    /// The springs of `mesh`'s edges at their rest lengths, `material`'s stiffness.
    pub(crate) fn new(mesh: &TetMesh, elasticity: Elasticity) -> Self {
        let rest0: Vec<f32> = mesh
            .edges()
            .iter()
            .map(|&[i, j]| mesh.positions()[i as usize].distance(mesh.positions()[j as usize]))
            .collect();
        let n = rest0.len();
        let mut springs = Springs {
            rest: rest0.clone(),
            plastic_strain: vec![0.0; n],
            stiffness: vec![0.0; n],
            compliance: vec![0.0; n],
            damping: vec![0.0; n],
            directions: vec![Vec3::ZERO; n],
            rest0,
        };
        springs.update_elasticity(mesh, elasticity);
        springs
    }

    /// Fills the springs' stiffnesses, compliances and dampers from `elasticity`.
    pub(crate) fn update_elasticity(&mut self, mesh: &TetMesh, elasticity: Elasticity) {
        match elasticity {
            Elasticity::Springs {
                distance_stiffness,
                damping,
            } => {
                self.stiffness.fill(distance_stiffness);
                self.damping.fill(damping);
            }
            Elasticity::Elastic(e) => {
                // Each tet's volume to each of its six edges.
                let index: std::collections::HashMap<[u32; 2], usize> = mesh
                    .edges()
                    .iter()
                    .enumerate()
                    .map(|(k, &[i, j])| ([i.min(j), i.max(j)], k))
                    .collect();
                self.stiffness.fill(0.0);
                for (tet, &v0) in mesh.tets().iter().zip(mesh.rest_volumes()) {
                    for (a, b) in [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)] {
                        let (i, j) = (tet[a], tet[b]);
                        if let Some(&k) = index.get(&[i.min(j), i.max(j)]) {
                            self.stiffness[k] += e.youngs_modulus * v0;
                        }
                    }
                }
                for ((c, &k), &rest) in self
                    .damping
                    .iter_mut()
                    .zip(&self.stiffness)
                    .zip(&self.rest0)
                {
                    // A spring constant `k_D / D0^2` (N/m), times `beta`.
                    *c = e.damping * k / (rest * rest);
                }
            }
        }
        for (c, &k) in self.compliance.iter_mut().zip(&self.stiffness) {
            *c = if k > 0.0 { 1.0 / k } else { f32::INFINITY };
        }
    }

    /// The dampers of all springs of `mesh` at `positions` on `velocities`, in index order,
    /// which is the blocks' (see [`damp_spring`]).
    pub(crate) fn damp(
        &self,
        mesh: &TetMesh,
        positions: &[Vec3],
        inv_masses: &[f32],
        velocities: &mut [Vec3],
        h: f32,
    ) {
        // SAFETY: used on this thread alone.
        let velocities = unsafe { SharedSlice::new(velocities) };
        for (&edge, &damping) in mesh.edges().iter().zip(&self.damping) {
            let dir = spring_direction(positions, edge).0;
            damp_spring(edge, dir, inv_masses, velocities, h, damping);
        }
    }

    /// Plastic flow of the rest lengths over a step of `h` (section 6), driven by the strain
    /// of `positions`.
    pub(crate) fn flow(&mut self, mesh: &TetMesh, positions: &[Vec3], p: Plasticity, h: f32) {
        for (e, &[i, j]) in mesh.edges().iter().enumerate() {
            let length = positions[i as usize].distance(positions[j as usize]);
            let rest0 = self.rest0[e];
            let strain = (length - rest0) / rest0;
            let plastic = &mut self.plastic_strain[e];
            let elastic = strain - *plastic;
            if elastic.abs() > p.yield_strain {
                *plastic += h * p.creep * elastic;
            }
            *plastic = plastic.clamp(-p.max_strain, p.max_strain);
            self.rest[e] = rest0 * (1.0 + *plastic);
        }
    }
}

/// A body as its forces see it; the body lends its parts (`SoftBodyState::apply_forces`).
pub(crate) struct ForceBody<'a> {
    pub(crate) mesh: &'a TetMesh,
    pub(crate) material: &'a SoftBodyMaterial,
    pub(crate) positions: &'a [Vec3],
    pub(crate) inv_masses: &'a [f32],
    pub(crate) velocities: &'a mut [Vec3],
    /// Per-particle scratch, zero between uses: the forces.
    pub(crate) per_particle: &'a mut [Vec3],
    pub(crate) block_done: &'a BlockFlags,
    pub(crate) springs: &'a mut Springs,
}

/// [`Stage::Forces`](crate::core::Stage::Forces) of the paper's explicit springs: external,
/// spring and (baseline) volume forces change the velocities over a step of `h`.
///
/// The mesh's blocks are run by `parallel`: the same result bit for bit on any number of
/// threads (see `core::parallel`). Springs (and the baseline's tets) add their forces block by
/// block in the blocks' order, then each particle's velocity takes its force, then the dampers
/// act block by block, then drag.
pub(crate) fn explicit_forces(body: ForceBody, h: f32, gravity: Vec3, parallel: &dyn Parallel) {
    let mesh: &TetMesh = body.mesh;
    let blocks = mesh.blocks();
    let count = blocks.count();
    let any_damping = body.material.any_damping();
    let springs = &mut *body.springs;
    let (edge_stiffness, edge_damping) = (&springs.stiffness[..], &springs.damping[..]);
    let drag = body.material.linear_damping;
    let volume_stiffness = match body.material.method {
        VolumeMethod::Baseline { volume_stiffness } => Some(volume_stiffness),
        _ => None,
    };
    let (x, inv_masses, spring_rest) = (body.positions, body.inv_masses, &springs.rest[..]);
    // SAFETY: a phase starts when the one before has ended; in the springs' and the
    // dampers' phases a block runs after every block it shares a particle with
    // (`waits_for`), and writes only its own edges' directions; in the particles' phases
    // each chunk touches its own particles.
    let forces = unsafe { SharedSlice::new(body.per_particle) };
    let velocities = unsafe { SharedSlice::new(body.velocities) };
    let directions = unsafe { SharedSlice::new(&mut springs.directions) };
    let n = x.len();
    let chunks = n.div_ceil(PARTICLE_CHUNK);
    let (springs_done, dampers_done) = body.block_done.split_at(count);
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
