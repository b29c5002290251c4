//! unacorda as a CLAP instrument: the command line's engine (the exact engine on the keyboard's
//! 88 keys and one soundboard, [`unacorda::audio::Synth`]) driven by a host. Notes arrive in
//! CLAP's and MIDI's dialects (the pedals as MIDI CC64/66/67 or as parameters) and are played at
//! their frame; the synth renders on its grid one cell behind the host
//! ([`unacorda::audio::Aligned`], reported as latency), so every sample is the one
//! `unacorda render --offline --midi` gives for the same events, whatever the host's blocks.
//!
//! - [`entry`]: the entry point hosts load (clack's, `process` guarded against a malformed
//!   transport),
//! - [`params`]: the parameters and their shared values,
//! - [`state`]: the saved state (versioned text, refused when foreign or newer),
//! - [`prepare`]: the 88 keys prepared once per process, shared by instances and activations,
//! - [`rebuild`]: a new keyboard or pool size built in the background while the old one plays,
//! - [`processor`]: the audio thread's side,
//! - [`sound`]: what both formats play (the synth, the pedals followed, the output stage),
//! - [`vst3`]: the same instrument as a VST3 plugin.

use clack_extensions::audio_ports::{
    AudioPortFlags, AudioPortInfo, AudioPortInfoWriter, AudioPortRescanFlags, AudioPortType,
    HostAudioPorts, PluginAudioPorts, PluginAudioPortsImpl,
};
use clack_extensions::gui::PluginGui;
use clack_extensions::latency::{PluginLatency, PluginLatencyImpl};
use clack_extensions::log::{HostLog, LogSeverity};
use clack_extensions::note_ports::{
    NoteDialect, NoteDialects, NotePortInfo, NotePortInfoWriter, PluginNotePorts,
    PluginNotePortsImpl,
};
use clack_extensions::params::{
    HostParams, ParamDisplayWriter, ParamInfo, ParamInfoFlags, ParamInfoWriter, ParamRescanFlags,
    PluginAudioProcessorParams, PluginMainThreadParams, PluginParams,
};
use clack_extensions::render::{PluginRender, PluginRenderImpl, RenderMode};
use clack_extensions::state::{PluginState, PluginStateImpl};
use clack_extensions::tail::PluginTail;
use clack_extensions::thread_pool::{PluginThreadPool, PluginThreadPoolImpl};
use clack_plugin::events::spaces::CoreEventSpace;
use clack_plugin::prelude::*;
use clack_plugin::stream::{InputStream, OutputStream};
use std::cell::{Cell, RefCell};
use std::ffi::CStr;
use std::io::{Read, Write as _};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use unacorda::audio::activity::Activity;
use unacorda::audio::host_pool::Rendezvous;

pub mod clap_gui;
pub mod editor;
pub mod entry;
pub mod params;
pub mod prepare;
pub mod processor;
pub mod rebuild;
pub mod sound;
pub mod state;
pub mod vst3;

use params::{Values, PARAMS, REBUILDS};
use unacorda::engine::Integrator;

/// The plugin's id in hosts.
pub const PLUGIN_ID: &str = "org.unacorda.piano";

/// The plugin type clack builds instances of.
pub struct Unacorda;

/// What the main thread and the audio thread share.
pub struct Shared {
    /// The parameters' values (both threads, and the editor's).
    pub values: Arc<Values>,
    /// What the piano is doing, published by the audio thread for the editor.
    pub activity: Arc<Activity>,
    /// The parameters the editor changed, for the audio thread to tell the host.
    pub edits: Arc<editor::Edits>,
    /// The latency the active processor reports, in host frames (written by the main thread at
    /// activation, read by the host through the main thread).
    pub latency_frames: AtomicU32,
    /// Why the last activation plays silent, if it does (main thread).
    pub silent_because: Mutex<Option<String>>,
    /// The background build a change of keyboard or pool size asks for (both threads and the
    /// build thread; [`rebuild::Rebuild`] says which touches what).
    pub rebuild: rebuild::Rebuild,
    /// The engine's two halves handed to the host's thread pool (the audio thread posts them,
    /// the host's workers run them: [`unacorda::audio::host_pool`]).
    pub pool: Rendezvous,
    /// The host renders offline (CLAP's render extension: written by the main thread, read by
    /// both).
    pub offline: AtomicBool,
}

impl PluginShared<'_> for Shared {}

impl Shared {
    /// The integrator played ([`Values::integrator_played`]).
    pub fn integrator(&self) -> Integrator {
        self.values
            .integrator_played(self.offline.load(Ordering::Relaxed))
    }

    /// The values whose change rebuilds the piano, the integrator as played ([`Values::played`]).
    pub fn played(&self) -> [f64; REBUILDS.len()] {
        self.values.played(self.offline.load(Ordering::Relaxed))
    }
}

impl PluginThreadPoolImpl for Shared {
    /// A task of the host's pool, asked for by the audio thread inside `process`.
    fn exec(&self, task_index: u32) {
        self.pool.exec(task_index);
    }
}

/// The main thread's side.
pub struct MainThread<'a> {
    shared: &'a Shared,
    host: HostMainThreadHandle<'a>,
    /// The output port's channels as the host last read them (0: not yet read).
    announced_channels: Cell<u32>,
    /// The editor, when the host shows it.
    gui: RefCell<clap_gui::Gui>,
}

impl<'a> PluginMainThread<'a, Shared> for MainThread<'a> {
    /// The audio thread asked for a piano to be built: start it in the background.
    fn on_main_thread(&self) {
        let values = &self.shared.values;
        self.shared
            .rebuild
            .start_if_wanted(values.keyboard(), self.shared.integrator());
        self.follow_ports();
    }
}

impl Drop for MainThread<'_> {
    /// No build thread outlives the instance (nor, so, the plugin's code).
    fn drop(&mut self) {
        self.shared.rebuild.join();
    }
}

impl Plugin for Unacorda {
    type AudioProcessor<'a> = processor::Processor<'a>;
    type Shared<'a> = Shared;
    type MainThread<'a> = MainThread<'a>;

    fn declare_extensions(builder: &mut PluginExtensions<Self>, _shared: Option<&Shared>) {
        builder
            .register::<PluginAudioPorts>()
            .register::<PluginNotePorts>()
            .register::<PluginParams>()
            .register::<PluginState>()
            .register::<PluginLatency>()
            .register::<PluginTail>()
            .register::<PluginThreadPool>()
            .register::<PluginRender>()
            .register::<PluginGui>();
    }
}

impl DefaultPluginFactory for Unacorda {
    fn get_descriptor() -> PluginDescriptor {
        use clack_plugin::plugin::features::*;
        PluginDescriptor::new(PLUGIN_ID, "unacorda")
            .with_vendor("unacorda")
            .with_version(env!("CARGO_PKG_VERSION"))
            .with_description(
                "Physical-modelling grand piano: coupled stiff strings, felt hammers, a modal soundboard and a real una corda",
            )
            .with_features([INSTRUMENT, SYNTHESIZER, STEREO])
    }

    fn new_shared(_host: HostSharedHandle) -> Result<Shared, PluginError> {
        Ok(Shared {
            values: Arc::default(),
            activity: Arc::default(),
            edits: Arc::default(),
            latency_frames: AtomicU32::new(0),
            silent_because: Mutex::new(None),
            rebuild: rebuild::Rebuild::default(),
            pool: Rendezvous::default(),
            offline: AtomicBool::new(false),
        })
    }

    fn new_main_thread<'a>(
        host: HostMainThreadHandle<'a>,
        shared: &'a Shared,
    ) -> Result<MainThread<'a>, PluginError> {
        Ok(MainThread {
            shared,
            host,
            announced_channels: Cell::new(0),
            gui: RefCell::default(),
        })
    }
}

impl MainThread<'_> {
    /// What the editor shows and changes.
    fn shown(&self) -> editor::Shown {
        editor::Shown {
            values: self.shared.values.clone(),
            activity: self.shared.activity.clone(),
            edits: self.shared.edits.clone(),
        }
    }

    /// The channels of the keyboard chosen: 2 for a stereo pair of listeners, 1 for one (a
    /// keyboard that cannot be read plays silence: 2).
    fn keyboard_channels(&self) -> u32 {
        crate::prepare::channels(self.shared.values.keyboard())
    }

    /// Where the keyboard chosen has another number of channels than the port the host read,
    /// have the host read the port again — only while inactive, as CLAP allows a change of
    /// channels. While active the output follows the engine whatever the port (a mono piano in
    /// both channels of a stereo port, a stereo one mixed into a mono port) until the next
    /// deactivation, which asks for a main-thread callback to come here.
    fn follow_ports(&self) {
        let announced = self.announced_channels.get();
        if announced == 0 || self.shared.rebuild.active() || announced == self.keyboard_channels() {
            return;
        }
        let Some(ports) = self.host.get_extension::<HostAudioPorts>() else {
            return;
        };
        let flags = [
            AudioPortRescanFlags::CHANNEL_COUNT | AudioPortRescanFlags::PORT_TYPE,
            AudioPortRescanFlags::LIST,
        ]
        .into_iter()
        .find(|&f| ports.is_rescan_flag_supported(&self.host, f));
        if let Some(flags) = flags {
            ports.rescan(&self.host, flags);
        }
    }

    /// A main-thread callback, if the port has other channels than the keyboard chosen
    /// ([`MainThread::follow_ports`]).
    fn ask_to_follow_ports(&self) {
        let announced = self.announced_channels.get();
        if announced != 0 && announced != self.keyboard_channels() {
            self.host.request_callback();
        }
    }

    /// Tell the host (its log, else standard error) something the user should know.
    fn warn(&self, message: &str) {
        match self.host.get_extension::<HostLog>() {
            Some(log) => {
                let text = std::ffi::CString::new(message.replace('\0', " ")).unwrap_or_default();
                log.log(&self.host.shared(), LogSeverity::Warning, &text);
            }
            None => eprintln!("{message}"),
        }
    }
}

impl PluginAudioPortsImpl for MainThread<'_> {
    fn count(&self, is_input: bool) -> u32 {
        if is_input {
            0
        } else {
            1
        }
    }

    /// One output, as many channels as the keyboard chosen has.
    fn get(&self, index: u32, is_input: bool, writer: &mut AudioPortInfoWriter) {
        if !is_input && index == 0 {
            let channels = self.keyboard_channels();
            self.announced_channels.set(channels);
            writer.set(&AudioPortInfo {
                id: ClapId::new(0),
                name: b"main",
                channel_count: channels,
                flags: AudioPortFlags::IS_MAIN,
                port_type: Some(match channels {
                    1 => AudioPortType::MONO,
                    _ => AudioPortType::STEREO,
                }),
                in_place_pair: None,
            });
        }
    }
}

impl PluginNotePortsImpl for MainThread<'_> {
    fn count(&self, is_input: bool) -> u32 {
        u32::from(is_input)
    }

    fn get(&self, index: u32, is_input: bool, writer: &mut NotePortInfoWriter) {
        if is_input && index == 0 {
            writer.set(&NotePortInfo {
                id: ClapId::new(0),
                name: b"keys and pedals",
                preferred_dialect: Some(NoteDialect::Clap),
                // MIDI too: hosts send the pedals (CC64, 66, 67) only as MIDI.
                supported_dialects: NoteDialects::CLAP | NoteDialects::MIDI,
            });
        }
    }
}

impl PluginLatencyImpl for MainThread<'_> {
    fn get(&self) -> u32 {
        self.shared.latency_frames.load(Ordering::Relaxed)
    }
}

impl PluginMainThreadParams for MainThread<'_> {
    fn count(&self) -> u32 {
        PARAMS.len() as u32
    }

    fn get_info(&self, param_index: u32, info: &mut ParamInfoWriter) {
        let Some(p) = PARAMS.get(param_index as usize) else {
            return;
        };
        let mut flags = ParamInfoFlags::empty();
        if p.stepped {
            flags |= ParamInfoFlags::IS_STEPPED;
        }
        if p.automatable {
            flags |= ParamInfoFlags::IS_AUTOMATABLE;
        } else {
            flags |= ParamInfoFlags::REQUIRES_PROCESS;
        }
        if p.choices.is_some() {
            flags |= ParamInfoFlags::IS_ENUM;
        }
        info.set(&ParamInfo {
            id: ClapId::new(p.id),
            flags,
            cookie: Default::default(),
            name: p.name.as_bytes(),
            module: b"",
            min_value: p.min,
            max_value: p.max,
            default_value: p.default,
        });
    }

    fn get_value(&self, param_id: ClapId) -> Option<f64> {
        params::index_of(param_id.get()).map(|i| self.shared.values.get(i))
    }

    fn value_to_text(
        &self,
        param_id: ClapId,
        value: f64,
        writer: &mut ParamDisplayWriter,
    ) -> std::fmt::Result {
        let i = params::index_of(param_id.get()).ok_or(std::fmt::Error)?;
        params::write_text(i, value, writer)
    }

    fn text_to_value(&self, param_id: ClapId, text: &CStr) -> Option<f64> {
        let i = params::index_of(param_id.get())?;
        params::parse_text(i, text.to_str().ok()?)
    }

    fn flush(&self, input: &InputEvents, _output: &mut OutputEvents) {
        // The processor is not active: values are only stored (a rebuild parameter's change is
        // built at the next activation; a keyboard with other channels rescans the port).
        for event in input {
            if let Some(CoreEventSpace::ParamValue(e)) = event.as_core_event() {
                if let Some(i) = e.param_id().and_then(|id| params::index_of(id.get())) {
                    self.shared.values.set(i, e.value());
                }
            }
        }
        self.follow_ports();
    }
}

impl PluginAudioProcessorParams for processor::Processor<'_> {
    fn flush(&mut self, input: &InputEvents, output: &mut OutputEvents) {
        for event in input {
            self.handle(event);
        }
        self.tell_edits(output);
        self.follow_rebuild();
    }
}

impl PluginRenderImpl for MainThread<'_> {
    fn has_hard_realtime_requirement(&self) -> bool {
        false
    }

    /// Offline, the integrator chosen plays (RK4 among them); live, the exact engine. An active
    /// processor follows a change by a background build and a restart, as for a parameter.
    fn set(&self, mode: RenderMode) -> Result<(), PluginError> {
        let offline = mode == RenderMode::Offline;
        let before = self.shared.offline.swap(offline, Ordering::Relaxed);
        if before != offline && self.shared.rebuild.active() {
            self.host.shared().request_process();
        }
        Ok(())
    }
}

impl PluginStateImpl for MainThread<'_> {
    fn save(&self, output: &mut OutputStream) -> Result<(), PluginError> {
        output.write_all(state::save(&self.shared.values).as_bytes())?;
        Ok(())
    }

    fn load(&self, input: &mut InputStream) -> Result<(), PluginError> {
        let mut bytes = Vec::new();
        input
            .take(state::MAX_STATE_BYTES as u64 + 1)
            .read_to_end(&mut bytes)?;
        // A refusal's reason reaches the host's log through clack.
        let loaded = state::load(&bytes).map_err(|e| PluginError::Error(Box::new(e)))?;
        let rebuild = REBUILDS
            .iter()
            .any(|&i| self.shared.values.get(i) != loaded[i]);
        for (i, v) in loaded.into_iter().enumerate() {
            self.shared.values.set(i, v);
        }
        if let Some(host_params) = self.host.get_extension::<HostParams>() {
            host_params.rescan(&self.host, ParamRescanFlags::VALUES);
        }
        if rebuild && self.shared.rebuild.active() {
            // The processor sees the new keyboard or pool size at its next block (woken if it
            // sleeps), has it built in the background and asks for a restart; an inactive one
            // builds it at its activation.
            self.host.shared().request_process();
        }
        self.follow_ports();
        Ok(())
    }
}
