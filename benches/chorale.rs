//! What a pianist's pedalling costs: the four-part chorale (`assets/midi/chorale.mid`: a chord a
//! second, 35 keys from C1 to C8, the sustain pedal lifted 50 ms after each chord and pressed
//! again 100 ms later) through the synth on the concert keyboard (`render --offline --midi`'s
//! path), in 256-frame blocks as fast as they run, on one core and on two. Prints each block's
//! time as a fraction of its deadline (256 frames at 48 kHz: 5.33 ms) — median, p99, the largest
//! and how many are over — and how many are over in each half second: where the pedal rises the
//! dampers fall on every released key at once (a coupled felt's damped voice cost several held
//! ones). Then what is left, a chord's strike: eight keys struck at once on the exact engine's
//! pool, the 256-frame block while their hammers touch (each such voice steps one sample at a
//! time) beside the next.
//!   cargo bench --bench chorale

use std::ops::ControlFlow;
use std::path::Path;
use std::time::Instant;
use unacorda::engine::exact::ExactPool;
use unacorda::engine::{Policy, Strike, VoicePool};
use unacorda::measure::percentile;
use unacorda::render::performance::{render_midi_into, OFFLINE_BLOCK};

fn main() {
    let events = unacorda::midi::file::read_file(Path::new("assets/midi/chorale.mid"))
        .expect("the chorale (cargo run --example chorale_midi writes it)");
    let scaling = unacorda::config::scaling::Scaling::resolve("concert").expect("built in");
    let cache = unacorda::keycache::KeyCache::from_env();
    let deadline_s = OFFLINE_BLOCK as f64 / scaling.output_settings().rate_hz;
    for cores in [1, 2] {
        let keyboard = unacorda::play::Keyboard {
            scaling: &scaling,
            cache: cache.as_ref(),
        };
        let offline = unacorda::render::Offline {
            tail_s: 1.0,
            voices: unacorda::play::DEFAULT_VOICES,
            cores,
            halo: false,
        };
        // The time between two blocks handed over is the second one's.
        let mut times = Vec::new();
        let mut last: Option<Instant> = None;
        render_midi_into::<ExactPool>(
            keyboard,
            &events,
            offline,
            |_| {},
            None,
            |_| {
                let now = Instant::now();
                if let Some(last) = last {
                    times.push((now - last).as_secs_f64() / deadline_s);
                }
                last = Some(now);
                ControlFlow::Continue(())
            },
        )
        .expect("the chorale renders");
        let over = times.iter().filter(|&&t| t > 1.0).count();
        let mut sorted = times.clone();
        sorted.sort_by(f64::total_cmp);
        println!(
            "chorale, concert keyboard, {} blocks of {OFFLINE_BLOCK} frames on {cores} core(s): median {:.2} x the deadline, p99 {:.2} x, largest {:.2} x; {over} over",
            times.len(),
            percentile(&sorted, 0.5),
            percentile(&sorted, 0.99),
            sorted.last().copied().unwrap_or(0.0),
        );
        let per_half_s = 0.5 / deadline_s;
        let mut windows = vec![0; (times.len() as f64 / per_half_s) as usize + 1];
        for (i, _) in times.iter().enumerate().filter(|(_, &t)| t > 1.0) {
            windows[((i + 1) as f64 / per_half_s) as usize] += 1;
        }
        println!("  blocks over the deadline per half second from the start: {windows:?}");
    }
    let lifts: Vec<String> = events
        .iter()
        .filter(|e| {
            matches!(
                e.event,
                unacorda::midi::Event::Pedal {
                    pedal: unacorda::midi::Pedal::Sustain,
                    depth,
                } if depth < unacorda::midi::PEDAL_DOWN_AT
            )
        })
        .map(|e| format!("{:.2}", e.time_s))
        .collect();
    println!("  the pedal rises at (s): {}", lifts.join(", "));
    chord_struck(&scaling, deadline_s);
}

/// C2 C3 E3 G3 C4 E4 G4 C5 struck together at 3 m/s, 20 times (1.3 s apart), on one core: the
/// median time of the block the strike starts and of the block after it.
fn chord_struck(scaling: &unacorda::config::scaling::LoadedScaling, deadline_s: f64) {
    let keys = ["C2", "C3", "E3", "G3", "C4", "E4", "G4", "C5"];
    let specs: Vec<_> = keys
        .iter()
        .map(|k| {
            let key = unacorda::config::scaling::parse_key(k).expect("a key");
            scaling.key_preset(key).expect("built in").unison_spec()
        })
        .collect();
    let rate_hz = scaling.output_settings().rate_hz;
    let mut pool = ExactPool::build_pool(&specs, keys.len(), rate_hz).expect("the keys build");
    for k in 0..keys.len() {
        pool.assign(k, k);
        pool.set_active(k, true);
    }
    let mut out = vec![[0.0; 2]; OFFLINE_BLOCK];
    let (mut struck, mut after) = (vec![], vec![]);
    for _ in 0..20 {
        for k in 0..keys.len() {
            let strike = Strike {
                velocity_m_s: 3.0,
                shift: 0.0,
            };
            pool.strike_voice(k, strike);
        }
        for times in [&mut struck, &mut after] {
            let t = Instant::now();
            pool.run(&mut out, None);
            times.push(t.elapsed().as_secs_f64() / deadline_s);
        }
        for _ in 0..((1.3 * rate_hz) as usize / OFFLINE_BLOCK) {
            pool.run(&mut out, None);
        }
    }
    for t in [&mut struck, &mut after] {
        t.sort_by(f64::total_cmp);
    }
    println!(
        "a chord struck, {} (concert keyboard, exact pool, one core, {OFFLINE_BLOCK} frames): the block as the hammers touch {:.2} x the deadline (median of 20), the next {:.2} x",
        keys.join(" "),
        percentile(&struck, 0.5),
        percentile(&after, 0.5)
    );
}
