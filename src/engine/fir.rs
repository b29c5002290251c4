//! Short FIR filters fitted by least squares to a frequency response: how the output undoes what
//! sampling does to a continuous quantity (the pressure's derivative, `audio::radiate`; the exact
//! engine's shared board driven by forces linear over a step, [`super::exact`]), and the delay
//! line that applies them ([`Fir`]).

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

/// A short FIR applied sample by sample: `N` taps on the last `N` inputs. Allocation-free: safe
/// on the audio thread. Touched by the thread that owns its stage.
#[derive(Debug, Clone)]
pub struct Fir<const N: usize> {
    /// The taps, on the newest input first.
    taps: [f64; N],
    /// The last `N` inputs, newest first.
    history: [f64; N],
}

impl<const N: usize> Fir<N> {
    /// A filter of `taps` (newest input first), its past at rest.
    pub fn new(taps: [f64; N]) -> Fir<N> {
        Fir {
            taps,
            history: [0.0; N],
        }
    }

    /// The output after `x` comes in.
    pub fn push(&mut self, x: f64) -> f64 {
        self.history.copy_within(0..N - 1, 1);
        self.history[0] = x;
        self.taps
            .iter()
            .zip(&self.history)
            .map(|(t, h)| t * h)
            .sum()
    }

    /// The past set to `x` throughout, as if `x` had always come in (0: at rest).
    pub fn fill(&mut self, x: f64) {
        self.history = [x; N];
    }

    /// Whether the newest input was finite.
    pub fn is_finite(&self) -> bool {
        self.history[0].is_finite()
    }

    /// Non-finite inputs in the past set to 0, the rest kept: clearing it all would make the
    /// output jump.
    pub fn forget_non_finite(&mut self) {
        for h in &mut self.history {
            if !h.is_finite() {
                *h = 0.0;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Fir;

    /// An impulse reads the taps out in order; a constant input gives the taps' sum; a non-finite
    /// input is forgotten without touching the rest of the past.
    #[test]
    fn the_delay_line_applies_its_taps_newest_first() {
        let taps = [0.5, -0.25, 2.0];
        let mut fir = Fir::new(taps);
        let impulse: Vec<f64> = [1.0, 0.0, 0.0, 0.0].map(|x| fir.push(x)).to_vec();
        println!("impulse response {impulse:?}");
        assert_eq!(impulse, [0.5, -0.25, 2.0, 0.0]);
        fir.fill(4.0);
        assert_eq!(fir.push(4.0), 4.0 * 2.25);
        fir.push(f64::NAN);
        assert!(!fir.is_finite());
        fir.forget_non_finite();
        assert_eq!(fir.push(1.0), 0.5 + 2.0 * 4.0);
    }
}
