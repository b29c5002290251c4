//! What the plugin costs a host: `process()` timed in blocks of 64 frames at 48 kHz (1.33 ms),
//! paced as a device runs them, with 16 and 64 keys sounding under the sustain pedal (spread from
//! A0, struck at velocity 80, as `unacorda bench` loads its callbacks), loaded in process through
//! clack-host, its second core from its helper thread and then from the host's thread pool. Prints
//! the median and the 99.9th percentile as fractions of the block's duration.
//!   cargo bench -p unacorda-clap --bench process

#[path = "../tests/host/mod.rs"]
mod host;

use clack_host::prelude::PluginEntry;
use host::{Play, Threads};
use std::time::{Duration, Instant};
use unacorda::measure::{paced_times_s, percentile};

const RATE_HZ: f64 = 48_000.0;
const BLOCK: usize = 64;

fn main() {
    let seconds: f64 = std::env::var("UNACORDA_BENCH_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(4.0);
    // SAFETY: the plugin's own static entry (what hosts load), valid for the process's life.
    let entry =
        unsafe { PluginEntry::load_from_raw(&unacorda_clap::entry::clap_entry, c"") }.unwrap();
    // The second core from the plugin's own helper thread (a host without a thread pool), and
    // from a host's thread pool whose worker runs one task while the audio thread runs the other.
    for (threads, second_core) in [
        (Threads::None, "helper thread"),
        (Threads::Parallel, "host's thread pool"),
    ] {
        let mut plugin = host::instantiate_with(&entry, threads, host::unchecked);
        for voices in [16, 64] {
            one(&mut plugin, voices, seconds, second_core);
        }
    }
}

/// `voices` keys sounding under the pedal, `process()` paced for `seconds`.
fn one(plugin: &mut host::Instance, voices: usize, seconds: f64, second_core: &str) {
    let deadline_s = BLOCK as f64 / RATE_HZ;
    let mut active = host::activate(plugin, RATE_HZ);
    let mut script = vec![(0, Play::Param(1, 1.0))];
    for v in 0..voices {
        let note = 21 + (v * 88 / voices) as u16;
        script.push((v as u64 * 48, Play::On(note, 80.0 / 127.0)));
    }
    // Every hammer off its strings before the timing starts.
    let warm = voices * 48 + (0.05 * RATE_HZ) as usize;
    active.run(warm, &[BLOCK], &script, host::unchecked);
    let blocks = (seconds / deadline_s) as usize;
    let period = Duration::from_secs_f64(deadline_s);
    let times = paced_times_s(period, blocks, || {
        let mut took = 0.0;
        active.run(BLOCK, &[BLOCK], &[], |f| {
            let t = Instant::now();
            f();
            took = t.elapsed().as_secs_f64();
            0
        });
        took
    });
    let at = |p: f64| percentile(&times, p) / deadline_s;
    let (requests, _, _, together, _) = host::pool(plugin);
    println!(
        "plugin process(), {voices} voices under the pedal, {blocks} blocks of {BLOCK} frames at 48 kHz, second core from the {second_core}: median {:.2} x the block's duration, p99.9 {:.2} x (host's pool so far: {together} of {requests} requests on two cores)",
        at(0.5),
        at(0.999)
    );
    host::deactivate(plugin, active);
}
