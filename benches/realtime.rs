//! The real-time path under load, at the engine's 48 kHz output:
//! - `callback/{voices}v_{frames}f` (RK4 at 96 kHz) and `callback_exact/…` (the exact engine at
//!   48 kHz; `callback_exact_2cores/…` with each block's work split over two cores): one audio
//!   callback ([`Synth::process`]) with 1, 8, 16, 32 or (exact) 64 voices sounding (keys spread over the keyboard, sustain held, one shared soundboard) and 64-
//!   or 128-frame blocks. Besides criterion's estimate, every block's time is recorded and the
//!   median and p99.9 are printed as a fraction of the block's deadline.
//! - `latency/event_to_first_sample`: a note-on stamped by the live clock, through the event queue
//!   and the callback, until the block that holds the first non-zero sample has been computed.
//! - `offline/demo_first_second`: `render_midi` of the demo file's first second (real-time factor
//!   = throughput in elements/s ÷ 48 000).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;
use std::time::{Duration, Instant};
use unacorda::audio::synth::{Scheduled, Synth, EVENT_QUEUE};
use unacorda::config::scaling::{Scaling, KEYS};
use unacorda::engine::exact::ExactPool;
use unacorda::engine::{Rk4Pool, VoicePool};
use unacorda::measure::{loaded_synth, percentile};
use unacorda::midi::Event;
use unacorda::play::Piano;

fn keyboard<E: VoicePool>(voices: usize) -> (Piano<E>, unacorda::config::output::OutputSettings) {
    let scaling = Scaling::resolve("paper").expect("built-in keyboard");
    let keys: Vec<usize> = (1..=KEYS).collect();
    let piano = Piano::<E>::build(&scaling, &keys, voices).expect("the keyboard builds");
    (piano, scaling.output_settings())
}

fn callback(c: &mut Criterion) {
    callback_on::<Rk4Pool>(c, "callback", "RK4 at 96 kHz", false, &[1, 8, 16, 32]);
    let voices = [1, 8, 16, 32, 64];
    callback_on::<ExactPool>(c, "callback_exact", "exact at 48 kHz", false, &voices);
    callback_on::<ExactPool>(
        c,
        "callback_exact_2cores",
        "exact at 48 kHz, each block split over two cores",
        true,
        &voices,
    );
}

fn callback_on<E: VoicePool>(
    c: &mut Criterion,
    name: &str,
    label: &str,
    two_cores: bool,
    voice_counts: &[usize],
) {
    let (piano, settings) = keyboard::<E>(voice_counts.iter().copied().max().unwrap_or(1));
    let fs = settings.rate_hz;
    let mut report = Vec::new();
    let mut group = c.benchmark_group(name);
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(4));
    for &voices in voice_counts {
        for frames in [64usize, 128] {
            let (mut synth, handle) = loaded_synth(&piano, settings, voices, frames);
            if two_cores {
                synth.use_second_core().expect("a helper thread starts");
            }
            let mut out = vec![0f32; frames * 2];
            let mut times = Vec::new();
            group.throughput(Throughput::Elements(frames as u64));
            group.bench_function(format!("{voices}v_{frames}f"), |b| {
                b.iter_custom(|iters| {
                    let mut total = Duration::ZERO;
                    for _ in 0..iters {
                        let t = Instant::now();
                        synth.process(black_box(&mut out), 2);
                        let dt = t.elapsed();
                        total += dt;
                        times.push(dt.as_secs_f64());
                    }
                    total
                })
            });
            times.sort_by(f64::total_cmp);
            let deadline = frames as f64 / fs;
            let sounding = handle
                .stats
                .peak_voices
                .load(std::sync::atomic::Ordering::Relaxed);
            report.push(format!(
                "{voices:>3} voices ({sounding} simulated), {frames:>3} frames: median {:7.3} ms = {:6.2} x deadline, p99.9 {:7.3} ms = {:6.2} x deadline ({} blocks)",
                percentile(&times, 0.5) * 1e3,
                percentile(&times, 0.5) / deadline,
                percentile(&times, 0.999) * 1e3,
                percentile(&times, 0.999) / deadline,
                times.len()
            ));
        }
    }
    group.finish();
    println!("\nAudio callback block time, {label} (deadline = block length at {fs} Hz):");
    for line in report {
        println!("  {line}");
    }
}

fn latency(c: &mut Criterion) {
    let (piano, settings) = keyboard::<Rk4Pool>(32);
    let frames = 64;
    let (silent, _handle) = Synth::new(piano, settings, EVENT_QUEUE).expect("rates match");
    let mut delays = Vec::new();
    let mut group = c.benchmark_group("latency");
    group.sample_size(20);
    group.bench_function("event_to_first_sample", |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                let (mut synth, mut handle) =
                    Synth::new(silent.piano().clone(), settings, EVENT_QUEUE).expect("rates match");
                let mut out = vec![0f32; frames];
                synth.process(&mut out, 1);
                let t = Instant::now();
                let arrival = synth.frame();
                let frame = handle.clock.frame_at(t);
                let event = Event::NoteOn {
                    note: 60,
                    velocity: 80.0,
                };
                handle
                    .schedule(Scheduled { frame, event })
                    .expect("queue has room");
                loop {
                    let start = synth.frame();
                    synth.process(&mut out, 1);
                    if let Some(i) = out.iter().position(|&s| s != 0.0) {
                        delays.push(start + i as u64 - arrival);
                        break;
                    }
                }
                total += t.elapsed();
            }
            total
        })
    });
    group.finish();
    delays.sort_unstable();
    println!(
        "\nNote-on to first non-zero sample ({frames}-frame blocks): the live clock stamped the event {}–{} frames ({:.2}–{:.2} ms) past the next block's start (its extrapolation of the time since the last block began; in a paced stream this is at most one block); the time above is push → queue → callbacks → first non-zero sample computed",
        delays[0],
        delays[delays.len() - 1],
        delays[0] as f64 / settings.rate_hz * 1e3,
        delays[delays.len() - 1] as f64 / settings.rate_hz * 1e3
    );
}

fn offline(c: &mut Criterion) {
    let scaling = Scaling::resolve("paper").expect("built-in keyboard");
    let events: Vec<_> =
        unacorda::midi::file::read_file(std::path::Path::new("assets/midi/demo.mid"))
            .expect("the demo file")
            .into_iter()
            .filter(|e| e.time_s < 1.0)
            .collect();
    let tail = 1.0 - events.last().map_or(0.0, |e| e.time_s);
    let mut group = c.benchmark_group("offline");
    group.sample_size(10);
    group.throughput(Throughput::Elements(48_000));
    group.bench_function("demo_first_second", |b| {
        b.iter(|| {
            unacorda::render::render_midi(&scaling, &events, tail, 32, |_| {})
                .expect("renders")
                .samples
                .len()
        })
    });
    group.finish();
}

criterion_group!(benches, callback, latency, offline);
criterion_main!(benches);
