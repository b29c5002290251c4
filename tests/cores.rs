//! The callback's ways of running the engine all sound the same, bit for bit: the live pool split
//! over two cores (a helper thread) and on one, the engine run from event to event and one frame
//! at a time; and the two-core callback never allocates.

use assert_no_alloc::{assert_no_alloc, reset_violation_count, violation_count, AllocDisabler};
use std::sync::atomic::Ordering;
use unacorda::audio::synth::{OutputSettings, Scheduled, Synth, EVENT_QUEUE};
use unacorda::engine::exponential::{ExponentialInstrument, Pair};
use unacorda::engine::{Instrument, VoicePool};
use unacorda::midi::{Event, Pedal};
use unacorda::play::Piano;
use unacorda::scaling::{parse_key, Scaling};

#[global_allocator]
static ALLOCATOR: AllocDisabler = AllocDisabler;

fn piano<E: VoicePool>(voices: usize) -> (Piano<E>, OutputSettings) {
    let scaling = Scaling::resolve("grand").unwrap();
    // Single, double and triple strings, damped and undamped keys.
    let names = ["A0", "C2", "E2", "C3", "G3", "C4", "E5", "C7"];
    let keys: Vec<usize> = names.iter().map(|n| parse_key(n).unwrap()).collect();
    (
        Piano::build(&scaling, &keys, voices).unwrap(),
        scaling.base.output_settings(),
    )
}

/// Notes, pedals, releases and (the pool holds 5 voices for 8 keys) steals with their fades.
fn script() -> Vec<(u64, Event)> {
    let on = |note, velocity| Event::NoteOn { note, velocity };
    let pedal = |pedal, down| Event::Pedal { pedal, down };
    vec![
        (0, on(21, 90)),
        (10, on(36, 80)),
        (100, pedal(Pedal::Sustain, true)),
        (700, on(40, 100)),
        (701, on(48, 70)),
        (1500, pedal(Pedal::Soft, true)),
        (2000, on(55, 90)),
        (2600, on(60, 110)),
        (3000, on(76, 60)),
        (3100, on(96, 100)),
        (4000, Event::NoteOff { note: 36 }),
        (5000, pedal(Pedal::Sustain, false)),
        (6000, on(36, 127)),
        (9000, Event::AllNotesOff),
        (11000, on(48, 90)),
    ]
}

/// `blocks` blocks of `frames` frames of `synth` playing the script.
fn play<E: VoicePool>(
    mut synth: Synth<E>,
    mut handle: unacorda::audio::SynthHandle<E>,
    blocks: usize,
    frames: usize,
    frame_by_frame: bool,
) -> Vec<f32> {
    for (frame, event) in script() {
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

fn compare(label: &str, a: &[f32], b: &[f32]) {
    let differ = a
        .iter()
        .zip(b)
        .filter(|(x, y)| x.to_bits() != y.to_bits())
        .count();
    let peak = a.iter().fold(0f32, |m, x| m.max(x.abs()));
    println!(
        "{label}: {} frames, peak {peak:.3}, {differ} frames differ",
        a.len()
    );
    assert!(peak > 0.01, "{label}: the script is heard");
    assert_eq!(differ, 0, "{label}: the outputs differ");
}

#[test]
fn two_cores_sound_exactly_like_one() {
    let (piano, settings) = piano::<ExponentialInstrument>(5);
    let one = {
        let (synth, handle) = Synth::new(piano.clone(), settings, EVENT_QUEUE).unwrap();
        play(synth, handle, 200, 64, false)
    };
    let two = {
        let (mut synth, handle) = Synth::new(piano.clone(), settings, EVENT_QUEUE).unwrap();
        synth.use_second_core().unwrap();
        let stats = handle.stats.clone();
        let out = play(synth, handle, 200, 64, false);
        let (split, late) = (
            stats.two_core_runs.load(Ordering::Relaxed),
            stats.helper_late.load(Ordering::Relaxed),
        );
        println!("engine runs on two cores {split}, on one with the helper late {late}");
        assert!(split > 0, "the helper thread never took a run");
        out
    };
    compare(
        "live pool, two cores vs one (output, of full scale)",
        &one,
        &two,
    );
    let framewise = {
        let (synth, handle) = Synth::new(piano, settings, EVENT_QUEUE).unwrap();
        play(synth, handle, 200, 64, true)
    };
    compare(
        "live pool, event to event vs frame by frame (output, of full scale)",
        &one,
        &framewise,
    );
}

#[test]
fn the_reference_runs_alike_from_event_to_event() {
    let (piano, settings) = piano::<Instrument>(5);
    let runs = [false, true].map(|framewise| {
        let (synth, handle) = Synth::new(piano.clone(), settings, EVENT_QUEUE).unwrap();
        play(synth, handle, 40, 256, framewise)
    });
    compare(
        "RK4 pool, event to event vs frame by frame (output, of full scale)",
        &runs[0],
        &runs[1],
    );
}

#[test]
fn the_callback_on_two_cores_never_allocates() {
    let (piano, settings) = piano::<ExponentialInstrument>(5);
    let (mut synth, mut handle) = Synth::new(piano, settings, EVENT_QUEUE).unwrap();
    synth.use_second_core().unwrap();
    for (frame, event) in script() {
        handle.schedule(Scheduled { frame, event }).unwrap();
    }
    let mut out = vec![0f32; 64];
    reset_violation_count();
    for _ in 0..400 {
        assert_no_alloc(|| synth.process(&mut out, 1));
    }
    println!(
        "allocations in 400 two-core callbacks: {}",
        violation_count()
    );
    assert_eq!(violation_count(), 0);
}

/// A second core that never starts: every split is declined.
struct Declines;

impl Pair for Declines {
    fn join(&self, _there: &mut (dyn FnMut() + Send), _here: &mut dyn FnMut()) -> bool {
        false
    }
}

#[test]
fn a_second_core_that_does_not_start_costs_nothing_but_time() {
    let (piano, _) = piano::<ExponentialInstrument>(5);
    let runs = [false, true].map(|declined| {
        let mut piano = piano.clone();
        let mut out = vec![0.0; 64];
        let mut all = Vec::new();
        let mut script = script().into_iter().peekable();
        for block in 0..100u64 {
            while let Some((_, event)) = script.next_if(|(f, _)| *f < (block + 1) * 64) {
                piano.apply(event);
            }
            let pair = declined.then_some(&Declines as &dyn Pair);
            piano.instrument.run(&mut out, pair);
            all.extend(out.iter().map(|&x| x as f32));
        }
        all
    });
    compare(
        "live pool, every split declined vs one core (volume velocity, m^3/s)",
        &runs[0],
        &runs[1],
    );
}
