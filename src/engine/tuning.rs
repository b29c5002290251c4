//! Tuning: the first partial of a string on its bridge, from the undamped linear system.
//!
//! Without damping, string T modes, contact spring and board T modes form a symmetric system
//! (Eq. 2, 5, 6 with mass-normalised modes, `M = I`):
//! ```text
//! K = [ Omega_s^2 + k psi psi^T      -k psi phi_T^T           ]
//!     [ -k phi_T psi^T               Omega_b^2 + k phi_T phi_T^T ]
//! ```
//! Its eigenvalues are the coupled frequencies. The truncated string mode set (a Ritz basis) puts
//! the first partial above the speaking length's fundamental, by tens of cents when few modes are
//! kept; the spring and the board's reactance move it further. Tuning against this system puts the
//! struck note on pitch.

use crate::engine::physics::soundboard::{BridgePoint, SoundboardModes};
use crate::engine::physics::string::StringParams;
use faer::{Mat, Side};
use std::f64::consts::PI;

/// The coupled partial (Hz) nearest in character to the string's first partial: of the
/// eigenvalues within a semitone of `near_hz`, the one whose mode has the largest share of its
/// motion in the string. `board` is `None` for a rigid bridge.
pub fn bridged_first_partial_hz(
    string: &StringParams,
    modes: usize,
    contact_n_m: f64,
    board: Option<(&SoundboardModes, &BridgePoint)>,
    near_hz: f64,
) -> f64 {
    let ls = string.speaking_length_m;
    let psi: Vec<f64> = (1..=modes).map(|n| string.mode_shape(n, ls)).collect();
    let (nb, phi, wb2): (usize, &[f64], Vec<f64>) = match board {
        Some((b, p)) => (
            b.len(),
            &p.shape[0],
            b.freq_hz.iter().map(|f| (2.0 * PI * f).powi(2)).collect(),
        ),
        None => (0, &[], vec![]),
    };
    let n = modes + nb;
    // Coupling vector g: the spring's stretch is g^T q.
    let g: Vec<f64> = psi.iter().copied().chain(phi.iter().map(|x| -x)).collect();
    let k = Mat::<f64>::from_fn(n, n, |i, j| {
        let diag = match (i == j, i < modes) {
            (true, true) => string.transverse_omega(i + 1).powi(2),
            (true, false) => wb2[i - modes],
            _ => 0.0,
        };
        diag + contact_n_m * g[i] * g[j]
    });
    let evd = k
        .self_adjoint_eigen(Side::Lower)
        .expect("a real symmetric matrix has real eigenvalues");
    let (vals, vecs) = (evd.S().column_vector(), evd.U());
    let band = 2f64.powf(1.0 / 12.0);
    (0..n)
        .map(|m| (vals[m].max(0.0).sqrt() / (2.0 * PI), m))
        .filter(|(f, _)| *f > near_hz / band && *f < near_hz * band)
        .max_by(|a, b| {
            let share = |m: usize| (0..modes).map(|i| vecs[(i, m)].powi(2)).sum::<f64>();
            share(a.1).total_cmp(&share(b.1))
        })
        .map(|(f, _)| f)
        .unwrap_or(near_hz)
}
