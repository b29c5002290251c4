//! The command line on its happy path, as a new user meets it: a render that needs no flag but
//! its output, a key's note rung out to its end, the defaults said and kept.

mod support;

use support::cli;

/// A WAV's samples (interleaved) and its channel count and rate.
fn read_wav(path: &std::path::Path) -> (Vec<f32>, usize, f64) {
    let reader = hound::WavReader::open(path).unwrap();
    let spec = reader.spec();
    let samples = reader.into_samples::<f32>().map(Result::unwrap).collect();
    (samples, spec.channels.into(), f64::from(spec.sample_rate))
}

/// Each 100 ms window's level (dB re the loudest window), every channel's energy summed.
fn window_levels_db(samples: &[f32], channels: usize, rate_hz: f64) -> Vec<f64> {
    let window = (0.1 * rate_hz) as usize * channels;
    let energy: Vec<f64> = samples
        .chunks_exact(window)
        .map(|w| w.iter().map(|&s| f64::from(s).powi(2)).sum())
        .collect();
    let loudest = energy.iter().copied().fold(0.0, f64::max);
    energy
        .iter()
        .map(|e| 10.0 * (e / loudest).max(1e-30).log10())
        .collect()
}

/// `render --key` without `--offline` or `--seconds`: the fast engine, the note rung out to 60 dB
/// under its loudest and no further. C7 released after 0.3 s (its damper falls) rings out in a
/// second or two; held, it would ring for many.
#[test]
fn a_keys_render_rings_out_and_stops() {
    let dir = tempfile::tempdir().unwrap();
    let wav = dir.path().join("c7.wav");
    let (code, stderr) = cli(&[
        "render",
        "--key",
        "c7",
        "--release-at",
        "0.3",
        "--out",
        wav.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "render needs no --offline");
    assert!(
        stderr.contains("exact engine"),
        "a key renders on the fast engine"
    );
    assert!(
        stderr.contains("rung out to 60 dB"),
        "the summary says why it ended"
    );
    let (samples, channels, rate_hz) = read_wav(&wav);
    let seconds = samples.len() as f64 / channels as f64 / rate_hz;
    let levels = window_levels_db(&samples, channels, rate_hz);
    let (last, before) = (levels[levels.len() - 1], levels[levels.len() - 2]);
    println!(
        "C7 released at 0.3 s: {seconds:.2} s rendered; last 100 ms window {last:.1} dB re the \
         loudest, the one before {before:.1} dB"
    );
    // The damper takes the note under −60 dB within a few seconds; far short of the 30 s cap.
    assert!((0.4..10.0).contains(&seconds), "{seconds} s");
    // The render stops at the first window under the floor (its windows and these line up).
    assert!(last <= -60.0 && before > -60.0, "{last} / {before} dB");
}

/// `play` checks the device before it builds the keys, says what it will do as the flags ask,
/// and ends with a summary a pianist can read: whether it kept up, its headroom, the latency.
#[test]
fn play_checks_the_device_first_and_reads_out_how_it_went() {
    let (code, stderr) = cli(&["play", "--device", "no-such-device"]);
    assert_eq!(code, Some(1));
    assert!(stderr.contains("no audio output device matches \"no-such-device\""));
    assert!(
        !stderr.contains("building"),
        "the device is refused before any key is built"
    );
    let (code, stderr) = cli(&[
        "play",
        "--device",
        "null",
        "--buffer",
        "64",
        "--voices",
        "2",
        "--callbacks",
        "200",
    ]);
    assert_eq!(code, Some(0));
    // Without a MIDI input the message says how long it runs, as the flags ask.
    if stderr.contains("no MIDI input") {
        assert!(stderr.contains("runs silent for 200 callbacks"));
    }
    for line in [
        "kept up: ",
        "headroom: ",
        "latency: about ",
        "sound: silent",
    ] {
        assert!(stderr.contains(line), "the summary has `{line}`");
    }
    // At 64 frames and 48 kHz: one callback rendering, one in the device, 1.33 ms each.
    let at = stderr.find("latency: about ").unwrap() + "latency: about ".len();
    let latency_ms: f64 = stderr[at..]
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap();
    println!("latency said: {latency_ms} ms at 64 frames (two callbacks: 2.67 ms)");
    assert!((2.6..4.0).contains(&latency_ms), "{latency_ms} ms");
    assert!(!stderr.contains("-200"), "no level of a silence");
}

/// The plugin's output gain and velocity curve as flags of `render` (and `play`, which shares
/// them): the gain moves the level by its dB exactly, the curve turns one velocity into another.
#[test]
fn gain_and_velocity_curve_flags_do_what_they_say() {
    let dir = tempfile::tempdir().unwrap();
    let render = |name: &str, extra: &[&str]| {
        let wav = dir.path().join(name);
        let mut args = vec!["render", "--key", "C7", "--seconds", "0.3"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--out", wav.to_str().unwrap()]);
        let (code, _) = cli(&args);
        assert_eq!(code, Some(0));
        read_wav(&wav).0
    };
    let peak = |s: &[f32]| s.iter().fold(0f32, |m, x| m.max(x.abs()));
    let plain = render("plain.wav", &[]);
    let quieter = render("quieter.wav", &["--gain-db", "-6"]);
    let change_db = 20.0 * (peak(&quieter) / peak(&plain)).log10();
    println!("--gain-db -6: the peak moves {change_db:.4} dB");
    assert!((change_db + 6.0).abs() < 0.01, "{change_db} dB");
    // 127 (63.5/127)^2 = 31.75 exactly: velocity 63.5 through the curve 2 strikes as 31.75 does
    // (a fraction of a MIDI step, as a CC88 prefix gives it, unrounded).
    let curved = render(
        "curved.wav",
        &["--midi-velocity", "63.5", "--velocity-curve", "2"],
    );
    let direct = render("direct.wav", &["--midi-velocity", "31.75"]);
    let plain64 = render("plain64.wav", &["--midi-velocity", "63.5"]);
    println!(
        "velocity 63.5 curved by 2: peak {:.5}; velocity 31.75: {:.5}; 63.5: {:.5}",
        peak(&curved),
        peak(&direct),
        peak(&plain64)
    );
    assert_eq!(curved, direct, "the same strike, sample for sample");
    assert!(peak(&plain64) > peak(&curved));
    for (args, needle) in [
        (
            ["render", "--key", "C4", "--gain-db", "20", "--out"],
            "--gain-db 20",
        ),
        (
            [
                "play",
                "--device",
                "null",
                "--velocity-curve",
                "9",
                "--voices",
            ],
            "--velocity-curve 9",
        ),
    ] {
        let wav = dir.path().join("refused.wav");
        let last = if args[0] == "render" {
            wav.to_str().unwrap().to_owned()
        } else {
            "2".to_owned()
        };
        let mut args: Vec<&str> = args.to_vec();
        args.push(&last);
        let (code, stderr) = cli(&args);
        assert_eq!(code, Some(1));
        assert!(stderr.contains(needle) && !stderr.contains("building"));
        assert!(!wav.exists());
    }
}

/// `devices` says in its own words what is there and what is not: alsa-lib's raw error lines
/// (`ALSA lib seq_hw.c:…` where the machine has no sequencer) stay off standard error.
#[test]
fn devices_prints_only_its_own_messages() {
    let (code, stderr) = cli(&["devices"]);
    assert_eq!(code, Some(0));
    assert!(!stderr.contains("ALSA lib"), "{stderr}");
}

/// `analyze`'s table reads on its own: headed columns with units, a legend for every column
/// (the tuner's partial count among them), a word for a figure that is not there, and a note
/// where the model's T60 and the recording's differ by design.
#[test]
fn analyze_heads_its_columns_and_says_what_they_mean() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_unacorda"))
        .args(["analyze", "--keys", "A0"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let table = String::from_utf8_lossy(&out.stdout);
    println!("{table}");
    let row = table
        .lines()
        .find(|l| l.trim_start().starts_with("1 A0"))
        .unwrap();
    // A0's recording has an early decay and no late one: said, not left as a dash.
    assert!(row.ends_with("to n/a") && !row.contains("–-"), "{row}");
    assert!(table.contains("tuner ¢ (n)") && table.contains("recorded p1 T60 (s)"));
    let legend = table.lines().find(|l| l.starts_with("columns:")).unwrap();
    for column in [
        "tuner ¢ (n)",
        "fit B",
        "p1 ¢",
        "p1 and p2 T60",
        "recorded p1 T60",
        "n/a",
    ] {
        assert!(
            legend.contains(column),
            "the legend says what `{column}` is"
        );
    }
    assert!(table
        .lines()
        .any(|l| l.starts_with("note: the model's T60")));
}

/// `figures` draws Fig. 6 with its colour bar (and Fig. 7, the soft pedal's depths): at its right, a column of pixels running through
/// the spectrograms' colour map from its top (loud) to its bottom (quiet) over most of the
/// plot's height, which a spectrogram's own column (harmonics over a quiet floor) never does.
#[test]
fn figure_6_has_a_colour_bar() {
    use unacorda::analysis::figures::colormap;
    let dir = tempfile::tempdir().unwrap();
    let (code, _) = cli(&[
        "figures",
        "--seconds",
        "0.3",
        "--out-dir",
        dir.path().to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0));
    // Figure 7 beside it: the felt force at each of the soft pedal's five depths, the normal
    // strike's the strongest, the una corda's (one string of two) under 0.7 of it.
    let csv = std::fs::read_to_string(dir.path().join("fig7_soft_pedal.csv")).unwrap();
    let peak = |depth: &str| {
        csv.lines()
            .filter_map(|l| l.strip_prefix(&format!("force,{depth},")))
            .filter_map(|l| l.split(',').nth(1)?.parse::<f64>().ok())
            .fold(0.0, f64::max)
    };
    let peaks: Vec<f64> = ["0", "0.5", "0.8", "0.9", "1"].map(peak).to_vec();
    println!("Fig. 7's peak forces at depths 0, 0.5, 0.8, 0.9, 1: {peaks:.2?} N");
    assert!(peaks[1..].iter().all(|&p| p < peaks[0]) && (0.0..0.7 * peaks[0]).contains(&peaks[4]));
    assert!(dir.path().join("fig7_soft_pedal.png").exists());
    let png = image::open(dir.path().join("fig6_spectrograms.png"))
        .unwrap()
        .to_rgb8();
    let (width, height) = png.dimensions();
    // The colour map sampled finely; a pixel's place on it, if it lies on it.
    let map: Vec<[f64; 3]> = (0..=1000)
        .map(|i| {
            let c = colormap(f64::from(i) / 1000.0);
            [c.0, c.1, c.2].map(f64::from)
        })
        .collect();
    let place = |x: u32, y: u32| -> Option<f64> {
        let p = png.get_pixel(x, y).0.map(f64::from);
        let (i, d) = map
            .iter()
            .map(|m| (0..3).map(|k| (m[k] - p[k]).powi(2)).sum::<f64>())
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap();
        (d < 30.0).then_some(i as f64 / 1000.0)
    };
    // The longest run down a column on the map, never rising, and the span it covers.
    let best = (width - 150..width)
        .map(|x| {
            let (mut best, mut run, mut first, mut last) = (0.0f64, 0, None, 0.0);
            for y in 0..height {
                match place(x, y) {
                    Some(t) if first.is_some() && t <= last + 0.01 => {
                        run += 1;
                        last = t;
                    }
                    Some(t) => {
                        (run, first, last) = (1, Some(t), t);
                    }
                    None => {
                        (run, first) = (0, None);
                    }
                }
                if run >= height / 2 {
                    best = best.max(first.unwrap_or(0.0) - last);
                }
            }
            best
        })
        .fold(0.0, f64::max);
    println!("Fig. 6's right edge: a column runs down the colour map over {best:.2} of its span");
    assert!(best > 0.9, "no colour bar: {best:.2} of the map");
}
