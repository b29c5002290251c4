//! MIDI input: the byte-stream parser that live input (midir) feeds, the standard-MIDI-file reader,
//! and their common mapping to piano events ([`Decoder`]): note on → hammer strike
//! with a speed from the velocity curve, refined by a CC88 high-resolution velocity prefix; note
//! off (or velocity 0) → damper; CC64 sustain, CC66 sostenuto, CC67 soft pedal (its depth shifts the action: 127 the una corda),
//! CC120 all sound off, CC121 reset controllers, CC123–127 all notes off; pitch bend and other
//! messages are ignored.

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
/// steps are nearly equal ratios of speed, a little larger at the soft end. A velocity between two
/// of MIDI's steps (a CC88 prefix's, a plugin host's) lies on the same parabola. `None` under 1
/// (MIDI's 0 is a note-off), above 127 or not a number.
pub fn hammer_speed_m_s(v: f64) -> Option<f64> {
    if !(1.0..=127.0).contains(&v) {
        return None;
    }
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

/// MIDI velocity `v` (1–127, with any fraction) through the velocity curve `exponent`
/// ([`VELOCITY_CURVE`]): above 1 a harder touch is needed for the same loudness, below 1 a lighter
/// one; 1 leaves it as it is. The result is not rounded to MIDI's steps.
pub fn curved_velocity(v: f64, exponent: f64) -> f64 {
    if exponent == 1.0 {
        return v;
    }
    let x = v.clamp(1.0, 127.0) / 127.0;
    (127.0 * x.powf(exponent)).clamp(1.0, 127.0)
}

/// The velocity of a note-on or note-off from its MIDI byte and the low 7 bits of a CC88 prefix
/// (0 without one): the 14-bit velocity `msb << 7 | lsb` on MIDI's 1–127 scale, `msb + lsb/128`,
/// at most 127 (the fastest blow a key is built for).
pub fn fine_velocity(msb: u8, lsb: u8) -> f64 {
    (f64::from(msb) + f64::from(lsb & 0x7F) / 128.0).min(127.0)
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
    /// CC67: the action shifted sideways by the pedal's depth (the una corda fully down).
    Soft,
}

/// The release velocity of a note-off that has none (a note-on of velocity 0, a MIDI note-off
/// of velocity 0, a plugin host's note-off without one): MIDI's default.
pub const DEFAULT_RELEASE_VELOCITY: f64 = 64.0;

/// A pedal's depth from which it counts as down, of 0 (up) to 1 (fully down): MIDI's convention,
/// a controller value of 64 or more (64/127 = 0.504, 63/127 = 0.496).
pub const PEDAL_DOWN_AT: f64 = 0.5;

/// A piano event, whatever channel it came on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// A key struck: `velocity` on MIDI's scale, 1–127 with a fraction where the source has one
    /// (a CC88 prefix, a plugin host's floating-point velocity).
    NoteOn {
        note: u8,
        velocity: f64,
    },
    /// A key let go: `velocity` its release velocity on MIDI's scale, 1–127 (how fast the key
    /// rose), [`DEFAULT_RELEASE_VELOCITY`] where the source has none.
    NoteOff {
        note: u8,
        velocity: f64,
    },
    /// A pedal moved to `depth`, 0 (up) to 1 (fully down): a controller's value / 127, or a plugin
    /// parameter's value.
    Pedal {
        pedal: Pedal,
        depth: f64,
    },
    AllNotesOff,
    AllSoundOff,
    ResetControllers,
}

impl Event {
    /// A pedal fully down (`down`) or up.
    pub fn pedal(pedal: Pedal, down: bool) -> Event {
        Event::Pedal {
            pedal,
            depth: if down { 1.0 } else { 0.0 },
        }
    }

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

/// MIDI's high-resolution velocity prefix (CA-031): the low 7 bits of the velocity of the
/// channel's next note-on or note-off.
pub const VELOCITY_PREFIX_CC: u8 = 88;

/// Channel messages to piano events, with what must be remembered between them: each channel's
/// CC88 prefix, kept until that channel's next note-on or note-off takes it (MIDI CA-031; a
/// controller reset clears it). One per stream of messages (a device, a file's track, a plugin
/// instance); touched by the thread that reads that stream. Never allocates.
#[derive(Debug, Clone, Default)]
pub struct Decoder {
    velocity_lsb: [u8; 16],
}

impl Decoder {
    /// The piano event of a channel message (`status` with its channel nibble), if it has one.
    pub fn decode(&mut self, status: u8, data1: u8, data2: u8) -> Option<Event> {
        let channel = usize::from(status & 0x0F);
        let lsb = &mut self.velocity_lsb[channel];
        match status & 0xF0 {
            // A release velocity of 0 is a keyboard that sends none (MIDI asks for 64 then).
            0x80 if data2 > 0 => Some(Event::NoteOff {
                note: data1,
                velocity: fine_velocity(data2, std::mem::take(lsb)),
            }),
            0x80 | 0x90 if data2 == 0 => {
                *lsb = 0;
                Some(Event::NoteOff {
                    note: data1,
                    velocity: DEFAULT_RELEASE_VELOCITY,
                })
            }
            0x90 => Some(Event::NoteOn {
                note: data1,
                velocity: fine_velocity(data2, std::mem::take(lsb)),
            }),
            0xB0 => {
                let depth = f64::from(data2.min(127)) / 127.0;
                match data1 {
                    VELOCITY_PREFIX_CC => {
                        *lsb = data2 & 0x7F;
                        None
                    }
                    64 => Some(Event::Pedal {
                        pedal: Pedal::Sustain,
                        depth,
                    }),
                    66 => Some(Event::Pedal {
                        pedal: Pedal::Sostenuto,
                        depth,
                    }),
                    67 => Some(Event::Pedal {
                        pedal: Pedal::Soft,
                        depth,
                    }),
                    120 => Some(Event::AllSoundOff),
                    121 => {
                        *lsb = 0;
                        Some(Event::ResetControllers)
                    }
                    // 123 all notes off; 124–127 (omni/mono/poly mode changes) imply it.
                    123..=127 => Some(Event::AllNotesOff),
                    _ => None,
                }
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_velocity_curve_is_monotonic_and_identity_at_one() {
        for e in [0.25, 0.5, 1.0, 2.0, 4.0] {
            let v: Vec<f64> = (128..=127 * 128)
                .map(|v| curved_velocity(f64::from(v) / 128.0, e))
                .collect();
            // Rising at every 1/128 of a step, but where the curve holds the softest at 1.
            let rising = |w: &[f64]| w[1] > w[0] || (w[0] == 1.0 && w[1] == 1.0);
            assert!(v.windows(2).all(rising), "exponent {e}");
            assert!(v[0] >= 1.0 && v[v.len() - 1] == 127.0, "exponent {e}");
        }
        assert!((1..=127).all(|v| curved_velocity(f64::from(v), 1.0) == f64::from(v)));
        assert!(curved_velocity(64.0, 2.0) < 64.0 && curved_velocity(64.0, 0.5) > 64.0);
    }

    #[test]
    fn curve_passes_its_anchors_and_rises_at_every_step() {
        assert_eq!(hammer_speed_m_s(0.0), None);
        assert_eq!(hammer_speed_m_s(127.5), None);
        assert_eq!(hammer_speed_m_s(f64::NAN), None);
        for (velocity, speed_m_s) in VELOCITY_ANCHORS_M_S {
            let speed = hammer_speed_m_s(f64::from(velocity)).unwrap();
            assert!((speed / speed_m_s - 1.0).abs() < 1e-12);
        }
        let v: Vec<f64> = (1..=127)
            .map(|k| hammer_speed_m_s(f64::from(k)).unwrap())
            .collect();
        println!("velocity 1 -> {:.3} m/s, 127 -> {:.3} m/s", v[0], v[126]);
        assert!((0.3..0.32).contains(&v[0]), "velocity 1: {} m/s", v[0]);
        assert!(v.windows(2).all(|w| w[1] > w[0]));
    }

    /// CC88 refines its channel's next note-on to 1/128 of a velocity step (MIDI CA-031), and only
    /// that one: another channel's note-on leaves it, a note-off or a controller reset takes it.
    #[test]
    fn a_cc88_prefix_refines_the_next_note_on_of_its_channel() {
        let mut d = Decoder::default();
        let on = |velocity: f64| Some(Event::NoteOn { note: 60, velocity });
        assert_eq!(d.decode(0xB0, VELOCITY_PREFIX_CC, 64), None);
        assert_eq!(d.decode(0x91, 60, 100), on(100.0));
        assert_eq!(d.decode(0x90, 60, 100), on(100.5));
        assert_eq!(d.decode(0x90, 60, 100), on(100.0));
        d.decode(0xB0, VELOCITY_PREFIX_CC, 127);
        assert_eq!(d.decode(0x90, 60, 127), on(127.0));
        for reset in [(0x80, 60, 0), (0x90, 60, 0), (0xB0, 121, 0)] {
            d.decode(0xB0, VELOCITY_PREFIX_CC, 32);
            d.decode(reset.0, reset.1, reset.2);
            assert_eq!(d.decode(0x90, 60, 90), on(90.0), "after {reset:?}");
        }
        let speed = |v: f64| hammer_speed_m_s(v).unwrap();
        println!(
            "velocity 100 -> {:.4} m/s, 100 + 64/128 -> {:.4}, 101 -> {:.4}",
            speed(100.0),
            speed(100.5),
            speed(101.0)
        );
        assert!(speed(100.0) < speed(100.5) && speed(100.5) < speed(101.0));
    }

    /// A note-off's release velocity is its data byte, refined by a CC88 prefix as a note-on's;
    /// a note-off of velocity 0 and a note-on of velocity 0 have none: MIDI's default, 64.
    #[test]
    fn a_note_off_carries_its_release_velocity() {
        let mut d = Decoder::default();
        let off = |velocity: f64| Some(Event::NoteOff { note: 60, velocity });
        assert_eq!(d.decode(0x80, 60, 30), off(30.0));
        d.decode(0xB2, VELOCITY_PREFIX_CC, 64);
        assert_eq!(d.decode(0x82, 60, 30), off(30.5));
        assert_eq!(d.decode(0x82, 60, 30), off(30.0));
        assert_eq!(d.decode(0x80, 60, 0), off(DEFAULT_RELEASE_VELOCITY));
        assert_eq!(d.decode(0x90, 60, 0), off(DEFAULT_RELEASE_VELOCITY));
        assert_eq!(d.decode(0x80, 60, 127), off(127.0));
    }

    /// A pedal controller's value is its depth, value / 127, and it is down from 64 up, as MIDI
    /// has it, at every value of every pedal.
    #[test]
    fn a_pedals_depth_is_its_value_and_down_from_64() {
        let mut d = Decoder::default();
        for (cc, pedal) in [
            (64, Pedal::Sustain),
            (66, Pedal::Sostenuto),
            (67, Pedal::Soft),
        ] {
            for value in 0..=127u8 {
                let Some(Event::Pedal { pedal: p, depth }) = d.decode(0xB3, cc, value) else {
                    panic!("CC{cc} {value}: no pedal event");
                };
                assert_eq!((p, depth), (pedal, f64::from(value) / 127.0));
                assert_eq!(depth >= PEDAL_DOWN_AT, value >= 64, "CC{cc} {value}");
            }
        }
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
