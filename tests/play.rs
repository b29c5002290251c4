//! Keys sharing one soundboard, played through MIDI events with the pedals.

use midly::num::{u15, u28, u4, u7};
use midly::{Format, Header, MetaMessage, MidiMessage, Smf, Timing, TrackEvent, TrackEventKind};
use std::process::Command;
use unacorda::config::scaling::{parse_key, Scaling};
use unacorda::engine::Policy;
use unacorda::engine::UnisonSpec;
use unacorda::engine::{Rk4Pool, Strike};
use unacorda::midi::file::TimedEvent;
use unacorda::midi::{Event, Pedal};
use unacorda::render::render_midi_with;

fn key_spec(name: &str) -> (usize, UnisonSpec) {
    let keyboard = Scaling::resolve("paper").unwrap();
    let k = parse_key(name).unwrap();
    (k, keyboard.key_preset(k).unwrap().unison_spec())
}

fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

#[test]
fn a_damped_second_key_on_the_board_barely_changes_the_first() {
    // C2 struck alone on its board, and with C3 sounding beside it on the same board (simulated,
    // its damper down): C3's strings load the board at its point, so C2's bridge force changes a
    // little, and only a little.
    let (_, c2) = key_spec("C2");
    let (_, c3) = key_spec("C3");
    let mut one = Rk4Pool::new(&c2).unwrap();
    let mut two = Rk4Pool::with_keys(&[c2, c3]).unwrap();
    two.set_active(1, true);
    two.set_damper_voice(1, true);
    let strike = Strike {
        velocity_m_s: 2.5,
        shift: 0.0,
    };
    one.strike(strike);
    two.strike_voice(0, strike);
    let (mut diff, mut power) = (0.0, 0.0);
    let steps = (0.1 / one.step_s()) as usize;
    for _ in 0..steps {
        one.step();
        two.step();
        let (a, b) = (
            one.observe().total_force_n[0],
            two.observe_voice(0).total_force_n[0],
        );
        diff += (a - b).powi(2);
        power += a * a;
    }
    let relative = (diff / power).sqrt();
    println!("C2 alone vs C2 beside a damped C3 on the same board, bridge T force over 100 ms: RMS difference {relative:.2e} of C2's");
    // C3 enters the arithmetic (an inactive voice would give 0), and changes C2 by little.
    assert!(relative > 1e-6, "C3 did not take part: {relative:e}");
    assert!(relative < 0.05, "C3 changed C2 by {relative}");
}

#[test]
fn undamped_strings_ring_in_sympathy_through_the_board() {
    let (_, c2) = key_spec("C2");
    let (_, c3) = key_spec("C3");
    let run = |c3_damper_up: bool| -> f64 {
        let mut u = Rk4Pool::with_keys(&[c2.clone(), c3.clone()]).unwrap();
        u.set_active(1, true);
        u.set_damper_voice(1, !c3_damper_up);
        u.strike_voice(
            0,
            Strike {
                velocity_m_s: 2.5,
                shift: 0.0,
            },
        );
        let steps = (0.6 / u.step_s()) as usize;
        let mut late = Vec::new();
        for k in 0..steps {
            u.step();
            if k * 10 >= steps * 8 {
                late.push(u.observe_voice(1).total_force_n[0]);
            }
        }
        rms(&late)
    };
    let (up, down) = (run(true), run(false));
    let gain_db = 20.0 * (up / down).log10();
    println!("C2 struck; unstruck C3's T force on the bridge, RMS 0.48–0.6 s: damper up {up:.2e} N, down {down:.2e} N ({gain_db:.1} dB)");
    // A lifted damper lets C3 ring in sympathy: 28.6 dB louder than against its damper.
    assert!((25.0..32.0).contains(&gain_db), "{gain_db:.1} dB");
}

/// Render `events` (time s, event) through the MIDI render path (queue, synth, voice pool) and
/// record, at every output frame, the observation of the voice playing each of `names` (nothing
/// before its first note; once a key has a voice it must keep it: the pool of 32 never steals
/// here).
fn perform(
    names: &[&str],
    events: &[(f64, Event)],
    tail_s: f64,
) -> (Vec<Vec<unacorda::engine::Observation>>, f64) {
    let scaling = Scaling::resolve("paper").unwrap();
    let timed: Vec<TimedEvent> = events
        .iter()
        .map(|&(time_s, event)| TimedEvent { time_s, event })
        .collect();
    let keys: Vec<usize> = names.iter().map(|n| parse_key(n).unwrap()).collect();
    let mut obs = vec![Vec::new(); keys.len()];
    let perf = render_midi_with(
        &scaling,
        &timed,
        tail_s,
        32,
        |_| {},
        |inst, _| {
            for (k, o) in obs.iter_mut().enumerate() {
                // The bank holds the file's keys in ascending order.
                let bank = {
                    let mut sorted = keys.clone();
                    sorted.sort_unstable();
                    sorted.iter().position(|&x| x == keys[k]).unwrap()
                };
                o.push(inst.voice_of_key(bank).map(|v| inst.observe_voice(v)));
            }
        },
    )
    .unwrap();
    let obs = obs
        .into_iter()
        .map(|o| {
            let first = o
                .iter()
                .position(Option::is_some)
                .expect("the key was played");
            assert!(
                o[first..].iter().all(Option::is_some),
                "a key lost its voice"
            );
            o.into_iter().map(Option::unwrap_or_default).collect()
        })
        .collect();
    (obs, perf.rate_hz)
}

#[test]
fn soft_pedal_marks_only_the_notes_played_under_it() {
    let events = [
        (0.0, Event::pedal(Pedal::Soft, true)),
        (
            0.0,
            Event::NoteOn {
                note: 36,
                velocity: 90.0,
            },
        ),
        (0.05, Event::pedal(Pedal::Soft, false)),
        (
            0.05,
            Event::NoteOn {
                note: 48,
                velocity: 90.0,
            },
        ),
    ];
    let (obs, fs) = perform(&["C2", "C3"], &events, 0.15);
    let peak = |v: usize, s: usize| obs[v].iter().fold(0f64, |m, o| m.max(o.hammer_force_n[s]));
    println!("MIDI file through the queue and the synth — hammer force peaks (N): C2 (soft pedal) strings {:.1} {:.1}; C3 (no pedal) strings {:.1} {:.1} {:.1}",
        peak(0, 0), peak(0, 1), peak(1, 0), peak(1, 1), peak(1, 2));
    assert!(
        peak(0, 0) > 1.0 && peak(0, 1) == 0.0,
        "una corda on C2: one string of two"
    );
    assert!(
        (0..3).all(|s| peak(1, s) > 1.0),
        "C3 after the pedal rose: all three strings"
    );
    // The passive C2 string's bridge force grows, the una-corda signature of issue 2.
    let per_ms = fs / 1000.0;
    let f2: Vec<f64> = obs[0].iter().map(|o| o.bridge_force_n[1][0]).collect();
    let ms = |a: f64, b: f64| &f2[(a * per_ms) as usize..(b * per_ms) as usize];
    let (early, later) = (rms(ms(0.0, 15.0)), rms(ms(135.0, 150.0)));
    println!(
        "passive C2 string, T bridge force RMS: 0–15 ms {early:.3} N, 135–150 ms {later:.3} N"
    );
    assert!(later > 3.0 * early);
}

#[test]
fn sustain_keeps_a_released_key_ringing() {
    let level = |sustain: bool| -> f64 {
        let mut events = vec![
            (
                0.0,
                Event::NoteOn {
                    note: 36,
                    velocity: 90.0,
                },
            ),
            (
                0.1,
                Event::NoteOff {
                    note: 36,
                    velocity: 64.0,
                },
            ),
        ];
        if sustain {
            events.insert(1, (0.05, Event::pedal(Pedal::Sustain, true)));
        }
        let (obs, _) = perform(&["C2"], &events, 0.5);
        let tail: Vec<f64> = obs[0][obs[0].len() * 5 / 6..]
            .iter()
            .map(|o| o.total_force_n[0])
            .collect();
        20.0 * rms(&tail).max(1e-30).log10()
    };
    let (held, damped) = (level(true), level(false));
    println!("C2 released at 0.1 s (MIDI render path), T force level 0.5–0.6 s: sustain down {held:.1} dB, no pedal {damped:.1} dB");
    assert!(held - damped > 20.0);
}

#[test]
fn cli_renders_a_midi_file() {
    let ev = |delta: u32, kind| TrackEvent {
        delta: u28::new(delta),
        kind,
    };
    let midi = |message| TrackEventKind::Midi {
        channel: u4::new(0),
        message,
    };
    let mut smf = Smf::new(Header::new(
        Format::SingleTrack,
        Timing::Metrical(u15::new(480)),
    ));
    smf.tracks.push(vec![
        ev(
            0,
            midi(MidiMessage::Controller {
                controller: u7::new(67),
                value: u7::new(127),
            }),
        ),
        ev(
            0,
            midi(MidiMessage::NoteOn {
                key: u7::new(36),
                vel: u7::new(80),
            }),
        ),
        ev(
            96,
            midi(MidiMessage::NoteOn {
                key: u7::new(60),
                vel: u7::new(70),
            }),
        ),
        ev(
            96,
            midi(MidiMessage::NoteOff {
                key: u7::new(36),
                vel: u7::new(0),
            }),
        ),
        ev(0, TrackEventKind::Meta(MetaMessage::EndOfTrack)),
    ]);
    let dir = tempfile::tempdir().unwrap();
    let (mid, wav) = (dir.path().join("two.mid"), dir.path().join("two.wav"));
    smf.save(&mid).unwrap();
    // The concert keyboard in stereo (its pair of listeners), and with --mono at its listener.
    for (mono, channels) in [(false, 2), (true, 1)] {
        let mut args = vec!["render", "--offline", "--midi", mid.to_str().unwrap()];
        args.extend(["--tail", "0.1", "--out", wav.to_str().unwrap()]);
        if mono {
            args.push("--mono");
        }
        let out = Command::new(env!("CARGO_BIN_EXE_unacorda"))
            .args(&args)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        println!("{}", stderr.trim());
        let sound = if mono { "mono" } else { "stereo" };
        assert!(out.status.success() && stderr.contains("on 2 keys") && stderr.contains(sound));
        let reader = hound::WavReader::open(&wav).unwrap();
        assert_eq!(reader.spec().channels, channels);
        let samples: Vec<f32> = reader.into_samples::<f32>().map(Result::unwrap).collect();
        // Last event at 192 ticks = 0.2 s (120 bpm), plus the 0.1 s tail.
        assert_eq!(
            samples.len(),
            (0.3 * 48_000.0) as usize * usize::from(channels)
        );
        assert!(samples.iter().all(|s| s.is_finite()) && samples.iter().any(|s| s.abs() > 1e-3));
        if !mono {
            let differ = samples.chunks(2).filter(|lr| lr[0] != lr[1]).count();
            println!(
                "stereo: the channels differ in {differ} of {} frames",
                samples.len() / 2
            );
            assert!(differ > samples.len() / 4);
        }
    }
}
