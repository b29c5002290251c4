//! The audio thread's work, the same for live play and offline render: take the piano events due
//! in this block from a bounded lock-free queue (each at its own output frame), take control
//! commands from a channel, advance the shared-soundboard instrument at the internal rate, turn the
//! board's radiating source of each channel (left, right) into sound pressure (DESIGN.md §1.7) and
//! decimate it to the output rate. [`Synth::process`] never allocates, locks, prints or blocks (a test runs it under
//! `assert_no_alloc`), and runs with denormals flushed to zero. Nothing non-finite or outside
//! [-1, 1] leaves it: a voice that blows up is reset within the block, and a soft clipper bounds
//! the output.

use super::backlog::Backlog;
use super::clock::Clock;
use super::helper::Helper;
use super::radiate::{soft_clip, Monopole, KNEE};
use super::Decimator;
use crate::config::output::OutputSettings;
use crate::engine::{Pair, VoicePool, CHANNELS};
use crate::midi::Event;
use crate::play::Piano;
use crossbeam_channel::{Receiver, Sender, TrySendError};
use ringbuf::traits::{Consumer, Observer, Producer, Split};
use ringbuf::{HeapCons, HeapProd, HeapRb};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A piano event due at an output frame of the engine's clock (frame 0 is the first sample the
/// engine produced).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scheduled {
    pub frame: u64,
    pub event: Event,
}

/// Commands from the controlling thread.
#[derive(Debug)]
pub enum Control<E: VoicePool> {
    /// Output silence from now on and stop simulating.
    Shutdown,
    /// Play another piano (a preset or keyboard change), built off the audio thread; the old
    /// one is handed back through the handle so that it is never freed on the audio thread.
    Replace(Box<Piano<E>>),
}

/// Energy above which a voice (or the board) is taken as blown up and reset: a fortissimo hammer
/// brings about 0.2 J, so 50 J is far beyond anything the model can hold legitimately.
pub const RUNAWAY_J: f64 = 50.0;

/// The growth guard: when the pool's mechanical energy (strings, contact springs, board) has stood
/// above what it held when nothing last began to drive it — by more than [`GROWTH_TOLERANCE`] —
/// at the end of this many housekeeping periods ([`HOUSEKEEPING_FRAMES`]) in a row, while nothing
/// drove it (no hammer in play, no voice fading, none joining or leaving), every sounding voice
/// and the board are reset. A physical
/// piano's energy only falls between strikes, and the engines' stays within rounding of that
/// (`tests/stability.rs`), so this is a safety net for a numerical runaway too slow for
/// [`RUNAWAY_J`] (steady or oscillating), not something music can trigger.
pub const GROWTH_PERIODS: u32 = 8;
/// Relative rise over its reference that the growth guard counts (rounding moves the energy by
/// ~1e-12 of itself; the slowest physical decay, A0's first partial, loses 2e-5 per period).
pub const GROWTH_TOLERANCE: f64 = 1e-6;

/// The engine's runs end on this grid of output frames (counted from the synth's first frame) as
/// well as at events: the exact engine advances a run in blocks of 32 steps from its start, in
/// single precision inside a block, so a run cut elsewhere would round otherwise. Whatever
/// lengths the callbacks have, as long as each ends on this grid (or the host's blocks are
/// realigned to it: [`super::Aligned`]), every sample is the same.
pub const ALIGN_FRAMES: u64 = 32;

/// Runaways are reset and the growth guard checked on this grid of output frames, not at the
/// callbacks' ends, for the same reason: a voice reset a frame earlier would change what follows.
pub const HOUSEKEEPING_FRAMES: u64 = 64;

/// Silent voices are retired, and what of a voice's strings has died away left out, on this
/// coarser grid (a multiple of [`HOUSEKEEPING_FRAMES`]): the offline render's blocks, so that its
/// tails are as they were before the grid.
pub const RETIRE_FRAMES: u64 = 256;

/// Counters the audio thread publishes (relaxed atomics: readable from any thread at any time).
#[derive(Debug, Default)]
pub struct Stats {
    pub blocks: AtomicU64,
    pub frames: AtomicU64,
    /// Events that arrived after their frame had passed (applied at the block's start).
    pub late_events: AtomicU64,
    /// Largest number of simultaneously simulated voices.
    pub peak_voices: AtomicU64,
    /// Voices (or the board) reset because a value became non-finite or the energy ran away.
    pub resets: AtomicU64,
    /// Times the growth guard ([`GROWTH_PERIODS`]) reset the pool.
    pub growth_resets: AtomicU64,
    /// Output samples the soft clipper bent (above [`KNEE`] in magnitude), and the largest
    /// magnitude before it (`f32` bits; non-negative floats order as their bits).
    pub clipped: AtomicU64,
    pub peak_before_clip: AtomicU64,
    /// Engine runs split over two cores, and runs done on one because the helper thread did not
    /// start in time ([`Synth::use_second_core`]).
    pub two_core_runs: AtomicU64,
    pub helper_late: AtomicU64,
    /// The helper thread's real-time priority, as it reported it.
    pub helper_priority: super::priority::Promotion,
}

/// The audio thread's side: owns the piano, reads events and commands.
pub struct Synth<E: VoicePool> {
    piano: Box<Piano<E>>,
    events: HeapCons<Scheduled>,
    control: Receiver<Control<E>>,
    returned: Sender<Box<Piano<E>>>,
    clock: Arc<Clock>,
    stats: Arc<Stats>,
    decimator: Decimator,
    radiation: [Monopole; CHANNELS],
    scale: f64,
    silence_j: f64,
    frame: u64,
    running: bool,
    /// The board's radiating source of each channel after each step of the current run of steps
    /// (a run is at most [`ALIGN_FRAMES`] long).
    volume: Vec<[f64; CHANNELS]>,
    helper: Option<Helper>,
    /// The growth guard's memory, and whether something drove the pool when this period began.
    growth: Growth,
    driven_at_start: bool,
}

/// What the growth guard ([`GROWTH_PERIODS`]) remembers: the pool's energy when nothing last
/// began to drive it, which voices were sounding then (a hash), and the periods in a row its
/// energy has stood above that. The default is a pool at rest.
#[derive(Debug, Clone, Copy, Default)]
struct Growth {
    reference_j: f64,
    sounding: u64,
    rising_periods: u32,
}

/// The other threads' side: schedule events, send commands, read the clock and the counters.
pub struct SynthHandle<E: VoicePool> {
    pub events: HeapProd<Scheduled>,
    control: Sender<Control<E>>,
    returned: Receiver<Box<Piano<E>>>,
    pub clock: Arc<Clock>,
    pub stats: Arc<Stats>,
    /// The releases a full queue could not take from [`SynthHandle::schedule_live`], and the
    /// strikes it dropped.
    pub backlog: Backlog,
}

/// Why the synth cannot be set up.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SynthError {
    #[error(
        "the internal rate {internal_hz} Hz is not an integer multiple of the output rate {output_hz} Hz"
    )]
    Rates { internal_hz: f64, output_hz: f64 },
}

/// Room in the event queue: a second of dense playing.
pub const EVENT_QUEUE: usize = 4096;

impl<E: VoicePool> Synth<E> {
    /// A synth playing `piano` with its pair of handles; `queue` events fit in the queue.
    pub fn new(
        piano: Piano<E>,
        out: OutputSettings,
        queue: usize,
    ) -> Result<(Synth<E>, SynthHandle<E>), SynthError> {
        let internal_rate_hz = 1.0 / piano.instrument.step_s();
        let ratio = (internal_rate_hz / out.rate_hz).round();
        if ratio < 1.0 || (ratio * out.rate_hz - internal_rate_hz).abs() > 1e-6 * internal_rate_hz {
            return Err(SynthError::Rates {
                internal_hz: internal_rate_hz,
                output_hz: out.rate_hz,
            });
        }
        let (prod, cons) = HeapRb::<Scheduled>::new(queue.max(1)).split();
        let (control_tx, control_rx) = crossbeam_channel::bounded(8);
        // One slot: `SynthHandle::replace` waits for the old piano before sending another.
        let (returned_tx, returned_rx) = crossbeam_channel::bounded(1);
        let clock = Arc::new(Clock::new(out.rate_hz));
        let stats = Arc::new(Stats::default());
        let synth = Synth {
            piano: Box::new(piano),
            events: cons,
            control: control_rx,
            returned: returned_tx,
            clock: clock.clone(),
            stats: stats.clone(),
            decimator: Decimator::new(ratio as usize, CHANNELS),
            radiation: std::array::from_fn(|_| {
                Monopole::new(out.air_density_kg_m3, out.distance_m, internal_rate_hz)
            }),
            scale: 1.0 / out.full_scale_pa,
            silence_j: out.silence_j,
            frame: 0,
            running: true,
            volume: vec![[0.0; CHANNELS]; ALIGN_FRAMES as usize * ratio as usize],
            helper: None,
            growth: Growth::default(),
            driven_at_start: false,
        };
        let handle = SynthHandle {
            events: prod,
            control: control_tx,
            returned: returned_rx,
            clock,
            stats,
            backlog: Backlog::default(),
        };
        Ok((synth, handle))
    }

    /// The piano being played.
    pub fn piano(&self) -> &Piano<E> {
        &self.piano
    }

    /// The piano, to change its state outside the event path (tests, hosts that drive the engine
    /// directly).
    pub fn piano_mut(&mut self) -> &mut Piano<E> {
        &mut self.piano
    }

    /// Whether it still plays (no shutdown received).
    pub fn is_running(&self) -> bool {
        self.running
    }

    /// Output frames produced so far.
    pub fn frame(&self) -> u64 {
        self.frame
    }

    /// Fill an interleaved block of `channels` channels: the left and right channels in the first
    /// two (the rest silent), or their mean in one (a mono piano's two channels are the same).
    pub fn process(&mut self, out: &mut [f32], channels: usize) {
        self.process_on(out, channels, None);
    }

    /// [`Synth::process`] with `pair` lending the engine its second core for this block (a host's
    /// thread pool, [`super::host_pool`]); where it declines ([`Pair::declines`]), the helper
    /// thread, if any.
    pub fn process_on(&mut self, out: &mut [f32], channels: usize, pair: Option<&dyn Pair>) {
        // SAFETY: as in `process_with`.
        unsafe {
            no_denormals::no_denormals(|| {
                self.render(out, channels.max(1), &mut |_, _| {}, false, pair)
            })
        }
    }

    /// [`Synth::process`], calling `tap(instrument, frame)` after each output frame (for tests and
    /// analysis; the engine then runs one frame at a time).
    pub fn process_with(&mut self, out: &mut [f32], channels: usize, mut tap: impl FnMut(&E, u64)) {
        // SAFETY: flush-to-zero and denormals-are-zero only change how subnormal results are
        // rounded (to zero) for the duration of the block on this thread; the guard restores MXCSR.
        unsafe {
            no_denormals::no_denormals(|| self.render(out, channels.max(1), &mut tap, true, None))
        }
    }

    /// The decimation filter's delay, in output frames (0 when the engine runs at the output
    /// rate).
    pub fn decimation_delay_frames(&self) -> f64 {
        self.decimator.delay_out_samples()
    }

    /// Whether nothing sounds or is about to: no event queued, no hammer in play or voice
    /// fading, and the strings and board holding less than the silence threshold (strings a pedal
    /// holds up may still be simulated, at rest).
    pub fn is_quiet(&self) -> bool {
        let inst = &self.piano.instrument;
        self.events.is_empty() && !inst.is_driven() && inst.mechanical_energy_j() < self.silence_j
    }

    /// Silence everything at once (a host's reset): the queued events dropped, every key and
    /// pedal up, every voice's strings and the board at rest, the output stage's memory cleared.
    /// Never allocates.
    pub fn silence(&mut self) {
        while self.events.try_pop().is_some() {}
        self.piano.apply(Event::ResetControllers);
        self.piano.apply(Event::AllSoundOff);
        self.piano.instrument.silence();
        // Strings and board at rest radiate nothing.
        self.radiation.iter_mut().for_each(|r| r.restart(0.0));
        self.decimator.reset();
        self.growth = Growth::default();
    }

    /// Give the engine a second core from now on: a helper thread that takes half of each of
    /// the exact pool's block passes while the callback does the other half (engines that cannot
    /// split ignore it).
    pub fn use_second_core(&mut self) -> std::io::Result<()> {
        self.use_second_core_with(super::helper::run_job)
    }

    /// Have the helper thread (if any) ask for real-time priority, as the audio thread does
    /// ([`super::priority`]); its outcome shows in [`Stats::helper_priority`].
    pub fn ask_real_time_priority(&self) {
        if let Some(helper) = &self.helper {
            helper.ask_real_time_priority();
        }
    }

    /// [`Synth::use_second_core`], the helper running each of its jobs inside `wrap`.
    pub fn use_second_core_with(&mut self, wrap: super::helper::JobWrapper) -> std::io::Result<()> {
        self.helper = Some(Helper::spawn_with(wrap)?);
        Ok(())
    }

    /// `frame_by_frame`: the engine runs one frame at a time (so that `tap` sees every frame);
    /// otherwise it runs from event to event.
    fn render(
        &mut self,
        out: &mut [f32],
        channels: usize,
        tap: &mut impl FnMut(&E, u64),
        frame_by_frame: bool,
        pair: Option<&dyn Pair>,
    ) {
        let started = Instant::now();
        let frames_out = (out.len() / channels) as u64;
        self.clock.publish(self.frame, started, frames_out);
        while let Ok(command) = self.control.try_recv() {
            match command {
                Control::Shutdown => self.running = false,
                Control::Replace(new) => {
                    let old = std::mem::replace(&mut self.piano, new);
                    self.radiation.iter_mut().for_each(|r| r.restart(0.0));
                    self.growth = Growth::default();
                    if let Err(TrySendError::Full(old) | TrySendError::Disconnected(old)) =
                        self.returned.try_send(old)
                    {
                        // Only when the handle is gone (shutting down): nothing else can free it.
                        std::mem::forget(old);
                    }
                }
            }
        }
        let block_start = self.frame;
        let ratio = self.decimator.ratio();
        // The output channels that carry sound: the left and right, or their mean in one.
        let width = channels.min(CHANNELS);
        let mut frames = out.chunks_exact_mut(channels);
        loop {
            while let Some(&Scheduled { frame, event }) = self.events.try_peek() {
                if frame > self.frame {
                    break;
                }
                self.events.try_pop();
                if frame < block_start {
                    self.stats.late_events.fetch_add(1, Ordering::Relaxed);
                }
                self.piano.apply(event);
            }
            // The frames up to the next event (or the block's end) in one run of the engine.
            let left = frames.len();
            if left == 0 {
                break;
            }
            let next = self.events.try_peek().map_or(u64::MAX, |e| e.frame);
            let grid = (self.frame / ALIGN_FRAMES + 1) * ALIGN_FRAMES;
            let until = usize::try_from(next.min(grid) - self.frame).unwrap_or(usize::MAX);
            let n = if frame_by_frame { 1 } else { left.min(until) };
            if self.running {
                let helper = self.helper.as_ref().map(|h| h as &dyn Pair);
                let cores = pair.filter(|p| !p.declines()).or(helper);
                let inst = &mut self.piano.instrument;
                // The voices' energies are read at a housekeeping period's end, by an event
                // (the choice of a voice), and by the host after the callback.
                let end = self.frame + n as u64;
                inst.energies_read_after_run(
                    end.is_multiple_of(HOUSEKEEPING_FRAMES) || end == next || n == left,
                );
                inst.run(&mut self.volume[..n * ratio], cores);
            }
            let mut blown = false;
            let (mut clipped, mut peak) = (0, 0f32);
            for i in 0..n {
                let p = match self.running {
                    true => self.pressure_pa(i * ratio..(i + 1) * ratio),
                    false => [0.0; CHANNELS],
                };
                let mut y: [f32; CHANNELS] = match channels {
                    1 => [(0.5 * (p[0] + p[1]) * self.scale) as f32; CHANNELS],
                    _ => p.map(|p| (p * self.scale) as f32),
                };
                let y = &mut y[..width];
                // Something blew up: silence until it is reset, below.
                blown |= y.iter().any(|y| !y.is_finite());
                for y in y.iter_mut() {
                    *y = if blown {
                        0.0
                    } else {
                        clipped += u64::from(y.abs() > KNEE);
                        peak = peak.max(y.abs());
                        soft_clip(*y)
                    };
                }
                if let Some(frame_out) = frames.next() {
                    frame_out[..width].copy_from_slice(y);
                    frame_out[width..].fill(0.0);
                }
                tap(&self.piano.instrument, self.frame);
                self.frame += 1;
            }
            self.stats.clipped.fetch_add(clipped, Ordering::Relaxed);
            self.stats
                .peak_before_clip
                .fetch_max(u64::from(peak.to_bits()), Ordering::Relaxed);
            if blown {
                self.reset_runaways();
            }
            if self.frame.is_multiple_of(HOUSEKEEPING_FRAMES) {
                self.housekeep();
            }
        }
        self.stats
            .frames
            .fetch_add(self.frame - block_start, Ordering::Relaxed);
        self.stats.blocks.fetch_add(1, Ordering::Relaxed);
        if let Some(helper) = &self.helper {
            let s = &self.stats;
            s.two_core_runs
                .store(helper.joined_jobs(), Ordering::Relaxed);
            s.helper_late.store(helper.late_jobs(), Ordering::Relaxed);
            s.helper_priority.copy_from(helper.promotion());
            // The next callback comes a block after this one began (a device's clock).
            let period_s = frames_out as f64 / self.clock.rate_hz();
            helper.rest_until(started + Duration::try_from_secs_f64(period_s).unwrap_or_default());
        }
    }

    /// At the end of a housekeeping period ([`HOUSEKEEPING_FRAMES`]): reset what has blown up or
    /// grown, retire the silent voices (every [`RETIRE_FRAMES`]), count the voices, and note
    /// whether something drives the pool as the next period begins.
    fn housekeep(&mut self) {
        self.reset_runaways();
        self.guard_growth(self.driven_at_start);
        let inst = &mut self.piano.instrument;
        if self.frame.is_multiple_of(RETIRE_FRAMES) {
            inst.shed_modes();
            inst.retire_silent(self.silence_j);
        }
        let active = (0..inst.n_voices()).filter(|&v| inst.is_active(v)).count() as u64;
        self.stats.peak_voices.fetch_max(active, Ordering::Relaxed);
        self.driven_at_start = self.piano.instrument.is_driven();
    }

    /// Reset whatever has blown up, and the output stage's memory with it if anything did.
    fn reset_runaways(&mut self) {
        let n = self.piano.instrument.reset_runaways(RUNAWAY_J);
        if n > 0 || self.radiation.iter().any(|r| !r.is_finite()) {
            self.restart_radiation();
            self.decimator.reset();
            self.stats.resets.fetch_add(n as u64, Ordering::Relaxed);
        }
    }

    /// The growth guard ([`GROWTH_PERIODS`]), at a period's end; `driven`: something drove the pool
    /// at the period's start.
    fn guard_growth(&mut self, driven: bool) {
        let inst = &mut self.piano.instrument;
        let e = inst.mechanical_energy_j();
        // FNV-1a over the sounding voices: a voice joining brings the energy its strings held in
        // following the board, one leaving takes it away.
        let sounding = (0..inst.n_voices())
            .filter(|&k| inst.is_active(k))
            .fold(0xcbf2_9ce4_8422_2325u64, |h, k| {
                (h ^ k as u64).wrapping_mul(0x100_0000_01b3)
            });
        let g = &mut self.growth;
        if driven || inst.is_driven() || sounding != g.sounding {
            *g = Growth {
                reference_j: e,
                sounding,
                rising_periods: 0,
            };
            return;
        }
        let above = e > g.reference_j * (1.0 + GROWTH_TOLERANCE) && e > self.silence_j;
        g.rising_periods = if above { g.rising_periods + 1 } else { 0 };
        if g.rising_periods >= GROWTH_PERIODS {
            // Every voice holding energy, and the board.
            let n = inst.reset_runaways(0.0);
            self.restart_radiation();
            self.decimator.reset();
            self.stats.resets.fetch_add(n as u64, Ordering::Relaxed);
            self.stats.growth_resets.fetch_add(1, Ordering::Relaxed);
            // The same voices stay; their energy is measured again from rest.
            (self.growth.reference_j, self.growth.rising_periods) = (0.0, 0);
        }
    }

    /// The radiation's memory set to where the instrument is now (after a reset).
    fn restart_radiation(&mut self) {
        let q = self.piano.instrument.radiated_m3_s();
        for (r, q) in self.radiation.iter_mut().zip(q) {
            r.restart(q);
        }
    }

    /// The sound pressure (Pa) of each channel of one output frame from the radiating sources of
    /// its steps.
    fn pressure_pa(&mut self, steps: std::ops::Range<usize>) -> [f64; CHANNELS] {
        let mut out = [0.0; CHANNELS];
        for i in steps {
            let q = self.volume[i];
            let p: [f64; CHANNELS] = std::array::from_fn(|c| self.radiation[c].pressure_pa(q[c]));
            self.decimator.push(&p, &mut out);
        }
        out
    }
}

impl<E: VoicePool> SynthHandle<E> {
    /// Queue an event; returns it back if the queue is full.
    pub fn schedule(&mut self, event: Scheduled) -> Result<(), Scheduled> {
        self.events.try_push(event)
    }

    /// Queue a live event (one that cannot wait for room), never losing a release: what a full
    /// queue cannot take waits in [`SynthHandle::backlog`] (a release) or is dropped and counted
    /// there (a strike). Releases already waiting go first; while any still waits a new event
    /// joins them rather than overtake them.
    pub fn schedule_live(&mut self, event: Scheduled) {
        self.flush_backlog(event.frame);
        if !self.backlog.is_empty() {
            self.backlog.keep(event.event);
        } else if let Err(refused) = self.events.try_push(event) {
            self.backlog.keep(refused.event);
        }
    }

    /// Queue the releases waiting in the backlog, at `frame`, as far as the queue has room.
    pub fn flush_backlog(&mut self, frame: u64) {
        while let Some(event) = self.backlog.next() {
            if self.events.try_push(Scheduled { frame, event }).is_err() {
                return;
            }
            self.backlog.taken(event);
        }
    }

    /// Queue `events[next..]` (times from `start_frame`) as far as the queue has room; returns
    /// the index of the first event not queued.
    pub fn schedule_timed(
        &mut self,
        events: &[crate::midi::file::TimedEvent],
        mut next: usize,
        start_frame: u64,
    ) -> usize {
        let rate_hz = self.clock.rate_hz();
        while next < events.len() && self.events.vacant_len() > 0 {
            let e = &events[next];
            let frame = start_frame + (e.time_s * rate_hz).round() as u64;
            // Room was checked: the push cannot fail.
            let _ = self.events.try_push(Scheduled {
                frame,
                event: e.event,
            });
            next += 1;
        }
        next
    }

    /// Ask the audio thread to go silent.
    pub fn shutdown(&self) {
        let _ = self.control.send(Control::Shutdown);
    }

    /// Hand the audio thread a new piano and wait until it gives the old one back, which is then
    /// freed here. `process` must be running (the wait ends when it picks the command up).
    pub fn replace(&self, piano: Piano<E>) -> Option<Box<Piano<E>>> {
        self.control.send(Control::Replace(Box::new(piano))).ok()?;
        self.returned.recv().ok()
    }
}
