//! The voices and their ETDRK4 stages: each voice's state and working values, the lane-wise
//! stage over its string blocks, and the step's end (hammers, strings, fades).

use super::board::*;
use super::kernels::*;
use super::keys::*;
use crate::engine::physics::contact::spring_damper_n;
use crate::engine::pool::{fade_step, VoiceState};
use crate::engine::spec::Direction;
use crate::engine::spec::MAX_STRINGS;

/// Per stage: the row read from the start state (0: `r`, 1: `r E`, 2: `r E²`) and the terms
/// `(earlier stage, response kind (0: `r Q g`, 1: `r (E - 1) Q g`), coefficient)` (see the
/// module's notes).
pub(super) type StagePlan = (usize, [(usize, usize, f64); 2]);
pub(super) const ETDRK4_STAGES: [StagePlan; 4] = [
    (0, [(0, 0, 0.0), (0, 0, 0.0)]),
    (1, [(0, 0, 1.0), (0, 0, 0.0)]),
    (1, [(1, 0, 1.0), (0, 0, 0.0)]),
    (2, [(0, 1, 1.0), (1, 0, 2.0)]),
];

/// One voice of the pool: the state of the key it plays.
#[derive(Debug, Clone)]
pub(super) struct Voice {
    /// The policy's state (`engine::pool`), read and moved along by the step.
    pub(super) state: VoiceState,
    pub(super) z: [[ComplexState; 3]; MAX_STRINGS],
    pub(super) hammer_y: f64,
    pub(super) hammer_v: f64,
}

/// A voice's working values within one step (kept between steps only to avoid allocation).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Work {
    /// `start[o][which][b]`: output `o` of block `b` through row `which` (`r`, `r E`, `r E²`) of
    /// the step's starting modes.
    pub(super) start: [[Lanes; 3]; 4],
    /// `u[p][j][b]`: input `j` ([`INPUTS`]) of block `b` at stage `p`.
    pub(super) u: [[Lanes; INPUTS]; 4],
    pub(super) hammer_acc: [f64; 4],
}

/// Voices with their working values, and which of them are simulated.
#[derive(Debug, Clone)]
pub(super) struct VoiceSet {
    pub(super) voices: Vec<Voice>,
    pub(super) work: Vec<Work>,
    pub(super) live: Vec<usize>,
}

impl VoiceSet {
    /// Every row each live voice reads from the step's start.
    #[inline(always)]
    pub(super) fn begin<const FMA: bool>(&mut self, keys: &[EtdKey]) {
        for &i in &self.live {
            let v = &self.voices[i];
            let km = &keys[v.state.key.expect("live voices have a key")];
            let w = &mut self.work[i];
            w.start = [[[0.0; BLOCKS]; 3]; 4];
            for (s, blocks) in km.strings.iter().enumerate() {
                for (d, b) in blocks.iter().enumerate() {
                    let (z, lane) = (&v.z[s][d], 3 * s + d);
                    let [q, qd] = read_rows::<FMA, 2>([&b.rows[BRIDGE_Q], &b.rows[BRIDGE_V]], z);
                    for which in 0..3 {
                        w.start[BRIDGE_Q][which][lane] = q[which];
                        w.start[BRIDGE_V][which][lane] = qd[which];
                    }
                    if Direction::ALL[d].is_struck() && v.state.hammer_on && v.state.struck[s] {
                        let [y] = read_rows::<FMA, 1>([&b.rows[STRIKE_Q]], z);
                        (0..3).for_each(|which| w.start[STRIKE_Q][which][lane] = y[which]);
                    }
                    if Direction::ALL[d].is_transverse() && v.state.damper_down {
                        let [y] = read_rows::<FMA, 1>([&b.rows[DAMPER_V]], z);
                        (0..3).for_each(|which| w.start[DAMPER_V][which][lane] = y[which]);
                    }
                }
            }
        }
    }

    /// One ETDRK4 stage of these voices against the board's stage state `board` (modal `q`,
    /// `qdot`), adding their modal force on the board to `force`.
    #[inline(always)]
    pub(super) fn stage<const FMA: bool>(
        &mut self,
        keys: &[EtdKey],
        stage: usize,
        &(which, terms): &StagePlan,
        h: f64,
        board: &[Vec<f64>; 2],
        force: &mut [f64],
    ) {
        for &i in &self.live {
            let v = &self.voices[i];
            let km = &keys[v.state.key.expect("live voices have a key")];
            let at = read_point::<FMA>(&km.board_shape, board);
            let f = voice_stage(km, v, &mut self.work[i], stage, which, &terms, at, h);
            drive_point::<FMA>(force, &km.board_shape, f);
        }
    }

    /// The stage's bridge accelerations of these voices, from the board's modal acceleration.
    #[inline(always)]
    pub(super) fn accel<const FMA: bool>(&mut self, keys: &[EtdKey], stage: usize, acc: &[f64]) {
        for &i in &self.live {
            let km = &keys[self.voices[i].state.key.expect("live voices have a key")];
            voice_accel(
                &mut self.work[i],
                stage,
                read_accel::<FMA>(&km.board_shape, acc),
            );
        }
    }

    /// The step's end for these voices: hammers (classical RK4), strings, fades; `board` has
    /// already advanced.
    #[inline(always)]
    pub(super) fn finish<const FMA: bool>(
        &mut self,
        keys: &[EtdKey],
        h: f64,
        fade_steps: u32,
        board: &Board,
    ) {
        for &i in &self.live {
            let v = &mut self.voices[i];
            let km = &keys[v.state.key.expect("live voices have a key")];
            let w = &self.work[i];
            let ah = w.hammer_acc;
            let felt = v.state.hammer_on;
            if felt {
                let v0 = v.hammer_v;
                let (v2, v3, v4) = (v0 + 0.5 * h * ah[0], v0 + 0.5 * h * ah[1], v0 + h * ah[2]);
                v.hammer_y += h / 6.0 * (v0 + 2.0 * v2 + 2.0 * v3 + v4);
                v.hammer_v += h / 6.0 * (ah[0] + 2.0 * ah[1] + 2.0 * ah[2] + ah[3]);
            }
            for (s, blocks) in km.strings.iter().enumerate() {
                for (d, b) in blocks.iter().enumerate() {
                    let (z, lane) = (&mut v.z[s][d], 3 * s + d);
                    let u = |j: usize| std::array::from_fn(|p| w.u[p][j][lane]);
                    let gains = [&b.gains[IN_VEL], &b.gains[IN_ACCEL]];
                    propagate_drive::<FMA>(&b.e_full, gains, [u(IN_VEL), u(IN_ACCEL)], z);
                    drive::<FMA>(&b.gains[IN_FADE], u(IN_FADE), z);
                    if felt && Direction::ALL[d].is_struck() {
                        drive::<FMA>(&b.gains[IN_FELT], u(IN_FELT), z);
                    }
                    if v.state.damper_down && Direction::ALL[d].is_transverse() {
                        drive::<FMA>(&b.gains[IN_DAMPER], u(IN_DAMPER), z);
                    }
                }
            }
            // (The board's displacement is read only for a receding hammer.)
            if v.state.hammer_on && v.hammer_v < 0.0 {
                let y = board.at(&km.board_shape[0]).0;
                let (z, struck) = (&v.z, v.state.struck);
                let points = (0..km.strings.len())
                    .filter(|&s| struck[s])
                    .map(|s| strike_point(km, s, &z[s][0], y));
                if km.hammer.is_clear(v.hammer_y, v.hammer_v, points) {
                    v.state.hammer_on = false;
                }
            }
        }
        // Stolen voices fade out along a raised cosine (their next key is given between chunks).
        for v in &mut self.voices {
            fade_step(&mut v.state, fade_steps);
        }
    }
}

/// One stage of one voice, lane-wise over its blocks: each block's outputs (row `which` of the
/// start plus the responses to the earlier stages' inputs), the contact forces against the board
/// at the voice's point (`board`: `(y, y')` for T, L, P), the felt and damper forces. Stores the
/// stage's inputs in `w` (all but the bridge acceleration, [`voice_accel`]) and returns the force
/// on the board at the voice's point (T, L, P).
///
/// In the coordinates `q^ = q - g y` ([`Statics`]) the contact force is
/// `f = c_f (k (psi.q^ - (1 - psi.g) y) + c (psi.q^dot - (1 - psi.g) y'))` with the fade's
/// coupling `c_f` (see [`INPUTS`] for what the string receives).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn voice_stage(
    km: &EtdKey,
    v: &Voice,
    w: &mut Work,
    stage: usize,
    which: usize,
    terms: &[(usize, usize, f64); 2],
    board: [[f64; 2]; 3],
    h: f64,
) -> [f64; 3] {
    let (felt, damped, fading) = (
        v.state.hammer_on,
        v.state.damper_down,
        v.state.coupling != 1.0,
    );
    let out = |o: usize| {
        let mut y = w.start[o][which];
        for &(p, kind, coef) in terms {
            if coef == 0.0 {
                continue;
            }
            for j in 0..INPUTS {
                if (j == IN_FELT && !felt)
                    || (j == IN_DAMPER && !damped)
                    || (j == IN_FADE && !fading)
                {
                    continue;
                }
                let (r, u) = (&km.resp[o][j][kind], &w.u[p][j]);
                for b in 0..BLOCKS {
                    y[b] += coef * r[b] * u[b];
                }
            }
        }
        y
    };
    let (q, qd) = (out(BRIDGE_Q), out(BRIDGE_V));
    let (kc, cc, through) = (&km.lane_k, &km.lane_c, &km.lane_through);
    let mut fade = [0.0; BLOCKS];
    let mut force = [0.0; BLOCKS];
    let mut velocity = [0.0; BLOCKS];
    for b in 0..BLOCKS {
        let [by, bv] = board[b % 3];
        let rest = 1.0 - through[b];
        let f = spring_damper_n(kc[b], cc[b], q[b] - rest * by, qd[b] - rest * bv);
        fade[b] = (1.0 - v.state.coupling) * f;
        force[b] = v.state.coupling * f;
        velocity[b] = bv;
    }
    let mut felt_u = [0.0; BLOCKS];
    let mut felt_total = 0.0;
    if felt {
        let y = hammer_stage_y(v, &w.hammer_acc, stage, h);
        let strike = out(STRIKE_Q);
        for s in (0..km.strings.len()).filter(|&s| v.state.struck[s]) {
            let b = 3 * s;
            let f = km
                .hammer
                .felt_force_n(y - strike[b] - km.lane_strike[b] * board[0][0]);
            felt_u[b] = f;
            felt_total += f;
        }
    }
    let mut damper_u = [0.0; BLOCKS];
    if damped {
        let dv = out(DAMPER_V);
        for b in 0..BLOCKS {
            damper_u[b] = -km.lane_damper[b] * (dv[b] + km.lane_damper_g[b] * board[b % 3][1]);
        }
    }
    w.u[stage][IN_VEL] = velocity;
    w.u[stage][IN_FELT] = felt_u;
    w.u[stage][IN_DAMPER] = damper_u;
    w.u[stage][IN_FADE] = fade;
    w.hammer_acc[stage] = -felt_total / km.hammer.mass_kg;
    std::array::from_fn(|d| (0..MAX_STRINGS).map(|s| force[3 * s + d]).sum())
}

/// The stage's bridge-acceleration input of one voice, `-y''` at its point in T, L, P (the board's
/// acceleration once every voice's force of the stage is known).
#[inline(always)]
pub(super) fn voice_accel(w: &mut Work, stage: usize, accel: [f64; 3]) {
    w.u[stage][IN_ACCEL] = std::array::from_fn(|b| -accel[b % 3]);
}

/// The hammer's position at `stage` of classical RK4 (it has no linear part): `y0`,
/// `y0 + h/2 v0`, `y0 + h/2 v2`, `y0 + h v3` with `v2 = v0 + h/2 a1`, `v3 = v0 + h/2 a2`, from
/// the accelerations `acc` of the earlier stages.
pub(super) fn hammer_stage_y(v: &Voice, acc: &[f64; 4], stage: usize, h: f64) -> f64 {
    let (y0, v0) = (v.hammer_y, v.hammer_v);
    match stage {
        0 => y0,
        1 => y0 + 0.5 * h * v0,
        2 => y0 + 0.5 * h * (v0 + 0.5 * h * acc[0]),
        _ => y0 + h * (v0 + 0.5 * h * acc[1]),
    }
}

/// The displacement of string `s` at the strike point: its motion `q^` plus its static deflection
/// by the board's displacement `y` (T) at the key's point.
pub(super) fn strike_point(km: &EtdKey, s: usize, z: &ComplexState, y: f64) -> f64 {
    let b = &km.strings[s][0];
    read(&b.rows[STRIKE_Q][0], z) + b.statics.strike * y
}
