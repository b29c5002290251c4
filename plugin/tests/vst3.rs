//! The VST3 plugin loaded in process from its factory (`GetPluginFactory`, as hosts find it): its
//! class, buses, parameters and state; its sound, in host blocks of 1 to 4096 frames with note
//! events and parameter changes inside them, equal sample for sample to the offline render of
//! the same events (as the CLAP plugin's is) with `process` never allocating; and an offline
//! block that finds RK4 chosen waits for the piano rebuilt on it.

mod render;
mod screen;
mod vst3_host;

use assert_no_alloc::{assert_no_alloc, violation_count, AllocDisabler};
use render::offline;
use std::ffi::c_char;
use std::time::{Duration, Instant};
use unacorda::engine::exact::ExactPool;
use unacorda::engine::Rk4Pool;
use unacorda::midi::file::TimedEvent;
use unacorda::midi::Event as PianoEvent;
use vst3::Steinberg::Linux::ITimerHandlerTrait;
use vst3::Steinberg::Vst::*;
use vst3::Steinberg::*;
use vst3::{ComPtr, ComWrapper, Interface};
use vst3_host::{note, stream, Changes, EventList, Queue};

#[global_allocator]
static ALLOCATOR: AllocDisabler = AllocDisabler;

/// Activations share a process-wide piano cache and two cores: one test at a time.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

const RATE_HZ: f64 = 48_000.0;
/// Parameter ids (the CLAP plugin's).
const SUSTAIN: u32 = 1;
const SOFT: u32 = 3;
const GAIN_DB: u32 = 4;
const INTEGRATOR: u32 = 8;

/// What a test plays: a note-on or note-off (pitch, velocity 0–1), or a parameter's normalised
/// value.
#[derive(Clone, Copy)]
enum Play {
    On(i16, f32),
    Off(i16, f32),
    Param(u32, f64),
}

fn factory() -> ComPtr<IPluginFactory> {
    let raw = unacorda_clap::vst3::factory::GetPluginFactory();
    // SAFETY: a new reference from the plugin's factory.
    unsafe { ComPtr::from_raw(raw) }.expect("a factory")
}

/// A plugin instance as a host makes one: created from the factory's class, initialised.
fn instance() -> ComPtr<IComponent> {
    let factory = factory();
    let mut info: PClassInfo = unsafe { std::mem::zeroed() };
    assert_eq!(unsafe { factory.getClassInfo(0, &mut info) }, kResultOk);
    let mut obj = std::ptr::null_mut();
    let iid = IComponent::IID;
    let created = unsafe {
        factory.createInstance(info.cid.as_ptr(), iid.as_ptr() as *const c_char, &mut obj)
    };
    assert_eq!(created, kResultOk);
    let component = unsafe { ComPtr::from_raw(obj.cast::<IComponent>()) }.unwrap();
    assert_eq!(
        unsafe { component.initialize(std::ptr::null_mut()) },
        kResultOk
    );
    component
}

fn c_text(text: &[c_char]) -> String {
    let bytes: Vec<u8> = text
        .iter()
        .take_while(|&&c| c != 0)
        .map(|&c| c as u8)
        .collect();
    String::from_utf8(bytes).unwrap()
}

fn wide_text(text: &[char16]) -> String {
    let units: Vec<u16> = text.iter().take_while(|&&c| c != 0).copied().collect();
    String::from_utf16(&units).unwrap()
}

/// `f` under the allocation checker; the allocations it made.
fn checked(f: &mut dyn FnMut()) -> u32 {
    let before = violation_count();
    assert_no_alloc(f);
    violation_count() - before
}

/// Set up for `mode` at 48 kHz in stereo, activated and processing.
fn start(component: &ComPtr<IComponent>, mode: ProcessModes) -> ComPtr<IAudioProcessor> {
    let processor = component.cast::<IAudioProcessor>().unwrap();
    let mut stereo = SpeakerArr::kStereo;
    unsafe {
        assert_eq!(
            processor.setBusArrangements(std::ptr::null_mut(), 0, &mut stereo, 1),
            kResultTrue
        );
        let mut setup = ProcessSetup {
            processMode: mode as int32,
            symbolicSampleSize: SymbolicSampleSizes_::kSample32 as int32,
            maxSamplesPerBlock: 4096,
            sampleRate: RATE_HZ,
        };
        assert_eq!(processor.setupProcessing(&mut setup), kResultOk);
        assert_eq!(component.setActive(1), kResultOk);
        assert_eq!(processor.setProcessing(1), kResultOk);
    }
    processor
}

fn stop(component: &ComPtr<IComponent>, processor: &ComPtr<IAudioProcessor>) {
    unsafe {
        processor.setProcessing(0);
        component.setActive(0);
        component.terminate();
    }
}

/// Both channels of `frames` frames played in blocks of `blocks` (cycled), `script`'s events and
/// parameter changes at their frames, each block's `processMode` `mode`; and the allocations
/// `process` made.
fn run(
    processor: &ComPtr<IAudioProcessor>,
    frames: usize,
    blocks: &[usize],
    script: &[(usize, Play)],
    mode: ProcessModes,
) -> ([Vec<f32>; 2], u32) {
    let mut out = [vec![0f32; frames], vec![0f32; frames]];
    let mut allocations = 0;
    let mut at = 0;
    for &block in blocks.iter().cycle() {
        if at >= frames {
            break;
        }
        let n = block.min(frames - at);
        let inside = |&&(t, _): &&(usize, Play)| (at..at + n).contains(&t);
        let mut events = Vec::new();
        let mut queues: Vec<(u32, Vec<(int32, f64)>)> = Vec::new();
        for &(t, play) in script.iter().filter(inside) {
            let offset = (t - at) as i32;
            match play {
                Play::On(pitch, v) => events.push(note(offset, pitch, v, true)),
                Play::Off(pitch, v) => events.push(note(offset, pitch, v, false)),
                Play::Param(id, v) => match queues.iter_mut().find(|q| q.0 == id) {
                    Some(q) => q.1.push((offset, v)),
                    None => queues.push((id, vec![(offset, v)])),
                },
            }
        }
        let events = ComWrapper::new(EventList(events))
            .to_com_ptr::<IEventList>()
            .unwrap();
        let queues = queues
            .into_iter()
            .map(|(id, points)| {
                ComWrapper::new(Queue { id, points })
                    .to_com_ptr::<IParamValueQueue>()
                    .unwrap()
            })
            .collect();
        let changes = ComWrapper::new(Changes(queues))
            .to_com_ptr::<IParameterChanges>()
            .unwrap();
        let (left, right) = out.split_at_mut(1);
        let mut channels = [left[0][at..].as_mut_ptr(), right[0][at..].as_mut_ptr()];
        let mut bus = AudioBusBuffers {
            numChannels: 2,
            silenceFlags: 0,
            __field0: AudioBusBuffers__type0 {
                channelBuffers32: channels.as_mut_ptr(),
            },
        };
        let mut data = ProcessData {
            processMode: mode as int32,
            symbolicSampleSize: SymbolicSampleSizes_::kSample32 as int32,
            numSamples: n as int32,
            numInputs: 0,
            numOutputs: 1,
            inputs: std::ptr::null_mut(),
            outputs: &mut bus,
            inputParameterChanges: changes.as_ptr(),
            outputParameterChanges: std::ptr::null_mut(),
            inputEvents: events.as_ptr(),
            outputEvents: std::ptr::null_mut(),
            processContext: std::ptr::null_mut(),
        };
        allocations += checked(&mut || {
            assert_eq!(unsafe { processor.process(&mut data) }, kResultOk);
        });
        at += n;
    }
    (out, allocations)
}

/// A performance: notes (one at velocity 0, the softest strike), release velocities, the
/// sustain pedal down, part way and up as its parameter (what a host makes of CC64 through the
/// plugin's MIDI mapping), the soft pedal part way down, several changes in one block.
fn script() -> Vec<(usize, Play)> {
    let ms = |t: f64| (t * RATE_HZ / 1000.0).round() as usize;
    vec![
        (ms(0.0) + 17, Play::On(60, 100.0 / 127.0)),
        (ms(20.0), Play::On(64, 80.0 / 127.0)),
        (ms(35.0), Play::On(67, 0.0)),
        (ms(60.0), Play::Param(SUSTAIN, 1.0)),
        (ms(80.0), Play::Off(60, 0.0)),
        (ms(90.0), Play::Off(64, 30.0 / 127.0)),
        (ms(110.0), Play::Param(SOFT, 0.6)),
        (ms(120.0), Play::On(48, 90.0 / 127.0)),
        (ms(120.0) + 5, Play::Param(SUSTAIN, 0.45)),
        (ms(145.0), Play::Off(48, 0.2)),
        (ms(160.0), Play::Param(SUSTAIN, 0.0)),
        (ms(168.0), Play::On(55, 0.7)),
        (ms(170.0), Play::Param(SOFT, 0.0)),
        (ms(175.0), Play::On(72, 0.4321)),
        (ms(200.0), Play::Off(55, 0.5)),
        (ms(200.0) + 1, Play::Off(72, 0.5)),
    ]
}

/// The script as the piano's events, timed as a MIDI file's (what `render --midi` plays).
fn as_piano_events(script: &[(usize, Play)]) -> Vec<TimedEvent> {
    script
        .iter()
        .filter_map(|&(frame, play)| {
            let event = match play {
                Play::On(note, v) => PianoEvent::NoteOn {
                    note: note as u8,
                    velocity: (f64::from(v) * 127.0).clamp(1.0, 127.0),
                },
                Play::Off(note, v) => PianoEvent::NoteOff {
                    note: note as u8,
                    velocity: f64::from(v) * 127.0,
                },
                Play::Param(id, value) => render::pedal_of_param(id, value)?,
            };
            Some(TimedEvent {
                time_s: frame as f64 / RATE_HZ,
                event,
            })
        })
        .collect()
}

/// Both channels of what the plugin played equal to the offline render's, `latency` frames
/// late ([`render::equals_offline`]).
fn equals_offline(engine: &str, heard: &[Vec<f32>; 2], latency: usize, render: &[Vec<f32>; 2]) {
    render::equals_offline(
        engine,
        [&heard[0], &heard[1]],
        latency,
        [&render[0], &render[1]],
    );
}

#[test]
fn the_class_buses_parameters_and_state() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let factory = factory();
    assert_eq!(unsafe { factory.countClasses() }, 1);
    let factory2 = factory.cast::<IPluginFactory2>().expect("IPluginFactory2");
    let mut info: PClassInfo2 = unsafe { std::mem::zeroed() };
    assert_eq!(unsafe { factory2.getClassInfo2(0, &mut info) }, kResultOk);
    let (name, category, sub) = (
        c_text(&info.name),
        c_text(&info.category),
        c_text(&info.subCategories),
    );
    println!("class: {name}, {category}, {sub}");
    assert_eq!(
        (name.as_str(), category.as_str(), sub.as_str()),
        ("unacorda", "Audio Module Class", "Instrument|Piano")
    );

    let component = instance();
    let audio = MediaTypes_::kAudio as MediaType;
    let event = MediaTypes_::kEvent as MediaType;
    let (input, output) = (
        BusDirections_::kInput as BusDirection,
        BusDirections_::kOutput as BusDirection,
    );
    let counts = unsafe {
        [
            component.getBusCount(audio, input),
            component.getBusCount(audio, output),
            component.getBusCount(event, input),
            component.getBusCount(event, output),
        ]
    };
    assert_eq!(counts, [0, 1, 1, 0], "audio in, out; events in, out");
    let mut bus: BusInfo = unsafe { std::mem::zeroed() };
    assert_eq!(
        unsafe { component.getBusInfo(audio, output, 0, &mut bus) },
        kResultOk
    );
    assert_eq!(bus.channelCount, 2, "the concert keyboard's stereo pair");

    let controller = component
        .cast::<IEditController>()
        .expect("its own controller");
    let count = unsafe { controller.getParameterCount() };
    assert_eq!(count as usize, unacorda_clap::params::PARAMS.len());
    for i in 0..count {
        let mut p: ParameterInfo = unsafe { std::mem::zeroed() };
        assert_eq!(unsafe { controller.getParameterInfo(i, &mut p) }, kResultOk);
        let shown = {
            let mut s: String128 = [0; 128];
            unsafe { controller.getParamStringByValue(p.id, p.defaultNormalizedValue, &mut s) };
            wide_text(&s)
        };
        println!(
            "{:2} {:45} steps {:3} default {:.3} ({shown}) flags {}",
            p.id,
            wide_text(&p.title),
            p.stepCount,
            p.defaultNormalizedValue,
            p.flags
        );
    }
    // Text both ways, through the normalised value.
    let mut text: Vec<char16> = "-6 dB".encode_utf16().collect();
    text.push(0);
    let mut normalised = 0.0;
    assert_eq!(
        unsafe { controller.getParamValueByString(GAIN_DB, text.as_mut_ptr(), &mut normalised) },
        kResultOk
    );
    let plain = unsafe { controller.normalizedParamToPlain(GAIN_DB, normalised) };
    assert!((plain + 6.0).abs() < 1e-9, "-6 dB read back as {plain}");
    let mut shown: String128 = [0; 128];
    unsafe { controller.getParamStringByValue(GAIN_DB, normalised, &mut shown) };
    assert_eq!(wide_text(&shown), "-6.0 dB");

    // The sustain, sostenuto and soft pedals' controllers map to their parameters.
    let mapping = component.cast::<IMidiMapping>().expect("IMidiMapping");
    let mapped: Vec<Option<u32>> = [64, 66, 67, 1]
        .iter()
        .map(|&cc| {
            let mut id = 0;
            (unsafe { mapping.getMidiControllerAssignment(0, 0, cc, &mut id) } == kResultOk)
                .then_some(id)
        })
        .collect();
    assert_eq!(mapped, [Some(1), Some(2), Some(3), None]);

    // State: saved, changed, loaded into another instance; a foreign one refused.
    unsafe { controller.setParamNormalized(GAIN_DB, normalised) };
    let saved = ComWrapper::new(vst3_host::Stream::default());
    let saved_ptr = saved.to_com_ptr::<IBStream>().unwrap();
    assert_eq!(unsafe { component.getState(saved_ptr.as_ptr()) }, kResultOk);
    let bytes = saved.bytes.borrow().clone();
    let text = String::from_utf8(bytes.clone()).unwrap();
    println!("state:\n{text}");
    let other = instance();
    let other_controller = other.cast::<IEditController>().unwrap();
    assert_eq!(
        unsafe { other.setState(stream(&bytes).as_ptr()) },
        kResultOk
    );
    let loaded = unsafe { other_controller.getParamNormalized(GAIN_DB) };
    assert!(
        (loaded - normalised).abs() < 1e-12,
        "{loaded} != {normalised}"
    );
    assert_eq!(
        unsafe { other.setState(stream(b"format = \"something else\"\n").as_ptr()) },
        kResultFalse
    );
    assert_eq!(
        unsafe { other_controller.getParamNormalized(GAIN_DB) },
        loaded,
        "a refused state changes nothing"
    );
    unsafe {
        component.terminate();
        other.terminate();
    }
}

#[test]
fn plays_exactly_like_the_offline_render_in_any_blocks_without_allocating() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let component = instance();
    let processor = start(&component, ProcessModes_::kRealtime);
    let latency = unsafe { processor.getLatencySamples() } as usize;
    let tail = unsafe { processor.getTailSamples() };
    println!("latency {latency} frames, tail {tail} frames");
    assert_eq!(latency, unacorda::audio::aligned::LATENCY_FRAMES as usize);
    assert!(
        tail > 48_000 && tail < kInfiniteTail,
        "a finite tail of seconds"
    );
    let script = script();
    let render = offline::<ExactPool>(&as_piano_events(&script), 0.2, false);
    let blocks = [1, 4096, 17, 333, 2, 1000, 95, 31, 64, 3, 512, 777];
    let (heard, allocations) = run(
        &processor,
        render[0].len() + latency,
        &blocks,
        &script,
        ProcessModes_::kRealtime,
    );
    println!(
        "blocks of {blocks:?} frames, {} events and parameter changes: {allocations} allocations in process()",
        script.len()
    );
    assert_eq!(allocations, 0, "process() allocated");
    equals_offline("exact", &heard, latency, &render);
    stop(&component, &processor);
}

/// Ardour says an export is offline only in each block's `processMode`: a block that finds RK4
/// chosen waits for the piano rebuilt on it, so the render is RK4's from its first sample.
#[test]
fn an_offline_block_plays_the_rk4_integrator_chosen() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let component = instance();
    let controller = component.cast::<IEditController>().unwrap();
    unsafe { controller.setParamNormalized(INTEGRATOR, 1.0) };
    let processor = start(&component, ProcessModes_::kRealtime);
    let live = unsafe { processor.getLatencySamples() };
    let latency = unacorda::audio::aligned::LATENCY_FRAMES as usize;
    assert_eq!(live as usize, latency, "live, the exact engine plays");
    let script: Vec<_> = script().into_iter().take(6).collect();
    let render = offline::<Rk4Pool>(&as_piano_events(&script), 0.1, false);
    let started = std::time::Instant::now();
    let (heard, _) = run(
        &processor,
        render[0].len() + latency,
        &[333, 64, 4096, 1],
        &script,
        ProcessModes_::kOffline,
    );
    let (reported, tail) = unsafe { (processor.getLatencySamples(), processor.getTailSamples()) };
    println!(
        "offline: {:.1} s, latency reported {reported} (live {live}), tail {tail}",
        started.elapsed().as_secs_f64()
    );
    assert!(reported as usize > latency, "RK4's decimation filter");
    assert_eq!(tail, kInfiniteTail);
    equals_offline("RK4", &heard, latency, &render);
    stop(&component, &processor);
}

/// The host's side of an editor: its frame and run loop (timers fired by the test), and a
/// component handler recording the edits it hears of.
#[derive(Default)]
struct HostUi {
    timers: std::cell::RefCell<Vec<ComPtr<vst3::Steinberg::Linux::ITimerHandler>>>,
    edits: std::cell::RefCell<Vec<(u32, f64)>>,
}

impl vst3::Class for HostUi {
    type Interfaces = (
        IPlugFrame,
        vst3::Steinberg::Linux::IRunLoop,
        IComponentHandler,
    );
}

impl IPlugFrameTrait for HostUi {
    unsafe fn resizeView(&self, _view: *mut IPlugView, _size: *mut ViewRect) -> tresult {
        kResultOk
    }
}

impl vst3::Steinberg::Linux::IRunLoopTrait for HostUi {
    unsafe fn registerEventHandler(
        &self,
        _handler: *mut vst3::Steinberg::Linux::IEventHandler,
        _fd: vst3::Steinberg::Linux::FileDescriptor,
    ) -> tresult {
        kResultOk
    }
    unsafe fn unregisterEventHandler(
        &self,
        _handler: *mut vst3::Steinberg::Linux::IEventHandler,
    ) -> tresult {
        kResultOk
    }
    unsafe fn registerTimer(
        &self,
        handler: *mut vst3::Steinberg::Linux::ITimerHandler,
        _ms: vst3::Steinberg::Linux::TimerInterval,
    ) -> tresult {
        let handler = unsafe { vst3::ComRef::from_raw(handler) }
            .unwrap()
            .to_com_ptr();
        self.timers.borrow_mut().push(handler);
        kResultOk
    }
    unsafe fn unregisterTimer(
        &self,
        handler: *mut vst3::Steinberg::Linux::ITimerHandler,
    ) -> tresult {
        self.timers.borrow_mut().retain(|t| t.as_ptr() != handler);
        kResultOk
    }
}

impl IComponentHandlerTrait for HostUi {
    unsafe fn beginEdit(&self, _id: ParamID) -> tresult {
        kResultOk
    }
    unsafe fn performEdit(&self, id: ParamID, value: ParamValue) -> tresult {
        self.edits.borrow_mut().push((id, value));
        kResultOk
    }
    unsafe fn endEdit(&self, _id: ParamID) -> tresult {
        kResultOk
    }
    unsafe fn restartComponent(&self, _flags: int32) -> tresult {
        kResultOk
    }
}

/// The editor embedded in a host's X11 window as a VST3 host embeds it, on Xvfb, while the host
/// plays a chord held and a key ringing under the pedal: the screen shows them; a click on the
/// sostenuto pedal's box (XTest, as a mouse) reaches the host through its component handler on
/// its run loop's timer; removed, the window is gone.
#[test]
fn the_editor_embeds_in_the_hosts_window_and_tells_it_of_a_click() {
    let _serial = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let x = screen::Xvfb::start(80);
    // SAFETY: set before the plugin's window threads start.
    std::env::set_var("DISPLAY", &x.1);
    let component = instance();
    let controller = component.cast::<IEditController>().unwrap();
    let ui = ComWrapper::new(HostUi::default());
    let handler = ui.to_com_ptr::<IComponentHandler>().unwrap();
    unsafe { controller.setComponentHandler(handler.as_ptr()) };
    let processor = start(&component, ProcessModes_::kRealtime);
    let ms = |t: f64| (t * RATE_HZ / 1000.0).round() as usize;
    let script = [
        (ms(1.0), Play::Param(SUSTAIN, 1.0)),
        (ms(2.0), Play::On(21, 0.7)),
        (ms(80.0), Play::Off(21, 0.5)),
        (ms(100.0), Play::On(60, 0.7)),
        (ms(100.0), Play::On(64, 0.7)),
        (ms(100.0), Play::On(67, 0.7)),
    ];
    let (_, mut allocations) = run(
        &processor,
        ms(200.0),
        &[256],
        &script,
        ProcessModes_::kRealtime,
    );

    let view = unsafe { controller.createView(c"editor".as_ptr()) };
    let view = unsafe { ComPtr::from_raw(view) }.expect("an editor view");
    let scale = view.cast::<IPlugViewContentScaleSupport>().unwrap();
    assert_eq!(unsafe { scale.setContentScaleFactor(1.0) }, kResultOk);
    let frame = ui.to_com_ptr::<IPlugFrame>().unwrap();
    assert_eq!(unsafe { view.setFrame(frame.as_ptr()) }, kResultOk);
    let x11 = screen::X11::open();
    let mut rect: ViewRect = unsafe { std::mem::zeroed() };
    assert_eq!(unsafe { view.getSize(&mut rect) }, kResultOk);
    let (w, h) = (
        (rect.right - rect.left) as u32,
        (rect.bottom - rect.top) as u32,
    );
    let parent = x11.window(w, h);
    let x11_type = c"X11EmbedWindowID";
    assert_eq!(
        unsafe { view.isPlatformTypeSupported(x11_type.as_ptr()) },
        kResultTrue
    );
    assert_eq!(
        unsafe { view.attached(parent as *mut std::ffi::c_void, x11_type.as_ptr()) },
        kResultOk
    );
    assert_eq!(
        ui.timers.borrow().len(),
        1,
        "a timer on the host's run loop"
    );

    // Drawn: keys held and ringing, while the host plays.
    let key = (w as f64 / 52.0) * (w as f64 / 7.0).min(140.0) * 0.5;
    let started = Instant::now();
    let (held, ringing, panel) = loop {
        let playing = Instant::now();
        while playing.elapsed() < Duration::from_millis(300) {
            allocations += run(&processor, 256, &[256], &[], ProcessModes_::kRealtime).1;
        }
        let shot = x.screenshot();
        let (held, _) = screen::find(&shot, screen::HELD);
        let (ringing, _) = screen::find(&shot, screen::RINGING);
        let (panel, _) = screen::find(&shot, screen::PANEL);
        if held as f64 > 3.0 * key || started.elapsed() > Duration::from_secs(30) {
            break (held, ringing, panel);
        }
    };
    println!(
        "VST3 editor {w} x {h}, drawn after {:.1} s: held keys {held} pixels, ringing {ringing}, panel {panel}",
        started.elapsed().as_secs_f64()
    );
    assert!(held as f64 > 3.0 * key && ringing as f64 > key);

    // A click on the sostenuto pedal's box, told to the host at its run loop's next timer.
    x11.click(120, 103);
    let started = Instant::now();
    while ui.edits.borrow().is_empty() && started.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(30));
        let timers = ui.timers.borrow().clone();
        for t in &timers {
            unsafe { t.onTimer() };
        }
    }
    let edits = ui.edits.borrow().clone();
    println!("the host heard {edits:?} after the click");
    assert_eq!(edits, [(2, 1.0)], "the sostenuto pedal down");
    assert_eq!(unsafe { controller.getParamNormalized(2) }, 1.0);

    assert_eq!(unsafe { view.removed() }, kResultOk);
    assert!(ui.timers.borrow().is_empty(), "the timer unregistered");
    std::thread::sleep(Duration::from_millis(300));
    let (after, _) = screen::find(&x.screenshot(), screen::PANEL);
    println!("removed: {after} panel pixels left");
    assert!(after < panel / 10, "the window goes");
    println!("process() allocations while the editor was open: {allocations}");
    assert_eq!(allocations, 0);
    drop(view);
    stop(&component, &processor);
}
