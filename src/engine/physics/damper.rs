//! The damper: a felt pad that drops onto the strings when the key is released (unless a pedal
//! holds it off). While it is down it adds viscous damping on every string's T and P motion,
//! `C_damper = c sum_k a_k^2 psi(x_k) psi(x_k)^T`, to the damping of Eq. 11: each mode loses energy
//! at the extra rate `c sum_k a_k^2 psi_n(x_k)^2`. A felt of no width is one point (`a = 1`); a
//! felt with a width `w` touches the string at its two ends, `x_d +- w/2` (`a_k^2 = 1/2`), as a
//! grand's split damper felts do. A point spares every mode with a node under it (a damped key
//! then rings on in those partials); two contact points spare only a mode with nodes under both,
//! `n w / L` an integer — beyond partial 50 at C2 for a 3.4 cm felt.

use std::f64::consts::PI;

/// Contact points of a felt with a width: its two ends.
pub const FELT_POINTS: usize = 2;

/// How the exact engine carries the felt (RK4 always carries it in full).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FeltModel {
    /// Coupled to the key's modes in full: the felt's force on each of its channels solved
    /// every step. Exact at any strength, a felt that pins the string too; a damped voice then
    /// reads and drives its channels beside the key's rows (5.7-6.2 times a held voice's cost on
    /// the concert keyboard's keys).
    #[default]
    Coupled,
    /// On each mode's decay alone, to first order (its eigenvalue moved by the diagonal of the
    /// felt's feedback in the modes): a damped voice costs what a held one does. Exact for a
    /// light felt only: the concert keyboard's releases within 0.4 dB of the coupled felt's;
    /// the paper keyboard's 6 N s/m point, which pins the strings from C2 up, 3-13 dB too fast
    /// in the first 0.1 s.
    Modal,
}

/// Damper parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DamperParams {
    /// Centre of the felt as a fraction of the speaking length, `x_d / L_s` (-).
    pub position_ratio: f64,
    /// Viscous coefficient of the whole felt on the string (N s/m).
    pub damping_n_s_m: f64,
    /// Distance between the felt's two contact points along the string (m); 0 is a point.
    pub width_m: f64,
    /// How the exact engine carries it.
    pub model: FeltModel,
}

impl DamperParams {
    /// The felt's points on a string of speaking length `speaking_length_m`: position (m) and the
    /// square root of its share of the felt's coefficient, as many as it has (1 or
    /// [`FELT_POINTS`]).
    pub fn felt_points(&self, speaking_length_m: f64) -> ([(f64, f64); FELT_POINTS], usize) {
        let x = self.position_ratio * speaking_length_m;
        if self.point_count() == 1 {
            return ([(x, 1.0), (x, 0.0)], 1);
        }
        let (d, a) = (self.width_m / 2.0, 0.5f64.sqrt());
        ([(x - d, a), (x + d, a)], FELT_POINTS)
    }

    /// How many points the felt touches each string at: 1 without a width, else [`FELT_POINTS`].
    pub fn point_count(&self) -> usize {
        if self.width_m > 0.0 {
            FELT_POINTS
        } else {
            1
        }
    }

    /// The coefficient (N s/m) with which this felt gives the first mode of the speaking length
    /// `l_s` (linear density `mu`) the amplitude T60 `t60_s`: that mode, `psi_1 =
    /// sqrt(2 / (mu L_s)) sin(pi x / L_s)`, decays at `sigma = c/2 sum_k a_k^2 psi_1(x_k)^2`, and
    /// `T60 = ln(1000) / sigma`.
    pub fn coefficient_for_t60(&self, t60_s: f64, l_s: f64, mu_kg_m: f64) -> f64 {
        let sigma = 1000f64.ln() / t60_s;
        let (points, n) = self.felt_points(l_s);
        let psi2: f64 = points[..n]
            .iter()
            .map(|&(x, a)| a * a * 2.0 / (mu_kg_m * l_s) * (PI * x / l_s).sin().powi(2))
            .sum();
        2.0 * sigma / psi2
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The coefficient gives the first mode the T60 asked for: `sigma = c/2 sum_k a_k^2
    /// psi_1(x_k)^2` checked against the mass-normalised shape written out, for a point and a
    /// felt with a width; a mode with a node at the felt's centre is damped by both contacts.
    #[test]
    fn the_coefficient_gives_the_first_mode_its_t60() {
        let (l, mu) = (0.62, 7.0e-3);
        for width_m in [0.0, 0.03] {
            let felt = DamperParams {
                position_ratio: 0.155,
                damping_n_s_m: 0.0,
                width_m,
                model: FeltModel::Coupled,
            };
            let c = felt.coefficient_for_t60(0.5, l, mu);
            let (points, n) = felt.felt_points(l);
            let rate = |mode: f64| -> f64 {
                points[..n]
                    .iter()
                    .map(|&(x, a)| {
                        let psi = (2.0 / (mu * l)).sqrt() * (mode * PI * x / l).sin();
                        0.5 * c * a * a * psi * psi
                    })
                    .sum()
            };
            let t60 = 1000f64.ln() / rate(1.0);
            // The node of mode 2 at the centre of a felt at the middle of the string.
            let middle = DamperParams {
                position_ratio: 0.5,
                ..felt
            };
            let (mid, m) = middle.felt_points(l);
            let at_node: f64 = mid[..m]
                .iter()
                .map(|&(x, a)| a * a * (2.0 * PI * x / l).sin().powi(2))
                .sum();
            println!(
                "width {width_m} m: c = {c:.4} N s/m, first mode T60 {t60:.4} s; mode 2 at a \
                 node under the centre: {at_node:.2e}"
            );
            assert!((t60 - 0.5).abs() < 1e-12);
            assert_eq!(at_node > 1e-3, width_m > 0.0);
        }
    }
}
