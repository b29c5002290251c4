//! The live integrator: exponential (integrating-factor, Lawson) RK4 on the system's complex modes.
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
//! The board's modes are diagonal already. What stays explicit, at fourth order, is small: the
//! board's motion felt by the string through its contact spring and damper (≈ 2 kHz stiffness, so
//! `omega h ≈ 0.25` at 48 kHz), the felt hammer (Eq. 8) and the damper felt. RK4 at the paper's
//! rate stays the reference ([`super::Instrument`]); `tests/integrators.rs` compares the two.
//!
//! Lawson RK4 for `y' = L y + N(y)` with `E = e^{L h/2}`:
//! `a = N(y)`, `b = N(E (y + h/2 a))`, `c = N(E y + h/2 b)`, `d = N(E² y + h E c)`,
//! `y⁺ = E² y + h/6 (E² a + 2 E (b + c) + d)`. Every explicit force enters through a few input
//! vectors `g_j = V^-1 b_j` and is read through a few output rows `r_o = c_o V`, so the stage
//! states are never formed: each stage output is a dot product of the step's starting `z` with a
//! precomputed row (`r`, `r E` or `r E²`) plus precomputed scalar responses to the earlier stages'
//! inputs. A step touches each complex mode for three dot products per output and one update.

use super::duplex::duplex_damping_matrix;
use super::hammer::HammerParams;
use super::system::{BuildError, Observation, Strike, UnisonSpec};
use super::MAX_STRINGS;
use faer::linalg::solvers::Solve;
use faer::{c64, Mat};

/// A linear block `x' = A x + sum_j B_j u_j` in its complex modes, with the rows that read it.
///
/// Of each complex-conjugate pair of modes only one is stored (its partner is its conjugate: the
/// block is real), with weight 2 folded into the output rows; real (overdamped) modes have weight 1.
#[derive(Debug, Clone)]
struct Block {
    /// `z` (real and imaginary parts) over the stored modes.
    zr: Vec<f64>,
    zi: Vec<f64>,
    /// `e^{lambda h}`.
    e_full: [Vec<f64>; 2],
    /// Per output: the row `r`, `r e^{lambda h/2}`, `r e^{lambda h}` (re, im), weights folded in.
    rows: Vec<[[Vec<f64>; 2]; 3]>,
    /// Per input: `f1 g`, `f2 g`, `f3 g` (re, im), the ETDRK4 weights of the final update.
    gains: Vec<[[Vec<f64>; 2]; 3]>,
    /// `resp[o][j] = [Re r_o Q g_j, Re r_o (e^{lambda h/2} - 1) Q g_j]`: what one unit of input `j`
    /// adds to output `o` at the later stages.
    resp: Vec<Vec<[f64; 2]>>,
}

/// Which outputs and inputs a block has: displacement rows (`c^T q`), velocity rows (`c^T qdot`)
/// and force inputs (`b u` on the acceleration).
struct Ports<'a> {
    displacement: &'a [&'a [f64]],
    velocity: &'a [&'a [f64]],
    inputs: &'a [&'a [f64]],
}

impl Block {
    /// Diagonalise `qdd = -K q - C qdot + sum_j b_j u_j` (dense `n × n`, row-major) for step `h`.
    fn new(k: &[f64], c: &[f64], n: usize, ports: Ports, h: f64) -> Result<Block, BuildError> {
        let a = Mat::<f64>::from_fn(2 * n, 2 * n, |i, j| match (i < n, j < n) {
            (true, true) => 0.0,
            (true, false) => f64::from(u8::from(j - n == i)),
            (false, true) => -k[(i - n) * n + j],
            (false, false) => -c[(i - n) * n + (j - n)],
        });
        let eig = a.eigen().map_err(|_| BuildError::Modes)?;
        let (u, s) = (eig.U(), eig.S().column_vector());
        let lu = u.partial_piv_lu();
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
        if 2 * pairs + (keep.len() - pairs) != 2 * n {
            return Err(BuildError::Modes);
        }
        // Stored modes padded with zeros to whole SIMD lanes (a zero mode stays zero).
        let padded = keep.len().div_ceil(LANES) * LANES;
        let split = |v: Vec<c64>| -> [Vec<f64>; 2] {
            let mut re: Vec<f64> = v.iter().map(|x| x.re).collect();
            let mut im: Vec<f64> = v.iter().map(|x| x.im).collect();
            re.resize(padded, 0.0);
            im.resize(padded, 0.0);
            [re, im]
        };
        let exp = |t: f64| -> Vec<c64> {
            keep.iter()
                .map(|&(i, _)| {
                    let l = s[i] * c64::new(t, 0.0);
                    c64::new(l.re.exp() * l.im.cos(), l.re.exp() * l.im.sin())
                })
                .collect()
        };
        let (eh, ef) = (exp(0.5 * h), exp(h));
        // Output rows r = c^T V over the kept modes, weighted.
        let mut rows_c = Vec::new();
        let outs = ports
            .displacement
            .iter()
            .map(|r| (r, 0))
            .chain(ports.velocity.iter().map(|r| (r, n)));
        for (row, off) in outs {
            let r: Vec<c64> = keep
                .iter()
                .map(|&(m, w)| {
                    let mut acc = c64::new(0.0, 0.0);
                    for (i, &ci) in row.iter().enumerate() {
                        acc += u[(off + i, m)] * c64::new(ci, 0.0);
                    }
                    acc * c64::new(w, 0.0)
                })
                .collect();
            rows_c.push(r);
        }
        // Inputs g = V^-1 [0; b].
        let mut g_c = Vec::new();
        for b in ports.inputs {
            let rhs = Mat::<c64>::from_fn(2 * n, 1, |i, _| {
                if i >= n {
                    c64::new(b[i - n], 0.0)
                } else {
                    c64::new(0.0, 0.0)
                }
            });
            let g = lu.solve(&rhs);
            g_c.push(keep.iter().map(|&(m, _)| g[(m, 0)]).collect::<Vec<c64>>());
        }
        // ETDRK4 weights per mode (Cox & Matthews 2002), from phi functions of z = lambda h.
        let lam: Vec<c64> = keep.iter().map(|&(i, _)| s[i]).collect();
        let weights: Vec<[c64; 5]> = lam.iter().map(|&l| etd_weights(l, h)).collect();
        let w = |k: usize| -> Vec<c64> { weights.iter().map(|x| x[k]).collect() };
        let (q, eq, f1, f2, f3) = (w(0), w(1), w(2), w(3), w(4));
        let dot_re = |r: &[c64], e: &[c64], g: &[c64]| -> f64 {
            (0..r.len()).map(|m| (r[m] * e[m] * g[m]).re).sum()
        };
        let resp = rows_c
            .iter()
            .map(|r| {
                g_c.iter()
                    .map(|g| [dot_re(r, &q, g), dot_re(r, &eq, g)])
                    .collect()
            })
            .collect();
        let times =
            |a: &[c64], b: &[c64]| -> Vec<c64> { a.iter().zip(b).map(|(x, y)| x * y).collect() };
        let rows = rows_c
            .iter()
            .map(|r| [split(r.clone()), split(times(r, &eh)), split(times(r, &ef))])
            .collect();
        let gains = g_c
            .iter()
            .map(|g| {
                [
                    split(times(g, &f1)),
                    split(times(g, &f2)),
                    split(times(g, &f3)),
                ]
            })
            .collect();
        Ok(Block {
            zr: vec![0.0; padded],
            zi: vec![0.0; padded],
            e_full: split(ef),
            rows,
            gains,
            resp,
        })
    }

    /// `Re(r z)` for output `o` through row `which` (0: `r`, 1: `r E`, 2: `r E²`).
    fn read(&self, o: usize, which: usize) -> f64 {
        let [rr, ri] = &self.rows[o][which];
        rr.iter()
            .zip(ri)
            .zip(self.zr.iter().zip(&self.zi))
            .map(|((a, b), (x, y))| a * x - b * y)
            .sum()
    }

    /// [`Block::read`] through all three rows of output `o` in one pass over `z`, in SIMD lanes
    /// with the real and imaginary products in separate accumulators: six independent FMA
    /// chains that stay in registers, so the loop is limited by loads rather than latency.
    #[inline(always)]
    fn read3<const FMA: bool>(&self, o: usize) -> [f64; 3] {
        let n = self.zr.len();
        let [[r0, i0], [r1, i1], [r2, i2]] = &self.rows[o];
        #[cfg(target_arch = "x86_64")]
        if FMA {
            let rows = [&r0[..n], &i0[..n], &r1[..n], &i1[..n], &r2[..n], &i2[..n]];
            // SAFETY: `FMA` is true only inside `step_avx2`, entered after detecting AVX2 and
            // FMA; every row holds the block's `n` (a multiple of 4) modes, as `z` does.
            return unsafe { read3_avx2(&self.zr, &self.zi, rows) };
        }
        let mut a = [[0.0; LANES]; 6];
        let zs = self.zr[..n]
            .chunks_exact(LANES)
            .zip(self.zi[..n].chunks_exact(LANES));
        let rs = r0[..n].chunks_exact(LANES).zip(i0[..n].chunks_exact(LANES));
        let rs1 = r1[..n].chunks_exact(LANES).zip(i1[..n].chunks_exact(LANES));
        let rs2 = r2[..n].chunks_exact(LANES).zip(i2[..n].chunks_exact(LANES));
        for ((((zr, zi), (r0, i0)), (r1, i1)), (r2, i2)) in zs.zip(rs).zip(rs1).zip(rs2) {
            for l in 0..LANES {
                a[0][l] = fma::<FMA>(r0[l], zr[l], a[0][l]);
                a[1][l] = fma::<FMA>(i0[l], zi[l], a[1][l]);
                a[2][l] = fma::<FMA>(r1[l], zr[l], a[2][l]);
                a[3][l] = fma::<FMA>(i1[l], zi[l], a[3][l]);
                a[4][l] = fma::<FMA>(r2[l], zr[l], a[4][l]);
                a[5][l] = fma::<FMA>(i2[l], zi[l], a[5][l]);
            }
        }
        let sum = |x: [f64; LANES]| (x[0] + x[1]) + (x[2] + x[3]);
        [
            sum(a[0]) - sum(a[1]),
            sum(a[2]) - sum(a[3]),
            sum(a[4]) - sum(a[5]),
        ]
    }

    /// The step's end: `z <- E² z + sum_j (f1 g_j a_j + f2 g_j (b_j + c_j) + f3 g_j d_j)`.
    #[inline(always)]
    fn advance<const FMA: bool>(&mut self, u: &[[f64; 4]]) {
        let n = self.zr.len();
        let (er, ei) = (&self.e_full[0][..n], &self.e_full[1][..n]);
        let (zr, zi) = (&mut self.zr[..n], &mut self.zi[..n]);
        for m in 0..n {
            let (a, b) = (zr[m], zi[m]);
            zr[m] = fma::<FMA>(er[m], a, -ei[m] * b);
            zi[m] = fma::<FMA>(er[m], b, ei[m] * a);
        }
        for (gain, &[ua, ub, uc, ud]) in self.gains.iter().zip(u) {
            for (g, s) in gain.iter().zip([ua, ub + uc, ud]) {
                if s != 0.0 {
                    let (gr, gi) = (&g[0][..n], &g[1][..n]);
                    for m in 0..n {
                        zr[m] = fma::<FMA>(gr[m], s, zr[m]);
                        zi[m] = fma::<FMA>(gi[m], s, zi[m]);
                    }
                }
            }
        }
    }
}

/// [`Block::read3`] with explicit AVX2 + FMA: six accumulators (re and im products of the three
/// rows) over `n` modes, `n` a multiple of 4 and every slice `n` long.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn read3_avx2(zr: &[f64], zi: &[f64], rows: [&[f64]; 6]) -> [f64; 3] {
    use std::arch::x86_64::*;
    let n = zr.len();
    debug_assert!(n % LANES == 0 && zi.len() == n && rows.iter().all(|r| r.len() == n));
    let mut a = [_mm256_setzero_pd(); 6];
    let mut i = 0;
    while i < n {
        let x = _mm256_loadu_pd(zr.as_ptr().add(i));
        let y = _mm256_loadu_pd(zi.as_ptr().add(i));
        for (k, acc) in a.iter_mut().enumerate() {
            let z = if k % 2 == 0 { x } else { y };
            *acc = _mm256_fmadd_pd(_mm256_loadu_pd(rows[k].as_ptr().add(i)), z, *acc);
        }
        i += LANES;
    }
    let sum = |v: __m256d| {
        let mut x = [0.0; LANES];
        _mm256_storeu_pd(x.as_mut_ptr(), v);
        (x[0] + x[1]) + (x[2] + x[3])
    };
    [
        sum(a[0]) - sum(a[1]),
        sum(a[2]) - sum(a[3]),
        sum(a[4]) - sum(a[5]),
    ]
}

/// SIMD lanes of the mode loops (four f64 in an AVX2 register).
const LANES: usize = 4;

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

/// Rows of a string block: `psi.q` at the bridge, `psi(L_e).q` at the strike point (T only),
/// `psi.qdot` at the bridge, `psi(x_d).qdot` at the damper; its inputs are the bridge force, the
/// felt (T only) and the damper felt, in that order.
const BRIDGE_Q: usize = 0;
const STRIKE_Q: usize = 1;
const BRIDGE_V: usize = 2;
const DAMPER_V: usize = 3;
/// Rows of the board: `phi_d.q_b` (0–2), `phi_d.qdot_b` (3–5), the volume velocity (6).
const BOARD_V: usize = 3;
const VOLUME: usize = 6;

/// What the blocks read at one stage: `(psi.q, psi.qdot)` of each string direction at the bridge,
/// the board's `(phi_d.q_b, phi_d.qdot_b)`, the strike-point displacements, the damper-point
/// velocities (T, P) and the hammer's position.
#[derive(Debug, Clone, Copy, Default)]
struct StageOutputs {
    bridge: [[[f64; 2]; 3]; MAX_STRINGS],
    board: [[f64; 2]; 3],
    strike_q: [f64; MAX_STRINGS],
    damper_v: [[f64; 2]; MAX_STRINGS],
    hammer_y: f64,
}

/// The explicit forces of one stage: each string block's inputs (bridge, felt, damper felt), the
/// board's (T, L, P), the hammer's acceleration.
#[derive(Debug, Clone, Copy, Default)]
struct StageInputs {
    strings: [[[f64; 3]; 3]; MAX_STRINGS],
    board: [f64; 3],
    hammer_acc: f64,
}

/// ETDRK4 (Cox & Matthews 2002) with `E = e^{L h/2}`, `Q = (E - 1) L^-1`: `a = E y + Q N(y)`,
/// `b = E y + Q N(a)`, `c = E² y + (E - 1) Q N(y) + 2 Q N(b)`. Per stage: the row read from the
/// start state (0: `r`, 1: `r E`, 2: `r E²`) and the terms `(earlier stage, response kind
/// (0: `r Q g`, 1: `r (E - 1) Q g`), coefficient)`.
type StagePlan = (usize, [(usize, usize, f64); 2]);
const ETDRK4_STAGES: [StagePlan; 4] = [
    (0, [(0, 0, 0.0), (0, 0, 0.0)]),
    (1, [(0, 0, 1.0), (0, 0, 0.0)]),
    (1, [(1, 0, 1.0), (0, 0, 0.0)]),
    (2, [(0, 1, 1.0), (1, 0, 2.0)]),
];

/// One unison on its bridge point advanced by exponential RK4 at `spec.sample_rate_hz` (48 kHz:
/// the output rate, no decimation needed). The same physics as [`super::Instrument`]; see the
/// module's notes.
#[derive(Debug, Clone)]
pub struct ExponentialUnison {
    /// `strings[s][d]`, directions T, L, P.
    strings: Vec<[Block; 3]>,
    board: Block,
    n_strings: usize,
    contact_k: [f64; 3],
    contact_c: [f64; 3],
    hammer: HammerParams,
    has_damper: bool,
    damper_n_s_m: f64,
    damper_down: bool,
    hammer_on: bool,
    struck: [bool; MAX_STRINGS],
    hammer_y: f64,
    hammer_v: f64,
    h: f64,
    fast_path: bool,
}

impl ExponentialUnison {
    /// Diagonalise every string direction and the board for the step `1 / spec.sample_rate_hz`.
    pub fn new(spec: &UnisonSpec) -> Result<ExponentialUnison, BuildError> {
        let ns = spec.strings.len();
        if ns == 0 || ns > MAX_STRINGS {
            return Err(BuildError::StringCount(ns));
        }
        let point = spec
            .board
            .points
            .get(spec.bridge_point)
            .ok_or(BuildError::BridgePoint(spec.bridge_point))?;
        let h = 1.0 / spec.sample_rate_hz;
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
                        ck[i * n + j] = cc * psi[i] * psi[j]
                            + if transverse { duplex[i * nd + j] } else { 0.0 };
                    }
                    let w = omega(i);
                    kk[i * n + i] += w * w;
                    ck[i * n + i] += 2.0 * zeta * w;
                }
                // Uniform ports (zero rows where a direction has no hammer or no damper):
                // rows psi.q, psi(L_e).q, psi.qdot, psi(x_d).qdot; inputs bridge, hammer, damper.
                let at = |x: Option<f64>| -> Vec<f64> {
                    match x {
                        Some(x) => (0..n).map(|k| string.mode_shape(k + 1, x)).collect(),
                        None => vec![0.0; n],
                    }
                };
                let hammer = at((d == 0).then_some(strike_x));
                let damper = at(damper_x.filter(|_| transverse));
                let ports = Ports {
                    displacement: &[&psi, &hammer],
                    velocity: &[&psi, &damper],
                    inputs: &[&psi, &hammer, &damper],
                };
                let block = Block::new(&kk, &ck, n, ports, h)?;
                blocks.push(block);
            }
            let [t, l, p]: [Block; 3] = blocks.try_into().expect("three directions");
            strings.push([t, l, p]);
        }
        // The board: diagonal, read and driven at this key's point in T, L, P; its volume velocity.
        let nb = spec.board.len();
        let mut kb = vec![0.0; nb * nb];
        let mut cb = vec![0.0; nb * nb];
        for i in 0..nb {
            let w = 2.0 * std::f64::consts::PI * spec.board.freq_hz[i];
            kb[i * nb + i] = w * w;
            cb[i * nb + i] = 2.0 * spec.board.damping_ratio[i] * w;
        }
        let shape: Vec<&[f64]> = point.shape.iter().map(Vec::as_slice).collect();
        let mut velocity = shape.clone();
        velocity.push(&spec.board.volume_m2_per_sqrt_kg);
        let board = Block::new(
            &kb,
            &cb,
            nb,
            Ports {
                displacement: &shape,
                velocity: &velocity,
                inputs: &shape,
            },
            h,
        )?;
        Ok(ExponentialUnison {
            strings,
            board,
            n_strings: ns,
            contact_k: spec.contact.stiffness_n_m,
            contact_c: spec.contact.damping_n_s_m,
            hammer: spec.hammer,
            has_damper: damper_x.is_some(),
            damper_n_s_m: spec.damper.map_or(0.0, |d| d.damping_n_s_m),
            damper_down: false,
            hammer_on: false,
            struck: [false; MAX_STRINGS],
            hammer_y: 0.0,
            hammer_v: 0.0,
            h,
            fast_path: super::system::has_avx2_fma(),
        })
    }

    /// Step (s).
    pub fn step_s(&self) -> f64 {
        self.h
    }

    /// Lower or lift the damper (keys without one ignore it).
    pub fn set_damper(&mut self, down: bool) {
        self.damper_down = down && self.has_damper;
    }

    /// Launch the hammer at the struck strings from their current displacement, moving towards
    /// them at `velocity_m_s` (as [`super::Instrument::strike_voice`]).
    pub fn strike(&mut self, strike: Strike) {
        let n = strike.strings_struck(self.n_strings);
        self.struck = [false; MAX_STRINGS];
        self.struck[..n].iter_mut().for_each(|s| *s = true);
        self.hammer_on = true;
        self.hammer_y = (0..n)
            .map(|s| self.strings[s][0].read(STRIKE_Q, 0))
            .fold(f64::NEG_INFINITY, f64::max);
        self.hammer_v = strike.velocity_m_s;
    }

    /// The explicit forces at one stage from what the blocks read there: the inputs of every
    /// string block (bridge, felt, damper felt) and of the board, and the hammer's acceleration.
    fn forces(&self, at: &StageOutputs) -> StageInputs {
        let mut inputs = StageInputs::default();
        let mut felt_total = 0.0;
        for s in 0..self.n_strings {
            for d in 0..3 {
                let (k, c) = (self.contact_k[d], self.contact_c[d]);
                let [q, v] = at.bridge[s][d];
                let f = k * (q - at.board[d][0]) + c * (v - at.board[d][1]);
                // The linear part holds -psi (k psi.q + c psi.qdot); the rest of -psi F is this.
                inputs.strings[s][d][0] = k * q + c * v - f;
                inputs.board[d] += f;
            }
            if self.hammer_on && self.struck[s] {
                let f = self.hammer.felt_force_n(at.hammer_y - at.strike_q[s]);
                inputs.strings[s][0][1] = f;
                felt_total += f;
            }
            if self.damper_down {
                inputs.strings[s][0][2] = -self.damper_n_s_m * at.damper_v[s][0];
                inputs.strings[s][2][2] = -self.damper_n_s_m * at.damper_v[s][1];
            }
        }
        inputs.hammer_acc = -felt_total / self.hammer.mass_kg;
        inputs
    }

    /// Advance one step of exponential RK4 (ETDRK4); never allocates.
    pub fn step(&mut self) {
        #[cfg(target_arch = "x86_64")]
        if self.fast_path {
            // SAFETY: `fast_path` is set only when the CPU reports AVX2 and FMA.
            unsafe { self.step_avx2() };
            return;
        }
        self.step_impl::<false>();
    }

    /// The step compiled for AVX2 + FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn step_avx2(&mut self) {
        self.step_impl::<true>();
    }

    #[inline(always)]
    fn step_impl<const FMA: bool>(&mut self) {
        let h = self.h;
        let ns = self.n_strings;
        let (hammer, damper) = (self.hammer_on, self.damper_down);
        // Each output row read from the step's start: r z, r E z, r E² z.
        let mut start = [[[[0.0; 3]; 4]; 3]; MAX_STRINGS];
        for s in 0..ns {
            for d in 0..3 {
                let b = &self.strings[s][d];
                start[s][d][BRIDGE_Q] = b.read3::<FMA>(BRIDGE_Q);
                start[s][d][BRIDGE_V] = b.read3::<FMA>(BRIDGE_V);
                if d == 0 && hammer && self.struck[s] {
                    start[s][d][STRIKE_Q] = b.read3::<FMA>(STRIKE_Q);
                }
                if d != 1 && damper {
                    start[s][d][DAMPER_V] = b.read3::<FMA>(DAMPER_V);
                }
            }
        }
        let board_start: [[f64; 3]; 6] = std::array::from_fn(|o| self.board.read3::<FMA>(o));
        // Inputs of every block at each stage, and the hammer's accelerations.
        let mut inputs = [StageInputs::default(); 4];
        let (hy0, hv0) = (self.hammer_y, self.hammer_v);
        let (mut hy, mut hv) = (hy0, hv0);
        for (stage, &(which, terms)) in ETDRK4_STAGES.iter().enumerate() {
            // Row `which` of the start state plus the responses to earlier stages' inputs.
            let out = |b: &Block, x: &[f64; 3], o: usize, input: &[[f64; 3]; 4]| {
                let mut v = x[which];
                for &(p, kind, coef) in &terms {
                    if coef != 0.0 {
                        for (j, uj) in input[p].iter().enumerate() {
                            v += coef * b.resp[o][j][kind] * uj;
                        }
                    }
                }
                v
            };
            let mut at = StageOutputs {
                hammer_y: hy,
                ..StageOutputs::default()
            };
            for s in 0..ns {
                for d in 0..3 {
                    let (b, x) = (&self.strings[s][d], &start[s][d]);
                    let input = inputs.map(|i| i.strings[s][d]);
                    at.bridge[s][d] = [
                        out(b, &x[BRIDGE_Q], BRIDGE_Q, &input),
                        out(b, &x[BRIDGE_V], BRIDGE_V, &input),
                    ];
                    if d == 0 && hammer && self.struck[s] {
                        at.strike_q[s] = out(b, &x[STRIKE_Q], STRIKE_Q, &input);
                    }
                    if d != 1 && damper {
                        at.damper_v[s][d / 2] = out(b, &x[DAMPER_V], DAMPER_V, &input);
                    }
                }
            }
            let input = inputs.map(|i| i.board);
            for d in 0..3 {
                let b = &self.board;
                at.board[d] = [
                    out(b, &board_start[d], d, &input),
                    out(b, &board_start[BOARD_V + d], BOARD_V + d, &input),
                ];
            }
            inputs[stage] = self.forces(&at);
            // The hammer has no linear part: classical RK4 stages at the same times.
            if stage < 3 {
                let c = if stage < 2 { 0.5 } else { 1.0 };
                let dy = if stage == 0 { hv0 } else { hv };
                hy = hy0 + c * h * dy;
                hv = hv0 + c * h * inputs[stage].hammer_acc;
            }
        }
        let ah = inputs.map(|i| i.hammer_acc);
        if hammer {
            let v2 = hv0 + 0.5 * h * ah[0];
            let v3 = hv0 + 0.5 * h * ah[1];
            let v4 = hv0 + h * ah[2];
            self.hammer_y += h / 6.0 * (hv0 + 2.0 * v2 + 2.0 * v3 + v4);
            self.hammer_v += h / 6.0 * (ah[0] + 2.0 * ah[1] + 2.0 * ah[2] + ah[3]);
        }
        for s in 0..ns {
            for d in 0..3 {
                let stages = |j: usize| inputs.map(|i| i.strings[s][d][j]);
                self.strings[s][d].advance::<FMA>(&[stages(0), stages(1), stages(2)]);
            }
        }
        let stages = |j: usize| inputs.map(|i| i.board[j]);
        self.board
            .advance::<FMA>(&[stages(0), stages(1), stages(2)]);
        if self.hammer_on && self.hammer_v < 0.0 {
            let clear = (0..ns).filter(|&s| self.struck[s]).all(|s| {
                self.strings[s][0].read(STRIKE_Q, 0) - self.hammer_y > self.hammer.release_gap_m
            });
            if clear {
                self.hammer_on = false;
            }
        }
    }

    /// Forces on the bridge and the hammer, and the board's volume velocity, now (Eq. 19).
    pub fn observe(&self) -> Observation {
        let mut obs = Observation {
            volume_velocity_m3_s: self.board.read(VOLUME, 0),
            ..Observation::default()
        };
        let mut rb = [[0.0; 2]; 3];
        for (d, rb) in rb.iter_mut().enumerate() {
            *rb = [self.board.read(d, 0), self.board.read(BOARD_V + d, 0)];
            obs.bridge_velocity_m_s[d] = rb[1];
        }
        for s in 0..self.n_strings {
            for d in 0..3 {
                let b = &self.strings[s][d];
                let f = self.contact_k[d] * (b.read(BRIDGE_Q, 0) - rb[d][0])
                    + self.contact_c[d] * (b.read(BRIDGE_V, 0) - rb[d][1]);
                obs.bridge_force_n[s][d] = f;
                obs.total_force_n[d] += f;
            }
            if self.hammer_on && self.struck[s] {
                let ye = self.strings[s][0].read(STRIKE_Q, 0);
                obs.hammer_force_n[s] = self.hammer.felt_force_n(self.hammer_y - ye);
            }
        }
        obs
    }

    /// Floating-point operations of one step in the current state, counted from the loops of
    /// [`Block::read3`] and [`Block::advance`] over the stored (padded) modes: 4 per mode for each
    /// row read (a complex multiply-add, real part), 6 for the propagation, 4 for each non-zero
    /// input of each of the three final weights. What `unacorda bench` divides by time.
    pub fn flops_per_step(&self) -> f64 {
        let (hammer, damper) = (self.hammer_on, self.damper_down);
        let mut flops = 0;
        for s in 0..self.n_strings {
            for d in 0..3 {
                let n = self.strings[s][d].zr.len();
                let struck = d == 0 && hammer && self.struck[s];
                let damped = d != 1 && damper;
                let outputs = 2 + usize::from(struck) + usize::from(damped);
                let inputs = 1 + usize::from(struck) + usize::from(damped);
                flops += n * (outputs * 3 * 4 + 6 + inputs * 3 * 4);
            }
        }
        flops += self.board.zr.len() * (6 * 3 * 4 + 6 + 3 * 3 * 4);
        flops as f64
    }

    /// Complex modes stored over all blocks (what a step touches).
    pub fn n_modes(&self) -> usize {
        self.strings
            .iter()
            .flatten()
            .chain(std::iter::once(&self.board))
            .map(|b| b.zr.len())
            .sum()
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
