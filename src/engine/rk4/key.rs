//! One key's coefficients for the RK4 pool: its strings' modes (Eq. 2–3), bridge and hammer
//! shapes, static deflection, duplex factor (Eq. 13), hammer, damper and contact; built once per
//! key, copied into a voice's slot when it plays the key.

use crate::engine::kernels::Real;
use crate::engine::physics::contact::Contact;
use crate::engine::physics::damper::DamperParams;
use crate::engine::physics::duplex::{duplex_damping_matrix, low_rank_factor};
use crate::engine::physics::hammer::HammerParams;
use crate::engine::physics::string::ModeSet;
use crate::engine::spec::Direction;
use crate::engine::spec::{BuildError, UnisonSpec, MAX_STRINGS};
use std::f64::consts::PI;
use std::ops::Range;

/// Coefficients of one key: its strings' modes (laid out from 0), hammer, damper and bridge point.
/// Built once ([`Rk4Pool::prepare_key`]); a voice playing the key copies the per-mode arrays
/// into its own slot.
#[derive(Debug, Clone)]
pub struct Rk4Key<T> {
    pub(super) n_strings: usize,
    /// `ranges[s][d]`: modes of string `s` in direction `d` (T, L, P), from the key's first mode.
    pub(super) ranges: [[Range<usize>; 3]; MAX_STRINGS],
    pub(super) n_modes: usize,
    pub(super) omega2: Vec<T>,
    pub(super) damp: Vec<T>,
    pub(super) bridge_shape: Vec<T>,
    /// Each string direction's static deflection per unit displacement of its bridge point, `g`
    /// with `(Omega^2 + k psi psi^T) g = k psi`: where a string at rest on a moving board is.
    pub(super) static_shape: Vec<T>,
    /// Board modes: `phi_T`, `phi_L`, `phi_P` at this key's bridge point (Eq. 5).
    pub(super) board_shape: [Vec<T>; 3],
    /// The board's dropped modes at the point (`UnisonSpec::dropped`): driven, not coupled; empty
    /// without them.
    pub(super) residual_shape: [Vec<T>; 3],
    /// `psi_n(L_e)` of the T modes (identical for every string: same length).
    pub(super) hammer_shape: Vec<T>,
    /// Per point of the damper felt, `a_k psi_n(x_k)` of the transverse modes
    /// ([`crate::engine::physics::damper::DamperParams::felt_points`]), and the felt's coefficient (N s/m); empty without damper.
    pub(super) damper_shapes: Vec<Vec<T>>,
    pub(super) damper_n_s_m: f64,
    /// The felt's parameters (its travel: [`DamperParams::contact_share`]); none without damper.
    pub(super) damper: Option<DamperParams>,
    /// The duplex matrix (Eq. 13) as `C_d = Wᵀ W`: `W` is `duplex_rank × duplex_n`, row-major.
    pub(super) duplex_w: Vec<T>,
    pub(super) duplex_n: usize,
    pub(super) duplex_rank: usize,
    pub(super) hammer: HammerParams,
    pub(super) contact: Contact,
}

/// One key's coefficients, its modes laid out from 0.
pub(super) fn build_key<T: Real>(spec: &UnisonSpec) -> Result<Rk4Key<T>, BuildError> {
    let ns = spec.string_count()?;
    let point = spec.bridge()?;
    let ModeSet {
        modes_t: nt,
        modes_p: np,
        modes_l: nl,
        ..
    } = spec.modes;
    let per_string = nt + np + nl;
    let n_modes = ns * per_string;
    let (mut omega2, mut damp, mut bridge_shape) =
        (vec![0.0; n_modes], vec![0.0; n_modes], vec![0.0; n_modes]);
    let mut ranges: [[Range<usize>; 3]; MAX_STRINGS] = Default::default();
    for (s, string) in spec.strings.iter().enumerate() {
        let b = s * per_string;
        // Flat layout [T | P | L]; direction index d is T = 0, L = 1, P = 2.
        ranges[s] = [b..b + nt, b + nt + np..b + per_string, b + nt..b + nt + np];
        let ls = string.speaking_length_m;
        for dir in Direction::ALL {
            for (k, i) in ranges[s][dir.index()].clone().enumerate() {
                let mode = string.oscillator(dir, k + 1, &spec.modes);
                omega2[i] = mode.omega2();
                damp[i] = mode.damping_per_s();
                bridge_shape[i] = string.mode_shape(k + 1, ls);
            }
        }
    }
    // `g = k Omega^-2 psi / (1 + k psi^T Omega^-2 psi)` per string direction (Sherman–Morrison).
    let mut static_shape = vec![0.0; n_modes];
    for ranges in &ranges[..ns] {
        for (d, r) in ranges.iter().enumerate() {
            let k = spec.contact.stiffness_n_m[d];
            let compliance: f64 = r.clone().map(|i| bridge_shape[i].powi(2) / omega2[i]).sum();
            for i in r.clone() {
                static_shape[i] = k * bridge_shape[i] / omega2[i] / (1.0 + k * compliance);
            }
        }
    }
    let s0 = &spec.strings[0];
    let strike_x = spec.hammer.strike_ratio * s0.speaking_length_m;
    let (damper_shapes, damper_n_s_m) = match spec.damper {
        Some(d) => {
            let (points, count) = d.felt_points(s0.speaking_length_m);
            let shapes = points[..count]
                .iter()
                .map(|&(x, a)| {
                    let shape: Vec<f64> =
                        (1..=nt.max(np)).map(|k| a * s0.mode_shape(k, x)).collect();
                    cast(&shape)
                })
                .collect();
            (shapes, d.damping_n_s_m)
        }
        None => (Vec::new(), 0.0),
    };
    let duplex_n = nt.max(np);
    let (duplex_w, duplex_rank) = low_rank_factor(
        &duplex_damping_matrix(
            duplex_n,
            s0.length_m(),
            s0.speaking_length_m,
            spec.duplex_damping_n_s_m2,
            s0.linear_density_kg_m,
        ),
        duplex_n,
    )
    .ok_or(BuildError::Duplex)?;
    // The stiffest coupled mode: a string's bridge point on its contact spring, with the
    // effective point mass of the retained modes, 1 / sum psi_n(L_s)^2 (DESIGN.md §5).
    let h = 1.0 / spec.sample_rate_hz;
    let inv_mass: f64 = ranges[0][0].clone().map(|i| bridge_shape[i].powi(2)).sum();
    let k_max = spec
        .contact
        .stiffness_n_m
        .iter()
        .copied()
        .fold(0.0, f64::max);
    let w_top = omega2.iter().copied().fold(0.0, f64::max);
    let w_contact = (k_max * inv_mass + w_top).sqrt();
    if w_contact * h > 2.78 {
        return Err(BuildError::Unstable {
            freq_hz: w_contact / (2.0 * PI),
            omega_h: w_contact * h,
            rate_hz: spec.sample_rate_hz,
        });
    }
    Ok(Rk4Key {
        n_strings: ns,
        ranges,
        n_modes,
        omega2: cast(&omega2),
        damp: cast(&damp),
        bridge_shape: cast(&bridge_shape),
        static_shape: cast(&static_shape),
        board_shape: point.shape.each_ref().map(|phi| cast(phi)),
        residual_shape: match &spec.dropped {
            Some(d) => d.shape.each_ref().map(|phi| cast(phi)),
            None => Default::default(),
        },
        hammer_shape: (1..=nt)
            .map(|k| T::from_f64(s0.mode_shape(k, strike_x)))
            .collect(),
        damper_shapes,
        damper_n_s_m,
        damper: spec.damper,
        duplex_w: cast(&duplex_w),
        duplex_n,
        duplex_rank,
        hammer: spec.hammer,
        contact: spec.contact,
    })
}

/// `f64` coefficients in the engine's precision.
pub(super) fn cast<T: Real>(x: &[f64]) -> Vec<T> {
    x.iter().map(|&v| T::from_f64(v)).collect()
}
