//! The live integrator: exponential RK4 (ETDRK4) on the system's complex modes, for a pool of
//! voices on one shared board at the output rate.
//!
//! RK4 at 96 kHz is limited by the stiffest coupled mode — a string's end bouncing on its contact
//! spring, ≈ 22 kHz, far above anything audible — and by the duplex matrix (Eq. 13), dense in the
//! string's modes. Both are linear and belong to one string direction, so they are moved into the
//! exactly integrated part: for each string direction the second-order block
//! ```text
//! qdd = -(Omega^2 + k psi psi^T) q - (C_m + C_d + c psi psi^T) qdot + psi u_bridge + ...
//! ```
//! (the string on its contact spring against a *fixed* bridge, Eq. 6 and 13) is diagonalised once
//! into complex modes `x = V z`, `z' = Lambda z + V^-1 b u`, and advanced exactly by `e^{Lambda h}`.
//! The board's modes are diagonal already.
//!
//! The strings are advanced relative to their static deflection by the bridge, `q^ = q - g y`
//! with `K g = k psi` ([`Statics`]): a string's end follows the board through its stiff contact
//! spring within a sample or two, so in `q` itself the board would feel every string's `k`
//! (with nine keys sounding, 340 × the first board mode's own stiffness) explicitly, cancelled
//! but for ~1/1000 by the strings' response — and ETDRK4's error on those two large terms acted
//! as negative damping on the board's modes (a runaway with chords: `tests/stability.rs`). In
//! `q^` the two cancel exactly and what stays explicit, at fourth order, is small: the contact
//! spring in series with the string, the string's mass moving with the bridge and the damping of
//! that motion, the felt hammer (Eq. 8) and the damper felt. RK4 at the paper's rate stays the
//! reference ([`crate::engine::Rk4Pool`]); `tests/integrators.rs` compares.
//!
//! ETDRK4 (Cox & Matthews 2002) for `y' = L y + N(y)`, `E = e^{L h/2}`, `Q = (E - 1) L^-1`:
//! `a = E y + Q N(y)`, `b = E y + Q N(a)`, `c = E² y + (E - 1) Q N(y) + 2 Q N(b)`,
//! `y⁺ = E² y + f1 N(y) + f2 (N(a) + N(b)) + f3 N(c)`. (Lawson's integrating-factor RK4 on the
//! same split is 2 cents and 50 % in decay rates off at 48 kHz: it forces the stiff contact mode
//! explicitly; ETD's weights integrate that forcing exactly.) Every explicit force enters through
//! a few input vectors `g_j = V^-1 b_j` and is read through a few output rows `r_o = c_o V`, so the
//! stage states are never formed: each stage output is a dot product of the step's starting `z`
//! with a precomputed row (`r`, `r E` or `r E²`) plus precomputed scalar responses to the earlier
//! stages' inputs. The board, whose modes are known in closed form, is formed once per stage as
//! modal displacements and velocities (and, once every voice's force is known, accelerations) and
//! read at each voice's point ([`Board`]).

use crate::engine::kernels::has_avx2_fma;
use crate::engine::pool::{Policy, VoiceState};
use crate::engine::spec::Direction;
use crate::engine::spec::{BuildError, Observation, Strike, UnisonSpec, STEAL_FADE_S};
use crate::engine::Pair;
use std::panic::AssertUnwindSafe;
use std::sync::atomic::Ordering;

mod board;
mod kernels;
mod keys;
mod split;
mod voices;
use board::*;
use kernels::*;
pub use keys::PreparedKey;
use keys::*;
use split::*;
use voices::*;

/// Strings of up to 88 keys on one shared soundboard, advanced by ETDRK4 at the output rate: a
/// bank of keys and a fixed pool of voices with the same behaviour as [`crate::engine::Rk4Pool`] (assign,
/// steal with a fade, strike in the current motion, dampers, silent voices retired, runaways reset).
/// Voices `k` live in half `k % 2`; [`EtdPool::run`] advances the halves on two
/// cores when given a [`Pair`], in turn on one otherwise, with the same result.
#[derive(Debug, Clone)]
pub struct EtdPool {
    keys: Vec<EtdKey>,
    halves: [Half; 2],
    exchange: Exchange,
    voice_of_key: Vec<Option<usize>>,
    n_voices: usize,
    h: f64,
    fade_steps: u32,
    fast_path: bool,
}

impl EtdPool {
    /// Several keys on one shared soundboard and a pool of `voices` voices, stepping at each
    /// spec's `sample_rate_hz` (the output rate).
    pub fn with_pool(specs: &[UnisonSpec], voices: usize) -> Result<EtdPool, BuildError> {
        let strings = specs
            .iter()
            .map(Self::prepare_key)
            .collect::<Result<_, _>>()?;
        Self::from_keys(specs, strings, voices)
    }

    /// One key's strings diagonalised and their propagators formed at `spec.sample_rate_hz`: the
    /// costly part of building, independent from key to key (a caller may prepare keys on
    /// several threads, then call [`EtdPool::from_keys`]).
    pub fn prepare_key(spec: &UnisonSpec) -> Result<PreparedKey, BuildError> {
        key_strings(spec, 1.0 / spec.sample_rate_hz).map(PreparedKey)
    }

    /// The pool of [`EtdPool::with_pool`] from keys already prepared, one per spec.
    pub fn from_keys(
        specs: &[UnisonSpec],
        strings: Vec<PreparedKey>,
        voices: usize,
    ) -> Result<EtdPool, BuildError> {
        let first = crate::engine::pool::check_keys(specs, strings.len(), voices)?;
        let h = 1.0 / first.sample_rate_hz;
        let board = &first.board;
        let mut keys = Vec::with_capacity(specs.len());
        for (spec, PreparedKey(strings)) in specs.iter().zip(strings) {
            let point = board
                .points
                .get(spec.bridge_point)
                .ok_or(BuildError::BridgePoint(spec.bridge_point))?;
            keys.push(EtdKey::new(strings, spec, &point.shape));
        }
        let nk = keys.len();
        // Voice state sized for the largest key in each direction.
        let cap: [usize; 3] = std::array::from_fn(|d| {
            keys.iter()
                .flat_map(|k| k.strings.iter().map(move |s| s[d].e_full[0].len()))
                .max()
                .unwrap_or(0)
        });
        let voice = Voice {
            state: VoiceState::default(),
            z: std::array::from_fn(|_| std::array::from_fn(|d| ComplexState::zeros(cap[d]))),
            hammer_y: 0.0,
            hammer_v: 0.0,
        };
        let board = Board::new(board, h);
        let halves = std::array::from_fn(|half| {
            let n = (voices + 1 - half) / 2;
            Half {
                set: VoiceSet {
                    voices: vec![voice.clone(); n],
                    work: vec![Work::default(); n],
                    live: Vec::with_capacity(n),
                },
                board: board.clone(),
                steps: 0,
            }
        });
        Ok(EtdPool {
            exchange: Exchange::new(board.zr.len()),
            halves,
            keys,
            voice_of_key: vec![None; nk],
            n_voices: voices,
            h,
            fade_steps: ((STEAL_FADE_S / h).round() as u32).max(1),
            fast_path: has_avx2_fma(),
        })
    }

    fn voice(&self, k: usize) -> &Voice {
        &self.halves[k % 2].set.voices[k / 2]
    }

    fn voice_mut(&mut self, k: usize) -> &mut Voice {
        &mut self.halves[k % 2].set.voices[k / 2]
    }

    fn board(&self) -> &Board {
        &self.halves[0].board
    }

    /// Number of voices in the pool.
    pub fn n_voices(&self) -> usize {
        self.n_voices
    }

    /// Step (s).
    pub fn step_s(&self) -> f64 {
        self.h
    }

    /// Voice 0's strike (one-key use).
    pub fn strike(&mut self, strike: Strike) {
        self.strike_voice(0, strike);
    }

    /// Voice 0's damper.
    pub fn set_damper(&mut self, down: bool) {
        self.set_damper_voice(0, down);
    }

    /// Mechanical energy of the strings, their contact springs and the board (J), hammers apart.
    pub fn mechanical_energy_j(&self) -> f64 {
        let voices: f64 = (0..self.n_voices).map(|k| self.strings_energy_j(k)).sum();
        self.board().energy_j() + voices
    }

    /// Mechanical energy of voice `k`'s strings and contact springs (J; 0 while it is not
    /// simulated): what decides when a voice has fallen silent and which voice is the quietest.
    /// In the coordinates `q^ = q - g y` ([`Statics`]) each string direction holds
    /// `E_K(q^) + y' g.q^dot + 1/2 g.g y'^2 + 1/2 k (1 - psi.g) y^2` (with the fade's coupling
    /// `c < 1`: `-(1 - c)/2 k (psi.q^)^2 + (1 - c) k (1 - psi.g) y psi.q^` more, and `c` on the
    /// contact's share of the last term), `E_K` the energy of its modes on the contact spring
    /// against a fixed bridge and `y` the board's displacement at the key's point: a string at
    /// rest on a moving board holds the energy of following it, and is not silent.
    fn strings_energy_j(&self, k: usize) -> f64 {
        let v = self.voice(k);
        let (true, Some(key)) = (v.state.active, v.state.key) else {
            return 0.0;
        };
        let (board, km) = (self.board(), &self.keys[key]);
        let at: [(f64, f64); 3] = std::array::from_fn(|d| board.at(&km.board_shape[d]));
        let c = v.state.coupling;
        let mut e = 0.0;
        for (s, blocks) in km.strings.iter().enumerate() {
            for (d, b) in blocks.iter().enumerate() {
                let (z, (y, yv)) = (&v.z[s][d], at[d]);
                let (st, kc) = (&b.statics, km.contact.stiffness_n_m[d]);
                let rest = 1.0 - st.bridge;
                let psi_q = read(&b.rows[BRIDGE_Q][0], z);
                e += energy_j(&b.energy, z)
                    + yv * read(&b.g_row, z)
                    + 0.5 * st.mass_kg * yv * yv
                    + 0.5 * kc * rest * y * y * (st.bridge + c * rest)
                    - 0.5 * (1.0 - c) * kc * psi_q * psi_q
                    + (1.0 - c) * kc * rest * y * psi_q;
            }
        }
        e
    }

    /// Net volume velocity of the board (m^3/s).
    pub fn volume_velocity_m3_s(&self) -> f64 {
        self.board().volume_velocity()
    }

    /// Forces of voice `k` and the board's velocity at its point, now (Eq. 19).
    pub fn observe_voice(&self, k: usize) -> Observation {
        let mut obs = Observation {
            volume_velocity_m3_s: self.volume_velocity_m3_s(),
            ..Observation::default()
        };
        let v = self.voice(k);
        let Some(key) = v.state.key else {
            return obs;
        };
        let km = &self.keys[key];
        let mut rb = [[0.0; 2]; 3];
        for (d, rb) in rb.iter_mut().enumerate() {
            let (q, v) = self.board().at(&km.board_shape[d]);
            *rb = [q, v];
            obs.bridge_velocity_m_s[d] = rb[1];
        }
        for (s, blocks) in km.strings.iter().enumerate() {
            for d in 0..3 {
                let (b, z) = (&blocks[d], &v.z[s][d]);
                let rest = 1.0 - b.statics.bridge;
                let f = v.state.coupling
                    * km.contact.force_n(
                        d,
                        read(&b.rows[BRIDGE_Q][0], z) - rest * rb[d][0],
                        read(&b.rows[BRIDGE_V][0], z) - rest * rb[d][1],
                    );
                obs.bridge_force_n[s][d] = f;
                obs.total_force_n[d] += f;
            }
            if v.state.hammer_on && v.state.struck[s] {
                let ye = strike_point(km, s, &v.z[s][0], rb[0][0]);
                obs.hammer_force_n[s] = km.hammer.felt_force_n(v.hammer_y - ye);
            }
        }
        obs
    }

    /// Voice 0's outputs.
    pub fn observe(&self) -> Observation {
        self.observe_voice(0)
    }

    /// Advance one step of ETDRK4 over the active voices and the board; never allocates.
    pub fn step(&mut self) {
        self.run(&mut [0.0], None);
    }

    /// Advance `volume_velocity.len()` steps, writing the board's net volume velocity (m^3/s)
    /// after each; the two halves of the pool on two cores through `pair`, in turn without one
    /// (the same result bit for bit). Never allocates.
    pub fn run(&mut self, volume_velocity: &mut [f64], pair: Option<&dyn Pair>) {
        let mut done = 0;
        while done < volume_velocity.len() {
            // Chunks end where a stolen voice's fade does, so its next key starts between steps.
            let fade = self.halves.iter().flat_map(|h| &h.set.voices);
            let fade = fade
                .filter(|v| v.state.fade_left > 0)
                .map(|v| v.state.fade_left as usize);
            let n = fade.min().unwrap_or(usize::MAX);
            let n = n.min(volume_velocity.len() - done);
            for half in &mut self.halves {
                let set = &mut half.set;
                set.live.clear();
                for (i, v) in set.voices.iter().enumerate() {
                    if v.state.active && v.state.key.is_some() {
                        set.live.push(i);
                    }
                }
            }
            let out = &mut volume_velocity[done..done + n];
            match pair {
                Some(pair) if self.halves.iter().all(|h| !h.set.live.is_empty()) => {
                    if !self.run_split(out, pair) {
                        self.run_alone(out);
                    }
                }
                _ => self.run_alone(out),
            }
            self.finish_fades();
            done += n;
        }
    }

    /// Both halves in turn, stage by stage, on this core.
    fn run_alone(&mut self, out: &mut [f64]) {
        #[cfg(target_arch = "x86_64")]
        if self.fast_path {
            // SAFETY: `fast_path` is set only when the CPU reports AVX2 and FMA.
            unsafe { self.run_alone_avx2(out) };
            return;
        }
        self.run_alone_impl::<false>(out);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn run_alone_avx2(&mut self, out: &mut [f64]) {
        self.run_alone_impl::<true>(out);
    }

    /// Both halves' voices against half 0's board replica, each half's forces summed as on two
    /// cores (half 1's replica is brought up to date when the halves next split).
    #[inline(always)]
    fn run_alone_impl<const FMA: bool>(&mut self, out: &mut [f64]) {
        let (keys, h, fade) = (&self.keys, self.h, self.fade_steps);
        let [h0, h1] = &mut self.halves;
        for q in out {
            h0.set.begin::<FMA>(keys);
            h1.set.begin::<FMA>(keys);
            h0.board.read_start();
            for (stage, plan) in ETDRK4_STAGES.iter().enumerate() {
                let b0 = &mut h0.board;
                b0.form_stage::<FMA>(plan.0, &plan.1);
                h0.set
                    .stage::<FMA>(keys, stage, plan, h, &b0.stage, &mut b0.force[stage]);
                let mine = &mut h1.board.force[stage];
                h1.set.stage::<FMA>(keys, stage, plan, h, &b0.stage, mine);
                b0.sum_forces(stage, mine.iter().copied());
                mine.fill(0.0);
                b0.accel(stage);
                h0.set.accel::<FMA>(keys, stage, &b0.acc);
                h1.set.accel::<FMA>(keys, stage, &b0.acc);
            }
            h0.board.advance::<FMA>();
            h0.set.finish::<FMA>(keys, h, fade, &h0.board);
            h1.set.finish::<FMA>(keys, h, fade, &h0.board);
            h0.steps += 1;
            h1.steps += 1;
            *q = h0.board.volume_velocity();
        }
    }

    /// Half 1 on the other core through `pair`, half 0 here, meeting after every stage; `false`
    /// (nothing advanced) when the other core did not start.
    fn run_split(&mut self, out: &mut [f64], pair: &dyn Pair) -> bool {
        let (keys, ex) = (&self.keys, &self.exchange);
        let timing = (self.h, self.fade_steps, self.fast_path);
        let [h0, h1] = &mut self.halves;
        // Half 1's replica of the board was left behind while the halves ran on one core.
        h1.board.zr.copy_from_slice(&h0.board.zr);
        h1.board.zi.copy_from_slice(&h0.board.zi);
        let steps = out.len();
        // A panic on either side abandons the meetings, so the other side cannot wait forever,
        // and is raised again here once both have stopped.
        let mut panic = [None, None];
        let [p0, p1] = &mut panic;
        let mut there = || {
            let run = AssertUnwindSafe(|| h1.run_part(keys, ex, 1, timing, steps, None));
            if let Err(e) = std::panic::catch_unwind(run) {
                ex.abandoned.store(true, Ordering::Relaxed);
                *p1 = Some(e);
            }
        };
        let mut here = || {
            let run = AssertUnwindSafe(|| h0.run_part(keys, ex, 0, timing, steps, Some(out)));
            if let Err(e) = std::panic::catch_unwind(run) {
                ex.abandoned.store(true, Ordering::Relaxed);
                *p0 = Some(e);
            }
        };
        let joined = pair.join(&mut there, &mut here);
        if let Some(e) = panic.into_iter().flatten().next() {
            std::panic::resume_unwind(e);
        }
        joined
    }

    /// At the end of a chunk, give every voice whose fade has ended its next key.
    fn finish_fades(&mut self) {
        for k in 0..self.n_voices {
            self.complete_fade(k);
        }
    }

    /// The state of the linear part: every active voice's string modes (real and imaginary parts,
    /// voice by voice) and then the board's (see [`crate::engine::LinearState`]).
    pub fn linear_state(&self) -> crate::engine::LinearState {
        let mut state = crate::engine::LinearState::default();
        for k in 0..self.n_voices {
            let v = self.voice(k);
            let (true, Some(key)) = (v.state.active, v.state.key) else {
                continue;
            };
            for (s, blocks) in self.keys[key].strings.iter().enumerate() {
                for (d, b) in blocks.iter().enumerate() {
                    let z = &v.z[s][d];
                    for part in [&z.re, &z.im] {
                        state.push(Some(k), &part[..b.modes], &b.energy[..b.modes]);
                    }
                }
            }
        }
        let board = self.board();
        // A board mode `q = 2 Re z` holds `(|lambda|^2 + omega^2) |z|^2` on average.
        let weight: Vec<f64> = (0..board.zr.len())
            .map(|i| board.lam[0][i].powi(2) + board.lam[1][i].powi(2) + board.omega2[i])
            .collect();
        state.push(None, &board.zr, &weight);
        state.push(None, &board.zi, &weight);
        state
    }

    /// Set the state that [`EtdPool::linear_state`] reads, in the same layout.
    pub fn set_linear_state(&mut self, x: &[f64]) {
        let mut at = 0;
        let mut take = |n: usize| {
            at += n;
            &x[at - n..at]
        };
        for k in 0..self.n_voices {
            let (true, Some(key)) = (self.voice(k).state.active, self.voice(k).state.key) else {
                continue;
            };
            let v = &mut self.halves[k % 2].set.voices[k / 2];
            for (s, blocks) in self.keys[key].strings.iter().enumerate() {
                for (d, b) in blocks.iter().enumerate() {
                    let z = &mut v.z[s][d];
                    z.re[..b.modes].copy_from_slice(take(b.modes));
                    z.im[..b.modes].copy_from_slice(take(b.modes));
                }
            }
        }
        let n = self.board().zr.len();
        let (re, im) = (take(n).to_vec(), take(n).to_vec());
        for half in &mut self.halves {
            half.board.zr.copy_from_slice(&re);
            half.board.zi.copy_from_slice(&im);
        }
    }

    /// Floating-point operations of one step in the current state, counted from the loops of
    /// [`read_rows`], [`propagate_drive`] and [`drive`]: 4 per mode for each row read (a complex
    /// multiply-add, real part), 6 for the propagation, 4 per non-zero input and final weight.
    pub fn flops_per_step(&self) -> f64 {
        let nb = self.board().zr.len();
        // The board (one replica on one core): start reads (3 × 6), stage forms (2 × 2 per
        // term), the stages' accelerations (4 × 4), the update (14).
        let mut flops = nb * (18 + 16 + 16 + 14);
        for v in self.halves.iter().flat_map(|h| &h.set.voices) {
            let (true, Some(key)) = (v.state.active, v.state.key) else {
                continue;
            };
            let km = &self.keys[key];
            for (s, blocks) in km.strings.iter().enumerate() {
                for (d, b) in blocks.iter().enumerate() {
                    let n = b.e_full[0].len();
                    let struck =
                        Direction::ALL[d].is_struck() && v.state.hammer_on && v.state.struck[s];
                    let damped = Direction::ALL[d].is_transverse() && v.state.damper_down;
                    let fading = v.state.coupling != 1.0;
                    let ports = 2 + usize::from(struck) + usize::from(damped);
                    let inputs =
                        2 + usize::from(struck) + usize::from(damped) + usize::from(fading);
                    flops += n * (ports * 3 * 4 + 6 + inputs * 3 * 4);
                }
            }
            // Each voice's board reads, accelerations and forces: 6 + 3 dots and 3 axpys per
            // stage.
            flops += nb * 4 * (6 + 3 + 3) * 2;
        }
        flops as f64
    }

    /// Complex modes stored per voice for the largest key, and for the board.
    pub fn bytes_per_voice(&self) -> usize {
        self.voice(0)
            .z
            .iter()
            .flatten()
            .map(|m| m.re.len() * 16)
            .sum::<usize>()
            + std::mem::size_of::<Work>()
    }
}

/// The pool policy ([`Policy`]) on the live integrator's voices, whose strings move in
/// coordinates relative to the bridge (so a voice enters and leaves the board as it is).
impl Policy for EtdPool {
    fn n_voices(&self) -> usize {
        self.n_voices
    }

    fn state(&self, k: usize) -> &VoiceState {
        &self.voice(k).state
    }

    fn state_mut(&mut self, k: usize) -> &mut VoiceState {
        &mut self.voice_mut(k).state
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
        self.keys[key].strings.len()
    }

    fn key_has_damper(&self, key: usize) -> bool {
        self.keys[key].has_damper
    }

    /// The voice points at the key's precomputed modes; only its state is cleared.
    fn load_key(&mut self, k: usize, _key: usize) {
        self.voice_mut(k)
            .z
            .iter_mut()
            .flatten()
            .for_each(ComplexState::clear);
    }

    fn rest_strings(&mut self, k: usize) {
        self.voice_mut(k)
            .z
            .iter_mut()
            .flatten()
            .for_each(ComplexState::clear);
    }

    fn enter(&mut self, _k: usize) {}

    fn leave(&mut self, _k: usize) {}

    fn strike_contact_m(&self, k: usize, struck: usize) -> f64 {
        let v = self.voice(k);
        let Some(key) = v.state.key else {
            return 0.0;
        };
        let km = &self.keys[key];
        let y = self.board().at(&km.board_shape[0]).0;
        (0..struck)
            .map(|s| strike_point(km, s, &v.z[s][0], y))
            .fold(f64::NEG_INFINITY, f64::max)
    }

    fn set_hammer(&mut self, k: usize, position_m: f64, velocity_m_s: f64) {
        let v = self.voice_mut(k);
        (v.hammer_y, v.hammer_v) = (position_m, velocity_m_s);
    }

    fn hammer_finite(&self, k: usize) -> bool {
        let v = self.voice(k);
        v.hammer_y.is_finite() && v.hammer_v.is_finite()
    }

    fn voice_energy_j(&self, k: usize) -> f64 {
        self.strings_energy_j(k)
    }

    fn board_energy_j(&self) -> f64 {
        self.board().energy_j()
    }

    fn rest_board(&mut self) {
        self.halves.iter_mut().for_each(|h| h.board.clear());
    }
}

/// One unison on its bridge point advanced by ETDRK4 (the pool with one key and one voice).
#[derive(Debug, Clone)]
pub struct EtdUnison(EtdPool);

impl EtdUnison {
    /// Diagonalise every string direction and the board for the step `1 / spec.sample_rate_hz`.
    pub fn new(spec: &UnisonSpec) -> Result<EtdUnison, BuildError> {
        let mut pool = EtdPool::with_pool(std::slice::from_ref(spec), 1)?;
        pool.assign(0, 0);
        pool.set_active(0, true);
        Ok(EtdUnison(pool))
    }

    pub fn step_s(&self) -> f64 {
        self.0.step_s()
    }

    pub fn set_damper(&mut self, down: bool) {
        self.0.set_damper(down);
    }

    pub fn strike(&mut self, strike: Strike) {
        self.0.strike(strike);
    }

    pub fn step(&mut self) {
        self.0.step();
    }

    pub fn observe(&self) -> Observation {
        self.0.observe()
    }

    pub fn flops_per_step(&self) -> f64 {
        self.0.flops_per_step()
    }
}
