//! The reduced modal soundboard (paper Eq. 4–5).
//!
//! The board is a set of mass-normalised modes with natural frequency, damping ratio, net volume
//! (for radiation, DESIGN.md §1.7), at each named bridge point the three mode-shape components
//! T, L, P, and at each named listener how the mode radiates there. The driving-point mobility at
//! a point is
//! `Y_ij(omega) = sum_k i omega phi_i,k phi_j,k / (omega_k^2 - omega^2 + 2 i zeta_k omega_k omega)`.

use super::Oscillator;
use crate::engine::spec::CHANNELS;
use std::f64::consts::PI;
use std::sync::Arc;

/// A reduced modal soundboard, structure-of-arrays.
#[derive(Debug, Clone, PartialEq)]
pub struct SoundboardModes {
    pub freq_hz: Vec<f64>,
    pub damping_ratio: Vec<f64>,
    /// Net volume displacement per unit modal coordinate (m^2/sqrt(kg)).
    pub volume_m2_per_sqrt_kg: Vec<f64>,
    /// Bridge points, each with its mode shapes.
    pub points: Vec<BridgePoint>,
    /// Listeners over the board, each with every mode's Rayleigh integral there (may be none).
    pub listeners: Vec<Listener>,
    /// The listener each output channel (left, right) hears
    /// ([`SoundboardModes::radiation_weights`]); `None`: the monopole of the net volume velocity
    /// (the paper's board). The same in both channels: a mono piano.
    pub heard: [Option<usize>; CHANNELS],
    /// The modes the reduction dropped from some frequency up, at the same points and listeners
    /// (their own Rayleigh integrals): heard, not coupled ([`DroppedModes`]); `None` for the
    /// paper's boards. Shared, not copied, by every key's preset.
    pub residual: Option<Arc<SoundboardModes>>,
}

/// The board's dropped modes at one key's bridge point ([`SoundboardModes::dropped_at`]): each
/// driven by the force the key's strings put on the bridge (`q_j'' + 2 zeta_j w_j q_j' + w_j^2 q_j
/// = phi_j . F`, Eq. 4's board without the strings' reaction) and radiated to each channel as the
/// kept modes are ([`SoundboardModes::radiation_weights`]). What the reduction (§2.2) leaves out of
/// the sound, not out of the strings' coupling: the kept modes couple, the dropped ones are heard.
#[derive(Debug, Clone, PartialEq)]
pub struct DroppedModes {
    pub freq_hz: Vec<f64>,
    pub damping_ratio: Vec<f64>,
    /// `[phi_T, phi_L, phi_P]` at the key's point, one value per mode (1/sqrt(kg)).
    pub shape: [Vec<f64>; 3],
    /// Per channel, the radiating source's weights on each mode's velocity and displacement.
    pub weights: [[Vec<f64>; 2]; CHANNELS],
}

impl DroppedModes {
    /// Dropped mode `j` (0-based) as an oscillator (Eq. 4).
    pub fn oscillator(&self, j: usize) -> Oscillator {
        Oscillator {
            omega_rad_s: 2.0 * PI * self.freq_hz[j],
            damping_ratio: self.damping_ratio[j],
        }
    }

    /// Whether `other` holds the same modes, heard alike, wherever its point (two keys on one
    /// board).
    pub fn same_modes(&self, other: &DroppedModes) -> bool {
        self.freq_hz == other.freq_hz
            && self.damping_ratio == other.damping_ratio
            && self.weights == other.weights
    }

    /// The radiating source of `channel` per unit force in direction `d` at the key's point,
    /// oscillating as `e^{lambda t}`: `sum_j phi_j,d (a_j lambda + b_j) / (lambda^2 + 2 zeta_j w_j
    /// lambda + w_j^2)` (`a`, `b` the weights), as `(re, im)`.
    pub fn source_per_force(&self, channel: usize, d: usize, lambda: (f64, f64)) -> (f64, f64) {
        let (lr, li) = lambda;
        let [a, b] = &self.weights[channel];
        let (mut re, mut im) = (0.0, 0.0);
        for j in 0..self.freq_hz.len() {
            let mode = self.oscillator(j);
            let (c, w2) = (mode.damping_per_s(), mode.omega2());
            // lambda^2 + c lambda + w^2
            let (dr, di) = (lr * lr - li * li + c * lr + w2, 2.0 * lr * li + c * li);
            // a lambda + b
            let (nr, ni) = (a[j] * lr + b[j], a[j] * li);
            let den = dr * dr + di * di;
            let s = self.shape[d][j];
            re += s * (nr * dr + ni * di) / den;
            im += s * (ni * dr - nr * di) / den;
        }
        (re, im)
    }
}

/// How each mode radiates to one listener over the board as a baffled plate: its Rayleigh
/// integral `D_m = ∫ phi_m(x) e^{-i k (R - R0)} / R dA` at the mode's own frequency
/// (`crate::board::radiation`), real and imaginary parts (m/sqrt(kg)).
#[derive(Debug, Clone, PartialEq)]
pub struct Listener {
    pub name: String,
    pub rayleigh_re: Vec<f64>,
    pub rayleigh_im: Vec<f64>,
}

/// The distance (m) at which the radiated source `Y` of a listener is an equivalent monopole:
/// `p = rho0 / (4 pi LISTENER_REFERENCE_M) dY/dt` ([`SoundboardModes::radiation_weights`]).
pub const LISTENER_REFERENCE_M: f64 = 1.0;

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

    /// The dropped modes ([`SoundboardModes::residual`]) at bridge point `point`, heard as this
    /// board's channels are; `None` without them.
    pub fn dropped_at(&self, point: usize) -> Option<DroppedModes> {
        let r = self.residual.as_deref()?;
        Some(DroppedModes {
            freq_hz: r.freq_hz.clone(),
            damping_ratio: r.damping_ratio.clone(),
            shape: r.points[point].shape.clone(),
            weights: std::array::from_fn(|c| r.weights_heard(self.heard[c])),
        })
    }

    /// What the engines read as the board's radiating source `Y` (m^3/s) of output `channel`
    /// (0 left, 1 right, [`SoundboardModes::heard`]): per mode, the weight
    /// of its modal velocity and of its modal displacement. Without a listener, the net volume
    /// velocity (weights `V_m`, 0), whose pressure at `r` is `rho0 / (4 pi r) dY/dt`. With one,
    /// the Rayleigh integral (`p = rho0 / (2 pi) sum_m D_m qdd_m`) as a monopole at
    /// [`LISTENER_REFERENCE_M`]: `2 r_ref (Re D_m qdot_m - omega_m Im D_m q_m)`, whose phasor at
    /// the mode's frequency is `2 r_ref D_m Qdot_m`.
    pub fn radiation_weights(&self, channel: usize) -> [Vec<f64>; 2] {
        self.weights_heard(self.heard[channel])
    }

    /// [`SoundboardModes::radiation_weights`] at listener `heard` (`None`: the monopole).
    fn weights_heard(&self, heard: Option<usize>) -> [Vec<f64>; 2] {
        match heard.and_then(|l| self.listeners.get(l)) {
            None => [self.volume_m2_per_sqrt_kg.clone(), vec![0.0; self.len()]],
            Some(l) => {
                let r2 = 2.0 * LISTENER_REFERENCE_M;
                [
                    l.rayleigh_re.iter().map(|d| r2 * d).collect(),
                    (0..self.len())
                        .map(|k| -r2 * 2.0 * PI * self.freq_hz[k] * l.rayleigh_im[k])
                        .collect(),
                ]
            }
        }
    }

    /// Whether the two channels hear different listeners.
    pub fn is_stereo(&self) -> bool {
        self.heard[0] != self.heard[1]
    }

    /// The index of the listener called `name`.
    pub fn listener(&self, name: &str) -> Option<usize> {
        self.listeners.iter().position(|l| l.name == name)
    }

    /// Keep the modes `keep` says (the reduction; tests that cut the board).
    pub fn retain(&mut self, keep: impl Fn(usize) -> bool) {
        let pick = |v: &mut Vec<f64>| {
            let mut k = 0;
            v.retain(|_| {
                k += 1;
                keep(k - 1)
            });
        };
        pick(&mut self.freq_hz);
        pick(&mut self.damping_ratio);
        pick(&mut self.volume_m2_per_sqrt_kg);
        for p in &mut self.points {
            p.shape.iter_mut().for_each(pick);
        }
        for l in &mut self.listeners {
            pick(&mut l.rayleigh_re);
            pick(&mut l.rayleigh_im);
        }
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

#[cfg(test)]
mod tests {
    use super::{Listener, SoundboardModes, LISTENER_REFERENCE_M};
    use std::f64::consts::PI;

    /// A mode moving as `q = cos(omega t)` radiates `p = rho0 / (2 pi) Re(D qdd)` to a listener
    /// (the Rayleigh integral with its phase): the weights on `qdot` and `q`, heard as a monopole
    /// at the reference distance, give exactly that at every instant.
    #[test]
    fn the_weights_radiate_the_rayleigh_integral_with_its_phase() {
        let (f_hz, re, im) = (440.0, 3e-3, -2e-3);
        let board = SoundboardModes {
            freq_hz: vec![f_hz],
            damping_ratio: vec![0.0],
            volume_m2_per_sqrt_kg: vec![1e-2],
            points: vec![],
            listeners: vec![Listener {
                name: "above".into(),
                rayleigh_re: vec![re],
                rayleigh_im: vec![im],
            }],
            heard: [Some(0), None],
            residual: None,
        };
        let [by_v, by_q] = board.radiation_weights(0);
        let (w, rho) = (2.0 * PI * f_hz, 1.2);
        let mut worst: f64 = 0.0;
        for i in 0..100 {
            let t = i as f64 * 3.7e-5;
            // dY/dt of Y = a qdot + b q, heard at the reference distance.
            let dy = by_v[0] * (-w * w * (w * t).cos()) + by_q[0] * (-w * (w * t).sin());
            let heard = rho / (4.0 * PI * LISTENER_REFERENCE_M) * dy;
            // rho0 / (2 pi) Re(D (-omega^2) e^{i omega t}).
            let rayleigh = rho / (2.0 * PI) * (-w * w) * (re * (w * t).cos() - im * (w * t).sin());
            worst = worst.max((heard - rayleigh).abs() / (rho / (2.0 * PI) * w * w * re.hypot(im)));
        }
        println!("a mode heard through its weights vs rho0/(2 pi) Re(D qdd): worst {worst:.1e} of the amplitude");
        assert!(worst < 1e-12);
        // Without a listener (the right channel here), the monopole of the net volume velocity.
        assert_eq!(board.radiation_weights(1), [vec![1e-2], vec![0.0]]);
        assert!(board.is_stereo());
    }
}
