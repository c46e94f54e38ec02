//! RC10_LIB's own M3508 speed loop, for comparison runs: its incremental PID with the demo
//! gains it shipped them with (kp 18, ki 0.015 per call, kd 0, deadband 5 rpm, limit 15 A, TD
//! off; currents in mA), computing a current that rc10's DJI driver then sends in current mode.
//!
//! The step follows `PID_Incremental::pid_calc` in RC10_LIB's `APP/Src/APP_PID.cpp` as of the
//! commit that introduced these gains (`User/debug/Src/frame_demo.cpp`), which later versions
//! keep. It differs from rc10's own [`IncrementalPid`](rc10_core::pid::IncrementalPid) on
//! purpose. RC10_LIB's:
//! - outputs 0 on its first call, and takes that call's error as the previous one: the
//!   proportional term only ever adds the error's *changes*, so a step is not met by a kick
//!   of kp·e but by the integral alone (the built-in speed steps therefore hold 0 rpm before
//!   they step, so that the loop meets the step already running);
//! - sets an error inside the deadband to 0 and still applies the increments: entering the
//!   band steps the output back by kp times the last error, and leaving it steps it up by kp
//!   times the new one (rc10 leaves the output and the history alone inside the band);
//! - adds `ki · e` and `kd · (e − 2e₁ + e₂)` per call, with no `dt`: each call is one tick,
//!   however much time passed (its `dt` only feeds the differentiator, off here);
//! - clamps the output, and carries the clamped output into the next call.

use rc10_core::can::CanFrame;
use rc10_core::encoder::GearRatio;
use rc10_core::motor::dji::DjiMotor;
use rc10_core::motor::{ControlMode, Motor, MotorState, TargetError};
use rc10_core::node::{BusUsage, CanNode, FrameError, TxBatch};
use rc10_core::time::Instant;
use std::sync::Mutex;

/// RC10_LIB's demo speed-loop gains (`m3508_speed_pid_params`), in its units: rpm in, mA out.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LegacyGains {
    /// Proportional gain on the change of the error, mA per rpm.
    pub kp: f32,
    /// Integral gain, mA per rpm per call: RC10_LIB adds `ki · e` on every call, with no `dt`.
    pub ki_per_call: f32,
    /// Derivative gain on the error's second difference, mA per rpm (no `dt` either).
    pub kd: f32,
    /// An error of magnitude below this (rpm) is taken as 0.
    pub deadband_rpm: f32,
    /// Output limit, mA.
    pub output_limit_ma: f32,
}

/// The gains RC10_LIB's demo gives its M3508 speed loop (its tracking differentiator off).
/// Its `I_Outlimit` of 8000 mA, which later versions apply to the per-call I increment, is
/// left out: the increment is `0.015 · e`, and it would take an error of 533 000 rpm to reach it.
pub const RC10_DEMO_SPEED_GAINS: LegacyGains = LegacyGains {
    kp: 18.0,
    ki_per_call: 0.015,
    kd: 0.0,
    deadband_rpm: 5.0,
    output_limit_ma: 15_000.0,
};

/// An M3508 driven by RC10_LIB's speed loop.
#[derive(Debug)]
pub struct LegacyM3508 {
    inner: DjiMotor,
    loop_state: Mutex<LoopState>,
}

/// RC10_LIB's loop: its PID and the target.
#[derive(Debug, Default)]
struct LoopState {
    pid: LegacyPid,
    target: Option<f32>,
}

/// RC10_LIB's incremental PID step (see the module docs for how it differs from rc10's).
#[derive(Debug, Default)]
struct LegacyPid {
    /// Output, mA.
    output: f32,
    /// The previous two errors after the deadband, rpm.
    history: (f32, f32),
    /// Whether the first call has been made.
    started: bool,
}

impl LegacyPid {
    /// One step with [`RC10_DEMO_SPEED_GAINS`]; returns the output in mA.
    fn step(&mut self, target: f32, measurement: f32) -> f32 {
        let g = RC10_DEMO_SPEED_GAINS;
        let mut e = target - measurement;
        if e.abs() < g.deadband_rpm {
            e = 0.0;
        }
        let (e1, e2) = self.history;
        if self.started {
            let p = g.kp * (e - e1);
            let i = g.ki_per_call * e;
            let d = g.kd * (e - 2.0 * e1 + e2);
            self.output += p + i + d;
        } else {
            self.started = true;
            self.output = 0.0;
        }
        self.output = self.output.clamp(-g.output_limit_ma, g.output_limit_ma);
        self.history = (e, e1);
        self.output
    }
}

impl LegacyM3508 {
    /// An M3508 with ESC id `esc_id`, or `None` for an invalid id.
    pub fn new(esc_id: u8) -> Option<Self> {
        Some(Self {
            inner: DjiMotor::m3508(esc_id).ok()?,
            loop_state: Mutex::new(LoopState::default()),
        })
    }

    fn with_loop<R>(&self, f: impl FnOnce(&mut LoopState) -> R) -> R {
        let mut guard = self
            .loop_state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        f(&mut guard)
    }
}

impl CanNode for LegacyM3508 {
    fn bus_usage(&self) -> BusUsage {
        self.inner.bus_usage()
    }

    fn matches_frame(&self, frame: &CanFrame) -> bool {
        self.inner.matches_frame(frame)
    }

    fn update_feedback(&self, frame: &CanFrame, now: Instant) -> Result<(), FrameError> {
        self.inner.update_feedback(frame, now)
    }

    fn update(&self, now: Instant, dt_s: f32) {
        let rpm = self.inner.speed_rpm();
        let milliamps = self.with_loop(|l| {
            let t = l.target?;
            Some(l.pid.step(t, rpm))
        });
        if let Some(ma) = milliamps {
            let _ = self.inner.set_target_current(ma / 1000.0);
        }
        self.inner.update(now, dt_s);
    }

    fn pack_command(&self, out: &mut TxBatch) {
        self.inner.pack_command(out);
    }
}

impl Motor for LegacyM3508 {
    fn set_target_current(&self, amps: f32) -> Result<(), TargetError> {
        self.with_loop(|l| l.target = None);
        self.inner.set_target_current(amps)
    }

    fn set_target_rpm(&self, rpm: f32) -> Result<(), TargetError> {
        if !rpm.is_finite() {
            return Err(TargetError::NotFinite);
        }
        self.with_loop(|l| l.target = Some(rpm));
        Ok(())
    }

    fn set_target_angle_deg(&self, _angle_deg: f32) -> Result<(), TargetError> {
        Err(TargetError::Unsupported)
    }

    fn set_target_total_angle_deg(&self, _angle_deg: f32) -> Result<(), TargetError> {
        Err(TargetError::Unsupported)
    }

    fn disable(&self) {
        self.with_loop(|l| {
            *l = LoopState::default();
        });
        self.inner.disable();
    }

    fn state(&self) -> MotorState {
        let mut s = self.inner.state();
        if let Some(t) = self.with_loop(|l| l.target) {
            s.mode = ControlMode::Speed;
            s.target = t;
        }
        s
    }

    fn gear_ratio(&self) -> GearRatio {
        self.inner.gear_ratio()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_comparison_pid_starts_at_zero_and_never_kicks_by_kp_e() {
        let mut pid = LegacyPid::default();
        // First call: 0, whatever the error.
        assert_eq!(pid.step(300.0, 0.0), 0.0);
        // The error has not changed: no P; I = 0.015 · 300 per call.
        assert!((pid.step(300.0, 0.0) - 4.5).abs() < 1e-4);
        assert!((pid.step(300.0, 0.0) - 9.0).abs() < 1e-4);
        // The error shrinks by 100: P = 18 · (200 − 300) = −1800, I = 3.
        assert!((pid.step(300.0, 100.0) - (9.0 - 1800.0 + 3.0)).abs() < 1e-3);
    }

    #[test]
    fn the_comparison_pid_zeroes_the_error_in_the_band_and_still_applies_the_increments() {
        let mut pid = LegacyPid::default();
        pid.step(7.0, 0.0); // 0; history 7
        // Still 7: I = 0.105.
        assert!((pid.step(7.0, 0.0) - 0.105).abs() < 1e-5);
        // 3 rpm is inside the 5 rpm band: e = 0, P = 18 · (0 − 7) = −126, I = 0.
        assert!((pid.step(3.0, 0.0) - (0.105 - 126.0)).abs() < 1e-3);
        // Inside again: nothing changes.
        assert!((pid.step(4.9, 0.0) - (0.105 - 126.0)).abs() < 1e-3);
        // Out at 7: P = 18 · (7 − 0) = 126, I = 0.105.
        assert!((pid.step(7.0, 0.0) - 0.21).abs() < 1e-3);
        // Exactly 5 rpm is outside the band (RC10_LIB's `fabs(e) < deadband`): P = 18 · (5 − 7).
        assert!((pid.step(5.0, 0.0) - (0.21 - 36.0 + 0.075)).abs() < 1e-3);
    }

    #[test]
    fn the_comparison_pid_clamps_and_carries_the_clamped_output() {
        let mut pid = LegacyPid::default();
        pid.step(0.0, 0.0);
        // A 1000 rpm jump: P = 18 000, I = 15, clamped to 15 000 mA.
        assert_eq!(pid.step(1000.0, 0.0), 15_000.0);
        // The error falls to 900: P = −1800, I = 13.5, from the clamped 15 000.
        assert!((pid.step(1000.0, 100.0) - (15_000.0 - 1800.0 + 13.5)).abs() < 1e-2);
    }

    #[test]
    fn the_comparison_loop_integrates_one_tick_per_call_after_a_stall() {
        let motor = LegacyM3508::new(1).unwrap();
        motor.set_target_rpm(100.0).unwrap();
        motor.update(Instant::from_micros(1_000), 0.001); // first call: 0
        // The next call comes after a 50 ms stall: I = 0.015 · 100 (one call's worth), not
        // 50 calls' worth; P = 0 (the error did not change). 1.5 mA.
        motor.update(Instant::from_micros(51_000), 0.05);
        // The current target the loop gave the DJI driver (its command stays 0: offline).
        let amps = motor.inner.state().target;
        assert!((amps - 0.0015).abs() < 1e-6, "{amps}");
    }
}
