//! A second core from a host's thread pool (CLAP's `thread-pool` extension): the audio thread
//! posts the engine's two halves ([`Pair`]) here, asks the host to run two tasks, and the host
//! calls [`Rendezvous::exec`] twice, on its workers or one after the other on one thread.
//!
//! The engine's halves exchange forces sample by sample, so they must run at once: a host that
//! runs the tasks one after another would leave the first waiting for the second for ever. So the
//! first task to arrive waits at most [`CLAIM`] for the second; if it comes, each runs a half; if
//! not, the first gives the block up and the second, when it comes, finds nothing to do: the
//! host's request returns, [`Pair::join`] says `false`, and the engine runs the block on the
//! audio thread alone, with the same samples (the engine's result does not depend on the cores).
//! A second task that comes, too late, on the thread the first ran on shows a host running its
//! tasks one after another; after [`SERIAL_MISSES`] such blocks in a row
//! ([`Rendezvous::seems_serial`]) it is no longer asked, and the synth's helper thread, if it has
//! one, lends the core instead ([`Pair::declines`]). A worker merely late (on another thread)
//! costs that block its second core, not the pool.
//!
//! Nothing here locks, allocates or makes a system call: the jobs are handed over through one
//! atomic state word, as in [`super::helper`].

use super::helper::{post, run_job, run_posted, Job};
use crate::engine::Pair;
use std::cell::UnsafeCell;
use std::sync::atomic::{AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// How long the first task waits for the second (as [`super::helper::CLAIM`]: under 4 % of a
/// 64-frame block at 48 kHz; a host's idle worker takes a task within microseconds).
pub const CLAIM: Duration = super::helper::CLAIM;

/// Blocks in a row whose tasks the host ran one after another on one thread before
/// [`Rendezvous::seems_serial`].
pub const SERIAL_MISSES: u32 = 8;

const IDLE: u32 = 0;
const POSTED: u32 = 1;
/// One task arrived, taking job 0 or job 1.
const ONE: [u32; 2] = [2, 3];
const BOTH: u32 = 4;
const GIVEN_UP: u32 = 5;

/// The two halves of a block and who runs them (shared by the audio thread and the host's
/// workers; lives as long as the plugin instance).
pub struct Rendezvous {
    state: AtomicU32,
    /// Written by [`Rendezvous::join`] before `POSTED` (`here`, `there`); each taken by one task
    /// once the state says both have arrived.
    jobs: [UnsafeCell<Option<Job>>; 2],
    /// The thread the first task of the current block arrived on ([`this_thread`]).
    first_thread: AtomicUsize,
    /// Blocks run on two cores and blocks the host's pool missed (the audio thread's counters),
    /// and blocks in a row whose tasks came one after another on one thread (the host's).
    joined: AtomicU64,
    missed: AtomicU64,
    serial_in_a_row: AtomicU32,
}

// SAFETY: each job slot is written by `join` only while no task can read it (state `IDLE` before
// `POSTED`, and again after the host's request has returned, when every task has), and read by
// the task that the compare-exchanges on `state` (release/acquire) make its owner: the first
// arrival (`POSTED` → `ONE[j]`) takes job `j` and the second (`ONE[j]` → `BOTH`) the other, and
// only once the state is `BOTH`. The closures are `Send`.
unsafe impl Sync for Rendezvous {}
// SAFETY: as above.
unsafe impl Send for Rendezvous {}

impl Default for Rendezvous {
    fn default() -> Self {
        Rendezvous {
            state: AtomicU32::new(IDLE),
            jobs: [UnsafeCell::new(None), UnsafeCell::new(None)],
            first_thread: AtomicUsize::new(0),
            joined: AtomicU64::new(0),
            missed: AtomicU64::new(0),
            serial_in_a_row: AtomicU32::new(0),
        }
    }
}

impl std::fmt::Debug for Rendezvous {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Rendezvous")
            .field("joined", &self.joined_blocks())
            .field("missed", &self.missed_blocks())
            .finish_non_exhaustive()
    }
}

impl Rendezvous {
    /// Run `there` and `here` at once as the two tasks of `request` (which asks the host to call
    /// [`Rendezvous::exec`] twice and returns once both calls have returned, or the host refused).
    /// `true` when both ran to their end; `false` when neither ran. The tasks' meeting says which,
    /// not the host's answer: a host that ran them and answered no still had them run.
    pub fn join(
        &self,
        there: &mut (dyn FnMut() + Send),
        here: &mut (dyn FnMut() + Send),
        request: impl FnOnce(),
    ) -> bool {
        // SAFETY: the slots are this thread's while the state is `IDLE`; the pointers are
        // dropped below, before this function returns, and a task dereferences one only inside
        // `request`.
        unsafe {
            *self.jobs[0].get() = Some(post(here));
            *self.jobs[1].get() = Some(post(there));
        }
        self.state.store(POSTED, Ordering::Release);
        request();
        // Both tasks have returned (or were never called): nobody touches the slots any more.
        let state = self.state.swap(IDLE, Ordering::AcqRel);
        // SAFETY: as above.
        unsafe {
            *self.jobs[0].get() = None;
            *self.jobs[1].get() = None;
        }
        let joined = state == BOTH;
        if joined {
            self.joined.fetch_add(1, Ordering::Relaxed);
            self.serial_in_a_row.store(0, Ordering::Relaxed);
        } else {
            self.missed.fetch_add(1, Ordering::Relaxed);
        }
        joined
    }

    /// Task `task_index` of the host's pool: task 0 runs `here` and task 1 `there` of
    /// [`Rendezvous::join`], so that a host that keeps a task on one thread keeps each half's
    /// voices in one core's cache (taken in the order of arrival, one core's halves crossed over
    /// from block to block: 64 voices in the plugin's bench cost 0.72 of the block instead of
    /// 0.55 through the helper thread). Whether the two meet goes by the order of arrival.
    pub fn exec(&self, task_index: u32) {
        // The first to arrive says in the state which job it takes.
        let job = usize::from(task_index == 1);
        let first =
            self.state
                .compare_exchange(POSTED, ONE[job], Ordering::AcqRel, Ordering::Acquire);
        let mine = match first {
            Ok(_) => {
                // Wait for the second task; give the block up if it does not come in time.
                self.first_thread.store(this_thread(), Ordering::Relaxed);
                let arrived = Instant::now();
                loop {
                    match self.state.load(Ordering::Acquire) {
                        BOTH => break job,
                        _ if arrived.elapsed() > CLAIM => {
                            let gave_up = self.state.compare_exchange(
                                ONE[job],
                                GIVEN_UP,
                                Ordering::AcqRel,
                                Ordering::Acquire,
                            );
                            if gave_up.is_ok() {
                                return;
                            }
                            // The second came as time ran out: both run.
                            break job;
                        }
                        _ => std::hint::spin_loop(),
                    }
                }
            }
            Err(one) if ONE.contains(&one) => {
                let second =
                    self.state
                        .compare_exchange(one, BOTH, Ordering::AcqRel, Ordering::Acquire);
                if second.is_err() {
                    // The first gave up a moment ago: nothing to do.
                    return;
                }
                // The job the first did not take.
                usize::from(one == ONE[0])
            }
            // The block given up: by a host running the tasks one after another if this one
            // comes on the first one's thread (stored before the first's release of `GIVEN_UP`).
            Err(GIVEN_UP) => {
                if self.first_thread.load(Ordering::Relaxed) == this_thread() {
                    self.serial_in_a_row.fetch_add(1, Ordering::Relaxed);
                }
                return;
            }
            // Nothing posted, or a third task: nothing to do.
            Err(_) => return,
        };
        // SAFETY: the state is `BOTH` and the two tasks took different slots (the second the one
        // the first did not): the slot is this task's until `join` clears it after the host's
        // request returns (see `Rendezvous`).
        let job = unsafe { *self.jobs[mine].get() };
        if let Some(job) = job {
            // SAFETY: `join` keeps the closure alive and untouched until the request returns.
            unsafe { run_posted(job, run_job) };
        }
    }

    /// A new activation: the host is given its chance again ([`Rendezvous::seems_serial`]).
    pub fn start_over(&self) {
        self.serial_in_a_row.store(0, Ordering::Relaxed);
    }

    /// Blocks run on two cores.
    pub fn joined_blocks(&self) -> u64 {
        self.joined.load(Ordering::Relaxed)
    }

    /// Blocks the host's pool missed (run on the audio thread alone).
    pub fn missed_blocks(&self) -> u64 {
        self.missed.load(Ordering::Relaxed)
    }

    /// Whether the host ran the tasks of the last [`SERIAL_MISSES`] blocks it was asked for one
    /// after another on one thread: asking it again would cost [`CLAIM`] a block for nothing.
    pub fn seems_serial(&self) -> bool {
        self.serial_in_a_row.load(Ordering::Relaxed) >= SERIAL_MISSES
    }
}

/// Which thread this is: the address of a thread-local (no allocation, no system call).
fn this_thread() -> usize {
    thread_local!(static MARK: u8 = const { 0 });
    MARK.with(|m| m as *const u8 as usize)
}

/// A host's thread pool as the engine's [`Pair`]: `request` asks the host to run two tasks of
/// [`Rendezvous::exec`].
pub struct HostPool<'r, R: Fn()> {
    pub rendezvous: &'r Rendezvous,
    pub request: R,
}

impl<R: Fn()> Pair for HostPool<'_, R> {
    /// No host is asked once it seems to run its tasks one after another.
    fn join(&self, there: &mut (dyn FnMut() + Send), here: &mut (dyn FnMut() + Send)) -> bool {
        !self.declines() && self.rendezvous.join(there, here, &self.request)
    }

    fn declines(&self) -> bool {
        self.rendezvous.seems_serial()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicBool;

    /// A host that runs the two tasks one after the other on the calling thread.
    fn serial(r: &Rendezvous) -> impl Fn() + '_ {
        move || {
            r.exec(0);
            r.exec(1);
        }
    }

    #[test]
    fn a_host_running_the_tasks_one_after_another_gets_them_back() {
        let r = Rendezvous::default();
        let (mut a, mut b) = (0, 0);
        let t = Instant::now();
        // The halves wait for each other, as the engine's do: run one after the other they would
        // hang.
        let met = AtomicBool::new(false);
        let joined = r.join(
            &mut || {
                a += 1;
                met.store(true, Ordering::Release);
            },
            &mut || {
                b += 1;
                while !met.load(Ordering::Acquire) {
                    std::hint::spin_loop();
                }
            },
            serial(&r),
        );
        assert!(!joined);
        assert!(t.elapsed() >= CLAIM);
        assert_eq!((a, b), (0, 0), "neither half runs");
        assert_eq!((r.joined_blocks(), r.missed_blocks()), (0, 1));
        for _ in 1..SERIAL_MISSES {
            assert!(!r.seems_serial());
            assert!(!r.join(&mut || {}, &mut || {}, serial(&r)));
        }
        assert!(r.seems_serial());
    }

    #[test]
    fn a_host_running_them_at_once_runs_both_halves_together() {
        let r = Rendezvous::default();
        let (mut a, mut b) = (0u64, 0u64);
        let (mut joined, mut rounds) = (0, 0u32);
        let go = AtomicU32::new(0);
        let done = AtomicU32::new(0);
        let (caller, crossed) = (this_thread(), AtomicU32::new(0));
        let quit = AtomicBool::new(false);
        std::thread::scope(|s| {
            // The host's worker: takes task 1 of each request while the caller runs task 0.
            let (go, done, quit, rr) = (&go, &done, &quit, &r);
            s.spawn(move || {
                let mut seen = 0;
                while !quit.load(Ordering::Acquire) {
                    let n = go.load(Ordering::Acquire);
                    if n != seen {
                        seen = n;
                        rr.exec(1);
                        done.store(n, Ordering::Release);
                    }
                    std::hint::spin_loop();
                }
            });
            // 500 rounds, and on a machine so loaded that the worker missed every one of them
            // (it must arrive within `CLAIM`), more until one meets: at most 50 000.
            while rounds < 500 || (joined == 0 && rounds < 50_000) {
                rounds += 1;
                let round = rounds;
                let request = || {
                    go.store(round, Ordering::Release);
                    r.exec(0);
                    while done.load(Ordering::Acquire) != round {
                        std::hint::spin_loop();
                    }
                };
                // Each half waits for the other: only run at once do they finish. `here` is task
                // 0's, on this thread, whichever task arrives first.
                let (ra, rb) = (AtomicBool::new(false), AtomicBool::new(false));
                let ok = r.join(
                    &mut || {
                        a += 1;
                        crossed.fetch_add(u32::from(this_thread() == caller), Ordering::Relaxed);
                        ra.store(true, Ordering::Release);
                        while !rb.load(Ordering::Acquire) {
                            std::hint::spin_loop();
                        }
                    },
                    &mut || {
                        b += 2;
                        crossed.fetch_add(u32::from(this_thread() != caller), Ordering::Relaxed);
                        rb.store(true, Ordering::Release);
                        while !ra.load(Ordering::Acquire) {
                            std::hint::spin_loop();
                        }
                    },
                    request,
                );
                joined += u64::from(ok);
                assert_eq!((a, b), (joined, 2 * joined), "round {round}");
            }
            quit.store(true, Ordering::Release);
        });
        println!(
            "host pool with a spinning worker: {joined} of {rounds} blocks on two cores, {} missed",
            r.missed_blocks()
        );
        assert_eq!(joined, r.joined_blocks());
        assert_eq!(joined + r.missed_blocks(), u64::from(rounds));
        assert_eq!(
            crossed.load(Ordering::Relaxed),
            0,
            "task 0 runs `here`, task 1 `there`"
        );
        // How many meet depends on the scheduler (a worker descheduled past `CLAIM` misses one);
        // that they meet at all, both halves or neither, is what is checked.
        assert!(joined > 0);
    }

    #[test]
    fn a_worker_late_on_another_thread_does_not_make_the_host_serial() {
        let r = Rendezvous::default();
        let (mut a, mut b) = (0, 0);
        for _ in 0..2 * SERIAL_MISSES {
            // The second task comes after the first gave up, from another thread.
            let late = || {
                r.exec(0);
                std::thread::scope(|s| {
                    s.spawn(|| r.exec(1));
                });
            };
            assert!(!r.join(&mut || a += 1, &mut || b += 1, late));
        }
        assert_eq!((a, b), (0, 0));
        assert_eq!(r.missed_blocks(), u64::from(2 * SERIAL_MISSES));
        assert!(!r.seems_serial(), "late, not serial: still asked");
    }

    #[test]
    fn a_host_that_refuses_or_calls_late_runs_nothing() {
        let r = Rendezvous::default();
        let ran = AtomicU32::new(0);
        let run = || {
            ran.fetch_add(1, Ordering::Relaxed);
        };
        // A host that refuses: no task comes.
        assert!(!r.join(&mut || run(), &mut || run(), || {}));
        // A task called after its request has returned finds nothing.
        r.exec(0);
        r.exec(1);
        // A host that calls only one of the two.
        assert!(!r.join(&mut || run(), &mut || run(), || r.exec(1)));
        assert_eq!(ran.load(Ordering::Relaxed), 0);
        assert_eq!(r.missed_blocks(), 2);
    }
}
