//! A MIDI performance rendered offline through exactly the live engine's path: the file's events
//! go through the synth's event queue at their output frames and the audio engine renders block
//! by block, so the result is what `play` would sound, sample for sample.

use crate::engine::{BuildError, Rk4Pool};
use std::ops::ControlFlow;

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
    #[error("could not start the second core's thread: {0}")]
    Helper(std::io::Error),
}

/// A MIDI performance rendered offline, its sound in memory.
#[derive(Debug, Clone)]
pub struct Performance {
    pub rate_hz: f64,
    /// Channels of the sound: 1, or 2 for a keyboard heard in stereo.
    pub channels: u16,
    /// Sound pressure normalised to full scale, the channels interleaved.
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
    /// Channels of the sound the sink was handed (interleaved): 1, or 2 for a stereo keyboard.
    pub channels: u16,
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
    tap: impl FnMut(&Rk4Pool, u64),
) -> Result<Performance, RenderError> {
    let mut tap = tap;
    render_midi_kept::<Rk4Pool>(
        crate::play::Keyboard {
            scaling,
            cache: None,
        },
        events,
        Offline {
            tail_s,
            voices,
            cores: 1,
            halo: false,
        },
        progress,
        Some(&mut tap),
    )
}

/// [`render_midi_into`] with the whole performance kept in memory, on the engine `E`.
pub fn render_midi_kept<E: crate::engine::VoicePool>(
    keyboard: crate::play::Keyboard<'_>,
    events: &[crate::midi::file::TimedEvent],
    offline: Offline,
    progress: impl FnMut(f64),
    tap: Option<Tap<'_, E>>,
) -> Result<Performance, RenderError> {
    let mut samples = Vec::new();
    let r = render_midi_into::<E>(keyboard, events, offline, progress, tap, |block| {
        samples.extend_from_slice(block);
        ControlFlow::Continue(())
    })?;
    Ok(Performance {
        rate_hz: r.rate_hz,
        channels: r.channels,
        samples,
        keys: r.keys,
        voices: r.voices,
    })
}

/// What a render calls after every output frame: `tap(instrument, frame)`.
pub type Tap<'a, E> = &'a mut dyn FnMut(&E, u64);

/// How an offline render runs: seconds of sound after the last event, the voice pool's size, the
/// cores the engine may use (1, or 2 with a helper thread, as `play`'s callback), and whether
/// the pedal has its halo.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Offline {
    pub tail_s: f64,
    pub voices: usize,
    pub cores: usize,
    /// The pedal's halo ([`crate::play::Player::set_halo`]): every key of the keyboard is
    /// built and, under the sustain pedal, rings in sympathy (the pool then holds at least
    /// [`crate::play::HALO_VOICES`]).
    pub halo: bool,
}

/// A MIDI performance on the engine `E` (RK4 [`Rk4Pool`] or the exact engine
/// [`crate::engine::exact::ExactPool`]), handing each block of samples (in the keyboard's
/// channels, interleaved: [`Rendered::channels`]) to `sink`
/// as it is made (a WAV being written) instead of keeping them, the prepared keys read from and
/// kept in the keyboard's cache where it has one; the render stops early when `sink` breaks
/// (interrupted, or the disk is full). Without `tap` the engine runs from event to event (in
/// whole blocks, as the live callback does); with it one frame at a time, `tap(instrument,
/// frame)` called after each — the same sound either way but for the exact engine's
/// single-precision rounding inside a block.
pub fn render_midi_into<E: crate::engine::VoicePool>(
    keyboard: crate::play::Keyboard<'_>,
    events: &[crate::midi::file::TimedEvent],
    offline: Offline,
    mut progress: impl FnMut(f64),
    mut tap: Option<Tap<'_, E>>,
    mut sink: impl FnMut(&[f32]) -> ControlFlow<()>,
) -> Result<Rendered, RenderError> {
    let Offline {
        tail_s,
        voices,
        cores,
        halo,
    } = offline;
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
    // With the halo every key rings under the pedal, struck or not.
    let (keys, voices) = if halo {
        ((1..=88).collect(), voices.max(crate::play::HALO_VOICES))
    } else {
        let voices = voices.min(keys.len());
        (keys, voices)
    };
    let scaling = keyboard.scaling;
    let mut piano = crate::play::Piano::<E>::build_with(scaling, &keys, voices, keyboard.cache)?;
    piano.player.set_halo(halo);
    let settings = scaling.output_settings();
    let (fs, channels) = (settings.rate_hz, settings.channels);
    let width = usize::from(channels);
    let (mut synth, mut handle) = Synth::new(piano, settings, EVENT_QUEUE)?;
    if cores >= 2 {
        synth.use_second_core().map_err(RenderError::Helper)?;
    }
    let end_s = events.last().map_or(0.0, |e| e.time_s) + tail_s;
    let total_frames = (end_s * fs).round() as u64;
    let n_blocks = total_frames.div_ceil(OFFLINE_BLOCK as u64).max(1);
    let mut block = [0f32; 2 * OFFLINE_BLOCK];
    let (mut next, mut frames) = (0, 0u64);
    for b in 0..n_blocks {
        let n = (total_frames - frames).min(OFFLINE_BLOCK as u64) as usize;
        next = handle.schedule_timed(events, next, 0);
        let block = &mut block[..n * width];
        match tap.as_deref_mut() {
            Some(tap) => synth.process_with(block, width, tap),
            None => synth.process(block, width),
        }
        frames += n as u64;
        if sink(block).is_break() {
            break;
        }
        if b % 64 == 0 {
            progress(b as f64 / n_blocks as f64);
        }
    }
    progress(1.0);
    Ok(Rendered {
        rate_hz: fs,
        channels,
        frames,
        total_frames,
        keys,
        voices,
    })
}
