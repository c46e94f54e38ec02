//! DJI DR16 receiver frames (DBUS): 18-byte frames to the parser, and byte streams with
//! arrival times (byte by byte, and in DMA chunks) to the receiver.
//!
//! Input: byte 0 even: the rest is one frame for `DbusFrame::parse` (any length); odd: a
//! stream (see `rc10_fuzz::remote::run_stream`).
//!
//! Invariants (DR16 protocol: four 11-bit sticks little-endian in bits 0–43, right switch
//! bits 44–45, left switch 46–47, switch values 1 up / 3 middle / 2 down, mouse x/y/z i16 LE,
//! buttons, keys u16 LE, wheel): no panic; a frame is accepted exactly when it has 18 bytes,
//! every stick is within 324–1724 (±700 around 1024, the margin DJI's examples allow) and
//! both switches are valid, and then decodes to those
//! fields; normalised sticks are finite and within [-1, 1] for any deadband; a frame
//! completed from a stream is the last 18 bytes with no gap of silence inside; the signal is
//! the last valid frame until 100 ms after it, then neutral.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rc10_core::remote::dbus::{DbusFrame, Switch};
use rc10_fuzz::input::SPECIAL_F32;
use rc10_fuzz::remote::run_stream;

fuzz_target!(|data: &[u8]| {
    match data.split_first() {
        Some((mode, rest)) if mode % 2 == 0 => {
            let parsed = DbusFrame::parse(rest);
            match (parsed, decode(rest)) {
                (Ok(f), Some(e)) => {
                    assert_eq!(f, e, "{rest:02X?}");
                    check(&f);
                }
                (Err(_), None) => {}
                (p, e) => panic!("{rest:02X?}: parser {p:?}, protocol {e:?}"),
            }
        }
        Some((_, rest)) => run_stream::<DbusFrame, 18>(
            rest,
            decode,
            |_| false, // the DR16 has no failsafe flag: silence is its failsafe
            DbusFrame::NEUTRAL,
            check,
        ),
        None => {}
    }
});

/// The DR16 frame layout, decoded from the protocol.
fn decode(b: &[u8]) -> Option<DbusFrame> {
    let b: &[u8; 18] = b.try_into().ok()?;
    let mut bits = 0u64;
    for (i, byte) in b[..6].iter().enumerate() {
        bits |= u64::from(*byte) << (8 * i);
    }
    let stick = |i: u32| ((bits >> (11 * i)) & 0x7FF) as u16;
    let sticks = [stick(0), stick(1), stick(2), stick(3)];
    if sticks.iter().any(|s| !(324..=1724).contains(s)) {
        return None;
    }
    let switch = |v: u64| match v & 0b11 {
        1 => Some(Switch::Up),
        3 => Some(Switch::Middle),
        2 => Some(Switch::Down),
        _ => None,
    };
    let i16le = |i: usize| i16::from_le_bytes([b[i], b[i + 1]]);
    Some(DbusFrame {
        sticks,
        right_switch: switch(bits >> 44)?,
        left_switch: switch(bits >> 46)?,
        mouse: [i16le(6), i16le(8), i16le(10)],
        mouse_left: b[12] != 0,
        mouse_right: b[13] != 0,
        keys: rc10_core::remote::dbus::Keys(u16::from_le_bytes([b[14], b[15]])),
        wheel: u16::from_le_bytes([b[16], b[17]]) & 0x7FF,
    })
}

fn check(f: &DbusFrame) {
    for i in 0..6 {
        for deadband in SPECIAL_F32 {
            let x = f.stick(i, deadband);
            assert!(
                x.is_finite() && (-1.0..=1.0).contains(&x),
                "stick {i} = {x} (deadband {deadband})"
            );
            if i >= 4 {
                assert_eq!(x, 0.0, "stick {i} does not exist");
            }
        }
    }
}
