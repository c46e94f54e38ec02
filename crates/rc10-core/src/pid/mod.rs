//! PID controllers: positional ([`Pid`]) for angle loops and general use, incremental
//! ([`IncrementalPid`]) with a [`TrackingDifferentiator`] for speed loops (RC10_LIB's pair).
//!
//! Both controllers
//! - take `dt` in seconds explicitly on every call (from the scheduler period or
//!   [`DeltaTime`](crate::time::DeltaTime)), so gains mean the same thing at any tick rate;
//! - return a [`PidTerms`] breakdown (p, i, d, feed-forward, output) for tuning and telemetry;
//! - never return NaN or infinity and never panic: a non-finite target, measurement or
//!   feed-forward is rejected (the state is untouched and the output is zero); a `dt` that is not
//!   finite and positive freezes the integral and derivative for that call;
//! - validate their configuration once, at construction ([`PidConfigError`]).
//!
//! Units: the error is in the units of the measurement (rpm, deg, …) and the output in the
//! units of the actuator (amps, volts, rpm for a cascaded loop). `ki` is per second and `kd`
//! in seconds: RC10_LIB's per-tick `ki` at 1 kHz equals `ki_per_s × 0.001`.

mod incremental;
mod positional;
mod td;

pub use incremental::{IncrementalPid, IncrementalPidConfig};
pub(crate) use positional::Integrate;
pub use positional::{Pid, PidConfig};
pub use td::TrackingDifferentiator;

use core::fmt;

/// How the error `target - measurement` is formed.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ErrorMode {
    /// Plain difference.
    Linear,
    /// Angles on a circle of `period` (360.0 for degrees, 2π for radians): the error is the
    /// shortest signed way round, in `[-period/2, period/2)`, whatever the convention of the
    /// inputs (`[0, 360)`, `±180` or multi-turn). The derivative uses the wrapped change of the
    /// measurement, so a measurement wrapping from 359° to 0° is a 1° step, not a spike.
    Circular {
        /// Length of one turn in the measurement's unit.
        period: f32,
    },
}

impl ErrorMode {
    /// Circular error in degrees.
    pub const DEGREES: Self = Self::Circular { period: 360.0 };
    /// Circular error in radians.
    pub const RADIANS: Self = Self::Circular {
        period: core::f32::consts::TAU,
    };

    /// The difference `a - b` in this mode.
    #[inline]
    pub(crate) fn diff(self, a: f32, b: f32) -> f32 {
        match self {
            Self::Linear => a - b,
            // The period was validated with the configuration.
            Self::Circular { period } => crate::math::wrap_signed_valid_period(a - b, period),
        }
    }

    const fn is_valid(self) -> bool {
        match self {
            Self::Linear => true,
            Self::Circular { period } => period.is_finite() && period > 0.0,
        }
    }
}

/// The contribution of each term to one controller output, for logging and tuning.
///
/// `output` is the limited sum that the controller returns as its command; for the incremental
/// controller `p`, `i` and `d` are the terms of this call's increment.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PidTerms {
    /// Proportional term.
    pub p: f32,
    /// Integral term.
    pub i: f32,
    /// Derivative term.
    pub d: f32,
    /// Feed-forward term (passed in by the caller).
    pub ff: f32,
    /// The limited output.
    pub output: f32,
}

impl PidTerms {
    /// All terms zero: what a controller returns for rejected (non-finite) input.
    pub const ZERO: Self = Self {
        p: 0.0,
        i: 0.0,
        d: 0.0,
        ff: 0.0,
        output: 0.0,
    };
}

/// A PID configuration that cannot work; returned by the controllers' constructors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PidConfigError {
    /// `kp`, `ki` or `kd` is NaN or infinite.
    GainNotFinite,
    /// An output or integral limit is NaN or negative (use `f32::INFINITY` for "no limit").
    InvalidLimit,
    /// The deadband is NaN, infinite or negative.
    InvalidDeadband,
    /// The integral-separation threshold is NaN, or not above the deadband (0 without one):
    /// no error would ever be integrated. Use `f32::INFINITY` for no separation.
    InvalidSeparation,
    /// The derivative filter cutoff is NaN or negative (use `0.0` for no filter).
    InvalidFilter,
    /// A circular error mode with a period that is not finite and positive.
    InvalidPeriod,
    /// The tracking differentiator's `r` is not finite and positive.
    InvalidTrackingRate,
}

impl fmt::Display for PidConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::GainNotFinite => "PID gain is NaN or infinite",
            Self::InvalidLimit => "PID limit is NaN or negative",
            Self::InvalidDeadband => "PID deadband is NaN, infinite or negative",
            Self::InvalidSeparation => {
                "PID integral-separation threshold is NaN or not above the deadband"
            }
            Self::InvalidFilter => "PID derivative filter cutoff is NaN or negative",
            Self::InvalidPeriod => "PID circular period is not finite and positive",
            Self::InvalidTrackingRate => "tracking differentiator r is not finite and positive",
        })
    }
}

impl core::error::Error for PidConfigError {}

const fn check_gains(kp: f32, ki: f32, kd: f32) -> Result<(), PidConfigError> {
    if kp.is_finite() && ki.is_finite() && kd.is_finite() {
        Ok(())
    } else {
        Err(PidConfigError::GainNotFinite)
    }
}

/// A limit is valid when it is not NaN and not negative (infinity means "no limit").
const fn check_limit(limit: f32) -> Result<(), PidConfigError> {
    if !limit.is_nan() && limit >= 0.0 {
        Ok(())
    } else {
        Err(PidConfigError::InvalidLimit)
    }
}

const fn check_deadband(deadband: f32) -> Result<(), PidConfigError> {
    if deadband.is_finite() && deadband >= 0.0 {
        Ok(())
    } else {
        Err(PidConfigError::InvalidDeadband)
    }
}
