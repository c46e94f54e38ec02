//! Damiao feedback to a Damiao motor of any valid configuration, and MIT commands packed
//! from any values with any ranges.
//!
//! Input: CAN ID, master ID and MIT ranges; then operations (tag byte): a feedback frame
//! (ID choice, payload, timestamp), a tick, or an MIT command to pack.
//!
//! Invariants (from the Damiao protocol): no panic; the motor claims exactly standard frames
//! on its master ID and accepts exactly DLC-8 data frames whose D0 low nibble is its CAN ID's;
//! it reports position / velocity / torque decoded from their 16 / 12 / 12-bit fields over
//! ±PMAX / ±VMAX / ±TMAX, the state code (0 disabled, 1 enabled, faults), both temperatures;
//! the multi-turn position moves by at most PMAX per frame (it unwraps the shortest way);
//! a rejected frame changes nothing; reported values finite, angles in [0, 360). A packed MIT
//! command's five fields, decoded from their bit widths, are each the clamped input to within
//! one step (NaN as 0), and the eight bytes never form a special command (FF×7 then FB–FE).
//! The tick's frame is zero torque (or a special command) while offline.
#![no_main]

use arbitrary::{Arbitrary, Unstructured};
use libfuzzer_sys::fuzz_target;
use rc10_core::can::{CanFrame, ExtendedId, Id, StandardId};
use rc10_core::motor::Motor;
use rc10_core::motor::dm::{DmConfig, DmMotor, DmStatus, MitCommand, MitLimits};
use rc10_core::node::{CanNode, TxBatch};
use rc10_core::time::Instant;
use rc10_fuzz::input::{Payload, f32_from};
use rc10_fuzz::pending::{DM_MIT_SPECIAL_COLLISION, DM_RANGE_CAP};
use rc10_fuzz::proto;

fuzz_target!(|data: &[u8]| run(data));

fn run(data: &[u8]) {
    let mut u = Unstructured::new(data);
    let can_id = u16::arbitrary(&mut u).unwrap_or(1) & 0x7FF;
    let master_id = u16::arbitrary(&mut u).unwrap_or(0x11) & 0x7FF;
    let mut range = |default: f32| {
        let x = f32_from(&mut u).unwrap_or(default);
        if x.abs() > DM_RANGE_CAP { default } else { x }
    };
    let limits = MitLimits {
        p_max_rad: range(12.5),
        v_max_rad_s: range(30.0),
        t_max_nm: range(10.0),
    };
    let config = DmConfig {
        limits,
        ..DmConfig::new(master_id)
    };
    let (motor, limits) = match DmMotor::new(can_id, config) {
        Ok(m) => (m, limits),
        // Invalid ranges or IDs are refused at construction; fuzz the defaults then.
        Err(_) => (
            DmMotor::new(0x01, DmConfig::new(0x11)).expect("defaults"),
            MitLimits::DEFAULT,
        ),
    };
    let (can_id, master_id) = (motor.can_id(), motor.config().master_id);
    let mut now: u64 = 1_000_000;
    let mut last_total: Option<f32> = None;
    while !u.is_empty() {
        match u8::arbitrary(&mut u).unwrap_or(0) % 8 {
            0..=4 => {
                let kind = u8::arbitrary(&mut u).unwrap_or(0);
                let other = u16::arbitrary(&mut u).unwrap_or(0) & 0x7FF;
                let id = match kind % 8 {
                    0..=5 => Id::Standard(StandardId::new(master_id).expect("11-bit")),
                    6 => Id::Standard(StandardId::new(other).expect("11-bit")),
                    _ => Id::Extended(ExtendedId::new(u32::from(master_id)).expect("29-bit")),
                };
                let mut payload = Payload::arbitrary(&mut u).unwrap_or(Payload::full([0; 8]));
                if kind & 0x80 != 0 {
                    // Mostly this motor's nibble, so most frames get through.
                    payload.data[0] = payload.data[0] & 0xF0 | (can_id & 0x0F) as u8;
                }
                now = now.saturating_add(u64::from(u16::arbitrary(&mut u).unwrap_or(0)));
                if let Some(frame) = payload.frame(id) {
                    feed(
                        &motor,
                        &frame,
                        now,
                        can_id,
                        master_id,
                        &limits,
                        &mut last_total,
                    );
                }
            }
            5 | 6 => {
                now = now.saturating_add(u64::from(u16::arbitrary(&mut u).unwrap_or(1000)));
                let x = f32_from(&mut u).unwrap_or(0.0);
                let _ = match u8::arbitrary(&mut u).unwrap_or(0) % 4 {
                    0 => motor.set_target_rpm(x),
                    1 => motor.set_target_angle_deg(x),
                    2 => motor.set_target_total_angle_deg(x),
                    _ => motor.set_target_torque_nm(x),
                };
                tick(&motor, now, can_id);
            }
            _ => pack(&mut u),
        }
    }
}

fn feed(
    motor: &DmMotor,
    frame: &CanFrame,
    now: u64,
    can_id: u16,
    master_id: u16,
    l: &MitLimits,
    last_total: &mut Option<f32>,
) {
    let mine = !frame.is_extended() && frame.raw_id() == u32::from(master_id);
    assert_eq!(motor.matches_frame(frame), mine, "{frame:?}");
    if !mine {
        return;
    }
    let before = (motor.state(), motor.status(), motor.temperatures_c());
    let result = motor.update_feedback(frame, Instant::from_ticks(now));
    let after = motor.state();
    let fb = proto::dm_feedback(frame).filter(|f| u16::from(f.id_nibble) == can_id & 0x0F);
    let Some(fb) = fb else {
        assert!(result.is_err(), "{frame:?} accepted");
        assert_eq!(
            before,
            (after, motor.status(), motor.temperatures_c()),
            "rejected {frame:?} changed the state"
        );
        return;
    };
    assert!(result.is_ok(), "{frame:?}: {result:?}");
    let v = proto::code_to_value(fb.v, -l.v_max_rad_s, l.v_max_rad_s, 12);
    // f32 decoding: errors relative to the range, not to the value (near zero the value is
    // the difference of two numbers of the range's size).
    let rpm_per_rad_s = 60.0 / core::f64::consts::TAU;
    let rpm = v * rpm_per_rad_s;
    let v_range_rpm = f64::from(l.v_max_rad_s) * rpm_per_rad_s;
    assert!(
        (f64::from(after.speed_rpm) - rpm).abs() <= (rpm.abs() + v_range_rpm) * 1e-6 + 1e-6,
        "speed {} ≠ {rpm}",
        after.speed_rpm
    );
    let t = proto::code_to_value(fb.t, -l.t_max_nm, l.t_max_nm, 12);
    let t_err = (f64::from(motor.torque_nm()) - t).abs();
    assert!(
        t_err <= (t.abs() + f64::from(l.t_max_nm)) * 1e-6 + 1e-9,
        "torque {t} off by {t_err}"
    );
    let status = match fb.state {
        0 => DmStatus::Disabled,
        1 => DmStatus::Enabled,
        _ => {
            assert!(
                matches!(motor.status(), DmStatus::Fault(_)),
                "state {} is a fault",
                fb.state
            );
            motor.status()
        }
    };
    assert_eq!(motor.status(), status);
    assert_eq!(
        motor.temperatures_c(),
        (Some(f32::from(fb.mos)), Some(f32::from(fb.rotor)))
    );
    let angle = after.angle_deg.expect("angle after feedback");
    assert!((0.0..360.0).contains(&angle), "angle {angle}");
    let total = after.total_angle_deg.expect("total angle after feedback");
    assert!(total.is_finite(), "{after:?}");
    // The reported position wraps at ±PMAX; unwrapped, one frame moves it at most PMAX.
    if let Some(prev) = last_total.replace(total) {
        let step = (f64::from(total) - f64::from(prev)).to_radians().abs();
        let p = f64::from(l.p_max_rad);
        assert!(
            step <= p * (1.0 + 1e-4) + 1e-3 * (1.0 + f64::from(total).to_radians().abs() * 1e-3),
            "position jumped {step} rad (PMAX {p}): {prev}° → {total}°"
        );
    }
}

fn tick(motor: &DmMotor, now: u64, can_id: u16) {
    motor.update(Instant::from_ticks(now), 0.001);
    let mut batch = TxBatch::new();
    motor.pack_command(&mut batch);
    assert_eq!(batch.frames().len(), 1);
    let f = &batch.frames()[0];
    assert!(!f.is_extended() && f.raw_id() == u32::from(can_id));
    let d = proto::data8(f).expect("DLC 8");
    let s = motor.state();
    if !s.online && proto::dm_special(&d).is_none() {
        let c = proto::mit_codes(&d);
        assert!(
            c.kp == 0 && c.kd == 0 && (c.t == 2047 || c.t == 2048),
            "offline, not zero torque: {c:?}"
        );
        assert_eq!(s.command, 0.0);
    }
}

/// Packs an MIT command of any values with any ranges.
fn pack(u: &mut Unstructured<'_>) {
    let mut f = || f32_from(u).unwrap_or(0.0);
    let command = MitCommand {
        position_rad: f(),
        velocity_rad_s: f(),
        kp: f(),
        kd: f(),
        torque_nm: f(),
    };
    let range = |x: f32| if x.abs() > DM_RANGE_CAP { 12.5 } else { x };
    let limits = MitLimits {
        p_max_rad: range(f()),
        v_max_rad_s: range(f()),
        t_max_nm: range(f()),
    };
    let d = command.pack(&limits);
    let valid = |x: f32| x.is_finite() && x > 0.0;
    if !(valid(limits.p_max_rad) && valid(limits.v_max_rad_s) && valid(limits.t_max_nm)) {
        return; // not a range a motor can hold; packing must only not panic
    }
    let c = proto::mit_codes(&d);
    let check = |code: u16, x: f32, min: f32, max: f32, bits: u32, what: &str| {
        let got = proto::code_to_value(code, min, max, bits);
        let want = proto::clamp_f64(x, min, max);
        let step = proto::code_step(min, max, bits);
        assert!(
            (got - want).abs() <= step * 1.001 + want.abs() * 1e-6,
            "{what}: code {code} = {got}, want {want} ({command:?}, {limits:?})"
        );
    };
    let (p, v, t) = (limits.p_max_rad, limits.v_max_rad_s, limits.t_max_nm);
    check(c.p, command.position_rad, -p, p, 16, "position");
    check(c.v, command.velocity_rad_s, -v, v, 12, "velocity");
    check(c.kp, command.kp, 0.0, 500.0, 12, "kp");
    check(c.kd, command.kd, 0.0, 5.0, 12, "kd");
    // The documented exception: with every other field at the top, a torque code of
    // 0xFFB..=0xFFE would make a special command and is sent as 0xFFA.
    let all_top = c.p == 0xFFFF && c.v == 0xFFF && c.kp == 0xFFF && c.kd == 0xFFF;
    if all_top && c.t == 0xFFA {
        let want = proto::clamp_f64(command.torque_nm, -t, t);
        let step = proto::code_step(-t, t, 12);
        let got = proto::code_to_value(c.t, -t, t, 12);
        assert!(
            got <= want + step * 1.001 && got >= want - step * 5.001,
            "torque near the top"
        );
    } else {
        check(c.t, command.torque_nm, -t, t, 12, "torque");
    }
    assert!(
        proto::dm_special(&d).is_none() || DM_MIT_SPECIAL_COLLISION,
        "MIT command {command:?} packs to special command bytes {d:02X?}"
    );
}
