//! PPM (RC10_LIB's AirJoy): any sequence of pulse intervals with arrival times to an 8- and
//! a 2-channel receiver.
//!
//! Input: operations (tag byte): an interval (a channel width 750–2250 µs, a sync gap, or any
//! u32), time moving on, or reading the signal later.
//!
//! Invariants (PPM: channels 750–2250 µs between sync gaps of at least 2700 µs): no panic; a
//! frame is reported exactly when a sync ends a run of exactly N channel widths that began
//! with a sync, and holds those widths; an interval that is neither a width nor a sync is
//! reported as such; a run of the wrong length is reported with its length; the signal is
//! the last frame until 100 ms after it, then neutral (1500 µs); normalised channels are
//! finite and within [-1, 1] for any deadband.
#![no_main]

use arbitrary::{Arbitrary, Unstructured};
use libfuzzer_sys::fuzz_target;
use rc10_core::remote::ppm::{PpmError, PpmReceiver};
use rc10_core::time::{Duration, Instant};
use rc10_fuzz::remote::{LinkOracle, TIMEOUT_US};

fuzz_target!(|data: &[u8]| {
    let mut u = Unstructured::new(data);
    let mut rx8 = Rx::<8>::new();
    let mut rx2 = Rx::<2>::new();
    let mut now: u64 = 1_000_000;
    while !u.is_empty() {
        let tag = u8::arbitrary(&mut u).unwrap_or(0);
        let interval = match tag % 8 {
            0..=4 => 750 + u32::from(u16::arbitrary(&mut u).unwrap_or(0) % 1501),
            5 => 2700 + u32::from(u16::arbitrary(&mut u).unwrap_or(0)),
            6 => u32::arbitrary(&mut u).unwrap_or(0),
            _ => {
                let later = now.saturating_add(u64::from(u16::arbitrary(&mut u).unwrap_or(0)) * 8);
                if tag & 0x80 != 0 {
                    now = later;
                }
                rx8.check_signal(later);
                rx2.check_signal(later);
                continue;
            }
        };
        now = now.saturating_add(u64::from(interval));
        rx8.push(interval, now);
        rx2.push(interval, now);
    }
});

struct Rx<const N: usize> {
    rx: PpmReceiver<N>,
    oracle: LinkOracle<[u16; N]>,
    history: Vec<u32>,
}

const MIN_SYNC: u32 = 2700;

/// Deadbands tried on every channel read: none, typical, the edges, and non-finite.
const DEADBANDS: [f32; 7] = [0.0, 0.05, 0.99, 1.0, -1.0, f32::NAN, f32::INFINITY];

fn is_width(us: u32) -> bool {
    (750..=2250).contains(&us)
}

impl<const N: usize> Rx<N> {
    fn new() -> Self {
        Self {
            rx: PpmReceiver::new(Duration::from_micros(TIMEOUT_US)),
            oracle: LinkOracle::new(),
            history: Vec::new(),
        }
    }

    fn push(&mut self, interval: u32, now: u64) {
        self.history.push(interval);
        let result = self.rx.push_interval(interval, Instant::from_ticks(now));
        let h = &self.history;
        // [sync, N widths, sync] at the end: a frame of exactly those widths.
        let complete = h.len() >= N + 2
            && h[h.len() - N - 2] >= MIN_SYNC
            && h[h.len() - N - 1..h.len() - 1].iter().all(|w| is_width(*w))
            && interval >= MIN_SYNC;
        match result {
            Some(Ok(frame)) => {
                assert!(
                    complete,
                    "frame {frame:?} from intervals {:?}",
                    &h[h.len().saturating_sub(N + 2)..]
                );
                let widths: Vec<u16> = h[h.len() - N - 1..h.len() - 1]
                    .iter()
                    .map(|w| *w as u16)
                    .collect();
                assert_eq!(frame.as_slice(), widths.as_slice());
                // The frame ended where its sync gap began: the edge closing its last channel.
                self.oracle
                    .accept(frame, now.saturating_sub(u64::from(interval)));
            }
            Some(Err(PpmError::BadInterval(us))) => {
                assert!(!complete);
                assert_eq!(us, interval);
                assert!(!is_width(us) && us < MIN_SYNC, "{us} µs reported as bad");
            }
            Some(Err(PpmError::WrongChannelCount(n))) => {
                assert!(!complete, "a complete frame reported as {n} channels");
                assert!(interval >= MIN_SYNC && n != N, "{n} channels at a sync");
            }
            None => assert!(
                !complete,
                "a complete frame not reported: {:?}",
                &h[h.len() - N - 2..]
            ),
        }
        self.check_signal(now);
    }

    fn check_signal(&self, now: u64) {
        let at = Instant::from_ticks(now);
        let s = self.rx.signal(at);
        let (value, lost) = self.oracle.expect(now, [1500; N]);
        assert_eq!((s.value, s.lost), (value, lost), "signal at {now} µs");
        for i in 0..N + 2 {
            for deadband in DEADBANDS {
                let x = self.rx.channel(i, at, deadband);
                assert!(
                    x.is_finite() && (-1.0..=1.0).contains(&x),
                    "channel {i} = {x}"
                );
            }
        }
    }
}
