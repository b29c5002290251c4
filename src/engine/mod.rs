//! Pure physics: no I/O, no threads, no allocation after a [`Instrument`] is built.
//!
//! One module per physical part of the paper's model, one for their assembly:
//! - [`string`]: stiff-string modes in T, P and L (Eq. 1–3),
//! - [`duplex`]: the distributed damper on the duplex segment (Eq. 13),
//! - [`soundboard`]: the reduced modal soundboard (Eq. 4–5) and its asset format,
//! - [`plate`]: the generator of that asset from an orthotropic plate,
//! - [`contact`]: the string–bridge contact springs and dampers (Eq. 6–7),
//! - [`hammer`]: the nonlinear felt hammer (Eq. 8–9),
//! - [`damper`]: the felt that silences a released key,
//! - [`system`]: the state-space assembly (Eq. 10–19) advanced with classical RK4,
//! - [`statespace`]: the same system in the paper's literal dense form, the baseline it is checked
//!   and measured against,
//! - [`tuning`]: the coupled first partial, from the undamped linear system.

pub mod contact;
pub mod damper;
pub mod duplex;
pub mod hammer;
pub mod plate;
pub mod soundboard;
pub mod statespace;
pub mod string;
pub mod system;
pub mod tuning;

pub use system::{Instrument, Observation, Strike, UnisonSpec};

/// Directions at the bridge, in the paper's order (Eq. 5–6): transverse to the
/// board (T), longitudinal along the string (L), parallel to the board (P).
pub const DIRECTIONS: [&str; 3] = ["T", "L", "P"];

/// The most strings a unison can hold (a treble trichord).
pub const MAX_STRINGS: usize = 3;
