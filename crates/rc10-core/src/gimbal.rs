//! A yaw/pitch gimbal on a turning chassis: where the yaw and pitch motors must go so the
//! gimbal points at a world heading, the short way round, within mechanical limits.

use crate::math::{constrain, wrap_deg_180};

/// Mechanical limits of a gimbal, degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GimbalLimits {
    /// Lowest pitch, degrees (negative is down).
    pub pitch_min_deg: f32,
    /// Highest pitch, degrees.
    pub pitch_max_deg: f32,
    /// Yaw range relative to the chassis, degrees, for gimbals whose cables do not allow
    /// endless rotation; `None` for a slip ring (any angle, shortest way).
    pub yaw_range_deg: Option<(f32, f32)>,
}

/// Where to send the gimbal motors.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GimbalTarget {
    /// Multi-turn target for the yaw motor relative to the chassis, degrees (use
    /// `set_target_total_angle_deg`): the nearest angle to where the motor is now.
    pub yaw_motor_deg: f32,
    /// Pitch target within the limits, degrees.
    pub pitch_deg: f32,
}

impl GimbalLimits {
    /// Targets for pointing at `yaw_world_deg` / `pitch_deg` while the chassis faces
    /// `chassis_yaw_deg`, with the yaw motor now at `yaw_motor_now_deg` (its multi-turn angle
    /// relative to the chassis). `None` if any input is NaN or infinite: keep the old targets.
    ///
    /// ```
    /// use rc10_core::gimbal::GimbalLimits;
    /// let g = GimbalLimits { pitch_min_deg: -20.0, pitch_max_deg: 30.0, yaw_range_deg: None };
    /// // Look at world −170° with the chassis at 170°: 20° relative to the chassis. The yaw
    /// // motor is at 700° (multi-turn, ≡ −20°), so it turns +40° to 740°, not back 680°.
    /// let t = g.targets(-170.0, 45.0, 170.0, 700.0).unwrap();
    /// assert!((t.yaw_motor_deg - 740.0).abs() < 1e-3);
    /// assert_eq!(t.pitch_deg, 30.0); // clamped
    /// ```
    pub fn targets(
        &self,
        yaw_world_deg: f32,
        pitch_deg: f32,
        chassis_yaw_deg: f32,
        yaw_motor_now_deg: f32,
    ) -> Option<GimbalTarget> {
        let inputs = [yaw_world_deg, pitch_deg, chassis_yaw_deg, yaw_motor_now_deg];
        if inputs.iter().any(|x| !x.is_finite()) {
            return None;
        }
        let relative = wrap_deg_180(yaw_world_deg - chassis_yaw_deg);
        let yaw_motor_deg = match self.yaw_range_deg {
            None => yaw_motor_now_deg + wrap_deg_180(relative - yaw_motor_now_deg),
            // Limited yaw: the angle within the range (no wrapping through the cable stop).
            Some((lo, hi)) => constrain(relative, lo, hi),
        };
        Some(GimbalTarget {
            yaw_motor_deg,
            pitch_deg: constrain(pitch_deg, self.pitch_min_deg, self.pitch_max_deg),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SLIP_RING: GimbalLimits = GimbalLimits {
        pitch_min_deg: -20.0,
        pitch_max_deg: 30.0,
        yaw_range_deg: None,
    };

    #[test]
    fn world_heading_is_held_while_chassis_turns() {
        // World target 90°; chassis at 0°, 45°, 90°: relative 90, 45, 0.
        for (chassis, expect) in [(0.0, 90.0), (45.0, 45.0), (90.0, 0.0)] {
            let t = SLIP_RING.targets(90.0, 0.0, chassis, 0.0).unwrap();
            assert!((t.yaw_motor_deg - expect).abs() < 1e-4, "{t:?}");
        }
    }

    #[test]
    fn yaw_goes_the_short_way_from_a_multi_turn_position() {
        // Motor at 350° (relative), wants relative 10°: +20° → 370°, not −340°.
        let t = SLIP_RING.targets(10.0, 0.0, 0.0, 350.0).unwrap();
        assert!((t.yaw_motor_deg - 370.0).abs() < 1e-3);
        let t = SLIP_RING.targets(-10.0, 0.0, 0.0, -720.0).unwrap();
        assert!((t.yaw_motor_deg + 730.0).abs() < 1e-3);
    }

    #[test]
    fn limited_yaw_and_pitch_are_clamped() {
        let g = GimbalLimits {
            yaw_range_deg: Some((-90.0, 90.0)),
            ..SLIP_RING
        };
        let t = g.targets(170.0, -45.0, 0.0, 0.0).unwrap();
        assert_eq!(t.yaw_motor_deg, 90.0);
        assert_eq!(t.pitch_deg, -20.0);
    }

    #[test]
    fn non_finite_input_gives_none() {
        assert!(SLIP_RING.targets(f32::NAN, 0.0, 0.0, 0.0).is_none());
        assert!(SLIP_RING.targets(0.0, 0.0, f32::INFINITY, 0.0).is_none());
    }
}
