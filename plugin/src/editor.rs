//! The plugin's window, the same in every format: the keyboard chosen, the voices and the halo
//! (each rebuilds the piano in the background), the output gain, the velocity curve and the three
//! pedals' depths; a keyboard showing the keys held and the keys sounding, the pedals as the
//! engine plays them (from the host's MIDI or the parameters), the polyphony and the audio
//! callback's time against its deadline. egui on baseview, in a window of its own thread (X11),
//! embedded in the host's or floating. It reads and writes the parameters' shared values and
//! reads [`Activity`]; nothing it does waits on the audio thread.

use crate::params::{
    self, Values, GAIN_DB, HALO, KEYBOARD, KEYBOARDS, PARAMS, SOFT, SOSTENUTO, SUSTAIN,
    VELOCITY_CURVE, VOICES,
};
use egui_baseview::baseview::dpi::LogicalSize;
use egui_baseview::{EguiWindow, EguiWindowSettings};
use raw_window_handle::{
    HandleError, HasWindowHandle, RawWindowHandle, WindowHandle, XlibWindowHandle,
};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;
use unacorda::audio::activity::{Activity, Snapshot, Watch};
use unacorda::config::scaling::KEYS;

/// The window's size in logical pixels (the host's scale factor multiplies it), and its
/// smallest.
pub const WIDTH: f64 = 780.0;
pub const HEIGHT: f64 = 330.0;
const MIN: (f64, f64) = (WIDTH * 0.6, HEIGHT * 0.6);

/// A size in logical pixels as the host's physical pixels at `scale` (hosts on X11 count
/// physical ones).
pub fn physical(size: (f64, f64), scale: f64) -> (u32, u32) {
    let s = scale.max(1.0);
    ((size.0 * s).round() as u32, (size.1 * s).round() as u32)
}

/// A host's physical size at `scale` as logical pixels, no smaller than the window's smallest.
pub fn logical(width: u32, height: u32, scale: f64) -> (f64, f64) {
    let s = scale.max(1.0);
    (
        (f64::from(width) / s).max(MIN.0),
        (f64::from(height) / s).max(MIN.1),
    )
}

/// The smallest size at `scale` (physical pixels), rounded up.
pub fn smallest(scale: f64) -> (u32, u32) {
    let s = scale.max(1.0);
    ((MIN.0 * s).ceil() as u32, (MIN.1 * s).ceil() as u32)
}

/// How often the window redraws to follow the piano.
const REDRAW: Duration = Duration::from_millis(33);

/// The parameters the window changed, for the host to hear of (every thread: the window sets,
/// the format's side takes).
#[derive(Debug, Default)]
pub struct Edits([AtomicBool; PARAMS.len()]);

impl Edits {
    /// Set parameter `index` to `value` (plain) and mark it for the host.
    pub fn set(&self, values: &Values, index: usize, value: f64) {
        values.set(index, value);
        self.0[index].store(true, Ordering::Release);
    }

    /// Whether parameter `index` was changed since the last call.
    pub fn take(&self, index: usize) -> bool {
        self.0[index].swap(false, Ordering::Acquire)
    }
}

/// What the window shows and changes, shared with the plugin.
#[derive(Clone)]
pub struct Shown {
    pub values: Arc<Values>,
    pub activity: Arc<Activity>,
    pub edits: Arc<Edits>,
}

/// An X11 window of the host's, by its id, to embed the editor in.
pub struct X11Parent(pub std::ffi::c_ulong);

impl HasWindowHandle for X11Parent {
    fn window_handle(&self) -> Result<WindowHandle<'_>, HandleError> {
        let raw = RawWindowHandle::Xlib(XlibWindowHandle::new(self.0));
        // SAFETY: the host keeps its window open while the editor is embedded in it.
        Ok(unsafe { WindowHandle::borrow_raw(raw) })
    }
}

/// An open editor window; closed when dropped (its thread joined by baseview). While it is open
/// the audio thread publishes what the piano does.
pub struct Window {
    window: egui_baseview::baseview::Window,
    /// Held for the window's life, dropped with it.
    _watch: Watch,
}

impl Window {
    /// Open the editor in `parent` (none: a floating window of its own) at `scale`.
    pub fn open(shown: Shown, parent: Option<&X11Parent>, scale: f64) -> Result<Window, String> {
        let settings = EguiWindowSettings::new()
            .with_title("unacorda")
            .with_size(LogicalSize {
                width: WIDTH,
                height: HEIGHT,
            })
            .with_resizable(true)
            .with_min_size(Some(LogicalSize {
                width: MIN.0,
                height: MIN.1,
            }))
            .with_parent(parent)
            .with_fallback_scale_factor(scale)
            .with_repaint_poll_interval(REDRAW);
        let watch = Activity::watch(&shown.activity);
        let window = EguiWindow::create(
            settings,
            Editor {
                shown,
                last: Snapshot::default(),
                peak: 0.0,
            },
        )
        .map_err(|e| format!("unacorda: the editor's window: {e}"))?;
        window
            .show()
            .map_err(|e| format!("unacorda: the editor's window: {e}"))?;
        Ok(Window {
            window,
            _watch: watch,
        })
    }

    /// Resize it (logical pixels).
    pub fn resize(&self, width: f64, height: f64) -> Result<(), String> {
        self.window
            .resize(LogicalSize { width, height })
            .map_err(|e| e.to_string())
    }

    pub fn show(&self) -> Result<(), String> {
        self.window.show().map_err(|e| e.to_string())
    }

    pub fn hide(&self) -> Result<(), String> {
        self.window.hide().map_err(|e| e.to_string())
    }
}

/// The window's own state (its thread).
struct Editor {
    shown: Shown,
    /// What the piano did at the last frame, and the load's peak held for display.
    last: Snapshot,
    peak: f32,
}

impl egui_baseview::App for Editor {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut egui_baseview::Frame) {
        self.last = self.shown.activity.take();
        // The peak falls slowly, so that a pianist sees the worst block of the last second.
        self.peak = (self.peak * 0.97).max(self.last.peak_load);
        egui::CentralPanel::default().show(ui, |ui| {
            self.header(ui);
            ui.separator();
            self.controls(ui);
            ui.add_space(6.0);
            keyboard(ui, &self.last);
            ui.add_space(6.0);
            self.meters(ui);
        });
        ui.ctx().request_repaint_after(REDRAW);
    }
}

impl Editor {
    fn set(&self, index: usize, value: f64) {
        self.shown.edits.set(&self.shown.values, index, value);
    }

    fn header(&self, ui: &mut egui::Ui) {
        let values = &self.shown.values;
        ui.horizontal(|ui| {
            ui.heading("unacorda");
            ui.add_space(16.0);
            let chosen = values.keyboard();
            egui::ComboBox::from_label("keyboard")
                .selected_text(chosen)
                .show_ui(ui, |ui| {
                    for (i, name) in KEYBOARDS.iter().enumerate() {
                        if ui.selectable_label(chosen == *name, *name).clicked() {
                            self.set(KEYBOARD, i as f64);
                        }
                    }
                });
            let mut voices = values.get(VOICES);
            let spec = PARAMS[VOICES];
            if ui
                .add(egui::DragValue::new(&mut voices).range(spec.min..=spec.max))
                .changed()
            {
                self.set(VOICES, voices);
            }
            ui.label("voices");
            let mut halo = values.halo();
            if ui.checkbox(&mut halo, "pedal halo").changed() {
                self.set(HALO, f64::from(u8::from(halo)));
            }
        });
    }

    fn controls(&self, ui: &mut egui::Ui) {
        let values = &self.shown.values;
        egui::Grid::new("controls")
            .num_columns(4)
            .spacing([12.0, 6.0])
            .show(ui, |ui| {
                self.slider(ui, GAIN_DB, "output gain", false);
                self.slider(ui, VELOCITY_CURVE, "velocity curve", true);
                ui.end_row();
                self.slider(ui, SUSTAIN, "sustain pedal", false);
                self.slider(ui, SOFT, "soft pedal", false);
                ui.end_row();
                ui.label("sostenuto pedal");
                let mut down = values.on(SOSTENUTO);
                if ui.checkbox(&mut down, "down").changed() {
                    self.set(SOSTENUTO, f64::from(u8::from(down)));
                }
                ui.end_row();
            });
    }

    /// A parameter's slider, its value shown as the host shows it.
    fn slider(&self, ui: &mut egui::Ui, index: usize, label: &str, log: bool) {
        let spec = PARAMS[index];
        let mut value = self.shown.values.get(index);
        ui.label(label);
        let slider = egui::Slider::new(&mut value, spec.min..=spec.max)
            .logarithmic(log)
            .custom_formatter(|v, _| {
                let mut text = String::new();
                let _ = params::write_text(index, v, &mut text);
                text
            });
        if ui.add(slider).changed() {
            self.set(index, value);
        }
    }

    fn meters(&self, ui: &mut egui::Ui) {
        let s = &self.last;
        ui.horizontal(|ui| {
            pedal(ui, "sustain", s.sustain_lift);
            pedal(ui, "sostenuto", if s.sostenuto { 1.0 } else { 0.0 });
            pedal(ui, "soft", s.soft_shift);
        });
        ui.horizontal(|ui| {
            ui.label(format!(
                "polyphony {} of {} voices ({} keys sounding)",
                s.voices,
                s.pool,
                s.sounding.len()
            ));
            ui.add_space(16.0);
            let colour = if self.peak >= 1.0 {
                egui::Color32::from_rgb(220, 60, 50)
            } else if self.peak >= 0.7 {
                egui::Color32::from_rgb(230, 170, 40)
            } else {
                egui::Color32::from_rgb(80, 170, 90)
            };
            ui.label("load");
            ui.add(
                egui::ProgressBar::new(s.load.clamp(0.0, 1.0))
                    .desired_width(220.0)
                    .fill(colour)
                    .text(format!(
                        "{:.0} % of the deadline (peak {:.0} %)",
                        100.0 * s.load,
                        100.0 * self.peak
                    )),
            );
        });
    }
}

/// A pedal's depth as a small bar.
fn pedal(ui: &mut egui::Ui, name: &str, depth: f32) {
    ui.label(name);
    ui.add(
        egui::ProgressBar::new(depth.clamp(0.0, 1.0))
            .desired_width(110.0)
            .text(if depth <= 0.0 {
                "up".to_string()
            } else if depth >= 1.0 {
                "down".to_string()
            } else {
                format!("{:.0} %", 100.0 * depth)
            }),
    );
    ui.add_space(8.0);
}

/// Key colours: a key at rest, held down, sounding without a finger (a pedal holds it, or it
/// rings in sympathy).
const HELD: egui::Color32 = egui::Color32::from_rgb(70, 130, 230);
const RINGING: egui::Color32 = egui::Color32::from_rgb(235, 170, 60);

/// Whether piano key `key` (1–88, A0 first) is a black key.
fn is_black(key: usize) -> bool {
    // Semitones above A: A♯, C♯, D♯, F♯, G♯.
    matches!((key + 8) % 12, 1 | 3 | 6 | 8 | 10)
}

/// The 88 keys across the window's width: held keys blue, keys sounding without a finger amber.
fn keyboard(ui: &mut egui::Ui, s: &Snapshot) {
    let width = ui.available_width();
    let height = (width / 7.0).clamp(60.0, 140.0);
    let (rect, _) = ui.allocate_exact_size(egui::vec2(width, height), egui::Sense::hover());
    let painter = ui.painter_at(rect);
    let whites = (1..=KEYS).filter(|&k| !is_black(k)).count() as f32;
    let w = rect.width() / whites;
    let colour = |key: usize, rest: egui::Color32| {
        if s.down.contains(key) {
            HELD
        } else if s.sounding.contains(key) {
            RINGING
        } else {
            rest
        }
    };
    let stroke = egui::Stroke::new(1.0, egui::Color32::from_gray(40));
    let mut x = rect.left();
    for key in (1..=KEYS).filter(|&k| !is_black(k)) {
        let r = egui::Rect::from_min_size(egui::pos2(x, rect.top()), egui::vec2(w, height));
        painter.rect_filled(r, 1.0, colour(key, egui::Color32::from_gray(235)));
        painter.rect_stroke(r, 1.0, stroke, egui::StrokeKind::Inside);
        x += w;
    }
    let mut white = 0.0;
    for key in 1..=KEYS {
        if is_black(key) {
            let centre = rect.left() + white * w;
            let r = egui::Rect::from_min_size(
                egui::pos2(centre - 0.3 * w, rect.top()),
                egui::vec2(0.6 * w, 0.62 * height),
            );
            painter.rect_filled(r, 1.0, colour(key, egui::Color32::from_gray(25)));
        } else {
            white += 1.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_keyboard_has_52_white_and_36_black_keys_from_a0_to_c8() {
        let black: Vec<usize> = (1..=KEYS).filter(|&k| is_black(k)).collect();
        assert_eq!((KEYS - black.len(), black.len()), (52, 36));
        // A♯0, C♯1; C8 (key 88) white, C4 (key 40) white, C♯4 black.
        assert_eq!(&black[..2], &[2, 5]);
        assert!(!is_black(88) && !is_black(40) && is_black(41));
    }
}
