//! The reduced modal soundboard (paper Eq. 4–5).
//!
//! The board is a set of mass-normalised modes with natural frequency, damping ratio, net volume
//! (for radiation, DESIGN.md §1.7) and, at each named bridge point, the three mode-shape components
//! T, L, P. The driving-point mobility at a point is
//! `Y_ij(omega) = sum_k i omega phi_i,k phi_j,k / (omega_k^2 - omega^2 + 2 i zeta_k omega_k omega)`.

use super::Oscillator;
use std::f64::consts::PI;

/// A reduced modal soundboard, structure-of-arrays.
#[derive(Debug, Clone, PartialEq)]
pub struct SoundboardModes {
    pub freq_hz: Vec<f64>,
    pub damping_ratio: Vec<f64>,
    /// Net volume displacement per unit modal coordinate (m^2/sqrt(kg)).
    pub volume_m2_per_sqrt_kg: Vec<f64>,
    /// Bridge points, each with its mode shapes.
    pub points: Vec<BridgePoint>,
}

/// Mode-shape components at one bridge point (Eq. 5: `Phi_b = [phi_T; phi_L; phi_P]`).
#[derive(Debug, Clone, PartialEq)]
pub struct BridgePoint {
    pub name: String,
    /// `[phi_T, phi_L, phi_P]`, each one value per mode (1/sqrt(kg)).
    pub shape: [Vec<f64>; 3],
}

impl SoundboardModes {
    /// Board mode `k` (0-based) as an oscillator (Eq. 4).
    pub fn oscillator(&self, k: usize) -> Oscillator {
        Oscillator {
            omega_rad_s: 2.0 * PI * self.freq_hz[k],
            damping_ratio: self.damping_ratio[k],
        }
    }

    pub fn len(&self) -> usize {
        self.freq_hz.len()
    }

    pub fn is_empty(&self) -> bool {
        self.freq_hz.is_empty()
    }

    /// The bridge point called `name`.
    pub fn point(&self, name: &str) -> Option<&BridgePoint> {
        self.points.iter().find(|p| p.name == name)
    }

    /// Driving-point mobility matrix at `point` for angular frequency `omega` (m/(N s)),
    /// as `[re, im]` per entry, directions T, L, P (Eq. 4).
    pub fn mobility(&self, point: &BridgePoint, omega: f64) -> [[[f64; 2]; 3]; 3] {
        let mut y = [[[0.0; 2]; 3]; 3];
        for k in 0..self.len() {
            let wk = 2.0 * PI * self.freq_hz[k];
            // i w / (wk^2 - w^2 + 2 i zeta wk w)
            let (re_d, im_d) = (
                wk * wk - omega * omega,
                2.0 * self.damping_ratio[k] * wk * omega,
            );
            let den = re_d * re_d + im_d * im_d;
            let (re, im) = (omega * im_d / den, omega * re_d / den);
            for i in 0..3 {
                for j in 0..3 {
                    let s = point.shape[i][k] * point.shape[j][k];
                    y[i][j][0] += s * re;
                    y[i][j][1] += s * im;
                }
            }
        }
        y
    }
}
