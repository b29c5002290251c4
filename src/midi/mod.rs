//! MIDI input: the byte-stream parser that live input (midir) feeds, the standard-MIDI-file reader,
//! and their common mapping to piano events (DESIGN.md §3): note on → hammer strike with a speed
//! from the velocity curve, note off (or velocity 0) → damper, CC64 sustain, CC66 sostenuto, CC67
//! soft pedal (≥ 64: una corda), CC120 all sound off, CC121 reset controllers, CC123–127 all notes
//! off; pitch bend and other messages are ignored.

pub mod file;
pub mod live;

/// Hammer speed at the lowest MIDI velocity (m/s): a pianissimo touch.
pub const MIN_HAMMER_SPEED_M_S: f64 = 0.5;
/// Hammer speed at velocity 127 (m/s): fortissimo.
pub const MAX_HAMMER_SPEED_M_S: f64 = 6.0;

/// MIDI velocity 1–127 → hammer speed (m/s), exponential between 0.5 and 6 m/s, so that equal
/// velocity steps are equal ratios of speed (and roughly equal steps in level); `None` for 0,
/// which MIDI defines as a note-off, or for values above 127.
pub fn hammer_speed_m_s(velocity: u8) -> Option<f64> {
    if !(1..=127).contains(&velocity) {
        return None;
    }
    let x = (velocity - 1) as f64 / 126.0;
    Some(MIN_HAMMER_SPEED_M_S * (MAX_HAMMER_SPEED_M_S / MIN_HAMMER_SPEED_M_S).powf(x))
}

/// Piano key 1 (A0) to 88 (C8) of a MIDI note number, `None` off the keyboard.
pub fn piano_key(note: u8) -> Option<usize> {
    (21..=108).contains(&note).then(|| (note - 20) as usize)
}

/// The three pedals.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pedal {
    /// CC64: dampers off every string.
    Sustain,
    /// CC66: dampers held off the keys down when it is pressed.
    Sostenuto,
    /// CC67: una corda.
    Soft,
}

/// A piano event, whatever channel it came on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    NoteOn { note: u8, velocity: u8 },
    NoteOff { note: u8 },
    Pedal { pedal: Pedal, down: bool },
    AllNotesOff,
    AllSoundOff,
    ResetControllers,
}

/// The piano event of a channel message (`status` with its channel nibble), if it has one.
pub fn map_channel_message(status: u8, data1: u8, data2: u8) -> Option<Event> {
    match status & 0xF0 {
        0x80 => Some(Event::NoteOff { note: data1 }),
        0x90 if data2 == 0 => Some(Event::NoteOff { note: data1 }),
        0x90 => Some(Event::NoteOn {
            note: data1,
            velocity: data2,
        }),
        0xB0 => {
            let down = data2 >= 64;
            match data1 {
                64 => Some(Event::Pedal {
                    pedal: Pedal::Sustain,
                    down,
                }),
                66 => Some(Event::Pedal {
                    pedal: Pedal::Sostenuto,
                    down,
                }),
                67 => Some(Event::Pedal {
                    pedal: Pedal::Soft,
                    down,
                }),
                120 => Some(Event::AllSoundOff),
                121 => Some(Event::ResetControllers),
                // 123 all notes off; 124–127 (omni/mono/poly mode changes) imply it.
                123..=127 => Some(Event::AllNotesOff),
                _ => None,
            }
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curve_spans_the_documented_range_monotonically() {
        assert_eq!(hammer_speed_m_s(0), None);
        assert_eq!(hammer_speed_m_s(128), None);
        assert!((hammer_speed_m_s(1).unwrap() - 0.5).abs() < 1e-12);
        assert!((hammer_speed_m_s(127).unwrap() - 6.0).abs() < 1e-12);
        let v: Vec<f64> = (1..=127).map(|k| hammer_speed_m_s(k).unwrap()).collect();
        assert!(v.windows(2).all(|w| w[1] > w[0]));
    }

    #[test]
    fn keyboard_spans_a0_to_c8() {
        assert_eq!(
            (
                piano_key(20),
                piano_key(21),
                piano_key(36),
                piano_key(108),
                piano_key(109)
            ),
            (None, Some(1), Some(16), Some(88), None)
        );
    }
}
