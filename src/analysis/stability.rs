//! Stability as a computed property: the linear one-step map of a voice pool (no hammer in
//! contact, dampers as they are) formed column by column from the engine's own step, and its
//! eigenvalues. A pool is stable when the spectral radius of that map is at most 1.

use crate::engine::{LinearState, VoicePool};
use faer::Mat;

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
    let mut out = [0.0];
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
pub fn step_eigenvalues(map: &Mat<f64>, state: &LinearState, h: f64) -> Vec<StepEigen> {
    let eig = map
        .eigen()
        .expect("eigen-decomposition of the one-step map");
    let (u, s) = (eig.U(), eig.S().column_vector());
    let mut out: Vec<StepEigen> = (0..s.nrows())
        .map(|m| {
            let mu = s[m];
            let modulus = mu.norm();
            // Share of the eigenvector's energy per owner (the energy's diagonal).
            let mut shares: Vec<(Option<usize>, f64)> = Vec::new();
            let mut total = 0.0;
            for (i, &o) in state.owner.iter().enumerate() {
                let w = u[(i, m)].norm_sqr() * state.energy_weight[i];
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
