//! The voice pool's policy, written once for every engine: a bank of keys and a fixed pool of
//! voices on one board; a key takes a free voice or steals the quietest after a fade; a struck
//! voice enters the simulation, a silent one leaves it; dampers follow the keys and pedals;
//! whatever blows up is reset. An engine keeps each voice's [`VoiceState`] where its step reads it
//! and implements the few hooks of [`Policy`] (what its strings and board do); the decisions are
//! the provided methods.

use super::physics::hammer::{FeltLaw, HammerParams};
use super::spec::{BuildError, Strike, UnisonSpec, MAX_STRINGS};
use std::f64::consts::PI;

/// What one voice of a pool is doing, whatever the engine. Written by the policy on the thread
/// that owns the pool (events, block ends); read by the engine's step, which also moves the fade
/// ([`fade_step`]) and releases the hammer ([`HammerParams::is_clear`](crate::engine::physics::hammer::HammerParams::is_clear)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoiceState {
    /// The key (bank index) the voice plays.
    pub key: Option<usize>,
    /// Simulated at all: a voice joins when struck or its damper is lifted, and leaves when it
    /// falls silent.
    pub active: bool,
    /// The hammer is in play (from the strike until it recedes clear of the strings).
    pub hammer_on: bool,
    /// The felt's law on each string the hammer strikes, where the soft pedal's shift put it
    /// ([`Strike::felt_laws`]); `None` for a string it misses.
    pub felt: [Option<FeltLaw>; MAX_STRINGS],
    /// How far the key or a pedal lifts the damper: 0 resting on the strings, 1 clear of them,
    /// in between part-lifted ([`Policy::touch_felt`]).
    pub damper_lift: f64,
    /// The felt rests fully on the strings: the damped key (a resting damper, or a part-lifted
    /// one that every string still touches all the time).
    pub damper_down: bool,
    /// The share of the felt's damping a part-lifted damper gives while it is not down (0 for
    /// one resting or clear): written between steps by [`Policy::touch_felt`].
    pub damper_share: f64,
    /// Where a moving damper is going (a lift), and how far it moves each step (0: still):
    /// [`Policy::move_damper`].
    pub damper_target: f64,
    pub damper_speed: f64,
    /// Scale of the contact forces: 1, or falling to 0 along the fade of a stolen voice.
    pub coupling: f64,
    /// Steps left in the fade of a stolen voice, and the key and strike that follow it.
    pub fade_left: u32,
    pub pending: Option<(usize, Strike)>,
}

impl VoiceState {
    /// The share of the damper felt's damping on the strings now: all of it while the damper is
    /// down, a part-lifted felt's share, or none.
    pub fn felt_share(&self) -> f64 {
        if self.damper_down {
            1.0
        } else {
            self.damper_share
        }
    }
}

impl Default for VoiceState {
    fn default() -> VoiceState {
        VoiceState {
            key: None,
            active: false,
            hammer_on: false,
            felt: [None; MAX_STRINGS],
            damper_lift: 1.0,
            damper_down: false,
            damper_share: 0.0,
            damper_target: 1.0,
            damper_speed: 0.0,
            coupling: 1.0,
            fade_left: 0,
            pending: None,
        }
    }
}

/// What every pool asks of its keys: at least one key and one voice, one board and one rate
/// shared by all, one prepared key per spec. Returns the first spec.
pub fn check_keys(
    specs: &[UnisonSpec],
    prepared: usize,
    voices: usize,
) -> Result<&UnisonSpec, BuildError> {
    let first = specs.first().ok_or(BuildError::NoVoice)?;
    if voices == 0 {
        return Err(BuildError::NoVoice);
    }
    // The board's dropped modes are one set of states for every key (RK4): every key's must be
    // the same modes, at its own point.
    let same_dropped = |s: &UnisonSpec| match (&s.dropped, &first.dropped) {
        (None, None) => true,
        (Some(d), Some(e)) => d.same_modes(e),
        _ => false,
    };
    if specs.iter().any(|s| {
        s.sample_rate_hz != first.sample_rate_hz || s.board != first.board || !same_dropped(s)
    }) {
        return Err(BuildError::SharedBoard);
    }
    if prepared != specs.len() {
        return Err(BuildError::PreparedKeys {
            specs: specs.len(),
            keys: prepared,
        });
    }
    Ok(first)
}

/// One step along a stolen voice's fade: the contact forces fall to zero along a raised cosine
/// over `fade_steps` steps. Returns whether the fade has just ended (the next key may start).
#[inline(always)]
pub fn fade_step(state: &mut VoiceState, fade_steps: u32) -> bool {
    if state.fade_left == 0 {
        return false;
    }
    state.fade_left -= 1;
    let x = f64::from(state.fade_left) / f64::from(fade_steps);
    state.coupling = 0.5 - 0.5 * (PI * x).cos();
    state.fade_left == 0
}

/// The pool policy over an engine's hooks. The required methods say where the voices' states
/// are and what the engine's strings, hammers and board do; the provided ones decide.
pub trait Policy {
    fn n_voices(&self) -> usize;
    fn state(&self, k: usize) -> &VoiceState;
    fn state_mut(&mut self, k: usize) -> &mut VoiceState;
    /// Which voice plays `key` (bank index), if any.
    fn voice_of_key(&self, key: usize) -> Option<usize>;
    fn set_voice_of_key(&mut self, key: usize, voice: Option<usize>);
    /// Steps of a stolen voice's fade ([`super::STEAL_FADE_S`] at the engine's rate).
    fn fade_steps(&self) -> u32;
    /// Strings of `key`, and whether it has a damper.
    fn key_strings(&self, key: usize) -> usize;
    fn key_has_damper(&self, key: usize) -> bool;
    /// Voice `k` takes `key`'s coefficients, its strings at rest (never allocates).
    fn load_key(&mut self, k: usize, key: usize);
    /// Voice `k`'s strings at rest.
    fn rest_strings(&mut self, k: usize);
    /// Voice `k` enters the simulation (its strings keep their motion relative to the bridge), or
    /// leaves it.
    fn enter(&mut self, k: usize);
    fn leave(&mut self, k: usize);
    /// Voice `k` (active, with a key) is about to be struck: an engine whose voices may step
    /// fewer than all their modes takes the rest up here. By default nothing.
    fn ready_to_strike(&mut self, _k: usize) {}
    /// Where the hammer starts on the first `struck` strings of voice `k`: the highest of their
    /// displacements at the striking point (a sounding key is struck in its motion).
    fn strike_contact_m(&self, k: usize, struck: usize) -> f64;
    /// The hammer of `key`.
    fn key_hammer(&self, key: usize) -> &HammerParams;
    fn set_hammer(&mut self, k: usize, position_m: f64, velocity_m_s: f64);
    fn hammer_finite(&self, k: usize) -> bool;
    /// Mechanical energy of voice `k`'s strings and contact springs (J; 0 while not simulated),
    /// and of the board.
    fn voice_energy_j(&self, k: usize) -> f64;
    fn board_energy_j(&self) -> f64;
    fn rest_board(&mut self);

    /// The key voice `k` plays.
    fn key_of_voice(&self, k: usize) -> Option<usize> {
        self.state(k).key
    }

    fn is_active(&self, k: usize) -> bool {
        self.state(k).active
    }

    /// Whether voice `k` is fading out before it changes key.
    fn is_fading(&self, k: usize) -> bool {
        self.state(k).fade_left > 0
    }

    /// Whether voice `k`'s hammer is in play.
    fn hammer_on(&self, k: usize) -> bool {
        self.state(k).hammer_on
    }

    /// Give voice `k` to `key`: the previous key loses it, the slot takes the key's coefficients
    /// and starts at rest, damper lifted, inactive until struck. Never allocates.
    fn assign(&mut self, k: usize, key: usize) {
        if let Some(old) = self.state(k).key {
            self.set_voice_of_key(old, None);
        }
        self.load_key(k, key);
        self.set_voice_of_key(key, Some(k));
        let s = self.state_mut(k);
        s.key = Some(key);
        (s.active, s.hammer_on, s.damper_down) = (false, false, false);
        (s.damper_lift, s.damper_share) = (1.0, 0.0);
        (s.damper_target, s.damper_speed) = (1.0, 0.0);
        (s.coupling, s.fade_left, s.pending) = (1.0, 0, None);
        self.damper_moved(k);
    }

    /// Hand sounding voice `k` to `key`: over [`super::STEAL_FADE_S`] its contact forces fall to
    /// zero with a raised cosine (the board is released smoothly, no click), then the voice takes
    /// `key` at rest and `strike` hits it ([`Policy::complete_fade`]). Stealing a voice already
    /// fading only replaces what follows. A voice that is not active is assigned and struck at once.
    fn steal(&mut self, k: usize, key: usize, strike: Strike) {
        if !self.state(k).active {
            self.assign(k, key);
            self.strike_voice(k, strike);
            return;
        }
        if let Some(old) = self.state(k).key {
            if self.voice_of_key(old) == Some(k) {
                self.set_voice_of_key(old, None);
            }
        }
        if let Some((old_pending, _)) = self.state(k).pending {
            if old_pending != key {
                self.set_voice_of_key(old_pending, None);
            }
        }
        self.set_voice_of_key(key, Some(k));
        let fade_steps = self.fade_steps();
        let s = self.state_mut(k);
        if s.fade_left == 0 {
            s.fade_left = fade_steps;
        }
        s.pending = Some((key, strike));
        (s.damper_lift, s.damper_down, s.damper_share) = (1.0, false, 0.0);
        (s.damper_target, s.damper_speed) = (1.0, 0.0);
        self.damper_moved(k);
    }

    /// Once voice `k`'s fade has ended, give it the key that follows and strike it.
    fn complete_fade(&mut self, k: usize) {
        let s = self.state(k);
        if s.fade_left != 0 {
            return;
        }
        if let Some((key, strike)) = s.pending {
            let lift = s.damper_target;
            self.assign(k, key);
            self.strike_voice(k, strike);
            self.set_damper_lift(k, lift);
        }
    }

    /// Launch voice `k`'s hammer at its strings (Eq. 14–15): it starts touching the struck strings
    /// at their current displacement and moves towards them at `strike.velocity_m_s`. A voice
    /// without a key, or whose hammer would miss every string (a felt profile that cannot hold
    /// its unison, [`crate::engine::physics::felt_profile::FeltProfile::check`]), ignores it.
    fn strike_voice(&mut self, k: usize, strike: Strike) {
        let Some(key) = self.state(k).key else {
            return;
        };
        if !self.state(k).active {
            self.enter(k);
        }
        self.ready_to_strike(k);
        let felt = strike.felt_laws(self.key_hammer(key), self.key_strings(key));
        // The strings the hammer meets are the first ones (the shift moves the last off the felt),
        // and it starts touching the nearest felt's surface.
        let n = felt.iter().flatten().count();
        if n == 0 {
            return;
        }
        let nearest_m = felt
            .iter()
            .flatten()
            .map(|law| law.offset_m)
            .fold(f64::INFINITY, f64::min);
        self.state_mut(k).felt = felt;
        let contact = self.strike_contact_m(k, n) + nearest_m;
        self.set_hammer(k, contact, strike.velocity_m_s);
        let s = self.state_mut(k);
        (s.hammer_on, s.active) = (true, true);
    }

    /// Include voice `k` in the simulation without striking it (a key held silently, or every key
    /// under the sustain pedal, whose strings then ring in sympathy through the board), or leave it
    /// out. A left-out voice keeps its motion relative to the bridge frozen, and joins again
    /// following the board. A voice without a key stays out.
    fn set_active(&mut self, k: usize, active: bool) {
        let s = self.state(k);
        let now = s.key.is_some() && (active || s.hammer_on || s.fade_left > 0);
        match (s.active, now) {
            (false, true) => self.enter(k),
            (true, false) => self.leave(k),
            _ => {}
        }
        self.state_mut(k).active = now;
    }

    /// Lower (key released) or lift (key down, or a pedal holding it) voice `k`'s damper. Keys
    /// without a damper ignore it. For a fading voice it applies to the key that follows.
    fn set_damper_voice(&mut self, k: usize, down: bool) {
        self.set_damper_lift(k, if down { 0.0 } else { 1.0 });
    }

    /// Set voice `k`'s damper at the lift `lift` (0 resting on the strings, 1 clear of them, in
    /// between part-lifted: [`Policy::touch_felt`]). Keys without a damper ignore it. For a
    /// fading voice it applies to the key that follows.
    fn set_damper_lift(&mut self, k: usize, lift: f64) {
        let lift = self.damper_lift_for(k, lift);
        let s = self.state_mut(k);
        (s.damper_target, s.damper_speed) = (lift, 0.0);
        self.place_damper(k, lift);
    }

    /// Move voice `k`'s damper to the lift `lift` at a constant speed over `steps` steps (a key
    /// let go: its damper falls with it), at once within a step. Keys without a damper ignore it.
    fn move_damper(&mut self, k: usize, lift: f64, steps: f64) {
        let lift = self.damper_lift_for(k, lift);
        let distance = (lift - self.state(k).damper_lift).abs();
        if steps < 1.0 || distance == 0.0 {
            self.set_damper_lift(k, lift);
            return;
        }
        let s = self.state_mut(k);
        (s.damper_target, s.damper_speed) = (lift, distance / steps);
    }

    /// Each moving damper ([`Policy::move_damper`]) moves on by `steps` steps: the engines call
    /// it before each step or block, before [`Policy::touch_felts`].
    fn move_dampers(&mut self, steps: usize) {
        for k in 0..self.n_voices() {
            let s = *self.state(k);
            if s.damper_speed == 0.0 {
                continue;
            }
            let (to, by) = (s.damper_target, s.damper_speed * steps as f64);
            if (to - s.damper_lift).abs() <= by {
                self.state_mut(k).damper_speed = 0.0;
                self.place_damper(k, to);
            } else {
                // On its way the felt is part-lifted: [`Policy::touch_felts`] takes it from here.
                self.state_mut(k).damper_lift = s.damper_lift + by.copysign(to - s.damper_lift);
            }
        }
    }

    /// `lift` for voice `k`'s damper within 0-1, or clear for a key without one (that of the key
    /// that follows a fading voice).
    fn damper_lift_for(&self, k: usize, lift: f64) -> f64 {
        let s = self.state(k);
        let key = s.pending.map(|(key, _)| key).or(s.key);
        let has = key.is_some_and(|key| self.key_has_damper(key));
        if has {
            lift.clamp(0.0, 1.0)
        } else {
            1.0
        }
    }

    /// Voice `k`'s damper at the lift `lift` now, where it moves or not, touching its strings as
    /// far as it reaches them ([`Policy::felt_contact`]).
    fn place_damper(&mut self, k: usize, lift: f64) {
        self.state_mut(k).damper_lift = lift;
        let (down, share) = self.felt_contact(k);
        let s = self.state_mut(k);
        (s.damper_down, s.damper_share) = (down, share);
        self.damper_moved(k);
    }

    /// Whether voice `k`'s damper is down at its lift, and a part-lifted felt's share while it is
    /// not ([`Policy::felt_share`]): down resting, clear at the full lift, and part-lifted on a
    /// voice not simulated (its strings at rest reach no felt above them).
    fn felt_contact(&self, k: usize) -> (bool, f64) {
        let s = self.state(k);
        if s.damper_lift <= 0.0 {
            return (true, 0.0);
        }
        if s.damper_lift >= 1.0 || !s.active {
            return (false, 0.0);
        }
        let share = self.felt_share(k, s.damper_lift);
        if share >= 1.0 {
            (true, 0.0)
        } else {
            (false, share)
        }
    }

    /// The share of its felt's damping voice `k`'s damper gives at the lift `lift`
    /// ([`crate::engine::physics::damper::DamperParams::contact_share`]) with its loudest
    /// string's vertical excursion under the felt now (the amplitude of a sinusoid of the same
    /// mean square, from its modes' amplitudes). By default none.
    fn felt_share(&self, _k: usize, _lift: f64) -> f64 {
        0.0
    }

    /// How much of its felt a part-lifted damper gives voice `k` from its strings' excursion now
    /// ([`Policy::felt_share`]): all of it (the damper down, as if
    /// resting), a share ([`VoiceState::damper_share`]) or none. A damper resting or clear, or a
    /// voice not simulated, is left as it is. Between steps.
    fn touch_felt(&mut self, k: usize) {
        let s = *self.state(k);
        if s.damper_lift <= 0.0 || s.damper_lift >= 1.0 || !s.active {
            return;
        }
        let (down, share) = self.felt_contact(k);
        let s = self.state_mut(k);
        s.damper_share = share;
        if s.damper_down != down {
            s.damper_down = down;
            self.damper_moved(k);
        }
    }

    /// [`Policy::touch_felt`] for every voice: the engines call it before each step or block.
    fn touch_felts(&mut self) {
        for k in 0..self.n_voices() {
            self.touch_felt(k);
        }
    }

    /// What an engine does once voice `k`'s damper has been lowered or lifted (between steps):
    /// every write of `damper_down` is followed by it. By default nothing, the engine reading
    /// `damper_down` as it steps.
    fn damper_moved(&mut self, _k: usize) {}

    /// Let the voices leave out what of their strings has died away, where the engine can
    /// (the exact engine's modes, [`crate::engine::VoiceModes::AsHeard`]). By default nothing.
    fn shed_modes(&mut self) {}

    /// Stop simulating the voices that have fallen silent: strings and contact springs below
    /// `threshold_j`, no hammer, no fade, and either the damper down or no damper at all (strings
    /// whose damper a key or pedal lifts keep ringing in sympathy). Their strings are set to rest;
    /// they keep their key until another key needs the voice. Returns how many were retired.
    fn retire_silent(&mut self, threshold_j: f64) -> usize {
        let mut retired = 0;
        for k in 0..self.n_voices() {
            let s = *self.state(k);
            let Some(key) = s.key else {
                continue;
            };
            let undamped = !self.key_has_damper(key);
            if s.active
                && !s.hammer_on
                && s.fade_left == 0
                && (s.damper_down || undamped)
                && self.voice_energy_j(k) < threshold_j
            {
                self.rest_strings(k);
                self.state_mut(k).active = false;
                retired += 1;
            }
        }
        retired
    }

    /// Put right what has blown up: a voice whose strings hold a non-finite value or more than
    /// `bound_j`, or whose hammer is not finite, is set to rest, silent and out of the simulation
    /// (its key kept); a non-finite or overloaded board is set to rest too. Returns how many parts
    /// were reset. O(modes), for once per audio block.
    fn reset_runaways(&mut self, bound_j: f64) -> usize {
        let mut reset = 0;
        for k in 0..self.n_voices() {
            let e = self.voice_energy_j(k);
            let hammer_ok = self.hammer_finite(k);
            if self.state(k).active && (!e.is_finite() || e > bound_j || !hammer_ok) {
                self.rest_voice(k);
                reset += 1;
            }
        }
        let board_j = self.board_energy_j();
        if !board_j.is_finite() || board_j > bound_j {
            self.rest_board();
            reset += 1;
        }
        reset
    }

    /// Everything at rest at once (a host's reset): every voice as [`Policy::rest_voice`] leaves
    /// it, and the board still.
    fn silence(&mut self) {
        for k in 0..self.n_voices() {
            self.rest_voice(k);
        }
        self.rest_board();
        self.forget_radiation();
    }

    /// Forget what the pool radiated before now (an engine whose radiating source is filtered
    /// keeps some of it: the exact engine's board source). By default nothing is kept.
    fn forget_radiation(&mut self) {}

    /// Voice `k` at rest: its strings and hammer still, out of the simulation, its fade and the
    /// key waiting for it dropped (its own key kept).
    fn rest_voice(&mut self, k: usize) {
        self.rest_strings(k);
        self.set_hammer(k, 0.0, 0.0);
        let s = self.state_mut(k);
        (s.active, s.hammer_on, s.fade_left, s.pending) = (false, false, 0, None);
        s.coupling = 1.0;
    }
}
