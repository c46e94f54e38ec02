//! The board the examples run on: a NUCLEO-G474RE (STM32G474RETx, 170 MHz) with CAN
//! transceivers on FDCAN1..3. Every pin, interrupt and DMA channel the examples use is named
//! here, so retargeting your own board means editing this file only.
//!
//! | function | pins | notes |
//! |---|---|---|
//! | FDCAN1 | PA11 RX, PA12 TX | to a 3.3 V transceiver (e.g. TJA1051T/3, SN65HVD230), 120 Ω at both bus ends |
//! | FDCAN2 | PB12 RX, PB13 TX | |
//! | FDCAN3 | PA8 RX, PB4 TX | |
//! | DR16 DBUS | PC11 (USART3 RX), DMA1 CH1 | the DR16 line is inverted: inverted in the USART here |
//! | clock | 24 MHz crystal (X3) | CAN at 1 Mbit/s needs a crystal, not the ±1 % internal oscillator |
//! | VOFA+ telemetry | PA2 (LPUART1 TX, the ST-LINK virtual COM port), DMA1 CH2 | 921 600 baud |
//!
//! The control loop (schedulers, receivers) runs on an interrupt executor at priority 6
//! (software-triggered through the otherwise unused UART5 interrupt); application tasks run in
//! thread mode and are preempted by it.
#![no_std]

pub mod my_motor;

use defmt_rtt as _;
use embassy_executor::{InterruptExecutor, SendSpawner};
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::usart::{RingBufferedUartRx, UartRx, UartTx};
use embassy_stm32::{Peripherals, bind_interrupts, can, dma, interrupt, mode, peripherals, usart};
use panic_probe as _;
use rc10_core::bus::{BusBuilder, BusConfig};
use rc10_stm32::can::{Instance, TX_BUFFERS};
use rc10_stm32::tasks::{G4Bus, MAX_NODES, receiver_task, scheduler_task};
use static_cell::StaticCell;

bind_interrupts!(pub struct Irqs {
    FDCAN1_IT0 => can::IT0InterruptHandler<peripherals::FDCAN1>;
    FDCAN1_IT1 => can::IT1InterruptHandler<peripherals::FDCAN1>;
    FDCAN2_IT0 => can::IT0InterruptHandler<peripherals::FDCAN2>;
    FDCAN2_IT1 => can::IT1InterruptHandler<peripherals::FDCAN2>;
    FDCAN3_IT0 => can::IT0InterruptHandler<peripherals::FDCAN3>;
    FDCAN3_IT1 => can::IT1InterruptHandler<peripherals::FDCAN3>;
    USART3 => usart::InterruptHandler<peripherals::USART3>;
    LPUART1 => usart::InterruptHandler<peripherals::LPUART1>;
    DMA1_CHANNEL1 => dma::InterruptHandler<peripherals::DMA1_CH1>;
    DMA1_CHANNEL2 => dma::InterruptHandler<peripherals::DMA1_CH2>;
});

/// Bitrate of every DJI / Damiao / VESC bus.
pub const CAN_BITRATE_BPS: u32 = 1_000_000;

/// Clocks at 170 MHz from the NUCLEO's 24 MHz crystal (X3), FDCAN on PCLK1; returns the
/// peripherals. Change the crystal here for your board.
pub fn init() -> Peripherals {
    embassy_stm32::init(rc10_stm32::clocks_170mhz(rc10_stm32::Crystal::Mhz24))
}

/// A bus configuration for a G4 FDCAN: [`CAN_BITRATE_BPS`] (the FDCAN is started at this
/// bitrate too), 1 kHz, its 3 TX buffers.
pub const fn bus_config() -> BusConfig {
    BusConfig {
        bitrate_bps: CAN_BITRATE_BPS,
        ..BusConfig::DEFAULT
    }
    .with_tx_depth(TX_BUFFERS)
}

/// An empty bus builder for a G4 FDCAN.
pub const fn bus_builder() -> BusBuilder<'static, MAX_NODES> {
    BusBuilder::with_config(bus_config())
}

/// FDCAN1's configurator on PA11 (RX) / PA12 (TX), with the instance that names it (the
/// pair [`start_bus`] takes, so the two cannot disagree).
#[macro_export]
macro_rules! fdcan1 {
    ($p:ident) => {
        (
            embassy_stm32::can::CanConfigurator::new($p.FDCAN1, $p.PA11, $p.PA12, $crate::Irqs),
            rc10_stm32::can::Instance::Fdcan1,
        )
    };
}

/// FDCAN2's configurator on PB12 (RX) / PB13 (TX), with the instance that names it (the
/// pair [`start_bus`] takes, so the two cannot disagree).
#[macro_export]
macro_rules! fdcan2 {
    ($p:ident) => {
        (
            embassy_stm32::can::CanConfigurator::new($p.FDCAN2, $p.PB12, $p.PB13, $crate::Irqs),
            rc10_stm32::can::Instance::Fdcan2,
        )
    };
}

/// FDCAN3's configurator on PA8 (RX) / PB4 (TX), with the instance that names it (the
/// pair [`start_bus`] takes, so the two cannot disagree).
#[macro_export]
macro_rules! fdcan3 {
    ($p:ident) => {
        (
            embassy_stm32::can::CanConfigurator::new($p.FDCAN3, $p.PA8, $p.PB4, $crate::Irqs),
            rc10_stm32::can::Instance::Fdcan3,
        )
    };
}

/// The DR16 receiver's UART: USART3 RX on PC11 with DMA1 CH1, ring-buffered into its own
/// static 128-byte buffer.
#[macro_export]
macro_rules! dr16_uart {
    ($p:ident) => {{
        static BUFFER: static_cell::StaticCell<[u8; 128]> = static_cell::StaticCell::new();
        $crate::ring_buffered(
            embassy_stm32::usart::UartRx::new(
                $p.USART3,
                $p.PC11,
                $p.DMA1_CH1,
                $crate::Irqs,
                rc10_stm32::remote::dbus_config(true),
            ),
            BUFFER.init([0; 128]),
        )
    }};
}

/// The VOFA+ telemetry UART: LPUART1 TX on PA2 (ST-LINK virtual COM port), DMA1 CH2.
#[macro_export]
macro_rules! vofa_uart {
    ($p:ident) => {
        $crate::telemetry_uart(embassy_stm32::usart::UartTx::new(
            $p.LPUART1,
            $p.PA2,
            $p.DMA1_CH2,
            $crate::Irqs,
            $crate::vofa_config(),
        ))
    };
}

/// 921 600 baud, 8N1, for VOFA+.
pub fn vofa_config() -> usart::Config {
    let mut config = usart::Config::default();
    config.baudrate = 921_600;
    config
}

/// Unwraps the telemetry UART (a bad baud rate is a setup error).
pub fn telemetry_uart(
    uart: Result<UartTx<'static, mode::Async>, usart::ConfigError>,
) -> UartTx<'static, mode::Async> {
    defmt::unwrap!(uart)
}

/// Turns a DMA UART receiver into a ring-buffered one over `buffer` (a setup error stops
/// the firmware with a defmt message).
pub fn ring_buffered(
    uart: Result<UartRx<'static, mode::Async>, usart::ConfigError>,
    buffer: &'static mut [u8],
) -> RingBufferedUartRx<'static> {
    defmt::unwrap!(uart).into_ring_buffered(buffer)
}

static CONTROL: InterruptExecutor = InterruptExecutor::new();

#[interrupt]
unsafe fn UART5() {
    // SAFETY: UART5 is not used as a UART on this board; its interrupt only runs the control
    // executor, which `control_spawner` started on it (embassy's InterruptExecutor pattern).
    unsafe { CONTROL.on_interrupt() }
}

/// Starts the high-priority control executor (once) and returns its spawner.
pub fn control_spawner() -> SendSpawner {
    interrupt::UART5.set_priority(Priority::P6);
    CONTROL.start(interrupt::UART5)
}

/// Freezes `builder` into `cell`, programs the FDCAN's acceptance filters from it, starts the
/// controller and spawns the bus's scheduler and receiver tasks on `control`.
///
/// Setup errors (filters that do not fit, a task pool exhausted) stop the firmware with a
/// defmt message: they are wiring mistakes to fix before the robot moves.
pub fn start_bus(
    builder: BusBuilder<'static, MAX_NODES>,
    cell: &'static StaticCell<G4Bus>,
    (configurator, instance): (can::CanConfigurator<'static>, Instance),
    control: SendSpawner,
) -> &'static G4Bus {
    let bus: &'static G4Bus = cell.init(builder.build());
    let (tx, rx) = defmt::unwrap!(rc10_stm32::start_can(configurator, instance, bus));
    control.spawn(defmt::unwrap!(scheduler_task(bus, tx)));
    control.spawn(defmt::unwrap!(receiver_task(bus, rx)));
    bus
}

/// Starts the independent watchdog, fed by `rc10_stm32::tasks::watchdog_task` on `$spawner`
/// (the thread-mode executor's) while every listed bus's scheduler ticks: a hung scheduler
/// or a starved thread-mode executor resets the board after
/// `rc10_stm32::tasks::WATCHDOG_TIMEOUT_US` (250 ms). Once started it cannot be stopped.
#[macro_export]
macro_rules! start_watchdog {
    ($spawner:expr, $p:ident, [$($bus:expr),+ $(,)?]) => {{
        static BUSES: static_cell::StaticCell<
            [&'static rc10_stm32::tasks::G4Bus; { [$(stringify!($bus)),+].len() }],
        > = static_cell::StaticCell::new();
        let watchdog = embassy_stm32::wdg::IndependentWatchdog::new(
            $p.IWDG,
            rc10_stm32::tasks::WATCHDOG_TIMEOUT_US,
        );
        $spawner.spawn(defmt::unwrap!(rc10_stm32::tasks::watchdog_task(
            watchdog,
            BUSES.init([$($bus),+]),
        )));
    }};
}

/// Logs a bus's counters (once a second is plenty).
pub fn log_bus(name: &str, bus: &G4Bus) {
    let c = bus.stats().snapshot();
    let r = bus.rates();
    defmt::info!(
        "{}: rx {} f/s, tx {} f/s, load {}%, tx full {}, stale {}, bus-off {}, errors {}, overruns {}",
        name,
        r.rx_frames_per_s,
        r.tx_frames_per_s,
        r.load_percent,
        c.tx_full,
        c.tx_stale,
        c.bus_off_events,
        c.bus_errors,
        c.rx_overruns
    );
}
