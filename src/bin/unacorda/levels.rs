//! The flags `play` and `render` share with the plugin's parameters: the output gain and the
//! velocity curve.

use anyhow::{bail, Result};
use unacorda::config::output::GAIN_DB;
use unacorda::midi::VELOCITY_CURVE;

/// Output gain and velocity curve.
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct Levels {
    /// Output gain (dB), -60 to 12, applied before the soft clipper (as the plugin's "Output
    /// gain"); raise a quiet keyboard, lower a loud one.
    #[arg(
        long,
        default_value_t = 0.0,
        value_name = "DB",
        allow_negative_numbers = true
    )]
    pub gain_db: f64,
    /// Velocity curve exponent, 0.25 to 4 (the plugin's "Velocity curve"): MIDI velocity v
    /// becomes 127 (v/127)^exponent before the hammer's speed is found from it; above 1 a harder
    /// touch is needed for the same loudness, below 1 a lighter one.
    #[arg(
        long,
        default_value_t = 1.0,
        value_name = "EXP",
        allow_negative_numbers = true
    )]
    pub velocity_curve: f64,
}

impl Levels {
    /// Refuse a value out of range, naming the flag and the range.
    pub fn check(&self) -> Result<()> {
        if !GAIN_DB.contains(&self.gain_db) {
            bail!(
                "--gain-db {}: expected a gain in [{}, {}] dB",
                self.gain_db,
                GAIN_DB.start(),
                GAIN_DB.end()
            );
        }
        if !VELOCITY_CURVE.contains(&self.velocity_curve) {
            bail!(
                "--velocity-curve {}: expected an exponent in [{}, {}]",
                self.velocity_curve,
                VELOCITY_CURVE.start(),
                VELOCITY_CURVE.end()
            );
        }
        Ok(())
    }
}
