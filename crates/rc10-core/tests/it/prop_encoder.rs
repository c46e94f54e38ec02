//! Property tests of the non-periodic multi-turn unwrapping in `rc10_core::encoder`
//! (`Encoder::update`, the half-turn rule, and `Encoder::update_predicted`), beyond the unit
//! property in `encoder.rs` (DJI counts, M3508 gear, power-on origin, up to 2000 steps):
//!
//! - any encoder resolution (2…65535 counts, odd ones included), any exact gear ratio, a
//!   power-on or absolute origin: for any motion whose steps stay below half a turn (the
//!   documented bound) the multi-turn count is exact, the last raw count is kept, and every
//!   angle read out (rotor angle, output single-turn angle in [0, 360), whole output turns,
//!   multi-turn output angle) equals the exact rational value worked out here in i128;
//! - the same far from the origin (homed to ±10¹⁵ counts) and over a run longer than 2³¹
//!   counts at top speed: no 32-bit overflow, no float drift in the single-turn angle;
//! - `update_predicted`: steps of many turns are exact whenever the prediction is within half
//!   a turn of the truth; a non-finite prediction falls back to the half-turn rule;
//! - a raw count at or above the resolution is rejected and changes nothing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use proptest::prelude::*;
use proptest::test_runner::Config;
use rc10_core::encoder::{Encoder, EncoderConfig, EncoderError, GearRatio, Origin};

/// `cases` cases (or `PROPTEST_CASES` if set, for a longer run); failures are not persisted
/// to files (a case worth keeping becomes a plain test).
fn config(cases: u32) -> Config {
    Config {
        cases: std::env::var("PROPTEST_CASES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(cases),
        failure_persistence: None,
        ..Config::default()
    }
}

#[derive(Debug, Clone, Copy)]
struct Setup {
    cpr: u16,
    rotor_turns: u32,
    output_turns: u32,
    origin: Origin,
    start: u16,
}

impl Setup {
    fn encoder(&self) -> Encoder {
        let gear = GearRatio::new(self.rotor_turns, self.output_turns).unwrap();
        Encoder::new(EncoderConfig {
            counts_per_rev: self.cpr,
            gear,
            origin: self.origin,
        })
        .unwrap()
    }

    /// The largest step below half a turn: (cpr − 1) / 2 counts.
    fn max_step(&self) -> i64 {
        (i64::from(self.cpr) - 1) / 2
    }

    /// The count of the first reading: 0 at power-on; for an absolute encoder, the reading
    /// placed within half a turn of the zero offset (an angle in [−180°, 180°)).
    fn first_count(&self) -> i64 {
        match self.origin {
            Origin::PowerOn => 0,
            Origin::Absolute { zero_offset_counts } => {
                let n = i64::from(self.cpr);
                let c = (i64::from(self.start) - i64::from(zero_offset_counts)).rem_euclid(n);
                if 2 * c >= n { c - n } else { c }
            }
        }
    }

    /// The raw reading at multi-turn count `total`.
    fn raw_at(&self, total: i64) -> u16 {
        (total - self.first_count() + i64::from(self.start)).rem_euclid(i64::from(self.cpr)) as u16
    }
}

fn setup() -> impl Strategy<Value = Setup> {
    (
        prop_oneof![2 => Just(8192u16), 1 => 2u16..=u16::MAX],
        prop_oneof![
            1 => Just((3591u32, 187u32)), // M3508
            1 => Just((36, 1)),           // M2006
            1 => Just((1, 1)),            // direct drive
            2 => (1u32..=100_000, 1u32..=10_000),
        ],
        any::<bool>(),
        any::<u16>(),
        any::<u16>(),
    )
        .prop_map(
            |(cpr, (rotor_turns, output_turns), absolute, offset, start)| Setup {
                cpr,
                rotor_turns,
                output_turns,
                origin: if absolute {
                    Origin::Absolute {
                        zero_offset_counts: offset % cpr,
                    }
                } else {
                    Origin::PowerOn
                },
                start: start % cpr,
            },
        )
}

/// Steps below half a turn for `s`, as fractions in (−1, 1) of the largest one (so the
/// strategy does not depend on the resolution drawn).
fn steps(len: std::ops::Range<usize>) -> impl Strategy<Value = Vec<f64>> {
    proptest::collection::vec(
        prop_oneof![
            6 => -1.0f64..=1.0,
            1 => prop_oneof![Just(1.0f64), Just(-1.0), Just(0.0)],
        ],
        len,
    )
}

fn scaled(s: &Setup, fraction: f64) -> i64 {
    (fraction * s.max_step() as f64).round() as i64
}

/// Checks every read-out of `e` against the exact values for multi-turn count `total`.
fn check_readout(e: &Encoder, s: &Setup, total: i64) -> Result<(), TestCaseError> {
    prop_assert_eq!(e.total_counts(), total);
    prop_assert_eq!(e.raw(), Some(s.raw_at(total)));
    let n = i128::from(s.cpr);
    // Rotor angle: the count within one rotor turn.
    let rotor = (i128::from(total).rem_euclid(n)) as f64 * 360.0 / n as f64;
    let got = f64::from(e.rotor_angle_deg());
    prop_assert!((0.0..360.0).contains(&got), "rotor angle {got}");
    prop_assert!(
        circular_gap(got, rotor) <= 1e-4,
        "rotor angle {got}, want {rotor}"
    );
    // Output: total · output_turns / (cpr · rotor_turns) turns.
    let per_turn = n * i128::from(s.rotor_turns);
    let scaled = i128::from(total) * i128::from(s.output_turns);
    let turns = scaled.div_euclid(per_turn);
    let within = scaled.rem_euclid(per_turn) as f64 * 360.0 / per_turn as f64;
    prop_assert_eq!(i128::from(e.total_turns()), turns);
    let (angle, total_deg) = e.angles_deg();
    prop_assert_eq!(angle, e.angle_deg());
    prop_assert_eq!(total_deg, e.total_angle_deg());
    let angle = f64::from(angle);
    prop_assert!((0.0..360.0).contains(&angle), "angle {angle}");
    prop_assert!(
        circular_gap(angle, within) <= 1e-4,
        "angle {angle}, want {within}"
    );
    let want_total = turns as f64 * 360.0 + within;
    prop_assert!(
        (f64::from(total_deg) - want_total).abs() <= 1e-6 * want_total.abs() + 1e-4,
        "total angle {total_deg}, want {want_total}"
    );
    Ok(())
}

fn circular_gap(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    d.min(360.0 - d)
}

proptest! {
    #![proptest_config(config(256))]

    /// The half-turn rule: exact for every step below half a turn, any resolution, gear and
    /// origin, and every read-out exact.
    #[test]
    fn half_turn_rule_is_exact(s in setup(), fractions in steps(1..1000)) {
        let mut e = s.encoder();
        prop_assert!(!e.has_reading());
        e.update(s.start).unwrap();
        let mut total = s.first_count();
        check_readout(&e, &s, total)?;
        for f in fractions {
            total += scaled(&s, f);
            e.update(s.raw_at(total)).unwrap();
            check_readout(&e, &s, total)?;
        }
    }

    /// Far from the origin (homed to up to ±10¹⁵ counts: thousands of years at top speed):
    /// still exact, and the single-turn angle still exact to f32 rounding.
    #[test]
    fn exact_far_from_the_origin(
        s in setup(), target in -1.0e15f64..1.0e15, fractions in steps(1..200),
    ) {
        let mut e = s.encoder();
        e.update(s.start).unwrap();
        // Homing to the angle of `target` counts, rounded to the nearest count.
        let counts_per_deg = f64::from(s.cpr) * f64::from(s.rotor_turns) / (f64::from(s.output_turns) * 360.0);
        let angle = (target / counts_per_deg) as f32;
        prop_assume!((f64::from(angle) * counts_per_deg).abs() < 1.0e15);
        prop_assert!(e.set_total_angle_deg(angle));
        let homed = e.total_counts();
        let want = (f64::from(angle) * counts_per_deg).round();
        prop_assert!((homed as f64 - want).abs() <= 1.0, "homed to {homed}, want {want}");
        // Homing does not move the rotor: the raw reading is unchanged. Continue from there.
        let shift = homed - s.first_count();
        let raw_at = |total: i64| s.raw_at(total - shift);
        let mut total = homed;
        for f in fractions {
            total += scaled(&s, f);
            e.update(raw_at(total)).unwrap();
            prop_assert_eq!(e.total_counts(), total);
            prop_assert_eq!(e.raw(), Some(raw_at(total)));
            let n = i128::from(s.cpr) * i128::from(s.rotor_turns);
            let scaled_total = i128::from(total) * i128::from(s.output_turns);
            let within = scaled_total.rem_euclid(n) as f64 * 360.0 / n as f64;
            prop_assert_eq!(i128::from(e.total_turns()), scaled_total.div_euclid(n));
            let angle = f64::from(e.angle_deg());
            prop_assert!((0.0..360.0).contains(&angle));
            prop_assert!(circular_gap(angle, within) <= 1e-4, "angle {angle}, want {within}");
        }
    }

}

proptest! {
    // Fixed at 3 cases (1.8 million readings), whatever PROPTEST_CASES says.
    #![proptest_config(Config { cases: 3, failure_persistence: None, ..Config::default() })]

    /// A long run at top speed (about 4000 counts per reading, 600 000 readings: past 2³¹
    /// counts, where a 32-bit count wraps): exact to the end.
    #[test]
    fn exact_past_two_to_the_31_counts(seed: u64, forward: bool) {
        let s = Setup {
            cpr: 8192,
            rotor_turns: 3591,
            output_turns: 187,
            origin: Origin::PowerOn,
            start: (seed % 8192) as u16,
        };
        let mut e = s.encoder();
        e.update(s.start).unwrap();
        let sign = if forward { 1 } else { -1 };
        let mut rng = seed | 1;
        let mut total = 0i64;
        for k in 0..600_000u32 {
            // xorshift: steps of 3600…4095 counts, always below half a turn.
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            total += sign * (3600 + (rng % 496) as i64);
            e.update(s.raw_at(total)).unwrap();
            if k % 50_000 == 0 {
                prop_assert_eq!(e.total_counts(), total);
            }
        }
        prop_assert!(total.unsigned_abs() > 1 << 31);
        check_readout(&e, &s, total)?;
    }
}

proptest! {
    #![proptest_config(config(256))]

    /// `update_predicted`: a step of any number of turns is counted exactly when the
    /// prediction is within half a turn of it; a non-finite prediction is the half-turn rule.
    #[test]
    fn prediction_within_half_a_turn_is_exact(
        s in setup(),
        moves in proptest::collection::vec((-20.0f64..20.0, -1.0f64..1.0, 0u8..10), 1..300),
    ) {
        let mut e = s.encoder();
        e.update(s.start).unwrap();
        let mut total = s.first_count();
        let n = f64::from(s.cpr);
        for (turns, miss, kind) in moves {
            if kind == 0 {
                // Non-finite prediction: the half-turn rule.
                let step = scaled(&s, turns / 20.0);
                total += step;
                let bad = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][(step.unsigned_abs() % 3) as usize];
                e.update_predicted(s.raw_at(total), bad).unwrap();
            } else {
                let step = (turns * n).round() as i64;
                total += step;
                // Off by less than half a turn (one count of margin for f32 rounding).
                let prediction = step as f64 + miss * (n / 2.0 - 1.0).max(0.0);
                e.update_predicted(s.raw_at(total), prediction as f32).unwrap();
            }
            prop_assert_eq!(e.total_counts(), total, "step to {}", total);
        }
        check_readout(&e, &s, total)?;
    }

    /// A raw count at or above the resolution is rejected and changes nothing, before the
    /// first reading and after.
    #[test]
    fn out_of_range_reading_changes_nothing(
        s in setup(), excess: u16, fractions in steps(0..20),
    ) {
        prop_assume!(s.cpr < u16::MAX);
        let bad = s.cpr + excess % (u16::MAX - s.cpr + 1);
        let mut e = s.encoder();
        let fresh = e;
        prop_assert_eq!(e.update(bad), Err(EncoderError::OutOfRange { raw: bad }));
        prop_assert_eq!(e, fresh);
        e.update(s.start).unwrap();
        let mut total = s.first_count();
        for f in fractions {
            total += scaled(&s, f);
            e.update(s.raw_at(total)).unwrap();
        }
        let before = e;
        prop_assert_eq!(e.update(bad), Err(EncoderError::OutOfRange { raw: bad }));
        prop_assert_eq!(e.update_predicted(bad, 123.0), Err(EncoderError::OutOfRange { raw: bad }));
        prop_assert_eq!(e, before);
    }
}
