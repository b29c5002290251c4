//! `play` and `devices`: the live shell around the library's audio engine.

use crate::IntegratorArg;
use anyhow::{bail, Context, Result};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use unacorda::audio::device::{self, midi_input, output_devices, CallbackStats, Fault, MidiError};
use unacorda::audio::synth::{Scheduled, Synth, SynthHandle, EVENT_QUEUE};
use unacorda::config::scaling::{Scaling, KEYS};
use unacorda::engine::exact::ExactPool;
use unacorda::engine::{Rk4Pool, VoicePool};
use unacorda::midi::live::LiveParser;
use unacorda::play::{Piano, MAX_VOICES};

/// The flags of `play`.
#[derive(clap::Args)]
#[command(after_help = "Examples:
  unacorda play                                   the first MIDI keyboard, the default device
  unacorda play --midi-in 1 --device hw:1,0       a chosen keyboard and sound card (`unacorda devices`)
  unacorda play --midi assets/midi/chorale.mid    a file in real time
  unacorda play --buffer 128 --voices 32          lower latency on a slower machine")]
pub struct PlayArgs {
    /// MIDI input port: its number in `unacorda devices` or part of its name (default: the first).
    #[arg(long, value_name = "PORT")]
    pub midi_in: Option<String>,
    /// Play this MIDI file in real time instead of live input.
    #[arg(long, value_name = "FILE.mid")]
    pub midi: Option<PathBuf>,
    /// Audio output: its id in `unacorda devices` (e.g. alsa:null) or part of its name.
    #[arg(long, value_name = "NAME")]
    pub device: Option<String>,
    /// Frames per audio callback, 16–8192 (default: the device's).
    #[arg(long, value_name = "N")]
    pub buffer: Option<u32>,
    /// Size of the voice pool, 1–256.
    #[arg(long, default_value_t = unacorda::play::DEFAULT_VOICES, value_name = "N")]
    pub voices: usize,
    /// The pedal's halo: under the sustain pedal every key's strings ring in sympathy, struck or
    /// not (each undamped key takes a voice: the pool holds at least 128). About twice the work
    /// of playing without it: check `unacorda bench --halo` before playing live.
    #[arg(long)]
    pub halo: bool,
    /// Keyboard: built-in name (concert, the default; paper, the paper's model) or path to a .toml file.
    #[arg(long, default_value = "concert")]
    pub keyboard: String,
    /// One channel, heard at the keyboard's listener, instead of its stereo pair (concert:
    /// `bass_close` left, `treble_close` right; heard from `above` in mono). A mono piano plays
    /// the same sound on both channels of a stereo device.
    #[arg(long)]
    pub mono: bool,
    /// Stop after this many seconds (default: at the end of --midi plus 2 s, else at Ctrl-C).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub seconds: Option<f64>,
    /// Stop after this many audio callbacks (for tests on devices that play faster than real time).
    #[arg(long, value_name = "N")]
    pub callbacks: Option<u64>,
    /// `exact` (default): each key's coupled modes advanced exactly at 48 kHz, the keys coupled
    /// through the board (the first run prepares the 88 keys, with a bar of their progress, and
    /// keeps them in the cache of prepared keys; later runs read them back); `rk4`: the paper's RK4 at
    /// 96 kHz, the reference (a few voices at most: see `unacorda bench`).
    #[arg(long, value_enum, default_value_t = IntegratorArg::Exact)]
    pub integrator: IntegratorArg,
    /// Cores for the audio callback, 1–2: with 2 a helper thread takes half of each block's
    /// work (default: 2 where the machine has them).
    #[arg(long, value_name = "N")]
    pub cores: Option<usize>,
    #[command(flatten)]
    pub levels: crate::levels::Levels,
    /// Fault test: report the device as lost after this many callbacks, as cpal would on unplug.
    #[arg(long, value_name = "N", hide = true)]
    pub lose_device_after: Option<u64>,
}

/// Attempts to reopen a lost audio device, and the pause before each (ms).
const REOPEN_ATTEMPTS: u32 = 5;
const REOPEN_PAUSE_MS: u64 = 200;

/// Open the output, giving the synth back with the error when it cannot be opened.
fn open<E: VoicePool>(
    synth: Synth<E>,
    args: &PlayArgs,
    rate_hz: u32,
    stats: &Arc<CallbackStats>,
) -> Result<device::Output<E>, device::Refused<E>> {
    device::start(
        synth,
        args.device.as_deref(),
        rate_hz,
        args.buffer,
        stats.clone(),
    )
}

/// After the stream reported the device lost: take the synth back and open the device again
/// (a few attempts), continuing with the same voices, queue and clock.
fn reopen<E: VoicePool>(
    output: device::Output<E>,
    args: &PlayArgs,
    stats: &Arc<CallbackStats>,
) -> Result<device::Output<E>> {
    let (device, rate_hz) = (output.device.clone(), output.rate_hz);
    let Some(mut synth) = output.close() else {
        bail!("audio device {device} lost, and its stream did not return the engine; stopped");
    };
    let mut last = None;
    for attempt in 1..=REOPEN_ATTEMPTS {
        std::thread::sleep(Duration::from_millis(REOPEN_PAUSE_MS));
        match open(synth, args, rate_hz, stats) {
            Ok(output) => {
                eprintln!(
                    "audio: reopened {} (attempt {attempt}); the notes sounding go on",
                    output.device
                );
                return Ok(output);
            }
            Err((e, back)) => {
                eprintln!(
                    "audio: reopening {device} failed (attempt {attempt}/{REOPEN_ATTEMPTS}): {e:#}"
                );
                last = Some(anyhow::Error::from(e));
                match back {
                    Some(s) => synth = *s,
                    None => break,
                }
            }
        }
    }
    Err(last.unwrap_or_else(|| anyhow::anyhow!("the engine was lost with the stream")))
        .with_context(|| format!("audio device {device} was lost and could not be reopened; check the device, or choose another with --device (`unacorda devices` lists them)"))
}

/// Sound after the last event of a file played live (s).
const FILE_TAIL_S: f64 = 2.0;

pub fn play(args: PlayArgs) -> Result<()> {
    match args.integrator {
        IntegratorArg::Rk4 => play_on::<Rk4Pool>(args),
        IntegratorArg::Exact => play_on::<ExactPool>(args),
    }
}

/// `play` on the engine `E`.
fn play_on<E: VoicePool>(args: PlayArgs) -> Result<()> {
    if !(1..=MAX_VOICES).contains(&args.voices) {
        bail!("--voices {}: expected 1 to {MAX_VOICES}", args.voices);
    }
    if let Some(s) = args.seconds {
        if !(s > 0.0 && s <= 86_400.0) {
            bail!("--seconds {s}: expected a duration in (0, 86400] s");
        }
    }
    device::check_buffer(args.buffer)?;
    args.levels.check()?;
    let available = std::thread::available_parallelism().map_or(1, |n| n.get());
    let cores = args.cores.unwrap_or(available.min(2));
    if !(1..=2).contains(&cores) {
        bail!("--cores {cores}: expected 1 or 2");
    }
    // Read the file first: a bad file should fail before the keys are built.
    let file_events = match &args.midi {
        Some(path) => {
            let mut events = unacorda::midi::file::read_file(path)?;
            for e in &mut events {
                e.event = e.event.with_velocity_curve(args.levels.velocity_curve);
            }
            Some(events)
        }
        None => None,
    };
    let mut scaling = Scaling::resolve(&args.keyboard)?;
    if args.mono {
        scaling.make_mono();
    }
    scaling.set_gain_db(args.levels.gain_db);
    let settings = scaling.output_settings();
    // The device before the keys: a wrong name or format fails in a moment, not after the build.
    device::check_output(args.device.as_deref(), settings.rate_hz as u32)?;
    let keys: Vec<usize> = (1..=KEYS).collect();
    eprintln!("building {} keys on one soundboard…", keys.len());
    let started = std::time::Instant::now();
    let cache = unacorda::keycache::KeyCache::from_env();
    let voices = if args.halo {
        args.voices.max(unacorda::play::HALO_VOICES)
    } else {
        args.voices
    };
    let mut piano = crate::keys_bar::building(cache.as_ref(), keys.len(), |_| {
        Piano::<E>::build_with(&scaling, &keys, voices, cache.as_ref())
    })?;
    piano.player.set_halo(args.halo);
    if let Some(cache) = &cache {
        let (hits, stored) = (
            cache.hits.load(Ordering::Relaxed),
            cache.stored.load(Ordering::Relaxed),
        );
        if hits + stored > 0 {
            eprintln!(
                "built in {:.1} s ({hits} keys read back from {}, {stored} prepared and kept there)",
                started.elapsed().as_secs_f64(),
                cache.dir().display()
            );
        }
    }
    crate::warn_refused(cache.as_ref());
    let (mut synth, mut handle) = Synth::new(piano, settings, EVENT_QUEUE)?;
    let filter_delay_frames = synth.decimation_delay_frames();
    if cores == 2 {
        synth.use_second_core()?;
        synth.ask_real_time_priority();
    }
    // A file's first events (as many as the queue holds) are scheduled before the stream starts,
    // from its first frame: a callback running at real-time priority on a device that does not
    // pace it (ALSA's null device) may otherwise play many blocks before this thread runs again.
    let file_events = file_events.map(|events| {
        let next = handle.schedule_timed(&events, 0, 0);
        (events, next)
    });
    let stats = handle.stats.clone();
    let callback_stats = Arc::new(CallbackStats::default());
    let mut output =
        open(synth, &args, settings.rate_hz as u32, &callback_stats).map_err(|(e, _)| e)?;
    eprintln!(
        "playing on {} ({} ch, {} Hz, {} sound, {} voices, {cores} core{})",
        output.device,
        output.channels,
        output.rate_hz,
        unacorda::config::output::channel_layout(settings.channels),
        voices,
        if cores == 2 { "s" } else { "" }
    );
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // Without a handler Ctrl-C would end the process before the summary; failing to install
        // one (another handler exists) only loses the summary.
        let _ = ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed));
    }
    let started = Instant::now();
    let (mut injected, mut xruns, mut reopened) = (false, 0u64, 0u32);
    let mut priority_reported = false;
    let mut last_watch = started;
    let mut deadline = args.seconds.map(|s| started + Duration::from_secs_f64(s));
    // The event source: a file fed in real time from this thread, or the MIDI input's callback.
    let mut feed = None;
    let mut midi_link = None;
    let shared = Arc::new(Mutex::new(handle));
    match file_events {
        Some((events, next)) => {
            let length = events.last().map_or(0.0, |e| e.time_s) + FILE_TAIL_S;
            deadline.get_or_insert(started + Duration::from_secs_f64(length));
            eprintln!("playing {} events from the file ({length:.1} s)", events.len());
            feed = Some((events, 0, next));
        }
        None => match connect_midi(args.midi_in.as_deref(), &shared, args.levels.velocity_curve) {
            Ok((connection, name)) => {
                eprintln!("MIDI input: {name} — play; Ctrl-C stops");
                midi_link = Some(MidiLink::Connected(connection, name));
            }
            Err(reason) => eprintln!(
                "{reason}\nno MIDI input: the engine runs silent {}; use --midi FILE to play a file in real time",
                match (args.seconds, args.callbacks) {
                    (Some(s), _) => format!("for {s} s"),
                    (None, Some(n)) => format!("for {n} callbacks"),
                    (None, None) => "until Ctrl-C".to_owned(),
                }
            ),
        },
    }
    loop {
        std::thread::sleep(Duration::from_millis(5));
        if let Ok(mut handle) = shared.lock() {
            if let Some((events, start, next)) = &mut feed {
                *next = handle.schedule_timed(events, *next, *start);
            }
            // Releases a full queue could not take from the MIDI input, queued once it has room.
            let now = handle.clock.frame_at(Instant::now());
            handle.flush_backlog(now);
        }
        if last_watch.elapsed() >= Duration::from_secs(1) {
            last_watch = Instant::now();
            midi_link = midi_link.map(|l| l.watch(&shared, args.levels.velocity_curve));
        }
        let n = output.stats.callbacks.load(Ordering::Relaxed);
        if args.lose_device_after.is_some_and(|after| n >= after) && !injected {
            injected = true;
            output.inject(cpal::Error::new(cpal::ErrorKind::DeviceNotAvailable));
        }
        if !priority_reported {
            let helper = if cores == 2 {
                stats.helper_priority.outcome()
            } else {
                Some(Ok(()))
            };
            if let (Some(audio), Some(helper)) = (callback_stats.priority.outcome(), helper) {
                priority_reported = true;
                match (audio, helper) {
                    (Ok(()), Ok(())) => eprintln!(
                        "real-time priority (SCHED_FIFO) granted to the audio thread{}",
                        if cores == 2 { " and the helper" } else { "" }
                    ),
                    (Err(e), _) | (_, Err(e)) => eprintln!(
                        "real-time priority not granted: {e}; other work may preempt a block"
                    ),
                }
            }
        }
        let mut lost = None;
        while let Ok(e) = output.errors.try_recv() {
            match device::classify(&e) {
                Fault::Xrun => xruns += 1,
                Fault::Lost => lost = Some(e),
                Fault::Note => eprintln!("audio: {e}"),
            }
        }
        if let Some(e) = lost {
            eprintln!("audio: device {} lost ({e}); reopening…", output.device);
            output = reopen(output, &args, &callback_stats)?;
            reopened += 1;
        }
        if stop.load(Ordering::Relaxed)
            || args.callbacks.is_some_and(|c| n >= c)
            || deadline.is_some_and(|d| Instant::now() >= d)
        {
            break;
        }
    }
    let wall = started.elapsed().as_secs_f64();
    let backlog = shared
        .lock()
        .map(|handle| handle.backlog.clone())
        .unwrap_or_default();
    let summary = Summary {
        device: &output.device,
        wall_s: wall,
        rate_hz: settings.rate_hz,
        filter_delay_frames,
        cores,
        xruns,
        reopened,
        backlog,
    };
    eprint!("{}", summary.describe(&output.stats, &stats));
    Ok(())
}

/// What `play` says when it stops: whether the engine kept up, its headroom, the latency from
/// key to sound, what sounded, and anything lost on the way.
struct Summary<'a> {
    device: &'a str,
    wall_s: f64,
    rate_hz: f64,
    filter_delay_frames: f64,
    cores: usize,
    xruns: u64,
    reopened: u32,
    backlog: unacorda::audio::backlog::Backlog,
}

impl Summary<'_> {
    fn describe(&self, callback: &CallbackStats, synth: &unacorda::audio::synth::Stats) -> String {
        let load = |a: &AtomicU64| a.load(Ordering::Relaxed);
        let callbacks = load(&callback.callbacks);
        let frames = load(&callback.max_frames);
        let deadline_ms = frames as f64 / self.rate_hz * 1e3;
        let mean_ms = load(&callback.busy_ns) as f64 / callbacks.max(1) as f64 * 1e-6;
        let max_ms = load(&callback.max_ns) as f64 * 1e-6;
        let over = load(&callback.overruns);
        let percent = |ms: f64| 100.0 * ms / deadline_ms.max(1e-9);
        let mut out = format!(
            "played {:.1} s on {}, {} core{}: {callbacks} callbacks ({} frames) of up to {frames} frames ({deadline_ms:.2} ms each at {} Hz)\n",
            self.wall_s,
            self.device,
            self.cores,
            if self.cores == 2 { "s" } else { "" },
            load(&synth.frames),
            self.rate_hz,
        );
        out += &match (over, self.xruns) {
            (0, 0) => "  kept up: yes, no callback over its deadline\n".to_owned(),
            _ => format!(
                "  kept up: no, {over} of {callbacks} callbacks over their deadline (each a click); the device reported {} xruns. Fewer --voices, a larger --buffer, or `unacorda bench` to see what this machine holds\n",
                self.xruns
            ),
        };
        out += &format!(
            "  headroom: a callback took {mean_ms:.2} ms on average ({:.0} % of its deadline), the slowest {max_ms:.2} ms ({:.0} %)\n",
            percent(mean_ms),
            percent(max_ms)
        );
        // An event waits for the next callback, which is played after the one in the device.
        let latency_ms = 2.0 * deadline_ms + self.filter_delay_frames / self.rate_hz * 1e3;
        out += &format!(
            "  latency: about {latency_ms:.1} ms from key to sound at {frames} frames (a callback to be rendered, one in the device's buffer{}), plus the device's own\n",
            if self.filter_delay_frames > 0.0 {
                ", the anti-alias filter's delay"
            } else {
                ""
            }
        );
        let peak = f32::from_bits(load(&synth.peak_before_clip) as u32);
        let voices = load(&synth.peak_voices);
        out += &if voices == 0 || peak <= 0.0 {
            "  sound: silent, no note was played\n".to_owned()
        } else {
            format!(
                "  sound: at most {voices} voices at once, peak {:.1} dBFS, {} samples soft-clipped, {} voices reset\n",
                20.0 * peak.log10(),
                load(&synth.clipped),
                load(&synth.resets)
            )
        };
        let late = load(&synth.late_events);
        let (dropped, delayed) = (self.backlog.dropped_note_ons, self.backlog.delayed);
        if late + dropped + delayed > 0 {
            out += &format!(
                "  events: {late} came late; a full event queue dropped {dropped} strikes and queued {delayed} releases late (none lost)\n"
            );
        }
        if self.cores == 2 {
            out += &format!(
                "  cores: {} engine blocks on two, {} on one because the helper thread was late\n",
                load(&synth.two_core_runs),
                load(&synth.helper_late)
            );
        }
        if self.reopened > 0 {
            out += &format!("  device: lost, and reopened {} times\n", self.reopened);
        }
        out
    }
}

/// Open the MIDI input `port` (a number or part of a name; `None`: the first) and move the event
/// queue's producer into its callback, which parses the bytes with the same [`LiveParser`] the
/// tests feed and stamps each event one block ahead of the audio clock. The producer is shared
/// (locked only by the MIDI thread, never by the audio thread) so that a reconnection can use it.
fn connect_midi<E: VoicePool>(
    port: Option<&str>,
    handle: &Arc<Mutex<SynthHandle<E>>>,
    velocity_curve: f64,
) -> Result<(midir::MidiInputConnection<()>, String), MidiError> {
    let (input, ports, names) = midi_input()?;
    let index = match port {
        None => (!ports.is_empty()).then_some(0),
        Some(p) => p
            .parse::<usize>()
            .ok()
            .filter(|&i| i < ports.len())
            .or_else(|| names.iter().position(|n| n.contains(p))),
    };
    let Some(index) = index else {
        return Err(match port {
            Some(p) => MidiError::NoMatch {
                port: p.to_owned(),
                inputs: names,
            },
            None => MidiError::NoPort,
        });
    };
    let handle = handle.clone();
    let clock = handle
        .lock()
        .map_err(|_| MidiError::QueueGone)?
        .clock
        .clone();
    let mut parser = LiveParser::new();
    input
        .connect(
            &ports[index],
            "unacorda-in",
            move |_stamp_us, bytes, _| {
                let now = Instant::now();
                let Ok(mut handle) = handle.lock() else {
                    return;
                };
                for &b in bytes {
                    if let Some(event) = parser.push(b) {
                        let frame = clock.frame_at(now);
                        // A full queue keeps the releases for later and drops a strike.
                        handle.schedule_live(Scheduled {
                            frame,
                            event: event.with_velocity_curve(velocity_curve),
                        });
                    }
                }
            },
            (),
        )
        .map(|c| (c, names[index].clone()))
        .map_err(|e| MidiError::Connect {
            port: names[index].clone(),
            reason: e.to_string(),
        })
}

/// The live MIDI input, watched for being unplugged (midir reports nothing: the port just leaves
/// the sequencer's list) and reconnected when a port of that name comes back.
enum MidiLink {
    Connected(midir::MidiInputConnection<()>, String),
    Unplugged(String),
}

impl MidiLink {
    /// Check the port list (about once a second); say when the input goes or comes back.
    fn watch<E: VoicePool>(
        self,
        handle: &Arc<Mutex<SynthHandle<E>>>,
        velocity_curve: f64,
    ) -> MidiLink {
        let present =
            |name: &str| midi_input().is_ok_and(|(_, _, names)| names.iter().any(|n| n == name));
        match self {
            MidiLink::Connected(c, name) if !present(&name) => {
                c.close();
                eprintln!("MIDI input {name} was unplugged: what was already played sounds on; plug it back in to go on playing (Ctrl-C stops)");
                MidiLink::Unplugged(name)
            }
            MidiLink::Unplugged(name) if present(&name) => {
                match connect_midi(Some(&name), handle, velocity_curve) {
                    Ok((c, name)) => {
                        eprintln!("MIDI input {name} is back");
                        MidiLink::Connected(c, name)
                    }
                    Err(_) => MidiLink::Unplugged(name),
                }
            }
            link => link,
        }
    }
}

/// `devices`: audio outputs (with whether they can play the engine's format) and MIDI inputs.
pub fn devices() -> Result<()> {
    let rate = unacorda::config::preset::Preset::resolve("c2")?
        .output_settings()
        .rate_hz as u32;
    println!("audio outputs (--device):");
    for d in output_devices(rate).context("listing audio outputs")? {
        println!(
            "  {}{}  {}{}",
            d.id,
            if d.is_default { " (default)" } else { "" },
            d.description,
            if d.supports_rate {
                String::new()
            } else {
                format!("  [no 32-bit float output at {rate} Hz]")
            }
        );
    }
    println!("MIDI inputs (--midi-in):");
    match midi_input() {
        Ok((_, _, names)) if names.is_empty() => println!("  none connected"),
        Ok((_, _, names)) => {
            for (i, n) in names.iter().enumerate() {
                println!("  {i}: {n}");
            }
        }
        Err(reason) => println!("  {reason}"),
    }
    Ok(())
}
