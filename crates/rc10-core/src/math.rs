//! Small numeric helpers every robot needs: clamping with defined NaN behaviour, degree/radian
//! conversion, angle wrapping and the RC10 `ramp` step.
//!
//! Everything here is total: no input (NaN, ±inf, reversed bounds) panics, and every function
//! documents what it returns for such input.

use core::f32::consts::{PI, TAU};

/// Clamps `value` into `[min, max]` (RC10_LIB `constrain`).
///
/// Defined for every input, unlike [`f32::clamp`] which panics on reversed or NaN bounds:
/// - a NaN `value` returns `0.0` clamped into the bounds (the "do nothing" command for a motor);
/// - a NaN bound is ignored (that side is unbounded);
/// - reversed bounds (`min > max`) are swapped.
///
/// ```
/// use rc10_core::math::constrain;
/// assert_eq!(constrain(25.0, -20.0, 20.0), 20.0);
/// assert_eq!(constrain(f32::NAN, -20.0, 20.0), 0.0);
/// assert_eq!(constrain(f32::NAN, 1.0, 2.0), 1.0);
/// assert_eq!(constrain(5.0, 10.0, -10.0), 5.0);
/// ```
#[inline]
pub fn constrain(value: f32, min: f32, max: f32) -> f32 {
    let (lo, hi) = if min > max { (max, min) } else { (min, max) };
    let mut v = if value.is_nan() { 0.0 } else { value };
    // Plain comparisons, not `f32::max`/`min`: those are library calls (`fmaxf`/`fminf`) on
    // the Cortex-M4, whose FPU has no VMAXNM. A comparison with a NaN bound is false, so a
    // NaN bound leaves that side open.
    if v < lo {
        v = lo;
    }
    if v > hi {
        v = hi;
    }
    v
}

/// Clamps `value` into `[-limit, limit]` and always returns a finite number.
///
/// `limit` is taken by magnitude; an infinite limit means "no limit" (the result is still
/// kept within `±f32::MAX`), and a NaN limit holds the value at 0: a limit computed from bad
/// numbers (a derating, a power budget) stops the output rather than freeing it, as the PID's
/// limit in force and [`crate::chassis::clamp_twist`] read one. A NaN `value` returns `0.0`.
///
/// ```
/// use rc10_core::math::saturate;
/// assert_eq!(saturate(-30.0, 20.0), -20.0);
/// assert_eq!(saturate(f32::INFINITY, f32::INFINITY), f32::MAX);
/// assert_eq!(saturate(f32::NAN, 1.0), 0.0);
/// assert_eq!(saturate(15.0, f32::NAN), 0.0);
/// ```
#[inline]
pub fn saturate(value: f32, limit: f32) -> f32 {
    let lim = if limit.is_finite() {
        limit.abs()
    } else if limit.is_nan() {
        0.0
    } else {
        f32::MAX
    };
    constrain(value, -lim, lim)
}

/// `value` if finite; `±f32::MAX` for `±inf`; `0.0` for NaN. The same as
/// `saturate(value, f32::INFINITY)`, in a few instructions.
///
/// ```
/// use rc10_core::math::finite;
/// assert_eq!(finite(1.5), 1.5);
/// assert_eq!(finite(f32::NEG_INFINITY), -f32::MAX);
/// assert_eq!(finite(f32::NAN), 0.0);
/// ```
#[inline]
pub fn finite(value: f32) -> f32 {
    if value.is_finite() {
        value
    } else if value.is_nan() {
        0.0
    } else if value > 0.0 {
        f32::MAX
    } else {
        -f32::MAX
    }
}

/// Converts degrees to radians.
#[inline]
pub const fn deg_to_rad(angle_deg: f32) -> f32 {
    angle_deg * (PI / 180.0)
}

/// Converts radians to degrees.
#[inline]
pub const fn rad_to_deg(angle_rad: f32) -> f32 {
    angle_rad * (180.0 / PI)
}

/// Wraps `value` into `[0, period)`.
///
/// Returns `0.0` for a non-finite `value` or a non-finite or non-positive `period`.
///
/// ```
/// use rc10_core::math::wrap_positive;
/// assert_eq!(wrap_positive(370.0, 360.0), 10.0);
/// assert_eq!(wrap_positive(-10.0, 360.0), 350.0);
/// ```
#[inline]
pub fn wrap_positive(value: f32, period: f32) -> f32 {
    if !value.is_finite() || !period.is_finite() || period <= 0.0 {
        return 0.0;
    }
    wrap_positive_valid_period(value, period)
}

/// [`wrap_positive`] for a finite `value` and a `period` known to be finite and positive.
#[inline]
fn wrap_positive_valid_period(value: f32, period: f32) -> f32 {
    let r = value - period * floor(value / period);
    // Rounding can land exactly on `period` for tiny negative inputs (e.g. -1e-9); a
    // negative zero (from -0.0) comes out as +0.0, which prints as 0.
    if r > 0.0 && r < period { r } else { 0.0 }
}

/// [`wrap_signed`] for a `period` already checked to be finite and positive (a validated
/// configuration): the same result, without checking the period again on every call.
#[inline]
pub(crate) fn wrap_signed_valid_period(value: f32, period: f32) -> f32 {
    let half = period * 0.5;
    // Already in range: the value itself, exactly (`+ 0.0` turns −0 into +0). Shifted by
    // half a period and back it would come out rounded to the spacing of floats near the
    // half period (1.5e-5° near 180°: an error of 1e-6° would read 0), and a value just
    // below the half period could round up to it and come out as −half.
    if value >= -half && value < half {
        return value + 0.0;
    }
    let shifted = value + half;
    if !shifted.is_finite() {
        return 0.0 - half;
    }
    wrap_positive_valid_period(shifted, period) - half
}

/// `floor(x)`, exactly as `libm::floorf`, without its library call on the Cortex-M4 for the
/// values that have a fraction (`|x| < 2²³`, where the truncating conversion is exact); every
/// float of larger magnitude is an integer already (and NaN and ±inf pass through).
#[inline]
pub(crate) fn floor(x: f32) -> f32 {
    if x.abs() < 8_388_608.0 {
        let truncated = x as i32 as f32;
        if truncated > x {
            truncated - 1.0
        } else {
            truncated
        }
    } else {
        x
    }
}

/// `roundf(x) as i32` (half away from zero; saturating at the `i32` range; NaN to 0) without
/// the library call `roundf` is on the Cortex-M4.
///
/// Adds the float just below one half, away from zero, and truncates. Adding 0.5 itself
/// would round 0.49999997 up (the sum rounds to 1.0); with 0.49999997 the sum truncates to
/// `roundf(x)` for every float: below 2²³ the sum is within half a spacing of `x + 0.5`, and
/// from 2²³ on (a spacing of 1 or more) it rounds back to `x`, a whole number. Checked for
/// all 2³² bit patterns against `libm::roundf` (an ignored test), and tested here on the
/// edges and on a sample.
#[inline]
pub(crate) fn round_i32(x: f32) -> i32 {
    const HALF_BELOW: f32 = 0.499_999_97;
    let half = if x < 0.0 { -HALF_BELOW } else { HALF_BELOW };
    (x + half) as i32 // towards zero, saturating; NaN becomes 0
}

/// Test values for rounding by hand: alternately a float of any magnitude (random bits, so
/// NaN and ±inf too) and an exact half `k/2` within `±span` — 200,000 in all, the same
/// every run.
#[cfg(test)]
pub(crate) fn rounding_samples(seed: u32, span: u32) -> impl Iterator<Item = f32> {
    let mut bits = seed;
    (0..200_000u32).map(move |k| {
        bits ^= bits << 13;
        bits ^= bits >> 17;
        bits ^= bits << 5;
        if k % 2 == 0 {
            f32::from_bits(bits)
        } else {
            (bits % (4 * span)) as f32 * 0.5 - span as f32
        }
    })
}

/// Wraps `value` into `[-period/2, period/2)`: the signed shortest offset on a circle. A
/// value already in that range comes back exactly (`−0.0` as `+0.0`).
///
/// Returns `0.0` for a non-finite `value` or a non-finite or non-positive `period`.
///
/// ```
/// use rc10_core::math::wrap_signed;
/// assert_eq!(wrap_signed(350.0, 360.0), -10.0);
/// assert_eq!(wrap_signed(180.0, 360.0), -180.0);
/// ```
#[inline]
pub fn wrap_signed(value: f32, period: f32) -> f32 {
    if !value.is_finite() || !period.is_finite() || period <= 0.0 {
        return 0.0;
    }
    wrap_signed_valid_period(value, period)
}

/// Wraps an angle into `[0, 360)` degrees.
#[inline]
pub fn wrap_deg_360(angle_deg: f32) -> f32 {
    wrap_positive(angle_deg, 360.0)
}

/// Wraps an angle into `[-180, 180)` degrees.
#[inline]
pub fn wrap_deg_180(angle_deg: f32) -> f32 {
    wrap_signed(angle_deg, 360.0)
}

/// Wraps an angle into `[-π, π)` radians.
#[inline]
pub fn wrap_rad_pi(angle_rad: f32) -> f32 {
    wrap_signed(angle_rad, TAU)
}

/// The shortest signed rotation from `from_deg` to `to_deg`, in `[-180, 180)` degrees.
///
/// Works for any mix of conventions (`[0, 360)`, `±180`, multi-turn): only the difference
/// modulo 360° matters.
///
/// ```
/// use rc10_core::math::angle_diff_deg;
/// assert_eq!(angle_diff_deg(350.0, 10.0), 20.0);   // across 0, not -340
/// assert_eq!(angle_diff_deg(170.0, -170.0), 20.0); // across ±180
/// ```
#[inline]
pub fn angle_diff_deg(from_deg: f32, to_deg: f32) -> f32 {
    wrap_deg_180(to_deg - from_deg)
}

/// Moves `current` towards `target` by at most `max_step`.
///
/// RC10_LIB's `ramp(target, current, rate, dt)` takes the target first and a rate per
/// second: porting a call as it stands compiles (all `f32`) and ramps the wrong value. Here
/// the value that moves comes first and the limit is a step per call (`rate · dt`);
/// [`crate::filter::Ramp`] keeps the value and takes a rate in units per second.
///
/// `max_step` is taken by magnitude. Within one step of `target` the result is `target`
/// exactly (never a rounding short of or past it). A NaN `target` leaves `current`
/// unchanged; a NaN or infinite `current` jumps to `target` (there is nothing to ramp from:
/// an infinite one would stay infinite, as `∞ − step = ∞`).
///
/// ```
/// use rc10_core::math::ramp;
/// assert_eq!(ramp(0.0, 10.0, 3.0), 3.0);
/// assert_eq!(ramp(9.0, 10.0, 3.0), 10.0);
/// assert_eq!(ramp(0.0, -10.0, 3.0), -3.0);
/// ```
#[inline]
pub fn ramp(current: f32, target: f32, max_step: f32) -> f32 {
    if target.is_nan() {
        return current;
    }
    if !current.is_finite() {
        return target;
    }
    let step = if max_step.is_nan() {
        0.0
    } else {
        max_step.abs()
    };
    let delta = target - current;
    // Within one step: the target itself (`current + delta` can round past it when the two
    // differ in magnitude or sign). A NaN `delta` (both the same infinity) is "there".
    if delta.abs() <= step || delta.is_nan() {
        return target;
    }
    // One step towards it. Rounding is monotonic: `step` is below the rounded gap, so below
    // the exact one, and `current ± step` rounds to at most `target`: never past it.
    if delta > 0.0 {
        current + step
    } else {
        current - step
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn round_i32_rounds_half_away_from_zero_and_saturates_like_roundf() {
        // Ties away from zero; the float just below 0.5 rounds down (`x + 0.5` would give
        // 1.0 there); 2^23 - 0.5 is the last tie; from 2^23 on floats are whole; beyond the
        // i32 range the conversion saturates; NaN gives 0.
        let cases = [
            (0.5, 1),
            (-0.5, -1),
            (2.5, 3),
            (-2.5, -3),
            (0.499_999_97, 0),
            (-0.499_999_97, 0),
            (1.499_999_9, 1),
            (-0.0, 0),
            (2_097_152.0 - 0.25, 2_097_152), // exact: 2^21 - 1/4
            (2_097_152.0 + 0.25, 2_097_152), // exact: 2^21 + 1/4
            (8_388_607.0, 8_388_607),
            (8_388_607.5, 8_388_608),
            (-8_388_607.5, -8_388_608),
            (8_388_609.0, 8_388_609),
            (2.0e9, 2_000_000_000),
            (3.0e9, i32::MAX),
            (-3.0e9, i32::MIN),
            (f32::INFINITY, i32::MAX),
            (f32::NEG_INFINITY, i32::MIN),
            (f32::NAN, 0),
        ];
        for (x, want) in cases {
            assert_eq!(round_i32(x), want, "{x}");
        }
        // And libm's `roundf` agrees on floats of every magnitude and on many exact halves.
        for x in rounding_samples(0x9E37_79B9, 10_000_000) {
            assert_eq!(round_i32(x), libm::roundf(x) as i32, "{x}");
        }
    }

    /// The claim in [`round_i32`]'s docs, for every float: about 15 s in release
    /// (`cargo test -p rc10-core --release --lib -- --ignored every_float`).
    #[test]
    #[ignore = "2^32 floats: run in release on demand"]
    fn round_i32_equals_roundf_for_every_float() {
        for bits in 0..=u32::MAX {
            let x = f32::from_bits(bits);
            assert_eq!(round_i32(x), libm::roundf(x) as i32, "{x}");
        }
    }

    #[test]
    fn constrain_inside_range_returns_value() {
        assert_eq!(constrain(1.5, -2.0, 2.0), 1.5);
    }

    #[test]
    fn constrain_infinite_value_clamps_to_bound() {
        assert_eq!(constrain(f32::INFINITY, -2.0, 2.0), 2.0);
        assert_eq!(constrain(f32::NEG_INFINITY, -2.0, 2.0), -2.0);
    }

    #[test]
    fn constrain_nan_bound_is_open() {
        assert_eq!(constrain(100.0, f32::NAN, 2.0), 2.0);
        assert_eq!(constrain(-100.0, f32::NAN, 2.0), -100.0);
    }

    #[test]
    fn constrain_nan_value_with_range_excluding_zero_returns_nearest_bound() {
        assert_eq!(constrain(f32::NAN, -5.0, -1.0), -1.0);
    }

    #[test]
    fn wrap_deg_360_examples_match_hand_values() {
        assert_eq!(wrap_deg_360(720.0), 0.0);
        assert_eq!(wrap_deg_360(-90.0), 270.0);
        assert_eq!(wrap_deg_360(359.5), 359.5);
        // Tiny negative: mathematically 360 - 1e-9, not representable: must not return 360.
        let w = wrap_deg_360(-1e-9);
        assert!((0.0..360.0).contains(&w));
        // -0° is 0°, not a negative zero (which telemetry would print as "-0.00").
        assert!(wrap_deg_360(-0.0).is_sign_positive());
        assert!(wrap_positive(-720.0, 360.0).is_sign_positive());
    }

    #[test]
    fn saturate_holds_the_value_at_zero_under_a_nan_limit() {
        assert_eq!(saturate(15.0, f32::NAN), 0.0);
        assert_eq!(saturate(-15.0, f32::NAN), 0.0);
        // An infinite limit is no limit; a negative one is taken by magnitude.
        assert_eq!(saturate(15.0, f32::INFINITY), 15.0);
        assert_eq!(saturate(15.0, -10.0), 10.0);
    }

    #[test]
    fn wrap_signed_returns_values_in_range_exactly() {
        // Shifted by 180° and back, 1e-6° came out 0 (floats near 180 are 1.5e-5 apart).
        assert_eq!(wrap_deg_180(1e-6), 1e-6);
        assert_eq!(wrap_deg_180(-1e-6), -1e-6);
        assert_eq!(wrap_rad_pi(1e-9), 1e-9);
        // Just below 180: itself, not rounded up to 180 and wrapped to −180.
        let below = 180.0f32.next_down();
        assert_eq!(wrap_deg_180(below), below);
        assert_eq!(wrap_deg_180(-180.0), -180.0);
        assert_eq!(wrap_deg_180(180.0), -180.0);
        assert!(wrap_deg_180(-0.0).is_sign_positive());
        // Out of range, exact where the arithmetic is: 190 − 360, −190 + 360.
        assert_eq!(wrap_deg_180(190.0), -170.0);
        assert_eq!(wrap_deg_180(-190.0), 170.0);
    }

    #[test]
    fn wrap_rad_pi_maps_three_half_pi_to_minus_half_pi() {
        assert!((wrap_rad_pi(1.5 * PI) + 0.5 * PI).abs() < 1e-6);
    }

    #[test]
    fn wrap_non_finite_returns_zero() {
        assert_eq!(wrap_deg_360(f32::NAN), 0.0);
        assert_eq!(wrap_deg_180(f32::INFINITY), 0.0);
        assert_eq!(wrap_positive(1.0, 0.0), 0.0);
    }

    #[test]
    fn angle_diff_takes_short_way_in_both_conventions() {
        assert_eq!(angle_diff_deg(10.0, 350.0), -20.0);
        assert_eq!(angle_diff_deg(-170.0, 170.0), -20.0);
        assert_eq!(angle_diff_deg(0.0, 90.0), 90.0);
    }

    #[test]
    fn deg_rad_round_trip() {
        assert!((deg_to_rad(180.0) - PI).abs() < 1e-6);
        assert!((rad_to_deg(PI / 2.0) - 90.0).abs() < 1e-4);
    }

    #[test]
    fn ramp_nan_target_holds_current() {
        assert_eq!(ramp(4.0, f32::NAN, 1.0), 4.0);
        assert_eq!(ramp(f32::NAN, 7.0, 1.0), 7.0);
    }

    #[test]
    fn ramp_from_an_infinite_current_jumps_to_the_target() {
        // ∞ − 1 is ∞: stepping would never leave it.
        assert_eq!(ramp(f32::INFINITY, 0.0, 1.0), 0.0);
        assert_eq!(ramp(f32::NEG_INFINITY, -3.0, 1.0), -3.0);
    }

    #[test]
    fn ramp_lands_exactly_on_a_target_within_one_step() {
        // In f32, 1e8 + (1.0 − 1e8) is 0.0 (1.0 − 1e8 rounds to −1e8), and 0.7 + (−0.001 − 0.7)
        // is not −0.001: the last step must give the target itself.
        assert_eq!(ramp(1e8, 1.0, f32::INFINITY), 1.0);
        assert_eq!(ramp(0.7, -0.001, f32::INFINITY), -0.001);
        assert_eq!(ramp(0.7, -0.001, 1.0), -0.001);
        // Both at the same infinity: already there.
        assert_eq!(
            ramp(f32::INFINITY, f32::INFINITY, f32::INFINITY),
            f32::INFINITY
        );
        // A step short of it stays short, on either side.
        assert_eq!(ramp(1e8, 1.0, 5e7), 5e7);
        assert_eq!(ramp(-2.0, 2.0, 1.5), -0.5);
    }

    proptest! {
        #[test]
        fn ramp_never_passes_the_target_and_lands_on_it_within_a_step(
            current in -1.0e9f32..1.0e9, target in -1.0e9f32..1.0e9, step in 0.0f32..1.0e9,
        ) {
            let next = ramp(current, target, step);
            let (lo, hi) = if current <= target { (current, target) } else { (target, current) };
            prop_assert!(lo <= next && next <= hi, "{current} -> {target} by {step}: {next}");
            // Exactly the target once within a step (compared in f64, exact for f32 values).
            if (f64::from(target) - f64::from(current)).abs() <= f64::from(step) {
                prop_assert_eq!(next, target);
            }
        }

        #[test]
        fn wrap_signed_stays_in_half_open_range(v in -1.0e6f32..1.0e6) {
            let w = wrap_deg_180(v);
            prop_assert!((-180.0..180.0).contains(&w), "{v} -> {w}");
        }

        #[test]
        fn angle_diff_is_equivalent_mod_360(a in -720.0f32..720.0, b in -720.0f32..720.0) {
            let d = angle_diff_deg(a, b);
            // a + d must point where b points.
            let miss = wrap_deg_180(a + d - b).abs();
            prop_assert!(miss < 1e-3, "a={a} b={b} d={d}");
        }

        #[test]
        fn constrain_never_escapes_bounds(v in proptest::num::f32::ANY, lo in -1e3f32..1e3, hi in -1e3f32..1e3) {
            let c = constrain(v, lo, hi);
            prop_assert!(c >= lo.min(hi) && c <= lo.max(hi));
        }
    }
}
