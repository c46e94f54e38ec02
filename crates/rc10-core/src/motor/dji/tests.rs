//! Byte-for-byte tests of the DJI driver. Expected bytes are worked out by hand from the
//! protocol table in the module docs.

use super::*;
use crate::motor::MultiTurnOnReturn;
use crate::time::Duration;

const T0: Instant = Instant::from_millis(1000);
const DT: f32 = 0.001;

fn fb(id: u16, angle: u16, rotor_rpm: i16, current: i16, temp: u8) -> CanFrame {
    let a = angle.to_be_bytes();
    let r = rotor_rpm.to_be_bytes();
    let c = current.to_be_bytes();
    CanFrame::standard(id, &[a[0], a[1], r[0], r[1], c[0], c[1], temp, 0]).unwrap()
}

/// Brings the motor online at `T0` with a neutral feedback frame.
fn online(m: &DjiMotor) {
    let id = m.model().feedback_id(m.esc_id());
    m.update_feedback(&fb(id, 0, 0, 0, 30), T0).unwrap();
}

/// Update then pack one tick at `now`; returns the batch.
fn tick(m: &DjiMotor, now: Instant) -> TxBatch {
    let mut b = TxBatch::new();
    m.update(now, DT);
    m.pack_command(&mut b);
    b
}

fn only_frame(b: &TxBatch) -> (u32, [u8; 8]) {
    assert_eq!(b.frames().len(), 1);
    let f = b.frames()[0];
    (f.raw_id(), *f.data8().unwrap())
}

#[test]
fn m3508_current_10a_id1_packs_0x2000_in_slot_0_of_0x200() {
    let m = DjiMotor::m3508(1).unwrap();
    online(&m);
    m.set_target_current(10.0).unwrap();
    // 10 A · 16384 / 20 A = 8192 = 0x2000.
    assert_eq!(
        only_frame(&tick(&m, T0)),
        (0x200, [0x20, 0x00, 0, 0, 0, 0, 0, 0])
    );
}

#[test]
fn m3508_negative_current_id6_packs_slot_1_of_0x1ff() {
    let m = DjiMotor::m3508(6).unwrap();
    online(&m);
    m.set_target_current(-5.0).unwrap();
    // -5 A → -4096 = 0xF000, ids 5–8 on 0x1FF, id 6 → slot 1 (bytes 2–3).
    assert_eq!(
        only_frame(&tick(&m, T0)),
        (0x1FF, [0, 0, 0xF0, 0x00, 0, 0, 0, 0])
    );
}

#[test]
fn m3508_current_beyond_range_clamps_without_wrap() {
    let m = DjiMotor::m3508(4).unwrap();
    online(&m);
    m.set_target_current(25.0).unwrap();
    // Clamped to 20 A = 16384 = 0x4000 (a wrapping conversion of 20480 would be fine, but
    // of 1000 A it would flip sign).
    assert_eq!(only_frame(&tick(&m, T0)).1, [0, 0, 0, 0, 0, 0, 0x40, 0x00]);
    m.set_target_current(-1000.0).unwrap();
    assert_eq!(only_frame(&tick(&m, T0)).1, [0, 0, 0, 0, 0, 0, 0xC0, 0x00]);
}

#[test]
fn command_to_raw_saturates_for_every_model() {
    let m = DjiMotor::m3508(1).unwrap();
    assert_eq!(m.command_to_raw(1e9), 16384);
    assert_eq!(m.command_to_raw(f32::NAN), 0);
    let c610 = DjiMotor::m2006(1).unwrap();
    assert_eq!(c610.command_to_raw(11.0), 10000);
    assert_eq!(c610.command_to_raw(-0.0015), -2); // -1.5 mA rounds away from zero
    let gm_v = DjiMotor::gm6020_voltage(1).unwrap();
    assert_eq!(gm_v.command_to_raw(24.0), 25000);
    let gm_i = DjiMotor::gm6020_current(1).unwrap();
    assert_eq!(gm_i.command_to_raw(-3.5), -16384);
}

#[test]
fn command_just_below_half_a_count_rounds_to_zero_as_roundf_does() {
    // C610: 10 000 counts per 10 A, 1000 per amp. A command whose raw value is the float
    // just below 0.5 (0.49999997) is less than half a count: 0, not 1 (adding 0.5 and
    // truncating would give 1); exactly 0.5 count is a tie and goes away from zero.
    let c610 = DjiMotor::m2006(1).unwrap();
    let below_half = 0.499_999_97f32;
    let amps = (0..10_000u32)
        .map(|k| f32::from_bits((below_half / 1000.0).to_bits() - 5_000 + k))
        .find(|a| a * 1000.0 == below_half)
        .expect("a command of 0.49999997 counts");
    assert_eq!(c610.command_to_raw(amps), 0);
    assert_eq!(c610.command_to_raw(-amps), 0);
    assert_eq!(c610.command_to_raw(0.0005), 1);
    assert_eq!(c610.command_to_raw(-0.0005), -1);
}

#[test]
fn m2006_2_5a_id3_packs_2500_in_slot_2() {
    let m = DjiMotor::m2006(3).unwrap();
    online(&m);
    m.set_target_current(2.5).unwrap();
    // 2.5 A · 10000 / 10 A = 2500 = 0x09C4.
    assert_eq!(
        only_frame(&tick(&m, T0)),
        (0x200, [0, 0, 0, 0, 0x09, 0xC4, 0, 0])
    );
}

#[test]
fn gm6020_voltage_slots_and_default_limit() {
    let m = DjiMotor::gm6020_voltage(2).unwrap();
    online(&m);
    m.set_target_voltage(12.0).unwrap();
    // 12 V · 30000 / 24 V = 15000 = 0x3A98, ids 1–4 on 0x1FF, id 2 → slot 1.
    assert_eq!(
        only_frame(&tick(&m, T0)),
        (0x1FF, [0, 0, 0x3A, 0x98, 0, 0, 0, 0])
    );
    m.set_target_voltage(-24.0).unwrap();
    // -30000 clamped to the default -25000 = 0x9E58.
    assert_eq!(only_frame(&tick(&m, T0)).1, [0, 0, 0x9E, 0x58, 0, 0, 0, 0]);
}

#[test]
fn gm6020_voltage_limit_is_configurable_to_30000() {
    let model = DjiModel::Gm6020Voltage;
    let mut cfg = DjiConfig::default_for(model);
    cfg.voltage_raw_limit = 30000;
    let m = DjiMotor::new(model, 7, cfg).unwrap();
    // id 7 → 0x2FF slot 2; feedback 0x20B.
    assert_eq!(m.command_slot(), CommandSlot::new(0x2FF, 2).unwrap());
    assert_eq!(m.model().feedback_id(7), 0x20B);
    assert_eq!(m.command_to_raw(24.0), 30000);
}

#[test]
fn raised_voltage_limit_is_reachable_through_the_control_path() {
    let model = DjiModel::Gm6020Voltage;
    let mut cfg = DjiConfig::default_for(model);
    cfg.voltage_raw_limit = 30000;
    let m = DjiMotor::new(model, 1, cfg).unwrap();
    assert_eq!(m.command_limit(), 24.0);
    online(&m);
    m.set_target_voltage(24.0).unwrap();
    // 24 V = 30000 = 0x7530 in slot 0 of 0x1FF (not held at the default 25000).
    assert_eq!(
        only_frame(&tick(&m, T0)),
        (0x1FF, [0x75, 0x30, 0, 0, 0, 0, 0, 0])
    );
}

#[test]
fn gm6020_current_mode_uses_0x1fe_0x2fe() {
    let m = DjiMotor::gm6020_current(6).unwrap();
    online(&m);
    m.set_target_current(1.5).unwrap();
    // 1.5 A · 16384 / 3 A = 8192 = 0x2000; id 6 → 0x2FE slot 1.
    assert_eq!(
        only_frame(&tick(&m, T0)),
        (0x2FE, [0, 0, 0x20, 0x00, 0, 0, 0, 0])
    );
    assert_eq!(
        DjiMotor::gm6020_current(1).unwrap().command_slot().id(),
        0x1FE
    );
}

#[test]
fn every_id_maps_to_its_slot() {
    for id in 1..=8u8 {
        let m = DjiMotor::m3508(id).unwrap();
        let expect_id = if id <= 4 { 0x200 } else { 0x1FF };
        assert_eq!(
            m.command_slot(),
            CommandSlot::new(expect_id, (id - 1) % 4).unwrap()
        );
        assert!(m.matches_frame(&fb(0x200 + u16::from(id), 0, 0, 0, 0)));
    }
    for id in 1..=7u8 {
        let m = DjiMotor::gm6020_voltage(id).unwrap();
        let expect_id = if id <= 4 { 0x1FF } else { 0x2FF };
        assert_eq!(
            m.command_slot(),
            CommandSlot::new(expect_id, (id - 1) % 4).unwrap()
        );
        assert!(m.matches_frame(&fb(0x204 + u16::from(id), 0, 0, 0, 0)));
    }
}

#[test]
fn invalid_thermal_limits_are_rejected() {
    let mut cfg = DjiConfig::default_for(DjiModel::M3508);
    cfg.health.thermal = Some(ThermalLimits {
        derate_start_c: f32::NAN,
        cutoff_c: 120.0,
    });
    assert_eq!(
        DjiMotor::new(DjiModel::M3508, 1, cfg).unwrap_err(),
        DjiError::InvalidThermal
    );
    cfg.health.thermal = Some(ThermalLimits {
        derate_start_c: 120.0,
        cutoff_c: 100.0,
    });
    assert_eq!(
        DjiMotor::new(DjiModel::M3508, 1, cfg).unwrap_err(),
        DjiError::InvalidThermal
    );
}

#[test]
fn out_of_range_ids_are_rejected() {
    assert_eq!(
        DjiMotor::m3508(0).unwrap_err(),
        DjiError::IdOutOfRange { id: 0, max: 8 }
    );
    assert_eq!(
        DjiMotor::m3508(9).unwrap_err(),
        DjiError::IdOutOfRange { id: 9, max: 8 }
    );
    assert_eq!(
        DjiMotor::gm6020_voltage(8).unwrap_err(),
        DjiError::IdOutOfRange { id: 8, max: 7 }
    );
}

#[test]
fn m3508_feedback_parsed_to_output_shaft_units() {
    let m = DjiMotor::m3508(2).unwrap();
    // angle 8191, rotor 1000 rpm, current 2048 (2.5 A), 45 °C.
    m.update_feedback(&fb(0x202, 8191, 1000, 2048, 45), T0)
        .unwrap();
    let s = m.state();
    assert!((s.speed_rpm - 1000.0 * 187.0 / 3591.0).abs() < 1e-3); // 52.075 rpm
    assert!((s.current_amps.unwrap() - 2.5).abs() < 1e-6);
    assert_eq!(s.temperature_c, Some(45.0));
    assert_eq!(s.last_feedback, Some(T0));
    m.update_feedback(&fb(0x202, 100, -1000, -2048, 45), T0)
        .unwrap();
    let s = m.state();
    assert!((s.speed_rpm + 52.075).abs() < 1e-3);
    assert!((s.current_amps.unwrap() + 2.5).abs() < 1e-6);
    // 8191 → 100 is +101 rotor counts across the wrap.
    let expect_deg = 101.0 * 360.0 / 8192.0 / (3591.0 / 187.0);
    assert!(
        (s.total_angle_deg.unwrap() - expect_deg).abs() < 1e-4,
        "{:?}",
        s.total_angle_deg
    );
}

#[test]
fn m2006_feedback_has_no_temperature() {
    let m = DjiMotor::m2006(1).unwrap();
    m.update_feedback(&fb(0x201, 0, 3600, 1000, 99), T0)
        .unwrap();
    let s = m.state();
    assert_eq!(s.temperature_c, None);
    assert!((s.speed_rpm - 100.0).abs() < 1e-4); // 3600 / 36
    assert!((s.current_amps.unwrap() - 1.0).abs() < 1e-6); // 1000 mA
}

#[test]
fn malformed_feedback_is_rejected_and_changes_nothing() {
    let m = DjiMotor::m3508(1).unwrap();
    let short = CanFrame::standard(0x201, &[0; 7]).unwrap();
    assert_eq!(
        m.update_feedback(&short, T0),
        Err(FrameError::WrongLength { dlc: 7 })
    );
    assert_eq!(
        m.update_feedback(&fb(0x201, 8192, 0, 0, 0), T0),
        Err(FrameError::OutOfRange)
    );
    let remote = CanFrame::remote(crate::can::StandardId::new(0x201).unwrap(), 8).unwrap();
    assert!(m.update_feedback(&remote, T0).is_err());
    assert_eq!(m.state().last_feedback, None);
    // After good feedback, malformed frames change nothing the application reads.
    m.update_feedback(&fb(0x201, 1000, 1920, 800, 40), T0)
        .unwrap();
    let before = m.state();
    let later = T0 + Duration::from_millis(1);
    assert!(m.update_feedback(&short, later).is_err());
    assert!(
        m.update_feedback(&fb(0x201, 9000, -500, 100, 90), later)
            .is_err()
    );
    assert!(m.update_feedback(&remote, later).is_err());
    assert_eq!(m.state(), before);
}

#[test]
fn no_feedback_ever_sends_zero() {
    let m = DjiMotor::m3508(1).unwrap();
    m.set_target_current(10.0).unwrap();
    assert_eq!(only_frame(&tick(&m, T0)).1, [0; 8]);
    assert!(!m.is_online());
}

#[test]
fn offline_after_timeout_zeroes_command_and_recovers() {
    let m = DjiMotor::m3508(1).unwrap();
    online(&m);
    m.set_target_current(10.0).unwrap();
    assert_eq!(
        only_frame(&tick(&m, T0 + Duration::from_millis(100))).1[..2],
        [0x20, 0]
    );
    assert!(m.is_online());
    // 101 ms of silence: offline, zero command.
    assert_eq!(
        only_frame(&tick(&m, T0 + Duration::from_millis(101))).1,
        [0; 8]
    );
    let s = m.state();
    assert!(!s.online);
    assert_eq!(s.offline_events, 1);
    assert_eq!(s.command, 0.0);
    // Power returns: the next frame brings it back, the target is kept.
    let back = T0 + Duration::from_millis(500);
    m.update_feedback(&fb(0x201, 10, 0, 0, 30), back).unwrap();
    assert_eq!(only_frame(&tick(&m, back)).1[..2], [0x20, 0]);
    assert!(m.is_online());
    assert_eq!(m.state().offline_events, 1);
}

#[test]
fn offline_resets_speed_loop_so_return_has_no_windup_kick() {
    let m = DjiMotor::m3508(1).unwrap();
    online(&m);
    // A small error, so the loop integrates instead of sitting at the current limit; the
    // stalled motor keeps reporting (stale feedback would hold the integral).
    m.set_target_rpm(20.0).unwrap();
    for k in 0..50 {
        let now = T0 + Duration::from_millis(k);
        m.update_feedback(&fb(0x201, 0, 0, 0, 30 + k as u8), now)
            .unwrap();
        tick(&m, now);
    }
    let wound = m.speed_loop_terms().i;
    assert!(wound > 0.0);
    tick(&m, T0 + Duration::from_millis(200)); // offline
    let back = T0 + Duration::from_millis(300);
    m.update_feedback(&fb(0x201, 0, 0, 0, 30), back).unwrap();
    tick(&m, back);
    // First tick back: integral restarted from zero (one step's worth only).
    assert!(m.speed_loop_terms().i < wound / 10.0);
}

#[test]
fn stale_feedback_holds_the_speed_integral_until_frames_return() {
    // Default M3508 speed loop: kp 0.6 A/rpm, ki 8 A/(rpm·s). One frame at T0 (the motor at
    // rest), then none: the motor stays online for 100 ms, but after 3 ms without a frame
    // the integral must stop growing on an error that nobody measures.
    let m = DjiMotor::m3508(1).unwrap();
    online(&m);
    m.set_target_rpm(20.0).unwrap();
    let at = |ms: u64| T0 + Duration::from_millis(ms);
    // Ages 0–3 ms integrate, 8·20·0.001 = 0.16 A a tick (the first trapezoid uses e twice).
    for k in 0..4 {
        tick(&m, at(k));
        let i = m.speed_loop_terms().i;
        assert!((i - 0.16 * (k + 1) as f32).abs() < 1e-5, "tick {k}: {i}");
    }
    // From 4 ms: held at 0.64 A, the command at 0.6·20 + 0.64 = 12.64 A.
    for k in 4..60 {
        tick(&m, at(k));
        let s = m.state();
        assert!(s.online);
        assert!((s.command - 12.64).abs() < 1e-4, "tick {k}: {}", s.command);
    }
    // A new target still acts at once (0.6·10 + 0.64), and a lower user limit too.
    m.set_target_rpm(10.0).unwrap();
    tick(&m, at(60));
    assert!((m.state().command - 6.64).abs() < 1e-4);
    m.set_current_limit_amps(5.0).unwrap();
    tick(&m, at(61));
    assert_eq!(m.state().command, 5.0);
    m.set_current_limit_amps(20.0).unwrap();
    // Frames return (still at rest): integration resumes from 0.64, + 8·10·0.001.
    m.update_feedback(&fb(0x201, 0, 0, 0, 31), at(70)).unwrap();
    tick(&m, at(70));
    assert!((m.speed_loop_terms().i - 0.72).abs() < 1e-5);
    assert!((m.state().command - 6.72).abs() < 1e-4);
}

#[test]
fn multi_turn_restart_policy_restarts_total_angle() {
    let mut cfg = DjiConfig::default_for(DjiModel::M2006);
    cfg.health = cfg.health.with_on_return(MultiTurnOnReturn::Restart);
    let m = DjiMotor::new(DjiModel::M2006, 1, cfg).unwrap();
    m.update_feedback(&fb(0x201, 0, 0, 0, 0), T0).unwrap();
    m.update_feedback(&fb(0x201, 4000, 0, 0, 0), T0).unwrap();
    tick(&m, T0);
    assert!(m.total_angle_deg().unwrap() > 0.0);
    tick(&m, T0 + Duration::from_millis(150)); // offline
    let back = T0 + Duration::from_millis(300);
    m.update_feedback(&fb(0x201, 7000, 0, 0, 0), back).unwrap();
    assert_eq!(m.total_angle_deg(), Some(0.0));
    // Back with the very frame it sent before the outage (it did not move while off): not
    // taken as a copy of that frame, the return policy applies and the count restarts.
    let m = DjiMotor::new(DjiModel::M2006, 1, cfg).unwrap();
    m.update_feedback(&fb(0x201, 0, 0, 0, 0), T0).unwrap();
    m.update_feedback(&fb(0x201, 4000, 0, 0, 0), T0).unwrap();
    tick(&m, T0);
    tick(&m, T0 + Duration::from_millis(150)); // offline
    m.update_feedback(&fb(0x201, 4000, 0, 0, 0), back).unwrap();
    assert_eq!(m.total_angle_deg(), Some(0.0));
}

#[test]
fn gm6020_with_the_restart_policy_reads_its_true_angle_when_it_returns() {
    // A cable-limited yaw at +160° (raw 3641 ≈ 160.0°) loses power and is turned the long
    // way, through 0, to −160° (raw 4551 = −3641 counts). Continuing would add the wrapped
    // step (+40°) to 160°: 200°. With `Restart`, the absolute encoder says −160°.
    let mut cfg = DjiConfig::default_for(DjiModel::Gm6020Voltage);
    cfg.health = cfg.health.with_on_return(MultiTurnOnReturn::Restart);
    let m = DjiMotor::new(DjiModel::Gm6020Voltage, 1, cfg).unwrap();
    m.update_feedback(&fb(0x205, 3641, 0, 0, 30), T0).unwrap();
    tick(&m, T0);
    assert!((m.total_angle_deg().unwrap() - 160.0).abs() < 0.05);
    tick(&m, T0 + Duration::from_millis(150)); // offline
    let back = T0 + Duration::from_millis(300);
    m.update_feedback(&fb(0x205, 4551, 0, 0, 30), back).unwrap();
    let expect = -3641.0 * 360.0 / 8192.0;
    assert!((m.total_angle_deg().unwrap() - expect).abs() < 1e-3);
    // By default it continues (right for the usual short power cut, and for ranges wider
    // than ±180°): the same return reads 200°.
    let m = DjiMotor::gm6020_voltage(1).unwrap();
    m.update_feedback(&fb(0x205, 3641, 0, 0, 30), T0).unwrap();
    tick(&m, T0);
    tick(&m, T0 + Duration::from_millis(150)); // offline
    m.update_feedback(&fb(0x205, 4551, 0, 0, 30), back).unwrap();
    let expect = (3641.0 + 910.0) * 360.0 / 8192.0;
    assert!((m.total_angle_deg().unwrap() - expect).abs() < 1e-3);
}

#[test]
fn multi_turn_continue_policy_keeps_counting() {
    let m = DjiMotor::m2006(1).unwrap();
    m.update_feedback(&fb(0x201, 0, 0, 0, 0), T0).unwrap();
    m.update_feedback(&fb(0x201, 4000, 0, 0, 0), T0).unwrap();
    tick(&m, T0);
    tick(&m, T0 + Duration::from_millis(150)); // offline
    let back = T0 + Duration::from_millis(300);
    m.update_feedback(&fb(0x201, 4100, 0, 0, 0), back).unwrap();
    let expect = 4100.0 * 360.0 / 8192.0 / 36.0;
    assert!((m.total_angle_deg().unwrap() - expect).abs() < 1e-3);
}

#[test]
fn thermal_derating_halves_limit_at_110c_and_cuts_at_120c() {
    let m = DjiMotor::m3508(1).unwrap();
    m.update_feedback(&fb(0x201, 0, 0, 0, 110), T0).unwrap();
    m.set_target_current(20.0).unwrap();
    // Limit 20 A · (120 - 110) / (120 - 100) = 10 A = 8192 = 0x2000.
    assert_eq!(only_frame(&tick(&m, T0)).1[..2], [0x20, 0x00]);
    m.update_feedback(&fb(0x201, 0, 0, 0, 121), T0).unwrap();
    assert_eq!(only_frame(&tick(&m, T0)).1[..2], [0, 0]);
}

#[test]
fn nan_target_is_refused_and_previous_kept() {
    let m = DjiMotor::m3508(1).unwrap();
    m.set_target_rpm(100.0).unwrap();
    assert_eq!(m.set_target_rpm(f32::NAN), Err(TargetError::NotFinite));
    assert_eq!(
        m.set_target_angle_deg(f32::INFINITY),
        Err(TargetError::NotFinite)
    );
    assert_eq!(m.state().target, 100.0);
    assert_eq!(m.mode(), ControlMode::Speed);
}

#[test]
fn voltage_mode_refuses_current_target_and_vice_versa() {
    let v = DjiMotor::gm6020_voltage(1).unwrap();
    assert_eq!(v.set_target_current(1.0), Err(TargetError::Unsupported));
    let c = DjiMotor::m3508(1).unwrap();
    assert_eq!(c.set_target_voltage(1.0), Err(TargetError::Unsupported));
}

#[test]
fn speed_mode_drives_towards_target() {
    let m = DjiMotor::m3508(1).unwrap();
    online(&m);
    m.set_target_rpm(100.0).unwrap();
    // At rest below target: positive current; above target: negative.
    assert!(m.command_to_raw(m.state().command) == 0);
    tick(&m, T0);
    assert!(m.state().command > 0.0);
    m.update_feedback(&fb(0x201, 0, 3000, 0, 30), T0).unwrap(); // 156 rpm at the output
    for _ in 0..5 {
        tick(&m, T0);
    }
    assert!(m.state().command < 0.0);
}

#[test]
fn disable_sends_zero() {
    let m = DjiMotor::m3508(1).unwrap();
    online(&m);
    m.set_target_current(5.0).unwrap();
    tick(&m, T0);
    m.disable();
    assert_eq!(only_frame(&tick(&m, T0)).1, [0; 8]);
    assert_eq!(m.mode(), ControlMode::Disabled);
}

/// The slot value of a one-frame batch, in raw counts.
fn slot0(b: &TxBatch) -> i16 {
    let (_, d) = only_frame(b);
    i16::from_be_bytes([d[0], d[1]])
}

#[test]
fn current_then_speed_at_present_speed_does_not_run_away() {
    // set_target_current(100) is clamped to 20 A. Then a speed target equal to the present
    // speed: the loop takes over from the 20 A really sent, so once the motor is above the
    // target the command falls at once instead of staying at 20 A.
    let m = DjiMotor::m3508(1).unwrap();
    online(&m);
    m.set_target_current(100.0).unwrap();
    assert_eq!(slot0(&tick(&m, T0)), 16384);
    // Present speed 100 rpm at the output = 1920 rotor rpm.
    m.update_feedback(&fb(0x201, 0, 1920, 0, 30), T0).unwrap();
    m.set_target_rpm(100.0).unwrap();
    // The motor accelerates past the target: 150 rpm (2880 rotor rpm).
    m.update_feedback(&fb(0x201, 0, 2880, 0, 30), T0).unwrap();
    let raw = slot0(&tick(&m, T0 + Duration::from_millis(1)));
    // kp 0.6 A/rpm · -50 rpm = -30 A on top of 20 A: well below full scale (was 16384).
    assert!(raw < 16384 / 2, "raw {raw}");
}

#[test]
fn derating_is_the_limit_the_speed_loop_winds_against() {
    // 110 °C: the limit is 10 A. A stalled motor far from its speed target must not wind its
    // integral up to the loop's own 20 A, or the command jumps to 20 A when it cools.
    let m = DjiMotor::m3508(1).unwrap();
    m.update_feedback(&fb(0x201, 0, 0, 0, 110), T0).unwrap();
    m.set_target_rpm(5.0).unwrap(); // small error: the integral does the work
    for k in 0..3000 {
        let b = tick(&m, T0 + Duration::from_millis(k / 2));
        assert!(slot0(&b) <= 8192); // never above 10 A
        m.update_feedback(&fb(0x201, 0, 0, 0, 110), T0 + Duration::from_millis(k / 2))
            .unwrap();
    }
    assert!(m.speed_loop_terms().i <= 10.0 + 1e-4);
    // Cooled down: the command continues from about 10 A instead of jumping to 20 A.
    let now = T0 + Duration::from_millis(1600);
    m.update_feedback(&fb(0x201, 0, 0, 0, 40), now).unwrap();
    let raw = slot0(&tick(&m, now));
    assert!(raw < 8192 + 400, "raw {raw} after cooling");
}

#[test]
fn user_current_limit_caps_the_command_and_is_validated() {
    let m = DjiMotor::m3508(2).unwrap();
    online_id(&m, 0x202);
    m.set_target_current(15.0).unwrap();
    m.set_current_limit_amps(5.0).unwrap();
    // 5 A = 4096 counts in slot 1 of 0x200.
    let (_, d) = only_frame(&tick(&m, T0));
    assert_eq!(i16::from_be_bytes([d[2], d[3]]), 4096);
    assert_eq!(m.state().command, 5.0);
    assert_eq!(m.set_current_limit_amps(-1.0), Err(TargetError::OutOfRange));
    assert_eq!(
        m.set_current_limit_amps(f32::NAN),
        Err(TargetError::NotFinite)
    );
    m.set_current_limit_amps(f32::INFINITY).unwrap();
    let (_, d) = only_frame(&tick(&m, T0));
    assert_eq!(i16::from_be_bytes([d[2], d[3]]), 12288); // 15 A
    let gm = DjiMotor::gm6020_voltage(1).unwrap();
    assert_eq!(
        gm.set_current_limit_amps(1.0),
        Err(TargetError::Unsupported)
    );
}

fn online_id(m: &DjiMotor, id: u16) {
    m.update_feedback(&fb(id, 0, 0, 0, 30), T0).unwrap();
}

#[test]
fn gm6020_voltage_limit_in_volts_and_raw_target() {
    let m = DjiMotor::gm6020_voltage(1).unwrap();
    online_id(&m, 0x205);
    // Raw 12345 counts go out as 12345 (exact round trip through volts).
    m.set_target_raw(12345).unwrap();
    assert_eq!(slot0(&tick(&m, T0)), 12345);
    m.set_target_raw(-30000).unwrap();
    assert_eq!(slot0(&tick(&m, T0)), -25000); // the default raw limit
    // 6 V limit = 7500 counts at 30000 ↔ 24 V.
    m.set_voltage_limit_volts(6.0).unwrap();
    m.set_target_voltage(20.0).unwrap();
    assert_eq!(slot0(&tick(&m, T0)), 7500);
    assert_eq!(
        DjiMotor::m3508(1).unwrap().set_voltage_limit_volts(6.0),
        Err(TargetError::Unsupported)
    );
}

#[test]
fn gm6020_voltage_limit_outside_the_protocol_range_is_rejected() {
    // The 2018 manual's range is ±30000: 30001 and up are not commands the motor defines.
    for limit in [0, -100, 30001, i16::MAX] {
        let mut cfg = DjiConfig::default_for(DjiModel::Gm6020Voltage);
        cfg.voltage_raw_limit = limit;
        assert_eq!(
            DjiMotor::new(DjiModel::Gm6020Voltage, 1, cfg).unwrap_err(),
            DjiError::InvalidVoltageLimit
        );
    }
    for limit in [1, 30000] {
        let mut cfg = DjiConfig::default_for(DjiModel::Gm6020Voltage);
        cfg.voltage_raw_limit = limit;
        assert!(DjiMotor::new(DjiModel::Gm6020Voltage, 1, cfg).is_ok());
    }
    // Irrelevant for the other models.
    let mut cfg = DjiConfig::default_for(DjiModel::M3508);
    cfg.voltage_raw_limit = 0;
    assert!(DjiMotor::new(DjiModel::M3508, 1, cfg).is_ok());
}

#[test]
fn gm6020_defaults_to_its_absolute_encoder_origin() {
    // Raw 2048 is 90° from the default zero offset 0, at every power-on.
    let m = DjiMotor::gm6020_voltage(1).unwrap();
    m.update_feedback(&fb(0x205, 2048, 0, 0, 30), T0).unwrap();
    assert!((m.angle_deg().unwrap() - 90.0).abs() < 1e-4);
    // A geared M3508 starts at 0 wherever its rotor is.
    let w = DjiMotor::m3508(1).unwrap();
    w.update_feedback(&fb(0x201, 2048, 0, 0, 30), T0).unwrap();
    assert_eq!(w.total_angle_deg(), Some(0.0));
}

#[test]
fn torque_target_goes_through_the_torque_constant() {
    // M3508: 3 N·m / 0.3 N·m/A = 10 A = 8192 counts.
    let m = DjiMotor::m3508(1).unwrap();
    online(&m);
    m.set_target_torque_nm(3.0).unwrap();
    assert_eq!(slot0(&tick(&m, T0)), 8192);
    assert_eq!(m.mode(), ControlMode::Current);
    // GM6020 current mode: 0.741 N·m = 1 A = 16384 / 3 = 5461.3 → 5461.
    let g = DjiMotor::gm6020_current(1).unwrap();
    online_id(&g, 0x205);
    g.set_target_torque_nm(0.741).unwrap();
    assert_eq!(slot0(&tick(&g, T0)), 5461);
    let v = DjiMotor::gm6020_voltage(1).unwrap();
    assert_eq!(v.set_target_torque_nm(1.0), Err(TargetError::Unsupported));
    assert_eq!(
        m.set_target_torque_nm(f32::NAN),
        Err(TargetError::NotFinite)
    );
}

#[test]
fn feed_forward_torque_holds_in_speed_mode() {
    // A pitch arm needing 0.6 N·m: M2006 0.18 N·m/A → 3.333 A = 3333 counts at zero error.
    let m = DjiMotor::m2006(1).unwrap();
    online(&m);
    m.set_feed_forward_torque_nm(0.6).unwrap();
    m.set_target_rpm(0.0).unwrap();
    assert_eq!(slot0(&tick(&m, T0)), 3333);
    // GM6020 voltage mode, from the published torque–speed line: at 24 V it stalls at
    // 320 rpm / 156 rpm/(N·m) = 2.05 N·m, so 1 N·m takes 24 · 156 / 320 = 11.7 V = 14625
    // counts (30000 ↔ 24 V).
    let g = DjiMotor::gm6020_voltage(1).unwrap();
    online_id(&g, 0x205);
    g.set_feed_forward_torque_nm(1.0).unwrap();
    g.set_target_rpm(0.0).unwrap();
    assert_eq!(slot0(&tick(&g, T0)), 14625);
    // Not in open-loop modes.
    m.set_target_current(1.0).unwrap();
    assert_eq!(slot0(&tick(&m, T0)), 1000);
}

#[test]
fn homing_through_the_trait_moves_the_total_angle_origin() {
    let m = DjiMotor::m3508(1).unwrap();
    m.update_feedback(&fb(0x201, 100, 0, 0, 30), T0).unwrap();
    m.update_feedback(&fb(0x201, 3000, 0, 0, 30), T0).unwrap(); // +2900 counts ≈ 6.6°
    assert!(m.total_angle_deg().unwrap() > 1.0);
    m.set_total_angle_here_deg(-90.0).unwrap();
    assert!(m.total_angle_deg().unwrap() > 1.0); // recorded, not applied yet
    tick(&m, T0);
    assert!((m.total_angle_deg().unwrap() + 90.0).abs() < 0.01);
    // A total-angle target of -90° is now "here": next to no current asked (the homed
    // position is rounded to a rotor count, 0.002° at the output).
    m.set_target_total_angle_deg(-90.0).unwrap();
    tick(&m, T0);
    assert!(slot0(&tick(&m, T0)).abs() <= 5);
    // Whereas 0° is now 90° away: the angle loop asks for speed.
    // (the angle loop runs every 10th tick).
    m.set_target_total_angle_deg(0.0).unwrap();
    let most = (0..10).map(|_| slot0(&tick(&m, T0))).max().unwrap();
    assert!(most > 1000, "{most}");
    assert_eq!(
        m.set_total_angle_here_deg(f32::INFINITY),
        Err(TargetError::NotFinite)
    );
}

#[test]
fn homing_while_holding_a_total_angle_gives_no_derivative_kick() {
    // An angle loop with D: kp 8 rpm/°, kd 0.1 rpm/(°/s), limited to 400 rpm, run every 10th
    // tick (10 ms). The motor holds 0° (error 0); then the target and the homed reading both
    // become 50°, together: still no error, and the shaft has not moved. Differentiating the
    // reading's 50° jump would ask -0.1 · 50° / 0.01 s = -500 rpm (limited to -400).
    let mut cfg = DjiConfig::default_for(DjiModel::M3508);
    cfg.cascade.angle = PidConfig::new(8.0, 0.0, 0.1).with_output_limit(400.0);
    let m = DjiMotor::new(DjiModel::M3508, 1, cfg).unwrap();
    online(&m);
    m.set_target_total_angle_deg(2.0).unwrap();
    tick(&m, T0); // the first tick in the mode runs the angle loop: p = 8 · 2° = 16 rpm
    assert!((m.angle_loop_terms().p - 16.0).abs() < 0.1);
    m.set_target_total_angle_deg(0.0).unwrap();
    for _ in 0..10 {
        tick(&m, T0);
    }
    assert!(m.angle_loop_terms().output.abs() < 0.1); // the 10th ran it again, at 0°
    m.set_target_total_angle_deg(50.0).unwrap();
    m.set_total_angle_here_deg(50.0).unwrap();
    for _ in 0..10 {
        tick(&m, T0); // the first homes; the 10th runs the angle loop
    }
    assert!((m.total_angle_deg().unwrap() - 50.0).abs() < 0.01);
    let terms = m.angle_loop_terms();
    assert_eq!(terms.d, 0.0);
    // P: the homed reading is rounded to a rotor count (0.002° at the output).
    assert!(terms.output.abs() < 0.1, "{terms:?}");
}

#[test]
fn live_speed_gains_apply_from_the_next_tick() {
    let m = DjiMotor::m3508(1).unwrap();
    online(&m);
    m.set_target_rpm(10.0).unwrap();
    // Default kp 0.6 A/rpm, ki 8: first tick 6 A + 0.08 A.
    assert_eq!(slot0(&tick(&m, T0)), 4981); // 6.08 A · 819.2
    m.set_speed_pid(PidConfig::new(0.2, 0.0, 0.0).with_output_limit(20.0))
        .unwrap();
    // kp 0.2: 2 A plus the 0.08 A integral kept = 2.08 A = 1704 counts.
    assert_eq!(slot0(&tick(&m, T0)), 1704);
    assert!(m.set_speed_pid(PidConfig::new(f32::NAN, 0.0, 0.0)).is_err());
}

#[test]
fn m2006_at_full_speed_keeps_its_total_angle_through_lost_frames() {
    // 18 000 rotor rpm (500 rpm at the output) = 2457.6 counts per ms. Frames arrive every
    // ms except that 1, 2 or 3 in a row are lost now and then; the total angle must match
    // the true rotation exactly (to the count).
    let m = DjiMotor::m2006(1).unwrap();
    let counts_per_ms = 18_000.0f64 / 60.0 * 8192.0 / 1000.0;
    let mut t_ms = 0u64;
    let mut sent = 0u32;
    for k in 0..600u64 {
        let lost = [0, 0, 1, 0, 2, 0, 0, 3][(k % 8) as usize];
        t_ms += 1 + lost;
        let true_counts = (counts_per_ms * t_ms as f64).round() as i64;
        let raw = true_counts.rem_euclid(8192) as u16;
        let now = T0 + Duration::from_millis(t_ms);
        m.update_feedback(&fb(0x201, raw, 18_000, 0, 0), now)
            .unwrap();
        sent += 1;
        if k == 0 {
            continue;
        }
        let first = (counts_per_ms * 1.0).round() as i64; // power-on origin at t = 1 ms
        let expect_deg = (true_counts - first) as f64 * 360.0 / 8192.0 / 36.0;
        let got = f64::from(m.total_angle_deg().unwrap());
        assert!(
            (got - expect_deg).abs() < 0.05,
            "frame {k}: {got} vs {expect_deg}"
        );
    }
    assert_eq!(sent, 600);
}

#[test]
fn m3508_at_full_speed_keeps_its_total_angle_through_lost_frames() {
    // 9 256 rotor rpm backwards (C620 no-load 482 rpm at the output), 3 frames lost in a row.
    let m = DjiMotor::m3508(1).unwrap();
    let counts_per_ms = -9_256.0f64 / 60.0 * 8192.0 / 1000.0;
    let mut t_ms = 0u64;
    for _ in 0..300 {
        t_ms += 4;
        let true_counts = (counts_per_ms * t_ms as f64).round() as i64;
        let now = T0 + Duration::from_millis(t_ms);
        m.update_feedback(
            &fb(0x201, true_counts.rem_euclid(8192) as u16, -9256, 0, 30),
            now,
        )
        .unwrap();
    }
    let first = (counts_per_ms * 4.0).round() as i64;
    let true_counts = (counts_per_ms * t_ms as f64).round() as i64;
    let expect_deg = (true_counts - first) as f64 * 360.0 * 187.0 / (8192.0 * 3591.0);
    let got = f64::from(m.total_angle_deg().unwrap());
    assert!((got - expect_deg).abs() < 0.05, "{got} vs {expect_deg}");
}

#[test]
fn feedback_stamped_far_ahead_does_not_keep_the_motor_online() {
    let m = DjiMotor::m3508(1).unwrap();
    m.set_target_current(5.0).unwrap();
    m.update_feedback(&fb(0x201, 0, 0, 0, 30), T0 + Duration::from_secs(3600))
        .unwrap();
    assert_ne!(slot0(&tick(&m, T0)), 0); // fresh now…
    // …but nothing else arrives: offline and zero one timeout later.
    assert_eq!(slot0(&tick(&m, T0 + Duration::from_millis(101))), 0);
    assert!(!m.is_online());
}

#[test]
fn state_reports_none_for_what_has_not_been_measured() {
    let m = DjiMotor::m3508(1).unwrap();
    let s = m.state();
    assert_eq!(
        (
            s.angle_deg,
            s.total_angle_deg,
            s.current_amps,
            s.temperature_c
        ),
        (None, None, None, None)
    );
    online(&m);
    let s = m.state();
    assert_eq!(s.angle_deg, Some(0.0));
    assert_eq!(s.current_amps, Some(0.0));
    assert_eq!(s.temperature_c, Some(30.0));
    // The C610 never reports a temperature.
    let w = DjiMotor::m2006(1).unwrap();
    online(&w);
    assert_eq!(w.state().temperature_c, None);
}

#[test]
fn m2006_total_angle_survives_frames_read_late() {
    // Full speed (2457.6 counts per 1 ms frame); the receiver is held up now and then and
    // reads frames up to 1.7 ms late (stamped when read). Ticks run every 1 ms meanwhile.
    let m = DjiMotor::m2006(1).unwrap();
    let counts_per_ms = 18_000.0f64 / 60.0 * 8192.0 / 1000.0;
    let mut last_stamp_us = 0u64;
    for k in 1..=500u64 {
        let late_us = [0, 0, 1700, 900, 0, 300, 0, 0, 1200, 0][(k % 10) as usize];
        let stamp_us = (k * 1000 + late_us).max(last_stamp_us);
        last_stamp_us = stamp_us;
        tick(&m, T0 + Duration::from_micros(k * 1000));
        let true_counts = (counts_per_ms * k as f64).round() as i64;
        let raw = true_counts.rem_euclid(8192) as u16;
        m.update_feedback(
            &fb(0x201, raw, 18_000, 0, 0),
            T0 + Duration::from_micros(stamp_us),
        )
        .unwrap();
        let first = counts_per_ms.round() as i64;
        let expect_deg = (true_counts - first) as f64 * 360.0 / 8192.0 / 36.0;
        let got = f64::from(m.total_angle_deg().unwrap());
        assert!(
            (got - expect_deg).abs() < 0.05,
            "frame {k}: {got} vs {expect_deg}"
        );
    }
}

#[test]
fn a_far_future_stamp_does_not_corrupt_the_total_angle() {
    // M3508 at full speed; one frame is stamped an hour ahead. Its timing is not trusted
    // (taken as one period), so counting goes on exactly.
    let m = DjiMotor::m3508(1).unwrap();
    let counts_per_ms = 9_256.0f64 / 60.0 * 8192.0 / 1000.0;
    for k in 1..=100u64 {
        let now = T0 + Duration::from_millis(k);
        tick(&m, now);
        let true_counts = (counts_per_ms * k as f64).round() as i64;
        let stamp = if k == 50 {
            now + Duration::from_secs(3600)
        } else {
            now
        };
        m.update_feedback(
            &fb(0x201, true_counts.rem_euclid(8192) as u16, 9256, 0, 30),
            stamp,
        )
        .unwrap();
    }
    let first = counts_per_ms.round() as i64;
    let true_counts = (counts_per_ms * 100.0).round() as i64;
    let expect_deg = (true_counts - first) as f64 * 360.0 * 187.0 / (8192.0 * 3591.0);
    let got = f64::from(m.total_angle_deg().unwrap());
    assert!((got - expect_deg).abs() < 0.05, "{got} vs {expect_deg}");
}

#[test]
fn a_frame_delivered_twice_does_not_add_a_turn() {
    // M2006 at 17 000 rotor rpm (472 rpm at the output, below its 500 rpm no-load speed):
    // 2321.07 counts per 1 ms frame. Every frame comes twice (CAN repeats a frame whose last
    // bit met an error), the copy read 0.13 ms later, or 0.6 ms later behind a busy
    // receiver. A copy is a step of 0; three periods (6963 counts, 0.85 of a turn) would
    // explain it almost as well as one.
    for copy_after_us in [130, 600] {
        let m = DjiMotor::m2006(1).unwrap();
        let counts_per_ms = 17_000.0f64 / 60.0 * 8192.0 / 1000.0;
        for k in 1..=50u64 {
            let now = T0 + Duration::from_millis(k);
            tick(&m, now);
            let raw = ((counts_per_ms * k as f64).round() as i64).rem_euclid(8192) as u16;
            let frame = fb(0x201, raw, 17_000, 0, 0);
            m.update_feedback(&frame, now).unwrap();
            m.update_feedback(&frame, now + Duration::from_micros(copy_after_us))
                .unwrap();
        }
        // 49 frames' worth of travel after the first, at 36:1.
        let first = counts_per_ms.round() as i64;
        let true_counts = (counts_per_ms * 50.0).round() as i64;
        let expect_deg = (true_counts - first) as f64 * 360.0 / (8192.0 * 36.0);
        let got = f64::from(m.total_angle_deg().unwrap());
        assert!((got - expect_deg).abs() < 0.05, "{got} vs {expect_deg}");
    }
}

#[test]
fn a_frame_older_than_the_last_one_taken_is_rejected_and_changes_nothing() {
    // M3508 at full speed (9256 rotor rpm, 1263.7 counts a frame). After each fresh frame, a
    // transport that stamps frames itself hands over an old one (2 to 10 ms old, with its
    // old contents and stamp): unwrapped against the newer reading it could count a turn.
    // Rejected, it changes nothing, and counting goes on exactly.
    let m = DjiMotor::m3508(1).unwrap();
    let counts_per_ms = 9_256.0f64 / 60.0 * 8192.0 / 1000.0;
    let frame_at = |k: u64| {
        let counts = (counts_per_ms * k as f64).round() as i64;
        fb(0x201, counts.rem_euclid(8192) as u16, 9256, 0, 30)
    };
    for k in 1..=100u64 {
        let now = T0 + Duration::from_millis(k);
        tick(&m, now);
        m.update_feedback(&frame_at(k), now).unwrap();
        if k > 10 {
            let age = 2 + k % 9;
            let before = m.state();
            assert_eq!(
                m.update_feedback(&frame_at(k - age), now - Duration::from_millis(age)),
                Err(FrameError::OutOfOrder)
            );
            assert_eq!(m.state(), before);
        }
    }
    let first = counts_per_ms.round() as i64;
    let true_counts = (counts_per_ms * 100.0).round() as i64;
    let expect_deg = (true_counts - first) as f64 * 360.0 * 187.0 / (8192.0 * 3591.0);
    let got = f64::from(m.total_angle_deg().unwrap());
    assert!((got - expect_deg).abs() < 0.05, "{got} vs {expect_deg}");
    // The same stamp as the newest is not older: a copy read at once is taken (as no step).
    let now = T0 + Duration::from_millis(100);
    assert_eq!(m.update_feedback(&frame_at(100), now), Ok(()));
}

#[test]
fn lowered_gm6020_voltage_limit_is_what_the_speed_loop_winds_against() {
    // Limit 3 V (3750 counts at 30000 ↔ 24 V); a stalled gimbal asked for a small speed.
    let m = DjiMotor::gm6020_voltage(1).unwrap();
    m.set_voltage_limit_volts(3.0).unwrap();
    m.set_target_rpm(2.0).unwrap();
    for k in 0..3000u64 {
        let now = T0 + Duration::from_micros(k * 500);
        m.update_feedback(&fb(0x205, 0, 0, 0, 30), now).unwrap();
        assert!(slot0(&tick(&m, now)) <= 3750);
    }
    assert!(m.speed_loop_terms().i <= 3.0 + 1e-4);
    // Limit lifted: the command continues from about 3 V instead of jumping to the 20 V the
    // loop would have wound up to against its own limit.
    m.set_voltage_limit_volts(f32::INFINITY).unwrap();
    let now = T0 + Duration::from_millis(1600);
    m.update_feedback(&fb(0x205, 0, 0, 0, 30), now).unwrap();
    let raw = slot0(&tick(&m, now));
    assert!(raw < 3750 + 300, "raw {raw} after the limit was lifted");
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    /// One thing an application or the bus can do to a motor.
    #[derive(Debug, Clone)]
    enum Op {
        Current(f32),
        Voltage(f32),
        Rpm(f32),
        Angle(f32),
        Total(f32),
        Torque(f32),
        FeedForward(f32),
        Limit(f32),
        Disable,
        Feedback { angle: u16, rpm: i16, temp: u8 },
        Silence(u64),
    }

    fn any_f32() -> impl Strategy<Value = f32> {
        prop_oneof![
            -1e6f32..1e6,
            Just(f32::NAN),
            Just(f32::INFINITY),
            Just(f32::NEG_INFINITY),
            Just(f32::MAX),
            Just(-f32::MAX),
            -50.0f32..50.0,
        ]
    }

    fn op() -> impl Strategy<Value = Op> {
        prop_oneof![
            any_f32().prop_map(Op::Current),
            any_f32().prop_map(Op::Voltage),
            any_f32().prop_map(Op::Rpm),
            any_f32().prop_map(Op::Angle),
            any_f32().prop_map(Op::Total),
            any_f32().prop_map(Op::Torque),
            any_f32().prop_map(Op::FeedForward),
            any_f32().prop_map(Op::Limit),
            Just(Op::Disable),
            (0u16..8192, any::<i16>(), 0u8..140).prop_map(|(angle, rpm, temp)| Op::Feedback {
                angle,
                rpm,
                temp
            }),
            (1u64..300).prop_map(Op::Silence),
        ]
    }

    proptest! {
        /// Whatever the targets, limits, mode switches and feedback, the slot value on the wire
        /// is within the ESC's range, and exactly zero while the motor is offline.
        #[test]
        fn packed_command_stays_in_range_and_is_zero_offline(
            model in prop_oneof![
                Just(DjiModel::M3508),
                Just(DjiModel::M2006),
                Just(DjiModel::Gm6020Voltage),
                Just(DjiModel::Gm6020Current),
            ],
            ops in proptest::collection::vec(op(), 1..200),
        ) {
            let m = DjiMotor::new(model, 1, DjiConfig::default_for(model)).unwrap();
            let id = model.feedback_id(1);
            let range: i16 = match model {
                DjiModel::M3508 | DjiModel::Gm6020Current => 16384,
                DjiModel::M2006 => 10000,
                DjiModel::Gm6020Voltage => 25000,
            };
            let mut now = T0;
            for op in ops {
                match op {
                    Op::Current(x) => { let _ = m.set_target_current(x); }
                    Op::Voltage(x) => { let _ = m.set_target_voltage(x); }
                    Op::Rpm(x) => { let _ = m.set_target_rpm(x); }
                    Op::Angle(x) => { let _ = m.set_target_angle_deg(x); }
                    Op::Total(x) => { let _ = m.set_target_total_angle_deg(x); }
                    Op::Torque(x) => { let _ = m.set_target_torque_nm(x); }
                    Op::FeedForward(x) => { let _ = m.set_feed_forward_torque_nm(x); }
                    Op::Limit(x) => {
                        let _ = m.set_current_limit_amps(x);
                        let _ = m.set_voltage_limit_volts(x);
                    }
                    Op::Disable => m.disable(),
                    Op::Feedback { angle, rpm, temp } => {
                        m.update_feedback(&fb(id, angle, rpm, 0, temp), now).unwrap();
                    }
                    Op::Silence(ms) => now += Duration::from_millis(ms),
                }
                now += Duration::from_millis(1);
                let raw = slot0(&tick(&m, now));
                prop_assert!((-range..=range).contains(&raw), "{raw} outside ±{range}");
                prop_assert!(m.state().command.is_finite());
                if !m.is_online() {
                    prop_assert_eq!(raw, 0);
                }
            }
        }
    }
}

#[test]
fn feedback_at_the_end_of_time_is_counted_not_a_panic() {
    // Was a panic: the trust check added 2 ms to the last tick's stamp (`Instant + Duration`
    // panics on overflow).
    let m = DjiMotor::m3508(1).unwrap();
    let id = m.model().feedback_id(1);
    let end = Instant::from_ticks(u64::MAX);
    m.update_feedback(&fb(id, 0, 0, 0, 30), end).unwrap();
    tick(&m, end);
    m.update_feedback(&fb(id, 100, 0, 0, 30), end).unwrap();
    assert!(m.is_online());
    assert!(m.total_angle_deg().unwrap() > 0.0);
}

/// Runs `motor` (an M2006 or M3508 with ESC id 1) for 60 ms at a constant `rotor_rpm` with
/// its ESC sending every 1 ms, `phase_us` after each whole millisecond, while the receive
/// path stalls in `[stall_from_us, stall_to_us)`: frames that come meanwhile wait in a
/// 3-deep FIFO (later ones are lost) and are read, and stamped, when the stall ends; every
/// other frame is stamped on arrival. Ticks every 1 ms. After every frame taken the
/// multi-turn angle must be the rotor's true travel since the first frame, at the gear.
fn run_through_a_receive_stall(
    motor: &DjiMotor,
    rotor_rpm: i16,
    phase_us: u64,
    (stall_from_us, stall_to_us): (u64, u64),
) {
    let counts_per_ms = f64::from(rotor_rpm) / 60.0 * 8192.0 / 1000.0;
    let gear = f64::from(motor.model().gear().as_f32());
    let counts_at = |k: u64| (counts_per_ms * k as f64).round() as i64;
    let mut fifo: Vec<(u64, i64)> = Vec::new(); // (frame index, true counts)
    let mut taken = Vec::new(); // (frame index, stamp µs)
    let check = |k: u64| {
        let expect_deg = (counts_at(k) - counts_at(1)) as f64 * 360.0 / 8192.0 / gear;
        let got = f64::from(motor.total_angle_deg().unwrap());
        assert!(
            (got - expect_deg).abs() < 0.05,
            "{rotor_rpm} rpm, stall {stall_from_us}..{stall_to_us} µs, frame {k}: \
             {got}° vs {expect_deg}°"
        );
    };
    let frame = |counts: i64| fb(0x201, counts.rem_euclid(8192) as u16, rotor_rpm, 0, 30);
    for ms in 1..=60u64 {
        let now_us = ms * 1000;
        tick(motor, T0 + Duration::from_micros(now_us));
        let arrival_us = now_us + phase_us;
        // The stall is over before this frame comes: the backlog is read first.
        if arrival_us >= stall_to_us && !fifo.is_empty() {
            for (k, counts) in fifo.drain(..) {
                motor
                    .update_feedback(&frame(counts), T0 + Duration::from_micros(stall_to_us))
                    .unwrap();
                taken.push((k, stall_to_us));
                check(k);
            }
        }
        if (stall_from_us..stall_to_us).contains(&arrival_us) {
            if fifo.len() < 3 {
                fifo.push((ms, counts_at(ms)));
            }
            continue;
        }
        motor
            .update_feedback(
                &frame(counts_at(ms)),
                T0 + Duration::from_micros(arrival_us),
            )
            .unwrap();
        taken.push((ms, arrival_us));
        check(ms);
    }
    // The stall really held frames back and lost some.
    assert!(taken.len() < 60 && taken.iter().any(|&(k, at)| at > k * 1000 + phase_us + 1000));
}

#[test]
fn multi_turn_counting_survives_a_stalled_receive_path() {
    // The frames of a backlog are read late, stamped when the stall ends: the first one
    // follows the last frame taken however late its stamp, and the first frame read on
    // time after a backlog that overflowed is timed from when the backlog came, not from
    // its late stamps. (Speeds where one period and the stall's length fit a reading alike
    // are the documented limit and left out: -16 500 rpm with a 13 ms stall is one.)
    type Case = (fn() -> DjiMotor, i16, u64, (u64, u64)); // motor, rpm, phase, stall (µs)
    let cases: [Case; 8] = [
        // M2006 near full speed (2400 counts a period): read 4.6 ms late, then 10 ms.
        (
            || DjiMotor::m2006(1).unwrap(),
            17_578,
            300,
            (20_000, 24_650),
        ),
        (
            || DjiMotor::m2006(1).unwrap(),
            17_578,
            300,
            (20_000, 30_650),
        ),
        (
            || DjiMotor::m2006(1).unwrap(),
            -16_500,
            700,
            (20_200, 26_200),
        ),
        (
            || DjiMotor::m2006(1).unwrap(),
            13_000,
            300,
            (20_000, 24_800),
        ),
        // M3508 at full speed (1264 counts a period), and at 3600 rpm (492 counts: once
        // taken by the low-speed shortcut around the stamped gap).
        (|| DjiMotor::m3508(1).unwrap(), 9_256, 100, (20_000, 28_600)),
        (|| DjiMotor::m3508(1).unwrap(), 3_600, 100, (20_000, 28_500)),
        (
            || DjiMotor::m3508(1).unwrap(),
            -3_600,
            500,
            (20_000, 28_000),
        ),
        // Slow: nothing to decide, and nothing must go wrong.
        (|| DjiMotor::m3508(1).unwrap(), 200, 100, (20_000, 40_500)),
    ];
    for (motor, rpm, phase_us, stall) in cases {
        run_through_a_receive_stall(&motor(), rpm, phase_us, stall);
    }
}

#[test]
fn a_backlog_holding_a_repeat_keeps_the_count_exact() {
    // CAN repeats a frame whose last bit met an error; here the repeat lands in the FIFO
    // just as the receive path stalls, and is read 6 ms later with the frames behind it.
    // It is a copy (no step), and the frames after it keep counting exactly.
    let m = DjiMotor::m2006(1).unwrap();
    let counts_per_ms = 17_000.0f64 / 60.0 * 8192.0 / 1000.0;
    let counts_at = |k: u64| (counts_per_ms * k as f64).round() as i64;
    let frame = |k: u64| fb(0x201, counts_at(k).rem_euclid(8192) as u16, 17_000, 0, 0);
    let at = |us: u64| T0 + Duration::from_micros(us);
    for k in 1..=10 {
        tick(&m, at(k * 1000));
        m.update_feedback(&frame(k), at(k * 1000 + 300)).unwrap();
    }
    // Stall from 10.4 ms to 16.6 ms: the repeat of frame 10 and frames 11 and 12 wait;
    // 13 to 16 are lost.
    for k in [10, 11, 12] {
        m.update_feedback(&frame(k), at(16_600)).unwrap();
    }
    for k in 17..=30 {
        tick(&m, at(k * 1000));
        m.update_feedback(&frame(k), at(k * 1000 + 300)).unwrap();
        let expect_deg = (counts_at(k) - counts_at(1)) as f64 * 360.0 / (8192.0 * 36.0);
        let got = f64::from(m.total_angle_deg().unwrap());
        assert!(
            (got - expect_deg).abs() < 0.05,
            "frame {k}: {got} vs {expect_deg}"
        );
    }
}

#[test]
fn a_stamp_ahead_of_the_tick_does_not_stretch_the_next_gap() {
    // M2006 at 15 000 rotor rpm: 2048 counts a period, so 1, 5 and 9 periods all fit a step
    // of 2048 counts (0, 1 and 2 turns more). Frame 50 is stamped 10 ms ahead; the next tick
    // pulls its time back to the tick's. Frame 51, on time, is 1 period on: timed from that
    // frame's estimated arrival left where the far stamp put it, it would look 10 periods on
    // and the tie would go to 9 (two turns).
    let m = DjiMotor::m2006(1).unwrap();
    let counts_per_ms = 15_000.0f64 / 60.0 * 8192.0 / 1000.0;
    for k in 1..=60u64 {
        let now = T0 + Duration::from_millis(k);
        tick(&m, now);
        let counts = (counts_per_ms * k as f64).round() as i64;
        let stamp = if k == 50 {
            now + Duration::from_millis(10)
        } else {
            now
        };
        m.update_feedback(
            &fb(0x201, counts.rem_euclid(8192) as u16, 15_000, 0, 0),
            stamp,
        )
        .unwrap();
    }
    let expect_deg = (counts_per_ms * 59.0).round() * 360.0 / (8192.0 * 36.0);
    let got = f64::from(m.total_angle_deg().unwrap());
    assert!((got - expect_deg).abs() < 0.05, "{got} vs {expect_deg}");
}
