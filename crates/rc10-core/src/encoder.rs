//! Absolute rotary encoders read as raw counts (DJI: 0..8191 per rotor turn), turned into an
//! exact multi-turn position and output-shaft angles through an exact gear ratio.
//!
//! The position is kept as an integer count of rotor encoder steps (`i64`), and the gear ratio
//! as a fraction of integers (M3508: 3591/187), so nothing drifts however long the robot runs:
//! floats are produced only when an angle is read. RC10_LIB accumulated an `int32` (overflow
//! after ~30 min at full speed) and converted through floats each tick.

use core::fmt;

/// Rotor counts of one turn on DJI motors (C620/C610/GM6020 feedback D0–1: 0..8191).
pub const DJI_COUNTS_PER_REV: u16 = 8192;

/// An exact gear ratio: `rotor_turns` turns of the rotor make `output_turns` turns of the
/// output shaft.
///
/// ```
/// use rc10_core::encoder::GearRatio;
/// assert!((GearRatio::M3508.as_f32() - 19.2032).abs() < 1e-4);
/// assert_eq!(GearRatio::new(0, 1), None);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GearRatio {
    rotor_turns: u32,
    output_turns: u32,
}

impl GearRatio {
    /// Direct drive (GM6020): 1:1.
    pub const DIRECT: Self = Self {
        rotor_turns: 1,
        output_turns: 1,
    };
    /// M3508 P19 gearbox: 3591/187 ≈ 19.2032 (DJI M3508 user guide).
    pub const M3508: Self = Self {
        rotor_turns: 3591,
        output_turns: 187,
    };
    /// M2006 P36 gearbox: 36:1 (DJI M2006 user guide).
    pub const M2006: Self = Self {
        rotor_turns: 36,
        output_turns: 1,
    };

    /// `rotor_turns : output_turns`; `None` if either is zero.
    pub const fn new(rotor_turns: u32, output_turns: u32) -> Option<Self> {
        if rotor_turns == 0 || output_turns == 0 {
            None
        } else {
            Some(Self {
                rotor_turns,
                output_turns,
            })
        }
    }

    /// Rotor turns in the ratio (numerator).
    pub const fn rotor_turns(&self) -> u32 {
        self.rotor_turns
    }

    /// Output turns in the ratio (denominator).
    pub const fn output_turns(&self) -> u32 {
        self.output_turns
    }

    /// Whether the rotor and the output turn together (1:1, also when written 2:2; `==`
    /// compares the written terms).
    pub const fn is_direct(&self) -> bool {
        self.rotor_turns == self.output_turns
    }

    /// The ratio `rotor speed / output speed` as a float (for speed conversions).
    pub fn as_f32(&self) -> f32 {
        self.rotor_turns as f32 / self.output_turns as f32
    }
}

/// Where the multi-turn position starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Origin {
    /// Position 0 is wherever the rotor was at the first reading (geared motors, whose rotor
    /// angle says nothing about the output's absolute position).
    PowerOn,
    /// The encoder is absolute (direct drive, e.g. a GM6020 gimbal): position 0 is raw count
    /// `zero_offset_counts`, and the first reading is placed within half a turn of it, so a
    /// gimbal starts with an angle in [-180°, 180°) around its configured zero.
    Absolute {
        /// The raw count that means angle 0.
        zero_offset_counts: u16,
    },
}

/// Static description of an encoder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EncoderConfig {
    /// Counts per rotor turn (8192 on DJI motors).
    pub counts_per_rev: u16,
    /// Gear ratio from the rotor to the output shaft.
    pub gear: GearRatio,
    /// Where position 0 is.
    pub origin: Origin,
}

impl EncoderConfig {
    /// A DJI encoder (8192 counts) behind `gear`, zeroed at power-on.
    pub const fn dji(gear: GearRatio) -> Self {
        Self {
            counts_per_rev: DJI_COUNTS_PER_REV,
            gear,
            origin: Origin::PowerOn,
        }
    }

    /// Sets [`origin`](Self::origin).
    #[must_use]
    pub const fn with_origin(mut self, origin: Origin) -> Self {
        self.origin = origin;
        self
    }
}

/// A raw reading the encoder cannot use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncoderError {
    /// The raw count is not below `counts_per_rev`; the reading was ignored.
    OutOfRange {
        /// The rejected raw count.
        raw: u16,
    },
}

impl fmt::Display for EncoderError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::OutOfRange { raw } => write!(f, "encoder count {raw} out of range"),
        }
    }
}

impl core::error::Error for EncoderError {}

/// Multi-turn encoder state.
///
/// Between two readings the rotor is assumed to have turned less than half a turn (at 1 kHz
/// that is 30 000 rpm at the rotor, three times an M3508's no-load rotor speed).
///
/// ```
/// use rc10_core::encoder::{Encoder, EncoderConfig, GearRatio};
/// let mut enc = Encoder::new(EncoderConfig::dji(GearRatio::DIRECT)).unwrap();
/// enc.update(8000).unwrap(); // power-on position = 0
/// enc.update(100).unwrap(); // wrapped forward by 292 counts
/// assert_eq!(enc.total_counts(), 292);
/// assert!((enc.angle_deg() - 292.0 * 360.0 / 8192.0).abs() < 1e-4);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Encoder {
    config: EncoderConfig,
    last_raw: Option<u16>,
    total_counts: i64,
    /// Degrees of output per unit of [`output_position`](Self::output_position)'s remainder
    /// (derived from the configuration; f32 bits, so that `Encoder` stays `Eq`).
    deg_per_unit_bits: u32,
}

/// `v as f32`, through the single-instruction 32-bit conversion when `v` fits `i32`.
#[inline]
fn to_f32(v: i64) -> f32 {
    match i32::try_from(v) {
        Ok(v) => v as f32,
        Err(_) => wide_to_f32(v),
    }
}

/// The 64-bit conversion, out of line so that it is not computed speculatively.
#[cold]
#[inline(never)]
fn wide_to_f32(v: i64) -> f32 {
    v as f32
}

impl Encoder {
    /// An encoder with no reading yet; `None` if `counts_per_rev < 2` or an absolute zero
    /// offset is not below it.
    pub const fn new(config: EncoderConfig) -> Option<Self> {
        if config.counts_per_rev < 2 {
            return None;
        }
        if let Origin::Absolute { zero_offset_counts } = config.origin
            && zero_offset_counts >= config.counts_per_rev
        {
            return None;
        }
        Some(Self {
            config,
            last_raw: None,
            total_counts: 0,
            deg_per_unit_bits: (360.0 / units_per_turn(&config) as f32).to_bits(),
        })
    }

    /// The configuration.
    pub const fn config(&self) -> &EncoderConfig {
        &self.config
    }

    /// Feeds one raw reading, assuming the rotor turned less than half a turn since the
    /// previous one. An out-of-range count is rejected and changes nothing.
    pub fn update(&mut self, raw: u16) -> Result<(), EncoderError> {
        self.update_predicted(raw, 0.0)
    }

    /// Feeds one raw reading, given a prediction of how many counts the rotor turned since the
    /// previous reading (rotor speed × elapsed time; positive forward).
    ///
    /// Of all the steps consistent with the raw count (`d + k · counts_per_rev`), the one
    /// nearest the prediction is taken. So a rotor that turned more than half a turn between
    /// two readings (frames lost at high speed: an M2006 above 417 output rpm loses a whole
    /// rotor turn to one lost frame under the half-turn rule) is still counted exactly,
    /// provided the prediction is within half a turn of the truth. A prediction of 0 is the
    /// half-turn rule; a non-finite one is treated as 0. An out-of-range count is rejected
    /// and changes nothing.
    ///
    /// ```
    /// use rc10_core::encoder::{Encoder, EncoderConfig, GearRatio};
    /// let mut enc = Encoder::new(EncoderConfig::dji(GearRatio::M2006)).unwrap();
    /// enc.update(0).unwrap();
    /// // 9 ms at 18 000 rotor rpm (eight frames lost): 2.7 rotor turns = 22 118.4 counts.
    /// enc.update_predicted((22_118 % 8192) as u16, 22_118.4).unwrap();
    /// assert_eq!(enc.total_counts(), 22_118);
    /// ```
    pub fn update_predicted(
        &mut self,
        raw: u16,
        predicted_counts: f32,
    ) -> Result<(), EncoderError> {
        let cpr = self.config.counts_per_rev;
        if raw >= cpr {
            return Err(EncoderError::OutOfRange { raw });
        }
        match self.last_raw {
            Some(last) => {
                let step = wrapped_step(raw, last, cpr);
                // 32-bit conversions (one instruction; the 64-bit ones are library calls).
                let nf = f32::from(cpr);
                let off = if predicted_counts.is_finite() {
                    predicted_counts - to_f32(step)
                } else {
                    0.0
                };
                let step = if off.abs() * 2.0 < nf {
                    step // the usual case: the prediction agrees with the half-turn rule
                } else {
                    plus_whole_turns(step, off / nf, cpr)
                };
                self.total_counts = self.total_counts.saturating_add(step);
            }
            None => {
                self.total_counts = match self.config.origin {
                    Origin::PowerOn => 0,
                    Origin::Absolute { zero_offset_counts } => {
                        wrapped_step(raw, zero_offset_counts, cpr)
                    }
                };
            }
        }
        self.last_raw = Some(raw);
        Ok(())
    }

    /// Whether at least one reading has been accepted.
    pub const fn has_reading(&self) -> bool {
        self.last_raw.is_some()
    }

    /// The last accepted raw count.
    pub const fn raw(&self) -> Option<u16> {
        self.last_raw
    }

    /// Rotor position in encoder counts since the origin (exact, any run length).
    pub const fn total_counts(&self) -> i64 {
        self.total_counts
    }

    /// Rotor angle within one rotor turn in degrees, [0, 360), measured from the origin
    /// (`total_counts` modulo a turn): for a power-on origin 0 at the first reading, whatever
    /// the raw count; moved by [`set_total_angle_deg`](Self::set_total_angle_deg). Not the
    /// encoder's raw angle.
    pub fn rotor_angle_deg(&self) -> f32 {
        let n = i64::from(self.config.counts_per_rev);
        self.total_counts.rem_euclid(n) as f32 * (360.0 / n as f32)
    }

    /// Output-shaft position as whole turns and the remainder in units of
    /// `1 / (counts_per_rev · rotor_turns)` of a turn, and that unit's count per turn. Exact
    /// integer arithmetic: `i64` (cheap on a Cortex-M4), or `i128` only if the product could
    /// overflow, which takes thousands of years of continuous rotation.
    fn output_position(&self) -> (i64, i64, i64) {
        let per_turn = units_per_turn(&self.config);
        // Within ±2^31 counts the scaled position cannot overflow i64 (|i32 × u32| < 2^63),
        // so it needs no overflow check; within ±2^31 of scaled position (an M3508 within 73
        // output turns of its origin, a GM6020 within 262 000) the 32-bit division is one
        // instruction, where the 64-bit one is a library call of some sixty. All paths are
        // exact.
        if let Ok(counts) = i32::try_from(self.total_counts)
            && let Ok(scaled) = i32::try_from(
                i64::from(counts).wrapping_mul(i64::from(self.config.gear.output_turns)),
            )
            && let Ok(per) = i32::try_from(per_turn)
            && let (Some(turns), Some(rem)) = (
                scaled.checked_div_euclid(per),
                scaled.checked_rem_euclid(per),
            )
        {
            return (i64::from(turns), i64::from(rem), per_turn);
        }
        match self
            .total_counts
            .checked_mul(i64::from(self.config.gear.output_turns))
        {
            Some(scaled) => (
                scaled.div_euclid(per_turn),
                scaled.rem_euclid(per_turn),
                per_turn,
            ),
            None => {
                #[allow(
                    clippy::arithmetic_side_effects,
                    reason = "i64 × u32 is below 2^95: fits i128"
                )]
                let scaled =
                    i128::from(self.total_counts) * i128::from(self.config.gear.output_turns);
                let per = i128::from(per_turn);
                // The quotient fits i64 (it is smaller than total_counts); the remainder is
                // below per_turn.
                (
                    scaled.div_euclid(per) as i64,
                    scaled.rem_euclid(per) as i64,
                    per_turn,
                )
            }
        }
    }

    /// Whole output-shaft turns since the origin (floor).
    pub fn total_turns(&self) -> i64 {
        self.output_position().0
    }

    /// Output-shaft angle within one turn in degrees, [0, 360); exact to f32 rounding however
    /// many turns were made.
    pub fn angle_deg(&self) -> f32 {
        self.angles_deg().0
    }

    /// [`angle_deg`](Self::angle_deg) and [`total_angle_deg`](Self::total_angle_deg)
    /// together, for the price of one (a 64-bit division).
    pub fn angles_deg(&self) -> (f32, f32) {
        let (turns, rem, _) = self.output_position();
        // `rem < per_turn` fits i32 for every real encoder and gear (the 32-bit conversion is
        // one instruction, the 64-bit one a library call on the Cortex-M4).
        let within = to_f32(rem) * f32::from_bits(self.deg_per_unit_bits);
        // Rounding of the last count below a full turn can give exactly 360.0.
        let angle = if within >= 360.0 { 0.0 } else { within };
        (angle, to_f32(turns) * 360.0 + within)
    }

    /// Output-shaft multi-turn angle in degrees. Computed from whole turns plus the exact
    /// single-turn angle, so its only error is f32 rounding of the result (0.01° up to about
    /// 500 turns, 1° up to about 50 000 turns): it never drifts.
    pub fn total_angle_deg(&self) -> f32 {
        self.angles_deg().1
    }

    /// Makes the current position the origin (multi-turn position 0, angle 0).
    /// With no reading yet this does nothing.
    pub fn set_zero_here(&mut self) {
        if let Some(raw) = self.last_raw {
            self.total_counts = 0;
            if let Origin::Absolute { .. } = self.config.origin {
                self.config.origin = Origin::Absolute {
                    zero_offset_counts: raw,
                };
            }
        }
    }

    /// Feeds one raw reading from a device that reports every `period` exactly (DJI ESCs:
    /// 1 ms), when the receive timestamps may be late (frames stamped when the receiver read
    /// them, not when they arrived). Returns the interval the step was taken over, in periods
    /// (1 for the first reading or non-finite inputs).
    ///
    /// `counts_per_period` is the rotor's mean speed over the interval in counts per period;
    /// `gap_periods` the interval measured from the timestamps, in periods. The true interval
    /// is a whole number `m ≥ 1` of periods (the frames in between were lost); it is searched
    /// within ±2 of the measured gap and at `m = 1` (the first frame of a backlog, read late
    /// after a stalled receive path, follows the last one taken however late its stamp), and
    /// the step `d + k · counts_per_rev` that a whole `m` explains best is taken: the rotor
    /// position, not the late timestamp, decides. Where two intervals explain the reading
    /// equally well (within 1/32 of a turn: the rotor turns a whole number of times in their
    /// difference, e.g. 2048 counts per period for `Δm` = 4), the one nearer the measured gap
    /// wins (so a frame read late by several periods at such a speed still counts a turn
    /// wrong). Where every candidate gives the same step (at low speed no candidate changes
    /// the turn count, and this is [`update_predicted`](Self::update_predicted) with
    /// `counts_per_period · gap_periods`), the position cannot tell the intervals apart and
    /// the one returned is the measured gap rounded. Non-finite inputs fall back to the
    /// half-turn rule.
    ///
    /// ```
    /// use rc10_core::encoder::{Encoder, EncoderConfig, GearRatio};
    /// let mut enc = Encoder::new(EncoderConfig::dji(GearRatio::M2006)).unwrap();
    /// enc.update(0).unwrap();
    /// // M2006 at full speed: 2457.6 counts per 1 ms frame. The next frame really came 1 ms
    /// // later, but was read 1.7 ms late: the stamps say 2.7 ms.
    /// assert_eq!(enc.update_periodic(2458, 2457.6, 2.7), Ok(1));
    /// assert_eq!(enc.total_counts(), 2458);
    /// // The next one was read 4.6 ms late (a stalled receive path): still one period.
    /// assert_eq!(enc.update_periodic(4916, 2457.6, 5.6), Ok(1));
    /// assert_eq!(enc.total_counts(), 4916);
    /// ```
    pub fn update_periodic(
        &mut self,
        raw: u16,
        counts_per_period: f32,
        gap_periods: f32,
    ) -> Result<u32, EncoderError> {
        let cpr = self.config.counts_per_rev;
        let (Some(last), true) = (
            self.last_raw,
            counts_per_period.is_finite() && gap_periods.is_finite(),
        ) else {
            return self.update_predicted(raw, 0.0).map(|()| 1);
        };
        if raw >= cpr {
            return Err(EncoderError::OutOfRange { raw });
        }
        let gap = gap_periods.clamp(1.0, 1.0e6);
        let centre = round_clamped(gap); // 1 ..= 10^6: gap is clamped
        #[allow(
            clippy::arithmetic_side_effects,
            reason = "centre is within [1, 10^6]: gap is clamped"
        )]
        let (first, last_m) = ((centre - 2).max(1), centre + 2);
        // Every candidate, from one period to the window's end (`centre + 2 ≤ gap + 2.5`;
        // over at least four periods, as the window alone spans), moves the rotor by less
        // than a quarter turn: they all give the same turn count.
        let spread = if gap > 2.5 { gap + 1.5 } else { 4.0 };
        if counts_per_period.abs() * spread < f32::from(cpr) * 0.25 {
            return self
                .update_predicted(raw, counts_per_period * gap)
                .map(|()| centre.unsigned_abs());
        }
        let d0 = wrapped_step(raw, last, cpr);
        // The turn count each candidate gives is monotonic in `m` (every operation of
        // `step_for` is): when one period and the window's end agree, every candidate gives
        // the same step and the search below could only return it.
        let (step, m) = if step_for(d0, counts_per_period, 1, cpr)
            == step_for(d0, counts_per_period, last_m, cpr)
        {
            (step_for(d0, counts_per_period, last_m, cpr), centre)
        } else {
            best_step(d0, counts_per_period, gap, (first, last_m), cpr)
        };
        self.total_counts = self.total_counts.saturating_add(step);
        self.last_raw = Some(raw);
        Ok(m.unsigned_abs())
    }

    /// Homing: declares the present position to be the output-shaft multi-turn angle
    /// `angle_deg` (rounded to the nearest rotor count). For an absolute origin the zero
    /// offset moves with it, so a later [`reset`](Self::reset) keeps the new origin. Returns
    /// `false` (and changes nothing) with no reading yet or a non-finite or absurdly large
    /// angle.
    pub fn set_total_angle_deg(&mut self, angle_deg: f32) -> bool {
        let Some(raw) = self.last_raw else {
            return false;
        };
        let n = i64::from(self.config.counts_per_rev);
        // Rotor counts per output degree, in f64: this runs once per homing, not per tick.
        let counts_per_deg = n as f64 * f64::from(self.config.gear.rotor_turns)
            / (f64::from(self.config.gear.output_turns) * 360.0);
        let counts = libm::round(f64::from(angle_deg) * counts_per_deg);
        if !counts.is_finite() || counts.abs() > 1e15 {
            return false;
        }
        self.total_counts = counts as i64;
        if let Origin::Absolute { .. } = self.config.origin {
            // Never fails: |total_counts| ≤ 10^15 (checked above), and the remainder is < n.
            let offset = i64::from(raw)
                .checked_sub(self.total_counts)
                .map(|d| d.rem_euclid(n));
            self.config.origin = Origin::Absolute {
                zero_offset_counts: offset.and_then(|o| u16::try_from(o).ok()).unwrap_or(0),
            };
        }
        true
    }

    /// Forgets the readings: the next one starts again from the origin (for an absolute
    /// encoder, the true angle; for a power-on encoder, 0).
    pub fn reset(&mut self) {
        self.last_raw = None;
        self.total_counts = 0;
    }
}

/// The step `d0 + k · cpr` nearest the motion `counts_per_period · m` predicts for an interval
/// of `m` periods.
fn step_for(d0: i64, counts_per_period: f32, m: i32, cpr: u16) -> i64 {
    let predicted = counts_per_period * m as f32;
    plus_whole_turns(d0, (predicted - to_f32(d0)) / f32::from(cpr), cpr)
}

/// Of the intervals 1 and `first..=last` (in periods), the step of the one that explains the
/// reading best ([`Encoder::update_periodic`]), and that interval: the smallest residual
/// between step and prediction; within [`AMBIGUOUS_COUNTS`] of each other, the interval
/// nearer the measured `gap`.
fn best_step(
    d0: i64,
    counts_per_period: f32,
    gap: f32,
    (first, last): (i32, i32),
    cpr: u16,
) -> (i64, i32) {
    // (residual, distance to gap, step, interval); the first candidate always replaces it.
    let mut best = (f32::INFINITY, f32::INFINITY, d0, 1);
    let mut m = 1;
    loop {
        let step = step_for(d0, counts_per_period, m, cpr);
        let residual = (to_f32(step) - counts_per_period * m as f32).abs();
        let distance = (m as f32 - gap).abs();
        if residual + AMBIGUOUS_COUNTS < best.0
            || ((residual - best.0).abs() <= AMBIGUOUS_COUNTS && distance < best.1)
        {
            best = (residual, distance, step, m);
        }
        if m >= last {
            return (best.2, best.3);
        }
        // 1, then the window (which may start at 1 itself).
        #[allow(clippy::arithmetic_side_effects, reason = "m < last ≤ 10^6 + 2")]
        let next = m + 1;
        m = if m < first { first } else { next };
    }
}

/// Two candidate steps whose fits to a whole number of periods differ by less than this many
/// counts (1/32 of a DJI rotor turn) are taken as equally good.
const AMBIGUOUS_COUNTS: f32 = 256.0;

/// Units of [`Encoder::output_position`]'s remainder per output-shaft turn:
/// `counts_per_rev · rotor_turns`.
#[allow(
    clippy::arithmetic_side_effects,
    reason = "u16 × u32 is below 2^48: fits i64"
)]
const fn units_per_turn(config: &EncoderConfig) -> i64 {
    config.counts_per_rev as i64 * config.gear.rotor_turns as i64
}

/// The step from reading `from` to reading `to`, both below `n`, wrapped into `[-n/2, n/2)`.
/// The difference lies in `(-n, n)`, so one correction suffices: no division (an `i64`
/// remainder is a library call on the Cortex-M4).
#[allow(
    clippy::arithmetic_side_effects,
    reason = "u16 readings and count widened to i64: every value is within ±2^17"
)]
fn wrapped_step(to: u16, from: u16, n: u16) -> i64 {
    let (delta, n) = (i64::from(to) - i64::from(from), i64::from(n));
    let half = n / 2;
    if delta >= n - half {
        delta - n
    } else if delta < -half {
        delta + n
    } else {
        delta
    }
}

/// `step` plus the whole number of rotor turns nearest `turns`, clamped to ±10⁶ turns so that
/// even an absurd prediction cannot overflow the count.
#[allow(
    clippy::arithmetic_side_effects,
    reason = "step is a wrapped_step (|step| ≤ 2^15), |turns| ≤ 10^6, n < 2^16: below 2^37"
)]
fn plus_whole_turns(step: i64, turns: f32, n: u16) -> i64 {
    step + i64::from(round_clamped(turns)) * i64::from(n)
}

/// `x` clamped to ±10⁶ and rounded half away from zero, NaN to 0: the value of
/// `roundf(x).clamp(-1e6, 1e6) as i32` without the library call.
fn round_clamped(x: f32) -> i32 {
    // Comparisons; NaN stays NaN (and then becomes 0).
    crate::math::round_i32(x.clamp(-1.0e6, 1.0e6))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn dji(gear: GearRatio) -> Encoder {
        Encoder::new(EncoderConfig::dji(gear)).unwrap()
    }

    /// M2006 counts per 1 ms frame at `rotor_rpm`: rpm · 8192 / 60 000.
    fn m2006_counts_per_ms(rotor_rpm: f32) -> f32 {
        rotor_rpm * 8192.0 / 60_000.0
    }

    #[test]
    fn a_frame_read_late_after_a_stall_is_one_period_on() {
        // M2006 at 17 578 rotor rpm: 2399.9 counts a period. The frame after the last one
        // taken is read 4.6 ms late (stamps 5.6 periods apart). The window around 5.6
        // periods (4..8) alone would take 8 periods: 8 · 2399.9 = 19 199 counts, two turns
        // and 2815 counts, the nearest fit to a reading 2400 on. One period fits exactly.
        let cpp = m2006_counts_per_ms(17_578.0);
        let mut e = dji(GearRatio::M2006);
        e.update(1000).unwrap();
        assert_eq!(e.update_periodic(3400, cpp, 5.6), Ok(1));
        assert_eq!(e.total_counts(), 2400);
        // Read on time after four frames lost (5 periods, stamps 5.05 apart): 5 periods.
        // 5 · 2399.9 = 11 999.7 counts: one turn and 3808 on.
        assert_eq!(e.update_periodic(3400 + 3808, cpp, 5.05), Ok(5));
        assert_eq!(e.total_counts(), 2400 + 12_000);
    }

    #[test]
    fn the_low_speed_shortcut_weighs_one_period_too() {
        // M3508 at 3600 rotor rpm: 491.52 counts a period. Read 8.5 ms late (stamps 9.5
        // periods apart), a prediction of 9.5 periods (4669 counts, past half a turn) would
        // take the reading 492 counts on as 492 + 8192 (4 window periods move the rotor less
        // than a quarter turn, which once let it skip the search). One period fits.
        let cpp = 3600.0 * 8192.0 / 60_000.0;
        let mut e = dji(GearRatio::M3508);
        e.update(0).unwrap();
        assert_eq!(e.update_periodic(492, cpp, 9.5), Ok(1));
        assert_eq!(e.total_counts(), 492);
        // Slow enough that one period and the window's end move the rotor less than a
        // quarter turn apart: the prediction decides, and the interval is the measured one.
        let mut e = dji(GearRatio::M3508);
        e.update(0).unwrap();
        assert_eq!(e.update_periodic(300, 100.0, 3.0), Ok(3));
        assert_eq!(e.total_counts(), 300);
    }

    #[test]
    fn a_tie_between_one_period_and_the_stamped_gap_goes_to_the_gap() {
        // M2006 at 15 000 rotor rpm: 2048 counts a period, so 1 and 5 periods both explain a
        // reading 2048 on (5 periods: one turn and 2048). Frames lost and the reading on time,
        // or one frame read 4 ms late: the position cannot tell, and the stamps decide, as
        // before one period was weighed (the documented limit for frames read late). Below
        // 3.5 periods, one period is in the window itself and the nearer.
        let cpp = m2006_counts_per_ms(15_000.0);
        for (gap, periods, counts) in [(5.0, 5, 10_240), (5.4, 5, 10_240), (2.9, 1, 2048)] {
            let mut e = dji(GearRatio::M2006);
            e.update(0).unwrap();
            assert_eq!(e.update_periodic(2048, cpp, gap), Ok(periods), "{gap}");
            assert_eq!(e.total_counts(), counts, "{gap}");
        }
    }

    #[test]
    fn rounding_by_hand_rounds_half_away_from_zero_and_clamps() {
        // Ties go away from zero; just below a tie goes towards it (0.49999997 is where
        // `x + 0.5` would round the wrong way); the clamp is ±10^6; NaN gives 0.
        let cases = [
            (0.5, 1),
            (-0.5, -1),
            (1.5, 2),
            (-2.5, -3),
            (0.499_999_97, 0),
            (-0.499_999_97, 0),
            (2.499_999_8, 2),
            (0.0, 0),
            (-0.0, 0),
            (999_999.5, 1_000_000),
            (3.0e9, 1_000_000),
            (f32::NEG_INFINITY, -1_000_000),
            (f32::NAN, 0),
        ];
        for (x, want) in cases {
            assert_eq!(round_clamped(x), want, "{x}");
        }
        // And libm's `roundf` agrees on values spread over every magnitude and ties.
        for x in crate::math::rounding_samples(0x1234_5678, 1_000_000) {
            let want = libm::roundf(x).clamp(-1.0e6, 1.0e6) as i32;
            assert_eq!(round_clamped(x), want, "{x}");
        }
    }

    #[test]
    fn output_position_is_exact_on_both_sides_of_the_32_bit_fast_path() {
        // M3508: scaled = counts · 187 leaves i32 near ±11.48 M counts (73 output turns).
        let mut enc = dji(GearRatio::M3508);
        let per = 8192i128 * 3591;
        let edge = i64::from(i32::MAX) / 187;
        for base in [
            0,
            edge,
            -edge,
            4 * edge,
            -4 * edge,
            i64::MAX / 187,
            i64::MIN / 187,
        ] {
            for delta in -3..=3 {
                let counts = base + delta;
                enc.total_counts = counts;
                let scaled = i128::from(counts) * 187;
                let (turns, rem, per_turn) = enc.output_position();
                assert_eq!(i128::from(turns), scaled.div_euclid(per), "{counts}");
                assert_eq!(i128::from(rem), scaled.rem_euclid(per), "{counts}");
                assert_eq!(i128::from(per_turn), per);
            }
        }
    }

    /// Simulates a rotor at constant `rotor_rpm` read every 1 ms, with `lost` frames dropped
    /// after every received one, unwrapping with the speed × gap prediction.
    fn run_with_losses(gear: GearRatio, rotor_rpm: f64, lost: u32, frames: u32) -> (i64, i64) {
        let mut enc = dji(gear);
        let counts_per_ms = rotor_rpm / 60.0 * 8192.0 / 1000.0;
        let mut true_counts = 0.0f64;
        enc.update(0).unwrap();
        for _ in 0..frames {
            let gap_ms = f64::from(lost + 1);
            true_counts += counts_per_ms * gap_ms;
            let raw = (true_counts.round() as i64).rem_euclid(8192) as u16;
            enc.update_predicted(raw, (counts_per_ms * gap_ms) as f32)
                .unwrap();
        }
        (enc.total_counts(), true_counts.round() as i64)
    }

    #[test]
    fn m2006_at_full_speed_survives_one_to_three_lost_frames() {
        // M2006 no-load: 500 output rpm · 36 = 18 000 rotor rpm = 0.3 rotor turns per ms.
        for lost in 1..=3 {
            let (counted, truth) = run_with_losses(GearRatio::M2006, 18_000.0, lost, 500);
            assert_eq!(counted, truth, "{lost} lost frames");
        }
        // The half-turn rule alone loses a whole turn per gap: the prediction is what helps.
        let mut plain = dji(GearRatio::M2006);
        plain.update(0).unwrap();
        plain
            .update(((0.6f64 * 8192.0) as i64 % 8192) as u16)
            .unwrap();
        assert_eq!(plain.total_counts(), (0.6f64 * 8192.0) as i64 - 8192);
    }

    #[test]
    fn m3508_at_full_speed_survives_one_to_three_lost_frames() {
        // M3508 with the C620: 482 output rpm · 3591/187 ≈ 9 256 rotor rpm.
        for lost in 1..=3 {
            let (counted, truth) = run_with_losses(GearRatio::M3508, 9_256.0, lost, 500);
            assert_eq!(counted, truth, "{lost} lost frames");
        }
        // Backwards too.
        let (counted, truth) = run_with_losses(GearRatio::M3508, -9_256.0, 3, 500);
        assert_eq!(counted, truth);
    }

    /// Frames every 1 ms at `counts_per_ms`, each stamped `late_ms[i]` after it arrived.
    fn run_late_reads(gear: GearRatio, counts_per_ms: f64, late_ms: &[f64]) -> (i64, i64) {
        let mut enc = dji(gear);
        enc.update(0).unwrap();
        let mut prev_stamp = 0.0f64;
        let mut true_counts = 0.0f64;
        for (i, late) in late_ms.iter().enumerate() {
            let t = (i + 1) as f64;
            true_counts = counts_per_ms * t;
            let raw = (true_counts.round() as i64).rem_euclid(8192) as u16;
            let stamp = (t + late).max(prev_stamp);
            let gap = stamp - prev_stamp;
            prev_stamp = stamp;
            enc.update_periodic(raw, counts_per_ms as f32, gap as f32)
                .unwrap();
        }
        (enc.total_counts(), true_counts.round() as i64)
    }

    #[test]
    fn late_reads_do_not_cost_turns_at_full_speed() {
        // Receiver delays of up to 2 ms, in bursts (frames then read back to back).
        let late: Vec<f64> = (0..400)
            .map(|i| match i % 10 {
                3 => 1.7,
                4 => 1.2,
                7 => 2.0,
                8 => 0.4,
                _ => 0.05,
            })
            .collect();
        for (gear, counts_per_ms) in [
            (GearRatio::M2006, 18_000.0 / 60.0 * 8192.0 / 1000.0),
            (GearRatio::M3508, 9_256.0 / 60.0 * 8192.0 / 1000.0),
            (GearRatio::M2006, -18_000.0 / 60.0 * 8192.0 / 1000.0),
        ] {
            let (counted, truth) = run_late_reads(gear, counts_per_ms, &late);
            assert_eq!(counted, truth, "{counts_per_ms} counts/ms");
        }
    }

    #[test]
    fn slow_rotor_with_late_reads_counts_exactly() {
        let late: Vec<f64> = (0..200)
            .map(|i| if i % 5 == 0 { 3.0 } else { 0.0 })
            .collect();
        let (counted, truth) = run_late_reads(GearRatio::M3508, 100.0, &late);
        assert_eq!(counted, truth);
    }

    #[test]
    fn absurd_prediction_cannot_overflow() {
        let mut enc = dji(GearRatio::DIRECT);
        enc.update(0).unwrap();
        enc.update_predicted(10, f32::MAX).unwrap();
        enc.update_predicted(20, f32::NAN).unwrap();
        enc.update_periodic(30, f32::MAX, 1.0).unwrap();
        enc.update_periodic(40, 2000.0, f32::INFINITY).unwrap();
        enc.update_periodic(50, 2000.0, 1.0e30).unwrap();
        assert!(enc.total_counts() > 0);
    }

    #[test]
    fn homing_sets_the_total_angle_and_keeps_counting_from_it() {
        let mut enc = dji(GearRatio::M3508);
        assert!(!enc.set_total_angle_deg(0.0)); // no reading yet
        enc.update(1000).unwrap();
        enc.update(3000).unwrap();
        assert!(enc.set_total_angle_deg(90.0));
        // 90° of output = 8192 · 3591 / (187 · 4) = 39 328.17 → 39 328 rotor counts.
        assert_eq!(enc.total_counts(), 39_328);
        assert!((enc.total_angle_deg() - 90.0).abs() < 0.01);
        enc.update(3100).unwrap();
        assert_eq!(enc.total_counts(), 39_428);
        assert!(!enc.set_total_angle_deg(f32::NAN));
    }

    #[test]
    fn homing_an_absolute_encoder_moves_its_zero_offset() {
        let mut enc = Encoder::new(EncoderConfig::dji(GearRatio::DIRECT).with_origin(
            Origin::Absolute {
                zero_offset_counts: 0,
            },
        ))
        .unwrap();
        enc.update(2048).unwrap(); // 90°
        assert!(enc.set_total_angle_deg(0.0));
        enc.reset();
        enc.update(2048).unwrap();
        assert_eq!(enc.total_counts(), 0); // still zero after a restart
    }

    #[test]
    fn new_rejects_bad_config() {
        let mut c = EncoderConfig::dji(GearRatio::DIRECT);
        c.counts_per_rev = 1;
        assert!(Encoder::new(c).is_none());
        let c = EncoderConfig::dji(GearRatio::DIRECT).with_origin(Origin::Absolute {
            zero_offset_counts: 8192,
        });
        assert!(Encoder::new(c).is_none());
    }

    #[test]
    fn out_of_range_raw_is_rejected_and_ignored() {
        let mut e = dji(GearRatio::DIRECT);
        e.update(100).unwrap();
        assert_eq!(e.update(8192), Err(EncoderError::OutOfRange { raw: 8192 }));
        assert_eq!(e.raw(), Some(100));
        assert_eq!(e.total_counts(), 0);
    }

    #[test]
    fn backwards_wrap_counts_negative() {
        let mut e = dji(GearRatio::DIRECT);
        e.update(10).unwrap();
        e.update(8182).unwrap(); // 20 counts backwards across 0
        assert_eq!(e.total_counts(), -20);
        assert!((e.angle_deg() - (360.0 - 20.0 * 360.0 / 8192.0)).abs() < 1e-3);
        assert_eq!(e.total_turns(), -1);
    }

    #[test]
    fn m3508_one_output_turn_is_exact_after_187_rotor_cycles() {
        // 3591 rotor turns = 187 output turns exactly: feed them in 1000-count steps.
        let mut e = dji(GearRatio::M3508);
        let total: i64 = 3591 * 8192;
        let mut pos: i64 = 0;
        e.update(0).unwrap();
        while pos < total {
            pos = (pos + 1000).min(total);
            e.update((pos % 8192) as u16).unwrap();
        }
        assert_eq!(e.total_counts(), total);
        assert_eq!(e.total_turns(), 187);
        assert_eq!(e.angle_deg(), 0.0);
        assert_eq!(e.total_angle_deg(), 187.0 * 360.0);
    }

    #[test]
    fn absolute_origin_places_first_reading_around_zero() {
        let cfg = EncoderConfig::dji(GearRatio::DIRECT).with_origin(Origin::Absolute {
            zero_offset_counts: 4000,
        });
        let mut e = Encoder::new(cfg).unwrap();
        e.update(3000).unwrap(); // 1000 counts below zero: -43.95°
        assert_eq!(e.total_counts(), -1000);
        assert!((e.total_angle_deg() + 1000.0 * 360.0 / 8192.0).abs() < 1e-3);
        assert!((e.angle_deg() - (360.0 - 1000.0 * 360.0 / 8192.0)).abs() < 1e-3);
    }

    #[test]
    fn set_zero_here_resets_position() {
        let mut e = dji(GearRatio::M2006);
        e.update(0).unwrap();
        e.update(4000).unwrap();
        e.set_zero_here();
        assert_eq!(e.total_counts(), 0);
        e.update(4100).unwrap();
        assert_eq!(e.total_counts(), 100);
    }

    #[test]
    fn overflowing_product_falls_back_to_wide_arithmetic() {
        // total_counts · 187 overflows i64 here; the i128 path must give the same answer as
        // exact integer math.
        let mut e = dji(GearRatio::M3508);
        e.update(0).unwrap();
        e.total_counts = i64::MAX / 100;
        let per_turn = 8192i128 * 3591;
        let scaled = i128::from(e.total_counts) * 187;
        assert_eq!(i128::from(e.total_turns()), scaled.div_euclid(per_turn));
        let expect = scaled.rem_euclid(per_turn) as f64 * 360.0 / per_turn as f64;
        assert!((f64::from(e.angle_deg()) - expect).abs() < 1e-3);
    }

    #[test]
    fn long_run_at_full_speed_keeps_single_turn_angle_exact() {
        // 10 hours at 9000 rotor rpm (1228.8 counts/ms): 4.4e10 counts, past i32 after 29 min.
        let mut e = dji(GearRatio::M3508);
        e.update(0).unwrap();
        // Jump the state forward as 10 h of readings would, then take one more reading.
        let counts: i64 = 9000 * 8192 / 60 * 36_000;
        e.total_counts = counts;
        e.last_raw = Some((counts % 8192) as u16);
        e.update(((counts + 100) % 8192) as u16).unwrap();
        let expect_counts = counts + 100;
        assert_eq!(e.total_counts(), expect_counts);
        // Exact expected output angle via integer math: counts·187 mod (8192·3591).
        let per_turn = 8192i128 * 3591;
        let rem = (i128::from(expect_counts) * 187).rem_euclid(per_turn);
        let expect_deg = rem as f64 * 360.0 / per_turn as f64;
        assert!((e.angle_deg() as f64 - expect_deg).abs() < 1e-3);
    }

    proptest! {
        #[test]
        fn unwrapping_is_exact_for_long_random_motion(
            start in 0u16..8192,
            steps in proptest::collection::vec(-4095i64..=4095, 1..2000),
        ) {
            let mut e = dji(GearRatio::M3508);
            e.update(start).unwrap();
            let mut truth: i64 = 0;
            for s in steps {
                truth += s;
                let raw = (i64::from(start) + truth).rem_euclid(8192) as u16;
                e.update(raw).unwrap();
                prop_assert_eq!(e.total_counts(), truth);
            }
            let a = e.angle_deg();
            prop_assert!((0.0..360.0).contains(&a));
        }

        /// The shortcut (one period and the window's end agree, so all candidates do) and the
        /// search take the step (and interval) a search computing every candidate afresh takes,
        /// for any reading, speed and gap, down to a 2-count encoder.
        #[test]
        fn periodic_shortcut_takes_the_step_the_full_search_takes(
            counts_per_rev in prop_oneof![Just(8192u16), Just(16384), 2u16..9000],
            from in 0u16..u16::MAX,
            to in 0u16..u16::MAX,
            counts_per_period in prop_oneof![-20_000.0f32..20_000.0, -3_000.0f32..3_000.0],
            gap in prop_oneof![0.5f32..6.0, 0.0f32..2_000_000.0],
        ) {
            let config = EncoderConfig { counts_per_rev, ..EncoderConfig::dji(GearRatio::DIRECT) };
            let (from, to) = (from % counts_per_rev, to % counts_per_rev);
            let mut e = Encoder::new(config).unwrap();
            e.update(from).unwrap();
            let before = e.total_counts();
            let interval = e.update_periodic(to, counts_per_period, gap).unwrap();
            let nf = f32::from(counts_per_rev);
            let gap = gap.clamp(1.0, 1.0e6);
            let centre = round_clamped(gap);
            let spread = if gap > 2.5 { gap + 1.5 } else { 4.0 };
            prop_assume!(counts_per_period.abs() * spread >= nf * 0.25);
            let d0 = wrapped_step(to, from, counts_per_rev);
            let (first, last) = ((centre - 2).max(1), centre + 2);
            // The search's reference: every candidate's step computed afresh, one period
            // first, then the window.
            let mut best: Option<(f32, f32, i64, i32)> = None;
            for m in core::iter::once(1).chain(first.max(2)..=last) {
                let step = step_for(d0, counts_per_period, m, counts_per_rev);
                let residual = (step as f32 - counts_per_period * m as f32).abs();
                let distance = (m as f32 - gap).abs();
                let better = best.is_none_or(|(r, d, _, _)| {
                    residual + AMBIGUOUS_COUNTS < r
                        || ((residual - r).abs() <= AMBIGUOUS_COUNTS && distance < d)
                });
                if better {
                    best = Some((residual, distance, step, m));
                }
            }
            let (_, _, expected, m) = best.unwrap();
            prop_assert_eq!(e.total_counts() - before, expected);
            // Where the ends agree the interval is the measured one (every candidate fits
            // alike); otherwise the one the search found.
            if step_for(d0, counts_per_period, 1, counts_per_rev)
                != step_for(d0, counts_per_period, last, counts_per_rev)
            {
                prop_assert_eq!(interval, m.unsigned_abs());
            } else {
                prop_assert_eq!(interval, centre.unsigned_abs());
            }
        }

        /// Any speed a DJI rotor reaches (±18 000 rpm = ±2457.6 counts per 1 ms frame), any
        /// pattern of 0–3 lost frames, and timestamps up to 1 ms late (read late): the count
        /// stays exact. Speed changes slowly (at most ±20 counts per period per period, about
        /// an M2006's full-current acceleration), and each frame reports the mean speed of
        /// its interval, as the driver computes it from two reported speeds.
        #[test]
        fn periodic_unwrapping_is_exact_through_losses_and_late_reads(
            start_speed in -2457.0f64..2457.0,
            frames in proptest::collection::vec((-20.0f64..20.0, 0u32..4, 0.0f64..1.0), 1..300),
        ) {
            let mut e = dji(GearRatio::M2006);
            e.update(0).unwrap();
            let (mut speed, mut pos, mut t, mut prev_stamp) = (start_speed, 0.0f64, 0u64, 0.0f64);
            for (accel, lost, late) in frames {
                let periods = u64::from(lost) + 1;
                let mut travelled = 0.0;
                for _ in 0..periods {
                    let next = (speed + accel).clamp(-2457.6, 2457.6);
                    travelled += (speed + next) / 2.0;
                    speed = next;
                }
                pos += travelled;
                t += periods;
                let stamp = (t as f64 + late).max(prev_stamp);
                let gap = stamp - prev_stamp;
                prev_stamp = stamp;
                let raw = (pos.round() as i64).rem_euclid(8192) as u16;
                let mean = travelled / periods as f64;
                e.update_periodic(raw, mean as f32, gap as f32).unwrap();
                prop_assert_eq!(e.total_counts(), pos.round() as i64);
            }
        }
    }
}
