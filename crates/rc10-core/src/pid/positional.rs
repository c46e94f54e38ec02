//! Positional PID (RC10_LIB `PID_Position`): trapezoid integral, derivative on measurement,
//! integral separation, deadband, integral and output limits, circular error for angles.

use super::{ErrorMode, PidConfigError, PidTerms, check_deadband, check_gains, check_limit};
use crate::filter::LowPass;
use crate::math::{finite, saturate};

/// Configuration of a positional [`Pid`]. Build it with [`PidConfig::new`] and the chainable
/// `with_*` setters (all `const`, so configurations can be constants).
///
/// ```
/// use rc10_core::pid::{ErrorMode, PidConfig};
/// const ANGLE_LOOP: PidConfig = PidConfig::new(8.0, 0.0, 0.05)
///     .with_output_limit(300.0) // rpm: the angle loop commands the speed loop
///     .with_error_mode(ErrorMode::DEGREES);
/// assert_eq!(ANGLE_LOOP.output_limit, 300.0);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PidConfig {
    /// Proportional gain, output units per error unit.
    pub kp: f32,
    /// Integral gain, output units per (error unit · second).
    pub ki: f32,
    /// Derivative gain, output units per (error unit / second).
    pub kd: f32,
    /// `|output| ≤ output_limit`, in output units; `f32::INFINITY` for none.
    pub output_limit: f32,
    /// `|i term| ≤ integral_limit`, in output units; `f32::INFINITY` for none.
    pub integral_limit: f32,
    /// Integral separation: while `|error| > integral_separation` the integral is **frozen**
    /// (it neither grows nor decays, and it still contributes its held value to the output).
    /// RC10_LIB switched the whole I term off instead, which made the output jump at the
    /// threshold. `f32::INFINITY` disables separation. It must be above the
    /// [`deadband`](Self::deadband) (0 with no deadband): at or below it no error would ever
    /// be integrated, and the I term would be off without a word (a C habit writes 0 for "no
    /// separation"); [`validate`](Self::validate) refuses it.
    pub integral_separation: f32,
    /// Errors with `|error| ≤ deadband` count as zero for P and I (the I term holds, so a
    /// holding current is kept; the step that enters the band still adds the trapezoid's
    /// half of the previous error); D still damps. Outside the band the full error is used.
    /// (RC10_LIB's band is `|error| < deadband`.)
    pub deadband: f32,
    /// Cutoff of a first-order low-pass on the D term in hertz; `0.0` for no filter. After a
    /// reset the filter starts from zero, so the first derivative sample is smoothed like
    /// the rest rather than passed through.
    pub d_cutoff_hz: f32,
    /// Linear or circular (angle) error.
    pub error_mode: ErrorMode,
}

impl PidConfig {
    /// Gains with no limits, no separation, no deadband, no D filter and a linear error.
    pub const fn new(kp: f32, ki: f32, kd: f32) -> Self {
        Self {
            kp,
            ki,
            kd,
            output_limit: f32::INFINITY,
            integral_limit: f32::INFINITY,
            integral_separation: f32::INFINITY,
            deadband: 0.0,
            d_cutoff_hz: 0.0,
            error_mode: ErrorMode::Linear,
        }
    }

    /// Sets [`output_limit`](Self::output_limit).
    #[must_use]
    pub const fn with_output_limit(mut self, limit: f32) -> Self {
        self.output_limit = limit;
        self
    }

    /// Sets [`integral_limit`](Self::integral_limit).
    #[must_use]
    pub const fn with_integral_limit(mut self, limit: f32) -> Self {
        self.integral_limit = limit;
        self
    }

    /// Sets [`integral_separation`](Self::integral_separation).
    #[must_use]
    pub const fn with_integral_separation(mut self, threshold: f32) -> Self {
        self.integral_separation = threshold;
        self
    }

    /// Sets [`deadband`](Self::deadband).
    #[must_use]
    pub const fn with_deadband(mut self, deadband: f32) -> Self {
        self.deadband = deadband;
        self
    }

    /// Sets [`d_cutoff_hz`](Self::d_cutoff_hz).
    #[must_use]
    pub const fn with_d_cutoff_hz(mut self, cutoff_hz: f32) -> Self {
        self.d_cutoff_hz = cutoff_hz;
        self
    }

    /// Sets [`error_mode`](Self::error_mode).
    #[must_use]
    pub const fn with_error_mode(mut self, mode: ErrorMode) -> Self {
        self.error_mode = mode;
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
        if let Err(e) = check_limit(self.integral_limit) {
            return Err(e);
        }
        if let Err(e) = check_deadband(self.deadband) {
            return Err(e);
        }
        if self.integral_separation.is_nan() || self.integral_separation <= self.deadband {
            return Err(PidConfigError::InvalidSeparation);
        }
        if self.d_cutoff_hz.is_nan() || self.d_cutoff_hz < 0.0 {
            return Err(PidConfigError::InvalidFilter);
        }
        if !self.error_mode.is_valid() {
            return Err(PidConfigError::InvalidPeriod);
        }
        Ok(())
    }
}

/// Positional PID controller.
///
/// `output = kp·e + I + D + ff`, limited to `±output_limit`, where
/// - the integral accumulates `ki · (e[k] + e[k-1]) / 2 · dt` (trapezoid rule) and is stored
///   in output units, so changing `ki` on the fly does not bump the output;
/// - anti-windup: the integral is limited to `±integral_limit`, frozen during integral
///   separation, and not grown while the output is saturated in the same direction
///   (conditional integration);
/// - `D = -kd · d(measurement)/dt` (derivative on measurement: a target step gives no kick),
///   optionally low-pass filtered, and computed on the wrapped change in circular mode.
///
/// ```
/// use rc10_core::pid::{Pid, PidConfig};
/// let mut pid = Pid::new(PidConfig::new(2.0, 0.0, 0.0).with_output_limit(5.0)).unwrap();
/// let terms = pid.update(10.0, 8.0, 0.001);
/// assert_eq!(terms.p, 4.0);
/// assert_eq!(terms.output, 4.0);
/// assert_eq!(pid.update(10.0, 0.0, 0.001).output, 5.0); // limited
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pid {
    config: PidConfig,
    integral: f32,
    prev_error: Option<f32>,
    prev_measurement: Option<f32>,
    d_filter: LowPass,
    last: PidTerms,
    /// `output_limit`, at most `f32::MAX` (derived from the configuration).
    output_cap: f32,
    /// `integral_limit`, at most `f32::MAX` (derived from the configuration).
    integral_cap: f32,
    /// Which step the configuration takes (derived from it).
    path: Path,
}

/// The step a configuration takes, decided once when it is set so that a step tests one
/// value instead of each part of the configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Path {
    /// Deadband, integral separation or a D filter: the general step.
    General,
    /// None of those: the general step with those parts known to do nothing.
    Plain,
    /// Plain, and also a linear error, `kd = 0` and `ki ≠ 0` (the usual speed loop): the plain
    /// step with those known too.
    PlainPi,
}

/// Which ways a step may move the integral: what a cascade asks of its loops. Every loop
/// holds its integral while readings are stale ([`Integrate::NOT`]); an angle loop also holds
/// it from growing the way that would push a speed loop held at its limit further into it
/// ([`Integrate::NOT_UP`], [`Integrate::NOT_DOWN`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Integrate(u8);

impl Integrate {
    /// Either way (the usual step).
    pub(crate) const FREELY: Self = Self(Self::AT_ALL);
    /// Neither way: the integral holds.
    pub(crate) const NOT: Self = Self(0);
    /// Down only: the integral does not grow.
    pub(crate) const NOT_UP: Self = Self(Self::AT_ALL | Self::NO_UP);
    /// Up only: the integral does not fall.
    pub(crate) const NOT_DOWN: Self = Self(Self::AT_ALL | Self::NO_DOWN);
    // Laid out so that a `bool` is already the value `when` gives (no instruction on the
    // speed loop's path).
    const AT_ALL: u8 = 1;
    const NO_UP: u8 = 2;
    const NO_DOWN: u8 = 4;

    /// [`FREELY`](Self::FREELY) if `integrate`, else [`NOT`](Self::NOT).
    pub(crate) const fn when(integrate: bool) -> Self {
        Self(integrate as u8)
    }

    const fn at_all(self) -> bool {
        self.0 & Self::AT_ALL != 0
    }

    const fn up(self) -> bool {
        self.0 & Self::NO_UP == 0
    }

    const fn down(self) -> bool {
        self.0 & Self::NO_DOWN == 0
    }
}

/// Whether all three are finite, in a few instructions: `x · 0` is zero for finite `x` and
/// NaN for ±inf and NaN, and a NaN anywhere makes the sum NaN.
#[inline]
pub(super) fn all_finite(a: f32, b: f32, c: f32) -> bool {
    a * 0.0 + b * 0.0 + c * 0.0 == 0.0
}

/// Whether `dt_s` is finite and positive, in one integer comparison: the positive finite
/// floats (subnormals included) are exactly the bit patterns `1..=0x7F7F_FFFF`; zero, the
/// negatives (sign bit set), infinity and NaN all fall outside.
#[inline]
pub(super) fn dt_valid(dt_s: f32) -> bool {
    dt_s.to_bits().wrapping_sub(1) < 0x7F7F_FFFF
}

/// The smaller of `a` and `b` by comparison (`f32::min` is a library call on the Cortex-M4).
#[inline]
pub(super) fn below(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// `x` within `±lim`, for a `lim` in `[0, f32::MAX]` and an `x` that is not NaN.
#[inline]
pub(super) fn clamp_abs(x: f32, lim: f32) -> f32 {
    if x > lim {
        lim
    } else if x < -lim {
        -lim
    } else {
        x
    }
}

/// A limit capped at `f32::MAX` (infinity, "no limit", becomes the largest finite value).
pub(super) const fn cap(limit: f32) -> f32 {
    if limit < f32::MAX { limit } else { f32::MAX }
}

/// The step a (valid) configuration takes.
const fn path_of(config: &PidConfig) -> Path {
    let plain = config.deadband == 0.0
        && config.integral_separation == f32::INFINITY
        && LowPass::new(config.d_cutoff_hz).tau_s() == 0.0;
    let pi = matches!(config.error_mode, ErrorMode::Linear) && config.kd == 0.0 && config.ki != 0.0;
    match (plain, pi) {
        (false, _) => Path::General,
        (true, false) => Path::Plain,
        (true, true) => Path::PlainPi,
    }
}

impl Pid {
    /// A controller with the given configuration, or why the configuration cannot work.
    pub const fn new(config: PidConfig) -> Result<Self, PidConfigError> {
        match config.validate() {
            Ok(()) => Ok(Self {
                config,
                integral: 0.0,
                prev_error: None,
                prev_measurement: None,
                d_filter: LowPass::new(config.d_cutoff_hz),
                last: PidTerms::ZERO,
                output_cap: cap(config.output_limit),
                integral_cap: cap(config.integral_limit),
                path: path_of(&config),
            }),
            Err(e) => Err(e),
        }
    }

    /// The configuration.
    pub const fn config(&self) -> &PidConfig {
        &self.config
    }

    /// Replaces the configuration (live tuning), keeping the integral (re-limited) and history.
    pub fn set_config(&mut self, config: PidConfig) -> Result<(), PidConfigError> {
        config.validate()?;
        if config.kd == 0.0 {
            // No D path runs while kd is 0, so the filter would keep the derivative of the
            // moment kd was cleared and hand it back when kd returns: start it afresh.
            self.d_filter = LowPass::new(config.d_cutoff_hz);
        } else if config.d_cutoff_hz != self.config.d_cutoff_hz {
            // New cutoff, same present output: no bump in the D term.
            let present = self.d_filter.output();
            self.d_filter = LowPass::new(config.d_cutoff_hz);
            if let Some(d) = present {
                self.d_filter.reset_to(d);
            }
        }
        self.config = config;
        self.output_cap = cap(config.output_limit);
        self.integral_cap = cap(config.integral_limit);
        self.path = path_of(&config);
        self.integral = saturate(self.integral, config.integral_limit);
        Ok(())
    }

    /// One step without feed-forward; see [`update_with_ff`](Self::update_with_ff).
    #[inline]
    pub fn update(&mut self, target: f32, measurement: f32, dt_s: f32) -> PidTerms {
        self.update_within(target, measurement, 0.0, dt_s, f32::INFINITY)
    }

    /// One control step: `target` and `measurement` in the measured unit, `feed_forward` in
    /// output units, `dt_s` the time since the previous step in seconds.
    ///
    /// Non-finite `target`, `measurement` or `feed_forward`: returns [`PidTerms::ZERO`] and
    /// leaves the state unchanged. A `dt_s` that is not finite and positive keeps the integral
    /// and the derivative as they were for this step.
    #[inline]
    pub fn update_with_ff(
        &mut self,
        target: f32,
        measurement: f32,
        feed_forward: f32,
        dt_s: f32,
    ) -> PidTerms {
        self.update_within(target, measurement, feed_forward, dt_s, f32::INFINITY)
    }

    /// [`update_with_ff`](Self::update_with_ff) under an extra output limit that is in force
    /// now, `|output| ≤ limit` (e.g. an ESC limit lowered by thermal derating or by chassis
    /// power limiting). The smaller of `limit` and the configured
    /// [`output_limit`](PidConfig::output_limit) is the *effective* limit, and anti-windup
    /// works against it: the integral does not grow while the output is held there, and it is
    /// kept within `±(effective limit + |feed_forward|)` (what, with the feed-forward, can
    /// reach the limit; beyond it is effort that cannot be applied, and would make the output
    /// jump when the limit is lifted), and within `integral_limit`. A NaN or negative `limit`
    /// counts as zero.
    #[inline]
    pub fn update_within(
        &mut self,
        target: f32,
        measurement: f32,
        feed_forward: f32,
        dt_s: f32,
        limit: f32,
    ) -> PidTerms {
        if !all_finite(target, measurement, feed_forward) {
            return PidTerms::ZERO;
        }
        let ways = Integrate::FREELY;
        self.step_finite::<false>(target, measurement, feed_forward, dt_s, limit, ways);
        self.last
    }

    /// [`update_within`](Self::update_within) returning the output only (`0.0` for rejected
    /// input); the per-term breakdown is in [`last_terms`](Self::last_terms). What a cascade
    /// calls every tick: nothing is built or copied that it does not read.
    #[inline]
    pub fn output_within(
        &mut self,
        target: f32,
        measurement: f32,
        feed_forward: f32,
        dt_s: f32,
        limit: f32,
    ) -> f32 {
        let ways = Integrate::FREELY;
        self.output_integrating(target, measurement, feed_forward, dt_s, limit, ways)
    }

    /// [`output_within`](Self::output_within), moving the integral only the `ways` allowed
    /// (otherwise it holds where it is, within the limits in force): what a cascade runs for
    /// its angle loop, holding it while the feedback is stale (the loop would integrate an
    /// error whose measurement no longer changes) or from winding up against a speed loop held
    /// at its limit.
    #[inline]
    pub(crate) fn output_integrating(
        &mut self,
        target: f32,
        measurement: f32,
        feed_forward: f32,
        dt_s: f32,
        limit: f32,
        ways: Integrate,
    ) -> f32 {
        if !all_finite(target, measurement, feed_forward) {
            return 0.0;
        }
        self.step_finite::<false>(target, measurement, feed_forward, dt_s, limit, ways)
    }

    /// [`output_within`](Self::output_within) for a caller that keeps `target` and
    /// `feed_forward` finite itself (the cascade, whose setters refuse anything else): only
    /// `measurement` is checked (a non-finite one returns `0.0` and changes nothing). Unless
    /// `integrate`, the integral holds (the speed loop on stale feedback).
    #[inline]
    pub(crate) fn output_within_finite_target(
        &mut self,
        target: f32,
        measurement: f32,
        feed_forward: f32,
        dt_s: f32,
        limit: f32,
        integrate: bool,
    ) -> f32 {
        if !measurement.is_finite() {
            return 0.0;
        }
        // The PI path only here, where the speed loop calls: one more copy of the step in
        // the firmware, not one per entry point.
        let ways = Integrate::when(integrate);
        self.step_finite::<true>(target, measurement, feed_forward, dt_s, limit, ways)
    }

    /// One step for finite `target`, `measurement` and `feed_forward`: updates the state and
    /// `last`, returns the output.
    ///
    /// Every intermediate stays finite, so the limits are plain comparisons: the error, P and
    /// D are held within `±f32::MAX` (a difference of two huge finite values can overflow),
    /// the limits are at most `f32::MAX`, an integral increment can only be `±inf` (never NaN:
    /// `ki ≠ 0`, `dt > 0` and the two errors are finite) and is clamped, and a sum of finite
    /// terms with at most one infinite partial sum is never NaN.
    ///
    /// The configuration is looked at once, when it is set ([`Path`]): without a deadband,
    /// integral separation or D filter (the usual speed and angle loops) the step is the
    /// general one with those parts known to do nothing, so they are not computed at all.
    /// With `PI_PATH` a linear PI loop also skips the D term and the error mode (what the
    /// speed loop's entry point, [`output_within_finite_target`](Self::output_within_finite_target),
    /// asks for); without it the plain step serves a PI loop too (it tests kd and ki itself).
    #[inline(always)]
    fn step_finite<const PI_PATH: bool>(
        &mut self,
        target: f32,
        measurement: f32,
        feed_forward: f32,
        dt_s: f32,
        limit: f32,
        ways: Integrate,
    ) -> f32 {
        let (t, m, ff) = (target, measurement, feed_forward);
        match self.path {
            Path::PlainPi if PI_PATH => self.step_plain::<true>(t, m, ff, dt_s, limit, ways),
            Path::PlainPi | Path::Plain => self.step_plain::<false>(t, m, ff, dt_s, limit, ways),
            Path::General => self.step_general(t, m, ff, dt_s, limit, ways),
        }
    }

    /// The limit in force (`limit` or the configured one, the lower; NaN and negative count
    /// as zero) and the integral's limit under it.
    #[inline(always)]
    fn limits(&self, feed_forward: f32, limit: f32) -> (f32, f32) {
        // `max(0)` by comparison: NaN and negative limits become 0.
        let extra = if limit > 0.0 { limit } else { 0.0 };
        let out_limit = below(extra, self.output_cap);
        // The integral never needs to exceed what, with the feed-forward, reaches the limit.
        let i_limit = below(out_limit + feed_forward.abs(), self.integral_cap);
        (out_limit, i_limit)
    }

    /// The integral after this step, starting from the stored one, given the increment's
    /// trapezoid mean `(error + prev_error) / 2`, computed as `0.5·error + 0.5·prev_error` so
    /// that two errors of `f32::MAX` stay finite (conditional integration against
    /// `out_limit`).
    /// With `DIRECTIONAL`, `ways` may also hold it from moving one way (the angle loop's
    /// steps; the speed loop's PI step, which never gets such a request, skips the test).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn integrate<const DIRECTIONAL: bool>(
        &self,
        error_mean: f32,
        dt_s: f32,
        (p, d, feed_forward): (f32, f32, f32),
        out_limit: f32,
        i_limit: f32,
        ways: Integrate,
    ) -> f32 {
        // Held within the limit in force (which may have dropped since the last step); a
        // new value below replaces it already clamped.
        let integral = clamp_abs(self.integral, i_limit);
        // Finite error mean: a ki so small that it multiplies to 0 gives 0, not 0 · ∞ = NaN.
        let increment = self.config.ki * error_mean * dt_s;
        let candidate = clamp_abs(integral + increment, i_limit);
        // The plain sum: should terms near ±f32::MAX cancel and a partial sum overflow, it
        // errs towards holding the integral for the step, which is harmless at such values
        // (the output itself is summed exactly, in `finish`).
        let unlimited = p + candidate + d + feed_forward;
        // Signs compared, not multiplied: a product of two tiny values underflows to 0.
        let growth = candidate - integral;
        let winding_up =
            (unlimited > out_limit && growth > 0.0) || (unlimited < -out_limit && growth < 0.0);
        let refused =
            DIRECTIONAL && ((growth > 0.0 && !ways.up()) || (growth < 0.0 && !ways.down()));
        if winding_up || refused {
            integral
        } else {
            candidate
        }
    }

    /// [`step_finite`](Self::step_finite) for a configuration without deadband, integral
    /// separation or D filter: the error is always in band, `|e| ≤ 0` only for `±0` (which
    /// the deadband turns into `+0`, as `e + 0.0` does), and D passes unfiltered. With `PI`
    /// ([`Path::PlainPi`]) the error is also linear, D is 0 and I runs. Inlined where the
    /// optimiser chooses (forced, the chassis firmware grew by almost a kilobyte).
    #[inline]
    fn step_plain<const PI: bool>(
        &mut self,
        target: f32,
        measurement: f32,
        feed_forward: f32,
        dt_s: f32,
        limit: f32,
        ways: Integrate,
    ) -> f32 {
        let (out_limit, i_limit) = self.limits(feed_forward, limit);
        let c = &self.config;
        let difference = if PI {
            target - measurement
        } else {
            c.error_mode.diff(target, measurement)
        };
        let error = finite(difference) + 0.0;
        let dt_ok = dt_valid(dt_s);
        let p = finite(c.kp * error);
        let d = if PI || c.kd == 0.0 {
            0.0
        } else {
            self.plain_derivative(measurement, dt_s, dt_ok)
        };
        let integral = if dt_ok && ways.at_all() && (PI || self.config.ki != 0.0) {
            let prev_error = match self.prev_error {
                Some(e) => e,
                None => error,
            };
            let mean = 0.5 * error + 0.5 * prev_error;
            let terms = (p, d, feed_forward);
            if PI {
                self.integrate::<false>(mean, dt_s, terms, out_limit, i_limit, ways)
            } else {
                self.integrate::<true>(mean, dt_s, terms, out_limit, i_limit, ways)
            }
        } else {
            clamp_abs(self.integral, i_limit)
        };
        self.finish(
            p,
            integral,
            d,
            feed_forward,
            out_limit,
            Some(error),
            measurement,
        )
    }

    /// The unfiltered D term (`kd ≠ 0`, no D filter): what [`derivative`](Self::derivative)
    /// gives with a pass-through filter, whose output is the last raw value.
    #[inline(always)]
    fn plain_derivative(&mut self, measurement: f32, dt_s: f32, dt_ok: bool) -> f32 {
        match self.prev_measurement {
            Some(prev) if dt_ok => {
                let change = self.config.error_mode.diff(measurement, prev);
                let raw_d = finite(-self.config.kd * change / dt_s);
                self.d_filter.set_output(raw_d);
                raw_d
            }
            Some(_) => self.d_filter.output().unwrap_or(0.0),
            None => 0.0,
        }
    }

    /// Stores the step's state and terms and returns them.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn finish(
        &mut self,
        p: f32,
        integral: f32,
        d: f32,
        feed_forward: f32,
        out_limit: f32,
        prev_error: Option<f32>,
        measurement: f32,
    ) -> f32 {
        let output = clamp_abs(sum_terms(p, integral, d, feed_forward), out_limit);
        self.integral = integral;
        self.prev_error = prev_error;
        self.prev_measurement = Some(measurement);
        // Field by field: a whole-struct store is built on the stack and copied.
        self.last.p = p;
        self.last.i = integral;
        self.last.d = d;
        self.last.ff = feed_forward;
        self.last.output = output;
        output
    }

    /// [`step_finite`](Self::step_finite) for any configuration.
    #[inline(never)]
    fn step_general(
        &mut self,
        target: f32,
        measurement: f32,
        feed_forward: f32,
        dt_s: f32,
        limit: f32,
        ways: Integrate,
    ) -> f32 {
        let (out_limit, i_limit) = self.limits(feed_forward, limit);
        let c = &self.config;
        let raw_error = finite(c.error_mode.diff(target, measurement));
        let error = if raw_error.abs() <= c.deadband {
            0.0
        } else {
            raw_error
        };
        let dt_ok = dt_valid(dt_s);

        let p = finite(c.kp * error);
        // With kd = 0 the D path is skipped entirely (no divide, no filter).
        let d = if c.kd == 0.0 {
            0.0
        } else {
            self.derivative(measurement, dt_s, dt_ok)
        };

        let c = &self.config;
        let in_band = raw_error.abs() <= c.integral_separation;
        let integral = if dt_ok && ways.at_all() && c.ki != 0.0 && in_band {
            // Trapezoid over in-band errors only: right after the error re-enters the band the
            // previous (separated) error is not folded in.
            let prev_error = match self.prev_error {
                Some(e) => e,
                None => error,
            };
            self.integrate::<true>(
                0.5 * error + 0.5 * prev_error,
                dt_s,
                (p, d, feed_forward),
                out_limit,
                i_limit,
                ways,
            )
        } else {
            clamp_abs(self.integral, i_limit)
        };
        let prev_error = if in_band { Some(error) } else { None };
        self.finish(
            p,
            integral,
            d,
            feed_forward,
            out_limit,
            prev_error,
            measurement,
        )
    }

    /// The D term (`kd ≠ 0`): `-kd · d(measurement)/dt`, through the optional low-pass.
    fn derivative(&mut self, measurement: f32, dt_s: f32, dt_ok: bool) -> f32 {
        let c = &self.config;
        match self.prev_measurement {
            Some(prev) if dt_ok => {
                let change = c.error_mode.diff(measurement, prev);
                let raw_d = finite(-c.kd * change / dt_s);
                if self.d_filter.output().is_none() {
                    // Start the filter from "no derivative", so the first sample after a
                    // reset is smoothed like every other one instead of passing straight
                    // through.
                    self.d_filter.reset_to(0.0);
                }
                self.d_filter.update(raw_d, dt_s)
            }
            Some(_) => self.d_filter.output().unwrap_or(0.0),
            None => 0.0,
        }
    }

    /// The terms of the most recent accepted step ([`PidTerms::ZERO`] before the first).
    pub const fn last_terms(&self) -> PidTerms {
        self.last
    }

    /// Which way the last accepted step's output was held at its limit: `1` when the terms
    /// summed to more than the output (held at `+limit`), `-1` when to less (held at
    /// `-limit`), `0` when the output is the sum itself (or before the first step, and after
    /// a reset). Exact: the output is the clamped sum of the same terms. A step refused for
    /// non-finite input changes nothing, this included.
    pub(crate) fn last_clamp(&self) -> i8 {
        let t = &self.last;
        let sum = sum_terms(t.p, t.i, t.d, t.ff);
        if sum > t.output {
            1
        } else if sum < t.output {
            -1
        } else {
            0
        }
    }

    /// The integral term in output units.
    pub const fn integral(&self) -> f32 {
        self.integral
    }

    /// Sets the integral term (output units, limited to `±integral_limit`; NaN sets zero).
    ///
    /// Used for bumpless transfer: when a loop takes over from another mode, preload the
    /// integral with the output the actuator already has, and the first step continues from it.
    pub fn set_integral(&mut self, value_out: f32) {
        self.integral = saturate(value_out, self.config.integral_limit);
    }

    /// Forgets the error and measurement history and the D filter, keeping the integral: the
    /// next step takes no derivative and starts its trapezoid from its own error. For a
    /// measurement whose origin just moved (an encoder re-homed while running), whose jump is
    /// no motion: differentiated, it would kick the output for a step.
    pub fn forget_history(&mut self) {
        self.prev_error = None;
        self.prev_measurement = None;
        self.d_filter.reset();
    }

    /// Clears the integral, the error and measurement history and the D filter, so the next
    /// step behaves like the first (no derivative from stale history).
    pub fn reset(&mut self) {
        self.integral = 0.0;
        self.prev_error = None;
        self.prev_measurement = None;
        self.d_filter.reset();
        self.last = PidTerms::ZERO;
    }
}

/// `p + i + d + ff` of finite terms. Summed left to right as usual; should a partial sum
/// overflow (terms near `±f32::MAX` of opposite signs, whose total may be small), summed
/// again in quarters, which cannot overflow (scaling by 4 is exact for normal values): the
/// result is then the true sum within a rounding of the largest term, as any f32 sum is,
/// and infinite only when the true sum is beyond `f32::MAX`. One comparison on the usual
/// path.
#[inline(always)]
fn sum_terms(p: f32, i: f32, d: f32, ff: f32) -> f32 {
    let sum = p + i + d + ff;
    if sum.is_finite() {
        sum
    } else {
        ((p * 0.25 + i * 0.25) + (d * 0.25 + ff * 0.25)) * 4.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const DT: f32 = 0.001;

    fn pid(config: PidConfig) -> Pid {
        Pid::new(config).unwrap()
    }

    #[test]
    fn a_one_way_hold_stops_the_integral_one_way_only() {
        // ki 10, 1 unit of error for 1 ms: ±0.01 a step. Plain and general steps alike (a
        // deadband takes the general one).
        for config in [
            PidConfig::new(0.0, 10.0, 0.0),
            PidConfig::new(0.0, 10.0, 0.0).with_deadband(0.001),
        ] {
            let mut p = pid(config);
            p.output_integrating(1.0, 0.0, 0.0, DT, f32::INFINITY, Integrate::NOT_UP);
            assert_eq!(p.integral(), 0.0);
            p.output_integrating(-1.0, 0.0, 0.0, DT, f32::INFINITY, Integrate::NOT_UP);
            // Trapezoid from +1 to −1: the mean is 0 for this step; the next falls.
            p.output_integrating(-1.0, 0.0, 0.0, DT, f32::INFINITY, Integrate::NOT_UP);
            assert!((p.integral() + 0.01).abs() < 1e-7, "{}", p.integral());
            p.output_integrating(-1.0, 0.0, 0.0, DT, f32::INFINITY, Integrate::NOT_DOWN);
            assert!((p.integral() + 0.01).abs() < 1e-7, "{}", p.integral());
            p.output_integrating(1.0, 0.0, 0.0, DT, f32::INFINITY, Integrate::NOT_DOWN);
            p.output_integrating(1.0, 0.0, 0.0, DT, f32::INFINITY, Integrate::NOT_DOWN);
            assert!(p.integral().abs() < 1e-7, "{}", p.integral());
            p.output_integrating(1.0, 0.0, 0.0, DT, f32::INFINITY, Integrate::NOT);
            assert!(p.integral().abs() < 1e-7, "{}", p.integral());
        }
    }

    #[test]
    fn the_last_clamp_says_which_way_the_output_was_held() {
        let mut p = pid(PidConfig::new(1.0, 0.0, 0.0).with_output_limit(5.0));
        assert_eq!(p.last_clamp(), 0);
        p.update(3.0, 0.0, DT);
        assert_eq!(p.last_clamp(), 0);
        p.update(8.0, 0.0, DT);
        assert_eq!(p.last_clamp(), 1);
        p.update(-8.0, 0.0, DT);
        assert_eq!(p.last_clamp(), -1);
        // Exactly at the limit is not held.
        p.update(5.0, 0.0, DT);
        assert_eq!(p.last_clamp(), 0);
        p.reset();
        assert_eq!(p.last_clamp(), 0);
    }

    #[test]
    fn new_invalid_config_is_rejected_with_reason() {
        assert_eq!(
            Pid::new(PidConfig::new(f32::NAN, 0.0, 0.0)).unwrap_err(),
            PidConfigError::GainNotFinite
        );
        assert_eq!(
            Pid::new(PidConfig::new(1.0, 0.0, 0.0).with_output_limit(-1.0)).unwrap_err(),
            PidConfigError::InvalidLimit
        );
        assert_eq!(
            Pid::new(
                PidConfig::new(1.0, 0.0, 0.0).with_error_mode(ErrorMode::Circular { period: 0.0 })
            )
            .unwrap_err(),
            PidConfigError::InvalidPeriod
        );
        assert_eq!(
            Pid::new(PidConfig::new(1.0, 0.0, 0.0).with_integral_separation(f32::NAN)).unwrap_err(),
            PidConfigError::InvalidSeparation
        );
    }

    #[test]
    fn integral_uses_trapezoid_rule() {
        // ki = 10 /s; errors 2 then 4 with dt = 0.1 s.
        // Step 1: (2 + 2)/2 · 0.1 · 10 = 2.  Step 2: (2 + 4)/2 · 0.1 · 10 = 3 → 5.
        let mut c = pid(PidConfig::new(0.0, 10.0, 0.0));
        assert!((c.update(2.0, 0.0, 0.1).i - 2.0).abs() < 1e-6);
        assert!((c.update(4.0, 0.0, 0.1).i - 5.0).abs() < 1e-6);
    }

    #[test]
    fn target_step_gives_no_derivative_kick() {
        let mut c = pid(PidConfig::new(0.0, 0.0, 1.0));
        c.update(0.0, 5.0, DT);
        let t = c.update(1000.0, 5.0, DT); // target jumps, measurement does not move
        assert_eq!(t.d, 0.0);
    }

    #[test]
    fn derivative_opposes_measurement_motion() {
        // Measurement rises 0.01 in 1 ms = 10 units/s; kd = 0.5 → d = -5.
        let mut c = pid(PidConfig::new(0.0, 0.0, 0.5));
        c.update(0.0, 0.0, DT);
        let d = c.update(0.0, 0.01, DT).d;
        assert!((d + 5.0).abs() < 1e-3, "d = {d}");
    }

    #[test]
    fn circular_error_takes_short_way_in_0_360_convention() {
        let mut c = pid(PidConfig::new(1.0, 0.0, 0.0).with_error_mode(ErrorMode::DEGREES));
        // From 350° to 10°: +20°, not -340°.
        assert!((c.update(10.0, 350.0, DT).p - 20.0).abs() < 1e-4);
        // From 10° to 350°: -20°.
        assert!((c.update(350.0, 10.0, DT).p + 20.0).abs() < 1e-4);
    }

    #[test]
    fn circular_error_takes_short_way_in_pm180_convention() {
        let mut c = pid(PidConfig::new(1.0, 0.0, 0.0).with_error_mode(ErrorMode::DEGREES));
        assert!((c.update(-170.0, 170.0, DT).p - 20.0).abs() < 1e-4);
    }

    #[test]
    fn circular_derivative_does_not_spike_when_measurement_wraps() {
        // 359.5° → 0.5° is a +1° move in 1 ms = 1000 deg/s: d = -kd · 1000 = -1 for kd = 0.001.
        // A linear derivative would see -359° and give +359.
        let mut c = pid(PidConfig::new(0.0, 0.0, 0.001).with_error_mode(ErrorMode::DEGREES));
        c.update(0.0, 359.5, DT);
        let d = c.update(0.0, 0.5, DT).d;
        assert!((d + 1.0).abs() < 1e-3, "d = {d}");
    }

    #[test]
    fn integral_separation_freezes_but_keeps_integral() {
        let mut c = pid(PidConfig::new(0.0, 100.0, 0.0).with_integral_separation(10.0));
        for _ in 0..10 {
            c.update(5.0, 0.0, DT); // inside the band: integrates
        }
        let held = c.integral();
        assert!(held > 4.0, "integral = {held}");
        // A large error: the integral stays where it was and still drives the output.
        let t = c.update(50.0, 0.0, DT);
        assert_eq!(t.i, held);
        assert_eq!(t.output, held);
    }

    #[test]
    fn deadband_zeroes_p_and_holds_integral() {
        let mut c = pid(PidConfig::new(2.0, 100.0, 0.0).with_deadband(1.0));
        c.update(10.0, 0.0, DT);
        let i = c.integral();
        let t = c.update(10.0, 9.5, DT); // error 0.5 inside the band
        assert_eq!(t.p, 0.0);
        // Trapezoid between the previous 10 and 0 adds half a step: (10 + 0)/2 · 0.001 · 100 = 0.5.
        assert!((t.i - (i + 0.5)).abs() < 1e-5);
        let t2 = c.update(10.0, 9.5, DT);
        assert!(
            (t2.i - t.i).abs() < 1e-6,
            "integral must hold inside the band"
        );
    }

    #[test]
    fn output_saturation_stops_windup() {
        let mut c = pid(PidConfig::new(1.0, 1000.0, 0.0).with_output_limit(10.0));
        for _ in 0..10_000 {
            c.update(100.0, 0.0, DT);
        }
        // Without anti-windup the integral would be ~1e5 (or the 10 its clamp allows); with
        // it, p = 1·100 alone is past the limit from the first step, so it never grows.
        assert_eq!(c.integral(), 0.0);
        // Once the error reverses, the output leaves saturation at once: p = −5, and the
        // trapezoid (−5 + 100)/2 · 1000 · 0.001 = 47.5 brings the integral to its limit 10.
        let t = c.update(0.0, 5.0, DT);
        assert!((t.output - 5.0).abs() < 1e-5, "output = {}", t.output);
    }

    #[test]
    fn restoring_kd_does_not_bring_back_the_derivative_of_before() {
        // kd 0.05 through a 20 Hz filter, 10 ms steps; the shaft turns 24 units a step
        // (2400 /s): raw D = −0.05 · 2400 = −120, and the filter settles there.
        let cfg = PidConfig::new(0.0, 0.0, 0.05).with_d_cutoff_hz(20.0);
        let mut c = pid(cfg);
        let mut d = 0.0;
        for k in 0..50 {
            d = c.update(0.0, k as f32 * 24.0, 0.01).d;
        }
        assert!((d + 120.0).abs() < 0.5, "{d}");
        // Live tuning of another gain keeps the filter: D goes on at −120 (restarted from 0
        // it would be 0.557 · −120 = −67).
        c.set_config(PidConfig { kp: 0.1, ..cfg }).unwrap();
        let d = c.update(0.0, 50.0 * 24.0, 0.01).d;
        assert!((d + 120.0).abs() < 0.5, "{d}");
        // kd cleared while it moves, then the shaft stops, then kd comes back: D is 0.
        c.set_config(PidConfig { kd: 0.0, ..cfg }).unwrap();
        for _ in 0..5 {
            c.update(0.0, 1224.0, 0.01);
        }
        c.set_config(cfg).unwrap();
        assert_eq!(c.update(0.0, 1224.0, 0.01).d, 0.0);
    }

    #[test]
    fn an_integral_gain_that_multiplies_to_zero_gives_no_nan() {
        // The smallest ki there is; errors of f32::MAX twice (the target and measurement are
        // 6e38 apart): their mean is f32::MAX, and ki · MAX · dt is a small number.
        let mut c = pid(PidConfig::new(0.0, f32::from_bits(1), 0.0));
        for _ in 0..3 {
            let t = c.update(3e38, -3e38, DT);
            assert!(t.output.is_finite() && t.i.is_finite(), "{t:?}");
            assert!(t.output > 0.0, "{t:?}");
        }
    }

    #[test]
    fn integral_limit_bounds_i_term() {
        let mut c = pid(PidConfig::new(0.0, 1000.0, 0.0).with_integral_limit(3.0));
        for _ in 0..1000 {
            c.update(1.0, 0.0, DT);
        }
        assert_eq!(c.integral(), 3.0);
    }

    #[test]
    fn non_finite_input_returns_zero_and_keeps_state() {
        let mut c = pid(PidConfig::new(1.0, 10.0, 0.1));
        c.update(5.0, 0.0, DT);
        let before = c;
        assert_eq!(c.update(f32::NAN, 0.0, DT), PidTerms::ZERO);
        assert_eq!(c.update(1.0, f32::INFINITY, DT), PidTerms::ZERO);
        assert_eq!(c.update_with_ff(1.0, 0.0, f32::NAN, DT), PidTerms::ZERO);
        assert_eq!(c, before);
    }

    #[test]
    fn invalid_dt_freezes_i_and_d() {
        let mut c = pid(PidConfig::new(1.0, 10.0, 1.0));
        c.update(5.0, 0.0, DT);
        let i = c.integral();
        let t = c.update(5.0, 1.0, 0.0);
        assert_eq!(t.i, i);
        assert_eq!(t.d, 0.0);
        assert!(t.output.is_finite());
    }

    #[test]
    fn feed_forward_adds_to_output() {
        let mut c = pid(PidConfig::new(1.0, 0.0, 0.0).with_output_limit(100.0));
        let t = c.update_with_ff(3.0, 1.0, 7.0, DT);
        assert_eq!(t.ff, 7.0);
        assert_eq!(t.output, 9.0);
    }

    #[test]
    fn set_integral_gives_bumpless_start() {
        let mut c = pid(PidConfig::new(1.0, 10.0, 0.0));
        c.set_integral(4.0);
        let t = c.update(0.0, 0.0, DT);
        assert_eq!(t.output, 4.0);
    }

    #[test]
    fn reset_clears_history_so_no_derivative_from_stale_measurement() {
        let mut c = pid(PidConfig::new(0.0, 1.0, 1.0));
        c.update(1.0, 0.0, DT);
        c.reset();
        let t = c.update(0.0, 100.0, DT);
        assert_eq!(t.d, 0.0);
        // Only this step's integral remains: ki · e · dt = 1 · (-100) · 0.001 (the +0.001 from
        // before the reset is gone).
        assert!((t.i + 0.1).abs() < 1e-6, "i = {}", t.i);
    }

    #[test]
    fn output_within_is_the_output_of_update_within() {
        let config = PidConfig::new(0.5, 2.0, 0.3).with_output_limit(4.0);
        let (mut a, mut b) = (pid(config), pid(config));
        for (target, meas, limit) in [(3.0, 0.0, 10.0), (3.0, 1.0, 2.5), (-2.0, 1.5, 10.0)] {
            let out = a.output_within(target, meas, 0.25, DT, limit);
            assert_eq!(out, b.update_within(target, meas, 0.25, DT, limit).output);
            assert_eq!(a.last_terms(), b.last_terms());
        }
        // The first step: p = 0.5·3 = 1.5, i = 2·3·0.001 = 0.006, d = 0, ff 0.25.
        let mut c = pid(config);
        assert!((c.output_within(3.0, 0.0, 0.25, DT, 10.0) - 1.756).abs() < 1e-6);
        // Rejected input: 0, nothing changes.
        assert_eq!(c.output_within(f32::NAN, 0.0, 0.0, DT, 10.0), 0.0);
        assert_eq!(c.output_within(1.0, f32::INFINITY, 0.0, DT, 10.0), 0.0);
        assert!((c.integral() - 0.006).abs() < 1e-7);
    }

    #[test]
    fn forget_history_keeps_the_integral_and_takes_no_derivative_from_the_jump() {
        // A measurement whose origin moves from 0 to 1000 while the shaft stays put.
        for cutoff_hz in [0.0, 10.0] {
            let config = PidConfig::new(0.5, 2.0, 0.3).with_d_cutoff_hz(cutoff_hz);
            let mut c = pid(config);
            for k in 0..5 {
                c.update(1.0, k as f32 * 0.1, DT);
            }
            let integral = c.integral();
            c.forget_history();
            assert_eq!(c.integral(), integral);
            // From here it steps exactly as a fresh loop preloaded with the same integral: no
            // derivative of the jump, a trapezoid that does not fold in the old error, a D
            // filter that starts from nothing.
            let mut fresh = pid(config);
            fresh.set_integral(integral);
            for meas in [1000.4, 1000.5, 1000.7] {
                let (a, b) = (c.update(1001.0, meas, DT), fresh.update(1001.0, meas, DT));
                assert_eq!(a, b, "cutoff {cutoff_hz} Hz, measurement {meas}");
            }
        }
    }

    #[test]
    fn d_filter_smooths_derivative() {
        let mut raw = pid(PidConfig::new(0.0, 0.0, 1.0));
        let mut filt = pid(PidConfig::new(0.0, 0.0, 1.0).with_d_cutoff_hz(10.0));
        raw.update(0.0, 0.0, DT);
        filt.update(0.0, 0.0, DT);
        let d_raw = raw.update(0.0, 1.0, DT).d;
        let d_filt = filt.update(0.0, 1.0, DT).d;
        assert!((d_raw + 1000.0).abs() < 1e-3);
        // The filter starts from "no derivative": tau = 1/(2π·10 Hz) = 15.915 ms, so the first
        // sample is weighted by alpha = dt / (tau + dt) = 1 / 16.915 = 0.05912.
        assert!((d_filt + 1000.0 * 0.05912).abs() < 0.05, "{d_filt}");
        let d_filt2 = filt.update(0.0, 1.0, DT).d; // raw derivative now 0
        assert!(
            (d_filt2 + 1000.0 * 0.05912 * (1.0 - 0.05912)).abs() < 0.05,
            "{d_filt2}"
        );
    }

    #[test]
    fn terms_near_f32_max_of_opposite_signs_sum_to_what_is_left() {
        // P and D saturated at ±MAX cancel; the integral is what remains (left to right,
        // MAX + 1e33 overflowed and the output read MAX). Found by the property test.
        // Within a rounding of MAX/4 (2^101) in the quarter sum, times 4: 2^103 ≈ 1.0e31.
        let left = sum_terms(f32::MAX, 1.0e33, -f32::MAX, 0.0);
        assert!((left - 1.0e33).abs() <= 2f32.powi(103), "{left}");
        assert_eq!(sum_terms(f32::MAX, f32::MAX, -f32::MAX, -f32::MAX), 0.0);
        assert_eq!(sum_terms(f32::MAX, 0.0, -f32::MAX, 2.5), 2.5);
        // Beyond MAX for real: infinite, which the output limit clamps.
        assert_eq!(sum_terms(f32::MAX, f32::MAX, 0.0, 0.0), f32::INFINITY);
        assert_eq!(sum_terms(-f32::MAX, -1.0e33, 0.0, 0.0), f32::NEG_INFINITY);
        // The usual case, as summed.
        assert_eq!(sum_terms(1.5, 0.25, -0.5, 2.0), 3.25);
    }

    #[test]
    fn output_is_the_sum_of_p_i_d_and_ff_with_every_term_nonzero() {
        // kp 2, ki 100 /s, kd 0.01 s; target 10, measurement 0 then 1 (rising at 1000 /s).
        let mut c = pid(PidConfig::new(2.0, 100.0, 0.01));
        c.update_with_ff(10.0, 0.0, 0.5, DT);
        let t = c.update_with_ff(10.0, 1.0, 0.5, DT);
        assert!((t.p - 18.0).abs() < 1e-4); // 2 · 9
        assert!((t.d + 10.0).abs() < 1e-3); // -0.01 · 1 / 0.001: opposes the rise
        // i: step 1 (10+10)/2·0.001·100 = 1.0; step 2 (10+9)/2·0.001·100 = 0.95.
        assert!((t.i - 1.95).abs() < 1e-4, "{}", t.i);
        assert!(
            (t.output - (18.0 + 1.95 - 10.0 + 0.5)).abs() < 1e-3,
            "{}",
            t.output
        );
    }

    #[test]
    fn integral_separation_reentry_integrates_only_in_band_error() {
        // M3508 speed-loop scale: ki 8 A/(rpm·s), band 50 rpm. A 300 rpm error is separated;
        // the next step, back at 10 rpm, must add ki·10·dt = 0.08 A, not the trapezoid over
        // the separated error, ki·(300 + 10)/2·dt = 1.24 A.
        let mut c = pid(PidConfig::new(0.0, 8.0, 0.0).with_integral_separation(50.0));
        c.update(300.0, 0.0, DT);
        assert_eq!(c.integral(), 0.0);
        let t = c.update(10.0, 0.0, DT);
        assert!((t.i - 8.0 * 10.0 * DT).abs() < 1e-6, "i = {}", t.i);
    }

    #[test]
    fn anti_windup_works_against_a_lower_limit_in_force() {
        // Derated to 5 A while the loop's own limit is 20 A: the integral must stay within the
        // 5 A that can be applied, so the command does not jump when the limit is lifted.
        let mut c = pid(PidConfig::new(0.1, 50.0, 0.0).with_output_limit(20.0));
        for _ in 0..2000 {
            let t = c.update_within(100.0, 0.0, 0.0, DT, 5.0);
            assert!(t.output.abs() <= 5.0);
        }
        // p = 0.1·100 = 10 is past the 5 A in force from the first step: no integral.
        assert_eq!(c.integral(), 0.0);
        // Error reverses as soon as the limit is lifted: p = −1, and the trapezoid
        // (−10 + 100)/2 · 50 · 0.001 = 2.25 gives 1.25 A.
        let after = c.update_within(-10.0, 0.0, 0.0, DT, 20.0);
        assert!((after.output - 1.25).abs() < 1e-5, "{}", after.output);
        // A NaN limit counts as zero.
        assert_eq!(c.update_within(100.0, 0.0, 0.0, DT, f32::NAN).output, 0.0);
    }

    proptest! {
        #[test]
        fn plain_step_is_the_general_step_bit_for_bit(
            kp in -1e3f32..1e3, ki in -1e3f32..1e3, kd in prop_oneof![Just(0.0f32), -1.0f32..1.0],
            out_limit in prop_oneof![Just(f32::INFINITY), 0.0f32..1e3],
            i_limit in prop_oneof![Just(f32::INFINITY), 0.0f32..1e3],
            circular in proptest::bool::ANY,
            steps in proptest::collection::vec(
                (proptest::num::f32::ANY, -1e4f32..1e4, -1e2f32..1e2,
                 prop_oneof![Just(0.001f32), proptest::num::f32::ANY],
                 prop_oneof![Just(f32::INFINITY), proptest::num::f32::ANY],
                 prop_oneof![4 => Just(true), 1 => Just(false)]),
                1..48),
        ) {
            let mode = if circular { ErrorMode::DEGREES } else { ErrorMode::Linear };
            let config = PidConfig::new(kp, ki, kd)
                .with_output_limit(out_limit)
                .with_integral_limit(i_limit)
                .with_error_mode(mode);
            let mut plain = pid(config);
            let pi = !circular && kd == 0.0 && ki != 0.0;
            prop_assert_eq!(plain.path, if pi { Path::PlainPi } else { Path::Plain });
            let mut general = plain;
            general.path = Path::General;
            for (target, meas, ff, dt, limit, integrate) in steps {
                // The plain (and PI) side through the cascade's entry point where its
                // precondition holds (finite target and feed-forward), the public one where
                // it does not; the general side always through the public one, or the
                // cascade's general one when the integral holds (stale readings).
                let a = if target.is_finite() {
                    let out =
                        plain.output_within_finite_target(target, meas, ff, dt, limit, integrate);
                    prop_assert_eq!(out.to_bits(), plain.last_terms().output.to_bits());
                    plain.last_terms()
                } else if integrate {
                    plain.update_within(target, meas, ff, dt, limit)
                } else {
                    prop_assert_eq!(plain.output_integrating(target, meas, ff, dt, limit, Integrate::NOT), 0.0);
                    PidTerms::ZERO
                };
                let b = if integrate {
                    general.update_within(target, meas, ff, dt, limit)
                } else {
                    let before = general.integral;
                    let out = general.output_integrating(target, meas, ff, dt, limit, Integrate::NOT);
                    if !(target.is_finite() && meas.is_finite()) {
                        prop_assert_eq!(out, 0.0);
                        PidTerms::ZERO
                    } else {
                        // Held: only clamped to the limits in force.
                        let (_, i_limit) = general.limits(ff, limit);
                        prop_assert_eq!(general.integral.to_bits(), clamp_abs(before, i_limit).to_bits());
                        general.last_terms()
                    }
                };
                let bits = |t: PidTerms| [t.p, t.i, t.d, t.ff, t.output].map(f32::to_bits);
                prop_assert_eq!(bits(a), bits(b));
                general.path = plain.path;
                prop_assert_eq!(plain, general);
                general.path = Path::General;
            }
        }

        #[test]
        fn one_way_holds_match_on_both_steps_and_never_move_the_integral_the_held_way(
            kp in -1e3f32..1e3, ki in -1e3f32..1e3, kd in prop_oneof![Just(0.0f32), -1.0f32..1.0],
            out_limit in prop_oneof![Just(f32::INFINITY), 0.0f32..1e3],
            circular in proptest::bool::ANY,
            steps in proptest::collection::vec(
                (-1e4f32..1e4, -1e4f32..1e4, -1e2f32..1e2, 1e-4f32..1e-2,
                 prop_oneof![Just(f32::INFINITY), 0.0f32..1e3], 0usize..4),
                1..48),
        ) {
            let mode = if circular { ErrorMode::DEGREES } else { ErrorMode::Linear };
            let config = PidConfig::new(kp, ki, kd).with_output_limit(out_limit).with_error_mode(mode);
            let mut plain = pid(config);
            let mut general = plain;
            general.path = Path::General;
            let all = [Integrate::FREELY, Integrate::NOT, Integrate::NOT_UP, Integrate::NOT_DOWN];
            for (target, meas, ff, dt, limit, k) in steps {
                let ways = all[k];
                let (_, i_limit) = plain.limits(ff, limit);
                let before = clamp_abs(plain.integral, i_limit);
                // The angle loop's entry point: the plain step without the PI shortcut.
                let a = plain.output_integrating(target, meas, ff, dt, limit, ways);
                let b = general.output_integrating(target, meas, ff, dt, limit, ways);
                prop_assert_eq!(a.to_bits(), b.to_bits());
                prop_assert_eq!(plain.integral.to_bits(), general.integral.to_bits());
                if !ways.up() {
                    prop_assert!(plain.integral <= before, "{} rose from {}", plain.integral, before);
                }
                if !ways.down() {
                    prop_assert!(plain.integral >= before, "{} fell from {}", plain.integral, before);
                }
                // Held exactly when the terms summed past the output.
                let t = plain.last_terms();
                let sum = sum_terms(t.p, t.i, t.d, t.ff);
                prop_assert_eq!(plain.last_clamp(), (sum > t.output) as i8 - (sum < t.output) as i8);
            }
        }

        #[test]
        fn output_always_finite_and_within_limits(
            kp in -1e4f32..1e4, ki in -1e4f32..1e4, kd in -1e2f32..1e2,
            limit in 0.0f32..1e4,
            steps in proptest::collection::vec(
                (proptest::num::f32::ANY, proptest::num::f32::ANY, proptest::num::f32::ANY, proptest::num::f32::ANY),
                1..64),
        ) {
            let mut c = pid(PidConfig::new(kp, ki, kd).with_output_limit(limit).with_d_cutoff_hz(50.0));
            for (target, meas, ff, dt) in steps {
                let t = c.update_with_ff(target, meas, ff, dt);
                prop_assert!(t.output.is_finite());
                prop_assert!(t.output.abs() <= limit);
                prop_assert!(t.p.is_finite() && t.i.is_finite() && t.d.is_finite());
            }
        }

        #[test]
        fn circular_mode_output_is_continuous_across_wrap(target in 0.0f32..360.0, meas in 0.0f32..360.0) {
            // The same physical angle written in [0, 360) or ±180 gives the same error.
            let mut a = pid(PidConfig::new(1.0, 0.0, 0.0).with_error_mode(ErrorMode::DEGREES));
            let mut b = pid(PidConfig::new(1.0, 0.0, 0.0).with_error_mode(ErrorMode::DEGREES));
            let pa = a.update(target, meas, DT).p;
            let pb = b.update(crate::math::wrap_deg_180(target), crate::math::wrap_deg_180(meas), DT).p;
            prop_assert!(pa.abs() <= 180.0);
            // Equal modulo 360 (±180 exactly can flip sign, both are the short way).
            prop_assert!(crate::math::wrap_deg_180(pa - pb).abs() < 1e-3);
        }
    }
}
