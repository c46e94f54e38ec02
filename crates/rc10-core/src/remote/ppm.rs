//! PPM receivers (RC10_LIB's AirJoy): one pulse train per frame, each channel the time between
//! two rising edges (about 1000–2000 µs), frames separated by a long sync gap.

use super::{Link, Signal, normalize};
use crate::time::{Duration, Instant};
use core::fmt;

/// Shortest interval accepted as a channel, µs: the bound flight controllers' PPM inputs use
/// (Cleanflight and its descendants), so a transmitter whose endpoints are set beyond 100 %
/// still decodes at full throw.
pub const MIN_CHANNEL_US: u32 = 750;
/// Longest interval accepted as a channel, µs (see [`MIN_CHANNEL_US`]).
pub const MAX_CHANNEL_US: u32 = 2250;
/// Intervals at least this long are the sync gap between frames, µs.
pub const MIN_SYNC_US: u32 = 2700;

/// Why a PPM frame was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PpmError {
    /// An interval neither a channel nor a sync gap (noise); the frame is dropped.
    BadInterval(u32),
    /// A sync gap came after this many channels instead of the expected number.
    WrongChannelCount(usize),
}

impl fmt::Display for PpmError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BadInterval(us) => write!(f, "PPM interval of {us} µs is no channel"),
            Self::WrongChannelCount(n) => write!(f, "PPM frame with {n} channels"),
        }
    }
}

impl core::error::Error for PpmError {}

/// A PPM decoder for `N` channels, fed with the interval between successive rising edges
/// (from a timer input capture).
///
/// ```
/// use rc10_core::remote::ppm::PpmReceiver;
/// use rc10_core::time::{Duration, Instant};
/// let mut rx = PpmReceiver::<8>::new(Duration::from_millis(100));
/// let now = Instant::from_millis(20);
/// rx.push_interval(5000, now); // sync gap
/// for us in [1500, 1000, 2000, 1500, 1500, 1500, 1500, 1500] {
///     rx.push_interval(us, now);
/// }
/// let frame = rx.push_interval(5000, now).unwrap().unwrap(); // next sync ends the frame
/// assert_eq!(frame[2], 2000);
/// assert_eq!(rx.channel(1, now, 0.0), -1.0);
/// ```
#[derive(Debug, Clone)]
pub struct PpmReceiver<const N: usize> {
    current: [u16; N],
    count: usize,
    synced: bool,
    link: Link<[u16; N]>,
}

impl<const N: usize> PpmReceiver<N> {
    /// A decoder that goes neutral (all 1500 µs) after `timeout` without a valid frame. A
    /// frame counts from its last channel's edge, so the next one completes a frame period
    /// plus a sync gap later (about 37 ms for 22.5 ms frames): keep `timeout` well above
    /// that (100 ms is usual).
    pub const fn new(timeout: Duration) -> Self {
        Self::with_failsafe(timeout, [1500; N])
    }

    /// A decoder that reports `failsafe_us` (a pulse width in µs per channel) instead of
    /// 1500 µs everywhere before the first frame and after `timeout` without a valid frame:
    /// the values this robot is safe with (a throttle channel at its bottom, a mode switch
    /// at the position that disarms). [`Signal::lost`] says it is the failsafe either way.
    pub const fn with_failsafe(timeout: Duration, failsafe_us: [u16; N]) -> Self {
        Self {
            current: [1500; N],
            count: 0,
            synced: false,
            link: Link::new(failsafe_us, timeout),
        }
    }

    /// Feeds one interval in µs measured at `now` (the edge that ends it); returns the frame a
    /// sync gap completed. The link counts a frame from the edge that closed its last channel
    /// (`now − interval`, where the sync gap began), so a frame completed by pulses that
    /// stopped and came back after longer than the link timeout is already stale: the
    /// signal stays lost until the next frame.
    pub fn push_interval(
        &mut self,
        interval_us: u32,
        now: Instant,
    ) -> Option<Result<[u16; N], PpmError>> {
        if interval_us >= MIN_SYNC_US {
            let was_synced = self.synced;
            let count = self.count;
            self.synced = true;
            self.count = 0;
            if !was_synced {
                return None; // the first sync only starts counting
            }
            return Some(if count == N {
                // The frame ended at the edge that closed its last channel, where the sync
                // gap began: stamped there, a frame whose "sync" was pulses stopping and
                // coming back much later is as old as it is (a receiver set to "no pulses"
                // stops right after a frame; its last values must not come back as fresh).
                let ended = Duration::from_micros(u64::from(interval_us));
                let ended = now.checked_sub(ended).unwrap_or(Instant::from_ticks(0));
                self.link.accept(self.current, ended);
                Ok(self.current)
            } else {
                self.link.reject();
                Err(PpmError::WrongChannelCount(count))
            });
        }
        if !self.synced {
            return None;
        }
        if !(MIN_CHANNEL_US..=MAX_CHANNEL_US).contains(&interval_us) {
            self.synced = false; // wait for the next sync gap
            self.count = 0;
            self.link.reject();
            return Some(Err(PpmError::BadInterval(interval_us)));
        }
        match self.current.get_mut(self.count) {
            Some(slot) => *slot = interval_us as u16,
            None => {
                // More channels than expected: drop this frame at its sync.
            }
        }
        // Saturating: a stream of pulses that never sees a sync gap must not overflow.
        self.count = self.count.saturating_add(1);
        None
    }

    /// The channels to act on at `now`, in µs (if lost: 1500, or the failsafe values this
    /// decoder was built [`with_failsafe`](Self::with_failsafe)).
    pub fn signal(&self, now: Instant) -> Signal<[u16; N]> {
        self.link.signal(now)
    }

    /// Channel `i` at `now` in −1…1 (1000–2000 µs), with `deadband`; when lost, 0 (or the
    /// failsafe value's, for a decoder built [`with_failsafe`](Self::with_failsafe)).
    pub fn channel(&self, i: usize, now: Instant, deadband: f32) -> f32 {
        self.signal(now)
            .value
            .get(i)
            .map_or(0.0, |us| normalize(*us, 1500, 500, deadband))
    }

    /// The link's counters.
    pub const fn link(&self) -> &Link<[u16; N]> {
        &self.link
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn train(
        rx: &mut PpmReceiver<8>,
        channels: &[u32],
        now: Instant,
    ) -> Option<Result<[u16; 8], PpmError>> {
        let mut last = None;
        for us in channels {
            if let Some(r) = rx.push_interval(*us, now) {
                last = Some(r);
            }
        }
        rx.push_interval(6000, now).or(last)
    }

    /// An 8-channel receiver (100 ms timeout) that has seen a sync gap at 1 ms, and that time.
    fn synced() -> (PpmReceiver<8>, Instant) {
        let mut rx = PpmReceiver::<8>::new(Duration::from_millis(100));
        let t = Instant::from_millis(1);
        rx.push_interval(6000, t);
        (rx, t)
    }

    #[test]
    fn frames_between_syncs_decode_and_noise_drops_one_frame() {
        let (mut rx, t) = synced();
        let ok = [1100, 1200, 1300, 1400, 1500, 1600, 1700, 1800];
        assert_eq!(
            train(&mut rx, &ok, t),
            Some(Ok([1100, 1200, 1300, 1400, 1500, 1600, 1700, 1800]))
        );
        // A noise spike of 300 µs: the frame is dropped, the next one decodes.
        let noisy = [1100, 300, 1300];
        assert_eq!(
            train(&mut rx, &noisy, t),
            Some(Err(PpmError::BadInterval(300)))
        );
        assert_eq!(train(&mut rx, &ok, t).unwrap().unwrap()[7], 1800);
        assert_eq!(rx.link().errors(), 1);
    }

    #[test]
    fn endpoints_beyond_100_percent_decode_up_to_750_and_2250_us() {
        // A transmitter with its endpoints at 150 % of ±500 µs sends 750 µs at one end of the
        // stick and 2250 µs at the other; they read as full throw. One µs further is noise.
        let (mut rx, t) = synced();
        let wide = [750, 2250, 1500, 1500, 1500, 1500, 1500, 1500];
        assert_eq!(
            train(&mut rx, &wide, t),
            Some(Ok([750, 2250, 1500, 1500, 1500, 1500, 1500, 1500]))
        );
        assert_eq!(rx.channel(0, t, 0.0), -1.0);
        assert_eq!(rx.channel(1, t, 0.0), 1.0);
        for noise in [749, 2251] {
            let mut frame = wide;
            frame[4] = noise;
            assert_eq!(
                train(&mut rx, &frame, t),
                Some(Err(PpmError::BadInterval(noise)))
            );
        }
    }

    #[test]
    fn failsafe_pulse_widths_of_the_users_replace_1500_whenever_the_link_is_lost() {
        // Channel 3 is the throttle: its failsafe is the bottom (1000 µs), not mid-stick.
        let mut failsafe = [1500; 8];
        failsafe[2] = 1000;
        let mut rx = PpmReceiver::<8>::with_failsafe(Duration::from_millis(100), failsafe);
        let t = Instant::from_millis(1);
        let before = rx.signal(t);
        assert!(before.lost);
        assert_eq!(before.value, failsafe);
        assert_eq!(rx.channel(2, t, 0.0), -1.0);
        rx.push_interval(6000, t);
        train(
            &mut rx,
            &[1500, 1500, 1750, 1500, 1500, 1500, 1500, 1500],
            t,
        );
        assert!(!rx.signal(t).lost);
        assert_eq!(rx.channel(2, t, 0.0), 0.5);
        // More than 100 ms after the frame (stamped where its last channel ended and the 6 ms
        // sync gap began: before the clock started, so at 0).
        let later = Instant::from_millis(102);
        assert!(rx.signal(later).lost);
        assert_eq!(rx.signal(later).value, failsafe);
        assert_eq!(rx.channel(2, later, 0.0), -1.0);
    }

    #[test]
    fn pulse_counter_saturates_instead_of_overflowing() {
        let mut rx = PpmReceiver::<8>::new(Duration::from_millis(100));
        let now = Instant::from_millis(1);
        rx.push_interval(5000, now);
        rx.count = usize::MAX - 1;
        assert_eq!(rx.push_interval(1500, now), None);
        assert_eq!(rx.push_interval(1500, now), None);
        assert_eq!(rx.count, usize::MAX);
        assert_eq!(
            rx.push_interval(5000, now),
            Some(Err(PpmError::WrongChannelCount(usize::MAX)))
        );
    }

    #[test]
    fn short_frame_is_rejected() {
        let (mut rx, t) = synced();
        assert_eq!(
            train(&mut rx, &[1500; 6], t),
            Some(Err(PpmError::WrongChannelCount(6)))
        );
        assert!(rx.signal(t).lost);
    }

    #[test]
    fn a_frame_counts_from_its_last_edge_so_pulses_that_come_back_do_not_revive_it() {
        let mut rx = PpmReceiver::<8>::new(Duration::from_millis(100));
        let mut t = Instant::from_millis(10);
        rx.push_interval(6000, t);
        for _ in 0..8 {
            t += Duration::from_micros(2000);
            assert_eq!(rx.push_interval(2000, t), None);
        }
        // The receiver (set to "no pulses") stops after channel 8 and comes back 1 s later:
        // its first edge closes a 1 s "sync gap". The frame's values are 1 s old.
        let back = t + Duration::from_millis(1000);
        assert_eq!(rx.push_interval(1_000_000, back), Some(Ok([2000; 8])));
        assert!(rx.signal(back).lost);
        assert_eq!(rx.channel(0, back, 0.0), 0.0);
        // A running train: the frame counts from the edge that closed channel 8 (where the
        // 6 ms sync gap began), fresh for the 100 ms timeout from there.
        let mut t = back;
        for _ in 0..8 {
            t += Duration::from_micros(1000);
            assert_eq!(rx.push_interval(1000, t), None);
        }
        let sync_end = t + Duration::from_micros(6000);
        assert_eq!(rx.push_interval(6000, sync_end), Some(Ok([1000; 8])));
        let timeout_end = t + Duration::from_millis(100);
        assert!(!rx.signal(timeout_end).lost);
        assert!(rx.signal(timeout_end + Duration::from_micros(1)).lost);
    }

    #[test]
    fn signal_loss_returns_neutral() {
        let mut rx = PpmReceiver::<8>::new(Duration::from_millis(50));
        rx.push_interval(6000, Instant::from_millis(0));
        train(&mut rx, &[2000; 8], Instant::from_millis(20));
        assert_eq!(rx.channel(0, Instant::from_millis(60), 0.0), 1.0);
        assert_eq!(rx.channel(0, Instant::from_millis(71), 0.0), 0.0);
        assert!(rx.signal(Instant::from_millis(71)).lost);
    }
}
