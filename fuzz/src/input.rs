//! Turning fuzz bytes into values, and values back into bytes (for the seed corpus).
//!
//! Everything is read through [`arbitrary::Unstructured`]: integers little-endian, missing
//! bytes read as zero, so every input decodes to something.

use arbitrary::{Arbitrary, Result, Unstructured};

/// Floats worth trying on purpose: non-finite, extreme, zero, and the limits of the devices
/// (ESC ranges, MIT ranges, angle periods, thermal thresholds).
pub const SPECIAL_F32: [f32; 48] = [
    0.0,
    -0.0,
    f32::NAN,
    f32::INFINITY,
    f32::NEG_INFINITY,
    f32::MAX,
    f32::MIN,
    f32::MIN_POSITIVE,
    1.0e-45, // the smallest subnormal
    -1.0e-45,
    1.0e30,
    -1.0e30,
    1.0e9,
    -1.0e9,
    1.0,
    -1.0,
    0.5,
    -0.5,
    3.0,
    -3.0,
    10.0,
    -10.0,
    20.0,
    -20.0,
    24.0,
    25.0,
    30.0,
    -30.0,
    100.0,
    119.5,
    120.0,
    180.0,
    -180.0,
    359.99997,
    360.0,
    -360.0,
    720.0,
    716.2,
    500.0,
    5.0,
    12.5,
    -12.5,
    9.995,
    16384.0,
    30000.0,
    1.0e6,
    core::f32::consts::PI,
    core::f32::consts::TAU,
];

/// A float as the fuzz input spells it: a tag byte (`kind + 4 · index`) and its payload.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Float {
    /// Any bit pattern (NaN payloads, subnormals, everything).
    Bits(u32),
    /// One of [`SPECIAL_F32`].
    Special(u8),
    /// `n / 16`: fine steps around zero (±2048).
    Fine(i16),
    /// `n · 4`: the range of commands, targets and angles (±131 072).
    Coarse(i16),
}

impl Float {
    /// The value.
    pub fn value(self) -> f32 {
        match self {
            Self::Bits(b) => f32::from_bits(b),
            Self::Special(i) => SPECIAL_F32[usize::from(i) % SPECIAL_F32.len()],
            Self::Fine(n) => f32::from(n) / 16.0,
            Self::Coarse(n) => f32::from(n) * 4.0,
        }
    }

    /// The bytes that decode to `self`.
    pub fn encode(self, out: &mut Vec<u8>) {
        match self {
            Self::Bits(b) => {
                out.push(0);
                out.extend_from_slice(&b.to_le_bytes());
            }
            Self::Special(i) => out.push(1 + 4 * (i % 64)),
            Self::Fine(n) => {
                out.push(2);
                out.extend_from_slice(&n.to_le_bytes());
            }
            Self::Coarse(n) => {
                out.push(3);
                out.extend_from_slice(&n.to_le_bytes());
            }
        }
    }

    /// A finite value given in the input as exactly as it can be (for seeds).
    pub fn of(x: f32) -> Self {
        if let Some(i) = SPECIAL_F32.iter().position(|s| s.to_bits() == x.to_bits()) {
            return Self::Special(i as u8);
        }
        let fine = x * 16.0;
        if fine.fract() == 0.0 && (-32768.0..=32767.0).contains(&fine) {
            return Self::Fine(fine as i16);
        }
        Self::Bits(x.to_bits())
    }
}

impl<'a> Arbitrary<'a> for Float {
    fn arbitrary(u: &mut Unstructured<'a>) -> Result<Self> {
        let tag = u8::arbitrary(u)?;
        Ok(match tag % 4 {
            0 => Self::Bits(u32::arbitrary(u)?),
            1 => Self::Special(tag / 4),
            2 => Self::Fine(i16::arbitrary(u)?),
            _ => Self::Coarse(i16::arbitrary(u)?),
        })
    }
}

/// Reads a float in the [`Float`] format.
pub fn f32_from(u: &mut Unstructured<'_>) -> Result<f32> {
    Ok(Float::arbitrary(u)?.value())
}

/// A CAN payload as the input spells it: a length byte (`dlc`; 9 and above mean 8, so random
/// bytes mostly give full frames; bit 7 set: a remote frame) and always eight data bytes
/// (those beyond the DLC are not sent).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Payload {
    /// Data length code, 0–8.
    pub dlc: u8,
    /// Remote (RTR) frame.
    pub remote: bool,
    /// The bytes; only `..dlc` are sent.
    pub data: [u8; 8],
}

impl Payload {
    /// An eight-byte data frame's payload.
    pub const fn full(data: [u8; 8]) -> Self {
        Self {
            dlc: 8,
            remote: false,
            data,
        }
    }

    /// The bytes that decode to `self`.
    pub fn encode(&self, out: &mut Vec<u8>) {
        out.push(self.dlc.min(8) | if self.remote { 0x80 } else { 0 });
        out.extend_from_slice(&self.data);
    }

    /// The frame with this payload on `id` (`None` for an ID out of range).
    pub fn frame(&self, id: rc10_core::can::Id) -> Option<rc10_core::can::CanFrame> {
        use rc10_core::can::CanFrame;
        if self.remote {
            CanFrame::remote(id, usize::from(self.dlc))
        } else {
            CanFrame::new(id, self.data.get(..usize::from(self.dlc))?)
        }
    }
}

impl<'a> Arbitrary<'a> for Payload {
    fn arbitrary(u: &mut Unstructured<'a>) -> Result<Self> {
        let b = u8::arbitrary(u)?;
        let data = <[u8; 8]>::arbitrary(u)?;
        Ok(Self {
            dlc: (b & 0x7F).min(8),
            remote: b & 0x80 != 0,
            data,
        })
    }
}
