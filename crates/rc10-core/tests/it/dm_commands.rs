//! Damiao MIT commands on the wire, byte for byte, where mutation testing found gaps: the
//! gains and feed-forward of an angle target, the special-command guard only when every
//! field is at the top, and ranges so wide that the scaling must avoid overflow. Field codes
//! follow Damiao's reference conversion: code = trunc((x - min) / (max - min) · (2^bits - 1)).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use rc10_core::can::CanFrame;
use rc10_core::motor::Motor;
use rc10_core::motor::dm::{DmConfig, DmMotor, MitCommand, MitLimits};
use rc10_core::node::{CanNode, TxBatch};
use rc10_core::time::Instant;

#[test]
fn angle_targets_carry_the_position_gains_and_feed_forward() {
    // DM4310 defaults: position kp 20 N·m/rad -> trunc(20/500 · 4095) = 163 = 0x0A3;
    // kd 1.0 N·m·s/rad -> trunc(1/5 · 4095) = 819 = 0x333; feed-forward 2 N·m of ±10 ->
    // trunc(12/20 · 4095) = 2457 = 0x999.
    let m = DmMotor::new(0x02, DmConfig::new(0x12)).unwrap();
    assert_eq!(m.can_id(), 0x02);
    let now = Instant::from_millis(7);
    // Enabled (state 1), motor id 2, position code 0x7FFF (≈ 0 rad), velocity and torque 0.
    let fb = CanFrame::standard(0x12, &[0x12, 0x7F, 0xFF, 0x7F, 0xF7, 0xFF, 30, 30]).unwrap();
    m.update_feedback(&fb, now).unwrap();
    m.set_feed_forward_torque_nm(2.0).unwrap();
    m.set_target_total_angle_deg(90.0).unwrap();
    m.update(now, 0.001);
    let mut out = TxBatch::new();
    m.pack_command(&mut out);
    let d = out.frames()[0].data();
    assert_eq!(out.frames()[0].raw_id(), 0x02);
    assert_eq!((d[3] & 0x0F, d[4]), (0x0, 0xA3), "kp {d:02X?}");
    assert_eq!((d[5], d[6] >> 4), (0x33, 0x3), "kd {d:02X?}");
    assert_eq!((d[6] & 0x0F, d[7]), (0x9, 0x99), "torque {d:02X?}");
    assert_eq!((d[3] >> 4, d[2]), (0xF, 0x7F), "velocity 0x7FF {d:02X?}");
}

#[test]
fn torque_codes_near_the_top_are_kept_unless_every_field_is_at_the_top() {
    // Torque 9.98779 N·m of ±10: trunc(19.98779/20 · 4095) = 4092 = 0xFFC. With only the
    // position at the top the frame cannot read as a special command (FF×7 FC needs every
    // field at the top), so the torque goes as asked.
    let cmd = MitCommand {
        position_rad: 12.5,
        velocity_rad_s: 0.0,
        kp: 0.0,
        kd: 0.0,
        torque_nm: 9.98779,
    };
    let d = cmd.pack(&MitLimits::DEFAULT);
    assert_eq!((d[0], d[1]), (0xFF, 0xFF));
    assert_eq!((d[6] & 0x0F, d[7]), (0xF, 0xFC), "{d:02X?}");
}

#[test]
fn very_wide_ranges_scale_without_overflow() {
    // ±1e36 rad: (x - min) · 65535 overflows f32, the ratio does not. 5e35 is 3/4 of the way
    // from -1e36 to 1e36: trunc(0.75 · 65535) = 49151 = 0xBFFF.
    let limits = MitLimits {
        p_max_rad: 1e36,
        v_max_rad_s: 30.0,
        t_max_nm: 10.0,
    };
    let cmd = MitCommand {
        position_rad: 5e35,
        ..MitCommand::ZERO_TORQUE
    };
    let d = cmd.pack(&limits);
    assert_eq!((d[0], d[1]), (0xBF, 0xFF), "{d:02X?}");
}
