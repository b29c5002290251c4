//! Many keys on the exact engine: a bank of prepared keys and a fixed pool of voices on one
//! shared board, with the same behaviour as the other pools ([`Policy`]: assign, steal with a
//! fade, strike in the current motion, dampers, silent voices retired, runaways reset).

use super::board::BoardCoupling;
use super::halves::{run_alone, run_half, Context, Exchange, Half};
use super::kernels::BLOCK;
use super::key::ExactKey;
use super::voice::Voice;
use crate::engine::kernels::has_avx2_fma;
use crate::engine::pool::{Policy, VoiceState};
use crate::engine::spec::{BuildError, LinearState, Observation, UnisonSpec, STEAL_FADE_S};
use crate::engine::Pair;
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::atomic::Ordering;

/// Voices of up to 88 keys on one shared soundboard, each key integrated exactly in its coupled
/// modes, the keys coupled through the board ([`super::board`]). Stepped by the thread that owns it.
#[derive(Debug, Clone)]
pub struct ExactPool {
    keys: Vec<ExactKey>,
    /// Each key's mode shapes at its bridge point, on the modes the keys are coupled through.
    points: Vec<[Vec<f64>; 3]>,
    voices: Vec<Voice>,
    voice_of_key: Vec<Option<usize>>,
    board: BoardCoupling,
    /// Each half's working values and replica of the board's shared part (half 0's is the
    /// pool's between blocks), and what the halves hand each other on two cores.
    halves: [Half; 2],
    exchange: Exchange,
    h: f64,
    fade_steps: u32,
    fast_path: bool,
    /// The board's net volume velocity after the last step (m^3/s).
    volume_velocity_m3_s: f64,
}

impl ExactPool {
    /// One key diagonalised at `spec.sample_rate_hz` (the costly part of building, independent
    /// from key to key).
    pub fn prepare_key(spec: &UnisonSpec) -> Result<ExactKey, BuildError> {
        ExactKey::new(spec)
    }

    /// The pool for `specs` (one per key, in order with `keys`) with `voices` voices.
    pub fn from_keys(
        specs: &[UnisonSpec],
        keys: Vec<ExactKey>,
        voices: usize,
    ) -> Result<ExactPool, BuildError> {
        let first = crate::engine::pool::check_keys(specs, keys.len(), voices)?;
        let h = 1.0 / first.sample_rate_hz;
        let modes = keys.iter().map(ExactKey::n_modes).max().unwrap_or(0);
        let board = BoardCoupling::new(&first.board, h);
        let points = specs
            .iter()
            .map(|s| {
                s.board
                    .points
                    .get(s.bridge_point)
                    .map(|p| board.restrict(&p.shape))
                    .ok_or(BuildError::BridgePoint(s.bridge_point))
            })
            .collect::<Result<_, _>>()?;
        Ok(ExactPool {
            points,
            voice_of_key: vec![None; keys.len()],
            voices: vec![Voice::new(modes, board.modes()); voices],
            keys,
            halves: [Half::new(modes, &board), Half::new(modes, &board)],
            exchange: Exchange::new(board.modes()),
            board,
            h,
            fade_steps: ((STEAL_FADE_S / h).round() as u32).max(1),
            fast_path: has_avx2_fma(),
            volume_velocity_m3_s: 0.0,
        })
    }

    pub fn step_s(&self) -> f64 {
        self.h
    }

    /// One step of every active voice, each one sample at a time ([`Voice::step`]), then of the
    /// board coupling.
    pub fn step(&mut self) {
        for v in self.voices.iter_mut() {
            v.in_block = false;
        }
        let mut out = [0.0];
        let cx = Context {
            keys: &self.keys,
            points: &self.points,
            board: &self.board,
            fade_steps: self.fade_steps,
            fast: self.fast_path,
        };
        run_alone(
            &cx,
            [&mut self.voices, &mut []],
            &mut self.halves,
            &mut out,
            false,
        );
        self.volume_velocity_m3_s = out[0];
        self.finish_fades();
    }

    /// Advance `volume_velocity.len()` steps, writing the board's net volume velocity after each,
    /// in blocks of up to [`BLOCK`] steps ([`ExactPool::block`]) that end where a stolen voice's
    /// fade does (so that its next key starts between blocks); the voices split in two halves
    /// over two cores through `pair` (the same result bit for bit: [`super::halves`]).
    pub fn run(&mut self, volume_velocity: &mut [f64], pair: Option<&dyn Pair>) {
        let mut done = 0;
        while done < volume_velocity.len() {
            let fade = self
                .voices
                .iter()
                .filter(|v| v.state.active && v.state.fade_left > 0)
                .map(|v| v.state.fade_left as usize)
                .min()
                .unwrap_or(BLOCK);
            let n = (volume_velocity.len() - done).min(BLOCK).min(fade);
            self.block(&mut volume_velocity[done..done + n], pair);
            self.finish_fades();
            done += n;
        }
    }

    /// Every voice whose fade has ended takes its next key.
    fn finish_fades(&mut self) {
        for k in 0..self.voices.len() {
            self.complete_fade(k);
        }
    }

    /// `out.len()` (at most [`BLOCK`]) steps, the same as as many [`ExactPool::step`]s but for
    /// rounding. A voice whose steps are linear and time-invariant ([`Voice::is_free`]: no hammer,
    /// damper or fade) is advanced mode by mode over the whole block — each mode's coefficients
    /// loaded once, not once a step — and gets the coupling back by superposition: its reads
    /// from its own Markov parameters step by step (the board needs them), its modes from the
    /// inputs folded in at the end — one input per direction, in the shifted state
    /// [`ExactKey::block_alpha`] describes. The others step one sample at a time, as in `step`.
    fn block(&mut self, out: &mut [f64], pair: Option<&dyn Pair>) {
        let len = out.len();
        for v in self.voices.iter_mut() {
            v.in_block = match (v.state.active, v.state.key) {
                (true, Some(key)) => v.is_free(&self.keys[key]),
                _ => false,
            };
        }
        // A voice's work over the block: its modes, a voice stepped sample by sample costing
        // about three in the block.
        let work = |v: &Voice| match (v.state.active, v.state.key) {
            (true, Some(key)) => self.keys[key].n_modes() * if v.in_block { 1 } else { 3 },
            _ => 0,
        };
        let total: usize = self.voices.iter().map(work).sum();
        // Two halves of about equal work, in voice order.
        let (mut at, mut first) = (0, 0);
        while at < self.voices.len() && 2 * first < total {
            first += work(&self.voices[at]);
            at += 1;
        }
        let cx = Context {
            keys: &self.keys,
            points: &self.points,
            board: &self.board,
            fade_steps: self.fade_steps,
            fast: self.fast_path,
        };
        let (v0, v1) = self.voices.split_at_mut(at);
        let joined = match pair {
            Some(pair) if first > 0 && first < total => {
                let [h0, h1] = &mut self.halves;
                h1.part.copy_from(&h0.part);
                self.exchange.reset();
                let ex = &self.exchange;
                // A panic on either side abandons the meetings, so the other side cannot wait
                // forever, and is raised again here once both have stopped.
                let mut panic = [None, None];
                let [p0, p1] = &mut panic;
                let cx = &cx;
                let out = &mut *out;
                let (v0, v1) = (&mut *v0, &mut *v1);
                let mut there = || {
                    let run = AssertUnwindSafe(|| run_half(cx, 1, v1, h1, ex, None, len));
                    if let Err(e) = catch_unwind(run) {
                        ex.abandoned.store(true, Ordering::Relaxed);
                        *p1 = Some(e);
                    }
                };
                let mut here = || {
                    let run = AssertUnwindSafe(|| run_half(cx, 0, v0, h0, ex, Some(out), len));
                    if let Err(e) = catch_unwind(run) {
                        ex.abandoned.store(true, Ordering::Relaxed);
                        *p0 = Some(e);
                    }
                };
                let joined = pair.join(&mut there, &mut here);
                if let Some(e) = panic.into_iter().flatten().next() {
                    resume_unwind(e);
                }
                joined
            }
            _ => false,
        };
        if !joined {
            run_alone(&cx, [v0, v1], &mut self.halves, out, true);
        }
        self.volume_velocity_m3_s = out[len - 1];
    }

    pub fn volume_velocity_m3_s(&self) -> f64 {
        self.volume_velocity_m3_s
    }

    /// Voice `k`'s forces and its part of the volume velocity now (Eq. 19).
    pub fn observe_voice(&self, k: usize) -> Observation {
        let v = &self.voices[k];
        let (true, Some(key)) = (v.state.active, v.state.key) else {
            return Observation::default();
        };
        let key = &self.keys[key];
        let c = v.state.coupling;
        let mut obs = Observation {
            volume_velocity_m3_s: c * v.read[0],
            hammer_force_n: v.hammer_force_n(key),
            ..Observation::default()
        };
        let ns = key.n_strings as f64;
        for d in 0..3 {
            let slope = (v.other_m[d] - v.other_before_m[d]) / self.h;
            obs.bridge_velocity_m_s[d] = key.bridge_velocity_row[d].read(&v.z) + slope;
            obs.total_force_n[d] = v.force_n[d];
            // The total's direct part, shared equally: every string's spring sees the same D.
            let direct = (key.feed_k[d] * v.other_m[d] + key.feed_c[d] * slope) / ns;
            for s in 0..key.n_strings {
                obs.bridge_force_n[s][d] = c * (key.force_row[s][d].read(&v.z) - direct);
            }
        }
        obs
    }

    /// Bytes per voice of its state, and of the coefficients of the largest key it may play.
    pub fn bytes_per_voice(&self) -> usize {
        let v = &self.voices[0];
        let state = 16 * (v.z.len() + v.own_board.len());
        state + self.keys.iter().map(ExactKey::bytes).max().unwrap_or(0)
    }

    /// The linear state: per active voice its modes (real, imaginary), its own board part, the
    /// coupling input it remembers and its last forces; then the shared board part.
    pub fn linear_state(&self) -> LinearState {
        let mut state = LinearState::default();
        for (k, v) in self.voices.iter().enumerate() {
            let (true, Some(key)) = (v.state.active, v.state.key) else {
                continue;
            };
            let key = &self.keys[key];
            let n = key.n_modes();
            state.push(Some(k), &v.z.re[..n], &key.energy);
            state.push(Some(k), &v.z.im[..n], &key.energy);
            let rest = Self::memory(v);
            state.push(Some(k), &rest, &vec![0.0; rest.len()]);
        }
        let board = self.halves[0].part.state();
        state.push(None, &board, &vec![1.0; board.len()]);
        state
    }

    /// A voice's memory beyond its modes, as plain numbers.
    fn memory(v: &Voice) -> Vec<f64> {
        let mut x = v.own_board.re.clone();
        x.extend_from_slice(&v.own_board.im);
        x.extend_from_slice(&v.other_m);
        x.extend_from_slice(&v.other_before_m);
        x.extend_from_slice(&v.force_n);
        x.extend_from_slice(&v.damper_n);
        x
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
            let n = self.keys[key].n_modes();
            v.z.re[..n].copy_from_slice(take(n));
            v.z.im[..n].copy_from_slice(take(n));
            let m = v.own_board.len();
            v.own_board.re.copy_from_slice(take(m));
            v.own_board.im.copy_from_slice(take(m));
            v.other_m.copy_from_slice(take(3));
            v.other_before_m.copy_from_slice(take(3));
            v.force_n.copy_from_slice(take(3));
            let c = v.damper_n.len();
            v.damper_n.copy_from_slice(take(c));
        }
        let m = 3 * self.board.modes();
        self.halves[0].part.set_state(take(m));
    }

    /// Mechanical energy of every active key's modes (J; each key's copy of the board in it,
    /// cycle-averaged per mode).
    pub fn mechanical_energy_j(&self) -> f64 {
        (0..self.voices.len()).map(|k| self.voice_energy_j(k)).sum()
    }

    /// Remove voice `k`'s part from the shared board and set it at rest.
    fn rest_voice(&mut self, k: usize) {
        let v = &mut self.voices[k];
        if v.state.active {
            if let Some(key) = v.state.key {
                let part = &mut self.halves[0].part;
                self.board
                    .join(part, &v.own_board, &self.points[key], v.force_n, -1.0);
            }
        }
        v.rest();
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

    fn key_has_damper(&self, key: usize) -> bool {
        self.keys[key].damper.is_some()
    }

    /// The voice's coefficients are its key's (an index); its state starts at rest.
    fn load_key(&mut self, k: usize, _key: usize) {
        self.rest_voice(k);
    }

    fn rest_strings(&mut self, k: usize) {
        self.rest_voice(k);
    }

    /// A voice joins on the board as the other keys move it: its strings at their static
    /// deflection by the change in that motion since it left, its own part added to the shared.
    fn enter(&mut self, k: usize) {
        let v = &mut self.voices[k];
        let Some(key) = v.state.key else {
            return;
        };
        let (point, key) = (&self.points[key], &self.keys[key]);
        let part = &mut self.halves[0].part;
        let now = self.board.shared_at(part, self.fast_path, point);
        for (d, follow) in key.follow.iter().enumerate() {
            follow.add_to(&mut v.z, now[d] - v.other_m[d]);
        }
        v.other_m = now;
        v.other_before_m = now;
        self.board.join(part, &v.own_board, point, v.force_n, 1.0);
    }

    fn leave(&mut self, k: usize) {
        let v = &self.voices[k];
        if let Some(key) = v.state.key {
            let part = &mut self.halves[0].part;
            self.board
                .join(part, &v.own_board, &self.points[key], v.force_n, -1.0);
        }
    }

    fn strike_contact_m(&self, k: usize, struck: usize) -> f64 {
        let v = &self.voices[k];
        v.state
            .key
            .map_or(0.0, |key| v.strike_contact_m(&self.keys[key], struck))
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
            (true, Some(key)) => v.energy_j(&self.keys[key]),
            _ => 0.0,
        }
    }

    fn board_energy_j(&self) -> f64 {
        self.board.energy_j(&self.halves[0].part)
    }

    /// The shared part at rest, and every voice's own part with it (they are its terms).
    fn rest_board(&mut self) {
        self.halves[0].part.rest();
        for v in &mut self.voices {
            v.own_board.fill_zero();
            v.force_n = [0.0; 3];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::scaling::{parse_key, Scaling};
    use crate::engine::{Strike, VoicePool};

    #[test]
    fn a_block_advanced_mode_by_mode_equals_its_steps() {
        // C2 struck, C3 held (free after the first block), E3 struck with its damper down:
        // 0.5 s by blocks of 64 (single precision inside each, double from block to block)
        // against 0.5 s of single steps in double precision.
        let scaling = Scaling::resolve("grand").unwrap();
        let rate = scaling.base.output_rate_hz();
        let specs: Vec<_> = ["C2", "C3", "E3"]
            .iter()
            .map(|k| {
                scaling
                    .key_preset(parse_key(k).unwrap())
                    .unwrap()
                    .unison_spec()
            })
            .collect();
        let mut blocks = ExactPool::build_pool(&specs, 3, rate).unwrap();
        for k in 0..3 {
            blocks.assign(k, k);
            blocks.set_active(k, true);
        }
        let strike = Strike {
            velocity_m_s: 3.0,
            una_corda: false,
        };
        blocks.strike_voice(0, strike);
        blocks.strike_voice(2, strike);
        blocks.set_damper_voice(2, true);
        let mut steps = blocks.clone();
        let n = (0.5 * rate) as usize;
        let mut a = vec![0.0; n];
        let mut ones = blocks.clone();
        blocks.run(&mut a, None);
        let c: Vec<f64> = (0..n)
            .map(|_| {
                let mut x = [0.0];
                ones.run(&mut x, None);
                x[0]
            })
            .collect();
        let b: Vec<f64> = (0..n)
            .map(|_| {
                steps.step();
                steps.volume_velocity_m3_s()
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
        println!("blocks of one step vs single steps, 0.5 s: volume velocity {ones_worst:.1e} of its peak (f32 rounding of each block's inputs, compounded over more blocks)");
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
            "blocks of {BLOCK} mode by mode vs single steps, 0.5 s: volume velocity {worst:.1e} of its peak, state {state_worst:.1e}"
        );
        // f32 inside a block: ~1e-7 per step, not compounded from block to block.
        assert!(
            worst < 1e-5 && state_worst < 1e-5,
            "{worst:e} {state_worst:e}"
        );
    }
}
