//! String–bridge contact (paper Eq. 6–7).
//!
//! Each string touches the bridge through a spring and a damper in each of the three directions;
//! the force that string `i` exerts on the board is `F_i = K_c (r_s,i - r_b) + C_c (rdot_s,i - rdot_b)`
//! with diagonal `K_c`, `C_c` (Eq. 6).

use std::f64::consts::PI;

/// Contact stiffness and damping per direction, in the order T, L, P.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// Spring stiffness per direction (N/m).
    pub stiffness_n_m: [f64; 3],
    /// Damper coefficient per direction (N s/m).
    pub damping_n_s_m: [f64; 3],
}

impl Contact {
    /// Eq. 6 in direction `d` (0 = T, 1 = L, 2 = P): the force (N) on the board from a string
    /// whose bridge end is `stretch_m` from the bridge and moves at `rate_m_s` relative to it.
    #[inline]
    pub fn force_n(&self, d: usize, stretch_m: f64, rate_m_s: f64) -> f64 {
        spring_damper_n(
            self.stiffness_n_m[d],
            self.damping_n_s_m[d],
            stretch_m,
            rate_m_s,
        )
    }

    /// The contact spring's potential energy in direction `d` at `stretch_m` (J).
    #[inline]
    pub fn energy_j(&self, d: usize, stretch_m: f64) -> f64 {
        0.5 * self.stiffness_n_m[d] * stretch_m * stretch_m
    }
}

/// Eq. 6 for one direction, `k s + c sdot` (N): the one place the contact force is written, for
/// the engines' scalar loops ([`Contact::force_n`]) and their lanes alike.
#[inline]
pub fn spring_damper_n(
    stiffness_n_m: f64,
    damping_n_s_m: f64,
    stretch_m: f64,
    rate_m_s: f64,
) -> f64 {
    stiffness_n_m * stretch_m + damping_n_s_m * rate_m_s
}

/// Hertzian line-contact stiffness of a steel string on a wooden bridge (Eq. 7):
/// `k = (pi L_c / 4) E_s E_w / (E_s (1 - nu_w^2) + E_w (1 - nu_s^2))` (N/m).
pub fn hertz_stiffness_n_m(
    contact_length_m: f64,
    string_young_pa: f64,
    string_poisson: f64,
    bridge_young_pa: f64,
    bridge_poisson: f64,
) -> f64 {
    PI * contact_length_m / 4.0 * string_young_pa * bridge_young_pa
        / (string_young_pa * (1.0 - bridge_poisson.powi(2))
            + bridge_young_pa * (1.0 - string_poisson.powi(2)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hertz_gives_the_papers_order_of_magnitude() {
        // The paper: "k_c,T is in the order of L_c E_w"; with L_c = 1 cm it quotes 4.8e6 N/m.
        let k = hertz_stiffness_n_m(0.01, 2.0e11, 0.3, 5.4e8, 0.35);
        assert!((k / 4.8e6 - 1.0).abs() < 0.01, "k = {k}");
        assert!(k > 0.5 * 0.01 * 5.4e8 && k < 2.0 * 0.01 * 5.4e8);
    }
}
