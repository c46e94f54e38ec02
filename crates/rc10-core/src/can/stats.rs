//! Per-bus statistics: cumulative counters readable at any time from any task, and per-second
//! rates (frames/s, bus load %) latched by the scheduler tick.
//!
//! Counters are `AtomicU32`s (native on Cortex-M4) and wrap after 2^32: a frame counter at a
//! full bus's 6,000 frames/s after about 8 days, a bit counter at its 666 kbit/s after about
//! 1.8 hours. Compare snapshots with wrapping subtraction, as [`BusCounters::since`] does,
//! taken less than that apart (the 1 s rate windows are far within it). Rates are computed
//! from two snapshots one window apart.

#[cfg(doc)]
use super::timing;
use crate::time::{Duration, Instant, micros_to_s};
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

/// Live counters of one bus. All methods take `&self` and never block.
#[derive(Debug, Default)]
pub struct BusStats {
    rx_frames: AtomicU32,
    rx_bits: AtomicU32,
    rx_unmatched: AtomicU32,
    rx_rejected: AtomicU32,
    rx_overruns: AtomicU32,
    bus_errors: AtomicU32,
    tx_frames: AtomicU32,
    tx_bits: AtomicU32,
    tx_full: AtomicU32,
    tx_stale: AtomicU32,
    tx_bus_off: AtomicU32,
    tx_batch_overflow: AtomicU32,
    tx_undeclared: AtomicU32,
    bus_off_events: AtomicU32,
    ticks: AtomicU32,
    ticks_skipped: AtomicU32,
    bus_off_now: AtomicBool,
}

macro_rules! bump {
    ($field:expr) => {
        $field.fetch_add(1, Ordering::Relaxed)
    };
    ($field:expr, $n:expr) => {
        $field.fetch_add($n, Ordering::Relaxed)
    };
}

impl BusStats {
    /// All counters zero.
    pub const fn new() -> Self {
        Self {
            rx_frames: AtomicU32::new(0),
            rx_bits: AtomicU32::new(0),
            rx_unmatched: AtomicU32::new(0),
            rx_rejected: AtomicU32::new(0),
            rx_overruns: AtomicU32::new(0),
            bus_errors: AtomicU32::new(0),
            tx_frames: AtomicU32::new(0),
            tx_bits: AtomicU32::new(0),
            tx_full: AtomicU32::new(0),
            tx_stale: AtomicU32::new(0),
            tx_bus_off: AtomicU32::new(0),
            tx_batch_overflow: AtomicU32::new(0),
            tx_undeclared: AtomicU32::new(0),
            bus_off_events: AtomicU32::new(0),
            ticks: AtomicU32::new(0),
            ticks_skipped: AtomicU32::new(0),
            bus_off_now: AtomicBool::new(false),
        }
    }

    pub(crate) fn record_rx(&self, bits: u32) {
        bump!(self.rx_frames);
        bump!(self.rx_bits, bits);
    }
    pub(crate) fn record_unmatched(&self) {
        bump!(self.rx_unmatched);
    }
    pub(crate) fn record_rejected(&self) {
        bump!(self.rx_rejected);
    }
    pub(crate) fn record_overrun(&self) {
        bump!(self.rx_overruns);
    }
    pub(crate) fn record_bus_error(&self) {
        bump!(self.bus_errors);
    }
    pub(crate) fn record_bus_errors(&self, n: u32) {
        bump!(self.bus_errors, n);
    }
    pub(crate) fn record_tx(&self, bits: u32) {
        bump!(self.tx_frames);
        bump!(self.tx_bits, bits);
    }
    pub(crate) fn record_tx_full(&self) {
        bump!(self.tx_full);
    }
    pub(crate) fn record_tx_stale(&self, n: u32) {
        bump!(self.tx_stale, n);
    }
    pub(crate) fn record_tx_bus_off(&self) {
        bump!(self.tx_bus_off);
    }
    pub(crate) fn record_batch_overflow(&self, n: u32) {
        bump!(self.tx_batch_overflow, n);
    }
    pub(crate) fn record_tx_undeclared(&self, n: u32) {
        bump!(self.tx_undeclared, n);
    }
    pub(crate) fn record_tick(&self) {
        bump!(self.ticks);
    }
    pub(crate) fn record_skipped_ticks(&self, n: u32) {
        bump!(self.ticks_skipped, n);
    }

    /// Records the controller's bus-off flag; counts an event on each entry into bus-off.
    pub(crate) fn record_bus_off_state(&self, bus_off: bool) {
        let was = self.bus_off_now.swap(bus_off, Ordering::Relaxed);
        if bus_off && !was {
            bump!(self.bus_off_events);
        }
    }

    /// Whether the controller was bus-off at the last check.
    pub fn is_bus_off(&self) -> bool {
        self.bus_off_now.load(Ordering::Relaxed)
    }

    /// A consistent-enough copy of every counter (each read is atomic; the set is not).
    pub fn snapshot(&self) -> BusCounters {
        let l = |a: &AtomicU32| a.load(Ordering::Relaxed);
        BusCounters {
            rx_frames: l(&self.rx_frames),
            rx_bits: l(&self.rx_bits),
            rx_unmatched: l(&self.rx_unmatched),
            rx_rejected: l(&self.rx_rejected),
            rx_overruns: l(&self.rx_overruns),
            bus_errors: l(&self.bus_errors),
            tx_frames: l(&self.tx_frames),
            tx_bits: l(&self.tx_bits),
            tx_full: l(&self.tx_full),
            tx_stale: l(&self.tx_stale),
            tx_bus_off: l(&self.tx_bus_off),
            tx_batch_overflow: l(&self.tx_batch_overflow),
            tx_undeclared: l(&self.tx_undeclared),
            bus_off_events: l(&self.bus_off_events),
            ticks: l(&self.ticks),
            ticks_skipped: l(&self.ticks_skipped),
        }
    }
}

impl BusStats {
    /// The counters [`BusRates`] are computed from, written into `out` (what the tick copies
    /// once per statistics window: five values, straight from the atomics).
    fn rate_counts_into(&self, out: &mut RateCounts) {
        let l = |a: &AtomicU32| a.load(Ordering::Relaxed);
        out.rx_frames = l(&self.rx_frames);
        out.rx_bits = l(&self.rx_bits);
        out.tx_frames = l(&self.tx_frames);
        out.tx_bits = l(&self.tx_bits);
        out.tx_dropped = l(&self.tx_full)
            .wrapping_add(l(&self.tx_bus_off))
            .wrapping_add(l(&self.tx_batch_overflow));
    }
}

/// A copy of a bus's counters at one moment (all cumulative since start, wrapping at 2^32).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BusCounters {
    /// Frames received (all, matched or not).
    pub rx_frames: u32,
    /// Bits of received frames without stuff bits ([`timing::unstuffed_bits`]: constant
    /// time, cheap enough for every frame on the MCU; stuffing adds up to 20 % more).
    pub rx_bits: u32,
    /// Received frames no registered device claimed.
    pub rx_unmatched: u32,
    /// Frames a device claimed but rejected as malformed (wrong DLC, bad values).
    pub rx_rejected: u32,
    /// RX FIFO overruns reported by the transport.
    pub rx_overruns: u32,
    /// Bus protocol errors (stuff, form, ACK, bit, CRC): every error the controller logged
    /// ([`BusStatus::errors_logged`](super::BusStatus::errors_logged), FDCAN's error log), or
    /// one per status read that saw an error where the controller cannot count them, plus
    /// [`ReceiveError::BusError`](super::ReceiveError::BusError)s from the receiver.
    pub bus_errors: u32,
    /// Frames queued into the transport's TX buffers. Queued is not yet on the wire: a frame
    /// that is never acknowledged (no node on the bus) stays queued and is retransmitted.
    pub tx_frames: u32,
    /// Bits of queued frames without stuff bits (see `rx_bits`).
    pub tx_bits: u32,
    /// Frames not queued because the TX buffers were full.
    pub tx_full: u32,
    /// Frames found still waiting in the TX buffers at the start of a later tick (late, if
    /// sent at all; see [`CanTransmit::still_queued`](super::CanTransmit::still_queued)),
    /// counted at every tick that finds them: a frame that waits three ticks counts three
    /// (frame-ticks of delay, so it can exceed the frames queued while nobody acknowledges).
    pub tx_stale: u32,
    /// Frames not queued because the controller was bus-off.
    pub tx_bus_off: u32,
    /// Frames the devices tried to pack beyond the per-tick batch capacity.
    pub tx_batch_overflow: u32,
    /// Whole frames a node packed beyond what its `BusUsage` declared (too many, or on an
    /// undeclared ID): dropped, never sent.
    pub tx_undeclared: u32,
    /// Times the controller entered bus-off.
    pub bus_off_events: u32,
    /// Scheduler ticks run.
    pub ticks: u32,
    /// Scheduler ticks skipped to re-synchronise after a stall (not run late, back to back).
    pub ticks_skipped: u32,
}

impl BusCounters {
    /// All counts zero (the `const` twin of `Default`).
    pub const ZERO: Self = Self {
        rx_frames: 0,
        rx_bits: 0,
        rx_unmatched: 0,
        rx_rejected: 0,
        rx_overruns: 0,
        bus_errors: 0,
        tx_frames: 0,
        tx_bits: 0,
        tx_full: 0,
        tx_stale: 0,
        tx_bus_off: 0,
        tx_batch_overflow: 0,
        tx_undeclared: 0,
        bus_off_events: 0,
        ticks: 0,
        ticks_skipped: 0,
    };

    /// Frames that should have gone out but did not (TX full, bus-off, batch overflow).
    pub const fn tx_dropped(&self) -> u32 {
        self.tx_full
            .wrapping_add(self.tx_bus_off)
            .wrapping_add(self.tx_batch_overflow)
    }

    /// The counts between `earlier` and `self` (wrapping subtraction, field by field).
    pub const fn since(&self, earlier: &Self) -> Self {
        Self {
            rx_frames: self.rx_frames.wrapping_sub(earlier.rx_frames),
            rx_bits: self.rx_bits.wrapping_sub(earlier.rx_bits),
            rx_unmatched: self.rx_unmatched.wrapping_sub(earlier.rx_unmatched),
            rx_rejected: self.rx_rejected.wrapping_sub(earlier.rx_rejected),
            rx_overruns: self.rx_overruns.wrapping_sub(earlier.rx_overruns),
            bus_errors: self.bus_errors.wrapping_sub(earlier.bus_errors),
            tx_frames: self.tx_frames.wrapping_sub(earlier.tx_frames),
            tx_bits: self.tx_bits.wrapping_sub(earlier.tx_bits),
            tx_full: self.tx_full.wrapping_sub(earlier.tx_full),
            tx_stale: self.tx_stale.wrapping_sub(earlier.tx_stale),
            tx_bus_off: self.tx_bus_off.wrapping_sub(earlier.tx_bus_off),
            tx_batch_overflow: self
                .tx_batch_overflow
                .wrapping_sub(earlier.tx_batch_overflow),
            tx_undeclared: self.tx_undeclared.wrapping_sub(earlier.tx_undeclared),
            bus_off_events: self.bus_off_events.wrapping_sub(earlier.bus_off_events),
            ticks: self.ticks.wrapping_sub(earlier.ticks),
            ticks_skipped: self.ticks_skipped.wrapping_sub(earlier.ticks_skipped),
        }
    }

    /// Rates over `elapsed`, given these counts are the difference over that interval.
    pub fn rates(&self, elapsed: Duration, bitrate_bps: u32) -> BusRates {
        let s = micros_to_s(elapsed.as_micros());
        if s <= 0.0 {
            return BusRates::default();
        }
        // Summed in 64 bits. Over a window `BusConfig::check` accepts the two fit 32 together
        // (the bus carries one frame at a time), but any counts may be passed here.
        let bits = u64::from(self.rx_bits).saturating_add(u64::from(self.tx_bits)) as f32;
        BusRates {
            rx_frames_per_s: self.rx_frames as f32 / s,
            tx_frames_per_s: self.tx_frames as f32 / s,
            tx_dropped_per_s: self.tx_dropped() as f32 / s,
            load_percent: 100.0 * bits / (bitrate_bps.max(1) as f32 * s),
        }
    }
}

/// Per-second figures of a bus.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BusRates {
    /// Frames received per second.
    pub rx_frames_per_s: f32,
    /// Frames queued for transmission per second (queued frames normally go out within the
    /// period; see `tx_stale` for those that did not).
    pub tx_frames_per_s: f32,
    /// Frames dropped on the TX side per second.
    pub tx_dropped_per_s: f32,
    /// Share of the bus's bit time used by the frames this node received and queued, in
    /// percent, counted without stuff bits: the true load is up to a fifth higher. What the
    /// node does not see is not in it: retransmissions, error frames, frames its acceptance
    /// filters reject, and frames refused while the TX buffers are full. So it reads low,
    /// not high, when the bus is in trouble (nobody acknowledging: near 0 % while the
    /// controller retransmits all the time); read it with `bus_errors` and `tx_full`.
    pub load_percent: f32,
}

/// The counters [`BusRates`] are computed from (cumulative, wrapping like [`BusCounters`]);
/// `tx_dropped` is [`BusCounters::tx_dropped`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct RateCounts {
    rx_frames: u32,
    rx_bits: u32,
    tx_frames: u32,
    tx_bits: u32,
    tx_dropped: u32,
}

impl RateCounts {
    const ZERO: Self = Self {
        rx_frames: 0,
        rx_bits: 0,
        tx_frames: 0,
        tx_bits: 0,
        tx_dropped: 0,
    };

    /// The counts between `earlier` and `self`, as [`BusCounters`] (the counters that
    /// [`BusCounters::rates`] does not read are zero).
    const fn since(&self, earlier: &Self) -> BusCounters {
        BusCounters {
            rx_frames: self.rx_frames.wrapping_sub(earlier.rx_frames),
            rx_bits: self.rx_bits.wrapping_sub(earlier.rx_bits),
            tx_frames: self.tx_frames.wrapping_sub(earlier.tx_frames),
            tx_bits: self.tx_bits.wrapping_sub(earlier.tx_bits),
            // `tx_dropped()` of the result: all of it counted as `tx_full`.
            tx_full: self.tx_dropped.wrapping_sub(earlier.tx_dropped),
            ..BusCounters::ZERO
        }
    }
}

/// Latches the counts of each complete window from successive snapshots (owned by the tick).
/// The rates are computed from them when read ([`Bus::rates`](crate::bus::Bus::rates)): the
/// tick that closes a window only copies five counters into a free slot (no subtraction,
/// 64-bit division, float conversion or divide on the 1 kHz path).
#[derive(Debug, Clone, Copy)]
pub(crate) struct RateWindow {
    /// Counter snapshots: the present window's start and the last complete window's two ends
    /// are among them (three slots: a new window can start while the last one is kept).
    snapshots: [RateCounts; 3],
    /// When the present window started, and the slot of its snapshot.
    start: Option<(Instant, u8)>,
    /// The last complete window: its length and the slots of its first and last snapshot.
    last: Option<(Duration, u8, u8)>,
}

impl RateWindow {
    pub(crate) const fn new() -> Self {
        Self {
            snapshots: [RateCounts::ZERO; 3],
            start: None,
            last: None,
        }
    }

    /// The last complete window's length and the counts within it (those that
    /// [`BusCounters::rates`] reads), if one has completed.
    pub(crate) fn latched(&self) -> Option<(Duration, BusCounters)> {
        let (elapsed, first, last) = self.last?;
        let first = self.snapshots.get(usize::from(first))?;
        let last = self.snapshots.get(usize::from(last))?;
        Some((elapsed, last.since(first)))
    }

    /// Takes a snapshot of `stats` into a slot other than `keep`'s and returns the slot.
    /// Out of line: it runs once per window, and inlined into the tick it would cost every
    /// tick registers.
    #[cold]
    #[inline(never)]
    fn snapshot_into_free_slot(&mut self, keep: [Option<u8>; 2], stats: &BusStats) -> u8 {
        // Three slots, at most two kept: there is always a free one.
        let free = [0u8, 1, 2]
            .into_iter()
            .find(|i| !keep.contains(&Some(*i)))
            .unwrap_or(0);
        if let Some(slot) = self.snapshots.get_mut(usize::from(free)) {
            stats.rate_counts_into(slot);
        }
        free
    }

    /// Latches the window if a window has passed since the last latch. `stats` is only read
    /// then (once per window, not every tick).
    pub(crate) fn update(&mut self, now: Instant, stats: &BusStats, window: Duration) {
        if let Some((t0, first)) = self.start
            && let Some(elapsed) = now.checked_duration_since(t0)
        {
            if elapsed >= window {
                // The window ends here and the next one starts from the same snapshot.
                let end = self.snapshot_into_free_slot([Some(first), None], stats);
                self.last = Some((elapsed, first, end));
                self.start = Some((now, end));
            }
        } else {
            // The first tick, or time went backwards: a new window starts (the last complete
            // one stays latched).
            let keep = match self.last {
                Some((_, first, last)) => [Some(first), Some(last)],
                None => [None, None],
            };
            let first = self.snapshot_into_free_slot(keep, stats);
            self.start = Some((now, first));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn since_wraps_across_u32_overflow() {
        let a = BusCounters {
            rx_frames: u32::MAX - 1,
            ..Default::default()
        };
        let b = BusCounters {
            rx_frames: 3,
            ..Default::default()
        };
        assert_eq!(b.since(&a).rx_frames, 5);
    }

    #[test]
    fn rates_from_known_counts() {
        // 4000 frames of 111 bits in 1 s at 1 Mbit/s = 44.4 % load.
        let c = BusCounters {
            rx_frames: 3000,
            rx_bits: 3000 * 111,
            tx_frames: 1000,
            tx_bits: 1000 * 111,
            tx_full: 10,
            ..Default::default()
        };
        let r = c.rates(Duration::from_secs(1), 1_000_000);
        assert_eq!(r.rx_frames_per_s, 3000.0);
        assert_eq!(r.tx_frames_per_s, 1000.0);
        assert_eq!(r.tx_dropped_per_s, 10.0);
        assert!((r.load_percent - 44.4).abs() < 1e-3);
    }

    #[test]
    fn load_over_a_long_window_sums_the_two_directions_without_wrapping() {
        // 3.0e9 bits received and 1.3e9 sent over 4300 s at 1 Mbit/s: 4.3e9 bits of 4.3e9 bit
        // times, 100 %. Summed in 32 bits they wrap past 2^32 to about 5e6: 0.1 %.
        let c = BusCounters {
            rx_bits: 3_000_000_000,
            tx_bits: 1_300_000_000,
            ..Default::default()
        };
        let r = c.rates(Duration::from_secs(4300), 1_000_000);
        assert!((r.load_percent - 100.0).abs() < 1e-3, "{r:?}");
    }

    #[test]
    fn bus_off_counts_entries_not_ticks() {
        let s = BusStats::new();
        s.record_bus_off_state(true);
        s.record_bus_off_state(true);
        s.record_bus_off_state(false);
        s.record_bus_off_state(true);
        assert_eq!(s.snapshot().bus_off_events, 2);
        assert!(s.is_bus_off());
    }

    #[test]
    fn each_window_latches_its_own_counts_across_slot_reuse_and_a_clock_step_back() {
        let stats = BusStats::new();
        let mut w = RateWindow::new();
        let second = Duration::from_secs(1);
        let frames_in = |w: &RateWindow| w.latched().map(|(_, c)| c.tx_frames);
        // Windows of 500, 300, 700, 100 frames: slots 0 and 1 take turns, each reused; the
        // step back below brings slot 2 in (it must not overwrite the kept window's two).
        let mut t_ms = 0;
        w.update(Instant::from_millis(t_ms), &stats, second);
        for n in [500, 300, 700, 100] {
            for _ in 0..n {
                stats.record_tx(100);
            }
            t_ms += 1000;
            w.update(Instant::from_millis(t_ms), &stats, second);
            assert_eq!(frames_in(&w), Some(n));
        }
        // The clock steps back: a new window starts, the last complete one (100) stays, and
        // the next window counts only what came after the step.
        for _ in 0..40 {
            stats.record_tx(100);
        }
        w.update(Instant::from_millis(1500), &stats, second);
        assert_eq!(frames_in(&w), Some(100));
        for _ in 0..60 {
            stats.record_tx(100);
        }
        w.update(Instant::from_millis(2000), &stats, second);
        assert_eq!(frames_in(&w), Some(100));
        w.update(Instant::from_millis(2600), &stats, second);
        assert_eq!(
            w.latched(),
            Some((
                Duration::from_millis(1100),
                BusCounters {
                    tx_frames: 60,
                    tx_bits: 6000,
                    ..BusCounters::ZERO
                }
            ))
        );
        for _ in 0..250 {
            stats.record_tx(100);
        }
        w.update(Instant::from_millis(3600), &stats, second);
        assert_eq!(frames_in(&w), Some(250));
    }

    #[test]
    fn window_latches_after_one_period_from_its_boundary_snapshots_only() {
        let stats = BusStats::new();
        let mut w = RateWindow::new();
        let second = Duration::from_secs(1);
        w.update(Instant::from_micros(0), &stats, second);
        for _ in 0..500 {
            stats.record_tx(100);
        }
        // Mid-window: nothing latched, and nothing taken (a snapshot here would become the
        // window's start and drop the 500 frames before it).
        w.update(Instant::from_millis(500), &stats, second);
        assert_eq!(w.latched(), None);
        stats.record_tx_full();
        stats.record_tx_bus_off();
        stats.record_batch_overflow(2);
        w.update(Instant::from_millis(1000), &stats, second);
        let (elapsed, counts) = w.latched().unwrap();
        assert_eq!(elapsed, second);
        let rates = counts.rates(elapsed, 1_000_000);
        assert_eq!(rates.tx_frames_per_s, 500.0);
        assert_eq!(rates.tx_dropped_per_s, 4.0); // 1 full + 1 bus-off + 2 batch overflow
        // 500 frames × 100 bits in 1 s at 1 Mbit/s.
        assert!((rates.load_percent - 5.0).abs() < 1e-4);
        // Time going backwards starts a new window and keeps the last complete one.
        w.update(Instant::from_millis(400), &stats, second);
        assert_eq!(w.latched(), Some((elapsed, counts)));
    }
}
