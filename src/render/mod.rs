//! From a preset and a strike to frames at the output rate: forces (Eq. 19) and radiated sound.
//!
//! The [`Renderer`] advances the [`Instrument`] at the internal rate, reads the outputs after each step,
//! turns the board's net volume velocity into pressure at the listener (a monopole,
//! `p = rho0 / (4 pi r) dQ/dt`, DESIGN.md §1.7) and decimates every channel through the same
//! anti-alias filter to the output rate.

use crate::audio::Decimator;
use crate::config::preset::LoadedPreset;
use crate::engine::etd::ExponentialUnison;
use crate::engine::MAX_STRINGS;
use crate::engine::{BuildError, Instrument, Observation, Strike};
use crate::engine::{Engine, Integrator};
use std::ops::ControlFlow;

/// Number of decimated channels: hammer (3), bridge (3 × 3), total (3), bridge velocity (3), pressure.
const CHANNELS: usize = MAX_STRINGS + 3 * MAX_STRINGS + 3 + 3 + 1;

/// One output-rate frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Frame {
    /// Forces and velocities at the bridge and hammer (Eq. 19), low-passed with the audio.
    pub obs: Observation,
    /// Sound pressure at the listener (Pa).
    pub pressure_pa: f64,
}

impl Frame {
    fn pack(&self, out: &mut [f64; CHANNELS]) {
        let o = &self.obs;
        let flat = o
            .hammer_force_n
            .iter()
            .chain(o.bridge_force_n.iter().flatten())
            .chain(&o.total_force_n)
            .chain(&o.bridge_velocity_m_s)
            .chain(std::iter::once(&self.pressure_pa));
        for (slot, v) in out.iter_mut().zip(flat) {
            *slot = *v;
        }
    }

    fn unpack(ch: &[f64; CHANNELS]) -> Frame {
        let mut f = Frame::default();
        let mut it = ch.iter().copied();
        let mut next = || it.next().unwrap_or(0.0);
        f.obs.hammer_force_n.iter_mut().for_each(|x| *x = next());
        f.obs
            .bridge_force_n
            .iter_mut()
            .flatten()
            .for_each(|x| *x = next());
        f.obs.total_force_n.iter_mut().for_each(|x| *x = next());
        f.obs
            .bridge_velocity_m_s
            .iter_mut()
            .for_each(|x| *x = next());
        f.pressure_pa = next();
        f
    }
}

/// An engine (by default the RK4 [`Instrument`]) and its output stage, with analysis channels
/// (forces of voice 0).
pub struct Renderer<E: Engine = Instrument> {
    instrument: E,
    decimator: Decimator,
    /// `rho0 / (4 pi r)` (kg/m^4).
    monopole: f64,
    last_volume_velocity: f64,
    output_rate_hz: f64,
    inputs: [f64; CHANNELS],
    outputs: [f64; CHANNELS],
}

impl Renderer {
    pub fn new(preset: &LoadedPreset) -> Result<Renderer, BuildError> {
        let spec = preset.unison_spec();
        let instrument = Instrument::new(&spec)?;
        Ok(Self::from_instrument(instrument, preset))
    }
}

impl Renderer<ExponentialUnison> {
    /// The preset's key on the live integrator, stepping at the output rate.
    pub fn exponential(preset: &LoadedPreset) -> Result<Self, BuildError> {
        let mut spec = preset.unison_spec();
        spec.sample_rate_hz = preset.output_rate_hz();
        Ok(Self::from_instrument(
            ExponentialUnison::new(&spec)?,
            preset,
        ))
    }
}

impl<E: Engine> Renderer<E> {
    /// The output stage of `preset` (rates, radiation) around a built system; the analysis
    /// channels follow its first voice.
    pub fn from_instrument(instrument: E, preset: &LoadedPreset) -> Renderer<E> {
        let ratio = (preset.output_rate_hz() * instrument.step_s())
            .recip()
            .round() as usize;
        let r = &preset.preset.radiation;
        Renderer {
            instrument,
            decimator: Decimator::new(ratio, CHANNELS),
            monopole: r.air_density_kg_m3 / (4.0 * std::f64::consts::PI * r.distance_m),
            last_volume_velocity: 0.0,
            output_rate_hz: preset.output_rate_hz(),
            inputs: [0.0; CHANNELS],
            outputs: [0.0; CHANNELS],
        }
    }

    pub fn instrument(&self) -> &E {
        &self.instrument
    }

    pub fn instrument_mut(&mut self) -> &mut E {
        &mut self.instrument
    }

    pub fn output_rate_hz(&self) -> f64 {
        self.output_rate_hz
    }

    /// Internal steps per output frame.
    pub fn oversampling(&self) -> usize {
        self.decimator.ratio()
    }

    /// Delay of the anti-alias filter (output samples).
    pub fn filter_delay_samples(&self) -> f64 {
        self.decimator.delay_out_samples()
    }

    pub fn strike(&mut self, strike: Strike) {
        self.instrument.strike(strike);
    }

    /// Advance by one output frame.
    pub fn next_frame(&mut self) -> Frame {
        let fs_int = 1.0 / self.instrument.step_s();
        loop {
            self.instrument.step();
            let obs = self.instrument.observe();
            let dq = (obs.volume_velocity_m3_s - self.last_volume_velocity) * fs_int;
            self.last_volume_velocity = obs.volume_velocity_m3_s;
            Frame {
                obs,
                pressure_pa: self.monopole * dq,
            }
            .pack(&mut self.inputs);
            if self.decimator.push(&self.inputs, &mut self.outputs) {
                return Frame::unpack(&self.outputs);
            }
        }
    }
}

/// A whole offline simulation at the output rate.
#[derive(Debug, Clone)]
pub struct Recording {
    pub rate_hz: f64,
    /// Group delay of the anti-alias filter (s): frame `k` shows the system at `k / rate_hz - delay_s`.
    pub delay_s: f64,
    pub frames: Vec<Frame>,
}

impl Recording {
    /// Physical time of frame `k` (s), the filter delay removed.
    pub fn time_s(&self, k: usize) -> f64 {
        k as f64 / self.rate_hz - self.delay_s
    }

    /// One channel of the recording, extracted by `f`.
    pub fn channel(&self, f: impl Fn(&Frame) -> f64) -> Vec<f64> {
        self.frames.iter().map(f).collect()
    }
}

/// Strike the preset's unison, release the key after `release_s` (the damper drops; `None` holds
/// the key) and record `seconds` of output with RK4; `progress` receives the fraction done.
pub fn simulate(
    preset: &LoadedPreset,
    strike: Strike,
    release_s: Option<f64>,
    seconds: f64,
    progress: impl FnMut(f64),
) -> Result<Recording, BuildError> {
    simulate_with(
        preset,
        Integrator::Rk4,
        strike,
        release_s,
        seconds,
        progress,
    )
}

/// [`simulate`] with the chosen integrator.
pub fn simulate_with(
    preset: &LoadedPreset,
    integrator: Integrator,
    strike: Strike,
    release_s: Option<f64>,
    seconds: f64,
    progress: impl FnMut(f64),
) -> Result<Recording, BuildError> {
    match integrator {
        Integrator::Rk4 => record(Renderer::new(preset)?, strike, release_s, seconds, progress),
        Integrator::Exponential => record(
            Renderer::exponential(preset)?,
            strike,
            release_s,
            seconds,
            progress,
        ),
    }
}

fn record<E: Engine>(
    mut r: Renderer<E>,
    strike: Strike,
    release_s: Option<f64>,
    seconds: f64,
    mut progress: impl FnMut(f64),
) -> Result<Recording, BuildError> {
    r.strike(strike);
    let n = (seconds * r.output_rate_hz()).round() as usize;
    let release_frame = release_s.map(|s| (s * r.output_rate_hz()).round() as usize);
    let mut frames = Vec::with_capacity(n);
    let every = (r.output_rate_hz() as usize / 20).max(1);
    for k in 0..n {
        if Some(k) == release_frame {
            r.instrument_mut().set_damper(true);
        }
        frames.push(r.next_frame());
        if k % every == 0 {
            progress(k as f64 / n as f64);
        }
    }
    progress(1.0);
    Ok(Recording {
        rate_hz: r.output_rate_hz(),
        delay_s: r.filter_delay_samples() / r.output_rate_hz(),
        frames,
    })
}

/// Why a MIDI performance cannot be rendered.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error(transparent)]
    Preset(#[from] crate::config::preset::PresetError),
    #[error(transparent)]
    Build(#[from] BuildError),
    #[error(transparent)]
    Piano(#[from] crate::play::PianoError),
    #[error(transparent)]
    Synth(#[from] crate::audio::synth::SynthError),
    #[error("the MIDI file plays no key of the piano (notes 21–108)")]
    NoKeys,
    #[error("the voice pool needs 1 to {max} voices, got {0}", max = crate::play::MAX_VOICES)]
    Voices(usize),
}

/// A MIDI performance rendered offline, its sound in memory.
#[derive(Debug, Clone)]
pub struct Performance {
    pub rate_hz: f64,
    /// Sound pressure normalised to full scale, one channel.
    pub samples: Vec<f32>,
    /// The piano keys (1–88) the file plays.
    pub keys: Vec<usize>,
    /// Size of the voice pool used.
    pub voices: usize,
}

/// What [`render_midi_into`] rendered.
#[derive(Debug, Clone)]
pub struct Rendered {
    pub rate_hz: f64,
    /// Frames handed to the sink, and the frames the whole performance lasts.
    pub frames: u64,
    pub total_frames: u64,
    /// The piano keys (1–88) the file plays.
    pub keys: Vec<usize>,
    /// Size of the voice pool used.
    pub voices: usize,
}

/// Output frames per block of the offline render (the live block sizes give the same samples:
/// events are applied at their own frame whatever the block).
pub const OFFLINE_BLOCK: usize = 256;

/// Render a MIDI performance on the keyboard `scaling` through the live engine's path: every key
/// the file plays in the bank, a pool of at most `voices` voices on one soundboard, events queued
/// with their output frame and applied by the [`crate::audio::Synth`] block by block, and `tail_s`
/// of sound after the last event.
pub fn render_midi(
    scaling: &crate::config::scaling::LoadedScaling,
    events: &[crate::midi::file::TimedEvent],
    tail_s: f64,
    voices: usize,
    progress: impl FnMut(f64),
) -> Result<Performance, RenderError> {
    render_midi_with(scaling, events, tail_s, voices, progress, |_, _| {})
}

/// [`render_midi`], with `tap(instrument, frame)` called after every output frame.
pub fn render_midi_with(
    scaling: &crate::config::scaling::LoadedScaling,
    events: &[crate::midi::file::TimedEvent],
    tail_s: f64,
    voices: usize,
    progress: impl FnMut(f64),
    tap: impl FnMut(&Instrument, u64),
) -> Result<Performance, RenderError> {
    let mut samples = Vec::new();
    let r =
        render_midi_into::<Instrument>(scaling, events, tail_s, voices, progress, tap, |block| {
            samples.extend_from_slice(block);
            ControlFlow::Continue(())
        })?;
    Ok(Performance {
        rate_hz: r.rate_hz,
        samples,
        keys: r.keys,
        voices: r.voices,
    })
}

/// [`render_midi_with`] on the engine `E` (RK4 [`Instrument`] or the live integrator,
/// [`crate::engine::etd::ExponentialInstrument`]), handing each block of samples to `sink`
/// as it is made (a WAV being written) instead of keeping them; the render stops early when
/// `sink` breaks (interrupted, or the disk is full).
pub fn render_midi_into<E: crate::engine::VoicePool>(
    scaling: &crate::config::scaling::LoadedScaling,
    events: &[crate::midi::file::TimedEvent],
    tail_s: f64,
    voices: usize,
    mut progress: impl FnMut(f64),
    mut tap: impl FnMut(&E, u64),
    mut sink: impl FnMut(&[f32]) -> ControlFlow<()>,
) -> Result<Rendered, RenderError> {
    use crate::audio::synth::{Synth, EVENT_QUEUE};
    use crate::midi::{piano_key, Event};
    if !(1..=crate::play::MAX_VOICES).contains(&voices) {
        return Err(RenderError::Voices(voices));
    }
    let mut keys: Vec<usize> = events
        .iter()
        .filter_map(|e| match e.event {
            Event::NoteOn { note, .. } => piano_key(note),
            _ => None,
        })
        .collect();
    keys.sort_unstable();
    keys.dedup();
    if keys.is_empty() {
        return Err(RenderError::NoKeys);
    }
    let voices = voices.min(keys.len());
    let piano = crate::play::Piano::<E>::build(scaling, &keys, voices)?;
    let settings = scaling.base.output_settings();
    let fs = settings.rate_hz;
    let (mut synth, mut handle) = Synth::new(piano, settings, EVENT_QUEUE)?;
    let end_s = events.last().map_or(0.0, |e| e.time_s) + tail_s;
    let total_frames = (end_s * fs).round() as u64;
    let n_blocks = total_frames.div_ceil(OFFLINE_BLOCK as u64).max(1);
    let mut block = [0f32; OFFLINE_BLOCK];
    let (mut next, mut frames) = (0, 0u64);
    for b in 0..n_blocks {
        let n = (total_frames - frames).min(OFFLINE_BLOCK as u64) as usize;
        next = handle.schedule_timed(events, next, 0);
        synth.process_with(&mut block[..n], 1, &mut tap);
        frames += n as u64;
        if sink(&block[..n]).is_break() {
            break;
        }
        if b % 64 == 0 {
            progress(b as f64 / n_blocks as f64);
        }
    }
    progress(1.0);
    Ok(Rendered {
        rate_hz: fs,
        frames,
        total_frames,
        keys,
        voices,
    })
}
