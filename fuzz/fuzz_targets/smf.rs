//! Any bytes as a standard MIDI file: an error or events, never a panic; events in time order
//! with finite times.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(events) = unacorda::midi::file::parse(data, std::path::Path::new("fuzz.mid")) {
        assert!(events
            .iter()
            .all(|e| e.time_s.is_finite() && e.time_s >= 0.0));
        assert!(events.windows(2).all(|w| w[0].time_s <= w[1].time_s));
    }
});
