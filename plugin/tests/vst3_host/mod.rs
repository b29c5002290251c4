//! A headless VST3 host for the plugin's tests, on the `vst3` crate's bindings: the host's side
//! of a block (an event list, parameter queues, an output bus) and a memory stream for state.

#![allow(non_snake_case)]

use std::cell::{Cell, RefCell};
use std::ffi::c_void;
use vst3::Steinberg::Vst::*;
use vst3::Steinberg::*;
use vst3::{Class, ComPtr, ComWrapper};

/// A block's note events, in time order.
pub struct EventList(pub Vec<Event>);

impl Class for EventList {
    type Interfaces = (IEventList,);
}

impl IEventListTrait for EventList {
    unsafe fn getEventCount(&self) -> int32 {
        self.0.len() as int32
    }
    unsafe fn getEvent(&self, index: int32, e: *mut Event) -> tresult {
        match self.0.get(index as usize) {
            Some(event) => {
                unsafe { *e = *event };
                kResultOk
            }
            None => kInvalidArgument,
        }
    }
    unsafe fn addEvent(&self, _e: *mut Event) -> tresult {
        kNotImplemented
    }
}

/// One parameter's changes within a block: (frame, normalised value).
pub struct Queue {
    pub id: ParamID,
    pub points: Vec<(int32, f64)>,
}

impl Class for Queue {
    type Interfaces = (IParamValueQueue,);
}

impl IParamValueQueueTrait for Queue {
    unsafe fn getParameterId(&self) -> ParamID {
        self.id
    }
    unsafe fn getPointCount(&self) -> int32 {
        self.points.len() as int32
    }
    unsafe fn getPoint(&self, index: int32, offset: *mut int32, value: *mut ParamValue) -> tresult {
        match self.points.get(index as usize) {
            Some(&(o, v)) => {
                unsafe { (*offset, *value) = (o, v) };
                kResultOk
            }
            None => kInvalidArgument,
        }
    }
    unsafe fn addPoint(&self, _o: int32, _v: ParamValue, _i: *mut int32) -> tresult {
        kNotImplemented
    }
}

/// A block's parameter changes.
pub struct Changes(pub Vec<ComPtr<IParamValueQueue>>);

impl Class for Changes {
    type Interfaces = (IParameterChanges,);
}

impl IParameterChangesTrait for Changes {
    unsafe fn getParameterCount(&self) -> int32 {
        self.0.len() as int32
    }
    unsafe fn getParameterData(&self, index: int32) -> *mut IParamValueQueue {
        self.0
            .get(index as usize)
            .map_or(std::ptr::null_mut(), |q| q.as_ptr())
    }
    unsafe fn addParameterData(
        &self,
        _id: *const ParamID,
        _i: *mut int32,
    ) -> *mut IParamValueQueue {
        std::ptr::null_mut()
    }
}

/// A stream in memory.
#[derive(Default)]
pub struct Stream {
    pub bytes: RefCell<Vec<u8>>,
    at: Cell<usize>,
}

impl Class for Stream {
    type Interfaces = (IBStream,);
}

impl IBStreamTrait for Stream {
    unsafe fn read(&self, buffer: *mut c_void, n: int32, read: *mut int32) -> tresult {
        let bytes = self.bytes.borrow();
        let at = self.at.get();
        let n = (n.max(0) as usize).min(bytes.len() - at);
        unsafe { std::ptr::copy_nonoverlapping(bytes[at..].as_ptr(), buffer.cast::<u8>(), n) };
        self.at.set(at + n);
        if !read.is_null() {
            unsafe { *read = n as int32 };
        }
        kResultOk
    }
    unsafe fn write(&self, buffer: *mut c_void, n: int32, written: *mut int32) -> tresult {
        let n = n.max(0) as usize;
        let data = unsafe { std::slice::from_raw_parts(buffer.cast::<u8>(), n) };
        self.bytes.borrow_mut().extend_from_slice(data);
        if !written.is_null() {
            unsafe { *written = n as int32 };
        }
        kResultOk
    }
    unsafe fn seek(&self, pos: int64, _mode: int32, result: *mut int64) -> tresult {
        self.at.set(pos as usize);
        if !result.is_null() {
            unsafe { *result = pos };
        }
        kResultOk
    }
    unsafe fn tell(&self, pos: *mut int64) -> tresult {
        unsafe { *pos = self.at.get() as int64 };
        kResultOk
    }
}

/// A stream holding `bytes`, read from the start.
pub fn stream(bytes: &[u8]) -> ComPtr<IBStream> {
    let s = Stream::default();
    s.bytes.borrow_mut().extend_from_slice(bytes);
    ComWrapper::new(s).to_com_ptr::<IBStream>().unwrap()
}

/// A note-on (`on`) or note-off event at `offset`.
pub fn note(offset: i32, pitch: i16, velocity: f32, on: bool) -> Event {
    let mut e: Event = unsafe { std::mem::zeroed() };
    e.sampleOffset = offset;
    if on {
        e.r#type = Event_::EventTypes_::kNoteOnEvent as u16;
        e.__field0.noteOn = NoteOnEvent {
            channel: 0,
            pitch,
            tuning: 0.0,
            velocity,
            length: 0,
            noteId: -1,
        };
    } else {
        e.r#type = Event_::EventTypes_::kNoteOffEvent as u16;
        e.__field0.noteOff = NoteOffEvent {
            channel: 0,
            pitch,
            velocity,
            noteId: -1,
            tuning: 0.0,
        };
    }
    e
}
