//! What a listener measures on a note, rendered or recorded (issue 17's table): the power in a
//! frequency band over a stretch of time, the A-weighted level, how many partials stand within a
//! range of the strongest, and the late broadband decay. Plain functions of a signal and its rate,
//! so that a render and a recording are measured alike (`scripts/recorded_grand.py` measures the
//! recorded grand the same way).

use realfft::RealFftPlanner;
use std::f64::consts::PI;

/// The power spectrum of `x[from_s..to_s]` (seconds from its start) under a Hann window, scaled so
/// that its bins add up to the stretch's mean square (Parseval with the window's power): `(bin
/// width Hz, one value per bin from 0 Hz)`.
pub fn power_spectrum(x: &[f64], fs: f64, from_s: f64, to_s: f64) -> (f64, Vec<f64>) {
    power_spectrum_with(&mut RealFftPlanner::new(), x, fs, from_s, to_s)
}

/// [`power_spectrum`] with the FFT from `planner`, which keeps each length's plan for the next
/// stretch of that length.
fn power_spectrum_with(
    planner: &mut RealFftPlanner<f64>,
    x: &[f64],
    fs: f64,
    from_s: f64,
    to_s: f64,
) -> (f64, Vec<f64>) {
    let a = ((from_s * fs).round() as usize).min(x.len());
    let b = ((to_s * fs).round() as usize).clamp(a, x.len());
    let n = b - a;
    if n < 2 {
        return (fs, vec![0.0]);
    }
    let window: Vec<f64> = (0..n)
        .map(|k| 0.5 - 0.5 * (2.0 * PI * k as f64 / n as f64).cos())
        .collect();
    let fft = planner.plan_fft_forward(n);
    let mut input: Vec<f64> = x[a..b].iter().zip(&window).map(|(v, w)| v * w).collect();
    let mut output = fft.make_output_vec();
    fft.process(&mut input, &mut output)
        .expect("buffer sizes from the plan");
    let w2: f64 = window.iter().map(|w| w * w).sum();
    let spectrum = output
        .iter()
        .enumerate()
        .map(|(k, c)| {
            // Every bin but 0 and n/2 stands for a positive and a negative frequency.
            let both = if k == 0 || 2 * k == n { 1.0 } else { 2.0 };
            both * c.norm_sqr() / (n as f64 * w2)
        })
        .collect();
    (fs / n as f64, spectrum)
}

/// Frames of the band measurements (s): short enough that a stretch is weighted evenly in time,
/// long enough for a few bins per octave above 100 Hz.
pub const FRAME_S: f64 = 0.03;

/// Mean square of `x` between `from_s` and `to_s` in the band `[lo_hz, hi_hz)`: the mean over
/// Hann frames of [`FRAME_S`] overlapping by half (Welch), so that every moment of the stretch
/// counts alike.
pub fn band_power(
    x: &[f64],
    fs: f64,
    (from_s, to_s): (f64, f64),
    (lo_hz, hi_hz): (f64, f64),
) -> f64 {
    let frames = (((to_s - from_s) / FRAME_S * 2.0).round() as usize).max(2) - 1;
    let hop = (to_s - from_s - FRAME_S) / (frames.max(2) - 1) as f64;
    let mut planner = RealFftPlanner::new();
    let total: f64 = (0..frames)
        .map(|i| {
            let a = from_s + i as f64 * hop.max(0.0);
            let (df, p) =
                power_spectrum_with(&mut planner, x, fs, a, a + FRAME_S.min(to_s - from_s));
            p.iter()
                .enumerate()
                .filter(|(k, _)| (lo_hz..hi_hz).contains(&(*k as f64 * df)))
                .map(|(_, v)| v)
                .sum::<f64>()
        })
        .sum();
    total / frames as f64
}

/// A band's level late re early (dB): issue 17's brightness rows use the 2–4 and 4–8 kHz bands at
/// 0.5–1.5 s re the first 30 ms.
pub fn band_change_db(
    x: &[f64],
    fs: f64,
    band_hz: (f64, f64),
    early_s: (f64, f64),
    late_s: (f64, f64),
) -> f64 {
    power_db(band_power(x, fs, late_s, band_hz) / band_power(x, fs, early_s, band_hz))
}

/// `10 log10 p`, floored at −300 dB.
pub fn power_db(p: f64) -> f64 {
    10.0 * p.max(1e-30).log10()
}

/// The A-weighting (IEC 61672-1) at `f_hz`, in dB (0 dB at 1 kHz).
pub fn a_weighting_db(f_hz: f64) -> f64 {
    let f2 = f_hz * f_hz;
    let ra = 12194f64.powi(2) * f2 * f2
        / ((f2 + 20.6f64.powi(2))
            * ((f2 + 107.7f64.powi(2)) * (f2 + 737.9f64.powi(2))).sqrt()
            * (f2 + 12194f64.powi(2)));
    20.0 * ra.max(1e-30).log10() + 2.0
}

/// A-weighted level of `x` between `from_s` and `to_s` (dB re a unit mean square).
pub fn a_weighted_level_db(x: &[f64], fs: f64, from_s: f64, to_s: f64) -> f64 {
    let (df, p) = power_spectrum(x, fs, from_s, to_s);
    let weighted: f64 = p
        .iter()
        .enumerate()
        .skip(1)
        .map(|(k, v)| v * 10f64.powf(a_weighting_db(k as f64 * df) / 10.0))
        .sum();
    power_db(weighted)
}

/// A spectral peak near an expected partial.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Peak {
    /// The strongest bin's power (dB).
    pub level_db: f64,
    /// The median bin's power over the same span (dB): the floor the peak stands on.
    pub floor_db: f64,
}

impl Peak {
    /// Whether it stands `margin_db` above its floor: a partial, not leakage or noise.
    pub fn stands_out(&self, margin_db: f64) -> bool {
        self.level_db >= self.floor_db + margin_db
    }
}

/// The peak of the power spectrum of `x` between `from_s` and `to_s` within `half_width_hz` of
/// each of `freqs_hz`.
pub fn peaks(
    x: &[f64],
    fs: f64,
    (from_s, to_s): (f64, f64),
    freqs_hz: &[f64],
    half_width_hz: f64,
) -> Vec<Peak> {
    let (df, p) = power_spectrum(x, fs, from_s, to_s);
    freqs_hz
        .iter()
        .map(|&f| {
            let lo = (((f - half_width_hz) / df).ceil().max(0.0) as usize).min(p.len() - 1);
            let hi = (((f + half_width_hz) / df).floor() as usize).clamp(lo, p.len() - 1);
            let mut span = p[lo..=hi].to_vec();
            span.sort_by(f64::total_cmp);
            Peak {
                level_db: power_db(span[span.len() - 1]),
                floor_db: power_db(span[span.len() / 2]),
            }
        })
        .collect()
}

/// Edges of the octave bands that describe a spectrum's shape (Hz): 0–125, 125–250, …, 4–8 kHz.
pub const OCTAVE_EDGES_HZ: [f64; 8] = [0.0, 125.0, 250.0, 500.0, 1e3, 2e3, 4e3, 8e3];

/// The power of `x` over a stretch (one Hann window) in each octave band of [`OCTAVE_EDGES_HZ`],
/// re the sum of the seven (dB): its spectrum's shape, whatever its level
/// (`scripts/recorded_dynamics.py` measures the recorded grand so).
pub fn octave_shape_db(x: &[f64], fs: f64, (from_s, to_s): (f64, f64)) -> [f64; 7] {
    let (df, p) = power_spectrum(x, fs, from_s, to_s);
    let bands: [f64; 7] = std::array::from_fn(|b| {
        let (lo, hi) = (OCTAVE_EDGES_HZ[b], OCTAVE_EDGES_HZ[b + 1]);
        p.iter()
            .enumerate()
            .filter(|(k, _)| (lo..hi).contains(&(*k as f64 * df)))
            .map(|(_, v)| v)
            .sum()
    });
    let total: f64 = bands.iter().sum();
    bands.map(|b| power_db(b / total.max(f64::MIN_POSITIVE)))
}

/// The power-weighted mean frequency of `x` over a stretch (Hz): its brightness.
pub fn spectral_centroid_hz(x: &[f64], fs: f64, (from_s, to_s): (f64, f64)) -> f64 {
    let (df, p) = power_spectrum(x, fs, from_s, to_s);
    let total: f64 = p.iter().sum();
    p.iter()
        .enumerate()
        .map(|(k, v)| k as f64 * df * v)
        .sum::<f64>()
        / total.max(f64::MIN_POSITIVE)
}

/// Late broadband decay: the T60 (s) of a straight line fitted (least squares) to the level of
/// `x`'s mean square in 50-ms windows between `from_s` and `to_s`.
pub fn late_t60_s(x: &[f64], fs: f64, from_s: f64, to_s: f64) -> f64 {
    let n = (0.05 * fs) as usize;
    let points: Vec<(f64, f64)> = x
        .chunks_exact(n)
        .enumerate()
        .map(|(i, c)| {
            let t = (i as f64 + 0.5) * n as f64 / fs;
            (t, power_db(c.iter().map(|v| v * v).sum::<f64>() / n as f64))
        })
        .filter(|(t, _)| (from_s..=to_s).contains(t))
        .collect();
    let m = points.len() as f64;
    let (st, sl) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), (t, l)| (a + t, b + l));
    let (tm, lm) = (st / m, sl / m);
    let (num, den) = points.iter().fold((0.0, 0.0), |(a, b), (t, l)| {
        (a + (t - tm) * (l - lm), b + (t - tm) * (t - tm))
    });
    -60.0 / (num / den)
}

/// The early decay of a key's first partial, at `f1_hz`, as `scripts/recorded_grand.py` measures
/// the recorded grand's: the partial's power (the bins within max(12.5 Hz, 0.003 f1), at most
/// 0.4 f1, of it) in Hann frames of 0.2 s every 0.05 s from the onset at 0; the peak of its
/// three-frame mean in the first second; the window from the peak to where that mean is 10 dB
/// down, held to 0.3–1.0 s after the peak and to the last frame; the T60 (s) of the Theil–Sen
/// slope of the frames' levels in it. `None` where the window is short of 0.2 s or four frames;
/// infinite where the partial does not decay.
pub fn early_t60_s(x: &[f64], fs: f64, f1_hz: f64) -> Option<f64> {
    const STFT_FRAME_S: f64 = 0.2;
    const STFT_HOP_S: f64 = 0.05;
    let half_hz = (0.003 * f1_hz).max(12.5).min(0.4 * f1_hz);
    let mut planner = RealFftPlanner::new();
    let frames = ((x.len() as f64 / fs - STFT_FRAME_S) / STFT_HOP_S).floor() as usize + 1;
    let (times, power): (Vec<f64>, Vec<f64>) = (0..frames)
        .map(|i| {
            let from_s = i as f64 * STFT_HOP_S;
            let (df, bins) =
                power_spectrum_with(&mut planner, x, fs, from_s, from_s + STFT_FRAME_S);
            let band = bins
                .iter()
                .enumerate()
                .filter(|(k, _)| (*k as f64 * df - f1_hz).abs() <= half_hz)
                .map(|(_, p)| p)
                .sum::<f64>();
            (from_s + 0.5 * STFT_FRAME_S, band.max(f64::MIN_POSITIVE))
        })
        .unzip();
    let level: Vec<f64> = power.iter().map(|&p| power_db(p)).collect();
    let smooth: Vec<f64> = (0..power.len())
        .map(|i| {
            let near = &power[i.saturating_sub(1)..(i + 2).min(power.len())];
            power_db(near.iter().sum::<f64>() / near.len() as f64)
        })
        .collect();
    let peak = (0..times.len())
        .filter(|&i| times[i] <= 1.0)
        .max_by(|&i, &j| smooth[i].total_cmp(&smooth[j]))?;
    let peak_s = times[peak];
    let down_s = (peak + 1..times.len())
        .find(|&i| smooth[i] <= smooth[peak] - 10.0)
        .map_or(peak_s + 1.0, |i| times[i]);
    let end_s = down_s
        .clamp(peak_s + 0.3, peak_s + 1.0)
        .min(times[times.len() - 1]);
    let window: Vec<(f64, f64)> = (peak..times.len())
        .take_while(|&i| times[i] <= end_s)
        .map(|i| (times[i], level[i]))
        .collect();
    if window.len() < 4 || end_s - peak_s < 0.2 {
        return None;
    }
    let slope_db_s = theil_sen_slope(&window);
    Some(if slope_db_s < 0.0 {
        -60.0 / slope_db_s
    } else {
        f64::INFINITY
    })
}

/// The median of the slopes between every pair of `points` (Theil–Sen): a line through a
/// beating decay that a beat's trough does not pull as a least-squares one is pulled.
fn theil_sen_slope(points: &[(f64, f64)]) -> f64 {
    let mut slopes: Vec<f64> = points
        .iter()
        .enumerate()
        .flat_map(|(i, a)| {
            points[i + 1..]
                .iter()
                .map(move |b| (b.1 - a.1) / (b.0 - a.0))
        })
        .collect();
    median(&mut slopes)
}

/// The median of `values` (sorted in place): the middle one, or the mean of the middle two;
/// NaN for none.
pub fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n == 0 {
        return f64::NAN;
    }
    0.5 * (values[(n - 1) / 2] + values[n / 2])
}

/// Level drop (dB, negative) from the 10 ms before `at_s` to the 10 ms that end `after_s` later:
/// how a damper takes a note.
pub fn level_change_db(x: &[f64], fs: f64, at_s: f64, after_s: f64) -> f64 {
    let ms = |from: f64| {
        let (a, b) = ((from * fs) as usize, ((from + 0.01) * fs) as usize);
        let b = b.min(x.len());
        let a = a.min(b);
        x[a..b].iter().map(|v| v * v).sum::<f64>() / (b - a).max(1) as f64
    };
    power_db(ms(at_s + after_s - 0.01) / ms(at_s - 0.01))
}

#[cfg(test)]
mod tests {
    use super::*;

    const FS: f64 = 48_000.0;

    fn tone(parts: &[(f64, f64, f64)], seconds: f64) -> Vec<f64> {
        (0..(seconds * FS) as usize)
            .map(|k| {
                let t = k as f64 / FS;
                parts
                    .iter()
                    .map(|&(f, a, sigma)| a * (-sigma * t).exp() * (2.0 * PI * f * t).sin())
                    .sum()
            })
            .collect()
    }

    #[test]
    fn a_band_and_its_decay_are_read_as_written() {
        // 3 kHz decaying at 2 /s (17.4 dB/s) beside a steady 500 Hz: the 2–4 kHz band at 0.5–1.5 s
        // re its first 30 ms is -17.4 dB (the band's mean square at the stretch's mean level,
        // up to the exponential's curvature).
        let x = tone(&[(500.0, 1.0, 0.0), (3000.0, 0.5, 2.0)], 2.0);
        let change = band_change_db(&x, FS, (2000.0, 4000.0), (0.0, 0.03), (0.5, 1.5));
        let expected = power_db(
            ((-4.0f64 * 0.5).exp() - (-4.0f64 * 1.5).exp())
                / 4.0
                / ((1.0 - (-4.0f64 * 0.03).exp()) / 4.0 / 0.03),
        );
        println!("2–4 kHz band at 0.5–1.5 s re 0–30 ms: {change:.2} dB (exact {expected:.2})");
        assert!((change - expected).abs() < 0.3);
        // The mean square of a sine of amplitude 1 is 1/2.
        let p = band_power(&x, FS, (0.0, 1.0), (400.0, 600.0));
        println!("500 Hz band power {p:.4} (0.5)");
        assert!((p - 0.5).abs() < 0.01);
        let t60 = late_t60_s(&tone(&[(3000.0, 1.0, 2.0)], 3.0), FS, 0.5, 2.5);
        println!("T60 of a 2 /s decay: {t60:.3} s (3.454)");
        assert!((t60 - 3.454).abs() < 0.02);
    }

    #[test]
    fn a_partials_early_decay_is_read_as_the_recordings_script_reads_it() {
        // 440 Hz decaying at 2 /s (T60 3.454 s) under a 1.2 kHz partial 20 dB louder decaying
        // three times as fast, which a broadband reading would take (1.2 s): the window runs
        // from the peak (the first frame, centred at 0.1 s) to 1.0 s after it, and the partial's
        // own T60 comes back.
        let x = tone(&[(440.0, 1.0, 2.0), (1200.0, 10.0, 6.0)], 2.0);
        let t60 = early_t60_s(&x, FS, 440.0).unwrap();
        println!("early T60 of a 2 /s decay beside a louder 6 /s one: {t60:.3} s (3.454)");
        assert!((t60 - 3.454).abs() < 0.02);
        // A steady partial does not decay; a render too short for the window gives nothing.
        assert_eq!(
            early_t60_s(&tone(&[(440.0, 1.0, 0.0)], 2.0), FS, 440.0),
            Some(f64::INFINITY)
        );
        assert_eq!(
            early_t60_s(&tone(&[(440.0, 1.0, 2.0)], 0.3), FS, 440.0),
            None
        );
    }

    #[test]
    fn a_weighting_follows_the_standard() {
        // IEC 61672-1's table: -26.2 dB at 63 Hz, -19.1 at 100 Hz, 0 at 1 kHz, -4.3 at 12.5 kHz.
        for (f, a) in [
            (100.0, -19.1),
            (1000.0, 0.0),
            (12_500.0, -4.3),
            (63.0, -26.2),
        ] {
            let w = a_weighting_db(f);
            println!("A({f} Hz) = {w:.2} dB ({a})");
            assert!((w - a).abs() < 0.1);
        }
    }
}
