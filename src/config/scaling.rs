//! Keyboard scaling: the strings and hammer of every key A0 (1) … C8 (88) from a few anchor keys.
//!
//! A scaling file (TOML, `presets/keyboard.toml`) names a base preset for what does not vary along
//! the keyboard (damping ratios, contact, soundboard, rates), the string layout (single, bichord,
//! trichord; wound or plain; muted or free duplex) and anchor keys. Between anchors every quantity
//! is interpolated linearly in key number on a log scale; the linear density follows the pitch,
//! `mu = T0 / (2 L_s f_ET)^2`, times a correction exact at the anchors. Each key becomes an ordinary
//! per-note [`Preset`] bridged at its own point of the soundboard.

use crate::config::preset::{
    bridge_point_index, check_damper_travel, heard, read_text, FeltModelName, HammerFeltSection,
    LoadedPreset, Preset, PresetError, RadiationSection, StringsSection, MAX_EXPONENT,
    MAX_FULL_SCALE_PA, MAX_HAMMER_MASS_KG, MAX_HYSTERESIS_S, MIN_EXPONENT, MIN_FULL_SCALE_PA,
    MIN_HAMMER_MASS_KG,
};
use crate::engine::physics::damper::{DamperParams, FeltModel};
use crate::engine::physics::string::StringParams;
use crate::engine::tuning::bridged_pitch_hz;
use serde::Deserialize;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

/// The built-in keyboards: name, file, text. `grand` is the paper's keyboard's earlier name.
const BUILTIN: &[(&str, &str, &str)] = &[
    (
        "concert",
        "presets/concert.toml",
        include_str!("../../presets/concert.toml"),
    ),
    (
        "paper",
        "presets/keyboard.toml",
        include_str!("../../presets/keyboard.toml"),
    ),
    (
        "grand",
        "presets/keyboard.toml",
        include_str!("../../presets/keyboard.toml"),
    ),
];

/// The number of keys.
pub const KEYS: usize = 88;

/// A keyboard: its layout, its anchor keys and the strings' losses, resolved (a file that names a
/// `base_keyboard` takes from it what it does not set itself).
#[derive(Debug, Clone, PartialEq)]
pub struct Scaling {
    pub name: String,
    pub base_preset: String,
    pub layout: Layout,
    pub anchors: Vec<Anchor>,
    pub strings: StringOverrides,
    pub losses: Vec<LossAnchor>,
    pub dampers: Vec<DamperAnchor>,
    /// How the exact engine carries every key's damper felt (`damper_model`); `None`: the base
    /// preset's.
    pub damper_model: Option<FeltModel>,
    /// Every key's damper travel (`[damper_travel]`); `None`: the base preset's.
    pub damper_travel: Option<DamperTravel>,
    /// Every key's hammer felt across its width (`[hammer_felt]`); `None`: the base preset's.
    pub hammer_felt: Option<HammerFeltSection>,
    pub voicing: Vec<VoicingAnchor>,
    /// Registers whose string modes reach another frequency than `layout.max_mode_freq_hz`
    /// (`mode_limits`), in increasing keys.
    pub mode_limits: Vec<ModeLimit>,
    pub tuning: Tuning,
    /// The octave a stretched tuning reaches in the bass (`bass_octave`).
    pub bass_octave: BassOctave,
    /// The key from which down the bass octaves are `bass_octave`'s (`bass_octave_from_key`,
    /// 1–36); between it and the temperament they blend from 2:1.
    pub bass_octave_from_key: usize,
    /// The soundboard asset every key stands on (`soundboard.asset`); `None`: the base preset's.
    pub soundboard_asset: Option<AssetRef>,
    /// The soundboard asset's listener every key radiates to (`radiation.listener`); `None`: the
    /// base preset's.
    pub listener: Option<String>,
    /// The listeners of the left and right channels (`radiation.stereo`); `None`: the base
    /// preset's.
    pub stereo: Option<[String; 2]>,
    /// The sound pressure heard as full scale, 0 dBFS (`radiation.full_scale_pa`, Pa); `None`:
    /// the base preset's.
    pub full_scale_pa: Option<f64>,
}

/// A soundboard asset as a keyboard file names it: a built-in asset's name or a file's path, and
/// the directory of the keyboard file that names it, which a path is relative to.
#[derive(Debug, Clone, PartialEq)]
pub struct AssetRef {
    pub name: String,
    pub dir: PathBuf,
}

/// What a keyboard is tuned to.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Tuning {
    /// Equal temperament, A4 = 440 Hz.
    #[default]
    Equal,
    /// Octaves stretched from A3–A4 outwards on the keys' own inharmonicity
    /// ([`LoadedScaling::stretch_cents`]).
    Stretched,
}

/// The octave a stretched tuning reaches in the bass: the lower key's partial that is tuned
/// beatless against the upper key's half-numbered one. The wider the pair, the more the strings'
/// stiffness counts and the wider the octave. Tuners choose the interval per register and blend
/// between them (docs/realism-sources.md §3): from the temperament's 2:1 to this one.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
pub enum BassOctave {
    #[default]
    #[serde(rename = "4:2")]
    FourTwo,
    #[serde(rename = "6:3")]
    SixThree,
    #[serde(rename = "8:4")]
    EightFour,
    #[serde(rename = "10:5")]
    TenFive,
}

impl BassOctave {
    /// The lower key's partial number (the upper key's is half of it).
    pub fn lower_partial(self) -> f64 {
        match self {
            BassOctave::FourTwo => 4.0,
            BassOctave::SixThree => 6.0,
            BassOctave::EightFour => 8.0,
            BassOctave::TenFive => 10.0,
        }
    }
}

/// `bass_octave_from_key` when a keyboard gives none: E2.
const BASS_OCTAVE_FROM_KEY: usize = 20;

/// How many keys either side the bass's inharmonicity is averaged over for a stretched tuning
/// ([`LoadedScaling::tuning_inharmonicity`]): an octave's span.
const TUNING_B_WINDOW_KEYS: usize = 6;

/// The temperament octave A3–A4, from which a stretched tuning sets octaves outwards.
const TEMPERAMENT_OCTAVE: std::ops::RangeInclusive<usize> = 37..=49;

/// A scaling file as written.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct ScalingFile {
    name: String,
    base_preset: Option<String>,
    /// A built-in keyboard or a file whose layout, anchors, string settings and losses this one
    /// keeps where it does not give its own.
    base_keyboard: Option<String>,
    layout: Option<Layout>,
    anchors: Option<Vec<Anchor>>,
    #[serde(default)]
    strings: StringOverrides,
    #[serde(default)]
    losses: Vec<LossAnchor>,
    /// A built-in soundboard asset or a file relative to this one.
    soundboard_asset: Option<String>,
    listener: Option<String>,
    stereo: Option<[String; 2]>,
    full_scale_pa: Option<f64>,
    #[serde(default)]
    dampers: Vec<DamperAnchor>,
    /// `coupled` or `modal` ([`FeltModel`]); inherited from the base keyboard when absent.
    damper_model: Option<FeltModelField>,
    /// Inherited from the base keyboard when absent.
    damper_travel: Option<DamperTravel>,
    /// Inherited from the base keyboard when absent; a field it leaves out takes the default
    /// profile's.
    hammer_felt: Option<HammerFeltSection>,
    #[serde(default)]
    voicing: Vec<VoicingAnchor>,
    #[serde(default)]
    mode_limits: Vec<ModeLimit>,
    /// `equal` (the default) or `stretched`; inherited from the base keyboard when absent.
    tuning: Option<Tuning>,
    /// `4:2` (the default), `6:3`, `8:4` or `10:5`; inherited from the base keyboard when absent.
    bass_octave: Option<BassOctave>,
    /// 1–36 (default 20, E2); inherited from the base keyboard when absent.
    bass_octave_from_key: Option<usize>,
}

/// A [`FeltModel`] as a keyboard file names it.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(transparent)]
struct FeltModelField(#[serde(with = "FeltModelName")] FeltModel);

/// String settings of the base preset that a keyboard replaces on every key.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StringOverrides {
    pub damping_ratio_t: Option<f64>,
    pub damping_ratio_p: Option<f64>,
    /// The duplex felt's c_d (N s/m^2, Eq. 13) on the keys whose duplex is damped.
    pub duplex_damping_n_s_m2: Option<f64>,
}

/// The strings' frequency-dependent losses at one key (`ModeSet`: `sigma = b1 + b3 omega^2` on
/// T and P), interpolated between such keys like the anchors.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LossAnchor {
    pub key: usize,
    pub b1_per_s: f64,
    pub b3_s: f64,
}

/// Every damper's travel: how far its felt rises clear of the strings at the full lift and how
/// far it sits pressed into them at rest (m), what a part-lifted damper's share of its felt
/// follows ([`DamperParams::contact_share`]).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DamperTravel {
    pub full_lift_m: f64,
    pub rest_compression_m: f64,
}

/// The damper at one key: where its felt lies, how far apart its two contact points are, and how
/// fast it silences the key's first partial (its coefficient follows,
/// [`DamperParams::coefficient_for_t60`]), interpolated between such keys like the anchors.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DamperAnchor {
    pub key: usize,
    /// Centre of the felt as a fraction of the speaking length (-).
    pub position_ratio: f64,
    /// Distance between the felt's two contact points along the string (m).
    pub width_m: f64,
    /// T60 of the speaking length's first mode with the damper down (s).
    pub t60_s: f64,
}

/// The hammers' voicing at one key: how much harder its felt is than the anchors' (a technician
/// hardens the top hammers so that the treble carries), and optionally the felt's exponent and
/// hysteresis and the hammer's mass, interpolated between such keys like the anchors.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VoicingAnchor {
    pub key: usize,
    /// Factor on the felt's stiffness `K` (Eq. 8) (-).
    pub felt_stiffness_factor: f64,
    /// The felt's hysteresis `alpha` (s, [`HammerParams::hysteresis_s`]), interpolated linearly;
    /// given at every voicing point or at none (then the base preset's).
    ///
    /// [`HammerParams::hysteresis_s`]: crate::engine::physics::hammer::HammerParams::hysteresis_s
    pub felt_hysteresis_s: Option<f64>,
    /// The felt's exponent `p` (Eq. 8, -), interpolated linearly; its `K` is then set so that the
    /// force at [`VOICING_COMPRESSION_M`] is the anchors' felt's times `felt_stiffness_factor`.
    /// Given at every voicing point or at none (then the anchors').
    pub felt_exponent: Option<f64>,
    /// The hammer's mass as the string feels it (kg), interpolated geometrically like the
    /// anchors'; given at every voicing point or at none (then the anchors').
    pub hammer_mass_kg: Option<f64>,
}

/// The string modes a register keeps: from `from_key` up to the next limit's key (or C8), modes
/// below `max_mode_freq_hz` in place of `layout.max_mode_freq_hz` (still at most
/// `layout.max_modes_t` and `max_modes_l`). The exact engine advances every mode at the output
/// rate, so the limit is at most half of it; the keys below the first limit keep the layout's.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModeLimit {
    pub from_key: usize,
    /// Modes of the register's strings are kept below this frequency (Hz).
    pub max_mode_freq_hz: f64,
}

/// An optional field of a voicing point.
type OptionalField = fn(&VoicingAnchor) -> Option<f64>;

/// The compression at which a voicing that changes a felt's exponent keeps its force (m): about
/// a mezzoforte blow's (C4 struck at 2.4 m/s compresses the paper's felt 0.97 mm).
pub const VOICING_COMPRESSION_M: f64 = 1e-3;

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Layout {
    pub single_until_key: usize,
    pub bichord_until_key: usize,
    pub wound_until_key: usize,
    pub duplex_damped_until_key: usize,
    pub dampers_until_key: usize,
    pub mistuning_cents: [f64; 3],
    pub max_mode_freq_hz: f64,
    pub max_modes_t: usize,
    pub max_modes_l: usize,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Anchor {
    pub key: usize,
    pub speaking_length_m: f64,
    pub duplex_length_m: f64,
    pub tension_n: f64,
    /// The anchor's tension is final (tuned on the coupled system); otherwise the key is tuned
    /// on its bridge spring like every key between anchors.
    pub tension_tuned: bool,
    pub linear_density_kg_m: f64,
    pub core_diameter_m: f64,
    pub hammer_mass_kg: f64,
    pub hammer_stiffness_n_m_p: f64,
    pub hammer_exponent: f64,
    pub strike_ratio: f64,
}

/// A scaling with its base preset resolved.
#[derive(Debug, Clone)]
pub struct LoadedScaling {
    pub scaling: Scaling,
    pub source: PathBuf,
    pub base: LoadedPreset,
}

/// Equal-tempered frequency of key `k` (A4 = key 49 = 440 Hz).
pub fn equal_tempered_hz(key: usize) -> f64 {
    440.0 * 2f64.powf((key as f64 - 49.0) / 12.0)
}

/// Key number of a name (`C4`, `Bb3`, `Db2`; flats or sharps, in any case: `c4`, `bb3`, `DB2`)
/// or of a number 1–88.
pub fn parse_key(text: &str) -> Option<usize> {
    if let Ok(k) = text.parse::<usize>() {
        return (1..=KEYS).contains(&k).then_some(k);
    }
    let names = [
        "C", "C#", "D", "D#", "E", "F", "F#", "G", "G#", "A", "A#", "B",
    ];
    let flats = [
        "C", "Db", "D", "Eb", "E", "F", "Gb", "G", "Ab", "A", "Bb", "B",
    ];
    let split = text.find(|c: char| c.is_ascii_digit() || c == '-')?;
    let (pitch, octave) = text.split_at(split);
    let octave: i32 = octave.parse().ok()?;
    // The letter in capitals, an accidental after it `#` or `b` whatever the case it was typed.
    let mut chars = pitch.chars();
    let pitch: String = chars
        .next()
        .map(|c| c.to_ascii_uppercase())
        .into_iter()
        .chain(chars.map(|c| if c == 'B' { 'b' } else { c }))
        .collect();
    let pitch = pitch.as_str();
    let pc = names
        .iter()
        .position(|n| *n == pitch)
        .or_else(|| flats.iter().position(|n| *n == pitch))? as i32;
    let key = (octave + 1) * 12 + pc - 20;
    (1..=KEYS as i32).contains(&key).then_some(key as usize)
}

/// How many keyboards a `base_keyboard` chain may hold (a file naming itself would never end).
const MAX_CHAIN: usize = 4;

impl Scaling {
    /// A built-in keyboard by name (`concert`, `paper`, also called `grand`) or a TOML file by
    /// path.
    pub fn resolve(name_or_path: &str) -> Result<LoadedScaling, PresetError> {
        let (scaling, source) = Scaling::read(name_or_path, 1)?;
        scaling.with_base(source)
    }

    /// A keyboard file's text (`path` names it in errors), its `base_keyboard` chain resolved.
    pub fn parse(text: &str, path: &Path) -> Result<LoadedScaling, PresetError> {
        Scaling::from_text(text, path, 1)?.with_base(path.to_owned())
    }

    /// This keyboard read from `source`, with its base preset.
    fn with_base(self, source: PathBuf) -> Result<LoadedScaling, PresetError> {
        let base = Preset::resolve(&self.base_preset)?;
        let base = match &self.soundboard_asset {
            Some(asset) => base.on_board(&asset.name, &asset.dir)?,
            None => base,
        };
        // The exact engine advances every mode at the output rate: a string mode above the
        // output's band edge would fold back into the audible band (tests/bad_input.rs). The
        // lower bound is `validate`'s; this one needs the base preset's output rate.
        let edge_hz = 0.5 * base.output_rate_hz();
        let limits = std::iter::once((
            "layout.max_mode_freq_hz",
            None,
            self.layout.max_mode_freq_hz,
        ))
        .chain(self.mode_limits.iter().map(|m| {
            (
                "mode_limits.max_mode_freq_hz",
                Some(m.from_key),
                m.max_mode_freq_hz,
            )
        }));
        for (field, from_key, max_hz) in limits {
            if max_hz > edge_hz {
                return Err(PresetError::Range {
                    path: source,
                    field,
                    value: match from_key {
                        Some(k) => format!("{max_hz} (from key {k})"),
                        None => max_hz.to_string(),
                    },
                    allowed: format!(
                        "a frequency above 100 Hz and at most half the output rate ({edge_hz} Hz), where a mode would fold back"
                    ),
                });
            }
        }
        Ok(LoadedScaling {
            scaling: self,
            source,
            base,
        })
    }

    /// The keyboard `name_or_path`, the `depth`-th of a `base_keyboard` chain, resolved.
    fn read(name_or_path: &str, depth: usize) -> Result<(Scaling, PathBuf), PresetError> {
        let (text, path) = match BUILTIN.iter().find(|(n, _, _)| *n == name_or_path) {
            Some((_, path, text)) => (text.to_string(), PathBuf::from(path)),
            None => {
                let path = PathBuf::from(name_or_path);
                (read_text(&path)?, path)
            }
        };
        Ok((Scaling::from_text(&text, &path, depth)?, path))
    }

    /// [`Scaling::parse`] at `depth` of a chain.
    fn from_text(text: &str, path: &Path, depth: usize) -> Result<Scaling, PresetError> {
        let path = path.to_owned();
        let file: ScalingFile = toml::from_str(text).map_err(|e| PresetError::Parse {
            path: path.clone(),
            message: e.to_string().trim_end().to_owned(),
        })?;
        let base = match &file.base_keyboard {
            Some(name) if depth >= MAX_CHAIN => {
                return Err(PresetError::Range {
                    path,
                    field: "base_keyboard",
                    value: name.clone(),
                    allowed: format!("a chain of at most {MAX_CHAIN} keyboards"),
                })
            }
            Some(name) => Some(Scaling::read(name, depth + 1)?.0),
            None => None,
        };
        let missing = |field: &'static str| PresetError::Range {
            path: path.clone(),
            field,
            value: "absent".to_owned(),
            allowed: "given in this file or by its base_keyboard".to_owned(),
        };
        let inherit = |own: Option<f64>, f: fn(&StringOverrides) -> Option<f64>| {
            own.or_else(|| base.as_ref().and_then(|b| f(&b.strings)))
        };
        let strings = StringOverrides {
            damping_ratio_t: inherit(file.strings.damping_ratio_t, |s| s.damping_ratio_t),
            damping_ratio_p: inherit(file.strings.damping_ratio_p, |s| s.damping_ratio_p),
            duplex_damping_n_s_m2: inherit(file.strings.duplex_damping_n_s_m2, |s| {
                s.duplex_damping_n_s_m2
            }),
        };
        let scaling = Scaling {
            name: file.name,
            strings,
            tuning: file
                .tuning
                .or_else(|| base.as_ref().map(|b| b.tuning))
                .unwrap_or_default(),
            bass_octave: file
                .bass_octave
                .or_else(|| base.as_ref().map(|b| b.bass_octave))
                .unwrap_or_default(),
            bass_octave_from_key: file
                .bass_octave_from_key
                .or_else(|| base.as_ref().map(|b| b.bass_octave_from_key))
                .unwrap_or(BASS_OCTAVE_FROM_KEY),
            soundboard_asset: file
                .soundboard_asset
                .map(|name| AssetRef {
                    name,
                    dir: path.parent().unwrap_or(Path::new(".")).to_owned(),
                })
                .or_else(|| base.as_ref().and_then(|b| b.soundboard_asset.clone())),
            listener: file
                .listener
                .or_else(|| base.as_ref().and_then(|b| b.listener.clone())),
            stereo: file
                .stereo
                .or_else(|| base.as_ref().and_then(|b| b.stereo.clone())),
            full_scale_pa: file
                .full_scale_pa
                .or_else(|| base.as_ref().and_then(|b| b.full_scale_pa)),
            losses: inherit_points(file.losses, base.as_ref().map(|b| &b.losses)),
            dampers: inherit_points(file.dampers, base.as_ref().map(|b| &b.dampers)),
            damper_model: file
                .damper_model
                .map(|m| m.0)
                .or_else(|| base.as_ref().and_then(|b| b.damper_model)),
            damper_travel: file
                .damper_travel
                .or_else(|| base.as_ref().and_then(|b| b.damper_travel)),
            hammer_felt: file
                .hammer_felt
                .or_else(|| base.as_ref().and_then(|b| b.hammer_felt)),
            voicing: inherit_points(file.voicing, base.as_ref().map(|b| &b.voicing)),
            mode_limits: inherit_points(file.mode_limits, base.as_ref().map(|b| &b.mode_limits)),
            base_preset: file
                .base_preset
                .or_else(|| base.as_ref().map(|b| b.base_preset.clone()))
                .ok_or_else(|| missing("base_preset"))?,
            layout: file
                .layout
                .or_else(|| base.as_ref().map(|b| b.layout.clone()))
                .ok_or_else(|| missing("layout"))?,
            anchors: file
                .anchors
                .or_else(|| base.as_ref().map(|b| b.anchors.clone()))
                .ok_or_else(|| missing("anchors"))?,
        };
        scaling.validate(&path)?;
        Ok(scaling)
    }

    fn validate(&self, path: &Path) -> Result<(), PresetError> {
        let bad = |field: &'static str, value: String, allowed: &str| PresetError::Range {
            path: path.to_owned(),
            field,
            value,
            allowed: allowed.to_owned(),
        };
        if let Some(pa) = self.full_scale_pa {
            if !(pa.is_finite() && (MIN_FULL_SCALE_PA..=MAX_FULL_SCALE_PA).contains(&pa)) {
                return Err(bad(
                    "full_scale_pa",
                    pa.to_string(),
                    &format!(
                        "a sound pressure in [{MIN_FULL_SCALE_PA:e}, {MAX_FULL_SCALE_PA:e}] Pa"
                    ),
                ));
            }
        }
        let below_temperament = 1..*TEMPERAMENT_OCTAVE.start();
        if !below_temperament.contains(&self.bass_octave_from_key) {
            return Err(bad(
                "bass_octave_from_key",
                self.bass_octave_from_key.to_string(),
                "a key below the temperament, 1 (A0) to 36 (Ab3)",
            ));
        }
        // Points along the keyboard (anchors, losses, dampers, voicing) run in increasing keys
        // from A0 to C8.
        let spans_keyboard = |keys: &[usize]| {
            keys.first() == Some(&1)
                && keys.last() == Some(&KEYS)
                && keys.windows(2).all(|w| w[0] < w[1])
        };
        let keys: Vec<usize> = self.anchors.iter().map(|a| a.key).collect();
        if !spans_keyboard(&keys) {
            return Err(bad(
                "anchors.key",
                format!("{keys:?}"),
                "increasing keys from 1 (A0) to 88 (C8)",
            ));
        }
        for a in &self.anchors {
            for (field, v) in [
                ("anchors.speaking_length_m", a.speaking_length_m),
                ("anchors.duplex_length_m", a.duplex_length_m),
                ("anchors.tension_n", a.tension_n),
                ("anchors.linear_density_kg_m", a.linear_density_kg_m),
                ("anchors.core_diameter_m", a.core_diameter_m),
                ("anchors.hammer_mass_kg", a.hammer_mass_kg),
                ("anchors.hammer_stiffness_n_m_p", a.hammer_stiffness_n_m_p),
                ("anchors.hammer_exponent", a.hammer_exponent),
                ("anchors.strike_ratio", a.strike_ratio),
            ] {
                if !(v.is_finite() && v > 0.0) {
                    return Err(bad(
                        field,
                        format!("{v} (key {})", a.key),
                        "a finite number > 0",
                    ));
                }
            }
        }
        // Losses, dampers and voicing are optional; given, they span the keyboard like the
        // anchors.
        let optional = |field: &'static str, keys: Vec<usize>| match keys.is_empty()
            || spans_keyboard(&keys)
        {
            true => Ok(()),
            false => Err(bad(
                field,
                format!("{keys:?}"),
                "none, or increasing keys from 1 (A0) to 88 (C8)",
            )),
        };
        optional("losses.key", self.losses.iter().map(|a| a.key).collect())?;
        optional("dampers.key", self.dampers.iter().map(|a| a.key).collect())?;
        optional("voicing.key", self.voicing.iter().map(|a| a.key).collect())?;
        // The voicing's optional fields are given at every point or at none.
        let optional_fields: [(&str, OptionalField, f64, f64); 3] = [
            (
                "voicing.felt_hysteresis_s",
                |a| a.felt_hysteresis_s,
                0.0,
                MAX_HYSTERESIS_S,
            ),
            (
                "voicing.felt_exponent",
                |a| a.felt_exponent,
                MIN_EXPONENT,
                MAX_EXPONENT,
            ),
            (
                "voicing.hammer_mass_kg",
                |a| a.hammer_mass_kg,
                MIN_HAMMER_MASS_KG,
                MAX_HAMMER_MASS_KG,
            ),
        ];
        for (field, get, lo, hi) in optional_fields {
            let given = self.voicing.iter().filter(|a| get(a).is_some()).count();
            if given != 0 && given != self.voicing.len() {
                return Err(bad(
                    field,
                    format!("given at {given} of {} points", self.voicing.len()),
                    "at every voicing point or at none",
                ));
            }
            for a in &self.voicing {
                if let Some(v) = get(a) {
                    if !(v.is_finite() && (lo..=hi).contains(&v)) {
                        return Err(bad(
                            field,
                            format!("{v} (key {})", a.key),
                            &format!("a number in [{lo}, {hi}]"),
                        ));
                    }
                }
            }
        }
        for a in &self.voicing {
            let v = a.felt_stiffness_factor;
            if !(v.is_finite() && (0.01..=1e4).contains(&v)) {
                return Err(bad(
                    "voicing.felt_stiffness_factor",
                    format!("{v} (key {})", a.key),
                    "a number in [0.01, 10000]",
                ));
            }
        }
        for a in &self.losses {
            for (field, v, hi) in [
                ("losses.b1_per_s", a.b1_per_s, 100.0),
                ("losses.b3_s", a.b3_s, 1e-6),
            ] {
                if !(v.is_finite() && v > 0.0 && v <= hi) {
                    return Err(bad(
                        field,
                        format!("{v} (key {})", a.key),
                        &format!("a number in (0, {hi:e}]"),
                    ));
                }
            }
        }
        if let Some(t) = &self.damper_travel {
            check_damper_travel(
                t.full_lift_m,
                t.rest_compression_m,
                [
                    "damper_travel.rest_compression_m",
                    "damper_travel.full_lift_m",
                ],
            )
            .map_err(|(field, value, allowed)| bad(field, value, &allowed))?;
        }
        if let Some(felt) = &self.hammer_felt {
            felt.check()
                .map_err(|(field, value, allowed)| bad(field, value, &allowed))?;
        }
        for a in &self.dampers {
            for (field, v, lo, hi) in [
                ("dampers.position_ratio", a.position_ratio, 0.01, 0.5),
                ("dampers.width_m", a.width_m, 1e-3, 0.1),
                ("dampers.t60_s", a.t60_s, 0.02, 60.0),
            ] {
                if !(v.is_finite() && (lo..=hi).contains(&v)) {
                    return Err(bad(
                        field,
                        format!("{v} (key {})", a.key),
                        &format!("a number in [{lo}, {hi}]"),
                    ));
                }
            }
        }
        let l = &self.layout;
        if !(l.single_until_key < l.bichord_until_key && l.bichord_until_key <= KEYS) {
            return Err(bad(
                "layout.bichord_until_key",
                l.bichord_until_key.to_string(),
                "above layout.single_until_key and at most 88",
            ));
        }
        for (field, value, lo, hi) in [
            ("layout.max_modes_t", l.max_modes_t, 1, 400),
            ("layout.max_modes_l", l.max_modes_l, 0, 50),
        ] {
            if !(lo..=hi).contains(&value) {
                return Err(bad(field, value.to_string(), &format!("{lo} to {hi}")));
            }
        }
        if !(l.max_mode_freq_hz.is_finite() && l.max_mode_freq_hz > 100.0) {
            return Err(bad(
                "layout.max_mode_freq_hz",
                l.max_mode_freq_hz.to_string(),
                "a frequency above 100 Hz",
            ));
        }
        let from: Vec<usize> = self.mode_limits.iter().map(|m| m.from_key).collect();
        if !(from.iter().all(|k| (1..=KEYS).contains(k)) && from.windows(2).all(|w| w[0] < w[1])) {
            return Err(bad(
                "mode_limits.from_key",
                format!("{from:?}"),
                "increasing keys from 1 (A0) to 88 (C8)",
            ));
        }
        for m in &self.mode_limits {
            if !(m.max_mode_freq_hz.is_finite() && m.max_mode_freq_hz > 100.0) {
                return Err(bad(
                    "mode_limits.max_mode_freq_hz",
                    format!("{} (from key {})", m.max_mode_freq_hz, m.from_key),
                    "a frequency above 100 Hz",
                ));
            }
        }
        Ok(())
    }
}

/// A keyboard's own points along the keyboard (losses, dampers, voicing), or its base keyboard's where it
/// gives none.
fn inherit_points<A: Clone>(own: Vec<A>, base: Option<&Vec<A>>) -> Vec<A> {
    match (own.is_empty(), base) {
        (true, Some(base)) => base.clone(),
        _ => own,
    }
}

/// `f` at `key` from points at increasing keys: exact at a point, linear between two, the end
/// value beyond the ends.
fn linear<A>(points: &[A], key_of: impl Fn(&A) -> usize, key: usize, f: impl Fn(&A) -> f64) -> f64 {
    between(points, key_of, key, f, |a, b, t| a + (b - a) * t)
}

/// `f` at `key` from points at increasing keys: exact at a point, linear in `ln f` between two,
/// the end value beyond the ends.
fn log_linear<A>(
    points: &[A],
    key_of: impl Fn(&A) -> usize,
    key: usize,
    f: impl Fn(&A) -> f64,
) -> f64 {
    between(points, key_of, key, f, |a, b, t| {
        (a.ln() * (1.0 - t) + b.ln() * t).exp()
    })
}

/// `f` at `key` from points at increasing keys: exact at a point, `mix(f(a), f(b), t)` between
/// two (`t` from 0 at `a` to 1 at `b`), the end value beyond the ends.
fn between<A>(
    points: &[A],
    key_of: impl Fn(&A) -> usize,
    key: usize,
    f: impl Fn(&A) -> f64,
    mix: impl Fn(f64, f64, f64) -> f64,
) -> f64 {
    let hi = points
        .partition_point(|a| key_of(a) < key)
        .min(points.len() - 1);
    let b = &points[hi];
    if key_of(b) == key || hi == 0 {
        return f(b);
    }
    let a = &points[hi - 1];
    let t = (key - key_of(a)) as f64 / (key_of(b) - key_of(a)) as f64;
    mix(f(a), f(b), t)
}

impl LoadedScaling {
    /// The radiation every key has: the base preset's, with the keyboard's listener, stereo pair
    /// and full scale where it sets them.
    pub fn radiation(&self) -> RadiationSection {
        let mut r = self.base.preset.radiation.clone();
        if let Some(listener) = &self.scaling.listener {
            r.listener = Some(listener.clone());
        }
        if let Some(stereo) = &self.scaling.stereo {
            r.stereo = Some(stereo.clone());
        }
        if let Some(full_scale_pa) = self.scaling.full_scale_pa {
            r.full_scale_pa = full_scale_pa;
        }
        r
    }

    /// The output stage of the keyboard's keys ([`RadiationSection::output_settings`]).
    pub fn output_settings(&self) -> crate::config::output::OutputSettings {
        self.radiation().output_settings(self.base.output_rate_hz())
    }

    /// An output gain (dB, [`crate::config::output::GAIN_DB`]) before the soft clipper: the
    /// keyboard's full scale lowered by it.
    pub fn set_gain_db(&mut self, gain_db: f64) {
        let pa = self.radiation().full_scale_pa;
        self.scaling.full_scale_pa = Some(crate::config::output::full_scale_with_gain(pa, gain_db));
    }

    /// Every key heard at the keyboard's `listener` in both channels, the stereo pair set aside
    /// (a front end's `--mono`).
    pub fn make_mono(&mut self) {
        self.scaling.stereo = None;
        self.base.make_mono();
    }

    /// Interpolate an anchor quantity at `key`: exact at anchors, log-linear between them.
    fn interpolate(&self, key: usize, f: impl Fn(&Anchor) -> f64) -> f64 {
        log_linear(&self.scaling.anchors, |a| a.key, key, f)
    }

    /// The base preset's strings section with `key`'s layout and geometry: count, mistuning,
    /// winding, lengths, tension (interpolated, before tuning), mass and core.
    fn strings_of(&self, key: usize) -> StringsSection {
        let l = &self.scaling.layout;
        let mut strings = self.base.preset.strings.clone();
        let s = &mut strings;
        s.count = if key <= l.single_until_key {
            1
        } else if key <= l.bichord_until_key {
            2
        } else {
            3
        };
        s.mistuning_cents = l.mistuning_cents[..s.count].to_vec();
        s.wound = key <= l.wound_until_key;
        s.speaking_length_m = self.interpolate(key, |a| a.speaking_length_m);
        s.duplex_length_m = self.interpolate(key, |a| a.duplex_length_m);
        s.tension_n = self.interpolate(key, |a| a.tension_n);
        let f_et = equal_tempered_hz(key);
        let ideal = |a: &Anchor| {
            a.tension_n / (2.0 * a.speaking_length_m * equal_tempered_hz(a.key)).powi(2)
        };
        let correction = self.interpolate(key, |a| a.linear_density_kg_m / ideal(a));
        s.linear_density_kg_m = match self.scaling.anchors.iter().find(|a| a.key == key) {
            Some(a) => a.linear_density_kg_m,
            None => correction * s.tension_n / (2.0 * s.speaking_length_m * f_et).powi(2),
        };
        s.core_diameter_m = if s.wound {
            self.interpolate(key, |a| a.core_diameter_m)
        } else {
            // A plain wire is all core: its diameter follows from its mass.
            (4.0 * s.linear_density_kg_m / (PI * s.density_kg_m3)).sqrt()
        };
        strings
    }

    /// The stretch of `key`'s tuning against equal temperament (cents): 0 for `equal`; for
    /// `stretched`, what a tuner sets from the strings' inharmonicity (Eq. 2's `B` of each speaking
    /// length, partial `n` at `n f1 sqrt((1 + B n^2) / (1 + B))`, `f1` the first), octave by
    /// octave from A4 outwards:
    /// - the temperament octave A3–A4 a 2:1 octave, its semitones equal;
    /// - above, each key's first partial on the second of the key an octave below (2:1);
    /// - below, each key's partial `2m` on the partial `m` of the key an octave above, the
    ///   octave's width blended linearly in key from a 2:1 octave's just below the temperament to
    ///   a `bass_octave` one's from `bass_octave_from_key` down,
    ///
    /// on the [`tuning_inharmonicity`](Self::tuning_inharmonicity) of the bass and temperament.
    /// The widths meet at the temperament's two ends, so that no semitone there is off by more
    /// than the stretch's own slope.
    pub fn stretch_cents(&self, key: usize) -> f64 {
        if self.scaling.tuning == Tuning::Equal {
            return 0.0;
        }
        // Partial n's offset from n times the first partial (cents).
        let partial = |b: f64, n: f64| 600.0 * ((1.0 + n * n * b) / (1.0 + b)).log2();
        let (a3, a4) = (*TEMPERAMENT_OCTAVE.start(), *TEMPERAMENT_OCTAVE.end());
        let b = |k: usize| self.tuning_inharmonicity(k);
        // An octave below `k + 12` with the lower key's partial `2m` on the upper's `m`.
        let octave_below = |k: usize, m: f64| partial(b(k), 2.0 * m) - partial(b(k + 12), m);
        if key > a4 {
            return self.stretch_cents(key - 12) + partial(b(key - 12), 2.0);
        }
        if key >= a3 {
            return -octave_below(a3, 1.0) * (a4 - key) as f64 / 12.0;
        }
        let bass = self.scaling.bass_octave.lower_partial() / 2.0;
        let from = self.scaling.bass_octave_from_key;
        // 0 just below the temperament, 1 from `from` down.
        let t = match from + 1 < a3 {
            true => ((a3 - 1 - key) as f64 / (a3 - 1 - from) as f64).min(1.0),
            false => 1.0,
        };
        self.stretch_cents(key + 12)
            - (1.0 - t) * octave_below(key, 1.0)
            - t * octave_below(key, bass)
    }

    /// The `B` of `key`'s speaking length (Eq. 2) as a stretched tuning reads it: the strings' own
    /// above the temperament; in the bass and the temperament (A0–A4) the geometric mean of the
    /// strings' own over [`TUNING_B_WINDOW_KEYS`] keys either side (fewer at A0 and A4), as an
    /// electronic tuner models a scale's inharmonicity from the notes it measured rather than
    /// following each one (TuneLab, docs/realism-sources.md §3). The wound strings' `B` jumps where
    /// the plain strings begin (1.1e-4 to 1.9e-4 at G2 on the concert keyboard), and octaves
    /// beatless on each string's own would put a semitone 2–3 cents narrow there.
    pub fn tuning_inharmonicity(&self, key: usize) -> f64 {
        let own = |k: usize| self.strings_of(k).nominal_string().speaking_inharmonicity();
        let a4 = *TEMPERAMENT_OCTAVE.end();
        if key > a4 {
            return own(key);
        }
        let window =
            key.saturating_sub(TUNING_B_WINDOW_KEYS).max(1)..=(key + TUNING_B_WINDOW_KEYS).min(a4);
        let n = window.clone().count() as f64;
        (window.map(|k| own(k).ln()).sum::<f64>() / n).exp()
    }

    /// The pitch `key` is tuned to (Hz): equal temperament (A4 = 440 Hz) and the stretch.
    pub fn target_hz(&self, key: usize) -> f64 {
        equal_tempered_hz(key) * 2f64.powf(self.stretch_cents(key) / 1200.0)
    }

    /// The rate every key of an instrument on this keyboard steps at with RK4 (Hz): the paper's
    /// `min_rate_over_fmax` times the highest frequency any register keeps, a whole multiple of
    /// the output rate (96 kHz for the paper keyboard; 240 kHz for the concert one, whose
    /// Bb7-C8 keep their modes to 20 kHz). One key rendered alone steps at its own.
    pub fn internal_rate_hz(&self) -> f64 {
        let s = &self.scaling;
        let f_max = s
            .mode_limits
            .iter()
            .map(|m| m.max_mode_freq_hz)
            .fold(s.layout.max_mode_freq_hz, f64::max);
        self.base.oversampling_for(f_max) as f64 * self.base.output_rate_hz()
    }

    /// The frequency below which `key`'s string modes are kept (Hz): its register's
    /// `mode_limits`, or `layout.max_mode_freq_hz` below the first.
    pub fn max_mode_freq_hz(&self, key: usize) -> f64 {
        let s = &self.scaling;
        s.mode_limits
            .iter()
            .rev()
            .find(|m| m.from_key <= key)
            .map_or(s.layout.max_mode_freq_hz, |m| m.max_mode_freq_hz)
    }

    /// The per-note preset of `key` (1–88), bridged at its own soundboard point.
    pub fn key_preset(&self, key: usize) -> Result<LoadedPreset, PresetError> {
        let l = &self.scaling.layout;
        let mut preset = self.base.preset.clone();
        preset.name = format!("{} {}", self.scaling.name, crate::board::key_name(key));
        preset.damper.present = key <= l.dampers_until_key;
        preset.strings = self.strings_of(key);
        let s = &mut preset.strings;
        let f_et = equal_tempered_hz(key);
        let own = &self.scaling.strings;
        s.damping_ratio_t = own.damping_ratio_t.unwrap_or(s.damping_ratio_t);
        s.damping_ratio_p = own.damping_ratio_p.unwrap_or(s.damping_ratio_p);
        s.duplex_damping_n_s_m2 = match key > l.duplex_damped_until_key {
            true => 0.0,
            false => own.duplex_damping_n_s_m2.unwrap_or(s.duplex_damping_n_s_m2),
        };
        let losses = &self.scaling.losses;
        if !losses.is_empty() {
            s.loss_b1_per_s = log_linear(losses, |a| a.key, key, |a| a.b1_per_s);
            s.loss_b3_s = log_linear(losses, |a| a.key, key, |a| a.b3_s);
        }
        // The strings in range before the tuner's eigen-problems see them (an absurd anchor is
        // an error naming its field, not a failed or endless solve).
        preset.validate(&self.source)?;
        let s = &mut preset.strings;
        // Modes below the frequency limit (for the sharpest string of the unison), at most the
        // paper's counts.
        let mut string = s.nominal_string();
        let sharpest = s.mistuning_cents.iter().copied().fold(0.0, f64::max);
        let f_lim = 2.0 * PI * self.max_mode_freq_hz(key);
        let count_modes = |string: &StringParams| {
            let top = string.detuned(sharpest);
            let t = (1..=l.max_modes_t)
                .take_while(|&n| top.transverse_omega(n) < f_lim)
                .count()
                .max(1);
            let lon = (1..=l.max_modes_l)
                .take_while(|&n| top.longitudinal_omega(n) < f_lim)
                .count();
            (t, lon)
        };
        let tuned = self
            .scaling
            .anchors
            .iter()
            .any(|a| a.key == key && a.tension_tuned);
        let target = self.target_hz(key);
        let mut retuned = None;
        if tuned {
            // Tuned on the coupled system to equal temperament: the stretch through the tension.
            string.tension_n *= (target / f_et).powi(2);
            s.tension_n = string.tension_n;
        } else {
            // Tune the tension until the string on the bridge and board is on its target as a
            // tuner hears it, on partials 2–8 (`bridged_pitch_hz`; a board mode near the first
            // partial pulls it alone). It converges in a few rounds: the partials go as sqrt(T0),
            // with a small stiffness term.
            let k_contact = self.base.contact().stiffness_n_m[0];
            let point = self.base.board.point(&crate::board::key_name(key));
            let board = point.map(|p| (&self.base.board, p));
            let tune = |string: &mut StringParams, modes: Option<usize>| {
                let mut used = 0;
                for _ in 0..4 {
                    used = modes.unwrap_or_else(|| count_modes(string).0);
                    let f1 = bridged_pitch_hz(string, used, k_contact, board, target);
                    string.tension_n *= (target / f1).powi(2);
                }
                used
            };
            let used = tune(&mut string, None);
            // The last round may carry a mode across the frequency limit, and the truncated
            // basis then moves the pitch (E7 stretched: 3 modes sound 90 cents above 4): the key
            // is tuned again with the count the tuned string has, and keeps that count.
            let last = count_modes(&string).0;
            if last != used {
                tune(&mut string, Some(last));
                retuned = Some(last);
            }
            s.tension_n = string.tension_n;
        }
        (s.modes_t, s.modes_l) = count_modes(&string);
        s.modes_t = retuned.unwrap_or(s.modes_t);
        s.modes_p = s.modes_t;
        let dampers = &self.scaling.dampers;
        if !dampers.is_empty() {
            // The felt's place and width, and the coefficient that gives the first mode its T60
            // on this key's (tuned) strings.
            let at = |f: fn(&DamperAnchor) -> f64| log_linear(dampers, |a| a.key, key, f);
            let mut felt = DamperParams {
                position_ratio: at(|a| a.position_ratio),
                damping_n_s_m: 0.0,
                width_m: at(|a| a.width_m),
                model: preset.damper.model,
                full_lift_m: preset.damper.full_lift_m,
                rest_compression_m: preset.damper.rest_compression_m,
            };
            felt.damping_n_s_m = felt.coefficient_for_t60(
                at(|a| a.t60_s),
                s.speaking_length_m,
                s.linear_density_kg_m,
            );
            let d = &mut preset.damper;
            (d.position_ratio, d.width_m, d.damping_n_s_m) =
                (felt.position_ratio, felt.width_m, felt.damping_n_s_m);
        }
        if let Some(model) = self.scaling.damper_model {
            preset.damper.model = model;
        }
        if let Some(t) = self.scaling.damper_travel {
            let d = &mut preset.damper;
            (d.full_lift_m, d.rest_compression_m) = (t.full_lift_m, t.rest_compression_m);
        }
        if let Some(felt) = self.scaling.hammer_felt {
            preset.hammer_felt = felt;
        }
        let h = &mut preset.hammer;
        h.mass_kg = self.interpolate(key, |a| a.hammer_mass_kg);
        h.stiffness_n_m_p = self.interpolate(key, |a| a.hammer_stiffness_n_m_p);
        h.exponent = self.interpolate(key, |a| a.hammer_exponent);
        let voicing = &self.scaling.voicing;
        if !voicing.is_empty() {
            h.stiffness_n_m_p *= log_linear(voicing, |a| a.key, key, |a| a.felt_stiffness_factor);
            let given = |f: OptionalField| {
                voicing
                    .iter()
                    .all(|a| f(a).is_some())
                    .then(|| linear(voicing, |a| a.key, key, |a| f(a).unwrap_or_default()))
            };
            if let Some(alpha_s) = given(|a| a.felt_hysteresis_s) {
                h.hysteresis_s = alpha_s;
            }
            // A new exponent keeps the felt's force at the reference compression.
            if let Some(p) = given(|a| a.felt_exponent) {
                h.stiffness_n_m_p *= VOICING_COMPRESSION_M.powf(h.exponent - p);
                h.exponent = p;
            }
            if voicing.iter().all(|a| a.hammer_mass_kg.is_some()) {
                h.mass_kg = log_linear(
                    voicing,
                    |a| a.key,
                    key,
                    |a| a.hammer_mass_kg.unwrap_or_default(),
                );
            }
        }
        h.strike_ratio = self.interpolate(key, |a| a.strike_ratio);
        preset.soundboard.bridge_point = crate::board::key_name(key);
        preset.radiation = self.radiation();
        preset.validate(&self.source)?;
        let bridge_point = bridge_point_index(
            &self.base.board,
            &preset.soundboard.bridge_point,
            &self.source,
            &preset.soundboard.asset,
        )?;
        let mut board = self.base.board.clone();
        board.heard = heard(
            &board,
            &preset.radiation,
            &self.source,
            &preset.soundboard.asset,
        )?;
        Ok(LoadedPreset {
            preset,
            source: self.source.clone(),
            board,
            bridge_point,
        })
    }
}
