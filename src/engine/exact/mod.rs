//! The exact engine: each key's strings on their contact springs, the duplex damping and the
//! soundboard's high modes under its bridge point form one linear time-invariant system,
//! diagonalised once into complex modes, so that between hammer contacts a voice advances by
//! `z <- e^{lambda h} z` each sample — no stages, unconditionally stable, exact for its modes; the
//! board's low modes are one system shared by every key, met at the bridges by an interface
//! solved implicitly each step.
//!
//! Why this formulation (issue 16). The live integrator before it (issue 5's, since removed)
//! diagonalises each string direction alone and couples every direction to the board explicitly
//! at four ETDRK4 stages per sample; per voice and step that is ~42 FLOP per string mode plus
//! ~9.4 kFLOP of board reads and writes, and 32 voices already ask 28 GFLOP/s. Here a sounding
//! voice costs 6 FLOP per complex mode to propagate and ~4 per mode for each row it is read at
//! (its radiating source in each of two channels and its force on the board in three directions), and 6 per shared board
//! mode to meet the board (its force onto the modes, their displacement at its bridge); the board
//! costs `2 m^2` a step for the whole pool ([`interface`]). Only the felt hammer is nonlinear,
//! and only for the few milliseconds it touches: then the step is ETDRK4 (Cox & Matthews 2002)
//! with the felt force as the nonlinear term on the key's modes and on the hammer (whose linear
//! part is zero, so its stages are classical RK4), in substeps where a hard treble felt's contact
//! is only a few samples long (`HammerParams::contact_substeps`); after release, none.
//!
//! A key's system (second-order form, `q` over the strings' T, L, P modes and the board's modes
//! above [`interface::SHARED_BELOW_HZ`]):
//! ```text
//! qdd = -K q - C qdot + sum_i b_i F_e,i + sum_d g_d (k_d D_d + c_d Ddot_d)   (Eq. 10, contact folded in)
//! K = diag(omega^2) + sum_{i,d} k_d w_id w_id^T,   C = diag(2 zeta omega) + C_d + sum c_d w_id w_id^T
//! w_id = (psi(L_s) on string i's modes in direction d, -phi_d on the key's board modes)   (Eq. 6, 17)
//! m_H ydd_H = -sum_i F_e,i,   F_e,i = K_H max(y_H - y_e,i, 0)^p                       (Eq. 8-9)
//! ```
//! with `D` the shared board's displacement at the bridge point.
//!
//! Parts: [`key`] (one key's coefficients), [`bridge_modes`] (its modes, solved through its
//! bridge point), [`voice`] (a voice's state and step), [`interface`]
//! (the shared board and the keys' interface with it), [`pool`] (the voice pool), [`block`] (a
//! block of the pool: its passes, on one core or two, and its steps), [`kernels`] (the loops over modes),
//! [`bytes`] (a key's modes as bytes and back, to be kept between runs).

mod block;
mod bridge_modes;
mod bytes;
mod interface;
mod kernels;
mod key;
mod pool;
mod voice;

pub(crate) use block::Exchange;
pub use key::ExactKey;
pub use pool::ExactPool;

use crate::engine::pool::Policy;
use crate::engine::spec::{BuildError, Observation, Strike, UnisonSpec};

/// One unison alone on the board, on the exact engine: a pool of one voice ([`ExactPool`]), so
/// that a key rendered alone sounds as it does in the pool.
#[derive(Debug, Clone)]
pub struct ExactUnison {
    pool: ExactPool,
    modes: usize,
}

impl ExactUnison {
    /// Diagonalise `spec`'s key for the step `1 / spec.sample_rate_hz` and set it on the board,
    /// its damper lifted.
    pub fn new(spec: &UnisonSpec) -> Result<ExactUnison, BuildError> {
        let key = ExactKey::new(spec)?;
        let modes = key.n_modes();
        let mut pool = ExactPool::from_keys(std::slice::from_ref(spec), [key].into(), 1)?;
        // Every mode stepped: the key's forces are read string by string.
        pool.set_voice_modes(crate::engine::VoiceModes::All);
        pool.assign(0, 0);
        pool.set_active(0, true);
        let modes = modes + pool.shared_modes();
        Ok(ExactUnison { pool, modes })
    }

    /// Complex modes: the key's (one of each conjugate pair, and each real mode) and the shared
    /// board's.
    pub fn n_modes(&self) -> usize {
        self.modes
    }

    pub fn step_s(&self) -> f64 {
        self.pool.step_s()
    }

    /// Whether the hammer is still part of the system.
    pub fn hammer_engaged(&self) -> bool {
        self.pool.hammer_on(0)
    }

    /// Launch the hammer in contact with the struck strings' current displacement, moving at the
    /// strike's speed (as the other engines do).
    pub fn strike(&mut self, strike: Strike) {
        self.pool.strike_voice(0, strike);
    }

    /// Lower or lift the damper (a key without one ignores it).
    pub fn set_damper(&mut self, down: bool) {
        self.pool.set_damper_voice(0, down);
    }

    /// Advance one step: exactly while the hammer is away, by ETDRK4 while it touches.
    pub fn step(&mut self) {
        self.pool.step();
    }

    /// Advance `sound.len()` steps, writing the board's radiating source of each channel
    /// (m^3/s) after each (by whole blocks once the hammer has left, as the pool does).
    pub fn run(&mut self, sound: &mut [[f64; crate::engine::spec::CHANNELS]]) {
        self.pool.run(sound, None);
    }

    /// Floating-point operations of one free step in a block: per complex mode of the key 6 to
    /// propagate and 4 per row read (two channels' sources, three forces) in the block's first
    /// pass, 6 and 4 per input (three directions) in its last; the Markov convolution (15 sums of
    /// `BLOCK / 2` taps on average); per shared mode 12 for the key's part of the interface and
    /// 24 for the board's step (its two sources); and the solve, `2 m^2`.
    pub fn flops_per_step(&self) -> f64 {
        let shared = self.pool.shared_modes() as f64;
        let own = self.modes as f64 - shared;
        let reads = kernels::READS as f64;
        let convolution = 2.0 * reads * 3.0 * kernels::BLOCK as f64 / 2.0;
        own * (6.0 + 4.0 * reads + 6.0 + 3.0 * 4.0) + convolution + shared * (36.0 + 2.0 * shared)
    }

    /// Net volume velocity of the board (m^3/s) after the last step.
    pub fn volume_velocity_m3_s(&self) -> f64 {
        self.pool.volume_velocity_m3_s()
    }

    /// The board's radiating source of each sound channel (m^3/s) after the last step.
    pub fn radiated_m3_s(&self) -> [f64; crate::engine::spec::CHANNELS] {
        self.pool.radiated_m3_s()
    }

    /// Forces and volume velocity now (Eq. 19).
    pub fn observe(&self) -> Observation {
        Observation {
            volume_velocity_m3_s: self.volume_velocity_m3_s(),
            ..self.pool.observe_voice(0)
        }
    }
}

/// A repeatable stream of numbers in [-0.5, 0.5) for the engine's tests, from `seed`: a 64-bit
/// linear congruential generator (Knuth's MMIX constants), its top 53 bits.
#[cfg(test)]
pub(crate) fn test_numbers(mut seed: u64) -> impl FnMut() -> f64 {
    move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::preset::Preset;

    /// c2 cut down to a few modes (so that five decompositions take no time), at `rate_hz`: its
    /// board's 24 highest modes, all in the key's own (no shared mode: the interface's
    /// second-order error left out of the contact step's).
    fn small_c2(rate_hz: f64) -> UnisonSpec {
        let mut spec = Preset::resolve("c2").unwrap().unison_spec();
        spec.modes.modes_t = 24;
        spec.modes.modes_p = 24;
        spec.modes.modes_l = 2;
        let b = &mut spec.board;
        let drop = b.len() - 24;
        b.retain(|k| k >= drop);
        assert!(b.freq_hz.iter().all(|&f| f >= interface::SHARED_BELOW_HZ));
        spec.sample_rate_hz = rate_hz;
        spec
    }

    /// The hammer's position 0.5 ms into its contact (it lasts ~2 ms), struck at 2.5 m/s.
    fn hammer_at(rate_hz: f64) -> f64 {
        let mut u = ExactUnison::new(&small_c2(rate_hz)).unwrap();
        u.strike(Strike {
            velocity_m_s: 2.5,
            shift: 0.0,
        });
        for _ in 0..(0.5e-3 * rate_hz).round() as usize {
            u.step();
        }
        assert!(u.hammer_engaged());
        u.pool.hammer_position_m(0)
    }

    #[test]
    fn the_fast_passes_agree_with_the_portable_ones() {
        // c2 struck, 2 s: its contact (the hammer's steps' passes) and its tail (the block
        // passes) through the AVX2 and AVX-512 passes (where the CPU has them) and the portable
        // ones: the same to single-precision rounding (the block passes run in f32).
        let mut spec = Preset::resolve("c2").unwrap().unison_spec();
        spec.sample_rate_hz = 48_000.0;
        let at_rest = ExactUnison::new(&spec).unwrap();
        let render = |simd: kernels::Simd| {
            let mut u = at_rest.clone();
            u.pool.set_simd(simd);
            u.strike(Strike {
                velocity_m_s: 2.5,
                shift: 0.0,
            });
            let mut x = vec![[0.0; 2]; 96_000];
            u.run(&mut x);
            assert!(!u.hammer_engaged());
            x.concat()
        };
        let portable = render(kernels::Simd::Portable);
        let peak = portable.iter().fold(0f64, |m, x| m.max(x.abs()));
        let detected = kernels::Simd::detect();
        for simd in [kernels::Simd::Avx2, kernels::Simd::Avx512] {
            if detected == kernels::Simd::Portable
                || (simd == kernels::Simd::Avx512 && detected != simd)
            {
                println!("{simd:?}: not on this CPU");
                continue;
            }
            let worst = render(simd)
                .iter()
                .zip(&portable)
                .fold(0f64, |m, (x, y)| m.max((x - y).abs()))
                / peak;
            println!("{simd:?} vs portable: {worst:.1e} of the peak over 2 s");
            assert!(worst < 1e-5, "{simd:?}: {worst:e}");
        }
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
