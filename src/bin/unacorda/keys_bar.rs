//! The keys' preparation shown as it goes: a bar on standard error of the keys done out of those
//! asked for, how many were read back from the cache of prepared keys, the time taken and an
//! estimate of what is left. Drawn only where standard error is a terminal, so scripts and tests
//! that read it see the lines they saw before and nothing else.

use indicatif::{HumanDuration, ProgressBar, ProgressState, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::Duration;
use unacorda::keycache::KeyCache;

/// How often the bar reads the cache's counts.
const POLL: Duration = Duration::from_millis(100);

/// Run `build`, which prepares `total` keys through `cache`, under a bar of their progress.
/// `build` is handed a function to call once the keys are done (a render, which goes on to
/// play them, ends the bar there); the bar ends when `build` returns in any case. Without a cache
/// the keys are counted by nothing: the bar shows the time taken alone.
pub fn building<T>(
    cache: Option<&KeyCache>,
    total: usize,
    build: impl FnOnce(&dyn Fn()) -> T,
) -> T {
    if !std::io::stderr().is_terminal() {
        return build(&|| {});
    }
    let bar = match cache {
        Some(_) => ProgressBar::new(total as u64).with_style(
            ProgressStyle::with_template(
                "building [{bar:20}] {pos}/{len} keys ({msg}), {elapsed}{left}",
            )
            .expect("static template")
            .progress_chars("=> ")
            // The estimate once a key is done (before, there is nothing to estimate from).
            .with_key(
                "left",
                |state: &ProgressState, w: &mut dyn std::fmt::Write| {
                    if state.pos() > 0 {
                        let _ = write!(w, ", ~{:#} left", HumanDuration(state.eta()));
                    }
                },
            ),
        ),
        None => ProgressBar::new_spinner().with_style(
            ProgressStyle::with_template("building {spinner} {msg}, {elapsed}")
                .expect("static template"),
        ),
    };
    // The cache's counts from before (a cache may have built other pianos in this run).
    let (hits_before, done_before) =
        cache.map_or((0, 0), |c| (c.hits.load(Ordering::Relaxed), c.done()));
    let show = |bar: &ProgressBar| match cache {
        Some(c) => {
            // The keys done read after the hits, so never fewer; the message, set last, draws
            // both.
            let hits = c.hits.load(Ordering::Relaxed) - hits_before;
            bar.set_position((c.done() - done_before) as u64);
            bar.set_message(format!("{hits} from the cache"));
        }
        None => {
            bar.set_message(format!("{total} keys, no cache of prepared keys"));
            bar.tick();
        }
    };
    let stop = AtomicBool::new(false);
    std::thread::scope(|s| {
        let poller = s.spawn(|| {
            while !stop.load(Ordering::Acquire) {
                show(&bar);
                std::thread::park_timeout(POLL);
            }
        });
        // The poller is joined before the bar is cleared, so that nothing draws it again.
        let poller = Mutex::new(Some(poller));
        let done = || {
            let Some(poller) = poller.lock().unwrap_or_else(|e| e.into_inner()).take() else {
                return;
            };
            stop.store(true, Ordering::Release);
            poller.thread().unpark();
            let _ = poller.join();
            bar.finish_and_clear();
        };
        let built = build(&done);
        done();
        built
    })
}
