//! Property tests: the commands the VESC and Damiao drivers put on the wire stay within their
//! configured ranges for any sequence of targets, limits, mode switches, feedback and silence,
//! and release the motor while it is offline (the DJI driver's version of this property is in
//! `src/motor/dji/tests.rs`).
//!
//! - VESC: every frame is one of the documented command packets to this controller
//!   (extended ID `(packet << 8) | id`, four bytes); SET_CURRENT within ± the configured
//!   maximum and the user limit, SET_CURRENT_BRAKE within [0, configured maximum], SET_DUTY
//!   within ±1, SET_RPM within ± the maximum speed in eRPM, SET_POS within [0°, 360°]; more
//!   than the offline timeout (100 ms) after the last STATUS frame, exactly SET_CURRENT 0.
//! - Damiao: every frame goes to the motor's CAN ID with eight bytes; while offline it is
//!   either a special command (enable) or an MIT command with zero gains and zero torque
//!   (within one torque quantum), never a position or velocity hold; the reported command
//!   torque is finite and within ±TMAX.
//!
//! Frames are decoded here from the protocol layouts (VESC `comm_can`, SPEC.md for Damiao).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use proptest::prelude::*;
use proptest::test_runner::Config;
use rc10_core::can::CanFrame;
use rc10_core::encoder::GearRatio;
use rc10_core::motor::Motor;
use rc10_core::motor::dm::{DmConfig, DmMotor, DmSpecial, MitCommand, MitLimits};
use rc10_core::motor::vesc::{VescConfig, VescMotor};
use rc10_core::node::{CanNode, TxBatch};
use rc10_core::time::{Duration, Instant};

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
/// The documented default offline timeout.
const OFFLINE_AFTER: Duration = Duration::from_millis(100);

/// A target: usually plausible, sometimes huge, occasionally not finite (rejected by setters).
fn target() -> impl Strategy<Value = f32> {
    prop_oneof![
        8 => -500.0f32..500.0,
        2 => proptest::num::f32::NORMAL,
        1 => prop_oneof![Just(f32::NAN), Just(f32::INFINITY), Just(f32::NEG_INFINITY)],
    ]
}

#[derive(Debug, Clone)]
enum VescOp {
    Current(f32),
    Rpm(f32),
    Duty(f32),
    Brake(f32),
    Angle(f32),
    Torque(f32),
    Limit(f32),
    Disable,
    Status { erpm: i32, current: i16, duty: i16 },
    Silence(u64),
}

fn vesc_op() -> impl Strategy<Value = VescOp> {
    prop_oneof![
        target().prop_map(VescOp::Current),
        target().prop_map(|x| VescOp::Rpm(x * 100.0)),
        target().prop_map(|x| VescOp::Duty(x / 100.0)),
        target().prop_map(VescOp::Brake),
        target().prop_map(VescOp::Angle),
        target().prop_map(VescOp::Torque),
        prop_oneof![0.0f32..300.0, Just(f32::INFINITY)].prop_map(VescOp::Limit),
        Just(VescOp::Disable),
        (any::<i32>(), any::<i16>(), any::<i16>()).prop_map(|(erpm, current, duty)| {
            VescOp::Status {
                erpm,
                current,
                duty,
            }
        }),
        prop_oneof![1u64..20, 90u64..300].prop_map(VescOp::Silence),
    ]
}

fn vesc_config() -> impl Strategy<Value = VescConfig> {
    (
        1u8..=30,
        prop_oneof![Just((1u32, 1u32)), (1u32..=50, 1u32..=5)],
        (0.0f32..200.0, 0.0f32..100.0, 0.0f32..20_000.0),
        proptest::option::of(0.0f32..150.0),
        proptest::option::of(0.01f32..2.0),
    )
        .prop_map(|(pp, (rot, out), (cur, brake, speed), zero_brake, kt)| {
            let mut c = VescConfig::new(pp);
            c.gear = GearRatio::new(rot, out).unwrap();
            c.max_current_amps = cur;
            c.max_brake_amps = brake;
            c.max_speed_rpm = speed;
            c.zero_speed_brake_amps = zero_brake;
            c.torque_constant_nm_per_amp = kt;
            c
        })
}

/// STATUS (packet 9): i32 eRPM, i16 current × 10, i16 duty × 1000, big-endian.
fn vesc_status(id: u8, erpm: i32, current: i16, duty: i16) -> CanFrame {
    let mut d = [0u8; 8];
    d[..4].copy_from_slice(&erpm.to_be_bytes());
    d[4..6].copy_from_slice(&current.to_be_bytes());
    d[6..].copy_from_slice(&duty.to_be_bytes());
    CanFrame::extended((9 << 8) | u32::from(id), &d).unwrap()
}

proptest! {
    #![proptest_config(config(256))]

    /// VESC: every packed command within its configured range; SET_CURRENT 0 while offline.
    #[test]
    fn vesc_commands_stay_in_range_and_release_offline(
        id in 0u8..=254, cfg in vesc_config(), ops in proptest::collection::vec(vesc_op(), 1..100),
    ) {
        let m = VescMotor::new(id, cfg).unwrap();
        let mut now = T0;
        let mut last_status: Option<Instant> = None;
        let mut user_limit = f32::INFINITY;
        let erpm_max = f64::from(cfg.max_speed_rpm) * f64::from(cfg.pole_pairs)
            * f64::from(cfg.gear.rotor_turns()) / f64::from(cfg.gear.output_turns());
        for op in ops {
            match op {
                VescOp::Current(x) => { let _ = m.set_target_current(x); }
                VescOp::Rpm(x) => { let _ = m.set_target_rpm(x); }
                VescOp::Duty(x) => { let _ = m.set_duty(x); }
                VescOp::Brake(x) => { let _ = m.set_brake_current(x); }
                VescOp::Angle(x) => { let _ = m.set_target_angle_deg(x); }
                VescOp::Torque(x) => { let _ = m.set_target_torque_nm(x); }
                VescOp::Limit(x) => {
                    m.set_current_limit_amps(x).unwrap();
                    user_limit = x;
                }
                VescOp::Disable => m.disable(),
                VescOp::Status { erpm, current, duty } => {
                    m.update_feedback(&vesc_status(id, erpm, current, duty), now).unwrap();
                    last_status = Some(now);
                }
                VescOp::Silence(ms) => now += Duration::from_millis(ms),
            }
            now += Duration::from_millis(1);
            let mut batch = TxBatch::new();
            m.update(now, 0.001);
            m.pack_command(&mut batch);
            prop_assert_eq!(batch.frames().len(), 1);
            let f = batch.frames()[0];
            prop_assert!(f.is_extended());
            prop_assert_eq!(f.raw_id() & 0xFF, u32::from(id));
            prop_assert_eq!(f.dlc(), 4);
            let d = f.data();
            let raw = i32::from_be_bytes([d[0], d[1], d[2], d[3]]);
            let packet = f.raw_id() >> 8;
            let offline = last_status.is_none_or(|t| now.checked_duration_since(t).is_some_and(|e| e > OFFLINE_AFTER));
            if offline {
                prop_assert_eq!((packet, raw), (1, 0), "offline must send SET_CURRENT 0");
                prop_assert!(!m.is_online());
                continue;
            }
            // Half a mA of rounding to the wire's integer, plus the f32 rounding of amps × 1000.
            let amps_ok =
                |amps: f64, max: f32| amps.abs() <= f64::from(max) * (1.0 + 1e-6) + 0.0005;
            match packet {
                0 => prop_assert!(raw.abs() <= 100_000, "duty {raw}"),
                1 => {
                    let amps = f64::from(raw) / 1000.0;
                    prop_assert!(amps_ok(amps, cfg.max_current_amps), "current {amps} A");
                    prop_assert!(amps_ok(amps, user_limit), "current {amps} A beyond the limit {user_limit}");
                }
                2 => {
                    let amps = f64::from(raw) / 1000.0;
                    prop_assert!(amps >= 0.0 && amps_ok(amps, cfg.max_brake_amps), "brake {amps} A");
                }
                3 => prop_assert!(f64::from(raw).abs() <= erpm_max * (1.0 + 1e-6) + 1.0, "eRPM {raw} beyond {erpm_max}"),
                4 => prop_assert!((0..=360_000_000).contains(&raw), "position {raw}"),
                other => prop_assert!(false, "packet {other}"),
            }
            prop_assert!(m.state().command.is_finite());
        }
    }
}

#[derive(Debug, Clone)]
enum DmOp {
    Rpm(f32),
    Angle(f32),
    Total(f32),
    Torque(f32),
    FeedForward(f32),
    Mit(MitCommand),
    Home(f32),
    Disable,
    Special(DmSpecial),
    Feedback { state: u8, p: u16, v: u16, t: u16 },
    Silence(u64),
}

fn dm_op() -> impl Strategy<Value = DmOp> {
    prop_oneof![
        target().prop_map(DmOp::Rpm),
        target().prop_map(DmOp::Angle),
        target().prop_map(DmOp::Total),
        target().prop_map(DmOp::Torque),
        target().prop_map(DmOp::FeedForward),
        (target(), target(), target(), target(), target()).prop_map(|(p, v, kp, kd, t)| {
            DmOp::Mit(MitCommand {
                position_rad: p,
                velocity_rad_s: v,
                kp,
                kd,
                torque_nm: t,
            })
        }),
        target().prop_map(DmOp::Home),
        Just(DmOp::Disable),
        prop_oneof![
            Just(DmSpecial::Enable),
            Just(DmSpecial::Disable),
            Just(DmSpecial::SaveZero),
            Just(DmSpecial::ClearError),
        ]
        .prop_map(DmOp::Special),
        (
            prop_oneof![Just(0u8), Just(1), 8u8..15],
            any::<u16>(),
            0u16..4096,
            0u16..4096
        )
            .prop_map(|(state, p, v, t)| DmOp::Feedback { state, p, v, t }),
        prop_oneof![1u64..20, 90u64..300].prop_map(DmOp::Silence),
    ]
}

fn dm_feedback(master: u16, id: u16, state: u8, p: u16, v: u16, t: u16) -> CanFrame {
    let d = [
        (id & 0xF) as u8 | (state << 4),
        (p >> 8) as u8,
        (p & 0xFF) as u8,
        (v >> 4) as u8,
        (((v & 0xF) << 4) as u8) | ((t >> 8) as u8),
        (t & 0xFF) as u8,
        40,
        40,
    ];
    CanFrame::standard(master, &d).unwrap()
}

fn is_special(d: &[u8; 8]) -> bool {
    d[..7].iter().all(|b| *b == 0xFF) && (0xFB..=0xFE).contains(&d[7])
}

proptest! {
    #![proptest_config(config(256))]

    /// Damiao: while offline the motor gets zero gains and zero torque (or a special command),
    /// and the command torque the driver reports is finite and within ±TMAX.
    #[test]
    fn dm_commands_release_offline(
        limits in prop_oneof![
            Just(MitLimits::DEFAULT),
            (3.2f32..50.0, 1.0f32..100.0, 1.0f32..50.0)
                .prop_map(|(p, v, t)| MitLimits { p_max_rad: p, v_max_rad_s: v, t_max_nm: t }),
        ],
        ops in proptest::collection::vec(dm_op(), 1..100),
    ) {
        let (can_id, master) = (0x03u16, 0x13u16);
        let mut cfg = DmConfig::new(master);
        cfg.limits = limits;
        let m = DmMotor::new(can_id, cfg).unwrap();
        let mut now = T0;
        let mut last_feedback: Option<Instant> = None;
        let t_step = 2.0 * f64::from(limits.t_max_nm) / 4095.0;
        for op in ops {
            match op {
                DmOp::Rpm(x) => { let _ = m.set_target_rpm(x); }
                DmOp::Angle(x) => { let _ = m.set_target_angle_deg(x); }
                DmOp::Total(x) => { let _ = m.set_target_total_angle_deg(x); }
                DmOp::Torque(x) => { let _ = m.set_target_torque_nm(x); }
                DmOp::FeedForward(x) => { let _ = m.set_feed_forward_torque_nm(x); }
                DmOp::Mit(c) => { let _ = m.set_mit(c); }
                DmOp::Home(x) => { let _ = m.set_total_angle_here_deg(x); }
                DmOp::Disable => m.disable(),
                DmOp::Special(s) => m.send_special(s),
                DmOp::Feedback { state, p, v, t } => {
                    m.update_feedback(&dm_feedback(master, can_id, state, p, v, t), now).unwrap();
                    last_feedback = Some(now);
                }
                DmOp::Silence(ms) => now += Duration::from_millis(ms),
            }
            now += Duration::from_millis(1);
            let mut batch = TxBatch::new();
            m.update(now, 0.001);
            m.pack_command(&mut batch);
            prop_assert_eq!(batch.frames().len(), 1);
            let f = batch.frames()[0];
            prop_assert!(!f.is_extended());
            prop_assert_eq!(f.raw_id(), u32::from(can_id));
            let d = *f.data8().unwrap();
            let command = m.state().command;
            prop_assert!(command.is_finite() && command.abs() <= limits.t_max_nm, "command {command}");
            let offline = last_feedback.is_none_or(|t| now.checked_duration_since(t).is_some_and(|e| e > OFFLINE_AFTER));
            if offline && !is_special(&d) {
                // MIT fields: kp = D3 low nibble + D4, kd = D5 + D6 high nibble, t 12 bits.
                let kp = (u32::from(d[3] & 0xF) << 8) | u32::from(d[4]);
                let kd = (u32::from(d[5]) << 4) | u32::from(d[6] >> 4);
                let t = (u32::from(d[6] & 0xF) << 8) | u32::from(d[7]);
                let torque = f64::from(t) * t_step - f64::from(limits.t_max_nm);
                prop_assert_eq!((kp, kd), (0, 0), "offline with gains: {:02X?}", d);
                prop_assert!(torque.abs() <= t_step, "offline with torque {torque}: {d:02X?}");
            }
        }
    }
}
