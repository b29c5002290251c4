//! A change of keyboard, pool size, integrator or render mode while the plugin plays. The audio
//! thread asks the main thread (`request_callback`), which prepares the keyboard's keys on a
//! thread of its own into [`prepare`](crate::prepare)'s store while the old piano plays on; once
//! they are kept, the audio thread asks the host to restart the plugin, and the activation makes
//! its piano from them (a copy, not a build): the host never waits for the 88 keys. A pool size
//! alone needs no keys prepared, so its restart follows at once. Each request supersedes the one
//! before: a build under way for an older request is called off between two keys.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use unacorda::engine::Integrator;

/// The background build shared by an instance's threads.
#[derive(Default)]
pub struct Rebuild {
    /// A build is asked for (set by the audio thread, taken by the main thread).
    wanted: AtomicBool,
    /// The number of the latest request (the audio thread counts them; the main thread's
    /// builds read it, and one for an older request stops). Shared with the build threads.
    requested: Arc<AtomicU64>,
    /// The latest request whose build has ended, its keys kept or its failure left for the
    /// activation to report (written by the build threads, read by the audio thread).
    finished: Arc<AtomicU64>,
    /// The active processor's host rate, the bits of an `f64` (written at activation and
    /// deactivation, read by the main thread); 0 while inactive.
    rate_bits: AtomicU64,
    /// The build threads started (main thread), joined before the instance goes so that none
    /// outlives the plugin's code.
    threads: Mutex<Vec<JoinHandle<()>>>,
}

impl Rebuild {
    /// An activation at `rate_hz` (main thread): later builds are for that rate.
    pub fn activated(&self, rate_hz: f64) {
        self.rate_bits.store(rate_hz.to_bits(), Ordering::Relaxed);
    }

    /// The processor deactivated (main thread): nothing is built until the next activation,
    /// which builds what it needs itself.
    pub fn deactivated(&self) {
        self.rate_bits.store(0, Ordering::Relaxed);
    }

    /// Whether a processor is active (main thread).
    pub fn active(&self) -> bool {
        self.rate_bits.load(Ordering::Relaxed) != 0
    }

    /// Ask for a build of the current choice (audio thread; the caller then asks the host for a
    /// main-thread callback), calling off any build for an older one. Returns the request's
    /// number for [`Rebuild::finished`]. Never allocates.
    pub fn ask(&self) -> u64 {
        let request = self.call_off();
        self.wanted.store(true, Ordering::Release);
        request
    }

    /// Call off the build under way, if any: its choice was changed back (audio thread). Returns
    /// the number this makes the latest. Never allocates.
    pub fn call_off(&self) -> u64 {
        self.requested.fetch_add(1, Ordering::AcqRel) + 1
    }

    /// Whether the build of request `request` (or of a later one) has ended (audio thread).
    pub fn finished(&self, request: u64) -> bool {
        self.finished.load(Ordering::Acquire) >= request
    }

    /// Start the build asked for, if one is and a processor is active (main thread).
    pub fn start_if_wanted(&self, keyboard: &'static str, integrator: Integrator) {
        if !self.wanted.swap(false, Ordering::AcqRel) || !self.active() {
            return;
        }
        let rate_hz = f64::from_bits(self.rate_bits.load(Ordering::Relaxed));
        let request = self.requested.load(Ordering::Acquire);
        let (requested, finished) = (self.requested.clone(), self.finished.clone());
        let build = move || {
            let cancelled = || requested.load(Ordering::Acquire) != request;
            // A piano that cannot be built is reported by the activation that asks for it.
            let _ = crate::prepare::keep(keyboard, rate_hz, integrator, &cancelled);
            finished.fetch_max(request, Ordering::AcqRel);
        };
        let mut threads = self.threads.lock().unwrap_or_else(|e| e.into_inner());
        threads.retain(|t| !t.is_finished());
        match std::thread::Builder::new()
            .name("unacorda build".into())
            .spawn(build)
        {
            Ok(thread) => threads.push(thread),
            // No thread to build on: restart now and let the activation build.
            Err(_) => {
                self.finished.fetch_max(request, Ordering::AcqRel);
            }
        }
    }

    /// Call off every build under way and wait for them to stop (main thread, as the instance
    /// is destroyed).
    pub fn join(&self) {
        self.call_off();
        let threads = std::mem::take(&mut *self.threads.lock().unwrap_or_else(|e| e.into_inner()));
        for thread in threads {
            let _ = thread.join();
        }
    }
}
