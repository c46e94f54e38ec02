//! The RC10_LIB manual's "MyMotor" (如果你想拓展电机？): a motor rc10 does not know, written
//! against rc10-core's traits. Used by the `custom-motor` firmware example and, unchanged, by
//! the host test `tests/custom_motor.rs` in the repository.
//!
//! MyMotor's (made-up) protocol: command on 0x300 + id, DLC 2, int16 big-endian milliamps;
//! feedback on 0x380 + id, DLC 4: rotor rpm (i16 BE), current in mA (i16 BE); 27:1 gearbox.
//! Implementing `CanNode` (what the scheduler and receiver call) and `Motor` (what the
//! application calls), with the state behind one blocking mutex, is the whole recipe.

use core::cell::RefCell;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use rc10_core::can::{CanFrame, IdFilter};
use rc10_core::encoder::GearRatio;
use rc10_core::math::saturate;
use rc10_core::motor::{ControlMode, HealthConfig, Liveness, Motor, MotorState, TargetError};
use rc10_core::node::{BusUsage, CanNode, FrameError, TxBatch};
use rc10_core::pid::{IncrementalPid, IncrementalPidConfig};
use rc10_core::time::Instant;

/// MyMotor's gearbox, 27:1.
pub const GEAR: GearRatio = match GearRatio::new(27, 1) {
    Some(g) => g,
    None => panic!("gear"),
};
/// The motor driver's current range, amps.
pub const MAX_AMPS: f32 = 8.0;

struct MyState {
    mode: ControlMode,
    target: f32,
    speed_rpm: f32,
    current_amps: Option<f32>,
    liveness: Liveness,
    command_amps: f32,
    speed_pid: IncrementalPid,
}

/// The manual's `MyMotor`: a motor with its own CAN protocol, written against rc10-core's
/// traits.
pub struct MyMotor {
    id: u8,
    health: HealthConfig,
    state: Mutex<CriticalSectionRawMutex, RefCell<MyState>>,
}

impl MyMotor {
    /// A MyMotor with driver id `id` (command 0x300 + id, feedback 0x380 + id).
    pub const fn new(id: u8) -> Self {
        let pid = match IncrementalPid::new(
            IncrementalPidConfig::new(0.05, 2.0, 0.0).with_output_limit(MAX_AMPS),
        ) {
            Ok(p) => p,
            Err(_) => panic!("gains"),
        };
        Self {
            id,
            health: HealthConfig::DEFAULT,
            state: Mutex::new(RefCell::new(MyState {
                mode: ControlMode::Disabled,
                target: 0.0,
                speed_rpm: 0.0,
                current_amps: None,
                liveness: Liveness::NEW,
                command_amps: 0.0,
                speed_pid: pid,
            })),
        }
    }

    fn set(&self, mode: ControlMode, target: f32) -> Result<(), TargetError> {
        if !target.is_finite() {
            return Err(TargetError::NotFinite);
        }
        self.state.lock(|s| {
            let mut s = s.borrow_mut();
            if s.mode != mode {
                s.speed_pid.reset();
            }
            s.mode = mode;
            s.target = target;
        });
        Ok(())
    }
}

impl CanNode for MyMotor {
    fn bus_usage(&self) -> BusUsage {
        let id = u16::from(self.id);
        BusUsage::NONE
            .listening(IdFilter::standard(0x380 + id), 1000)
            .sending(IdFilter::standard(0x300 + id), 1)
    }

    fn update_feedback(&self, frame: &CanFrame, now: Instant) -> Result<(), FrameError> {
        let [r0, r1, c0, c1] = *frame.data() else {
            return Err(FrameError::WrongLength {
                dlc: frame.dlc() as u8,
            });
        };
        let rotor_rpm = f32::from(i16::from_be_bytes([r0, r1]));
        let milliamps = f32::from(i16::from_be_bytes([c0, c1]));
        self.state.lock(|s| {
            let mut s = s.borrow_mut();
            s.speed_rpm = rotor_rpm / GEAR.as_f32();
            s.current_amps = Some(milliamps / 1000.0);
            s.liveness.record_feedback(now);
        });
        Ok(())
    }

    fn update(&self, now: Instant, dt_s: f32) {
        self.state.lock(|s| {
            let mut s = s.borrow_mut();
            if s.liveness.check(&self.health, now) {
                s.speed_pid.reset();
            }
            let amps = if !s.liveness.is_online() {
                0.0
            } else {
                match s.mode {
                    ControlMode::Current => s.target,
                    ControlMode::Speed => {
                        let (target, speed) = (s.target, s.speed_rpm);
                        s.speed_pid.update(target, speed, dt_s).output
                    }
                    _ => 0.0,
                }
            };
            s.command_amps = saturate(amps, MAX_AMPS);
        });
    }

    fn pack_command(&self, out: &mut TxBatch) {
        let amps = self.state.lock(|s| s.borrow().command_amps);
        // |amps| ≤ 8 A, so milliamps fit an i16.
        let milliamps = libm::roundf(amps * 1000.0) as i16;
        if let Some(frame) =
            CanFrame::standard(0x300 + u16::from(self.id), &milliamps.to_be_bytes())
        {
            let _ = out.push(frame);
        }
    }
}

impl Motor for MyMotor {
    fn set_target_current(&self, amps: f32) -> Result<(), TargetError> {
        self.set(ControlMode::Current, amps)
    }

    fn set_target_rpm(&self, rpm: f32) -> Result<(), TargetError> {
        self.set(ControlMode::Speed, rpm)
    }

    fn set_target_angle_deg(&self, _angle_deg: f32) -> Result<(), TargetError> {
        Err(TargetError::Unsupported)
    }

    fn set_target_total_angle_deg(&self, _angle_deg: f32) -> Result<(), TargetError> {
        Err(TargetError::Unsupported)
    }

    fn disable(&self) {
        let _ = self.set(ControlMode::Disabled, 0.0);
    }

    fn state(&self) -> MotorState {
        self.state.lock(|s| {
            let s = s.borrow();
            MotorState {
                online: s.liveness.is_online(),
                mode: s.mode,
                target: s.target,
                speed_rpm: s.speed_rpm,
                current_amps: s.current_amps,
                command: s.command_amps,
                offline_events: s.liveness.offline_events(),
                last_feedback: s.liveness.last_feedback(),
                ..MotorState::default()
            }
        })
    }

    fn gear_ratio(&self) -> GearRatio {
        GEAR
    }
}
