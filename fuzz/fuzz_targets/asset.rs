//! Any text as a soundboard asset: an error naming file, line and field, or modes whose numbers
//! are all finite — never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok(board) = unacorda::config::asset::parse(text, std::path::Path::new("fuzz.txt")) {
            assert!(board.freq_hz.iter().all(|f| f.is_finite()));
            assert!(board
                .points
                .iter()
                .all(|p| p.shape.iter().flatten().all(|x| x.is_finite())));
            assert!(board.listeners.iter().all(|l| {
                l.rayleigh_re.len() == board.freq_hz.len()
                    && l.rayleigh_re.iter().chain(&l.rayleigh_im).all(|x| x.is_finite())
            }));
        }
    }
});
