//! `unacorda modes`: the linearised system's modes of one key (strings on their contact springs,
//! duplex damping, the board at the key's point; hammer out of play), as a table an acoustician
//! can read: frequency, decay rate, T60 and where the mode's energy is.

use anyhow::{bail, Context, Result};
use std::fmt::Write as _;
use std::path::PathBuf;
use unacorda::analysis::modes::{linear_modes, LinearMode};
use unacorda::config::preset::Preset;
use unacorda::config::scaling::{parse_key, Scaling};
use unacorda::engine::Direction;

#[derive(clap::Args)]
pub struct ModesArgs {
    /// Built-in preset name (c2) or path to a preset .toml file.
    #[arg(long, default_value = "c2")]
    preset: String,
    /// A key of the keyboard scaling instead of the preset: a name (C4, Bb0) or 1 (A0) – 88 (C8).
    #[arg(long)]
    key: Option<String>,
    /// Keyboard for --key: built-in name (concert, the default; paper, the paper's model) or path to a .toml file.
    #[arg(long, default_value = "concert")]
    keyboard: String,
    /// List modes up to this frequency (Hz), 1–100000.
    #[arg(
        long,
        default_value_t = 2000.0,
        value_name = "HZ",
        allow_negative_numbers = true
    )]
    max_hz: f64,
    /// Also write every listed mode as CSV.
    #[arg(long, value_name = "FILE.csv")]
    csv: Option<PathBuf>,
}

/// Where a mode's energy mostly is: the board, or a string and direction, with its share.
fn dominant(m: &LinearMode) -> (String, f64) {
    let (d, share) = (0..3)
        .map(|d| (d, m.shares[d]))
        .fold((0, f64::MIN), |a, b| if b.1 > a.1 { b } else { a });
    if m.shares[3] >= share {
        return ("board".into(), m.shares[3]);
    }
    let s = (0..m.string_shares.len()).fold(0, |a, s| {
        if m.string_shares[s] > m.string_shares[a] {
            s
        } else {
            a
        }
    });
    (
        format!("string {} {}", s + 1, Direction::ALL[d].name()),
        share,
    )
}

pub fn modes(args: ModesArgs) -> Result<()> {
    if !(1.0..=100_000.0).contains(&args.max_hz) {
        bail!(
            "--max-hz {}: expected a frequency in [1, 100000] Hz",
            args.max_hz
        );
    }
    let loaded = match &args.key {
        Some(name) => {
            let k = parse_key(name)
                .with_context(|| format!("--key {name}: expected A0–C8 (e.g. C4, Bb0) or 1–88"))?;
            Scaling::resolve(&args.keyboard)?.key_preset(k)?
        }
        None => Preset::resolve(&args.preset)?,
    };
    let spec = loaded.unison_spec();
    let modes = linear_modes(&spec)?;
    let listed: Vec<&LinearMode> = modes.iter().filter(|m| m.freq_hz <= args.max_hz).collect();
    let mut table = String::new();
    let _ = writeln!(
        table,
        "{}: {} strings, {} modes of the linearised system (hammer out of play), {} up to {} Hz",
        loaded.preset.name,
        spec.strings.len(),
        modes.len(),
        listed.len(),
        args.max_hz
    );
    let _ = writeln!(
        table,
        "{:>10} {:>10} {:>9} {:>7}  {:<16} {:>6} {:>6} {:>6} {:>6}",
        "f (Hz)", "σ (1/s)", "T60 (s)", "ζ", "mostly", "T", "L", "P", "board"
    );
    let mut csv = String::from(
        "freq_hz,decay_per_s,t60_s,damping_ratio,mostly,share_t,share_l,share_p,share_board\n",
    );
    for m in &listed {
        let zeta = m.decay_per_s / m.decay_per_s.hypot(2.0 * std::f64::consts::PI * m.freq_hz);
        let (mostly, share) = dominant(m);
        let pct = |x: f64| format!("{:.0}%", 100.0 * x);
        let _ = writeln!(
            table,
            "{:>10.3} {:>10.3} {:>9.3} {:>7.1e}  {:<16} {:>6} {:>6} {:>6} {:>6}",
            m.freq_hz,
            m.decay_per_s,
            m.t60_s(),
            zeta,
            format!("{mostly} {}", pct(share)),
            pct(m.shares[0]),
            pct(m.shares[1]),
            pct(m.shares[2]),
            pct(m.shares[3])
        );
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{},{},{}",
            m.freq_hz,
            m.decay_per_s,
            m.t60_s(),
            zeta,
            mostly,
            m.shares[0],
            m.shares[1],
            m.shares[2],
            m.shares[3]
        );
    }
    // A closed pipe (`| head`) ends the listing quietly.
    match std::io::Write::write_all(&mut std::io::stdout().lock(), table.as_bytes()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => return Err(e.into()),
        _ => {}
    }
    if let Some(path) = &args.csv {
        std::fs::write(path, csv).with_context(|| format!("writing {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
