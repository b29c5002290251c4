//! The paper's Figures 2–6: the soundboard's mobility (full vs reduced model) and, una corda vs
//! normal playing, Figures 3–6; each as a PNG and the CSV of its data.
//!
//! Figures 4 and 5 span seconds of a signal that oscillates at 65 Hz and up; they are drawn (and
//! tabulated) as the minimum and maximum of the force in each 5 ms bin, which is what a plot of
//! every sample shows.

use super::listening::{power_db, power_spectrum};
use super::mobility::{mobility_curves, TERM_NAMES};
use super::spectral::spectrogram;
use crate::engine::physics::soundboard::SoundboardModes;
use crate::engine::Direction;
use crate::render::Recording;
use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// What can go wrong while writing figures.
#[derive(Debug, thiserror::Error)]
pub enum FigureError {
    #[error("{path}: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}: drawing failed: {message}")]
    Plot { path: PathBuf, message: String },
}

const FONT: &str = "sans-serif";
const BIN_S: f64 = 0.005;
const COLORS: [RGBColor; 3] = [
    RGBColor(31, 119, 180),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
];

/// A tick label as a reader writes the number: `100`, `0.5`, `1.25` (never `100.0` or
/// `0.30000000000000004`).
fn tick(v: &f64) -> String {
    let rounded = format!("{v:.6}");
    let trimmed = rounded.trim_end_matches('0').trim_end_matches('.');
    match trimmed {
        "-0" => "0".to_owned(),
        t => t.to_owned(),
    }
}

/// Register the bundled DejaVu Sans so that text needs no system fonts.
fn register_font() {
    static DONE: OnceLock<()> = OnceLock::new();
    DONE.get_or_init(|| {
        let bytes: &'static [u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
        plotters::style::register_font(FONT, FontStyle::Normal, bytes)
            .unwrap_or_else(|_| panic!("bundled font is a valid TTF"));
    });
}

/// Figure 2: the six distinct terms of the 3×3 driving-point mobility at `point`, full model
/// (every mode below f_max) vs the reduced one, 20–7000 Hz, log-log.
pub fn figure2(
    dir: &Path,
    full: &SoundboardModes,
    reduced: &SoundboardModes,
    point: &str,
) -> Result<Vec<PathBuf>, FigureError> {
    register_font();
    let png = dir.join("fig2_mobility.png");
    let missing = || FigureError::Plot {
        path: png.clone(),
        message: format!("bridge point {point} is not in the soundboard model"),
    };
    let cf = mobility_curves(
        full,
        full.point(point).ok_or_else(missing)?,
        20.0,
        7000.0,
        1200,
    );
    let cr = mobility_curves(
        reduced,
        reduced.point(point).ok_or_else(missing)?,
        20.0,
        7000.0,
        1200,
    );
    let mut csv = String::from("freq_hz");
    for t in TERM_NAMES {
        let _ = write!(csv, ",{t}_full_m_per_n_s,{t}_reduced_m_per_n_s");
    }
    csv.push('\n');
    for k in 0..cf.freq_hz.len() {
        let _ = write!(csv, "{:.3}", cf.freq_hz[k]);
        for t in 0..6 {
            let _ = write!(
                csv,
                ",{:.6e},{:.6e}",
                cf.magnitude[t][k], cr.magnitude[t][k]
            );
        }
        csv.push('\n');
    }
    let draw = || -> Result2<()> {
        let (root, body) = titled_canvas(
            &png,
            (1300, 800),
            &format!("Fig. 2 — driving-point mobility at {point}: full model ({} modes, blue) vs reduced ({} modes, red)", full.len(), reduced.len()),
            20,
        )?;
        let all = cf
            .magnitude
            .iter()
            .chain(&cr.magnitude)
            .flatten()
            .copied()
            .filter(|v| *v > 0.0);
        let (lo, hi) = all.fold((f64::INFINITY, 0f64), |(a, b), v| (a.min(v), b.max(v)));
        let y_range = (lo.max(hi * 1e-6) * 0.5)..(hi * 2.0);
        for (t, panel) in body.split_evenly((2, 3)).iter().enumerate() {
            let mut chart = ChartBuilder::on(panel)
                .caption(format!("|Y_{}|", TERM_NAMES[t]), (FONT, 16))
                .margin(8)
                .x_label_area_size(35)
                .y_label_area_size(65)
                .build_cartesian_2d((20.0..7000.0).log_scale(), y_range.clone().log_scale())?;
            chart
                .configure_mesh()
                .x_desc("frequency (Hz)")
                .y_desc("m/(N s)")
                .x_label_formatter(&tick)
                .y_label_formatter(&|v| format!("{v:.0e}"))
                .label_style((FONT, 12))
                .draw()?;
            for (curves, color) in [(&cf, COLORS[0]), (&cr, COLORS[2])] {
                let pts = curves
                    .freq_hz
                    .iter()
                    .zip(&curves.magnitude[t])
                    .filter(|(_, m)| **m > 0.0)
                    .map(|(f, m)| (*f, *m));
                chart.draw_series(LineSeries::new(pts, color.stroke_width(1)))?;
            }
        }
        root.present()?;
        Ok(())
    };
    draw().map_err(plot_err(&png))?;
    Ok(vec![png, write_text(dir.join("fig2_mobility.csv"), &csv)?])
}

/// Write Figures 3–6 into `dir`; returns the files written.
pub fn write_all(
    dir: &Path,
    una_corda: &Recording,
    normal: &Recording,
) -> Result<Vec<PathBuf>, FigureError> {
    register_font();
    let mut written = Vec::new();
    written.extend(figure3(dir, una_corda, normal)?);
    written.extend(figure4(dir, una_corda, normal)?);
    written.extend(figure5(dir, una_corda, normal)?);
    written.extend(figure6(dir, una_corda, normal)?);
    Ok(written)
}

/// The soft pedal's depths that [`soft_pedal`] draws: up, on the unworn felt between the
/// grooves, the last string rounding the hammer's shoulder, nearly off it, and the una corda.
pub const SOFT_PEDAL_DEPTHS: [f64; 5] = [0.0, 0.5, 0.8, 0.9, 1.0];

/// Figure 7, beyond the paper: one key struck with the soft pedal at each of `runs`' depths
/// (depth, recording): (a) the summed felt force on its strings, and (b) the upper envelope of
/// the transmitted T force's spectrum over the first half second (its partials' levels); `title` names the key and blow. Writes the
/// PNG and a CSV of both panels.
pub fn soft_pedal(
    dir: &Path,
    title: &str,
    runs: &[(f64, Recording)],
) -> Result<Vec<PathBuf>, FigureError> {
    register_font();
    let Some((_, first)) = runs.first() else {
        return Ok(vec![]);
    };
    let fs = first.rate_hz;
    let force: Vec<Vec<f64>> = runs
        .iter()
        .map(|(_, r)| r.channel(|f| f.obs.hammer_force_n.iter().sum()))
        .collect();
    // The spectrum's upper envelope: every 20 Hz, its loudest bin within a window wider than
    // the partials' spacing (a sixth of the frequency, at least 150 Hz), so that each depth's
    // partial levels read as one curve.
    let grid: Vec<f64> = (2..=150).map(|i| 20.0 * i as f64).collect();
    let spectra: Vec<Vec<f64>> = runs
        .iter()
        .map(|(_, r)| {
            let (df, p) = power_spectrum(&r.channel(|f| f.obs.total_force_n[0]), fs, 0.0, 0.5);
            grid.iter()
                .map(|&f| {
                    let half = (f / 6.0).max(150.0) / 2.0;
                    let from = (((f - half) / df).floor().max(0.0) as usize).min(p.len());
                    let to = (((f + half) / df).ceil() as usize).clamp(from, p.len());
                    power_db(p[from..to].iter().fold(0.0, |m: f64, &v| m.max(v)))
                })
                .collect()
        })
        .collect();
    let n = ((0.008 * fs) as usize).min(first.frames.len());
    let mut csv = String::from("panel,depth,x,value\n");
    for ((depth, r), f) in runs.iter().zip(&force) {
        for (k, v) in f[..n].iter().enumerate() {
            let _ = writeln!(csv, "force,{depth},{:.4},{v:.5}", r.time_s(k) * 1e3);
        }
    }
    for ((depth, _), db) in runs.iter().zip(&spectra) {
        for (f, v) in grid.iter().zip(db) {
            let _ = writeln!(csv, "envelope,{depth},{f},{v:.2}");
        }
    }
    let colour = |i: usize| colormap(i as f64 / (runs.len().max(2) - 1) as f64);
    let png = dir.join("fig7_soft_pedal.png");
    let draw = || -> Result2<()> {
        let (root, body) = titled_canvas(
            &png,
            (1300, 560),
            &format!("Fig. 7 — the soft pedal's depth ({title})"),
            20,
        )?;
        let panels = body.split_evenly((1, 2));
        let y_max = 1.1
            * force
                .iter()
                .flat_map(|f| &f[..n])
                .fold(0f64, |m, &v| m.max(v));
        let mut chart = ChartBuilder::on(&panels[0])
            .caption("(a) summed felt force", (FONT, 17))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..8.0, -0.02 * y_max..y_max)?;
        label_axes(&mut chart, "time (ms)", "force (N)", 13)?;
        for (i, ((depth, r), f)) in runs.iter().zip(&force).enumerate() {
            let c = colour(i);
            chart
                .draw_series(LineSeries::new(
                    (0..n).map(|k| (r.time_s(k) * 1e3, f[k])),
                    c.stroke_width(2),
                ))?
                .label(format!("depth {depth}"))
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 24, y)], c.stroke_width(2)));
        }
        chart
            .configure_series_labels()
            .label_font((FONT, 13))
            .border_style(BLACK)
            .background_style(WHITE.mix(0.9))
            .draw()?;
        let top_db = spectra
            .iter()
            .flatten()
            .fold(f64::NEG_INFINITY, |m, &v| m.max(v));
        let mut chart = ChartBuilder::on(&panels[1])
            .caption(
                "(b) transmitted T force, 0–0.5 s: its partials' envelope",
                (FONT, 17),
            )
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..3000.0, top_db - 70.0..top_db + 3.0)?;
        label_axes(&mut chart, "frequency (Hz)", "power (dB re 1 N²)", 13)?;
        for (i, db) in spectra.iter().enumerate() {
            let points = grid
                .iter()
                .zip(db)
                .map(|(&f, &v)| (f, v.max(top_db - 70.0)));
            chart.draw_series(LineSeries::new(points, colour(i).stroke_width(2)))?;
        }
        root.present()?;
        Ok(())
    };
    draw().map_err(plot_err(&png))?;
    Ok(vec![
        png,
        write_text(dir.join("fig7_soft_pedal.csv"), &csv)?,
    ])
}

/// The T60 of each key's first partial — its fastest and slowest string mode, a bar per key from
/// one to the other (`keys`: key 1–88, fastest, slowest, in s) — beside published values
/// (`published`: key, T60 in s, source) and a recorded grand's early and late T60 (`recorded`:
/// key, early, late, NaN where not measured), log scale (`unacorda analyze --figure`).
pub fn partial_decay(
    png: &Path,
    keyboard: &str,
    keys: &[(usize, f64, f64)],
    published: &[(usize, f64, &str)],
    recorded: &[(usize, f64, f64)],
) -> Result<(), FigureError> {
    register_font();
    let draw = || -> Result2<()> {
        let root = BitMapBackend::new(png, (1100, 650)).into_drawing_area();
        root.fill(&WHITE)?;
        let values = keys
            .iter()
            .flat_map(|k| [k.1, k.2])
            .chain(published.iter().map(|p| p.1))
            .chain(recorded.iter().flat_map(|r| [r.1, r.2]))
            .filter(|v| v.is_finite() && *v > 0.0);
        let (lo, hi) = values.fold((f64::INFINITY, 0f64), |(a, b), v| (a.min(v), b.max(v)));
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!("First partial's T60 per key, keyboard {keyboard}: fastest to slowest string mode (blue), recorded grand early and late (green), published (red)"),
                (FONT, 18),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..89.0, ((lo * 0.7).max(1e-3)..hi * 1.5).log_scale())?;
        label_axes(&mut chart, "key (1 = A0, 40 = C4, 88 = C8)", "T60 (s)", 13)?;
        chart.draw_series(keys.iter().map(|&(k, fast, slow)| {
            PathElement::new(
                vec![(k as f64, fast), (k as f64, slow)],
                COLORS[0].stroke_width(3),
            )
        }))?;
        chart.draw_series(
            keys.iter()
                .map(|&(k, _, slow)| Circle::new((k as f64, slow), 2, COLORS[0].filled())),
        )?;
        let shown = |v: f64| v.is_finite() && v > 0.0;
        chart
            .draw_series(
                recorded
                    .iter()
                    .flat_map(|&(k, early, late)| [(k, early), (k, late)])
                    .filter(|&(_, t)| shown(t))
                    .map(|(k, t)| TriangleMarker::new((k as f64 + 0.4, t), 5, COLORS[1].filled())),
            )?
            .label("recorded grand (Salamander, Yamaha C5): early and late T60")
            .legend(|(x, y)| TriangleMarker::new((x + 10, y), 5, COLORS[1].filled()));
        chart
            .draw_series(
                published
                    .iter()
                    .map(|&(k, t60, _)| Circle::new((k as f64, t60), 6, COLORS[2].filled())),
            )?
            .label(published.first().map_or("", |p| p.2))
            .legend(|(x, y)| Circle::new((x + 10, y), 5, COLORS[2].filled()));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font((FONT, 13))
            .draw()?;
        root.present()?;
        Ok(())
    };
    draw().map_err(plot_err(png))
}

fn write_text(path: PathBuf, text: &str) -> Result<PathBuf, FigureError> {
    std::fs::write(&path, text).map_err(|error| FigureError::Io {
        path: path.clone(),
        error,
    })?;
    Ok(path)
}

fn plot_err(path: &Path) -> impl Fn(Box<dyn std::error::Error + '_>) -> FigureError + '_ {
    move |e| FigureError::Plot {
        path: path.to_owned(),
        message: e.to_string(),
    }
}

type Result2<T> = Result<T, Box<dyn std::error::Error>>;

/// Axis titles and tick labels (numbers as [`tick`] writes them, in `label_px`) on a chart of
/// plain numbers, its mesh drawn.
fn label_axes<X, Y>(
    chart: &mut ChartContext<'_, BitMapBackend<'_>, Cartesian2d<X, Y>>,
    x_desc: &str,
    y_desc: &str,
    label_px: u32,
) -> Result2<()>
where
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(&tick)
        .y_label_formatter(&tick)
        .label_style((FONT, label_px))
        .draw()?;
    Ok(())
}

/// A drawing area of a bitmap.
type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// A white canvas of `size` pixels drawn to `png`, with `title` across its top in `font_px`:
/// the canvas (to present once drawn) and the area under the title.
fn titled_canvas<'a>(
    png: &'a Path,
    size: (u32, u32),
    title: &str,
    font_px: u32,
) -> Result2<(Area<'a>, Area<'a>)> {
    let root = BitMapBackend::new(png, size).into_drawing_area();
    root.fill(&WHITE)?;
    let (head, body) = root.split_vertically(40);
    head.titled(title, (FONT, font_px))?;
    Ok((root, body))
}

/// One recorded channel with each sample's physical time ([`Recording::time_s`]).
struct Trace {
    t_s: Vec<f64>,
    x: Vec<f64>,
}

impl Trace {
    fn new(rec: &Recording, x: Vec<f64>) -> Trace {
        Trace {
            t_s: (0..x.len()).map(|k| rec.time_s(k)).collect(),
            x,
        }
    }

    fn end_s(&self) -> f64 {
        self.t_s.last().copied().unwrap_or(1.0)
    }
}

/// Minimum and maximum of a trace in consecutive bins of `width_s` from t = 0 (a bin with no
/// sample holds none: `lo > hi`).
struct MinMax {
    /// Bin start times (s).
    t: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
}

fn min_max(trace: &Trace, width_s: f64, bins: usize) -> MinMax {
    let mut out = MinMax {
        t: (0..bins).map(|b| b as f64 * width_s).collect(),
        lo: vec![f64::INFINITY; bins],
        hi: vec![f64::NEG_INFINITY; bins],
    };
    for (&t, &x) in trace.t_s.iter().zip(&trace.x) {
        let b = (t / width_s).floor();
        if b >= 0.0 && (b as usize) < bins {
            let b = b as usize;
            out.lo[b] = out.lo[b].min(x);
            out.hi[b] = out.hi[b].max(x);
        }
    }
    out
}

fn symmetric_range(series: &[&[f64]]) -> f64 {
    let m = series
        .iter()
        .flat_map(|s| s.iter())
        .fold(0f64, |m, v| m.max(v.abs()));
    if m > 0.0 {
        1.1 * m
    } else {
        1.0
    }
}

/// Figure 3: hammer–string contact force, first 8 ms.
fn figure3(dir: &Path, uc: &Recording, normal: &Recording) -> Result<Vec<PathBuf>, FigureError> {
    let n = (0.008 * uc.rate_hz) as usize;
    let series = [
        (
            "una corda, string 1",
            uc.channel(|f| f.obs.hammer_force_n[0]),
        ),
        (
            "normal, string 1",
            normal.channel(|f| f.obs.hammer_force_n[0]),
        ),
        (
            "normal, string 2 (mistuned)",
            normal.channel(|f| f.obs.hammer_force_n[1]),
        ),
    ];
    let mut csv = String::from("time_ms,una_corda_string1_n,normal_string1_n,normal_string2_n\n");
    for k in 0..n {
        let _ = writeln!(
            csv,
            "{:.4},{:.5},{:.5},{:.5}",
            uc.time_s(k) * 1e3,
            series[0].1[k],
            series[1].1[k],
            series[2].1[k]
        );
    }
    let png = dir.join("fig3_hammer_force.png");
    let draw = || -> Result2<()> {
        let root = BitMapBackend::new(&png, (900, 560)).into_drawing_area();
        root.fill(&WHITE)?;
        let y_max = 1.1
            * series
                .iter()
                .flat_map(|s| s.1[..n].iter())
                .fold(0f64, |m, &v| m.max(v));
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "Fig. 3 — hammer–string contact force (c2, 2.5 m/s)",
                (FONT, 22),
            )
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..8.0, -0.02 * y_max..y_max)?;
        label_axes(&mut chart, "time (ms)", "force (N)", 15)?;
        // The normal strike's two strings meet the hammer almost alike: the first is drawn wide
        // and the second dashed over it, so that both show where they coincide.
        for (i, (label, data)) in series.iter().enumerate() {
            let color = COLORS[i];
            let width = if i == 1 { 6 } else { 2 };
            let points = (0..n).map(|k| (uc.time_s(k) * 1e3, data[k]));
            let drawn = if i == 2 {
                let style = color.stroke_width(width);
                chart.draw_series(DashedLineSeries::new(points, 6, 4, style))?
            } else {
                chart.draw_series(LineSeries::new(points, color.stroke_width(width)))?
            };
            drawn.label(*label).legend(move |(x, y)| {
                // Dashed as its curve (a gap of 0: one stroke for the others).
                let (dash, gap) = if i == 2 { (6, 4) } else { (24, 0) };
                let style = color.stroke_width(width);
                plotters::element::DashedPathElement::new([(x, y), (x + 24, y)], dash, gap, style)
            });
        }
        chart
            .configure_series_labels()
            .label_font((FONT, 15))
            .border_style(BLACK)
            .background_style(WHITE.mix(0.9))
            .draw()?;
        root.present()?;
        Ok(())
    };
    draw().map_err(plot_err(&png))?;
    Ok(vec![
        png,
        write_text(dir.join("fig3_hammer_force.csv"), &csv)?,
    ])
}

/// One panel of min/max bins: a filled band per bin.
/// A trace's envelope: the min/max of the samples under each pixel column, so the band reads as
/// a continuous envelope at any size (bins of fixed width alias against the pixel grid).
fn draw_band(
    area: &DrawingArea<BitMapBackend, Shift>,
    caption: &str,
    trace: &Trace,
    y: f64,
    color: RGBColor,
    x_label: bool,
) -> Result2<()> {
    let t_end = trace.end_s();
    let mut chart = ChartBuilder::on(area)
        .caption(caption, (FONT, 15))
        .margin(6)
        .x_label_area_size(if x_label { 30 } else { 18 })
        .y_label_area_size(55)
        .build_cartesian_2d(0.0..t_end, -y..y)?;
    let mut mesh = chart.configure_mesh();
    mesh.label_style((FONT, 11))
        .y_desc("N")
        .x_label_formatter(&tick)
        .y_label_formatter(&tick)
        .disable_x_mesh();
    if x_label {
        mesh.x_desc("time (s)");
    }
    mesh.draw()?;
    let columns = chart.plotting_area().dim_in_pixel().0.max(1) as usize;
    let width_s = t_end / columns as f64;
    let band = min_max(trace, width_s, columns);
    chart.draw_series(
        band.t
            .iter()
            .zip(band.lo.iter().zip(&band.hi))
            .filter(|(_, (a, b))| a <= b)
            .map(|(&ti, (&a, &b))| Rectangle::new([(ti, a), (ti + width_s, b)], color.filled())),
    )?;
    Ok(())
}

/// Figure 4: force of each string on the soundboard in T, L and P, una corda (a, b) and normal (c, d).
fn figure4(dir: &Path, uc: &Recording, normal: &Recording) -> Result<Vec<PathBuf>, FigureError> {
    let string = |rec: &Recording, s: usize| -> [Trace; 3] {
        std::array::from_fn(|d| Trace::new(rec, rec.channel(|f| f.obs.bridge_force_n[s][d])))
    };
    let columns = [
        (
            "(a) una corda, string 1 (struck)",
            "a_uc_str1",
            string(uc, 0),
        ),
        (
            "(b) una corda, string 2 (passive)",
            "b_uc_str2",
            string(uc, 1),
        ),
        ("(c) normal, string 1", "c_normal_str1", string(normal, 0)),
        ("(d) normal, string 2", "d_normal_str2", string(normal, 1)),
    ];
    band_grid(
        dir,
        "fig4_string_forces",
        "Fig. 4 — force of each string on the soundboard (rows T, L, P)",
        (1400, 900),
        &columns,
    )
}

/// Figure 5: total force transmitted to the soundboard, una corda (a) and normal (b).
fn figure5(dir: &Path, uc: &Recording, normal: &Recording) -> Result<Vec<PathBuf>, FigureError> {
    let total = |rec: &Recording| -> [Trace; 3] {
        std::array::from_fn(|d| Trace::new(rec, rec.channel(|f| f.obs.total_force_n[d])))
    };
    let columns = [
        ("(a) una corda", "a_uc", total(uc)),
        ("(b) normal", "b_normal", total(normal)),
    ];
    band_grid(
        dir,
        "fig5_total_force",
        "Fig. 5 — total force transmitted to the soundboard (rows T, L, P)",
        (1100, 800),
        &columns,
    )
}

/// A grid of min/max force bands, one row per direction (T, L, P) and one column per case, each
/// row on one scale so that the cases compare; written as `stem.png` and `stem.csv` (the CSV in
/// bins of `BIN_S`).
fn band_grid(
    dir: &Path,
    stem: &str,
    title: &str,
    size: (u32, u32),
    columns: &[(&str, &str, [Trace; 3])],
) -> Result<Vec<PathBuf>, FigureError> {
    let bins = (columns[0].2[0].end_s() / BIN_S).ceil() as usize;
    let binned: Vec<[MinMax; 3]> = columns
        .iter()
        .map(|(_, _, traces)| traces.each_ref().map(|t| min_max(t, BIN_S, bins)))
        .collect();
    let mut csv = String::from("time_s");
    for (_, tag, _) in columns {
        for d in Direction::ALL.map(Direction::name) {
            let _ = write!(csv, ",{tag}_{d}_min_n,{tag}_{d}_max_n");
        }
    }
    csv.push('\n');
    for k in 0..bins {
        let _ = write!(csv, "{:.4}", binned[0][0].t[k]);
        for bins in &binned {
            for b in bins {
                let _ = write!(csv, ",{:.6},{:.6}", b.lo[k], b.hi[k]);
            }
        }
        csv.push('\n');
    }
    let png = dir.join(format!("{stem}.png"));
    let draw = || -> Result2<()> {
        let (root, body) = titled_canvas(&png, size, title, 22)?;
        let panels = body.split_evenly((3, columns.len()));
        for d in 0..3 {
            let y = symmetric_range(
                &columns
                    .iter()
                    .map(|(_, _, t)| &t[d].x[..])
                    .collect::<Vec<_>>(),
            );
            for (c, (label, _, traces)) in columns.iter().enumerate() {
                let caption = format!("{label} — {}", Direction::ALL[d].name());
                draw_band(
                    &panels[d * columns.len() + c],
                    &caption,
                    &traces[d],
                    y,
                    COLORS[d],
                    Direction::ALL[d] == Direction::P,
                )?;
            }
        }
        root.present()?;
        Ok(())
    };
    draw().map_err(plot_err(&png))?;
    Ok(vec![
        png,
        write_text(dir.join(format!("{stem}.csv")), &csv)?,
    ])
}

/// A perceptually ordered colour map (viridis, five stops), `x` in [0, 1]: Fig. 6's colours
/// and its colour bar's.
pub fn colormap(x: f64) -> RGBColor {
    const STOPS: [(f64, f64, f64); 5] = [
        (68.0, 1.0, 84.0),
        (59.0, 82.0, 139.0),
        (33.0, 145.0, 140.0),
        (94.0, 201.0, 98.0),
        (253.0, 231.0, 37.0),
    ];
    let x = x.clamp(0.0, 1.0) * 4.0;
    let i = (x.floor() as usize).min(3);
    let f = x - i as f64;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    let mix = |p: f64, q: f64| (p + f * (q - p)).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// The width of Fig. 6's colour bar with its labels (px).
const COLOUR_BAR_PX: u32 = 110;

/// A vertical colour bar of [`colormap`] from `lo_db` (bottom) to `hi_db` (top), labelled in dB.
fn colour_bar(area: &DrawingArea<BitMapBackend, Shift>, lo_db: f64, hi_db: f64) -> Result2<()> {
    let mut chart = ChartBuilder::on(area)
        .caption("dB re 1 N", (FONT, 14))
        .margin_top(10)
        .margin_bottom(10)
        .margin_right(10)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..1.0, lo_db..hi_db)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_label_formatter(&|v| format!("{v:.0}"))
        .label_style((FONT, 12))
        .draw()?;
    let steps = 256;
    let step_db = (hi_db - lo_db) / steps as f64;
    chart.draw_series((0..steps).map(|i| {
        let db = lo_db + i as f64 * step_db;
        let c = colormap((i as f64 + 0.5) / steps as f64);
        Rectangle::new([(0.0, db), (1.0, db + step_db)], c.filled())
    }))?;
    Ok(())
}

/// Figure 6: spectrograms of the transmitted T force, first 4 s, up to 4 kHz, with their colour
/// bar.
fn figure6(dir: &Path, uc: &Recording, normal: &Recording) -> Result<Vec<PathBuf>, FigureError> {
    let fs = uc.rate_hz;
    let n_fft = 4096;
    let hop = 1024;
    let seconds = 4.0f64.min(uc.frames.len() as f64 / fs);
    let spec = |rec: &Recording| {
        let x = rec.channel(|f| f.obs.total_force_n[0]);
        spectrogram(&x[..(seconds * fs) as usize], fs, n_fft, hop, 4000.0)
    };
    let (times, freqs, s_uc) = spec(uc);
    let (_, _, s_n) = spec(normal);
    let mut csv = String::from("time_s,freq_hz,una_corda_db,normal_db\n");
    for (i, t) in times.iter().enumerate() {
        for (j, f) in freqs.iter().enumerate() {
            let _ = writeln!(csv, "{t:.4},{f:.2},{:.2},{:.2}", s_uc[i][j], s_n[i][j]);
        }
    }
    let top = s_uc
        .iter()
        .chain(&s_n)
        .flatten()
        .fold(f64::NEG_INFINITY, |m, &v| m.max(v));
    let range_db = 70.0;
    let png = dir.join("fig6_spectrograms.png");
    let df = fs / n_fft as f64;
    let dt = hop as f64 / fs;
    let freqs = &freqs[..];
    let draw = || -> Result2<()> {
        let (root, body) = titled_canvas(
            &png,
            (1300, 560),
            &format!("Fig. 6 — spectrogram of the transmitted T force (dB re 1 N, {range_db:.0} dB range)"),
            20,
        )?;
        let (spectra, bar) = body.split_horizontally(body.dim_in_pixel().0 - COLOUR_BAR_PX);
        colour_bar(&bar, top - range_db, top)?;
        let panels = spectra.split_evenly((1, 2));
        for (panel, (label, rows)) in panels
            .iter()
            .zip([("(a) una corda", &s_uc), ("(b) normal", &s_n)])
        {
            let mut chart = ChartBuilder::on(panel)
                .caption(label, (FONT, 17))
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..seconds, 0.0..4000.0)?;
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc("time (s)")
                .y_desc("frequency (Hz)")
                .x_label_formatter(&tick)
                .y_label_formatter(&tick)
                .label_style((FONT, 13))
                .draw()?;
            chart.draw_series(rows.iter().enumerate().flat_map(|(i, row)| {
                let t0 = times[i] - dt / 2.0;
                row.iter().enumerate().map(move |(j, &db)| {
                    let f0 = freqs[j] - df / 2.0;
                    let c = colormap(1.0 - (top - db) / range_db);
                    Rectangle::new([(t0.max(0.0), f0.max(0.0)), (t0 + dt, f0 + df)], c.filled())
                })
            }))?;
        }
        root.present()?;
        Ok(())
    };
    draw().map_err(plot_err(&png))?;
    Ok(vec![
        png,
        write_text(dir.join("fig6_spectrograms.csv"), &csv)?,
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_read_as_numbers_are_written() {
        for (v, label) in [
            (100.0, "100"),
            (1000.0, "1000"),
            (0.1 + 0.2, "0.3"),
            (1.25, "1.25"),
            (-0.0, "0"),
            (-20.0, "-20"),
        ] {
            assert_eq!(tick(&v), label, "{v}");
        }
    }

    #[test]
    fn pixel_columns_hold_every_sample_once() {
        // 1 s of a 1 kHz sine at 48 kHz on 700 columns (68.6 samples each, not a whole number):
        // every column is filled, spans the sine's full swing, and the counts add up.
        let rate = 48_000.0;
        let trace = Trace {
            t_s: (0..48_000).map(|k| k as f64 / rate).collect(),
            x: (0..48_000)
                .map(|k| (2.0 * std::f64::consts::PI * 1000.0 * k as f64 / rate).sin())
                .collect(),
        };
        let columns = 700;
        let band = min_max(&trace, trace.end_s() / columns as f64, columns);
        let worst = (0..columns)
            .map(|c| (1.0 - band.hi[c]).max(1.0 + band.lo[c]))
            .fold(0.0, f64::max);
        println!("700 columns over a 1 kHz sine: every column within {worst:.3} of ±1");
        assert!(worst < 0.01, "{worst}");
        // A ramp x = t: each column holds exactly the samples of its own time span.
        let ramp = Trace {
            x: trace.t_s.clone(),
            t_s: trace.t_s.clone(),
        };
        let width = ramp.end_s() / columns as f64;
        let band = min_max(&ramp, width, columns);
        for c in 0..columns {
            let (start, end) = (c as f64 * width, (c + 1) as f64 * width);
            assert!(
                band.lo[c] >= start && band.lo[c] < start + 1.0 / rate,
                "column {c}"
            );
            assert!(
                band.hi[c] < end && band.hi[c] >= end - 1.0 / rate - 1e-12,
                "column {c}"
            );
        }
    }
}
