//! Regression tests for what the fuzz targets (`fuzz/`, see fuzz/README.md) found: each test
//! reproduces one finding with plain values, in the ordinary suite. A test marked
//! `#[ignore = "fuzz crash, fix pending"]` fails today; when its fix lands, remove the
//! `#[ignore]` and set the matching switch in `fuzz/src/lib.rs` (`pending`) to `false`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use rc10_core::can::CanFrame;
use rc10_core::motor::Motor;
use rc10_core::motor::dm::{DmConfig, DmMotor, MitCommand, MitLimits};
use rc10_core::node::{CanNode, TxBatch};
use rc10_core::time::Instant;

/// Whether eight bytes are a Damiao special command: `FF FF FF FF FF FF FF` then FB (clear
/// error), FC (enable), FD (disable) or FE (save position zero).
fn is_special(d: &[u8]) -> bool {
    d.len() == 8 && d[..7].iter().all(|b| *b == 0xFF) && (0xFB..=0xFE).contains(&d[7])
}

/// The torque that packs to 12-bit code `code` over ±`t_max` (the middle of its step).
fn torque_for_code(code: u16, t_max: f32) -> f32 {
    (f32::from(code) + 0.5) * (2.0 * t_max / 4095.0) - t_max
}

/// Found by `fuzz/fuzz_targets/dm_feedback.rs` (`MitCommand { position_rad: 92520.0,
/// velocity_rad_s: 1445.6, kp: 1445.6, kd: 117.6, torque_nm: 1638.4 }` with a 1638.4 N·m
/// range packed to `FF FF FF FF FF FF FF FE`).
///
/// Every MIT field is clamped to its range, so position ≥ PMAX, velocity ≥ VMAX, kp ≥ 500 and
/// kd ≥ 5 all become all-ones codes; a torque just below TMAX then makes the last byte FB–FE,
/// and the eight bytes are exactly a special command. The motor executes it instead of the MIT
/// command: clear error, enable, disable (the joint goes limp) or save position zero (the
/// joint's zero moves to wherever it is). An MIT command must never take that shape (e.g.
/// keep the torque code at or below 0xFFA when the other fields are all ones).
#[test]
fn mit_command_at_the_range_ends_never_packs_to_a_special_command() {
    let limits = MitLimits::DEFAULT;
    for code in 0xFFB..=0xFFE {
        let command = MitCommand {
            position_rad: limits.p_max_rad,
            velocity_rad_s: limits.v_max_rad_s,
            kp: 500.0,
            kd: 5.0,
            torque_nm: torque_for_code(code, limits.t_max_nm),
        };
        let bytes = command.pack(&limits);
        assert!(
            !is_special(&bytes),
            "{command:?} packs to the special command {bytes:02X?}"
        );
    }
}

/// The same through the driver: a raw MIT command set on an online, enabled motor goes on the
/// bus as "save position zero".
#[test]
fn mit_command_on_the_bus_is_not_read_as_save_zero() {
    let motor = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
    let t0 = Instant::from_millis(10);
    // Feedback: motor 1, enabled (state 1), mid-range position, zero speed and torque.
    let feedback = CanFrame::standard(0x11, &[0x11, 0x80, 0x00, 0x80, 0x07, 0xFF, 30, 30]).unwrap();
    motor.update_feedback(&feedback, t0).unwrap();
    motor
        .set_mit(MitCommand {
            position_rad: 12.5,
            velocity_rad_s: 30.0,
            kp: 500.0,
            kd: 5.0,
            torque_nm: torque_for_code(0xFFE, 10.0),
        })
        .unwrap();
    motor.update(t0, 0.001);
    let mut batch = TxBatch::new();
    motor.pack_command(&mut batch);
    let sent = batch.frames()[0].data();
    assert!(!is_special(sent), "sent {sent:02X?}");
}

/// Found by `fuzz/fuzz_targets/dm_feedback.rs` (reported speed `inf` with a VMAX of about
/// 3.3e37 rad/s).
///
/// `DmMotor::new` accepts any finite, positive MIT range, but the driver's own unit
/// conversions overflow for ranges near `f32::MAX`: the speed (rad/s × 60 / 2π) and the angle
/// (rad → degrees) it reports become infinite, and `MitCommand::pack` with a range whose span
/// (2 · max) overflows packs every field as code 0 (the bottom of the range). No real motor
/// has such ranges (factory: 12.5 rad, 30 rad/s, 10 N·m), so the fix is to refuse them at
/// construction (`DmError::InvalidLimit`) or to convert without overflowing.
#[test]
fn dm_motor_accepts_only_ranges_it_can_convert() {
    let huge = MitLimits {
        p_max_rad: 1.0e37,
        v_max_rad_s: 1.0e37,
        t_max_nm: 10.0,
    };
    let config = DmConfig {
        limits: huge,
        ..DmConfig::new(0x11)
    };
    let Ok(motor) = DmMotor::new(0x01, config) else {
        return; // refused at construction: fixed
    };
    // Feedback at the top of the velocity and position fields.
    let feedback = CanFrame::standard(0x11, &[0x11, 0xFF, 0xFF, 0xFF, 0xF7, 0xFF, 30, 30]).unwrap();
    motor
        .update_feedback(&feedback, Instant::from_millis(1))
        .unwrap();
    let state = motor.state();
    assert!(state.speed_rpm.is_finite(), "speed {}", state.speed_rpm);
    assert!(
        state.total_angle_deg.is_some_and(f32::is_finite),
        "angle {:?}",
        state.total_angle_deg
    );
}

/// The packing half of the finding above: a range whose span overflows f32.
#[test]
fn mit_pack_with_a_range_near_f32_max_keeps_zero_in_the_middle() {
    let limits = MitLimits {
        p_max_rad: f32::MAX,
        v_max_rad_s: 30.0,
        t_max_nm: 10.0,
    };
    let bytes = MitCommand::ZERO_TORQUE.pack(&limits);
    // Position 0 over ±f32::MAX is code 0x7FFF (the middle), not 0 (−f32::MAX).
    assert_eq!(
        u16::from_be_bytes([bytes[0], bytes[1]]),
        0x7FFF,
        "{bytes:02X?}"
    );
}
