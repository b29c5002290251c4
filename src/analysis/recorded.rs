//! A recorded concert grand to hold the keyboard against: the Salamander Grand Piano V3 (a Yamaha
//! C5, A. Holm, CC BY 3.0), MIDI velocity layer 10 (velocities 73–80), 30 keys, measured by
//! `scripts/recorded_grand.py` into `docs/data/recorded_grand.csv`; and all 16 of its velocity
//! layers of the same keys, measured by `scripts/recorded_dynamics.py` into
//! `docs/data/recorded_dynamics.csv` (the scripts' docstrings define every column;
//! docs/realism-sources.md names the source).

use std::collections::HashMap;

const CSV: &str = include_str!("../../docs/data/recorded_grand.csv");
const DYNAMICS_CSV: &str = include_str!("../../docs/data/recorded_dynamics.csv");

/// The lowest key (F#1) whose recorded early T60 of partial 1 is its string's: A0–D#1's
/// fundamentals are too weak to track past 0.4 s (3 s against their 24.5 s broadband).
pub const EARLY_T60_FROM_KEY: usize = 10;

/// One recorded key's figures; `None` where the recording did not allow the measurement.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedKey {
    pub key: usize,
    /// The fitted first partial `f0 sqrt(1 + B)` against equal temperament (cents).
    pub cents: Option<f64>,
    /// Partial 1's T60, early and late window (s).
    pub p1_t60_s: (Option<f64>, Option<f64>),
    /// Broadband T60 fitted from 1 to 12 s after the onset (s).
    pub broadband_t60_s: Option<f64>,
    /// A-weighted level of the first 0.5 s re the mean of A3, C4, D#4, F#4, A4 (dB).
    pub a_level_re_middle_db: Option<f64>,
    /// Partial 1 re partial 2, first 0.3 s (dB).
    pub fundamental_re_second_db: Option<f64>,
    /// The 2–4 and 4–8 kHz bands at 0.5–1.5 s re their first 30 ms (dB).
    pub upper_bands_db: [Option<f64>; 2],
    /// Partials within 60 dB of the strongest, first 0.5 s.
    pub partials_in_range: Option<usize>,
}

/// One recorded key at one velocity layer: its first 0.5 s.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedLayer {
    pub key: usize,
    /// The MIDI velocities the upstream SFZ plays this layer for.
    pub velocities: std::ops::RangeInclusive<u8>,
    /// A-weighted level (dB re the file's full scale; one gain per key, so compare layers of one
    /// key, not keys).
    pub a_level_db: f64,
    /// The power-weighted mean frequency (Hz).
    pub centroid_hz: f64,
    /// Octave bands 0–125 Hz … 4–8 kHz re their sum (dB, [`super::listening::octave_shape_db`]).
    pub octave_shape_db: [f64; 7],
}

/// The layer of recorded key `key` that MIDI velocity `velocity` plays, if the key was recorded.
pub fn recorded_layer(key: usize, velocity: u8) -> Option<RecordedLayer> {
    static LAYERS: std::sync::OnceLock<Vec<RecordedLayer>> = std::sync::OnceLock::new();
    LAYERS
        .get_or_init(recorded_layers)
        .iter()
        .find(|l| l.key == key && l.velocities.contains(&velocity))
        .cloned()
}

/// Every recorded layer of every key.
fn recorded_layers() -> Vec<RecordedLayer> {
    rows(DYNAMICS_CSV)
        .filter_map(|row| {
            let get = |name: &str| row.get(name).copied();
            let velocities = get("velocity_min")? as u8..=get("velocity_max")? as u8;
            let band = |lo: &str, hi: &str| get(&format!("band_{lo}_{hi}_db"));
            Some(RecordedLayer {
                key: get("key_number")? as usize,
                velocities,
                a_level_db: get("la_db")?,
                centroid_hz: get("centroid_hz")?,
                octave_shape_db: [
                    band("0", "125")?,
                    band("125", "250")?,
                    band("250", "500")?,
                    band("500", "1000")?,
                    band("1000", "2000")?,
                    band("2000", "4000")?,
                    band("4000", "8000")?,
                ],
            })
        })
        .collect()
}

/// Each data line of a CSV: its finite numbers by column name.
fn rows(csv: &str) -> impl Iterator<Item = HashMap<&str, f64>> {
    let mut lines = csv.lines();
    let names: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    lines.filter(|l| !l.trim().is_empty()).map(move |line| {
        names
            .iter()
            .zip(line.split(','))
            .filter_map(|(&name, cell)| {
                let v: f64 = cell.trim().parse().ok()?;
                v.is_finite().then_some((name, v))
            })
            .collect()
    })
}

/// The recorded keys, by key number.
pub fn recorded_grand() -> Vec<RecordedKey> {
    rows(CSV)
        .filter_map(|row| {
            let get = |name: &str| row.get(name).copied();
            Some(RecordedKey {
                key: get("key_number")? as usize,
                cents: get("cents_vs_et"),
                p1_t60_s: (get("p1_t60_early_s"), get("p1_t60_late_s")),
                broadband_t60_s: get("bb_t60_1_12s"),
                a_level_re_middle_db: get("la_re_a3a4_db"),
                fundamental_re_second_db: get("p1_re_p2_db"),
                upper_bands_db: [get("band_2_4k_re_attack_db"), get("band_4_8k_re_attack_db")],
                partials_in_range: get("n_partials_60db").map(|n| n as usize),
            })
        })
        .collect()
}

/// The recorded key `key`, if it is one of the 30.
pub fn recorded_key(key: usize) -> Option<RecordedKey> {
    recorded_grand().into_iter().find(|r| r.key == key)
}

/// An early T60 of partial 1 at `key` (`ours_s`, s) re the recorded grand's, where the recording
/// has it as its string's (from [`EARLY_T60_FROM_KEY`] up).
pub fn early_t60_re_recorded(key: usize, ours_s: f64) -> Option<f64> {
    if key < EARLY_T60_FROM_KEY {
        return None;
    }
    Some(ours_s / recorded_key(key)?.p1_t60_s.0?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_recording_reads_whole() {
        let keys = recorded_grand();
        let c4 = recorded_key(40).expect("C4 is recorded");
        println!("{} recorded keys; C4: {c4:?}", keys.len());
        assert_eq!(keys.len(), 30);
        assert_eq!(keys[0].key, 1);
        assert_eq!(keys[29].key, 88);
        assert_eq!(c4.partials_in_range, Some(16));
        assert!(c4.upper_bands_db.iter().all(Option::is_some));
    }

    #[test]
    fn every_recorded_key_has_its_sixteen_layers() {
        for key in recorded_grand().iter().map(|k| k.key) {
            let layers: Vec<RecordedLayer> =
                (1..=127).filter_map(|v| recorded_layer(key, v)).collect();
            assert_eq!(layers.len(), 127, "key {key}");
            assert!(layers.iter().all(|l| l.key == key));
        }
        let (pp, ff) = (
            recorded_layer(40, 30).unwrap(),
            recorded_layer(40, 127).unwrap(),
        );
        println!("C4 at velocity 30: {pp:?}\nC4 at 127: {ff:?}");
        assert_eq!((pp.velocities, ff.velocities), (27..=34, 121..=127));
        assert!(recorded_layer(41, 30).is_none());
    }
}
