//! The `Motor` trait's provided methods: a device that implements only the required ones
//! reports every optional capability as `Unsupported` (never a silent `Ok`), and the
//! convenience getters read its `state()`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use rc10_core::encoder::GearRatio;
use rc10_core::motor::{ControlMode, Motor, MotorState, TargetError};

/// A device with only the required methods and a fixed state.
struct Minimal;

const STATE: MotorState = MotorState {
    online: true,
    mode: ControlMode::Speed,
    target: 120.0,
    speed_rpm: 118.5,
    angle_deg: Some(45.0),
    total_angle_deg: Some(405.0),
    current_amps: Some(2.25),
    temperature_c: Some(41.0),
    command: 2.5,
    offline_events: 3,
    last_feedback: None,
};

impl Motor for Minimal {
    fn set_target_current(&self, _amps: f32) -> Result<(), TargetError> {
        Ok(())
    }
    fn set_target_rpm(&self, _rpm: f32) -> Result<(), TargetError> {
        Ok(())
    }
    fn set_target_angle_deg(&self, _angle_deg: f32) -> Result<(), TargetError> {
        Ok(())
    }
    fn set_target_total_angle_deg(&self, _angle_deg: f32) -> Result<(), TargetError> {
        Ok(())
    }
    fn disable(&self) {}
    fn state(&self) -> MotorState {
        STATE
    }
    fn gear_ratio(&self) -> GearRatio {
        GearRatio::DIRECT
    }
}

#[test]
fn optional_capabilities_default_to_unsupported() {
    let m = Minimal;
    let unsupported = Err(TargetError::Unsupported);
    assert_eq!(m.set_target_voltage(5.0), unsupported);
    assert_eq!(m.set_target_torque_nm(1.0), unsupported);
    assert_eq!(m.set_feed_forward_torque_nm(0.5), unsupported);
    assert_eq!(m.set_current_limit_amps(3.0), unsupported);
    assert_eq!(m.set_total_angle_here_deg(0.0), unsupported);
}

#[test]
fn getters_read_the_state() {
    let m = Minimal;
    assert_eq!(m.speed_rpm(), 118.5);
    assert_eq!(m.angle_deg(), Some(45.0));
    assert_eq!(m.total_angle_deg(), Some(405.0));
    assert_eq!(m.current_amps(), Some(2.25));
    assert_eq!(m.temperature_c(), Some(41.0));
    assert_eq!(m.mode(), ControlMode::Speed);
    assert!(m.is_online());
}
