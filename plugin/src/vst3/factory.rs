//! The VST3 factory (one class: the instrument, in the category hosts list instruments under)
//! and the three functions a VST3 library exports on Linux.

use super::component::Component;
use super::copy_narrow;
use std::ffi::c_void;
use vst3::Steinberg::Vst::SDKVersionString;
use vst3::Steinberg::*;
use vst3::{uid, Class, ComWrapper};

/// The instrument's class id: the same in every build, so that hosts find saved sessions' plugin.
pub const CLASS_ID: TUID = uid(0x756E6163, 0x6F726461, 0x5069616E, 0x6F564633);

/// The SDK's category of a processor's class (`kVstAudioEffectClass`).
const CATEGORY: &str = "Audio Module Class";

/// Hosts may make any number of instances.
const MANY: int32 = PClassInfo_::ClassCardinality_::kManyInstances as int32;

/// What hosts list it as: an instrument, a piano.
const SUBCATEGORIES: &str = "Instrument|Piano";

/// The factory hosts get from [`GetPluginFactory`].
pub struct Factory;

impl Class for Factory {
    type Interfaces = (IPluginFactory2,);
}

impl IPluginFactoryTrait for Factory {
    unsafe fn getFactoryInfo(&self, info: *mut PFactoryInfo) -> tresult {
        // SAFETY: the host passes a struct to fill, or null.
        let Some(info) = (unsafe { info.as_mut() }) else {
            return kInvalidArgument;
        };
        copy_narrow("unacorda", &mut info.vendor);
        copy_narrow("https://github.com/unacorda/unacorda", &mut info.url);
        copy_narrow("", &mut info.email);
        info.flags = PFactoryInfo_::FactoryFlags_::kUnicode as int32;
        kResultOk
    }

    unsafe fn countClasses(&self) -> int32 {
        1
    }

    unsafe fn getClassInfo(&self, index: int32, info: *mut PClassInfo) -> tresult {
        // SAFETY: the host passes a struct to fill, or null.
        let Some(info) = (unsafe { info.as_mut() }).filter(|_| index == 0) else {
            return kInvalidArgument;
        };
        (info.cid, info.cardinality) = (CLASS_ID, MANY);
        copy_narrow(CATEGORY, &mut info.category);
        copy_narrow("unacorda", &mut info.name);
        kResultOk
    }

    unsafe fn createInstance(
        &self,
        cid: FIDString,
        iid: FIDString,
        obj: *mut *mut c_void,
    ) -> tresult {
        if cid.is_null() || iid.is_null() || obj.is_null() {
            return kInvalidArgument;
        }
        // SAFETY: a class id is 16 bytes.
        if unsafe { *cid.cast::<TUID>() } != CLASS_ID {
            return kInvalidArgument;
        }
        let Some(instance) = ComWrapper::new(Component::new()).to_com_ptr::<FUnknown>() else {
            return kNoInterface;
        };
        let ptr = instance.as_ptr();
        // SAFETY: a live object; the host's iid is 16 bytes, `obj` where to write the result.
        unsafe { ((*(*ptr).vtbl).queryInterface)(ptr, iid.cast::<TUID>(), obj) }
    }
}

impl IPluginFactory2Trait for Factory {
    unsafe fn getClassInfo2(&self, index: int32, info: *mut PClassInfo2) -> tresult {
        // SAFETY: the host passes a struct to fill, or null.
        let Some(info) = (unsafe { info.as_mut() }).filter(|_| index == 0) else {
            return kInvalidArgument;
        };
        (info.cid, info.cardinality, info.classFlags) = (CLASS_ID, MANY, 0);
        copy_narrow(CATEGORY, &mut info.category);
        copy_narrow("unacorda", &mut info.name);
        copy_narrow(SUBCATEGORIES, &mut info.subCategories);
        copy_narrow("unacorda", &mut info.vendor);
        copy_narrow(env!("CARGO_PKG_VERSION"), &mut info.version);
        copy_class_text(SDKVersionString, &mut info.sdkVersion);
        kResultOk
    }
}

/// One of the SDK's C strings into a host's buffer.
fn copy_class_text(text: *const std::ffi::c_char, dest: &mut [std::ffi::c_char]) {
    // SAFETY: the SDK's constants are zero-ended static strings.
    let text = unsafe { std::ffi::CStr::from_ptr(text) };
    copy_narrow(&text.to_string_lossy(), dest);
}

/// The factory (a new reference each call; the host releases it).
#[unsafe(no_mangle)]
pub extern "system" fn GetPluginFactory() -> *mut IPluginFactory {
    ComWrapper::new(Factory)
        .to_com_ptr::<IPluginFactory>()
        .map_or(std::ptr::null_mut(), |f| f.into_raw())
}

/// Called once as the library is loaded: nothing to set up.
#[cfg(target_os = "linux")]
#[unsafe(no_mangle)]
pub extern "system" fn ModuleEntry(_library: *mut c_void) -> bool {
    true
}

/// Called once before the library is unloaded: nothing to tear down.
#[cfg(target_os = "linux")]
#[unsafe(no_mangle)]
pub extern "system" fn ModuleExit() -> bool {
    true
}
