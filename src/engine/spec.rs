//! The plain data that crosses the engine's modules: what a key is made of ([`UnisonSpec`]), how it
//! is struck ([`Strike`]), what is read from it ([`Observation`], [`Energy`]), why it cannot be
//! built ([`BuildError`]), and the state of a pool's linear part ([`LinearState`]).

use crate::engine::physics::contact::Contact;
use crate::engine::physics::damper::DamperParams;
use crate::engine::physics::hammer::{FeltLaw, HammerParams};
use crate::engine::physics::soundboard::{BridgePoint, DroppedModes, SoundboardModes};
use crate::engine::physics::string::{ModeSet, StringParams};
use std::f64::consts::PI;

pub use crate::engine::physics::Direction;

/// The most strings a unison can hold (a treble trichord).
pub const MAX_STRINGS: usize = 3;

/// Output channels the engines radiate, left and right: each the sound at one listener over the
/// board ([`crate::engine::physics::soundboard::SoundboardModes::heard`]), the same one in both
/// for a mono piano.
pub const CHANNELS: usize = 2;

/// Everything needed to build one key of a voice pool; plain data, every field public.
#[derive(Debug, Clone)]
pub struct UnisonSpec {
    /// The strings of the unison (1 to 3), which differ only in tension.
    pub strings: Vec<StringParams>,
    pub modes: ModeSet,
    /// Damping per unit length on the duplex segment, c_d (N s/m^2) (Eq. 13).
    pub duplex_damping_n_s_m2: f64,
    pub hammer: HammerParams,
    /// The key's damper; `None` for the top keys, which have none.
    pub damper: Option<DamperParams>,
    pub contact: Contact,
    /// The reduced soundboard and the index of the bridge point where this unison rests.
    pub board: SoundboardModes,
    pub bridge_point: usize,
    /// The board's dropped modes at the bridge point, heard, not coupled
    /// ([`SoundboardModes::dropped_at`]); `None`: the reduced board's sound alone (the paper).
    pub dropped: Option<DroppedModes>,
    /// Internal (integration) rate (Hz).
    pub sample_rate_hz: f64,
}

impl UnisonSpec {
    /// Highest natural frequency among the retained modes (Hz), the paper's `f_max`.
    pub fn max_mode_freq_hz(&self) -> f64 {
        let strings = self.strings.iter().map(|s| {
            let t = s.transverse_omega(self.modes.modes_t.max(self.modes.modes_p));
            let l = s.longitudinal_omega(self.modes.modes_l);
            t.max(l) / (2.0 * PI)
        });
        let board = self.board.freq_hz.iter().copied();
        strings.chain(board).fold(0.0, f64::max)
    }

    /// The number of strings, 1 to [`MAX_STRINGS`].
    pub(crate) fn string_count(&self) -> Result<usize, BuildError> {
        let ns = self.strings.len();
        if ns == 0 || ns > MAX_STRINGS {
            return Err(BuildError::StringCount(ns));
        }
        Ok(ns)
    }

    /// The bridge point the unison rests on.
    pub(crate) fn bridge(&self) -> Result<&BridgePoint, BuildError> {
        self.board
            .points
            .get(self.bridge_point)
            .ok_or(BuildError::BridgePoint(self.bridge_point))
    }
}

/// Which of its modes a voice steps. An engine that steps them all (RK4) ignores it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum VoiceModes {
    /// As many as the sound needs: a chunk of modes that has died away is left to follow the
    /// bridge quasi-statically, and a voice whose damper is lifted steps at least the modes the
    /// board drives (every key ringing in sympathy costs only those).
    #[default]
    AsHeard,
    /// Those each voice steps now, and no fewer from here on (a linear map of the pool as it is).
    AsNow,
    /// Every mode of every voice.
    All,
}

/// How the hammer meets the unison.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Strike {
    /// Hammer speed when it reaches the strings (m/s).
    pub velocity_m_s: f64,
    /// The soft pedal's shift of the action when the key is struck, a fraction of the full shift:
    /// 0 the normal strike, 1 the una corda (the last string of the unison missed, the others in
    /// their neighbours' grooves), between them the felt's other parts
    /// ([`crate::engine::physics::felt_profile`]).
    pub shift: f64,
}

impl Strike {
    /// The felt law each string of a unison of `n_strings` meets (`None`: missed).
    pub fn felt_laws(
        &self,
        hammer: &HammerParams,
        n_strings: usize,
    ) -> [Option<FeltLaw>; MAX_STRINGS] {
        std::array::from_fn(|s| {
            (s < n_strings)
                .then(|| hammer.profile.law(hammer, n_strings, s, self.shift))
                .flatten()
        })
    }
}

/// Physical outputs read from the state (Eq. 19).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Observation {
    /// Felt force on each string (N), zero for strings the hammer does not touch (Eq. 8).
    pub hammer_force_n: [f64; MAX_STRINGS],
    /// Force each string exerts on the bridge, per direction T, L, P (N) (Eq. 6).
    pub bridge_force_n: [[f64; 3]; MAX_STRINGS],
    /// Total force on the soundboard per direction (N): the sum over strings.
    pub total_force_n: [f64; 3],
    /// Velocity of the bridge point per direction (m/s).
    pub bridge_velocity_m_s: [f64; 3],
    /// Net volume velocity of the board (m^3/s), the source of the radiated sound (DESIGN.md §1.7).
    pub volume_velocity_m3_s: f64,
}

/// Mechanical energy split by part (J).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Energy {
    pub strings_j: f64,
    pub board_j: f64,
    pub contact_j: f64,
    pub hammer_j: f64,
}

impl Energy {
    pub fn total_j(&self) -> f64 {
        self.strings_j + self.board_j + self.contact_j + self.hammer_j
    }
}

/// Why a voice pool cannot be built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum BuildError {
    #[error("a unison holds 1 to {MAX_STRINGS} strings, got {0}")]
    StringCount(usize),
    #[error("bridge point index {0} is not in the soundboard model")]
    BridgePoint(usize),
    #[error("keys of one instrument must share one soundboard and one internal rate")]
    SharedBoard,
    #[error("an instrument needs at least one key and one voice")]
    NoVoice,
    #[error("{keys} prepared keys for {specs} key specifications")]
    PreparedKeys { specs: usize, keys: usize },
    #[error("the duplex damping matrix cannot be factored (non-finite string parameters?)")]
    Duplex,
    #[error("the complex modes of a string direction or the board cannot be computed (non-finite parameters?)")]
    Modes,
    #[error(
        "RK4 would be unstable: the stiffest coupled mode (≈{freq_hz:.0} Hz) gives omega h = {omega_h:.2} \
         above the limit 2.78 at {rate_hz:.0} Hz; raise the internal rate or soften the contact"
    )]
    Unstable {
        freq_hz: f64,
        omega_h: f64,
        rate_hz: f64,
    },
}

/// Length of the fade that takes a stolen voice off the board (s): long enough not to click
/// (a raised cosine over 5 ms has no energy above ~200 Hz beyond the sound itself), short enough
/// that the new note's delay stays below what a pianist feels.
pub const STEAL_FADE_S: f64 = 0.005;

/// The state of a pool's linear part (strings on their contact springs and the board), flattened
/// in an engine's own coordinates, with the voice each entry belongs to (`None`: the board) and
/// the energy it holds per unit squared (J, the diagonal of the energy's quadratic form, to tell
/// where a mode's energy sits). While no hammer touches a string, one step of the engine is a
/// linear map of it ([`crate::analysis::stability`] forms that map).
#[derive(Debug, Clone, Default)]
pub struct LinearState {
    pub x: Vec<f64>,
    pub owner: Vec<Option<usize>>,
    pub energy_weight: Vec<f64>,
}

impl LinearState {
    pub(crate) fn push(&mut self, owner: Option<usize>, x: &[f64], weight: &[f64]) {
        self.x.extend_from_slice(x);
        self.owner.extend(std::iter::repeat_n(owner, x.len()));
        self.energy_weight.extend_from_slice(&weight[..x.len()]);
    }
}

/// Default retirement threshold: about 100 dB below the energy a mezzo-forte hammer brings
/// (≈ 0.02 J). A retired voice leaves the board, and a string at rest on a moving board holds the
/// energy of following it, so this also bounds the jolt its leaving gives the board: at 1e-10 J
/// retiring the nine-key chord's treble voices while its bass still rang raised the decaying tail
/// from −64 to −59 dBFS (`tests/stability.rs`).
pub const SILENCE_J: f64 = 1e-12;
