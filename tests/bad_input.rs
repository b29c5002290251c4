//! Malformed presets, assets and command lines: clear errors that name the file, the line or
//! field and what was expected; a non-zero exit; no panic; no output file.

mod support;

use std::path::Path;
use std::process::Command;
use support::cli;
use unacorda::config::preset::Preset;
use unacorda::config::scaling::Scaling;

fn data(name: &str) -> String {
    format!("{}/tests/data/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// The message with which `load` refuses the data file `name` (printed).
fn refusal<T: std::fmt::Debug, E: ToString>(
    name: &str,
    load: impl Fn(&str) -> Result<T, E>,
) -> String {
    let e = load(&data(name)).unwrap_err().to_string();
    println!("{name}: {e}");
    e
}

fn asset_error(name: &str) -> String {
    refusal(name, |path| {
        unacorda::config::asset::load_file(Path::new(path))
    })
}

fn preset_error(name: &str) -> String {
    refusal(name, Preset::resolve)
}

fn keyboard_error(name: &str) -> String {
    refusal(name, Scaling::resolve)
}

#[test]
fn malformed_assets_are_rejected_with_file_line_and_field() {
    let e = asset_error("bad_asset_columns.txt");
    assert!(e.contains("bad_asset_columns.txt:6:") && e.contains("expected 6 columns, found 5"));
    let e = asset_error("bad_asset_nan.txt");
    assert!(e.contains("bad_asset_nan.txt:7:") && e.contains("`T@C2`") && e.contains("finite"));
    let e = asset_error("bad_asset_zeta.txt");
    assert!(e.contains("bad_asset_zeta.txt:6:") && e.contains("`zeta`") && e.contains("[0, 1)"));
    let e = asset_error("bad_asset_no_modes.txt");
    assert!(e.contains("bad_asset_no_modes.txt") && e.contains("no modes"));
    // Found by fuzzing: a header after the rows used to index past the rows' width.
    let e = asset_error("bad_asset_points_after_rows.txt");
    assert!(
        e.contains("bad_asset_points_after_rows.txt:6:") && e.contains("header `points:` repeated")
    );
    let e = asset_error("bad_asset_listeners.txt");
    assert!(
        e.contains("bad_asset_listeners.txt:5:")
            && e.contains("`listeners:` must come before `columns:`")
    );
    let e = asset_error("does_not_exist.txt");
    assert!(e.contains("does_not_exist.txt") && e.contains("cannot read"));
}

#[test]
fn malformed_presets_are_rejected_with_field_and_range() {
    let e = preset_error("bad_preset_unknown_field.toml");
    assert!(
        e.contains("bad_preset_unknown_field.toml")
            && e.contains("felt_colour")
            && e.contains("line 50")
    );
    let e = preset_error("bad_preset_missing_field.toml");
    assert!(e.contains("missing field `mass_kg`"));
    let e = preset_error("bad_preset_range.toml");
    assert!(e.contains("`strings.tension_n` = -747.8") && e.contains("[1e1, 5e3]"));
    // The felt's stiffness is bounded by its force at 1 mm (K's unit depends on p).
    let e = preset_error("bad_preset_felt.toml");
    assert!(
        e.contains("`hammer.stiffness_n_m_p` = 4e14")
            && e.contains("1e-3 to 1e5 N at 1 mm")
            && e.contains("5.036e7 N")
    );
    let e = preset_error("bad_preset_asset.toml");
    assert!(e.contains("bad_asset_nan.txt:7:"));
    let e = preset_error("bad_preset_point.toml");
    assert!(e.contains("`soundboard.bridge_point` = `C9`") && e.contains("has points A0, Bb0"));
    let e = Preset::resolve("c3").unwrap_err().to_string();
    println!("c3: {e}");
    assert!(e.contains("unknown preset `c3`") && e.contains("c2"));
}

#[test]
fn malformed_keyboards_are_rejected_with_file_and_field() {
    // Each is refused with the file and the field, before any key is built.
    let e = keyboard_error("bad_keyboard_loop.toml");
    assert!(
        e.contains("bad_keyboard_loop.toml")
            && e.contains("`base_keyboard`")
            && e.contains("at most 4")
    );
    let e = keyboard_error("bad_keyboard_losses.toml");
    assert!(e.contains("bad_keyboard_losses.toml") && e.contains("`losses.key` = [2, 88]"));
    let e = keyboard_error("bad_keyboard_dampers.toml");
    assert!(e.contains("`dampers.width_m` = 0.2 (key 1)") && e.contains("[0.001, 0.1]"));
    let e = keyboard_error("bad_keyboard_damper_travel.toml");
    assert!(
        e.contains("bad_keyboard_damper_travel.toml")
            && e.contains("`damper_travel.full_lift_m` = 0.0003")
            && e.contains("more than damper_travel.rest_compression_m (0.0005) up to 0.02")
    );
    let e = keyboard_error("bad_keyboard_hammer_felt.toml");
    assert!(
        e.contains("bad_keyboard_hammer_felt.toml")
            && e.contains("`hammer_felt.overhang_m` = 0.0015")
            && e.contains("half a groove plus the shoulder")
    );
    let e = keyboard_error("bad_keyboard_voicing.toml");
    assert!(
        e.contains("`voicing.felt_stiffness_factor` = 1000000 (key 88)")
            && e.contains("[0.01, 10000]")
    );
    let e = keyboard_error("bad_keyboard_hysteresis.toml");
    assert!(
        e.contains("`voicing.felt_hysteresis_s` = given at 1 of 2 points")
            && e.contains("at every voicing point or at none")
    );
    let e = keyboard_error("bad_keyboard_hysteresis_range.toml");
    assert!(e.contains("`voicing.felt_hysteresis_s` = 1 (key 88)") && e.contains("[0, 0.005]"));
    let e = keyboard_error("bad_keyboard_exponent.toml");
    assert!(e.contains("`voicing.felt_exponent` = 9 (key 1)") && e.contains("[1, 6]"));
    let e = keyboard_error("bad_keyboard_hammer_mass.toml");
    assert!(e.contains("`voicing.hammer_mass_kg` = 0.5 (key 88)") && e.contains("[0.0001, 0.1]"));
    let e = keyboard_error("bad_keyboard_hammer_mass_points.toml");
    assert!(
        e.contains("`voicing.hammer_mass_kg` = given at 1 of 2 points")
            && e.contains("at every voicing point or at none")
    );
    let e = keyboard_error("bad_keyboard_full_scale.toml");
    assert!(e.contains("`full_scale_pa` = 1000000000") && e.contains("[1e-6, 1e4] Pa"));
    let e = keyboard_error("bad_keyboard_bass_octave_key.toml");
    assert!(e.contains("`bass_octave_from_key` = 49") && e.contains("1 (A0) to 36 (Ab3)"));
    let e = keyboard_error("bad_keyboard_bass_octave.toml");
    assert!(
        e.contains("bad_keyboard_bass_octave.toml") && e.contains("line 4") && e.contains("`10:5`")
    );
    let e = keyboard_error("bad_keyboard_damper_model.toml");
    assert!(
        e.contains("bad_keyboard_damper_model.toml")
            && e.contains("line 4")
            && e.contains("`implicit`")
            && e.contains("`coupled`")
            && e.contains("`modal`")
    );
    // A listener the asset does not have, alone or in a stereo pair, is refused when the first
    // key is made, naming the asset's.
    for (file, field) in [
        (
            "bad_keyboard_listener.toml",
            "`radiation.listener` = `balcony`",
        ),
        (
            "bad_keyboard_stereo.toml",
            "`radiation.stereo (right)` = `gallery`",
        ),
    ] {
        let e = refusal(file, |path| {
            Scaling::resolve(path).and_then(|s| s.key_preset(40))
        });
        assert!(e.contains(file) && e.contains(field) && e.contains("above, treble, bass"));
    }
    let e = keyboard_error("bad_keyboard_no_layout.toml");
    assert!(e.contains("`layout`") && e.contains("base_keyboard"));
    let e = keyboard_error("bad_keyboard_modes.toml");
    assert!(e.contains("`layout.max_modes_t` = 100000") && e.contains("1 to 400"));
    let e = keyboard_error("bad_keyboard_band_edge.toml");
    assert!(
        e.contains("bad_keyboard_band_edge.toml")
            && e.contains("`layout.max_mode_freq_hz` = 30000")
            && e.contains("24000 Hz")
    );
    let e = keyboard_error("bad_keyboard_mode_limit.toml");
    assert!(
        e.contains("bad_keyboard_mode_limit.toml")
            && e.contains("`mode_limits.max_mode_freq_hz` = 30000 (from key 80)")
            && e.contains("24000 Hz")
    );
    let e = keyboard_error("bad_keyboard_mode_limit_keys.toml");
    assert!(
        e.contains("bad_keyboard_mode_limit_keys.toml")
            && e.contains("`mode_limits.from_key` = [86, 40]")
            && e.contains("increasing keys")
    );
    // A device that never ends is refused after 1 MiB, not read forever.
    let e = Scaling::resolve("/dev/zero").unwrap_err().to_string();
    println!("/dev/zero: {e}");
    assert!(e.contains("/dev/zero") && e.contains("longer than 1048576 bytes"));
}

/// Each command fails, its message contains the needle, and `out` (if any) was not written.
fn assert_refused(cases: &[(&[&str], &str)], out: Option<&str>) {
    for &(args, needle) in cases {
        let (code, stderr) = cli(args);
        assert_eq!(
            code,
            Some(1),
            "must fail with status 1 (the README's promise)"
        );
        assert!(stderr.contains(needle), "message names `{needle}`");
        // Each cause once: the message does not repeat what it wraps.
        assert!(stderr.matches("(os error").count() <= 1, "a cause repeated");
        if let Some(out) = out {
            assert!(!Path::new(out).exists(), "nothing written");
        }
    }
}

#[test]
fn cli_rejects_bad_input_without_writing() {
    let dir = tempfile::tempdir().unwrap();
    let wav = dir.path().join("out.wav");
    let wav = wav.to_str().unwrap();
    let bad_preset = data("bad_preset_range.toml");
    let cases: [(&[&str], &str); 12] = [
        (&["modes", "--max-hz", "0"], "--max-hz 0"),
        (&["modes", "--key", "H9"], "--key H9"),
        (
            &["analyze", "--keys", "C4,H9"],
            "--keys: \"H9\" is not a key",
        ),
        (
            &["analyze", "--keyboard", "no-such-keyboard"],
            "no-such-keyboard",
        ),
        (
            &["render", "--offline", "--midi-velocity", "0", "--out", wav],
            "--midi-velocity 0",
        ),
        (
            &["render", "--offline", "--preset", &bad_preset, "--out", wav],
            "strings.tension_n",
        ),
        (
            &["render", "--offline", "--seconds", "-1", "--out", wav],
            "--seconds",
        ),
        (
            &["render", "--offline", "--seconds", "nan", "--out", wav],
            "--seconds",
        ),
        (
            &["render", "--offline", "--velocity", "40", "--out", wav],
            "--velocity 40",
        ),
        (
            &["render", "--key", "C4", "--release-at", "31", "--out", wav],
            "--release-at 31",
        ),
        (
            &["figures", "--seconds", "0", "--out-dir", wav],
            "--seconds",
        ),
        (
            &["render", "--key", "C4", "--soft", "1.5", "--out", wav],
            "--soft 1.5",
        ),
    ];
    assert_refused(&cases, Some(wav));
}

#[test]
fn cli_renders_a_short_wav() {
    let dir = tempfile::tempdir().unwrap();
    let wav = dir.path().join("c2.wav");
    let (code, _) = cli(&[
        "render",
        "--offline",
        "--preset",
        "c2",
        "--una-corda",
        "--seconds",
        "0.2",
        "--out",
        wav.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0));
    let reader = hound::WavReader::open(&wav).unwrap();
    assert_eq!(reader.spec().sample_rate, 48_000);
    let samples: Vec<f32> = reader.into_samples::<f32>().map(Result::unwrap).collect();
    assert_eq!(samples.len(), 9600);
    let peak = samples.iter().fold(0f32, |m, s| m.max(s.abs()));
    println!("0.2 s una corda render: peak {peak:.3} of full scale");
    assert!(samples.iter().all(|s| s.is_finite()) && peak > 1e-3 && peak <= 1.0);
}

#[test]
fn cli_lists_a_keys_modes() {
    // C4 (three strings near 261.6 Hz): the table names the strings' modes, and the CSV holds
    // every listed one.
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("c4.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_unacorda"))
        .args(["modes", "--key", "C4", "--max-hz", "600", "--csv"])
        .arg(&csv)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
    let table = String::from_utf8_lossy(&out.stdout);
    println!("{table}");
    let rows: Vec<Vec<String>> = std::fs::read_to_string(&csv)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    assert_eq!(
        table.lines().count(),
        rows.len() + 2,
        "a table line per CSV row"
    );
    let near = |f: f64| {
        rows.iter()
            .filter(|r| {
                let hz: f64 = r[0].parse().unwrap();
                (hz / f - 1.0).abs() < 0.01 && r[4].starts_with("string")
            })
            .count()
    };
    // Partials 1 and 2: T and P of each of the three strings.
    assert_eq!((near(261.6), near(523.3)), (6, 6));
}

/// A one-note MIDI file whose note-off comes `beats` quarter notes later at 120 bpm.
fn long_midi(path: &Path, beats: u32) {
    use midly::num::{u15, u28, u4, u7};
    use midly::{
        Format, Header, MetaMessage, MidiMessage, Smf, Timing, TrackEvent, TrackEventKind,
    };
    let note = |delta: u32, vel: u8| TrackEvent {
        delta: u28::new(delta),
        kind: TrackEventKind::Midi {
            channel: u4::new(0),
            message: MidiMessage::NoteOn {
                key: u7::new(60),
                vel: u7::new(vel),
            },
        },
    };
    let mut smf = Smf::new(Header::new(
        Format::SingleTrack,
        Timing::Metrical(u15::new(480)),
    ));
    smf.tracks.push(vec![
        note(0, 80),
        note(480 * beats, 0),
        TrackEvent {
            delta: u28::new(0),
            kind: TrackEventKind::Meta(MetaMessage::EndOfTrack),
        },
    ]);
    smf.save(path).unwrap();
}

#[test]
fn midi_renders_refuse_bad_limits_and_hour_long_files() {
    let dir = tempfile::tempdir().unwrap();
    let wav = dir.path().join("out.wav");
    let wav = wav.to_str().unwrap();
    let long = dir.path().join("long.mid");
    // 8000 beats at 120 bpm: 4000 s, over an hour.
    long_midi(&long, 8000);
    let long = long.to_str().unwrap();
    let cases: [(&[&str], &str); 4] = [
        (
            &["render", "--offline", "--midi", long, "--out", wav],
            "lasts 4002 s",
        ),
        (
            &[
                "render",
                "--offline",
                "--midi",
                long,
                "--max-seconds",
                "0",
                "--out",
                wav,
            ],
            "--max-seconds 0",
        ),
        (
            &[
                "render",
                "--offline",
                "--midi",
                long,
                "--voices",
                "0",
                "--max-seconds",
                "5000",
                "--out",
                wav,
            ],
            "1 to 256 voices",
        ),
        (
            &[
                "render",
                "--offline",
                "--midi",
                long,
                "--tail",
                "-1",
                "--out",
                wav,
            ],
            "--tail -1",
        ),
    ];
    assert_refused(&cases, Some(wav));
}

#[test]
fn missing_files_are_named_once() {
    let dir = tempfile::tempdir().unwrap();
    let wav = dir.path().join("out.wav");
    let wav = wav.to_str().unwrap();
    let cases: [(&[&str], &str); 3] = [
        (
            &["render", "--offline", "--midi", "nosuch.mid", "--out", wav],
            "nosuch.mid: cannot read MIDI file: No such file",
        ),
        (
            &["analyze", "--keyboard", "nosuch.toml"],
            "nosuch.toml: cannot read: No such file",
        ),
        (
            &[
                "render",
                "--offline",
                "--preset",
                "nosuch.toml",
                "--out",
                wav,
            ],
            "nosuch.toml: cannot read: No such file",
        ),
    ];
    assert_refused(&cases, Some(wav));
}

/// Flags the command line's parser refuses — a value that is not a number, a required flag
/// missing, an unknown flag — exit with status 1 like every other bad input, nothing written;
/// `--help` with 0.
#[test]
fn unparsable_flags_exit_with_status_1() {
    let dir = tempfile::tempdir().unwrap();
    let wav = dir.path().join("out.wav");
    let wav = wav.to_str().unwrap();
    let cases: [(&[&str], &str); 3] = [
        (
            &["render", "--offline", "--seconds", "abc", "--out", wav],
            "abc",
        ),
        (&["render", "--offline", "--key", "C4"], "--out"),
        (&["play", "--no-such-flag"], "--no-such-flag"),
    ];
    assert_refused(&cases, Some(wav));
    let (code, _) = cli(&["render", "--help"]);
    assert_eq!(code, Some(0), "--help is not an error");
}

#[test]
fn play_refuses_bad_flags_and_missing_devices() {
    let cases: [(&[&str], &str); 4] = [
        (&["play", "--voices", "0"], "--voices 0"),
        (&["play", "--seconds", "-2"], "--seconds -2"),
        (
            &["play", "--device", "no-such-device", "--callbacks", "1"],
            "no audio output device matches \"no-such-device\"",
        ),
        (
            &[
                "play",
                "--device",
                "null",
                "--buffer",
                "3",
                "--callbacks",
                "1",
            ],
            "--buffer 3",
        ),
    ];
    assert_refused(&cases, None);
}

#[test]
fn bench_writes_every_printed_figure_as_json() {
    // A short bench: the JSON holds each engine's callback figures for every voice count it
    // printed, the same numbers as the text, each with its scenario; the held chord's windows
    // as printed; and the real-time factors, start-up and memory.
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("bench.json");
    let out = Command::new(env!("CARGO_BIN_EXE_unacorda"))
        .args(["bench", "--seconds", "0.1", "--voices", "2", "--json"])
        .arg(&json)
        .env("UNACORDA_CACHE", dir.path().join("keys"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8_lossy(&out.stdout);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    // The text's "(0.28 × deadline)" medians, in order, and on two cores its "cores meet in
    // 0.19 / 0.22 us" ("-" where the cores did not meet within the bench's 2 s: a loaded machine).
    let lines: Vec<&str> = text
        .lines()
        .filter(|l| l.contains(" voices: median"))
        .collect();
    let printed: Vec<f64> = lines
        .iter()
        .map(|l| {
            let open = l.find('(').unwrap();
            l[open + 1..]
                .split('×')
                .next()
                .unwrap()
                .trim()
                .parse()
                .unwrap()
        })
        .collect();
    let meetings: Vec<Option<Vec<Option<f64>>>> = lines
        .iter()
        .map(|l| {
            let (_, after) = l.split_once("cores meet in ")?;
            let figures = after.split(" us").next()?;
            Some(
                figures
                    .split(" / ")
                    .map(|m| m.trim().parse().ok())
                    .collect(),
            )
        })
        .collect();
    let callbacks = report["callbacks"].as_array().unwrap();
    println!(
        "{} callback figures printed, {} in the JSON",
        printed.len(),
        callbacks.len()
    );
    assert_eq!(printed.len(), callbacks.len());
    assert_eq!(
        printed.len(),
        6,
        "rk4 and the exact pool, on one core and (exact) two, 1 and 2 voices"
    );
    for ((p, c), meeting_printed) in printed.iter().zip(callbacks).zip(&meetings) {
        for field in [
            "engine",
            "cores",
            "voices",
            "scenario",
            "median_x_deadline",
            "p999_x_deadline",
            "misses",
            "blocks",
        ] {
            assert!(!c[field].is_null(), "{field} in {c}");
        }
        let median = c["median_x_deadline"].as_f64().unwrap();
        assert!((median - p).abs() <= 0.0051, "printed {p}, JSON {median}");
        // On two cores, the cores' meeting before and after the blocks (this machine's state),
        // as printed: a time, or none where they did not meet in time.
        if c["cores"] == 2 && std::thread::available_parallelism().map_or(1, |n| n.get()) >= 2 {
            let meeting = c["meeting_us"].as_array().expect("meeting_us on two cores");
            let printed = meeting_printed
                .as_ref()
                .expect("the meeting printed on two cores");
            assert_eq!(meeting.len(), 2);
            for (m, p) in meeting.iter().zip(printed) {
                match p {
                    Some(us) => {
                        let json = m.as_f64().unwrap_or(f64::NAN);
                        assert!((json - us).abs() <= 0.0051 && json > 0.0, "{c}");
                    }
                    None => assert!(m.is_null(), "{c}"),
                }
            }
        }
        assert!(c["p999_x_deadline"].as_f64().unwrap() >= median);
        let scenario = c["scenario"].as_str().unwrap();
        assert!(
            scenario.contains("sustain down") && scenario.contains(&format!("{} key", c["voices"])),
            "{c}"
        );
    }
    // The keyboard played: `concert` by default, what `play` sounds.
    assert_eq!(report["keyboard"], "concert");
    assert!(text.contains("live callback: concert keyboard, exact engine"));
    // The held chord: each window's median and voices as printed, in order, over the 10 s after
    // the strike.
    let held: Vec<(f64, u64, u64)> = text
        .lines()
        .filter(|l| l.contains("after the strike: median"))
        .map(|l| {
            let open = l.find('(').unwrap();
            let median = l[open + 1..].split('×').next().unwrap().trim().parse();
            // "…, 7 voices active at its end, stepping 2848 modes"
            let number_of = |segment: &str| -> u64 {
                let part = l.split(", ").find(|p| p.contains(segment)).unwrap();
                let word = part.split(' ').find(|w| w.parse::<u64>().is_ok()).unwrap();
                word.parse().unwrap()
            };
            (
                median.unwrap(),
                number_of("voices active"),
                number_of("modes"),
            )
        })
        .collect();
    let windows = report["held_chord"].as_array().unwrap();
    println!("held chord: printed {held:?}");
    assert_eq!(held.len(), 5);
    assert_eq!(windows.len(), held.len());
    assert_eq!(windows[0]["from_s"], 0.0);
    assert_eq!(windows[4]["to_s"], 10.0);
    for (w, (median, voices, modes)) in windows.iter().zip(&held) {
        let json = w["median_x_deadline"].as_f64().unwrap();
        assert!(
            (json - median).abs() <= 0.0051,
            "printed {median}, JSON {w}"
        );
        assert_eq!(w["active_voices"].as_u64(), Some(*voices), "{w}");
        assert_eq!(w["modes_stepped"].as_u64(), Some(*modes), "{w}");
        assert!(w["scenario"]
            .as_str()
            .unwrap()
            .contains("C2 G2 E3 C4 E4 G4 C5"));
    }
    let engines: Vec<&str> = report["voices"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["engine"].as_str().unwrap())
        .collect();
    assert_eq!(engines, ["rk4-f64", "rk4-f32", "exact"]);
    assert!(report["voices"][2]["real_time_factor"].as_f64().unwrap() > 0.0);
    assert_eq!(report["startup"][0]["keys"], 88);
    // The exact engine's keys prepared and kept, then its start-up from them.
    let exact: Vec<_> = report["startup"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|s| s["engine"] == "exact")
        .map(|s| s["keys_from_cache"].as_u64().unwrap())
        .collect();
    println!("exact engine's start-up, keys read back: {exact:?}");
    assert_eq!(exact, [0, 88]);
    assert!(report["memory"][0]["bytes_per_voice"].as_u64().unwrap() > 0);
}

#[test]
fn pools_refuse_keys_that_stand_on_different_boards() {
    // Every key of one instrument shares its soundboard, the board's dropped modes included:
    // RK4 carries them once for all its keys (`engine::pool::check_keys`). C7 of the concert
    // keyboard beside the same key without its dropped modes, in either order, or with its
    // first dropped mode 1 % higher: both engines refuse the pair, where RK4 stepped the first
    // key's dropped modes and silently left the other key's force off them (or carried none).
    use unacorda::engine::{exact::ExactPool, BuildError, Rk4Pool, VoicePool};
    let preset = Scaling::resolve("concert").unwrap().key_preset(76).unwrap();
    let with = preset.unison_spec();
    let (mut without, mut moved) = (with.clone(), with.clone());
    without.dropped = None;
    moved.dropped.as_mut().unwrap().freq_hz[0] *= 1.01;
    let rate = preset.output_rate_hz();
    for specs in [
        [with.clone(), without.clone()],
        [without, with.clone()],
        [with, moved],
    ] {
        let refused = [
            Rk4Pool::build_pool(&specs, 2, rate).err(),
            ExactPool::build_pool(&specs, 2, rate).err(),
        ];
        println!("{refused:?}");
        assert_eq!(refused, [const { Some(BuildError::SharedBoard) }; 2]);
    }
}
