//! The damper: a felt pad that drops onto the strings when the key is released (unless a pedal
//! holds it off). While it is down it adds viscous damping on every string's T and P motion,
//! `C_damper = c sum_k a_k^2 psi(x_k) psi(x_k)^T`, to the damping of Eq. 11: each mode loses energy
//! at the extra rate `c sum_k a_k^2 psi_n(x_k)^2`. A felt of no width is one point (`a = 1`); a
//! felt with a width `w` touches the string at its two ends, `x_d +- w/2` (`a_k^2 = 1/2`), as a
//! grand's split damper felts do. A point spares every mode with a node under it (a damped key
//! then rings on in those partials); two contact points spare only a mode with nodes under both,
//! `n w / L` an integer — beyond partial 50 at C2 for a 3.4 cm felt. A part-lifted felt (half
//! pedalling, a damper landing) gives a share of that damping ([`DamperParams::contact_share`]).

use std::f64::consts::PI;

/// How far a pedal (or a key) lifts a damper's felt clear of its strings at the end of its travel
/// by default (m): a few millimetres, the regulation of a grand's damper lift, well beyond any
/// string's excursion under the felt.
pub const FULL_LIFT_M: f64 = 4e-3;

/// How far a resting felt sits pressed into the strings under its own weight by default (m):
/// lifted by less, it still touches them, more lightly.
pub const REST_COMPRESSION_M: f64 = 0.5e-3;

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
    /// How far the felt rises clear of the strings at the full lift (m), and how far it sits
    /// pressed into them at rest (m): [`DamperParams::contact_share`].
    pub full_lift_m: f64,
    pub rest_compression_m: f64,
}

impl DamperParams {
    /// The felt's gap above a string's rest position (m) at the lift `lift` (0 resting, 1 the
    /// full lift); negative while the felt still presses on the string.
    pub fn gap_m(&self, lift: f64) -> f64 {
        lift * self.full_lift_m - self.rest_compression_m
    }

    /// The share of the felt's damping that a string gets with the felt lifted by `lift`
    /// (0 resting: all of it; 1 the full lift: none) while its vertical excursion under the felt
    /// has the amplitude `amplitude_m`. The felt damps in proportion to how far the string
    /// presses into it (its contact grows with the pressure; resting, it is pressed in by
    /// `rest_compression_m`), and only while the string reaches it: a felt lifted to a gap
    /// touches the part of each period in which the string rises past the gap — the
    /// damper-string interaction of part pedalling, a fast decay while a loud string still
    /// reaches the felt, a free one after. For `y = A sin(theta)` against the felt at the gap `g`
    /// (pressed in by `y - g` while `y > g`, from `sin(theta_1) = g / A`), the power it takes
    /// over a period, `c (y - g) / d_rest v^2` averaged, is the resting felt's times
    /// `(2/3 A cos^3 theta_1 - g (pi - 2 theta_1 - sin 2 theta_1) / 2) / (pi d_rest)`:
    /// `-g / d_rest` while the string never leaves the felt, 0 once it never reaches it,
    /// continuous and falling as the felt rises. The engines take that share of the felt's
    /// coefficient.
    pub fn contact_share(&self, lift: f64, amplitude_m: f64) -> f64 {
        if lift <= 0.0 {
            return 1.0;
        }
        if lift >= 1.0 {
            return 0.0;
        }
        let (g, rest) = (self.gap_m(lift), self.rest_compression_m);
        if amplitude_m <= g.abs() {
            return (-g / rest).clamp(0.0, 1.0);
        }
        let theta = (g / amplitude_m).asin();
        let touched = 2.0 / 3.0 * amplitude_m * theta.cos().powi(3)
            - g * (PI - 2.0 * theta - (2.0 * theta).sin()) / 2.0;
        (touched / (PI * rest)).clamp(0.0, 1.0)
    }

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

    /// The share is the power a part-lifted felt takes from a sinusoid: `c (y - g) / d_rest v^2`
    /// averaged over a period, counted only while `y > g`, integrated numerically, over the
    /// resting felt's `c v^2`; both ends are exact and the share falls as the felt rises.
    #[test]
    fn the_contact_share_is_the_power_a_part_lifted_felt_takes() {
        let felt = DamperParams {
            position_ratio: 0.12,
            damping_n_s_m: 1.0,
            width_m: 0.0,
            model: FeltModel::Modal,
            full_lift_m: FULL_LIFT_M,
            rest_compression_m: REST_COMPRESSION_M,
        };
        let (gap_m, contact_share) = (|l| felt.gap_m(l), |l, a| felt.contact_share(l, a));
        let mut worst: f64 = 0.0;
        for a in [0.05e-3, 0.3e-3, 0.8e-3] {
            let mut last = 1.0;
            for i in 1..80 {
                let lift = i as f64 / 400.0;
                let g = gap_m(lift);
                let n = 100_000;
                let (mut touched, mut full) = (0.0, 0.0);
                for j in 0..n {
                    let t = 2.0 * PI * (j as f64 + 0.5) / n as f64;
                    let (y, v2) = (a * t.sin(), t.cos().powi(2));
                    full += v2;
                    if y > g {
                        touched += (y - g) / REST_COMPRESSION_M * v2;
                    }
                }
                let share = contact_share(lift, a);
                worst = worst.max((share - (touched / full).min(1.0)).abs());
                assert!(share <= last, "the share rises with the lift at {lift}");
                last = share;
            }
        }
        println!(
            "contact share against the integrated power, 3 amplitudes x 79 lifts: worst {worst:.1e}"
        );
        // The midpoint rule over 100 000 points is good to ~1e-6; a wrong closed form is off by
        // ~0.1.
        assert!(worst < 1e-4);
        assert_eq!(contact_share(0.0, 1.0), 1.0);
        assert_eq!(contact_share(1.0, 1.0), 0.0);
        assert_eq!(
            contact_share(0.5, 0.0),
            0.0,
            "a string at rest is clear of a lifted felt"
        );
        assert!(
            (contact_share(0.0625, 1e-5) - 0.5).abs() < 1e-12,
            "half-pressed: half"
        );
    }

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
                full_lift_m: FULL_LIFT_M,
                rest_compression_m: REST_COMPRESSION_M,
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
