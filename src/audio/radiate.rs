//! From the board to the listener (DESIGN.md §1.7): the engines read the board's radiating source
//! `Q` — its net volume velocity, or the monopole at 1 m equivalent to its modes' Rayleigh
//! integrals at a listener ([`crate::engine::physics::soundboard::SoundboardModes::radiation_weights`])
//! — and the sound pressure at distance `r` is `p = rho0 / (4 pi r) dQ/dt` ([`Monopole`]); what
//! goes out is bounded by a soft clipper. Used live ([`super::synth`]) and offline
//! (`render::strike`) alike.

use crate::engine::fir::{Fir, FIT_BAND};

/// Taps of the pressure's differentiator. With 10 (a delay of 4.5 samples) its gain is within
/// 0.02 % of `i ω` to 0.1 × the rate (5 kHz at 48 kHz), 0.24 % at 0.375 × and 0.7 % at 0.417 ×;
/// the step-to-step difference it replaced was 1.8 % under at 5 kHz and 26 % (2.6 dB) at
/// 20 kHz. With 8 taps (and the fit taking the exact engine's board source as it then was) the
/// low band's error was 0.9 %, RK4 and the exact engine 0.8 % apart on C2.
const TAPS: usize = 10;

/// The monopole: `Q` sampled at the engine's rate, differentiated by a short linear-phase FIR
/// fitted to `i ω` over the audible band.
#[derive(Debug, Clone)]
pub struct Monopole {
    /// `rho0 / (4 pi r)` (kg/m^4).
    gain: f64,
    /// The differentiator (taps in 1/s) on the sources (m^3/s).
    differentiator: Fir<TAPS>,
}

impl Monopole {
    /// Air of density `air_density_kg_m3`, a listener at `distance_m`, `Q` sampled at `rate_hz`.
    /// Designs the differentiator (allocates: not on the audio thread).
    pub fn new(air_density_kg_m3: f64, distance_m: f64, rate_hz: f64) -> Monopole {
        Monopole {
            gain: air_density_kg_m3 / (4.0 * std::f64::consts::PI * distance_m),
            differentiator: Fir::new(differentiator_taps(rate_hz)),
        }
    }

    /// The pressure (Pa) of the step that brought `Q` to `volume_velocity_m3_s`, as it was
    /// [`Monopole::delay_samples`] steps before.
    pub fn pressure_pa(&mut self, volume_velocity_m3_s: f64) -> f64 {
        self.gain * self.differentiator.push(volume_velocity_m3_s)
    }

    /// The differentiator's delay (steps): linear phase, `(TAPS - 1) / 2`.
    pub fn delay_samples(&self) -> f64 {
        (TAPS - 1) as f64 / 2.0
    }

    /// Start again from `Q` = `volume_velocity_m3_s` (after a reset, a new piano).
    pub fn restart(&mut self, volume_velocity_m3_s: f64) {
        self.differentiator.fill(volume_velocity_m3_s);
    }

    /// Whether the last `Q` was finite.
    pub fn is_finite(&self) -> bool {
        self.differentiator.is_finite()
    }
}

/// The taps (1/s) of a linear-phase FIR whose response is `i ω` delayed by `(TAPS - 1) / 2`
/// samples: least squares in relative error over the band up to `FIT_BAND` × `rate_hz`, the
/// low band weighted up to 21 times (`1 + 20 (1 - f / f_band)^4`: where the partials' energy is).
/// The problem depends on `ω h` alone, so it is as well conditioned at every rate.
fn differentiator_taps(rate_hz: f64) -> [f64; TAPS] {
    let delay = (TAPS - 1) as f64 / 2.0;
    let taps = crate::engine::fir::least_squares_fir::<TAPS>(FIT_BAND, |wh| {
        // i ω h e^{-i ω h delay}.
        (wh * (wh * delay).sin(), wh * (wh * delay).cos())
    });
    taps.map(|t| t * rate_hz)
}

/// Output level from which the soft clipper bends the signal towards ±1.
pub const KNEE: f32 = 0.8;

/// Identity below `KNEE`, then a tanh curve that reaches ±1 only asymptotically: no sample leaves
/// [-1, 1] and loud peaks are rounded rather than cut.
pub fn soft_clip(x: f32) -> f32 {
    let a = x.abs();
    if a <= KNEE {
        x
    } else {
        (KNEE + (1.0 - KNEE) * ((a - KNEE) / (1.0 - KNEE)).tanh()).copysign(x)
    }
}

#[cfg(test)]
mod tests {
    use super::{soft_clip, KNEE};

    #[test]
    fn the_soft_clipper_is_odd_increasing_continuous_and_below_one() {
        // Identity to the knee; there, continuous with slope 1 (tanh'(0) = 1).
        assert_eq!(soft_clip(0.5), 0.5);
        assert_eq!(soft_clip(KNEE), KNEE);
        let slope = (soft_clip(KNEE + 1e-4) - KNEE) / 1e-4;
        // A known value: 0.8 + 0.2 tanh(0.5) at 0.9.
        let known = soft_clip(0.9);
        println!("soft clip: slope just above the knee {slope:.4}, f(0.9) = {known:.7}, f(10) = {}, f(1e30) = {}", soft_clip(10.0), soft_clip(1e30));
        assert!((slope - 1.0).abs() < 1e-2, "slope {slope}");
        assert!((known - 0.892_423_4).abs() < 1e-6, "{known}");
        let mut last = -1.0f32;
        for i in -2000..=2000 {
            let x = i as f32 * 0.005;
            let y = soft_clip(x);
            assert_eq!(soft_clip(-x), -y, "odd at {x}");
            assert!(y >= last, "increasing at {x}");
            // In f32 the curve rounds to 1 from about 0.8 + 0.2 * 8.2 = 2.44 on.
            assert!(
                y.abs() < 1.0 || x.abs() > 2.4,
                "reaches full scale only asymptotically: {x} -> {y}"
            );
            last = y;
        }
        assert!(soft_clip(1e30) <= 1.0 && soft_clip(f32::INFINITY) <= 1.0);
    }
}
