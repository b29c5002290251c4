//! The sound shell: decimation to the output rate, the audio thread's engine ([`synth`]), the
//! audio device ([`device`]) and WAV files.

pub mod decimate;
pub mod device;
pub mod synth;
pub mod wav;

pub use decimate::Decimator;
pub use synth::{Scheduled, Synth, SynthHandle};
