//! The angle → speed → command cascade that runs on the MCU for motors whose ESC takes a
//! current or voltage command (DJI). Reusable by user-written motors.
//!
//! - Speed mode: the speed loop turns rpm error into the command (amps or volts).
//! - Angle / total-angle mode: the angle loop, run every `angle_divider` ticks (RC10_LIB: every
//!   10th), turns degrees of error into a speed target for the speed loop. Angle mode uses a
//!   circular error (shortest way round); total-angle mode a linear one.
//! - Mode switches are bumpless: a loop that takes over starts from the command the motor
//!   really received last tick (after the limit in force: ESC range, thermal derating, a
//!   user's current limit), so the output does not jump; a loop that is left is reset.
//! - The limit in force is an argument of every [`Cascade::step`]: the output never exceeds
//!   it and the speed loop's anti-windup works against it.
//! - A feed-forward (command units) is added by the speed loop in speed and angle modes.
//! - While the feedback is stale ([`Measured::stale`]) both loops hold their integrals.
//! - While the speed loop's output is held at its limit, the angle loop does not integrate an
//!   error that would push it further there (the motor cannot follow a higher speed target:
//!   integrating would only wind the angle loop up, and the angle would overshoot once the
//!   motor is free); an error the other way still integrates.

use super::ControlMode;
use crate::math::{saturate, wrap_deg_360};
use crate::pid::{ErrorMode, Integrate, Pid, PidConfig, PidConfigError, PidTerms};

/// Gains and structure of a [`Cascade`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CascadeConfig {
    /// Speed loop: rpm in, command (amps or volts) out. Its output limit is the command limit.
    pub speed: PidConfig,
    /// Angle loop: degrees in, rpm out. Its error mode is set by the cascade (circular for
    /// angle mode, linear for total-angle mode).
    pub angle: PidConfig,
    /// The angle loop runs every this many ticks (1 = every tick; 0 is treated as 1).
    pub angle_divider: u8,
}

/// What the cascade measures each tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Measured {
    /// Output-shaft speed in rpm.
    pub speed_rpm: f32,
    /// Output-shaft angle in [0, 360) degrees. Read only on ticks when
    /// [`Cascade::angle_loop_due`].
    pub angle_deg: f32,
    /// Output-shaft multi-turn angle in degrees. Read only on ticks when
    /// [`Cascade::angle_loop_due`].
    pub total_angle_deg: f32,
    /// The readings are stale: feedback frames have stopped coming for longer than the
    /// device's feedback period allows (lost frames, a stalled receive path), and the motor
    /// is not yet offline. Both loops then hold their integrals where they are (still within
    /// the limits in force): integrating an error whose measurement no longer changes winds
    /// the loop up by whatever the reading missed, and that has to unwind once feedback
    /// returns. Proportional and derivative terms, feed-forward, targets, mode switches and
    /// limits all act as usual. An angle step on stale readings holds the angle loop's
    /// integral for its whole interval. [`DjiMotor`](super::dji::DjiMotor) sets it once its
    /// newest frame is more than 3 ms (three feedback periods) old.
    pub stale: bool,
}

/// The cascade's state: mode, target and the two loops.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cascade {
    config: CascadeConfig,
    mode: ControlMode,
    target: f32,
    speed: Pid,
    angle: Pid,
    ticks_since_angle: u8,
    angle_dt_s: f32,
    speed_target_rpm: f32,
    feed_forward: f32,
    output: f32,
    /// Whether `output` reached the motor: a step ran since the cascade was built, reset
    /// (offline) or disabled.
    applied: bool,
}

impl Cascade {
    /// A disabled cascade, or why a loop's configuration cannot work.
    pub const fn new(config: CascadeConfig) -> Result<Self, PidConfigError> {
        let speed = match Pid::new(config.speed) {
            Ok(p) => p,
            Err(e) => return Err(e),
        };
        let angle = match Pid::new(config.angle.with_error_mode(ErrorMode::DEGREES)) {
            Ok(p) => p,
            Err(e) => return Err(e),
        };
        Ok(Self {
            config,
            mode: ControlMode::Disabled,
            target: 0.0,
            speed,
            angle,
            ticks_since_angle: 0,
            angle_dt_s: 0.0,
            speed_target_rpm: 0.0,
            feed_forward: 0.0,
            output: 0.0,
            applied: false,
        })
    }

    /// The configuration.
    pub const fn config(&self) -> &CascadeConfig {
        &self.config
    }

    /// The mode.
    pub const fn mode(&self) -> ControlMode {
        self.mode
    }

    /// The target in the mode's unit.
    pub const fn target(&self) -> f32 {
        self.target
    }

    /// The speed target the angle loop produced last (rpm), or the speed target in speed mode.
    pub const fn speed_target_rpm(&self) -> f32 {
        self.speed_target_rpm
    }

    /// The speed loop's last per-term output (for tuning).
    pub const fn speed_terms(&self) -> PidTerms {
        self.speed.last_terms()
    }

    /// The angle loop's last per-term output (for tuning).
    pub const fn angle_terms(&self) -> PidTerms {
        self.angle.last_terms()
    }

    /// The command the last [`step`](Self::step) returned (what was applied).
    pub const fn output(&self) -> f32 {
        self.output
    }

    /// The feed-forward in command units (amps or volts).
    pub const fn feed_forward(&self) -> f32 {
        self.feed_forward
    }

    /// Sets the feed-forward in command units, added by the speed loop in speed and angle
    /// modes (not in open-loop modes). A non-finite value is ignored.
    pub fn set_feed_forward(&mut self, command: f32) {
        if command.is_finite() {
            self.feed_forward = command;
        }
    }

    /// Replaces the speed loop's configuration while running (live tuning), keeping its
    /// integral; its output limit is the command limit. Unchanged on error.
    pub fn set_speed_config(&mut self, speed: PidConfig) -> Result<(), PidConfigError> {
        self.speed.set_config(speed)?;
        self.config.speed = speed;
        Ok(())
    }

    /// Replaces the angle loop's configuration while running (its error mode stays the one
    /// the present mode needs). Unchanged on error.
    pub fn set_angle_config(&mut self, angle: PidConfig) -> Result<(), PidConfigError> {
        let mode = self.angle.config().error_mode;
        self.angle.set_config(angle.with_error_mode(mode))?;
        self.config.angle = angle;
        Ok(())
    }

    /// Whether the next [`step`](Self::step) runs the angle loop, i.e. reads
    /// [`Measured::angle_deg`] or [`Measured::total_angle_deg`]. On other ticks a motor may
    /// leave them at zero and skip computing them (an encoder's angles cost a 64-bit
    /// division): in angle mode with the default divider, nine ticks in ten.
    pub fn angle_loop_due(&self) -> bool {
        matches!(self.mode, ControlMode::Angle | ControlMode::TotalAngle)
            && self.ticks_since_angle.saturating_add(1) >= self.config.angle_divider.max(1)
    }

    /// Sets the angle loop's divider (0 is treated as 1).
    pub fn set_angle_divider(&mut self, divider: u8) {
        self.config.angle_divider = divider;
    }

    /// Sets mode and target. A change of mode resets the loops that start working, preloading
    /// the speed loop with the command applied last tick (bumpless). The target must be finite
    /// (callers check; a non-finite target is ignored here).
    pub fn set_target(&mut self, mode: ControlMode, target: f32) {
        if !target.is_finite() {
            return;
        }
        let target = if mode == ControlMode::Angle {
            wrap_deg_360(target)
        } else {
            target
        };
        if mode != self.mode {
            let uses_speed = |m: ControlMode| {
                matches!(
                    m,
                    ControlMode::Speed | ControlMode::Angle | ControlMode::TotalAngle
                )
            };
            if uses_speed(mode) && !uses_speed(self.mode) {
                self.speed.reset();
                // From an open-loop mode, start at what the motor really got (already within
                // the limit that was in force): at zero error the output is integral +
                // feed-forward. From Disabled, or while nothing has been applied since the
                // motor came (back) online, start from the feed-forward alone (e.g. holding
                // an arm against gravity at once).
                if self.applied {
                    self.speed.set_integral(self.output - self.feed_forward);
                }
            }
            if matches!(mode, ControlMode::Angle | ControlMode::TotalAngle) {
                let error_mode = if mode == ControlMode::Angle {
                    ErrorMode::DEGREES
                } else {
                    ErrorMode::Linear
                };
                // Same gains, new error mode: cannot fail, the gains were validated.
                let _ = self
                    .angle
                    .set_config(self.config.angle.with_error_mode(error_mode));
                self.angle.reset();
                // Run the angle loop on the first tick in the new mode.
                self.ticks_since_angle = u8::MAX;
                self.angle_dt_s = 0.0;
            }
            if mode == ControlMode::Disabled {
                self.output = 0.0;
                self.applied = false;
            }
            self.mode = mode;
        }
        self.target = target;
    }

    /// The angle readings jumped without the shaft moving (its origin was moved: re-homing):
    /// the angle loop forgets its error and measurement history, so the jump is not taken as
    /// motion (a derivative kick for one angle step); its integral and the speed loop stay.
    pub fn angle_origin_moved(&mut self) {
        self.angle.forget_history();
    }

    /// Forgets loop history and the present command (used when the motor goes offline); mode
    /// and target stay.
    pub fn reset(&mut self) {
        self.speed.reset();
        self.angle.reset();
        self.output = 0.0;
        self.applied = false;
        self.speed_target_rpm = 0.0;
        self.ticks_since_angle = u8::MAX;
        self.angle_dt_s = 0.0;
    }

    /// One tick: returns the command (amps or volts) to apply, within `±limit` (the limit in
    /// force: the ESC's range after derating and any user limit; NaN or negative counts as
    /// zero) and, in closed-loop modes, within the speed loop's own output limit. In current /
    /// voltage / torque mode the target is passed through, clamped.
    pub fn step(&mut self, m: &Measured, dt_s: f32, limit: f32) -> f32 {
        let speed_target_rpm = match self.mode {
            ControlMode::Disabled => {
                self.output = 0.0;
                return 0.0;
            }
            ControlMode::Current | ControlMode::Voltage | ControlMode::Torque => {
                // A NaN or negative limit counts as zero (the speed loop does the same).
                self.output = saturate(self.target, if limit > 0.0 { limit } else { 0.0 });
                self.applied = true;
                return self.output;
            }
            ControlMode::Speed => self.target,
            ControlMode::Angle | ControlMode::TotalAngle => {
                self.angle_dt_s += dt_s;
                let divider = self.config.angle_divider.max(1);
                self.ticks_since_angle = self.ticks_since_angle.saturating_add(1);
                if self.ticks_since_angle >= divider {
                    let measured = if self.mode == ControlMode::Angle {
                        m.angle_deg
                    } else {
                        m.total_angle_deg
                    };
                    // Every `angle_divider` ticks: the general entry point (its finiteness
                    // checks cost nothing that matters here).
                    let ways = self.angle_may_integrate(m.stale);
                    self.speed_target_rpm = self.angle.output_integrating(
                        self.target,
                        measured,
                        0.0,
                        self.angle_dt_s,
                        f32::INFINITY,
                        ways,
                    );
                    self.ticks_since_angle = 0;
                    self.angle_dt_s = 0.0;
                }
                self.speed_target_rpm
            }
        };
        // One call site for the speed loop, in speed and angle modes alike. Its target is
        // finite (the target's setter refuses anything else, and the angle loop's output is
        // finite) and so is the feed-forward: only the measurement is checked.
        self.speed_target_rpm = speed_target_rpm;
        self.output = self.speed.output_within_finite_target(
            speed_target_rpm,
            m.speed_rpm,
            self.feed_forward,
            dt_s,
            limit,
            !m.stale,
        );
        self.applied = true;
        self.output
    }

    /// Which ways the angle loop may move its integral this step. Neither on stale readings.
    /// Otherwise not the way that winds it up: when the speed loop held its output at its
    /// limit last tick, a larger speed target the same way cannot be followed (the motor is
    /// at its current limit: accelerating, pushing a load it cannot move, stalled), so an
    /// integral growing towards it would only collect the error the motor cannot close, and
    /// the angle would overshoot by it once the motor is free again. It may still move the
    /// other way (unwinding).
    ///
    /// A higher speed target moves the speed loop's output with the sign of its `kp` (of its
    /// `ki` when `kp` is 0); the angle integral moves the speed target one for one.
    fn angle_may_integrate(&self, stale: bool) -> Integrate {
        if stale {
            return Integrate::NOT;
        }
        if self.angle.config().ki == 0.0 {
            // Nothing to integrate (the default angle loops): skip the test.
            return Integrate::FREELY;
        }
        let held = self.speed.last_clamp();
        if held == 0 {
            return Integrate::FREELY;
        }
        let speed = self.speed.config();
        let gain = if speed.kp != 0.0 { speed.kp } else { speed.ki };
        // Exact (`held` is ±1): positive when a higher speed target pushes the output further
        // into the limit it is held at, negative when a lower one does; 0 when the target
        // moves nothing (no kp, no ki: feed-forward alone).
        let into_limit = f32::from(held) * gain;
        if into_limit > 0.0 {
            Integrate::NOT_UP
        } else if into_limit < 0.0 {
            Integrate::NOT_DOWN
        } else {
            Integrate::FREELY
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cascade() -> Cascade {
        Cascade::new(CascadeConfig {
            speed: PidConfig::new(0.1, 10.0, 0.0).with_output_limit(20.0),
            angle: PidConfig::new(10.0, 0.0, 0.0).with_output_limit(300.0),
            angle_divider: 10,
        })
        .unwrap()
    }

    #[test]
    fn speed_mode_outputs_speed_loop() {
        let mut c = cascade();
        c.set_target(ControlMode::Speed, 100.0);
        // p = 0.1·100 = 10; i = 10·100·0.001 = 1 (first trapezoid step uses e for both ends).
        let out = c.step(&Measured::default(), 0.001, 20.0);
        assert!((out - 11.0).abs() < 1e-4, "{out}");
    }

    #[test]
    fn open_loop_modes_take_a_nan_or_negative_limit_as_zero() {
        // `saturate` alone would read a NaN limit as "no limit" and a negative one by its
        // magnitude: the limit in force must never let a command through that way.
        let mut c = cascade();
        c.set_target(ControlMode::Current, 5.0);
        assert_eq!(c.step(&Measured::default(), 0.001, 20.0), 5.0);
        assert_eq!(c.step(&Measured::default(), 0.001, f32::NAN), 0.0);
        assert_eq!(c.step(&Measured::default(), 0.001, -10.0), 0.0);
        assert_eq!(c.step(&Measured::default(), 0.001, 2.0), 2.0);
        // The speed loop applies the same rule.
        c.set_target(ControlMode::Speed, 100.0);
        assert_eq!(c.step(&Measured::default(), 0.001, f32::NAN), 0.0);
        assert_eq!(c.step(&Measured::default(), 0.001, -10.0), 0.0);
    }

    #[test]
    fn switch_from_current_to_speed_is_bumpless() {
        let mut c = cascade();
        c.set_target(ControlMode::Current, 5.0);
        assert_eq!(c.step(&Measured::default(), 0.001, 20.0), 5.0);
        // Speed target equal to the measured speed: the output must stay at 5 A.
        c.set_target(ControlMode::Speed, 50.0);
        let m = Measured {
            speed_rpm: 50.0,
            ..Default::default()
        };
        assert!((c.step(&m, 0.001, 20.0) - 5.0).abs() < 1e-6);
    }

    #[test]
    fn switch_to_speed_preloads_what_was_applied_not_the_unclamped_target() {
        // 100 A asked in current mode is clamped to the ESC's 20 A. Switching to a speed target
        // equal to the present speed starts the loop from the 20 A really applied, so as soon
        // as the motor runs faster than the target the current falls. (Preloaded with the
        // unclamped 100 A, the loop would hold 20 A until 80 A of integral had unwound: a
        // runaway.)
        let mut c = cascade();
        c.set_target(ControlMode::Current, 100.0);
        assert_eq!(c.step(&Measured::default(), 0.001, 20.0), 20.0);
        c.set_target(ControlMode::Speed, 0.0);
        assert_eq!(c.speed.integral(), 20.0);
        let too_fast = Measured {
            speed_rpm: 50.0,
            ..Default::default()
        };
        // p = 0.1 A/rpm · -50 rpm = -5 A on top of the 20 A held.
        let out = c.step(&too_fast, 0.001, 20.0);
        assert!(out < 15.5, "{out}");
        // Derated to 5 A: the command is within 5 A and so is the integral.
        let out = c.step(&Measured::default(), 0.001, 5.0);
        assert!(out <= 5.0);
        assert!(c.speed.integral() <= 5.0);
    }

    #[test]
    fn switch_after_derated_current_preloads_the_derated_value() {
        let mut c = cascade();
        c.set_target(ControlMode::Current, 15.0);
        assert_eq!(c.step(&Measured::default(), 0.001, 6.0), 6.0); // derated
        c.set_target(ControlMode::Speed, 0.0);
        let out = c.step(&Measured::default(), 0.001, 20.0);
        assert!((out - 6.0).abs() < 1e-6, "{out}");
    }

    #[test]
    fn feed_forward_adds_in_closed_loop_modes_only() {
        let mut c = cascade();
        c.set_feed_forward(2.0);
        c.set_target(ControlMode::Speed, 0.0);
        assert!((c.step(&Measured::default(), 0.001, 20.0) - 2.0).abs() < 1e-6);
        c.set_target(ControlMode::Angle, 0.0);
        assert!((c.step(&Measured::default(), 0.001, 20.0) - 2.0).abs() < 1e-6);
        c.set_target(ControlMode::Current, 1.0);
        assert_eq!(c.step(&Measured::default(), 0.001, 20.0), 1.0);
        // Bumpless into speed mode with a feed-forward: still 1 A at zero error.
        c.set_target(ControlMode::Speed, 0.0);
        assert!((c.step(&Measured::default(), 0.001, 20.0) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn a_mode_switch_while_nothing_is_applied_starts_from_the_feed_forward() {
        // Holding an arm against gravity: 2 A of feed-forward. The motor goes offline
        // (`reset`) in current mode and the application switches to speed mode meanwhile:
        // back online, at zero error, the arm gets its 2 A at once, as from Disabled (it got
        // 0 A offline: starting from that would cancel the feed-forward).
        let mut c = cascade();
        c.set_feed_forward(2.0);
        c.set_target(ControlMode::Current, 1.0);
        assert_eq!(c.step(&Measured::default(), 0.001, 20.0), 1.0);
        c.reset();
        c.set_target(ControlMode::Speed, 0.0);
        assert!((c.step(&Measured::default(), 0.001, 20.0) - 2.0).abs() < 1e-6);
        // The same before the first step ever (a motor not yet online).
        let mut c = cascade();
        c.set_feed_forward(2.0);
        c.set_target(ControlMode::Current, 1.0);
        c.set_target(ControlMode::Speed, 0.0);
        assert!((c.step(&Measured::default(), 0.001, 20.0) - 2.0).abs() < 1e-6);
    }

    #[test]
    fn stale_readings_hold_both_integrals_while_everything_else_acts() {
        let mut c = angle_cascade();
        let fresh = Measured::default();
        let stale = Measured {
            stale: true,
            ..Default::default()
        };
        c.set_target(ControlMode::Speed, 10.0);
        // p = 0.1·10 = 1, i = 10·10·0.001 = 0.1.
        assert!((c.step(&fresh, 0.001, 20.0) - 1.1).abs() < 1e-6);
        // Stale for 50 ticks: the integral stays at 0.1 (integrating would add 0.1 a tick).
        for _ in 0..50 {
            assert!((c.step(&stale, 0.001, 20.0) - 1.1).abs() < 1e-6);
        }
        assert!((c.speed.integral() - 0.1).abs() < 1e-7);
        // A new target acts at once through P (0.1·30 = 3), and so does a lower limit.
        c.set_target(ControlMode::Speed, 30.0);
        assert!((c.step(&stale, 0.001, 20.0) - 3.1).abs() < 1e-6);
        assert_eq!(c.step(&stale, 0.001, 2.0), 2.0);
        // Fresh again: integration resumes from the held value, 0.1 + 10·30·0.001 = 0.4.
        assert!((c.step(&fresh, 0.001, 20.0) - 3.4).abs() < 1e-5);
        // The angle loop too: 10° of error, p = 100 rpm, i = 2·10·0.001 = 0.02 rpm.
        c.set_target(ControlMode::TotalAngle, 10.0);
        c.step(&fresh, 0.001, 20.0);
        assert!((c.speed_target_rpm() - 100.02).abs() < 1e-4);
        for _ in 0..20 {
            c.step(&stale, 0.001, 20.0);
            assert!((c.speed_target_rpm() - 100.02).abs() < 1e-4);
        }
        c.step(&fresh, 0.001, 20.0);
        assert!((c.speed_target_rpm() - 100.04).abs() < 1e-4);
    }

    /// An integrating angle loop (kp 10, ki 2, ±300 rpm) run every tick over `speed`.
    fn angle_cascade_over(speed: PidConfig) -> Cascade {
        Cascade::new(CascadeConfig {
            speed: speed.with_output_limit(20.0),
            angle: PidConfig::new(10.0, 2.0, 0.0).with_output_limit(300.0),
            angle_divider: 1,
        })
        .unwrap()
    }

    fn angle_cascade() -> Cascade {
        angle_cascade_over(PidConfig::new(0.1, 10.0, 0.0))
    }

    #[test]
    fn the_angle_loop_does_not_wind_up_while_the_speed_loop_is_held_at_its_limit() {
        let mut c = angle_cascade();
        let still = Measured::default();
        c.set_target(ControlMode::TotalAngle, 10.0);
        // First tick: 10° of error, p = 100 rpm, i = 2·10·0.001 = 0.02 rpm. The speed loop
        // asks 0.1·100.02 = 10 A of a 0.5 A limit: held at +0.5 A.
        assert_eq!(c.step(&still, 0.001, 0.5), 0.5);
        assert!((c.speed_target_rpm() - 100.02).abs() < 1e-4);
        // A stalled shaft for 100 ms: integrating would add 0.02 rpm a tick (102 rpm at the
        // end, and 2 rpm more to unwind once it moves); held, it stays at 100.02.
        for _ in 0..100 {
            assert_eq!(c.step(&still, 0.001, 0.5), 0.5);
            assert!((c.speed_target_rpm() - 100.02).abs() < 1e-4);
        }
        // The limit lifted: the speed loop is no longer held (0.1·100.02 + 10·100.02·0.001 ≈
        // 11 A of 20), and integration resumes on the next angle step.
        c.step(&still, 0.001, 20.0);
        assert!((c.speed_target_rpm() - 100.02).abs() < 1e-4);
        c.step(&still, 0.001, 20.0);
        assert!((c.speed_target_rpm() - 100.04).abs() < 1e-4);
    }

    #[test]
    fn the_angle_loop_still_integrates_an_error_that_unwinds_the_speed_loop() {
        let mut c = angle_cascade();
        // Angle error −10° while the shaft still runs at −1000 rpm: the speed target is
        // −100.02 rpm, the speed error +899.98 rpm, the speed loop held at +0.5 A. The angle
        // integral moves the speed target down, the speed loop's output with it: away from
        // the limit it is held at. It integrates, −0.02 rpm a tick.
        let running = Measured {
            speed_rpm: -1000.0,
            ..Default::default()
        };
        c.set_target(ControlMode::TotalAngle, -10.0);
        for _ in 0..10 {
            assert_eq!(c.step(&running, 0.001, 0.5), 0.5);
        }
        assert!((c.speed_target_rpm() + 100.2).abs() < 1e-4);
    }

    #[test]
    fn in_angle_mode_the_hold_follows_the_error_the_short_way_round() {
        let mut c = angle_cascade();
        // Target 350°, shaft at 10°: the error is −20° (the short way), not +340°. p = −200
        // rpm, i = −0.04 rpm; the speed loop asks −20 A of 0.5: held at −0.5 A. Integrating
        // the −20° error would push it further down: held at −200.04 rpm.
        let at_10 = Measured {
            angle_deg: 10.0,
            ..Default::default()
        };
        c.set_target(ControlMode::Angle, 350.0);
        for _ in 0..20 {
            assert_eq!(c.step(&at_10, 0.001, 0.5), -0.5);
            assert!((c.speed_target_rpm() + 200.04).abs() < 1e-3);
        }
    }

    #[test]
    fn the_wind_up_check_follows_a_speed_loop_with_negative_gains() {
        // A speed loop wired the other way round (negative gains: more speed target, less
        // command). 10° of error: speed target 100.02 rpm, command −0.1·100.02 ≈ −10 A, held
        // at −0.5 A; a higher speed target pushes it further down: the integral holds.
        let mut c = angle_cascade_over(PidConfig::new(-0.1, -10.0, 0.0));
        c.set_target(ControlMode::TotalAngle, 10.0);
        for _ in 0..20 {
            assert_eq!(c.step(&Measured::default(), 0.001, 0.5), -0.5);
            assert!((c.speed_target_rpm() - 100.02).abs() < 1e-4);
        }
        // The mirror: −10°, speed target −100.02 rpm, command +10 A held at +0.5 A; a lower
        // speed target pushes it further up: the integral holds at −0.02 rpm.
        c.set_target(ControlMode::Disabled, 0.0);
        c.set_target(ControlMode::TotalAngle, -10.0);
        for _ in 0..20 {
            assert_eq!(c.step(&Measured::default(), 0.001, 0.5), 0.5);
            assert!((c.speed_target_rpm() + 100.02).abs() < 1e-4);
        }
    }

    #[test]
    fn the_wind_up_check_reads_the_speed_loops_ki_when_it_has_no_kp() {
        // An I-only speed loop with 1 A of feed-forward against a 0.5 A limit: held at +0.5 A
        // from the first tick (its integral cannot grow either). A higher speed target would
        // push it further through ki = 10 > 0: the angle integral holds at 0.02 rpm.
        let mut c = angle_cascade_over(PidConfig::new(0.0, 10.0, 0.0));
        c.set_feed_forward(1.0);
        c.set_target(ControlMode::TotalAngle, 10.0);
        for _ in 0..20 {
            assert_eq!(c.step(&Measured::default(), 0.001, 0.5), 0.5);
            assert!((c.speed_target_rpm() - 100.02).abs() < 1e-4);
        }
    }

    #[test]
    fn a_speed_loop_without_gains_does_not_stop_the_angle_integral() {
        // Feed-forward alone (1 A against 0.5 A: held high): the speed target moves nothing,
        // so the angle loop integrates as usual, 0.02 rpm a tick.
        let mut c = angle_cascade_over(PidConfig::new(0.0, 0.0, 0.0));
        c.set_feed_forward(1.0);
        c.set_target(ControlMode::TotalAngle, 10.0);
        for _ in 0..10 {
            assert_eq!(c.step(&Measured::default(), 0.001, 0.5), 0.5);
        }
        assert!((c.speed_target_rpm() - 100.2).abs() < 1e-4);
        // And the other way: −10°, the integral falls 0.02 rpm a tick.
        c.set_target(ControlMode::Disabled, 0.0);
        c.set_target(ControlMode::TotalAngle, -10.0);
        for _ in 0..10 {
            assert_eq!(c.step(&Measured::default(), 0.001, 0.5), 0.5);
        }
        assert!((c.speed_target_rpm() + 100.2).abs() < 1e-4);
    }

    #[test]
    fn live_gain_change_keeps_the_integral() {
        let mut c = cascade();
        c.set_target(ControlMode::Speed, 10.0);
        for _ in 0..10 {
            c.step(&Measured::default(), 0.001, 20.0);
        }
        let held = c.speed.integral();
        c.set_speed_config(PidConfig::new(0.0, 10.0, 0.0).with_output_limit(20.0))
            .unwrap();
        assert_eq!(c.speed.integral(), held);
        // kp is now 0: the output is the integral (plus this step's increment).
        let out = c.step(&Measured::default(), 0.001, 20.0);
        assert!((out - (held + 10.0 * 10.0 * 0.001)).abs() < 1e-5, "{out}");
        assert!(
            c.set_speed_config(PidConfig::new(f32::NAN, 0.0, 0.0))
                .is_err()
        );
    }

    #[test]
    fn angle_loop_runs_every_divider_ticks_with_accumulated_dt() {
        let mut c = cascade();
        c.set_target(ControlMode::Angle, 10.0);
        let m = Measured::default();
        c.step(&m, 0.001, 20.0);
        assert!((c.speed_target_rpm() - 100.0).abs() < 1e-4); // first tick runs the angle loop
        let m2 = Measured {
            angle_deg: 5.0,
            ..Default::default()
        };
        for _ in 0..9 {
            c.step(&m2, 0.001, 20.0);
            assert!(
                (c.speed_target_rpm() - 100.0).abs() < 1e-4,
                "held between runs"
            );
        }
        c.step(&m2, 0.001, 20.0);
        assert!((c.speed_target_rpm() - 50.0).abs() < 1e-4);
    }

    #[test]
    fn angle_loop_due_exactly_on_the_ticks_that_read_the_angle() {
        let mut c = cascade();
        c.set_target(ControlMode::Speed, 10.0);
        assert!(!c.angle_loop_due(), "speed mode never reads angles");
        c.set_target(ControlMode::TotalAngle, 10.0);
        // A wrong angle on the ticks the loop is not due must change nothing; the right one
        // (0°, error 10° → 100 rpm) is given only when due.
        let wrong = Measured {
            total_angle_deg: 1.0e4,
            ..Default::default()
        };
        let mut due_ticks = 0;
        for k in 0..25 {
            let due = c.angle_loop_due();
            let m = if due { Measured::default() } else { wrong };
            c.step(&m, 0.001, 20.0);
            if due {
                due_ticks += 1;
                assert_eq!(k % 10, 0, "due on tick {k}");
            }
            assert!((c.speed_target_rpm() - 100.0).abs() < 1e-3, "tick {k}");
        }
        assert_eq!(due_ticks, 3);
    }

    #[test]
    fn angle_mode_goes_short_way_total_angle_mode_does_not() {
        let mut c = cascade();
        let m = Measured {
            angle_deg: 350.0,
            total_angle_deg: 350.0,
            ..Default::default()
        };
        c.set_target(ControlMode::Angle, 370.0); // = 10°: +20° from 350°
        c.step(&m, 0.001, 20.0);
        assert!((c.speed_target_rpm() - 200.0).abs() < 1e-3);
        c.set_target(ControlMode::TotalAngle, 10.0); // -340° the linear way: limited to -300
        c.step(&m, 0.001, 20.0);
        assert!((c.speed_target_rpm() + 300.0).abs() < 1e-3);
    }

    #[test]
    fn disabled_outputs_zero_and_reset_clears_command() {
        let mut c = cascade();
        c.set_target(ControlMode::Current, 3.0);
        c.step(&Measured::default(), 0.001, 20.0);
        c.set_target(ControlMode::Disabled, 0.0);
        assert_eq!(c.step(&Measured::default(), 0.001, 20.0), 0.0);
        // Wind the speed loop's integral up, then reset: the next step starts from nothing,
        // p = 0.1·10 = 1 and i = 10·10·0.001 = 0.1 (the first trapezoid uses e at both ends).
        c.set_target(ControlMode::Speed, 10.0);
        for _ in 0..100 {
            c.step(&Measured::default(), 0.001, 20.0);
        }
        assert!(c.speed.integral() > 5.0, "{}", c.speed.integral());
        c.reset();
        assert_eq!(c.output(), 0.0);
        let out = c.step(&Measured::default(), 0.001, 20.0);
        assert!((out - 1.1).abs() < 1e-6, "{out}");
    }
}
