//! The 88 keys prepared once per process and shared by every instance and every activation: a
//! keyboard's keys are prepared (read back from the command line's key cache where they are
//! kept, `$UNACORDA_CACHE`) the first time a keyboard, engine rate and integrator are asked for;
//! every activation then makes its piano from them with the pool size it wants, sharing their
//! coefficients (a change of pool size prepares nothing). One keyboard is prepared at a time: an activation
//! that asks for the keys a background build ([`crate::rebuild`]) is preparing waits for them.
//! Hosts run one engine per host rate: from 44.1 to 192 kHz the engine runs at the host's rate;
//! below, at the smallest multiple of it from 44.1 kHz, decimated by the synth. Kept keys the
//! cache refused (and prepared afresh) are told to the host by the next activation, on the main
//! thread.

use std::sync::{Arc, Mutex};
use unacorda::config::output::OutputSettings;
use unacorda::config::scaling::Scaling;
use unacorda::engine::exact::ExactPool;
use unacorda::engine::rk4::Rk4Pool;
use unacorda::engine::Integrator;
use unacorda::play::{Piano, PianoError, PreparedKeys};

/// Host rates the plugin plays at (Hz); others activate silent.
pub const HOST_RATES_HZ: std::ops::RangeInclusive<f64> = 8_000.0..=192_000.0;
/// The lowest rate the engine runs at (Hz).
pub const MIN_ENGINE_RATE_HZ: f64 = 44_100.0;
/// Keyboards' prepared keys kept (the oldest let go first).
const KEPT: usize = 4;

/// A piano on either engine (boxed: the two differ in size).
pub enum Pianos {
    Exact(Box<Piano<ExactPool>>),
    Rk4(Box<Piano<Rk4Pool>>),
}

/// A keyboard's keys prepared for either engine.
enum Keys {
    Exact(PreparedKeys<ExactPool>),
    Rk4(PreparedKeys<Rk4Pool>),
}

/// What an activation plays: a piano of its own and the synth's output settings.
pub struct Prepared {
    pub piano: Pianos,
    pub settings: OutputSettings,
    /// Engine steps per host frame (1 from 44.1 kHz up).
    pub oversampling: u32,
}

impl Prepared {
    /// With the pedal's halo or without ([`unacorda::play::Player::set_halo`]).
    pub fn with_halo(mut self, halo: bool) -> Self {
        match &mut self.piano {
            Pianos::Exact(piano) => piano.player.set_halo(halo),
            Pianos::Rk4(piano) => piano.player.set_halo(halo),
        }
        self
    }
}

/// Prepared keys' keyboard, engine rate (Hz) and integrator.
type Key = (&'static str, u32, Integrator);
/// A keyboard's keys as prepared, with the output settings of its keyboard.
type Kept = Arc<(Keys, OutputSettings)>;
/// The keyboards prepared so far, oldest first (any thread that activates an instance or builds
/// in the background).
static KEYBOARDS: Mutex<Vec<(Key, Kept)>> = Mutex::new(Vec::new());
/// Held while a keyboard is prepared, so that no two threads prepare at once (the same threads).
static BUILDING: Mutex<()> = Mutex::new(());
/// What builds found the user should know (kept keys refused and prepared afresh), left by
/// whichever thread built (an activation's, or a background build's) for the next activation to
/// tell the host on the main thread ([`take_warnings`]).
static WARNINGS: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// The warnings builds left since the last call (main thread, at activation).
pub fn take_warnings() -> Vec<String> {
    std::mem::take(&mut *WARNINGS.lock().unwrap_or_else(|e| e.into_inner()))
}

/// The channels of built-in keyboard `keyboard`'s output: 2 for a stereo pair of listeners, 1
/// for one (2 for a keyboard that cannot be read: it plays silence). Read once per process: the
/// port asks at every deactivation, and reading a keyboard parses its files.
pub fn channels(keyboard: &'static str) -> u32 {
    static READ: Mutex<Vec<(&str, u32)>> = Mutex::new(Vec::new());
    let mut read = READ.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(&(_, channels)) = read.iter().find(|(k, _)| *k == keyboard) {
        return channels;
    }
    let channels =
        Scaling::resolve(keyboard).map_or(2, |s| u32::from(s.output_settings().channels));
    read.push((keyboard, channels));
    channels
}

/// How many keyboards' prepared keys this process holds (each engine rate and integrator
/// counted apart): the memory the plugin keeps beside its instances' pianos.
pub fn keyboards_kept() -> usize {
    KEYBOARDS.lock().unwrap_or_else(|e| e.into_inner()).len()
}

/// Engine steps per host frame at `host_rate_hz`, or why it cannot play there.
pub fn oversampling(host_rate_hz: f64) -> Result<u32, String> {
    if !HOST_RATES_HZ.contains(&host_rate_hz) || host_rate_hz.fract() != 0.0 {
        return Err(format!(
            "unacorda: the host's sample rate {host_rate_hz} Hz is not a whole number of Hz in {}–{} Hz: the plugin stays silent",
            HOST_RATES_HZ.start(),
            HOST_RATES_HZ.end()
        ));
    }
    Ok((MIN_ENGINE_RATE_HZ / host_rate_hz).ceil().max(1.0) as u32)
}

/// The piano of `keyboard` with `voices` voices on `integrator` for a host at `host_rate_hz`,
/// made from its keyboard's prepared keys (prepared on all cores the first time).
pub fn prepare(
    keyboard: &'static str,
    host_rate_hz: f64,
    voices: usize,
    integrator: Integrator,
) -> Result<Prepared, String> {
    let oversampling = oversampling(host_rate_hz)?;
    let engine_rate = host_rate_hz as u32 * oversampling;
    let key = (keyboard, engine_rate, integrator);
    let kept = kept_or_built(key, &|| false)?;
    let (keys, settings) = &*kept;
    let failed = |e| format!("unacorda: {keyboard} with {voices} voices: {e}");
    let piano = match keys {
        Keys::Exact(keys) => Pianos::Exact(Box::new(keys.piano(voices).map_err(failed)?)),
        Keys::Rk4(keys) => Pianos::Rk4(Box::new(keys.piano(voices).map_err(failed)?)),
    };
    Ok(Prepared {
        piano,
        settings: OutputSettings {
            rate_hz: host_rate_hz,
            ..*settings
        },
        oversampling,
    })
}

/// Prepare and keep the keys [`prepare`] would make its piano from, if they are not kept yet (a
/// background build; the activation then finds them). `cancelled` calls the build off.
pub fn keep(
    keyboard: &'static str,
    host_rate_hz: f64,
    integrator: Integrator,
    cancelled: &(dyn Fn() -> bool + Sync),
) -> Result<(), String> {
    let engine_rate = host_rate_hz as u32 * oversampling(host_rate_hz)?;
    kept_or_built((keyboard, engine_rate, integrator), cancelled).map(|_| ())
}

/// The prepared keys for `key`: the kept ones, or prepared (after any build under way) and kept.
fn kept_or_built(key: Key, cancelled: &(dyn Fn() -> bool + Sync)) -> Result<Kept, String> {
    let kept = |key: &Key| {
        let keyboards = KEYBOARDS.lock().unwrap_or_else(|e| e.into_inner());
        keyboards
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, p)| p.clone())
    };
    if let Some(kept) = kept(&key) {
        return Ok(kept);
    }
    let _building = BUILDING.lock().unwrap_or_else(|e| e.into_inner());
    // The build this one waited for may have been these keys.
    if let Some(kept) = kept(&key) {
        return Ok(kept);
    }
    let built = Arc::new(build(key, cancelled)?);
    let mut keyboards = KEYBOARDS.lock().unwrap_or_else(|e| e.into_inner());
    if keyboards.len() >= KEPT {
        keyboards.remove(0);
    }
    keyboards.push((key, built.clone()));
    Ok(built)
}

fn build(
    key: Key,
    cancelled: &(dyn Fn() -> bool + Sync),
) -> Result<(Keys, OutputSettings), String> {
    let (keyboard, engine_rate_hz, integrator) = key;
    let mut scaling = Scaling::resolve(keyboard).map_err(|e| format!("unacorda: {e}"))?;
    scaling.base.preset.simulation.output_rate_hz = engine_rate_hz;
    let numbers: Vec<usize> = (1..=88).collect();
    let cache = unacorda::keycache::KeyCache::from_env();
    let failed = |e: PianoError| format!("unacorda: {keyboard} at {engine_rate_hz} Hz: {e}");
    let keys = match integrator {
        Integrator::Exact => Keys::Exact(
            PreparedKeys::prepare(&scaling, &numbers, cache.as_ref(), cancelled).map_err(failed)?,
        ),
        Integrator::Rk4 => Keys::Rk4(
            PreparedKeys::prepare(&scaling, &numbers, cache.as_ref(), cancelled).map_err(failed)?,
        ),
    };
    if let Some(warning) = cache.as_ref().and_then(|c| c.refusal_warning()) {
        let mut warnings = WARNINGS.lock().unwrap_or_else(|e| e.into_inner());
        warnings.push(format!("unacorda: {warning}"));
    }
    Ok((keys, scaling.output_settings()))
}
