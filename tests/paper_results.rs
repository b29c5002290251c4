//! The paper's findings (Figures 3–6) as numbers, on the c2 preset: una corda vs normal playing.

use std::sync::OnceLock;
use unacorda::analysis::spectral::{
    beating_depth_db, partial_envelope, peak_frequency, rms_envelope,
};
use unacorda::config::preset::{LoadedPreset, Preset};
use unacorda::engine::Strike;
use unacorda::render::{simulate, Recording};

const SECONDS: f64 = 3.0;
/// One period of C2 (s): envelopes over whole periods do not ripple with the waveform.
const PERIOD_S: f64 = 1.0 / 65.406;

struct Runs {
    preset: LoadedPreset,
    una_corda: Recording,
    normal: Recording,
}

fn runs() -> &'static Runs {
    static RUNS: OnceLock<Runs> = OnceLock::new();
    RUNS.get_or_init(|| {
        let preset = Preset::resolve("c2").expect("built-in preset");
        let v = preset.preset.hammer.velocity_m_s;
        let run = |una_corda| {
            simulate(
                &preset,
                Strike {
                    velocity_m_s: v,
                    shift: if una_corda { 1.0 } else { 0.0 },
                },
                None,
                SECONDS,
                |_| {},
            )
            .unwrap()
        };
        let (una_corda, normal) = std::thread::scope(|s| {
            let a = s.spawn(|| run(true));
            let b = s.spawn(|| run(false));
            (a.join().unwrap(), b.join().unwrap())
        });
        Runs {
            preset,
            una_corda,
            normal,
        }
    })
}

#[test]
fn recorded_frames_are_at_their_stated_times() {
    // The hammer force of string 1 (normal playing) straight from RK4 at 96 kHz, each step
    // observed after it is taken (step i shows t = (i + 1) h), against the decimated recording
    // read at `Recording::time_s`: the anti-alias filter passes the ~2 ms pulse unchanged, so
    // the two agree once the times are right; one output frame off they do not.
    use unacorda::engine::Rk4Pool;
    let r = runs();
    let mut raw = Rk4Pool::new(&r.preset.unison_spec()).unwrap();
    raw.strike(Strike {
        velocity_m_s: r.preset.preset.hammer.velocity_m_s,
        shift: 0.0,
    });
    let h = raw.step_s();
    let force: Vec<f64> = (0..(0.01 / h) as usize)
        .map(|_| {
            raw.step();
            raw.observe().hammer_force_n[0]
        })
        .collect();
    let at = |t: f64| -> f64 {
        let x = t / h - 1.0;
        let i = x.floor().max(0.0) as usize;
        let w = x - i as f64;
        force[i] * (1.0 - w) + force[i + 1] * w
    };
    let peak = force.iter().fold(0f64, |m, &x| m.max(x));
    let rec = &r.normal;
    let error = |shift: f64| -> f64 {
        (0..(0.008 * rec.rate_hz) as usize)
            .filter(|&k| rec.time_s(k) + shift > 0.0)
            .map(|k| (rec.frames[k].obs.hammer_force_n[0] - at(rec.time_s(k) + shift)).abs())
            .fold(0.0, f64::max)
            / peak
    };
    let (aligned, early) = (error(0.0), error(-1.0 / rec.rate_hz));
    println!(
        "hammer force, recording vs undecimated RK4 at the stated times: {aligned:.1e} of the peak ({early:.1e} read one frame early)"
    );
    assert!(aligned < 1e-3, "{aligned:e}");
    assert!(early > 10.0 * aligned);
}

/// Peak (N) and duration (ms) of the main contact pulse of a hammer-force channel.
fn pulse(rec: &Recording, string: usize) -> (f64, f64) {
    let f = rec.channel(|fr| fr.obs.hammer_force_n[string]);
    let peak = f.iter().fold(0f64, |m, &x| m.max(x));
    let on: Vec<usize> = f
        .iter()
        .enumerate()
        .filter(|(_, &x)| x > 0.01 * peak)
        .map(|(i, _)| i)
        .collect();
    let duration_ms = (on.last().unwrap() - on.first().unwrap()) as f64 / rec.rate_hz * 1e3;
    (peak, duration_ms)
}

#[test]
fn fig3_una_corda_hammer_force_is_higher_and_longer() {
    let r = runs();
    let (uc_peak, uc_ms) = pulse(&r.una_corda, 0);
    let (n1_peak, n1_ms) = pulse(&r.normal, 0);
    let (n2_peak, n2_ms) = pulse(&r.normal, 1);
    println!("Figure 3 — hammer–string contact force");
    println!("  una corda, string 1: peak {uc_peak:7.1} N, contact {uc_ms:5.2} ms");
    println!("  normal,    string 1: peak {n1_peak:7.1} N, contact {n1_ms:5.2} ms");
    println!("  normal,    string 2: peak {n2_peak:7.1} N, contact {n2_ms:5.2} ms");
    let unstruck = r
        .una_corda
        .channel(|f| f.obs.hammer_force_n[1])
        .iter()
        .fold(0f64, |m, &x| m.max(x.abs()));
    assert_eq!(
        unstruck, 0.0,
        "the unstruck string never touches the hammer"
    );
    // The paper gives no numbers for Figure 3, only its shape: una corda higher and longer than
    // each of the two equal forces of normal playing. The figures here (12.2 N for 3.23 ms
    // against 10.7 N for 2.83 ms) are the paper's model as an independent implementation of it
    // gives them too, to 1e-12 of the peak: a change of more than a percent is a change of the
    // model (a felt 10 % stiffer raises the peaks 3 %), and these limits say so.
    let (peak_ratio, time_ratio) = (uc_peak / n1_peak.max(n2_peak), uc_ms / n1_ms.max(n2_ms));
    println!("  una corda / normal: peak × {peak_ratio:.3}, contact × {time_ratio:.3}");
    assert!(
        (1.10..1.18).contains(&peak_ratio),
        "una corda peak × {peak_ratio} the per-string normal peak"
    );
    assert!(
        (1.10..1.18).contains(&time_ratio),
        "una corda contact × {time_ratio} as long"
    );
    assert!(
        (uc_peak / 12.18 - 1.0).abs() < 0.01,
        "una corda peak {uc_peak} N"
    );
    assert!(
        (n1_peak / 10.73 - 1.0).abs() < 0.01,
        "normal peak {n1_peak} N"
    );
    assert!(
        (n1_peak / n2_peak - 1.0).abs() < 0.01,
        "normal playing: two near-equal forces"
    );
}

#[test]
fn fig4_passive_string_force_rises_over_tens_of_ms() {
    let r = runs();
    let fs = r.una_corda.rate_hz;
    let f2 = r.una_corda.channel(|f| f.obs.bridge_force_n[1][0]);
    let (t, env) = rms_envelope(&f2[..(0.2 * fs) as usize], fs, PERIOD_S);
    println!(
        "Figure 4(b) — una corda, passive string 2, T bridge force, RMS over one period of C2:"
    );
    for (ti, e) in t.iter().zip(&env) {
        println!("  t = {:5.1} ms  {:9.4} N", ti * 1e3, e);
    }
    let early = env[0];
    let (k_max, max) = env
        .iter()
        .enumerate()
        .fold((0, 0f64), |b, (k, &e)| if e > b.1 { (k, e) } else { b });
    println!(
        "  first window {early:.4} N, maximum {max:.4} N at {:.1} ms",
        t[k_max] * 1e3
    );
    assert!(
        t[k_max] > 0.02,
        "the passive string's force peaks after the first tens of ms"
    );
    assert!(
        max > 3.0 * early,
        "and grows several-fold from its first window"
    );
    // In normal playing both strings are struck: string 2's force is largest at once.
    let n2 = r.normal.channel(|f| f.obs.bridge_force_n[1][0]);
    let (_, nenv) = rms_envelope(&n2[..(0.2 * fs) as usize], fs, PERIOD_S);
    let (n_max, nmax) = nenv
        .iter()
        .enumerate()
        .fold((0, 0f64), |b, (k, &e)| if e > b.1 { (k, e) } else { b });
    println!(
        "  normal playing, string 2: first window {:.4} N, maximum {nmax:.4} N at {:.1} ms",
        nenv[0],
        t[n_max] * 1e3
    );
    assert!(
        t[n_max] < t[k_max],
        "a struck string's force peaks before the passive one's"
    );
}

/// Partial frequencies of the total T force, measured on the normal run.
fn partials(r: &Runs, count: usize) -> Vec<f64> {
    let s = &r.preset.strings()[0];
    let fs = r.normal.rate_hz;
    let x = r.normal.channel(|f| f.obs.total_force_n[0]);
    let x = &x[(0.1 * fs) as usize..];
    let b = s.inharmonicity() * (s.length_m() / s.speaking_length_m).powi(2);
    let f0 = (s.tension_n / s.linear_density_kg_m).sqrt() / (2.0 * s.speaking_length_m);
    (1..=count)
        .map(|n| {
            let guess = n as f64 * f0 * (1.0 + b * (n * n) as f64).sqrt();
            peak_frequency(x, fs, guess - 8.0, guess + 8.0)
        })
        .collect()
}

#[test]
fn fig6_normal_playing_beats_una_corda_decays_evenly() {
    let r = runs();
    let fs = r.normal.rate_hz;
    let freqs = partials(r, 20);
    let depth = |rec: &Recording| -> Vec<f64> {
        let x = rec.channel(|f| f.obs.total_force_n[0]);
        let x = &x[(0.1 * fs) as usize..];
        freqs
            .iter()
            .map(|&f| {
                let (t, a) = partial_envelope(x, fs, f, 0.1, 0.02);
                beating_depth_db(&t, &a)
            })
            .collect()
    };
    let (uc, normal) = (depth(&r.una_corda), depth(&r.normal));
    println!("Figure 6 — beating depth of the total T force partials (dB RMS about a cubic fit of the level):");
    println!("  partial   freq Hz   una corda   normal");
    for (k, f) in freqs.iter().enumerate() {
        println!("  {:7} {:9.2} {:10.2} {:8.2}", k + 1, f, uc[k], normal[k]);
    }
    let median = |v: &[f64]| {
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        0.5 * (s[s.len() / 2] + s[(s.len() - 1) / 2])
    };
    let (mu, mn) = (median(&uc), median(&normal));
    println!("  median: una corda {mu:.2} dB, normal {mn:.2} dB");
    // Normal playing's partials beat by several dB (5.48 here), una corda's barely (0.24): a
    // beat of 1 dB is already plain to hear, and an even decay leaves well under half a dB.
    assert!(mn > 4.0, "normal playing beats: {mn:.2} dB");
    assert!(mu < 0.5, "una corda decays evenly: {mu:.2} dB");
}

#[test]
fn fig5_aftersound_to_attack_is_larger_with_una_corda() {
    let r = runs();
    let ratio = |rec: &Recording| {
        let fs = rec.rate_hz;
        let x = rec.channel(|f| f.obs.total_force_n[0]);
        let (_, env) = rms_envelope(&x, fs, 0.02);
        let attack = env[..10].iter().fold(0f64, |m, &e| m.max(e));
        let tail = &x[(2.0 * fs) as usize..(3.0 * fs) as usize];
        let after = (tail.iter().map(|v| v * v).sum::<f64>() / tail.len() as f64).sqrt();
        (attack, after, 20.0 * (after / attack).log10())
    };
    let (ua, uf, ur) = ratio(&r.una_corda);
    let (na, nf, nr) = ratio(&r.normal);
    println!("Figure 5 — total transmitted T force: attack (max 20 ms RMS, first 0.2 s) vs aftersound (RMS 2–3 s)");
    println!("  una corda: attack {ua:8.3} N, aftersound {uf:8.4} N, ratio {ur:6.1} dB");
    println!("  normal:    attack {na:8.3} N, aftersound {nf:8.4} N, ratio {nr:6.1} dB");
    assert!(na > 1.3 * ua, "normal playing transmits the larger attack");
    // Weinreich: with one string struck, the aftersound is larger relative to the attack (by
    // 2.7 dB here: −12.6 against −15.3 dB).
    assert!(
        (2.0..3.5).contains(&(ur - nr)),
        "aftersound relative to attack: una corda {ur:.1} dB, normal {nr:.1} dB"
    );
}
