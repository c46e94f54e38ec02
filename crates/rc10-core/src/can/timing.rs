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

/// An upper bound on the bits a frame of this kind and length takes: one stuff bit for
/// every four bits after the first of the stuffed region (the textbook worst case, which
/// real frames do not reach: the CRC depends on the data; [`frame_bits`] is exact).
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
/// // 111 bits before stuffing; zeros stuff heavily: 15 stuff bits.
/// assert_eq!(timing::frame_bits(&f), 126);
/// ```
#[allow(
    clippy::arithmetic_side_effects,
    reason = "at most 118 stuffable bits: every shift is below 128, every sum below 160"
)]
pub fn frame_bits(frame: &CanFrame) -> u32 {
    // SOF to DLC, right-aligned in a word (the SOF bit is the top one and is 0).
    let rtr = u64::from(frame.is_remote());
    let dlc = frame.dlc() as u64;
    let (header, header_len) = match frame.id() {
        // SOF, ID 11, RTR, IDE = 0, r0, DLC 4.
        Id::Standard(id) => ((u64::from(id.as_raw()) << 7) | (rtr << 6) | dlc, 19),
        Id::Extended(id) => {
            // SOF, base ID 11, SRR = 1, IDE = 1, ID extension 18, RTR, r1, r0, DLC 4.
            let raw = u64::from(id.as_raw());
            let (base, extension) = (raw >> 18, raw & 0x3_FFFF);
            let fields = (base << 27) | (0b11 << 25) | (extension << 7) | (rtr << 6) | dlc;
            (fields, 39)
        }
    };
    let data = frame.data();
    // SOF to the end of the data, right-aligned: at most 39 + 64 = 103 bits.
    let data_bits = 8 * data.len() as u32;
    let data_word = u128::from(frame.data_word());
    let message = (u128::from(header) << data_bits) | data_word;
    let crc = crc15(message);
    // The stuffed region, SOF to the end of the CRC, left-aligned (frame bit i is word bit
    // 127 − i) and padded so that it can be stuffed a byte at a time.
    let len = header_len + data_bits + 15;
    let stream = (message << 15) | u128::from(crc);
    let padded = (stream << (128 - len)) | neutral_padding(stream & 1 == 1, 128 - len);
    // A standard frame's stuffed region is at most 19 + 64 + 15 = 98 bits: its first 13
    // bytes; an extended one's at most 118 bits: 15 bytes. The padding after it adds no
    // stuff bits, so the walk stops there (a fixed count, unrolled).
    let stuffed = if header_len == 19 {
        stuff_bits::<13>(padded)
    } else {
        stuff_bits::<15>(padded)
    };
    len + stuffed + UNSTUFFED_TAIL_BITS
}

/// A controller's nominal bit timing: the CAN clock divided by `prescaler` gives the time
/// quantum; a bit is 1 (sync) + `seg1` (propagation and phase 1) + `seg2` (phase 2) quanta,
/// sampled after `1 + seg1` of them; a node resynchronises by up to `sync_jump_width` quanta
/// per edge. The fields are counts, not register values (the FDCAN's `NBTP` holds each minus
/// one).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BitTiming {
    /// Clock cycles per time quantum, 1–511 from [`bit_timing`] (the FDCAN takes 512, which
    /// embassy-stm32 0.6 cannot write).
    pub prescaler: u16,
    /// Quanta before the sample point, after the sync quantum, 2–255.
    pub seg1: u8,
    /// Quanta after the sample point, 2–128 (the controller needs 2 to process the sampled
    /// bit).
    pub seg2: u8,
    /// Resynchronisation jump width in quanta, 1–128, at most `seg2`.
    pub sync_jump_width: u8,
}

impl BitTiming {
    /// Quanta per bit.
    #[allow(clippy::arithmetic_side_effects, reason = "u8 + u8 + 1 fits a u32")]
    pub fn quanta_per_bit(&self) -> u32 {
        1 + u32::from(self.seg1) + u32::from(self.seg2)
    }

    /// The sample point in per mille of the bit time (rounded down).
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "at most 1000 · 256; quanta_per_bit ≥ 1"
    )]
    pub fn sample_point_permille(&self) -> u32 {
        1000 * (1 + u32::from(self.seg1)) / self.quanta_per_bit()
    }

    /// The bitrate this timing gives from a `clock_hz` CAN clock, in bit/s (rounded down).
    pub fn bitrate_bps(&self, clock_hz: u32) -> u32 {
        let cycles = u64::from(self.prescaler).saturating_mul(u64::from(self.quanta_per_bit()));
        u64::from(clock_hz)
            .checked_div(cycles)
            .and_then(|b| u32::try_from(b).ok())
            .unwrap_or(0)
    }
}

/// The nominal bit timing for `bitrate_bps` from a `clock_hz` CAN clock, exact (no bitrate
/// error), or `None` when no prescaler up to 511 gives 8–25 quanta per bit exactly.
///
/// The sample point is put nearest 80 % from 800 kbit/s up and 87.5 % below (CiA 301
/// recommends 75 % at 1 Mbit/s and 87.5 % up to 500 kbit/s; DJI's RoboMaster boards sample
/// at 78.6 % at 1 Mbit/s), at the finest quantum among equally close choices (and the
/// earlier of two equally close sample points, for the longer phase 2), and the
/// resynchronisation jump width is all of phase 2, for the widest tolerance of clock error
/// between nodes. At 1 Mbit/s from the G4's 170 MHz: 10 quanta of 17 cycles, sampled at
/// 80 %, jump width 2 (each node may be 0.78 % off); embassy-stm32's own choice samples at
/// 90 % with a jump width of 1 (0.39 %).
///
/// ```
/// use rc10_core::can::timing::{bit_timing, BitTiming};
/// let t = bit_timing(170_000_000, 1_000_000).unwrap();
/// assert_eq!(t, BitTiming { prescaler: 17, seg1: 7, seg2: 2, sync_jump_width: 2 });
/// assert_eq!(t.sample_point_permille(), 800);
/// assert_eq!(t.bitrate_bps(170_000_000), 1_000_000);
/// ```
pub fn bit_timing(clock_hz: u32, bitrate_bps: u32) -> Option<BitTiming> {
    let target_permille: u32 = if bitrate_bps >= 800_000 { 800 } else { 875 };
    // (distance from the target in per mille · quanta, quanta, timing): compared by
    // cross-multiplying, so no rounding decides between two quantum counts.
    let mut best: Option<(u64, u32, BitTiming)> = None;
    for quanta in MIN_QUANTA..=MAX_QUANTA {
        let Some(cycles_per_bit) = bitrate_bps.checked_mul(quanta) else {
            continue;
        };
        // A whole number of clock cycles per quantum (none for a zero bitrate).
        if clock_hz.checked_rem(cycles_per_bit) != Some(0) {
            continue;
        }
        let Some(prescaler) = clock_hz
            .checked_div(cycles_per_bit)
            .and_then(|p| u16::try_from(p).ok())
            .filter(|p| (1..=511).contains(p))
        else {
            continue;
        };
        // Quanta up to the sample point (sync + seg1), either side of the target, but at
        // least 3 (seg1 ≥ 2) and leaving seg2 ≥ 2 (the distance only grows further out, so
        // the nearest allowed count is the best one).
        let ideal_milli = quanta.saturating_mul(target_permille); // ≤ 25 · 875
        let last = quanta.saturating_sub(2);
        let below = (ideal_milli / 1000).max(3).min(last);
        for upto in [below, below.saturating_add(1).min(last)] {
            // At least 2 (`upto ≤ last`): the controller's processing time after sampling.
            let seg2 = quanta.saturating_sub(upto);
            let (Ok(seg1), Ok(seg2)) = (u8::try_from(upto.saturating_sub(1)), u8::try_from(seg2))
            else {
                continue;
            };
            // |upto/quanta − target/1000|, scaled by 1000 · quanta.
            let distance = u64::from(upto.saturating_mul(1000).abs_diff(ideal_milli));
            let timing = BitTiming {
                prescaler,
                seg1,
                seg2,
                sync_jump_width: seg2,
            };
            // distance / quanta compared across quantum counts: d₁ · q₂ vs d₂ · q₁.
            let better = match best {
                None => true,
                Some((d, q, _)) => {
                    let (mine, theirs) = (
                        distance.saturating_mul(u64::from(q)),
                        d.saturating_mul(u64::from(quanta)),
                    );
                    mine < theirs || (mine == theirs && quanta > q)
                }
            };
            if better {
                best = Some((distance, quanta, timing));
            }
        }
    }
    best.map(|(_, _, t)| t)
}

/// Fewest quanta per bit [`bit_timing`] uses: coarser puts the sample point too far off.
const MIN_QUANTA: u32 = 8;
/// Most quanta per bit [`bit_timing`] uses (CAN controllers' usual range ends near 25).
const MAX_QUANTA: u32 = 25;

/// Time a frame occupies the bus at `bitrate_bps`, in whole microseconds (rounded up).
pub fn frame_time_us(frame: &CanFrame, bitrate_bps: u32) -> u32 {
    let bits = frame_bits(frame);
    if bitrate_bps == 1_000_000 {
        // One bit per microsecond (the usual rate): no division.
        return bits;
    }
    let bits = u64::from(bits);
    let rate = u64::from(bitrate_bps.max(1));
    (bits * 1_000_000).div_ceil(rate) as u32
}

/// CRC-15/CAN (polynomial 0x4599, initial 0) of a message of up to 104 bits, right-aligned
/// in `message` and fed MSB first.
///
/// From 0, leading zero bits leave the CRC at 0, so the message's length does not matter, and
/// the CRC is linear: it is the XOR of each byte's own CRC followed by as many zero bytes as
/// come after it. All 13 table lookups are independent of each other.
fn crc15(message: u128) -> u16 {
    message
        .to_le_bytes()
        .iter()
        .zip(&CRC15_BY_DISTANCE)
        // A u8 index into a 256-entry table: always present.
        .fold(0, |crc, (&byte, table)| {
            crc ^ table.get(usize::from(byte)).copied().unwrap_or(0)
        })
}

/// The low `count` (10–94) bits of a word whose bits alternate, starting just below a last
/// bit of value `last`: appended after a bit string, they add no stuff bits (each forms a
/// run of 1, or of 2 with a stuff bit that ended the string), so the string can be stuffed in
/// whole bytes.
#[allow(
    clippy::arithmetic_side_effects,
    reason = "count is between 10 and 94: both shifts stay below 128"
)]
fn neutral_padding(last: bool, count: u32) -> u128 {
    const ALTERNATING: u128 = 0x5555_5555_5555_5555_5555_5555_5555_5555; // bit 0 set
    // The pattern whose top padding bit (bit count − 1) is the opposite of `last`.
    let top_set = (ALTERNATING >> (count - 1)) & 1 == 1;
    let pattern = if top_set == last {
        !ALTERNATING
    } else {
        ALTERNATING
    };
    pattern & ((1u128 << count) - 1)
}

/// Stuff bits a transmitter inserts into the first `BYTES` bytes of these 128 bits, sent
/// MSB first.
fn stuff_bits<const BYTES: usize>(bits: u128) -> u32 {
    let mut state = STUFF_START;
    let mut stuffed = 0u32;
    for &byte in bits.to_be_bytes().iter().take(BYTES) {
        // A u8 row index into 256 rows, and a state masked below 16 into 16 columns: always
        // present (the bounds checks fold away). The next state is the only value carried
        // from byte to byte: one load and a mask.
        let entry = STUFF
            .get(usize::from(byte))
            .and_then(|row| row.get(usize::from(state & STUFF_STATE_MASK)))
            .copied()
            .unwrap_or(0);
        state = entry & STUFF_STATE_MASK;
        // At most 2 per byte, 30 in all: no overflow.
        stuffed = stuffed.wrapping_add(u32::from(entry >> 4));
    }
    stuffed
}

/// One bit of CRC-15/CAN.
const fn crc15_bit(crc: u16, bit: bool) -> u16 {
    let feedback = bit ^ ((crc >> 14) & 1 == 1);
    let shifted = (crc << 1) & 0x7FFF;
    if feedback { shifted ^ 0x4599 } else { shifted }
}

/// Entry `[d][x]`: CRC-15/CAN, from 0, of byte `x` followed by `d` zero bytes.
// Built at compile time: an out-of-bounds index would fail the build, not panic at run time.
#[allow(clippy::indexing_slicing)]
const CRC15_BY_DISTANCE: [[u16; 256]; 13] = {
    let mut table = [[0u16; 256]; 13];
    let mut byte = 0;
    while byte < 256 {
        let mut crc = 0u16;
        let mut k = 0;
        while k < 8 {
            crc = crc15_bit(crc, (byte >> (7 - k)) & 1 == 1);
            k += 1;
        }
        let mut distance = 0;
        while distance < 13 {
            table[distance][byte] = crc;
            let mut k = 0;
            while k < 8 {
                crc = crc15_bit(crc, false);
                k += 1;
            }
            distance += 1;
        }
        byte += 1;
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

/// The stuffing of one byte from `state`: `(state after it, stuff bits inserted)`.
#[allow(
    clippy::arithmetic_side_effects,
    reason = "k < 8 and at most 8 stuff bits: no overflow"
)]
const fn stuff_byte(state: u8, byte: u8) -> (u8, u8) {
    let (mut s, mut stuffed, mut k) = (state, 0u8, 0);
    while k < 8 {
        let (next, stuff) = stuff_bit(s, (byte >> (7 - k)) & 1 == 1);
        s = next;
        stuffed += stuff as u8;
        k += 1;
    }
    (s, stuffed)
}

/// The low four bits of a [`STUFF`] entry: the state after the byte.
const STUFF_STATE_MASK: u8 = 0xF;

/// For each byte and state: the state after the byte in the low four bits, and the stuff
/// bits inserted while sending it (0–2) in the high four. Indexed `[byte][state]` so that the
/// chain from one byte to the next is a single load (the row address does not depend on the
/// state).
// Built at compile time: an out-of-bounds index would fail the build, not panic at run time.
#[allow(clippy::indexing_slicing)]
const STUFF: [[u8; 16]; 256] = {
    let mut table = [[0u8; 16]; 256];
    let mut byte = 0;
    while byte < 256 {
        let mut state = 0;
        while state < 16 {
            let (next, count) = stuff_byte(state as u8, byte as u8);
            table[byte][state] = count << 4 | next;
            state += 1;
        }
        byte += 1;
    }
    table
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bit_timings_for_the_clocks_robots_use() {
        let t = |p, s1, s2| BitTiming {
            prescaler: p,
            seg1: s1,
            seg2: s2,
            sync_jump_width: s2,
        };
        // G4 at 170 MHz: 10 quanta of 17 cycles, 8/10 = 80 %.
        assert_eq!(bit_timing(170_000_000, 1_000_000), Some(t(17, 7, 2)));
        // 85 MHz = 5 · 17 MHz: only 17 quanta fit; 14/17 = 82.4 % beats 13/17 = 76.5 %.
        let half = bit_timing(85_000_000, 1_000_000).unwrap();
        assert_eq!(half, t(5, 13, 3));
        assert_eq!(half.sample_point_permille(), 823);
        // 160 MHz: 10 and 20 quanta both sample at exactly 80 %: the finer wins.
        assert_eq!(bit_timing(160_000_000, 1_000_000), Some(t(8, 15, 4)));
        // 48 MHz: 24 quanta, 19/24 = 79.2 % (16 quanta give 81.25 %, 12 give 83.3 %).
        assert_eq!(bit_timing(48_000_000, 1_000_000), Some(t(2, 18, 5)));
        // RoboMaster C board's 42 MHz CAN clock: 21 quanta, 17/21 = 81.0 %.
        assert_eq!(bit_timing(42_000_000, 1_000_000), Some(t(2, 16, 4)));
        // 500 kbit/s aims at 87.5 %: 15/17 = 88.2 % beats 9/10 and 18/20 (90 %).
        assert_eq!(bit_timing(170_000_000, 500_000), Some(t(20, 14, 2)));
        // 10 MHz at 500 kbit/s: 10 quanta (9/10 = 90 %) and 20 (17/20 = 85 % or 18/20 =
        // 90 %) all miss 87.5 % by 2.5 %: the finer quantum, and of its two the earlier
        // sample point, which leaves the longer phase 2 and jump width.
        assert_eq!(bit_timing(10_000_000, 500_000), Some(t(1, 16, 3)));
        // 20 MHz at 500 kbit/s: 7/8 = 87.5 % exactly would leave a phase 2 of one quantum,
        // too short for the controller; 17/20 (85 %, phase 2 of 3) instead.
        assert_eq!(bit_timing(20_000_000, 500_000), Some(t(2, 16, 3)));
        // 250 kbit/s from 170 MHz: 8 quanta at 87.5 % the same; 15/17 = 88.2 %.
        assert_eq!(bit_timing(170_000_000, 250_000), Some(t(40, 14, 2)));
        // No whole number of 8–25 quanta: 7 MHz / 1 Mbit/s is 7 cycles a bit.
        assert_eq!(bit_timing(7_000_000, 1_000_000), None);
        assert_eq!(bit_timing(0, 1_000_000), None);
        assert_eq!(bit_timing(170_000_000, 0), None);
        // A prescaler beyond 511: 1 kbit/s from 170 MHz needs 170 000 cycles a bit; at
        // 10 kbit/s from 40.96 MHz, 16 quanta would need exactly 256 (taken).
        assert_eq!(bit_timing(170_000_000, 1_000), None);
        assert_eq!(bit_timing(40_960_000, 10_000), Some(t(256, 13, 2)));
    }

    #[test]
    fn bit_timing_is_exact_and_its_sample_point_the_closest_there_is() {
        for clock_mhz in 8..=200u32 {
            let clock = clock_mhz * 1_000_000;
            for rate in [125_000u32, 250_000, 500_000, 800_000, 1_000_000] {
                let target = if rate >= 800_000 { 0.8 } else { 0.875 };
                // Every exact split, by brute force: the best sample point distance.
                let mut closest = f64::INFINITY;
                for q in 8..=25u32 {
                    if clock % (rate * q) != 0 || clock / (rate * q) > 511 {
                        continue;
                    }
                    for upto in 2..=q - 2 {
                        closest = closest.min((f64::from(upto) / f64::from(q) - target).abs());
                    }
                }
                match bit_timing(clock, rate) {
                    None => assert!(closest.is_infinite(), "{clock} {rate}"),
                    Some(t) => {
                        assert_eq!(t.bitrate_bps(clock), rate);
                        assert_eq!(clock % (u32::from(t.prescaler) * t.quanta_per_bit()), 0);
                        assert!(t.seg1 >= 2 && t.seg2 >= 2 && t.sync_jump_width == t.seg2);
                        let sp = f64::from(1 + u32::from(t.seg1)) / f64::from(t.quanta_per_bit());
                        assert!(
                            (sp - target).abs() <= closest + 1e-12,
                            "{clock} {rate} {t:?}"
                        );
                    }
                }
            }
        }
    }
    use embedded_can::{ExtendedId, StandardId};
    use proptest::prelude::*;

    /// The frame's bits from SOF to the end of the data field, MSB first, as ISO 11898-1
    /// lays them out.
    fn spec_fields(frame: &CanFrame) -> Vec<bool> {
        let mut bits = Vec::new();
        let mut push = |value: u32, count: u32| {
            (0..count)
                .rev()
                .for_each(|i| bits.push((value >> i) & 1 == 1))
        };
        push(0, 1); // SOF (dominant)
        match frame.id() {
            Id::Standard(id) => {
                push(u32::from(id.as_raw()), 11);
                push(u32::from(frame.is_remote()), 1); // RTR
                push(0, 1); // IDE (dominant: standard)
                push(0, 1); // r0
            }
            Id::Extended(id) => {
                push(id.as_raw() >> 18, 11); // base ID
                push(1, 1); // SRR (recessive)
                push(1, 1); // IDE (recessive: extended)
                push(id.as_raw() & 0x3_FFFF, 18); // ID extension
                push(u32::from(frame.is_remote()), 1); // RTR
                push(0, 1); // r1
                push(0, 1); // r0
            }
        }
        push(frame.dlc() as u32, 4);
        for &byte in frame.data() {
            push(u32::from(byte), 8);
        }
        bits
    }

    /// CRC-15 as ISO 11898-1 specifies it, one bit at a time: `CRCNXT = NXTBIT xor CRC_RG(14)`,
    /// shift left, and if `CRCNXT` xor with 0x4599.
    fn spec_crc15(bits: &[bool]) -> u16 {
        let mut register = 0u16;
        for &bit in bits {
            let next = bit ^ (register & 0x4000 != 0);
            register = (register << 1) & 0x7FFF;
            if next {
                register ^= 0x4599;
            }
        }
        register
    }

    /// The bits a transmitter actually sends for `bits`: after five consecutive equal bits
    /// (stuff bits included) it inserts one of the opposite value.
    fn spec_stuff(bits: &[bool]) -> Vec<bool> {
        let mut sent: Vec<bool> = Vec::new();
        for &bit in bits {
            sent.push(bit);
            let tail = &sent[sent.len().saturating_sub(5)..];
            if tail.len() == 5 && tail.iter().all(|&b| b == bit) {
                sent.push(!bit);
            }
        }
        sent
    }

    /// Bit-by-bit reference, from the spec: fields, CRC-15 over SOF..data, stuffing over
    /// SOF..CRC, then the 13 unstuffed tail bits.
    fn reference_bits(frame: &CanFrame) -> u32 {
        let mut stuffable = spec_fields(frame);
        let crc = spec_crc15(&stuffable);
        (0..15)
            .rev()
            .for_each(|i| stuffable.push((crc >> i) & 1 == 1));
        spec_stuff(&stuffable).len() as u32 + 13
    }

    /// A small deterministic generator (xorshift64*), so the exhaustive check needs no seed
    /// handling.
    fn next(state: &mut u64) -> u64 {
        *state ^= *state >> 12;
        *state ^= *state << 25;
        *state ^= *state >> 27;
        state.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    #[test]
    fn frame_bits_equal_bit_by_bit_reference_for_many_frames_of_every_kind() {
        let mut rng = 0x9E37_79B9_7F4A_7C15u64;
        let mut checked = 0;
        for extended in [false, true] {
            for dlc in 0..=8usize {
                for k in 0..2_000 {
                    let r = next(&mut rng);
                    // Random bytes, and bytes biased to 0x00/0xFF to make long runs.
                    let byte = |i: usize| match k % 3 {
                        0 => (r >> (8 * i)) as u8,
                        1 => [0x00, 0xFF, 0x0F, 0xF8][((r >> (2 * i)) & 3) as usize],
                        _ => 0,
                    };
                    let data: Vec<u8> = (0..dlc).map(byte).collect();
                    let id = match k % 4 {
                        0 => 0,
                        1 => u32::MAX,
                        _ => (r >> 32) as u32,
                    };
                    let frame = if extended {
                        CanFrame::extended(id & 0x1FFF_FFFF, &data).unwrap()
                    } else {
                        CanFrame::standard((id & 0x7FF) as u16, &data).unwrap()
                    };
                    assert_eq!(frame_bits(&frame), reference_bits(&frame), "{frame:?}");
                    let remote = if extended {
                        CanFrame::remote(ExtendedId::new(id & 0x1FFF_FFFF).unwrap(), dlc)
                    } else {
                        CanFrame::remote(StandardId::new((id & 0x7FF) as u16).unwrap(), dlc)
                    }
                    .unwrap();
                    assert_eq!(frame_bits(&remote), reference_bits(&remote), "{remote:?}");
                    checked += 2;
                }
            }
        }
        assert_eq!(checked, 2 * 9 * 2_000 * 2);
    }

    #[test]
    fn crc15_matches_the_catalogued_check_value() {
        // CRC-15/CAN (width 15, poly 0x4599, init 0, no reflection, no final xor): the CRC of
        // the ASCII bytes "123456789" is 0x059E (Greg Cook's CRC catalogue).
        let mut message = [0u8; 16];
        message[7..].copy_from_slice(b"123456789");
        assert_eq!(crc15(u128::from_be_bytes(message)), 0x059E);
        let bits: Vec<bool> = b"123456789"
            .iter()
            .flat_map(|b| (0..8).rev().map(move |i| (b >> i) & 1 == 1))
            .collect();
        assert_eq!(spec_crc15(&bits), 0x059E);
    }

    #[test]
    fn frame_whose_crc_is_zero_counts_hand_worked_stuff_bits() {
        // Standard ID 0x000, data [0x58, 0xCF]: SOF..data is the polynomial x^17 (the DLC's
        // one bit, 0b0010) plus 0x58CF, and 0x58CF = x^17 mod 0xC599 (x^15 ≡ 0x4599,
        // x^16 ≡ 0x8B32 ^ 0xC599 = 0x4EAB, x^17 ≡ 0x9D56 ^ 0xC599 = 0x58CF): the message is a
        // multiple of the generator, so its CRC is 0.
        // Stuffable bits: 17 zeros (SOF, ID, RTR, IDE, r0, DLC 00), 1, 0, then data
        // 0101 1000 1100 1111, then 15 CRC zeros. The 17 zeros take stuff bits after the
        // 5th, 10th and 15th; the data has no run of five; the 15 CRC zeros take 3.
        // 19 + 16 + 15 = 50 bits + 6 stuff bits + 13 tail bits = 69.
        let f = CanFrame::standard(0x000, &[0x58, 0xCF]).unwrap();
        assert_eq!(spec_crc15(&spec_fields(&f)), 0);
        assert_eq!(frame_bits(&f), 69);
    }

    #[test]
    fn neutral_padding_alternates_from_the_opposite_bit_and_adds_no_stuff_bits() {
        for count in 10..=94u32 {
            for last in [false, true] {
                let pad = neutral_padding(last, count);
                assert_eq!(pad >> count, 0, "{count}");
                let pad_bits: Vec<bool> = (0..count).rev().map(|i| (pad >> i) & 1 == 1).collect();
                assert_ne!(pad_bits[0], last);
                assert!(pad_bits.windows(2).all(|w| w[0] != w[1]));
                // After five equal bits: their stuff bit, and none in the padding.
                let mut bits = vec![last; 5];
                bits.extend(&pad_bits);
                assert_eq!(spec_stuff(&bits).len(), 5 + 1 + count as usize);
            }
        }
    }

    proptest! {
        #[test]
        fn frame_bits_equal_bit_by_bit_reference(
            id in 0u32..0x2000_0000, extended: bool, remote: bool,
            data in proptest::collection::vec(any::<u8>(), 0..=8),
        ) {
            let f = match (extended, remote) {
                (true, false) => CanFrame::extended(id, &data).unwrap(),
                (false, false) => CanFrame::standard((id & 0x7FF) as u16, &data).unwrap(),
                (true, true) => CanFrame::remote(ExtendedId::new(id).unwrap(), data.len()).unwrap(),
                (false, true) => {
                    CanFrame::remote(StandardId::new((id & 0x7FF) as u16).unwrap(), data.len())
                        .unwrap()
                }
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
