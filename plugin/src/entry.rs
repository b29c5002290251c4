//! The entry point hosts load (`clap_entry`): clack's, with a guard in front of `process`.
//!
//! Qtractor (0.9.31, and its source as of this writing) clears its transport event and fills in
//! the fields but not the header, so the header says size 0, type 0. clack-plugin 0.2.0 checks the
//! transport's header before the plugin sees the block and panics on a mismatch: every block
//! failed and unacorda was silent in Qtractor. The guard passes such a transport on as none (the
//! plugin does not read the transport); every other call goes to clack as it is.

use clack_plugin::entry::{EntryDescriptor, SinglePluginEntry};
use clap_sys::events::{CLAP_CORE_EVENT_SPACE_ID, CLAP_EVENT_TRANSPORT};
use clap_sys::factory::plugin_factory::{clap_plugin_factory, CLAP_PLUGIN_FACTORY_ID};
use clap_sys::host::clap_host;
use clap_sys::plugin::{clap_plugin, clap_plugin_descriptor};
use clap_sys::process::{clap_process, clap_process_status, CLAP_PROCESS_ERROR};
use std::ffi::{c_char, c_void, CStr};
use std::sync::atomic::{AtomicPtr, Ordering};
use std::sync::OnceLock;

/// clack's entry, not exported.
static CLACK: EntryDescriptor = clack_plugin::clack_entry!(SinglePluginEntry<crate::Unacorda>);

/// The entry hosts find in the library.
#[allow(non_upper_case_globals)]
#[unsafe(no_mangle)]
pub static clap_entry: EntryDescriptor = EntryDescriptor {
    clap_version: clap_sys::version::CLAP_VERSION,
    init: Some(init),
    deinit: Some(deinit),
    get_factory: Some(get_factory),
};

/// The plugin factory hosts see: clack's, each instance's `process` guarded.
static FACTORY: clap_plugin_factory = clap_plugin_factory {
    get_plugin_count: Some(plugin_count),
    get_plugin_descriptor: Some(plugin_descriptor),
    create_plugin: Some(create_plugin),
};

/// clack's plugin factory (set by `get_factory`).
static CLACK_FACTORY: AtomicPtr<clap_plugin_factory> = AtomicPtr::new(std::ptr::null_mut());

type Process = unsafe extern "C" fn(*const clap_plugin, *const clap_process) -> clap_process_status;

/// clack's `process` (the same function for every instance of the one plugin type).
static CLACK_PROCESS: OnceLock<Process> = OnceLock::new();

unsafe extern "C" fn init(plugin_path: *const c_char) -> bool {
    // SAFETY: the host's call, passed on.
    CLACK.init.is_some_and(|f| unsafe { f(plugin_path) })
}

unsafe extern "C" fn deinit() {
    if let Some(f) = CLACK.deinit {
        // SAFETY: the host's call, passed on.
        unsafe { f() }
    }
}

unsafe extern "C" fn get_factory(factory_id: *const c_char) -> *const c_void {
    let Some(get) = CLACK.get_factory else {
        return std::ptr::null();
    };
    // SAFETY: the host's call, passed on.
    let theirs = unsafe { get(factory_id) };
    // SAFETY: a factory id is a C string (CLAP).
    let id = unsafe { CStr::from_ptr(factory_id) };
    if theirs.is_null() || id != CLAP_PLUGIN_FACTORY_ID {
        return theirs;
    }
    CLACK_FACTORY.store(theirs as *mut clap_plugin_factory, Ordering::Release);
    (&raw const FACTORY).cast()
}

/// clack's factory, where `get_factory` gave it out.
fn clack_factory() -> Option<&'static clap_plugin_factory> {
    // SAFETY: the pointer is clack's static factory, valid for the library's life.
    unsafe { CLACK_FACTORY.load(Ordering::Acquire).as_ref() }
}

unsafe extern "C" fn plugin_count(_factory: *const clap_plugin_factory) -> u32 {
    clack_factory()
        .and_then(|f| Some((f, f.get_plugin_count?)))
        // SAFETY: clack's factory, called with itself.
        .map_or(0, |(f, count)| unsafe { count(f) })
}

unsafe extern "C" fn plugin_descriptor(
    _factory: *const clap_plugin_factory,
    index: u32,
) -> *const clap_plugin_descriptor {
    clack_factory()
        .and_then(|f| Some((f, f.get_plugin_descriptor?)))
        // SAFETY: clack's factory, called with itself.
        .map_or(std::ptr::null(), |(f, get)| unsafe { get(f, index) })
}

unsafe extern "C" fn create_plugin(
    _factory: *const clap_plugin_factory,
    host: *const clap_host,
    plugin_id: *const c_char,
) -> *const clap_plugin {
    let Some((f, create)) = clack_factory().and_then(|f| Some((f, f.create_plugin?))) else {
        return std::ptr::null();
    };
    // SAFETY: clack's factory, called with itself and the host's arguments.
    let plugin = unsafe { create(f, host, plugin_id) };
    if plugin.is_null() {
        return plugin;
    }
    // SAFETY: clack hands over a new instance it allocated (a leaked `Box<clap_plugin>`): nothing
    // refers to it yet, and it is this call's to give to the host.
    let plugin = plugin.cast_mut();
    unsafe {
        if let Some(theirs) = (*plugin).process {
            let _ = CLACK_PROCESS.set(theirs);
            (*plugin).process = Some(process);
        }
    }
    plugin
}

/// Whether a transport event's header says it is one (what clack checks).
pub fn is_transport(header: &clap_sys::events::clap_event_header) -> bool {
    header.space_id == CLAP_CORE_EVENT_SPACE_ID && header.type_ == CLAP_EVENT_TRANSPORT
}

/// clack's `process`, a transport that is not one passed on as none.
unsafe extern "C" fn process(
    plugin: *const clap_plugin,
    block: *const clap_process,
) -> clap_process_status {
    let Some(theirs) = CLACK_PROCESS.get() else {
        return CLAP_PROCESS_ERROR;
    };
    // SAFETY: the host's block, valid for this call (CLAP); read, not kept.
    let bad = unsafe {
        block
            .as_ref()
            .and_then(|b| b.transport.as_ref())
            .is_some_and(|t| !is_transport(&t.header))
    };
    if !bad {
        // SAFETY: the host's call, passed on.
        return unsafe { theirs(plugin, block) };
    }
    // SAFETY: as above; the copy lives through the call.
    let mut copy = unsafe { *block };
    copy.transport = std::ptr::null();
    unsafe { theirs(plugin, &copy) }
}
