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
#[allow(
    clippy::arithmetic_side_effects,
    reason = "a classic frame has at most 8 data bytes: at most 131 bits"
)]
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
#[allow(
    clippy::arithmetic_side_effects,
    reason = "n ≤ 8 data bytes: every value is at most 160"
)]
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
#[allow(
    clippy::arithmetic_side_effects,
    reason = "at most 118 stuffable bits, 29 stuff bits and 13 tail bits"
)]
pub fn frame_bits(frame: &CanFrame) -> u32 {
    // The whole stuffed region (at most 103 bits + 15 CRC bits) as one MSB-first bit string.
    let mut bits = BitString::default();
    bits.push(0, 1); // SOF
    match frame.id() {
        Id::Standard(id) => {
            bits.push(u32::from(id.as_raw()), 11);
            bits.push(u32::from(frame.is_remote()), 1); // RTR
            bits.push(0, 2); // IDE, r0
        }
        Id::Extended(id) => {
            let raw = id.as_raw();
            bits.push(raw >> 18, 11);
            bits.push(0b11, 2); // SRR, IDE
            bits.push(raw & 0x3_FFFF, 18);
            bits.push(u32::from(frame.is_remote()), 1); // RTR
            bits.push(0, 2); // r1, r0
        }
    }
    bits.push(frame.dlc() as u32, 4);
    for &byte in frame.data() {
        bits.push(u32::from(byte), 8);
    }
    let crc = bits.crc15();
    bits.push(u32::from(crc), 15);
    bits.len + bits.stuff_bits() + UNSTUFFED_TAIL_BITS
}

/// Time a frame occupies the bus at `bitrate_bps`, in whole microseconds (rounded up).
pub fn frame_time_us(frame: &CanFrame, bitrate_bps: u32) -> u32 {
    let bits = u64::from(frame_bits(frame));
    let rate = u64::from(bitrate_bps.max(1));
    (bits * 1_000_000).div_ceil(rate) as u32
}

/// Up to 128 bits, MSB-first: bit `i` of the frame is bit `127 - i` of `bits`.
#[derive(Default)]
struct BitString {
    bits: u128,
    len: u32,
}

impl BitString {
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "frame_bits pushes at most 118 bits in all: len + count ≤ 128"
    )]
    fn push(&mut self, value: u32, count: u32) {
        let v = u128::from(value) & ((1u128 << count) - 1);
        self.bits |= v << (128 - self.len - count);
        self.len += count;
    }

    /// The byte starting at bit `at` (bits past the end read as 0).
    fn byte_at(&self, at: u32) -> u8 {
        (self.bits << at >> 120) as u8
    }

    /// Bit `at` (< 128).
    fn bit(&self, at: u32) -> bool {
        self.bits << at >> 127 == 1
    }

    /// The positions of the whole bytes, then of the bits after them.
    fn bytes_then_bits(&self) -> (impl Iterator<Item = u32>, core::ops::Range<u32>) {
        let whole = self.len & !7;
        ((0..whole).step_by(8), whole..self.len)
    }

    /// CRC-15/CAN (polynomial 0x4599, initial 0) of all bits pushed so far.
    fn crc15(&self) -> u16 {
        let (bytes, bits) = self.bytes_then_bits();
        let crc = bytes.fold(0u16, |crc, at| {
            let index = usize::from(((crc >> 7) as u8) ^ self.byte_at(at));
            let entry = CRC15_TABLE.get(index).copied().unwrap_or(0); // index < 256 always
            ((crc << 8) ^ entry) & 0x7FFF
        });
        bits.fold(crc, |crc, at| crc15_bit(crc, self.bit(at)))
    }

    /// Stuff bits the transmitter inserts into these bits.
    fn stuff_bits(&self) -> u32 {
        let (bytes, bits) = self.bytes_then_bits();
        let mut state = STUFF_START;
        let mut stuffed = 0u32; // at most 29
        for at in bytes {
            // state < 16 and byte < 256 always.
            let entry = STUFF_TABLE
                .get(usize::from(state))
                .and_then(|row| row.get(usize::from(self.byte_at(at))))
                .copied()
                .unwrap_or(0);
            state = entry & 0x0F;
            stuffed = stuffed.saturating_add(u32::from(entry >> 4));
        }
        for at in bits {
            let (next, stuff) = stuff_bit(state, self.bit(at));
            state = next;
            stuffed = stuffed.saturating_add(u32::from(stuff));
        }
        stuffed
    }
}

/// One bit of CRC-15/CAN.
const fn crc15_bit(crc: u16, bit: bool) -> u16 {
    let feedback = bit ^ ((crc >> 14) & 1 == 1);
    let shifted = (crc << 1) & 0x7FFF;
    if feedback { shifted ^ 0x4599 } else { shifted }
}

/// CRC-15/CAN of each byte fed MSB-first into a register holding that byte in its top bits.
// Built at compile time: an out-of-bounds index would fail the build, not panic at run time.
#[allow(clippy::indexing_slicing)]
const CRC15_TABLE: [u16; 256] = {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = (i as u16) << 7;
        let mut k = 0;
        while k < 8 {
            // The byte already sits in the register: shift through eight zero bits.
            crc = crc15_bit(crc & 0x7FFF, false);
            k += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
};

/// Stuffing state: `run value << 3 | run length (1–5)`; `STUFF_START` before the first bit.
const STUFF_START: u8 = 0;

/// Emits one bit; returns the new state and whether a stuff bit followed it.
#[allow(
    clippy::arithmetic_side_effects,
    reason = "run_len = state & 7 is at most 7"
)]
const fn stuff_bit(state: u8, bit: bool) -> (u8, bool) {
    let run_value = state >> 3 == 1;
    let run_len = state & 0x7;
    let len = if run_len > 0 && bit == run_value {
        run_len + 1
    } else {
        1
    };
    if len == 5 {
        // The stuff bit (opposite value) starts a new run of length 1.
        (((!bit) as u8) << 3 | 1, true)
    } else {
        ((bit as u8) << 3 | len, false)
    }
}

/// For each state and byte: `stuff bits << 4 | new state`.
// Built at compile time: an out-of-bounds index would fail the build, not panic at run time.
#[allow(clippy::indexing_slicing)]
const STUFF_TABLE: [[u8; 256]; 16] = {
    let mut table = [[0u8; 256]; 16];
    let mut state = 0;
    while state < 16 {
        let mut byte = 0;
        while byte < 256 {
            let mut s = state as u8;
            let mut stuffed = 0u8;
            let mut k = 0;
            while k < 8 {
                let (next, stuff) = stuff_bit(s, (byte >> (7 - k)) & 1 == 1);
                s = next;
                stuffed += stuff as u8;
                k += 1;
            }
            table[state][byte] = stuffed << 4 | s;
            byte += 1;
        }
        state += 1;
    }
    table
};

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Bit-by-bit reference: CRC and stuffing computed one bit at a time.
    fn reference_bits(frame: &CanFrame) -> u32 {
        fn push_to(stream: &mut Vec<bool>, v: u32, n: u32) {
            (0..n).rev().for_each(|i| stream.push((v >> i) & 1 == 1));
        }
        let mut stream: Vec<bool> = Vec::new();
        let mut push = |v: u32, n: u32| push_to(&mut stream, v, n);
        push(0, 1);
        match frame.id() {
            Id::Standard(id) => {
                push(u32::from(id.as_raw()), 11);
                push(u32::from(frame.is_remote()), 1);
                push(0, 2);
            }
            Id::Extended(id) => {
                push(id.as_raw() >> 18, 11);
                push(3, 2);
                push(id.as_raw() & 0x3_FFFF, 18);
                push(u32::from(frame.is_remote()), 1);
                push(0, 2);
            }
        }
        push(frame.dlc() as u32, 4);
        frame.data().iter().for_each(|b| push(u32::from(*b), 8));
        let crc = stream.iter().fold(0u16, |c, b| crc15_bit(c, *b));
        push_to(&mut stream, u32::from(crc), 15);
        let (mut state, mut stuffed) = (STUFF_START, 0);
        for b in &stream {
            let (s, x) = stuff_bit(state, *b);
            state = s;
            stuffed += u32::from(x);
        }
        stream.len() as u32 + stuffed + 13
    }

    proptest! {
        #[test]
        fn table_driven_bits_equal_bit_by_bit_reference(
            id in 0u32..0x2000_0000, extended: bool, data in proptest::collection::vec(any::<u8>(), 0..=8),
        ) {
            let f = if extended {
                CanFrame::extended(id, &data).unwrap()
            } else {
                CanFrame::standard((id & 0x7FF) as u16, &data).unwrap()
            };
            prop_assert_eq!(frame_bits(&f), reference_bits(&f));
        }
    }

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
