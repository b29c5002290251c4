//! What a full event queue could not take from a live input, kept until it has room again.
//!
//! A live input (a MIDI keyboard's callback) cannot wait for the audio thread: when the queue is
//! full (the audio thread held up by a device hiccup or a slow rebuild) an event must be kept or
//! dropped at once. A lost note-off is a stuck note and a lost pedal release a piano that never
//! stops ringing, so every release is kept — a key's note-off once per key, each pedal's latest
//! position, all-notes-off, all-sound-off and reset — and queued, late, as soon as there is room.
//! A strike that finds the queue full (or releases still waiting ahead of it) is dropped and
//! counted: played late it would no longer be the note the pianist played. No allocation: the
//! backlog is a fixed set of flags.

use crate::midi::{Event, Pedal};

/// The pedals in the order the backlog keeps them.
const PEDALS: [Pedal; 3] = [Pedal::Sustain, Pedal::Sostenuto, Pedal::Soft];

/// Releases waiting for room in the queue, and what the queue has cost (written by the thread
/// that schedules live events; read by it for the summary).
#[derive(Debug, Clone, PartialEq)]
pub struct Backlog {
    /// Notes whose note-off waits, one bit per MIDI note, and each one's release velocity.
    note_offs: u128,
    release_velocity: [f64; 128],
    /// Each pedal's latest position not yet queued ([`PEDALS`] order).
    pedals: [Option<f64>; 3],
    all_sound_off: bool,
    all_notes_off: bool,
    reset_controllers: bool,
    /// Strikes dropped because the queue was full.
    pub dropped_note_ons: u64,
    /// Releases and pedal moves queued late, once the queue had room.
    pub delayed: u64,
}

impl Default for Backlog {
    fn default() -> Backlog {
        Backlog {
            note_offs: 0,
            release_velocity: [0.0; 128],
            pedals: [None; 3],
            all_sound_off: false,
            all_notes_off: false,
            reset_controllers: false,
            dropped_note_ons: 0,
            delayed: 0,
        }
    }
}

impl Backlog {
    /// Whether nothing waits.
    pub fn is_empty(&self) -> bool {
        self.note_offs == 0
            && self.pedals.iter().all(Option::is_none)
            && !(self.all_sound_off || self.all_notes_off || self.reset_controllers)
    }

    /// Keep `event`, which the queue had no room for: a release until there is room, a strike
    /// counted and dropped.
    pub fn keep(&mut self, event: Event) {
        match event {
            Event::NoteOn { .. } => self.dropped_note_ons += 1,
            // A MIDI note is a data byte, 0–127: one bit each.
            Event::NoteOff { note, velocity } => {
                self.note_offs |= 1u128 << (note & 0x7F);
                self.release_velocity[usize::from(note & 0x7F)] = velocity;
            }
            Event::Pedal { pedal, depth } => {
                let i = PEDALS.iter().position(|&p| p == pedal).unwrap_or(0);
                self.pedals[i] = Some(depth);
            }
            Event::AllSoundOff => self.all_sound_off = true,
            Event::AllNotesOff => self.all_notes_off = true,
            Event::ResetControllers => self.reset_controllers = true,
        }
    }

    /// The next event waiting (silencing first, then the keys, then the pedals), without taking
    /// it: [`Backlog::taken`] once the queue has accepted it.
    pub fn next(&self) -> Option<Event> {
        if self.all_sound_off {
            return Some(Event::AllSoundOff);
        }
        if self.all_notes_off {
            return Some(Event::AllNotesOff);
        }
        if self.reset_controllers {
            return Some(Event::ResetControllers);
        }
        if self.note_offs != 0 {
            let note = self.note_offs.trailing_zeros() as u8;
            let velocity = self.release_velocity[usize::from(note)];
            return Some(Event::NoteOff { note, velocity });
        }
        PEDALS
            .iter()
            .zip(&self.pedals)
            .find_map(|(&pedal, depth)| depth.map(|depth| Event::Pedal { pedal, depth }))
    }

    /// `event` (the one [`Backlog::next`] gave) is queued: no longer waiting.
    pub fn taken(&mut self, event: Event) {
        match event {
            Event::AllSoundOff => self.all_sound_off = false,
            Event::AllNotesOff => self.all_notes_off = false,
            Event::ResetControllers => self.reset_controllers = false,
            Event::NoteOff { note, .. } => self.note_offs &= !(1u128 << (note & 0x7F)),
            Event::Pedal { pedal, .. } => {
                let i = PEDALS.iter().position(|&p| p == pedal).unwrap_or(0);
                self.pedals[i] = None;
            }
            Event::NoteOn { .. } => return,
        }
        self.delayed += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn off(note: u8, velocity: f64) -> Event {
        Event::NoteOff { note, velocity }
    }

    /// A key's note-off kept once, with its latest release velocity.
    #[test]
    fn every_release_is_kept_once_and_strikes_are_counted() {
        let mut b = Backlog::default();
        for event in [
            Event::NoteOn {
                note: 60,
                velocity: 90.0,
            },
            off(60, 30.0),
            off(60, 100.5),
            off(127, 64.0),
            off(0, 1.0),
            Event::pedal(Pedal::Sustain, true),
            Event::pedal(Pedal::Sustain, false),
            Event::pedal(Pedal::Soft, true),
            Event::AllNotesOff,
        ] {
            b.keep(event);
        }
        let mut out = vec![];
        while let Some(e) = b.next() {
            b.taken(e);
            out.push(e);
        }
        assert_eq!(
            out,
            [
                Event::AllNotesOff,
                off(0, 1.0),
                off(60, 100.5),
                off(127, 64.0),
                Event::pedal(Pedal::Sustain, false),
                Event::pedal(Pedal::Soft, true),
            ]
        );
        assert!(b.is_empty());
        assert_eq!((b.dropped_note_ons, b.delayed), (1, 6));
    }
}
