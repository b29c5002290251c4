//! What the audio stage needs from a preset: the output rate, the listener and the full scale,
//! and when a voice falls silent.

/// How a sound of `channels` channels is called in messages: `mono` or `stereo`.
pub fn channel_layout(channels: u16) -> &'static str {
    if channels == 2 {
        "stereo"
    } else {
        "mono"
    }
}

/// The output gain a front end may set (dB): from near silence to a quiet keyboard brought up
/// into the soft clipper's knee.
pub const GAIN_DB: std::ops::RangeInclusive<f64> = -60.0..=12.0;

/// The sound pressure heard as full scale once `gain_db` is applied before the soft clipper: a
/// gain of `g` dB is a full scale `g` dB lower.
pub fn full_scale_with_gain(full_scale_pa: f64, gain_db: f64) -> f64 {
    full_scale_pa * 10f64.powf(-gain_db / 20.0)
}

/// Output stage settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutputSettings {
    /// Output sample rate (Hz); the instrument's internal rate must be an integer multiple.
    pub rate_hz: f64,
    /// Air density and listener distance give `rho0 / (4 pi r)` (kg/m^4).
    pub air_density_kg_m3: f64,
    pub distance_m: f64,
    /// Sound pressure at digital full scale (Pa).
    pub full_scale_pa: f64,
    /// Channels of the sound: 1 (mono: both engine channels hear one listener) or 2 (a stereo
    /// pair of listeners, left and right).
    pub channels: u16,
    /// Voices whose strings hold less energy than this stop being simulated (J).
    pub silence_j: f64,
}
