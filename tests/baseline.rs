//! The optimised engine against the paper's literal dense formulation (Eq. 10–19 with the dense
//! state matrix A): the same c2 strike, normal, una corda and with a hysteretic felt, must give
//! the same bridge forces.

use unacorda::config::preset::Preset;
use unacorda::engine::rk4::dense::DenseUnison;
use unacorda::engine::{Rk4Pool, Strike};

#[test]
fn optimised_engine_matches_the_dense_state_space_form() {
    let preset = Preset::resolve("c2").unwrap();
    let spec = preset.unison_spec();
    let steps = (0.05 * spec.sample_rate_hz) as usize;
    let compare = |una_corda: bool, hysteresis_s: f64| {
        let mut spec = spec.clone();
        spec.hammer.hysteresis_s = hysteresis_s;
        let strike = Strike {
            velocity_m_s: 2.5,
            shift: if una_corda { 1.0 } else { 0.0 },
        };
        let mut fast = Rk4Pool::new(&spec).unwrap();
        let mut dense = DenseUnison::new(&spec);
        fast.strike(strike);
        dense.strike(strike);
        let (mut worst, mut peak) = (0f64, 0f64);
        for _ in 0..steps {
            fast.step();
            dense.step();
            let (a, b) = (fast.observe().bridge_force_n, dense.bridge_forces_n());
            for s in 0..spec.strings.len() {
                for d in 0..3 {
                    worst = worst.max((a[s][d] - b[s][d]).abs());
                    peak = peak.max(b[s][d].abs());
                }
            }
        }
        (dense.state_len(), worst, peak)
    };
    let (normal, una) = std::thread::scope(|s| {
        let n = s.spawn(|| compare(false, 0.0));
        let u = s.spawn(|| compare(true, 0.0));
        (n.join().unwrap(), u.join().unwrap())
    });
    // Stulov's felt: the strings' velocity under the hammer enters the felt's force.
    let hysteretic = compare(false, 300e-6);
    for (name, (n, worst, peak)) in [
        ("normal", normal),
        ("una corda", una),
        ("hysteretic felt (300 µs)", hysteretic),
    ] {
        println!(
            "c2 {name}, first 50 ms ({steps} RK4 steps), dense A of order {n}: bridge forces differ by at most {worst:.2e} N of {peak:.2} N peak ({:.1e} relative)",
            worst / peak
        );
        assert!(worst / peak < 1e-9, "{name}: {:.2e} relative", worst / peak);
    }
}
