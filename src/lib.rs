//! unacorda: a physical model of the piano's una-corda effect, after "Modelling the una-corda
//! effect in pianos" — stiff strings in three directions coupled through the bridge to a reduced
//! modal soundboard, struck by a nonlinear felt hammer, advanced with RK4.
//!
//! - [`engine`]: the physics (pure, no I/O),
//! - [`preset`]: parameter files,
//! - [`play`]: MIDI events and pedals applied to keys sharing one soundboard,
//! - [`keycache`]: prepared keys kept between runs,
//! - [`render`]: strikes to frames at the output rate,
//! - [`scaling`]: every key of the keyboard from a few anchor keys,
//! - [`analysis`]: spectra, envelopes and the paper's figures,
//! - [`audio`]: decimation and WAV output,
//! - [`midi`]: MIDI input — live byte parser, MIDI files, mapping to piano events,
//! - [`measure`]: speed and memory figures for the benchmarks and `unacorda bench`,
//! - [`cores`]: independent work (each key's preparation or analysis) on every core.

// Index loops mirror the equations' indices (modes k, directions d, strings s) across parallel
// arrays; iterator chains over three or four of them read worse.
#![allow(clippy::needless_range_loop)]

pub mod analysis;
pub mod audio;
pub mod board;
pub mod config;
pub mod cores;
pub mod engine;
pub mod keycache;
pub mod measure;
pub mod midi;
pub mod play;
pub mod render;
