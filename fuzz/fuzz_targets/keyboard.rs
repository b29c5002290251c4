//! Any text as a keyboard file: an error naming the problem, or a keyboard whose middle key (C4)
//! builds or is refused with one — never a panic, never an endless read or solve.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let path = std::path::Path::new("fuzz.toml");
        if let Ok(keyboard) = unacorda::config::scaling::Scaling::parse(text, path) {
            let _ = keyboard.key_preset(40);
        }
    }
});
