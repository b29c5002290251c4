//! Real-time factor of one paper-faithful c2 voice (2 strings × 205 modes, 130 board modes, dense
//! duplex damping, RK4 at 96 kHz: `rk4_steps_10ms` in f64, `rk4_f32_steps_10ms` in f32), of the
//! same voice in the paper's literal dense state-space form (`dense_baseline_1ms`, Eq. 10–11 with
//! A of order 1082), and on the exact engine (`exact_10ms`: the key's coupled modes advanced
//! exactly at 48 kHz on the shared board's low modes, `engine::exact`). Throughput is reported in output samples (48 kHz) per second:
//! the real-time factor is that figure divided by 48 000, and the ratio of two throughputs is the
//! speed-up.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;
use unacorda::config::preset::Preset;
use unacorda::engine::exact::ExactUnison;
use unacorda::engine::rk4::dense::DenseUnison;
use unacorda::engine::{Rk4Pool, Strike};
use unacorda::render::Renderer;

const FRAMES: usize = 480; // 10 ms at 48 kHz

fn c2_voice(c: &mut Criterion) {
    let preset = Preset::resolve("c2").expect("built-in preset");
    let strike = Strike {
        velocity_m_s: 2.5,
        shift: 0.0,
    };
    let mut group = c.benchmark_group("c2_voice");
    group.throughput(Throughput::Elements(FRAMES as u64));
    group.sample_size(20);

    // The whole output path: RK4 steps, outputs, radiation and the anti-alias decimator.
    let mut renderer = Renderer::new(&preset).expect("c2 builds");
    renderer.strike(strike);
    group.bench_function("render_10ms", |b| {
        b.iter(|| {
            for _ in 0..FRAMES {
                black_box(renderer.next_frame());
            }
        })
    });

    // The integrator alone: RK4 steps of the state-space system.
    let spec = preset.unison_spec();
    let steps = FRAMES * preset.oversampling(&spec);
    let mut instrument = Rk4Pool::new(&spec).expect("c2 builds");
    instrument.strike(strike);
    group.bench_function("rk4_steps_10ms", |b| {
        b.iter(|| {
            for _ in 0..steps {
                instrument.step();
            }
            black_box(instrument.observe())
        })
    });

    // The same RK4 steps in f32 (tests/precision.rs bounds its drift from f64).
    let mut single = Rk4Pool::<f32>::unison(&spec).expect("c2 builds");
    single.strike(strike);
    group.bench_function("rk4_f32_steps_10ms", |b| {
        b.iter(|| {
            for _ in 0..steps {
                single.step();
            }
            black_box(single.observe())
        })
    });

    // The exact engine at the output rate.
    let mut live_spec = spec.clone();
    live_spec.sample_rate_hz = preset.output_rate_hz();
    let mut live = ExactUnison::new(&live_spec).expect("c2 builds");
    live.strike(strike);
    group.bench_function("exact_10ms", |b| {
        b.iter(|| {
            for _ in 0..FRAMES {
                live.step();
            }
            black_box(live.observe())
        })
    });

    // The paper's formulation as written: dense A x + B u + B2 F_b, RK4, 1 ms of sound.
    let mut dense = DenseUnison::new(&spec);
    dense.strike(strike);
    group.throughput(Throughput::Elements(FRAMES as u64 / 10));
    group.sample_size(10);
    group.bench_function("dense_baseline_1ms", |b| {
        b.iter(|| {
            for _ in 0..steps / 10 {
                dense.step();
            }
            black_box(dense.bridge_forces_n())
        })
    });
    group.finish();
}

criterion_group!(benches, c2_voice);
criterion_main!(benches);
