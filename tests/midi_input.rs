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
                velocity: 100
            },
            Event::NoteOn {
                note: 64,
                velocity: 90
            },
            Event::NoteOff { note: 60 }
        ]
    );
    // Real-time bytes (clock, active sensing) inside a message change nothing.
    assert_eq!(
        live(&[0x91, 0xF8, 48, 0xFE, 70]),
        [Event::NoteOn {
            note: 48,
            velocity: 70
        }]
    );
    // SysEx is skipped, and clears running status: the stray data after it is dropped.
    assert_eq!(
        live(&[0x90, 60, 1, 0xF0, 0x7E, 60, 100, 0xF7, 61, 100]),
        [Event::NoteOn {
            note: 60,
            velocity: 1
        }]
    );
    // System common (song position, 2 data bytes) is skipped with its data.
    assert_eq!(
        live(&[0xF2, 60, 100, 0xB0, 67, 127]),
        [Event::Pedal {
            pedal: Pedal::Soft,
            down: true
        }]
    );
    // Pedals and channel-mode messages on any channel; pitch bend and program change ignored.
    assert_eq!(
        live(&[0xBF, 64, 63, 0xB3, 66, 64, 0xE0, 0, 64, 0xC0, 5, 0xB0, 120, 0, 121, 0, 123, 0]),
        [
            Event::Pedal {
                pedal: Pedal::Sustain,
                down: false
            },
            Event::Pedal {
                pedal: Pedal::Sostenuto,
                down: true
            },
            Event::AllSoundOff,
            Event::ResetControllers,
            Event::AllNotesOff
        ]
    );
    // Data bytes with no status at all are dropped.
    assert_eq!(live(&[60, 100, 0x80, 60, 0]), [Event::NoteOff { note: 60 }]);
    println!(
        "live parser: running status, interleaved real-time, SysEx, system common, stray data: ok"
    );
}

#[test]
fn live_parser_survives_random_bytes() {
    // A fixed-seed LCG: the same million bytes every run.
    let mut state: u64 = 0x2545_F491_4F6C_DD1D;
    let mut p = LiveParser::new();
    let mut events = 0;
    for _ in 0..1_000_000 {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        if let Some(e) = p.push((state >> 56) as u8) {
            events += 1;
            if let Event::NoteOn { note, velocity } = e {
                assert!(note < 128 && (1..128).contains(&velocity));
            }
        }
    }
    println!("1 000 000 random bytes → {events} events, no panic");
    assert!(events > 0);
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
    assert_eq!(
        events[1].event,
        Event::Pedal {
            pedal: Pedal::Soft,
            down: true
        }
    );
    assert_eq!(events[3].event, Event::NoteOff { note: 60 });
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
