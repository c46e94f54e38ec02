//! A simulated classic CAN bus in virtual time: frame durations from the exact bit count
//! (stuffing included) at the configured bitrate, arbitration by ID among all nodes with a
//! frame waiting, and bounded TX queues (the STM32G4's 3 TX buffers on the controller side,
//! sent oldest first or lowest ID first: [`TxOrder`]).
//!
//! The bus does not run by itself: the world loop asks it for the next moment something
//! happens ([`SimBus::busy_until`]), completes frames ([`SimBus::complete`]) and starts the next
//! one ([`SimBus::start_next`]).
//!
//! Two controller faults are modelled here: bus-off ([`SimBus::set_mcu_bus_off`]: nothing sent
//! or received, pending frames held and sent on recovery) and no acknowledgement
//! ([`SimBus::set_mcu_no_ack`]: the controller is cut off from the other nodes, so its frames
//! are retransmitted without end and stay in its TX buffers, and it receives nothing).

use rc10_core::can::{BusStatus, CanFrame, CanTransmit, ErrorState, Id, SendError, timing};
use std::collections::VecDeque;

/// Which node a frame came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sender {
    /// The controller running rc10 (the STM32).
    Mcu,
    /// Device `n` (an ESC), in the order devices were added.
    Device(usize),
}

/// Which of the controller's pending TX frames enters arbitration next: the STM32G4 FDCAN's
/// TX FIFO or TX queue mode.
///
/// Only the order is modelled: in both modes a full set of buffers refuses the next frame
/// ([`SendError::Full`]), nothing pending is aborted or replaced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TxOrder {
    /// TX FIFO: the oldest pending frame goes first, whatever its ID (`TXBC.TFQM = 0`; HAL
    /// `FDCAN_TX_FIFO_OPERATION`; embassy-stm32 `TxBufferMode::Fifo`, which rc10-stm32 sets).
    #[default]
    Fifo,
    /// TX queue: the pending frame with the lowest ID (highest priority, compared as in
    /// arbitration) goes first (`TXBC.TFQM = 1`; HAL `FDCAN_TX_QUEUE_OPERATION`; embassy-stm32's
    /// default `TxBufferMode::Priority`). Frames with the same ID go oldest first (the FDCAN
    /// takes the lowest buffer number; buffer numbers are not modelled).
    LowestIdFirst,
}

/// Bus parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SimBusConfig {
    /// Bitrate in bits per second (1 Mbit/s for DJI motors).
    pub bitrate_bps: u32,
    /// TX buffers of the controller, in frames (3 on an STM32G4 FDCAN).
    pub mcu_tx_depth: usize,
    /// Order in which the controller's pending TX frames are sent ([`TxOrder::Fifo`] by
    /// default).
    pub mcu_tx_order: TxOrder,
    /// TX buffers of each device, in frames (always sent oldest first).
    pub device_tx_depth: usize,
}

impl Default for SimBusConfig {
    fn default() -> Self {
        Self {
            bitrate_bps: 1_000_000,
            mcu_tx_depth: 3,
            mcu_tx_order: TxOrder::Fifo,
            device_tx_depth: 3,
        }
    }
}

/// Counters of the simulated bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SimBusStats {
    /// Frames that completed on the wire.
    pub frames: u64,
    /// Microseconds the bus was busy.
    pub busy_us: u64,
    /// Controller frames refused because its TX buffers were full.
    pub mcu_tx_full: u64,
    /// Device frames dropped because the device's TX buffers were full.
    pub device_tx_dropped: u64,
    /// Frames the fault injector removed from the wire.
    pub lost: u64,
    /// Controller frames refused because it was bus-off.
    pub mcu_tx_bus_off: u64,
}

/// The simulated bus.
#[derive(Debug)]
pub struct SimBus {
    config: SimBusConfig,
    /// The controller's pending frames, each with its sequence number ([`SimBus::next_mcu_seq`]).
    mcu_tx: VecDeque<(u64, CanFrame)>,
    device_tx: Vec<VecDeque<CanFrame>>,
    /// Frames waiting in all of `device_tx` (so an idle bus with nothing waiting is seen at
    /// once: [`SimBus::start_next`] runs after every event).
    device_waiting: usize,
    /// The frame on the wire: sender, frame, end time, and for a controller frame its sequence
    /// number.
    on_wire: Option<(Sender, CanFrame, u64, Option<u64>)>,
    mcu_bus_off: bool,
    mcu_no_ack: bool,
    mcu_seq: u64,
    stats: SimBusStats,
}

impl SimBus {
    /// An idle bus with no devices.
    pub fn new(config: SimBusConfig) -> Self {
        Self {
            config,
            mcu_tx: VecDeque::new(),
            device_tx: Vec::new(),
            device_waiting: 0,
            on_wire: None,
            mcu_bus_off: false,
            mcu_no_ack: false,
            mcu_seq: 0,
            stats: SimBusStats::default(),
        }
    }

    /// Adds a device node; returns its index for [`Sender::Device`].
    pub fn add_device(&mut self) -> usize {
        self.device_tx.push(VecDeque::new());
        self.device_tx.len() - 1
    }

    /// The configuration.
    pub fn config(&self) -> &SimBusConfig {
        &self.config
    }

    /// Counters so far.
    pub fn stats(&self) -> SimBusStats {
        self.stats
    }

    /// The controller's transmit port, for `rc10_core::bus::Bus::transmit`.
    pub fn mcu_port(&mut self) -> McuPort<'_> {
        McuPort { bus: self }
    }

    /// Queues a frame from device `index`; dropped (and counted) if its buffers are full.
    pub fn device_send(&mut self, index: usize, frame: CanFrame) {
        let depth = self.config.device_tx_depth;
        match self.device_tx.get_mut(index) {
            Some(q) if q.len() < depth => {
                q.push_back(frame);
                self.device_waiting += 1;
            }
            _ => self.stats.device_tx_dropped += 1,
        }
    }

    /// Device `index` loses power: the frames it had queued are gone, and a frame of its on
    /// the wire breaks off (the bus is free at once; counted in `lost`).
    pub fn power_off_device(&mut self, index: usize) {
        if let Some(q) = self.device_tx.get_mut(index) {
            self.device_waiting -= q.len();
            q.clear();
        }
        if matches!(self.on_wire, Some((Sender::Device(d), _, _, _)) if d == index) {
            self.on_wire = None;
            self.stats.lost += 1;
        }
    }

    /// When the frame on the wire ends, if one is.
    pub fn busy_until(&self) -> Option<u64> {
        self.on_wire.map(|(_, _, end, _)| end)
    }

    /// Takes the frame that ends at `now_us`, if any.
    pub fn complete(&mut self, now_us: u64) -> Option<(Sender, CanFrame)> {
        self.complete_with_seq(now_us)
            .map(|(sender, frame, _)| (sender, frame))
    }

    /// [`complete`](Self::complete), with the sequence number of a controller frame (the
    /// order in which [`McuPort`] accepted it: see [`next_mcu_seq`](Self::next_mcu_seq)).
    pub fn complete_with_seq(&mut self, now_us: u64) -> Option<(Sender, CanFrame, Option<u64>)> {
        match self.on_wire {
            Some((sender, frame, end, seq)) if end <= now_us => {
                self.on_wire = None;
                self.stats.frames += 1;
                Some((sender, frame, seq))
            }
            _ => None,
        }
    }

    /// The sequence number the next frame the controller's port accepts will get: frames are
    /// numbered 0, 1, 2… in the order `try_send` accepted them.
    pub fn next_mcu_seq(&self) -> u64 {
        self.mcu_seq
    }

    /// Controller frames holding a TX buffer now: waiting, or on the wire (what
    /// [`CanTransmit::still_queued`] reports).
    pub fn mcu_pending(&self) -> usize {
        self.mcu_frames_held()
    }

    /// Puts the controller into bus-off (it sends and receives nothing and refuses new frames)
    /// or lets it recover. Its pending TX frames stay in their buffers and go out on
    /// recovery, carrying the commands they were packed with: the FDCAN clears a pending
    /// request (TXBRP) only when its frame was sent or when software cancels it (TXBCR;
    /// RM0440), and rc10 cancels nothing.
    pub fn set_mcu_bus_off(&mut self, bus_off: bool) {
        self.mcu_bus_off = bus_off;
    }

    /// Whether the controller is bus-off.
    pub fn mcu_bus_off(&self) -> bool {
        self.mcu_bus_off
    }

    /// Cuts the controller off from every other node (no node acknowledges its frames: the
    /// other nodes are unpowered, or the wire to them is broken) or reconnects it.
    ///
    /// While cut off, the controller retransmits its pending frame without end: its frames
    /// never complete and keep their TX buffers, so its port soon reports
    /// [`SendError::Full`] and [`CanTransmit::still_queued`] counts them at every tick; its
    /// status is error-passive with an ACK error each time it is read (the FDCAN's TEC stops
    /// at 128 on ACK errors, so it never goes bus-off this way). The other nodes no longer
    /// hear it and it no longer hears them (the world loop does not deliver their frames to
    /// it: [`mcu_no_ack`](Self::mcu_no_ack)); among themselves they carry on. When it is
    /// reconnected, its pending frames go out, oldest first: they carry the commands they
    /// were packed with.
    pub fn set_mcu_no_ack(&mut self, no_ack: bool) {
        self.mcu_no_ack = no_ack;
    }

    /// Whether the controller is cut off from the other nodes (see
    /// [`set_mcu_no_ack`](Self::set_mcu_no_ack)).
    pub fn mcu_no_ack(&self) -> bool {
        self.mcu_no_ack
    }

    /// Controller frames holding a TX buffer: waiting, or on the wire.
    fn mcu_frames_held(&self) -> usize {
        let on_wire = matches!(self.on_wire, Some((Sender::Mcu, _, _, _)));
        self.mcu_tx.len() + usize::from(on_wire)
    }

    /// Counts a frame that a fault removed from the wire.
    pub fn record_lost(&mut self) {
        self.stats.lost += 1;
    }

    /// Index in `mcu_tx` of the controller's frame that enters arbitration next, per
    /// [`SimBusConfig::mcu_tx_order`].
    fn mcu_next(&self) -> Option<usize> {
        if self.mcu_no_ack || self.mcu_bus_off {
            // No ACK: retransmitted on the controller's own side of the cut, nobody else
            // hears it. Bus-off: held until recovery.
            return None;
        }
        match self.config.mcu_tx_order {
            TxOrder::Fifo => (!self.mcu_tx.is_empty()).then_some(0),
            // `min_by_key` keeps the first of equal keys: the oldest.
            TxOrder::LowestIdFirst => self
                .mcu_tx
                .iter()
                .enumerate()
                .min_by_key(|(_, (_, f))| arbitration_key(f))
                .map(|(i, _)| i),
        }
    }

    /// If the bus is idle, starts the waiting frame that wins arbitration (lowest ID; a
    /// standard ID beats an extended one with the same first 11 bits). The controller offers
    /// one of its pending frames, chosen by [`SimBusConfig::mcu_tx_order`]; each device offers
    /// its oldest.
    pub fn start_next(&mut self, now_us: u64) {
        if self.on_wire.is_some() || (self.device_waiting == 0 && self.mcu_tx.is_empty()) {
            return;
        }
        // The controller's offer first, then each device's: on equal keys the first stays.
        let mcu_next = self.mcu_next();
        let mut best: Option<(u64, Sender)> = mcu_next
            .and_then(|i| self.mcu_tx.get(i))
            .map(|(_, f)| (arbitration_key(f), Sender::Mcu));
        for (i, q) in self.device_tx.iter().enumerate() {
            if let Some(f) = q.front() {
                let key = arbitration_key(f);
                if best.is_none_or(|(k, _)| key < k) {
                    best = Some((key, Sender::Device(i)));
                }
            }
        }
        let Some((_, sender)) = best else { return };
        let frame = match sender {
            Sender::Mcu => mcu_next
                .and_then(|i| {
                    if i == 0 {
                        self.mcu_tx.pop_front()
                    } else {
                        self.mcu_tx.remove(i)
                    }
                })
                .map(|(seq, f)| (f, Some(seq))),
            Sender::Device(i) => {
                let popped = self.device_tx.get_mut(i).and_then(VecDeque::pop_front);
                self.device_waiting -= usize::from(popped.is_some());
                popped.map(|f| (f, None))
            }
        };
        if let Some((frame, seq)) = frame {
            let duration = u64::from(timing::frame_time_us(&frame, self.config.bitrate_bps));
            self.stats.busy_us += duration;
            self.on_wire = Some((sender, frame, now_us + duration, seq));
        }
    }
}

/// The arbitration field as a number: lower wins. Standard: ID, RTR, IDE=0. Extended: base ID,
/// SRR=1, IDE=1, ID extension, RTR.
fn arbitration_key(frame: &CanFrame) -> u64 {
    let rtr = u64::from(frame.is_remote());
    match frame.id() {
        Id::Standard(id) => (u64::from(id.as_raw()) << 21) | (rtr << 20),
        Id::Extended(id) => {
            let raw = u64::from(id.as_raw());
            ((raw >> 18) << 21) | (1 << 20) | (1 << 19) | ((raw & 0x3_FFFF) << 1) | rtr
        }
    }
}

/// The controller's TX buffers, as rc10's scheduler sees them.
#[derive(Debug)]
pub struct McuPort<'a> {
    bus: &'a mut SimBus,
}

impl CanTransmit for McuPort<'_> {
    fn try_send(&mut self, frame: &CanFrame) -> Result<(), SendError> {
        if self.bus.mcu_bus_off {
            self.bus.stats.mcu_tx_bus_off += 1;
            return Err(SendError::BusOff);
        }
        // A frame on the wire still holds its TX buffer until it completes, as on the FDCAN.
        if self.bus.mcu_frames_held() >= self.bus.config.mcu_tx_depth {
            self.bus.stats.mcu_tx_full += 1;
            return Err(SendError::Full);
        }
        let seq = self.bus.mcu_seq;
        self.bus.mcu_seq += 1;
        self.bus.mcu_tx.push_back((seq, *frame));
        Ok(())
    }

    fn status(&self) -> BusStatus {
        if self.bus.mcu_bus_off {
            BusStatus {
                state: ErrorState::BusOff,
                tx_error_count: 255,
                ..BusStatus::default()
            }
        } else if self.bus.mcu_no_ack && self.bus.mcu_frames_held() > 0 {
            // Retransmitting without acknowledgement: an ACK error on every attempt, the TEC
            // held at 128 (error-passive; ACK errors while passive do not raise it further).
            BusStatus {
                state: ErrorState::Passive,
                tx_error_count: 128,
                protocol_error: true,
                ..BusStatus::default()
            }
        } else {
            BusStatus::default()
        }
    }

    fn still_queued(&self) -> u8 {
        u8::try_from(self.bus.mcu_frames_held()).unwrap_or(u8::MAX)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn std_frame(id: u16) -> CanFrame {
        CanFrame::standard(id, &[0x55; 8]).unwrap()
    }

    #[test]
    fn lowest_id_wins_and_frame_lasts_its_bit_time() {
        let mut bus = SimBus::new(SimBusConfig::default());
        let esc = bus.add_device();
        bus.device_send(esc, std_frame(0x201));
        bus.mcu_port().try_send(&std_frame(0x200)).unwrap();
        bus.start_next(100);
        let end = bus.busy_until().unwrap();
        assert_eq!(end, 100 + u64::from(timing::frame_bits(&std_frame(0x200))));
        assert_eq!(bus.complete(end), Some((Sender::Mcu, std_frame(0x200))));
        bus.start_next(end);
        let end2 = bus.busy_until().unwrap();
        assert_eq!(
            bus.complete(end2),
            Some((Sender::Device(0), std_frame(0x201)))
        );
    }

    #[test]
    fn command_0x2ff_loses_to_feedback_0x205() {
        let mut bus = SimBus::new(SimBusConfig::default());
        let esc = bus.add_device();
        bus.mcu_port().try_send(&std_frame(0x2FF)).unwrap();
        bus.device_send(esc, std_frame(0x205));
        bus.start_next(0);
        let end = bus.busy_until().unwrap();
        assert_eq!(bus.complete(end).unwrap().0, Sender::Device(0));
    }

    #[test]
    fn standard_beats_extended_with_same_base() {
        let s = CanFrame::standard(0x100, &[]).unwrap();
        let e = CanFrame::extended(0x100 << 18, &[]).unwrap();
        assert!(arbitration_key(&s) < arbitration_key(&e));
        let e_low = CanFrame::extended(0x0000_0901, &[]).unwrap(); // base 0
        assert!(arbitration_key(&e_low) < arbitration_key(&s));
    }

    /// Queues 0x2FF, 0x200, 0x1FF on the controller (no devices) and returns the order in
    /// which they complete on the wire.
    fn mcu_send_order(order: TxOrder) -> Vec<u16> {
        let mut bus = SimBus::new(SimBusConfig {
            mcu_tx_order: order,
            ..SimBusConfig::default()
        });
        for id in [0x2FF, 0x200, 0x1FF] {
            bus.mcu_port().try_send(&std_frame(id)).unwrap();
        }
        let mut sent = Vec::new();
        let mut now = 0;
        bus.start_next(now);
        while let Some(end) = bus.busy_until() {
            now = end;
            let (sender, frame) = bus.complete(now).unwrap();
            assert_eq!(sender, Sender::Mcu);
            let Id::Standard(id) = frame.id() else {
                panic!("sent only standard frames")
            };
            sent.push(id.as_raw());
            bus.start_next(now);
        }
        sent
    }

    #[test]
    fn default_mcu_tx_order_is_fifo() {
        assert_eq!(SimBusConfig::default().mcu_tx_order, TxOrder::Fifo);
        assert_eq!(TxOrder::default(), TxOrder::Fifo);
    }

    #[test]
    fn fifo_sends_the_oldest_pending_frame_first() {
        assert_eq!(mcu_send_order(TxOrder::Fifo), vec![0x2FF, 0x200, 0x1FF]);
    }

    #[test]
    fn lowest_id_first_sends_the_highest_priority_pending_frame_first() {
        assert_eq!(
            mcu_send_order(TxOrder::LowestIdFirst),
            vec![0x1FF, 0x200, 0x2FF]
        );
    }

    #[test]
    fn lowest_id_first_reorders_frames_queued_while_the_bus_is_busy() {
        // 0x2FF takes the wire; meanwhile 0x205 and then 0x201 are queued: the queue sends
        // 0x201 next, the FIFO 0x205.
        for (order, expected) in [(TxOrder::Fifo, 0x205), (TxOrder::LowestIdFirst, 0x201)] {
            let mut bus = SimBus::new(SimBusConfig {
                mcu_tx_order: order,
                ..SimBusConfig::default()
            });
            bus.mcu_port().try_send(&std_frame(0x2FF)).unwrap();
            bus.start_next(0);
            bus.mcu_port().try_send(&std_frame(0x205)).unwrap();
            bus.mcu_port().try_send(&std_frame(0x201)).unwrap();
            let end = bus.busy_until().unwrap();
            assert_eq!(bus.complete(end).unwrap().1, std_frame(0x2FF));
            bus.start_next(end);
            let end2 = bus.busy_until().unwrap();
            assert_eq!(
                bus.complete(end2).unwrap().1,
                std_frame(expected),
                "{order:?}"
            );
        }
    }

    #[test]
    fn lowest_id_first_keeps_arrival_order_for_equal_ids() {
        let mut bus = SimBus::new(SimBusConfig {
            mcu_tx_order: TxOrder::LowestIdFirst,
            ..SimBusConfig::default()
        });
        let first = CanFrame::standard(0x200, &[1; 8]).unwrap();
        let second = CanFrame::standard(0x200, &[2; 8]).unwrap();
        bus.mcu_port().try_send(&std_frame(0x2FF)).unwrap();
        bus.mcu_port().try_send(&first).unwrap();
        bus.mcu_port().try_send(&second).unwrap();
        bus.start_next(0);
        let end = bus.busy_until().unwrap();
        assert_eq!(bus.complete(end).unwrap().1, first);
        bus.start_next(end);
        let end2 = bus.busy_until().unwrap();
        assert_eq!(bus.complete(end2).unwrap().1, second);
    }

    #[test]
    fn lowest_id_first_still_loses_arbitration_to_a_lower_device_id() {
        let mut bus = SimBus::new(SimBusConfig {
            mcu_tx_order: TxOrder::LowestIdFirst,
            ..SimBusConfig::default()
        });
        let esc = bus.add_device();
        bus.mcu_port().try_send(&std_frame(0x2FF)).unwrap();
        bus.mcu_port().try_send(&std_frame(0x200)).unwrap();
        bus.device_send(esc, std_frame(0x1FF));
        bus.start_next(0);
        let end = bus.busy_until().unwrap();
        assert_eq!(
            bus.complete(end),
            Some((Sender::Device(0), std_frame(0x1FF)))
        );
        bus.start_next(end);
        let end2 = bus.busy_until().unwrap();
        assert_eq!(bus.complete(end2), Some((Sender::Mcu, std_frame(0x200))));
    }

    #[test]
    fn frames_still_held_at_the_next_tick_are_reported_and_hold_buffers() {
        let mut bus = SimBus::new(SimBusConfig::default());
        let mut port = bus.mcu_port();
        port.try_send(&std_frame(0x200)).unwrap();
        port.try_send(&std_frame(0x1FF)).unwrap();
        assert_eq!(port.still_queued(), 2);
        bus.start_next(0); // 0x200 goes on the wire: it still holds its buffer
        let mut port = bus.mcu_port();
        assert_eq!(port.still_queued(), 2);
        port.try_send(&std_frame(0x2FF)).unwrap();
        assert_eq!(port.try_send(&std_frame(0x2FE)), Err(SendError::Full));
        let end = bus.busy_until().unwrap();
        bus.complete(end);
        assert_eq!(bus.mcu_port().still_queued(), 2);
    }

    #[test]
    fn without_acknowledgement_controller_frames_stay_queued_until_reconnected() {
        let mut bus = SimBus::new(SimBusConfig::default());
        let esc = bus.add_device();
        bus.set_mcu_no_ack(true);
        assert_eq!(bus.mcu_port().status(), BusStatus::default()); // nothing to send yet
        for id in [0x200, 0x1FF, 0x2FF] {
            bus.mcu_port().try_send(&std_frame(id)).unwrap();
        }
        assert_eq!(
            bus.mcu_port().try_send(&std_frame(0x2FE)),
            Err(SendError::Full)
        );
        assert_eq!(bus.stats().mcu_tx_full, 1);
        let status = bus.mcu_port().status();
        assert_eq!(status.state, ErrorState::Passive);
        assert!(status.protocol_error);
        // The devices still talk among themselves; the controller's frames never go out.
        bus.device_send(esc, std_frame(0x201));
        bus.start_next(0);
        let end = bus.busy_until().unwrap();
        assert_eq!(
            bus.complete(end),
            Some((Sender::Device(0), std_frame(0x201)))
        );
        bus.start_next(end);
        assert_eq!(bus.busy_until(), None);
        assert_eq!(bus.mcu_port().still_queued(), 3);
        // Reconnected: the held frames leave, oldest first, with their sequence numbers.
        bus.set_mcu_no_ack(false);
        assert_eq!(bus.mcu_port().status(), BusStatus::default());
        let mut now = end;
        for (seq, id) in [(0, 0x200), (1, 0x1FF), (2, 0x2FF)] {
            bus.start_next(now);
            now = bus.busy_until().unwrap();
            assert_eq!(
                bus.complete_with_seq(now),
                Some((Sender::Mcu, std_frame(id), Some(seq)))
            );
        }
        assert_eq!(bus.next_mcu_seq(), 3);
        assert_eq!(bus.mcu_pending(), 0);
    }

    #[test]
    fn frames_refused_while_bus_off_are_counted() {
        let mut bus = SimBus::new(SimBusConfig::default());
        bus.set_mcu_bus_off(true);
        assert_eq!(
            bus.mcu_port().try_send(&std_frame(0x200)),
            Err(SendError::BusOff)
        );
        assert_eq!(bus.stats().mcu_tx_bus_off, 1);
        assert_eq!(bus.next_mcu_seq(), 0);
    }

    #[test]
    fn frames_pending_at_bus_off_go_out_on_recovery() {
        // Three commands queued, the bus goes off before any starts: none goes out while
        // off, and all three, in order, after it recovers (the FDCAN keeps its pending
        // requests; only a sent frame or a cancellation clears them).
        let mut bus = SimBus::new(SimBusConfig::default());
        for id in [0x200, 0x1FF, 0x1FE] {
            bus.mcu_port().try_send(&std_frame(id)).unwrap();
        }
        bus.set_mcu_bus_off(true);
        bus.start_next(0);
        assert_eq!(bus.busy_until(), None);
        assert_eq!(bus.mcu_pending(), 3);
        bus.set_mcu_bus_off(false);
        let mut now = 1000;
        for (seq, id) in [0x200, 0x1FF, 0x1FE].into_iter().enumerate() {
            bus.start_next(now);
            now = bus.busy_until().unwrap();
            assert_eq!(
                bus.complete_with_seq(now),
                Some((Sender::Mcu, std_frame(id), Some(seq as u64)))
            );
        }
        assert_eq!(bus.mcu_pending(), 0);
    }

    #[test]
    fn a_device_that_loses_power_sends_nothing_more() {
        let mut bus = SimBus::new(SimBusConfig::default());
        let esc = bus.add_device();
        let other = bus.add_device();
        bus.device_send(esc, std_frame(0x201));
        bus.device_send(esc, std_frame(0x201));
        bus.device_send(other, std_frame(0x202));
        bus.start_next(0); // 0x201 wins arbitration and is on the wire
        bus.power_off_device(esc);
        assert_eq!(bus.busy_until(), None);
        assert_eq!(bus.stats().lost, 1);
        // Only the other device's frame is left.
        bus.start_next(10);
        let end = bus.busy_until().unwrap();
        assert_eq!(
            bus.complete(end),
            Some((Sender::Device(other), std_frame(0x202)))
        );
        bus.start_next(end);
        assert_eq!(bus.busy_until(), None);
    }

    #[test]
    fn mcu_tx_depth_is_three() {
        let mut bus = SimBus::new(SimBusConfig::default());
        let mut port = bus.mcu_port();
        for _ in 0..3 {
            port.try_send(&std_frame(0x200)).unwrap();
        }
        assert_eq!(port.try_send(&std_frame(0x200)), Err(SendError::Full));
        assert_eq!(bus.stats().mcu_tx_full, 1);
    }
}
