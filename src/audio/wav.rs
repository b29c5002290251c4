//! WAV output (32-bit float, mono) through hound.

use std::path::Path;

/// Write `samples` (full scale ±1) as a 32-bit float mono WAV at `rate_hz`.
pub fn write_f32(path: &Path, rate_hz: u32, samples: &[f32]) -> Result<(), hound::Error> {
    let spec = hound::WavSpec {
        channels: 1,
        sample_rate: rate_hz,
        bits_per_sample: 32,
        sample_format: hound::SampleFormat::Float,
    };
    let mut w = hound::WavWriter::create(path, spec)?;
    for &s in samples {
        w.write_sample(s)?;
    }
    w.finalize()
}
