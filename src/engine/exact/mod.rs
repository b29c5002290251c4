//! One key integrated exactly: its strings on their contact springs and dampers, the duplex
//! damping and the soundboard under its bridge point form one linear time-invariant system,
//! diagonalised once into complex modes, so that between hammer contacts a voice advances by
//! `z <- e^{lambda h} z` each sample — no stages, unconditionally stable, exact for the key.
//!
//! Why this formulation (issue 16). The live integrator before it ([`crate::engine::etd`])
//! diagonalises each string direction alone and couples every direction to the board explicitly
//! at four ETDRK4 stages per sample; per voice and step that is ~42 FLOP per string mode plus
//! ~9.4 kFLOP of board reads and writes, and 32 voices already ask 28 GFLOP/s. Here the board is
//! part of each key's modes, so a sounding voice costs 6 FLOP per complex mode to propagate and
//! ~4 per mode for each output it is read at (the board's volume velocity), with no stage and no
//! board traffic. Only the felt hammer is nonlinear, and only for the few milliseconds it
//! touches: then the step is ETDRK4 (Cox & Matthews 2002) with the felt force as the nonlinear
//! term on the key's modes and on the hammer (whose linear part is zero, so its stages are
//! classical RK4); after release, none.
//!
//! The system (second-order form, `q` over the strings' T, L, P modes and the board's modes):
//! ```text
//! qdd = -K q - C qdot + sum_i b_i F_e,i            (Eq. 10 with the contact forces folded in)
//! K = diag(omega^2) + sum_{i,d} k_d w_id w_id^T,   C = diag(2 zeta omega) + C_d + sum c_d w_id w_id^T
//! w_id = (psi(L_s) on string i's modes in direction d, -phi_d on the board's modes)   (Eq. 6, 17)
//! m_H ydd_H = -sum_i F_e,i,   F_e,i = K_H max(y_H - y_e,i, 0)^p                       (Eq. 8-9)
//! ```
//! The board copy is this key's; the keys of a pool ([`ExactPool`]) are coupled through the
//! shared board ([`board`]), and a key's damper felt acts as an implicit feedback on its modes
//! ([`key`]).
//!
//! Parts: [`key`] (one key's coefficients), [`voice`] (a voice's state and step), [`board`] (the
//! coupling between keys), [`pool`] (the voice pool), [`halves`] (a block of the pool in two
//! halves, on one core or two), [`kernels`] (the loops over modes), [`bytes`] (a key's
//! coefficients as bytes and back, to be kept between runs).

mod board;
mod bytes;
mod halves;
mod kernels;
mod key;
mod pool;
mod voice;

pub use key::ExactKey;
pub use pool::ExactPool;

use crate::engine::kernels::has_avx2_fma;
use crate::engine::spec::{BuildError, Observation, Strike, UnisonSpec};
use faer::c64;
use kernels::{propagate_read, Split};
use voice::Voice;

/// One unison on its own copy of the board, integrated exactly in the complex modes of the
/// coupled system (module notes); the hammer staged with ETDRK4 while it touches.
#[derive(Debug, Clone)]
pub struct ExactUnison {
    key: ExactKey,
    voice: Voice,
    scratch: [Split; 3],
    /// Whether the CPU has AVX2 + FMA (the mode loops then use them).
    fast_path: bool,
}

impl ExactUnison {
    /// Diagonalise `spec`'s key (strings, contact, duplex, the board at its point) for the step
    /// `1 / spec.sample_rate_hz`.
    pub fn new(spec: &UnisonSpec) -> Result<ExactUnison, BuildError> {
        let key = ExactKey::new(spec)?;
        let n = key.n_modes();
        let mut voice = Voice::new(n, 0);
        voice.state.active = true;
        Ok(ExactUnison {
            key,
            voice,
            scratch: std::array::from_fn(|_| Split::zeros(n)),
            fast_path: has_avx2_fma(),
        })
    }

    /// Complex modes kept (one of each conjugate pair, and each real mode).
    pub fn n_modes(&self) -> usize {
        self.key.n_modes()
    }

    /// Every kept mode's eigenvalue `lambda` (1/s): `-sigma + i omega`.
    pub fn eigenvalues(&self) -> &[c64] {
        &self.key.lambda
    }

    pub fn step_s(&self) -> f64 {
        self.key.h
    }

    /// Whether the hammer is still part of the system.
    pub fn hammer_engaged(&self) -> bool {
        self.voice.state.hammer_on
    }

    /// Launch the hammer in contact with the struck strings' current displacement, moving at the
    /// strike's speed (as the other engines do).
    pub fn strike(&mut self, strike: Strike) {
        let n_struck = strike.strings_struck(self.key.n_strings);
        let s = &mut self.voice.state;
        s.struck = std::array::from_fn(|i| i < n_struck);
        self.voice.hammer_y = self.voice.strike_contact_m(&self.key, n_struck);
        self.voice.hammer_v = strike.velocity_m_s;
        self.voice.state.hammer_on = true;
    }

    /// Lower or lift the damper (a key without one ignores it).
    pub fn set_damper(&mut self, down: bool) {
        self.voice.state.damper_down = down && self.key.damper.is_some();
    }

    /// Advance one step: exactly while the hammer is away, by ETDRK4 while it touches.
    pub fn step(&mut self) {
        self.voice
            .step(&self.key, &mut self.scratch, self.fast_path);
    }

    /// Advance `volume_velocity.len()` steps, writing the board's net volume velocity (m^3/s)
    /// after each; once the hammer is released (damper lifted), each step and its read are one
    /// pass over the modes ([`kernels::propagate_read`]).
    pub fn run(&mut self, volume_velocity: &mut [f64]) {
        for out in volume_velocity {
            *out = if self.voice.state.hammer_on || self.voice.state.damper_down {
                self.step();
                self.voice.read[0]
            } else {
                self.voice.read[0] = propagate_read(
                    &self.key.ef,
                    &mut self.voice.z,
                    &self.key.reads[0],
                    self.fast_path,
                );
                self.voice.read[0]
            };
        }
    }

    /// Floating-point operations of one step and of reading the volume velocity after it: 6 per
    /// complex mode to propagate and 4 to read, once the hammer is released; with the hammer,
    /// ETDRK4's four reads of each struck string's point (4 each), three stage states (6 each,
    /// and 2 per struck string), the final drive (6 per struck string) and the forces' reads.
    pub fn flops_per_step(&self) -> f64 {
        let m = self.n_modes() as f64;
        let free = 10.0 * m;
        if !self.voice.state.hammer_on {
            return free;
        }
        let struck = self.voice.state.struck.iter().filter(|&&s| s).count() as f64;
        free + m * (4.0 * 4.0 * struck + 3.0 * (6.0 + 2.0 * struck) + 6.0 * struck + 12.0)
    }

    /// Net volume velocity of the board (m^3/s) after the last step (read by the step itself).
    pub fn volume_velocity_m3_s(&self) -> f64 {
        self.voice.read[0]
    }

    /// Forces and volume velocity now (Eq. 19).
    pub fn observe(&self) -> Observation {
        let (key, v) = (&self.key, &self.voice);
        let mut obs = Observation {
            volume_velocity_m3_s: self.volume_velocity_m3_s(),
            hammer_force_n: v.hammer_force_n(key),
            ..Observation::default()
        };
        for d in 0..3 {
            obs.bridge_velocity_m_s[d] = key.bridge_velocity_row[d].read(&v.z);
            for s in 0..key.n_strings {
                let f = key.force_row[s][d].read(&v.z);
                obs.bridge_force_n[s][d] = f;
                obs.total_force_n[d] += f;
            }
        }
        obs
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::preset::Preset;

    /// c2 cut down to a few modes (so that five decompositions take no time), at `rate_hz`.
    fn small_c2(rate_hz: f64) -> UnisonSpec {
        let mut spec = Preset::resolve("c2").unwrap().unison_spec();
        spec.modes.modes_t = 24;
        spec.modes.modes_p = 24;
        spec.modes.modes_l = 2;
        let keep = 24;
        let b = &mut spec.board;
        b.freq_hz.truncate(keep);
        b.damping_ratio.truncate(keep);
        b.volume_m2_per_sqrt_kg.truncate(keep);
        for p in &mut b.points {
            p.shape.iter_mut().for_each(|s| s.truncate(keep));
        }
        spec.sample_rate_hz = rate_hz;
        spec
    }

    /// The hammer's position 0.5 ms into its contact (it lasts ~2 ms), struck at 2.5 m/s.
    fn hammer_at(rate_hz: f64) -> f64 {
        let mut u = ExactUnison::new(&small_c2(rate_hz)).unwrap();
        u.strike(Strike {
            velocity_m_s: 2.5,
            una_corda: false,
        });
        for _ in 0..(0.5e-3 * rate_hz).round() as usize {
            u.step();
        }
        assert!(u.hammer_engaged());
        u.voice.hammer_y
    }

    #[test]
    fn the_fused_step_agrees_with_the_portable_one() {
        // 2 s of c2's tail (hammer released) through the AVX2 + FMA pass and the portable one.
        let mut spec = Preset::resolve("c2").unwrap().unison_spec();
        spec.sample_rate_hz = 48_000.0;
        let mut fast = ExactUnison::new(&spec).unwrap();
        fast.strike(Strike {
            velocity_m_s: 2.5,
            una_corda: false,
        });
        let mut warm = [0.0; 480];
        fast.run(&mut warm);
        assert!(!fast.hammer_engaged());
        let mut slow = fast.clone();
        slow.fast_path = false;
        let (mut a, mut b) = (vec![0.0; 96_000], vec![0.0; 96_000]);
        fast.run(&mut a);
        slow.run(&mut b);
        let peak = b.iter().fold(0f64, |m, x| m.max(x.abs()));
        let worst = a
            .iter()
            .zip(&b)
            .fold(0f64, |m, (x, y)| m.max((x - y).abs()))
            / peak;
        println!(
            "fused step, AVX2 + FMA (used: {}) vs portable: {worst:.1e} of the peak over 2 s",
            has_avx2_fma()
        );
        assert!(worst < 1e-12, "{worst:e}");
    }

    #[test]
    fn the_contact_step_converges_with_order_four() {
        // ETDRK4 is fourth order for a smooth nonlinear term; the felt's xi^p (p = 2.3) starts
        // from zero, which is smooth enough here. Errors against 1536 kHz at 48, 96, 192 kHz.
        let reference = hammer_at(1_536_000.0);
        let errors: Vec<f64> = [48_000.0, 96_000.0, 192_000.0]
            .iter()
            .map(|&r| (hammer_at(r) - reference).abs())
            .collect();
        let orders: Vec<f64> = errors.windows(2).map(|e| (e[0] / e[1]).log2()).collect();
        println!(
            "hammer position errors {:.1e} {:.1e} {:.1e} m, observed orders {orders:.2?}",
            errors[0], errors[1], errors[2]
        );
        assert!(orders.iter().all(|&p| p > 3.3), "{orders:?}");
    }
}
