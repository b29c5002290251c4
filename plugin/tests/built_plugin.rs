//! The built `unacorda.clap` (the cdylib this package makes) loaded as a DAW loads it, with
//! dlopen, by the headless host in `tests/host`: its ports, parameters and state; activation at
//! 44.1, 48 and 96 kHz with a note at a chosen frame in blocks of 1 to 4096 frames; and at 48 kHz
//! a MIDI performance with both pedals, its output equal sample for sample to what the command
//! line's `unacorda render --offline --midi` writes for the same MIDI file.

mod host;

use clack_host::prelude::PluginEntry;
use host::Play;
use midly::{Format, Header, MidiMessage, Smf, Timing, TrackEvent, TrackEventKind};
use std::path::PathBuf;

/// The directory cargo builds this test into (`target/<profile>/deps`), where the plugin's
/// cdylib is too.
fn deps_dir() -> PathBuf {
    std::env::current_exe()
        .unwrap()
        .parent()
        .unwrap()
        .to_path_buf()
}

/// The plugin built with this test, or the file `UNACORDA_CLAP` names (an installed
/// `unacorda.clap`, stripped by scripts/install-plugins.sh).
fn load() -> PluginEntry {
    let path = std::env::var_os("UNACORDA_CLAP").map_or_else(
        || {
            deps_dir().join(format!(
                "{}unacorda_clap{}",
                std::env::consts::DLL_PREFIX,
                std::env::consts::DLL_SUFFIX
            ))
        },
        PathBuf::from,
    );
    assert!(path.exists(), "{} not built", path.display());
    // SAFETY: the library is this package's own plugin, built with this test.
    unsafe { PluginEntry::load(&path) }.unwrap()
}

/// The command line, built beside this test by `cargo test --workspace` (scripts/test.sh).
fn cli() -> PathBuf {
    let path = deps_dir().parent().unwrap().join("unacorda");
    assert!(
        path.exists(),
        "{} not built: run the workspace's tests (bash scripts/test.sh)",
        path.display()
    );
    path
}

/// Ticks of the MIDI file: 480 per quarter at the default 120 bpm, 50 frames at 48 kHz.
const FRAMES_PER_TICK: u64 = 50;

/// A performance as (tick, MIDI message): notes, a release under the sustain pedal, the soft
/// pedal, a chord, a note-on at velocity 0 (a release in MIDI).
fn performance() -> Vec<(u64, [u8; 3])> {
    vec![
        (3, [0x90, 60, 96]),
        (20, [0x90, 67, 70]),
        (40, [0xB0, 64, 127]),
        (60, [0x80, 60, 0]),
        (70, [0x90, 67, 0]),
        (90, [0xB0, 67, 127]),
        (100, [0x90, 43, 100]),
        (100, [0x90, 55, 90]),
        (101, [0x90, 62, 85]),
        (140, [0xB0, 64, 0]),
        (150, [0xB0, 67, 0]),
        (160, [0x90, 79, 110]),
        (200, [0x80, 43, 0]),
        (200, [0x80, 55, 0]),
        (200, [0x80, 62, 0]),
        (230, [0x80, 79, 0]),
    ]
}

fn write_midi(path: &std::path::Path, events: &[(u64, [u8; 3])]) {
    let mut track = Vec::new();
    let mut last = 0;
    for &(tick, [status, d1, d2]) in events {
        let message = match status & 0xF0 {
            0x90 => MidiMessage::NoteOn {
                key: d1.into(),
                vel: d2.into(),
            },
            0x80 => MidiMessage::NoteOff {
                key: d1.into(),
                vel: d2.into(),
            },
            _ => MidiMessage::Controller {
                controller: d1.into(),
                value: d2.into(),
            },
        };
        track.push(TrackEvent {
            delta: ((tick - last) as u32).into(),
            kind: TrackEventKind::Midi {
                channel: (status & 0x0F).into(),
                message,
            },
        });
        last = tick;
    }
    track.push(TrackEvent {
        delta: 0.into(),
        kind: TrackEventKind::Meta(midly::MetaMessage::EndOfTrack),
    });
    let smf = Smf {
        header: Header::new(Format::SingleTrack, Timing::Metrical(480.into())),
        tracks: vec![track],
    };
    smf.save(path).unwrap();
}

#[test]
fn the_built_plugin_plays_like_the_command_line() {
    let entry = load();
    let mut plugin = host::instantiate(&entry);
    let (outputs, channels, note_ports, dialects) = host::ports(&mut plugin);
    let params = host::params(&mut plugin);
    println!(
        "loaded by dlopen: {outputs} audio output ({channels} ch), {note_ports} note input (dialects {dialects:#b}), {} parameters",
        params.len()
    );
    assert_eq!(
        (outputs, channels, note_ports, dialects & 0b11),
        (1, 2, 1, 0b11)
    );
    let state = host::save(&mut plugin);
    host::load(&mut plugin, &state).unwrap();
    assert_eq!(host::save(&mut plugin), state);

    let blocks = [1, 4096, 17, 333, 2, 1000, 95, 31, 64, 3, 512, 777];
    for rate_hz in [44_100.0, 96_000.0] {
        let mut active = host::activate(&mut plugin, rate_hz);
        let latency = host::latency(&mut plugin) as u64;
        let at = 1234;
        let heard = active.run(
            8192,
            &blocks,
            &[(at, Play::Midi([0x90, 69, 100]))],
            host::unchecked,
        );
        let first = heard.left.iter().position(|&s| s != 0.0);
        println!("{rate_hz} Hz: note at frame {at}, first sound at {first:?} (latency {latency})");
        assert_eq!(first, Some((at + latency) as usize));
        host::deactivate(&mut plugin, active);
    }

    let dir = tempfile::tempdir().unwrap();
    let (midi, wav) = (dir.path().join("p.mid"), dir.path().join("p.wav"));
    let performance = performance();
    write_midi(&midi, &performance);
    let tail_s = 0.3;
    let status = std::process::Command::new(cli())
        .args(["render", "--offline", "--midi"])
        .arg(&midi)
        .args(["--tail", &tail_s.to_string(), "--out"])
        .arg(&wav)
        .status()
        .unwrap();
    assert!(status.success());
    let mut reader = hound::WavReader::open(&wav).unwrap();
    assert_eq!(
        (reader.spec().channels, reader.spec().sample_rate),
        (2, 48_000)
    );
    let rendered: Vec<f32> = reader.samples::<f32>().map(Result::unwrap).collect();
    let frames = rendered.len() / 2;

    let mut active = host::activate(&mut plugin, 48_000.0);
    let latency = host::latency(&mut plugin) as usize;
    let script: Vec<(u64, Play)> = performance
        .iter()
        .map(|&(tick, data)| (tick * FRAMES_PER_TICK, Play::Midi(data)))
        .collect();
    let heard = active.run(frames + latency, &blocks, &script, host::unchecked);
    host::deactivate(&mut plugin, active);
    for (c, name, side) in [(0, "left", &heard.left), (1, "right", &heard.right)] {
        let cli_side: Vec<f32> = rendered.iter().skip(c).step_by(2).copied().collect();
        let differ = side[latency..]
            .iter()
            .zip(&cli_side)
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count();
        let peak = cli_side.iter().fold(0f32, |m, s| m.max(s.abs()));
        println!("48 kHz, {name}: {frames} frames of `unacorda render --offline --midi` (peak {peak:.3}), {differ} differ from the plugin's");
        assert!(peak > 0.01);
        assert_eq!(
            differ, 0,
            "{name}: the plugin does not sound as the command line"
        );
    }
}
