//! The paper's formulation taken literally, as a MATLAB user runs it: Eq. 10,
//! `xdot = A x + B u + B2 F_b`, with the dense state matrix `A` of Eq. 11 (duplex damping Eq. 13
//! inside it), dense `B` (Eq. 14–15), `B2` (Eq. 17) and output matrix `C` (Eq. 19), advanced with
//! classical RK4. Every evaluation is a dense matrix–vector product, O(n²) in the state size.
//!
//! It is assembled here from the physical parts (string, duplex, board, contact, hammer) without
//! the optimised [`crate::engine::rk4`]'s layout or kernels, so that the two check each other, and it
//! is the baseline the optimised engine's speed is reported against.

use crate::engine::physics::duplex::duplex_damping_matrix;
use crate::engine::physics::hammer::FeltLaw;
use crate::engine::spec::Direction;
use crate::engine::spec::{Strike, UnisonSpec, MAX_STRINGS};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};
use std::ops::Range;

/// One unison in the paper's dense state-space form.
pub struct DenseUnison {
    spec: UnisonSpec,
    n_strings: usize,
    /// Length of `q` (all string and board modes), and where each string's directions and the
    /// board lie in it.
    nq: usize,
    ranges: [[Range<usize>; 3]; MAX_STRINGS],
    board: Range<usize>,
    a: Mat<f64>,
    b: Mat<f64>,
    b2: Mat<f64>,
    c: Mat<f64>,
    x: Mat<f64>,
    // RK4 scratch.
    xs: Mat<f64>,
    k: Mat<f64>,
    sum: Mat<f64>,
    y: Mat<f64>,
    u: Mat<f64>,
    fb: Mat<f64>,
    felt: [Option<FeltLaw>; MAX_STRINGS],
    hammer_on: bool,
    h: f64,
}

/// Rows of the output `y = C x`: bridge displacement and velocity of each string and direction,
/// of the board at the bridge, and each string's displacement and velocity under the hammer.
fn out_rs(s: usize, d: usize) -> usize {
    3 * s + d
}
fn out_vs(s: usize, d: usize) -> usize {
    3 * MAX_STRINGS + 3 * s + d
}
fn out_rb(d: usize) -> usize {
    6 * MAX_STRINGS + d
}
fn out_vb(d: usize) -> usize {
    6 * MAX_STRINGS + 3 + d
}
fn out_ye(s: usize) -> usize {
    6 * MAX_STRINGS + 6 + s
}
fn out_ve(s: usize) -> usize {
    7 * MAX_STRINGS + 6 + s
}
const OUTPUTS: usize = 8 * MAX_STRINGS + 6;

/// `dst = a x` (`Replace`) or `dst += a x` (`Add`): faer's product, on one core.
fn gemv(dst: &mut Mat<f64>, accum: Accum, a: &Mat<f64>, x: &Mat<f64>) {
    matmul(dst.as_mut(), accum, a.as_ref(), x.as_ref(), 1.0, Par::Seq);
}

impl DenseUnison {
    /// Assemble `A`, `B`, `B2` and `C` for `spec`.
    pub fn new(spec: &UnisonSpec) -> DenseUnison {
        let ns = spec.strings.len().min(MAX_STRINGS);
        let (nt, np, nl) = (spec.modes.modes_t, spec.modes.modes_p, spec.modes.modes_l);
        let per_string = nt + np + nl;
        let nb = spec.board.len();
        let nq = ns * per_string + nb;
        let n = 2 * nq + 2;
        let mut ranges: [[Range<usize>; 3]; MAX_STRINGS] = Default::default();
        for (s, r) in ranges.iter_mut().enumerate().take(ns) {
            let o = s * per_string;
            *r = [o..o + nt, o + nt + np..o + per_string, o + nt..o + nt + np];
        }
        let board = ns * per_string..nq;
        let point = &spec.board.points[spec.bridge_point];
        let mut a = Mat::<f64>::zeros(n, n);
        let mut b = Mat::<f64>::zeros(n, ns);
        let mut b2 = Mat::<f64>::zeros(n, 3 * (ns + 1));
        let mut c = Mat::<f64>::zeros(OUTPUTS, n);
        // Kinematics: qdot rows of A are the identity; the hammer's [0 1; 0 0].
        for i in 0..nq {
            a[(i, nq + i)] = 1.0;
        }
        a[(2 * nq, 2 * nq + 1)] = 1.0;
        for (s, string) in spec.strings.iter().enumerate().take(ns) {
            let ls = string.speaking_length_m;
            for dir in Direction::ALL {
                let d = dir.index();
                for (k, i) in ranges[s][d].clone().enumerate() {
                    let mode = string.oscillator(dir, k + 1, &spec.modes);
                    // -K and -C (Eq. 11, 12).
                    a[(nq + i, i)] = -mode.omega2();
                    a[(nq + i, nq + i)] = -mode.damping_per_s();
                    let phi = string.mode_shape(k + 1, ls);
                    // B2 (Eq. 17): the string's bridge forces on its own modes.
                    b2[(nq + i, 3 * s + d)] = phi;
                    // C (Eq. 19): the string's bridge point, displacement and velocity.
                    c[(out_rs(s, d), i)] = phi;
                    c[(out_vs(s, d), nq + i)] = phi;
                }
            }
            // -C_d on both transverse polarisations (Eq. 13), for this string's length.
            let nd = nt.max(np);
            let cd = duplex_damping_matrix(
                nd,
                string.length_m(),
                ls,
                spec.duplex_damping_n_s_m2,
                string.linear_density_kg_m,
            );
            for d in [0, 2] {
                let r = ranges[s][d].clone();
                for (p, i) in r.clone().enumerate() {
                    for (q, j) in r.clone().enumerate() {
                        a[(nq + i, nq + j)] -= cd[p * nd + q];
                    }
                }
            }
            // B (Eq. 14–16): the hammer's force on the T modes at the striking point, and on the
            // hammer mass.
            let xe = spec.hammer.strike_ratio * spec.strings[0].speaking_length_m;
            for (k, i) in ranges[s][0].clone().enumerate() {
                let phi = string.mode_shape(k + 1, xe);
                b[(nq + i, s)] = phi;
                c[(out_ye(s), i)] = phi;
                c[(out_ve(s), nq + i)] = phi;
            }
            b[(2 * nq + 1, s)] = -1.0 / spec.hammer.mass_kg;
        }
        for (k, i) in board.clone().enumerate() {
            let mode = spec.board.oscillator(k);
            a[(nq + i, i)] = -mode.omega2();
            a[(nq + i, nq + i)] = -mode.damping_per_s();
            for d in 0..3 {
                let phi = point.shape[d][k];
                b2[(nq + i, 3 * ns + d)] = phi;
                c[(out_rb(d), i)] = phi;
                c[(out_vb(d), nq + i)] = phi;
            }
        }
        let col = |len| Mat::<f64>::zeros(len, 1);
        DenseUnison {
            spec: spec.clone(),
            n_strings: ns,
            nq,
            ranges,
            board,
            a,
            b,
            b2,
            c,
            x: col(n),
            xs: col(n),
            k: col(n),
            sum: col(n),
            y: col(OUTPUTS),
            u: col(ns),
            fb: col(3 * (ns + 1)),
            felt: [None; MAX_STRINGS],
            hammer_on: false,
            h: 1.0 / spec.sample_rate_hz,
        }
    }

    /// State size (the order of `A`).
    pub fn state_len(&self) -> usize {
        self.x.nrows()
    }

    /// The linear part of Eq. 10 with the hammer out of play: `xdot = (A + B2 G C) x` over
    /// `x = (q, qdot)` (the hammer's two states left out), where `F_b = G C x` are the contact
    /// forces of Eq. 6 (Eq. 17), each string on its contact spring and damper against the board.
    /// Its eigenvalues are every partial's frequency and decay, exactly (DESIGN.md §5).
    pub fn linear_system(&self) -> Mat<f64> {
        let (ns, n) = (self.n_strings, 2 * self.nq);
        let ct = &self.spec.contact;
        // G: outputs (bridge displacement and velocity of strings and board) to F_b.
        let mut g = Mat::<f64>::zeros(3 * (ns + 1), OUTPUTS);
        for s in 0..ns {
            for d in 0..3 {
                let (k, c) = (ct.stiffness_n_m[d], ct.damping_n_s_m[d]);
                for (row, sign) in [(3 * s + d, -1.0), (3 * ns + d, 1.0)] {
                    g[(row, out_rs(s, d))] += sign * k;
                    g[(row, out_rb(d))] -= sign * k;
                    g[(row, out_vs(s, d))] += sign * c;
                    g[(row, out_vb(d))] -= sign * c;
                }
            }
        }
        let gc = &g * &self.c;
        let coupled = &self.a + &self.b2 * &gc;
        coupled.submatrix(0, 0, n, n).to_owned()
    }

    /// Where string `s`'s modes in direction `d` (T, L, P) and the board's lie in `q`.
    pub fn layout(&self) -> ([[Range<usize>; 3]; MAX_STRINGS], Range<usize>) {
        (self.ranges.clone(), self.board.clone())
    }

    /// Launch the hammer as [`crate::engine::Rk4Pool::strike_voice`] does: in contact with the struck
    /// strings' current displacement, moving at the strike's speed.
    pub fn strike(&mut self, strike: Strike) {
        let ns = self.n_strings;
        self.felt = strike.felt_laws(&self.spec.hammer, ns);
        self.outputs_of_x();
        let (mut contact, mut nearest_m) = (f64::NEG_INFINITY, f64::INFINITY);
        for s in 0..ns {
            if let Some(law) = self.felt[s] {
                contact = contact.max(self.y[(out_ye(s), 0)]);
                nearest_m = nearest_m.min(law.offset_m);
            }
        }
        self.x[(2 * self.nq, 0)] = contact + nearest_m;
        self.x[(2 * self.nq + 1, 0)] = strike.velocity_m_s;
        self.hammer_on = true;
    }

    /// `y = C x` at the current state.
    fn outputs_of_x(&mut self) {
        gemv(&mut self.y, Accum::Replace, &self.c, &self.x);
    }

    /// The right-hand side of Eq. 10 at `xs`, into `k`.
    fn evaluate(&mut self) {
        let (ns, nq) = (self.n_strings, self.nq);
        gemv(&mut self.y, Accum::Replace, &self.c, &self.xs);
        // Contact forces (Eq. 6) into F_b = (-F_1, -F_2, F_1 + F_2) (Eq. 17).
        for d in 0..3 {
            let mut total = 0.0;
            for s in 0..ns {
                let f = self.contact_force_n(s, d);
                self.fb[(3 * s + d, 0)] = -f;
                total += f;
            }
            self.fb[(3 * ns + d, 0)] = total;
        }
        // Hammer forces (Eq. 8) on the struck strings.
        for s in 0..ns {
            self.u[(s, 0)] = match (self.hammer_on, self.felt[s]) {
                (true, Some(law)) => {
                    let (yh, vh) = (self.xs[(2 * nq, 0)], self.xs[(2 * nq + 1, 0)]);
                    law.force_n(
                        yh - self.y[(out_ye(s), 0)],
                        vh - self.y[(out_ve(s), 0)],
                        self.spec.hammer.hysteresis_s,
                    )
                }
                _ => 0.0,
            };
        }
        gemv(&mut self.k, Accum::Replace, &self.a, &self.xs);
        gemv(&mut self.k, Accum::Add, &self.b, &self.u);
        gemv(&mut self.k, Accum::Add, &self.b2, &self.fb);
        if !self.hammer_on {
            self.k[(2 * nq, 0)] = 0.0;
            self.k[(2 * nq + 1, 0)] = 0.0;
        }
    }

    /// One classical RK4 step; the hammer leaves the system, as in the optimised engine, once it
    /// recedes and is clear of every struck string by the release gap.
    pub fn step(&mut self) {
        let (h, n) = (self.h, self.state_len());
        self.xs.copy_from(&self.x);
        // Stage weights 1, 2, 2, 1; the next stage at h/2, h/2, h.
        for (stage, (w, c)) in [(1.0, 0.5), (2.0, 0.5), (2.0, 1.0), (1.0, 0.0)]
            .into_iter()
            .enumerate()
        {
            self.evaluate();
            for i in 0..n {
                let ki = self.k[(i, 0)];
                self.sum[(i, 0)] = if stage == 0 {
                    ki
                } else {
                    self.sum[(i, 0)] + w * ki
                };
                self.xs[(i, 0)] = self.x[(i, 0)] + c * h * ki;
            }
        }
        for i in 0..n {
            self.x[(i, 0)] += h / 6.0 * self.sum[(i, 0)];
        }
        let (yh, vh) = (self.x[(2 * self.nq, 0)], self.x[(2 * self.nq + 1, 0)]);
        if self.hammer_on && vh < 0.0 {
            self.outputs_of_x();
            let points = (0..self.n_strings)
                .filter(|&s| self.felt[s].is_some())
                .map(|s| self.y[(out_ye(s), 0)]);
            if self.spec.hammer.is_clear(yh, vh, points) {
                self.hammer_on = false;
            }
        }
    }

    /// Force of each string on the bridge per direction T, L, P (N) (Eq. 6) at the current state.
    pub fn bridge_forces_n(&mut self) -> [[f64; 3]; MAX_STRINGS] {
        self.outputs_of_x();
        let mut f = [[0.0; 3]; MAX_STRINGS];
        for (s, fs) in f.iter_mut().enumerate().take(self.n_strings) {
            for (d, fsd) in fs.iter_mut().enumerate() {
                *fsd = self.contact_force_n(s, d);
            }
        }
        f
    }

    /// Force of string `s` on the bridge in direction `d` (Eq. 6), from the outputs `y`.
    fn contact_force_n(&self, s: usize, d: usize) -> f64 {
        let y = &self.y;
        self.spec.contact.force_n(
            d,
            y[(out_rs(s, d), 0)] - y[(out_rb(d), 0)],
            y[(out_vs(s, d), 0)] - y[(out_vb(d), 0)],
        )
    }
}
