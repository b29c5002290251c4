//! The pool in two halves, each with its replica of the board, on one core in turn or on two at
//! once, meeting lock-free after every stage.

use super::board::*;
use super::keys::*;
use super::voices::*;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Half of the pool's voices (even or odd indices) with its working values and its own replica of
/// the board: what one core advances. Both replicas see the same forces in the same order, so they
/// stay identical bit for bit whether the halves run in turn on one core or at once on two.
#[derive(Debug, Clone)]
pub(super) struct Half {
    pub(super) set: VoiceSet,
    pub(super) board: Board,
    pub(super) steps: u64,
}

/// What the two halves hand each other within a step: each half's modal force on the board at
/// each stage (f64 bits; relaxed stores and loads ordered by the meeting counters), and each half's
/// last finished phase (`4 step + stage + 1`). Lock-free: a half waits for the other by spinning
/// on its counter, never by blocking.
#[derive(Debug)]
pub(super) struct Exchange {
    pub(super) force: Vec<AtomicU64>,
    pub(super) modes: usize,
    pub(super) phase: [Padded; 2],
    pub(super) abandoned: AtomicBool,
}

/// A counter on its own cache line (the two halves write theirs from different cores).
#[derive(Debug, Default)]
#[repr(align(128))]
pub(super) struct Padded(pub(super) AtomicU64);

impl Exchange {
    pub(super) fn new(modes: usize) -> Exchange {
        Exchange {
            force: (0..2 * 4 * modes).map(|_| AtomicU64::new(0)).collect(),
            modes,
            phase: Default::default(),
            abandoned: AtomicBool::new(false),
        }
    }

    pub(super) fn slot(&self, half: usize, stage: usize) -> &[AtomicU64] {
        let start = (half * 4 + stage) * self.modes;
        &self.force[start..start + self.modes]
    }

    /// Announce that `half` has finished `phase` and wait until the other half has too (or has
    /// been abandoned after a panic).
    pub(super) fn meet(&self, half: usize, phase: u64) {
        self.phase[half].0.store(phase, Ordering::Release);
        while self.phase[1 - half].0.load(Ordering::Acquire) < phase {
            if self.abandoned.load(Ordering::Relaxed) {
                return;
            }
            std::hint::spin_loop();
        }
    }
}

impl Clone for Exchange {
    fn clone(&self) -> Exchange {
        Exchange::new(self.modes)
    }
}

impl Half {
    /// `steps` steps of this half, meeting the other half (on another core) after every stage;
    /// `out` (half 0) receives the board's volume velocity after each step.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn run_part(
        &mut self,
        keys: &[EtdKey],
        ex: &Exchange,
        half: usize,
        (h, fade, fast): (f64, u32, bool),
        steps: usize,
        mut out: Option<&mut [f64]>,
    ) {
        for n in 0..steps {
            #[cfg(target_arch = "x86_64")]
            if fast {
                // SAFETY: `fast` is the pool's `fast_path`, set only when the CPU reports AVX2
                // and FMA.
                unsafe { self.split_step_avx2(keys, ex, half, h, fade) };
            } else {
                self.split_step::<false>(keys, ex, half, h, fade);
            }
            #[cfg(not(target_arch = "x86_64"))]
            self.split_step::<false>(keys, ex, half, h, fade);
            if let Some(out) = out.as_deref_mut() {
                out[n] = self.board.volume_velocity();
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn split_step_avx2(
        &mut self,
        keys: &[EtdKey],
        ex: &Exchange,
        half: usize,
        h: f64,
        fade: u32,
    ) {
        self.split_step::<true>(keys, ex, half, h, fade);
    }

    #[inline(always)]
    pub(super) fn split_step<const FMA: bool>(
        &mut self,
        keys: &[EtdKey],
        ex: &Exchange,
        half: usize,
        h: f64,
        fade: u32,
    ) {
        self.set.begin::<FMA>(keys);
        let b = &mut self.board;
        b.read_start();
        for (stage, plan) in ETDRK4_STAGES.iter().enumerate() {
            b.form_stage::<FMA>(plan.0, &plan.1);
            self.set
                .stage::<FMA>(keys, stage, plan, h, &b.stage, &mut b.force[stage]);
            // Publish this half's force, wait for the other's, and sum them (the same sum, in
            // either order, on both sides).
            for (slot, f) in ex.slot(half, stage).iter().zip(&b.force[stage]) {
                slot.store(f.to_bits(), Ordering::Relaxed);
            }
            ex.meet(half, 4 * self.steps + stage as u64 + 1);
            let other = ex.slot(1 - half, stage).iter();
            b.sum_forces(
                stage,
                other.map(|o| f64::from_bits(o.load(Ordering::Relaxed))),
            );
            b.accel(stage);
            self.set.accel::<FMA>(keys, stage, &b.acc);
        }
        b.advance::<FMA>();
        self.set.finish::<FMA>(keys, h, fade, &self.board);
        self.steps += 1;
    }
}
