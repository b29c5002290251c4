//! Faults outside the engine: a disk that fills, a file-size limit, Ctrl-C during a long render,
//! an audio device lost mid-stream. The WAV that exists afterwards is valid and the message says
//! how much it holds; nothing panics.

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// A MIDI file of `notes` quarter notes (C4, E4, G4 in turn) at 120 bpm: `notes / 2` s of playing.
fn midi_file(path: &Path, notes: u32) {
    use midly::num::{u15, u28, u4, u7};
    use midly::{
        Format, Header, MetaMessage, MidiMessage, Smf, Timing, TrackEvent, TrackEventKind,
    };
    let ev = |delta: u32, key: u8, vel: u8| TrackEvent {
        delta: u28::new(delta),
        kind: TrackEventKind::Midi {
            channel: u4::new(0),
            message: MidiMessage::NoteOn {
                key: u7::new(key),
                vel: u7::new(vel),
            },
        },
    };
    let mut track = Vec::new();
    for n in 0..notes {
        let key = [60, 64, 67][n as usize % 3];
        track.push(ev(0, key, 80));
        track.push(ev(480, key, 0));
    }
    track.push(TrackEvent {
        delta: u28::new(0),
        kind: TrackEventKind::Meta(MetaMessage::EndOfTrack),
    });
    let mut smf = Smf::new(Header::new(
        Format::SingleTrack,
        Timing::Metrical(u15::new(480)),
    ));
    smf.tracks.push(track);
    smf.save(path).unwrap();
}

fn report(what: &str, out: &Output) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    println!(
        "{what}\n  → exit {:?}: {}",
        out.status.code(),
        stderr.trim()
    );
    assert!(!stderr.contains("panicked"), "must not panic");
    stderr
}

/// Seconds of sound in a WAV that hound reads completely, or a panic naming what is wrong.
fn valid_wav_seconds(path: &Path) -> f64 {
    let reader = hound::WavReader::open(path).expect("a valid WAV header");
    let (rate, channels) = (
        f64::from(reader.spec().sample_rate),
        usize::from(reader.spec().channels),
    );
    let n = reader.len() as usize;
    let samples: Vec<f32> = reader
        .into_samples::<f32>()
        .collect::<Result<_, _>>()
        .expect("every sample the header announces is there");
    assert_eq!(samples.len(), n);
    assert!(samples.iter().all(|s| s.is_finite() && s.abs() <= 1.0));
    assert_eq!(n % channels, 0, "whole frames");
    (n / channels) as f64 / rate
}

/// The number in `text` just before `unit` after `after` (e.g. "first 1.23 s").
fn number_after(text: &str, after: &str) -> f64 {
    let rest = &text[text.find(after).expect("phrase present") + after.len()..];
    rest.split_whitespace().next().unwrap().parse().unwrap()
}

#[test]
fn a_full_disk_leaves_a_valid_wav_and_says_how_much() {
    let dir = tempfile::tempdir().unwrap();
    let mid = dir.path().join("ten.mid");
    midi_file(&mid, 20);
    // A directory that does not exist: nothing is created.
    let out = Command::new(env!("CARGO_BIN_EXE_unacorda"))
        .args(["render", "--offline", "--midi", mid.to_str().unwrap()])
        .args(["--out", "/nonexistent/dir/out.wav"])
        .output()
        .unwrap();
    let e = report("render --midi … --out /nonexistent/dir/out.wav", &out);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        e.contains("/nonexistent/dir/out.wav: cannot create the WAV") && e.contains("No such file")
    );
    // The device that is always full: nothing can be written at all.
    let out = Command::new(env!("CARGO_BIN_EXE_unacorda"))
        .args(["render", "--offline", "--midi", mid.to_str().unwrap()])
        .args(["--out", "/dev/full"])
        .output()
        .unwrap();
    let e = report("render --midi … --out /dev/full", &out);
    assert_eq!(out.status.code(), Some(1));
    assert!(e.contains("/dev/full") && e.contains("No space left on device"));
    // A file-size limit of 400 blocks (200–400 kB): the render fills it part way. SIGXFSZ is
    // ignored, as a disk-full write fails, with an error rather than a signal.
    let wav = dir.path().join("limited.wav");
    let out = Command::new("sh")
        .args(["-c", "trap '' XFSZ; ulimit -f 400; exec \"$0\" \"$@\""])
        .arg(env!("CARGO_BIN_EXE_unacorda"))
        .args(["render", "--offline", "--midi", mid.to_str().unwrap()])
        .args(["--out", wav.to_str().unwrap()])
        .output()
        .unwrap();
    let e = report("ulimit -f 400; render --midi (10 s) …", &out);
    assert_eq!(out.status.code(), Some(1));
    assert!(e.contains("limited.wav") && e.contains("File too large"));
    let kept = number_after(&e, "holds the first ");
    let seconds = valid_wav_seconds(&wav);
    println!(
        "the file holds {seconds:.3} s ({} bytes); the message says {kept:.2} s",
        std::fs::metadata(&wav).unwrap().len()
    );
    assert!((seconds - kept).abs() < 0.01 && seconds > 0.5 && seconds < 10.0);
}

#[test]
fn ctrl_c_during_a_render_leaves_a_valid_wav_and_says_how_much() {
    let dir = tempfile::tempdir().unwrap();
    let mid = dir.path().join("minute.mid");
    midi_file(&mid, 120);
    let wav = dir.path().join("interrupted.wav");
    let child = Command::new(env!("CARGO_BIN_EXE_unacorda"))
        .args(["render", "--offline", "--midi", mid.to_str().unwrap()])
        .args(["--out", wav.to_str().unwrap()])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until more than a second of sound has reached the file (the concert keyboard in
    // stereo: 8 bytes a frame), then interrupt.
    let t = Instant::now();
    while std::fs::metadata(&wav).map_or(0, |m| m.len()) < 48_000 * 8 {
        assert!(
            t.elapsed() < Duration::from_secs(120),
            "the render wrote nothing"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let out = child.wait_with_output().unwrap();
    let e = report("render --midi (61 s) …, SIGINT after ≥ 1 s written", &out);
    assert_eq!(out.status.code(), Some(1));
    assert!(e.contains("interrupted") && e.contains("valid WAV"));
    let kept = number_after(&e, "holds the first ");
    let seconds = valid_wav_seconds(&wav);
    println!("the file holds {seconds:.3} s; the message says {kept:.2} s of 62 s");
    assert!((seconds - kept).abs() < 0.01 && (1.0..60.0).contains(&seconds));
}

#[test]
fn a_lost_audio_device_is_reopened_with_the_engine_intact() {
    // cpal reports an unplugged device through the stream's error callback; the null device is
    // never unplugged, so `--lose-device-after` delivers that same error (DeviceNotAvailable)
    // after 200 callbacks. `play` must take the engine back from the dead stream, open the device
    // again and go on: the one synth has then processed every callback of both streams.
    let dir = tempfile::tempdir().unwrap();
    let mid = dir.path().join("one.mid");
    midi_file(&mid, 1);
    let out = Command::new(env!("CARGO_BIN_EXE_unacorda"))
        .args([
            "play", "--device", "null", "--buffer", "64", "--voices", "2",
        ])
        .args(["--callbacks", "600", "--lose-device-after", "200"])
        .args(["--midi", mid.to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = report("play --device null … --lose-device-after 200", &out);
    assert!(out.status.success());
    assert!(stderr.contains("audio: device alsa:null lost"));
    assert!(stderr.contains("audio: reopened alsa:null"));
    let summary = stderr.lines().find(|l| l.starts_with("played")).unwrap();
    let callbacks = number_after(summary, ": ") as u64;
    let frames = number_after(summary, "callbacks (");
    println!("{callbacks} callbacks, {frames} frames through one synth");
    assert!(callbacks >= 600 && frames == (callbacks * 64) as f64);
    assert!(stderr.contains("lost, and reopened 1 times"));
}
