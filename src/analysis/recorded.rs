//! A recorded concert grand to hold the keyboard against: the Salamander Grand Piano V3 (a Yamaha
//! C5, A. Holm, CC BY 3.0), MIDI velocity layer 10 (velocities 73–80), 30 keys, measured by
//! `scripts/recorded_grand.py` into `docs/data/recorded_grand.csv` (its docstring defines every
//! column; docs/realism-sources.md names the source).

use std::collections::HashMap;

const CSV: &str = include_str!("../../docs/data/recorded_grand.csv");

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

/// The recorded keys, by key number.
pub fn recorded_grand() -> Vec<RecordedKey> {
    let mut lines = CSV.lines();
    let header: HashMap<&str, usize> = lines
        .next()
        .unwrap_or_default()
        .split(',')
        .enumerate()
        .map(|(i, name)| (name, i))
        .collect();
    lines
        .filter(|l| !l.trim().is_empty())
        .filter_map(|line| {
            let cells: Vec<&str> = line.split(',').collect();
            let get = |name: &str| -> Option<f64> {
                let v: f64 = cells.get(*header.get(name)?)?.trim().parse().ok()?;
                v.is_finite().then_some(v)
            };
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
}
