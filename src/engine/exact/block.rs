//! A block of the exact pool: the block-long passes of the voices advanced mode by mode
//! ([`begin`], [`end`]: independent from voice to voice, so the pool may split them over two
//! cores) and the steps between them ([`run`]): each sample, every voice's step up to the
//! interface ([`Voice::pre_step`], or for a voice in the block its free reads and Markov
//! parameters), their known forces summed onto the shared board's modes, the board stepped with
//! the interface solved ([`super::interface`]), every voice's step finished with the board's
//! displacement at its bridge.

use super::interface::{BoardState, SharedBoard};
use super::kernels::{fold_block, free_block, Reversed, Simd, Split, BLOCK, DIRECTIONS, READS};
use super::key::ExactKey;
use super::voice::Voice;
use crate::engine::pool::fade_step;

/// What the block reads: the keys, their bridge points on the shared modes, the shared board
/// (its coefficients and the interface's matrices) and timing.
pub(crate) struct Context<'a> {
    pub(crate) keys: &'a [ExactKey],
    pub(crate) points: &'a [[Vec<f64>; 3]],
    pub(crate) board: &'a SharedBoard,
    pub(crate) fade_steps: u32,
    pub(crate) simd: Simd,
}

/// The steps' working values: the stage states of a hammer step, the voices' known modal force
/// this sample, the shared board's state, and the volume velocity of each sample of the block.
/// Touched by the thread that steps the pool.
#[derive(Debug, Clone)]
pub(crate) struct Steps {
    pub(crate) stages: [Split; 3],
    pub(crate) known: Vec<f64>,
    pub(crate) part: BoardState,
    pub(crate) volume: [f64; BLOCK],
}

impl Steps {
    pub(crate) fn new(modes: usize, board: &SharedBoard) -> Steps {
        Steps {
            stages: std::array::from_fn(|_| Split::zeros(modes)),
            known: vec![0.0; board.modes()],
            part: board.state(),
            volume: [0.0; BLOCK],
        }
    }
}

/// The first pass of a block over `voices`: each voice in the block advanced freely over it, its
/// free reads kept ([`free_block`]); a damped one first shifted to `u = w - sum_j to_j f_j`, in
/// which the felt's force is an input ([`super::key::DamperKey`]).
pub(crate) fn begin(cx: &Context<'_>, voices: &mut [Voice], len: usize) {
    for v in voices.iter_mut() {
        let (true, Some(key)) = (v.in_block, v.state.key) else {
            continue;
        };
        let key = &cx.keys[key];
        match (v.damped(key), &key.damper) {
            (true, Some(damper)) => {
                for (j, to) in damper.to.iter().enumerate() {
                    to.add_to(&mut v.w, -v.damper_n[j]);
                }
                free_block(
                    cx.simd,
                    &damper.block,
                    &key.ef,
                    &mut v.w,
                    &mut v.block_read,
                    len,
                );
            }
            _ => {
                let out: &mut [[f64; BLOCK]; READS] = (&mut v.block_read[..READS])
                    .try_into()
                    .expect("the first reads are the four rows");
                free_block(cx.simd, &key.block, &key.ef, &mut v.w, out, len);
            }
        }
    }
}

/// The last pass: each voice in the block gets the block's inputs folded into its modes (a
/// damped one shifted back to `w`).
pub(crate) fn end(cx: &Context<'_>, voices: &mut [Voice], len: usize) {
    for v in voices.iter_mut() {
        if let (true, Some(key)) = (v.in_block, v.state.key) {
            let key = &cx.keys[key];
            match (v.damped(key), &key.damper) {
                (true, Some(damper)) => {
                    fold_block(cx.simd, &damper.block, &mut v.w, &v.block_inputs, len);
                    for (j, to) in damper.to.iter().enumerate() {
                        to.add_to(&mut v.w, v.damper_n[j]);
                    }
                }
                _ => {
                    let inputs: &Reversed<DIRECTIONS> = v.block_inputs[..DIRECTIONS]
                        .try_into()
                        .expect("the first inputs are the bridge's");
                    fold_block(cx.simd, &key.block, &mut v.w, inputs, len);
                }
            }
        }
        v.in_block = false;
    }
}

/// Sample `t` of the voices up to the interface: a voice in the block from its free reads and
/// its Markov parameters, any other by [`Voice::pre_step`] (its fade moving: a stolen voice's
/// modes shrink with it); their known forces added onto the shared modes in `steps.known`.
fn known(cx: &Context<'_>, voices: &mut [Voice], steps: &mut Steps, t: usize) {
    for v in voices.iter_mut() {
        let (true, Some(k)) = (v.state.active, v.state.key) else {
            continue;
        };
        let key = &cx.keys[k];
        if v.in_block {
            v.pre_block_step(key, t, cx.simd);
        } else {
            let before = v.state.coupling;
            fade_step(&mut v.state, cx.fade_steps);
            if v.state.coupling != before {
                let ratio = if before > 0.0 {
                    v.state.coupling / before
                } else {
                    0.0
                };
                v.w.scale(ratio);
            }
            v.pre_step(key, &mut steps.stages, cx.simd);
        }
        let f = [v.known[1], v.known[2], v.known[3]];
        cx.board
            .add_force(cx.simd, &cx.points[k], f, &mut steps.known);
    }
}

/// After the shared board has stepped: every voice reads its displacement at its bridge and
/// finishes its step. Returns the voices' volume velocity.
fn finish(cx: &Context<'_>, voices: &mut [Voice], part: &BoardState) -> f64 {
    let mut total = 0.0;
    for v in voices.iter_mut() {
        let (true, Some(k)) = (v.state.active, v.state.key) else {
            continue;
        };
        let next = cx.board.at(part, &cx.points[k], cx.simd);
        v.post_step(&cx.keys[k], next);
        total += v.read[0];
    }
    total
}

/// `len` samples of every voice and the shared board (the block passes of the voices in the
/// block done before and after: [`begin`], [`end`]); the volume velocity of each in
/// `steps.volume`.
pub(crate) fn run(cx: &Context<'_>, voices: [&mut [Voice]; 2], steps: &mut Steps, len: usize) {
    let [v0, v1] = voices;
    for t in 0..len {
        steps.known.iter_mut().for_each(|f| *f = 0.0);
        known(cx, v0, steps, t);
        known(cx, v1, steps, t);
        let board = cx.board.step(&mut steps.part, &steps.known, cx.simd);
        steps.volume[t] = finish(cx, v0, &steps.part) + finish(cx, v1, &steps.part) + board;
    }
}
