//! A GM6020 yaw + pitch gimbal holding angles on FDCAN2, voltage mode, with a feed-forward
//! torque on the pitch against gravity.
//!
//! The yaw sweeps between -30° and +30° every 2 s (multi-turn targets, the way a gimbal that
//! follows a world heading commands it); the pitch holds 10°. Both GM6020s use their absolute
//! encoders: angle 0 is raw count `*_ZERO_COUNTS`. As shipped these are `None`: the firmware
//! then drives nothing (0 V to both motors) and logs each motor's raw count, so you can move
//! the gimbal by hand to its zero (yaw forward, pitch level), read the counts, set them here
//! and flash again. Until then nothing moves: a made-up zero would drive the pitch into its
//! stops.
//!
//! Wiring: NUCLEO-G474RE; FDCAN2 (PB12 RX / PB13 TX) to a transceiver; GM6020 yaw set to id 1
//! (feedback 0x205), pitch to id 2 (0x206), 24 V.
//!
//! Run: `cargo embed --release --bin gimbal` in `examples/stm32g474`.
#![no_std]
#![no_main]

use embassy_executor::Spawner;
use embassy_time::{Duration, Ticker, Timer};
use rc10_core::encoder::Origin;
use rc10_core::motor::Motor;
use rc10_core::motor::dji::{DjiConfig, DjiModel, DjiMotor};
use rc10_examples_stm32g474 as board;
use rc10_stm32::tasks::G4Bus;
use static_cell::StaticCell;

/// Raw encoder count (0–8191) of the yaw's mechanical zero; `None` until you have read it.
const YAW_ZERO_COUNTS: Option<u16> = None;
/// Raw encoder count (0–8191) of the pitch's level position; `None` until you have read it.
const PITCH_ZERO_COUNTS: Option<u16> = None;
/// Both zeros set: the gimbal may move.
const CALIBRATED: bool = YAW_ZERO_COUNTS.is_some() && PITCH_ZERO_COUNTS.is_some();
/// Gravity torque of the pitch assembly at level, N·m (mass × centre-of-mass offset × g).
const PITCH_GRAVITY_NM: f32 = 0.3;

const fn gm6020(id: u8, zero: Option<u16>) -> DjiMotor {
    let mut config = DjiConfig::default_for(DjiModel::Gm6020Voltage);
    // Without a zero, angle 0 is raw count 0.
    config.origin = Origin::Absolute {
        zero_offset_counts: match zero {
            Some(counts) => counts,
            None => 0,
        },
    };
    match DjiMotor::new(DjiModel::Gm6020Voltage, id, config) {
        Ok(m) => m,
        Err(_) => panic!("GM6020 configuration"),
    }
}

static YAW: DjiMotor = gm6020(1, YAW_ZERO_COUNTS);
static PITCH: DjiMotor = gm6020(2, PITCH_ZERO_COUNTS);
static BUS: StaticCell<G4Bus> = StaticCell::new();

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = board::init();
    let mut builder = board::bus_builder();
    defmt::unwrap!(builder.register(&YAW));
    defmt::unwrap!(builder.register(&PITCH));
    let bus = board::start_bus(builder, &BUS, board::fdcan2!(p), board::control_spawner());
    board::start_watchdog!(spawner, p, [bus]);
    spawner.spawn(defmt::unwrap!(log_state()));
    if !CALIBRATED {
        defmt::warn!(
            "gimbal zeros not set: both GM6020s get 0 V; move the gimbal to its zero and copy the \
             raw counts from the log into YAW_ZERO_COUNTS / PITCH_ZERO_COUNTS"
        );
        return; // No target is ever set: the motors stay disabled, the log task runs on.
    }

    defmt::unwrap!(PITCH.set_feed_forward_torque_nm(PITCH_GRAVITY_NM));
    defmt::unwrap!(PITCH.set_target_angle_deg(10.0));
    loop {
        for yaw_deg in [-30.0, 30.0] {
            defmt::unwrap!(YAW.set_target_total_angle_deg(yaw_deg));
            Timer::after(Duration::from_secs(2)).await;
        }
    }
}

#[embassy_executor::task]
async fn log_state() {
    let mut ticker = Ticker::every(Duration::from_millis(100));
    loop {
        ticker.next().await;
        let (y, p) = (YAW.state(), PITCH.state());
        if !CALIBRATED {
            // The single-turn angle is (raw count − zero) × 360 / 8192, the zero 0 where unset.
            let raw = |deg: Option<f32>, zero: Option<u16>| {
                deg.map(|d| ((d * 8192.0 / 360.0 + 0.5) as u16 + zero.unwrap_or(0)) % 8192)
            };
            defmt::info!(
                "raw counts: yaw {} pitch {} (online {}/{})",
                raw(y.angle_deg, YAW_ZERO_COUNTS),
                raw(p.angle_deg, PITCH_ZERO_COUNTS),
                y.online,
                p.online
            );
            continue;
        }
        defmt::info!(
            "yaw {} deg (target {}), pitch {} deg (target {}), commands {} V / {} V, online {}/{}",
            y.total_angle_deg,
            y.target,
            p.angle_deg,
            p.target,
            y.command,
            p.command,
            y.online,
            p.online
        );
    }
}
