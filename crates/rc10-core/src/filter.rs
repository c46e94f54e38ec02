//! Stateful signal shapers: a first-order low-pass filter and a slew-rate limiter (ramp).
//!
//! Both take an explicit `dt_s` (seconds) on every call, so they work at any tick rate and in
//! the simulator's virtual time. Non-finite inputs are ignored (the state is kept), so one bad
//! sample never poisons the filter.

use core::f32::consts::TAU;

/// First-order low-pass filter `y' = (x - y) / tau`, with `tau = 1 / (2π · cutoff_hz)`.
///
/// Discretised as `y += alpha · (x - y)` with `alpha = dt / (tau + dt)` (backward Euler):
/// stable for every `dt ≥ 0`, and a long `dt` simply means "mostly the new sample".
///
/// ```
/// use rc10_core::filter::LowPass;
/// let mut lp = LowPass::new(10.0); // 10 Hz cutoff
/// let first = lp.update(1.0, 0.001); // the first sample initialises the output
/// assert_eq!(first, 1.0);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LowPass {
    tau_s: f32,
    output: Option<f32>,
}

impl LowPass {
    /// A filter with the given cutoff frequency in hertz.
    ///
    /// A cutoff that is not finite or not positive gives a pass-through filter (`tau = 0`).
    pub const fn new(cutoff_hz: f32) -> Self {
        let tau_s = if cutoff_hz.is_finite() && cutoff_hz > 0.0 {
            1.0 / (TAU * cutoff_hz)
        } else {
            0.0
        };
        Self {
            tau_s,
            output: None,
        }
    }

    /// The time constant in seconds (`0.0` for a pass-through filter).
    pub const fn tau_s(&self) -> f32 {
        self.tau_s
    }

    /// Feeds one sample taken `dt_s` seconds after the previous one and returns the output.
    ///
    /// The first finite sample initialises the output to itself (no start-up transient from 0).
    /// A non-finite `input` or `dt_s` leaves the state unchanged and returns the current output
    /// (`0.0` if there is none yet).
    pub fn update(&mut self, input: f32, dt_s: f32) -> f32 {
        if !input.is_finite() || !dt_s.is_finite() {
            return self.output.unwrap_or(0.0);
        }
        let y = match self.output {
            // A pass-through filter: the weighted form below would give `input` too.
            _ if self.tau_s == 0.0 => input,
            None => input,
            Some(y) => {
                // By comparison: `f32::max` is a library call on the Cortex-M4.
                let dt = if dt_s > 0.0 { dt_s } else { 0.0 };
                let denom = self.tau_s + dt;
                // denom == 0 only for a pass-through filter called with dt = 0.
                let alpha = if denom > 0.0 { dt / denom } else { 1.0 };
                // Weighted form: never overflows for finite inputs, unlike `y + a·(x - y)`.
                crate::math::finite((1.0 - alpha) * y + alpha * input)
            }
        };
        self.output = Some(y);
        y
    }

    /// The current output, `None` before the first sample.
    pub const fn output(&self) -> Option<f32> {
        self.output
    }

    /// Sets the output to a finite `value` (the caller knows it is finite), as a pass-through
    /// filter's `update(value, dt)` would.
    #[inline]
    pub(crate) fn set_output(&mut self, value: f32) {
        self.output = Some(value);
    }

    /// Forgets the state: the next sample initialises the output again.
    pub fn reset(&mut self) {
        self.output = None;
    }

    /// Sets the output to `value` (a non-finite value forgets the state instead), so the next
    /// sample is filtered from there.
    pub fn reset_to(&mut self, value: f32) {
        self.output = value.is_finite().then_some(value);
    }
}

/// Slew-rate limiter: the output follows the target at no more than `rate_per_s` units per
/// second (RC10_LIB `ramp`, with the rate in per-second units instead of per call).
///
/// ```
/// use rc10_core::filter::Ramp;
/// let mut r = Ramp::new(1000.0, 0.0); // 1000 rpm/s, starting at 0 rpm
/// assert_eq!(r.update(300.0, 0.001), 1.0); // 1 rpm per 1 ms tick
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ramp {
    rate_per_s: f32,
    output: f32,
}

impl Ramp {
    /// A ramp limited to `rate_per_s` (taken by magnitude), starting at `initial`.
    ///
    /// A NaN rate gives a ramp that never moves; an infinite rate passes the target through.
    /// A non-finite `initial` starts at `0.0`.
    pub const fn new(rate_per_s: f32, initial: f32) -> Self {
        Self {
            rate_per_s: if rate_per_s.is_nan() {
                0.0
            } else {
                rate_per_s.abs()
            },
            output: if initial.is_finite() { initial } else { 0.0 },
        }
    }

    /// The rate limit in units per second.
    pub const fn rate_per_s(&self) -> f32 {
        self.rate_per_s
    }

    /// Changes the rate limit (units per second, taken by magnitude; NaN freezes the ramp).
    pub fn set_rate_per_s(&mut self, rate_per_s: f32) {
        self.rate_per_s = if rate_per_s.is_nan() {
            0.0
        } else {
            rate_per_s.abs()
        };
    }

    /// Moves towards `target` for `dt_s` seconds and returns the new output.
    ///
    /// A non-finite `target` or a non-finite or negative `dt_s` holds the output.
    pub fn update(&mut self, target: f32, dt_s: f32) -> f32 {
        if !target.is_finite() || !dt_s.is_finite() || dt_s < 0.0 {
            return self.output;
        }
        // An infinite rate passes the target through, even for a `dt_s` of 0 (∞·0 is NaN,
        // which `ramp` would read as no step at all).
        let max_step = if self.rate_per_s == f32::INFINITY {
            f32::INFINITY
        } else {
            self.rate_per_s * dt_s
        };
        self.output = crate::math::ramp(self.output, target, max_step);
        self.output
    }

    /// The current output.
    pub const fn output(&self) -> f32 {
        self.output
    }

    /// Sets the output immediately (for a bumpless start from a measured value).
    /// A non-finite value is ignored.
    pub fn reset(&mut self, value: f32) {
        if value.is_finite() {
            self.output = value;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn low_pass_step_reaches_63_percent_after_one_tau() {
        // 1 Hz cutoff: tau = 1/(2π) ≈ 0.159 s. After tau the continuous response is 1 - e^-1.
        let mut lp = LowPass::new(1.0);
        lp.update(0.0, 0.001);
        let tau = lp.tau_s();
        let steps = (tau / 1e-4) as usize;
        let mut y = 0.0;
        for _ in 0..steps {
            y = lp.update(1.0, 1e-4);
        }
        assert!((y - 0.632).abs() < 0.01, "y = {y}");
    }

    #[test]
    fn low_pass_ignores_nan_sample() {
        let mut lp = LowPass::new(5.0);
        lp.update(2.0, 0.001);
        assert_eq!(lp.update(f32::NAN, 0.001), 2.0);
        assert_eq!(lp.output(), Some(2.0));
    }

    #[test]
    fn low_pass_huge_dt_is_stable_and_near_input() {
        let mut lp = LowPass::new(100.0);
        lp.update(0.0, 0.001);
        let y = lp.update(1.0, 1.0e6);
        assert!(y > 0.999 && y <= 1.0);
    }

    #[test]
    fn low_pass_invalid_cutoff_passes_through() {
        let mut lp = LowPass::new(f32::NAN);
        lp.update(0.0, 0.001);
        assert_eq!(lp.update(5.0, 0.001), 5.0);
        assert_eq!(lp.update(7.0, 0.0), 7.0);
    }

    #[test]
    fn ramp_reaches_target_in_expected_ticks() {
        // 300 rpm at 1000 rpm/s with 1 ms ticks: exactly 300 ticks.
        let mut r = Ramp::new(1000.0, 0.0);
        let mut n = 0;
        while r.output() < 300.0 - 1e-3 {
            r.update(300.0, 0.001);
            n += 1;
            assert!(n < 1000);
        }
        assert!((299..=301).contains(&n), "n = {n}");
        // Never overshoots.
        assert_eq!(r.update(300.0, 0.001), 300.0);
    }

    #[test]
    fn ramp_infinite_rate_jumps_and_nan_rate_freezes() {
        let mut fast = Ramp::new(f32::INFINITY, 0.0);
        assert_eq!(fast.update(42.0, 0.001), 42.0);
        // Also with no time passed (∞·0 would be no step).
        assert_eq!(fast.update(-7.0, 0.0), -7.0);
        let mut frozen = Ramp::new(f32::NAN, 1.0);
        assert_eq!(frozen.update(42.0, 0.001), 1.0);
    }

    #[test]
    fn ramp_ignores_nan_target_and_negative_dt() {
        let mut r = Ramp::new(10.0, 3.0);
        assert_eq!(r.update(f32::NAN, 0.1), 3.0);
        assert_eq!(r.update(10.0, -0.1), 3.0);
    }
}
