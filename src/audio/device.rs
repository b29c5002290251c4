//! Audio output through cpal (ALSA on Linux, whose `null` device plays without a sound card) and
//! the list of MIDI inputs through midir. The stream's callback runs [`Synth::process`] and
//! measures itself against the block's deadline; nothing in it allocates, locks or prints.

use super::synth::Synth;
use crate::engine::VoicePool;
use cpal::traits::{DeviceTrait, HostTrait, StreamTrait};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// One audio output as `devices` lists it.
#[derive(Debug, Clone)]
pub struct OutputInfo {
    /// cpal's id, `host:device` (e.g. `alsa:null`, `alsa:hw:0,0`): what `--device` matches.
    pub id: String,
    pub description: String,
    /// Whether the device can run the engine's format: 32-bit float at the output rate.
    pub supports_rate: bool,
    pub is_default: bool,
}

/// Why audio output cannot start.
#[derive(Debug, thiserror::Error)]
pub enum DeviceError {
    #[error("no audio output device{}: run `unacorda devices` to list them, or render to a file with `unacorda render`", .0.as_ref().map(|n| format!(" matches {n:?}")).unwrap_or_default())]
    NotFound(Option<String>),
    #[error("audio device {device}: no 32-bit float output at {rate_hz} Hz (it offers {offers}); `unacorda devices` lists the others (alsa:null plays without a sound card)")]
    Format {
        device: String,
        rate_hz: u32,
        offers: String,
    },
    #[error("--buffer {0}: expected 16 to 8192 frames")]
    Buffer(u32),
    #[error("audio device {device}: {source}")]
    Cpal {
        device: String,
        #[source]
        source: cpal::Error,
    },
}

/// Why live MIDI input cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum MidiError {
    #[error(
        "live MIDI input is unavailable: {0} (on Linux it needs the ALSA sequencer, /dev/snd/seq)"
    )]
    Unavailable(String),
    #[error("no MIDI input port is connected")]
    NoPort,
    #[error("no MIDI input matches {port:?} (inputs: {})", .inputs.join(", "))]
    NoMatch { port: String, inputs: Vec<String> },
    #[error("cannot open MIDI input {port}: {reason}")]
    Connect { port: String, reason: String },
    #[error("the event queue is gone")]
    QueueGone,
}

/// Keep alsa-lib's own error lines (`ALSA lib seq_hw.c:…`) off standard error on this thread:
/// what failed is said once, by the error this module returns. alsa-lib writes them into a buffer
/// instead, replaced (and the last one freed) at each call.
fn quiet_alsa() {
    #[cfg(target_os = "linux")]
    let _ = alsa::Output::local_error_handler();
}

/// Every output device of the default host, with whether it can play at `rate_hz`.
pub fn output_devices(rate_hz: u32) -> Result<Vec<OutputInfo>, DeviceError> {
    quiet_alsa();
    let host = cpal::default_host();
    let default_id = host
        .default_output_device()
        .and_then(|d| d.id().ok())
        .map(|id| id.to_string());
    let devices = host.output_devices().map_err(|source| DeviceError::Cpal {
        device: "host".into(),
        source,
    })?;
    Ok(devices
        .map(|d| {
            let id = d.id().map_or_else(|_| "?".into(), |id| id.to_string());
            OutputInfo {
                description: d
                    .description()
                    .map_or_else(|_| String::new(), |x| x.to_string()),
                supports_rate: f32_config(&d, rate_hz).is_ok(),
                is_default: default_id.as_deref() == Some(id.as_str()),
                id,
            }
        })
        .collect())
}

/// The MIDI input client with its ports and their names, or why live MIDI is unavailable (on
/// Linux it needs the ALSA sequencer, `/dev/snd/seq`).
pub fn midi_input() -> Result<(midir::MidiInput, Vec<midir::MidiInputPort>, Vec<String>), MidiError>
{
    quiet_alsa();
    let input =
        midir::MidiInput::new("unacorda").map_err(|e| MidiError::Unavailable(e.to_string()))?;
    let ports = input.ports();
    let names = ports
        .iter()
        .map(|p| input.port_name(p).unwrap_or_else(|_| "?".into()))
        .collect();
    Ok((input, ports, names))
}

/// Frames per callback that `start` accepts.
pub const BUFFER_FRAMES: std::ops::RangeInclusive<u32> = 16..=8192;

/// Check a requested callback size before anything is built around it.
pub fn check_buffer(buffer: Option<u32>) -> Result<(), DeviceError> {
    match buffer {
        Some(b) if !BUFFER_FRAMES.contains(&b) => Err(DeviceError::Buffer(b)),
        _ => Ok(()),
    }
}

/// A channel count for 32-bit float output at `rate_hz`, or what the device offers instead.
fn f32_config(device: &cpal::Device, rate_hz: u32) -> Result<u16, String> {
    let configs: Vec<_> = device
        .supported_output_configs()
        .map_err(|e| format!("nothing: it cannot be opened: {e}"))?
        .collect();
    configs
        .iter()
        .filter(|c| c.sample_format() == cpal::SampleFormat::F32)
        .filter(|c| (c.min_sample_rate()..=c.max_sample_rate()).contains(&rate_hz))
        .map(|c| c.channels())
        .min_by_key(|&ch| (ch != 2, ch))
        .ok_or_else(|| {
            configs
                .iter()
                .map(|c| {
                    format!(
                        "{} ch {:?} {}–{} Hz",
                        c.channels(),
                        c.sample_format(),
                        c.min_sample_rate(),
                        c.max_sample_rate()
                    )
                })
                .collect::<Vec<_>>()
                .join(", ")
        })
}

/// What the callback measures about itself (relaxed atomics, read from any thread).
#[derive(Debug, Default)]
pub struct CallbackStats {
    pub callbacks: AtomicU64,
    /// Callbacks that took longer than their block lasts (the engine could not keep up).
    pub overruns: AtomicU64,
    pub busy_ns: AtomicU64,
    pub max_ns: AtomicU64,
    /// Frames of the largest block seen.
    pub max_frames: AtomicU64,
    /// The callback thread's real-time priority (asked at its first callback).
    pub priority: super::priority::Promotion,
}

/// Why a stream did not start, with the synth handed back when it could be (boxed: the error
/// stays small).
pub type Refused<E> = (DeviceError, Option<Box<Synth<E>>>);

/// A running output stream.
pub struct Output<E: VoicePool = crate::engine::Rk4Pool> {
    /// Dropping the stream stops it; the synth then comes back through `synth_back`.
    stream: cpal::Stream,
    pub device: String,
    pub channels: u16,
    pub rate_hz: u32,
    pub stats: Arc<CallbackStats>,
    /// Errors the stream reported (device lost, xruns).
    pub errors: crossbeam_channel::Receiver<cpal::Error>,
    inject: crossbeam_channel::Sender<cpal::Error>,
    synth_back: crossbeam_channel::Receiver<Synth<E>>,
}

/// What a stream error asks of the program.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// A buffer under- or overrun: count it, carry on.
    Xrun,
    /// The stream is gone (device unplugged, busy, invalidated): reopen it.
    Lost,
    /// Anything else: report it, carry on.
    Note,
}

/// How `play` treats a stream error.
pub fn classify(e: &cpal::Error) -> Fault {
    use cpal::ErrorKind as K;
    match e.kind() {
        K::Xrun => Fault::Xrun,
        K::DeviceNotAvailable
        | K::DeviceBusy
        | K::StreamInvalidated
        | K::HostUnavailable
        | K::BackendError => Fault::Lost,
        _ => Fault::Note,
    }
}

/// The synth inside the stream's callback; when cpal drops the callback (the stream closed), the
/// synth is handed back so that a reopened stream continues with the same state.
struct Returning<E: VoicePool> {
    synth: Option<Synth<E>>,
    back: crossbeam_channel::Sender<Synth<E>>,
}

impl<E: VoicePool> Drop for Returning<E> {
    fn drop(&mut self) {
        if let Some(synth) = self.synth.take() {
            let _ = self.back.try_send(synth);
        }
    }
}

impl<E: VoicePool> Output<E> {
    /// Stop the stream and take the synth back (with its voices, queue and clock), to start it on
    /// another stream; `None` if the stream's thread did not hand it back within a second.
    pub fn close(self) -> Option<Synth<E>> {
        let back = self.synth_back.clone();
        drop(self.stream);
        back.recv_timeout(std::time::Duration::from_secs(1)).ok()
    }

    /// Deliver `e` as if cpal's error callback had reported it (fault-injection tests: a null
    /// device is never unplugged).
    pub fn inject(&self, e: cpal::Error) {
        let _ = self.inject.try_send(e);
    }
}

/// Open `device` (an id or part of an id or description; `None`: the default output) at
/// `rate_hz` with `buffer` frames per callback (`None`: the device's default), and start `synth`
/// in its callback, which counts into `stats`. On failure the synth is returned with the error
/// (boxed: the error stays small).
/// The output `device` names (`None`: the default), its id and the channel count it plays
/// 32-bit float at `rate_hz` with — or why there is none.
fn find_output(
    device: Option<&str>,
    rate_hz: u32,
) -> Result<(cpal::Device, String, u16), DeviceError> {
    quiet_alsa();
    let host = cpal::default_host();
    let chosen = match device {
        None => host.default_output_device(),
        Some(name) => host.output_devices().ok().and_then(|mut all| {
            all.find(|d| {
                let id = d.id().map(|id| id.to_string()).unwrap_or_default();
                let desc = d.description().map(|x| x.to_string()).unwrap_or_default();
                id == name || id.ends_with(&format!(":{name}")) || desc.contains(name)
            })
        }),
    };
    let chosen = chosen.ok_or_else(|| DeviceError::NotFound(device.map(str::to_owned)))?;
    let id = chosen.id().map_or_else(|_| "?".into(), |id| id.to_string());
    match f32_config(&chosen, rate_hz) {
        Ok(channels) => Ok((chosen, id, channels)),
        Err(offers) => Err(DeviceError::Format {
            device: id,
            rate_hz,
            offers,
        }),
    }
}

/// Check that the output `device` names exists and plays 32-bit float at `rate_hz`, before
/// anything costly is built for it; its id.
pub fn check_output(device: Option<&str>, rate_hz: u32) -> Result<String, DeviceError> {
    find_output(device, rate_hz).map(|(_, id, _)| id)
}

pub fn start<E: VoicePool>(
    synth: Synth<E>,
    device: Option<&str>,
    rate_hz: u32,
    buffer: Option<u32>,
    stats: Arc<CallbackStats>,
) -> Result<Output<E>, Refused<E>> {
    if let Err(e) = check_buffer(buffer) {
        return Err((e, Some(Box::new(synth))));
    }
    let (chosen, id, channels) = match find_output(device, rate_hz) {
        Ok(found) => found,
        Err(e) => return Err((e, Some(Box::new(synth)))),
    };
    let config = cpal::StreamConfig {
        channels,
        sample_rate: rate_hz,
        buffer_size: buffer.map_or(cpal::BufferSize::Default, cpal::BufferSize::Fixed),
    };
    let (err_tx, err_rx) = crossbeam_channel::bounded(64);
    let (back_tx, back_rx) = crossbeam_channel::bounded(1);
    let cb_stats = stats.clone();
    let ch = usize::from(channels);
    let fs = f64::from(rate_hz);
    let mut held = Returning {
        synth: Some(synth),
        back: back_tx,
    };
    let inject = err_tx.clone();
    let built = chosen.build_output_stream(
        config,
        move |data: &mut [f32], _: &cpal::OutputCallbackInfo| {
            cb_stats.priority.ask();
            let start = Instant::now();
            if let Some(synth) = held.synth.as_mut() {
                synth.process(data, ch);
            }
            let ns = start.elapsed().as_nanos() as u64;
            let frames = (data.len() / ch) as u64;
            let deadline_ns = (frames as f64 / fs * 1e9) as u64;
            let s = &cb_stats;
            s.callbacks.fetch_add(1, Ordering::Relaxed);
            s.busy_ns.fetch_add(ns, Ordering::Relaxed);
            s.max_ns.fetch_max(ns, Ordering::Relaxed);
            s.max_frames.fetch_max(frames, Ordering::Relaxed);
            if ns > deadline_ns {
                s.overruns.fetch_add(1, Ordering::Relaxed);
            }
        },
        move |e: cpal::Error| {
            let _ = err_tx.try_send(e);
        },
        None,
    );
    // A stream that failed to build or start drops its callback, which hands the synth back.
    let fail = |source, back: &crossbeam_channel::Receiver<Synth<E>>| {
        let e = DeviceError::Cpal {
            device: id.clone(),
            source,
        };
        (e, back.try_recv().ok().map(Box::new))
    };
    let stream = built.map_err(|e| fail(e, &back_rx))?;
    if let Err(e) = stream.play() {
        drop(stream);
        return Err(fail(e, &back_rx));
    }
    Ok(Output {
        stream,
        device: id,
        channels,
        rate_hz,
        stats,
        errors: err_rx,
        inject,
        synth_back: back_rx,
    })
}
