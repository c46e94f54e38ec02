//! The controller's receive side as an STM32G4 FDCAN has it: acceptance filters, two 3-deep
//! RX FIFOs with their message-lost flags, read as rc10-stm32's receiver reads them.

use rc10_core::can::CanFrame;
use rc10_core::can::acceptance::{Fifo, FilterPlan, PlanError};
use rc10_core::node::BusUsage;
use std::collections::VecDeque;

/// Frames each RX FIFO holds (RM0440: two FIFOs of up to 3 elements in the G4's fixed
/// message RAM).
pub(super) const RX_FIFO_DEPTH: usize = 3;

/// The G4's filter elements: 28 standard-ID and 8 extended-ID ones.
type G4Plan = FilterPlan<28, 8>;

/// Where a received frame went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Stored {
    /// Into a FIFO, to be read when the receive path runs.
    Queued,
    /// Its FIFO was full: the frame is lost and the FIFO's message-lost flag set (the FIFOs
    /// run in blocking mode, the reset default: the newest frame is the one lost).
    Lost,
    /// No filter element accepts its ID: the hardware discards it and nobody hears of it.
    Rejected,
}

/// What the receive path reads when it runs again after a stall.
#[derive(Debug, Default)]
pub(super) struct Drained {
    /// Whether a FIFO lost frames: the receiver reports one overrun for any number of lost
    /// frames in either FIFO (it reads and clears both flags at once).
    pub overrun: bool,
    /// The stored frames in the order the receiver reads them: FIFO 0 until it is empty,
    /// then FIFO 1 (embassy-stm32 reads FIFO 0 first).
    pub frames: Vec<CanFrame>,
}

/// The acceptance filters and the two RX FIFOs of one controller.
#[derive(Debug)]
pub(super) struct RxPath {
    plan: G4Plan,
    fifos: [VecDeque<CanFrame>; 2],
    lost: [bool; 2],
}

impl RxPath {
    /// The filters rc10-stm32 programs for nodes with these declarations (in registration
    /// order), or why they do not fit the G4's filter elements (the board could not start).
    pub(super) fn new(usages: impl Iterator<Item = BusUsage>) -> Result<Self, PlanError> {
        Ok(Self {
            plan: G4Plan::new(usages)?,
            fifos: Default::default(),
            lost: [false; 2],
        })
    }

    /// Whether the filters pass a frame with this ID (into either FIFO).
    pub(super) fn accepts(&self, frame: &CanFrame) -> bool {
        self.fifo_of(frame).is_some()
    }

    fn fifo_of(&self, frame: &CanFrame) -> Option<usize> {
        self.plan
            .fifo_of(frame.raw_id(), frame.is_extended())
            .map(|fifo| match fifo {
                Fifo::Fifo0 => 0,
                Fifo::Fifo1 => 1,
            })
    }

    /// Stores a frame that arrived while the receive path is stalled.
    pub(super) fn store(&mut self, frame: CanFrame) -> Stored {
        let Some(f) = self.fifo_of(&frame) else {
            return Stored::Rejected;
        };
        let (Some(fifo), Some(lost)) = (self.fifos.get_mut(f), self.lost.get_mut(f)) else {
            return Stored::Rejected; // f is 0 or 1: unreachable
        };
        if fifo.len() < RX_FIFO_DEPTH {
            fifo.push_back(frame);
            Stored::Queued
        } else {
            *lost = true;
            Stored::Lost
        }
    }

    /// Everything the receive path reads when it runs again, leaving the FIFOs empty and
    /// the flags clear. `None` when there is nothing to read (the usual case).
    pub(super) fn drain(&mut self) -> Option<Drained> {
        let overrun = self.lost.contains(&true);
        if !overrun && self.fifos.iter().all(VecDeque::is_empty) {
            return None;
        }
        self.lost = [false; 2];
        let frames = self.fifos.iter_mut().flat_map(|f| f.drain(..)).collect();
        Some(Drained { overrun, frames })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rc10_core::motor::dji::DjiMotor;
    use rc10_core::node::CanNode;

    fn feedback(id: u16) -> CanFrame {
        CanFrame::standard(id, &[0; 8]).unwrap()
    }

    /// Four M3508s (feedback 0x201–0x204): the plan puts 0x201 and 0x203 in FIFO 0,
    /// 0x202 and 0x204 in FIFO 1 (alternating, as their rates are equal).
    fn four_wheels() -> RxPath {
        let wheels: Vec<DjiMotor> = (1..=4).map(|i| DjiMotor::m3508(i).unwrap()).collect();
        RxPath::new(wheels.iter().map(|w| w.bus_usage())).unwrap()
    }

    #[test]
    fn each_fifo_holds_three_frames_and_loses_the_newest() {
        let mut rx = four_wheels();
        let frame = |id: u16, round: u8| CanFrame::standard(id, &[round; 8]).unwrap();
        // Round 0: all four, two in each FIFO. Round 1: 0x201 and 0x202 fill their FIFOs to
        // 3; 0x203 and 0x204 find them full.
        for id in 0x201..=0x204 {
            assert_eq!(rx.store(frame(id, 0)), Stored::Queued, "{id:#x}");
        }
        for (id, expected) in [
            (0x201, Stored::Queued),
            (0x202, Stored::Queued),
            (0x203, Stored::Lost),
            (0x204, Stored::Lost),
        ] {
            assert_eq!(rx.store(frame(id, 1)), expected, "{id:#x}");
        }
        let drained = rx.drain().unwrap();
        assert!(drained.overrun);
        // FIFO 0 first, oldest first, then FIFO 1.
        let expected = [
            (0x201, 0),
            (0x203, 0),
            (0x201, 1),
            (0x202, 0),
            (0x204, 0),
            (0x202, 1),
        ];
        assert_eq!(
            drained.frames,
            expected.map(|(id, round)| frame(id, round)).to_vec()
        );
        // Read and cleared: nothing more, no second overrun.
        assert!(rx.drain().is_none());
    }

    #[test]
    fn one_full_fifo_loses_frames_while_the_other_still_stores() {
        let mut rx = four_wheels();
        for _ in 0..3 {
            assert_eq!(rx.store(feedback(0x201)), Stored::Queued);
        }
        // 0x203 shares FIFO 0 with 0x201; 0x202 is in FIFO 1.
        assert_eq!(rx.store(feedback(0x203)), Stored::Lost);
        assert_eq!(rx.store(feedback(0x202)), Stored::Queued);
        let drained = rx.drain().unwrap();
        assert!(drained.overrun);
        assert_eq!(drained.frames.len(), 4);
    }

    #[test]
    fn frames_no_filter_accepts_are_discarded_without_an_overrun() {
        let mut rx = four_wheels();
        // A command frame and a GM6020's feedback ID: no element for them.
        for id in [0x200, 0x205] {
            assert!(!rx.accepts(&feedback(id)));
            assert_eq!(rx.store(feedback(id)), Stored::Rejected);
        }
        assert!(rx.accepts(&feedback(0x204)));
        assert!(rx.drain().is_none());
    }

    #[test]
    fn stored_frames_without_a_loss_drain_without_an_overrun() {
        let mut rx = four_wheels();
        assert_eq!(rx.store(feedback(0x202)), Stored::Queued);
        let drained = rx.drain().unwrap();
        assert!(!drained.overrun);
        assert_eq!(drained.frames, vec![feedback(0x202)]);
    }
}
