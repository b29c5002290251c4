//! MIDI input: the byte-stream parser that live input (midir) feeds, the standard-MIDI-file reader,
//! and their common mapping to piano events (DESIGN.md §3): note on → hammer strike with a speed
//! from the velocity curve, note off (or velocity 0) → damper, CC64 sustain, CC66 sostenuto, CC67
//! soft pedal (≥ 64: una corda), CC120 all sound off, CC121 reset controllers, CC123–127 all notes
//! off; pitch bend and other messages are ignored.

pub mod file;
pub mod live;

/// The velocity curve's anchors, (MIDI velocity, hammer speed m/s): pianissimo, mezzoforte and
/// fortissimo. Hammer speeds of 1–6 m/s span the normal dynamic range (Russell & Rossing 1998;
/// docs/realism-sources.md §5); mezzoforte and fortissimo are where the exponential 0.5–6 m/s curve
/// put them (the realism figures at velocity 80). Pianissimo is set so that C4 grows 20–25 dB from
/// velocity 30 to 127 (issue 17; the recorded grand as its sampler plays it: 24.7 dB, Goncalves
/// 2014: 23 dB for one key), where the exponential curve's 0.89 m/s gave 18.2 (docs/realism.md,
/// "Dynamics").
pub const VELOCITY_ANCHORS_M_S: [(u8, f64); 3] = [(30, 0.70), (80, 2.37), (127, 6.0)];

/// MIDI velocity 1–127 → hammer speed (m/s): the logarithm of the speed is the parabola through
/// [`VELOCITY_ANCHORS_M_S`] (0.31 m/s at velocity 1, rising at every step), so that equal velocity
/// steps are nearly equal ratios of speed, a little larger at the soft end; `None` for 0, which MIDI
/// defines as a note-off, or for values above 127.
pub fn hammer_speed_m_s(velocity: u8) -> Option<f64> {
    if !(1..=127).contains(&velocity) {
        return None;
    }
    let v = velocity as f64;
    let ln_speed: f64 = VELOCITY_ANCHORS_M_S
        .iter()
        .map(|&(vi, si)| {
            let vi = vi as f64;
            let weight: f64 = VELOCITY_ANCHORS_M_S
                .iter()
                .filter(|&&(vj, _)| vj as f64 != vi)
                .map(|&(vj, _)| (v - vj as f64) / (vi - vj as f64))
                .product();
            weight * si.ln()
        })
        .sum();
    Some(ln_speed.exp())
}

/// The velocity curve's exponents a front end may set: MIDI velocity `v` becomes
/// `127 (v/127)^exponent` before the hammer's speed is found from it ([`curved_velocity`]).
pub const VELOCITY_CURVE: std::ops::RangeInclusive<f64> = 0.25..=4.0;

/// MIDI velocity `v` (1–127) through the velocity curve `exponent` ([`VELOCITY_CURVE`]): above 1 a
/// harder touch is needed for the same loudness, below 1 a lighter one; 1 leaves it as it is.
pub fn curved_velocity(v: u8, exponent: f64) -> u8 {
    if exponent == 1.0 {
        return v;
    }
    let x = f64::from(v.clamp(1, 127)) / 127.0;
    (127.0 * x.powf(exponent)).round().clamp(1.0, 127.0) as u8
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

impl Event {
    /// The event with a note-on's velocity through the velocity curve `exponent`
    /// ([`curved_velocity`]); any other event as it is.
    pub fn with_velocity_curve(self, exponent: f64) -> Event {
        match self {
            Event::NoteOn { note, velocity } => Event::NoteOn {
                note,
                velocity: curved_velocity(velocity, exponent),
            },
            other => other,
        }
    }
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
    fn the_velocity_curve_is_monotonic_and_identity_at_one() {
        for e in [0.25, 0.5, 1.0, 2.0, 4.0] {
            let v: Vec<u8> = (1..=127).map(|v| curved_velocity(v, e)).collect();
            assert!(v.windows(2).all(|w| w[1] >= w[0]), "exponent {e}");
            assert_eq!((v[0].max(1), v[126]), (v[0], 127));
        }
        assert!((1..=127).all(|v| curved_velocity(v, 1.0) == v));
        assert!(curved_velocity(64, 2.0) < 64 && curved_velocity(64, 0.5) > 64);
    }

    #[test]
    fn curve_passes_its_anchors_and_rises_at_every_step() {
        assert_eq!(hammer_speed_m_s(0), None);
        assert_eq!(hammer_speed_m_s(128), None);
        for (velocity, speed_m_s) in VELOCITY_ANCHORS_M_S {
            assert!((hammer_speed_m_s(velocity).unwrap() / speed_m_s - 1.0).abs() < 1e-12);
        }
        let v: Vec<f64> = (1..=127).map(|k| hammer_speed_m_s(k).unwrap()).collect();
        println!("velocity 1 -> {:.3} m/s, 127 -> {:.3} m/s", v[0], v[126]);
        assert!((0.3..0.32).contains(&v[0]), "velocity 1: {} m/s", v[0]);
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
