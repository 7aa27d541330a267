//! The crew: the compute pool's other threads, kept awake for the length of a step.
//!
//! A step has a parallel section in each of its stages (forces, contacts, the volume passes,
//! integration), one Bevy system each. Handed to the compute task pool as tasks, every section
//! waits for a sleeping thread to wake up and take them: about 50 microseconds on the machine
//! this was measured on, five times a step, with steps of a few hundred microseconds on two
//! threads (16 bodies on two threads were 1.25-1.55 times faster than on one). So, as physics
//! engines do with their worker threads, the plugin asks the pool's other threads to stay awake
//! through a step: at its start ([`SoftBodySystems::Prepare`](crate::SoftBodySystems)) it spawns one
//! task per other thread, a crew member, that waits for work by spinning on the [`Board`]; the
//! sections post their jobs there, the posting thread takes jobs too, and the members take the
//! rest without waking anyone. At the end of the step
//! ([`SoftBodySystems::Integrate`](crate::SoftBodySystems)) the crew is dismissed and its tasks
//! end.
//! Measured with `bench --only` on two threads, interleaved with the crew off
//! (`--threads-sleep`): 16 bodies 0.42-0.53 ms a step against 0.50-0.59, the soft cube
//! 0.47-0.48 against 0.53-0.58 (one thread: 0.81-0.86 and 0.83-0.88).
//!
//! Members leave by themselves after [`IDLE_LIMIT`] without work (a step that never reaches
//! its end costs at most that much spinning; the pool is one per process, so another app's
//! step may also dismiss them early, which costs only speed), and
//! give the pool's other tasks a turn every [`YIELD_EVERY`] of waiting, so systems running
//! beside the step still get threads. One thread of the pool is never a member: the systems of
//! the step themselves need one. Where the crew is not on duty, or another section holds the
//! board, a section's jobs go to the pool as tasks as before. Which thread runs which job never
//! changes a result (see `core::parallel`).

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, PoisonError};
use std::time::Duration;

use bevy::platform::time::Instant;

use crate::core::parallel::wait_until;

/// How long a crew member waits for work before it leaves by itself.
pub const IDLE_LIMIT: Duration = Duration::from_millis(2);

/// How long a crew member waits for work before it lets the pool run its other tasks once.
pub const YIELD_EVERY: Duration = Duration::from_micros(50);

/// A job posted on the board: a job function of the posting section and its count.
#[derive(Clone, Copy)]
struct Posting {
    /// Which posting this is (the board's count of postings).
    number: usize,
    jobs: usize,
    /// The section's job function, its lifetime erased: it lives until the section's `run`
    /// returns, which is after every member has let go of it (`Board::inside`).
    job: *const (dyn Fn(usize) + Sync + 'static),
}

// Safety: the job function is `Sync`, and only called while the posting section waits for it.
unsafe impl Send for Posting {}

/// Where sections post their jobs and crew members take them.
pub(crate) struct Board {
    /// The number of the latest posting; members watch it change.
    postings: AtomicUsize,
    /// The open posting, if any.
    posting: Mutex<Option<Posting>>,
    /// The next job of the open posting to take.
    next: AtomicUsize,
    /// Jobs of the open posting finished.
    done: AtomicUsize,
    /// Members holding the open posting: the section returns only when none does.
    inside: AtomicUsize,
    /// Whether a job of the open posting panicked on a member.
    panicked: AtomicBool,
    /// Whether a section holds the board (one at a time; others use the pool's tasks).
    held: AtomicBool,
    /// Whether a step is going on (members stay while it is).
    on_duty: AtomicBool,
    /// Members spawned and not yet gone.
    members: AtomicUsize,
    /// How long a member waits for work before it leaves ([`IDLE_LIMIT`] but in tests).
    idle_limit: Duration,
}

/// The board of the compute task pool's crew (one pool per process, so one board).
pub(crate) static BOARD: Board = Board::new(IDLE_LIMIT);

impl Board {
    const fn new(idle_limit: Duration) -> Board {
        Board {
            idle_limit,
            postings: AtomicUsize::new(0),
            posting: Mutex::new(None),
            next: AtomicUsize::new(0),
            done: AtomicUsize::new(0),
            inside: AtomicUsize::new(0),
            panicked: AtomicBool::new(false),
            held: AtomicBool::new(false),
            on_duty: AtomicBool::new(false),
            members: AtomicUsize::new(0),
        }
    }

    /// Runs `job(i)` for every `i` in `0..jobs` on this thread and the crew's, and returns
    /// when all have returned; or returns `false` at once, having run nothing, when there is no
    /// crew on duty or another section holds the board.
    pub(crate) fn run(&self, jobs: usize, job: &(dyn Fn(usize) + Sync)) -> bool {
        if !self.on_duty.load(Ordering::Acquire) || self.members.load(Ordering::Acquire) == 0 {
            return false;
        }
        if self
            .held
            .compare_exchange(false, true, Ordering::Acquire, Ordering::Relaxed)
            .is_err()
        {
            return false;
        }
        // Closes the posting, and waits for the members still holding it, however the jobs
        // end (a panic included): the job function must not outlive this call.
        struct Close<'a>(&'a Board);
        impl Drop for Close<'_> {
            fn drop(&mut self) {
                *self.0.lock() = None;
                wait_until(|| self.0.inside.load(Ordering::Acquire) == 0);
                self.0.held.store(false, Ordering::Release);
            }
        }
        let close = Close(self);
        self.next.store(0, Ordering::Relaxed);
        self.done.store(0, Ordering::Relaxed);
        self.panicked.store(false, Ordering::Relaxed);
        let number = self.postings.load(Ordering::Relaxed).wrapping_add(1);
        // SAFETY: only the lifetime changes; `Close` keeps the function from being called
        // after this returns.
        let erased = unsafe {
            std::mem::transmute::<
                *const (dyn Fn(usize) + Sync + '_),
                *const (dyn Fn(usize) + Sync + 'static),
            >(job as *const _)
        };
        *self.lock() = Some(Posting {
            number,
            jobs,
            job: erased,
        });
        self.postings.store(number, Ordering::Release);
        self.take_jobs(jobs, job);
        wait_until(|| self.done.load(Ordering::Acquire) >= jobs);
        drop(close);
        if self.panicked.load(Ordering::Acquire) {
            panic!("a soft-body job panicked on another thread");
        }
        true
    }

    /// Takes jobs of the open posting until none is left.
    fn take_jobs(&self, jobs: usize, job: &(dyn Fn(usize) + Sync)) {
        loop {
            let i = self.next.fetch_add(1, Ordering::Relaxed);
            if i >= jobs {
                return;
            }
            job(i);
            self.done.fetch_add(1, Ordering::Release);
        }
    }

    /// A member's part in posting number `number`, if it is still open: takes its jobs until
    /// none is left. Returns whether there was such a posting.
    fn serve(&self, number: usize) -> bool {
        let posting = {
            let open = self.lock();
            match *open {
                // Counted inside while the lock is held, so the section, which closes the
                // posting under the lock, then waits for this member to let go.
                Some(posting) if posting.number == number => {
                    self.inside.fetch_add(1, Ordering::AcqRel);
                    posting
                }
                _ => return false,
            }
        };
        // SAFETY: the posting section is waiting in `run` until `inside` drops back.
        let job = unsafe { &*posting.job };
        let result = catch_unwind(AssertUnwindSafe(|| self.take_jobs(posting.jobs, job)));
        if result.is_err() {
            // Counted as done so the section stops waiting; it panics in turn.
            self.panicked.store(true, Ordering::Release);
            self.done.fetch_add(posting.jobs, Ordering::Release);
        }
        self.inside.fetch_sub(1, Ordering::AcqRel);
        true
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Option<Posting>> {
        self.posting.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Puts the crew on duty and returns how many more members to spawn for `wanted` in all.
    /// The caller must spawn them (each running [`Board::member`]).
    pub(crate) fn muster(&self, wanted: usize) -> usize {
        self.on_duty.store(true, Ordering::Release);
        let mut spawn = 0;
        let _ = self
            .members
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |members| {
                spawn = wanted.saturating_sub(members);
                Some(members.max(wanted))
            });
        spawn
    }

    /// Ends the crew's duty: members leave once they see it.
    pub(crate) fn dismiss(&self) {
        self.on_duty.store(false, Ordering::Release);
    }

    /// A crew member: takes the jobs of every posting until dismissed or idle for
    /// [`IDLE_LIMIT`] (the board's idle limit), letting the pool run its other tasks every
    /// [`YIELD_EVERY`] of waiting.
    pub(crate) async fn member(&self) {
        let mut seen = self.postings.load(Ordering::Acquire).wrapping_sub(1);
        let mut idle_since = Instant::now();
        let mut last_yield = idle_since;
        let mut spins = 0u32;
        while self.on_duty.load(Ordering::Acquire) {
            let latest = self.postings.load(Ordering::Acquire);
            if latest != seen {
                seen = latest;
                if self.serve(latest) {
                    idle_since = Instant::now();
                    last_yield = idle_since;
                }
                continue;
            }
            std::hint::spin_loop();
            spins = spins.wrapping_add(1);
            if spins.is_multiple_of(64) {
                let now = Instant::now();
                if now - idle_since > self.idle_limit {
                    break;
                }
                if now - last_yield > YIELD_EVERY {
                    bevy::tasks::futures_lite::future::yield_now().await;
                    last_yield = Instant::now();
                }
            }
        }
        self.members.fetch_sub(1, Ordering::AcqRel);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicU32;

    /// A board of its own (the process's is shared by every test) with a crew of `members` on
    /// threads of their own, for `test`; dismissed afterwards, when every member has left.
    /// Members wait for work as long as the test runs: tests share two cores, and a test
    /// thread can be kept waiting longer than [`IDLE_LIMIT`], which would send them away.
    fn with_crew(members: usize, test: impl FnOnce(&'static Board)) -> &'static Board {
        let board: &'static Board = Box::leak(Box::new(Board::new(Duration::from_secs(3600))));
        std::thread::scope(|scope| {
            for _ in 0..board.muster(members) {
                scope.spawn(|| bevy::tasks::block_on(board.member()));
            }
            test(board);
            board.dismiss();
        });
        board
    }

    /// Every job of every posting runs exactly once, whoever takes it, with members joining
    /// as their threads start; a board without a crew on duty runs nothing and says so.
    #[test]
    fn every_job_runs_once_on_the_posting_thread_or_a_member() {
        let idle = Board::new(IDLE_LIMIT);
        assert!(!idle.run(3, &|_| panic!("no crew: nothing may run")));
        let board = with_crew(2, |board| {
            for round in 0..2000usize {
                let jobs = round % 7;
                let counts: Vec<AtomicU32> = (0..jobs).map(|_| AtomicU32::new(0)).collect();
                let ran = board.run(jobs, &|i| {
                    counts[i].fetch_add(1, Ordering::Relaxed);
                });
                assert!(ran, "the crew is on duty");
                assert!(counts.iter().all(|c| c.load(Ordering::Relaxed) == 1));
            }
        });
        assert_eq!(board.members.load(Ordering::Acquire), 0);
        assert!(!board.run(1, &|_| panic!("dismissed: nothing may run")));
    }

    /// A second section posting while one holds the board is refused (it then uses the
    /// pool's tasks), so sections nested in a job do not wait for the board.
    #[test]
    fn a_section_inside_a_job_is_refused_the_board() {
        with_crew(1, |board| {
            let refused = AtomicU32::new(0);
            assert!(board.run(4, &|_| {
                if !board.run(1, &|_| {}) {
                    refused.fetch_add(1, Ordering::Relaxed);
                }
            }));
            assert_eq!(refused.load(Ordering::Relaxed), 4);
        });
    }

    /// A job panicking on a member makes the posting section panic instead of waiting for
    /// it forever, and the board stays usable.
    #[test]
    fn a_panic_on_a_member_reaches_the_posting_section() {
        with_crew(1, |board| {
            let main = std::thread::current().id();
            let mut panicked = false;
            // Until a member takes the panicking job (the posting thread may take them all).
            for _ in 0..1000 {
                let result = catch_unwind(AssertUnwindSafe(|| {
                    board.run(64, &|_| {
                        if std::thread::current().id() != main {
                            panic!("a job failed");
                        }
                        std::thread::sleep(Duration::from_micros(20));
                    })
                }));
                if result.is_err() {
                    panicked = true;
                    break;
                }
            }
            assert!(panicked, "a member took a job within 1000 postings");
            assert!(board.run(2, &|_| {}));
        });
    }
}
