//! The Embassy adapter of rc10 for STM32G4 boards: FDCAN1..3 as rc10-core transports with
//! hardware acceptance filters planned from the registered nodes, the scheduler and receiver
//! tasks, DR16/SBUS/PPM inputs and VOFA+ telemetry over a UART.
//!
//! Built for `thumbv7em-none-eabihf` only (it is not a default workspace member: host
//! `cargo test` never builds it). Select your chip with a feature (`stm32g474re`, …). The
//! firmware binary selects embassy-stm32's time driver (`time-driver-any`) and `memory-x`.
//!
//! # A board in a few lines
//!
//! ```ignore
//! // Clocks: 170 MHz from the crystal + PLL, FDCAN kernel clock from PCLK1.
//! let p = embassy_stm32::init(rc10_stm32::clocks_170mhz(Crystal::Mhz24));
//! // The control loop's executor: an InterruptExecutor at a high priority (see below; the
//! // examples' `control_spawner()` in examples/stm32g474/src/lib.rs starts one).
//! let control: SendSpawner = control_spawner();
//! // Motors are statics; register them, freeze the bus, plan the filters from it.
//! let mut builder = BusBuilder::with_config(BusConfig::DEFAULT.with_tx_depth(rc10_stm32::can::TX_BUFFERS));
//! builder.register(&WHEEL_1)?;
//! let bus: &'static G4Bus = BUS.init(builder.build());
//! // Filters planned from the bus's nodes, the FDCAN started at the bus's own bitrate.
//! let (tx, rx) = rc10_stm32::start_can(CanConfigurator::new(p.FDCAN1, p.PA11, p.PA12, Irqs), Instance::Fdcan1, bus)?;
//! control.spawn(scheduler_task(bus, tx)?);
//! control.spawn(receiver_task(bus, rx)?);
//! // Reset the board if a scheduler stops ticking (thread-mode executor).
//! static BUSES: StaticCell<[&'static G4Bus; 1]> = StaticCell::new();
//! spawner.spawn(watchdog_task(IndependentWatchdog::new(p.IWDG, WATCHDOG_TIMEOUT_US), BUSES.init([bus]))?);
//! ```
//!
//! The firmware examples in `examples/stm32g474/` are complete, commented versions.
//!
//! # Priorities
//!
//! Run the scheduler and receiver tasks on an `InterruptExecutor` at a high interrupt
//! priority, and application tasks (targets, remote handling, logging, telemetry) on the
//! thread-mode executor. The control loop then preempts application code, never the other
//! way round; motors, buses and receivers are shared through rc10-core's short critical
//! sections, so no priority inversion lasts longer than one of them. Keep the FDCAN
//! interrupts above the executor's, as embassy does by default (it only wakes tasks).
//!
//! # Coming from RC10_LIB and FreeRTOS
//!
//! | RC10_LIB / FreeRTOS | rc10 on Embassy |
//! |---|---|
//! | `fdCANbus::init`, RX ISR → queue → RX task | [`start_can`] (filters from the registered nodes), [`tasks::receiver_task`] |
//! | 1 kHz `schedulerTask` with `vTaskDelayUntil` | [`tasks::scheduler_task`] (`Ticker`, missed ticks skipped) |
//! | task priorities | `InterruptExecutor` priority for the control loop, thread mode for the rest |
//! | `AirJoy` PPM on a timer | [`remote::ppm_task`] |
//! | `debugTool` printf | `defmt` over RTT; VOFA+ with [`telemetry::run_vofa`] |
#![no_std]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod can;
pub mod remote;
pub mod status;
pub mod tasks;
pub mod telemetry;

pub use rc10_core;

use embassy_stm32::rcc;
use rc10_core::can::acceptance::PlanError;

/// The crystal on the board (HSE), for [`clocks_170mhz`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Crystal {
    /// 8 MHz.
    Mhz8,
    /// 12 MHz.
    Mhz12,
    /// 16 MHz.
    Mhz16,
    /// 24 MHz (NUCLEO-G474RE).
    Mhz24,
}

/// embassy-stm32 configuration for an STM32G4 at 170 MHz from the board's crystal (PLL input
/// 4 MHz · 85 = 340 MHz VCO, / 2 = 170 MHz; voltage range 1 boost), with the FDCAN kernel
/// clock on PCLK1 (170 MHz; [`can::start`] derives the 1 Mbit/s bit timing from it). The
/// HSE is a crystal (`HseMode::Oscillator`); a board fed a clock signal instead (ST-LINK's
/// MCO, a TCXO) needs `HseMode::Bypass`: change `config.rcc.hse` after this.
///
/// Why a crystal: CAN at 1 Mbit/s tolerates only a few tenths of a percent of clock error
/// between nodes, and the internal HSI is specified to about ±1 %: fine on the bench, out of
/// tolerance when warm or cold. Why the FDCAN mux is set: its default, HSE as a direct
/// source, is easy to leave unconfigured, and `CanConfigurator::new` then panics when HSE is
/// not enabled.
pub fn clocks_170mhz(crystal: Crystal) -> embassy_stm32::Config {
    let (mhz, prediv) = match crystal {
        Crystal::Mhz8 => (8, rcc::PllPreDiv::DIV2),
        Crystal::Mhz12 => (12, rcc::PllPreDiv::DIV3),
        Crystal::Mhz16 => (16, rcc::PllPreDiv::DIV4),
        Crystal::Mhz24 => (24, rcc::PllPreDiv::DIV6),
    };
    let mut config = embassy_stm32::Config::default();
    config.rcc.hse = Some(rcc::Hse {
        freq: embassy_stm32::time::Hertz::mhz(mhz),
        mode: rcc::HseMode::Oscillator,
    });
    config.rcc.pll = Some(rcc::Pll {
        source: rcc::PllSource::HSE,
        prediv,
        mul: rcc::PllMul::MUL85,
        divp: None,
        divq: None,
        divr: Some(rcc::PllRDiv::DIV2),
    });
    config.rcc.sys = rcc::Sysclk::PLL1_R;
    config.rcc.boost = true; // 170 MHz needs the voltage-range 1 boost mode
    config.rcc.mux.fdcansel = rcc::mux::Fdcansel::PCLK1;
    config
}

/// The acceptance-filter plan for a frozen bus (what [`can::start`] programs).
pub fn filter_plan<const N: usize>(
    bus: &rc10_core::bus::Bus<'_, N>,
) -> Result<can::G4FilterPlan, PlanError> {
    can::G4FilterPlan::new(bus.nodes().iter().map(|node| node.bus_usage()))
}

/// Why [`start_can`] started nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StartError {
    /// The nodes' IDs do not fit the FDCAN's filter elements.
    Filters(PlanError),
    /// `instance` does not name the configurator's peripheral.
    WrongInstance(can::Instance),
    /// No bit timing gives the bus's bitrate from the FDCAN kernel clock (see [`can::start`]).
    NoBitTiming {
        /// The FDCAN kernel clock, Hz.
        kernel_clock_hz: u32,
        /// The bitrate asked for, bit/s.
        bitrate_bps: u32,
    },
}

impl core::fmt::Display for StartError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Filters(e) => write!(f, "{e}"),
            Self::WrongInstance(i) => write!(f, "{i:?} is not the configurator's FDCAN"),
            Self::NoBitTiming {
                kernel_clock_hz,
                bitrate_bps,
            } => write!(
                f,
                "no CAN bit timing gives {bitrate_bps} bit/s from a {kernel_clock_hz} Hz FDCAN clock"
            ),
        }
    }
}

impl core::error::Error for StartError {}

/// Starts a FDCAN for a frozen `bus`: the acceptance filters planned from its nodes
/// ([`filter_plan`]) and the bitrate of its own configuration (`bus.config().bitrate_bps`, the
/// one its load figures and frame budget are computed with), through [`can::start`], whose
/// requirements apply (`instance` names the configurator's peripheral, which is checked; the
/// FDCAN kernel clock is configured). Returns the halves for [`tasks::scheduler_task`] and
/// [`tasks::receiver_task`], or why nothing was started.
pub fn start_can<const N: usize>(
    configurator: embassy_stm32::can::CanConfigurator<'static>,
    instance: can::Instance,
    bus: &rc10_core::bus::Bus<'_, N>,
) -> Result<(can::FdcanTx, can::FdcanRx), StartError> {
    let plan = filter_plan(bus).map_err(StartError::Filters)?;
    can::start(configurator, instance, &plan, bus.config().bitrate_bps)
}
