//! Short FIR filters fitted by least squares to a frequency response: how the output undoes what
//! sampling does to a continuous quantity (the pressure's derivative, `audio::radiate`; the exact
//! engine's shared board driven by forces linear over a step, [`super::exact`]).

use faer::linalg::solvers::SolveLstsq;

/// The band the corrections are fitted over, as a fraction of the rate: 20 kHz at 48 kHz (the
/// decimator's passband, `audio::decimate`).
pub const FIT_BAND: f64 = 20.0 / 48.0;

/// Frequencies the fit is taken at, evenly from `band / POINTS` to `band` (× the rate).
const POINTS: usize = 400;

/// The `N` real taps `c_k` whose response `sum_k c_k e^{-i k ω h}` best meets `target(ω h)` (its
/// real and imaginary parts) in relative error over `ω h` up to `2 π band`, the low band weighted
/// up to 21 times (`1 + 20 (1 - f / f_band)^4`: where the partials' energy is). The problem
/// depends on `ω h` alone, so it is as well conditioned at every rate. Allocates (not on the
/// audio thread).
pub fn least_squares_fir<const N: usize>(
    band: f64,
    target: impl Fn(f64) -> (f64, f64),
) -> [f64; N] {
    let mut a = faer::Mat::<f64>::zeros(2 * POINTS, N);
    let mut b = faer::Mat::<f64>::zeros(2 * POINTS, 1);
    for i in 0..POINTS {
        let u = (i + 1) as f64 / POINTS as f64;
        let wh = 2.0 * std::f64::consts::PI * band * u;
        let (re, im) = target(wh);
        let weight = (1.0 + 20.0 * (1.0 - u).powi(4)) / re.hypot(im);
        // Row `i` the real part, `POINTS + i` the imaginary.
        for k in 0..N {
            let phase = wh * k as f64;
            a[(i, k)] = weight * phase.cos();
            a[(POINTS + i, k)] = -weight * phase.sin();
        }
        b[(i, 0)] = weight * re;
        b[(POINTS + i, 0)] = weight * im;
    }
    let x = a.qr().solve_lstsq(&b);
    std::array::from_fn(|k| x[(k, 0)])
}
