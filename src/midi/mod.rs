//! MIDI-facing mappings. Live input and MIDI files arrive with the keyboard work; the velocity
//! curve is shared by the CLI now.

/// Hammer speed at the lowest MIDI velocity (m/s): a pianissimo touch.
pub const MIN_HAMMER_SPEED_M_S: f64 = 0.5;
/// Hammer speed at velocity 127 (m/s): fortissimo.
pub const MAX_HAMMER_SPEED_M_S: f64 = 6.0;

/// MIDI velocity 1–127 → hammer speed (m/s), exponential between 0.5 and 6 m/s, so that equal
/// velocity steps are equal ratios of speed (and roughly equal steps in level); `None` for 0,
/// which MIDI defines as a note-off, or for values above 127.
pub fn hammer_speed_m_s(velocity: u8) -> Option<f64> {
    if !(1..=127).contains(&velocity) {
        return None;
    }
    let x = (velocity - 1) as f64 / 126.0;
    Some(MIN_HAMMER_SPEED_M_S * (MAX_HAMMER_SPEED_M_S / MIN_HAMMER_SPEED_M_S).powf(x))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curve_spans_the_documented_range_monotonically() {
        assert_eq!(hammer_speed_m_s(0), None);
        assert_eq!(hammer_speed_m_s(128), None);
        assert!((hammer_speed_m_s(1).unwrap() - 0.5).abs() < 1e-12);
        assert!((hammer_speed_m_s(127).unwrap() - 6.0).abs() < 1e-12);
        let v: Vec<f64> = (1..=127).map(|k| hammer_speed_m_s(k).unwrap()).collect();
        assert!(v.windows(2).all(|w| w[1] > w[0]));
    }
}
