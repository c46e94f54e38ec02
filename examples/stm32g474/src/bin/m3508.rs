//! RC10_LIB manual's walkthrough: one M3508 (C620 ESC id 1) on FDCAN1. It runs at 100 rpm
//! for three seconds, then holds output angles 0°, 90°, 180°, 270° in turn, then a multi-turn
//! angle of 720°; its state is logged over defmt at 10 Hz.
//!
//! Wiring: NUCLEO-G474RE, PA11/PA12 to a CAN transceiver, CAN_H/CAN_L to the C620 (set to
//! id 1 with its button), 120 Ω at both ends of the bus, 24 V to the C620.
//!
//! Run: `cargo embed --release --bin m3508` (or `cargo run --release --bin m3508` with
//! probe-rs) in `examples/stm32g474`.
#![no_std]
#![no_main]

use embassy_executor::Spawner;
use embassy_time::{Duration, Ticker, Timer};
use rc10_core::motor::Motor;
use rc10_core::motor::dji::DjiMotor;
use rc10_examples_stm32g474 as board;
use rc10_stm32::tasks::G4Bus;
use static_cell::StaticCell;

static WHEEL: DjiMotor = match DjiMotor::m3508(1) {
    Ok(m) => m,
    Err(_) => panic!("M3508 id"),
};
static BUS: StaticCell<G4Bus> = StaticCell::new();

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = board::init();
    let mut builder = board::bus_builder();
    defmt::unwrap!(builder.register(&WHEEL));
    let bus = board::start_bus(builder, &BUS, board::fdcan1!(p), board::control_spawner());
    board::start_watchdog!(spawner, p, [bus]);
    spawner.spawn(defmt::unwrap!(log_state()));

    defmt::unwrap!(WHEEL.set_target_rpm(100.0));
    Timer::after(Duration::from_secs(3)).await;
    for angle_deg in [0.0, 90.0, 180.0, 270.0] {
        defmt::unwrap!(WHEEL.set_target_angle_deg(angle_deg));
        Timer::after(Duration::from_secs(2)).await;
    }
    defmt::unwrap!(WHEEL.set_target_total_angle_deg(720.0));
}

#[embassy_executor::task]
async fn log_state() {
    let mut ticker = Ticker::every(Duration::from_millis(100));
    loop {
        ticker.next().await;
        let s = WHEEL.state();
        defmt::info!(
            "online {} mode {} target {} speed {} rpm angle {} deg total {} deg current {} A temp {} C",
            s.online,
            s.mode,
            s.target,
            s.speed_rpm,
            s.angle_deg,
            s.total_angle_deg,
            s.current_amps,
            s.temperature_c
        );
    }
}
