//! The exact engine — each key's coupled modes advanced exactly at the output rate of 48 kHz —
//! against the paper's RK4 at 96 kHz on c2, C4 and A0: partial frequencies (1 cent), decay rates
//! (2 %), hammer force peak (1 %), the spectrum of the force on the bridge (0.5 dB in third-octave
//! bands below 5 kHz), also with a hysteretic felt, the linearised system's eigenvalues and the
//! radiated sound through the renderer; a released key under the damper felt. (Sympathy and chords: `tests/exact_pool.rs`,
//! `tests/stability.rs`.)

use realfft::RealFftPlanner;
use unacorda::analysis::spectral::{partial_envelope, peak_frequency};
use unacorda::config::preset::Preset;
use unacorda::config::scaling::{parse_key, Scaling};
use unacorda::engine::exact::ExactUnison;
use unacorda::engine::{Observation, Rk4Pool, Strike, UnisonSpec};

const FS: f64 = 48_000.0;

struct Run {
    /// Largest felt force on string 1 (N).
    hammer_peak_n: f64,
    /// Total transverse force on the bridge, at 48 kHz.
    force_t: Vec<f64>,
    rate_hz: f64,
}

#[derive(Clone, Copy)]
enum Integrator {
    Rk4,
    Exact,
}

fn c2() -> UnisonSpec {
    Preset::resolve("c2").unwrap().unison_spec()
}

/// Key `name` of the paper's keyboard.
fn key(name: &str) -> UnisonSpec {
    keyboard_key("paper", name)
}

/// Key `name` of a built-in keyboard.
fn keyboard_key(keyboard: &str, name: &str) -> UnisonSpec {
    Scaling::resolve(keyboard)
        .unwrap()
        .key_preset(parse_key(name).unwrap())
        .unwrap()
        .unison_spec()
}

fn run(integrator: Integrator, spec: &UnisonSpec, una_corda: bool, seconds: f64) -> Run {
    let mut spec = spec.clone();
    let strike = Strike {
        velocity_m_s: 2.5,
        shift: if una_corda { 1.0 } else { 0.0 },
    };
    let mut step: Box<dyn FnMut() -> Observation> = match integrator {
        Integrator::Rk4 => {
            let mut inst = Rk4Pool::new(&spec).unwrap();
            inst.set_damper(false);
            inst.strike(strike);
            Box::new(move || {
                inst.step();
                inst.observe()
            })
        }
        Integrator::Exact => {
            spec.sample_rate_hz = FS;
            let mut inst = ExactUnison::new(&spec).unwrap();
            inst.strike(strike);
            Box::new(move || {
                inst.step();
                inst.observe()
            })
        }
    };
    let stride = (spec.sample_rate_hz / FS).round() as usize;
    let mut force_t = Vec::new();
    let mut hammer_peak_n = 0f64;
    for k in 0..(seconds * spec.sample_rate_hz) as usize {
        let o = step();
        hammer_peak_n = hammer_peak_n.max(o.hammer_force_n[0]);
        if k % stride == stride - 1 {
            force_t.push(o.total_force_n[0]);
        }
    }
    Run {
        hammer_peak_n,
        force_t,
        rate_hz: spec.sample_rate_hz,
    }
}

/// Level (dB) of `x` in third-octave bands from 50 Hz to 5 kHz.
fn band_levels_db(x: &[f64]) -> Vec<(f64, f64)> {
    third_octave_levels_db(x, 50.0, 5000.0)
}

/// [`third_octave_levels_db`] from 1 kHz to `last_hz` of `seconds` of `p` from sample `skip`,
/// faded out over its second half (a strike starts from silence: the onset needs no window).
fn faded_third_octaves_db(p: &[f64], skip: usize, seconds: f64, last_hz: f64) -> Vec<(f64, f64)> {
    let n = (seconds * FS) as usize;
    let x: Vec<f64> = p[skip..skip + n]
        .iter()
        .enumerate()
        .map(|(k, v)| {
            let t = k as f64 / n as f64 - 0.5;
            v * if t < 0.0 {
                1.0
            } else {
                (std::f64::consts::PI * t).cos().powi(2)
            }
        })
        .collect();
    third_octave_levels_db(&x, 1000.0, last_hz)
}

/// Level (dB) of `x` (at 48 kHz) in third-octave bands centred from `first_hz` to `last_hz`.
fn third_octave_levels_db(x: &[f64], first_hz: f64, last_hz: f64) -> Vec<(f64, f64)> {
    let n = x.len();
    let mut planner = RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(n);
    let mut input: Vec<f64> = x.to_vec();
    let mut spectrum = fft.make_output_vec();
    fft.process(&mut input, &mut spectrum).unwrap();
    let df = FS / n as f64;
    let mut bands = Vec::new();
    let mut centre = first_hz;
    while centre <= last_hz * 1.001 {
        let (lo, hi) = (centre / 2f64.powf(1.0 / 6.0), centre * 2f64.powf(1.0 / 6.0));
        let power: f64 = spectrum
            .iter()
            .enumerate()
            .filter(|(k, _)| (lo..hi).contains(&(*k as f64 * df)))
            .map(|(_, c)| c.norm_sqr())
            .sum();
        bands.push((centre, 10.0 * power.max(1e-300).log10()));
        centre *= 2f64.powf(1.0 / 3.0);
    }
    bands
}

/// How far `fast` is from `reference`: hammer peak (relative), partials 1–20 (cents), decay
/// rates of partials 1–10 (relative, to at least 0.5 dB/s), third-octave bands of the bridge T
/// force (dB).
struct Distance {
    hammer: f64,
    cents: f64,
    decay: f64,
    band_db: f64,
}

/// Compare two runs of `spec`'s key; each partial is sought within 1 % of Eq. 2's frequency for
/// string 1's speaking length (stiff strings' partials run sharp of n f1).
fn distance(spec: &UnisonSpec, reference: &Run, fast: &Run) -> Distance {
    let hammer = fast.hammer_peak_n / reference.hammer_peak_n - 1.0;
    println!(
        "  hammer force peak {:.3} N vs {:.3} N ({:+.3} %)",
        reference.hammer_peak_n,
        fast.hammer_peak_n,
        100.0 * hammer
    );
    // Partials 1–20: frequency and decay rate, from 0.1 s on.
    let skip = (0.1 * FS) as usize;
    let (xr, xf) = (&reference.force_t[skip..], &fast.force_t[skip..]);
    let (mut cents_worst, mut decay_worst) = (0f64, 0f64);
    for n in 1..=20 {
        // The speaking length's partial n (the bridge holds the string nearly still there).
        let speaking = unacorda::engine::physics::string::StringParams {
            duplex_length_m: 0.0,
            ..spec.strings[0].clone()
        };
        let nominal = speaking.transverse_omega(n) / (2.0 * std::f64::consts::PI);
        if nominal > 5000.0 {
            break;
        }
        let (lo, hi) = (nominal * 0.99, nominal * 1.01);
        let (fr, ff) = (
            peak_frequency(xr, FS, lo, hi),
            peak_frequency(xf, FS, lo, hi),
        );
        let cents = 1200.0 * (ff / fr).log2();
        cents_worst = cents_worst.max(cents.abs());
        if n <= 10 {
            let slope = |x: &[f64], f: f64| {
                let (t, a) = partial_envelope(x, FS, f, 0.1, 0.05);
                let db: Vec<f64> = a.iter().map(|v| 20.0 * v.log10()).collect();
                let (mt, md) = (
                    t.iter().sum::<f64>() / t.len() as f64,
                    db.iter().sum::<f64>() / db.len() as f64,
                );
                let num: f64 = t.iter().zip(&db).map(|(t, d)| (t - mt) * (d - md)).sum();
                let den: f64 = t.iter().map(|t| (t - mt).powi(2)).sum();
                num / den
            };
            // Relative to the slope, or to 0.5 dB/s where it is smaller: a partial whose envelope
            // barely moves in the window is one of a unison's beating modes (C4's partial 5,
            // -0.2 dB/s), and a slope near zero is no measure of its decay.
            let (sr, sf) = (slope(xr, fr), slope(xf, ff));
            let rel = (sf - sr).abs() / sr.abs().max(0.5);
            decay_worst = decay_worst.max(rel);
            if n <= 3 || rel > 0.02 {
                println!("  partial {n}: {fr:.3} Hz vs {ff:.3} Hz ({cents:+.4} cents), decay {sr:.2} vs {sf:.2} dB/s");
            }
        }
    }
    // Spectrum of the bridge force, third-octave bands 50 Hz – 5 kHz, whole run.
    let (br, bf) = (
        band_levels_db(&reference.force_t),
        band_levels_db(&fast.force_t),
    );
    let (band_db, at) = br
        .iter()
        .zip(&bf)
        .map(|((c, a), (_, b))| ((a - b).abs(), *c))
        .fold((0.0, 0.0), |m, x| if x.0 > m.0 { x } else { m });
    println!(
        "  partials: worst {cents_worst:.4} cents; decay rates of partials 1–10: worst {:.3} %; bridge T force bands: worst {band_db:.3} dB at {at:.0} Hz",
        100.0 * decay_worst
    );
    Distance {
        hammer,
        cents: cents_worst,
        decay: decay_worst,
        band_db,
    }
}

/// RK4 at the key's rate and `integrator` at 48 kHz, on two threads.
fn pair(integrator: Integrator, spec: &UnisonSpec, una_corda: bool, seconds: f64) -> (Run, Run) {
    std::thread::scope(|s| {
        let r = s.spawn(|| run(Integrator::Rk4, spec, una_corda, seconds));
        let f = s.spawn(|| run(integrator, spec, una_corda, seconds));
        (r.join().unwrap(), f.join().unwrap())
    })
}

#[test]
fn exact_engine_at_48_khz_matches_rk4_at_96_khz_on_c2_c4_and_a0() {
    // Issue 16's single-key gates: 1 % hammer peak, 1 cent (partials 1–20 below 5 kHz), 2 %
    // decay (partials 1–10), 0.5 dB in third-octave bands, over 1.2 s; c2 normal and una
    // corda, a trichord (C4) and a single string (A0). Limits: see the assertions.
    // And C4 with Stulov's hysteretic felt, whose force reads the strings' velocity under the
    // hammer (the exact engine's `r lambda` rows).
    let mut hysteretic = key("C4");
    hysteretic.hammer.hysteresis_s = 300e-6;
    for (name, spec, una_corda) in [
        ("c2 normal", c2(), false),
        ("c2 una corda", c2(), true),
        ("C4 (three strings)", key("C4"), false),
        ("A0 (one string)", key("A0"), false),
        ("C4, hysteretic felt (300 µs)", hysteretic, false),
    ] {
        let (reference, exact) = pair(Integrator::Exact, &spec, una_corda, 1.2);
        println!(
            "{name}: RK4 at {:.0} kHz vs the exact engine at 48 kHz",
            reference.rate_hz / 1e3
        );
        let d = distance(&spec, &reference, &exact);
        // Measured: hammer −0.41 % (C4), 0.16 cents (C4's partial 20 near 5.3 kHz, where RK4's
        // own phase error at 96 kHz is (omega h)^4 / 120 = 1e-4), decay 0.62 %, 0.07 dB.
        assert!(
            d.hammer.abs() < 0.01,
            "{name}: hammer peak {:+.3} %",
            100.0 * d.hammer
        );
        assert!(d.cents < 0.5, "{name}: {} cents", d.cents);
        assert!(d.decay < 0.02, "{name}: decay {} %", 100.0 * d.decay);
        assert!(d.band_db < 0.25, "{name}: {} dB", d.band_db);
    }
}

#[test]
fn exact_engines_modes_are_the_linearised_systems_eigenvalues() {
    // The exact engine's one-step map of one key on the board (its own modes, the shared board's,
    // the interface between: `analysis::stability`), against the paper's dense state matrix with
    // the contact forces folded in (`analysis::modes`, from `DenseUnison`): every oscillating mode
    // of the reference has a mode of the map beside it. The key's own modes are exact; the
    // interface with the shared board is not (`engine::exact::interface`: an error of
    // (omega h)^2 / 12 in the coupling), so the modes are held to half the gates above: the
    // ringing string modes (most of their energy in the strings, decaying slower than 100 /s)
    // within 0.5 cents and 1 % of their decay rate; the board's and the strongly damped ones
    // (the duplex segment's, 800–2700 /s) within 1 % of their eigenvalue. The concert keyboard's
    // C4 has losses that grow with frequency (b1 + b3 omega^2) and a lighter duplex felt.
    use unacorda::analysis::modes::linear_modes;
    use unacorda::analysis::stability::{one_step_map, step_eigenvalues};
    use unacorda::engine::exact::ExactPool;
    use unacorda::engine::{Policy, VoiceModes, VoicePool};
    for (name, spec) in [
        ("c2", c2()),
        ("C4", key("C4")),
        ("A0", key("A0")),
        ("C4 concert", keyboard_key("concert", "C4")),
    ] {
        let mut spec = spec;
        spec.sample_rate_hz = FS;
        let mut pool = ExactPool::build_pool(std::slice::from_ref(&spec), 1, FS).unwrap();
        // Every mode stepped (an unstruck key steps, by default, only those the board drives).
        pool.set_voice_modes(VoiceModes::All);
        pool.assign(0, 0);
        pool.set_active(0, true);
        let (map, state) = one_step_map(&pool);
        let order = map.nrows();
        let engine = step_eigenvalues(map, &state, 1.0 / FS);
        let exact = linear_modes(&spec).unwrap();
        let (mut cents, mut decay, mut others) = (0f64, 0f64, 0f64);
        for m in exact.iter().filter(|m| m.freq_hz < 0.45 * FS) {
            let nearest = engine
                .iter()
                .min_by(|a, b| {
                    let d = |e: &&unacorda::analysis::stability::StepEigen| {
                        (e.freq_hz - m.freq_hz)
                            .hypot((-e.rate_per_s - m.decay_per_s) / std::f64::consts::TAU)
                    };
                    d(a).total_cmp(&d(b))
                })
                .unwrap();
            let df = 1200.0 * (nearest.freq_hz / m.freq_hz).log2();
            let dd = (-nearest.rate_per_s / m.decay_per_s - 1.0).abs();
            if m.shares[3] < 0.5 && m.decay_per_s < 100.0 {
                cents = cents.max(df.abs());
                decay = decay.max(dd);
            } else {
                // A mode that rings a few cycles at most: its eigenvalue's distance re its size.
                let w = 2.0 * std::f64::consts::PI;
                let d =
                    (w * (nearest.freq_hz - m.freq_hz)).hypot(-nearest.rate_per_s - m.decay_per_s);
                others = others.max(d / (w * m.freq_hz).hypot(m.decay_per_s));
            }
        }
        println!(
            "{name}: {} modes of the linearised system, a one-step map of order {}; ringing string modes: worst {cents:.3} cents, decay {:.2} %; the others' eigenvalues within {:.2} %",
            exact.len(),
            order,
            100.0 * decay,
            100.0 * others
        );
        assert!(cents < 0.5 && decay < 0.01 && others < 0.01, "{name}");
    }
}

#[test]
fn the_radiated_sound_agrees_through_the_renderer() {
    // The same through `simulate_with` (what `render --offline --integrator` runs): RK4 at 96 kHz
    // decimated to 48 kHz through the anti-alias FIR (a delay of 0.72 ms), and the exact engine at
    // 48 kHz (no filter), radiated pressure 0.1–1 s. Compared as waveforms, Hann-windowed, after the
    // relative delay that best aligns them (found from the cross-spectrum, sub-sample), and in
    // third-octave bands (which no delay changes). The paper's C2 heard as the monopole of the
    // board's net volume velocity, and the concert C4 in stereo, each channel at its listener
    // (each board mode by its Rayleigh integral there: the weights on the modes' velocities and
    // displacements).
    let concert_c4 = Scaling::resolve("concert").unwrap().key_preset(40).unwrap();
    assert!(concert_c4.board.is_stereo() && concert_c4.board.heard[0].is_some());
    // The paper's C2 agrees to -51 dB as waveforms (2.7e-3 measured) and to 0.03 dB in bands;
    // the concert C4 to 2.2e-2 and 0.77 dB at the bass listener, 1.3e-2 and 0.70 dB at the
    // treble one. C4's worst bands are 3.2 and 4 kHz, where the exact engine is 0.33 and
    // 0.77 dB over RK4 in the pressure and 0.32 and 0.73 dB in its force on the bridge (the
    // interface's force linear over a step): the radiation adds nothing. Its pressure agreed to
    // 0.52 dB while a step-to-step difference took the exact engine's source 0.1 dB under RK4's
    // at 4 kHz and the shared board's forces linear over a step another 0.2 (both undone now,
    // `audio::radiate`, `engine::exact::interface`): two errors cancelling. Those limits guard
    // what is measured; the c2 case is the tight one.
    let c2 = Preset::resolve("c2").unwrap();
    let (left, right): (Channel, Channel) = (|f| f.pressure_pa, |f| f.pressure_right_pa);
    for (name, preset, channel, waveform, band_db) in [
        ("C2 paper", &c2, left, 5e-3, 0.1),
        ("C4 concert, left (bass)", &concert_c4, left, 4e-2, 1.0),
        ("C4 concert, right (treble)", &concert_c4, right, 4e-2, 1.0),
    ] {
        agree_through_the_renderer(name, preset, channel, waveform, band_db);
    }
}

/// One channel of a recording's frames.
type Channel = fn(&unacorda::render::Frame) -> f64;

fn agree_through_the_renderer(
    name: &str,
    preset: &unacorda::config::preset::LoadedPreset,
    channel: Channel,
    waveform: f64,
    band_db: f64,
) {
    use unacorda::engine::Integrator;
    use unacorda::render::simulate_with;
    let strike = Strike {
        velocity_m_s: 2.5,
        shift: 0.0,
    };
    let window = |integrator| {
        let rec = simulate_with(preset, integrator, strike, None, 1.0, |_| {}).unwrap();
        let p = rec.channel(channel);
        let x = &p[(0.1 * rec.rate_hz) as usize..(0.1 * rec.rate_hz) as usize + 43_200];
        let n = x.len() as f64;
        let hann: Vec<f64> = x
            .iter()
            .enumerate()
            .map(|(k, v)| v * (std::f64::consts::PI * k as f64 / n).sin().powi(2))
            .collect();
        (hann, rec.pressure_delay_s)
    };
    let ((r, r_delay), (e, e_delay)) = (window(Integrator::Rk4), window(Integrator::Exact));
    let spectrum = |x: &[f64]| {
        let mut planner = RealFftPlanner::<f64>::new();
        let fft = planner.plan_fft_forward(x.len());
        let (mut input, mut out) = (x.to_vec(), fft.make_output_vec());
        fft.process(&mut input, &mut out).unwrap();
        out
    };
    let (pr, pe) = (spectrum(&r), spectrum(&e));
    let df = FS / r.len() as f64;
    let audible = |k: usize| (20.0..20_000.0).contains(&(k as f64 * df));
    // The residual of RK4's spectrum advanced by `tau` against the exact engine's.
    let residual = |tau: f64| -> f64 {
        let (mut diff, mut power) = (0.0, 0.0);
        for (k, (a, b)) in pr.iter().zip(&pe).enumerate().filter(|(k, _)| audible(*k)) {
            let w = 2.0 * std::f64::consts::PI * k as f64 * df;
            let shifted = a * faer::c64::new((w * tau).cos(), (w * tau).sin());
            diff += (shifted - b).norm_sqr();
            power += b.norm_sqr();
        }
        (diff / power).sqrt()
    };
    let (tau, err) = (-2000..=2000)
        .map(|i| i as f64 * 1e-6)
        .map(|tau| (tau, residual(tau)))
        .fold((0.0, f64::INFINITY), |m, x| if x.1 < m.1 { x } else { m });
    let bands = |x: &[f64]| band_levels_db(x);
    // Bands within 40 dB of the loudest: those holding partials (the empty ones between them,
    // 75 dB down, are window leakage).
    let (br, be) = (bands(&r), bands(&e));
    let loudest = br.iter().map(|b| b.1).fold(f64::NEG_INFINITY, f64::max);
    let worst_band = br
        .iter()
        .zip(&be)
        .filter(|((_, a), _)| *a > loudest - 40.0)
        .map(|((_, a), (_, b))| (a - b).abs())
        .fold(0.0, f64::max);
    println!(
        "{name}: radiated pressure 0.1–1 s, RK4 (filter delay {:.3} ms) vs the exact engine (delay {:.3} ms): best aligned {:.3} ms apart, waveform difference {err:.2e} of the sound ({:.1} dB); third-octave bands 50 Hz–5 kHz within 40 dB of the loudest agree to {worst_band:.3} dB",
        r_delay * 1e3,
        e_delay * 1e3,
        tau * 1e3,
        20.0 * err.log10()
    );
    // The FIR's delay is what separates them (to a quarter of a sample: the filter is linear
    // phase), and once aligned the two sound alike.
    assert!(
        (tau - (r_delay - e_delay)).abs() < 1e-5,
        "{name}: aligned {tau} s apart"
    );
    assert!(err < waveform, "{name}: waveform difference {err:.2e}");
    assert!(
        worst_band < band_db,
        "{name}: bands differ by {worst_band} dB"
    );
}

#[test]
fn both_engines_damp_a_released_key_alike() {
    // The damper felt's two contact points (concert keyboard) in both engines: RK4 at the key's
    // rate and the exact engine at 48 kHz through the renderer, the key released at 0.5 s; the
    // radiated level in 0.1 s windows from 0.4 s to 1.0 s (shorter ones see the partials beat
    // against the window: +-0.6 dB on C2 before the release), while it falls by tens of dB (C2
    // 29 dB, where held it falls 5.8: never released, this fails).
    use unacorda::analysis::spectral::rms_envelope;
    use unacorda::engine::Integrator;
    use unacorda::render::simulate_with;
    let keyboard = Scaling::resolve("concert").unwrap();
    let strike = Strike {
        velocity_m_s: 2.5,
        shift: 0.0,
    };
    for name in ["C2", "C4"] {
        let mut preset = keyboard.key_preset(parse_key(name).unwrap()).unwrap();
        // Heard as the monopole, so that the damper is what is compared (at the listener the
        // engines' held C2 differs by 0.5 dB already: its high board modes, the exact engine's
        // per key; `the_radiated_sound_agrees_through_the_renderer` compares them there).
        preset.board.heard = [None; 2];
        (
            preset.preset.radiation.listener,
            preset.preset.radiation.stereo,
        ) = (None, None);
        let level = |integrator| {
            let rec = simulate_with(&preset, integrator, strike, Some(0.5), 1.0, |_| {}).unwrap();
            let p = rec.channel(|f| f.pressure_pa);
            let (t, env) = rms_envelope(&p, rec.rate_hz, 0.1);
            t.iter()
                .zip(env)
                .filter(|(t, _)| (0.4..1.0).contains(*t))
                .map(|(_, e)| 20.0 * e.max(1e-15).log10())
                .collect::<Vec<f64>>()
        };
        let (r, e) = (level(Integrator::Rk4), level(Integrator::Exact));
        let n = r.len().min(e.len());
        let worst = (0..n).map(|k| (r[k] - e[k]).abs()).fold(0.0, f64::max);
        let fall = r[0] - r[n - 1];
        println!(
            "{name} released at 0.5 s: level falls {fall:.1} dB by 1.0 s (RK4); RK4 vs exact at most {worst:.3} dB apart in 0.1 s windows"
        );
        assert!(fall > 20.0, "{name}: the damper barely acts ({fall:.1} dB)");
        assert!(
            worst < 0.5,
            "{name}: the engines' dampers differ by {worst:.2} dB"
        );
    }
}

/// RK4's rate over the key's highest mode where its bands to 18 kHz no longer move at fortissimo
/// (`string_modes_to_20_khz_sound_without_aliasing`).
const RK4_CONVERGED_RATE_OVER_FMAX: f64 = 20.0;

#[test]
fn string_modes_to_20_khz_sound_without_aliasing() {
    // The concert keyboard keeps the string modes of C4-C8 to 20 kHz (`mode_limits`: C4's to
    // 19.9 kHz, Bb7's partials 1–4 to 17.3 kHz, C8's 1–3 to 14.0 kHz); here C4, C6, C7, Bb7 and
    // C8. The exact engine advances every mode exactly at 48 kHz, and the hammer's stages at
    // 48 kHz too; RK4 runs at 20 × the key's highest mode (336–432 kHz) and its output passes the
    // anti-alias FIR (flat to 20 kHz, −90 dB from 24 kHz) on the way to 48 kHz. Struck
    // fortissimo (6 m/s, the felt's shortest contact), the first 0.2 s, third-octave bands from 1
    // to 16 kHz (to 18 kHz) within 60 dB of the loudest (the next, to 20 kHz, where both filters
    // bend, left out):
    // - the force on the bridge, where the strings' modes to 20 kHz act, agrees within 1 dB
    //   (C4 0.05, C6 0.27, C7 0.16, Bb7 0.62, C8 0.31 dB). The top felts (p = 2) stay on the
    //   strings under 0.2 ms at 6 m/s, eight samples at 48 kHz, and the exact engine steps the
    //   contact in three substeps
    //   (`HammerParams::contact_substeps`); in one step of 48 kHz its ETDRK4 puts Bb7 30 dB off,
    //   and this fails. With Bb7's felt 300 times the paper's rather than 200, its
    //   partial 3 at 11 kHz, near a null of the contact's spectrum, came out 1.9 dB off;
    // - the pressure at the treble listener agrees within 0.5 dB from C4 to C7 (C4 0.08, C6 0.30,
    //   C7 0.11 dB) and 1 dB on the two hardest felts (Bb7 0.83, C8 0.81 dB: Bb7's 16 kHz band
    //   over as its force is). The shared board's modes take each key's force linear over a step
    //   (`engine::exact::interface`), which reaches their source as `x cot x` (`x = ωh/2`: the
    //   force's images, each through a mass-like mode), and a step-to-step difference of the
    //   source was `sinc x`: together the exact engine's pressure was once `sinc³` under RK4's
    //   (measured on Bb7 −1.1, −2.9, −5.1 dB at 8, 12.7, 16 kHz). The differentiator
    //   (`audio::radiate::Monopole`) now differentiates to 20 kHz, and the board's part of the
    //   exact engine's source passes a filter fitted to `tan x / x`
    //   (`engine::exact::interface::HeardSource`). Fitted to `1 / sinc²` (the first image alone;
    //   7 taps as it was) C4 and C6 come out 0.71 and 1.03 dB under at 12.7–16 kHz, and this
    //   fails; with the filter a pure delay C4's bands are 3.5 dB apart, and this fails. With the modes
    //   let through to 40 kHz (the band-edge refusal lifted), those above 24 kHz advance in the
    //   exact engine as their images below it would: Bb7's 16 kHz band came out 2.4 dB off, and
    //   this failed.
    use unacorda::engine::Integrator;
    use unacorda::render::simulate_with;
    let concert = Scaling::resolve("concert").unwrap();
    let strike = Strike {
        velocity_m_s: 6.0,
        shift: 0.0,
    };
    let force: Channel = |f| f.obs.total_force_n[0];
    let pressure: Channel = |f| f.pressure_right_pa;
    for key in [40, 64, 76, 86, 88] {
        let name = unacorda::board::key_name(key);
        let mut preset = concert.key_preset(key).unwrap();
        // The board's dropped modes set aside: the exact engine hears them as each key mode
        // rings, not in the attack's brief transient (`the_boards_dropped_modes_sound_alike_on_both_engines`).
        preset.board.residual = None;
        // The reference converged: RK4 at the paper's 10 × f_max is not, above 12 kHz, on a hard
        // felt at fortissimo (Bb7's force in the 16 kHz band 2.4 dB under its value at 20 and
        // 40 × f_max, which agree within 0.1 dB; C6's pressure there 0.5 dB under).
        preset.preset.simulation.min_rate_over_fmax = RK4_CONVERGED_RATE_OVER_FMAX;
        let f_max = preset.unison_spec().max_mode_freq_hz();
        assert!(f_max > 9600.0, "{name}: modes to {f_max} Hz");
        let recordings = [Integrator::Rk4, Integrator::Exact]
            .map(|i| simulate_with(&preset, i, strike, None, 0.25, |_| {}).unwrap());
        // 0.2 s of system time (each recording advanced by its delay: the anti-alias filter's,
        // and for the pressure the exact engine's source's and the differentiator's too), faded
        // out over its second half: the strike starts from silence, so the onset needs no window.
        let bands = |rec: &unacorda::render::Recording, what: &str, channel: Channel| {
            assert_eq!(rec.rate_hz, FS);
            let p = rec.channel(channel);
            let delay_s = match what {
                "pressure" => rec.pressure_delay_s,
                _ => rec.delay_s,
            };
            faded_third_octaves_db(&p, (delay_s * FS).round() as usize, 0.2, 16_000.0)
        };
        let mut heard_above = 0;
        for (what, channel) in [("bridge force", force), ("pressure", pressure)] {
            let [r, e] = [
                bands(&recordings[0], what, channel),
                bands(&recordings[1], what, channel),
            ];
            let loudest = r.iter().map(|b| b.1).fold(f64::NEG_INFINITY, f64::max);
            let mut worst: f64 = 0.0;
            for ((centre, a), (_, b)) in r.iter().zip(&e) {
                println!(
                    "{name} {what}: {centre:6.0} Hz band: RK4 {:+6.1} dB, exact {:+6.1} dB re the loudest",
                    a - loudest,
                    b - loudest
                );
                if *a > loudest - 60.0 {
                    worst = worst.max((b - a).abs());
                    heard_above += usize::from(*centre > 9600.0);
                }
            }
            println!(
                "{name} {what}: modes to {f_max:.0} Hz; bands within 60 dB of the loudest agree to {worst:.2} dB"
            );
            let limit = match what {
                "pressure" if key < 86 => 0.5,
                _ => 1.0,
            };
            assert!(worst < limit, "{name} {what}: {worst} dB");
        }
        assert!(heard_above >= 2, "{name}: nothing above 9.6 kHz");
    }
}

#[test]
fn the_boards_dropped_modes_sound_alike_on_both_engines() {
    // The concert keyboard's board keeps the modes the reduction dropped from 1.5 kHz up as a
    // residual (`SoundboardModes::residual`): driven by the key's force at its bridge point and
    // heard, not pushing back. RK4 carries them as oscillators; the exact engine passes each of
    // the key's modes' force through them at the mode's own eigenvalue (`DroppedModes`,
    // `engine::exact::key`), exact as the mode rings and blind to their own brief response to
    // the attack (their decay 1/(zeta w): 2 ms at 2.5 kHz). Struck at velocity 80, the first
    // 0.5 s at the treble listener (faded over its second half), third-octave bands from 1 to
    // 8 kHz: those within 20 dB of the loudest, where the partials are, agree within 1 dB (A4
    // 0.12, C6 0.15, C7 0.08, B7 0.03 dB), and what the dropped modes add (RK4 with and without
    // them, the loudest band: A4 +0.8, C6 +0.4, C7 +15.0, B7 +8.2 dB) is what each engine adds
    // within 1 dB (+0.8, +0.3, +15.1, +8.2). The exact engine without its residual read: A4's
    // bands 10.6 dB apart, and this fails. Between the partials, 20-30 dB under, the attack's
    // part differs by up to 3.4 dB (C6's 2.5 kHz band over the first 0.2 s at fortissimo).
    use unacorda::engine::Integrator;
    use unacorda::render::simulate_with;
    let concert = Scaling::resolve("concert").unwrap();
    let strike = Strike {
        velocity_m_s: unacorda::midi::hammer_speed_m_s(80.0).unwrap(),
        shift: 0.0,
    };
    for key in [49, 64, 76, 87] {
        let name = unacorda::board::key_name(key);
        let preset = concert.key_preset(key).unwrap();
        assert!(
            preset.unison_spec().dropped.is_some(),
            "{name}: no residual"
        );
        let mut bare = preset.clone();
        bare.board.residual = None;
        let bands = |preset: &unacorda::config::preset::LoadedPreset, i: Integrator| {
            let rec = simulate_with(preset, i, strike, None, 0.55, |_| {}).unwrap();
            let p = rec.channel(|f| f.pressure_right_pa);
            faded_third_octaves_db(
                &p,
                (rec.pressure_delay_s * FS).round() as usize,
                0.5,
                8000.0,
            )
        };
        let [r, e, r0] = [
            bands(&preset, Integrator::Rk4),
            bands(&preset, Integrator::Exact),
            bands(&bare, Integrator::Rk4),
        ];
        let loudest = |b: &[(f64, f64)]| b.iter().map(|x| x.1).fold(f64::NEG_INFINITY, f64::max);
        let top = loudest(&r);
        let mut worst: f64 = 0.0;
        for ((f, lr), (_, le)) in r.iter().zip(&e) {
            if *lr > top - 20.0 {
                worst = worst.max((lr - le).abs());
                println!(
                    "{name}: {f:6.0} Hz band: RK4 {:+.1} dB, exact {:+.1} dB re RK4's loudest",
                    lr - top,
                    le - top
                );
            }
        }
        let added = top - loudest(&r0);
        let added_exact = loudest(&e) - loudest(&r0);
        println!(
            "{name}: bands within 20 dB of the loudest agree to {worst:.2} dB; the dropped modes add {added:+.1} dB to the loudest band on RK4, {added_exact:+.1} on the exact engine"
        );
        assert!(worst < 1.0, "{name}: {worst:.2} dB");
        assert!(
            (added - added_exact).abs() < 1.0,
            "{name}: {added:+.1} against {added_exact:+.1} dB"
        );
    }
}
