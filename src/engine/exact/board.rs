//! The coupling between keys through the shared soundboard.
//!
//! Each key carries its own copy of the board in its modes, driven by its own contact forces, so
//! the true board's motion is the sum of the copies (the board is linear). A key's strings must
//! feel the whole board, so each key is also driven by the *other* keys' board motion at its
//! bridge point, `D_k = phi_k^T sum_{j != k} b_j`. That is formed here from the forces alone: a
//! modal integration of the board (its modes are diagonal, `z_m' = lambda_m z_m + f_m/(2 i
//! omega_dm)`, `q_m = 2 Re z_m`) driven by the sum of every key's force, less the same
//! integration driven by the key's own force — so that what a key receives holds no part of
//! itself, whatever the scheme's error (reading the key's own exact copy instead would leave
//! that error, `O((omega h)^2)` of its own large part, in its input). The forces enter linearly
//! over the step between their values at its ends (exact for such a force), so the shared part
//! lags the keys by one step: each key extrapolates `D` over the next step from its last two
//! values (a ramp), which keeps the coupled system's decay (`tests/exact_pool.rs`).

use super::kernels::{fma, Split, LANES};
use crate::engine::modal::input_weights;
use crate::engine::physics::soundboard::SoundboardModes;
use faer::c64;

/// The keys are coupled through the board's modes below this frequency (Hz); each key's own copy
/// keeps them all. Above it the coupling's one-step lag, extrapolated, is no longer accurate
/// enough: with all 88 keys sounding the coupled pool runs away at 4.6 kHz when the modes up to
/// 5 kHz couple, and stays stable up to 4 kHz (`tests/exact_pool.rs`); sympathy and chords are
/// carried by the modes well below (`tests/exact_pool.rs`, `tests/stability.rs`).
pub(crate) const COUPLING_MAX_HZ: f64 = 3000.0;

/// The board's modes as the coupling integrates them, and the shared part's state. Owned and
/// stepped by the thread that steps the pool.
#[derive(Debug, Clone)]
pub(crate) struct BoardCoupling {
    /// The board's modes the keys are coupled through (below [`COUPLING_MAX_HZ`]).
    modes: Vec<usize>,
    /// Per mode `e^{lambda h}`, and the weights of the force at the start and the end of the step.
    e: Split,
    from: Split,
    to: Split,
    lambda: Vec<c64>,
    omega2: Vec<f64>,
}

/// The shared part's state: every key's part together, and the modal force of every key at the
/// start of the step. Owned by the thread that steps the pool; the pool keeps a replica per half
/// of its voices, stepped alike.
#[derive(Debug, Clone)]
pub(crate) struct SharedPart {
    shared: Split,
    force_before: Vec<f64>,
}

impl BoardCoupling {
    pub(crate) fn new(board: &SoundboardModes, h: f64) -> BoardCoupling {
        let modes: Vec<usize> = (0..board.len())
            .filter(|&k| board.freq_hz[k] < COUPLING_MAX_HZ)
            .collect();
        let m = modes.len();
        let mut lambda = Vec::with_capacity(m);
        let mut omega2 = Vec::with_capacity(m);
        let (mut e, mut from, mut to) = (Vec::new(), Vec::new(), Vec::new());
        for &k in &modes {
            let osc = board.oscillator(k);
            let (w, zeta) = (osc.omega_rad_s, osc.damping_ratio);
            let wd = w * (1.0 - zeta * zeta).sqrt();
            let l = c64::new(-zeta * w, wd);
            let g = c64::new(0.0, -0.5 / wd); // 1 / (2 i omega_d)
            let [w1, w2] = input_weights(l, h);
            e.push((l * h).exp());
            from.push(g * (w1 - w2 / h));
            to.push(g * (w2 / h));
            lambda.push(l);
            omega2.push(w * w);
        }
        // Padded to whole lanes with modes that are never driven and never move (their `e`,
        // weights and shapes zero), so that the loops over modes have no remainder.
        let padded = m.div_ceil(LANES) * LANES;
        for v in [&mut e, &mut from, &mut to, &mut lambda] {
            v.resize(padded, c64::new(0.0, 0.0));
        }
        omega2.resize(padded, 0.0);
        BoardCoupling {
            modes,
            e: Split::new(&e),
            from: Split::new(&from),
            to: Split::new(&to),
            lambda,
            omega2,
        }
    }

    /// The shared part at rest.
    pub(crate) fn part(&self) -> SharedPart {
        SharedPart {
            shared: Split::zeros(self.e.len()),
            force_before: vec![0.0; self.e.len()],
        }
    }

    pub(crate) fn modes(&self) -> usize {
        self.e.len()
    }

    /// A key's mode shapes at its bridge point (all the board's modes) restricted to the
    /// coupling's (zero on the padding).
    pub(crate) fn restrict(&self, shape: &[Vec<f64>; 3]) -> [Vec<f64>; 3] {
        std::array::from_fn(|d| {
            let mut phi: Vec<f64> = self.modes.iter().map(|&k| shape[d][k]).collect();
            phi.resize(self.e.len(), 0.0);
            phi
        })
    }

    /// Advance a key's own part over the step in which its total contact force went from
    /// `before` to `after` (N, per direction, at its point `phi`), add that force to `sum` (the
    /// step's modal force), and return the own part's displacement at the point after the step (m, per
    /// direction); with AVX2 + FMA where `fast`.
    pub(crate) fn step_own(
        &self,
        fast: bool,
        own: &mut Split,
        phi: &[Vec<f64>; 3],
        (before, after): ([f64; 3], [f64; 3]),
        sum: &mut [f64],
    ) -> [f64; 3] {
        #[cfg(target_arch = "x86_64")]
        if fast {
            // SAFETY: `fast` is set only where `has_avx2_fma()` found AVX2 and FMA.
            return unsafe { self.step_own_avx2(own, phi, before, after, sum) };
        }
        let _ = fast;
        self.step_own_with::<false>(own, phi, before, after, sum)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn step_own_avx2(
        &self,
        own: &mut Split,
        phi: &[Vec<f64>; 3],
        before: [f64; 3],
        after: [f64; 3],
        sum: &mut [f64],
    ) -> [f64; 3] {
        self.step_own_with::<true>(own, phi, before, after, sum)
    }

    #[inline(always)]
    fn step_own_with<const FMA: bool>(
        &self,
        own: &mut Split,
        phi: &[Vec<f64>; 3],
        before: [f64; 3],
        after: [f64; 3],
        sum: &mut [f64],
    ) -> [f64; 3] {
        let n = self.e.len();
        let (er, ei) = (&self.e.re[..n], &self.e.im[..n]);
        let (fr, fi, tr, ti) = (
            &self.from.re[..n],
            &self.from.im[..n],
            &self.to.re[..n],
            &self.to.im[..n],
        );
        let (or, oi) = (&mut own.re[..n], &mut own.im[..n]);
        let (p0, p1, p2) = (&phi[0][..n], &phi[1][..n], &phi[2][..n]);
        let sum = &mut sum[..n];
        let mut at = [[0.0; LANES]; 3];
        // The modes are padded to whole lanes ([`BoardCoupling::new`]); each chunk is loaded into
        // registers (local arrays), so that the lanes vectorise.
        for base in (0..n).step_by(LANES) {
            let r = base..base + LANES;
            let ld = |x: &[f64]| -> [f64; LANES] { x[r.clone()].try_into().unwrap() };
            let (er, ei, fr, fi, tr, ti) = (ld(er), ld(ei), ld(fr), ld(fi), ld(tr), ld(ti));
            let (p0, p1, p2) = (ld(p0), ld(p1), ld(p2));
            let (mut zr, mut zi, mut sm) = (ld(or), ld(oi), ld(sum));
            for l in 0..LANES {
                let f0 = fma::<FMA>(
                    p0[l],
                    before[0],
                    fma::<FMA>(p1[l], before[1], p2[l] * before[2]),
                );
                let f1 = fma::<FMA>(
                    p0[l],
                    after[0],
                    fma::<FMA>(p1[l], after[1], p2[l] * after[2]),
                );
                let (a, b) = (zr[l], zi[l]);
                zr[l] = fma::<FMA>(
                    er[l],
                    a,
                    fma::<FMA>(-ei[l], b, fma::<FMA>(fr[l], f0, tr[l] * f1)),
                );
                zi[l] = fma::<FMA>(
                    er[l],
                    b,
                    fma::<FMA>(ei[l], a, fma::<FMA>(fi[l], f0, ti[l] * f1)),
                );
                sm[l] += f1;
                let q = 2.0 * zr[l];
                at[0][l] = fma::<FMA>(p0[l], q, at[0][l]);
                at[1][l] = fma::<FMA>(p1[l], q, at[1][l]);
                at[2][l] = fma::<FMA>(p2[l], q, at[2][l]);
            }
            or[r.clone()].copy_from_slice(&zr);
            oi[r.clone()].copy_from_slice(&zi);
            sum[r].copy_from_slice(&sm);
        }
        at.map(|a| a.iter().sum())
    }

    /// Advance the shared part over the step in which every key's modal force together went
    /// from the part's last to `force_now`.
    pub(crate) fn step_shared(&self, part: &mut SharedPart, force_now: &[f64]) {
        let (e, from, to) = (&self.e, &self.from, &self.to);
        let g = &mut part.shared;
        for m in 0..e.len() {
            let (f0, f1) = (part.force_before[m], force_now[m]);
            let (a, b) = (g.re[m], g.im[m]);
            g.re[m] = e.re[m] * a - e.im[m] * b + from.re[m] * f0 + to.re[m] * f1;
            g.im[m] = e.re[m] * b + e.im[m] * a + from.im[m] * f0 + to.im[m] * f1;
        }
        part.force_before.copy_from_slice(&force_now[..e.len()]);
    }

    /// The shared part's displacement at a key's point `phi` (m, per direction: every key's,
    /// its own included); with AVX2 + FMA where `fast`.
    pub(crate) fn shared_at(&self, part: &SharedPart, fast: bool, phi: &[Vec<f64>; 3]) -> [f64; 3] {
        #[cfg(target_arch = "x86_64")]
        if fast {
            // SAFETY: `fast` is set only where `has_avx2_fma()` found AVX2 and FMA.
            return unsafe { self.shared_at_avx2(part, phi) };
        }
        let _ = fast;
        self.shared_at_with::<false>(part, phi)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn shared_at_avx2(&self, part: &SharedPart, phi: &[Vec<f64>; 3]) -> [f64; 3] {
        self.shared_at_with::<true>(part, phi)
    }

    #[inline(always)]
    fn shared_at_with<const FMA: bool>(&self, part: &SharedPart, phi: &[Vec<f64>; 3]) -> [f64; 3] {
        let n = self.e.len();
        let s = &part.shared.re[..n];
        let (p0, p1, p2) = (&phi[0][..n], &phi[1][..n], &phi[2][..n]);
        let mut at = [[0.0; LANES]; 3];
        for base in (0..n).step_by(LANES) {
            let r = base..base + LANES;
            let ld = |x: &[f64]| -> [f64; LANES] { x[r.clone()].try_into().unwrap() };
            let (q, p0, p1, p2) = (ld(s), ld(p0), ld(p1), ld(p2));
            for l in 0..LANES {
                at[0][l] = fma::<FMA>(p0[l], 2.0 * q[l], at[0][l]);
                at[1][l] = fma::<FMA>(p1[l], 2.0 * q[l], at[1][l]);
                at[2][l] = fma::<FMA>(p2[l], 2.0 * q[l], at[2][l]);
            }
        }
        at.map(|a| a.iter().sum())
    }

    /// A key joins (`sign` 1) or leaves (`sign` -1) the shared part with its own part and its
    /// last force.
    pub(crate) fn join(
        &self,
        part: &mut SharedPart,
        own: &Split,
        phi: &[Vec<f64>; 3],
        force: [f64; 3],
        sign: f64,
    ) {
        for m in 0..self.e.len() {
            part.shared.re[m] += sign * own.re[m];
            part.shared.im[m] += sign * own.im[m];
            part.force_before[m] +=
                sign * (phi[0][m] * force[0] + phi[1][m] * force[1] + phi[2][m] * force[2]);
        }
    }

    /// The shared part's energy as a board's (J): a measure of its size.
    pub(crate) fn energy_j(&self, part: &SharedPart) -> f64 {
        (0..self.e.len())
            .map(|m| {
                let z = c64::new(part.shared.re[m], part.shared.im[m]);
                let (q, v) = (2.0 * z.re, 2.0 * (self.lambda[m] * z).re);
                0.5 * (v * v + self.omega2[m] * q * q)
            })
            .sum()
    }
}

impl SharedPart {
    pub(crate) fn rest(&mut self) {
        self.shared.fill_zero();
        self.force_before.iter_mut().for_each(|f| *f = 0.0);
    }

    /// Take `other`'s values (no allocation).
    pub(crate) fn copy_from(&mut self, other: &SharedPart) {
        self.shared.re.copy_from_slice(&other.shared.re);
        self.shared.im.copy_from_slice(&other.shared.im);
        self.force_before.copy_from_slice(&other.force_before);
    }

    /// The shared part and the force at the start of the step, as plain numbers (the linear
    /// state), and back.
    pub(crate) fn state(&self) -> Vec<f64> {
        let mut x = self.shared.re.clone();
        x.extend_from_slice(&self.shared.im);
        x.extend_from_slice(&self.force_before);
        x
    }

    pub(crate) fn set_state(&mut self, x: &[f64]) {
        let m = self.force_before.len();
        self.shared.re.copy_from_slice(&x[..m]);
        self.shared.im.copy_from_slice(&x[m..2 * m]);
        self.force_before.copy_from_slice(&x[2 * m..3 * m]);
    }
}
