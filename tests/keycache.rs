//! The cache of prepared keys: a piano built from keys read back sounds exactly as one prepared
//! afresh. A kept file that changed since it was written (checksum), is not this key's or not
//! this framing's (layout), or is whole but holds values no key has (meaning) is refused, counted
//! under its reason, prepared again and replaced, and the piano sounds bit for bit as one
//! prepared afresh. Two small keys of the paper's keyboard, A0 (one string) and E5.

use std::path::PathBuf;
use std::sync::atomic::Ordering;
use unacorda::config::scaling::{parse_key, LoadedScaling, Scaling};
use unacorda::engine::exact::{ExactKey, ExactPool};
use unacorda::engine::{Policy, StoredKeyError, Strike, UnisonSpec, VoicePool};
use unacorda::keycache::{KeyCache, Refusal, HEADER_BYTES};
use unacorda::play::Piano;

const KEYS: [&str; 2] = ["A0", "E5"];

fn render(piano: &Piano<ExactPool>) -> Vec<f64> {
    let mut pool = piano.instrument.clone();
    for k in 0..2 {
        pool.assign(k, k);
        pool.strike_voice(
            k,
            Strike {
                velocity_m_s: 3.0,
                shift: if k == 1 { 1.0 } else { 0.0 },
            },
        );
    }
    let mut out = vec![[0.0; 2]; 4800];
    pool.run(&mut out, None);
    out.concat()
}

/// Samples of `a` and `b` that are not the same bits.
fn differ(a: &[f64], b: &[f64]) -> usize {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .filter(|(x, y)| x.to_bits() != y.to_bits())
        .count()
}

/// `key`'s spec as the exact engine prepares it on `scaling`.
fn spec(scaling: &LoadedScaling, key: &str) -> UnisonSpec {
    let spec = scaling
        .key_preset(parse_key(key).unwrap())
        .unwrap()
        .unison_spec();
    <ExactPool as VoicePool>::at_engine_rate(spec, scaling.base.output_rate_hz())
}

/// A0's and E5's files as prepared and kept in a directory of their own, and the sound of the
/// piano built as they were prepared.
struct Kept {
    dir: PathBuf,
    scaling: LoadedScaling,
    keys: Vec<usize>,
    /// Each key's file (in the order of [`KEYS`]) and its bytes as first written.
    files: Vec<(PathBuf, Vec<u8>)>,
    sound: Vec<f64>,
}

impl Kept {
    fn new(name: &str) -> Kept {
        let dir =
            std::env::temp_dir().join(format!("unacorda-keycache-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let scaling = Scaling::resolve("paper").unwrap();
        let keys: Vec<usize> = KEYS.iter().map(|k| parse_key(k).unwrap()).collect();
        let cache = KeyCache::new(dir.clone());
        let piano = Piano::<ExactPool>::build_with(&scaling, &keys, 2, Some(&cache)).unwrap();
        assert_eq!(cache.stored.load(Ordering::Relaxed), 2);
        let files = KEYS
            .iter()
            .map(|k| {
                let path = cache.path::<ExactKey>(&spec(&scaling, k)).unwrap();
                let bytes = std::fs::read(&path).unwrap();
                (path, bytes)
            })
            .collect();
        Kept {
            sound: render(&piano),
            dir,
            scaling,
            keys,
            files,
        }
    }

    /// The engine's bytes in file `i` as first written.
    fn payload(&self, i: usize) -> &[u8] {
        &self.files[i].1[HEADER_BYTES..]
    }

    /// Every file as first written, then those `damage(i)` damages (it writes file `i` and says
    /// whether it did); then a piano built from the cache. Every damaged file is refused for
    /// `why` and no other, its key prepared again and its file replaced by the one first
    /// written; the piano sounds bit for bit as the one prepared afresh.
    fn refused(&self, case: &str, why: Refusal, damage: impl Fn(usize) -> bool) {
        let mut damaged = 0;
        for (i, (path, bytes)) in self.files.iter().enumerate() {
            std::fs::write(path, bytes).unwrap();
            damaged += usize::from(damage(i));
        }
        let cache = KeyCache::new(self.dir.clone());
        let piano =
            Piano::<ExactPool>::build_with(&self.scaling, &self.keys, 2, Some(&cache)).unwrap();
        let sound = render(&piano);
        let differ = differ(&sound, &self.sound);
        let replaced = self
            .files
            .iter()
            .filter(|(path, bytes)| std::fs::read(path).ok().as_ref() == Some(bytes))
            .count();
        let (hits, stored) = (
            cache.hits.load(Ordering::Relaxed),
            cache.stored.load(Ordering::Relaxed),
        );
        let [checksum, meaning, layout] = Refusal::ALL.map(|r| cache.refused(r));
        println!(
            "{case}: {damaged} of 2 files damaged; refused for checksum {checksum}, meaning {meaning}, layout {layout}; {stored} prepared again and kept, {hits} read back; {replaced} of 2 files as first written; {differ} of {} samples differ from keys prepared afresh",
            sound.len()
        );
        assert!(damaged > 0);
        assert_eq!(cache.refused(why), damaged, "{case}: refused for {why:?}");
        assert_eq!(
            cache.refused_total(),
            damaged,
            "{case}: refused for another reason"
        );
        assert_eq!((stored, hits), (damaged, 2 - damaged), "{case}");
        assert_eq!(replaced, 2, "{case}: files replaced as first written");
        assert_eq!(differ, 0, "{case}: the piano sounds otherwise");
        assert_eq!(cache.first_refused().map(|(_, r)| r), Some(why));
        let warning = cache.refusal_warning().unwrap();
        println!("  warning: {warning}");
        assert!(warning.starts_with(&format!("{damaged} kept key")));
        assert!(warning.contains(&self.dir.display().to_string()));
    }

    /// File `i` with the engine's bytes `payload`, framed (and checksummed) by the cache.
    fn store(&self, i: usize, payload: &[u8]) {
        let cache = KeyCache::new(self.dir.clone());
        let spec = spec(&self.scaling, KEYS[i]);
        assert_eq!(
            cache.path::<ExactKey>(&spec).as_ref(),
            Some(&self.files[i].0)
        );
        cache.store::<ExactKey>(&spec, payload).unwrap();
    }
}

impl Drop for Kept {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

#[test]
fn keys_read_back_sound_exactly_as_prepared() {
    let kept = Kept::new("read-back");
    let fresh = Piano::<ExactPool>::build(&kept.scaling, &kept.keys, 2).unwrap();
    let cache = KeyCache::new(kept.dir.clone());
    let second =
        Piano::<ExactPool>::build_with(&kept.scaling, &kept.keys, 2, Some(&cache)).unwrap();
    let (hits, stored) = (
        cache.hits.load(Ordering::Relaxed),
        cache.stored.load(Ordering::Relaxed),
    );
    let a = render(&fresh);
    let differ = differ(&a, &render(&second));
    let peak = a.iter().fold(0f64, |m, x| m.max(x.abs()));
    println!(
        "2 keys: {stored} prepared and kept, {hits} read back; 0.1 s of A0 and E5 struck: {differ} of {} samples differ from keys prepared afresh (peak {peak:.2e} m^3/s)",
        a.len()
    );
    assert_eq!((stored, hits), (0, 2));
    assert_eq!(cache.refused_total(), 0);
    assert!(cache.refusal_warning().is_none());
    assert!(peak > 0.0);
    assert_eq!(a, kept.sound);
    assert_eq!(differ, 0, "keys read back sound otherwise");

    // The engine's bytes cut short, or with a byte of their layout changed, are refused.
    let (a0, e5) = (spec(&kept.scaling, "A0"), spec(&kept.scaling, "E5"));
    let bytes = ExactKey::new(&e5).unwrap().to_bytes();
    assert_eq!(bytes, kept.payload(1), "the file holds the engine's bytes");
    assert!(ExactKey::from_bytes(&e5, &bytes).is_ok());
    let layout = |b: &[u8], spec: &UnisonSpec| {
        usize::from(ExactKey::from_bytes(spec, b).err() == Some(StoredKeyError::Layout))
    };
    let mut refused = 0;
    for cut in [0, 7, 8, 100, bytes.len() / 2, bytes.len() - 1] {
        refused += layout(&bytes[..cut], &e5);
    }
    let mut other = bytes.clone();
    other[0] ^= 1;
    refused += layout(&other, &e5);
    let mut longer = bytes.clone();
    longer.push(0);
    refused += layout(&longer, &e5);
    // E5's coefficients for A0 (one string, another mode count): refused.
    refused += layout(&bytes, &a0);
    println!("engine's bytes of another layout refused: {refused} of 9");
    assert_eq!(refused, 9);
}

/// A file changed after it was written is refused by its checksum: the meaning check alone
/// would take (a) and (b), whose values stay finite and decaying.
#[test]
fn a_damaged_file_is_refused_by_its_checksum() {
    let kept = Kept::new("checksum");
    let write = |i: usize, bytes: &[u8]| std::fs::write(&kept.files[i].0, bytes).unwrap();
    // The file damaged by `f` at the first of the payload's middle values, which the engine
    // still reads as a playable key.
    let damage_middle = |i: usize, f: &dyn Fn(&mut [u8])| {
        let mut b = kept.files[i].1.clone();
        let at = HEADER_BYTES + (b.len() - HEADER_BYTES) / 2 / 8 * 8;
        f(&mut b[at..]);
        let spec = spec(&kept.scaling, KEYS[i]);
        assert!(ExactKey::from_bytes(&spec, &b[HEADER_BYTES..]).is_ok());
        write(i, &b);
        true
    };
    // (a) One bit: the lowest of a coefficient's exponent (the coefficient doubled or halved).
    kept.refused("(a) one bit flipped", Refusal::Checksum, |i| {
        damage_middle(i, &|b| b[6] ^= 0x10)
    });
    // (b) 16 bytes inverted: every bit of two coefficients.
    kept.refused("(b) 16 bytes inverted", Refusal::Checksum, |i| {
        damage_middle(i, &|b| b[..16].iter_mut().for_each(|x| *x = !*x))
    });
    // (c) Cut to a third, as a write interrupted leaves it.
    kept.refused("(c) truncated", Refusal::Checksum, |i| {
        let b = &kept.files[i].1;
        write(i, &b[..b.len() / 3]);
        true
    });
}

/// A file that is not this key's, or not of this framing, is refused as another layout.
#[test]
fn a_file_not_of_this_key_or_framing_is_refused_by_its_layout() {
    let kept = Kept::new("layout");
    let write = |i: usize, bytes: &[u8]| std::fs::write(&kept.files[i].0, bytes).unwrap();
    kept.refused("(d) empty", Refusal::Layout, |i| {
        write(i, &[]);
        true
    });
    // (e) A0's file renamed onto E5's name and E5's onto A0's.
    kept.refused("(e) another key's file", Refusal::Layout, |i| {
        write(i, &kept.files[1 - i].1);
        true
    });
    // The same with a key of the same layout: E5 with its strings 0.1 % tighter (0.9 cent
    // sharper), whose bytes the engine would read for E5; only the identity tells them apart.
    let sharp = {
        let mut s = spec(&kept.scaling, "E5");
        s.strings.iter_mut().for_each(|s| s.tension_n *= 1.001);
        s
    };
    let sharp_bytes = ExactKey::new(&sharp).unwrap().to_bytes();
    assert!(ExactKey::from_bytes(&spec(&kept.scaling, "E5"), &sharp_bytes).is_ok());
    kept.refused("(e) a sharper E5's file", Refusal::Layout, |i| {
        if KEYS[i] != "E5" {
            return false;
        }
        let cache = KeyCache::new(kept.dir.clone());
        cache.store::<ExactKey>(&sharp, &sharp_bytes).unwrap();
        std::fs::rename(cache.path::<ExactKey>(&sharp).unwrap(), &kept.files[i].0).unwrap();
        true
    });
    // The engine's bytes without the cache's header, as files were kept before it framed them.
    kept.refused("(g) unframed", Refusal::Layout, |i| {
        write(i, kept.payload(i));
        true
    });
}

/// Bytes whole and laid out right (framed and checksummed by the cache) but holding values no
/// key has are refused by the engine's check of their meaning.
#[test]
fn bytes_that_mean_nothing_are_refused_by_their_meaning() {
    let kept = Kept::new("meaning");
    // The payload: the version word and the mode count `n`, then Re λ (its length and `n`
    // values), Im λ (the same), the strike rows (their count; the first's real parts' length and
    // values), … and last the modes' energies.
    let set = |i: usize, at: usize, value: f64| {
        let mut b = kept.payload(i).to_vec();
        b[at..at + 8].copy_from_slice(&value.to_le_bytes());
        kept.store(i, &b);
        true
    };
    let word = |i: usize, at: usize| {
        u64::from_le_bytes(kept.payload(i)[at..at + 8].try_into().unwrap()) as usize
    };
    let modes = |i: usize| {
        let (n, strings) = (word(i, 8), spec(&kept.scaling, KEYS[i]).strings.len());
        assert_eq!(
            [
                word(i, 16),
                word(i, 24 + 8 * n),
                word(i, 32 + 16 * n),
                word(i, 40 + 16 * n)
            ],
            [n, n, strings, n],
            "the payload's layout"
        );
        n
    };
    kept.refused(
        "(f) a mode that grows, Re λ = +1/s",
        Refusal::Meaning,
        |i| set(i, 24, 1.0),
    );
    kept.refused("(f) a NaN coefficient", Refusal::Meaning, |i| {
        set(i, 48 + 16 * modes(i), f64::NAN)
    });
    kept.refused("(f) a negative energy", Refusal::Meaning, |i| {
        set(i, kept.payload(i).len() - 8, -1.0)
    });
}
