//! Incremental (velocity-form) PID with an optional tracking differentiator on the target:
//! RC10_LIB's speed-loop controller.

use super::positional::{all_finite, cap, clamp_abs, dt_valid};
use super::{
    ErrorMode, PidConfigError, PidTerms, TrackingDifferentiator, check_deadband, check_gains,
    check_limit,
};
use crate::math::{finite, saturate};

/// Configuration of an [`IncrementalPid`]; chainable `const` setters like
/// [`PidConfig`](super::PidConfig).
///
/// ```
/// use rc10_core::pid::IncrementalPidConfig;
/// // RC10_LIB's M3508 speed-loop demo gains, converted: kp 18 mA/rpm, ki 0.015 mA/rpm per
/// // 1 ms tick = 15 mA/(rpm·s), 5 rpm deadband, 15 A limit, TD off. Output in mA. The
/// // gains carry over; the band does not behave the same: RC10_LIB takes an error inside it
/// // as 0, which steps its output back by kp·e₁ on entering, and its band is `|e| < 5`;
/// // here the output holds and the band is `|e| ≤ 5`.
/// let rc10_demo = IncrementalPidConfig::new(18.0, 15.0, 0.0)
///     .with_deadband(5.0)
///     .with_output_limit(15_000.0);
/// assert!(rc10_demo.validate().is_ok());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IncrementalPidConfig {
    /// Proportional gain, output units per error unit.
    pub kp: f32,
    /// Integral gain, output units per (error unit · second).
    pub ki: f32,
    /// Derivative gain, output units per (error unit / second).
    pub kd: f32,
    /// `|output| ≤ output_limit`. In the incremental form the output *is* the integrator, so
    /// limiting it is the anti-windup: the output leaves the limit as soon as the error reverses.
    pub output_limit: f32,
    /// While `|error| ≤ deadband` the output is held (no increment) and the error history is
    /// not updated, so the P difference and the D rate span the time since the error was last
    /// outside the band. 0 is no band.
    pub deadband: f32,
    /// Tracking-differentiator speed `r` in rad/s applied to the target; `None` for no TD.
    pub td_r_rad_s: Option<f32>,
}

impl IncrementalPidConfig {
    /// Gains with no limit, no deadband and no TD.
    pub const fn new(kp: f32, ki: f32, kd: f32) -> Self {
        Self {
            kp,
            ki,
            kd,
            output_limit: f32::INFINITY,
            deadband: 0.0,
            td_r_rad_s: None,
        }
    }

    /// Sets [`output_limit`](Self::output_limit).
    #[must_use]
    pub const fn with_output_limit(mut self, limit: f32) -> Self {
        self.output_limit = limit;
        self
    }

    /// Sets [`deadband`](Self::deadband).
    #[must_use]
    pub const fn with_deadband(mut self, deadband: f32) -> Self {
        self.deadband = deadband;
        self
    }

    /// Enables the tracking differentiator with speed `r_rad_s` (rad/s).
    #[must_use]
    pub const fn with_td(mut self, r_rad_s: f32) -> Self {
        self.td_r_rad_s = Some(r_rad_s);
        self
    }

    /// Checks that the configuration can work.
    pub const fn validate(&self) -> Result<(), PidConfigError> {
        if let Err(e) = check_gains(self.kp, self.ki, self.kd) {
            return Err(e);
        }
        if let Err(e) = check_limit(self.output_limit) {
            return Err(e);
        }
        if let Err(e) = check_deadband(self.deadband) {
            return Err(e);
        }
        if let Some(r) = self.td_r_rad_s
            && let Err(e) = TrackingDifferentiator::new(r)
        {
            return Err(e);
        }
        Ok(())
    }
}

/// Incremental PID: each step adds
/// `Δu = kp·(e[k] - e[k-1]) + ki·e[k]·dt + kd·(ė[k] - ė[k-1])`
/// to the output, which is limited to `±output_limit`; `ė[k] = (e[k] - e[k-1]) / Δt[k]` is the
/// error's rate over the time `Δt[k]` since `e[k-1]`.
///
/// At a fixed `dt`, away from the deadband's edge, the D increment is the textbook
/// `kd·(e[k] - 2e[k-1] + e[k-2]) / dt` (up to rounding). Taken as a difference of rates, the D
/// increments add up to `kd·ė[k]` whatever the steps' `dt` (the textbook form drifts without
/// bound when `dt` varies), and a step that leaves the deadband measures the rate over the
/// whole time since the error was last outside it rather than over one `dt` (no spike; this
/// step and the next differ from the textbook form). The D part is kept within
/// `±output_limit`: an absurdly short `dt` cannot leave a rate behind that swings the output
/// from one limit to the other on the next step.
///
/// A changed `kd` ([`set_config`](Self::set_config)) is bumpless, as a changed `kp` is: the
/// increments follow the new gain from the next step on. (Switching `kd` on from 0 adds
/// `kd·ė` once: the rate is not kept while `kd` is 0.)
///
/// With a TD, `e = tracked target - measurement`, where the TD follows the target smoothly
/// (so a target step does not kick P and D). On the first step after construction or
/// [`reset`](Self::reset) the TD starts from the measurement and the error history from the
/// current error, so the first step adds only the I term.
///
/// ```
/// use rc10_core::pid::{IncrementalPid, IncrementalPidConfig};
/// let mut pid = IncrementalPid::new(IncrementalPidConfig::new(1.0, 100.0, 0.0)).unwrap();
/// let t = pid.update(10.0, 0.0, 0.001);
/// assert!((t.output - 1.0).abs() < 1e-6); // first step: ki·e·dt = 100·10·0.001
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IncrementalPid {
    config: IncrementalPidConfig,
    /// The deadband as one comparison: a step runs when `|e| > band`; −1 for no band
    /// (deadband 0), so an error of exactly 0 runs too.
    band: f32,
    /// The output limit capped at `f32::MAX` (no limit, infinity, becomes the largest
    /// finite value), so that clamping to it keeps every output finite.
    limit: f32,
    td: Option<TrackingDifferentiator>,
    output: f32,
    /// The last error outside the deadband, and `kd·ė` then (with the present `kd`, within
    /// ±the capped output limit).
    history: Option<(f32, f32)>,
    /// Seconds since the error in `history` (valid `dt`s of the steps inside the band).
    since_s: f32,
    last: PidTerms,
}

/// [`IncrementalPid::band`] for `deadband` (validated: finite, not negative).
const fn band_of(deadband: f32) -> f32 {
    // A deadband of 0 is no band: an error of exactly 0 is a step like any other.
    if deadband == 0.0 { -1.0 } else { deadband }
}

impl IncrementalPid {
    /// A controller with the given configuration, or why the configuration cannot work.
    pub const fn new(config: IncrementalPidConfig) -> Result<Self, PidConfigError> {
        if let Err(e) = config.validate() {
            return Err(e);
        }
        let td = match config.td_r_rad_s {
            Some(r) => match TrackingDifferentiator::new(r) {
                Ok(td) => Some(td),
                Err(e) => return Err(e),
            },
            None => None,
        };
        Ok(Self {
            config,
            band: band_of(config.deadband),
            limit: cap(config.output_limit),
            td,
            output: 0.0,
            history: None,
            since_s: 0.0,
            last: PidTerms::ZERO,
        })
    }

    /// The configuration.
    pub const fn config(&self) -> &IncrementalPidConfig {
        &self.config
    }

    /// Replaces the configuration (live tuning); the output is re-limited, the history kept.
    ///
    /// A new TD rate `r` goes on from the tracked value and rate of the old one; a TD switched
    /// on while running starts at the target, where the error was measured from (before any
    /// step outside the deadband it starts at the measurement, as on a fresh controller); a
    /// TD switched off hands over to the raw target at once (a P step of `kp` times whatever
    /// the TD still lagged behind it).
    pub fn set_config(&mut self, config: IncrementalPidConfig) -> Result<(), PidConfigError> {
        let fresh = Self::new(config)?;
        if config.td_r_rad_s != self.config.td_r_rad_s {
            let previous = self.td.take();
            self.td = fresh.td;
            if let (Some(td), Some(previous)) = (&mut self.td, &previous) {
                td.continue_from(previous);
            }
        }
        if let Some((_, d_part)) = &mut self.history {
            if config.kd != self.config.kd {
                // Bumpless: the next increment is the new kd times the change of rate. (From
                // kd = 0 the kept part is 0 and stays 0: 0 · ∞ is NaN, which `finite` makes 0.)
                *d_part = finite(*d_part * (config.kd / self.config.kd));
            }
            *d_part = clamp_abs(*d_part, fresh.limit);
        }
        self.config = config;
        self.band = fresh.band;
        self.limit = fresh.limit;
        self.output = saturate(self.output, config.output_limit);
        Ok(())
    }

    /// One control step (`target`, `measurement` in the measured unit, `dt_s` in seconds).
    ///
    /// Non-finite `target` or `measurement`: returns [`PidTerms::ZERO`] and leaves the state
    /// unchanged. A `dt_s` that is not finite and positive holds the output.
    pub fn update(&mut self, target: f32, measurement: f32, dt_s: f32) -> PidTerms {
        if !all_finite(target, measurement, 0.0) {
            return PidTerms::ZERO;
        }
        let c = self.config;
        let tracked = match &mut self.td {
            Some(td) => {
                // A fresh controller tracks from the measurement, so a target step is
                // smoothed from where the motor is; a TD switched on while running (history
                // kept) starts at the target itself, so the error goes on unchanged.
                if !td.is_started() && self.history.is_none() {
                    td.reset(measurement);
                }
                td.update(target, dt_s).0
            }
            None => target,
        };
        let e = ErrorMode::Linear.diff(tracked, measurement);
        let dt_ok = dt_valid(dt_s);
        if !dt_ok || e.abs() <= self.band {
            // Held. An invalid dt adds no time; inside the deadband nothing happens but the
            // clock: the P difference and the rate then span the steps outside the band only,
            // and a target that dithers across the band edge cannot ratchet the output by
            // kp·(e − e_in-band) each time.
            if dt_ok {
                self.since_s += dt_s;
            }
            self.last = PidTerms {
                output: self.output,
                ..PidTerms::ZERO
            };
            return self.last;
        }
        let (e1, d_before) = self.history.unwrap_or((e, 0.0));
        let limit = self.limit;
        // kd = 0 (the usual speed loop): no divide and no D. The kept part is ±0 then
        // (`set_config` scales it by the gains' ratio), so the change of rate is +0 exactly
        // (`−d_before` could be −0, which would carry into the output's sign of zero).
        let (d_now, d) = if c.kd == 0.0 {
            (0.0, 0.0)
        } else {
            let since_s = self.since_s + dt_s;
            let d_now = clamp_abs(finite(c.kd * (e - e1) / since_s), limit);
            (d_now, d_now - d_before)
        };
        let (mut p, mut i, mut d) = (c.kp * (e - e1), c.ki * e * dt_s, d);
        let mut sum = self.output + p + i + d;
        // A finite sum has finite terms (an infinite or NaN one makes it infinite or NaN),
        // each its own `finite` value: checked once for all. Otherwise each term is held
        // finite and the sum redone: finite or ±inf, never NaN.
        if !sum.is_finite() {
            (p, i, d) = (finite(p), finite(i), finite(d));
            sum = self.output + p + i + d;
        }
        // The capped limit is finite.
        self.output = clamp_abs(sum, limit);
        self.history = Some((e, d_now));
        self.since_s = 0.0;
        self.last = PidTerms {
            p,
            i,
            d,
            ff: 0.0,
            output: self.output,
        };
        self.last
    }

    /// The terms of the most recent accepted step.
    pub const fn last_terms(&self) -> PidTerms {
        self.last
    }

    /// The current output.
    pub const fn output(&self) -> f32 {
        self.output
    }

    /// Sets the output (limited; NaN sets zero) for a bumpless takeover from another mode.
    pub fn set_output(&mut self, value: f32) {
        self.output = saturate(value, self.config.output_limit);
    }

    /// Zeroes the output and forgets the error history and the TD state.
    pub fn reset(&mut self) {
        self.output = 0.0;
        self.history = None;
        self.since_s = 0.0;
        if let Some(td) = &mut self.td {
            td.reset(f32::NAN);
        }
        self.last = PidTerms::ZERO;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const DT: f32 = 0.001;

    #[test]
    fn a_target_dithering_across_the_deadband_does_not_ratchet_the_output() {
        // kp 18, deadband 5: errors 7, 3, 7, 3, 7. The steps inside the band change nothing,
        // the history included, so P = 18·(7 − 7) = 0 each time the error leaves it.
        let mut c =
            IncrementalPid::new(IncrementalPidConfig::new(18.0, 0.0, 0.0).with_deadband(5.0))
                .unwrap();
        for e in [7.0, 3.0, 7.0, 3.0, 7.0] {
            c.update(e, 0.0, DT);
        }
        assert_eq!(c.output(), 0.0);
        // Out of the band at 9: P spans the outside steps, 18·(9 − 7) = 36.
        c.update(3.0, 0.0, DT);
        assert_eq!(c.update(9.0, 0.0, DT).p, 36.0);
        assert_eq!(c.output(), 36.0);
    }

    /// Runs kp 18, ki 15 /s towards 300 from 250 until the TD (if any) has caught up.
    fn settled(td: Option<f32>) -> IncrementalPid {
        let cfg = IncrementalPidConfig::new(18.0, 15.0, 0.0).with_output_limit(1e6);
        let cfg = match td {
            Some(r) => cfg.with_td(r),
            None => cfg,
        };
        let mut c = IncrementalPid::new(cfg).unwrap();
        for _ in 0..2000 {
            c.update(300.0, 250.0, DT);
        }
        c
    }

    #[test]
    fn a_new_td_rate_goes_on_from_the_tracked_target() {
        let mut c = settled(Some(30.0));
        let before = c.output();
        c.set_config(*c.config()).unwrap(); // unchanged: nothing to do
        c.set_config(c.config().with_td(40.0)).unwrap();
        // The tracked target stays at 300: e = 50 goes on, P = 0, I = 15·50·0.001 = 0.75
        // (restarted from the measurement it would be P = 18·(0 − 50) = −900).
        let step = c.update(300.0, 250.0, DT).output - before;
        assert!((step - 0.75).abs() < 0.01, "{step}");
    }

    #[test]
    fn a_new_td_rate_mid_step_goes_on_from_the_tracked_value_and_rate() {
        // From 250 towards 300 with r = 30: after 20 ms the TD has tracked about 12 % of the
        // way (1 − (1 + rt)·e^(−rt) at rt = 0.6), so e ≈ 6 rpm and rising ≈ 0.5 rpm a tick.
        let cfg = IncrementalPidConfig::new(18.0, 0.0, 0.0)
            .with_output_limit(1e6)
            .with_td(30.0);
        let mut c = IncrementalPid::new(cfg).unwrap();
        for _ in 0..20 {
            c.update(300.0, 250.0, DT);
        }
        c.set_config(cfg.with_td(40.0)).unwrap();
        // Going on: P = 18 · (one tick's progress) ≈ 10. Restarted at the target it would
        // be 18 · (50 − 6) ≈ 790; at the measurement, 18 · (0 − 6) ≈ −110.
        let p = c.update(300.0, 250.0, DT).p;
        assert!(p > 0.0 && p < 30.0, "{p}");
    }

    #[test]
    fn a_td_switched_on_while_running_starts_at_the_target() {
        let mut c = settled(None);
        let before = c.output();
        c.set_config(c.config().with_td(30.0)).unwrap();
        let step = c.update(300.0, 250.0, DT).output - before;
        assert!((step - 0.75).abs() < 0.01, "{step}");
    }

    #[test]
    fn increments_follow_velocity_form_by_hand() {
        // kp 2, ki 100/s, kd 0.001 s; errors 10, 12, 11 at dt 1 ms.
        // k1: p 0, i 1.0, d 0 (no rate yet)                          → u 1.0
        // k2: p 2·2 = 4, i 1.2; ė 2/ms: D part 2, d = 2 − 0 = 2       → u 8.2
        // k3: p 2·(-1) = -2, i 1.1; ė −1/ms: D part −1, d = −1 − 2 = −3 → u 4.3
        let mut c = IncrementalPid::new(IncrementalPidConfig::new(2.0, 100.0, 0.001)).unwrap();
        assert!((c.update(10.0, 0.0, DT).output - 1.0).abs() < 1e-5);
        assert!((c.update(12.0, 0.0, DT).output - 8.2).abs() < 1e-4);
        let t = c.update(11.0, 0.0, DT);
        assert!((t.p + 2.0).abs() < 1e-4 && (t.i - 1.1).abs() < 1e-4 && (t.d + 3.0).abs() < 1e-3);
        assert!((t.output - 4.3).abs() < 1e-3);
    }

    #[test]
    fn d_part_is_kd_times_the_rate_when_dt_varies() {
        // Error ramp at 1000 units/s, dt alternating 0.5 and 1.5 ms, kd 0.001 s: the rate is
        // 1000/s throughout, so the D part of the output is kd·ė = 1 from the second step
        // on. (The fixed-dt form kd·(e − 2e₁ + e₂)/dt adds −2 and +2/3 on alternate steps
        // here: −64 after 100 steps.)
        let mut c = IncrementalPid::new(IncrementalPidConfig::new(0.0, 0.0, 0.001)).unwrap();
        let mut e = 0.0f32;
        for k in 0..100 {
            let dt = if k % 2 == 0 { 0.0005 } else { 0.0015 };
            e += 1000.0 * dt;
            let out = c.update(e, 0.0, dt).output;
            if k > 0 {
                assert!((out - 1.0).abs() < 1e-3, "step {k}: {out}");
            }
        }
    }

    #[test]
    fn leaving_the_deadband_measures_the_rate_since_the_error_was_last_outside_it() {
        // Error falls 1 a ms from 8 through the band (5) to −6; kd 0.001 s: ė = −1000/s, so
        // the D part is −1 from the second step on. At −6 the rate spans the 12 ms since 6
        // (12 / 12 ms), not one ms (which would step the output to −12).
        let mut c =
            IncrementalPid::new(IncrementalPidConfig::new(0.0, 0.0, 0.001).with_deadband(5.0))
                .unwrap();
        let mut last = 0.0;
        for k in 0..=14 {
            last = c.update(8.0 - k as f32, 0.0, DT).output;
            if k >= 1 {
                assert!((last + 1.0).abs() < 1e-4, "error {}: {last}", 8 - k);
            }
        }
        assert!((c.last_terms().d).abs() < 1e-4, "{:?}", c.last_terms());
        assert!((last + 1.0).abs() < 1e-4);
    }

    #[test]
    fn invalid_dt_holds_without_counting_time() {
        // Errors 0, then 1 after a NaN and a negative dt and then a 1 ms dt: the rate is 1
        // per ms (kd·ė = 1); the held steps add no time (−0.5 ms would make it 2 per ms).
        let mut c = IncrementalPid::new(IncrementalPidConfig::new(0.0, 0.0, 0.001)).unwrap();
        c.update(0.0, 0.0, DT);
        assert_eq!(c.update(0.5, 0.0, f32::NAN).output, 0.0);
        assert_eq!(c.update(0.7, 0.0, -0.0005).output, 0.0);
        assert!((c.update(1.0, 0.0, DT).output - 1.0).abs() < 1e-4);
    }

    #[test]
    fn a_new_kd_is_bumpless_and_the_increments_follow_it() {
        // kp = ki = 0, so the output is the sum of the D increments.
        let mut c = IncrementalPid::new(IncrementalPidConfig::new(0.0, 0.0, 0.001)).unwrap();
        let mut e = 0.0;
        let mut ramp = |c: &mut IncrementalPid, per_ms: f32, kd: Option<f32>| {
            if let Some(kd) = kd {
                c.set_config(IncrementalPidConfig::new(0.0, 0.0, kd))
                    .unwrap();
            }
            e += per_ms;
            c.update(e, 0.0, DT).output
        };
        for _ in 0..5 {
            ramp(&mut c, 1.0, None);
        }
        assert!((c.output() - 1.0).abs() < 1e-4); // kd·ė = 0.001 · 1000/s
        // kd 0.003 on the same ramp: no step (it jumped to 3 when the new gain applied to
        // the whole rate at once).
        assert!((ramp(&mut c, 1.0, Some(0.003)) - 1.0).abs() < 1e-4);
        // The ramp steepens to 2/ms: 0.003 · (2000 − 1000)/s = +3.
        assert!((ramp(&mut c, 2.0, None) - 4.0).abs() < 1e-3);
        // kd 0: nothing more from D, and no step either.
        assert!((ramp(&mut c, 2.0, Some(0.0)) - 4.0).abs() < 1e-3);
        assert!((ramp(&mut c, 3.0, None) - 4.0).abs() < 1e-3);
        // Switched on from 0: the rate was not kept, so kd·ė is added once (0.001 · 3000/s).
        assert!((ramp(&mut c, 3.0, Some(0.001)) - 7.0).abs() < 1e-3);
        assert!((ramp(&mut c, 3.0, None) - 7.0).abs() < 1e-3);
    }

    #[test]
    fn an_absurdly_short_dt_cannot_swing_the_output_to_the_other_limit() {
        // kd 0.001 s, limit 10: errors 0, 1 at 1 ms (D part 1), then 1.5 after 10⁻³⁰ s (a
        // rate of 5·10²⁹/s: the output goes to the limit), then 2 after 1 ms: ė 500/s, so the
        // D part, and with kp = ki = 0 the output, is 0.5. (Had the D part kept the absurd
        // rate, the last step would subtract f32::MAX and land on −10.)
        let mut c =
            IncrementalPid::new(IncrementalPidConfig::new(0.0, 0.0, 0.001).with_output_limit(10.0))
                .unwrap();
        c.update(0.0, 0.0, DT);
        assert!((c.update(1.0, 0.0, DT).output - 1.0).abs() < 1e-4);
        assert_eq!(c.update(1.5, 0.0, 1e-30).output, 10.0);
        assert!((c.update(2.0, 0.0, DT).output - 0.5).abs() < 1e-4);
    }

    #[test]
    fn an_overflowing_term_is_held_at_the_largest_float_before_the_sum() {
        // No limit, kp 1e30: errors 0, then 1e10 (P = 1e40, past f32::MAX ≈ 3.4e38), then
        // −1e10 (P = −2e40). Each P is held at ±f32::MAX before it is added: the output goes
        // to f32::MAX and back to exactly 0 (summed raw, P would read ∞ and the output land
        // on −f32::MAX: ∞ clamped, then −∞ added).
        let mut c = IncrementalPid::new(IncrementalPidConfig::new(1e30, 0.0, 0.0)).unwrap();
        c.update(0.0, 0.0, DT);
        let up = c.update(1e10, 0.0, DT);
        assert_eq!((up.p, up.output), (f32::MAX, f32::MAX));
        let down = c.update(-1e10, 0.0, DT);
        assert_eq!((down.p, down.output), (-f32::MAX, 0.0));
        // P and I overflowing the opposite ways in one step (ki −1e30 /s, error 1e10 for
        // 1 s: I = −1e40): +f32::MAX and −f32::MAX, an output of 0, not NaN.
        let mut c = IncrementalPid::new(IncrementalPidConfig::new(1e30, -1e30, 0.0)).unwrap();
        c.update(0.0, 0.0, DT);
        let t = c.update(1e10, 0.0, 1.0);
        assert_eq!((t.p, t.i, t.output), (f32::MAX, -f32::MAX, 0.0));
    }

    #[test]
    fn kd_switched_off_leaves_no_d_and_no_negative_zero() {
        // kd 0.001 on a falling error (−1 a ms: a kept D part of −1), then kd 0: the kept
        // part scales to −0. The next step's D is +0 (the rates' change is 0 − 0), and
        // P and I alone move the output: kp · (−3 − (−2)) + ki · (−3) · 0.001 = −1 − 0.003.
        let cfg = IncrementalPidConfig::new(1.0, 1.0, 0.001);
        let mut c = IncrementalPid::new(cfg).unwrap();
        for e in [0.0, -1.0, -2.0] {
            c.update(e, 0.0, DT);
        }
        let before = c.output();
        c.set_config(IncrementalPidConfig { kd: 0.0, ..cfg })
            .unwrap();
        let t = c.update(-3.0, 0.0, DT);
        assert_eq!(t.d.to_bits(), 0.0f32.to_bits());
        assert!((t.output - (before - 1.003)).abs() < 1e-5, "{t:?}");
    }

    #[test]
    fn output_limit_is_anti_windup() {
        let mut c =
            IncrementalPid::new(IncrementalPidConfig::new(0.0, 1000.0, 0.0).with_output_limit(5.0))
                .unwrap();
        for _ in 0..1000 {
            c.update(100.0, 0.0, DT);
        }
        assert_eq!(c.output(), 5.0);
        // The first reversed error leaves the limit at once: 5 + 1000·(-1)·0.001 = 4.
        assert!((c.update(0.0, 1.0, DT).output - 4.0).abs() < 1e-5);
    }

    #[test]
    fn deadband_holds_output() {
        let mut c =
            IncrementalPid::new(IncrementalPidConfig::new(1.0, 100.0, 0.0).with_deadband(5.0))
                .unwrap();
        c.update(100.0, 0.0, DT);
        let held = c.output();
        assert_eq!(c.update(100.0, 97.0, DT).output, held);
        // On the edge, |e| = 5: still inside.
        assert_eq!(c.update(100.0, 95.0, DT).output, held);
        // No deadband: an error of exactly 0 is a step, P = 18 · (0 − 7) = −126.
        let mut c = IncrementalPid::new(IncrementalPidConfig::new(18.0, 0.0, 0.0)).unwrap();
        c.update(7.0, 0.0, DT);
        assert_eq!(c.update(7.0, 7.0, DT).output, -126.0);
    }

    #[test]
    fn td_starts_from_measurement_so_first_call_does_not_jump() {
        let mut c =
            IncrementalPid::new(IncrementalPidConfig::new(10.0, 0.0, 0.0).with_td(30.0)).unwrap();
        // Motor at 50 rpm, target 300 rpm: the TD starts at 50, so the error is small at first.
        let t = c.update(300.0, 50.0, DT);
        assert_eq!(t.output, 0.0);
        let t2 = c.update(300.0, 50.0, DT);
        assert!(t2.output > 0.0 && t2.output < 10.0, "{t2:?}");
    }

    #[test]
    fn td_after_long_pause_stays_bounded() {
        let mut c =
            IncrementalPid::new(IncrementalPidConfig::new(1.0, 1.0, 0.0).with_td(100.0)).unwrap();
        c.update(0.0, 0.0, DT);
        let t = c.update(1000.0, 0.0, 5.0); // five seconds without a call
        assert!(t.output.is_finite());
        assert!(t.output.abs() <= 1.0 * 1000.0 + 1.0 * 1000.0 * 5.0 + 1e-3);
    }

    #[test]
    fn absurd_target_through_td_does_not_latch_the_output() {
        let mut c = IncrementalPid::new(
            IncrementalPidConfig::new(1.0, 10.0, 0.0)
                .with_output_limit(20.0)
                .with_td(100.0),
        )
        .unwrap();
        c.update(0.0, 0.0, DT);
        assert_eq!(c.update(3e38, 0.0, DT).output, 20.0);
        // A sane negative target afterwards must drive the output down to the other limit.
        let mut out = 20.0;
        for _ in 0..2000 {
            out = c.update(-50.0, 0.0, DT).output;
            assert!(out.is_finite());
        }
        assert_eq!(out, -20.0);
    }

    #[test]
    fn invalid_td_rate_is_rejected() {
        assert_eq!(
            IncrementalPid::new(IncrementalPidConfig::new(1.0, 0.0, 0.0).with_td(0.0)).unwrap_err(),
            PidConfigError::InvalidTrackingRate
        );
    }

    #[test]
    fn reset_zeroes_output() {
        let mut c = IncrementalPid::new(IncrementalPidConfig::new(1.0, 100.0, 0.0)).unwrap();
        c.update(10.0, 0.0, DT);
        c.reset();
        assert_eq!(c.output(), 0.0);
        c.set_output(3.0);
        assert_eq!(c.update(0.0, 0.0, DT).output, 3.0);
    }

    /// The step as documented, written out plainly with every term held finite before the
    /// sum (no shortcut): what `update` must equal bit for bit, without a TD.
    struct Plain {
        kp: f32,
        ki: f32,
        kd: f32,
        limit: f32,
        band: f32,
        output: f32,
        history: Option<(f32, f32)>,
        since_s: f32,
    }

    impl Plain {
        fn step(&mut self, target: f32, measurement: f32, dt_s: f32) -> PidTerms {
            if !(target.is_finite() && measurement.is_finite()) {
                return PidTerms::ZERO;
            }
            let e = target - measurement;
            let dt_ok = dt_s.is_finite() && dt_s > 0.0;
            if !dt_ok || e.abs() <= self.band {
                if dt_ok {
                    self.since_s += dt_s;
                }
                return PidTerms {
                    output: self.output,
                    ..PidTerms::ZERO
                };
            }
            let (e1, d_before) = self.history.unwrap_or((e, 0.0));
            let cap = self.limit.min(f32::MAX);
            let d_now = if self.kd == 0.0 {
                0.0
            } else {
                finite(self.kd * (e - e1) / (self.since_s + dt_s)).clamp(-cap, cap)
            };
            let p = finite(self.kp * (e - e1));
            let i = finite(self.ki * e * dt_s);
            let d = finite(d_now - d_before);
            self.output = (self.output + p + i + d).clamp(-cap, cap);
            self.history = Some((e, d_now));
            self.since_s = 0.0;
            PidTerms {
                p,
                i,
                d,
                ff: 0.0,
                output: self.output,
            }
        }
    }

    proptest! {
        #[test]
        fn the_step_is_the_plain_documented_step_bit_for_bit(
            kp in prop_oneof![Just(0.0f32), -1e3f32..1e3, -1e36f32..1e36],
            ki in prop_oneof![Just(0.0f32), -1e3f32..1e3, -1e36f32..1e36],
            kd in prop_oneof![Just(0.0f32), -1.0f32..1.0, -1e36f32..1e36],
            limit in prop_oneof![Just(f32::INFINITY), 0.0f32..1e3],
            deadband in prop_oneof![Just(0.0f32), 0.0f32..5.0],
            steps in proptest::collection::vec(
                (prop_oneof![-1e4f32..1e4, -3e38f32..3e38, Just(-0.0f32), proptest::num::f32::ANY],
                 prop_oneof![-1e4f32..1e4, -3e38f32..3e38, Just(0.0f32)],
                 prop_oneof![Just(0.001f32), 1e-30f32..10.0, proptest::num::f32::ANY]),
                1..48),
        ) {
            let config = IncrementalPidConfig::new(kp, ki, kd)
                .with_output_limit(limit)
                .with_deadband(deadband);
            let mut c = IncrementalPid::new(config).unwrap();
            let band = if deadband == 0.0 { -1.0 } else { deadband };
            let mut plain = Plain {
                kp, ki, kd, limit, band, output: 0.0, history: None, since_s: 0.0,
            };
            let bits = |t: PidTerms| [t.p, t.i, t.d, t.ff, t.output].map(f32::to_bits);
            for (target, measurement, dt) in steps {
                prop_assert_eq!(bits(c.update(target, measurement, dt)), bits(plain.step(target, measurement, dt)));
                prop_assert_eq!(c.output().to_bits(), plain.output.to_bits());
            }
        }

        #[test]
        fn output_finite_and_limited_for_any_input(
            kp in -1e4f32..1e4, ki in -1e4f32..1e4, kd in -10f32..10.0,
            limit in 0.0f32..1e5, td in proptest::option::of(1.0f32..1e3),
            steps in proptest::collection::vec(
                (proptest::num::f32::ANY, proptest::num::f32::ANY, proptest::num::f32::ANY), 1..64),
        ) {
            let mut cfg = IncrementalPidConfig::new(kp, ki, kd).with_output_limit(limit);
            cfg.td_r_rad_s = td;
            let mut c = IncrementalPid::new(cfg).unwrap();
            for (target, meas, dt) in steps {
                let t = c.update(target, meas, dt);
                prop_assert!(t.output.is_finite() && t.output.abs() <= limit);
            }
        }
    }
}
