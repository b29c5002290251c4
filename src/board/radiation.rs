//! How each board mode radiates to a listener: the Rayleigh integral of the board as a baffled
//! plate (DESIGN.md §1.7). A mode with deflection `phi_m(x)` per unit modal coordinate, moving
//! with acceleration `qdd_m` at angular frequency `omega`, gives at the listener `r`
//! `p = rho0 / (2 pi) qdd_m D_m(omega)`, `D_m(omega) = ∫ phi_m(x) e^{-i k (R - R0)} / R dA`,
//! `R = |r - x|`, `k = omega / c`. The common delay `R0 / c` (to the nearest point of the board)
//! is left out, so that the sound is not late; what remains is each mode's strength and phase at
//! the listener. At `k R << 1` and a far listener `D_m` is the net volume over the distance, the
//! monopole (`volume_m2_per_sqrt_kg / r`), and the baffle's half-space doubles it.

use super::{Basis1d, BoardSpec, SolvedBoard};
use crate::engine::physics::soundboard::Listener;
use faer::c64;
use serde::Deserialize;

/// Speed of sound in air (m/s), 20 °C.
pub const SOUND_SPEED_M_S: f64 = 343.0;

/// The grid on which the integral is summed (m): a quarter of the wavelength in air at 7 kHz
/// (4.9 cm), and a fifth of the board's shortest bending wavelength there (about 5 cm across
/// the grain).
pub const GRID_SPACING_M: f64 = 0.01;

/// Every mode's Rayleigh integral at its own frequency, at each of `spec`'s listeners, into
/// `solved`'s modes.
pub fn listen(spec: &BoardSpec, solved: &mut SolvedBoard) {
    if spec.listeners.is_empty() {
        return;
    }
    let grid = BoardGrid::new(spec, solved, GRID_SPACING_M);
    let modes = &mut solved.modes;
    modes.listeners = spec
        .listeners
        .iter()
        .map(|l| {
            let r = grid.distances_m(l.position_m);
            let d: Vec<c64> = (0..modes.freq_hz.len())
                .map(|m| grid.rayleigh(m, &r, modes.freq_hz[m]))
                .collect();
            Listener {
                name: l.name.clone(),
                rayleigh_re: d.iter().map(|x| x.re).collect(),
                rayleigh_im: d.iter().map(|x| x.im).collect(),
            }
        })
        .collect();
}

/// A listener (or microphone) over the board.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ListenerSpec {
    pub name: String,
    /// `[x, y, z]` (m): x along the grain, y across it (the board's coordinates), z above the
    /// plate.
    pub position_m: [f64; 3],
}

/// The board's modes sampled on a grid of the plate (every `spacing` in x and y, the edges
/// included), with each point's trapezoid weight.
#[derive(Debug, Clone)]
pub struct BoardGrid {
    pub points_m: Vec<[f64; 2]>,
    pub area_m2: Vec<f64>,
    /// Per mode of the solved board, its deflection at every point (m per unit modal coordinate,
    /// 1/sqrt(kg)).
    pub deflection: Vec<Vec<f64>>,
}

impl BoardGrid {
    /// Sample `solved`'s modes (made from `spec`) every `spacing_m` or closer.
    pub fn new(spec: &BoardSpec, solved: &SolvedBoard, spacing_m: f64) -> BoardGrid {
        let p = &spec.plate;
        let axis = |len: f64, terms: usize| {
            let basis = Basis1d {
                len,
                terms,
                edges: p.edges,
            };
            let n = ((len / spacing_m).ceil() as usize).max(2);
            let h = len / n as f64;
            let at: Vec<f64> = (0..=n).map(|s| s as f64 * h).collect();
            let weight: Vec<f64> = (0..=n)
                .map(|s| if s == 0 || s == n { 0.5 * h } else { h })
                .collect();
            let values: Vec<Vec<f64>> = at
                .iter()
                .map(|&x| (0..terms).map(|i| basis.eval(i, x)[0]).collect())
                .collect();
            (at, weight, values)
        };
        let (nx, ny) = (spec.basis.terms_x, spec.basis.terms_y);
        let (xs, wx, bx) = axis(p.width_m, nx);
        let (ys, wy, by) = axis(p.length_m, ny);
        let mut points_m = Vec::with_capacity(xs.len() * ys.len());
        let mut area_m2 = Vec::with_capacity(points_m.capacity());
        for (x, a) in xs.iter().zip(&wx) {
            for (y, b) in ys.iter().zip(&wy) {
                points_m.push([*x, *y]);
                area_m2.push(a * b);
            }
        }
        let c = &solved.coefficients;
        let deflection = (0..c.ncols())
            .map(|m| {
                // Along y first: t[i][gy] = sum_j c_ij Y_j(y_gy); then along x.
                let t: Vec<Vec<f64>> = (0..nx)
                    .map(|i| {
                        by.iter()
                            .map(|yv| (0..ny).map(|j| c[(i * ny + j, m)] * yv[j]).sum())
                            .collect()
                    })
                    .collect();
                let mut w = Vec::with_capacity(points_m.len());
                for xv in &bx {
                    for g in 0..ys.len() {
                        w.push((0..nx).map(|i| xv[i] * t[i][g]).sum());
                    }
                }
                w
            })
            .collect();
        BoardGrid {
            points_m,
            area_m2,
            deflection,
        }
    }

    /// Distance (m) from `listener` to each grid point, and the least of them.
    pub fn distances_m(&self, listener: [f64; 3]) -> (Vec<f64>, f64) {
        let r: Vec<f64> = self
            .points_m
            .iter()
            .map(|[x, y]| {
                let (dx, dy) = (listener[0] - x, listener[1] - y);
                (dx * dx + dy * dy + listener[2] * listener[2]).sqrt()
            })
            .collect();
        let nearest = r.iter().copied().fold(f64::INFINITY, f64::min);
        (r, nearest)
    }

    /// `D_m(omega)` (module notes) of mode `m` (m per sqrt(kg)) for a listener at distances `r`
    /// (from [`BoardGrid::distances_m`]) at `freq_hz`.
    pub fn rayleigh(&self, m: usize, r: &(Vec<f64>, f64), freq_hz: f64) -> c64 {
        let k = 2.0 * std::f64::consts::PI * freq_hz / SOUND_SPEED_M_S;
        let (dist, nearest) = r;
        let (mut re, mut im) = (0.0, 0.0);
        for ((w, a), rr) in self.deflection[m].iter().zip(&self.area_m2).zip(dist) {
            let g = w * a / rr;
            let (s, c) = (k * (rr - nearest)).sin_cos();
            re += g * c;
            im -= g * s;
        }
        c64::new(re, im)
    }
}
