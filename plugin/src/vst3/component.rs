//! The VST3 plugin's object: component, audio processor and edit controller in one. Its buses
//! (one note input, one output of the keyboard's channels or of the host's choice of mono or
//! stereo), its parameters (the CLAP plugin's, in VST3's normalised form), its state (the CLAP
//! plugin's text), the sustain, sostenuto and soft pedals' MIDI controllers mapped to their
//! parameters, and activation. The audio thread's side is [`super::audio`].

use super::audio::{Audio, Builder, Slot};
use super::view::View;
use super::{copy_wide, read_wide};
use crate::editor::Edits;
use crate::params::{self, Values, PARAMS, REBUILDS, SOFT, SOSTENUTO, SUSTAIN};
use crate::state;
use std::ffi::c_void;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use unacorda::audio::activity::Activity;
use unacorda::engine::Integrator;
use vst3::Steinberg::Vst::*;
use vst3::Steinberg::*;
use vst3::{Class, ComPtr, ComRef, ComWrapper};

/// What the host's threads share: the main thread's calls, the audio thread's and the
/// background builder's ([`Builder`]).
pub struct Inner {
    /// The parameters' values (every thread, and the editor's).
    pub values: Arc<Values>,
    /// What the piano is doing, published by the audio thread for the editor.
    pub activity: Arc<Activity>,
    /// The parameters the editor changed, for the host to hear of ([`super::view`]).
    pub edits: Arc<Edits>,
    /// The host's component handler, told of those changes (the host's UI thread).
    handler: Mutex<Option<ComPtr<IComponentHandler>>>,
    /// The host renders offline: from `setupProcessing` (main thread) and each block's
    /// `processMode` (audio thread); read by both and the builder.
    pub offline: AtomicBool,
    /// The host's rate as `setupProcessing` gave it, the bits of an `f64` (main thread).
    rate_bits: AtomicU64,
    /// The output's channels, 1 or 2: the keyboard's until the host arranges the bus (main
    /// thread; the audio thread writes what the host's buffers hold).
    out_channels: AtomicU32,
    /// The host arranged the output bus itself (main thread).
    arranged: AtomicBool,
    /// The latency and tail reported (host frames; the tail `kInfiniteTail` for RK4): written at
    /// activation and when a rebuilt piano is swapped in (audio thread), read by the host.
    pub latency_frames: AtomicU32,
    pub tail_frames: AtomicU32,
    /// Why the last activation plays silent, if it does (main thread and the builder).
    pub silent_because: Mutex<Option<String>>,
    /// The audio side while active: built by `setActive` (main thread), used by `process`
    /// (audio thread), which never waits for it (`try_lock`; the host does not call both at
    /// once).
    pub audio: Mutex<Option<Audio>>,
    /// The background builder while active (main thread).
    builder: Mutex<Option<Builder>>,
    /// A rebuilt piano handed to the audio thread, and the one it replaced handed back
    /// (the builder and the audio thread, which only `try_lock`s it).
    pub rebuilt: Mutex<Slot>,
}

impl Inner {
    /// The integrator played ([`Values::integrator_played`]).
    pub fn integrator(&self) -> Integrator {
        self.values
            .integrator_played(self.offline.load(Ordering::Relaxed))
    }

    /// The values whose change rebuilds the piano, the integrator as played ([`Values::played`]).
    pub fn played(&self) -> [f64; REBUILDS.len()] {
        self.values.played(self.offline.load(Ordering::Relaxed))
    }

    /// What the editor shows and changes.
    pub fn shown(&self) -> crate::editor::Shown {
        crate::editor::Shown {
            values: self.values.clone(),
            activity: self.activity.clone(),
            edits: self.edits.clone(),
        }
    }

    /// The host's component handler, if it gave one.
    pub fn handler(&self) -> Option<ComPtr<IComponentHandler>> {
        lock(&self.handler).clone()
    }

    /// The host's rate (Hz).
    pub fn rate_hz(&self) -> f64 {
        f64::from_bits(self.rate_bits.load(Ordering::Relaxed))
    }

    /// The slot between the builder and the audio thread (never the audio thread: it only
    /// `try_lock`s it).
    pub fn lock_rebuilt(&self) -> std::sync::MutexGuard<'_, Slot> {
        lock(&self.rebuilt)
    }

    /// The output's channels.
    fn channels(&self) -> u32 {
        if self.arranged.load(Ordering::Relaxed) {
            self.out_channels.load(Ordering::Relaxed)
        } else {
            crate::prepare::channels(self.values.keyboard())
        }
    }
}

/// The plugin object hosts create.
pub struct Component {
    inner: Arc<Inner>,
}

impl Class for Component {
    type Interfaces = (
        IComponent,
        IAudioProcessor,
        IEditController,
        IMidiMapping,
        IProcessContextRequirements,
    );
}

impl Component {
    pub fn new() -> Component {
        Component {
            inner: Arc::new(Inner {
                values: Arc::default(),
                activity: Arc::default(),
                edits: Arc::default(),
                handler: Mutex::new(None),
                offline: AtomicBool::new(false),
                rate_bits: AtomicU64::new(48_000f64.to_bits()),
                out_channels: AtomicU32::new(2),
                arranged: AtomicBool::new(false),
                latency_frames: AtomicU32::new(0),
                tail_frames: AtomicU32::new(0),
                silent_because: Mutex::new(None),
                audio: Mutex::new(None),
                builder: Mutex::new(None),
                rebuilt: Mutex::new(Slot::default()),
            }),
        }
    }

    fn deactivate(&self) {
        // The builder first, so that nothing is swapped into the audio side as it goes.
        if let Some(builder) = lock(&self.inner.builder).take() {
            builder.stop(&self.inner);
        }
        lock(&self.inner.audio).take();
    }
}

impl Default for Component {
    fn default() -> Self {
        Component::new()
    }
}

impl Drop for Component {
    /// No builder thread outlives the instance (nor, so, the library's code).
    fn drop(&mut self) {
        self.deactivate();
    }
}

/// A mutex's value even after a panic elsewhere.
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The index of the parameter with VST3 id `id` (the CLAP id).
fn index(id: ParamID) -> Option<usize> {
    params::index_of(id)
}

/// Parameter `i`'s plain value as VST3's normalised one (0–1).
pub fn normalised(i: usize, plain: f64) -> f64 {
    let p = PARAMS[i];
    ((plain - p.min) / (p.max - p.min)).clamp(0.0, 1.0)
}

/// Parameter `i`'s normalised value (0–1) as its plain one, in range (stepped ones rounded).
pub fn plain(i: usize, normalised: f64) -> f64 {
    let p = PARAMS[i];
    p.clamp(p.min + normalised.clamp(0.0, 1.0) * (p.max - p.min))
}

/// Read a host's stream to its end, at most `limit` bytes (more: `None`).
///
/// # Safety
/// `stream` is null or a live `IBStream`.
unsafe fn read_stream(stream: *mut IBStream, limit: usize) -> Option<Vec<u8>> {
    // SAFETY: the caller's promise.
    let stream = unsafe { ComRef::from_raw(stream) }?;
    let mut bytes = Vec::new();
    let mut chunk = [0u8; 4096];
    loop {
        let mut read = 0;
        // SAFETY: `chunk` holds the bytes asked for.
        let result = unsafe {
            stream.read(
                chunk.as_mut_ptr().cast::<c_void>(),
                chunk.len() as int32,
                &mut read,
            )
        };
        let read = usize::try_from(read).unwrap_or(0).min(chunk.len());
        bytes.extend_from_slice(&chunk[..read]);
        if bytes.len() > limit {
            return None;
        }
        if result != kResultOk || read == 0 {
            return Some(bytes);
        }
    }
}

impl IPluginBaseTrait for Component {
    unsafe fn initialize(&self, _context: *mut FUnknown) -> tresult {
        kResultOk
    }

    unsafe fn terminate(&self) -> tresult {
        self.deactivate();
        lock(&self.inner.handler).take();
        kResultOk
    }
}

impl IComponentTrait for Component {
    unsafe fn getControllerClassId(&self, _class_id: *mut TUID) -> tresult {
        // The component is its own controller.
        kNoInterface
    }

    unsafe fn setIoMode(&self, _mode: IoMode) -> tresult {
        kResultOk
    }

    unsafe fn getBusCount(&self, media_type: MediaType, dir: BusDirection) -> int32 {
        let (audio, event) = (
            MediaTypes_::kAudio as MediaType,
            MediaTypes_::kEvent as MediaType,
        );
        let (input, output) = (
            BusDirections_::kInput as BusDirection,
            BusDirections_::kOutput as BusDirection,
        );
        int32::from((media_type == audio && dir == output) || (media_type == event && dir == input))
    }

    unsafe fn getBusInfo(
        &self,
        media_type: MediaType,
        dir: BusDirection,
        index: int32,
        bus: *mut BusInfo,
    ) -> tresult {
        // SAFETY: the host passes a struct to fill, or null.
        let Some(bus) = (unsafe { bus.as_mut() }).filter(|_| index == 0) else {
            return kInvalidArgument;
        };
        let main = BusTypes_::kMain as BusType;
        let active = BusInfo_::BusFlags_::kDefaultActive as uint32;
        match (media_type as MediaTypes, dir as BusDirections) {
            (MediaTypes_::kAudio, BusDirections_::kOutput) => {
                bus.mediaType = media_type;
                bus.direction = dir;
                bus.channelCount = self.inner.channels() as int32;
                copy_wide("main", &mut bus.name);
                bus.busType = main;
                bus.flags = active;
                kResultOk
            }
            (MediaTypes_::kEvent, BusDirections_::kInput) => {
                bus.mediaType = media_type;
                bus.direction = dir;
                bus.channelCount = 16;
                copy_wide("keys and pedals", &mut bus.name);
                bus.busType = main;
                bus.flags = active;
                kResultOk
            }
            _ => kInvalidArgument,
        }
    }

    unsafe fn getRoutingInfo(
        &self,
        _in_info: *mut RoutingInfo,
        _out_info: *mut RoutingInfo,
    ) -> tresult {
        kNotImplemented
    }

    unsafe fn activateBus(
        &self,
        _media_type: MediaType,
        _dir: BusDirection,
        _index: int32,
        _state: TBool,
    ) -> tresult {
        kResultOk
    }

    unsafe fn setActive(&self, state: TBool) -> tresult {
        self.deactivate();
        if state == 0 {
            return kResultOk;
        }
        let inner = &self.inner;
        let audio = Audio::activate(inner, &|message| eprintln!("{message}"));
        let built = audio.built();
        *lock(&inner.audio) = Some(audio);
        *lock(&inner.builder) = Some(Builder::start(inner.clone(), built));
        kResultOk
    }

    unsafe fn setState(&self, stream: *mut IBStream) -> tresult {
        // SAFETY: the host's stream, or null.
        let Some(bytes) = (unsafe { read_stream(stream, state::MAX_STATE_BYTES) }) else {
            eprintln!(
                "unacorda: a saved state over {} bytes is not unacorda's: not loaded",
                state::MAX_STATE_BYTES
            );
            return kResultFalse;
        };
        match state::load(&bytes) {
            Ok(loaded) => {
                // An active piano follows a new keyboard or pool size through its builder.
                for (i, v) in loaded.into_iter().enumerate() {
                    self.inner.values.set(i, v);
                }
                kResultOk
            }
            Err(e) => {
                eprintln!("unacorda: {e}");
                kResultFalse
            }
        }
    }

    unsafe fn getState(&self, stream: *mut IBStream) -> tresult {
        // SAFETY: the host's stream, or null.
        let Some(stream) = (unsafe { ComRef::from_raw(stream) }) else {
            return kInvalidArgument;
        };
        let text = state::save(&self.inner.values);
        let mut bytes = text.as_bytes();
        while !bytes.is_empty() {
            let mut written = 0;
            // SAFETY: `bytes` holds the bytes offered.
            let result = unsafe {
                stream.write(
                    bytes.as_ptr().cast_mut().cast::<c_void>(),
                    bytes.len() as int32,
                    &mut written,
                )
            };
            let written = usize::try_from(written).unwrap_or(0).min(bytes.len());
            if result != kResultOk || written == 0 {
                return kResultFalse;
            }
            bytes = &bytes[written..];
        }
        kResultOk
    }
}

impl IAudioProcessorTrait for Component {
    unsafe fn setBusArrangements(
        &self,
        _inputs: *mut SpeakerArrangement,
        num_ins: int32,
        outputs: *mut SpeakerArrangement,
        num_outs: int32,
    ) -> tresult {
        if num_ins != 0 || num_outs != 1 || outputs.is_null() {
            return kResultFalse;
        }
        // SAFETY: one arrangement, as `num_outs` says.
        let channels = match unsafe { *outputs } {
            SpeakerArr::kMono => 1,
            SpeakerArr::kStereo => 2,
            _ => return kResultFalse,
        };
        self.inner.out_channels.store(channels, Ordering::Relaxed);
        self.inner.arranged.store(true, Ordering::Relaxed);
        kResultTrue
    }

    unsafe fn getBusArrangement(
        &self,
        dir: BusDirection,
        index: int32,
        arr: *mut SpeakerArrangement,
    ) -> tresult {
        if dir != BusDirections_::kOutput as BusDirection || index != 0 || arr.is_null() {
            return kInvalidArgument;
        }
        // SAFETY: checked not null.
        unsafe {
            *arr = match self.inner.channels() {
                1 => SpeakerArr::kMono,
                _ => SpeakerArr::kStereo,
            };
        }
        kResultOk
    }

    unsafe fn canProcessSampleSize(&self, size: int32) -> tresult {
        match size as SymbolicSampleSizes {
            SymbolicSampleSizes_::kSample32 => kResultOk,
            _ => kResultFalse,
        }
    }

    unsafe fn getLatencySamples(&self) -> uint32 {
        self.inner.latency_frames.load(Ordering::Relaxed)
    }

    unsafe fn setupProcessing(&self, setup: *mut ProcessSetup) -> tresult {
        // SAFETY: the host's setup, or null.
        let Some(setup) = (unsafe { setup.as_ref() }) else {
            return kInvalidArgument;
        };
        if setup.symbolicSampleSize != SymbolicSampleSizes_::kSample32 as int32 {
            return kResultFalse;
        }
        self.inner
            .rate_bits
            .store(setup.sampleRate.to_bits(), Ordering::Relaxed);
        let offline = setup.processMode == ProcessModes_::kOffline as int32;
        self.inner.offline.store(offline, Ordering::Relaxed);
        kResultOk
    }

    unsafe fn setProcessing(&self, state: TBool) -> tresult {
        if state == 0 {
            if let Some(audio) = lock(&self.inner.audio).as_mut() {
                audio.reset();
            }
        }
        kResultOk
    }

    unsafe fn process(&self, data: *mut ProcessData) -> tresult {
        // SAFETY: the host's block, or null.
        match unsafe { data.as_ref() } {
            // SAFETY: the host's block as VST3 defines it.
            Some(data) => unsafe { super::audio::process(&self.inner, data) },
            None => kInvalidArgument,
        }
    }

    unsafe fn getTailSamples(&self) -> uint32 {
        self.inner.tail_frames.load(Ordering::Relaxed)
    }
}

impl IProcessContextRequirementsTrait for Component {
    unsafe fn getProcessContextRequirements(&self) -> uint32 {
        // Nothing of the transport is read.
        0
    }
}

impl IEditControllerTrait for Component {
    unsafe fn setComponentState(&self, _state: *mut IBStream) -> tresult {
        // The component is the controller: its state is already the controller's.
        kResultOk
    }

    unsafe fn setState(&self, _state: *mut IBStream) -> tresult {
        kResultOk
    }

    unsafe fn getState(&self, _state: *mut IBStream) -> tresult {
        kResultOk
    }

    unsafe fn getParameterCount(&self) -> int32 {
        PARAMS.len() as int32
    }

    unsafe fn getParameterInfo(&self, param_index: int32, info: *mut ParameterInfo) -> tresult {
        let p = usize::try_from(param_index)
            .ok()
            .and_then(|i| PARAMS.get(i));
        // SAFETY: the host passes a struct to fill, or null.
        let (Some(p), Some(info)) = (p, unsafe { info.as_mut() }) else {
            return kInvalidArgument;
        };
        let i = param_index as usize;
        info.id = p.id;
        copy_wide(p.name, &mut info.title);
        copy_wide(p.key, &mut info.shortTitle);
        copy_wide(
            if i == params::GAIN_DB { "dB" } else { "" },
            &mut info.units,
        );
        info.stepCount = if p.stepped {
            (p.max - p.min).round() as int32
        } else {
            0
        };
        info.defaultNormalizedValue = normalised(i, p.default);
        info.unitId = 0;
        let mut flags = 0;
        if p.automatable {
            flags |= ParameterInfo_::ParameterFlags_::kCanAutomate;
        }
        if p.choices.is_some() {
            flags |= ParameterInfo_::ParameterFlags_::kIsList;
        }
        info.flags = flags as int32;
        kResultOk
    }

    unsafe fn getParamStringByValue(
        &self,
        id: ParamID,
        value_normalized: ParamValue,
        string: *mut String128,
    ) -> tresult {
        // SAFETY: the host passes a buffer to fill, or null.
        let (Some(i), Some(string)) = (index(id), unsafe { string.as_mut() }) else {
            return kInvalidArgument;
        };
        let mut text = String::new();
        if params::write_text(i, plain(i, value_normalized), &mut text).is_err() {
            return kResultFalse;
        }
        copy_wide(&text, string);
        kResultOk
    }

    unsafe fn getParamValueByString(
        &self,
        id: ParamID,
        string: *mut TChar,
        value_normalized: *mut ParamValue,
    ) -> tresult {
        // SAFETY: a host's string is zero-ended within a String128.
        let text = unsafe { read_wide(string, 128) };
        let value = index(id).and_then(|i| Some((i, params::parse_text(i, &text?)?)));
        match (value, value_normalized.is_null()) {
            (Some((i, v)), false) => {
                // SAFETY: checked not null.
                unsafe { *value_normalized = normalised(i, v) };
                kResultOk
            }
            _ => kResultFalse,
        }
    }

    unsafe fn normalizedParamToPlain(
        &self,
        id: ParamID,
        value_normalized: ParamValue,
    ) -> ParamValue {
        index(id).map_or(0.0, |i| plain(i, value_normalized))
    }

    unsafe fn plainParamToNormalized(&self, id: ParamID, plain_value: ParamValue) -> ParamValue {
        index(id).map_or(0.0, |i| normalised(i, plain_value))
    }

    unsafe fn getParamNormalized(&self, id: ParamID) -> ParamValue {
        index(id).map_or(0.0, |i| normalised(i, self.inner.values.get(i)))
    }

    unsafe fn setParamNormalized(&self, id: ParamID, value: ParamValue) -> tresult {
        match index(id) {
            Some(i) => {
                self.inner.values.set(i, plain(i, value));
                kResultOk
            }
            None => kInvalidArgument,
        }
    }

    unsafe fn setComponentHandler(&self, handler: *mut IComponentHandler) -> tresult {
        // SAFETY: the host's handler, or null; kept with a reference of our own.
        *lock(&self.inner.handler) = unsafe { ComRef::from_raw(handler) }.map(|h| h.to_com_ptr());
        kResultOk
    }

    unsafe fn createView(&self, name: FIDString) -> *mut IPlugView {
        // SAFETY: the host's zero-ended view name, or null.
        if name.is_null() || unsafe { std::ffi::CStr::from_ptr(name) }.to_bytes() != b"editor" {
            return std::ptr::null_mut();
        }
        ComWrapper::new(View::new(self.inner.clone()))
            .to_com_ptr::<IPlugView>()
            .map_or(std::ptr::null_mut(), |v| v.into_raw())
    }
}

impl IMidiMappingTrait for Component {
    /// The pedals' controllers (CC64 sustain, CC66 sostenuto, CC67 soft, on any channel) as
    /// their parameters: VST3 hosts deliver MIDI controllers only so.
    unsafe fn getMidiControllerAssignment(
        &self,
        bus_index: int32,
        _channel: int16,
        controller: CtrlNumber,
        id: *mut ParamID,
    ) -> tresult {
        let pedal = match controller {
            64 => SUSTAIN,
            66 => SOSTENUTO,
            67 => SOFT,
            _ => return kResultFalse,
        };
        if bus_index != 0 || id.is_null() {
            return kResultFalse;
        }
        // SAFETY: checked not null.
        unsafe { *id = PARAMS[pedal].id };
        kResultOk
    }
}
