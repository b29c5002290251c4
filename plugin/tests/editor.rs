//! The editor as a person sees it: the plugin loaded through clack-host, its window opened by
//! the host (floating) on an X server with no screen (Xvfb), while the host plays a chord held
//! down and a key let go under the sustain pedal; a screenshot of the screen (`xwd`) read back
//! and checked: the window's size at the host's scale, the held keys drawn blue and the key
//! ringing under the pedal amber; a click on the sostenuto pedal's box (XTest, as a mouse) told to
//! the host as the plugin's parameter event; then closed and opened again at another scale, and closed;
//! opened and closed a dozen times more without the memory growing; `process` never allocating
//! meanwhile. Needs Xvfb, xwd and xwdtopnm (scripts/deps.sh installs
//! them).

mod host;
mod screen;

use assert_no_alloc::{assert_no_alloc, violation_count, AllocDisabler};
use clack_host::prelude::PluginEntry;
use host::Play;
use screen::{find, Xvfb, HELD, PANEL, RINGING};
use std::time::{Duration, Instant};

#[global_allocator]
static ALLOCATOR: AllocDisabler = AllocDisabler;

const RATE_HZ: f64 = 48_000.0;
const SUSTAIN: u32 = 1;
const SOSTENUTO: u32 = 2;
/// glibc's allocation statistics (`mallinfo2`, glibc 2.33 on).
#[repr(C)]
struct Mallinfo2 {
    arena: usize,
    ordblks: usize,
    smblks: usize,
    hblks: usize,
    hblkhd: usize,
    usmblks: usize,
    fsmblks: usize,
    uordblks: usize,
    fordblks: usize,
    keepcost: usize,
}

extern "C" {
    fn mallinfo2() -> Mallinfo2;
}

fn checked(f: &mut dyn FnMut()) -> u32 {
    let before = violation_count();
    assert_no_alloc(f);
    violation_count() - before
}

#[test]
fn the_editor_draws_the_keys_held_and_ringing_and_opens_again() {
    let x = Xvfb::start(90);
    // SAFETY: set before any thread of this test reads the environment (the plugin's window
    // threads are not started yet).
    std::env::set_var("DISPLAY", &x.1);
    let entry =
        unsafe { PluginEntry::load_from_raw(&unacorda_clap::entry::clap_entry, c"") }.unwrap();
    let mut plugin = host::instantiate(&entry);
    let mut active = host::activate(&mut plugin, RATE_HZ);
    // A0 struck and let go under the pedal (ringing), then C4, E4, G4 held.
    let script = [
        (100, Play::Param(SUSTAIN, 1.0)),
        (200, Play::On(21, 0.7)),
        (4_000, Play::Off(Some(21), 0.5)),
        (5_000, Play::On(60, 0.7)),
        (5_000, Play::On(64, 0.7)),
        (5_000, Play::On(67, 0.7)),
    ];
    let mut allocations = active.run(9_600, &[256], &script, checked).allocations;

    for (round, scale) in [1.0, 1.5].into_iter().enumerate() {
        let (w, h) = host::editor(&mut plugin, Some(scale)).unwrap();
        // The host keeps playing while the window draws what the piano does, until it shows
        // the keys (at most 30 s: software OpenGL on a loaded machine is slow to start).
        let key = (w as f64 / 52.0) * (w as f64 / 7.0).min(140.0 * scale) * 0.5;
        let started = Instant::now();
        let (shot, panel, window, held, ringing) = loop {
            let playing = Instant::now();
            while playing.elapsed() < Duration::from_millis(300) {
                allocations += active.run(256, &[256], &[], checked).allocations;
                std::thread::sleep(Duration::from_millis(5));
            }
            let shot = x.screenshot();
            let (panel, window) = find(&shot, PANEL);
            let (held, _) = find(&shot, HELD);
            let (ringing, _) = find(&shot, RINGING);
            if held as f64 > 3.0 * key || started.elapsed() > Duration::from_secs(30) {
                break (shot, panel, window, held, ringing);
            }
        };
        let drawn = (window[2] + 1 - window[0], window[3] + 1 - window[1]);
        println!(
            "round {round}, scale {scale}: size {w} x {h} reported, drawn after {:.1} s, {} x {} ({panel} panel pixels); held keys {held} pixels, ringing {ringing}",
            started.elapsed().as_secs_f64(),
            drawn.0,
            drawn.1
        );
        let path = std::env::temp_dir().join(format!("unacorda-editor-{round}.ppm"));
        let (sw, sh, data) = &shot;
        let mut ppm = format!("P6\n{sw} {sh}\n255\n").into_bytes();
        ppm.extend_from_slice(data);
        std::fs::write(&path, ppm).unwrap();
        println!("the screenshot: {}", path.display());
        assert_eq!(
            (w, h),
            (
                (780.0 * scale).round() as u32,
                (330.0 * scale).round() as u32
            )
        );
        // The panel fills the window but for its widgets: its extent is the window's.
        assert!(
            drawn.0.abs_diff(w as usize) <= 2 && drawn.1.abs_diff(h as usize) <= 2,
            "the window drawn {drawn:?}, {w} x {h} reported"
        );
        // Three white keys held, one ringing: each key ~(w / 52) wide, a seventh of w high, half
        // of it clear of the black keys.
        assert!(
            held as f64 > 3.0 * key,
            "held keys: {held} pixels, a key ~{key:.0}"
        );
        assert!(
            ringing as f64 > key,
            "ringing key: {ringing} pixels, a key ~{key:.0}"
        );
        assert!(
            (ringing as f64) < 2.0 * key,
            "one key rings: {ringing} pixels"
        );
        if round == 0 {
            // A click on the sostenuto pedal's box, as a mouse: the plugin tells the host.
            screen::X11::open().click(120, 103);
            let clicked = Instant::now();
            let mut told = Vec::new();
            while told.is_empty() && clicked.elapsed() < Duration::from_secs(10) {
                let heard = active.run(256, &[256], &[], checked);
                allocations += heard.allocations;
                told = heard.params;
                std::thread::sleep(Duration::from_millis(5));
            }
            println!("after a click on the sostenuto box the host heard {told:?}");
            assert_eq!(told, [(SOSTENUTO, 1.0)], "the sostenuto pedal down");
        }
        host::editor(&mut plugin, None);
        std::thread::sleep(Duration::from_millis(300));
        let (after, _) = find(&x.screenshot(), PANEL);
        println!("closed: {after} panel pixels left");
        assert!(after < panel / 10, "the window closes");
    }
    // Opened and closed again and again: the memory in use settles (a window's worth kept would
    // grow it by megabytes each time). Counted as the allocator's bytes in use over every arena
    // (glibc's `mallinfo2`), not the resident size: each window thread's freed memory stays in
    // its own arena, so the resident size grows until the arenas are all made, leak or not.
    let resident_mb = || {
        // SAFETY: glibc's statistics, read.
        let m = unsafe { mallinfo2() };
        (m.uordblks + m.hblkhd) as f64 / 1e6
    };
    let mut resident = Vec::new();
    for _ in 0..12 {
        host::editor(&mut plugin, Some(1.0));
        let shown = Instant::now();
        while shown.elapsed() < Duration::from_millis(250) {
            allocations += active.run(256, &[256], &[], checked).allocations;
        }
        host::editor(&mut plugin, None);
        // The least over half a second: a closed window's thread frees its memory as it ends.
        let closed = Instant::now();
        let mut least = f64::MAX;
        while closed.elapsed() < Duration::from_millis(500) {
            least = least.min(resident_mb());
            std::thread::sleep(Duration::from_millis(20));
        }
        resident.push(least);
    }
    // The floor of the last six against that of the first six (the count moves between two
    // levels as the allocator's arenas keep or give back a window's memory: a leak raises the
    // floor).
    let floor = |r: &[f64]| r.iter().copied().fold(f64::MAX, f64::min);
    let growth = (floor(&resident[6..]) - floor(&resident[..6])) / 6.0;
    println!(
        "in use after each of 12 openings: {:?} MB; the floor rising {growth:.2} MB an opening",
        resident.iter().map(|r| r.round()).collect::<Vec<_>>()
    );
    assert!(growth < 1.0, "the editor leaks {growth:.2} MB an opening");
    println!("process() allocations while the editor was open: {allocations}");
    assert_eq!(allocations, 0);
    host::deactivate(&mut plugin, active);
}
