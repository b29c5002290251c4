//! The sound shell: decimation to the output rate and WAV files.

pub mod decimate;
pub mod wav;

pub use decimate::Decimator;
