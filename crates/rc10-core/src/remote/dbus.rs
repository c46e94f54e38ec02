//! DJI DR16 receiver (DT7 transmitter) over DBUS: 18-byte frames every 14 ms at 100 kbit/s,
//! 8E1, inverted (DJI RoboMaster development-board examples).
//!
//! Layout (little-endian bit fields): channels 0–3 are 11 bits each from byte 0 (right stick
//! x, right stick y, left stick x, left stick y; 364…1684, centre 1024, accepted up to ±700
//! around the centre as DJI's own examples do); byte 5 bits 4–5 the
//! right switch, bits 6–7 the left switch (1 up, 3 middle, 2 down; HNU's basic_framework and
//! RoboMaster's RoboRTS-Firmware read them so; a comment in DJI's development-board examples
//! calls bits 4–5 "Switch left", which is not the switch they are); bytes 6–11 mouse x, y, z
//! (i16); bytes 12–13 mouse buttons; bytes 14–15 the keyboard bit mask; bytes 16–17 the wheel
//! (11 bits, on newer receivers).

use super::{FrameReceiver, ReceiverFrame, normalize};
use core::fmt;

/// Raw stick minimum of the DR16 (full deflection, −660 from the centre).
pub const STICK_MIN: u16 = 364;
/// Raw stick centre.
pub const STICK_CENTER: u16 = 1024;
/// Raw stick maximum (full deflection, +660 from the centre).
pub const STICK_MAX: u16 = 1684;
/// How far from the centre a stick value may read before the frame is rejected as corrupt:
/// 700, the margin DJI's RoboMaster development-board examples allow, because a transmitter
/// can read a little past ±660 (beyond ±660 a stick reads as full scale).
pub const STICK_TOLERANCE: u16 = 700;
/// Bytes in a frame.
pub const FRAME_LEN: usize = 18;

/// A three-position switch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Switch {
    /// Up (raw 1).
    Up,
    /// Middle (raw 3).
    Middle,
    /// Down (raw 2).
    Down,
}

impl Switch {
    const fn from_raw(raw: u8) -> Option<Self> {
        match raw {
            1 => Some(Self::Up),
            3 => Some(Self::Middle),
            2 => Some(Self::Down),
            _ => None,
        }
    }
}

/// Keyboard keys as the DR16 reports them (bit mask).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Keys(pub u16);

impl Keys {
    /// W.
    pub const W: u16 = 1 << 0;
    /// S.
    pub const S: u16 = 1 << 1;
    /// A.
    pub const A: u16 = 1 << 2;
    /// D.
    pub const D: u16 = 1 << 3;
    /// Shift.
    pub const SHIFT: u16 = 1 << 4;
    /// Ctrl.
    pub const CTRL: u16 = 1 << 5;
    /// Q.
    pub const Q: u16 = 1 << 6;
    /// E.
    pub const E: u16 = 1 << 7;
    /// R.
    pub const R: u16 = 1 << 8;
    /// F.
    pub const F: u16 = 1 << 9;
    /// G.
    pub const G: u16 = 1 << 10;
    /// Z.
    pub const Z: u16 = 1 << 11;
    /// X.
    pub const X: u16 = 1 << 12;
    /// C.
    pub const C: u16 = 1 << 13;
    /// V.
    pub const V: u16 = 1 << 14;
    /// B.
    pub const B: u16 = 1 << 15;

    /// Whether every key in `mask` is held.
    pub const fn held(&self, mask: u16) -> bool {
        self.0 & mask == mask
    }
}

/// One decoded DBUS frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DbusFrame {
    /// Raw sticks: right x, right y, left x, left y (364…1684; up to 324…1724 accepted).
    pub sticks: [u16; 4],
    /// Left switch.
    pub left_switch: Switch,
    /// Right switch.
    pub right_switch: Switch,
    /// Mouse motion x, y, z (wheel), counts per frame.
    pub mouse: [i16; 3],
    /// Mouse left button.
    pub mouse_left: bool,
    /// Mouse right button.
    pub mouse_right: bool,
    /// Keyboard.
    pub keys: Keys,
    /// Transmitter wheel, raw 11 bits (1024 centre; 0 on receivers that do not send it).
    pub wheel: u16,
}

impl DbusFrame {
    /// Sticks centred, both switches down (the conventional "safe" position in RoboMaster
    /// code), no mouse motion, no keys: what a lost link reports.
    pub const NEUTRAL: Self = Self {
        sticks: [STICK_CENTER; 4],
        left_switch: Switch::Down,
        right_switch: Switch::Down,
        mouse: [0; 3],
        mouse_left: false,
        mouse_right: false,
        keys: Keys(0),
        wheel: STICK_CENTER,
    };

    /// Decodes 18 bytes; rejects values the DR16 never sends.
    pub fn parse(bytes: &[u8]) -> Result<Self, DbusError> {
        let b: &[u8; FRAME_LEN] = bytes
            .try_into()
            .map_err(|_| DbusError::WrongLength(bytes.len()))?;
        let [
            b0,
            b1,
            b2,
            b3,
            b4,
            b5,
            m0,
            m1,
            m2,
            m3,
            m4,
            m5,
            left,
            right,
            k0,
            k1,
            w0,
            w1,
        ] = *b;
        let w = u16::from;
        let sticks = [
            (w(b0) | w(b1) << 8) & 0x7FF,
            (w(b1) >> 3 | w(b2) << 5) & 0x7FF,
            (w(b2) >> 6 | w(b3) << 2 | w(b4) << 10) & 0x7FF,
            (w(b4) >> 1 | w(b5) << 7) & 0x7FF,
        ];
        let accepted = STICK_CENTER - STICK_TOLERANCE..=STICK_CENTER + STICK_TOLERANCE;
        if sticks.iter().any(|s| !accepted.contains(s)) {
            return Err(DbusError::StickOutOfRange);
        }
        let right_switch = Switch::from_raw((b5 >> 4) & 0x03).ok_or(DbusError::InvalidSwitch)?;
        let left_switch = Switch::from_raw((b5 >> 6) & 0x03).ok_or(DbusError::InvalidSwitch)?;
        Ok(Self {
            sticks,
            left_switch,
            right_switch,
            mouse: [
                i16::from_le_bytes([m0, m1]),
                i16::from_le_bytes([m2, m3]),
                i16::from_le_bytes([m4, m5]),
            ],
            mouse_left: left != 0,
            mouse_right: right != 0,
            keys: Keys(u16::from_le_bytes([k0, k1])),
            wheel: u16::from_le_bytes([w0, w1]) & 0x7FF,
        })
    }

    /// Stick `i` (0 right x, 1 right y, 2 left x, 3 left y) in −1…1 with `deadband` (fraction).
    pub fn stick(&self, i: usize, deadband: f32) -> f32 {
        self.sticks.get(i).map_or(0.0, |raw| {
            normalize(*raw, STICK_CENTER, STICK_CENTER - STICK_MIN, deadband)
        })
    }
}

/// Why a DBUS frame was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DbusError {
    /// Not 18 bytes.
    WrongLength(usize),
    /// A stick value more than [`STICK_TOLERANCE`] from the centre (outside 324…1724).
    StickOutOfRange,
    /// A switch value outside {1, 2, 3}.
    InvalidSwitch,
}

impl fmt::Display for DbusError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::WrongLength(n) => write!(f, "DBUS frame of {n} bytes, expected 18"),
            Self::StickOutOfRange => f.write_str("DBUS stick value out of range"),
            Self::InvalidSwitch => f.write_str("DBUS switch value invalid"),
        }
    }
}

impl core::error::Error for DbusError {}

/// A DR16 receiver (see [`FrameReceiver`]): `DbusReceiver::new(timeout)`, then
/// `push_byte` / `push_frame` and `signal(now)`.
pub type DbusReceiver = FrameReceiver<DbusFrame, FRAME_LEN>;

impl ReceiverFrame for DbusFrame {
    type Error = DbusError;
    const NEUTRAL: Self = DbusFrame::NEUTRAL;

    fn parse(bytes: &[u8]) -> Result<Self, DbusError> {
        DbusFrame::parse(bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::time::{Duration, Instant};

    /// Encodes a frame the way the DR16 does (the inverse of `parse`, written independently).
    fn encode(ch: [u16; 4], s_left: u8, s_right: u8, mouse: [i16; 3], keys: u16) -> [u8; 18] {
        let mut bits: u64 = 0;
        for (i, c) in ch.iter().enumerate() {
            bits |= u64::from(*c) << (11 * i);
        }
        bits |= u64::from(s_right) << 44 | u64::from(s_left) << 46;
        let mut b = [0u8; 18];
        for (i, byte) in b.iter_mut().take(6).enumerate() {
            *byte = (bits >> (8 * i)) as u8;
        }
        for (k, m) in mouse.iter().enumerate() {
            b[6 + 2 * k..8 + 2 * k].copy_from_slice(&m.to_le_bytes());
        }
        b[14..16].copy_from_slice(&keys.to_le_bytes());
        b[16..18].copy_from_slice(&1024u16.to_le_bytes());
        b
    }

    #[test]
    fn centred_sticks_switches_mouse_and_keys_decode() {
        let b = encode([1024; 4], 3, 1, [0; 3], 0);
        let f = DbusFrame::parse(&b).unwrap();
        assert_eq!(f.sticks, [1024; 4]);
        assert_eq!(
            (f.left_switch, f.right_switch),
            (Switch::Middle, Switch::Up)
        );
        let b = encode(
            [1684, 364, 1354, 694],
            2,
            3,
            [-5, 300, 1],
            Keys::W | Keys::SHIFT,
        );
        let f = DbusFrame::parse(&b).unwrap();
        assert_eq!(f.sticks, [1684, 364, 1354, 694]);
        assert_eq!(
            (f.left_switch, f.right_switch),
            (Switch::Down, Switch::Middle)
        );
        assert_eq!(f.mouse, [-5, 300, 1]);
        assert!(f.keys.held(Keys::W | Keys::SHIFT) && !f.keys.held(Keys::S));
        assert_eq!(f.stick(0, 0.0), 1.0);
        assert_eq!(f.stick(1, 0.0), -1.0);
        assert!((f.stick(2, 0.0) - 0.5).abs() < 1e-6); // (1354 − 1024) / 660
        assert_eq!(f.wheel, 1024);
    }

    #[test]
    fn the_dji_example_frame_decodes() {
        // A frame as the DR16 sends it with both sticks centred and both switches in the
        // middle: bytes worked out by hand from 1024 = 0b100_0000_0000 per channel.
        let b = [
            0x00, 0x04, 0x20, 0x00, 0x01, 0xF8, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x04,
        ];
        let f = DbusFrame::parse(&b).unwrap();
        assert_eq!(f.sticks, [1024; 4]);
        assert_eq!(
            (f.left_switch, f.right_switch),
            (Switch::Middle, Switch::Middle)
        );
    }

    #[test]
    fn mouse_buttons_and_wheel_come_from_bytes_12_to_17() {
        let mut b = encode([1024; 4], 3, 3, [0; 3], 0);
        // Left button only (byte 12), then right only (byte 13); the wheel at 1684 in bytes
        // 16–17, little-endian: 0x694 → 94 06.
        b[12] = 1;
        b[16..18].copy_from_slice(&[0x94, 0x06]);
        let f = DbusFrame::parse(&b).unwrap();
        assert!(f.mouse_left && !f.mouse_right);
        assert_eq!(f.wheel, 1684);
        b[12] = 0;
        b[13] = 1;
        let f = DbusFrame::parse(&b).unwrap();
        assert!(!f.mouse_left && f.mouse_right);
    }

    #[test]
    fn sticks_a_little_past_full_scale_are_accepted_and_read_as_full_scale() {
        // DJI's examples reject a channel only beyond ±700 from 1024: 1724 and 324 are the
        // last values kept, 1725 and 323 the first refused.
        let f = DbusFrame::parse(&encode([1724, 324, 1700, 1024], 1, 1, [0; 3], 0)).unwrap();
        assert_eq!(f.sticks, [1724, 324, 1700, 1024]);
        assert_eq!(
            (f.stick(0, 0.0), f.stick(1, 0.0), f.stick(2, 0.0)),
            (1.0, -1.0, 1.0)
        );
        for bad in [[1725, 1024, 1024, 1024], [1024, 1024, 1024, 323]] {
            assert_eq!(
                DbusFrame::parse(&encode(bad, 1, 1, [0; 3], 0)),
                Err(DbusError::StickOutOfRange)
            );
        }
    }

    #[test]
    fn garbage_is_rejected() {
        assert_eq!(DbusFrame::parse(&[0; 17]), Err(DbusError::WrongLength(17)));
        assert_eq!(DbusFrame::parse(&[0; 18]), Err(DbusError::StickOutOfRange));
        let bad_switch = encode([1024; 4], 0, 1, [0; 3], 0);
        assert_eq!(DbusFrame::parse(&bad_switch), Err(DbusError::InvalidSwitch));
    }

    #[test]
    fn byte_stream_with_a_dropped_byte_resyncs_on_the_next_frame() {
        let mut rx = DbusReceiver::new(Duration::from_millis(100));
        let frame = encode([1354, 1024, 1024, 1024], 1, 1, [0; 3], 0);
        let mut t = 0u64;
        let mut decoded = 0;
        for k in 0..5 {
            for (i, byte) in frame.iter().enumerate() {
                if k == 1 && i == 7 {
                    continue; // a byte lost on the wire
                }
                t += 110;
                if let Some(Ok(_)) = rx.push_byte(*byte, Instant::from_micros(t)) {
                    decoded += 1;
                }
            }
            t += 12_000; // the gap between frames
        }
        // The last frame is proven whole by the silence after it.
        if let Some(Ok(_)) = rx.poll(Instant::from_micros(t)) {
            decoded += 1;
        }
        assert_eq!(decoded, 4);
        assert_eq!(rx.link().errors(), 1);
        assert!((rx.signal(Instant::from_micros(t)).value.stick(0, 0.0) - 0.5).abs() < 1e-6);
    }

    #[test]
    fn a_byte_that_creeps_into_a_frame_drops_it_instead_of_shifting_it() {
        // Line noise adds 0xFF before byte 14 of a neutral frame. Read as the first 18 bytes,
        // the keyboard (bytes 14–15) would say 0x00FF: W, S, A, D, Shift, Ctrl, Q, E held.
        let mut rx = DbusReceiver::new(Duration::from_millis(100));
        let frame = encode([1024; 4], 3, 3, [0; 3], 0);
        let mut burst = frame.to_vec();
        burst.insert(14, 0xFF);
        let mut t = 1_000u64;
        for byte in &burst {
            t += 110;
            assert!(rx.push_byte(*byte, Instant::from_micros(t)).is_none());
        }
        let quiet = Instant::from_micros(t + 12_000);
        assert!(rx.poll(quiet).is_none());
        let s = rx.signal(quiet);
        assert!(s.lost);
        assert_eq!(s.value.keys, Keys(0));
        assert_eq!((rx.link().frames(), rx.link().errors()), (0, 1));
        // The next clean frame, 14 ms after the burst began, is read.
        t += 12_000;
        for byte in &frame {
            t += 110;
            assert!(rx.push_byte(*byte, Instant::from_micros(t)).is_none());
        }
        let s = rx.signal(Instant::from_micros(t + 2_501));
        assert!(!s.lost);
        assert_eq!(s.value.left_switch, Switch::Middle);
    }

    #[test]
    fn signal_loss_goes_neutral_after_timeout() {
        let mut rx = DbusReceiver::new(Duration::from_millis(100));
        let f = encode([1684, 1024, 1024, 1024], 1, 1, [0; 3], 0);
        rx.push_frame(&f, Instant::from_millis(0)).unwrap();
        assert!(!rx.signal(Instant::from_millis(100)).lost);
        let s = rx.signal(Instant::from_millis(101));
        assert!(s.lost);
        assert_eq!(s.value, DbusFrame::NEUTRAL);
        assert_eq!(s.value.stick(0, 0.0), 0.0);
    }
}
