//! One CAN bus and the nodes on it: registration with checks ([`BusBuilder`]), the frozen
//! [`Bus`] that the scheduler and receiver tasks share, and those two tasks' loops.
//!
//! # Tick order (RC10_LIB's `schedulerTask`, kept)
//!
//! Every period (1 ms by default): `update(now, dt)` on every node in registration order
//! (control math only), then `pack_command` on every node (frame assembly only: DJI slots with
//! the same command ID merge into one frame), then the frames are handed to the transport with
//! `try_send`, in packing order. Frames the transport cannot queue (TX buffers full: 3 on an
//! STM32G4; or bus-off) are counted in [`BusStats`], never waited for: the next tick sends
//! fresh commands anyway.
//!
//! # Receiving
//!
//! Each received frame goes to the first node whose `matches_frame` claims it (registration
//! guarantees at most one can), which parses it in `update_feedback`. A frame nobody claims is
//! counted as unmatched; a claimed frame the node rejects (wrong DLC, out-of-range field) is
//! counted as rejected and changes nothing.
//!
//! # Sync core, async shell
//!
//! [`Bus::tick`], [`Bus::transmit`] and [`Bus::dispatch`] are plain functions that unit tests
//! and the simulator call directly with virtual time. [`run_scheduler`] and [`run_receiver`]
//! are thin async loops over them for Embassy tasks.

use crate::can::stats::RateWindow;
use crate::can::{
    BusRates, BusStats, CanFrame, CanReceive, CanTransmit, ErrorState, ReceiveError, SendError,
    timing,
};
use crate::node::{CanNode, TxBatch};
use crate::time::{DeltaTime, Duration, Instant};
use core::cell::RefCell;
use core::fmt;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;

/// Bus parameters used for the frame budget and load statistics.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BusConfig {
    /// Nominal bitrate in bits per second (1 Mbit/s for DJI motors).
    pub bitrate_bps: u32,
    /// Scheduler tick period (1 ms).
    pub tick_period: Duration,
    /// Registration fails when the nominal (unstuffed) load of all declared traffic would
    /// exceed this, in percent. 90 % admits six DJI motors (89 %) and rejects seven (100 %),
    /// matching "5–6 marginal, 8 impossible" (SPEC.md).
    pub max_load_percent: f32,
    /// Window over which [`Bus::rates`] are computed.
    pub rate_window: Duration,
}

impl BusConfig {
    /// 1 Mbit/s, 1 kHz tick, 90 % registration limit, 1 s rate window.
    pub const DEFAULT: Self = Self {
        bitrate_bps: 1_000_000,
        tick_period: Duration::from_millis(1),
        max_load_percent: 90.0,
        rate_window: Duration::from_secs(1),
    };
}

impl Default for BusConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// How much of the bus the registered traffic needs.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameBudget {
    /// Frames per tick: feedback plus command frames.
    pub frames_per_tick: f32,
    /// Load in percent with unstuffed 8-byte frames.
    pub nominal_load_percent: f32,
    /// Load in percent with worst-case stuffing.
    pub worst_case_load_percent: f32,
}

impl FrameBudget {
    /// How comfortable the budget is.
    pub fn level(&self) -> BudgetLevel {
        if self.worst_case_load_percent <= 80.0 {
            BudgetLevel::Comfortable
        } else {
            BudgetLevel::Marginal
        }
    }
}

/// A summary of a [`FrameBudget`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BudgetLevel {
    /// Fits even with worst-case bit stuffing and leaves at least 20 % of the bus free.
    Comfortable,
    /// Fits nominally but may lose frames under worst-case stuffing or extra traffic: expect
    /// TX drops and late feedback. Consider a second bus.
    Marginal,
}

/// Why a node could not be registered.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RegisterError {
    /// The bus already holds its capacity (`N`) of nodes.
    Full,
    /// The node's feedback IDs overlap those of the node registered at `existing` (e.g. an
    /// M3508 with id 5 and a GM6020 with id 1 both answer on 0x205).
    FeedbackConflict {
        /// Index of the node already registered.
        existing: usize,
    },
    /// The node writes the same command slot as the node registered at `existing`.
    SlotConflict {
        /// Index of the node already registered.
        existing: usize,
    },
    /// With this node the bus would need `load_percent` of its capacity, above
    /// [`BusConfig::max_load_percent`].
    FrameBudget {
        /// Nominal load the bus would have, in percent.
        load_percent: f32,
    },
}

impl fmt::Display for RegisterError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Full => f.write_str("bus registry full"),
            Self::FeedbackConflict { existing } => {
                write!(f, "feedback ID conflicts with node {existing}")
            }
            Self::SlotConflict { existing } => {
                write!(f, "command slot conflicts with node {existing}")
            }
            Self::FrameBudget { load_percent } => {
                write!(f, "bus would be {load_percent:.0} % loaded")
            }
        }
    }
}

impl core::error::Error for RegisterError {}

/// Registers nodes on one bus, checking capacity, ID and slot conflicts and the frame budget.
/// [`build`](Self::build) freezes it into a [`Bus`].
///
/// ```
/// use rc10_core::bus::{BusBuilder, RegisterError};
/// use rc10_core::motor::dji::DjiMotor;
///
/// let wheel = DjiMotor::m3508(5).unwrap();
/// let yaw = DjiMotor::gm6020_voltage(1).unwrap(); // also answers on 0x205
/// let mut builder = BusBuilder::<4>::new();
/// builder.register(&wheel).unwrap();
/// assert_eq!(builder.register(&yaw), Err(RegisterError::FeedbackConflict { existing: 0 }));
/// let bus = builder.build();
/// assert_eq!(bus.nodes().len(), 1);
/// ```
pub struct BusBuilder<'a, const N: usize> {
    nodes: heapless::Vec<&'a dyn CanNode, N>,
    config: BusConfig,
}

impl<'a, const N: usize> BusBuilder<'a, N> {
    /// An empty builder with [`BusConfig::DEFAULT`].
    pub const fn new() -> Self {
        Self::with_config(BusConfig::DEFAULT)
    }

    /// An empty builder with `config`.
    pub const fn with_config(config: BusConfig) -> Self {
        Self {
            nodes: heapless::Vec::new(),
            config,
        }
    }

    /// Adds `node`, or says why it cannot be added (the builder is then unchanged).
    pub fn register(&mut self, node: &'a dyn CanNode) -> Result<(), RegisterError> {
        let usage = node.bus_usage();
        for (i, other) in self.nodes.iter().enumerate() {
            let theirs = other.bus_usage();
            if let (Some(a), Some(b)) = (usage.listen, theirs.listen)
                && a.overlaps(&b)
            {
                return Err(RegisterError::FeedbackConflict { existing: i });
            }
            if usage.command_slot.is_some() && usage.command_slot == theirs.command_slot {
                return Err(RegisterError::SlotConflict { existing: i });
            }
        }
        let budget = self.budget_with(Some(node));
        if budget.nominal_load_percent > self.config.max_load_percent {
            return Err(RegisterError::FrameBudget {
                load_percent: budget.nominal_load_percent,
            });
        }
        self.nodes.push(node).map_err(|_| RegisterError::Full)
    }

    /// The frame budget of the nodes registered so far.
    pub fn budget(&self) -> FrameBudget {
        self.budget_with(None)
    }

    fn budget_with(&self, extra: Option<&dyn CanNode>) -> FrameBudget {
        frame_budget(self.nodes.iter().copied().chain(extra), &self.config)
    }

    /// Freezes the registry. Nothing can be registered after this.
    pub fn build(self) -> Bus<'a, N> {
        Bus {
            nodes: self.nodes,
            config: self.config,
            stats: BusStats::new(),
            window: Mutex::new(RefCell::new(RateWindow::new())),
        }
    }
}

impl<const N: usize> Default for BusBuilder<'_, N> {
    fn default() -> Self {
        Self::new()
    }
}

fn frame_budget<'n>(
    nodes: impl Iterator<Item = &'n dyn CanNode>,
    config: &BusConfig,
) -> FrameBudget {
    let tick_s = crate::time::micros_to_s(config.tick_period.as_micros().max(1));
    let mut command_ids: heapless::Vec<u16, 16> = heapless::Vec::new();
    let (mut frames, mut nominal_bits, mut worst_bits) = (0.0f32, 0.0f32, 0.0f32);
    let mut add = |count: f32, extended: bool| {
        frames += count;
        let nominal = if extended { 131.0 } else { 111.0 };
        nominal_bits += count * nominal;
        worst_bits += count * timing::worst_case_bits(extended, 8) as f32;
    };
    for node in nodes {
        let u = node.bus_usage();
        add(u.feedback_hz as f32 * tick_s, u.feedback_extended);
        add(f32::from(u.command_frames_per_tick), u.command_extended);
        if let Some(slot) = u.command_slot
            && !command_ids.contains(&slot.id())
        {
            // More than 16 distinct slot IDs cannot fit a bus anyway; count them regardless.
            let _ = command_ids.push(slot.id());
            add(1.0, false);
        }
    }
    let capacity_bits = config.bitrate_bps as f32 * tick_s;
    FrameBudget {
        frames_per_tick: frames,
        nominal_load_percent: 100.0 * nominal_bits / capacity_bits,
        worst_case_load_percent: 100.0 * worst_bits / capacity_bits,
    }
}

/// What happened to a received frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Dispatch {
    /// The node at this index parsed it.
    Handled(usize),
    /// The node at this index claimed it but rejected it as malformed.
    Rejected(usize, crate::node::FrameError),
    /// No node claimed it.
    Unmatched,
}

/// What one [`Bus::transmit`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TransmitReport {
    /// Frames queued.
    pub sent: u8,
    /// Frames not queued: TX buffers full.
    pub full: u8,
    /// Frames not queued: controller bus-off.
    pub bus_off: u8,
}

/// A frozen bus: its nodes, statistics and rates. Shared as `&'static` by the scheduler task,
/// the receiver task and anyone reading statistics.
pub struct Bus<'a, const N: usize> {
    nodes: heapless::Vec<&'a dyn CanNode, N>,
    config: BusConfig,
    stats: BusStats,
    window: Mutex<CriticalSectionRawMutex, RefCell<RateWindow>>,
}

impl<'a, const N: usize> Bus<'a, N> {
    /// The registered nodes, in registration (and tick) order.
    pub fn nodes(&self) -> &[&'a dyn CanNode] {
        &self.nodes
    }

    /// The configuration.
    pub const fn config(&self) -> &BusConfig {
        &self.config
    }

    /// The frame budget of the registered nodes.
    pub fn budget(&self) -> FrameBudget {
        frame_budget(self.nodes.iter().copied(), &self.config)
    }

    /// Live counters.
    pub const fn stats(&self) -> &BusStats {
        &self.stats
    }

    /// Rates over the last complete [`BusConfig::rate_window`].
    pub fn rates(&self) -> BusRates {
        self.window.lock(|w| w.borrow().latched())
    }

    /// One scheduler tick at `now`, `dt_s` seconds after the previous: update every node, then
    /// pack every node into `out` (cleared first). Does not send; see [`transmit`](Self::transmit).
    pub fn tick(&self, now: Instant, dt_s: f32, out: &mut TxBatch) {
        out.clear();
        for node in &self.nodes {
            node.update(now, dt_s);
        }
        for node in &self.nodes {
            node.pack_command(out);
        }
        if out.overflowed() > 0 {
            self.stats.record_batch_overflow(out.overflowed());
        }
        self.stats.record_tick();
        self.window.lock(|w| {
            w.borrow_mut().update(
                now,
                || self.stats.snapshot(),
                self.config.rate_window,
                self.config.bitrate_bps,
            )
        });
    }

    /// Hands the batch's frames to `tx` in order with `try_send`, counting what was queued and
    /// what was not. Also records the controller's bus-off state (counting each entry).
    pub fn transmit(&self, batch: &TxBatch, tx: &mut impl CanTransmit) -> TransmitReport {
        self.stats
            .record_bus_off_state(tx.status().state == ErrorState::BusOff);
        let mut report = TransmitReport::default();
        for frame in batch.frames() {
            match tx.try_send(frame) {
                Ok(()) => {
                    self.stats.record_tx(timing::unstuffed_bits(frame));
                    report.sent += 1;
                }
                Err(SendError::Full) => {
                    self.stats.record_tx_full();
                    report.full += 1;
                }
                Err(SendError::BusOff) => {
                    self.stats.record_tx_bus_off();
                    self.stats.record_bus_off_state(true);
                    report.bus_off += 1;
                }
            }
        }
        report
    }

    /// Routes a received frame to the node that claims it.
    pub fn dispatch(&self, frame: &CanFrame, now: Instant) -> Dispatch {
        self.stats.record_rx(timing::unstuffed_bits(frame));
        for (i, node) in self.nodes.iter().enumerate() {
            if node.matches_frame(frame) {
                return match node.update_feedback(frame, now) {
                    Ok(()) => Dispatch::Handled(i),
                    Err(e) => {
                        self.stats.record_rejected();
                        Dispatch::Rejected(i, e)
                    }
                };
            }
        }
        self.stats.record_unmatched();
        Dispatch::Unmatched
    }

    /// Counts a receive-side error reported by the transport.
    pub fn record_receive_error(&self, error: ReceiveError) {
        match error {
            ReceiveError::Overrun => self.stats.record_overrun(),
            ReceiveError::BusError => self.stats.record_bus_error(),
            ReceiveError::BusOff => self.stats.record_bus_off_state(true),
        }
    }
}

/// The scheduler task's loop: every `period` from an embassy-time `Ticker`, [`Bus::tick`] then
/// [`Bus::transmit`]. `dt` is measured with 64-bit microsecond time, bounded to
/// `[period, 10·period]` on the first tick and after a stall.
pub async fn run_scheduler<T: CanTransmit, const N: usize>(
    bus: &Bus<'_, N>,
    mut tx: T,
    period: Duration,
) -> ! {
    let mut ticker = embassy_time::Ticker::every(period);
    let mut dt = DeltaTime::new(period, period * 10);
    let mut batch = TxBatch::new();
    loop {
        ticker.next().await;
        let now = Instant::now();
        let dt_s = dt.update(now);
        bus.tick(now, dt_s, &mut batch);
        bus.transmit(&batch, &mut tx);
    }
}

/// The receiver task's loop: awaits frames and dispatches each with its reception timestamp.
pub async fn run_receiver<R: CanReceive, const N: usize>(bus: &Bus<'_, N>, mut rx: R) -> ! {
    loop {
        match rx.receive().await {
            Ok(received) => {
                bus.dispatch(&received.frame, received.timestamp);
            }
            Err(e) => bus.record_receive_error(e),
        }
    }
}

#[cfg(test)]
mod tests;
