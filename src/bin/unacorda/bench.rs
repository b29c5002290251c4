//! `bench`: the engine's speed on this machine, in the user's terms (real-time factors, voices
//! within the deadline, FLOP rate against the core's peak, memory).

use anyhow::{bail, Result};
use std::sync::atomic::Ordering;
use unacorda::config::preset::Preset;
use unacorda::config::scaling::{LoadedScaling, Scaling, KEYS};
use unacorda::engine::etd::EtdPool;
use unacorda::engine::{Rk4Pool, VoicePool};
use unacorda::measure::{
    block_times_s, denormal_tail_step_s, dense_real_time_factor, exponential_speed, loaded_synth,
    nominal_f64_peak, percentile, resident_bytes, voice_speed,
};
use unacorda::play::{Piano, MAX_VOICES};

/// Block length of the live figures (frames at 48 kHz).
const BLOCK: usize = 64;

pub fn bench(seconds: f64, max_voices: usize) -> Result<()> {
    if !(0.1..=60.0).contains(&seconds) {
        bail!("--seconds {seconds}: expected 0.1 to 60 s per measurement");
    }
    if !(1..=MAX_VOICES).contains(&max_voices) {
        bail!("--voices {max_voices}: expected 1 to {MAX_VOICES}");
    }
    let c2 = Preset::resolve("c2")?;
    let spec = c2.unison_spec();
    let fast = voice_speed::<f64>(&spec, seconds);
    println!(
        "c2 voice, paper-faithful ({} × {} string modes, {} board modes, duplex damping (Eq. 13, applied through its exact rank-16 factor), RK4 in f64 at {:.0} kHz):",
        spec.strings.len(),
        spec.modes.modes_t + spec.modes.modes_p + spec.modes.modes_l,
        spec.board.len(),
        spec.sample_rate_hz / 1e3
    );
    println!(
        "  real-time factor {:.2} (1 s of sound takes {:.2} s)",
        fast.real_time_factor,
        1.0 / fast.real_time_factor
    );
    match nominal_f64_peak() {
        Some((peak, ghz)) => println!(
            "  {:.1} GFLOP/s = {:.0} % of this core's nominal f64 peak ({:.1} GFLOP/s at {ghz:.2} GHz)",
            fast.flops_per_s / 1e9,
            100.0 * fast.flops_per_s / peak,
            peak / 1e9
        ),
        None => println!("  {:.1} GFLOP/s", fast.flops_per_s / 1e9),
    }
    let single = voice_speed::<f32>(&spec, seconds);
    println!(
        "same voice, RK4 in f32 (bridge forces within 1e-4 of f64 over 4 s: tests/precision.rs):\n  real-time factor {:.2} ({:.2} × f64), {:.1} GFLOP/s{}",
        single.real_time_factor,
        single.real_time_factor / fast.real_time_factor,
        single.flops_per_s / 1e9,
        nominal_f64_peak().map_or(String::new(), |(peak, _)| format!(
            " = {:.0} % of this core's nominal f32 peak ({:.1} GFLOP/s)",
            100.0 * single.flops_per_s / (2.0 * peak),
            2.0 * peak / 1e9
        ))
    );
    let rate = c2.output_rate_hz();
    let live = exponential_speed(&spec, rate, seconds);
    println!(
        "same voice on the live integrator (exponential RK4, ETDRK4, on each string direction's complex modes with its contact spring and duplex damping; board coupling, hammer and damper explicit) at {:.0} kHz:\n  real-time factor {:.2} ({:.1} × the paper-faithful RK4), {:.1} GFLOP/s{}",
        rate / 1e3,
        live.real_time_factor,
        live.real_time_factor / fast.real_time_factor,
        live.flops_per_s / 1e9,
        nominal_f64_peak().map_or(String::new(), |(peak, _)| format!(
            " = {:.0} % of nominal f64 peak",
            100.0 * live.flops_per_s / peak
        ))
    );
    // The dense baseline is a few hundred times slower: time a slice of the same length in steps
    // that takes about `seconds`.
    let steps = ((seconds * spec.sample_rate_hz * fast.real_time_factor / 400.0) as usize).max(20);
    let dense = dense_real_time_factor(&spec, steps);
    println!(
        "dense state-space baseline (Eq. 10–11 as written: A of order {}, faer mat-vec, RK4), same voice:\n  real-time factor {dense:.5}; unacorda is {:.0} × faster",
        2 * (spec.strings.len() * (spec.modes.modes_t + spec.modes.modes_p + spec.modes.modes_l)
            + spec.board.len())
            + 2,
        fast.real_time_factor / dense
    );

    let steps = ((seconds * spec.sample_rate_hz * fast.real_time_factor) as usize).max(100);
    let (sounding, ftz, plain) = denormal_tail_step_s(&spec, steps);
    println!(
        "denormals, same voice in a long silent tail (state scaled to ≤ 1e-305, mostly subnormal), µs per RK4 step:\n  sounding {:.2}; tail with FTZ/DAZ as in the audio thread {:.2} ({:.2} × sounding); tail without {:.2} ({:.1} × sounding)",
        sounding * 1e6,
        ftz * 1e6,
        ftz / sounding,
        plain * 1e6,
        plain / sounding
    );

    let scaling = Scaling::resolve("grand")?;
    callback::<Rk4Pool>(
        &scaling,
        seconds,
        max_voices,
        1,
        "RK4 at 96 kHz, the reference",
    )?;
    callback::<EtdPool>(
        &scaling,
        seconds,
        max_voices,
        1,
        "ETDRK4 at 48 kHz, the live integrator",
    )?;
    callback::<EtdPool>(
        &scaling,
        seconds,
        max_voices,
        2,
        "ETDRK4 at 48 kHz, the live integrator, voices split over two cores",
    )?;
    Ok(())
}

/// The audio callback on engine `E` (on `cores` cores: 1, or 2 with a helper thread) with 1, 2,
/// 4 … `max_voices` voices sounding, and memory.
fn callback<E: VoicePool>(
    scaling: &LoadedScaling,
    seconds: f64,
    max_voices: usize,
    cores: usize,
    label: &str,
) -> Result<()> {
    let keys: Vec<usize> = (1..=KEYS).collect();
    let piano = Piano::<E>::build(scaling, &keys, max_voices)?;
    let settings = scaling.base.output_settings();
    let deadline = BLOCK as f64 / settings.rate_hz;
    println!(
        "live callback ({label}), {BLOCK}-frame blocks at {:.0} kHz (deadline {:.2} ms), keys spread from A0 under the sustain pedal:",
        settings.rate_hz / 1e3,
        deadline * 1e3
    );
    let mut within = 0;
    let mut voices = 1;
    loop {
        let (mut synth, handle) = loaded_synth(&piano, settings, voices, BLOCK);
        if cores == 2 {
            synth.use_second_core()?;
        }
        let probe = block_times_s(&mut synth, BLOCK, 5);
        let blocks = ((seconds / percentile(&probe, 0.5)) as usize).clamp(20, 5000);
        let t = block_times_s(&mut synth, BLOCK, blocks);
        let (median, p999) = (percentile(&t, 0.5), percentile(&t, 0.999));
        let misses = t.iter().filter(|&&x| x > deadline).count();
        let late = handle.stats.helper_late.load(Ordering::Relaxed);
        let split = handle.stats.two_core_runs.load(Ordering::Relaxed);
        println!(
            "  {voices:>3} voices: median {:7.3} ms ({:6.2} × deadline), p99.9 {:7.3} ms ({:6.2} ×), deadline misses (xruns) {misses} of {blocks} blocks{}",
            median * 1e3,
            median / deadline,
            p999 * 1e3,
            p999 / deadline,
            if cores == 2 {
                format!("; helper late (run on one core) {late} of {} runs", late + split)
            } else {
                String::new()
            }
        );
        if p999 < 0.5 * deadline {
            within = voices;
        }
        if voices >= max_voices || median > 4.0 * deadline * voices as f64 {
            break;
        }
        voices = (voices * 2).min(max_voices);
    }
    println!("  voices within the deadline (p99.9 below 50 % of it): {within}");
    let (synth, _handle) = loaded_synth(&piano, settings, max_voices, BLOCK);
    println!(
        "  memory: {:.1} kB of state per voice; resident {:.0} MB with {max_voices} voices sounding",
        synth.piano().instrument.bytes_per_voice() as f64 / 1e3,
        resident_bytes().unwrap_or(0) as f64 / 1e6
    );
    Ok(())
}
