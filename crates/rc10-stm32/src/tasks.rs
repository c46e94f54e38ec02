//! Embassy tasks that run rc10-core's bus loops on a board. Embassy tasks cannot be generic,
//! so the bus type is fixed: [`G4Bus`], up to [`MAX_NODES`] nodes per bus, and each task can
//! be spawned once per FDCAN (pool of three).

use crate::can::{FdcanRx, FdcanTx};
use crate::status::TickProgress;
use embassy_stm32::peripherals::IWDG;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_time::{Duration, Ticker};
use rc10_core::bus::{Bus, run_receiver, run_scheduler};

/// Most nodes on one bus (at 1 kHz a classic CAN bus carries six DJI motors at most; eight
/// leaves room for nodes that send less).
pub const MAX_NODES: usize = 8;

/// A frozen bus as the tasks take it.
pub type G4Bus = Bus<'static, MAX_NODES>;

/// The 1 kHz scheduler of one bus: every `bus.config().tick_period`, update all nodes, pack,
/// send (rc10-core's `run_scheduler`). Spawn it on a high-priority `InterruptExecutor` so that
/// application tasks in thread mode never delay a tick.
#[embassy_executor::task(pool_size = 3)]
pub async fn scheduler_task(bus: &'static G4Bus, tx: FdcanTx) -> ! {
    run_scheduler(bus, tx).await
}

/// The receiver of one bus: routes each frame to the node that claims it (rc10-core's
/// `run_receiver`). Spawn it at the same priority as the scheduler (or just below it), so
/// the 3-deep RX FIFOs are drained promptly.
#[embassy_executor::task(pool_size = 3)]
pub async fn receiver_task(bus: &'static G4Bus, rx: FdcanRx) -> ! {
    run_receiver(bus, rx).await
}

/// How often [`watchdog_task`] looks at the schedulers' tick counts.
pub const WATCHDOG_CHECK: Duration = Duration::from_millis(50);

/// The watchdog timeout the examples use, in µs (`IndependentWatchdog::new`): five looks of
/// [`WATCHDOG_CHECK`], so a scheduler stalled by a bounded hold-up (tens of ms) never trips it.
pub const WATCHDOG_TIMEOUT_US: u32 = 250_000;

/// Feeds the independent watchdog every [`WATCHDOG_CHECK`] while the scheduler of every bus
/// in `buses` (up to three) has ticked since the last look. A scheduler that stops (a hang,
/// a fault, a panic that halts the core) or a thread-mode executor that no longer runs this
/// task (an application task that never yields, so stale targets would stay in force) stops
/// the feeding, and the IWDG resets the MCU at its timeout: the motors are commanded again
/// from a clean start, and go offline-safe (no command) meanwhile.
///
/// A scheduler that stops (waiting on something that never comes) is seen at the second look
/// after its last tick, so the reset comes 250–300 ms after it (with
/// [`WATCHDOG_TIMEOUT_US`]); a task that spins on the higher-priority control executor (an
/// endless loop in a motor's `update`) starves thread mode and this task with it, and a fault
/// or panic stops the core: either stops the feeding at once, and the reset comes 200–250 ms
/// after it (the last feed was up to a look earlier). Nominal figures: the IWDG counts the LSI, 32 kHz nominal and
/// 29.5–34 kHz over temperature on the G4, so the 250 ms timeout is 235–271 ms. With a
/// debugger attached, a panic (panic-probe: a HardFault) halts the core for the backtrace,
/// and the frozen IWDG (below) does not reset it.
///
/// Spawn it on the thread-mode executor after the schedulers (a bus whose scheduler starts
/// more than a look later counts as stopped), with the watchdog made from `p.IWDG` and a
/// timeout of several looks ([`WATCHDOG_TIMEOUT_US`]). Blocking work in thread mode longer
/// than the timeout less a look (200 ms; 185 ms on a fast LSI) resets the board (a flash
/// erase, a busy-wait calibration): do it before spawning this task. A `tick_period` longer
/// than a look never feeds it. The task also freezes the IWDG while a debugger halts the
/// core (DBGMCU), so breakpoints do not reset the board.
#[embassy_executor::task]
pub async fn watchdog_task(
    mut watchdog: IndependentWatchdog<'static, IWDG>,
    buses: &'static [&'static G4Bus],
) -> ! {
    embassy_stm32::pac::DBGMCU
        .apb1lfzr()
        .modify(|w| w.set_iwdg(true));
    let mut progress = TickProgress::new();
    watchdog.unleash();
    let mut ticker = Ticker::every(WATCHDOG_CHECK);
    loop {
        ticker.next().await;
        if progress.all_advanced(buses.iter().map(|bus| bus.stats().snapshot().ticks)) {
            watchdog.pet();
        }
    }
}
