//! A second core for the audio callback: a helper thread that runs one half of the live pool's
//! step while the callback runs the other ([`Pair`]).
//!
//! Nothing here locks or allocates after [`Helper::spawn`]: the job (a pointer to the caller's
//! closure) is handed over through an atomic state word, the caller wakes the helper with
//! `unpark` (a futex wake that never blocks the caller) and spins until the helper reports done.
//! After each job the helper spins for [`SPIN`] so that the next block finds it awake, then parks.

use crate::engine::exponential::Pair;
use std::cell::UnsafeCell;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long the helper stays awake after a job (a little over one 64-frame block at 48 kHz).
pub const SPIN: Duration = Duration::from_millis(2);

const IDLE: u32 = 0;
const POSTED: u32 = 1;
const DONE: u32 = 2;
const QUIT: u32 = 3;

/// The job slot and the state word that says who owns it.
struct Shared {
    state: AtomicU32,
    /// Written by the caller before `POSTED`, taken by the helper after it sees `POSTED`.
    job: UnsafeCell<Option<*mut (dyn FnMut() + Send)>>,
}

// SAFETY: `job` is touched only by the side that the `state` protocol makes its owner (the caller
// before it publishes `POSTED`, the helper between `POSTED` and `DONE`), with release/acquire
// ordering on `state`; the closure it points to is `Send`.
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
        let shared = Arc::new(Shared {
            state: AtomicU32::new(IDLE),
            job: UnsafeCell::new(None),
        });
        let theirs = shared.clone();
        let thread = std::thread::Builder::new()
            .name("unacorda-helper".into())
            .spawn(move || work(&theirs))?;
        Ok(Helper {
            shared,
            thread: Some(thread),
        })
    }
}

/// The helper's loop: wait (spinning, then parked) for a job, run it, report it done.
fn work(shared: &Shared) {
    let mut awake_since = Instant::now();
    loop {
        match shared.state.load(Ordering::Acquire) {
            QUIT => return,
            POSTED => {
                // SAFETY: `POSTED` hands the slot to this thread (see `Shared`).
                let job = unsafe { (*shared.job.get()).take() };
                if let Some(job) = job {
                    // SAFETY: the caller of `join` keeps the closure alive and untouched until it
                    // sees `DONE`; a panic is caught so that `DONE` is always reported.
                    let run = std::panic::AssertUnwindSafe(|| unsafe { (*job)() });
                    // SAFETY: flush-to-zero and denormals-are-zero for the job, as on the audio
                    // thread (the guard restores MXCSR).
                    let _ = unsafe { no_denormals::no_denormals(|| std::panic::catch_unwind(run)) };
                }
                shared.state.store(DONE, Ordering::Release);
                awake_since = Instant::now();
            }
            _ if awake_since.elapsed() < SPIN => std::hint::spin_loop(),
            _ => std::thread::park(),
        }
    }
}

impl Pair for Helper {
    fn join(&self, there: &mut (dyn FnMut() + Send), here: &mut dyn FnMut()) {
        let Some(thread) = &self.thread else {
            there();
            here();
            return;
        };
        let job: *mut (dyn FnMut() + Send + '_) = there;
        // SAFETY: only the lifetime is erased; this function does not return (or unwind) before
        // the helper reports `DONE`, after which it never touches the closure again.
        let job: *mut (dyn FnMut() + Send + 'static) = unsafe { std::mem::transmute(job) };
        // SAFETY: the slot is this thread's while the state is not `POSTED`.
        unsafe { *self.shared.job.get() = Some(job) };
        self.shared.state.store(POSTED, Ordering::Release);
        thread.thread().unpark();
        let mine = std::panic::catch_unwind(std::panic::AssertUnwindSafe(here));
        while self.shared.state.load(Ordering::Acquire) != DONE {
            std::hint::spin_loop();
        }
        self.shared.state.store(IDLE, Ordering::Relaxed);
        if let Err(e) = mine {
            std::panic::resume_unwind(e);
        }
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
    fn both_jobs_run_and_the_borrow_is_released() {
        let helper = Helper::spawn().unwrap();
        let (mut a, mut b) = (0u64, 0u64);
        for round in 1..=1000 {
            helper.join(&mut || a += 1, &mut || b += 2);
            assert_eq!((a, b), (round, 2 * round));
        }
    }

    #[test]
    fn a_panic_on_the_helper_does_not_hang_the_caller() {
        let helper = Helper::spawn().unwrap();
        let mut ran = false;
        helper.join(&mut || panic!("helper job"), &mut || ran = true);
        assert!(ran);
        let mut after = 0;
        helper.join(&mut || after += 1, &mut || {});
        assert_eq!(after, 1);
    }
}
