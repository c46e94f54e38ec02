//! SBUS receivers (FrSky, Futaba and compatibles): 25-byte frames at 100 kbit/s, 8E2, inverted.
//!
//! Layout: byte 0 is the header 0x0F; bytes 1–22 hold 16 channels of 11 bits, least
//! significant bit first; byte 23 holds flags (bit 0 digital channel 17, bit 1 channel 18,
//! bit 2 frame lost, bit 3 failsafe); byte 24 is the footer (0x00, or 0x04/0x14/0x24/0x34 on
//! receivers that interleave telemetry slots). Channel values run about 172…1811, centre 992.

use super::{FrameReceiver, ReceiverFrame, normalize};
use core::fmt;

/// Bytes in a frame.
pub const FRAME_LEN: usize = 25;
/// Header byte.
pub const HEADER: u8 = 0x0F;
/// Usual channel centre.
pub const CENTER: u16 = 992;
/// Usual distance from centre to full scale.
pub const HALF_RANGE: u16 = 820;

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
        if footer != 0x00 && footer & 0x0F != 0x04 {
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

    /// Channel `i` (0-based) in −1…1 around 992 with `deadband` (fraction of full scale).
    pub fn channel(&self, i: usize, deadband: f32) -> f32 {
        self.channels
            .get(i)
            .map_or(0.0, |raw| normalize(*raw, CENTER, HALF_RANGE, deadband))
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
/// outputs neutral at once, and frames it flags as lost are counted (`frames_lost`).
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
        assert_eq!(f.channel(0, 0.0), -1.0); // (172 − 992) / 820 = −1.0
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
        assert_eq!(ok, 3);
        assert_eq!(rx.frames_lost(), 3);
    }
}
