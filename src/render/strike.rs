//! One key struck once, for analysis: from a preset and a strike to frames at the output rate —
//! forces (Eq. 19) and radiated sound.
//!
//! The [`Renderer`] advances the [`Rk4Pool`] at the internal rate, reads the outputs after each step,
//! turns the board's radiating source of each sound channel into pressure at its listener
//! (`p = rho0 / (4 pi r) dQ/dt`, DESIGN.md §1.7) and decimates every channel through the same
//! anti-alias filter to the output rate.

use crate::audio::radiate::Monopole;
use crate::audio::Decimator;
use crate::config::preset::LoadedPreset;
use crate::engine::exact::ExactUnison;
use crate::engine::MAX_STRINGS;
use crate::engine::{BuildError, Observation, Rk4Pool, Strike};
use crate::engine::{Engine, Integrator};

/// Number of decimated channels: hammer (3), bridge (3 × 3), total (3), bridge velocity (3),
/// pressure left and right.
const CHANNELS: usize = MAX_STRINGS + 3 * MAX_STRINGS + 3 + 3 + 2;

/// One output-rate frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Frame {
    /// Forces and velocities at the bridge and hammer (Eq. 19), low-passed with the audio.
    pub obs: Observation,
    /// Sound pressure at the left channel's listener (Pa), and at the right one's (the same for
    /// a mono preset).
    pub pressure_pa: f64,
    pub pressure_right_pa: f64,
}

impl Frame {
    fn pack(&self, out: &mut [f64; CHANNELS]) {
        let o = &self.obs;
        let flat = o
            .hammer_force_n
            .iter()
            .chain(o.bridge_force_n.iter().flatten())
            .chain(&o.total_force_n)
            .chain(&o.bridge_velocity_m_s)
            .chain([&self.pressure_pa, &self.pressure_right_pa]);
        for (slot, v) in out.iter_mut().zip(flat) {
            *slot = *v;
        }
    }

    fn unpack(ch: &[f64; CHANNELS]) -> Frame {
        let mut f = Frame::default();
        let mut it = ch.iter().copied();
        let mut next = || it.next().unwrap_or(0.0);
        f.obs.hammer_force_n.iter_mut().for_each(|x| *x = next());
        f.obs
            .bridge_force_n
            .iter_mut()
            .flatten()
            .for_each(|x| *x = next());
        f.obs.total_force_n.iter_mut().for_each(|x| *x = next());
        f.obs
            .bridge_velocity_m_s
            .iter_mut()
            .for_each(|x| *x = next());
        f.pressure_pa = next();
        f.pressure_right_pa = next();
        f
    }
}

/// An engine (by default the RK4 [`Rk4Pool`]) and its output stage, with analysis channels
/// (forces of voice 0).
pub struct Renderer<E: Engine> {
    instrument: E,
    decimator: Decimator,
    radiation: [Monopole; crate::engine::CHANNELS],
    output_rate_hz: f64,
    inputs: [f64; CHANNELS],
    outputs: [f64; CHANNELS],
}

impl Renderer<Rk4Pool> {
    pub fn new(preset: &LoadedPreset) -> Result<Renderer<Rk4Pool>, BuildError> {
        let spec = preset.unison_spec();
        let instrument = Rk4Pool::new(&spec)?;
        Ok(Self::from_instrument(instrument, preset))
    }
}

impl Renderer<ExactUnison> {
    /// The preset's key on the exact engine, stepping at the output rate.
    pub fn exact(preset: &LoadedPreset) -> Result<Self, BuildError> {
        let mut spec = preset.unison_spec();
        spec.sample_rate_hz = preset.output_rate_hz();
        Ok(Self::from_instrument(ExactUnison::new(&spec)?, preset))
    }
}

impl<E: Engine> Renderer<E> {
    /// The output stage of `preset` (rates, radiation) around a built system; the analysis
    /// channels follow its first voice.
    pub fn from_instrument(instrument: E, preset: &LoadedPreset) -> Renderer<E> {
        let ratio = (preset.output_rate_hz() * instrument.step_s())
            .recip()
            .round() as usize;
        let out = preset.output_settings();
        let rate_hz = 1.0 / instrument.step_s();
        Renderer {
            instrument,
            decimator: Decimator::new(ratio, CHANNELS),
            radiation: std::array::from_fn(|_| {
                Monopole::new(out.air_density_kg_m3, out.distance_m, rate_hz)
            }),
            output_rate_hz: preset.output_rate_hz(),
            inputs: [0.0; CHANNELS],
            outputs: [0.0; CHANNELS],
        }
    }

    pub fn instrument(&self) -> &E {
        &self.instrument
    }

    pub fn instrument_mut(&mut self) -> &mut E {
        &mut self.instrument
    }

    pub fn output_rate_hz(&self) -> f64 {
        self.output_rate_hz
    }

    /// Internal steps per output frame.
    pub fn oversampling(&self) -> usize {
        self.decimator.ratio()
    }

    /// Delay of the anti-alias filter (output samples).
    pub fn filter_delay_samples(&self) -> f64 {
        self.decimator.delay_out_samples()
    }

    /// Delay of the pressure (output samples) on top of the filter's: the engine's source's and
    /// the differentiator's.
    pub fn radiation_delay_samples(&self) -> f64 {
        let steps = self.instrument.source_delay_steps() as f64 + self.radiation[0].delay_samples();
        steps / self.decimator.ratio() as f64
    }

    pub fn strike(&mut self, strike: Strike) {
        self.instrument.strike(strike);
    }

    /// Advance by one output frame.
    pub fn next_frame(&mut self) -> Frame {
        loop {
            self.instrument.step();
            let obs = self.instrument.observe();
            let [left, right] = self.instrument.radiated_m3_s();
            Frame {
                obs,
                pressure_pa: self.radiation[0].pressure_pa(left),
                pressure_right_pa: self.radiation[1].pressure_pa(right),
            }
            .pack(&mut self.inputs);
            if self.decimator.push(&self.inputs, &mut self.outputs) {
                return Frame::unpack(&self.outputs);
            }
        }
    }
}

/// A whole offline simulation at the output rate.
#[derive(Debug, Clone)]
pub struct Recording {
    pub rate_hz: f64,
    /// Group delay of the anti-alias filter (s): frame `k` shows the system at
    /// `(k + 1) / rate_hz - delay_s` ([`Recording::time_s`]).
    pub delay_s: f64,
    /// The pressure's delay (s): the filter's, the engine's source's
    /// ([`crate::engine::Engine::source_delay_steps`]) and the differentiator's
    /// ([`crate::audio::radiate::Monopole::delay_samples`]).
    pub pressure_delay_s: f64,
    pub frames: Vec<Frame>,
}

impl Recording {
    /// Physical time of frame `k` (s), the filter delay removed: the frame is filtered from
    /// states after every step up to the `(k + 1)`-th frame's worth (each step is observed after
    /// it is taken), centred `delay_s` before the newest.
    pub fn time_s(&self, k: usize) -> f64 {
        (k + 1) as f64 / self.rate_hz - self.delay_s
    }

    /// One channel of the recording, extracted by `f`.
    pub fn channel(&self, f: impl Fn(&Frame) -> f64) -> Vec<f64> {
        self.frames.iter().map(f).collect()
    }
}

/// Strike the preset's unison, release the key after `release_s` (the damper drops; `None` holds
/// the key) and record `seconds` of output with RK4; `progress` receives the fraction done.
pub fn simulate(
    preset: &LoadedPreset,
    strike: Strike,
    release_s: Option<f64>,
    seconds: f64,
    progress: impl FnMut(f64),
) -> Result<Recording, BuildError> {
    simulate_with(
        preset,
        Integrator::Rk4,
        strike,
        release_s,
        seconds,
        progress,
    )
}

/// How long a strike is recorded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Length {
    /// This many seconds.
    Seconds(f64),
    /// Until the note has rung out: the sound's level (both channels' pressure, over
    /// [`RING_OUT_WINDOW_S`] windows) `floor_db` under its loudest window, or `max_s`, whichever
    /// comes first.
    RingOut { floor_db: f64, max_s: f64 },
}

impl From<f64> for Length {
    fn from(seconds: f64) -> Length {
        Length::Seconds(seconds)
    }
}

/// The window a ringing-out note's level is read over (s): long enough to span a few periods of
/// the lowest key's fundamental, so that a beat or a period's shape does not end it early.
pub const RING_OUT_WINDOW_S: f64 = 0.1;

/// [`simulate`] with the chosen integrator, for `length` ([`Length`]; seconds convert into it).
pub fn simulate_with(
    preset: &LoadedPreset,
    integrator: Integrator,
    strike: Strike,
    release_s: Option<f64>,
    length: impl Into<Length>,
    progress: impl FnMut(f64),
) -> Result<Recording, BuildError> {
    let length = length.into();
    match integrator {
        Integrator::Rk4 => record(Renderer::new(preset)?, strike, release_s, length, progress),
        Integrator::Exact => record(
            Renderer::exact(preset)?,
            strike,
            release_s,
            length,
            progress,
        ),
    }
}

/// The level of a note as it rings out, window by window: when it has fallen `floor_db` under
/// its loudest window.
struct RingOut {
    floor_db: f64,
    window: usize,
    at: usize,
    energy: f64,
    loudest: f64,
}

impl RingOut {
    fn new(floor_db: f64, rate_hz: f64) -> RingOut {
        RingOut {
            floor_db,
            window: ((RING_OUT_WINDOW_S * rate_hz).round() as usize).max(1),
            at: 0,
            energy: 0.0,
            loudest: 0.0,
        }
    }

    /// Take one frame; `Some(dB under the loudest window)` when a window ends (infinite while
    /// nothing has sounded: a strike too soft to move the strings has rung out at once).
    fn push(&mut self, f: &Frame) -> Option<f64> {
        self.energy += f.pressure_pa * f.pressure_pa + f.pressure_right_pa * f.pressure_right_pa;
        self.at += 1;
        if self.at < self.window {
            return None;
        }
        let e = std::mem::take(&mut self.energy);
        self.at = 0;
        self.loudest = self.loudest.max(e);
        Some(if self.loudest > 0.0 {
            -10.0 * (e / self.loudest).max(1e-30).log10()
        } else {
            f64::INFINITY
        })
    }
}

fn record<E: Engine>(
    mut r: Renderer<E>,
    strike: Strike,
    release_s: Option<f64>,
    length: Length,
    mut progress: impl FnMut(f64),
) -> Result<Recording, BuildError> {
    r.strike(strike);
    let rate_hz = r.output_rate_hz();
    let (seconds, mut ring) = match length {
        Length::Seconds(s) => (s, None),
        Length::RingOut { floor_db, max_s } => (max_s, Some(RingOut::new(floor_db, rate_hz))),
    };
    let n = (seconds * rate_hz).round() as usize;
    let release_frame = release_s.map(|s| (s * rate_hz).round() as usize);
    // A ring-out's cap is rarely reached: its frames grow as it goes, not to the cap up front.
    let mut frames = Vec::with_capacity(if ring.is_some() { 0 } else { n });
    let every = (rate_hz as usize / 20).max(1);
    // How far the note has fallen towards the floor, for the progress of a ring-out.
    let mut fallen = 0.0f64;
    for k in 0..n {
        if Some(k) == release_frame {
            r.instrument_mut().set_damper(true);
        }
        let frame = r.next_frame();
        frames.push(frame);
        if let Some(ring) = &mut ring {
            if let Some(under_db) = ring.push(&frame) {
                if under_db >= ring.floor_db {
                    break;
                }
                fallen = fallen.max(under_db / ring.floor_db);
            }
        }
        if k % every == 0 {
            progress((k as f64 / n as f64).max(fallen.min(1.0)));
        }
    }
    progress(1.0);
    Ok(Recording {
        rate_hz: r.output_rate_hz(),
        delay_s: r.filter_delay_samples() / r.output_rate_hz(),
        pressure_delay_s: (r.filter_delay_samples() + r.radiation_delay_samples())
            / r.output_rate_hz(),
        frames,
    })
}
