//! Standard MIDI files (midly): every track merged into one list of piano events in seconds,
//! through the file's tempo map (metrical timing) or its SMPTE rate (timecode timing).

use super::{Decoder, Event};
use midly::num::{u15, u24, u28, u4};
use midly::{Format, Header, MetaMessage, MidiMessage, Smf, Timing, TrackEvent, TrackEventKind};
use std::path::{Path, PathBuf};

/// A piano event at a time (s) from the start of the file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedEvent {
    pub time_s: f64,
    pub event: Event,
}

/// A MIDI file that cannot be played.
#[derive(Debug, thiserror::Error)]
pub enum MidiFileError {
    #[error("{path}: cannot read MIDI file: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}: not a valid standard MIDI file: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Content { path: PathBuf, message: String },
}

/// Default tempo of a metrical file before any tempo event: 120 beats per minute.
const DEFAULT_TEMPO_US_PER_BEAT: f64 = 500_000.0;

/// midly reads what it can of a damaged file; a file whose chunks run past its end is refused
/// instead, so that a truncated download is an error and not a silently shortened piece.
fn check_chunks(bytes: &[u8]) -> Result<(), String> {
    let mut pos = 0;
    let mut index = 0;
    while pos + 8 <= bytes.len() {
        let id = String::from_utf8_lossy(&bytes[pos..pos + 4]).into_owned();
        let len = u32::from_be_bytes([
            bytes[pos + 4],
            bytes[pos + 5],
            bytes[pos + 6],
            bytes[pos + 7],
        ]) as usize;
        let remaining = bytes.len() - pos - 8;
        if len > remaining {
            return Err(format!(
                "chunk {index} (`{id}`) at byte {pos} declares {len} bytes but only {remaining} remain (truncated file?)"
            ));
        }
        pos += 8 + len;
        index += 1;
    }
    // SMPTE division: the high byte is minus the frame rate. midly negates it as an i8, which
    // overflows for 0x80 (found by fuzzing); only the four standard rates are meaningful anyway.
    if bytes.len() >= 14 && &bytes[..4] == b"MThd" && bytes[12] & 0x80 != 0 {
        let fps = -i16::from(bytes[12] as i8);
        if ![24, 25, 29, 30].contains(&fps) {
            return Err(format!(
                "header: SMPTE timing at {fps} frames per second (expected 24, 25, 29 or 30)"
            ));
        }
    }
    Ok(())
}

/// Read a MIDI file from disk.
pub fn read_file(path: &Path) -> Result<Vec<TimedEvent>, MidiFileError> {
    let bytes = std::fs::read(path).map_err(|error| MidiFileError::Io {
        path: path.to_owned(),
        error,
    })?;
    parse(&bytes, path)
}

/// Parse MIDI file bytes; `path` names the source in errors. Events come out sorted by time, ties
/// in track order.
pub fn parse(bytes: &[u8], path: &Path) -> Result<Vec<TimedEvent>, MidiFileError> {
    check_chunks(bytes).map_err(|message| MidiFileError::Parse {
        path: path.to_owned(),
        message,
    })?;
    let smf = Smf::parse(bytes).map_err(|e| MidiFileError::Parse {
        path: path.to_owned(),
        message: e.to_string(),
    })?;
    let content = |message: String| MidiFileError::Content {
        path: path.to_owned(),
        message,
    };
    // (absolute tick, track, order in track, what)
    enum What {
        Tempo(f64),
        Piano(Event),
    }
    let mut items: Vec<(u64, usize, usize, What)> = Vec::new();
    let mut track_start = 0u64;
    for (t, track) in smf.tracks.iter().enumerate() {
        let mut tick = track_start;
        // A CC88 prefix refines the next note of its channel in its own track.
        let mut decoder = Decoder::default();
        for (k, ev) in track.iter().enumerate() {
            tick += ev.delta.as_int() as u64;
            match ev.kind {
                TrackEventKind::Meta(MetaMessage::Tempo(us)) => {
                    if us.as_int() == 0 {
                        return Err(content(format!(
                            "track {t}, event {k}: tempo of 0 µs per beat"
                        )));
                    }
                    items.push((tick, t, k, What::Tempo(us.as_int() as f64)));
                }
                TrackEventKind::Midi { channel, message } => {
                    let (kind, d1, d2) = match message {
                        MidiMessage::NoteOff { key, vel } => (0x80, key.as_int(), vel.as_int()),
                        MidiMessage::NoteOn { key, vel } => (0x90, key.as_int(), vel.as_int()),
                        MidiMessage::Controller { controller, value } => {
                            (0xB0, controller.as_int(), value.as_int())
                        }
                        _ => continue,
                    };
                    if let Some(e) = decoder.decode(kind | channel.as_int(), d1, d2) {
                        items.push((tick, t, k, What::Piano(e)));
                    }
                }
                _ => {}
            }
        }
        // A sequential file (format 2) plays its tracks one after another.
        if smf.header.format == Format::Sequential {
            track_start = tick;
        }
    }
    items.sort_by_key(|(tick, t, k, _)| (*tick, *t, *k));
    let mut out = Vec::new();
    match smf.header.timing {
        Timing::Metrical(tpb) => {
            let tpb = tpb.as_int() as f64;
            if tpb == 0.0 {
                return Err(content("division of 0 ticks per beat".into()));
            }
            let (mut us_per_beat, mut last_tick, mut time_s) =
                (DEFAULT_TEMPO_US_PER_BEAT, 0u64, 0.0);
            for (tick, _, _, what) in items {
                time_s += (tick - last_tick) as f64 * us_per_beat / tpb * 1e-6;
                last_tick = tick;
                match what {
                    What::Tempo(us) => us_per_beat = us,
                    What::Piano(event) => out.push(TimedEvent { time_s, event }),
                }
            }
        }
        Timing::Timecode(fps, subframes) => {
            if subframes == 0 {
                return Err(content("SMPTE division with 0 ticks per frame".into()));
            }
            let s_per_tick = 1.0 / (fps.as_f32() as f64 * subframes as f64);
            for (tick, _, _, what) in items {
                if let What::Piano(event) = what {
                    out.push(TimedEvent {
                        time_s: tick as f64 * s_per_tick,
                        event,
                    });
                }
            }
        }
    }
    Ok(out)
}

/// A format-0 standard MIDI file, as bytes, of `messages` on channel 1 at their ticks
/// (`ticks_per_beat` to the beat; sorted here, those at one tick kept in order), with a tempo
/// (µs per beat) at its start if given, else the default 120 beats per minute: what [`parse`]
/// reads. The generated files of `examples/` and the tests' performances are written by it.
pub fn single_track_bytes(
    ticks_per_beat: u16,
    tempo_us_per_beat: Option<u32>,
    mut messages: Vec<(u32, MidiMessage)>,
) -> std::io::Result<Vec<u8>> {
    messages.sort_by_key(|&(tick, _)| tick);
    let tempo = tempo_us_per_beat.map(|us| TrackEvent {
        delta: u28::new(0),
        kind: TrackEventKind::Meta(MetaMessage::Tempo(u24::new(us))),
    });
    let mut last = 0;
    let notes = messages.into_iter().map(|(tick, message)| {
        let delta = u28::new(tick - last);
        last = tick;
        TrackEvent {
            delta,
            kind: TrackEventKind::Midi {
                channel: u4::new(0),
                message,
            },
        }
    });
    let end = TrackEvent {
        delta: u28::new(0),
        kind: TrackEventKind::Meta(MetaMessage::EndOfTrack),
    };
    let mut smf = Smf::new(Header::new(
        Format::SingleTrack,
        Timing::Metrical(u15::new(ticks_per_beat)),
    ));
    smf.tracks
        .push(tempo.into_iter().chain(notes).chain([end]).collect());
    let mut bytes = Vec::new();
    smf.write_std(&mut bytes)?;
    Ok(bytes)
}
