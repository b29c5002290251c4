//! A headless CLAP host for the plugin's tests, built on clack-host: instantiate from an entry
//! (in process, or the built `.clap` loaded with dlopen), read ports, parameters and state,
//! activate at a rate, and play events at chosen frames in blocks of chosen lengths.

#![allow(dead_code)]

use clack_extensions::audio_ports::{AudioPortInfoBuffer, PluginAudioPorts};
use clack_extensions::latency::PluginLatency;
use clack_extensions::note_ports::{NotePortInfoBuffer, PluginNotePorts};
use clack_extensions::params::{
    HostParams, HostParamsImplMainThread, HostParamsImplShared, ParamClearFlags, ParamInfoBuffer,
    ParamRescanFlags, PluginParams,
};
use clack_extensions::state::PluginState;
use clack_host::events::event_types::{
    MidiEvent, NoteChokeEvent, NoteOffEvent, NoteOnEvent, ParamValueEvent,
};
use clack_host::events::{Match, Pckn};
use clack_host::factory::plugin::PluginFactory;
use clack_host::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering};

pub struct Host;
#[derive(Default)]
pub struct HostShared {
    pub restarts: AtomicU32,
    pub rescans: AtomicU32,
    /// Main-thread callbacks the plugin asked for.
    pub callbacks: AtomicU32,
}
pub struct HostMain<'a> {
    shared: &'a HostShared,
}
pub struct HostAudio;

impl<'a> SharedHandler<'a> for HostShared {
    fn request_restart(&self) {
        self.restarts.fetch_add(1, Ordering::Relaxed);
    }
    fn request_process(&self) {}
    fn request_callback(&self) {
        self.callbacks.fetch_add(1, Ordering::Relaxed);
    }
}
impl<'a> MainThreadHandler<'a> for HostMain<'a> {}
impl<'a> AudioProcessorHandler<'a> for HostAudio {}
impl HostParamsImplShared for HostShared {
    fn request_flush(&self) {}
}
impl HostParamsImplMainThread for HostMain<'_> {
    fn rescan(&self, flags: ParamRescanFlags) {
        if flags.contains(ParamRescanFlags::VALUES) {
            self.shared.rescans.fetch_add(1, Ordering::Relaxed);
        }
    }
    fn clear(&self, _param_id: ClapId, _flags: ParamClearFlags) {}
}
impl HostHandlers for Host {
    type Shared<'a> = HostShared;
    type MainThread<'a> = HostMain<'a>;
    type AudioProcessor<'a> = HostAudio;

    fn declare_extensions(builder: &mut HostExtensions<Self>, _shared: &HostShared) {
        builder.register::<HostParams>();
    }
}

/// What the test plays at a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Play {
    /// CLAP note on (velocity 0–1) and off; `None`: the wildcard key (−1).
    On(u16, f64),
    Off(Option<u16>),
    Choke(Option<u16>),
    /// A MIDI 1.0 message.
    Midi([u8; 3]),
    /// A parameter (its CLAP id) set to a value.
    Param(u32, f64),
}

/// An instance of the plugin.
pub struct Instance {
    pub instance: PluginInstance<Host>,
}

pub fn instantiate(entry: &PluginEntry) -> Instance {
    let info = HostInfo::new("unacorda tests", "unacorda", "", "0.1").unwrap();
    let factory = entry.get_factory::<PluginFactory>().unwrap();
    let descriptor = factory.plugin_descriptor(0).unwrap();
    let id = descriptor.id().unwrap();
    assert_eq!(id.to_bytes(), b"org.unacorda.piano");
    let instance = PluginInstance::<Host>::new(
        |_| HostShared::default(),
        |shared| HostMain { shared },
        entry,
        id,
        &info,
    )
    .unwrap();
    Instance { instance }
}

/// The plugin's ports: (output ports, channels of the first, note ports, note dialects).
pub fn ports(instance: &mut Instance) -> (u32, u32, u32, u32) {
    let handle = instance.instance.plugin_handle();
    let audio = handle.get_extension::<PluginAudioPorts>().unwrap();
    let notes = handle.get_extension::<PluginNotePorts>().unwrap();
    let mut buffer = AudioPortInfoBuffer::new();
    let info = audio.get(&handle, 0, false, &mut buffer).unwrap();
    let mut note_buffer = NotePortInfoBuffer::new();
    let note = notes.get(&handle, 0, true, &mut note_buffer).unwrap();
    (
        audio.count(&handle, false),
        info.channel_count,
        notes.count(&handle, true),
        note.supported_dialects.bits(),
    )
}

/// Every parameter: (id, name, min, max, default).
pub fn params(instance: &mut Instance) -> Vec<(u32, String, f64, f64, f64)> {
    let handle = instance.instance.plugin_handle();
    let params = handle.get_extension::<PluginParams>().unwrap();
    let mut buffer = ParamInfoBuffer::new();
    (0..params.count(&handle))
        .map(|i| {
            let info = params.get_info(&handle, i, &mut buffer).unwrap();
            (
                info.id.get(),
                String::from_utf8_lossy(info.name).into_owned(),
                info.min_value,
                info.max_value,
                info.default_value,
            )
        })
        .collect()
}

pub fn param_value(instance: &mut Instance, id: u32) -> Option<f64> {
    let handle = instance.instance.plugin_handle();
    let params = handle.get_extension::<PluginParams>().unwrap();
    params.get_value(&handle, ClapId::new(id))
}

pub fn save(instance: &mut Instance) -> Vec<u8> {
    let handle = instance.instance.plugin_handle();
    let state = handle.get_extension::<PluginState>().unwrap();
    let mut out = Vec::new();
    state.save(&handle, &mut out).unwrap();
    out
}

pub fn load(instance: &mut Instance, bytes: &[u8]) -> Result<(), String> {
    let handle = instance.instance.plugin_handle();
    let state = handle.get_extension::<PluginState>().unwrap();
    state
        .load(&handle, &mut std::io::Cursor::new(bytes))
        .map_err(|e| e.to_string())
}

pub fn rescans(instance: &mut Instance) -> u32 {
    instance
        .instance
        .access_shared_handler(|h| h.rescans.load(Ordering::Relaxed))
}

pub fn restarts(instance: &mut Instance) -> u32 {
    instance
        .instance
        .access_shared_handler(|h| h.restarts.load(Ordering::Relaxed))
}

/// How many main-thread callbacks the plugin asked for.
pub fn callbacks(instance: &mut Instance) -> u32 {
    instance
        .instance
        .access_shared_handler(|h| h.callbacks.load(Ordering::Relaxed))
}

/// Call the plugin's main-thread callback, as a host does after `request_callback`.
pub fn on_main_thread(instance: &mut Instance) {
    instance.instance.call_on_main_thread_callback();
}

/// The latency the plugin reports.
pub fn latency(instance: &mut Instance) -> u32 {
    let handle = instance.instance.plugin_handle();
    handle
        .get_extension::<PluginLatency>()
        .map_or(0, |l| l.get(&handle))
}

/// The ring-out the active plugin reports as its tail (frames; `None`: no tail extension).
pub fn tail(active: &mut Active) -> Option<u32> {
    let handle = active.processor.plugin_handle();
    let tail = handle.get_extension::<clack_extensions::tail::PluginTail>()?;
    Some(tail.get(&handle).to_raw())
}

/// What [`Active::run`] heard: both channels and each block's status.
pub struct Heard {
    pub left: Vec<f32>,
    pub right: Vec<f32>,
    pub sleeps: usize,
    /// Allocations counted inside `process` (when the caller's allocator counts them).
    pub allocations: u32,
}

/// For [`Active::run`]: run `process` as it is, counting nothing.
pub fn unchecked(f: &mut dyn FnMut()) -> u32 {
    f();
    0
}

/// Root mean square of a channel.
pub fn rms(x: &[f32]) -> f64 {
    (x.iter().map(|s| f64::from(*s).powi(2)).sum::<f64>() / x.len() as f64).sqrt()
}

/// An activated, processing instance.
pub struct Active {
    pub processor: StartedPluginAudioProcessor<Host>,
    pub frame: u64,
}

pub fn activate(instance: &mut Instance, rate_hz: f64) -> Active {
    let config = PluginAudioConfiguration {
        sample_rate: rate_hz,
        min_frames_count: 1,
        max_frames_count: 4096,
    };
    let processor = instance
        .instance
        .activate(|_, _| HostAudio, config)
        .unwrap()
        .start_processing()
        .unwrap();
    Active {
        processor,
        frame: 0,
    }
}

pub fn deactivate(instance: &mut Instance, active: Active) {
    instance
        .instance
        .deactivate(active.processor.stop_processing());
}

impl Active {
    /// `frames` frames in blocks of `blocks` (cycled), the events `script` (absolute frames,
    /// sorted) at their offsets; `checked(f)` runs each `process` (e.g. under an allocation
    /// checker) and returns the allocations it saw.
    pub fn run(
        &mut self,
        frames: usize,
        blocks: &[usize],
        script: &[(u64, Play)],
        mut checked: impl FnMut(&mut dyn FnMut()) -> u32,
    ) -> Heard {
        let mut heard = Heard {
            left: vec![0.0; frames],
            right: vec![0.0; frames],
            sleeps: 0,
            allocations: 0,
        };
        let mut events = EventBuffer::with_capacity(1024);
        let mut out_events = EventBuffer::with_capacity(1024);
        let mut ports = AudioPorts::with_capacity(2, 1);
        let start = self.frame;
        let mut next = script.partition_point(|(f, _)| *f < start);
        let mut at = 0;
        for &len in blocks.iter().cycle() {
            if at == frames {
                break;
            }
            let n = len.min(frames - at);
            let block_start = self.frame;
            events.clear();
            while next < script.len() && script[next].0 < block_start + n as u64 {
                let (frame, play) = script[next];
                push(&mut events, (frame - block_start) as u32, play);
                next += 1;
            }
            let (left, right) = (&mut heard.left[at..at + n], &mut heard.right[at..at + n]);
            let mut outputs = ports.with_output_buffers([AudioPortBuffer {
                channels: AudioPortBufferType::f32_output_only([left, right].into_iter()),
                latency: 0,
            }]);
            let mut status = None;
            heard.allocations += checked(&mut || {
                status = Some(self.processor.process(
                    &InputAudioBuffers::empty(),
                    &mut outputs,
                    &events.as_input(),
                    &mut out_events.as_output(),
                    None,
                    None,
                ));
            });
            if let Some(Ok(ProcessStatus::Sleep)) = status {
                heard.sleeps += 1;
            }
            status.unwrap().unwrap();
            self.frame += n as u64;
            at += n;
        }
        heard
    }
}

fn push(events: &mut EventBuffer, time: u32, play: Play) {
    let key = |k: Option<u16>| k.map_or(Match::All, Match::Specific);
    match play {
        Play::On(k, v) => events.push(&NoteOnEvent::new(
            time,
            Pckn::new(0u16, 0u16, k, Match::All),
            v,
        )),
        Play::Off(k) => events.push(&NoteOffEvent::new(
            time,
            Pckn::new(0u16, Match::All, key(k), Match::All),
            0.0,
        )),
        Play::Choke(k) => events.push(&NoteChokeEvent::new(
            time,
            Pckn::new(0u16, Match::All, key(k), Match::All),
        )),
        Play::Midi(data) => events.push(&MidiEvent::new(time, 0, data)),
        Play::Param(id, value) => events.push(&ParamValueEvent::new(
            time,
            ClapId::new(id),
            Pckn::match_all(),
            value,
        )),
    }
}
