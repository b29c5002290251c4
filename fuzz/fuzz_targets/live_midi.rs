//! Any byte stream through the live parser the midir callback uses, and every event it yields
//! through the piano's mapping: never a panic, notes and velocities in range.
#![no_main]
use libfuzzer_sys::fuzz_target;
use unacorda::midi::{hammer_speed_m_s, live::LiveParser, Event};

fuzz_target!(|data: &[u8]| {
    let mut parser = LiveParser::new();
    for &b in data {
        if let Some(Event::NoteOn { note, velocity }) = parser.push(b) {
            assert!(note < 128 && velocity < 128);
            if let Some(v) = hammer_speed_m_s(velocity) {
                assert!(v.is_finite() && v > 0.0);
            }
        }
    }
});
