//! What the piano is doing, for a front end to show (an editor, a standalone window): which keys
//! are down and which sound, how far each pedal is down, the voices in use, and how long the
//! audio callback takes against its deadline. While something watches it ([`Activity::watch`]),
//! the audio thread publishes it after each callback (relaxed atomics: no allocation, no lock,
//! never waiting); any thread reads a [`Snapshot`].

use crate::config::scaling::KEYS;
use crate::engine::VoicePool;
use crate::play::Piano;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::sync::Arc;

/// A set of piano keys 1–88.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct KeySet(pub [u64; 2]);

impl KeySet {
    /// Piano key `key` (1–88) in the set; others are ignored.
    pub fn insert(&mut self, key: usize) {
        if (1..=KEYS).contains(&key) {
            let bit = key - 1;
            self.0[bit / 64] |= 1 << (bit % 64);
        }
    }

    /// Whether piano key `key` (1–88) is in the set.
    pub fn contains(&self, key: usize) -> bool {
        (1..=KEYS).contains(&key) && self.0[(key - 1) / 64] & (1 << ((key - 1) % 64)) != 0
    }

    /// How many keys are in the set.
    pub fn len(&self) -> usize {
        self.0.iter().map(|w| w.count_ones() as usize).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// What a front end reads of [`Activity`] at one moment.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Snapshot {
    /// Keys held down by the player.
    pub down: KeySet,
    /// Keys whose strings hold a voice (struck, or ringing in sympathy under the pedal's halo).
    pub sounding: KeySet,
    /// How far the sustain pedal lifts the dampers (0 resting to 1 clear of the strings).
    pub sustain_lift: f32,
    /// Whether the sostenuto pedal holds dampers up.
    pub sostenuto: bool,
    /// The soft pedal's shift of the action (0 up to 1, the una corda).
    pub soft_shift: f32,
    /// Voices in use and the pool's size.
    pub voices: u32,
    pub pool: u32,
    /// The last callback's time as a fraction of the audio it rendered (1: the deadline), and
    /// the largest since the last [`Activity::take`].
    pub load: f32,
    pub peak_load: f32,
}

/// [`Snapshot`]'s values, published by the audio thread, read by any other.
#[derive(Debug, Default)]
pub struct Activity {
    /// How many watch it ([`Watch`]: any thread); nothing is published while none does.
    watchers: AtomicU32,
    down: [AtomicU64; 2],
    sounding: [AtomicU64; 2],
    /// `f32` bits.
    sustain_lift: AtomicU32,
    sostenuto: AtomicU32,
    /// `f32` bits.
    soft_shift: AtomicU32,
    voices: AtomicU32,
    pool: AtomicU32,
    /// `f32` bits.
    load: AtomicU32,
    /// `f32` bits; swapped to zero by [`Activity::take`].
    peak_load: AtomicU32,
}

/// Something watching an [`Activity`] (an open editor); it stops watching when dropped.
#[derive(Debug)]
pub struct Watch(Arc<Activity>);

impl Drop for Watch {
    fn drop(&mut self) {
        self.0.watchers.fetch_sub(1, Ordering::Relaxed);
    }
}

impl Activity {
    /// Have the audio thread publish from now on, until the [`Watch`] is dropped.
    pub fn watch(activity: &Arc<Activity>) -> Watch {
        activity.watchers.fetch_add(1, Ordering::Relaxed);
        Watch(activity.clone())
    }

    /// Whether anything watches it: the audio thread publishes only then (a piano's keys and
    /// voices walked, the clock read, for no one otherwise).
    pub fn is_watched(&self) -> bool {
        self.watchers.load(Ordering::Relaxed) > 0
    }

    /// Publish the state of `piano` (audio thread, after a callback). Never allocates.
    pub fn publish<E: VoicePool>(&self, piano: &Piano<E>) {
        let (mut down, mut sounding) = (KeySet::default(), KeySet::default());
        for key in 1..=KEYS {
            if piano.player.is_down(key) {
                down.insert(key);
            }
        }
        let pool = &piano.instrument;
        let mut voices = 0;
        for v in 0..pool.n_voices() {
            let state = pool.state(v);
            if let (true, Some(bank)) = (state.active, state.key) {
                voices += 1;
                if let Some(&key) = piano.keys.get(bank) {
                    sounding.insert(key);
                }
            }
        }
        for w in 0..2 {
            self.down[w].store(down.0[w], Ordering::Relaxed);
            self.sounding[w].store(sounding.0[w], Ordering::Relaxed);
        }
        let player = &piano.player;
        let f = |x: f64| (x as f32).to_bits();
        self.sustain_lift
            .store(f(player.sustain_lift()), Ordering::Relaxed);
        self.sostenuto
            .store(u32::from(player.sostenuto()), Ordering::Relaxed);
        self.soft_shift
            .store(f(player.soft_shift()), Ordering::Relaxed);
        self.voices.store(voices, Ordering::Relaxed);
        self.pool.store(pool.n_voices() as u32, Ordering::Relaxed);
    }

    /// Publish a callback that took `took_s` to render `rendered_s` of audio (audio thread).
    pub fn publish_load(&self, took_s: f64, rendered_s: f64) {
        if rendered_s <= 0.0 {
            return;
        }
        let load = (took_s / rendered_s) as f32;
        self.load.store(load.to_bits(), Ordering::Relaxed);
        // The largest since the last take: positive floats order as their bits do.
        self.peak_load.fetch_max(load.to_bits(), Ordering::Relaxed);
    }

    /// What was last published; the peak load starts again from zero.
    pub fn take(&self) -> Snapshot {
        let keys = |k: &[AtomicU64; 2]| KeySet([0, 1].map(|w| k[w].load(Ordering::Relaxed)));
        let f = |a: &AtomicU32| f32::from_bits(a.load(Ordering::Relaxed));
        Snapshot {
            down: keys(&self.down),
            sounding: keys(&self.sounding),
            sustain_lift: f(&self.sustain_lift),
            sostenuto: self.sostenuto.load(Ordering::Relaxed) != 0,
            soft_shift: f(&self.soft_shift),
            voices: self.voices.load(Ordering::Relaxed),
            pool: self.pool.load(Ordering::Relaxed),
            load: f(&self.load),
            peak_load: f32::from_bits(self.peak_load.swap(0, Ordering::Relaxed)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_sets_hold_keys_1_to_88_and_nothing_else() {
        let mut s = KeySet::default();
        for key in [0, 1, 40, 64, 65, 88, 89] {
            s.insert(key);
        }
        let held: Vec<usize> = (0..=90).filter(|&k| s.contains(k)).collect();
        assert_eq!(held, [1, 40, 64, 65, 88]);
        assert_eq!(s.len(), 5);
    }

    #[test]
    fn it_is_watched_while_a_watch_lives() {
        let a = std::sync::Arc::new(Activity::default());
        assert!(!a.is_watched());
        let (w1, w2) = (Activity::watch(&a), Activity::watch(&a));
        drop(w1);
        assert!(a.is_watched(), "one watch left");
        drop(w2);
        assert!(!a.is_watched());
    }

    #[test]
    fn the_peak_load_holds_until_taken() {
        let a = Activity::default();
        for took in [0.2, 0.9, 0.4] {
            a.publish_load(took * 1e-3, 1e-3);
        }
        let s = a.take();
        println!("load {:.2}, peak {:.2}", s.load, s.peak_load);
        assert!((s.load - 0.4).abs() < 1e-6 && (s.peak_load - 0.9).abs() < 1e-6);
        assert_eq!(a.take().peak_load, 0.0, "taken: from zero again");
    }
}
