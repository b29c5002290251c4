//! Pure physics: no I/O, no threads, no allocation after a pool is built.
//!
//! - [`physics`]: one module per physical part of the paper's model — the stiff strings in T, P
//!   and L (Eq. 1–3), the duplex damper (Eq. 13), the reduced modal soundboard (Eq. 4–5), the
//!   string–bridge contact (Eq. 6–7), the felt hammer (Eq. 8–9), the damper felt;
//! - [`rk4`]: their state-space assembly (Eq. 10–19) advanced with classical RK4 at the paper's
//!   rate ([`Rk4Pool`], the reference), and the paper's literal dense form it is checked against;
//! - [`exact`]: each key's coupled modes advanced exactly at the output rate, the keys met at the
//!   bridges by one shared board ([`exact::ExactPool`], the engine `play` and `render --midi` use);
//! - [`pool`]: the policy both pools share (assign, steal, strike, dampers, retire, reset);
//! - [`kernels`], [`parallel`]: SIMD kernels and the two-core split;
//! - [`tuning`]: the coupled first partial, from the undamped linear system.

pub mod exact;
pub mod fir;
pub mod kernels;
pub(crate) mod modal;
pub mod parallel;
pub mod physics;
pub mod pool;
pub mod rk4;
pub mod spec;
pub mod tuning;

pub use parallel::Pair;
pub use pool::Policy;
pub use rk4::Rk4Pool;
pub use spec::{
    BuildError, Direction, Energy, LinearState, Observation, Strike, UnisonSpec, VoiceModes,
    CHANNELS, MAX_STRINGS, SILENCE_J, STEAL_FADE_S,
};

/// A pool of voices on one shared board, as the player and the audio callback drive it: RK4 at
/// the paper's rate ([`Rk4Pool`], the reference) or each key's coupled modes advanced exactly
/// at the output rate ([`exact::ExactPool`]). The pool policy (assign, steal, strike,
/// dampers, retire, reset) is [`Policy`], written once for both; this is the rest.
pub trait VoicePool: Policy + Clone + Send + std::fmt::Debug + 'static {
    /// One key's coefficients, prepared before the pool is built.
    type Key: Send + Sync + StoredKey;
    /// `spec` at the rate this engine steps at: unchanged (the internal rate), or `output_rate_hz`
    /// for an engine that steps at the output rate.
    fn at_engine_rate(spec: UnisonSpec, output_rate_hz: f64) -> UnisonSpec;
    /// Prepare one key from its spec at the engine's rate (the costly part of building,
    /// independent from key to key: callers may prepare keys on several threads).
    fn prepare_key(spec: &UnisonSpec) -> Result<Self::Key, BuildError>;
    /// The pool for `specs` (at the engine's rate, one per key, in order with `keys`) with
    /// `voices` voices.
    fn from_keys(
        specs: &[UnisonSpec],
        keys: std::sync::Arc<[Self::Key]>,
        voices: usize,
    ) -> Result<Self, BuildError>;
    /// Prepare every key in turn, then build the pool.
    fn build_pool(
        specs: &[UnisonSpec],
        voices: usize,
        output_rate_hz: f64,
    ) -> Result<Self, BuildError> {
        let specs: Vec<_> = specs
            .iter()
            .map(|s| Self::at_engine_rate(s.clone(), output_rate_hz))
            .collect();
        let keys = specs
            .iter()
            .map(Self::prepare_key)
            .collect::<Result<Vec<_>, _>>()?;
        Self::from_keys(&specs, keys.into(), voices)
    }
    fn step_s(&self) -> f64;
    fn step(&mut self);
    /// Advance `sound.len()` steps, writing the board's radiating source of each channel
    /// (m^3/s: its net volume velocity, or its equivalent at the channel's listener) after each;
    /// an engine that can split its voices over two cores does so through `pair`.
    fn run(&mut self, sound: &mut [[f64; CHANNELS]], pair: Option<&dyn Pair>);
    /// The radiating source of each channel after the last step (m^3/s).
    fn radiated_m3_s(&self) -> [f64; CHANNELS];
    fn observe_voice(&self, k: usize) -> Observation;
    fn bytes_per_voice(&self) -> usize;
    /// The linear part's state: the active voices' strings, then the board.
    fn linear_state(&self) -> LinearState;
    /// Set the state [`VoicePool::linear_state`] reads (`x` in its layout).
    fn set_linear_state(&mut self, x: &[f64]);
    /// Mechanical energy of the strings, their contact springs and the board (J), hammers apart.
    fn mechanical_energy_j(&self) -> f64;
    /// Modes the active voices step now, where the engine steps fewer than all of them (the
    /// exact engine: [`exact::ExactPool::modes_stepped`]); `None` for an engine that always
    /// steps every mode.
    fn modes_stepped(&self) -> Option<usize> {
        None
    }
    /// Which of their modes the voices step from now on ([`VoiceModes`]; by default as many
    /// as the sound needs). An engine that steps them all ignores it.
    fn set_voice_modes(&mut self, _modes: VoiceModes) {}
    /// Whether anything reads the voices' energies ([`Policy::voice_energy_j`],
    /// [`VoicePool::mechanical_energy_j`]) before the next [`VoicePool::run`] after this one:
    /// an engine that works them out as it steps, while each voice's modes are in cache, then
    /// leaves them to be worked out on demand. It holds for the next run only; by default they
    /// are read after every run.
    fn energies_read_after_run(&mut self, _read: bool) {}
    /// Whether energy may enter the strings now: a hammer is in play (from the strike until it
    /// is released) or a stolen voice is fading (its contact springs change).
    fn is_driven(&self) -> bool {
        (0..self.n_voices()).any(|k| self.hammer_on(k) || self.is_fading(k))
    }
}

/// A key's prepared coefficients as bytes, for an engine whose keys are costly to prepare, so
/// that a front end may keep them between runs (the engine does no I/O). By default a key is
/// not kept.
pub trait StoredKey: Sized {
    /// The engine's name in the store; `None`: its keys are cheap and never kept.
    const STORE: Option<&'static str> = None;
    /// The source of everything that decides the coefficients beside the spec: a stored key
    /// is used only by a build of the same source.
    const SOURCE: &'static [&'static str] = &[];
    fn to_bytes(&self) -> Vec<u8> {
        Vec::new()
    }
    /// The key [`StoredKey::to_bytes`] wrote for `spec`, or why the bytes are not one.
    fn from_bytes(_spec: &UnisonSpec, _bytes: &[u8]) -> Result<Self, StoredKeyError> {
        Err(StoredKeyError::Layout)
    }
}

/// Why bytes are not a stored key of a spec.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum StoredKeyError {
    /// Not laid out as this build writes this spec's key: another version, cut short or longer,
    /// or counts (modes, strings, damper channels) that are another key's.
    #[error("the bytes are not laid out as this key's")]
    Layout,
    /// Laid out right, but no key of this engine has such values: a mode that grows, a value
    /// that is not a finite number, a negative energy (a key read back is played as it is, so it
    /// is checked first).
    #[error("the bytes do not describe a key that can be played")]
    Meaning,
}

impl StoredKey for rk4::Rk4Key<f64> {}

impl StoredKey for exact::ExactKey {
    const STORE: Option<&'static str> = Some("exact");
    const SOURCE: &'static [&'static str] = &[
        include_str!("exact/key.rs"),
        include_str!("exact/interface.rs"),
        include_str!("exact/kernels.rs"),
        include_str!("exact/bytes.rs"),
        include_str!("modal.rs"),
        include_str!("spec.rs"),
        include_str!("physics/contact.rs"),
        include_str!("physics/damper.rs"),
        include_str!("physics/duplex.rs"),
        include_str!("physics/hammer.rs"),
        include_str!("physics/soundboard.rs"),
        include_str!("physics/string.rs"),
    ];
    fn to_bytes(&self) -> Vec<u8> {
        exact::ExactKey::to_bytes(self)
    }
    fn from_bytes(spec: &UnisonSpec, bytes: &[u8]) -> Result<Self, StoredKeyError> {
        exact::ExactKey::from_bytes(spec, bytes)
    }
}

/// Both pools implement [`VoicePool`] with their own inherent methods.
macro_rules! voice_pool {
    ($t:ty, $key:ty, $rate:expr $(, $extra:item)*) => {
        impl VoicePool for $t {
            type Key = $key;
            fn at_engine_rate(spec: UnisonSpec, output_rate_hz: f64) -> UnisonSpec {
                match $rate(output_rate_hz) {
                    Some(sample_rate_hz) => UnisonSpec {
                        sample_rate_hz,
                        ..spec
                    },
                    None => spec,
                }
            }
            fn prepare_key(spec: &UnisonSpec) -> Result<Self::Key, BuildError> {
                <$t>::prepare_key(spec)
            }
            fn from_keys(
                specs: &[UnisonSpec],
                keys: std::sync::Arc<[Self::Key]>,
                voices: usize,
            ) -> Result<Self, BuildError> {
                <$t>::from_keys(specs, keys, voices)
            }
            fn step_s(&self) -> f64 {
                <$t>::step_s(self)
            }
            fn step(&mut self) {
                <$t>::step(self)
            }
            fn run(&mut self, sound: &mut [[f64; CHANNELS]], pair: Option<&dyn Pair>) {
                <$t>::run(self, sound, pair)
            }
            fn radiated_m3_s(&self) -> [f64; CHANNELS] {
                <$t>::radiated_m3_s(self)
            }
            fn observe_voice(&self, k: usize) -> Observation {
                <$t>::observe_voice(self, k)
            }
            fn bytes_per_voice(&self) -> usize {
                <$t>::bytes_per_voice(self)
            }
            fn linear_state(&self) -> LinearState {
                <$t>::linear_state(self)
            }
            fn set_linear_state(&mut self, x: &[f64]) {
                <$t>::set_linear_state(self, x)
            }
            fn mechanical_energy_j(&self) -> f64 {
                <$t>::mechanical_energy_j(self)
            }
            $($extra)*
        }
    };
}

voice_pool!(Rk4Pool, rk4::Rk4Key<f64>, |_| None::<f64>);
voice_pool!(
    exact::ExactPool,
    exact::ExactKey,
    Some::<f64>,
    fn set_voice_modes(&mut self, modes: VoiceModes) {
        exact::ExactPool::set_voice_modes(self, modes)
    },
    fn modes_stepped(&self) -> Option<usize> {
        Some(exact::ExactPool::modes_stepped(self))
    },
    fn energies_read_after_run(&mut self, read: bool) {
        exact::ExactPool::energies_read_after_run(self, read)
    }
);

/// What the offline renderer needs of a one-key engine: RK4 on [`Rk4Pool`] (the reference, at
/// the paper's rate) or the exact engine on [`exact::ExactUnison`] (at the output rate).
pub trait Engine {
    /// Advance one internal step.
    fn step(&mut self);
    /// Forces and volume velocity now (Eq. 19), of the first voice.
    fn observe(&self) -> Observation;
    /// The board's radiating source of each sound channel now (m^3/s).
    fn radiated_m3_s(&self) -> [f64; CHANNELS];
    fn strike(&mut self, strike: Strike);
    fn set_damper(&mut self, down: bool);
    /// Internal step (s).
    fn step_s(&self) -> f64;
    /// How many steps the radiating source lags the state (the exact engine's correction of its
    /// shared board's source, [`exact::ExactPool::source_delay_steps`]).
    fn source_delay_steps(&self) -> usize {
        0
    }
}

impl Engine for Rk4Pool {
    fn step(&mut self) {
        Rk4Pool::step(self)
    }
    fn observe(&self) -> Observation {
        Rk4Pool::observe(self)
    }
    fn radiated_m3_s(&self) -> [f64; CHANNELS] {
        Rk4Pool::radiated_m3_s(self)
    }
    fn strike(&mut self, strike: Strike) {
        Rk4Pool::strike(self, strike)
    }
    fn set_damper(&mut self, down: bool) {
        Rk4Pool::set_damper(self, down)
    }
    fn step_s(&self) -> f64 {
        Rk4Pool::step_s(self)
    }
}

impl Engine for exact::ExactUnison {
    fn step(&mut self) {
        exact::ExactUnison::step(self)
    }
    fn observe(&self) -> Observation {
        exact::ExactUnison::observe(self)
    }
    fn radiated_m3_s(&self) -> [f64; CHANNELS] {
        exact::ExactUnison::radiated_m3_s(self)
    }
    fn strike(&mut self, strike: Strike) {
        exact::ExactUnison::strike(self, strike)
    }
    fn set_damper(&mut self, down: bool) {
        exact::ExactUnison::set_damper(self, down)
    }
    fn step_s(&self) -> f64 {
        exact::ExactUnison::step_s(self)
    }
    fn source_delay_steps(&self) -> usize {
        exact::ExactPool::source_delay_steps()
    }
}

/// How a render integrates: the paper's RK4 at `min_rate_over_fmax × f_max` (the reference), or
/// the key's coupled modes advanced exactly ([`exact`]) at the output rate (`tests/integrators.rs`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Integrator {
    #[default]
    Rk4,
    Exact,
}
