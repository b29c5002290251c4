//! Prepared keys kept between runs: the exact engine's diagonalisation of the 88 keys takes
//! ~25 s on two cores, reading them back a fraction of a second. One file per key under the
//! cache directory, named by a hash of everything that decides its coefficients — the key's full
//! spec (every parameter, the board at its point, the rate), the engine and the source of the
//! code that computes them ([`StoredKey::SOURCE`]) — so a file is only ever read by a build and a
//! keyboard that would compute the same numbers.
//!
//! A file is the engine's bytes framed by the cache: [`MAGIC`], the key's identity (the hash its
//! name carries), a CRC-32 of the identity and the bytes, then the bytes. A key read back is
//! played as it is, so a file is used only if it is this key's, arrived as it was written (the
//! checksum) and says something a key can be (the engine's check, [`StoredKey::from_bytes`]);
//! any other is refused, counted by why ([`Refusal`]), prepared again and replaced. A directory
//! that cannot be written costs only the time.

use crate::engine::physics::soundboard::{BridgePoint, Listener, SoundboardModes};
use crate::engine::{StoredKey, StoredKeyError, UnisonSpec};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// The first bytes of every kept file: which framing follows (another framing's files are
/// never read: the names hash it too).
pub const MAGIC: [u8; 8] = *b"unacKEY1";

/// Bytes before the engine's: [`MAGIC`], the identity (`u64`), the checksum (`u32`), all
/// little-endian.
pub const HEADER_BYTES: usize = MAGIC.len() + 8 + 4;

/// Why a kept file was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// Its checksum does not match: the file changed after it was written (cut short, a bit
    /// flipped on the disk or by a tool).
    Checksum,
    /// Whole and this key's, but the engine finds values no key has ([`StoredKeyError::Meaning`]).
    Meaning,
    /// Not a kept key of this framing and this key: too short for the header, another magic,
    /// another key's identity (a file copied or renamed onto this name), or bytes the engine does
    /// not lay out as this key's ([`StoredKeyError::Layout`]).
    Layout,
}

impl Refusal {
    pub const ALL: [Refusal; 3] = [Refusal::Checksum, Refusal::Meaning, Refusal::Layout];

    pub fn name(self) -> &'static str {
        match self {
            Refusal::Checksum => "checksum",
            Refusal::Meaning => "meaning",
            Refusal::Layout => "layout",
        }
    }
}

impl From<StoredKeyError> for Refusal {
    fn from(e: StoredKeyError) -> Refusal {
        match e {
            StoredKeyError::Layout => Refusal::Layout,
            StoredKeyError::Meaning => Refusal::Meaning,
        }
    }
}

/// Where prepared keys are kept, and what this run read, prepared and refused there. The counts
/// are touched by the threads that build keys; a front end reads them once the keys are built
/// (or polls them while they are, for progress), never on the audio thread.
#[derive(Debug)]
pub struct KeyCache {
    dir: PathBuf,
    /// Keys read back from the cache.
    pub hits: AtomicUsize,
    /// Keys prepared and stored.
    pub stored: AtomicUsize,
    /// Keys prepared (stored or not, kept by this engine or not): with `hits`, the keys done.
    pub prepared: AtomicUsize,
    /// Kept files refused, per [`Refusal`] (in the order of [`Refusal::ALL`]).
    refused: [AtomicUsize; 3],
    /// The first file refused, and why.
    first_refused: Mutex<Option<(PathBuf, Refusal)>>,
}

/// FNV-1a, 64 bits: a stable hash (the same in every build and on every machine).
fn fnv1a(hash: u64, bytes: &[u8]) -> u64 {
    bytes.iter().fold(hash, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// FNV-1a's step over 64-bit words: a stable hash of numbers by their bits, a word a step.
fn fnv1a_words(hash: u64, words: impl IntoIterator<Item = u64>) -> u64 {
    words
        .into_iter()
        .fold(hash, |h, w| (h ^ w).wrapping_mul(0x0000_0100_0000_01b3))
}

/// `hash` followed by `x`'s length and its values' bits.
fn floats_hash(hash: u64, x: &[f64]) -> u64 {
    let h = fnv1a_words(hash, [x.len() as u64]);
    fnv1a_words(h, x.iter().map(|x| x.to_bits()))
}

/// `hash` followed by `text`'s length and its bytes.
fn text_hash(hash: u64, text: &str) -> u64 {
    fnv1a(fnv1a_words(hash, [text.len() as u64]), text.as_bytes())
}

/// `hash` followed by every number and name of `board` (and its dropped modes'): what its
/// `Debug` text says, without writing a few hundred thousand numbers out as text for every key.
fn board_hash(hash: u64, board: &SoundboardModes) -> u64 {
    let SoundboardModes {
        freq_hz,
        damping_ratio,
        volume_m2_per_sqrt_kg,
        points,
        listeners,
        heard,
        residual,
    } = board;
    let mut h = [freq_hz, damping_ratio, volume_m2_per_sqrt_kg]
        .into_iter()
        .fold(hash, |h, x| floats_hash(h, x));
    h = fnv1a_words(h, [points.len() as u64]);
    for BridgePoint { name, shape } in points {
        h = text_hash(h, name);
        h = shape.iter().fold(h, |h, x| floats_hash(h, x));
    }
    h = fnv1a_words(h, [listeners.len() as u64]);
    for Listener {
        name,
        rayleigh_re,
        rayleigh_im,
    } in listeners
    {
        h = text_hash(h, name);
        h = floats_hash(floats_hash(h, rayleigh_re), rayleigh_im);
    }
    h = text_hash(h, &format!("{heard:?}"));
    match residual {
        Some(residual) => board_hash(fnv1a_words(h, [1]), residual),
        None => fnv1a_words(h, [0]),
    }
}

/// The checksum of a file: CRC-32 (IEEE) of the identity and the engine's bytes. It guards
/// against accidents, not against someone who means harm (whoever can write the directory can
/// write a valid checksum; the engine's check is what keeps unplayable values out). CRC-32 sees
/// every burst of up to 32 damaged bits and any one or two flipped bits in a file of any size a
/// key has, lets other damage through once in 2^32, and is computed (with the processor's
/// carry-less multiply where it has one) far faster than the disk reads. A 64-bit hash would only lower that
/// chance, which accidents do not need; the FNV hash the names use reads a byte at a time.
fn checksum(identity: u64, payload: &[u8]) -> u32 {
    let mut crc = crc32fast::Hasher::new();
    crc.update(&identity.to_le_bytes());
    crc.update(payload);
    crc.finalize()
}

/// `payload` framed as the file of the key `identity`.
fn frame(identity: u64, payload: &[u8]) -> Vec<u8> {
    let mut file = Vec::with_capacity(HEADER_BYTES + payload.len());
    file.extend_from_slice(&MAGIC);
    file.extend_from_slice(&identity.to_le_bytes());
    file.extend_from_slice(&checksum(identity, payload).to_le_bytes());
    file.extend_from_slice(payload);
    file
}

/// The engine's bytes in `file` if it is the whole file of the key `identity`.
fn unframe(identity: u64, file: &[u8]) -> Result<&[u8], Refusal> {
    let (header, payload) = file.split_at_checked(HEADER_BYTES).ok_or(Refusal::Layout)?;
    let (magic, rest) = header.split_at(MAGIC.len());
    let (id, sum) = rest.split_at(8);
    if magic != MAGIC {
        return Err(Refusal::Layout);
    }
    let id = u64::from_le_bytes(id.try_into().map_err(|_| Refusal::Layout)?);
    let sum = u32::from_le_bytes(sum.try_into().map_err(|_| Refusal::Layout)?);
    // The checksum first: a header damaged in its identity is damage, not another key's file.
    if checksum(id, payload) != sum {
        return Err(Refusal::Checksum);
    }
    if id != identity {
        return Err(Refusal::Layout);
    }
    Ok(payload)
}

impl KeyCache {
    pub fn new(dir: PathBuf) -> KeyCache {
        KeyCache {
            dir,
            hits: AtomicUsize::new(0),
            stored: AtomicUsize::new(0),
            prepared: AtomicUsize::new(0),
            refused: Default::default(),
            first_refused: Mutex::new(None),
        }
    }

    /// The user's cache: `$UNACORDA_CACHE` if set (empty: none), else `$XDG_CACHE_HOME/unacorda`,
    /// else `$HOME/.cache/unacorda`.
    pub fn from_env() -> Option<KeyCache> {
        let dir = match std::env::var_os("UNACORDA_CACHE") {
            Some(dir) if dir.is_empty() => return None,
            Some(dir) => PathBuf::from(dir),
            None => match std::env::var_os("XDG_CACHE_HOME") {
                Some(dir) if !dir.is_empty() => PathBuf::from(dir).join("unacorda"),
                _ => PathBuf::from(std::env::var_os("HOME")?).join(".cache/unacorda"),
            },
        };
        Some(KeyCache::new(dir))
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Keys read back or prepared so far.
    pub fn done(&self) -> usize {
        self.hits.load(Ordering::Relaxed) + self.prepared.load(Ordering::Relaxed)
    }

    /// Kept files refused (and their keys prepared again) for `why`.
    pub fn refused(&self, why: Refusal) -> usize {
        self.refused[why as usize].load(Ordering::Relaxed)
    }

    /// Kept files refused for any reason.
    pub fn refused_total(&self) -> usize {
        Refusal::ALL.iter().map(|&why| self.refused(why)).sum()
    }

    /// The first file refused, and why.
    pub fn first_refused(&self) -> Option<(PathBuf, Refusal)> {
        self.first_refused
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// The line a front end shows when kept keys were refused (`None`: none was): how many, why,
    /// where, and that they were prepared afresh.
    pub fn refusal_warning(&self) -> Option<String> {
        let total = self.refused_total();
        if total == 0 {
            return None;
        }
        let why = Refusal::ALL
            .iter()
            .filter(|&&why| self.refused(why) > 0)
            .map(|&why| format!("{} {}", self.refused(why), why.name()))
            .collect::<Vec<_>>()
            .join(", ");
        let first = self
            .first_refused()
            .and_then(|(path, _)| Some(format!("; first {}", path.file_name()?.to_str()?)))
            .unwrap_or_default();
        Some(format!(
            "{total} kept key{} in {} refused ({why}{first}) and prepared afresh",
            if total == 1 { "" } else { "s" },
            self.dir.display()
        ))
    }

    /// The identity of `spec`'s key on engine `K` (the hash its file is named by), and the
    /// engine's name in the store, if `K`'s keys are kept.
    fn identity<K: StoredKey>(spec: &UnisonSpec) -> Option<(&'static str, u64)> {
        let store = K::STORE?;
        let mut h = fnv1a(0xcbf2_9ce4_8422_2325, env!("CARGO_PKG_VERSION").as_bytes());
        h = fnv1a(h, &MAGIC);
        h = fnv1a(h, store.as_bytes());
        for source in K::SOURCE {
            h = fnv1a(h, source.as_bytes());
        }
        // Every field: a new one that is left out does not compile. The board (every bridge
        // point's and listener's modes, shared by the keyboard's keys) by its numbers' bits,
        // the rest as text.
        let UnisonSpec {
            strings,
            modes,
            duplex_damping_n_s_m2,
            hammer,
            damper,
            contact,
            board,
            bridge_point,
            dropped,
            sample_rate_hz,
        } = spec;
        h = fnv1a(
            h,
            format!(
                "{strings:?}{modes:?}{duplex_damping_n_s_m2:?}{hammer:?}{damper:?}{contact:?}\
                 {bridge_point:?}{dropped:?}{sample_rate_hz:?}"
            )
            .as_bytes(),
        );
        Some((store, board_hash(h, board)))
    }

    /// The file of the key `identity` on the engine named `store`.
    fn file(&self, store: &str, identity: u64) -> PathBuf {
        self.dir.join(format!("{store}-{identity:016x}.key"))
    }

    /// The file of `spec`'s key on engine `K`, if `K`'s keys are kept.
    pub fn path<K: StoredKey>(&self, spec: &UnisonSpec) -> Option<PathBuf> {
        let (store, identity) = Self::identity::<K>(spec)?;
        Some(self.file(store, identity))
    }

    /// Keep `payload` (the engine's bytes, [`StoredKey::to_bytes`]) as the file of `spec`'s key
    /// on engine `K`; nothing if `K`'s keys are not kept.
    pub fn store<K: StoredKey>(&self, spec: &UnisonSpec, payload: &[u8]) -> std::io::Result<()> {
        match Self::identity::<K>(spec) {
            Some((store, identity)) => self.write(&self.file(store, identity), identity, payload),
            None => Ok(()),
        }
    }

    /// Write `payload` framed as the key `identity`'s file `path`.
    fn write(&self, path: &Path, identity: u64, payload: &[u8]) -> std::io::Result<()> {
        // Written whole under another name, then renamed: another run never reads half a file.
        let part = path.with_extension(format!("part{}", std::process::id()));
        let written = std::fs::create_dir_all(&self.dir)
            .and_then(|()| std::fs::write(&part, frame(identity, payload)))
            .and_then(|()| std::fs::rename(&part, path));
        if written.is_err() {
            let _ = std::fs::remove_file(&part);
        }
        written
    }

    /// `spec`'s key: read back if kept, whole and playable, else prepared by `prepare` and kept
    /// (a file refused is counted and replaced).
    pub fn key<K: StoredKey, E>(
        &self,
        spec: &UnisonSpec,
        prepare: impl FnOnce(&UnisonSpec) -> Result<K, E>,
    ) -> Result<K, E> {
        let Some((store, identity)) = Self::identity::<K>(spec) else {
            let key = prepare(spec)?;
            self.prepared.fetch_add(1, Ordering::Relaxed);
            return Ok(key);
        };
        let path = self.file(store, identity);
        // A file that cannot be read (none yet, or no permission) is prepared without a refusal.
        if let Ok(file) = std::fs::read(&path) {
            match unframe(identity, &file).and_then(|b| Ok(K::from_bytes(spec, b)?)) {
                Ok(key) => {
                    self.hits.fetch_add(1, Ordering::Relaxed);
                    return Ok(key);
                }
                Err(why) => {
                    self.refused[why as usize].fetch_add(1, Ordering::Relaxed);
                    self.first_refused
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .get_or_insert_with(|| (path.clone(), why));
                }
            }
        }
        let key = prepare(spec)?;
        self.prepared.fetch_add(1, Ordering::Relaxed);
        if self.write(&path, identity, &key.to_bytes()).is_ok() {
            self.stored.fetch_add(1, Ordering::Relaxed);
        }
        Ok(key)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every single flipped bit of a framed file, header included, is refused (by the checksum,
    /// or as another framing where the magic is hit), and so is every cut; the file as written
    /// reads back, and as another key's it is refused by its identity.
    #[test]
    fn every_flipped_bit_and_every_cut_of_a_framed_file_is_refused() {
        let payload: Vec<u8> = (0..1024u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8)
            .collect();
        let identity = 0x0123_4567_89ab_cdef;
        let file = frame(identity, &payload);
        assert_eq!(unframe(identity, &file), Ok(&payload[..]));
        assert_eq!(unframe(identity ^ 1, &file), Err(Refusal::Layout));
        let mut counts = [0usize; 3];
        let mut accepted = 0;
        for bit in 0..8 * file.len() {
            let mut damaged = file.clone();
            damaged[bit / 8] ^= 1 << (bit % 8);
            match unframe(identity, &damaged) {
                Ok(_) => accepted += 1,
                Err(why) => counts[why as usize] += 1,
            }
        }
        for cut in 0..file.len() {
            match unframe(identity, &file[..cut]) {
                Ok(_) => accepted += 1,
                Err(why) => counts[why as usize] += 1,
            }
        }
        println!(
            "{} single-bit flips and {} cuts of a {}-byte file: {accepted} accepted; refused by checksum {}, meaning {}, layout {}",
            8 * file.len(),
            file.len(),
            file.len(),
            counts[0],
            counts[1],
            counts[2]
        );
        assert_eq!(accepted, 0);
        // The magic's 64 bits and the cuts into the header are another framing; the rest damage.
        assert_eq!(counts[Refusal::Layout as usize], 64 + HEADER_BYTES);
        assert_eq!(
            counts[Refusal::Checksum as usize],
            8 * (file.len() - MAGIC.len()) + file.len() - HEADER_BYTES
        );
    }

    /// A key's identity follows every number of its description and of its board, the other
    /// keys' bridge points, the listeners and the dropped modes included: each changed alone by
    /// one unit in its last place changes it, and an equal description keeps it.
    #[test]
    fn every_number_of_a_key_and_its_board_is_in_its_identity() {
        use crate::engine::exact::ExactKey;
        use std::sync::Arc;
        let scaling = crate::config::scaling::Scaling::resolve("concert").unwrap();
        let spec = scaling.key_preset(40).unwrap().unison_spec();
        let id = |s: &UnisonSpec| KeyCache::identity::<ExactKey>(s).unwrap().1;
        let base = id(&spec);
        assert_eq!(id(&spec.clone()), base, "an equal description");
        let next = |x: &mut f64| *x = f64::from_bits(x.to_bits() + 1);
        let board = |change: &dyn Fn(&mut SoundboardModes)| {
            let mut s = spec.clone();
            change(&mut s.board);
            id(&s)
        };
        // A board with dropped modes of its own (here a copy of itself), and one of them moved.
        let with_residual = |change: &dyn Fn(&mut SoundboardModes)| {
            board(&|b| {
                let mut r = b.clone();
                change(&mut r);
                b.residual = Some(Arc::new(r));
            })
        };
        let residual_base = with_residual(&|_| {});
        let last = spec.board.points.len() - 1;
        let changed = [
            ("a string's tension", {
                let mut s = spec.clone();
                next(&mut s.strings[0].tension_n);
                id(&s)
            }),
            ("the rate", {
                let mut s = spec.clone();
                next(&mut s.sample_rate_hz);
                id(&s)
            }),
            (
                "a board mode's frequency",
                board(&|b| next(&mut b.freq_hz[7])),
            ),
            (
                "a board mode's damping",
                board(&|b| next(&mut b.damping_ratio[7])),
            ),
            (
                "a board mode's volume",
                board(&|b| next(&mut b.volume_m2_per_sqrt_kg[7])),
            ),
            (
                "another key's point, P",
                board(&|b| next(&mut b.points[last].shape[2][5])),
            ),
            ("a point's name", board(&|b| b.points[last].name.push('x'))),
            (
                "a listener's integral",
                board(&|b| next(&mut b.listeners[0].rayleigh_im[3])),
            ),
            ("the channels' listeners", board(&|b| b.heard.swap(0, 1))),
            ("the key's dropped modes", {
                let mut s = spec.clone();
                next(
                    &mut s
                        .dropped
                        .as_mut()
                        .expect("concert keys hear theirs")
                        .freq_hz[0],
                );
                id(&s)
            }),
            ("dropped modes given to the board", residual_base),
        ];
        for (what, changed) in &changed {
            assert_ne!(*changed, base, "{what} changed, the identity did not");
        }
        let in_residual = [
            (
                "a dropped mode's frequency",
                with_residual(&|r| next(&mut r.freq_hz[0])),
            ),
            (
                "a dropped mode at a point",
                with_residual(&|r| next(&mut r.points[0].shape[1][2])),
            ),
        ];
        for (what, changed) in &in_residual {
            assert_ne!(
                *changed, residual_base,
                "{what} changed, the identity did not"
            );
        }
        println!(
            "{} single changes, as many identities changed",
            changed.len() + in_residual.len()
        );
    }
}
