//! A second core for the audio callback: a helper thread that runs one half of the exact pool's
//! block passes and steps while the callback runs the other ([`Pair`]).
//!
//! Nothing here locks or allocates after [`Helper::spawn`]: the job (a pointer to the caller's
//! closure) is handed over through an atomic state word, the caller wakes the helper with
//! `unpark` (a futex wake that never blocks the caller) and spins until the helper reports done.
//! After each job the helper spins for [`SPIN`] so that the next block finds it awake, then parks;
//! at real-time priority it first sleeps [`REST`] after each callback (never past [`EARLY`] before
//! the next: [`Helper::rest_until`]), so that its spinning does not use up the real-time budget
//! the kernel allows a core (95 % of each second by default: a helper that spun through every
//! callback's idle time was throttled for 50 ms a second).
//! A helper that has not taken the job within [`CLAIM`] (descheduled, or slow to wake) loses it:
//! the caller takes it back and [`Pair::join`] says so, so the engine runs the block on one core
//! instead of waiting for a thread it does not control.

use super::priority::Promotion;
use crate::engine::Pair;
use std::cell::UnsafeCell;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long the helper stays awake after a job (a little over one 64-frame block at 48 kHz).
pub const SPIN: Duration = Duration::from_millis(2);

/// How long before the next callback a resting helper wakes and spins (its wake-up, a timer on an
/// idle core, takes tens of microseconds on a virtual machine, and a virtual core idle for long
/// comes back slow: sleeping until 150 us before each callback made the median 64-voice block
/// 0.55–0.9 ms on a 2-core VM).
pub const EARLY: Duration = Duration::from_micros(400);

/// The longest single rest (the helper then looks again, and rests again until [`EARLY`] before
/// the next callback). The kernel throttles a core's real-time threads that run more than 95 % of
/// a second (for the remaining 50 ms), so the helper must be idle more than 5 % of each 1.33-ms
/// block (67 us). On a 2-core VM, 64 voices paced at 48 kHz: with rests of 200 us the median
/// block took 0.42–0.53 ms and p99.9 0.59–0.64 × the deadline in five runs; never resting, the
/// helper was throttled about once a second and 40 blocks in a row ran slow.
pub const REST: Duration = Duration::from_micros(200);

/// How long the caller waits for the helper to take a job before taking it back (under 4 % of a
/// 64-frame block at 48 kHz; a spinning helper takes it within a microsecond).
pub const CLAIM: Duration = Duration::from_micros(50);

/// What the helper runs each job inside: [`run_job`] as it is, or a harness around it (the
/// tests run the helper's half under the allocation checker).
pub type JobWrapper = fn(&mut dyn FnMut());

/// A job as it is.
pub fn run_job(job: &mut dyn FnMut()) {
    job()
}

/// A job posted to another thread: a closure whose lifetime is erased ([`post`]).
pub(super) type Job = *mut (dyn FnMut() + Send);

/// `job` as a [`Job`] another thread may run.
///
/// # Safety
/// Only the lifetime is erased: the poster must keep the closure alive and untouched until the
/// other thread has finished with it, and not return (or unwind) before that.
pub(super) unsafe fn post(job: &mut (dyn FnMut() + Send)) -> Job {
    let job: *mut (dyn FnMut() + Send + '_) = job;
    // SAFETY: the same pointer, its lifetime the caller's to keep (above).
    unsafe { std::mem::transmute(job) }
}

/// Run a posted job on this thread inside `wrap`, as the audio thread runs its own part:
/// flush-to-zero and denormals-are-zero (the guard restores MXCSR), and a panic caught — it must
/// not cross a thread that is not the caller's; the engine's halves catch their own and tell the
/// other half to stop waiting.
///
/// # Safety
/// `job` is alive and this thread's alone until this returns ([`post`]).
pub(super) unsafe fn run_posted(job: Job, wrap: JobWrapper) {
    // SAFETY: as the caller promises.
    let run = std::panic::AssertUnwindSafe(|| wrap(&mut || unsafe { (*job)() }));
    // SAFETY: the guard restores the caller's MXCSR.
    let _ = unsafe { no_denormals::no_denormals(|| std::panic::catch_unwind(run)) };
}

const IDLE: u32 = 0;
const POSTED: u32 = 1;
const DONE: u32 = 2;
const QUIT: u32 = 3;
const TAKEN: u32 = 4;

/// The job slot and the state word that says who owns it.
struct Shared {
    state: AtomicU32,
    /// Jobs run on both cores, and jobs the helper did not take in time.
    joined: AtomicU64,
    late: AtomicU64,
    /// Written by the caller before `POSTED`, taken by the helper after it sees `POSTED`.
    job: UnsafeCell<Option<Job>>,
    /// Whether the helper should ask for real-time priority (set by its owner), and what it got.
    wanted: AtomicBool,
    priority: Promotion,
    /// When the next job is expected (ns after `epoch`; 0: not known), set by the caller.
    next_job_ns: AtomicU64,
    epoch: Instant,
}

// SAFETY: `job` is touched only by the side that the `state` protocol makes its owner (the caller
// before it publishes `POSTED` and after it takes a `POSTED` job back, the helper once it has
// moved `POSTED` to `TAKEN` and until `DONE`), with release/acquire ordering on `state` and a
// compare-exchange deciding who gets a posted job; the closure it points to is `Send`.
unsafe impl Sync for Shared {}
// SAFETY: as above.
unsafe impl Send for Shared {}

/// The helper thread; dropping it stops and joins the thread.
pub struct Helper {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for Helper {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Helper").finish_non_exhaustive()
    }
}

impl Helper {
    /// Start the helper thread.
    pub fn spawn() -> std::io::Result<Helper> {
        Helper::spawn_with(run_job)
    }

    /// Start the helper thread, running each job inside `wrap`.
    pub fn spawn_with(wrap: JobWrapper) -> std::io::Result<Helper> {
        let shared = Arc::new(Shared {
            state: AtomicU32::new(IDLE),
            joined: AtomicU64::new(0),
            late: AtomicU64::new(0),
            job: UnsafeCell::new(None),
            wanted: AtomicBool::new(false),
            priority: Promotion::default(),
            next_job_ns: AtomicU64::new(0),
            epoch: Instant::now(),
        });
        let theirs = shared.clone();
        let thread = std::thread::Builder::new()
            .name("unacorda-helper".into())
            .spawn(move || work(&theirs, wrap))?;
        Ok(Helper {
            shared,
            thread: Some(thread),
        })
    }

    /// Jobs the helper did not take within [`CLAIM`] (each ran on the caller's core alone).
    pub fn late_jobs(&self) -> u64 {
        self.shared.late.load(Ordering::Relaxed)
    }

    /// Jobs run on both cores.
    pub fn joined_jobs(&self) -> u64 {
        self.shared.joined.load(Ordering::Relaxed)
    }

    /// Have the helper thread ask for real-time priority (before its next job, once).
    pub fn ask_real_time_priority(&self) {
        self.shared.wanted.store(true, Ordering::Relaxed);
        if let Some(thread) = &self.thread {
            thread.thread().unpark();
        }
    }

    /// No job is expected before `at` (the next callback): a helper at real-time priority sleeps
    /// until [`EARLY`] before it instead of spinning (no allocation, no system call).
    pub fn rest_until(&self, at: Instant) {
        let ns = at.saturating_duration_since(self.shared.epoch).as_nanos();
        self.shared
            .next_job_ns
            .store(u64::try_from(ns).unwrap_or(u64::MAX), Ordering::Relaxed);
    }

    /// The helper thread's real-time priority.
    pub fn promotion(&self) -> &Promotion {
        &self.shared.priority
    }
}

/// The helper's loop: wait (spinning, then parked) for a job, run it inside `wrap`, report it
/// done.
fn work(shared: &Shared, wrap: JobWrapper) {
    let mut awake_since = Instant::now();
    loop {
        if shared.wanted.load(Ordering::Relaxed) {
            shared.priority.ask();
        }
        match shared.state.load(Ordering::Acquire) {
            QUIT => return,
            POSTED => {
                let claim = shared.state.compare_exchange(
                    POSTED,
                    TAKEN,
                    Ordering::Acquire,
                    Ordering::Relaxed,
                );
                if claim.is_err() {
                    // The caller took the job back.
                    continue;
                }
                // SAFETY: `TAKEN` hands the slot to this thread (see `Shared`).
                let job = unsafe { (*shared.job.get()).take() };
                if let Some(job) = job {
                    // SAFETY: the caller of `join` keeps the closure alive and untouched until it
                    // sees `DONE`; a panic is caught so that `DONE` is always reported.
                    unsafe { run_posted(job, wrap) };
                }
                shared.state.store(DONE, Ordering::Release);
                awake_since = Instant::now();
            }
            _ => match rest(shared) {
                Some(rest) => {
                    std::thread::park_timeout(rest);
                    awake_since = Instant::now();
                }
                None if awake_since.elapsed() < SPIN => std::hint::spin_loop(),
                None => {
                    std::thread::park();
                    // Woken for a job, or spuriously: stay awake for the next one either way (a
                    // job taken back while this thread woke is posted again a block later).
                    awake_since = Instant::now();
                }
            },
        }
    }
}

/// How long to sleep now ([`rest_for`]) where the next job's time is known and the helper runs
/// at real-time priority (else it spins, then parks).
fn rest(shared: &Shared) -> Option<Duration> {
    if !shared.priority.granted() {
        return None;
    }
    let next_ns = shared.next_job_ns.load(Ordering::Relaxed);
    let next = shared.epoch + Duration::from_nanos(next_ns);
    rest_for(Instant::now(), next)
}

/// At `now`, with the next job due at `next`: [`REST`] at most, and never past [`EARLY`] before
/// `next`.
fn rest_for(now: Instant, next: Instant) -> Option<Duration> {
    let wake = next.checked_sub(EARLY)?;
    (wake > now).then(|| (wake - now).min(REST))
}

impl Pair for Helper {
    fn join(&self, there: &mut (dyn FnMut() + Send), here: &mut (dyn FnMut() + Send)) -> bool {
        let Some(thread) = &self.thread else {
            return false;
        };
        // SAFETY: this function does not return (or unwind) before the helper reports `DONE`,
        // after which it never touches the closure again.
        let job = unsafe { post(there) };
        // SAFETY: the slot is this thread's while the state is not `POSTED`.
        unsafe { *self.shared.job.get() = Some(job) };
        self.shared.state.store(POSTED, Ordering::Release);
        thread.thread().unpark();
        // `here` may wait for `there`: start it only once the helper has taken the job.
        let posted = Instant::now();
        while self.shared.state.load(Ordering::Acquire) == POSTED {
            if posted.elapsed() > CLAIM {
                let back = self.shared.state.compare_exchange(
                    POSTED,
                    IDLE,
                    Ordering::Acquire,
                    Ordering::Relaxed,
                );
                if back.is_ok() {
                    // SAFETY: the job was taken back before the helper claimed it: the slot is
                    // this thread's again, and the helper never saw the closure.
                    unsafe { *self.shared.job.get() = None };
                    self.shared.late.fetch_add(1, Ordering::Relaxed);
                    return false;
                }
            }
            std::hint::spin_loop();
        }
        let mine = std::panic::catch_unwind(std::panic::AssertUnwindSafe(here));
        while self.shared.state.load(Ordering::Acquire) != DONE {
            std::hint::spin_loop();
        }
        self.shared.state.store(IDLE, Ordering::Relaxed);
        self.shared.joined.fetch_add(1, Ordering::Relaxed);
        if let Err(e) = mine {
            std::panic::resume_unwind(e);
        }
        true
    }
}

impl Drop for Helper {
    fn drop(&mut self) {
        self.shared.state.store(QUIT, Ordering::Release);
        if let Some(thread) = self.thread.take() {
            thread.thread().unpark();
            let _ = thread.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rest_ends_early_before_the_next_job_and_is_short() {
        let now = Instant::now();
        let us = Duration::from_micros;
        assert_eq!(rest_for(now, now + us(1333)), Some(REST));
        assert_eq!(rest_for(now, now + EARLY + us(50)), Some(us(50)));
        assert_eq!(rest_for(now, now + EARLY), None);
        assert_eq!(rest_for(now, now), None, "a job due now: spin");
        assert_eq!(rest_for(now + us(10), now), None, "a job overdue: spin");
    }

    #[test]
    fn both_jobs_run_and_the_borrow_is_released() {
        let helper = Helper::spawn().unwrap();
        let (mut a, mut b) = (0u64, 0u64);
        let mut joined = 0;
        for round in 1..=1000 {
            if helper.join(&mut || a += 1, &mut || b += 2) {
                joined += 1;
            }
            // Both ran, or (the helper late) neither.
            assert_eq!((a, b), (joined, 2 * joined), "round {round}");
        }
        assert_eq!(joined, helper.joined_jobs());
        assert_eq!(joined + helper.late_jobs(), 1000);
        assert!(joined > 0);
    }

    #[test]
    fn a_helper_that_never_starts_loses_the_job() {
        let helper = Helper::spawn().unwrap();
        // Stop the helper thread, then post as if it were there: nobody takes the job.
        helper.shared.state.store(QUIT, Ordering::Release);
        let thread = helper.thread.as_ref().unwrap();
        thread.thread().unpark();
        while !thread.is_finished() {
            std::thread::yield_now();
        }
        helper.shared.state.store(IDLE, Ordering::Release);
        let (mut a, mut b) = (0, 0);
        let t = Instant::now();
        assert!(!helper.join(&mut || a += 1, &mut || b += 1));
        assert!(t.elapsed() >= CLAIM);
        assert_eq!((a, b), (0, 0), "neither job runs when the helper is late");
        assert_eq!(helper.late_jobs(), 1);
    }

    #[test]
    fn a_panic_on_the_helper_does_not_hang_the_caller() {
        let helper = Helper::spawn().unwrap();
        let mut ran = false;
        // (A helper still starting loses the job: ask again.)
        while !helper.join(&mut || panic!("helper job"), &mut || ran = true) {}
        assert!(ran);
        let mut after = 0;
        while !helper.join(&mut || after += 1, &mut || {}) {}
        assert_eq!(after, 1);
    }
}
