//! Tracking differentiator (TD): a critically damped second-order tracker that turns a step
//! target into a smooth one and gives its rate of change.

use super::PidConfigError;

/// Most Euler sub-steps taken in one call; a longer `dt` snaps to the input (see `update`).
const MAX_SUBSTEPS: u32 = 8;

/// Critically damped second-order tracker:
/// `x1' = x2`, `x2' = -r²·(x1 - v) - 2r·x2`, where `v` is the input, `x1` the tracked value
/// and `x2` its rate. `r` (rad/s) sets the speed: a step is 90 % tracked after about `3.9 / r`
/// seconds, with no overshoot.
///
/// This is the linear tracker of RC10_LIB's `calc_track_D`, not Han Jingqing's nonlinear TD
/// with `fhan(x1 − v, x2, r, h0)`: there `r` bounds the tracked signal's acceleration (units
/// per s²) and `h0` is a filter factor; here `r` is a bandwidth in rad/s, and the time a
/// step takes does not depend on its size. Gains tuned for an `fhan` TD do not carry over.
///
/// Integrated by explicit Euler. Explicit Euler of this system is stable only for
/// `r·dt < 2` and overshoots for `r·dt > 1`, so a call whose `dt` exceeds `1/r` is split into
/// sub-steps of at most `1/r` (a step of exactly `1/r` is dead-beat). After a pause longer than
/// `8/r` the tracker snaps to the input with zero rate, which is where the sub-steps would have
/// brought it. This is why there is no blow-up after a pause (RC10_LIB's TD diverged when `dt`
/// was large). The first call starts from the value given to [`reset`](Self::reset), or from
/// the input itself (no jump, no rate).
///
/// ```
/// use rc10_core::pid::TrackingDifferentiator;
/// let mut td = TrackingDifferentiator::new(50.0).unwrap();
/// td.reset(0.0);
/// let (x1, _rate) = td.update(100.0, 0.001);
/// assert!(x1 < 1.0); // a step input is followed smoothly
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackingDifferentiator {
    r_rad_s: f32,
    /// The longest Euler step, `1/r` seconds (dead-beat).
    h_max_s: f32,
    /// Gaps longer than this (`8/r` seconds) snap to the input.
    snap_after_s: f32,
    /// `-r²` and `2r`, the system's coefficients.
    neg_r_sq: f32,
    two_r: f32,
    state: Option<(f32, f32)>,
}

impl TrackingDifferentiator {
    /// A tracker with speed `r_rad_s` (rad/s, finite and positive).
    pub const fn new(r_rad_s: f32) -> Result<Self, PidConfigError> {
        if r_rad_s.is_finite() && r_rad_s > 0.0 {
            // Everything a step needs that depends on `r` alone, computed once (the same
            // values, bit for bit, as computing them in every step).
            let h_max_s = 1.0 / r_rad_s;
            Ok(Self {
                r_rad_s,
                h_max_s,
                snap_after_s: h_max_s * MAX_SUBSTEPS as f32,
                neg_r_sq: -r_rad_s * r_rad_s,
                two_r: 2.0 * r_rad_s,
                state: None,
            })
        } else {
            Err(PidConfigError::InvalidTrackingRate)
        }
    }

    /// The speed parameter in rad/s.
    pub const fn r_rad_s(&self) -> f32 {
        self.r_rad_s
    }

    /// Starts tracking from `value` at rest. A non-finite value clears the state instead
    /// (the next input is then taken as the start).
    pub fn reset(&mut self, value: f32) {
        self.state = if value.is_finite() {
            Some((value, 0.0))
        } else {
            None
        };
    }

    /// Takes over `previous`'s tracked value and rate (after a change of `r`, so that the
    /// tracked value goes on from where it was instead of restarting).
    pub(crate) fn continue_from(&mut self, previous: &Self) {
        self.state = previous.state;
    }

    /// Whether the tracker has a state (it was reset to a value or has seen an input).
    pub const fn is_started(&self) -> bool {
        self.state.is_some()
    }

    /// Advances by `dt_s` seconds towards `input`; returns `(tracked value, rate per second)`.
    ///
    /// A non-finite `input` leaves the state unchanged (and returns it; `(0, 0)` if there is
    /// none). A `dt_s` that is not finite and positive does not advance a started tracker
    /// (it returns its state); an unstarted one starts at `input` at rest.
    pub fn update(&mut self, input: f32, dt_s: f32) -> (f32, f32) {
        if !input.is_finite() {
            return self.state.unwrap_or((0.0, 0.0));
        }
        let (mut x1, mut x2) = self.state.unwrap_or((input, 0.0));
        if super::positional::dt_valid(dt_s) {
            let h_max = self.h_max_s;
            if dt_s <= h_max {
                // One step (every call at a tick period shorter than `1/r`).
                let accel = self.neg_r_sq * (x1 - input) - self.two_r * x2;
                x1 += dt_s * x2;
                x2 += dt_s * accel;
            } else if dt_s > self.snap_after_s {
                (x1, x2) = (input, 0.0);
            } else {
                let mut remaining = dt_s;
                while remaining > 0.0 {
                    // By comparison: `f32::min` is a library call on the Cortex-M4.
                    let h = if remaining < h_max { remaining } else { h_max };
                    let accel = self.neg_r_sq * (x1 - input) - self.two_r * x2;
                    x1 += h * x2;
                    x2 += h * accel;
                    remaining -= h;
                }
            }
        }
        if !super::positional::all_finite(x1, x2, 0.0) {
            // An absurd (finite) input overflowed the state: start again from the input at
            // rest rather than carry infinities or NaN into every later call.
            (x1, x2) = (input, 0.0);
        }
        self.state = Some((x1, x2));
        (x1, x2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absurd_finite_input_does_not_latch_the_state() {
        let mut td = TrackingDifferentiator::new(100.0).unwrap();
        td.reset(0.0);
        for _ in 0..3 {
            let (x1, x2) = td.update(3e38, 0.001);
            assert!(x1.is_finite() && x2.is_finite());
        }
        // Back to a sane input: the tracker follows it again, smoothly and finitely.
        let mut last = (0.0, 0.0);
        for _ in 0..200 {
            last = td.update(100.0, 0.001);
            assert!(last.0.is_finite() && last.1.is_finite());
        }
        assert!((last.0 - 100.0).abs() < 1.0, "{last:?}");
    }

    #[test]
    fn new_rejects_non_positive_rate() {
        assert!(TrackingDifferentiator::new(0.0).is_err());
        assert!(TrackingDifferentiator::new(f32::NAN).is_err());
        assert!(TrackingDifferentiator::new(-5.0).is_err());
    }

    #[test]
    fn first_call_without_reset_starts_at_input() {
        let mut td = TrackingDifferentiator::new(100.0).unwrap();
        assert_eq!(td.update(42.0, 0.001), (42.0, 0.0));
    }

    #[test]
    fn step_is_tracked_without_overshoot_in_expected_time() {
        // Continuous critically damped step: 1 - (1 + r t) e^{-r t} = 0.9 at r t ≈ 3.89.
        let r = 50.0;
        let mut td = TrackingDifferentiator::new(r).unwrap();
        td.reset(0.0);
        let dt = 0.0005;
        let mut t90 = None;
        for k in 1..=2000 {
            let (x1, _) = td.update(1.0, dt);
            assert!(x1 <= 1.0 + 1e-6, "overshoot {x1}");
            if t90.is_none() && x1 >= 0.9 {
                t90 = Some(k as f32 * dt);
            }
        }
        let t90 = t90.unwrap();
        assert!((t90 - 3.89 / r).abs() < 0.004, "t90 = {t90}");
    }

    #[test]
    fn steps_of_one_over_r_are_dead_beat_whether_one_call_or_sub_steps() {
        // Euler with h = 1/r from rest at 0 towards 1: x2 = h·r²·1 = r, x1 = 0; then
        // x1 = h·r = 1 and x2 = r + h·(r²·1 − 2r·r) = 0: on the input, at rest, in two steps.
        let close = |(a, b): (f32, f32), (x, y): (f32, f32)| {
            assert!((a - x).abs() < 1e-4 && (b - y).abs() < 1e-3, "({a}, {b})");
        };
        let mut td = TrackingDifferentiator::new(100.0).unwrap();
        td.reset(0.0);
        close(td.update(1.0, 0.01), (0.0, 100.0));
        close(td.update(1.0, 0.01), (1.0, 0.0));
        // The same two steps as the sub-steps of one call of 2/r.
        td.reset(0.0);
        close(td.update(1.0, 0.02), (1.0, 0.0));
        // 1.5/r: a full step, then the remaining half: x1 = 0.005·100 = 0.5,
        // x2 = 100 + 0.005·(10^4 − 200·100) = 50.
        td.reset(0.0);
        close(td.update(1.0, 0.015), (0.5, 50.0));
        // Shorter calls take one step each: h = dt, x2 = dt·r² = 10 after the first.
        td.reset(0.0);
        close(td.update(1.0, 0.001), (0.0, 10.0));
    }

    #[test]
    fn long_pause_does_not_blow_up() {
        let mut td = TrackingDifferentiator::new(200.0).unwrap();
        td.reset(0.0);
        td.update(10.0, 0.001);
        // A 0.5 s pause (r·dt = 100): naive Euler would multiply the error by (1 - 100)^2.
        let (x1, x2) = td.update(10.0, 0.5);
        assert_eq!((x1, x2), (10.0, 0.0));
        // A moderate gap (r·dt = 4) is sub-stepped: bounded and approaching the input.
        td.reset(0.0);
        let (x1, x2) = td.update(10.0, 0.02);
        assert!(x1 > 0.0 && x1 <= 10.0, "x1 = {x1}");
        assert!(x2.is_finite());
    }

    #[test]
    fn non_finite_input_keeps_state() {
        let mut td = TrackingDifferentiator::new(50.0).unwrap();
        td.reset(3.0);
        assert_eq!(td.update(f32::NAN, 0.001), (3.0, 0.0));
        assert_eq!(td.update(5.0, f32::INFINITY), (3.0, 0.0));
    }
}
