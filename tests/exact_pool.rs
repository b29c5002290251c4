//! The exact engine's pool against the paper's RK4 pool: keys coupled through the shared board.
//!
//! - Sympathy: C2 struck, C3 held silent (its damper lifted), moved only through the board: C3's
//!   bridge force within 0.5 dB of RK4's in every half second over 2 s.
//! - Stability with every key of the keyboard sounding at once: all 88 struck together, dampers
//!   up, then down: the pool's energy never rises and falls once the dampers drop (a runaway of
//!   the coupling — the board's modes above 4 kHz coupling the keys — grows by 290 dB in 0.4 s).
//! - By hand (ignored): A0 struck with the 87 other keys held, every key against RK4.
//!
//! The nine-key chord against RK4 is in `tests/stability.rs`.

use unacorda::config::scaling::{parse_key, Scaling, KEYS};
use unacorda::engine::exact::ExactPool;
use unacorda::engine::{Policy, Rk4Pool, Strike, VoicePool};

/// Bridge force T of each of `keys`' voices at the output rate for `seconds`, the first key struck
/// at 3 m/s, the others held silent (dampers lifted).
fn forces<E: VoicePool>(keys: &[&str], seconds: f64) -> (Vec<Vec<f64>>, f64) {
    let scaling = Scaling::resolve("paper").unwrap();
    let rate = scaling.base.output_rate_hz();
    let specs: Vec<_> = keys
        .iter()
        .map(|k| {
            scaling
                .key_preset(parse_key(k).unwrap())
                .unwrap()
                .unison_spec()
        })
        .collect();
    let mut pool = E::build_pool(&specs, keys.len(), rate).unwrap();
    for k in 0..keys.len() {
        pool.assign(k, k);
        pool.set_active(k, true);
    }
    pool.strike_voice(
        0,
        Strike {
            velocity_m_s: 3.0,
            shift: 0.0,
        },
    );
    let per = (1.0 / (rate * pool.step_s())).round() as usize;
    let mut scratch = vec![[0.0; 2]; per];
    let mut out = vec![Vec::new(); keys.len()];
    for _ in 0..(seconds * rate) as usize {
        pool.run(&mut scratch, None);
        for (k, o) in out.iter_mut().enumerate() {
            o.push(pool.observe_voice(k).total_force_n[0]);
        }
    }
    (out, rate)
}

/// Level (dB re 1 N) of `x` in windows of `window_s`.
fn levels(x: &[f64], rate: f64, window_s: f64) -> Vec<f64> {
    x.chunks((window_s * rate) as usize)
        .map(|w| 10.0 * (w.iter().map(|v| v * v).sum::<f64>() / w.len() as f64).log10())
        .collect()
}

#[test]
fn a_held_key_rings_in_sympathy_as_on_rk4() {
    let keys = ["C2", "C3"];
    let (rk4, rate) = forces::<Rk4Pool>(&keys, 2.0);
    let (exact, _) = forces::<ExactPool>(&keys, 2.0);
    let mut worst: f64 = 0.0;
    for (k, name) in keys.iter().enumerate() {
        let (a, b) = (levels(&rk4[k], rate, 0.5), levels(&exact[k], rate, 0.5));
        let d: Vec<f64> = a.iter().zip(&b).map(|(a, b)| b - a).collect();
        println!(
            "{name} bridge force T per half second, RK4 {:.2?} dB re 1 N, exact - RK4 {d:+.3?} dB",
            a
        );
        // A NaN (a runaway) is the worst of all.
        worst = d.iter().fold(worst, |m, x| {
            if x.is_nan() {
                f64::INFINITY
            } else {
                m.max(x.abs())
            }
        });
    }
    println!("C2 struck, C3 moved through the board: worst half second {worst:.3} dB from RK4 (limit 0.5)");
    assert!(worst < 0.5, "{worst}");
}

/// Every key struck at once at 3 m/s, dampers lifted for `up_s`, then down for `down_s`: the
/// pool's energy (J) every 0.05 s.
fn every_key(up_s: f64, down_s: f64) -> Vec<f64> {
    let scaling = Scaling::resolve("paper").unwrap();
    let rate = scaling.base.output_rate_hz();
    let specs: Vec<_> = (1..=KEYS)
        .map(|k| scaling.key_preset(k).unwrap().unison_spec())
        .collect();
    let mut pool = ExactPool::build_pool(&specs, KEYS, rate).unwrap();
    for k in 0..KEYS {
        pool.assign(k, k);
        pool.strike_voice(
            k,
            Strike {
                velocity_m_s: 3.0,
                shift: 0.0,
            },
        );
    }
    let mut energy = Vec::new();
    let mut block = vec![[0.0; 2]; (0.05 * rate) as usize];
    for b in 0..((up_s + down_s) / 0.05).round() as usize {
        if b == (up_s / 0.05).round() as usize {
            (0..KEYS).for_each(|k| pool.set_damper_voice(k, true));
        }
        pool.run(&mut block, None);
        energy.push(pool.mechanical_energy_j());
    }
    energy
}

#[test]
fn every_key_struck_at_once_rings_and_is_damped() {
    let (up_s, down_s) = (0.25, 0.2);
    let energy = every_key(up_s, down_s);
    let db: Vec<f64> = energy
        .iter()
        .map(|e| 10.0 * (e / energy[0]).log10())
        .collect();
    println!("88 keys struck at once, dampers up {up_s} s then down {down_s} s: energy every 0.05 s re the first {db:.2?} dB");
    // A runaway of the coupling (the modes above 4 kHz coupling, or the other keys' motion held
    // over the step) grows by orders of magnitude within a few hundred milliseconds.
    let up = (up_s / 0.05).round() as usize;
    assert!(
        db[..up].iter().all(|&d| d <= 0.5),
        "rose with the dampers up: {db:?}"
    );
    assert!(
        db[up..].windows(2).all(|w| w[1] < w[0]),
        "rose with the dampers down: {db:?}"
    );
    // The top 19 keys have no damper and ring on.
    assert!(
        *db.last().unwrap() < db[up - 1] - 12.0,
        "the dampers did not silence it: {db:?}"
    );
}

/// Run by hand (`cargo test --release --test exact_pool -- --ignored`, ~5 min): A0 struck, the
/// other 87 keys held silent, 1 s on both pools; every key's bridge force per quarter second.
#[test]
#[ignore]
fn every_key_held_while_a0_rings() {
    let names: Vec<String> = (1..=KEYS).map(unacorda::board::key_name).collect();
    let keys: Vec<&str> = names.iter().map(|s| s.as_str()).collect();
    let (rk4, rate) = forces::<Rk4Pool>(&keys, 1.0);
    let (exact, _) = forces::<ExactPool>(&keys, 1.0);
    for k in 0..keys.len() {
        let (a, b) = (levels(&rk4[k], rate, 0.25), levels(&exact[k], rate, 0.25));
        let d: Vec<f64> = a.iter().zip(&b).map(|(a, b)| b - a).collect();
        println!("{} RK4 {a:.1?} exact - RK4 {d:+.2?}", keys[k]);
    }
}
