//! `unacorda`: command-line front end (render, play, devices, modes, bench, figures, soundboard).

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use unacorda::analysis::figures::SOFT_PEDAL_DEPTHS;
use unacorda::audio::wav::WavStream;
use unacorda::board::generate_asset;
use unacorda::config::output::channel_layout;
use unacorda::config::preset::Preset;
use unacorda::config::preset::GRAND_BOARD_TOML;
use unacorda::config::scaling::Scaling;
use unacorda::engine::Strike;
use unacorda::render::{simulate, simulate_with, Length, Recording};

/// A strike rendered without `--seconds` rings until it is this far under its loudest (dB)…
const RING_OUT_FLOOR_DB: f64 = 60.0;
/// …or this long (s): the lowest keys of a grand ring for half a minute.
const RING_OUT_MAX_S: f64 = 30.0;
/// A preset's strike without `--seconds` (s): the span of the paper's spectrograms.
const PRESET_SECONDS: f64 = 4.0;

#[derive(Parser)]
#[command(
    name = "unacorda",
    version,
    about = "Physical-modelling piano: the una-corda effect",
    after_help = "Examples:
  unacorda render --key C4 --out c4.wav                 one note of the concert grand, to a WAV
  unacorda render --midi assets/midi/demo.mid --out demo.wav
  unacorda play                                         play from the first MIDI keyboard
  unacorda play --midi assets/midi/chorale.mid          play a file through the sound card

`unacorda COMMAND --help` says every flag, its range and its default."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render one strike of a preset or a key, or a MIDI file, to a WAV file (32-bit float), as
    /// fast as the machine allows, without any audio device (`play` is live). With no other flag
    /// it strikes the paper's c2 preset, mono, for 4 s on its RK4 reference (the paper's case).
    #[command(after_help = "Examples:
  unacorda render --key C4 --out c4.wav                      one key of the concert grand, rung out
  unacorda render --key A0 --una-corda --midi-velocity 100 --out a0.wav
  unacorda render --midi assets/midi/chorale.mid --out chorale.wav
  unacorda render --preset c2 --seconds 4 --out c2.wav       the paper's case on RK4")]
    Render {
        /// Accepted and not needed: render always works offline (scripts written when it was
        /// required still run).
        #[arg(long)]
        offline: bool,
        /// Built-in preset name (c2, the paper's bichord C2 on Table 1's board: the default,
        /// as the paper's reference case) or path to a preset .toml file.
        #[arg(long, default_value = "c2")]
        preset: String,
        /// Render this key of the keyboard scaling instead of the preset: a name (C4, Bb0, F#6)
        /// or a number 1 (A0) – 88 (C8).
        #[arg(long)]
        key: Option<String>,
        /// Play a standard MIDI file on the keyboard (all tracks, tempo map, pedals) instead of
        /// striking one note.
        #[arg(long, value_name = "FILE.mid", conflicts_with_all = ["key", "una_corda", "soft", "velocity", "midi_velocity", "release_at"])]
        midi: Option<PathBuf>,
        /// With --midi: size of the voice pool, 1–256 (the quietest voice is stolen when it is full).
        #[arg(long, default_value_t = unacorda::play::DEFAULT_VOICES, value_name = "N")]
        voices: usize,
        /// With --midi: the pedal's halo — under the sustain pedal every key's strings ring in
        /// sympathy, struck or not (each undamped key takes a voice: the pool holds at least 128;
        /// about twice the work of a performance without it).
        #[arg(long, requires = "midi")]
        halo: bool,
        /// With --midi: refuse performances longer than this (s), 1–86400; a file whose tempo map
        /// or deltas make it last hours is more likely a mistake than a request.
        #[arg(
            long,
            default_value_t = 600.0,
            value_name = "S",
            allow_negative_numbers = true
        )]
        max_seconds: f64,
        /// With --midi: seconds of sound after the last event, 0–60.
        #[arg(
            long,
            default_value_t = 2.0,
            value_name = "S",
            allow_negative_numbers = true
        )]
        tail: f64,
        /// Keyboard for --key and --midi: built-in name (concert, the default; paper, the paper's model) or path to a .toml file.
        #[arg(long, default_value = "concert")]
        keyboard: String,
        /// The full soft pedal: the hammer strikes one string of two (two of three); --soft 1.
        #[arg(long, conflicts_with = "soft")]
        una_corda: bool,
        /// The soft pedal's depth, 0–1: the action shifted by that fraction of a string spacing,
        /// each string meeting another part of the felt (1 is --una-corda).
        #[arg(long, value_name = "DEPTH", allow_negative_numbers = true)]
        soft: Option<f64>,
        /// `rk4`, the paper's RK4 at 10 × f_max (the reference; the default of --preset); or
        /// `exact`, each key's coupled modes advanced exactly at the output rate, the keys
        /// coupled through the board (within 0.2 cents and 1 % of RK4 on c2, C4, A0; the
        /// default of --key and --midi, several times faster).
        #[arg(long, value_enum)]
        integrator: Option<IntegratorArg>,
        /// Hammer speed at the strings (m/s), 0.01–10; default: the preset's.
        #[arg(
            long,
            value_name = "M/S",
            allow_negative_numbers = true,
            conflicts_with = "midi_velocity"
        )]
        velocity: Option<f64>,
        /// Hammer speed from a MIDI velocity 1–127, fractions allowed as a CC88 prefix gives them
        /// (0.31–6 m/s: 30 → 0.70, 80 → 2.37, 127 → 6).
        #[arg(long, value_name = "1-127", allow_negative_numbers = true)]
        midi_velocity: Option<f64>,
        /// Length of the strike's render (s), 0.001–600; default: for --key, until the note has
        /// rung out, 60 dB under its loudest, at most 30 s; for a preset, 4 s (the paper's
        /// spectrograms' span).
        #[arg(long, value_name = "S", allow_negative_numbers = true)]
        seconds: Option<f64>,
        /// Release the key after this many seconds: the damper falls on the strings.
        #[arg(long, value_name = "S", allow_negative_numbers = true)]
        release_at: Option<f64>,
        /// One channel, heard at the keyboard's (or preset's) listener, instead of its stereo
        /// pair of listeners (concert: `bass_close` left, `treble_close` right; heard from `above`
        /// in mono).
        #[arg(long)]
        mono: bool,
        /// Output WAV file (32-bit float; two channels for a stereo keyboard).
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        levels: levels::Levels,
    },
    /// The modes of one key's linearised system (hammer out of play): frequency, decay rate, T60,
    /// and which string and direction, or the board, holds each.
    Modes(modes::ModesArgs),
    /// How the keyboard sounds against a grand, key by key, from each key's linearised system:
    /// pitch on partials 2–8 against equal temperament, the first partial's pitch, and the T60 of
    /// the first partials' fastest and slowest modes (table, and CSV with --csv).
    Analyze(analyze::AnalyzeArgs),
    /// Play live: MIDI input (or a MIDI file in real time) on all 88 keys through an audio device.
    Play(live::PlayArgs),
    /// List audio outputs and MIDI inputs.
    Devices,
    /// Measure the engine on this machine: real-time factor of one voice and of the dense
    /// state-space baseline, FLOP rate against the core's peak, callback times and voices within
    /// the deadline, the cost of a held chord over time, memory; each figure with what it plays.
    Bench(bench::BenchArgs),
    /// Regenerate the paper's Figures 2–6 (PNG + CSV): the board's mobility, full vs reduced, and
    /// a preset struck una corda vs normal.
    Figures {
        #[arg(long, default_value = "figures")]
        out_dir: PathBuf,
        /// Board description for Figure 2 (default: the built-in grand board of the c2 preset).
        #[arg(long)]
        board: Option<PathBuf>,
        #[arg(long, default_value = "c2")]
        preset: String,
        /// Simulated length of each case (s), 0.1–20; the paper's spectrograms span 4 s.
        #[arg(long, default_value_t = 4.0, allow_negative_numbers = true)]
        seconds: f64,
    },
    /// Generate a reduced soundboard asset from a board description (TOML): clamped, ribbed
    /// orthotropic plate with bridges, all modes below f_max, reduced by the paper's rule.
    #[command(after_help = "Example:
  unacorda soundboard --input assets/soundboard_modes/grand.toml --out my_board.txt")]
    Soundboard {
        /// Board description (TOML): plate, ribs, bridges, listeners and the reduction's rule.
        #[arg(long, default_value = "assets/soundboard_modes/grand.toml")]
        input: PathBuf,
        /// Output asset (text). The default, in the current directory, never overwrites a board
        /// the keyboards ship with; pass a path under assets/soundboard_modes/ to replace one.
        #[arg(long, default_value = "soundboard_modes.txt")]
        out: PathBuf,
        /// Keys whose dominant modes are kept, instead of the description's `reduction.points`
        /// (comma-separated names: C2,C8).
        #[arg(long, value_delimiter = ',')]
        points: Option<Vec<String>>,
    },
}

mod analyze;
mod bench;
mod keys_bar;
mod levels;
mod live;
mod modes;

/// `--integrator` values.
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum IntegratorArg {
    Rk4,
    Exact,
}

impl From<IntegratorArg> for unacorda::engine::Integrator {
    fn from(a: IntegratorArg) -> Self {
        match a {
            IntegratorArg::Rk4 => Self::Rk4,
            IntegratorArg::Exact => Self::Exact,
        }
    }
}

/// Say (once the keys are built) how many kept keys were refused and prepared afresh, if any.
fn warn_refused(cache: Option<&unacorda::keycache::KeyCache>) {
    if let Some(warning) = cache.and_then(|c| c.refusal_warning()) {
        eprintln!("warning: {warning}");
    }
}

fn progress_bar(seconds: f64, label: &str) -> ProgressBar {
    // Anything that simulates more than a second shows progress.
    if seconds <= 1.0 {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(1000);
    pb.set_style(
        ProgressStyle::with_template("{msg:>12} [{bar:40}] {percent:>3}% eta {eta}")
            .expect("static template")
            .progress_chars("=> "),
    );
    pb.set_message(label.to_owned());
    pb
}

/// Write the recording's sound pressure as a WAV of `channels` channels (0 dBFS =
/// `full_scale_pa`); returns its peak (dBFS).
fn write_wav(out: &Path, rec: &Recording, full_scale_pa: f64, channels: u16) -> Result<f64> {
    let samples: Vec<f32> = rec
        .frames
        .iter()
        .flat_map(|f| {
            [f.pressure_pa, f.pressure_right_pa]
                .into_iter()
                .take(channels.into())
        })
        .map(|p| (p / full_scale_pa) as f32)
        .collect();
    let peak = samples.iter().fold(0f32, |m, s| m.max(s.abs()));
    unacorda::audio::wav::write_f32(out, rec.rate_hz as u32, channels, &samples)?;
    Ok(20.0 * f64::from(peak).max(1e-12).log10())
}

/// `render --offline --midi` on the engine `E`: the WAV streamed as it is rendered, Ctrl-C and
/// write failures leaving a valid file and saying how much it holds.
fn render_midi_file<E: unacorda::engine::VoicePool>(
    scaling: &unacorda::config::scaling::LoadedScaling,
    events: &[unacorda::midi::file::TimedEvent],
    offline: unacorda::render::Offline,
    path: &Path,
    out: &Path,
    length_s: f64,
) -> Result<()> {
    let started = std::time::Instant::now();
    let settings = scaling.output_settings();
    let mut wav = WavStream::create(out, settings.rate_hz as u32, settings.channels)?;
    // Ctrl-C ends the render at the next block and keeps what is written, a valid WAV.
    let interrupted = Arc::new(AtomicBool::new(false));
    {
        let interrupted = interrupted.clone();
        let _ = ctrlc::set_handler(move || interrupted.store(true, Ordering::Relaxed));
    }
    let (mut peak, mut failure) = (0f32, None);
    let cache = unacorda::keycache::KeyCache::from_env();
    let keyboard = unacorda::play::Keyboard {
        scaling,
        cache: cache.as_ref(),
    };
    let cores = offline.cores;
    // The keys the render prepares: those the file plays.
    let mut keys: Vec<usize> = events
        .iter()
        .filter_map(|e| match e.event {
            unacorda::midi::Event::NoteOn { note, .. } => unacorda::midi::piano_key(note),
            _ => None,
        })
        .collect();
    keys.sort_unstable();
    keys.dedup();
    // The render's bar, drawn from its first block on, once the keys' bar has ended.
    let mut pb = None;
    let r = keys_bar::building(cache.as_ref(), keys.len(), |keys_done| {
        unacorda::render::render_midi_into::<E>(
            keyboard,
            events,
            offline,
            |f| {
                pb.get_or_insert_with(|| {
                    keys_done();
                    progress_bar(length_s, "rendering")
                })
                .set_position((f * 1000.0) as u64)
            },
            None,
            |block| {
                peak = block.iter().fold(peak, |m, s| m.max(s.abs()));
                if let Err(e) = wav.write(block) {
                    failure = Some(e);
                    return ControlFlow::Break(());
                }
                if interrupted.load(Ordering::Relaxed) {
                    return ControlFlow::Break(());
                }
                ControlFlow::Continue(())
            },
        )
    });
    if let Some(pb) = pb {
        pb.finish_and_clear();
    }
    warn_refused(cache.as_ref());
    if let Some(e) = failure {
        return Err(e.into());
    }
    let r = match r {
        Ok(r) => r,
        Err(e) => {
            // Nothing was rendered: leave no header-only file behind.
            drop(wav);
            let _ = std::fs::remove_file(out);
            return Err(e).with_context(|| format!("{}", path.display()));
        }
    };
    let written_s = wav.finish()?;
    let took_s = started.elapsed().as_secs_f64();
    let summary = format!(
        "{} events on {} keys sharing one soundboard, {} voices, {:.1} s of {} sound in {:.1} s ({:.2} × real time on {cores} core{}, the keys' preparation included), peak {:.1} dBFS",
        events.len(),
        r.keys.len(),
        r.voices,
        written_s,
        channel_layout(r.channels),
        took_s,
        written_s / took_s,
        if cores == 1 { "" } else { "s" },
        20.0 * f64::from(peak).max(1e-12).log10()
    );
    if r.frames < r.total_frames {
        bail!(
            "interrupted: {} holds the first {written_s:.2} s of {length_s:.2} s as a valid WAV ({summary})",
            out.display()
        );
    }
    eprintln!("wrote {} ({summary})", out.display());
    Ok(())
}

fn main() -> std::process::ExitCode {
    // Bad flags exit with status 1, as every other bad input does (clap's own is 2); help and
    // version with 0.
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            let _ = e.print();
            return match e.use_stderr() {
                true => std::process::ExitCode::FAILURE,
                false => std::process::ExitCode::SUCCESS,
            };
        }
    };
    match run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Render {
            offline,
            preset,
            key,
            midi,
            voices,
            halo,
            max_seconds,
            tail,
            keyboard,
            una_corda,
            soft,
            integrator,
            velocity,
            midi_velocity,
            seconds,
            release_at,
            mono,
            out,
            levels,
        } => {
            levels.check()?;
            // Render always works offline; the flag is accepted for scripts that pass it.
            let _ = offline;
            if let Some(path) = midi {
                if !(0.0..=60.0).contains(&tail) {
                    bail!("--tail {tail}: expected a duration in [0, 60] s");
                }
                let mut events = unacorda::midi::file::read_file(&path)?;
                for e in &mut events {
                    e.event = e.event.with_velocity_curve(levels.velocity_curve);
                }
                let mut scaling = Scaling::resolve(&keyboard)?;
                if mono {
                    scaling.make_mono();
                }
                scaling.set_gain_db(levels.gain_db);
                if !(1.0..=86_400.0).contains(&max_seconds) {
                    bail!("--max-seconds {max_seconds}: expected a duration in [1, 86400] s");
                }
                let length_s = events.last().map_or(0.0, |e| e.time_s) + tail;
                if length_s > max_seconds {
                    bail!(
                        "{}: the performance lasts {length_s:.0} s (last event at {:.0} s), longer than --max-seconds {max_seconds:.0}; pass a larger --max-seconds to render it",
                        path.display(),
                        length_s - tail
                    );
                }
                let offline = unacorda::render::Offline {
                    tail_s: tail,
                    voices,
                    // Both cores where the machine has two, as `play` does.
                    cores: std::thread::available_parallelism().map_or(1, |n| n.get().min(2)),
                    halo,
                };
                return match integrator.unwrap_or(IntegratorArg::Exact) {
                    IntegratorArg::Rk4 => render_midi_file::<unacorda::engine::Rk4Pool>(
                        &scaling, &events, offline, &path, &out, length_s,
                    ),
                    IntegratorArg::Exact => render_midi_file::<unacorda::engine::exact::ExactPool>(
                        &scaling, &events, offline, &path, &out, length_s,
                    ),
                };
            }
            let shift = match (una_corda, soft) {
                (true, _) => 1.0,
                (false, Some(depth)) if (0.0..=1.0).contains(&depth) => depth,
                (false, Some(depth)) => {
                    bail!("--soft {depth}: expected the soft pedal's depth in [0, 1]")
                }
                (false, None) => 0.0,
            };
            if let Some(seconds) = seconds {
                if !(0.001..=600.0).contains(&seconds) {
                    bail!("--seconds {seconds}: expected a duration in [0.001, 600] s");
                }
            }
            let length = match (seconds, &key) {
                (Some(s), _) => Length::Seconds(s),
                (None, None) => Length::Seconds(PRESET_SECONDS),
                (None, Some(_)) => Length::RingOut {
                    floor_db: RING_OUT_FLOOR_DB,
                    max_s: RING_OUT_MAX_S,
                },
            };
            let (longest_s, rings_out) = match length {
                Length::Seconds(s) => (s, false),
                Length::RingOut { max_s, .. } => (max_s, true),
            };
            let mut loaded = match &key {
                Some(name) => {
                    let k = unacorda::config::scaling::parse_key(name).with_context(|| {
                        format!("--key {name}: expected A0–C8 (e.g. C4, Bb0, F#6) or 1–88")
                    })?;
                    Scaling::resolve(&keyboard)?.key_preset(k)?
                }
                None => Preset::resolve(&preset)?,
            };
            if mono {
                loaded.make_mono();
            }
            loaded.set_gain_db(levels.gain_db);
            let velocity_m_s = match (velocity, midi_velocity) {
                (_, Some(v)) => {
                    if !(1.0..=127.0).contains(&v) {
                        bail!("--midi-velocity {v}: expected 1–127");
                    }
                    let curved = unacorda::midi::curved_velocity(v, levels.velocity_curve);
                    unacorda::midi::hammer_speed_m_s(curved)
                        .context("the velocity curve keeps a velocity within 1–127")?
                }
                (Some(v), None) => v,
                (None, None) => loaded.preset.hammer.velocity_m_s,
            };
            if !(0.01..=10.0).contains(&velocity_m_s) {
                bail!("--velocity {velocity_m_s}: expected a hammer speed in [0.01, 10] m/s");
            }
            if let Some(r) = release_at {
                if !(0.0..=longest_s).contains(&r) {
                    bail!(
                        "--release-at {r}: expected a time in [0, {longest_s}] s (within {})",
                        if rings_out {
                            "the longest ring-out"
                        } else {
                            "the render's length"
                        }
                    );
                }
            }
            // The fast engine for a key of the keyboard; the paper's reference for its preset.
            let integrator = integrator.unwrap_or(match key {
                Some(_) => IntegratorArg::Exact,
                None => IntegratorArg::Rk4,
            });
            let started = std::time::Instant::now();
            let pb = progress_bar(longest_s, "rendering");
            let rec = simulate_with(
                &loaded,
                integrator.into(),
                Strike {
                    velocity_m_s,
                    shift,
                },
                release_at,
                length,
                |f| pb.set_position((f * 1000.0) as u64),
            )?;
            pb.finish_and_clear();
            let channels = loaded.output_settings().channels;
            let peak_dbfs = write_wav(&out, &rec, loaded.preset.radiation.full_scale_pa, channels)?;
            let written_s = rec.frames.len() as f64 / rec.rate_hz;
            let ending = match rings_out {
                false => String::new(),
                true if written_s < RING_OUT_MAX_S => {
                    format!(", rung out to {RING_OUT_FLOOR_DB:.0} dB under its loudest")
                }
                true => format!(
                    ", stopped at {RING_OUT_MAX_S:.0} s before it rang out (--seconds renders longer)"
                ),
            };
            eprintln!(
                "wrote {} ({}, {written_s:.2} s at {} Hz {}, peak {:.1} dBFS, {}, {} engine{ending}; {:.1} s to render)",
                out.display(),
                loaded.preset.name,
                rec.rate_hz,
                channel_layout(channels),
                peak_dbfs,
                match shift {
                    0.0 => "normal".to_string(),
                    1.0 => "una corda".to_string(),
                    _ => format!("soft pedal at {shift}"),
                },
                match integrator {
                    IntegratorArg::Rk4 => "RK4",
                    IntegratorArg::Exact => "exact",
                },
                started.elapsed().as_secs_f64()
            );
        }
        Command::Figures {
            out_dir,
            board,
            preset,
            seconds,
        } => {
            if !(0.1..=20.0).contains(&seconds) {
                bail!("--seconds {seconds}: expected a duration in [0.1, 20] s");
            }
            let loaded = Preset::resolve(&preset)?;
            std::fs::create_dir_all(&out_dir)
                .with_context(|| format!("creating {}", out_dir.display()))?;
            let v = loaded.preset.hammer.velocity_m_s;
            eprintln!(
                "simulating {} struck una corda and normally, {seconds} s each on RK4 (Figures 3–6)…",
                loaded.preset.name
            );
            // The two cases are independent: simulate them on two threads.
            let bars = MultiProgress::new();
            let [una_corda, normal] = std::thread::scope(|scope| {
                [true, false]
                    .map(|una_corda| {
                        let label = if una_corda { "una corda" } else { "normal" };
                        let pb = bars.add(progress_bar(seconds, label));
                        let loaded = &loaded;
                        scope.spawn(move || {
                            let rec = simulate(
                                loaded,
                                Strike {
                                    velocity_m_s: v,
                                    shift: if una_corda { 1.0 } else { 0.0 },
                                },
                                None,
                                seconds,
                                |f| pb.set_position((f * 1000.0) as u64),
                            );
                            pb.finish_and_clear();
                            rec
                        })
                    })
                    .map(|h| h.join().expect("simulation thread"))
            });
            let runs = [una_corda?, normal?];
            eprintln!(
                "simulating {} at five depths of the soft pedal, 0.5 s each on RK4 (Figure 7)…",
                loaded.preset.name
            );
            let depths: Vec<(f64, Recording)> = std::thread::scope(|scope| {
                SOFT_PEDAL_DEPTHS
                    .map(|shift| {
                        let loaded = &loaded;
                        scope.spawn(move || {
                            let strike = Strike {
                                velocity_m_s: v,
                                shift,
                            };
                            simulate(loaded, strike, None, 0.5, |_| {}).map(|r| (shift, r))
                        })
                    })
                    .into_iter()
                    .map(|h| h.join().expect("simulation thread"))
                    .collect::<Result<_, _>>()
            })?;
            let spec = match &board {
                Some(path) => unacorda::config::preset::load_board_spec(path)?,
                None => unacorda::config::preset::parse_board_spec(
                    GRAND_BOARD_TOML,
                    Path::new("assets/soundboard_modes/grand.toml"),
                )?,
            };
            eprintln!("solving the full soundboard and reducing it (Figure 2)…");
            let (solved, reduced, _) = generate_asset(&spec, "")?;
            eprintln!("drawing…");
            let mut written = unacorda::analysis::figures::figure2(
                &out_dir,
                &solved.modes,
                &reduced,
                &loaded.preset.soundboard.bridge_point,
            )?;
            written.extend(unacorda::analysis::figures::write_all(
                &out_dir, &runs[0], &runs[1],
            )?);
            written.extend(unacorda::analysis::figures::soft_pedal(
                &out_dir,
                &format!("{}, {v} m/s", loaded.preset.name),
                &depths,
            )?);
            for w in written {
                eprintln!("wrote {}", w.display());
            }
        }
        Command::Play(args) => live::play(args)?,
        Command::Devices => live::devices()?,
        Command::Modes(args) => modes::modes(args)?,
        Command::Analyze(args) => analyze::analyze(args)?,
        Command::Bench(args) => bench::bench(args)?,
        Command::Soundboard { input, out, points } => {
            let mut spec = unacorda::config::preset::load_board_spec(&input)?;
            let mut command = format!(
                "cargo run --release -- soundboard --input {} --out {}",
                input.display(),
                out.display()
            );
            if let Some(points) = points {
                command += &format!(" --points {}", points.join(","));
                spec.reduction.points = points;
            }
            let (solved, reduced, header) =
                generate_asset(&spec, &command).with_context(|| format!("{}", input.display()))?;
            let text = unacorda::config::asset::to_text(&reduced, &header);
            std::fs::write(&out, text).with_context(|| format!("writing {}", out.display()))?;
            eprintln!(
                "wrote {}: {} modes below {} Hz reduced to {} at {} keys",
                out.display(),
                solved.modes.len(),
                spec.reduction.f_max_hz,
                reduced.len(),
                solved.keys.len()
            );
        }
    }
    Ok(())
}
