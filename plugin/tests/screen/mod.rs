//! A screen for the editors' tests: an X server with no screen (Xvfb) on a display of its own,
//! read back with `xwd` and `xwdtopnm`, and the pixels of a colour found on it.

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
