//! A key's coefficients as bytes and back, so that a front end can keep the costly
//! diagonalisation between runs (the engine does no I/O: where the bytes are kept is the caller's
//! business). The layout is this build's own: a version word, then every vector as its length
//! and its values, little-endian; anything that does not read back whole is refused, never
//! patched.

use super::kernels::{BlockCoefficients, Split, Split32, BLOCK, DIRECTIONS, INPUTS, READS};
use super::key::{DamperKey, ExactKey, DAMPER_CHANNELS};
use crate::engine::spec::UnisonSpec;
use faer::c64;

/// Changes whenever the layout or what the coefficients mean changes.
const VERSION: u64 = 2;

#[derive(Default)]
struct Writer(Vec<u8>);

impl Writer {
    fn f64(&mut self, x: f64) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    fn len(&mut self, n: usize) {
        self.0.extend_from_slice(&(n as u64).to_le_bytes());
    }
    fn f64s(&mut self, x: &[f64]) {
        self.len(x.len());
        x.iter().for_each(|&x| self.f64(x));
    }
    fn f32s(&mut self, x: &[f32]) {
        self.len(x.len());
        x.iter()
            .for_each(|&x| self.0.extend_from_slice(&x.to_le_bytes()));
    }
    fn split(&mut self, s: &Split) {
        self.f64s(&s.re);
        self.f64s(&s.im);
    }
    fn splits(&mut self, s: &[Split]) {
        self.len(s.len());
        s.iter().for_each(|s| self.split(s));
    }
    fn split32(&mut self, s: &Split32) {
        self.f32s(&s.re);
        self.f32s(&s.im);
    }
}

struct Reader<'a>(&'a [u8]);

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Option<&[u8]> {
        let (head, rest) = self.0.split_at_checked(n)?;
        self.0 = rest;
        Some(head)
    }
    fn f64(&mut self) -> Option<f64> {
        Some(f64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    /// A length, refused if the bytes left cannot hold that many values of `size` bytes.
    fn len(&mut self, size: usize) -> Option<usize> {
        let n = usize::try_from(u64::from_le_bytes(self.take(8)?.try_into().ok()?)).ok()?;
        (n.checked_mul(size)? <= self.0.len()).then_some(n)
    }
    fn f64s(&mut self) -> Option<Vec<f64>> {
        let n = self.len(8)?;
        (0..n).map(|_| self.f64()).collect()
    }
    fn f32s(&mut self) -> Option<Vec<f32>> {
        let n = self.len(4)?;
        (0..n)
            .map(|_| Some(f32::from_le_bytes(self.take(4)?.try_into().ok()?)))
            .collect()
    }
    fn array<const N: usize>(&mut self) -> Option<[f64; N]> {
        self.f64s()?.try_into().ok()
    }
    /// An `R × C` matrix written row by row as one vector.
    fn matrix<const R: usize, const C: usize>(&mut self) -> Option<[[f64; C]; R]> {
        let flat = self.f64s()?;
        (flat.len() == R * C)
            .then(|| std::array::from_fn(|i| std::array::from_fn(|j| flat[i * C + j])))
    }
    /// A split of exactly `modes` modes.
    fn split(&mut self, modes: usize) -> Option<Split> {
        let s = Split {
            re: self.f64s()?,
            im: self.f64s()?,
        };
        (s.re.len() == modes && s.im.len() == modes).then_some(s)
    }
    fn splits(&mut self, modes: usize) -> Option<Vec<Split>> {
        let n = self.len(16)?;
        (0..n).map(|_| self.split(modes)).collect()
    }
    fn split_array<const N: usize>(&mut self, modes: usize) -> Option<[Split; N]> {
        self.splits(modes)?.try_into().ok()
    }
    fn split32(&mut self, modes: usize) -> Option<Split32> {
        let s = Split32 {
            re: self.f32s()?,
            im: self.f32s()?,
        };
        (s.re.len() == modes && s.im.len() == modes).then_some(s)
    }
}

impl ExactKey {
    /// The coefficients as bytes ([`ExactKey::from_bytes`] reads them back for the same spec).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut w = Writer::default();
        w.len(VERSION as usize);
        w.len(self.n_modes());
        w.f64s(&self.lambda.iter().map(|l| l.re).collect::<Vec<_>>());
        w.f64s(&self.lambda.iter().map(|l| l.im).collect::<Vec<_>>());
        w.split(&self.eh);
        w.split(&self.ef);
        w.splits(&self.strike_row);
        w.splits(&self.drive_q);
        w.splits(&self.drive_f.concat());
        w.splits(&self.force_row.concat());
        w.splits(&self.bridge_velocity_row);
        w.splits(&self.reads);
        w.splits(&self.coupling);
        w.f64s(&self.feed_k);
        w.f64s(&self.feed_c);
        w.splits(&self.follow);
        w.splits(&self.block_alpha);
        w.f64s(&self.block_alpha_read.concat());
        w.split32(&self.block.e);
        w.split(&self.block.e_block);
        self.block.rows.iter().for_each(|s| w.split32(s));
        self.block.inputs.iter().for_each(|s| w.split32(s));
        for taps in self.markov.iter().flatten() {
            w.f64s(taps);
        }
        match &self.damper {
            None => w.len(0),
            Some(d) => {
                w.len(d.channels);
                w.splits(&d.rows);
                w.splits(&d.from);
                w.splits(&d.to);
                w.f64s(&d.rows_from);
                w.f64s(&d.solve);
                w.f64s(&d.reads_from.concat());
                w.f64s(&d.reads_to.concat());
            }
        }
        w.f64s(&self.energy);
        w.0
    }

    /// The coefficients [`ExactKey::to_bytes`] wrote for `spec`'s key (the hammer, the strings'
    /// count and the step are taken from `spec`); `None` if the bytes are of another layout,
    /// truncated or do not fit the spec.
    pub fn from_bytes(spec: &UnisonSpec, bytes: &[u8]) -> Option<ExactKey> {
        let mut r = Reader(bytes);
        if r.len(0)? != VERSION as usize {
            return None;
        }
        let n = r.len(0)?;
        let ns = spec.strings.len();
        let (lre, lim) = (r.f64s()?, r.f64s()?);
        if lre.len() != n || lim.len() != n {
            return None;
        }
        let lambda = lre
            .iter()
            .zip(&lim)
            .map(|(&a, &b)| c64::new(a, b))
            .collect();
        let eh = r.split(n)?;
        let ef = r.split(n)?;
        let strike_row = r.splits(n)?;
        let drive_q = r.splits(n)?;
        let grouped = |v: Vec<Split>| -> Option<Vec<[Split; 3]>> {
            if v.len() != 3 * ns {
                return None;
            }
            let mut it = v.into_iter();
            (0..ns)
                .map(|_| Some([it.next()?, it.next()?, it.next()?]))
                .collect()
        };
        let drive_f = grouped(r.splits(n)?)?;
        let force_row = grouped(r.splits(n)?)?;
        if strike_row.len() != ns || drive_q.len() != ns {
            return None;
        }
        let bridge_velocity_row = r.split_array::<3>(n)?;
        let reads = r.split_array::<READS>(n)?;
        let coupling = r.split_array::<INPUTS>(n)?;
        let feed_k = r.array::<3>()?;
        let feed_c = r.array::<3>()?;
        let follow = r.split_array::<3>(n)?;
        let block_alpha = r.split_array::<DIRECTIONS>(n)?;
        let block_alpha_read = r.matrix()?;
        let e32 = r.split32(n)?;
        let e_block = r.split(n)?;
        let mut rows: [Split32; READS] = Default::default();
        for row in rows.iter_mut() {
            *row = r.split32(n)?;
        }
        let mut inputs: [Split32; DIRECTIONS] = Default::default();
        for input in inputs.iter_mut() {
            *input = r.split32(n)?;
        }
        let mut markov = Box::new([[[0.0; BLOCK]; DIRECTIONS]; READS]);
        for taps in markov.iter_mut().flatten() {
            *taps = r.array::<BLOCK>()?;
        }
        let channels = r.len(0)?;
        let damper = match channels {
            0 => None,
            c if c <= DAMPER_CHANNELS => {
                let rows = r.splits(n)?;
                let from = r.splits(n)?;
                let to = r.splits(n)?;
                if rows.len() != c || from.len() != c || to.len() != c {
                    return None;
                }
                let rows_from = r.array::<{ DAMPER_CHANNELS * DAMPER_CHANNELS }>()?;
                let solve = r.array::<{ DAMPER_CHANNELS * DAMPER_CHANNELS }>()?;
                let reads_from = r.matrix()?;
                let reads_to = r.matrix()?;
                Some(DamperKey {
                    channels: c,
                    rows,
                    from,
                    to,
                    rows_from,
                    solve,
                    reads_from,
                    reads_to,
                })
            }
            _ => return None,
        };
        if damper.is_some() != spec.damper.is_some() {
            return None;
        }
        let energy = r.f64s()?;
        if energy.len() != n || !r.0.is_empty() {
            return None;
        }
        Some(ExactKey {
            n_strings: ns,
            h: 1.0 / spec.sample_rate_hz,
            lambda,
            eh,
            ef,
            strike_row,
            drive_q,
            drive_f,
            force_row,
            bridge_velocity_row,
            reads,
            coupling,
            feed_k,
            feed_c,
            follow,
            block_alpha,
            block_alpha_read,
            block: BlockCoefficients {
                e: e32,
                e_block,
                rows,
                inputs,
            },
            markov,
            damper,
            energy,
            hammer: spec.hammer,
        })
    }
}
