//! One key's coefficients for the live integrator: its string directions in complex modes with
//! their ports and inputs, in coordinates relative to the static deflection by the bridge
//! ([`Statics`]).

use crate::engine::modal::*;
use crate::engine::physics::contact::Contact;
use crate::engine::physics::duplex::duplex_damping_matrix;
use crate::engine::physics::hammer::HammerParams;
use crate::engine::spec::Direction;
use crate::engine::spec::{BuildError, UnisonSpec, MAX_STRINGS};
use faer::c64;

/// A string direction's coefficients with its ports, in the coordinates `q^ = q - g y` relative
/// to the string's static deflection `g y` by the bridge (see [`Statics`]): rows `psi.q^` at the
/// bridge, `psi(L_e).q^` at the strike point (T only), `psi.q^dot` at the bridge, `psi(x_d).q^dot`
/// at the damper (T and P); inputs ([`INPUTS`]) the bridge's velocity and acceleration, the felt
/// (T only), the damper felt and the fade of a stolen voice's contact, in that order.
#[derive(Debug, Clone)]
pub(super) struct Block {
    /// Stored modes (the arrays below are padded to whole SIMD lanes beyond it with zeros).
    pub(super) modes: usize,
    /// `e^{lambda h}`.
    pub(super) e_full: [Vec<f64>; 2],
    /// Per output: the row `r`, `r E`, `r E²` (re, im), weights folded in.
    pub(super) rows: Vec<[[Vec<f64>; 2]; 3]>,
    /// Per input: `f1 g`, `f2 g`, `f3 g` (re, im), the ETDRK4 weights of the final update.
    pub(super) gains: Vec<[[Vec<f64>; 2]; 3]>,
    /// `resp[o][j]`: what one unit of input `j` adds to output `o` at the later stages.
    pub(super) resp: Vec<Vec<[f64; 2]>>,
    /// Energy per `|z|²` of each stored mode (J).
    pub(super) energy: Vec<f64>,
    /// The row `g.q^dot` (the energy's cross term between the deflection and the motion).
    pub(super) g_row: [Vec<f64>; 2],
    pub(super) statics: Statics,
}

/// A string direction's static deflection by its bridge point: when the bridge moves by `y`, the
/// string on its contact spring (stiffness `K = Omega^2 + k psi psi^T`) comes to rest at `g y`,
/// `K g = k psi` — at low frequencies its end follows the board almost entirely. The live
/// integrator advances `q^ = q - g y`, in which the contact spring's pull `k psi y` and the
/// string's return `K g y` cancel exactly, so that the board coupling left explicit is small: the
/// net stiffness `k (1 - psi.g) = k / (1 + k psi^T Omega^-2 psi)` (the contact spring in series
/// with the string, ~1/1000 of `k` at C2), the string's mass moving with the bridge (`-g y''`) and
/// the damping of that motion (`-C_0 g y'`, `C_0` the modal and duplex damping). In `q` itself the
/// board felt `k` per string explicitly, nearly cancelled by the string's response within the
/// step, and ETDRK4's error on those two large terms undamped the board's modes
/// (docs/robustness.md).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Statics {
    /// `psi.g` at the bridge, `psi(L_e).g` at the strike point, `psi(x_d).g` at the damper.
    pub(super) bridge: f64,
    pub(super) strike: f64,
    pub(super) damper: f64,
    /// `g.g` (kg): the string's mass moving with the bridge.
    pub(super) mass_kg: f64,
}

pub(super) const BRIDGE_Q: usize = 0;
pub(super) const STRIKE_Q: usize = 1;
pub(super) const BRIDGE_V: usize = 2;
pub(super) const DAMPER_V: usize = 3;

/// Inputs of a block (force distributions on `q^dd`, with their stage values): the bridge's
/// velocity `y'` through `c (1 - psi.g) psi - C_0 g` (the contact damper's net part and the
/// damping of the deflection's motion), its acceleration `-y''` through `g`, the felt (`psi(L_e)`,
/// T only), the damper felt (`psi(x_d)`), and while a stolen voice fades with coupling `c_f < 1`,
/// `(1 - c_f) (k (psi.q^ - (1 - psi.g) y) + c (psi.q^dot - (1 - psi.g) y'))` through `psi` (the
/// contact the linear part holds but the fade takes away).
pub(super) const INPUTS: usize = 5;
pub(super) const IN_VEL: usize = 0;
pub(super) const IN_ACCEL: usize = 1;
pub(super) const IN_FELT: usize = 2;
pub(super) const IN_DAMPER: usize = 3;
pub(super) const IN_FADE: usize = 4;

/// One key's coefficients: its string directions in complex modes, and the board's mode shapes
/// at its bridge point.
#[derive(Debug, Clone)]
pub(super) struct EtdKey {
    pub(super) strings: Vec<[Block; 3]>,
    pub(super) contact: Contact,
    pub(super) hammer: HammerParams,
    pub(super) has_damper: bool,
    pub(super) damper_n_s_m: f64,
    /// `phi_T`, `phi_L`, `phi_P` of the board at this key's point (Eq. 5).
    pub(super) board_shape: [Vec<f64>; 3],
    /// Per block (zero where the key has no such string): contact stiffness and damping, the
    /// damper felt's damping (T and P of a damped key), the static deflection's values
    /// ([`Statics`]: `psi.g` at the bridge, strike point and damper), and `resp[o][j][kind]`, what
    /// one unit of input `j` adds to output `o` at the later stages (see [`ETDRK4_STAGES`]).
    pub(super) lane_k: Lanes,
    pub(super) lane_c: Lanes,
    pub(super) lane_damper: Lanes,
    pub(super) lane_through: Lanes,
    pub(super) lane_strike: Lanes,
    pub(super) lane_damper_g: Lanes,
    pub(super) resp: [[[Lanes; 2]; INPUTS]; 4],
}

impl EtdKey {
    pub(super) fn new(
        strings: Vec<[Block; 3]>,
        spec: &UnisonSpec,
        board_shape: &[Vec<f64>; 3],
    ) -> EtdKey {
        let mut key = EtdKey {
            contact: spec.contact,
            hammer: spec.hammer,
            has_damper: spec.damper.is_some(),
            damper_n_s_m: spec.damper.map_or(0.0, |d| d.damping_n_s_m),
            board_shape: board_shape.clone(),
            lane_k: [0.0; BLOCKS],
            lane_c: [0.0; BLOCKS],
            lane_damper: [0.0; BLOCKS],
            lane_through: [0.0; BLOCKS],
            lane_strike: [0.0; BLOCKS],
            lane_damper_g: [0.0; BLOCKS],
            resp: [[[[0.0; BLOCKS]; 2]; INPUTS]; 4],
            strings,
        };
        for (s, blocks) in key.strings.iter().enumerate() {
            for (d, block) in blocks.iter().enumerate() {
                let b = 3 * s + d;
                key.lane_k[b] = key.contact.stiffness_n_m[d];
                key.lane_c[b] = key.contact.damping_n_s_m[d];
                if Direction::ALL[d].is_transverse() {
                    key.lane_damper[b] = key.damper_n_s_m;
                }
                key.lane_through[b] = block.statics.bridge;
                key.lane_strike[b] = block.statics.strike;
                key.lane_damper_g[b] = block.statics.damper;
                for (o, resp) in block.resp.iter().enumerate() {
                    for (j, r) in resp.iter().enumerate() {
                        key.resp[o][j][0][b] = r[0];
                        key.resp[o][j][1][b] = r[1];
                    }
                }
            }
        }
        key
    }
}

/// One key's string blocks, prepared ([`EtdPool::prepare_key`]) and waiting to be
/// placed on the board.
#[derive(Debug, Clone)]
pub struct PreparedKey(pub(super) Vec<[Block; 3]>);

/// Build one key's string blocks (the board's rows and inputs are added by the instrument).
pub(super) fn key_strings(spec: &UnisonSpec, h: f64) -> Result<Vec<[Block; 3]>, BuildError> {
    let ns = spec.strings.len();
    if ns == 0 || ns > MAX_STRINGS {
        return Err(BuildError::StringCount(ns));
    }
    let m = &spec.modes;
    let s0 = &spec.strings[0];
    let strike_x = spec.hammer.strike_ratio * s0.speaking_length_m;
    let damper_x = spec.damper.map(|d| d.position_ratio * s0.speaking_length_m);
    let mut strings = Vec::with_capacity(ns);
    for string in &spec.strings {
        let ls = string.speaking_length_m;
        let nd = m.modes_t.max(m.modes_p);
        let duplex = duplex_damping_matrix(
            nd,
            string.length_m(),
            ls,
            spec.duplex_damping_n_s_m2,
            string.linear_density_kg_m,
        );
        let mut blocks = Vec::with_capacity(3);
        for dir in Direction::ALL {
            let (d, n, transverse) = (dir.index(), m.count(dir), dir.is_transverse());
            let mode = |k: usize| string.oscillator(dir, k + 1, m);
            let psi: Vec<f64> = (0..n).map(|k| string.mode_shape(k + 1, ls)).collect();
            let (kc, cc) = (spec.contact.stiffness_n_m[d], spec.contact.damping_n_s_m[d]);
            let mut kk = vec![0.0; n * n];
            let mut ck = vec![0.0; n * n];
            for i in 0..n {
                for j in 0..n {
                    kk[i * n + j] = kc * psi[i] * psi[j];
                    ck[i * n + j] =
                        cc * psi[i] * psi[j] + if transverse { duplex[i * nd + j] } else { 0.0 };
                }
                kk[i * n + i] += mode(i).omega2();
                ck[i * n + i] += mode(i).damping_per_s();
            }
            // Uniform ports, zero where a direction has no hammer or no damper.
            let at = |x: Option<f64>| -> Vec<f64> {
                match x {
                    Some(x) => (0..n).map(|k| string.mode_shape(k + 1, x)).collect(),
                    None => vec![0.0; n],
                }
            };
            let hammer = at(dir.is_struck().then_some(strike_x));
            let damper = at(damper_x.filter(|_| transverse));
            // The static deflection `K g = k psi` (Sherman–Morrison on `K = Omega^2 + k psi psi^T`)
            // and `C_0 g`, `C_0` the damping without the contact damper.
            let flex: Vec<f64> = (0..n).map(|i| psi[i] / mode(i).omega2()).collect();
            let compliance: f64 = (0..n).map(|i| psi[i] * flex[i]).sum();
            let g: Vec<f64> = flex
                .iter()
                .map(|f| kc * f / (1.0 + kc * compliance))
                .collect();
            let dot = |a: &[f64], b: &[f64]| -> f64 { a.iter().zip(b).map(|(x, y)| x * y).sum() };
            let through = dot(&psi, &g);
            // `c (1 - psi.g) psi - C_0 g` = `c psi - C g` with `C` the whole damping.
            let vel: Vec<f64> = (0..n)
                .map(|i| cc * psi[i] - dot(&ck[i * n..(i + 1) * n], &g))
                .collect();
            let statics = Statics {
                bridge: through,
                strike: dot(&hammer, &g),
                damper: dot(&damper, &g),
                mass_kg: dot(&g, &g),
            };
            let modal = Modal::new(&kk, &ck, n, h)?;
            let rows = [
                modal.row(&psi, false),
                modal.row(&hammer, false),
                modal.row(&psi, true),
                modal.row(&damper, true),
            ];
            let inputs: [Vec<c64>; INPUTS] = [
                modal.input(&vel),
                modal.input(&g),
                modal.input(&hammer),
                modal.input(&damper),
                modal.input(&psi),
            ];
            blocks.push(Block {
                modes: modal.keep.len(),
                g_row: modal.split(&modal.row(&g, true)),
                statics,
                e_full: modal.propagator(),
                rows: rows.iter().map(|r| modal.rows3(r)).collect(),
                gains: inputs.iter().map(|g| modal.gains3(g)).collect(),
                resp: rows
                    .iter()
                    .map(|r| inputs.iter().map(|g| modal.resp(r, g)).collect())
                    .collect(),
                energy: modal.energy(&kk),
            });
        }
        let [t, l, p]: [Block; 3] = blocks.try_into().expect("three directions");
        strings.push([t, l, p]);
    }
    Ok(strings)
}

/// Blocks of one voice, `b = 3 s + d` for string `s` and direction `d` (T = 0, L = 1, P = 2): the
/// per-stage glue (outputs, contact forces, inputs) runs lane-wise over all of them at once.
pub(super) const BLOCKS: usize = MAX_STRINGS * 3;
pub(super) type Lanes = [f64; BLOCKS];
