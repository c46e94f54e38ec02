//! An in-memory transmit queue with the depth of a real controller's TX buffers, for host
//! tests of nodes and schedulers (yours included) without hardware or the simulator.

use super::{BusStatus, CanFrame, CanTransmit, ErrorState, SendError};

/// A FIFO of `DEPTH` TX buffers (3 on an STM32G4 FDCAN). [`try_send`](CanTransmit::try_send)
/// reports [`SendError::Full`] when every buffer is taken; [`pop`](Self::pop) plays the bus
/// taking the oldest frame.
///
/// ```
/// use rc10_core::can::{CanFrame, CanTransmit, SendError, loopback::TxQueue};
/// let mut tx = TxQueue::<3>::new();
/// let f = CanFrame::standard(0x200, &[0; 8]).unwrap();
/// for _ in 0..3 { tx.try_send(&f).unwrap(); }
/// assert_eq!(tx.try_send(&f), Err(SendError::Full));
/// assert_eq!(tx.pop(), Some(f));
/// ```
#[derive(Debug, Default)]
pub struct TxQueue<const DEPTH: usize> {
    queue: heapless::Deque<CanFrame, DEPTH>,
    status: BusStatus,
}

impl<const DEPTH: usize> TxQueue<DEPTH> {
    /// An empty, error-active queue.
    pub const fn new() -> Self {
        Self {
            queue: heapless::Deque::new(),
            status: BusStatus {
                state: ErrorState::Active,
                tx_error_count: 0,
                rx_error_count: 0,
                protocol_error: false,
                errors_logged: 0,
            },
        }
    }

    /// Takes the oldest queued frame, as the bus would.
    pub fn pop(&mut self) -> Option<CanFrame> {
        self.queue.pop_front()
    }

    /// Frames waiting.
    pub fn len(&self) -> usize {
        self.queue.len()
    }

    /// Whether no frame is waiting.
    pub fn is_empty(&self) -> bool {
        self.queue.is_empty()
    }

    /// Sets the reported error state (to test bus-off handling).
    pub fn set_status(&mut self, status: BusStatus) {
        self.status = status;
    }
}

impl<const DEPTH: usize> CanTransmit for TxQueue<DEPTH> {
    fn try_send(&mut self, frame: &CanFrame) -> Result<(), SendError> {
        if self.status.state == ErrorState::BusOff {
            return Err(SendError::BusOff);
        }
        self.queue.push_back(*frame).map_err(|_| SendError::Full)
    }

    fn status(&self) -> BusStatus {
        self.status
    }

    fn still_queued(&self) -> u8 {
        u8::try_from(self.queue.len()).unwrap_or(u8::MAX)
    }
}
