//! How long a frame occupies the bus: exact bit counts of classic CAN frames, with the real
//! bit stuffing of the real CRC, for bus-load statistics, frame budgets and the simulator.
//!
//! Bit layout (ISO 11898-1, classic data/remote frame), counted from SOF to the end of the
//! 3-bit interframe space:
//! - standard: SOF 1, ID 11, RTR 1, IDE 1, r0 1, DLC 4, data 8·n, CRC 15, then CRC delimiter 1,
//!   ACK 2, EOF 7, IFS 3 → `47 + 8n` bits before stuffing (111 for n = 8);
//! - extended: SOF 1, base ID 11, SRR 1, IDE 1, ID extension 18, RTR 1, r1 1, r0 1, DLC 4,
//!   data 8·n, CRC 15, then the same 13 fixed bits → `67 + 8n` bits before stuffing.
//!
//! Stuffing applies from SOF to the end of the CRC: after five equal bits the transmitter
//! inserts one opposite bit, which itself counts towards the next run.

use super::CanFrame;
use embedded_can::Id;

/// Bits after the CRC that are never stuffed: CRC delimiter 1, ACK 2, EOF 7, IFS 3.
const UNSTUFFED_TAIL_BITS: u32 = 13;

/// Frame length in bits without stuffing (SOF to the end of the interframe space).
///
/// ```
/// use rc10_core::can::{CanFrame, timing};
/// assert_eq!(timing::unstuffed_bits(&CanFrame::standard(0x200, &[0; 8]).unwrap()), 111);
/// assert_eq!(timing::unstuffed_bits(&CanFrame::extended(0x901, &[0; 8]).unwrap()), 131);
/// ```
pub fn unstuffed_bits(frame: &CanFrame) -> u32 {
    let header = if frame.is_extended() { 67 } else { 47 };
    header + 8 * frame.data().len() as u32
}

/// The most bits a frame of this kind and length can take with worst-case stuffing.
///
/// ```
/// use rc10_core::can::timing;
/// assert_eq!(timing::worst_case_bits(false, 8), 135);
/// ```
pub fn worst_case_bits(extended: bool, data_len: usize) -> u32 {
    let n = data_len.min(8) as u32;
    let stuffable = if extended { 54 } else { 34 } + 8 * n;
    let base = if extended { 67 } else { 47 } + 8 * n;
    base + (stuffable - 1) / 4
}

/// The exact frame length in bits on the wire, including the stuff bits this frame's ID,
/// control field, data and CRC actually produce.
///
/// ```
/// use rc10_core::can::{CanFrame, timing};
/// let f = CanFrame::standard(0x200, &[0; 8]).unwrap();
/// let bits = timing::frame_bits(&f);
/// assert!(bits > 111 && bits <= 135); // zeros stuff heavily
/// ```
pub fn frame_bits(frame: &CanFrame) -> u32 {
    let mut w = StuffCounter::new();
    w.push(false); // SOF
    match frame.id() {
        Id::Standard(id) => {
            w.push_bits(u32::from(id.as_raw()), 11);
            w.push(frame.is_remote()); // RTR
            w.push(false); // IDE
            w.push(false); // r0
        }
        Id::Extended(id) => {
            let raw = id.as_raw();
            w.push_bits(raw >> 18, 11);
            w.push(true); // SRR
            w.push(true); // IDE
            w.push_bits(raw & 0x3_FFFF, 18);
            w.push(frame.is_remote()); // RTR
            w.push(false); // r1
            w.push(false); // r0
        }
    }
    w.push_bits(frame.dlc() as u32, 4);
    for &byte in frame.data() {
        w.push_bits(u32::from(byte), 8);
    }
    let crc = w.crc;
    w.crc_done = true; // the CRC field is stuffed but not part of its own checksum
    w.push_bits(u32::from(crc), 15);
    w.bits + UNSTUFFED_TAIL_BITS
}

/// Time a frame occupies the bus at `bitrate_bps`, in whole microseconds (rounded up).
pub fn frame_time_us(frame: &CanFrame, bitrate_bps: u32) -> u32 {
    let bits = u64::from(frame_bits(frame));
    let rate = u64::from(bitrate_bps.max(1));
    (bits * 1_000_000).div_ceil(rate) as u32
}

/// Counts bits including stuff bits while computing the CAN CRC-15 over the stuffed region.
struct StuffCounter {
    bits: u32,
    run_value: bool,
    run_len: u32,
    crc: u16,
    crc_done: bool,
}

impl StuffCounter {
    const fn new() -> Self {
        Self {
            bits: 0,
            run_value: false,
            run_len: 0,
            crc: 0,
            crc_done: false,
        }
    }

    fn push_bits(&mut self, value: u32, count: u32) {
        for i in (0..count).rev() {
            self.push((value >> i) & 1 == 1);
        }
    }

    fn push(&mut self, bit: bool) {
        if !self.crc_done {
            // CRC-15/CAN, polynomial 0x4599, over SOF..data (destuffed bits).
            let feedback = bit ^ ((self.crc >> 14) & 1 == 1);
            self.crc = (self.crc << 1) & 0x7FFF;
            if feedback {
                self.crc ^= 0x4599;
            }
        }
        self.emit(bit);
        if self.run_len == 5 {
            self.emit(!bit); // stuff bit
        }
    }

    fn emit(&mut self, bit: bool) {
        self.bits += 1;
        if self.run_len > 0 && bit == self.run_value {
            self.run_len += 1;
        } else {
            self.run_value = bit;
            self.run_len = 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn worst_case_matches_spec_figures() {
        // SPEC.md: an 8-byte standard frame takes 111 µs, 135 µs with worst-case stuffing.
        assert_eq!(worst_case_bits(false, 8), 135);
        assert_eq!(
            unstuffed_bits(&CanFrame::standard(0x1, &[0; 8]).unwrap()),
            111
        );
    }

    #[test]
    fn exact_bits_never_exceed_worst_case() {
        for id in [0x000u16, 0x200, 0x1FF, 0x7FF, 0x555] {
            for pattern in [0x00u8, 0xFF, 0xAA, 0x0F, 0xF0] {
                let f = CanFrame::standard(id, &[pattern; 8]).unwrap();
                let bits = frame_bits(&f);
                assert!(
                    bits >= 111 && bits <= worst_case_bits(false, 8),
                    "{id:#x} {pattern:#x}: {bits}"
                );
            }
        }
    }

    #[test]
    fn all_zero_frame_counts_hand_worked_stuff_bits() {
        // Standard ID 0x000, DLC 0: SOF..DLC are 19 zero bits and their CRC-15 (init 0) is 0,
        // so the stuffed region is 34 zeros. A stuff bit (a one) follows every fifth zero and
        // breaks the run: 34 = 6·5 + 4 → 6 stuff bits. 34 + 6 + 13 fixed tail bits = 53.
        let f = CanFrame::standard(0x000, &[]).unwrap();
        assert_eq!(frame_bits(&f), 53);
    }

    #[test]
    fn extended_frame_is_longer_than_standard() {
        let s = CanFrame::standard(0x7F, &[0x12; 8]).unwrap();
        let e = CanFrame::extended(0x7F, &[0x12; 8]).unwrap();
        assert!(frame_bits(&e) >= 131 && frame_bits(&e) <= worst_case_bits(true, 8));
        assert!(frame_bits(&e) > frame_bits(&s));
    }

    #[test]
    fn alternating_payload_has_few_stuff_bits() {
        let f = CanFrame::standard(0x555, &[0x55; 8]).unwrap();
        // Alternating data cannot form runs of five: only the header/CRC may stuff.
        assert!(frame_bits(&f) <= 111 + 4, "{}", frame_bits(&f));
    }

    #[test]
    fn frame_time_at_1_mbit_is_bits_in_us() {
        let f =
            CanFrame::standard(0x201, &[0x12, 0x34, 0x56, 0x78, 0x9A, 0xBC, 0xDE, 0xF0]).unwrap();
        assert_eq!(frame_time_us(&f, 1_000_000), frame_bits(&f));
        assert_eq!(frame_time_us(&f, 500_000), 2 * frame_bits(&f));
    }
}
