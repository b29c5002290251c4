//! What the duplex felt (Eq. 13) does to a key, from its linearised system with and without it:
//! the decay of the speaking length's partials, which it should leave alone, and of the duplex
//! segment's first resonance, which it is there to mute.

use super::modes::{linear_modes, LinearMode, ModesError};
use super::partials::KeyPartials;
use crate::engine::tuning::STRING_SHARE;
use crate::engine::UnisonSpec;

/// Share of a string mode's transverse kinetic energy on the duplex segment from which it is a
/// resonance of that segment rather than a partial of the speaking length.
pub const DUPLEX_SHARE: f64 = 0.5;

/// A key with its felt and without it.
#[derive(Debug, Clone, PartialEq)]
pub struct FeltEffect {
    /// The felt's c_d (N s/m^2).
    pub damping_n_s_m2: f64,
    pub with: KeyPartials,
    pub without: KeyPartials,
    /// The duplex segment's first resonance with the felt and without it.
    pub resonance_with: Option<LinearMode>,
    pub resonance_without: Option<LinearMode>,
}

impl FeltEffect {
    /// Partial `n`'s slowest T60 with the felt over its slowest T60 without it (1: untouched).
    pub fn kept(&self, n: usize) -> Option<f64> {
        Some(self.with.partial(n)?.t60_max_s / self.without.partial(n)?.t60_max_s)
    }
}

/// The lowest string mode (mostly transverse) whose energy is mostly on the duplex segment.
pub fn duplex_resonance(modes: &[LinearMode]) -> Option<LinearMode> {
    modes
        .iter()
        .find(|m| m.shares[0] >= STRING_SHARE && m.duplex_share >= DUPLEX_SHARE)
        .copied()
}

/// `spec` as it is and with its duplex felt taken off; partials `1..=count` against `target_hz`.
pub fn felt_effect(
    spec: &UnisonSpec,
    target_hz: f64,
    count: usize,
) -> Result<FeltEffect, ModesError> {
    let bare = UnisonSpec {
        duplex_damping_n_s_m2: 0.0,
        ..spec.clone()
    };
    let (with, without) = (linear_modes(spec)?, linear_modes(&bare)?);
    Ok(FeltEffect {
        damping_n_s_m2: spec.duplex_damping_n_s_m2,
        with: KeyPartials::of_modes(&with, spec, target_hz, count),
        without: KeyPartials::of_modes(&without, &bare, target_hz, count),
        resonance_with: duplex_resonance(&with),
        resonance_without: duplex_resonance(&without),
    })
}
