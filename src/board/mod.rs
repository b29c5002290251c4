//! The soundboard generator: a clamped, ribbed orthotropic plate carrying the bridges, solved for
//! all its modes below 7 kHz and reduced by the paper's rule (§2.2) to the asset the engine reads.
//!
//! **Method: Rayleigh–Ritz**, chosen over finite elements because the board's smallest bending
//! wavelength at 7 kHz (≈ 5 cm across the grain) would need ~10⁵ plate-element DOFs and a sparse
//! shift-invert eigensolver, while global functions resolve it with ~2000 and a dense solver:
//! - basis `X_i(x) Y_j(y)` with `X_i = sin(pi x/a) sin(i pi x/a)` for clamped edges (zero
//!   deflection and slope; a complete cosine family) or `X_i = sin(i pi x/a)` for simply-supported;
//! - plate (Kirchhoff, orthotropic, grain along x):
//!   `U = ½∫ D1 w_xx² + 2 D12 w_xx w_yy + D2 w_yy² + 4 D66 w_xy² dA`, `T = ½∫ rho h ẇ² dA`,
//!   separable, so its matrices are Kronecker products of 1-D integrals (exact by the trapezoid
//!   rule: every integrand is a cosine series on [0, a]);
//! - ribs: beams along y (across the grain) at fixed x, bending `EI ∫ w_yy² dy` and torsion
//!   `GJ ∫ w_xy² dy`, and their mass. A rib glued on one face bends with a strip of the plate as a
//!   T-section: its stiffness about the plate's mid-plane is `E_b I_b + (E_b A_b · E_f A_f) /
//!   (E_b A_b + E_f A_f) e²`, `e` the offset of the rib's axis, `A_f` the plate strip (flange) that
//!   works with it (the rib spacing wide) and `E_f` the plate's modulus along the rib — the
//!   composite section's neutral-axis shift, which the bare parallel-axis rule (`A_b e²`) would
//!   overstate several-fold;
//! - bridges: curved beams (quadratic Bézier curves) glued on the board, bending along the curve's
//!   tangent `EI ∫ w_ss² ds` (the same T-section rule, flange `flange_width_m`, `E_f` the plate's
//!   modulus along the local tangent), torsion `GJ ∫ w_sn² ds`, mass, by quadrature along the curve;
//! - rims: curves inside the plate held as a clamped edge by a penalty,
//!   `k_w ∫ w² ds + k_θ ∫ w_n² ds` by the same quadrature, for an outline that is not a rectangle;
//! - `K c = omega² M c` by Cholesky of `M` and a dense symmetric eigensolver (faer), sequential and
//!   so deterministic; eigenvectors are mass-normalised (`cᵀ M c = 1`) and signed so that their
//!   largest coefficient is positive.
//!
//! At each key's bridge point the T component is the deflection `w`; the bridge top, `lever` above
//! the mid-plane, moves in the plane by `-lever ∇w` when the board rotates under it, which gives
//! the L (along the strings) and P (across them) components (DESIGN.md §4).

pub mod equivalent;
pub mod radiation;

use crate::engine::physics::soundboard::{BridgePoint, SoundboardModes};
use faer::{Mat, Side};
use serde::Deserialize;
use std::f64::consts::PI;

/// Input of the generator: the board, its ribs and bridges, the basis and the reduction.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BoardSpec {
    pub plate: PlateSpec,
    #[serde(default)]
    pub ribs: Option<RibSpec>,
    #[serde(default)]
    pub bridges: Vec<BridgeSpec>,
    /// Curves inside the plate held as clamped edges (may be none: the rectangle).
    #[serde(default)]
    pub rims: Vec<RimSpec>,
    pub basis: BasisSpec,
    pub reduction: ReductionSpec,
    /// Listeners at which each mode's radiation is worked out (`radiation`); may be none.
    #[serde(default)]
    pub listeners: Vec<radiation::ListenerSpec>,
}

/// The orthotropic plate (paper Table 1). Grain (E1) along x.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PlateSpec {
    /// Extent along the grain, x (m).
    pub width_m: f64,
    /// Extent across the grain, y (m).
    pub length_m: f64,
    pub thickness_m: f64,
    pub density_kg_m3: f64,
    pub e1_pa: f64,
    pub e2_pa: f64,
    pub nu12: f64,
    pub g12_pa: f64,
    /// `clamped` (the paper) or `simply-supported` (closed-form check).
    pub edges: Edges,
    pub damping_ratio: f64,
}

#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Edges {
    Clamped,
    SimplySupported,
}

/// Equally spaced ribs running across the grain (along y) over the whole board.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RibSpec {
    pub count: usize,
    /// x of the first rib (m).
    pub first_x_m: f64,
    pub spacing_m: f64,
    pub width_m: f64,
    pub height_m: f64,
    /// Along the rib's own grain (Pa).
    pub young_modulus_pa: f64,
    pub shear_modulus_pa: f64,
    pub density_kg_m3: f64,
}

/// A bridge: a quadratic Bézier curve on the board carrying a range of keys.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BridgeSpec {
    pub name: String,
    /// Start, control and end points `[x, y]` (m); `first_key` sits at the start.
    pub curve_m: [[f64; 2]; 3],
    /// Keys 1 (A0) to 88 (C8) spread evenly along the bridge by arc length.
    pub first_key: usize,
    pub last_key: usize,
    pub width_m: f64,
    pub height_m: f64,
    pub young_modulus_pa: f64,
    pub shear_modulus_pa: f64,
    pub density_kg_m3: f64,
    /// Width of the board strip that bends with the bridge as the flange of a T-section (m).
    pub flange_width_m: f64,
    /// Direction of the strings crossing this bridge, from the grain (deg).
    pub string_angle_deg: f64,
}

/// A rim inside the plate: a quadratic Bézier curve along which the plate is held as at a
/// clamped edge, by springs on its deflection and on its slope across the curve (a penalty),
/// so that a board need not be a rectangle (a grand's bent side and tail). The plate beyond the
/// rim is left as a separate piece whose modes the bridges inside do not drive. With 1e10 N/m²
/// and 1e7 N, a rim across a clamped 1.4 × 1 m spruce plate leaves a clamped square within 0.6 %
/// of Leissa's frequencies (`tests/soundboard_asset.rs`).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RimSpec {
    /// Start, control and end points `[x, y]` (m).
    pub curve_m: [[f64; 2]; 3],
    /// Spring on the deflection per unit length (N/m²).
    pub stiffness_n_m2: f64,
    /// Spring on the slope across the curve per unit length (N m/m: N).
    pub rotational_stiffness_n: f64,
}

/// Size of the Ritz basis.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BasisSpec {
    pub terms_x: usize,
    pub terms_y: usize,
    /// Quadrature points per metre along the bridges.
    pub bridge_points_per_m: f64,
}

/// The paper's reduction.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ReductionSpec {
    pub f_min_hz: f64,
    pub f_max_hz: f64,
    /// Bridge points whose dominant modes are kept (the paper: C2).
    pub points: Vec<String>,
    /// With listeners: the kept modes below this frequency (Hz) radiate what the full board's
    /// modes radiate ([`equivalent`]); absent (and above it), each by its own Rayleigh integral.
    #[serde(default)]
    pub radiation_fit_below_hz: Option<f64>,
    /// The modes the reduction drops from this frequency (Hz) up are kept in the asset as its
    /// residual ([`SoundboardModes::residual`]): driven by each key's bridge force and heard, not
    /// coupled. At or above `radiation_fit_below_hz`, where the kept modes radiate by their own
    /// integrals (below it their fit stands for the dropped ones). Absent: none (the paper).
    #[serde(default)]
    pub residual_from_hz: Option<f64>,
}

/// Name of key `k` (1 = A0 … 88 = C8), with flats so that names hold no `#`.
pub fn key_name(k: usize) -> String {
    const NAMES: [&str; 12] = [
        "C", "Db", "D", "Eb", "E", "F", "Gb", "G", "Ab", "A", "Bb", "B",
    ];
    let midi = k + 20;
    format!("{}{}", NAMES[midi % 12], midi / 12 - 1)
}

impl PlateSpec {
    /// Flexural rigidities `(D1, D2, D12, D66)` (N m).
    pub fn rigidities(&self) -> (f64, f64, f64, f64) {
        let h3 = self.thickness_m.powi(3);
        let nu21 = self.nu12 * self.e2_pa / self.e1_pa;
        let den = 12.0 * (1.0 - self.nu12 * nu21);
        let d1 = self.e1_pa * h3 / den;
        let d2 = self.e2_pa * h3 / den;
        (d1, d2, self.nu12 * d2, self.g12_pa * h3 / 12.0)
    }
}

/// One-dimensional basis along an edge of length `len`: values and derivatives 0–2.
#[derive(Debug, Clone, Copy)]
struct Basis1d {
    len: f64,
    terms: usize,
    edges: Edges,
}

impl Basis1d {
    /// `[f, f', f'']` of function `i` (0-based) at `x`.
    fn eval(&self, i: usize, x: f64) -> [f64; 3] {
        let k = PI / self.len;
        let n = (i + 1) as f64 * k;
        match self.edges {
            Edges::SimplySupported => {
                let (s, c) = (n * x).sin_cos();
                [s, n * c, -n * n * s]
            }
            Edges::Clamped => {
                // sin(kx) sin(nx) = ½[cos((n-k)x) - cos((n+k)x)]
                let (a, b) = (n - k, n + k);
                let (sa, ca) = (a * x).sin_cos();
                let (sb, cb) = (b * x).sin_cos();
                [
                    0.5 * (ca - cb),
                    0.5 * (-a * sa + b * sb),
                    0.5 * (-a * a * ca + b * b * cb),
                ]
            }
        }
    }

    /// `[f, f', f'']` of every function at `x`.
    fn at(&self, x: f64) -> Vec<[f64; 3]> {
        (0..self.terms).map(|i| self.eval(i, x)).collect()
    }

    /// `∫ f_i^(p) f_k^(q) dx` over the edge for all i, k: exact by the trapezoid rule, since every
    /// product is a cosine series of degree below twice the number of intervals.
    fn integrals(&self, p: usize, q: usize) -> Vec<f64> {
        let n = self.terms;
        let intervals = 4 * (n + 2);
        let h = self.len / intervals as f64;
        let mut out = vec![0.0; n * n];
        let values: Vec<Vec<[f64; 3]>> = (0..=intervals)
            .map(|s| (0..n).map(|i| self.eval(i, s as f64 * h)).collect())
            .collect();
        for (s, row) in values.iter().enumerate() {
            let w = if s == 0 || s == intervals { 0.5 * h } else { h };
            for i in 0..n {
                for k in 0..n {
                    out[i * n + k] += w * row[i][p] * row[k][q];
                }
            }
        }
        out
    }

    /// `∫ f_i dx` for all i, by Simpson's rule (the trapezoid's `(pi h)^2 / 12` was 5e-4 of a
    /// mode's net volume; checked against the simply-supported plate's closed form).
    fn means(&self) -> Vec<f64> {
        let intervals = 4 * (self.terms + 2);
        let h = self.len / intervals as f64;
        (0..self.terms)
            .map(|i| {
                (0..=intervals)
                    .map(|s| simpson_weight(s, intervals, h) * self.eval(i, s as f64 * h)[0])
                    .sum()
            })
            .collect()
    }
}

/// Composite Simpson weight of point `s` of `0..=intervals` (an even count) spaced `h`.
fn simpson_weight(s: usize, intervals: usize, h: f64) -> f64 {
    if s == 0 || s == intervals {
        h / 3.0
    } else if s % 2 == 1 {
        4.0 * h / 3.0
    } else {
        2.0 * h / 3.0
    }
}

/// A point on a bridge where a key's strings cross it.
#[derive(Debug, Clone, PartialEq)]
pub struct KeyPoint {
    pub key: usize,
    pub name: String,
    pub x_m: f64,
    pub y_m: f64,
    /// Unit vector along the strings, in the board's plane.
    pub string_dir: [f64; 2],
    /// Height of the string contact above the plate's mid-plane (m).
    pub lever_m: f64,
}

/// The solved board: every mode below `f_max`, at every key.
#[derive(Debug, Clone)]
pub struct SolvedBoard {
    pub modes: SoundboardModes,
    pub keys: Vec<KeyPoint>,
    /// Size of the Ritz basis.
    pub basis_size: usize,
    /// The Ritz mass matrix `M` (for checks).
    pub mass_matrix: Mat<f64>,
    /// Ritz coefficients of the kept modes, one column each, mass-normalised (`cᵀ M c = 1`).
    pub coefficients: Mat<f64>,
}

/// Errors of the generator.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum BoardError {
    #[error("field `{field}` = {value}: expected {allowed}")]
    Range {
        field: String,
        value: String,
        allowed: String,
    },
    #[error("the mass matrix is not positive definite (a degenerate basis?)")]
    MassMatrix,
    #[error("the eigensolver did not converge")]
    Eigen,
    #[error(
        "the fit of the reduced modes' radiation is singular (no listener or no bridge point?)"
    )]
    RadiationFit,
}

fn check(field: &str, value: f64, lo: f64, hi: f64) -> Result<(), BoardError> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        Err(BoardError::Range {
            field: field.to_owned(),
            value: value.to_string(),
            allowed: format!("a number in [{lo:e}, {hi:e}]"),
        })
    }
}

/// Bending stiffness (N m²) about the plate's mid-plane of a beam of Young's modulus `e_b`, section
/// `width × height` glued on a plate of thickness `h`, working with a plate flange of modulus `e_f`
/// and width `flange`: the T-section with its shifted neutral axis (membrane action of the flange).
fn glued_beam_ei(e_b: f64, width: f64, height: f64, h: f64, e_f: f64, flange: f64) -> f64 {
    let (a_b, a_f) = (width * height, flange * h);
    let offset = 0.5 * (h + height);
    let axial = e_b * a_b * e_f * a_f / (e_b * a_b + e_f * a_f);
    e_b * width * height.powi(3) / 12.0 + axial * offset * offset
}

/// Torsion constant of a solid rectangle (Roark): `J ≈ b t³ (1/3 − 0.21 t/b)`, `b ≥ t`.
fn rectangle_torsion_m4(width: f64, height: f64) -> f64 {
    let (long, short) = (width.max(height), width.min(height));
    long * short.powi(3) * (1.0 / 3.0 - 0.21 * short / long)
}

impl PlateSpec {
    /// In-plane Young's modulus along a direction at `cos`, `sin` to the grain (Pa).
    fn modulus_along(&self, c: f64, s: f64) -> f64 {
        let compliance = c.powi(4) / self.e1_pa
            + s.powi(4) / self.e2_pa
            + (1.0 / self.g12_pa - 2.0 * self.nu12 / self.e1_pa) * s * s * c * c;
        1.0 / compliance
    }
}

/// Point, unit tangent and speed `|dB/dt|` of a quadratic Bézier curve at `t`.
fn bezier(c: &[[f64; 2]; 3], t: f64) -> ([f64; 2], [f64; 2], f64) {
    let u = 1.0 - t;
    let p = [0, 1].map(|d| u * u * c[0][d] + 2.0 * u * t * c[1][d] + t * t * c[2][d]);
    let dp = [0, 1].map(|d| 2.0 * u * (c[1][d] - c[0][d]) + 2.0 * t * (c[2][d] - c[1][d]));
    let speed = dp[0].hypot(dp[1]);
    (p, [dp[0] / speed, dp[1] / speed], speed)
}

/// A point on a curve and the unit tangent there.
type CurvePoint = ([f64; 2], [f64; 2]);

/// `n` points along a Bézier curve at equal arc length, with the tangent there, and the length.
fn arc_points(c: &[[f64; 2]; 3], n: usize) -> (Vec<CurvePoint>, f64) {
    // Cumulative arc length on a fine parameter grid, then inverse interpolation.
    let fine = 4000;
    let mut cum = vec![0.0; fine + 1];
    for k in 1..=fine {
        let (t0, t1) = ((k - 1) as f64 / fine as f64, k as f64 / fine as f64);
        let s = 0.5 * (bezier(c, t0).2 + bezier(c, t1).2) * (t1 - t0);
        cum[k] = cum[k - 1] + s;
    }
    let total = cum[fine];
    let points = (0..n)
        .map(|j| {
            let target = if n == 1 {
                0.5 * total
            } else {
                total * j as f64 / (n - 1) as f64
            };
            let k = cum.partition_point(|&s| s < target).clamp(1, fine);
            let frac = (target - cum[k - 1]) / (cum[k] - cum[k - 1]).max(1e-300);
            let t = ((k - 1) as f64 + frac) / fine as f64;
            let (p, tan, _) = bezier(c, t);
            (p, tan)
        })
        .collect();
    (points, total)
}

/// Trapezoid quadrature along a Bézier curve at about `per_m` points per metre (at least three):
/// each point, its unit tangent and its weight (m).
fn curve_quadrature(c: &[[f64; 2]; 3], per_m: f64) -> Vec<(CurvePoint, f64)> {
    let (_, length) = arc_points(c, 2);
    let count = ((length * per_m).ceil() as usize).max(2);
    let ds = length / count as f64;
    let (pts, _) = arc_points(c, count + 1);
    pts.into_iter()
        .enumerate()
        .map(|(q, p)| (p, if q == 0 || q == count { 0.5 * ds } else { ds }))
        .collect()
}

impl BoardSpec {
    fn validate(&self) -> Result<(), BoardError> {
        let p = &self.plate;
        check("plate.width_m", p.width_m, 0.1, 5.0)?;
        check("plate.length_m", p.length_m, 0.1, 5.0)?;
        check("plate.thickness_m", p.thickness_m, 1e-3, 0.05)?;
        check("plate.density_kg_m3", p.density_kg_m3, 50.0, 3000.0)?;
        check("plate.e1_pa", p.e1_pa, 1e7, 1e12)?;
        check("plate.e2_pa", p.e2_pa, 1e7, 1e12)?;
        check("plate.nu12", p.nu12, 0.0, 0.6)?;
        check("plate.g12_pa", p.g12_pa, 1e6, 1e12)?;
        check("plate.damping_ratio", p.damping_ratio, 0.0, 0.5)?;
        check("basis.terms_x", self.basis.terms_x as f64, 2.0, 80.0)?;
        check("basis.terms_y", self.basis.terms_y as f64, 2.0, 80.0)?;
        check(
            "basis.bridge_points_per_m",
            self.basis.bridge_points_per_m,
            10.0,
            5000.0,
        )?;
        check("reduction.f_min_hz", self.reduction.f_min_hz, 1.0, 1e4)?;
        check(
            "reduction.f_max_hz",
            self.reduction.f_max_hz,
            self.reduction.f_min_hz,
            2e4,
        )?;
        // A point the reduction does not know would keep nothing there, silently.
        let named = |p: &String| (1..=88).any(|k| key_name(k) == *p);
        if self.reduction.points.is_empty() {
            return Err(BoardError::Range {
                field: "reduction.points".to_owned(),
                value: "[]".to_owned(),
                allowed: "at least one key name".to_owned(),
            });
        }
        if let Some(f) = self.reduction.radiation_fit_below_hz {
            check(
                "reduction.radiation_fit_below_hz",
                f,
                self.reduction.f_min_hz,
                self.reduction.f_max_hz,
            )?;
            if self.listeners.is_empty() {
                return Err(BoardError::Range {
                    field: "reduction.radiation_fit_below_hz".to_owned(),
                    value: f.to_string(),
                    allowed: "no value without a [[listeners]] entry".to_owned(),
                });
            }
        }
        if let Some(f) = self.reduction.residual_from_hz {
            let from = self
                .reduction
                .radiation_fit_below_hz
                .unwrap_or(self.reduction.f_min_hz);
            check(
                "reduction.residual_from_hz",
                f,
                from,
                self.reduction.f_max_hz,
            )?;
        }
        if let Some(p) = self.reduction.points.iter().find(|p| !named(p)) {
            return Err(BoardError::Range {
                field: "reduction.points".to_owned(),
                value: p.clone(),
                allowed: "key names A0 … C8 (flats: Bb0, Db1 …)".to_owned(),
            });
        }
        if let Some(r) = &self.ribs {
            check("ribs.count", r.count as f64, 0.0, 100.0)?;
            check("ribs.first_x_m", r.first_x_m, 0.0, p.width_m)?;
            check(
                "ribs.spacing_m",
                r.first_x_m + r.spacing_m * r.count.saturating_sub(1) as f64,
                0.0,
                p.width_m,
            )?;
            check("ribs.width_m", r.width_m, 1e-3, 0.2)?;
            check("ribs.height_m", r.height_m, 1e-3, 0.2)?;
            check("ribs.young_modulus_pa", r.young_modulus_pa, 1e7, 1e12)?;
            check("ribs.shear_modulus_pa", r.shear_modulus_pa, 1e6, 1e12)?;
            check("ribs.density_kg_m3", r.density_kg_m3, 50.0, 3000.0)?;
        }
        for (i, l) in self.listeners.iter().enumerate() {
            let [x, y, z] = l.position_m;
            check("listeners.position_m (x)", x, -10.0, 10.0)?;
            check("listeners.position_m (y)", y, -10.0, 10.0)?;
            check("listeners.position_m (z)", z, 0.05, 10.0)?;
            let plain = !l.name.is_empty()
                && !l
                    .name
                    .contains(|c: char| c.is_whitespace() || c == '@' || c == '#');
            let unique = self.listeners[..i].iter().all(|o| o.name != l.name);
            if !(plain && unique) {
                return Err(BoardError::Range {
                    field: "listeners.name".to_owned(),
                    value: format!("`{}`", l.name),
                    allowed: "a unique name without spaces, `@` or `#`".to_owned(),
                });
            }
        }
        for r in &self.rims {
            for pt in &r.curve_m {
                check("rims.curve_m (x)", pt[0], 0.0, p.width_m)?;
                check("rims.curve_m (y)", pt[1], 0.0, p.length_m)?;
            }
            check("rims.stiffness_n_m2", r.stiffness_n_m2, 0.0, 1e14)?;
            check(
                "rims.rotational_stiffness_n",
                r.rotational_stiffness_n,
                0.0,
                1e11,
            )?;
        }
        for b in &self.bridges {
            for pt in &b.curve_m {
                check("bridges.curve_m (x)", pt[0], 0.0, p.width_m)?;
                check("bridges.curve_m (y)", pt[1], 0.0, p.length_m)?;
            }
            check("bridges.first_key", b.first_key as f64, 1.0, 88.0)?;
            check(
                "bridges.last_key",
                b.last_key as f64,
                b.first_key as f64,
                88.0,
            )?;
            check("bridges.width_m", b.width_m, 1e-3, 0.2)?;
            check("bridges.height_m", b.height_m, 1e-3, 0.2)?;
            check("bridges.young_modulus_pa", b.young_modulus_pa, 1e7, 1e12)?;
            check("bridges.shear_modulus_pa", b.shear_modulus_pa, 1e6, 1e12)?;
            check("bridges.density_kg_m3", b.density_kg_m3, 50.0, 3000.0)?;
            check("bridges.flange_width_m", b.flange_width_m, 0.0, 1.0)?;
        }
        Ok(())
    }

    /// Every key's bridge point, in key order.
    pub fn key_points(&self) -> Vec<KeyPoint> {
        let h = self.plate.thickness_m;
        let mut keys = Vec::new();
        for b in &self.bridges {
            let n = b.last_key - b.first_key + 1;
            let (pts, _) = arc_points(&b.curve_m, n);
            let (s, c) = b.string_angle_deg.to_radians().sin_cos();
            for (j, (p, _)) in pts.into_iter().enumerate() {
                let key = b.first_key + j;
                keys.push(KeyPoint {
                    key,
                    name: key_name(key),
                    x_m: p[0],
                    y_m: p[1],
                    string_dir: [c, s],
                    lever_m: b.height_m + 0.5 * h,
                });
            }
        }
        keys.sort_by_key(|k| k.key);
        keys
    }

    /// Assemble and solve the Ritz model; returns all modes with `f_min ≤ f < f_max` at every key.
    pub fn solve(&self) -> Result<SolvedBoard, BoardError> {
        self.validate()?;
        let p = &self.plate;
        let bx = Basis1d {
            len: p.width_m,
            terms: self.basis.terms_x,
            edges: p.edges,
        };
        let by = Basis1d {
            len: p.length_m,
            terms: self.basis.terms_y,
            edges: p.edges,
        };
        let (nx, ny) = (bx.terms, by.terms);
        let n = nx * ny;
        let idx = |i: usize, j: usize| i * ny + j;
        let (d1, d2, d12, d66) = p.rigidities();
        let rho_h = p.density_kg_m3 * p.thickness_m;
        let [x00, x11, x22, x20] =
            [(0, 0), (1, 1), (2, 2), (2, 0)].map(|(a, b)| bx.integrals(a, b));
        let [y00, y11, y22, y20] =
            [(0, 0), (1, 1), (2, 2), (2, 0)].map(|(a, b)| by.integrals(a, b));
        let mut k = Mat::<f64>::zeros(n, n);
        let mut m = Mat::<f64>::zeros(n, n);
        // Ribs: along y at x = x_r, their values and slopes in x at the rib line.
        let rib_lines: Vec<(f64, f64, f64, Vec<[f64; 3]>)> = match &self.ribs {
            Some(r) => {
                let ei = glued_beam_ei(
                    r.young_modulus_pa,
                    r.width_m,
                    r.height_m,
                    p.thickness_m,
                    p.e2_pa,
                    r.spacing_m,
                );
                let gj = r.shear_modulus_pa * rectangle_torsion_m4(r.width_m, r.height_m);
                let rho_a = r.density_kg_m3 * r.width_m * r.height_m;
                (0..r.count)
                    .map(|c| {
                        let xr = r.first_x_m + c as f64 * r.spacing_m;
                        (ei, gj, rho_a, bx.at(xr))
                    })
                    .collect()
            }
            None => Vec::new(),
        };
        for i in 0..nx {
            for a in 0..nx {
                let (xi0, xi1, xi2) = (x00[i * nx + a], x11[i * nx + a], x22[i * nx + a]);
                let (x20_ia, x02_ia) = (x20[i * nx + a], x20[a * nx + i]);
                let (mut rib_b, mut rib_t, mut rib_m) = (0.0, 0.0, 0.0);
                for (ei, gj, rho_a, vals) in &rib_lines {
                    rib_b += ei * vals[i][0] * vals[a][0];
                    rib_t += gj * vals[i][1] * vals[a][1];
                    rib_m += rho_a * vals[i][0] * vals[a][0];
                }
                for j in 0..ny {
                    for b in 0..ny {
                        let (yj0, yj1, yj2) = (y00[j * ny + b], y11[j * ny + b], y22[j * ny + b]);
                        let (y20_jb, y02_jb) = (y20[j * ny + b], y20[b * ny + j]);
                        let kv = d1 * xi2 * yj0
                            + d2 * xi0 * yj2
                            + d12 * (x20_ia * y02_jb + x02_ia * y20_jb)
                            + 4.0 * d66 * xi1 * yj1
                            + rib_b * yj2
                            + rib_t * yj1;
                        k[(idx(i, j), idx(a, b))] = kv;
                        m[(idx(i, j), idx(a, b))] = rho_h * xi0 * yj0 + rib_m * yj0;
                    }
                }
            }
        }
        // Bridges: quadrature along each curve.
        for br in &self.bridges {
            let pts = curve_quadrature(&br.curve_m, self.basis.bridge_points_per_m);
            let gj = br.shear_modulus_pa * rectangle_torsion_m4(br.width_m, br.height_m);
            let rho_a = br.density_kg_m3 * br.width_m * br.height_m;
            // Columns: basis values, bending curvature and twist at each point, scaled by sqrt(weight).
            let np = pts.len();
            let mut g_mass = Mat::<f64>::zeros(n, np);
            let mut g_bend = Mat::<f64>::zeros(n, np);
            let mut g_twist = Mat::<f64>::zeros(n, np);
            for (q, &((pt, t), w)) in pts.iter().enumerate() {
                let (xs, ys) = (bx.at(pt[0]), by.at(pt[1]));
                let (tx, ty) = (t[0], t[1]);
                let e_f = p.modulus_along(tx, ty);
                let ei = glued_beam_ei(
                    br.young_modulus_pa,
                    br.width_m,
                    br.height_m,
                    p.thickness_m,
                    e_f,
                    br.flange_width_m,
                );
                for i in 0..nx {
                    for j in 0..ny {
                        let (w0, wx, wxx) = (xs[i][0], xs[i][1], xs[i][2]);
                        let (v0, vy, vyy) = (ys[j][0], ys[j][1], ys[j][2]);
                        let (f, fxx, fyy, fxy) = (w0 * v0, wxx * v0, w0 * vyy, wx * vy);
                        let bend = tx * tx * fxx + 2.0 * tx * ty * fxy + ty * ty * fyy;
                        let twist = -tx * ty * fxx + (tx * tx - ty * ty) * fxy + tx * ty * fyy;
                        let r = idx(i, j);
                        g_mass[(r, q)] = (rho_a * w).sqrt() * f;
                        g_bend[(r, q)] = (ei * w).sqrt() * bend;
                        g_twist[(r, q)] = (gj * w).sqrt() * twist;
                    }
                }
            }
            m += &g_mass * g_mass.transpose();
            k += &g_bend * g_bend.transpose();
            k += &g_twist * g_twist.transpose();
        }
        for rim in &self.rims {
            let pts = curve_quadrature(&rim.curve_m, self.basis.bridge_points_per_m);
            let np = pts.len();
            let mut g_pin = Mat::<f64>::zeros(n, np);
            let mut g_rot = Mat::<f64>::zeros(n, np);
            for (q, &((pt, t), w)) in pts.iter().enumerate() {
                let (xs, ys) = (bx.at(pt[0]), by.at(pt[1]));
                let (tx, ty) = (t[0], t[1]);
                for i in 0..nx {
                    for j in 0..ny {
                        let (f, fx, fy) = (
                            xs[i][0] * ys[j][0],
                            xs[i][1] * ys[j][0],
                            xs[i][0] * ys[j][1],
                        );
                        let r = idx(i, j);
                        g_pin[(r, q)] = (rim.stiffness_n_m2 * w).sqrt() * f;
                        g_rot[(r, q)] =
                            (rim.rotational_stiffness_n * w).sqrt() * (-ty * fx + tx * fy);
                    }
                }
            }
            k += &g_pin * g_pin.transpose();
            k += &g_rot * g_rot.transpose();
        }
        // K c = w² M c  →  (L⁻¹ K L⁻ᵀ) y = w² y,  c = L⁻ᵀ y.
        let llt = m.llt(Side::Lower).map_err(|_| BoardError::MassMatrix)?;
        // `m` stays for the caller's checks; the factor is all the solve needs.
        let l = llt.L();
        let mut a = k;
        l.solve_lower_triangular_in_place(&mut a);
        let mut a = a.transpose().to_owned();
        l.solve_lower_triangular_in_place(&mut a);
        let evd = a
            .self_adjoint_eigen(Side::Lower)
            .map_err(|_| BoardError::Eigen)?;
        let eig = evd.S().column_vector();
        let mut c = evd.U().to_owned();
        l.transpose().solve_upper_triangular_in_place(&mut c);

        let keys = self.key_points();
        let mean_x = bx.means();
        let mean_y = by.means();
        // Per key: the 1-D basis values and derivatives along x and along y.
        type KeyBasis = (Vec<[f64; 3]>, Vec<[f64; 3]>);
        let key_basis: Vec<KeyBasis> = keys
            .iter()
            .map(|kp| (bx.at(kp.x_m), by.at(kp.y_m)))
            .collect();
        let mut modes = SoundboardModes {
            freq_hz: vec![],
            damping_ratio: vec![],
            volume_m2_per_sqrt_kg: vec![],
            points: keys
                .iter()
                .map(|kp| BridgePoint {
                    name: kp.name.clone(),
                    shape: [vec![], vec![], vec![]],
                })
                .collect(),
            listeners: vec![],
            heard: [None; 2],
            residual: None,
        };
        let mut kept: Vec<(usize, f64)> = Vec::new();
        for mode in 0..n {
            let f = eig[mode].max(0.0).sqrt() / (2.0 * PI);
            if f >= self.reduction.f_max_hz {
                break;
            }
            if f < self.reduction.f_min_hz {
                continue;
            }
            // Sign: the largest coefficient positive (eigenvectors are defined up to sign).
            let col = c.col(mode);
            let big = (0..n)
                .max_by(|&u, &v| col[u].abs().total_cmp(&col[v].abs()))
                .unwrap_or(0);
            let sign = if col[big] < 0.0 { -1.0 } else { 1.0 };
            let coef = |i: usize, j: usize| sign * col[idx(i, j)];
            kept.push((mode, sign));
            modes.freq_hz.push(f);
            modes.damping_ratio.push(p.damping_ratio);
            let mut volume = 0.0;
            for i in 0..nx {
                for j in 0..ny {
                    volume += coef(i, j) * mean_x[i] * mean_y[j];
                }
            }
            modes.volume_m2_per_sqrt_kg.push(volume);
            for ((kp, (xs, ys)), point) in keys.iter().zip(&key_basis).zip(modes.points.iter_mut())
            {
                let (mut w, mut wx, mut wy) = (0.0, 0.0, 0.0);
                for i in 0..nx {
                    for j in 0..ny {
                        let cij = coef(i, j);
                        w += cij * xs[i][0] * ys[j][0];
                        wx += cij * xs[i][1] * ys[j][0];
                        wy += cij * xs[i][0] * ys[j][1];
                    }
                }
                let [sx, sy] = kp.string_dir;
                point.shape[0].push(w);
                point.shape[1].push(-kp.lever_m * (sx * wx + sy * wy));
                point.shape[2].push(-kp.lever_m * (-sy * wx + sx * wy));
            }
        }
        let coefficients = Mat::from_fn(n, kept.len(), |r, k| kept[k].1 * c[(r, kept[k].0)]);
        Ok(SolvedBoard {
            modes,
            keys,
            basis_size: n,
            mass_matrix: m,
            coefficients,
        })
    }
}

/// The paper's reduction (§2.2): in each 1/12-octave band from `f_min_hz` to `f_max_hz` and in each
/// direction, keep the mode whose driving-point peak `phi_d^2 / (2 zeta omega)` is the largest at
/// any of `points`. Modes chosen several times are kept once.
pub fn reduce(
    full: &SoundboardModes,
    points: &[&str],
    f_min_hz: f64,
    f_max_hz: f64,
) -> SoundboardModes {
    kept_only(full, &kept_modes(full, points, f_min_hz, f_max_hz))
}

/// `full` with its modes `kept` (ascending) alone.
fn kept_only(full: &SoundboardModes, kept: &[usize]) -> SoundboardModes {
    let mut reduced = full.clone();
    reduced.retain(|k| kept.binary_search(&k).is_ok());
    reduced
}

/// The modes [`reduce`] keeps, ascending.
pub fn kept_modes(
    full: &SoundboardModes,
    points: &[&str],
    f_min_hz: f64,
    f_max_hz: f64,
) -> Vec<usize> {
    let n_bands = (12.0 * (f_max_hz / f_min_hz).log2()).ceil() as usize;
    let mut keep = vec![false; full.len()];
    for p in points.iter().filter_map(|name| full.point(name)) {
        for band in 0..n_bands {
            let lo = f_min_hz * 2f64.powf(band as f64 / 12.0);
            let hi = (f_min_hz * 2f64.powf((band + 1) as f64 / 12.0)).min(f_max_hz);
            for d in 0..3 {
                let peak =
                    |k: usize| p.shape[d][k].powi(2) / (full.damping_ratio[k] * full.freq_hz[k]);
                let best = (0..full.len())
                    .filter(|&k| full.freq_hz[k] >= lo && full.freq_hz[k] < hi)
                    .max_by(|&i, &j| peak(i).total_cmp(&peak(j)));
                if let Some(k) = best {
                    keep[k] = true;
                }
            }
        }
    }
    (0..full.len()).filter(|&k| keep[k]).collect()
}

/// Solve and reduce the board, with the header lines that say how the asset was made (the text
/// itself is `config::asset::to_text`).
pub fn generate_asset(
    spec: &BoardSpec,
    command: &str,
) -> Result<(SolvedBoard, SoundboardModes, Vec<String>), BoardError> {
    let mut solved = spec.solve()?;
    radiation::listen(spec, &mut solved);
    let r = &spec.reduction;
    let points: Vec<&str> = r.points.iter().map(String::as_str).collect();
    let kept = kept_modes(&solved.modes, &points, r.f_min_hz, r.f_max_hz);
    let mut reduced = kept_only(&solved.modes, &kept);
    if let Some(below_hz) = r.radiation_fit_below_hz {
        reduced.listeners = equivalent::fit(&solved.modes, &kept, below_hz)?;
    }
    if let Some(from_hz) = r.residual_from_hz {
        let full = &solved.modes;
        let mut dropped = full.clone();
        dropped.retain(|k| kept.binary_search(&k).is_err() && full.freq_hz[k] >= from_hz);
        reduced.residual = Some(std::sync::Arc::new(dropped));
    }
    let p = &spec.plate;
    let mut header = vec![
        "unacorda reduced soundboard model (DESIGN.md §1.3, §4; format in src/config/asset.rs)".to_string(),
        format!("regenerate with: {command}"),
        format!(
            "{:?} orthotropic plate {} m x {} m x {} m, rho {} kg/m^3, E1 {:.3e} Pa, E2 {:.3e} Pa, nu12 {}, G12 {:.3e} Pa",
            p.edges, p.width_m, p.length_m, p.thickness_m, p.density_kg_m3, p.e1_pa, p.e2_pa, p.nu12, p.g12_pa
        ),
    ];
    if let Some(rb) = &spec.ribs {
        header.push(format!(
            "{} ribs across the grain from x = {} m every {} m, {} m x {} m",
            rb.count, rb.first_x_m, rb.spacing_m, rb.width_m, rb.height_m
        ));
    }
    for b in &spec.bridges {
        header.push(format!(
            "bridge {}: keys {}-{} ({}-{}), {} m x {} m, strings at {} deg to the grain",
            b.name,
            b.first_key,
            b.last_key,
            key_name(b.first_key),
            key_name(b.last_key),
            b.width_m,
            b.height_m,
            b.string_angle_deg
        ));
    }
    for rim in &spec.rims {
        header.push(format!(
            "rim along {:?} m, held by {:e} N/m^2 on the deflection and {:e} N on the slope",
            rim.curve_m, rim.stiffness_n_m2, rim.rotational_stiffness_n
        ));
    }
    header.push(format!(
        "Ritz basis {} functions; {} modes in {}-{} Hz reduced to {} (dominant mode per 1/12 octave and direction at {})",
        solved.basis_size,
        solved.modes.len(),
        r.f_min_hz,
        r.f_max_hz,
        reduced.len(),
        r.points.join(", ")
    ));
    if !spec.listeners.is_empty() {
        let at: Vec<String> = spec
            .listeners
            .iter()
            .map(|l| format!("{} at {:?} m", l.name, l.position_m))
            .collect();
        header.push(format!(
            "listeners (Rayleigh integral of each mode at its frequency, {} m grid, c = {} m/s): {}",
            radiation::GRID_SPACING_M,
            radiation::SOUND_SPEED_M_S,
            at.join(", ")
        ));
    }
    if let Some(below_hz) = r.radiation_fit_below_hz {
        header.push(format!(
            "kept modes below {below_hz} Hz radiate what the full board's modes radiate for forces at the bridges (least squares over frequency and every key, src/board/equivalent.rs); above, each by its own Rayleigh integral"
        ));
    }
    if let (Some(from_hz), Some(dropped)) = (r.residual_from_hz, &reduced.residual) {
        header.push(format!(
            "residual: the {} modes dropped from {from_hz} Hz up, heard (driven by each key's bridge force, radiated by their own integrals) and not coupled (src/engine/physics/soundboard.rs, DroppedModes)",
            dropped.len()
        ));
    }
    Ok((solved, reduced, header))
}
