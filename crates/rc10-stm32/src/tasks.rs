//! Embassy tasks that run rc10-core's bus loops on a board. Embassy tasks cannot be generic,
//! so the bus type is fixed: [`G4Bus`], up to [`MAX_NODES`] nodes per bus, and each task can
//! be spawned once per FDCAN (pool of three).

use crate::can::{FdcanRx, FdcanTx};
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
    run_scheduler(bus, tx, bus.config().tick_period).await
}

/// The receiver of one bus: routes each frame to the node that claims it (rc10-core's
/// `run_receiver`). Spawn it at the same priority as the scheduler (or just below it), so
/// the 3-deep RX FIFOs are drained promptly.
#[embassy_executor::task(pool_size = 3)]
pub async fn receiver_task(bus: &'static G4Bus, rx: FdcanRx) -> ! {
    run_receiver(bus, rx).await
}
