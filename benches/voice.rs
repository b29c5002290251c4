//! Real-time factor of one paper-faithful c2 voice (2 strings × 205 modes, 130 board modes, dense
//! duplex damping, RK4 at 96 kHz). Throughput is reported in output samples (48 kHz) per second:
//! the real-time factor is that figure divided by 48 000.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;
use unacorda::engine::{Instrument, Strike};
use unacorda::preset::Preset;
use unacorda::render::Renderer;

const FRAMES: usize = 480; // 10 ms at 48 kHz

fn c2_voice(c: &mut Criterion) {
    let preset = Preset::resolve("c2").expect("built-in preset");
    let strike = Strike {
        velocity_m_s: 2.5,
        una_corda: false,
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
    let mut unison = Instrument::new(&spec).expect("c2 builds");
    unison.strike(strike);
    group.bench_function("rk4_steps_10ms", |b| {
        b.iter(|| {
            for _ in 0..steps {
                unison.step();
            }
            black_box(unison.observe())
        })
    });
    group.finish();
}

criterion_group!(benches, c2_voice);
criterion_main!(benches);
