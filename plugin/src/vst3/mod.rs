//! unacorda as a VST3 instrument, on the `vst3` crate's raw bindings of the SDK's interfaces: one
//! object is the component, the audio processor and the edit controller at once (hosts query the
//! controller from the component), beside the CLAP plugin in the same library and playing the
//! same synth ([`crate::sound`]).
//!
//! - [`component`]: the plugin's object: buses, parameters, state, MIDI controllers mapped to the
//!   pedals, activation;
//! - [`audio`]: the audio thread's side: events and parameter changes at their frame, the render
//!   mode read every block, a piano rebuilt in the background swapped in at a block's start;
//! - [`view`]: the editor embedded in the host's window;
//! - [`factory`]: the factory and the library's exports (`GetPluginFactory`, `ModuleEntry`,
//!   `ModuleExit`).

pub mod audio;
pub mod component;
pub mod factory;
pub mod view;

use vst3::Steinberg::char16;

/// `text` into a host's UTF-16 buffer, cut to fit and ended with a zero.
fn copy_wide(text: &str, dest: &mut [char16]) {
    let Some(room) = dest.len().checked_sub(1) else {
        return;
    };
    let mut n = 0;
    for (d, c) in dest[..room].iter_mut().zip(text.encode_utf16()) {
        *d = c as char16;
        n += 1;
    }
    dest[n] = 0;
}

/// `text` into a host's byte-string buffer, cut to fit and ended with a zero.
fn copy_narrow(text: &str, dest: &mut [std::ffi::c_char]) {
    let Some(room) = dest.len().checked_sub(1) else {
        return;
    };
    let mut n = 0;
    for (d, &b) in dest[..room].iter_mut().zip(text.as_bytes()) {
        *d = b as std::ffi::c_char;
        n += 1;
    }
    dest[n] = 0;
}

/// A host's zero-ended UTF-16 string (at most `max` units), if it is valid text.
///
/// # Safety
/// `text` is null or points at a zero-ended string of at most `max` units.
unsafe fn read_wide(text: *const char16, max: usize) -> Option<String> {
    if text.is_null() {
        return None;
    }
    let mut len = 0;
    // SAFETY: the caller's promise: within `max` units, up to the zero.
    while len < max && unsafe { *text.add(len) } != 0 {
        len += 1;
    }
    // SAFETY: the `len` units just read.
    let units = unsafe { std::slice::from_raw_parts(text.cast::<u16>(), len) };
    String::from_utf16(units).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strings_are_cut_to_fit_and_ended_with_a_zero() {
        let mut wide = [7 as char16; 5];
        copy_wide("Sustain pedal", &mut wide);
        assert_eq!(wide, [83, 117, 115, 116, 0].map(|c| c as char16));
        // SAFETY: ended with a zero within its length.
        assert_eq!(
            unsafe { read_wide(wide.as_ptr(), 5) }.as_deref(),
            Some("Sust")
        );
        let mut narrow = [7 as std::ffi::c_char; 4];
        copy_narrow("unacorda", &mut narrow);
        assert_eq!(narrow, [117, 110, 97, 0].map(|c| c as std::ffi::c_char));
        copy_wide("", &mut wide);
        assert_eq!(wide[0], 0);
    }
}
