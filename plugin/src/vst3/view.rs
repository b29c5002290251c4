//! The VST3 editor: the plugin's window ([`crate::editor`]) embedded in the host's X11 window
//! (`IPlugView`), at the host's content scale, resizable. A change made in the window reaches the
//! host through its component handler (`beginEdit`, `performEdit`, `endEdit`), which must be
//! called on the host's UI thread: a timer on the host's run loop (`Linux::IRunLoop`, from the
//! view's frame) hands them over. Every method here runs on the host's UI thread.

use super::component::{normalised, Inner};
use crate::editor::{self, X11Parent};
use crate::params::PARAMS;
use std::cell::{Cell, RefCell};
use std::ffi::{c_void, CStr};
use std::sync::Arc;
use vst3::Steinberg::Linux::{IRunLoop, IRunLoopTrait, ITimerHandler, ITimerHandlerTrait};
use vst3::Steinberg::Vst::IComponentHandlerTrait;
use vst3::Steinberg::*;
use vst3::{Class, ComPtr, ComRef, ComWrapper};

/// How often the host's run loop hands the window's changes to the host (ms).
const EDITS_MS: u64 = 30;

/// The editor's view of one plugin instance.
pub struct View {
    inner: Arc<Inner>,
    window: RefCell<Option<editor::Window>>,
    /// The size in logical pixels and the host's scale.
    size: Cell<(f64, f64)>,
    scale: Cell<f64>,
    /// The host's frame, and the timer registered on its run loop while attached.
    frame: RefCell<Option<ComPtr<IPlugFrame>>>,
    timer: RefCell<Option<(ComPtr<IRunLoop>, ComPtr<ITimerHandler>)>>,
}

impl Class for View {
    type Interfaces = (IPlugView, IPlugViewContentScaleSupport);
}

impl View {
    pub fn new(inner: Arc<Inner>) -> View {
        View {
            inner,
            window: RefCell::new(None),
            size: Cell::new((editor::WIDTH, editor::HEIGHT)),
            scale: Cell::new(1.0),
            frame: RefCell::new(None),
            timer: RefCell::new(None),
        }
    }

    fn physical(&self) -> ViewRect {
        let (w, h) = editor::physical(self.size.get(), self.scale.get());
        ViewRect {
            left: 0,
            top: 0,
            right: w as int32,
            bottom: h as int32,
        }
    }

    fn stop_timer(&self) {
        if let Some((run_loop, timer)) = self.timer.borrow_mut().take() {
            // SAFETY: the host's run loop and the handler registered on it.
            unsafe { run_loop.unregisterTimer(timer.as_ptr()) };
        }
    }
}

impl Drop for View {
    fn drop(&mut self) {
        self.stop_timer();
    }
}

impl IPlugViewTrait for View {
    unsafe fn isPlatformTypeSupported(&self, r#type: FIDString) -> tresult {
        if r#type.is_null() {
            return kInvalidArgument;
        }
        // SAFETY: the host's zero-ended type name.
        match unsafe { CStr::from_ptr(r#type) }.to_bytes() {
            b"X11EmbedWindowID" => kResultTrue,
            _ => kResultFalse,
        }
    }

    unsafe fn attached(&self, parent: *mut c_void, r#type: FIDString) -> tresult {
        // SAFETY: as the host passes it.
        if parent.is_null() || unsafe { self.isPlatformTypeSupported(r#type) } != kResultTrue {
            return kResultFalse;
        }
        let shown = self.inner.shown();
        let parent = X11Parent(parent as std::ffi::c_ulong);
        let window = match editor::Window::open(shown, Some(&parent), self.scale.get().max(1.0)) {
            Ok(w) => w,
            Err(e) => {
                eprintln!("{e}");
                return kResultFalse;
            }
        };
        let (w, h) = self.size.get();
        let _ = window.resize(w, h);
        *self.window.borrow_mut() = Some(window);
        // The window's changes reach the host on its UI thread, from its run loop.
        let run_loop = self
            .frame
            .borrow()
            .as_ref()
            .and_then(|f| f.cast::<IRunLoop>());
        let timer = ComWrapper::new(Edits(self.inner.clone())).to_com_ptr::<ITimerHandler>();
        if let (Some(run_loop), Some(timer)) = (run_loop, timer) {
            // SAFETY: a live run loop and handler; unregistered before either goes.
            if unsafe { run_loop.registerTimer(timer.as_ptr(), EDITS_MS) } == kResultOk {
                *self.timer.borrow_mut() = Some((run_loop, timer));
            }
        }
        kResultOk
    }

    unsafe fn removed(&self) -> tresult {
        self.stop_timer();
        // The window's thread is joined as it drops.
        self.window.borrow_mut().take();
        kResultOk
    }

    unsafe fn onWheel(&self, _distance: f32) -> tresult {
        kResultFalse
    }

    unsafe fn onKeyDown(&self, _key: char16, _code: int16, _modifiers: int16) -> tresult {
        kResultFalse
    }

    unsafe fn onKeyUp(&self, _key: char16, _code: int16, _modifiers: int16) -> tresult {
        kResultFalse
    }

    unsafe fn getSize(&self, size: *mut ViewRect) -> tresult {
        if size.is_null() {
            return kInvalidArgument;
        }
        // SAFETY: checked not null.
        unsafe { *size = self.physical() };
        kResultOk
    }

    unsafe fn onSize(&self, new_size: *mut ViewRect) -> tresult {
        // SAFETY: the host's rectangle, or null.
        let Some(r) = (unsafe { new_size.as_ref() }) else {
            return kInvalidArgument;
        };
        let physical = |a: int32, b: int32| u32::try_from(b - a).unwrap_or(0);
        let size = editor::logical(
            physical(r.left, r.right),
            physical(r.top, r.bottom),
            self.scale.get(),
        );
        self.size.set(size);
        if let Some(w) = self.window.borrow().as_ref() {
            let _ = w.resize(size.0, size.1);
        }
        kResultOk
    }

    unsafe fn onFocus(&self, _state: TBool) -> tresult {
        kResultOk
    }

    unsafe fn setFrame(&self, frame: *mut IPlugFrame) -> tresult {
        // SAFETY: the host's frame, or null; kept with a reference of our own.
        *self.frame.borrow_mut() = unsafe { ComRef::from_raw(frame) }.map(|f| f.to_com_ptr());
        kResultOk
    }

    unsafe fn canResize(&self) -> tresult {
        kResultTrue
    }

    unsafe fn checkSizeConstraint(&self, rect: *mut ViewRect) -> tresult {
        // SAFETY: the host's rectangle, or null.
        let Some(r) = (unsafe { rect.as_mut() }) else {
            return kInvalidArgument;
        };
        let (width, height) = editor::smallest(self.scale.get());
        r.right = r.right.max(r.left + width as int32);
        r.bottom = r.bottom.max(r.top + height as int32);
        kResultTrue
    }
}

impl IPlugViewContentScaleSupportTrait for View {
    unsafe fn setContentScaleFactor(&self, factor: f32) -> tresult {
        if !(0.25..=8.0).contains(&factor) {
            return kResultFalse;
        }
        self.scale.set(f64::from(factor));
        kResultOk
    }
}

/// The run loop's timer: the parameters changed in the window, told to the host.
struct Edits(Arc<Inner>);

impl Class for Edits {
    type Interfaces = (ITimerHandler,);
}

impl ITimerHandlerTrait for Edits {
    unsafe fn onTimer(&self) {
        let inner = &self.0;
        let handler = inner.handler();
        for (i, p) in PARAMS.iter().enumerate() {
            if !inner.edits.take(i) {
                continue;
            }
            if let Some(h) = &handler {
                let value = normalised(i, inner.values.get(i));
                // SAFETY: the host's handler, on its UI thread.
                unsafe {
                    h.beginEdit(p.id);
                    h.performEdit(p.id, value);
                    h.endEdit(p.id);
                }
            }
        }
    }
}
