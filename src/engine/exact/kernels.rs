//! The exact engine's loops over a key's complex modes, real and imaginary parts apart: the
//! propagation `z <- e ⊙ z`, the inputs that enter over the step and the rows read after it, in
//! one pass (8-lane partial sums so that the loop vectorises; AVX2 + FMA where the CPU has them).

use crate::engine::kernels::has_avx2_fma;
use crate::engine::physics::damper::FELT_POINTS;
use crate::engine::spec::{CHANNELS, MAX_STRINGS};
use faer::c64;
use std::ops::Range;

/// A complex vector per mode, real and imaginary parts apart (the kernels' layout).
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Split {
    pub(crate) re: Vec<f64>,
    pub(crate) im: Vec<f64>,
}

impl Split {
    pub(crate) fn new(v: &[c64]) -> Split {
        Split {
            re: v.iter().map(|x| x.re).collect(),
            im: v.iter().map(|x| x.im).collect(),
        }
    }

    pub(crate) fn zeros(n: usize) -> Split {
        Split {
            re: vec![0.0; n],
            im: vec![0.0; n],
        }
    }

    /// Mode `m` of `g` times `f(m)`.
    pub(crate) fn weighted_by(g: &Split, f: impl Fn(usize) -> c64) -> Split {
        let p: Vec<c64> = (0..g.len())
            .map(|m| c64::new(g.re[m], g.im[m]) * f(m))
            .collect();
        Split::new(&p)
    }

    /// Mode `m` of `g` times `f(weights[m])` (a mode's weights of an input over the step).
    pub(crate) fn weighted(g: &Split, weights: &[[c64; 2]], f: impl Fn([c64; 2]) -> c64) -> Split {
        Split::weighted_by(g, |m| f(weights[m]))
    }

    pub(crate) fn len(&self) -> usize {
        self.re.len()
    }

    /// `Re(r z)` of a row `r` (self) and the first `self.len()` modes of a state `z` (or of an
    /// input `g`: what a unit of it adds to the read).
    pub(crate) fn read(&self, z: &Split) -> f64 {
        let mut acc = 0.0;
        for m in 0..self.re.len() {
            acc += self.re[m] * z.re[m] - self.im[m] * z.im[m];
        }
        acc
    }

    /// `z += g u` on the first `self.len()` modes.
    pub(crate) fn add_to(&self, z: &mut Split, u: f64) {
        for m in 0..self.re.len() {
            z.re[m] += self.re[m] * u;
            z.im[m] += self.im[m] * u;
        }
    }

    /// `z += g u` on the modes in `range` (within `self`'s).
    pub(crate) fn add_range_to(&self, z: &mut Split, u: f64, range: Range<usize>) {
        for m in range {
            z.re[m] += self.re[m] * u;
            z.im[m] += self.im[m] * u;
        }
    }

    /// `z *= x`.
    pub(crate) fn scale(&mut self, x: f64) {
        self.re.iter_mut().for_each(|v| *v *= x);
        self.im.iter_mut().for_each(|v| *v *= x);
    }

    pub(crate) fn fill_zero(&mut self) {
        self.re.iter_mut().for_each(|x| *x = 0.0);
        self.im.iter_mut().for_each(|x| *x = 0.0);
    }
}

/// Lanes of the mode loops' partial sums (so that they vectorise: a single sum would be a serial
/// chain).
pub(crate) const LANES: usize = 8;

/// Directions of the bridge's motion (T, L, P): a step's inputs, one per direction; and the rows
/// read after a step: the left channel's radiating source, the total contact force per
/// direction, the right channel's source ([`SOUND_READS`]).
pub(crate) const DIRECTIONS: usize = 3;
pub(crate) const READS: usize = 5;
/// The reads that are each channel's radiating source (left, right).
pub(crate) const SOUND_READS: [usize; CHANNELS] = [0, 4];

/// One pass over the first `n` modes (at most `e.len()`): `z <- e ⊙ z` (if `propagate`), then
/// `z += sum_j g_j u_j` over the inputs, then `Re(r_i z)` for each row: 6 FLOP per mode to
/// propagate, 4 per input and 4 per row.
#[allow(clippy::too_many_arguments)]
pub(crate) fn advance(
    fast: bool,
    propagate: bool,
    n: usize,
    e: &Split,
    z: &mut Split,
    g: &[Split; DIRECTIONS],
    u: &[f64; DIRECTIONS],
    rows: &[Split; READS],
) -> [f64; READS] {
    let n = n.min(e.len());
    #[cfg(target_arch = "x86_64")]
    if fast {
        // SAFETY: `fast` is set only where `has_avx2_fma()` found AVX2 and FMA.
        return unsafe { advance_avx2(propagate, n, e, z, g, u, rows) };
    }
    let _ = fast;
    dispatch::<false>(propagate, n, e, z, g, u, rows)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn advance_avx2(
    propagate: bool,
    n: usize,
    e: &Split,
    z: &mut Split,
    g: &[Split; DIRECTIONS],
    u: &[f64; DIRECTIONS],
    rows: &[Split; READS],
) -> [f64; READS] {
    dispatch::<true>(propagate, n, e, z, g, u, rows)
}

/// The variant without inputs where every input is zero (one key alone on the board, or before
/// any other key has moved it).
#[inline(always)]
fn dispatch<const FMA: bool>(
    propagate: bool,
    n: usize,
    e: &Split,
    z: &mut Split,
    g: &[Split; DIRECTIONS],
    u: &[f64; DIRECTIONS],
    rows: &[Split; READS],
) -> [f64; READS] {
    let inputs = u.iter().any(|&x| x != 0.0);
    match (propagate, inputs) {
        (true, true) => pass::<FMA, true, true>(n, e, z, g, u, rows),
        (true, false) => pass::<FMA, true, false>(n, e, z, g, u, rows),
        (false, true) => pass::<FMA, false, true>(n, e, z, g, u, rows),
        (false, false) => pass::<FMA, false, false>(n, e, z, g, u, rows),
    }
}

/// `a b + c`, fused with `FMA`.
#[inline(always)]
pub(crate) fn fma<const FMA: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

#[inline(always)]
fn pass<const FMA: bool, const PROPAGATE: bool, const INPUT: bool>(
    n: usize,
    e: &Split,
    z: &mut Split,
    g: &[Split; DIRECTIONS],
    u: &[f64; DIRECTIONS],
    rows: &[Split; READS],
) -> [f64; READS] {
    let (er, ei) = (&e.re[..n], &e.im[..n]);
    let (zr, zi) = (&mut z.re[..n], &mut z.im[..n]);
    let gr: [&[f64]; DIRECTIONS] = std::array::from_fn(|j| &g[j].re[..n]);
    let gi: [&[f64]; DIRECTIONS] = std::array::from_fn(|j| &g[j].im[..n]);
    let rr: [&[f64]; READS] = std::array::from_fn(|i| &rows[i].re[..n]);
    let ri: [&[f64]; READS] = std::array::from_fn(|i| &rows[i].im[..n]);
    let mut acc = [[0.0; LANES]; READS];
    // A plain loop, not a closure: a closure would be compiled without the caller's target
    // features (its `mul_add` a library call).
    for m in 0..n {
        let lane = m % LANES;
        let (mut re, mut im) = (zr[m], zi[m]);
        if PROPAGATE {
            (re, im) = (
                fma::<FMA>(er[m], re, -ei[m] * im),
                fma::<FMA>(er[m], im, ei[m] * re),
            );
        }
        if INPUT {
            for j in 0..DIRECTIONS {
                re = fma::<FMA>(gr[j][m], u[j], re);
                im = fma::<FMA>(gi[j][m], u[j], im);
            }
        }
        zr[m] = re;
        zi[m] = im;
        for i in 0..READS {
            acc[i][lane] = fma::<FMA>(rr[i][m], re, fma::<FMA>(-ri[i][m], im, acc[i][lane]));
        }
    }
    acc.map(|a| a.iter().sum())
}

/// Most rows a hammer's felt reads: each string's striking-point displacement and velocity.
pub(crate) const FELT_ROWS: usize = 2 * MAX_STRINGS;

/// `[Re r z, Re r (e ⊙ z), Re r (e ⊙ e ⊙ z)]` of each of `rows` (at most [`FELT_ROWS`]), in
/// one pass over the modes (ETDRK4's stages are linear in `z` and the felt's forces, so what a
/// stage reads follows from these: [`super::voice`]).
pub(crate) fn powers_read(
    fast: bool,
    e: &Split,
    z: &Split,
    rows: &[&Split],
) -> [[f64; 3]; FELT_ROWS] {
    #[cfg(target_arch = "x86_64")]
    if fast {
        // SAFETY: `fast` is set only where `has_avx2_fma()` found AVX2 and FMA.
        return unsafe { powers_read_avx2(e, z, rows) };
    }
    let _ = fast;
    powers_by_count::<false>(e, z, rows)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn powers_read_avx2(e: &Split, z: &Split, rows: &[&Split]) -> [[f64; 3]; FELT_ROWS] {
    powers_by_count::<true>(e, z, rows)
}

/// [`powers`] with its row count known to the compiler (its loops then unrolled).
#[inline(always)]
fn powers_by_count<const FMA: bool>(
    e: &Split,
    z: &Split,
    rows: &[&Split],
) -> [[f64; 3]; FELT_ROWS] {
    match rows.len() {
        1 => powers::<FMA, 1>(e, z, rows),
        2 => powers::<FMA, 2>(e, z, rows),
        3 => powers::<FMA, 3>(e, z, rows),
        4 => powers::<FMA, 4>(e, z, rows),
        5 => powers::<FMA, 5>(e, z, rows),
        _ => powers::<FMA, FELT_ROWS>(e, z, rows),
    }
}

#[inline(always)]
fn powers<const FMA: bool, const R: usize>(
    e: &Split,
    z: &Split,
    rows: &[&Split],
) -> [[f64; 3]; FELT_ROWS] {
    let n = e.len();
    let (er, ei) = (&e.re[..n], &e.im[..n]);
    let (zr, zi) = (&z.re[..n], &z.im[..n]);
    let rr: [&[f64]; R] = std::array::from_fn(|i| &rows[i].re[..n]);
    let ri: [&[f64]; R] = std::array::from_fn(|i| &rows[i].im[..n]);
    let mut acc = [[[0.0; LANES]; 3]; R];
    for m in 0..n {
        let lane = m % LANES;
        let z = [zr[m], zi[m]];
        let a = [
            fma::<FMA>(er[m], z[0], -ei[m] * z[1]),
            fma::<FMA>(er[m], z[1], ei[m] * z[0]),
        ];
        let b = [
            fma::<FMA>(er[m], a[0], -ei[m] * a[1]),
            fma::<FMA>(er[m], a[1], ei[m] * a[0]),
        ];
        for i in 0..R {
            for (k, x) in [z, a, b].iter().enumerate() {
                acc[i][k][lane] =
                    fma::<FMA>(rr[i][m], x[0], fma::<FMA>(-ri[i][m], x[1], acc[i][k][lane]));
            }
        }
    }
    let mut out = [[0.0; 3]; FELT_ROWS];
    for (out, acc) in out.iter_mut().zip(&acc) {
        *out = acc.map(|a| a.iter().sum());
    }
    out
}

/// `z += sum_d a_d u_d` over the modes of `e` (three directions' inputs, in one pass).
pub(crate) fn add_directions(
    fast: bool,
    e: &Split,
    z: &mut Split,
    a: &[Split; DIRECTIONS],
    u: &[f64; DIRECTIONS],
) {
    let a: [&Split; DIRECTIONS] = std::array::from_fn(|d| &a[d]);
    #[cfg(target_arch = "x86_64")]
    if fast {
        // SAFETY: `fast` is set only where `has_avx2_fma()` found AVX2 and FMA.
        return unsafe { add_directions_avx2(e, z, &a, u) };
    }
    let _ = fast;
    drive_pass::<false, false, DIRECTIONS>(e, z, &a, u)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn add_directions_avx2(
    e: &Split,
    z: &mut Split,
    a: &[&Split; DIRECTIONS],
    u: &[f64; DIRECTIONS],
) {
    drive_pass::<true, false, DIRECTIONS>(e, z, a, u)
}

/// Most inputs a hammer's step drives: ETDRK4's three per string.
pub(crate) const FELT_INPUTS: usize = 3 * MAX_STRINGS;

/// `z = e ⊙ z + sum_k g_k u_k` (at most [`FELT_INPUTS`] inputs) in one pass over the modes.
pub(crate) fn drive(fast: bool, e: &Split, z: &mut Split, g: &[&Split], u: &[f64]) {
    #[cfg(target_arch = "x86_64")]
    if fast {
        // SAFETY: `fast` is set only where `has_avx2_fma()` found AVX2 and FMA.
        return unsafe { drive_avx2(e, z, g, u) };
    }
    let _ = fast;
    drive_by_count::<false>(e, z, g, u)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn drive_avx2(e: &Split, z: &mut Split, g: &[&Split], u: &[f64]) {
    drive_by_count::<true>(e, z, g, u)
}

/// [`drive_pass`] with its input count known to the compiler: one string's three, two's or
/// three's.
#[inline(always)]
fn drive_by_count<const FMA: bool>(e: &Split, z: &mut Split, g: &[&Split], u: &[f64]) {
    match g.len() {
        3 => drive_pass::<FMA, true, 3>(e, z, g, u),
        6 => drive_pass::<FMA, true, 6>(e, z, g, u),
        9 => drive_pass::<FMA, true, 9>(e, z, g, u),
        _ => {
            drive_pass::<FMA, true, 0>(e, z, &[], &[]);
            for (g, &u) in g.iter().zip(u) {
                g.add_to(z, u);
            }
        }
    }
}

/// `z = e ⊙ z + sum_k g_k u_k`, or without `e` unless `PROPAGATE`.
#[inline(always)]
fn drive_pass<const FMA: bool, const PROPAGATE: bool, const K: usize>(
    e: &Split,
    z: &mut Split,
    g: &[&Split],
    u: &[f64],
) {
    let n = e.len();
    let (er, ei) = (&e.re[..n], &e.im[..n]);
    let (zr, zi) = (&mut z.re[..n], &mut z.im[..n]);
    let gr: [&[f64]; K] = std::array::from_fn(|k| &g[k].re[..n]);
    let gi: [&[f64]; K] = std::array::from_fn(|k| &g[k].im[..n]);
    let u: [f64; K] = std::array::from_fn(|k| u[k]);
    for m in 0..n {
        let (a, b) = (zr[m], zi[m]);
        let (mut re, mut im) = if PROPAGATE {
            (
                fma::<FMA>(er[m], a, -ei[m] * b),
                fma::<FMA>(er[m], b, ei[m] * a),
            )
        } else {
            (a, b)
        };
        for k in 0..K {
            re = fma::<FMA>(gr[k][m], u[k], re);
            im = fma::<FMA>(gi[k][m], u[k], im);
        }
        zr[m] = re;
        zi[m] = im;
    }
}
/// Longest block advanced mode by mode ([`free_block`], [`fold_block`]). Its reads' inputs are
/// convolved step by step ([`scatter`]: on average `BLOCK / 2` taps each), its coefficients
/// loaded once: 32 balances the two (64: the convolution 30 % of the work; 16: the block's own
/// overhead grows more than the convolution saves).
pub(crate) const BLOCK: usize = 32;

/// Modes of one AVX-512 pass ([`free_block`], [`fold_block`]): two registers of 16, two
/// independent recursions to hide each one's latency. A key's block coefficients are padded to
/// a whole number of them with modes that never move.
pub(crate) const WIDE: usize = 32;

/// Which form of the loops this CPU runs: portable, AVX2 + FMA, or (the block passes, the
/// convolution) AVX-512. Chosen once, at run time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Simd {
    Portable,
    Avx2,
    Avx512,
}

impl Simd {
    pub(crate) fn detect() -> Simd {
        #[cfg(target_arch = "x86_64")]
        if has_avx2_fma() && is_x86_feature_detected!("avx512f") {
            return Simd::Avx512;
        }
        if has_avx2_fma() {
            Simd::Avx2
        } else {
            Simd::Portable
        }
    }

    /// Whether the AVX2 + FMA forms may run.
    pub(crate) fn avx2(self) -> bool {
        self != Simd::Portable
    }
}

/// Damper channels of a key at most: T and P of each string at each point of the felt.
pub(crate) const DAMPER_CHANNELS: usize = 2 * MAX_STRINGS * FELT_POINTS;

/// Inputs of a damped voice's block: the bridge's motion in three directions and the damper
/// felt's force on each channel; rows it reads: [`READS`] and the felt's velocity per channel.
pub(crate) const DAMPED_INPUTS: usize = DIRECTIONS + DAMPER_CHANNELS;
pub(crate) const DAMPED_READS: usize = READS + DAMPER_CHANNELS;

/// A block's inputs, step `t` at `BLOCK - 1 - t` (so that a convolution with Markov parameters
/// is a forward dot product), in single precision.
pub(crate) type Reversed<const I: usize> = [[f32; BLOCK]; I];

/// Markov parameters per read and input for [`scatter`]: tap `k` (steps after the input) at
/// `k`. Aligned to a cache line, so that each 16 taps of a row are one line.
#[derive(Debug, Clone, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct Taps<const R: usize, const I: usize>(pub(crate) [[[f32; BLOCK]; I]; R]);

/// What each read of a block's steps has received so far from the block's inputs, step `s` at
/// `s`, in single precision.
pub(crate) type Pending<const R: usize> = [[f32; BLOCK]; R];

/// Step `t`'s inputs `x` added to what they bring to the reads of steps `t..BLOCK`:
/// `pending[i][s] += sum_d taps[i][d][s - t] x_d`. After it `pending[i][t]` is what the inputs
/// of steps `0..=t` add to read `i` after step `t` — the convolution with the Markov parameters,
/// summed as the inputs arrive, in whole registers over the steps to come (no sums across
/// lanes, which a dot product per step would need). `inputs` holds the block's inputs so far
/// ([`Reversed`]), step `t`'s (`x`) the last of them: the AVX-512 form adds what the first half
/// of the block's inputs bring to its second half in one pass at the half, each row's taps
/// brought in once rather than at every step (the same sums, in the same order).
pub(crate) fn scatter<const R: usize, const I: usize>(
    simd: Simd,
    taps: &Taps<R, I>,
    inputs: &Reversed<I>,
    t: usize,
    pending: &mut Pending<R>,
) {
    let x: [f32; I] = std::array::from_fn(|d| inputs[d][BLOCK - 1 - t]);
    #[cfg(target_arch = "x86_64")]
    match simd {
        // SAFETY: `Simd::detect` chose these only where the CPU has them.
        Simd::Avx512 => return unsafe { scatter_avx512::<R, I>(taps, &x, inputs, t, pending) },
        Simd::Avx2 => return unsafe { scatter_avx2::<R, I>(taps, &x, t, pending) },
        Simd::Portable => {}
    }
    let _ = simd;
    scatter_with::<false, R, I>(taps, &x, t, pending)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn scatter_avx2<const R: usize, const I: usize>(
    taps: &Taps<R, I>,
    x: &[f32; I],
    t: usize,
    pending: &mut Pending<R>,
) {
    scatter_with::<true, R, I>(taps, x, t, pending)
}

#[inline(always)]
fn scatter_with<const FMA: bool, const R: usize, const I: usize>(
    taps: &Taps<R, I>,
    x: &[f32; I],
    t: usize,
    pending: &mut Pending<R>,
) {
    for (taps, pending) in taps.0.iter().zip(pending.iter_mut()) {
        for (taps, &x) in taps.iter().zip(x) {
            for (p, &a) in pending[t..].iter_mut().zip(taps) {
                *p = fma32::<FMA>(a, x, *p);
            }
        }
    }
}

/// Steps per register of [`scatter_avx512`]: the block is two of them.
const HALF: usize = 16;
const _: () = assert!(
    BLOCK == 2 * HALF,
    "scatter_avx512 works on a block of two registers"
);

/// [`scatter`] in 16-lane registers. Step `t`'s inputs reach the steps of its own half through
/// its row's first 16 taps moved up `t mod 16` lanes (those below `t` zero); at the half, the
/// first half's inputs reach the second half through each row's 32 taps, `16 + j - s` for input
/// step `s` and lane `j`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn scatter_avx512<const R: usize, const I: usize>(
    taps: &Taps<R, I>,
    x: &[f32; I],
    inputs: &Reversed<I>,
    t: usize,
    pending: &mut Pending<R>,
) {
    use std::arch::x86_64::*;
    let lanes = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    // SAFETY (every load and store below): each row of `taps` and `pending` holds BLOCK = 32
    // values, read or written as two registers of 16 at 0 and 16.
    let row = |i: usize, d: usize, at: usize| _mm512_loadu_ps(taps.0[i][d].as_ptr().add(at));
    if t == HALF {
        for (i, pending) in pending.iter_mut().enumerate() {
            let p = pending.as_mut_ptr().add(HALF);
            let mut acc = _mm512_loadu_ps(p);
            for s in 0..HALF {
                let index = _mm512_add_epi32(lanes, _mm512_set1_epi32((HALF - s) as i32));
                for (d, input) in inputs.iter().enumerate() {
                    let a = _mm512_permutex2var_ps(row(i, d, 0), index, row(i, d, HALF));
                    acc = _mm512_fmadd_ps(a, _mm512_set1_ps(input[BLOCK - 1 - s]), acc);
                }
            }
            _mm512_storeu_ps(p, acc);
        }
    }
    let (half, shift) = (t / HALF * HALF, t % HALF);
    let index = _mm512_sub_epi32(lanes, _mm512_set1_epi32(shift as i32));
    let from: __mmask16 = !0 << shift;
    let x: [__m512; I] = std::array::from_fn(|d| _mm512_set1_ps(x[d]));
    for (i, pending) in pending.iter_mut().enumerate() {
        let p = pending.as_mut_ptr().add(half);
        let mut acc = _mm512_loadu_ps(p);
        for (d, &x) in x.iter().enumerate() {
            let a = _mm512_maskz_permutexvar_ps(from, index, row(i, d, 0));
            acc = _mm512_fmadd_ps(a, x, acc);
        }
        _mm512_storeu_ps(p, acc);
    }
}

/// A complex vector per mode in single precision, real and imaginary parts apart: the block
/// kernels' coefficients (half the bytes and twice the lanes of [`Split`]), padded to [`WIDE`].
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Split32 {
    pub(crate) re: Vec<f32>,
    pub(crate) im: Vec<f32>,
}

impl Split32 {
    pub(crate) fn new(v: &Split) -> Split32 {
        let pad = |x: &[f64]| -> Vec<f32> {
            let mut y: Vec<f32> = x.iter().map(|&x| x as f32).collect();
            y.resize(x.len().div_ceil(WIDE) * WIDE, 0.0);
            y
        };
        Split32 {
            re: pad(&v.re),
            im: pad(&v.im),
        }
    }
}

/// Lanes of the portable and AVX2 block loops: two AVX2 registers, two independent recursions
/// to hide the latency of each.
const LANES32: usize = 16;

/// `e^n` of one mode, in double precision.
fn power(re: f64, im: f64, n: usize) -> (f64, f64) {
    let (mut pr, mut pi) = (1.0, 0.0);
    let (mut br, mut bi) = (re, im);
    let mut n = n;
    while n > 0 {
        if n & 1 == 1 {
            (pr, pi) = (pr * br - pi * bi, pr * bi + pi * br);
        }
        (br, bi) = (br * br - bi * bi, 2.0 * br * bi);
        n >>= 1;
    }
    (pr, pi)
}

/// A key's coefficients for the block loops: per mode `e^{lambda h}` in single precision for the
/// steps inside a block and `e^{lambda h BLOCK}` in double for the state carried from block to
/// block, so that rounding inside a block is never compounded over a note's life (`e` rounded to
/// f32 would shift the slowest modes' decay by ~8 %). Padded to [`WIDE`] modes (the padding
/// never moves: its `e` is zero).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct BlockCoefficients<const R: usize, const I: usize> {
    pub(crate) e: Split32,
    pub(crate) e_block: Split,
    /// The rows read after every step and the inputs folded in.
    pub(crate) rows: [Split32; R],
    pub(crate) inputs: [Split32; I],
}

impl<const R: usize, const I: usize> BlockCoefficients<R, I> {
    pub(crate) fn new(
        e: &Split,
        rows: &[&Split; R],
        inputs: &[&Split; I],
    ) -> BlockCoefficients<R, I> {
        let padded = e.len().div_ceil(WIDE) * WIDE;
        let mut e_block = Split::zeros(padded);
        for m in 0..e.len() {
            (e_block.re[m], e_block.im[m]) = power(e.re[m], e.im[m], BLOCK);
        }
        BlockCoefficients {
            e: Split32::new(e),
            e_block,
            rows: std::array::from_fn(|i| Split32::new(rows[i])),
            inputs: std::array::from_fn(|j| Split32::new(inputs[j])),
        }
    }

    /// Modes of the loops (padded).
    pub(crate) fn modes(&self) -> usize {
        self.e.re.len()
    }
}

/// `len` free steps of the first `n` modes (a multiple of [`WIDE`], at most
/// [`BlockCoefficients::modes`]), mode by mode (each mode's coefficients loaded once):
/// `out[i][t] = Re(r_i e^{t+1} z)` for `t < len` in single precision, then `z <- e^len ⊙ z` in
/// double (`e_step` is the double-precision step, for a block shorter than [`BLOCK`]). `z` holds
/// at least `n` modes.
pub(crate) fn free_block<const R: usize, const I: usize>(
    simd: Simd,
    c: &BlockCoefficients<R, I>,
    n: usize,
    e_step: &Split,
    z: &mut Split,
    out: &mut [[f64; BLOCK]; R],
    len: usize,
) {
    assert!(n <= c.modes() && n.is_multiple_of(WIDE) && z.re.len() >= n && z.im.len() >= n);
    #[cfg(target_arch = "x86_64")]
    match simd {
        // SAFETY: `Simd::detect` chose these only where the CPU has them.
        Simd::Avx512 if R <= READS => {
            return unsafe { free_block_avx512::<R, I, 2>(c, n, e_step, z, out, len) }
        }
        Simd::Avx512 => return unsafe { free_block_avx512::<R, I, 1>(c, n, e_step, z, out, len) },
        Simd::Avx2 => return unsafe { free_block_avx2(c, n, e_step, z, out, len) },
        Simd::Portable => {}
    }
    let _ = simd;
    free_block_with::<false, R, I>(c, n, e_step, z, out, len)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn free_block_avx2<const R: usize, const I: usize>(
    c: &BlockCoefficients<R, I>,
    n: usize,
    e_step: &Split,
    z: &mut Split,
    out: &mut [[f64; BLOCK]; R],
    len: usize,
) {
    free_block_with::<true, R, I>(c, n, e_step, z, out, len)
}

/// `a b + c` in single precision, fused with `FMA`.
#[inline(always)]
fn fma32<const FMA: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// The state carried to the next block in double precision: `z <- e^len ⊙ z` on `range`.
#[inline(always)]
fn carry<const R: usize, const I: usize>(
    c: &BlockCoefficients<R, I>,
    e_step: &Split,
    z: &mut Split,
    range: std::ops::Range<usize>,
    len: usize,
) {
    let (zr, zi) = (&mut z.re[range.clone()], &mut z.im[range.clone()]);
    if len == BLOCK {
        // The whole block's power, loaded (a loop that vectorises).
        let (er, ei) = (&c.e_block.re[range.clone()], &c.e_block.im[range]);
        for m in 0..zr.len() {
            let (a, b) = (zr[m], zi[m]);
            zr[m] = er[m] * a - ei[m] * b;
            zi[m] = er[m] * b + ei[m] * a;
        }
        return;
    }
    for (m, (zr, zi)) in range.zip(zr.iter_mut().zip(zi.iter_mut())) {
        let (pr, pi) = if m < e_step.len() {
            power(e_step.re[m], e_step.im[m], len)
        } else {
            (0.0, 0.0)
        };
        let (a, b) = (*zr, *zi);
        *zr = pr * a - pi * b;
        *zi = pr * b + pi * a;
    }
}

#[inline(always)]
fn free_block_with<const FMA: bool, const R: usize, const I: usize>(
    c: &BlockCoefficients<R, I>,
    n: usize,
    e_step: &Split,
    z: &mut Split,
    out: &mut [[f64; BLOCK]; R],
    len: usize,
) {
    let mut acc = [[[0f32; LANES32]; BLOCK]; R];
    for base in (0..n).step_by(LANES32) {
        let mut er = [0f32; LANES32];
        let mut ei = [0f32; LANES32];
        let mut zr = [0f32; LANES32];
        let mut zi = [0f32; LANES32];
        let mut rr = [[0f32; LANES32]; R];
        let mut ri = [[0f32; LANES32]; R];
        for l in 0..LANES32 {
            let m = base + l;
            (er[l], ei[l]) = (c.e.re[m], c.e.im[m]);
            (zr[l], zi[l]) = (z.re[m] as f32, z.im[m] as f32);
            for i in 0..R {
                (rr[i][l], ri[i][l]) = (c.rows[i].re[m], c.rows[i].im[m]);
            }
        }
        for t in 0..len {
            for l in 0..LANES32 {
                let (a, b) = (zr[l], zi[l]);
                zr[l] = fma32::<FMA>(er[l], a, -ei[l] * b);
                zi[l] = fma32::<FMA>(er[l], b, ei[l] * a);
                for i in 0..R {
                    acc[i][t][l] = fma32::<FMA>(
                        rr[i][l],
                        zr[l],
                        fma32::<FMA>(-ri[i][l], zi[l], acc[i][t][l]),
                    );
                }
            }
        }
        carry(c, e_step, z, base..base + LANES32, len);
    }
    for i in 0..R {
        for t in 0..len {
            out[i][t] = acc[i][t].iter().map(|&x| f64::from(x)).sum();
        }
    }
}

/// [`free_block`] in AVX-512: `16 W` modes a pass in `W` registers of 16 lanes (two
/// independent recursions where the rows leave registers for them, one where they do not),
/// every read's sum over them in one register per step.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn free_block_avx512<const R: usize, const I: usize, const W: usize>(
    c: &BlockCoefficients<R, I>,
    n: usize,
    e_step: &Split,
    z: &mut Split,
    out: &mut [[f64; BLOCK]; R],
    len: usize,
) {
    use std::arch::x86_64::*;
    let mut acc = [[_mm512_setzero_ps(); BLOCK]; R];
    // SAFETY (every load and store below): `base + 16 W <= n`, at most the length of every
    // coefficient (padded to WIDE, a multiple of 16 W) and of `z` (asserted by `free_block`).
    let ld = |x: &[f32], at: usize| _mm512_loadu_ps(x.as_ptr().add(at));
    let ld64 = |x: &[f64], at: usize| {
        let lo = _mm512_cvtpd_ps(_mm512_loadu_pd(x.as_ptr().add(at)));
        let hi = _mm512_cvtpd_ps(_mm512_loadu_pd(x.as_ptr().add(at + 8)));
        _mm512_insertf32x8::<1>(_mm512_castps256_ps512(lo), hi)
    };
    for base in (0..n).step_by(16 * W) {
        let h: [usize; W] = std::array::from_fn(|k| base + 16 * k);
        let er = h.map(|b| ld(&c.e.re, b));
        let ei = h.map(|b| ld(&c.e.im, b));
        let rr: [[__m512; W]; R] = std::array::from_fn(|i| h.map(|b| ld(&c.rows[i].re, b)));
        let ri: [[__m512; W]; R] = std::array::from_fn(|i| h.map(|b| ld(&c.rows[i].im, b)));
        let mut zr = h.map(|b| ld64(&z.re, b));
        let mut zi = h.map(|b| ld64(&z.im, b));
        for t in 0..len {
            for k in 0..W {
                let (a, b) = (zr[k], zi[k]);
                zr[k] = _mm512_fmsub_ps(er[k], a, _mm512_mul_ps(ei[k], b));
                zi[k] = _mm512_fmadd_ps(er[k], b, _mm512_mul_ps(ei[k], a));
            }
            for i in 0..R {
                let mut a = acc[i][t];
                for k in 0..W {
                    a = _mm512_fmadd_ps(rr[i][k], zr[k], a);
                    a = _mm512_fnmadd_ps(ri[i][k], zi[k], a);
                }
                acc[i][t] = a;
            }
        }
        carry(c, e_step, z, base..base + 16 * W, len);
    }
    for i in 0..R {
        for t in 0..len {
            out[i][t] = f64::from(_mm512_reduce_add_ps(acc[i][t]));
        }
    }
}

/// Fold `len` steps of inputs into the first `n` modes (as [`free_block`]), mode by mode: `z +=
/// sum_t e^{len-1-t} (sum_j g_j u_j(t))`, the sum formed in single precision (it starts from zero
/// each block) and added in double — by superposition, what stepping the inputs in one at a time
/// adds. The inputs are [`Reversed`].
pub(crate) fn fold_block<const R: usize, const I: usize>(
    simd: Simd,
    c: &BlockCoefficients<R, I>,
    n: usize,
    z: &mut Split,
    u: &Reversed<I>,
    len: usize,
) {
    assert!(n <= c.modes() && n.is_multiple_of(WIDE) && z.re.len() >= n && z.im.len() >= n);
    #[cfg(target_arch = "x86_64")]
    match simd {
        // SAFETY: `Simd::detect` chose these only where the CPU has them.
        Simd::Avx512 if I <= DIRECTIONS => {
            return unsafe { fold_block_avx512::<R, I, 2>(c, n, z, u, len) }
        }
        Simd::Avx512 => return unsafe { fold_block_avx512::<R, I, 1>(c, n, z, u, len) },
        Simd::Avx2 => return unsafe { fold_block_avx2(c, n, z, u, len) },
        Simd::Portable => {}
    }
    let _ = simd;
    fold_block_with::<false, R, I>(c, n, z, u, len)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn fold_block_avx2<const R: usize, const I: usize>(
    c: &BlockCoefficients<R, I>,
    n: usize,
    z: &mut Split,
    u: &Reversed<I>,
    len: usize,
) {
    fold_block_with::<true, R, I>(c, n, z, u, len)
}

#[inline(always)]
fn fold_block_with<const FMA: bool, const R: usize, const I: usize>(
    c: &BlockCoefficients<R, I>,
    n: usize,
    z: &mut Split,
    u: &Reversed<I>,
    len: usize,
) {
    let steps: [[f32; I]; BLOCK] =
        std::array::from_fn(|t| std::array::from_fn(|j| u[j][BLOCK - 1 - t]));
    for base in (0..n).step_by(LANES32) {
        let mut er = [0f32; LANES32];
        let mut ei = [0f32; LANES32];
        let mut gr = [[0f32; LANES32]; I];
        let mut gi = [[0f32; LANES32]; I];
        for l in 0..LANES32 {
            let m = base + l;
            (er[l], ei[l]) = (c.e.re[m], c.e.im[m]);
            for j in 0..I {
                (gr[j][l], gi[j][l]) = (c.inputs[j].re[m], c.inputs[j].im[m]);
            }
        }
        let (mut ar, mut ai) = ([0f32; LANES32], [0f32; LANES32]);
        for ut in steps.iter().take(len) {
            for l in 0..LANES32 {
                let (a, b) = (ar[l], ai[l]);
                let (mut re, mut im) = (
                    fma32::<FMA>(er[l], a, -ei[l] * b),
                    fma32::<FMA>(er[l], b, ei[l] * a),
                );
                for j in 0..I {
                    re = fma32::<FMA>(gr[j][l], ut[j], re);
                    im = fma32::<FMA>(gi[j][l], ut[j], im);
                }
                (ar[l], ai[l]) = (re, im);
            }
        }
        for l in 0..LANES32 {
            z.re[base + l] += f64::from(ar[l]);
            z.im[base + l] += f64::from(ai[l]);
        }
    }
}

/// [`fold_block`] in AVX-512: `16 W` modes a pass in `W` registers of 16 lanes, the step's
/// inputs summed apart from the recursion (so that its chain is two operations long).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn fold_block_avx512<const R: usize, const I: usize, const W: usize>(
    c: &BlockCoefficients<R, I>,
    n: usize,
    z: &mut Split,
    u: &Reversed<I>,
    len: usize,
) {
    use std::arch::x86_64::*;
    // SAFETY (every load and store below): `base + 16 W <= n`, at most the length of every
    // coefficient (padded to WIDE) and of `z` (asserted by `fold_block`).
    let ld = |x: &[f32], at: usize| _mm512_loadu_ps(x.as_ptr().add(at));
    for base in (0..n).step_by(16 * W) {
        let h: [usize; W] = std::array::from_fn(|k| base + 16 * k);
        let er = h.map(|b| ld(&c.e.re, b));
        let ei = h.map(|b| ld(&c.e.im, b));
        let gr: [[__m512; W]; I] = std::array::from_fn(|j| h.map(|b| ld(&c.inputs[j].re, b)));
        let gi: [[__m512; W]; I] = std::array::from_fn(|j| h.map(|b| ld(&c.inputs[j].im, b)));
        let (mut ar, mut ai) = ([_mm512_setzero_ps(); W], [_mm512_setzero_ps(); W]);
        for t in 0..len {
            let x: [__m512; I] = std::array::from_fn(|j| _mm512_set1_ps(u[j][BLOCK - 1 - t]));
            for k in 0..W {
                let mut ur = _mm512_mul_ps(gr[0][k], x[0]);
                let mut ui = _mm512_mul_ps(gi[0][k], x[0]);
                for j in 1..I {
                    ur = _mm512_fmadd_ps(gr[j][k], x[j], ur);
                    ui = _mm512_fmadd_ps(gi[j][k], x[j], ui);
                }
                let (a, b) = (ar[k], ai[k]);
                ar[k] = _mm512_fmadd_ps(er[k], a, _mm512_fnmadd_ps(ei[k], b, ur));
                ai[k] = _mm512_fmadd_ps(er[k], b, _mm512_fmadd_ps(ei[k], a, ui));
            }
        }
        // The sums added to the state in double precision, eight modes at a time.
        for k in 0..W {
            let halves = [
                (_mm512_castps512_ps256(ar[k]), _mm512_castps512_ps256(ai[k])),
                (
                    _mm512_extractf32x8_ps::<1>(ar[k]),
                    _mm512_extractf32x8_ps::<1>(ai[k]),
                ),
            ];
            for (part, (sr, si)) in halves.into_iter().enumerate() {
                let at = h[k] + 8 * part;
                let (pr, pi) = (z.re.as_mut_ptr().add(at), z.im.as_mut_ptr().add(at));
                _mm512_storeu_pd(pr, _mm512_add_pd(_mm512_loadu_pd(pr), _mm512_cvtps_pd(sr)));
                _mm512_storeu_pd(pi, _mm512_add_pd(_mm512_loadu_pd(pi), _mm512_cvtps_pd(si)));
            }
        }
    }
}

/// What a voice's two energies read of its key, in single precision and padded to [`WIDE`]:
/// per direction the shifts `a_d` (`z = w + a D`) and `a_d - follow_d` (the state about the
/// strings' static deflection by `D`), and each mode's energy per `|z|^2` (J). Single precision
/// halves what the pass brings from memory (the state and the sums stay in double): the energies
/// are read after every housekeeping period for every sounding voice, and these coefficients are
/// touched by nothing else.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct EnergyCoefficients {
    pub(crate) settle: [Split32; DIRECTIONS],
    pub(crate) unfollow: [Split32; DIRECTIONS],
    pub(crate) weight: Vec<f32>,
}

impl EnergyCoefficients {
    pub(crate) fn new(
        settle: &[Split; DIRECTIONS],
        unfollow: &[Split; DIRECTIONS],
        weight: &[f64],
    ) -> EnergyCoefficients {
        let n = settle[0].len();
        let mut w: Vec<f32> = weight[..n].iter().map(|&x| x as f32).collect();
        w.resize(n.div_ceil(WIDE) * WIDE, 0.0);
        EnergyCoefficients {
            settle: std::array::from_fn(|d| Split32::new(&settle[d])),
            unfollow: std::array::from_fn(|d| Split32::new(&unfollow[d])),
            weight: w,
        }
    }

    /// Modes of the pass (padded).
    pub(crate) fn modes(&self) -> usize {
        self.weight.len()
    }
}

/// The energies `[sum_m e_m |w_m + sum_d a_d,m D_d|^2, sum_m e_m |w_m + sum_d u_d,m D_d|^2]`
/// (J; `a` the shift to `z`, `u` that about the static deflection: [`EnergyCoefficients`]) of
/// the modes in `range` (whole lanes, within the padded modes and `w`), in one pass, in the
/// widest registers the machine has.
pub(crate) fn energies(
    simd: Simd,
    c: &EnergyCoefficients,
    w: &Split,
    d: [f64; 3],
    range: Range<usize>,
) -> [f64; 2] {
    assert!(
        range.start.is_multiple_of(LANES)
            && range.end.is_multiple_of(LANES)
            && range.end <= c.modes()
            && range.end <= w.re.len().min(w.im.len())
    );
    match simd {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Simd::detect` found AVX-512F (AVX2 + FMA) on this machine.
        Simd::Avx512 => unsafe { energies_avx512(c, w, d, range) },
        #[cfg(target_arch = "x86_64")]
        Simd::Avx2 => unsafe { energies_avx2(c, w, d, range) },
        _ => energies_with::<false>(c, w, d, range),
    }
}

/// [`energies`] in AVX-512: eight modes a register, the coefficients widened to double as they
/// are loaded.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn energies_avx512(
    c: &EnergyCoefficients,
    w: &Split,
    d: [f64; 3],
    range: Range<usize>,
) -> [f64; 2] {
    use std::arch::x86_64::*;
    let dd = d.map(|x| _mm512_set1_pd(x));
    let (mut es, mut eu) = (_mm512_setzero_pd(), _mm512_setzero_pd());
    // SAFETY (every load below): `m + LANES <= range.end`, within `w` and every coefficient
    // (asserted by `energies`).
    let wide = |x: &[f32], m: usize| _mm512_cvtps_pd(_mm256_loadu_ps(x.as_ptr().add(m)));
    for m in range.step_by(LANES) {
        let (wr, wi) = (
            _mm512_loadu_pd(w.re.as_ptr().add(m)),
            _mm512_loadu_pd(w.im.as_ptr().add(m)),
        );
        let (mut sr, mut si, mut ur, mut ui) = (wr, wi, wr, wi);
        for k in 0..DIRECTIONS {
            sr = _mm512_fmadd_pd(wide(&c.settle[k].re, m), dd[k], sr);
            si = _mm512_fmadd_pd(wide(&c.settle[k].im, m), dd[k], si);
            ur = _mm512_fmadd_pd(wide(&c.unfollow[k].re, m), dd[k], ur);
            ui = _mm512_fmadd_pd(wide(&c.unfollow[k].im, m), dd[k], ui);
        }
        let e = wide(&c.weight, m);
        es = _mm512_fmadd_pd(e, _mm512_fmadd_pd(sr, sr, _mm512_mul_pd(si, si)), es);
        eu = _mm512_fmadd_pd(e, _mm512_fmadd_pd(ur, ur, _mm512_mul_pd(ui, ui)), eu);
    }
    [_mm512_reduce_add_pd(es), _mm512_reduce_add_pd(eu)]
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn energies_avx2(
    c: &EnergyCoefficients,
    w: &Split,
    d: [f64; 3],
    range: Range<usize>,
) -> [f64; 2] {
    energies_with::<true>(c, w, d, range)
}

#[inline(always)]
fn energies_with<const FMA: bool>(
    c: &EnergyCoefficients,
    w: &Split,
    d: [f64; 3],
    range: Range<usize>,
) -> [f64; 2] {
    const L: usize = LANES;
    let lanes = |x: &[f32], m: usize| -> [f64; L] { std::array::from_fn(|l| f64::from(x[m + l])) };
    let mut acc = [[0.0; L]; 2];
    for m in range.step_by(L) {
        let wr: &[f64; L] = w.re[m..m + L].try_into().expect("L modes");
        let wi: &[f64; L] = w.im[m..m + L].try_into().expect("L modes");
        let (mut sr, mut si, mut ur, mut ui) = (*wr, *wi, *wr, *wi);
        for k in 0..DIRECTIONS {
            let (ar, ai) = (lanes(&c.settle[k].re, m), lanes(&c.settle[k].im, m));
            let (br, bi) = (lanes(&c.unfollow[k].re, m), lanes(&c.unfollow[k].im, m));
            for l in 0..L {
                sr[l] = fma::<FMA>(ar[l], d[k], sr[l]);
                si[l] = fma::<FMA>(ai[l], d[k], si[l]);
                ur[l] = fma::<FMA>(br[l], d[k], ur[l]);
                ui[l] = fma::<FMA>(bi[l], d[k], ui[l]);
            }
        }
        let e = lanes(&c.weight, m);
        for l in 0..L {
            acc[0][l] = fma::<FMA>(e[l], fma::<FMA>(sr[l], sr[l], si[l] * si[l]), acc[0][l]);
            acc[1][l] = fma::<FMA>(e[l], fma::<FMA>(ur[l], ur[l], ui[l] * ui[l]), acc[1][l]);
        }
    }
    acc.map(|a| a.iter().sum())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block's convolution of three inputs with five reads' Markov parameters, summed step by
    /// step by `scatter` on `simd`, against the same sums taken directly in double precision.
    fn convolved(simd: Simd) -> Pending<READS> {
        let mut numbers = crate::engine::exact::test_numbers(11);
        let mut next = || numbers() as f32;
        let mut taps = Box::new(Taps([[[0f32; BLOCK]; DIRECTIONS]; READS]));
        taps.0
            .iter_mut()
            .flatten()
            .flatten()
            .for_each(|a| *a = next());
        let x: Vec<[f32; DIRECTIONS]> = (0..BLOCK)
            .map(|_| std::array::from_fn(|_| next()))
            .collect();
        let mut inputs: Reversed<DIRECTIONS> = [[0.0; BLOCK]; DIRECTIONS];
        let mut pending: Pending<READS> = [[0.0; BLOCK]; READS];
        for (t, x) in x.iter().enumerate() {
            for d in 0..DIRECTIONS {
                inputs[d][BLOCK - 1 - t] = x[d];
            }
            scatter(simd, &taps, &inputs, t, &mut pending);
        }
        let mut worst = 0f64;
        for (i, pending) in pending.iter().enumerate() {
            for (t, &p) in pending.iter().enumerate() {
                let direct: f64 = (0..=t)
                    .flat_map(|s| (0..DIRECTIONS).map(move |d| (s, d)))
                    .map(|(s, d)| f64::from(taps.0[i][d][t - s]) * f64::from(x[s][d]))
                    .sum();
                worst = worst.max((f64::from(p) - direct).abs());
            }
        }
        println!("{simd:?}: the convolution within {worst:.1e} of its sums in double precision");
        // Up to 96 products of size 0.25 summed in single precision: a few times 1e-7 each.
        assert!(worst < 1e-5, "{simd:?}: {worst:.1e}");
        pending
    }

    #[test]
    fn scatter_sums_the_block_convolution_alike_in_every_form() {
        convolved(Simd::Portable);
        let detected = Simd::detect();
        if detected.avx2() {
            let avx2 = convolved(Simd::Avx2);
            if detected == Simd::Avx512 {
                // The same products summed in the same order, each with one rounding (FMA).
                assert_eq!(
                    convolved(Simd::Avx512),
                    avx2,
                    "AVX-512 and AVX2 bit for bit"
                );
            }
        }
    }
}
