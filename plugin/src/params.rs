//! The plugin's parameters: the three pedals (the sustain pedal's depth continuous), the output gain and the velocity curve
//! (automatable, applied within the block at their event's frame), the keyboard, the voice pool's
//! size, the integrator and the pedal's halo (not automatable: a change rebuilds the piano in the
//! background, [`crate::rebuild`]). Values are shared between the main thread and the audio thread as atomics.

use std::sync::atomic::{AtomicU64, Ordering};

/// One parameter: its CLAP id, names, range, default and kind.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spec {
    pub id: u32,
    /// Its name in hosts, and the state's field.
    pub name: &'static str,
    pub key: &'static str,
    pub min: f64,
    pub max: f64,
    pub default: f64,
    /// Integer values only (switches, counts, choices).
    pub stepped: bool,
    /// The host may automate it; otherwise a change rebuilds the piano.
    pub automatable: bool,
    /// The names of a choice's values 0, 1, … (hosts show them; the state writes them).
    pub choices: Option<&'static [&'static str]>,
    /// The state version that first saved it (an older state gives it its default).
    pub since_version: i64,
}

/// Index of each parameter in [`PARAMS`] (its CLAP id is the index + 1).
pub const SUSTAIN: usize = 0;
pub const SOSTENUTO: usize = 1;
pub const SOFT: usize = 2;
pub const GAIN_DB: usize = 3;
pub const VELOCITY_CURVE: usize = 4;
pub const KEYBOARD: usize = 5;
pub const VOICES: usize = 6;
pub const INTEGRATOR: usize = 7;
pub const HALO: usize = 8;

/// The built-in keyboards the `keyboard` parameter chooses from (its values 0, 1).
pub const KEYBOARDS: [&str; 2] = ["concert", "paper"];
/// The integrators the `integrator` parameter chooses from (its values 0, 1): the exact engine
/// (`play`'s and `render --midi`'s) or the paper's RK4 (the reference, slower than real time: it
/// plays in offline renders, [`crate::Shared::integrator`]).
pub const INTEGRATORS: [&str; 2] = ["exact", "rk4"];

const fn switch(id: u32, name: &'static str, key: &'static str) -> Spec {
    Spec {
        id,
        name,
        key,
        min: 0.0,
        max: 1.0,
        default: 0.0,
        stepped: true,
        automatable: true,
        choices: None,
        since_version: 1,
    }
}

/// Every parameter, in the order hosts list them.
pub const PARAMS: [Spec; 9] = [
    // Continuous: how far the dampers are lifted (`unacorda::play::sustain_lift`; half
    // pedalling between the ends).
    Spec {
        stepped: false,
        ..switch(1, "Sustain pedal", "sustain")
    },
    switch(2, "Sostenuto pedal", "sostenuto"),
    // Continuous: the soft pedal's shift of the action (the una corda at 1).
    Spec {
        stepped: false,
        ..switch(3, "Soft pedal (una corda)", "soft")
    },
    Spec {
        id: 4,
        name: "Output gain (dB)",
        key: "gain_db",
        min: *unacorda::config::output::GAIN_DB.start(),
        max: *unacorda::config::output::GAIN_DB.end(),
        default: 0.0,
        stepped: false,
        automatable: true,
        choices: None,
        since_version: 1,
    },
    // unacorda::midi::curved_velocity: MIDI velocity v becomes 127 (v/127)^curve.
    Spec {
        id: 5,
        name: "Velocity curve (exponent)",
        key: "velocity_curve",
        min: *unacorda::midi::VELOCITY_CURVE.start(),
        max: *unacorda::midi::VELOCITY_CURVE.end(),
        default: 1.0,
        stepped: false,
        automatable: true,
        choices: None,
        since_version: 1,
    },
    Spec {
        id: 6,
        name: "Keyboard",
        key: "keyboard",
        min: 0.0,
        max: (KEYBOARDS.len() - 1) as f64,
        default: 0.0,
        stepped: true,
        automatable: false,
        choices: Some(&KEYBOARDS),
        since_version: 1,
    },
    Spec {
        id: 7,
        name: "Voices",
        key: "voices",
        min: 1.0,
        max: unacorda::play::MAX_VOICES as f64,
        default: unacorda::play::DEFAULT_VOICES as f64,
        stepped: true,
        automatable: false,
        choices: None,
        since_version: 1,
    },
    Spec {
        id: 8,
        name: "Integrator (RK4 in offline renders only)",
        key: "integrator",
        min: 0.0,
        max: (INTEGRATORS.len() - 1) as f64,
        default: 0.0,
        stepped: true,
        automatable: false,
        choices: Some(&INTEGRATORS),
        since_version: 2,
    },
    // Under the sustain pedal every key's strings ring in sympathy, struck or not
    // (`unacorda::play::Player::set_halo`); the pool then holds at least HALO_VOICES voices.
    Spec {
        id: 9,
        name: "Pedal halo (every undamped string rings)",
        key: "halo",
        min: 0.0,
        max: 1.0,
        default: 0.0,
        stepped: true,
        automatable: false,
        choices: None,
        since_version: 3,
    },
];

/// The parameters whose change rebuilds the piano.
pub const REBUILDS: [usize; 4] = [KEYBOARD, VOICES, INTEGRATOR, HALO];

/// The index of the parameter with CLAP id `id`.
pub fn index_of(id: u32) -> Option<usize> {
    PARAMS.iter().position(|p| p.id == id)
}

impl Spec {
    /// The name of a choice's `value`, if it is a choice.
    pub fn choice(&self, value: f64) -> Option<&'static str> {
        let choices = self.choices?;
        Some(choices[(self.clamp(value) as usize).min(choices.len() - 1)])
    }

    /// `value` brought into range (rounded where stepped); NaN becomes the default.
    pub fn clamp(&self, value: f64) -> f64 {
        if value.is_nan() {
            return self.default;
        }
        let v = value.clamp(self.min, self.max);
        if self.stepped {
            v.round()
        } else {
            v
        }
    }
}

/// The parameters' values (any thread: relaxed atomics holding `f64` bits).
#[derive(Debug)]
pub struct Values([AtomicU64; PARAMS.len()]);

impl Default for Values {
    fn default() -> Self {
        Values(std::array::from_fn(|i| {
            AtomicU64::new(PARAMS[i].default.to_bits())
        }))
    }
}

impl Values {
    pub fn get(&self, index: usize) -> f64 {
        f64::from_bits(self.0[index].load(Ordering::Relaxed))
    }

    /// Set parameter `index` (clamped to its range); returns the value stored.
    pub fn set(&self, index: usize, value: f64) -> f64 {
        let v = PARAMS[index].clamp(value);
        self.0[index].store(v.to_bits(), Ordering::Relaxed);
        v
    }

    /// A switch parameter as on/off.
    pub fn on(&self, index: usize) -> bool {
        self.get(index) >= 0.5
    }

    /// The keyboard chosen.
    pub fn keyboard(&self) -> &'static str {
        KEYBOARDS[(self.get(KEYBOARD) as usize).min(KEYBOARDS.len() - 1)]
    }

    /// The integrator chosen.
    pub fn integrator(&self) -> unacorda::engine::Integrator {
        match self.get(INTEGRATOR) >= 0.5 {
            true => unacorda::engine::Integrator::Rk4,
            false => unacorda::engine::Integrator::Exact,
        }
    }

    /// The values whose change rebuilds the piano ([`REBUILDS`]).
    pub fn rebuilds(&self) -> [f64; REBUILDS.len()] {
        REBUILDS.map(|i| self.get(i))
    }

    /// The integrator played: the one chosen when the host renders `offline`, the exact engine
    /// live (RK4 takes longer than real time for a single voice).
    pub fn integrator_played(&self, offline: bool) -> unacorda::engine::Integrator {
        match offline {
            true => self.integrator(),
            false => unacorda::engine::Integrator::Exact,
        }
    }

    /// The values whose change rebuilds the piano ([`REBUILDS`]), the integrator as played
    /// ([`Values::integrator_played`]).
    pub fn played(&self, offline: bool) -> [f64; REBUILDS.len()] {
        let rk4 = self.integrator_played(offline) == unacorda::engine::Integrator::Rk4;
        let mut values = self.rebuilds();
        for (v, &i) in values.iter_mut().zip(&REBUILDS) {
            if i == INTEGRATOR {
                *v = f64::from(u8::from(rk4));
            }
        }
        values
    }

    /// The voice pool's size: as chosen, and with the halo room for every key
    /// ([`unacorda::play::HALO_VOICES`]).
    pub fn voices(&self) -> usize {
        let chosen = self.get(VOICES) as usize;
        if self.halo() {
            chosen.max(unacorda::play::HALO_VOICES)
        } else {
            chosen
        }
    }

    /// Whether the pedal's halo is on.
    pub fn halo(&self) -> bool {
        self.on(HALO)
    }
}

/// Parameter `i`'s `value` as hosts and editors show it.
pub fn write_text(i: usize, value: f64, w: &mut impl std::fmt::Write) -> std::fmt::Result {
    let p = PARAMS[i];
    if let Some(name) = p.choice(value) {
        return write!(w, "{name}");
    }
    match i {
        GAIN_DB => write!(w, "{value:.1} dB"),
        VELOCITY_CURVE => write!(w, "{value:.2}"),
        SUSTAIN | SOFT if value <= 0.0 => write!(w, "up"),
        SUSTAIN | SOFT if value >= 1.0 => write!(w, "down"),
        SUSTAIN | SOFT => write!(w, "{:.0} %", 100.0 * value),
        _ if p.max == 1.0 && p.stepped => {
            write!(w, "{}", if value >= 0.5 { "down" } else { "up" })
        }
        _ => write!(w, "{}", value.round()),
    }
}

/// Parameter `i`'s value from text as [`write_text`] writes it (or a bare number), in range.
pub fn parse_text(i: usize, text: &str) -> Option<f64> {
    let text = text.trim();
    let value = match PARAMS[i].choices {
        Some(names) => names.iter().position(|k| *k == text)? as f64,
        None if PARAMS[i].max == 1.0 && PARAMS[i].stepped => match text {
            "down" | "on" | "1" => 1.0,
            "up" | "off" | "0" => 0.0,
            _ => return None,
        },
        None if i == SUSTAIN || i == SOFT => match text {
            "down" | "on" => 1.0,
            "up" | "off" => 0.0,
            _ => match text.strip_suffix('%') {
                Some(percent) => percent.trim().parse::<f64>().ok()? / 100.0,
                None => text.parse().ok()?,
            },
        },
        _ => text.trim_end_matches("dB").trim().parse().ok()?,
    };
    Some(PARAMS[i].clamp(value))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_are_distinct_and_defaults_in_range() {
        for (i, p) in PARAMS.iter().enumerate() {
            assert_eq!(index_of(p.id), Some(i));
            assert_eq!(p.clamp(p.default), p.default, "{}", p.key);
        }
        assert_eq!(index_of(0), None);
    }
}
