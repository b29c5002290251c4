//! One RK4 stage and the right-hand side of Eq. 10 over the live modes, with the duplex
//! damping (Eq. 13) through its low-rank factor.

use super::*;

/// One RK4 stage over the entries `r` of a second-order state `(q, v)` with acceleration `acc`
/// (modes, or hammers): the stage sums take the derivative (`v0` at the first stage, the stage
/// velocity after; weight 1 at the first stage, 2 after), and the next stage point is
/// `(q0, v0) + ch (dq, acc)`. Sliced to equal lengths first, so the loop vectorises.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn stage<T: Real, const FIRST: bool>(
    ch: T,
    r: Range<usize>,
    q0: &[T],
    v0: &[T],
    acc: &[T],
    qs: &mut [T],
    vs: &mut [T],
    sum_q: &mut [T],
    sum_v: &mut [T],
) {
    let two = T::from_f64(2.0);
    let n = r.len();
    let (q0, v0, acc) = (&q0[r.clone()], &v0[r.clone()][..n], &acc[r.clone()][..n]);
    let (qs, vs) = (&mut qs[r.clone()][..n], &mut vs[r.clone()][..n]);
    let (sum_q, sum_v) = (&mut sum_q[r.clone()][..n], &mut sum_v[r][..n]);
    for i in 0..n {
        let dq = if FIRST { v0[i] } else { vs[i] };
        if FIRST {
            sum_q[i] = dq;
            sum_v[i] = acc[i];
        } else {
            sum_q[i] += two * dq;
            sum_v[i] += two * acc[i];
        }
        qs[i] = q0[i] + ch * dq;
        vs[i] = v0[i] + ch * acc[i];
    }
}

/// Right-hand side of Eq. 10 over the `live` modes: writes their accelerations into `acc` and each
/// hammer's into `ah`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn evaluate<T: Real, const SIMD: bool>(
    m: &Model<T>,
    states: &[VoiceState],
    live: &[Range<usize>],
    q: &[T],
    v: &[T],
    hammer_y: &[f64],
    hammer_v: &[f64],
    acc: &mut [T],
    ah: &mut [f64],
    duplex_z: &mut [T],
) {
    // Uncoupled modal oscillators: -Omega^2 q - C qdot (diagonal blocks of Eq. 11).
    for r in live {
        let n = r.len();
        let (w2, d) = (&m.omega2[r.clone()], &m.damp[r.clone()][..n]);
        let (q, v, a) = (
            &q[r.clone()][..n],
            &v[r.clone()][..n],
            &mut acc[r.clone()][..n],
        );
        for i in 0..n {
            a[i] = -w2[i] * q[i] - d[i] * v[i];
        }
    }
    let qb = &q[m.board.clone()];
    let vb = &v[m.board.clone()];
    for (k, voice) in m.voices.iter().enumerate() {
        ah[k] = 0.0;
        let (true, Some(key)) = (states[k].active, states[k].key) else {
            continue;
        };
        let km = &m.keys[key];
        let gain = states[k].coupling;
        // This voice's bridge point of the board in T, L, P (Eq. 5).
        let mut rb = [0.0; 3];
        let mut rb_dot = [0.0; 3];
        for d in 0..3 {
            rb[d] = T::dot_wide::<SIMD>(&km.board_shape[d], qb);
            rb_dot[d] = T::dot::<SIMD>(&km.board_shape[d], vb).to_f64();
        }
        // Contact forces (Eq. 6) and their modal projections on each string (Eq. 17).
        let mut total = [0.0; 3];
        for s in 0..voice.n_strings {
            for d in 0..3 {
                let r = voice.ranges[s][d].clone();
                let shape = &m.bridge_shape[r.clone()];
                let rs = T::dot_wide::<SIMD>(shape, &q[r.clone()]);
                let rs_dot = T::dot::<SIMD>(shape, &v[r.clone()]).to_f64();
                let f = gain * km.contact.force_n(d, rs - rb[d], rs_dot - rb_dot[d]);
                total[d] += f;
                T::axpy::<SIMD>(&mut acc[r], shape, T::from_f64(-f));
            }
        }
        // Duplex damping on both transverse polarisations of every string (Eq. 13).
        duplex_damping::<T, SIMD>(km, &voice.ranges, v, acc, duplex_z);
        // The damper felt, while it touches (its share of the felt: all of it while down): at each
        // of its points, a point damper on T and P of every string. The share may belong to the
        // key that follows a fading voice, so the key's own damper decides.
        let share = states[k].felt_share();
        if share > 0.0 {
            let c = share * km.damper_n_s_m;
            for shape in &km.damper_shapes {
                for s in 0..voice.n_strings {
                    for d in [0, 2] {
                        let r = voice.ranges[s][d].clone();
                        let shape = &shape[..r.len()];
                        let f = c * T::dot::<SIMD>(shape, &v[r.clone()]).to_f64();
                        T::axpy::<SIMD>(&mut acc[r], shape, T::from_f64(-f));
                    }
                }
            }
        }
        // The board receives the sum of the strings' forces at this voice's point (Eq. 17).
        let ab = &mut acc[m.board.clone()];
        for d in 0..3 {
            T::axpy::<SIMD>(ab, &km.board_shape[d], T::from_f64(total[d]));
        }
        // ... and the board's dropped modes, which do not push back (every key's at its own point,
        // the same modes: `pool::check_keys`; none, empty).
        let ar = &mut acc[m.residual.clone()];
        for d in 0..3 {
            T::axpy::<SIMD>(ar, &km.residual_shape[d], T::from_f64(total[d]));
        }
        // Hammer (Eq. 8, 14): felt force on each struck string, reaction on the hammer mass.
        if states[k].hammer_on {
            let mut felt_total = 0.0;
            for s in 0..voice.n_strings {
                if let Some(law) = &states[k].felt[s] {
                    let r = voice.ranges[s][0].clone();
                    let ye = T::dot::<SIMD>(&km.hammer_shape, &q[r.clone()]).to_f64();
                    let ve = if km.hammer.is_hysteretic() {
                        T::dot::<SIMD>(&km.hammer_shape, &v[r.clone()]).to_f64()
                    } else {
                        0.0
                    };
                    let f = law.force_n(hammer_y[k] - ye, hammer_v[k] - ve, km.hammer.hysteresis_s);
                    felt_total += f;
                    T::axpy::<SIMD>(&mut acc[r], &km.hammer_shape, T::from_f64(f));
                }
            }
            ah[k] = -felt_total / km.hammer.mass_kg;
        }
    }
}

/// `acc -= C_d v` on the T and P blocks of every string (Eq. 13), through `C_d = Wᵀ W`: first
/// `z = W v` for every block, then `acc -= Wᵀ z`. All blocks share `W`, so each of its rows is
/// loaded once for all of them (when they have one length).
#[inline(always)]
pub(super) fn duplex_damping<T: Real, const SIMD: bool>(
    m: &Rk4Key<T>,
    ranges: &[[Range<usize>; 3]; MAX_STRINGS],
    v: &[T],
    acc: &mut [T],
    z: &mut [T],
) {
    let (n, rank) = (m.duplex_n, m.duplex_rank);
    let blocks = (0..m.n_strings).flat_map(|s| [ranges[s][0].clone(), ranges[s][2].clone()]);
    let (nt, np) = (ranges[0][0].len(), ranges[0][2].len());
    let mut offsets = [0; 2 * MAX_STRINGS];
    for (o, r) in offsets.iter_mut().zip(blocks.clone()) {
        *o = r.start;
    }
    let k = 2 * m.n_strings;
    if nt == np {
        T::project::<SIMD>(&m.duplex_w, n, rank, nt, v, &offsets[..k], z);
        T::project_back::<SIMD>(&m.duplex_w, n, rank, nt, z, &offsets[..k], acc);
        return;
    }
    for (b, r) in blocks.enumerate() {
        let (o, len, zb) = (&[r.start], r.len(), &mut z[b * rank..(b + 1) * rank]);
        T::project::<SIMD>(&m.duplex_w, n, rank, len, v, o, zb);
        T::project_back::<SIMD>(&m.duplex_w, n, rank, len, zb, o, acc);
    }
}
