//! Any byte stream through the live parser the midir callback uses, and every event it yields
//! through the piano's mapping: never a panic, notes and velocities (CC88's fractions included) in
//! range.
#![no_main]
use libfuzzer_sys::fuzz_target;
use unacorda::midi::{hammer_speed_m_s, live::LiveParser, Event};

fuzz_target!(|data: &[u8]| {
    let mut parser = LiveParser::new();
    for &b in data {
        if let Some(Event::NoteOn { note, velocity }) = parser.push(b) {
            assert!(note < 128 && (1.0..=127.0).contains(&velocity));
            let v = hammer_speed_m_s(velocity).expect("a note-on's velocity has a speed");
            assert!(v.is_finite() && v > 0.0);
        }
    }
});
