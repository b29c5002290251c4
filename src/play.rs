//! Playing the instrument: piano events (from live MIDI or a MIDI file) applied to keys that share
//! one soundboard, with the pedals' logic. Keys are voices of one [`Unison`] system, each at its
//! own bridge point; a key struck again is struck in its current motion.

use crate::engine::{Strike, Unison};
use crate::midi::{hammer_speed_m_s, piano_key, Event, Pedal};

/// The performer's state: which keys are down and what the pedals do.
#[derive(Debug, Clone)]
pub struct Player {
    /// Voice of each key (1–88), if the instrument has that key.
    voice_of_key: [Option<usize>; 89],
    key_down: [bool; 89],
    /// Keys whose dampers the sostenuto pedal holds up.
    sostenuto_held: [bool; 89],
    sustain: bool,
    sostenuto: bool,
    soft: bool,
}

impl Player {
    /// A player for an instrument whose voice `k` is key `keys[k]` (1–88).
    pub fn new(keys: &[usize]) -> Player {
        let mut voice_of_key = [None; 89];
        for (voice, &key) in keys.iter().enumerate() {
            if (1..=88).contains(&key) {
                voice_of_key[key] = Some(voice);
            }
        }
        Player {
            voice_of_key,
            key_down: [false; 89],
            sostenuto_held: [false; 89],
            sustain: false,
            sostenuto: false,
            soft: false,
        }
    }

    /// Whether the soft pedal is down.
    pub fn soft(&self) -> bool {
        self.soft
    }

    /// Apply one event to the instrument. Events for keys the instrument lacks are ignored.
    pub fn apply(&mut self, event: Event, instrument: &mut Unison) {
        match event {
            Event::NoteOn { note, velocity } => {
                let (Some(key), Some(speed)) = (piano_key(note), hammer_speed_m_s(velocity)) else {
                    return;
                };
                if let Some(v) = self.voice_of_key[key] {
                    self.key_down[key] = true;
                    instrument.set_damper_voice(v, false);
                    instrument.strike_voice(
                        v,
                        Strike {
                            velocity_m_s: speed,
                            una_corda: self.soft,
                        },
                    );
                }
            }
            Event::NoteOff { note } => {
                if let Some(key) = piano_key(note) {
                    self.key_down[key] = false;
                    self.settle_damper(key, instrument);
                }
            }
            Event::Pedal {
                pedal: Pedal::Sustain,
                down,
            } => {
                self.sustain = down;
                self.settle_all(instrument);
            }
            Event::Pedal {
                pedal: Pedal::Sostenuto,
                down,
            } => {
                self.sostenuto = down;
                self.sostenuto_held = if down { self.key_down } else { [false; 89] };
                self.settle_all(instrument);
            }
            Event::Pedal {
                pedal: Pedal::Soft,
                down,
            } => self.soft = down,
            Event::AllNotesOff => {
                self.key_down = [false; 89];
                self.settle_all(instrument);
            }
            Event::AllSoundOff => {
                self.key_down = [false; 89];
                for v in self.voice_of_key.iter().flatten() {
                    instrument.set_damper_voice(*v, true);
                }
            }
            Event::ResetControllers => {
                self.sustain = false;
                self.sostenuto = false;
                self.sostenuto_held = [false; 89];
                self.soft = false;
                self.settle_all(instrument);
            }
        }
    }

    /// Lift or drop one key's damper from the key and the pedals.
    fn settle_damper(&self, key: usize, instrument: &mut Unison) {
        if let Some(v) = self.voice_of_key[key] {
            let lifted = self.key_down[key] || self.sustain || self.sostenuto_held[key];
            instrument.set_damper_voice(v, !lifted);
            // Strings whose damper is up ring in sympathy with the rest through the board.
            if lifted {
                instrument.set_active(v, true);
            }
        }
    }

    fn settle_all(&self, instrument: &mut Unison) {
        for key in 1..=88 {
            self.settle_damper(key, instrument);
        }
    }
}
