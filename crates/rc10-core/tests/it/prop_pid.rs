//! Property tests of the controllers in `rc10_core::pid`, for any finite inputs and any `dt`,
//! beyond the unit properties in `positional.rs` / `incremental.rs` (which check a finite,
//! limited output for gains up to ±1e4 and a linear error):
//!
//! - positional [`Pid`], every option drawn (any finite gains including huge ones, output and
//!   integral limits, integral separation, deadband, D filter, linear or circular error, a
//!   limit in force that may be NaN or negative, feed-forward): the output is finite, within
//!   the effective limit and equal to `p + i + d + ff` limited; the integral stays within its
//!   limit and within what can reach the output limit; P is `kp ·` the (wrapped, deadbanded)
//!   error; separation freezes the integral; it never grows while the output is saturated the
//!   same way; the documented NaN rule (zero, state untouched) and invalid-`dt` rule (integral
//!   and derivative held);
//! - incremental [`IncrementalPid`], with or without TD: finite and limited for any input; the
//!   NaN and invalid-`dt` rules; the deadband holds the output; and, for moderate inputs, each
//!   increment equals the velocity-form formula worked out here;
//! - [`TrackingDifferentiator`]: finite for any finite input sequence and any `dt` (huge steps,
//!   long pauses); non-finite input or invalid `dt` leave a started tracker unchanged; a pause
//!   beyond 8/r snaps to the input at rest; a step from rest is followed without overshoot,
//!   and in general the tracked value stays within the range of the start and the inputs.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use proptest::prelude::*;
use proptest::test_runner::Config;
use rc10_core::pid::{
    ErrorMode, IncrementalPid, IncrementalPidConfig, Pid, PidConfig, PidTerms,
    TrackingDifferentiator,
};

/// Absolute tolerance for f32 results that underflow (the smallest subnormal is 1.4e-45).
const TINY: f64 = 1e-44;

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

/// A finite gain: usually moderate, sometimes zero, sometimes as large as f32 allows.
fn gain() -> impl Strategy<Value = f32> {
    prop_oneof![
        6 => -1.0e3f32..1.0e3,
        2 => Just(0.0f32),
        1 => proptest::num::f32::NORMAL | proptest::num::f32::SUBNORMAL,
    ]
}

/// A limit: finite and non-negative, or infinity ("no limit").
fn limit() -> impl Strategy<Value = f32> {
    prop_oneof![
        6 => 0.0f32..1.0e4,
        1 => Just(0.0f32),
        2 => Just(f32::INFINITY),
        1 => proptest::num::f32::POSITIVE,
    ]
}

/// A finite input: usually moderate, sometimes huge or tiny.
fn finite_input() -> impl Strategy<Value = f32> {
    prop_oneof![
        8 => -1.0e4f32..1.0e4,
        1 => proptest::num::f32::NORMAL | proptest::num::f32::SUBNORMAL | proptest::num::f32::ZERO,
    ]
}

/// Any input; non-finite ones sometimes.
fn any_input() -> impl Strategy<Value = f32> {
    prop_oneof![
        12 => finite_input(),
        1 => prop_oneof![Just(f32::NAN), Just(f32::INFINITY), Just(f32::NEG_INFINITY)],
    ]
}

/// Any dt: usually a plausible period, sometimes a pause, zero, negative, NaN or infinite.
fn any_dt() -> impl Strategy<Value = f32> {
    prop_oneof![
        8 => 1.0e-5f32..0.02,
        2 => 0.02f32..1.0e4,
        1 => prop_oneof![
            Just(0.0f32), Just(-0.001), Just(f32::NAN), Just(f32::INFINITY),
            Just(f32::NEG_INFINITY), Just(f32::MIN_POSITIVE), Just(f32::MAX),
        ],
    ]
}

fn dt_valid(dt: f32) -> bool {
    dt.is_finite() && dt > 0.0
}

fn error_mode() -> impl Strategy<Value = ErrorMode> {
    prop_oneof![
        2 => Just(ErrorMode::Linear),
        1 => Just(ErrorMode::DEGREES),
        1 => Just(ErrorMode::RADIANS),
        1 => (1.0e-3f32..1.0e3).prop_map(|period| ErrorMode::Circular { period }),
    ]
}

fn pid_config() -> impl Strategy<Value = PidConfig> {
    (
        (gain(), gain(), gain()),
        (limit(), limit()),
        // Separation above the deadband (the rule), by this much.
        prop_oneof![2 => Just(f32::INFINITY), 1 => 1.0e-2f32..1.0e3],
        prop_oneof![2 => Just(0.0f32), 1 => 0.0f32..100.0],
        prop_oneof![2 => Just(0.0f32), 1 => 0.1f32..500.0],
        error_mode(),
    )
        .prop_map(
            |((kp, ki, kd), (out, int), above, deadband, cutoff, mode)| {
                let sep = deadband + above;
                PidConfig::new(kp, ki, kd)
                    .with_output_limit(out)
                    .with_integral_limit(int)
                    .with_integral_separation(sep)
                    .with_deadband(deadband)
                    .with_d_cutoff_hz(cutoff)
                    .with_error_mode(mode)
            },
        )
}

/// The limit in force passed to `update_within`: anything, NaN and negative included.
fn limit_in_force() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => Just(f32::INFINITY),
        4 => 0.0f32..1.0e4,
        1 => prop_oneof![Just(f32::NAN), Just(-1.0f32), Just(0.0)],
    ]
}

/// The error `target − measurement` as the configuration defines it, in f64: the plain
/// difference, or the shortest way round in `[−period/2, period/2)`.
fn error_of(mode: ErrorMode, target: f32, measurement: f32) -> f64 {
    let d = f64::from(target) - f64::from(measurement);
    match mode {
        ErrorMode::Linear => d,
        ErrorMode::Circular { period } => {
            let p = f64::from(period);
            (d + p / 2.0).rem_euclid(p) - p / 2.0
        }
    }
}

proptest! {
    #![proptest_config(config(256))]

    /// The positional controller under every option and any input sequence.
    #[test]
    fn positional_pid_is_finite_limited_and_keeps_its_rules(
        cfg in pid_config(),
        steps in proptest::collection::vec(
            (any_input(), any_input(), prop_oneof![3 => Just(0.0f32), 1 => any_input()], any_dt(), limit_in_force()),
            1..80,
        ),
    ) {
        let mut pid = Pid::new(cfg).unwrap();
        let mut last_d = 0.0f32;
        for (target, meas, ff, dt, in_force) in steps {
            let before = pid;
            let t = pid.update_within(target, meas, ff, dt, in_force);
            if !(target.is_finite() && meas.is_finite() && ff.is_finite()) {
                // Documented NaN rule: zero out, state untouched.
                prop_assert_eq!(t, PidTerms::ZERO);
                prop_assert_eq!(pid, before);
                continue;
            }
            // The limit in force: the smaller of the two, NaN or negative counting as zero,
            // "no limit" meaning the largest finite value (the output is never infinite).
            let eff = if in_force > 0.0 { in_force.min(cfg.output_limit) } else { 0.0 };
            let eff = f64::from(eff.min(f32::MAX));
            let (p, i, d, out) = (f64::from(t.p), f64::from(t.i), f64::from(t.d), f64::from(t.output));
            let ff64 = f64::from(ff);
            let terms = p.abs() + i.abs() + d.abs() + ff64.abs();
            prop_assert!(out.is_finite() && p.is_finite() && i.is_finite() && d.is_finite(), "{t:?}");
            prop_assert!(out.abs() <= eff, "{t:?} beyond {eff}");
            prop_assert_eq!(t.ff, ff);
            // The output is the limited sum of the terms it reports.
            let sum = (p + i + d + ff64).clamp(-eff, eff);
            prop_assert!(
                (out - sum).abs() <= 1e-6 * terms + TINY,
                "{t:?}: output is not p + i + d + ff limited to {eff}"
            );
            // The integral: within its own limit and within what can reach the output limit.
            prop_assert_eq!(pid.integral(), t.i);
            prop_assert!(i.abs() <= f64::from(cfg.integral_limit), "{t:?}");
            prop_assert!(i.abs() <= (eff + ff64.abs()) * (1.0 + 1e-6), "{t:?}: i beyond {eff} + |ff|");

            // P = kp · error, zero inside the deadband. The error is formed in f32: a few
            // roundings of the operands (`err_tol`); cases that close to the deadband's edge or
            // to the ends of the circular range may go either way and are skipped.
            let raw = error_of(cfg.error_mode, target, meas);
            let period = match cfg.error_mode {
                ErrorMode::Circular { period } => f64::from(period),
                ErrorMode::Linear => 0.0,
            };
            let err_tol = 4e-7 * (f64::from(target.abs()) + f64::from(meas.abs()) + period);
            let on_edge = period > 0.0 && (raw.abs() - period / 2.0).abs() <= 2.0 * err_tol;
            let edge_of_band = (raw.abs() - f64::from(cfg.deadband)).abs() <= 2.0 * err_tol;
            if !on_edge && !edge_of_band {
                let e = if raw.abs() <= f64::from(cfg.deadband) { 0.0 } else { raw };
                let want = (f64::from(cfg.kp) * e).clamp(-f64::from(f32::MAX), f64::from(f32::MAX));
                prop_assert!(
                    (p - want).abs() <= f64::from(cfg.kp).abs() * err_tol + 1e-6 * want.abs() + TINY,
                    "p = {p}, want kp · {e} = {want}"
                );
            }

            let held = f64::from(before.integral());
            // No limit cut into the held integral this step:
            let unclamped = held.abs() <= eff.min(f64::from(cfg.integral_limit));
            // Integral separation freezes the integral; an invalid dt holds it (and D).
            let separated = !on_edge && raw.abs() > f64::from(cfg.integral_separation) + 2.0 * err_tol;
            if separated || !dt_valid(dt) {
                prop_assert!(i.abs() <= held.abs() && i * held >= 0.0, "{t:?}: integral moved from {held}");
                if unclamped {
                    prop_assert_eq!(t.i, before.integral(), "{:?}: integral not frozen", t);
                }
            }
            if !dt_valid(dt) {
                prop_assert_eq!(t.d, last_d, "{:?}: derivative not held", t);
            }
            // Conditional integration: the integral never grows towards a saturated output
            // (at any scale: see `anti_windup_holds_with_a_tiny_output_limit`).
            if unclamped && (i - held) * out > 0.0 {
                prop_assert!(
                    (p + i + d + ff64).abs() <= eff * (1.0 + 1e-6) + 1e-6 * terms,
                    "{t:?}: integral grew from {held} while saturated at {eff}"
                );
            }
            last_d = t.d;
        }
    }
}

fn incremental_config() -> impl Strategy<Value = IncrementalPidConfig> {
    (
        (gain(), gain(), gain()),
        limit(),
        prop_oneof![2 => Just(0.0f32), 1 => 0.0f32..100.0],
        proptest::option::of(prop_oneof![0.1f32..1.0e4, proptest::num::f32::POSITIVE]),
    )
        .prop_map(|((kp, ki, kd), out, deadband, td)| {
            let mut c = IncrementalPidConfig::new(kp, ki, kd)
                .with_output_limit(out)
                .with_deadband(deadband);
            c.td_r_rad_s = td;
            c
        })
}

proptest! {
    #![proptest_config(config(256))]

    /// The incremental controller: finite and within its limit for any input, with the
    /// documented NaN rule (zero, state untouched), invalid-dt rule (output held) and deadband
    /// (no TD: an error within a band wider than 0 holds the output).
    #[test]
    fn incremental_pid_is_finite_limited_and_keeps_its_rules(
        cfg in incremental_config(),
        steps in proptest::collection::vec((any_input(), any_input(), any_dt()), 1..80),
    ) {
        let mut pid = IncrementalPid::new(cfg).unwrap();
        for (target, meas, dt) in steps {
            let before = pid;
            let t = pid.update(target, meas, dt);
            if !(target.is_finite() && meas.is_finite()) {
                prop_assert_eq!(t, PidTerms::ZERO);
                prop_assert_eq!(pid, before);
                continue;
            }
            prop_assert!(t.output.is_finite() && t.p.is_finite() && t.i.is_finite() && t.d.is_finite(), "{t:?}");
            prop_assert!(t.output.abs() <= cfg.output_limit, "{t:?}");
            prop_assert_eq!(pid.output(), t.output);
            if !dt_valid(dt) {
                prop_assert_eq!(t.output, before.output(), "invalid dt must hold the output");
            }
            // A deadband of 0 is no band: an error of exactly 0 is a step like any other.
            if cfg.td_r_rad_s.is_none() && cfg.deadband > 0.0 && (target - meas).abs() <= cfg.deadband {
                prop_assert_eq!(t.output, before.output(), "error within the deadband must hold the output");
            }
        }
    }

    /// Without TD, for moderate inputs, every increment is the velocity form
    /// `kp·(e − e₁) + ki·e·dt + D − D₁` over the errors outside the deadband (history
    /// starting from the first of them, at D part 0), where the D part `D = kd·ė` limited to
    /// `±output_limit`, `ė = (e − e₁)/Δt` and `Δt` is the time since `e₁`, the steps inside
    /// the band included; added to the output and limited;
    /// a step inside the band changes nothing, its error included; a step with an invalid dt
    /// (NaN, zero, negative) changes nothing and adds no time. Measurements are often drawn
    /// near the target, so that runs of steps inside the band occur.
    #[test]
    fn incremental_pid_follows_the_velocity_form(
        (kp, ki, kd) in (-100.0f32..100.0, -1.0e3f32..1.0e3, -1.0f32..1.0),
        out_limit in 1.0f32..1.0e5,
        deadband in prop_oneof![Just(0.0f32), 0.0f32..5.0],
        steps in proptest::collection::vec(
            (
                -100.0f32..100.0,
                -100.0f32..100.0,
                any::<bool>(),
                prop_oneof![8 => 1.0e-4f32..0.01, 1 => Just(f32::NAN), 1 => -0.01f32..=0.0],
            ),
            1..60,
        ),
    ) {
        let cfg = IncrementalPidConfig::new(kp, ki, kd).with_output_limit(out_limit).with_deadband(deadband);
        let mut pid = IncrementalPid::new(cfg).unwrap();
        // (e₁, D part then, ė₁, Δt of ė₁), and the time since e₁.
        let mut history: Option<(f64, f64, f64, f64)> = None;
        let mut since = 0.0f64;
        let mut u = 0.0f64;
        for (target, far, near, dt) in steps {
            // Near: within 1.5 deadbands of the target (inside the band two times in three).
            let meas = if near { target + far / 100.0 * 1.5 * deadband } else { far };
            let t = pid.update(target, meas, dt);
            if dt.is_nan() || dt <= 0.0 {
                prop_assert_eq!(f64::from(t.output), u, "an invalid dt holds the output");
                prop_assert_eq!((t.p, t.i, t.d), (0.0, 0.0, 0.0));
                continue;
            }
            // In or out of the band as the f32 error is; the terms from the exact error.
            let outside = (target - meas).abs() > deadband || deadband == 0.0;
            let e = f64::from(target) - f64::from(meas);
            let dt = f64::from(dt);
            since += dt;
            let (e1, d1, rate1, span1) = history.unwrap_or((e, 0.0, 0.0, f64::INFINITY));
            let span = since;
            let limit = f64::from(out_limit);
            let (p, i, d) = if outside {
                let rate = (e - e1) / since;
                let d_part = (f64::from(kd) * rate).clamp(-limit, limit);
                history = Some((e, d_part, rate, since));
                since = 0.0;
                (f64::from(kp) * (e - e1), f64::from(ki) * e * dt, d_part - d1)
            } else {
                (0.0, 0.0, 0.0)
            };
            // Errors are formed in f32 from inputs below 100: each within 8e-6.
            let tol = |v: f64, gain: f32, per: f64| 4.0 * 8e-6 * f64::from(gain.abs()) * per + 1e-5 * v.abs();
            prop_assert!((f64::from(t.p) - p).abs() <= tol(p, kp, 1.0), "p {} want {p}", t.p);
            prop_assert!((f64::from(t.i) - i).abs() <= tol(i, ki, dt), "i {} want {i}", t.i);
            // Each rate: its errors' rounding over its span, and a few roundings of itself.
            let d_tol = tol(0.0, kd, 1.0 / span + 1.0 / span1)
                + 1e-6 * f64::from(kd.abs()) * ((e - e1) / span).abs().max(rate1.abs()) + 1e-5 * d.abs();
            prop_assert!((f64::from(t.d) - d).abs() <= d_tol, "d {} want {d}", t.d);
            let (tp, ti, td) = (f64::from(t.p), f64::from(t.i), f64::from(t.d));
            let want = (u + tp + ti + td).clamp(-f64::from(out_limit), f64::from(out_limit));
            // Three f32 additions: a few roundings of the largest partial sum.
            let sum_tol = 1e-6 * (u.abs() + tp.abs() + ti.abs() + td.abs()) + 1e-6;
            prop_assert!((f64::from(t.output) - want).abs() <= sum_tol, "output {} want {want}", t.output);
            u = f64::from(t.output);
        }
    }
}

/// A TD rate: usually a tuned value, sometimes extreme.
fn td_rate() -> impl Strategy<Value = f32> {
    prop_oneof![
        6 => 1.0f32..2000.0,
        1 => proptest::num::f32::POSITIVE,
    ]
}

proptest! {
    #![proptest_config(config(256))]

    /// Finite for any finite inputs and any dt: huge steps, long pauses, invalid dt.
    #[test]
    fn td_is_finite_for_any_finite_input_and_dt(
        r in td_rate(), start in proptest::option::of(finite_input()),
        steps in proptest::collection::vec((finite_input(), any_dt()), 1..100),
    ) {
        let mut td = TrackingDifferentiator::new(r).unwrap();
        if let Some(x0) = start {
            td.reset(x0);
        }
        for (input, dt) in steps {
            let (x1, x2) = td.update(input, dt);
            prop_assert!(x1.is_finite() && x2.is_finite(), "({x1}, {x2}) after {input} over {dt}");
        }
    }

    /// Once started, a non-finite input or a dt that is not finite and positive leaves the
    /// state unchanged and returns it; a pause longer than 8/r snaps to the input at rest.
    #[test]
    fn td_holds_on_invalid_input_and_snaps_after_a_pause(
        r in 1.0f32..2000.0, x0 in finite_input(),
        warmup in proptest::collection::vec((-1.0e3f32..1.0e3, 1.0e-4f32..0.01), 0..20),
        bad_input in prop_oneof![Just(f32::NAN), Just(f32::INFINITY), Just(f32::NEG_INFINITY)],
        bad_dt in prop_oneof![Just(0.0f32), Just(-1.0), Just(f32::NAN), Just(f32::INFINITY), Just(-f32::MIN_POSITIVE)],
        input in finite_input(), pause_factor in 8.01f32..1.0e4,
    ) {
        let mut td = TrackingDifferentiator::new(r).unwrap();
        td.reset(x0);
        let mut state = (x0, 0.0);
        for (v, dt) in warmup {
            state = td.update(v, dt);
        }
        prop_assert_eq!(td.update(bad_input, 0.001), state);
        prop_assert_eq!(td.update(input, bad_dt), state);
        prop_assert_eq!(td.update(input, pause_factor / r), (input, 0.0));
    }

    /// A step from rest, followed with any sequence of dt: no overshoot, and the rate never
    /// points away from the input.
    #[test]
    fn td_step_from_rest_never_overshoots(
        r in 1.0f32..2000.0, x0 in -1.0e3f32..1.0e3, v in -1.0e3f32..1.0e3,
        dts in proptest::collection::vec(prop_oneof![
            4 => 1.0e-5f32..0.002,
            1 => 0.0f32..0.1,
        ], 1..200),
    ) {
        let mut td = TrackingDifferentiator::new(r).unwrap();
        td.reset(x0);
        let (lo, hi) = (f64::from(x0.min(v)), f64::from(x0.max(v)));
        // f32 rounding of values up to 1e3.
        let tol = 1e-5 * (hi - lo) + 1e-6 * f64::from(x0.abs().max(v.abs())) + 1e-6;
        for dt in dts {
            let (x1, x2) = td.update(v, dt);
            let x1 = f64::from(x1);
            prop_assert!(x1 >= lo - tol && x1 <= hi + tol, "x1 = {x1} outside [{lo}, {hi}] (dt {dt})");
            // At rest within rounding: a rate that moves x1 by less than `tol` in 1/r.
            let rate_tol = tol * f64::from(r);
            prop_assert!(
                f64::from(x2) * (f64::from(v) - f64::from(x0)).signum() >= -rate_tol,
                "rate {x2} away from the input"
            );
        }
    }

    /// Any input sequence: the tracked value stays within the range of the start value and
    /// the inputs so far (a critically damped tracker's weights are all positive).
    #[test]
    fn td_stays_within_the_range_of_its_inputs(
        r in 1.0f32..2000.0, x0 in -1.0e3f32..1.0e3,
        steps in proptest::collection::vec((-1.0e3f32..1.0e3, 1.0e-5f32..0.05), 1..200),
    ) {
        let mut td = TrackingDifferentiator::new(r).unwrap();
        td.reset(x0);
        let (mut lo, mut hi) = (f64::from(x0), f64::from(x0));
        for (v, dt) in steps {
            lo = lo.min(f64::from(v));
            hi = hi.max(f64::from(v));
            let (x1, _) = td.update(v, dt);
            let x1 = f64::from(x1);
            let tol = 1e-5 * (hi - lo) + 1e-6 * lo.abs().max(hi.abs()) + 1e-6;
            prop_assert!(x1 >= lo - tol && x1 <= hi + tol, "x1 = {x1} outside [{lo}, {hi}]");
        }
    }
}

/// Found by `positional_pid_is_finite_limited_and_keeps_its_rules`: the anti-windup test
/// used to multiply `(candidate − integral) · unlimited`, two values of the size of the
/// output limit; below about 1e-19 the product underflowed to 0 and the integral jumped to
/// the limit while the output was saturated the same way. It now compares signs; the same
/// step holds the integral at 0 at every scale.
#[test]
fn anti_windup_holds_with_a_tiny_output_limit() {
    // kp 1e-4, ki 1000 /s, dt 1 ms, error −scale: P = −1e-4·scale, and the first integral
    // increment, 1000 · (−scale) · 0.001 = −scale, would take P + I beyond the limit `scale`.
    let step = |scale: f32| {
        let cfg = PidConfig::new(1.0e-4, 1000.0, 0.0).with_output_limit(scale);
        Pid::new(cfg).unwrap().update(0.0, scale, 0.001)
    };
    let normal = step(1.0);
    assert_eq!(normal.i, 0.0, "{normal:?}");
    let tiny = step(1.0e-30);
    assert_eq!(tiny.i, 0.0, "{tiny:?}: the integral wound up to the limit");
}
