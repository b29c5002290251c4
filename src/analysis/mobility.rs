//! Driving-point mobility curves of a modal soundboard (paper Eq. 4, Figure 2).

use crate::engine::physics::soundboard::{BridgePoint, SoundboardModes};
use std::f64::consts::PI;

/// The six distinct terms of the symmetric 3×3 mobility, in the order of `TERMS`.
pub const TERMS: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];
/// Their names (response–excitation, directions T, L, P).
pub const TERM_NAMES: [&str; 6] = ["TT", "TL", "TP", "LL", "LP", "PP"];

/// |Y| of the six terms on a log-spaced frequency grid.
#[derive(Debug, Clone)]
pub struct MobilityCurves {
    pub freq_hz: Vec<f64>,
    /// `magnitude[term][k]` (m/(N s)).
    pub magnitude: [Vec<f64>; 6],
}

/// |Y_ij(f)| at `point` for `points` log-spaced frequencies from `f_lo` to `f_hi`.
pub fn mobility_curves(
    board: &SoundboardModes,
    point: &BridgePoint,
    f_lo: f64,
    f_hi: f64,
    points: usize,
) -> MobilityCurves {
    let freq_hz: Vec<f64> = (0..points)
        .map(|k| f_lo * (f_hi / f_lo).powf(k as f64 / (points - 1) as f64))
        .collect();
    let mut magnitude: [Vec<f64>; 6] = Default::default();
    for &f in &freq_hz {
        let y = board.mobility(point, 2.0 * PI * f);
        for (t, &(i, j)) in TERMS.iter().enumerate() {
            magnitude[t].push(y[i][j][0].hypot(y[i][j][1]));
        }
    }
    MobilityCurves { freq_hz, magnitude }
}

/// 1/3-octave band levels (dB re 1 m/(N s)) of a magnitude curve sampled on a log grid: the mean of
/// |Y|² over the grid points in each band. Returns `(band centre Hz, level dB)` for full bands.
pub fn band_levels_db(freq_hz: &[f64], magnitude: &[f64]) -> Vec<(f64, f64)> {
    let (f_lo, f_hi) = (freq_hz[0], freq_hz[freq_hz.len() - 1]);
    let mut out = Vec::new();
    // Preferred centres 1000 · 2^(k/3).
    for k in -20..=12 {
        let fc = 1000.0 * 2f64.powf(k as f64 / 3.0);
        let (lo, hi) = (fc * 2f64.powf(-1.0 / 6.0), fc * 2f64.powf(1.0 / 6.0));
        if lo < f_lo || hi > f_hi {
            continue;
        }
        let vals: Vec<f64> = freq_hz
            .iter()
            .zip(magnitude)
            .filter(|(f, _)| **f >= lo && **f < hi)
            .map(|(_, m)| m * m)
            .collect();
        if !vals.is_empty() {
            out.push((
                fc,
                10.0 * (vals.iter().sum::<f64>() / vals.len() as f64).log10(),
            ));
        }
    }
    out
}
