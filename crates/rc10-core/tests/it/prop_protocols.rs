//! Property tests: pack → parse round trips for every wire protocol rc10-core speaks.
//!
//! Every frame is built (or decoded) here, bit by bit, from the protocol documents — SPEC.md's
//! "Protocol and physical facts" for DJI and Damiao, the VESC firmware's `comm_can` packets
//! for VESC, the DR16 / SBUS / PPM / VOFA+ layouts in rc10's module docs — never by calling
//! the code under test. Covered:
//!
//! - DJI feedback (C620/C610/GM6020): angle, rotor rpm, torque current, temperature, the
//!   feedback ID; malformed frames (DLC, angle ≥ 8192) rejected without effect.
//! - DJI command slots: the int16 big-endian slot value equals `round(command · counts per
//!   unit)` clamped to the ESC's range, on the right command ID and slot, other slots zero.
//! - VESC STATUS (packet 9) and STATUS_4 (packet 16) parsing; VESC command frames (SET_DUTY,
//!   SET_CURRENT, SET_CURRENT_BRAKE, SET_RPM, SET_POS) decoded back to the value, with
//!   saturation instead of wrap for values beyond the i32 range.
//! - Damiao MIT: command pack decoded field by field (within one quantisation step of the
//!   clamped target); feedback parsing (position, velocity, torque, temperatures, state
//!   codes); multi-turn unwrapping of the ±PMAX position through feedback frames.
//! - DBUS (DR16 18-byte frames) and SBUS (25-byte frames) encoded from field values and parsed
//!   back equal, directly and byte by byte through the receivers (gap framing, failsafe).
//! - PPM: pulse trains with sync gaps decode to the pulse widths; corrupted frames are dropped
//!   alone, the next frame decodes.
//! - VOFA+ JustFloat (bit-exact) and FireWater (within the printed decimals) parsed back.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use proptest::prelude::*;
use proptest::test_runner::Config;
use rc10_core::can::CanFrame;
use rc10_core::encoder::{GearRatio, Origin};
use rc10_core::motor::Motor;
use rc10_core::motor::dji::{DjiConfig, DjiModel, DjiMotor};
use rc10_core::motor::dm::{
    DmConfig, DmFault, DmMotor, DmStatus, KD_MAX, KP_MAX, MitCommand, MitLimits,
};
use rc10_core::motor::vesc::{VescCommand, VescConfig, VescMotor, VescStatusSet};
use rc10_core::node::{CanNode, FrameError, TxBatch};
use rc10_core::remote::FRAME_GAP;
use rc10_core::remote::dbus::{DbusFrame, DbusReceiver, Switch};
use rc10_core::remote::ppm::{PpmError, PpmReceiver};
use rc10_core::remote::sbus::{SbusFrame, SbusReceiver};
use rc10_core::telemetry::{BufferTooSmall, firewater, justfloat};
use rc10_core::time::{Duration, Instant};
use std::f64::consts::{PI, TAU};

/// `cases` cases (or `PROPTEST_CASES` if set, for a longer run); failures are not persisted
/// to files (a case worth keeping becomes a plain test).
fn config(cases: u32) -> Config {
    Config {
        cases: std::env::var("PROPTEST_CASES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(cases),
        failure_persistence: None,
        ..Config::default()
    }
}

const T0: Instant = Instant::from_millis(1000);

/// Smallest distance between two angles in degrees, around the circle.
fn circular_gap_deg(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    d.min(360.0 - d)
}

// ---------------------------------------------------------------------------------------------
// DJI (SPEC.md: C620/C610/GM6020)
// ---------------------------------------------------------------------------------------------

fn dji_model() -> impl Strategy<Value = DjiModel> {
    prop_oneof![
        Just(DjiModel::M3508),
        Just(DjiModel::M2006),
        Just(DjiModel::Gm6020Voltage),
        Just(DjiModel::Gm6020Current),
    ]
}

fn is_gm6020(model: DjiModel) -> bool {
    matches!(model, DjiModel::Gm6020Voltage | DjiModel::Gm6020Current)
}

/// ESC ids: C620/C610 1–8, GM6020 1–7.
fn dji_id(model: DjiModel, seed: u8) -> u8 {
    let max = if is_gm6020(model) { 7 } else { 8 };
    1 + seed % max
}

/// Feedback ID: 0x200 + id (C620, C610), 0x204 + id (GM6020).
fn dji_feedback_id(model: DjiModel, id: u8) -> u16 {
    if is_gm6020(model) {
        0x204 + u16::from(id)
    } else {
        0x200 + u16::from(id)
    }
}

/// Rotor turns per output turn: M3508 3591/187, M2006 36, GM6020 direct.
fn dji_gear(model: DjiModel) -> f64 {
    match model {
        DjiModel::M3508 => 3591.0 / 187.0,
        DjiModel::M2006 => 36.0,
        DjiModel::Gm6020Voltage | DjiModel::Gm6020Current => 1.0,
    }
}

/// Amps per count of the feedback torque current: the command scale of the current-mode ESC
/// (C620 16384 ↔ 20 A, C610 10000 ↔ 10 A, GM6020 16384 ↔ 3 A in either command mode).
fn dji_feedback_amps_per_count(model: DjiModel) -> f64 {
    match model {
        DjiModel::M3508 => 20.0 / 16384.0,
        DjiModel::M2006 => 10.0 / 10000.0,
        DjiModel::Gm6020Voltage | DjiModel::Gm6020Current => 3.0 / 16384.0,
    }
}

/// A feedback frame: D0–1 angle, D2–3 rotor rpm, D4–5 torque current (big-endian), D6 temp.
fn dji_feedback(id: u16, angle: u16, rpm: i16, current: i16, temp: u8, d7: u8) -> CanFrame {
    let (r, c) = (rpm as u16, current as u16);
    let d = [
        (angle >> 8) as u8,
        (angle & 0xFF) as u8,
        (r >> 8) as u8,
        (r & 0xFF) as u8,
        (c >> 8) as u8,
        (c & 0xFF) as u8,
        temp,
        d7,
    ];
    CanFrame::standard(id, &d).unwrap()
}

/// Command ID for ESC `id`: C620/C610 0x200 (1–4) / 0x1FF (5–8); GM6020 voltage 0x1FF / 0x2FF,
/// current 0x1FE / 0x2FE (1–4 / 5–7). Slot `(id − 1) mod 4`.
fn dji_command_id_and_slot(model: DjiModel, id: u8) -> (u32, usize) {
    let low = id <= 4;
    let cmd = match model {
        DjiModel::M3508 | DjiModel::M2006 => {
            if low {
                0x200
            } else {
                0x1FF
            }
        }
        DjiModel::Gm6020Voltage => {
            if low {
                0x1FF
            } else {
                0x2FF
            }
        }
        DjiModel::Gm6020Current => {
            if low {
                0x1FE
            } else {
                0x2FE
            }
        }
    };
    (cmd, usize::from((id - 1) % 4))
}

/// Raw counts per command unit and the largest raw value: C620 16384 ↔ 20 A, C610 10000 ↔
/// 10 A, GM6020 current 16384 ↔ 3 A, GM6020 voltage 30000 ↔ 24 V up to its configured limit.
fn dji_scale(model: DjiModel, voltage_raw_limit: i16) -> (f64, f64) {
    match model {
        DjiModel::M3508 => (16384.0 / 20.0, 16384.0),
        DjiModel::M2006 => (10000.0 / 10.0, 10000.0),
        DjiModel::Gm6020Current => (16384.0 / 3.0, 16384.0),
        DjiModel::Gm6020Voltage => (30000.0 / 24.0, f64::from(voltage_raw_limit)),
    }
}

/// Checks a slot value against `command` (amps or volts): the rounded, clamped raw value. A
/// value within 1 % of a count of a rounding boundary may round either way (the driver
/// multiplies in f32).
fn check_raw(
    raw: i16,
    command: f32,
    counts_per_unit: f64,
    limit: f64,
) -> Result<(), TestCaseError> {
    if command.is_nan() {
        prop_assert_eq!(raw, 0, "NaN must pack as 0");
        return Ok(());
    }
    let exact = (f64::from(command) * counts_per_unit).clamp(-limit, limit);
    let want = exact.round(); // half away from zero
    let near_half = (exact.abs().fract() - 0.5).abs() < 0.01;
    let got = f64::from(raw);
    if near_half {
        prop_assert!((got - want).abs() <= 1.0, "{command} → {raw}, want {want}");
    } else {
        prop_assert_eq!(got, want, "{} → {}", command, raw);
    }
    Ok(())
}

/// A command value: mostly within twice the ESC range, sometimes anything finite.
fn command_value() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => -40.0f32..40.0,
        1 => proptest::num::f32::NORMAL | proptest::num::f32::ZERO,
    ]
}

proptest! {
    #![proptest_config(config(256))]

    /// Every feedback field decodes to its physical value, on the model's feedback ID.
    #[test]
    fn dji_feedback_fields_decode(
        model in dji_model(), seed: u8, angle in 0u16..8192, rpm: i16, current: i16,
        temp: u8, d7: u8, other_id in 0u16..0x800,
    ) {
        let id = dji_id(model, seed);
        // An absolute origin at raw 0, so the first reading gives the angle directly: placed
        // within half a rotor turn of 0.
        let mut config = DjiConfig::default_for(model);
        config.origin = Origin::Absolute { zero_offset_counts: 0 };
        let m = DjiMotor::new(model, id, config).unwrap();
        let fid = dji_feedback_id(model, id);
        let frame = dji_feedback(fid, angle, rpm, current, temp, d7);
        prop_assert!(m.matches_frame(&frame));
        if other_id != fid {
            let other = dji_feedback(other_id, angle, rpm, current, temp, d7);
            prop_assert!(!m.matches_frame(&other), "claims {other_id:#x}");
        }
        let ext = CanFrame::extended(u32::from(fid), frame.data()).unwrap();
        prop_assert!(!m.matches_frame(&ext), "claims an extended frame");

        m.update_feedback(&frame, T0).unwrap();
        let s = m.state();
        let gear = dji_gear(model);
        let want_speed = f64::from(rpm) / gear;
        prop_assert!(
            (f64::from(s.speed_rpm) - want_speed).abs() <= 1e-6 * want_speed.abs() + 1e-9,
            "speed {} want {want_speed}", s.speed_rpm
        );
        let counts = if angle >= 4096 { i32::from(angle) - 8192 } else { i32::from(angle) };
        let want_total = f64::from(counts) * 360.0 / 8192.0 / gear;
        let total = f64::from(s.total_angle_deg.unwrap());
        prop_assert!((total - want_total).abs() < 1e-4, "total {total} want {want_total}");
        let single = f64::from(s.angle_deg.unwrap());
        prop_assert!((0.0..360.0).contains(&single));
        prop_assert!(circular_gap_deg(single, want_total) < 1e-4, "angle {single} want {want_total}");
        let want_amps = f64::from(current) * dji_feedback_amps_per_count(model);
        let amps = f64::from(s.current_amps.unwrap());
        prop_assert!((amps - want_amps).abs() <= 1e-6 * want_amps.abs() + 1e-9, "{amps} want {want_amps}");
        let want_temp = if model == DjiModel::M2006 { None } else { Some(f32::from(temp)) };
        prop_assert_eq!(s.temperature_c, want_temp);
        prop_assert_eq!(s.last_feedback, Some(T0));
    }

    /// A frame that is not eight bytes, or an angle ≥ 8192, is rejected and changes nothing.
    #[test]
    fn dji_malformed_feedback_is_rejected_without_effect(
        model in dji_model(), seed: u8, len in 0usize..8, angle in 8192u16..=u16::MAX, rpm: i16,
    ) {
        let id = dji_id(model, seed);
        let m = DjiMotor::new(model, id, DjiConfig::default_for(model)).unwrap();
        let fid = dji_feedback_id(model, id);
        let full = dji_feedback(fid, 100, rpm, 0, 30, 0);
        let short = CanFrame::standard(fid, &full.data()[..len]).unwrap();
        prop_assert_eq!(
            m.update_feedback(&short, T0),
            Err(FrameError::WrongLength { dlc: len as u8 })
        );
        let bad = dji_feedback(fid, angle, rpm, 0, 30, 0);
        prop_assert_eq!(m.update_feedback(&bad, T0), Err(FrameError::OutOfRange));
        let s = m.state();
        prop_assert_eq!(s.last_feedback, None);
        prop_assert_eq!(s.angle_deg, None);
        prop_assert_eq!(s.current_amps, None);
    }

    /// The slot on the wire is `round(command · counts per unit)`, clamped to the ESC's range,
    /// on the model's command ID and slot; every other slot of the frame is zero.
    #[test]
    fn dji_command_slot_is_the_rounded_clamped_command(
        model in dji_model(), seed: u8, command in command_value(),
        voltage_raw_limit in 1i16..=30000,
    ) {
        let id = dji_id(model, seed);
        let mut config = DjiConfig::default_for(model);
        config.voltage_raw_limit = voltage_raw_limit;
        let m = DjiMotor::new(model, id, config).unwrap();
        // Online, cool (no thermal derating).
        m.update_feedback(&dji_feedback(dji_feedback_id(model, id), 0, 0, 0, 25, 0), T0).unwrap();
        if model == DjiModel::Gm6020Voltage {
            m.set_target_voltage(command).unwrap();
        } else {
            m.set_target_current(command).unwrap();
        }
        let mut batch = TxBatch::new();
        m.update(T0, 0.001);
        m.pack_command(&mut batch);
        prop_assert_eq!(batch.frames().len(), 1);
        let frame = batch.frames()[0];
        let (cmd_id, slot) = dji_command_id_and_slot(model, id);
        prop_assert!(!frame.is_extended());
        prop_assert_eq!(frame.raw_id(), cmd_id);
        let d = frame.data8().unwrap();
        for other in (0..4).filter(|s| *s != slot) {
            prop_assert_eq!((d[2 * other], d[2 * other + 1]), (0, 0));
        }
        let raw = ((u16::from(d[2 * slot]) << 8) | u16::from(d[2 * slot + 1])) as i16;
        let (per_unit, limit) = dji_scale(model, voltage_raw_limit);
        check_raw(raw, command, per_unit, limit)?;
    }

    /// `command_to_raw` for any f32, NaN and infinities included: clamped, rounded, NaN → 0.
    #[test]
    fn dji_command_to_raw_any_value(
        model in dji_model(), seed: u8, voltage_raw_limit in 1i16..=30000,
        command in proptest::num::f32::ANY,
    ) {
        let mut config = DjiConfig::default_for(model);
        config.voltage_raw_limit = voltage_raw_limit;
        let m = DjiMotor::new(model, dji_id(model, seed), config).unwrap();
        let (per_unit, limit) = dji_scale(model, voltage_raw_limit);
        check_raw(m.command_to_raw(command), command, per_unit, limit)?;
    }
}

// ---------------------------------------------------------------------------------------------
// VESC (firmware comm_can: big-endian integers, extended ID (packet << 8) | controller id)
// ---------------------------------------------------------------------------------------------

fn put_be_i16(v: i16) -> [u8; 2] {
    let u = v as u16;
    [(u >> 8) as u8, (u & 0xFF) as u8]
}

fn put_be_i32(v: i32) -> [u8; 4] {
    let u = v as u32;
    [(u >> 24) as u8, (u >> 16) as u8, (u >> 8) as u8, u as u8]
}

fn vesc_frame(packet: u32, vesc_id: u8, d: &[u8]) -> CanFrame {
    CanFrame::extended((packet << 8) | u32::from(vesc_id), d).unwrap()
}

/// STATUS (packet 9): i32 eRPM, i16 current × 10, i16 duty × 1000.
fn vesc_status1(vesc_id: u8, erpm: i32, current_x10: i16, duty_x1000: i16) -> CanFrame {
    let mut d = [0u8; 8];
    d[..4].copy_from_slice(&put_be_i32(erpm));
    d[4..6].copy_from_slice(&put_be_i16(current_x10));
    d[6..].copy_from_slice(&put_be_i16(duty_x1000));
    vesc_frame(9, vesc_id, &d)
}

/// STATUS_4 (packet 16): i16 MOSFET °C × 10, motor °C × 10, input current × 10, PID pos × 50.
fn vesc_status4(vesc_id: u8, fet: i16, motor: i16, current_in: i16, pid_pos: i16) -> CanFrame {
    let mut d = [0u8; 8];
    d[..2].copy_from_slice(&put_be_i16(fet));
    d[2..4].copy_from_slice(&put_be_i16(motor));
    d[4..6].copy_from_slice(&put_be_i16(current_in));
    d[6..].copy_from_slice(&put_be_i16(pid_pos));
    vesc_frame(16, vesc_id, &d)
}

/// (packet, value): decodes a 4-byte command frame for `vesc_id`.
fn decode_vesc_command(frame: &CanFrame, vesc_id: u8) -> Result<(u32, i32), TestCaseError> {
    prop_assert!(frame.is_extended());
    prop_assert_eq!(frame.raw_id() & 0xFF, u32::from(vesc_id));
    prop_assert_eq!(frame.raw_id() >> 16, 0);
    let d = frame.data();
    prop_assert_eq!(d.len(), 4);
    let raw = i32::from_be_bytes([d[0], d[1], d[2], d[3]]);
    Ok((frame.raw_id() >> 8, raw))
}

fn vesc_command() -> impl Strategy<Value = (VescCommand, u32, f64)> {
    // (command, packet, scale of the integer on the wire)
    prop_oneof![
        (-1.0f32..=1.0).prop_map(|v| (VescCommand::Duty(v), 0, 100_000.0)),
        (-500.0f32..500.0).prop_map(|v| (VescCommand::Current(v), 1, 1000.0)),
        (0.0f32..500.0).prop_map(|v| (VescCommand::Brake(v), 2, 1000.0)),
        (-2.0e6f32..2.0e6).prop_map(|v| (VescCommand::Erpm(v), 3, 1.0)),
        (0.0f32..360.0).prop_map(|v| (VescCommand::Position(v), 4, 1_000_000.0)),
    ]
}

fn vesc_value(c: VescCommand) -> f32 {
    match c {
        VescCommand::Duty(v)
        | VescCommand::Current(v)
        | VescCommand::Brake(v)
        | VescCommand::Erpm(v)
        | VescCommand::Position(v) => v,
    }
}

proptest! {
    #![proptest_config(config(256))]

    /// STATUS: eRPM, current and duty decode; the output speed is eRPM / (pole pairs · gear).
    #[test]
    fn vesc_status1_decodes(
        vesc_id in 0u8..=254, pole_pairs in 1u8..=50, rotor_turns in 1u32..=100, output_turns in 1u32..=10,
        erpm: i32, current_x10: i16, duty_x1000: i16, other_id: u8,
    ) {
        let mut config = VescConfig::new(pole_pairs);
        config.gear = GearRatio::new(rotor_turns, output_turns).unwrap();
        let m = VescMotor::new(vesc_id, config).unwrap();
        let f = vesc_status1(vesc_id, erpm, current_x10, duty_x1000);
        prop_assert!(m.matches_frame(&f));
        if other_id != vesc_id {
            prop_assert!(!m.matches_frame(&vesc_status1(other_id, erpm, 0, 0)));
        }
        // STATUS_4 is not in the default set (STATUS_1 only).
        prop_assert!(!m.matches_frame(&vesc_status4(vesc_id, 0, 0, 0, 0)));
        m.update_feedback(&f, T0).unwrap();
        let s = m.state();
        let want_speed = f64::from(erpm) * f64::from(output_turns)
            / (f64::from(pole_pairs) * f64::from(rotor_turns));
        prop_assert!(
            (f64::from(s.speed_rpm) - want_speed).abs() <= 1e-6 * want_speed.abs() + 1e-6,
            "speed {} want {want_speed}", s.speed_rpm
        );
        let want_amps = f64::from(current_x10) / 10.0;
        let amps = f64::from(s.current_amps.unwrap());
        prop_assert!((amps - want_amps).abs() <= 1e-6 * want_amps.abs() + 1e-9);
        let want_duty = f64::from(duty_x1000) / 1000.0;
        prop_assert!((f64::from(m.duty()) - want_duty).abs() <= 1e-6 * want_duty.abs() + 1e-9);
        prop_assert_eq!(s.last_feedback, Some(T0));
    }

    /// STATUS_4: temperatures and (direct drive) the PID position, wrapped to [0, 360).
    #[test]
    fn vesc_status4_decodes(vesc_id in 0u8..=254, fet: i16, motor: i16, current_in: i16, pid_pos: i16) {
        let mut config = VescConfig::new(7);
        config.status_packets = VescStatusSet::STATUS_1.with(VescStatusSet::STATUS_4);
        let m = VescMotor::new(vesc_id, config).unwrap();
        let f = vesc_status4(vesc_id, fet, motor, current_in, pid_pos);
        prop_assert!(m.matches_frame(&f));
        m.update_feedback(&f, T0).unwrap();
        let (want_fet, want_motor) = (f64::from(fet) / 10.0, f64::from(motor) / 10.0);
        let got_fet = f64::from(m.mosfet_temperature_c().unwrap());
        let got_motor = f64::from(m.motor_temperature_c().unwrap());
        prop_assert!((got_fet - want_fet).abs() <= 1e-6 * want_fet.abs() + 1e-9);
        prop_assert!((got_motor - want_motor).abs() <= 1e-6 * want_motor.abs() + 1e-9);
        let t = f64::from(m.state().temperature_c.unwrap());
        prop_assert!((t - want_fet.max(want_motor)).abs() <= 1e-3);
        let angle = f64::from(m.state().angle_deg.unwrap());
        prop_assert!((0.0..360.0).contains(&angle));
        prop_assert!(circular_gap_deg(angle, f64::from(pid_pos) / 50.0) < 1e-3);
    }

    /// Command frames decode to their value within half a count of the wire scale (plus the
    /// f32 rounding of the scaled value).
    #[test]
    fn vesc_command_frames_decode((command, packet, scale) in vesc_command(), vesc_id: u8) {
        let frame = command.to_frame(vesc_id).unwrap();
        let (p, raw) = decode_vesc_command(&frame, vesc_id)?;
        prop_assert_eq!(p, packet);
        let value = f64::from(vesc_value(command));
        let decoded = f64::from(raw) / scale;
        let tol = 0.5 / scale + value.abs() * 2.4e-7;
        prop_assert!((decoded - value).abs() <= tol, "{command:?} → {raw}");
    }

    /// Any f32, however large, NaN included: the wire integer saturates at the i32 range
    /// (no wrap, no sign flip), NaN → 0.
    #[test]
    fn vesc_command_integer_saturates(
        (command, _, scale) in vesc_command(), value in proptest::num::f32::ANY, vesc_id: u8,
    ) {
        let command = match command {
            VescCommand::Duty(_) => VescCommand::Duty(value),
            VescCommand::Current(_) => VescCommand::Current(value),
            VescCommand::Brake(_) => VescCommand::Brake(value),
            VescCommand::Erpm(_) => VescCommand::Erpm(value),
            VescCommand::Position(_) => VescCommand::Position(value),
        };
        let (_, raw) = decode_vesc_command(&command.to_frame(vesc_id).unwrap(), vesc_id)?;
        if value.is_nan() {
            prop_assert_eq!(raw, 0);
        } else {
            let want = (f64::from(value) * scale).round().clamp(f64::from(i32::MIN), f64::from(i32::MAX));
            let tol = 1.0 + want.abs() * 2.4e-7;
            prop_assert!((f64::from(raw) - want).abs() <= tol, "{value} → {raw}, want {want}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Damiao MIT (SPEC.md: DM-J4310-2EC)
// ---------------------------------------------------------------------------------------------

fn mit_limits() -> impl Strategy<Value = MitLimits> {
    prop_oneof![
        1 => Just(MitLimits::DEFAULT),
        3 => (PI as f32..100.0, 0.1f32..100.0, 0.1f32..100.0).prop_map(|(p, v, t)| MitLimits {
            p_max_rad: p,
            v_max_rad_s: v,
            t_max_nm: t,
        }),
    ]
}

/// A field value: in range, beyond it, infinite, or (rarely) NaN.
fn mit_field(max: f32) -> impl Strategy<Value = f32> {
    prop_oneof![
        8 => -max * 1.5..max * 1.5,
        1 => proptest::num::f32::NORMAL,
        1 => prop_oneof![Just(f32::INFINITY), Just(f32::NEG_INFINITY), Just(f32::NAN)],
    ]
}

/// `x` clamped into `[lo, hi]`, NaN → the value of the range nearest zero.
fn clamp_field(x: f32, lo: f64, hi: f64) -> f64 {
    if x.is_nan() {
        0.0f64.clamp(lo, hi)
    } else {
        f64::from(x).clamp(lo, hi)
    }
}

/// Unsigned `bits`-bit code → value in `[lo, hi]`.
fn from_code(code: u32, lo: f64, hi: f64, bits: u32) -> f64 {
    f64::from(code) * (hi - lo) / f64::from((1u32 << bits) - 1) + lo
}

/// The five MIT codes of a command: p 16, v 12, kp 12, kd 12, t 12, big-endian bit fields.
fn mit_codes(b: &[u8; 8]) -> [u32; 5] {
    let b = b.map(u32::from);
    [
        (b[0] << 8) | b[1],
        (b[2] << 4) | (b[3] >> 4),
        ((b[3] & 0xF) << 8) | b[4],
        (b[5] << 4) | (b[6] >> 4),
        ((b[6] & 0xF) << 8) | b[7],
    ]
}

/// One DM feedback frame: D0 = id | state << 4, p 16, v 12, t 12, MOS °C, rotor °C.
fn dm_feedback(
    master: u16,
    (id_nibble, state): (u8, u8),
    p: u16,
    v: u16,
    t: u16,
    (mos, rotor): (u8, u8),
) -> CanFrame {
    let d = [
        (id_nibble & 0xF) | (state << 4),
        (p >> 8) as u8,
        (p & 0xFF) as u8,
        (v >> 4) as u8,
        (((v & 0xF) << 4) as u8) | ((t >> 8) as u8),
        (t & 0xFF) as u8,
        mos,
        rotor,
    ];
    CanFrame::standard(master, &d).unwrap()
}

/// SPEC's state codes: 0 disabled, 1 enabled, 8 over-voltage … E overload.
fn dm_status(code: u8) -> DmStatus {
    match code {
        0 => DmStatus::Disabled,
        1 => DmStatus::Enabled,
        8 => DmStatus::Fault(DmFault::OverVoltage),
        9 => DmStatus::Fault(DmFault::UnderVoltage),
        0xA => DmStatus::Fault(DmFault::OverCurrent),
        0xB => DmStatus::Fault(DmFault::MosOverTemperature),
        0xC => DmStatus::Fault(DmFault::CoilOverTemperature),
        0xD => DmStatus::Fault(DmFault::CommunicationLost),
        0xE => DmStatus::Fault(DmFault::Overload),
        other => DmStatus::Fault(DmFault::Unknown(other)),
    }
}

/// A command ID and a different master ID, both below 0x7FF (Damiao's parameter channel, refused).
fn dm_ids() -> impl Strategy<Value = (u16, u16)> {
    (0u16..0x7FF, 0u16..0x7FF).prop_filter("distinct IDs", |(a, b)| a != b)
}

/// A case the property below found: every field beyond its range, so each is clamped to
/// its top (the position range is ±π). In f32 the position, velocity and gains reach their
/// top codes (0xFFFF, 0xFFF), but the torque's top works out as
/// (2 · 8.16696) · 4095 / (2 · 8.16696) = 4094.9998, truncated to 0xFFE: the frame would be FF×7 FE, Damiao's "save zero". It goes out with
/// the torque code 0xFFA instead.
#[test]
fn dm_mit_command_at_every_top_with_a_torque_top_of_0xffe_is_not_save_zero() {
    let limits = MitLimits {
        p_max_rad: PI as f32,
        v_max_rad_s: 0.1,
        t_max_nm: 8.16696,
    };
    let cmd = MitCommand {
        position_rad: 24.93385,
        velocity_rad_s: 3.7598628e21,
        kp: 815.86273,
        kd: 11555216000000.0,
        torque_nm: 26.681833,
    };
    assert_eq!(
        cmd.pack(&limits),
        [0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFA]
    );
}

proptest! {
    #![proptest_config(config(256))]

    /// Each packed field decodes to the clamped target within one quantisation step
    /// (`span / (2^bits − 1)`), whatever the input: beyond the range, infinite, NaN.
    #[test]
    fn dm_mit_command_fields_decode_to_the_clamped_targets(
        limits in mit_limits(),
        (p, v, kp, kd, t) in (mit_field(20.0), mit_field(50.0), mit_field(600.0), mit_field(6.0), mit_field(20.0)),
    ) {
        let cmd = MitCommand { position_rad: p, velocity_rad_s: v, kp, kd, torque_nm: t };
        let codes = mit_codes(&cmd.pack(&limits));
        let (pm, vm, tm) = (
            f64::from(limits.p_max_rad),
            f64::from(limits.v_max_rad_s),
            f64::from(limits.t_max_nm),
        );
        let fields = [
            (p, -pm, pm, 16u32, "position"),
            (v, -vm, vm, 12, "velocity"),
            (kp, 0.0, 500.0, 12, "kp"),
            (kd, 0.0, 5.0, 12, "kd"),
            (t, -tm, tm, 12, "torque"),
        ];
        // Never the shape of a special command (FF×7 then FB–FE): with the other four
        // fields at the top of their codes, a torque code of 0xFFB–0xFFE goes out as 0xFFA,
        // up to 4 codes below the request (`MitCommand::pack`).
        let others_top = codes[..4] == [0xFFFF, 0xFFF, 0xFFF, 0xFFF];
        prop_assert!(
            !(others_top && (0xFFB..=0xFFE).contains(&codes[4])),
            "the shape of a special command: {codes:X?}"
        );
        for ((x, lo, hi, bits, name), code) in fields.into_iter().zip(codes) {
            prop_assert!(code < (1 << bits), "{name} code {code} overflows {bits} bits");
            let step = (hi - lo) / f64::from((1u32 << bits) - 1);
            let decoded = from_code(code, lo, hi, bits);
            let want = clamp_field(x, lo, hi);
            let moved_down = if name == "torque" && others_top && code == 0xFFA {
                4.0 * step
            } else {
                0.0
            };
            let slack = step * 1.001 + (hi - lo) * 1e-6;
            prop_assert!(
                decoded - want <= slack && want - decoded <= slack + moved_down,
                "{name}: {x} → code {code} = {decoded}, want {want} ± {step}"
            );
        }
        // The protocol's gain ranges are what the crate exports.
        prop_assert_eq!((KP_MAX, KD_MAX), (500.0, 5.0));
    }

    /// Feedback decodes: position, velocity, torque over the configured ranges, both
    /// temperatures, the state code; a reply carrying another motor's id nibble is refused.
    #[test]
    fn dm_feedback_decodes(
        (can_id, master) in dm_ids(), limits in mit_limits(), state in 0u8..16,
        p: u16, v in 0u16..4096, t in 0u16..4096, mos: u8, rotor: u8, wrong_nibble in 1u8..16,
    ) {
        let mut config = DmConfig::new(master);
        config.limits = limits;
        let m = DmMotor::new(can_id, config).unwrap();
        let nibble = (can_id & 0xF) as u8;
        let other = dm_feedback(master, (nibble ^ wrong_nibble, state), p, v, t, (mos, rotor));
        prop_assert_eq!(m.update_feedback(&other, T0), Err(FrameError::OutOfRange));
        prop_assert_eq!(m.state().last_feedback, None);

        m.update_feedback(&dm_feedback(master, (nibble, state), p, v, t, (mos, rotor)), T0).unwrap();
        let (pm, vm, tm) = (
            f64::from(limits.p_max_rad),
            f64::from(limits.v_max_rad_s),
            f64::from(limits.t_max_nm),
        );
        let s = m.state();
        let want_deg = from_code(u32::from(p), -pm, pm, 16).to_degrees();
        let total = f64::from(s.total_angle_deg.unwrap());
        prop_assert!((total - want_deg).abs() <= 1e-5 * pm.to_degrees(), "{total} want {want_deg}");
        let single = f64::from(s.angle_deg.unwrap());
        prop_assert!((0.0..360.0).contains(&single));
        prop_assert!(circular_gap_deg(single, want_deg) <= 1e-5 * pm.to_degrees() + 1e-4);
        let want_rpm = from_code(u32::from(v), -vm, vm, 12) * 60.0 / TAU;
        prop_assert!((f64::from(s.speed_rpm) - want_rpm).abs() <= 1e-5 * vm * 60.0 / TAU);
        let want_nm = from_code(u32::from(t), -tm, tm, 12);
        prop_assert!((f64::from(m.torque_nm()) - want_nm).abs() <= 1e-5 * tm);
        prop_assert_eq!(m.temperatures_c(), (Some(f32::from(mos)), Some(f32::from(rotor))));
        prop_assert_eq!(s.temperature_c, Some(f32::from(mos.max(rotor))));
        prop_assert_eq!(m.status(), dm_status(state));
    }

    /// A joint turning any number of times, less than PMAX per frame: the reported position
    /// wraps at ±PMAX, the driver's multi-turn angle follows the true one within the position
    /// quantum (and f32 rounding of the total).
    #[test]
    fn dm_position_unwraps_through_feedback(
        limits in mit_limits(),
        start in -1.0f64..1.0,
        steps in proptest::collection::vec(-0.95f64..0.95, 1..300),
    ) {
        let mut config = DmConfig::new(0x11);
        config.limits = limits;
        let m = DmMotor::new(0x01, config).unwrap();
        let pm = f64::from(limits.p_max_rad);
        let quantum = 2.0 * pm / 65535.0;
        // What the motor reports for the true position x: x wrapped into [-PMAX, PMAX),
        // quantised down to 16 bits.
        let report = |x: f64| {
            let wrapped = (x + pm).rem_euclid(2.0 * pm);
            ((wrapped / (2.0 * pm) * 65535.0).floor() as u32).min(65535) as u16
        };
        let mut x = start * pm;
        // The first reading is taken as it is reported (no wrap to count yet).
        let mut now = T0;
        m.update_feedback(&dm_feedback(0x11, (1, 1), report(x), 2048, 2048, (30, 30)), now).unwrap();
        let offset = from_code(u32::from(report(x)), -pm, pm, 16) - x;
        for s in steps {
            x += s * pm;
            now += Duration::from_millis(1);
            m.update_feedback(&dm_feedback(0x11, (1, 1), report(x), 2048, 2048, (30, 30)), now).unwrap();
            let got = f64::from(m.state().total_angle_deg.unwrap()).to_radians();
            let want = x + offset;
            prop_assert!(
                (got - want).abs() <= 2.0 * quantum + 1e-6 * want.abs() + 1e-5,
                "x = {x}: got {got}, want {want}"
            );
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Remote receivers: DBUS, SBUS, PPM
// ---------------------------------------------------------------------------------------------

/// Writes `width` bits of `value` at bit `bit` of `buf`, least significant bit first.
fn put_bits(buf: &mut [u8], bit: usize, width: usize, value: u32) {
    for j in 0..width {
        if (value >> j) & 1 == 1 {
            buf[(bit + j) / 8] |= 1 << ((bit + j) % 8);
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Dr16 {
    sticks: [u16; 4],
    left: u8,
    right: u8,
    mouse: [i16; 3],
    press: [u8; 2],
    keys: u16,
    wheel: u16,
}

/// DR16 frame: four 11-bit channels from bit 0, right switch at bits 44–45, left at 46–47,
/// mouse x/y/z i16 little-endian in bytes 6–11, buttons 12 and 13, keys 14–15, wheel 16–17.
fn dbus_encode(f: &Dr16) -> [u8; 18] {
    let mut b = [0u8; 18];
    for (i, s) in f.sticks.iter().enumerate() {
        put_bits(&mut b, 11 * i, 11, u32::from(*s));
    }
    put_bits(&mut b, 44, 2, u32::from(f.right));
    put_bits(&mut b, 46, 2, u32::from(f.left));
    for (k, m) in f.mouse.iter().enumerate() {
        let u = *m as u16;
        b[6 + 2 * k] = (u & 0xFF) as u8;
        b[7 + 2 * k] = (u >> 8) as u8;
    }
    b[12] = f.press[0];
    b[13] = f.press[1];
    b[14] = (f.keys & 0xFF) as u8;
    b[15] = (f.keys >> 8) as u8;
    b[16] = (f.wheel & 0xFF) as u8;
    b[17] = (f.wheel >> 8) as u8;
    b
}

fn switch_of(raw: u8) -> Switch {
    match raw {
        1 => Switch::Up,
        3 => Switch::Middle,
        _ => Switch::Down,
    }
}

fn dr16() -> impl Strategy<Value = Dr16> {
    (
        [364u16..=1684, 364u16..=1684, 364u16..=1684, 364u16..=1684],
        prop_oneof![Just(1u8), Just(2), Just(3)],
        prop_oneof![Just(1u8), Just(2), Just(3)],
        any::<[i16; 3]>(),
        any::<[u8; 2]>(),
        any::<u16>(),
        0u16..2048,
    )
        .prop_map(|(sticks, left, right, mouse, press, keys, wheel)| Dr16 {
            sticks,
            left,
            right,
            mouse,
            press,
            keys,
            wheel,
        })
}

fn dbus_expected(f: &Dr16) -> DbusFrame {
    DbusFrame {
        sticks: f.sticks,
        left_switch: switch_of(f.left),
        right_switch: switch_of(f.right),
        mouse: f.mouse,
        mouse_left: f.press[0] != 0,
        mouse_right: f.press[1] != 0,
        keys: rc10_core::remote::dbus::Keys(f.keys),
        wheel: f.wheel,
    }
}

/// SBUS frame: 0x0F, 16 × 11-bit channels LSB first in bytes 1–22, flags in 23, footer.
fn sbus_encode(channels: &[u16; 16], flags: u8, footer: u8) -> [u8; 25] {
    let mut b = [0u8; 25];
    b[0] = 0x0F;
    for (i, c) in channels.iter().enumerate() {
        put_bits(&mut b[1..23], 11 * i, 11, u32::from(*c));
    }
    b[23] = flags;
    b[24] = footer;
    b
}

fn sbus_footer() -> impl Strategy<Value = u8> {
    prop_oneof![Just(0x00u8), Just(0x04), Just(0x14), Just(0x24), Just(0x34)]
}

/// Feeds `bytes` one every 120 µs from `start` (100 kbit/s, 12-bit characters); returns what
/// each byte produced that was not `None`.
fn feed<R>(
    bytes: &[u8],
    start: Instant,
    mut push: impl FnMut(u8, Instant) -> Option<R>,
) -> (Vec<R>, Instant) {
    let mut out = Vec::new();
    let mut t = start;
    for b in bytes {
        if let Some(r) = push(*b, t) {
            out.push(r);
        }
        t += Duration::from_micros(120);
    }
    (out, t)
}

proptest! {
    #![proptest_config(config(256))]

    /// Any valid DR16 frame parses back to its fields.
    #[test]
    fn dbus_frame_round_trips(f in dr16()) {
        prop_assert_eq!(DbusFrame::parse(&dbus_encode(&f)), Ok(dbus_expected(&f)));
    }

    /// A stick more than 700 from the centre 1024 (the margin DJI's examples allow) or a
    /// switch value 0 is rejected, never parsed into a command.
    #[test]
    fn dbus_values_the_dr16_never_sends_are_rejected(
        f in dr16(), stick in 0usize..4, bad in prop_oneof![0u16..324, 1725u16..2048], which_switch: bool,
    ) {
        let mut g = f;
        g.sticks[stick] = bad;
        prop_assert!(DbusFrame::parse(&dbus_encode(&g)).is_err());
        let mut h = f;
        if which_switch { h.left = 0 } else { h.right = 0 }
        prop_assert!(DbusFrame::parse(&dbus_encode(&h)).is_err());
    }

    /// DR16 frames streamed byte by byte (frames 7–14 ms apart) come out whole and equal.
    #[test]
    fn dbus_receiver_reassembles_streamed_frames(
        frames in proptest::collection::vec((dr16(), 7u64..=14), 1..8),
    ) {
        let mut rx = DbusReceiver::new(Duration::from_millis(100));
        let mut t = T0;
        for (f, gap_ms) in frames {
            let (mut out, end) = feed(&dbus_encode(&f), t, |b, now| rx.push_byte(b, now));
            // Whole once the silence after it is longer than the frame gap (`end` is one
            // byte time after the last byte).
            let done = end + FRAME_GAP;
            out.extend(rx.poll(done));
            prop_assert_eq!(out, vec![Ok(dbus_expected(&f))]);
            let sig = rx.signal(done);
            prop_assert!(!sig.lost);
            prop_assert_eq!(sig.value, dbus_expected(&f));
            t = end + Duration::from_millis(gap_ms);
        }
    }

    /// A byte that creeps into a DR16 frame anywhere (line noise) makes a 19-byte burst:
    /// dropped and counted, never read as a frame shifted by a byte (DBUS has no checksum, so
    /// a shifted frame could read as keys or a mouse click). The next clean frame is read.
    #[test]
    fn dbus_burst_with_a_byte_too_many_is_dropped(
        f in dr16(), g in dr16(), at in 0usize..=18, extra: u8,
    ) {
        let mut rx = DbusReceiver::new(Duration::from_millis(100));
        let mut burst = dbus_encode(&f).to_vec();
        burst.insert(at, extra);
        let (mut out, end) = feed(&burst, T0, |b, now| rx.push_byte(b, now));
        out.extend(rx.poll(end + FRAME_GAP));
        prop_assert!(out.is_empty(), "{:?}", out);
        prop_assert_eq!(rx.link().errors(), 1);
        prop_assert_eq!(rx.link().frames(), 0);
        prop_assert!(rx.signal(end + FRAME_GAP).lost);
        let t = end + Duration::from_millis(12);
        let (mut out, end) = feed(&dbus_encode(&g), t, |b, now| rx.push_byte(b, now));
        out.extend(rx.poll(end + FRAME_GAP));
        prop_assert_eq!(out, vec![Ok(dbus_expected(&g))]);
    }

    /// Any 16 channel values, flags and footer parse back equal.
    #[test]
    fn sbus_frame_round_trips(channels: [u16; 16], flags in 0u8..16, footer in sbus_footer()) {
        let channels = channels.map(|c| c & 0x7FF);
        let parsed = SbusFrame::parse(&sbus_encode(&channels, flags, footer)).unwrap();
        prop_assert_eq!(parsed, SbusFrame {
            channels,
            ch17: flags & 1 != 0,
            ch18: flags & 2 != 0,
            frame_lost: flags & 4 != 0,
            failsafe: flags & 8 != 0,
        });
    }

    /// A wrong header or footer is rejected.
    #[test]
    fn sbus_bad_header_or_footer_is_rejected(
        channels: [u16; 16], header in any::<u8>().prop_filter("not 0x0F", |h| *h != 0x0F),
        footer in any::<u8>().prop_filter("no footer", |f| ![0x00, 0x04, 0x14, 0x24, 0x34].contains(f)),
    ) {
        let channels = channels.map(|c| c & 0x7FF);
        let mut b = sbus_encode(&channels, 0, 0);
        b[0] = header;
        prop_assert!(SbusFrame::parse(&b).is_err());
        let b = sbus_encode(&channels, 0, footer);
        prop_assert!(SbusFrame::parse(&b).is_err());
    }

    /// SBUS streamed byte by byte: every frame comes out equal; the receiver's failsafe flag
    /// sends the outputs neutral at once; a "frame lost" frame is acted on only while the
    /// link is live; otherwise the signal is the frame.
    #[test]
    fn sbus_receiver_reassembles_streamed_frames(
        frames in proptest::collection::vec((any::<[u16; 16]>(), 0u8..16, sbus_footer()), 1..8),
    ) {
        let mut rx = SbusReceiver::new(Duration::from_millis(100));
        let mut t = T0;
        // Whether a fresh frame (neither failsafe nor "frame lost") came since the last
        // failsafe: frames are 7 ms apart here, well within the 100 ms timeout.
        let mut live = false;
        for (channels, flags, footer) in frames {
            let channels = channels.map(|c| c & 0x7FF);
            let bytes = sbus_encode(&channels, flags, footer);
            let want = SbusFrame::parse(&bytes).unwrap();
            let (mut out, end) = feed(&bytes, t, |b, now| rx.push_byte(b, now));
            let done = end + FRAME_GAP;
            out.extend(rx.poll(done));
            prop_assert_eq!(out, vec![Ok(want)]);
            let sig = rx.signal(done);
            if flags & 8 != 0 {
                live = false; // failsafe: neutral at once
            } else if flags & 4 == 0 {
                live = true; // fresh
            } // "frame lost": repeated values, live only if it already was
            if live {
                prop_assert!(!sig.lost);
                prop_assert_eq!(sig.value, want);
            } else {
                prop_assert!(sig.lost);
                prop_assert_eq!(sig.value, SbusFrame::NEUTRAL);
            }
            t = end + Duration::from_millis(7);
        }
    }
}

/// One PPM frame on the wire: the channel intervals, optionally corrupted.
#[derive(Debug, Clone)]
enum PpmFrame {
    Good([u16; 8]),
    /// A channel interval replaced by noise (neither a channel nor a sync gap).
    Noise([u16; 8], usize, u32),
    /// One channel fewer or more than the receiver expects.
    WrongCount(Vec<u16>),
}

fn ppm_frame() -> impl Strategy<Value = PpmFrame> {
    let channels = [
        750u16..=2250,
        750u16..=2250,
        750u16..=2250,
        750u16..=2250,
        750u16..=2250,
        750u16..=2250,
        750u16..=2250,
        750u16..=2250,
    ];
    prop_oneof![
        6 => channels.clone().prop_map(PpmFrame::Good),
        1 => (channels, 0usize..8, prop_oneof![0u32..750, 2251u32..2700])
            .prop_map(|(c, i, bad)| PpmFrame::Noise(c, i, bad)),
        1 => prop_oneof![
            proptest::collection::vec(750u16..=2250, 1..8),
            proptest::collection::vec(750u16..=2250, 9..12),
        ].prop_map(PpmFrame::WrongCount),
    ]
}

proptest! {
    #![proptest_config(config(256))]

    /// Pulse trains separated by sync gaps decode to their widths; a corrupted frame is
    /// dropped and counted, and only it: the next one decodes.
    #[test]
    fn ppm_pulse_widths_decode_to_channels(
        frames in proptest::collection::vec((ppm_frame(), 2700u32..20_000), 1..30),
    ) {
        let mut rx = PpmReceiver::<8>::new(Duration::from_millis(100));
        let mut now = T0;
        prop_assert_eq!(rx.push_interval(5000, now), None); // the first sync starts counting
        let (mut good, mut bad) = (0u32, 0u32);
        for (frame, sync) in frames {
            let (intervals, want): (Vec<u32>, Option<[u16; 8]>) = match &frame {
                PpmFrame::Good(c) => (c.iter().map(|x| u32::from(*x)).collect(), Some(*c)),
                PpmFrame::Noise(c, i, noise) => {
                    let mut v: Vec<u32> = c.iter().map(|x| u32::from(*x)).collect();
                    v[*i] = *noise;
                    (v, None)
                }
                PpmFrame::WrongCount(c) => (c.iter().map(|x| u32::from(*x)).collect(), None),
            };
            let mut results = Vec::new();
            for us in intervals.iter().copied().chain([sync]) {
                now += Duration::from_micros(u64::from(us));
                if let Some(r) = rx.push_interval(us, now) {
                    results.push(r);
                }
            }
            match want {
                Some(c) => {
                    good += 1;
                    prop_assert_eq!(results, vec![Ok(c)]);
                    prop_assert_eq!(rx.signal(now).value, c);
                    for (i, us) in c.iter().enumerate() {
                        let norm = ((f32::from(*us) - 1500.0) / 500.0).clamp(-1.0, 1.0);
                        prop_assert!((rx.channel(i, now, 0.0) - norm).abs() < 1e-6);
                    }
                }
                None => {
                    bad += 1;
                    prop_assert_eq!(results.len(), 1, "{:?}", results);
                    match (&frame, &results[0]) {
                        (PpmFrame::Noise(_, _, noise), Err(PpmError::BadInterval(us))) => {
                            prop_assert_eq!(us, noise);
                        }
                        (PpmFrame::WrongCount(c), Err(PpmError::WrongChannelCount(n))) => {
                            prop_assert_eq!(*n, c.len());
                        }
                        (f, r) => prop_assert!(false, "{f:?} gave {r:?}"),
                    }
                }
            }
            prop_assert_eq!((rx.link().frames(), rx.link().errors()), (good, bad));
        }
    }
}

// ---------------------------------------------------------------------------------------------
// VOFA+ telemetry
// ---------------------------------------------------------------------------------------------

/// A FireWater line parsed as VOFA+ does: optional `prefix:`, comma-separated numbers, `\n`.
fn parse_firewater(line: &str, prefix: &str) -> Result<Vec<f64>, TestCaseError> {
    let body = line.strip_suffix('\n');
    prop_assert!(body.is_some(), "no newline: {line:?}");
    let mut body = body.unwrap_or_default();
    if !prefix.is_empty() {
        let rest = body.strip_prefix(prefix).and_then(|r| r.strip_prefix(':'));
        prop_assert!(rest.is_some(), "no prefix in {line:?}");
        body = rest.unwrap_or_default();
    }
    if body.is_empty() {
        return Ok(Vec::new());
    }
    let mut out = Vec::new();
    for field in body.split(',') {
        let v = field.parse::<f64>();
        prop_assert!(v.is_ok(), "{field:?} in {line:?}");
        out.push(v.unwrap_or_default());
    }
    Ok(out)
}

proptest! {
    #![proptest_config(config(256))]

    /// JustFloat: little-endian f32s (bit-exact, NaN payloads included; +inf, whose bits are
    /// the tail, as f32::MAX) then 00 00 80 7F; a buffer one byte short is refused with the
    /// exact size needed.
    #[test]
    fn justfloat_round_trips_bit_exactly(values in proptest::collection::vec(proptest::num::f32::ANY, 0..16)) {
        let mut buf = vec![0u8; 4 * values.len() + 4];
        let n = justfloat(&values, &mut buf).unwrap();
        prop_assert_eq!(n, 4 * values.len() + 4);
        for (chunk, v) in buf.chunks_exact(4).zip(&values) {
            let back = f32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]);
            // +inf's bits are the tail: it goes out as f32::MAX, so no value ends a frame.
            let sent = if *v == f32::INFINITY { f32::MAX } else { *v };
            prop_assert_eq!(back.to_bits(), sent.to_bits());
            prop_assert_ne!(chunk, &[0x00, 0x00, 0x80, 0x7F][..]);
        }
        prop_assert_eq!(&buf[n - 4..n], &[0x00, 0x00, 0x80, 0x7F]);
        let mut short = vec![0u8; n - 1];
        prop_assert_eq!(justfloat(&values, &mut short), Err(BufferTooSmall { needed: n }));
    }

    /// FireWater: `prefix:v1,…\n`; each value parses back within half a unit of the last
    /// printed decimal; nan / inf / -inf spelled out; a short buffer is refused.
    #[test]
    fn firewater_round_trips_within_the_decimals(
        prefix in "[a-z_]{0,8}",
        values in proptest::collection::vec(prop_oneof![
            8 => -1.0e4f32..1.0e4,
            1 => proptest::num::f32::NORMAL,
            1 => prop_oneof![Just(f32::NAN), Just(f32::INFINITY), Just(f32::NEG_INFINITY)],
        ], 1..10),
        decimals in 0usize..=6,
        cap_seed: usize,
    ) {
        let mut buf = vec![0u8; 1024];
        let n = firewater(&prefix, &values, decimals, &mut buf).unwrap();
        let line = std::str::from_utf8(&buf[..n]).unwrap().to_owned();
        let parsed = parse_firewater(&line, &prefix)?;
        prop_assert_eq!(parsed.len(), values.len());
        let half_unit = 0.5 * 10f64.powi(-(decimals as i32));
        for (got, v) in parsed.iter().zip(&values) {
            if v.is_nan() {
                prop_assert!(got.is_nan());
            } else if v.is_infinite() {
                prop_assert_eq!(*got, f64::from(*v));
            } else {
                let v = f64::from(*v);
                prop_assert!((got - v).abs() <= half_unit + v.abs() * 1e-15, "{v} printed {got} in {line:?}");
            }
        }
        // Any smaller buffer: refused, with the line's exact length.
        let cap = cap_seed % n;
        let mut small = vec![0u8; cap];
        match firewater(&prefix, &values, decimals, &mut small) {
            Err(BufferTooSmall { needed }) => prop_assert_eq!(needed, n),
            Ok(m) => prop_assert!(false, "{m} bytes written into {cap}"),
        }
    }
}
