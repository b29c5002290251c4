//! Writes `assets/midi/chorale.mid`, the offline benchmark of issue 16: a four-part chorale in C
//! major (sixteen chords, one a second, the last held two), each chord's bass doubled one and two
//! octaves down and its soprano one and two octaves up, so that every chord sounds up to eight
//! keys from the lowest octave to the top of the keyboard; the sustain pedal changed legato at
//! every chord (lifted just after it sounds, pressed again at once), so that two chords ring at
//! each change. Regenerate with `cargo run --example chorale_midi`.

use midly::num::u7;
use midly::MidiMessage;

const TICKS_PER_BEAT: u16 = 480;

/// Bass, tenor, alto, soprano (MIDI notes) of each chord: I IV V I vi ii V I iii vi IV V7 I IV V I.
const CHORDS: [[u8; 4]; 16] = [
    [48, 55, 64, 72],
    [53, 57, 65, 72],
    [55, 59, 62, 71],
    [48, 55, 64, 72],
    [45, 57, 64, 72],
    [50, 57, 65, 74],
    [43, 55, 62, 71],
    [48, 55, 64, 72],
    [52, 55, 64, 71],
    [45, 57, 64, 72],
    [41, 57, 65, 72],
    [43, 59, 65, 74],
    [48, 55, 64, 72],
    [53, 57, 65, 77],
    [55, 59, 62, 74],
    [36, 55, 64, 72],
];

fn main() -> std::io::Result<()> {
    let tick = |beat: f64| (beat * f64::from(TICKS_PER_BEAT)).round() as u32;
    let cc = |value: u8| MidiMessage::Controller {
        controller: u7::new(64),
        value: u7::new(value),
    };
    let mut timed: Vec<(u32, MidiMessage)> = vec![(0, cc(127))];
    for (i, chord) in CHORDS.iter().enumerate() {
        let beat = i as f64;
        let length = if i + 1 == CHORDS.len() { 2.0 } else { 1.0 };
        // A phrase rises to its middle and falls: velocity 70 to 94.
        let velocity = 70 + (12.0 * (std::f64::consts::PI * (i % 8) as f64 / 7.0).sin()) as u8 * 2;
        let [bass, tenor, alto, soprano] = *chord;
        let keys = [
            bass.checked_sub(24),
            bass.checked_sub(12),
            Some(bass),
            Some(tenor),
        ]
        .into_iter()
        .chain([
            Some(alto),
            Some(soprano),
            Some(soprano + 12),
            Some(soprano + 24),
        ])
        .flatten()
        .filter(|k| (21..=108).contains(k));
        for key in keys {
            let on = MidiMessage::NoteOn {
                key: u7::new(key),
                vel: u7::new(velocity),
            };
            let off = MidiMessage::NoteOff {
                key: u7::new(key),
                vel: u7::new(0),
            };
            timed.push((tick(beat), on));
            timed.push((tick(beat + length) - 1, off));
        }
        if i > 0 {
            timed.push((tick(beat + 0.05), cc(0)));
            timed.push((tick(beat + 0.15), cc(127)));
        }
    }
    timed.push((tick(CHORDS.len() as f64 + 1.5), cc(0)));
    let bytes = unacorda::midi::file::single_track_bytes(TICKS_PER_BEAT, Some(1_000_000), timed)?;
    std::fs::write("assets/midi/chorale.mid", bytes)?;
    eprintln!("wrote assets/midi/chorale.mid");
    Ok(())
}
