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
        una_corda: false,
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
