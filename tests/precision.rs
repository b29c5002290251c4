//! The RK4 engine in `f32` against the same engine in `f64` (the reference): a c2 strike, normal
//! and una corda, over 4 s. The bridge forces must stay within 1e-4 of the largest force, the
//! hammer's within 2e-6 of its peak, and the board's volume velocity within 3e-5 of its peak; and
//! a voice in `f32` must take half the memory, as measured by the allocator.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use unacorda::config::preset::Preset;
use unacorda::engine::{Rk4Pool, Strike};

/// The system allocator, counting the bytes each thread holds (tests run on several threads).
struct Counting;

thread_local! {
    static HELD: Cell<isize> = const { Cell::new(0) };
}

// SAFETY: forwards to the system allocator unchanged; the counter is a const-initialised
// thread-local `Cell` (no allocation, no destructor).
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        HELD.with(|h| h.set(h.get() + layout.size() as isize));
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        HELD.with(|h| h.set(h.get() - layout.size() as isize));
        System.dealloc(ptr, layout)
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Largest differences over `seconds` of a strike, each relative to the `f64` run's peak:
/// (bridge forces, hammer force, volume velocity).
fn drift(una_corda: bool, seconds: f64) -> (f64, f64, f64) {
    let spec = Preset::resolve("c2").unwrap().unison_spec();
    let strike = Strike {
        velocity_m_s: 2.5,
        shift: if una_corda { 1.0 } else { 0.0 },
    };
    let mut reference = Rk4Pool::new(&spec).unwrap();
    let mut single = Rk4Pool::<f32>::unison(&spec).unwrap();
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
    // Measured 3.2e-5 / 4.5e-5, 2.8e-7 / 4.7e-7 and 1.1e-5 / 1.2e-5 (normal / una corda): the
    // f32 modes' rounding over 4 s; the hammer, computed in f64, sees it only through the strings.
    assert!(force < 1e-4, "bridge forces drift {force:.2e}");
    assert!(hammer < 2e-6, "hammer force drifts {hammer:.2e}");
    assert!(volume < 3e-5, "volume velocity drifts {volume:.2e}");
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

/// Bytes a pool of `T` holds per voice, measured: the pool with 9 voices less the pool with 1.
fn measured_bytes_per_voice<T: unacorda::engine::kernels::Real>() -> (f64, usize) {
    // Building runs faer's factorisations; on one thread every byte is counted where it is held.
    faer::set_global_parallelism(faer::Par::Seq);
    let spec = Preset::resolve("c2").unwrap().unison_spec();
    let held = |voices: usize| {
        let before = HELD.with(Cell::get);
        let pool = Rk4Pool::<T>::pool(std::slice::from_ref(&spec), voices).unwrap();
        let after = HELD.with(Cell::get);
        (after - before, pool.bytes_per_voice())
    };
    // The first build also fills one-time caches: measure after it.
    held(1);
    let ((one, stated), (nine, _)) = (held(1), held(9));
    ((nine - one) as f64 / 8.0, stated)
}

#[test]
fn f32_halves_the_bytes_per_voice() {
    let (f64_bytes, f64_stated) = measured_bytes_per_voice::<f64>();
    let (f32_bytes, f32_stated) = measured_bytes_per_voice::<f32>();
    println!(
        "bytes per c2 voice, measured by the allocator: f64 {f64_bytes:.0} (stated {f64_stated}), f32 {f32_bytes:.0} (stated {f32_stated}); ratio {:.3}",
        f32_bytes / f64_bytes
    );
    // What a voice adds beyond its modes (flags, hammer, a few f64 per voice) is small.
    let ratio = f32_bytes / f64_bytes;
    assert!((0.49..0.53).contains(&ratio), "f32 / f64 = {ratio}");
    // `bytes_per_voice`, what `bench` reports, is what the pool really holds.
    for (measured, stated) in [(f64_bytes, f64_stated), (f32_bytes, f32_stated)] {
        assert!(
            (measured / stated as f64 - 1.0).abs() < 0.02,
            "{measured} vs {stated}"
        );
    }
}
