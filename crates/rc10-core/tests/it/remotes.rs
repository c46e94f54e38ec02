//! Remote-control decoding details mutation testing found unpinned: the DR16 keyboard bit
//! mask (DJI's DBUS protocol: W, S, A, D, Shift, Ctrl, Q, E, R, F, G, Z, X, C, V, B in bits
//! 0–15), SBUS channel scaling, and the tracking differentiator's smoothing of a step.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use rc10_core::pid::TrackingDifferentiator;
use rc10_core::remote::dbus::Keys;
use rc10_core::remote::sbus::SbusFrame;

#[test]
fn dr16_key_bits_follow_the_dbus_protocol() {
    let keys = [
        Keys::W,
        Keys::S,
        Keys::A,
        Keys::D,
        Keys::SHIFT,
        Keys::CTRL,
        Keys::Q,
        Keys::E,
        Keys::R,
        Keys::F,
        Keys::G,
        Keys::Z,
        Keys::X,
        Keys::C,
        Keys::V,
        Keys::B,
    ];
    for (bit, key) in keys.into_iter().enumerate() {
        assert_eq!(key, 1u16 << bit, "key {bit}");
    }
    let held = Keys(Keys::W | Keys::SHIFT);
    assert!(held.held(Keys::W));
    assert!(held.held(Keys::W | Keys::SHIFT));
    assert!(!held.held(Keys::W | Keys::S), "S is not held");
    assert!(!Keys(Keys::W).held(Keys::S));
}

/// An SBUS frame with every channel at `raw` (11 bits each, little-endian bit order).
fn sbus_all(raw: u16) -> [u8; 25] {
    let mut f = [0u8; 25];
    f[0] = 0x0F;
    for ch in 0..16 {
        for b in 0..11 {
            if raw >> b & 1 == 1 {
                let bit = ch * 11 + b;
                f[1 + bit / 8] |= 1 << (bit % 8);
            }
        }
    }
    f
}

#[test]
fn sbus_channels_scale_around_992() {
    // OpenTX/EdgeTX: 992 is centre (0), 172 and 1811 full scale (−1, +1); ±100 % is 819.2
    // counts, so −50 % is 992 − 409.6.
    let centre = SbusFrame::parse(&sbus_all(992)).unwrap();
    assert_eq!(centre.channel(0, 0.0), 0.0);
    assert_eq!(centre.channel(15, 0.0), 0.0);
    let top = SbusFrame::parse(&sbus_all(1811)).unwrap();
    assert_eq!(top.channel(3, 0.0), 1.0);
    let bottom = SbusFrame::parse(&sbus_all(172)).unwrap();
    assert_eq!(bottom.channel(3, 0.0), -1.0);
    let half_down = SbusFrame::parse(&sbus_all(992 - 410)).unwrap();
    assert!((half_down.channel(7, 0.0) + 0.5).abs() < 1e-3);
}

#[test]
fn tracking_differentiator_smooths_a_step() {
    // r = 50 rad/s: a critically damped second-order tracker (time constant 20 ms). One
    // 1 ms step after the input jumps 0 -> 1 it has barely moved (≈ r²t²/2 = 0.00125), and
    // half a second later it has arrived.
    let mut td = TrackingDifferentiator::new(50.0).unwrap();
    td.update(0.0, 0.001);
    let (x1, _) = td.update(1.0, 0.001);
    assert!(x1 < 0.01, "{x1}");
    let mut x = x1;
    for _ in 0..500 {
        x = td.update(1.0, 0.001).0;
    }
    assert!((x - 1.0).abs() < 1e-3, "{x}");
    // A 10 ms tick is still tracked, not jumped (the continuous tracker is at
    // 1 - e^(-0.5)·1.5 = 0.09 after 10 ms); only a gap beyond 8 integration steps of 1/r
    // (160 ms) restarts it at the input.
    let mut td = TrackingDifferentiator::new(50.0).unwrap();
    td.update(0.0, 0.01);
    let (x1, _) = td.update(1.0, 0.01);
    assert!(x1 < 0.2, "{x1}");
    let (x1, rate) = td.update(3.0, 0.2);
    assert_eq!(
        (x1, rate),
        (3.0, 0.0),
        "after a long gap: restarted at the input"
    );
}

#[test]
fn sbus_frame_lost_flag_is_bit_2_of_the_flags_byte() {
    use rc10_core::remote::ReceiverFrame;
    let mut f = sbus_all(992);
    assert!(!SbusFrame::parse(&f).unwrap().frame_lost());
    f[23] = 0x04;
    let lost = SbusFrame::parse(&f).unwrap();
    assert!(lost.frame_lost());
    assert!(!lost.failsafe());
}
