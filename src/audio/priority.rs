//! Real-time priority for the threads that make the sound — the audio callback's and the helper's:
//! `SCHED_FIFO` where the system allows it (root, `CAP_SYS_NICE` or an `RLIMIT_RTPRIO` above zero;
//! elsewhere the platform's highest priority), so that other work cannot preempt a block half
//! done. Asked once by each thread for itself; what it was granted is kept for the front end to
//! report. Where it is refused the thread runs at normal priority.

use std::cell::Cell;
use std::sync::atomic::{AtomicI32, Ordering};

/// The priority asked for, on `thread_priority`'s 0–100 scale (mapped into `SCHED_FIFO`'s range:
/// above most of the system, below the kernel's own real-time threads).
const PRIORITY: u8 = 70;

/// What a thread was granted: not asked yet, granted, or refused with the OS error's number
/// (touched by the thread that asks and read by the one that reports).
#[derive(Debug)]
pub struct Promotion(AtomicI32);

const UNASKED: i32 = i32::MIN;
const GRANTED: i32 = 0;
/// Refused without an OS error number.
const REFUSED: i32 = -1;

impl Default for Promotion {
    fn default() -> Promotion {
        Promotion(AtomicI32::new(UNASKED))
    }
}

thread_local! {
    /// Whether this thread has asked (a reopened device's stream has a new callback thread).
    static ASKED: Cell<bool> = const { Cell::new(false) };
}

impl Promotion {
    /// Ask real-time priority for the calling thread (a few system calls, no allocation), once
    /// per thread; the record keeps the last outcome.
    pub fn ask(&self) {
        if !ASKED.get() {
            ASKED.set(true);
            self.0.store(promote_current_thread(), Ordering::Relaxed);
        }
    }

    /// Take what another thread's record says (relaxed; no allocation).
    pub fn copy_from(&self, other: &Promotion) {
        self.0
            .store(other.0.load(Ordering::Relaxed), Ordering::Relaxed);
    }

    /// Whether it was asked and granted (relaxed; no allocation).
    pub fn granted(&self) -> bool {
        self.0.load(Ordering::Relaxed) == GRANTED
    }

    /// `None` until asked; then `Ok` or the reason it was refused.
    pub fn outcome(&self) -> Option<Result<(), String>> {
        match self.0.load(Ordering::Relaxed) {
            UNASKED => None,
            GRANTED => Some(Ok(())),
            REFUSED => Some(Err("refused".into())),
            errno => Some(Err(format!(
                "{} (give the user a real-time limit, e.g. `@audio - rtprio 95` in /etc/security/limits.conf)",
                std::io::Error::from_raw_os_error(errno)
            ))),
        }
    }
}

#[cfg(unix)]
fn promote_current_thread() -> i32 {
    use thread_priority::unix::{
        set_thread_priority_and_policy, thread_native_id, RealtimeThreadSchedulePolicy,
        ThreadSchedulePolicy,
    };
    use thread_priority::{Error, ThreadPriority, ThreadPriorityValue};
    let Ok(value) = ThreadPriorityValue::try_from(PRIORITY) else {
        return REFUSED;
    };
    let policy = ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo);
    match set_thread_priority_and_policy(
        thread_native_id(),
        ThreadPriority::Crossplatform(value),
        policy,
    ) {
        Ok(()) => GRANTED,
        Err(Error::OS(errno)) if errno > 0 => errno,
        Err(_) => REFUSED,
    }
}

#[cfg(not(unix))]
fn promote_current_thread() -> i32 {
    match thread_priority::set_current_thread_priority(thread_priority::ThreadPriority::Max) {
        Ok(()) => GRANTED,
        Err(_) => REFUSED,
    }
}
