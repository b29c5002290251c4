//! Tuning: a string's partials on its bridge, from the undamped linear system, and the pitch a
//! tuner hears from them.
//!
//! Without damping, string T modes, contact spring and board T modes form a symmetric system
//! (Eq. 2, 5, 6 with mass-normalised modes, `M = I`):
//! ```text
//! K = [ Omega_s^2 + k psi psi^T      -k psi phi_T^T           ]
//!     [ -k phi_T psi^T               Omega_b^2 + k phi_T phi_T^T ]
//! ```
//! Its eigenvalues are the coupled frequencies. The truncated string mode set (a Ritz basis) puts
//! the first partial above the speaking length's fundamental, by tens of cents when few modes are
//! kept; the spring and the board's reactance move it further, and a board mode near a partial
//! pulls that partial alone. Tuning against this system's partials 2–8, as a tuner listens, puts
//! the struck note on pitch.

use crate::engine::physics::soundboard::{BridgePoint, SoundboardModes};
use crate::engine::physics::string::StringParams;
use faer::{Mat, Side};
use std::f64::consts::PI;

/// A partial's modes lie within this fraction of the partial spacing of where the stiff string
/// puts it (also the analysis's window: [`crate::analysis::partials`]).
pub const PARTIAL_WINDOW: f64 = 0.3;

/// Share of a mode's energy in the string's transverse motion from which it counts as a string
/// mode of a partial (also the analysis's: [`crate::analysis::partials`]; a mode shared with the
/// board, string 50 % and board 43 %, does not).
pub const STRING_SHARE: f64 = 0.6;

/// The coupled partials `1..=count` (Hz) as a listener meets them: for each `n`, the eigenvalues
/// within [`PARTIAL_WINDOW`] of the spacing `expected_hz(1)` of `expected_hz(n)` whose modes hold
/// at least [`STRING_SHARE`] of their motion in the string, averaged weighted by that share (the
/// analysis's partial, so that a key is tuned as it is measured); none where no string mode is
/// there (a board mode's frequency would pull the tuning anywhere). `board` is `None` for a
/// rigid bridge.
pub fn bridged_partials_hz(
    string: &StringParams,
    modes: usize,
    contact_n_m: f64,
    board: Option<(&SoundboardModes, &BridgePoint)>,
    expected_hz: impl Fn(usize) -> f64,
    count: usize,
) -> Vec<(usize, f64)> {
    let system = RankOne::new(string, modes, contact_n_m, board);
    let spacing = expected_hz(1);
    let windows: Vec<(f64, f64)> = (1..=count)
        .map(|p| (expected_hz(p), PARTIAL_WINDOW * spacing))
        .collect();
    // Each window's coupled modes (Hz, string share): from the secular equation, or from the
    // whole eigen-solve where it does not apply.
    let found: Vec<Vec<(f64, f64)>> = match windows
        .iter()
        .map(|&(centre, width)| system.modes_within(centre - width, centre + width))
        .collect::<Option<_>>()
    {
        Some(found) => found,
        None => {
            let all = system.dense_modes();
            windows
                .iter()
                .map(|&(centre, width)| {
                    let near = |m: &&(f64, f64)| (m.0 - centre).abs() <= width;
                    all.iter().filter(near).copied().collect()
                })
                .collect()
        }
    };
    (1..=count)
        .zip(&found)
        .filter_map(|(p, modes)| {
            let (weight, sum) = modes
                .iter()
                .filter(|(_, share)| *share >= STRING_SHARE)
                .fold((0.0, 0.0), |(w, s), (f, share)| (w + share, s + share * f));
            (weight > 0.0).then(|| (p, sum / weight))
        })
        .collect()
}

/// The undamped string on its contact spring and the board's T modes (module notes): a diagonal
/// `D` (the string's and the board's `omega^2`, the string's first) and the spring's rank-one
/// term `k g g^T`, `g = [psi; -phi_T]`.
struct RankOne {
    d: Vec<f64>,
    g: Vec<f64>,
    k: f64,
    /// How many of the modes are the string's.
    strings: usize,
    /// The secular equation's poles: each `d_i` of nonzero `g_i`, rising, with `g_i^2` and `i`.
    poles: Vec<Pole>,
    /// Whether no two poles (nearly) coincide, so that the secular equation separates every
    /// mode ([`RankOne::modes_within`]).
    separable: bool,
    /// `k g^T g`: the highest eigenvalue lies within this of the highest pole.
    reach: f64,
}

/// A pole of the secular equation: `d_i`, `g_i^2` and the mode `i` it stands for.
#[derive(Clone, Copy)]
struct Pole {
    d: f64,
    g2: f64,
    i: usize,
}

impl RankOne {
    fn new(
        string: &StringParams,
        modes: usize,
        contact_n_m: f64,
        board: Option<(&SoundboardModes, &BridgePoint)>,
    ) -> RankOne {
        let ls = string.speaking_length_m;
        let mut d: Vec<f64> = (1..=modes)
            .map(|n| string.transverse_omega(n).powi(2))
            .collect();
        // Coupling vector g: the spring's stretch is g^T q.
        let mut g: Vec<f64> = (1..=modes).map(|n| string.mode_shape(n, ls)).collect();
        if let Some((b, p)) = board {
            d.extend(b.freq_hz.iter().map(|f| (2.0 * PI * f).powi(2)));
            g.extend(p.shape[0].iter().map(|x| -x));
        }
        let mut poles: Vec<Pole> = (0..d.len())
            .filter(|&i| g[i] != 0.0)
            .map(|i| Pole {
                d: d[i],
                g2: g[i].powi(2),
                i,
            })
            .collect();
        poles.sort_by(|a, b| a.d.total_cmp(&b.d));
        let separable = poles
            .windows(2)
            .all(|w| w[1].d - w[0].d > 1e-12 * w[1].d.abs());
        let reach = contact_n_m * poles.iter().map(|p| p.g2).sum::<f64>();
        RankOne {
            d,
            g,
            k: contact_n_m,
            strings: modes,
            poles,
            separable,
            reach,
        }
    }

    /// Every mode (Hz, the share of its motion in the string) by one eigen-solve of the whole
    /// system.
    fn dense_modes(&self) -> Vec<(f64, f64)> {
        let n = self.d.len();
        let a = Mat::<f64>::from_fn(n, n, |i, j| {
            let diag = if i == j { self.d[i] } else { 0.0 };
            diag + self.k * self.g[i] * self.g[j]
        });
        let evd = a
            .self_adjoint_eigen(Side::Lower)
            .expect("a real symmetric matrix has real eigenvalues");
        let (vals, vecs) = (evd.S().column_vector(), evd.U());
        (0..n)
            .map(|m| {
                let share = (0..self.strings).map(|i| vecs[(i, m)].powi(2)).sum();
                (vals[m].max(0.0).sqrt() / (2.0 * PI), share)
            })
            .collect()
    }

    /// The modes between `lo_hz` and `hi_hz` (Hz, string share), from the secular equation
    /// `1 + k sum_i g_i^2 / (d_i - lambda) = 0`: with `k > 0` exactly one eigenvalue lies between
    /// each two neighbouring `d_i` of nonzero `g_i` (and one above the highest, within
    /// `k g^T g`), found by bisection (the left side rises through the interval), its vector
    /// `(D - lambda)^{-1} g`. A `d_i` whose `g_i` is zero is an eigenvalue itself, its vector
    /// `e_i`. `None` where two `d_i` of nonzero `g_i` (nearly) coincide: the equation does not
    /// separate them.
    fn modes_within(&self, lo_hz: f64, hi_hz: f64) -> Option<Vec<(f64, f64)>> {
        if !self.separable {
            return None;
        }
        let lambda = |hz: f64| (2.0 * PI * hz.max(0.0)).powi(2);
        let (lo, hi) = (lambda(lo_hz), lambda(hi_hz));
        let hz = |l: f64| l.max(0.0).sqrt() / (2.0 * PI);
        let is_string = |i: usize| if i < self.strings { 1.0 } else { 0.0 };
        let mut found: Vec<(f64, f64)> = (0..self.d.len())
            .filter(|&i| self.g[i] == 0.0 && (lo..=hi).contains(&self.d[i]))
            .map(|i| (hz(self.d[i]), is_string(i)))
            .collect();
        let poles = &self.poles;
        let secular = |l: f64| 1.0 + self.k * poles.iter().map(|p| p.g2 / (p.d - l)).sum::<f64>();
        for (j, pole) in poles.iter().enumerate() {
            let a = pole.d;
            let b = poles.get(j + 1).map_or(a + self.reach, |p| p.d);
            if b < lo || a > hi {
                continue;
            }
            let (mut below, mut above) = (a, b);
            loop {
                let mid = 0.5 * (below + above);
                if mid <= below || mid >= above {
                    break;
                }
                if secular(mid) < 0.0 {
                    below = mid;
                } else {
                    above = mid;
                }
            }
            // Off the poles even where a root lies within a rounding of one (a tiny `g_i`).
            let l = if below > a { below } else { above };
            if !(lo..=hi).contains(&l) {
                continue;
            }
            let (mut string, mut all) = (0.0, 0.0);
            for p in poles {
                let v2 = p.g2 / (p.d - l).powi(2);
                all += v2;
                string += is_string(p.i) * v2;
            }
            found.push((hz(l), string / all));
        }
        Some(found)
    }
}

/// Eq. 2's law fitted to partials 2–8 of `partials` (`(n, Hz)`): `f_n^2 = a n^2 + b n^4` with
/// `a = f0^2`, `b = f0^2 B`, each equation divided by `f_n^2` so that every partial weighs by its
/// error in cents. A partial that a board mode pulls off the law counts little: the fit is
/// reweighted ([`OUTLIER_CENTS`], Cauchy weights `1 / (1 + (r/c)^2)` of each partial's distance
/// `r` from the law, until they settle). Returns the law's first partial `f0 sqrt(1 + B)` (Hz),
/// its `B`, and how many partials it rests on (weight at least one half); from one or two, `B` is
/// `nominal_b` and only `f0` is fitted. `None` without any of partials 2–8. The inharmonicity the
/// coupled key shows (`analyze`'s "fit B"); its pitch is [`series_offset_cents`]'s.
pub fn stiff_string_fit(partials: &[(usize, f64)], nominal_b: f64) -> Option<(f64, f64, usize)> {
    let used: Vec<(f64, f64)> = partials
        .iter()
        .filter(|p| (2..=8).contains(&p.0))
        .map(|&(n, f)| (n as f64, f))
        .collect();
    if used.is_empty() {
        return None;
    }
    if used.len() < 3 {
        // f0 from each partial with B given, averaged in cents.
        let log_f0 = used
            .iter()
            .map(|&(n, f)| (f / (n * (1.0 + nominal_b * n * n).sqrt())).ln())
            .sum::<f64>()
            / used.len() as f64;
        let f0_sq = (2.0 * log_f0).exp();
        return Some((
            f0_sq.sqrt() * (1.0 + nominal_b).sqrt(),
            nominal_b,
            used.len(),
        ));
    }
    let mut weight = vec![1.0; used.len()];
    let (mut a, mut b) = (0.0, 0.0);
    for _ in 0..50 {
        // Weighted normal equations of rows (n^2 / f^2, n^4 / f^2) = 1.
        let (mut s11, mut s12, mut s22, mut r1, mut r2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (&(n, f), w) in used.iter().zip(&weight) {
            let (x1, x2) = (n * n / (f * f), n.powi(4) / (f * f));
            (s11, s12, s22, r1, r2) = (
                s11 + w * x1 * x1,
                s12 + w * x1 * x2,
                s22 + w * x2 * x2,
                r1 + w * x1,
                r2 + w * x2,
            );
        }
        let det = s11 * s22 - s12 * s12;
        (a, b) = ((r1 * s22 - r2 * s12) / det, (s11 * r2 - s12 * r1) / det);
        let mut moved: f64 = 0.0;
        for (&(n, f), w) in used.iter().zip(weight.iter_mut()) {
            let cents = 600.0 * (f * f / (a * n * n + b * n.powi(4))).log2();
            let next = 1.0 / (1.0 + (cents / OUTLIER_CENTS).powi(2));
            moved = moved.max((next - *w).abs());
            *w = if next.is_finite() { next } else { 0.0 };
        }
        if moved < 1e-9 {
            break;
        }
    }
    let counted = weight.iter().filter(|&&w| w >= 0.5).count();
    (a > 0.0 && a.is_finite() && b.is_finite()).then(|| ((a + b).sqrt(), b / a, counted))
}

/// How far partials 2–8 of `partials` (`(n, Hz)`) lie from the series `stiff_string_hz(target_hz,
/// b)` that the key should sound (cents), as a tuner balances them: the mean of their offsets,
/// each partial weighing `1 / (1 + (r/c)^2)` of its distance `r` from that mean
/// ([`OUTLIER_CENTS`]), iterated from the median until the weights settle — so that a partial a
/// board mode pulls off the series counts little, and the result is continuous in the partials (a
/// small change of tension never jumps it). With `b` the string's own, a partial's offset is what
/// a tuning device shows for it; fitting `B` as well ([`stiff_string_fit`]) would extrapolate the
/// first partial from 2–8 and turn a tilt of a few cents across them (the board's pulls on Bb0)
/// into several cents of pitch. Returns the offset and how many partials it rests on (weight at
/// least one half); `None` without any of partials 2–8.
pub fn series_offset_cents(
    partials: &[(usize, f64)],
    target_hz: f64,
    b: f64,
) -> Option<(f64, usize)> {
    let series = stiff_string_hz(target_hz, b);
    let mut offsets: Vec<f64> = partials
        .iter()
        .filter(|p| (2..=8).contains(&p.0))
        .map(|&(n, f)| 1200.0 * (f / series(n)).log2())
        .filter(|c| c.is_finite())
        .collect();
    if offsets.is_empty() {
        return None;
    }
    offsets.sort_by(f64::total_cmp);
    let half = offsets.len() / 2;
    let mut centre = if offsets.len() % 2 == 1 {
        offsets[half]
    } else {
        0.5 * (offsets[half - 1] + offsets[half])
    };
    let weight = |c: f64, centre: f64| 1.0 / (1.0 + ((c - centre) / OUTLIER_CENTS).powi(2));
    for _ in 0..200 {
        let (w, wx) = offsets.iter().fold((0.0, 0.0), |(w, wx), &c| {
            let k = weight(c, centre);
            (w + k, wx + k * c)
        });
        let next = wx / w;
        let moved = (next - centre).abs();
        centre = next;
        if moved < 1e-12 {
            break;
        }
    }
    let counted = offsets
        .iter()
        .filter(|&&c| weight(c, centre) >= 0.5)
        .count();
    Some((centre, counted))
}

/// The scale of a tuner's weights (cents): a partial this far from the others weighs one half,
/// one pulled 15 cents by a board mode 1/26.
pub const OUTLIER_CENTS: f64 = 3.0;

/// The stiff string's partials with the first at `target_hz` and inharmonicity `b` (Eq. 2).
pub fn stiff_string_hz(target_hz: f64, b: f64) -> impl Fn(usize) -> f64 {
    move |n| {
        let n = n as f64;
        n * target_hz * ((1.0 + b * n * n) / (1.0 + b)).sqrt()
    }
}

/// The pitch a tuner hears from `string` on its bridge and board (Hz): `target_hz` moved by the
/// offset of its coupled partials 2–8 from the target's series ([`series_offset_cents`], `B` the
/// string's own), or its first partial where none of them is below the modes kept (the top keys).
pub fn bridged_pitch_hz(
    string: &StringParams,
    modes: usize,
    contact_n_m: f64,
    board: Option<(&SoundboardModes, &BridgePoint)>,
    target_hz: f64,
) -> f64 {
    let b = string.speaking_inharmonicity();
    let found = bridged_partials_hz(
        string,
        modes,
        contact_n_m,
        board,
        stiff_string_hz(target_hz, b),
        8.min(modes),
    );
    series_offset_cents(&found, target_hz, b)
        .map(|(cents, _)| target_hz * 2f64.powf(cents / 1200.0))
        .or_else(|| found.iter().find(|p| p.0 == 1).map(|p| p.1))
        .unwrap_or(target_hz)
}

#[cfg(test)]
mod tests {
    use super::{series_offset_cents, stiff_string_fit, stiff_string_hz};

    /// Partials 2–8 of a stiff string (E1-like: 41.1 Hz, B = 1.5e-4), one of them pulled by a
    /// board mode: the tuner's pitch stays on the string's as the pull grows from 0 to 30 cents,
    /// and moves with it continuously (no jump as a partial loses its weight); the law's fit finds
    /// the string's `B`.
    #[test]
    fn a_pulled_partial_does_not_pull_the_pitch() {
        let (f1, b) = (41.1, 1.5e-4);
        let law = stiff_string_hz(f1, b);
        let partials = |pull_cents: f64| -> Vec<(usize, f64)> {
            (2..=8)
                .map(|n| {
                    let pull = if n == 2 { pull_cents } else { 0.0 };
                    (n, law(n) * 2f64.powf(pull / 1200.0))
                })
                .collect()
        };
        let pitch = |pull_cents: f64| series_offset_cents(&partials(pull_cents), f1, b).unwrap();
        let (mut worst, mut jump, mut last): (f64, f64, f64) = (0.0, 0.0, 0.0);
        for i in 0..=300 {
            let (cents, _) = pitch(i as f64 * 0.1);
            worst = worst.max(cents.abs());
            jump = jump.max((cents - last).abs());
            last = cents;
        }
        let (at_pull, counted) = pitch(26.7);
        let (_, fitted_b, _) = stiff_string_fit(&partials(0.0), 0.0).unwrap();
        println!("partial 2 pulled 0–30 cents: pitch at most {worst:.2} cents off, steps of 0.1 cent move it at most {jump:.3}; pulled 26.7 (E1's): {at_pull:+.2} cents on {counted} partials; the law's B {fitted_b:.4e}");
        assert!(worst < 1.0 && jump < 0.1 && at_pull.abs() < 0.2 && counted == 6);
        assert!((fitted_b / b - 1.0).abs() < 1e-6);
    }

    #[test]
    fn the_secular_equation_finds_the_whole_solves_modes() {
        // Every fifth key of the concert keyboard, its tuned string on its bridge point: the
        // coupled modes within partials 1-8's windows from the secular equation against faer's
        // eigen-solve of the whole system. The same modes, each root where the equation is zero
        // to rounding (a Newton step from it a few 1e-16 of it), their frequencies and string
        // shares as the whole solve's to that solve's accuracy where modes crowd (a board mode
        // 3 Hz from another in key 56's 8th window is 3e-8 off there: the equation's left side
        // at the whole solve's value is 8e-3, at the root 1e-11).
        use super::{stiff_string_hz, RankOne, PARTIAL_WINDOW, PI};
        let scaling = crate::config::scaling::Scaling::resolve("concert").unwrap();
        let contact = scaling.base.contact().stiffness_n_m[0];
        let (mut worst_hz, mut worst_share, mut worst_residual, mut compared) =
            (0f64, 0f64, 0f64, 0);
        for key in (1..=88).step_by(5) {
            let preset = scaling.key_preset(key).unwrap();
            let strings = &preset.preset.strings;
            let string = strings.nominal_string();
            let point = &preset.board.points[preset.bridge_point];
            let system = RankOne::new(
                &string,
                strings.modes_t,
                contact,
                Some((&preset.board, point)),
            );
            // How far a root is from where the equation is zero: a Newton step `f / f'`, as a
            // fraction of the eigenvalue.
            let newton = |hz: f64| {
                let l = (2.0 * PI * hz).powi(2);
                let (mut f, mut slope) = (1.0, 0.0);
                for (d, g) in system.d.iter().zip(&system.g) {
                    f += system.k * g * g / (d - l);
                    slope += system.k * (g / (d - l)).powi(2);
                }
                (f / slope).abs() / l
            };
            let whole = system.dense_modes();
            let expected = stiff_string_hz(scaling.target_hz(key), string.speaking_inharmonicity());
            let spacing = expected(1);
            for p in 1..=8.min(strings.modes_t) {
                let (centre, width) = (expected(p), PARTIAL_WINDOW * spacing);
                let within = |m: &(f64, f64)| (m.0 - centre).abs() <= width;
                let mut dense: Vec<(f64, f64)> = whole.iter().copied().filter(within).collect();
                let mut found = system
                    .modes_within(centre - width, centre + width)
                    .expect("the concert keys' poles are apart");
                found.retain(within);
                dense.sort_by(|a, b| a.0.total_cmp(&b.0));
                found.sort_by(|a, b| a.0.total_cmp(&b.0));
                assert_eq!(dense.len(), found.len(), "key {key}, partial {p}");
                for (d, s) in dense.iter().zip(&found) {
                    worst_hz = worst_hz.max((d.0 - s.0).abs() / d.0);
                    worst_share = worst_share.max((d.1 - s.1).abs());
                    worst_residual = worst_residual.max(newton(s.0));
                    compared += 1;
                }
            }
        }
        println!(
            "{compared} modes: each within {worst_residual:.1e} of its root (a Newton step); frequencies within {worst_hz:.1e} of the whole solve's, string shares within {worst_share:.1e}"
        );
        assert!(worst_residual < 2e-15, "{worst_residual:e}");
        assert!(
            worst_hz < 1e-7 && worst_share < 3e-8,
            "{worst_hz:e} {worst_share:e}"
        );
    }
}
