//! SBUS receivers (FrSky, Futaba and compatibles): 25-byte frames at 100 kbit/s, 8E2, inverted.
//!
//! Layout: byte 0 is the header 0x0F; bytes 1–22 hold 16 channels of 11 bits, least
//! significant bit first; byte 23 holds flags (bit 0 digital channel 17, bit 1 channel 18,
//! bit 2 frame lost, bit 3 failsafe); byte 24 is the footer (0x00, or 0x04/0x14/0x24/0x34 on
//! receivers that interleave telemetry slots).
//!
//! Scaling: [`SbusFrame::channel`] uses FrSky's (OpenTX/EdgeTX) convention, ±100 % at
//! 172…1811 around 992 (a half-span of 819.2 counts: [`HALF_RANGE`] is 819, so that both
//! ends read ±1). Futaba receivers centre near 1024 with a different span: use
//! [`SbusFrame::channel_scaled`] with your receiver's centre and span (read them from
//! `channels` with the sticks centred and at full throw).
//!
//! A frame flagged "frame lost" repeats the last values; it does not keep the link alive
//! (see [`Link::hold`](super::Link::hold)), so a receiver that repeats after the transmitter
//! is gone still goes neutral after the timeout.

use super::{FrameReceiver, ReceiverFrame, normalize};
use core::fmt;

/// Bytes in a frame.
pub const FRAME_LEN: usize = 25;
/// Header byte.
pub const HEADER: u8 = 0x0F;
/// Channel centre, FrSky convention (1500 µs).
pub const CENTER: u16 = 992;
/// Distance from centre to full scale (±100 %), FrSky convention: 1024 · 0.8 = 819.2 counts
/// (172 and 1811 are 820 and 819 from [`CENTER`]), rounded down so that full throw reads
/// +1 as well as −1.
pub const HALF_RANGE: u16 = 819;

/// One decoded SBUS frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SbusFrame {
    /// Channels 1–16, raw 11-bit values.
    pub channels: [u16; 16],
    /// Digital channel 17.
    pub ch17: bool,
    /// Digital channel 18.
    pub ch18: bool,
    /// The receiver missed a frame from the transmitter (values are held).
    pub frame_lost: bool,
    /// The receiver is in failsafe: the transmitter link is gone.
    pub failsafe: bool,
}

impl SbusFrame {
    /// All channels centred, no flags: what a lost link reports.
    pub const NEUTRAL: Self = Self {
        channels: [CENTER; 16],
        ch17: false,
        ch18: false,
        frame_lost: false,
        failsafe: false,
    };

    /// Decodes 25 bytes, checking header and footer.
    pub fn parse(bytes: &[u8]) -> Result<Self, SbusError> {
        let b: &[u8; FRAME_LEN] = bytes
            .try_into()
            .map_err(|_| SbusError::WrongLength(bytes.len()))?;
        if b[0] != HEADER {
            return Err(SbusError::BadHeader(b[0]));
        }
        let footer = b[24];
        // 0x00, or an SBUS2 telemetry-slot footer 0x04 / 0x14 / 0x24 / 0x34.
        if footer != 0x00 && footer & 0xCF != 0x04 {
            return Err(SbusError::BadFooter(footer));
        }
        let mut channels = [0u16; 16];
        let payload = &b[1..23];
        // Channel i is the 11 bits from bit 11·i, spread over up to three bytes.
        for (ch, bit) in channels.iter_mut().zip((0usize..).step_by(11)) {
            let bytes = payload.get(bit / 8..).unwrap_or(&[]);
            let byte = |k: usize| bytes.get(k).copied().map_or(0, u32::from);
            let (lo, mid, hi) = (byte(0), byte(1), byte(2));
            let word = lo | mid << 8 | hi << 16;
            *ch = ((word >> (bit % 8)) & 0x7FF) as u16;
        }
        let flags = b[23];
        Ok(Self {
            channels,
            ch17: flags & 0x01 != 0,
            ch18: flags & 0x02 != 0,
            frame_lost: flags & 0x04 != 0,
            failsafe: flags & 0x08 != 0,
        })
    }

    /// Channel `i` (0-based) in −1…1 around 992 with `deadband` (fraction of full scale),
    /// FrSky scaling ([`CENTER`], [`HALF_RANGE`]).
    pub fn channel(&self, i: usize, deadband: f32) -> f32 {
        self.channel_scaled(i, CENTER, HALF_RANGE, deadband)
    }

    /// Channel `i` (0-based) in −1…1 for a receiver whose centre is `center` and whose full
    /// scale is `half_range` counts from it, with `deadband` (fraction of full scale).
    pub fn channel_scaled(&self, i: usize, center: u16, half_range: u16, deadband: f32) -> f32 {
        self.channels
            .get(i)
            .map_or(0.0, |raw| normalize(*raw, center, half_range, deadband))
    }
}

/// Why an SBUS frame was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SbusError {
    /// Not 25 bytes.
    WrongLength(usize),
    /// The first byte is not 0x0F.
    BadHeader(u8),
    /// The last byte is not a known footer.
    BadFooter(u8),
}

impl fmt::Display for SbusError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::WrongLength(n) => write!(f, "SBUS frame of {n} bytes, expected 25"),
            Self::BadHeader(b) => write!(f, "SBUS header {b:#04x}, expected 0x0f"),
            Self::BadFooter(b) => write!(f, "SBUS footer {b:#04x} unknown"),
        }
    }
}

impl core::error::Error for SbusError {}

/// An SBUS receiver (see [`FrameReceiver`]); the receiver's own failsafe flag sends the
/// outputs neutral (every channel centred; or the frame given to
/// [`with_failsafe`](FrameReceiver::with_failsafe)) at once, and frames it flags as lost are
/// counted (`frames_lost`).
pub type SbusReceiver = FrameReceiver<SbusFrame, FRAME_LEN>;

impl ReceiverFrame for SbusFrame {
    type Error = SbusError;
    const NEUTRAL: Self = SbusFrame::NEUTRAL;

    fn parse(bytes: &[u8]) -> Result<Self, SbusError> {
        SbusFrame::parse(bytes)
    }

    fn failsafe(&self) -> bool {
        self.failsafe
    }

    fn frame_lost(&self) -> bool {
        self.frame_lost
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::remote::Signal;
    use crate::time::{Duration, Instant};

    /// Encodes a frame (written independently of `parse`: a bit-by-bit packer).
    fn encode(channels: [u16; 16], flags: u8, footer: u8) -> [u8; 25] {
        let mut b = [0u8; 25];
        b[0] = HEADER;
        for (i, ch) in channels.iter().enumerate() {
            for k in 0..11 {
                if ch >> k & 1 == 1 {
                    let bit = 11 * i + k;
                    b[1 + bit / 8] |= 1 << (bit % 8);
                }
            }
        }
        b[23] = flags;
        b[24] = footer;
        b
    }

    #[test]
    fn sixteen_channels_and_flags_decode() {
        let mut ch = [0u16; 16];
        for (i, c) in ch.iter_mut().enumerate() {
            *c = 172 + 100 * i as u16;
        }
        let f = SbusFrame::parse(&encode(ch, 0b0101, 0x00)).unwrap();
        assert_eq!(f.channels, ch);
        assert!(f.ch17 && !f.ch18 && f.frame_lost && !f.failsafe);
        assert_eq!(f.channel(0, 0.0), -1.0); // (172 − 992) / 819, −1.001: full scale
        // The other flags: channel 18 and failsafe.
        let f = SbusFrame::parse(&encode(ch, 0b1010, 0x00)).unwrap();
        assert!(!f.ch17 && f.ch18 && !f.frame_lost && f.failsafe);
    }

    #[test]
    fn full_throw_reads_full_scale_both_ways() {
        let mut ch = [992u16; 16];
        ch[0] = 1811; // +100 % in OpenTX/EdgeTX
        ch[1] = 172; // −100 %
        ch[2] = 992 + 410; // +50 % of 819.2 is 409.6
        let f = SbusFrame::parse(&encode(ch, 0, 0x00)).unwrap();
        assert_eq!(f.channel(0, 0.0), 1.0);
        assert_eq!(f.channel(1, 0.0), -1.0);
        assert!((f.channel(2, 0.0) - 0.5).abs() < 1e-3);
        assert_eq!(f.channel(3, 0.0), 0.0);
    }

    #[test]
    fn telemetry_footers_are_accepted_and_bad_frames_rejected() {
        let ch = [992; 16];
        assert!(SbusFrame::parse(&encode(ch, 0, 0x14)).is_ok());
        assert_eq!(
            SbusFrame::parse(&encode(ch, 0, 0x55)),
            Err(SbusError::BadFooter(0x55))
        );
        let mut bad = encode(ch, 0, 0);
        bad[0] = 0x0E;
        assert_eq!(SbusFrame::parse(&bad), Err(SbusError::BadHeader(0x0E)));
        assert_eq!(
            SbusFrame::parse(&bad[..24]),
            Err(SbusError::WrongLength(24))
        );
    }

    #[test]
    fn only_the_sbus2_slot_footers_are_accepted() {
        let ch = [992; 16];
        for ok in [0x00, 0x04, 0x14, 0x24, 0x34] {
            assert!(SbusFrame::parse(&encode(ch, 0, ok)).is_ok(), "{ok:#04x}");
        }
        for bad in [0x44, 0x54, 0x84, 0xF4, 0x01, 0x0F] {
            assert_eq!(
                SbusFrame::parse(&encode(ch, 0, bad)),
                Err(SbusError::BadFooter(bad))
            );
        }
    }

    #[test]
    fn futaba_scaling_centres_on_its_own_neutral() {
        // A Futaba receiver's neutral reads 1024: FrSky scaling shows (1024 − 992)/819 ≈ 0.04
        // there, its own centre 0.
        let mut ch = [1024; 16];
        ch[1] = 1024 + 672;
        let f = SbusFrame::parse(&encode(ch, 0, 0)).unwrap();
        assert!((f.channel(0, 0.0) - 32.0 / 819.0).abs() < 1e-6);
        assert_eq!(f.channel_scaled(0, 1024, 672, 0.0), 0.0);
        assert_eq!(f.channel_scaled(1, 1024, 672, 0.0), 1.0);
    }

    #[test]
    fn frames_flagged_lost_do_not_keep_a_dead_link_alive() {
        // The transmitter goes silent after t = 0; the receiver goes on repeating the last
        // values with the "frame lost" flag (bit 2) every 7 ms and never sets failsafe.
        let mut rx = SbusReceiver::new(Duration::from_millis(100));
        let mut ch = [992; 16];
        ch[2] = 1811;
        rx.push_frame(&encode(ch, 0, 0), Instant::from_millis(0))
            .unwrap();
        for k in 1..=30u64 {
            rx.push_frame(&encode(ch, 0x04, 0), Instant::from_millis(7 * k))
                .unwrap();
        }
        assert_eq!(rx.frames_lost(), 30);
        // Within 100 ms of the last fresh frame: the held values.
        assert_eq!(rx.signal(Instant::from_millis(100)).value.channels[2], 1811);
        // After it: lost and neutral, although repeats keep arriving (the last at 210 ms).
        let s = rx.signal(Instant::from_millis(210));
        assert!(s.lost);
        assert_eq!(s.value, SbusFrame::NEUTRAL);
        // A fresh frame brings the link back.
        rx.push_frame(&encode(ch, 0, 0), Instant::from_millis(217))
            .unwrap();
        assert!(!rx.signal(Instant::from_millis(218)).lost);
        // A link that starts with repeats is not live.
        let mut rx = SbusReceiver::new(Duration::from_millis(100));
        rx.push_frame(&encode(ch, 0x04, 0), Instant::from_millis(0))
            .unwrap();
        assert!(rx.signal(Instant::from_millis(1)).lost);
    }

    #[test]
    fn receiver_failsafe_flag_goes_neutral_immediately() {
        let mut rx = SbusReceiver::new(Duration::from_millis(100));
        let mut ch = [992; 16];
        ch[2] = 1811;
        rx.push_frame(&encode(ch, 0, 0), Instant::from_millis(0))
            .unwrap();
        assert_eq!(rx.signal(Instant::from_millis(1)).value.channels[2], 1811);
        rx.push_frame(&encode(ch, 0x08, 0), Instant::from_millis(7))
            .unwrap();
        let s = rx.signal(Instant::from_millis(8));
        assert!(s.lost);
        assert_eq!(s.value, SbusFrame::NEUTRAL);
    }

    #[test]
    fn a_failsafe_frame_of_the_users_replaces_neutral_whenever_the_link_is_lost() {
        // Channel 5 arms the robot when high: the failsafe holds it low (172, −100 %).
        let mut failsafe = SbusFrame::NEUTRAL;
        failsafe.channels[4] = 172;
        let mut rx = SbusReceiver::with_failsafe(Duration::from_millis(100), failsafe);
        let lost = |s: Signal<SbusFrame>| s.lost && s.value == failsafe;
        // Before the first frame.
        assert!(lost(rx.signal(Instant::from_millis(1))));
        // Live: the frame as sent, switch high.
        let mut armed = [992; 16];
        armed[4] = 1811;
        rx.push_frame(&encode(armed, 0, 0), Instant::from_millis(7))
            .unwrap();
        let live = rx.signal(Instant::from_millis(8));
        assert!(!live.lost);
        assert_eq!(live.value.channel(4, 0.0), 1.0);
        // The receiver's own failsafe flag, then silence past the timeout.
        rx.push_frame(&encode(armed, 0x08, 0), Instant::from_millis(14))
            .unwrap();
        let s = rx.signal(Instant::from_millis(15));
        assert!(lost(s));
        assert_eq!(s.value.channel(4, 0.0), -1.0);
        rx.push_frame(&encode(armed, 0, 0), Instant::from_millis(21))
            .unwrap();
        assert!(!rx.signal(Instant::from_millis(22)).lost);
        assert!(lost(rx.signal(Instant::from_millis(122))));
    }

    #[test]
    fn byte_stream_frames_by_gaps_and_counts_lost_frames() {
        let mut rx = SbusReceiver::new(Duration::from_millis(100));
        let frame = encode([1500; 16], 0x04, 0);
        let mut t = 0;
        let mut ok = 0;
        for _ in 0..3 {
            for byte in frame {
                t += 120;
                if let Some(Ok(_)) = rx.push_byte(byte, Instant::from_micros(t)) {
                    ok += 1;
                }
            }
            t += 4000;
        }
        // The last frame is proven whole by the silence after it.
        if let Some(Ok(_)) = rx.poll(Instant::from_micros(t)) {
            ok += 1;
        }
        assert_eq!(ok, 3);
        assert_eq!(rx.frames_lost(), 3);
    }

    #[test]
    fn a_byte_that_creeps_into_a_frame_drops_it_instead_of_shifting_it() {
        // A 0x00 after the header: read as the first 25 bytes, every channel would shift by a
        // byte and the flags byte (0) would land on the footer, which 0 satisfies.
        let mut rx = SbusReceiver::new(Duration::from_millis(100));
        let frame = encode([992; 16], 0, 0);
        let mut burst = frame.to_vec();
        burst.insert(1, 0x00);
        let mut t = 0u64;
        for byte in &burst {
            t += 120;
            assert!(rx.push_byte(*byte, Instant::from_micros(t)).is_none());
        }
        assert!(rx.signal(Instant::from_micros(t + 4_000)).lost);
        assert_eq!((rx.link().frames(), rx.link().errors()), (0, 1));
    }
}
