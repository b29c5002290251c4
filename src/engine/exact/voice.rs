//! One sounding key of the exact engine: its modal state, its hammer, the coupling input it
//! receives and the damper force it feels, and the step that advances them.

use super::kernels::{
    advance, propagate, stage, Reversed, Split, BLOCK, DIRECTIONS, INPUTS, READS,
};
use super::key::{ExactKey, DAMPER_CHANNELS};
use crate::engine::pool::VoiceState;
use crate::engine::spec::MAX_STRINGS;

/// A voice's state. Written by the thread that owns the pool (the audio thread).
#[derive(Debug, Clone)]
pub(crate) struct Voice {
    pub(crate) state: VoiceState,
    /// Modal amplitudes (sized for the largest key; the key's first `n_modes` are used).
    pub(crate) z: Split,
    pub(crate) hammer_y: f64,
    pub(crate) hammer_v: f64,
    /// The other keys' board displacement at this bridge point now and a step ago (m), per
    /// direction.
    pub(crate) other_m: [f64; 3],
    pub(crate) other_before_m: [f64; 3],
    /// The total contact force this key put on the board at the end of the last step (N).
    pub(crate) force_n: [f64; 3],
    /// The damper felt's force per channel at the end of the last step (N).
    pub(crate) damper_n: [f64; DAMPER_CHANNELS],
    /// This key's part of the shared board's motion as the board coupling integrates it
    /// ([`super::board`]).
    pub(crate) own_board: Split,
    /// The own part's displacement at the bridge point after the last step (m, per direction;
    /// taken from the shared part's to leave the other keys').
    pub(crate) own_at_m: [f64; 3],
    /// What the last step read: volume velocity (m^3/s), total contact force T, L, P (N).
    pub(crate) read: [f64; READS],
    /// Over a block advanced mode by mode ([`super::pool`]): whether this voice is, what its
    /// modes read with no input, and the coupling input of each step (`c D_d`, m, [`Reversed`]).
    pub(crate) in_block: bool,
    pub(crate) block_read: [[f64; BLOCK]; READS],
    pub(crate) block_inputs: Reversed,
}

impl Voice {
    pub(crate) fn new(modes: usize, board_modes: usize) -> Voice {
        Voice {
            state: VoiceState::default(),
            z: Split::zeros(modes),
            hammer_y: 0.0,
            hammer_v: 0.0,
            other_m: [0.0; 3],
            other_before_m: [0.0; 3],
            force_n: [0.0; 3],
            damper_n: [0.0; DAMPER_CHANNELS],
            own_board: Split::zeros(board_modes),
            own_at_m: [0.0; 3],
            read: [0.0; READS],
            in_block: false,
            block_read: [[0.0; BLOCK]; READS],
            block_inputs: [[0.0; BLOCK]; DIRECTIONS],
        }
    }

    /// Whether the next steps are linear and time-invariant: no hammer, no damper on the strings,
    /// no fade (a block of them may then be advanced mode by mode).
    pub(crate) fn is_free(&self, key: &ExactKey) -> bool {
        let damped = self.state.damper_down && key.damper.is_some();
        !(self.state.hammer_on || damped) && self.state.fade_left == 0
    }

    /// The coupling inputs of the next step: the other keys' board motion `D` now and its slope
    /// over the last step, scaled by the voice's coupling.
    pub(crate) fn inputs(&self, h: f64) -> [f64; INPUTS] {
        let c = self.state.coupling;
        let mut u = [0.0; INPUTS];
        for d in 0..3 {
            u[d] = c * self.other_m[d];
            u[3 + d] = c * (self.other_m[d] - self.other_before_m[d]) / h;
        }
        u
    }

    /// The step's reads with the contact springs' direct part, stretched by the other keys'
    /// board motion: the total contact force this key puts on the board.
    pub(crate) fn finish(&mut self, key: &ExactKey, u: &[f64; INPUTS], mut read: [f64; READS]) {
        for d in 0..3 {
            let at_end = u[d] + key.h * u[3 + d];
            read[1 + d] -= key.feed_k[d] * at_end + key.feed_c[d] * u[3 + d];
            self.force_n[d] = self.state.coupling * read[1 + d];
        }
        self.read = read;
    }

    /// Strings, board copy and everything they remember at rest.
    pub(crate) fn rest(&mut self) {
        self.z.fill_zero();
        self.own_board.fill_zero();
        self.own_at_m = [0.0; 3];
        self.other_m = [0.0; 3];
        self.other_before_m = [0.0; 3];
        self.force_n = [0.0; 3];
        self.damper_n = [0.0; DAMPER_CHANNELS];
        self.read = [0.0; READS];
        self.in_block = false;
    }

    /// Mechanical energy of the key's modes (J, cycle-averaged per mode).
    pub(crate) fn energy_j(&self, key: &ExactKey) -> f64 {
        (0..key.n_modes())
            .map(|m| key.energy[m] * (self.z.re[m] * self.z.re[m] + self.z.im[m] * self.z.im[m]))
            .sum()
    }

    /// The felt force on each string (Eq. 8) with the hammer at `y` and the modes at `z`.
    fn felt(&self, key: &ExactKey, z: &Split, y: f64) -> [f64; MAX_STRINGS] {
        std::array::from_fn(|s| {
            if s < key.n_strings && self.state.struck[s] {
                key.hammer.felt_force_n(y - key.strike_row[s].read(z))
            } else {
                0.0
            }
        })
    }

    pub(crate) fn hammer_force_n(&self, key: &ExactKey) -> [f64; MAX_STRINGS] {
        if self.state.hammer_on {
            self.felt(key, &self.z, self.hammer_y)
        } else {
            [0.0; MAX_STRINGS]
        }
    }

    /// The highest of the first `struck` strings' displacements at the striking point.
    pub(crate) fn strike_contact_m(&self, key: &ExactKey, struck: usize) -> f64 {
        (0..struck.min(key.n_strings))
            .map(|s| key.strike_row[s].read(&self.z))
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// Advance one step (`scratch`: three stage states): the hammer by ETDRK4 while it touches,
    /// the modes exactly, the other keys' board motion entering as a ramp extrapolated from its
    /// last two values, the damper felt implicitly. Fills `self.read` and `self.force_n`.
    pub(crate) fn step(&mut self, key: &ExactKey, scratch: &mut [Split; 3], fast: bool) {
        let u = self.inputs(key.h);
        let contact = self.state.hammer_on;
        if contact {
            self.contact_step(key, scratch);
        }
        let mut read = advance(
            fast,
            !contact,
            &key.ef,
            &mut self.z,
            &key.coupling,
            &u,
            &key.reads,
        );
        if self.state.damper_down {
            if let Some(damper) = &key.damper {
                let r = damper.channels;
                let before = self.damper_n;
                let v: [f64; DAMPER_CHANNELS] = std::array::from_fn(|i| {
                    if i < r {
                        damper.rows[i].read(&self.z)
                            + (0..r)
                                .map(|j| damper.rows_from[i * DAMPER_CHANNELS + j] * before[j])
                                .sum::<f64>()
                    } else {
                        0.0
                    }
                });
                let after: [f64; DAMPER_CHANNELS] = std::array::from_fn(|i| {
                    (0..r)
                        .map(|j| damper.solve[i * DAMPER_CHANNELS + j] * v[j])
                        .sum()
                });
                for j in 0..r {
                    damper.from[j].add_to(&mut self.z, before[j]);
                    damper.to[j].add_to(&mut self.z, after[j]);
                }
                for (i, x) in read.iter_mut().enumerate() {
                    for j in 0..r {
                        *x +=
                            damper.reads_from[i][j] * before[j] + damper.reads_to[i][j] * after[j];
                    }
                }
                self.damper_n = after;
            }
        } else {
            self.damper_n = [0.0; DAMPER_CHANNELS];
        }
        self.finish(key, &u, read);
        if contact {
            let points = (0..key.n_strings)
                .filter(|&s| self.state.struck[s])
                .map(|s| key.strike_row[s].read(&self.z));
            if key.hammer.is_clear(self.hammer_y, self.hammer_v, points) {
                self.state.hammer_on = false;
            }
        }
    }

    /// ETDRK4 (Cox & Matthews): `a = E_2 u + Q N(u)`, `b = E_2 u + Q N(a)`,
    /// `c = E_2 a + Q (2 N(b) - N(u))`, `u' = E u + f1 N(u) + f2 (N(a) + N(b)) + f3 N(c)`, the
    /// felt force `N` entering the modes through each struck string's input, and the hammer's
    /// own linear part zero (its stages are classical RK4).
    fn contact_step(&mut self, key: &ExactKey, scratch: &mut [Split; 3]) {
        let (h, m_h) = (key.h, key.hammer.mass_kg);
        let (y, v) = (self.hammer_y, self.hammer_v);
        let accel = |f: &[f64; MAX_STRINGS]| -> f64 { -f.iter().sum::<f64>() / m_h };
        let [za, zb, zc] = scratch;
        let fu = self.felt(key, &self.z, y);
        stage(za, &key.eh, &self.z, &key.drive_q, &fu);
        let (ya, va) = (y + 0.5 * h * v, v + 0.5 * h * accel(&fu));
        let fa = self.felt(key, za, ya);
        stage(zb, &key.eh, &self.z, &key.drive_q, &fa);
        let (yb, vb) = (y + 0.5 * h * va, v + 0.5 * h * accel(&fa));
        let fb = self.felt(key, zb, yb);
        let mixed: [f64; MAX_STRINGS] = std::array::from_fn(|s| 2.0 * fb[s] - fu[s]);
        stage(zc, &key.eh, za, &key.drive_q, &mixed);
        let (yc, vc) = (
            ya + 0.5 * h * (2.0 * vb - v),
            va + 0.5 * h * (2.0 * accel(&fb) - accel(&fu)),
        );
        let fc = self.felt(key, zc, yc);
        propagate(&key.ef, &mut self.z);
        for s in (0..key.n_strings).filter(|&s| self.state.struck[s]) {
            let [g1, g2, g3] = &key.drive_f[s];
            g1.add_to(&mut self.z, fu[s]);
            g2.add_to(&mut self.z, fa[s] + fb[s]);
            g3.add_to(&mut self.z, fc[s]);
        }
        self.hammer_y = y + h / 6.0 * v + h / 3.0 * (va + vb) + h / 6.0 * vc;
        self.hammer_v =
            v + h / 6.0 * accel(&fu) + h / 3.0 * (accel(&fa) + accel(&fb)) + h / 6.0 * accel(&fc);
    }
}
