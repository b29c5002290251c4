//! The CLAP audio thread's side: notes, MIDI and parameter changes applied at their frame to the
//! synth ([`crate::sound`]), sleep when nothing sounds, and a change of keyboard or pool size
//! built in the background. Never allocates, locks or prints in `process` (the plugin's tests
//! run it under `assert_no_alloc`).

use crate::params::{PARAMS, REBUILDS, VELOCITY_CURVE};
use crate::sound::{Engine, Output, Pedals, SCRATCH_FRAMES};
use crate::{MainThread, Shared};
use clack_extensions::tail::TailLength;
use clack_extensions::thread_pool::HostThreadPool;
use clack_plugin::events::event_types::ParamValueEvent;
use clack_plugin::events::spaces::CoreEventSpace;
use clack_plugin::events::{Match, Pckn};
use clack_plugin::prelude::*;
use std::sync::atomic::Ordering;
use unacorda::audio::host_pool::HostPool;
use unacorda::engine::Pair;
use unacorda::midi::{curved_velocity, Decoder, Event};

/// An active instance's audio side (audio thread).
pub struct Processor<'a> {
    shared: &'a Shared,
    host: HostAudioProcessorHandle<'a>,
    /// The synth, or none when the activation could not build one (it plays silence).
    engine: Option<Engine>,
    /// The output stage: the gain, the engine's channels to the port's.
    output: Output,
    /// The pedal parameters as last played (a state load changes them behind the processor).
    pedals: Pedals,
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
    /// The host's rate (Hz), for the callback's load.
    rate_hz: f64,
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

impl<'a> PluginAudioProcessor<'a, Shared, MainThread<'a>> for Processor<'a> {
    fn activate(
        host: HostAudioProcessorHandle<'a>,
        main_thread: &MainThread<'a>,
        shared: &'a Shared,
        config: PluginAudioConfiguration,
    ) -> Result<Self, PluginError> {
        let values = &shared.values;
        let built = shared.played();
        let activation = crate::sound::activate(
            values,
            config.sample_rate,
            shared.integrator(),
            &shared.silent_because,
            &|message| main_thread.warn(message),
        );
        shared
            .latency_frames
            .store(activation.latency_frames, Ordering::Relaxed);
        shared.rebuild.activated(config.sample_rate);
        let tail = activation
            .tail_frames
            .map_or(TailLength::Infinite, TailLength::Finite);
        let engine = activation.engine;
        shared.pool.start_over();
        let thread_pool = host.get_extension::<HostThreadPool>();
        Ok(Processor {
            shared,
            host,
            output: Output::new(engine.as_ref(), values),
            engine,
            pedals: Pedals::default(),
            tail,
            built,
            rebuild: Rebuilding::No,
            thread_pool,
            midi: Decoder::default(),
            rate_hz: config.sample_rate,
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
        // The editor's figures are worked out only while an editor shows them.
        let started = self
            .shared
            .activity
            .is_watched()
            .then(std::time::Instant::now);
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
        self.tell_edits(events.output);
        self.follow_rebuild();
        if let Some(started) = started {
            if let Some(engine) = &self.engine {
                engine.publish(&self.shared.activity);
            }
            self.shared.activity.publish_load(
                started.elapsed().as_secs_f64(),
                frames as f64 / self.rate_hz,
            );
        }
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
        self.pedals.lift();
    }
}

impl Processor<'_> {
    /// Play the pedal parameters that changed since they were last played (an automation event,
    /// or a state load on the main thread).
    fn settle_pedals(&mut self) {
        self.pedals
            .settle(&self.shared.values, self.engine.as_mut());
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

    /// Tell the host of the parameters the editor changed (as the host's own changes, they are
    /// already played: a pedal at the next block, a rebuild followed). Never allocates.
    pub(crate) fn tell_edits(&mut self, output: &mut OutputEvents) {
        for (i, p) in PARAMS.iter().enumerate() {
            if self.shared.edits.take(i) {
                let value = self.shared.values.get(i);
                let event = ParamValueEvent::new(0, ClapId::new(p.id), Pckn::match_all(), value);
                let _ = output.try_push(event);
            }
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
        let host_channels = out.channel_count() as usize;
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
            let ch = self.output.channels();
            let frames = self
                .output
                .render(self.engine.as_mut(), &self.shared.values, n, pair);
            for c in 0..host_channels {
                if let Some(dest) = out
                    .channel_mut(c as u32)
                    .and_then(|d| d.get_mut(start..start + n))
                {
                    crate::sound::write(frames, ch, c, host_channels, dest);
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
