//! The callback's ways of running the engine all sound the same, bit for bit: the exact pool split
//! over two cores (a helper thread) and on one, the engine run from event to event and (within
//! rounding) one frame at a time; and the two-core callback never allocates. Each on a few voices
//! (two cores share the block passes) and on a 40-key chord (they share the steps too, meeting
//! every sample).

use assert_no_alloc::{assert_no_alloc, reset_violation_count, violation_count, AllocDisabler};
use std::sync::atomic::{AtomicU64, Ordering};
use unacorda::audio::aligned::{Aligned, LATENCY_FRAMES};
use unacorda::audio::synth::{Scheduled, Synth, EVENT_QUEUE};
use unacorda::config::output::OutputSettings;
use unacorda::config::scaling::{parse_key, Scaling};
use unacorda::engine::exact::ExactPool;
use unacorda::engine::Pair;
use unacorda::engine::{Rk4Pool, VoicePool};
use unacorda::midi::{Event, Pedal};
use unacorda::play::Piano;

#[global_allocator]
static ALLOCATOR: AllocDisabler = AllocDisabler;

/// The tests here run threads that spin for each other: one at a time, or on two cores they
/// only wait for each other's helpers.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn piano<E: VoicePool>(voices: usize) -> (Piano<E>, OutputSettings) {
    let scaling = Scaling::resolve("paper").unwrap();
    // Single, double and triple strings, damped and undamped keys.
    let names = ["A0", "C2", "E2", "C3", "G3", "C4", "E5", "C7"];
    let keys: Vec<usize> = names.iter().map(|n| parse_key(n).unwrap()).collect();
    (
        Piano::build(&scaling, &keys, voices).unwrap(),
        scaling.output_settings(),
    )
}

/// What a test plays on the exact pool: a piano, a script of events and how many 64-frame blocks.
struct Case {
    name: &'static str,
    piano: Piano<ExactPool>,
    settings: OutputSettings,
    script: Vec<(u64, Event)>,
    blocks: usize,
}

/// Eight keys on five voices ([`script`]).
fn few() -> Case {
    let (piano, settings) = piano::<ExactPool>(5);
    Case {
        name: "exact pool, 5 voices",
        piano,
        settings,
        script: script(),
        blocks: 200,
    }
}

/// Every other key from A0 up (40) struck under the sustain pedal 0.5 ms apart, the pedal lifted
/// (the damped keys' felts fall on their strings), the soft pedal, a few struck again: up to 40
/// voices, enough that the two cores share the steps.
fn chord() -> Case {
    let scaling = Scaling::resolve("paper").unwrap();
    let keys: Vec<usize> = (0..40).map(|k| 1 + 2 * k).collect();
    let on = |note, velocity| Event::NoteOn { note, velocity };
    let pedal = |pedal, down| Event::pedal(pedal, down);
    let mut script = vec![(0, pedal(Pedal::Sustain, true))];
    for (i, &key) in keys.iter().enumerate() {
        script.push((
            24 * i as u64,
            on(20 + key as u8, f64::from(30 + (i as u8 % 5) * 10)),
        ));
        script.push((
            2_000 + i as u64,
            Event::NoteOff {
                note: 20 + key as u8,
                velocity: 64.0,
            },
        ));
    }
    script.push((6_000, pedal(Pedal::Soft, true)));
    script.push((7_000, pedal(Pedal::Sustain, false)));
    script.push((7_500, on(60, 100.0)));
    script.push((7_600, on(64, 90.0)));
    script.sort_by_key(|&(frame, _)| frame);
    Case {
        name: "exact pool, 40-key chord",
        piano: Piano::build(&scaling, &keys, keys.len()).unwrap(),
        settings: scaling.output_settings(),
        script,
        blocks: 160,
    }
}

/// Notes, pedals, releases and (the pool holds 5 voices for 8 keys) steals with their fades.
fn script() -> Vec<(u64, Event)> {
    let on = |note, velocity| Event::NoteOn { note, velocity };
    let pedal = |pedal, down| Event::pedal(pedal, down);
    vec![
        (0, on(21, 90.0)),
        (10, on(36, 80.0)),
        (100, pedal(Pedal::Sustain, true)),
        (700, on(40, 100.0)),
        (701, on(48, 70.0)),
        (1500, pedal(Pedal::Soft, true)),
        (2000, on(55, 90.0)),
        (2600, on(60, 110.0)),
        (3000, on(76, 60.0)),
        (3100, on(96, 100.0)),
        (
            4000,
            Event::NoteOff {
                note: 36,
                velocity: 64.0,
            },
        ),
        (5000, pedal(Pedal::Sustain, false)),
        (6000, on(36, 127.0)),
        (9000, Event::AllNotesOff),
        (11000, on(48, 90.0)),
    ]
}

/// `blocks` blocks of `frames` frames of `synth` playing `script`.
fn play<E: VoicePool>(
    mut synth: Synth<E>,
    mut handle: unacorda::audio::SynthHandle<E>,
    script: &[(u64, Event)],
    blocks: usize,
    frames: usize,
    frame_by_frame: bool,
) -> Vec<f32> {
    for &(frame, event) in script {
        handle.schedule(Scheduled { frame, event }).unwrap();
    }
    let mut out = vec![0f32; blocks * frames];
    for block in out.chunks_exact_mut(frames) {
        if frame_by_frame {
            synth.process_with(block, 1, |_, _| {});
        } else {
            synth.process(block, 1);
        }
    }
    out
}

/// `a` and `b` equal bit for bit (and not silent).
fn compare<T: Copy + Into<f64>>(label: &str, a: &[T], b: &[T]) {
    let (a, b): (Vec<f64>, Vec<f64>) = (
        a.iter().map(|&x| x.into()).collect(),
        b.iter().map(|&x| x.into()).collect(),
    );
    let differ = a
        .iter()
        .zip(&b)
        .filter(|(x, y)| x.to_bits() != y.to_bits())
        .count();
    let peak = a.iter().fold(0f64, |m, x| m.max(x.abs()));
    println!(
        "{label}: {} frames, peak {peak:.3e}, {differ} frames differ",
        a.len()
    );
    assert!(peak > 0.0, "{label}: the script is heard");
    assert_eq!(differ, 0, "{label}: the outputs differ");
}

/// The exact pool advances a block in single precision inside it and in double from one block to
/// the next, so frame by frame (blocks of one) rounds otherwise than event to event: ~1e-5 of the
/// peak (the engine's own test), enough to move a hammer's release by a step here (1.2e-3).
#[test]
fn two_cores_sound_exactly_like_one() {
    two_cores_alike(&few(), 5e-3);
    two_cores_alike(&chord(), 5e-3);
}

/// `framewise`: how far (of the peak) the run frame by frame may be from the run event to event.
fn two_cores_alike(case: &Case, framewise_within: f32) {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let Case {
        name,
        ref piano,
        settings,
        ref script,
        blocks,
    } = *case;
    let one = {
        let (synth, handle) = Synth::new(piano.clone(), settings, EVENT_QUEUE).unwrap();
        play(synth, handle, script, blocks, 64, false)
    };
    let two = {
        let (mut synth, handle) = Synth::new(piano.clone(), settings, EVENT_QUEUE).unwrap();
        synth.use_second_core().unwrap();
        let stats = handle.stats.clone();
        let out = play(synth, handle, script, blocks, 64, false);
        let (split, late) = (
            stats.two_core_runs.load(Ordering::Relaxed),
            stats.helper_late.load(Ordering::Relaxed),
        );
        println!("{name}: engine runs on two cores {split}, on one with the helper late {late}");
        assert!(split > 0, "the helper thread never took a run");
        out
    };
    compare(
        &format!("{name}, two cores vs one (output, of full scale)"),
        &one,
        &two,
    );
    let framewise = {
        let (synth, handle) = Synth::new(piano.clone(), settings, EVENT_QUEUE).unwrap();
        play(synth, handle, script, blocks, 64, true)
    };
    let label = format!("{name}, event to event vs frame by frame (output, of full scale)");
    let peak = one.iter().fold(0f32, |m, x| m.max(x.abs()));
    let worst = one
        .iter()
        .zip(&framewise)
        .fold(0f32, |m, (x, y)| m.max((x - y).abs()));
    println!(
        "{label}: largest difference {:.1e} of the peak {peak:.3}",
        worst / peak
    );
    assert!(peak > 0.01 && worst <= framewise_within * peak, "{label}");
}

#[test]
fn the_reference_runs_alike_from_event_to_event() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let (piano, settings) = piano::<Rk4Pool>(5);
    let runs = [false, true].map(|framewise| {
        let (synth, handle) = Synth::new(piano.clone(), settings, EVENT_QUEUE).unwrap();
        play(synth, handle, &script(), 40, 256, framewise)
    });
    compare(
        "RK4 pool, event to event vs frame by frame (output, of full scale)",
        &runs[0],
        &runs[1],
    );
}

/// `script` on `synth` handed out in host blocks of the given lengths (cycled) through
/// [`Aligned`], each event scheduled at its frame of the host's timeline; the output advanced by
/// the latency, so that it lines up with [`play`]'s.
fn play_aligned<E: VoicePool>(
    synth: Synth<E>,
    handle: unacorda::audio::SynthHandle<E>,
    script: &[(u64, Event)],
    frames: usize,
    blocks: &[usize],
) -> Vec<f32> {
    let latency = LATENCY_FRAMES as usize;
    let mut aligned = Aligned::new(synth, handle, 1);
    let mut out = vec![0f32; frames + latency];
    let (mut next, mut at) = (0, 0);
    for &len in blocks.iter().cycle() {
        if at == out.len() {
            break;
        }
        let end = (at + len).min(out.len());
        // A host's block carries its events at offsets inside it: the block is handed out in
        // pieces from event to event, as the plugin does.
        while at < end {
            while next < script.len() && script[next].0 as usize == at {
                assert!(aligned.schedule(script[next].1));
                next += 1;
            }
            let until = script
                .get(next)
                .map_or(end, |e| (e.0 as usize).clamp(at + 1, end));
            aligned.process(&mut out[at..until]);
            at = until;
        }
    }
    assert!(
        out[..latency].iter().all(|&s| s == 0.0),
        "the latency is silent"
    );
    out.split_off(latency)
}

/// Host blocks of any length, the synth realigned to its grid ([`Aligned`]), sound exactly as the
/// offline render's blocks of 256, once the reported latency is taken off; callbacks of 64 (a
/// multiple of the grid) sound the same without realignment.
#[test]
fn any_host_blocks_sound_exactly_like_the_offline_render() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    for case in [few(), chord()] {
        let (name, script, settings) = (case.name, &case.script, case.settings);
        let frames = case.blocks * 64;
        let synth = || Synth::new(case.piano.clone(), settings, EVENT_QUEUE).unwrap();
        let offline = {
            let (synth, handle) = synth();
            play(synth, handle, script, frames / 256, 256, false)
        };
        let by_64 = {
            let (synth, handle) = synth();
            play(synth, handle, script, frames / 64, 64, false)
        };
        compare(
            &format!("{name}, callbacks of 64 vs 256"),
            &offline,
            &by_64[..offline.len()],
        );
        // Lengths from 1 to 4096 frames, none a multiple of the grid but 4096.
        let host_blocks = [1, 4096, 17, 333, 2, 1000, 95, 31, 33, 3];
        let (synth, handle) = synth();
        let hosted = play_aligned(synth, handle, script, offline.len(), &host_blocks);
        compare(
            &format!("{name}, host blocks of {host_blocks:?} realigned vs the offline render"),
            &offline,
            &hosted,
        );
    }
}

/// Allocations counted on the helper thread (the checker's counts are per thread), and its jobs.
static HELPER_ALLOCATIONS: AtomicU64 = AtomicU64::new(0);
static HELPER_JOBS: AtomicU64 = AtomicU64::new(0);

/// The helper's half of every split, under the allocation checker.
fn checked(job: &mut dyn FnMut()) {
    let before = violation_count();
    assert_no_alloc(job);
    let during = violation_count() - before;
    HELPER_ALLOCATIONS.fetch_add(u64::from(during), Ordering::Relaxed);
    HELPER_JOBS.fetch_add(1, Ordering::Relaxed);
}

#[test]
fn the_callback_on_two_cores_never_allocates() {
    // A split a block on few voices, and only while two voices sound (the script's last 30
    // blocks are one); on the chord, several splits a block (passes and steps).
    never_allocates(&few(), 50);
    never_allocates(&chord(), 300);
}

/// `min_jobs`: the helper's jobs at least (each under the checker).
fn never_allocates(case: &Case, min_jobs: u64) {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    HELPER_ALLOCATIONS.store(0, Ordering::Relaxed);
    HELPER_JOBS.store(0, Ordering::Relaxed);
    let (mut synth, mut handle) =
        Synth::new(case.piano.clone(), case.settings, EVENT_QUEUE).unwrap();
    synth.use_second_core_with(checked).unwrap();
    for &(frame, event) in &case.script {
        handle.schedule(Scheduled { frame, event }).unwrap();
    }
    let mut out = vec![0f32; 64];
    reset_violation_count();
    // At least `case.blocks` blocks, and on until the helper has taken `min_jobs` jobs (how often
    // it is on time depends on what else the machine runs; the checker's verdict does not).
    let mut blocks = 0;
    while blocks < case.blocks
        || (HELPER_JOBS.load(Ordering::Relaxed) < min_jobs && blocks < 40_000)
    {
        assert_no_alloc(|| synth.process(&mut out, 1));
        blocks += 1;
    }
    let stats = &handle.stats;
    let (splits, late) = (
        stats.two_core_runs.load(Ordering::Relaxed),
        stats.helper_late.load(Ordering::Relaxed),
    );
    let (helper, jobs) = (
        HELPER_ALLOCATIONS.load(Ordering::Relaxed),
        HELPER_JOBS.load(Ordering::Relaxed),
    );
    println!(
        "{}: {blocks} two-core callbacks: {} allocations in the callback, {helper} on the helper thread in its {jobs} jobs; {splits} runs split over both cores, {late} run on one because the helper was late",
        case.name,
        violation_count()
    );
    assert_eq!(violation_count(), 0, "the callback allocated");
    assert_eq!(helper, 0, "the helper's half allocated");
    // Every split ran the helper's half under the checker.
    assert!(
        jobs >= min_jobs && jobs == splits,
        "the work was not split: {jobs} jobs"
    );
}

/// A second core that starts every other time: odd calls decline (the engine then runs the
/// block on one core), even calls run `there` on a thread of their own beside `here`.
#[derive(Default)]
struct Alternates {
    calls: AtomicU64,
}

impl Pair for Alternates {
    fn join(&self, there: &mut (dyn FnMut() + Send), here: &mut (dyn FnMut() + Send)) -> bool {
        if self.calls.fetch_add(1, Ordering::Relaxed) % 2 == 1 {
            return false;
        }
        std::thread::scope(|s| {
            s.spawn(there);
            here();
        });
        true
    }
}

#[test]
fn split_and_declined_blocks_interleave_without_a_trace() {
    interleave(&few());
    interleave(&chord());
}

fn interleave(case: &Case) {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let alternates = Alternates::default();
    let runs = [false, true].map(|alternating| {
        let mut piano = case.piano.clone();
        let mut out = vec![[0.0; 2]; 64];
        let mut all = Vec::new();
        let mut script = case.script.iter().peekable();
        for block in 0..case.blocks as u64 {
            while let Some((_, event)) = script.next_if(|(f, _)| *f < (block + 1) * 64) {
                piano.apply(*event);
            }
            let pair = alternating.then_some(&alternates as &dyn Pair);
            piano.instrument.run(&mut out, pair);
            all.extend_from_slice(&out.concat());
        }
        all
    });
    let calls = alternates.calls.load(Ordering::Relaxed);
    println!(
        "{}: {calls} offers of a second core: half split the run over two threads, half declined",
        case.name
    );
    assert!(calls >= 100, "only {calls} runs were offered a second core");
    compare(
        &format!(
            "{}, splits and declined splits interleaved vs one core (volume velocity, m^3/s)",
            case.name
        ),
        &runs[0],
        &runs[1],
    );
}
