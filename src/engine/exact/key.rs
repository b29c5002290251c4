//! One key's coefficients for the exact engine: its coupled system (strings on their contact
//! springs, the duplex felt, its copy of the board) in complex modes, and every row and input a
//! voice reads and drives it through — the hammer (ETDRK4 weights), the other keys' board motion
//! at its bridge point (the coupling), the damper felt, the radiated volume velocity.

use super::kernels::{BlockCoefficients, Split, Taps, BLOCK, DIRECTIONS, INPUTS, READS};
use crate::engine::modal::{input_weights, Modal};
use crate::engine::physics::duplex::duplex_damping_matrix;
use crate::engine::physics::hammer::HammerParams;
use crate::engine::spec::{BuildError, Direction, UnisonSpec, MAX_STRINGS};
use faer::c64;
use std::ops::Range;

/// Damper channels of a key at most: T and P of each string.
pub(crate) const DAMPER_CHANNELS: usize = 2 * MAX_STRINGS;

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

    /// A vector over `q` from `(index, value)` entries.
    fn vector(&self, entries: impl Iterator<Item = (usize, f64)>) -> Vec<f64> {
        let mut v = vec![0.0; self.n];
        for (i, x) in entries {
            v[i] += x;
        }
        v
    }
}

/// One key's second-order system `qdd = -K q - C qdot + ...` (dense, row-major), contact
/// springs, duplex damping and the board at its point folded in.
fn coupled_system(
    spec: &UnisonSpec,
    layout: &Layout,
    point: &[Vec<f64>; 3],
) -> (Vec<f64>, Vec<f64>) {
    let n = layout.n;
    let (mut k, mut c) = (vec![0.0; n * n], vec![0.0; n * n]);
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
            let w = contact_vector(spec, layout, point, s, d);
            let nz: Vec<(usize, f64)> = w
                .iter()
                .enumerate()
                .filter(|(_, x)| **x != 0.0)
                .map(|(i, x)| (i, *x))
                .collect();
            let (kc, cc) = (spec.contact.stiffness_n_m[d], spec.contact.damping_n_s_m[d]);
            for &(i, wi) in &nz {
                for &(j, wj) in &nz {
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
    (k, c)
}

/// `w_sd`: string `s`'s end in direction `d` relative to the board under it, `psi(L_s)` on the
/// string's modes and `-phi_d` on the board's (Eq. 6, 17).
fn contact_vector(
    spec: &UnisonSpec,
    layout: &Layout,
    point: &[Vec<f64>; 3],
    s: usize,
    d: usize,
) -> Vec<f64> {
    let string = &spec.strings[s];
    layout.vector(
        layout.strings[s][d]
            .clone()
            .enumerate()
            .map(|(j, i)| (i, string.mode_shape(j + 1, string.speaking_length_m)))
            .chain(
                layout
                    .board
                    .clone()
                    .enumerate()
                    .map(|(m, i)| (i, -point[d][m])),
            ),
    )
}

/// The damper felt of a key as an implicit feedback on its strings: channel `j` is the T or P
/// motion of one string at the felt, `f_j = -c v_j`, entering over the step as a force linear in
/// time from `f_j^n` to `f_j^{n+1}` (exact for the modes, trapezoidal for the felt) and solved for
/// `f^{n+1}` from the velocities after the step — stable however stiff the felt.
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
}

/// `Re(r_i e^k g_j)` for `k < BLOCK`.
fn markov_parameters(e: &[c64], rows: &[Split; READS], inputs: &[Split; DIRECTIONS]) -> Box<Taps> {
    let mut power: Vec<c64> = vec![c64::new(1.0, 0.0); e.len()];
    let mut out = Box::new([[[0.0; BLOCK]; DIRECTIONS]; READS]);
    for k in 0..BLOCK {
        for (i, row) in rows.iter().enumerate() {
            for (j, input) in inputs.iter().enumerate() {
                out[i][j][k] = (0..e.len())
                    .map(|m| {
                        let r = c64::new(row.re[m], row.im[m]);
                        let g = c64::new(input.re[m], input.im[m]);
                        (r * power[m] * g).re
                    })
                    .sum();
            }
        }
        for (p, e) in power.iter_mut().zip(e) {
            *p *= e;
        }
    }
    out
}

/// One key's coefficients (module notes), shared by every voice that plays it.
#[derive(Debug, Clone)]
pub struct ExactKey {
    pub(crate) n_strings: usize,
    pub(crate) h: f64,
    /// Every mode's eigenvalue `lambda` (1/s), one of each conjugate pair.
    pub(crate) lambda: Vec<c64>,
    /// `e^{lambda h/2}`, `e^{lambda h}`.
    pub(crate) eh: Split,
    pub(crate) ef: Split,
    /// Per string: the striking point's displacement row, and the felt force's input through
    /// ETDRK4's `Q`, `f1`, `f2`, `f3` (Eq. 14-15 in modal coordinates).
    pub(crate) strike_row: Vec<Split>,
    pub(crate) drive_q: Vec<Split>,
    pub(crate) drive_f: Vec<[Split; 3]>,
    /// Per string and direction, the contact force's row (Eq. 6); per direction, the board's
    /// velocity at the bridge point.
    pub(crate) force_row: Vec<[Split; 3]>,
    pub(crate) bridge_velocity_row: [Split; 3],
    /// Read after every step: the board's net volume velocity, and the total contact force per
    /// direction T, L, P (the force this key puts on the shared board).
    pub(crate) reads: [Split; READS],
    /// The other keys' board displacement `D_d` at this bridge point entering over the step as
    /// `D_d + s_d tau`: inputs of `D_T, D_L, D_P, s_T, s_L, s_P` (the contact springs and dampers
    /// stretched by it, Eq. 6), and its direct part in the total contact force,
    /// `-n_s (k_d D_d + c_d s_d)`.
    pub(crate) coupling: [Split; INPUTS],
    pub(crate) feed_k: [f64; 3],
    pub(crate) feed_c: [f64; 3],
    /// Per direction, the modes' static response to a unit `D` held (a key joining a moving
    /// board starts on it, not jolted by its contact springs).
    pub(crate) follow: [Split; 3],
    /// The coupling over a block with one input per direction: the ramp's two inputs
    /// `z' = e z + g_v D_n + g_s (D_n - D_{n-1})/h` become one, `w' = e w + beta D_n`, in the
    /// shifted state `w_n = z_n + alpha D_{n-1}` with `alpha = -g_s/(h e)` and
    /// `beta = g_v + g_s/h + alpha` (the reads corrected by `-Re(r_i alpha) D_n`).
    pub(crate) block_alpha: [Split; DIRECTIONS],
    pub(crate) block_alpha_read: [[f64; DIRECTIONS]; READS],
    /// The block loops' coefficients: `e`, the reads and the inputs `beta_d`.
    pub(crate) block: BlockCoefficients,
    /// What a unit of `D_d` entering at one step adds to each read `k` steps later,
    /// `Re(r_i e^{lambda h k} beta_d)` for `k < BLOCK` (the key's Markov parameters: a block
    /// advanced freely, mode by mode, gets its coupling back by superposition).
    pub(crate) markov: Box<Taps>,
    pub(crate) damper: Option<DamperKey>,
    /// Per mode, its mechanical energy per `|z|^2` (J, cycle-averaged).
    pub(crate) energy: Vec<f64>,
    pub(crate) hammer: HammerParams,
}

impl ExactKey {
    /// Diagonalise `spec`'s key for the step `1 / spec.sample_rate_hz` and form its rows and
    /// inputs.
    pub fn new(spec: &UnisonSpec) -> Result<ExactKey, BuildError> {
        let ns = spec.strings.len();
        if ns == 0 || ns > MAX_STRINGS {
            return Err(BuildError::StringCount(ns));
        }
        let h = 1.0 / spec.sample_rate_hz;
        let point = spec
            .board
            .points
            .get(spec.bridge_point)
            .ok_or(BuildError::BridgePoint(spec.bridge_point))?
            .shape
            .clone();
        let layout = Layout::new(spec);
        let (k, c) = coupled_system(spec, &layout, &point);
        let modal = Modal::new(&k, &c, layout.n, h)?;
        let s0 = &spec.strings[0];
        let strike_x = spec.hammer.strike_ratio * s0.speaking_length_m;
        let t_modes = |s: usize, x: f64| {
            let string = &spec.strings[s];
            layout.vector(
                layout.strings[s][Direction::T.index()]
                    .clone()
                    .enumerate()
                    .map(move |(j, i)| (i, string.mode_shape(j + 1, x))),
            )
        };
        let mut strike_row = Vec::new();
        let mut drive_q = Vec::new();
        let mut drive_f = Vec::new();
        let mut force_row = Vec::new();
        for s in 0..ns {
            let psi_e = t_modes(s, strike_x);
            strike_row.push(Split::new(&modal.row(&psi_e, false)));
            let g = modal.input(&psi_e);
            drive_q.push(Split::times(&g, &modal.etd[0]));
            drive_f.push(std::array::from_fn(|w| Split::times(&g, &modal.etd[2 + w])));
            force_row.push(std::array::from_fn(|d| {
                let w = contact_vector(spec, &layout, &point, s, d);
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
            let v = layout.vector(layout.board.clone().enumerate().map(|(m, i)| (i, x[m])));
            Split::new(&modal.row(&v, true))
        };
        let total_force = |d: usize| -> Split {
            let mut t = Split::zeros(modal.keep.len());
            for row in &force_row {
                let row: &[Split; 3] = row;
                row[d].add_to(&mut t, 1.0);
            }
            t
        };
        let reads = [
            board_row(&spec.board.volume_m2_per_sqrt_kg),
            total_force(0),
            total_force(1),
            total_force(2),
        ];
        // The coupling: D_d stretches every string's contact spring and damper in direction d.
        let weights: Vec<[c64; 2]> = modal.lambda.iter().map(|&l| input_weights(l, h)).collect();
        let coupling_inputs: [[Vec<c64>; 3]; 3] = std::array::from_fn(|d| {
            let mut w = vec![0.0; layout.n];
            for s in 0..ns {
                for (x, y) in w
                    .iter_mut()
                    .zip(contact_vector(spec, &layout, &point, s, d))
                {
                    *x += y;
                }
            }
            let gk = modal.input(
                &w.iter()
                    .map(|x| x * spec.contact.stiffness_n_m[d])
                    .collect::<Vec<_>>(),
            );
            let gc = modal.input(
                &w.iter()
                    .map(|x| x * spec.contact.damping_n_s_m[d])
                    .collect::<Vec<_>>(),
            );
            // D enters as k D + c Ddot with D = D0 + s tau: value h phi1 gk, slope
            // h phi1 gc + h^2 phi2 gk.
            let value: Vec<c64> = (0..gk.len()).map(|m| weights[m][0] * gk[m]).collect();
            let slope: Vec<c64> = (0..gk.len())
                .map(|m| weights[m][0] * gc[m] + weights[m][1] * gk[m])
                .collect();
            // Held at D, the modes settle at -gk D / lambda: the strings following the bridge.
            let follow: Vec<c64> = (0..gk.len()).map(|m| -gk[m] / modal.lambda[m]).collect();
            [value, slope, follow]
        });
        let coupling = std::array::from_fn(|j| Split::new(&coupling_inputs[j % 3][j / 3]));
        let follow = std::array::from_fn(|d| Split::new(&coupling_inputs[d][2]));
        let n_s = ns as f64;
        let alpha: [Vec<c64>; DIRECTIONS] = std::array::from_fn(|d| {
            (0..modal.ef.len())
                .map(|m| -coupling_inputs[d][1][m] / (h * modal.ef[m]))
                .collect()
        });
        let beta: [Vec<c64>; DIRECTIONS] = std::array::from_fn(|d| {
            (0..modal.ef.len())
                .map(|m| coupling_inputs[d][0][m] + coupling_inputs[d][1][m] / h + alpha[d][m])
                .collect()
        });
        let block_beta = beta.map(|b| Split::new(&b));
        let block_alpha = alpha.map(|a| Split::new(&a));
        let block_alpha_read =
            std::array::from_fn(|i| std::array::from_fn(|d| reads[i].read(&block_alpha[d])));
        let markov = markov_parameters(&modal.ef, &reads, &block_beta);
        let block = BlockCoefficients::new(&Split::new(&modal.ef), &reads, &block_beta);
        let damper = spec.damper.map(|damper| {
            let x = damper.position_ratio * s0.speaking_length_m;
            let mut rows = Vec::new();
            let mut from = Vec::new();
            let mut to = Vec::new();
            for s in 0..ns {
                let string = &spec.strings[s];
                for dir in [Direction::T, Direction::P] {
                    let v = layout.vector(
                        layout.strings[s][dir.index()]
                            .clone()
                            .enumerate()
                            .map(|(j, i)| (i, string.mode_shape(j + 1, x))),
                    );
                    rows.push(Split::new(&modal.row(&v, true)));
                    let g = modal.input(&v);
                    // f linear from f0 to f1: h phi1 f0 + h phi2 (f1 - f0).
                    let f0: Vec<c64> = (0..g.len())
                        .map(|m| (weights[m][0] - weights[m][1] / h) * g[m])
                        .collect();
                    let f1: Vec<c64> = (0..g.len()).map(|m| weights[m][1] / h * g[m]).collect();
                    from.push(Split::new(&f0));
                    to.push(Split::new(&f1));
                }
            }
            let r = rows.len();
            let cf = damper.damping_n_s_m;
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
            DamperKey {
                channels: r,
                rows,
                from,
                to,
                rows_from,
                solve,
                reads_from,
                reads_to,
            }
        });
        let mut energy = modal.energy(&k);
        energy.truncate(modal.keep.len());
        Ok(ExactKey {
            n_strings: ns,
            h,
            lambda: modal.lambda.clone(),
            eh: Split::new(&modal.eh),
            ef: Split::new(&modal.ef),
            strike_row,
            drive_q,
            drive_f,
            force_row,
            bridge_velocity_row: std::array::from_fn(|d| board_row(&point[d])),
            reads,
            coupling,
            feed_k: std::array::from_fn(|d| n_s * spec.contact.stiffness_n_m[d]),
            feed_c: std::array::from_fn(|d| n_s * spec.contact.damping_n_s_m[d]),
            follow,
            block,
            block_alpha,
            block_alpha_read,
            markov,
            damper,
            energy,
            hammer: spec.hammer,
        })
    }

    /// Complex modes kept (one of each conjugate pair, and each real mode).
    pub fn n_modes(&self) -> usize {
        self.ef.len()
    }

    /// Bytes of the coefficients.
    pub fn bytes(&self) -> usize {
        let split = |s: &Split| 16 * s.len();
        let n = self.n_modes();
        let damper = self.damper.as_ref().map_or(0, |d| 3 * d.channels * 16 * n);
        (2 + self.n_strings * (1 + 1 + 3 + 3) + 3 + READS + INPUTS + 3 + DIRECTIONS + 1)
            * split(&self.ef)
            + (1 + READS + DIRECTIONS) * split(&self.ef) / 2
            + 8 * BLOCK * READS * DIRECTIONS
            + 8 * n
            + damper
    }
}
