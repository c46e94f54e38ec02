//! Property tests of the chassis kinematics (`rc10_core::chassis`) over random geometries,
//! where the unit tests in `chassis.rs` use one fixed chassis each:
//!
//! - mecanum (O and X rollers, any motor signs), omni (3–6 wheels, any first-wheel angle) and
//!   swerve: wheel speeds equal the rigid-body formula (the velocity of each wheel's contact
//!   point, worked out here), and odometry of them gives the twist back;
//! - swerve modules never turn more than 90° (they reverse the wheel instead), keep their angle
//!   at zero speed, and report angles in (−π, π];
//! - wheel-speed saturation (`wheel_rpm_limited`, `modules_limited`) scales every wheel by one
//!   factor, no more than needed, so the twist keeps its direction and curvature;
//! - the acceleration limiter moves every axis by one common factor of the requested change,
//!   within each axis's limit, and holds on non-finite input;
//! - world ↔ robot frame conversions are inverse rotations.
//!
//! Tolerances: everything runs in f32 (unit roundoff 6e-8). The wheel matrices of these
//! layouts have orthogonal columns, so the least-squares inverse (computed once, in f32) adds
//! only a few roundings; the error that matters is the rounding of the rim speeds, a few
//! unit roundoffs of the twist's size `|vx| + |vy| + lever·|ω|` (lever: the most a rim speed
//! changes per rad/s, a + b for mecanum, R for omni), amplified for ω by 1 / (the moment arm
//! of the rotation column).
//! 2e-4 of the size (about 3000 roundoffs) is used: loose against rounding, tight against any
//! wrong sign or factor, which errs by the size itself. The X roller layout's rotation column
//! is `±(a − b)` (half wheelbase minus half track): it cannot turn a square chassis, so X
//! geometries are drawn with `|a − b| ≥ 5 cm` and ω is checked against that moment arm.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use proptest::prelude::*;
use proptest::test_runner::Config;
use rc10_core::chassis::{
    LinearChassis, MecanumConfig, MecanumRollers, ModuleState, Swerve, Twist, TwistLimiter, omni,
};
use std::f64::consts::{FRAC_PI_2, PI, TAU};

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

/// Output rpm per rad/s.
const RPM_PER_RAD_S: f64 = 60.0 / TAU;
/// Relative tolerance of forward kinematics (see the module docs).
const REL: f64 = 2e-4;

fn twist() -> impl Strategy<Value = Twist> {
    prop_oneof![
        12 => (-5f32..5.0, -5f32..5.0, -20f32..20.0).prop_map(|(x, y, w)| Twist::new(x, y, w)),
        1 => Just(Twist::ZERO),
    ]
}

/// The twist's size in m/s at a wheel `lever` metres from the centre.
fn size(t: &Twist, lever: f64) -> f64 {
    f64::from(t.vx_m_s).abs() + f64::from(t.vy_m_s).abs() + lever * f64::from(t.omega_rad_s).abs()
}

/// Checks `got ≈ want` axis by axis: linear within `tol` m/s, angular within `tol / lever`
/// (`lever`: the moment arm through which the wheels see ω).
fn check_twist(
    got: &Twist,
    want: (f64, f64, f64),
    tol: f64,
    lever: f64,
) -> Result<(), TestCaseError> {
    let (x, y, w) = want;
    prop_assert!(
        (f64::from(got.vx_m_s) - x).abs() <= tol,
        "vx {got:?} want {want:?}"
    );
    prop_assert!(
        (f64::from(got.vy_m_s) - y).abs() <= tol,
        "vy {got:?} want {want:?}"
    );
    prop_assert!(
        (f64::from(got.omega_rad_s) - w).abs() <= tol / lever,
        "ω {got:?} want {want:?}"
    );
    Ok(())
}

fn as_f64(t: &Twist) -> (f64, f64, f64) {
    (
        f64::from(t.vx_m_s),
        f64::from(t.vy_m_s),
        f64::from(t.omega_rad_s),
    )
}

#[derive(Debug, Clone, Copy)]
struct Mecanum {
    wheelbase: f32,
    track: f32,
    radius: f32,
    rollers: MecanumRollers,
    signs: [f32; 4],
}

fn mecanum() -> impl Strategy<Value = Mecanum> {
    (
        0.1f32..1.0,
        0.1f32..1.0,
        0.02f32..0.2,
        prop_oneof![Just(MecanumRollers::O), Just(MecanumRollers::X)],
        [
            prop_oneof![Just(1.0f32), Just(-1.0)],
            prop_oneof![Just(1.0f32), Just(-1.0)],
            prop_oneof![Just(1.0f32), Just(-1.0)],
            prop_oneof![Just(1.0f32), Just(-1.0)],
        ],
    )
        .prop_map(|(wheelbase, track, radius, rollers, signs)| Mecanum {
            wheelbase,
            track,
            radius,
            rollers,
            signs,
        })
        .prop_filter("X rollers need |a − b| ≥ 5 cm to turn", |g| {
            g.rollers == MecanumRollers::O || (g.wheelbase - g.track).abs() >= 0.1
        })
}

impl Mecanum {
    fn build(&self) -> LinearChassis<4> {
        LinearChassis::mecanum(
            MecanumConfig::new(self.wheelbase, self.track, self.radius)
                .with_rollers(self.rollers)
                .with_wheel_signs(self.signs),
        )
        .unwrap()
    }

    /// Half wheelbase plus half track: the farthest a wheel's rim term reaches per rad/s.
    fn lever(&self) -> f64 {
        f64::from(self.wheelbase + self.track) / 2.0
    }

    /// The moment arm through which the wheels see ω: a + b for O rollers, |a − b| for X.
    fn omega_lever(&self) -> f64 {
        match self.rollers {
            MecanumRollers::O => self.lever(),
            MecanumRollers::X => f64::from(self.wheelbase - self.track).abs() / 2.0,
        }
    }

    /// Rim speeds (FL, FR, RL, RR): the contact point moves at (vx − ω·y, vy + ω·x); the
    /// wheel drives the x component and its 45° rollers pass ∓ the y component (O rollers:
    /// strafing left turns the front-left wheel backwards, so its roller sign is −1).
    fn expected_rpm(&self, t: &Twist) -> [f64; 4] {
        let (a, b) = (f64::from(self.wheelbase) / 2.0, f64::from(self.track) / 2.0);
        let pos = [(a, b), (a, -b), (-a, b), (-a, -b)];
        let roller = match self.rollers {
            MecanumRollers::O => [-1.0, 1.0, 1.0, -1.0],
            MecanumRollers::X => [1.0, -1.0, -1.0, 1.0],
        };
        let (vx, vy, w) = as_f64(t);
        let mut out = [0.0; 4];
        for i in 0..4 {
            let (x, y) = pos[i];
            let rim = (vx - w * y) + roller[i] * (vy + w * x);
            out[i] = f64::from(self.signs[i]) * rim / f64::from(self.radius) * RPM_PER_RAD_S;
        }
        out
    }
}

/// Checks wheel rpm against the expected ones within `REL` of the largest rim speed.
fn check_rpm(
    got: &[f32],
    want: &[f64],
    t: &Twist,
    lever: f64,
    radius: f32,
) -> Result<(), TestCaseError> {
    let tol = REL * (size(t, lever) / f64::from(radius) * RPM_PER_RAD_S) + 1e-6;
    for (g, w) in got.iter().zip(want) {
        prop_assert!((f64::from(*g) - w).abs() <= tol, "{got:?} want {want:?}");
    }
    Ok(())
}

/// Checks that `limited` is `unlimited` scaled by the one factor that brings its peak to
/// `max_rpm` (or unchanged if already within it); returns the factor.
fn check_scaled(limited: &[f32], unlimited: &[f32], max_rpm: f32) -> Result<f64, TestCaseError> {
    let peak = unlimited
        .iter()
        .fold(0.0f64, |m, w| m.max(f64::from(*w).abs()));
    let max = f64::from(max_rpm);
    if peak <= max {
        prop_assert_eq!(limited, unlimited);
        return Ok(1.0);
    }
    let k = max / peak;
    for (l, u) in limited.iter().zip(unlimited) {
        prop_assert!(
            f64::from(*l).abs() <= max * (1.0 + 1e-6),
            "{limited:?} beyond {max}"
        );
        prop_assert!(
            (f64::from(*l) - k * f64::from(*u)).abs() <= 1e-5 * max,
            "{limited:?} is not {k} × {unlimited:?}"
        );
    }
    Ok(k)
}

proptest! {
    #![proptest_config(config(256))]

    /// Mecanum: wheel rpm = the rigid-body formula; odometry of them = the twist.
    #[test]
    fn mecanum_inverse_matches_formula_and_forward_inverts_it(g in mecanum(), t in twist()) {
        let c = g.build();
        let rpm = c.wheel_rpm(t);
        check_rpm(&rpm, &g.expected_rpm(&t), &t, g.lever(), g.radius)?;
        check_twist(&c.twist(&rpm), as_f64(&t), REL * size(&t, g.lever()) + 1e-6, g.omega_lever())?;
    }

    /// Mecanum saturation: one common factor, only as much as needed; the robot keeps its
    /// direction and curvature (odometry of the limited wheels = the twist × that factor).
    #[test]
    fn mecanum_saturation_keeps_direction(g in mecanum(), t in twist(), max_rpm in 1.0f32..3000.0) {
        let c = g.build();
        let k = check_scaled(&c.wheel_rpm_limited(t, max_rpm), &c.wheel_rpm(t), max_rpm)?;
        let (x, y, w) = as_f64(&t);
        let back = c.twist(&c.wheel_rpm_limited(t, max_rpm));
        check_twist(&back, (k * x, k * y, k * w), REL * k * size(&t, g.lever()) + 1e-6, g.omega_lever())?;
    }
}

/// Omni wheel `i` of `n` at angle θᵢ = first + 2π·i/n on radius R, driving tangentially:
/// rim = (vx − ω·y, vy + ω·x) · (−sin θ, cos θ) = −sin θ·vx + cos θ·vy + R·ω.
fn omni_expected_rpm(n: usize, radius: f64, wheel: f64, first: f64, t: &Twist) -> Vec<f64> {
    let (vx, vy, w) = as_f64(t);
    (0..n)
        .map(|i| {
            let th = first + TAU * i as f64 / n as f64;
            (-th.sin() * vx + th.cos() * vy + radius * w) / wheel * RPM_PER_RAD_S
        })
        .collect()
}

fn check_omni<const N: usize>(
    radius: f32,
    wheel: f32,
    first: f32,
    t: Twist,
    max_rpm: f32,
) -> Result<(), TestCaseError> {
    let c = omni::<N>(radius, wheel, first).unwrap();
    let lever = f64::from(radius);
    let rpm = c.wheel_rpm(t);
    let want = omni_expected_rpm(N, lever, f64::from(wheel), f64::from(first), &t);
    check_rpm(&rpm, &want, &t, lever, wheel)?;
    check_twist(
        &c.twist(&rpm),
        as_f64(&t),
        REL * size(&t, lever) + 1e-6,
        lever,
    )?;
    let k = check_scaled(&c.wheel_rpm_limited(t, max_rpm), &rpm, max_rpm)?;
    let (x, y, w) = as_f64(&t);
    check_twist(
        &c.twist(&c.wheel_rpm_limited(t, max_rpm)),
        (k * x, k * y, k * w),
        REL * k * size(&t, lever) + 1e-6,
        lever,
    )
}

proptest! {
    #![proptest_config(config(256))]

    /// Omni, 3 to 6 wheels, any first-wheel angle: inverse = the formula, forward ∘ inverse =
    /// identity, saturation keeps the direction.
    #[test]
    fn omni_inverse_forward_and_saturation(
        n in 3usize..=6, radius in 0.1f32..1.0, wheel in 0.02f32..0.2, first in -3.2f32..3.2,
        t in twist(), max_rpm in 1.0f32..3000.0,
    ) {
        match n {
            3 => check_omni::<3>(radius, wheel, first, t, max_rpm)?,
            4 => check_omni::<4>(radius, wheel, first, t, max_rpm)?,
            5 => check_omni::<5>(radius, wheel, first, t, max_rpm)?,
            _ => check_omni::<6>(radius, wheel, first, t, max_rpm)?,
        }
    }
}

fn modules_now() -> impl Strategy<Value = [ModuleState; 4]> {
    proptest::array::uniform4((
        -std::f32::consts::PI..=std::f32::consts::PI,
        -100.0f32..100.0,
    ))
    .prop_map(|m| {
        m.map(|(steer_rad, wheel_rpm)| ModuleState {
            steer_rad,
            wheel_rpm,
        })
    })
}

/// Shortest angle between two directions, radians.
fn angle_gap(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(TAU);
    d.min(TAU - d)
}

proptest! {
    #![proptest_config(config(256))]

    /// Swerve: each module's velocity is the contact point's rigid-body velocity, reached
    /// turning at most 90° from the present angle (reversing the wheel instead), angles in
    /// (−π, π], a module at zero speed keeps its angle; odometry gives the twist back;
    /// saturation scales the wheel speeds by one factor and leaves the angles.
    #[test]
    fn swerve_modules_forward_and_saturation(
        wheelbase in 0.1f32..1.0, track in 0.1f32..1.0, wheel in 0.02f32..0.2,
        t in twist(), now in modules_now(), max_rpm in 1.0f32..3000.0,
    ) {
        let s = Swerve::new(wheelbase, track, wheel).unwrap();
        let m = s.modules(t, &now);
        let (a, b) = (f64::from(wheelbase) / 2.0, f64::from(track) / 2.0);
        let lever = a + b;
        let (vx, vy, w) = as_f64(&t);
        let tol = REL * size(&t, lever) + 1e-6;
        for (i, (x, y)) in [(a, b), (a, -b), (-a, b), (-a, -b)].into_iter().enumerate() {
            let (want_x, want_y) = (vx - w * y, vy + w * x);
            let speed = f64::from(m[i].wheel_rpm) / RPM_PER_RAD_S * f64::from(wheel);
            let steer = f64::from(m[i].steer_rad);
            prop_assert!(steer > -PI - 1e-6 && steer <= PI + 1e-6, "steer {steer}");
            prop_assert!((speed * steer.cos() - want_x).abs() <= tol, "module {i}: {m:?}");
            prop_assert!((speed * steer.sin() - want_y).abs() <= tol, "module {i}: {m:?}");
            prop_assert!(
                angle_gap(steer, f64::from(now[i].steer_rad)) <= FRAC_PI_2 + 1e-5,
                "module {i} turned from {} to {steer}", now[i].steer_rad
            );
            if t == Twist::ZERO {
                prop_assert_eq!(m[i], ModuleState { steer_rad: now[i].steer_rad, wheel_rpm: 0.0 });
            }
        }
        check_twist(&s.twist(&m), (vx, vy, w), tol, lever)?;

        let limited = s.modules_limited(t, &now, max_rpm);
        for (l, u) in limited.iter().zip(&m) {
            prop_assert_eq!(l.steer_rad, u.steer_rad);
        }
        let k = check_scaled(&limited.map(|x| x.wheel_rpm), &m.map(|x| x.wheel_rpm), max_rpm)?;
        check_twist(&s.twist(&limited), (k * vx, k * vy, k * w), REL * k * size(&t, lever) + 1e-6, lever)?;
    }

    /// The acceleration limiter: each step moves by `k × (target − output)` with one `k` in
    /// [0, 1], the largest that keeps every axis within its limit × dt; non-finite targets and
    /// negative or non-finite dt hold the output.
    #[test]
    fn twist_limiter_scales_the_whole_change(
        limits in (0.1f32..20.0, 0.1f32..20.0, 0.1f32..50.0),
        steps in proptest::collection::vec((twist(), prop_oneof![
            8 => 0.0f32..0.05,
            1 => prop_oneof![Just(f32::NAN), Just(-0.001f32), Just(f32::INFINITY)],
        ], 0u8..20), 1..60),
    ) {
        let lim = [f64::from(limits.0), f64::from(limits.1), f64::from(limits.2)];
        let mut limiter = TwistLimiter::new(Twist::new(limits.0, limits.1, limits.2));
        for (target, dt, poison) in steps {
            let target = if poison == 0 { Twist::new(f32::NAN, 0.0, 0.0) } else { target };
            let before = limiter.output();
            let out = limiter.update(target, dt);
            prop_assert_eq!(out, limiter.output());
            let finite = [target.vx_m_s, target.vy_m_s, target.omega_rad_s].iter().all(|x| x.is_finite());
            if !finite || !dt.is_finite() || dt < 0.0 {
                prop_assert_eq!(out, before);
                continue;
            }
            let p = as_f64(&before);
            let (p, g, o) = ([p.0, p.1, p.2], as_f64(&target), as_f64(&out));
            let (g, o) = ([g.0, g.1, g.2], [o.0, o.1, o.2]);
            let dt = f64::from(dt);
            let d: Vec<f64> = (0..3).map(|i| g[i] - p[i]).collect();
            let k = (0..3)
                .filter(|&i| d[i] != 0.0)
                .map(|i| lim[i] * dt / d[i].abs())
                .fold(1.0f64, f64::min);
            for i in 0..3 {
                let moved = o[i] - p[i];
                let round = 1e-6 * (p[i].abs() + g[i].abs()) + 1e-9;
                prop_assert!(moved.abs() <= lim[i] * dt * (1.0 + 1e-5) + round, "axis {i} moved {moved}");
                prop_assert!((moved - k * d[i]).abs() <= 1e-5 * d[i].abs() + round, "axis {i}: {moved} ≠ {k} × {}", d[i]);
            }
        }
    }

    /// World → robot is a rotation by −yaw (ω unchanged) and robot → world undoes it.
    #[test]
    fn frame_conversions_are_inverse_rotations(t in twist(), yaw in -10.0f32..10.0) {
        let r = t.world_to_robot(yaw);
        let (vx, vy, w) = as_f64(&t);
        let (s, c) = f64::from(yaw).sin_cos();
        let tol = 1e-5 * (vx.abs() + vy.abs()) + 1e-6;
        check_twist(&r, (c * vx + s * vy, -s * vx + c * vy, w), tol, 1.0)?;
        check_twist(&r.robot_to_world(yaw), (vx, vy, w), 2.0 * tol, 1.0)?;
    }
}
