//! The exact engine's loops over a key's complex modes, real and imaginary parts apart: the
//! propagation `z <- e ⊙ z`, the inputs that enter over the step and the rows read after it, in
//! one pass (8-lane partial sums so that the loop vectorises; AVX2 + FMA where the CPU has them).

use faer::c64;

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

    pub(crate) fn times(a: &[c64], b: &[c64]) -> Split {
        let p: Vec<c64> = a.iter().zip(b).map(|(x, y)| x * y).collect();
        Split::new(&p)
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

    pub(crate) fn fill_zero(&mut self) {
        self.re.iter_mut().for_each(|x| *x = 0.0);
        self.im.iter_mut().for_each(|x| *x = 0.0);
    }
}

/// Lanes of the mode loops' partial sums (so that they vectorise: a single sum would be a serial
/// chain).
pub(crate) const LANES: usize = 8;

/// Inputs that enter a step (the coupling's value and slope per direction) and rows read after it
/// (the volume velocity and the total contact force per direction).
pub(crate) const INPUTS: usize = 6;

/// Directions of the coupling (T, L, P): a block's inputs, one per direction.
pub(crate) const DIRECTIONS: usize = 3;
pub(crate) const READS: usize = 4;

/// One pass over the first `e.len()` modes: `z <- e ⊙ z` (if `propagate`), then
/// `z += sum_j g_j u_j` over the inputs, then `Re(r_i z)` for each row: 6 FLOP per mode to
/// propagate, 4 per input and 4 per row.
pub(crate) fn advance(
    fast: bool,
    propagate: bool,
    e: &Split,
    z: &mut Split,
    g: &[Split; INPUTS],
    u: &[f64; INPUTS],
    rows: &[Split; READS],
) -> [f64; READS] {
    #[cfg(target_arch = "x86_64")]
    if fast {
        // SAFETY: `fast` is set only where `has_avx2_fma()` found AVX2 and FMA.
        return unsafe { advance_avx2(propagate, e, z, g, u, rows) };
    }
    let _ = fast;
    dispatch::<false>(propagate, e, z, g, u, rows)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn advance_avx2(
    propagate: bool,
    e: &Split,
    z: &mut Split,
    g: &[Split; INPUTS],
    u: &[f64; INPUTS],
    rows: &[Split; READS],
) -> [f64; READS] {
    dispatch::<true>(propagate, e, z, g, u, rows)
}

/// The variant without inputs where every input is zero (one key alone on the board, or before
/// any other key has moved it).
#[inline(always)]
fn dispatch<const FMA: bool>(
    propagate: bool,
    e: &Split,
    z: &mut Split,
    g: &[Split; INPUTS],
    u: &[f64; INPUTS],
    rows: &[Split; READS],
) -> [f64; READS] {
    let inputs = u.iter().any(|&x| x != 0.0);
    match (propagate, inputs) {
        (true, true) => pass::<FMA, true, true>(e, z, g, u, rows),
        (true, false) => pass::<FMA, true, false>(e, z, g, u, rows),
        (false, true) => pass::<FMA, false, true>(e, z, g, u, rows),
        (false, false) => pass::<FMA, false, false>(e, z, g, u, rows),
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
    e: &Split,
    z: &mut Split,
    g: &[Split; INPUTS],
    u: &[f64; INPUTS],
    rows: &[Split; READS],
) -> [f64; READS] {
    let n = e.len();
    let (er, ei) = (&e.re[..n], &e.im[..n]);
    let (zr, zi) = (&mut z.re[..n], &mut z.im[..n]);
    let gr: [&[f64]; INPUTS] = std::array::from_fn(|j| &g[j].re[..n]);
    let gi: [&[f64]; INPUTS] = std::array::from_fn(|j| &g[j].im[..n]);
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
            for j in 0..INPUTS {
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

/// `z <- e ⊙ z`, then `Re(r z)`, in one pass: 6 FLOP per mode to propagate, 4 to read; with
/// AVX2 + FMA where the CPU has them (a key alone: nothing else enters, one row is read).
pub(crate) fn propagate_read(e: &Split, z: &mut Split, r: &Split, fast: bool) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if fast {
        // SAFETY: `fast` is set only where `has_avx2_fma()` found AVX2 and FMA.
        return unsafe { propagate_read_avx2(e, z, r) };
    }
    let _ = fast;
    propagate_read_with::<false>(e, z, r)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn propagate_read_avx2(e: &Split, z: &mut Split, r: &Split) -> f64 {
    propagate_read_with::<true>(e, z, r)
}

#[inline(always)]
fn propagate_read_with<const FMA: bool>(e: &Split, z: &mut Split, r: &Split) -> f64 {
    let n = e.len();
    let (er, ei, rr, ri) = (&e.re[..n], &e.im[..n], &r.re[..n], &r.im[..n]);
    let (zr, zi) = (&mut z.re[..n], &mut z.im[..n]);
    let mut acc = [0.0; LANES];
    let mut tail = 0.0;
    let whole = n / LANES * LANES;
    for base in (0..whole).step_by(LANES) {
        for l in 0..LANES {
            let m = base + l;
            let (a, b) = (zr[m], zi[m]);
            let (re, im) = (
                fma::<FMA>(er[m], a, -ei[m] * b),
                fma::<FMA>(er[m], b, ei[m] * a),
            );
            zr[m] = re;
            zi[m] = im;
            acc[l] = fma::<FMA>(rr[m], re, fma::<FMA>(-ri[m], im, acc[l]));
        }
    }
    for m in whole..n {
        let (a, b) = (zr[m], zi[m]);
        let (re, im) = (er[m] * a - ei[m] * b, er[m] * b + ei[m] * a);
        zr[m] = re;
        zi[m] = im;
        tail += rr[m] * re - ri[m] * im;
    }
    acc.iter().sum::<f64>() + tail
}

/// `z <- e ⊙ z` (complex, per mode) on the first `e.len()` modes.
pub(crate) fn propagate(e: &Split, z: &mut Split) {
    for m in 0..e.len() {
        let (a, b) = (z.re[m], z.im[m]);
        z.re[m] = e.re[m] * a - e.im[m] * b;
        z.im[m] = e.re[m] * b + e.im[m] * a;
    }
}

/// `out = e2 ⊙ from + sum_s q_s u_s` over the struck strings' inputs (zero forces add nothing).
pub(crate) fn stage(out: &mut Split, e2: &Split, from: &Split, q: &[Split], u: &[f64]) {
    for m in 0..e2.len() {
        let (a, b) = (from.re[m], from.im[m]);
        out.re[m] = e2.re[m] * a - e2.im[m] * b;
        out.im[m] = e2.re[m] * b + e2.im[m] * a;
    }
    for (s, q) in q.iter().enumerate() {
        if u[s] != 0.0 {
            q.add_to(out, u[s]);
        }
    }
}

/// Longest block advanced mode by mode ([`free_block`], [`fold_block`]).
pub(crate) const BLOCK: usize = 64;

/// A block's inputs per direction, step `t` at `BLOCK - 1 - t` (so that a convolution with
/// Markov parameters is a forward dot product).
pub(crate) type Reversed = [[f64; BLOCK]; DIRECTIONS];

/// Markov parameters per read and direction, tap `k` (steps after the input) at `k`.
pub(crate) type Taps = [[[f64; BLOCK]; DIRECTIONS]; READS];

/// What the inputs of steps `0..=t` add to each read after step `t`:
/// `sum_d sum_{j<=t} taps[i][d][t-j] u_d(j)`; with AVX2 + FMA where `fast`.
pub(crate) fn convolve(fast: bool, taps: &Taps, u: &Reversed, t: usize) -> [f64; READS] {
    #[cfg(target_arch = "x86_64")]
    if fast {
        // SAFETY: `fast` is set only where `has_avx2_fma()` found AVX2 and FMA.
        return unsafe { convolve_avx2(taps, u, t) };
    }
    let _ = fast;
    convolve_with::<false>(taps, u, t)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn convolve_avx2(taps: &Taps, u: &Reversed, t: usize) -> [f64; READS] {
    convolve_with::<true>(taps, u, t)
}

#[inline(always)]
fn convolve_with<const FMA: bool>(taps: &Taps, u: &Reversed, t: usize) -> [f64; READS] {
    const W: usize = 4;
    let start = BLOCK - 1 - t;
    std::array::from_fn(|i| {
        let mut acc = [0.0; W];
        for d in 0..DIRECTIONS {
            let (a, b) = (&taps[i][d][..=t], &u[d][start..]);
            let whole = a.len() / W * W;
            for k in (0..whole).step_by(W) {
                for l in 0..W {
                    acc[l] = fma::<FMA>(a[k + l], b[k + l], acc[l]);
                }
            }
            for k in whole..a.len() {
                acc[0] = fma::<FMA>(a[k], b[k], acc[0]);
            }
        }
        acc.iter().sum()
    })
}

/// A complex vector per mode in single precision, real and imaginary parts apart: the block
/// kernels' coefficients (half the bytes and twice the lanes of [`Split`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Split32 {
    pub(crate) re: Vec<f32>,
    pub(crate) im: Vec<f32>,
}

impl Split32 {
    pub(crate) fn new(v: &Split) -> Split32 {
        Split32 {
            re: v.re.iter().map(|&x| x as f32).collect(),
            im: v.im.iter().map(|&x| x as f32).collect(),
        }
    }
}

/// Lanes of the single-precision block loops: two AVX2 registers, two independent recursions
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
/// f32 would shift the slowest modes' decay by ~8 %).
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct BlockCoefficients {
    pub(crate) e: Split32,
    pub(crate) e_block: Split,
    /// The rows read after every step ([`READS`]) and the inputs folded in ([`DIRECTIONS`]).
    pub(crate) rows: [Split32; READS],
    pub(crate) inputs: [Split32; DIRECTIONS],
}

impl BlockCoefficients {
    pub(crate) fn new(
        e: &Split,
        rows: &[Split; READS],
        inputs: &[Split; DIRECTIONS],
    ) -> BlockCoefficients {
        let mut e_block = Split::zeros(e.len());
        for m in 0..e.len() {
            (e_block.re[m], e_block.im[m]) = power(e.re[m], e.im[m], BLOCK);
        }
        BlockCoefficients {
            e: Split32::new(e),
            e_block,
            rows: std::array::from_fn(|i| Split32::new(&rows[i])),
            inputs: std::array::from_fn(|j| Split32::new(&inputs[j])),
        }
    }
}

/// `len` free steps of every mode, mode by mode (each mode's coefficients loaded once):
/// `out[i][t] = Re(r_i e^{t+1} z)` for `t < len` in single precision, then `z <- e^len ⊙ z` in
/// double (`e_step` is the double-precision step, for a block shorter than [`BLOCK`]).
pub(crate) fn free_block(
    fast: bool,
    c: &BlockCoefficients,
    e_step: &Split,
    z: &mut Split,
    out: &mut [[f64; BLOCK]; READS],
    len: usize,
) {
    #[cfg(target_arch = "x86_64")]
    if fast {
        // SAFETY: `fast` is set only where `has_avx2_fma()` found AVX2 and FMA.
        return unsafe { free_block_avx2(c, e_step, z, out, len) };
    }
    let _ = fast;
    free_block_with::<false>(c, e_step, z, out, len)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn free_block_avx2(
    c: &BlockCoefficients,
    e_step: &Split,
    z: &mut Split,
    out: &mut [[f64; BLOCK]; READS],
    len: usize,
) {
    free_block_with::<true>(c, e_step, z, out, len)
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

#[inline(always)]
fn free_block_with<const FMA: bool>(
    c: &BlockCoefficients,
    e_step: &Split,
    z: &mut Split,
    out: &mut [[f64; BLOCK]; READS],
    len: usize,
) {
    let n = c.e.re.len();
    let mut acc = [[[0f32; LANES32]; BLOCK]; READS];
    let mut base = 0;
    while base < n {
        let lanes = LANES32.min(n - base);
        let mut er = [0f32; LANES32];
        let mut ei = [0f32; LANES32];
        let mut zr = [0f32; LANES32];
        let mut zi = [0f32; LANES32];
        let mut rr = [[0f32; LANES32]; READS];
        let mut ri = [[0f32; LANES32]; READS];
        for l in 0..lanes {
            let m = base + l;
            (er[l], ei[l]) = (c.e.re[m], c.e.im[m]);
            (zr[l], zi[l]) = (z.re[m] as f32, z.im[m] as f32);
            for i in 0..READS {
                (rr[i][l], ri[i][l]) = (c.rows[i].re[m], c.rows[i].im[m]);
            }
        }
        for t in 0..len {
            for l in 0..LANES32 {
                let (a, b) = (zr[l], zi[l]);
                zr[l] = fma32::<FMA>(er[l], a, -ei[l] * b);
                zi[l] = fma32::<FMA>(er[l], b, ei[l] * a);
                for i in 0..READS {
                    acc[i][t][l] = fma32::<FMA>(
                        rr[i][l],
                        zr[l],
                        fma32::<FMA>(-ri[i][l], zi[l], acc[i][t][l]),
                    );
                }
            }
        }
        for m in base..base + lanes {
            let (pr, pi) = if len == BLOCK {
                (c.e_block.re[m], c.e_block.im[m])
            } else {
                power(e_step.re[m], e_step.im[m], len)
            };
            let (a, b) = (z.re[m], z.im[m]);
            z.re[m] = pr * a - pi * b;
            z.im[m] = pr * b + pi * a;
        }
        base += lanes;
    }
    for i in 0..READS {
        for t in 0..len {
            out[i][t] = acc[i][t].iter().map(|&x| f64::from(x)).sum();
        }
    }
}

/// Fold `len` steps of inputs into the modes, mode by mode: `z += sum_t e^{len-1-t} (sum_j g_j
/// u_j(t))`, the sum formed in single precision (it starts from zero each block) and added in
/// double — by superposition, what stepping the inputs in one at a time adds. The inputs are
/// [`Reversed`].
pub(crate) fn fold_block(
    fast: bool,
    c: &BlockCoefficients,
    z: &mut Split,
    u: &Reversed,
    len: usize,
) {
    #[cfg(target_arch = "x86_64")]
    if fast {
        // SAFETY: `fast` is set only where `has_avx2_fma()` found AVX2 and FMA.
        return unsafe { fold_block_avx2(c, z, u, len) };
    }
    let _ = fast;
    fold_block_with::<false>(c, z, u, len)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn fold_block_avx2(c: &BlockCoefficients, z: &mut Split, u: &Reversed, len: usize) {
    fold_block_with::<true>(c, z, u, len)
}

#[inline(always)]
fn fold_block_with<const FMA: bool>(
    c: &BlockCoefficients,
    z: &mut Split,
    u: &Reversed,
    len: usize,
) {
    let n = c.e.re.len();
    let u32s: [[f32; DIRECTIONS]; BLOCK] =
        std::array::from_fn(|t| std::array::from_fn(|j| u[j][BLOCK - 1 - t] as f32));
    let mut base = 0;
    while base < n {
        let lanes = LANES32.min(n - base);
        let mut er = [0f32; LANES32];
        let mut ei = [0f32; LANES32];
        let mut gr = [[0f32; LANES32]; DIRECTIONS];
        let mut gi = [[0f32; LANES32]; DIRECTIONS];
        for l in 0..lanes {
            let m = base + l;
            (er[l], ei[l]) = (c.e.re[m], c.e.im[m]);
            for j in 0..DIRECTIONS {
                (gr[j][l], gi[j][l]) = (c.inputs[j].re[m], c.inputs[j].im[m]);
            }
        }
        let (mut ar, mut ai) = ([0f32; LANES32], [0f32; LANES32]);
        for ut in u32s.iter().take(len) {
            for l in 0..LANES32 {
                let (a, b) = (ar[l], ai[l]);
                let (mut re, mut im) = (
                    fma32::<FMA>(er[l], a, -ei[l] * b),
                    fma32::<FMA>(er[l], b, ei[l] * a),
                );
                for j in 0..DIRECTIONS {
                    re = fma32::<FMA>(gr[j][l], ut[j], re);
                    im = fma32::<FMA>(gi[j][l], ut[j], im);
                }
                (ar[l], ai[l]) = (re, im);
            }
        }
        for l in 0..lanes {
            z.re[base + l] += f64::from(ar[l]);
            z.im[base + l] += f64::from(ai[l]);
        }
        base += lanes;
    }
}
