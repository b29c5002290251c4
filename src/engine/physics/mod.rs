//! The physical parts of the paper's model, one module per equation group:
//! - [`string`]: stiff-string modes in T, P and L (Eq. 1–3),
//! - [`duplex`]: the distributed damper on the duplex segment (Eq. 13),
//! - [`soundboard`]: the reduced modal soundboard (Eq. 4–5),
//! - [`contact`]: the string–bridge contact springs and dampers (Eq. 6–7),
//! - [`hammer`]: the nonlinear felt hammer (Eq. 8–9),
//! - [`damper`]: the felt that silences a released key.

pub mod contact;
pub mod damper;
pub mod duplex;
pub mod hammer;
pub mod soundboard;
pub mod string;
