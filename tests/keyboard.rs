//! The 88-key scaling: C2 is the c2 preset, every key builds a stable voice with its own bridge
//! point, string layout and mode counts follow the documented rules, and the keys sound near pitch.

use unacorda::analysis::spectral::peak_frequency;
use unacorda::config::preset::Preset;
use unacorda::config::scaling::{equal_tempered_hz, parse_key, Scaling, KEYS};
use unacorda::engine::rk4::Rk4Pool;
use unacorda::engine::Policy;
use unacorda::engine::{Strike, VoicePool};
use unacorda::render::simulate;

#[test]
fn c2_key_is_the_c2_preset() {
    let keyboard = Scaling::resolve("paper").unwrap();
    let key = keyboard.key_preset(parse_key("C2").unwrap()).unwrap();
    let c2 = Preset::resolve("c2").unwrap();
    println!(
        "key 16 = {}: strings {:?}",
        key.preset.name, key.preset.strings
    );
    assert_eq!(key.preset.strings, c2.preset.strings);
    assert_eq!(key.preset.hammer, c2.preset.hammer);
    assert_eq!(key.preset.contact, c2.preset.contact);
    assert_eq!(key.preset.soundboard, c2.preset.soundboard);
    assert_eq!(key.bridge_point, c2.bridge_point);
}

#[test]
fn the_concert_keyboard_is_the_paper_keyboard_but_for_what_it_sets() {
    // `concert` names `paper` as its base keyboard: the same strings, striking points and layout
    // on every key, at the same bridge points of another board (`grand_sized`); only the board,
    // the strings' losses, the duplex felt, the dampers, the tuning (stretched), the hammers'
    // voicing (masses and felts) and the listener differ.
    let paper = Scaling::resolve("paper").unwrap();
    let concert = Scaling::resolve("concert").unwrap();
    println!("key  c_d paper/concert  zeta_T paper/concert  b1 1/s   b3 s");
    for k in 1..=KEYS {
        let (p, c) = (
            paper.key_preset(k).unwrap().preset,
            concert.key_preset(k).unwrap().preset,
        );
        let (ps, cs) = (&p.strings, &c.strings);
        if [1, 16, 40, 52, 53, 76, 88].contains(&k) {
            println!(
                "{k:3}  {:5} / {:<5}      {:.0e} / {:<4}         {:6.3}  {:.2e}",
                ps.duplex_damping_n_s_m2,
                cs.duplex_damping_n_s_m2,
                ps.damping_ratio_t,
                cs.damping_ratio_t,
                cs.loss_b1_per_s,
                cs.loss_b3_s
            );
        }
        // The same strings but for their losses, felt and tension (the stretched tuning).
        let same = |mut s: unacorda::config::preset::StringsSection| {
            s.damping_ratio_t = 0.0;
            s.damping_ratio_p = 0.0;
            s.loss_b1_per_s = 0.0;
            s.loss_b3_s = 0.0;
            s.duplex_damping_n_s_m2 = 0.0;
            s.tension_n = 0.0;
            s.modes_t = 0;
            s.modes_p = 0;
            s.modes_l = 0;
            s
        };
        assert_eq!(same(ps.clone()), same(cs.clone()), "key {k}: strings");
        // The tension carries the stretch (f ∝ sqrt(T0)), but where the stretch moves a mode across
        // the frequency limit (E7 and Bb7 keep one fewer at their higher tension, and the tuner
        // then tunes with the count the key has).
        // C4-C8 keep their string modes to 20 kHz (`mode_limits`), the rest to 9.6 kHz as the
        // paper's: with 9.6 kHz Bb7-C8 kept no speaking partial but their first
        // (tests/realism.rs).
        let top_mode_hz = |s: &unacorda::config::scaling::LoadedScaling| {
            s.key_preset(k).unwrap().unison_spec().max_mode_freq_hz()
        };
        let (p_top, c_top) = (top_mode_hz(&paper), top_mode_hz(&concert));
        if k >= 40 {
            assert!(
                cs.modes_t > ps.modes_t
                    && cs.modes_l >= ps.modes_l
                    && (9600.0..20_000.0).contains(&c_top),
                "key {k}: {} modes to {c_top:.0} Hz against the paper's {} to {p_top:.0} Hz",
                cs.modes_t,
                ps.modes_t
            );
        } else {
            assert!(c_top < 9600.0, "key {k}: a mode at {c_top:.0} Hz");
            assert_eq!(cs.modes_l, ps.modes_l, "key {k}");
        }
        let by_tension = 600.0 * (cs.tension_n / ps.tension_n).log2();
        let stretch = concert.stretch_cents(k);
        if cs.modes_t == ps.modes_t {
            // Within a few cents: the tuner works on the coupled system, where the pitch is not
            // quite as sqrt(T0) (F1: a board mode splits a partial; the top keys: the contact
            // spring and few modes), and it is checked there (tests/realism.rs).
            if (by_tension - stretch).abs() >= 1.0 {
                println!("key {k}: tension {by_tension:+.2} cents for a stretch of {stretch:+.2}");
            }
            assert!((by_tension - stretch).abs() < 5.0, "key {k}");
        } else {
            println!(
                "key {k}: {} modes against the paper's {}, tension {by_tension:+.1} cents for a stretch of {stretch:+.1}",
                cs.modes_t, ps.modes_t
            );
        }
        // The same hammers but for the voicing: the felts' exponents 4.5 from A0 to C4, 3.75 at
        // C6, 2.6 at G#6 and 2 from C7 up, linear in key number between; their force at 1 mm of
        // compression the paper's felt's times 0.5 at A0, 2 at C2 and C4, 4 at C6, 1 at G#6, 2.5
        // at C7, 3 at E7, 8 at F#7, 40 at A7, 200 at Bb7, 100 at C8; the hammers' masses 11.5 g
        // at A0, 6.5 at C2, 6.1 at C4, 4.5 at C6, 1.6 at G#6, 2.2 at C7, 2.13 at E7, 2.1 at F#7,
        // 2.05 at A7, 3.0 at Bb7, 2.0 at C8; both log-linear in key number between
        // (docs/parameters.md).
        let points: [(usize, f64, f64, f64); 11] = [
            (1, 0.5, 11.5e-3, 4.5),
            (16, 2.0, 6.5e-3, 4.5),
            (40, 2.0, 6.1e-3, 4.5),
            (64, 4.0, 4.5e-3, 3.75),
            (72, 1.0, 1.6e-3, 2.6),
            (76, 2.5, 2.2e-3, 2.0),
            (80, 3.0, 2.13e-3, 2.0),
            (82, 8.0, 2.1e-3, 2.0),
            (85, 40.0, 2.05e-3, 2.0),
            (86, 200.0, 3.0e-3, 2.0),
            (88, 100.0, 2.0e-3, 2.0),
        ];
        let (a, b) = points
            .windows(2)
            .map(|w| (w[0], w[1]))
            .find(|(a, b)| (a.0..=b.0).contains(&k))
            .unwrap();
        let t = (k - a.0) as f64 / (b.0 - a.0) as f64;
        let geometric = |x: f64, y: f64| (x.ln() * (1.0 - t) + y.ln() * t).exp();
        let (voiced, mass_kg) = (geometric(a.1, b.1), geometric(a.2, b.2));
        let exponent = a.3 * (1.0 - t) + b.3 * t;
        let force_at_mm_n = |h: &unacorda::config::preset::HammerSection| {
            h.stiffness_n_m_p * 1e-3f64.powf(h.exponent)
        };
        let ratio = force_at_mm_n(&c.hammer) / force_at_mm_n(&p.hammer);
        assert!(
            (c.hammer.exponent - exponent).abs() < 1e-12,
            "key {k}: exponent {}",
            c.hammer.exponent
        );
        assert!(
            (ratio / voiced - 1.0).abs() < 1e-9,
            "key {k}: voiced {ratio}"
        );
        assert!(
            (c.hammer.mass_kg / mass_kg - 1.0).abs() < 1e-12,
            "key {k}: mass {} kg",
            c.hammer.mass_kg
        );
        let unvoiced = unacorda::config::preset::HammerSection {
            stiffness_n_m_p: p.hammer.stiffness_n_m_p,
            exponent: p.hammer.exponent,
            mass_kg: p.hammer.mass_kg,
            ..c.hammer.clone()
        };
        assert_eq!(p.hammer, unvoiced, "key {k}");
        // Heard as the paper's monopole, and at the listener above the board.
        assert_eq!(p.radiation.listener, None, "key {k}");
        assert_eq!(c.radiation.listener.as_deref(), Some("above"), "key {k}");
        // In stereo by the close pair over the two ends of the bridges, bass on the left, 0 dBFS
        // at 20 Pa (the paper's: c2's 2 Pa).
        assert_eq!(p.radiation.stereo, None, "key {k}");
        let pair = c.radiation.stereo.clone().map(|lr| lr.map(String::from));
        assert_eq!(
            pair,
            Some(["bass_close".into(), "treble_close".into()]),
            "key {k}"
        );
        assert_eq!(
            (p.radiation.full_scale_pa, c.radiation.full_scale_pa),
            (2.0, 20.0),
            "key {k}"
        );
        // The same keys have dampers; the paper's is c2's point felt on every key, the concert's
        // a felt with two contact points and a coefficient of its own (tests/damper.rs).
        assert_eq!(p.damper.present, c.damper.present, "key {k}");
        assert_eq!(
            (
                p.damper.width_m,
                p.damper.damping_n_s_m,
                p.damper.position_ratio
            ),
            (0.0, 6.0, 0.16),
            "key {k}: the paper's damper"
        );
        assert!(c.damper.width_m > 0.0, "key {k}: the concert felt");
        assert_eq!(p.soundboard.asset, "grand", "key {k}");
        assert_eq!(c.soundboard.asset, "grand_sized", "key {k}");
        assert_eq!(
            p.soundboard.bridge_point, c.soundboard.bridge_point,
            "key {k}"
        );
        assert_eq!(
            (ps.loss_b1_per_s, ps.loss_b3_s),
            (0.0, 0.0),
            "key {k}: the paper's strings"
        );
        assert!(cs.loss_b1_per_s > 0.0 && cs.loss_b3_s > 0.0, "key {k}");
        assert_eq!(cs.damping_ratio_t, 0.0);
        assert_eq!(
            cs.duplex_damping_n_s_m2 > 0.0,
            ps.duplex_damping_n_s_m2 > 0.0,
            "key {k}: the felt on the same keys"
        );
    }
    // `grand` is the paper keyboard's earlier name.
    assert_eq!(
        Scaling::resolve("grand").unwrap().scaling,
        paper.scaling,
        "grand = paper"
    );
}

#[test]
fn every_key_builds_with_the_documented_layout() {
    let keyboard = Scaling::resolve("paper").unwrap();
    println!("key  name  strings wound  L_s m   T0 N   mu g/m  d mm   B        modes T/L  f_max Hz  m_H g  K_H        p    rate kHz  L_s pitch cents");
    for k in 1..=KEYS {
        let lp = keyboard.key_preset(k).unwrap();
        let s = &lp.preset.strings;
        let spec = lp.unison_spec();
        let unison = Rk4Pool::new(&spec).unwrap_or_else(|e| panic!("key {k}: {e}"));
        let string = &spec.strings[0];
        let f_speaking = (s.tension_n / s.linear_density_kg_m).sqrt() / (2.0 * s.speaking_length_m);
        let cents = 1200.0 * (f_speaking / equal_tempered_hz(k)).log2();
        let b = string.inharmonicity() * (string.length_m() / s.speaking_length_m).powi(2);
        if k % 6 == 1 || [16, 40, 76, KEYS].contains(&k) {
            println!(
                "{k:3}  {:5} {:7} {:5} {:7.3} {:6.0} {:7.2} {:5.2} {:8.1e} {:4}/{:<4} {:9.0} {:6.2} {:9.2e} {:4.2} {:8.0} {:+8.2}",
                spec.board.points[spec.bridge_point].name,
                s.count,
                s.wound,
                s.speaking_length_m,
                s.tension_n,
                s.linear_density_kg_m * 1e3,
                s.core_diameter_m * 1e3,
                b,
                s.modes_t,
                s.modes_l,
                spec.max_mode_freq_hz(),
                lp.preset.hammer.mass_kg * 1e3,
                lp.preset.hammer.stiffness_n_m_p,
                lp.preset.hammer.exponent,
                1.0 / unison.step_s() / 1e3,
                cents
            );
        }
        // The layout docs/parameters.md documents, typed here rather than read from the scaling: single
        // strings A0–E1 (1–8), bichords F1–F#2 (9–22), trichords above; wound through F#2;
        // duplex felt-muted up to C5 (52); dampers up to F6 (69).
        let expected_strings = match k {
            1..=8 => 1,
            9..=22 => 2,
            _ => 3,
        };
        assert_eq!(s.count, expected_strings, "key {k}");
        assert_eq!(unison.n_strings(), expected_strings);
        assert_eq!(s.wound, k <= 22, "key {k}: wound");
        assert_eq!(
            spec.duplex_damping_n_s_m2 > 0.0,
            k <= 52,
            "key {k}: duplex felt"
        );
        assert_eq!(spec.damper.is_some(), k <= 69, "key {k}: damper");
        assert!(s.modes_t <= 100 && s.modes_l <= 5);
        assert!(
            spec.max_mode_freq_hz() < 9600.0 || s.modes_t == 1,
            "key {k}: modes above the limit"
        );
        assert_eq!(
            1.0 / unison.step_s(),
            96_000.0,
            "key {k}: every key at the c2 internal rate"
        );
        assert_eq!(
            spec.board.points[spec.bridge_point].name,
            unacorda::board::key_name(k)
        );
    }
}

/// Every key struck at 6 m/s (fortissimo) and stepped for 20 ms on engine `E`: the state stays
/// finite, and once the hammer is out of play the energy never rises. Returns the largest
/// relative rise per step after the hammer's release, and the keys whose hammer was released.
fn strike_every_key<E: VoicePool>() -> (f64, usize) {
    let keyboard = Scaling::resolve("paper").unwrap();
    let rate = keyboard.base.output_rate_hz();
    let (mut worst, mut released) = (f64::NEG_INFINITY, 0);
    for k in 1..=KEYS {
        let spec = keyboard.key_preset(k).unwrap().unison_spec();
        let mut pool = E::build_pool(&[spec], 1, rate).unwrap();
        pool.assign(0, 0);
        pool.strike_voice(
            0,
            Strike {
                velocity_m_s: 6.0,
                shift: 0.0,
            },
        );
        let mut out = [[0.0; 2]];
        let mut last = None;
        for _ in 0..(0.02 / pool.step_s()) as usize {
            pool.run(&mut out, None);
            let e = pool.mechanical_energy_j();
            assert!(
                e.is_finite() && out[0].iter().all(|x| x.is_finite()),
                "key {k}: not finite"
            );
            if pool.is_driven() {
                continue;
            }
            if let Some(before) = last {
                worst = f64::max(worst, (e - before) / before);
            } else {
                released += 1;
            }
            last = Some(e);
        }
    }
    (worst, released)
}

/// How far the energy may rise in a step: by rounding on RK4 (a sum of ~1e3 terms in f64); on the
/// exact engine by what its sum of modal energies weighs unevenly (`tests/soak.rs`).
#[test]
fn every_key_struck_fortissimo_stays_finite_and_decays() {
    use unacorda::engine::exact::ExactPool;
    for (engine, tolerance, (worst, released)) in [
        ("RK4", 1e-12, strike_every_key::<Rk4Pool>()),
        ("exact", 1e-2, strike_every_key::<ExactPool>()),
    ] {
        println!("{engine}: all 88 keys struck at 6 m/s for 20 ms: finite; {released} hammers released, after which the energy changed by at most {worst:+.2e} per step (limit {tolerance:e})");
        assert!(released > 80, "{engine}: only {released} hammers released");
        assert!(
            worst < tolerance,
            "{engine}: the energy rose by {worst:e} in a step"
        );
    }
}

#[test]
fn keys_sound_near_their_pitch() {
    // Keys are tuned as a tuner listens, on partials 2–8 of the undamped bridge and board
    // (`engine::tuning::bridged_pitch_hz`): the struck key's second partial sits where the stiff
    // string (Eq. 2) with its first partial on equal temperament puts it, within the damping's
    // and the unison spread's few cents.
    let keyboard = Scaling::resolve("paper").unwrap();
    println!("second partial of the struck unison (normal playing, 0.6 s) against Eq. 2 on pitch:");
    for name in ["A1", "C4", "A5", "C7"] {
        let k = parse_key(name).unwrap();
        let lp = keyboard.key_preset(k).unwrap();
        let b = lp.unison_spec().strings[0].speaking_inharmonicity();
        let rec = simulate(
            &lp,
            Strike {
                velocity_m_s: 2.5,
                shift: 0.0,
            },
            None,
            0.6,
            |_| {},
        )
        .unwrap();
        let x = rec.channel(|f| f.obs.total_force_n[0]);
        let x = &x[(0.1 * rec.rate_hz) as usize..];
        let f_et = equal_tempered_hz(k);
        let target = 2.0 * f_et * ((1.0 + 4.0 * b) / (1.0 + b)).sqrt();
        let f = peak_frequency(x, rec.rate_hz, target * 0.97, target * 1.03);
        let cents = 1200.0 * (f / target).log2();
        println!("  {name}: {f:9.3} Hz, Eq. 2 on pitch {target:9.3} Hz, {cents:+6.1} cents");
        assert!(cents.abs() < 5.0);
    }
}

/// `Piano::build` prepares keys on several threads, interleaved; the pool must hold them in the
/// order asked for, exactly as built one after another.
#[test]
fn keys_prepared_on_several_threads_land_in_order() {
    use unacorda::engine::exact::ExactPool;
    use unacorda::engine::BuildError;
    use unacorda::engine::VoicePool;
    use unacorda::play::Piano;
    let keyboard = Scaling::resolve("paper").unwrap();
    let keys = [1, 16, 40, 52, 64, 88, 30];
    let rate = keyboard.base.output_rate_hz();
    let specs: Vec<_> = keys
        .iter()
        .map(|&k| keyboard.key_preset(k).unwrap().unison_spec())
        .collect();
    let mut sequential = ExactPool::build_pool(&specs, 2, rate).unwrap();
    let mut threaded = Piano::<ExactPool>::build(&keyboard, &keys, 2)
        .unwrap()
        .instrument;
    let strike = Strike {
        velocity_m_s: 2.0,
        shift: 0.0,
    };
    for (bank, key) in keys.iter().enumerate() {
        for pool in [&mut sequential, &mut threaded] {
            Policy::assign(pool, 0, bank);
            Policy::strike_voice(pool, 0, strike);
        }
        let (mut a, mut b) = (vec![[0.0; 2]; 200], vec![[0.0; 2]; 200]);
        VoicePool::run(&mut sequential, &mut a, None);
        VoicePool::run(&mut threaded, &mut b, None);
        assert!(a.iter().any(|&x| x[0] != 0.0), "key {key} sounds");
        assert_eq!(a, b, "key {key} (bank index {bank})");
    }
    println!(
        "{} keys, threaded and sequential builds: identical",
        keys.len()
    );
    // Prepared keys and their specs must pair up.
    let one = vec![Rk4Pool::prepare_key(&specs[0]).unwrap()];
    let err = Rk4Pool::<f64>::from_keys(&specs[..2], one.into(), 1).unwrap_err();
    println!("{err}");
    assert_eq!(err, BuildError::PreparedKeys { specs: 2, keys: 1 });
}

#[test]
fn a_keyboards_felt_hysteresis_runs_linearly_between_its_voicing_points() {
    // Unset, every felt is the paper's elastic one; set at A0 and C8, key k has
    // alpha = 100 + 200 (k - 1) / 87 us.
    let concert = Scaling::resolve("concert").unwrap();
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/keyboard_hysteresis.toml"
    );
    let hysteretic = Scaling::resolve(path).unwrap();
    for k in [1, 40, 88] {
        let (elastic, felt) = (
            concert.key_preset(k).unwrap().preset.hammer,
            hysteretic.key_preset(k).unwrap().preset.hammer,
        );
        let expected_s = 1e-4 + 2e-4 * (k - 1) as f64 / 87.0;
        println!(
            "key {k}: felt hysteresis {:.1} us (expected {:.1})",
            1e6 * felt.hysteresis_s,
            1e6 * expected_s
        );
        assert_eq!(elastic.hysteresis_s, 0.0);
        assert!((felt.hysteresis_s - expected_s).abs() < 1e-15);
        assert_eq!(
            hysteretic
                .key_preset(k)
                .unwrap()
                .unison_spec()
                .hammer
                .hysteresis_s,
            felt.hysteresis_s
        );
    }
}

#[test]
fn a_keyboard_stands_its_keys_on_the_soundboard_it_names() {
    // `soundboard_asset`, relative to the keyboard file: a copy of the concert keyboard's built-in
    // board (`grand_sized`) whose modes are damped at zeta 0.01 (its own: 0.03) carries every
    // key, bridge point and listener alike; a file that is not there is refused, naming it.
    let dir = std::env::temp_dir().join(format!("unacorda-asset-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let board = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/assets/soundboard_modes/grand_sized.txt"
    ))
    .unwrap();
    let damped: String = board
        .lines()
        .map(|l| match l.split_once(' ') {
            Some((f, rest)) if f.parse::<f64>().is_ok() => {
                let (_, after) = rest.split_once(' ').unwrap();
                format!("{f} 0.0100 {after}\n")
            }
            _ => format!("{l}\n"),
        })
        .collect();
    std::fs::write(dir.join("lighter.txt"), damped).unwrap();
    let keyboard = |asset: &str| {
        let path = dir.join(format!("{asset}.toml"));
        let text = format!(
            "name = \"on {asset}\"\nbase_keyboard = \"concert\"\nsoundboard_asset = \"{asset}.txt\"\n"
        );
        std::fs::write(&path, text).unwrap();
        Scaling::resolve(path.to_str().unwrap())
    };
    let concert = Scaling::resolve("concert").unwrap();
    let lighter = keyboard("lighter").unwrap();
    for k in [1, 40, 88] {
        let (ours, theirs) = (
            lighter.key_preset(k).unwrap(),
            concert.key_preset(k).unwrap(),
        );
        println!(
            "key {k}: board zeta {} (concert {}), on {}",
            ours.board.damping_ratio[0],
            theirs.board.damping_ratio[0],
            ours.preset.soundboard.asset
        );
        assert!(ours.board.damping_ratio.iter().all(|&z| z == 0.01));
        assert!(theirs.board.damping_ratio.iter().all(|&z| z == 0.03));
        assert_eq!(ours.board.freq_hz, theirs.board.freq_hz);
        assert_eq!(ours.bridge_point, theirs.bridge_point);
        assert_eq!(ours.board.heard, theirs.board.heard);
    }
    let e = keyboard("missing").map(|_| ()).unwrap_err().to_string();
    println!("{e}");
    assert!(e.contains("missing.txt"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Key names in any case, sharps or flats; numbers 1–88; nothing else.
#[test]
fn key_names_are_read_in_any_case() {
    for (names, key) in [
        (&["C4", "c4", "40"][..], 40),
        (&["Bb3", "bb3", "BB3", "A#3", "a#3"][..], 38),
        (&["Db2", "db2", "DB2", "C#2", "c#2"][..], 17),
        (&["A0", "a0", "1"][..], 1),
        (&["C8", "c8", "88"][..], 88),
    ] {
        for name in names {
            assert_eq!(parse_key(name), Some(key), "{name}");
        }
    }
    for name in ["H4", "h4", "c9", "Cb", "", "89", "0", "cbb4", "C#"] {
        assert_eq!(parse_key(name), None, "{name}");
    }
}
