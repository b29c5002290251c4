//! What both plugin formats play, whatever their host's calls: an activation's synth on either
//! engine realigned to the host's blocks ([`Engine`], [`activate`]), the pedal parameters
//! followed ([`Pedals`]), and the output stage ([`Output`]: the gain smoothed, the engine's
//! channels written to the host's). The CLAP processor ([`crate::processor`]) and the VST3
//! component ([`crate::vst3`]) differ only in how events, parameters and buffers reach these.

use crate::params::{Values, GAIN_DB, SOFT, SOSTENUTO, SUSTAIN};
use crate::prepare::{Pianos, Prepared};
use std::sync::Mutex;
use unacorda::audio::activity::Activity;
use unacorda::audio::aligned::LATENCY_FRAMES;
use unacorda::audio::synth::EVENT_QUEUE;
use unacorda::audio::{Aligned, Synth};
use unacorda::engine::exact::ExactPool;
use unacorda::engine::{Integrator, Pair, Rk4Pool, VoicePool};
use unacorda::midi::{Event, Pedal};

/// The ring-out the tail reports: how long the slowest mode takes to fall this far (dB), from a
/// fortissimo's level to below the 24-bit floor.
pub const TAIL_FALL_DB: f64 = 120.0;

/// What the host is told when RK4 is chosen and it plays live.
pub const RK4_LIVE: &str = "unacorda: the RK4 integrator (the paper's reference) plays in offline renders only: it takes longer than real time for a single voice. Live, the exact engine plays.";

/// Frames rendered at a time into the interleaved scratch buffer.
pub const SCRATCH_FRAMES: usize = 256;

/// The output gain's smoothing: the gain moves this fraction of the way to its target each
/// frame (a time constant of ~5 ms at 48 kHz), so automating it never clicks.
const GAIN_SMOOTHING: f32 = 0.004;

/// The synth on either engine, realigned to the host's blocks.
pub enum Engine {
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
    pub fn channels(&self) -> usize {
        on_engine!(self, e => e.channels())
    }
    pub fn schedule(&mut self, event: Event) {
        on_engine!(self, e => {
            e.schedule(event);
        })
    }
    pub fn process(&mut self, out: &mut [f32], pair: Option<&dyn Pair>) {
        on_engine!(self, e => e.process_on(out, pair))
    }
    pub fn is_silent(&self) -> bool {
        on_engine!(self, e => e.is_silent())
    }
    pub fn silence(&mut self) {
        on_engine!(self, e => e.silence())
    }
    /// Publish what the piano is doing for the editor (audio thread).
    pub fn publish(&self, activity: &Activity) {
        on_engine!(self, e => activity.publish(e.synth().piano()))
    }
    /// How long the slowest mode takes to fall [`TAIL_FALL_DB`] (s): the exact engine's modes
    /// say; RK4 has none to ask, and its tail is reported infinite (the plugin sleeps when
    /// silent).
    pub fn ring_out_s(&self) -> f64 {
        match self {
            Engine::Exact(e) => e.synth().piano().instrument.ring_out_s(TAIL_FALL_DB),
            Engine::Rk4(_) => f64::INFINITY,
        }
    }
}

/// An activation's engine (none when it could not be built: it plays silence), the latency it
/// reports (host frames) and its tail (host frames; `None`: infinite).
pub struct Activation {
    pub engine: Option<Engine>,
    pub latency_frames: u32,
    pub tail_frames: Option<u32>,
}

/// The engine `values` ask for at `rate_hz` on `integrator` (the integrator as played). Never
/// fails: what cannot be built plays silence and says why through `warn`, once per reason
/// (`silent_because` keeps the last).
pub fn activate(
    values: &Values,
    rate_hz: f64,
    integrator: Integrator,
    silent_because: &Mutex<Option<String>>,
    warn: &dyn Fn(&str),
) -> Activation {
    if values.integrator() != integrator {
        warn(RK4_LIVE);
    }
    let prepared = crate::prepare::prepare(values.keyboard(), rate_hz, values.voices(), integrator)
        .map(|prepared| prepared.with_halo(values.halo()));
    for warning in crate::prepare::take_warnings() {
        warn(&warning);
    }
    let started = prepared.and_then(start);
    let mut last = silent_because.lock().unwrap_or_else(|e| e.into_inner());
    let (engine, latency_frames) = match started {
        Ok((engine, latency)) => {
            *last = None;
            (Some(engine), latency)
        }
        Err(why) => {
            if last.as_deref() != Some(why.as_str()) {
                warn(&why);
                *last = Some(why);
            }
            (None, 0)
        }
    };
    let tail_frames = match engine.as_ref().map(|e| e.ring_out_s() * rate_hz) {
        None => Some(0),
        Some(frames) if frames < f64::from(i32::MAX) => Some(frames as u32),
        Some(_) => None,
    };
    Activation {
        engine,
        latency_frames,
        tail_frames,
    }
}

/// The engine of a prepared piano: its synth realigned to the host's blocks, and the latency to
/// report (host frames).
fn start(prepared: Prepared) -> Result<(Engine, u32), String> {
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

pub fn db_to_gain(db: f64) -> f32 {
    10f64.powf(db / 20.0) as f32
}

/// The pedal parameters and the pedals they move.
const PEDALS: [(usize, Pedal); 3] = [
    (SUSTAIN, Pedal::Sustain),
    (SOSTENUTO, Pedal::Sostenuto),
    (SOFT, Pedal::Soft),
];

/// The pedal parameters as last played (audio thread): a value changed by automation, a state
/// load or an editor is played at the next look.
#[derive(Debug, Default)]
pub struct Pedals([f64; 3]);

impl Pedals {
    /// The pedals' events for the values that changed since the last call, played on `engine`.
    pub fn settle(&mut self, values: &Values, engine: Option<&mut Engine>) {
        let mut engine = engine;
        for (i, &(index, pedal)) in PEDALS.iter().enumerate() {
            let depth = values.get(index);
            if depth != self.0[i] {
                self.0[i] = depth;
                if let Some(engine) = engine.as_deref_mut() {
                    engine.schedule(Event::Pedal { pedal, depth });
                }
            }
        }
    }

    /// Every pedal as up (after a reset that silenced the engine).
    pub fn lift(&mut self) {
        self.0 = [0.0; 3];
    }
}

/// The output stage (audio thread): the engine's frames rendered into an interleaved scratch
/// buffer, the gain smoothed toward the parameter's, then written to the host's channels.
pub struct Output {
    /// Channels the engine renders (1 or 2).
    channels: usize,
    scratch: Vec<f32>,
    /// The gain applied to the last frame (linear).
    gain: f32,
}

impl Output {
    /// For `engine` (two channels of silence without one), the gain starting at `values`'.
    pub fn new(engine: Option<&Engine>, values: &Values) -> Output {
        let channels = engine.map_or(2, Engine::channels);
        Output {
            channels,
            scratch: vec![0.0; SCRATCH_FRAMES * channels],
            gain: db_to_gain(values.get(GAIN_DB)),
        }
    }

    /// The next `frames` frames (at most [`SCRATCH_FRAMES`]) of `engine` (silence without
    /// one), the gain applied: interleaved, [`Output::channels`] to a frame. Never allocates.
    pub fn render(
        &mut self,
        engine: Option<&mut Engine>,
        values: &Values,
        frames: usize,
        pair: Option<&dyn Pair>,
    ) -> &[f32] {
        let target = db_to_gain(values.get(GAIN_DB));
        let scratch = &mut self.scratch[..frames * self.channels];
        match engine {
            Some(engine) => engine.process(scratch, pair),
            None => scratch.fill(0.0),
        }
        let mut gain = self.gain;
        for frame in scratch.chunks_exact_mut(self.channels) {
            gain += (target - gain) * GAIN_SMOOTHING;
            frame.iter_mut().for_each(|s| *s *= gain);
        }
        self.gain = gain;
        scratch
    }

    /// The channels the engine renders.
    pub fn channels(&self) -> usize {
        self.channels
    }
}

/// Host channel `c` of `host_channels` from `frames` rendered with `ch` channels (as
/// [`Output::render`] gave them): a mono host hears both of a stereo engine's channels, a stereo
/// host both channels of a mono engine, a host's third channel and on silence.
pub fn write(frames: &[f32], ch: usize, c: usize, host_channels: usize, dest: &mut [f32]) {
    for (d, frame) in dest.iter_mut().zip(frames.chunks_exact(ch)) {
        *d = match (host_channels, ch) {
            (1, 2) => 0.5 * (frame[0] + frame[1]),
            _ if c < 2 => frame[c.min(ch - 1)],
            _ => 0.0,
        };
    }
}
