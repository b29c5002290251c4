//! A headless CLAP host for the plugin's tests, built on clack-host: instantiate from an entry
//! (in process, or the built `.clap` loaded with dlopen), read ports, parameters and state,
//! activate at a rate, and play events at chosen frames in blocks of chosen lengths.

#![allow(dead_code)]

use clack_extensions::audio_ports::{
    AudioPortInfoBuffer, AudioPortRescanFlags, HostAudioPorts, HostAudioPortsImpl, PluginAudioPorts,
};
use clack_extensions::latency::PluginLatency;
use clack_extensions::note_ports::{NotePortInfoBuffer, PluginNotePorts};
use clack_extensions::params::{
    HostParams, HostParamsImplMainThread, HostParamsImplShared, ParamClearFlags, ParamInfoBuffer,
    ParamRescanFlags, PluginParams,
};
use clack_extensions::state::PluginState;
use clack_extensions::thread_pool::{HostThreadPool, HostThreadPoolImpl, PluginThreadPool};
use clack_host::events::event_types::{
    MidiEvent, NoteChokeEvent, NoteOffEvent, NoteOnEvent, ParamValueEvent, TransportEvent,
};
use clack_host::events::spaces::CoreEventSpace;
use clack_host::events::{Match, Pckn};
use clack_host::factory::plugin::PluginFactory;
use clack_host::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, OnceLock};
use std::thread::JoinHandle;

pub struct Host;
#[derive(Default)]
pub struct HostShared {
    pub restarts: AtomicU32,
    pub rescans: AtomicU32,
    /// Rescans of the audio ports' channels the plugin asked for.
    pub port_rescans: AtomicU32,
    /// Main-thread callbacks the plugin asked for.
    pub callbacks: AtomicU32,
    /// How this host runs the tasks the plugin asks its thread pool for (none: no pool).
    pub threads: Threads,
    /// The plugin's handle and its side of the thread pool, once it is initialised.
    plugin: OnceLock<(PluginSharedHandle<'static>, PluginThreadPool)>,
    pub pool: Arc<PoolStats>,
}
pub struct HostMain<'a> {
    shared: &'a HostShared,
}
pub struct HostAudio<'a> {
    shared: &'a HostShared,
    worker: Option<Worker>,
}

/// How the test host's thread pool runs a request's tasks.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Threads {
    /// The host has no thread pool.
    #[default]
    None,
    /// One after the other on the audio thread (a host whose workers are busy).
    Serial,
    /// Task 0 on the audio thread, task 1 on a worker thread at the same time.
    Parallel,
}

/// What a task runs inside (the test's allocation checker), returning the allocations it saw.
pub type Checker = fn(&mut dyn FnMut()) -> u32;

/// What the host's thread pool saw.
#[derive(Debug, Default)]
pub struct PoolStats {
    pub requests: AtomicU32,
    pub tasks: AtomicU32,
    /// Tasks inside the plugin now, and the most there were at once (2: the two halves ran
    /// together).
    inside: AtomicU32,
    pub most_at_once: AtomicU32,
    /// Tasks that came while the other was inside (blocks the halves ran together).
    pub together: AtomicU32,
    /// Allocations the worker's tasks made (under the test's checker).
    pub worker_allocations: AtomicU32,
    /// What each worker task runs inside (the test's allocation checker).
    pub checker: OnceLock<Checker>,
}

impl PoolStats {
    /// Task `i` of the plugin's request, counted.
    fn run(&self, plugin: &(PluginSharedHandle<'static>, PluginThreadPool), i: u32) {
        let now = self.inside.fetch_add(1, Ordering::AcqRel) + 1;
        self.most_at_once.fetch_max(now, Ordering::Relaxed);
        if now == 2 {
            self.together.fetch_add(1, Ordering::Relaxed);
        }
        plugin.1.exec(&plugin.0, i);
        self.inside.fetch_sub(1, Ordering::AcqRel);
        self.tasks.fetch_add(1, Ordering::Relaxed);
    }
}

/// The host's worker thread: runs task 1 of each request (rounds numbered from 1), spinning for
/// 300 us after each, then parked until the next (spinning through every block, a real-time
/// worker is throttled by the kernel; the plugin's helper thread rests for the same reason).
struct Worker {
    round: Arc<(AtomicU32, AtomicU32, AtomicBool)>,
    thread: Option<JoinHandle<()>>,
    posted: u32,
}

impl Worker {
    fn spawn(
        plugin: (PluginSharedHandle<'static>, PluginThreadPool),
        stats: Arc<PoolStats>,
    ) -> Worker {
        let round = Arc::new((AtomicU32::new(0), AtomicU32::new(0), AtomicBool::new(false)));
        let theirs = round.clone();
        let thread = std::thread::spawn(move || {
            // A host's audio workers run at real-time priority, as the plugin's helper asks to.
            unacorda::audio::priority::Promotion::default().ask();
            let (posted, done, quit) = (&theirs.0, &theirs.1, &theirs.2);
            let mut idle = std::time::Instant::now();
            let checker = *stats.checker.get().unwrap_or(&(unchecked as Checker));
            while !quit.load(Ordering::Acquire) {
                let n = posted.load(Ordering::Acquire);
                if n != done.load(Ordering::Relaxed) {
                    let allocations = checker(&mut || stats.run(&plugin, 1));
                    stats
                        .worker_allocations
                        .fetch_add(allocations, Ordering::Relaxed);
                    done.store(n, Ordering::Release);
                    idle = std::time::Instant::now();
                } else if idle.elapsed() > std::time::Duration::from_micros(300) {
                    std::thread::park_timeout(std::time::Duration::from_millis(1));
                } else {
                    std::hint::spin_loop();
                }
            }
        });
        Worker {
            round,
            thread: Some(thread),
            posted: 0,
        }
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.round.2.store(true, Ordering::Release);
        if let Some(thread) = self.thread.take() {
            thread.thread().unpark();
            let _ = thread.join();
        }
    }
}

impl HostThreadPoolImpl for HostAudio<'_> {
    fn request_exec(&mut self, task_count: u32) -> Result<(), HostError> {
        let plugin = self
            .shared
            .plugin
            .get()
            .ok_or(HostError::Message("no plugin"))?;
        let stats = &self.shared.pool;
        stats.requests.fetch_add(1, Ordering::Relaxed);
        match (self.shared.threads, &mut self.worker) {
            (Threads::Parallel, Some(worker)) if task_count >= 2 => {
                worker.posted = worker.posted.wrapping_add(1).max(1);
                worker.round.0.store(worker.posted, Ordering::Release);
                if let Some(thread) = &worker.thread {
                    thread.thread().unpark();
                }
                stats.run(plugin, 0);
                while worker.round.1.load(Ordering::Acquire) != worker.posted {
                    std::hint::spin_loop();
                }
                (2..task_count).for_each(|i| stats.run(plugin, i));
            }
            (Threads::None, _) => return Err(HostError::Message("no thread pool")),
            _ => (0..task_count).for_each(|i| stats.run(plugin, i)),
        }
        Ok(())
    }
}

impl<'a> SharedHandler<'a> for HostShared {
    fn request_restart(&self) {
        self.restarts.fetch_add(1, Ordering::Relaxed);
    }
    fn request_process(&self) {}
    fn request_callback(&self) {
        self.callbacks.fetch_add(1, Ordering::Relaxed);
    }
}
impl<'a> MainThreadHandler<'a> for HostMain<'a> {
    fn initialized(&self, instance: InitializedPluginHandle<'a>) {
        if self.shared.threads == Threads::None {
            return;
        }
        if let Some(pool) = instance.get_extension::<PluginThreadPool>() {
            // SAFETY: the handle is used only by the host's audio side and its worker, which end
            // (deactivation joins the worker) before the instance does.
            let handle = instance.access(|h| unsafe {
                std::mem::transmute::<PluginSharedHandle<'_>, PluginSharedHandle<'static>>(h)
            });
            if let Some(handle) = handle {
                let _ = self.shared.plugin.set((handle, pool));
            }
        }
    }
}
impl<'a> AudioProcessorHandler<'a> for HostAudio<'a> {}
impl HostAudioPortsImpl for HostMain<'_> {
    fn is_rescan_flag_supported(&self, _flag: AudioPortRescanFlags) -> bool {
        true
    }
    fn rescan(&self, flags: AudioPortRescanFlags) {
        if flags.contains(AudioPortRescanFlags::CHANNEL_COUNT) {
            self.shared.port_rescans.fetch_add(1, Ordering::Relaxed);
        }
    }
}
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
    type AudioProcessor<'a> = HostAudio<'a>;

    fn declare_extensions(builder: &mut HostExtensions<Self>, shared: &HostShared) {
        builder
            .register::<HostParams>()
            .register::<HostAudioPorts>();
        if shared.threads != Threads::None {
            builder.register::<HostThreadPool>();
        }
    }
}

/// What the test plays at a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Play {
    /// CLAP note on (velocity 0–1) and off (release velocity 0–1, 0 for none); `None`: the
    /// wildcard key (−1).
    On(u16, f64),
    Off(Option<u16>, f64),
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
    instantiate_with(entry, Threads::None, unchecked)
}

/// An instance in a host with a thread pool that runs tasks as `threads` says, each worker task
/// inside `checker`.
pub fn instantiate_with(entry: &PluginEntry, threads: Threads, checker: Checker) -> Instance {
    let info = HostInfo::new("unacorda tests", "unacorda", "", "0.1").unwrap();
    let factory = entry.get_factory::<PluginFactory>().unwrap();
    let descriptor = factory.plugin_descriptor(0).unwrap();
    let id = descriptor.id().unwrap();
    assert_eq!(id.to_bytes(), b"org.unacorda.piano");
    let instance = PluginInstance::<Host>::new(
        |_| {
            let pool = PoolStats::default();
            let _ = pool.checker.set(checker);
            HostShared {
                threads,
                pool: Arc::new(pool),
                ..HostShared::default()
            }
        },
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

/// What the host's thread pool saw: (requests, tasks, most tasks inside the plugin at once,
/// requests whose tasks were inside together, allocations on the worker).
pub fn pool(instance: &mut Instance) -> (u32, u32, u32, u32, u32) {
    instance.instance.access_shared_handler(|h| {
        let p = &h.pool;
        (
            p.requests.load(Ordering::Relaxed),
            p.tasks.load(Ordering::Relaxed),
            p.most_at_once.load(Ordering::Relaxed),
            p.together.load(Ordering::Relaxed),
            p.worker_allocations.load(Ordering::Relaxed),
        )
    })
}

/// How many times the plugin asked the host to read its ports' channels again.
pub fn port_rescans(instance: &mut Instance) -> u32 {
    instance
        .instance
        .access_shared_handler(|h| h.port_rescans.load(Ordering::Relaxed))
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

/// Tell the plugin the host renders offline (a bounce), or live.
pub fn render_offline(instance: &mut Instance, offline: bool) {
    use clack_extensions::render::{PluginRender, RenderMode};
    let handle = instance.instance.plugin_handle();
    let render = handle.get_extension::<PluginRender>().unwrap();
    let mode = match offline {
        true => RenderMode::Offline,
        false => RenderMode::Realtime,
    };
    render.set(&handle, mode).unwrap();
}

/// The plugin's editor as a host drives it: `Some(scale)` creates a floating window at that
/// scale and shows it (returning its size in pixels), `None` destroys it.
pub fn editor(instance: &mut Instance, open: Option<f64>) -> Option<(u32, u32)> {
    use clack_extensions::gui::{GuiApiType, GuiConfiguration, PluginGui};
    let handle = instance.instance.plugin_handle();
    let gui = handle
        .get_extension::<PluginGui>()
        .expect("the gui extension");
    let Some(scale) = open else {
        gui.destroy(&handle);
        return None;
    };
    let floating = GuiConfiguration {
        api_type: GuiApiType::X11,
        is_floating: true,
    };
    assert!(gui.is_api_supported(&handle, floating));
    gui.create(&handle, floating).unwrap();
    gui.set_scale(&handle, scale).unwrap();
    let size = gui.get_size(&handle).unwrap();
    gui.show(&handle).unwrap();
    Some((size.width, size.height))
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
    /// The parameter changes the plugin told the host of (id, value).
    pub params: Vec<(u32, f64)>,
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
    /// The transport event handed with every block (none by default).
    pub transport: Option<TransportEvent>,
}

pub fn activate(instance: &mut Instance, rate_hz: f64) -> Active {
    let config = PluginAudioConfiguration {
        sample_rate: rate_hz,
        min_frames_count: 1,
        max_frames_count: 4096,
    };
    let processor = instance
        .instance
        .activate(
            |shared, _| HostAudio {
                shared,
                worker: match (shared.threads, shared.plugin.get()) {
                    (Threads::Parallel, Some(plugin)) => {
                        Some(Worker::spawn(*plugin, shared.pool.clone()))
                    }
                    _ => None,
                },
            },
            config,
        )
        .unwrap()
        .start_processing()
        .unwrap();
    Active {
        processor,
        frame: 0,
        transport: None,
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
            params: Vec::new(),
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
                    self.transport.as_ref(),
                ));
            });
            if let Some(Ok(ProcessStatus::Sleep)) = status {
                heard.sleeps += 1;
            }
            for event in out_events.iter() {
                if let Some(CoreEventSpace::ParamValue(e)) = event.as_core_event() {
                    heard
                        .params
                        .push((e.param_id().map_or(0, |id| id.get()), e.value()));
                }
            }
            out_events.clear();
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
        Play::Off(k, velocity) => events.push(&NoteOffEvent::new(
            time,
            Pckn::new(0u16, Match::All, key(k), Match::All),
            velocity,
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
