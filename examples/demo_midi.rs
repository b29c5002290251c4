//! Writes `assets/midi/demo.mid`, the demo performance: a phrase in C major played twice on the
//! sustain pedal, the second time with the soft pedal (CC67) down, so that the una-corda colour
//! can be heard against the normal one. Regenerate with `cargo run --example demo_midi`.

use midly::num::u7;
use midly::MidiMessage;

const TICKS_PER_BEAT: u16 = 480;

fn main() -> std::io::Result<()> {
    // (beat, note, velocity, length in beats)
    let phrase: [(f64, u8, u8, f64); 10] = [
        (0.0, 36, 70, 3.5),
        (0.0, 48, 60, 3.5),
        (0.5, 64, 72, 1.0),
        (1.0, 67, 76, 1.0),
        (1.5, 72, 82, 2.0),
        (2.0, 76, 70, 1.5),
        (4.0, 41, 70, 3.5),
        (4.5, 69, 74, 1.0),
        (5.0, 72, 78, 1.0),
        (5.5, 77, 84, 2.0),
    ];
    let mut timed: Vec<(u32, MidiMessage)> = Vec::new();
    let tick = |beat: f64| (beat * f64::from(TICKS_PER_BEAT)).round() as u32;
    let cc = |controller: u8, value: u8| MidiMessage::Controller {
        controller: u7::new(controller),
        value: u7::new(value),
    };
    for (pass, soft) in [(0.0, false), (8.0, true)] {
        if soft {
            timed.push((tick(pass - 0.25), cc(67, 127)));
        }
        timed.push((tick(pass + 0.05), cc(64, 127)));
        timed.push((tick(pass + 3.9), cc(64, 0)));
        timed.push((tick(pass + 4.05), cc(64, 127)));
        timed.push((tick(pass + 7.5), cc(64, 0)));
        for &(beat, note, vel, len) in &phrase {
            timed.push((
                tick(pass + beat),
                MidiMessage::NoteOn {
                    key: u7::new(note),
                    vel: u7::new(vel),
                },
            ));
            timed.push((
                tick(pass + beat + len),
                MidiMessage::NoteOff {
                    key: u7::new(note),
                    vel: u7::new(0),
                },
            ));
        }
    }
    let bytes = unacorda::midi::file::single_track_bytes(TICKS_PER_BEAT, None, timed)?;
    std::fs::write("assets/midi/demo.mid", bytes)?;
    eprintln!("wrote assets/midi/demo.mid");
    Ok(())
}
