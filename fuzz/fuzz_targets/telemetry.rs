//! Telemetry encoders (VOFA+ JustFloat and FireWater) and `Channels` with any values, names,
//! precision and buffer size. rc10-core's telemetry parses no input (it only encodes), so this
//! target checks the encoders against the two formats.
//!
//! Invariants: no panic; JustFloat is the values' little-endian bits (+inf, whose bits are
//! the tail, as f32::MAX) then 00 00 80 7F, and no value's bytes equal the tail, or
//! `BufferTooSmall` with the exact size when the buffer is smaller; FireWater is
//! `prefix:v1,...,vn\n` (no `prefix:` when empty) within the buffer, each value written with
//! the requested decimals (at most 65535, the formatter's limit) and reading back to the value
//! within half a unit of the last place, or as nan / inf / -inf; or `BufferTooSmall` with the
//! exact size of the line (more than the buffer's, and the line fits a buffer of that size).
//! `Channels` stores and encodes what was set.
#![no_main]

use arbitrary::{Arbitrary, Unstructured};
use libfuzzer_sys::fuzz_target;
use rc10_core::telemetry::{Channels, JUSTFLOAT_TAIL, firewater, justfloat};
use rc10_fuzz::input::f32_from;

static SCOPE: Channels<3> = Channels::new(["a", "b", "wheel_rpm"]);

fuzz_target!(|data: &[u8]| {
    let mut u = Unstructured::new(data);
    let n = usize::from(u8::arbitrary(&mut u).unwrap_or(0) % 12);
    let values: Vec<f32> = (0..n).map(|_| f32_from(&mut u).unwrap_or(0.0)).collect();
    // Mostly small buffers; sometimes one that holds 65535 decimals.
    let size = match u16::arbitrary(&mut u).unwrap_or(0) {
        n @ 0..=0xFFEF => usize::from(n % 2048),
        n => 65_500 + usize::from(n - 0xFFF0) * 100,
    };
    let decimals = u32::arbitrary(&mut u).unwrap_or(0) as usize;
    let prefix_len = usize::from(u8::arbitrary(&mut u).unwrap_or(0) % 16);
    let prefix_bytes = u.bytes(prefix_len.min(u.len())).unwrap_or(&[]);
    let prefix = String::from_utf8_lossy(prefix_bytes).into_owned();
    let mut out = vec![0u8; size];

    // JustFloat.
    let needed = 4 * values.len() + 4;
    match justfloat(&values, &mut out) {
        Ok(written) => {
            assert_eq!(written, needed);
            for (chunk, v) in out[..4 * n].chunks(4).zip(&values) {
                let sent = if *v == f32::INFINITY { f32::MAX } else { *v };
                assert_eq!(chunk, sent.to_le_bytes(), "value {v}");
                assert_ne!(chunk, JUSTFLOAT_TAIL, "a value that reads as the tail");
            }
            assert_eq!(out[4 * n..needed], JUSTFLOAT_TAIL);
        }
        Err(e) => {
            assert!(size < needed);
            assert_eq!(e.needed, needed);
        }
    }

    // FireWater.
    match firewater(&prefix, &values, decimals, &mut out) {
        Ok(written) => {
            assert!(written <= size);
            let line = std::str::from_utf8(&out[..written]).expect("FireWater is text");
            let body = line
                .strip_suffix('\n')
                .expect("FireWater ends with a newline");
            let body = if prefix.is_empty() {
                body
            } else {
                body.strip_prefix(&format!("{prefix}:"))
                    .expect("prefix and colon")
            };
            let fields: Vec<&str> = if values.is_empty() {
                Vec::new()
            } else {
                body.split(',').collect()
            };
            assert_eq!(fields.len(), values.len(), "{line:?}");
            for (field, v) in fields.iter().zip(&values) {
                if v.is_nan() {
                    assert_eq!(*field, "nan");
                } else if v.is_infinite() {
                    assert_eq!(*field, if *v < 0.0 { "-inf" } else { "inf" });
                } else {
                    let places = field.split_once('.').map_or(0, |(_, f)| f.len());
                    // Rust's formatter takes at most u16::MAX digits of precision.
                    let decimals = decimals.min(usize::from(u16::MAX));
                    assert_eq!(places, decimals, "{field} for {v}");
                    let back: f64 = field.parse().expect("a number");
                    let half_unit = 0.5 * 10f64.powi(-(decimals.min(400) as i32));
                    let tolerance = half_unit + f64::from(*v).abs() * 1e-7;
                    assert!((back - f64::from(*v)).abs() <= tolerance, "{field} for {v}");
                }
            }
        }
        Err(e) => {
            assert!(
                e.needed > size,
                "BufferTooSmall({}) with {size} bytes",
                e.needed
            );
            let mut exact = vec![0u8; e.needed];
            assert_eq!(
                firewater(&prefix, &values, decimals, &mut exact),
                Ok(e.needed),
                "the size BufferTooSmall names"
            );
        }
    }

    // Channels.
    for (i, v) in values.iter().enumerate() {
        assert_eq!(SCOPE.set(i, *v), i < 3);
    }
    if let Some(v) = values.first() {
        assert!(SCOPE.set_named("wheel_rpm", *v));
        assert!(!SCOPE.set_named(&prefix, *v) || SCOPE.names().contains(&prefix.as_str()));
        assert_eq!(SCOPE.get(2).map(f32::to_bits), Some(v.to_bits()));
    }
    let snapshot = SCOPE.snapshot();
    if let Ok(written) = SCOPE.encode_justfloat(&mut out) {
        assert_eq!(written, 16);
        for (chunk, v) in out[..12].chunks(4).zip(&snapshot) {
            let sent = if *v == f32::INFINITY { f32::MAX } else { *v };
            assert_eq!(chunk, sent.to_bits().to_le_bytes());
        }
    }
    assert_eq!(SCOPE.get(3), None);
});
