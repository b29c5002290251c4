//! Files become specifications: presets and the keyboard scaling (TOML), the soundboard asset, the
//! output stage's settings.

pub mod asset;
pub mod output;
pub mod preset;
pub mod scaling;
