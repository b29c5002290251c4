//! The soundboard asset format (`assets/soundboard_modes/*.txt`, version 1): a reduced modal
//! board ([`SoundboardModes`]) as text, written by `unacorda soundboard` and read by the presets.
//!
//! Plain text, one record a line. Lines starting with `#` and blank lines are ignored.
//! ```text
//! format: unacorda-soundboard-modes 1
//! points: C2 C4                      # names of the bridge points, separated by spaces
//! listeners: above                   # optional: names of the listeners
//! columns: freq_hz zeta volume_m2_per_sqrt_kg T@C2 L@C2 P@C2 T@C4 L@C4 P@C4 Dre@above Dim@above
//! 21.52 0.03 1.23e-2 4.5e-2 -1.2e-3 3.4e-4 ...   # one row per mode
//! ```
//! A line `residual:` may follow the mode rows: the rows after it are the modes the reduction
//! dropped ([`SoundboardModes::residual`]), in the same columns, heard and not coupled.
//!
//! Units: `freq_hz` Hz (> 0), `zeta` damping ratio in [0, 1), `volume_m2_per_sqrt_kg` the mode's
//! net volume displacement per unit modal coordinate (m^2/sqrt(kg)), `T@X`, `L@X`, `P@X` the
//! mass-normalised mode shape at point X in each direction (1/sqrt(kg)), `Dre@Y`, `Dim@Y` the
//! mode's Rayleigh integral at listener Y ([`crate::board::radiation`], m/sqrt(kg)).

use crate::engine::physics::soundboard::{BridgePoint, Listener, SoundboardModes};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Header value of the `format:` line.
pub const FORMAT_TAG: &str = "unacorda-soundboard-modes 1";

/// What can be wrong with an asset file.
#[derive(Debug, thiserror::Error)]
pub enum AssetError {
    #[error("{path}: cannot read soundboard asset: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}:{line}: {message}")]
    Syntax {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error("{path}: {message}")]
    Content { path: PathBuf, message: String },
}

/// Read an asset file (at build time, never from the audio path).
pub fn load_file(path: &Path) -> Result<SoundboardModes, AssetError> {
    let text = std::fs::read_to_string(path).map_err(|error| AssetError::Io {
        path: path.to_owned(),
        error,
    })?;
    parse(&text, path)
}

/// Parse asset text; `path` names the source in error messages.
pub fn parse(text: &str, path: &Path) -> Result<SoundboardModes, AssetError> {
    let syntax = |line: usize, message: String| AssetError::Syntax {
        path: path.to_owned(),
        line,
        message,
    };
    let mut format_seen = false;
    let mut points: Option<Vec<String>> = None;
    let mut listeners: Option<Vec<String>> = None;
    let mut columns: Option<Vec<String>> = None;
    // The kept modes' rows, once `residual:` is read (`rows` then gathers the dropped ones).
    let mut residual: Option<Vec<Vec<f64>>> = None;
    let mut rows: Vec<Vec<f64>> = Vec::new();
    for (idx, raw) in text.lines().enumerate() {
        let line_no = idx + 1;
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        // Each header once, all before the mode rows (the rows' width follows `points:`).
        for (tag, seen) in [
            ("format:", format_seen),
            ("points:", points.is_some()),
            ("listeners:", listeners.is_some()),
            ("columns:", columns.is_some()),
        ] {
            if line.starts_with(tag) && (seen || !rows.is_empty()) {
                let what = if seen {
                    "repeated"
                } else {
                    "after the mode rows"
                };
                return Err(syntax(line_no, format!("header `{tag}` {what}")));
            }
        }
        if let Some(v) = line.strip_prefix("format:") {
            if v.trim() != FORMAT_TAG {
                return Err(syntax(
                    line_no,
                    format!(
                        "field `format`: expected `{FORMAT_TAG}`, got `{}`",
                        v.trim()
                    ),
                ));
            }
            format_seen = true;
        } else if let Some(v) = line.strip_prefix("points:") {
            let names: Vec<String> = v.split_whitespace().map(str::to_owned).collect();
            if names.is_empty() {
                return Err(syntax(
                    line_no,
                    "field `points`: no bridge point named".into(),
                ));
            }
            points = Some(names);
        } else if let Some(v) = line.strip_prefix("listeners:") {
            if columns.is_some() {
                return Err(syntax(
                    line_no,
                    "`listeners:` must come before `columns:`".into(),
                ));
            }
            listeners = Some(v.split_whitespace().map(str::to_owned).collect());
        } else if line == "residual:" {
            if columns.is_none() || rows.is_empty() || residual.is_some() {
                return Err(syntax(
                    line_no,
                    "`residual:` must come once, after the kept modes' rows".into(),
                ));
            }
            residual = Some(std::mem::take(&mut rows));
        } else if let Some(v) = line.strip_prefix("columns:") {
            let Some(names) = &points else {
                return Err(syntax(line_no, "`columns:` must follow `points:`".into()));
            };
            let expected = expected_columns(names, listeners.as_deref().unwrap_or_default());
            let got: Vec<String> = v.split_whitespace().map(str::to_owned).collect();
            if got != expected {
                return Err(syntax(
                    line_no,
                    format!(
                        "field `columns`: expected `{}`, got `{}`",
                        expected.join(" "),
                        got.join(" ")
                    ),
                ));
            }
            columns = Some(got);
        } else {
            if !format_seen {
                return Err(syntax(
                    line_no,
                    format!("expected the header line `format: {FORMAT_TAG}` first"),
                ));
            }
            let Some(cols) = &columns else {
                return Err(syntax(
                    line_no,
                    "mode row before the `columns:` header".into(),
                ));
            };
            let fields: Vec<&str> = line.split_whitespace().collect();
            if fields.len() != cols.len() {
                return Err(syntax(
                    line_no,
                    format!("expected {} columns, found {}", cols.len(), fields.len()),
                ));
            }
            let mut row = Vec::with_capacity(cols.len());
            for (c, (name, s)) in cols.iter().zip(&fields).enumerate() {
                let value: f64 = s.parse().map_err(|_| {
                    syntax(
                        line_no,
                        format!("field `{name}` (column {}): `{s}` is not a number", c + 1),
                    )
                })?;
                let (ok, range) = match c {
                    0 => (
                        value.is_finite() && value > 0.0,
                        "a finite frequency > 0 Hz",
                    ),
                    1 => ((0.0..1.0).contains(&value), "a damping ratio in [0, 1)"),
                    _ => (value.is_finite(), "a finite number"),
                };
                if !ok {
                    return Err(syntax(
                        line_no,
                        format!(
                            "field `{name}` (column {}): expected {range}, got {s}",
                            c + 1
                        ),
                    ));
                }
                row.push(value);
            }
            rows.push(row);
        }
    }
    let content = |message: &str| AssetError::Content {
        path: path.to_owned(),
        message: message.to_owned(),
    };
    if !format_seen {
        return Err(content(
            "missing header line `format: unacorda-soundboard-modes 1`",
        ));
    }
    let names = points.ok_or_else(|| content("missing header line `points:`"))?;
    if columns.is_none() {
        return Err(content("missing header line `columns:`"));
    }
    if rows.is_empty() {
        return Err(content("no modes: at least one mode row is required"));
    }
    let listeners = listeners.unwrap_or_default();
    Ok(match residual {
        None => board(&rows, &names, &listeners),
        Some(kept) => SoundboardModes {
            residual: Some(std::sync::Arc::new(board(&rows, &names, &listeners))),
            ..board(&kept, &names, &listeners)
        },
    })
}

/// The board of mode rows `rows` (columns as `expected_columns` names them).
fn board(rows: &[Vec<f64>], names: &[String], listeners: &[String]) -> SoundboardModes {
    let col = |c: usize| rows.iter().map(|r| r[c]).collect::<Vec<f64>>();
    let at = 3 + 3 * names.len();
    SoundboardModes {
        freq_hz: col(0),
        damping_ratio: col(1),
        volume_m2_per_sqrt_kg: col(2),
        points: names
            .iter()
            .enumerate()
            .map(|(p, name)| BridgePoint {
                name: name.clone(),
                shape: [col(3 + 3 * p), col(4 + 3 * p), col(5 + 3 * p)],
            })
            .collect(),
        listeners: listeners
            .iter()
            .enumerate()
            .map(|(l, name)| Listener {
                name: name.clone(),
                rayleigh_re: col(at + 2 * l),
                rayleigh_im: col(at + 2 * l + 1),
            })
            .collect(),
        heard: [None; 2],
        residual: None,
    }
}

/// Write the asset text; `header` lines are written as comments first.
pub fn to_text(modes: &SoundboardModes, header: &[String]) -> String {
    let mut out = String::new();
    for h in header {
        let _ = writeln!(out, "# {h}");
    }
    let names: Vec<String> = modes.points.iter().map(|p| p.name.clone()).collect();
    let _ = writeln!(out, "format: {FORMAT_TAG}");
    let heard: Vec<String> = modes.listeners.iter().map(|l| l.name.clone()).collect();
    let _ = writeln!(out, "points: {}", names.join(" "));
    if !heard.is_empty() {
        let _ = writeln!(out, "listeners: {}", heard.join(" "));
    }
    let _ = writeln!(
        out,
        "columns: {}",
        expected_columns(&names, &heard).join(" ")
    );
    rows(&mut out, modes);
    if let Some(r) = &modes.residual {
        let _ = writeln!(out, "residual:");
        rows(&mut out, r);
    }
    out
}

/// One line per mode of `modes`.
fn rows(out: &mut String, modes: &SoundboardModes) {
    for k in 0..modes.len() {
        let _ = write!(
            out,
            "{:.6} {:.4} {:.9e}",
            modes.freq_hz[k], modes.damping_ratio[k], modes.volume_m2_per_sqrt_kg[k]
        );
        for p in &modes.points {
            for d in &p.shape {
                let _ = write!(out, " {:.9e}", d[k]);
            }
        }
        for l in &modes.listeners {
            let _ = write!(out, " {:.9e} {:.9e}", l.rayleigh_re[k], l.rayleigh_im[k]);
        }
        out.push('\n');
    }
}

fn expected_columns(points: &[String], listeners: &[String]) -> Vec<String> {
    let mut cols: Vec<String> = ["freq_hz", "zeta", "volume_m2_per_sqrt_kg"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    for p in points {
        for d in crate::engine::Direction::ALL {
            cols.push(format!("{}@{p}", d.name()));
        }
    }
    for l in listeners {
        cols.push(format!("Dre@{l}"));
        cols.push(format!("Dim@{l}"));
    }
    cols
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_round_trip() {
        let sb = SoundboardModes {
            freq_hz: vec![30.0, 45.5],
            damping_ratio: vec![0.03, 0.03],
            volume_m2_per_sqrt_kg: vec![1e-2, 0.0],
            points: vec![BridgePoint {
                name: "C2".into(),
                shape: [vec![0.5, -0.25], vec![0.01, 0.02], vec![-0.03, 0.04]],
            }],
            listeners: vec![Listener {
                name: "above".into(),
                rayleigh_re: vec![3e-3, -1e-4],
                rayleigh_im: vec![2e-5, 4e-4],
            }],
            heard: [None; 2],
            residual: None,
        };
        let text = to_text(&sb, &["test".into()]);
        let back = parse(&text, Path::new("mem")).unwrap();
        assert_eq!(back, sb);

        // With the dropped modes after `residual:`, the same columns.
        let with = SoundboardModes {
            residual: Some(std::sync::Arc::new(SoundboardModes {
                freq_hz: vec![1600.0],
                damping_ratio: vec![0.03],
                volume_m2_per_sqrt_kg: vec![-2e-4],
                points: vec![BridgePoint {
                    name: "C2".into(),
                    shape: [vec![0.1], vec![0.2], vec![-0.3]],
                }],
                listeners: vec![Listener {
                    name: "above".into(),
                    rayleigh_re: vec![1e-4],
                    rayleigh_im: vec![-2e-4],
                }],
                heard: [None; 2],
                residual: None,
            })),
            ..sb
        };
        let text = to_text(&with, &[]);
        assert!(text.contains("\nresidual:\n"));
        assert_eq!(parse(&text, Path::new("mem")).unwrap(), with);
        // `residual:` before the kept rows, or twice: refused, naming the line.
        let rows: Vec<&str> = text.lines().collect();
        let at = rows.iter().position(|l| *l == "residual:").unwrap();
        let mut early = rows.clone();
        let marker = early.remove(at);
        early.insert(at - 2, marker);
        let mut twice = rows.clone();
        twice.push("residual:");
        for (bad, line) in [(early, at - 1), (twice, rows.len() + 1)] {
            let e = parse(&bad.join("\n"), Path::new("mem.txt"))
                .unwrap_err()
                .to_string();
            println!("{e}");
            assert!(e.contains(&format!("mem.txt:{line}:")) && e.contains("`residual:`"));
        }
    }
}
