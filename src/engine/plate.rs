//! Generator of the reduced soundboard asset from a simply-supported orthotropic plate.
//!
//! The plate has Table 1's dimensions and Sitka-spruce properties, grain along x (E1). Its modes
//! have a closed form (Leissa, *Vibration of Plates*, §11.3):
//! `omega_mn^2 = pi^4 / (rho h) [D1 (m/a)^4 + 2 H (m/a)^2 (n/b)^2 + D2 (n/b)^4]`,
//! `D1 = E1 h^3 / 12(1 - nu12 nu21)`, `D2 = E2 h^3 / 12(1 - nu12 nu21)`, `H = nu12 D2 + 2 G12 h^3/12`,
//! `w_mn = 2 / sqrt(rho h a b) sin(m pi x / a) sin(n pi y / b)` (mass-normalised).
//! The bridge top sits `lever_m` above the mid-plane; a rotation of the plate under the bridge
//! moves it in the plane by `-lever ∇w`, which gives the L (along the string) and P (across it)
//! components. The reduction keeps, in each 1/12-octave band of 20–7000 Hz and in each direction,
//! the mode with the largest driving-point peak `phi^2 / (2 zeta omega)` (the paper's rule, §2.2).
//!
//! The clamped, ribbed board with bridges (issue 3) replaces this generator's physics; the asset
//! format and the reduction stay.

use super::soundboard::{BridgePoint, SoundboardModes};
use std::f64::consts::PI;

/// Inputs of the plate model (SI units).
#[derive(Debug, Clone, PartialEq)]
pub struct PlateParams {
    /// Extent along the grain, x (m). Table 1: width 1.37 m.
    pub width_m: f64,
    /// Extent across the grain, y (m). Table 1: length 1.0 m.
    pub length_m: f64,
    pub thickness_m: f64,
    pub density_kg_m3: f64,
    /// Young's modulus along the grain E1 (Pa).
    pub e1_pa: f64,
    /// Young's modulus across the grain E2 (Pa).
    pub e2_pa: f64,
    pub nu12: f64,
    /// In-plane shear modulus G12 (Pa).
    pub g12_pa: f64,
    pub damping_ratio: f64,
    /// Height of the string contact above the plate's mid-plane (bridge height + h/2) (m).
    pub lever_m: f64,
    /// Bridge points: name, x (m), y (m), string direction measured from the grain (deg).
    pub points: Vec<(String, f64, f64, f64)>,
    /// Band limits of the reduction (Hz).
    pub f_min_hz: f64,
    pub f_max_hz: f64,
}

impl Default for PlateParams {
    /// Table 1 of the paper; bridge point and height are this project's assumptions.
    fn default() -> Self {
        PlateParams {
            width_m: 1.37,
            length_m: 1.0,
            thickness_m: 0.008,
            density_kg_m3: 488.0,
            e1_pa: 12.7e9,
            e2_pa: 1.04e9,
            nu12: 0.37,
            g12_pa: 1.0e9,
            damping_ratio: 0.03,
            // 25 mm bass bridge + half the 8 mm board.
            lever_m: 0.029,
            // The C2 string crosses the (bass) bridge off the plate's symmetry lines, its direction
            // 60° from the grain (strings run obliquely to the grain in grands).
            points: vec![("C2".to_string(), 0.41, 0.27, 60.0)],
            f_min_hz: 20.0,
            f_max_hz: 7000.0,
        }
    }
}

/// All plate modes below `f_max_hz`, before reduction.
#[derive(Debug, Clone)]
pub struct PlateModes {
    pub index: Vec<(usize, usize)>,
    pub modes: SoundboardModes,
}

impl PlateParams {
    /// Flexural rigidities `(D1, D2, H)` (N m).
    pub fn rigidities(&self) -> (f64, f64, f64) {
        let h3 = self.thickness_m.powi(3);
        let nu21 = self.nu12 * self.e2_pa / self.e1_pa;
        let den = 12.0 * (1.0 - self.nu12 * nu21);
        let d1 = self.e1_pa * h3 / den;
        let d2 = self.e2_pa * h3 / den;
        let h = self.nu12 * d2 + 2.0 * self.g12_pa * h3 / 12.0;
        (d1, d2, h)
    }

    /// Natural frequency of mode (m, n) (Hz).
    pub fn freq_hz(&self, m: usize, n: usize) -> f64 {
        let (d1, d2, h) = self.rigidities();
        let (a, b) = (self.width_m, self.length_m);
        let (km, kn) = (m as f64 / a, n as f64 / b);
        let rho_h = self.density_kg_m3 * self.thickness_m;
        let w2 =
            PI.powi(4) / rho_h * (d1 * km.powi(4) + 2.0 * h * km * km * kn * kn + d2 * kn.powi(4));
        w2.sqrt() / (2.0 * PI)
    }

    /// Every mode with frequency below `f_max_hz`, sorted by frequency.
    pub fn all_modes(&self) -> PlateModes {
        let (a, b) = (self.width_m, self.length_m);
        let rho_h = self.density_kg_m3 * self.thickness_m;
        let amp = 2.0 / (rho_h * a * b).sqrt();
        let mut list: Vec<(f64, usize, usize)> = Vec::new();
        for m in 1.. {
            if self.freq_hz(m, 1) > self.f_max_hz {
                break;
            }
            for n in 1.. {
                let f = self.freq_hz(m, n);
                if f > self.f_max_hz {
                    break;
                }
                list.push((f, m, n));
            }
        }
        list.sort_by(|x, y| x.0.total_cmp(&y.0));
        let volume = |m: usize, n: usize| -> f64 {
            if m % 2 == 1 && n % 2 == 1 {
                amp * (2.0 * a / (m as f64 * PI)) * (2.0 * b / (n as f64 * PI))
            } else {
                0.0
            }
        };
        let points = self
            .points
            .iter()
            .map(|(name, x, y, angle_deg)| {
                let (s, c) = angle_deg.to_radians().sin_cos();
                let mut shape = [vec![], vec![], vec![]];
                for &(_, m, n) in &list {
                    let (kx, ky) = (m as f64 * PI / a, n as f64 * PI / b);
                    let w = amp * (kx * x).sin() * (ky * y).sin();
                    let dwdx = amp * kx * (kx * x).cos() * (ky * y).sin();
                    let dwdy = amp * ky * (kx * x).sin() * (ky * y).cos();
                    shape[0].push(w);
                    // Along the string (c, s) and across it (-s, c), in the board's plane.
                    shape[1].push(-self.lever_m * (c * dwdx + s * dwdy));
                    shape[2].push(-self.lever_m * (-s * dwdx + c * dwdy));
                }
                BridgePoint {
                    name: name.clone(),
                    shape,
                }
            })
            .collect();
        PlateModes {
            index: list.iter().map(|&(_, m, n)| (m, n)).collect(),
            modes: SoundboardModes {
                freq_hz: list.iter().map(|l| l.0).collect(),
                damping_ratio: vec![self.damping_ratio; list.len()],
                volume_m2_per_sqrt_kg: list.iter().map(|&(_, m, n)| volume(m, n)).collect(),
                points,
            },
        }
    }
}

/// The paper's reduction (§2.2): in each 1/12-octave band from `f_min_hz` to `f_max_hz` and in each
/// direction, keep the mode whose driving-point peak `phi_d^2 / (2 zeta omega)` at `point` is the
/// largest. Modes chosen in several directions are kept once.
pub fn reduce(
    full: &SoundboardModes,
    point: &str,
    f_min_hz: f64,
    f_max_hz: f64,
) -> SoundboardModes {
    let p = full.point(point).expect("reduction point exists");
    let n_bands = (12.0 * (f_max_hz / f_min_hz).log2()).ceil() as usize;
    let mut keep = vec![false; full.len()];
    for band in 0..n_bands {
        let lo = f_min_hz * 2f64.powf(band as f64 / 12.0);
        let hi = (f_min_hz * 2f64.powf((band + 1) as f64 / 12.0)).min(f_max_hz);
        for d in 0..3 {
            let best = (0..full.len())
                .filter(|&k| full.freq_hz[k] >= lo && full.freq_hz[k] < hi)
                .max_by(|&i, &j| {
                    let peak = |k: usize| {
                        p.shape[d][k].powi(2) / (full.damping_ratio[k] * full.freq_hz[k])
                    };
                    peak(i).total_cmp(&peak(j))
                });
            if let Some(k) = best {
                keep[k] = true;
            }
        }
    }
    let pick = |v: &Vec<f64>| -> Vec<f64> {
        v.iter()
            .zip(&keep)
            .filter(|(_, &k)| k)
            .map(|(x, _)| *x)
            .collect()
    };
    SoundboardModes {
        freq_hz: pick(&full.freq_hz),
        damping_ratio: pick(&full.damping_ratio),
        volume_m2_per_sqrt_kg: pick(&full.volume_m2_per_sqrt_kg),
        points: full
            .points
            .iter()
            .map(|bp| BridgePoint {
                name: bp.name.clone(),
                shape: [pick(&bp.shape[0]), pick(&bp.shape[1]), pick(&bp.shape[2])],
            })
            .collect(),
    }
}

/// Generate the reduced asset text for `params`, with a header saying how it was made.
pub fn generate_asset(params: &PlateParams, command: &str) -> (SoundboardModes, String) {
    let full = params.all_modes();
    let reduced = reduce(
        &full.modes,
        &params.points[0].0,
        params.f_min_hz,
        params.f_max_hz,
    );
    let header = vec![
        "unacorda reduced soundboard model (DESIGN.md §1.3, format in src/engine/soundboard.rs)".to_string(),
        format!("regenerate with: {command}"),
        format!(
            "simply-supported orthotropic plate {} m x {} m x {} m, rho {} kg/m^3, E1 {:.3e} Pa, E2 {:.3e} Pa, nu12 {}, G12 {:.3e} Pa (paper Table 1)",
            params.width_m, params.length_m, params.thickness_m, params.density_kg_m3, params.e1_pa, params.e2_pa, params.nu12, params.g12_pa
        ),
        format!("bridge lever arm {} m; points (name x_m y_m string_angle_deg): {}", params.lever_m,
            params.points.iter().map(|(n, x, y, a)| format!("{n} {x} {y} {a}")).collect::<Vec<_>>().join(", ")),
        format!(
            "{} plate modes below {} Hz; the {}-{} Hz bands keep {} (dominant mode per 1/12 octave and direction at {})",
            full.modes.len(), params.f_max_hz, params.f_min_hz, params.f_max_hz, reduced.len(), params.points[0].0
        ),
    ];
    let text = reduced.to_text(&header);
    (reduced, text)
}
