//! The pool policy ([`Policy`]) on RK4's flat arrays: the hooks the shared policy calls.

use super::*;
use crate::engine::physics::hammer::HammerParams;

/// The pool policy ([`Policy`]) on RK4's flat arrays.
impl<T: Real> Policy for Rk4Pool<T> {
    fn n_voices(&self) -> usize {
        self.model.voices.len()
    }

    fn state(&self, k: usize) -> &VoiceState {
        &self.states[k]
    }

    fn state_mut(&mut self, k: usize) -> &mut VoiceState {
        &mut self.states[k]
    }

    fn voice_of_key(&self, key: usize) -> Option<usize> {
        self.voice_of_key[key]
    }

    fn set_voice_of_key(&mut self, key: usize, voice: Option<usize>) {
        self.voice_of_key[key] = voice;
    }

    fn fade_steps(&self) -> u32 {
        self.fade_steps
    }

    fn key_strings(&self, key: usize) -> usize {
        self.model.keys[key].n_strings
    }

    fn key_hammer(&self, key: usize) -> &HammerParams {
        &self.model.keys[key].hammer
    }

    fn key_has_damper(&self, key: usize) -> bool {
        !self.model.keys[key].damper_shapes.is_empty()
    }

    /// The loudest string's excursion from `sum_k sum_n (a_k psi_n(x_k))^2 (q_n^2 + qdot_n^2 /
    /// omega_n^2)` over the felt's points `k` (shares `a_k^2` summing to one) and the T modes
    /// `n`: the mean square of each mode's amplitude under the felt.
    fn felt_share(&self, k: usize, lift: f64) -> f64 {
        let Some(key) = self.states[k].key else {
            return 0.0;
        };
        let (km, voice) = (&self.model.keys[key], &self.model.voices[k]);
        let Some(felt) = km.damper else {
            return 0.0;
        };
        let amplitude_m = (0..voice.n_strings)
            .map(|s| {
                let r = voice.ranges[s][0].clone();
                let mut sum = 0.0;
                for shape in &km.damper_shapes {
                    for (j, i) in r.clone().enumerate() {
                        let (q, v) = (self.q[i].to_f64(), self.v[i].to_f64());
                        let w2 = self.model.omega2[i].to_f64();
                        sum += shape[j].to_f64().powi(2) * (q * q + v * v / w2);
                    }
                }
                sum
            })
            .fold(0.0, f64::max)
            .sqrt();
        felt.contact_share(lift, amplitude_m)
    }

    /// Copies the key's coefficients into the slot.
    fn load_key(&mut self, k: usize, key: usize) {
        let km = &self.model.keys[key];
        let voice = &mut self.model.voices[k];
        let (base, capacity_end) = (voice.base, voice.base + km.n_modes);
        let slot_end = self
            .model
            .voices
            .get(k + 1)
            .map_or(self.model.board.start, |v| v.base);
        debug_assert!(capacity_end <= slot_end);
        let voice = &mut self.model.voices[k];
        voice.n_strings = km.n_strings;
        voice.n_modes = km.n_modes;
        for (s, r) in voice.ranges.iter_mut().enumerate() {
            for d in 0..3 {
                let local = &km.ranges[s][d];
                r[d] = base + local.start..base + local.end;
            }
        }
        self.model.omega2[base..capacity_end].copy_from_slice(&km.omega2);
        self.model.damp[base..capacity_end].copy_from_slice(&km.damp);
        self.model.bridge_shape[base..capacity_end].copy_from_slice(&km.bridge_shape);
        self.model.static_shape[base..capacity_end].copy_from_slice(&km.static_shape);
        self.q[base..slot_end].fill(T::ZERO);
        self.v[base..slot_end].fill(T::ZERO);
        self.left_at[k] = [[0.0; 2]; 3];
    }

    fn rest_strings(&mut self, k: usize) {
        self.rest(self.voice_modes(k));
        self.left_at[k] = [[0.0; 2]; 3];
    }

    /// A string at rest enters at its static deflection by the bridge point (`g y`, moving with
    /// it), not at zero, which would jolt the board through the contact spring: `q += g (y -
    /// y_left)`, `qdot += g (y' - y'_left)` in each direction, `y_left` where the board was when
    /// the voice left (zero once its strings were set at rest).
    fn enter(&mut self, k: usize) {
        let (now, left) = (self.board_at(k), self.left_at[k]);
        let voice = &self.model.voices[k];
        for s in 0..voice.n_strings {
            for d in 0..3 {
                let dy = T::from_f64(now[d][0] - left[d][0]);
                let dv = T::from_f64(now[d][1] - left[d][1]);
                for i in voice.ranges[s][d].clone() {
                    let g = self.model.static_shape[i];
                    self.q[i] += g * dy;
                    self.v[i] += g * dv;
                }
            }
        }
        self.left_at[k] = [[0.0; 2]; 3];
    }

    fn leave(&mut self, k: usize) {
        self.left_at[k] = self.board_at(k);
    }

    fn strike_contact_m(&self, k: usize, struck: usize) -> f64 {
        let (voice, key) = (&self.model.voices[k], self.states[k].key);
        let Some(key) = key else {
            return 0.0;
        };
        let km = &self.model.keys[key];
        (0..struck)
            .map(|s| T::dot_wide::<false>(&km.hammer_shape, &self.q[voice.ranges[s][0].clone()]))
            .fold(f64::NEG_INFINITY, f64::max)
    }

    fn set_hammer(&mut self, k: usize, position_m: f64, velocity_m_s: f64) {
        (self.hammer_y[k], self.hammer_v[k]) = (position_m, velocity_m_s);
    }

    fn hammer_finite(&self, k: usize) -> bool {
        self.hammer_y[k].is_finite() && self.hammer_v[k].is_finite()
    }

    /// A string at rest on a moving board holds the energy of following it, and is not silent.
    fn voice_energy_j(&self, k: usize) -> f64 {
        if !self.states[k].active {
            return 0.0;
        }
        self.modal_energy_j(self.voice_modes(k)) + self.voice_contact_j(k)
    }

    fn board_energy_j(&self) -> f64 {
        self.modal_energy_j(self.model.board.clone())
    }

    fn rest_board(&mut self) {
        self.rest(self.model.board_and_residual());
    }
}
