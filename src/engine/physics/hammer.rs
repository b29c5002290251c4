//! The felt hammer (paper Eq. 8–9, 14–15).
//!
//! A point mass `m_H` moving along T. On each struck string `i` the felt is compressed by
//! `xi_i = max(y_H - y_e,i, 0)` and pushes with `F_e,i = K_H xi_i^p` (Eq. 8); the hammer obeys
//! `m_H ydd_H = -sum_i F_e,i` (Eq. 9 for several strings, Eq. 14).

/// Hammer parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HammerParams {
    /// Mass m_H (kg).
    pub mass_kg: f64,
    /// Felt stiffness K_H (N/m^p).
    pub stiffness_n_m_p: f64,
    /// Power-law exponent p (-).
    pub exponent: f64,
    /// Striking point as a fraction of the speaking length, L_e / L_s (-).
    pub strike_ratio: f64,
    /// Distance from every string beyond which a receding hammer is released (m).
    pub release_gap_m: f64,
}

impl HammerParams {
    /// Felt force for a compression `xi_m` (m); zero when the felt is not compressed (Eq. 8).
    #[inline(always)]
    pub fn felt_force_n(&self, xi_m: f64) -> f64 {
        if xi_m > 0.0 {
            self.stiffness_n_m_p * xi_m.powf(self.exponent)
        } else {
            0.0
        }
    }

    /// The release rule: the hammer leaves the system once it recedes (`velocity_m_s < 0`) and is
    /// clear of every struck string by the release gap; `strike_points_m` are their displacements
    /// at the striking point.
    #[inline(always)]
    pub fn is_clear(
        &self,
        position_m: f64,
        velocity_m_s: f64,
        mut strike_points_m: impl Iterator<Item = f64>,
    ) -> bool {
        velocity_m_s < 0.0 && strike_points_m.all(|y| y - position_m >= self.release_gap_m)
    }

    /// Potential energy stored in the felt at compression `xi_m` (J).
    pub fn felt_energy_j(&self, xi_m: f64) -> f64 {
        if xi_m > 0.0 {
            self.stiffness_n_m_p * xi_m.powf(self.exponent + 1.0) / (self.exponent + 1.0)
        } else {
            0.0
        }
    }
}
