//! Motors on FDCAN1, FDCAN2 and FDCAN3 at once, each bus with its own scheduler and receiver
//! task on the control executor; every bus's statistics are logged once a second.
//!
//! FDCAN1: four M3508 (C620 ids 1–4), a chassis. FDCAN2: two GM6020 (ids 1, 2), a gimbal.
//! FDCAN3: two M2006 (C610 ids 1, 2), feeders. All hold speed or angle targets.
//!
//! **The wheels (50 rpm) and feeders (120 rpm) start turning at boot**, with no remote and no
//! enable switch: run it with the robot on blocks. The GM6020s hold the angle they powered on
//! at (a power-on origin), so they do not move; a real gimbal uses absolute zeros measured on
//! the mechanism, as the `gimbal` example shows.
//!
//! Wiring: NUCLEO-G474RE with three transceivers: FDCAN1 PA11/PA12, FDCAN2 PB12/PB13, FDCAN3
//! PA8/PB4; each bus terminated with 120 Ω at both ends.
//!
//! Run: `cargo embed --release --bin three-buses` in `examples/stm32g474`.
#![no_std]
#![no_main]

use embassy_executor::Spawner;
use embassy_time::{Duration, Ticker};
use rc10_core::encoder::Origin;
use rc10_core::motor::Motor;
use rc10_core::motor::dji::{DjiConfig, DjiModel, DjiMotor};
use rc10_examples_stm32g474 as board;
use rc10_stm32::tasks::G4Bus;
use static_cell::StaticCell;

const fn ok(m: Result<DjiMotor, rc10_core::motor::dji::DjiError>) -> DjiMotor {
    match m {
        Ok(m) => m,
        Err(_) => panic!("DJI motor id"),
    }
}

static WHEELS: [DjiMotor; 4] = [
    ok(DjiMotor::m3508(1)),
    ok(DjiMotor::m3508(2)),
    ok(DjiMotor::m3508(3)),
    ok(DjiMotor::m3508(4)),
];
/// A GM6020's default zero is raw count 0, wherever that is on the mechanism: an angle target
/// would turn the motor up to 180° towards it (into a pitch's stops). This demo counts from the
/// power-on position instead, so angle 0 holds the gimbal where it is.
const HOLD_AT_POWER_ON: DjiConfig = DjiConfig {
    origin: Origin::PowerOn,
    ..DjiConfig::default_for(DjiModel::Gm6020Voltage)
};
static GIMBAL: [DjiMotor; 2] = [
    ok(DjiMotor::new(DjiModel::Gm6020Voltage, 1, HOLD_AT_POWER_ON)),
    ok(DjiMotor::new(DjiModel::Gm6020Voltage, 2, HOLD_AT_POWER_ON)),
];
static FEEDERS: [DjiMotor; 2] = [ok(DjiMotor::m2006(1)), ok(DjiMotor::m2006(2))];
static BUS1: StaticCell<G4Bus> = StaticCell::new();
static BUS2: StaticCell<G4Bus> = StaticCell::new();
static BUS3: StaticCell<G4Bus> = StaticCell::new();

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = board::init();
    let control = board::control_spawner();
    let mut b1 = board::bus_builder();
    for m in &WHEELS {
        defmt::unwrap!(b1.register(m));
    }
    let mut b2 = board::bus_builder();
    for m in &GIMBAL {
        defmt::unwrap!(b2.register(m));
    }
    let mut b3 = board::bus_builder();
    for m in &FEEDERS {
        defmt::unwrap!(b3.register(m));
    }
    let buses = [
        (
            "FDCAN1",
            board::start_bus(b1, &BUS1, board::fdcan1!(p), control),
        ),
        (
            "FDCAN2",
            board::start_bus(b2, &BUS2, board::fdcan2!(p), control),
        ),
        (
            "FDCAN3",
            board::start_bus(b3, &BUS3, board::fdcan3!(p), control),
        ),
    ];
    board::start_watchdog!(spawner, p, [buses[0].1, buses[1].1, buses[2].1]);

    for m in &WHEELS {
        defmt::unwrap!(m.set_target_rpm(50.0));
    }
    for m in &GIMBAL {
        defmt::unwrap!(m.set_target_angle_deg(0.0));
    }
    for m in &FEEDERS {
        defmt::unwrap!(m.set_target_rpm(120.0));
    }
    let mut ticker = Ticker::every(Duration::from_secs(1));
    loop {
        ticker.next().await;
        for (name, bus) in &buses {
            board::log_bus(name, bus);
        }
    }
}
