//! Motors: the user-facing [`Motor`] trait, control modes, health (online/offline, thermal
//! derating) and the drivers (DJI, VESC, Damiao).
//!
//! # Sharing model
//!
//! A motor object is used at the same time by three kinds of task, possibly at different
//! priorities (an `InterruptExecutor` for the control loop is common):
//! - the scheduler task calls [`CanNode::update`](crate::node::CanNode::update) and
//!   [`CanNode::pack_command`](crate::node::CanNode::pack_command) every tick;
//! - the receiver task calls [`CanNode::update_feedback`](crate::node::CanNode::update_feedback)
//!   for each of its frames;
//! - application tasks call the [`Motor`] setters and getters.
//!
//! Every method takes `&self`. A driver keeps all its mutable state in one
//! `embassy_sync::blocking_mutex::Mutex<CriticalSectionRawMutex, RefCell<_>>`, locked for the
//! few dozen instructions of one call and never across an `.await` (there are no `.await`s in
//! these methods). On a single-core Cortex-M a critical section is `cpsid i` / `cpsie i`, so a
//! tick's lock traffic costs a handful of cycles per motor; in exchange there is no `unsafe`,
//! no `static mut` and no torn read (a reader sees rpm, angle and current from the same
//! feedback frame). Motors therefore live in plain `static`s or `StaticCell`s and are shared
//! as `&'static`.
//!
//! # Health
//!
//! A motor whose feedback has been silent for longer than
//! [`HealthConfig::offline_timeout`] (default 100 ms: a hundred DJI feedback periods, so
//! bursts of lost frames on a busy bus do not trip it, and short enough that a motor whose
//! power was cut by the referee system stops being driven at once) is **offline**: its command
//! is zero, its controllers are reset (no integral wound up while it was away), and
//! [`Motor::is_online`] says so. It comes back by itself with its next feedback frame; what
//! happens to the multi-turn angle then is set by [`MultiTurnOnReturn`].

pub mod cascade;
pub mod dji;
pub mod dm;
pub mod vesc;

use crate::encoder::GearRatio;
use crate::time::{Duration, Instant};
use core::fmt;

/// What a motor is asked to follow.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ControlMode {
    /// Zero command (the initial mode, and after [`Motor::disable`]).
    #[default]
    Disabled,
    /// Open-loop current (torque) command in amps. DJI motors also take torque targets this
    /// way ([`Motor::set_target_torque_nm`] converts through the torque constant).
    Current,
    /// Open-loop torque at the output shaft in N·m, for devices that take torque natively
    /// (Damiao MIT: also a raw MIT command set with `DmMotor::set_mit`).
    Torque,
    /// Open-loop voltage command: volts for a GM6020 in voltage mode, duty cycle (−1…1) for a
    /// VESC.
    Voltage,
    /// Output-shaft speed in rpm.
    Speed,
    /// Output-shaft angle within one turn in degrees, reached the shortest way round.
    Angle,
    /// Output-shaft multi-turn angle in degrees.
    TotalAngle,
}

/// Why a target was refused (the previous target stays in force).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TargetError {
    /// The target is NaN or infinite.
    NotFinite,
    /// This motor (or its current configuration) has no such mode, e.g. a current target for
    /// a GM6020 configured for voltage mode.
    Unsupported,
    /// The value is finite but outside what the device can do (a negative limit, or a Damiao
    /// total-angle target beyond the motor's position range).
    OutOfRange,
}

impl fmt::Display for TargetError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::NotFinite => "motor target is NaN or infinite",
            Self::Unsupported => "motor does not support this control mode",
            Self::OutOfRange => "motor target or limit out of the device's range",
        })
    }
}

impl core::error::Error for TargetError {}

/// Everything an application may want to read about a motor, from one consistent moment.
///
/// Every field means the same on every device. A quantity the device does not report, or has
/// not reported yet (no feedback since start), is `None`, never a made-up zero; the one
/// exception is `speed_rpm`, 0 until the first frame (`last_feedback` is `None` then).
///
/// `command` is in the unit the device is commanded in:
///
/// | device | `command` |
/// |---|---|
/// | DJI M3508 / M2006 / GM6020 in current mode | amps |
/// | DJI GM6020 in voltage mode | volts |
/// | VESC current or brake (brake negative) | amps |
/// | VESC duty, eRPM or position (the VESC runs the loop: no current is commanded) | 0 |
/// | Damiao MIT | N·m of feed-forward torque (the motor adds its kp/kd terms) |
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MotorState {
    /// Whether feedback arrived within the offline timeout. The measured fields below
    /// (speed, angles, current, temperature) are those of the last accepted frame: while
    /// offline they keep their last values, so check this (or `last_feedback`) before
    /// integrating a speed, for odometry say.
    pub online: bool,
    /// Current control mode.
    pub mode: ControlMode,
    /// The active target in the mode's unit (amps, N·m, volts, rpm or degrees; a DJI motor
    /// reports an angle-mode target wrapped into [0, 360), the others as given).
    pub target: f32,
    /// Output-shaft speed in rpm (0 before the first feedback: see `last_feedback`).
    pub speed_rpm: f32,
    /// Output-shaft angle within one turn, [0, 360) degrees, where the device reports one.
    pub angle_deg: Option<f32>,
    /// Output-shaft multi-turn angle in degrees, where the device reports one.
    pub total_angle_deg: Option<f32>,
    /// Measured torque current in amps, where the device reports a current (a Damiao motor
    /// reports torque instead: see its driver).
    pub current_amps: Option<f32>,
    /// Temperature in °C, where the device reports one (the hottest it reports: winding,
    /// rotor or MOSFET; see each driver).
    pub temperature_c: Option<f32>,
    /// The command applied last tick, after every clamp and derating, in the device's command
    /// unit (see the table above); zero while offline.
    pub command: f32,
    /// Times the motor went offline since start.
    pub offline_events: u32,
    /// Time of the last accepted feedback frame.
    pub last_feedback: Option<Instant>,
}

/// The user-facing side of a motor (RC10_LIB `Motor_Base`'s public API).
///
/// Setters only record a target (and switch mode); the scheduler does the work on its next
/// tick. Speeds and angles are of the output shaft.
pub trait Motor: Sync {
    /// Commands a torque current in amps (clamped to the ESC's range when packed).
    fn set_target_current(&self, amps: f32) -> Result<(), TargetError>;

    /// Commands a voltage in volts. Only voltage-mode devices support it.
    fn set_target_voltage(&self, volts: f32) -> Result<(), TargetError> {
        let _ = volts;
        Err(TargetError::Unsupported)
    }

    /// Holds an output-shaft speed in rpm.
    fn set_target_rpm(&self, rpm: f32) -> Result<(), TargetError>;

    /// Holds an output-shaft angle in degrees (any value; taken modulo 360 and reached the
    /// shortest way round).
    fn set_target_angle_deg(&self, angle_deg: f32) -> Result<(), TargetError>;

    /// Holds a multi-turn output-shaft angle in degrees.
    fn set_target_total_angle_deg(&self, angle_deg: f32) -> Result<(), TargetError>;

    /// Commands a torque at the output shaft in N·m: natively where the device takes torque
    /// (Damiao), through the torque constant where it takes current (DJI, VESC with a
    /// configured torque constant). The default reports [`TargetError::Unsupported`].
    fn set_target_torque_nm(&self, torque_nm: f32) -> Result<(), TargetError> {
        let _ = torque_nm;
        Err(TargetError::Unsupported)
    }

    /// A torque in N·m at the output shaft added to what the speed and angle loops command
    /// (gravity compensation for an arm or a gimbal pitch). Kept until changed; 0 removes it.
    /// Not added in open-loop modes. The default reports [`TargetError::Unsupported`].
    fn set_feed_forward_torque_nm(&self, torque_nm: f32) -> Result<(), TargetError> {
        let _ = torque_nm;
        Err(TargetError::Unsupported)
    }

    /// Limits the current the motor is commanded, in amps, from the next tick on (chassis
    /// power limiting): the ESC's own range still applies on top, and the loops' anti-windup
    /// works against the lower of the two. Negative is [`TargetError::OutOfRange`]; infinity
    /// means "the ESC's range". A device that runs its own loop limits only what rc10
    /// commands in amps: a VESC in speed, duty or position mode keeps the current limits set
    /// in VESC Tool. The default reports [`TargetError::Unsupported`].
    fn set_current_limit_amps(&self, amps: f32) -> Result<(), TargetError> {
        let _ = amps;
        Err(TargetError::Unsupported)
    }

    /// Homing: declares that the output shaft is at multi-turn angle `angle_deg` now (0 for
    /// "here is zero"). Applied by the next tick that has feedback; single-turn angles and
    /// total-angle targets refer to the new origin from then on. The default reports
    /// [`TargetError::Unsupported`].
    fn set_total_angle_here_deg(&self, angle_deg: f32) -> Result<(), TargetError> {
        let _ = angle_deg;
        Err(TargetError::Unsupported)
    }

    /// Stops driving the motor (zero command) until a new target is set.
    fn disable(&self);

    /// A consistent snapshot of the motor's state.
    fn state(&self) -> MotorState;

    /// Rotor turns per output turn.
    fn gear_ratio(&self) -> GearRatio;

    /// Output-shaft speed in rpm.
    fn speed_rpm(&self) -> f32 {
        self.state().speed_rpm
    }

    /// Output-shaft angle in [0, 360) degrees, where the device reports one.
    fn angle_deg(&self) -> Option<f32> {
        self.state().angle_deg
    }

    /// Output-shaft multi-turn angle in degrees, where the device reports one.
    fn total_angle_deg(&self) -> Option<f32> {
        self.state().total_angle_deg
    }

    /// Measured torque current in amps, where the device reports one.
    fn current_amps(&self) -> Option<f32> {
        self.state().current_amps
    }

    /// Temperature in °C, if the device reports one.
    fn temperature_c(&self) -> Option<f32> {
        self.state().temperature_c
    }

    /// The control mode.
    fn mode(&self) -> ControlMode {
        self.state().mode
    }

    /// Whether feedback is arriving.
    fn is_online(&self) -> bool {
        self.state().online
    }
}

/// What the multi-turn angle does when an offline motor's feedback returns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MultiTurnOnReturn {
    /// Continue counting from the last reading before the outage, assuming the rotor moved
    /// less than half a turn meanwhile (M3508: ±9.4° at the output). Right for a wheel or an
    /// arm that was held still while the ESC was unpowered; the default.
    #[default]
    Continue,
    /// Start again from the encoder origin, as after power-on (for a geared motor the total
    /// angle restarts at 0; for an absolute encoder it restarts at the true angle, within
    /// half a turn of its zero: for a GM6020 whose range lies within ±180° of its zero).
    Restart,
}

/// Temperature limits for devices that report a temperature.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ThermalLimits {
    /// At and above this temperature the command limit falls linearly…
    pub derate_start_c: f32,
    /// …to zero at this temperature and above.
    pub cutoff_c: f32,
}

impl ThermalLimits {
    /// The factor (0–1) applied to the command limit at `temperature_c`.
    pub fn derating(&self, temperature_c: f32) -> f32 {
        if !temperature_c.is_finite() {
            return 1.0;
        }
        if temperature_c >= self.cutoff_c {
            0.0
        } else if temperature_c <= self.derate_start_c {
            1.0
        } else {
            (self.cutoff_c - temperature_c) / (self.cutoff_c - self.derate_start_c)
        }
    }
}

/// Online/offline and thermal policy of a motor.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HealthConfig {
    /// Silence after which the motor is offline (default 100 ms).
    pub offline_timeout: Duration,
    /// Multi-turn angle policy when feedback returns.
    pub on_return: MultiTurnOnReturn,
    /// Thermal derating and cut-off, where the device reports a temperature.
    pub thermal: Option<ThermalLimits>,
}

impl HealthConfig {
    /// 100 ms offline timeout, continue multi-turn counting, no thermal limits.
    pub const DEFAULT: Self = Self {
        offline_timeout: Duration::from_millis(100),
        on_return: MultiTurnOnReturn::Continue,
        thermal: None,
    };

    /// Sets [`offline_timeout`](Self::offline_timeout).
    #[must_use]
    pub const fn with_offline_timeout(mut self, timeout: Duration) -> Self {
        self.offline_timeout = timeout;
        self
    }

    /// Sets [`thermal`](Self::thermal).
    #[must_use]
    pub const fn with_thermal(mut self, limits: Option<ThermalLimits>) -> Self {
        self.thermal = limits;
        self
    }

    /// Sets [`on_return`](Self::on_return).
    #[must_use]
    pub const fn with_on_return(mut self, policy: MultiTurnOnReturn) -> Self {
        self.on_return = policy;
        self
    }

    /// Whether feedback last seen at `last` still counts as online at `now`.
    pub fn is_online(&self, last: Option<Instant>, now: Instant) -> bool {
        match last {
            // A timestamp from the "future" (receiver stamped after the tick read the clock)
            // is fresh.
            Some(t) => now
                .checked_duration_since(t)
                .is_none_or(|elapsed| elapsed <= self.offline_timeout),
            None => false,
        }
    }
}

/// Online/offline bookkeeping shared by the drivers: when feedback last arrived, whether the
/// motor counts as online, and how often it went offline.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Liveness {
    last_feedback: Option<Instant>,
    online: bool,
    offline_events: u32,
}

impl Liveness {
    /// Never heard from, offline.
    pub const NEW: Self = Self {
        last_feedback: None,
        online: false,
        offline_events: 0,
    };

    /// Records accepted feedback received at `now` (the motor is online from the next check).
    /// A stamp before the last one (a transport that stamps frames itself and delivers one
    /// late) leaves the last one: the newest feedback decides, and the next frame's interval
    /// is measured from it.
    pub fn record_feedback(&mut self, now: Instant) {
        if self.last_feedback.is_none_or(|last| now > last) {
            self.last_feedback = Some(now);
        }
    }

    /// [`record_feedback`](Self::record_feedback) for a driver that has refused frames
    /// stamped before the last one (so `now` is not before it): one store on the 1 kHz path.
    pub(crate) fn record_feedback_in_order(&mut self, now: Instant) {
        self.last_feedback = Some(now);
    }

    /// Re-evaluates at `now` under `health`; returns `true` exactly when the motor has just
    /// gone offline (so the driver can zero its command and reset its loops once).
    ///
    /// A feedback time later than `now` (a receiver that stamped a frame after this tick
    /// read the clock, or a bogus timestamp far in the future) is clamped to `now`: it counts
    /// as fresh for one offline timeout, never longer.
    pub fn check(&mut self, health: &HealthConfig, now: Instant) -> bool {
        self.check_staleness(health, now, Duration::MAX).0
    }

    /// [`check`](Self::check), also telling whether the newest feedback is more than
    /// `stale_after` old at `now` (or there is none): `(went_offline, stale)`. The age is
    /// worked out once for both.
    #[inline(always)]
    pub(crate) fn check_staleness(
        &mut self,
        health: &HealthConfig,
        now: Instant,
        stale_after: Duration,
    ) -> (bool, bool) {
        let (went_offline, stale, _) = self.check_staleness_clamped(health, now, stale_after);
        (went_offline, stale)
    }

    /// [`check_staleness`](Self::check_staleness), also returning how far ahead of `now` the
    /// newest feedback time was, in ticks, when it was clamped to `now` (0 otherwise): for a
    /// driver that keeps other times relative to it.
    #[inline(always)]
    pub(crate) fn check_staleness_clamped(
        &mut self,
        health: &HealthConfig,
        now: Instant,
        stale_after: Duration,
    ) -> (bool, bool, u64) {
        let (online, stale, ahead) = match self.last_feedback {
            // A stamp at `now` or after it (clamped to `now`): fresh.
            Some(t) if t >= now => {
                self.last_feedback = Some(now);
                // `t ≥ now`: no wrap.
                (true, false, t.as_ticks().wrapping_sub(now.as_ticks()))
            }
            Some(t) => {
                // `t < now`: no wrap.
                let age = now.as_ticks().wrapping_sub(t.as_ticks());
                (
                    age <= health.offline_timeout.as_ticks(),
                    age > stale_after.as_ticks(),
                    0,
                )
            }
            None => (false, true, 0),
        };
        let went_offline = self.online && !online;
        if went_offline {
            self.offline_events = self.offline_events.wrapping_add(1);
        }
        self.online = online;
        (went_offline, stale, ahead)
    }

    /// Whether the motor was online at the last check.
    pub const fn is_online(&self) -> bool {
        self.online
    }

    /// Times the motor went offline.
    pub const fn offline_events(&self) -> u32 {
        self.offline_events
    }

    /// When feedback last arrived.
    pub const fn last_feedback(&self) -> Option<Instant> {
        self.last_feedback
    }
}

impl Default for HealthConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derating_is_linear_between_limits() {
        let t = ThermalLimits {
            derate_start_c: 100.0,
            cutoff_c: 120.0,
        };
        assert_eq!(t.derating(25.0), 1.0);
        assert_eq!(t.derating(110.0), 0.5);
        assert_eq!(t.derating(120.0), 0.0);
        assert_eq!(t.derating(150.0), 0.0);
        assert_eq!(t.derating(f32::NAN), 1.0);
    }

    #[test]
    fn liveness_reports_going_offline_once_and_counts_it() {
        let h = HealthConfig::DEFAULT;
        let mut l = Liveness::NEW;
        assert!(!l.check(&h, Instant::from_millis(0)));
        l.record_feedback(Instant::from_millis(1));
        assert!(!l.check(&h, Instant::from_millis(2)));
        assert!(l.is_online());
        assert!(l.check(&h, Instant::from_millis(200)));
        assert!(!l.check(&h, Instant::from_millis(300)));
        assert_eq!((l.is_online(), l.offline_events()), (false, 1));
    }

    #[test]
    fn a_stamp_older_than_the_last_one_does_not_move_the_last_feedback_back() {
        // A transport that stamps frames itself hands over a frame from 5 ms before the one
        // it already gave: the motor was heard from at 50 ms, not 45 ms (which would bring
        // the offline timeout 5 ms closer).
        let h = HealthConfig::DEFAULT;
        let mut l = Liveness::NEW;
        l.record_feedback(Instant::from_millis(50));
        l.record_feedback(Instant::from_millis(45));
        assert_eq!(l.last_feedback(), Some(Instant::from_millis(50)));
        assert!(!l.check(&h, Instant::from_millis(148)));
        assert!(l.is_online()); // 98 ms after 50 ms (103 ms after 45 ms)
        l.record_feedback(Instant::from_millis(149));
        assert_eq!(l.last_feedback(), Some(Instant::from_millis(149)));
    }

    #[test]
    fn feedback_stamped_far_in_the_future_does_not_keep_a_motor_online() {
        let h = HealthConfig::DEFAULT;
        let mut l = Liveness::NEW;
        let now = Instant::from_millis(1000);
        l.record_feedback(now + Duration::from_secs(3600)); // a bogus stamp an hour ahead
        assert!(!l.check(&h, now));
        assert!(l.is_online());
        assert_eq!(l.last_feedback(), Some(now)); // clamped
        // Nothing else arrives: offline one timeout later, not an hour later.
        assert!(l.check(&h, now + Duration::from_millis(101)));
        assert!(!l.is_online());
    }

    #[test]
    fn staleness_is_the_age_of_the_newest_stamp_beyond_the_threshold() {
        let h = HealthConfig::DEFAULT;
        let after = Duration::from_millis(3);
        let mut l = Liveness::NEW;
        // Never heard from: offline and stale.
        assert_eq!(
            l.check_staleness(&h, Instant::from_millis(5), after),
            (false, true)
        );
        l.record_feedback(Instant::from_millis(10));
        let at = |us: u64| Instant::from_micros(10_000 + us);
        // Exactly 3 ms old is fresh, 1 µs more is stale; online either way.
        assert_eq!(l.check_staleness(&h, at(3000), after), (false, false));
        assert_eq!(l.check_staleness(&h, at(3001), after), (false, true));
        assert!(l.is_online());
        // Offline at 100 ms + 1 µs, as `check` says, and stale.
        assert_eq!(l.check_staleness(&h, at(100_000), after), (false, true));
        assert_eq!(l.check_staleness(&h, at(100_001), after), (true, true));
        assert_eq!(l.offline_events(), 1);
        // A stamp ahead of `now` is clamped to it: fresh, then ages from `now`.
        let now = Instant::from_millis(500);
        l.record_feedback(now + Duration::from_secs(60));
        assert_eq!(l.check_staleness(&h, now, after), (false, false));
        assert!(l.is_online());
        assert_eq!(
            l.check_staleness(&h, now + Duration::from_micros(3001), after),
            (false, true)
        );
    }

    #[test]
    fn online_window_is_inclusive_of_timeout() {
        let h = HealthConfig::DEFAULT;
        let t0 = Instant::from_millis(1000);
        assert!(!h.is_online(None, t0));
        assert!(h.is_online(Some(t0), Instant::from_millis(1100)));
        assert!(!h.is_online(Some(t0), Instant::from_millis(1101)));
        assert!(h.is_online(Some(Instant::from_millis(1200)), t0));
    }
}
