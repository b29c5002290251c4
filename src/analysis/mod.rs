//! Signal analysis for tests and figures: spectra, partial tracking, envelopes.

pub mod figures;
pub mod mobility;
pub mod modes;
pub mod partials;
pub mod spectral;
pub mod stability;
