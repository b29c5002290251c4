//! Preset files (TOML): every parameter of a note, with units in the field names.
//!
//! Unknown fields, missing fields and out-of-range values are errors that name the file, the field
//! and the allowed range. A preset names its soundboard asset either as a built-in (`grand`) or
//! as a path relative to the preset file.

use crate::board::BoardSpec;
use crate::config::asset::{self, AssetError};
use crate::engine::physics::contact::{hertz_stiffness_n_m, Contact};
use crate::engine::physics::damper::{self, DamperParams, FeltModel};
use crate::engine::physics::felt_profile::{FeltProfile, DEFAULT_PROFILE};
use crate::engine::physics::hammer::HammerParams;
use crate::engine::physics::soundboard::SoundboardModes;
use crate::engine::physics::string::{ModeSet, StringParams};
use crate::engine::UnisonSpec;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Built-in presets, by name.
const BUILTIN_PRESETS: &[(&str, &str)] = &[("c2", include_str!("../../presets/c2.toml"))];

/// Built-in soundboard assets, by name: Table 1's board (`grand`, the paper's) and the same
/// spruce and ribs on a grand's size and layout (`grand_sized`, the concert keyboard's).
const BUILTIN_ASSETS: &[(&str, &str)] = &[
    (
        "grand",
        include_str!("../../assets/soundboard_modes/grand.txt"),
    ),
    (
        "grand_sized",
        include_str!("../../assets/soundboard_modes/grand_sized.txt"),
    ),
];

/// The built-in board description that `grand.txt` is generated from.
pub const GRAND_BOARD_TOML: &str = include_str!("../../assets/soundboard_modes/grand.toml");

/// The sound pressures a preset or keyboard may hear as full scale (Pa).
pub const MIN_FULL_SCALE_PA: f64 = 1e-6;
pub const MAX_FULL_SCALE_PA: f64 = 1e4;

/// The largest preset, keyboard or board description read (bytes): the built-in ones are under
/// 20 kB; a larger file, or a device that never ends (`/dev/zero`), is refused, not read forever.
pub const MAX_TEXT_BYTES: u64 = 1 << 20;

/// The range of a hammer's mass (kg).
pub const MIN_HAMMER_MASS_KG: f64 = 1e-4;
pub const MAX_HAMMER_MASS_KG: f64 = 0.1;

/// The felt's exponent `p` a file may set (Eq. 8; measured hammers: 2.1–5).
pub const MIN_EXPONENT: f64 = 1.0;
pub const MAX_EXPONENT: f64 = 6.0;

/// The largest felt hysteresis a file may set (s): ten times the hundreds of microseconds fitted
/// to real hammers (docs/realism-sources.md §4).
pub const MAX_HYSTERESIS_S: f64 = 0.005;

/// The text of the file at `path`, refused past [`MAX_TEXT_BYTES`].
pub fn read_text(path: &Path) -> Result<String, PresetError> {
    use std::io::Read;
    let io = |error| PresetError::Io {
        path: path.to_owned(),
        error,
    };
    let mut text = String::new();
    std::fs::File::open(path)
        .map_err(io)?
        .take(MAX_TEXT_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(io)?;
    if text.len() as u64 > MAX_TEXT_BYTES {
        return Err(PresetError::Parse {
            path: path.to_owned(),
            message: format!("longer than {MAX_TEXT_BYTES} bytes: not a description of a piano"),
        });
    }
    Ok(text)
}

/// Read a soundboard description (the generator's input).
pub fn load_board_spec(path: &Path) -> Result<BoardSpec, PresetError> {
    parse_board_spec(&read_text(path)?, path)
}

/// Parse a soundboard description; `path` names it in errors.
pub fn parse_board_spec(text: &str, path: &Path) -> Result<BoardSpec, PresetError> {
    toml::from_str(text).map_err(|e| PresetError::Parse {
        path: path.to_owned(),
        message: e.to_string().trim_end().to_owned(),
    })
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Preset {
    pub name: String,
    pub strings: StringsSection,
    pub hammer: HammerSection,
    /// The hammer's felt across its width, which the soft pedal moves the strings over; the
    /// default profile when absent.
    #[serde(default)]
    pub hammer_felt: HammerFeltSection,
    pub damper: DamperSection,
    pub contact: ContactSection,
    pub soundboard: SoundboardSection,
    pub simulation: SimulationSection,
    pub radiation: RadiationSection,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StringsSection {
    pub count: usize,
    pub speaking_length_m: f64,
    pub duplex_length_m: f64,
    pub tension_n: f64,
    pub linear_density_kg_m: f64,
    pub core_diameter_m: f64,
    pub young_modulus_pa: f64,
    pub poisson_ratio: f64,
    pub density_kg_m3: f64,
    pub wound: bool,
    pub mistuning_cents: Vec<f64>,
    pub modes_t: usize,
    pub modes_p: usize,
    pub modes_l: usize,
    pub damping_ratio_t: f64,
    pub damping_ratio_p: f64,
    pub damping_ratio_l: f64,
    /// Chaigne & Askenfelt's string losses on T and P (`ModeSet`): `b1` (1/s) and `b3` (s);
    /// absent means none, as in the paper.
    #[serde(default)]
    pub loss_b1_per_s: f64,
    #[serde(default)]
    pub loss_b3_s: f64,
    pub duplex_damping_n_s_m2: f64,
}

impl StringsSection {
    /// The string at nominal tension (before the unison's mistuning).
    pub fn nominal_string(&self) -> StringParams {
        StringParams {
            speaking_length_m: self.speaking_length_m,
            duplex_length_m: self.duplex_length_m,
            tension_n: self.tension_n,
            linear_density_kg_m: self.linear_density_kg_m,
            core_diameter_m: self.core_diameter_m,
            young_modulus_pa: self.young_modulus_pa,
            density_kg_m3: self.density_kg_m3,
            wound: self.wound,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HammerSection {
    pub mass_kg: f64,
    pub stiffness_n_m_p: f64,
    pub exponent: f64,
    pub strike_ratio: f64,
    pub velocity_m_s: f64,
    pub release_gap_m: f64,
    /// The felt's hysteresis `alpha` (s); 0 (the default) is the paper's elastic felt.
    #[serde(default)]
    pub hysteresis_s: f64,
}

/// The felt across the hammer's width ([`FeltProfile`]'s fields, each defaulting to
/// [`DEFAULT_PROFILE`]'s).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HammerFeltSection {
    pub string_spacing_m: f64,
    pub overhang_m: f64,
    pub shoulder_m: f64,
    pub shoulder_depth_m: f64,
    pub groove_width_m: f64,
    pub groove_depth_m: f64,
    pub unworn_stiffness_ratio: f64,
    pub unworn_exponent_change: f64,
}

impl Default for HammerFeltSection {
    fn default() -> HammerFeltSection {
        HammerFeltSection::of(&DEFAULT_PROFILE)
    }
}

impl HammerFeltSection {
    fn of(p: &FeltProfile) -> HammerFeltSection {
        HammerFeltSection {
            string_spacing_m: p.string_spacing_m,
            overhang_m: p.overhang_m,
            shoulder_m: p.shoulder_m,
            shoulder_depth_m: p.shoulder_depth_m,
            groove_width_m: p.groove_width_m,
            groove_depth_m: p.groove_depth_m,
            unworn_stiffness_ratio: p.unworn_stiffness_ratio,
            unworn_exponent_change: p.unworn_exponent_change,
        }
    }

    pub fn profile(&self) -> FeltProfile {
        FeltProfile {
            string_spacing_m: self.string_spacing_m,
            overhang_m: self.overhang_m,
            shoulder_m: self.shoulder_m,
            shoulder_depth_m: self.shoulder_depth_m,
            groove_width_m: self.groove_width_m,
            groove_depth_m: self.groove_depth_m,
            unworn_stiffness_ratio: self.unworn_stiffness_ratio,
            unworn_exponent_change: self.unworn_exponent_change,
        }
    }

    /// The profile holds every unison ([`FeltProfile::check`]), or the field (`hammer_felt.…`, in
    /// a preset or a keyboard) that does not, with its value and what is allowed.
    pub(crate) fn check(&self) -> Result<(), (&'static str, String, String)> {
        self.profile().check().map_err(|e| {
            let field = match e.field {
                "string_spacing_m" => "hammer_felt.string_spacing_m",
                "overhang_m" => "hammer_felt.overhang_m",
                "shoulder_m" => "hammer_felt.shoulder_m",
                "shoulder_depth_m" => "hammer_felt.shoulder_depth_m",
                "groove_width_m" => "hammer_felt.groove_width_m",
                "groove_depth_m" => "hammer_felt.groove_depth_m",
                "unworn_stiffness_ratio" => "hammer_felt.unworn_stiffness_ratio",
                _ => "hammer_felt.unworn_exponent_change",
            };
            (field, e.value.to_string(), e.allowed)
        })
    }
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DamperSection {
    /// Whether the key has a damper (the top keys of a piano have none).
    pub present: bool,
    pub position_ratio: f64,
    pub damping_n_s_m: f64,
    /// Width of the felt along the string (m); 0 (the default) is a point.
    #[serde(default)]
    pub width_m: f64,
    /// How the exact engine carries the felt: `coupled` (the default) or `modal`
    /// ([`FeltModel`]).
    #[serde(default, with = "FeltModelName")]
    pub model: FeltModel,
    /// How far the felt rises clear of the strings at the full lift (m), and how far it sits
    /// pressed into them at rest (m): a part-lifted damper's share of the felt
    /// ([`DamperParams::contact_share`]).
    #[serde(default = "default_full_lift_m")]
    pub full_lift_m: f64,
    #[serde(default = "default_rest_compression_m")]
    pub rest_compression_m: f64,
}

fn default_full_lift_m() -> f64 {
    damper::FULL_LIFT_M
}

fn default_rest_compression_m() -> f64 {
    damper::REST_COMPRESSION_M
}

/// The ranges of a damper's travel: its compression at rest (m), and its full lift (m), which
/// must clear the compression (a felt still pressing at the full lift would jump off the strings
/// there).
pub const REST_COMPRESSION_M: std::ops::RangeInclusive<f64> = 1e-5..=5e-3;
pub const MAX_FULL_LIFT_M: f64 = 0.02;

/// A damper's travel within its ranges, or the one of `fields` (the compression's, the full
/// lift's) that is not, with its value and what is allowed.
pub(crate) fn check_damper_travel(
    full_lift_m: f64,
    rest_compression_m: f64,
    fields: [&'static str; 2],
) -> Result<(), (&'static str, String, String)> {
    let (lo, hi) = (*REST_COMPRESSION_M.start(), *REST_COMPRESSION_M.end());
    if !(lo..=hi).contains(&rest_compression_m) {
        return Err((
            fields[0],
            rest_compression_m.to_string(),
            format!("a number in [{lo:e}, {hi:e}]"),
        ));
    }
    if !(full_lift_m > rest_compression_m && full_lift_m <= MAX_FULL_LIFT_M) {
        return Err((
            fields[1],
            full_lift_m.to_string(),
            format!(
                "more than {} ({rest_compression_m}) up to {MAX_FULL_LIFT_M}",
                fields[0]
            ),
        ));
    }
    Ok(())
}

/// [`FeltModel`] as a preset or keyboard names it.
#[derive(Deserialize)]
#[serde(remote = "FeltModel", rename_all = "lowercase")]
pub(crate) enum FeltModelName {
    Coupled,
    Modal,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactSection {
    pub length_m: f64,
    pub bridge_young_modulus_pa: f64,
    pub bridge_poisson_ratio: f64,
    pub stiffness_ratio_l: f64,
    pub stiffness_ratio_p: f64,
    pub damping_n_s_m: [f64; 3],
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SoundboardSection {
    pub asset: String,
    pub bridge_point: String,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationSection {
    pub output_rate_hz: u32,
    pub min_rate_over_fmax: f64,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RadiationSection {
    /// The listener of the soundboard asset the board radiates to (each mode by its Rayleigh
    /// integral there, DESIGN.md §1.7); absent: the monopole of the net volume velocity heard
    /// at `distance_m` (the paper's board).
    #[serde(default)]
    pub listener: Option<String>,
    /// The listeners of the left and right channels (a stereo pair over the board, e.g. `bass`
    /// and `treble`: the pianist's view); absent: both channels hear `listener`.
    #[serde(default)]
    pub stereo: Option<[String; 2]>,
    pub distance_m: f64,
    pub air_density_kg_m3: f64,
    pub full_scale_pa: f64,
}

impl RadiationSection {
    /// The output stage at `rate_hz` for this radiation: a listener's source is a monopole at
    /// [`crate::engine::physics::soundboard::LISTENER_REFERENCE_M`], the net volume velocity one
    /// at `distance_m`; two channels for a stereo pair.
    pub fn output_settings(&self, rate_hz: f64) -> crate::config::output::OutputSettings {
        crate::config::output::OutputSettings {
            rate_hz,
            air_density_kg_m3: self.air_density_kg_m3,
            distance_m: match (&self.listener, &self.stereo) {
                (None, None) => self.distance_m,
                _ => crate::engine::physics::soundboard::LISTENER_REFERENCE_M,
            },
            full_scale_pa: self.full_scale_pa,
            channels: if self.stereo.is_some() { 2 } else { 1 },
            silence_j: crate::engine::SILENCE_J,
        }
    }
}

/// What can be wrong with a preset.
#[derive(Debug, thiserror::Error)]
pub enum PresetError {
    #[error("unknown preset `{0}`: built-in presets are {1}; or give a path to a .toml file")]
    Unknown(String, String),
    #[error("{path}: cannot read: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("{path}: field `{field}` = {value}: expected {allowed}")]
    Range {
        path: PathBuf,
        field: &'static str,
        value: String,
        allowed: String,
    },
    #[error(transparent)]
    Asset(#[from] AssetError),
    #[error("{path}: field `soundboard.bridge_point` = `{point}`: the asset {asset} has points {available}")]
    BridgePoint {
        path: PathBuf,
        point: String,
        asset: String,
        available: String,
    },
}

/// A preset with its resolved soundboard, ready to build unisons.
#[derive(Debug, Clone)]
pub struct LoadedPreset {
    pub preset: Preset,
    pub source: PathBuf,
    pub board: SoundboardModes,
    pub bridge_point: usize,
}

impl Preset {
    /// A built-in preset by name, or a TOML file by path.
    pub fn resolve(name_or_path: &str) -> Result<LoadedPreset, PresetError> {
        if let Some((_, text)) = BUILTIN_PRESETS.iter().find(|(n, _)| *n == name_or_path) {
            return Self::from_str(text, Path::new(&format!("presets/{name_or_path}.toml")));
        }
        let path = Path::new(name_or_path);
        if path.extension().is_some_and(|e| e == "toml") || path.exists() {
            return Self::from_str(&read_text(path)?, path);
        }
        let names: Vec<&str> = BUILTIN_PRESETS.iter().map(|(n, _)| *n).collect();
        Err(PresetError::Unknown(
            name_or_path.to_owned(),
            names.join(", "),
        ))
    }

    /// Parse and validate preset text read from `path`, without resolving its soundboard.
    pub fn parse(text: &str, path: &Path) -> Result<Preset, PresetError> {
        let preset: Preset = toml::from_str(text).map_err(|e| PresetError::Parse {
            path: path.to_owned(),
            message: e.to_string().trim_end().to_owned(),
        })?;
        preset.validate(path)?;
        Ok(preset)
    }

    /// Parse, validate and resolve the soundboard of preset text read from `path`.
    pub fn from_str(text: &str, path: &Path) -> Result<LoadedPreset, PresetError> {
        let preset = Self::parse(text, path)?;
        let asset = preset.soundboard.asset.clone();
        let dir = path.parent().unwrap_or(Path::new("."));
        LoadedPreset::stand_on(preset, path.to_owned(), &asset, dir)
    }

    pub(crate) fn validate(&self, path: &Path) -> Result<(), PresetError> {
        let range =
            |field: &'static str, value: f64, lo: f64, hi: f64| -> Result<(), PresetError> {
                if value.is_finite() && value >= lo && value <= hi {
                    Ok(())
                } else {
                    Err(PresetError::Range {
                        path: path.to_owned(),
                        field,
                        value: value.to_string(),
                        allowed: format!("a number in [{lo:e}, {hi:e}]"),
                    })
                }
            };
        let s = &self.strings;
        range("strings.count", s.count as f64, 1.0, 3.0)?;
        range("strings.speaking_length_m", s.speaking_length_m, 0.01, 3.0)?;
        range("strings.duplex_length_m", s.duplex_length_m, 1e-3, 1.0)?;
        range("strings.tension_n", s.tension_n, 10.0, 5000.0)?;
        range(
            "strings.linear_density_kg_m",
            s.linear_density_kg_m,
            1e-4,
            0.5,
        )?;
        range("strings.core_diameter_m", s.core_diameter_m, 1e-4, 5e-3)?;
        range("strings.young_modulus_pa", s.young_modulus_pa, 1e9, 1e12)?;
        range("strings.poisson_ratio", s.poisson_ratio, 0.0, 0.5)?;
        range("strings.density_kg_m3", s.density_kg_m3, 1000.0, 25000.0)?;
        if s.mistuning_cents.len() != s.count {
            return Err(PresetError::Range {
                path: path.to_owned(),
                field: "strings.mistuning_cents",
                value: format!("{:?}", s.mistuning_cents),
                allowed: format!("one value per string ({} values)", s.count),
            });
        }
        for &c in &s.mistuning_cents {
            range("strings.mistuning_cents", c, -100.0, 100.0)?;
        }
        range("strings.modes_t", s.modes_t as f64, 1.0, 400.0)?;
        range("strings.modes_p", s.modes_p as f64, 0.0, 400.0)?;
        range("strings.modes_l", s.modes_l as f64, 0.0, 50.0)?;
        range("strings.damping_ratio_t", s.damping_ratio_t, 0.0, 0.5)?;
        range("strings.damping_ratio_p", s.damping_ratio_p, 0.0, 0.5)?;
        range("strings.damping_ratio_l", s.damping_ratio_l, 0.0, 0.5)?;
        range("strings.loss_b1_per_s", s.loss_b1_per_s, 0.0, 100.0)?;
        range("strings.loss_b3_s", s.loss_b3_s, 0.0, 1e-6)?;
        range(
            "strings.duplex_damping_n_s_m2",
            s.duplex_damping_n_s_m2,
            0.0,
            1e4,
        )?;
        let h = &self.hammer;
        range(
            "hammer.mass_kg",
            h.mass_kg,
            MIN_HAMMER_MASS_KG,
            MAX_HAMMER_MASS_KG,
        )?;
        range("hammer.exponent", h.exponent, MIN_EXPONENT, MAX_EXPONENT)?;
        // K's unit depends on p: what is bounded is the force at 1 mm of compression.
        let force_at_mm_n = h.stiffness_n_m_p * 1e-3f64.powf(h.exponent);
        if !(force_at_mm_n.is_finite() && (1e-3..=1e5).contains(&force_at_mm_n)) {
            return Err(PresetError::Range {
                path: path.to_owned(),
                field: "hammer.stiffness_n_m_p",
                value: format!("{:e}", h.stiffness_n_m_p),
                allowed: format!(
                    "a felt pushing 1e-3 to 1e5 N at 1 mm of compression (this one: {force_at_mm_n:.3e} N)"
                ),
            });
        }
        range("hammer.strike_ratio", h.strike_ratio, 0.01, 0.5)?;
        range("hammer.velocity_m_s", h.velocity_m_s, 0.01, 10.0)?;
        range("hammer.release_gap_m", h.release_gap_m, 0.0, 0.05)?;
        range("hammer.hysteresis_s", h.hysteresis_s, 0.0, MAX_HYSTERESIS_S)?;
        // A check that names the field, its value and what is allowed, refused as that field.
        let refused = |(field, value, allowed)| PresetError::Range {
            path: path.to_owned(),
            field,
            value,
            allowed,
        };
        self.hammer_felt.check().map_err(refused)?;
        range(
            "damper.position_ratio",
            self.damper.position_ratio,
            0.0,
            1.0,
        )?;
        range("damper.damping_n_s_m", self.damper.damping_n_s_m, 0.0, 1e3)?;
        check_damper_travel(
            self.damper.full_lift_m,
            self.damper.rest_compression_m,
            ["damper.rest_compression_m", "damper.full_lift_m"],
        )
        .map_err(refused)?;
        // The felt lies on the speaking length.
        let d = &self.damper;
        let (x_m, half_m) = (d.position_ratio * s.speaking_length_m, d.width_m / 2.0);
        range("damper.width_m", d.width_m, 0.0, 0.1)?;
        if d.present && !(x_m - half_m > 0.0 && x_m + half_m < s.speaking_length_m) {
            return Err(PresetError::Range {
                path: path.to_owned(),
                field: "damper.width_m",
                value: d.width_m.to_string(),
                allowed: format!(
                    "a felt within the speaking length: less than {:.4} m at position_ratio {}",
                    2.0 * x_m.min(s.speaking_length_m - x_m),
                    d.position_ratio
                ),
            });
        }
        let c = &self.contact;
        range("contact.length_m", c.length_m, 1e-4, 0.1)?;
        range(
            "contact.bridge_young_modulus_pa",
            c.bridge_young_modulus_pa,
            1e6,
            1e11,
        )?;
        range(
            "contact.bridge_poisson_ratio",
            c.bridge_poisson_ratio,
            0.0,
            0.5,
        )?;
        range("contact.stiffness_ratio_l", c.stiffness_ratio_l, 0.0, 100.0)?;
        range("contact.stiffness_ratio_p", c.stiffness_ratio_p, 0.0, 100.0)?;
        for &d in &c.damping_n_s_m {
            range("contact.damping_n_s_m", d, 0.0, 1e4)?;
        }
        range(
            "simulation.output_rate_hz",
            self.simulation.output_rate_hz as f64,
            8000.0,
            384000.0,
        )?;
        range(
            "simulation.min_rate_over_fmax",
            self.simulation.min_rate_over_fmax,
            2.0,
            100.0,
        )?;
        let r = &self.radiation;
        range("radiation.distance_m", r.distance_m, 0.01, 100.0)?;
        range(
            "radiation.air_density_kg_m3",
            r.air_density_kg_m3,
            0.1,
            10.0,
        )?;
        range(
            "radiation.full_scale_pa",
            r.full_scale_pa,
            MIN_FULL_SCALE_PA,
            MAX_FULL_SCALE_PA,
        )?;
        Ok(())
    }
}

/// The soundboard asset `name`: a built-in one, or a file relative to `dir`; with the name errors
/// give it.
fn load_asset(name: &str, dir: &Path) -> Result<(String, SoundboardModes), PresetError> {
    match BUILTIN_ASSETS.iter().find(|(n, _)| *n == name) {
        Some((name, text)) => {
            let p = PathBuf::from(format!("assets/soundboard_modes/{name}.txt"));
            Ok((p.display().to_string(), asset::parse(text, &p)?))
        }
        None => {
            let p = dir.join(name);
            Ok((p.display().to_string(), asset::load_file(&p)?))
        }
    }
}

/// Index of the bridge point `name` in `board`, or an error naming the file, the asset and the
/// points it has.
pub(crate) fn bridge_point_index(
    board: &SoundboardModes,
    name: &str,
    path: &Path,
    asset: &str,
) -> Result<usize, PresetError> {
    board
        .points
        .iter()
        .position(|p| p.name == name)
        .ok_or_else(|| PresetError::BridgePoint {
            path: path.to_owned(),
            point: name.to_owned(),
            asset: asset.to_owned(),
            available: board
                .points
                .iter()
                .map(|p| p.name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
        })
}

/// What each channel of `board` hears under `radiation` ([`SoundboardModes::heard`]): the stereo
/// pair's listeners where it has one, else `listener` in both (`None`: the monopole); an error
/// names the file, the field and the listeners the asset has.
pub(crate) fn heard(
    board: &SoundboardModes,
    radiation: &RadiationSection,
    path: &Path,
    asset: &str,
) -> Result<[Option<usize>; 2], PresetError> {
    let index = |name: Option<&str>, field| listener_index(board, name, field, path, asset);
    let mono = index(radiation.listener.as_deref(), "radiation.listener")?;
    match &radiation.stereo {
        None => Ok([mono; 2]),
        Some([left, right]) => Ok([
            index(Some(left), "radiation.stereo (left)")?,
            index(Some(right), "radiation.stereo (right)")?,
        ]),
    }
}

/// The index of the listener `name` in `board` (`None` for none), or an error naming the file,
/// the field and the listeners the asset has.
fn listener_index(
    board: &SoundboardModes,
    name: Option<&str>,
    field: &'static str,
    path: &Path,
    asset: &str,
) -> Result<Option<usize>, PresetError> {
    let Some(name) = name else {
        return Ok(None);
    };
    match board.listener(name) {
        Some(l) => Ok(Some(l)),
        None => {
            let names: Vec<&str> = board.listeners.iter().map(|l| l.name.as_str()).collect();
            Err(PresetError::Range {
                path: path.to_owned(),
                field,
                value: format!("`{name}`"),
                allowed: match names.is_empty() {
                    true => format!("none: the asset {asset} has no listeners"),
                    false => format!("a listener of the asset {asset}: {}", names.join(", ")),
                },
            })
        }
    }
}

impl LoadedPreset {
    /// `preset`, read from `source`, on the soundboard asset `name` (built-in, or a file relative
    /// to `dir`): its bridge point and listeners found on that board.
    fn stand_on(
        mut preset: Preset,
        source: PathBuf,
        name: &str,
        dir: &Path,
    ) -> Result<LoadedPreset, PresetError> {
        let (asset_name, mut board) = load_asset(name, dir)?;
        let bridge_point = bridge_point_index(
            &board,
            &preset.soundboard.bridge_point,
            &source,
            &asset_name,
        )?;
        board.heard = heard(&board, &preset.radiation, &source, &asset_name)?;
        preset.soundboard.asset = name.to_owned();
        Ok(LoadedPreset {
            preset,
            source,
            board,
            bridge_point,
        })
    }

    /// This preset on the soundboard asset `name` (built-in, or a file relative to `dir`).
    pub(crate) fn on_board(self, name: &str, dir: &Path) -> Result<LoadedPreset, PresetError> {
        Self::stand_on(self.preset, self.source, name, dir)
    }

    /// The strings of the unison, string `i` retuned by `mistuning_cents[i]` through its tension.
    pub fn strings(&self) -> Vec<StringParams> {
        let s = &self.preset.strings;
        let nominal = s.nominal_string();
        s.mistuning_cents
            .iter()
            .map(|&c| nominal.detuned(c))
            .collect()
    }

    /// Contact springs from Hertz (Eq. 7) in T, scaled for L and P; dampers as given.
    pub fn contact(&self) -> Contact {
        let c = &self.preset.contact;
        let s = &self.preset.strings;
        let k_t = hertz_stiffness_n_m(
            c.length_m,
            s.young_modulus_pa,
            s.poisson_ratio,
            c.bridge_young_modulus_pa,
            c.bridge_poisson_ratio,
        );
        Contact {
            stiffness_n_m: [k_t, k_t * c.stiffness_ratio_l, k_t * c.stiffness_ratio_p],
            damping_n_s_m: c.damping_n_s_m,
        }
    }

    /// Everything the engine needs, at an internal rate that is the smallest integer multiple of
    /// the output rate at or above `min_rate_over_fmax × f_max` (the paper: 10 × f_max).
    pub fn unison_spec(&self) -> UnisonSpec {
        let s = &self.preset.strings;
        let h = &self.preset.hammer;
        let mut spec = UnisonSpec {
            strings: self.strings(),
            modes: ModeSet {
                modes_t: s.modes_t,
                modes_p: s.modes_p,
                modes_l: s.modes_l,
                damping_ratio_t: s.damping_ratio_t,
                damping_ratio_p: s.damping_ratio_p,
                damping_ratio_l: s.damping_ratio_l,
                loss_b1_per_s: s.loss_b1_per_s,
                loss_b3_s: s.loss_b3_s,
            },
            duplex_damping_n_s_m2: s.duplex_damping_n_s_m2,
            hammer: HammerParams {
                mass_kg: h.mass_kg,
                stiffness_n_m_p: h.stiffness_n_m_p,
                exponent: h.exponent,
                strike_ratio: h.strike_ratio,
                release_gap_m: h.release_gap_m,
                hysteresis_s: h.hysteresis_s,
                profile: self.preset.hammer_felt.profile(),
            },
            damper: self.preset.damper.present.then_some(DamperParams {
                position_ratio: self.preset.damper.position_ratio,
                damping_n_s_m: self.preset.damper.damping_n_s_m,
                width_m: self.preset.damper.width_m,
                model: self.preset.damper.model,
                full_lift_m: self.preset.damper.full_lift_m,
                rest_compression_m: self.preset.damper.rest_compression_m,
            }),
            contact: self.contact(),
            // The residual stays with the preset's board: the key takes its own point's share.
            board: SoundboardModes {
                residual: None,
                ..self.board.clone()
            },
            bridge_point: self.bridge_point,
            dropped: self.board.dropped_at(self.bridge_point),
            sample_rate_hz: 0.0,
        };
        spec.sample_rate_hz = self.oversampling(&spec) as f64 * self.output_rate_hz();
        spec
    }

    /// Output (audio and analysis) rate (Hz).
    pub fn output_rate_hz(&self) -> f64 {
        self.preset.simulation.output_rate_hz as f64
    }

    /// An output gain (dB, [`crate::config::output::GAIN_DB`]) before the soft clipper: the
    /// preset's full scale lowered by it.
    pub fn set_gain_db(&mut self, gain_db: f64) {
        let r = &mut self.preset.radiation;
        r.full_scale_pa = crate::config::output::full_scale_with_gain(r.full_scale_pa, gain_db);
    }

    /// Both channels heard at `radiation.listener`, the stereo pair set aside (a front end's
    /// `--mono`).
    pub fn make_mono(&mut self) {
        self.preset.radiation.stereo = None;
        let listener = self.preset.radiation.listener.as_deref();
        self.board.heard = [listener.and_then(|name| self.board.listener(name)); 2];
    }

    /// The output stage the preset describes: rate, radiation, full scale, and the default
    /// threshold below which a voice stops being simulated.
    pub fn output_settings(&self) -> crate::config::output::OutputSettings {
        self.preset.radiation.output_settings(self.output_rate_hz())
    }

    /// Internal steps per output sample for `spec`'s modes ([`LoadedPreset::oversampling_for`]).
    pub fn oversampling(&self, spec: &UnisonSpec) -> usize {
        self.oversampling_for(spec.max_mode_freq_hz())
    }

    /// Internal steps per output sample for modes up to `max_mode_freq_hz`: the rate RK4 needs,
    /// `min_rate_over_fmax` times it, rounded up to a whole multiple of the output rate.
    pub fn oversampling_for(&self, max_mode_freq_hz: f64) -> usize {
        let needed = self.preset.simulation.min_rate_over_fmax * max_mode_freq_hz;
        (needed / self.output_rate_hz()).ceil().max(1.0) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A damper felt must lie on the speaking length: one reaching past its end is refused with
    /// the field and the width that would fit.
    #[test]
    fn a_felt_off_the_speaking_length_is_refused() {
        let mut p = Preset::resolve("c2").unwrap().preset;
        p.damper.position_ratio = 0.01;
        p.damper.width_m = 0.05;
        let e = p.validate(Path::new("c2.toml")).unwrap_err().to_string();
        println!("{e}");
        assert!(e.contains("`damper.width_m` = 0.05") && e.contains("less than 0.0"));
        p.damper.width_m = 0.0;
        assert!(p.validate(Path::new("c2.toml")).is_ok());
    }

    /// A damper's travel: a compression out of its range, and a full lift that would leave the
    /// felt pressed on the strings, are refused with the field and the range.
    #[test]
    fn a_damper_travel_out_of_range_is_refused() {
        let mut p = Preset::resolve("c2").unwrap().preset;
        p.damper.rest_compression_m = 0.0;
        let e = p.validate(Path::new("c2.toml")).unwrap_err().to_string();
        println!("{e}");
        assert!(e.contains("`damper.rest_compression_m` = 0") && e.contains("[1e-5, 5e-3]"));
        p.damper.rest_compression_m = 1e-3;
        p.damper.full_lift_m = 1e-3;
        let e = p.validate(Path::new("c2.toml")).unwrap_err().to_string();
        println!("{e}");
        assert!(
            e.contains("`damper.full_lift_m` = 0.001")
                && e.contains("more than damper.rest_compression_m (0.001) up to 0.02")
        );
        p.damper.full_lift_m = 4e-3;
        assert!(p.validate(Path::new("c2.toml")).is_ok());
    }
}
