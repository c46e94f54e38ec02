//! VESC status frames (STATUS 1–5) to a VESC of any configuration, and VESC command frames
//! packed from any value.
//!
//! Input: controller id, pole pairs, gear ratio and status set; then operations (tag byte): a
//! frame (packet, controller, payload, timestamp), or a command to pack.
//!
//! Invariants: no panic; the motor claims exactly the extended IDs `(packet << 8) | id` of
//! its status packets (bits 16–28 zero); it accepts STATUS and STATUS_4 exactly when they are
//! DLC-8 data frames and reports what they say (speed = eRPM / pole pairs / gear, current
//! / 10, duty / 1000, temperatures / 10, the PID position / 50 as the angle in direct drive);
//! a rejected frame changes nothing; reported values are finite. A packed command is the
//! extended ID `(packet << 8) | id`, four bytes, the value scaled and rounded, saturated at
//! the i32 range, with the value's sign, NaN as 0.
#![no_main]

use arbitrary::{Arbitrary, Unstructured};
use libfuzzer_sys::fuzz_target;
use rc10_core::can::{CanFrame, ExtendedId, Id, StandardId};
use rc10_core::encoder::GearRatio;
use rc10_core::motor::Motor;
use rc10_core::motor::vesc::{VescCommand, VescConfig, VescMotor, VescStatusSet};
use rc10_core::node::CanNode;
use rc10_core::time::Instant;
use rc10_fuzz::input::{Payload, f32_from};
use rc10_fuzz::proto::{self, vesc_packet as vp};

const PACKETS: [(u8, VescStatusSet); 5] = [
    (vp::STATUS, VescStatusSet::STATUS_1),
    (vp::STATUS_2, VescStatusSet::STATUS_2),
    (vp::STATUS_3, VescStatusSet::STATUS_3),
    (vp::STATUS_4, VescStatusSet::STATUS_4),
    (vp::STATUS_5, VescStatusSet::STATUS_5),
];

fuzz_target!(|data: &[u8]| run(data));

fn run(data: &[u8]) {
    let mut u = Unstructured::new(data);
    let byte = |u: &mut Unstructured<'_>| u8::arbitrary(u).unwrap_or(0);
    let vesc_id = byte(&mut u).min(254); // 255: the broadcast address, refused
    let pole_pairs = byte(&mut u).max(1);
    let gear = GearRatio::new(
        u32::from(byte(&mut u) % 64 + 1),
        u32::from(byte(&mut u) % 8 + 1),
    )
    .expect("non-zero ratio");
    let set_bits = byte(&mut u);
    let mut set = VescStatusSet::STATUS_1;
    let mut packets = vec![vp::STATUS];
    for (k, (p, flag)) in PACKETS.iter().enumerate().skip(1) {
        if set_bits & (1 << k) != 0 {
            set = set.with(*flag);
            packets.push(*p);
        }
    }
    let config = VescConfig {
        gear,
        status_packets: set,
        ..VescConfig::new(pole_pairs)
    };
    let motor = VescMotor::new(vesc_id, config).expect("valid configuration");
    let erpm_per_rpm = f64::from(pole_pairs) * gear.as_f32() as f64;
    let mut now: u64 = 1_000_000;
    while !u.is_empty() {
        let tag = byte(&mut u);
        if tag % 4 == 3 {
            let id = byte(&mut u);
            pack(&mut u, id);
            continue;
        }
        let packet = match byte(&mut u) % 8 {
            0..=5 => [
                vp::STATUS,
                vp::STATUS_2,
                vp::STATUS_3,
                vp::STATUS_4,
                vp::STATUS_5,
                vp::STATUS,
            ][usize::from(tag / 4 % 6)],
            _ => byte(&mut u),
        };
        let controller = if byte(&mut u) % 4 == 0 {
            byte(&mut u)
        } else {
            vesc_id
        };
        let high = if byte(&mut u) % 16 == 0 {
            u32::from(byte(&mut u) % 32) << 16
        } else {
            0
        };
        let raw_id = high | u32::from(packet) << 8 | u32::from(controller);
        let id = if byte(&mut u) % 16 == 0 {
            Id::Standard(StandardId::new((raw_id & 0x7FF) as u16).expect("11-bit"))
        } else {
            Id::Extended(ExtendedId::new(raw_id).expect("29-bit"))
        };
        let payload = Payload::arbitrary(&mut u).unwrap_or(Payload::full([0; 8]));
        now = now.saturating_add(u64::from(u16::arbitrary(&mut u).unwrap_or(0)));
        let Some(frame) = payload.frame(id) else {
            continue;
        };
        feed(
            &motor,
            &frame,
            now,
            vesc_id,
            &packets,
            erpm_per_rpm,
            // Direct drive: the rotor and the output turn together (also written 2:2).
            gear.rotor_turns() == gear.output_turns(),
        );
    }
}

fn feed(
    motor: &VescMotor,
    frame: &CanFrame,
    now: u64,
    vesc_id: u8,
    packets: &[u8],
    erpm_per_rpm: f64,
    direct: bool,
) {
    let parsed = proto::vesc_id(frame);
    let mine = parsed.is_some_and(|v| v.controller == vesc_id && packets.contains(&v.packet));
    assert_eq!(motor.matches_frame(frame), mine, "{frame:?}");
    let before = motor.state();
    let before_temps = (motor.motor_temperature_c(), motor.mosfet_temperature_c());
    let result = motor.update_feedback(frame, Instant::from_ticks(now));
    let after = motor.state();
    assert!(
        after.speed_rpm.is_finite() && after.current_amps.is_none_or(f32::is_finite),
        "{after:?}"
    );
    if !mine {
        return; // the bus never hands it over; it only must not panic
    }
    let packet = parsed.expect("mine").packet;
    let d = proto::data8(frame);
    match packet {
        vp::STATUS | vp::STATUS_4 => {
            let Some(d) = d else {
                assert!(result.is_err(), "short status {frame:?} accepted");
                assert_eq!(before, after, "rejected {frame:?} changed the state");
                assert_eq!(
                    before_temps,
                    (motor.motor_temperature_c(), motor.mosfet_temperature_c())
                );
                return;
            };
            assert!(result.is_ok(), "{frame:?}: {result:?}");
            if packet == vp::STATUS {
                let erpm = f64::from(i32::from_be_bytes([d[0], d[1], d[2], d[3]]));
                let current = f64::from(i16::from_be_bytes([d[4], d[5]])) / 10.0;
                let duty = f64::from(i16::from_be_bytes([d[6], d[7]])) / 1000.0;
                let speed = erpm / erpm_per_rpm;
                let got = f64::from(after.speed_rpm);
                assert!(
                    (got - speed).abs() <= speed.abs() * 1e-5 + 1e-6,
                    "speed {got} ≠ {speed}"
                );
                let amps = f64::from(after.current_amps.expect("current"));
                assert!((amps - current).abs() <= 1e-4, "current {amps} ≠ {current}");
                assert!(
                    (f64::from(motor.duty()) - duty).abs() <= duty.abs() * 1e-6 + 1e-9,
                    "duty"
                );
                assert_eq!(after.last_feedback, Some(Instant::from_ticks(now)));
            } else {
                let mos = f64::from(i16::from_be_bytes([d[0], d[1]])) / 10.0;
                let winding = f64::from(i16::from_be_bytes([d[2], d[3]])) / 10.0;
                let position = f64::from(i16::from_be_bytes([d[6], d[7]])) / 50.0;
                let t = |x: Option<f32>| f64::from(x.expect("temperature"));
                assert!((t(motor.mosfet_temperature_c()) - mos).abs() <= 1e-4);
                assert!((t(motor.motor_temperature_c()) - winding).abs() <= 1e-4);
                if direct {
                    let a = f64::from(after.angle_deg.expect("angle in direct drive"));
                    assert!((0.0..360.0).contains(&a), "angle {a}");
                    let want = position.rem_euclid(360.0);
                    let diff = (a - want).abs();
                    assert!(diff.min(360.0 - diff) <= 1e-3, "angle {a} ≠ {want}");
                } else {
                    assert_eq!(after.angle_deg, None, "a rotor angle is no output angle");
                }
            }
        }
        _ => assert!(result.is_ok(), "known status packet {packet} refused"),
    }
}

/// Packs one command of any value and checks the frame against the protocol.
fn pack(u: &mut Unstructured<'_>, vesc_id: u8) {
    let kind = u8::arbitrary(u).unwrap_or(0) % 5;
    let x = f32_from(u).unwrap_or(0.0);
    let (command, packet, scale) = match kind {
        0 => (VescCommand::Duty(x), vp::SET_DUTY, 100_000.0),
        1 => (VescCommand::Current(x), vp::SET_CURRENT, 1000.0),
        2 => (VescCommand::Brake(x), vp::SET_CURRENT_BRAKE, 1000.0),
        3 => (VescCommand::Erpm(x), vp::SET_RPM, 1.0),
        _ => (VescCommand::Position(x), vp::SET_POS, 1_000_000.0),
    };
    let frame = command
        .to_frame(vesc_id)
        .expect("a VESC ID always fits 29 bits");
    assert!(frame.is_extended() && !frame.is_remote());
    assert_eq!(frame.raw_id(), u32::from(packet) << 8 | u32::from(vesc_id));
    let value = proto::vesc_command_value(&frame).expect("DLC 4");
    let exact = if x.is_nan() {
        0.0
    } else {
        f64::from(x) * scale
    };
    let want = exact
        .round()
        .clamp(f64::from(i32::MIN), f64::from(i32::MAX));
    assert!(
        (f64::from(value) - want).abs() <= 1.0 + want.abs() * 1e-6,
        "{command:?} packed as {value}, want {want}"
    );
    assert!(
        value == 0 || (value > 0) == (exact > 0.0),
        "{command:?}: sign flip ({value})"
    );
}
