//! The exact pool's block in two halves of its voices, on one core in turn or on two at once.
//!
//! Each half advances its own voices — the block-long passes ([`free_block`], [`fold_block`])
//! and every sample's reads, steps and own board parts — and keeps a replica of the board's
//! shared part. Every sample the halves hand each other their modal force on the board and their
//! volume velocity, and each replica takes the two forces' sum (two terms: the same in either
//! order): the replicas stay identical, and the result is the same bit for bit whether the halves run in turn or at once.
//! On two cores they meet once a sample, lock-free (a half waits by spinning on the other's
//! counter).

use super::board::{BoardCoupling, SharedPart};
use super::kernels::{convolve, fold_block, free_block, Split, BLOCK, DIRECTIONS};
use super::key::ExactKey;
use super::voice::Voice;
use crate::engine::pool::fade_step;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// What every half reads: the keys, their bridge points, the board's coefficients and timing.
pub(crate) struct Context<'a> {
    pub(crate) keys: &'a [ExactKey],
    pub(crate) points: &'a [[Vec<f64>; 3]],
    pub(crate) board: &'a BoardCoupling,
    pub(crate) fade_steps: u32,
    pub(crate) fast: bool,
}

/// One half's working values and its replica of the board's shared part: the stage states of a
/// hammer step, its modal force on the board this sample and the two halves' together. Touched
/// by the core that runs the half.
#[derive(Debug, Clone)]
pub(crate) struct Half {
    pub(crate) stages: [Split; 3],
    pub(crate) force: Vec<f64>,
    pub(crate) sum: Vec<f64>,
    pub(crate) part: SharedPart,
}

impl Half {
    pub(crate) fn new(modes: usize, board: &BoardCoupling) -> Half {
        Half {
            stages: std::array::from_fn(|_| Split::zeros(modes)),
            force: vec![0.0; board.modes()],
            sum: vec![0.0; board.modes()],
            part: board.part(),
        }
    }
}

/// A counter on its own cache line (the halves write theirs from different cores).
#[derive(Debug, Default)]
#[repr(align(128))]
struct Padded(AtomicU64);

/// What the halves hand each other within a block on two cores: per half and sample parity its
/// modal force and its volume velocity (f64 bits; relaxed stores and loads ordered by the
/// meeting counters), and each half's samples done. Two slots, so that a half may publish the
/// next sample while the other still reads the last.
#[derive(Debug)]
pub(crate) struct Exchange {
    force: Vec<AtomicU64>,
    total: [AtomicU64; 4],
    modes: usize,
    done: [Padded; 2],
    pub(crate) abandoned: AtomicBool,
}

impl Exchange {
    pub(crate) fn new(modes: usize) -> Exchange {
        Exchange {
            force: (0..4 * modes).map(|_| AtomicU64::new(0)).collect(),
            total: Default::default(),
            modes,
            done: Default::default(),
            abandoned: AtomicBool::new(false),
        }
    }

    fn slot(&self, half: usize, t: usize) -> &[AtomicU64] {
        let start = (2 * half + t % 2) * self.modes;
        &self.force[start..start + self.modes]
    }

    /// Announce that `half` has published sample `count` and wait until the other half has too
    /// (or has been abandoned after a panic).
    fn meet(&self, half: usize, count: u64) {
        self.done[half].0.store(count, Ordering::Release);
        while self.done[1 - half].0.load(Ordering::Acquire) < count {
            if self.abandoned.load(Ordering::Relaxed) {
                return;
            }
            std::hint::spin_loop();
        }
    }

    /// Start counting afresh (between blocks, when neither half runs).
    pub(crate) fn reset(&mut self) {
        for d in &mut self.done {
            *d.0.get_mut() = 0;
        }
        *self.abandoned.get_mut() = false;
    }
}

impl Clone for Exchange {
    /// A fresh exchange of the same size (what it holds lives only within a block).
    fn clone(&self) -> Exchange {
        Exchange::new(self.modes)
    }
}

/// Phase 1 of a block for a half's voices: each voice in the block advanced freely over it, its
/// free reads kept ([`free_block`], after the shift of [`ExactKey::block_alpha`]).
pub(crate) fn begin(cx: &Context<'_>, voices: &mut [Voice], len: usize) {
    for v in voices.iter_mut() {
        if let (true, Some(key)) = (v.in_block, v.state.key) {
            let key = &cx.keys[key];
            for (d, alpha) in key.block_alpha.iter().enumerate() {
                alpha.add_to(&mut v.z, v.state.coupling * v.other_before_m[d]);
            }
            free_block(
                cx.fast,
                &key.block,
                &key.ef,
                &mut v.z,
                &mut v.block_read,
                len,
            );
        }
    }
}

/// The last phase: each voice in the block gets the block's inputs folded into its modes.
pub(crate) fn end(cx: &Context<'_>, voices: &mut [Voice], len: usize) {
    for v in voices.iter_mut() {
        if let (true, Some(key)) = (v.in_block, v.state.key) {
            let key = &cx.keys[key];
            fold_block(cx.fast, &key.block, &mut v.z, &v.block_inputs, len);
            for (d, alpha) in key.block_alpha.iter().enumerate() {
                alpha.add_to(&mut v.z, -v.block_inputs[d][BLOCK - len]);
            }
        }
        v.in_block = false;
    }
}

/// Sample `t` of a half's voices up to the board: a voice in the block from its free reads and
/// its Markov parameters, any other by [`Voice::step`] (its fade moving); each voice's own board
/// part advanced, its modal force summed into `half.force`. Returns the half's volume velocity.
pub(crate) fn forces(cx: &Context<'_>, voices: &mut [Voice], half: &mut Half, t: usize) -> f64 {
    half.force.iter_mut().for_each(|f| *f = 0.0);
    let mut total = 0.0;
    for v in voices.iter_mut() {
        let (true, Some(k)) = (v.state.active, v.state.key) else {
            continue;
        };
        let key = &cx.keys[k];
        let before = v.force_n;
        if v.in_block {
            let u = v.inputs(key.h);
            for d in 0..DIRECTIONS {
                v.block_inputs[d][BLOCK - 1 - t] = u[d];
            }
            let mut read = convolve(cx.fast, &key.markov, &v.block_inputs, t);
            for (i, r) in read.iter_mut().enumerate() {
                *r += v.block_read[i][t];
                for d in 0..DIRECTIONS {
                    *r -= key.block_alpha_read[i][d] * u[d];
                }
            }
            v.finish(key, &u, read);
        } else {
            fade_step(&mut v.state, cx.fade_steps);
            v.step(key, &mut half.stages, cx.fast);
        }
        v.own_at_m = cx.board.step_own(
            cx.fast,
            &mut v.own_board,
            &cx.points[k],
            (before, v.force_n),
            &mut half.force,
        );
        total += v.state.coupling * v.read[0];
    }
    total
}

/// After the board has stepped: every voice of a half reads the other keys' motion at its point.
pub(crate) fn feel(cx: &Context<'_>, voices: &mut [Voice], part: &SharedPart) {
    for v in voices.iter_mut() {
        let (true, Some(k)) = (v.state.active, v.state.key) else {
            continue;
        };
        let shared = cx.board.shared_at(part, cx.fast, &cx.points[k]);
        v.other_before_m = v.other_m;
        v.other_m = std::array::from_fn(|d| shared[d] - v.own_at_m[d]);
    }
}

/// A whole block of both halves on this core, in turn (`blocks`: the voices in the block
/// advanced by block-long passes); `out[t]` the board's volume velocity. Half 0's replica of the
/// shared part serves both.
pub(crate) fn run_alone(
    cx: &Context<'_>,
    [v0, v1]: [&mut [Voice]; 2],
    [h0, h1]: &mut [Half; 2],
    out: &mut [f64],
    blocks: bool,
) {
    let len = out.len();
    if blocks {
        begin(cx, v0, len);
        begin(cx, v1, len);
    }
    for (t, out) in out.iter_mut().enumerate() {
        let total0 = forces(cx, v0, h0, t);
        let total1 = forces(cx, v1, h1, t);
        for ((sum, a), b) in h0.sum.iter_mut().zip(&h0.force).zip(&h1.force) {
            *sum = a + b;
        }
        cx.board.step_shared(&mut h0.part, &h0.sum);
        feel(cx, v0, &h0.part);
        feel(cx, v1, &h0.part);
        *out = total0 + total1;
    }
    if blocks {
        end(cx, v0, len);
        end(cx, v1, len);
    }
}

/// Half `half` of a block on this core while the other runs on another, meeting every sample;
/// half 0 writes `out` (the same sums as [`run_alone`]).
pub(crate) fn run_half(
    cx: &Context<'_>,
    half: usize,
    voices: &mut [Voice],
    mine: &mut Half,
    ex: &Exchange,
    mut out: Option<&mut [f64]>,
    len: usize,
) {
    begin(cx, voices, len);
    for t in 0..len {
        let total = forces(cx, voices, mine, t);
        for (slot, f) in ex.slot(half, t).iter().zip(&mine.force) {
            slot.store(f.to_bits(), Ordering::Relaxed);
        }
        ex.total[2 * half + t % 2].store(total.to_bits(), Ordering::Relaxed);
        ex.meet(half, t as u64 + 1);
        let theirs = ex.slot(1 - half, t);
        for ((sum, f), theirs) in mine.sum.iter_mut().zip(&mine.force).zip(theirs) {
            let theirs = f64::from_bits(theirs.load(Ordering::Relaxed));
            // Two terms: the same sum, bit for bit, on either side and on one core.
            *sum = f + theirs;
        }
        cx.board.step_shared(&mut mine.part, &mine.sum);
        feel(cx, voices, &mine.part);
        if let Some(out) = out.as_deref_mut() {
            let theirs = f64::from_bits(ex.total[2 + t % 2].load(Ordering::Relaxed));
            out[t] = total + theirs;
        }
    }
    end(cx, voices, len);
}
