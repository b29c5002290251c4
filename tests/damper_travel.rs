//! The dampers between resting and clear: the sustain pedal's depth sets how far they are lifted
//! (half pedalling: a part-lifted felt touches lightly, then only the strings that still reach
//! it), and a key's release velocity how fast its damper lands.

use unacorda::analysis::listening::peaks;
use unacorda::config::scaling::{LoadedScaling, Scaling};
use unacorda::engine::exact::ExactPool;
use unacorda::engine::tuning::stiff_string_hz;
use unacorda::engine::{Rk4Pool, VoicePool, CHANNELS};
use unacorda::midi::{Event, Pedal};
use unacorda::play::Piano;

/// The concert keyboard's C4 struck at `velocity` with the sustain pedal at `depth`, released at
/// 0.3 s at the release velocity 64: the left channel's radiating source, at the engine's rate.
fn released_under_pedal<E: VoicePool>(
    piano: &Piano<E>,
    velocity: f64,
    depth: f64,
) -> (f64, Vec<f64>) {
    released(piano, velocity, depth, 64.0)
}

/// [`released_under_pedal`] with the key let go at the release velocity `release`.
fn released<E: VoicePool>(
    piano: &Piano<E>,
    velocity: f64,
    depth: f64,
    release: f64,
) -> (f64, Vec<f64>) {
    let mut piano = piano.clone();
    let fs = 1.0 / piano.instrument.step_s();
    let mut x = vec![];
    let mut block = vec![[0.0; CHANNELS]; 64];
    piano.apply(Event::Pedal {
        pedal: Pedal::Sustain,
        depth,
    });
    piano.apply(Event::NoteOn { note: 60, velocity });
    let total = (1.6 * fs) as usize;
    let at = (0.3 * fs) as usize;
    while x.len() < total {
        if x.len() == at {
            piano.apply(Event::NoteOff {
                note: 60,
                velocity: release,
            });
        }
        let end = if x.len() < at { at } else { total };
        let n = (end - x.len()).min(block.len());
        piano.instrument.run(&mut block[..n], None);
        x.extend(block[..n].iter().map(|s| s[0]));
    }
    (fs, x)
}

/// The frequencies of partials 1-8 of `key` (Hz): the stiff string's law at its tuned pitch.
fn partials(scaling: &LoadedScaling, key: usize) -> Vec<f64> {
    let b = scaling
        .key_preset(key)
        .unwrap()
        .preset
        .strings
        .nominal_string()
        .speaking_inharmonicity();
    let law = stiff_string_hz(scaling.target_hz(key), b);
    (1..=8).map(law).collect()
}

/// Partials 1-8's mean decay rates (dB/s) from the key held (0.1-0.3 s) to 0.5-0.6 s after the
/// strike: each mode's level falls the more the lower the felt, so these do too (a rate
/// between two windows after the release would not: a partial's felt-damped modes gone by the
/// first window under a resting felt make its later rate look slow).
fn decay_rates(x: &[f64], fs: f64, freqs: &[f64]) -> Vec<f64> {
    let half = 0.25 * freqs[0];
    let a = peaks(x, fs, (0.1, 0.3), freqs, half);
    let b = peaks(x, fs, (0.5, 0.6), freqs, half);
    a.iter()
        .zip(&b)
        .map(|(a, b)| (a.level_db - b.level_db) / 0.35)
        .collect()
}

/// The pedal's controller values the test plays: up, the free travel's end, through the felt's
/// decompression and the part-pedalling zone, and fully down.
const DEPTHS: [u8; 12] = [0, 26, 30, 34, 38, 42, 46, 50, 53, 56, 60, 127];

/// C4's partials 1-8 released under the sustain pedal at 12 depths, on the concert keyboard's
/// exact engine: every partial's decay rate falls as the pedal goes down (the felt lifts: it
/// touches more lightly, then only while the string reaches it), continuously from the resting
/// felt's (a lift of 6e-5 of the full one changes no rate by more than 1 dB/s: the part-lifted
/// felt's decay taken mode by mode on the free modes meets the felt's own face) to the free
/// string's; half way, the felt takes the upper partials faster than the fundamental.
#[test]
fn partials_decay_faster_the_lower_the_dampers() {
    let scaling = Scaling::resolve("concert").unwrap();
    let key = 40;
    let piano: Piano<ExactPool> = Piano::build(&scaling, &[key], 4).unwrap();
    let freqs = partials(&scaling, key);
    println!("C4 velocity 100, released at 0.3 s: mean decay rate (dB/s) of partials 1-8 from the key held");
    let rows: Vec<Vec<f64>> = DEPTHS
        .iter()
        .map(|&cc| {
            let (fs, x) = released_under_pedal(&piano, 100.0, cc as f64 / 127.0);
            let r = decay_rates(&x, fs, &freqs);
            let line: Vec<String> = r.iter().map(|r| format!("{r:6.1}")).collect();
            println!("CC64 {cc:3}: {}", line.join(" "));
            r
        })
        .collect();
    let (down, up) = (&rows[0], &rows[rows.len() - 1]);
    // Monotonic, partial by partial: a rise of more than 0.1 dB/s (the rates' rounding in the
    // spectra's peaks) is a felt taking more as it rises.
    let mut worst_rise = f64::MIN;
    for n in 0..8 {
        for pair in rows.windows(2) {
            worst_rise = worst_rise.max(pair[1][n] - pair[0][n]);
        }
    }
    let first_step = (0..8)
        .map(|n| (rows[1][n] - down[n]).abs())
        .fold(0.0, f64::max);
    println!(
        "largest rise with depth {worst_rise:.2} dB/s; CC 26 against the resting felt: {first_step:.2} dB/s"
    );
    assert!(worst_rise < 0.1, "a rate rises as the pedal goes down");
    assert!(
        first_step < 1.0,
        "the part-lifted felt meets the resting one"
    );
    // Half way (CC 42) the felt is part of the way between, and adds more to partials 2-4 than
    // to the fundamental: near the string's end, where the felt sits, `psi_n(x)` grows with `n`.
    let mid = &rows[5];
    for n in 0..8 {
        let at = (mid[n] - up[n]) / (down[n] - up[n]);
        assert!(
            (0.2..0.8).contains(&at),
            "partial {}: {at:.2} of the way at CC 42",
            n + 1
        );
    }
    let added = |n: usize| mid[n] - up[n];
    println!(
        "the felt's added rate at CC 42: partial 1 {:.1}, partials 2-4 {:.1} {:.1} {:.1} dB/s",
        added(0),
        added(1),
        added(2),
        added(3)
    );
    assert!((1..4).all(|n| added(n) > 2.0 * added(0)));
}

/// The RK4 reference, its felt's force scaled by the share its own strings' excursion gives,
/// against the exact engine's (the share from the coupled modes, the felt's decay taken mode by
/// mode): C4's partials 1-8 released at the pedal's mid depth (CC 42) decay at rates within
/// 5 % of the felt's added rate of each other.
#[test]
fn the_part_lifted_felt_agrees_with_rk4() {
    let scaling = Scaling::resolve("concert").unwrap();
    let key = 40;
    let freqs = partials(&scaling, key);
    let depth = 42.0 / 127.0;
    let exact: Piano<ExactPool> = Piano::build(&scaling, &[key], 4).unwrap();
    let (fs, x) = released_under_pedal(&exact, 100.0, depth);
    let e = decay_rates(&x, fs, &freqs);
    let (fs, x) = released_under_pedal(&exact, 100.0, 1.0);
    let free = decay_rates(&x, fs, &freqs);
    let rk4: Piano<Rk4Pool> = Piano::build(&scaling, &[key], 4).unwrap();
    let (fs, x) = released_under_pedal(&rk4, 100.0, depth);
    let r = decay_rates(&x, fs, &freqs);
    println!("C4 released at CC64 42: decay rate (dB/s) of partials 1-8, exact / RK4 / exact free");
    for n in 0..8 {
        println!("  {}: {:6.1} {:6.1} {:6.1}", n + 1, e[n], r[n], free[n]);
    }
    let worst = (0..8)
        .map(|n| (e[n] - r[n]).abs() / (e[n] - free[n]))
        .fold(0.0, f64::max);
    println!(
        "largest difference: {:.1} % of the felt's added rate",
        100.0 * worst
    );
    // The limit: a few times what the full felt differs by between its modal and coupled forms.
    assert!(worst < 0.05);
}

/// A key let go slowly lets its damper land late and gently: C4 (velocity 100) released at
/// 0.3 s at release velocities 10, 64 (MIDI's default) and 120, its level in 20 ms windows 50 ms
/// and 200 ms after the release. The slow release is the loudest at both (its damper lands in
/// 0.19 s, the default's in 30 ms, the fast one's in 16 ms), the fast one the quietest.
#[test]
fn a_slow_release_lets_the_note_die_more_gradually() {
    let scaling = Scaling::resolve("concert").unwrap();
    let piano: Piano<ExactPool> = Piano::build(&scaling, &[40], 4).unwrap();
    let level_db = |x: &[f64], fs: f64, t: f64| {
        let (a, b) = (((t - 0.01) * fs) as usize, ((t + 0.01) * fs) as usize);
        let ms = x[a..b].iter().map(|v| v * v).sum::<f64>() / (b - a) as f64;
        10.0 * ms.log10()
    };
    let levels: Vec<[f64; 3]> = [10.0, 64.0, 120.0]
        .iter()
        .map(|&release| {
            let (fs, x) = released(&piano, 100.0, 0.0, release);
            [0.29, 0.35, 0.5].map(|t| level_db(&x, fs, t))
        })
        .collect();
    println!("C4 released at 0.3 s: level (dB) just before, 50 ms and 200 ms after");
    for (v, l) in [10, 64, 120].iter().zip(&levels) {
        println!(
            "  release velocity {v:3}: {:6.1} {:6.1} {:6.1}",
            l[0], l[1], l[2]
        );
    }
    let [slow, default, fast] = [&levels[0], &levels[1], &levels[2]];
    assert!(
        (slow[0] - fast[0]).abs() < 1e-9,
        "the same until the release"
    );
    for i in 1..3 {
        assert!(
            slow[i] > default[i] + 1.0 && default[i] > fast[i],
            "ordered as the releases' speeds {} ms after",
            if i == 1 { 50 } else { 200 }
        );
    }
}

/// The keyboard's damper travel reaches the engine: felts pressed 1 mm into the strings at rest
/// (`tests/data/damper_travel_deep.toml`) in place of 0.5 mm still press 0.81 mm at CC64 42,
/// where the concert keyboard's press 0.31 mm: the first partial dies faster under them, and
/// slower than under a resting felt.
#[test]
fn the_keyboards_damper_travel_sets_the_half_pedal() {
    let rate = |scaling: &LoadedScaling, depth: f64| {
        let piano: Piano<ExactPool> = Piano::build(scaling, &[40], 4).unwrap();
        let f1 = scaling.target_hz(40);
        let (fs, x) = released_under_pedal(&piano, 100.0, depth);
        decay_rates(&x, fs, &[f1])[0]
    };
    let concert = Scaling::resolve("concert").unwrap();
    let deep = Scaling::resolve("tests/data/damper_travel_deep.toml").unwrap();
    let depth = 42.0 / 127.0;
    let (resting, part, deep_part) = (
        rate(&concert, 0.0),
        rate(&concert, depth),
        rate(&deep, depth),
    );
    println!(
        "C4's first partial (dB/s): resting felt {resting:.1}; CC64 42 {part:.1}, felts 1 mm deep {deep_part:.1}"
    );
    assert!(part + 5.0 < deep_part && deep_part + 5.0 < resting);
}
