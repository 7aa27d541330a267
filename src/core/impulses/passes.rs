//! Running the volume passes over a body: the one-ring pass (section 5) and the per-tet pass
//! (section 4), serial or in the mesh's blocks on threads, each impulse as in
//! [`VolumePass`]'s files (`ring.rs`, `tet.rs`, `clamp.rs`), and the pass's findings added up
//! into the body.

use std::sync::Arc;

use super::*;
use crate::core::lanes::Point4;
use crate::core::parallel::BlockFlags;
use crate::core::tet_mesh::Blocks;

/// What the volume passes keep in a body between passes and steps: their clamp bounds and
/// what tracks them, one worker per block, the guess of which rings need correcting. Only
/// saves work: every shortcut it allows gives the plain passes' result (the tests hold them).
#[derive(Clone, Debug)]
pub(crate) struct VolumePassScratch {
    /// Bounds that let most impulses skip the neighbour clamp (see `bounds.rs`).
    pub(crate) clamp_bounds: SafeRadii,
    /// What the clamp bounds track per particle while a volume pass runs.
    pub(crate) clamp_motion: DriftTracking,
    /// One per block of the mesh: what each job of a volume pass owns.
    pub(crate) pass_workers: Vec<PassWorker>,
    /// Per vertex, whether its ring was past its tolerance when its impulse last checked it:
    /// a guess of whether it will be again, which decides only how the check is computed,
    /// never its result (see `VolumePass::ring_impulse`).
    pub(crate) ring_corrected: Vec<bool>,
}

impl VolumePassScratch {
    /// The passes' memory for `mesh`.
    pub(crate) fn for_mesh(mesh: &TetMesh) -> Self {
        VolumePassScratch {
            clamp_bounds: Default::default(),
            clamp_motion: DriftTracking::default(),
            pass_workers: vec![PassWorker::for_mesh(mesh); mesh.blocks().count()],
            ring_corrected: vec![false; mesh.vertex_count()],
        }
    }

    /// At a step's start: no bounds taken in it yet.
    pub(crate) fn begin_step(&mut self) {
        self.clamp_bounds.taken_this_step = false;
    }
}

/// A body as its volume passes see it: what they read, the velocities and predicted positions
/// they change, and their own memory. The body lends its parts (`SoftBodyState::pass_body`).
pub(crate) struct PassBody<'a> {
    pub(crate) mesh: &'a Arc<TetMesh>,
    pub(crate) method: VolumeMethod,
    pub(crate) positions: &'a [Vec3],
    pub(crate) inv_masses: &'a [f32],
    pub(crate) velocities: &'a mut Vec<Vec3>,
    pub(crate) contact_normals: &'a [Vec3],
    pub(crate) contact_second: &'a [Vec3],
    pub(crate) contact_kept: &'a [f32],
    pub(crate) contact_sphere: &'a [u32],
    pub(crate) touching: &'a [u32],
    pub(crate) counters: &'a mut StepCounters,
    /// Predicted positions `x + h v`, kept in step with every velocity change.
    pub(crate) predicted: &'a mut Vec<Point4>,
    /// Per-particle scratch, zero between uses.
    pub(crate) per_particle: &'a mut Vec<Vec3>,
    /// What the impulses' pushes into another soft body lost (see `soft_lockstep.rs`).
    pub(crate) soft_removed: &'a mut Vec<Vec3>,
    pub(crate) block_done: &'a BlockFlags,
    pub(crate) passes: &'a mut VolumePassScratch,
}

impl PassBody<'_> {
    /// Sets every predicted position to `x + h v`.
    pub(crate) fn refresh_predicted(&mut self, h: f32) {
        for ((xp, x), v) in self
            .predicted
            .iter_mut()
            .zip(self.positions)
            .zip(self.velocities.iter())
        {
            *xp = Point4::new(*x + h * *v);
        }
    }

    /// [`SubstepStage::OneRing`](crate::core::SubstepStage::OneRing): one impulse per vertex
    /// restoring the volume of its one-ring (section 5), on the predicted positions `x + h v`
    /// of a substep of `h`. Nothing for the baseline or when the one-ring switch is off.
    /// `spheres` are the rigid spheres of the last contact pass, in the same order: particles
    /// pressed against one move it along.
    ///
    /// The mesh's blocks are run by `parallel`: the same result bit for bit on any number of
    /// threads (see `core::parallel`).
    pub(crate) fn one_ring_impulses(
        &mut self,
        h: f32,
        spheres: &mut [RigidSphereState],
        parallel: &dyn Parallel,
    ) {
        let VolumeMethod::Impulses(settings) = self.method else {
            return;
        };
        if !settings.one_ring {
            return;
        }
        self.refresh_predicted(h);
        let regions = settings.neighbour_clamp.then_some(ClampRegions::Rings);
        let mesh = self.mesh.clone();
        // The per-tet pass, if it runs, goes on from this pass's clamp bounds.
        self.passes.clamp_bounds.keep_for_tets = settings.per_tet && settings.gamma != 0.0;
        self.run_blocks(
            h,
            spheres,
            parallel,
            regions,
            &mesh.blocks().vertices,
            &|view, worker, centres, _| {
                for &p in centres {
                    let known = view.bounds.ring_checks
                        && view.ring_known_within(worker, p as usize, &settings);
                    if !known {
                        view.ring_impulse(worker, p as usize, &settings);
                    }
                }
            },
        );
    }

    /// [`SubstepStage::PerTet`](crate::core::SubstepStage::PerTet): one impulse per tet towards
    /// its own rest volume, scaled by `gamma` (section 4, end of section 5). Nothing for the
    /// baseline or when the per-tet switch is off. `spheres` and `parallel` as for
    /// [`PassBody::one_ring_impulses`].
    pub(crate) fn per_tet_impulses(
        &mut self,
        h: f32,
        spheres: &mut [RigidSphereState],
        parallel: &dyn Parallel,
    ) {
        let VolumeMethod::Impulses(settings) = self.method else {
            return;
        };
        if !settings.per_tet || settings.gamma == 0.0 {
            return;
        }
        self.refresh_predicted(h);
        let regions = settings.neighbour_clamp.then_some(ClampRegions::Tets);
        let mesh = self.mesh.clone();
        self.run_blocks(
            h,
            spheres,
            parallel,
            regions,
            &mesh.blocks().tet_bundles,
            &|view, worker, bundles, first| {
                let blocks = mesh.blocks();
                for (k, bundle) in bundles.chunks(LANES).enumerate() {
                    let at = first + LANES * k..first + LANES * k + bundle.len();
                    let corners = &blocks.bundle_corners[at.clone()];
                    let rest = &blocks.bundle_rest_volumes[at];
                    view.tet_bundle(worker, bundle, corners, rest, &settings);
                }
            },
        );
    }

    /// Runs `impulse` on each task's row of `items` (the mesh's [`Blocks`]' vertices or tet
    /// bundles; with the row's place in the flat list of items), which it works through in
    /// order, with the result of running the tasks one after another (see
    /// [`super::parallel`]): the threads of `parallel` take tasks in order as they come free,
    /// each waiting for the earlier tasks it shares particles with. A thread only ever waits
    /// for tasks a running thread has already taken, so any number of threads, one included,
    /// finishes. Then adds up the tasks' counters and sphere velocity
    /// changes in task order.
    ///
    /// [`Blocks`]: super::tet_mesh::Blocks
    fn run_blocks(
        &mut self,
        h: f32,
        spheres: &mut [RigidSphereState],
        parallel: &dyn Parallel,
        clamp_regions: Option<ClampRegions>,
        items: &Csr,
        impulse: &BlockImpulses<'_>,
    ) {
        self.reset_workers(spheres);
        #[cfg(test)]
        let clamp_regions = clamp_regions.filter(|_| !self.passes.clamp_bounds.disabled);
        let plan = self.plan_bounds(clamp_regions);
        self.run_pass_phases(h, parallel, clamp_regions, &plan, items, impulse);
        self.keep_bounds(clamp_regions, &plan);
        self.add_up_workers(spheres);
    }

    /// The pass's phases on the threads of `parallel`: the clamp bounds in chunks (the tets',
    /// the vertices', then the regions'; or, going on from earlier bounds, the drifts block by
    /// block), then the blocks' impulses, each block after the blocks it waits for.
    fn run_pass_phases(
        &mut self,
        h: f32,
        parallel: &dyn Parallel,
        clamp_regions: Option<ClampRegions>,
        plan: &BoundsPlan,
        items: &Csr,
        impulse: &BlockImpulses<'_>,
    ) {
        let BoundsPlan {
            carry,
            ring_checks,
            shapes,
            ..
        } = *plan;
        let blocks = self.mesh.blocks();
        let mesh: &TetMesh = self.mesh;
        let (inv_masses, contact_normals) = (self.inv_masses, self.contact_normals);
        let (contact_kept, contact_sphere) = (self.contact_kept, self.contact_sphere);
        let any_touching = !self.touching.is_empty();
        let contact_second = second_contacts(self.touching, self.contact_second);
        // SAFETY (for the view and every `SharedSlice` below): the pass's phases run one
        // after another; in a chunked phase each chunk writes its own tets', vertices' or
        // regions' entries; in a phase over the blocks a block runs after every block whose
        // one-ring or tets it shares (`waits_for`), and writes only the particles, tets and
        // block entries of its own items and their one-rings; each task has its own worker.
        let mut bounds = unsafe {
            self.passes
                .clamp_bounds
                .view(clamp_regions.unwrap_or(ClampRegions::Rings))
        };
        bounds.ring_checks = ring_checks;
        let velocities = unsafe { SharedSlice::new(self.velocities) };
        let predicted = unsafe { SharedSlice::new(self.predicted) };
        let scratch = unsafe { SharedSlice::new(self.per_particle) };
        let drift = unsafe { SharedSlice::new(&mut self.passes.clamp_motion.drift) };
        let move_len = unsafe { SharedSlice::new(&mut self.passes.clamp_motion.move_len) };
        let walks = WalkMarks {
            walked: &self.passes.clamp_motion.walked.0,
            walks: &self.passes.clamp_motion.walks.0,
        };
        let block_drift = unsafe { SharedSlice::new(&mut self.passes.clamp_motion.block_drift) };
        let ring_corrected = unsafe { SharedSlice::new(&mut self.passes.ring_corrected) };
        let removed = unsafe { SharedSlice::new(self.soft_removed) };
        let far = FarDriftMarks {
            marks: &self.passes.clamp_motion.far_nearby.0,
            pass: self.passes.clamp_motion.pass_number,
        };
        let workers = unsafe { SharedSlice::new(&mut self.passes.pass_workers) };
        let waits_for = &mesh.blocks().waits_for;
        let count = items.len();
        // The clamp bounds are computed first, in chunks: the tets', then the vertices'
        // (which need all tets'), then the regions' (which need all vertices'): the rings'
        // for a one-ring pass, the tets' for a per-tet pass or to keep; threads that join
        // late (waking one takes longer than a chunk) find the work going. A pass going on
        // from bounds taken earlier only measures the drifts, block by block.
        let (n, tet_count) = (mesh.vertex_count(), mesh.tet_count());
        let (ring_chunks, chunked) = bound_chunks(n, tet_count, count, clamp_regions, plan);
        let chunk_phase = |tasks: usize| Phase { tasks, order: None };
        let phases = [
            chunk_phase(chunked[0]),
            chunk_phase(chunked[1]),
            chunk_phase(chunked[2]),
            Phase {
                tasks: count,
                order: Some((waits_for, &self.block_done[..count])),
            },
        ];
        run_phases(parallel, &phases, &|phase, task| {
            let range = |items: usize| BOUNDS_CHUNK * task..(BOUNDS_CHUNK * (task + 1)).min(items);
            match phase {
                0 if shapes => bounds.compute_tet_shapes(mesh, range(tet_count)),
                0 => bounds.compute_tets(mesh, predicted, range(tet_count)),
                1 if shapes => bounds.compute_ring_checks(mesh, range(n)),
                1 => bounds.compute_vertices(mesh, predicted, drift, range(n)),
                2 if carry => {
                    let vertices = blocks.vertices.row(task);
                    let largest = bounds.carry_drift(mesh, predicted, drift, far, vertices);
                    block_drift.set(task, largest);
                }
                2 => {
                    if task < ring_chunks {
                        bounds.compute_regions(mesh, ClampRegions::Rings, range(n));
                    } else {
                        let task = task - ring_chunks;
                        let range = BOUNDS_CHUNK * task..(BOUNDS_CHUNK * (task + 1)).min(tet_count);
                        bounds.compute_regions(mesh, ClampRegions::Tets, range);
                    }
                }
                _ => {
                    let view = VolumePass {
                        mesh,
                        h,
                        inv_masses,
                        contact_normals,
                        contact_kept,
                        contact_second,
                        contact_sphere,
                        removed,
                        any_touching,
                        bounds,
                        velocities,
                        predicted,
                        scratch,
                        drift,
                        move_len,
                        walks,
                        far,
                        ring_corrected,
                    };
                    let start_drift = start_drift(workers, blocks, block_drift, carry, task);
                    // SAFETY: each task is run by one thread only.
                    let worker = unsafe { workers.get_mut(task) };
                    worker.max_moved = start_drift;
                    impulse(&view, worker, items.row(task), items.range(task).start);
                }
            }
        });
    }

    /// Clears every task's worker for a pass among `spheres`.
    fn reset_workers(&mut self, spheres: &[RigidSphereState]) {
        for worker in &mut self.passes.pass_workers {
            worker.counters = StepCounters::default();
            worker.max_moved = 0.0;
            worker.sphere_dv.clear();
            worker.sphere_dv.resize(spheres.len(), Vec3::ZERO);
        }
    }

    /// How this pass takes its clamp bounds: fresh or going on from earlier ones, with or
    /// without the tets' regions and the rings' checks; the bounds reserved for it.
    fn plan_bounds(&mut self, clamp_regions: Option<ClampRegions>) -> BoundsPlan {
        let take_tet_regions =
            clamp_regions == Some(ClampRegions::Tets) || self.passes.clamp_bounds.keep_for_tets;
        self.passes.clamp_bounds.keep_for_tets = false;
        // A per-tet pass after its step's one-ring pass goes on from the bounds that pass took
        // (they hold as long as drifts are measured from where they were taken): it only
        // measures each particle's drift again. Taking them costs about as much as the
        // per-tet pass's impulses in the soft cube. A one-ring pass goes on from an earlier
        // step's while the body has hardly moved since (see `CARRY_DRIFT`).
        // Whether the body is quiet (see `QUIET_DRIFT`), known only when a one-ring pass checks
        // whether it can go on from earlier bounds.
        let mut quiet_body = false;
        let carry = match clamp_regions {
            Some(ClampRegions::Tets) => self.passes.clamp_bounds.taken_this_step,
            Some(ClampRegions::Rings) => {
                if self.passes.clamp_bounds.kept {
                    self.passes.clamp_bounds.follow_translation(self.predicted);
                }
                let (carry, quiet) = self
                    .passes
                    .clamp_bounds
                    .still_hold(take_tet_regions, self.predicted);
                quiet_body = quiet as f32 >= QUIET_SHARE * self.predicted.len() as f32;
                carry
            }
            None => false,
        };
        // A one-ring pass going on from earlier bounds knows most rings of a body at rest to be
        // within their tolerances (see `RingErrorBound`); the first such pass computes what it
        // needs from the bounds' start, in the bounds' first two phases.
        let ring_checks = carry && clamp_regions == Some(ClampRegions::Rings) && quiet_body;
        let shapes = ring_checks && !self.passes.clamp_bounds.ring_checks_ready;
        if clamp_regions.is_some() {
            self.passes.clamp_bounds.reserve(
                self.mesh,
                self.mesh.blocks().count(),
                &mut self.passes.clamp_motion,
            );
            self.passes.clamp_bounds.active = true;
            self.passes.clamp_motion.next_pass();
        }
        BoundsPlan {
            take_tet_regions,
            carry,
            ring_checks,
            shapes,
        }
    }

    /// After a pass: which bounds are kept for the passes that go on from them.
    fn keep_bounds(&mut self, clamp_regions: Option<ClampRegions>, plan: &BoundsPlan) {
        let BoundsPlan {
            take_tet_regions,
            carry,
            shapes,
            ..
        } = *plan;
        self.passes.clamp_bounds.active = false;
        let bounds = &mut self.passes.clamp_bounds;
        match (clamp_regions, carry) {
            (Some(ClampRegions::Rings), false) => {
                bounds.taken_this_step = take_tet_regions;
                (bounds.kept, bounds.kept_tet_regions) = (true, take_tet_regions);
                bounds.ring_checks_ready = false;
            }
            (Some(ClampRegions::Rings), true) => {
                bounds.taken_this_step = bounds.kept_tet_regions;
                #[cfg(test)]
                {
                    bounds.carried_passes = bounds.carried_passes.saturating_add(1);
                }
                // Only a pass that computed the rings' checks makes them ready: a carried pass
                // in a body not quiet enough computes none, and the next quiet one must.
                bounds.ring_checks_ready |= shapes;
            }
            // Taken by a per-tet pass, without the rings' regions.
            (Some(ClampRegions::Tets), false) => {
                bounds.taken_this_step = true;
                bounds.kept = false;
                bounds.ring_checks_ready = false;
            }
            _ => {}
        }
    }

    /// Adds up the tasks' counters and sphere velocity changes, in task order.
    fn add_up_workers(&mut self, spheres: &mut [RigidSphereState]) {
        let c = &mut self.counters;
        for worker in &self.passes.pass_workers {
            let w = &worker.counters;
            c.rings_corrected += w.rings_corrected;
            c.rings_without_root += w.rings_without_root;
            c.rings_clamped += w.rings_clamped;
            c.tets_without_root += w.tets_without_root;
            c.tets_clamped += w.tets_clamped;
            c.clamps_skipped += w.clamps_skipped;
            c.ring_checks_skipped += w.ring_checks_skipped;
            for (sphere, dv) in spheres.iter_mut().zip(&worker.sphere_dv) {
                sphere.velocity += *dv;
            }
        }
    }

    /// The one-ring impulse of vertex `p` alone, outside a pass (no clamp bounds). Needs
    /// `refresh_predicted` first.
    #[cfg(test)]
    pub(crate) fn ring_impulse(
        &mut self,
        p: usize,
        h: f32,
        settings: &ImpulseSettings,
        spheres: &mut [RigidSphereState],
    ) -> ImpulseOutcome {
        let mut worker = PassWorker::for_mesh(self.mesh);
        worker.sphere_dv.resize(spheres.len(), Vec3::ZERO);
        // SAFETY: the view is used here, on this thread.
        let outcome = unsafe { self.single_view(h) }.ring_impulse(&mut worker, p, settings);
        self.finish_single(worker, spheres);
        outcome
    }

    /// The per-tet impulse of tet `t` alone, outside a pass (no clamp bounds). Needs
    /// `refresh_predicted` first.
    #[cfg(test)]
    pub(crate) fn tet_impulse(
        &mut self,
        t: usize,
        h: f32,
        settings: &ImpulseSettings,
        spheres: &mut [RigidSphereState],
    ) -> ImpulseOutcome {
        let mut worker = PassWorker::for_mesh(self.mesh);
        worker.sphere_dv.resize(spheres.len(), Vec3::ZERO);
        let (corners, rest) = (self.mesh.tets()[t], self.mesh.rest_volumes()[t]);
        // SAFETY: the view is used here, on this thread.
        let [outcome, ..] = unsafe { self.single_view(h) }.tet_bundle(
            &mut worker,
            &[t as u32],
            &[corners],
            &[rest],
            settings,
        );
        self.finish_single(worker, spheres);
        outcome
    }

    #[cfg(test)]
    fn finish_single(&mut self, worker: PassWorker, spheres: &mut [RigidSphereState]) {
        *self.counters = worker.counters;
        for (sphere, dv) in spheres.iter_mut().zip(&worker.sphere_dv) {
            sphere.velocity += *dv;
        }
    }

    /// A view for one item's impulse on this thread, outside a pass.
    ///
    /// # Safety
    /// The view is used by one thread at a time.
    #[cfg(test)]
    unsafe fn single_view(&mut self, h: f32) -> VolumePass<'_> {
        self.passes
            .clamp_motion
            .drift
            .resize(self.predicted.len(), 0.0);
        self.passes
            .clamp_motion
            .move_len
            .resize(self.predicted.len(), 0.0);
        let tets = self.mesh.tet_count();
        self.passes
            .clamp_motion
            .walked
            .0
            .resize_with(tets, || AtomicU32::new(0));
        VolumePass {
            mesh: self.mesh,
            h,
            inv_masses: self.inv_masses,
            contact_normals: self.contact_normals,
            contact_kept: self.contact_kept,
            contact_second: second_contacts(self.touching, self.contact_second),
            contact_sphere: self.contact_sphere,
            removed: unsafe { SharedSlice::new(self.soft_removed) },
            any_touching: !self.touching.is_empty(),
            // SAFETY (for the view and every `SharedSlice`): this function's caller's promise.
            bounds: unsafe { self.passes.clamp_bounds.view(ClampRegions::Rings) },
            velocities: unsafe { SharedSlice::new(self.velocities) },
            predicted: unsafe { SharedSlice::new(self.predicted) },
            scratch: unsafe { SharedSlice::new(self.per_particle) },
            drift: unsafe { SharedSlice::new(&mut self.passes.clamp_motion.drift) },
            move_len: unsafe { SharedSlice::new(&mut self.passes.clamp_motion.move_len) },
            walks: WalkMarks {
                walked: &self.passes.clamp_motion.walked.0,
                walks: &self.passes.clamp_motion.walks.0,
            },
            far: FarDriftMarks {
                marks: &self.passes.clamp_motion.far_nearby.0,
                pass: self.passes.clamp_motion.pass_number,
            },
            ring_corrected: unsafe { SharedSlice::new(&mut self.passes.ring_corrected) },
        }
    }
}

/// `second` (each particle's `contact_second`) when some particle of `touching` touches two
/// static colliders (the passes then take its pushes out of both), `None` otherwise.
fn second_contacts<'a>(touching: &[u32], second: &'a [Vec3]) -> Option<&'a [Vec3]> {
    touching
        .iter()
        .any(|&i| second[i as usize] != Vec3::ZERO)
        .then_some(second)
}

/// What bounds the drift of the particles block `task` reads: they were last moved by the
/// tasks it waits for (done by now), so those tasks' largest drift bounds them; going on from
/// earlier bounds (`carry`), so does the largest drift at the start in this block and its
/// neighbours (a block's impulses read no further).
#[inline(always)]
fn start_drift(
    workers: SharedSlice<'_, PassWorker>,
    blocks: &Blocks,
    block_drift: SharedSlice<'_, f32>,
    carry: bool,
    task: usize,
) -> f32 {
    let waits_for = &blocks.waits_for;
    let mut start_drift = 0.0f32;
    if carry {
        start_drift = block_drift.get(task);
        for &near in blocks.neighbours.row(task) {
            start_drift = larger(start_drift, block_drift.get(near as usize));
        }
    }
    for &earlier in waits_for.row(task) {
        // SAFETY: that task is done; nothing writes its worker now.
        let moved = unsafe { workers.get_mut(earlier as usize) }.max_moved;
        start_drift = larger(start_drift, moved);
    }
    start_drift
}

/// The tasks of the bounds' three chunked phases, for a body of `n` vertices and `tet_count`
/// tets whose pass has `blocks` blocks, and how many of the third phase's are the rings'
/// regions (the rest are the tets').
fn bound_chunks(
    n: usize,
    tet_count: usize,
    blocks: usize,
    clamp_regions: Option<ClampRegions>,
    plan: &BoundsPlan,
) -> (usize, [usize; 3]) {
    let fresh = clamp_regions.is_some() && !plan.carry;
    let chunks = |items: usize| {
        if fresh {
            items.div_ceil(BOUNDS_CHUNK)
        } else {
            0
        }
    };
    let ring_chunks = match clamp_regions {
        Some(ClampRegions::Rings) => chunks(n),
        _ => 0,
    };
    let tet_chunks = if plan.take_tet_regions {
        chunks(tet_count)
    } else {
        0
    };
    let shape_chunks = |items: usize| {
        if plan.shapes {
            items.div_ceil(BOUNDS_CHUNK)
        } else {
            0
        }
    };
    let third = if plan.carry {
        blocks
    } else {
        ring_chunks + tet_chunks
    };
    (
        ring_chunks,
        [
            chunks(tet_count) + shape_chunks(tet_count),
            chunks(n) + shape_chunks(n),
            third,
        ],
    )
}

/// How a pass takes its clamp bounds (see `PassBody::plan_bounds`).
#[derive(Clone, Copy)]
struct BoundsPlan {
    /// Whether the tets' regions are taken (for a per-tet pass, or to keep for one).
    take_tet_regions: bool,
    /// Whether the pass goes on from bounds taken earlier.
    carry: bool,
    /// Whether the rings' checks are answered by the bounds (a quiet body going on).
    ring_checks: bool,
    /// Whether this pass computes what the rings' checks need.
    shapes: bool,
}
