//! Remote-control receivers: DJI DR16 (DBUS), SBUS and PPM (RC10_LIB's AirJoy), as pure
//! parsers fed with bytes or pulse widths and their arrival time, plus a [`Link`] that turns
//! "no valid frame for a while" into neutral outputs and a flag.
//!
//! The parsers do no I/O: the STM32 adapter (or a test) feeds them from a UART or timer
//! capture. Malformed input is counted and ignored, never parsed into a command.

pub mod dbus;
pub mod ppm;
pub mod sbus;

use crate::time::{Duration, Instant};

/// The latest valid input of a receiver, or neutral after the signal is lost.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Signal<T> {
    /// The last valid frame, or, while the link is lost, the neutral value the link was
    /// made with (a receiver's neutral frame, or the failsafe values it was built with).
    pub value: T,
    /// Whether the link is lost (no fresh valid frame within the timeout, or the receiver
    /// itself reported failsafe). A frame the receiver flags as a repeat of old values (SBUS
    /// "frame lost") is not fresh.
    pub lost: bool,
}

/// Tracks one receiver link: the last valid frame, when it arrived, and counters.
///
/// ```
/// use rc10_core::remote::Link;
/// use rc10_core::time::{Duration, Instant};
/// let mut link = Link::new(0u16, Duration::from_millis(100));
/// link.accept(42, Instant::from_millis(10));
/// assert_eq!(link.signal(Instant::from_millis(50)).value, 42);
/// let later = link.signal(Instant::from_millis(111));
/// assert!(later.lost);
/// assert_eq!(later.value, 0); // neutral
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Link<T> {
    neutral: T,
    last: T,
    last_valid: Option<Instant>,
    failsafe: bool,
    timeout: Duration,
    frames: u32,
    errors: u32,
}

impl<T: Copy> Link<T> {
    /// A link that reports `neutral` until the first frame and after `timeout` of silence.
    pub const fn new(neutral: T, timeout: Duration) -> Self {
        Self {
            neutral,
            last: neutral,
            last_valid: None,
            failsafe: false,
            timeout,
            frames: 0,
            errors: 0,
        }
    }

    /// Records a valid frame received at `now`.
    pub fn accept(&mut self, frame: T, now: Instant) {
        self.last = frame;
        self.last_valid = Some(now);
        self.failsafe = false;
        self.frames = self.frames.wrapping_add(1);
    }

    /// Records a valid frame that only repeats old values (the receiver missed the
    /// transmitter's frame: SBUS "frame lost"). Its values are kept while the link is live,
    /// but it does not restart the timeout: a receiver that goes on repeating after the
    /// transmitter is gone (as many do until their own failsafe delay, or for ever in "hold"
    /// mode) does not keep the robot acting on stale commands.
    pub fn hold(&mut self, frame: T) {
        // Shown only while the link is live (a failsafe or timed-out link shows neutral, and
        // the next fresh frame replaces it).
        self.last = frame;
        self.frames = self.frames.wrapping_add(1);
    }

    /// Records that the receiver itself reports failsafe (SBUS flag): outputs go to the
    /// link's neutral value at once, without waiting for the timeout.
    pub fn failsafe(&mut self, now: Instant) {
        self.failsafe = true;
        self.last_valid = Some(now);
    }

    /// Counts a malformed frame (it changes nothing else).
    pub fn reject(&mut self) {
        self.errors = self.errors.wrapping_add(1);
    }

    /// The value to act on at `now`: the last valid frame while it is at most the timeout
    /// old. A frame stamped after `now` (by another task a moment later) counts as fresh
    /// while it is at most the timeout ahead; one further ahead is no sign of a live link (a
    /// clock or stamping fault) and does not hold the link alive: the signal is lost. (This
    /// does not change the link: such a frame reads fresh again, with its old values, from
    /// the timeout before its stamp to the timeout after it.)
    pub fn signal(&self, now: Instant) -> Signal<T> {
        let fresh = self.last_valid.is_some_and(|t| {
            let apart = now
                .checked_duration_since(t)
                .or_else(|| t.checked_duration_since(now));
            apart.is_some_and(|d| d <= self.timeout)
        });
        if fresh && !self.failsafe {
            Signal {
                value: self.last,
                lost: false,
            }
        } else {
            Signal {
                value: self.neutral,
                lost: true,
            }
        }
    }

    /// Valid frames received (fresh ones and held repeats).
    pub const fn frames(&self) -> u32 {
        self.frames
    }

    /// Malformed frames rejected.
    pub const fn errors(&self) -> u32 {
        self.errors
    }
}

/// What feeding one byte to a [`GapFramer`] produced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Framed<const N: usize> {
    /// Nothing complete yet.
    Pending,
    /// The byte came after a gap that proves the `N` bytes before it a whole frame (nothing
    /// followed them), with the time of the frame's last byte; the byte starts the next frame.
    Frame([u8; N], Instant),
    /// The byte came after a gap that cut the previous frame short; it starts a new frame.
    /// The short frame is dropped.
    Truncated,
    /// The byte came without a gap after `N` bytes: the burst is longer than a frame (a byte
    /// crept in, or it is not this protocol). The burst is dropped up to the next gap: its
    /// first `N` bytes are not a frame, whatever they would parse as.
    Overlong,
}

/// Assembles fixed-length frames from a byte stream whose frames are separated by silence on
/// the line (DBUS, SBUS). A frame is exactly `N` bytes between two silences longer than
/// `gap`:
/// - a byte arriving more than `gap` after the previous one starts a new frame, so a lost
///   byte costs one frame, not all that follow;
/// - `N` bytes are a frame only once the silence after them is seen (the next byte comes
///   after a gap, or [`poll`](Self::poll) finds the line quiet for more than `gap`): a byte
///   that crept into a frame (line noise) makes the burst `N + 1` long, and it is dropped
///   rather than read shifted by one byte (DBUS has no checksum: a shifted frame can parse
///   as phantom keys or a mouse click).
#[derive(Debug, Clone)]
pub struct GapFramer<const N: usize> {
    buf: [u8; N],
    len: usize,
    /// Dropping an overlong burst until the next gap (`len` stays 0 meanwhile).
    discarding: bool,
    last_byte: Option<Instant>,
    gap: Duration,
}

impl<const N: usize> GapFramer<N> {
    /// A framer for `N`-byte frames separated by more than `gap`.
    pub const fn new(gap: Duration) -> Self {
        Self {
            buf: [0; N],
            len: 0,
            discarding: false,
            last_byte: None,
            gap,
        }
    }

    /// Feeds one byte received at `now`.
    pub fn push(&mut self, byte: u8, now: Instant) -> Framed<N> {
        // Time going backwards counts as a gap.
        let after_gap = self
            .last_byte
            .is_none_or(|t| now.checked_duration_since(t).is_none_or(|d| d > self.gap));
        let previous = self.last_byte.replace(now);
        let mut framed = Framed::Pending;
        if after_gap {
            // (While a burst is dropped, `len` stays 0: nothing to report.)
            if self.len == N
                && let Some(at) = previous
            {
                framed = Framed::Frame(self.buf, at);
            } else if self.len > 0 {
                framed = Framed::Truncated;
            }
            self.len = 0;
            self.discarding = false;
        } else if self.discarding {
            return Framed::Pending;
        } else if self.len == N {
            self.len = 0;
            self.discarding = true;
            return Framed::Overlong;
        }
        if let Some(slot) = self.buf.get_mut(self.len) {
            *slot = byte;
            #[allow(
                clippy::arithmetic_side_effects,
                reason = "len < N: the slot at len exists"
            )]
            {
                self.len += 1;
            }
        }
        framed
    }

    /// The frame the line's silence has proven whole by `now`: `N` bytes received, the last
    /// more than `gap` before `now`, nothing after them. Returns it (with its last byte's time)
    /// once.
    pub fn poll(&mut self, now: Instant) -> Option<([u8; N], Instant)> {
        let at = self.last_byte?;
        let quiet = now.checked_duration_since(at).is_some_and(|d| d > self.gap);
        // (While a burst is dropped, `len` stays 0.)
        if self.len == N && quiet {
            self.len = 0;
            Some((self.buf, at))
        } else {
            None
        }
    }
}

/// A fixed-length receiver frame format (DBUS, SBUS).
pub trait ReceiverFrame: Copy {
    /// Why a frame is rejected.
    type Error;
    /// What a lost link reports.
    const NEUTRAL: Self;
    /// Decodes one frame.
    fn parse(bytes: &[u8]) -> Result<Self, Self::Error>;
    /// Whether the receiver itself reports failsafe in this frame.
    fn failsafe(&self) -> bool {
        false
    }
    /// Whether the receiver reports a frame lost between transmitter and receiver.
    fn frame_lost(&self) -> bool {
        false
    }
}

/// Silence that ends a frame of a DBUS or SBUS stream. The bytes of a frame are 110–120 µs
/// apart; the silence between frames is 12 ms on DBUS (an 18-byte frame every 14 ms) and at
/// least 4 ms on SBUS (a 25-byte frame every 7 ms at the fastest; a source with less than
/// 2.5 ms of silence between frames cannot be framed: its bursts merge and are dropped as too
/// long). 2.5 ms sits between them
/// and leaves the UART task 2.3 ms to be late with the second half of a frame the DMA split
/// (its bytes are stamped back from when they were read; see [`Shared::push_bytes_ending_at`]).
pub const FRAME_GAP: Duration = Duration::from_micros(2500);

/// A receiver of `N`-byte frames of type `F`, fed byte by byte (UART RX interrupt or DMA
/// chunks, framed by line silence: [`GapFramer`]) or frame by frame (a burst known to be
/// whole); see [`dbus::DbusReceiver`] and [`sbus::SbusReceiver`].
///
/// Fed byte by byte, a frame counts once the silence after it proves it whole: when the
/// next frame's first byte arrives, or when [`signal`](Self::signal) or
/// [`poll`](Self::poll) runs more than [`FRAME_GAP`] (2.5 ms) after its last byte. Read at
/// 1 kHz, a frame is acted on 2.5–3.5 ms after its last byte's stamp (with the DMA adapter,
/// when the chunk holding it was read: add the idle-line detection, about one byte time, and
/// the UART task's lateness); a burst with a byte too many
/// is dropped and counted, never read shifted.
#[derive(Debug, Clone)]
pub struct FrameReceiver<F: ReceiverFrame, const N: usize> {
    framer: GapFramer<N>,
    link: Link<F>,
    frames_lost: u32,
}

impl<F: ReceiverFrame, const N: usize> FrameReceiver<F, N> {
    /// A receiver that goes neutral after `timeout` without a valid frame (100 ms is a sensible
    /// timeout for both DBUS and SBUS).
    pub const fn new(timeout: Duration) -> Self {
        Self::with_failsafe(timeout, F::NEUTRAL)
    }

    /// A receiver that reports `failsafe` instead of [`ReceiverFrame::NEUTRAL`] before the
    /// first frame, after `timeout` without a valid frame and while the receiver reports
    /// failsafe: the values this robot is safe with (an SBUS mode switch at the position that
    /// disarms, where the neutral frame centres every channel). [`Signal::lost`] says it is
    /// the failsafe either way.
    ///
    /// ```
    /// use rc10_core::remote::sbus::{SbusFrame, SbusReceiver};
    /// use rc10_core::time::{Duration, Instant};
    /// let mut failsafe = SbusFrame::NEUTRAL;
    /// failsafe.channels[4] = 172; // channel 5, the arming switch: low
    /// let mut rx = SbusReceiver::with_failsafe(Duration::from_millis(100), failsafe);
    /// let s = rx.signal(Instant::from_millis(5));
    /// assert!(s.lost);
    /// assert_eq!(s.value.channel(4, 0.0), -1.0);
    /// ```
    pub const fn with_failsafe(timeout: Duration, failsafe: F) -> Self {
        Self {
            framer: GapFramer::new(FRAME_GAP),
            link: Link::new(failsafe, timeout),
            frames_lost: 0,
        }
    }

    /// Feeds one byte received at `now`; returns the frame that the gap before this byte
    /// proved whole, if any (counted at its last byte's time).
    pub fn push_byte(&mut self, byte: u8, now: Instant) -> Option<Result<F, F::Error>> {
        match self.framer.push(byte, now) {
            Framed::Frame(frame, at) => Some(self.push_frame(&frame, at)),
            // A frame cut short by a gap, or a burst longer than a frame.
            Framed::Truncated | Framed::Overlong => {
                self.link.reject();
                None
            }
            Framed::Pending => None,
        }
    }

    /// Takes the frame whose last byte came more than [`FRAME_GAP`] before `now` with nothing
    /// after it (the silence proves it whole), if one waits: returns it as
    /// [`push_byte`](Self::push_byte) would have. [`signal`](Self::signal) calls this first.
    pub fn poll(&mut self, now: Instant) -> Option<Result<F, F::Error>> {
        let (frame, at) = self.framer.poll(now)?;
        Some(self.push_frame(&frame, at))
    }

    /// Feeds a whole frame received at `now`. A frame in which the receiver reports failsafe
    /// sends the outputs neutral (or to the failsafe frame) at once; one it flags as a repeat
    /// of old values ([`ReceiverFrame::frame_lost`]) does not restart the timeout
    /// ([`Link::hold`]).
    pub fn push_frame(&mut self, bytes: &[u8], now: Instant) -> Result<F, F::Error> {
        let parsed = F::parse(bytes);
        match &parsed {
            Ok(frame) if frame.failsafe() => self.link.failsafe(now),
            Ok(frame) if frame.frame_lost() => {
                self.frames_lost = self.frames_lost.wrapping_add(1);
                self.link.hold(*frame);
            }
            Ok(frame) => self.link.accept(*frame, now),
            Err(_) => self.link.reject(),
        }
        parsed
    }

    /// The frame to act on at `now` (neutral, or the failsafe frame this receiver was built
    /// [`with_failsafe`](Self::with_failsafe), if lost or in failsafe), after taking a frame
    /// the line's silence has proven whole by `now` ([`poll`](Self::poll)).
    pub fn signal(&mut self, now: Instant) -> Signal<F> {
        let _ = self.poll(now);
        self.link.signal(now)
    }

    /// The link's counters.
    pub const fn link(&self) -> &Link<F> {
        &self.link
    }

    /// Frames the receiver flagged as lost between transmitter and receiver.
    pub const fn frames_lost(&self) -> u32 {
        self.frames_lost
    }
}

/// Maps a raw channel value to −1…1 around `center` with `half_range` counts to full scale,
/// clamped, with a `deadband` (fraction of full scale) around the centre.
pub fn normalize(raw: u16, center: u16, half_range: u16, deadband: f32) -> f32 {
    if half_range == 0 {
        return 0.0;
    }
    let x = (f32::from(raw) - f32::from(center)) / f32::from(half_range);
    let x = crate::math::constrain(x, -1.0, 1.0);
    let db = crate::math::constrain(deadband, 0.0, 0.99);
    if x.abs() <= db {
        0.0
    } else {
        // Rescale so the output still reaches ±1 and starts from 0 at the band's edge.
        x.signum() * (x.abs() - db) / (1.0 - db)
    }
}

/// A receiver shared between the task that feeds it bytes (UART DMA, an edge interrupt) and
/// the tasks that read its signal, in a `static`. Each access holds a critical section for
/// one call: a reader's few instructions, or a feeder's whole chunk (a 64-byte DMA chunk and
/// the up to three frames it completes: some microseconds, tens at most, on a 170 MHz G4; not
/// measured).
///
/// ```
/// use rc10_core::remote::Shared;
/// use rc10_core::remote::dbus::DbusReceiver;
/// use rc10_core::time::{Duration, Instant};
/// static DR16: Shared<DbusReceiver> = Shared::new(DbusReceiver::new(Duration::from_millis(100)));
/// // UART task: DR16.push_bytes_ending_at(&chunk, now, byte_time). Control task:
/// let sticks = DR16.with(|r| r.signal(Instant::from_millis(5)).value);
/// assert_eq!(sticks.stick(0, 0.0), 0.0); // nothing received yet: neutral
/// ```
pub struct Shared<R> {
    inner: embassy_sync::blocking_mutex::Mutex<
        embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex,
        core::cell::RefCell<R>,
    >,
    input_errors: core::sync::atomic::AtomicU32,
}

impl<R> Shared<R> {
    /// Wraps `receiver`.
    pub const fn new(receiver: R) -> Self {
        Self {
            inner: embassy_sync::blocking_mutex::Mutex::new(core::cell::RefCell::new(receiver)),
            input_errors: core::sync::atomic::AtomicU32::new(0),
        }
    }

    /// Runs `f` on the receiver under the lock.
    pub fn with<T>(&self, f: impl FnOnce(&mut R) -> T) -> T {
        self.inner.lock(|cell| f(&mut cell.borrow_mut()))
    }

    /// Counts an error of the input below the decoder (UART framing, parity or overrun
    /// errors): the bytes were lost, the decoder resynchronises on its own.
    pub fn record_input_error(&self) {
        self.input_errors
            .fetch_add(1, core::sync::atomic::Ordering::Relaxed);
    }

    /// Input errors counted so far.
    pub fn input_errors(&self) -> u32 {
        self.input_errors
            .load(core::sync::atomic::Ordering::Relaxed)
    }
}

impl<F: ReceiverFrame, const N: usize> Shared<FrameReceiver<F, N>> {
    /// Feeds bytes that all arrived at `now`: for bytes read one at a time (a UART RX
    /// interrupt). A DMA chunk holds bytes that arrived over up to 64 byte times: feed it with
    /// [`push_bytes_ending_at`](Self::push_bytes_ending_at). Stamped all at their read time,
    /// the second piece of a frame the DMA split looks as late as its whole length (plus the
    /// task's delay), and the frame is dropped once that exceeds the frame gap.
    pub fn push_bytes(&self, bytes: &[u8], now: Instant) {
        self.with(|r| {
            for b in bytes {
                let _ = r.push_byte(*b, now);
            }
        });
    }

    /// Feeds bytes of which the last arrived at `last_at`, each `byte_time` after the one
    /// before (a DMA chunk read as soon as it ended). Stamping them back keeps the bytes of a
    /// frame that the DMA split over two chunks less than a frame gap apart.
    pub fn push_bytes_ending_at(&self, bytes: &[u8], last_at: Instant, byte_time: Duration) {
        let n = u32::try_from(bytes.len()).unwrap_or(u32::MAX);
        self.with(|r| {
            for (i, b) in (0u32..).zip(bytes) {
                // Before the start of time (or an absurd byte time): stamped at time zero.
                let at = byte_time
                    .checked_mul(n.saturating_sub(1).saturating_sub(i))
                    .and_then(|back| last_at.checked_sub(back))
                    .unwrap_or(Instant::from_ticks(0));
                let _ = r.push_byte(*b, at);
            }
        });
    }
}

impl<R> core::fmt::Debug for Shared<R> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Shared")
            .field("input_errors", &self.input_errors())
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod shared_tests {
    use super::*;
    use crate::remote::dbus::DbusReceiver;

    /// A neutral DBUS frame: four sticks at 1024, both switches up (1), no mouse, no keys.
    fn neutral_dbus() -> [u8; 18] {
        let ch = [1024u64; 4];
        let bits = ch[0] | ch[1] << 11 | ch[2] << 22 | ch[3] << 33 | 1 << 44 | 1 << 46;
        let mut f = [0u8; 18];
        for (i, byte) in f.iter_mut().take(6).enumerate() {
            *byte = (bits >> (8 * i)) as u8;
        }
        f
    }

    #[test]
    fn a_frame_split_over_two_dma_chunks_is_still_one_frame() {
        let rx: Shared<DbusReceiver> = Shared::new(DbusReceiver::new(Duration::from_millis(100)));
        let frame = neutral_dbus();
        let byte = Duration::from_micros(110);
        // The DMA half-transfer point falls after byte 9: that chunk is read as it ends; the
        // rest at line idle, one byte time after its last byte.
        let t1 = Instant::from_millis(100);
        rx.push_bytes_ending_at(&frame[..9], t1, byte);
        let t2 = t1 + byte * 9 + byte;
        rx.push_bytes_ending_at(&frame[9..], t2, byte);
        // And the next frame, 14 ms later, in one chunk.
        let t3 = t1 + Duration::from_millis(14);
        rx.push_bytes_ending_at(&frame, t3, byte);
        // Its first byte proved the first frame whole; the silence after it, the second.
        assert_eq!(rx.with(|r| r.link().frames()), 1);
        assert!(rx.with(|r| r.poll(t3 + Duration::from_millis(3))).is_some());
        assert_eq!(rx.with(|r| r.link().frames()), 2);
        assert_eq!(rx.with(|r| r.link().errors()), 0);
        // An absurd byte time stamps the earlier bytes at time zero instead of panicking in
        // `Duration * u32` (it did).
        rx.push_bytes_ending_at(&frame, t3, Duration::from_ticks(u64::MAX / 2));
        // Stamping every byte of a chunk with its read time would have split that frame.
        let naive: Shared<DbusReceiver> =
            Shared::new(DbusReceiver::new(Duration::from_millis(100)));
        naive.push_bytes(&frame[..9], t1);
        naive.push_bytes(&frame[9..], t2 + Duration::from_millis(2));
        naive.push_bytes(&frame, t3);
        assert!(naive.with(|r| r.link().frames()) < 2);
        assert!(naive.with(|r| r.link().errors()) >= 1);
    }

    #[test]
    fn a_split_frame_survives_a_uart_task_two_ms_late() {
        // The second half of a split frame read 2.2 ms after the line went idle (the task
        // was busy): its bytes are stamped 2.2 ms late, 2.31 ms after the first half's last
        // byte (under the 2.5 ms gap). Still one frame.
        let rx: Shared<DbusReceiver> = Shared::new(DbusReceiver::new(Duration::from_millis(100)));
        let frame = neutral_dbus();
        let byte = Duration::from_micros(110);
        let t1 = Instant::from_millis(100);
        rx.push_bytes_ending_at(&frame[..9], t1, byte);
        let t2 = t1 + byte * 9 + Duration::from_micros(2200);
        rx.push_bytes_ending_at(&frame[9..], t2, byte);
        let _ = rx.with(|r| r.signal(t2 + Duration::from_millis(3)));
        assert_eq!(rx.with(|r| r.link().frames()), 1);
        assert_eq!(rx.with(|r| r.link().errors()), 0);
    }

    #[test]
    fn sbus_frames_at_the_fastest_rate_stay_apart() {
        // SBUS at 7 ms: 25 bytes of 120 µs (3 ms), then 4 ms of silence; a frame whose last
        // byte is missing is cut by that silence, and the next frame still decodes.
        let rx: Shared<sbus::SbusReceiver> =
            Shared::new(sbus::SbusReceiver::new(Duration::from_millis(100)));
        let byte = Duration::from_micros(120);
        let mut frame = [0u8; 25];
        frame[0] = 0x0F; // header; channels, flags and footer 0
        let start = Instant::from_millis(10);
        rx.push_bytes_ending_at(&frame[..24], start + byte * 23, byte);
        let next = start + Duration::from_millis(7);
        rx.push_bytes_ending_at(&frame, next + byte * 24, byte);
        let _ = rx.with(|r| r.signal(next + Duration::from_millis(7)));
        assert_eq!(rx.with(|r| r.link().frames()), 1);
        assert_eq!(rx.with(|r| r.link().errors()), 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failsafe_goes_neutral_immediately_and_frames_recover() {
        let mut link = Link::new(0i32, Duration::from_millis(100));
        link.accept(5, Instant::from_millis(0));
        link.failsafe(Instant::from_millis(1));
        assert_eq!(
            link.signal(Instant::from_millis(2)),
            Signal {
                value: 0,
                lost: true
            }
        );
        link.accept(7, Instant::from_millis(3));
        assert_eq!(link.signal(Instant::from_millis(4)).value, 7);
    }

    #[test]
    fn gap_framer_takes_exactly_n_bytes_between_silences() {
        let mut f = GapFramer::<3>::new(Duration::from_millis(1));
        let at = Instant::from_micros;
        assert_eq!(f.push(1, at(0)), Framed::Pending);
        assert_eq!(f.push(2, at(100)), Framed::Pending);
        // 2 ms of silence: the two bytes were a cut-short frame; 9 starts a new one.
        assert_eq!(f.push(9, at(2100)), Framed::Truncated);
        assert_eq!(f.push(8, at(2200)), Framed::Pending);
        // Three bytes: a frame only if silence follows.
        assert_eq!(f.push(7, at(2300)), Framed::Pending);
        assert_eq!(f.poll(at(3300)), None); // 1 ms of silence is not more than the gap
        // 6 comes after more than the gap: 9 8 7 were a frame, ending at 2300 µs.
        assert_eq!(f.push(6, at(3301)), Framed::Frame([9, 8, 7], at(2300)));
        assert_eq!(f.push(5, at(3400)), Framed::Pending);
        assert_eq!(f.push(4, at(3500)), Framed::Pending);
        // Or the line stays quiet: polled after more than the gap, 6 5 4 are a frame, once.
        assert_eq!(f.poll(at(4500)), None);
        assert_eq!(f.poll(at(4501)), Some(([6, 5, 4], at(3500))));
        assert_eq!(f.poll(at(9000)), None);
        assert_eq!(f.push(3, at(9000)), Framed::Pending); // the next frame starts afresh
        // A byte exactly the gap after the one before is still the same burst.
        assert_eq!(f.push(2, at(10_000)), Framed::Pending);
        assert_eq!(f.push(1, at(10_100)), Framed::Pending);
        assert_eq!(f.poll(at(11_101)), Some(([3, 2, 1], at(10_100))));
    }

    #[test]
    fn gap_framer_drops_a_burst_longer_than_a_frame() {
        let mut f = GapFramer::<3>::new(Duration::from_millis(1));
        let at = Instant::from_micros;
        assert_eq!(f.push(1, at(0)), Framed::Pending);
        assert_eq!(f.push(2, at(100)), Framed::Pending);
        assert_eq!(f.push(3, at(200)), Framed::Pending);
        // A fourth byte without a gap: 1 2 3 were not a frame.
        assert_eq!(f.push(4, at(300)), Framed::Overlong);
        // The rest of the burst is dropped with it (reported once), up to the next gap.
        assert_eq!(f.push(5, at(400)), Framed::Pending);
        assert_eq!(f.push(6, at(500)), Framed::Pending);
        assert_eq!(f.push(7, at(600)), Framed::Pending);
        assert_eq!(f.poll(at(5000)), None);
        // After the gap: a frame again.
        assert_eq!(f.push(7, at(6000)), Framed::Pending);
        assert_eq!(f.push(8, at(6100)), Framed::Pending);
        assert_eq!(f.push(9, at(6200)), Framed::Pending);
        assert_eq!(f.poll(at(7201)), Some(([7, 8, 9], at(6200))));
    }

    #[test]
    fn stamps_at_the_ends_of_time_neither_panic_nor_wrap() {
        let mut link = Link::new(0i32, Duration::from_millis(100));
        link.accept(5, Instant::from_ticks(u64::MAX));
        // A stamp at the end of time, read at its start: far ahead of `now`, so lost
        // (neutral), not fresh for ever.
        assert_eq!(
            link.signal(Instant::from_ticks(0)),
            Signal {
                value: 0,
                lost: true
            }
        );
        assert!(!link.signal(Instant::from_ticks(u64::MAX)).lost);
        let mut f = GapFramer::<3>::new(Duration::from_millis(1));
        assert_eq!(f.push(1, Instant::from_ticks(u64::MAX)), Framed::Pending);
        // Time going backwards is a gap.
        assert_eq!(f.push(2, Instant::from_ticks(0)), Framed::Truncated);
    }

    #[test]
    fn a_stamp_ahead_of_now_is_fresh_only_within_the_timeout() {
        // Stamped by the receive task a moment after the control task read its clock: fresh.
        // Stamped further ahead than the timeout (100 ms): lost.
        let mut link = Link::new(0i32, Duration::from_millis(100));
        link.accept(7, Instant::from_millis(1_100));
        let at = |ms| link.signal(Instant::from_millis(ms));
        assert_eq!(
            at(1_000),
            Signal {
                value: 7,
                lost: false
            }
        ); // 100 ms ahead
        assert_eq!(
            at(999),
            Signal {
                value: 0,
                lost: true
            }
        ); // 101 ms ahead
        assert_eq!(
            at(1_200),
            Signal {
                value: 7,
                lost: false
            }
        ); // 100 ms old
        assert_eq!(
            at(1_201),
            Signal {
                value: 0,
                lost: true
            }
        ); // 101 ms old
    }

    #[test]
    fn never_received_is_lost() {
        let link = Link::new(0u8, Duration::from_millis(100));
        assert!(link.signal(Instant::from_millis(0)).lost);
    }

    #[test]
    fn normalize_centre_ends_and_deadband() {
        assert_eq!(normalize(1024, 1024, 660, 0.0), 0.0);
        assert_eq!(normalize(1684, 1024, 660, 0.0), 1.0);
        assert_eq!(normalize(364, 1024, 660, 0.0), -1.0);
        assert_eq!(normalize(2000, 1024, 660, 0.0), 1.0); // clamped
        assert_eq!(normalize(1030, 1024, 660, 0.05), 0.0); // 0.009 inside the band
        // Near halfway between the band's edge (0.05) and 1: 346 / 660 = 0.52424, and
        // (0.52424 − 0.05) / 0.95 = 0.49920 (exactly half would need 346.5 counts).
        assert!((normalize(1024 + 346, 1024, 660, 0.05) - 0.49920).abs() < 1e-5);
    }
}
