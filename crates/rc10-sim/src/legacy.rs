//! RC10_LIB's own M3508 speed loop, for comparison runs: incremental PID with the library's
//! demo gains (kp 18, ki 0.015 per 1 ms tick, deadband 5 rpm, limit 15 A, TD off; currents in
//! mA), computing a current that rc10's DJI driver then sends in current mode.

use rc10_core::can::CanFrame;
use rc10_core::encoder::GearRatio;
use rc10_core::motor::dji::DjiMotor;
use rc10_core::motor::{ControlMode, Motor, MotorState, TargetError};
use rc10_core::node::{BusUsage, CanNode, FrameError, TxBatch};
use rc10_core::pid::IncrementalPidConfig;
use rc10_core::time::Instant;
use std::sync::Mutex;

/// RC10_LIB's demo gains: output in mA, ki per second = 0.015 per tick × 1000 ticks/s.
pub const RC10_DEMO_SPEED_PID: IncrementalPidConfig = IncrementalPidConfig::new(18.0, 15.0, 0.0)
    .with_deadband(5.0)
    .with_output_limit(15_000.0);

/// The `dt` RC10_LIB's PID hard-codes (`0.001f`): its `update()` is trusted to run at 1 kHz.
const LEGACY_DT_S: f32 = 0.001;

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

/// RC10_LIB's incremental PID step as this comparison reproduces it, kept apart from rc10's
/// own [`IncrementalPid`](rc10_core::pid::IncrementalPid), which differs on purpose: the
/// error history starts at zero (the first step kicks by kp·e) and shifts on every call,
/// inside the deadband too (rc10 leaves it alone there), while the output moves only
/// outside the band; its D term is the fixed-dt `kd·(e − 2e₁ + e₂)/dt` (rc10 takes the change of
/// `kd·ė` over the time since the last error outside the band; the demo's kd is 0).
#[derive(Debug, Default)]
struct LegacyPid {
    /// Output, mA.
    output: f32,
    /// The previous two errors, rpm.
    history: (f32, f32),
}

impl LegacyPid {
    /// One step with [`RC10_DEMO_SPEED_PID`]; returns the output in mA. Like RC10_LIB's
    /// `pid_calc`, it takes every call to be one 1 ms tick ([`LEGACY_DT_S`]), whatever time
    /// passed: after a scheduler stall its integral grows by one tick's worth, not the stall's.
    fn step(&mut self, target: f32, measurement: f32) -> f32 {
        let c = RC10_DEMO_SPEED_PID;
        let e = target - measurement;
        let (e1, e2) = self.history;
        if e.abs() > c.deadband {
            let p = c.kp * (e - e1);
            let i = c.ki * e * LEGACY_DT_S;
            let d = if c.kd == 0.0 {
                0.0
            } else {
                c.kd * (e - 2.0 * e1 + e2) / LEGACY_DT_S
            };
            self.output = (self.output + p + i + d).clamp(-c.output_limit, c.output_limit);
        }
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
    fn the_comparison_pid_kicks_on_its_first_step_and_shifts_history_inside_the_band() {
        let mut pid = LegacyPid::default();
        // From a zero history: P = 18 · 300, I = 15 · 300 · 0.001.
        assert!((pid.step(300.0, 0.0) - 5404.5).abs() < 1e-3);
        let mut pid = LegacyPid::default();
        pid.step(7.0, 0.0); // 18 · 7 + 15 · 7 · 0.001 = 126.105
        // Inside the band: no output change, but the history takes the 3.
        assert!((pid.step(3.0, 0.0) - 126.105).abs() < 1e-3);
        // Out again at 7: P = 18 · (7 − 3) = 72, I = 0.105.
        assert!((pid.step(7.0, 0.0) - 198.21).abs() < 1e-3);
    }

    #[test]
    fn the_comparison_loop_integrates_one_tick_per_call_after_a_stall() {
        let motor = LegacyM3508::new(1).unwrap();
        motor.set_target_rpm(100.0).unwrap();
        // First call after a 50 ms stall: I = 15 · 100 · 0.001 (RC10_LIB's fixed dt), not
        // 15 · 100 · 0.05; P = 18 · 100 from the zero history. 1801.5 mA.
        motor.update(Instant::from_micros(50_000), 0.05);
        // The current target the loop gave the DJI driver (its command stays 0: offline).
        let amps = motor.inner.state().target;
        assert!((amps - 1.8015).abs() < 1e-4, "{amps}");
    }
}
