//! RC10_LIB manual's "MyMotor": a motor rc10 does not know, written against rc10-core's
//! traits in [`my_motor.rs`](../my_motor.rs), sharing FDCAN1 with an M3508. The bus checks
//! its declared IDs against the M3508's and builds the FDCAN filters from them; code written
//! against the `Motor` trait drives both alike.
//!
//! Wiring: NUCLEO-G474RE; FDCAN1 (PA11 RX / PA12 TX) to a transceiver; an M3508 (C620 id 1)
//! and your MyMotor (id 1) on the bus.
//!
//! Run: `cargo embed --release --bin custom-motor` in `examples/stm32g474`.
#![no_std]
#![no_main]

use embassy_executor::Spawner;
use embassy_time::{Duration, Ticker};
use rc10_core::motor::Motor;
use rc10_core::motor::dji::DjiMotor;
use rc10_examples_stm32g474 as board;
use rc10_examples_stm32g474::my_motor::MyMotor;
use rc10_stm32::tasks::G4Bus;
use static_cell::StaticCell;

static MINE: MyMotor = MyMotor::new(1);
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
    defmt::unwrap!(builder.register(&MINE));
    let bus = board::start_bus(builder, &BUS, board::fdcan1!(p), board::control_spawner());
    board::start_watchdog!(spawner, p, [bus]);

    // Code written against the trait drives both motors alike.
    let motors: [&dyn Motor; 2] = [&WHEEL, &MINE];
    for m in motors {
        defmt::unwrap!(m.set_target_rpm(60.0));
    }
    let mut ticker = Ticker::every(Duration::from_millis(500));
    loop {
        ticker.next().await;
        for (name, m) in [("M3508", motors[0]), ("MyMotor", motors[1])] {
            let s = m.state();
            defmt::info!(
                "{}: online {} speed {} rpm command {} A",
                name,
                s.online,
                s.speed_rpm,
                s.command
            );
        }
        board::log_bus("FDCAN1", bus);
    }
}
