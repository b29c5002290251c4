//! One key integrated exactly: its strings on their contact springs and dampers, the duplex
//! damping and the soundboard under its bridge point form one linear time-invariant system,
//! diagonalised once into complex modes, so that between hammer contacts a voice advances by
//! `z <- e^{lambda h} z` each sample — no stages, unconditionally stable, exact for the key.
//!
//! Why this formulation (issue 16). The live integrator before it ([`crate::engine::etd`])
//! diagonalises each string direction alone and couples every direction to the board explicitly
//! at four ETDRK4 stages per sample; per voice and step that is ~42 FLOP per string mode plus
//! ~9.4 kFLOP of board reads and writes, and 32 voices already ask 28 GFLOP/s. Here the board is
//! part of each key's modes, so a sounding voice costs 6 FLOP per complex mode to propagate and
//! ~4 per mode for each output it is read at (the board's volume velocity), with no stage and no
//! board traffic. Only the felt hammer is nonlinear, and only for the few milliseconds it
//! touches: then the step is ETDRK4 (Cox & Matthews 2002) with the felt force as the nonlinear
//! term on the key's modes and on the hammer (whose linear part is zero, so its stages are
//! classical RK4); after release, none.
//!
//! The system (second-order form, `q` over the strings' T, L, P modes and the board's modes):
//! ```text
//! qdd = -K q - C qdot + sum_i b_i F_e,i            (Eq. 10 with the contact forces folded in)
//! K = diag(omega^2) + sum_{i,d} k_d w_id w_id^T,   C = diag(2 zeta omega) + C_d + sum c_d w_id w_id^T
//! w_id = (psi(L_s) on string i's modes in direction d, -phi_d on the board's modes)   (Eq. 6, 17)
//! m_H ydd_H = -sum_i F_e,i,   F_e,i = K_H max(y_H - y_e,i, 0)^p                       (Eq. 8-9)
//! ```
//! The board copy is this key's: the coupling between keys through the shared board, and the
//! dampers, come with the pool (issue 16, step 2).

use crate::engine::kernels::has_avx2_fma;
use crate::engine::modal::Modal;
use crate::engine::physics::duplex::duplex_damping_matrix;
use crate::engine::physics::hammer::HammerParams;
use crate::engine::spec::{BuildError, Direction, Observation, Strike, UnisonSpec, MAX_STRINGS};
use faer::c64;
use std::ops::Range;

/// A complex vector per mode, real and imaginary parts apart (the kernels' layout).
#[derive(Debug, Clone, Default)]
struct Split {
    re: Vec<f64>,
    im: Vec<f64>,
}

impl Split {
    fn new(v: &[c64]) -> Split {
        Split {
            re: v.iter().map(|x| x.re).collect(),
            im: v.iter().map(|x| x.im).collect(),
        }
    }

    fn zeros(n: usize) -> Split {
        Split {
            re: vec![0.0; n],
            im: vec![0.0; n],
        }
    }

    fn times(a: &[c64], b: &[c64]) -> Split {
        let p: Vec<c64> = a.iter().zip(b).map(|(x, y)| x * y).collect();
        Split::new(&p)
    }

    /// `Re(r z)` of a row `r` (self) and a state `z`.
    fn read(&self, z: &Split) -> f64 {
        let mut acc = 0.0;
        for m in 0..self.re.len() {
            acc += self.re[m] * z.re[m] - self.im[m] * z.im[m];
        }
        acc
    }
}

/// Where each string direction's modes and the board's lie in `q`.
#[derive(Debug, Clone)]
struct Layout {
    strings: [[Range<usize>; 3]; MAX_STRINGS],
    board: Range<usize>,
    n: usize,
}

impl Layout {
    fn new(spec: &UnisonSpec) -> Layout {
        let mut strings: [[Range<usize>; 3]; MAX_STRINGS] = Default::default();
        let mut at = 0;
        for ranges in strings.iter_mut().take(spec.strings.len()) {
            for dir in Direction::ALL {
                let n = spec.modes.count(dir);
                ranges[dir.index()] = at..at + n;
                at += n;
            }
        }
        let board = at..at + spec.board.len();
        Layout {
            strings,
            board: board.clone(),
            n: board.end,
        }
    }
}

/// One key's second-order system `qdd = -K q - C qdot + ...` (dense, row-major), contact
/// springs, duplex damping and the board at its point folded in.
fn coupled_system(spec: &UnisonSpec, layout: &Layout) -> Result<(Vec<f64>, Vec<f64>), BuildError> {
    let n = layout.n;
    let (mut k, mut c) = (vec![0.0; n * n], vec![0.0; n * n]);
    let point = spec
        .board
        .points
        .get(spec.bridge_point)
        .ok_or(BuildError::BridgePoint(spec.bridge_point))?;
    let nd = spec.modes.modes_t.max(spec.modes.modes_p);
    for (s, string) in spec.strings.iter().enumerate() {
        let ls = string.speaking_length_m;
        for dir in Direction::ALL {
            for (j, i) in layout.strings[s][dir.index()].clone().enumerate() {
                let mode = string.oscillator(dir, j + 1, &spec.modes);
                k[i * n + i] += mode.omega2();
                c[i * n + i] += mode.damping_per_s();
            }
        }
        // The duplex felt on both transverse polarisations (Eq. 13).
        let cd = duplex_damping_matrix(
            nd,
            string.length_m(),
            ls,
            spec.duplex_damping_n_s_m2,
            string.linear_density_kg_m,
        );
        for dir in [Direction::T, Direction::P] {
            let r = layout.strings[s][dir.index()].clone();
            for (p, i) in r.clone().enumerate() {
                for (q, j) in r.clone().enumerate() {
                    c[i * n + j] += cd[p * nd + q];
                }
            }
        }
        // Contact springs and dampers against the board (Eq. 6): K += k w w^T, C += c w w^T.
        for dir in Direction::ALL {
            let d = dir.index();
            let mut w: Vec<(usize, f64)> = layout.strings[s][d]
                .clone()
                .enumerate()
                .map(|(j, i)| (i, string.mode_shape(j + 1, ls)))
                .collect();
            w.extend(
                layout
                    .board
                    .clone()
                    .enumerate()
                    .map(|(m, i)| (i, -point.shape[d][m])),
            );
            let (kc, cc) = (spec.contact.stiffness_n_m[d], spec.contact.damping_n_s_m[d]);
            for &(i, wi) in &w {
                for &(j, wj) in &w {
                    k[i * n + j] += kc * wi * wj;
                    c[i * n + j] += cc * wi * wj;
                }
            }
        }
    }
    for (m, i) in layout.board.clone().enumerate() {
        let mode = spec.board.oscillator(m);
        k[i * n + i] += mode.omega2();
        c[i * n + i] += mode.damping_per_s();
    }
    Ok((k, c))
}

/// One unison on its own copy of the board, integrated exactly in the complex modes of the
/// coupled system (module notes); the hammer staged with ETDRK4 while it touches.
#[derive(Debug, Clone)]
pub struct ExactUnison {
    n_strings: usize,
    h: f64,
    /// Every mode's eigenvalue `lambda` (1/s), one of each conjugate pair.
    lambda: Vec<c64>,
    /// `e^{lambda h/2}`, `e^{lambda h}`.
    eh: Split,
    ef: Split,
    /// Per string: the striking point's displacement row, and the felt force's input through
    /// ETDRK4's `Q`, `f1`, `f2`, `f3` (Eq. 14-15 in modal coordinates).
    strike_row: Vec<Split>,
    drive_q: Vec<Split>,
    drive_f: Vec<[Split; 3]>,
    /// Per string and direction, the contact force's row (Eq. 6); per direction, the board's
    /// velocity at the bridge point; the board's net volume velocity.
    force_row: Vec<[Split; 3]>,
    bridge_velocity_row: [Split; 3],
    volume_velocity_row: Split,
    hammer: HammerParams,
    /// The state: modal amplitudes, the hammer, which strings it strikes.
    z: Split,
    hammer_y: f64,
    hammer_v: f64,
    hammer_on: bool,
    struck: [bool; MAX_STRINGS],
    /// ETDRK4 stage states, sized once.
    za: Split,
    zb: Split,
    zc: Split,
    /// Whether the CPU has AVX2 + FMA (the mode loops then use them).
    fast_path: bool,
}

impl ExactUnison {
    /// Diagonalise `spec`'s key (strings, contact, duplex, the board at its point) for the step
    /// `1 / spec.sample_rate_hz`.
    pub fn new(spec: &UnisonSpec) -> Result<ExactUnison, BuildError> {
        let ns = spec.strings.len();
        if ns == 0 || ns > MAX_STRINGS {
            return Err(BuildError::StringCount(ns));
        }
        let h = 1.0 / spec.sample_rate_hz;
        let layout = Layout::new(spec);
        let n = layout.n;
        let (k, c) = coupled_system(spec, &layout)?;
        let modal = Modal::new(&k, &c, n, h)?;
        let point = &spec.board.points[spec.bridge_point];
        let on = |entries: &mut dyn Iterator<Item = (usize, f64)>| -> Vec<f64> {
            let mut v = vec![0.0; n];
            for (i, x) in entries {
                v[i] = x;
            }
            v
        };
        let s0 = &spec.strings[0];
        let strike_x = spec.hammer.strike_ratio * s0.speaking_length_m;
        let mut strike_row = Vec::new();
        let mut drive_q = Vec::new();
        let mut drive_f = Vec::new();
        let mut force_row = Vec::new();
        for (s, string) in spec.strings.iter().enumerate() {
            let t = layout.strings[s][Direction::T.index()].clone();
            let psi_e = on(&mut t
                .enumerate()
                .map(|(j, i)| (i, string.mode_shape(j + 1, strike_x))));
            strike_row.push(Split::new(&modal.row(&psi_e, false)));
            let g = modal.input(&psi_e);
            drive_q.push(Split::times(&g, &modal.etd[0]));
            drive_f.push(std::array::from_fn(|w| Split::times(&g, &modal.etd[2 + w])));
            force_row.push(std::array::from_fn(|d| {
                let w = on(&mut layout.strings[s][d]
                    .clone()
                    .enumerate()
                    .map(|(j, i)| (i, string.mode_shape(j + 1, string.speaking_length_m)))
                    .chain(
                        layout
                            .board
                            .clone()
                            .enumerate()
                            .map(|(m, i)| (i, -point.shape[d][m])),
                    ));
                let (kc, cc) = (spec.contact.stiffness_n_m[d], spec.contact.damping_n_s_m[d]);
                let row: Vec<c64> = modal
                    .row(&w, false)
                    .iter()
                    .zip(modal.row(&w, true))
                    .map(|(q, v)| q * kc + v * cc)
                    .collect();
                Split::new(&row)
            }));
        }
        let board_row = |x: &[f64]| -> Split {
            let v = on(&mut layout.board.clone().enumerate().map(|(m, i)| (i, x[m])));
            Split::new(&modal.row(&v, true))
        };
        let kept = modal.keep.len();
        let lambda = modal.lambda.clone();
        Ok(ExactUnison {
            n_strings: ns,
            h,
            lambda,
            eh: Split::new(&modal.eh),
            ef: Split::new(&modal.ef),
            strike_row,
            drive_q,
            drive_f,
            force_row,
            bridge_velocity_row: std::array::from_fn(|d| board_row(&point.shape[d])),
            volume_velocity_row: board_row(&spec.board.volume_m2_per_sqrt_kg),
            hammer: spec.hammer,
            z: Split::zeros(kept),
            hammer_y: 0.0,
            hammer_v: 0.0,
            hammer_on: false,
            struck: [false; MAX_STRINGS],
            za: Split::zeros(kept),
            zb: Split::zeros(kept),
            zc: Split::zeros(kept),
            fast_path: has_avx2_fma(),
        })
    }

    /// Complex modes kept (one of each conjugate pair, and each real mode).
    pub fn n_modes(&self) -> usize {
        self.z.re.len()
    }

    /// Every kept mode's eigenvalue `lambda` (1/s): `-sigma + i omega`.
    pub fn eigenvalues(&self) -> &[c64] {
        &self.lambda
    }

    pub fn step_s(&self) -> f64 {
        self.h
    }

    /// Whether the hammer is still part of the system.
    pub fn hammer_engaged(&self) -> bool {
        self.hammer_on
    }

    /// Launch the hammer in contact with the struck strings' current displacement, moving at the
    /// strike's speed (as the other engines do).
    pub fn strike(&mut self, strike: Strike) {
        let n_struck = strike.strings_struck(self.n_strings);
        let mut contact = f64::NEG_INFINITY;
        for s in 0..self.n_strings {
            self.struck[s] = s < n_struck;
            if self.struck[s] {
                contact = contact.max(self.strike_row[s].read(&self.z));
            }
        }
        self.hammer_y = contact;
        self.hammer_v = strike.velocity_m_s;
        self.hammer_on = true;
    }

    /// The felt force on each string (Eq. 8) with the hammer at `y` and the modes at `z`.
    fn felt(&self, z: &Split, y: f64) -> [f64; MAX_STRINGS] {
        std::array::from_fn(|s| {
            if s < self.n_strings && self.struck[s] {
                self.hammer.felt_force_n(y - self.strike_row[s].read(z))
            } else {
                0.0
            }
        })
    }

    /// Advance one step: exactly while the hammer is away, by ETDRK4 while it touches.
    pub fn step(&mut self) {
        if self.hammer_on {
            self.contact_step();
            let points = (0..self.n_strings)
                .filter(|&s| self.struck[s])
                .map(|s| self.strike_row[s].read(&self.z));
            if self.hammer.is_clear(self.hammer_y, self.hammer_v, points) {
                self.hammer_on = false;
            }
        } else {
            propagate(&self.ef, &mut self.z);
        }
    }

    /// Advance `volume_velocity.len()` steps, writing the board's net volume velocity (m^3/s)
    /// after each; once the hammer is released, each step and its read are one pass over the
    /// modes ([`propagate_read`]).
    pub fn run(&mut self, volume_velocity: &mut [f64]) {
        for out in volume_velocity {
            *out = if self.hammer_on {
                self.step();
                self.volume_velocity_m3_s()
            } else {
                propagate_read(
                    &self.ef,
                    &mut self.z,
                    &self.volume_velocity_row,
                    self.fast_path,
                )
            };
        }
    }

    /// ETDRK4 (Cox & Matthews): `a = E_2 u + Q N(u)`, `b = E_2 u + Q N(a)`,
    /// `c = E_2 a + Q (2 N(b) - N(u))`, `u' = E u + f1 N(u) + f2 (N(a) + N(b)) + f3 N(c)`, the
    /// felt force `N` entering the modes through each struck string's input, and the hammer's
    /// own linear part zero (its stages are classical RK4).
    fn contact_step(&mut self) {
        let (h, m_h) = (self.h, self.hammer.mass_kg);
        let (y, v) = (self.hammer_y, self.hammer_v);
        let accel = |f: &[f64; MAX_STRINGS]| -> f64 { -f.iter().sum::<f64>() / m_h };
        // Stage a.
        let fu = self.felt(&self.z, y);
        stage(&mut self.za, &self.eh, &self.z, &self.drive_q, &fu);
        let (ya, va) = (y + 0.5 * h * v, v + 0.5 * h * accel(&fu));
        // Stage b.
        let fa = self.felt(&self.za, ya);
        stage(&mut self.zb, &self.eh, &self.z, &self.drive_q, &fa);
        let (yb, vb) = (y + 0.5 * h * va, v + 0.5 * h * accel(&fa));
        // Stage c.
        let fb = self.felt(&self.zb, yb);
        let mixed: [f64; MAX_STRINGS] = std::array::from_fn(|s| 2.0 * fb[s] - fu[s]);
        stage(&mut self.zc, &self.eh, &self.za, &self.drive_q, &mixed);
        let (yc, vc) = (
            ya + 0.5 * h * (2.0 * vb - v),
            va + 0.5 * h * (2.0 * accel(&fb) - accel(&fu)),
        );
        let fc = self.felt(&self.zc, yc);
        // The step.
        propagate(&self.ef, &mut self.z);
        let z = &mut self.z;
        for s in (0..self.n_strings).filter(|&s| self.struck[s]) {
            let [g1, g2, g3] = &self.drive_f[s];
            let (u1, u2, u3) = (fu[s], fa[s] + fb[s], fc[s]);
            for m in 0..z.re.len() {
                z.re[m] += g1.re[m] * u1 + g2.re[m] * u2 + g3.re[m] * u3;
                z.im[m] += g1.im[m] * u1 + g2.im[m] * u2 + g3.im[m] * u3;
            }
        }
        self.hammer_y = y + h / 6.0 * v + h / 3.0 * (va + vb) + h / 6.0 * vc;
        self.hammer_v =
            v + h / 6.0 * accel(&fu) + h / 3.0 * (accel(&fa) + accel(&fb)) + h / 6.0 * accel(&fc);
    }

    /// Floating-point operations of one step and of reading the volume velocity after it: 6 per
    /// complex mode to propagate and 4 to read, once the hammer is released; with the hammer,
    /// ETDRK4's four reads of each struck string's point (4 each), three stage states (6 each,
    /// and 2 per struck string) and the final drive (6 per struck string).
    pub fn flops_per_step(&self) -> f64 {
        let m = self.n_modes() as f64;
        let free = 10.0 * m;
        if !self.hammer_on {
            return free;
        }
        let struck = self.struck.iter().filter(|&&s| s).count() as f64;
        free + m * (4.0 * 4.0 * struck + 3.0 * (6.0 + 2.0 * struck) + 6.0 * struck)
    }

    /// Net volume velocity of the board (m^3/s).
    pub fn volume_velocity_m3_s(&self) -> f64 {
        self.volume_velocity_row.read(&self.z)
    }

    /// Forces and volume velocity now (Eq. 19).
    pub fn observe(&self) -> Observation {
        let mut obs = Observation {
            volume_velocity_m3_s: self.volume_velocity_m3_s(),
            ..Observation::default()
        };
        for d in 0..3 {
            obs.bridge_velocity_m_s[d] = self.bridge_velocity_row[d].read(&self.z);
        }
        for s in 0..self.n_strings {
            for d in 0..3 {
                let f = self.force_row[s][d].read(&self.z);
                obs.bridge_force_n[s][d] = f;
                obs.total_force_n[d] += f;
            }
        }
        if self.hammer_on {
            obs.hammer_force_n = self.felt(&self.z, self.hammer_y);
        }
        obs
    }
}

/// Lanes of the mode loops' partial sums (so that they vectorise: a single sum would be a serial
/// chain).
const LANES: usize = 8;

/// `z <- e ⊙ z`, then `Re(r z)`, in one pass: 6 FLOP per mode to propagate, 4 to read; with
/// AVX2 + FMA where the CPU has them.
fn propagate_read(e: &Split, z: &mut Split, r: &Split, fast: bool) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if fast {
        // SAFETY: `fast` is set only where `has_avx2_fma()` found AVX2 and FMA.
        return unsafe { propagate_read_avx2(e, z, r) };
    }
    let _ = fast;
    propagate_read_with::<false>(e, z, r)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn propagate_read_avx2(e: &Split, z: &mut Split, r: &Split) -> f64 {
    propagate_read_with::<true>(e, z, r)
}

/// `a b + c`, fused with `FMA`.
#[inline(always)]
fn fma<const FMA: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

#[inline(always)]
fn propagate_read_with<const FMA: bool>(e: &Split, z: &mut Split, r: &Split) -> f64 {
    let n = z.re.len();
    let (er, ei, rr, ri) = (&e.re[..n], &e.im[..n], &r.re[..n], &r.im[..n]);
    let (zr, zi) = (&mut z.re[..n], &mut z.im[..n]);
    let mut acc = [0.0; LANES];
    let mut tail = 0.0;
    let whole = n / LANES * LANES;
    for base in (0..whole).step_by(LANES) {
        for l in 0..LANES {
            let m = base + l;
            let (a, b) = (zr[m], zi[m]);
            let (re, im) = (
                fma::<FMA>(er[m], a, -ei[m] * b),
                fma::<FMA>(er[m], b, ei[m] * a),
            );
            zr[m] = re;
            zi[m] = im;
            acc[l] = fma::<FMA>(rr[m], re, fma::<FMA>(-ri[m], im, acc[l]));
        }
    }
    for m in whole..n {
        let (a, b) = (zr[m], zi[m]);
        let (re, im) = (er[m] * a - ei[m] * b, er[m] * b + ei[m] * a);
        zr[m] = re;
        zi[m] = im;
        tail += rr[m] * re - ri[m] * im;
    }
    acc.iter().sum::<f64>() + tail
}

/// `z <- e ⊙ z` (complex, per mode).
fn propagate(e: &Split, z: &mut Split) {
    for m in 0..z.re.len() {
        let (a, b) = (z.re[m], z.im[m]);
        z.re[m] = e.re[m] * a - e.im[m] * b;
        z.im[m] = e.re[m] * b + e.im[m] * a;
    }
}

/// `out = e2 ⊙ from + sum_s q_s u_s` over the struck strings' inputs (zero forces add nothing).
fn stage(out: &mut Split, e2: &Split, from: &Split, q: &[Split], u: &[f64; MAX_STRINGS]) {
    for m in 0..out.re.len() {
        let (a, b) = (from.re[m], from.im[m]);
        out.re[m] = e2.re[m] * a - e2.im[m] * b;
        out.im[m] = e2.re[m] * b + e2.im[m] * a;
    }
    for (s, q) in q.iter().enumerate() {
        if u[s] != 0.0 {
            for m in 0..out.re.len() {
                out.re[m] += q.re[m] * u[s];
                out.im[m] += q.im[m] * u[s];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::preset::Preset;

    /// c2 cut down to a few modes (so that five decompositions take no time), at `rate_hz`.
    fn small_c2(rate_hz: f64) -> UnisonSpec {
        let mut spec = Preset::resolve("c2").unwrap().unison_spec();
        spec.modes.modes_t = 24;
        spec.modes.modes_p = 24;
        spec.modes.modes_l = 2;
        let keep = 24;
        let b = &mut spec.board;
        b.freq_hz.truncate(keep);
        b.damping_ratio.truncate(keep);
        b.volume_m2_per_sqrt_kg.truncate(keep);
        for p in &mut b.points {
            p.shape.iter_mut().for_each(|s| s.truncate(keep));
        }
        spec.sample_rate_hz = rate_hz;
        spec
    }

    /// The hammer's position 0.5 ms into its contact (it lasts ~2 ms), struck at 2.5 m/s.
    fn hammer_at(rate_hz: f64) -> f64 {
        let mut u = ExactUnison::new(&small_c2(rate_hz)).unwrap();
        u.strike(Strike {
            velocity_m_s: 2.5,
            una_corda: false,
        });
        for _ in 0..(0.5e-3 * rate_hz).round() as usize {
            u.step();
        }
        assert!(u.hammer_engaged());
        u.hammer_y
    }

    #[test]
    fn the_fused_step_agrees_with_the_portable_one() {
        // 2 s of c2's tail (hammer released) through the AVX2 + FMA pass and the portable one.
        let mut spec = Preset::resolve("c2").unwrap().unison_spec();
        spec.sample_rate_hz = 48_000.0;
        let mut fast = ExactUnison::new(&spec).unwrap();
        fast.strike(Strike {
            velocity_m_s: 2.5,
            una_corda: false,
        });
        let mut warm = [0.0; 480];
        fast.run(&mut warm);
        assert!(!fast.hammer_engaged());
        let mut slow = fast.clone();
        slow.fast_path = false;
        let (mut a, mut b) = (vec![0.0; 96_000], vec![0.0; 96_000]);
        fast.run(&mut a);
        slow.run(&mut b);
        let peak = b.iter().fold(0f64, |m, x| m.max(x.abs()));
        let worst = a
            .iter()
            .zip(&b)
            .fold(0f64, |m, (x, y)| m.max((x - y).abs()))
            / peak;
        println!(
            "fused step, AVX2 + FMA (used: {}) vs portable: {worst:.1e} of the peak over 2 s",
            has_avx2_fma()
        );
        assert!(worst < 1e-12, "{worst:e}");
    }

    #[test]
    fn the_contact_step_converges_with_order_four() {
        // ETDRK4 is fourth order for a smooth nonlinear term; the felt's xi^p (p = 2.3) starts
        // from zero, which is smooth enough here. Errors against 1536 kHz at 48, 96, 192 kHz.
        let reference = hammer_at(1_536_000.0);
        let errors: Vec<f64> = [48_000.0, 96_000.0, 192_000.0]
            .iter()
            .map(|&r| (hammer_at(r) - reference).abs())
            .collect();
        let orders: Vec<f64> = errors.windows(2).map(|e| (e[0] / e[1]).log2()).collect();
        println!(
            "hammer position errors {:.1e} {:.1e} {:.1e} m, observed orders {orders:.2?}",
            errors[0], errors[1], errors[2]
        );
        assert!(orders.iter().all(|&p| p > 3.3), "{orders:?}");
    }
}
