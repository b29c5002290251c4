//! The board's low modes, one system shared by every sounding key, and the interface at the
//! bridges solved implicitly each step.
//!
//! Why this split (issue 16). Keys are coupled through the board, and the coupling is stiff: a
//! contact spring (4.8e6 N/m per string and direction) ties each string's end to the board under
//! it. Put a whole copy of the board in every key's modes and the stiff part is exact, but every
//! key then carries the board's 130 modes (40 % of an average key's, 85 % of a treble key's)
//! and the keys' copies must be kept apart from their sum by integrating each key's own part
//! again, sample by sample (89 modes per key). Here the board's modes below [`SHARED_BELOW_HZ`]
//! (55 of 130, where every key meets every other) are integrated once, for all keys; each key
//! keeps only the board's modes above it, local to its bridge (the key's own modes,
//! [`super::key`]): keys do not meet through those (each rings its own copy), which the chord
//! and sympathy gates bound (`tests/stability.rs`, `tests/exact_pool.rs`). Over a step every key's force `F_k` on the board and the board's
//! displacement `D_k` under it are taken linear in time — exact for the modes on both sides, an
//! error of `(omega h)^2 / 12` at the interface: 1.3 % of the coupling at 3 kHz, 0.1 % at 1 kHz —
//! and solved together, implicitly: each key's reads after the step are known but for
//! `Z_k D_k^{n+1}` (3×3, [`super::key::Settle`]), so the board's displacement after the step
//! solves
//! ```text
//! (I - T W) q^{n+1} = q_known,   W = sum_k Phi_k Z_k Phi_k^T,   T = diag(2 Re to_m)
//! ```
//! with `q_known` what the board would do under the keys' known forces alone. `W` and the inverse
//! change only when a key joins, leaves or has its damper lowered or lifted: a rank-3 update of
//! both (Woodbury, ~9 m² FLOP, m = 55: ~27 kFLOP). Each step costs 2 m² (the inverse and `W`
//! applied) for the whole pool, and 6 m per key (its force onto the modes, their displacement at
//! its bridge). Measured against the exact continuous system of one key (`tests/integrators.rs`):
//! c2's partials within 0.33 cents and 0.5 % of their decay; the one-step map of the nine-key
//! chord and of the 23 stiffest keys stays inside the unit circle (`tests/stability.rs`).

use super::kernels::{fma, Simd, Split, LANES};
use crate::engine::fir::{least_squares_fir, Fir, FIT_BAND};
use crate::engine::modal::input_weights;
use crate::engine::physics::soundboard::SoundboardModes;
use crate::engine::spec::CHANNELS;
use faer::c64;

/// The board's modes below this frequency (Hz) are shared by every key; each key carries those
/// above in its own modes. Higher, the interface's error grows as `(omega h)^2` (with every mode
/// shared, 7 kHz, C7's fundamental decays 3.6 % off, at 3 kHz 1.2 %) and so does the per-sample
/// work that stays on one core (6 m per key and 2 m² per step); lower, every key carries more
/// modes and the keys meet through fewer. At 1.5 kHz against 3 kHz (64 voices, one core): the
/// callback 15 % faster, 20 % on two cores; the nine-key chord within 0.37 dB of RK4 (0.31 at
/// 3 kHz), a held key's sympathy 0.011 dB (the same); at 1 kHz no faster on one core.
pub(crate) const SHARED_BELOW_HZ: f64 = 1500.0;

/// Taps of the correction of the shared board's radiating source (odd: a whole delay).
const SOURCE_TAPS: usize = 11;

/// The delay of the pool's radiating source (steps): the shared board's correction's, which the
/// voices' part keeps too.
pub(crate) const SOURCE_DELAY_STEPS: usize = (SOURCE_TAPS - 1) / 2;

/// The pool's radiating source as heard. The shared board's modes take each key's force linear
/// over a step (above): the samples joined by straight lines, whose spectrum is the samples'
/// times `sinc²(ω h / 2)`, repeated every `2π / h`. Read again at the steps, a mode's source
/// gathers every repeat: above its own frequency (every shared mode is under
/// [`SHARED_BELOW_HZ`]) its velocity is a mass's, `1 / (jω)`, and with `x = ω h / 2` the repeats
/// sum to `Σ_k x/(x + kπ) · sin²x/(x + kπ)² = x cot x` of what the continuous force gives (at
/// 48 kHz: −1.4 dB at 10 kHz, −4.4 at 16, −9.1 at 20 kHz). `sinc²` alone, the first term, left
/// C4's and C6's 12.7–16 kHz bands 0.7 and 1.1 dB under RK4's at 20 × f_max
/// (`tests/integrators.rs`). Their part goes through a linear-phase FIR fitted to `tan x / x`
/// (within 1 % to 16 kHz, 2.1 % at 18 kHz, 5.9 % at 20 kHz); the modes' displacement, which
/// the source weighs less by `omega_m / omega`, is left to it too. The voices' part — integrated
/// exactly — is delayed as much, [`SOURCE_DELAY_STEPS`]. Touched by the thread that steps the
/// pool.
#[derive(Debug, Clone)]
pub(crate) struct HeardSource {
    /// The board's part, per channel, through the correction.
    board: [Fir<SOURCE_TAPS>; CHANNELS],
    /// The voices' part of the last `SOURCE_DELAY_STEPS + 1` steps, newest first (a plain delay
    /// line: a non-finite value stays where it is rather than spreading over taps).
    voices: [[f64; CHANNELS]; SOURCE_DELAY_STEPS + 1],
}

impl HeardSource {
    /// Designs the correction (allocates: not on the audio thread).
    pub(crate) fn new() -> HeardSource {
        let delay = SOURCE_DELAY_STEPS as f64;
        let taps = least_squares_fir(FIT_BAND, |wh| {
            let x = 0.5 * wh;
            let gain = x.tan() / x;
            (gain * (wh * delay).cos(), -gain * (wh * delay).sin())
        });
        HeardSource {
            board: std::array::from_fn(|_| Fir::new(taps)),
            voices: [[0.0; CHANNELS]; SOURCE_DELAY_STEPS + 1],
        }
    }

    /// The radiating source of each channel `SOURCE_DELAY_STEPS` steps ago, from this step's
    /// voices' and board's parts.
    pub(crate) fn next(
        &mut self,
        voices: [f64; CHANNELS],
        board: [f64; CHANNELS],
    ) -> [f64; CHANNELS] {
        self.voices.copy_within(0..SOURCE_DELAY_STEPS, 1);
        self.voices[0] = voices;
        std::array::from_fn(|c| self.voices[SOURCE_DELAY_STEPS][c] + self.board[c].push(board[c]))
    }

    /// Forget the past (the pool set to a new state).
    pub(crate) fn clear(&mut self) {
        self.clear_board();
        self.voices = [[0.0; CHANNELS]; SOURCE_DELAY_STEPS + 1];
    }

    /// Forget the board's past (the board set at rest).
    pub(crate) fn clear_board(&mut self) {
        for fir in &mut self.board {
            fir.fill(0.0);
        }
    }

    /// Forget what was not finite (a runaway voice's source, the voice set at rest), keeping the
    /// rest: clearing it all would make the source jump.
    pub(crate) fn forget_non_finite(&mut self) {
        for fir in &mut self.board {
            fir.forget_non_finite();
        }
        for x in self.voices.iter_mut().flatten() {
            if !x.is_finite() {
                *x = 0.0;
            }
        }
    }
}

/// The shared modes' coefficients and the interface's matrices. Built off the audio thread;
/// updated by the thread that owns the pool (between blocks), read by both halves of a block.
#[derive(Debug, Clone)]
pub(crate) struct SharedBoard {
    /// The board's modes that are shared (indices into the board's modes).
    modes: Vec<usize>,
    /// Per mode (padded to whole lanes with modes that never move): `e^{lambda h}`, the weights
    /// of the modal force at the start and the end of the step, `lambda`, `omega^2`, `2 Re(to)`
    /// and its reciprocal (zero on the padding), and each channel's radiating source per unit
    /// `Re z` and `Im z` (from its source per unit modal velocity `2 Re(lambda z)` and
    /// displacement `2 Re z`:
    /// [`crate::engine::physics::soundboard::SoundboardModes::radiation_weights`]).
    e: Split,
    from: Split,
    to: Split,
    lambda: Vec<c64>,
    omega2: Vec<f64>,
    t: Vec<f64>,
    t_inv: Vec<f64>,
    heard: [Split; CHANNELS],
    /// `(I - T W)^{-1}`, `m × m`, column by column (the step applies it a column at a time:
    /// [`matvec`]). `W` itself is never needed: `T W q = q - q_known`.
    inverse: Vec<f64>,
    /// The Woodbury update's working values (`m × 3`, `3 × m`).
    x: Vec<f64>,
    y: Vec<f64>,
    c: Vec<f64>,
}

/// The shared modes' state. Written by the thread that steps the pool.
#[derive(Debug, Clone)]
pub(crate) struct BoardState {
    /// `z_m` with `q_m = 2 Re z_m` (`z' = lambda z + f / (2 i omega_d)`).
    z: Split,
    /// The modal force at the end of the last step, and the displacement after it.
    force: Vec<f64>,
    q: Vec<f64>,
    /// Working values of a step.
    known: Vec<f64>,
}

impl SharedBoard {
    /// Each shared mode's eigenvalue `lambda` (1/s; the padding's are zero).
    pub(crate) fn lambda(&self) -> &[c64] {
        &self.lambda
    }

    /// The shared modes of `board` for the step `h`, no key on them yet.
    pub(crate) fn new(board: &SoundboardModes, h: f64) -> SharedBoard {
        let modes: Vec<usize> = (0..board.len())
            .filter(|&k| board.freq_hz[k] < SHARED_BELOW_HZ)
            .collect();
        let m = modes.len().div_ceil(LANES) * LANES;
        let zero = c64::new(0.0, 0.0);
        let (mut e, mut from, mut to, mut lambda) =
            (vec![zero; m], vec![zero; m], vec![zero; m], vec![zero; m]);
        let mut omega2 = vec![0.0; m];
        let mut heard: [Split; CHANNELS] = std::array::from_fn(|_| Split::zeros(m));
        let weights: [[Vec<f64>; 2]; CHANNELS] =
            std::array::from_fn(|c| board.radiation_weights(c));
        for (i, &k) in modes.iter().enumerate() {
            let osc = board.oscillator(k);
            let (w, zeta) = (osc.omega_rad_s, osc.damping_ratio);
            let wd = w * (1.0 - zeta * zeta).sqrt();
            let l = c64::new(-zeta * w, wd);
            let g = c64::new(0.0, -0.5 / wd); // 1 / (2 i omega_d)
            let [w1, w2] = input_weights(l, h);
            e[i] = (l * h).exp();
            from[i] = g * (w1 - w2 / h);
            to[i] = g * (w2 / h);
            lambda[i] = l;
            omega2[i] = w * w;
            for (heard, [by_v, by_q]) in heard.iter_mut().zip(&weights) {
                heard.re[i] = 2.0 * (by_v[k] * l.re + by_q[k]);
                heard.im[i] = -2.0 * by_v[k] * l.im;
            }
        }
        let t: Vec<f64> = to.iter().map(|x| 2.0 * x.re).collect();
        let t_inv = t
            .iter()
            .map(|&t| if t > 0.0 { 1.0 / t } else { 0.0 })
            .collect();
        let mut inverse = vec![0.0; m * m];
        (0..m).for_each(|a| inverse[a * m + a] = 1.0);
        SharedBoard {
            modes,
            e: Split::new(&e),
            from: Split::new(&from),
            to: Split::new(&to),
            lambda,
            omega2,
            t,
            t_inv,
            heard,
            inverse,
            x: vec![0.0; 3 * m],
            y: vec![0.0; 3 * m],
            c: vec![0.0; 3 * m],
        }
    }

    /// Modes (padded).
    pub(crate) fn modes(&self) -> usize {
        self.e.len()
    }

    /// The shared modes at rest.
    pub(crate) fn state(&self) -> BoardState {
        let m = self.modes();
        BoardState {
            z: Split::zeros(m),
            force: vec![0.0; m],
            q: vec![0.0; m],
            known: vec![0.0; m],
        }
    }

    /// A key's mode shapes at its bridge point (all the board's modes) restricted to the shared
    /// ones (zero on the padding).
    pub(crate) fn restrict(&self, shape: &[Vec<f64>; 3]) -> BridgePoint {
        BridgePoint::new(std::array::from_fn(|d| {
            let mut phi: Vec<f64> = self.modes.iter().map(|&k| shape[d][k]).collect();
            phi.resize(self.modes(), 0.0);
            phi
        }))
    }

    /// A key at `phi` starts (`dz = Z`) or stops (`dz = -Z`) loading the board through the
    /// interface, or its `Z` changes by `dz`: `W += Phi dz Phi^T`, the inverse updated (Woodbury,
    /// rank 3). Allocates nothing.
    pub(crate) fn update(&mut self, phi: &[Vec<f64>; 3], dz: &[[f64; 3]; 3]) {
        let m = self.modes();
        // Entry (a, b) of an m × m matrix stored column by column.
        let at = |a: usize, b: usize| b * m + a;
        // C = dz Phi^T (3 × m), U = T Phi (m × 3).
        for i in 0..3 {
            for b in 0..m {
                self.c[i * m + b] = (0..3).map(|d| dz[i][d] * phi[d][b]).sum();
            }
        }
        // X = inverse U (m × 3), Y = C inverse (3 × m).
        self.x.iter_mut().for_each(|x| *x = 0.0);
        self.y.iter_mut().for_each(|y| *y = 0.0);
        for b in 0..m {
            let u = [0, 1, 2].map(|i| self.t[b] * phi[i][b]);
            let col = &self.inverse[b * m..(b + 1) * m];
            for a in 0..m {
                for i in 0..3 {
                    self.x[a * 3 + i] += col[a] * u[i];
                }
            }
            for i in 0..3 {
                self.y[i * m + b] = (0..m).map(|a| self.c[i * m + a] * col[a]).sum();
            }
        }
        // S = I - C X (3 × 3); inverse += X S^-1 Y.
        let s: [[f64; 3]; 3] = std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                let cx: f64 = (0..m).map(|a| self.c[i * m + a] * self.x[a * 3 + j]).sum();
                f64::from(u8::from(i == j)) - cx
            })
        });
        let s_inv = inverse3(&s);
        for a in 0..m {
            let xs: [f64; 3] =
                std::array::from_fn(|j| (0..3).map(|i| self.x[a * 3 + i] * s_inv[i][j]).sum());
            for b in 0..m {
                self.inverse[at(a, b)] +=
                    xs[0] * self.y[b] + xs[1] * self.y[m + b] + xs[2] * self.y[2 * m + b];
            }
        }
    }

    /// One step of the shared modes under the keys' known forces `known` (modal, the sum of
    /// every key's `Phi_k F_k` with `D^{n+1}` left out), solved with the keys' `Z D^{n+1}`
    /// (module notes); returns the board's radiating source of each channel after it (m^3/s).
    /// The keys then read `D^{n+1}` with [`SharedBoard::at`].
    pub(crate) fn step(
        &self,
        state: &mut BoardState,
        known: &[f64],
        simd: Simd,
    ) -> [f64; CHANNELS] {
        let m = self.modes();
        assert!(known.len() == m && state.modes() == m && self.inverse.len() == m * m);
        #[cfg(target_arch = "x86_64")]
        match simd {
            // SAFETY: `Simd::detect` chose these only where the CPU has them; every slice holds
            // `m` values, a whole number of lanes (asserted above and by construction).
            Simd::Avx512 => return unsafe { step_avx512(self, state, known) },
            Simd::Avx2 => return unsafe { step_avx2(self, state, known) },
            Simd::Portable => {}
        }
        let _ = simd;
        step_with::<false>(self, state, known)
    }

    /// The shared modes' displacement at a key's point `phi` after the last step (m, per
    /// direction).
    pub(crate) fn at(&self, state: &BoardState, point: &BridgePoint, simd: Simd) -> [f64; 3] {
        project(simd, &state.q, &point.packed)
    }

    /// Their velocity at `phi` (m/s, per direction).
    pub(crate) fn velocity_at(&self, state: &BoardState, phi: &[Vec<f64>; 3]) -> [f64; 3] {
        std::array::from_fn(|d| {
            (0..self.modes())
                .map(|k| {
                    let l = self.lambda[k];
                    phi[d][k] * 2.0 * (l.re * state.z.re[k] - l.im * state.z.im[k])
                })
                .sum()
        })
    }

    /// `sum += Phi f`: a key's force `f` (N, per direction) at its point onto the modes.
    pub(crate) fn add_force(&self, simd: Simd, point: &BridgePoint, f: [f64; 3], sum: &mut [f64]) {
        spread(simd, &point.packed, f, sum)
    }

    /// A key joins (`sign` 1) or leaves (`sign` -1) the board with the force it puts on it.
    pub(crate) fn join(&self, state: &mut BoardState, phi: &[Vec<f64>; 3], f: [f64; 3], sign: f64) {
        for k in 0..self.modes() {
            state.force[k] += sign * (phi[0][k] * f[0] + phi[1][k] * f[1] + phi[2][k] * f[2]);
        }
    }

    /// The shared modes' energy (J).
    pub(crate) fn energy_j(&self, state: &BoardState) -> f64 {
        (0..self.modes())
            .map(|k| {
                let z = c64::new(state.z.re[k], state.z.im[k]);
                let (q, v) = (2.0 * z.re, 2.0 * (self.lambda[k] * z).re);
                0.5 * (v * v + self.omega2[k] * q * q)
            })
            .sum()
    }

    /// `(I - T W)^{-1}` formed afresh for `W = sum Phi Z Phi^T` over `loads` (a test of the
    /// updates).
    #[cfg(test)]
    pub(crate) fn fresh_inverse(&self, loads: &[Load<'_>]) -> Vec<f64> {
        let m = self.modes();
        let w = |i: usize, j: usize| -> f64 {
            loads
                .iter()
                .map(|(phi, z)| {
                    (0..3)
                        .map(|a| (0..3).map(|b| phi[a][i] * z[a][b] * phi[b][j]).sum::<f64>())
                        .sum::<f64>()
                })
                .sum()
        };
        let a = faer::Mat::<f64>::from_fn(m, m, |i, j| {
            f64::from(u8::from(i == j)) - self.t[i] * w(i, j)
        });
        let inv = faer::linalg::solvers::DenseSolveCore::inverse(&a.partial_piv_lu());
        (0..m * m).map(|k| inv[(k % m, k / m)]).collect()
    }

    #[cfg(test)]
    pub(crate) fn inverse(&self) -> &[f64] {
        &self.inverse
    }
}

impl BoardState {
    pub(crate) fn rest(&mut self) {
        self.z.fill_zero();
        for v in [&mut self.force, &mut self.q, &mut self.known] {
            v.iter_mut().for_each(|x| *x = 0.0);
        }
    }

    /// Modes (padded).
    pub(crate) fn modes(&self) -> usize {
        self.force.len()
    }

    /// This state made a copy of `from` (the same board's; no allocation).
    pub(crate) fn copy_from(&mut self, from: &BoardState) {
        self.z.re.copy_from_slice(&from.z.re);
        self.z.im.copy_from_slice(&from.z.im);
        self.force.copy_from_slice(&from.force);
        self.q.copy_from_slice(&from.q);
    }

    /// The state as plain numbers (modes, force at the step's end), and back; the displacement
    /// follows from the modes.
    pub(crate) fn values(&self) -> Vec<f64> {
        let mut x = self.z.re.clone();
        x.extend_from_slice(&self.z.im);
        x.extend_from_slice(&self.force);
        x
    }

    pub(crate) fn set_values(&mut self, x: &[f64]) {
        let m = self.force.len();
        self.z.re.copy_from_slice(&x[..m]);
        self.z.im.copy_from_slice(&x[m..2 * m]);
        self.force.copy_from_slice(&x[2 * m..3 * m]);
        for k in 0..m {
            self.q[k] = 2.0 * self.z.re[k];
        }
    }
}

/// A key's mode shapes on the shared modes and its `Z` (a test's account of `W`).
#[cfg(test)]
pub(crate) type Load<'a> = (&'a [Vec<f64>; 3], [[f64; 3]; 3]);

/// The inverse of a 3×3 matrix (by its adjugate).
fn inverse3(a: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let cof = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0]
    };
    let det = a[0][0] * cof(0, 0) + a[0][1] * cof(0, 1) + a[0][2] * cof(0, 2);
    std::array::from_fn(|i| std::array::from_fn(|j| cof(j, i) / det))
}

/// [`SharedBoard::step`] in AVX2 + FMA: the modes stepped as the portable form, `(I - T W)^{-1}`
/// applied in registers of four.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn step_avx2(board: &SharedBoard, state: &mut BoardState, known: &[f64]) -> [f64; CHANNELS] {
    step_with::<true>(board, state, known)
}

/// [`SharedBoard::step`] one mode at a time: each mode propagated under the known force, its
/// displacement solved for, what the keys' `Z D^{n+1}` adds folded back in.
#[inline(always)]
fn step_with<const FMA: bool>(
    board: &SharedBoard,
    state: &mut BoardState,
    known: &[f64],
) -> [f64; CHANNELS] {
    let m = board.modes();
    let (e, from, to) = (&board.e, &board.from, &board.to);
    for k in 0..m {
        let (a, b, f0, f1) = (state.z.re[k], state.z.im[k], state.force[k], known[k]);
        let re = e.re[k] * a - e.im[k] * b + from.re[k] * f0 + to.re[k] * f1;
        let im = e.re[k] * b + e.im[k] * a + from.im[k] * f0 + to.im[k] * f1;
        (state.z.re[k], state.z.im[k]) = (re, im);
        state.known[k] = 2.0 * re;
    }
    matvec_with::<FMA>(&board.inverse, &state.known, &mut state.q);
    let mut volume = [0.0; CHANNELS];
    for k in 0..m {
        // W q from T W q = q - q_known (T > 0 on every mode but the padding, where q = 0).
        let wq = (state.q[k] - state.known[k]) * board.t_inv[k];
        state.z.re[k] += to.re[k] * wq;
        state.z.im[k] += to.im[k] * wq;
        state.force[k] = known[k] + wq;
        for (y, heard) in volume.iter_mut().zip(&board.heard) {
            *y += heard.re[k] * state.z.re[k] + heard.im[k] * state.z.im[k];
        }
    }
    volume
}

/// [`SharedBoard::step`] in AVX-512, a register of [`LANES`] modes at a time: the modes
/// propagated, `(I - T W)^{-1}` applied ([`matvec_avx512`]), the correction folded in, each
/// channel's source summed lane by lane.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn step_avx512(
    board: &SharedBoard,
    state: &mut BoardState,
    known: &[f64],
) -> [f64; CHANNELS] {
    use std::arch::x86_64::*;
    let m = board.modes();
    let (e, from, to) = (&board.e, &board.from, &board.to);
    let z = &mut state.z;
    let load = |v: &[f64], k: usize| _mm512_loadu_pd(v.as_ptr().add(k));
    for k in (0..m).step_by(LANES) {
        let (a, b) = (load(&z.re, k), load(&z.im, k));
        let (f0, f1) = (load(&state.force, k), load(known, k));
        let mut re = _mm512_mul_pd(load(&e.re, k), a);
        re = _mm512_fnmadd_pd(load(&e.im, k), b, re);
        re = _mm512_fmadd_pd(load(&from.re, k), f0, re);
        re = _mm512_fmadd_pd(load(&to.re, k), f1, re);
        let mut im = _mm512_mul_pd(load(&e.re, k), b);
        im = _mm512_fmadd_pd(load(&e.im, k), a, im);
        im = _mm512_fmadd_pd(load(&from.im, k), f0, im);
        im = _mm512_fmadd_pd(load(&to.im, k), f1, im);
        _mm512_storeu_pd(z.re.as_mut_ptr().add(k), re);
        _mm512_storeu_pd(z.im.as_mut_ptr().add(k), im);
        _mm512_storeu_pd(state.known.as_mut_ptr().add(k), _mm512_add_pd(re, re));
    }
    matvec_avx512(&board.inverse, &state.known, &mut state.q);
    let mut volume = [_mm512_setzero_pd(); CHANNELS];
    for k in (0..m).step_by(LANES) {
        let wq = _mm512_mul_pd(
            _mm512_sub_pd(load(&state.q, k), load(&state.known, k)),
            load(&board.t_inv, k),
        );
        let re = _mm512_fmadd_pd(load(&to.re, k), wq, load(&z.re, k));
        let im = _mm512_fmadd_pd(load(&to.im, k), wq, load(&z.im, k));
        _mm512_storeu_pd(z.re.as_mut_ptr().add(k), re);
        _mm512_storeu_pd(z.im.as_mut_ptr().add(k), im);
        _mm512_storeu_pd(
            state.force.as_mut_ptr().add(k),
            _mm512_add_pd(load(known, k), wq),
        );
        for (y, heard) in volume.iter_mut().zip(&board.heard) {
            *y = _mm512_fmadd_pd(load(&heard.re, k), re, *y);
            *y = _mm512_fmadd_pd(load(&heard.im, k), im, *y);
        }
    }
    volume.map(|y| _mm512_reduce_add_pd(y))
}

/// `y = A x` of a square `A` stored column by column, its order a whole number of lanes: `y`
/// in chunks held in registers, each column's chunk added in (independent sums, so that the
/// loop runs at the FMA units' rate rather than their latency).
#[inline(always)]
fn matvec_with<const FMA: bool>(a: &[f64], x: &[f64], y: &mut [f64]) {
    let m = x.len();
    let mut base = 0;
    while base + 4 * LANES <= m {
        matvec_chunk::<FMA, { 4 * LANES }>(a, x, &mut y[base..base + 4 * LANES], base);
        base += 4 * LANES;
    }
    while base < m {
        matvec_chunk::<FMA, LANES>(a, x, &mut y[base..base + LANES], base);
        base += LANES;
    }
}

/// Rows `base..base + C` of `y = A x`.
#[inline(always)]
fn matvec_chunk<const FMA: bool, const C: usize>(a: &[f64], x: &[f64], y: &mut [f64], base: usize) {
    let m = x.len();
    let mut acc = [0.0; C];
    for (b, &xb) in x.iter().enumerate() {
        let col: &[f64; C] = a[b * m + base..b * m + base + C].try_into().unwrap();
        for l in 0..C {
            acc[l] = fma::<FMA>(col[l], xb, acc[l]);
        }
    }
    y.copy_from_slice(&acc);
}

/// [`matvec_with`] in AVX-512: rows in chunks of up to eight registers, and each chunk's columns
/// shared round-robin among `S` sets of sums, so that at least eight sums are independent
/// (a chunk of one register alone would wait on the FMA's latency at every column).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn matvec_avx512(a: &[f64], x: &[f64], y: &mut [f64]) {
    let m = x.len();
    assert!(a.len() == m * m && y.len() == m && m.is_multiple_of(LANES));
    let mut base = 0;
    while base + 8 * LANES <= m {
        matvec_chunk_avx512::<8, 2>(a, x, y, base);
        base += 8 * LANES;
    }
    match (m - base) / LANES {
        0 => {}
        1 => matvec_chunk_avx512::<1, 8>(a, x, y, base),
        2 => matvec_chunk_avx512::<2, 4>(a, x, y, base),
        3 => matvec_chunk_avx512::<3, 3>(a, x, y, base),
        4 => matvec_chunk_avx512::<4, 2>(a, x, y, base),
        5 => matvec_chunk_avx512::<5, 2>(a, x, y, base),
        6 => matvec_chunk_avx512::<6, 2>(a, x, y, base),
        _ => matvec_chunk_avx512::<7, 2>(a, x, y, base),
    }
}

/// Rows `base..base + R LANES` of `y = A x` in `R` registers, in `S` sets of sums.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
unsafe fn matvec_chunk_avx512<const R: usize, const S: usize>(
    a: &[f64],
    x: &[f64],
    y: &mut [f64],
    base: usize,
) {
    use std::arch::x86_64::*;
    let m = x.len();
    debug_assert!(base + R * LANES <= m && a.len() == m * m);
    let mut acc = [[_mm512_setzero_pd(); R]; S];
    let add = |acc: &mut [__m512d; R], b: usize| {
        // SAFETY: column `b < m`, rows `base..base + R LANES <= m` (the caller's bounds).
        let col = a.as_ptr().add(b * m + base);
        let xb = _mm512_set1_pd(*x.get_unchecked(b));
        for (r, acc) in acc.iter_mut().enumerate() {
            *acc = _mm512_fmadd_pd(_mm512_loadu_pd(col.add(r * LANES)), xb, *acc);
        }
    };
    let whole = m - m % S;
    for b in (0..whole).step_by(S) {
        for (s, acc) in acc.iter_mut().enumerate() {
            add(acc, b + s);
        }
    }
    for b in whole..m {
        add(&mut acc[0], b);
    }
    for r in 0..R {
        let mut sum = acc[0][r];
        for acc in &acc[1..] {
            sum = _mm512_add_pd(sum, acc[r]);
        }
        _mm512_storeu_pd(y.as_mut_ptr().add(base + r * LANES), sum);
    }
}

/// `Phi^T q` (per direction) over modes padded to whole lanes, `Phi` packed
/// ([`BridgePoint::packed`]).
fn project(simd: Simd, q: &[f64], packed: &[f32]) -> [f64; 3] {
    assert_eq!(
        packed.len(),
        3 * q.len(),
        "a point packs three directions of every mode"
    );
    #[cfg(target_arch = "x86_64")]
    match simd {
        // SAFETY: `Simd::detect` chose these only where the CPU has them.
        Simd::Avx512 => return unsafe { project_avx512(q, packed) },
        Simd::Avx2 => return unsafe { project_avx2(q, packed) },
        Simd::Portable => {}
    }
    let _ = simd;
    project_with::<false>(q, packed)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn project_avx2(q: &[f64], packed: &[f32]) -> [f64; 3] {
    project_with::<true>(q, packed)
}

#[inline(always)]
fn project_with<const FMA: bool>(q: &[f64], packed: &[f32]) -> [f64; 3] {
    let m = q.len();
    let mut at = [[0.0; LANES]; 3];
    for (d, at) in at.iter_mut().enumerate() {
        for (q, p) in q
            .chunks_exact(LANES)
            .zip(packed[d * m..(d + 1) * m].chunks_exact(LANES))
        {
            for l in 0..LANES {
                at[l] = fma::<FMA>(f64::from(p[l]), q[l], at[l]);
            }
        }
    }
    at.map(|a| a.iter().sum())
}

/// [`project`] in AVX-512: a register of [`LANES`] modes a pass.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn project_avx512(q: &[f64], packed: &[f32]) -> [f64; 3] {
    use std::arch::x86_64::*;
    let m = q.len();
    assert!(packed.len() == 3 * m && m.is_multiple_of(LANES));
    let mut at = [_mm512_setzero_pd(); 3];
    for k in (0..m).step_by(LANES) {
        // SAFETY: `k + LANES <= m`, within `q` and each direction's `m` values of `packed`
        // (asserted above).
        let x = _mm512_loadu_pd(q.as_ptr().add(k));
        for (d, at) in at.iter_mut().enumerate() {
            let p = _mm512_cvtps_pd(_mm256_loadu_ps(packed.as_ptr().add(d * m + k)));
            *at = _mm512_fmadd_pd(p, x, *at);
        }
    }
    at.map(|a| _mm512_reduce_add_pd(a))
}

/// `sum += Phi f` over modes padded to whole lanes, `Phi` packed ([`BridgePoint::packed`]).
fn spread(simd: Simd, packed: &[f32], f: [f64; 3], sum: &mut [f64]) {
    assert_eq!(
        packed.len(),
        3 * sum.len(),
        "a point packs three directions of every mode"
    );
    #[cfg(target_arch = "x86_64")]
    match simd {
        // SAFETY: `Simd::detect` chose these only where the CPU has them.
        Simd::Avx512 => return unsafe { spread_avx512(packed, f, sum) },
        Simd::Avx2 => return unsafe { spread_avx2(packed, f, sum) },
        Simd::Portable => {}
    }
    let _ = simd;
    spread_with::<false>(packed, f, sum)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn spread_avx2(packed: &[f32], f: [f64; 3], sum: &mut [f64]) {
    spread_with::<true>(packed, f, sum)
}

#[inline(always)]
fn spread_with<const FMA: bool>(packed: &[f32], f: [f64; 3], sum: &mut [f64]) {
    let m = sum.len();
    let (p0, rest) = packed.split_at(m);
    let (p1, p2) = rest.split_at(m);
    for (k, s) in sum.iter_mut().enumerate() {
        *s = fma::<FMA>(
            f64::from(p0[k]),
            f[0],
            fma::<FMA>(
                f64::from(p1[k]),
                f[1],
                fma::<FMA>(f64::from(p2[k]), f[2], *s),
            ),
        );
    }
}

/// [`spread`] in AVX-512: a register of [`LANES`] modes a pass.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn spread_avx512(packed: &[f32], f: [f64; 3], sum: &mut [f64]) {
    use std::arch::x86_64::*;
    let m = sum.len();
    assert!(packed.len() == 3 * m && m.is_multiple_of(LANES));
    let g = f.map(|x| _mm512_set1_pd(x));
    let phi = |d: usize, k: usize| _mm512_cvtps_pd(_mm256_loadu_ps(packed.as_ptr().add(d * m + k)));
    for k in (0..m).step_by(LANES) {
        // SAFETY: `k + LANES <= m`, within `sum` and each direction's `m` values of `packed`
        // (asserted above).
        let at = sum.as_mut_ptr().add(k);
        let mut s = _mm512_loadu_pd(at);
        s = _mm512_fmadd_pd(phi(2, k), g[2], s);
        s = _mm512_fmadd_pd(phi(1, k), g[1], s);
        s = _mm512_fmadd_pd(phi(0, k), g[0], s);
        _mm512_storeu_pd(at, s);
    }
}

/// A key's bridge point on the shared modes: each direction's mode shapes there (padded to
/// whole lanes), rounded to single precision. In double (`phi`) for what changes the interface
/// (a key joining or leaving, its `Z`); the same values packed in single precision, direction
/// after direction (`packed`), for the displacement read and the force spread at every step —
/// the per-sample sweep over the voices brings every sounding key's point in from the cache
/// twice a sample, and half the bytes are half that traffic.
#[derive(Debug, Clone)]
pub(crate) struct BridgePoint {
    pub(crate) phi: [Vec<f64>; 3],
    packed: Vec<f32>,
}

impl BridgePoint {
    fn new(phi: [Vec<f64>; 3]) -> BridgePoint {
        let packed: Vec<f32> = phi.iter().flatten().map(|&x| x as f32).collect();
        let m = phi[0].len();
        BridgePoint {
            phi: std::array::from_fn(|d| {
                packed[d * m..(d + 1) * m]
                    .iter()
                    .map(|&x| f64::from(x))
                    .collect()
            }),
            packed,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::preset::Preset;

    #[test]
    fn the_woodbury_updates_keep_the_inverse() {
        // Thirty keys' worth of rank-3 updates (joins, damper changes, leaves) on the c2 board,
        // against the inverse formed afresh.
        let spec = Preset::resolve("c2").unwrap().unison_spec();
        let mut board = SharedBoard::new(&spec.board, 1.0 / 48_000.0);
        let mut next = crate::engine::exact::test_numbers(7);
        let points: Vec<[Vec<f64>; 3]> = spec
            .board
            .points
            .iter()
            .take(30)
            .map(|p| board.restrict(&p.shape).phi)
            .collect();
        // A key's Z: the contact springs' direct part (about -2 k_c per direction) and a little
        // more.
        let zs: Vec<[[f64; 3]; 3]> = (0..30)
            .map(|_| {
                std::array::from_fn(|i| {
                    std::array::from_fn(|d| {
                        let direct = if i == d { -1.0e7 } else { 0.0 };
                        direct + 1.0e5 * next()
                    })
                })
            })
            .collect();
        for (p, z) in points.iter().zip(&zs) {
            board.update(p, z);
        }
        for (p, z) in points.iter().zip(&zs).step_by(3) {
            board.update(p, &z.map(|r| r.map(|x| -x)));
        }
        let kept: Vec<_> = points
            .iter()
            .zip(&zs)
            .enumerate()
            .filter(|(k, _)| k % 3 != 0)
            .map(|(_, (p, z))| (p, *z))
            .collect();
        let fresh = board.fresh_inverse(&kept);
        let worst = board
            .inverse()
            .iter()
            .zip(&fresh)
            .fold(0f64, |m, (a, b)| m.max((a - b).abs()));
        let scale = fresh.iter().fold(0f64, |m, x| m.max(x.abs()));
        println!(
            "40 rank-3 updates vs the inverse formed afresh: {:.1e} of its largest entry",
            worst / scale
        );
        assert!(worst / scale < 1e-10, "{}", worst / scale);
    }

    #[test]
    fn the_fast_matrix_products_agree_with_the_plain_sum() {
        // `(I - T W)^{-1} q` for every order of 8 to 160 modes: each chunk of rows and each way
        // of sharing the columns among sets of sums (a column left over when the order is not a
        // multiple of the sets), against the sum taken one term at a time in f64. What differs
        // is the order of the sums: rounding, under 1e-16 of the terms' size (a column left out
        // would be about 1 / m of it).
        let mut next = crate::engine::exact::test_numbers(11);
        let detected = Simd::detect();
        let mut worst = 0f64;
        for m in (LANES..=160).step_by(LANES) {
            let a: Vec<f64> = (0..m * m).map(|_| next()).collect();
            let x: Vec<f64> = (0..m).map(|_| next()).collect();
            let plain: Vec<f64> = (0..m)
                .map(|r| (0..m).map(|b| a[b * m + r] * x[b]).sum())
                .collect();
            let mut forms: Vec<(&str, Vec<f64>)> = Vec::new();
            let mut y = vec![0.0; m];
            matvec_with::<false>(&a, &x, &mut y);
            forms.push(("portable", y.clone()));
            #[cfg(target_arch = "x86_64")]
            if detected == Simd::Avx512 {
                // SAFETY: the CPU has AVX-512; `a` is m × m, `m` a whole number of lanes.
                unsafe { matvec_avx512(&a, &x, &mut y) };
                forms.push(("avx512", y.clone()));
            }
            let scale: f64 = (0..m).map(|b| x[b].abs()).sum();
            for (form, y) in &forms {
                let error = y
                    .iter()
                    .zip(&plain)
                    .fold(0f64, |e, (y, p)| e.max((y - p).abs()))
                    / scale;
                assert!(error < 3e-16, "{form}, order {m}: {error:e}");
                worst = worst.max(error);
            }
        }
        println!(
            "the products of orders 8-160 ({detected:?}) within {worst:.1e} of the terms' size"
        );
    }
}
