//! The assembled state-space system of one unison (paper Eq. 10–19), advanced with classical RK4.
//!
//! The state `x = (q_1 .. q_n, q_b, qdot_1 .. qdot_n, qdot_b, y_H, ydot_H)` is held as two flat
//! arrays `q`, `v` over all modes, laid out per string as `[T | P | L]` and then the board. Every
//! block of the paper's `A` (Eq. 11) is diagonal except the duplex damping, and all coupling passes
//! through rank-3 bridge projections and the rank-1 hammer projection (Eq. 14–18). The duplex
//! matrix (Eq. 13) is applied as `Wᵀ W` of rank ~16 (exact to rounding: `duplex::low_rank_factor`),
//! so one evaluation of the right-hand side costs O(modes):
//! ```text
//! qdd_i = -Omega_i^2 q_i - (C_i + C_d) qdot_i - Phi_s^T F_i + [struck] psi_e F_e,i
//! qdd_b = -Omega_b^2 q_b - C_b qdot_b + Phi_b^T sum_i F_i
//! ydd_H = -(1/m_H) sum_i F_e,i
//! ```

pub mod dense;
mod key;
mod observe;
mod policy;
mod rhs;

pub use key::Rk4Key;
use key::{build_key, cast};
use rhs::{evaluate, stage};

use crate::engine::kernels::{has_avx2_fma, Real};
use crate::engine::pool::{fade_step, Policy, VoiceState};
use crate::engine::spec::{
    BuildError, Energy, Observation, Strike, UnisonSpec, CHANNELS, MAX_STRINGS, STEAL_FADE_S,
};
use std::ops::Range;

/// One voice of the pool: a fixed slot of `capacity` modes in the flat arrays, playing one key.
#[derive(Debug, Clone)]
struct Voice {
    base: usize,
    /// The key's `ranges` moved to this slot.
    ranges: [[Range<usize>; 3]; MAX_STRINGS],
    n_strings: usize,
    n_modes: usize,
}

/// Coefficients of the system: the key bank, where each voice sits and what it plays, the board.
#[derive(Debug, Clone)]
struct Model<T> {
    keys: std::sync::Arc<[Rk4Key<T>]>,
    voices: Vec<Voice>,
    board: Range<usize>,
    /// The board's dropped modes (`UnisonSpec::dropped`), right after `board`: driven by every
    /// voice's bridge force at its point, heard, not coupled (empty without them).
    residual: Range<usize>,
    omega2: Vec<T>,
    /// `2 zeta omega` per mode (1/s).
    damp: Vec<T>,
    /// String modes: `psi_n(L_s)` in the mode's own direction; zero over the board block.
    bridge_shape: Vec<T>,
    /// The voices' keys' `static_shape`.
    static_shape: Vec<T>,
    /// The board's radiating source of each channel per unit modal velocity and displacement
    /// ([`crate::engine::physics::soundboard::SoundboardModes::radiation_weights`]); whether the
    /// two channels hear different listeners.
    board_radiation: [[Vec<T>; 2]; CHANNELS],
    /// The same for the dropped modes.
    residual_radiation: [[Vec<T>; 2]; CHANNELS],
    stereo: bool,
    h: f64,
}

impl<T> Model<T> {
    /// The board's modes and its dropped modes, which follow them.
    fn board_and_residual(&self) -> Range<usize> {
        self.board.start..self.residual.end
    }
}

/// Strings of up to 88 keys on one shared soundboard (paper Eq. 10, the board coupling every
/// string of every sounding key), with their hammers and dampers.
///
/// The instrument holds a bank of keys and a fixed pool of voices. A voice is a slot in the flat
/// state arrays that plays one key at a time at that key's bridge point; [`Rk4Pool::assign`]
/// gives a free voice a key (copying coefficients, no allocation) and [`Rk4Pool::steal`] fades a
/// sounding voice off the board before handing it to another key. Built for one key with
/// [`Rk4Pool::new`] (the paper's system), one voice per key with [`Rk4Pool::with_keys`], or
/// with a pool of any size with [`Rk4Pool::with_pool`]. Only active voices are simulated.
///
/// Modes are held and advanced in `T`: `f64`, the reference, or `f32` (twice the SIMD lanes;
/// [`Rk4Pool::pool`] builds either); hammers, forces and energies are computed in `f64`.
#[derive(Debug, Clone)]
pub struct Rk4Pool<T: Real = f64> {
    model: Model<T>,
    q: Vec<T>,
    v: Vec<T>,
    hammer_y: Vec<f64>,
    hammer_v: Vec<f64>,
    /// Per voice, the board's displacement and velocity at its point (T, L, P) when it stopped
    /// being simulated (zero once its strings are set at rest): see [`Rk4Pool::set_active`].
    left_at: Vec<[[f64; 2]; 3]>,
    /// Each voice's policy state (`engine::pool`), read by every evaluation.
    states: Vec<VoiceState>,
    voice_of_key: Vec<Option<usize>>,
    /// Mode ranges simulated in this step, the first `n_live`: the active voices' and the
    /// board's. One slot per voice and the board, filled in place (a `Vec` pushed to would lose
    /// its reserved room in a clone, and the clone's first step would allocate).
    live: Vec<Range<usize>>,
    n_live: usize,
    /// `W v` of the duplex product for up to six blocks (T and P of three strings).
    duplex_z: Vec<T>,
    fade_steps: u32,
    // RK4 scratch, sized once.
    qs: Vec<T>,
    vs: Vec<T>,
    acc: Vec<T>,
    sum_q: Vec<T>,
    sum_v: Vec<T>,
    hy_s: Vec<f64>,
    hv_s: Vec<f64>,
    sum_hy: Vec<f64>,
    sum_hv: Vec<f64>,
    ah: Vec<f64>,
    fast_path: bool,
    time_s: f64,
}

impl Rk4Pool {
    /// One unison on its bridge point (the paper's system), active from the start; precomputes
    /// every coefficient and allocates all state and scratch.
    pub fn new(spec: &UnisonSpec) -> Result<Rk4Pool, BuildError> {
        Self::unison(spec)
    }

    /// Several keys on one shared soundboard, one voice each: voice `k` plays `specs[k]` at its
    /// own bridge point. A voice is simulated once struck or its damper lifted.
    pub fn with_keys(specs: &[UnisonSpec]) -> Result<Rk4Pool, BuildError> {
        let mut u = Self::pool(specs, specs.len())?;
        for k in 0..specs.len() {
            u.assign(k, k);
        }
        Ok(u)
    }

    /// A bank of keys and a pool of voices (see [`Rk4Pool::pool`]), in `f64`.
    pub fn with_pool(specs: &[UnisonSpec], voices: usize) -> Result<Rk4Pool, BuildError> {
        Self::pool(specs, voices)
    }
}

impl<T: Real> Rk4Pool<T> {
    /// [`Rk4Pool::new`] in precision `T`.
    pub fn unison(spec: &UnisonSpec) -> Result<Self, BuildError> {
        let mut u = Self::pool(std::slice::from_ref(spec), 1)?;
        u.assign(0, 0);
        u.states[0].active = true;
        Ok(u)
    }

    /// A bank of keys (`specs`, all on the same board and internal rate) and a pool of `voices`
    /// voices in precision `T`, each large enough for any key; no voice plays a key yet.
    pub fn pool(specs: &[UnisonSpec], voices: usize) -> Result<Self, BuildError> {
        let keys = specs
            .iter()
            .map(Self::prepare_key)
            .collect::<Result<Vec<_>, _>>()?;
        Self::from_keys(specs, keys.into(), voices)
    }

    /// One key's coefficients (modes, duplex factor, hammer, damper, stability check), independent
    /// from key to key (a caller may prepare keys on several threads, then call
    /// [`Rk4Pool::from_keys`]).
    pub fn prepare_key(spec: &UnisonSpec) -> Result<Rk4Key<T>, BuildError> {
        build_key(spec)
    }

    /// The pool of [`Rk4Pool::pool`] from keys already prepared, one per spec.
    pub fn from_keys(
        specs: &[UnisonSpec],
        keys: std::sync::Arc<[Rk4Key<T>]>,
        voices: usize,
    ) -> Result<Self, BuildError> {
        let first = crate::engine::pool::check_keys(specs, keys.len(), voices)?;
        let capacity = keys.iter().map(|k| k.n_modes).max().unwrap_or(0);
        let voice_slots: Vec<Voice> = (0..voices)
            .map(|i| Voice {
                base: i * capacity,
                ranges: Default::default(),
                n_strings: 0,
                n_modes: 0,
            })
            .collect();
        let strings_end = voices * capacity;
        let board = strings_end..strings_end + first.board.len();
        let dropped = first.dropped.as_ref();
        let residual = board.end..board.end + dropped.map_or(0, |d| d.freq_hz.len());
        let n = residual.end;
        // Every per-mode array at its final length at once (no growth, no spare capacity).
        let (mut omega2, mut damp) = (vec![T::ZERO; n], vec![T::ZERO; n]);
        let (bridge_shape, static_shape) = (vec![T::ZERO; n], vec![T::ZERO; strings_end]);
        for (k, i) in board.clone().enumerate() {
            let mode = first.board.oscillator(k);
            omega2[i] = T::from_f64(mode.omega2());
            damp[i] = T::from_f64(mode.damping_per_s());
        }
        if let Some(d) = dropped {
            for (j, i) in residual.clone().enumerate() {
                let mode = d.oscillator(j);
                omega2[i] = T::from_f64(mode.omega2());
                damp[i] = T::from_f64(mode.damping_per_s());
            }
        }
        let h = 1.0 / first.sample_rate_hz;
        let model = Model {
            keys,
            voices: voice_slots,
            board,
            residual,
            omega2,
            damp,
            bridge_shape,
            static_shape,
            board_radiation: std::array::from_fn(|c| {
                first.board.radiation_weights(c).map(|w| cast(&w))
            }),
            residual_radiation: std::array::from_fn(|c| match dropped {
                Some(d) => d.weights[c].each_ref().map(|w| cast(w)),
                None => [vec![], vec![]],
            }),
            stereo: first.board.is_stereo(),
            h,
        };
        let max_rank = model.keys.iter().map(|k| k.duplex_rank).max().unwrap_or(0);
        Ok(Rk4Pool {
            duplex_z: vec![T::ZERO; 2 * MAX_STRINGS * max_rank],
            voice_of_key: vec![None; specs.len()],
            live: vec![0..0; voices + 1],
            n_live: 0,
            fade_steps: (STEAL_FADE_S / h).round().max(1.0) as u32,
            model,
            q: vec![T::ZERO; n],
            v: vec![T::ZERO; n],
            hammer_y: vec![0.0; voices],
            hammer_v: vec![0.0; voices],
            left_at: vec![[[0.0; 2]; 3]; voices],
            states: vec![VoiceState::default(); voices],
            qs: vec![T::ZERO; n],
            vs: vec![T::ZERO; n],
            acc: vec![T::ZERO; n],
            sum_q: vec![T::ZERO; n],
            sum_v: vec![T::ZERO; n],
            hy_s: vec![0.0; voices],
            hv_s: vec![0.0; voices],
            sum_hy: vec![0.0; voices],
            sum_hv: vec![0.0; voices],
            ah: vec![0.0; voices],
            fast_path: has_avx2_fma(),
            time_s: 0.0,
        })
    }

    /// Number of voices in the pool.
    pub fn n_voices(&self) -> usize {
        self.model.voices.len()
    }

    /// Number of keys in the bank.
    pub fn n_keys(&self) -> usize {
        self.model.keys.len()
    }

    /// Number of strings of voice 0.
    pub fn n_strings(&self) -> usize {
        self.model.voices[0].n_strings
    }

    /// Total number of modes (every voice's slot and the board).
    pub fn n_modes(&self) -> usize {
        self.q.len()
    }

    /// Integration step (s).
    pub fn step_s(&self) -> f64 {
        self.model.h
    }

    /// Simulated time since the system was built (s).
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Flat-array range of voice 0's string `s` in direction `d` (0 = T, 1 = L, 2 = P).
    pub fn string_range(&self, s: usize, d: usize) -> Range<usize> {
        self.model.voices[0].ranges[s][d].clone()
    }

    /// Flat-array range of the board's modes.
    pub fn board_range(&self) -> Range<usize> {
        self.model.board.clone()
    }

    /// Modal displacements and velocities, for setting initial conditions.
    pub fn state_mut(&mut self) -> (&mut [T], &mut [T]) {
        (&mut self.q, &mut self.v)
    }

    /// Modal displacements and velocities.
    pub fn state(&self) -> (&[T], &[T]) {
        (&self.q, &self.v)
    }

    /// The state of the linear part: every active voice's modal displacements and velocities
    /// (voice by voice), then the board's (see [`crate::engine::LinearState`]; the displacements' energy
    /// weights include the contact springs', `1/2 (omega^2 + k psi^2)` for a string mode and
    /// `1/2 (omega^2 + sum k phi^2)` over the active strings for a board mode).
    pub fn linear_state(&self) -> crate::engine::LinearState {
        let m = &self.model;
        let mut stiffness: Vec<f64> = m.omega2.iter().map(|w| w.to_f64()).collect();
        for (k, voice) in m.voices.iter().enumerate() {
            let (true, Some(key)) = (self.states[k].active, self.states[k].key) else {
                continue;
            };
            let km = &m.keys[key];
            for s in 0..voice.n_strings {
                for d in 0..3 {
                    let kc = km.contact.stiffness_n_m[d];
                    for i in voice.ranges[s][d].clone() {
                        stiffness[i] += kc * m.bridge_shape[i].to_f64().powi(2);
                    }
                    for (j, phi) in m.board.clone().zip(&km.board_shape[d]) {
                        stiffness[j] += kc * phi.to_f64().powi(2);
                    }
                }
            }
        }
        let mut state = crate::engine::LinearState::default();
        for (r, k) in self.linear_ranges() {
            let weight: Vec<f64> = stiffness[r.clone()].iter().map(|w| 0.5 * w).collect();
            let q: Vec<f64> = self.q[r.clone()].iter().map(|x| x.to_f64()).collect();
            let v: Vec<f64> = self.v[r.clone()].iter().map(|x| x.to_f64()).collect();
            state.push(k, &q, &weight);
            state.push(k, &v, &vec![0.5; r.len()]);
        }
        state
    }

    /// Set the state that [`Rk4Pool::linear_state`] reads, in the same layout.
    pub fn set_linear_state(&mut self, x: &[f64]) {
        let mut at = 0;
        for (r, _) in self.linear_ranges() {
            for part in [&mut self.q, &mut self.v] {
                for (p, &x) in part[r.clone()].iter_mut().zip(&x[at..at + r.len()]) {
                    *p = T::from_f64(x);
                }
                at += r.len();
            }
        }
    }

    /// The modes of every active voice and of the board, with their owner.
    fn linear_ranges(&self) -> Vec<(Range<usize>, Option<usize>)> {
        let voices = self.model.voices.iter().enumerate();
        voices
            .filter(|&(k, _)| self.states[k].active && self.states[k].key.is_some())
            .map(|(k, v)| (v.base..v.base + v.n_modes, Some(k)))
            .chain([(self.model.board.clone(), None)])
            .collect()
    }

    /// Whether voice 0's hammer is still part of the system.
    pub fn hammer_engaged(&self) -> bool {
        self.states[0].hammer_on
    }

    /// Kinetic and potential energy of the uncoupled modes `r` (J).
    fn modal_energy_j(&self, r: Range<usize>) -> f64 {
        r.map(|i| {
            let (q, v, w2) = (
                self.q[i].to_f64(),
                self.v[i].to_f64(),
                self.model.omega2[i].to_f64(),
            );
            0.5 * (v * v + w2 * q * q)
        })
        .sum()
    }

    /// Flat-array range of voice `k`'s modes.
    fn voice_modes(&self, k: usize) -> Range<usize> {
        let voice = &self.model.voices[k];
        voice.base..voice.base + voice.n_modes
    }

    /// Set the modes `r` at rest.
    fn rest(&mut self, r: Range<usize>) {
        self.q[r.clone()].fill(T::ZERO);
        self.v[r].fill(T::ZERO);
    }

    /// Energy in voice `k`'s contact springs (J), `1/2 k (r_s - r_b)^2` per string and direction
    /// (Eq. 6), scaled by the fade of a stolen voice.
    fn voice_contact_j(&self, k: usize) -> f64 {
        let (m, voice) = (&self.model, &self.model.voices[k]);
        let Some(key) = self.states[k].key else {
            return 0.0;
        };
        let km = &m.keys[key];
        let qb = &self.q[m.board.clone()];
        let mut e = 0.0;
        for s in 0..voice.n_strings {
            for d in 0..3 {
                let r = voice.ranges[s][d].clone();
                let rs = T::dot_wide::<false>(&m.bridge_shape[r.clone()], &self.q[r]);
                let rb = T::dot_wide::<false>(&km.board_shape[d], qb);
                e += self.states[k].coupling * km.contact.energy_j(d, rs - rb);
            }
        }
        e
    }

    /// Strike voice 0 (see [`Policy::strike_voice`]).
    pub fn strike(&mut self, strike: Strike) {
        self.strike_voice(0, strike);
    }

    /// The board's displacement and velocity at voice `k`'s point (T, L, P).
    fn board_at(&self, k: usize) -> [[f64; 2]; 3] {
        let m = &self.model;
        let Some(key) = self.states[k].key else {
            return [[0.0; 2]; 3];
        };
        let shape = &m.keys[key].board_shape;
        let (qb, vb) = (&self.q[m.board.clone()], &self.v[m.board.clone()]);
        std::array::from_fn(|d| {
            [
                T::dot_wide::<false>(&shape[d], qb),
                T::dot_wide::<false>(&shape[d], vb),
            ]
        })
    }

    /// Lower or lift voice 0's damper (see [`Policy::set_damper_voice`]).
    pub fn set_damper(&mut self, down: bool) {
        self.set_damper_voice(0, down);
    }

    /// Whether voice 0's damper rests on the strings.
    pub fn damper_down(&self) -> bool {
        self.states[0].damper_down
    }

    /// Advance `sound.len()` steps, writing the board's radiating source of each channel (m^3/s,
    /// [`Rk4Pool::radiated_m3_s`]) after each (one core: RK4's many small stages are not worth
    /// splitting).
    pub fn run(&mut self, sound: &mut [[f64; CHANNELS]], _pair: Option<&dyn crate::engine::Pair>) {
        for q in sound {
            self.step();
            *q = self.radiated_m3_s();
        }
    }

    /// Advance one RK4 step; never allocates.
    pub fn step(&mut self) {
        self.move_dampers(1);
        self.touch_felts();
        let mut n = 0;
        for (k, voice) in self.model.voices.iter().enumerate() {
            if self.states[k].active {
                self.live[n] = voice.base..voice.base + voice.n_modes;
                n += 1;
            }
        }
        self.live[n] = self.model.board_and_residual();
        self.n_live = n + 1;
        #[cfg(target_arch = "x86_64")]
        if self.fast_path {
            // SAFETY: `fast_path` is set only when the CPU reports AVX2 and FMA.
            unsafe { self.step_avx2() };
            self.advance_fades();
            return;
        }
        self.step_impl::<false>();
        self.advance_fades();
    }

    /// The step compiled for AVX2 + FMA, with the explicit kernels of [`dot`] and [`axpy`].
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn step_avx2(&mut self) {
        self.step_impl::<true>();
    }

    /// Classical RK4 over `(q, v, y_H, ydot_H)` of the active voices and the board, stage sums
    /// accumulated in place. `SIMD` selects the AVX2 + FMA kernels; it is true only inside
    /// [`Self::step_avx2`], entered after detecting them.
    #[inline(always)]
    fn step_impl<const SIMD: bool>(&mut self) {
        let h = self.model.h;
        let (m, states, live) = (&self.model, &self.states, &self.live[..self.n_live]);
        let z = &mut self.duplex_z;
        let (q0, v0, hy0, hv0) = (&self.q, &self.v, &self.hammer_y, &self.hammer_v);
        let (qs, vs, acc) = (&mut self.qs, &mut self.vs, &mut self.acc);
        let (sum_q, sum_v) = (&mut self.sum_q, &mut self.sum_v);
        let (hy_s, hv_s, sum_hy, sum_hv, ah) = (
            &mut self.hy_s,
            &mut self.hv_s,
            &mut self.sum_hy,
            &mut self.sum_hv,
            &mut self.ah,
        );
        let hammers = 0..hy0.len();
        let ch = |c: f64| T::from_f64(c * h);
        // Stage 1 at the current state.
        evaluate::<T, SIMD>(m, states, live, q0, v0, hy0, hv0, acc, ah, z);
        for r in live {
            stage::<T, true>(ch(0.5), r.clone(), q0, v0, acc, qs, vs, sum_q, sum_v);
        }
        stage::<f64, true>(
            0.5 * h,
            hammers.clone(),
            hy0,
            hv0,
            ah,
            hy_s,
            hv_s,
            sum_hy,
            sum_hv,
        );
        // Stages 2 and 3: weights 2, next stage at h/2 then h.
        for c in [0.5, 1.0] {
            evaluate::<T, SIMD>(m, states, live, qs, vs, hy_s, hv_s, acc, ah, z);
            for r in live {
                stage::<T, false>(ch(c), r.clone(), q0, v0, acc, qs, vs, sum_q, sum_v);
            }
            stage::<f64, false>(
                c * h,
                hammers.clone(),
                hy0,
                hv0,
                ah,
                hy_s,
                hv_s,
                sum_hy,
                sum_hv,
            );
        }
        // Stage 4 and the combination.
        evaluate::<T, SIMD>(m, states, live, qs, vs, hy_s, hv_s, acc, ah, z);
        let w = T::from_f64(h / 6.0);
        let (q, v) = (&mut self.q, &mut self.v);
        for r in live {
            let n = r.len();
            let (q, v) = (&mut q[r.clone()], &mut v[r.clone()]);
            let (sq, sv) = (&sum_q[r.clone()][..n], &sum_v[r.clone()][..n]);
            let (vs, acc) = (&vs[r.clone()][..n], &acc[r.clone()][..n]);
            for i in 0..n {
                q[i] += w * (sq[i] + vs[i]);
                v[i] += w * (sv[i] + acc[i]);
            }
        }
        let w = h / 6.0;
        for k in 0..self.hammer_y.len() {
            if self.states[k].hammer_on {
                self.hammer_y[k] += w * (sum_hy[k] + hv_s[k]);
                self.hammer_v[k] += w * (sum_hv[k] + ah[k]);
            }
        }
        for k in 0..self.hammer_y.len() {
            if self.states[k].hammer_on {
                self.release_hammer_if_clear(k);
            }
        }
        self.time_s += h;
    }

    /// Move every stolen voice one step along its fade; at the end, give it its next key.
    fn advance_fades(&mut self) {
        for k in 0..self.n_voices() {
            if fade_step(&mut self.states[k], self.fade_steps) {
                self.complete_fade(k);
            }
        }
    }

    /// A hammer leaves the system once it recedes and is clear of every string by the release gap.
    fn release_hammer_if_clear(&mut self, k: usize) {
        let (voice, state) = (&self.model.voices[k], &self.states[k]);
        let Some(key) = state.key else {
            return;
        };
        let km = &self.model.keys[key];
        let strike_points = (0..voice.n_strings)
            .filter(|&s| state.felt[s].is_some())
            .map(|s| T::dot_wide::<false>(&km.hammer_shape, &self.q[voice.ranges[s][0].clone()]));
        if km
            .hammer
            .is_clear(self.hammer_y[k], self.hammer_v[k], strike_points)
        {
            self.states[k].hammer_on = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The portable step (what runs on a CPU without AVX2 + FMA) against the AVX2 one, in both
    /// precisions: c2 struck, 20 ms, bridge forces relative to their peak.
    fn portable_agrees<T: Real>(tol: f64) {
        if !has_avx2_fma() {
            println!("skipped: this CPU has no AVX2 + FMA, so the portable step is the only one");
            return;
        }
        let spec = crate::config::preset::Preset::resolve("c2")
            .unwrap()
            .unison_spec();
        let mut fast = Rk4Pool::<T>::unison(&spec).unwrap();
        let mut portable = fast.clone();
        portable.fast_path = false;
        let strike = Strike {
            velocity_m_s: 2.5,
            shift: 0.0,
        };
        fast.strike(strike);
        portable.strike(strike);
        let (mut worst, mut peak) = (0f64, 0f64);
        for _ in 0..(0.02 / fast.step_s()) as usize {
            fast.step();
            portable.step();
            let (a, b) = (fast.observe(), portable.observe());
            for (fa, fb) in a.bridge_force_n.iter().zip(&b.bridge_force_n) {
                for d in 0..3 {
                    worst = worst.max((fa[d] - fb[d]).abs());
                    peak = peak.max(fa[d].abs());
                }
            }
        }
        println!(
            "{}: portable vs AVX2 step, 20 ms: {:.1e} of the peak force",
            T::NAME,
            worst / peak
        );
        assert!(
            peak > 1.0 && worst / peak < tol,
            "{}: {worst} of {peak}",
            T::NAME
        );
    }

    #[test]
    fn the_portable_step_agrees_with_the_avx2_step() {
        portable_agrees::<f64>(1e-11);
        portable_agrees::<f32>(1e-4);
    }
}
