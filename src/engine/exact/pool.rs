//! Many keys on the exact engine: a bank of prepared keys and a fixed pool of voices on one
//! shared board, with the same behaviour as the other pools ([`Policy`]: assign, steal with a
//! fade, strike in the current motion, dampers, silent voices retired, runaways reset).

use super::block::{begin, end, run, run_on_two, Context, Steps};
use super::interface::{BridgePoint, HeardSource, SharedBoard, SOURCE_DELAY_STEPS};
use super::kernels::{Simd, BLOCK};
use super::key::{ExactKey, LEFT_BELOW, LEFT_UNDER_J};
use super::voice::Voice;
use crate::engine::physics::hammer::HammerParams;
use crate::engine::pool::{Policy, VoiceState};
use crate::engine::spec::{
    BuildError, LinearState, Observation, UnisonSpec, VoiceModes, CHANNELS, STEAL_FADE_S,
};
use crate::engine::Pair;
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};

/// Voices of up to 88 keys on one shared soundboard: each key's strings and the board's high
/// modes at its bridge integrated exactly in their coupled modes ([`super::key`]), the board's
/// low modes shared, the keys meeting them at an interface solved implicitly each step
/// ([`super::interface`]). Stepped by the thread that owns it.
#[derive(Debug, Clone)]
pub struct ExactPool {
    /// The keys' coefficients, shared by every pool made from the same prepared keys.
    keys: std::sync::Arc<[ExactKey]>,
    /// Each key's mode shapes at its bridge point, on the shared modes.
    points: Vec<BridgePoint>,
    voices: Vec<Voice>,
    voice_of_key: Vec<Option<usize>>,
    board: SharedBoard,
    /// The steps' working values and the shared board's state.
    steps: Steps,
    h: f64,
    fade_steps: u32,
    simd: Simd,
    /// The voices' and the board's radiating source as heard ([`HeardSource`]).
    heard: HeardSource,
    /// The board's radiating source of each channel after the last step, as heard (m^3/s).
    radiated_m3_s: [f64; CHANNELS],
    /// Which of their modes the voices step ([`VoiceModes`]).
    voice_modes: VoiceModes,
    /// Whether anything reads the voices' energies after the next run
    /// ([`ExactPool::energies_read_after_run`]); set again to `true` by every run.
    energies_read: bool,
}

impl ExactPool {
    /// One key diagonalised at `spec.sample_rate_hz` (the costly part of building, independent
    /// from key to key).
    pub fn prepare_key(spec: &UnisonSpec) -> Result<ExactKey, BuildError> {
        ExactKey::new(spec)
    }

    /// How long the pool may ring once nothing drives it (s): the time the slowest of its keys'
    /// modes (their dampers lifted) and the shared board's takes to fall by `fall_db`.
    pub fn ring_out_s(&self, fall_db: f64) -> f64 {
        let slowest_per_s = self
            .keys
            .iter()
            .flat_map(|k| k.modes.lambda.iter())
            .chain(self.board.lambda())
            .map(|l| -l.re)
            .filter(|&sigma| sigma > 0.0)
            .fold(f64::INFINITY, f64::min);
        // An amplitude e^{-sigma t} falls by 20 log10(e) sigma dB a second.
        fall_db / (20.0 * std::f64::consts::LOG10_E * slowest_per_s)
    }

    /// The pool for `specs` (one per key, in order with `keys`) with `voices` voices.
    pub fn from_keys(
        specs: &[UnisonSpec],
        keys: std::sync::Arc<[ExactKey]>,
        voices: usize,
    ) -> Result<ExactPool, BuildError> {
        let first = crate::engine::pool::check_keys(specs, keys.len(), voices)?;
        let h = 1.0 / first.sample_rate_hz;
        let modes = keys.iter().map(|k| k.block.modes()).max().unwrap_or(0);
        let board = SharedBoard::new(&first.board, h);
        let points = specs
            .iter()
            .map(|s| Ok(board.restrict(&s.bridge()?.shape)))
            .collect::<Result<_, _>>()?;
        Ok(ExactPool {
            points,
            voice_of_key: vec![None; keys.len()],
            voices: vec![Voice::new(modes); voices],
            keys,
            steps: Steps::new(&board),
            board,
            h,
            fade_steps: ((STEAL_FADE_S / h).round() as u32).max(1),
            simd: Simd::detect(),
            heard: HeardSource::new(),
            radiated_m3_s: [0.0; CHANNELS],
            voice_modes: VoiceModes::default(),
            energies_read: true,
        })
    }

    /// Whether anything reads the voices' energies between the next run and the one after
    /// ([`crate::engine::VoicePool::energies_read_after_run`]): if not, that run's last block
    /// leaves them to be worked out on demand.
    pub fn energies_read_after_run(&mut self, read: bool) {
        self.energies_read = read;
    }

    /// Which of their modes the voices step from now on ([`VoiceModes`]); every active voice
    /// takes up at once what that asks ([`ExactPool::take_up`]).
    pub fn set_voice_modes(&mut self, modes: VoiceModes) {
        self.voice_modes = modes;
        for k in 0..self.voices.len() {
            self.take_up(k);
        }
    }

    /// Voice `k` (if active) steps the chunks of modes it must from now on: all of them while a
    /// hammer touches, a coupled felt is down or the pool steps every mode; at least those the
    /// board drives while its damper is lifted ([`ExactKey::sympathetic`]). Between steps only.
    fn take_up(&mut self, k: usize) {
        let v = &mut self.voices[k];
        let (true, Some(key)) = (v.state.active, v.state.key) else {
            return;
        };
        let face = v.face(&self.keys[key]);
        let want = if v.state.hammer_on || v.damped(face) || self.voice_modes == VoiceModes::All {
            face.chunks()
        } else if !v.state.damper_down {
            face.sympathetic
        } else {
            0
        };
        if want > v.live {
            v.keep_chunks(face, want);
        }
    }

    pub fn step_s(&self) -> f64 {
        self.h
    }

    /// How many steps the radiating source lags the state ([`HeardSource`]).
    pub fn source_delay_steps() -> usize {
        SOURCE_DELAY_STEPS
    }

    /// Modes of the shared board (padded to whole lanes).
    pub fn shared_modes(&self) -> usize {
        self.board.modes()
    }

    /// One step of every active voice, each one sample at a time ([`Voice::pre_step`],
    /// [`Voice::post_step`]), the interface solved between.
    pub fn step(&mut self) {
        self.move_dampers(1);
        self.touch_felts();
        for k in 0..self.voices.len() {
            self.take_up(k);
        }
        self.sync_loads();
        for v in self.voices.iter_mut() {
            (v.in_block, v.energies) = (false, None);
        }
        let cx = Context {
            keys: &self.keys,
            points: &self.points,
            board: &self.board,
            fade_steps: self.fade_steps,
            simd: self.simd,
            keep_energies: false,
        };
        run(&cx, [&mut self.voices, &mut []], &mut self.steps, 1);
        self.damp_part_felts(1);
        self.radiated_m3_s = self
            .heard
            .next(self.steps.volume[0], self.steps.board_volume[0]);
        self.finish_fades();
    }

    /// Advance `sound.len()` steps, writing the board's radiating source of each channel after each,
    /// in blocks of up to [`BLOCK`] steps ([`ExactPool::block`]) that end where a stolen voice's
    /// fade does (so that its next key starts between blocks); the voices split in two halves
    /// over two cores through `pair` (the same result bit for bit: [`ExactPool::block`]).
    pub fn run(&mut self, sound: &mut [[f64; CHANNELS]], pair: Option<&dyn Pair>) {
        self.run_watched(sound, None, pair);
    }

    /// Modes the active voices step now (each voice's chunks, the last one padded): what their
    /// block passes cost, beside the coupling and the shared board.
    pub fn modes_stepped(&self) -> usize {
        self.voices
            .iter()
            .filter_map(|v| match (v.state.active, v.state.key) {
                (true, Some(key)) => Some(v.live_modes(&self.keys[key])),
                _ => None,
            })
            .sum()
    }

    /// Which voices' forces on the board [`ExactPool::run_watched`] sums: those for which
    /// `watched(voice)` holds.
    pub fn watch(&mut self, watched: impl Fn(usize) -> bool) {
        for (k, v) in self.voices.iter_mut().enumerate() {
            v.watched = watched(k);
        }
    }

    /// [`ExactPool::run`], also writing after each step the total force on the board of the
    /// voices watched ([`ExactPool::watch`]; N, per direction) to `watched_n` (as long as
    /// `sound`): what a set of strings does to the board, sample by sample.
    pub fn run_watched(
        &mut self,
        sound: &mut [[f64; CHANNELS]],
        mut watched_n: Option<&mut [[f64; 3]]>,
        pair: Option<&dyn Pair>,
    ) {
        let mut done = 0;
        while done < sound.len() {
            let fade = self
                .voices
                .iter()
                .filter(|v| v.state.active && v.state.fade_left > 0)
                .map(|v| v.state.fade_left as usize)
                .min()
                .unwrap_or(BLOCK);
            let n = (sound.len() - done).min(BLOCK).min(fade);
            let last = done + n == sound.len() && self.energies_read;
            self.block(&mut sound[done..done + n], pair, last);
            if let Some(w) = watched_n.as_deref_mut() {
                w[done..done + n].copy_from_slice(&self.steps.watched_n[..n]);
            }
            self.finish_fades();
            done += n;
        }
        self.energies_read = true;
    }

    /// Each voice whose damper is part-lifted, not down, loses its felt's share of damping over
    /// the `steps` just taken ([`super::key::PartFelt::damp`]): the felt's damping is diagonal in
    /// the modes, as the free steps are, so the two taken one after the other are the steps with
    /// both, at the block's ends.
    fn damp_part_felts(&mut self, steps: usize) {
        for v in self.voices.iter_mut() {
            let (true, Some(key)) = (v.state.active, v.state.key) else {
                continue;
            };
            let share = v.state.damper_share;
            if v.state.damper_down || share <= 0.0 {
                continue;
            }
            let key = &self.keys[key];
            let face = v.face(key);
            if let Some(felt) = &key.part_felt {
                let live = v.live_unpadded(face);
                felt.damp(&mut v.w, &face.settle, &v.d, live, share, steps);
                v.energies = None;
            }
        }
    }

    /// Every voice whose fade has ended takes its next key.
    fn finish_fades(&mut self) {
        for k in 0..self.voices.len() {
            self.complete_fade(k);
        }
    }

    /// The interface holds every active voice's `Z` as its damper is: what changed since the
    /// last block (a voice joined, left, changed key, had its damper lowered or lifted) is added
    /// or taken out, a rank-3 update each ([`SharedBoard::update`]).
    fn sync_loads(&mut self) {
        for v in self.voices.iter_mut() {
            let want = match (v.state.active, v.state.key) {
                (true, Some(key)) => Some((key, v.state.damper_down, v.live)),
                _ => None,
            };
            if want == v.loads {
                continue;
            }
            let settle = |(key, down, live): (usize, bool, usize)| {
                let face = self.keys[key].face_for(down);
                face.settle_for(down, live).force
            };
            match (v.loads, want) {
                (Some(old), Some(new)) if old.0 == new.0 => {
                    let (a, b) = (settle(old), settle(new));
                    let dz = std::array::from_fn(|i| std::array::from_fn(|d| b[i][d] - a[i][d]));
                    self.board.update(&self.points[new.0].phi, &dz);
                }
                (old, new) => {
                    if let Some(old) = old {
                        let z = settle(old).map(|r| r.map(|x| -x));
                        self.board.update(&self.points[old.0].phi, &z);
                    }
                    if let Some(new) = new {
                        self.board.update(&self.points[new.0].phi, &settle(new));
                    }
                }
            }
            v.loads = want;
        }
    }

    /// `out.len()` (at most [`BLOCK`]) steps, the same as as many [`ExactPool::step`]s but for
    /// rounding. A voice whose steps are linear and time-invariant ([`Voice::is_linear`]: no
    /// hammer or fade; the damper lifted or down) is advanced mode by mode over the whole block — each mode's coefficients
    /// loaded once, not once a step — and gets its input back by superposition: its reads step
    /// by step from its Markov parameters (the interface needs them every step), its modes from
    /// the inputs folded in at the end. The others step one sample at a time, as in `step`.
    /// The last block of a run (`last`) keeps each voice's energies for the policy
    /// ([`Voice::energies`]).
    fn block(&mut self, out: &mut [[f64; CHANNELS]], pair: Option<&dyn Pair>, last: bool) {
        self.move_dampers(out.len());
        self.touch_felts();
        for k in 0..self.voices.len() {
            self.take_up(k);
        }
        self.sync_loads();
        let len = out.len();
        for v in self.voices.iter_mut() {
            v.in_block = match (v.state.active, v.state.key) {
                (true, Some(_)) => v.is_linear(),
                _ => false,
            };
            v.energies = None;
        }
        let cx = Context {
            keys: &self.keys,
            points: &self.points,
            board: &self.board,
            fade_steps: self.fade_steps,
            simd: self.simd,
            keep_energies: last,
        };
        // Where there is a second core, the block-long passes split over the two in two halves
        // of about equal work (the voices' modes, in voice order; a damped voice reads and folds
        // in three times as much), and the steps between them in two halves of about equal
        // steps ([`step_work`]): the steps meet every sample, so each half's share of them must
        // be even, not only its total.
        let pass_work = |v: &Voice| match (v.in_block, v.state.key) {
            (true, Some(key)) => {
                let key = v.face(&self.keys[key]);
                v.live_modes(key) * if v.damped(key) { 3 } else { 1 }
            }
            _ => 0,
        };
        let (passes, _) = halves(&self.voices, pass_work);
        let (steps, step_total) = halves(&self.voices, |v| step_work(&self.keys, v));
        let (v0, v1) = self.voices.split_at_mut(passes);
        let split = pair.filter(|_| !v0.is_empty() && !v1.is_empty());
        both(split, &mut || begin(&cx, v1, len), &mut || {
            begin(&cx, v0, len)
        });
        let (v0, v1) = self.voices.split_at_mut(steps);
        let two = pair.filter(|_| step_total >= MEET_FROM && !v0.is_empty() && !v1.is_empty());
        if !two
            .is_some_and(|pair| run_on_two(pair, &cx, [&mut *v0, &mut *v1], &mut self.steps, len))
        {
            run(&cx, [v0, v1], &mut self.steps, len);
        }
        let (v0, v1) = self.voices.split_at_mut(passes);
        both(split, &mut || end(&cx, v1, len), &mut || end(&cx, v0, len));
        self.damp_part_felts(len);
        for (t, out) in out.iter_mut().enumerate() {
            *out = self
                .heard
                .next(self.steps.volume[t], self.steps.board_volume[t]);
        }
        self.radiated_m3_s = out[len - 1];
    }

    /// The board's radiating source of the left channel after the last step (m^3/s).
    pub fn volume_velocity_m3_s(&self) -> f64 {
        self.radiated_m3_s[0]
    }

    /// The board's radiating source of each channel after the last step (m^3/s).
    pub fn radiated_m3_s(&self) -> [f64; CHANNELS] {
        self.radiated_m3_s
    }

    /// Voice `k`'s forces, the bridge's velocity under it and the volume velocity of its key's
    /// board modes now (Eq. 19).
    pub fn observe_voice(&self, k: usize) -> Observation {
        let v = &self.voices[k];
        let (true, Some(key_index)) = (v.state.active, v.state.key) else {
            return Observation::default();
        };
        let key = v.face(&self.keys[key_index]);
        let mut obs = Observation {
            volume_velocity_m3_s: v.read[0],
            hammer_force_n: v.hammer_force_n(key),
            ..Observation::default()
        };
        let shared = self
            .board
            .velocity_at(&self.steps.part, &self.points[key_index].phi);
        let ns = key.n_strings as f64;
        for d in 0..3 {
            let own = v.read_z(&key.modes.bridge_velocity_row[d], &key.velocity_settle[d]);
            obs.bridge_velocity_m_s[d] = own + shared[d];
            obs.total_force_n[d] = v.force_n[d];
            // Every string's spring sees the same D: the direct part shared equally.
            let slope = (v.d[d] - v.d_before[d]) / self.h;
            let direct = (key.feed_k[d] * v.d[d] + key.feed_c[d] * slope) / ns;
            for s in 0..key.n_strings {
                obs.bridge_force_n[s][d] =
                    v.read_z(&key.modes.force_row[s][d], &key.force_settle[s][d]) - direct;
            }
        }
        obs
    }

    /// Bytes per voice of its state, and of the coefficients of the largest key it may play.
    pub fn bytes_per_voice(&self) -> usize {
        let state = 16 * self.voices[0].w.len();
        state + self.keys.iter().map(ExactKey::bytes).max().unwrap_or(0)
    }

    /// The linear state: per active voice the modes it steps (real, imaginary, shifted:
    /// [`super::key`])
    /// and what it remembers (`D^n`, the damper's force); then the shared board (modes, force).
    pub fn linear_state(&self) -> LinearState {
        let mut state = LinearState::default();
        for (k, v) in self.voices.iter().enumerate() {
            let (true, Some(key)) = (v.state.active, v.state.key) else {
                continue;
            };
            let key = &self.keys[key];
            let n = v.live_unpadded(key);
            state.push(Some(k), &v.w.re[..n], &key.modes.energy[..n]);
            state.push(Some(k), &v.w.im[..n], &key.modes.energy[..n]);
            let mut rest = v.d.to_vec();
            rest.extend_from_slice(&v.damper_n);
            state.push(Some(k), &rest, &vec![0.0; rest.len()]);
        }
        let board = self.steps.part.values();
        state.push(None, &board, &vec![1.0; board.len()]);
        state
    }

    /// Set the state [`ExactPool::linear_state`] reads, in the same layout.
    pub fn set_linear_state(&mut self, x: &[f64]) {
        let mut at = 0;
        let mut take = |n: usize| {
            at += n;
            &x[at - n..at]
        };
        for v in self.voices.iter_mut() {
            let (true, Some(key)) = (v.state.active, v.state.key) else {
                continue;
            };
            let key = &self.keys[key];
            let n = v.live_unpadded(key);
            v.energies = None;
            v.w.re[..n].copy_from_slice(take(n));
            v.w.im[..n].copy_from_slice(take(n));
            v.d.copy_from_slice(take(3));
            v.d_before = v.d;
            let c = v.damper_n.len();
            v.damper_n.copy_from_slice(take(c));
        }
        let m = 3 * self.board.modes();
        self.steps.part.set_values(take(m));
        self.heard.clear();
    }

    /// Mechanical energy of every active key's modes about their static deflection by the board
    /// ([`Voice::energies_now_j`]) and of the shared board (J, cycle-averaged per mode).
    pub fn mechanical_energy_j(&self) -> f64 {
        let keys = self
            .voices
            .iter()
            .map(|v| match (v.state.active, v.state.key) {
                (true, Some(key)) => v.energies_j(v.face(&self.keys[key]), self.simd)[1],
                _ => 0.0,
            });
        keys.sum::<f64>() + self.board_energy_j()
    }

    /// Take voice `k` off the board and set it at rest.
    fn rest_voice(&mut self, k: usize) {
        if self.voices[k].state.active {
            self.leave(k);
        }
        self.voices[k].rest();
        // A runaway's non-finite source is forgotten with it.
        self.heard.forget_non_finite();
    }
}

/// Where to split `voices` in two halves of about equal `work` (the first index of the second
/// half; 0 or `voices.len()` when one half would have nothing to do), and the work in all.
fn halves(voices: &[Voice], work: impl Fn(&Voice) -> usize) -> (usize, usize) {
    let total: usize = voices.iter().map(&work).sum();
    let (mut at, mut first) = (0, 0);
    while at < voices.len() && 2 * first < total {
        first += work(&voices[at]);
        at += 1;
    }
    (if first == total { voices.len() } else { at }, total)
}

/// The least [`step_work`] for which the steps are split over two cores: 16 voices in the block,
/// their damper lifted. Below it the two cores' meeting every sample costs more than the split
/// saves (docs/log/2026-12-02-two-cores-and-the-bench.md).
const MEET_FROM: usize = 16 * 16;

/// A voice's share of the steps of a block, in a voice in the block with its damper lifted (its
/// free reads and Markov sums, its force on the shared modes and their displacement at its
/// bridge): one with its damper down reads and remembers the felt's channels too (10 reads of 9
/// inputs' sums instead of 4 of 3), weighed 4 ×, where the halves' waits at the meetings come out
/// even; one stepped sample by sample (a hammer touching, a fade) advances every mode each step.
fn step_work(keys: &[ExactKey], v: &Voice) -> usize {
    let (true, Some(key)) = (v.state.active, v.state.key) else {
        return 0;
    };
    let key = v.face(&keys[key]);
    match (v.in_block, v.damped(key)) {
        (true, false) => 16,
        (true, true) => 64,
        (false, _) => v.live_modes(key) / 2,
    }
}

/// `there` and `here` on two cores through `pair` where it takes them, else both on this one. A
/// panic on either side is raised again here once both have stopped.
fn both(
    pair: Option<&dyn Pair>,
    there: &mut (dyn FnMut() + Send),
    here: &mut (dyn FnMut() + Send),
) {
    let joined = pair.is_some_and(|pair| {
        let mut panic = None;
        let mut guarded = || {
            if let Err(e) = catch_unwind(AssertUnwindSafe(&mut *there)) {
                panic = Some(e);
            }
        };
        let joined = pair.join(&mut guarded, here);
        if let Some(e) = panic {
            resume_unwind(e);
        }
        joined
    });
    if !joined {
        there();
        here();
    }
}

#[cfg(test)]
impl ExactPool {
    /// Voice `k`'s hammer position (m).
    pub(crate) fn hammer_position_m(&self, k: usize) -> f64 {
        self.voices[k].hammer_y
    }

    /// Which form of the loops to run.
    pub(crate) fn set_simd(&mut self, simd: Simd) {
        self.simd = simd;
    }

    /// Voices whose energies are kept from a block's end (`Some`) and, of those, how many differ
    /// from their energies worked out now.
    fn kept_and_stale_energies(&self) -> (usize, usize) {
        let kept: Vec<_> = self
            .voices
            .iter()
            .filter_map(|v| Some((v, v.energies?, v.face(&self.keys[v.state.key?]))))
            .collect();
        let stale = kept
            .iter()
            .filter(|(v, e, key)| *e != v.energies_now_j(key, self.simd))
            .count();
        (kept.len(), stale)
    }
}

/// The pool policy's hooks on the exact engine's voices.
impl Policy for ExactPool {
    fn n_voices(&self) -> usize {
        self.voices.len()
    }

    fn state(&self, k: usize) -> &VoiceState {
        &self.voices[k].state
    }

    fn state_mut(&mut self, k: usize) -> &mut VoiceState {
        &mut self.voices[k].state
    }

    fn voice_of_key(&self, key: usize) -> Option<usize> {
        self.voice_of_key[key]
    }

    fn set_voice_of_key(&mut self, key: usize, voice: Option<usize>) {
        self.voice_of_key[key] = voice;
    }

    fn fade_steps(&self) -> u32 {
        self.fade_steps
    }

    fn key_strings(&self, key: usize) -> usize {
        self.keys[key].n_strings
    }

    fn key_hammer(&self, key: usize) -> &HammerParams {
        &self.keys[key].hammer
    }

    fn key_has_damper(&self, key: usize) -> bool {
        self.keys[key].has_damper()
    }

    fn felt_share(&self, k: usize, lift: f64) -> f64 {
        let v = &self.voices[k];
        let Some(key) = v.state.key else {
            return 0.0;
        };
        let key = &self.keys[key];
        key.part_felt.as_ref().map_or(0.0, |felt| {
            felt.share(lift, &v.w, v.live_unpadded(v.face(key)))
        })
    }

    /// The voice steps with its key's face with the modal felt down from now on, or no longer
    /// ([`Voice::follow_damper`]).
    fn damper_moved(&mut self, k: usize) {
        let v = &mut self.voices[k];
        if let Some(key) = v.state.key {
            v.follow_damper(&self.keys[key]);
        }
        self.take_up(k);
    }

    /// The voice's coefficients are its key's (an index); its state starts at rest.
    fn load_key(&mut self, k: usize, _key: usize) {
        self.rest_voice(k);
    }

    fn rest_strings(&mut self, k: usize) {
        self.rest_voice(k);
    }

    /// A voice joins the board as it moves: its strings at their static deflection by the change
    /// in the board's motion under them since they left, its force added to the board's.
    fn enter(&mut self, k: usize) {
        // Active from here on (the policy marks it so after this hook).
        self.voices[k].state.active = true;
        self.take_up(k);
        let v = &mut self.voices[k];
        let Some(key) = v.state.key else {
            return;
        };
        let (point, key) = (&self.points[key], v.face(&self.keys[key]));
        let part = &mut self.steps.part;
        let now = self.board.at(part, point, self.simd);
        v.energies = None;
        let live = v.live_unpadded(key);
        for d in 0..3 {
            let change = now[d] - v.d[d];
            key.follow[d].add_range_to(&mut v.w, change, 0..live);
            key.settle[d].add_range_to(&mut v.w, -change, 0..live);
        }
        v.d = now;
        v.d_before = now;
        v.force_n = v.static_force_n(key);
        self.board.join(part, &point.phi, v.force_n, 1.0);
    }

    fn leave(&mut self, k: usize) {
        let v = &self.voices[k];
        if let Some(key) = v.state.key {
            let part = &mut self.steps.part;
            self.board
                .join(part, &self.points[key].phi, v.force_n, -1.0);
        }
    }

    /// Every voice whose steps are linear leaves out the chunks of modes that have died away
    /// ([`Voice::shed`]), keeping those the board drives while its damper is lifted; nothing
    /// where every mode is stepped, or while a coupled felt is down.
    fn shed_modes(&mut self) {
        if self.voice_modes != VoiceModes::AsHeard {
            return;
        }
        for v in self.voices.iter_mut() {
            let (true, Some(key)) = (v.state.active, v.state.key) else {
                continue;
            };
            let face = v.face(&self.keys[key]);
            if !v.is_linear() || v.damped(face) {
                continue;
            }
            let keep = if v.state.damper_down {
                0
            } else {
                face.sympathetic
            };
            v.shed(face, keep, LEFT_BELOW, LEFT_UNDER_J, self.simd);
        }
    }

    /// A struck voice steps every mode (the hammer drives them all), those it had left out
    /// taken up as they stood ([`Voice::keep_chunks`]).
    fn ready_to_strike(&mut self, k: usize) {
        let v = &mut self.voices[k];
        if let Some(key) = v.state.key {
            let face = v.face(&self.keys[key]);
            v.keep_chunks(face, face.chunks());
        }
    }

    fn strike_contact_m(&self, k: usize, struck: usize) -> f64 {
        let v = &self.voices[k];
        v.state.key.map_or(0.0, |key| {
            v.strike_contact_m(v.face(&self.keys[key]), struck)
        })
    }

    fn set_hammer(&mut self, k: usize, position_m: f64, velocity_m_s: f64) {
        let v = &mut self.voices[k];
        (v.hammer_y, v.hammer_v) = (position_m, velocity_m_s);
    }

    fn hammer_finite(&self, k: usize) -> bool {
        let v = &self.voices[k];
        v.hammer_y.is_finite() && v.hammer_v.is_finite()
    }

    fn voice_energy_j(&self, k: usize) -> f64 {
        let v = &self.voices[k];
        match (v.state.active, v.state.key) {
            (true, Some(key)) => v.energies_j(v.face(&self.keys[key]), self.simd)[0],
            _ => 0.0,
        }
    }

    fn board_energy_j(&self) -> f64 {
        self.board.energy_j(&self.steps.part)
    }

    /// The radiating source's filtered past forgotten ([`HeardSource::clear`]).
    fn forget_radiation(&mut self) {
        self.heard.clear();
    }

    /// The shared board at rest; each sounding voice's strings moved with it (to their static
    /// deflection by the board's new position under them, as a voice joining one), their forces
    /// on it its terms again — a board set at rest under strings that still feel it where it was
    /// would jolt them through their contact springs.
    fn rest_board(&mut self) {
        self.steps.part.rest();
        self.heard.clear_board();
        for k in 0..self.voices.len() {
            let v = &mut self.voices[k];
            v.force_n = [0.0; 3];
            if v.state.active && v.state.key.is_some() {
                self.enter(k);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::scaling::{parse_key, Scaling};
    use crate::engine::{Strike, UnisonSpec, VoicePool};

    /// The `grand` keyboard's specs of `names`, and its output rate.
    fn grand_keys(names: &[&str]) -> (Vec<UnisonSpec>, f64) {
        keyboard_keys("paper", names)
    }

    /// `keyboard`'s specs of `names`, and its output rate.
    fn keyboard_keys(keyboard: &str, names: &[&str]) -> (Vec<UnisonSpec>, f64) {
        let scaling = Scaling::resolve(keyboard).unwrap();
        let specs = names
            .iter()
            .map(|k| {
                let key = parse_key(k).unwrap();
                scaling.key_preset(key).unwrap().unison_spec()
            })
            .collect();
        (specs, scaling.base.output_rate_hz())
    }

    /// Voice `k` assigned key `k`, activated and struck with `strike`, for every voice.
    fn strike_every_voice(pool: &mut ExactPool, strike: Strike) {
        for k in 0..pool.voices.len() {
            pool.assign(k, k);
            pool.set_active(k, true);
            pool.strike_voice(k, strike);
        }
    }

    #[test]
    fn the_energies_kept_from_a_blocks_end_are_those_of_the_voices_as_they_are() {
        // Strikes, a damper lowered, a steal with its fade, blocks of uneven lengths, single
        // steps, the policy's retirements, the board set at rest and the state set anew: after
        // each, every energy kept from a block's end equals the voice's energy worked out now.
        let (specs, rate) = grand_keys(&["A0", "C2", "E3", "C4"]);
        let mut pool = ExactPool::build_pool(&specs, 3, rate).unwrap();
        let strike = Strike {
            velocity_m_s: 3.0,
            shift: 0.0,
        };
        let (mut kept, mut checks) = (0, 0);
        let mut check = |pool: &ExactPool, what: &str| {
            let (k, stale) = pool.kept_and_stale_energies();
            assert_eq!(stale, 0, "{stale} of {k} kept energies stale after {what}");
            kept += k;
            checks += 1;
        };
        let mut out = vec![[0.0; CHANNELS]; 300];
        strike_every_voice(&mut pool, strike);
        pool.run(&mut out[..100], None);
        check(&pool, "strikes and 100 steps");
        for _ in 0..16 {
            pool.run(&mut out, None);
        }
        check(&pool, "0.1 s: the hammers gone");
        pool.set_damper_voice(2, true);
        pool.run(&mut out[..70], None);
        check(&pool, "a damper lowered");
        pool.steal(1, 3, strike);
        check(&pool, "a steal");
        for n in [1, 5, 64, 200] {
            pool.run(&mut out[..n], None);
            check(&pool, "the fade");
        }
        pool.run(&mut out, None);
        pool.step();
        check(&pool, "a single step");
        pool.run(&mut out, None);
        pool.retire_silent(1e-3);
        check(&pool, "retirements");
        pool.run(&mut out, None);
        pool.rest_board();
        check(&pool, "the board set at rest");
        pool.run(&mut out, None);
        let x = pool.linear_state().x;
        pool.set_linear_state(&x.iter().map(|x| 0.5 * x).collect::<Vec<_>>());
        check(&pool, "the state set anew");
        pool.run(&mut out, None);
        pool.reset_runaways(0.0);
        check(&pool, "every voice reset");
        println!(
            "{checks} checks, {kept} energies kept from a block's end: each that of its voice now"
        );
        assert!(
            kept >= checks,
            "the energies are kept: {kept} in {checks} checks"
        );
    }

    #[test]
    fn a_run_after_which_nothing_reads_the_energies_leaves_them_to_be_worked_out() {
        // Told that nothing reads them, a run keeps no energy; the next run keeps them again
        // (the hint holds for one run), and a voice's energy read after the first is the same
        // worked out on demand.
        let (specs, rate) = grand_keys(&["C2", "C4"]);
        let mut pool = ExactPool::build_pool(&specs, 2, rate).unwrap();
        strike_every_voice(
            &mut pool,
            Strike {
                velocity_m_s: 3.0,
                shift: 0.0,
            },
        );
        let mut out = vec![[0.0; CHANNELS]; 64];
        for _ in 0..40 {
            pool.run(&mut out, None);
        }
        let mut twin = pool.clone();
        pool.energies_read_after_run(false);
        pool.run(&mut out, None);
        twin.run(&mut out, None);
        let (kept, _) = pool.kept_and_stale_energies();
        let (twin_kept, stale) = twin.kept_and_stale_energies();
        println!("energies kept after a run told nothing reads them: {kept}; after one not told: {twin_kept}");
        assert_eq!(kept, 0, "a run after which nothing reads them keeps none");
        assert_eq!(
            (twin_kept, stale),
            (2, 0),
            "a run keeps every voice's by default"
        );
        for k in 0..2 {
            assert_eq!(pool.voice_energy_j(k), twin.voice_energy_j(k), "voice {k}");
        }
        pool.run(&mut out, None);
        assert_eq!(
            pool.kept_and_stale_energies(),
            (2, 0),
            "the hint holds for one run"
        );
    }

    /// A modal felt that falls or rises changes the face a voice steps with, not its strings:
    /// at that instant every force and velocity of the voice at its bridge and its energy are
    /// what they were (the shifted state `w = z - a D` takes the new face's `a`; left as it was,
    /// they move by 2e-3 of themselves). Not its energy about the static deflection by `D`: the
    /// felt's first order moves each mode's static response `-g/lambda` a little.
    #[test]
    fn a_modal_felt_falling_or_rising_moves_nothing_at_that_instant() {
        let (specs, rate) = keyboard_keys("concert", &["C2", "C3"]);
        let mut pool = ExactPool::build_pool(&specs, 2, rate).unwrap();
        // Every mode stepped: what is observed string by string is then the whole state.
        pool.set_voice_modes(VoiceModes::All);
        for k in 0..2 {
            assert!(pool.keys[k].modal_felt.is_some() && pool.keys[k].damper.is_none());
            pool.assign(k, k);
            pool.set_active(k, true);
        }
        pool.strike_voice(
            0,
            Strike {
                velocity_m_s: 3.0,
                shift: 0.0,
            },
        );
        let mut out = vec![[0.0; CHANNELS]; (0.2 * rate) as usize];
        pool.run(&mut out, None);
        let seen = |pool: &ExactPool, k: usize| -> Vec<f64> {
            let obs = pool.observe_voice(k);
            let mut x = obs.bridge_velocity_m_s.to_vec();
            x.extend(obs.bridge_force_n.iter().flatten());
            // The energy at `z = w + a D` in double precision throughout (the policy's, from
            // single-precision shifts, rounds otherwise in each face).
            let v = &pool.voices[k];
            let key = v.face(&pool.keys[k]);
            let energy: f64 = (0..key.n_modes())
                .map(|m| {
                    let z = (0..3).fold((v.w.re[m], v.w.im[m]), |(re, im), d| {
                        let a = &key.settle[d];
                        (re + a.re[m] * v.d[d], im + a.im[m] * v.d[d])
                    });
                    key.modes.energy[m] * (z.0 * z.0 + z.1 * z.1)
                })
                .sum();
            x.push(energy);
            x
        };
        for (k, name) in [(0, "C2"), (1, "C3")] {
            let mut worst = 0f64;
            for down in [true, false] {
                let before = seen(&pool, k);
                pool.set_damper_voice(k, down);
                assert_eq!(pool.voices[k].modal_felt, down);
                let after = seen(&pool, k);
                for (a, b) in before.iter().zip(&after) {
                    worst = worst.max((a - b).abs() / a.abs().max(1e-30));
                }
                pool.run(&mut out[..100], None);
            }
            println!("{name}: damper down, then up: forces, velocities and energy move by {worst:.1e} of themselves");
            assert!(worst < 1e-9, "{name}: {worst:e}");
        }
        // A steal lifts a sounding voice's damper for its fade, and an assignment for its next
        // key: the face follows at once (the pool's policy writes `damper_down` there too).
        pool.set_damper_voice(0, true);
        let before = seen(&pool, 0);
        pool.steal(
            0,
            1,
            Strike {
                velocity_m_s: 1.0,
                shift: 0.0,
            },
        );
        assert!(
            !pool.voices[0].modal_felt,
            "the stolen voice's felt is lifted"
        );
        let after = seen(&pool, 0);
        let moved = before
            .iter()
            .zip(&after)
            .map(|(a, b)| (a - b).abs() / a.abs().max(1e-30))
            .fold(0f64, f64::max);
        println!("C2 stolen with its damper down: its state moves by {moved:.1e} of itself");
        assert!(moved < 1e-9, "{moved:e}");
        pool.set_damper_voice(1, true);
        pool.assign(1, 0);
        assert!(
            !pool.voices[1].modal_felt,
            "an assigned voice's felt is lifted"
        );
    }

    #[test]
    fn a_block_advanced_mode_by_mode_equals_its_steps() {
        // C2 struck, C3 held (free after the first block), E3 struck with its damper down:
        // 0.5 s by blocks of 64 (single precision inside each, double from block to block)
        // against 0.5 s of single steps in double precision, heard in stereo.
        let (mut specs, rate) = grand_keys(&["C2", "C3", "E3"]);
        for s in &mut specs {
            let board = &mut s.board;
            board.heard = ["bass", "treble"].map(|l| board.listener(l));
            assert!(board.is_stereo());
        }
        let mut blocks = ExactPool::build_pool(&specs, 3, rate).unwrap();
        blocks.set_voice_modes(VoiceModes::All);
        for k in 0..3 {
            blocks.assign(k, k);
            blocks.set_active(k, true);
        }
        let strike = Strike {
            velocity_m_s: 3.0,
            shift: 0.0,
        };
        blocks.strike_voice(0, strike);
        blocks.strike_voice(2, strike);
        blocks.set_damper_voice(2, true);
        let mut steps = blocks.clone();
        let n = (0.5 * rate) as usize;
        let mut a = vec![[0.0; CHANNELS]; n];
        let mut ones = blocks.clone();
        blocks.run(&mut a, None);
        let a = a.concat();
        let c: Vec<f64> = (0..n)
            .flat_map(|_| {
                let mut x = [[0.0; CHANNELS]];
                ones.run(&mut x, None);
                x[0]
            })
            .collect();
        let b: Vec<f64> = (0..n)
            .flat_map(|_| {
                steps.step();
                steps.radiated_m3_s()
            })
            .collect();
        let peak = b.iter().fold(0f64, |m, x| m.max(x.abs()));
        let worst = a
            .iter()
            .zip(&b)
            .fold(0f64, |m, (x, y)| m.max((x - y).abs()))
            / peak;
        let ones_worst = c
            .iter()
            .zip(&b)
            .fold(0f64, |m, (x, y)| m.max((x - y).abs()))
            / peak;
        println!("blocks of one step vs single steps, 0.5 s: both channels {ones_worst:.1e} of their peak (f32 rounding of each block's inputs, compounded over more blocks)");
        assert!(ones_worst < 1e-4, "{ones_worst:e}");
        let state = |p: &ExactPool| p.linear_state().x;
        let (sa, sb) = (state(&blocks), state(&steps));
        let scale = sb.iter().fold(0f64, |m, x| m.max(x.abs()));
        let state_worst = sa
            .iter()
            .zip(&sb)
            .fold(0f64, |m, (x, y)| m.max((x - y).abs()))
            / scale;
        println!(
            "blocks of {BLOCK} mode by mode vs single steps, 0.5 s: both channels {worst:.1e} of their peak, state {state_worst:.1e}"
        );
        // f32 inside a block: ~1e-7 per step, not compounded from block to block.
        assert!(
            worst < 1e-5 && state_worst < 1e-5,
            "{worst:e} {state_worst:e}"
        );
    }
}
