//! Stability as a computed property: the linear one-step map of a voice pool (no hammer in
//! contact, dampers as they are) formed column by column from the engine's own step, and its
//! eigenvalues. A pool is stable when the spectral radius of that map is at most 1.

use crate::engine::{LinearState, VoicePool};
use faer::{c64, Mat};

/// One eigenvalue of a one-step map, where it lives and what it means.
#[derive(Debug, Clone, Copy)]
pub struct StepEigen {
    /// `|mu|`: above 1 the mode grows by that factor every step.
    pub modulus: f64,
    /// The mode's frequency, `arg(mu) / (2 pi h)` (Hz, 0 to half the step rate).
    pub freq_hz: f64,
    /// Growth (positive) or decay rate, `ln|mu| / h` (1/s).
    pub rate_per_s: f64,
    /// The voice whose state holds most of the eigenvector's energy (`None`: the board), and
    /// that share.
    pub owner: Option<usize>,
    pub share: f64,
}

/// The map `x -> step(x)` of `pool`'s linear state ([`VoicePool::linear_state`]), one column per
/// unit state; the pool itself is left untouched. Every hammer must be out of contact.
pub fn one_step_map<E: VoicePool>(pool: &E) -> (Mat<f64>, LinearState) {
    let state = pool.linear_state();
    let n = state.x.len();
    let mut probe = pool.clone();
    let mut map = Mat::<f64>::zeros(n, n);
    let mut unit = vec![0.0; n];
    let mut out = [[0.0; 2]];
    for j in 0..n {
        unit[j] = 1.0;
        probe.set_linear_state(&unit);
        unit[j] = 0.0;
        probe.run(&mut out, None);
        let y = probe.linear_state().x;
        assert_eq!(y.len(), n, "the set of active voices changed during a step");
        for (i, y) in y.into_iter().enumerate() {
            map[(i, j)] = y;
        }
    }
    (map, state)
}

/// The eigenvalues of the one-step map `map` (step `h`), largest modulus first, each with the
/// owner of most of its eigenvector.
/// The map is balanced in place first ([`balance`]).
pub fn step_eigenvalues(map: Mat<f64>, state: &LinearState, h: f64) -> Vec<StepEigen> {
    let (balanced, scale) = balance(map);
    let eig = balanced
        .eigen()
        .expect("eigen-decomposition of the one-step map");
    drop(balanced);
    let (u, s) = (eig.U(), eig.S().column_vector());
    let mut out: Vec<StepEigen> = (0..s.nrows())
        .map(|m| {
            let mu = s[m];
            let modulus = mu.norm();
            // Share of the eigenvector's energy per owner (the energy's diagonal).
            let mut shares: Vec<(Option<usize>, f64)> = Vec::new();
            let mut total = 0.0;
            for (i, &o) in state.owner.iter().enumerate() {
                // The map's eigenvector: the balanced map's, scaled back.
                let w = (u[(i, m)] * scale[i]).norm_sqr() * state.energy_weight[i];
                total += w;
                match shares.iter_mut().find(|(k, _)| *k == o) {
                    Some((_, s)) => *s += w,
                    None => shares.push((o, w)),
                }
            }
            let (owner, share) = shares
                .into_iter()
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap_or((None, 0.0));
            StepEigen {
                modulus,
                freq_hz: mu.im.atan2(mu.re).abs() / (2.0 * std::f64::consts::PI * h),
                rate_per_s: modulus.ln() / h,
                owner,
                share: share / total.max(f64::MIN_POSITIVE),
            }
        })
        .collect();
    out.sort_by(|a, b| b.modulus.total_cmp(&a.modulus));
    out
}

/// The eigenvalues of a one-step map, balanced first ([`balance`]).
pub fn map_eigenvalues(map: Mat<f64>) -> Vec<c64> {
    balance(map)
        .0
        .eigenvalues()
        .expect("eigen-decomposition of the one-step map")
}

/// `D^-1 A D` with a diagonal `D` of powers of two that brings each row and column of `A` to
/// comparable norms (Parlett & Reinsch 1969, LAPACK's `gebal` without permutations), and `D`.
/// The eigenvalues are the same, computed more accurately, and faer's QR iteration converges on
/// maps it did not (the exact engine's, whose state mixes modal amplitudes with forces and board
/// displacements: an unbalanced map of one key stalled in its deflation for minutes).
pub fn balance(a: Mat<f64>) -> (Mat<f64>, Vec<f64>) {
    let n = a.nrows();
    let mut b = a;
    let mut d = vec![1.0; n];
    let mut converged = false;
    while !converged {
        converged = true;
        for i in 0..n {
            let (mut c, mut r) = (0.0, 0.0);
            for j in (0..n).filter(|&j| j != i) {
                c += b[(j, i)].abs();
                r += b[(i, j)].abs();
            }
            if c == 0.0 || r == 0.0 {
                continue;
            }
            let (mut f, total) = (1.0, c + r);
            while c < r / 2.0 {
                (c, r, f) = (c * 2.0, r / 2.0, f * 2.0);
            }
            while c >= r * 2.0 {
                (c, r, f) = (c / 2.0, r * 2.0, f / 2.0);
            }
            if c + r < 0.95 * total {
                converged = false;
                d[i] *= f;
                for j in 0..n {
                    b[(i, j)] /= f;
                    b[(j, i)] *= f;
                }
            }
        }
    }
    (b, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn balancing_keeps_the_eigenvalues_and_evens_the_norms() {
        // A companion-like map with eigenvalues 0.5, 0.9 ± 0.1i, badly scaled by diag(1, 1e6, 1e-6).
        let core = [[2.3, -1.72, 0.41], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let s = [1.0, 1e6, 1e-6];
        let a = Mat::<f64>::from_fn(3, 3, |i, j| core[i][j] * s[j] / s[i]);
        let (b, d) = balance(a.clone());
        let mut want: Vec<c64> = vec![c64::new(0.5, 0.0), c64::new(0.9, 0.1), c64::new(0.9, -0.1)];
        let mut got = map_eigenvalues(a);
        let key = |z: &c64| (z.re * 1e6).round() as i64 * 10 + z.im.signum() as i64;
        want.sort_by_key(key);
        got.sort_by_key(key);
        let worst = want
            .iter()
            .zip(&got)
            .map(|(w, g)| (w - g).norm())
            .fold(0.0, f64::max);
        // Off-diagonal row and column norms of the balanced map within a factor of 4.
        let spread = (0..3)
            .map(|i| {
                let (c, r) = (0..3).filter(|&j| j != i).fold((0.0, 0.0), |(c, r), j| {
                    (c + b[(j, i)].abs(), r + b[(i, j)].abs())
                });
                (c / r).max(r / c)
            })
            .fold(0.0, f64::max);
        println!(
            "balanced: scale {d:?}, eigenvalues within {worst:.1e}, row/column ratio {spread:.2}"
        );
        assert!(worst < 1e-12, "{worst:e}");
        assert!(spread < 4.0, "{spread}");
    }
}
