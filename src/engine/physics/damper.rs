//! The damper: a felt pad that drops onto the strings when the key is released (unless a pedal
//! holds it off). It is modelled as a viscous point damper at `x_d` on every string's T and P
//! motion, `C_damper = c psi(x_d) psi(x_d)^T` added to the damping of Eq. 11 while it is down:
//! each mode then loses energy at the extra rate `c psi_n(x_d)^2`, a mode with a node under the
//! felt escaping it as on a real piano.

/// Damper parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DamperParams {
    /// Position of the felt as a fraction of the speaking length, `x_d / L_s` (-).
    pub position_ratio: f64,
    /// Viscous coefficient of the felt on the string (N s/m).
    pub damping_n_s_m: f64,
}
