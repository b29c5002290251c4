//! The VST3 audio thread's side: each block's note events and parameter changes played at their
//! frame (merged in time order, allocation-free), the host's render mode read from every block
//! (hosts such as Ardour say an export is offline only there), and a piano whose keyboard, pool
//! size, integrator or halo changed built in the background ([`Builder`]) and swapped in at a
//! block's start — waited for when the host renders offline, where a block may take its time.
//! VST3 hosts restart a plugin on their own terms (Ardour only on `kReloadComponent`), so the
//! plugin does not ask for one. Never allocates, locks or prints in `process`.

use super::component::{plain, Inner};
use crate::params::{index_of, PARAMS, REBUILDS, VELOCITY_CURVE};
use crate::sound::{self, Engine, Output, Pedals, SCRATCH_FRAMES};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use unacorda::midi::{curved_velocity, Event};
use vst3::ComRef;
use vst3::Steinberg::Vst::*;
use vst3::Steinberg::*;

/// How often the builder looks for a change to build.
const BUILDER_POLL: Duration = Duration::from_millis(5);
/// How long an offline block waits for a rebuilt piano before it plays on with the old one.
const OFFLINE_WAIT: Duration = Duration::from_secs(120);

/// An activation's audio side (audio thread; built on the main thread or the builder's).
pub struct Audio {
    /// The synth, or none when it could not be built (it plays silence).
    engine: Option<Engine>,
    output: Output,
    /// The pedal parameters as last played.
    pedals: Pedals,
    /// The values this piano was built for ([`Inner::played`]).
    built: [f64; REBUILDS.len()],
    /// What the host is told once this piano plays (host frames; the tail `kInfiniteTail`).
    latency_frames: u32,
    tail_frames: u32,
}

impl Audio {
    /// The piano the parameters ask for now, at the host's rate; its latency and tail published.
    /// Main thread.
    pub fn activate(inner: &Inner, warn: &dyn Fn(&str)) -> Audio {
        let audio = Audio::build(inner, warn);
        audio.publish(inner);
        audio
    }

    /// The piano the parameters ask for now (any thread but the audio thread).
    fn build(inner: &Inner, warn: &dyn Fn(&str)) -> Audio {
        let built = inner.played();
        let activation = sound::activate(
            &inner.values,
            inner.rate_hz(),
            inner.integrator(),
            &inner.silent_because,
            warn,
        );
        Audio {
            output: Output::new(activation.engine.as_ref(), &inner.values),
            engine: activation.engine,
            pedals: Pedals::default(),
            built,
            latency_frames: activation.latency_frames,
            tail_frames: activation.tail_frames.unwrap_or(kInfiniteTail),
        }
    }

    /// The values this piano was built for.
    pub fn built(&self) -> [f64; REBUILDS.len()] {
        self.built
    }

    fn publish(&self, inner: &Inner) {
        inner
            .latency_frames
            .store(self.latency_frames, Ordering::Relaxed);
        inner.tail_frames.store(self.tail_frames, Ordering::Relaxed);
    }

    /// Every string at rest and every pedal up (the host stopped processing).
    pub fn reset(&mut self) {
        if let Some(engine) = &mut self.engine {
            engine.silence();
        }
        self.pedals.lift();
    }

    /// Swap in the piano the builder left, if it left one (the one played goes back to the
    /// builder, which drops it). Offline, wait for the piano the parameters ask for if it is
    /// not the one played. Never allocates.
    fn follow_rebuild(&mut self, inner: &Inner, offline: bool) {
        let started = Instant::now();
        loop {
            if let Ok(mut slot) = inner.rebuilt.try_lock() {
                if slot.fresh.is_some() && slot.retired.is_none() {
                    if let Some(mut fresh) = slot.fresh.take() {
                        std::mem::swap(self, &mut fresh);
                        self.publish(inner);
                        slot.retired = Some(fresh);
                    }
                }
            }
            if !offline || self.built == inner.played() || started.elapsed() > OFFLINE_WAIT {
                return;
            }
            std::thread::sleep(BUILDER_POLL);
        }
    }

    /// The next `frames` frames into the host's `channels` from frame `at` on.
    ///
    /// # Safety
    /// Each of `channels` points at a buffer of at least `at + frames` samples.
    unsafe fn render(&mut self, inner: &Inner, channels: &[*mut f32], at: usize, frames: usize) {
        let mut start = at;
        while start < at + frames {
            let n = (at + frames - start).min(SCRATCH_FRAMES);
            let ch = self.output.channels();
            let rendered = self
                .output
                .render(self.engine.as_mut(), &inner.values, n, None);
            for (c, &buffer) in channels.iter().enumerate() {
                if buffer.is_null() {
                    continue;
                }
                // SAFETY: the caller's promise.
                let dest = unsafe { std::slice::from_raw_parts_mut(buffer.add(start), n) };
                sound::write(rendered, ch, c, channels.len(), dest);
            }
            start += n;
        }
    }

    fn play(&mut self, event: Event) {
        if let Some(engine) = &mut self.engine {
            engine.schedule(event);
        }
    }

    /// A note event of the host's (others are passed over).
    fn note(&mut self, inner: &Inner, event: &vst3::Steinberg::Vst::Event) {
        let curve = inner.values.get(VELOCITY_CURVE);
        let event = match event.r#type as Event_::EventTypes {
            Event_::EventTypes_::kNoteOnEvent => {
                // SAFETY: the type says which of the union's fields the host wrote.
                let on = unsafe { event.__field0.noteOn };
                u8::try_from(on.pitch)
                    .ok()
                    .filter(|k| *k < 128)
                    .map(|note| {
                        // VST3's velocity 0–1 onto MIDI's 1–127, unrounded; 0 is the softest
                        // strike, not a release.
                        Event::NoteOn {
                            note,
                            velocity: curved_velocity(
                                (f64::from(on.velocity) * 127.0).clamp(1.0, 127.0),
                                curve,
                            ),
                        }
                    })
            }
            Event_::EventTypes_::kNoteOffEvent => {
                // SAFETY: as above.
                let off = unsafe { event.__field0.noteOff };
                u8::try_from(off.pitch)
                    .ok()
                    .filter(|k| *k < 128)
                    .map(|note| Event::NoteOff {
                        note,
                        velocity: (f64::from(off.velocity) * 127.0).clamp(0.0, 127.0),
                    })
            }
            _ => None,
        };
        if let Some(event) = event {
            self.play(event);
        }
    }

    /// A parameter's new value (plain): a pedal's is played at once; a rebuild parameter's is
    /// followed by the builder.
    fn param(&mut self, inner: &Inner, index: usize, value: f64) {
        inner.values.set(index, value);
        self.pedals.settle(&inner.values, self.engine.as_mut());
    }
}

/// What the builder and the audio thread hand each other: a rebuilt piano not yet played, and
/// the one it replaced, to be dropped off the audio thread.
#[derive(Default)]
pub struct Slot {
    fresh: Option<Audio>,
    retired: Option<Audio>,
}

/// A thread that, while the plugin is active, builds the piano the parameters ask for whenever
/// it is not the one played or left to be played, and drops the pianos played before.
pub struct Builder {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Builder {
    /// Start it (main thread); `built`: the values of the piano played now.
    pub fn start(inner: Arc<Inner>, built: [f64; REBUILDS.len()]) -> Builder {
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = stop.clone();
        let run = move || {
            let mut have = built;
            while !stopped.load(Ordering::Relaxed) {
                let want = inner.played();
                if want != have {
                    let fresh = Audio::build(&inner, &|message| eprintln!("{message}"));
                    have = fresh.built;
                    // An older piano left unplayed is dropped here.
                    let older = inner.lock_rebuilt().fresh.replace(fresh);
                    drop(older);
                }
                let retired = inner.lock_rebuilt().retired.take();
                drop(retired);
                std::thread::sleep(BUILDER_POLL);
            }
        };
        let thread = std::thread::Builder::new()
            .name("unacorda build".into())
            .spawn(run)
            .map_err(|e| eprintln!("unacorda: no thread to rebuild the piano on ({e}): a change of keyboard or pool size waits for the next activation"))
            .ok();
        Builder { stop, thread }
    }

    /// Stop it and wait (main thread); what it left unplayed is dropped.
    pub fn stop(mut self, inner: &Inner) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
        *inner.lock_rebuilt() = Slot::default();
    }
}

/// One parameter's changes within a block, and the next of them to play.
#[derive(Clone, Copy)]
struct Queue<'a> {
    queue: ComRef<'a, IParamValueQueue>,
    index: usize,
    next: int32,
    count: int32,
}

/// What comes next in a block.
enum Next {
    Param(usize, f64),
    Note(vst3::Steinberg::Vst::Event),
}

/// One block of the host's.
///
/// # Safety
/// `data` is the host's block as VST3 defines it: its buffers hold `numSamples` samples, its
/// lists are null or live.
pub unsafe fn process(inner: &Inner, data: &ProcessData) -> tresult {
    // The editor's figures are worked out only while an editor shows them.
    let started = inner.activity.is_watched().then(Instant::now);
    let offline = data.processMode == ProcessModes_::kOffline as int32;
    inner.offline.store(offline, Ordering::Relaxed);
    let frames = usize::try_from(data.numSamples).unwrap_or(0);
    let mut channels: [*mut f32; 2] = [std::ptr::null_mut(); 2];
    let mut host_channels = 0;
    if data.numOutputs >= 1 && !data.outputs.is_null() && frames > 0 {
        // SAFETY: the host's first output bus.
        let bus = unsafe { &mut *data.outputs };
        bus.silenceFlags = 0;
        // SAFETY: a bus of 32-bit samples (the only size the plugin accepts).
        let buffers = unsafe { bus.__field0.channelBuffers32 };
        host_channels = usize::try_from(bus.numChannels).unwrap_or(0).min(2);
        if buffers.is_null() {
            host_channels = 0;
        }
        for (c, channel) in channels.iter_mut().enumerate().take(host_channels) {
            // SAFETY: `numChannels` pointers.
            *channel = unsafe { *buffers.add(c) };
        }
    }
    let channels = &channels[..host_channels];
    let Ok(mut audio) = inner.audio.try_lock() else {
        // SAFETY: the host's buffers, `frames` long.
        unsafe { silence(channels, frames) };
        return kResultOk;
    };
    let Some(audio) = audio.as_mut() else {
        // SAFETY: as above.
        unsafe { silence(channels, frames) };
        return kResultOk;
    };
    audio.follow_rebuild(inner, offline);
    audio.pedals.settle(&inner.values, audio.engine.as_mut());

    // SAFETY: the host's lists, or null.
    let changes = unsafe { ComRef::from_raw(data.inputParameterChanges) };
    let mut queues: [Option<Queue>; PARAMS.len()] = [None; PARAMS.len()];
    if let Some(changes) = changes {
        // SAFETY: a live list.
        for q in 0..unsafe { changes.getParameterCount() } {
            // SAFETY: an index within the count; a queue is null or live for the block.
            let Some(queue) = (unsafe { ComRef::from_raw(changes.getParameterData(q)) }) else {
                continue;
            };
            // SAFETY: a live queue.
            let (id, count) = unsafe { (queue.getParameterId(), queue.getPointCount()) };
            if let Some(index) = index_of(id) {
                queues[index] = Some(Queue {
                    queue,
                    index,
                    next: 0,
                    count,
                });
            }
        }
    }
    // SAFETY: the host's list, or null.
    let events = unsafe { ComRef::from_raw(data.inputEvents) };
    // SAFETY: a live list.
    let event_count = events.map_or(0, |e| unsafe { e.getEventCount() });
    let mut next_event = 0;
    let mut at = 0;
    loop {
        // The earliest of the parameters' next changes and the next event; at the same frame a
        // parameter first (a pedal pressed with a note).
        let mut next: Option<(usize, Next, Option<usize>)> = None;
        for (slot, queue) in queues.iter().enumerate() {
            let Some(q) = queue.filter(|q| q.next < q.count) else {
                continue;
            };
            let (mut offset, mut value) = (0, 0.0);
            // SAFETY: an index within the queue's count.
            if unsafe { q.queue.getPoint(q.next, &mut offset, &mut value) } != kResultOk {
                continue;
            }
            let offset = usize::try_from(offset).unwrap_or(0);
            if next.as_ref().is_none_or(|n| offset < n.0) {
                next = Some((
                    offset,
                    Next::Param(q.index, plain(q.index, value)),
                    Some(slot),
                ));
            }
        }
        if let Some(events) = events.filter(|_| next_event < event_count) {
            // SAFETY: an event to fill.
            let mut event: vst3::Steinberg::Vst::Event = unsafe { std::mem::zeroed() };
            // SAFETY: an index within the count.
            let got = unsafe { events.getEvent(next_event, &mut event) } == kResultOk;
            let offset = usize::try_from(event.sampleOffset).unwrap_or(0);
            if !got || event.busIndex != 0 {
                next_event += 1;
                continue;
            }
            if next.as_ref().is_none_or(|n| offset < n.0) {
                next = Some((offset, Next::Note(event), None));
            }
        }
        let Some((offset, what, slot)) = next else {
            break;
        };
        let offset = offset.clamp(at, frames);
        // SAFETY: the host's buffers, `frames` long.
        unsafe { audio.render(inner, channels, at, offset - at) };
        at = offset;
        match (what, slot) {
            (Next::Param(index, value), Some(slot)) => {
                if let Some(q) = queues[slot].as_mut() {
                    q.next += 1;
                }
                audio.param(inner, index, value);
            }
            (Next::Note(event), _) => {
                next_event += 1;
                audio.note(inner, &event);
            }
            (Next::Param(..), None) => {}
        }
    }
    // SAFETY: as above.
    unsafe { audio.render(inner, channels, at, frames - at) };
    if let Some(started) = started {
        if let Some(engine) = &audio.engine {
            engine.publish(&inner.activity);
        }
        let rendered_s = frames as f64 / inner.rate_hz();
        inner
            .activity
            .publish_load(started.elapsed().as_secs_f64(), rendered_s);
    }
    kResultOk
}

/// Zeros into the host's `channels`, `frames` long.
///
/// # Safety
/// Each of `channels` is null or points at `frames` samples.
unsafe fn silence(channels: &[*mut f32], frames: usize) {
    for &c in channels.iter().filter(|c| !c.is_null()) {
        // SAFETY: the caller's promise.
        unsafe { std::slice::from_raw_parts_mut(c, frames) }.fill(0.0);
    }
}
