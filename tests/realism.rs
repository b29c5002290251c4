//! How the keyboard sounds against a grand (issue 17), measured: the partials `unacorda analyze`
//! reads from each key's linearised system, checked against the stiff string they come from
//! (Eq. 2), and the command's table and CSV.

use std::process::Command;
use unacorda::analysis::listening::median;
use unacorda::analysis::modes::linear_modes;
use unacorda::analysis::partials::{cents, partials, tuner_pitch, KeyPartials};
use unacorda::config::scaling::{parse_key, Scaling};

#[test]
fn c4s_partials_are_its_strings_and_the_tuner_finds_their_stiffness() {
    // C4's three strings on their bridge: each partial 1–8 is the cluster of the three strings'
    // transverse modes near `n f0 sqrt(1 + B n^2)` of the speaking length (Eq. 2). All sit a few
    // cents sharp of it alike — the contact spring and the truncated mode set shorten the string a
    // little (the tuner sets the tension against the coupled system, `engine::tuning`) — so the
    // partials' spread about that offset is what Eq. 2 checks; the law fitted to partials 2–8
    // finds the strings' own B.
    let scaling = Scaling::resolve("paper").unwrap();
    let spec = scaling
        .key_preset(parse_key("C4").unwrap())
        .unwrap()
        .unison_spec();
    let modes = linear_modes(&spec).unwrap();
    // Each string's law on its speaking length (its own tension: the unison's mistuning), and
    // their mean.
    let laws: Vec<(f64, f64)> = spec
        .strings
        .iter()
        .map(|s| {
            let f0 = (s.tension_n / s.linear_density_kg_m).sqrt() / (2.0 * s.speaking_length_m);
            let b = s.speaking_inharmonicity();
            (f0, b)
        })
        .collect();
    let law = |n: usize| {
        let n = n as f64;
        laws.iter()
            .map(|&(f0, b)| n * f0 * (1.0 + b * n * n).sqrt())
            .sum::<f64>()
            / laws.len() as f64
    };
    let b = laws.iter().map(|l| l.1).sum::<f64>() / laws.len() as f64;
    let found = partials(&modes, law, 8);
    let off: Vec<f64> = found.iter().map(|p| cents(p.freq_hz, law(p.n))).collect();
    println!("C4's partials 1–8 against Eq. 2 (cents): {off:.2?}");
    let worst = off.iter().fold(0f64, |m, x| m.max(x.abs()));
    let spread =
        off.iter().fold(f64::MIN, |m, &x| m.max(x)) - off.iter().fold(f64::MAX, |m, &x| m.min(x));
    let pitch = tuner_pitch(&found, law(1), b).unwrap();
    println!(
        "C4: {} partials of 8, within {worst:.2} cents of Eq. 2 (the strings' mean), spread {spread:.2} cents (modes per partial {:?}); the tuner's B {:.3e} against the strings' {b:.3e}",
        found.len(),
        found.iter().map(|p| p.modes).collect::<Vec<_>>(),
        pitch.inharmonicity
    );
    assert_eq!(found.len(), 8);
    assert!(found.iter().all(|p| p.modes == 3), "one T mode per string");
    assert!(
        worst < 15.0 && spread < 3.0,
        "{worst} cents, spread {spread}"
    );
    assert!((pitch.inharmonicity / b - 1.0).abs() < 0.1);
    assert!(found.iter().all(|p| p.t60_min_s <= p.t60_max_s));
}

#[test]
fn analyze_prints_and_writes_each_keys_pitch_and_decay() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("keys.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_unacorda"))
        .args(["analyze", "--keys", "A0,C4,E7", "--csv"])
        .arg(&csv)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8_lossy(&out.stdout);
    print!("{text}");
    let rows: Vec<Vec<String>> = std::fs::read_to_string(&csv)
        .unwrap()
        .lines()
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    assert_eq!(rows.len(), 4, "a header and three keys");
    assert!(rows.iter().all(|r| r.len() == 8 + 4 * 8));
    let names: Vec<&str> = rows[1..].iter().map(|r| r[1].as_str()).collect();
    assert_eq!(names, ["A0", "C4", "E7"]);
    let c4_tuner: f64 = rows[2][4].parse().unwrap();
    assert!(c4_tuner.abs() < 3.0, "C4 on pitch: {c4_tuner}");
    assert!(text.contains("pitch (partials 2–8"));
    assert!(text.contains("partial 1 T60"));
}

#[test]
fn the_keyboard_is_tuned_as_a_tuner_hears_it() {
    // Every key's pitch on partials 2–8 of its linearised system (the damped, three-direction
    // coupled system, not the undamped one the tuner works on) against its target: equal
    // temperament on the paper keyboard, the stretched tuning on the concert one. Issue 17 asks
    // all 88 within ±3 cents. The pitch is how far partials 2–8 lie, balanced, from the target's
    // series with the string's own B (`series_offset_cents`): the concert keyboard holds 88, Bb0
    // at -2.7 (its partials 2 and 3 split by board modes); the paper keyboard 87, Bb0 at -3.0.
    // Measured otherwise: extrapolating the first partial from a law fitted with B free, 87 (Bb0
    // -3.9: a tilt of a few cents across the pulled partials); with every key's first partial on
    // pitch, 51, and the top octave up to 341 cents off; fitting with a partial a board mode
    // pulls 15–27 cents weighing as much as the others, 79 (E1 +15, A0 +9, Bb0 -9, C2 +7). On
    // the concert keyboard E7 keeps a mode fewer than the paper's at its higher tension, and is
    // tuned with it. With their modes to 9.6 kHz, Bb7, B7 and C8 keep their first partial alone
    // and are heard on it; the concert keyboard keeps theirs to 20 kHz (`mode_limits`), and every
    // one of its keys is tuned on partials 2–8 as issue 17 asks.
    for keyboard in ["paper", "concert"] {
        let scaling = Scaling::resolve(keyboard).unwrap();
        let keys: Vec<usize> = (1..=88).collect();
        let heard = unacorda::cores::map_on_cores(&keys, |&k| {
            let spec = scaling.key_preset(k).unwrap().unison_spec();
            let target = scaling.target_hz(k);
            let key = KeyPartials::new(&spec, target, 8).map_err(|e| format!("key {k}: {e}"))?;
            let heard = key.heard_hz().ok_or(format!("key {k}: no partial found"))?;
            Ok::<_, String>((cents(heard, target), key.pitch.is_some()))
        })
        .unwrap();
        let pitch: Vec<f64> = heard.iter().map(|h| h.0).collect();
        let on_the_first: Vec<String> = (1..=88)
            .filter(|&k| !heard[k - 1].1)
            .map(unacorda::board::key_name)
            .collect();
        println!("{keyboard}: heard on the first partial alone: {on_the_first:?}");
        if keyboard == "concert" {
            assert!(on_the_first.is_empty(), "{on_the_first:?}");
        }
        let within: Vec<usize> = (0..88)
            .filter(|&i| pitch[i].abs() <= 3.0)
            .map(|i| i + 1)
            .collect();
        let top = &pitch[75..];
        println!(
            "{keyboard}: {} of 88 keys within ±3 cents of their target on partials 2–8; C7–C8: {top:+.1?} cents; the rest: {:?}",
            within.len(),
            (1..=88)
                .filter(|k| !within.contains(k))
                .map(|k| format!("{k} {:+.1}", pitch[k - 1]))
                .collect::<Vec<_>>()
        );
        let needed = if keyboard == "concert" { 88 } else { 87 };
        assert!(
            within.len() >= needed,
            "{keyboard}: {} keys within ±3 cents",
            within.len()
        );
        assert!(
            top.iter().all(|c| c.abs() <= 3.0),
            "{keyboard}: the top octave: {top:?}"
        );
    }
}

#[test]
fn the_concert_keyboard_is_stretched_on_its_own_inharmonicity() {
    // A tuner sets the temperament octave A3–A4 and tunes octaves outwards, each against the
    // partials of the key an octave away: the temperament and above, 2:1; below, from 2:1
    // widening to 10:5 from E2 down (the concert keyboard's `bass_octave`,
    // `bass_octave_from_key`), on the bass's inharmonicity as a tuner models it (ln B averaged
    // over an octave). Checked here on Eq. 2's partials from each key's target and that `B`: the
    // octaves beatless on the partials they are tuned on, the blend between, and a curve that
    // rises from the bass to the treble without a step. Railsback's
    // curve (issue 17): -10 … -26 cents at A0–A1, +15 … +33 at Eb7–C8; the recorded grand (much
    // stiffer bass strings than these) -27 at A0, -8.6 at C2, +23 at C7.
    let concert = Scaling::resolve("concert").unwrap();
    let paper = Scaling::resolve("paper").unwrap();
    let stretch: Vec<f64> = (0..=88)
        .map(|k| {
            if k == 0 {
                f64::NAN
            } else {
                concert.stretch_cents(k)
            }
        })
        .collect();
    let b = |k: usize| concert.tuning_inharmonicity(k);
    // Partial n of key k (Hz), its first partial on the target.
    let partial_hz =
        |k: usize, n: f64| n * concert.target_hz(k) * ((1.0 + b(k) * n * n) / (1.0 + b(k))).sqrt();
    let beat_cents =
        |k: usize, n: f64| 1200.0 * (partial_hz(k + 12, n) / partial_hz(k, 2.0 * n)).log2();
    let recorded = unacorda::analysis::recorded::recorded_grand();
    println!("key   stretch ¢   recorded grand ¢   B tuned on / the string's own");
    for k in [1, 4, 13, 16, 23, 28, 37, 40, 52, 64, 76, 79, 85, 88] {
        let r = recorded.iter().find(|r| r.key == k).and_then(|r| r.cents);
        let own = concert.key_preset(k).unwrap().unison_spec().strings[0].speaking_inharmonicity();
        println!(
            "{k:3} {:+11.1} {:>18}   {:.2e} / {own:.2e}",
            stretch[k],
            r.map_or("-".into(), |c| format!("{c:+.1}")),
            b(k)
        );
    }
    for k in 1..=88 {
        assert_eq!(paper.stretch_cents(k), 0.0);
        if k <= 20 {
            // 10:5 octaves up to E2–E3.
            assert!(beat_cents(k, 5.0).abs() < 1e-6, "key {k}: 10:5");
        } else if k < 37 {
            // Between a 2:1 and a 10:5 octave.
            let (wide, narrow) = (beat_cents(k, 5.0), beat_cents(k, 1.0));
            assert!(wide <= 1e-9 && narrow >= -1e-9, "key {k}: {wide} {narrow}");
        } else if k > 49 {
            // 2:1 above.
            assert!(beat_cents(k - 12, 1.0).abs() < 1e-6, "key {k}: 2:1");
        } else {
            // A 2:1 temperament octave, its semitones equal.
            assert!(beat_cents(37, 1.0).abs() < 1e-6, "A3–A4: 2:1");
            let step = stretch[49] - stretch[48];
            assert!((stretch[k] - stretch[49] + step * (49 - k) as f64).abs() < 1e-9);
        }
    }
    // The bass's averaged B follows its strings' own (which jump from 1.1e-4 to 1.9e-4 where the
    // plain strings begin, at G2): within 40 %, and 12 % in rms of ln B.
    let ratios: Vec<f64> = (1..=49)
        .map(|k| {
            b(k) / concert.key_preset(k).unwrap().unison_spec().strings[0].speaking_inharmonicity()
        })
        .collect();
    let worst = ratios.iter().map(|r| (r - 1.0).abs()).fold(0.0, f64::max);
    let rms = (ratios.iter().map(|r| r.ln().powi(2)).sum::<f64>() / ratios.len() as f64).sqrt();
    println!("the bass's averaged B against its strings': worst {worst:.2}, rms of ln {rms:.3}");
    assert!(worst < 0.4 && rms < 0.12);
    // It rises up the keyboard: no semitone narrower than equal temperament by a quarter of a
    // cent (A2, where the plain strings' stiffer octaves begin: 0.18).
    let falls: Vec<String> = (2..=88)
        .filter(|&k| stretch[k] < stretch[k - 1] - 0.05)
        .map(|k| format!("{} {:+.2} → {:+.2}", k, stretch[k - 1], stretch[k]))
        .collect();
    println!("where it falls: {falls:?}");
    assert!((2..=88).all(|k| stretch[k] > stretch[k - 1] - 0.25));
    assert!((1..=13).all(|k| (-26.0..=-10.0).contains(&stretch[k])));
    assert!(stretch[88] > 30.0);
    assert!((15.0..=33.0).contains(&stretch[79]) && (15.0..=33.0).contains(&stretch[85]));
}

fn key_spec(keyboard: &str, name: &str) -> (unacorda::engine::UnisonSpec, f64) {
    let k = parse_key(name).unwrap();
    let spec = Scaling::resolve(keyboard)
        .unwrap()
        .key_preset(k)
        .unwrap()
        .unison_spec();
    (spec, unacorda::config::scaling::equal_tempered_hz(k))
}

#[test]
fn the_concert_keyboards_strings_ring_as_long_as_a_grands() {
    // Issue 17: the first partial's T60 about 20–30 s in the bass, falling to 1–2 s near C7 (the
    // recorded grand: 30–39 s at F#1–C2 late, 1.1 s early at C7). The paper's constant zeta =
    // 5e-5 gives A0 666 s; the concert keyboard's losses (b1 + b3 omega^2) bring it down. Each
    // partial's fastest and slowest mode: the early and late decay of a coupled unison.
    let t60 = |keyboard: &str, name: &str| {
        let (spec, target) = key_spec(keyboard, name);
        let p = *KeyPartials::new(&spec, target, 1)
            .unwrap()
            .partial(1)
            .unwrap();
        (p.t60_min_s, p.t60_max_s)
    };
    let keys = ["A0", "C1", "C2", "C3", "C4", "C5", "C6", "C7"];
    let concert: Vec<(f64, f64)> = keys.iter().map(|k| t60("concert", k)).collect();
    for (k, (lo, hi)) in keys.iter().zip(&concert) {
        println!("concert {k}: partial 1 T60 {lo:.2}–{hi:.2} s");
    }
    let paper_a0 = t60("paper", "A0");
    println!("paper A0: {:.0} s", paper_a0.1);
    assert!(paper_a0.1 > 600.0, "the paper's A0 rings for minutes");
    for (k, &(_, slowest)) in keys[..3].iter().zip(&concert) {
        assert!((20.0..=40.0).contains(&slowest), "{k}: {slowest} s");
    }
    let c7 = concert[7];
    assert!((1.0..=2.0).contains(&c7.0), "C7 early {} s", c7.0);
}

#[test]
fn the_concert_keyboards_first_partials_fall_early_as_the_recorded_grands() {
    // The early decay of partial 1 (the board draining the unison's in-phase motion), rendered
    // (the exact engine, MIDI velocity 80, 1.5 s at the listener, as `analyze --render` renders
    // it) and measured as the recorded grand's is (`analysis::listening::early_t60_s`), at the
    // recorded keys from F#1 to C8 (below, the recording's fundamentals are too weak to track:
    // A0-D#1 3 s against its 24.5 s broadband). Key by key the two scatter by a factor of 3
    // either way on any board, a partial falling near a board mode or between two; held here:
    // the median ratio within 1.5 (1.27; 1.21 before the radiation was fitted on the partials, 1.06 with the string modes of C4-A7 below 9.6 kHz, 0.98
    // on Table 1's board). A board that drains too little fails: its modes damped at zeta 0.003
    // rather than the paper's 0.03 give 1.62.
    use unacorda::analysis::recorded::{early_t60_re_recorded, recorded_key, EARLY_T60_FROM_KEY};
    use unacorda::analysis::struck::{struck_key, LATE_S};
    let speed = unacorda::midi::hammer_speed_m_s(80.0).unwrap();
    let keyboard = Scaling::resolve("concert").unwrap();
    let keys: Vec<usize> = (EARLY_T60_FROM_KEY..=88)
        .filter(|&k| recorded_key(k).is_some_and(|r| r.p1_t60_s.0.is_some()))
        .collect();
    let ours = unacorda::cores::map_on_cores(&keys, |&key| {
        let preset = keyboard.key_preset(key)?;
        let struck = struck_key(&preset, keyboard.target_hz(key), speed, LATE_S.1)?;
        Ok::<_, anyhow::Error>(struck.heard.early_t60_s.unwrap())
    })
    .unwrap();
    let mut ratios: Vec<f64> = keys
        .iter()
        .zip(&ours)
        .map(|(&key, &t60)| {
            let ratio = early_t60_re_recorded(key, t60).unwrap();
            println!(
                "{}: partial 1 early T60 {t60:.2} s, {ratio:.2} × the recording's",
                unacorda::board::key_name(key)
            );
            ratio
        })
        .collect();
    let median = median(&mut ratios);
    println!(
        "early T60 re the recording's over {} keys: median {median:.2} (limit 1/1.5–1.5), from {:.2} to {:.2}",
        ratios.len(),
        ratios[0],
        ratios[ratios.len() - 1]
    );
    assert!((1.0 / 1.5..=1.5).contains(&median));
}

#[test]
fn the_duplex_felt_mutes_its_segment_and_leaves_the_speaking_length() {
    // The felt (Eq. 13) acts on the duplex segment, but the bridge moves and the duplex answers,
    // most near its own resonance: with the paper's c_d = 20 N s/m^2, C4's partial 8 keeps 0.23 of
    // its T60. The concert felt (0.4) still mutes the segment's first resonance — from seconds to
    // a few tenths — while the partials below 0.7 of its frequency keep at least 0.9 of their
    // decay, and those nearer it (C4's partial 8: 2.1 against 2.6 kHz) 0.7.
    use unacorda::analysis::duplex::felt_effect;
    for keyboard in ["paper", "concert"] {
        for name in ["C2", "C3", "C4", "C5"] {
            let (spec, target) = key_spec(keyboard, name);
            let e = felt_effect(&spec, target, 8).unwrap();
            let kept: Vec<f64> = (1..=8).map(|n| e.kept(n).unwrap()).collect();
            let (with, without) = (
                e.resonance_with.unwrap().t60_s(),
                e.resonance_without.unwrap().t60_s(),
            );
            println!(
                "{keyboard} {name} (c_d {}): duplex resonance {:.0} Hz T60 {with:.3} s with the felt, {without:.2} s without; partials 1–8 keep {kept:.2?}",
                e.damping_n_s_m2,
                e.resonance_without.unwrap().freq_hz
            );
            if keyboard == "concert" {
                assert!(
                    with <= 0.5 && with <= 0.5 * without,
                    "{name}: {with} / {without} s"
                );
                let resonance_hz = e.resonance_without.unwrap().freq_hz;
                for (n, &k) in (1..=8).zip(&kept) {
                    let near = e.without.partial(n).unwrap().freq_hz > 0.7 * resonance_hz;
                    assert!(k >= if near { 0.7 } else { 0.9 }, "{name} partial {n}: {k}");
                }
            }
        }
    }
}

#[test]
fn the_concert_keyboard_fades_and_rings_out_like_the_recorded_grand() {
    // Rendered (the exact engine, MIDI velocity 80) and measured as the recorded grand is
    // (`docs/data/recorded_grand.csv`): C4's 2–4 and 4–8 kHz bands at 0.5–1.5 s re their first
    // 30 ms within 10 dB of the recording's (the paper's keyboard: about -90 and -110 dB), and A0's
    // broadband T60 from 1 to 12 s within 30 % of the recording's.
    use unacorda::analysis::listening::late_t60_s;
    use unacorda::analysis::recorded::recorded_key;
    use unacorda::analysis::struck::{pressure, StruckKey, LATE_S};
    let speed = unacorda::midi::hammer_speed_m_s(80.0).unwrap();
    let keyboard = Scaling::resolve("concert").unwrap();
    let c4 = keyboard.key_preset(40).unwrap();
    let (fs, x) = pressure(&c4, speed, LATE_S.1, None).unwrap();
    let b = c4.unison_spec().strings[0].speaking_inharmonicity();
    let heard = StruckKey::measure(&x, fs, unacorda::config::scaling::equal_tempered_hz(40), b);
    let recorded = recorded_key(40).unwrap().upper_bands_db.map(Option::unwrap);
    println!(
        "C4 upper bands at 0.5–1.5 s re 0–30 ms: 2–4 kHz {:.1} dB (recorded {:.1}), 4–8 kHz {:.1} dB (recorded {:.1})",
        heard.upper_bands_db[0], recorded[0], heard.upper_bands_db[1], recorded[1]
    );
    for (ours, theirs) in heard.upper_bands_db.iter().zip(recorded) {
        assert!((ours - theirs).abs() <= 10.0);
    }
    let a0 = keyboard.key_preset(1).unwrap();
    let (fs, x) = pressure(&a0, speed, 12.0, None).unwrap();
    let ours = late_t60_s(&x, fs, 1.0, 12.0);
    let theirs = recorded_key(1).unwrap().broadband_t60_s.unwrap();
    println!("A0 broadband T60 over 1–12 s: {ours:.1} s (recorded {theirs:.1} s)");
    assert!((ours / theirs - 1.0).abs() <= 0.3);
}

/// `key` of `keyboard` struck at `velocity_m_s` on the exact engine, its first 0.5 s heard at the
/// listener and measured as the recorded grand is (`analysis::struck::StruckKey`).
fn struck_at_listener(
    keyboard: &unacorda::config::scaling::LoadedScaling,
    key: usize,
    velocity_m_s: f64,
) -> unacorda::analysis::struck::StruckKey {
    let preset = keyboard.key_preset(key).unwrap();
    unacorda::analysis::struck::struck_key(&preset, keyboard.target_hz(key), velocity_m_s, 0.5)
        .unwrap()
        .heard
}

/// `keys` of the concert keyboard struck at MIDI velocity 80 (the exact engine, 0.5 s, at the
/// listener above the board): each one's A-weighted level re the mean of the recorded keys of
/// A3–A4 (A3, C4, D#4, F#4, A4), as the recording's balance is taken.
fn concert_levels_re_middle_db(keys: &[usize]) -> Vec<f64> {
    let speed = unacorda::midi::hammer_speed_m_s(80.0).unwrap();
    let keyboard = Scaling::resolve("concert").unwrap();
    let middle_keys = [37, 40, 43, 46, 49];
    let all: Vec<usize> = middle_keys.iter().chain(keys).copied().collect();
    let levels = unacorda::cores::map_on_cores(&all, |&key| {
        Ok::<_, anyhow::Error>(struck_at_listener(&keyboard, key, speed).a_level_db)
    })
    .unwrap();
    let (middle, levels) = levels.split_at(middle_keys.len());
    let middle = middle.iter().sum::<f64>() / middle_keys.len() as f64;
    levels.iter().map(|l| l - middle).collect()
}

#[test]
fn every_concert_key_carries_within_six_db_of_the_middle() {
    // Issue 17: the A-weighted level of the first 0.5 s of every key from A0 to C8 at the same
    // velocity (80, the exact engine, at the listener above the board) within ±6 dB of A3–A4's
    // recorded keys (A3, C4, D#4, F#4, A4), as the recording's balance is taken; the recorded
    // grand's top falls further (A7 −8.4, C8 −13.2 dB). From −5.2 (Bb7) to +5.8 dB (A6). What
    // each voicing or radiation step held off, each seen failing this:
    // - Bb7: its first partial reaches the listener 2.6 dB less per newton than A7's and its
    //   strings' P polarisation drives the board's dropped modes against it: on the hammers
    //   between A7 and C8 it came out at −6.8; its voicing point is a 3 g hammer on a felt 200
    //   times the paper's;
    // - C#6–D6, whose fundamentals (1.0–1.3 kHz) are heard through the kept board modes' fitted
    //   radiation (`board::equivalent`): fitted alike at every frequency, the fit missed C#6's
    //   first partial by 18 dB at the listener, and C#6 came out at −8.1, D6 −6.9;
    // - the top octave: heard as a monopole C7 was 15 dB under the recording; with the paper's
    //   felts A7 and C8 were 15 and 55 dB under; with the felts of p = 4.5 voiced soft to the
    //   recording's A7 and C8, C8 −13.9.
    use unacorda::analysis::recorded::recorded_key;
    let keys: Vec<usize> = (1..=88).collect();
    let levels = concert_levels_re_middle_db(&keys);
    let name = unacorda::board::key_name;
    for (&key, &level) in keys.iter().zip(&levels) {
        if let Some(theirs) = recorded_key(key).and_then(|r| r.a_level_re_middle_db) {
            println!(
                "{}: {level:+.1} dB re A3–A4 (recorded {theirs:+.1})",
                name(key)
            );
        }
    }
    let by_level = |a: &(&usize, &f64), b: &(&usize, &f64)| a.1.total_cmp(b.1);
    let (low, high) = (
        keys.iter().zip(&levels).min_by(by_level).unwrap(),
        keys.iter().zip(&levels).max_by(by_level).unwrap(),
    );
    println!(
        "88 keys re A3–A4: from {:+.1} dB ({}) to {:+.1} dB ({})",
        low.1,
        name(*low.0),
        high.1,
        name(*high.0)
    );
    for (&key, &level) in keys.iter().zip(&levels) {
        assert!(level.abs() <= 6.0, "{}: {level:+.1} dB", name(key));
    }
}

/// `keys` of the concert keyboard struck at MIDI velocity 30 and 127 (the exact engine, 0.5 s),
/// heard by the stereo pair mixed to mono as the recorded grand's pair is, and measured as its
/// velocity layers are (`analysis::struck::Touch`).
fn concert_touches(keys: &[usize]) -> Vec<[unacorda::analysis::struck::Touch; 2]> {
    use unacorda::analysis::struck::{Hearing, Touch};
    let keyboard = Scaling::resolve("concert").unwrap();
    unacorda::cores::map_on_cores(keys, |&k| {
        Ok::<_, anyhow::Error>(Touch::pp_and_ff(
            &keyboard.key_preset(k)?,
            Hearing::PairMix,
        )?)
    })
    .unwrap()
}

#[test]
fn the_concert_treble_grows_louder_with_velocity_as_the_recorded_grand() {
    // The recorded keys from C5 to C8 struck at MIDI velocity 30 and 127 (the exact engine,
    // 0.5 s, heard by the stereo pair mixed to mono as the recorded grand's pair is), and how much
    // louder ff is than pp (the A-weighted level), beside the recorded grand's layers for those
    // velocities (docs/data/recorded_dynamics.csv: +15.5 … +31.3 dB). Held: each key within
    // 10 dB of the recording's rise (single keys scatter: its C6 +15.5, D#6 +24.5), and the
    // median of the differences within ±5 dB. With every felt's exponent 4.5 (as first voiced on
    // the grand-sized board) a pianissimo in the top octave and a half all but vanished: the felt stayed on
    // C7's strings 1.67 ms at velocity 30, 3.5 of its periods, and C7 rose 47.5 dB, F#7 56.6,
    // C8 47.6 (a median of +13.8 dB over the recording's), and this fails.
    use unacorda::analysis::struck::{recorded_pp_and_ff, TREBLE_TOUCH_KEYS};
    let touches = concert_touches(&TREBLE_TOUCH_KEYS);
    let mut over_db = Vec::new();
    for (&k, [pp, ff]) in TREBLE_TOUCH_KEYS.iter().zip(&touches) {
        let rise_db = ff.a_level_db - pp.a_level_db;
        let [rp, rf] = recorded_pp_and_ff(k).unwrap();
        let recorded_db = rf.a_level_db - rp.a_level_db;
        println!(
            "{}: level {rise_db:+.1} dB from velocity 30 to 127 (recorded {recorded_db:+.1})",
            unacorda::board::key_name(k)
        );
        assert!(
            (rise_db - recorded_db).abs() <= 10.0,
            "key {k}: {rise_db:+.1} dB"
        );
        over_db.push(rise_db - recorded_db);
    }
    let over_db = median(&mut over_db);
    println!("median over the 13 keys: {over_db:+.1} dB over the recording's rise (limit ±5)");
    assert!(over_db.abs() <= 5.0);
}

#[test]
fn the_concert_hammers_leave_the_strings_when_measured_hammers_do() {
    // The felt's contact with the strings at MIDI velocity 80 (2.37 m/s, the exact engine,
    // `analysis::struck::contact_s`), beside Askenfelt & Jansson's at mezzoforte (Five Lectures on
    // the Acoustics of the Piano, 1990, Fig. 7: C2 3.0, C3 2.8, C4 2.1, C5 1.45, C6 1.1 ms;
    // docs/realism-sources.md §4), within 15 %; C7 (0.6 ms) within 25 %: its felt is voiced for
    // the touch: one that stays 0.56 ms at mezzoforte (p = 2.25, factor 1.5) stays 0.77 at
    // pianissimo, and C7 then rises 30.9 dB to fortissimo against the recording's 22.5. With the paper
    // keyboard's hammer masses (Chaigne & Askenfelt's, 2.97 g at C4) C4 and C6 leave after 1.62
    // and 0.88 ms, 23 and 20 % early (C2 after 3.52 ms, 17 % late), and this fails; with every
    // felt's exponent 4.5, C7 after 0.85 ms, 42 % late, and this fails.
    use unacorda::analysis::struck::contact_s;
    let speed = unacorda::midi::hammer_speed_m_s(80.0).unwrap();
    let keyboard = Scaling::resolve("concert").unwrap();
    for (key, measured_ms, within) in [
        (16, 3.0, 0.15),
        (28, 2.8, 0.15),
        (40, 2.1, 0.15),
        (52, 1.45, 0.15),
        (64, 1.1, 0.15),
        (76, 0.6, 0.25),
    ] {
        let preset = keyboard.key_preset(key).unwrap();
        let contact_ms = 1e3 * contact_s(&preset, speed).unwrap();
        println!(
            "{}: the felt on the strings {contact_ms:.2} ms (measured at mezzoforte {measured_ms} ms), hammer {:.2} g",
            unacorda::board::key_name(key),
            1e3 * preset.preset.hammer.mass_kg
        );
        assert!(
            (contact_ms / measured_ms - 1.0).abs() <= within,
            "key {key}: {contact_ms:.2} ms"
        );
    }
}

#[test]
fn the_middle_registers_fundamental_is_as_strong_as_the_recorded_grands() {
    // Partial 1 re partial 2 (first 0.3 s, MIDI velocity 80, heard at the listener) of the 16
    // recorded keys from D#2 to C6, against the recorded grand's. Issue 17 asks the fundamental
    // to be no weaker against partial 2 than the recording's. On the grand-sized board it is
    // stronger, by a median of 1.3 dB; held here: no weaker than the recording's by more than
    // 2 dB on median, the median's sampling error over 16 keys (bootstrap: ±2 dB; single keys
    // move 10–20 dB with the recording's microphone, docs/realism.md). On Table 1's board (the
    // tenor's bridge on the minor lobes of its modes at 134–174 Hz) it was 6.8 dB weaker and
    // this fails; with the paper keyboard's hammers there (Chaigne & Askenfelt's masses, 2.97 g
    // at C4: contacts 20-30 % shorter than measured), 9.0 dB.
    use unacorda::analysis::recorded::recorded_key;
    let speed = unacorda::midi::hammer_speed_m_s(80.0).unwrap();
    let keyboard = Scaling::resolve("concert").unwrap();
    let keys: Vec<usize> = (19..=64).step_by(3).collect();
    let ours = unacorda::cores::map_on_cores(&keys, |&key| {
        Ok::<_, anyhow::Error>(struck_at_listener(&keyboard, key, speed).fundamental_re_second_db)
    })
    .unwrap();
    let mut short_db: Vec<f64> = keys
        .iter()
        .zip(&ours)
        .map(|(&key, &db)| {
            let theirs = recorded_key(key).unwrap().fundamental_re_second_db.unwrap();
            println!(
                "{}: partial 1 re 2 {db:+.1} dB (recorded {theirs:+.1})",
                unacorda::board::key_name(key)
            );
            theirs - db
        })
        .collect();
    let median_db = median(&mut short_db);
    println!("partial 1 re 2 short of the recording's: median {median_db:.1} dB (limit 2)");
    assert!(median_db <= 2.0);
}

#[test]
fn the_concert_keyboard_grows_louder_and_brighter_with_velocity_as_the_recorded_grand() {
    // C2, F#3, C4, A4 and C6 struck at MIDI velocity 30 and 127 (the exact engine, 0.5 s), heard
    // by the stereo pair mixed to mono as the recorded grand's pair is measured, beside its layers
    // for the same velocities (`docs/data/recorded_dynamics.csv`). How much louder ff is (the
    // A-weighted level's rise) and how much brighter (the rise of the 2–4 kHz band re the whole)
    // are the hammer's, but each key's figure also carries its board's transfer at its bridge
    // point: moving the keys from Table 1's board to the grand-sized one moved single keys' rises
    // by up to 4 dB and their brightening by up to 3.5 (A4 +23.7 → +19.6 dB, C6 +13.1 → +9.8),
    // so the hammer is held by the median over the five keys, as the fundamental is:
    // - the level's rise no less than the recording's less 5 dB at any key, and more than the
    //   recording's by at most 5 dB on median (+2.5; on Table 1's board +5.8: its A4 and C6
    //   rose 6.6 and 8.9 dB more than recorded); at C4 +20 … +25 dB (issue 17; Goncalves 2014,
    //   one key: 23 dB; the recording's layers are one sampler's choice of touch, which plays
    //   layer 2 10.2 dB softer than recorded: 24.7 dB at C4);
    // - the brightening within 10 dB of the recording's (+17.6 … +37.5 dB) on median (7.6 short;
    //   C6 12.0, the felt's pianissimo too bright there: docs/realism.md#dynamics);
    // - ff's 2–4 kHz band re the whole within 8 dB of the recording's at every key.
    // The paper keyboard (its felts, p = 2.2–3.2) fails each: C2's ff band 15.2 dB dark, C4's
    // rise +19.4 dB, the brightening 10.4 dB from the recording's on median (13.3 at F#3).
    use unacorda::analysis::struck::{recorded_pp_and_ff, TOUCH_KEYS};
    let touches = concert_touches(&TOUCH_KEYS);
    let (mut louder_db, mut brighter_db) = (Vec::new(), Vec::new());
    for (&k, [pp, ff]) in TOUCH_KEYS.iter().zip(&touches) {
        let [rp, rf] = recorded_pp_and_ff(k).unwrap();
        let rise_db = ff.a_level_db - pp.a_level_db;
        let recorded_rise_db = rf.a_level_db - rp.a_level_db;
        let brighter = ff.octave_shape_db[5] - pp.octave_shape_db[5];
        let recorded_brighter = rf.octave_shape_db[5] - rp.octave_shape_db[5];
        println!(
            "{}: level {rise_db:+.1} dB (recorded {recorded_rise_db:+.1}); 2–4 kHz re all {:+.1} → {:+.1} dB, {brighter:+.1} (recorded {:+.1} → {:+.1}, {recorded_brighter:+.1})",
            unacorda::board::key_name(k),
            pp.octave_shape_db[5],
            ff.octave_shape_db[5],
            rp.octave_shape_db[5],
            rf.octave_shape_db[5],
        );
        assert!(
            rise_db >= recorded_rise_db - 5.0,
            "key {k}: level rise {rise_db:.1} dB"
        );
        if k == 40 {
            assert!(
                (20.0..=25.0).contains(&rise_db),
                "C4's level rise: issue 17"
            );
        }
        assert!(
            (ff.octave_shape_db[5] - rf.octave_shape_db[5]).abs() <= 8.0,
            "key {k}: ff's 2–4 kHz band"
        );
        louder_db.push(rise_db - recorded_rise_db);
        brighter_db.push((brighter - recorded_brighter).abs());
    }
    let (louder_db, brighter_db) = (median(&mut louder_db), median(&mut brighter_db));
    println!(
        "median over the five keys: the level rises {louder_db:+.1} dB more than recorded (limit 5), the brightening {brighter_db:.1} dB from the recording's (limit 10)"
    );
    assert!(louder_db <= 5.0);
    assert!(brighter_db <= 10.0);
}
