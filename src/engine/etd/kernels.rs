//! The live integrator's inner loops over complex modes and board modes: reading output rows,
//! propagating with the stage inputs, reading and driving the board at a voice's point; each in
//! portable form and, where it pays, with explicit AVX2 + FMA.

use crate::engine::kernels::{Real, LANES};

/// Complex-mode state of one block (re, im), sized for the largest key's block.
#[derive(Debug, Clone, Default)]
pub(super) struct ComplexState {
    pub(super) re: Vec<f64>,
    pub(super) im: Vec<f64>,
}

impl ComplexState {
    pub(super) fn zeros(n: usize) -> ComplexState {
        ComplexState {
            re: vec![0.0; n],
            im: vec![0.0; n],
        }
    }
    pub(super) fn clear(&mut self) {
        self.re.fill(0.0);
        self.im.fill(0.0);
    }
}

/// `Re(r z)` through `row` over the first `row.len()` modes.
pub(super) fn read(row: &[Vec<f64>; 2], z: &ComplexState) -> f64 {
    let n = row[0].len();
    (0..n)
        .map(|m| row[0][m] * z.re[m] - row[1][m] * z.im[m])
        .sum()
}

/// `R` outputs, each through its three rows `r`, `r E`, `r E²`, read in one pass over `z`.
#[inline(always)]
pub(super) fn read_rows<const FMA: bool, const R: usize>(
    rows: [&[[Vec<f64>; 2]; 3]; R],
    z: &ComplexState,
) -> [[f64; 3]; R] {
    let n = rows[0][0][0].len();
    let (zr, zi) = (&z.re[..n], &z.im[..n]);
    #[cfg(target_arch = "x86_64")]
    if FMA {
        // SAFETY: `FMA` is true only inside `step_avx2`, entered after detecting AVX2 and FMA;
        // every row holds the block's `n` (a multiple of 4) modes and `z` at least as many.
        return unsafe { read_rows_avx2(zr, zi, rows) };
    }
    rows.map(|r| {
        r.each_ref()
            .map(|[re, im]| f64::dot::<FMA>(re, zr) - f64::dot::<FMA>(im, zi))
    })
}

/// `z <- e^{lambda h} z + sum_j (f1 g_j a_j + f2 g_j (b_j + c_j) + f3 g_j d_j)` for two inputs
/// `j` with stage values `u[j] = [a, b, c, d]`, in one pass.
#[inline(always)]
pub(super) fn propagate_drive<const FMA: bool>(
    e: &[Vec<f64>; 2],
    gains: [&[[Vec<f64>; 2]; 3]; 2],
    u: [[f64; 4]; 2],
    z: &mut ComplexState,
) {
    let n = e[0].len();
    let (er, ei) = (&e[0][..n], &e[1][..n]);
    let g = gains.map(|g| g.each_ref().map(|[re, im]| [&re[..n], &im[..n]]));
    let s = u.map(|u| [u[0], u[1] + u[2], u[3]]);
    let (zr, zi) = (&mut z.re[..n], &mut z.im[..n]);
    for m in 0..n {
        let (a, b) = (zr[m], zi[m]);
        let mut re = fma::<FMA>(er[m], a, -ei[m] * b);
        let mut im = fma::<FMA>(er[m], b, ei[m] * a);
        for (g, s) in g.iter().zip(&s) {
            for k in 0..3 {
                re = fma::<FMA>(g[k][0][m], s[k], re);
                im = fma::<FMA>(g[k][1][m], s[k], im);
            }
        }
        zr[m] = re;
        zi[m] = im;
    }
}

/// `z += f1 g a + f2 g (b + c) + f3 g d` for one input with stage values `[a, b, c, d]`.
#[inline(always)]
pub(super) fn drive<const FMA: bool>(gain: &[[Vec<f64>; 2]; 3], u: [f64; 4], z: &mut ComplexState) {
    let n = gain[0][0].len();
    let (zr, zi) = (&mut z.re[..n], &mut z.im[..n]);
    for (g, s) in gain.iter().zip([u[0], u[1] + u[2], u[3]]) {
        if s != 0.0 {
            let (gr, gi) = (&g[0][..n], &g[1][..n]);
            for m in 0..n {
                zr[m] = fma::<FMA>(gr[m], s, zr[m]);
                zi[m] = fma::<FMA>(gi[m], s, zi[m]);
            }
        }
    }
}

/// `sum |z|² e` over a block's modes (J).
pub(super) fn energy_j(e: &[f64], z: &ComplexState) -> f64 {
    e.iter()
        .zip(z.re.iter().zip(&z.im))
        .map(|(e, (r, i))| e * (r * r + i * i))
        .sum()
}

/// The board's acceleration at one point, `phi_d . acc` for d = T, L, P.
#[inline(always)]
pub(super) fn read_accel<const FMA: bool>(phi: &[Vec<f64>; 3], acc: &[f64]) -> [f64; 3] {
    std::array::from_fn(|d| f64::dot::<FMA>(&phi[d], acc))
}

/// [`read_rows`] with explicit AVX2 + FMA: `6 R` accumulators (re and im products of every
/// row) over `n` modes, `n` a multiple of 4 and every slice `n` long.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn read_rows_avx2<const R: usize>(
    zr: &[f64],
    zi: &[f64],
    rows: [&[[Vec<f64>; 2]; 3]; R],
) -> [[f64; 3]; R] {
    use std::arch::x86_64::*;
    let n = zr.len();
    debug_assert!(n.is_multiple_of(LANES) && zi.len() == n);
    let mut ptr = [[[std::ptr::null::<f64>(); 2]; 3]; R];
    for r in 0..R {
        for which in 0..3 {
            for k in 0..2 {
                ptr[r][which][k] = rows[r][which][k][..n].as_ptr();
            }
        }
    }
    let mut acc = [[[_mm256_setzero_pd(); 2]; 3]; R];
    let mut i = 0;
    while i < n {
        let z = [
            _mm256_loadu_pd(zr.as_ptr().add(i)),
            _mm256_loadu_pd(zi.as_ptr().add(i)),
        ];
        for (acc, ptr) in acc.iter_mut().zip(&ptr) {
            for (acc, ptr) in acc.iter_mut().zip(ptr) {
                for k in 0..2 {
                    acc[k] = _mm256_fmadd_pd(_mm256_loadu_pd(ptr[k].add(i)), z[k], acc[k]);
                }
            }
        }
        i += LANES;
    }
    // Horizontal sums written out (closures here would not inherit the target features).
    let mut out = [[0.0; 3]; R];
    for r in 0..R {
        for which in 0..3 {
            let mut x = [[0.0; LANES]; 2];
            _mm256_storeu_pd(x[0].as_mut_ptr(), acc[r][which][0]);
            _mm256_storeu_pd(x[1].as_mut_ptr(), acc[r][which][1]);
            out[r][which] = ((x[0][0] + x[0][1]) + (x[0][2] + x[0][3]))
                - ((x[1][0] + x[1][1]) + (x[1][2] + x[1][3]));
        }
    }
    out
}

/// The board at one point: `(phi_d . q, phi_d . qdot)` for d = T, L, P, in one pass over the modal
/// displacements and velocities `qv` (six accumulators, SIMD lanes).
#[inline(always)]
pub(super) fn read_point<const FMA: bool>(
    phi: &[Vec<f64>; 3],
    qv: &[Vec<f64>; 2],
) -> [[f64; 2]; 3] {
    #[cfg(target_arch = "x86_64")]
    if FMA {
        // SAFETY: `FMA` is true only inside `step_avx2`, entered after detecting AVX2 and FMA.
        return unsafe { read_point_avx2(phi, qv) };
    }
    std::array::from_fn(|d| {
        [
            f64::dot::<FMA>(&phi[d], &qv[0]),
            f64::dot::<FMA>(&phi[d], &qv[1]),
        ]
    })
}

/// [`read_point`] with explicit AVX2 + FMA.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn read_point_avx2(phi: &[Vec<f64>; 3], qv: &[Vec<f64>; 2]) -> [[f64; 2]; 3] {
    use std::arch::x86_64::*;
    let n = qv[0]
        .len()
        .min(qv[1].len())
        .min(phi.iter().map(Vec::len).min().unwrap_or(0));
    let (q, v) = (qv[0].as_ptr(), qv[1].as_ptr());
    let p = [phi[0].as_ptr(), phi[1].as_ptr(), phi[2].as_ptr()];
    let mut acc = [_mm256_setzero_pd(); 6];
    let mut i = 0;
    while i + LANES <= n {
        let (x, y) = (_mm256_loadu_pd(q.add(i)), _mm256_loadu_pd(v.add(i)));
        for d in 0..3 {
            let f = _mm256_loadu_pd(p[d].add(i));
            acc[2 * d] = _mm256_fmadd_pd(f, x, acc[2 * d]);
            acc[2 * d + 1] = _mm256_fmadd_pd(f, y, acc[2 * d + 1]);
        }
        i += LANES;
    }
    let mut out = [[0.0; 2]; 3];
    for d in 0..3 {
        for k in 0..2 {
            let mut x = [0.0; LANES];
            _mm256_storeu_pd(x.as_mut_ptr(), acc[2 * d + k]);
            out[d][k] = (x[0] + x[1]) + (x[2] + x[3]);
        }
    }
    for j in i..n {
        for d in 0..3 {
            out[d][0] += phi[d][j] * qv[0][j];
            out[d][1] += phi[d][j] * qv[1][j];
        }
    }
    out
}

/// `force += phi_T u_T + phi_L u_L + phi_P u_P`, in one pass.
#[inline(always)]
pub(super) fn drive_point<const FMA: bool>(force: &mut [f64], phi: &[Vec<f64>; 3], u: [f64; 3]) {
    let n = force.len();
    let (a, b, c) = (&phi[0][..n], &phi[1][..n], &phi[2][..n]);
    for i in 0..n {
        force[i] = fma::<FMA>(
            a[i],
            u[0],
            fma::<FMA>(b[i], u[1], fma::<FMA>(c[i], u[2], force[i])),
        );
    }
}

/// `a b + c`, fused when the step runs with FMA (a separate multiply and add otherwise, never
/// the slow software `fma`).
#[inline(always)]
pub(super) fn fma<const FMA: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::kernels::has_avx2_fma;

    /// Deterministic values in [-1, 1).
    fn values(n: usize, seed: u64) -> Vec<f64> {
        let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        (0..n)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                (x >> 11) as f64 / (1u64 << 52) as f64 - 1.0
            })
            .collect()
    }

    #[test]
    fn avx2_reads_agree_with_the_portable_ones() {
        if !has_avx2_fma() {
            println!("skipped: this CPU has no AVX2 + FMA");
            return;
        }
        let mut worst: f64 = 0.0;
        for n in (LANES..=48).step_by(LANES) {
            let z = ComplexState {
                re: values(n, 1),
                im: values(n, 2),
            };
            let rows: [[[Vec<f64>; 2]; 3]; 2] = std::array::from_fn(|r| {
                std::array::from_fn(|w| [values(n, 10 + 6 * r as u64 + w as u64), values(n, 40)])
            });
            let refs = [&rows[0], &rows[1]];
            let fast = unsafe { read_rows_avx2(&z.re, &z.im, refs) };
            let slow = read_rows::<false, 2>(refs, &z);
            for (f, s) in fast.iter().flatten().zip(slow.iter().flatten()) {
                worst = worst.max((f - s).abs());
            }
        }
        // read_point takes any length: every tail.
        for n in 0..=23 {
            let phi: [Vec<f64>; 3] = std::array::from_fn(|d| values(n, 70 + d as u64));
            let qv = [values(n, 80), values(n, 81)];
            let fast = unsafe { read_point_avx2(&phi, &qv) };
            let slow = read_point::<false>(&phi, &qv);
            for (f, s) in fast.iter().flatten().zip(slow.iter().flatten()) {
                worst = worst.max((f - s).abs());
            }
        }
        println!("AVX2 vs portable reads: largest difference {worst:.1e} (values of order 1)");
        assert!(worst < 1e-12, "{worst:e}");
    }
}
