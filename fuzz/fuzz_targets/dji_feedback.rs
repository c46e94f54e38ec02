//! DJI feedback (C620 + M3508, C610 + M2006, GM6020 in both modes): any frames, with any
//! timestamps, interleaved with ticks, to one motor.
//!
//! Input: byte 0 picks the model, byte 1 the ESC id; then operations (tag byte): a frame
//! (ID choice, payload, timestamp offset), a tick after some µs, or a target.
//!
//! Invariants: no panic; the motor claims exactly frames with its feedback ID (0x200 + id,
//! GM6020 0x204 + id, standard); it accepts exactly DLC-8 data frames with an angle below
//! 8192 not stamped before the newest frame it took, and then reports what the frame says
//! (rotor rpm through the gear ratio, torque current on the ESC's scale, temperature except
//! on the C610, the absolute angle of a GM6020); a rejected frame changes nothing; reported
//! values are finite, angles in [0, 360); the packed slot is within the ESC's range and zero
//! while offline.
#![no_main]

use arbitrary::{Arbitrary, Unstructured};
use libfuzzer_sys::fuzz_target;
use rc10_core::can::{CanFrame, ExtendedId, Id, StandardId};
use rc10_core::motor::Motor;
use rc10_core::motor::dji::{DjiConfig, DjiModel, DjiMotor};
use rc10_core::node::{CanNode, FrameError, TxBatch};
use rc10_core::time::Instant;
use rc10_fuzz::input::{Payload, f32_from};
use rc10_fuzz::proto;

fuzz_target!(|data: &[u8]| run(data));

fn run(data: &[u8]) {
    let mut u = Unstructured::new(data);
    let byte = |u: &mut Unstructured<'_>| u8::arbitrary(u).unwrap_or(0);
    let model = [
        DjiModel::M3508,
        DjiModel::M2006,
        DjiModel::Gm6020Voltage,
        DjiModel::Gm6020Current,
    ][usize::from(byte(&mut u) % 4)];
    // The protocol's id ranges: C620 / C610 1–8, GM6020 1–7.
    let max_id = if matches!(model, DjiModel::M3508 | DjiModel::M2006) {
        8
    } else {
        7
    };
    let id = 1 + byte(&mut u) % max_id;
    let motor = DjiMotor::new(model, id, DjiConfig::default_for(model)).expect("valid id");
    let gm6020 = matches!(model, DjiModel::Gm6020Voltage | DjiModel::Gm6020Current);
    let feedback_id = if gm6020 { 0x204 } else { 0x200 } + u16::from(id);
    let (gear, amps_per_count, range): (f64, f64, i16) = match model {
        DjiModel::M3508 => (3591.0 / 187.0, 20.0 / 16384.0, 16384),
        DjiModel::M2006 => (36.0, 10.0 / 10000.0, 10000),
        // GM6020 torque current on the ±16384 ↔ ±3 A scale in both modes.
        DjiModel::Gm6020Voltage => (1.0, 3.0 / 16384.0, 25000),
        DjiModel::Gm6020Current => (1.0, 3.0 / 16384.0, 16384),
    };
    let mut now: u64 = 1_000_000;
    let mut homed = false;
    while !u.is_empty() {
        match byte(&mut u) % 8 {
            0..=4 => {
                let id_kind = byte(&mut u);
                let raw = u16::arbitrary(&mut u).unwrap_or(0);
                let id = match id_kind % 8 {
                    0..=5 => Id::Standard(StandardId::new(feedback_id).expect("11-bit")),
                    6 => Id::Standard(StandardId::new(raw & 0x7FF).expect("11-bit")),
                    _ => Id::Extended(ExtendedId::new(u32::from(feedback_id)).expect("29-bit")),
                };
                let payload = Payload::arbitrary(&mut u).unwrap_or(Payload::full([0; 8]));
                let offset = i32::from(i16::arbitrary(&mut u).unwrap_or(0)) * 16;
                let stamp = now.saturating_add_signed(i64::from(offset));
                if let Some(frame) = payload.frame(id) {
                    let absolute = gm6020 && !homed;
                    feed(
                        &motor,
                        &frame,
                        stamp,
                        feedback_id,
                        gear,
                        amps_per_count,
                        model,
                        absolute,
                    );
                }
            }
            5 | 6 => {
                now += u64::from(u16::arbitrary(&mut u).unwrap_or(1000));
                tick(&motor, now, range);
            }
            _ => {
                let x = f32_from(&mut u).unwrap_or(0.0);
                let _ = match byte(&mut u) % 5 {
                    0 => motor.set_target_rpm(x),
                    1 => motor.set_target_angle_deg(x),
                    2 => motor.set_target_total_angle_deg(x),
                    3 => motor
                        .set_target_current(x)
                        .or_else(|_| motor.set_target_voltage(x)),
                    _ => {
                        homed = true;
                        motor.set_total_angle_here_deg(x)
                    }
                };
            }
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn feed(
    motor: &DjiMotor,
    frame: &CanFrame,
    stamp: u64,
    feedback_id: u16,
    gear: f64,
    amps_per_count: f64,
    model: DjiModel,
    absolute: bool,
) {
    let mine = !frame.is_extended() && frame.raw_id() == u32::from(feedback_id);
    assert_eq!(motor.matches_frame(frame), mine, "{frame:?}");
    if !mine {
        return; // the bus never hands it over
    }
    let before = motor.state();
    let result = motor.update_feedback(frame, Instant::from_ticks(stamp));
    let after = motor.state();
    let decoded = proto::dji_feedback(frame).filter(|f| f.angle < proto::DJI_COUNTS);
    let Some(f) = decoded else {
        assert!(result.is_err(), "malformed {frame:?} accepted");
        assert_eq!(before, after, "rejected {frame:?} changed the state");
        return;
    };
    // A frame stamped before the newest feedback the motor took is older than its state.
    if before
        .last_feedback
        .is_some_and(|newest| Instant::from_ticks(stamp) < newest)
    {
        assert_eq!(result, Err(FrameError::OutOfOrder), "{frame:?} at {stamp}");
        assert_eq!(before, after, "an out-of-order {frame:?} changed the state");
        return;
    }
    assert!(result.is_ok(), "valid {frame:?} rejected: {result:?}");
    let speed = f64::from(f.rpm) / gear;
    assert!(
        (f64::from(after.speed_rpm) - speed).abs() <= speed.abs() * 1e-6,
        "speed {} for rotor {} rpm",
        after.speed_rpm,
        f.rpm
    );
    let amps = f64::from(f.current) * amps_per_count;
    let got = f64::from(after.current_amps.expect("current reported"));
    assert!(
        (got - amps).abs() <= amps.abs() * 1e-6 + 1e-9,
        "current {got} for {}",
        f.current
    );
    let temperature = (model != DjiModel::M2006).then_some(f32::from(f.temperature));
    assert_eq!(after.temperature_c, temperature);
    assert_eq!(after.last_feedback, Some(Instant::from_ticks(stamp)));
    let angle = after.angle_deg.expect("angle after a reading");
    assert!((0.0..360.0).contains(&angle), "angle {angle}");
    assert!(
        after.total_angle_deg.is_some_and(f32::is_finite),
        "{after:?}"
    );
    if absolute {
        // Direct drive, absolute encoder with zero offset 0 and no homing yet: the output
        // angle is the reading.
        let reading = f64::from(f.angle) * 360.0 / 8192.0;
        assert!(
            (f64::from(angle) - reading).abs() < 1e-3,
            "angle {angle} for {}",
            f.angle
        );
    }
}

fn tick(motor: &DjiMotor, now: u64, range: i16) {
    motor.update(Instant::from_ticks(now), 0.001);
    let mut batch = TxBatch::new();
    motor.pack_command(&mut batch);
    assert_eq!(batch.frames().len(), 1);
    let d = proto::data8(&batch.frames()[0]).expect("DLC 8");
    let slot = usize::from(motor.command_slot().index());
    let raw = proto::dji_slot(&d, slot);
    for other in (0..4).filter(|s| *s != slot) {
        assert_eq!(
            proto::dji_slot(&d, other),
            0,
            "another motor's slot written"
        );
    }
    assert!(
        raw.unsigned_abs() <= range.unsigned_abs(),
        "raw {raw} beyond ±{range}"
    );
    let s = motor.state();
    assert!(s.command.is_finite() && s.speed_rpm.is_finite(), "{s:?}");
    if !s.online {
        assert!(
            raw == 0 && s.command == 0.0,
            "offline motor commands {raw}: {s:?}"
        );
    }
}
