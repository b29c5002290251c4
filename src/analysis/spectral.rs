//! Spectral measurements: precise partial frequencies, band envelopes, spectrograms, and the
//! metrics the paper's findings are tested with.

use realfft::RealFftPlanner;
use std::f64::consts::PI;

/// Magnitude of the Hann-windowed DTFT of `x` (sampled at `fs`) at frequency `f_hz`.
pub fn dtft_magnitude(x: &[f64], fs: f64, f_hz: f64) -> f64 {
    windowed_dtft_magnitude(&hann_windowed(x), fs, f_hz)
}

/// `x` under a Hann window of its length.
fn hann_windowed(x: &[f64]) -> Vec<f64> {
    let n = x.len();
    x.iter()
        .enumerate()
        .map(|(k, &xk)| xk * (0.5 - 0.5 * (2.0 * PI * k as f64 / n as f64).cos()))
        .collect()
}

/// [`dtft_magnitude`] of a signal already under its Hann window (`xw`, from [`hann_windowed`]):
/// a search over frequencies windows it once.
fn windowed_dtft_magnitude(xw: &[f64], fs: f64, f_hz: f64) -> f64 {
    let n = xw.len();
    let w = 2.0 * PI * f_hz / fs;
    // Rotating phasor with periodic renormalisation keeps this O(n) without trig per sample.
    let (mut re, mut im) = (0.0, 0.0);
    let (c, s) = (w.cos(), w.sin());
    let (mut pr, mut pi) = (1.0, 0.0);
    for (k, &xwk) in xw.iter().enumerate() {
        re += xwk * pr;
        im -= xwk * pi;
        let npr = pr * c - pi * s;
        pi = pr * s + pi * c;
        pr = npr;
        if k % 1024 == 1023 {
            let norm = (pr * pr + pi * pi).sqrt();
            pr /= norm;
            pi /= norm;
        }
    }
    2.0 * (re * re + im * im).sqrt() / (0.5 * n as f64)
}

/// Frequency of the spectral peak of `x` within `[lo_hz, hi_hz]`: a coarse grid, then golden-section
/// refinement of the Hann-windowed DTFT maximum (exact for an isolated, exponentially decaying
/// sinusoid, whose magnitude spectrum is symmetric about its frequency).
pub fn peak_frequency(x: &[f64], fs: f64, lo_hz: f64, hi_hz: f64) -> f64 {
    let duration = x.len() as f64 / fs;
    let xw = hann_windowed(x);
    let step = 0.25 / duration;
    let mut best = (lo_hz, 0.0);
    let mut f = lo_hz;
    while f <= hi_hz {
        let m = windowed_dtft_magnitude(&xw, fs, f);
        if m > best.1 {
            best = (f, m);
        }
        f += step;
    }
    let (mut a, mut b) = ((best.0 - step).max(lo_hz), (best.0 + step).min(hi_hz));
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut mc, mut md) = (
        windowed_dtft_magnitude(&xw, fs, c),
        windowed_dtft_magnitude(&xw, fs, d),
    );
    while b - a > 1e-7 * best.0.max(1.0) {
        if mc > md {
            b = d;
            d = c;
            md = mc;
            c = b - g * (b - a);
            mc = windowed_dtft_magnitude(&xw, fs, c);
        } else {
            a = c;
            c = d;
            mc = md;
            d = a + g * (b - a);
            md = windowed_dtft_magnitude(&xw, fs, d);
        }
    }
    0.5 * (a + b)
}

/// Amplitude envelope of the partial at `f_hz`: Hann-windowed DTFT magnitude over frames of
/// `frame_s` every `hop_s`. Returns `(frame centre times, amplitudes)`.
pub fn partial_envelope(
    x: &[f64],
    fs: f64,
    f_hz: f64,
    frame_s: f64,
    hop_s: f64,
) -> (Vec<f64>, Vec<f64>) {
    let n = (frame_s * fs) as usize;
    let hop = ((hop_s * fs) as usize).max(1);
    let mut times = Vec::new();
    let mut amps = Vec::new();
    let mut start = 0;
    while start + n <= x.len() {
        times.push((start as f64 + n as f64 / 2.0) / fs);
        amps.push(dtft_magnitude(&x[start..start + n], fs, f_hz));
        start += hop;
    }
    (times, amps)
}

/// RMS of `x` over consecutive windows of `window_s`: `(window centre times, rms)`.
pub fn rms_envelope(x: &[f64], fs: f64, window_s: f64) -> (Vec<f64>, Vec<f64>) {
    let n = ((window_s * fs) as usize).max(1);
    x.chunks_exact(n)
        .enumerate()
        .map(|(i, c)| {
            let t = (i as f64 + 0.5) * n as f64 / fs;
            (t, (c.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt())
        })
        .unzip()
}

/// How much a decaying envelope beats: the RMS deviation (dB) of its level from a least-squares
/// cubic in time. A smooth one- or two-stage decay is followed by the cubic; beating, whose level
/// repeatedly falls and rises, is not.
pub fn beating_depth_db(times: &[f64], amps: &[f64]) -> f64 {
    let db: Vec<f64> = amps.iter().map(|a| 20.0 * a.max(1e-30).log10()).collect();
    let fit = polyfit(times, &db, 3);
    let resid: f64 = times
        .iter()
        .zip(&db)
        .map(|(&t, &y)| {
            let p = fit.iter().rev().fold(0.0, |acc, c| acc * t + c);
            (y - p).powi(2)
        })
        .sum();
    (resid / times.len() as f64).sqrt()
}

/// Least-squares polynomial fit of degree `deg`; coefficients from the constant term up.
fn polyfit(x: &[f64], y: &[f64], deg: usize) -> Vec<f64> {
    let m = deg + 1;
    // Normal equations on a centred, scaled abscissa are well enough conditioned for deg ≤ 3.
    let (x0, sx) = {
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let span = x
            .iter()
            .fold(0f64, |a, &v| a.max((v - mean).abs()))
            .max(1e-12);
        (mean, span)
    };
    let mut a = vec![vec![0.0; m + 1]; m];
    for (&xi, &yi) in x.iter().zip(y) {
        let t = (xi - x0) / sx;
        let pw: Vec<f64> = (0..m).map(|k| t.powi(k as i32)).collect();
        for r in 0..m {
            for c in 0..m {
                a[r][c] += pw[r] * pw[c];
            }
            a[r][m] += pw[r] * yi;
        }
    }
    // Gauss–Jordan with partial pivoting.
    for col in 0..m {
        let piv = (col..m)
            .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
            .unwrap_or(col);
        a.swap(col, piv);
        for r in 0..m {
            if r != col {
                let f = a[r][col] / a[col][col];
                for c in col..=m {
                    a[r][c] -= f * a[col][c];
                }
            }
        }
    }
    let scaled: Vec<f64> = (0..m).map(|r| a[r][m] / a[r][r]).collect();
    // Back to the unscaled abscissa: p(x) = sum c_k ((x - x0)/sx)^k.
    let mut coeffs = vec![0.0; m];
    for (k, &ck) in scaled.iter().enumerate() {
        // Expand ((x - x0)/sx)^k with the binomial theorem.
        for j in 0..=k {
            let binom = (0..j).fold(1.0, |b, i| b * (k - i) as f64 / (i + 1) as f64);
            coeffs[j] += ck * binom * (-x0).powi((k - j) as i32) / sx.powi(k as i32);
        }
    }
    coeffs
}

/// Magnitude spectrogram (dB re 1) with a Hann window of `n_fft` samples every `hop` samples, up to
/// `f_max_hz`. Returns `(frame times s, bin frequencies Hz, rows[frame][bin])`.
pub fn spectrogram(
    x: &[f64],
    fs: f64,
    n_fft: usize,
    hop: usize,
    f_max_hz: f64,
) -> (Vec<f64>, Vec<f64>, Vec<Vec<f64>>) {
    let mut planner = RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(n_fft);
    let mut input = fft.make_input_vec();
    let mut output = fft.make_output_vec();
    let window: Vec<f64> = (0..n_fft)
        .map(|k| 0.5 - 0.5 * (2.0 * PI * k as f64 / n_fft as f64).cos())
        .collect();
    let n_bins = ((f_max_hz / fs * n_fft as f64) as usize + 1).min(n_fft / 2 + 1);
    let freqs: Vec<f64> = (0..n_bins).map(|b| b as f64 * fs / n_fft as f64).collect();
    let (mut times, mut rows) = (Vec::new(), Vec::new());
    let mut start = 0;
    while start + n_fft <= x.len() {
        for k in 0..n_fft {
            input[k] = x[start + k] * window[k];
        }
        fft.process(&mut input, &mut output)
            .expect("buffer sizes from the plan");
        rows.push(
            output[..n_bins]
                .iter()
                .map(|c| 20.0 * (2.0 * c.norm() / (0.5 * n_fft as f64)).max(1e-12).log10())
                .collect(),
        );
        times.push((start + n_fft / 2) as f64 / fs);
        start += hop;
    }
    (times, freqs, rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peak_frequency_of_a_damped_sine() {
        let fs = 48000.0;
        let f = 523.2511;
        let x: Vec<f64> = (0..48000)
            .map(|k| {
                let t = k as f64 / fs;
                (-1.5 * t).exp() * (2.0 * PI * f * t + 0.3).sin()
            })
            .collect();
        let est = peak_frequency(&x, fs, 500.0, 550.0);
        let cents = 1200.0 * (est / f).log2();
        assert!(cents.abs() < 0.01, "estimate {est} ({cents} cents)");
        let amp = dtft_magnitude(&x[..4800], fs, f);
        assert!((amp - 0.93).abs() < 0.05, "amplitude {amp}");
    }

    #[test]
    fn beating_depth_separates_beats_from_smooth_decay() {
        let t: Vec<f64> = (0..200).map(|k| k as f64 * 0.02).collect();
        let smooth: Vec<f64> = t
            .iter()
            .map(|&t| (-2.0 * t).exp() + 0.1 * (-0.3 * t).exp())
            .collect();
        let beating: Vec<f64> = t
            .iter()
            .map(|&t| (-0.5 * t).exp() * (1.0 + 0.8 * (2.0 * PI * 1.3 * t).cos()).abs())
            .collect();
        let (s, b) = (
            beating_depth_db(&t, &smooth),
            beating_depth_db(&t, &beating),
        );
        assert!(s < 0.5 && b > 3.0, "smooth {s} dB, beating {b} dB");
    }
}
