//! A key's partials as a tuner and a listener meet them, from its linearised system's modes
//! ([`super::modes`]): each partial is the cluster of string modes (mostly transverse) near the
//! stiff string's `n`-th frequency (Eq. 2) — one per string and polarisation, split by the
//! strings' mistuning and their coupling at the bridge — with its frequency and the decay of its
//! fastest and slowest mode (the early and late decay of a coupled unison: Weinreich 1977). The
//! key's pitch is what a tuner listening to partials 2–8 hears: how far they lie, balanced, from
//! the series `f_n = n f0 sqrt(1 + B n^2)` the key should sound, so that a board mode pulling the
//! first partial alone does not move it.

use super::modes::{linear_modes, LinearMode, ModesError};
use crate::engine::tuning::{
    series_offset_cents, stiff_string_fit, stiff_string_hz, PARTIAL_WINDOW, STRING_SHARE,
};
use crate::engine::UnisonSpec;

/// Partial `n` of a key.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Partial {
    pub n: usize,
    /// The mean of its modes' frequencies weighted by their transverse share (Hz).
    pub freq_hz: f64,
    /// T60 of its fastest and its slowest mode (s).
    pub t60_min_s: f64,
    pub t60_max_s: f64,
    /// How many modes it has (strings × polarisations where they are coupled).
    pub modes: usize,
}

/// Partials `1..=count` of a string whose stiff-string frequencies are `expected_hz(n)` (Hz), found
/// among `modes`: those with no string mode near their frequency are left out (above the modes
/// the keyboard keeps, or drowned in the board).
pub fn partials(
    modes: &[LinearMode],
    expected_hz: impl Fn(usize) -> f64,
    count: usize,
) -> Vec<Partial> {
    let spacing = expected_hz(1);
    (1..=count)
        .filter_map(|n| {
            let centre = expected_hz(n);
            let near: Vec<&LinearMode> = modes
                .iter()
                .filter(|m| m.shares[0] >= STRING_SHARE)
                .filter(|m| (m.freq_hz - centre).abs() <= PARTIAL_WINDOW * spacing)
                .collect();
            if near.is_empty() {
                return None;
            }
            let weight: f64 = near.iter().map(|m| m.shares[0]).sum();
            let t60 = near.iter().map(|m| m.t60_s());
            Some(Partial {
                n,
                freq_hz: near.iter().map(|m| m.freq_hz * m.shares[0]).sum::<f64>() / weight,
                t60_min_s: t60.clone().fold(f64::INFINITY, f64::min),
                t60_max_s: t60.fold(0.0, f64::max),
                modes: near.len(),
            })
        })
        .collect()
}

/// The pitch a tuner hears from partials 2–8.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TunerPitch {
    /// The first partial of the series partials 2–8 sound on: the target moved by their balanced
    /// offset from its series ([`series_offset_cents`]) (Hz).
    pub first_partial_hz: f64,
    /// The inharmonicity `B` of the stiff-string law fitted to them ([`stiff_string_fit`]; from
    /// fewer than three partials, the given one).
    pub inharmonicity: f64,
    /// How many of partials 2–8 the pitch rests on.
    pub partials: usize,
}

/// The pitch of `partials` against the series of `target_hz` with the string's `nominal_b`
/// ([`series_offset_cents`]), and the `B` they show. `None` without any of partials 2–8.
pub fn tuner_pitch(partials: &[Partial], target_hz: f64, nominal_b: f64) -> Option<TunerPitch> {
    let found: Vec<(usize, f64)> = partials.iter().map(|p| (p.n, p.freq_hz)).collect();
    let (offset_cents, counted) = series_offset_cents(&found, target_hz, nominal_b)?;
    let inharmonicity = stiff_string_fit(&found, nominal_b).map_or(nominal_b, |f| f.1);
    Some(TunerPitch {
        first_partial_hz: target_hz * 2f64.powf(offset_cents / 1200.0),
        inharmonicity,
        partials: counted,
    })
}

/// A key's partials and the pitch a tuner hears, from its linearised system ([`linear_modes`])
/// against the stiff string with its first partial on `target_hz` (the speaking length's `B`).
#[derive(Debug, Clone, PartialEq)]
pub struct KeyPartials {
    pub target_hz: f64,
    /// Partials `1..=count` found among the modes.
    pub partials: Vec<Partial>,
    /// On partials 2–8 ([`tuner_pitch`]).
    pub pitch: Option<TunerPitch>,
}

impl KeyPartials {
    pub fn new(spec: &UnisonSpec, target_hz: f64, count: usize) -> Result<KeyPartials, ModesError> {
        Ok(KeyPartials::of_modes(
            &linear_modes(spec)?,
            spec,
            target_hz,
            count,
        ))
    }

    /// The same from `spec`'s modes, already computed.
    pub fn of_modes(
        modes: &[LinearMode],
        spec: &UnisonSpec,
        target_hz: f64,
        count: usize,
    ) -> KeyPartials {
        let b = spec.strings[0].speaking_inharmonicity();
        let partials = partials(modes, stiff_string_hz(target_hz, b), count);
        let pitch = tuner_pitch(&partials, target_hz, b);
        KeyPartials {
            target_hz,
            partials,
            pitch,
        }
    }

    pub fn partial(&self, n: usize) -> Option<&Partial> {
        self.partials.iter().find(|p| p.n == n)
    }

    /// The pitch as a tuner hears it (Hz): on partials 2–8, or on the first where none of them
    /// is among the key's modes (B7, C8).
    pub fn heard_hz(&self) -> Option<f64> {
        self.pitch
            .map(|p| p.first_partial_hz)
            .or_else(|| self.partial(1).map(|p| p.freq_hz))
    }
}

/// `f` against `target` (cents).
pub fn cents(f_hz: f64, target_hz: f64) -> f64 {
    1200.0 * (f_hz / target_hz).log2()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mode of a string at `freq_hz` with decay `decay_per_s`, `t` of its energy transverse.
    fn mode(freq_hz: f64, decay_per_s: f64, t: f64) -> LinearMode {
        LinearMode {
            freq_hz,
            decay_per_s,
            shares: [t, 0.0, 1.0 - t, 0.0],
            string_shares: [1.0, 0.0, 0.0],
            duplex_share: 0.0,
        }
    }

    #[test]
    fn the_tuner_hears_partials_2_to_8_not_a_first_partial_pulled_by_the_board() {
        // A stiff string (f0 110 Hz, B 4e-4), two strings a partial apart by 0.1 Hz, its first
        // partial pulled 30 cents sharp by a board mode, P modes and board modes between.
        let (f0, b) = (110.0, 4e-4);
        let law = |n: usize| n as f64 * f0 * (1.0 + b * (n * n) as f64).sqrt();
        let mut modes = vec![];
        for n in 1..=10 {
            let f = if n == 1 {
                law(1) * 2f64.powf(30.0 / 1200.0)
            } else {
                law(n)
            };
            modes.push(mode(f - 0.05, 0.1 * n as f64, 0.95));
            modes.push(mode(f + 0.05, 2.0 * n as f64, 0.9));
            modes.push(mode(f + 0.2, 0.3, 0.1)); // a P mode: not counted
            modes.push(mode(f + 0.4 * f0, 30.0, 0.2)); // a board mode between partials
        }
        let found = partials(&modes, law, 8);
        assert_eq!(found.len(), 8);
        assert!(found.iter().all(|p| p.modes == 2));
        let p2 = found[1];
        let expected_t60 = |sigma: f64| 3.0 * std::f64::consts::LN_10 / sigma;
        assert!((p2.t60_max_s - expected_t60(0.2)).abs() < 1e-9);
        assert!((p2.t60_min_s - expected_t60(4.0)).abs() < 1e-9);
        let pitch = tuner_pitch(&found, law(1), b).unwrap();
        let heard = cents(pitch.first_partial_hz, law(1));
        let first = cents(found[0].freq_hz, law(1));
        println!(
            "partial 1 {first:+.2} cents off (pulled), the tuner's pitch from partials 2-8 {heard:+.4} cents, B {:.3e} (true 4e-4)",
            pitch.inharmonicity
        );
        assert_eq!(pitch.partials, 7);
        assert!(heard.abs() < 0.05, "{heard}");
        assert!((pitch.inharmonicity / b - 1.0).abs() < 0.01);
        assert!((first - 30.0).abs() < 0.5);
        // From two partials the string's own B is used.
        let two = tuner_pitch(&found[..3], law(1), b).unwrap();
        assert_eq!(two.partials, 2);
        assert!(cents(two.first_partial_hz, law(1)).abs() < 0.05);
        // Against a target 5 cents sharp the key sounds 5 cents flat of it.
        let flat = tuner_pitch(&found, law(1) * 2f64.powf(5.0 / 1200.0), b).unwrap();
        assert!(cents(flat.first_partial_hz, law(1)).abs() < 0.05);
    }
}
