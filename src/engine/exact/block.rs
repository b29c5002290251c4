//! A block of the exact pool: the block-long passes of the voices advanced mode by mode
//! ([`begin`], [`end`]: independent from voice to voice, so the pool may split them over two
//! cores) and the steps between them ([`run`]): each sample, every voice's step up to the
//! interface ([`Voice::pre_step`], or for a voice in the block its free reads and Markov
//! parameters), their known forces summed onto the shared board's modes, the board stepped with
//! the interface solved ([`super::interface`]), every voice's step finished with the board's
//! displacement at its bridge. On two cores ([`run_on_two`]) each core steps half of the voices
//! and a copy of the shared board, the two meeting every sample to exchange their halves' known
//! forces.

use super::interface::{BoardState, BridgePoint, SharedBoard};
use super::kernels::{
    fold_block, free_block, Reversed, Simd, BLOCK, DIRECTIONS, READS, SOUND_READS,
};
use super::key::ExactKey;
use super::voice::Voice;
use crate::engine::pool::fade_step;
use crate::engine::spec::CHANNELS;
use crate::engine::Pair;
use std::any::Any;
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};

/// What the block reads: the keys, their bridge points on the shared modes, the shared board
/// (its coefficients and the interface's matrices) and timing.
pub(crate) struct Context<'a> {
    pub(crate) keys: &'a [ExactKey],
    pub(crate) points: &'a [BridgePoint],
    pub(crate) board: &'a SharedBoard,
    pub(crate) fade_steps: u32,
    pub(crate) simd: Simd,
    /// Whether [`end`] keeps each voice's energies (the last block before the policy looks).
    pub(crate) keep_energies: bool,
}

/// The steps' working values: per half of the voices ([`Half`]), the shared board's state (and
/// the second core's copy of it), the meeting of the two cores, and the radiating source of each
/// sample of the block: the voices' and the shared board's apart
/// ([`super::interface::HeardSource`] hears them). Touched by the thread that steps the pool
/// (and, within a block on two cores, `halves[1]`, `copy` and `exchange` by the second core).
#[derive(Debug)]
pub(crate) struct Steps {
    pub(crate) halves: [Half; 2],
    pub(crate) part: BoardState,
    copy: BoardState,
    exchange: Exchange,
    pub(crate) volume: [[f64; CHANNELS]; BLOCK],
    pub(crate) board_volume: [[f64; CHANNELS]; BLOCK],
    /// Each sample's total force on the board of the voices watched ([`Voice::watched`], N).
    pub(crate) watched_n: [[f64; 3]; BLOCK],
}

/// One half of the voices' working values within the steps: the half's known modal force this
/// sample (and, on two cores, the other half's as received,
/// and their sum), each sample's volume velocity of the half's voices and of the board.
#[derive(Debug, Clone)]
pub(crate) struct Half {
    known: Vec<f64>,
    other: Vec<f64>,
    sum: Vec<f64>,
    volume: [[f64; CHANNELS]; BLOCK],
    board_volume: [[f64; CHANNELS]; BLOCK],
    watched_n: [[f64; 3]; BLOCK],
}

impl Steps {
    pub(crate) fn new(board: &SharedBoard) -> Steps {
        let m = board.modes();
        let half = Half {
            known: vec![0.0; m],
            other: vec![0.0; m],
            sum: vec![0.0; m],
            volume: [[0.0; CHANNELS]; BLOCK],
            board_volume: [[0.0; CHANNELS]; BLOCK],
            watched_n: [[0.0; 3]; BLOCK],
        };
        Steps {
            halves: [half.clone(), half],
            part: board.state(),
            copy: board.state(),
            exchange: Exchange::new(m),
            volume: [[0.0; CHANNELS]; BLOCK],
            board_volume: [[0.0; CHANNELS]; BLOCK],
            watched_n: [[0.0; 3]; BLOCK],
        }
    }
}

impl Steps {
    /// The block's first `len` samples of both halves' voices: their radiating source and the
    /// watched voices' force, half 0's plus half 1's.
    fn add_halves(&mut self, len: usize) {
        let [h0, h1] = &self.halves;
        for t in 0..len {
            self.volume[t] = std::array::from_fn(|c| h0.volume[t][c] + h1.volume[t][c]);
            self.watched_n[t] = std::array::from_fn(|d| h0.watched_n[t][d] + h1.watched_n[t][d]);
        }
    }
}

impl Clone for Steps {
    /// The state and working values; a fresh meeting (no block is under way while the pool is
    /// cloned).
    fn clone(&self) -> Steps {
        Steps {
            halves: self.halves.clone(),
            part: self.part.clone(),
            copy: self.copy.clone(),
            exchange: Exchange::new(self.part.modes()),
            volume: self.volume,
            board_volume: self.board_volume,
            watched_n: self.watched_n,
        }
    }
}

/// A cache line of its own for a value one core writes and the other reads.
#[derive(Debug, Default)]
#[repr(align(128))]
struct Line<T>(T);

/// Where the two halves of a block on two cores meet each sample: each publishes its known
/// modal force (two slots per half, alternating by sample: a slot is written again only after
/// the other core has published the next sample, so after it has read this one) and the count of
/// samples it has published; each reads the other's. `abort` stops a core waiting for one that
/// has panicked.
#[derive(Debug)]
pub(crate) struct Exchange {
    ready: [Line<AtomicUsize>; 2],
    slots: [[Vec<AtomicU64>; 2]; 2],
    abort: Line<AtomicBool>,
}

impl Exchange {
    pub(crate) fn new(modes: usize) -> Exchange {
        let slot = || (0..modes).map(|_| AtomicU64::new(0)).collect();
        Exchange {
            ready: Default::default(),
            slots: std::array::from_fn(|_| std::array::from_fn(|_| slot())),
            abort: Line::default(),
        }
    }

    /// Before a block (neither core in it).
    pub(crate) fn reset(&self) {
        for r in &self.ready {
            r.0.store(0, Ordering::Relaxed);
        }
        self.abort.0.store(false, Ordering::Relaxed);
    }

    /// Stop both halves waiting at their next meeting (a half that failed, or a watchdog).
    pub(crate) fn give_up(&self) {
        self.abort.0.store(true, Ordering::Relaxed);
    }

    /// Half `me` publishes its known force of sample `t`.
    pub(crate) fn publish(&self, me: usize, t: usize, known: &[f64]) {
        for (slot, x) in self.slots[me][t % 2].iter().zip(known) {
            slot.store(x.to_bits(), Ordering::Relaxed);
        }
        self.ready[me].0.store(t + 1, Ordering::Release);
    }

    /// Half `me` waits for the other's known force of sample `t` and copies it into `into`;
    /// `false` if the other core has given up.
    pub(crate) fn receive(&self, me: usize, t: usize, into: &mut [f64]) -> bool {
        let other = 1 - me;
        while self.ready[other].0.load(Ordering::Acquire) <= t {
            if self.abort.0.load(Ordering::Relaxed) {
                return false;
            }
            std::hint::spin_loop();
        }
        for (x, slot) in into.iter_mut().zip(&self.slots[other][t % 2]) {
            *x = f64::from_bits(slot.load(Ordering::Relaxed));
        }
        true
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
        let key = v.face(&cx.keys[key]);
        let live = v.live_modes(key);
        match (v.damped(key), &key.damper) {
            (true, Some(damper)) => {
                for (j, to) in damper.to.iter().enumerate() {
                    to.add_to(&mut v.w, -v.damper_n[j]);
                }
                free_block(
                    cx.simd,
                    &damper.block,
                    live,
                    &key.ef,
                    &mut v.w,
                    &mut v.block_read,
                    len,
                );
            }
            _ => {
                let out: &mut [[f64; BLOCK]; READS] = (&mut v.block_read[..READS])
                    .try_into()
                    .expect("the first reads are the undamped key's");
                free_block(cx.simd, &key.block, live, &key.ef, &mut v.w, out, len);
            }
        }
    }
}

/// The last pass: each voice in the block gets the block's inputs folded into its modes (a
/// damped one shifted back to `w`), and at the end of a run its energies for the pool's policy
/// worked out while its modes are in this core's cache ([`Voice::energies`]).
pub(crate) fn end(cx: &Context<'_>, voices: &mut [Voice], len: usize) {
    for v in voices.iter_mut() {
        if let (true, Some(key)) = (v.in_block, v.state.key) {
            let key = v.face(&cx.keys[key]);
            let live = v.live_modes(key);
            match (v.damped(key), &key.damper) {
                (true, Some(damper)) => {
                    fold_block(cx.simd, &damper.block, live, &mut v.w, &v.block_inputs, len);
                    for (j, to) in damper.to.iter().enumerate() {
                        to.add_to(&mut v.w, v.damper_n[j]);
                    }
                }
                _ => {
                    let inputs: &Reversed<DIRECTIONS> = v.block_inputs[..DIRECTIONS]
                        .try_into()
                        .expect("the first inputs are the bridge's");
                    fold_block(cx.simd, &key.block, live, &mut v.w, inputs, len);
                }
            }
            if cx.keep_energies {
                v.energies = Some(v.energies_now_j(key, cx.simd));
            }
        }
        v.in_block = false;
    }
}

/// Sample `t` of voice `v` up to the interface: in the block, from its free reads and its Markov
/// parameters, else by [`Voice::pre_step`] (its fade moving: a stolen voice's modes shrink with
/// it); its known force summed onto the shared modes in `known`.
#[inline(always)]
fn pre(cx: &Context<'_>, v: &mut Voice, k: usize, t: usize, known: &mut [f64]) {
    let key = v.face(&cx.keys[k]);
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
        v.pre_step(key, cx.simd);
    }
    let f = [v.known[1], v.known[2], v.known[3]];
    cx.board.add_force(cx.simd, &cx.points[k], f, known);
}

/// The voices' first sample up to the interface ([`pre`]), their known forces in `half.known`.
fn first(cx: &Context<'_>, voices: &mut [Voice], half: &mut Half) {
    half.known.iter_mut().for_each(|f| *f = 0.0);
    for v in voices.iter_mut() {
        if let (true, Some(k)) = (v.state.active, v.state.key) {
            pre(cx, v, k, 0, &mut half.known);
        }
    }
}

/// After the shared board has stepped: every voice reads its displacement at its bridge and
/// finishes step `t`, then (unless this was the block's last) takes the next sample up to the
/// interface ([`pre`]), its known force in `half.known` — one pass over the voices a sample,
/// each voice's bridge point and state brought in once for both. Writes the voices' radiating
/// source of each channel to `half.volume[t]` and the watched voices' force to
/// `half.watched_n[t]`.
fn finish(
    cx: &Context<'_>,
    voices: &mut [Voice],
    part: &BoardState,
    half: &mut Half,
    t: usize,
    len: usize,
) {
    let next = (t + 1 < len).then_some(t + 1);
    if next.is_some() {
        half.known.iter_mut().for_each(|f| *f = 0.0);
    }
    let (mut total, mut watched) = ([0.0; CHANNELS], [0.0; 3]);
    for i in 0..voices.len() {
        if let Some(n) = voices.get(i + 1) {
            prefetch_prefix(cx, n);
        }
        let v = &mut voices[i];
        let (true, Some(k)) = (v.state.active, v.state.key) else {
            continue;
        };
        let d = cx.board.at(part, &cx.points[k], cx.simd);
        v.post_step(v.face(&cx.keys[k]), d);
        for (t, &r) in total.iter_mut().zip(&SOUND_READS) {
            *t += v.read[r];
        }
        if v.watched {
            watched.iter_mut().zip(v.force_n).for_each(|(w, f)| *w += f);
        }
        if let Some(t) = next {
            pre(cx, v, k, t, &mut half.known);
        }
    }
    (half.volume[t], half.watched_n[t]) = (total, watched);
}

/// Ask for the next voice's live prefix (its reads' coefficients, read every sample) to be
/// brought into the cache while this voice steps.
#[inline(always)]
fn prefetch_prefix(cx: &Context<'_>, v: &Voice) {
    #[cfg(target_arch = "x86_64")]
    if let (true, Some(k)) = (v.state.active, v.state.key) {
        let key = v.face(&cx.keys[k]);
        if let Some(p) = key.prefixes.get(v.live) {
            let at = (p as *const super::key::Prefix).cast::<i8>();
            for line in 0..std::mem::size_of::<super::key::Prefix>().div_ceil(64) {
                // SAFETY: a prefetch never faults; the address lies within `p`.
                unsafe {
                    std::arch::x86_64::_mm_prefetch(
                        at.add(line * 64),
                        std::arch::x86_64::_MM_HINT_T0,
                    )
                };
            }
        }
    }
}

/// The shared modes' known force: half 0's plus half 1's, in that order on either core (so that
/// one core and two give the same board bit for bit).
fn sum(first: &[f64], second: &[f64], total: &mut [f64]) {
    for ((t, a), b) in total.iter_mut().zip(first).zip(second) {
        *t = a + b;
    }
}

/// `len` samples of every voice (both halves) and the shared board on this core (the block
/// passes of the voices in the block done before and after: [`begin`], [`end`]); the radiating
/// source of the voices in `steps.volume`, of the board in `steps.board_volume`.
pub(crate) fn run(cx: &Context<'_>, voices: [&mut [Voice]; 2], steps: &mut Steps, len: usize) {
    let [v0, v1] = voices;
    let [h0, h1] = &mut steps.halves;
    first(cx, v0, h0);
    first(cx, v1, h1);
    for t in 0..len {
        sum(&h0.known, &h1.known, &mut h0.sum);
        let board = cx.board.step(&mut steps.part, &h0.sum, cx.simd);
        finish(cx, v0, &steps.part, h0, t, len);
        finish(cx, v1, &steps.part, h1, t, len);
        steps.board_volume[t] = board;
    }
    steps.add_halves(len);
}

/// Half `me` of the steps on two cores: its voices' `len` samples, meeting the other half each
/// sample to exchange the known forces, both cores stepping their own identical copy of the
/// shared board (`part`). Stops early if the other core gives up.
fn run_half(
    cx: &Context<'_>,
    voices: &mut [Voice],
    half: &mut Half,
    part: &mut BoardState,
    exchange: &Exchange,
    me: usize,
    len: usize,
) {
    first(cx, voices, half);
    for t in 0..len {
        exchange.publish(me, t, &half.known);
        if !exchange.receive(me, t, &mut half.other) {
            return;
        }
        let (first, second) = match me {
            0 => (&half.known, &half.other),
            _ => (&half.other, &half.known),
        };
        sum(first, second, &mut half.sum);
        half.board_volume[t] = cx.board.step(part, &half.sum, cx.simd);
        finish(cx, voices, part, half, t, len);
    }
}

/// `run` with a panic caught: the other core told to stop waiting, the panic kept to be raised
/// again once both have stopped.
fn stop_on_panic(exchange: &Exchange, run: impl FnOnce()) -> Option<Box<dyn Any + Send>> {
    let caught = catch_unwind(AssertUnwindSafe(run)).err();
    if caught.is_some() {
        exchange.give_up();
    }
    caught
}

/// [`run`] with `voices[0]` on this core and `voices[1]` on the other through `pair`: the same
/// result bit for bit. `false` if the other core could not start (nothing done). A panic on
/// either core stops the other at its next meeting and is raised again here.
pub(crate) fn run_on_two(
    pair: &dyn Pair,
    cx: &Context<'_>,
    voices: [&mut [Voice]; 2],
    steps: &mut Steps,
    len: usize,
) -> bool {
    let [v0, v1] = voices;
    let Steps {
        halves: [h0, h1],
        part,
        copy,
        exchange,
        ..
    } = steps;
    copy.copy_from(part);
    exchange.reset();
    let exchange = &*exchange;
    let (mut theirs, mut mine) = (None, None);
    let mut there =
        || theirs = stop_on_panic(exchange, || run_half(cx, v1, h1, copy, exchange, 1, len));
    let mut here =
        || mine = stop_on_panic(exchange, || run_half(cx, v0, h0, part, exchange, 0, len));
    if !pair.join(&mut there, &mut here) {
        return false;
    }
    if let Some(e) = mine.or(theirs) {
        resume_unwind(e);
    }
    let board = steps.halves[0].board_volume;
    steps.board_volume[..len].copy_from_slice(&board[..len]);
    steps.add_halves(len);
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};

    /// Sets `abort` when dropped (as a thread unwinds).
    struct Abort<'a>(&'a Exchange);

    impl Drop for Abort<'_> {
        fn drop(&mut self) {
            self.0.abort.0.store(true, Ordering::Relaxed);
        }
    }

    #[test]
    fn the_halves_receive_each_others_forces_sample_by_sample() {
        // Two threads meet 20 000 times, each publishing values unique to its half and the
        // sample and checking what it receives: were a slot written again before the other had
        // read it (one slot instead of two alternating), a value of the next sample would show.
        const MODES: usize = 64;
        const SAMPLES: usize = 20_000;
        let exchange = Exchange::new(MODES);
        let value = |half: usize, t: usize, k: usize| (half * 1_000_000_000 + t * 100 + k) as f64;
        let started = Instant::now();
        std::thread::scope(|s| {
            for me in 0..2 {
                let exchange = &exchange;
                s.spawn(move || {
                    // A failed check must not leave the other thread waiting.
                    let give_up = Abort(exchange);
                    let mut mine = vec![0.0; MODES];
                    let mut theirs = vec![0.0; MODES];
                    for t in 0..SAMPLES {
                        mine.iter_mut()
                            .enumerate()
                            .for_each(|(k, x)| *x = value(me, t, k));
                        exchange.publish(me, t, &mine);
                        assert!(
                            exchange.receive(me, t, &mut theirs),
                            "the other half gave up"
                        );
                        for (k, &x) in theirs.iter().enumerate() {
                            assert_eq!(x, value(1 - me, t, k), "half {me}, sample {t}, mode {k}");
                        }
                    }
                    std::mem::forget(give_up);
                });
            }
        });
        println!(
            "{SAMPLES} meetings of two threads, {MODES} modes each way: every value received as published ({:.1} us a meeting)",
            started.elapsed().as_secs_f64() * 1e6 / SAMPLES as f64
        );
    }

    #[test]
    fn a_panicking_half_tells_the_other_to_stop_and_keeps_its_panic() {
        let exchange = Exchange::new(8);
        exchange.reset();
        assert!(stop_on_panic(&exchange, || {}).is_none());
        assert!(
            !exchange.abort.0.load(Ordering::Relaxed),
            "no panic, no abort"
        );
        let caught = stop_on_panic(&exchange, || panic!("a fault in one half"));
        let message = caught.as_ref().and_then(|e| e.downcast_ref::<&str>());
        assert_eq!(message, Some(&"a fault in one half"));
        assert!(
            exchange.abort.0.load(Ordering::Relaxed),
            "the other half is told to stop"
        );
        assert!(!exchange.receive(0, 0, &mut [0.0; 8]), "and stops waiting");
    }

    #[test]
    fn a_core_that_gives_up_releases_the_other() {
        let exchange = Exchange::new(8);
        exchange.reset();
        let started = Instant::now();
        std::thread::scope(|s| {
            s.spawn(|| {
                std::thread::sleep(Duration::from_millis(20));
                exchange.abort.0.store(true, Ordering::Relaxed);
            });
            assert!(!exchange.receive(0, 0, &mut [0.0; 8]));
        });
        println!(
            "the waiting half returned {:.0} ms after the other gave up",
            started.elapsed().as_secs_f64() * 1e3 - 20.0
        );
    }
}
