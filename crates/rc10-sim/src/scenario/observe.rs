//! Watching a run as it happens: every frame on the wire, every frame handed to rc10, every
//! tick, for checks that span a whole run without keeping a sample of every tick in memory
//! (the [`soak`](super::soak) checks). [`run_observed`](super::run_observed) calls a
//! [`RunObserver`]; [`run`](super::run) uses one that watches nothing.

use super::Sample;
use crate::bus::Sender;
use rc10_core::bus::{Dispatch, PacedTick, TransmitReport};
use rc10_core::can::CanFrame;
use rc10_core::node::TxBatch;

/// A frame that ended on the wire, and what the fault injector did to it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WireEvent {
    /// When it ended, µs.
    pub t_us: u64,
    /// Who sent it.
    pub sender: Sender,
    /// The frame as sent.
    pub frame: CanFrame,
    /// For a controller frame, its sequence number: the order in which the controller's
    /// transmit port accepted it (see [`TickEvent::first_seq`]).
    pub mcu_seq: Option<u64>,
    /// The frame as the other nodes received it (a corrupted copy if `corrupted`), or `None`
    /// if a fault removed it from the wire.
    pub received: Option<CanFrame>,
    /// Whether the fault injector corrupted it (a wrong DLC).
    pub corrupted: bool,
}

/// Why a frame on its way to the controller never reached rc10.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RxDrop {
    /// The controller was bus-off.
    BusOff,
    /// The controller was cut off from the other nodes (no acknowledgement).
    NoAck,
    /// The receive path was stalled and the frame's 3-deep RX FIFO was full (an overrun).
    Overrun,
    /// No acceptance filter passes its ID: the controller's hardware discarded it (rc10
    /// never hears of it, as on a board).
    Filtered,
}

/// One scheduler tick, after rc10's `tick` and `transmit`.
#[derive(Debug, Clone, Copy)]
pub struct TickEvent<'a> {
    /// When the tick ran, µs.
    pub t_us: u64,
    /// What rc10's tick pacing decided (its `dt` went to the tick).
    pub paced: PacedTick,
    /// The motors after the tick (their state, the command they packed).
    pub sample: &'a Sample,
    /// The frames the tick packed.
    pub batch: &'a TxBatch,
    /// What rc10's transmit did with them.
    pub report: TransmitReport,
    /// Controller frames of earlier ticks still holding TX buffers when this tick transmitted
    /// (what the transport's `still_queued` told rc10).
    pub held_before: usize,
    /// The sequence number of the first frame this tick queued: its `report.queued` frames
    /// have `first_seq..first_seq + queued`.
    pub first_seq: u64,
    /// Whether the controller was bus-off at the tick.
    pub bus_off: bool,
    /// Whether the controller was cut off from the other nodes at the tick.
    pub no_ack: bool,
}

/// Receives what happens during a run. Every method does nothing by default.
pub trait RunObserver {
    /// A frame ended on the wire.
    fn on_wire(&mut self, _event: &WireEvent) {}

    /// A frame was handed to rc10's `Bus::dispatch` at `t_us`, and what rc10 did with it.
    fn on_dispatch(&mut self, _t_us: u64, _frame: &CanFrame, _result: Dispatch) {}

    /// A frame on its way to the controller was dropped before rc10 saw it.
    fn on_rx_dropped(&mut self, _t_us: u64, _frame: &CanFrame, _why: RxDrop) {}

    /// The receive path ran again after a stall in which its FIFOs lost frames, and reported
    /// one overrun to rc10 (`Bus::record_receive_error`) at `t_us`.
    fn on_overrun_reported(&mut self, _t_us: u64) {}

    /// A scheduler tick ran.
    fn on_tick(&mut self, _tick: &TickEvent<'_>) {}

    /// Whether the run keeps the tick at `t_ms` in [`RunResult::samples`](super::RunResult)
    /// (true by default: every tick). Long runs thin their trace here.
    fn keep_sample(&mut self, _t_ms: u64) -> bool {
        true
    }
}

/// Watches nothing, keeps every sample.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoObserver;

impl RunObserver for NoObserver {}
