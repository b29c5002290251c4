//! A screen for the editors' tests: an X server with no screen (Xvfb) on a display of its own,
//! read back with `xwd` and `xwdtopnm`, the pixels of a colour found on it; a window of a host's
//! and a mouse click (Xlib, XTest).

#![allow(dead_code)]

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The editor's colours of a held key and of a key sounding without a finger, and its
/// background (egui's dark panel).
pub const HELD: [u8; 3] = [70, 130, 230];
pub const RINGING: [u8; 3] = [235, 170, 60];
pub const PANEL: [u8; 3] = [27, 27, 27];

/// A screenshot: width, height, RGB bytes.
pub type Shot = (usize, usize, Vec<u8>);

/// An X server with no screen, stopped when dropped.
pub struct Xvfb(Child, pub String);

impl Xvfb {
    pub fn start(first: u32) -> Xvfb {
        let n = first + std::process::id() % 9;
        let display = format!(":{n}");
        let child = Command::new("Xvfb")
            .args([&display, "-screen", "0", "1600x1000x24", "-nolisten", "tcp"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("Xvfb (scripts/deps.sh installs it)");
        let socket = format!("/tmp/.X11-unix/X{n}");
        let started = Instant::now();
        while !Path::new(&socket).exists() {
            assert!(
                started.elapsed() < Duration::from_secs(10),
                "Xvfb did not start"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        Xvfb(child, display)
    }

    /// The screen as (width, height, RGB bytes).
    pub fn screenshot(&self) -> (usize, usize, Vec<u8>) {
        let xwd = Command::new("xwd")
            .args(["-root", "-silent", "-display", &self.1])
            .output()
            .expect("xwd");
        let file = std::env::temp_dir().join(format!("unacorda-editor-{}.xwd", std::process::id()));
        std::fs::write(&file, &xwd.stdout).unwrap();
        let pnm = Command::new("xwdtopnm")
            .arg(&file)
            .stderr(Stdio::null())
            .output()
            .expect("xwdtopnm");
        let _ = std::fs::remove_file(&file);
        parse_ppm(&pnm.stdout)
    }
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A binary PPM (P6; 8 bits a channel, or 16 as xwdtopnm writes a screen with a deeper visual,
/// kept to their high byte).
fn parse_ppm(bytes: &[u8]) -> (usize, usize, Vec<u8>) {
    let mut fields = Vec::new();
    let mut at = 0;
    while fields.len() < 4 {
        while bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        let start = at;
        while !bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        fields.push(String::from_utf8_lossy(&bytes[start..at]).to_string());
    }
    assert_eq!(fields[0], "P6");
    let (w, h): (usize, usize) = (fields[1].parse().unwrap(), fields[2].parse().unwrap());
    let raw = &bytes[at + 1..];
    let data: Vec<u8> = match fields[3].as_str() {
        "255" => raw.to_vec(),
        "65535" => raw.chunks_exact(2).map(|b| b[0]).collect(),
        other => panic!("a PPM of maxval {other}"),
    };
    assert_eq!(data.len(), w * h * 3);
    (w, h, data)
}

/// Pixels within 3 of `colour` in each channel, and their bounding box (x0, y0, x1, y1).
pub fn find(shot: &(usize, usize, Vec<u8>), colour: [u8; 3]) -> (usize, [usize; 4]) {
    let (w, _, data) = shot;
    let mut count = 0;
    let mut bound = [usize::MAX, usize::MAX, 0, 0];
    for (i, px) in data.chunks_exact(3).enumerate() {
        if px.iter().zip(colour).all(|(&a, b)| a.abs_diff(b) <= 3) {
            count += 1;
            let (x, y) = (i % w, i / w);
            bound = [
                bound[0].min(x),
                bound[1].min(y),
                bound[2].max(x),
                bound[3].max(y),
            ];
        }
    }
    (count, bound)
}

/// An X11 window of the host's at the screen's top left, `w` × `h`, and a click at (x, y)
/// (XTest, as a person's mouse).
pub struct X11 {
    xlib: x11_dl::xlib::Xlib,
    xtest: x11_dl::xtest::Xf86vmode,
    display: *mut x11_dl::xlib::Display,
}

impl X11 {
    pub fn open() -> X11 {
        let xlib = x11_dl::xlib::Xlib::open().expect("libX11");
        let xtest = x11_dl::xtest::Xf86vmode::open().expect("libXtst");
        let display = unsafe { (xlib.XOpenDisplay)(std::ptr::null()) };
        assert!(!display.is_null(), "no X display");
        X11 {
            xlib,
            xtest,
            display,
        }
    }

    /// A window at the screen's top left, shown.
    pub fn window(&self, w: u32, h: u32) -> u64 {
        unsafe {
            let root = (self.xlib.XDefaultRootWindow)(self.display);
            let window = (self.xlib.XCreateSimpleWindow)(self.display, root, 0, 0, w, h, 0, 0, 0);
            (self.xlib.XMapWindow)(self.display, window);
            (self.xlib.XSync)(self.display, 0);
            window
        }
    }

    /// A left click at (x, y) on the screen.
    pub fn click(&self, x: i32, y: i32) {
        unsafe {
            (self.xtest.XTestFakeMotionEvent)(self.display, -1, x, y, 0);
            (self.xlib.XSync)(self.display, 0);
            std::thread::sleep(Duration::from_millis(100));
            (self.xtest.XTestFakeButtonEvent)(self.display, 1, 1, 0);
            (self.xlib.XSync)(self.display, 0);
            std::thread::sleep(Duration::from_millis(50));
            (self.xtest.XTestFakeButtonEvent)(self.display, 1, 0, 0);
            (self.xlib.XSync)(self.display, 0);
        }
    }
}

impl Drop for X11 {
    fn drop(&mut self) {
        unsafe { (self.xlib.XCloseDisplay)(self.display) };
    }
}
