//! A yaw/pitch gimbal on a turning chassis: where the yaw and pitch motors must go so the
//! gimbal points at a world heading, the short way round, within mechanical limits.

use crate::math::{constrain, floor, wrap_deg_180, wrap_deg_360};

/// Mechanical limits of a gimbal, degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GimbalLimits {
    /// Lowest pitch, degrees (negative is down: the opposite of [`geometry`](crate::geometry)'s
    /// ZYX pitch about a y axis pointing left, which is positive nose-down; negate a
    /// `Pose3D::pitch_rad` before using it here). Reversed pitch bounds are swapped; a NaN or
    /// infinite bound leaves that side open, as for the yaw range (check a computed limit).
    pub pitch_min_deg: f32,
    /// Highest pitch, degrees.
    pub pitch_max_deg: f32,
    /// Yaw range relative to the chassis, degrees (the yaw motor's multi-turn angle, `(lowest,
    /// highest)`), for gimbals whose cables do not allow endless rotation; `None` for a slip
    /// ring (any angle, shortest way). It may be wider than a turn (for example `(-270.0,
    /// 270.0)`) and need not be centred on 0; reversed bounds are swapped, and a NaN or
    /// infinite bound leaves that side open.
    ///
    /// The yaw motor's multi-turn angle must start within the range: rc10 cannot tell a
    /// reading a turn off from the real position. A GM6020 with an absolute origin first
    /// reads within ±180° of its zero, so put the zero in the middle of the range; a range
    /// wider than ±180° around it needs the gimbal homed (or powered on near its zero). After
    /// an outage the count continues from before it (`MultiTurnOnReturn::Continue`, right
    /// when the gimbal moved less than half a turn while off); a range within ±180° of the
    /// zero may use `Restart`, which reads the absolute angle again.
    pub yaw_range_deg: Option<(f32, f32)>,
}

/// Where to send the gimbal motors.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GimbalTarget {
    /// Multi-turn target for the yaw motor relative to the chassis, degrees (use
    /// `set_target_total_angle_deg`): of the angles that point the gimbal at the target (and
    /// lie within the yaw range, if it has one), the nearest to where the motor is now. With a
    /// yaw range that cannot reach the target heading, the nearer end of the range.
    pub yaw_motor_deg: f32,
    /// The heading to point at relative to the chassis, degrees in [−180, 180) (not limited
    /// by a yaw range). For a slip-ring yaw, `set_target_angle_deg(wrap_deg_360(..))` of it
    /// in single-turn angle mode stays exact however long the chassis spins: the angle
    /// loop's circular error takes the short way. `yaw_motor_deg` is a multi-turn f32, whose
    /// resolution falls as the turns add up (steps of 1/64° past 131 072°, four minutes of
    /// spinning at 1.5 rev/s; 1/8° past 1 048 576°, half an hour).
    pub yaw_relative_deg: f32,
    /// Pitch target within the limits, degrees.
    pub pitch_deg: f32,
}

impl GimbalLimits {
    /// Targets for pointing at `yaw_world_deg` / `pitch_deg` while the chassis faces
    /// `chassis_yaw_deg`, with the yaw motor now at `yaw_motor_now_deg` (its multi-turn angle
    /// relative to the chassis). `None` if any input is NaN or infinite: keep the old targets.
    ///
    /// Angles are counter-clockwise positive seen from above, for the chassis yaw and the yaw
    /// motor alike (mount or configure the yaw motor so that a positive angle turns the gimbal
    /// left).
    ///
    /// ```
    /// use rc10_core::gimbal::GimbalLimits;
    /// let g = GimbalLimits { pitch_min_deg: -20.0, pitch_max_deg: 30.0, yaw_range_deg: None };
    /// // Look at world −170° with the chassis at 170°: 20° relative to the chassis. The yaw
    /// // motor is at 700° (multi-turn, ≡ −20°), so it turns +40° to 740°, not back 680°.
    /// let t = g.targets(-170.0, 45.0, 170.0, 700.0).unwrap();
    /// assert!((t.yaw_motor_deg - 740.0).abs() < 1e-3);
    /// assert!((t.yaw_relative_deg - 20.0).abs() < 1e-3);
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
        // The angle that points there nearest to the motor's (a slip ring's answer).
        let nearest = yaw_motor_now_deg + wrap_deg_180(relative - yaw_motor_now_deg);
        let yaw_motor_deg = match self.yaw_range_deg {
            None => nearest,
            Some((lo, hi)) => within_yaw_range(nearest, lo, hi),
        };
        Some(GimbalTarget {
            yaw_motor_deg,
            yaw_relative_deg: relative,
            pitch_deg: constrain(pitch_deg, self.pitch_min_deg, self.pitch_max_deg),
        })
    }
}

/// For a cable-limited yaw: of the angles `nearest + k·360` (all of which point the same
/// way), the one within `[lo, hi]` nearest to `nearest` (so the motor, already within the
/// range, never turns through a stop); if the range holds none of them, the end of the range
/// nearer to the target heading (round the circle).
fn within_yaw_range(nearest: f32, lo: f32, hi: f32) -> f32 {
    let open = |bound: f32, side: f32| if bound.is_finite() { bound } else { side };
    let (lo, hi) = (open(lo, f32::NEG_INFINITY), open(hi, f32::INFINITY));
    let (lo, hi) = if lo > hi { (hi, lo) } else { (lo, hi) };
    let candidate = if nearest < lo {
        // The lowest such angle at or above the bottom: `nearest + 360·⌈(lo − nearest)/360⌉`.
        nearest - 360.0 * floor((nearest - lo) / 360.0)
    } else if nearest > hi {
        // The highest such angle at or below the top.
        nearest + 360.0 * floor((hi - nearest) / 360.0)
    } else {
        return nearest;
    };
    if lo <= candidate && candidate <= hi {
        candidate
    } else if wrap_deg_360(nearest - hi) <= wrap_deg_360(lo - nearest) {
        // The heading lies in the gap between `hi` and `lo + 360`: the nearer stop.
        hi
    } else {
        lo
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
    fn the_relative_heading_stays_exact_after_an_hour_of_spinning() {
        // An hour at 1.5 rev/s: the yaw motor's multi-turn angle is near 1.94e6°, where an
        // f32 steps by 1/8°. World target 33.3°, chassis at 10°: 23.3° relative, exactly, and
        // the single-turn angle mode's target is that, whatever the multi-turn angle.
        let t = SLIP_RING.targets(33.3, 0.0, 10.0, 1_944_000.0).unwrap();
        assert!((t.yaw_relative_deg - 23.3).abs() < 1e-4, "{t:?}");
        // A chassis heading past ±180° wraps: world −170°, chassis 170° → 20°.
        let t = SLIP_RING.targets(-170.0, 0.0, 170.0, 0.0).unwrap();
        assert!((t.yaw_relative_deg - 20.0).abs() < 1e-4, "{t:?}");
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

    fn limited(lo: f32, hi: f32) -> GimbalLimits {
        GimbalLimits {
            yaw_range_deg: Some((lo, hi)),
            ..SLIP_RING
        }
    }

    #[test]
    fn a_range_wider_than_a_turn_takes_the_nearest_turn_inside_it() {
        // Range ±270°, motor at 170°, target 190° left of the chassis (≡ −170°): 190° is 20°
        // away and inside the range; −170° would swing 340° the other way.
        let t = limited(-270.0, 270.0)
            .targets(-170.0, 0.0, 0.0, 170.0)
            .unwrap();
        assert!((t.yaw_motor_deg - 190.0).abs() < 1e-3, "{t:?}");
        // The same heading from −170°: −170° itself, 0° away.
        let t = limited(-270.0, 270.0)
            .targets(-170.0, 0.0, 0.0, -170.0)
            .unwrap();
        assert!((t.yaw_motor_deg + 170.0).abs() < 1e-3, "{t:?}");
        // From 0°, 190° and −170° are both inside: −170° is nearer (170° against 190°).
        let t = limited(-270.0, 270.0)
            .targets(190.0, 0.0, 0.0, 0.0)
            .unwrap();
        assert!((t.yaw_motor_deg + 170.0).abs() < 1e-3, "{t:?}");
    }

    #[test]
    fn a_range_not_centred_on_zero_reaches_headings_behind_its_zero() {
        // Range 0..350°: −10° is reached as 350°, not held at the 0° stop.
        let t = limited(0.0, 350.0).targets(-10.0, 0.0, 0.0, 0.0).unwrap();
        assert!((t.yaw_motor_deg - 350.0).abs() < 1e-3, "{t:?}");
        // Reversed bounds mean the same range.
        let t = limited(350.0, 0.0).targets(-10.0, 0.0, 0.0, 0.0).unwrap();
        assert!((t.yaw_motor_deg - 350.0).abs() < 1e-3, "{t:?}");
    }

    #[test]
    fn the_turn_inside_the_range_is_found_from_beyond_either_end() {
        // Range ±270°. Motor at −265°, heading 80°: the nearest turn is −280° (15° away, but
        // past the −270° stop), so the gimbal goes the long way inside the range to 80°.
        let t = limited(-270.0, 270.0)
            .targets(80.0, 0.0, 0.0, -265.0)
            .unwrap();
        assert!((t.yaw_motor_deg - 80.0).abs() < 1e-3, "{t:?}");
        // Mirrored: motor at 265°, heading −80°: 280° is past the stop, −80° is inside.
        let t = limited(-270.0, 270.0)
            .targets(-80.0, 0.0, 0.0, 265.0)
            .unwrap();
        assert!((t.yaw_motor_deg + 80.0).abs() < 1e-3, "{t:?}");
        // Reversed bounds are the same range.
        let t = limited(270.0, -270.0)
            .targets(80.0, 0.0, 0.0, -265.0)
            .unwrap();
        assert!((t.yaw_motor_deg - 80.0).abs() < 1e-3, "{t:?}");
        // Two turns away: range 720..1000°, motor at 730°, heading 0° is reached at 720°.
        let t = limited(720.0, 1000.0)
            .targets(0.0, 0.0, 0.0, 730.0)
            .unwrap();
        assert!((t.yaw_motor_deg - 720.0).abs() < 1e-3, "{t:?}");
        let t = limited(720.0, 1000.0)
            .targets(10.0, 0.0, 0.0, 2000.0)
            .unwrap();
        assert!((t.yaw_motor_deg - 730.0).abs() < 1e-3, "{t:?}");
        // From a reading two turns below it (not a valid start, but the target still lies
        // within the range): heading 100° from 0° is reached at 100 + 2·360 = 820°.
        let t = limited(720.0, 1000.0)
            .targets(100.0, 0.0, 0.0, 0.0)
            .unwrap();
        assert!((t.yaw_motor_deg - 820.0).abs() < 1e-3, "{t:?}");
    }

    #[test]
    fn infinite_bounds_are_open_sides_even_on_the_same_side() {
        // (+inf, NaN): both sides open, a slip ring: from 350°, 10° is reached at 370°.
        for (lo, hi) in [
            (f32::INFINITY, f32::NAN),
            (f32::INFINITY, f32::INFINITY),
            (f32::NEG_INFINITY, f32::NEG_INFINITY),
        ] {
            let t = limited(lo, hi).targets(10.0, 0.0, 0.0, 350.0).unwrap();
            assert!(
                (t.yaw_motor_deg - 370.0).abs() < 1e-3,
                "({lo}, {hi}): {t:?}"
            );
        }
    }

    #[test]
    fn an_unreachable_heading_goes_to_the_nearer_stop_round_the_circle() {
        // Range −170..0°, target 150°: past the 0° stop by 150°, past the −170° stop (≡ 190°)
        // by 40° round the other way: the gimbal waits at −170°.
        let t = limited(-170.0, 0.0)
            .targets(150.0, 0.0, 0.0, -10.0)
            .unwrap();
        assert_eq!(t.yaw_motor_deg, -170.0);
        // Target 20°: 20° past the 0° stop, 170° short of the other: 0°.
        let t = limited(-170.0, 0.0)
            .targets(20.0, 0.0, 0.0, -100.0)
            .unwrap();
        assert_eq!(t.yaw_motor_deg, 0.0);
    }

    #[test]
    fn an_open_side_of_the_range_allows_any_angle_on_that_side() {
        // Top open: from 300°, heading 10° is 370° (70° away, above the 0° bottom).
        let t = limited(0.0, f32::NAN)
            .targets(10.0, 0.0, 0.0, 300.0)
            .unwrap();
        assert!((t.yaw_motor_deg - 370.0).abs() < 1e-3, "{t:?}");
        // Bottom open: from 10°, heading −100° with the top at 0°: −100° itself.
        let t = limited(f32::NAN, 0.0)
            .targets(-100.0, 0.0, 0.0, 10.0)
            .unwrap();
        assert!((t.yaw_motor_deg + 100.0).abs() < 1e-3, "{t:?}");
    }

    #[test]
    fn non_finite_input_gives_none() {
        assert!(SLIP_RING.targets(f32::NAN, 0.0, 0.0, 0.0).is_none());
        assert!(SLIP_RING.targets(0.0, 0.0, f32::INFINITY, 0.0).is_none());
    }
}
