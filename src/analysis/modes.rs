//! The modes of one key's linearised system — strings on their contact springs and dampers, the
//! duplex damping and the board at the key's point, hammer out of play (DESIGN.md §5): the
//! eigenvalues of the paper's dense state matrix with the contact forces folded in
//! ([`crate::engine::rk4::dense::DenseUnison::linear_system`]). Each is a partial's exact
//! frequency and decay rate, what any integrator is measured against.

use crate::engine::physics::duplex::duplex_damping_matrix;
use crate::engine::rk4::dense::DenseUnison;
use crate::engine::MAX_STRINGS;
use crate::engine::{Direction, UnisonSpec};
use faer::{c64, Mat};

/// One mode (a complex-conjugate pair of eigenvalues `-sigma ± i omega`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearMode {
    pub freq_hz: f64,
    /// `sigma` (1/s): the amplitude falls as `e^{-sigma t}`.
    pub decay_per_s: f64,
    /// Share of the mode's energy in the strings' T, L and P motion and in the board (the diagonal
    /// of the energy's quadratic form, contact springs included), and in each string.
    pub shares: [f64; 4],
    pub string_shares: [f64; MAX_STRINGS],
    /// Share of the strings' transverse kinetic energy on their duplex segments (bridge to hitch
    /// pin), where the felt of Eq. 13 acts: near 1 for a resonance of the duplex segment, small
    /// for a partial of the speaking length.
    pub duplex_share: f64,
}

impl LinearMode {
    /// Time for the energy to fall by 60 dB (s).
    pub fn t60_s(&self) -> f64 {
        6.0 * std::f64::consts::LN_10 / (2.0 * self.decay_per_s)
    }
}

/// Why the modes cannot be computed.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("the eigen-decomposition of the linearised system did not converge")]
pub struct ModesError;

/// Every oscillating mode of `spec`'s linearised system, by rising frequency.
pub fn linear_modes(spec: &UnisonSpec) -> Result<Vec<LinearMode>, ModesError> {
    let dense = DenseUnison::new(spec);
    let a = dense.linear_system();
    let nq = a.nrows() / 2;
    let (ranges, board) = dense.layout();
    // Energy per unit squared of each displacement, 1/2 K_ii (K the stiffness with the contact
    // springs, -A's lower-left block); of each velocity, 1/2.
    let stiffness: Vec<f64> = (0..nq).map(|i| -0.5 * a[(nq + i, i)]).collect();
    // The mass on each string's duplex segment in its modal coordinates, mu ∫ psi_m psi_n over
    // [L_s, L] (Eq. 13's integral; the same for T and P).
    let nd = spec.modes.modes_t.max(spec.modes.modes_p);
    let duplex_mass: Vec<Vec<f64>> = spec
        .strings
        .iter()
        .map(|s| {
            let mu = s.linear_density_kg_m;
            duplex_damping_matrix(nd, s.length_m(), s.speaking_length_m, mu, mu)
        })
        .collect();
    // Balanced as the engine's modes are (`engine::modal`): velocities in units of the highest
    // undamped frequency, so that both blocks are of one size. Unbalanced (entries from 1 to
    // omega^2), faer's QR iteration looped for ever on C3 with its modes kept to 20 kHz and no
    // duplex felt.
    let omega_s = (0..nq).map(|i| -a[(nq + i, i)]).fold(1.0, f64::max).sqrt();
    let scale = |i: usize| if i < nq { 1.0 } else { omega_s };
    let balanced = Mat::<f64>::from_fn(2 * nq, 2 * nq, |i, j| a[(i, j)] * scale(j) / scale(i));
    let eig = balanced.eigen().map_err(|_| ModesError)?;
    let s = eig.S().column_vector();
    let u = Mat::<c64>::from_fn(2 * nq, s.nrows(), |i, m| eig.U()[(i, m)] * scale(i));
    let mut modes: Vec<LinearMode> = (0..s.nrows())
        .filter(|&m| s[m].im > 0.0)
        .map(|m| {
            let energy =
                |i: usize| u[(i, m)].norm_sqr() * stiffness[i] + 0.5 * u[(nq + i, m)].norm_sqr();
            let total: f64 = (0..nq).map(energy).sum::<f64>().max(f64::MIN_POSITIVE);
            let mut shares = [0.0; 4];
            let mut string_shares = [0.0; MAX_STRINGS];
            for (st, dirs) in ranges.iter().enumerate() {
                for (d, r) in dirs.iter().enumerate() {
                    let e: f64 = r.clone().map(energy).sum::<f64>() / total;
                    shares[d] += e;
                    string_shares[st] += e;
                }
            }
            shares[3] = board.clone().map(energy).sum::<f64>() / total;
            let (mut duplex, mut transverse) = (0.0, 0.0);
            for (dirs, mass) in ranges.iter().zip(&duplex_mass) {
                for dir in [Direction::T, Direction::P] {
                    let r = dirs[dir.index()].clone();
                    let v = |i: usize| u[(nq + r.start + i, m)];
                    for i in 0..r.len() {
                        transverse += v(i).norm_sqr();
                        for j in 0..r.len() {
                            duplex += mass[i * nd + j] * (v(i).conj() * v(j)).re;
                        }
                    }
                }
            }
            LinearMode {
                freq_hz: s[m].im / (2.0 * std::f64::consts::PI),
                decay_per_s: -s[m].re,
                shares,
                string_shares,
                duplex_share: duplex / transverse.max(f64::MIN_POSITIVE),
            }
        })
        .collect();
    modes.sort_by(|a, b| a.freq_hz.total_cmp(&b.freq_hz));
    Ok(modes)
}
