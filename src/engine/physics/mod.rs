//! The physical parts of the paper's model, one module per equation group:
//! - [`string`]: stiff-string modes in T, P and L (Eq. 1–3),
//! - [`duplex`]: the distributed damper on the duplex segment (Eq. 13),
//! - [`soundboard`]: the reduced modal soundboard (Eq. 4–5),
//! - [`contact`]: the string–bridge contact springs and dampers (Eq. 6–7),
//! - [`hammer`]: the nonlinear felt hammer (Eq. 8–9),
//! - [`felt_profile`]: the hammer's felt across its width, which the soft pedal moves over,
//! - [`damper`]: the felt that silences a released key.

pub mod contact;
pub mod damper;
pub mod duplex;
pub mod felt_profile;
pub mod hammer;
pub mod soundboard;
pub mod string;

/// The three directions of motion at the bridge, in the paper's order (Eq. 5–6) and the index
/// order of every per-direction array in the engines: transverse to the board (T), longitudinal
/// along the string (L), parallel to the board (P).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    T = 0,
    L = 1,
    P = 2,
}

impl Direction {
    /// T, L, P: `Direction::ALL[d]` is direction index `d`.
    pub const ALL: [Direction; 3] = [Direction::T, Direction::L, Direction::P];

    /// The index of this direction in per-direction arrays.
    pub const fn index(self) -> usize {
        self as usize
    }

    pub const fn name(self) -> &'static str {
        match self {
            Direction::T => "T",
            Direction::L => "L",
            Direction::P => "P",
        }
    }

    /// T and P: the string bends (Eq. 2's stiff-string modes, the duplex damping of Eq. 13 and
    /// the damper felt act here); L: it stretches.
    pub const fn is_transverse(self) -> bool {
        !matches!(self, Direction::L)
    }

    /// The hammer strikes in T only (Eq. 8).
    pub const fn is_struck(self) -> bool {
        matches!(self, Direction::T)
    }
}

/// One mode as a damped oscillator, `qdd + 2 zeta omega qdot + omega^2 q = ...`: the coefficients
/// every engine reads for a string mode (Eq. 2–3) or a board mode (Eq. 4), formed in one place.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Oscillator {
    pub omega_rad_s: f64,
    pub damping_ratio: f64,
}

impl Oscillator {
    /// `omega^2` (1/s^2), the mode's stiffness per unit modal mass.
    pub fn omega2(&self) -> f64 {
        self.omega_rad_s * self.omega_rad_s
    }

    /// `2 zeta omega` (1/s), the mode's damping per unit modal mass.
    pub fn damping_per_s(&self) -> f64 {
        2.0 * self.damping_ratio * self.omega_rad_s
    }
}
