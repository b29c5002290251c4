//! A change of keyboard, pool size or integrator while the plugin plays. The audio thread asks
//! the main thread (`request_callback`), which builds the new piano on a thread of its own into
//! [`prepare`](crate::prepare)'s cache while the old piano plays on; once it is kept, the audio
//! thread asks the host to restart the plugin, and the activation finds it there (a clone, not a
//! build): the host never waits for the 88 keys.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use unacorda::engine::Integrator;

/// The background build shared by an instance's threads.
#[derive(Default)]
pub struct Rebuild {
    /// A build is asked for (set by the audio thread, taken by the main thread).
    wanted: AtomicBool,
    /// The active processor's host rate, the bits of an `f64` (written at activation and
    /// deactivation, read by the main thread); 0 while inactive.
    rate_bits: AtomicU64,
    /// A build finished, its piano kept or its failure left for the activation to report (set by
    /// the build thread, taken by the audio thread).
    done: Arc<AtomicBool>,
    /// The build threads started (main thread), joined before the instance goes so that none
    /// outlives the plugin's code.
    threads: Mutex<Vec<JoinHandle<()>>>,
}

impl Rebuild {
    /// An activation at `rate_hz` (main thread): later builds are for that rate; a build
    /// finished for an earlier activation no longer counts.
    pub fn activated(&self, rate_hz: f64) {
        self.rate_bits.store(rate_hz.to_bits(), Ordering::Relaxed);
        self.done.store(false, Ordering::Release);
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

    /// Ask for a build of the parameters' current keyboard and pool size (audio thread; the
    /// caller then asks the host for a main-thread callback). Never allocates.
    pub fn ask(&self) {
        self.wanted.store(true, Ordering::Release);
    }

    /// Whether a build finished since the last call (audio thread). Never allocates.
    pub fn take_done(&self) -> bool {
        self.done.swap(false, Ordering::AcqRel)
    }

    /// Start the build asked for, if one is and a processor is active (main thread).
    pub fn start_if_wanted(&self, keyboard: &'static str, voices: usize, integrator: Integrator) {
        if !self.wanted.swap(false, Ordering::AcqRel) || !self.active() {
            return;
        }
        let rate_hz = f64::from_bits(self.rate_bits.load(Ordering::Relaxed));
        let done = self.done.clone();
        let build = move || {
            // A piano that cannot be built is reported by the activation that asks for it.
            let _ = crate::prepare::keep(keyboard, rate_hz, voices, integrator);
            done.store(true, Ordering::Release);
        };
        let mut threads = self.threads.lock().unwrap_or_else(|e| e.into_inner());
        threads.retain(|t| !t.is_finished());
        match std::thread::Builder::new()
            .name("unacorda build".into())
            .spawn(build)
        {
            Ok(thread) => threads.push(thread),
            // No thread to build on: restart now and let the activation build.
            Err(_) => self.done.store(true, Ordering::Release),
        }
    }

    /// Wait for every build under way (main thread, as the instance is destroyed).
    pub fn join(&self) {
        let threads = std::mem::take(&mut *self.threads.lock().unwrap_or_else(|e| e.into_inner()));
        for thread in threads {
            let _ = thread.join();
        }
    }
}
