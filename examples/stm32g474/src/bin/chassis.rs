//! A 4×M3508 mecanum chassis driven by a DJI DR16 receiver, with VOFA+ telemetry of target
//! and measured wheel speeds.
//!
//! Left stick: forward/back and sideways (asks up to 2 m/s); right stick horizontal: rotation
//! (up to 4 rad/s). Accelerations are limited (4 m/s², 12 rad/s²), wheel speeds scaled down
//! together past 400 rpm (about 3.2 m/s straight ahead with 76 mm-radius wheels, so it only
//! limits combined stick moves). If no valid DBUS frame arrives for 100 ms the sticks read
//! neutral and the chassis brakes to a stop.
//!
//! Wiring: NUCLEO-G474RE; FDCAN1 (PA11 RX / PA12 TX) to a transceiver and the four C620s set
//! to ids 1 (front left), 2 (front right), 3 (rear left), 4 (rear right), the order
//! `LinearChassis::mecanum` gives wheel speeds in; the DR16's DBUS
//! signal to PC11 (USART3 RX, inverted in the USART, no external inverter), DR16 powered from
//! 5 V; VOFA+ on the ST-LINK virtual COM port at 921 600 baud (JustFloat: channels t1..t4
//! target rpm, m1..m4 measured rpm).
//!
//! Run: `cargo embed --release --bin chassis` in `examples/stm32g474`.
#![no_std]
#![no_main]

use embassy_executor::Spawner;
use embassy_time::{Duration, Instant, Ticker};
use rc10_core::chassis::{LinearChassis, MecanumConfig, Twist, TwistLimiter};
use rc10_core::motor::Motor;
use rc10_core::motor::dji::DjiMotor;
use rc10_core::remote::Shared;
use rc10_core::remote::dbus::DbusReceiver;
use rc10_core::telemetry::Channels;
use rc10_examples_stm32g474 as board;
use rc10_stm32::tasks::G4Bus;
use rc10_stm32::telemetry::{VofaStats, run_vofa};
use static_cell::StaticCell;

const fn m3508(id: u8) -> DjiMotor {
    match DjiMotor::m3508(id) {
        Ok(m) => m,
        Err(_) => panic!("M3508 id"),
    }
}

/// C620 ids 1–4: front left, front right, rear left, rear right (`LinearChassis::mecanum`'s order).
static WHEELS: [DjiMotor; 4] = [m3508(1), m3508(2), m3508(3), m3508(4)];
static BUS: StaticCell<G4Bus> = StaticCell::new();
static DR16: Shared<DbusReceiver> = Shared::new(DbusReceiver::new(Duration::from_millis(100)));
static TELEMETRY: Channels<8> = Channels::new(["t1", "t2", "t3", "t4", "m1", "m2", "m3", "m4"]);
static VOFA: VofaStats = VofaStats::new();

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = board::init();
    let mut builder = board::bus_builder();
    for wheel in &WHEELS {
        defmt::unwrap!(builder.register(wheel));
    }
    let bus = board::start_bus(builder, &BUS, board::fdcan1!(p), board::control_spawner());
    board::start_watchdog!(spawner, p, [bus]);
    spawner.spawn(defmt::unwrap!(rc10_stm32::remote::dbus_task(
        board::dr16_uart!(p),
        &DR16
    )));
    spawner.spawn(defmt::unwrap!(vofa(board::vofa_uart!(p))));
    spawner.spawn(defmt::unwrap!(drive()));

    let mut ticker = Ticker::every(Duration::from_secs(1));
    loop {
        ticker.next().await;
        board::log_bus("FDCAN1", bus);
        defmt::info!(
            "DR16 frames {} errors {} uart errors {}; VOFA sent {} dropped {}",
            DR16.with(|r| r.link().frames()),
            DR16.with(|r| r.link().errors()),
            DR16.input_errors(),
            VOFA.sent(),
            VOFA.dropped()
        );
    }
}

/// Remote → twist → wheel speeds, at 500 Hz in thread mode.
#[embassy_executor::task]
async fn drive() {
    // 0.40 m wheelbase, 0.36 m track, 76 mm wheel radius; the right-side motors (front
    // right, rear right) are mounted mirrored.
    let chassis = defmt::unwrap!(LinearChassis::mecanum(
        MecanumConfig::new(0.40, 0.36, 0.076).with_wheel_signs([1.0, -1.0, 1.0, -1.0]),
    ));
    let mut limiter = TwistLimiter::new(Twist::new(4.0, 4.0, 12.0)); // m/s², m/s², rad/s²
    let period = Duration::from_millis(2);
    let mut ticker = Ticker::every(period);
    loop {
        ticker.next().await;
        let signal = DR16.with(|r| r.signal(Instant::now()));
        // Neutral sticks while lost: the limiter brings the chassis to a stop.
        let rc = signal.value;
        let wanted = Twist::new(
            rc.stick(3, 0.02) * 2.0,
            -rc.stick(2, 0.02) * 2.0,
            -rc.stick(0, 0.02) * 4.0,
        );
        let twist = limiter.update(wanted, 0.002);
        let rpm = chassis.wheel_rpm_limited(twist, 400.0);
        for (i, (wheel, target)) in WHEELS.iter().zip(rpm).enumerate() {
            // A NaN can only come from a bug upstream: keep the previous target then.
            let _ = wheel.set_target_rpm(target);
            TELEMETRY.set(i, target);
            TELEMETRY.set(i + 4, wheel.speed_rpm());
        }
    }
}

#[embassy_executor::task]
async fn vofa(tx: embassy_stm32::usart::UartTx<'static, embassy_stm32::mode::Async>) {
    run_vofa(tx, &TELEMETRY, Duration::from_millis(2), &VOFA).await
}
