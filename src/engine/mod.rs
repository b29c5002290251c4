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
pub mod exponential;
pub mod hammer;
pub mod plate;
pub mod soundboard;
pub mod statespace;
pub mod string;
pub mod system;
pub mod tuning;

pub use system::{Instrument, Observation, Strike, UnisonSpec};

/// What the offline renderer needs of a one-key engine: RK4 on [`Instrument`] (the reference, at
/// the paper's rate) or ETDRK4 on [`exponential::ExponentialUnison`] (at the output rate).
pub trait Engine {
    /// Advance one internal step.
    fn step(&mut self);
    /// Forces and volume velocity now (Eq. 19), of the first voice.
    fn observe(&self) -> Observation;
    fn strike(&mut self, strike: Strike);
    fn set_damper(&mut self, down: bool);
    /// Internal step (s).
    fn step_s(&self) -> f64;
}

impl Engine for Instrument {
    fn step(&mut self) {
        Instrument::step(self)
    }
    fn observe(&self) -> Observation {
        Instrument::observe(self)
    }
    fn strike(&mut self, strike: Strike) {
        Instrument::strike(self, strike)
    }
    fn set_damper(&mut self, down: bool) {
        Instrument::set_damper(self, down)
    }
    fn step_s(&self) -> f64 {
        Instrument::step_s(self)
    }
}

impl Engine for exponential::ExponentialUnison {
    fn step(&mut self) {
        exponential::ExponentialUnison::step(self)
    }
    fn observe(&self) -> Observation {
        exponential::ExponentialUnison::observe(self)
    }
    fn strike(&mut self, strike: Strike) {
        exponential::ExponentialUnison::strike(self, strike)
    }
    fn set_damper(&mut self, down: bool) {
        exponential::ExponentialUnison::set_damper(self, down)
    }
    fn step_s(&self) -> f64 {
        exponential::ExponentialUnison::step_s(self)
    }
}

/// How a one-key render integrates: the paper's RK4 at `min_rate_over_fmax × f_max` (the
/// reference), or exponential RK4 (ETDRK4) on complex modes at the output rate (the live
/// integrator, `tests/integrators.rs`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Integrator {
    #[default]
    Rk4,
    Exponential,
}

/// Directions at the bridge, in the paper's order (Eq. 5–6): transverse to the
/// board (T), longitudinal along the string (L), parallel to the board (P).
pub const DIRECTIONS: [&str; 3] = ["T", "L", "P"];

/// The most strings a unison can hold (a treble trichord).
pub const MAX_STRINGS: usize = 3;
