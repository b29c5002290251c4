//! The felt hammer (paper Eq. 8–9, 14–15).
//!
//! A point mass `m_H` moving along T. On each struck string `i` the felt is compressed by
//! `xi_i = max(y_H - y_e,i, 0)` and pushes with `F_e,i = K_H xi_i^p` (Eq. 8); the hammer obeys
//! `m_H ydd_H = -sum_i F_e,i` (Eq. 9 for several strings, Eq. 14).
//!
//! Beyond the paper, the felt may be hysteretic (Stulov 1995, in the form of Smith, *Physical Audio
//! Signal Processing*, Eq. 9.21): `F_e,i = K_H [xi^p + alpha d(xi^p)/dt]`, never pulling. A felt
//! compressed fast is then stiffer than one compressed slowly, and it loses energy over each
//! compression and release: a fortissimo blow is shorter and brighter than a pianissimo one.
//! `alpha = 0` is the paper's elastic felt, bit for bit.
//!
//! Where each string meets the felt — in its groove, or elsewhere under the soft pedal — sets its
//! law ([`FeltLaw`], from the hammer's [`FeltProfile`]).

pub use super::felt_profile::FeltProfile;

/// The fastest blow a key is built to resolve (m/s): MIDI velocity 127's hammer speed
/// (`midi::VELOCITY_ANCHORS_M_S`).
pub const FASTEST_BLOW_M_S: f64 = 6.0;

/// Steps in which a stepper that takes the felt's force as a polynomial over each step (the
/// exact engine's ETDRK4) must see the shortest contact ([`HammerParams::contact_substeps`]).
pub const STEPS_PER_CONTACT: f64 = 16.0;

/// Hammer parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HammerParams {
    /// The felt across the hammer's width, which the soft pedal's shift moves the strings over.
    pub profile: FeltProfile,
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
    /// The felt's hysteresis `alpha` (s): Stulov's `F = K [xi^p + alpha d(xi^p)/dt]`; 0 for the
    /// paper's elastic felt (Eq. 8).
    pub hysteresis_s: f64,
}

/// The felt's law where one string meets it (Eq. 8 at that place on the hammer: see
/// [`FeltProfile`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeltLaw {
    /// Stiffness K (N/m^p).
    pub stiffness_n_m_p: f64,
    /// Exponent p (-).
    pub exponent: f64,
    /// How far the felt's surface there lies behind the hammer's reference, a groove's (m): the
    /// compression is `y_H - y_e - offset_m`.
    pub offset_m: f64,
}

impl FeltLaw {
    /// Felt force for the hammer `y_H - y_e` = `gap_m` (m) from the string, the felt compressed
    /// by `xi = gap_m - offset_m` growing at `rate_m_s` (the hammer's velocity less the
    /// string's at the striking point): `K xi^p` (Eq. 8), and with the hysteresis `alpha_s`
    /// `K [xi^p + alpha p xi^(p-1) dxi/dt]`, at least 0 (a felt pushes, never pulls); zero when
    /// the felt is not compressed.
    #[inline(always)]
    pub fn force_n(&self, gap_m: f64, rate_m_s: f64, alpha_s: f64) -> f64 {
        let xi_m = gap_m - self.offset_m;
        if xi_m <= 0.0 {
            return 0.0;
        }
        let elastic = xi_m.powf(self.exponent);
        if alpha_s == 0.0 {
            return self.stiffness_n_m_p * elastic;
        }
        let rate = alpha_s * self.exponent * elastic / xi_m * rate_m_s;
        (self.stiffness_n_m_p * (elastic + rate)).max(0.0)
    }

    /// Potential energy stored in the felt for the hammer `gap_m` from the string (J).
    pub fn energy_j(&self, gap_m: f64) -> f64 {
        let xi_m = gap_m - self.offset_m;
        if xi_m > 0.0 {
            self.stiffness_n_m_p * xi_m.powf(self.exponent + 1.0) / (self.exponent + 1.0)
        } else {
            0.0
        }
    }
}

impl HammerParams {
    /// The felt's law in a groove: `K xi^p`, its surface the reference.
    pub fn groove_law(&self) -> FeltLaw {
        FeltLaw {
            stiffness_n_m_p: self.stiffness_n_m_p,
            exponent: self.exponent,
            offset_m: 0.0,
        }
    }

    /// Felt force in a groove ([`FeltLaw::force_n`] of [`Self::groove_law`]).
    #[inline(always)]
    pub fn felt_force_n(&self, xi_m: f64, rate_m_s: f64) -> f64 {
        self.groove_law().force_n(xi_m, rate_m_s, self.hysteresis_s)
    }

    /// Whether the felt's force depends on its rate of compression (then its callers read the
    /// strings' velocity under the hammer).
    #[inline(always)]
    pub fn is_hysteretic(&self) -> bool {
        self.hysteresis_s != 0.0
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

    /// How long the elastic felt (Eq. 8) stays on a rigid wall it meets at `speed_m_s` (s): it
    /// compresses to `xi_max = ((p + 1) m v^2 / 2K)^(1/(p+1))` and comes back, in
    /// `2 (xi_max / v) int_0^1 du / sqrt(1 - u^(p+1))`. A string yields, so the contact on it is
    /// longer: this is the shortest the felt can make it.
    pub fn rigid_contact_s(&self, speed_m_s: f64) -> f64 {
        let q = self.exponent + 1.0;
        let xi_max_m =
            (q * self.mass_kg * speed_m_s * speed_m_s / (2.0 * self.stiffness_n_m_p)).powf(1.0 / q);
        // u = 1 - w^2 takes the integrand's end singularity away: 2w / sqrt(1 - (1 - w^2)^q),
        // which tends to 2 / sqrt(q) at w = 0; Simpson's rule on 64 intervals.
        let f = |w: f64| {
            if w == 0.0 {
                2.0 / q.sqrt()
            } else {
                2.0 * w / (1.0 - (1.0 - w * w).powf(q)).sqrt()
            }
        };
        let n = 64;
        let integral = (0..=n)
            .map(|i| {
                let weight = if i == 0 || i == n {
                    1.0
                } else {
                    [4.0, 2.0][(i + 1) % 2]
                };
                weight * f(i as f64 / n as f64)
            })
            .sum::<f64>()
            / (3.0 * n as f64);
        2.0 * xi_max_m / speed_m_s * integral
    }

    /// How many steps of `h / n` a stepper of step `h` takes while the felt touches, so that the
    /// shortest contact ([`Self::rigid_contact_s`] at [`FASTEST_BLOW_M_S`]) spans at least
    /// [`STEPS_PER_CONTACT`] of them (1 to 16).
    pub fn contact_substeps(&self, h_s: f64) -> usize {
        let shortest_s = self.rigid_contact_s(FASTEST_BLOW_M_S);
        ((STEPS_PER_CONTACT * h_s / shortest_s).ceil() as usize).clamp(1, 16)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Chaigne & Askenfelt's C4 hammer (the paper keyboard's), elastic or hysteretic.
    pub(crate) fn c4(hysteresis_s: f64) -> HammerParams {
        HammerParams {
            mass_kg: 2.97e-3,
            stiffness_n_m_p: 4.5e9,
            exponent: 2.5,
            strike_ratio: 0.12,
            release_gap_m: 0.0,
            hysteresis_s,
            profile: crate::engine::physics::felt_profile::DEFAULT_PROFILE,
        }
    }

    /// The hammer thrown at `v0_m_s` against a rigid wall, `m xdd = -F(x, xd)`, by RK4 in steps
    /// of 10 ns until it leaves: its speed then, `int K alpha p x^(p-1) xd^2 dt` along the way and
    /// the time it took.
    fn rebound(h: &HammerParams, v0_m_s: f64) -> (f64, f64, f64) {
        let dt = 1e-8;
        let a = |x: f64, v: f64| -h.felt_force_n(x, v) / h.mass_kg;
        let (mut x, mut v, mut loss_j, mut t) = (0.0f64, v0_m_s, 0.0, 0.0);
        loop {
            t += dt;
            let (k1x, k1v) = (v, a(x, v));
            let (k2x, k2v) = (
                v + 0.5 * dt * k1v,
                a(x + 0.5 * dt * k1x, v + 0.5 * dt * k1v),
            );
            let (k3x, k3v) = (
                v + 0.5 * dt * k2v,
                a(x + 0.5 * dt * k2x, v + 0.5 * dt * k2v),
            );
            let (k4x, k4v) = (v + dt * k3v, a(x + dt * k3x, v + dt * k3v));
            x += dt / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
            v += dt / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
            if x > 0.0 {
                let p = h.exponent;
                loss_j += h.stiffness_n_m_p * p * x.powf(p - 1.0) * v * v * dt;
            }
            if x <= 0.0 && v < 0.0 {
                return (-v, loss_j, t);
            }
        }
    }

    #[test]
    fn the_paper_felt_is_elastic_and_the_hysteretic_one_loses_what_its_loop_encloses() {
        let elastic = c4(0.0);
        for xi in [1e-5, 3e-4, 1e-3] {
            assert_eq!(elastic.felt_force_n(xi, 3.0), 4.5e9 * xi.powf(2.5));
            assert_eq!(
                elastic.felt_force_n(xi, -3.0),
                elastic.felt_force_n(xi, 3.0)
            );
        }
        assert_eq!(elastic.felt_force_n(-1e-4, 3.0), 0.0);
        let (out, _, _) = rebound(&elastic, 2.5);
        println!("elastic felt: thrown at 2.5 m/s, leaves at {out:.6} m/s");
        assert!((out / 2.5 - 1.0).abs() < 1e-6);
        // Stulov's felt pushes harder compressed than released, never pulls.
        let felt = c4(1e-6);
        let xi = 3e-4;
        assert!(felt.felt_force_n(xi, 1.0) > elastic.felt_force_n(xi, 1.0));
        assert!(felt.felt_force_n(xi, -1.0) < elastic.felt_force_n(xi, -1.0));
        assert_eq!(felt.felt_force_n(xi, -1e3), 0.0);
        // The energy it loses is the work of its rate term, K alpha int p xi^(p-1) xid^2 dt along
        // its path: the elastic part gives back all it takes.
        let (out, loss_j, _) = rebound(&felt, 2.5);
        let lost_j = 0.5 * felt.mass_kg * (2.5f64.powi(2) - out * out);
        let predicted_j = felt.hysteresis_s * loss_j;
        println!(
            "hysteretic felt (alpha 1 us): leaves at {out:.4} m/s, loses {lost_j:.4e} J; its rate term's work {predicted_j:.4e} J"
        );
        assert!((lost_j / predicted_j - 1.0).abs() < 0.01);
    }

    #[test]
    fn the_felts_shortest_contact_is_its_rebound_from_a_rigid_wall() {
        // A linear felt (p = 1) is half a period of its spring, pi sqrt(m / K); the paper's C4
        // felt (p = 2.5) and a treble felt (p = 2, as hard as concert's C8) as RK4 throws them
        // at a wall in steps of 10 ns.
        let linear = HammerParams {
            exponent: 1.0,
            stiffness_n_m_p: 1e5,
            ..c4(0.0)
        };
        let half_period_s = std::f64::consts::PI * (linear.mass_kg / 1e5).sqrt();
        let got = linear.rigid_contact_s(3.0);
        println!(
            "linear felt: {got:.6e} s, half its period {half_period_s:.6e} s ({:.1e} apart)",
            (got / half_period_s - 1.0).abs()
        );
        assert!((got / half_period_s - 1.0).abs() < 1e-4);
        let treble = HammerParams {
            mass_kg: 2e-3,
            stiffness_n_m_p: 5.0e9,
            exponent: 2.0,
            ..c4(0.0)
        };
        for (felt, v) in [
            (c4(0.0), 2.5),
            (c4(0.0), FASTEST_BLOW_M_S),
            (treble, FASTEST_BLOW_M_S),
        ] {
            let (_, _, thrown_s) = rebound(&felt, v);
            let got = felt.rigid_contact_s(v);
            println!(
                "p {}, {v} m/s: contact {got:.4e} s, thrown {thrown_s:.4e} s ({:.1e} apart); {} substeps at 48 kHz",
                felt.exponent,
                (got / thrown_s - 1.0).abs(),
                felt.contact_substeps(1.0 / 48_000.0)
            );
            assert!((got / thrown_s - 1.0).abs() < 1e-3);
        }
        assert_eq!(c4(0.0).contact_substeps(1.0 / 48_000.0), 1);
    }
}
