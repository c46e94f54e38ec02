//! Telemetry for tuning: VOFA+ JustFloat and FireWater encoders, and [`Channels`], a static set
//! of named `f32` values any task can publish without locks (a UART or RTT task sends them).
//!
//! ```
//! use rc10_core::telemetry::Channels;
//! // Target and measured rpm of two wheels, published from the control loop.
//! static SCOPE: Channels<4> = Channels::new(["w1_target", "w1_rpm", "w2_target", "w2_rpm"]);
//! SCOPE.set(0, 300.0);
//! SCOPE.set(1, 297.5);
//! let mut buf = [0u8; 64];
//! let n = SCOPE.encode_justfloat(&mut buf).unwrap();
//! assert_eq!(n, 4 * 4 + 4);
//! assert_eq!(&buf[16..20], &[0x00, 0x00, 0x80, 0x7f]); // JustFloat tail
//! ```

use core::fmt;
use core::sync::atomic::{AtomicU32, Ordering};

/// The four bytes VOFA+ JustFloat puts after every frame (the bit pattern of +inf).
pub const JUSTFLOAT_TAIL: [u8; 4] = [0x00, 0x00, 0x80, 0x7f];

/// The most digits after the point [`firewater`] writes (the limit of Rust's formatter).
pub const MAX_DECIMALS: usize = u16::MAX as usize;

/// The output buffer is too small.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BufferTooSmall {
    /// Bytes the frame needs, exactly.
    pub needed: usize,
}

impl fmt::Display for BufferTooSmall {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "telemetry buffer too small: {} bytes needed",
            self.needed
        )
    }
}

impl core::error::Error for BufferTooSmall {}

/// Encodes `values` as one JustFloat frame (little-endian f32s, then the tail) into `out`;
/// returns the bytes written.
///
/// `+inf` is sent as [`f32::MAX`]: its own bit pattern is the frame tail, so VOFA+ would end
/// the frame at it and shift every later channel. Every other value, NaN and `-inf` included,
/// is sent bit for bit.
pub fn justfloat(values: &[f32], out: &mut [u8]) -> Result<usize, BufferTooSmall> {
    // 4 bytes per value; a slice never spans more than isize::MAX bytes, so the sum does not
    // saturate.
    let data_len = core::mem::size_of_val(values);
    let needed = data_len.saturating_add(JUSTFLOAT_TAIL.len());
    let frame = out.get_mut(..needed).ok_or(BufferTooSmall { needed })?;
    let (data, tail) = frame.split_at_mut(data_len);
    for (chunk, v) in data.as_chunks_mut::<4>().0.iter_mut().zip(values) {
        let v = if *v == f32::INFINITY { f32::MAX } else { *v };
        chunk.copy_from_slice(&v.to_le_bytes());
    }
    tail.copy_from_slice(&JUSTFLOAT_TAIL);
    Ok(needed)
}

/// Encodes `values` as one FireWater line, `prefix:v1,v2,...\n` (no `prefix:` if `prefix` is
/// empty), with `decimals` digits after the point (at most [`MAX_DECIMALS`]; more are taken
/// as that); returns the bytes written. NaN and infinities are written as `nan`, `inf` and
/// `-inf`. The prefix is written as it is: it must not contain `:`, `,` or a line break,
/// which would split the line differently in VOFA+, nor be `image`, which VOFA+ takes as the
/// header of a picture.
pub fn firewater(
    prefix: &str,
    values: &[f32],
    decimals: usize,
    out: &mut [u8],
) -> Result<usize, BufferTooSmall> {
    // Rust's formatter panics on a precision beyond u16::MAX.
    let decimals = decimals.min(MAX_DECIMALS);
    let mut w = SliceWriter { out, len: 0 };
    if firewater_line(&mut w, prefix, values, decimals).is_ok() {
        return Ok(w.len);
    }
    // Too long: the exact length, from the same line written to a counter.
    let mut count = Counter(0);
    let _ = firewater_line(&mut count, prefix, values, decimals);
    Err(BufferTooSmall { needed: count.0 })
}

/// Writes one FireWater line; stops at the first error of `w`.
fn firewater_line(
    w: &mut impl fmt::Write,
    prefix: &str,
    values: &[f32],
    decimals: usize,
) -> fmt::Result {
    if !prefix.is_empty() {
        write!(w, "{prefix}:")?;
    }
    for (i, v) in values.iter().enumerate() {
        let sep = if i == 0 { "" } else { "," };
        if v.is_finite() {
            write!(w, "{sep}{v:.decimals$}")?;
        } else if v.is_nan() {
            write!(w, "{sep}nan")?;
        } else {
            write!(w, "{sep}{}inf", if *v < 0.0 { "-" } else { "" })?;
        }
    }
    w.write_str("\n")
}

/// Counts the bytes written to it (saturating).
struct Counter(usize);

impl fmt::Write for Counter {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        self.0 = self.0.saturating_add(s.len());
        Ok(())
    }
}

/// Writes into a byte slice; fails (writing nothing more) once a piece does not fit.
struct SliceWriter<'a> {
    out: &'a mut [u8],
    len: usize,
}

impl fmt::Write for SliceWriter<'_> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        let end = self.len.checked_add(s.len()).ok_or(fmt::Error)?;
        let dst = self.out.get_mut(self.len..end).ok_or(fmt::Error)?;
        dst.copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

/// `N` named `f32` channels in a `static`: set from any task or interrupt without a lock (each
/// value is one atomic word), read and encoded by the task that sends telemetry.
#[derive(Debug)]
pub struct Channels<const N: usize> {
    names: [&'static str; N],
    values: [AtomicU32; N],
}

impl<const N: usize> Channels<N> {
    /// Channels with these names, all 0.0.
    pub const fn new(names: [&'static str; N]) -> Self {
        Self {
            names,
            values: [const { AtomicU32::new(0) }; N],
        }
    }

    /// Sets channel `index`; returns `false` (and changes nothing) if there is no such channel.
    pub fn set(&self, index: usize, value: f32) -> bool {
        match self.values.get(index) {
            Some(slot) => {
                slot.store(value.to_bits(), Ordering::Relaxed);
                true
            }
            None => false,
        }
    }

    /// Sets the channel called `name`; returns `false` if there is none.
    pub fn set_named(&self, name: &str, value: f32) -> bool {
        self.names
            .iter()
            .position(|n| *n == name)
            .is_some_and(|i| self.set(i, value))
    }

    /// The value of channel `index`.
    pub fn get(&self, index: usize) -> Option<f32> {
        self.values
            .get(index)
            .map(|v| f32::from_bits(v.load(Ordering::Relaxed)))
    }

    /// The channel names, in order (configure VOFA+ with them).
    pub const fn names(&self) -> &[&'static str; N] {
        &self.names
    }

    /// All values now.
    pub fn snapshot(&self) -> [f32; N] {
        let mut out = [0.0; N];
        for (o, v) in out.iter_mut().zip(&self.values) {
            *o = f32::from_bits(v.load(Ordering::Relaxed));
        }
        out
    }

    /// One JustFloat frame of all channels.
    pub fn encode_justfloat(&self, out: &mut [u8]) -> Result<usize, BufferTooSmall> {
        justfloat(&self.snapshot(), out)
    }

    /// One FireWater line of all channels.
    pub fn encode_firewater(
        &self,
        prefix: &str,
        decimals: usize,
        out: &mut [u8],
    ) -> Result<usize, BufferTooSmall> {
        firewater(prefix, &self.snapshot(), decimals, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn justfloat_bytes_are_little_endian_floats_then_tail() {
        let mut buf = [0u8; 12];
        // 1.0 = 0x3F800000, -2.0 = 0xC0000000.
        assert_eq!(justfloat(&[1.0, -2.0], &mut buf), Ok(12));
        assert_eq!(
            buf,
            [0, 0, 0x80, 0x3F, 0, 0, 0, 0xC0, 0x00, 0x00, 0x80, 0x7f]
        );
        assert_eq!(
            justfloat(&[1.0, 2.0, 3.0], &mut buf),
            Err(BufferTooSmall { needed: 16 })
        );
    }

    #[test]
    fn firewater_line_format() {
        let mut buf = [0u8; 64];
        let n = firewater("rpm", &[300.0, -12.5, f32::NAN], 2, &mut buf).unwrap();
        assert_eq!(&buf[..n], b"rpm:300.00,-12.50,nan\n");
        let n = firewater("", &[1.0], 0, &mut buf).unwrap();
        assert_eq!(&buf[..n], b"1\n");
        assert!(firewater("x", &[123456.0], 3, &mut buf[..8]).is_err());
    }

    #[test]
    fn firewater_decimals_beyond_the_formatter_limit_are_capped_not_a_panic() {
        // core::fmt panics on a precision above u16::MAX ("Formatting argument out of range").
        let mut buf = vec![0u8; MAX_DECIMALS + 4];
        let n = firewater("", &[1.0], usize::MAX, &mut buf).unwrap();
        assert_eq!(n, MAX_DECIMALS + 3); // "1." + the digits + "\n"
        let mut small = [0u8; 8];
        let needed = firewater("", &[1.0], usize::MAX, &mut small)
            .unwrap_err()
            .needed;
        assert_eq!(needed, MAX_DECIMALS + 3);
    }

    #[test]
    fn firewater_reports_exactly_the_bytes_a_line_needs() {
        // "1\n" is 2 bytes; "x:123456.000\n" is 13; "a:1.5,-inf,nan\n" is 15.
        assert_eq!(
            firewater("", &[1.0], 0, &mut [0u8; 1]),
            Err(BufferTooSmall { needed: 2 })
        );
        assert_eq!(
            firewater("x", &[123456.0], 3, &mut [0u8; 8]),
            Err(BufferTooSmall { needed: 13 })
        );
        let mut buf = [0u8; 15];
        assert_eq!(
            firewater("a", &[1.5, f32::NEG_INFINITY, f32::NAN], 1, &mut buf[..14]),
            Err(BufferTooSmall { needed: 15 })
        );
        assert_eq!(
            firewater("a", &[1.5, f32::NEG_INFINITY, f32::NAN], 1, &mut buf),
            Ok(15)
        );
        assert_eq!(&buf, b"a:1.5,-inf,nan\n");
    }

    #[test]
    fn justfloat_sends_plus_infinity_as_the_largest_float_not_the_tail() {
        // +inf is 0x7F800000, bytes 00 00 80 7F: the tail itself. f32::MAX is 0x7F7FFFFF.
        let mut buf = [0u8; 12];
        assert_eq!(
            justfloat(&[f32::INFINITY, f32::NEG_INFINITY], &mut buf),
            Ok(12)
        );
        assert_eq!(
            buf,
            [
                0xFF, 0xFF, 0x7F, 0x7F, 0x00, 0x00, 0x80, 0xFF, 0x00, 0x00, 0x80, 0x7F
            ]
        );
    }

    #[test]
    fn channels_set_by_index_and_name() {
        let ch = Channels::new(["a", "b"]);
        assert!(ch.set(1, 2.5));
        assert!(ch.set_named("a", -1.0));
        assert!(!ch.set(2, 0.0));
        assert!(!ch.set_named("c", 0.0));
        assert_eq!(ch.snapshot(), [-1.0, 2.5]);
        let mut buf = [0u8; 32];
        let n = ch.encode_firewater("m", 1, &mut buf).unwrap();
        assert_eq!(&buf[..n], b"m:-1.0,2.5\n");
    }
}
