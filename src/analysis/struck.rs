//! A key struck and recorded at the listener, measured as issue 17's table measures a recorded
//! grand ([`super::listening`]; the recorded figures are in `docs/data/recorded_grand.csv`, from
//! `scripts/recorded_grand.py`): its A-weighted level, how its upper bands fade, how many partials
//! it sounds, its fundamental against its second partial, the board's low boom and how fast its
//! fundamental falls at first.

use super::listening::{
    a_weighted_level_db, band_change_db, band_power, early_t60_s, octave_shape_db, peaks, power_db,
    spectral_centroid_hz,
};
use super::recorded::{recorded_layer, RecordedLayer};
use super::spectral::peak_frequency;
use crate::config::preset::LoadedPreset;
use crate::engine::tuning::stiff_string_hz;
use crate::engine::{BuildError, Integrator, Strike};
use crate::midi::hammer_speed_m_s;
use crate::render::{simulate_with, Recording};

/// The two upper bands whose fade issue 17 measures (Hz), at [`LATE_S`] re [`ATTACK_S`].
pub const UPPER_BANDS_HZ: [(f64, f64); 2] = [(2000.0, 4000.0), (4000.0, 8000.0)];
pub const ATTACK_S: (f64, f64) = (0.0, 0.03);
pub const LATE_S: (f64, f64) = (0.5, 1.5);
/// The stretch whose level and spectrum are taken (s).
pub const ONSET_S: (f64, f64) = (0.0, 0.5);
/// The board's low boom: the band and the stretch.
pub const BOOM_HZ: (f64, f64) = (40.0, 90.0);
/// Partials counted when they stand within this many dB of the strongest (first 0.5 s) and at
/// least [`PARTIAL_MARGIN_DB`] above the median of their search span (as the recorded grand's are
/// counted).
pub const PARTIAL_RANGE_DB: f64 = 60.0;
pub const PARTIAL_MARGIN_DB: f64 = 6.0;

/// The keys whose touch the dynamics rows measure (C2, F#3, C4, A4, C6: recorded at every
/// velocity layer), and the velocities of pp and ff.
pub const TOUCH_KEYS: [usize; 5] = [16, 34, 40, 49, 64];
/// The recorded keys from C5 to C8 (every third key, recorded at every velocity layer), on which
/// the treble's touch is read: how much louder ff is than pp. From C7 up the first partial lies in
/// the 2–4 kHz band or above it, and the level's rise is what tells a soft blow from a hard one.
pub const TREBLE_TOUCH_KEYS: [usize; 13] = [52, 55, 58, 61, 64, 67, 70, 73, 76, 79, 82, 85, 88];
pub const PP_VELOCITY: u8 = 30;
pub const FF_VELOCITY: u8 = 127;

/// The recorded grand's layers for [`PP_VELOCITY`] and [`FF_VELOCITY`] at `key`, where it has the
/// key (`docs/data/recorded_dynamics.csv`).
pub fn recorded_pp_and_ff(key: usize) -> Option<[RecordedLayer; 2]> {
    Some([
        recorded_layer(key, PP_VELOCITY)?,
        recorded_layer(key, FF_VELOCITY)?,
    ])
}

/// Where a struck key is heard.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Hearing {
    /// In mono, at `radiation.listener` (a measuring microphone), the stereo pair set aside.
    Listener,
    /// By the stereo pair, its two channels mixed to mono (their mean), as the recorded grand's
    /// files are measured (`scripts/recorded_dynamics.py`); the listener where there is no pair.
    PairMix,
}

/// The sound pressure (Pa) at the listener of `preset`'s key struck at `velocity_m_s` on the exact
/// engine at the output rate, for `seconds`, the key released after `release_s` (`None`: held),
/// heard in mono at `radiation.listener` ([`Hearing::Listener`]).
pub fn pressure(
    preset: &LoadedPreset,
    velocity_m_s: f64,
    seconds: f64,
    release_s: Option<f64>,
) -> Result<(f64, Vec<f64>), BuildError> {
    pressure_heard(preset, velocity_m_s, seconds, release_s, Hearing::Listener)
}

/// [`pressure`] heard as `hearing` says.
pub fn pressure_heard(
    preset: &LoadedPreset,
    velocity_m_s: f64,
    seconds: f64,
    release_s: Option<f64>,
    hearing: Hearing,
) -> Result<(f64, Vec<f64>), BuildError> {
    let rec = record(preset, velocity_m_s, seconds, release_s, hearing)?;
    Ok((rec.rate_hz, heard(&rec, hearing)))
}

/// `preset`'s key struck at `velocity_m_s` on the exact engine at the output rate, recorded for
/// `seconds` (the key released after `release_s`), mono at `radiation.listener` when `hearing`
/// is [`Hearing::Listener`].
fn record(
    preset: &LoadedPreset,
    velocity_m_s: f64,
    seconds: f64,
    release_s: Option<f64>,
    hearing: Hearing,
) -> Result<Recording, BuildError> {
    let strike = Strike {
        velocity_m_s,
        shift: 0.0,
    };
    let mut preset = preset.clone();
    if hearing == Hearing::Listener {
        preset.make_mono();
    }
    simulate_with(
        &preset,
        Integrator::Exact,
        strike,
        release_s,
        seconds,
        |_| {},
    )
}

/// The pressure (Pa) of `rec` as `hearing` hears it.
fn heard(rec: &Recording, hearing: Hearing) -> Vec<f64> {
    rec.channel(|f| match hearing {
        Hearing::Listener => f.pressure_pa,
        Hearing::PairMix => 0.5 * (f.pressure_pa + f.pressure_right_pa),
    })
}

/// The stretch over which [`contact_s`] watches the felt (s): longer than any key's contact
/// (A0's, the longest, 7.5 ms at velocity 80).
pub const CONTACT_WINDOW_S: f64 = 0.02;

/// How long the felt stays on the strings when `preset`'s key is struck at `velocity_m_s` (s): the
/// steps of the exact engine at the output rate in which it presses on any string (Eq. 8's force
/// above zero), over the first [`CONTACT_WINDOW_S`]. Askenfelt & Jansson measured 3.0 ms at C2 down
/// to 0.6 ms at C7 at mezzoforte (docs/realism-sources.md §4).
pub fn contact_s(preset: &LoadedPreset, velocity_m_s: f64) -> Result<f64, BuildError> {
    let rec = record(
        preset,
        velocity_m_s,
        CONTACT_WINDOW_S,
        None,
        Hearing::Listener,
    )?;
    Ok(pressing_s(&rec))
}

/// [`contact_s`] read off a recording of the strike (at least [`CONTACT_WINDOW_S`] long).
fn pressing_s(rec: &Recording) -> f64 {
    let pressing = rec
        .frames
        .iter()
        .take((CONTACT_WINDOW_S * rec.rate_hz).round() as usize)
        .filter(|f| f.obs.hammer_force_n.iter().sum::<f64>() > 0.0)
        .count();
    pressing as f64 / rec.rate_hz
}

/// A key struck and heard at the listener ([`struck_key`]), and where its fundamental stands
/// against its second partial on the way: in the felt's force on the strings (Eq. 8), in the
/// strings' force on the bridge (T, Eq. 6) and at the listener (`heard`).
#[derive(Debug, Clone, PartialEq)]
pub struct Struck {
    pub heard: StruckKey,
    /// How long the felt stayed on the strings (s), as [`contact_s`] counts.
    pub contact_s: f64,
    /// The felt's force pulse at partial 1 re at partial 2 (dB): its Fourier transform's
    /// magnitude at the two, the whole pulse taken (no window).
    pub felt_fundamental_re_second_db: f64,
    /// Partial 1 re partial 2 of the strings' force on the bridge across the board (T), first
    /// 0.3 s (dB).
    pub bridge_fundamental_re_second_db: f64,
}

/// `preset`'s key struck at `velocity_m_s` and heard at the listener for `seconds` (at least
/// [`CONTACT_WINDOW_S`]), its first partial on `target_hz`, all measured from the one recording.
pub fn struck_key(
    preset: &LoadedPreset,
    target_hz: f64,
    velocity_m_s: f64,
    seconds: f64,
) -> Result<Struck, BuildError> {
    let rec = record(preset, velocity_m_s, seconds, None, Hearing::Listener)?;
    let b = preset.unison_spec().strings[0].speaking_inharmonicity();
    let (fs, x) = (rec.rate_hz, heard(&rec, Hearing::Listener));
    let felt = rec.channel(|f| f.obs.hammer_force_n.iter().sum());
    let bridge = rec.channel(|f| f.obs.total_force_n[0]);
    Ok(Struck {
        heard: StruckKey::measure(&x, fs, target_hz, b),
        contact_s: pressing_s(&rec),
        felt_fundamental_re_second_db: pulse_fundamental_re_second_db(&felt, fs, target_hz, b),
        bridge_fundamental_re_second_db: fundamental_re_second_db(&bridge, fs, target_hz, b),
    })
}

/// A pulse `x` at `fs` (whole within the first [`CONTACT_WINDOW_S`]) at partial 1 re at partial 2
/// (dB) of the stiff string's law (first partial `f1_hz`, inharmonicity `b`): the magnitude of its
/// Fourier transform at each. A windowed spectrum (as [`fundamental_re_second_db`] takes of a
/// ringing sound) would weigh a pulse at the window's edge by the window's rise: a Hann window
/// over 0.3 s read C4's felt at +2.9 dB where its transform gives +5.3.
pub fn pulse_fundamental_re_second_db(x: &[f64], fs: f64, f1_hz: f64, b: f64) -> f64 {
    let law = stiff_string_hz(f1_hz, b);
    let n = ((CONTACT_WINDOW_S * fs).round() as usize).min(x.len());
    let magnitude = |f_hz: f64| {
        let w = 2.0 * std::f64::consts::PI * f_hz / fs;
        let (re, im) = x[..n]
            .iter()
            .enumerate()
            .fold((0.0, 0.0), |(re, im), (k, &v)| {
                let (s, c) = (w * k as f64).sin_cos();
                (re + v * c, im - v * s)
            });
        re.hypot(im)
    };
    20.0 * (magnitude(law(1)) / magnitude(law(2))).log10()
}

/// Partial 1 re partial 2 of `x` at `fs`, first 0.3 s (dB): the strongest spectral line within a
/// quarter of the first partial `f1_hz` of each of the first two partials of the stiff string's
/// law (inharmonicity `b`), as the recorded grand's are taken.
pub fn fundamental_re_second_db(x: &[f64], fs: f64, f1_hz: f64, b: f64) -> f64 {
    let law = stiff_string_hz(f1_hz, b);
    match peaks(x, fs, (0.0, 0.3), &[law(1), law(2)], 0.25 * f1_hz)[..] {
        [p1, p2] => p1.level_db - p2.level_db,
        _ => f64::NAN,
    }
}

/// One struck key's figures.
#[derive(Debug, Clone, PartialEq)]
pub struct StruckKey {
    /// A-weighted level of the first 0.5 s (dB re 1 Pa²).
    pub a_level_db: f64,
    /// The 2–4 and 4–8 kHz bands at 0.5–1.5 s re their first 30 ms (dB).
    pub upper_bands_db: [f64; 2],
    /// Partials (of the stiff string's law up to 20 kHz) within 60 dB of the strongest.
    pub partials_in_range: usize,
    /// Partial 1 re partial 2, first 0.3 s (dB).
    pub fundamental_re_second_db: f64,
    /// The 40–90 Hz band re the whole, first 0.5 s (dB).
    pub boom_db: f64,
    /// Partial 1's early T60 (s; [`early_t60_s`]) at its frequency as heard (the peak within
    /// 2 % of the law's in 0.05–1.05 s); `None` from a recording too short for its window.
    pub early_t60_s: Option<f64>,
}

impl StruckKey {
    /// Measure a recording `x` at `fs` of a key whose first partial is `f1_hz` with
    /// inharmonicity `b`.
    pub fn measure(x: &[f64], fs: f64, f1_hz: f64, b: f64) -> StruckKey {
        let law = stiff_string_hz(f1_hz, b);
        let partials: Vec<f64> = (1..).map(&law).take_while(|&f| f < 20_000.0).collect();
        let half = 0.25 * f1_hz;
        let found = peaks(x, fs, ONSET_S, &partials, half);
        let strongest = found
            .iter()
            .map(|p| p.level_db)
            .fold(f64::NEG_INFINITY, f64::max);
        let whole = band_power(x, fs, ONSET_S, (0.0, fs / 2.0));
        StruckKey {
            a_level_db: a_weighted_level_db(x, fs, ONSET_S.0, ONSET_S.1),
            upper_bands_db: UPPER_BANDS_HZ
                .map(|band| band_change_db(x, fs, band, ATTACK_S, LATE_S)),
            partials_in_range: found
                .iter()
                .filter(|p| p.level_db >= strongest - PARTIAL_RANGE_DB)
                .filter(|p| p.stands_out(PARTIAL_MARGIN_DB))
                .count(),
            fundamental_re_second_db: fundamental_re_second_db(x, fs, f1_hz, b),
            boom_db: power_db(band_power(x, fs, ONSET_S, BOOM_HZ) / whole),
            early_t60_s: early_partial_t60_s(x, fs, law(1)),
        }
    }
}

/// Partial 1's early T60 (s) of `x` at `fs`, at the peak within 2 % of `f1_hz` in its 0.05–1.05 s
/// (the recording's script reads the partial's frequency from a 1 s spectrum so).
fn early_partial_t60_s(x: &[f64], fs: f64, f1_hz: f64) -> Option<f64> {
    let (from, to) = ((0.05 * fs) as usize, ((1.05 * fs) as usize).min(x.len()));
    if to <= from {
        return None;
    }
    let heard_hz = peak_frequency(&x[from..to], fs, 0.98 * f1_hz, 1.02 * f1_hz);
    early_t60_s(x, fs, heard_hz)
}

/// A struck key's first 0.5 s as the dynamics rows measure it, rendered or recorded
/// (`scripts/recorded_dynamics.py`): how loud, how bright, and its spectrum's shape.
#[derive(Debug, Clone, PartialEq)]
pub struct Touch {
    /// A-weighted level (dB re 1 Pa²).
    pub a_level_db: f64,
    /// The power-weighted mean frequency (Hz).
    pub centroid_hz: f64,
    /// Octave bands 0–125 Hz … 4–8 kHz re their sum (dB).
    pub octave_shape_db: [f64; 7],
}

impl Touch {
    pub fn measure(x: &[f64], fs: f64) -> Touch {
        Touch {
            a_level_db: a_weighted_level_db(x, fs, ONSET_S.0, ONSET_S.1),
            centroid_hz: spectral_centroid_hz(x, fs, ONSET_S),
            octave_shape_db: octave_shape_db(x, fs, ONSET_S),
        }
    }

    /// `preset`'s key struck at [`PP_VELOCITY`] and at [`FF_VELOCITY`] (the MIDI velocity
    /// curve's hammer speeds), each heard as `hearing` says and measured.
    pub fn pp_and_ff(preset: &LoadedPreset, hearing: Hearing) -> Result<[Touch; 2], BuildError> {
        let at = |velocity: u8| -> Result<Touch, BuildError> {
            let speed = hammer_speed_m_s(f64::from(velocity)).expect("a MIDI velocity 1–127");
            let (fs, x) = pressure_heard(preset, speed, ONSET_S.1, None, hearing)?;
            Ok(Touch::measure(&x, fs))
        };
        Ok([at(PP_VELOCITY)?, at(FF_VELOCITY)?])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// A half-sine pulse of duration `T` has the transform `(2T/pi) cos(pi f T) / (1 - (2fT)^2)`
    /// (in magnitude): a felt that stays 2 ms on C4's strings, as a half-sine, is 8.4 dB
    /// stronger at the first partial than at the second.
    #[test]
    fn a_half_sine_pulse_is_read_as_its_transform() {
        let (fs, contact_s, f1_hz) = (48_000.0, 2e-3, 261.6);
        let n = (contact_s * fs) as usize;
        let mut x: Vec<f64> = (0..=n).map(|k| (PI * k as f64 / n as f64).sin()).collect();
        x.resize((0.3 * fs) as usize, 0.0);
        let transform = |f: f64| {
            (2.0 * contact_s / PI * (PI * f * contact_s).cos()
                / (1.0 - (2.0 * f * contact_s).powi(2)))
            .abs()
        };
        let expected = 20.0 * (transform(f1_hz) / transform(2.0 * f1_hz)).log10();
        let read = pulse_fundamental_re_second_db(&x, fs, f1_hz, 0.0);
        println!("half-sine of 2 ms: partial 1 re 2 {read:+.2} dB (transform {expected:+.2} dB)");
        assert!((read - expected).abs() < 0.05);
    }
}
