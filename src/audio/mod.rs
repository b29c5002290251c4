//! The sound shell: decimation to the output rate, the audio thread's engine ([`synth`]), the
//! audio device ([`device`]), the helper thread that lends the callback a second core ([`helper`]),
//! real-time priority for both ([`priority`]) and WAV files.

pub mod clock;
pub mod decimate;
pub mod device;
pub mod helper;
pub mod priority;
pub mod radiate;
pub mod synth;
pub mod wav;

pub use decimate::Decimator;
pub use synth::{Scheduled, Synth, SynthHandle};
