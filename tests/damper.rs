//! Releasing a key drops the damper: the note dies within a fraction of a second; held, it rings.

use unacorda::analysis::spectral::rms_envelope;
use unacorda::config::preset::Preset;
use unacorda::config::scaling::Scaling;
use unacorda::engine::Strike;
use unacorda::render::simulate;

/// Level (dB) of the total T force in 50 ms windows at `times` (s).
fn levels_db(x: &[f64], fs: f64, times: &[f64]) -> Vec<f64> {
    let (t, env) = rms_envelope(x, fs, 0.05);
    times
        .iter()
        .map(|&want| {
            let k = t.iter().position(|&ti| ti >= want).unwrap_or(t.len() - 1);
            20.0 * env[k].max(1e-12).log10()
        })
        .collect()
}

#[test]
fn released_key_is_damped_held_key_rings() {
    let c2 = Preset::resolve("c2").unwrap();
    let strike = Strike {
        velocity_m_s: 2.5,
        shift: 0.0,
    };
    let held = simulate(&c2, strike, None, 1.0, |_| {}).unwrap();
    let released = simulate(&c2, strike, Some(0.3), 1.0, |_| {}).unwrap();
    let fs = held.rate_hz;
    let times = [0.25, 0.5, 0.75, 0.95];
    let h = levels_db(&held.channel(|f| f.obs.total_force_n[0]), fs, &times);
    let r = levels_db(&released.channel(|f| f.obs.total_force_n[0]), fs, &times);
    println!("c2, total T force level (dB re 1 N) in 50 ms windows:");
    println!("  t s     held   released at 0.3 s");
    for k in 0..times.len() {
        println!("  {:4.2} {:8.1} {:8.1}", times[k], h[k], r[k]);
    }
    let (held_drop, released_drop) = (h[0] - h[3], r[0] - r[3]);
    println!(
        "  drop from 0.25 s to 0.95 s: held {held_drop:.1} dB, released {released_drop:.1} dB"
    );
    assert!((h[0] - r[0]).abs() < 0.1, "identical until the release");
    assert!(held_drop < 15.0, "a held C2 rings on");
    assert!(
        released_drop > held_drop + 30.0,
        "the damper silences a released key"
    );
}

#[test]
fn top_keys_have_no_damper() {
    let keyboard = Scaling::resolve("paper").unwrap();
    let top = keyboard.key_preset(80).unwrap();
    let mut u = unacorda::engine::Rk4Pool::new(&top.unison_spec()).unwrap();
    u.set_damper(true);
    println!(
        "key 80 ({}): damper present {}, down after release {}",
        top.preset.name,
        top.preset.damper.present,
        u.damper_down()
    );
    assert!(!top.preset.damper.present && !u.damper_down());
    assert!(keyboard.key_preset(60).unwrap().preset.damper.present);
}

/// A released key of the concert keyboard dies as under a damper, not a cut, and every partial
/// dies with it: the felt touches the strings at two points, so none with a node under it escapes
/// (a point felt at 0.16 lets C2's partials 6, 12 and 13 fall 6-9 dB in 0.6 s). Partials 1-24
/// within 50 dB of the strongest are measured over 0.2 s before the damper lands at 1.0 s and
/// 0.4-0.6 s after: each must fall 15 dB (a T60 under 2.4 s).
#[test]
fn the_concert_damper_silences_every_partial_of_a_released_key() {
    use unacorda::analysis::listening::{level_change_db, peaks};
    use unacorda::analysis::struck::pressure;
    use unacorda::engine::tuning::stiff_string_hz;
    let keyboard = Scaling::resolve("concert").unwrap();
    println!("key  0.1 s after  partial: level before / after (dB re the strongest before)");
    for (name, key) in [("C2", 16), ("F3", 33), ("C4", 40), ("C6", 64)] {
        let preset = keyboard.key_preset(key).unwrap();
        let (fs, x) = pressure(&preset, 2.5, 1.6, Some(1.0)).unwrap();
        let b = preset
            .preset
            .strings
            .nominal_string()
            .speaking_inharmonicity();
        let law = stiff_string_hz(keyboard.target_hz(key), b);
        let freqs: Vec<f64> = (1..=24).map(&law).take_while(|&f| f < 9000.0).collect();
        let half = 0.25 * freqs[0];
        let before = peaks(&x, fs, (0.8, 1.0), &freqs, half);
        let after = peaks(&x, fs, (1.4, 1.6), &freqs, half);
        let strongest = before.iter().map(|p| p.level_db).fold(f64::MIN, f64::max);
        let heard: Vec<usize> = (0..freqs.len())
            .filter(|&n| before[n].level_db > strongest - 50.0)
            .collect();
        let first = level_change_db(&x, fs, 1.0, 0.1);
        let line: Vec<String> = heard
            .iter()
            .map(|&n| {
                let (b, a) = (before[n].level_db, after[n].level_db);
                format!("{}:{:.0}/{:.0}", n + 1, b - strongest, a - strongest)
            })
            .collect();
        println!("{name} {first:+7.1} dB   {}", line.join(" "));
        let (worst, least) = heard
            .iter()
            .map(|&n| (n + 1, before[n].level_db - after[n].level_db))
            .fold((0, f64::MAX), |w, d| if d.1 < w.1 { d } else { w });
        assert!(
            least > 15.0,
            "{name}: partial {worst} escapes the damper ({least:.1} dB in 0.6 s)"
        );
        if name == "C6" {
            assert!(
                (-20.0..=-10.0).contains(&first),
                "C6 falls {first:.1} dB in the 0.1 s after release (a damper: -10...-20)"
            );
        }
    }
}
