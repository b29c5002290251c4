//! The RK4 engine's numeric kernels, in the two precisions it runs in.
//!
//! [`Real`] is `f64` (the reference) or `f32` (eight lanes per AVX2 register instead of four and
//! half the bytes; `tests/precision.rs` bounds its drift from `f64`). Each kernel has a portable
//! form written to vectorise without reassociation (independent lane accumulators) and an
//! AVX2 + FMA form, chosen by `SIMD`. Callers set `SIMD` only inside a function compiled with those
//! features, entered after [`has_avx2_fma`] reported them: the documented baseline runs on any
//! x86-64 (and elsewhere), the fast path is chosen at run time.

use std::fmt::Debug;
use std::ops::{Add, AddAssign, Mul, Neg, Sub};

/// Whether this CPU can run the AVX2 + FMA kernels.
pub fn has_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `f64` lanes in one AVX2 register.
pub(super) const LANES: usize = 4;

/// A floating-point type the RK4 engine's state and coefficients are held in.
pub trait Real:
    Copy
    + Default
    + PartialOrd
    + Debug
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Neg<Output = Self>
    + AddAssign
{
    const ZERO: Self;
    /// `"f64"` or `"f32"`, for reports.
    const NAME: &'static str;
    fn from_f64(x: f64) -> Self;
    fn to_f64(self) -> f64;
    /// `a·b` over the shorter length.
    fn dot<const SIMD: bool>(a: &[Self], b: &[Self]) -> Self;
    /// `a·b` accumulated in `f64` ([`Real::dot`] for `f64`): for the contact springs' stretch, a
    /// small difference of two such products, and for outputs and energies.
    fn dot_wide<const SIMD: bool>(a: &[Self], b: &[Self]) -> f64;
    /// `y += alpha x` over the shorter length.
    fn axpy<const SIMD: bool>(y: &mut [Self], x: &[Self], alpha: Self);
    /// `z[b * rank + j] = W[j, ..len] · v[offsets[b]..][..len]` for every block `b` of `offsets`
    /// (`W` row-major with `n` columns): each chunk of a row of `W` loaded once for all blocks.
    fn project<const SIMD: bool>(
        w: &[Self],
        n: usize,
        rank: usize,
        len: usize,
        v: &[Self],
        offsets: &[usize],
        z: &mut [Self],
    );
    /// `acc[offsets[b]..][..len] -= W[..rank, ..len]ᵀ z[b * rank..][..rank]` for every block `b`
    /// of `offsets` (disjoint), the transpose of [`Real::project`].
    #[allow(clippy::too_many_arguments)]
    fn project_back<const SIMD: bool>(
        w: &[Self],
        n: usize,
        rank: usize,
        len: usize,
        z: &[Self],
        offsets: &[usize],
        acc: &mut [Self],
    );
}

/// The portable and AVX2 kernels of one precision: its type, lanes per register, and the AVX2
/// intrinsics for that lane type.
macro_rules! real {
    ($t:ident, $name:literal, $lanes:literal, $m:ident, $wide:ident,
     $load:ident, $store:ident, $maskload:ident, $maskstore:ident, $mask:ident,
     $set1:ident, $zero:ident, $add:ident, $fmadd:ident, $fnmadd:ident, $hsum:ident) => {
        impl Real for $t {
            const ZERO: Self = 0.0;
            const NAME: &'static str = $name;
            #[inline(always)]
            fn from_f64(x: f64) -> Self {
                x as $t
            }
            #[inline(always)]
            fn to_f64(self) -> f64 {
                f64::from(self)
            }
            #[inline(always)]
            fn dot<const SIMD: bool>(a: &[Self], b: &[Self]) -> Self {
                #[cfg(target_arch = "x86_64")]
                if SIMD {
                    // SAFETY: `SIMD` is set only where AVX2 and FMA were detected.
                    return unsafe { $m::dot(a, b) };
                }
                let n = a.len().min(b.len());
                let (a, b) = (&a[..n], &b[..n]);
                let mut lanes = [0.0; $lanes];
                let split = n - n % $lanes;
                for (ca, cb) in a[..split]
                    .chunks_exact($lanes)
                    .zip(b[..split].chunks_exact($lanes))
                {
                    for l in 0..$lanes {
                        lanes[l] += ca[l] * cb[l];
                    }
                }
                // Pairwise over the lanes, as the AVX2 horizontal sum.
                let mut width = $lanes;
                while width > 1 {
                    width /= 2;
                    for l in 0..width {
                        lanes[l] += lanes[l + width];
                    }
                }
                let mut sum = lanes[0];
                for i in split..n {
                    sum += a[i] * b[i];
                }
                sum
            }
            #[inline(always)]
            fn dot_wide<const SIMD: bool>(a: &[Self], b: &[Self]) -> f64 {
                $wide::<SIMD>(a, b)
            }
            #[inline(always)]
            fn axpy<const SIMD: bool>(y: &mut [Self], x: &[Self], alpha: Self) {
                #[cfg(target_arch = "x86_64")]
                if SIMD {
                    // SAFETY: as in `dot`.
                    unsafe { $m::axpy(y, x, alpha) };
                    return;
                }
                for (yi, xi) in y.iter_mut().zip(x) {
                    *yi += alpha * xi;
                }
            }
            #[inline(always)]
            fn project<const SIMD: bool>(
                w: &[Self],
                n: usize,
                rank: usize,
                len: usize,
                v: &[Self],
                offsets: &[usize],
                z: &mut [Self],
            ) {
                #[cfg(target_arch = "x86_64")]
                if SIMD {
                    // SAFETY: as in `dot`.
                    unsafe {
                        match offsets.len() {
                            1 => $m::project::<1>(w, n, rank, len, v, offsets, z),
                            2 => $m::project::<2>(w, n, rank, len, v, offsets, z),
                            4 => $m::project::<4>(w, n, rank, len, v, offsets, z),
                            6 => $m::project::<6>(w, n, rank, len, v, offsets, z),
                            _ => project_rows::<$t, true>(w, n, rank, len, v, offsets, z),
                        }
                    }
                    return;
                }
                project_rows::<$t, false>(w, n, rank, len, v, offsets, z)
            }
            #[inline(always)]
            fn project_back<const SIMD: bool>(
                w: &[Self],
                n: usize,
                rank: usize,
                len: usize,
                z: &[Self],
                offsets: &[usize],
                acc: &mut [Self],
            ) {
                #[cfg(target_arch = "x86_64")]
                if SIMD {
                    // SAFETY: as in `dot`.
                    unsafe {
                        match offsets.len() {
                            1 => $m::project_back::<1>(w, n, rank, len, z, offsets, acc),
                            2 => $m::project_back::<2>(w, n, rank, len, z, offsets, acc),
                            4 => $m::project_back::<4>(w, n, rank, len, z, offsets, acc),
                            6 => $m::project_back::<6>(w, n, rank, len, z, offsets, acc),
                            _ => project_back_rows::<$t, true>(w, n, rank, len, z, offsets, acc),
                        }
                    }
                    return;
                }
                project_back_rows::<$t, false>(w, n, rank, len, z, offsets, acc)
            }
        }

        /// The AVX2 + FMA kernels of this precision.
        #[cfg(target_arch = "x86_64")]
        mod $m {
            use std::arch::x86_64::*;

            const LANES: usize = $lanes;

            /// `a·b` over the shorter length, two FMA chains.
            ///
            /// # Safety
            /// The CPU must support AVX2 and FMA.
            #[target_feature(enable = "avx2,fma")]
            #[inline]
            pub(super) unsafe fn dot(a: &[$t], b: &[$t]) -> $t {
                let n = a.len().min(b.len());
                let (pa, pb) = (a.as_ptr(), b.as_ptr());
                let (mut s0, mut s1) = ($zero(), $zero());
                let mut i = 0;
                // SAFETY (loads): every index read is below `n`, within both slices.
                while i + 2 * LANES <= n {
                    s0 = $fmadd($load(pa.add(i)), $load(pb.add(i)), s0);
                    s1 = $fmadd($load(pa.add(i + LANES)), $load(pb.add(i + LANES)), s1);
                    i += 2 * LANES;
                }
                if i + LANES <= n {
                    s0 = $fmadd($load(pa.add(i)), $load(pb.add(i)), s0);
                    i += LANES;
                }
                let mut sum = super::lanes::$hsum($add(s0, s1));
                while i < n {
                    sum += a[i] * b[i];
                    i += 1;
                }
                sum
            }

            /// `y += alpha x` over the shorter length.
            ///
            /// # Safety
            /// The CPU must support AVX2 and FMA.
            #[target_feature(enable = "avx2,fma")]
            #[inline]
            pub(super) unsafe fn axpy(y: &mut [$t], x: &[$t], alpha: $t) {
                let n = y.len().min(x.len());
                let (py, px) = (y.as_mut_ptr(), x.as_ptr());
                let a = $set1(alpha);
                let mut i = 0;
                // SAFETY (loads and stores): every index touched is below `n`.
                while i + LANES <= n {
                    $store(py.add(i), $fmadd(a, $load(px.add(i)), $load(py.add(i))));
                    i += LANES;
                }
                while i < n {
                    y[i] += alpha * x[i];
                    i += 1;
                }
            }

            /// [`super::Real::project`] for `K` blocks, two rows of `W` at a time: each
            /// chunk of `W` is loaded once for all blocks and `2 K` FMA chains run side by side.
            ///
            /// # Safety
            /// The CPU must support AVX2 and FMA.
            #[target_feature(enable = "avx2,fma")]
            #[inline]
            pub(super) unsafe fn project<const K: usize>(
                w: &[$t],
                n: usize,
                rank: usize,
                len: usize,
                v: &[$t],
                offsets: &[usize],
                z: &mut [$t],
            ) {
                assert!(
                    len <= n
                        && (rank == 0 || (rank - 1) * n + len <= w.len())
                        && z.len() >= K * rank
                        && offsets.len() == K
                );
                for &o in offsets {
                    assert!(o + len <= v.len());
                }
                let mut j = 0;
                while j + 2 <= rank {
                    project_rows::<K, 2>(w, n, j, len, v, offsets, rank, z);
                    j += 2;
                }
                if j < rank {
                    project_rows::<K, 1>(w, n, j, len, v, offsets, rank, z);
                }
            }

            /// Rows `j..j + R` of [`project`].
            ///
            /// # Safety
            /// The CPU must support AVX2 and FMA; the bounds are those asserted by [`project`].
            #[target_feature(enable = "avx2,fma")]
            #[inline]
            #[allow(clippy::too_many_arguments)]
            unsafe fn project_rows<const K: usize, const R: usize>(
                w: &[$t],
                n: usize,
                j: usize,
                len: usize,
                v: &[$t],
                offsets: &[usize],
                rank: usize,
                z: &mut [$t],
            ) {
                let (pw, pv) = (w.as_ptr(), v.as_ptr());
                let mut s = [[$zero(); K]; R];
                let mut i = 0;
                // SAFETY (loads): columns below `len` of rows below `rank` lie inside `w`,
                // and `offsets[b] + i < v.len()` (asserted by the caller); the tail's masked
                // loads touch no column at or past `len`.
                while i + LANES <= len {
                    let c: [_; R] = std::array::from_fn(|r| $load(pw.add((j + r) * n + i)));
                    for b in 0..K {
                        let x = $load(pv.add(offsets[b] + i));
                        for r in 0..R {
                            s[r][b] = $fmadd(c[r], x, s[r][b]);
                        }
                    }
                    i += LANES;
                }
                if i < len {
                    let m = super::lanes::$mask(len - i);
                    let c: [_; R] = std::array::from_fn(|r| $maskload(pw.add((j + r) * n + i), m));
                    for b in 0..K {
                        let x = $maskload(pv.add(offsets[b] + i), m);
                        for r in 0..R {
                            s[r][b] = $fmadd(c[r], x, s[r][b]);
                        }
                    }
                }
                for r in 0..R {
                    for b in 0..K {
                        z[b * rank + j + r] = super::lanes::$hsum(s[r][b]);
                    }
                }
            }

            /// [`super::Real::project_back`] for `K` blocks: two chunks of every block stay
            /// in registers while the rows are folded into them (`2 K` FMA chains), so each
            /// block is loaded and stored once and each chunk of `W` loaded once for all.
            ///
            /// # Safety
            /// The CPU must support AVX2 and FMA.
            #[target_feature(enable = "avx2,fma")]
            #[inline]
            pub(super) unsafe fn project_back<const K: usize>(
                w: &[$t],
                n: usize,
                rank: usize,
                len: usize,
                z: &[$t],
                offsets: &[usize],
                acc: &mut [$t],
            ) {
                assert!(
                    len <= n
                        && (rank == 0 || (rank - 1) * n + len <= w.len())
                        && z.len() >= K * rank
                        && offsets.len() == K
                );
                for &o in offsets {
                    assert!(o + len <= acc.len());
                }
                let mut i = 0;
                while i + 2 * LANES <= len {
                    project_back_chunks::<K, 2>(w, n, rank, i, z, offsets, acc);
                    i += 2 * LANES;
                }
                if i + LANES <= len {
                    project_back_chunks::<K, 1>(w, n, rank, i, z, offsets, acc);
                    i += LANES;
                }
                if i < len {
                    // The last columns, masked: lanes at or past `len` are neither loaded
                    // nor stored.
                    let m = super::lanes::$mask(len - i);
                    let (pw, pa) = (w.as_ptr(), acc.as_mut_ptr());
                    let mut a: [_; K] =
                        std::array::from_fn(|b| $maskload(pa.add(offsets[b] + i), m));
                    for j in 0..rank {
                        let c = $maskload(pw.add(j * n + i), m);
                        for b in 0..K {
                            a[b] = $fnmadd(c, $set1(z[b * rank + j]), a[b]);
                        }
                    }
                    for b in 0..K {
                        $maskstore(pa.add(offsets[b] + i), m, a[b]);
                    }
                }
            }

            /// Columns `i..i + C LANES` of [`project_back`].
            ///
            /// # Safety
            /// The CPU must support AVX2 and FMA; the bounds are those asserted by
            /// [`project_back`], with `i + C LANES <= len`.
            #[target_feature(enable = "avx2,fma")]
            #[inline]
            unsafe fn project_back_chunks<const K: usize, const C: usize>(
                w: &[$t],
                n: usize,
                rank: usize,
                i: usize,
                z: &[$t],
                offsets: &[usize],
                acc: &mut [$t],
            ) {
                let (pw, pa) = (w.as_ptr(), acc.as_mut_ptr());
                // SAFETY (loads and stores): rows below `rank` and columns below `len` lie
                // inside `w`, and `offsets[b] + len <= acc.len()` (asserted by the caller).
                let mut a: [[_; K]; C] = std::array::from_fn(|c| {
                    std::array::from_fn(|b| $load(pa.add(offsets[b] + i + c * LANES)))
                });
                for j in 0..rank {
                    let c: [_; C] = std::array::from_fn(|c| $load(pw.add(j * n + i + c * LANES)));
                    for b in 0..K {
                        let zb = $set1(z[b * rank + j]);
                        for c2 in 0..C {
                            a[c2][b] = $fnmadd(c[c2], zb, a[c2][b]);
                        }
                    }
                }
                for c in 0..C {
                    for b in 0..K {
                        $store(pa.add(offsets[b] + i + c * LANES), a[c][b]);
                    }
                }
            }
        }
    };
}

/// The portable back-projection, one row of `W` at a time.
#[inline(always)]
fn project_back_rows<T: Real, const SIMD: bool>(
    w: &[T],
    n: usize,
    rank: usize,
    len: usize,
    z: &[T],
    offsets: &[usize],
    acc: &mut [T],
) {
    for (b, &o) in offsets.iter().enumerate() {
        for j in 0..rank {
            T::axpy::<SIMD>(
                &mut acc[o..o + len],
                &w[j * n..j * n + len],
                -z[b * rank + j],
            );
        }
    }
}

/// `a·b` of `f64` values: the dot product itself.
#[inline(always)]
fn dot_f64_of_f64<const SIMD: bool>(a: &[f64], b: &[f64]) -> f64 {
    f64::dot::<SIMD>(a, b)
}

/// `a·b` of `f32` values accumulated in `f64` (exact products, four lanes).
#[inline(always)]
fn dot_f64_of_f32<const SIMD: bool>(a: &[f32], b: &[f32]) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if SIMD {
        // SAFETY: `SIMD` is set only where AVX2 and FMA were detected.
        return unsafe { lanes::dot_f64_of_f32(a, b) };
    }
    let n = a.len().min(b.len());
    let mut lanes = [0.0f64; LANES];
    let split = n - n % LANES;
    for (ca, cb) in a[..split]
        .chunks_exact(LANES)
        .zip(b[..split].chunks_exact(LANES))
    {
        for l in 0..LANES {
            lanes[l] += f64::from(ca[l]) * f64::from(cb[l]);
        }
    }
    let mut sum = (lanes[0] + lanes[2]) + (lanes[1] + lanes[3]);
    for i in split..n {
        sum += f64::from(a[i]) * f64::from(b[i]);
    }
    sum
}

/// The portable projection, one row of `W` at a time (also the AVX2 path's fallback for block
/// counts without a kernel).
#[inline(always)]
fn project_rows<T: Real, const SIMD: bool>(
    w: &[T],
    n: usize,
    rank: usize,
    len: usize,
    v: &[T],
    offsets: &[usize],
    z: &mut [T],
) {
    for (b, &o) in offsets.iter().enumerate() {
        for j in 0..rank {
            z[b * rank + j] = T::dot::<SIMD>(&w[j * n..j * n + len], &v[o..o + len]);
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod lanes {
    use std::arch::x86_64::*;

    /// Sum of four f64 lanes as `(s0 + s2) + (s1 + s3)`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(super) unsafe fn hsum_pd(s: __m256d) -> f64 {
        let h = _mm_add_pd(_mm256_castpd256_pd128(s), _mm256_extractf128_pd(s, 1));
        _mm_cvtsd_f64(_mm_add_sd(h, _mm_unpackhi_pd(h, h)))
    }

    /// Sum of eight f32 lanes, pairwise: `i + (i + 4)`, then `+ (i + 2)`, then `+ (i + 1)`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(super) unsafe fn hsum_ps(s: __m256) -> f32 {
        let h = _mm_add_ps(_mm256_castps256_ps128(s), _mm256_extractf128_ps(s, 1));
        let h = _mm_add_ps(h, _mm_movehl_ps(h, h));
        _mm_cvtss_f32(_mm_add_ss(h, _mm_shuffle_ps(h, h, 1)))
    }

    /// `a·b` of `f32` values in `f64`: four values widened per FMA, two chains.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(super) unsafe fn dot_f64_of_f32(a: &[f32], b: &[f32]) -> f64 {
        let n = a.len().min(b.len());
        let (pa, pb) = (a.as_ptr(), b.as_ptr());
        let (mut s0, mut s1) = (_mm256_setzero_pd(), _mm256_setzero_pd());
        let wide = |p: *const f32| _mm256_cvtps_pd(_mm_loadu_ps(p));
        let mut i = 0;
        // SAFETY (loads): every index read is below `n`, within both slices.
        while i + 8 <= n {
            s0 = _mm256_fmadd_pd(wide(pa.add(i)), wide(pb.add(i)), s0);
            s1 = _mm256_fmadd_pd(wide(pa.add(i + 4)), wide(pb.add(i + 4)), s1);
            i += 8;
        }
        if i + 4 <= n {
            s0 = _mm256_fmadd_pd(wide(pa.add(i)), wide(pb.add(i)), s0);
            i += 4;
        }
        let mut sum = hsum_pd(_mm256_add_pd(s0, s1));
        while i < n {
            sum += f64::from(a[i]) * f64::from(b[i]);
            i += 1;
        }
        sum
    }

    /// Load/store mask of the first `n` of four f64 lanes (`n < 4`).
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(super) unsafe fn mask_pd(n: usize) -> __m256i {
        _mm256_cmpgt_epi64(_mm256_set1_epi64x(n as i64), _mm256_setr_epi64x(0, 1, 2, 3))
    }

    /// Load/store mask of the first `n` of eight f32 lanes (`n < 8`).
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(super) unsafe fn mask_ps(n: usize) -> __m256i {
        _mm256_cmpgt_epi32(
            _mm256_set1_epi32(n as i32),
            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
        )
    }
}

real!(
    f64,
    "f64",
    4,
    avx2_f64,
    dot_f64_of_f64,
    _mm256_loadu_pd,
    _mm256_storeu_pd,
    _mm256_maskload_pd,
    _mm256_maskstore_pd,
    mask_pd,
    _mm256_set1_pd,
    _mm256_setzero_pd,
    _mm256_add_pd,
    _mm256_fmadd_pd,
    _mm256_fnmadd_pd,
    hsum_pd
);
real!(
    f32,
    "f32",
    8,
    avx2_f32,
    dot_f64_of_f32,
    _mm256_loadu_ps,
    _mm256_storeu_ps,
    _mm256_maskload_ps,
    _mm256_maskstore_ps,
    mask_ps,
    _mm256_set1_ps,
    _mm256_setzero_ps,
    _mm256_add_ps,
    _mm256_fmadd_ps,
    _mm256_fnmadd_ps,
    hsum_ps
);

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic values in [-0.5, 0.5).
    fn values<T: Real>(n: usize, seed: usize) -> Vec<T> {
        (0..n)
            .map(|k| T::from_f64(((k * seed) % 997) as f64 / 997.0 - 0.5))
            .collect()
    }

    /// The AVX2 projections against the portable ones, for every block count with a kernel and
    /// lengths that exercise the masked tail; `tol` relative to the terms' size.
    fn projections_agree<T: Real>(tol: f64) {
        let (n, rank) = (103, 16);
        let w = values::<T>(n * rank, 7919);
        let v = values::<T>(6 * n + 9, 104_729);
        for k in [1, 2, 4, 6] {
            let offsets: Vec<usize> = (0..k).map(|b| b * n + b % 3).collect();
            for len in [0, 1, 5, 7, 8, 9, 17, 100, 103] {
                let (mut fast, mut slow) = (vec![T::ZERO; k * rank], vec![T::ZERO; k * rank]);
                T::project::<true>(&w, n, rank, len, &v, &offsets, &mut fast);
                T::project::<false>(&w, n, rank, len, &v, &offsets, &mut slow);
                for (a, b) in fast.iter().zip(&slow) {
                    let d = (a.to_f64() - b.to_f64()).abs();
                    assert!(
                        d < tol * (len + 1) as f64,
                        "{}: project k {k} len {len}: {d}",
                        T::NAME
                    );
                }
                let (mut fast_acc, mut slow_acc) = (v.clone(), v.clone());
                T::project_back::<true>(&w, n, rank, len, &slow, &offsets, &mut fast_acc);
                T::project_back::<false>(&w, n, rank, len, &slow, &offsets, &mut slow_acc);
                for (i, (a, b)) in fast_acc.iter().zip(&slow_acc).enumerate() {
                    let d = (a.to_f64() - b.to_f64()).abs();
                    assert!(
                        d < tol * (len + 1) as f64,
                        "{}: back k {k} len {len} at {i}: {d}",
                        T::NAME
                    );
                }
            }
        }
    }

    /// The AVX2 dot products and `axpy` against the portable ones.
    fn kernels_agree<T: Real>(tol: f64) {
        let (x, y) = (values::<T>(203, 7919), values::<T>(203, 104_729));
        for n in [0, 1, 3, 4, 7, 8, 9, 15, 16, 17, 100, 203] {
            let (a, b) = (&x[..n], &y[..n]);
            let d = (T::dot::<true>(a, b).to_f64() - T::dot::<false>(a, b).to_f64()).abs();
            assert!(d < tol * (n + 1) as f64, "{}: dot, n = {n}: {d}", T::NAME);
            let d = (T::dot_wide::<true>(a, b) - T::dot_wide::<false>(a, b)).abs();
            assert!(
                d < 1e-14 * (n + 1) as f64,
                "{}: wide dot, n = {n}: {d}",
                T::NAME
            );
            let exact: f64 = a.iter().zip(b).map(|(p, q)| p.to_f64() * q.to_f64()).sum();
            assert!((T::dot_wide::<true>(a, b) - exact).abs() < 1e-14 * (n + 1) as f64);
            let (mut y1, mut y2) = (b.to_vec(), b.to_vec());
            T::axpy::<false>(&mut y1, a, T::from_f64(0.37));
            T::axpy::<true>(&mut y2, a, T::from_f64(0.37));
            let d = y1
                .iter()
                .zip(&y2)
                .map(|(p, q)| (p.to_f64() - q.to_f64()).abs())
                .fold(0.0, f64::max);
            assert!(d < tol, "{}: axpy, n = {n}: {d}", T::NAME);
        }
    }

    #[test]
    fn avx2_kernels_agree_with_the_portable_ones_in_f64_and_f32() {
        if !has_avx2_fma() {
            println!("skipped: this CPU has no AVX2 + FMA, so the kernels compared here never run");
            return;
        }
        kernels_agree::<f64>(1e-15);
        kernels_agree::<f32>(1e-6);
        projections_agree::<f64>(1e-15);
        projections_agree::<f32>(1e-6);
    }

    #[test]
    fn the_portable_dot_product_is_exact_on_integers() {
        // Small integers are exact in both precisions, whatever the order of the sums.
        let a: Vec<f32> = (0..37).map(|k| (k % 5) as f32).collect();
        let b: Vec<f32> = (0..37).map(|k| (k % 3) as f32 - 1.0).collect();
        let exact: f64 = a.iter().zip(&b).map(|(x, y)| f64::from(x * y)).sum();
        assert_eq!(f32::dot::<false>(&a, &b).to_f64(), exact);
        assert_eq!(f32::dot_wide::<false>(&a, &b), exact);
        let (a64, b64): (Vec<f64>, Vec<f64>) = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (f64::from(*x), f64::from(*y)))
            .unzip();
        assert_eq!(f64::dot::<false>(&a64, &b64), exact);
    }
}
