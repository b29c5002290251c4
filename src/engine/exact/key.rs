//! One key's coefficients for the exact engine: its strings on their contact springs, the duplex
//! felt and the board's modes above [`SHARED_BELOW_HZ`] under its bridge point, diagonalised once
//! into complex modes ([`KeyModes`], the costly part, kept between runs), and everything a voice
//! derives from them for its step ([`ExactKey`]): the propagators, the hammer's ETDRK4 weights, the
//! shared board's motion at the bridge entering as an input, the damper felt, the reads.
//!
//! The board's motion `D` at the bridge point (the shared low modes, [`super::interface`]) enters
//! linear over each step, from `D^n` to `D^{n+1}`: `z' = e z + g_v D^n + g_s (D^{n+1} - D^n)/h`,
//! exact for such an input. In the shifted state `w = z - a D` with `a = g_s/h` this has one input,
//! the value known at the start of the step: `w' = e w + beta D^n`, `beta = g_v + (e - 1) a` — so a
//! voice's reads after the step are known before `D^{n+1}` is, but for `Z D^{n+1}` with a 3×3 `Z`
//! per key, and the interface solves for `D^{n+1}` ([`super::interface`]).

use super::bridge_modes::{BridgeSystem, Strand};
use super::interface::SHARED_BELOW_HZ;
pub(crate) use super::kernels::DAMPER_CHANNELS;
use super::kernels::{
    BlockCoefficients, EnergyCoefficients, Split, Taps, BLOCK, DAMPED_INPUTS, DAMPED_READS,
    DIRECTIONS, FELT_ROWS, READS, SOUND_READS, WIDE,
};
use crate::engine::modal::{input_weights, Modal};
use crate::engine::physics::damper::{DamperParams, FeltModel};
use crate::engine::physics::duplex::duplex_damping_matrix;
use crate::engine::physics::hammer::HammerParams;
use crate::engine::spec::{BuildError, Direction, UnisonSpec, CHANNELS, MAX_STRINGS};
use faer::c64;
use std::ops::Range;

/// Where each string direction's modes and the key's board modes lie in `q`, and which of the
/// board's modes the key carries (those at or above [`SHARED_BELOW_HZ`]).
#[derive(Debug, Clone)]
struct Layout {
    strings: [[Range<usize>; 3]; MAX_STRINGS],
    board: Range<usize>,
    board_modes: Vec<usize>,
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
        let board_modes: Vec<usize> = (0..spec.board.len())
            .filter(|&k| spec.board.freq_hz[k] >= SHARED_BELOW_HZ)
            .collect();
        let board = at..at + board_modes.len();
        Layout {
            strings,
            board: board.clone(),
            board_modes,
            n: board.end,
        }
    }

    /// A vector over `q` from `(index, value)` entries.
    fn vector(&self, entries: impl Iterator<Item = (usize, f64)>) -> Vec<f64> {
        let mut v = vec![0.0; self.n];
        for (i, x) in entries {
            v[i] += x;
        }
        v
    }

    /// A vector over `q` from a value per board mode of the whole board (the key's share).
    fn board_vector(&self, x: &[f64]) -> Vec<f64> {
        self.vector(
            self.board
                .clone()
                .zip(&self.board_modes)
                .map(|(i, &k)| (i, x[k])),
        )
    }
}

/// String `s`'s strand in direction `d` in [`coupled_system`]'s order.
fn strand(s: usize, d: usize) -> usize {
    s * Direction::ALL.len() + d
}

/// One key's second-order system `qdd = -K q - C qdot + ...`: its strings' modes with their
/// losses and the duplex felt (Eq. 13) on contact springs to its board modes at its point.
fn coupled_system(spec: &UnisonSpec, layout: &Layout, point: &[Vec<f64>; 3]) -> BridgeSystem {
    let nd = spec.modes.modes_t.max(spec.modes.modes_p);
    let mut strands = vec![];
    for (s, string) in spec.strings.iter().enumerate() {
        let ls = string.speaking_length_m;
        // The duplex felt on both transverse polarisations (Eq. 13).
        let cd = duplex_damping_matrix(
            nd,
            string.length_m(),
            ls,
            spec.duplex_damping_n_s_m2,
            string.linear_density_kg_m,
        );
        for dir in Direction::ALL {
            let range = layout.strings[s][dir.index()].clone();
            let m = range.len();
            let oscillators: Vec<_> = (0..m)
                .map(|j| string.oscillator(dir, j + 1, &spec.modes))
                .collect();
            let mut damping = vec![0.0; m * m];
            for (j, o) in oscillators.iter().enumerate() {
                damping[j * m + j] = o.damping_per_s();
                if dir.is_transverse() {
                    for q in 0..m {
                        damping[j * m + q] += cd[j * nd + q];
                    }
                }
            }
            strands.push(Strand {
                direction: dir.index(),
                start: range.start,
                omega2: oscillators.iter().map(|o| o.omega2()).collect(),
                damping,
                at_bridge: (0..m).map(|j| string.mode_shape(j + 1, ls)).collect(),
            });
        }
    }
    let board: Vec<_> = layout
        .board_modes
        .iter()
        .map(|&m| spec.board.oscillator(m))
        .collect();
    BridgeSystem {
        n: layout.n,
        strands,
        board_start: layout.board.start,
        board_omega2: board.iter().map(|o| o.omega2()).collect(),
        board_damping: board.iter().map(|o| o.damping_per_s()).collect(),
        board_at_point: std::array::from_fn(|d| {
            layout.board_modes.iter().map(|&m| point[d][m]).collect()
        }),
        contact_stiffness_n_m: spec.contact.stiffness_n_m,
        contact_damping_n_s_m: spec.contact.damping_n_s_m,
    }
}

/// The damper felt's channels as vectors over `q` (none without a damper): at each of the
/// felt's points, T and P of each string, its shape there weighted by the point's share
/// ([`crate::engine::physics::damper::DamperParams::felt_points`]); `C_damper = c sum_j v_j v_j^T`.
fn felt_vectors(spec: &UnisonSpec, layout: &Layout) -> Vec<Vec<f64>> {
    let Some(damper) = spec.damper else {
        return vec![];
    };
    let (points, count) = damper.felt_points(spec.strings[0].speaking_length_m);
    let mut felt = vec![];
    for &(x, a) in &points[..count] {
        for (s, string) in spec.strings.iter().enumerate() {
            for dir in [Direction::T, Direction::P] {
                felt.push(
                    layout.vector(
                        layout.strings[s][dir.index()]
                            .clone()
                            .enumerate()
                            .map(|(j, i)| (i, a * string.mode_shape(j + 1, x))),
                    ),
                );
            }
        }
    }
    felt
}

/// A key's coupled system in complex modes: the eigenvalues and every row and input a voice
/// reads or drives — the costly part of preparing a key (an eigen-decomposition of order
/// `2 × modes`), kept between runs ([`super::bytes`]). Everything else is derived from it.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct KeyModes {
    /// Every kept mode's eigenvalue `lambda` (1/s), one of each conjugate pair.
    pub(crate) lambda: Vec<c64>,
    /// Per string: the striking point's displacement row and the felt force's input (Eq. 14).
    pub(crate) strike_row: Vec<Split>,
    pub(crate) strike_input: Vec<Split>,
    /// Per string and direction, the contact force's row (Eq. 6, relative to the key's board
    /// modes); per direction, the key's board modes' velocity at the bridge point; per channel,
    /// the key's board modes' radiating source.
    pub(crate) force_row: Vec<[Split; 3]>,
    pub(crate) bridge_velocity_row: [Split; 3],
    pub(crate) volume_rows: [Split; CHANNELS],
    /// Per direction, the inputs of the shared board's motion `D` at the bridge: every string's
    /// contact spring stretched by it (`k_d D`) and its damper (`c_d Ddot`).
    pub(crate) bridge_input: [[Split; 2]; 3],
    /// Per damper channel (T and P of each string at each point of the felt, weighted by the
    /// point's share, [`crate::engine::physics::damper::DamperParams::felt_points`]): its velocity
    /// row and its force's input.
    pub(crate) damper_row: Vec<Split>,
    pub(crate) damper_input: Vec<Split>,
    /// Per mode, its mechanical energy per `|z|^2` (J, cycle-averaged).
    pub(crate) energy: Vec<f64>,
}

impl KeyModes {
    /// Diagonalise `spec`'s key at the step `1 / spec.sample_rate_hz`.
    pub(crate) fn new(spec: &UnisonSpec) -> Result<KeyModes, BuildError> {
        let ns = spec.string_count()?;
        let point = &spec.bridge()?.shape;
        let layout = Layout::new(spec);
        let system = coupled_system(spec, &layout, point);
        let (k, c) = system.dense();
        let modal = match system.modes(&k, &c) {
            Some(modal) => modal,
            None => Modal::dense(&k, &c, layout.n)?,
        };
        let s0 = &spec.strings[0];
        let t_modes = |s: usize, x: f64| {
            let string = &spec.strings[s];
            layout.vector(
                layout.strings[s][Direction::T.index()]
                    .clone()
                    .enumerate()
                    .map(move |(j, i)| (i, string.mode_shape(j + 1, x))),
            )
        };
        let strike_x = spec.hammer.strike_ratio * s0.speaking_length_m;
        let (mut strike_row, mut strike_input, mut force_row) = (vec![], vec![], vec![]);
        // The dropped board modes' source per unit force at the point, per channel and direction,
        // at each mode's eigenvalue; and what the strings' forces make of it, per channel.
        let dropped: Option<Vec<[Vec<c64>; 3]>> = spec.dropped.as_ref().map(|dm| {
            (0..CHANNELS)
                .map(|c| {
                    std::array::from_fn(|d| {
                        modal
                            .lambda
                            .iter()
                            .map(|l| {
                                let (re, im) = dm.source_per_force(c, d, (l.re, l.im));
                                c64::new(re, im)
                            })
                            .collect()
                    })
                })
                .collect()
        });
        let mut dropped_rows = vec![vec![c64::new(0.0, 0.0); modal.lambda.len()]; CHANNELS];
        for s in 0..ns {
            let psi_e = t_modes(s, strike_x);
            strike_row.push(Split::new(&modal.row(&psi_e, false)));
            strike_input.push(Split::new(&modal.input(&psi_e)));
            force_row.push(std::array::from_fn(|d| {
                let w = system.contact(strand(s, d));
                let (kc, cc) = (spec.contact.stiffness_n_m[d], spec.contact.damping_n_s_m[d]);
                let row: Vec<c64> = modal
                    .row(&w, false)
                    .iter()
                    .zip(modal.row(&w, true))
                    .map(|(q, v)| q * kc + v * cc)
                    .collect();
                // Each mode's share of the force, through the dropped modes to each channel.
                for (c, per_dir) in dropped.iter().flatten().enumerate() {
                    for ((x, f), r) in dropped_rows[c].iter_mut().zip(&row).zip(&per_dir[d]) {
                        *x += f * r;
                    }
                }
                Split::new(&row)
            }));
        }
        let board_row = |x: &[f64]| Split::new(&modal.row(&layout.board_vector(x), true));
        // Each channel's radiating source: the board modes' velocities and displacements,
        // weighted, and the dropped modes' part, each key mode's force through them at its own
        // eigenvalue (as the mode rings, `e^{lambda t}`; what they do with the hammer's and the
        // shared board's inputs over their own brief transients is left out).
        let radiation = |c: usize| {
            let [by_v, by_q] = spec.board.radiation_weights(c);
            let mut row = modal.row(&layout.board_vector(&by_v), true);
            for ((r, q), x) in row
                .iter_mut()
                .zip(modal.row(&layout.board_vector(&by_q), false))
                .zip(&dropped_rows[c])
            {
                *r += q + x;
            }
            Split::new(&row)
        };
        let bridge_input = std::array::from_fn(|d| {
            let mut w = vec![0.0; layout.n];
            for s in 0..ns {
                let ws = system.contact(strand(s, d));
                w.iter_mut().zip(ws).for_each(|(x, y)| *x += y);
            }
            [spec.contact.stiffness_n_m[d], spec.contact.damping_n_s_m[d]]
                .map(|g| Split::new(&modal.input(&w.iter().map(|x| x * g).collect::<Vec<_>>())))
        });
        let felt = felt_vectors(spec, &layout);
        let damper_row = felt
            .iter()
            .map(|v| Split::new(&modal.row(v, true)))
            .collect();
        let damper_input = felt.iter().map(|v| Split::new(&modal.input(v))).collect();
        let mut energy = modal.energy(&k);
        energy.truncate(modal.lambda.len());
        Ok(KeyModes {
            lambda: modal.lambda.clone(),
            strike_row,
            strike_input,
            force_row,
            bridge_velocity_row: std::array::from_fn(|d| board_row(&point[d])),
            volume_rows: std::array::from_fn(radiation),
            bridge_input,
            damper_row,
            damper_input,
            energy,
        })
    }

    pub(crate) fn n_modes(&self) -> usize {
        self.lambda.len()
    }

    /// The key's modes with the damper felt (`damping_n_s_m`, N s/m) on its strings, to first
    /// order: each mode's eigenvalue moves by the diagonal of the felt's feedback in the modes,
    /// `delta_m = -c sum_j g_jm r_jm / w_m` over the felt's channels `j` (velocity row `r`, input
    /// `g`; `w_m` = 2 for a conjugate pair, whose row carries that weight, 1 for a real mode) —
    /// for a light felt `-c/2 sum_k a_k^2 psi_m(x_k)^2` ([`crate::engine::physics::damper`]). The
    /// shapes stay the key's own, so that a voice whose damper falls or rises keeps its modal
    /// state; what the felt would pass between modes is left out (the felt coupled in full,
    /// [`DamperKey`], keeps it: measured against the felt in the key's full decomposition in this
    /// module's tests). A felt can only take energy: a mode it would seem to feed keeps its own
    /// decay.
    pub(crate) fn with_felt(&self, damping_n_s_m: f64) -> KeyModes {
        let lambda = self
            .lambda
            .iter()
            .zip(self.felt_shift(damping_n_s_m))
            .map(|(l, d)| l + d)
            .collect();
        // The felt is in the eigenvalues now: its channels are not kept.
        KeyModes {
            lambda,
            damper_row: vec![],
            damper_input: vec![],
            ..self.clone()
        }
    }

    /// How far the felt of `damping_n_s_m` moves each mode's eigenvalue, to first order
    /// ([`KeyModes::with_felt`]; never towards growth).
    pub(crate) fn felt_shift(&self, damping_n_s_m: f64) -> Vec<c64> {
        let scale = self.lambda.iter().map(|l| l.norm()).fold(1.0, f64::max);
        self.lambda
            .iter()
            .enumerate()
            .map(|(m, l)| {
                let weight = if l.im > 1e-12 * scale { 2.0 } else { 1.0 };
                let mut delta = c64::new(0.0, 0.0);
                for (r, g) in self.damper_row.iter().zip(&self.damper_input) {
                    delta -= c64::new(r.re[m], r.im[m]) * c64::new(g.re[m], g.im[m]);
                }
                delta *= damping_n_s_m / weight;
                c64::new(delta.re.min(0.0), delta.im)
            })
            .collect()
    }
}

/// Below this size of its argument [`PartFelt::damp`] takes the exponential as its series to
/// third order (within 3e-7 of itself), above it in full.
const SERIES_BELOW: f64 = 0.05;

/// What a part-lifted damper reads and does on a key whose damper is neither down nor clear
/// ([`crate::engine::pool::Policy::touch_felt`]): its strings' excursion under the felt, and
/// the felt's share of damping on each mode's decay, to first order as the modal felt's.
#[derive(Debug, Clone)]
pub(crate) struct PartFelt {
    /// Per string, per mode, the square of its vertical displacement under the felt per `|w|`:
    /// `sum_k |r_k|^2 / |lambda|^2` over the felt's points `k` of the T channel's velocity row
    /// (each point's share `a_k^2` taken out: the points' mean square).
    excursion: Vec<Vec<f64>>,
    /// Per mode, the whole felt's `delta h` ([`KeyModes::felt_shift`] times the step).
    rate: Vec<c64>,
    felt: DamperParams,
}

impl PartFelt {
    /// A key's, from its modes with the felt's channels, its felt at the step `h` (s).
    fn new(modes: &KeyModes, felt: DamperParams, h: f64) -> PartFelt {
        let ns = modes.force_row.len();
        let points = modes.damper_row.len() / (2 * ns);
        let excursion = (0..ns)
            .map(|s| {
                (0..modes.n_modes())
                    .map(|m| {
                        let l2 = modes.lambda[m].norm_sqr();
                        (0..points)
                            .map(|p| {
                                let r = &modes.damper_row[2 * (p * ns + s)];
                                (r.re[m] * r.re[m] + r.im[m] * r.im[m]) / l2
                            })
                            .sum()
                    })
                    .collect()
            })
            .collect();
        let rate = modes
            .felt_shift(felt.damping_n_s_m)
            .iter()
            .map(|d| d * h)
            .collect();
        PartFelt {
            excursion,
            rate,
            felt,
        }
    }

    /// The share of the felt at the lift `lift` ([`DamperParams::contact_share`]) with the
    /// loudest string's excursion under it from the first `live` modes of `w`.
    pub(crate) fn share(&self, lift: f64, w: &Split, live: usize) -> f64 {
        let amplitude_m = self
            .excursion
            .iter()
            .map(|e| {
                e.iter()
                    .zip(w.re.iter().zip(&w.im))
                    .take(live)
                    .map(|(e, (re, im))| e * (re * re + im * im))
                    .sum::<f64>()
            })
            .fold(0.0, f64::max)
            .sqrt();
        self.felt.contact_share(lift, amplitude_m)
    }

    /// Give the first `live` modes of `z = w + sum_d settle_d D_d` the felt's `share` over
    /// `steps` steps: each mode's decay moved by `share delta`, `z <- e^{share delta h steps} z`.
    pub(crate) fn damp(
        &self,
        w: &mut Split,
        settle: &[Split; DIRECTIONS],
        d: &[f64; DIRECTIONS],
        live: usize,
        share: f64,
        steps: usize,
    ) {
        let k = share * steps as f64;
        for (m, rate) in self.rate.iter().enumerate().take(live) {
            let x = rate * k;
            // A light felt's decay over a block is a small fraction of one: the exponential to
            // third order (error `|x|^4 / 24`); a heavy felt's, in full.
            let one = c64::new(1.0, 0.0);
            let g = if x.norm_sqr() < SERIES_BELOW * SERIES_BELOW {
                one + x * (one + x * 0.5 * (one + x / 3.0))
            } else {
                x.exp()
            };
            let mut held = c64::new(0.0, 0.0);
            for (a, dd) in settle.iter().zip(d) {
                held += c64::new(a.re[m], a.im[m]) * dd;
            }
            let z = g * c64::new(w.re[m], w.im[m]) + (g - 1.0) * held;
            (w.re[m], w.im[m]) = (z.re, z.im);
        }
    }
}

/// The damper felt of a key as an implicit feedback on its strings: channel `j` is the T or P
/// motion of one string at one point of the felt (weighted by its share), `f_j = -c v_j`,
/// entering over the step as a force linear in time from `f_j^n` to `f_j^{n+1}` (exact for the
/// modes, trapezoidal for the felt) and solved for `f^{n+1}` from the velocities after the step —
/// stable however stiff the felt.
#[derive(Debug, Clone)]
pub(crate) struct DamperKey {
    pub(crate) channels: usize,
    /// Velocity rows at the felt, and the inputs of `f^n` and `f^{n+1}`.
    pub(crate) rows: Vec<Split>,
    pub(crate) from: Vec<Split>,
    pub(crate) to: Vec<Split>,
    /// `Re(r_i from_j)` and `-c (I + c Re(r_i to_j))^-1`, row-major over channels.
    pub(crate) rows_from: [f64; DAMPER_CHANNELS * DAMPER_CHANNELS],
    pub(crate) solve: [f64; DAMPER_CHANNELS * DAMPER_CHANNELS],
    /// What each channel's `f^n` and `f^{n+1}` add to the step's reads (volume velocity, forces).
    pub(crate) reads_from: [[f64; DAMPER_CHANNELS]; READS],
    pub(crate) reads_to: [[f64; DAMPER_CHANNELS]; READS],
    /// What a unit of `D^{n+1}_d` adds to each channel's `f^{n+1}` (through `a D` in the velocity).
    pub(crate) settle: [[f64; DIRECTIONS]; DAMPER_CHANNELS],
    /// The damped key over a block: in the state `u = w - sum_j to_j f_j` the felt's force
    /// enters with the value known at the start of each step, `u' = e u + beta D^n + gamma f^n`,
    /// `gamma = from + e to`; the block reads the key's five rows and the felt's velocity per channel,
    /// and folds in `D` and `f` (channels beyond the key's, zero).
    pub(crate) block: BlockCoefficients<DAMPED_READS, DAMPED_INPUTS>,
    pub(crate) markov: Box<Taps<DAMPED_READS, DAMPED_INPUTS>>,
}

impl DamperKey {
    fn new(modes: &KeyModes, key: &Undamped<'_>, damping_n_s_m: f64) -> DamperKey {
        let Undamped {
            weights,
            h,
            ef,
            reads,
            settle,
            beta,
        } = *key;
        let rows = modes.damper_row.clone();
        let r = rows.len();
        let (mut from, mut to) = (vec![], vec![]);
        for g in &modes.damper_input {
            // f linear from f0 to f1: h phi1 f0 + h phi2 (f1 - f0).
            from.push(Split::weighted(g, weights, |[w1, w2]| w1 - w2 / h));
            to.push(Split::weighted(g, weights, |[_, w2]| w2 / h));
        }
        let cf = damping_n_s_m;
        let mut rows_from = [0.0; DAMPER_CHANNELS * DAMPER_CHANNELS];
        let mut a = faer::Mat::<f64>::zeros(r, r);
        for i in 0..r {
            for j in 0..r {
                rows_from[i * DAMPER_CHANNELS + j] = rows[i].read(&from[j]);
                a[(i, j)] = f64::from(u8::from(i == j)) + cf * rows[i].read(&to[j]);
            }
        }
        let inv = faer::linalg::solvers::DenseSolveCore::inverse(&a.partial_piv_lu());
        let mut solve = [0.0; DAMPER_CHANNELS * DAMPER_CHANNELS];
        for i in 0..r {
            for j in 0..r {
                solve[i * DAMPER_CHANNELS + j] = -cf * inv[(i, j)];
            }
        }
        let reads_from = std::array::from_fn(|i| {
            std::array::from_fn(|j| if j < r { reads[i].read(&from[j]) } else { 0.0 })
        });
        let reads_to = std::array::from_fn(|i| {
            std::array::from_fn(|j| if j < r { reads[i].read(&to[j]) } else { 0.0 })
        });
        let settle = std::array::from_fn(|i| {
            std::array::from_fn(|d| {
                (0..r)
                    .map(|j| solve[i * DAMPER_CHANNELS + j] * rows[j].read(&settle[d]))
                    .sum()
            })
        });
        let zero = Split::zeros(ef.len());
        let gamma: Vec<Split> = (0..r)
            .map(|j| {
                let mut g = from[j].clone();
                Split::weighted_by(&to[j], |m| ef[m]).add_to(&mut g, 1.0);
                g
            })
            .collect();
        let block_rows: [&Split; DAMPED_READS] = std::array::from_fn(|i| {
            if i < READS {
                &reads[i]
            } else {
                rows.get(i - READS).unwrap_or(&zero)
            }
        });
        let block_inputs: [&Split; DAMPED_INPUTS] = std::array::from_fn(|j| {
            if j < DIRECTIONS {
                &beta[j]
            } else {
                gamma.get(j - DIRECTIONS).unwrap_or(&zero)
            }
        });
        let e = Split::new(ef);
        DamperKey {
            channels: r,
            block: BlockCoefficients::new(&e, &block_rows, &block_inputs),
            markov: markov_parameters(ef, &block_rows, &block_inputs),
            rows,
            from,
            to,
            rows_from,
            solve,
            reads_from,
            reads_to,
            settle,
        }
    }
}

/// What the damper's coefficients are formed from: the key's step with the damper lifted.
#[derive(Clone, Copy)]
struct Undamped<'a> {
    /// Each mode's weights of an input linear over the step, the step, `e^{lambda h}`.
    weights: &'a [[c64; 2]],
    h: f64,
    ef: &'a [c64],
    reads: &'a [Split; READS],
    settle: &'a [Split; DIRECTIONS],
    beta: &'a [Split; DIRECTIONS],
}

/// How the reads after a step depend on `D^{n+1}`: `Z[i][d]` for the total contact force (N/m)
/// and each channel's radiating source's `[d]`, with the damper lifted or down.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Settle {
    pub(crate) force: [[f64; DIRECTIONS]; DIRECTIONS],
    pub(crate) volume: [[f64; DIRECTIONS]; CHANNELS],
}

/// `Re(r_i e^k g_d)` for `k < BLOCK`, laid out for [`super::kernels::scatter`].
fn markov_parameters<const R: usize, const I: usize>(
    e: &[c64],
    rows: &[&Split; R],
    inputs: &[&Split; I],
) -> Box<Taps<R, I>> {
    taps(&markov_sums(e, rows, inputs, 0..e.len()))
}

/// `Re(r_i e^k g_d)` for `k < BLOCK`, summed over the modes in `range`, in double precision.
fn markov_sums<const R: usize, const I: usize>(
    e: &[c64],
    rows: &[&Split; R],
    inputs: &[&Split; I],
    range: Range<usize>,
) -> Box<[[[f64; BLOCK]; I]; R]> {
    let mut out = Box::new([[[0.0; BLOCK]; I]; R]);
    for m in range {
        let rg: [[c64; I]; R] = std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                c64::new(rows[i].re[m], rows[i].im[m]) * c64::new(inputs[j].re[m], inputs[j].im[m])
            })
        });
        let mut power = c64::new(1.0, 0.0);
        for k in 0..BLOCK {
            for i in 0..R {
                for j in 0..I {
                    out[i][j][k] += (rg[i][j] * power).re;
                }
            }
            power *= e[m];
        }
    }
    out
}

/// Markov sums in single precision, laid out for [`super::kernels::scatter`] (tap `k` at `k`).
fn taps<const R: usize, const I: usize>(sums: &[[[f64; BLOCK]; I]; R]) -> Box<Taps<R, I>> {
    let mut out = Box::new(Taps([[[0f32; BLOCK]; I]; R]));
    for (out, sums) in out.0.iter_mut().zip(sums) {
        for (out, sums) in out.iter_mut().zip(sums) {
            for (o, &x) in out.iter_mut().zip(sums) {
                *o = x as f32;
            }
        }
    }
    out
}

/// A voice whose damper is lifted steps at least its modes below this frequency (Hz): the shared
/// board drives its strings below [`SHARED_BELOW_HZ`], and a mode an octave above what drives it
/// answers within `(1/2)^2` of quasi-statically ([`Prefix`]), which the modes left out are
/// taken to do.
pub(crate) const SYMPATHETIC_BELOW_HZ: f64 = 4.0 * SHARED_BELOW_HZ;

/// A chunk of a voice's modes is left out once its energy about the strings' static deflection
/// is under this fraction of the voice's (90 dB) ...
pub(crate) const LEFT_BELOW: f64 = 1e-9;
/// ... or under this energy (J), a thousandth of what a whole voice holds when it falls silent
/// ([`crate::engine::SILENCE_J`]).
pub(crate) const LEFT_UNDER_J: f64 = 1e-3 * crate::engine::SILENCE_J;

/// A voice of the key that keeps only its first `modes` modes (a whole number of [`WIDE`]-mode
/// chunks, in order of `|lambda|`: [`crate::engine::modal::Modal`]) and lets the rest follow the
/// bridge quasi-statically. A mode far above what drives it answers `D` as
/// `z = -(g_k D + g_c Ddot) / lambda - g_k Ddot / lambda^2` (its own transient long gone: the
/// next terms go as `(omega / |lambda|)^2`), so the modes left out read as a stiffness and a
/// damper on `D` — the strings' ends following the bridge, the contact springs' fastest modes —
/// and cost nothing: `S_0 = -sum Re(r g_k / lambda)`, `S_1 = -sum Re(r (g_c / lambda + g_k /
/// lambda^2))` over them, with `Ddot = (D^{n+1} - D^n) / h` over the step.
#[derive(Debug, Clone)]
pub(crate) struct Prefix {
    /// Modes stepped (a multiple of [`WIDE`], at most the key's padded count).
    pub(crate) modes: usize,
    /// How the reads depend on `D^{n+1}` with the damper lifted: the modes kept
    /// (`Re(r a_d)`), the contact springs' direct terms and the modes left out (`S_0 + S_1 / h`).
    pub(crate) settle: Settle,
    /// What `D^n` adds to each read through the modes left out (`-S_1 / h`).
    pub(crate) known: [[f64; DIRECTIONS]; READS],
    /// What `D` held adds to each read: the modes kept (`Re(r a_d)`) and left out (`S_0`).
    pub(crate) held: [[f64; DIRECTIONS]; READS],
    /// The kept modes' Markov parameters.
    pub(crate) markov: Box<Taps<READS, DIRECTIONS>>,
}

/// What builds a key's [`Prefix`]es: its step, its reads and the inputs of `D`.
struct Prefixes<'a> {
    h: f64,
    lambda: &'a [c64],
    ef: &'a [c64],
    reads: &'a [Split; READS],
    settle: &'a [Split; DIRECTIONS],
    beta: &'a [Split; DIRECTIONS],
    bridge_input: &'a [[Split; 2]; 3],
    feed_k: [f64; DIRECTIONS],
    feed_c: [f64; DIRECTIONS],
}

impl Prefixes<'_> {
    /// Every prefix of whole chunks, from none kept to all.
    fn build(&self) -> Vec<Prefix> {
        let n = self.lambda.len();
        let chunks = n.div_ceil(WIDE);
        let re = |a: c64, b: c64| (a * b).re;
        let at = |s: &Split, m: usize| c64::new(s.re[m], s.im[m]);
        // Per chunk: the kept modes' `Re(r a)`, the static terms `S_0`, `S_1` and the Markov sums.
        type PerRead = [[f64; DIRECTIONS]; READS];
        let mut kept: Vec<PerRead> = vec![[[0.0; DIRECTIONS]; READS]; chunks];
        let mut s0 = kept.clone();
        let mut s1 = kept.clone();
        let rows: [&Split; READS] = std::array::from_fn(|i| &self.reads[i]);
        let inputs: [&Split; DIRECTIONS] = std::array::from_fn(|d| &self.beta[d]);
        let mut sums = Vec::with_capacity(chunks);
        for c in 0..chunks {
            let range = c * WIDE..((c + 1) * WIDE).min(n);
            for m in range.clone() {
                let l = self.lambda[m];
                for i in 0..READS {
                    let r = at(&self.reads[i], m);
                    for d in 0..DIRECTIONS {
                        let (gk, gc) = (
                            at(&self.bridge_input[d][0], m),
                            at(&self.bridge_input[d][1], m),
                        );
                        kept[c][i][d] += re(r, at(&self.settle[d], m));
                        s0[c][i][d] -= re(r, gk / l);
                        s1[c][i][d] -= re(r, gc / l + gk / (l * l));
                    }
                }
            }
            sums.push(markov_sums(self.ef, &rows, &inputs, range));
        }
        let total = |x: &[PerRead]| -> PerRead {
            let mut t = [[0.0; DIRECTIONS]; READS];
            for x in x {
                for (t, x) in t.iter_mut().zip(x) {
                    for (t, x) in t.iter_mut().zip(x) {
                        *t += x;
                    }
                }
            }
            t
        };
        let h = self.h;
        (0..=chunks)
            .map(|p| {
                let (live, left_s0, left_s1) =
                    (total(&kept[..p]), total(&s0[p..]), total(&s1[p..]));
                let z = |i: usize, d: usize| live[i][d] + left_s0[i][d] + left_s1[i][d] / h;
                let mut markov = Box::new([[[0.0; BLOCK]; DIRECTIONS]; READS]);
                for chunk in &sums[..p] {
                    for (m, c) in markov.iter_mut().zip(chunk.iter()) {
                        for (m, c) in m.iter_mut().zip(c) {
                            for (m, c) in m.iter_mut().zip(c) {
                                *m += c;
                            }
                        }
                    }
                }
                Prefix {
                    modes: (p * WIDE).min(n.div_ceil(WIDE) * WIDE),
                    settle: Settle {
                        force: std::array::from_fn(|i| {
                            std::array::from_fn(|d| {
                                let direct = if i == d {
                                    self.feed_k[d] + self.feed_c[d] / h
                                } else {
                                    0.0
                                };
                                z(1 + i, d) - direct
                            })
                        }),
                        volume: SOUND_READS.map(|r| std::array::from_fn(|d| z(r, d))),
                    },
                    known: std::array::from_fn(|i| std::array::from_fn(|d| -left_s1[i][d] / h)),
                    held: std::array::from_fn(|i| {
                        std::array::from_fn(|d| live[i][d] + left_s0[i][d])
                    }),
                    markov: taps(&markov),
                }
            })
            .collect()
    }
}

/// The step while the felt touches: ETDRK4 (Cox & Matthews) in `substeps` steps of `h` a sample,
/// as many as [`HammerParams::contact_substeps`] asks for the key's felt, so that its shortest
/// contact spans enough of them (a hard treble felt's, under 0.2 ms, is eight samples at 48 kHz).
#[derive(Debug, Clone)]
pub(crate) struct ContactStep {
    pub(crate) substeps: usize,
    /// The substep (s).
    pub(crate) h: f64,
    /// `e^{lambda h/2}`, `e^{lambda h}` of the substep.
    pub(crate) eh: Split,
    pub(crate) ef: Split,
    /// Per string, the felt force's input through ETDRK4's `f1`, `f2`, `f3` (through its `Q`,
    /// only as the stages read it: `stage_q`, `stage_eq`).
    pub(crate) drive_f: Vec<[Split; 3]>,
    /// What the felt reads at ETDRK4's stages: per row it reads (each string's striking-point
    /// displacement, then each string's velocity there) and per string, what a unit of the felt's
    /// force on that string adds through `Q` to the read at stages `a`, `b`, `c` (`Re(r Q_s)`),
    /// and through `e^{lambda h/2} Q` at stage `c` (`Re(r e_h Q_s)`).
    pub(crate) stage_q: [[f64; MAX_STRINGS]; FELT_ROWS],
    pub(crate) stage_eq: [[f64; MAX_STRINGS]; FELT_ROWS],
}

impl ContactStep {
    /// The contact step of `modes` for a sample of `h_sample` in `substeps`; `velocity_rows` are
    /// the striking points' velocity rows (read by a hysteretic felt).
    fn new(
        modes: &KeyModes,
        velocity_rows: &[Split],
        h_sample: f64,
        substeps: usize,
    ) -> ContactStep {
        let h = h_sample / substeps as f64;
        let exp = |t: f64| -> Vec<c64> { modes.lambda.iter().map(|&l| (l * t).exp()).collect() };
        let (eh, ef) = (exp(0.5 * h), exp(h));
        let etd: Vec<[c64; 5]> = modes
            .lambda
            .iter()
            .map(|&l| crate::engine::modal::etd_weights(l, h))
            .collect();
        let drive_q: Vec<Split> = modes
            .strike_input
            .iter()
            .map(|g| Split::weighted_by(g, |m| etd[m][0]))
            .collect();
        let drive_f = modes
            .strike_input
            .iter()
            .map(|g| std::array::from_fn(|w| Split::weighted_by(g, |m| etd[m][2 + w])))
            .collect();
        let felt_rows: Vec<&Split> = modes.strike_row.iter().chain(velocity_rows).collect();
        let eh_q: Vec<Split> = drive_q
            .iter()
            .map(|q| Split::weighted_by(q, |m| eh[m]))
            .collect();
        let (mut stage_q, mut stage_eq) = (
            [[0.0; MAX_STRINGS]; FELT_ROWS],
            [[0.0; MAX_STRINGS]; FELT_ROWS],
        );
        for (i, row) in felt_rows.iter().enumerate() {
            for (s, (q, eq)) in drive_q.iter().zip(&eh_q).enumerate() {
                stage_q[i][s] = row.read(q);
                stage_eq[i][s] = row.read(eq);
            }
        }
        ContactStep {
            substeps,
            h,
            eh: Split::new(&eh),
            ef: Split::new(&ef),
            drive_f,
            stage_q,
            stage_eq,
        }
    }
}

/// One key's coefficients (module notes), shared by every voice that plays it.
#[derive(Debug, Clone)]
pub struct ExactKey {
    /// What they are derived from (kept to be stored).
    pub(crate) modes: KeyModes,
    pub(crate) n_strings: usize,
    pub(crate) h: f64,
    /// `e^{lambda h}`.
    pub(crate) ef: Split,
    /// The step while the felt touches.
    pub(crate) contact: ContactStep,
    /// Read after every step: the key's board modes' radiating source of the left channel, the
    /// total contact force per direction T, L, P relative to them (the force on the shared board
    /// is this less `feed_k D + feed_c Ddot`), the right channel's source ([`SOUND_READS`]).
    pub(crate) reads: [Split; READS],
    pub(crate) feed_k: [f64; 3],
    pub(crate) feed_c: [f64; 3],
    /// Per direction: `a_d` (`z = w + a D`), `beta_d` (`w' = e w + beta D^n`) and `g_v - a`
    /// (what `D^n` adds over a contact step taken on `z`).
    pub(crate) settle: [Split; DIRECTIONS],
    pub(crate) beta: [Split; DIRECTIONS],
    pub(crate) hold: [Split; DIRECTIONS],
    /// Chunks holding every mode below [`SYMPATHETIC_BELOW_HZ`]: what a voice whose damper is
    /// lifted steps at least.
    pub(crate) sympathetic: usize,
    /// A voice keeping each whole number of chunks of its modes, from none to all
    /// ([`Prefix`]: the damper lifted, or a modal felt down); how the reads depend on
    /// `D^{n+1}` with a coupled felt down (every mode kept).
    pub(crate) prefixes: Vec<Prefix>,
    pub(crate) damped: Settle,
    /// `Re(r a_d)` of each string's striking-point row, and of each force and bridge-velocity row
    /// (what `D` adds to them beside `w`).
    pub(crate) strike_settle: Vec<[f64; DIRECTIONS]>,
    /// Per string, the striking point's velocity row (`r lambda` of its displacement row `r`:
    /// the forces enter the accelerations only) and its `Re(r lambda a_d)`: what a hysteretic
    /// felt reads.
    pub(crate) strike_velocity_row: Vec<Split>,
    pub(crate) strike_velocity_settle: Vec<[f64; DIRECTIONS]>,
    pub(crate) force_settle: Vec<[[f64; DIRECTIONS]; 3]>,
    pub(crate) velocity_settle: [[f64; DIRECTIONS]; 3],
    /// Per direction, the modes' static response to a unit `D` held (a key joining a moving
    /// board starts on it, not jolted by its contact springs).
    pub(crate) follow: [Split; 3],
    /// What the voice's energies read ([`super::voice::Voice::energies_now_j`]): the shifts
    /// `a_d` and `a_d - follow_d` (`w` plus these times `D` is the state about the strings'
    /// static deflection by `D`) and each mode's energy per `|z|^2`.
    pub(crate) energy: EnergyCoefficients,
    /// The block loops' coefficients: `e`, the reads and the inputs `beta_d` (what a unit of
    /// `D_d` entering at one step adds to each read `k` steps later, `Re(r_i e^k beta_d)`, is
    /// each prefix's: a block advanced freely, mode by mode, gets its input back by
    /// superposition).
    pub(crate) block: BlockCoefficients<READS, DIRECTIONS>,
    /// The damper felt coupled in full ([`FeltModel::Coupled`]), or the same key with the
    /// felt on its modes' decay ([`FeltModel::Modal`], [`KeyModes::with_felt`]), stepped whenever
    /// its damper is down: it reads, drives and costs as this one. At most one of them; neither
    /// for a key without a damper.
    pub(crate) damper: Option<DamperKey>,
    pub(crate) modal_felt: Option<Box<ExactKey>>,
    /// A part-lifted damper's reads and decay (the key's own face, with a damper).
    pub(crate) part_felt: Option<PartFelt>,
    pub(crate) hammer: HammerParams,
}

impl ExactKey {
    /// Diagonalise `spec`'s key for the step `1 / spec.sample_rate_hz` and form its rows and
    /// inputs.
    pub fn new(spec: &UnisonSpec) -> Result<ExactKey, BuildError> {
        Ok(ExactKey::from_modes(spec, KeyModes::new(spec)?))
    }

    /// Everything a voice steps with, from the key's modes (cheap: no decomposition), and its
    /// face with a modal felt down.
    pub(crate) fn from_modes(spec: &UnisonSpec, modes: KeyModes) -> ExactKey {
        let h = 1.0 / spec.sample_rate_hz;
        let part_felt = spec.damper.map(|felt| PartFelt::new(&modes, felt, h));
        let key = match spec.damper {
            Some(felt) if felt.model == FeltModel::Modal => {
                let face = ExactKey::face(spec, modes.with_felt(felt.damping_n_s_m), None);
                ExactKey {
                    modal_felt: Some(Box::new(face)),
                    ..ExactKey::face(spec, modes, None)
                }
            }
            felt => ExactKey::face(spec, modes, felt.map(|f| f.damping_n_s_m)),
        };
        ExactKey { part_felt, ..key }
    }

    /// The key as it steps with `modes`, with a coupled felt of `coupled_n_s_m` if given.
    fn face(spec: &UnisonSpec, modes: KeyModes, coupled_n_s_m: Option<f64>) -> ExactKey {
        let h = 1.0 / spec.sample_rate_hz;
        let n = modes.n_modes();
        let ef: Vec<c64> = modes.lambda.iter().map(|&l| (l * h).exp()).collect();
        let weights: Vec<[c64; 2]> = modes.lambda.iter().map(|&l| input_weights(l, h)).collect();
        let total_force = |d: usize| -> Split {
            let mut t = Split::zeros(n);
            for row in &modes.force_row {
                row[d].add_to(&mut t, 1.0);
            }
            t
        };
        let reads = [
            modes.volume_rows[0].clone(),
            total_force(0),
            total_force(1),
            total_force(2),
            modes.volume_rows[1].clone(),
        ];
        // D enters as k D + c Ddot with D = D^n + s tau: value h phi1 gk, slope
        // h phi1 gc + h^2 phi2 gk.
        let value: [Split; 3] = std::array::from_fn(|d| {
            Split::weighted(&modes.bridge_input[d][0], &weights, |[w1, _]| w1)
        });
        let slope: [Split; 3] = std::array::from_fn(|d| {
            let [gk, gc] = &modes.bridge_input[d];
            let mut s = Split::weighted(gc, &weights, |[w1, _]| w1);
            Split::weighted(gk, &weights, |[_, w2]| w2).add_to(&mut s, 1.0);
            s
        });
        let settle: [Split; 3] =
            std::array::from_fn(|d| Split::weighted_by(&slope[d], |_| c64::new(1.0 / h, 0.0)));
        let beta = std::array::from_fn(|d| {
            let mut b = value[d].clone();
            Split::weighted_by(&settle[d], |m| ef[m] - c64::new(1.0, 0.0)).add_to(&mut b, 1.0);
            b
        });
        let hold = std::array::from_fn(|d| {
            let mut b = value[d].clone();
            settle[d].add_to(&mut b, -1.0);
            b
        });
        // Held at D, the modes settle at -gk D / lambda: the strings following the bridge.
        let follow = std::array::from_fn(|d| {
            Split::weighted_by(&modes.bridge_input[d][0], |m| -modes.lambda[m].inv())
        });
        let n_s = modes.force_row.len() as f64;
        let feed_k = std::array::from_fn(|d| n_s * spec.contact.stiffness_n_m[d]);
        let feed_c = std::array::from_fn(|d| n_s * spec.contact.damping_n_s_m[d]);
        let prefixes = Prefixes {
            h,
            lambda: &modes.lambda,
            ef: &ef,
            reads: &reads,
            settle: &settle,
            beta: &beta,
            bridge_input: &modes.bridge_input,
            feed_k,
            feed_c,
        }
        .build();
        let free = prefixes.last().expect("the prefix of every mode").settle;
        let below = 2.0 * std::f64::consts::PI * SYMPATHETIC_BELOW_HZ;
        let sympathetic = modes
            .lambda
            .iter()
            .filter(|l| l.norm() < below)
            .count()
            .div_ceil(WIDE);
        let undamped = Undamped {
            weights: &weights,
            h,
            ef: &ef,
            reads: &reads,
            settle: &settle,
            beta: &beta,
        };
        let damper = coupled_n_s_m.map(|c| DamperKey::new(&modes, &undamped, c));
        let damped = damper.as_ref().map_or(free, |dk| {
            let through = |i: usize, d: usize| -> f64 {
                (0..dk.channels)
                    .map(|j| dk.reads_to[i][j] * dk.settle[j][d])
                    .sum()
            };
            Settle {
                force: std::array::from_fn(|i| {
                    std::array::from_fn(|d| free.force[i][d] + through(1 + i, d))
                }),
                volume: std::array::from_fn(|c| {
                    std::array::from_fn(|d| free.volume[c][d] + through(SOUND_READS[c], d))
                }),
            }
        });
        let reads_of =
            |row: &Split| -> [f64; DIRECTIONS] { std::array::from_fn(|d| row.read(&settle[d])) };
        let strike_settle = modes.strike_row.iter().map(reads_of).collect();
        let strike_velocity_row: Vec<Split> = modes
            .strike_row
            .iter()
            .map(|r| Split::weighted_by(r, |m| modes.lambda[m]))
            .collect();
        let strike_velocity_settle = strike_velocity_row.iter().map(reads_of).collect();
        let contact = ContactStep::new(
            &modes,
            &strike_velocity_row,
            h,
            spec.hammer.contact_substeps(h),
        );
        let force_settle = modes
            .force_row
            .iter()
            .map(|rows| std::array::from_fn(|d| reads_of(&rows[d])))
            .collect();
        let velocity_settle = std::array::from_fn(|d| reads_of(&modes.bridge_velocity_row[d]));
        let unfollow = std::array::from_fn(|d| {
            let mut u = settle[d].clone();
            follow[d].add_to(&mut u, -1.0);
            u
        });
        let rows: [&Split; READS] = std::array::from_fn(|i| &reads[i]);
        let inputs: [&Split; DIRECTIONS] = std::array::from_fn(|d| &beta[d]);
        let ef = Split::new(&ef);
        let block = BlockCoefficients::new(&ef, &rows, &inputs);
        let energy = EnergyCoefficients::new(&settle, &unfollow, &modes.energy);
        ExactKey {
            n_strings: modes.force_row.len(),
            h,
            ef,
            contact,
            reads,
            feed_k,
            feed_c,
            settle,
            beta,
            hold,
            sympathetic,
            prefixes,
            damped,
            strike_settle,
            strike_velocity_row,
            strike_velocity_settle,
            force_settle,
            velocity_settle,
            follow,
            energy,
            block,
            damper,
            modal_felt: None,
            part_felt: None,
            hammer: spec.hammer,
            modes,
        }
    }

    /// Complex modes kept (one of each conjugate pair, and each real mode).
    pub fn n_modes(&self) -> usize {
        self.ef.len()
    }

    /// The face a voice steps with: the modal felt's while its damper is down (a key without
    /// one has one face).
    pub(crate) fn face_for(&self, damper_down: bool) -> &ExactKey {
        match (&self.modal_felt, damper_down) {
            (Some(face), true) => face,
            _ => self,
        }
    }

    /// Whether the key has a damper, coupled or modal.
    pub(crate) fn has_damper(&self) -> bool {
        self.damper.is_some() || self.modal_felt.is_some()
    }

    /// How the reads depend on `D^{n+1}` with the coupled felt down (every mode kept) or a
    /// voice keeping `chunks` chunks of its modes.
    pub(crate) fn settle_for(&self, damper_down: bool, chunks: usize) -> &Settle {
        if damper_down && self.damper.is_some() {
            &self.damped
        } else {
            &self.prefixes[chunks].settle
        }
    }

    /// Chunks of [`WIDE`] modes (the last one padded).
    pub(crate) fn chunks(&self) -> usize {
        self.prefixes.len() - 1
    }

    /// Bytes of the coefficients a voice steps with.
    pub fn bytes(&self) -> usize {
        let split = 16 * self.n_modes();
        let damper = self.damper.as_ref().map_or(0, |d| 3 * d.channels * split)
            + self.modal_felt.as_ref().map_or(0, |f| f.bytes());
        // ef, and the contact step's eh and ef; per string the strike row, drive_f, three force
        // rows; reads, settle, beta, hold, follow, the bridge velocity rows; the block's f32
        // copies and e^BLOCK; the energies' f32 shifts and weights; the energy; the stored modes
        // (a dozen rows more); each prefix's Markov taps.
        (3 + self.n_strings * 7 + READS + 4 * DIRECTIONS + 3 + 12) * split
            + (1 + READS + DIRECTIONS) * split / 2
            + split
            + 2 * DIRECTIONS * split / 2
            + split / 4
            + self.prefixes.len() * std::mem::size_of::<Taps<READS, DIRECTIONS>>()
            + 8 * self.n_modes()
            + damper
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::scaling::Scaling;
    use crate::engine::modal::solved_response;

    /// The modes' amplitudes of the state `x = (q, qdot)` in `modal`'s kept modes: each mode's
    /// left vector `[(lambda + C) q; q]` on `x` (`c` dense, row-major).
    fn amplitudes(modal: &Modal, c: &[f64], x: &[f64]) -> Vec<c64> {
        let n = modal.n;
        let cx: Vec<f64> = (0..n)
            .map(|i| (0..n).map(|j| c[i * n + j] * x[j]).sum())
            .collect();
        (0..modal.lambda.len())
            .map(|m| {
                let l = modal.lambda[m];
                (0..n)
                    .map(|i| modal.shape[(i, m)] * (l * x[i] + cx[i] + x[n + i]))
                    .sum()
            })
            .collect()
    }

    /// `Re sum_m row_m z_m e^{lambda_m t}` at `len` samples of `1 / fs`.
    fn synthesise(row: &[c64], z: &[c64], lambda: &[c64], fs: f64, len: usize) -> Vec<f64> {
        let mut y = vec![0.0; len];
        for ((r, z), l) in row.iter().zip(z).zip(lambda) {
            let (step, mut p) = ((l / fs).exp(), r * z);
            for y in y.iter_mut() {
                *y += p.re;
                p *= step;
            }
        }
        y
    }

    /// Level (dB) of each octave band from 20 Hz of `y` (Hann window).
    fn octaves_db(y: &[f64], fs: f64) -> Vec<f64> {
        let mut planner = realfft::RealFftPlanner::<f64>::new();
        let fft = planner.plan_fft_forward(y.len());
        let n = y.len() as f64;
        let mut input: Vec<f64> = y
            .iter()
            .enumerate()
            .map(|(i, v)| v * (0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / n).cos()))
            .collect();
        let mut spectrum = fft.make_output_vec();
        fft.process(&mut input, &mut spectrum).unwrap();
        (0..10)
            .map(|b| {
                let lo = 20.0 * 2f64.powi(b);
                let e: f64 = spectrum
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| (lo..2.0 * lo).contains(&(*i as f64 * fs / n)))
                    .map(|(_, x)| x.norm_sqr())
                    .sum();
                10.0 * e.max(1e-300).log10()
            })
            .collect()
    }

    /// A key of a built-in keyboard: its spec, its layout and its system.
    fn key_system(keyboard: &str, key: usize) -> (UnisonSpec, Layout, BridgeSystem) {
        let spec = Scaling::resolve(keyboard)
            .unwrap()
            .key_preset(key)
            .unwrap()
            .unison_spec();
        let layout = Layout::new(&spec);
        let system = coupled_system(&spec, &layout, &spec.bridge().unwrap().shape);
        (spec, layout, system)
    }

    #[test]
    fn every_key_solved_through_its_bridge_responds_as_its_dense_system() {
        // Every concert key and every 8th of the paper's is solved through its bridge (its
        // checks pass; none falls back to the dense solve). On some, the response from the
        // hammer's point on the first string to that string's contact force in T, from the
        // modes, against a direct solve of the dense system at each frequency: it agrees to
        // within 6e-11 (rounding in sums over ~1 000 modes); the limit is 10 times that. The
        // dense eigen-solve's modes are printed beside it for scale.
        let some = [1, 9, 23, 40, 64, 88];
        let keys = (1..=88)
            .map(|k| ("concert", k))
            .chain((1..=88).step_by(8).map(|k| ("paper", k)));
        let mut worst: f64 = 0.0;
        for (keyboard, key) in keys {
            let (spec, layout, system) = key_system(keyboard, key);
            let (k, c) = system.dense();
            let Some(modal) = system.modes(&k, &c) else {
                panic!("{keyboard} key {key} was not solved through its bridge");
            };
            if keyboard != "concert" || !some.contains(&key) {
                continue;
            }
            let dense = Modal::dense(&k, &c, layout.n).unwrap();
            let s0 = &spec.strings[0];
            let strike = layout.vector(layout.strings[0][0].clone().enumerate().map(|(j, i)| {
                (
                    i,
                    s0.mode_shape(j + 1, spec.hammer.strike_ratio * s0.speaking_length_m),
                )
            }));
            let read = system.contact(strand(0, Direction::T.index()));
            let (mut bridge, mut eigen) = (0.0f64, 0.0f64);
            for f_hz in [50.0, 200.0, 440.0, 1000.0, 3000.0] {
                let w = 2.0 * std::f64::consts::PI * f_hz;
                let truth = solved_response(&k, &c, &read, &strike, w);
                let off = |m: &Modal| (m.response(&read, &strike, w) - truth).norm() / truth.norm();
                bridge = bridge.max(off(&modal));
                eigen = eigen.max(off(&dense));
            }
            println!(
                "concert key {key} (n {}): through the bridge {bridge:.1e}, dense eigen-solve {eigen:.1e}",
                layout.n
            );
            worst = worst.max(bridge);
        }
        assert!(worst < 6e-10, "{worst:e}");
    }

    /// The modal felt ([`KeyModes::with_felt`]) against the felt in the key's decomposition
    /// (`C` with `c sum_j v_j v_j^T` on the strings, diagonalised): keys struck (a unit velocity
    /// at the striking point of every string), ringing 0.5 s, then the felt down for 0.6 s. The
    /// key's radiating source in 0.1 s windows: on the concert keyboard (its felts modal) its
    /// level within 1 dB of the exact felt's, each octave band within 30 dB of the loudest within
    /// 6 dB (A0's 40–80 Hz, where the felt passes energy between the modes that the first order
    /// leaves out, is the worst). On the paper keyboard (coupled) the 6 N s/m point pins the
    /// strings from C2 up and the first order fails: more than 3 dB off in the first 0.1 s.
    #[test]
    fn the_modal_felt_damps_as_the_felt_in_the_keys_decomposition() {
        let fs = 48_000.0;
        let len = (0.6 * fs) as usize;
        println!("key: level, modal felt re exact, per 0.1 s window (dB) | worst octave band (dB)");
        let keys = [
            ("concert", "A0", 1),
            ("concert", "C2", 16),
            ("concert", "F3", 33),
            ("concert", "C4", 40),
            ("concert", "C6", 64),
            ("paper", "C2", 16),
            ("paper", "C6", 64),
        ];
        for (keyboard, name, key) in keys {
            let (spec, layout, system) = key_system(keyboard, key);
            let (k, c) = system.dense();
            let n = layout.n;
            let free = Modal::dense(&k, &c, n).unwrap();
            let modes = KeyModes::new(&spec).unwrap();
            let felt = spec.damper.unwrap();
            let modal_felt = modes.with_felt(felt.damping_n_s_m);
            // The felt's channels as `KeyModes::new` forms them, into C.
            let s0 = &spec.strings[0];
            let mut damped_c = c.clone();
            for v in felt_vectors(&spec, &layout) {
                for i in 0..n {
                    for j in 0..n {
                        damped_c[i * n + j] += felt.damping_n_s_m * v[i] * v[j];
                    }
                }
            }
            let exact = Modal::dense(&k, &damped_c, n).unwrap();
            // Struck, rung 0.5 s: the state in the key's modes and as (q, qdot).
            let strike_x = spec.hammer.strike_ratio * s0.speaking_length_m;
            let mut x0 = vec![0.0; 2 * n];
            for (s, string) in spec.strings.iter().enumerate() {
                for (j, i) in layout.strings[s][Direction::T.index()].clone().enumerate() {
                    x0[n + i] += string.mode_shape(j + 1, strike_x);
                }
            }
            let z: Vec<c64> = amplitudes(&free, &c, &x0)
                .iter()
                .zip(&free.lambda)
                .map(|(g, l)| g * (l * 0.5).exp())
                .collect();
            let mut x = vec![0.0; 2 * n];
            for (m, &w) in free.weight.iter().enumerate() {
                for (i, x) in x.iter_mut().enumerate() {
                    let q = free.shape[(i % n, m)] * z[m];
                    *x += w * if i < n { q } else { q * free.lambda[m] }.re;
                }
            }
            let [by_v, by_q] = spec.board.radiation_weights(0);
            let source = |m: &Modal| -> Vec<c64> {
                let q = m.row(&layout.board_vector(&by_q), false);
                m.row(&layout.board_vector(&by_v), true)
                    .iter()
                    .zip(q)
                    .map(|(v, q)| v + q)
                    .collect()
            };
            let want = synthesise(
                &source(&exact),
                &amplitudes(&exact, &damped_c, &x),
                &exact.lambda,
                fs,
                len,
            );
            let got = synthesise(&source(&free), &z, &modal_felt.lambda, fs, len);
            let window = (0.1 * fs) as usize;
            let (mut levels, mut worst_level, mut worst_band) = (vec![], 0.0f64, 0.0f64);
            let mut first = None;
            for (w, g) in want.chunks(window).zip(got.chunks(window)) {
                let energy = |y: &[f64]| y.iter().map(|v| v * v).sum::<f64>();
                let level = 10.0 * (energy(g) / energy(w)).log10();
                levels.push(format!("{level:+.2}"));
                first.get_or_insert(level);
                worst_level = worst_level.max(level.abs());
                let (bw, bg) = (octaves_db(w, fs), octaves_db(g, fs));
                let loudest = bw.iter().cloned().fold(f64::MIN, f64::max);
                for (a, b) in bw.iter().zip(&bg) {
                    if *a > loudest - 30.0 {
                        worst_band = worst_band.max((a - b).abs());
                    }
                }
            }
            let fall = {
                let e = |y: &[f64]| 10.0 * y.iter().map(|v| v * v).sum::<f64>().log10();
                e(&want[..window]) - e(&want[len - window..])
            };
            println!(
                "{keyboard} {name} (falls {fall:.0} dB): {} | {worst_band:.2}",
                levels.join(" ")
            );
            assert!(fall > 20.0, "{name}: the exact felt barely acts");
            if keyboard == "concert" {
                assert!(worst_level < 1.0, "{name}: level {worst_level:.2} dB off");
                assert!(worst_band < 6.0, "{name}: an octave {worst_band:.2} dB off");
            } else {
                let first = first.unwrap_or(0.0);
                assert!(
                    first < -3.0,
                    "paper {name}: the first order holds ({first:.2} dB)"
                );
            }
        }
    }
}
