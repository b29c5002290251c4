//! Sound from the engine offline: one key struck for analysis ([`strike`]), and MIDI
//! performances through the live engine's path ([`performance`]).

pub mod performance;
pub mod strike;

pub use performance::{
    render_midi, render_midi_into, render_midi_kept, render_midi_with, Offline, Performance,
    RenderError, Rendered, OFFLINE_BLOCK,
};
pub use strike::{simulate, simulate_with, Frame, Length, Recording, Renderer, RING_OUT_WINDOW_S};
