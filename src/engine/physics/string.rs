//! Stiff piano string modes (paper Eq. 1–3).
//!
//! The string of full length `L` (agraffe to hitch pin) is pinned at both ends; its modes are
//! mass-normalised, `psi_n(x) = sqrt(2 / (mu L)) sin(n pi x / L)`, so that the modal mass is 1 and
//! the modal stiffness is `omega_n^2`.

use super::{Direction, Oscillator};
use std::f64::consts::PI;

/// Physical description of one string of a unison.
#[derive(Debug, Clone, PartialEq)]
pub struct StringParams {
    /// Agraffe to bridge (m).
    pub speaking_length_m: f64,
    /// Bridge to hitch pin (m).
    pub duplex_length_m: f64,
    /// Static tension T0 (N).
    pub tension_n: f64,
    /// Mass per unit length mu (kg/m), including any wrapping.
    pub linear_density_kg_m: f64,
    /// Diameter of the steel core that carries the bending stiffness (m).
    pub core_diameter_m: f64,
    /// Young's modulus of the core E (Pa).
    pub young_modulus_pa: f64,
    /// Density of the core steel rho (kg/m^3).
    pub density_kg_m3: f64,
    /// Wound strings carry longitudinal waves at `sqrt(E S_core / mu)`, plain ones at `sqrt(E / rho)`.
    pub wound: bool,
}

impl StringParams {
    /// Full vibrating length `L = L_s + L_d` (m).
    pub fn length_m(&self) -> f64 {
        self.speaking_length_m + self.duplex_length_m
    }

    /// Bending stiffness `E S K^2` of the core (N m^2), `S K^2 = pi d^4 / 64` for a round wire.
    pub fn bending_stiffness_n_m2(&self) -> f64 {
        self.young_modulus_pa * PI * self.core_diameter_m.powi(4) / 64.0
    }

    /// Fundamental of the full string without stiffness, `f0 = sqrt(T0 / mu) / 2L` (Eq. 2).
    pub fn f0_hz(&self) -> f64 {
        (self.tension_n / self.linear_density_kg_m).sqrt() / (2.0 * self.length_m())
    }

    /// Inharmonicity coefficient `B = pi^2 E S K^2 / (T0 L^2)` (Eq. 2).
    pub fn inharmonicity(&self) -> f64 {
        PI * PI * self.bending_stiffness_n_m2() / (self.tension_n * self.length_m().powi(2))
    }

    /// `B` of the speaking length alone (Eq. 2's `B` goes as `1 / L^2`): the inharmonicity of
    /// the partials the struck string sounds.
    pub fn speaking_inharmonicity(&self) -> f64 {
        self.inharmonicity() * (self.length_m() / self.speaking_length_m).powi(2)
    }

    /// Transverse natural frequency of mode `n` (1-based), `omega_n = n 2 pi f0 sqrt(1 + B n^2)` (Eq. 2).
    pub fn transverse_omega(&self, n: usize) -> f64 {
        let n = n as f64;
        n * 2.0 * PI * self.f0_hz() * (1.0 + self.inharmonicity() * n * n).sqrt()
    }

    /// Longitudinal wave speed (m/s): `sqrt(E / rho)` (Eq. 3) for plain wire, `sqrt(E S_core / mu)`
    /// for wound strings, where the wrapping adds mass but no axial stiffness.
    pub fn longitudinal_speed_m_s(&self) -> f64 {
        if self.wound {
            let core_area = PI * self.core_diameter_m.powi(2) / 4.0;
            (self.young_modulus_pa * core_area / self.linear_density_kg_m).sqrt()
        } else {
            (self.young_modulus_pa / self.density_kg_m3).sqrt()
        }
    }

    /// Longitudinal natural frequency of mode `n`, `omega_L,n = n pi c_L / L` (Eq. 3).
    pub fn longitudinal_omega(&self, n: usize) -> f64 {
        n as f64 * PI * self.longitudinal_speed_m_s() / self.length_m()
    }

    /// Natural frequency of mode `n` (1-based) in direction `dir`: Eq. 2 for T and P, Eq. 3 for L.
    pub fn omega(&self, dir: Direction, n: usize) -> f64 {
        if dir.is_transverse() {
            self.transverse_omega(n)
        } else {
            self.longitudinal_omega(n)
        }
    }

    /// Mode `n` (1-based) of direction `dir` as an oscillator, damped as `modes` says.
    pub fn oscillator(&self, dir: Direction, n: usize, modes: &ModeSet) -> Oscillator {
        let omega_rad_s = self.omega(dir, n);
        Oscillator {
            omega_rad_s,
            damping_ratio: modes.damping_ratio(dir, omega_rad_s),
        }
    }

    /// Mass-normalised mode shape `psi_n(x)` (1/sqrt(kg)), the same for T, P and L.
    pub fn mode_shape(&self, n: usize, x_m: f64) -> f64 {
        let l = self.length_m();
        (2.0 / (self.linear_density_kg_m * l)).sqrt() * (n as f64 * PI * x_m / l).sin()
    }

    /// The same string retuned by `cents` through its tension alone (f ∝ sqrt(T0)).
    pub fn detuned(&self, cents: f64) -> StringParams {
        StringParams {
            tension_n: self.tension_n * 2f64.powf(2.0 * cents / 1200.0),
            ..self.clone()
        }
    }
}

/// Mode counts and losses per polarisation.
///
/// A mode of direction `dir` at `omega` decays at `sigma = zeta_dir omega + b1 + b3 omega^2`
/// (1/s): the paper's constant damping ratio (§2.1) plus, on the transverse polarisations,
/// Chaigne & Askenfelt's frequency-dependent string losses (JASA 95(2) 1994, Eq. 3:
/// `y_tt = ... - 2 b1 y_t + 2 b3 y_ttt` gives `1/tau = b1 + b3 omega^2`). The paper's keyboard has
/// `b1 = b3 = 0`.
#[derive(Debug, Clone, PartialEq)]
pub struct ModeSet {
    pub modes_t: usize,
    pub modes_p: usize,
    pub modes_l: usize,
    pub damping_ratio_t: f64,
    pub damping_ratio_p: f64,
    pub damping_ratio_l: f64,
    /// Frequency-independent transverse loss `b1` (1/s).
    pub loss_b1_per_s: f64,
    /// Transverse loss growing as `omega^2`, `b3` (s).
    pub loss_b3_s: f64,
}

impl ModeSet {
    /// How many modes direction `dir` keeps.
    pub fn count(&self, dir: Direction) -> usize {
        match dir {
            Direction::T => self.modes_t,
            Direction::L => self.modes_l,
            Direction::P => self.modes_p,
        }
    }

    /// Damping ratio of a mode of direction `dir` at `omega_rad_s`: `sigma / omega`.
    pub fn damping_ratio(&self, dir: Direction, omega_rad_s: f64) -> f64 {
        let strings = self.loss_b1_per_s / omega_rad_s + self.loss_b3_s * omega_rad_s;
        match dir {
            Direction::T => self.damping_ratio_t + strings,
            Direction::L => self.damping_ratio_l,
            Direction::P => self.damping_ratio_p + strings,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c2_like() -> StringParams {
        StringParams {
            speaking_length_m: 1.9,
            duplex_length_m: 0.2,
            tension_n: 750.0,
            linear_density_kg_m: 0.0121,
            core_diameter_m: 1.2e-3,
            young_modulus_pa: 2.0e11,
            density_kg_m3: 7850.0,
            wound: true,
        }
    }

    #[test]
    fn mode_shape_is_mass_normalised() {
        let s = c2_like();
        let l = s.length_m();
        let n_pts = 20_000;
        let dx = l / n_pts as f64;
        for n in [1, 7, 40] {
            let m: f64 = (0..n_pts)
                .map(|k| {
                    let x = (k as f64 + 0.5) * dx;
                    s.linear_density_kg_m * s.mode_shape(n, x).powi(2) * dx
                })
                .sum();
            assert!((m - 1.0).abs() < 1e-9, "modal mass of mode {n} = {m}");
        }
    }
}
