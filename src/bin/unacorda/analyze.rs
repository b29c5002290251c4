//! `unacorda analyze`: how the keyboard sounds against a grand piano, key by key, from each key's
//! linearised system (hammer out of play; [`unacorda::analysis::modes`]): its pitch as a tuner
//! hears it on partials 2–8 against its target, its first partial's pitch, and the decay of its
//! first partials' fastest and slowest modes (issue 17's table, the rows that need no render).

use anyhow::{bail, Context, Result};
use std::fmt::Write as _;
use std::path::PathBuf;
use unacorda::analysis::partials::{cents, KeyPartials, Partial};
use unacorda::board::key_name;
use unacorda::config::scaling::{equal_tempered_hz, parse_key, LoadedScaling, Scaling, KEYS};

/// Partials looked for on each key.
const PARTIALS: usize = 8;

/// Issue 17's tuning target: every key within this many cents of its target on partials 2–8.
const TUNED_CENTS: f64 = 3.0;

#[derive(clap::Args)]
pub struct AnalyzeArgs {
    /// Keyboard scaling: built-in name (grand) or path to a .toml file.
    #[arg(long, default_value = "grand")]
    keyboard: String,
    /// Keys to analyse: `all`, or names or numbers 1 (A0) – 88 (C8) separated by commas
    /// (`A0,C2,C4,88`).
    #[arg(long, default_value = "all")]
    keys: String,
    /// Also write one row per key as CSV.
    #[arg(long, value_name = "FILE.csv")]
    csv: Option<PathBuf>,
    /// Also draw each key's first-partial T60 beside published values (PNG).
    #[arg(long, value_name = "FILE.png")]
    figure: Option<PathBuf>,
}

/// Published first-partial T60s (s) of grand-piano strings, with their source (docs/realism-sources.md).
/// Chaigne & Askenfelt's C2, C4 and C7 losses as Saitis (2008, Table 4.1) gives them in Bensa et
/// al.'s form `sigma = b1 + b2 k^2`: T60 = ln(1000) / sigma of partial 1 (these lump the board's
/// losses into the string's).
const PUBLISHED_T60: [(usize, f64, &str); 3] = [
    (16, 27.6, "Chaigne & Askenfelt 1994 via Saitis 2008 T4.1"),
    (40, 6.24, "Chaigne & Askenfelt 1994 via Saitis 2008 T4.1"),
    (76, 0.59, "Chaigne & Askenfelt 1994 via Saitis 2008 T4.1"),
];

/// One key's figures.
struct KeyFigures {
    key: usize,
    heard: KeyPartials,
}

impl KeyFigures {
    fn partial(&self, n: usize) -> Option<&Partial> {
        self.heard.partial(n)
    }

    fn tuner_cents(&self) -> Option<f64> {
        self.heard
            .heard_hz()
            .map(|f| cents(f, self.heard.target_hz))
    }
}

fn parse_keys(text: &str) -> Result<Vec<usize>> {
    if text == "all" {
        return Ok((1..=KEYS).collect());
    }
    text.split(',')
        .map(|k| {
            parse_key(k.trim()).with_context(|| {
                format!(
                    "--keys: {k:?} is not a key: expected A0–C8 (e.g. C4, Bb0) or 1–88, or `all`"
                )
            })
        })
        .collect()
}

fn analyse_key(scaling: &LoadedScaling, key: usize) -> Result<KeyFigures> {
    let spec = scaling.key_preset(key)?.unison_spec();
    let heard = KeyPartials::new(&spec, equal_tempered_hz(key), PARTIALS)
        .with_context(|| format!("key {}", key_name(key)))?;
    Ok(KeyFigures { key, heard })
}

pub fn analyze(args: AnalyzeArgs) -> Result<()> {
    let keys = parse_keys(&args.keys)?;
    if keys.is_empty() {
        bail!("--keys: no key given");
    }
    let scaling = Scaling::resolve(&args.keyboard)?;
    let figures = unacorda::cores::map_on_cores(&keys, |&k| analyse_key(&scaling, k))?;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "keyboard {}: {} keys from their linearised systems (hammer out of play); cents against equal temperament (A4 = 440 Hz); T60 of each partial's fastest and slowest string mode",
        scaling.scaling.name,
        figures.len()
    );
    let _ = writeln!(
        out,
        "{:>4} {:<4} {:>9} {:>10} {:>9} {:>9} {:>17} {:>17}",
        "key",
        "name",
        "target Hz",
        "tuner ¢",
        "fit B",
        "partial1 ¢",
        "partial 1 T60 (s)",
        "partial 2 T60 (s)"
    );
    let mut csv =
        String::from("key,name,target_hz,tuner_cents,partials_fitted,fitted_b,partial1_cents");
    for n in 1..=PARTIALS {
        let _ = write!(csv, ",p{n}_hz,p{n}_t60_min_s,p{n}_t60_max_s,p{n}_modes");
    }
    csv.push('\n');
    let t60 = |p: Option<&Partial>| {
        p.map_or("-".to_string(), |p| {
            format!("{:.2}–{:.2}", p.t60_min_s, p.t60_max_s)
        })
    };
    for f in &figures {
        let first = f.partial(1).map(|p| cents(p.freq_hz, f.heard.target_hz));
        let show =
            |x: Option<f64>, digits: usize| x.map_or("-".into(), |x| format!("{x:+.digits$}"));
        let _ = writeln!(
            out,
            "{:>4} {:<4} {:>9.3} {:>10} {:>9} {:>9} {:>17} {:>17}",
            f.key,
            key_name(f.key),
            f.heard.target_hz,
            match f.heard.pitch {
                Some(p) => format!("{} ({})", show(f.tuner_cents(), 1), p.partials),
                None => format!("{} (1st)", show(f.tuner_cents(), 1)),
            },
            f.heard
                .pitch
                .map_or("-".into(), |p| format!("{:.2e}", p.inharmonicity)),
            show(first, 1),
            t60(f.partial(1)),
            t60(f.partial(2)),
        );
        let opt = |x: Option<f64>| x.map_or(String::new(), |x| x.to_string());
        let _ = write!(
            csv,
            "{},{},{},{},{},{},{}",
            f.key,
            key_name(f.key),
            f.heard.target_hz,
            opt(f.tuner_cents()),
            f.heard.pitch.map_or(0, |p| p.partials),
            opt(f.heard.pitch.map(|p| p.inharmonicity)),
            opt(first)
        );
        for n in 1..=PARTIALS {
            match f.partial(n) {
                Some(p) => {
                    let _ = write!(
                        csv,
                        ",{},{},{},{}",
                        p.freq_hz, p.t60_min_s, p.t60_max_s, p.modes
                    );
                }
                None => csv.push_str(",,,,0"),
            }
        }
        csv.push('\n');
    }
    // The rows of issue 17's table that the modes answer.
    let tuned = figures
        .iter()
        .filter(|f| f.tuner_cents().is_some_and(|c| c.abs() <= TUNED_CENTS))
        .count();
    let mut worst: Vec<(&KeyFigures, f64)> = figures
        .iter()
        .filter_map(|f| Some((f, f.tuner_cents()?)))
        .collect();
    worst.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
    let unheard: Vec<String> = figures
        .iter()
        .filter(|f| f.heard.pitch.is_none())
        .map(|f| key_name(f.key))
        .collect();
    let _ = writeln!(
        out,
        "pitch (partials 2–8; the first where none of them is among the modes: {}): {} of {} keys within ±{TUNED_CENTS} cents of equal temperament; furthest: {}",
        if unheard.is_empty() { "none".to_string() } else { unheard.join(", ") },
        tuned,
        figures.len(),
        worst
            .iter()
            .take(6)
            .map(|(f, c)| format!("{} {c:+.0}", key_name(f.key)))
            .collect::<Vec<_>>()
            .join(", "),
    );
    let _ = writeln!(
        out,
        "partial 1 T60, fastest – slowest mode (s): {}",
        figures
            .iter()
            .filter(|f| [1, 16, 28, 40, 52, 64, 76, 88].contains(&f.key))
            .map(|f| format!("{} {}", key_name(f.key), t60(f.partial(1))))
            .collect::<Vec<_>>()
            .join(", ")
    );
    match std::io::Write::write_all(&mut std::io::stdout().lock(), out.as_bytes()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => return Err(e.into()),
        _ => {}
    }
    if let Some(path) = &args.figure {
        let bars: Vec<(usize, f64, f64)> = figures
            .iter()
            .filter_map(|f| f.partial(1).map(|p| (f.key, p.t60_min_s, p.t60_max_s)))
            .collect();
        unacorda::analysis::figures::partial_decay(
            path,
            &scaling.scaling.name,
            &bars,
            &PUBLISHED_T60,
        )?;
        eprintln!("wrote {}", path.display());
    }
    if let Some(path) = &args.csv {
        std::fs::write(path, csv).with_context(|| format!("writing {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
