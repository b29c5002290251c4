//! A key's modes as bytes and back, so that a front end can keep the costly
//! diagonalisation between runs (the engine does no I/O: where the bytes are kept, and whether
//! they arrived as written, is the caller's business). The layout is this build's own: a version
//! word, then every vector as its length and its values, little-endian; anything that does not
//! read back whole, or reads back as values no key has, is refused, never patched.

use super::kernels::Split;
use super::key::{ExactKey, KeyModes};
use crate::engine::spec::{UnisonSpec, CHANNELS};
use crate::engine::StoredKeyError;
use faer::c64;

/// Changes whenever the layout or what the coefficients mean changes.
const VERSION: u64 = 4;

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
    fn split(&mut self, s: &Split) {
        self.f64s(&s.re);
        self.f64s(&s.im);
    }
    fn splits(&mut self, s: &[Split]) {
        self.len(s.len());
        s.iter().for_each(|s| self.split(s));
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
}

impl ExactKey {
    /// The key's modes as bytes ([`ExactKey::from_bytes`] reads them back for the same spec;
    /// everything else is derived from them).
    pub fn to_bytes(&self) -> Vec<u8> {
        let m = &self.modes;
        let mut w = Writer::default();
        w.len(VERSION as usize);
        w.len(m.n_modes());
        w.f64s(&m.lambda.iter().map(|l| l.re).collect::<Vec<_>>());
        w.f64s(&m.lambda.iter().map(|l| l.im).collect::<Vec<_>>());
        w.splits(&m.strike_row);
        w.splits(&m.strike_input);
        w.splits(&m.force_row.concat());
        w.splits(&m.bridge_velocity_row);
        w.splits(&m.volume_rows);
        w.splits(&m.bridge_input.concat());
        w.splits(&m.damper_row);
        w.splits(&m.damper_input);
        w.f64s(&m.energy);
        w.0
    }

    /// The key [`ExactKey::to_bytes`] wrote for `spec` (the hammer, the strings' count, the
    /// damper and the step are taken from `spec`); refused as [`StoredKeyError::Layout`] if the
    /// bytes are of another layout, truncated or do not fit the spec, as
    /// [`StoredKeyError::Meaning`] if their values are not a key's ([`KeyModes::playable`]).
    pub fn from_bytes(spec: &UnisonSpec, bytes: &[u8]) -> Result<ExactKey, StoredKeyError> {
        let modes = read_modes(spec, bytes).ok_or(StoredKeyError::Layout)?;
        if !modes.playable() {
            return Err(StoredKeyError::Meaning);
        }
        Ok(ExactKey::from_modes(spec, modes))
    }
}

impl KeyModes {
    /// Whether the modes are values a key can have: every eigenvalue finite with Re λ ≤ 0 (each
    /// mode decays or holds, |e^{λh}| ≤ 1 at any step; one that grows would drive the board
    /// louder every step), every row and input finite, every mode's energy finite and ≥ 0 (the
    /// pool ranks and retires voices by it).
    fn playable(&self) -> bool {
        let finite = |s: &Split| s.re.iter().chain(&s.im).all(|x| x.is_finite());
        // `<=` is false for NaN, so a NaN real part is refused with the growing modes.
        let decays = |l: &c64| l.re <= 0.0 && l.im.is_finite();
        self.lambda.iter().all(decays)
            && self
                .strike_row
                .iter()
                .chain(&self.strike_input)
                .chain(self.force_row.iter().flatten())
                .chain(&self.bridge_velocity_row)
                .chain(&self.volume_rows)
                .chain(self.bridge_input.iter().flatten())
                .chain(&self.damper_row)
                .chain(&self.damper_input)
                .all(finite)
            && self.energy.iter().all(|&e| e.is_finite() && e >= 0.0)
    }
}

/// The modes laid out in `bytes` for `spec`, if they are laid out as [`ExactKey::to_bytes`]
/// writes `spec`'s key.
fn read_modes(spec: &UnisonSpec, bytes: &[u8]) -> Option<KeyModes> {
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
    let strike_row = r.splits(n)?;
    let strike_input = r.splits(n)?;
    let force_row = r.splits(n)?;
    if strike_row.len() != ns || strike_input.len() != ns || force_row.len() != 3 * ns {
        return None;
    }
    let mut rows = force_row.into_iter();
    let force_row = (0..ns)
        .map(|_| Some([rows.next()?, rows.next()?, rows.next()?]))
        .collect::<Option<Vec<_>>>()?;
    let bridge_velocity_row = r.split_array::<3>(n)?;
    let volume_rows = r.split_array::<CHANNELS>(n)?;
    let [gk_t, gc_t, gk_l, gc_l, gk_p, gc_p] = r.split_array::<6>(n)?;
    let bridge_input = [[gk_t, gc_t], [gk_l, gc_l], [gk_p, gc_p]];
    let damper_row = r.splits(n)?;
    let damper_input = r.splits(n)?;
    let channels = spec.damper.map_or(0, |d| 2 * ns * d.point_count());
    if damper_row.len() != channels || damper_input.len() != channels {
        return None;
    }
    let energy = r.f64s()?;
    if energy.len() != n || !r.0.is_empty() {
        return None;
    }
    Some(KeyModes {
        lambda,
        strike_row,
        strike_input,
        force_row,
        bridge_velocity_row,
        volume_rows,
        bridge_input,
        damper_row,
        damper_input,
        energy,
    })
}
