//! CAN building blocks at the edges mutation testing found unpinned: ID kinds in filters and
//! acceptance elements, the embedded-can `Frame` view of a frame, the loopback queue's
//! length, and per-second rates from counters.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use rc10_core::can::acceptance::{Fifo, FilterElement};
use rc10_core::can::loopback::TxQueue;
use rc10_core::can::{BusCounters, CanFrame, CanTransmit, ExtendedId, Id, IdFilter, StandardId};
use rc10_core::time::Duration;

#[test]
fn filters_never_match_the_other_id_kind() {
    let std_201 = Id::Standard(StandardId::new(0x201).unwrap());
    let ext_201 = Id::Extended(ExtendedId::new(0x201).unwrap());
    assert!(IdFilter::standard(0x201).matches(std_201));
    assert!(!IdFilter::standard(0x201).matches(ext_201));
    assert!(IdFilter::extended(0x201).matches(ext_201));
    assert!(!IdFilter::extended(0x201).matches(std_201));
}

#[test]
fn acceptance_mask_elements_check_the_id_kind() {
    let mask = FilterElement::Mask {
        id: 0x200,
        mask: 0x7F0,
        extended: false,
        fifo: Fifo::Fifo0,
    };
    assert!(mask.accepts(0x205, false));
    assert!(!mask.accepts(0x205, true)); // same bits, extended: not this element's kind
    assert!(!mask.accepts(0x305, false));
    let dual = FilterElement::Dual {
        ids: [0x901, 0x902],
        extended: true,
        fifo: Fifo::Fifo1,
    };
    assert!(dual.accepts(0x902, true));
    assert!(!dual.accepts(0x902, false));
}

#[test]
fn embedded_can_frame_view_agrees_with_the_frame() {
    use embedded_can::Frame as _;
    let data = CanFrame::extended(0x1234, &[1, 2, 3]).unwrap();
    assert!(embedded_can::Frame::is_extended(&data));
    assert!(!data.is_remote_frame());
    assert_eq!(embedded_can::Frame::dlc(&data), 3);
    let remote: CanFrame =
        embedded_can::Frame::new_remote(embedded_can::StandardId::new(0x200).unwrap(), 5).unwrap();
    assert!(!embedded_can::Frame::is_extended(&remote));
    assert!(remote.is_remote_frame());
    assert_eq!(embedded_can::Frame::dlc(&remote), 5);
}

#[test]
fn loopback_queue_reports_its_length() {
    let mut tx: TxQueue<3> = TxQueue::new();
    assert!(tx.is_empty());
    assert_eq!(tx.len(), 0);
    let f = CanFrame::standard(0x200, &[0; 8]).unwrap();
    tx.try_send(&f).unwrap();
    tx.try_send(&f).unwrap();
    assert!(!tx.is_empty());
    assert_eq!(tx.len(), 2);
    tx.pop();
    assert_eq!(tx.len(), 1);
}

#[test]
fn rates_divide_counts_by_the_interval() {
    // Over 2 s: 2000 frames received, 1000 sent, 10 dropped; 1e6 bits at 1 Mbit/s = 50 %.
    let c = BusCounters {
        rx_frames: 2000,
        tx_frames: 1000,
        tx_full: 10,
        rx_bits: 600_000,
        tx_bits: 400_000,
        ..BusCounters::default()
    };
    let r = c.rates(Duration::from_secs(2), 1_000_000);
    assert!((r.rx_frames_per_s - 1000.0).abs() < 1e-3, "{r:?}");
    assert!((r.tx_frames_per_s - 500.0).abs() < 1e-3, "{r:?}");
    assert!((r.tx_dropped_per_s - 5.0).abs() < 1e-4, "{r:?}");
    assert!((r.load_percent - 50.0).abs() < 1e-3, "{r:?}");
}

/// A transport that implements only `try_send` (it can tell nothing else).
struct Plain(u32);

impl CanTransmit for Plain {
    fn try_send(&mut self, _frame: &CanFrame) -> Result<(), rc10_core::can::SendError> {
        self.0 += 1;
        Ok(())
    }
}

#[test]
fn a_transport_that_cannot_tell_reports_nothing_queued_and_error_active() {
    let t = Plain(0);
    assert_eq!(t.still_queued(), 0);
    assert_eq!(t.status(), rc10_core::can::BusStatus::default());
    assert_eq!(t.status().state, rc10_core::can::ErrorState::Active);
}

#[test]
fn a_borrowed_transport_forwards_everything() {
    use rc10_core::can::SendError;
    fn via<T: CanTransmit>(mut tx: T, f: &CanFrame) -> (Result<(), SendError>, u8) {
        (tx.try_send(f), tx.still_queued())
    }
    let mut q: TxQueue<1> = TxQueue::new();
    let f = CanFrame::standard(0x200, &[0; 8]).unwrap();
    assert_eq!(via(&mut q, &f), (Ok(()), 1));
    assert_eq!(via(&mut q, &f), (Err(SendError::Full), 1));
    assert_eq!(q.len(), 1);
}
