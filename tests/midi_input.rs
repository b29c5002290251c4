//! MIDI input: the live byte parser (the one the midir callback feeds) and the MIDI-file reader.

use midly::num::{u15, u24, u28, u4, u7};
use midly::{
    Format, Fps, Header, MetaMessage, MidiMessage, Smf, Timing, TrackEvent, TrackEventKind,
};
use std::path::Path;
use unacorda::midi::file::parse;
use unacorda::midi::live::LiveParser;
use unacorda::midi::{Event, Pedal};

fn live(bytes: &[u8]) -> Vec<Event> {
    let mut p = LiveParser::new();
    let mut out = Vec::new();
    p.feed(bytes, |e| out.push(e));
    out
}

#[test]
fn live_parser_follows_the_midi_byte_grammar() {
    // Running status: one note-on status, three notes, the last with velocity 0 (a note-off).
    assert_eq!(
        live(&[0x90, 60, 100, 64, 90, 60, 0]),
        [
            Event::NoteOn {
                note: 60,
                velocity: 100.0
            },
            Event::NoteOn {
                note: 64,
                velocity: 90.0
            },
            Event::NoteOff {
                note: 60,
                velocity: 64.0
            }
        ]
    );
    // Real-time bytes (clock, active sensing) inside a message change nothing.
    assert_eq!(
        live(&[0x91, 0xF8, 48, 0xFE, 70]),
        [Event::NoteOn {
            note: 48,
            velocity: 70.0
        }]
    );
    // SysEx is skipped, and clears running status: the stray data after it is dropped.
    assert_eq!(
        live(&[0x90, 60, 1, 0xF0, 0x7E, 60, 100, 0xF7, 61, 100]),
        [Event::NoteOn {
            note: 60,
            velocity: 1.0
        }]
    );
    // System common (song position, 2 data bytes) is skipped with its data.
    assert_eq!(
        live(&[0xF2, 60, 100, 0xB0, 67, 127]),
        [Event::pedal(Pedal::Soft, true)]
    );
    // Pedals and channel-mode messages on any channel; pitch bend and program change ignored.
    assert_eq!(
        live(&[0xBF, 64, 63, 0xB3, 66, 64, 0xE0, 0, 64, 0xC0, 5, 0xB0, 120, 0, 121, 0, 123, 0]),
        [
            Event::Pedal {
                pedal: Pedal::Sustain,
                depth: 63.0 / 127.0
            },
            Event::Pedal {
                pedal: Pedal::Sostenuto,
                depth: 64.0 / 127.0
            },
            Event::AllSoundOff,
            Event::ResetControllers,
            Event::AllNotesOff
        ]
    );
    // Data bytes with no status at all are dropped.
    assert_eq!(
        live(&[60, 100, 0x80, 60, 0]),
        [Event::NoteOff {
            note: 60,
            velocity: 64.0
        }]
    );
    // A stray end-of-SysEx is a system common message too: it cancels running status (found by
    // the reference decoder below; the parser used to keep it).
    assert_eq!(
        live(&[0x90, 60, 100, 0xF7, 61, 100]),
        [Event::NoteOn {
            note: 60,
            velocity: 100.0
        }]
    );
    println!(
        "live parser: running status, interleaved real-time, SysEx, system common, stray data: ok"
    );
}

/// A second decoder of the MIDI 1.0 byte stream, written from the specification and
/// independently of `LiveParser` and `map_channel_message`: every status byte ends what came
/// before it; real-time bytes (0xF8–0xFF) are transparent; SysEx and the system common messages
/// (0xF1–0xF7, EOX included) cancel running status, the latter skipping their data bytes.
fn reference_decoder(bytes: &[u8]) -> Vec<Event> {
    #[derive(Clone, Copy)]
    enum Mode {
        Idle,
        Channel(u8),
        SysEx,
        Common(usize),
    }
    // The CC88 prefix of each channel: the low 7 bits of its next note's 14-bit velocity.
    let mut lsb = [0u8; 16];
    let mut decode = |status: u8, d: &[u8]| -> Option<Event> {
        let (kind, a, b) = (status >> 4, d[0], d.get(1).copied().unwrap_or(0));
        let prefix = &mut lsb[usize::from(status & 0xF)];
        let pedal = |pedal| {
            Some(Event::Pedal {
                pedal,
                depth: f64::from(b) / 127.0,
            })
        };
        match (kind, a) {
            // A release velocity: the prefix's 14 bits, or MIDI's default for none (0).
            (0x8, _) if b > 0 => {
                let fourteen = u16::from(b) << 7 | u16::from(std::mem::take(prefix));
                Some(Event::NoteOff {
                    note: a,
                    velocity: (f64::from(fourteen) / 128.0).min(127.0),
                })
            }
            (0x8 | 0x9, _) if b == 0 => {
                *prefix = 0;
                Some(Event::NoteOff {
                    note: a,
                    velocity: 64.0,
                })
            }
            (0x9, _) => {
                let fourteen = u16::from(b) << 7 | u16::from(std::mem::take(prefix));
                Some(Event::NoteOn {
                    note: a,
                    velocity: (f64::from(fourteen) / 128.0).min(127.0),
                })
            }
            (0xB, 88) => {
                *prefix = b;
                None
            }
            (0xB, 64) => pedal(Pedal::Sustain),
            (0xB, 66) => pedal(Pedal::Sostenuto),
            (0xB, 67) => pedal(Pedal::Soft),
            (0xB, 120) => Some(Event::AllSoundOff),
            (0xB, 121) => {
                *prefix = 0;
                Some(Event::ResetControllers)
            }
            // All notes off, and the mode messages (omni off/on, mono, poly), which imply it.
            (0xB, 123..=127) => Some(Event::AllNotesOff),
            _ => None,
        }
    };
    let (mut mode, mut data, mut out) = (Mode::Idle, Vec::new(), Vec::new());
    for &b in bytes {
        if b >= 0xF8 {
            continue;
        }
        if b >= 0x80 {
            data.clear();
            mode = match b {
                0x80..=0xEF => Mode::Channel(b),
                0xF0 => Mode::SysEx,
                0xF2 => Mode::Common(2),
                0xF1 | 0xF3 => Mode::Common(1),
                _ => Mode::Common(0),
            };
            continue;
        }
        match mode {
            Mode::Channel(status) => {
                data.push(b);
                let needed = if matches!(status >> 4, 0xC | 0xD) {
                    1
                } else {
                    2
                };
                if data.len() == needed {
                    out.extend(decode(status, &data));
                    data.clear();
                }
            }
            Mode::Common(n) if n > 0 => mode = Mode::Common(n - 1),
            Mode::Idle | Mode::SysEx | Mode::Common(_) => {}
        }
    }
    out
}

#[test]
fn live_parser_agrees_with_a_reference_decoder_on_random_bytes() {
    // A fixed-seed LCG: the same million bytes every run, a third of them status bytes (so that
    // every kind of message, and every way of cutting one off, occurs often).
    let mut state: u64 = 0x2545_F491_4F6C_DD1D;
    let bytes: Vec<u8> = (0..1_000_000)
        .map(|_| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let r = (state >> 33) as u32;
            if r.is_multiple_of(3) {
                0x80 | (r >> 8) as u8
            } else {
                (r >> 8) as u8 & 0x7F
            }
        })
        .collect();
    let (ours, theirs) = (live(&bytes), reference_decoder(&bytes));
    let first_difference = ours.iter().zip(&theirs).position(|(a, b)| a != b);
    let count = |f: fn(&Event) -> bool| ours.iter().filter(|e| f(e)).count();
    println!(
        "1 000 000 random bytes: {} events from the live parser, {} from the reference decoder ({} note-ons, {} of them refined by a CC88 prefix, {} note-offs, {} pedals, {} all-notes/sound-off or resets); first difference at {first_difference:?}",
        ours.len(),
        theirs.len(),
        count(|e| matches!(e, Event::NoteOn { .. })),
        count(|e| matches!(e, Event::NoteOn { velocity, .. } if velocity.fract() != 0.0)),
        count(|e| matches!(e, Event::NoteOff { .. })),
        count(|e| matches!(e, Event::Pedal { .. })),
        count(|e| matches!(e, Event::AllNotesOff | Event::AllSoundOff | Event::ResetControllers))
    );
    assert!(ours.len() > 10_000, "too few events to say much");
    assert!(
        count(|e| matches!(e, Event::NoteOn { velocity, .. } if velocity.fract() != 0.0)) > 100,
        "too few prefixed notes to say much"
    );
    assert_eq!(first_difference, None);
    assert_eq!(ours.len(), theirs.len());
}

fn ev(delta: u32, kind: TrackEventKind<'static>) -> TrackEvent<'static> {
    TrackEvent {
        delta: u28::new(delta),
        kind,
    }
}

fn midi(message: MidiMessage) -> TrackEventKind<'static> {
    TrackEventKind::Midi {
        channel: u4::new(0),
        message,
    }
}

fn smf_bytes(smf: &Smf) -> Vec<u8> {
    let mut out = Vec::new();
    smf.write_std(&mut out).unwrap();
    out
}

#[test]
fn midi_file_follows_the_tempo_map_across_tracks() {
    let mut smf = Smf::new(Header::new(
        Format::Parallel,
        Timing::Metrical(u15::new(480)),
    ));
    // Track 0: tempo 120 bpm, then 240 bpm from beat 2.
    smf.tracks.push(vec![
        ev(
            0,
            TrackEventKind::Meta(MetaMessage::Tempo(u24::new(500_000))),
        ),
        ev(
            960,
            TrackEventKind::Meta(MetaMessage::Tempo(u24::new(250_000))),
        ),
        ev(0, TrackEventKind::Meta(MetaMessage::EndOfTrack)),
    ]);
    // Track 1: a note at beat 1, the soft pedal at beat 2, a note at beat 3, its release at beat 4.
    smf.tracks.push(vec![
        ev(
            480,
            midi(MidiMessage::NoteOn {
                key: u7::new(36),
                vel: u7::new(80),
            }),
        ),
        ev(
            480,
            midi(MidiMessage::Controller {
                controller: u7::new(67),
                value: u7::new(127),
            }),
        ),
        ev(
            480,
            midi(MidiMessage::NoteOn {
                key: u7::new(60),
                vel: u7::new(100),
            }),
        ),
        ev(
            480,
            midi(MidiMessage::NoteOff {
                key: u7::new(60),
                vel: u7::new(0),
            }),
        ),
        ev(0, TrackEventKind::Meta(MetaMessage::EndOfTrack)),
    ]);
    let events = parse(&smf_bytes(&smf), Path::new("tempo.mid")).unwrap();
    let times: Vec<f64> = events.iter().map(|e| e.time_s).collect();
    println!("tempo map: events at {times:?} s (expected 0.5, 1.0, 1.25, 1.5)");
    for (t, want) in times.iter().zip([0.5, 1.0, 1.25, 1.5]) {
        assert!((t - want).abs() < 1e-12);
    }
    assert_eq!(events[1].event, Event::pedal(Pedal::Soft, true));
    assert_eq!(
        events[3].event,
        Event::NoteOff {
            note: 60,
            velocity: 64.0
        }
    );
}

#[test]
fn midi_file_with_smpte_timing() {
    let mut smf = Smf::new(Header::new(
        Format::SingleTrack,
        Timing::Timecode(Fps::Fps25, 40),
    ));
    smf.tracks.push(vec![
        ev(
            500,
            midi(MidiMessage::NoteOn {
                key: u7::new(69),
                vel: u7::new(64),
            }),
        ),
        ev(0, TrackEventKind::Meta(MetaMessage::EndOfTrack)),
    ]);
    let events = parse(&smf_bytes(&smf), Path::new("smpte.mid")).unwrap();
    println!("SMPTE 25 fps × 40: tick 500 at {} s", events[0].time_s);
    assert!((events[0].time_s - 0.5).abs() < 1e-12);
}

/// A file's CC88 prefix refines the next note of its channel in its track: not another channel's,
/// not another track's.
#[test]
fn a_files_cc88_prefix_refines_the_next_note_of_its_channel_and_track() {
    let mut smf = Smf::new(Header::new(
        Format::Parallel,
        Timing::Metrical(u15::new(96)),
    ));
    let on = |channel: u8, key: u8, vel: u8| TrackEventKind::Midi {
        channel: u4::new(channel),
        message: MidiMessage::NoteOn {
            key: u7::new(key),
            vel: u7::new(vel),
        },
    };
    let prefix = TrackEventKind::Midi {
        channel: u4::new(0),
        message: MidiMessage::Controller {
            controller: u7::new(88),
            value: u7::new(96),
        },
    };
    let end = TrackEventKind::Meta(MetaMessage::EndOfTrack);
    smf.tracks.push(vec![
        ev(0, prefix),
        ev(10, on(1, 60, 100)),
        ev(10, on(0, 62, 100)),
        ev(10, on(0, 64, 100)),
        ev(0, end),
    ]);
    smf.tracks.push(vec![ev(5, prefix), ev(0, end)]);
    smf.tracks.push(vec![ev(40, on(0, 65, 100)), ev(0, end)]);
    let velocities: Vec<f64> = parse(&smf_bytes(&smf), Path::new("cc88.mid"))
        .unwrap()
        .iter()
        .filter_map(|e| match e.event {
            Event::NoteOn { velocity, .. } => Some(velocity),
            _ => None,
        })
        .collect();
    println!(
        "velocity 100 after CC88 96 on channel 1: channel 2's note, channel 1's, its next, another track's: {velocities:?}"
    );
    assert_eq!(velocities, [100.0, 100.75, 100.0, 100.0]);
}

#[test]
fn bad_midi_files_are_errors_that_name_the_file() {
    let mut smf = Smf::new(Header::new(
        Format::SingleTrack,
        Timing::Metrical(u15::new(96)),
    ));
    smf.tracks.push(vec![
        ev(
            0,
            midi(MidiMessage::NoteOn {
                key: u7::new(60),
                vel: u7::new(64),
            }),
        ),
        ev(
            96,
            midi(MidiMessage::NoteOff {
                key: u7::new(60),
                vel: u7::new(0),
            }),
        ),
        ev(0, TrackEventKind::Meta(MetaMessage::EndOfTrack)),
    ]);
    let good = smf_bytes(&smf);
    let mut zero_division = good.clone();
    zero_division[12] = 0;
    zero_division[13] = 0;
    // SMPTE division with the frame-rate byte 0x80: midly negates it as an i8 and overflows
    // (a panic found by fuzzing).
    let mut smpte_minus_128 = good.clone();
    smpte_minus_128[12] = 0x80;
    let cases: [(&str, Vec<u8>); 5] = [
        ("empty.mid", vec![]),
        ("truncated.mid", good[..good.len() - 5].to_vec()),
        ("not_midi.mid", b"RIFF\x00\x00\x00\x04WAVE".to_vec()),
        ("zero_division.mid", zero_division),
        ("smpte_minus_128.mid", smpte_minus_128),
    ];
    for (name, bytes) in cases {
        let e = parse(&bytes, Path::new(name)).unwrap_err().to_string();
        println!("{e}");
        assert!(e.starts_with(name));
    }
}

/// The live input's queue flooded while the audio thread is held up: 4 096 strikes of C4 fill it
/// (each played, a key struck again and again), then the releases of C4, E4 and G4 and the
/// sustain pedal down and up arrive, and one more strike. The releases wait in the backlog and
/// are queued, late, once the audio thread has emptied the queue; the strike is dropped and
/// counted. Every key then falls silent under its damper and its voice is retired: none is
/// stuck.
#[test]
fn a_flooded_queue_keeps_every_release() {
    use unacorda::audio::synth::{Scheduled, Synth, EVENT_QUEUE};
    use unacorda::config::scaling::{parse_key, Scaling};
    use unacorda::engine::exact::ExactPool;
    use unacorda::engine::Policy;
    use unacorda::play::Piano;
    let scaling = Scaling::resolve("concert").unwrap();
    let names = ["C4", "E4", "G4"];
    let keys: Vec<usize> = names.iter().map(|n| parse_key(n).unwrap()).collect();
    let piano = Piano::<ExactPool>::build(&scaling, &keys, 8).unwrap();
    let settings = scaling.output_settings();
    let (mut synth, mut handle) = Synth::new(piano, settings, EVENT_QUEUE).unwrap();
    let note = |k: usize| (k + 20) as u8;
    for &k in &keys {
        handle.schedule_live(Scheduled {
            frame: 0,
            event: Event::NoteOn {
                note: note(k),
                velocity: 90.0,
            },
        });
    }
    let mut out = vec![0f32; 512];
    for _ in 0..40 {
        synth.process(&mut out, 2);
    }
    // The audio thread held up: nothing is taken from the queue while it fills.
    let frame = synth.frame();
    let mut offered = 0;
    while handle.backlog.dropped_note_ons == 0 && handle.backlog.is_empty() {
        handle.schedule_live(Scheduled {
            frame,
            event: Event::NoteOn {
                note: note(keys[0]),
                velocity: 40.0,
            },
        });
        offered += 1;
    }
    let mut late = vec![];
    for &k in &keys {
        late.push(Event::NoteOff {
            note: note(k),
            velocity: 64.0,
        });
    }
    for down in [true, false] {
        late.push(Event::pedal(Pedal::Sustain, down));
    }
    late.push(Event::NoteOn {
        note: note(keys[1]),
        velocity: 100.0,
    });
    for event in late {
        handle.schedule_live(Scheduled { frame, event });
    }
    let waiting = handle.backlog.clone();
    println!(
        "queue of {EVENT_QUEUE}: {offered} strikes offered before it was full; waiting: {waiting:?}"
    );
    assert!(!waiting.is_empty(), "the releases should wait");
    // The audio thread runs again; the input's thread queues what waits as it has room.
    let mut sounding = usize::MAX;
    for block in 0..((4.0 * settings.rate_hz) as usize / 256) {
        synth.process(&mut out, 2);
        handle.flush_backlog(synth.frame());
        if block * 256 >= (3.0 * settings.rate_hz) as usize {
            let pool = &synth.piano().instrument;
            sounding = (0..pool.n_voices()).filter(|&v| pool.is_active(v)).count();
        }
    }
    let b = &handle.backlog;
    println!(
        "after 4 s: {} strikes dropped, {} releases queued late, {sounding} voices sounding",
        b.dropped_note_ons, b.delayed
    );
    assert!(b.is_empty());
    assert_eq!(
        b.dropped_note_ons, 2,
        "the strike that found the queue full and the one behind the releases"
    );
    assert_eq!(
        b.delayed, 4,
        "three note-offs and the pedal's last position"
    );
    assert_eq!(sounding, 0, "a key is stuck");
}

/// A plugin host's path (`audio::Aligned`): more events inside one 32-frame cell than the queue
/// holds — 4 096 strikes of C4, then C4 E4 G4's note-offs and one more strike. The releases wait
/// for the next cell; the keys fall silent; nothing waits and every voice is retired 3–4 s later.
#[test]
fn a_hosts_flood_inside_one_cell_keeps_every_release() {
    use std::sync::atomic::Ordering;
    use unacorda::audio::synth::{Synth, EVENT_QUEUE};
    use unacorda::audio::Aligned;
    use unacorda::config::scaling::{parse_key, Scaling};
    use unacorda::engine::exact::ExactPool;
    use unacorda::engine::Policy;
    use unacorda::play::Piano;
    let scaling = Scaling::resolve("concert").unwrap();
    let keys: Vec<usize> = ["C4", "E4", "G4"]
        .iter()
        .map(|n| parse_key(n).unwrap())
        .collect();
    let piano = Piano::<ExactPool>::build(&scaling, &keys, 8).unwrap();
    let settings = scaling.output_settings();
    let (synth, handle) = Synth::new(piano, settings, EVENT_QUEUE).unwrap();
    let stats = handle.stats.clone();
    let mut host = Aligned::new(synth, handle, 2);
    let note = |k: usize| (k + 20) as u8;
    let mut out = vec![0f32; 2 * 64];
    for &k in &keys {
        host.schedule(Event::NoteOn {
            note: note(k),
            velocity: 90.0,
        });
    }
    host.process(&mut out);
    let mut refused = 0;
    for _ in 0..EVENT_QUEUE {
        refused += usize::from(!host.schedule(Event::NoteOn {
            note: note(keys[0]),
            velocity: 40.0,
        }));
    }
    for &k in &keys {
        refused += usize::from(!host.schedule(Event::NoteOff {
            note: note(k),
            velocity: 64.0,
        }));
    }
    refused += usize::from(!host.schedule(Event::NoteOn {
        note: note(keys[1]),
        velocity: 100.0,
    }));
    let late = stats.late_events.load(Ordering::Relaxed);
    let mut sounding = usize::MAX;
    for block in 0..((4.0 * settings.rate_hz) as usize / 64) {
        host.process(&mut out);
        if block * 64 >= (3.0 * settings.rate_hz) as usize {
            let pool = &host.synth().piano().instrument;
            sounding = (0..pool.n_voices()).filter(|&v| pool.is_active(v)).count();
        }
    }
    println!(
        "{} events inside one cell into a queue of {EVENT_QUEUE}: {refused} not queued at once ({late} counted late), {sounding} voices sounding 3–4 s later",
        EVENT_QUEUE + keys.len() + 1
    );
    assert_eq!(refused, late as usize);
    assert!(refused > keys.len(), "the queue should have been full");
    assert!(host.is_silent(), "something still waits or sounds");
    assert_eq!(sounding, 0, "a key is stuck");
}
