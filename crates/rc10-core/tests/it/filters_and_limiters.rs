//! The small stateful helpers a robot's control code leans on (low-pass filter, ramp, twist
//! limiter, twist clamp): resets, rate changes and bad input, as documented.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use rc10_core::chassis::{Twist, TwistLimiter, clamp_twist};
use rc10_core::filter::{LowPass, Ramp};

#[test]
fn low_pass_reset_forgets_the_state() {
    // 1 Hz cutoff: a step from 0 to 10 moves the output only a little in 1 ms...
    let mut lp = LowPass::new(1.0);
    lp.update(0.0, 0.001);
    assert!(lp.update(10.0, 0.001) < 0.1);
    // ...but after a reset the next sample initialises the output.
    lp.reset();
    assert_eq!(lp.output(), None);
    assert_eq!(lp.update(10.0, 0.001), 10.0);
}

#[test]
fn ramp_rate_can_be_read_and_changed() {
    let mut r = Ramp::new(-1000.0, 0.0); // taken by magnitude
    assert_eq!(r.rate_per_s(), 1000.0);
    assert_eq!(r.update(300.0, 0.001), 1.0);
    r.set_rate_per_s(-5000.0);
    assert_eq!(r.rate_per_s(), 5000.0);
    assert_eq!(r.update(300.0, 0.001), 6.0); // 1 + 5 per 1 ms
    r.set_rate_per_s(f32::NAN); // freezes
    assert_eq!(r.rate_per_s(), 0.0);
    assert_eq!(r.update(300.0, 0.001), 6.0);
}

#[test]
fn ramp_holds_on_a_non_finite_target_or_dt() {
    let mut r = Ramp::new(1000.0, 5.0);
    for (target, dt) in [
        (f32::NAN, 0.001),
        (f32::INFINITY, 0.001),
        (10.0, f32::NAN),
        (10.0, -0.001),
    ] {
        assert_eq!(r.update(target, dt), 5.0, "{target} {dt}");
    }
}

#[test]
fn twist_limiter_reset_takes_a_finite_twist_only() {
    let mut l = TwistLimiter::new(Twist::new(1.0, 1.0, 1.0));
    l.reset(Twist::new(0.5, -0.25, 2.0));
    assert_eq!(l.output(), Twist::new(0.5, -0.25, 2.0));
    l.reset(Twist::new(f32::NAN, 0.0, 0.0)); // ignored
    assert_eq!(l.output(), Twist::new(0.5, -0.25, 2.0));
    // From there at 1 m/s² for 10 ms: vx moves 0.01 toward 0 (the largest relative change,
    // omega 2 -> 0 at 1 rad/s², scales all three together: k = 0.01 / 2).
    let out = l.update(Twist::ZERO, 0.01);
    assert!((out.omega_rad_s - 1.99).abs() < 1e-5, "{out:?}");
    assert!((out.vx_m_s - 0.5 * (1.0 - 0.005)).abs() < 1e-5, "{out:?}");
}

#[test]
fn clamp_twist_limits_each_axis() {
    let max = Twist::new(2.0, 1.0, 3.0);
    assert_eq!(
        clamp_twist(Twist::new(5.0, -4.0, 0.5), max),
        Twist::new(2.0, -1.0, 0.5)
    );
    assert_eq!(
        clamp_twist(Twist::new(-5.0, 0.25, -9.0), max),
        Twist::new(-2.0, 0.25, -3.0)
    );
}

#[test]
fn clamp_twist_holds_an_axis_with_a_nan_limit_and_frees_one_with_an_infinite_limit() {
    let max = Twist::new(f32::NAN, f32::INFINITY, -1.0);
    let t = clamp_twist(Twist::new(5.0, -40.0, 3.0), max);
    assert_eq!((t.vx_m_s, t.vy_m_s, t.omega_rad_s), (0.0, -40.0, 1.0));
    // A NaN command is 0 whatever the limit.
    let t = clamp_twist(Twist::new(f32::NAN, f32::NAN, 0.5), max);
    assert_eq!((t.vx_m_s, t.vy_m_s, t.omega_rad_s), (0.0, 0.0, 0.5));
}

#[test]
fn ramp_reset_jumps_to_a_finite_value() {
    let mut r = Ramp::new(1000.0, 0.0);
    r.reset(250.0);
    assert_eq!(r.output(), 250.0);
    assert_eq!(r.update(300.0, 0.001), 251.0); // and ramps on from there
    r.reset(f32::NAN); // ignored
    assert_eq!(r.output(), 251.0);
}
