//! Prepared keys kept between runs: the exact engine's diagonalisation of the 88 keys takes
//! ~25 s on two cores, reading them back a fraction of a second. One file per key under the
//! cache directory, named by a hash of everything that decides its coefficients — the key's full
//! spec (every parameter, the board at its point, the rate), the engine and the source of the
//! code that computes them ([`StoredKey::SOURCE`]) — so a file is only ever read by a build and a
//! keyboard that would compute the same numbers. A file that does not read back whole is
//! prepared again and replaced; a directory that cannot be written costs only the time.

use crate::engine::{StoredKey, UnisonSpec};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Where prepared keys are kept, and how many this run read and prepared.
#[derive(Debug)]
pub struct KeyCache {
    dir: PathBuf,
    /// Keys read from the cache, prepared and stored (touched by the threads that build keys).
    pub hits: AtomicUsize,
    pub stored: AtomicUsize,
}

/// FNV-1a, 64 bits: a stable hash (the same in every build and on every machine).
fn fnv1a(hash: u64, bytes: &[u8]) -> u64 {
    bytes.iter().fold(hash, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

impl KeyCache {
    pub fn new(dir: PathBuf) -> KeyCache {
        KeyCache {
            dir,
            hits: AtomicUsize::new(0),
            stored: AtomicUsize::new(0),
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

    /// The file of `spec`'s key on engine `K`, if `K`'s keys are kept.
    fn path<K: StoredKey>(&self, spec: &UnisonSpec) -> Option<PathBuf> {
        let store = K::STORE?;
        let mut h = fnv1a(0xcbf2_9ce4_8422_2325, env!("CARGO_PKG_VERSION").as_bytes());
        h = fnv1a(h, store.as_bytes());
        for source in K::SOURCE {
            h = fnv1a(h, source.as_bytes());
        }
        h = fnv1a(h, format!("{spec:?}").as_bytes());
        Some(self.dir.join(format!("{store}-{h:016x}.key")))
    }

    /// `spec`'s key: read back if kept and whole, else prepared by `prepare` and kept.
    pub fn key<K: StoredKey, E>(
        &self,
        spec: &UnisonSpec,
        prepare: impl FnOnce(&UnisonSpec) -> Result<K, E>,
    ) -> Result<K, E> {
        let Some(path) = self.path::<K>(spec) else {
            return prepare(spec);
        };
        if let Some(key) = std::fs::read(&path)
            .ok()
            .and_then(|b| K::from_bytes(spec, &b))
        {
            self.hits.fetch_add(1, Ordering::Relaxed);
            return Ok(key);
        }
        let key = prepare(spec)?;
        // Written whole under another name, then renamed: another run never reads half a file.
        let part = path.with_extension(format!("part{}", std::process::id()));
        let written = std::fs::create_dir_all(&self.dir)
            .and_then(|()| std::fs::write(&part, key.to_bytes()))
            .and_then(|()| std::fs::rename(&part, &path));
        match written {
            Ok(()) => {
                self.stored.fetch_add(1, Ordering::Relaxed);
            }
            Err(_) => {
                let _ = std::fs::remove_file(&part);
            }
        }
        Ok(key)
    }
}
