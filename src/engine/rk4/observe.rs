//! What is read from the RK4 pool: forces and volume velocity (Eq. 19), energies, and the cost
//! of a step (FLOPs, bytes per voice).

use super::*;

impl<T: Real> Rk4Pool<T> {
    /// Voice 0's outputs (see [`Rk4Pool::observe_voice`]).
    pub fn observe(&self) -> Observation {
        self.observe_voice(0)
    }

    /// Forces of voice `k`, the board's velocity at its bridge point and the board's volume
    /// velocity, at the current state (Eq. 19). A voice without a key observes nothing but the board.
    pub fn observe_voice(&self, k: usize) -> Observation {
        let mut obs = Observation {
            volume_velocity_m3_s: self.volume_velocity_m3_s(),
            ..Observation::default()
        };
        let (m, voice) = (&self.model, &self.model.voices[k]);
        let Some(key) = self.states[k].key else {
            return obs;
        };
        let km = &m.keys[key];
        let gain = self.states[k].coupling;
        let (q, v) = (&self.q, &self.v);
        let qb = &q[m.board.clone()];
        let vb = &v[m.board.clone()];
        let mut rb = [0.0; 3];
        for d in 0..3 {
            rb[d] = T::dot_wide::<false>(&km.board_shape[d], qb);
            obs.bridge_velocity_m_s[d] = T::dot_wide::<false>(&km.board_shape[d], vb);
        }
        for s in 0..voice.n_strings {
            for d in 0..3 {
                let r = voice.ranges[s][d].clone();
                let shape = &m.bridge_shape[r.clone()];
                let (rs, rs_dot) = (
                    T::dot_wide::<false>(shape, &q[r.clone()]),
                    T::dot_wide::<false>(shape, &v[r]),
                );
                let f = gain
                    * km.contact
                        .force_n(d, rs - rb[d], rs_dot - obs.bridge_velocity_m_s[d]);
                obs.bridge_force_n[s][d] = f;
                obs.total_force_n[d] += f;
            }
            if let (true, Some(law)) = (self.states[k].hammer_on, self.states[k].felt[s]) {
                let r = voice.ranges[s][0].clone();
                let ye = T::dot_wide::<false>(&km.hammer_shape, &q[r.clone()]);
                let ve = if km.hammer.is_hysteretic() {
                    T::dot_wide::<false>(&km.hammer_shape, &v[r])
                } else {
                    0.0
                };
                obs.hammer_force_n[s] = law.force_n(
                    self.hammer_y[k] - ye,
                    self.hammer_v[k] - ve,
                    km.hammer.hysteresis_s,
                );
            }
        }
        obs
    }

    /// The board's radiating source (m^3/s) of the left channel: its net volume velocity, or
    /// its equivalent at a listener
    /// ([`crate::engine::physics::soundboard::SoundboardModes::radiation_weights`]).
    pub fn volume_velocity_m3_s(&self) -> f64 {
        self.radiated_by(0)
    }

    /// The board's radiating source (m^3/s) of each channel, left and right.
    pub fn radiated_m3_s(&self) -> [f64; CHANNELS] {
        let left = self.radiated_by(0);
        match self.model.stereo {
            true => [left, self.radiated_by(1)],
            false => [left; CHANNELS],
        }
    }

    fn radiated_by(&self, channel: usize) -> f64 {
        let [by_v, by_q] = &self.model.board_radiation[channel];
        let board = self.model.board.clone();
        let [res_v, res_q] = &self.model.residual_radiation[channel];
        let res = self.model.residual.clone();
        T::dot_wide::<false>(by_v, &self.v[board.clone()])
            + T::dot_wide::<false>(by_q, &self.q[board])
            + T::dot_wide::<false>(res_v, &self.v[res.clone()])
            + T::dot_wide::<false>(res_q, &self.q[res])
    }

    /// Floating-point operations of one RK4 step in the current state (active voices, hammers,
    /// dampers), counted from the arithmetic of [`evaluate`] and the stage updates: a multiply-add
    /// counts 2. What `unacorda bench` divides by time to report a FLOP rate.
    pub fn flops_per_step(&self) -> f64 {
        let (m, f) = (&self.model, &self.states);
        let (nb, nr) = (m.board.len(), m.residual.len());
        let mut live = nb + nr;
        // Per evaluation: the uncoupled oscillators (3 per mode) of the board and its dropped
        // modes ...
        let mut eval = 3 * (nb + nr);
        for (k, voice) in m.voices.iter().enumerate() {
            let (true, Some(key)) = (f[k].active, f[k].key) else {
                continue;
            };
            let km = &m.keys[key];
            let n = voice.n_modes;
            let (nt, np) = (voice.ranges[0][0].len(), voice.ranges[0][2].len());
            live += n;
            // ... and the strings; bridge dot products and projections (4 + 2 per mode), the
            // board's side at this point (3 directions × (4 + 2) per board mode), the duplex
            // product through its rank-r factor (2 × 2 r per entry of W, T and P of every string).
            let r = km.duplex_rank;
            // (and the dropped modes driven by its force, 3 × 2 per mode).
            eval += 3 * n + 6 * n + 18 * nb + 6 * nr + 4 * r * voice.n_strings * (nt + np);
            if f[k].felt_share() > 0.0 {
                eval += 4 * km.damper_shapes.len() * voice.n_strings * (nt + np);
            }
            if f[k].hammer_on {
                eval += 4 * nt * f[k].felt.iter().flatten().count();
            }
        }
        // Four evaluations, and the stage updates: 4 + 8 + 8 + 6 per mode.
        (4 * eval + 26 * live) as f64
    }

    /// Bytes of state and coefficients per voice slot (arrays of `T` over its modes).
    pub fn bytes_per_voice(&self) -> usize {
        use std::mem::size_of;
        let capacity = self.model.board.start / self.n_voices().max(1);
        // Per mode: q and v, the RK4 stage state and acceleration (3), the stage sums (2), and
        // the coefficients omega^2, damping, bridge shape, static deflection (4). Per voice: its
        // slot, the hammer's state and RK4 scratch (7 f64), where it left the board, its flags
        // and its entry in the list of simulated ranges.
        let flags = 4 * size_of::<bool>()
            + size_of::<[bool; MAX_STRINGS]>()
            + size_of::<f64>()
            + size_of::<u32>()
            + size_of::<Option<(usize, Strike)>>();
        capacity * size_of::<T>() * 11
            + size_of::<Voice>()
            + 7 * size_of::<f64>()
            + size_of::<[[f64; 2]; 3]>()
            + flags
            + size_of::<Range<usize>>()
    }

    /// Mechanical energy of the strings, their contact springs and the board (J), hammers apart.
    pub fn mechanical_energy_j(&self) -> f64 {
        let e = self.energy();
        e.strings_j + e.contact_j + e.board_j
    }

    /// Mechanical energy of strings, board, contact springs and hammers (J).
    pub fn energy(&self) -> Energy {
        let m = &self.model;
        let strings_j = self.modal_energy_j(0..m.board.start);
        let board_j = self.modal_energy_j(m.board.clone());
        let (mut contact_j, mut hammer_j) = (0.0, 0.0);
        for (k, voice) in m.voices.iter().enumerate() {
            let Some(key) = self.states[k].key else {
                continue;
            };
            if !self.states[k].active {
                continue;
            }
            let km = &m.keys[key];
            contact_j += self.voice_contact_j(k);
            if self.states[k].hammer_on {
                hammer_j += 0.5 * km.hammer.mass_kg * self.hammer_v[k].powi(2);
                for s in 0..voice.n_strings {
                    if let Some(law) = self.states[k].felt[s] {
                        let ye = T::dot_wide::<false>(
                            &km.hammer_shape,
                            &self.q[voice.ranges[s][0].clone()],
                        );
                        hammer_j += law.energy_j(self.hammer_y[k] - ye);
                    }
                }
            }
        }
        Energy {
            strings_j,
            board_j,
            contact_j,
            hammer_j,
        }
    }
}
