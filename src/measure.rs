//! Measurements shared by the benchmarks (`benches/`) and `unacorda bench`: a loaded audio
//! engine, timings of its callback, real-time factors and FLOP rates. Timing is never a pass/fail
//! test (CI machines are noisy); these report figures.

use crate::audio::priority::Promotion;
use crate::audio::synth::{Scheduled, Synth, SynthHandle, EVENT_QUEUE};
use crate::config::output::OutputSettings;
use crate::engine::exact::{ExactUnison, Exchange};
use crate::engine::kernels::Real;
use crate::engine::rk4::dense::DenseUnison;
use crate::engine::{Rk4Pool, Strike, UnisonSpec, VoicePool};
use crate::midi::{Event, Pedal};
use crate::play::Piano;
use std::time::{Duration, Instant};

/// MIDI velocity of every key the measurements strike.
pub const VELOCITY: u8 = 80;

/// A synth on `piano` with `voices` keys sounding under the sustain pedal — spread over the
/// keyboard from A0 upwards, struck 48 frames (1 ms at 48 kHz) apart at MIDI velocity
/// [`VELOCITY`] — run until 50 ms after the last strike, so that every hammer has left its
/// strings ([`loaded_scenario`] says it in words). `piano` must hold all 88 keys and at least
/// `voices` voices.
pub fn loaded_synth<E: VoicePool>(
    piano: &Piano<E>,
    settings: OutputSettings,
    voices: usize,
    frames: usize,
) -> (Synth<E>, SynthHandle<E>) {
    let (mut synth, mut handle) =
        Synth::new(piano.clone(), settings, EVENT_QUEUE).expect("the keyboard's rates match");
    let sustain = Event::pedal(Pedal::Sustain, true);
    let mut events = vec![(0, sustain)];
    for v in 0..voices {
        let note = (21 + v * 88 / voices.max(1)) as u8;
        events.push((
            v as u64 * 48,
            Event::NoteOn {
                note,
                velocity: f64::from(VELOCITY),
            },
        ));
    }
    for (frame, event) in events {
        // The queue holds 4096 events; at most 257 are pushed.
        let _ = handle.schedule(Scheduled { frame, event });
    }
    let mut out = vec![0f32; frames];
    let last_strike = voices.saturating_sub(1) * 48;
    for _ in 0..(last_strike + (0.05 * settings.rate_hz) as usize).div_ceil(frames.max(1)) {
        synth.process(&mut out, 1);
    }
    (synth, handle)
}

/// What [`loaded_synth`] plays with `voices` keys, in words: the scenario of a callback figure
/// (`None`: with "N keys", a count given elsewhere).
pub fn loaded_scenario(voices: Option<usize>, halo: bool) -> String {
    let keys = match voices {
        Some(1) => format!("1 key (A0) struck at velocity {VELOCITY}"),
        Some(n) => format!("{n} keys struck 1 ms apart at velocity {VELOCITY} spread from A0"),
        None => format!("N keys struck 1 ms apart at velocity {VELOCITY} spread from A0"),
    };
    let halo = if halo {
        " with the halo (every key's strings undamped, those not struck ringing in sympathy)"
    } else {
        ""
    };
    format!("pedalled: sustain down{halo}, {keys}, measured from 50 ms after the last strike")
}

/// A pianist's chord held under the pedal (MIDI notes): C2 G2 E3 C4 E4 G4 C5, C major over
/// three octaves with the bass in octaves, the hands' usual spread.
pub const HELD_CHORD: [u8; 7] = [36, 43, 52, 60, 64, 67, 72];

/// A synth on `piano` at its first frame, with the sustain pedal down and `notes` about to be
/// struck together at MIDI velocity [`VELOCITY`] and then held (never released). `piano` must
/// hold the notes' keys and at least as many voices as notes.
pub fn struck_chord_synth<E: VoicePool>(
    piano: &Piano<E>,
    settings: OutputSettings,
    notes: &[u8],
) -> (Synth<E>, SynthHandle<E>) {
    let (synth, mut handle) =
        Synth::new(piano.clone(), settings, EVENT_QUEUE).expect("the keyboard's rates match");
    let sustain = Event::pedal(Pedal::Sustain, true);
    let strikes = notes.iter().map(|&note| Event::NoteOn {
        note,
        velocity: f64::from(VELOCITY),
    });
    for event in std::iter::once(sustain).chain(strikes) {
        // The queue holds 4096 events; a chord pushes a few.
        let _ = handle.schedule(Scheduled { frame: 0, event });
    }
    (synth, handle)
}

/// The callbacks that started within one window of time after a strike.
#[derive(Debug, Clone)]
pub struct Window {
    /// The window's bounds (s after the synth's first frame).
    pub from_s: f64,
    pub to_s: f64,
    /// Each callback's time (s), sorted.
    pub times_s: Vec<f64>,
    /// Voices simulated after the window's last callback, and the modes they step (where the
    /// engine says: [`VoicePool::modes_stepped`]).
    pub active_voices: usize,
    pub modes_stepped: Option<usize>,
}

/// Time each of `blocks` callbacks of `frames` frames at `rate_hz` (s), sorted — as `play`'s audio
/// device runs them: one block every `frames / rate_hz` seconds (each started on time, or at once
/// after one that ran late), on a thread of its own at real-time priority where the system grants
/// it, the helper thread (if any) asked for it too. Also says whether this thread's priority was
/// granted.
pub fn block_times_s<E: VoicePool>(
    synth: &mut Synth<E>,
    frames: usize,
    rate_hz: f64,
    blocks: usize,
) -> (Vec<f64>, bool) {
    let period = Duration::try_from_secs_f64(frames as f64 / rate_hz).unwrap_or_default();
    on_real_time_thread(synth, |synth| {
        let mut out = vec![0f32; frames];
        paced_times_s(period, blocks, || {
            let t = Instant::now();
            synth.process(&mut out, 1);
            t.elapsed().as_secs_f64()
        })
    })
}

/// Time every callback of `frames` frames at `rate_hz` from the synth's current frame until
/// the last of `bounds_s` (s after the synth's first frame, rising), paced as [`block_times_s`]
/// paces them, and group them by the window between two consecutive bounds in which each
/// started (a synth made by [`struck_chord_synth`]: the windows after the strike). Also says
/// whether the timing thread's real-time priority was granted.
pub fn windowed_block_times_s<E: VoicePool>(
    synth: &mut Synth<E>,
    frames: usize,
    rate_hz: f64,
    bounds_s: &[f64],
) -> (Vec<Window>, bool) {
    let period = Duration::try_from_secs_f64(frames as f64 / rate_hz).unwrap_or_default();
    let end_frame = (bounds_s.last().copied().unwrap_or(0.0) * rate_hz).ceil() as u64;
    let blocks = (end_frame.saturating_sub(synth.frame()) as usize).div_ceil(frames.max(1));
    on_real_time_thread(synth, |synth| {
        // Each callback's start (s) and the voices simulated after it, beside its time.
        let mut started_s = Vec::with_capacity(blocks);
        let mut active = Vec::with_capacity(blocks);
        let mut stepped = Vec::with_capacity(blocks);
        let mut out = vec![0f32; frames];
        let times = paced_unsorted_s(period, blocks, || {
            started_s.push(synth.frame() as f64 / rate_hz);
            let t = Instant::now();
            synth.process(&mut out, 1);
            let took = t.elapsed().as_secs_f64();
            let inst = &synth.piano().instrument;
            active.push((0..inst.n_voices()).filter(|&k| inst.is_active(k)).count());
            stepped.push(inst.modes_stepped());
            took
        });
        bounds_s
            .windows(2)
            .map(|w| {
                let within: Vec<usize> = (0..times.len())
                    .filter(|&b| (w[0]..w[1]).contains(&started_s[b]))
                    .collect();
                let mut times_s: Vec<f64> = within.iter().map(|&b| times[b]).collect();
                times_s.sort_by(f64::total_cmp);
                Window {
                    from_s: w[0],
                    to_s: w[1],
                    times_s,
                    active_voices: within.last().map_or(0, |&b| active[b]),
                    modes_stepped: within.last().and_then(|&b| stepped[b]),
                }
            })
            .collect()
    })
}

/// Run `work` on `synth` on a thread of its own at real-time priority where the system grants
/// it (the synth's helper thread, if any, asked for it too), as an audio device's thread runs
/// the callbacks; returns what `work` returns and whether this thread's priority was granted.
fn on_real_time_thread<E: VoicePool, R: Send>(
    synth: &mut Synth<E>,
    work: impl FnOnce(&mut Synth<E>) -> R + Send,
) -> (R, bool) {
    synth.ask_real_time_priority();
    std::thread::scope(|scope| {
        let measure = scope.spawn(|| {
            let priority = Promotion::default();
            priority.ask();
            let result = work(synth);
            (result, priority.granted())
        });
        measure.join().expect("the measuring thread does not panic")
    })
}

/// Run `block` (which returns the seconds it took to compute) `blocks` times, one every
/// `period` as a device asks for them (each started on time, or at once after one that ran
/// late), and return the times, sorted.
pub fn paced_times_s(period: Duration, blocks: usize, block: impl FnMut() -> f64) -> Vec<f64> {
    let mut times = paced_unsorted_s(period, blocks, block);
    times.sort_by(f64::total_cmp);
    times
}

/// [`paced_times_s`]'s times in the order the blocks ran.
fn paced_unsorted_s(period: Duration, blocks: usize, mut block: impl FnMut() -> f64) -> Vec<f64> {
    let start = Instant::now();
    (1..=blocks as u32)
        .map(|b| {
            let took = block();
            let next = start + period * b;
            let now = Instant::now();
            if next > now {
                std::thread::sleep(next - now);
            }
            took
        })
        .collect()
}

/// Percentile `p` (0–1) of sorted, non-empty `x`.
pub fn percentile(x: &[f64], p: f64) -> f64 {
    x[((x.len() - 1) as f64 * p).round() as usize]
}

/// Speed of one struck voice on its own.
#[derive(Debug, Clone, Copy)]
pub struct VoiceSpeed {
    /// Seconds of sound per second of computing.
    pub real_time_factor: f64,
    pub flops_per_s: f64,
}

/// Run `spec` struck normally for `seconds` of sound (RK4 steps only, in precision `T`) and time it.
pub fn voice_speed<T: Real>(spec: &UnisonSpec, seconds: f64) -> VoiceSpeed {
    let mut inst = Rk4Pool::<T>::unison(spec).expect("the preset builds");
    inst.strike(Strike {
        velocity_m_s: 2.5,
        shift: 0.0,
    });
    // Past the hammer's contact, so the FLOP count per step is steady.
    for _ in 0..(0.01 / inst.step_s()) as usize {
        inst.step();
    }
    let steps = (seconds / inst.step_s()).max(1.0) as usize;
    let flops = inst.flops_per_step() * steps as f64;
    let t = Instant::now();
    for _ in 0..steps {
        inst.step();
    }
    let dt = t.elapsed().as_secs_f64();
    VoiceSpeed {
        real_time_factor: steps as f64 * inst.step_s() / dt,
        flops_per_s: flops / dt,
    }
}

/// Build `spec`'s key on the exact engine ([`ExactUnison`]) at `rate_hz` and time the build (s);
/// then strike it, pass the hammer's contact, and time `seconds` of sound in 64-frame blocks
/// (each step and the volume velocity read after it, as the synth asks). Returns the speed, the
/// build time and the complex modes of the key.
pub fn exact_speed(spec: &UnisonSpec, rate_hz: f64, seconds: f64) -> (VoiceSpeed, f64, usize) {
    let mut spec = spec.clone();
    spec.sample_rate_hz = rate_hz;
    let t = Instant::now();
    let mut voice = ExactUnison::new(&spec).expect("the preset builds");
    let build_s = t.elapsed().as_secs_f64();
    voice.strike(Strike {
        velocity_m_s: 2.5,
        shift: 0.0,
    });
    for _ in 0..(0.01 * rate_hz) as usize {
        voice.step();
    }
    let mut block = [[0.0; 2]; 64];
    let blocks = ((seconds * rate_hz).max(1.0) as usize).div_ceil(block.len());
    let steps = blocks * block.len();
    let flops = voice.flops_per_step() * steps as f64;
    let t = Instant::now();
    for _ in 0..blocks {
        voice.run(&mut block);
        std::hint::black_box(&block);
    }
    let dt = t.elapsed().as_secs_f64();
    let speed = VoiceSpeed {
        real_time_factor: steps as f64 / rate_hz / dt,
        flops_per_s: flops / dt,
    };
    (speed, build_s, voice.n_modes())
}

/// Time per RK4 step (s) of a c2 voice in a long silent tail — its motion 50 ms after a strike,
/// scaled so that the largest state value is `1e-305` (most modes' values are then subnormal, as
/// after minutes of decay) — with flush-to-zero/denormals-are-zero set (as in the audio thread),
/// without, and of the same voice sounding: `(sounding, tail_ftz, tail_plain)`.
pub fn denormal_tail_step_s(spec: &UnisonSpec, steps: usize) -> (f64, f64, f64) {
    let mut sounding = Rk4Pool::new(spec).expect("the preset builds");
    sounding.set_damper(false);
    sounding.strike(Strike {
        velocity_m_s: 2.5,
        shift: 0.0,
    });
    for _ in 0..(0.05 / sounding.step_s()) as usize {
        sounding.step();
    }
    let mut tail = sounding.clone();
    let (q, v) = tail.state_mut();
    let largest = q.iter().chain(v.iter()).fold(0f64, |m, x| m.max(x.abs()));
    let scale = 1e-305 / largest;
    q.iter_mut().chain(v.iter_mut()).for_each(|x| *x *= scale);
    let time = |inst: &mut Rk4Pool| {
        let t = Instant::now();
        for _ in 0..steps {
            inst.step();
        }
        t.elapsed().as_secs_f64() / steps as f64
    };
    let mut plain = tail.clone();
    // SAFETY: FTZ/DAZ only change how subnormal results round, on this thread, for the closure.
    let ftz = unsafe { no_denormals::no_denormals(|| time(&mut tail)) };
    (time(&mut sounding), ftz, time(&mut plain))
}

/// Real-time factor of the dense state-space baseline on `spec` over `steps` RK4 steps.
pub fn dense_real_time_factor(spec: &UnisonSpec, steps: usize) -> f64 {
    let mut dense = DenseUnison::new(spec);
    dense.strike(Strike {
        velocity_m_s: 2.5,
        shift: 0.0,
    });
    let t = Instant::now();
    for _ in 0..steps {
        dense.step();
    }
    steps as f64 / spec.sample_rate_hz / t.elapsed().as_secs_f64()
}

/// This core's nominal f64 peak (FLOP/s): FMA units × lanes × 2 × clock, from `/proc/cpuinfo`
/// (2 × 4 × 2 = 16 FLOP per cycle with AVX2 + FMA, 8 with SSE2 only). `None` where the clock is
/// not listed. The f32 peak is twice it (eight lanes per register).
pub fn nominal_f64_peak() -> Option<(f64, f64)> {
    let info = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    let mhz: f64 = info
        .lines()
        .find(|l| l.starts_with("cpu MHz"))?
        .split(':')
        .nth(1)?
        .trim()
        .parse()
        .ok()?;
    let fma = info
        .lines()
        .any(|l| l.starts_with("flags") && l.contains(" avx2") && l.contains(" fma"));
    let per_cycle = if fma { 16.0 } else { 8.0 };
    Some((per_cycle * mhz * 1e6, mhz / 1e3))
}

/// Resident memory of this process (bytes), from `/proc/self/status`.
pub fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let kb: u64 = status
        .lines()
        .find(|l| l.starts_with("VmRSS:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()?;
    Some(kb * 1024)
}

/// How long two cores take to meet (s): two threads meeting through the exact pool's own
/// [`Exchange`] as its halves do every sample, each publishing `values` numbers and waiting for
/// the other's. The median of `rounds` rounds of `meetings` (the first rounds of a new thread may
/// share a core before the scheduler moves it). `None` if a value arrived wrong or the meetings
/// took over 2 s (one core, or a thread descheduled for long). A machine's own figure: on a
/// 2-core Zen 5 VM 0.1 us while its two virtual cores sit close on the host, 0.5–0.7 us for
/// minutes at a time when the host places them apart — and then a block on two cores takes about
/// as long as on one (docs/performance.md).
pub fn core_meeting_s(values: usize, meetings: usize, rounds: usize) -> Option<f64> {
    use std::sync::atomic::{AtomicBool, Ordering};
    let exchange = Exchange::new(values);
    exchange.reset();
    let value = |side: usize, t: usize, k: usize| (side * 1_000_000_000 + t * 1_000 + k) as f64;
    let total = meetings * rounds.max(1);
    let done = AtomicBool::new(false);
    // Side `me`: the time each round took, or `None` (the other side is told to stop).
    let side = |me: usize| -> Option<Vec<f64>> {
        let (mut mine, mut theirs) = (vec![0.0; values], vec![0.0; values]);
        let mut round_s = Vec::with_capacity(rounds);
        let mut round_start = Instant::now();
        for t in 0..total {
            for (k, x) in mine.iter_mut().enumerate() {
                *x = value(me, t, k);
            }
            exchange.publish(me, t, &mine);
            let received = exchange.receive(me, t, &mut theirs);
            if !received
                || theirs
                    .iter()
                    .enumerate()
                    .any(|(k, &x)| x != value(1 - me, t, k))
            {
                exchange.give_up();
                return None;
            }
            if (t + 1).is_multiple_of(meetings) {
                round_s.push(round_start.elapsed().as_secs_f64() / meetings as f64);
                round_start = Instant::now();
            }
        }
        Some(round_s)
    };
    let (here, there) = std::thread::scope(|s| {
        // The watchdog: meetings that take over 2 s in all are given up.
        s.spawn(|| {
            let started = Instant::now();
            while !done.load(Ordering::Relaxed) {
                if started.elapsed() > Duration::from_secs(2) {
                    exchange.give_up();
                    return;
                }
                std::thread::sleep(Duration::from_millis(5));
            }
        });
        let there = s.spawn(|| side(1));
        let here = side(0);
        let there = there.join().ok().flatten();
        done.store(true, Ordering::Relaxed);
        (here, there)
    });
    there?;
    let mut round_s = here?;
    round_s.sort_by(f64::total_cmp);
    Some(percentile(&round_s, 0.5))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_cores_meet_and_receive_what_the_other_published() {
        // Each side checks every value it receives against what the other published at that
        // meeting: were the exchange's slot written again before the other side had read it, a
        // value of the next meeting would show.
        let s = core_meeting_s(64, 2_000, 10).expect("every value received as published");
        println!(
            "two threads met 20 000 times, 64 values each way: {:.2} us a meeting (median of 10 rounds)",
            s * 1e6
        );
        assert!(s > 0.0 && s.is_finite());
    }
}
