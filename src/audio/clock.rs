//! The engine's frame clock, shared by the audio thread (which publishes it) and the threads that
//! stamp events with the frame they should sound at.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// The engine's frame clock as last published by the audio thread, so that other threads can
/// stamp events with the frame at which they should sound. A sequence lock: the audio thread
/// never waits, readers retry.
#[derive(Debug)]
pub struct Clock {
    seq: AtomicU64,
    frame: AtomicU64,
    at_ns: AtomicU64,
    block: AtomicU64,
    origin: Instant,
    rate_hz: f64,
}

impl Clock {
    /// The output rate the clock counts frames at (Hz).
    pub fn rate_hz(&self) -> f64 {
        self.rate_hz
    }

    pub fn new(rate_hz: f64) -> Clock {
        Clock {
            seq: AtomicU64::new(0),
            frame: AtomicU64::new(0),
            at_ns: AtomicU64::new(0),
            block: AtomicU64::new(0),
            origin: Instant::now(),
            rate_hz,
        }
    }

    /// Called by the audio thread at the start of each block of `block` frames.
    pub(super) fn publish(&self, frame: u64, now: Instant, block: u64) {
        let ns = now.saturating_duration_since(self.origin).as_nanos() as u64;
        self.seq.fetch_add(1, Ordering::AcqRel);
        self.frame.store(frame, Ordering::Release);
        self.at_ns.store(ns, Ordering::Release);
        self.block.store(block, Ordering::Release);
        self.seq.fetch_add(1, Ordering::AcqRel);
    }

    /// The frame at which an event arriving at `now` should sound: the frame being played,
    /// extrapolated from the last block start, plus one block. Stamping live events this way
    /// turns the callback's jitter into a constant delay of one block.
    pub fn frame_at(&self, now: Instant) -> u64 {
        loop {
            let s0 = self.seq.load(Ordering::Acquire);
            let frame = self.frame.load(Ordering::Acquire);
            let ns = self.at_ns.load(Ordering::Acquire);
            let block = self.block.load(Ordering::Acquire);
            if s0.is_multiple_of(2) && self.seq.load(Ordering::Acquire) == s0 {
                let now_ns = now.saturating_duration_since(self.origin).as_nanos() as u64;
                let ahead = now_ns.saturating_sub(ns) as f64 * 1e-9 * self.rate_hz;
                return frame + (ahead as u64).min(block) + block;
            }
            std::hint::spin_loop();
        }
    }
}
