//! Control-loop time: turning 64-bit microsecond timestamps into a bounded `dt` in seconds.
//!
//! The control logic never reads a clock: callers pass the current [`Instant`] (from
//! embassy-time on a board, from virtual time in the simulator). The only clock reads in
//! rc10-core are in the async task shell ([`crate::bus::TickerTicks`] and the receiver's
//! back-off), which a board needs anyway. Differences are taken in integer microseconds
//! and only then converted to `f32` seconds, so precision does not degrade with uptime: the
//! `dt` after 100 days is as exact as the `dt` after one second (RC10_LIB's float timestamps
//! lost resolution after hours).

pub use embassy_time::{Duration, Instant};

/// Computes the `dt` (seconds) between successive control-loop calls, bounded so that the
/// first call and a call after a gap cannot produce a derivative spike or an integral jump.
///
/// - First call (or after [`reset`](Self::reset)): returns the nominal period.
/// - Time going backwards or standing still: returns the nominal period (a clock glitch must
///   not produce a zero or negative `dt`).
/// - A call sooner than half the nominal period after the previous: returns half the nominal
///   period (a tick that ran late followed by an on-time one must not divide a derivative by
///   a few microseconds).
/// - A gap longer than `max`: returns `max`.
///
/// So every `dt` lies in `[nominal / 2, max]`.
///
/// ```
/// use rc10_core::time::{DeltaTime, Duration, Instant};
/// let mut dt = DeltaTime::new(Duration::from_micros(1000), Duration::from_micros(20_000));
/// assert_eq!(dt.update(Instant::from_micros(5_000_000)), 0.001); // first call: nominal
/// assert_eq!(dt.update(Instant::from_micros(5_001_500)), 0.0015);
/// assert_eq!(dt.update(Instant::from_micros(9_000_000)), 0.02); // gap: bounded
/// assert_eq!(dt.update(Instant::from_micros(9_000_010)), 0.0005); // burst: bounded
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeltaTime {
    nominal_us: u64,
    min_us: u64,
    max_us: u64,
    last: Option<Instant>,
}

impl DeltaTime {
    /// A dt source for a loop that runs every `nominal` and may be late by up to `max`.
    ///
    /// `max` below `nominal` is raised to `nominal`; a zero `nominal` is raised to 1 µs.
    pub const fn new(nominal: Duration, max: Duration) -> Self {
        let nominal_us = if nominal.as_micros() == 0 {
            1
        } else {
            nominal.as_micros()
        };
        let max_us = if max.as_micros() < nominal_us {
            nominal_us
        } else {
            max.as_micros()
        };
        Self {
            nominal_us,
            min_us: if nominal_us / 2 == 0 {
                1
            } else {
                nominal_us / 2
            },
            max_us,
            last: None,
        }
    }

    /// The nominal period in seconds.
    pub fn nominal_s(&self) -> f32 {
        micros_to_s(self.nominal_us)
    }

    /// Records `now` and returns the bounded time since the previous call, in seconds.
    pub fn update(&mut self, now: Instant) -> f32 {
        let dt_us = match self.last {
            Some(last) if now > last => {
                // `now > last`: never saturates.
                let elapsed = now.as_micros().saturating_sub(last.as_micros());
                elapsed.clamp(self.min_us, self.max_us)
            }
            _ => self.nominal_us,
        };
        self.last = Some(now);
        micros_to_s(dt_us)
    }

    /// Forgets the previous timestamp: the next call returns the nominal period.
    pub fn reset(&mut self) {
        self.last = None;
    }
}

/// Converts a microsecond count to seconds, for any count within a relative error of 2^-23
/// (1.2·10⁻⁷: the f32 nearest 10⁻⁶ is not 10⁻⁶, and the product rounds once more); the
/// count itself converts exactly below 2^24 µs (16.7 s), and the whole seconds are kept
/// apart from the fraction, so the relative error stays there for any count (absolute
/// precision is the f32's: about 0.24 ms at an hour; `dt` is computed from integer
/// differences first and stays exact).
#[inline]
pub fn micros_to_s(us: u64) -> f32 {
    // Below a second (every control period): one 32-bit conversion, the same value as the
    // split below (whose whole-second part is then 0).
    if us < 1_000_000 {
        return us as u32 as f32 * 1e-6;
    }
    // Split so that large counts keep their relative precision without f64 (soft-float on M4).
    let whole_s = (us / 1_000_000) as f32;
    let frac_us = (us % 1_000_000) as f32;
    whole_s + frac_us * 1e-6
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dt_1khz() -> DeltaTime {
        DeltaTime::new(Duration::from_micros(1000), Duration::from_micros(10_000))
    }

    #[test]
    fn first_call_returns_nominal() {
        let mut dt = dt_1khz();
        assert_eq!(dt.update(Instant::from_micros(123_456_789)), 0.001);
    }

    #[test]
    fn dt_after_100_days_uptime_is_exact_to_the_microsecond() {
        // 100 days in µs is 8.64e12: an f32 timestamp would have a resolution of ~1 s here.
        let t0 = 100 * 86_400 * 1_000_000u64;
        let mut dt = dt_1khz();
        dt.update(Instant::from_micros(t0));
        assert_eq!(dt.update(Instant::from_micros(t0 + 1000)), 0.001);
        assert_eq!(dt.update(Instant::from_micros(t0 + 1999)), 0.000999);
    }

    #[test]
    fn micros_to_s_is_within_two_roundings_for_any_count() {
        // 1 µs to 2^40 µs (12.7 days), densely below 2 s, then by a prime stride.
        let counts = (1..2_000_000u64)
            .step_by(7)
            .chain((2_000_000..1u64 << 40).step_by(1_234_567_891));
        for us in counts {
            let exact = us as f64 * 1e-6;
            let err = (f64::from(micros_to_s(us)) - exact).abs() / exact;
            assert!(err < f64::powi(2.0, -23), "{us} µs: {err:e}");
        }
    }

    #[test]
    fn gap_is_bounded_by_max() {
        let mut dt = dt_1khz();
        dt.update(Instant::from_micros(0));
        assert_eq!(dt.update(Instant::from_micros(3_000_000)), 0.01);
    }

    #[test]
    fn backwards_or_equal_time_returns_nominal() {
        let mut dt = dt_1khz();
        dt.update(Instant::from_micros(5000));
        assert_eq!(dt.update(Instant::from_micros(5000)), 0.001);
        assert_eq!(dt.update(Instant::from_micros(4000)), 0.001);
    }

    #[test]
    fn reset_makes_next_call_nominal() {
        let mut dt = dt_1khz();
        dt.update(Instant::from_micros(0));
        dt.reset();
        assert_eq!(dt.update(Instant::from_micros(7_000)), 0.001);
    }

    #[test]
    fn burst_of_back_to_back_calls_is_bounded_below_by_half_the_period() {
        let mut dt = dt_1khz();
        dt.update(Instant::from_micros(0));
        assert_eq!(dt.update(Instant::from_micros(3)), 0.0005);
        assert_eq!(dt.update(Instant::from_micros(400)), 0.0005);
        assert_eq!(dt.update(Instant::from_micros(1500)), 0.0011);
    }

    #[test]
    fn max_below_nominal_is_raised() {
        let mut dt = DeltaTime::new(Duration::from_micros(1000), Duration::from_micros(10));
        dt.update(Instant::from_micros(0));
        assert_eq!(dt.update(Instant::from_micros(50_000)), 0.001);
    }

    #[test]
    fn micros_to_s_large_values_keep_relative_precision() {
        let s = micros_to_s(3_600_000_000 + 250_000); // 1 h 0.25 s
        assert!((s - 3600.25).abs() < 3600.25 * 1.2e-7);
    }
}
