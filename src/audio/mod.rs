//! The sound shell: decimation to the output rate, the audio thread's engine ([`synth`]) and what
//! a full event queue keeps for it ([`backlog`]), a
//! host's blocks of any length realigned to the synth's grid ([`aligned`]), the audio device
//! (`device`, feature `device`), the helper thread that lends the callback a second core
//! ([`helper`]) or a host's thread pool that does ([`host_pool`]), real-time priority
//! ([`priority`]), WAV files, and what the piano is doing for a front end to show ([`activity`]).

pub mod activity;
pub mod aligned;
pub mod backlog;
pub mod clock;
pub mod decimate;
#[cfg(feature = "device")]
pub mod device;
pub mod helper;
pub mod host_pool;
pub mod priority;
pub mod radiate;
pub mod synth;
pub mod wav;

pub use aligned::Aligned;
pub use decimate::Decimator;
pub use synth::{Scheduled, Synth, SynthHandle};
