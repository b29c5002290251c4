//! Any bytes as the CLAP plugin's saved state (a DAW project is untrusted input): refused with a
//! reason, or values that are all in range and save back to a state that loads the same values
//! — never a panic. The fuzz script caps the memory a run may allocate.
#![no_main]
use libfuzzer_sys::fuzz_target;
use unacorda_clap::params::{Values, PARAMS};
use unacorda_clap::state;

fuzz_target!(|data: &[u8]| {
    if let Ok(loaded) = state::load(data) {
        let values = Values::default();
        for (i, v) in loaded.iter().enumerate() {
            assert!((PARAMS[i].min..=PARAMS[i].max).contains(v), "{}", PARAMS[i].key);
            values.set(i, *v);
        }
        let again = state::load(state::save(&values).as_bytes()).expect("a saved state loads");
        assert!(again.iter().zip(&loaded).all(|(a, b)| a.to_bits() == b.to_bits()));
    }
});
