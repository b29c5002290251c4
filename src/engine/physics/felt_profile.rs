//! The hammer's felt across its width, and the soft pedal's shift of the action (una corda).
//!
//! A grand's soft pedal shifts the whole action sideways, so that each hammer meets its strings
//! with another part of its felt. Across the hammer (coordinate `u`, 0 at its middle) the strings
//! of a unison of `n` rest `string_spacing_m` apart, string `j` at `x_j = ((n - 1)/2 - j) s`; a
//! shift `sigma` (a fraction of the full shift) puts it at `u_j = x_j - sigma s` on the felt. The
//! full shift is one string spacing, as technicians regulate it: the struck strings then meet the
//! grooves their neighbours have pressed into the felt, and the last string misses the hammer
//! (C. C. Chang, *Fundamentals of Piano Practice*, §40) — the paper's una corda, with the very
//! felt of the normal strike.
//!
//! Along the way each string meets:
//! - **a groove** (at every `x_j`, `groove_width_m` wide): felt compacted by the strings,
//!   the hammer's own law `K xi^p` (Eq. 8) at its middle;
//! - **unworn felt** between and beside the grooves: softer (`unworn_stiffness_ratio` of the
//!   groove's force at [`UNWORN_REFERENCE_M`] of compression) and less steep
//!   (`unworn_exponent_change`, as the felt's exponent falls with its density from treble to bass
//!   hammers: Hall & Askenfelt, JASA 83, 1988), its surface `groove_depth_m` proud of the groove's.
//!   Across a groove's flank the exponent and the logarithm of the stiffness blend with a raised
//!   cosine, so the law is smooth in the shift;
//! - **the shoulder**: the felt reaches `overhang_m` beyond the outer strings (a bichord's for a
//!   single string, whose hammer is at least that wide), and over its last `shoulder_m` (`r`) its
//!   surface rounds away, `shoulder_depth_m (e/r)^2` behind the crown `e` into the shoulder,
//!   while the contact narrows (the stiffness falls as `1 - (e/r)^2`) to nothing at the edge,
//!   beyond which the string is not struck. A shoulder deeper than a blow compresses the felt
//!   lets the string go before the edge, gradually.
//!
//! Each string's law ([`FeltLaw`]) follows from where it sits when the hammer is launched: a
//! string in its groove (shift 0, or a neighbour's at the full shift) has the hammer's own law,
//! bit for bit.

use super::hammer::{FeltLaw, HammerParams};
use std::f64::consts::PI;

/// The compression at which the unworn felt's force is `unworn_stiffness_ratio` of the groove's
/// (m): a typical compression of a mezzo-forte blow, so that the ratio reads as "how much softer".
pub const UNWORN_REFERENCE_M: f64 = 1e-3;

/// The felt across a hammer's width (see the module's description).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeltProfile {
    /// Between neighbouring strings of a unison at the strike, and the action's full shift (m).
    pub string_spacing_m: f64,
    /// How far the felt reaches beyond the outer strings of the unison at shift 0 (m).
    pub overhang_m: f64,
    /// Width of the rounded edge over which the contact narrows to nothing (m).
    pub shoulder_m: f64,
    /// How far the felt's surface falls away across the shoulder, at the edge (m).
    pub shoulder_depth_m: f64,
    /// Width of each string's groove (m).
    pub groove_width_m: f64,
    /// How far a groove lies below the unworn felt around it (m).
    pub groove_depth_m: f64,
    /// The unworn felt's force over the groove's at [`UNWORN_REFERENCE_M`] (-).
    pub unworn_stiffness_ratio: f64,
    /// The unworn felt's exponent less the groove's (-).
    pub unworn_exponent_change: f64,
}

/// The profile a preset or keyboard that says nothing about it gets: a felt worn to shallow
/// grooves, its unworn parts somewhat softer; the felt reaches a string spacing beyond the outer
/// strings, so that the last string rounds the shoulder over the last third of the travel and
/// leaves the felt just at the full shift.
pub const DEFAULT_PROFILE: FeltProfile = FeltProfile {
    string_spacing_m: 2.5e-3,
    overhang_m: 2.5e-3,
    shoulder_m: 0.8e-3,
    shoulder_depth_m: 2.4e-3,
    groove_width_m: 1.0e-3,
    groove_depth_m: 0.2e-3,
    unworn_stiffness_ratio: 0.6,
    unworn_exponent_change: -0.3,
};

/// Why a profile cannot hold a unison: the field, its value, and what it must be.
#[derive(Debug, Clone, PartialEq)]
pub struct ProfileError {
    pub field: &'static str,
    pub value: f64,
    pub allowed: String,
}

/// The range of a string spacing (m).
pub const STRING_SPACING_M: std::ops::RangeInclusive<f64> = 1e-3..=6e-3;
/// The deepest groove (m).
pub const MAX_GROOVE_DEPTH_M: f64 = 1e-3;
/// The deepest shoulder (m): a hammer's felt is about this thick.
pub const MAX_SHOULDER_DEPTH_M: f64 = 1e-2;

impl FeltProfile {
    /// The felt's half-width across the hammer for a unison of `n_strings` (m).
    pub fn half_width_m(&self, n_strings: usize) -> f64 {
        (n_strings.max(2) - 1) as f64 / 2.0 * self.string_spacing_m + self.overhang_m
    }

    /// Where string `string` of `n_strings` rests across the hammer at shift 0 (m).
    fn rest_m(&self, n_strings: usize, string: usize) -> f64 {
        ((n_strings - 1) as f64 / 2.0 - string as f64) * self.string_spacing_m
    }

    /// How much of a groove's felt is at `u_m` (1 at a groove's middle, 0 on unworn felt).
    fn groove_share(&self, n_strings: usize, u_m: f64) -> f64 {
        let half = self.groove_width_m / 2.0;
        (0..n_strings)
            .map(|g| (u_m - self.rest_m(n_strings, g)).abs())
            .filter(|&d| d < half)
            .map(|d| (PI * d / self.groove_width_m).cos().powi(2))
            .fold(0.0, f64::max)
    }

    /// The felt law string `string` of a unison of `n_strings` meets at the shift `shift` (0 the
    /// normal strike, 1 the full soft pedal; clamped, and 0 if not a number), or `None` where the
    /// hammer misses it.
    pub fn law(
        &self,
        hammer: &HammerParams,
        n_strings: usize,
        string: usize,
        shift: f64,
    ) -> Option<FeltLaw> {
        let shift = if shift.is_finite() {
            shift.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let u_m = self.rest_m(n_strings, string) - shift * self.string_spacing_m;
        let half_m = self.half_width_m(n_strings);
        if u_m.abs() >= half_m {
            return None;
        }
        let b = self.groove_share(n_strings, u_m);
        let unworn = 1.0 - b;
        let exponent =
            hammer.exponent * b + (hammer.exponent + self.unworn_exponent_change) * unworn;
        let mut stiffness_n_m_p = hammer.stiffness_n_m_p
            * UNWORN_REFERENCE_M.powf(hammer.exponent - exponent)
            * self.unworn_stiffness_ratio.powf(unworn);
        let mut offset_m = -self.groove_depth_m * unworn;
        let into_shoulder_m = u_m.abs() - (half_m - self.shoulder_m);
        if into_shoulder_m > 0.0 {
            let rounded = (into_shoulder_m / self.shoulder_m).powi(2);
            stiffness_n_m_p *= 1.0 - rounded;
            offset_m += self.shoulder_depth_m * rounded;
        }
        Some(FeltLaw {
            stiffness_n_m_p,
            exponent,
            offset_m,
        })
    }

    /// Whether the profile holds every unison a keyboard may have (one to three strings): every
    /// groove on the felt's crown at shift 0 (each string struck by the hammer's own law), the
    /// grooves apart, a single string struck at every shift, and a bichord's or trichord's last
    /// string clear of the felt at the full shift.
    pub fn check(&self) -> Result<(), ProfileError> {
        let err = |field, value, allowed: String| {
            Err(ProfileError {
                field,
                value,
                allowed,
            })
        };
        let s = self.string_spacing_m;
        if !STRING_SPACING_M.contains(&s) {
            return err(
                "string_spacing_m",
                s,
                format!(
                    "{:e} to {:e}",
                    STRING_SPACING_M.start(),
                    STRING_SPACING_M.end()
                ),
            );
        }
        if !(self.groove_width_m > 0.0 && self.groove_width_m <= s) {
            return err(
                "groove_width_m",
                self.groove_width_m,
                format!("more than 0, at most the string spacing ({s:e}): grooves apart"),
            );
        }
        if !(0.0..=MAX_GROOVE_DEPTH_M).contains(&self.groove_depth_m) {
            return err(
                "groove_depth_m",
                self.groove_depth_m,
                format!("0 to {MAX_GROOVE_DEPTH_M:e}"),
            );
        }
        if !(self.unworn_stiffness_ratio > 0.0 && self.unworn_stiffness_ratio <= 1.0) {
            return err(
                "unworn_stiffness_ratio",
                self.unworn_stiffness_ratio,
                "more than 0, at most 1 (unworn felt is no harder than a groove)".into(),
            );
        }
        if !(-1.0..=0.0).contains(&self.unworn_exponent_change) {
            return err(
                "unworn_exponent_change",
                self.unworn_exponent_change,
                "-1 to 0".into(),
            );
        }
        if !(0.0..=MAX_SHOULDER_DEPTH_M).contains(&self.shoulder_depth_m) {
            return err(
                "shoulder_depth_m",
                self.shoulder_depth_m,
                format!("0 to {MAX_SHOULDER_DEPTH_M:e}"),
            );
        }
        if !(self.shoulder_m > 0.0 && self.shoulder_m.is_finite()) {
            return err(
                "shoulder_m",
                self.shoulder_m,
                "more than 0, at most overhang_m less half a groove".into(),
            );
        }
        // The outer grooves lie on the crown (inside the shoulder), so that shift 0 strikes every
        // string with the hammer's own law; and a bichord's or trichord's last string leaves the
        // felt by the full shift, so that it gives the paper's una corda.
        // A single string stays on the felt (a bichord's width) at the full shift.
        let least_m = (self.groove_width_m / 2.0 + self.shoulder_m).max(s / 2.0);
        if !(self.overhang_m >= least_m && self.overhang_m > s / 2.0 && self.overhang_m <= s) {
            return err(
                "overhang_m",
                self.overhang_m,
                format!(
                    "more than {least_m:e} (half a groove plus the shoulder: the outer grooves \
                     on the crown, else a groove wider than the felt strikes no string whole; and \
                     half the spacing: a single string stays struck) up to the string spacing \
                     ({s:e}: a bichord's or trichord's last string clear at the full shift)"
                ),
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::physics::hammer::tests::c4;

    fn own(h: &HammerParams) -> FeltLaw {
        FeltLaw {
            stiffness_n_m_p: h.stiffness_n_m_p,
            exponent: h.exponent,
            offset_m: 0.0,
        }
    }

    /// Shift 0 strikes every string with the hammer's own law, the full shift every string but
    /// the last with it (each in its neighbour's groove) and the last not at all: bit for bit.
    #[test]
    fn both_ends_are_the_hammers_own_law() {
        let h = c4(0.0);
        for n in 1..=3 {
            for s in 0..n {
                assert_eq!(
                    h.profile.law(&h, n, s, 0.0),
                    Some(own(&h)),
                    "{n} strings, {s}"
                );
                assert_eq!(
                    h.profile.law(&h, n, s, f64::NAN),
                    Some(own(&h)),
                    "not a number"
                );
                let full = h.profile.law(&h, n, s, 1.0);
                if n == 1 {
                    // A single string moves onto the unworn felt beside its groove.
                    let law = full.unwrap();
                    println!("single string at the full shift: {law:?}");
                    assert!(law.stiffness_n_m_p < h.stiffness_n_m_p);
                } else if s + 1 < n {
                    assert_eq!(full, Some(own(&h)), "{n} strings, {s} at the full shift");
                } else {
                    assert_eq!(full, None, "{n} strings, the last at the full shift");
                }
            }
        }
    }

    /// The law moves continuously with the shift: the force at 1 mm of compression changes by
    /// less than 1 % of the groove's between shifts 1/2000 apart (the steepest place, the
    /// shoulder's edge, changes a few tenths of a percent per step; a jump would show as tens of
    /// percent), reaching nothing at the edge.
    #[test]
    fn the_law_is_continuous_in_the_shift() {
        let h = c4(0.0);
        let force = |law: Option<FeltLaw>| law.map_or(0.0, |l| l.force_n(1e-3, 0.0, 0.0));
        let full = force(Some(own(&h)));
        for n in 1..=3 {
            for s in 0..n {
                let mut worst: f64 = 0.0;
                let steps = 2000;
                for i in 0..steps {
                    let a = force(h.profile.law(&h, n, s, i as f64 / steps as f64));
                    let b = force(h.profile.law(&h, n, s, (i + 1) as f64 / steps as f64));
                    worst = worst.max((a - b).abs() / full);
                }
                println!("{n} strings, string {s}: largest step {worst:.4} of the groove's force");
                assert!(worst < 0.01, "{n} strings, string {s}: {worst}");
            }
        }
    }

    /// Mid-way every string lies on unworn felt (softer, proud of the grooves); the leaving
    /// string weakens through the shoulder.
    #[test]
    fn between_the_grooves_the_felt_is_softer() {
        let h = c4(0.0);
        let mid = h.profile.law(&h, 3, 0, 0.5).unwrap();
        println!("trichord mid-way: {mid:?}");
        let ratio = mid.force_n(UNWORN_REFERENCE_M + mid.offset_m, 0.0, 0.0)
            / own(&h).force_n(UNWORN_REFERENCE_M, 0.0, 0.0);
        assert!((ratio - 0.6).abs() < 1e-12, "{ratio}");
        assert_eq!(mid.offset_m, -h.profile.groove_depth_m);
        let leaving = h.profile.law(&h, 3, 2, 0.9).unwrap();
        println!("trichord's last string at 0.9: {leaving:?}");
        assert!(leaving.stiffness_n_m_p < mid.stiffness_n_m_p);
        assert!(leaving.offset_m > mid.offset_m);
    }

    #[test]
    fn profiles_that_cannot_hold_a_unison_are_refused() {
        let ok = DEFAULT_PROFILE;
        assert_eq!(ok.check(), Ok(()));
        let cases = [
            (
                FeltProfile {
                    groove_width_m: 3e-3,
                    ..ok
                },
                "groove_width_m",
            ),
            (
                FeltProfile {
                    overhang_m: 1e-3,
                    ..ok
                },
                "overhang_m",
            ),
            (
                FeltProfile {
                    overhang_m: 3e-3,
                    ..ok
                },
                "overhang_m",
            ),
            (
                FeltProfile {
                    overhang_m: 1.3e-3,
                    shoulder_m: 1e-3,
                    ..ok
                },
                "overhang_m",
            ),
            (
                FeltProfile {
                    unworn_stiffness_ratio: 1.5,
                    ..ok
                },
                "unworn_stiffness_ratio",
            ),
            (
                FeltProfile {
                    string_spacing_m: 0.0,
                    ..ok
                },
                "string_spacing_m",
            ),
        ];
        for (profile, field) in cases {
            let e = profile.check().unwrap_err();
            println!("{field}: {} — {}", e.value, e.allowed);
            assert_eq!(e.field, field);
        }
    }
}
