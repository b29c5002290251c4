//! What the reduced board radiates (DESIGN.md §1.7). The paper's reduction (§2.2) keeps, per
//! 1/12 octave and direction, the one mode that moves most at its points; a kept mode radiating
//! by its own Rayleigh integral leaves out what the dropped modes beside it carried from the
//! bridges to the listener. At ζ = 0.03 a mode's half-power band is 6 % of its frequency, a
//! twelfth of an octave, and the full board holds several modes in it from a few hundred hertz
//! up: they overlap, and what reaches a listener from a key is their sum. Through the kept modes
//! alone, a key whose partial falls where they cancel at the listener goes quiet (D6, C#5 and
//! C#6 were 8–14 dB under their neighbours: docs/realism.md, "The reduced board's radiation").
//!
//! Here the kept modes below `below_hz` keep their frequencies, damping and shapes at the
//! bridges — their coupling to the strings is the paper's — and radiate what the full board's
//! modes radiate for forces at the bridges: their weights, one set for every key, are the
//! least-squares fit over frequency (`[f_min, below_hz)`) and over every bridge point (T, L and
//! P; each point's rows scaled by its full transfer's norm, so that every key counts alike) of
//! the transfer from a unit force to the pressure at a listener, as the engines radiate it
//! ([`SoundboardModes::radiation_weights`]: `p = rho0 / (2 pi) sum_m (Re D_m qdd_m - w_m Im D_m qd_m)`):
//! ```text
//! H(w) = sum_m phi_m(x) (-w^2 Re D_m - i w w_m Im D_m) / (w_m^2 - w^2 + 2 i zeta_m w_m w)    (rho0 / (2 pi) left out)
//! ```
//! with the full board's `D_m` their Rayleigh integrals ([`super::radiation`]) and the kept
//! ones' the unknowns, returned as their equivalent `D_m`. A key is heard at its partials: each
//! point's rows within [`PARTIAL_BAND`] of its key's partials count [`PARTIAL_WEIGHT`] times those
//! between them (fitted alike at every frequency, C#6 had its one partial below 1.5 kHz in 2 % of
//! its rows, and it came out 18 dB under the full board's at `above`). The kept modes at and above
//! `below_hz` radiate by their own integrals (the fit's target leaves their part out); both
//! engines read the same integrals.

use crate::engine::physics::soundboard::{Listener, SoundboardModes};
use faer::linalg::solvers::Solve;
use faer::{Mat, Side};
use std::f64::consts::PI;

/// Ratio of neighbouring frequencies of the fit's grid: a sixth of a mode's half-power band at
/// ζ = 0.03.
const GRID_RATIO: f64 = 1.01;

/// Tikhonov weight, relative to the normal matrix's mean diagonal: keeps a mode the points
/// barely drive from taking an arbitrary weight.
const RIDGE: f64 = 1e-4;

/// `x + iy`.
type C = (f64, f64);

/// The listeners of `full` for its modes `kept` (indices, ascending, as the reduction keeps
/// them): below `below_hz` the fitted Rayleigh integrals, at and above each mode's own.
pub fn fit(
    full: &SoundboardModes,
    kept: &[usize],
    below_hz: f64,
) -> Result<Vec<Listener>, super::BoardError> {
    let f_min_hz = full.freq_hz.iter().copied().fold(f64::INFINITY, f64::min);
    let (low, high): (Vec<usize>, Vec<usize>) =
        kept.iter().partition(|&&m| full.freq_hz[m] < below_hz);
    let grid = grid(f_min_hz, below_hz);
    // The target: the full board without the kept modes that radiate by their own integrals.
    let heard: Vec<usize> = (0..full.len())
        .filter(|m| high.binary_search(m).is_err())
        .collect();
    let mut listeners = Vec::new();
    for l in 0..full.listeners.len() {
        let own: Vec<C> = full.listeners[l]
            .rayleigh_re
            .iter()
            .copied()
            .zip(full.listeners[l].rayleigh_im.iter().copied())
            .collect();
        let mut normal = Normal::new(2 * low.len());
        for p in &full.points {
            let f0_hz = fundamental_hz(&p.name);
            let rows: Vec<(Vec<C>, C, f64)> = (0..3)
                .flat_map(|d| grid.iter().map(move |&w| (d, w)))
                .map(|(d, w)| {
                    let shape = &p.shape[d];
                    let target = transfer(full, &heard, shape, &own, w);
                    let weight = partial_weight(f0_hz, w / (2.0 * PI));
                    (columns(full, &low, shape, w), target, weight)
                })
                .collect();
            let norm = rows
                .iter()
                .map(|(_, t, g)| g * g * abs2(*t))
                .sum::<f64>()
                .sqrt();
            let scale = if norm > 0.0 { 1.0 / norm } else { 0.0 };
            for (cols, target, weight) in &rows {
                normal.add(cols, *target, scale * weight);
            }
        }
        let mut d = own;
        for (&m, fitted) in low.iter().zip(normal.solve()?) {
            d[m] = fitted;
        }
        listeners.push(Listener {
            name: full.listeners[l].name.clone(),
            rayleigh_re: kept.iter().map(|&m| d[m].0).collect(),
            rayleigh_im: kept.iter().map(|&m| d[m].1).collect(),
        });
    }
    Ok(listeners)
}

/// How much more a row counts where the point's key has a partial ([`partial_weight`]), in
/// amplitude: between its partials a row still counts, for the attack's broadband knock and the
/// sympathetic partials (10 left C#6 at −7.8 dB re A3–A4 struck, 30 −4.6: docs/realism.md).
const PARTIAL_WEIGHT: f64 = 30.0;

/// Half-width of the band around each partial `n f0` that [`PARTIAL_WEIGHT`] covers, relative:
/// a board mode's half-power band at ζ = 0.03, and the stretch of a treble key's partials.
const PARTIAL_BAND: f64 = 0.04;

/// The equal-tempered fundamental (Hz) of the key a bridge point is named for (`A0`–`C8`);
/// `None` for another name.
fn fundamental_hz(name: &str) -> Option<f64> {
    (1..=88)
        .find(|&k| super::key_name(k) == name)
        .map(|k| 440.0 * 2f64.powf((k as f64 - 49.0) / 12.0))
}

/// A row's weight at `f_hz` for a point whose key sounds `f0_hz`: [`PARTIAL_WEIGHT`] within
/// [`PARTIAL_BAND`] of one of its (harmonic) partials, 1 elsewhere and at a point of no key.
fn partial_weight(f0_hz: Option<f64>, f_hz: f64) -> f64 {
    match f0_hz {
        Some(f0) => {
            let n = (f_hz / f0).round().max(1.0);
            if (f_hz / (n * f0) - 1.0).abs() <= PARTIAL_BAND {
                PARTIAL_WEIGHT
            } else {
                1.0
            }
        }
        None => 1.0,
    }
}

/// The grid `[lo, hi)` at [`GRID_RATIO`] (angular frequencies).
fn grid(lo_hz: f64, hi_hz: f64) -> Vec<f64> {
    std::iter::successors(Some(lo_hz), |f| Some(f * GRID_RATIO))
        .take_while(|&f| f < hi_hz)
        .map(|f| 2.0 * PI * f)
        .collect()
}

/// Mode `m`'s pressure per unit force and shape at `w`, per unit `Re D_m` and per unit `Im D_m`:
/// `-w^2 G_m(w)` and `-i w w_m G_m(w)`, `G_m = 1 / (w_m^2 - w^2 + 2 i zeta_m w_m w)`.
fn unit(full: &SoundboardModes, m: usize, w: f64) -> (C, C) {
    let wm = 2.0 * PI * full.freq_hz[m];
    let (re, im) = (wm * wm - w * w, 2.0 * full.damping_ratio[m] * wm * w);
    let den = re * re + im * im;
    let g = (re / den, -im / den);
    ((-w * w * g.0, -w * w * g.1), (w * wm * g.1, -w * wm * g.0))
}

/// The pressure at a listener per unit force at a bridge point, up to `rho0 / (4 pi r_ref)`, at
/// `freq_hz`: `board`'s modes with the weights the engines read
/// ([`SoundboardModes::radiation_weights`]: `a_m` on `qd_m`, `b_m` on `q_m`, so
/// `p = rho0 / (4 pi r_ref) sum_m (a_m qdd_m + b_m qd_m)`) driven through `shape` (one
/// direction at the point).
pub fn pressure_per_force(
    board: &SoundboardModes,
    weights: &[Vec<f64>; 2],
    shape: &[f64],
    freq_hz: f64,
) -> (f64, f64) {
    // a_m qdd_m is a_m times the unit of Re D; b_m qd_m is -b_m / w_m times that of Im D.
    let d: Vec<C> = (0..board.len())
        .map(|m| {
            let wm = 2.0 * PI * board.freq_hz[m];
            (weights[0][m], -weights[1][m] / wm)
        })
        .collect();
    let all: Vec<usize> = (0..board.len()).collect();
    transfer(board, &all, shape, &d, 2.0 * PI * freq_hz)
}

/// The transfer through `modes` with Rayleigh integrals `d` per mode of `full`, at shape
/// `shape`.
fn transfer(full: &SoundboardModes, modes: &[usize], shape: &[f64], d: &[C], w: f64) -> C {
    modes.iter().fold((0.0, 0.0), |acc, &m| {
        let (ur, ui) = unit(full, m, w);
        let (re, im) = d[m];
        let s = shape[m];
        (
            acc.0 + s * (re * ur.0 + im * ui.0),
            acc.1 + s * (re * ur.1 + im * ui.1),
        )
    })
}

/// The fit's columns at `w`: per mode of `modes`, its `Re D` and `Im D`.
fn columns(full: &SoundboardModes, modes: &[usize], shape: &[f64], w: f64) -> Vec<C> {
    modes
        .iter()
        .flat_map(|&m| {
            let (ur, ui) = unit(full, m, w);
            let s = shape[m];
            [(s * ur.0, s * ur.1), (s * ui.0, s * ui.1)]
        })
        .collect()
}

fn abs2(x: C) -> f64 {
    x.0 * x.0 + x.1 * x.1
}

/// Normal equations of a real least-squares problem with complex rows.
struct Normal {
    ata: Mat<f64>,
    atb: Mat<f64>,
}

impl Normal {
    fn new(n: usize) -> Normal {
        Normal {
            ata: Mat::zeros(n, n),
            atb: Mat::zeros(n, 1),
        }
    }

    /// Add the row `cols · x ≈ target`, both scaled by `scale`.
    fn add(&mut self, cols: &[C], target: C, scale: f64) {
        let s2 = scale * scale;
        for (i, ci) in cols.iter().enumerate() {
            self.atb[(i, 0)] += s2 * (ci.0 * target.0 + ci.1 * target.1);
            for (j, cj) in cols.iter().enumerate().take(i + 1) {
                self.ata[(i, j)] += s2 * (ci.0 * cj.0 + ci.1 * cj.1);
            }
        }
    }

    /// The solution, two unknowns per mode in the order of the columns.
    fn solve(mut self) -> Result<Vec<(f64, f64)>, super::BoardError> {
        let n = self.ata.nrows();
        if n == 0 {
            return Ok(vec![]);
        }
        let mean = (0..n).map(|i| self.ata[(i, i)]).sum::<f64>() / n as f64;
        for i in 0..n {
            self.ata[(i, i)] += RIDGE * mean.max(f64::MIN_POSITIVE);
            for j in 0..i {
                self.ata[(j, i)] = self.ata[(i, j)];
            }
        }
        let x = self
            .ata
            .llt(Side::Lower)
            .map_err(|_| super::BoardError::RadiationFit)?
            .solve(&self.atb);
        Ok((0..n / 2)
            .map(|i| (x[(2 * i, 0)], x[(2 * i + 1, 0)]))
            .collect())
    }
}
