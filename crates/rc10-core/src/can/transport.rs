//! The transport traits a CAN peripheral (or the simulator, or a test loopback) implements.
//!
//! They are deliberately small. Sending is non-blocking only ([`CanTransmit::try_send`]): the
//! 1 kHz tick must never wait for the bus, so a full TX queue is reported and counted, not
//! waited on. Receiving is async ([`CanReceive::receive`]) and carries a timestamp: the
//! reception time where the transport has one, else the time the driver read the frame
//! (embassy-stm32 0.6 gives no usable hardware reception time, so rc10-stm32 stamps frames
//! with embassy-time when it reads them from the RX FIFO: up to the receiver task's latency
//! late). Consumers therefore treat timestamps with care: a stamp later than the tick's `now`
//! is clamped to it, and lost-frame unwrapping takes at least one feedback period between
//! frames read back to back.

use super::CanFrame;
use crate::time::Instant;
use core::fmt;

/// Why a frame could not be queued for transmission.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SendError {
    /// Every TX buffer is in use (3 on an STM32G4 FDCAN); the frame was not queued.
    Full,
    /// The controller is bus-off and sends nothing until it recovers.
    BusOff,
}

impl fmt::Display for SendError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Full => "CAN TX queue full",
            Self::BusOff => "CAN controller is bus-off",
        })
    }
}

impl core::error::Error for SendError {}

/// A receive-side problem reported instead of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ReceiveError {
    /// The RX FIFO overflowed: at least one frame was lost.
    Overrun,
    /// The controller is bus-off.
    BusOff,
    /// A protocol error (stuff, form, CRC, ACK, bit) was seen on the bus.
    BusError,
}

impl fmt::Display for ReceiveError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Overrun => "CAN RX FIFO overrun: frames lost",
            Self::BusOff => "CAN controller is bus-off",
            Self::BusError => "CAN protocol error on the bus",
        })
    }
}

impl core::error::Error for ReceiveError {}

/// The controller's fault-confinement state (ISO 11898-1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ErrorState {
    /// Both error counters below 128: normal operation.
    #[default]
    Active,
    /// An error counter at 128 or above: the node still works but signals errors passively.
    Passive,
    /// TX error counter above 255: the node is off the bus until it recovers.
    BusOff,
}

/// Error state and counters of a CAN controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BusStatus {
    /// Fault-confinement state.
    pub state: ErrorState,
    /// Transmit error counter (0–255).
    pub tx_error_count: u8,
    /// Receive error counter (0–127: the FDCAN's ECR.REC is 7 bits wide; a receiver that is
    /// error-passive shows in `state`).
    pub rx_error_count: u8,
    /// Whether the controller recorded a protocol error (stuff, form, ACK, bit, CRC) since
    /// the last status read.
    pub protocol_error: bool,
    /// How many protocol errors the controller logged since the last status read, where it
    /// counts them (FDCAN: ECR.CEL, reset by the read, stopping at 255); 0 where it cannot
    /// tell. The bus adds this to `bus_errors`, or 1 for `protocol_error` when this is 0.
    /// (A last-error code such as FDCAN's PSR.LEC shows one error at most and is cleared by
    /// the next good frame: errors that were retried successfully within a tick only show
    /// here.)
    pub errors_logged: u8,
}

/// A received frame and its timestamp (see the module docs: possibly the time it was read).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Received {
    /// The frame.
    pub frame: CanFrame,
    /// When the frame was received: the peripheral's reception time if the transport has
    /// one, else when the driver read it (see the module docs).
    pub timestamp: Instant,
}

/// The sending half of a CAN transport.
pub trait CanTransmit {
    /// Queues `frame` for transmission without waiting. `Ok` means *queued* in a TX buffer,
    /// not sent: the frame still has to win arbitration and be acknowledged.
    fn try_send(&mut self, frame: &CanFrame) -> Result<(), SendError>;

    /// Current error state and counters. Transports that cannot tell report error-active.
    fn status(&self) -> BusStatus {
        BusStatus::default()
    }

    /// Frames queued on an earlier tick that are still waiting to go out, asked at the start
    /// of each tick's transmit. Non-zero means the bus could not carry last tick's commands
    /// within a period (congestion, or nobody acknowledging, so frames are retransmitted):
    /// they go out late, and they hold TX buffers this tick's fresher commands need. Counted
    /// in `tx_stale`. Transports that cannot tell report 0.
    fn still_queued(&self) -> u8 {
        0
    }
}

/// The receiving half of a CAN transport.
#[allow(async_fn_in_trait)] // Used through generics in Embassy tasks; no Send bound is wanted.
pub trait CanReceive {
    /// Waits for the next frame, or reports why frames were lost.
    ///
    /// Errors are one-off events: after reporting one, the next call waits for the next
    /// frame or the next *new* error. A transport that cannot promise this (it reports the
    /// same condition again at once) is still safe with [`run_receiver`](crate::bus::run_receiver),
    /// which backs off on repeated errors instead of spinning.
    async fn receive(&mut self) -> Result<Received, ReceiveError>;
}

impl<T: CanTransmit + ?Sized> CanTransmit for &mut T {
    fn try_send(&mut self, frame: &CanFrame) -> Result<(), SendError> {
        (**self).try_send(frame)
    }

    fn status(&self) -> BusStatus {
        (**self).status()
    }

    fn still_queued(&self) -> u8 {
        (**self).still_queued()
    }
}

impl<T: CanReceive + ?Sized> CanReceive for &mut T {
    async fn receive(&mut self) -> Result<Received, ReceiveError> {
        (**self).receive().await
    }
}
