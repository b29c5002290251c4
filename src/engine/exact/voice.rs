//! One sounding key of the exact engine: its modal state, its hammer, the board's motion it
//! feels at its bridge and the damper force, and the step that advances them — in two halves
//! around the interface's solve ([`super::interface`]): [`Voice::pre_step`] takes the step with
//! what is known (`D^n`), [`Voice::post_step`] adds what `D^{n+1}` brings.

use super::kernels::{
    self, advance, scatter, Pending, Reversed, Simd, Split, BLOCK, DAMPED_INPUTS, DAMPED_READS,
    DIRECTIONS, FELT_INPUTS, FELT_ROWS, READS, SOUND_READS,
};
use super::key::{ExactKey, DAMPER_CHANNELS};
use crate::engine::pool::VoiceState;
use crate::engine::spec::MAX_STRINGS;

/// A voice's state. Written by the thread that owns the pool (the audio thread), or by the core
/// that runs its half of a block.
#[derive(Debug, Clone)]
pub(crate) struct Voice {
    pub(crate) state: VoiceState,
    /// Modal amplitudes in the shifted state `w = z - a D` ([`super::key`]; sized for the largest
    /// key, the key's first `n_modes` used), `a` that of the key's face in `modal_felt`.
    pub(crate) w: Split,
    /// Whether `w` is stepped with the key's face with its modal felt down
    /// ([`ExactKey::face_for`]), as of the last time the pool followed the damper
    /// ([`Voice::follow_damper`]).
    pub(crate) modal_felt: bool,
    pub(crate) hammer_y: f64,
    pub(crate) hammer_v: f64,
    /// The shared board's displacement at the bridge point after the last step and the one
    /// before (m, per direction): `D^n`, `D^{n-1}`.
    pub(crate) d: [f64; 3],
    pub(crate) d_before: [f64; 3],
    /// The total contact force this key put on the board at the end of the last step (N), part
    /// of the shared board's modal force.
    pub(crate) force_n: [f64; 3],
    /// The damper felt's force per channel at the end of the last step (N).
    pub(crate) damper_n: [f64; DAMPER_CHANNELS],
    /// What the last step read: the radiating source of the key's board modes (m^3/s, left
    /// channel), the total contact force T, L, P on the shared board (N), the right channel's
    /// source ([`SOUND_READS`]).
    pub(crate) read: [f64; READS],
    /// Within a step, before the interface's solve: the reads without `Z D^{n+1}`, and the
    /// damper's force without what `D^{n+1}` adds.
    pub(crate) known: [f64; READS],
    pub(crate) damper_known: [f64; DAMPER_CHANNELS],
    /// Over a block advanced mode by mode ([`super::block`]): whether this voice is, what its
    /// modes read with no input (the key's five rows, and the damper felt's velocity per
    /// channel where the damper is down), the inputs of each step (`D^t`, m, and the felt's `f^t`, N,
    /// [`Reversed`]) and what they have added to the reads so far ([`Pending`]).
    pub(crate) in_block: bool,
    pub(crate) block_read: [[f64; BLOCK]; DAMPED_READS],
    pub(crate) block_inputs: Reversed<DAMPED_INPUTS>,
    pub(crate) pending: Pending<DAMPED_READS>,
    /// Chunks of the key's modes stepped ([`super::key::Prefix`]): the rest follow the bridge
    /// quasi-statically, their part of `w` zero. Every chunk while a hammer touches or a coupled
    /// felt is down; as few as the sound needs otherwise ([`Voice::shed`]).
    pub(crate) live: usize,
    /// Whether its total force on the board is summed with the other watched voices', sample
    /// by sample ([`super::pool::ExactPool::run_watched`]).
    pub(crate) watched: bool,
    /// What the interface holds for this voice: its key's `Z`, damper down or lifted, with its
    /// chunks stepped.
    pub(crate) loads: Option<(usize, bool, usize)>,
    /// [`Voice::energy_j`] and [`Voice::dynamic_energy_j`] as the last block's end left the
    /// voice, worked out there by the core that advanced it (its modes still in that core's
    /// cache); `None` once anything else has moved it since. The pool's policy reads them after
    /// every block: worked out afresh on the callback's core, they swept every voice's modes
    /// through it two or three times a block, the helper's half from the other core's cache.
    pub(crate) energies: Option<[f64; 2]>,
}

impl Voice {
    pub(crate) fn new(modes: usize) -> Voice {
        Voice {
            state: VoiceState::default(),
            w: Split::zeros(modes),
            modal_felt: false,
            hammer_y: 0.0,
            hammer_v: 0.0,
            d: [0.0; 3],
            d_before: [0.0; 3],
            force_n: [0.0; 3],
            damper_n: [0.0; DAMPER_CHANNELS],
            read: [0.0; READS],
            known: [0.0; READS],
            damper_known: [0.0; DAMPER_CHANNELS],
            in_block: false,
            block_read: [[0.0; BLOCK]; DAMPED_READS],
            block_inputs: [[0.0; BLOCK]; DAMPED_INPUTS],
            pending: [[0.0; BLOCK]; DAMPED_READS],
            live: 0,
            watched: false,
            loads: None,
            energies: None,
        }
    }

    /// Whether the next steps are linear and time-invariant: no hammer, no fade (a block of them
    /// may then be advanced mode by mode, the damper lifted or down).
    pub(crate) fn is_linear(&self) -> bool {
        !self.state.hammer_on && self.state.fade_left == 0
    }

    /// Whether a coupled damper felt is on the strings of `key` (the face it steps with).
    pub(crate) fn damped(&self, key: &ExactKey) -> bool {
        self.state.damper_down && key.damper.is_some()
    }

    /// The face of `key` this voice steps with ([`Voice::modal_felt`]).
    pub(crate) fn face<'a>(&self, key: &'a ExactKey) -> &'a ExactKey {
        key.face_for(self.modal_felt)
    }

    /// Step with the face of `key` its damper asks for from now on: a modal felt that has
    /// fallen or risen since the last step changes the face, and `w = z - a D` takes the new
    /// face's `a` (`z`, the modes' state, is both faces'). Between steps only.
    pub(crate) fn follow_damper(&mut self, key: &ExactKey) {
        let want = self.state.damper_down && key.modal_felt.is_some();
        if want == self.modal_felt {
            return;
        }
        let (from, to) = (key.face_for(self.modal_felt), key.face_for(want));
        let live = self.live_unpadded(from);
        for d in 0..DIRECTIONS {
            from.settle[d].add_range_to(&mut self.w, self.d[d], 0..live);
            to.settle[d].add_range_to(&mut self.w, -self.d[d], 0..live);
        }
        self.modal_felt = want;
        self.energies = None;
    }

    /// `Re(r z)` of a row `r` whose `Re(r a_d)` is `settle`: `z = w + a D`.
    pub(crate) fn read_z(&self, row: &Split, settle: &[f64; DIRECTIONS]) -> f64 {
        row.read(&self.w) + (0..DIRECTIONS).map(|d| settle[d] * self.d[d]).sum::<f64>()
    }

    /// The total contact force on the board with the strings as they are and the bridge held at
    /// `D` (no slope): what a joining voice adds to the board.
    pub(crate) fn static_force_n(&self, key: &ExactKey) -> [f64; 3] {
        let held = &key.prefixes[self.live].held;
        std::array::from_fn(|i| {
            let direct: f64 = (0..DIRECTIONS).map(|d| held[1 + i][d] * self.d[d]).sum();
            key.reads[1 + i].read(&self.w) + direct - key.feed_k[i] * self.d[i]
        })
    }

    /// Modes stepped (of `key`, the face the voice steps with): [`Voice::live`] chunks, the last
    /// one padded.
    pub(crate) fn live_modes(&self, key: &ExactKey) -> usize {
        key.prefixes[self.live].modes
    }

    /// The key's own modes among those stepped: [`Voice::live_modes`] without the last chunk's
    /// padding.
    pub(crate) fn live_unpadded(&self, key: &ExactKey) -> usize {
        self.live_modes(key).min(key.n_modes())
    }

    /// Step `chunks` chunks of `key`'s modes from now on: a chunk taken up starts as the
    /// quasi-static response to `D` it stood for (`z = follow D`, so `w = (follow - a) D`); one
    /// left out is set to zero. Between steps only.
    pub(crate) fn keep_chunks(&mut self, key: &ExactKey, chunks: usize) {
        let (from, to) = (self.live_modes(key), key.prefixes[chunks].modes);
        let n = key.n_modes();
        if to > from {
            let range = from.min(n)..to.min(n);
            for d in 0..DIRECTIONS {
                key.follow[d].add_range_to(&mut self.w, self.d[d], range.clone());
                key.settle[d].add_range_to(&mut self.w, -self.d[d], range.clone());
            }
        } else {
            self.w.re[to..from].fill(0.0);
            self.w.im[to..from].fill(0.0);
        }
        self.live = chunks;
        self.energies = None;
    }

    /// Leave out the top chunks of modes that have died away — whose energy about the strings'
    /// static deflection by `D` is under `left_below` of the voice's, or under `left_under_j` —
    /// keeping at least `keep` chunks. The modes left out go on answering `D` quasi-statically
    /// ([`super::key::Prefix`]); what they carried beyond that is dropped. Between steps only.
    pub(crate) fn shed(
        &mut self,
        key: &ExactKey,
        keep: usize,
        left_below: f64,
        left_under_j: f64,
        simd: Simd,
    ) {
        let floor = (left_below * self.energies_j(key, simd)[1]).max(left_under_j);
        let mut live = self.live;
        while live > keep {
            let chunk = key.prefixes[live - 1].modes..key.prefixes[live].modes;
            if kernels::energies(simd, &key.energy, &self.w, self.d, chunk)[1] >= floor {
                break;
            }
            live -= 1;
        }
        if live < self.live {
            self.keep_chunks(key, live);
        }
    }

    /// Strings, board modes and everything they remember at rest.
    pub(crate) fn rest(&mut self) {
        self.w.fill_zero();
        self.live = 0;
        self.d = [0.0; 3];
        self.d_before = [0.0; 3];
        self.force_n = [0.0; 3];
        self.damper_n = [0.0; DAMPER_CHANNELS];
        self.read = [0.0; READS];
        self.block_inputs = [[0.0; BLOCK]; DAMPED_INPUTS];
        self.in_block = false;
        self.energies = None;
    }

    /// `[energy_j, dynamic_energy_j]`: as the last block's end left them if nothing has moved
    /// the voice since, else worked out now.
    pub(crate) fn energies_j(&self, key: &ExactKey, simd: Simd) -> [f64; 2] {
        self.energies
            .unwrap_or_else(|| self.energies_now_j(key, simd))
    }

    /// Worked out now: the mechanical energy of the key's modes (J, cycle-averaged per mode) at
    /// `z = w + a D` — what the pool's policy weighs (a voice falls silent, is stolen, runs
    /// away), its contact springs counted as stretched by the board's motion `D` under them, so
    /// that a damped key is not retired while the board still moves it (taken off, it would no
    /// longer damp the board) — and the same about the strings' static deflection by `D` (`z`
    /// less `follow D`): the energy that only falls when nothing drives the pool, but for the
    /// coupling's exchanges between keys ([`super::pool::ExactPool::mechanical_energy_j`]).
    /// Measured from `z` itself that would count every contact spring as stretched by `D`
    /// (`k_c D^2 / 2` each, although the strings' ends follow the bridge): a damped key beside a
    /// loud C1 then seemed to gain 2e-3 J from nothing. One pass over the modes
    /// ([`kernels::energies`]).
    pub(crate) fn energies_now_j(&self, key: &ExactKey, simd: Simd) -> [f64; 2] {
        let live = self.live_modes(key);
        kernels::energies(simd, &key.energy, &self.w, self.d, 0..live)
    }

    /// String `s`'s displacement at the striking point (m).
    fn strike_point_m(&self, key: &ExactKey, s: usize) -> f64 {
        self.read_z(&key.modes.strike_row[s], &key.strike_settle[s])
    }

    /// The felt force on each struck string now (N).
    pub(crate) fn hammer_force_n(&self, key: &ExactKey) -> [f64; MAX_STRINGS] {
        std::array::from_fn(|s| {
            if let (true, true, Some(law)) =
                (self.state.hammer_on, s < key.n_strings, self.state.felt[s])
            {
                let ve = if key.hammer.is_hysteretic() {
                    self.read_z(&key.strike_velocity_row[s], &key.strike_velocity_settle[s])
                } else {
                    0.0
                };
                law.force_n(
                    self.hammer_y - self.strike_point_m(key, s),
                    self.hammer_v - ve,
                    key.hammer.hysteresis_s,
                )
            } else {
                0.0
            }
        })
    }

    /// The highest of the first `struck` strings' displacements at the striking point.
    pub(crate) fn strike_contact_m(&self, key: &ExactKey, struck: usize) -> f64 {
        (0..struck.min(key.n_strings))
            .map(|s| self.strike_point_m(key, s))
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// The step up to the interface: the hammer by ETDRK4 while it touches, the modes exactly
    /// with `D^n` entering, the damper's known part. Fills `self.known` (the reads less
    /// `Z D^{n+1}`).
    pub(crate) fn pre_step(&mut self, key: &ExactKey, simd: Simd) {
        let fast = simd.avx2();
        let dn = self.d;
        let mut read = if self.state.hammer_on {
            // The contact step is taken on z^n = w + a D^n; what D^n adds over it then follows.
            kernels::add_directions(fast, &key.ef, &mut self.w, &key.settle, &dn);
            self.contact_step(key, fast);
            advance(
                fast,
                false,
                key.n_modes(),
                &key.ef,
                &mut self.w,
                &key.hold,
                &dn,
                &key.reads,
            )
        } else {
            let live = self.live_modes(key);
            advance(
                fast,
                true,
                live,
                &key.ef,
                &mut self.w,
                &key.beta,
                &dn,
                &key.reads,
            )
        };
        if let (true, Some(damper)) = (self.state.damper_down, &key.damper) {
            let r = damper.channels;
            let before = self.damper_n;
            let v: [f64; DAMPER_CHANNELS] = std::array::from_fn(|i| {
                if i < r {
                    damper.rows[i].read(&self.w)
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
            for (i, x) in read.iter_mut().enumerate() {
                for j in 0..r {
                    *x += damper.reads_from[i][j] * before[j] + damper.reads_to[i][j] * after[j];
                }
            }
            self.damper_known = after;
        }
        self.known = self.with_feed(key, read);
    }

    /// The reads known before `D^{n+1}` of a voice in a block: its free reads and what its
    /// inputs so far add, `D^t` (and the damper felt's `f^t`) stored as this step's input; with
    /// the damper down, the felt's force known but for `D^{n+1}` (as [`Voice::pre_step`]).
    pub(crate) fn pre_block_step(&mut self, key: &ExactKey, t: usize, simd: Simd) {
        if t == 0 {
            self.pending = [[0.0; BLOCK]; DAMPED_READS];
        }
        for d in 0..DIRECTIONS {
            self.block_inputs[d][BLOCK - 1 - t] = self.d[d] as f32;
        }
        let mut read = [0.0; READS];
        match (self.damped(key), &key.damper) {
            (true, Some(damper)) => {
                for j in 0..damper.channels {
                    self.block_inputs[DIRECTIONS + j][BLOCK - 1 - t] = self.damper_n[j] as f32;
                }
                scatter(
                    simd,
                    &damper.markov,
                    &self.block_inputs,
                    t,
                    &mut self.pending,
                );
                let all: [f64; DAMPED_READS] =
                    std::array::from_fn(|i| self.block_read[i][t] + f64::from(self.pending[i][t]));
                // The felt's velocity after the step, from u (module notes of `key`): what the
                // per-sample step forms from `w` and the force at the step's start.
                let r = damper.channels;
                let after: [f64; DAMPER_CHANNELS] = std::array::from_fn(|i| {
                    (0..r)
                        .map(|j| damper.solve[i * DAMPER_CHANNELS + j] * all[READS + j])
                        .sum()
                });
                for (i, x) in read.iter_mut().enumerate() {
                    *x = all[i]
                        + (0..r)
                            .map(|j| damper.reads_to[i][j] * after[j])
                            .sum::<f64>();
                }
                self.damper_known = after;
            }
            _ => {
                let pending: &mut Pending<READS> = (&mut self.pending[..READS])
                    .try_into()
                    .expect("the first reads are the undamped key's");
                let inputs: &Reversed<DIRECTIONS> = self.block_inputs[..DIRECTIONS]
                    .try_into()
                    .expect("the first inputs are the bridge's");
                scatter(simd, &key.prefixes[self.live].markov, inputs, t, pending);
                for (i, r) in read.iter_mut().enumerate() {
                    *r = self.block_read[i][t] + f64::from(pending[i][t]);
                }
            }
        }
        self.known = self.with_feed(key, read);
    }

    /// What `D^n` adds to the reads beside the modes stepped: the contact dampers' `c D^n / h`
    /// in the force (the slope's known end) and the modes left out's answer to the slope.
    fn with_feed(&self, key: &ExactKey, mut read: [f64; READS]) -> [f64; READS] {
        for d in 0..DIRECTIONS {
            read[1 + d] += key.feed_c[d] * self.d[d] / key.h;
        }
        let known = &key.prefixes[self.live].known;
        for (r, known) in read.iter_mut().zip(known) {
            *r += (0..DIRECTIONS).map(|d| known[d] * self.d[d]).sum::<f64>();
        }
        read
    }

    /// The rest of the step once the interface has solved for `D^{n+1}` (`next`): the reads, the
    /// damper's force and its input, the hammer's release.
    pub(crate) fn post_step(&mut self, key: &ExactKey, next: [f64; 3]) {
        let damped = self.damped(key);
        let settle = key.settle_for(damped, self.live);
        if let (true, Some(damper)) = (damped, &key.damper) {
            let before = self.damper_n;
            for j in 0..damper.channels {
                let after = self.damper_known[j]
                    + (0..DIRECTIONS)
                        .map(|d| damper.settle[j][d] * next[d])
                        .sum::<f64>();
                // In a block the felt's force is an input, folded in at its end.
                if !self.in_block {
                    damper.from[j].add_to(&mut self.w, before[j]);
                    damper.to[j].add_to(&mut self.w, after);
                }
                self.damper_n[j] = after;
            }
        } else {
            self.damper_n = [0.0; DAMPER_CHANNELS];
        }
        let mut read = self.known;
        for d in 0..DIRECTIONS {
            for (c, &r) in SOUND_READS.iter().enumerate() {
                read[r] += settle.volume[c][d] * next[d];
            }
            for i in 0..DIRECTIONS {
                read[1 + i] += settle.force[i][d] * next[d];
            }
        }
        self.read = read;
        self.force_n = [read[1], read[2], read[3]];
        self.d_before = self.d;
        self.d = next;
        if self.state.hammer_on {
            let points = (0..key.n_strings)
                .filter(|&s| self.state.felt[s].is_some())
                .map(|s| self.strike_point_m(key, s));
            if key.hammer.is_clear(self.hammer_y, self.hammer_v, points) {
                self.state.hammer_on = false;
            }
        }
    }

    /// ETDRK4 (Cox & Matthews) on `z` (held in `w`): `a = E_2 u + Q N(u)`, `b = E_2 u + Q N(a)`,
    /// `c = E_2 a + Q (2 N(b) - N(u))`, `u' = E u + f1 N(u) + f2 (N(a) + N(b)) + f3 N(c)`, the
    /// felt force `N` entering the modes through each struck string's input, and the hammer's
    /// own linear part zero (its stages are classical RK4). The stages are linear in `u` and the
    /// forces, and the felt reads only its rows of them: those follow from the rows' reads of
    /// `u`, `E_2 u` and `E_2^2 u` (one pass over the modes) and the key's `Re(r Q)`,
    /// `Re(r E_2 Q)`; the modes are then advanced in one more pass — not four stages formed.
    fn contact_step(&mut self, key: &ExactKey, fast: bool) {
        for _ in 0..key.contact.substeps {
            self.contact_substep(key, fast);
        }
    }

    /// One substep of [`Self::contact_step`] (of `key.contact.h`).
    fn contact_substep(&mut self, key: &ExactKey, fast: bool) {
        let step = &key.contact;
        let (h, m_h) = (step.h, key.hammer.mass_kg);
        let (y, v) = (self.hammer_y, self.hammer_v);
        let accel = |f: &[f64; MAX_STRINGS]| -> f64 { -f.iter().sum::<f64>() / m_h };
        let ns = key.n_strings;
        let hysteretic = key.hammer.is_hysteretic();
        // The rows the felt reads: each string's displacement at the striking point, then (a
        // hysteretic felt) its velocity there, as in `ExactKey::stage_q`.
        let mut rows: [&Split; FELT_ROWS] = [&step.eh; FELT_ROWS];
        for s in 0..ns {
            rows[s] = &key.modes.strike_row[s];
            rows[ns + s] = &key.strike_velocity_row[s];
        }
        let count = if hysteretic { 2 * ns } else { ns };
        let p = kernels::powers_read(fast, &step.eh, &self.w, &rows[..count]);
        // Row `i` at a stage: `power` of `E_2` on `u`, with forces `fq` through `Q` and `feq`
        // through `E_2 Q`.
        let at = |i: usize, power: usize, fq: &[f64; MAX_STRINGS], feq: &[f64; MAX_STRINGS]| {
            p[i][power]
                + (0..ns)
                    .map(|s| step.stage_q[i][s] * fq[s] + step.stage_eq[i][s] * feq[s])
                    .sum::<f64>()
        };
        let (laws, alpha_s) = (self.state.felt, key.hammer.hysteresis_s);
        let felt = |power, fq: &[f64; MAX_STRINGS], feq: &[f64; MAX_STRINGS], y: f64, v: f64| {
            std::array::from_fn(|s| {
                if let (true, Some(law)) = (s < ns, laws[s]) {
                    let ve = if hysteretic {
                        at(ns + s, power, fq, feq)
                    } else {
                        0.0
                    };
                    law.force_n(y - at(s, power, fq, feq), v - ve, alpha_s)
                } else {
                    0.0
                }
            })
        };
        let none = [0.0; MAX_STRINGS];
        let fu: [f64; MAX_STRINGS] = felt(0, &none, &none, y, v);
        let (ya, va) = (y + 0.5 * h * v, v + 0.5 * h * accel(&fu));
        let fa = felt(1, &fu, &none, ya, va);
        let (yb, vb) = (y + 0.5 * h * va, v + 0.5 * h * accel(&fa));
        let fb = felt(1, &fa, &none, yb, vb);
        let mixed: [f64; MAX_STRINGS] = std::array::from_fn(|s| 2.0 * fb[s] - fu[s]);
        let (yc, vc) = (
            ya + 0.5 * h * (2.0 * vb - v),
            va + 0.5 * h * (2.0 * accel(&fb) - accel(&fu)),
        );
        let fc = felt(2, &mixed, &fu, yc, vc);
        let mut inputs: [&Split; FELT_INPUTS] = [&step.ef; FELT_INPUTS];
        let mut forces = [0.0; FELT_INPUTS];
        let mut k = 0;
        for s in (0..ns).filter(|&s| laws[s].is_some()) {
            for (g, f) in step.drive_f[s].iter().zip([fu[s], fa[s] + fb[s], fc[s]]) {
                (inputs[k], forces[k]) = (g, f);
                k += 1;
            }
        }
        kernels::drive(fast, &step.ef, &mut self.w, &inputs[..k], &forces[..k]);
        self.hammer_y = y + h / 6.0 * v + h / 3.0 * (va + vb) + h / 6.0 * vc;
        self.hammer_v =
            v + h / 6.0 * accel(&fu) + h / 3.0 * (accel(&fa) + accel(&fb)) + h / 6.0 * accel(&fc);
    }
}
