//! Signal analysis for tests and figures: spectra, partial tracking, envelopes.

pub mod duplex;
#[cfg(feature = "figures")]
pub mod figures;
pub mod listening;
pub mod mobility;
pub mod modes;
pub mod partials;
pub mod recorded;
pub mod spectral;
pub mod stability;
pub mod struck;
