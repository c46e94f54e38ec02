//! The DBUS and SBUS targets: whole frames to the parser, and byte streams with arrival times
//! to the receiver, checked against frame decoders written from the protocol and against
//! the link rule "the last valid frame while it is fresh, else neutral".

use arbitrary::{Arbitrary, Unstructured};
use core::fmt::Debug;
use rc10_core::remote::{FrameReceiver, ReceiverFrame, Shared};
use rc10_core::time::{Duration, Instant};

/// The receivers' link timeout in these targets.
pub const TIMEOUT_US: u64 = 100_000;

/// Bytes of one frame are at most this far apart: the receivers' frame gap, 2.5 ms (the
/// silence between DBUS frames is 12 ms, between SBUS frames at least 4 ms).
pub const GAP_US: u64 = 2500;

// The receivers' constant is the same rule: a change to one must be a change to both.
const _: () = assert!(rc10_core::remote::FRAME_GAP.as_micros() == GAP_US);

/// The gaps control bytes 0xF0–0xFB spell, µs: within a frame, around the frame gap, and
/// between frames.
const GAPS_US: [u64; 12] = [
    1000,
    2000,
    2400,
    GAP_US - 1,
    GAP_US,
    GAP_US + 1,
    3000,
    4000,
    6000,
    8000,
    10_000,
    12_000,
];

/// What the link should report at a time, from the frames accepted so far.
#[derive(Debug, Clone, Copy)]
pub struct LinkOracle<F> {
    /// Time of the last valid frame (or failsafe report), and the frame (`None`: failsafe).
    last: Option<(u64, Option<F>)>,
}

impl<F: Copy + PartialEq + Debug> LinkOracle<F> {
    /// Nothing received.
    pub const fn new() -> Self {
        Self { last: None }
    }

    /// A valid frame arrived at `now`.
    pub fn accept(&mut self, frame: F, now: u64) {
        self.last = Some((now, Some(frame)));
    }

    /// A valid frame flagged as repeating old values: its values while the link is live,
    /// without restarting the timeout.
    pub fn hold(&mut self, frame: F) {
        if let Some((t, Some(_))) = self.last {
            self.last = Some((t, Some(frame)));
        }
    }

    /// The receiver reported failsafe at `now`: neutral at once.
    pub fn failsafe(&mut self, now: u64) {
        self.last = Some((now, None));
    }

    /// The value and `lost` flag the link must report at `now`.
    pub fn expect(&self, now: u64, neutral: F) -> (F, bool) {
        match self.last {
            // Fresh within the timeout either side of `now` (a stamp further ahead is a
            // fault, not a live link).
            Some((t, Some(f))) if now.abs_diff(t) <= TIMEOUT_US => (f, false),
            _ => (neutral, true),
        }
    }
}

impl<F: Copy + PartialEq + Debug> Default for LinkOracle<F> {
    fn default() -> Self {
        Self::new()
    }
}

/// How a stream byte's arrival time is spelled in the input: a control byte before each data
/// byte. Below 0xF0: that many µs after the previous byte (a byte time is ~110 µs at
/// 100 kbit/s); 0xF0–0xFB: a gap of 1–12 ms (`GAPS_US`: both sides of the frame gap); 0xFC:
/// backwards by a u16 of µs; 0xFD: a whole
/// chunk through `Shared::push_bytes_ending_at` (length, byte time in µs, bytes); 0xFE: any
/// 64-bit time; 0xFF: read the signal at a time up to 255 ms later without a byte.
pub fn run_stream<F, const N: usize>(
    data: &[u8],
    parse: impl Fn(&[u8]) -> Option<F>,
    failsafe: impl Fn(&F) -> bool,
    neutral: F,
    check_frame: impl Fn(&F),
) where
    F: ReceiverFrame + PartialEq + Debug,
    F::Error: PartialEq + Debug,
{
    let mut u = Unstructured::new(data);
    let mut rx = FrameReceiver::<F, N>::new(Duration::from_micros(TIMEOUT_US));
    let shared: Shared<FrameReceiver<F, N>> =
        Shared::new(FrameReceiver::new(Duration::from_micros(TIMEOUT_US)));
    let mut oracle = LinkOracle::<F>::new();
    let mut framing = Framing::<N>::default();
    let mut now: u64 = 1_000_000;
    let settle =
        |oracle: &mut LinkOracle<F>, result: Result<F, F::Error>, bytes: &[u8], at: u64| {
            let expected = parse(bytes);
            match (&result, expected) {
                (Ok(f), Some(e)) => {
                    assert_eq!(*f, e, "frame {bytes:02X?} decoded wrongly");
                    check_frame(f);
                    if failsafe(f) {
                        oracle.failsafe(at);
                    } else if f.frame_lost() {
                        oracle.hold(*f);
                    } else {
                        oracle.accept(*f, at);
                    }
                }
                (Err(_), None) => {}
                (r, e) => panic!("frame {bytes:02X?}: parser says {r:?}, protocol says {e:?}"),
            }
            assert_eq!(
                F::parse(bytes),
                result,
                "stream and whole-frame parse differ"
            );
        };
    while !u.is_empty() {
        let Ok(ctl) = u8::arbitrary(&mut u) else {
            break;
        };
        match ctl {
            0..=0xEF => now = now.saturating_add(u64::from(ctl)),
            0xF0..=0xFB => {
                let gap = GAPS_US.get(usize::from(ctl - 0xF0)).copied().unwrap_or(0);
                now = now.saturating_add(gap);
            }
            0xFC => now = now.saturating_sub(u64::from(u16::arbitrary(&mut u).unwrap_or(0))),
            0xFD => {
                let len = usize::from(u8::arbitrary(&mut u).unwrap_or(0));
                let byte_us = u64::from(u16::arbitrary(&mut u).unwrap_or(0) % 10_000);
                let bytes = u.bytes(len.min(u.len())).unwrap_or(&[]);
                let at = Instant::from_ticks(now);
                shared.push_bytes_ending_at(bytes, at, Duration::from_micros(byte_us));
                // Whatever arrived, the signal is neutral or a valid frame.
                let s = shared.with(|r| r.signal(at));
                if s.lost {
                    assert_eq!(s.value, neutral, "lost link not neutral");
                } else {
                    check_frame(&s.value);
                    assert!(!failsafe(&s.value), "failsafe frame reported as live");
                }
                continue;
            }
            0xFE => now = u64::arbitrary(&mut u).unwrap_or(0),
            0xFF => {
                let later =
                    now.saturating_add(u64::from(u8::arbitrary(&mut u).unwrap_or(0)) * 1000);
                if let Some((bytes, at)) = framing.due_by(later) {
                    let result = rx.poll(Instant::from_ticks(later));
                    let result = result.expect("N bytes between two silences not taken as a frame");
                    settle(&mut oracle, result, &bytes, at);
                }
                assert!(
                    rx.poll(Instant::from_ticks(later)).is_none(),
                    "a frame the protocol does not frame"
                );
                check_signal(&mut rx, &oracle, later, neutral);
                continue;
            }
        }
        let Ok(byte) = u8::arbitrary(&mut u) else {
            break;
        };
        let due = framing.push(byte, now);
        match (rx.push_byte(byte, Instant::from_ticks(now)), due) {
            (Some(result), Some((bytes, at))) => settle(&mut oracle, result, &bytes, at),
            (None, None) => {}
            (r, d) => panic!("push_byte gave {r:?}; the protocol's framing gives {d:02X?}"),
        }
        check_signal(&mut rx, &oracle, now, neutral);
    }
}

/// The framing rule from the protocol: a frame is exactly `N` bytes between two silences
/// longer than the frame gap (time going backwards counts as one).
#[derive(Debug, Default)]
struct Framing<const N: usize> {
    /// The bytes since the last silence (or since the last frame was taken).
    burst: Vec<u8>,
    /// When the last byte came.
    last: Option<u64>,
}

impl<const N: usize> Framing<N> {
    /// A byte at `now`: the frame its silence proves whole, if any, with its last byte's time.
    fn push(&mut self, byte: u8, now: u64) -> Option<(Vec<u8>, u64)> {
        let after_gap = self.last.is_none_or(|t| now < t || now - t > GAP_US);
        let mut due = None;
        if after_gap {
            if self.burst.len() == N {
                due = self.last.map(|t| (std::mem::take(&mut self.burst), t));
            }
            self.burst.clear();
        }
        self.burst.push(byte);
        self.last = Some(now);
        due
    }

    /// The frame that the silence up to `now` proves whole, if any (taken once).
    fn due_by(&mut self, now: u64) -> Option<(Vec<u8>, u64)> {
        let t = self.last?;
        if self.burst.len() == N && now >= t && now - t > GAP_US {
            Some((std::mem::take(&mut self.burst), t))
        } else {
            None
        }
    }
}

fn check_signal<F, const N: usize>(
    rx: &mut FrameReceiver<F, N>,
    oracle: &LinkOracle<F>,
    now: u64,
    neutral: F,
) where
    F: ReceiverFrame + PartialEq + Debug,
{
    let s = rx.signal(Instant::from_ticks(now));
    let (value, lost) = oracle.expect(now, neutral);
    assert_eq!((s.value, s.lost), (value, lost), "signal at {now} µs");
}
