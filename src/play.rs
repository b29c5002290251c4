//! Playing the instrument: piano events (from live MIDI or a MIDI file) applied to keys that share
//! one soundboard, with the pedals' logic and the voice pool's allocation. A key struck again is
//! struck in its current motion; a key without a voice takes a free one, or steals the quietest.

use crate::engine::{Strike, UnisonSpec, VoicePool};
use crate::midi::{hammer_speed_m_s, piano_key, Event, Pedal, PEDAL_DOWN_AT};

/// The performer's state: which keys are down and what the pedals do.
#[derive(Debug, Clone)]
pub struct Player {
    /// Bank index (the instrument's key) of each piano key 1–88, if the instrument has it.
    bank_of_key: [Option<usize>; 89],
    /// Piano key (1–88) of each bank index.
    key_of_bank: Vec<usize>,
    key_down: [bool; 89],
    /// Keys whose dampers the sostenuto pedal holds up.
    sostenuto_held: [bool; 89],
    /// How far the sustain pedal lifts the dampers of released keys (0-1: [`sustain_lift`]).
    sustain_lift: f64,
    sostenuto: bool,
    /// The soft pedal's shift of the action, a fraction of the full shift (its depth).
    soft_shift: f64,
    /// Whether every key whose damper a pedal lifts rings in sympathy, struck or not (the
    /// pedal's halo: [`Player::set_halo`]); else only the keys that hold a voice.
    halo: bool,
}

impl Player {
    /// A player for an instrument whose bank key `k` is piano key `keys[k]` (1–88).
    pub fn new(keys: &[usize]) -> Player {
        let mut bank_of_key = [None; 89];
        for (bank, &key) in keys.iter().enumerate() {
            if (1..=88).contains(&key) {
                bank_of_key[key] = Some(bank);
            }
        }
        Player {
            bank_of_key,
            key_of_bank: keys.to_vec(),
            key_down: [false; 89],
            sostenuto_held: [false; 89],
            sustain_lift: 0.0,
            sostenuto: false,
            soft_shift: 0.0,
            halo: false,
        }
    }

    /// Whether every key whose damper a pedal lifts takes a voice at rest and rings in sympathy
    /// through the board — the halo of a grand's undamped strings around every note under the
    /// sustain pedal, its cost a voice per undamped key (their modes above the board's reach
    /// left to follow the bridge: [`crate::engine::VoiceModes::AsHeard`]) — or only the keys
    /// that were struck (the default). Takes effect at the next pedal or key.
    pub fn set_halo(&mut self, halo: bool) {
        self.halo = halo;
    }

    /// The soft pedal's shift of the action, 0 (up) to 1 (the una corda).
    pub fn soft_shift(&self) -> f64 {
        self.soft_shift
    }

    /// How far the sustain pedal lifts the dampers of released keys (0 resting, 1 clear).
    pub fn sustain_lift(&self) -> f64 {
        self.sustain_lift
    }

    /// Whether the sostenuto pedal is down.
    pub fn sostenuto(&self) -> bool {
        self.sostenuto
    }

    /// Whether piano key `key` (1–88) is held down.
    pub fn is_down(&self, key: usize) -> bool {
        self.key_down.get(key).copied().unwrap_or(false)
    }

    /// Apply one event to the instrument. Events for keys the instrument lacks are ignored.
    /// Never allocates.
    pub fn apply(&mut self, event: Event, instrument: &mut impl VoicePool) {
        match event {
            Event::NoteOn { note, velocity } => {
                let (Some(key), Some(speed)) = (piano_key(note), hammer_speed_m_s(velocity)) else {
                    return;
                };
                let Some(bank) = self.bank_of_key[key] else {
                    return;
                };
                self.key_down[key] = true;
                let strike = Strike {
                    velocity_m_s: speed,
                    shift: self.soft_shift,
                };
                match instrument.voice_of_key(bank) {
                    // Sounding (or waiting for its stolen voice): struck in its current motion.
                    Some(v) if !instrument.is_fading(v) => {
                        instrument.set_damper_voice(v, false);
                        instrument.strike_voice(v, strike);
                    }
                    Some(v) => instrument.steal(v, bank, strike),
                    None => {
                        let v = self.voice_for_new_key(instrument);
                        instrument.steal(v, bank, strike);
                    }
                }
            }
            Event::NoteOff { note, velocity } => {
                if let Some(key) = piano_key(note) {
                    self.key_down[key] = false;
                    let steps = damper_landing_s(velocity) / instrument.step_s();
                    self.move_damper(key, steps, instrument);
                }
            }
            Event::Pedal {
                pedal: Pedal::Sustain,
                depth,
            } => {
                self.sustain_lift = sustain_lift(depth);
                self.settle_all(instrument);
            }
            Event::Pedal {
                pedal: Pedal::Sostenuto,
                depth,
            } => {
                let down = depth >= PEDAL_DOWN_AT;
                self.sostenuto = down;
                self.sostenuto_held = if down { self.key_down } else { [false; 89] };
                self.settle_all(instrument);
            }
            Event::Pedal {
                pedal: Pedal::Soft,
                depth,
            } => self.soft_shift = depth.clamp(0.0, 1.0),
            Event::AllNotesOff => {
                self.key_down = [false; 89];
                self.settle_all(instrument);
            }
            Event::AllSoundOff => {
                self.key_down = [false; 89];
                for v in 0..instrument.n_voices() {
                    instrument.set_damper_voice(v, true);
                }
            }
            Event::ResetControllers => {
                self.sustain_lift = 0.0;
                self.sostenuto = false;
                self.sostenuto_held = [false; 89];
                self.soft_shift = 0.0;
                self.settle_all(instrument);
            }
        }
    }

    /// How far the damper of piano key `key` is lifted by the key or a pedal (0 resting, 1 clear
    /// of the strings).
    fn lift(&self, key: usize) -> f64 {
        if self.key_down[key] || self.sostenuto_held[key] {
            1.0
        } else {
            self.sustain_lift
        }
    }

    /// Whether the damper of piano key `key` is lifted at all by the key or a pedal.
    fn lifted(&self, key: usize) -> bool {
        self.lift(key) > 0.0
    }

    /// The voice a newly sounding key takes: a silent one if there is any (one that never played
    /// first), else the quietest by string energy, preferring keys whose dampers are down over
    /// keys held by a finger or a pedal, and never one already fading.
    fn voice_for_new_key(&self, instrument: &impl VoicePool) -> usize {
        let n = instrument.n_voices();
        if let Some(v) = free_voice(instrument) {
            return v;
        }
        let rank = |v: usize| {
            let held = instrument
                .key_of_voice(v)
                .is_some_and(|bank| self.lifted(self.key_of_bank[bank]));
            (instrument.is_fading(v), held, instrument.voice_energy_j(v))
        };
        (0..n)
            .min_by(|&a, &b| {
                rank(a)
                    .partial_cmp(&rank(b))
                    .unwrap_or(std::cmp::Ordering::Equal)
            })
            .unwrap_or(0)
    }

    /// Lift or drop one key's damper at once from the key and the pedals
    /// ([`Player::move_damper`]).
    fn settle_damper(&self, key: usize, instrument: &mut impl VoicePool) {
        self.move_damper(key, 0.0, instrument);
    }

    /// Lift or drop one key's damper from the key and the pedals, over `steps` of the
    /// instrument's steps (a key let go) or at once. A key whose damper is lifted rings in
    /// sympathy with the rest through the board; with the halo ([`Player::set_halo`]) one that
    /// holds no voice takes a free one at rest, where there is one (never a sounding voice).
    fn move_damper(&self, key: usize, steps: f64, instrument: &mut impl VoicePool) {
        let Some(bank) = self.bank_of_key[key] else {
            return;
        };
        let (lift, lifted) = (self.lift(key), self.lifted(key));
        let v = match instrument.voice_of_key(bank) {
            Some(v) => v,
            None if lifted && self.halo => match free_voice(instrument) {
                Some(v) => {
                    instrument.assign(v, bank);
                    v
                }
                None => return,
            },
            None => return,
        };
        instrument.move_damper(v, lift, steps);
        // Strings whose damper is up ring in sympathy with the rest through the board.
        if lifted {
            instrument.set_active(v, true);
        }
    }

    fn settle_all(&self, instrument: &mut impl VoicePool) {
        for key in 1..=88 {
            self.settle_damper(key, instrument);
        }
    }
}

/// Where the sustain pedal's travel lifts the dampers: from its free travel's end
/// ([`SUSTAIN_LIFT_FROM`]) to their full lift ([`SUSTAIN_LIFT_TO`]).
pub const SUSTAIN_LIFT_FROM: f64 = 0.2;
pub const SUSTAIN_LIFT_TO: f64 = 0.8;

/// How far a sustain pedal at `depth` (0 up, 1 fully down) lifts the dampers (0 resting on the
/// strings, 1 clear of them): not at all through the pedal's free travel, then as the square of
/// the pedal's travel beyond it. Part pedalling happens within a millimetre of the strings
/// (the felts at a gap that loud strings still reach, [`crate::engine::physics::damper`]), a
/// fraction of the dampers' full lift: the square spreads that millimetre over a third of the
/// controller's range, as a pianist's foot finds it on a grand's pedal.
pub fn sustain_lift(depth: f64) -> f64 {
    let travel = (depth - SUSTAIN_LIFT_FROM) / (SUSTAIN_LIFT_TO - SUSTAIN_LIFT_FROM);
    travel.clamp(0.0, 1.0).powi(2)
}

/// How long a key's damper takes to land on its strings from its lift when the key is let go
/// at MIDI's default release velocity (s): the damper falls with the key as it rises.
pub const DAMPER_LANDING_S: f64 = 0.03;

/// How long a key let go at the release velocity `velocity` (MIDI's scale, 1–127; 0 for none,
/// taken as [`crate::midi::DEFAULT_RELEASE_VELOCITY`]) takes to land its damper (s): the key
/// rises at a speed in proportion to the release velocity, and the damper with it —
/// [`DAMPER_LANDING_S`] at the default, half of it at 127, 6.4 times it at 10. A slow release
/// lets the felt reach the strings late and touch them gradually (a part-lifted felt on its
/// way: [`crate::engine::physics::damper::DamperParams::contact_share`]), the note dying more
/// gradually.
pub fn damper_landing_s(velocity: f64) -> f64 {
    let v = if velocity > 0.0 {
        velocity.clamp(1.0, 127.0)
    } else {
        crate::midi::DEFAULT_RELEASE_VELOCITY
    };
    DAMPER_LANDING_S * crate::midi::DEFAULT_RELEASE_VELOCITY / v
}

/// A voice neither sounding nor fading: one that never played first, else any.
fn free_voice(instrument: &impl VoicePool) -> Option<usize> {
    let n = instrument.n_voices();
    let free = |v: &usize| !instrument.is_active(*v) && !instrument.is_fading(*v);
    (0..n)
        .filter(free)
        .find(|&v| instrument.key_of_voice(v).is_none())
        .or_else(|| (0..n).find(free))
}

/// Why a piano cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum PianoError {
    #[error(transparent)]
    Preset(#[from] crate::config::preset::PresetError),
    #[error(transparent)]
    Build(#[from] crate::engine::BuildError),
    /// The build was called off before it ended ([`PreparedKeys::prepare`]).
    #[error("the piano's build was called off")]
    Cancelled,
}

/// A keyboard to build pianos from: its keys' parameters, and where prepared keys are kept.
#[derive(Debug, Clone, Copy)]
pub struct Keyboard<'a> {
    pub scaling: &'a crate::config::scaling::LoadedScaling,
    pub cache: Option<&'a crate::keycache::KeyCache>,
}

/// An instrument with its player: what the audio thread owns.
#[derive(Debug, Clone)]
pub struct Piano<E: VoicePool> {
    pub instrument: E,
    pub player: Player,
    /// Piano key (1–88) of each bank index.
    pub keys: Vec<usize>,
}

/// A keyboard's keys prepared for engine `E` (tuned, diagonalised or read back from the cache):
/// the costly part of building a piano, from which pianos of any pool size are made, sharing
/// the keys' coefficients.
#[derive(Debug)]
pub struct PreparedKeys<E: VoicePool> {
    /// Each key's spec at the engine's rate, in order with `prepared`.
    specs: Vec<UnisonSpec>,
    prepared: std::sync::Arc<[E::Key]>,
    /// Piano key (1–88) of each bank index.
    keys: Vec<usize>,
}

impl<E: VoicePool> PreparedKeys<E> {
    /// The `keys` (1–88) of `scaling` prepared on all cores, read from and kept in `cache` where
    /// the engine's keys are worth keeping. `cancelled` is asked before each key: once it says
    /// yes the preparation stops with [`PianoError::Cancelled`] (a build that a newer choice
    /// supersedes).
    pub fn prepare(
        scaling: &crate::config::scaling::LoadedScaling,
        keys: &[usize],
        cache: Option<&crate::keycache::KeyCache>,
        cancelled: &(dyn Fn() -> bool + Sync),
    ) -> Result<PreparedKeys<E>, PianoError> {
        let rate_hz = scaling.base.output_rate_hz();
        let go_on = || {
            if cancelled() {
                Err(PianoError::Cancelled)
            } else {
                Ok(())
            }
        };
        let specs = crate::cores::map_on_cores(keys, |&k| {
            go_on()?;
            Ok::<_, PianoError>(scaling.key_preset(k)?.unison_spec())
        })?;
        // The keys of one instrument step together, at the keyboard's rate whichever keys are
        // built ([`LoadedScaling::internal_rate_hz`]: RK4 runs the concert keyboard at 240 kHz,
        // where Bb7-C8 keep their modes to 20 kHz), or at the output rate (the exact engine).
        //
        // [`LoadedScaling::internal_rate_hz`]: crate::config::scaling::LoadedScaling::internal_rate_hz
        let common_hz = specs
            .iter()
            .map(|s| s.sample_rate_hz)
            .fold(scaling.internal_rate_hz(), f64::max);
        let specs: Vec<_> = specs
            .into_iter()
            .map(|spec| {
                let spec = UnisonSpec {
                    sample_rate_hz: common_hz,
                    ..spec
                };
                E::at_engine_rate(spec, rate_hz)
            })
            .collect();
        let prepared = crate::cores::map_on_cores(&specs, |spec| {
            go_on()?;
            Ok::<_, PianoError>(match cache {
                Some(cache) => cache.key(spec, E::prepare_key)?,
                None => E::prepare_key(spec)?,
            })
        })?;
        Ok(PreparedKeys {
            specs,
            prepared: prepared.into(),
            keys: keys.to_vec(),
        })
    }

    /// A piano of these keys with a pool of `voices` voices.
    pub fn piano(&self, voices: usize) -> Result<Piano<E>, PianoError> {
        Ok(Piano {
            instrument: E::from_keys(&self.specs, self.prepared.clone(), voices)?,
            player: Player::new(&self.keys),
            keys: self.keys.clone(),
        })
    }
}

/// Default size of the voice pool.
pub const DEFAULT_VOICES: usize = 64;

/// Size of the voice pool with the pedal's halo ([`Player::set_halo`]) at least: every key of the
/// keyboard, and room for the voices fading out as their keys are stolen.
pub const HALO_VOICES: usize = 128;

/// Largest voice pool the command line accepts.
pub const MAX_VOICES: usize = 256;

impl<E: VoicePool> Piano<E> {
    /// The `keys` (1–88) of `scaling` on one soundboard with a pool of `voices` voices. Keys are
    /// built (tuned, and prepared for the engine) on all cores.
    pub fn build(
        scaling: &crate::config::scaling::LoadedScaling,
        keys: &[usize],
        voices: usize,
    ) -> Result<Piano<E>, PianoError> {
        Piano::build_with(scaling, keys, voices, None)
    }

    /// [`Piano::build`], the prepared keys read from and kept in `cache` where the engine's
    /// keys are worth keeping.
    pub fn build_with(
        scaling: &crate::config::scaling::LoadedScaling,
        keys: &[usize],
        voices: usize,
        cache: Option<&crate::keycache::KeyCache>,
    ) -> Result<Piano<E>, PianoError> {
        PreparedKeys::prepare(scaling, keys, cache, &|| false)?.piano(voices)
    }

    /// Apply one event.
    pub fn apply(&mut self, event: Event) {
        self.player.apply(event, &mut self.instrument);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::exact::ExactPool;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// A preparation called off stops between two keys: asked before each key, the question
    /// answered yes once stops it within one key per thread, with [`PianoError::Cancelled`];
    /// never asked yes, it prepares every key.
    #[test]
    fn a_preparation_called_off_stops_between_two_keys() {
        let scaling = crate::config::scaling::Scaling::resolve("paper").unwrap();
        let keys: Vec<usize> = (60..=66).collect();
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        let asked = AtomicUsize::new(0);
        // Yes from the fifth question on.
        let cancelled = || asked.fetch_add(1, Ordering::Relaxed) >= 4;
        let result = PreparedKeys::<ExactPool>::prepare(&scaling, &keys, None, &cancelled);
        let questions = asked.load(Ordering::Relaxed);
        println!(
            "called off at the fifth question: {} after {questions} questions ({} keys, {threads} threads; unbroken, {} questions)",
            match &result {
                Err(e) => e.to_string(),
                Ok(_) => "prepared".into(),
            },
            keys.len(),
            2 * keys.len()
        );
        assert!(matches!(result, Err(PianoError::Cancelled)));
        // Each thread stops at its first yes.
        assert!(questions <= 4 + threads, "{questions} questions");

        let asked = AtomicUsize::new(0);
        let never = || {
            asked.fetch_add(1, Ordering::Relaxed);
            false
        };
        let prepared = PreparedKeys::<ExactPool>::prepare(&scaling, &keys, None, &never).unwrap();
        assert_eq!(asked.load(Ordering::Relaxed), 2 * keys.len());
        assert_eq!(prepared.piano(3).unwrap().keys, keys);
    }
}
