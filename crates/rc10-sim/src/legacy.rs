//! RC10_LIB's own M3508 speed loop, for comparison runs: incremental PID with the library's
//! demo gains (kp 18, ki 0.015 per 1 ms tick, deadband 5 rpm, limit 15 A, TD off; currents in
//! mA), computing a current that rc10's DJI driver then sends in current mode.

use rc10_core::can::CanFrame;
use rc10_core::encoder::GearRatio;
use rc10_core::motor::dji::DjiMotor;
use rc10_core::motor::{ControlMode, Motor, MotorState, TargetError};
use rc10_core::node::{BusUsage, CanNode, FrameError, TxBatch};
use rc10_core::pid::{IncrementalPid, IncrementalPidConfig};
use rc10_core::time::Instant;
use std::sync::Mutex;

/// RC10_LIB's demo gains: output in mA, ki per second = 0.015 per tick × 1000 ticks/s.
pub const RC10_DEMO_SPEED_PID: IncrementalPidConfig = IncrementalPidConfig::new(18.0, 15.0, 0.0)
    .with_deadband(5.0)
    .with_output_limit(15_000.0);

/// An M3508 driven by RC10_LIB's speed loop.
#[derive(Debug)]
pub struct LegacyM3508 {
    inner: DjiMotor,
    loop_state: Mutex<LoopState>,
}

/// RC10_LIB's loop: PID, target, and whether the error history has been zeroed.
#[derive(Debug)]
struct LoopState {
    pid: IncrementalPid,
    target: Option<f32>,
    primed: bool,
}

impl LegacyM3508 {
    /// An M3508 with ESC id `esc_id`, or `None` for an invalid id.
    pub fn new(esc_id: u8) -> Option<Self> {
        let pid = IncrementalPid::new(RC10_DEMO_SPEED_PID).ok()?;
        Some(Self {
            inner: DjiMotor::m3508(esc_id).ok()?,
            loop_state: Mutex::new(LoopState {
                pid,
                target: None,
                primed: false,
            }),
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
            if !l.primed {
                // RC10_LIB's error history starts at zero, so its first step kicks by kp·e.
                // rc10's controller starts from the present error and leaves its history
                // alone inside the deadband: prime it with a zero error under no deadband
                // (no output), then restore the demo's band.
                let _ = l.pid.set_config(IncrementalPidConfig {
                    deadband: 0.0,
                    ..RC10_DEMO_SPEED_PID
                });
                l.pid.update(0.0, 0.0, dt_s);
                let _ = l.pid.set_config(RC10_DEMO_SPEED_PID);
                l.primed = true;
            }
            Some(l.pid.update(t, rpm, dt_s).output)
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
            l.pid.reset();
            l.target = None;
            l.primed = false;
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
