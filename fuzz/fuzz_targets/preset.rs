//! Any text as a preset: an error naming the problem, or a preset whose values passed the range
//! checks — never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = unacorda::config::preset::Preset::parse(text, std::path::Path::new("fuzz.toml"));
    }
});
