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
const LANES: usize = 8;

/// Inputs that enter a step (the coupling's value and slope per direction) and rows read after it
/// (the volume velocity and the total contact force per direction).
pub(crate) const INPUTS: usize = 6;
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
fn fma<const FMA: bool>(a: f64, b: f64, c: f64) -> f64 {
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
    let mut mode = |m: usize, lane: usize, acc: &mut [[f64; LANES]; READS]| {
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
    };
    let whole = n / LANES * LANES;
    for base in (0..whole).step_by(LANES) {
        for lane in 0..LANES {
            mode(base + lane, lane, &mut acc);
        }
    }
    for m in whole..n {
        mode(m, 0, &mut acc);
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

/// `len` free steps of every mode, mode by mode (each mode's coefficients loaded once): `z <-
/// e^len ⊙ z`, and `out[i][t] = Re(r_i e^{t+1} z)` for `t < len` — what the per-sample
/// [`advance`] reads with no input, in another order of summation.
pub(crate) fn free_block(
    fast: bool,
    e: &Split,
    z: &mut Split,
    rows: &[Split; READS],
    out: &mut [[f64; BLOCK]; READS],
    len: usize,
) {
    #[cfg(target_arch = "x86_64")]
    if fast {
        // SAFETY: `fast` is set only where `has_avx2_fma()` found AVX2 and FMA.
        return unsafe { free_block_avx2(e, z, rows, out, len) };
    }
    let _ = fast;
    free_block_with::<false>(e, z, rows, out, len)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn free_block_avx2(
    e: &Split,
    z: &mut Split,
    rows: &[Split; READS],
    out: &mut [[f64; BLOCK]; READS],
    len: usize,
) {
    free_block_with::<true>(e, z, rows, out, len)
}

#[inline(always)]
fn free_block_with<const FMA: bool>(
    e: &Split,
    z: &mut Split,
    rows: &[Split; READS],
    out: &mut [[f64; BLOCK]; READS],
    len: usize,
) {
    let n = e.len();
    let mut acc = [[[0.0; LANES]; BLOCK]; READS];
    let mut chunk = |base: usize, lanes: usize, acc: &mut [[[f64; LANES]; BLOCK]; READS]| {
        let mut er = [0.0; LANES];
        let mut ei = [0.0; LANES];
        let mut zr = [0.0; LANES];
        let mut zi = [0.0; LANES];
        let mut rr = [[0.0; LANES]; READS];
        let mut ri = [[0.0; LANES]; READS];
        for l in 0..lanes {
            let m = base + l;
            (er[l], ei[l], zr[l], zi[l]) = (e.re[m], e.im[m], z.re[m], z.im[m]);
            for i in 0..READS {
                (rr[i][l], ri[i][l]) = (rows[i].re[m], rows[i].im[m]);
            }
        }
        for t in 0..len {
            for l in 0..LANES {
                let (a, b) = (zr[l], zi[l]);
                zr[l] = fma::<FMA>(er[l], a, -ei[l] * b);
                zi[l] = fma::<FMA>(er[l], b, ei[l] * a);
                for i in 0..READS {
                    acc[i][t][l] =
                        fma::<FMA>(rr[i][l], zr[l], fma::<FMA>(-ri[i][l], zi[l], acc[i][t][l]));
                }
            }
        }
        for l in 0..lanes {
            (z.re[base + l], z.im[base + l]) = (zr[l], zi[l]);
        }
    };
    let mut base = 0;
    while base < n {
        let lanes = LANES.min(n - base);
        chunk(base, lanes, &mut acc);
        base += lanes;
    }
    for i in 0..READS {
        for t in 0..len {
            out[i][t] = acc[i][t].iter().sum();
        }
    }
}

/// Fold `len` steps of inputs into the modes, mode by mode: `z += sum_t e^{len-1-t} (sum_j g_j
/// u[t][j])` — what the per-sample [`advance`] adds, by superposition.
pub(crate) fn fold_block(
    fast: bool,
    e: &Split,
    z: &mut Split,
    g: &[Split; INPUTS],
    u: &[[f64; INPUTS]; BLOCK],
    len: usize,
) {
    #[cfg(target_arch = "x86_64")]
    if fast {
        // SAFETY: `fast` is set only where `has_avx2_fma()` found AVX2 and FMA.
        return unsafe { fold_block_avx2(e, z, g, u, len) };
    }
    let _ = fast;
    fold_block_with::<false>(e, z, g, u, len)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn fold_block_avx2(
    e: &Split,
    z: &mut Split,
    g: &[Split; INPUTS],
    u: &[[f64; INPUTS]; BLOCK],
    len: usize,
) {
    fold_block_with::<true>(e, z, g, u, len)
}

#[inline(always)]
fn fold_block_with<const FMA: bool>(
    e: &Split,
    z: &mut Split,
    g: &[Split; INPUTS],
    u: &[[f64; INPUTS]; BLOCK],
    len: usize,
) {
    let n = e.len();
    let mut base = 0;
    while base < n {
        let lanes = LANES.min(n - base);
        let mut er = [0.0; LANES];
        let mut ei = [0.0; LANES];
        let mut gr = [[0.0; LANES]; INPUTS];
        let mut gi = [[0.0; LANES]; INPUTS];
        for l in 0..lanes {
            let m = base + l;
            (er[l], ei[l]) = (e.re[m], e.im[m]);
            for j in 0..INPUTS {
                (gr[j][l], gi[j][l]) = (g[j].re[m], g[j].im[m]);
            }
        }
        let (mut ar, mut ai) = ([0.0; LANES], [0.0; LANES]);
        for ut in u.iter().take(len) {
            for l in 0..LANES {
                let (a, b) = (ar[l], ai[l]);
                let (mut re, mut im) = (
                    fma::<FMA>(er[l], a, -ei[l] * b),
                    fma::<FMA>(er[l], b, ei[l] * a),
                );
                for j in 0..INPUTS {
                    re = fma::<FMA>(gr[j][l], ut[j], re);
                    im = fma::<FMA>(gi[j][l], ut[j], im);
                }
                (ar[l], ai[l]) = (re, im);
            }
        }
        for l in 0..lanes {
            z.re[base + l] += ar[l];
            z.im[base + l] += ai[l];
        }
        base += lanes;
    }
}
