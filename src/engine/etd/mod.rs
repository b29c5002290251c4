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
//! reference ([`crate::engine::Instrument`]); `tests/integrators.rs` compares.
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

use crate::engine::kernels::{has_avx2_fma, Real, LANES};
use crate::engine::physics::duplex::duplex_damping_matrix;
use crate::engine::physics::hammer::HammerParams;
use crate::engine::pool::{fade_step, hammer_clear, Policy, VoiceState};
use crate::engine::spec::{BuildError, Observation, Strike, UnisonSpec, MAX_STRINGS, STEAL_FADE_S};
use crate::engine::Pair;
use faer::linalg::solvers::{PartialPivLu, Solve};
use faer::{c64, Mat};
use std::f64::consts::PI;
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// A block `x' = A x + B u` in its complex modes: eigen-decomposition and ETDRK4 weights.
///
/// Of each complex-conjugate pair of modes only one is stored (its partner is its conjugate: the
/// block is real), with weight 2 folded into the output rows; real (overdamped) modes have weight 1.
struct Modal {
    n: usize,
    /// Kept eigenpairs `(column, weight)`.
    keep: Vec<(usize, f64)>,
    u: Mat<c64>,
    lu: PartialPivLu<c64>,
    /// Per kept mode: `e^{lambda h/2}`, `e^{lambda h}`, `Q`, `(E - 1) Q`, `f1`, `f2`, `f3`.
    eh: Vec<c64>,
    ef: Vec<c64>,
    etd: [Vec<c64>; 5],
    padded: usize,
}

impl Modal {
    /// Diagonalise `qdd = -K q - C qdot + ...` (dense `n × n`, row-major) for step `h`.
    fn new(k: &[f64], c: &[f64], n: usize, h: f64) -> Result<Modal, BuildError> {
        let a = Mat::<f64>::from_fn(2 * n, 2 * n, |i, j| match (i < n, j < n) {
            (true, true) => 0.0,
            (true, false) => f64::from(u8::from(j - n == i)),
            (false, true) => -k[(i - n) * n + j],
            (false, false) => -c[(i - n) * n + (j - n)],
        });
        let eig = a.eigen().map_err(|_| BuildError::Modes)?;
        let (u, s) = (eig.U().to_owned(), eig.S().column_vector().to_owned());
        // Representatives: Im > 0 of each pair (weight 2), real eigenvalues (weight 1).
        let scale = (0..2 * n).map(|i| s[i].norm()).fold(0.0, f64::max).max(1.0);
        let keep: Vec<(usize, f64)> = (0..2 * n)
            .filter_map(|i| {
                let im = s[i].im;
                if im > 1e-12 * scale {
                    Some((i, 2.0))
                } else if im.abs() <= 1e-12 * scale {
                    Some((i, 1.0))
                } else {
                    None
                }
            })
            .collect();
        let pairs = keep.iter().filter(|(_, w)| *w == 2.0).count();
        if 2 * pairs + (keep.len() - pairs) != 2 * n || !s.iter().all(|x| x.re.is_finite()) {
            return Err(BuildError::Modes);
        }
        let lam: Vec<c64> = keep.iter().map(|&(i, _)| s[i]).collect();
        let exp = |t: f64| -> Vec<c64> {
            lam.iter()
                .map(|&l| {
                    let m = (l.re * t).exp();
                    c64::new(m * (l.im * t).cos(), m * (l.im * t).sin())
                })
                .collect()
        };
        let weights: Vec<[c64; 5]> = lam.iter().map(|&l| etd_weights(l, h)).collect();
        let etd = std::array::from_fn(|k| weights.iter().map(|w| w[k]).collect());
        Ok(Modal {
            n,
            padded: keep.len().div_ceil(LANES) * LANES,
            lu: u.partial_piv_lu(),
            u,
            eh: exp(0.5 * h),
            ef: exp(h),
            etd,
            keep,
        })
    }

    /// The output row `r = c^T V` (weighted) reading `c^T q`, or `c^T qdot` if `velocity`.
    fn row(&self, c: &[f64], velocity: bool) -> Vec<c64> {
        let off = if velocity { self.n } else { 0 };
        self.keep
            .iter()
            .map(|&(m, w)| {
                let mut acc = c64::new(0.0, 0.0);
                for (i, &ci) in c.iter().enumerate() {
                    acc += self.u[(off + i, m)] * ci;
                }
                acc * w
            })
            .collect()
    }

    /// The input vector `g = V^-1 [0; b]` of a force distribution `b` on the accelerations.
    fn input(&self, b: &[f64]) -> Vec<c64> {
        let n = self.n;
        let rhs = Mat::<c64>::from_fn(2 * n, 1, |i, _| {
            c64::new(if i >= n { b[i - n] } else { 0.0 }, 0.0)
        });
        let g = self.lu.solve(&rhs);
        self.keep.iter().map(|&(m, _)| g[(m, 0)]).collect()
    }

    /// Real and imaginary parts, padded with zeros to whole SIMD lanes (a zero mode stays zero).
    fn split(&self, v: &[c64]) -> [Vec<f64>; 2] {
        let mut re: Vec<f64> = v.iter().map(|x| x.re).collect();
        let mut im: Vec<f64> = v.iter().map(|x| x.im).collect();
        re.resize(self.padded, 0.0);
        im.resize(self.padded, 0.0);
        [re, im]
    }

    fn times(a: &[c64], b: &[c64]) -> Vec<c64> {
        a.iter().zip(b).map(|(x, y)| x * y).collect()
    }

    /// A row through the three propagators the stages read: `r`, `r E`, `r E²`.
    fn rows3(&self, r: &[c64]) -> [[Vec<f64>; 2]; 3] {
        [
            self.split(r),
            self.split(&Self::times(r, &self.eh)),
            self.split(&Self::times(r, &self.ef)),
        ]
    }

    /// An input through the final weights: `f1 g`, `f2 g`, `f3 g`.
    fn gains3(&self, g: &[c64]) -> [[Vec<f64>; 2]; 3] {
        std::array::from_fn(|k| self.split(&Self::times(g, &self.etd[2 + k])))
    }

    /// What one unit of input `g` adds to the output `r` at the later stages: `[Re r Q g,
    /// Re r (E - 1) Q g]`.
    fn resp(&self, r: &[c64], g: &[c64]) -> [f64; 2] {
        let dot = |e: &[c64]| -> f64 { (0..r.len()).map(|m| (r[m] * e[m] * g[m]).re).sum() };
        [dot(&self.etd[0]), dot(&self.etd[1])]
    }

    /// Per stored mode, the mechanical energy per `|z|²` (J): the cycle-averaged
    /// `1/2 (qdot^T qdot + q^T K q)` of `w Re(v z)` for the mode's eigenvector `v`.
    fn energy(&self, k: &[f64]) -> Vec<f64> {
        let n = self.n;
        let mut e: Vec<f64> = self
            .keep
            .iter()
            .map(|&(m, w)| {
                let v = |i: usize| self.u[(i, m)];
                let kinetic: f64 = (0..n).map(|i| v(n + i).norm_sqr()).sum();
                let mut potential = 0.0;
                for i in 0..n {
                    let mut ki = c64::new(0.0, 0.0);
                    for j in 0..n {
                        ki += v(j) * k[i * n + j];
                    }
                    potential += (v(i).conj() * ki).re;
                }
                0.25 * w * w * (kinetic + potential)
            })
            .collect();
        e.resize(self.padded, 0.0);
        e
    }

    fn propagator(&self) -> [Vec<f64>; 2] {
        self.split(&self.ef)
    }
}

/// A string direction's coefficients with its ports, in the coordinates `q^ = q - g y` relative
/// to the string's static deflection `g y` by the bridge (see [`Statics`]): rows `psi.q^` at the
/// bridge, `psi(L_e).q^` at the strike point (T only), `psi.q^dot` at the bridge, `psi(x_d).q^dot`
/// at the damper (T and P); inputs ([`INPUTS`]) the bridge's velocity and acceleration, the felt
/// (T only), the damper felt and the fade of a stolen voice's contact, in that order.
#[derive(Debug, Clone)]
struct Block {
    /// Stored modes (the arrays below are padded to whole SIMD lanes beyond it with zeros).
    modes: usize,
    /// `e^{lambda h}`.
    e_full: [Vec<f64>; 2],
    /// Per output: the row `r`, `r E`, `r E²` (re, im), weights folded in.
    rows: Vec<[[Vec<f64>; 2]; 3]>,
    /// Per input: `f1 g`, `f2 g`, `f3 g` (re, im), the ETDRK4 weights of the final update.
    gains: Vec<[[Vec<f64>; 2]; 3]>,
    /// `resp[o][j]`: what one unit of input `j` adds to output `o` at the later stages.
    resp: Vec<Vec<[f64; 2]>>,
    /// Energy per `|z|²` of each stored mode (J).
    energy: Vec<f64>,
    /// The row `g.q^dot` (the energy's cross term between the deflection and the motion).
    g_row: [Vec<f64>; 2],
    statics: Statics,
}

/// A string direction's static deflection by its bridge point: when the bridge moves by `y`, the
/// string on its contact spring (stiffness `K = Omega^2 + k psi psi^T`) comes to rest at `g y`,
/// `K g = k psi` — at low frequencies its end follows the board almost entirely. The live
/// integrator advances `q^ = q - g y`, in which the contact spring's pull `k psi y` and the
/// string's return `K g y` cancel exactly, so that the board coupling left explicit is small: the
/// net stiffness `k (1 - psi.g) = k / (1 + k psi^T Omega^-2 psi)` (the contact spring in series
/// with the string, ~1/1000 of `k` at C2), the string's mass moving with the bridge (`-g y''`) and
/// the damping of that motion (`-C_0 g y'`, `C_0` the modal and duplex damping). In `q` itself the
/// board felt `k` per string explicitly, nearly cancelled by the string's response within the
/// step, and ETDRK4's error on those two large terms undamped the board's modes (README,
/// Robustness).
#[derive(Debug, Clone, Copy, Default)]
struct Statics {
    /// `psi.g` at the bridge, `psi(L_e).g` at the strike point, `psi(x_d).g` at the damper.
    bridge: f64,
    strike: f64,
    damper: f64,
    /// `g.g` (kg): the string's mass moving with the bridge.
    mass_kg: f64,
}

const BRIDGE_Q: usize = 0;
const STRIKE_Q: usize = 1;
const BRIDGE_V: usize = 2;
const DAMPER_V: usize = 3;

/// Inputs of a block (force distributions on `q^dd`, with their stage values): the bridge's
/// velocity `y'` through `c (1 - psi.g) psi - C_0 g` (the contact damper's net part and the
/// damping of the deflection's motion), its acceleration `-y''` through `g`, the felt (`psi(L_e)`,
/// T only), the damper felt (`psi(x_d)`), and while a stolen voice fades with coupling `c_f < 1`,
/// `(1 - c_f) (k (psi.q^ - (1 - psi.g) y) + c (psi.q^dot - (1 - psi.g) y'))` through `psi` (the
/// contact the linear part holds but the fade takes away).
const INPUTS: usize = 5;
const IN_VEL: usize = 0;
const IN_ACCEL: usize = 1;
const IN_FELT: usize = 2;
const IN_DAMPER: usize = 3;
const IN_FADE: usize = 4;

/// Complex-mode state of one block (re, im), sized for the largest key's block.
#[derive(Debug, Clone, Default)]
struct Modes {
    re: Vec<f64>,
    im: Vec<f64>,
}

impl Modes {
    fn zeros(n: usize) -> Modes {
        Modes {
            re: vec![0.0; n],
            im: vec![0.0; n],
        }
    }
    fn clear(&mut self) {
        self.re.fill(0.0);
        self.im.fill(0.0);
    }
}

/// `Re(r z)` through `row` over the first `row.len()` modes.
fn read(row: &[Vec<f64>; 2], z: &Modes) -> f64 {
    let n = row[0].len();
    (0..n)
        .map(|m| row[0][m] * z.re[m] - row[1][m] * z.im[m])
        .sum()
}

/// `R` outputs, each through its three rows `r`, `r E`, `r E²`, read in one pass over `z`.
#[inline(always)]
fn read_rows<const FMA: bool, const R: usize>(
    rows: [&[[Vec<f64>; 2]; 3]; R],
    z: &Modes,
) -> [[f64; 3]; R] {
    let n = rows[0][0][0].len();
    let (zr, zi) = (&z.re[..n], &z.im[..n]);
    #[cfg(target_arch = "x86_64")]
    if FMA {
        // SAFETY: `FMA` is true only inside `step_avx2`, entered after detecting AVX2 and FMA;
        // every row holds the block's `n` (a multiple of 4) modes and `z` at least as many.
        return unsafe { read_rows_avx2(zr, zi, rows) };
    }
    rows.map(|r| {
        r.each_ref()
            .map(|[re, im]| f64::dot::<FMA>(re, zr) - f64::dot::<FMA>(im, zi))
    })
}

/// `z <- e^{lambda h} z + sum_j (f1 g_j a_j + f2 g_j (b_j + c_j) + f3 g_j d_j)` for two inputs
/// `j` with stage values `u[j] = [a, b, c, d]`, in one pass.
#[inline(always)]
fn propagate_drive<const FMA: bool>(
    e: &[Vec<f64>; 2],
    gains: [&[[Vec<f64>; 2]; 3]; 2],
    u: [[f64; 4]; 2],
    z: &mut Modes,
) {
    let n = e[0].len();
    let (er, ei) = (&e[0][..n], &e[1][..n]);
    let g = gains.map(|g| g.each_ref().map(|[re, im]| [&re[..n], &im[..n]]));
    let s = u.map(|u| [u[0], u[1] + u[2], u[3]]);
    let (zr, zi) = (&mut z.re[..n], &mut z.im[..n]);
    for m in 0..n {
        let (a, b) = (zr[m], zi[m]);
        let mut re = fma::<FMA>(er[m], a, -ei[m] * b);
        let mut im = fma::<FMA>(er[m], b, ei[m] * a);
        for (g, s) in g.iter().zip(&s) {
            for k in 0..3 {
                re = fma::<FMA>(g[k][0][m], s[k], re);
                im = fma::<FMA>(g[k][1][m], s[k], im);
            }
        }
        zr[m] = re;
        zi[m] = im;
    }
}

/// `z += f1 g a + f2 g (b + c) + f3 g d` for one input with stage values `[a, b, c, d]`.
#[inline(always)]
fn drive<const FMA: bool>(gain: &[[Vec<f64>; 2]; 3], u: [f64; 4], z: &mut Modes) {
    let n = gain[0][0].len();
    let (zr, zi) = (&mut z.re[..n], &mut z.im[..n]);
    for (g, s) in gain.iter().zip([u[0], u[1] + u[2], u[3]]) {
        if s != 0.0 {
            let (gr, gi) = (&g[0][..n], &g[1][..n]);
            for m in 0..n {
                zr[m] = fma::<FMA>(gr[m], s, zr[m]);
                zi[m] = fma::<FMA>(gi[m], s, zi[m]);
            }
        }
    }
}

/// `sum |z|² e` over a block's modes (J).
fn energy_j(e: &[f64], z: &Modes) -> f64 {
    e.iter()
        .zip(z.re.iter().zip(&z.im))
        .map(|(e, (r, i))| e * (r * r + i * i))
        .sum()
}

/// The board in its own complex modes, known in closed form: each mode `qdd = -w² q - 2 zeta w
/// qdot + f` is `q = 2 Re z`, `qdot = 2 Re(lambda z)`, `z' = lambda z + f / (2 i Im lambda)`. The
/// board is read at each voice's point through its modal displacements and velocities (real,
/// formed once per stage for all voices) and driven by one modal force per stage, the sum over
/// voices of `Phi_b^T F` (Eq. 17) — so each voice costs a few dot products over the board's modes.
#[derive(Debug, Clone)]
struct Board {
    zr: Vec<f64>,
    zi: Vec<f64>,
    /// `lambda` and `e^{lambda h}`, `e^{lambda h/2}` (re, im).
    lam: [Vec<f64>; 2],
    ef: [Vec<f64>; 2],
    eh: [Vec<f64>; 2],
    /// What one unit of modal force at an earlier stage adds to `q` and `qdot` at a later one:
    /// `2 Re(k gamma)` and `2 Re(lambda k gamma)` for `k = Q` (kind 0) and `(E - 1) Q` (kind 1).
    cq: [Vec<f64>; 2],
    cv: [Vec<f64>; 2],
    /// `f1 gamma`, `f2 gamma`, `f3 gamma` (re, im): the final update per unit modal force.
    g: [[Vec<f64>; 2]; 3],
    omega2: Vec<f64>,
    /// `2 zeta omega` (1/s).
    damp: Vec<f64>,
    volume: Vec<f64>,
    /// Scratch: modal `q`, `qdot` through `1`, `E`, `E²` at the step's start; at the stage, and
    /// the modal acceleration there; the modal force of each stage.
    start: [[Vec<f64>; 2]; 3],
    stage: [Vec<f64>; 2],
    acc: Vec<f64>,
    /// This half's modal force of each stage, and both halves' together.
    force: [Vec<f64>; 4],
    total: [Vec<f64>; 4],
}

impl Board {
    fn new(board: &crate::engine::physics::soundboard::SoundboardModes, h: f64) -> Board {
        let n = board.len();
        let mut b = Board {
            zr: vec![0.0; n],
            zi: vec![0.0; n],
            lam: [vec![0.0; n], vec![0.0; n]],
            ef: [vec![0.0; n], vec![0.0; n]],
            eh: [vec![0.0; n], vec![0.0; n]],
            cq: [vec![0.0; n], vec![0.0; n]],
            cv: [vec![0.0; n], vec![0.0; n]],
            g: std::array::from_fn(|_| [vec![0.0; n], vec![0.0; n]]),
            omega2: vec![0.0; n],
            damp: vec![0.0; n],
            volume: board.volume_m2_per_sqrt_kg.clone(),
            start: std::array::from_fn(|_| [vec![0.0; n], vec![0.0; n]]),
            stage: [vec![0.0; n], vec![0.0; n]],
            acc: vec![0.0; n],
            force: std::array::from_fn(|_| vec![0.0; n]),
            total: std::array::from_fn(|_| vec![0.0; n]),
        };
        for i in 0..n {
            let w = 2.0 * PI * board.freq_hz[i];
            let zeta = board.damping_ratio[i];
            let lam = c64::new(-zeta * w, w * (1.0 - zeta * zeta).max(0.0).sqrt());
            let gamma = c64::new(1.0, 0.0) / c64::new(0.0, 2.0 * lam.im.max(f64::MIN_POSITIVE));
            let [q, eq, f1, f2, f3] = etd_weights(lam, h);
            let e = |t: f64| {
                let m = (lam.re * t).exp();
                c64::new(m * (lam.im * t).cos(), m * (lam.im * t).sin())
            };
            let set = |a: &mut [Vec<f64>; 2], x: c64| {
                a[0][i] = x.re;
                a[1][i] = x.im;
            };
            set(&mut b.lam, lam);
            set(&mut b.ef, e(h));
            set(&mut b.eh, e(0.5 * h));
            for (kind, k) in [q, eq].into_iter().enumerate() {
                b.cq[kind][i] = 2.0 * (k * gamma).re;
                b.cv[kind][i] = 2.0 * (lam * k * gamma).re;
            }
            for (g, f) in b.g.iter_mut().zip([f1, f2, f3]) {
                set(g, f * gamma);
            }
            b.omega2[i] = w * w;
            b.damp[i] = 2.0 * zeta * w;
        }
        b
    }

    /// The modal acceleration at the stage, once its total modal force is known (Eq. 4, 17).
    #[inline(always)]
    fn accel(&mut self, stage: usize) {
        let n = self.zr.len();
        let (q, v, f) = (
            &self.stage[0][..n],
            &self.stage[1][..n],
            &self.total[stage][..n],
        );
        let (w2, c, acc) = (&self.omega2[..n], &self.damp[..n], &mut self.acc[..n]);
        for i in 0..n {
            acc[i] = f[i] - w2[i] * q[i] - c[i] * v[i];
        }
    }

    /// Modal `q` and `qdot` of the state `e z`.
    fn modal(&self, e: Option<&[Vec<f64>; 2]>, i: usize) -> (f64, f64) {
        let (mut a, mut b) = (self.zr[i], self.zi[i]);
        if let Some(e) = e {
            (a, b) = (e[0][i] * a - e[1][i] * b, e[0][i] * b + e[1][i] * a);
        }
        (2.0 * a, 2.0 * (self.lam[0][i] * a - self.lam[1][i] * b))
    }

    /// Fill `start` with the modal displacements and velocities through `1`, `E`, `E²`.
    #[inline(always)]
    fn read_start(&mut self) {
        let n = self.zr.len();
        let (zr, zi) = (&self.zr[..n], &self.zi[..n]);
        let (lr, li) = (&self.lam[0][..n], &self.lam[1][..n]);
        for (which, e) in [None, Some(&self.eh), Some(&self.ef)]
            .into_iter()
            .enumerate()
        {
            let [q, v] = &mut self.start[which];
            let (q, v) = (&mut q[..n], &mut v[..n]);
            match e {
                None => {
                    for i in 0..n {
                        q[i] = 2.0 * zr[i];
                        v[i] = 2.0 * (lr[i] * zr[i] - li[i] * zi[i]);
                    }
                }
                Some([er, ei]) => {
                    let (er, ei) = (&er[..n], &ei[..n]);
                    for i in 0..n {
                        let a = er[i] * zr[i] - ei[i] * zi[i];
                        let b = er[i] * zi[i] + ei[i] * zr[i];
                        q[i] = 2.0 * a;
                        v[i] = 2.0 * (lr[i] * a - li[i] * b);
                    }
                }
            }
        }
    }

    /// Form the stage's modal `q`, `qdot`: row `which` of the start plus the responses to the
    /// modal forces of the earlier stages in `terms`.
    #[inline(always)]
    fn form_stage<const FMA: bool>(&mut self, which: usize, terms: &[(usize, usize, f64); 2]) {
        let n = self.zr.len();
        for x in 0..2 {
            let (c, dst) = (if x == 0 { &self.cq } else { &self.cv }, &mut self.stage[x]);
            dst.copy_from_slice(&self.start[which][x]);
            for &(p, kind, coef) in terms {
                if coef != 0.0 {
                    let (c, f) = (&c[kind][..n], &self.total[p][..n]);
                    for i in 0..n {
                        dst[i] = fma::<FMA>(coef * c[i], f[i], dst[i]);
                    }
                }
            }
        }
    }

    /// The stage's total modal force: this replica's own plus `other` (the other half's). One
    /// function for both ways of running the halves, so that they add alike bit for bit.
    #[inline(always)]
    fn sum_forces(&mut self, stage: usize, other: impl Iterator<Item = f64>) {
        for ((t, f), o) in self.total[stage]
            .iter_mut()
            .zip(&self.force[stage])
            .zip(other)
        {
            *t = f + o;
        }
    }

    /// The step's end: `z <- E² z + f1 gamma F0 + f2 gamma (F1 + F2) + f3 gamma F3`, and the
    /// modal forces cleared for the next step.
    #[inline(always)]
    fn advance<const FMA: bool>(&mut self) {
        let n = self.zr.len();
        let (zr, zi) = (&mut self.zr[..n], &mut self.zi[..n]);
        let (er, ei) = (&self.ef[0][..n], &self.ef[1][..n]);
        let [[g1r, g1i], [g2r, g2i], [g3r, g3i]] = &self.g;
        let [f0, f1, f2, f3] = &self.total;
        let (f0, f1, f2, f3) = (&f0[..n], &f1[..n], &f2[..n], &f3[..n]);
        for i in 0..n {
            let (a, b) = (zr[i], zi[i]);
            let mid = f1[i] + f2[i];
            let re = fma::<FMA>(er[i], a, -ei[i] * b);
            let im = fma::<FMA>(er[i], b, ei[i] * a);
            let re = fma::<FMA>(
                g1r[i],
                f0[i],
                fma::<FMA>(g2r[i], mid, fma::<FMA>(g3r[i], f3[i], re)),
            );
            let im = fma::<FMA>(
                g1i[i],
                f0[i],
                fma::<FMA>(g2i[i], mid, fma::<FMA>(g3i[i], f3[i], im)),
            );
            zr[i] = re;
            zi[i] = im;
        }
        self.force.iter_mut().for_each(|f| f.fill(0.0));
    }

    /// Net volume velocity (m^3/s).
    fn volume_velocity(&self) -> f64 {
        (0..self.zr.len())
            .map(|i| self.volume[i] * self.modal(None, i).1)
            .sum()
    }

    /// `(phi . q, phi . qdot)` at the current state.
    fn at(&self, phi: &[f64]) -> (f64, f64) {
        (0..self.zr.len())
            .map(|i| {
                let (q, v) = self.modal(None, i);
                (phi[i] * q, phi[i] * v)
            })
            .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1))
    }

    /// Mechanical energy (J).
    fn energy_j(&self) -> f64 {
        (0..self.zr.len())
            .map(|i| {
                let (q, v) = self.modal(None, i);
                0.5 * (v * v + self.omega2[i] * q * q)
            })
            .sum()
    }

    fn clear(&mut self) {
        self.zr.fill(0.0);
        self.zi.fill(0.0);
    }
}

/// One key's coefficients: its string directions in complex modes, and the board's mode shapes
/// at its bridge point.
#[derive(Debug, Clone)]
struct KeyModes {
    strings: Vec<[Block; 3]>,
    contact_k: [f64; 3],
    contact_c: [f64; 3],
    hammer: HammerParams,
    has_damper: bool,
    damper_n_s_m: f64,
    /// `phi_T`, `phi_L`, `phi_P` of the board at this key's point (Eq. 5).
    board_shape: [Vec<f64>; 3],
    /// Per block (zero where the key has no such string): contact stiffness and damping, the
    /// damper felt's damping (T and P of a damped key), the static deflection's values
    /// ([`Statics`]: `psi.g` at the bridge, strike point and damper), and `resp[o][j][kind]`, what
    /// one unit of input `j` adds to output `o` at the later stages (see [`ETDRK4_STAGES`]).
    lane_k: Lanes,
    lane_c: Lanes,
    lane_damper: Lanes,
    lane_through: Lanes,
    lane_strike: Lanes,
    lane_damper_g: Lanes,
    resp: [[[Lanes; 2]; INPUTS]; 4],
}

impl KeyModes {
    fn new(strings: Vec<[Block; 3]>, spec: &UnisonSpec, board_shape: &[Vec<f64>; 3]) -> KeyModes {
        let mut key = KeyModes {
            contact_k: spec.contact.stiffness_n_m,
            contact_c: spec.contact.damping_n_s_m,
            hammer: spec.hammer,
            has_damper: spec.damper.is_some(),
            damper_n_s_m: spec.damper.map_or(0.0, |d| d.damping_n_s_m),
            board_shape: board_shape.clone(),
            lane_k: [0.0; BLOCKS],
            lane_c: [0.0; BLOCKS],
            lane_damper: [0.0; BLOCKS],
            lane_through: [0.0; BLOCKS],
            lane_strike: [0.0; BLOCKS],
            lane_damper_g: [0.0; BLOCKS],
            resp: [[[[0.0; BLOCKS]; 2]; INPUTS]; 4],
            strings,
        };
        for (s, blocks) in key.strings.iter().enumerate() {
            for (d, block) in blocks.iter().enumerate() {
                let b = 3 * s + d;
                key.lane_k[b] = key.contact_k[d];
                key.lane_c[b] = key.contact_c[d];
                if d != 1 {
                    key.lane_damper[b] = key.damper_n_s_m;
                }
                key.lane_through[b] = block.statics.bridge;
                key.lane_strike[b] = block.statics.strike;
                key.lane_damper_g[b] = block.statics.damper;
                for (o, resp) in block.resp.iter().enumerate() {
                    for (j, r) in resp.iter().enumerate() {
                        key.resp[o][j][0][b] = r[0];
                        key.resp[o][j][1][b] = r[1];
                    }
                }
            }
        }
        key
    }
}

/// One key's string blocks, prepared ([`ExponentialInstrument::prepare_key`]) and waiting to be
/// placed on the board.
#[derive(Debug, Clone)]
pub struct PreparedKey(Vec<[Block; 3]>);

/// Build one key's string blocks (the board's rows and inputs are added by the instrument).
fn key_strings(spec: &UnisonSpec, h: f64) -> Result<Vec<[Block; 3]>, BuildError> {
    let ns = spec.strings.len();
    if ns == 0 || ns > MAX_STRINGS {
        return Err(BuildError::StringCount(ns));
    }
    let m = &spec.modes;
    let s0 = &spec.strings[0];
    let strike_x = spec.hammer.strike_ratio * s0.speaking_length_m;
    let damper_x = spec.damper.map(|d| d.position_ratio * s0.speaking_length_m);
    let mut strings = Vec::with_capacity(ns);
    for string in &spec.strings {
        let ls = string.speaking_length_m;
        let nd = m.modes_t.max(m.modes_p);
        let duplex = duplex_damping_matrix(
            nd,
            string.length_m(),
            ls,
            spec.duplex_damping_n_s_m2,
            string.linear_density_kg_m,
        );
        let mut blocks = Vec::with_capacity(3);
        // Directions T = 0, L = 1, P = 2.
        for (d, n, zeta, transverse) in [
            (0, m.modes_t, m.damping_ratio_t, true),
            (1, m.modes_l, m.damping_ratio_l, false),
            (2, m.modes_p, m.damping_ratio_p, true),
        ] {
            let omega = |k: usize| {
                if transverse {
                    string.transverse_omega(k + 1)
                } else {
                    string.longitudinal_omega(k + 1)
                }
            };
            let psi: Vec<f64> = (0..n).map(|k| string.mode_shape(k + 1, ls)).collect();
            let (kc, cc) = (spec.contact.stiffness_n_m[d], spec.contact.damping_n_s_m[d]);
            let mut kk = vec![0.0; n * n];
            let mut ck = vec![0.0; n * n];
            for i in 0..n {
                for j in 0..n {
                    kk[i * n + j] = kc * psi[i] * psi[j];
                    ck[i * n + j] =
                        cc * psi[i] * psi[j] + if transverse { duplex[i * nd + j] } else { 0.0 };
                }
                let w = omega(i);
                kk[i * n + i] += w * w;
                ck[i * n + i] += 2.0 * zeta * w;
            }
            // Uniform ports, zero where a direction has no hammer or no damper.
            let at = |x: Option<f64>| -> Vec<f64> {
                match x {
                    Some(x) => (0..n).map(|k| string.mode_shape(k + 1, x)).collect(),
                    None => vec![0.0; n],
                }
            };
            let hammer = at((d == 0).then_some(strike_x));
            let damper = at(damper_x.filter(|_| transverse));
            // The static deflection `K g = k psi` (Sherman–Morrison on `K = Omega^2 + k psi psi^T`)
            // and `C_0 g`, `C_0` the damping without the contact damper.
            let flex: Vec<f64> = (0..n).map(|i| psi[i] / omega(i).powi(2)).collect();
            let compliance: f64 = (0..n).map(|i| psi[i] * flex[i]).sum();
            let g: Vec<f64> = flex
                .iter()
                .map(|f| kc * f / (1.0 + kc * compliance))
                .collect();
            let dot = |a: &[f64], b: &[f64]| -> f64 { a.iter().zip(b).map(|(x, y)| x * y).sum() };
            let through = dot(&psi, &g);
            // `c (1 - psi.g) psi - C_0 g` = `c psi - C g` with `C` the whole damping.
            let vel: Vec<f64> = (0..n)
                .map(|i| cc * psi[i] - dot(&ck[i * n..(i + 1) * n], &g))
                .collect();
            let statics = Statics {
                bridge: through,
                strike: dot(&hammer, &g),
                damper: dot(&damper, &g),
                mass_kg: dot(&g, &g),
            };
            let modal = Modal::new(&kk, &ck, n, h)?;
            let rows = [
                modal.row(&psi, false),
                modal.row(&hammer, false),
                modal.row(&psi, true),
                modal.row(&damper, true),
            ];
            let inputs: [Vec<c64>; INPUTS] = [
                modal.input(&vel),
                modal.input(&g),
                modal.input(&hammer),
                modal.input(&damper),
                modal.input(&psi),
            ];
            blocks.push(Block {
                modes: modal.keep.len(),
                g_row: modal.split(&modal.row(&g, true)),
                statics,
                e_full: modal.propagator(),
                rows: rows.iter().map(|r| modal.rows3(r)).collect(),
                gains: inputs.iter().map(|g| modal.gains3(g)).collect(),
                resp: rows
                    .iter()
                    .map(|r| inputs.iter().map(|g| modal.resp(r, g)).collect())
                    .collect(),
                energy: modal.energy(&kk),
            });
        }
        let [t, l, p]: [Block; 3] = blocks.try_into().expect("three directions");
        strings.push([t, l, p]);
    }
    Ok(strings)
}

/// Blocks of one voice, `b = 3 s + d` for string `s` and direction `d` (T = 0, L = 1, P = 2): the
/// per-stage glue (outputs, contact forces, inputs) runs lane-wise over all of them at once.
const BLOCKS: usize = MAX_STRINGS * 3;
type Lanes = [f64; BLOCKS];

/// Per stage: the row read from the start state (0: `r`, 1: `r E`, 2: `r E²`) and the terms
/// `(earlier stage, response kind (0: `r Q g`, 1: `r (E - 1) Q g`), coefficient)` (see the
/// module's notes).
type StagePlan = (usize, [(usize, usize, f64); 2]);
const ETDRK4_STAGES: [StagePlan; 4] = [
    (0, [(0, 0, 0.0), (0, 0, 0.0)]),
    (1, [(0, 0, 1.0), (0, 0, 0.0)]),
    (1, [(1, 0, 1.0), (0, 0, 0.0)]),
    (2, [(0, 1, 1.0), (1, 0, 2.0)]),
];

/// One voice of the pool: the state of the key it plays.
#[derive(Debug, Clone)]
struct Voice {
    /// The policy's state (`engine::pool`), read and moved along by the step.
    state: VoiceState,
    z: [[Modes; 3]; MAX_STRINGS],
    hammer_y: f64,
    hammer_v: f64,
}

/// A voice's working values within one step (kept between steps only to avoid allocation).
#[derive(Debug, Clone, Copy, Default)]
struct Work {
    /// `start[o][which][b]`: output `o` of block `b` through row `which` (`r`, `r E`, `r E²`) of
    /// the step's starting modes.
    start: [[Lanes; 3]; 4],
    /// `u[p][j][b]`: input `j` ([`INPUTS`]) of block `b` at stage `p`.
    u: [[Lanes; INPUTS]; 4],
    hammer_acc: [f64; 4],
}

/// Half of the pool's voices (even or odd indices) with its working values and its own replica of
/// the board: what one core advances. Both replicas see the same forces in the same order, so they
/// stay identical bit for bit whether the halves run in turn on one core or at once on two.
#[derive(Debug, Clone)]
struct Half {
    set: VoiceSet,
    board: Board,
    steps: u64,
}

/// Voices with their working values, and which of them are simulated.
#[derive(Debug, Clone)]
struct VoiceSet {
    voices: Vec<Voice>,
    work: Vec<Work>,
    live: Vec<usize>,
}

/// What the two halves hand each other within a step: each half's modal force on the board at
/// each stage (f64 bits; relaxed stores and loads ordered by the meeting counters), and each half's
/// last finished phase (`4 step + stage + 1`). Lock-free: a half waits for the other by spinning
/// on its counter, never by blocking.
#[derive(Debug)]
struct Exchange {
    force: Vec<AtomicU64>,
    modes: usize,
    phase: [Padded; 2],
    abandoned: AtomicBool,
}

/// A counter on its own cache line (the two halves write theirs from different cores).
#[derive(Debug, Default)]
#[repr(align(128))]
struct Padded(AtomicU64);

impl Exchange {
    fn new(modes: usize) -> Exchange {
        Exchange {
            force: (0..2 * 4 * modes).map(|_| AtomicU64::new(0)).collect(),
            modes,
            phase: Default::default(),
            abandoned: AtomicBool::new(false),
        }
    }

    fn slot(&self, half: usize, stage: usize) -> &[AtomicU64] {
        let start = (half * 4 + stage) * self.modes;
        &self.force[start..start + self.modes]
    }

    /// Announce that `half` has finished `phase` and wait until the other half has too (or has
    /// been abandoned after a panic).
    fn meet(&self, half: usize, phase: u64) {
        self.phase[half].0.store(phase, Ordering::Release);
        while self.phase[1 - half].0.load(Ordering::Acquire) < phase {
            if self.abandoned.load(Ordering::Relaxed) {
                return;
            }
            std::hint::spin_loop();
        }
    }
}

impl Clone for Exchange {
    fn clone(&self) -> Exchange {
        Exchange::new(self.modes)
    }
}

/// Strings of up to 88 keys on one shared soundboard, advanced by ETDRK4 at the output rate: a
/// bank of keys and a fixed pool of voices with the same behaviour as [`crate::engine::Instrument`] (assign,
/// steal with a fade, strike in the current motion, dampers, silent voices retired, runaways reset).
/// Voices `k` live in half `k % 2`; [`ExponentialInstrument::run`] advances the halves on two
/// cores when given a [`Pair`], in turn on one otherwise, with the same result.
#[derive(Debug, Clone)]
pub struct ExponentialInstrument {
    keys: Vec<KeyModes>,
    halves: [Half; 2],
    exchange: Exchange,
    voice_of_key: Vec<Option<usize>>,
    n_voices: usize,
    h: f64,
    fade_steps: u32,
    fast_path: bool,
}

impl ExponentialInstrument {
    /// Several keys on one shared soundboard and a pool of `voices` voices, stepping at each
    /// spec's `sample_rate_hz` (the output rate).
    pub fn with_pool(
        specs: &[UnisonSpec],
        voices: usize,
    ) -> Result<ExponentialInstrument, BuildError> {
        let strings = specs
            .iter()
            .map(Self::prepare_key)
            .collect::<Result<_, _>>()?;
        Self::from_keys(specs, strings, voices)
    }

    /// One key's strings diagonalised and their propagators formed at `spec.sample_rate_hz`: the
    /// costly part of building, independent from key to key (a caller may prepare keys on
    /// several threads, then call [`ExponentialInstrument::from_keys`]).
    pub fn prepare_key(spec: &UnisonSpec) -> Result<PreparedKey, BuildError> {
        key_strings(spec, 1.0 / spec.sample_rate_hz).map(PreparedKey)
    }

    /// The pool of [`ExponentialInstrument::with_pool`] from keys already prepared, one per spec.
    pub fn from_keys(
        specs: &[UnisonSpec],
        strings: Vec<PreparedKey>,
        voices: usize,
    ) -> Result<ExponentialInstrument, BuildError> {
        let first = specs.first().ok_or(BuildError::NoVoice)?;
        if voices == 0 {
            return Err(BuildError::NoVoice);
        }
        if specs
            .iter()
            .any(|s| s.sample_rate_hz != first.sample_rate_hz || s.board != first.board)
        {
            return Err(BuildError::SharedBoard);
        }
        if strings.len() != specs.len() {
            return Err(BuildError::PreparedKeys {
                specs: specs.len(),
                keys: strings.len(),
            });
        }
        let h = 1.0 / first.sample_rate_hz;
        let board = &first.board;
        let mut keys = Vec::with_capacity(specs.len());
        for (spec, PreparedKey(strings)) in specs.iter().zip(strings) {
            let point = board
                .points
                .get(spec.bridge_point)
                .ok_or(BuildError::BridgePoint(spec.bridge_point))?;
            keys.push(KeyModes::new(strings, spec, &point.shape));
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
            z: std::array::from_fn(|_| std::array::from_fn(|d| Modes::zeros(cap[d]))),
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
        Ok(ExponentialInstrument {
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
                let (st, kc) = (&b.statics, km.contact_k[d]);
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
                    * (km.contact_k[d] * (read(&b.rows[BRIDGE_Q][0], z) - rest * rb[d][0])
                        + km.contact_c[d] * (read(&b.rows[BRIDGE_V][0], z) - rest * rb[d][1]));
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

    /// Set the state that [`ExponentialInstrument::linear_state`] reads, in the same layout.
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
                    let struck = d == 0 && v.state.hammer_on && v.state.struck[s];
                    let damped = d != 1 && v.state.damper_down;
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
impl Policy for ExponentialInstrument {
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
            .for_each(Modes::clear);
    }

    fn rest_strings(&mut self, k: usize) {
        self.voice_mut(k)
            .z
            .iter_mut()
            .flatten()
            .for_each(Modes::clear);
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

impl VoiceSet {
    /// Every row each live voice reads from the step's start.
    #[inline(always)]
    fn begin<const FMA: bool>(&mut self, keys: &[KeyModes]) {
        for &i in &self.live {
            let v = &self.voices[i];
            let km = &keys[v.state.key.expect("live voices have a key")];
            let w = &mut self.work[i];
            w.start = [[[0.0; BLOCKS]; 3]; 4];
            for (s, blocks) in km.strings.iter().enumerate() {
                for (d, b) in blocks.iter().enumerate() {
                    let (z, lane) = (&v.z[s][d], 3 * s + d);
                    let [q, qd] = read_rows::<FMA, 2>([&b.rows[BRIDGE_Q], &b.rows[BRIDGE_V]], z);
                    for which in 0..3 {
                        w.start[BRIDGE_Q][which][lane] = q[which];
                        w.start[BRIDGE_V][which][lane] = qd[which];
                    }
                    if d == 0 && v.state.hammer_on && v.state.struck[s] {
                        let [y] = read_rows::<FMA, 1>([&b.rows[STRIKE_Q]], z);
                        (0..3).for_each(|which| w.start[STRIKE_Q][which][lane] = y[which]);
                    }
                    if d != 1 && v.state.damper_down {
                        let [y] = read_rows::<FMA, 1>([&b.rows[DAMPER_V]], z);
                        (0..3).for_each(|which| w.start[DAMPER_V][which][lane] = y[which]);
                    }
                }
            }
        }
    }

    /// One ETDRK4 stage of these voices against the board's stage state `board` (modal `q`,
    /// `qdot`), adding their modal force on the board to `force`.
    #[inline(always)]
    fn stage<const FMA: bool>(
        &mut self,
        keys: &[KeyModes],
        stage: usize,
        &(which, terms): &StagePlan,
        h: f64,
        board: &[Vec<f64>; 2],
        force: &mut [f64],
    ) {
        for &i in &self.live {
            let v = &self.voices[i];
            let km = &keys[v.state.key.expect("live voices have a key")];
            let at = read_point::<FMA>(&km.board_shape, board);
            let f = voice_stage(km, v, &mut self.work[i], stage, which, &terms, at, h);
            drive_point::<FMA>(force, &km.board_shape, f);
        }
    }

    /// The stage's bridge accelerations of these voices, from the board's modal acceleration.
    #[inline(always)]
    fn accel<const FMA: bool>(&mut self, keys: &[KeyModes], stage: usize, acc: &[f64]) {
        for &i in &self.live {
            let km = &keys[self.voices[i].state.key.expect("live voices have a key")];
            voice_accel(
                &mut self.work[i],
                stage,
                read_accel::<FMA>(&km.board_shape, acc),
            );
        }
    }

    /// The step's end for these voices: hammers (classical RK4), strings, fades; `board` has
    /// already advanced.
    #[inline(always)]
    fn finish<const FMA: bool>(
        &mut self,
        keys: &[KeyModes],
        h: f64,
        fade_steps: u32,
        board: &Board,
    ) {
        for &i in &self.live {
            let v = &mut self.voices[i];
            let km = &keys[v.state.key.expect("live voices have a key")];
            let w = &self.work[i];
            let ah = w.hammer_acc;
            let felt = v.state.hammer_on;
            if felt {
                let v0 = v.hammer_v;
                let (v2, v3, v4) = (v0 + 0.5 * h * ah[0], v0 + 0.5 * h * ah[1], v0 + h * ah[2]);
                v.hammer_y += h / 6.0 * (v0 + 2.0 * v2 + 2.0 * v3 + v4);
                v.hammer_v += h / 6.0 * (ah[0] + 2.0 * ah[1] + 2.0 * ah[2] + ah[3]);
            }
            for (s, blocks) in km.strings.iter().enumerate() {
                for (d, b) in blocks.iter().enumerate() {
                    let (z, lane) = (&mut v.z[s][d], 3 * s + d);
                    let u = |j: usize| std::array::from_fn(|p| w.u[p][j][lane]);
                    let gains = [&b.gains[IN_VEL], &b.gains[IN_ACCEL]];
                    propagate_drive::<FMA>(&b.e_full, gains, [u(IN_VEL), u(IN_ACCEL)], z);
                    drive::<FMA>(&b.gains[IN_FADE], u(IN_FADE), z);
                    if felt && d == 0 {
                        drive::<FMA>(&b.gains[IN_FELT], u(IN_FELT), z);
                    }
                    if v.state.damper_down && d != 1 {
                        drive::<FMA>(&b.gains[IN_DAMPER], u(IN_DAMPER), z);
                    }
                }
            }
            // (The board's displacement is read only for a receding hammer.)
            if v.state.hammer_on && v.hammer_v < 0.0 {
                let y = board.at(&km.board_shape[0]).0;
                let (z, struck) = (&v.z, v.state.struck);
                let points = (0..km.strings.len())
                    .filter(|&s| struck[s])
                    .map(|s| strike_point(km, s, &z[s][0], y));
                if hammer_clear(v.hammer_y, v.hammer_v, km.hammer.release_gap_m, points) {
                    v.state.hammer_on = false;
                }
            }
        }
        // Stolen voices fade out along a raised cosine (their next key is given between chunks).
        for v in &mut self.voices {
            fade_step(&mut v.state, fade_steps);
        }
    }
}

impl Half {
    /// `steps` steps of this half, meeting the other half (on another core) after every stage;
    /// `out` (half 0) receives the board's volume velocity after each step.
    #[allow(clippy::too_many_arguments)]
    fn run_part(
        &mut self,
        keys: &[KeyModes],
        ex: &Exchange,
        half: usize,
        (h, fade, fast): (f64, u32, bool),
        steps: usize,
        mut out: Option<&mut [f64]>,
    ) {
        for n in 0..steps {
            #[cfg(target_arch = "x86_64")]
            if fast {
                // SAFETY: `fast` is the pool's `fast_path`, set only when the CPU reports AVX2
                // and FMA.
                unsafe { self.split_step_avx2(keys, ex, half, h, fade) };
            } else {
                self.split_step::<false>(keys, ex, half, h, fade);
            }
            #[cfg(not(target_arch = "x86_64"))]
            self.split_step::<false>(keys, ex, half, h, fade);
            if let Some(out) = out.as_deref_mut() {
                out[n] = self.board.volume_velocity();
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn split_step_avx2(
        &mut self,
        keys: &[KeyModes],
        ex: &Exchange,
        half: usize,
        h: f64,
        fade: u32,
    ) {
        self.split_step::<true>(keys, ex, half, h, fade);
    }

    #[inline(always)]
    fn split_step<const FMA: bool>(
        &mut self,
        keys: &[KeyModes],
        ex: &Exchange,
        half: usize,
        h: f64,
        fade: u32,
    ) {
        self.set.begin::<FMA>(keys);
        let b = &mut self.board;
        b.read_start();
        for (stage, plan) in ETDRK4_STAGES.iter().enumerate() {
            b.form_stage::<FMA>(plan.0, &plan.1);
            self.set
                .stage::<FMA>(keys, stage, plan, h, &b.stage, &mut b.force[stage]);
            // Publish this half's force, wait for the other's, and sum them (the same sum, in
            // either order, on both sides).
            for (slot, f) in ex.slot(half, stage).iter().zip(&b.force[stage]) {
                slot.store(f.to_bits(), Ordering::Relaxed);
            }
            ex.meet(half, 4 * self.steps + stage as u64 + 1);
            let other = ex.slot(1 - half, stage).iter();
            b.sum_forces(
                stage,
                other.map(|o| f64::from_bits(o.load(Ordering::Relaxed))),
            );
            b.accel(stage);
            self.set.accel::<FMA>(keys, stage, &b.acc);
        }
        b.advance::<FMA>();
        self.set.finish::<FMA>(keys, h, fade, &self.board);
        self.steps += 1;
    }
}

/// One stage of one voice, lane-wise over its blocks: each block's outputs (row `which` of the
/// start plus the responses to the earlier stages' inputs), the contact forces against the board
/// at the voice's point (`board`: `(y, y')` for T, L, P), the felt and damper forces. Stores the
/// stage's inputs in `w` (all but the bridge acceleration, [`voice_accel`]) and returns the force
/// on the board at the voice's point (T, L, P).
///
/// In the coordinates `q^ = q - g y` ([`Statics`]) the contact force is
/// `f = c_f (k (psi.q^ - (1 - psi.g) y) + c (psi.q^dot - (1 - psi.g) y'))` with the fade's
/// coupling `c_f` (see [`INPUTS`] for what the string receives).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn voice_stage(
    km: &KeyModes,
    v: &Voice,
    w: &mut Work,
    stage: usize,
    which: usize,
    terms: &[(usize, usize, f64); 2],
    board: [[f64; 2]; 3],
    h: f64,
) -> [f64; 3] {
    let (felt, damped, fading) = (
        v.state.hammer_on,
        v.state.damper_down,
        v.state.coupling != 1.0,
    );
    let out = |o: usize| {
        let mut y = w.start[o][which];
        for &(p, kind, coef) in terms {
            if coef == 0.0 {
                continue;
            }
            for j in 0..INPUTS {
                if (j == IN_FELT && !felt)
                    || (j == IN_DAMPER && !damped)
                    || (j == IN_FADE && !fading)
                {
                    continue;
                }
                let (r, u) = (&km.resp[o][j][kind], &w.u[p][j]);
                for b in 0..BLOCKS {
                    y[b] += coef * r[b] * u[b];
                }
            }
        }
        y
    };
    let (q, qd) = (out(BRIDGE_Q), out(BRIDGE_V));
    let (kc, cc, through) = (&km.lane_k, &km.lane_c, &km.lane_through);
    let mut fade = [0.0; BLOCKS];
    let mut force = [0.0; BLOCKS];
    let mut velocity = [0.0; BLOCKS];
    for b in 0..BLOCKS {
        let [by, bv] = board[b % 3];
        let rest = 1.0 - through[b];
        let f = kc[b] * (q[b] - rest * by) + cc[b] * (qd[b] - rest * bv);
        fade[b] = (1.0 - v.state.coupling) * f;
        force[b] = v.state.coupling * f;
        velocity[b] = bv;
    }
    let mut felt_u = [0.0; BLOCKS];
    let mut felt_total = 0.0;
    if felt {
        let y = hammer_stage_y(v, &w.hammer_acc, stage, h);
        let strike = out(STRIKE_Q);
        for s in (0..km.strings.len()).filter(|&s| v.state.struck[s]) {
            let b = 3 * s;
            let f = km
                .hammer
                .felt_force_n(y - strike[b] - km.lane_strike[b] * board[0][0]);
            felt_u[b] = f;
            felt_total += f;
        }
    }
    let mut damper_u = [0.0; BLOCKS];
    if damped {
        let dv = out(DAMPER_V);
        for b in 0..BLOCKS {
            damper_u[b] = -km.lane_damper[b] * (dv[b] + km.lane_damper_g[b] * board[b % 3][1]);
        }
    }
    w.u[stage][IN_VEL] = velocity;
    w.u[stage][IN_FELT] = felt_u;
    w.u[stage][IN_DAMPER] = damper_u;
    w.u[stage][IN_FADE] = fade;
    w.hammer_acc[stage] = -felt_total / km.hammer.mass_kg;
    std::array::from_fn(|d| (0..MAX_STRINGS).map(|s| force[3 * s + d]).sum())
}

/// The stage's bridge-acceleration input of one voice, `-y''` at its point in T, L, P (the board's
/// acceleration once every voice's force of the stage is known).
#[inline(always)]
fn voice_accel(w: &mut Work, stage: usize, accel: [f64; 3]) {
    w.u[stage][IN_ACCEL] = std::array::from_fn(|b| -accel[b % 3]);
}

/// The hammer's position at `stage` of classical RK4 (it has no linear part): `y0`,
/// `y0 + h/2 v0`, `y0 + h/2 v2`, `y0 + h v3` with `v2 = v0 + h/2 a1`, `v3 = v0 + h/2 a2`, from
/// the accelerations `acc` of the earlier stages.
fn hammer_stage_y(v: &Voice, acc: &[f64; 4], stage: usize, h: f64) -> f64 {
    let (y0, v0) = (v.hammer_y, v.hammer_v);
    match stage {
        0 => y0,
        1 => y0 + 0.5 * h * v0,
        2 => y0 + 0.5 * h * (v0 + 0.5 * h * acc[0]),
        _ => y0 + h * (v0 + 0.5 * h * acc[1]),
    }
}

/// The displacement of string `s` at the strike point: its motion `q^` plus its static deflection
/// by the board's displacement `y` (T) at the key's point.
fn strike_point(km: &KeyModes, s: usize, z: &Modes, y: f64) -> f64 {
    let b = &km.strings[s][0];
    read(&b.rows[STRIKE_Q][0], z) + b.statics.strike * y
}

/// The board's acceleration at one point, `phi_d . acc` for d = T, L, P.
#[inline(always)]
fn read_accel<const FMA: bool>(phi: &[Vec<f64>; 3], acc: &[f64]) -> [f64; 3] {
    std::array::from_fn(|d| f64::dot::<FMA>(&phi[d], acc))
}

/// One unison on its bridge point advanced by ETDRK4 (the pool with one key and one voice).
#[derive(Debug, Clone)]
pub struct ExponentialUnison(ExponentialInstrument);

impl ExponentialUnison {
    /// Diagonalise every string direction and the board for the step `1 / spec.sample_rate_hz`.
    pub fn new(spec: &UnisonSpec) -> Result<ExponentialUnison, BuildError> {
        let mut pool = ExponentialInstrument::with_pool(std::slice::from_ref(spec), 1)?;
        pool.assign(0, 0);
        pool.set_active(0, true);
        Ok(ExponentialUnison(pool))
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

/// [`read_rows`] with explicit AVX2 + FMA: `6 R` accumulators (re and im products of every
/// row) over `n` modes, `n` a multiple of 4 and every slice `n` long.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn read_rows_avx2<const R: usize>(
    zr: &[f64],
    zi: &[f64],
    rows: [&[[Vec<f64>; 2]; 3]; R],
) -> [[f64; 3]; R] {
    use std::arch::x86_64::*;
    let n = zr.len();
    debug_assert!(n % LANES == 0 && zi.len() == n);
    let mut ptr = [[[std::ptr::null::<f64>(); 2]; 3]; R];
    for r in 0..R {
        for which in 0..3 {
            for k in 0..2 {
                ptr[r][which][k] = rows[r][which][k][..n].as_ptr();
            }
        }
    }
    let mut acc = [[[_mm256_setzero_pd(); 2]; 3]; R];
    let mut i = 0;
    while i < n {
        let z = [
            _mm256_loadu_pd(zr.as_ptr().add(i)),
            _mm256_loadu_pd(zi.as_ptr().add(i)),
        ];
        for (acc, ptr) in acc.iter_mut().zip(&ptr) {
            for (acc, ptr) in acc.iter_mut().zip(ptr) {
                for k in 0..2 {
                    acc[k] = _mm256_fmadd_pd(_mm256_loadu_pd(ptr[k].add(i)), z[k], acc[k]);
                }
            }
        }
        i += LANES;
    }
    // Horizontal sums written out (closures here would not inherit the target features).
    let mut out = [[0.0; 3]; R];
    for r in 0..R {
        for which in 0..3 {
            let mut x = [[0.0; LANES]; 2];
            _mm256_storeu_pd(x[0].as_mut_ptr(), acc[r][which][0]);
            _mm256_storeu_pd(x[1].as_mut_ptr(), acc[r][which][1]);
            out[r][which] = ((x[0][0] + x[0][1]) + (x[0][2] + x[0][3]))
                - ((x[1][0] + x[1][1]) + (x[1][2] + x[1][3]));
        }
    }
    out
}

/// The board at one point: `(phi_d . q, phi_d . qdot)` for d = T, L, P, in one pass over the modal
/// displacements and velocities `qv` (six accumulators, SIMD lanes).
#[inline(always)]
fn read_point<const FMA: bool>(phi: &[Vec<f64>; 3], qv: &[Vec<f64>; 2]) -> [[f64; 2]; 3] {
    #[cfg(target_arch = "x86_64")]
    if FMA {
        // SAFETY: `FMA` is true only inside `step_avx2`, entered after detecting AVX2 and FMA.
        return unsafe { read_point_avx2(phi, qv) };
    }
    std::array::from_fn(|d| {
        [
            f64::dot::<FMA>(&phi[d], &qv[0]),
            f64::dot::<FMA>(&phi[d], &qv[1]),
        ]
    })
}

/// [`read_point`] with explicit AVX2 + FMA.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn read_point_avx2(phi: &[Vec<f64>; 3], qv: &[Vec<f64>; 2]) -> [[f64; 2]; 3] {
    use std::arch::x86_64::*;
    let n = qv[0]
        .len()
        .min(qv[1].len())
        .min(phi.iter().map(Vec::len).min().unwrap_or(0));
    let (q, v) = (qv[0].as_ptr(), qv[1].as_ptr());
    let p = [phi[0].as_ptr(), phi[1].as_ptr(), phi[2].as_ptr()];
    let mut acc = [_mm256_setzero_pd(); 6];
    let mut i = 0;
    while i + LANES <= n {
        let (x, y) = (_mm256_loadu_pd(q.add(i)), _mm256_loadu_pd(v.add(i)));
        for d in 0..3 {
            let f = _mm256_loadu_pd(p[d].add(i));
            acc[2 * d] = _mm256_fmadd_pd(f, x, acc[2 * d]);
            acc[2 * d + 1] = _mm256_fmadd_pd(f, y, acc[2 * d + 1]);
        }
        i += LANES;
    }
    let mut out = [[0.0; 2]; 3];
    for d in 0..3 {
        for k in 0..2 {
            let mut x = [0.0; LANES];
            _mm256_storeu_pd(x.as_mut_ptr(), acc[2 * d + k]);
            out[d][k] = (x[0] + x[1]) + (x[2] + x[3]);
        }
    }
    for j in i..n {
        for d in 0..3 {
            out[d][0] += phi[d][j] * qv[0][j];
            out[d][1] += phi[d][j] * qv[1][j];
        }
    }
    out
}

/// `force += phi_T u_T + phi_L u_L + phi_P u_P`, in one pass.
#[inline(always)]
fn drive_point<const FMA: bool>(force: &mut [f64], phi: &[Vec<f64>; 3], u: [f64; 3]) {
    let n = force.len();
    let (a, b, c) = (&phi[0][..n], &phi[1][..n], &phi[2][..n]);
    for i in 0..n {
        force[i] = fma::<FMA>(
            a[i],
            u[0],
            fma::<FMA>(b[i], u[1], fma::<FMA>(c[i], u[2], force[i])),
        );
    }
}

/// `a b + c`, fused when the step runs with FMA (a separate multiply and add otherwise, never
/// the slow software `fma`).
#[inline(always)]
fn fma<const FMA: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// ETDRK4 coefficients of one mode `lambda` for step `h`: `Q = (e^{lambda h/2} - 1)/lambda`,
/// `(e^{lambda h/2} - 1) Q`, and the final weights `f1`, `f2` (of `N(a) + N(b)`), `f3`:
/// `h {-4 - z + e^z (4 - 3z + z^2)} / z^3`, `2h {2 + z + e^z (z - 2)} / z^3`,
/// `h {-4 - 3z - z^2 + e^z (4 - z)} / z^3` with `z = lambda h`. Near `z = 0` these cancel, so
/// there they are the mean over a circle of radius 1 around `z` (Kassam & Trefethen 2005).
fn etd_weights(lambda: c64, h: f64) -> [c64; 5] {
    let one = c64::new(1.0, 0.0);
    let exp = |z: c64| {
        let m = z.re.exp();
        c64::new(m * z.im.cos(), m * z.im.sin())
    };
    let direct = |z: c64| -> [c64; 4] {
        let (e, e2) = (exp(z), exp(z * 0.5));
        let z3 = z * z * z;
        [
            (e2 - one) / z,
            ((-one * 4.0) - z + e * (one * 4.0 - z * 3.0 + z * z)) / z3,
            ((one * 2.0) + z + e * (z - one * 2.0)) / z3 * 2.0,
            ((-one * 4.0) - z * 3.0 - z * z + e * (one * 4.0 - z)) / z3,
        ]
    };
    let z = lambda * h;
    let phi = if z.norm() > 0.5 {
        direct(z)
    } else {
        const POINTS: usize = 64;
        let mut acc = [c64::new(0.0, 0.0); 4];
        for k in 0..POINTS {
            let t = 2.0 * std::f64::consts::PI * (k as f64 + 0.5) / POINTS as f64;
            let v = direct(z + c64::new(t.cos(), t.sin()));
            for (a, v) in acc.iter_mut().zip(v) {
                *a += v;
            }
        }
        acc.map(|a| a / POINTS as f64)
    };
    // phi[0] is Q / h; the others are already per unit h.
    let q = phi[0] * h;
    let e2 = exp(z * 0.5);
    [q, (e2 - one) * q, phi[1] * h, phi[2] * h, phi[3] * h]
}
