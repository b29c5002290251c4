//! The soft pedal's depth: the action shifted part way, each string meeting another part of the
//! hammer's felt (`engine::physics::felt_profile`), from the normal strike to the paper's una
//! corda.

use unacorda::analysis::listening::spectral_centroid_hz;
use unacorda::config::preset::{LoadedPreset, Preset};
use unacorda::config::scaling::Scaling;
use unacorda::engine::exact::ExactUnison;
use unacorda::engine::{Integrator, Strike};
use unacorda::render::{simulate_with, Recording};

/// What a strike does, read from its recording.
#[derive(Debug, Clone, Copy)]
struct Blow {
    /// The summed felt force's peak (N), and how long it stays above 1/1000 of it (ms).
    peak_n: f64,
    contact_ms: f64,
    /// The peak of the force on the string the shift takes off the hammer, the last (N).
    last_n: f64,
    /// The left pressure's level over the first 0.5 s (dB re 1 Pa) and its spectral centroid
    /// over the first 0.3 s (Hz).
    level_db: f64,
    centroid_hz: f64,
}

/// The summed felt force's peak (N), and how long it stays above 1/1000 of it (ms).
fn contact(rec: &Recording) -> (f64, f64) {
    let force = rec.channel(|f| f.obs.hammer_force_n.iter().sum());
    let peak_n = force.iter().copied().fold(0.0, f64::max);
    let touching = force.iter().filter(|&&f| f > 1e-3 * peak_n).count();
    (peak_n, 1e3 * touching as f64 / rec.rate_hz)
}

/// The peaks of the summed felt force and of the last string's over the first 10 ms of `unison`
/// struck at 2.5 m/s with the action shifted by `shift` (N), at the engine's rate.
fn felt_peaks(unison: &ExactUnison, shift: f64, n_strings: usize) -> (f64, f64) {
    let mut unison = unison.clone();
    unison.strike(Strike {
        velocity_m_s: 2.5,
        shift,
    });
    let steps = (0.01 / unison.step_s()) as usize;
    (0..steps).fold((0.0f64, 0.0f64), |(sum_n, last_n), _| {
        unison.step();
        let f = unison.observe().hammer_force_n;
        (sum_n.max(f.iter().sum()), last_n.max(f[n_strings - 1]))
    })
}

/// The peak of the felt's force on string `s` (N).
fn string_peak_n(rec: &Recording, s: usize) -> f64 {
    rec.channel(|f| f.obs.hammer_force_n[s])
        .into_iter()
        .fold(0.0, f64::max)
}

/// A recording of at least 0.5 s.
fn blow(rec: &Recording, n_strings: usize) -> Blow {
    let (peak_n, contact_ms) = contact(rec);
    let last_n = string_peak_n(rec, n_strings - 1);
    let p = rec.channel(|f| f.pressure_pa);
    let n = (0.5 * rec.rate_hz) as usize;
    let level_db = 10.0 * (p[..n].iter().map(|x| x * x).sum::<f64>() / n as f64).log10();
    Blow {
        peak_n,
        contact_ms,
        last_n,
        level_db,
        centroid_hz: spectral_centroid_hz(&p, rec.rate_hz, (0.0, 0.3)),
    }
}

fn strike(preset: &LoadedPreset, integrator: Integrator, shift: f64, seconds: f64) -> Recording {
    let strike = Strike {
        velocity_m_s: 2.5,
        shift,
    };
    simulate_with(preset, integrator, strike, None, seconds, |_| {}).unwrap()
}

/// The depths the sweep visits: 0, 1/11, …, 1.
const DEPTHS: usize = 12;

/// How many times a step of the sweep is halved to tell a jump from a steep change.
const HALVINGS: usize = 12;

fn sweep(name: &str, preset: &LoadedPreset) -> Vec<Blow> {
    println!("{name} at 2.5 m/s, exact engine:");
    println!("  shift  peak N  last string N  contact ms  level dB  centroid Hz");
    (0..DEPTHS)
        .map(|i| {
            let shift = i as f64 / (DEPTHS - 1) as f64;
            let rec = strike(preset, Integrator::Exact, shift, 0.5);
            let b = blow(&rec, preset.preset.strings.count);
            println!(
                "  {shift:.3}  {:6.2}  {:13.2}  {:10.3}  {:8.2}  {:11.1}",
                b.peak_n, b.last_n, b.contact_ms, b.level_db, b.centroid_hz
            );
            b
        })
        .collect()
}

/// The depths' blows on c2 (the paper's bichord) and the concert keyboard's C4 (a trichord).
fn keys() -> [(&'static str, LoadedPreset); 2] {
    [
        ("c2 (the paper's bichord)", Preset::resolve("c2").unwrap()),
        (
            "concert C4 (a trichord)",
            Scaling::resolve("concert").unwrap().key_preset(40).unwrap(),
        ),
    ]
}

/// Across the pedal's travel the last string's blow weakens to nothing without a jump: it
/// leaves its groove for softer felt, then rounds the hammer's shoulder and leaves it. The
/// other strings' felt softens and hardens again as they cross to their neighbours' grooves, so
/// the summed force, the contact, the level and the centroid are printed and held only where
/// the model says which way they go: the summed force moves without a jump, and on the
/// trichord the level falls (within 0.05 dB: once the last string is gone, the struck strings
/// re-entering the grooves raise it by a few hundredths of a decibel).
#[test]
fn the_soft_pedals_depth_weakens_the_strike_continuously() {
    for (name, preset) in keys() {
        let n_strings = preset.preset.strings.count;
        let blows = sweep(name, &preset);
        assert_eq!(
            blows[DEPTHS - 1].last_n,
            0.0,
            "{name}: the last string struck at the full shift"
        );
        for w in blows.windows(2) {
            assert!(
                w[1].last_n <= w[0].last_n,
                "{name}: the last string's blow grows"
            );
            if n_strings == 3 {
                assert!(
                    w[1].level_db <= w[0].level_db + 0.05,
                    "{name}: the level rises from {:.3} to {:.3} dB",
                    w[0].level_db,
                    w[1].level_db
                );
            }
        }
        // Continuous: each step of the sweep is halved twelve times, each time keeping the half
        // in which the summed peak force moves more, down to 1/45 056 of the travel. A smooth
        // change there moves as its slope says; a jump moves whole, however short the step.
        // The last half's slope is held within 8 times the sweep's steepest (a jump of 0.02 N
        // would show as ~15 times), on every step whose first halves move at all (0.1 % of the
        // whole travel's change). The last string's blow keeps falling at every point visited.
        let travel_n = (blows[0].peak_n - blows[DEPTHS - 1].peak_n).abs();
        let width = 1.0 / (DEPTHS - 1) as f64;
        let steepest = blows
            .windows(2)
            .map(|w| (w[1].peak_n - w[0].peak_n).abs() / width)
            .fold(0.0, f64::max);
        let mut spec = preset.unison_spec();
        spec.sample_rate_hz = preset.output_rate_hz();
        let unison = ExactUnison::new(&spec).unwrap();
        let at = |shift: f64| {
            let (sum_n, last_n) = felt_peaks(&unison, shift, n_strings);
            (shift, sum_n, last_n)
        };
        let mut worst: f64 = 0.0;
        for i in 0..DEPTHS - 1 {
            let (mut a, mut b) = (at(i as f64 * width), at((i + 1) as f64 * width));
            for halving in 0..HALVINGS {
                let mid = at(0.5 * (a.0 + b.0));
                assert!(
                    mid.2 <= a.2 && b.2 <= mid.2,
                    "{name}: the last string's blow grows about {:.4}",
                    mid.0
                );
                let (left, right) = ((mid.1 - a.1).abs(), (b.1 - mid.1).abs());
                if halving == 0 && left.max(right) < 1e-3 * travel_n {
                    break;
                }
                if left > right {
                    b = mid;
                } else {
                    a = mid;
                }
                if halving == HALVINGS - 1 {
                    let slope = left.max(right) / (b.0 - a.0) / steepest;
                    worst = worst.max(slope);
                    assert!(
                        slope < 8.0,
                        "{name}: a jump in the peak force about {:.5}: {:.4} to {:.4} N",
                        a.0,
                        a.1,
                        b.1
                    );
                }
            }
        }
        println!(
            "{name}: halved twelve times, the last half's slope at most {worst:.2} times the sweep's steepest ({steepest:.1} N per full shift)"
        );
    }
}

/// At both ends only the grooves matter: the normal strike and the una corda are the same, bit
/// for bit, whatever the unworn felt between the grooves is like (a felt without grooves, as
/// hard everywhere, gives exactly what the default profile gives) — the hammer's own law, as
/// before the soft pedal had a depth; and at the full shift the last string is never touched.
#[test]
fn both_ends_are_the_normal_strike_and_the_papers_una_corda() {
    for (name, preset) in keys() {
        let mut plain = preset.clone();
        let felt = &mut plain.preset.hammer_felt;
        (
            felt.unworn_stiffness_ratio,
            felt.unworn_exponent_change,
            felt.groove_depth_m,
        ) = (1.0, 0.0, 0.0);
        for shift in [0.0, 1.0] {
            let a = strike(&preset, Integrator::Exact, shift, 0.1);
            let b = strike(&plain, Integrator::Exact, shift, 0.1);
            let same = a.frames.iter().zip(&b.frames).all(|(x, y)| {
                x.pressure_pa == y.pressure_pa && x.obs.hammer_force_n == y.obs.hammer_force_n
            });
            println!("{name} at shift {shift}: the same as with a felt without grooves: {same}");
            assert!(same, "{name} at shift {shift}");
        }
        let n = preset.preset.strings.count;
        let last = |shift| string_peak_n(&strike(&preset, Integrator::Exact, shift, 0.02), n - 1);
        let (near, full) = (last(0.9), last(1.0));
        println!(
            "{name}: the last string's peak force {near:.3} N at 0.9, {full} N at the full shift"
        );
        assert!(near > 0.0 && full == 0.0);
    }
}

/// RK4, the reference, meets each string's felt the same way: c2 part way (all strings on
/// unworn felt; the last one on the shoulder), the peak force within 0.3 % (they agree to under
/// 0.1 %) and the contact within one output sample (its resolution here).
#[test]
fn rk4_agrees_with_the_exact_engine_part_way() {
    let c2 = Preset::resolve("c2").unwrap();
    for shift in [0.5, 0.9] {
        let [(rk4_n, rk4_ms), (exact_n, exact_ms)] =
            [Integrator::Rk4, Integrator::Exact].map(|i| contact(&strike(&c2, i, shift, 0.02)));
        let force = (rk4_n / exact_n - 1.0).abs();
        println!(
            "c2 at shift {shift}: RK4 {rk4_n:.3} N, {rk4_ms:.3} ms; exact {exact_n:.3} N, {exact_ms:.3} ms ({force:.1e} apart)"
        );
        let sample_ms = 1e3 / c2.output_rate_hz();
        assert!(force < 3e-3 && (rk4_ms - exact_ms).abs() <= sample_ms * (1.0 + 1e-9));
    }
}

/// The hammer is launched touching the nearest felt (the unworn felt stands proud of the
/// grooves): one step after the strike its force is a few millinewtons, as in a groove; a hammer
/// launched inside the proud felt pushes at once with the force of its compression, more than
/// a newton. The limit, 0.01 N, is a few times the first.
#[test]
fn the_hammer_is_launched_touching_the_nearest_felt() {
    let c4 = Scaling::resolve("concert").unwrap().key_preset(40).unwrap();
    let mut spec = c4.unison_spec();
    spec.sample_rate_hz = c4.output_rate_hz();
    let unison = ExactUnison::new(&spec).unwrap();
    for shift in [0.0, 0.5, 0.9] {
        let mut struck = unison.clone();
        struck.strike(Strike {
            velocity_m_s: 2.5,
            shift,
        });
        struck.step();
        let first_n: f64 = struck.observe().hammer_force_n.iter().sum();
        let (peak_n, _) = felt_peaks(&unison, shift, 3);
        println!("C4 at shift {shift}: {first_n:.3} N one step after the strike, of a peak of {peak_n:.2} N");
        assert!(first_n < 0.01);
    }
}

/// A keyboard's `[hammer_felt]` reaches every key's hammer: a worn felt (deeper grooves,
/// softer between them) softens the mid-way strike more than the default one does, and leaves
/// both ends as they are.
#[test]
fn a_keyboards_hammer_felt_reaches_its_keys() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("worn.toml");
    std::fs::write(
        &path,
        "name = \"worn hammers\"\nbase_keyboard = \"concert\"\n\n[hammer_felt]\n\
         groove_depth_m = 0.0005\nunworn_stiffness_ratio = 0.4\nunworn_exponent_change = -0.5\n",
    )
    .unwrap();
    let worn = Scaling::resolve(path.to_str().unwrap())
        .unwrap()
        .key_preset(40)
        .unwrap();
    let concert = Scaling::resolve("concert").unwrap().key_preset(40).unwrap();
    assert_eq!(
        worn.unison_spec().hammer.profile.unworn_stiffness_ratio,
        0.4
    );
    let peak = |preset: &LoadedPreset, shift| {
        let mut spec = preset.unison_spec();
        spec.sample_rate_hz = preset.output_rate_hz();
        felt_peaks(&ExactUnison::new(&spec).unwrap(), shift, 3).0
    };
    let (normal, mid, worn_normal, worn_mid) = (
        peak(&concert, 0.0),
        peak(&concert, 0.5),
        peak(&worn, 0.0),
        peak(&worn, 0.5),
    );
    println!(
        "C4 at 2.5 m/s, mid-way / normal: default felt {mid:.2} / {normal:.2} N, worn felt {worn_mid:.2} / {worn_normal:.2} N"
    );
    assert_eq!(normal, worn_normal);
    assert!(worn_mid < mid && mid < normal);
}
