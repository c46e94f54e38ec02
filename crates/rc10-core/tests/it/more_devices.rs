//! VESC, Damiao and incremental-PID behaviour that mutation testing found unpinned: what the
//! application reads back (command, mode, ids), the zero-speed brake, status packets the
//! driver ignores, homing offsets on the Damiao range, and live tuning of the incremental PID.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use rc10_core::can::CanFrame;
use rc10_core::motor::dm::{DmConfig, DmMotor};
use rc10_core::motor::vesc::{VescConfig, VescMotor, VescStatusSet, packet};
use rc10_core::motor::{ControlMode, Motor, TargetError};
use rc10_core::node::{CanNode, TxBatch};
use rc10_core::pid::{IncrementalPid, IncrementalPidConfig, PidConfigError};
use rc10_core::time::Instant;

const ID: u8 = 0x42;

fn status(packet: u8) -> CanFrame {
    CanFrame::extended((u32::from(packet) << 8) | u32::from(ID), &[0; 8]).unwrap()
}

/// The VESC packet of the command the motor sends after a tick at `now`.
fn sent_packet(m: &VescMotor, now: Instant) -> u8 {
    m.update(now, 0.001);
    let mut out = TxBatch::new();
    m.pack_command(&mut out);
    (out.frames()[0].raw_id() >> 8) as u8
}

fn online_vesc(config: VescConfig) -> VescMotor {
    let m = VescMotor::new(ID, config).unwrap();
    m.update_feedback(&status(packet::STATUS), Instant::from_millis(1))
        .unwrap();
    m
}

#[test]
fn vesc_reports_its_id_and_applied_command() {
    let m = online_vesc(VescConfig::new(7));
    assert_eq!(m.vesc_id(), ID);
    assert!(format!("{m:?}").contains("VescMotor"));
    m.set_target_current(3.0).unwrap();
    m.update(Instant::from_millis(2), 0.001);
    assert_eq!(m.state().command, 3.0);
    m.set_brake_current(2.0).unwrap();
    m.update(Instant::from_millis(3), 0.001);
    assert_eq!(
        m.state().command,
        -2.0,
        "braking reads as a negative current"
    );
    m.disable();
    m.update(Instant::from_millis(4), 0.001);
    assert_eq!(m.state().mode, ControlMode::Disabled);
    assert_eq!(m.state().command, 0.0);
}

#[test]
fn vesc_zero_speed_brake_only_at_zero_speed() {
    // SET_RPM is packet 3, SET_CURRENT_BRAKE packet 2 (VESC firmware's CAN command ids).
    let mut config = VescConfig::new(7);
    config.zero_speed_brake_amps = Some(5.0);
    let m = online_vesc(config);
    m.set_target_rpm(100.0).unwrap();
    assert_eq!(sent_packet(&m, Instant::from_millis(2)), 3);
    m.set_target_rpm(0.0).unwrap();
    assert_eq!(sent_packet(&m, Instant::from_millis(3)), 2);
}

#[test]
fn vesc_ignores_status_packets_it_does_not_use_without_error() {
    let m = VescMotor::new(ID, VescConfig::new(7)).unwrap();
    let now = Instant::from_millis(1);
    for p in [packet::STATUS_2, packet::STATUS_3, packet::STATUS_5] {
        assert_eq!(m.update_feedback(&status(p), now), Ok(()), "packet {p}");
    }
}

#[test]
fn vesc_current_limit_of_zero_is_allowed() {
    let m = online_vesc(VescConfig::new(7));
    assert_eq!(m.set_current_limit_amps(0.0), Ok(()));
    m.set_target_current(3.0).unwrap();
    m.update(Instant::from_millis(2), 0.001);
    assert_eq!(m.state().command, 0.0);
    assert_eq!(m.set_current_limit_amps(-1.0), Err(TargetError::OutOfRange));
}

#[test]
fn vesc_status_sets_combine_idempotently() {
    let s = VescStatusSet::STATUS_1.with(VescStatusSet::STATUS_1);
    assert!(s.contains(VescStatusSet::STATUS_1));
    let both = VescStatusSet::STATUS_1.with(VescStatusSet::STATUS_4);
    assert!(both.contains(VescStatusSet::STATUS_1) && both.contains(VescStatusSet::STATUS_4));
    assert!(!both.contains(VescStatusSet::STATUS_2));
}

fn dm_feedback(position_code: u16) -> CanFrame {
    // Enabled (state 1), motor id 1, velocity and torque codes at zero.
    let [p0, p1] = position_code.to_be_bytes();
    CanFrame::standard(0x11, &[0x11, p0, p1, 0x7F, 0xF7, 0xFF, 30, 30]).unwrap()
}

#[test]
fn damiao_total_angle_range_moves_with_homing() {
    // The MIT position spans ±12.5 rad = ±716.2° of the motor's frame. Homing the present
    // position (≈ 0 rad) to 90° shifts the reachable total angles to [-626.2°, 806.2°].
    let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
    assert!(format!("{m:?}").contains("DmMotor"));
    let t = Instant::from_millis;
    m.update_feedback(&dm_feedback(0x8000), t(1)).unwrap();
    m.set_total_angle_here_deg(90.0).unwrap();
    m.update(t(2), 0.001);
    let (lo, hi) = m.total_angle_range_deg();
    let half = 12.5f32.to_degrees();
    assert!((lo - (90.0 - half)).abs() < 0.05, "{lo}");
    assert!((hi - (90.0 + half)).abs() < 0.05, "{hi}");
    assert_eq!(m.set_target_total_angle_deg(800.0), Ok(()));
    assert_eq!(
        m.set_target_total_angle_deg(-650.0),
        Err(TargetError::OutOfRange)
    );
    m.disable();
    assert_eq!(m.state().mode, ControlMode::Disabled);
}

#[test]
fn incremental_pid_validates_and_retunes_live() {
    assert_eq!(
        IncrementalPidConfig::new(f32::NAN, 0.0, 0.0).validate(),
        Err(PidConfigError::GainNotFinite)
    );
    assert_eq!(IncrementalPidConfig::new(1.0, 0.0, 0.0).validate(), Ok(()));
    // kp 1 -> 2: a 10-unit error step moves the output by kp · Δe = 20 instead of 10.
    let mut pid = IncrementalPid::new(IncrementalPidConfig::new(1.0, 0.0, 0.0)).unwrap();
    pid.update(0.0, 0.0, 0.001);
    assert!(
        pid.set_config(IncrementalPidConfig::new(f32::NAN, 0.0, 0.0))
            .is_err()
    );
    pid.set_config(IncrementalPidConfig::new(2.0, 0.0, 0.0))
        .unwrap();
    pid.update(10.0, 0.0, 0.001);
    assert!((pid.output() - 20.0).abs() < 1e-4, "{}", pid.output());
}

#[test]
fn incremental_pid_gains_a_tracking_differentiator_by_live_tuning() {
    // A PID retuned to use a TD behaves as one built with it, and not as one without.
    let plain = IncrementalPidConfig::new(1.0, 0.0, 0.0);
    let with_td = plain.with_td(50.0);
    let mut retuned = IncrementalPid::new(plain).unwrap();
    retuned.set_config(with_td).unwrap();
    let mut built = IncrementalPid::new(with_td).unwrap();
    let mut without = IncrementalPid::new(plain).unwrap();
    for k in 0..20 {
        let target = if k < 2 { 0.0 } else { 100.0 };
        retuned.update(target, 0.0, 0.001);
        built.update(target, 0.0, 0.001);
        without.update(target, 0.0, 0.001);
    }
    assert_eq!(retuned.output(), built.output());
    assert_ne!(built.output(), without.output());
}

#[test]
fn tracking_differentiator_reports_its_rate() {
    use rc10_core::pid::TrackingDifferentiator;
    assert_eq!(TrackingDifferentiator::new(50.0).unwrap().r_rad_s(), 50.0);
    assert_eq!(
        TrackingDifferentiator::new(0.0).unwrap_err(),
        PidConfigError::InvalidTrackingRate
    );
}
