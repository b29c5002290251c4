//! The RK4 engine in `f32` against the same engine in `f64` (the reference): a c2 strike, normal
//! and una corda, over 4 s. The bridge forces must stay within 1e-4 of the largest force, the
//! hammer's within 1e-4 of its peak, and the board's volume velocity within 1e-4 of its peak.

use unacorda::engine::{Instrument, Strike};
use unacorda::preset::Preset;

/// Largest differences over `seconds` of a strike, each relative to the `f64` run's peak:
/// (bridge forces, hammer force, volume velocity).
fn drift(una_corda: bool, seconds: f64) -> (f64, f64, f64) {
    let spec = Preset::resolve("c2").unwrap().unison_spec();
    let strike = Strike {
        velocity_m_s: 2.5,
        una_corda,
    };
    let mut reference = Instrument::new(&spec).unwrap();
    let mut single = Instrument::<f32>::unison(&spec).unwrap();
    reference.strike(strike);
    single.strike(strike);
    let mut worst = [0f64; 3];
    let mut peak = [0f64; 3];
    let mut track = |i: usize, a: f64, b: f64| {
        worst[i] = worst[i].max((a - b).abs());
        peak[i] = peak[i].max(a.abs());
    };
    for _ in 0..(seconds / reference.step_s()) as usize {
        reference.step();
        single.step();
        let (a, b) = (reference.observe(), single.observe());
        for s in 0..spec.strings.len() {
            for d in 0..3 {
                track(0, a.bridge_force_n[s][d], b.bridge_force_n[s][d]);
            }
            track(1, a.hammer_force_n[s], b.hammer_force_n[s]);
        }
        track(2, a.volume_velocity_m3_s, b.volume_velocity_m3_s);
    }
    assert!(peak.iter().all(|&p| p > 0.0), "the strike sounds: {peak:?}");
    (worst[0] / peak[0], worst[1] / peak[1], worst[2] / peak[2])
}

fn check(una_corda: bool) {
    let (force, hammer, volume) = drift(una_corda, 4.0);
    println!(
        "c2 {}, f32 vs f64 over 4 s, largest difference / peak: bridge forces {force:.2e}, hammer force {hammer:.2e}, volume velocity {volume:.2e} (bound 1e-4)",
        if una_corda { "una corda" } else { "normal" }
    );
    assert!(force < 1e-4, "bridge forces drift {force:.2e}");
    assert!(hammer < 1e-4, "hammer force drifts {hammer:.2e}");
    assert!(volume < 1e-4, "volume velocity drifts {volume:.2e}");
    // Not trivially equal: f32 really rounds differently.
    assert!(
        force > 1e-9,
        "f32 and f64 agree to {force:.2e}: is f32 running at all?"
    );
}

#[test]
fn f32_bridge_forces_stay_within_1e_4_of_f64_over_4_s() {
    check(false);
}

#[test]
fn f32_bridge_forces_stay_within_1e_4_of_f64_over_4_s_una_corda() {
    check(true);
}

#[test]
fn f32_halves_the_bytes_per_voice() {
    let spec = Preset::resolve("c2").unwrap().unison_spec();
    let (a, b) = (
        Instrument::new(&spec).unwrap(),
        Instrument::<f32>::unison(&spec).unwrap(),
    );
    println!(
        "bytes per c2 voice: f64 {}, f32 {}",
        a.bytes_per_voice(),
        b.bytes_per_voice()
    );
    assert_eq!(2 * b.bytes_per_voice(), a.bytes_per_voice());
}
