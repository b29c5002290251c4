//! The cache of prepared keys: a piano built from keys read back sounds exactly as one prepared
//! afresh; a file that does not read back whole (truncated, another layout, another key's) is
//! prepared again and replaced, never used.

use std::sync::atomic::Ordering;
use unacorda::config::scaling::{parse_key, Scaling};
use unacorda::engine::exact::{ExactKey, ExactPool};
use unacorda::engine::{Policy, Strike, VoicePool};
use unacorda::keycache::KeyCache;
use unacorda::play::Piano;

fn render(piano: &Piano<ExactPool>) -> Vec<f64> {
    let mut pool = piano.instrument.clone();
    for k in 0..2 {
        pool.assign(k, k);
        pool.strike_voice(
            k,
            Strike {
                velocity_m_s: 3.0,
                una_corda: k == 1,
            },
        );
    }
    let mut out = vec![[0.0; 2]; 4800];
    pool.run(&mut out, None);
    out.concat()
}

#[test]
fn keys_read_back_sound_exactly_as_prepared() {
    let dir = std::env::temp_dir().join(format!("unacorda-keycache-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let scaling = Scaling::resolve("paper").unwrap();
    let keys: Vec<usize> = ["A0", "E5"].iter().map(|k| parse_key(k).unwrap()).collect();
    let fresh = Piano::<ExactPool>::build(&scaling, &keys, 2).unwrap();
    let cache = KeyCache::new(dir.clone());
    let first = Piano::<ExactPool>::build_with(&scaling, &keys, 2, Some(&cache)).unwrap();
    let second = Piano::<ExactPool>::build_with(&scaling, &keys, 2, Some(&cache)).unwrap();
    let (hits, stored) = (
        cache.hits.load(Ordering::Relaxed),
        cache.stored.load(Ordering::Relaxed),
    );
    let [a, b, c] = [&fresh, &first, &second].map(render);
    let differ = a
        .iter()
        .zip(&c)
        .filter(|(x, y)| x.to_bits() != y.to_bits())
        .count();
    let peak = a.iter().fold(0f64, |m, x| m.max(x.abs()));
    println!(
        "2 keys: {stored} prepared and kept, {hits} read back; 0.1 s of A0 and E5 struck: {differ} of {} samples differ from keys prepared afresh (peak {peak:.2e} m^3/s)",
        a.len()
    );
    assert_eq!((stored, hits), (2, 2));
    assert!(peak > 0.0);
    assert_eq!(a, b);
    assert_eq!(differ, 0, "keys read back sound otherwise");

    // Every file cut short, or with a byte of its layout changed, is refused and replaced.
    let files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(files.len(), 2, "{files:?}");
    let spec = |name: &str| {
        let spec = scaling
            .key_preset(parse_key(name).unwrap())
            .unwrap()
            .unison_spec();
        <ExactPool as VoicePool>::at_engine_rate(spec, scaling.base.output_rate_hz())
    };
    let bytes = ExactKey::new(&spec("E5")).unwrap().to_bytes();
    assert!(ExactKey::from_bytes(&spec("E5"), &bytes).is_some());
    let mut refused = 0;
    for cut in [0, 7, 8, 100, bytes.len() / 2, bytes.len() - 1] {
        refused += usize::from(ExactKey::from_bytes(&spec("E5"), &bytes[..cut]).is_none());
    }
    let mut other = bytes.clone();
    other[0] ^= 1;
    refused += usize::from(ExactKey::from_bytes(&spec("E5"), &other).is_none());
    let mut longer = bytes.clone();
    longer.push(0);
    refused += usize::from(ExactKey::from_bytes(&spec("E5"), &longer).is_none());
    // E5's coefficients for A0 (one string, another mode count): refused.
    refused += usize::from(ExactKey::from_bytes(&spec("A0"), &bytes).is_none());
    println!("bad files refused: {refused} of 9");
    assert_eq!(refused, 9);
    for f in &files {
        let b = std::fs::read(f).unwrap();
        std::fs::write(f, &b[..b.len() / 3]).unwrap();
    }
    let cache = KeyCache::new(dir.clone());
    let third = Piano::<ExactPool>::build_with(&scaling, &keys, 2, Some(&cache)).unwrap();
    assert_eq!(
        cache.stored.load(Ordering::Relaxed),
        2,
        "truncated files replaced"
    );
    assert_eq!(render(&third), a);
    let _ = std::fs::remove_dir_all(&dir);
}
