//! The audio thread's side: notes, MIDI and parameter changes applied at their frame, the synth
//! realigned to its grid ([`Aligned`]), the output gain, and sleep when nothing sounds. Never
//! allocates, locks or prints in `process` (the plugin's tests run it under `assert_no_alloc`).

use crate::params::{GAIN_DB, REBUILDS, SOFT, SOSTENUTO, SUSTAIN, VELOCITY_CURVE};
use crate::prepare::Pianos;
use crate::{MainThread, Shared};
use clack_extensions::tail::TailLength;
use clack_extensions::thread_pool::HostThreadPool;
use clack_plugin::events::spaces::CoreEventSpace;
use clack_plugin::events::Match;
use clack_plugin::prelude::*;
use std::sync::atomic::Ordering;
use unacorda::audio::aligned::LATENCY_FRAMES;
use unacorda::audio::host_pool::HostPool;
use unacorda::audio::synth::EVENT_QUEUE;
use unacorda::audio::{Aligned, Synth};
use unacorda::engine::exact::ExactPool;
use unacorda::engine::{Pair, Rk4Pool, VoicePool};
use unacorda::midi::{curved_velocity, Decoder, Event, Pedal};

/// The ring-out the tail reports: how long the slowest mode takes to fall this far (dB), from a
/// fortissimo's level to below the 24-bit floor.
pub const TAIL_FALL_DB: f64 = 120.0;

/// What the host is told when RK4 is chosen and it plays live.
const RK4_LIVE: &str = "unacorda: the RK4 integrator (the paper's reference) plays in offline renders only: it takes longer than real time for a single voice. Live, the exact engine plays.";

/// Frames rendered at a time into the interleaved scratch buffer.
const SCRATCH_FRAMES: usize = 256;

/// The output gain's smoothing: the gain moves this fraction of the way to its target each
/// frame (a time constant of ~5 ms at 48 kHz), so automating it never clicks.
const GAIN_SMOOTHING: f32 = 0.004;

/// An active instance's audio side (audio thread).
pub struct Processor<'a> {
    shared: &'a Shared,
    host: HostAudioProcessorHandle<'a>,
    /// The synth, or none when the activation could not build one (it plays silence).
    engine: Option<Engine>,
    /// Channels the engine renders (1 or 2) and the interleaved buffer it renders them into.
    channels: usize,
    scratch: Vec<f32>,
    /// The pedal parameters as last played (a state load changes them behind the processor).
    pedals: [f64; 3],
    /// The gain applied to the last frame (linear).
    gain: f32,
    /// The ring-out reported as the tail (host frames; infinite on RK4).
    tail: TailLength,
    /// The keyboard, pool size and integrator this activation built ([`REBUILDS`]).
    built: [f64; REBUILDS.len()],
    /// Where a change of them stands.
    rebuild: Rebuilding,
    /// The host's thread pool, if it has one: the engine's second core, before the helper thread.
    thread_pool: Option<HostThreadPool>,
    /// The host's MIDI messages to piano events (its CC88 prefixes kept between them).
    midi: Decoder,
}

/// The synth on either engine, realigned to the host's blocks.
enum Engine {
    Exact(Aligned<ExactPool>),
    Rk4(Aligned<Rk4Pool>),
}

/// `engine.$method(args)` on whichever engine it is.
macro_rules! on_engine {
    ($engine:expr, $e:ident => $body:expr) => {
        match $engine {
            Engine::Exact($e) => $body,
            Engine::Rk4($e) => $body,
        }
    };
}

impl Engine {
    fn channels(&self) -> usize {
        on_engine!(self, e => e.channels())
    }
    fn schedule(&mut self, event: Event) {
        on_engine!(self, e => {
            e.schedule(event);
        })
    }
    fn process(&mut self, out: &mut [f32], pair: Option<&dyn Pair>) {
        on_engine!(self, e => e.process_on(out, pair))
    }
    fn is_silent(&self) -> bool {
        on_engine!(self, e => e.is_silent())
    }
    fn silence(&mut self) {
        on_engine!(self, e => e.silence())
    }
    /// How long the slowest mode takes to fall [`TAIL_FALL_DB`] (s): the exact engine's modes
    /// say; RK4 has none to ask, and its tail is reported infinite (the plugin sleeps when
    /// silent).
    fn ring_out_s(&self) -> f64 {
        match self {
            Engine::Exact(e) => e.synth().piano().instrument.ring_out_s(TAIL_FALL_DB),
            Engine::Rk4(_) => f64::INFINITY,
        }
    }
}

/// A change of keyboard, pool size, integrator, halo or render mode while active
/// ([`crate::rebuild`]).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Rebuilding {
    /// Playing what was built.
    No,
    /// The main thread builds these values ([`REBUILDS`], as [`Shared::played`]) in the
    /// background, for the request of this number.
    Building([f64; REBUILDS.len()], u64),
    /// Built; the host was asked to restart the plugin.
    Restarting,
}

const PEDALS: [(usize, Pedal); 3] = [
    (SUSTAIN, Pedal::Sustain),
    (SOSTENUTO, Pedal::Sostenuto),
    (SOFT, Pedal::Soft),
];

impl<'a> PluginAudioProcessor<'a, Shared, MainThread<'a>> for Processor<'a> {
    fn activate(
        host: HostAudioProcessorHandle<'a>,
        main_thread: &MainThread<'a>,
        shared: &'a Shared,
        config: PluginAudioConfiguration,
    ) -> Result<Self, PluginError> {
        let values = &shared.values;
        let built = shared.played();
        if values.integrator() != shared.integrator() {
            main_thread.warn(RK4_LIVE);
        }
        // Activation never fails: what cannot be built plays silence and says why, once.
        let prepared = crate::prepare::prepare(
            values.keyboard(),
            config.sample_rate,
            values.voices(),
            shared.integrator(),
        )
        .map(|prepared| prepared.with_halo(values.halo()));
        for warning in crate::prepare::take_warnings() {
            main_thread.warn(&warning);
        }
        let (engine, latency) = match prepared.and_then(start) {
            Ok((engine, latency)) => {
                *shared
                    .silent_because
                    .lock()
                    .unwrap_or_else(|e| e.into_inner()) = None;
                (Some(engine), latency)
            }
            Err(why) => {
                let mut last = shared
                    .silent_because
                    .lock()
                    .unwrap_or_else(|e| e.into_inner());
                if last.as_deref() != Some(why.as_str()) {
                    main_thread.warn(&why);
                    *last = Some(why);
                }
                (None, 0)
            }
        };
        shared.latency_frames.store(latency, Ordering::Relaxed);
        shared.rebuild.activated(config.sample_rate);
        let tail = match engine.as_ref().map(|e| e.ring_out_s() * config.sample_rate) {
            None => TailLength::Finite(0),
            Some(frames) if frames < f64::from(i32::MAX) => TailLength::Finite(frames as u32),
            Some(_) => TailLength::Infinite,
        };
        // Silence is written to both channels of the port.
        let channels = engine.as_ref().map_or(2, Engine::channels);
        shared.pool.start_over();
        let thread_pool = host.get_extension::<HostThreadPool>();
        Ok(Processor {
            shared,
            host,
            engine,
            channels,
            scratch: vec![0.0; SCRATCH_FRAMES * channels],
            pedals: [0.0; 3],
            gain: db_to_gain(values.get(GAIN_DB)),
            tail,
            built,
            rebuild: Rebuilding::No,
            thread_pool,
            midi: Decoder::default(),
        })
    }

    fn deactivate(self, main_thread: &MainThread<'a>) {
        self.shared.rebuild.deactivated();
        // Inactive, the port may follow the keyboard's channels (in the callback, once the host
        // has finished deactivating).
        main_thread.ask_to_follow_ports();
    }

    fn process(
        &mut self,
        _process: Process,
        mut audio: Audio,
        events: Events,
    ) -> Result<ProcessStatus, PluginError> {
        let frames = audio.frames_count() as usize;
        // Without an output port or with one of 64-bit samples there is nothing to write into
        // (an error here would have clack format a message on the audio thread).
        let Some(mut port) = audio.output_port(0) else {
            return Ok(ProcessStatus::Continue);
        };
        let Some(mut out) = port.channels().ok().and_then(|c| c.into_f32()) else {
            return Ok(ProcessStatus::Continue);
        };
        self.settle_pedals();
        let mut at = 0;
        for event in events.input {
            let time = (event.header().time() as usize).clamp(at, frames);
            self.render(&mut out, at..time);
            at = time;
            self.handle(event);
        }
        self.render(&mut out, at..frames);
        self.follow_rebuild();
        let silent = self.engine.as_ref().is_none_or(|e| e.is_silent());
        // While a piano is built the host keeps calling, so that the restart is asked for when
        // it is ready.
        let building = matches!(self.rebuild, Rebuilding::Building(..));
        Ok(if silent && !building {
            ProcessStatus::Sleep
        } else {
            ProcessStatus::Continue
        })
    }

    fn reset(&mut self) {
        if let Some(engine) = &mut self.engine {
            engine.silence();
        }
        self.pedals = [0.0; 3];
    }
}

/// The engine of a prepared piano: its synth realigned to the host's blocks, and the latency to
/// report (host frames).
fn start(prepared: crate::prepare::Prepared) -> Result<(Engine, u32), String> {
    let (settings, channels) = (prepared.settings, usize::from(prepared.settings.channels));
    Ok(match prepared.piano {
        Pianos::Exact(piano) => {
            let (aligned, latency) = aligned(*piano, settings, channels)?;
            (Engine::Exact(aligned), latency)
        }
        Pianos::Rk4(piano) => {
            let (aligned, latency) = aligned(*piano, settings, channels)?;
            (Engine::Rk4(aligned), latency)
        }
    })
}

fn aligned<E: VoicePool>(
    piano: unacorda::play::Piano<E>,
    settings: unacorda::config::output::OutputSettings,
    channels: usize,
) -> Result<(Aligned<E>, u32), String> {
    let (mut synth, handle) =
        Synth::new(piano, settings, EVENT_QUEUE).map_err(|e| format!("unacorda: {e}"))?;
    if std::thread::available_parallelism().is_ok_and(|n| n.get() >= 2) {
        // The helper thread lends the engine a second core; without it, one core.
        let _ = synth.use_second_core();
        synth.ask_real_time_priority();
    }
    let latency = LATENCY_FRAMES as f64 + synth.decimation_delay_frames();
    Ok((
        Aligned::new(synth, handle, channels),
        latency.round() as u32,
    ))
}

fn db_to_gain(db: f64) -> f32 {
    10f64.powf(db / 20.0) as f32
}

impl Processor<'_> {
    /// Play the pedal parameters that changed since they were last played (an automation event,
    /// or a state load on the main thread).
    fn settle_pedals(&mut self) {
        for (i, &(index, pedal)) in PEDALS.iter().enumerate() {
            let depth = self.shared.values.get(index);
            if depth != self.pedals[i] {
                self.pedals[i] = depth;
                self.play(Event::Pedal { pedal, depth });
            }
        }
    }

    fn play(&mut self, event: Event) {
        if let Some(engine) = &mut self.engine {
            engine.schedule(event);
        }
    }

    /// Apply one host event at the next frame.
    pub(crate) fn handle(&mut self, event: &UnknownEvent) {
        let curve = self.shared.values.get(VELOCITY_CURVE);
        let note = |key: Match<u16>| match key {
            Match::Specific(k) => u8::try_from(k).ok().filter(|k| *k < 128),
            Match::All => None,
        };
        let event = match event.as_core_event() {
            // CLAP's velocity 0–1 onto MIDI's 1–127, unrounded; 0 is the softest strike, not a
            // release.
            Some(CoreEventSpace::NoteOn(e)) => note(e.pckn().key).map(|note| Event::NoteOn {
                note,
                velocity: curved_velocity((e.velocity() * 127.0).clamp(1.0, 127.0), curve),
            }),
            // CLAP's release velocity, 0-1, on MIDI's scale (0, a host that has none, is MIDI's
            // default).
            Some(CoreEventSpace::NoteOff(e)) => Some(match note(e.pckn().key) {
                Some(note) => Event::NoteOff {
                    note,
                    velocity: (e.velocity() * 127.0).min(127.0),
                },
                None => Event::AllNotesOff,
            }),
            // A choke stops the note at once: its damper falls as fast as a key lets it (every
            // damper for a wildcard).
            Some(CoreEventSpace::NoteChoke(e)) => Some(match note(e.pckn().key) {
                Some(note) => Event::NoteOff {
                    note,
                    velocity: 127.0,
                },
                None => Event::AllSoundOff,
            }),
            Some(CoreEventSpace::Midi(e)) => {
                let [status, data1, data2] = e.data();
                self.midi
                    .decode(status, data1, data2)
                    .map(|e| e.with_velocity_curve(curve))
            }
            Some(CoreEventSpace::ParamValue(e)) => {
                let index = e
                    .param_id()
                    .and_then(|id| crate::params::index_of(id.get()));
                if let Some(index) = index.filter(|_| e.pckn().matches_all()) {
                    self.set_param(index, e.value());
                }
                None
            }
            _ => None,
        };
        if let Some(event) = event {
            self.play(event);
        }
    }

    /// A parameter's new value: a pedal's is played at once (a keyboard's or pool size's is
    /// followed at the end of the block: [`Self::follow_rebuild`]).
    fn set_param(&mut self, index: usize, value: f64) {
        self.shared.values.set(index, value);
        self.settle_pedals();
    }

    /// Follow a change of keyboard, pool size, integrator, halo or render mode (by automation, a
    /// state load or the host): ask the main thread to build it in the background, and once it
    /// is built ask the host to restart the plugin (whose activation then finds it built). A
    /// change during the build supersedes it: the build is called off and the newer one asked
    /// for. Never allocates.
    pub(crate) fn follow_rebuild(&mut self) {
        let wanted = self.shared.played();
        match self.rebuild {
            Rebuilding::No if wanted != self.built => self.ask_build(wanted),
            Rebuilding::Building(asked, _) if wanted != asked => {
                if wanted == self.built {
                    // Changed back while it was built.
                    self.shared.rebuild.call_off();
                    self.rebuild = Rebuilding::No;
                } else {
                    self.ask_build(wanted);
                }
            }
            Rebuilding::Building(_, request) if self.shared.rebuild.finished(request) => {
                self.rebuild = Rebuilding::Restarting;
                self.host.request_restart();
            }
            _ => {}
        }
    }

    fn ask_build(&mut self, values: [f64; REBUILDS.len()]) {
        self.rebuild = Rebuilding::Building(values, self.shared.rebuild.ask());
        self.host.request_callback();
    }

    /// Frames `range` of the host's block: rendered, the gain applied, written to every channel.
    fn render(
        &mut self,
        out: &mut clack_plugin::process::audio::OutputChannels<f32>,
        range: std::ops::Range<usize>,
    ) {
        let target = db_to_gain(self.shared.values.get(GAIN_DB));
        let ch = self.channels;
        let host_channels = out.channel_count();
        // The host's pool lends the second core while it runs the two halves at once; from a
        // host that runs its tasks one after another the helper thread takes over.
        let host = std::cell::RefCell::new(&mut self.host);
        let pair = self.thread_pool.map(|pool| HostPool {
            rendezvous: &self.shared.pool,
            // A refused request runs no task: the rendezvous says the block was not split.
            request: move || {
                let _ = pool.request_exec(&mut host.borrow_mut(), 2);
            },
        });
        let pair = pair.as_ref().map(|p| p as &dyn Pair);
        let mut start = range.start;
        while start < range.end {
            let n = (range.end - start).min(SCRATCH_FRAMES);
            let scratch = &mut self.scratch[..n * ch];
            match &mut self.engine {
                Some(engine) => engine.process(scratch, pair),
                None => scratch.fill(0.0),
            }
            let mut gain = self.gain;
            for frame in scratch.chunks_exact_mut(ch) {
                gain += (target - gain) * GAIN_SMOOTHING;
                frame.iter_mut().for_each(|s| *s *= gain);
            }
            self.gain = gain;
            for c in 0..host_channels {
                let Some(dest) = out.channel_mut(c) else {
                    continue;
                };
                let Some(dest) = dest.get_mut(start..start + n) else {
                    continue;
                };
                let source = c as usize;
                for (d, frame) in dest.iter_mut().zip(scratch.chunks_exact(ch)) {
                    *d = match (host_channels, ch) {
                        // A mono host port hears both channels.
                        (1, 2) => 0.5 * (frame[0] + frame[1]),
                        _ if source < 2 => frame[source.min(ch - 1)],
                        _ => 0.0,
                    };
                }
            }
            start += n;
        }
    }
}

impl clack_extensions::tail::PluginTailImpl for Processor<'_> {
    fn get(&self) -> TailLength {
        self.tail
    }
}
