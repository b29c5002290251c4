//! Anti-aliased integer decimation from the internal rate to the output rate.
//!
//! A linear-phase FIR low-pass (Kaiser-windowed sinc) passes up to 0.417 × the output rate (20 kHz
//! at 48 kHz) and attenuates by 90 dB from the output Nyquist frequency on; only every `ratio`-th
//! output is computed (polyphase in effect). Several channels share the filter.

use std::f64::consts::PI;

/// Stopband attenuation of the anti-alias filter (dB).
pub const STOPBAND_DB: f64 = 90.0;
/// Passband edge as a fraction of the output rate.
pub const PASSBAND_EDGE: f64 = 20.0 / 48.0;

/// A multichannel FIR decimator; all memory is allocated in [`Decimator::new`].
#[derive(Debug, Clone)]
pub struct Decimator {
    ratio: usize,
    taps: Vec<f64>,
    /// Per channel, a doubled ring of the last `taps.len()` inputs, so the window is contiguous.
    history: Vec<Vec<f64>>,
    pos: usize,
    phase: usize,
}

impl Decimator {
    /// A decimator by `ratio` (1 passes samples through) for `channels` channels.
    pub fn new(ratio: usize, channels: usize) -> Self {
        let taps = if ratio <= 1 {
            vec![1.0]
        } else {
            design_lowpass(ratio)
        };
        let n = taps.len();
        Decimator {
            ratio: ratio.max(1),
            taps,
            history: vec![vec![0.0; 2 * n]; channels],
            pos: 0,
            phase: 0,
        }
    }

    /// Forget the past input (after the signal was reset).
    pub fn reset(&mut self) {
        for h in &mut self.history {
            h.fill(0.0);
        }
    }

    pub fn ratio(&self) -> usize {
        self.ratio
    }

    /// Group delay in output samples (the filter is linear-phase).
    pub fn delay_out_samples(&self) -> f64 {
        (self.taps.len() - 1) as f64 / 2.0 / self.ratio as f64
    }

    /// Push one input frame; returns true and fills `out` when an output frame is due.
    pub fn push(&mut self, input: &[f64], out: &mut [f64]) -> bool {
        let n = self.taps.len();
        for (h, &x) in self.history.iter_mut().zip(input) {
            h[self.pos] = x;
            h[self.pos + n] = x;
        }
        self.pos = (self.pos + 1) % n;
        self.phase += 1;
        if self.phase < self.ratio {
            return false;
        }
        self.phase = 0;
        // The oldest sample sits at `pos`; the taps are symmetric so their order does not matter.
        for (h, o) in self.history.iter().zip(out.iter_mut()) {
            let window = &h[self.pos..self.pos + n];
            *o = window.iter().zip(&self.taps).map(|(a, b)| a * b).sum();
        }
        true
    }
}

/// Kaiser-windowed sinc low-pass for decimation by `ratio`, unit DC gain.
fn design_lowpass(ratio: usize) -> Vec<f64> {
    let r = ratio as f64;
    let (pass, stop) = (PASSBAND_EDGE / r, 0.5 / r); // in cycles per input sample
    let cutoff = 0.5 * (pass + stop);
    let width = stop - pass;
    let a = STOPBAND_DB;
    let beta = 0.1102 * (a - 8.7);
    let mut n = ((a - 8.0) / (2.285 * 2.0 * PI * width)).ceil() as usize + 1;
    n |= 1; // odd length: integer group delay
    let m = (n - 1) as f64 / 2.0;
    let i0_beta = bessel_i0(beta);
    let mut taps: Vec<f64> = (0..n)
        .map(|k| {
            let t = k as f64 - m;
            let sinc = if t == 0.0 {
                2.0 * cutoff
            } else {
                (2.0 * PI * cutoff * t).sin() / (PI * t)
            };
            let w = bessel_i0(beta * (1.0 - (t / m).powi(2)).max(0.0).sqrt()) / i0_beta;
            sinc * w
        })
        .collect();
    let sum: f64 = taps.iter().sum();
    taps.iter_mut().for_each(|t| *t /= sum);
    taps
}

/// Modified Bessel function of the first kind, order 0 (power series).
fn bessel_i0(x: f64) -> f64 {
    let (mut sum, mut term, mut k) = (1.0, 1.0, 1.0);
    while term > 1e-17 * sum {
        term *= (x / (2.0 * k)).powi(2);
        sum += term;
        k += 1.0;
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gain_db(ratio: usize, freq_out_fraction: f64) -> f64 {
        // Steady-state amplitude (sqrt 2 × RMS) of a sine at freq (fraction of the output rate).
        let mut d = Decimator::new(ratio, 1);
        let f_in = freq_out_fraction / ratio as f64;
        let mut out = [0.0];
        let (mut sum_sq, mut count) = (0.0, 0);
        for k in 0..(40_000 * ratio) {
            let x = (2.0 * PI * f_in * k as f64).sin();
            if d.push(&[x], &mut out) && k > 2000 * ratio {
                sum_sq += out[0] * out[0];
                count += 1;
            }
        }
        10.0 * (2.0 * sum_sq / count as f64).log10()
    }

    #[test]
    fn passband_flat_and_stopband_rejected() {
        // The figures of docs/model.md: flat to 20 kHz at 48 kHz out (0.417 of the rate), −90 dB from
        // 24 kHz (half the rate) on.
        for r in [2, 3] {
            let pass = [0.01, 0.2, 0.4, 0.417].map(|f| gain_db(r, f));
            let stop = [0.5 + 1e-3, 0.55, 0.6, 0.75, 0.9].map(|f| gain_db(r, f));
            let ripple = pass.iter().fold(0f64, |m, g| m.max(g.abs()));
            let rejection = stop.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            println!("decimate by {r}: passband ripple {ripple:.4} dB, stopband at most {rejection:.1} dB");
            assert!(ripple < 0.01, "ratio {r}: passband ripple {ripple} dB");
            assert!(rejection < -90.0, "ratio {r}: stopband {rejection} dB");
        }
    }
}
