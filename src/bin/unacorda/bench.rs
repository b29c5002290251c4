//! `bench`: the engine's speed on this machine, in the user's terms (real-time factors, voices
//! within the deadline, FLOP rate against the core's peak, memory), each figure with the
//! keyboard, engine, cores, voices, block and what is played that it was measured on.

use anyhow::{bail, Context, Result};
use serde::Serialize;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::Instant;
use unacorda::board::key_name;
use unacorda::config::preset::Preset;
use unacorda::config::scaling::{LoadedScaling, Scaling, KEYS};
use unacorda::engine::exact::ExactPool;
use unacorda::engine::physics::damper::FeltModel;
use unacorda::engine::{Rk4Pool, VoicePool};
use unacorda::measure::{
    block_times_s, core_meeting_s, denormal_tail_step_s, dense_real_time_factor, exact_speed,
    loaded_scenario, loaded_synth, nominal_f64_peak, percentile, resident_bytes,
    struck_chord_synth, voice_speed, windowed_block_times_s, HELD_CHORD, VELOCITY,
};
use unacorda::play::{Piano, HALO_VOICES, MAX_VOICES};

#[derive(clap::Args)]
pub struct BenchArgs {
    /// Seconds spent on each measurement, 0.1–60.
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
    seconds: f64,
    /// Largest voice count tried (also the pool size), 1–256.
    #[arg(long, default_value_t = unacorda::play::DEFAULT_VOICES)]
    voices: usize,
    /// Also write every figure as JSON (the keyboard; per engine, core count and voice count:
    /// median and p99.9 as fractions of the deadline, misses, blocks, the scenario; real-time
    /// factors; start-up; memory; the held chord's windows).
    #[arg(long, value_name = "FILE.json")]
    json: Option<PathBuf>,
    /// Time the callback of this engine only (default: every engine).
    #[arg(long, value_parser = ["rk4", "exact"])]
    engine: Option<String>,
    /// Keyboard whose keys the callbacks, the damped figure and the held chord play: built-in
    /// name (concert, the default: what `play`, `render --midi` and the plugin sound; paper, the
    /// paper's model on Table 1's board) or path to a .toml file. The damped figure plays the
    /// concert keyboard's damper felts where the keyboard has none (paper).
    #[arg(long, default_value = "concert")]
    keyboard: String,
    /// Skip the held chord: the exact engine's callback over the 10 s after a chord is struck
    /// under the pedal, timed as a device runs it (10 s of the bench's time). It runs with
    /// `--engine exact` or no `--engine`.
    #[arg(long)]
    no_held_chord: bool,
    /// With the pedal's halo: under the sustain pedal every key takes a voice and rings in
    /// sympathy, struck or not (`play --halo`; the pool holds at least 128 voices).
    #[arg(long)]
    halo: bool,
}

/// Block length of the live figures (frames at 48 kHz).
const BLOCK: usize = 64;

/// The cores' meeting, timed around each two-core measurement: values each way (about the shared
/// board's modes) and meetings per round (the median of 10 rounds, a few milliseconds in all).
const MEETING_VALUES: usize = 64;
const MEETINGS: usize = 1_000;

/// The held chord's windows after its strike (s): bounds of consecutive windows.
const HELD_CHORD_BOUNDS_S: [f64; 6] = [0.0, 0.5, 1.0, 2.0, 5.0, 10.0];

/// Every figure `bench` prints, for `--json`.
#[derive(Serialize, Default)]
struct Report {
    /// The keyboard the callbacks, start-up, memory and held chord play (its name).
    keyboard: String,
    block_frames: usize,
    rate_hz: f64,
    deadline_s: f64,
    /// Whether the thread that timed the callbacks ran at real-time priority.
    real_time_priority: Option<bool>,
    /// Nominal f64 peak of one core (FLOP/s), where known.
    f64_peak_flops: Option<f64>,
    voices: Vec<VoiceFigure>,
    /// The dense baseline's and the denormal tail's figures (`null` with `--engine`, which
    /// skips the single voice).
    dense_real_time_factor: Option<f64>,
    denormal_step_us: Option<Denormals>,
    callbacks: Vec<CallbackFigure>,
    damped: Vec<DampedFigure>,
    held_chord: Vec<HeldWindow>,
    startup: Vec<Startup>,
    memory: Vec<Memory>,
}

/// One c2 voice on its own.
#[derive(Serialize)]
struct VoiceFigure {
    engine: &'static str,
    /// What is played and timed.
    scenario: String,
    real_time_factor: f64,
    flops_per_s: f64,
    /// Time to build the key (s), where it is measured.
    build_s: Option<f64>,
}

#[derive(Serialize)]
struct Denormals {
    /// What is played and timed.
    scenario: String,
    sounding: f64,
    tail_ftz: f64,
    tail_plain: f64,
}

/// The callback with `voices` sounding: times as fractions of the block's deadline.
#[derive(Serialize)]
struct CallbackFigure {
    engine: &'static str,
    cores: usize,
    voices: usize,
    /// What is played while the callbacks are timed ([`loaded_scenario`]).
    scenario: String,
    median_x_deadline: f64,
    p999_x_deadline: f64,
    misses: usize,
    blocks: usize,
    helper_late: Option<u64>,
    /// On two cores: how long the two took to meet just before and just after the blocks (us,
    /// [`core_meeting_s`]; `null` where they could not), the machine's state during them.
    meeting_us: Option<[Option<f64>; 2]>,
}

/// The exact engine's callback with the same voices held (dampers lifted) and released (the
/// felt on every string, carried as `model` says: `coupled` or `modal`): median block times as
/// fractions of the deadline.
#[derive(Serialize)]
struct DampedFigure {
    /// The keyboard whose keys and felts are played (the concert keyboard's where the chosen
    /// one has no felts).
    keyboard: String,
    model: &'static str,
    voices: usize,
    /// What is played while the callbacks are timed.
    scenario: String,
    held_median_x_deadline: f64,
    damped_median_x_deadline: f64,
}

/// One window of time after the held chord's strike: the median of the callbacks that started
/// in it, as a fraction of the deadline, and the voices still simulated at its end.
#[derive(Serialize)]
struct HeldWindow {
    /// What is played and how it is timed.
    scenario: String,
    from_s: f64,
    to_s: f64,
    median_x_deadline: f64,
    blocks: usize,
    active_voices: usize,
    /// Modes the active voices step at the window's end.
    modes_stepped: Option<usize>,
}

/// Building the 88-key piano, what `play` does before it sounds.
#[derive(Serialize)]
struct Startup {
    engine: &'static str,
    /// What is built.
    scenario: String,
    keys: usize,
    build_s: f64,
    /// Keys read back from the cache of prepared keys (the rest were prepared).
    keys_from_cache: usize,
}

#[derive(Serialize)]
struct Memory {
    engine: &'static str,
    /// What is sounding when the resident memory is read ([`loaded_scenario`]).
    scenario: String,
    bytes_per_voice: usize,
    voices: usize,
    resident_bytes: Option<u64>,
}

pub fn bench(args: BenchArgs) -> Result<()> {
    let BenchArgs {
        seconds,
        voices: max_voices,
        json,
        engine: only,
        keyboard,
        no_held_chord,
        halo,
    } = args;
    let only = only.as_deref();
    if !(0.1..=60.0).contains(&seconds) {
        bail!("--seconds {seconds}: expected 0.1 to 60 s per measurement");
    }
    if !(1..=MAX_VOICES).contains(&max_voices) {
        bail!("--voices {max_voices}: expected 1 to {MAX_VOICES}");
    }
    let started = Instant::now();
    let scaling = Scaling::resolve(&keyboard)?;
    let mut report = Report {
        keyboard: scaling.scaling.name.clone(),
        block_frames: BLOCK,
        f64_peak_flops: nominal_f64_peak().map(|(peak, _)| peak),
        ..Report::default()
    };
    if only.is_none() {
        single_voice(seconds, &mut report)?;
    }
    let settings = scaling.output_settings();
    report.rate_hz = settings.rate_hz;
    report.deadline_s = BLOCK as f64 / settings.rate_hz;
    for (engine, cores) in [("rk4", 1), ("exact", 1), ("exact", 2)] {
        if only.is_some_and(|only| only != engine) {
            continue;
        }
        let run = match engine {
            "rk4" => callback::<Rk4Pool>,
            _ => callback::<ExactPool>,
        };
        run(
            &scaling,
            seconds,
            max_voices,
            cores,
            engine,
            halo,
            &mut report,
        )?;
    }
    if only.is_none_or(|only| only == "exact") {
        // Felts whose decay it can lengthen: the keyboard's own, or the concert keyboard's where
        // it has none (paper, also called grand: the c2 preset's one point felt).
        let damped_keyboard = if scaling.scaling.dampers.is_empty() {
            "concert"
        } else {
            keyboard.as_str()
        };
        for model in [FeltModel::Modal, FeltModel::Coupled] {
            let figure = damped(damped_keyboard, model, seconds, max_voices.min(32))?;
            report.damped.push(figure);
        }
        if !no_held_chord {
            held_chord(&scaling, halo, &mut report)?;
        }
    }
    if let Some(path) = json {
        let text = serde_json::to_string_pretty(&report).expect("plain data serialises");
        std::fs::write(&path, text + "\n")
            .with_context(|| format!("writing {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    println!("bench took {:.1} s in all", started.elapsed().as_secs_f64());
    Ok(())
}

/// What the engine of `piano` is, for the text: its name, the rate it steps at, how it holds
/// the keys.
fn engine_label<E: VoicePool>(engine: &str, piano: &Piano<E>) -> String {
    let khz = 1e-3 / piano.instrument.step_s();
    match engine {
        "rk4" => format!("RK4 engine at {khz:.0} kHz (the reference)"),
        _ => format!(
            "exact engine at {khz:.0} kHz (each key's coupled modes, keys coupled through the board)"
        ),
    }
}

/// What the sustain pedal lifts, for the text.
fn halo_label(halo: bool) -> &'static str {
    if halo {
        " with the halo (every key's strings undamped, those not struck ringing in sympathy)"
    } else {
        ""
    }
}

/// The cores a figure ran on, for the text.
fn cores_label(cores: usize) -> &'static str {
    if cores == 2 {
        "two cores (voices split, the second on a helper thread)"
    } else {
        "one core"
    }
}

/// The audio callback on engine `E` (on `cores` cores: 1, or 2 with a helper thread) with 1, 2,
/// 4 … `max_voices` voices sounding, and memory.
fn callback<E: VoicePool>(
    scaling: &LoadedScaling,
    seconds: f64,
    max_voices: usize,
    cores: usize,
    engine: &'static str,
    halo: bool,
    report: &mut Report,
) -> Result<()> {
    let keys: Vec<usize> = (1..=KEYS).collect();
    // With the halo, room for every key: under the pedal the keys not struck ring in sympathy.
    let pool = if halo {
        max_voices.max(HALO_VOICES)
    } else {
        max_voices
    };
    let cache = unacorda::keycache::KeyCache::from_env();
    let build = |report: &mut Report| -> Result<Piano<E>> {
        let hits = cache.as_ref().map_or(0, |c| c.hits.load(Ordering::Relaxed));
        let started = std::time::Instant::now();
        let piano = crate::keys_bar::building(cache.as_ref(), keys.len(), |_| {
            Piano::<E>::build_with(scaling, &keys, pool, cache.as_ref())
        })?;
        let build_s = started.elapsed().as_secs_f64();
        let from_cache = cache.as_ref().map_or(0, |c| c.hits.load(Ordering::Relaxed)) - hits;
        if cores == 1 {
            println!(
                "start-up ({} keyboard, {engine} engine): {} keys built in {build_s:.2} s, {from_cache} read back from the cache of prepared keys",
                scaling.scaling.name,
                keys.len()
            );
            report.startup.push(Startup {
                engine,
                scenario: format!(
                    "the {} keyboard's {} keys prepared or read back from the cache, in a pool of {pool} voices",
                    scaling.scaling.name,
                    keys.len()
                ),
                keys: keys.len(),
                build_s,
                keys_from_cache: from_cache,
            });
        }
        Ok(piano)
    };
    let mut piano = build(report)?;
    // Keys just prepared and kept: the start-up of the next run, from the cache.
    if cache
        .as_ref()
        .is_some_and(|c| c.stored.load(Ordering::Relaxed) > 0)
        && cores == 1
    {
        piano = build(report)?;
    }
    piano.player.set_halo(halo);
    crate::warn_refused(cache.as_ref());
    let settings = scaling.output_settings();
    let deadline = BLOCK as f64 / settings.rate_hz;
    println!(
        "live callback: {} keyboard, {}, {}, {BLOCK}-frame blocks at {:.0} kHz (deadline {:.2} ms);\n  {} (N: each line's voices):",
        scaling.scaling.name,
        engine_label(engine, &piano),
        cores_label(cores),
        settings.rate_hz / 1e3,
        deadline * 1e3,
        loaded_scenario(None, halo)
    );
    let mut within = 0;
    let mut voices = 1;
    loop {
        let (mut synth, handle) = loaded_synth(&piano, settings, voices, BLOCK);
        if cores == 2 {
            synth.use_second_core()?;
        }
        // `seconds` of blocks paced at the deadline, or of back-to-back blocks where they overrun.
        let (probe, _) = block_times_s(&mut synth, BLOCK, settings.rate_hz, 5);
        let blocks = ((seconds / percentile(&probe, 0.5).max(deadline)) as usize).clamp(20, 45_000);
        // After the helper has parked (it spins for `SPIN` after its last job).
        let meeting_us = || {
            std::thread::sleep(3 * unacorda::audio::helper::SPIN);
            core_meeting_s(MEETING_VALUES, MEETINGS, 10).map(|s| s * 1e6)
        };
        let before = (cores == 2).then(meeting_us).flatten();
        let (t, granted) = block_times_s(&mut synth, BLOCK, settings.rate_hz, blocks);
        let meeting = (cores == 2).then(|| [before, meeting_us()]);
        if voices == 1 {
            println!(
                "  (paced as a device runs them, one block every {:.2} ms; real-time priority {})",
                deadline * 1e3,
                if granted {
                    "granted"
                } else {
                    "refused: other work may preempt a block"
                }
            );
            report.real_time_priority = Some(granted);
        }
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
            if let Some(meeting) = meeting {
                let us = meeting.map(|m| m.map_or("-".to_string(), |m| format!("{m:.2}")));
                format!(
                    "; helper late (run on one core) {late} of {} runs; cores meet in {} / {} us before / after",
                    late + split,
                    us[0],
                    us[1]
                )
            } else {
                String::new()
            }
        );
        report.callbacks.push(CallbackFigure {
            engine,
            cores,
            voices,
            scenario: loaded_scenario(Some(voices), halo),
            median_x_deadline: median / deadline,
            p999_x_deadline: p999 / deadline,
            misses,
            blocks,
            helper_late: (cores == 2).then_some(late),
            meeting_us: meeting,
        });
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
    report.memory.push(Memory {
        engine,
        scenario: loaded_scenario(Some(max_voices), halo),
        bytes_per_voice: synth.piano().instrument.bytes_per_voice(),
        voices: max_voices,
        resident_bytes: resident_bytes(),
    });
    println!(
        "  memory: {:.1} kB of state per voice; resident {:.0} MB with {max_voices} voices sounding",
        synth.piano().instrument.bytes_per_voice() as f64 / 1e3,
        resident_bytes().unwrap_or(0) as f64 / 1e6
    );
    Ok(())
}

/// What voices whose dampers are down cost beside held ones, their felts carried as `model`
/// says (a coupled felt's channels enter each step; a modal one moves the modes' decay alone):
/// `voices` keys of `keyboard` spread over those with dampers (A0–F6), struck and held, then
/// struck and released, their felts set to a T60 of 60 s so that they keep sounding while timed.
fn damped(keyboard: &str, model: FeltModel, seconds: f64, voices: usize) -> Result<DampedFigure> {
    use unacorda::audio::synth::{Scheduled, Synth, EVENT_QUEUE};
    use unacorda::midi::Event;
    // The keyboard's felts (place, width), their decay lengthened.
    let mut scaling = Scaling::resolve(keyboard)?;
    scaling.scaling.damper_model = Some(model);
    let model = match model {
        FeltModel::Modal => "modal",
        FeltModel::Coupled => "coupled",
    };
    for felt in &mut scaling.scaling.dampers {
        felt.t60_s = 60.0;
    }
    let damped_keys = scaling.scaling.layout.dampers_until_key;
    let keys: Vec<usize> = (1..=damped_keys).collect();
    let cache = unacorda::keycache::KeyCache::from_env();
    let piano = crate::keys_bar::building(cache.as_ref(), keys.len(), |_| {
        Piano::<ExactPool>::build_with(&scaling, &keys, voices, cache.as_ref())
    })?;
    crate::warn_refused(cache.as_ref());
    let settings = scaling.output_settings();
    let deadline = BLOCK as f64 / settings.rate_hz;
    let mut medians = [0.0; 2];
    for (released, median) in medians.iter_mut().enumerate() {
        let (mut synth, mut handle) = Synth::new(piano.clone(), settings, EVENT_QUEUE)?;
        for v in 0..voices {
            let note = (20 + keys[v * keys.len() / voices.max(1)]) as u8;
            let frame = v as u64 * 48;
            let _ = handle.schedule(Scheduled {
                frame,
                event: Event::NoteOn {
                    note,
                    velocity: f64::from(VELOCITY),
                },
            });
            if released == 1 {
                let _ = handle.schedule(Scheduled {
                    frame: frame + 480,
                    event: Event::NoteOff {
                        note,
                        velocity: 64.0,
                    },
                });
            }
        }
        let mut out = vec![0f32; BLOCK];
        for _ in 0..(voices * 48 + 4800).div_ceil(BLOCK) {
            synth.process(&mut out, 1);
        }
        let blocks = ((seconds / deadline) as usize).clamp(20, 45_000);
        let (t, _) = block_times_s(&mut synth, BLOCK, settings.rate_hz, blocks);
        *median = percentile(&t, 0.5) / deadline;
    }
    let scenario = format!(
        "{voices} keys spread over {}–{} (those with dampers), struck 1 ms apart at velocity {VELOCITY}, no pedal; held: every key kept down; released: each key let go 10 ms after its strike, its felt's T60 set to 60 s; measured from 100 ms after the last strike, paced as a device runs them",
        key_name(1),
        key_name(damped_keys)
    );
    println!(
        "dampers down ({} keyboard, exact engine, one core, {voices} voices, {BLOCK}-frame blocks, {model} felt): median {:.3} × deadline held, {:.3} × released (the felt on every string): {:.2} ×\n  {scenario}",
        scaling.scaling.name,
        medians[0],
        medians[1],
        medians[1] / medians[0]
    );
    Ok(DampedFigure {
        keyboard: scaling.scaling.name.clone(),
        model,
        voices,
        scenario,
        held_median_x_deadline: medians[0],
        damped_median_x_deadline: medians[1],
    })
}

/// The cost of a held chord over time: [`HELD_CHORD`] of `scaling`'s keys struck together
/// under the sustain pedal on the exact engine, one core, and every callback from the strike to
/// the last of [`HELD_CHORD_BOUNDS_S`] timed as a device runs them; the median of each window
/// and the voices still simulated at its end. Whether the cost falls as the chord dies away is
/// what the engine makes of decaying modes.
fn held_chord(scaling: &LoadedScaling, halo: bool, report: &mut Report) -> Result<()> {
    // Every key of the keyboard: with the halo the keys not struck ring in sympathy.
    let keys: Vec<usize> = (1..=KEYS).collect();
    let cache = unacorda::keycache::KeyCache::from_env();
    let mut piano = crate::keys_bar::building(cache.as_ref(), keys.len(), |_| {
        Piano::<ExactPool>::build_with(scaling, &keys, HALO_VOICES, cache.as_ref())
    })?;
    piano.player.set_halo(halo);
    crate::warn_refused(cache.as_ref());
    let settings = scaling.output_settings();
    let deadline = BLOCK as f64 / settings.rate_hz;
    let names: Vec<String> = HELD_CHORD
        .iter()
        .map(|&note| key_name(note as usize - 20))
        .collect();
    let end_s = HELD_CHORD_BOUNDS_S[HELD_CHORD_BOUNDS_S.len() - 1];
    let scenario = format!(
        "held chord: sustain down{}, {} struck together at velocity {VELOCITY} and held; every callback from the strike to {end_s:.0} s after it, paced as a device runs them",
        halo_label(halo),
        names.join(" ")
    );
    println!(
        "held chord over time: {} keyboard, {}, one core, {} struck, {BLOCK}-frame blocks at {:.0} kHz (deadline {:.2} ms);\n  {scenario}; median of each window after the strike:",
        scaling.scaling.name,
        engine_label("exact", &piano),
        HELD_CHORD.len(),
        settings.rate_hz / 1e3,
        deadline * 1e3,
    );
    let (mut synth, _handle) = struck_chord_synth(&piano, settings, &HELD_CHORD);
    let (windows, granted) =
        windowed_block_times_s(&mut synth, BLOCK, settings.rate_hz, &HELD_CHORD_BOUNDS_S);
    println!(
        "  (real-time priority {})",
        if granted {
            "granted"
        } else {
            "refused: other work may preempt a block"
        }
    );
    for w in windows {
        if w.times_s.is_empty() {
            continue;
        }
        let median = percentile(&w.times_s, 0.5);
        println!(
            "  {:4.1}–{:4.1} s after the strike: median {:7.3} ms ({:6.2} × deadline) over {} blocks, {} voices active at its end{}",
            w.from_s,
            w.to_s,
            median * 1e3,
            median / deadline,
            w.times_s.len(),
            w.active_voices,
            w.modes_stepped
                .map_or(String::new(), |m| format!(", stepping {m} modes"))
        );
        report.held_chord.push(HeldWindow {
            scenario: scenario.clone(),
            from_s: w.from_s,
            to_s: w.to_s,
            median_x_deadline: median / deadline,
            blocks: w.times_s.len(),
            active_voices: w.active_voices,
            modes_stepped: w.modes_stepped,
        });
    }
    Ok(())
}

/// One c2 voice on each engine alone, the dense baseline and the denormal tail.
fn single_voice(seconds: f64, report: &mut Report) -> Result<()> {
    let c2 = Preset::resolve("c2")?;
    let spec = c2.unison_spec();
    let fast = voice_speed::<f64>(&spec, seconds);
    // The c2 preset whatever the keyboard: the paper's Table 1 key on its own board.
    let scenario = "the c2 preset alone (not --keyboard's keys): one voice struck at 2.5 m/s, its steps timed back to back from 10 ms after the strike";
    println!("c2 voice: {scenario}");
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
    let mut voice = |engine, v: &unacorda::measure::VoiceSpeed, build_s| {
        report.voices.push(VoiceFigure {
            engine,
            scenario: scenario.to_string(),
            real_time_factor: v.real_time_factor,
            flops_per_s: v.flops_per_s,
            build_s,
        })
    };
    voice("rk4-f64", &fast, None);
    let single = voice_speed::<f32>(&spec, seconds);
    voice("rk4-f32", &single, None);
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
    let (exact, build_s, modes) = exact_speed(&spec, rate, seconds);
    voice("exact", &exact, Some(build_s));
    println!(
        "same voice on the exact engine (the key's strings and the board's high modes in {} complex modes, z <- e^(lambda h) z, on the board's shared low modes; built in {:.2} s) at {:.0} kHz, hammer released:\n  real-time factor {:.1} ({:.1} × the paper-faithful RK4), {:.1} GFLOP/s counted (mostly single precision)",
        modes,
        build_s,
        rate / 1e3,
        exact.real_time_factor,
        exact.real_time_factor / fast.real_time_factor,
        exact.flops_per_s / 1e9,
    );
    // The dense baseline is a few hundred times slower: time a slice of the same length in steps
    // that takes about `seconds`.
    let steps = ((seconds * spec.sample_rate_hz * fast.real_time_factor / 400.0) as usize).max(20);
    let dense = dense_real_time_factor(&spec, steps);
    report.dense_real_time_factor = Some(dense);
    println!(
        "dense state-space baseline (Eq. 10–11 as written: A of order {}, faer mat-vec, RK4), same voice:\n  real-time factor {dense:.5}; unacorda is {:.0} × faster",
        2 * (spec.strings.len() * (spec.modes.modes_t + spec.modes.modes_p + spec.modes.modes_l)
            + spec.board.len())
            + 2,
        fast.real_time_factor / dense
    );

    let steps = ((seconds * spec.sample_rate_hz * fast.real_time_factor) as usize).max(100);
    let (sounding, ftz, plain) = denormal_tail_step_s(&spec, steps);
    report.denormal_step_us = Some(Denormals {
        scenario: "the c2 preset alone, struck at 2.5 m/s, its RK4 steps timed back to back: sounding from 50 ms after the strike, and in a tail (that state scaled to 1e-305)".to_string(),
        sounding: sounding * 1e6,
        tail_ftz: ftz * 1e6,
        tail_plain: plain * 1e6,
    });
    println!(
        "denormals, same voice in a long silent tail (state scaled to ≤ 1e-305, mostly subnormal), µs per RK4 step:\n  sounding {:.2}; tail with FTZ/DAZ as in the audio thread {:.2} ({:.2} × sounding); tail without {:.2} ({:.1} × sounding)",
        sounding * 1e6,
        ftz * 1e6,
        ftz / sounding,
        plain * 1e6,
        plain / sounding
    );

    Ok(())
}
