//! The plugin's saved state: a short TOML text naming its format and version, then every
//! parameter by its key. A DAW project is untrusted input: a load refuses (and changes nothing)
//! what is not this format, a newer version, an unknown or missing field or a value out of its
//! range, saying which; the text is at most [`MAX_STATE_BYTES`]. An older version's state gives
//! the parameters it did not save their defaults (version 1: `integrator`, exact; versions 1–2:
//! `halo`, off).

use crate::params::{Values, PARAMS};
use std::fmt::Write as _;

/// The format's name, first in every state.
pub const FORMAT: &str = "unacorda-clap";
/// The version this build writes and the newest it reads.
pub const VERSION: i64 = 3;
/// Largest state read (a real one is ~250 bytes).
pub const MAX_STATE_BYTES: usize = 64 * 1024;

/// Why a state is refused.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum StateError {
    #[error("the state is larger than {MAX_STATE_BYTES} bytes: not an unacorda state")]
    TooLarge,
    #[error("the state is not UTF-8 text: not an unacorda state")]
    NotText,
    #[error("the state is not TOML ({0}): not an unacorda state")]
    NotToml(String),
    #[error("the state's format is {0:?}, not \"{FORMAT}\": it belongs to another plugin")]
    Foreign(String),
    #[error("the state is version {0}, newer than this unacorda-clap reads ({VERSION}): update the plugin")]
    Newer(i64),
    #[error("the state's version {0} is not valid (1–{VERSION})")]
    BadVersion(i64),
    #[error("the state has no field `{0}`")]
    Missing(&'static str),
    #[error("the state's field `{0}` is not known to version {1}")]
    Unknown(String, i64),
    #[error("the state's field `{field}` is {value}: expected {expected}")]
    Range {
        field: &'static str,
        value: String,
        expected: String,
    },
}

/// The state of `values` as text.
pub fn save(values: &Values) -> String {
    let mut s = format!("format = \"{FORMAT}\"\nversion = {VERSION}\n");
    for (i, p) in PARAMS.iter().enumerate() {
        let v = values.get(i);
        // Written so as to read back exactly: names for choices, integers where stepped, the
        // shortest decimal that round-trips otherwise.
        let _ = match p.choice(v) {
            Some(name) => writeln!(s, "{} = \"{name}\"", p.key),
            None if p.stepped => writeln!(s, "{} = {}", p.key, v as i64),
            None => writeln!(s, "{} = {v:?}", p.key),
        };
    }
    s
}

/// Read a state; on success every parameter's value, in [`PARAMS`] order.
pub fn load(bytes: &[u8]) -> Result<[f64; PARAMS.len()], StateError> {
    if bytes.len() > MAX_STATE_BYTES {
        return Err(StateError::TooLarge);
    }
    let text = std::str::from_utf8(bytes).map_err(|_| StateError::NotText)?;
    let table: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| StateError::NotToml(e.message().to_string()))?;
    match table.get("format") {
        Some(toml::Value::String(f)) if f == FORMAT => {}
        Some(toml::Value::String(other)) => return Err(StateError::Foreign(other.clone())),
        Some(other) => return Err(StateError::Foreign(other.to_string())),
        None => return Err(StateError::Missing("format")),
    }
    let version = match table.get("version") {
        Some(toml::Value::Integer(v)) if *v > VERSION => return Err(StateError::Newer(*v)),
        Some(toml::Value::Integer(v)) if *v >= 1 => *v,
        Some(toml::Value::Integer(v)) => return Err(StateError::BadVersion(*v)),
        Some(other) => {
            return Err(StateError::Range {
                field: "version",
                value: other.to_string(),
                expected: format!("an integer 1–{VERSION}"),
            })
        }
        None => return Err(StateError::Missing("version")),
    };
    let saved = |p: &crate::params::Spec| p.since_version <= version;
    if let Some(unknown) = table.keys().find(|k| {
        *k != "format" && *k != "version" && !PARAMS.iter().any(|p| saved(p) && p.key == *k)
    }) {
        return Err(StateError::Unknown(unknown.clone(), version));
    }
    let mut out = [0.0; PARAMS.len()];
    for (i, p) in PARAMS.iter().enumerate() {
        if !saved(p) {
            out[i] = p.default;
            continue;
        }
        let value = table.get(p.key).ok_or(StateError::Missing(p.key))?;
        let range = |value: &toml::Value| {
            let expected = match (p.choices, p.stepped) {
                (Some(names), _) => format!("one of {names:?}"),
                (None, true) => format!("an integer {}–{}", p.min, p.max),
                (None, false) => format!("a number in [{}, {}]", p.min, p.max),
            };
            StateError::Range {
                field: p.key,
                value: value.to_string(),
                expected,
            }
        };
        out[i] = match (p.choices, value) {
            (Some(names), toml::Value::String(name)) => names
                .iter()
                .position(|k| k == name)
                .ok_or_else(|| range(value))?
                as f64,
            (Some(_), _) => return Err(range(value)),
            (None, toml::Value::Integer(n)) if p.stepped => *n as f64,
            (None, toml::Value::Float(x)) if !p.stepped => *x,
            (None, toml::Value::Integer(n)) if !p.stepped => *n as f64,
            _ => return Err(range(value)),
        };
        if !(p.min..=p.max).contains(&out[i]) {
            return Err(range(value));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::{GAIN_DB, HALO, INTEGRATOR, KEYBOARD, SOFT, VELOCITY_CURVE, VOICES};

    #[test]
    fn a_state_round_trips_exactly() {
        let values = Values::default();
        values.set(SOFT, 1.0);
        values.set(GAIN_DB, -7.123456789012345);
        values.set(VELOCITY_CURVE, 1.0 / 3.0);
        values.set(KEYBOARD, 1.0);
        values.set(VOICES, 17.0);
        values.set(INTEGRATOR, 1.0);
        values.set(HALO, 1.0);
        let text = save(&values);
        println!("{text}");
        let back = load(text.as_bytes()).unwrap();
        for (i, v) in back.iter().enumerate() {
            assert_eq!(v.to_bits(), values.get(i).to_bits(), "{}", PARAMS[i].key);
        }
    }

    #[test]
    fn foreign_newer_and_out_of_range_states_are_refused_by_name() {
        let good = save(&Values::default());
        let cases = [
            (
                good.replace("unacorda-clap", "other-synth"),
                "another plugin",
            ),
            (good.replace("version = 3", "version = 4"), "newer than"),
            (
                good.replace("\"exact\"", "\"euler\""),
                "one of [\"exact\", \"rk4\"]",
            ),
            // Version 1 did not save the integrator, nor version 2 the halo.
            (
                good.replace("version = 3", "version = 1")
                    .replace("halo = 0\n", ""),
                "`integrator` is not known",
            ),
            (
                good.replace("version = 3", "version = 2"),
                "`halo` is not known",
            ),
            (good.replace("halo = 0", "halo = 2"), "`halo` is 2"),
            (good.replace("voices = 64", "voices = 0"), "`voices` is 0"),
            (
                good.replace("gain_db = 0.0", "gain_db = nan"),
                "`gain_db` is nan",
            ),
            (good.replace("\"concert\"", "\"harpsichord\""), "one of"),
            (good.replace("soft = 0.0\n", ""), "no field `soft`"),
            (format!("{good}colour = 3\n"), "`colour` is not known"),
            ("\u{0}\u{1}binary".to_string(), "not TOML"),
        ];
        for (text, says) in cases {
            let e = load(text.as_bytes()).unwrap_err().to_string();
            println!("{e}");
            assert!(e.contains(says), "{e:?} should say {says:?}");
        }
        assert_eq!(
            load(&[b' '; MAX_STATE_BYTES + 1]),
            Err(StateError::TooLarge)
        );
    }

    #[test]
    fn a_version_1_state_loads_with_the_exact_integrator() {
        let v1 = "format = \"unacorda-clap\"\nversion = 1\nsustain = 1\nsostenuto = 0\nsoft = 0\ngain_db = -3.5\nvelocity_curve = 1.0\nkeyboard = \"paper\"\nvoices = 32\n";
        let back = load(v1.as_bytes()).unwrap();
        assert_eq!(back[INTEGRATOR], 0.0);
        assert_eq!(back[HALO], 0.0);
        assert_eq!(
            (back[KEYBOARD], back[VOICES], back[GAIN_DB]),
            (1.0, 32.0, -3.5)
        );
    }
}
