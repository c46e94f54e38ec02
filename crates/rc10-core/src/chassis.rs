//! Chassis kinematics: robot twist ↔ wheel speeds for mecanum, omni and swerve drives, world ↔
//! robot frames, acceleration limiting that keeps the direction of motion, wheel-speed
//! saturation that scales all wheels together, forward kinematics (the twist the wheels
//! measure) and dead-reckoning odometry ([`Odometry`]: a world pose from that twist, with the
//! heading from the wheels or a gyro).
//!
//! Conventions: robot frame x forward, y left, z up; angles counter-clockwise positive, in
//! radians; speeds in m/s and rad/s; wheel speeds are **output-shaft rpm** of each wheel's
//! motor, positive when the wheel rolls the robot along its drive direction, times the wheel's
//! mounting sign (motors on the right side of a chassis usually face the other way: give them
//! sign −1 once, and the rest of your code never thinks about it).
//!
//! ```
//! use rc10_core::chassis::{LinearChassis, MecanumConfig, Twist};
//! // 0.4 m wheelbase, 0.36 m track, wheels of 76 mm radius (RoboMaster standard chassis).
//! let chassis = LinearChassis::mecanum(MecanumConfig::new(0.4, 0.36, 0.076)).unwrap();
//! let rpm = chassis.wheel_rpm(Twist::new(1.0, 0.0, 0.0)); // 1 m/s forward
//! // v / r = 1 / 0.076 rad/s = 125.65 rpm on every wheel.
//! assert!(rpm.iter().all(|w| (w - 125.65).abs() < 0.01));
//! let back = chassis.twist(&rpm);
//! assert!((back.vx_m_s - 1.0).abs() < 1e-5);
//! ```

use crate::geometry::Pose2D;
use crate::math::{saturate, wrap_rad_pi};
use core::f32::consts::{PI, TAU};
use core::fmt;
use nalgebra::{Matrix3, SMatrix, Vector3};

const RAD_S_TO_RPM: f32 = 60.0 / TAU;

/// A planar velocity: linear in m/s, angular in rad/s.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Twist {
    /// Velocity along x (forward), m/s.
    pub vx_m_s: f32,
    /// Velocity along y (left), m/s.
    pub vy_m_s: f32,
    /// Angular velocity about z (counter-clockwise), rad/s.
    pub omega_rad_s: f32,
}

impl Twist {
    /// A twist from its three components.
    pub const fn new(vx_m_s: f32, vy_m_s: f32, omega_rad_s: f32) -> Self {
        Self {
            vx_m_s,
            vy_m_s,
            omega_rad_s,
        }
    }

    /// Zero.
    pub const ZERO: Self = Self::new(0.0, 0.0, 0.0);

    /// The same motion written in a frame rotated by `yaw_rad` (counter-clockwise): turns a
    /// world-frame command into the robot frame when `yaw_rad` is the robot's heading
    /// (RC10_LIB Chassis_Base's world → robot conversion, for "field-centric" driving).
    pub fn world_to_robot(self, yaw_rad: f32) -> Self {
        let (s, c) = libm::sincosf(yaw_rad);
        Self::new(
            c * self.vx_m_s + s * self.vy_m_s,
            -s * self.vx_m_s + c * self.vy_m_s,
            self.omega_rad_s,
        )
    }

    /// The inverse of [`world_to_robot`](Self::world_to_robot).
    pub fn robot_to_world(self, yaw_rad: f32) -> Self {
        self.world_to_robot(-yaw_rad)
    }

    fn is_finite(&self) -> bool {
        self.vx_m_s.is_finite() && self.vy_m_s.is_finite() && self.omega_rad_s.is_finite()
    }
}

/// Why a chassis geometry cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ChassisError {
    /// A length is not finite and positive.
    InvalidDimension,
    /// The wheels cannot determine the twist (e.g. all omni wheels parallel).
    Singular,
    /// A wheel's sign is not +1 or −1.
    InvalidSign,
}

impl fmt::Display for ChassisError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::InvalidDimension => "chassis dimension not finite and positive",
            Self::Singular => "wheel arrangement cannot determine the chassis twist",
            Self::InvalidSign => "wheel sign is not +1 or -1",
        })
    }
}

impl core::error::Error for ChassisError {}

fn positive(x: f32) -> Result<f32, ChassisError> {
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        Err(ChassisError::InvalidDimension)
    }
}

/// How the mecanum rollers are arranged, seen from above.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MecanumRollers {
    /// The common arrangement: the rollers touching the ground form an "O" (a diamond), seen
    /// from above or from below alike; the rollers on top of an upright chassis, the ones you
    /// see, form an "X". Strafing left spins front-left backwards.
    #[default]
    O,
    /// The mirrored arrangement: the rollers touching the ground form an "X" (those on top of
    /// an upright chassis an "O"). Its wheels turn the chassis
    /// with a lever of half the wheelbase *minus* half the track, not plus: a near-square X
    /// chassis can barely spin (huge wheel rpm per rad/s), and its odometry divides by that
    /// small difference, so wheel-speed noise becomes large yaw-rate errors. An exactly square
    /// one cannot spin at all: [`LinearChassis::mecanum`] returns [`ChassisError::Singular`].
    X,
}

/// A four-wheel mecanum chassis; wheels in the order front-left, front-right, rear-left,
/// rear-right.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MecanumConfig {
    /// Distance between front and rear axles, m.
    pub wheelbase_m: f32,
    /// Distance between left and right wheel centres, m.
    pub track_m: f32,
    /// Wheel radius, m.
    pub wheel_radius_m: f32,
    /// Roller arrangement.
    pub rollers: MecanumRollers,
    /// Per-wheel motor sign (FL, FR, RL, RR): −1 for motors mounted mirrored.
    pub wheel_signs: [f32; 4],
}

impl MecanumConfig {
    /// O rollers, all motors with sign +1.
    pub const fn new(wheelbase_m: f32, track_m: f32, wheel_radius_m: f32) -> Self {
        Self {
            wheelbase_m,
            track_m,
            wheel_radius_m,
            rollers: MecanumRollers::O,
            wheel_signs: [1.0; 4],
        }
    }

    /// Sets [`wheel_signs`](Self::wheel_signs).
    #[must_use]
    pub const fn with_wheel_signs(mut self, signs: [f32; 4]) -> Self {
        self.wheel_signs = signs;
        self
    }

    /// Sets [`rollers`](Self::rollers).
    #[must_use]
    pub const fn with_rollers(mut self, rollers: MecanumRollers) -> Self {
        self.rollers = rollers;
        self
    }
}

/// A chassis whose wheel rim speeds are linear in the twist: mecanum and omni wheels.
///
/// Wheel `i`'s rim speed (m/s) is `rows[i] · (vx, vy, ω)`; its motor turns at
/// `sign[i] · rim / r` (converted to rpm). Odometry uses the least-squares inverse, computed
/// once at construction, so a slipping wheel pulls the estimate only by its share.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearChassis<const N: usize> {
    rows: SMatrix<f32, N, 3>,
    pseudo_inverse: SMatrix<f32, 3, N>,
    wheel_radius_m: f32,
    signs: [f32; N],
}

impl<const N: usize> LinearChassis<N> {
    /// A chassis from explicit rows `[kx, ky, kω]` (rim speed = kx·vx + ky·vy + kω·ω),
    /// wheel radius and per-wheel signs (+1, or −1 for a wheel whose motor turns the other
    /// way for a positive rim speed; anything else is [`ChassisError::InvalidSign`]).
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "nalgebra f32 product: no integer overflow"
    )]
    pub fn from_rows(
        rows: [[f32; 3]; N],
        wheel_radius_m: f32,
        signs: [f32; N],
    ) -> Result<Self, ChassisError> {
        let r = positive(wheel_radius_m)?;
        if rows.iter().flatten().any(|x| !x.is_finite()) {
            return Err(ChassisError::InvalidDimension);
        }
        // Odometry undoes a sign by multiplying by it again: only ±1 are their own inverse.
        if signs.iter().any(|&s| s != 1.0 && s != -1.0) {
            return Err(ChassisError::InvalidSign);
        }
        let m = SMatrix::<f32, N, 3>::from_fn(|i, j| {
            rows.get(i)
                .and_then(|row| row.get(j))
                .copied()
                .unwrap_or(0.0)
        });
        let normal: Matrix3<f32> = m.transpose() * m;
        let inverse = normal.try_inverse().ok_or(ChassisError::Singular)?;
        Ok(Self {
            rows: m,
            pseudo_inverse: inverse * m.transpose(),
            wheel_radius_m: r,
            signs,
        })
    }

    /// The same chassis with these per-wheel signs (+1, or −1 for a motor mounted the other
    /// way round), for the solvers that build their rows themselves ([`omni`]; mecanum
    /// takes them in [`MecanumConfig::with_wheel_signs`]). Anything but ±1 is
    /// [`ChassisError::InvalidSign`].
    ///
    /// ```
    /// use core::f32::consts::FRAC_PI_2;
    /// use rc10_core::chassis::{omni, Twist};
    /// let plain = omni::<3>(0.2, 0.05, FRAC_PI_2).unwrap();
    /// let mirrored = plain.with_wheel_signs([1.0, -1.0, 1.0]).unwrap();
    /// let (a, b) = (plain.wheel_rpm(Twist::new(1.0, 0.0, 0.0)), mirrored.wheel_rpm(Twist::new(1.0, 0.0, 0.0)));
    /// assert_eq!((b[0], b[1], b[2]), (a[0], -a[1], a[2]));
    /// ```
    pub fn with_wheel_signs(mut self, signs: [f32; N]) -> Result<Self, ChassisError> {
        if signs.iter().any(|&s| s != 1.0 && s != -1.0) {
            return Err(ChassisError::InvalidSign);
        }
        self.signs = signs;
        Ok(self)
    }

    /// Output-shaft rpm of every wheel for `twist`. A non-finite twist, or one so large that
    /// a wheel's rpm overflows `f32`, gives all zeros.
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "nalgebra f32 product: no integer overflow"
    )]
    pub fn wheel_rpm(&self, twist: Twist) -> [f32; N] {
        let mut out = [0.0; N];
        if !twist.is_finite() {
            return out;
        }
        let v = Vector3::new(twist.vx_m_s, twist.vy_m_s, twist.omega_rad_s);
        let rim = self.rows * v;
        for ((o, rim), sign) in out.iter_mut().zip(rim.iter()).zip(&self.signs) {
            *o = sign * rim / self.wheel_radius_m * RAD_S_TO_RPM;
        }
        if out.iter().any(|w| !w.is_finite()) {
            return [0.0; N];
        }
        out
    }

    /// Like [`wheel_rpm`](Self::wheel_rpm), but if any wheel would exceed `max_rpm` all are
    /// scaled down together, so the robot keeps its direction and curvature and only slows.
    pub fn wheel_rpm_limited(&self, twist: Twist, max_rpm: f32) -> [f32; N] {
        let mut rpm = self.wheel_rpm(twist);
        scale_to_limit(&mut rpm, max_rpm);
        rpm
    }

    /// The twist the wheels produce (odometry): least squares over all wheels. Non-finite
    /// wheel speeds give [`Twist::ZERO`].
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "nalgebra f32 product: no integer overflow"
    )]
    pub fn twist(&self, wheel_rpm: &[f32; N]) -> Twist {
        if wheel_rpm.iter().any(|w| !w.is_finite()) {
            return Twist::ZERO;
        }
        let rim = SMatrix::<f32, N, 1>::from_fn(|i, _| {
            let w = wheel_rpm.get(i).copied().unwrap_or(0.0);
            let s = self.signs.get(i).copied().unwrap_or(1.0);
            s * w / RAD_S_TO_RPM * self.wheel_radius_m
        });
        let t = self.pseudo_inverse * rim;
        Twist::new(t.x, t.y, t.z)
    }
}

impl LinearChassis<4> {
    /// A mecanum chassis (wheels FL, FR, RL, RR).
    ///
    /// Wheel `i` at `(xᵢ, yᵢ)` with roller sign `sᵢ` has rim speed
    /// `vx − ω·yᵢ + sᵢ·(vy + ω·xᵢ)`: for O rollers `s = (−1, +1, +1, −1)`, which gives the
    /// familiar rows, with `k = a + b` (`a`, `b` half the wheelbase and track):
    /// FL `vx − vy − k·ω`, FR `vx + vy + k·ω`, RL `vx + vy − k·ω`, RR `vx − vy + k·ω`.
    /// X rollers flip every roller sign, `s = (+1, −1, −1, +1)`: FL `vx + vy + k·ω`,
    /// FR `vx − vy − k·ω`, RL `vx − vy + k·ω`, RR `vx + vy − k·ω` with `k = a − b` (see
    /// [`MecanumRollers::X`]).
    pub fn mecanum(config: MecanumConfig) -> Result<Self, ChassisError> {
        let a = positive(config.wheelbase_m)? / 2.0;
        let b = positive(config.track_m)? / 2.0;
        let s = match config.rollers {
            MecanumRollers::O => [-1.0, 1.0, 1.0, -1.0],
            MecanumRollers::X => [1.0, -1.0, -1.0, 1.0],
        };
        let pos = [(a, b), (a, -b), (-a, b), (-a, -b)];
        let mut rows = [[0.0; 3]; 4];
        for ((row, (x, y)), s) in rows.iter_mut().zip(pos).zip(s) {
            *row = [1.0, s, s * x - y];
        }
        Self::from_rows(rows, config.wheel_radius_m, config.wheel_signs)
    }
}

/// An omni chassis of `N` wheels evenly spaced on a circle of radius `center_to_wheel_m`, the
/// first at `first_wheel_angle_rad` from the robot's x axis, counting counter-clockwise, each
/// driving tangentially (counter-clockwise positive). Three wheels at 90°, 210°, 330° or four at
/// 45°, 135°, 225°, 315° are the usual layouts.
///
/// ```
/// use core::f32::consts::FRAC_PI_4;
/// use rc10_core::chassis::{omni, Twist};
/// let chassis = omni::<4>(0.25, 0.05, FRAC_PI_4).unwrap();
/// let rpm = chassis.wheel_rpm(Twist::new(0.0, 0.0, 1.0)); // spin at 1 rad/s
/// // Every wheel's rim moves at R·ω = 0.25 m/s: 0.25 / 0.05 rad/s = 47.75 rpm.
/// assert!(rpm.iter().all(|w| (w - 47.75).abs() < 0.01));
/// ```
pub fn omni<const N: usize>(
    center_to_wheel_m: f32,
    wheel_radius_m: f32,
    first_wheel_angle_rad: f32,
) -> Result<LinearChassis<N>, ChassisError> {
    let radius = positive(center_to_wheel_m)?;
    if !first_wheel_angle_rad.is_finite() {
        return Err(ChassisError::InvalidDimension);
    }
    let mut rows = [[0.0; 3]; N];
    for (i, row) in rows.iter_mut().enumerate() {
        let theta = first_wheel_angle_rad + TAU * i as f32 / N as f32;
        let (s, c) = libm::sincosf(theta);
        // Tangential drive direction (−sin θ, cos θ) at (R cos θ, R sin θ).
        *row = [-s, c, radius];
    }
    LinearChassis::from_rows(rows, wheel_radius_m, [1.0; N])
}

/// Scales all values down together so none exceeds `max` in magnitude.
fn scale_to_limit(values: &mut [f32], max: f32) {
    let limit = if max.is_nan() { 0.0 } else { max.abs() };
    let peak = values.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    if peak > limit && peak > 0.0 {
        let k = limit / peak;
        values.iter_mut().for_each(|v| *v *= k);
    }
}

/// A finite angle brought into (−π, π] radians; a non-finite one as it is.
fn steer_range(angle_rad: f32) -> f32 {
    if !angle_rad.is_finite() {
        return angle_rad;
    }
    let a = wrap_rad_pi(angle_rad);
    if a <= -PI { a + TAU } else { a }
}

/// One swerve module's command.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ModuleState {
    /// Steering angle in radians, relative to the robot's x axis: (−π, π] in what
    /// [`Swerve::modules`] returns.
    pub steer_rad: f32,
    /// Wheel output-shaft rpm (negative: the wheel runs backwards).
    pub wheel_rpm: f32,
}

/// A four-module swerve chassis; modules front-left, front-right, rear-left, rear-right.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Swerve {
    positions: [(f32, f32); 4],
    wheel_radius_m: f32,
    pseudo_inverse: SMatrix<f32, 3, 8>,
}

impl Swerve {
    /// Modules at the corners of a `wheelbase_m` × `track_m` rectangle.
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "nalgebra f32 product: no integer overflow"
    )]
    pub fn new(wheelbase_m: f32, track_m: f32, wheel_radius_m: f32) -> Result<Self, ChassisError> {
        let a = positive(wheelbase_m)? / 2.0;
        let b = positive(track_m)? / 2.0;
        let r = positive(wheel_radius_m)?;
        let positions = [(a, b), (a, -b), (-a, b), (-a, -b)];
        // Module velocity: (vx − ω·y, vy + ω·x) — eight linear equations in (vx, vy, ω).
        let m = SMatrix::<f32, 8, 3>::from_fn(|row, col| {
            let (x, y) = positions.get(row / 2).copied().unwrap_or((0.0, 0.0));
            match (row % 2, col) {
                (0, 0) | (1, 1) => 1.0,
                (0, 2) => -y,
                (1, 2) => x,
                _ => 0.0,
            }
        });
        let inverse = (m.transpose() * m)
            .try_inverse()
            .ok_or(ChassisError::Singular)?;
        Ok(Self {
            positions,
            wheel_radius_m: r,
            pseudo_inverse: inverse * m.transpose(),
        })
    }

    /// Module commands for `twist`, steering each module the shortest way from `current`
    /// (reversing the wheel instead of turning more than 90°). A module whose speed is zero
    /// keeps its present angle (no snapping back to 0 when the robot stops), brought into
    /// (−π, π] (a NaN present angle stays NaN, which a motor's `set_target_*` refuses). A
    /// non-finite twist, or one so large that a wheel's rpm overflows `f32`, stops all wheels
    /// at their present angles.
    pub fn modules(&self, twist: Twist, current: &[ModuleState; 4]) -> [ModuleState; 4] {
        let stopped = current.map(|m| ModuleState {
            steer_rad: steer_range(m.steer_rad),
            wheel_rpm: 0.0,
        });
        if !twist.is_finite() {
            return stopped;
        }
        let mut out = stopped;
        for ((o, (x, y)), now) in out.iter_mut().zip(&self.positions).zip(current) {
            let vx = twist.vx_m_s - twist.omega_rad_s * y;
            let vy = twist.vy_m_s + twist.omega_rad_s * x;
            let speed = libm::hypotf(vx, vy);
            if speed < 1e-6 {
                continue;
            }
            let mut angle = libm::atan2f(vy, vx);
            let mut rpm = speed / self.wheel_radius_m * RAD_S_TO_RPM;
            if wrap_rad_pi(angle - now.steer_rad).abs() > PI / 2.0 {
                angle = wrap_rad_pi(angle + PI);
                rpm = -rpm;
            }
            o.steer_rad = steer_range(angle);
            o.wheel_rpm = rpm;
        }
        if out.iter().any(|m| !m.wheel_rpm.is_finite()) {
            return stopped;
        }
        out
    }

    /// Like [`modules`](Self::modules), scaling all wheel speeds together to at most `max_rpm`.
    pub fn modules_limited(
        &self,
        twist: Twist,
        current: &[ModuleState; 4],
        max_rpm: f32,
    ) -> [ModuleState; 4] {
        let mut m = self.modules(twist, current);
        let mut rpm = m.map(|s| s.wheel_rpm);
        scale_to_limit(&mut rpm, max_rpm);
        for (s, r) in m.iter_mut().zip(rpm) {
            s.wheel_rpm = r;
        }
        m
    }

    /// The twist measured module states produce (odometry, least squares).
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "nalgebra f32 product: no integer overflow"
    )]
    pub fn twist(&self, modules: &[ModuleState; 4]) -> Twist {
        if modules
            .iter()
            .any(|m| !(m.steer_rad.is_finite() && m.wheel_rpm.is_finite()))
        {
            return Twist::ZERO;
        }
        let v = SMatrix::<f32, 8, 1>::from_fn(|row, _| {
            let m = modules.get(row / 2).copied().unwrap_or_default();
            let speed = m.wheel_rpm / RAD_S_TO_RPM * self.wheel_radius_m;
            let (s, c) = libm::sincosf(m.steer_rad);
            if row % 2 == 0 { speed * c } else { speed * s }
        });
        let t = self.pseudo_inverse * v;
        Twist::new(t.x, t.y, t.z)
    }
}

/// Limits how fast a commanded twist may change: each axis has its own acceleration limit, and
/// when any axis is limited the whole change is scaled by the same factor, so the direction in
/// which the command moves is kept (a diagonal push stays diagonal instead of sliding along
/// whichever axis saturates first).
///
/// Limit the command in the frame it is given in. For a chassis that spins while it drives
/// field-relative (小陀螺), that is the world frame: limit the world-frame twist, then
/// [`Twist::world_to_robot`] it. Limited after the rotation, the robot-frame target turns
/// with the chassis (at 2 m/s and 10 rad/s it changes by 20 m/s² without anyone touching
/// the sticks), and a 2 m/s² limit shrinks the drive to a fraction of what was asked. As the
/// change is scaled as a whole, a change in ω also slows the linear axes while it lasts.
///
/// ```
/// use rc10_core::chassis::{Twist, TwistLimiter};
/// // 2 m/s² on each linear axis, 6 rad/s² in rotation.
/// let mut limiter = TwistLimiter::new(Twist::new(2.0, 2.0, 6.0));
/// let out = limiter.update(Twist::new(1.0, 0.5, 0.0), 0.1);
/// // x may change by 0.2 m/s: the whole step is scaled by 0.2, so y changes by 0.1.
/// assert!((out.vx_m_s - 0.2).abs() < 1e-6 && (out.vy_m_s - 0.1).abs() < 1e-6);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwistLimiter {
    max_accel: Twist,
    output: Twist,
}

impl TwistLimiter {
    /// Limits per axis: m/s², m/s², rad/s² (taken by magnitude; NaN counts as 0). The whole
    /// change is scaled by one factor, so a zero limit on one axis holds *every* axis while
    /// that axis's target differs from the output (the direction of the change is kept);
    /// an infinite limit leaves its axis unlimited.
    pub fn new(max_accel: Twist) -> Self {
        let clean = |x: f32| if x.is_nan() { 0.0 } else { x.abs() };
        Self {
            max_accel: Twist::new(
                clean(max_accel.vx_m_s),
                clean(max_accel.vy_m_s),
                clean(max_accel.omega_rad_s),
            ),
            output: Twist::ZERO,
        }
    }

    /// Moves towards `target` for `dt_s` seconds; returns the limited twist. A non-finite
    /// target or `dt_s` holds the output.
    pub fn update(&mut self, target: Twist, dt_s: f32) -> Twist {
        if !target.is_finite() || !dt_s.is_finite() || dt_s < 0.0 {
            return self.output;
        }
        let d = [
            target.vx_m_s - self.output.vx_m_s,
            target.vy_m_s - self.output.vy_m_s,
            target.omega_rad_s - self.output.omega_rad_s,
        ];
        let lim = [
            self.max_accel.vx_m_s * dt_s,
            self.max_accel.vy_m_s * dt_s,
            self.max_accel.omega_rad_s * dt_s,
        ];
        let k = d
            .iter()
            .zip(lim)
            .filter(|(d, _)| d.abs() > 0.0)
            .map(|(d, l)| l / d.abs())
            .fold(1.0f32, f32::min);
        self.output = if k >= 1.0 {
            // Within reach: the target itself (`output + d` can round beside it).
            target
        } else {
            Twist::new(
                self.output.vx_m_s + k * d[0],
                self.output.vy_m_s + k * d[1],
                self.output.omega_rad_s + k * d[2],
            )
        };
        self.output
    }

    /// The present output.
    pub const fn output(&self) -> Twist {
        self.output
    }

    /// Sets the output (e.g. to the measured twist after a stop).
    pub fn reset(&mut self, twist: Twist) {
        if twist.is_finite() {
            self.output = twist;
        }
    }
}

/// Clamps each axis of a twist to `±max` (m/s, m/s, rad/s): for commands from a remote.
/// Limits are taken by magnitude; an infinite one leaves its axis free, a NaN one holds that
/// axis at 0 (a limit computed from bad numbers stops the axis rather than freeing it;
/// [`TwistLimiter`] reads a NaN limit as 0 too). A NaN command on an axis is 0.
pub fn clamp_twist(twist: Twist, max: Twist) -> Twist {
    // `saturate` holds a value at 0 under a NaN limit.
    Twist::new(
        saturate(twist.vx_m_s, max.vx_m_s),
        saturate(twist.vy_m_s, max.vy_m_s),
        saturate(twist.omega_rad_s, max.omega_rad_s),
    )
}

/// Dead reckoning: integrates the robot-frame twist the wheels measure
/// ([`LinearChassis::twist`], [`Swerve::twist`]) into a world pose: `x`, `y` in metres,
/// heading in radians (counter-clockwise from world +x, kept in `[−π, π)`).
///
/// Each step takes the twist as constant over `dt_s`, so the robot moves along an arc: the
/// step is exact for a constant twist however long it is (a straight line when it does not
/// turn). The heading comes from the twist's `omega_rad_s` ([`update`](Self::update)), or
/// from a gyro ([`update_with_yaw`](Self::update_with_yaw), usually better: wheels slip when
/// the chassis spins). Wheel odometry drifts; correct it with an absolute fix through
/// [`reset`](Self::reset).
///
/// ```
/// use rc10_core::chassis::{Odometry, Twist};
/// use rc10_core::geometry::Pose2D;
/// let mut odom = Odometry::new(Pose2D::new(0.0, 0.0, 0.0));
/// // 1 m/s forward while turning left at 1 rad/s, for a quarter turn: a quarter of a circle
/// // of radius 1 m, ending at (1, 1) facing +y.
/// let quarter_s = core::f32::consts::FRAC_PI_2;
/// assert!(odom.update(Twist::new(1.0, 0.0, 1.0), quarter_s));
/// let p = odom.pose();
/// assert!((p.x - 1.0).abs() < 1e-5 && (p.y - 1.0).abs() < 1e-5);
/// assert!((p.theta_rad - quarter_s).abs() < 1e-6);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Odometry {
    pose: Pose2D,
    /// The gyro's yaw at the last [`update_with_yaw`](Self::update_with_yaw), rad.
    last_yaw: Option<f32>,
}

impl Odometry {
    /// Starts at `start` (its heading wrapped into `[−π, π)`; a non-finite pose starts at the
    /// origin).
    pub fn new(start: Pose2D) -> Self {
        let mut odometry = Self::default();
        odometry.reset(start);
        odometry
    }

    /// The pose now.
    pub const fn pose(&self) -> Pose2D {
        self.pose
    }

    /// Sets the pose (an absolute fix: a wall, a marker, the referee system's position).
    /// Returns `false`, and changes nothing, for a non-finite pose.
    pub fn reset(&mut self, pose: Pose2D) -> bool {
        if !(pose.x.is_finite() && pose.y.is_finite() && pose.theta_rad.is_finite()) {
            return false;
        }
        self.pose = Pose2D::new(pose.x, pose.y, wrap_rad_pi(pose.theta_rad));
        true
    }

    /// Advances `dt_s` seconds with the robot-frame `twist`, turning by
    /// `omega_rad_s · dt_s`. Returns `false`, and changes nothing, for a non-finite twist,
    /// a `dt_s` that is not finite and positive, or a step that overflows. The next
    /// [`update_with_yaw`](Self::update_with_yaw) starts afresh (it would otherwise turn
    /// again by the gyro's change over this step).
    pub fn update(&mut self, twist: Twist, dt_s: f32) -> bool {
        if !(twist.is_finite() && dt_s.is_finite() && dt_s > 0.0) {
            return false;
        }
        let moved = self.advance(twist, twist.omega_rad_s * dt_s, dt_s);
        if moved {
            self.last_yaw = None;
        }
        moved
    }

    /// Advances `dt_s` seconds with the robot-frame `twist` (its `omega_rad_s` unused), to
    /// the heading `yaw_rad` a gyro reads at the end of the step. The gyro may have any zero
    /// and any wrap, but must be counter-clockwise positive seen from above, as the pose's
    /// heading is: negate a clockwise-positive (NED) yaw. Only its change counts, the shorter
    /// way round, and the pose's heading follows the gyro's changes from the heading the pose
    /// had; the first call has no change to go by and moves without turning. Call it often
    /// enough that the gyro turns less than half a turn between calls: a change of π or more
    /// is taken the other way round. Returns `false`,
    /// and changes nothing, for a non-finite twist or yaw, a `dt_s` that is not finite and
    /// positive, or a step that overflows.
    pub fn update_with_yaw(&mut self, twist: Twist, yaw_rad: f32, dt_s: f32) -> bool {
        if !(twist.is_finite() && yaw_rad.is_finite() && dt_s.is_finite() && dt_s > 0.0) {
            return false;
        }
        let turn = match self.last_yaw {
            Some(last) => wrap_rad_pi(yaw_rad - last),
            None => 0.0,
        };
        let moved = self.advance(twist, turn, dt_s);
        if moved {
            self.last_yaw = Some(yaw_rad);
        }
        moved
    }

    /// Moves along the arc that turns by `turn_rad` while covering the robot-frame velocity
    /// for `dt_s`: the displacement is `∫ R(θ₀ + turn·t/dt) v dt`, which is
    /// `R(θ₀) · dt · [[s, −c], [c, s]] · v` with `s = sin φ / φ` and `c = (1 − cos φ) / φ`.
    fn advance(&mut self, twist: Twist, turn_rad: f32, dt_s: f32) -> bool {
        let phi = turn_rad;
        // From the half angle: sin φ = 2·sin(φ/2)·cos(φ/2) and 1 − cos φ = 2·sin²(φ/2), so
        // neither loses digits to a cancellation however small φ is (1 − cos φ would).
        let (s, c) = if phi == 0.0 {
            (1.0, 0.0)
        } else {
            let (sin_half, cos_half) = libm::sincosf(phi * 0.5);
            let twice_sin_half = 2.0 * sin_half / phi;
            (twice_sin_half * cos_half, twice_sin_half * sin_half)
        };
        let (vx, vy) = (twist.vx_m_s * dt_s, twist.vy_m_s * dt_s);
        let (local_x, local_y) = (s * vx - c * vy, c * vx + s * vy);
        let (sin0, cos0) = libm::sincosf(self.pose.theta_rad);
        let x = self.pose.x + cos0 * local_x - sin0 * local_y;
        let y = self.pose.y + sin0 * local_x + cos0 * local_y;
        let theta = wrap_rad_pi(self.pose.theta_rad + phi);
        if !(x.is_finite() && y.is_finite()) {
            return false;
        }
        self.pose = Pose2D::new(x, y, theta);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f32::consts::{FRAC_PI_2, FRAC_PI_4};
    use proptest::prelude::*;

    fn close(p: Pose2D, x: f32, y: f32, theta: f32, tol: f32) -> bool {
        (p.x - x).abs() < tol
            && (p.y - y).abs() < tol
            && wrap_rad_pi(p.theta_rad - theta).abs() < tol
    }

    #[test]
    fn odometry_drives_straight_along_its_heading() {
        // 1 m/s forward for 1 s in 1 ms steps, facing +y (90°): 1 m along +y.
        let mut odom = Odometry::new(Pose2D::new(2.0, 3.0, FRAC_PI_2));
        for _ in 0..1000 {
            assert!(odom.update(Twist::new(1.0, 0.0, 0.0), 0.001));
        }
        assert!(
            close(odom.pose(), 2.0, 4.0, FRAC_PI_2, 1e-4),
            "{:?}",
            odom.pose()
        );
        // Strafing left (+y in the robot frame) while facing +y goes towards world −x.
        for _ in 0..500 {
            odom.update(Twist::new(0.0, 1.0, 0.0), 0.001);
        }
        assert!(
            close(odom.pose(), 1.5, 4.0, FRAC_PI_2, 1e-4),
            "{:?}",
            odom.pose()
        );
    }

    #[test]
    fn odometry_follows_a_circle_exactly_in_one_step_or_many() {
        // v = 1 m/s, ω = 1 rad/s: a circle of radius 1 m about (0, 1). Half a turn (π s)
        // ends at (0, 2) facing −x; a whole turn back at the start.
        let arc = Twist::new(1.0, 0.0, 1.0);
        let mut fine = Odometry::default();
        for _ in 0..3142 {
            fine.update(arc, PI / 3142.0);
        }
        assert!(close(fine.pose(), 0.0, 2.0, PI, 1e-3), "{:?}", fine.pose());
        let mut coarse = Odometry::default();
        assert!(coarse.update(arc, PI));
        assert!(
            close(coarse.pose(), 0.0, 2.0, PI, 1e-5),
            "{:?}",
            coarse.pose()
        );
        // A quarter turn in one step: (1, 1), where the midpoint rule would say (1.11, 1.11).
        let mut quarter = Odometry::default();
        quarter.update(arc, FRAC_PI_2);
        assert!(
            close(quarter.pose(), 1.0, 1.0, FRAC_PI_2, 1e-5),
            "{:?}",
            quarter.pose()
        );
        // Strafing right at 1 m/s while turning left at 1 rad/s: the world velocity is
        // (sin t, −cos t), so after π s the robot is at (2, 0), facing −x.
        let mut side = Odometry::default();
        side.update(Twist::new(0.0, -1.0, 1.0), PI);
        assert!(close(side.pose(), 2.0, 0.0, PI, 1e-5), "{:?}", side.pose());
    }

    #[test]
    fn odometry_with_a_gyro_turns_by_the_gyros_change_the_short_way() {
        // The gyro reads in its own frame (offset 1 rad) and wraps at ±π: only its change,
        // the shorter way round, turns the pose. A quarter circle of radius 1 in 1000 steps.
        let mut odom = Odometry::default();
        let n = 1000;
        let dt = FRAC_PI_2 / n as f32;
        assert!(odom.update_with_yaw(Twist::new(1.0, 0.0, 0.0), 3.0, dt)); // first: no turn
        let mut fresh = Odometry::default();
        fresh.update(Twist::new(1.0, 0.0, 0.0), dt);
        assert_eq!(odom.pose(), fresh.pose());
        for k in 1..=n {
            let yaw = wrap_rad_pi(3.0 + FRAC_PI_2 * k as f32 / n as f32); // crosses +π
            // The twist's ω (wrong on purpose) is ignored: the gyro turns the pose.
            assert!(odom.update_with_yaw(Twist::new(1.0, 0.0, -5.0), yaw, dt));
        }
        assert!(
            close(odom.pose(), 1.0 + dt, 1.0, FRAC_PI_2, 2e-3),
            "{:?}",
            odom.pose()
        );
    }

    #[test]
    fn odometry_is_exact_for_small_turns_and_does_not_count_a_turn_twice() {
        // One step turning by 2e-3 rad at 1 m/s for 1 s: a chord of the circle of radius
        // 500 m, x = 500·sin(0.002), y = 500·(1 − cos(0.002)) = 0.999999333, 0.000999999667.
        let mut odom = Odometry::default();
        odom.update(Twist::new(1.0, 0.0, 2e-3), 1.0);
        let p = odom.pose();
        assert!((p.x - 0.999_999_3).abs() < 1e-6, "{p:?}");
        assert!((p.y - 0.000_999_999_8).abs() < 1e-9, "{p:?}");
        // A gyro step, then a step on the wheels' ω, then the gyro again: the gyro's change
        // across the wheel step is not applied a second time.
        let mut mixed = Odometry::default();
        mixed.update_with_yaw(Twist::new(0.0, 0.0, 0.0), 0.0, 0.001);
        mixed.update(Twist::new(0.0, 0.0, 1.0), 0.5); // turns 0.5 rad
        mixed.update_with_yaw(Twist::new(0.0, 0.0, 0.0), 0.5, 0.001); // starts afresh
        assert!(
            (mixed.pose().theta_rad - 0.5).abs() < 1e-6,
            "{:?}",
            mixed.pose()
        );
    }

    #[test]
    fn odometry_refuses_bad_input_and_changes_nothing() {
        let mut odom = Odometry::new(Pose2D::new(1.0, 2.0, 7.0)); // heading wrapped
        assert!((odom.pose().theta_rad - (7.0 - TAU)).abs() < 1e-6);
        let before = odom.pose();
        assert!(!odom.update(Twist::new(f32::NAN, 0.0, 0.0), 0.001));
        assert!(!odom.update(Twist::new(1.0, 0.0, f32::INFINITY), 0.001));
        assert!(!odom.update(Twist::new(1.0, 0.0, 0.0), 0.0));
        assert!(!odom.update(Twist::new(1.0, 0.0, 0.0), f32::NAN));
        assert!(!odom.update_with_yaw(Twist::new(1.0, 0.0, 0.0), f32::NAN, 0.001));
        assert!(!odom.update_with_yaw(Twist::new(1.0, 0.0, 0.0), 0.5, 0.0));
        assert!(!odom.update_with_yaw(Twist::new(f32::NAN, 0.0, 0.0), 0.5, 0.001));
        assert!(!odom.update(Twist::new(f32::MAX, 0.0, 0.0), f32::MAX)); // off the map
        assert!(!odom.reset(Pose2D::new(f32::NAN, 0.0, 0.0)));
        assert_eq!(odom.pose(), before);
        assert!(odom.reset(Pose2D::new(0.0, 0.0, 0.0)));
        assert_eq!(odom.pose(), Pose2D::default());
    }

    fn rm_chassis() -> LinearChassis<4> {
        LinearChassis::mecanum(MecanumConfig::new(0.4, 0.36, 0.076)).unwrap()
    }

    fn rpm_of(rim_m_s: f32, r: f32) -> f32 {
        rim_m_s / r * 60.0 / TAU
    }

    #[test]
    fn mecanum_strafe_and_spin_match_hand_formula() {
        let c = rm_chassis();
        // Strafe left 1 m/s: FL −, FR +, RL +, RR − (O rollers).
        let w = c.wheel_rpm(Twist::new(0.0, 1.0, 0.0));
        let v = rpm_of(1.0, 0.076);
        for (got, want) in w.iter().zip([-v, v, v, -v]) {
            assert!((got - want).abs() < 1e-3, "{w:?}");
        }
        // Spin 1 rad/s: rim = ∓(a + b)·ω = ∓0.38 m/s: FL −, FR +, RL −, RR +.
        let w = c.wheel_rpm(Twist::new(0.0, 0.0, 1.0));
        let v = rpm_of(0.38, 0.076);
        for (got, want) in w.iter().zip([-v, v, -v, v]) {
            assert!((got - want).abs() < 1e-3, "{w:?}");
        }
    }

    #[test]
    fn x_rollers_mirror_the_strafe() {
        let o = rm_chassis().wheel_rpm(Twist::new(0.0, 1.0, 0.0));
        let x = LinearChassis::mecanum(
            MecanumConfig::new(0.4, 0.36, 0.076).with_rollers(MecanumRollers::X),
        )
        .unwrap()
        .wheel_rpm(Twist::new(0.0, 1.0, 0.0));
        for (a, b) in o.iter().zip(x) {
            assert!((a + b).abs() < 1e-3);
        }
    }

    #[test]
    fn wheel_signs_flip_mirrored_motors_both_ways() {
        let signed = LinearChassis::mecanum(
            MecanumConfig::new(0.4, 0.36, 0.076).with_wheel_signs([1.0, -1.0, 1.0, -1.0]),
        )
        .unwrap();
        let rpm = signed.wheel_rpm(Twist::new(1.0, 0.0, 0.0));
        assert!(rpm[0] > 0.0 && rpm[1] < 0.0);
        let back = signed.twist(&rpm);
        assert!((back.vx_m_s - 1.0).abs() < 1e-5);
    }

    #[test]
    fn omni_wheel_signs_flip_their_motors_and_odometry_undoes_them() {
        let c = omni::<4>(0.25, 0.05, FRAC_PI_4)
            .unwrap()
            .with_wheel_signs([1.0, 1.0, -1.0, -1.0])
            .unwrap();
        // Spinning at 1 rad/s: every rim at R·ω = 0.25 m/s, 47.75 rpm; wheels 3 and 4 turn
        // their motors the other way.
        let w = c.wheel_rpm(Twist::new(0.0, 0.0, 1.0));
        for (got, want) in w.iter().zip([47.75, 47.75, -47.75, -47.75]) {
            assert!((got - want).abs() < 0.01, "{w:?}");
        }
        let back = c.twist(&w);
        assert!((back.omega_rad_s - 1.0).abs() < 1e-4 && back.vx_m_s.abs() < 1e-4);
        assert_eq!(
            omni::<4>(0.25, 0.05, 0.0)
                .unwrap()
                .with_wheel_signs([1.0, 0.5, 1.0, 1.0]),
            Err(ChassisError::InvalidSign)
        );
    }

    #[test]
    fn omni3_forward_drives_all_three_wheels() {
        // Wheels at 90°, 210°, 330°: the wheel at 90° (left side) drives along −x.
        let c = omni::<3>(0.2, 0.05, FRAC_PI_2).unwrap();
        let w = c.wheel_rpm(Twist::new(1.0, 0.0, 0.0));
        // rim = −sin θ: −1, +0.5, +0.5 m/s.
        for (got, want) in w.iter().zip([-1.0, 0.5, 0.5]) {
            assert!((got - rpm_of(want, 0.05)).abs() < 1e-2, "{w:?}");
        }
    }

    #[test]
    fn saturation_scales_all_wheels_together() {
        let c = rm_chassis();
        let twist = Twist::new(3.0, 1.0, 2.0);
        let free = c.wheel_rpm(twist);
        let limited = c.wheel_rpm_limited(twist, 400.0);
        let peak = limited.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!((peak - 400.0).abs() < 1e-2);
        let k = limited[0] / free[0];
        for (l, f) in limited.iter().zip(free) {
            assert!((l - k * f).abs() < 1e-2, "ratios differ");
        }
        // The resulting twist points the same way, only slower.
        let t = c.twist(&limited);
        assert!((t.vy_m_s / t.vx_m_s - 1.0 / 3.0).abs() < 1e-4);
    }

    #[test]
    fn world_to_robot_by_yaw() {
        // Robot facing +y (yaw 90°): a world +y command is robot forward.
        let t = Twist::new(0.0, 1.0, 0.5).world_to_robot(FRAC_PI_2);
        assert!((t.vx_m_s - 1.0).abs() < 1e-6 && t.vy_m_s.abs() < 1e-6);
        assert_eq!(t.omega_rad_s, 0.5);
        let back = t.robot_to_world(FRAC_PI_2);
        assert!(back.vx_m_s.abs() < 1e-6 && (back.vy_m_s - 1.0).abs() < 1e-6);
    }

    #[test]
    fn swerve_reverses_wheel_instead_of_turning_more_than_90_degrees() {
        let s = Swerve::new(0.5, 0.5, 0.05).unwrap();
        let forward = s.modules(Twist::new(1.0, 0.0, 0.0), &[ModuleState::default(); 4]);
        assert!(
            forward
                .iter()
                .all(|m| m.steer_rad.abs() < 1e-6 && m.wheel_rpm > 0.0)
        );
        // Now backwards: modules at 0 keep 0 and run the wheel in reverse.
        let back = s.modules(Twist::new(-1.0, 0.0, 0.0), &forward);
        assert!(
            back.iter()
                .all(|m| m.steer_rad.abs() < 1e-6 && m.wheel_rpm < 0.0)
        );
        // Left: turn 90°, not −90° with reversal (both are 90° away; not more than 90°).
        let left = s.modules(Twist::new(0.0, 1.0, 0.0), &forward);
        assert!(
            left.iter()
                .all(|m| (m.steer_rad - FRAC_PI_2).abs() < 1e-5 && m.wheel_rpm > 0.0)
        );
    }

    #[test]
    fn swerve_stopped_keeps_angles() {
        let s = Swerve::new(0.5, 0.5, 0.05).unwrap();
        let turned = s.modules(Twist::new(0.0, 1.0, 0.0), &[ModuleState::default(); 4]);
        let stopped = s.modules(Twist::ZERO, &turned);
        for (a, b) in stopped.iter().zip(&turned) {
            assert_eq!(a.steer_rad, b.steer_rad);
            assert_eq!(a.wheel_rpm, 0.0);
        }
    }

    #[test]
    fn swerve_stopped_module_angle_is_brought_into_range() {
        let s = Swerve::new(0.5, 0.5, 0.05).unwrap();
        let steer = [4.0, -PI, 1.0, f32::NAN];
        let now = steer.map(|a| ModuleState {
            steer_rad: a,
            wheel_rpm: 0.0,
        });
        let out = s.modules(Twist::ZERO, &now);
        // 4 rad is 4 − 2π = −2.2832 rad; −π is the same heading as π, the range's end.
        assert!((out[0].steer_rad - (4.0 - TAU)).abs() < 1e-6);
        assert_eq!(out[1].steer_rad, PI);
        assert_eq!(out[2].steer_rad, 1.0);
        assert!(out[3].steer_rad.is_nan());
        assert!(out.iter().all(|m| m.wheel_rpm == 0.0));
    }

    #[test]
    fn swerve_twist_whose_wheel_speed_overflows_stops_every_wheel() {
        let s = Swerve::new(0.5, 0.5, 0.05).unwrap();
        let now = [ModuleState {
            steer_rad: 0.3,
            wheel_rpm: 100.0,
        }; 4];
        // 1e38 m/s on a 0.05 m wheel is 1.9e40 rpm: beyond f32. Before, the rpm was
        // infinite and the limited version's scale (500 / ∞ = 0) made it NaN.
        for out in [
            s.modules(Twist::new(1e38, 0.0, 0.0), &now),
            s.modules_limited(Twist::new(1e38, 0.0, 0.0), &now, 500.0),
            // Spinning at 3e38 rad/s: each module moves at 1.06e38 m/s (finite), 2e40 rpm.
            s.modules(Twist::new(0.0, 0.0, 3e38), &now),
        ] {
            for m in out {
                assert_eq!(m.wheel_rpm, 0.0);
                assert_eq!(m.steer_rad, 0.3);
            }
        }
    }

    #[test]
    fn limiter_keeps_direction_and_reaches_target() {
        let mut l = TwistLimiter::new(Twist::new(1.0, 1.0, 1.0));
        let mut out = Twist::ZERO;
        for _ in 0..30 {
            out = l.update(Twist::new(2.0, 1.0, 0.0), 0.1);
            if out.vx_m_s > 0.0 {
                assert!((out.vy_m_s / out.vx_m_s - 0.5).abs() < 1e-5);
            }
        }
        assert_eq!(out, Twist::new(2.0, 1.0, 0.0));
        assert_eq!(l.update(Twist::new(f32::NAN, 0.0, 0.0), 0.1), out);
    }

    #[test]
    fn limiter_lands_exactly_and_a_zero_limit_holds_every_axis() {
        // Within one step, the output is the target itself: 0.7 + (−0.001 − 0.7) in f32 is
        // not −0.001.
        let mut l = TwistLimiter::new(Twist::new(10.0, 10.0, 10.0));
        l.reset(Twist::new(0.7, 0.0, 0.0));
        assert_eq!(l.update(Twist::new(-0.001, 0.0, 0.0), 1.0).vx_m_s, -0.001);
        // A zero (or NaN) rotation limit: the whole change waits while ω must change, as
        // the docs say; a change that leaves ω alone goes ahead.
        let mut l = TwistLimiter::new(Twist::new(1.0, 1.0, f32::NAN));
        assert_eq!(l.update(Twist::new(1.0, 0.0, 0.1), 0.1), Twist::ZERO);
        let out = l.update(Twist::new(1.0, 0.0, 0.0), 0.1);
        assert!((out.vx_m_s - 0.1).abs() < 1e-6, "{out:?}");
    }

    #[test]
    fn wheel_signs_other_than_plus_or_minus_one_are_refused() {
        let rows = [[1.0, 0.0, 0.2], [0.0, 1.0, 0.2], [-1.0, 0.0, 0.2]];
        for bad in [0.0, 0.5, -2.0, f32::NAN] {
            assert_eq!(
                LinearChassis::<3>::from_rows(rows, 0.05, [1.0, bad, -1.0]).unwrap_err(),
                ChassisError::InvalidSign
            );
        }
        assert!(LinearChassis::<3>::from_rows(rows, 0.05, [1.0, -1.0, -1.0]).is_ok());
    }

    #[test]
    fn a_twist_too_large_for_f32_wheel_speeds_gives_zeros() {
        // 1e37 m/s on a wheel of 76 mm radius is about 1.3e39 rpm: beyond f32, so no wheel gets an
        // infinity (or, scaled to a limit, a NaN).
        let c = rm_chassis();
        assert_eq!(c.wheel_rpm(Twist::new(1e37, 0.0, 0.0)), [0.0; 4]);
        assert_eq!(
            c.wheel_rpm_limited(Twist::new(1e37, 0.0, 0.0), 500.0),
            [0.0; 4]
        );
    }

    #[test]
    fn bad_geometry_is_rejected() {
        assert_eq!(
            LinearChassis::mecanum(MecanumConfig::new(0.0, 0.36, 0.076)).unwrap_err(),
            ChassisError::InvalidDimension
        );
        // Two parallel omni wheels cannot tell rotation from translation.
        assert_eq!(
            LinearChassis::<2>::from_rows([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]], 0.05, [1.0; 2])
                .unwrap_err(),
            ChassisError::Singular
        );
        assert_eq!(
            rm_chassis().wheel_rpm(Twist::new(f32::NAN, 0.0, 0.0)),
            [0.0; 4]
        );
        // X rollers on a square chassis: every wheel's turning lever is a − b = 0.
        assert_eq!(
            LinearChassis::mecanum(
                MecanumConfig::new(0.4, 0.4, 0.076).with_rollers(MecanumRollers::X)
            )
            .unwrap_err(),
            ChassisError::Singular
        );
        // Nearly square (a − b = 5 mm): 1 rad/s needs a rim speed of only 5 mm/s, against
        // (a + b) = 0.395 m/s with O rollers.
        let x = LinearChassis::mecanum(
            MecanumConfig::new(0.4, 0.39, 0.076).with_rollers(MecanumRollers::X),
        )
        .unwrap();
        let rim_m_s =
            x.wheel_rpm(Twist::new(0.0, 0.0, 1.0))[0].abs() / 60.0 * core::f32::consts::TAU * 0.076;
        assert!((rim_m_s - 0.005).abs() < 1e-4, "{rim_m_s}");
    }

    proptest! {
        #[test]
        fn mecanum_forward_of_inverse_is_identity(vx in -4f32..4.0, vy in -4f32..4.0, w in -10f32..10.0) {
            let c = rm_chassis();
            let t = c.twist(&c.wheel_rpm(Twist::new(vx, vy, w)));
            prop_assert!((t.vx_m_s - vx).abs() < 1e-3 && (t.vy_m_s - vy).abs() < 1e-3);
            prop_assert!((t.omega_rad_s - w).abs() < 1e-3);
        }

        #[test]
        fn omni_forward_of_inverse_is_identity(vx in -4f32..4.0, vy in -4f32..4.0, w in -10f32..10.0) {
            let c3 = omni::<3>(0.2, 0.05, FRAC_PI_2).unwrap();
            let t = c3.twist(&c3.wheel_rpm(Twist::new(vx, vy, w)));
            prop_assert!((t.vx_m_s - vx).abs() < 1e-3 && (t.vy_m_s - vy).abs() < 1e-3);
            prop_assert!((t.omega_rad_s - w).abs() < 1e-3);
            let c4 = omni::<4>(0.25, 0.05, core::f32::consts::FRAC_PI_4).unwrap();
            let t = c4.twist(&c4.wheel_rpm(Twist::new(vx, vy, w)));
            prop_assert!((t.vx_m_s - vx).abs() < 1e-3 && (t.omega_rad_s - w).abs() < 1e-3);
        }

        #[test]
        fn swerve_forward_of_inverse_is_identity(vx in -4f32..4.0, vy in -4f32..4.0, w in -10f32..10.0) {
            let s = Swerve::new(0.5, 0.4, 0.05).unwrap();
            let m = s.modules(Twist::new(vx, vy, w), &[ModuleState::default(); 4]);
            let t = s.twist(&m);
            prop_assert!((t.vx_m_s - vx).abs() < 1e-3 && (t.vy_m_s - vy).abs() < 1e-3);
            prop_assert!((t.omega_rad_s - w).abs() < 1e-3);
            // Every module turned at most 90° from its start (0 rad).
            prop_assert!(m.iter().all(|x| x.steer_rad.abs() <= FRAC_PI_2 + 1e-5));
        }
    }
}
