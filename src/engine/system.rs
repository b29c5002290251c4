//! The assembled state-space system of one unison (paper Eq. 10–19), advanced with classical RK4.
//!
//! The state `x = (q_1 .. q_n, q_b, qdot_1 .. qdot_n, qdot_b, y_H, ydot_H)` is held as two flat
//! arrays `q`, `v` over all modes, laid out per string as `[T | P | L]` and then the board. Every
//! block of the paper's `A` (Eq. 11) is diagonal except the duplex damping, and all coupling passes
//! through rank-3 bridge projections and the rank-1 hammer projection (Eq. 14–18), so one
//! evaluation of the right-hand side costs O(modes) plus the dense duplex product (Eq. 13):
//! ```text
//! qdd_i = -Omega_i^2 q_i - (C_i + C_d) qdot_i - Phi_s^T F_i + [struck] psi_e F_e,i
//! qdd_b = -Omega_b^2 q_b - C_b qdot_b + Phi_b^T sum_i F_i
//! ydd_H = -(1/m_H) sum_i F_e,i
//! ```

use super::contact::Contact;
use super::damper::DamperParams;
use super::duplex::duplex_damping_matrix;
use super::hammer::HammerParams;
use super::soundboard::SoundboardModes;
use super::string::{ModeSet, StringParams};
use super::MAX_STRINGS;
use std::f64::consts::PI;
use std::ops::Range;

/// Everything needed to build a [`Instrument`]; plain data, every field public.
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
}

/// How the hammer meets the unison.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Strike {
    /// Hammer speed when it reaches the strings (m/s).
    pub velocity_m_s: f64,
    /// Soft pedal: the hammer misses the last string of the unison (one of two, two of three).
    pub una_corda: bool,
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

/// Coefficients of one key: its strings' modes (laid out from 0), hammer, damper and bridge point.
/// Built once; a voice playing the key copies the per-mode arrays into its own slot.
#[derive(Debug, Clone)]
struct KeyModel {
    n_strings: usize,
    /// `ranges[s][d]`: modes of string `s` in direction `d` (T, L, P), from the key's first mode.
    ranges: [[Range<usize>; 3]; MAX_STRINGS],
    n_modes: usize,
    omega2: Vec<f64>,
    damp: Vec<f64>,
    bridge_shape: Vec<f64>,
    /// Board modes: `phi_T`, `phi_L`, `phi_P` at this key's bridge point (Eq. 5).
    board_shape: [Vec<f64>; 3],
    /// `psi_n(L_e)` of the T modes (identical for every string: same length).
    hammer_shape: Vec<f64>,
    /// `psi_n(x_d)` of the transverse modes, and the felt's coefficient (N s/m); empty without damper.
    damper_shape: Vec<f64>,
    damper_n_s_m: f64,
    /// Dense duplex matrix, `duplex_n × duplex_n` (Eq. 13).
    duplex: Vec<f64>,
    duplex_n: usize,
    hammer: HammerParams,
    contact: Contact,
}

/// One voice of the pool: a fixed slot of `capacity` modes in the flat arrays, playing one key.
#[derive(Debug, Clone)]
struct Voice {
    base: usize,
    key: Option<usize>,
    /// The key's `ranges` moved to this slot.
    ranges: [[Range<usize>; 3]; MAX_STRINGS],
    n_strings: usize,
    n_modes: usize,
}

/// Coefficients of the system: the key bank, where each voice sits and what it plays, the board.
#[derive(Debug, Clone)]
struct Model {
    keys: Vec<KeyModel>,
    voices: Vec<Voice>,
    board: Range<usize>,
    omega2: Vec<f64>,
    /// `2 zeta omega` per mode (1/s).
    damp: Vec<f64>,
    /// String modes: `psi_n(L_s)` in the mode's own direction; zero over the board block.
    bridge_shape: Vec<f64>,
    board_volume: Vec<f64>,
    h: f64,
}

/// What each voice is doing, apart from its modes; read by every evaluation.
#[derive(Debug, Clone)]
struct VoiceFlags {
    /// Simulated at all: a voice joins when struck or its damper is lifted, and leaves when it
    /// falls silent ([`Instrument::retire_silent`]).
    active: Vec<bool>,
    hammer_on: Vec<bool>,
    struck: Vec<[bool; MAX_STRINGS]>,
    damper_down: Vec<bool>,
    /// Scale of the voice's contact forces (1, or falling to 0 while the voice is stolen).
    coupling: Vec<f64>,
    /// Steps left in the fade of a stolen voice, and the key and strike that follow it.
    fade_left: Vec<u32>,
    pending: Vec<Option<(usize, Strike)>>,
}

/// Strings of up to 88 keys on one shared soundboard (paper Eq. 10, the board coupling every
/// string of every sounding key), with their hammers and dampers.
///
/// The instrument holds a bank of keys and a fixed pool of voices. A voice is a slot in the flat
/// state arrays that plays one key at a time at that key's bridge point; [`Instrument::assign`]
/// gives a free voice a key (copying coefficients, no allocation) and [`Instrument::steal`] fades a
/// sounding voice off the board before handing it to another key. Built for one key with
/// [`Instrument::new`] (the paper's system), one voice per key with [`Instrument::with_keys`], or
/// with a pool of any size with [`Instrument::with_pool`]. Only active voices are simulated.
#[derive(Debug, Clone)]
pub struct Instrument {
    model: Model,
    q: Vec<f64>,
    v: Vec<f64>,
    hammer_y: Vec<f64>,
    hammer_v: Vec<f64>,
    flags: VoiceFlags,
    voice_of_key: Vec<Option<usize>>,
    /// Mode ranges simulated in this step: the active voices' and the board's.
    live: Vec<Range<usize>>,
    fade_steps: u32,
    // RK4 scratch, sized once.
    qs: Vec<f64>,
    vs: Vec<f64>,
    acc: Vec<f64>,
    sum_q: Vec<f64>,
    sum_v: Vec<f64>,
    hy_s: Vec<f64>,
    hv_s: Vec<f64>,
    sum_hy: Vec<f64>,
    sum_hv: Vec<f64>,
    ah: Vec<f64>,
    fast_path: bool,
    time_s: f64,
}

/// Why an [`Instrument`] cannot be built.
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

/// One key's coefficients, its modes laid out from 0.
fn build_key(spec: &UnisonSpec) -> Result<KeyModel, BuildError> {
    let ns = spec.strings.len();
    if ns == 0 || ns > MAX_STRINGS {
        return Err(BuildError::StringCount(ns));
    }
    let point = spec
        .board
        .points
        .get(spec.bridge_point)
        .ok_or(BuildError::BridgePoint(spec.bridge_point))?;
    let ModeSet {
        modes_t: nt,
        modes_p: np,
        modes_l: nl,
        ..
    } = spec.modes;
    let per_string = nt + np + nl;
    let n_modes = ns * per_string;
    let (mut omega2, mut damp, mut bridge_shape) =
        (vec![0.0; n_modes], vec![0.0; n_modes], vec![0.0; n_modes]);
    let mut ranges: [[Range<usize>; 3]; MAX_STRINGS] = Default::default();
    for (s, string) in spec.strings.iter().enumerate() {
        let b = s * per_string;
        // Flat layout [T | P | L]; direction index d is T = 0, L = 1, P = 2.
        ranges[s] = [b..b + nt, b + nt + np..b + per_string, b + nt..b + nt + np];
        let ls = string.speaking_length_m;
        let blocks: [(usize, f64, bool); 3] = [
            (0, spec.modes.damping_ratio_t, true),
            (2, spec.modes.damping_ratio_p, true),
            (1, spec.modes.damping_ratio_l, false),
        ];
        for (d, zeta, transverse) in blocks {
            for (k, i) in ranges[s][d].clone().enumerate() {
                let w = if transverse {
                    string.transverse_omega(k + 1)
                } else {
                    string.longitudinal_omega(k + 1)
                };
                omega2[i] = w * w;
                damp[i] = 2.0 * zeta * w;
                bridge_shape[i] = string.mode_shape(k + 1, ls);
            }
        }
    }
    let s0 = &spec.strings[0];
    let strike_x = spec.hammer.strike_ratio * s0.speaking_length_m;
    let (damper_shape, damper_n_s_m) = match spec.damper {
        Some(d) => {
            let x = d.position_ratio * s0.speaking_length_m;
            (
                (1..=nt.max(np)).map(|k| s0.mode_shape(k, x)).collect(),
                d.damping_n_s_m,
            )
        }
        None => (Vec::new(), 0.0),
    };
    let duplex_n = nt.max(np);
    // The stiffest coupled mode: a string's bridge point on its contact spring, with the
    // effective point mass of the retained modes, 1 / sum psi_n(L_s)^2 (DESIGN.md §5).
    let h = 1.0 / spec.sample_rate_hz;
    let inv_mass: f64 = ranges[0][0].clone().map(|i| bridge_shape[i].powi(2)).sum();
    let k_max = spec
        .contact
        .stiffness_n_m
        .iter()
        .copied()
        .fold(0.0, f64::max);
    let w_top = omega2.iter().copied().fold(0.0, f64::max);
    let w_contact = (k_max * inv_mass + w_top).sqrt();
    if w_contact * h > 2.78 {
        return Err(BuildError::Unstable {
            freq_hz: w_contact / (2.0 * PI),
            omega_h: w_contact * h,
            rate_hz: spec.sample_rate_hz,
        });
    }
    Ok(KeyModel {
        n_strings: ns,
        ranges,
        n_modes,
        omega2,
        damp,
        bridge_shape,
        board_shape: point.shape.clone(),
        hammer_shape: (1..=nt).map(|k| s0.mode_shape(k, strike_x)).collect(),
        damper_shape,
        damper_n_s_m,
        duplex: duplex_damping_matrix(
            duplex_n,
            s0.length_m(),
            s0.speaking_length_m,
            spec.duplex_damping_n_s_m2,
            s0.linear_density_kg_m,
        ),
        duplex_n,
        hammer: spec.hammer,
        contact: spec.contact,
    })
}

impl Instrument {
    /// One unison on its bridge point (the paper's system), active from the start; precomputes
    /// every coefficient and allocates all state and scratch.
    pub fn new(spec: &UnisonSpec) -> Result<Instrument, BuildError> {
        let mut u = Self::with_keys(std::slice::from_ref(spec))?;
        u.flags.active[0] = true;
        Ok(u)
    }

    /// Several keys on one shared soundboard, one voice each: voice `k` plays `specs[k]` at its
    /// own bridge point. A voice is simulated once struck or its damper lifted.
    pub fn with_keys(specs: &[UnisonSpec]) -> Result<Instrument, BuildError> {
        let mut u = Self::with_pool(specs, specs.len())?;
        for k in 0..specs.len() {
            u.assign(k, k);
        }
        Ok(u)
    }

    /// A bank of keys (`specs`, all on the same board and internal rate) and a pool of `voices`
    /// voices, each large enough for any key; no voice plays a key yet.
    pub fn with_pool(specs: &[UnisonSpec], voices: usize) -> Result<Instrument, BuildError> {
        let first = specs.first().ok_or(BuildError::NoVoice)?;
        if voices == 0 {
            return Err(BuildError::NoVoice);
        }
        if specs
            .iter()
            .any(|s| s.board != first.board || s.sample_rate_hz != first.sample_rate_hz)
        {
            return Err(BuildError::SharedBoard);
        }
        let keys = specs.iter().map(build_key).collect::<Result<Vec<_>, _>>()?;
        let capacity = keys.iter().map(|k| k.n_modes).max().unwrap_or(0);
        let voice_slots: Vec<Voice> = (0..voices)
            .map(|i| Voice {
                base: i * capacity,
                key: None,
                ranges: Default::default(),
                n_strings: 0,
                n_modes: 0,
            })
            .collect();
        let strings_end = voices * capacity;
        let (mut omega2, mut damp, mut bridge_shape) = (
            vec![0.0; strings_end],
            vec![0.0; strings_end],
            vec![0.0; strings_end],
        );
        let board = strings_end..strings_end + first.board.len();
        for k in 0..first.board.len() {
            let w = 2.0 * PI * first.board.freq_hz[k];
            omega2.push(w * w);
            damp.push(2.0 * first.board.damping_ratio[k] * w);
            bridge_shape.push(0.0);
        }
        let n = omega2.len();
        let h = 1.0 / first.sample_rate_hz;
        let model = Model {
            keys,
            voices: voice_slots,
            board,
            omega2,
            damp,
            bridge_shape,
            board_volume: first.board.volume_m2_per_sqrt_kg.clone(),
            h,
        };
        Ok(Instrument {
            voice_of_key: vec![None; specs.len()],
            live: Vec::with_capacity(voices + 1),
            fade_steps: (STEAL_FADE_S / h).round().max(1.0) as u32,
            model,
            q: vec![0.0; n],
            v: vec![0.0; n],
            hammer_y: vec![0.0; voices],
            hammer_v: vec![0.0; voices],
            flags: VoiceFlags {
                active: vec![false; voices],
                hammer_on: vec![false; voices],
                struck: vec![[false; MAX_STRINGS]; voices],
                damper_down: vec![false; voices],
                coupling: vec![1.0; voices],
                fade_left: vec![0; voices],
                pending: vec![None; voices],
            },
            qs: vec![0.0; n],
            vs: vec![0.0; n],
            acc: vec![0.0; n],
            sum_q: vec![0.0; n],
            sum_v: vec![0.0; n],
            hy_s: vec![0.0; voices],
            hv_s: vec![0.0; voices],
            sum_hy: vec![0.0; voices],
            sum_hv: vec![0.0; voices],
            ah: vec![0.0; voices],
            fast_path: has_avx2_fma(),
            time_s: 0.0,
        })
    }

    /// Number of voices in the pool.
    pub fn n_voices(&self) -> usize {
        self.model.voices.len()
    }

    /// Number of keys in the bank.
    pub fn n_keys(&self) -> usize {
        self.model.keys.len()
    }

    /// Number of strings of voice 0.
    pub fn n_strings(&self) -> usize {
        self.model.voices[0].n_strings
    }

    /// Total number of modes (every voice's slot and the board).
    pub fn n_modes(&self) -> usize {
        self.q.len()
    }

    /// Integration step (s).
    pub fn step_s(&self) -> f64 {
        self.model.h
    }

    /// Simulated time since the system was built (s).
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Flat-array range of voice 0's string `s` in direction `d` (0 = T, 1 = L, 2 = P).
    pub fn string_range(&self, s: usize, d: usize) -> Range<usize> {
        self.model.voices[0].ranges[s][d].clone()
    }

    /// Flat-array range of the board's modes.
    pub fn board_range(&self) -> Range<usize> {
        self.model.board.clone()
    }

    /// Modal displacements and velocities, for setting initial conditions.
    pub fn state_mut(&mut self) -> (&mut [f64], &mut [f64]) {
        (&mut self.q, &mut self.v)
    }

    /// Modal displacements and velocities.
    pub fn state(&self) -> (&[f64], &[f64]) {
        (&self.q, &self.v)
    }

    /// Whether voice 0's hammer is still part of the system.
    pub fn hammer_engaged(&self) -> bool {
        self.flags.hammer_on[0]
    }

    /// The key voice `k` plays (an index into the bank), if any.
    pub fn key_of_voice(&self, k: usize) -> Option<usize> {
        self.model.voices[k].key
    }

    /// The voice that plays `key`, or will once its fade ends.
    pub fn voice_of_key(&self, key: usize) -> Option<usize> {
        self.voice_of_key[key]
    }

    /// Give voice `k` to `key`: the previous key loses it, the slot takes the key's coefficients
    /// and starts at rest, damper lifted, inactive until struck. Copies, never allocates.
    pub fn assign(&mut self, k: usize, key: usize) {
        if let Some(old) = self.model.voices[k].key {
            self.voice_of_key[old] = None;
        }
        let km = &self.model.keys[key];
        let voice = &mut self.model.voices[k];
        let (base, capacity_end) = (voice.base, voice.base + km.n_modes);
        let slot_end = self
            .model
            .voices
            .get(k + 1)
            .map_or(self.model.board.start, |v| v.base);
        debug_assert!(capacity_end <= slot_end);
        let voice = &mut self.model.voices[k];
        voice.key = Some(key);
        voice.n_strings = km.n_strings;
        voice.n_modes = km.n_modes;
        for (s, r) in voice.ranges.iter_mut().enumerate() {
            for d in 0..3 {
                let local = &km.ranges[s][d];
                r[d] = base + local.start..base + local.end;
            }
        }
        self.model.omega2[base..capacity_end].copy_from_slice(&km.omega2);
        self.model.damp[base..capacity_end].copy_from_slice(&km.damp);
        self.model.bridge_shape[base..capacity_end].copy_from_slice(&km.bridge_shape);
        self.q[base..slot_end].fill(0.0);
        self.v[base..slot_end].fill(0.0);
        self.voice_of_key[key] = Some(k);
        let f = &mut self.flags;
        (f.active[k], f.hammer_on[k], f.damper_down[k]) = (false, false, false);
        (f.coupling[k], f.fade_left[k], f.pending[k]) = (1.0, 0, None);
    }

    /// Hand sounding voice `k` to `key`: over [`STEAL_FADE_S`] its contact forces fall to zero
    /// with a raised cosine (the board is released smoothly, no click), then the voice takes `key`
    /// at rest and `strike` hits it. Stealing a voice already fading only replaces what follows.
    /// A voice that is not active is assigned and struck at once.
    pub fn steal(&mut self, k: usize, key: usize, strike: Strike) {
        if !self.flags.active[k] {
            self.assign(k, key);
            self.strike_voice(k, strike);
            return;
        }
        if let Some(old) = self.model.voices[k].key {
            if self.voice_of_key[old] == Some(k) {
                self.voice_of_key[old] = None;
            }
        }
        if let Some((old_pending, _)) = self.flags.pending[k] {
            if old_pending != key {
                self.voice_of_key[old_pending] = None;
            }
        }
        self.voice_of_key[key] = Some(k);
        if self.flags.fade_left[k] == 0 {
            self.flags.fade_left[k] = self.fade_steps;
        }
        self.flags.pending[k] = Some((key, strike));
        self.flags.damper_down[k] = false;
    }

    /// Whether voice `k` is fading out before it changes key.
    pub fn is_fading(&self, k: usize) -> bool {
        self.flags.fade_left[k] > 0
    }

    /// Mechanical energy in voice `k`'s strings (J): the measure of how loud it still is.
    pub fn voice_energy_j(&self, k: usize) -> f64 {
        let voice = &self.model.voices[k];
        let r = voice.base..voice.base + voice.n_modes;
        r.map(|i| 0.5 * (self.v[i] * self.v[i] + self.model.omega2[i] * self.q[i] * self.q[i]))
            .sum()
    }

    /// Stop simulating the voices that have fallen silent: strings below `threshold_j`, no hammer,
    /// no fade, and either the damper down or no damper at all (strings whose damper a key or
    /// pedal lifts keep ringing in sympathy). Their strings are set to rest; they keep their key
    /// until another key needs the voice. Returns how many were retired.
    pub fn retire_silent(&mut self, threshold_j: f64) -> usize {
        let mut retired = 0;
        for k in 0..self.n_voices() {
            let f = &self.flags;
            let Some(key) = self.model.voices[k].key else {
                continue;
            };
            let undamped = self.model.keys[key].damper_shape.is_empty();
            if f.active[k]
                && !f.hammer_on[k]
                && f.fade_left[k] == 0
                && (f.damper_down[k] || undamped)
                && self.voice_energy_j(k) < threshold_j
            {
                let voice = &self.model.voices[k];
                let r = voice.base..voice.base + voice.n_modes;
                self.q[r.clone()].fill(0.0);
                self.v[r].fill(0.0);
                self.flags.active[k] = false;
                retired += 1;
            }
        }
        retired
    }

    /// Strike voice 0 (see [`Instrument::strike_voice`]).
    pub fn strike(&mut self, strike: Strike) {
        self.strike_voice(0, strike);
    }

    /// Launch voice `k`'s hammer at its strings (Eq. 14–15): it starts touching the struck strings
    /// at their current displacement (a sounding key is re-struck in its motion) and moves towards
    /// them at `velocity_m_s`. A voice without a key ignores it.
    pub fn strike_voice(&mut self, k: usize, strike: Strike) {
        let voice = &self.model.voices[k];
        let Some(key) = voice.key else {
            return;
        };
        let km = &self.model.keys[key];
        let ns = voice.n_strings;
        let n_struck = if strike.una_corda && ns > 1 {
            ns - 1
        } else {
            ns
        };
        let mut struck = [false; MAX_STRINGS];
        let mut contact_y = f64::NEG_INFINITY;
        for s in 0..n_struck {
            struck[s] = true;
            let r = voice.ranges[s][0].clone();
            contact_y = contact_y.max(dot(&km.hammer_shape, &self.q[r]));
        }
        self.flags.struck[k] = struck;
        self.hammer_y[k] = contact_y;
        self.hammer_v[k] = strike.velocity_m_s;
        self.flags.hammer_on[k] = true;
        self.flags.active[k] = true;
    }

    /// Include voice `k` in the simulation without striking it (a key held silently, or every key
    /// under the sustain pedal, whose strings then ring in sympathy through the board), or leave it
    /// out. A left-out voice keeps its state frozen; a voice without a key stays out.
    pub fn set_active(&mut self, k: usize, active: bool) {
        let f = &mut self.flags;
        f.active[k] =
            self.model.voices[k].key.is_some() && (active || f.hammer_on[k] || f.fade_left[k] > 0);
    }

    /// Whether voice `k` is simulated.
    pub fn is_active(&self, k: usize) -> bool {
        self.flags.active[k]
    }

    /// Lower or lift voice 0's damper (see [`Instrument::set_damper_voice`]).
    pub fn set_damper(&mut self, down: bool) {
        self.set_damper_voice(0, down);
    }

    /// Lower (key released) or lift (key down, or a pedal holding it) voice `k`'s damper. Keys
    /// without a damper ignore it. For a fading voice it applies to the key that follows.
    pub fn set_damper_voice(&mut self, k: usize, down: bool) {
        let key = match self.flags.pending[k] {
            Some((key, _)) => Some(key),
            None => self.model.voices[k].key,
        };
        let has_damper = key.is_some_and(|key| !self.model.keys[key].damper_shape.is_empty());
        self.flags.damper_down[k] = down && has_damper;
    }

    /// Whether voice 0's damper rests on the strings.
    pub fn damper_down(&self) -> bool {
        self.flags.damper_down[0]
    }

    /// Advance one RK4 step; never allocates.
    pub fn step(&mut self) {
        self.live.clear();
        for (k, voice) in self.model.voices.iter().enumerate() {
            if self.flags.active[k] {
                self.live.push(voice.base..voice.base + voice.n_modes);
            }
        }
        self.live.push(self.model.board.clone());
        #[cfg(target_arch = "x86_64")]
        if self.fast_path {
            // SAFETY: `fast_path` is set only when the CPU reports AVX2 and FMA.
            unsafe { self.step_avx2() };
            self.advance_fades();
            return;
        }
        self.step_impl::<false>();
        self.advance_fades();
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn step_avx2(&mut self) {
        self.step_impl::<true>();
    }

    /// Classical RK4 over `(q, v, y_H, ydot_H)` of the active voices and the board, stage sums
    /// accumulated in place. `SIMD` selects the explicit AVX2 + FMA kernels; it is true only on
    /// the path entered after detecting them.
    #[inline(always)]
    fn step_impl<const SIMD: bool>(&mut self) {
        let h = self.model.h;
        let (m, flags, live) = (&self.model, &self.flags, &self.live);
        let (q0, v0, hy0, hv0) = (&self.q, &self.v, &self.hammer_y, &self.hammer_v);
        let (qs, vs, acc) = (&mut self.qs, &mut self.vs, &mut self.acc);
        let (sum_q, sum_v) = (&mut self.sum_q, &mut self.sum_v);
        let (hy_s, hv_s, sum_hy, sum_hv, ah) = (
            &mut self.hy_s,
            &mut self.hv_s,
            &mut self.sum_hy,
            &mut self.sum_hv,
            &mut self.ah,
        );
        // Stage 1 at the current state.
        evaluate::<SIMD>(m, flags, live, q0, v0, hy0, acc, ah);
        for r in live {
            for i in r.clone() {
                sum_q[i] = v0[i];
                sum_v[i] = acc[i];
                qs[i] = q0[i] + 0.5 * h * v0[i];
                vs[i] = v0[i] + 0.5 * h * acc[i];
            }
        }
        for k in 0..hy0.len() {
            sum_hy[k] = hv0[k];
            sum_hv[k] = ah[k];
            hy_s[k] = hy0[k] + 0.5 * h * hv0[k];
            hv_s[k] = hv0[k] + 0.5 * h * ah[k];
        }
        // Stages 2 and 3: weights 2, next stage at h/2 then h.
        for c in [0.5, 1.0] {
            evaluate::<SIMD>(m, flags, live, qs, vs, hy_s, acc, ah);
            for r in live {
                for i in r.clone() {
                    let vsi = vs[i];
                    sum_q[i] += 2.0 * vsi;
                    sum_v[i] += 2.0 * acc[i];
                    qs[i] = q0[i] + c * h * vsi;
                    vs[i] = v0[i] + c * h * acc[i];
                }
            }
            for k in 0..hy0.len() {
                let hvk = hv_s[k];
                sum_hy[k] += 2.0 * hvk;
                sum_hv[k] += 2.0 * ah[k];
                hy_s[k] = hy0[k] + c * h * hvk;
                hv_s[k] = hv0[k] + c * h * ah[k];
            }
        }
        // Stage 4 and the combination.
        evaluate::<SIMD>(m, flags, live, qs, vs, hy_s, acc, ah);
        let w = h / 6.0;
        let (q, v) = (&mut self.q, &mut self.v);
        for r in live {
            for i in r.clone() {
                q[i] += w * (sum_q[i] + vs[i]);
                v[i] += w * (sum_v[i] + acc[i]);
            }
        }
        for k in 0..self.hammer_y.len() {
            if self.flags.hammer_on[k] {
                self.hammer_y[k] += w * (sum_hy[k] + hv_s[k]);
                self.hammer_v[k] += w * (sum_hv[k] + ah[k]);
            }
        }
        for k in 0..self.hammer_y.len() {
            if self.flags.hammer_on[k] {
                self.release_hammer_if_clear(k);
            }
        }
        self.time_s += h;
    }

    /// Move every stolen voice one step along its fade; at the end, give it its next key.
    fn advance_fades(&mut self) {
        for k in 0..self.n_voices() {
            let left = self.flags.fade_left[k];
            if left == 0 {
                continue;
            }
            let left = left - 1;
            self.flags.fade_left[k] = left;
            let x = f64::from(left) / f64::from(self.fade_steps);
            self.flags.coupling[k] = 0.5 - 0.5 * (PI * x).cos();
            if left == 0 {
                if let Some((key, strike)) = self.flags.pending[k] {
                    let damper_down = self.flags.damper_down[k];
                    self.assign(k, key);
                    self.strike_voice(k, strike);
                    self.set_damper_voice(k, damper_down);
                }
            }
        }
    }

    /// A hammer leaves the system once it recedes and is clear of every string by the release gap.
    fn release_hammer_if_clear(&mut self, k: usize) {
        if self.hammer_v[k] >= 0.0 {
            return;
        }
        let voice = &self.model.voices[k];
        let Some(key) = voice.key else {
            return;
        };
        let km = &self.model.keys[key];
        for s in 0..voice.n_strings {
            if self.flags.struck[k][s] {
                let ye = dot(&km.hammer_shape, &self.q[voice.ranges[s][0].clone()]);
                if ye - self.hammer_y[k] < km.hammer.release_gap_m {
                    return;
                }
            }
        }
        self.flags.hammer_on[k] = false;
    }

    /// Voice 0's outputs (see [`Instrument::observe_voice`]).
    pub fn observe(&self) -> Observation {
        self.observe_voice(0)
    }

    /// Forces of voice `k`, the board's velocity at its bridge point and the board's volume
    /// velocity, at the current state (Eq. 19). A voice without a key observes nothing but the board.
    pub fn observe_voice(&self, k: usize) -> Observation {
        let mut obs = Observation {
            volume_velocity_m3_s: self.volume_velocity_m3_s(),
            ..Observation::default()
        };
        let (m, voice) = (&self.model, &self.model.voices[k]);
        let Some(key) = voice.key else {
            return obs;
        };
        let km = &m.keys[key];
        let gain = self.flags.coupling[k];
        let (q, v) = (&self.q, &self.v);
        let qb = &q[m.board.clone()];
        let vb = &v[m.board.clone()];
        let mut rb = [0.0; 3];
        for d in 0..3 {
            (rb[d], obs.bridge_velocity_m_s[d]) = dot2(&km.board_shape[d], qb, vb);
        }
        for s in 0..voice.n_strings {
            for d in 0..3 {
                let r = voice.ranges[s][d].clone();
                let (rs, rs_dot) = dot2(&m.bridge_shape[r.clone()], &q[r.clone()], &v[r]);
                let f = gain
                    * (km.contact.stiffness_n_m[d] * (rs - rb[d])
                        + km.contact.damping_n_s_m[d] * (rs_dot - obs.bridge_velocity_m_s[d]));
                obs.bridge_force_n[s][d] = f;
                obs.total_force_n[d] += f;
            }
            if self.flags.hammer_on[k] && self.flags.struck[k][s] {
                let ye = dot(&km.hammer_shape, &q[voice.ranges[s][0].clone()]);
                obs.hammer_force_n[s] = km.hammer.felt_force_n(self.hammer_y[k] - ye);
            }
        }
        obs
    }

    /// Net volume velocity of the board (m^3/s), the source of the radiated sound.
    pub fn volume_velocity_m3_s(&self) -> f64 {
        dot(&self.model.board_volume, &self.v[self.model.board.clone()])
    }

    /// Floating-point operations of one RK4 step in the current state (active voices, hammers,
    /// dampers), counted from the arithmetic of [`evaluate`] and the stage updates: a multiply-add
    /// counts 2. What `unacorda bench` divides by time to report a FLOP rate.
    pub fn flops_per_step(&self) -> f64 {
        let (m, f) = (&self.model, &self.flags);
        let nb = m.board.len();
        let mut live = nb;
        // Per evaluation: the uncoupled oscillators (3 per mode) of the board ...
        let mut eval = 3 * nb;
        for (k, voice) in m.voices.iter().enumerate() {
            let (true, Some(key)) = (f.active[k], voice.key) else {
                continue;
            };
            let km = &m.keys[key];
            let n = voice.n_modes;
            let (nt, np) = (voice.ranges[0][0].len(), voice.ranges[0][2].len());
            live += n;
            // ... and the strings; bridge dot products and projections (4 + 2 per mode), the
            // board's side at this point (3 directions × (4 + 2) per board mode), the duplex
            // product (2 per matrix entry, T and P of every string).
            eval += 3 * n + 6 * n + 18 * nb + 2 * voice.n_strings * (nt * nt + np * np);
            if f.damper_down[k] && !km.damper_shape.is_empty() {
                eval += 4 * voice.n_strings * (nt + np);
            }
            if f.hammer_on[k] {
                eval += 4 * nt * f.struck[k].iter().filter(|&&s| s).count();
            }
        }
        // Four evaluations, and the stage updates: 4 + 8 + 8 + 6 per mode.
        (4 * eval + 26 * live) as f64
    }

    /// Bytes of state and coefficients per voice slot (f64 arrays over its modes).
    pub fn bytes_per_voice(&self) -> usize {
        let capacity = self.model.board.start / self.n_voices().max(1);
        // q and v, the RK4 stage state and acceleration (3), the stage sums (2), and the
        // coefficients omega^2, damping, bridge shape (3).
        capacity * 8 * 10
    }

    /// Mechanical energy of strings, board, contact springs and hammers (J).
    pub fn energy(&self) -> Energy {
        let m = &self.model;
        let modal = |r: Range<usize>| -> f64 {
            r.map(|i| 0.5 * (self.v[i] * self.v[i] + m.omega2[i] * self.q[i] * self.q[i]))
                .sum()
        };
        let strings_j = modal(0..m.board.start);
        let board_j = modal(m.board.clone());
        let qb = &self.q[m.board.clone()];
        let (mut contact_j, mut hammer_j) = (0.0, 0.0);
        for (k, voice) in m.voices.iter().enumerate() {
            let Some(key) = voice.key else {
                continue;
            };
            let km = &m.keys[key];
            for s in 0..voice.n_strings {
                for d in 0..3 {
                    let r = voice.ranges[s][d].clone();
                    let rs = dot(&m.bridge_shape[r.clone()], &self.q[r]);
                    let rb = dot(&km.board_shape[d], qb);
                    contact_j += 0.5
                        * self.flags.coupling[k]
                        * km.contact.stiffness_n_m[d]
                        * (rs - rb).powi(2);
                }
            }
            if self.flags.hammer_on[k] {
                hammer_j += 0.5 * km.hammer.mass_kg * self.hammer_v[k].powi(2);
                for s in 0..voice.n_strings {
                    if self.flags.struck[k][s] {
                        let ye = dot(&km.hammer_shape, &self.q[voice.ranges[s][0].clone()]);
                        hammer_j += km.hammer.felt_energy_j(self.hammer_y[k] - ye);
                    }
                }
            }
        }
        Energy {
            strings_j,
            board_j,
            contact_j,
            hammer_j,
        }
    }
}

/// Right-hand side of Eq. 10 over the `live` modes: writes their accelerations into `acc` and each
/// hammer's into `ah`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn evaluate<const SIMD: bool>(
    m: &Model,
    flags: &VoiceFlags,
    live: &[Range<usize>],
    q: &[f64],
    v: &[f64],
    hammer_y: &[f64],
    acc: &mut [f64],
    ah: &mut [f64],
) {
    // Uncoupled modal oscillators: -Omega^2 q - C qdot (diagonal blocks of Eq. 11).
    for r in live {
        for i in r.clone() {
            acc[i] = -m.omega2[i] * q[i] - m.damp[i] * v[i];
        }
    }
    let qb = &q[m.board.clone()];
    let vb = &v[m.board.clone()];
    for (k, voice) in m.voices.iter().enumerate() {
        ah[k] = 0.0;
        let (true, Some(key)) = (flags.active[k], voice.key) else {
            continue;
        };
        let km = &m.keys[key];
        let gain = flags.coupling[k];
        // This voice's bridge point of the board in T, L, P (Eq. 5).
        let mut rb = [0.0; 3];
        let mut rb_dot = [0.0; 3];
        for d in 0..3 {
            (rb[d], rb_dot[d]) = dot2(&km.board_shape[d], qb, vb);
        }
        // Contact forces (Eq. 6) and their modal projections on each string (Eq. 17).
        let mut total = [0.0; 3];
        for s in 0..voice.n_strings {
            for d in 0..3 {
                let r = voice.ranges[s][d].clone();
                let shape = &m.bridge_shape[r.clone()];
                let (rs, rs_dot) = dot2(shape, &q[r.clone()], &v[r.clone()]);
                let f = gain
                    * (km.contact.stiffness_n_m[d] * (rs - rb[d])
                        + km.contact.damping_n_s_m[d] * (rs_dot - rb_dot[d]));
                total[d] += f;
                axpy(&mut acc[r], shape, -f);
            }
        }
        // Duplex damping on both transverse polarisations of every string (Eq. 13).
        duplex_damping::<SIMD>(km, &voice.ranges, v, acc);
        // The damper felt, while it is down: a point damper on T and P of every string.
        if flags.damper_down[k] {
            for s in 0..voice.n_strings {
                for d in [0, 2] {
                    let r = voice.ranges[s][d].clone();
                    let shape = &km.damper_shape[..r.len()];
                    let f = km.damper_n_s_m * dot(shape, &v[r.clone()]);
                    axpy(&mut acc[r], shape, -f);
                }
            }
        }
        // The board receives the sum of the strings' forces at this voice's point (Eq. 17).
        let ab = &mut acc[m.board.clone()];
        for d in 0..3 {
            axpy(ab, &km.board_shape[d], total[d]);
        }
        // Hammer (Eq. 8, 14): felt force on each struck string, reaction on the hammer mass.
        if flags.hammer_on[k] {
            let mut felt_total = 0.0;
            for s in 0..voice.n_strings {
                if flags.struck[k][s] {
                    let r = voice.ranges[s][0].clone();
                    let ye = dot(&km.hammer_shape, &q[r.clone()]);
                    let f = km.hammer.felt_force_n(hammer_y[k] - ye);
                    felt_total += f;
                    axpy(&mut acc[r], &km.hammer_shape, f);
                }
            }
            ah[k] = -felt_total / km.hammer.mass_kg;
        }
    }
}

/// Whether this CPU can run the AVX2 + FMA build of the step.
fn has_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

const LANES: usize = 4;

/// Dot product with independent lane accumulators, so that it vectorises without reassociation.
#[inline(always)]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut lanes = [0.0; LANES];
    let split = n - n % LANES;
    for (ca, cb) in a[..split]
        .chunks_exact(LANES)
        .zip(b[..split].chunks_exact(LANES))
    {
        for l in 0..LANES {
            lanes[l] += ca[l] * cb[l];
        }
    }
    let mut sum = (lanes[0] + lanes[2]) + (lanes[1] + lanes[3]);
    for i in split..n {
        sum += a[i] * b[i];
    }
    sum
}

/// Two dot products sharing the left operand: `(a·b, a·c)`.
#[inline(always)]
fn dot2(a: &[f64], b: &[f64], c: &[f64]) -> (f64, f64) {
    (dot(a, b), dot(a, c))
}

/// `y += alpha x`.
#[inline(always)]
fn axpy(y: &mut [f64], x: &[f64], alpha: f64) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += alpha * xi;
    }
}

/// `acc -= C_d v` on the T and P blocks of every string (Eq. 13). All blocks share the matrix, so
/// when they have the same length each row of `C_d` is loaded once for all of them.
#[inline(always)]
fn duplex_damping<const SIMD: bool>(
    m: &KeyModel,
    ranges: &[[Range<usize>; 3]; MAX_STRINGS],
    v: &[f64],
    acc: &mut [f64],
) {
    let starts = |d: usize| (0..m.n_strings).map(move |s| ranges[s][d].start);
    let (nt, np) = (ranges[0][0].len(), ranges[0][2].len());
    if nt == np {
        let mut offsets = [0; 2 * MAX_STRINGS];
        for (o, start) in offsets.iter_mut().zip(starts(0).chain(starts(2))) {
            *o = start;
        }
        match m.n_strings {
            1 => duplex_kernel::<2, SIMD>(
                &m.duplex,
                m.duplex_n,
                nt,
                v,
                offsets[..2].try_into().unwrap(),
                acc,
            ),
            2 => duplex_kernel::<4, SIMD>(
                &m.duplex,
                m.duplex_n,
                nt,
                v,
                offsets[..4].try_into().unwrap(),
                acc,
            ),
            _ => duplex_kernel::<6, SIMD>(&m.duplex, m.duplex_n, nt, v, offsets, acc),
        }
    } else {
        for (start, len) in starts(0).map(|o| (o, nt)).chain(starts(2).map(|o| (o, np))) {
            duplex_kernel::<1, SIMD>(&m.duplex, m.duplex_n, len, v, [start], acc);
        }
    }
}

/// The duplex product through the AVX2 kernel when `SIMD`, else the scalar reference.
#[inline(always)]
fn duplex_kernel<const K: usize, const SIMD: bool>(
    c: &[f64],
    n: usize,
    len: usize,
    v: &[f64],
    offsets: [usize; K],
    acc: &mut [f64],
) {
    #[cfg(target_arch = "x86_64")]
    if SIMD {
        // SAFETY: `SIMD` is true only inside `step_avx2`, entered after detecting AVX2 and FMA.
        unsafe { duplex_rows_avx2::<K>(c, n, len, v, offsets, acc) };
        return;
    }
    duplex_rows::<K>(c, n, len, v, offsets, acc)
}

/// For `K` blocks of length `len` starting at `offsets`: `acc[block] -= C[..len, ..len] v[block]`,
/// with `C` symmetric `n × n`, row by row, the row shared by the `K` dot products. The scalar
/// reference that the AVX2 kernel is tested against.
#[inline(always)]
fn duplex_rows<const K: usize>(
    c: &[f64],
    n: usize,
    len: usize,
    v: &[f64],
    offsets: [usize; K],
    acc: &mut [f64],
) {
    let split = len - len % LANES;
    for i in 0..len {
        let row = &c[i * n..i * n + len];
        let mut lanes = [[0.0; LANES]; K];
        for j in (0..split).step_by(LANES) {
            let cr = &row[j..j + LANES];
            for k in 0..K {
                let x = &v[offsets[k] + j..offsets[k] + j + LANES];
                for l in 0..LANES {
                    lanes[k][l] += cr[l] * x[l];
                }
            }
        }
        for k in 0..K {
            let mut sum = (lanes[k][0] + lanes[k][2]) + (lanes[k][1] + lanes[k][3]);
            for j in split..len {
                sum += row[j] * v[offsets[k] + j];
            }
            acc[offsets[k] + i] -= sum;
        }
    }
}

/// The AVX2 + FMA duplex kernel: two rows of `C_d` at a time against the `K` velocity blocks, four
/// lanes per instruction, so that every block load serves two rows and every row load `K` blocks
/// (the product is bound by FMA throughput rather than loads).
///
/// # Safety
/// The CPU must support AVX2 and FMA. Bounds are checked once on entry.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn duplex_rows_avx2<const K: usize>(
    c: &[f64],
    n: usize,
    len: usize,
    v: &[f64],
    offsets: [usize; K],
    acc: &mut [f64],
) {
    use std::arch::x86_64::*;
    if len == 0 {
        return;
    }
    assert!(len <= n && (len - 1) * n + len <= c.len());
    for &o in &offsets {
        assert!(o + len <= v.len() && o + len <= acc.len());
    }
    let split = len - len % 4;
    let (cp, vp) = (c.as_ptr(), v.as_ptr());
    let mut i = 0;
    while i < len {
        let pair = i + 1 < len;
        let r0 = cp.add(i * n);
        let r1 = if pair { cp.add((i + 1) * n) } else { r0 };
        let mut a0 = [_mm256_setzero_pd(); K];
        let mut a1 = [_mm256_setzero_pd(); K];
        let mut j = 0;
        while j < split {
            let c0 = _mm256_loadu_pd(r0.add(j));
            let c1 = _mm256_loadu_pd(r1.add(j));
            for k in 0..K {
                let x = _mm256_loadu_pd(vp.add(offsets[k] + j));
                a0[k] = _mm256_fmadd_pd(c0, x, a0[k]);
                a1[k] = _mm256_fmadd_pd(c1, x, a1[k]);
            }
            j += 4;
        }
        for k in 0..K {
            let (mut s0, mut s1) = (hsum_avx(a0[k]), hsum_avx(a1[k]));
            for j in split..len {
                let x = *vp.add(offsets[k] + j);
                s0 += *r0.add(j) * x;
                s1 += *r1.add(j) * x;
            }
            acc[offsets[k] + i] -= s0;
            if pair {
                acc[offsets[k] + i + 1] -= s1;
            }
        }
        i += if pair { 2 } else { 1 };
    }
}

/// Sum of the four lanes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn hsum_avx(x: std::arch::x86_64::__m256d) -> f64 {
    use std::arch::x86_64::*;
    let s = _mm_add_pd(_mm256_castpd256_pd128(x), _mm256_extractf128_pd(x, 1));
    _mm_cvtsd_f64(_mm_add_sd(s, _mm_unpackhi_pd(s, s)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn avx2_duplex_kernel_agrees_with_the_scalar_reference() {
        if !has_avx2_fma() {
            return;
        }
        let n = 103;
        let c: Vec<f64> = (0..n * n)
            .map(|k| ((k * 7919) % 1000) as f64 / 1000.0 - 0.5)
            .collect();
        let v: Vec<f64> = (0..4 * n + 9)
            .map(|k| ((k * 104_729) % 997) as f64 / 997.0 - 0.5)
            .collect();
        for len in [1, 2, 5, 100, 103] {
            let offsets = [0, n, 2 * n + 3, 3 * n + 9 - (n - len).min(9)];
            let mut reference = vec![0.25; v.len()];
            let mut fast = reference.clone();
            duplex_rows::<4>(&c, n, len, &v, offsets, &mut reference);
            // SAFETY: the CPU supports AVX2 and FMA (checked above).
            unsafe { duplex_rows_avx2::<4>(&c, n, len, &v, offsets, &mut fast) };
            let worst = reference
                .iter()
                .zip(&fast)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(worst < 1e-12, "len {len}: worst difference {worst}");
        }
    }
}
