//! SBUS receiver frames: 25-byte frames to the parser, and byte streams with arrival times
//! (byte by byte, and in DMA chunks) to the receiver.
//!
//! Input: byte 0 even: the rest is one frame for `SbusFrame::parse` (any length); odd: a
//! stream (see `rc10_fuzz::remote::run_stream`).
//!
//! Invariants (SBUS: header 0x0F, sixteen 11-bit channels LSB first in bytes 1–22, flags in
//! byte 23 (bit 0 ch17, 1 ch18, 2 frame lost, 3 failsafe), footer 0x00 or SBUS2's 0x04,
//! 0x14, 0x24, 0x34): no
//! panic; a frame is accepted exactly when it has 25 bytes, the header and a valid footer,
//! and decodes to those fields; normalised channels are finite and within [-1, 1] for any
//! deadband; a frame completed from a stream is the last 25 bytes with no gap of silence
//! inside; the signal is the last valid frame until 100 ms after the last one not flagged
//! "frame lost", then neutral, and neutral at once after a frame with the failsafe flag.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rc10_core::remote::sbus::SbusFrame;
use rc10_fuzz::input::SPECIAL_F32;
use rc10_fuzz::remote::run_stream;

fuzz_target!(|data: &[u8]| {
    match data.split_first() {
        Some((mode, rest)) if mode % 2 == 0 => match (SbusFrame::parse(rest), decode(rest)) {
            (Ok(f), Some(e)) => {
                assert_eq!(f, e, "{rest:02X?}");
                check(&f);
            }
            (Err(_), None) => {}
            (p, e) => panic!("{rest:02X?}: parser {p:?}, protocol {e:?}"),
        },
        Some((_, rest)) => {
            run_stream::<SbusFrame, 25>(rest, decode, |f| f.failsafe, SbusFrame::NEUTRAL, check)
        }
        None => {}
    }
});

/// The SBUS frame layout, decoded from the protocol one bit at a time.
fn decode(b: &[u8]) -> Option<SbusFrame> {
    let b: &[u8; 25] = b.try_into().ok()?;
    if b[0] != 0x0F || ![0x00, 0x04, 0x14, 0x24, 0x34].contains(&b[24]) {
        return None;
    }
    let mut channels = [0u16; 16];
    for (i, ch) in channels.iter_mut().enumerate() {
        for k in 0..11 {
            let bit = 11 * i + k;
            if b[1 + bit / 8] >> (bit % 8) & 1 == 1 {
                *ch |= 1 << k;
            }
        }
    }
    Some(SbusFrame {
        channels,
        ch17: b[23] & 0x01 != 0,
        ch18: b[23] & 0x02 != 0,
        frame_lost: b[23] & 0x04 != 0,
        failsafe: b[23] & 0x08 != 0,
    })
}

fn check(f: &SbusFrame) {
    for i in 0..18 {
        for deadband in SPECIAL_F32 {
            let x = f.channel(i, deadband);
            assert!(
                x.is_finite() && (-1.0..=1.0).contains(&x),
                "channel {i} = {x} (deadband {deadband})"
            );
        }
    }
}
