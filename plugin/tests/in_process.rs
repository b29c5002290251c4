//! The plugin loaded in process through clack-host from its entry point: its ports, parameters
//! and state; `process` never allocating over hundreds of blocks of notes, releases, pedals and
//! parameter changes; and its sound, in host blocks of 1 to 4096 frames, equal sample for sample
//! to the offline render of the same events once the reported latency is taken off.

mod host;
mod render;

use assert_no_alloc::{assert_no_alloc, violation_count, AllocDisabler};
use clack_host::prelude::PluginEntry;
use host::{Instance, Play, Threads};
use render::offline;
use unacorda::engine::exact::ExactPool;
use unacorda::engine::Rk4Pool;
use unacorda::midi::file::TimedEvent;
use unacorda::midi::{Decoder, Event};

#[global_allocator]
static ALLOCATOR: AllocDisabler = AllocDisabler;

/// Activations share a process-wide piano cache and two cores: one test at a time.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

const RATE_HZ: f64 = 48_000.0;
/// Parameter ids (see unacorda_clap::params::PARAMS).
const SUSTAIN: u32 = 1;
const SOFT: u32 = 3;
const GAIN_DB: u32 = 4;
const VELOCITY_CURVE: u32 = 5;
const KEYBOARD: u32 = 6;
const VOICES: u32 = 7;

/// The entry point the built library exports (`clap_entry`), as hosts load it.
fn entry() -> PluginEntry {
    // SAFETY: the plugin's own static entry, valid for the process's life.
    unsafe { PluginEntry::load_from_raw(&unacorda_clap::entry::clap_entry, c"") }.unwrap()
}

fn instance() -> Instance {
    host::instantiate(&entry())
}

/// `f` under the allocation checker; the allocations it made.
fn checked(f: &mut dyn FnMut()) -> u32 {
    let before = violation_count();
    assert_no_alloc(f);
    violation_count() - before
}

/// A performance in the host's events: CLAP notes (one at velocity 0, the softest strike, one
/// between MIDI's velocity steps), MIDI notes (one refined by a CC88 prefix), a CLAP release
/// velocity and a host's release without one, the sustain pedal
/// as MIDI CC64 and part way down as a parameter and as CC64 (a release under it), the soft pedal
/// part way down as a parameter and as CC67, releases with the pedal down and up, a wildcard
/// note-off.
fn script() -> Vec<(u64, Play)> {
    let ms = |t: f64| (t * RATE_HZ / 1000.0).round() as u64;
    let mut s = vec![
        (ms(0.0) + 17, Play::On(60, 100.0 / 127.0)),
        (ms(20.0), Play::Midi([0x90, 64, 80])),
        (ms(35.0), Play::On(67, 0.0)),
        (ms(60.0), Play::Midi([0xB0, 64, 127])),
        (ms(80.0), Play::Off(Some(60), 0.0)),
        (ms(90.0), Play::Midi([0x80, 64, 30])),
        (ms(110.0), Play::Param(SOFT, 0.6)),
        (ms(120.0), Play::On(48, 90.0 / 127.0)),
        (ms(129.0), Play::Midi([0xB1, 88, 64])),
        (ms(130.0), Play::Midi([0x91, 36, 110])),
        (ms(140.0), Play::Param(SUSTAIN, 0.45)),
        (ms(145.0), Play::Off(Some(48), 0.2)),
        (ms(150.0), Play::Midi([0xB0, 64, 50])),
        (ms(160.0), Play::Midi([0xB0, 64, 0])),
        (ms(165.0), Play::Midi([0xB0, 67, 100])),
        (ms(168.0), Play::On(55, 0.7)),
        (ms(170.0), Play::Param(SOFT, 0.0)),
        (ms(175.0), Play::On(72, 0.4321)),
        (ms(200.0), Play::Off(None, 0.0)),
        (ms(210.0), Play::Midi([0x90, 84, 127])),
        (ms(230.0), Play::Midi([0x90, 84, 0])),
    ];
    s.sort_by_key(|e| e.0);
    s
}

/// The script as the piano's events, timed as a MIDI file's (what `render --midi` plays).
fn as_piano_events(script: &[(u64, Play)]) -> Vec<TimedEvent> {
    let mut midi = Decoder::default();
    script
        .iter()
        .filter_map(|&(frame, play)| {
            let event = match play {
                Play::On(note, v) => Event::NoteOn {
                    note: note as u8,
                    velocity: (v * 127.0).clamp(1.0, 127.0),
                },
                Play::Off(Some(note), v) => Event::NoteOff {
                    note: note as u8,
                    velocity: 127.0 * v,
                },
                Play::Off(None, _) => Event::AllNotesOff,
                Play::Choke(_) => return None,
                Play::Midi([s, d1, d2]) => midi.decode(s, d1, d2)?,
                Play::Param(id, value) => render::pedal_of_param(id, value)?,
            };
            Some(TimedEvent {
                time_s: frame as f64 / RATE_HZ,
                event,
            })
        })
        .collect()
}

/// The state's line choosing the exact integrator, and the one choosing RK4.
const RK4_CHOSEN: (&str, &str) = ("integrator = \"exact\"", "integrator = \"rk4\"");

/// The plugin's own state with `from` changed to `to`, loaded back.
fn load_changed(plugin: &mut Instance, from: &str, to: &str) {
    let state = String::from_utf8(host::save(plugin)).unwrap();
    assert!(state.contains(from), "{from} in the state");
    host::load(plugin, state.replace(from, to).as_bytes()).unwrap();
}

fn first_sound(x: &[f32]) -> Option<usize> {
    x.iter().position(|&s| s != 0.0)
}

#[test]
fn ports_parameters_and_state() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let mut plugin = instance();
    let (outputs, channels, note_ports, dialects) = host::ports(&mut plugin);
    println!("audio outputs {outputs} ({channels} channels), note inputs {note_ports}, dialects {dialects:#b}");
    assert_eq!((outputs, channels, note_ports), (1, 2, 1));
    // CLAP (bit 0) and MIDI (bit 1): the pedals come as MIDI.
    assert_eq!(dialects & 0b11, 0b11);
    let params = host::params(&mut plugin);
    for p in &params {
        println!(
            "param {:>2} {:<28} {:>6} … {:<6} default {}",
            p.0, p.1, p.2, p.3, p.4
        );
    }
    assert_eq!(params.len(), 9);
    assert!(params.iter().any(|p| p.1.contains("Soft pedal")));

    let state = host::save(&mut plugin);
    println!(
        "state ({} bytes):\n{}",
        state.len(),
        String::from_utf8_lossy(&state)
    );
    let changed = String::from_utf8(state.clone())
        .unwrap()
        .replace("soft = 0", "soft = 1")
        .replace("gain_db = 0.0", "gain_db = -6.5");
    let rescans = host::rescans(&mut plugin);
    host::load(&mut plugin, changed.as_bytes()).unwrap();
    assert_eq!(host::param_value(&mut plugin, SOFT), Some(1.0));
    assert_eq!(host::param_value(&mut plugin, GAIN_DB), Some(-6.5));
    assert_eq!(
        host::rescans(&mut plugin),
        rescans + 1,
        "a load tells the host the values changed"
    );
    assert_eq!(
        host::save(&mut plugin),
        changed.as_bytes(),
        "the state round-trips exactly"
    );
    for bad in [
        changed.replace("unacorda-clap", "someone-else"),
        changed.replace("version = 3", "version = 7"),
        changed.replace("voices = 64", "voices = 100000"),
    ] {
        let e = host::load(&mut plugin, bad.as_bytes()).unwrap_err();
        println!("refused: {e}");
    }
    assert_eq!(
        host::save(&mut plugin),
        changed.as_bytes(),
        "a refused state changes nothing"
    );
}

/// The performance at 48 kHz in blocks of 1 to 4096 frames under the allocation checker: 0
/// allocations, sound from the first note's frame plus the latency, and every sample of both
/// channels equal to the offline render's.
#[test]
fn plays_exactly_like_the_offline_render_in_any_blocks_without_allocating() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let mut plugin = instance();
    let started = std::time::Instant::now();
    let mut active = host::activate(&mut plugin, RATE_HZ);
    println!("activated in {:.2} s", started.elapsed().as_secs_f64());
    let latency = host::latency(&mut plugin) as usize;
    assert_eq!(latency, unacorda::audio::aligned::LATENCY_FRAMES as usize);
    let script = script();
    let tail_s = 0.2;
    let events = as_piano_events(&script);
    let [left, right] = offline::<ExactPool>(&events, tail_s, false);
    let frames = left.len();
    let blocks = [1, 4096, 17, 333, 2, 1000, 95, 31, 64, 3, 512, 777];
    let heard = active.run(frames + latency, &blocks, &script, checked);
    let n_blocks = {
        let mut n = 0;
        let mut total = 0;
        for &b in blocks.iter().cycle() {
            if total >= frames + latency {
                break;
            }
            total += b;
            n += 1;
        }
        n
    };
    println!(
        "{n_blocks} blocks of {blocks:?} frames, {} events: {} allocations in process()",
        script.len(),
        heard.allocations
    );
    assert_eq!(heard.allocations, 0, "process() allocated");
    let first = first_sound(&heard.left).unwrap();
    println!(
        "first note at frame {}, first sound at {first} (latency {latency}); offline render's first sound at {:?}",
        script[0].0,
        first_sound(&left)
    );
    assert_eq!(Some(first - latency), first_sound(&left));
    assert!((first - latency) as u64 >= script[0].0 && (first - latency) as u64 <= script[0].0 + 2);
    equals_offline("exact", &heard, latency, [&left, &right]);
    host::deactivate(&mut plugin, active);
}

/// Both channels of what the plugin played equal to the offline render's, `latency` frames
/// late ([`render::equals_offline`]).
fn equals_offline(engine: &str, heard: &host::Heard, latency: usize, render: [&[f32]; 2]) {
    render::equals_offline(engine, [&heard.left, &heard.right], latency, render);
}

/// CLAP's thread pool: a host that runs the plugin's two tasks at once lends the engine its second
/// core (the two halves inside the plugin together); a host that runs them one after the other
/// gets them back at once, without a deadlock, and after a few blocks is no longer asked (the
/// helper thread takes over). Either way the same samples as the offline render, and no
/// allocation on the audio thread or the host's worker.
#[test]
fn a_hosts_thread_pool_lends_a_core_and_a_serial_one_gets_its_tasks_back() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let script = script();
    let events = as_piano_events(&script);
    let [left, right] = offline::<ExactPool>(&events, 0.1, false);
    for threads in [Threads::Parallel, Threads::Serial] {
        let mut plugin = host::instantiate_with(&entry(), threads, checked);
        let mut active = host::activate(&mut plugin, RATE_HZ);
        let latency = host::latency(&mut plugin) as usize;
        let heard = active.run(left.len() + latency, &[64, 256, 1000, 17], &script, checked);
        let (requests, tasks, most_at_once, together, worker_allocations) = host::pool(&mut plugin);
        println!(
            "{threads:?} host pool: {requests} requests, {tasks} tasks, {together} requests with both inside the plugin together (at most {most_at_once} at once); {} + {worker_allocations} allocations",
            heard.allocations
        );
        assert_eq!(heard.allocations, 0, "process() allocated");
        assert_eq!(worker_allocations, 0, "the worker's half allocated");
        assert_eq!(tasks, 2 * requests);
        match threads {
            Threads::Parallel => assert_eq!(most_at_once, 2, "the halves ran together"),
            _ => {
                assert_eq!(most_at_once, 1);
                assert_eq!(
                    requests,
                    unacorda::audio::host_pool::SERIAL_MISSES,
                    "asked until the host seemed serial, then no more"
                );
            }
        }
        equals_offline(
            &format!("{threads:?} pool"),
            &heard,
            latency,
            [&left, &right],
        );
        host::deactivate(&mut plugin, active);
    }
}

/// A host that hands over a transport event with an empty header, as Qtractor does (it clears
/// the event and fills in the fields only): the plugin plays on, as with a proper transport or
/// none, the same samples in all three (clack alone panicked on every such block, and the plugin
/// was silent in Qtractor).
#[test]
fn a_transport_with_an_empty_header_is_passed_over() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let mut plugin = instance();
    let script = [(0, Play::On(60, 0.6))];
    let mut heard = Vec::new();
    // SAFETY: a transport event is integers and flags: all zeros is a value of it (Qtractor's).
    let empty: clack_host::events::event_types::TransportEvent = unsafe { std::mem::zeroed() };
    let mut proper = empty;
    proper.header =
        clack_host::events::EventHeader::new_core(0, clack_host::events::EventFlags::empty());
    for (name, transport) in [
        ("none", None),
        ("proper", Some(proper)),
        ("empty", Some(empty)),
    ] {
        let mut active = host::activate(&mut plugin, RATE_HZ);
        active.transport = transport;
        // `run` fails the test on a block that returns an error.
        let h = active.run(4800, &[256], &script, checked);
        println!(
            "transport {name}: rms {:.4}, {} allocations",
            host::rms(&h.left),
            h.allocations
        );
        assert_eq!(h.allocations, 0, "process() allocated");
        heard.push(h.left);
        host::deactivate(&mut plugin, active);
    }
    assert!(host::rms(&heard[0]) > 0.0);
    assert!(
        heard[1] == heard[0] && heard[2] == heard[0],
        "the same samples"
    );
}

/// The integrator parameter (set by a state, before activation) plays the paper's RK4 in an
/// offline render (CLAP's render extension): the same events equal
/// `render --offline --integrator rk4 --midi`'s, sample for sample, one grid cell late, without
/// allocating; the latency reported adds the decimation filter's delay (RK4 runs
/// above the output rate, and both renders carry that delay), and the tail is infinite (RK4 has
/// no modes to say it).
#[test]
fn the_rk4_integrator_plays_like_its_offline_render() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let mut plugin = instance();
    let (exact, rk4) = RK4_CHOSEN;
    load_changed(&mut plugin, exact, rk4);
    host::render_offline(&mut plugin, true);
    let mut active = host::activate(&mut plugin, RATE_HZ);
    let reported = host::latency(&mut plugin) as usize;
    let latency = unacorda::audio::aligned::LATENCY_FRAMES as usize;
    let script: Vec<_> = script().into_iter().take(6).collect();
    let events = as_piano_events(&script);
    let [left, right] = offline::<Rk4Pool>(&events, 0.1, false);
    let heard = active.run(left.len() + latency, &[1, 333, 64, 4096], &script, checked);
    assert_eq!(heard.allocations, 0, "process() allocated");
    let tail = host::tail(&mut active).unwrap();
    println!(
        "RK4: latency reported {reported} (the grid's {latency} and the decimation filter's), first sound {:?} (offline {:?})",
        first_sound(&heard.left),
        first_sound(&left)
    );
    assert!(reported > latency);
    println!("RK4: tail {tail} frames");
    equals_offline("RK4", &heard, latency, [&left, &right]);
    assert!(
        tail >= i32::MAX as u32,
        "an infinite tail (CLAP: INT32_MAX or more)"
    );
    host::deactivate(&mut plugin, active);
}

/// With the pedal's halo (a state's `halo = 1`) the plugin plays as `render --midi --halo`: under
/// the sustain pedal every key takes a voice and rings in sympathy, in a pool of at least 128;
/// and not as without it.
#[test]
fn the_pedal_halo_plays_like_its_offline_render() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let mut plugin = instance();
    load_changed(&mut plugin, "halo = 0", "halo = 1");
    let mut active = host::activate(&mut plugin, RATE_HZ);
    let latency = host::latency(&mut plugin) as usize;
    let script = script();
    let events = as_piano_events(&script);
    let [left, right] = offline::<ExactPool>(&events, 0.1, true);
    let heard = active.run(left.len() + latency, &[64, 333, 1, 4096], &script, checked);
    assert_eq!(heard.allocations, 0, "process() allocated");
    equals_offline("exact with the halo", &heard, latency, [&left, &right]);
    let [without, _] = offline::<ExactPool>(&events, 0.1, false);
    let energy =
        |x: &mut dyn Iterator<Item = f32>| x.map(|v| f64::from(v) * f64::from(v)).sum::<f64>();
    let halo_db = 10.0
        * (energy(&mut left.iter().zip(&without).map(|(a, b)| a - b))
            / energy(&mut without.iter().copied()))
        .log10();
    println!("the halo's part of the sound (left, the difference re the render without it): {halo_db:.1} dB");
    assert!(halo_db > -60.0, "the halo changes nothing: {halo_db:.1} dB");
    host::deactivate(&mut plugin, active);
}

/// The sustain pedal (as a parameter) keeps a released note ringing; the soft pedal changes the
/// strike; a host's reset silences everything at once; with nothing sounding the plugin sleeps.
#[test]
fn pedals_reset_and_sleep() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let mut plugin = instance();
    let mut active = host::activate(&mut plugin, RATE_HZ);
    let db = |a: f64, b: f64| 20.0 * (a / b).log10();
    let second = RATE_HZ as usize;
    let quiet = active.run(second / 10, &[256], &[], host::unchecked);
    println!(
        "before any note: {} of {} blocks asleep",
        quiet.sleeps,
        (second / 10).div_ceil(256)
    );
    assert!(quiet.sleeps > 0 && quiet.left.iter().all(|&s| s == 0.0));

    // C4 struck and released after 0.1 s, without and with the sustain pedal.
    let mut played = Vec::new();
    for (sustain, soft) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)] {
        let t0 = active.frame;
        let script = [
            (t0, Play::Param(SUSTAIN, sustain)),
            (t0, Play::Param(SOFT, soft)),
            (t0 + 1, Play::On(60, 0.7)),
            (t0 + second as u64 / 10, Play::Off(Some(60), 0.0)),
        ];
        let heard = active.run(second / 2, &[480], &script, host::unchecked);
        active.processor.reset();
        played.push(heard);
        let after = active.run(1024, &[256], &[], host::unchecked);
        let nz = first_sound(&after.left);
        println!(
            "after reset: first non-zero {nz:?}, peak {}",
            after.left.iter().fold(0f32, |m, s| m.max(s.abs()))
        );
        assert!(
            after.left.iter().chain(&after.right).all(|&s| s == 0.0),
            "a reset silences everything"
        );
        println!("after reset: {} of 4 blocks asleep", after.sleeps);
        assert_eq!(after.sleeps, 4, "silent after a reset, the plugin sleeps");
    }
    let late = |h: &host::Heard| host::rms(&h.left[second * 3 / 10..second / 2]);
    let early = |h: &host::Heard| host::rms(&h.left[..second / 20]);
    let held = db(late(&played[1]), late(&played[0]));
    let soft = db(early(&played[2]), early(&played[0]));
    println!(
        "C4 released at 0.1 s: 0.3–0.5 s {held:+.1} dB with the sustain pedal; first 50 ms {soft:+.1} dB with the soft pedal"
    );
    assert!(held > 20.0, "the sustain pedal holds a released note");
    assert!(soft < -1.0, "the soft pedal strikes fewer strings: quieter");
    host::deactivate(&mut plugin, active);
}

/// Activation never fails: from 44.1 to 192 kHz the engine runs at the host's rate, below at a
/// multiple of it (the decimator's delay added to the latency), and at an absurd rate the plugin
/// plays silence. A note sounds from its frame plus the reported latency at every rate; a second
/// activation reuses the prepared keys.
#[test]
fn activates_at_every_rate() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let mut plugin = instance();
    for rate_hz in [44_100.0, 96_000.0, 22_050.0, 1.0] {
        for activation in ["first", "second"] {
            let started = std::time::Instant::now();
            let mut active = host::activate(&mut plugin, rate_hz);
            let took_s = started.elapsed().as_secs_f64();
            let latency = host::latency(&mut plugin) as usize;
            let tail_s = f64::from(host::tail(&mut active).unwrap()) / rate_hz;
            let at = 100;
            let frames = (0.05 * rate_hz).max(1000.0) as usize;
            let heard = active.run(
                frames,
                &[rate_hz as usize / 100 + 7],
                &[(at as u64, Play::On(69, 0.8))],
                host::unchecked,
            );
            let first = first_sound(&heard.left);
            let peak = heard.left.iter().fold(0f32, |m, s| m.max(s.abs()));
            println!(
                "{rate_hz} Hz, {activation} activation in {took_s:.2} s: latency {latency} frames, tail {tail_s:.1} s, note at frame {at}, first sound at {first:?}, peak {peak:.3}"
            );
            if rate_hz < 8_000.0 {
                assert_eq!(
                    (first, latency, tail_s),
                    (None, 0, 0.0),
                    "an absurd rate plays silence"
                );
            } else if rate_hz >= 44_100.0 {
                assert_eq!(first, Some(at + latency));
                // The concert keyboard's slowest partial, A0's first, rings 34 s to -60 dB.
                assert!((40.0..=120.0).contains(&tail_s), "tail {tail_s} s");
            } else {
                // The decimator's filter rings ahead of its delay: sound starts before it, within
                // its length.
                assert!(
                    first.is_some_and(|f| f >= at && f <= at + latency),
                    "{first:?}"
                );
                assert!(peak > 0.01);
            }
            host::deactivate(&mut plugin, active);
        }
    }
}

/// The automatable parameters move the sound without allocating: the gain by its decibels, the
/// velocity curve by the strike. A change of keyboard is built in the background while the old
/// one plays on (a main-thread callback asked for, blocks processed without allocating), and the
/// host is asked to restart once it is built, once; the activation after it plays the new
/// keyboard (paper: mono, the same in both channels, where concert's pair differs).
#[test]
fn gain_curve_and_rebuild_parameters() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let mut plugin = instance();
    let mut active = host::activate(&mut plugin, RATE_HZ);
    let frames = RATE_HZ as usize / 5;
    let mut heard = Vec::new();
    for (gain_db, curve) in [(0.0, 1.0), (-12.0, 1.0), (0.0, 2.0)] {
        let t0 = active.frame;
        let script = [
            (t0, Play::Param(GAIN_DB, gain_db)),
            (t0, Play::Param(VELOCITY_CURVE, curve)),
            // The gain settles within its ~5 ms smoothing before the note.
            (t0 + 960, Play::On(60, 0.6)),
        ];
        let h = active.run(frames, &[100, 17, 512], &script, checked);
        assert_eq!(h.allocations, 0, "process() allocated");
        active.processor.reset();
        heard.push(host::rms(&h.left[960..]));
    }
    let db = |a: f64| 20.0 * (a / heard[0]).log10();
    println!(
        "C4 at velocity 76: gain -12 dB -> {:+.2} dB; velocity curve 2 -> {:+.2} dB",
        db(heard[1]),
        db(heard[2]),
    );
    assert!((db(heard[1]) + 12.0).abs() < 0.05, "the gain");
    assert!(db(heard[2]) < -3.0, "a steeper curve strikes softer");

    let (restarts, callbacks) = (host::restarts(&mut plugin), host::callbacks(&mut plugin));
    assert_eq!(host::ports(&mut plugin).1, 2, "concert's port: stereo");
    let t0 = active.frame;
    let script = [
        (t0, Play::Param(KEYBOARD, 1.0)),
        (t0 + 5, Play::Param(KEYBOARD, 1.0)),
    ];
    let h = active.run(256, &[64], &script, checked);
    assert_eq!(h.allocations, 0, "process() allocated");
    assert_eq!(
        host::callbacks(&mut plugin),
        callbacks + 1,
        "one callback asked"
    );
    assert_eq!(
        host::restarts(&mut plugin),
        restarts,
        "no restart before the build"
    );
    host::on_main_thread(&mut plugin);
    // The old piano plays on while the new one is built (a hang guard, not a timing: the build
    // takes seconds).
    let started = std::time::Instant::now();
    let mut blocks = 0;
    while host::restarts(&mut plugin) == restarts {
        assert!(
            started.elapsed().as_secs() < 1200,
            "the background build never ended"
        );
        let t0 = active.frame;
        let h = active.run(256, &[256], &[(t0, Play::On(60, 0.6))], checked);
        assert_eq!(
            h.allocations, 0,
            "process() allocated while the piano was built"
        );
        assert!(host::rms(&h.left) > 0.0, "the old piano plays on");
        blocks += 1;
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let t0 = active.frame;
    active.run(2048, &[512], &[(t0, Play::Param(KEYBOARD, 1.0))], checked);
    println!(
        "keyboard changed: built in the background over {blocks} blocks, {} restart request(s), {} callback(s)",
        host::restarts(&mut plugin) - restarts,
        host::callbacks(&mut plugin) - callbacks
    );
    assert_eq!(
        host::restarts(&mut plugin),
        restarts + 1,
        "one restart, once built"
    );
    assert_eq!(host::callbacks(&mut plugin), callbacks + 1);
    host::deactivate(&mut plugin, active);
    // Inactive, the port follows the mono keyboard: the deactivation asks for a callback, which
    // has the host read the ports again (not before: active, the callback that started the build
    // left the port as it was).
    assert_eq!(host::callbacks(&mut plugin), callbacks + 2);
    assert_eq!(host::port_rescans(&mut plugin), 0, "no rescan while active");
    host::on_main_thread(&mut plugin);
    let channels = host::ports(&mut plugin).1;
    println!(
        "after the restart, inactive: {} port rescan(s), {channels} channel(s)",
        host::port_rescans(&mut plugin)
    );
    assert_eq!(host::port_rescans(&mut plugin), 1);
    assert_eq!(channels, 1, "paper's port: mono");

    // The host restarts the plugin: the activation finds the paper keyboard built.
    let mut active = host::activate(&mut plugin, RATE_HZ);
    let t0 = active.frame;
    let h = active.run(frames, &[512], &[(t0, Play::On(60, 0.6))], checked);
    assert_eq!(h.allocations, 0, "process() allocated");
    assert!(
        host::rms(&h.left) > 0.0 && h.left == h.right,
        "paper plays, mono"
    );
    host::deactivate(&mut plugin, active);
    // Nothing to follow: no callback asked at this deactivation.
    assert_eq!(host::callbacks(&mut plugin), callbacks + 2);

    // A state choosing concert again, loaded while inactive: the port is read again at once.
    load_changed(
        &mut plugin,
        "keyboard = \"paper\"",
        "keyboard = \"concert\"",
    );
    assert_eq!(host::port_rescans(&mut plugin), 2);
    assert_eq!(
        host::ports(&mut plugin).1,
        2,
        "concert's port: stereo again"
    );
}

/// RK4 takes longer than real time for one voice: chosen while the host plays live, the exact
/// engine plays (the same samples as the exact offline render); the host's switch to an offline
/// render is followed like a parameter, by a background build and one restart.
#[test]
fn the_rk4_choice_plays_the_exact_engine_live() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let mut plugin = instance();
    let (exact, rk4) = RK4_CHOSEN;
    load_changed(&mut plugin, exact, rk4);
    let mut active = host::activate(&mut plugin, RATE_HZ);
    let latency = unacorda::audio::aligned::LATENCY_FRAMES as usize;
    assert_eq!(host::latency(&mut plugin) as usize, latency, "no decimator");
    let script: Vec<_> = script().into_iter().take(6).collect();
    let [left, right] = offline::<ExactPool>(&as_piano_events(&script), 0.1, false);
    let heard = active.run(left.len() + latency, &[512], &script, checked);
    assert_eq!(heard.allocations, 0, "process() allocated");
    equals_offline("RK4 chosen, live", &heard, latency, [&left, &right]);

    let (restarts, callbacks) = (host::restarts(&mut plugin), host::callbacks(&mut plugin));
    host::render_offline(&mut plugin, true);
    let started = std::time::Instant::now();
    while host::restarts(&mut plugin) == restarts {
        // A hang guard, not a timing.
        assert!(
            started.elapsed().as_secs() < 1200,
            "the background build never ended"
        );
        let h = active.run(256, &[256], &[], checked);
        assert_eq!(h.allocations, 0, "process() allocated");
        if host::callbacks(&mut plugin) > callbacks {
            host::on_main_thread(&mut plugin);
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    active.run(2048, &[512], &[], checked);
    println!(
        "offline render asked: {} restart(s), {} callback(s)",
        host::restarts(&mut plugin) - restarts,
        host::callbacks(&mut plugin) - callbacks
    );
    assert_eq!(host::restarts(&mut plugin), restarts + 1, "one restart");
    host::deactivate(&mut plugin, active);
    host::activate(&mut plugin, RATE_HZ);
    assert!(
        host::latency(&mut plugin) as usize > latency,
        "RK4 plays, with its decimator's delay"
    );
}

/// A change of pool size prepares no keys: the restart it asks for comes as soon as the main
/// thread's build finds the keyboard's keys kept, and the activation after it makes its piano
/// from them.
#[test]
fn a_change_of_pool_size_prepares_no_keys() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let mut plugin = instance();
    let mut active = host::activate(&mut plugin, RATE_HZ);
    let kept = unacorda_clap::prepare::keyboards_kept();
    for voices in [17.0, 200.0] {
        let (restarts, callbacks) = (host::restarts(&mut plugin), host::callbacks(&mut plugin));
        let t0 = active.frame;
        let h = active.run(256, &[64], &[(t0, Play::Param(VOICES, voices))], checked);
        assert_eq!(h.allocations, 0, "process() allocated");
        assert_eq!(host::callbacks(&mut plugin), callbacks + 1);
        host::on_main_thread(&mut plugin);
        let started = std::time::Instant::now();
        while host::restarts(&mut plugin) == restarts {
            assert!(started.elapsed().as_secs() < 600, "the restart never came");
            active.run(256, &[256], &[], checked);
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        host::deactivate(&mut plugin, active);
        active = host::activate(&mut plugin, RATE_HZ);
        let t0 = active.frame;
        let h = active.run(4800, &[512], &[(t0, Play::On(60, 0.6))], checked);
        println!(
            "{voices} voices: restarted; keyboards' keys kept {} (before {kept})",
            unacorda_clap::prepare::keyboards_kept()
        );
        assert!(host::rms(&h.left) > 0.0, "the new pool plays");
        assert_eq!(
            unacorda_clap::prepare::keyboards_kept(),
            kept,
            "no keys prepared for a pool size"
        );
    }
    host::deactivate(&mut plugin, active);
}
