//! Running the jobs of one stage on several threads without changing its result.
//!
//! The volume passes are Gauss-Seidel sweeps: each impulse sees the ones before it. They run in
//! the blocks of the mesh's [`Blocks`](super::tet_mesh::Blocks), in the blocks' order, each
//! block's items in index order; a block waits only for the earlier blocks it shares particles
//! with, so blocks that share none run at the same time, and the result is the same bit for bit
//! on one thread or many (`run_phases`). The core spawns no threads: the caller passes a
//! [`Parallel`] (the plugin's runs jobs on Bevy's compute task pool).

use std::marker::PhantomData;
use std::sync::atomic::{AtomicBool, Ordering};

use super::lanes::{LANES, Point4, Vec3x4};

/// Something that runs independent jobs, possibly on several threads.
pub trait Parallel: Sync {
    /// Calls `job(i)` once for every `i` in `0..jobs`, in any order, on any threads, and
    /// returns when all have returned.
    fn run(&self, jobs: usize, job: &(dyn Fn(usize) + Sync));

    /// How many jobs can run at the same time: the most worth asking `run` for.
    fn threads(&self) -> usize;
}

/// Runs the jobs one after another on the calling thread.
#[derive(Clone, Copy, Debug, Default)]
pub struct Serial;

impl Parallel for Serial {
    fn run(&self, jobs: usize, job: &(dyn Fn(usize) + Sync)) {
        for i in 0..jobs {
            job(i);
        }
    }

    fn threads(&self) -> usize {
        1
    }
}

/// A slice that jobs running at the same time may write, each at indices no other running job
/// reads or writes. Bounds are checked; that no two jobs touch the same element is promised by
/// whoever creates it ([`SharedSlice::new`] is `unsafe`), and kept by the blocks (see
/// [`Blocks`](super::tet_mesh::Blocks) and its test) or by jobs that own their indices.
pub(crate) struct SharedSlice<'a, T> {
    ptr: *mut T,
    len: usize,
    _borrow: PhantomData<&'a mut [T]>,
}

// SAFETY: elements are only reached through `get`/`set`/`get_mut`, and the creator of the
// slice promised (`SharedSlice::new`) that no element is written by one thread while another
// reads or writes it.
unsafe impl<T: Send> Send for SharedSlice<'_, T> {}
unsafe impl<T: Send> Sync for SharedSlice<'_, T> {}

impl<T> Clone for SharedSlice<'_, T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for SharedSlice<'_, T> {}

impl<'a, T> SharedSlice<'a, T> {
    /// Shares `slice` for the lifetime of the borrow.
    ///
    /// # Safety
    /// As long as this slice or a copy of it lives, no element may be written (through `set`
    /// or `get_mut`) by one thread while another thread reads or writes it: the jobs that
    /// share it must split its indices between them, or order their accesses (the blocks'
    /// `waits_for`, a phase's end).
    pub(crate) unsafe fn new(slice: &'a mut [T]) -> Self {
        SharedSlice {
            ptr: slice.as_mut_ptr(),
            len: slice.len(),
            _borrow: PhantomData,
        }
    }

    /// Element `i`, for one job's own data (its index is its own).
    ///
    /// # Safety
    /// No other job may touch element `i` while the returned reference lives.
    #[inline(always)]
    #[allow(clippy::mut_from_ref)]
    pub(crate) unsafe fn get_mut(&self, i: usize) -> &mut T {
        assert!(i < self.len);
        unsafe { &mut *self.ptr.add(i) }
    }
}

impl<T: Copy> SharedSlice<'_, T> {
    /// Element `i`.
    #[inline(always)]
    pub(crate) fn get(&self, i: usize) -> T {
        assert!(i < self.len);
        // SAFETY: in bounds; no other job writes element `i` now (the promise of `new`).
        unsafe { *self.ptr.add(i) }
    }

    /// Sets element `i`.
    #[inline(always)]
    pub(crate) fn set(&self, i: usize, value: T) {
        assert!(i < self.len);
        // SAFETY: in bounds; no other job reads or writes element `i` now (the promise of
        // `new`).
        unsafe { *self.ptr.add(i) = value }
    }
}

impl SharedSlice<'_, Point4> {
    /// The points at `at` in lanes ([`Vec3x4::gather_points`]), each read as `get` reads it.
    #[inline(always)]
    pub(crate) fn gather(&self, at: [usize; LANES]) -> Vec3x4 {
        Vec3x4::from_rows(at.map(|i| self.get(i).row()))
    }
}

/// Runs `job` on every item of `items` (each a body), one item per job of `parallel`.
pub(crate) fn for_each_mut<T: Send>(
    items: &mut [T],
    parallel: &dyn Parallel,
    job: &(dyn Fn(&mut T) + Sync),
) {
    let count = items.len();
    // SAFETY: each job reaches its own item alone.
    let shared = unsafe { SharedSlice::new(items) };
    parallel.run(count, &|i| job(unsafe { shared.get_mut(i) }));
}

/// One flag per block: whether its job in the running pass is done. A clone has its own flags
/// (all clear), so clones of a body can step at the same time.
#[derive(Debug, Default)]
pub(crate) struct BlockFlags(Box<[AtomicBool]>);

impl BlockFlags {
    /// `count` clear flags.
    pub(crate) fn new(count: usize) -> BlockFlags {
        BlockFlags((0..count).map(|_| AtomicBool::new(false)).collect())
    }
}

impl Clone for BlockFlags {
    fn clone(&self) -> BlockFlags {
        BlockFlags::new(self.0.len())
    }
}

impl std::ops::Deref for BlockFlags {
    type Target = [AtomicBool];
    fn deref(&self) -> &[AtomicBool] {
        &self.0
    }
}

/// Waits until `flag` is set by another thread.
pub(crate) fn wait_for(flag: &AtomicBool) {
    wait_until(|| flag.load(Ordering::Acquire));
}

/// Waits until `ready` holds, spinning first: blocks take well under a millisecond, less than
/// a thread takes to be woken.
pub(crate) fn wait_until(ready: impl Fn() -> bool) {
    let mut spins = 0u32;
    while !ready() {
        if spins < 1 << 14 {
            std::hint::spin_loop();
            spins += 1;
        } else {
            std::thread::yield_now();
        }
    }
}

/// One phase of [`run_phases`].
pub(crate) struct Phase<'a> {
    /// Its number of tasks.
    pub(crate) tasks: usize,
    /// For a phase over the mesh's blocks: each task's earlier tasks in the phase, which it
    /// waits for ([`Blocks::waits_for`](super::tet_mesh::Blocks)), and one flag per task.
    pub(crate) order: Option<(&'a super::tet_mesh::Csr, &'a [AtomicBool])>,
}

/// Runs `job(phase, task)` for every task of every phase on the threads of `parallel`, with
/// the result of running them one after another: a task starts once every task of the earlier
/// phases is done and, in an ordered phase, the tasks it waits for. Threads take tasks in order
/// as they come free and only ever wait for tasks that running threads have taken, so any
/// number of threads, one included, finishes.
pub(crate) fn run_phases(
    parallel: &dyn Parallel,
    phases: &[Phase],
    job: &(dyn Fn(usize, usize) + Sync),
) {
    for phase in phases {
        if let Some((_, done)) = phase.order {
            for flag in &done[..phase.tasks] {
                flag.store(false, Ordering::Relaxed);
            }
        }
    }
    let total: usize = phases.iter().map(|p| p.tasks).sum();
    let next = std::sync::atomic::AtomicUsize::new(0);
    // Tasks finished, all phases together. No task of a phase finishes before every task of
    // the phases before it, so this reaching the number of tasks before a phase means that
    // all of those are done.
    let finished = std::sync::atomic::AtomicUsize::new(0);
    let run = |_thread: usize| {
        loop {
            let mut task = next.fetch_add(1, Ordering::Relaxed);
            if task >= total {
                return;
            }
            let (mut phase, mut before) = (0, 0);
            while task >= phases[phase].tasks {
                task -= phases[phase].tasks;
                before += phases[phase].tasks;
                phase += 1;
            }
            if finished.load(Ordering::Acquire) < before {
                wait_until(|| finished.load(Ordering::Acquire) >= before);
            }
            if let Some((waits_for, done)) = phases[phase].order {
                for &earlier in waits_for.row(task) {
                    wait_for(&done[earlier as usize]);
                }
                job(phase, task);
                done[task].store(true, Ordering::Release);
            } else {
                job(phase, task);
            }
            finished.fetch_add(1, Ordering::Release);
        }
    };
    parallel.run(parallel.threads().clamp(1, total.max(1)), &run);
}

/// Runs each job on its own thread: for tests that results do not depend on the threads.
#[cfg(test)]
pub(crate) struct Threads;

#[cfg(test)]
impl Parallel for Threads {
    fn run(&self, jobs: usize, job: &(dyn Fn(usize) + Sync)) {
        std::thread::scope(|scope| {
            for i in 0..jobs {
                scope.spawn(move || job(i));
            }
        });
    }

    fn threads(&self) -> usize {
        4
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_phase_starts_after_every_earlier_phase_even_past_an_empty_one() {
        for parallel in [&Threads as &dyn Parallel, &Serial] {
            let written: Vec<AtomicBool> = (0..8).map(|_| AtomicBool::new(false)).collect();
            let early = std::sync::atomic::AtomicUsize::new(0);
            let phases = [
                Phase {
                    tasks: 8,
                    order: None,
                },
                Phase {
                    tasks: 0,
                    order: None,
                },
                Phase {
                    tasks: 8,
                    order: None,
                },
            ];
            run_phases(parallel, &phases, &|phase, task| {
                if phase == 0 {
                    std::thread::sleep(std::time::Duration::from_millis(2 * task as u64));
                    written[task].store(true, Ordering::Release);
                } else if written.iter().any(|w| !w.load(Ordering::Acquire)) {
                    early.fetch_add(1, Ordering::Relaxed);
                }
            });
            assert_eq!(early.load(Ordering::Relaxed), 0);
        }
    }
}
