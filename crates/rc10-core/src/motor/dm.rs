//! Damiao (DM) joint motors in MIT mode (DM-J4310-2EC class).
//!
//! Command, standard ID = the motor's CAN ID, DLC 8, big-endian bit fields:
//! position 16 bits, velocity 12, kp 12, kd 12, torque 12, each mapped linearly from its range
//! (`p ∈ ±p_max` rad, `v ∈ ±v_max` rad/s, `kp ∈ [0, 500]`, `kd ∈ [0, 5]`, `t ∈ ±t_max` N·m;
//! defaults 12.5 rad, 30 rad/s, 10 N·m as set in Damiao's tool):
//!
//! ```text
//! D0 = p[15:8]  D1 = p[7:0]  D2 = v[11:4]  D3 = v[3:0] kp[11:8]  D4 = kp[7:0]
//! D5 = kd[11:4] D6 = kd[3:0] t[11:8]  D7 = t[7:0]
//! ```
//!
//! The output torque is `kp·(p − p_meas) + kd·(v − v_meas) + t`. Every field is clamped to its
//! range before conversion: the reference C code does not clamp, so an out-of-range value
//! spills into the neighbouring field. Special commands are `FF FF FF FF FF FF FF xx` with
//! `xx` = FC enable, FD disable, FE save position zero, FB clear error.
//!
//! Feedback on the master ID, DLC 8: D0 = motor id (low nibble) | state << 4, position 16 bits
//! (D1–D2), velocity 12 (D3, D4 high nibble), torque 12 (D4 low nibble, D5), D6 MOSFET °C,
//! D7 rotor °C. States: 0 disabled, 1 enabled, 8 over-voltage, 9 under-voltage,
//! A over-current, B MOSFET over-temperature, C coil over-temperature, D communication lost,
//! E overload.
//!
//! Positions are of the output shaft (the motor's driver accounts for its gearbox). The
//! reported position wraps at ±`p_max`; this driver unwraps it into a multi-turn angle. When
//! feedback returns after the motor was offline, [`HealthConfig::on_return`] decides:
//! `Continue` unwraps the first new position against the last one before the outage (the
//! output moved less than `p_max` meanwhile), `Restart` takes it as it comes, with no wraps
//! (choose it if the motor may have been power-cycled: its reported position then starts
//! again from its saved zero). Either way a software homing offset still applies (a homing
//! asked for while offline waits for the first reading after the return), and a
//! total-angle target set before the outage stays in force. After a `Restart` set it again:
//! should it now lie outside the reachable ±`p_max`, the motor holds where it is rather than
//! run to the end of the range.
//!
//! The single-turn angle and the angle mode's way to its target come from the reported
//! position and the wraps counted modulo a turn: exact however long the output spins. The
//! multi-turn total is an f32, whose resolution coarsens as it grows (values 1° apart beyond
//! about 23 000 turns).

use super::{
    ControlMode, HealthConfig, Liveness, Motor, MotorState, MultiTurnOnReturn, TargetError,
};
use crate::can::{CanFrame, IdFilter, SendError};
use crate::encoder::GearRatio;
use crate::math::{constrain, deg_to_rad, rad_to_deg, wrap_deg_360, wrap_signed};
use crate::node::{BusUsage, CanNode, FrameError, TxBatch};
use crate::time::Instant;
use core::cell::RefCell;
use core::f32::consts::TAU;
use core::fmt;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;

/// With [`DmConfig::auto_enable`], a motor that sends no feedback (not yet answered, or
/// offline) is sent Enable on every this many ticks (10 ms at 1 kHz), zero torque on the
/// others.
pub const PROBE_TICKS: u8 = 10;

/// How far past ±`p_max` (relative) a total-angle target's position field may round and
/// still count as in reach (then clamped to the range end when packed): the degree check
/// made when the target is set and the radian field differ by a few f32 steps.
const REACH_TOLERANCE: f32 = 1.0e-5;

/// Largest MIT position gain, N·m/rad (fixed by the protocol).
pub const KP_MAX: f32 = 500.0;
/// Largest MIT velocity gain, N·m·s/rad (fixed by the protocol).
pub const KD_MAX: f32 = 5.0;

/// The ranges configured in the motor (Damiao's tool: PMAX, VMAX, TMAX).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MitLimits {
    /// Position range ±this, in rad.
    pub p_max_rad: f32,
    /// Velocity range ±this, in rad/s.
    pub v_max_rad_s: f32,
    /// Torque range ±this, in N·m.
    pub t_max_nm: f32,
}

impl MitLimits {
    /// The factory defaults: 12.5 rad, 30 rad/s, 10 N·m.
    pub const DEFAULT: Self = Self {
        p_max_rad: 12.5,
        v_max_rad_s: 30.0,
        t_max_nm: 10.0,
    };
}

/// One MIT-mode command (output shaft).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MitCommand {
    /// Position target in rad.
    pub position_rad: f32,
    /// Velocity target in rad/s.
    pub velocity_rad_s: f32,
    /// Position gain, N·m/rad (0–500).
    pub kp: f32,
    /// Velocity gain, N·m·s/rad (0–5).
    pub kd: f32,
    /// Feed-forward torque in N·m.
    pub torque_nm: f32,
}

impl MitCommand {
    /// Zero gains and zero torque: the motor produces no torque. (The 12-bit torque field has
    /// no code for exactly 0: 0 N·m lies halfway between codes 2047 and 2048 and truncates to
    /// 2047, which the motor reads as −0.0024 N·m with a ±10 N·m range, `MitLimits::DEFAULT`.)
    pub const ZERO_TORQUE: Self = Self {
        position_rad: 0.0,
        velocity_rad_s: 0.0,
        kp: 0.0,
        kd: 0.0,
        torque_nm: 0.0,
    };

    /// The eight data bytes, every field clamped to its range first.
    ///
    /// Never a special command: with position, velocity, kp and kd all at the top of their
    /// ranges, a torque code of 0xFFB–0xFFE would make the frame `FF×7 FB..FE`, which the
    /// motor executes as clear error / enable / disable / save zero. That torque is sent as
    /// 0xFFA instead (at most 4 codes, 0.02 N·m at the default ±10 N·m, below the request).
    pub fn pack(&self, limits: &MitLimits) -> [u8; 8] {
        let p = float_to_uint(self.position_rad, limits.p_max_rad, 16);
        let v = float_to_uint(self.velocity_rad_s, limits.v_max_rad_s, 12);
        let kp = to_uint(self.kp, 0.0, KP_MAX, 12);
        let kd = to_uint(self.kd, 0.0, KD_MAX, 12);
        let t = float_to_uint(self.torque_nm, limits.t_max_nm, 12);
        let all_top = p == 0xFFFF && v == 0xFFF && kp == 0xFFF && kd == 0xFFF;
        let t = if all_top && (0xFFB..=0xFFE).contains(&t) {
            0xFFA
        } else {
            t
        };
        [
            (p >> 8) as u8,
            p as u8,
            (v >> 4) as u8,
            (((v & 0xF) << 4) | (kp >> 8)) as u8,
            kp as u8,
            (kd >> 4) as u8,
            (((kd & 0xF) << 4) | (t >> 8)) as u8,
            t as u8,
        ]
    }
}

/// The largest MIT range (`p_max` rad, `v_max` rad/s, `t_max` N·m) [`DmMotor::new`] accepts:
/// far beyond any Damiao motor (factory: 12.5, 30, 10), small enough that every conversion
/// the driver makes stays finite.
pub const MAX_MIT_RANGE: f32 = 1.0e6;

/// Whether a gain is within `[0, max]`.
const fn ok(x: f32, max: f32) -> bool {
    x.is_finite() && x >= 0.0 && x <= max
}

/// Maps `x ∈ [-max, max]` to `bits` bits.
fn float_to_uint(x: f32, max: f32, bits: u32) -> u32 {
    to_uint(x, -max, max, bits)
}

/// Clamps `x` into `[min, max]` (NaN → the value nearest 0) and truncates to `bits` bits as
/// Damiao's reference code does.
fn to_uint(x: f32, min: f32, max: f32, bits: u32) -> u32 {
    let span = max - min;
    let full = low_bits_mask(bits) as f32;
    if span.is_nan() || span <= 0.0 {
        return 0;
    }
    let x = constrain(x, min, max);
    // Damiao's order of operations where it stays finite; for ranges near f32::MAX the same
    // ratio without the overflowing intermediate (halved if even the span overflows).
    let num = (x - min) * full;
    let scaled = if num.is_finite() && span.is_finite() {
        num / span
    } else {
        (x * 0.5 - min * 0.5) / (max * 0.5 - min * 0.5) * full
    };
    constrain(scaled, 0.0, full) as u32
}

/// `2^bits - 1` for `bits` < 32 (the MIT fields are 12 and 16 bits wide).
const fn low_bits_mask(bits: u32) -> u32 {
    !(u32::MAX << bits)
}

fn uint_to_float(raw: u32, max: f32, bits: u32) -> f32 {
    let full = low_bits_mask(bits) as f32;
    raw as f32 * (2.0 * max) / full - max
}

/// A one-shot special command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DmSpecial {
    /// Enter motor mode (FC).
    Enable,
    /// Leave motor mode (FD).
    Disable,
    /// Make the present position zero (FE).
    SaveZero,
    /// Clear a latched error (FB).
    ClearError,
}

impl DmSpecial {
    /// The command that undoes this one, if any (Enable and Disable).
    const fn opposite(self) -> Option<Self> {
        match self {
            Self::Enable => Some(Self::Disable),
            Self::Disable => Some(Self::Enable),
            Self::SaveZero | Self::ClearError => None,
        }
    }

    /// The eight data bytes.
    pub const fn bytes(self) -> [u8; 8] {
        let last = match self {
            Self::Enable => 0xFC,
            Self::Disable => 0xFD,
            Self::SaveZero => 0xFE,
            Self::ClearError => 0xFB,
        };
        [0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, last]
    }
}

/// A fault the motor reports in its feedback.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DmFault {
    /// 8: supply over-voltage.
    OverVoltage,
    /// 9: supply under-voltage.
    UnderVoltage,
    /// A: over-current.
    OverCurrent,
    /// B: MOSFET over-temperature.
    MosOverTemperature,
    /// C: coil over-temperature.
    CoilOverTemperature,
    /// D: communication lost (the motor's own command timeout).
    CommunicationLost,
    /// E: overload.
    Overload,
    /// A state code this driver does not know.
    Unknown(u8),
}

/// The motor's state from its feedback.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DmStatus {
    /// Not in motor mode (no torque).
    #[default]
    Disabled,
    /// In motor mode.
    Enabled,
    /// Latched fault; send [`DmSpecial::ClearError`] to leave it.
    Fault(DmFault),
}

impl DmStatus {
    const fn from_code(code: u8) -> Self {
        match code {
            0 => Self::Disabled,
            1 => Self::Enabled,
            8 => Self::Fault(DmFault::OverVoltage),
            9 => Self::Fault(DmFault::UnderVoltage),
            0xA => Self::Fault(DmFault::OverCurrent),
            0xB => Self::Fault(DmFault::MosOverTemperature),
            0xC => Self::Fault(DmFault::CoilOverTemperature),
            0xD => Self::Fault(DmFault::CommunicationLost),
            0xE => Self::Fault(DmFault::Overload),
            other => Self::Fault(DmFault::Unknown(other)),
        }
    }
}

/// Configuration of a Damiao motor.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DmConfig {
    /// Ranges set in the motor.
    pub limits: MitLimits,
    /// The master ID its feedback arrives on (MST_ID in Damiao's tool; give each motor its own),
    /// below 0x7FF.
    pub master_id: u16,
    /// Velocity gain used by [`Motor::set_target_rpm`], N·m·s/rad.
    pub speed_kd: f32,
    /// Position gain used by the angle targets, N·m/rad.
    pub position_kp: f32,
    /// Velocity gain used by the angle targets, N·m·s/rad.
    pub position_kd: f32,
    /// Send Enable automatically while a target is set and the motor reports Disabled (never
    /// while it reports a fault: faults are cleared explicitly), and as a probe on every
    /// [`PROBE_TICKS`]-th tick while it sends no feedback (before its first answer, or
    /// offline: a motor power-cycled during an outage comes back in Disabled, and may not
    /// answer until enabled). A motor back from an outage resumes its target, as DJI motors
    /// do, when it returns enabled or Disabled; one that returns reporting a fault (such as
    /// [`DmFault::CommunicationLost`], if a CAN timeout is set in Damiao's tool and the
    /// outage outlasted it) stays limp until it is sent [`DmSpecial::ClearError`].
    pub auto_enable: bool,
    /// Gearbox of the motor (informational: positions are already of the output shaft).
    pub gear: GearRatio,
    /// Offline timeout and the multi-turn policy when feedback returns (see the module
    /// docs); thermal limits are not applied (the motor protects itself and reports faults).
    pub health: HealthConfig,
}

impl DmConfig {
    /// DM4310 defaults with feedback on `master_id`: factory ranges, speed kd 1.0, position
    /// kp 20 / kd 1.0, auto-enable, 10:1 gear, 100 ms offline timeout.
    pub const fn new(master_id: u16) -> Self {
        Self {
            limits: MitLimits::DEFAULT,
            master_id,
            speed_kd: 1.0,
            position_kp: 20.0,
            position_kd: 1.0,
            auto_enable: true,
            gear: match GearRatio::new(10, 1) {
                Some(g) => g,
                None => GearRatio::DIRECT,
            },
            health: HealthConfig::DEFAULT,
        }
    }
}

/// Why a Damiao motor could not be created.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DmError {
    /// The CAN ID or the master ID is 0x7FF or above (0x7FF is Damiao's parameter channel:
    /// an MIT command, or a feedback frame whose first bytes match a motor's ID and whose third
    /// is 0x55 or 0xAA, could be read there as a register write or a save), or they are
    /// equal.
    InvalidId,
    /// A range is not finite and positive or above [`MAX_MIT_RANGE`], a gain is not within the
    /// protocol's range, or the position range is below ±π (angle targets need a whole turn
    /// of it).
    InvalidLimit,
}

impl fmt::Display for DmError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::InvalidId => "DM CAN ID or master ID invalid",
            Self::InvalidLimit => "DM range or gain invalid",
        })
    }
}

impl core::error::Error for DmError {}

#[derive(Debug)]
struct DmState {
    mode: ControlMode,
    target: f32,
    user_mit: MitCommand,
    /// Special commands waiting, oldest first; each kind at most once (so never more than
    /// the four kinds).
    pending: heapless::Vec<DmSpecial, 4>,
    /// The waiting special packed on the last tick, if one was: queued again should the
    /// transport refuse it.
    sent_special: Option<DmSpecial>,
    /// What packing a `SaveZero` cleared, put back should the transport refuse it (the motor
    /// never took the new zero).
    before_zero: Option<BeforeZero>,
    status: DmStatus,
    position_rad: Option<f32>,
    wraps: i32,
    /// The frame offset ([`frame_offset_rad`](Self::frame_offset_rad)) modulo one output
    /// turn, in 2⁻⁶⁴ of a turn: the single-turn angle and the angle mode's error come from
    /// this, exact over any number of wraps (the f32 multi-turn position in radians spaces its
    /// values 0.0625 rad apart after 40 000 wraps of the factory ±12.5 rad).
    turn_offset: TurnFraction,
    /// Went offline; the next feedback applies the return policy.
    awaiting_return: bool,
    velocity_rad_s: f32,
    torque_nm: f32,
    mos_temp_c: Option<f32>,
    rotor_temp_c: Option<f32>,
    liveness: Liveness,
    /// Feed-forward torque added in speed and angle modes, N·m.
    feed_forward_nm: f32,
    /// Software homing: the wrap count it was made at (the total counts wraps from there)…
    home_wraps: i32,
    /// …and the angle asked for less the position then, rad: both small, so a homing made
    /// after many wraps reads its angle exactly, not as the difference of two large f32s.
    home_offset_rad: f32,
    pending_home_deg: Option<f32>,
    /// Ticks without feedback until the next Enable probe (auto-enable).
    probe_in: u8,
    /// The position field (the motor's own frame, rad) held while the total-angle target is
    /// out of reach: the position when it went out of reach.
    hold_rad: Option<f32>,
    torque_ff_nm: f32,
    out: [u8; 8],
}

/// The multi-turn count and homing a `SaveZero` clears when it is packed.
#[derive(Debug, Clone, Copy)]
struct BeforeZero {
    wraps: i32,
    home_wraps: i32,
    home_offset_rad: f32,
    turn_offset: TurnFraction,
    position_rad: Option<f32>,
    hold_rad: Option<f32>,
}

impl DmState {
    /// Takes a reported position `p` (rad, the motor's own wrapping frame), counting a wrap
    /// when it jumped by more than `p_max` from the last one.
    fn take_position(&mut self, p: f32, p_max: f32, wrap: TurnFraction) {
        if let Some(prev) = self.position_rad {
            if p - prev > p_max {
                self.count_wrap(false, wrap);
            } else if prev - p > p_max {
                self.count_wrap(true, wrap);
            }
        }
        self.position_rad = Some(p);
    }

    /// Clears the multi-turn count and homing for a `SaveZero` being packed, keeping them in
    /// `before_zero`.
    fn clear_for_zero(&mut self) {
        self.before_zero = Some(BeforeZero {
            wraps: self.wraps,
            home_wraps: self.home_wraps,
            home_offset_rad: self.home_offset_rad,
            turn_offset: self.turn_offset,
            position_rad: self.position_rad,
            hold_rad: self.hold_rad,
        });
        self.wraps = 0;
        self.home_wraps = 0;
        self.home_offset_rad = 0.0;
        self.turn_offset = TurnFraction::ZERO;
        self.position_rad = None;
        self.hold_rad = None;
    }

    /// Puts back what [`clear_for_zero`](Self::clear_for_zero) cleared (the `SaveZero` was
    /// refused): the count goes on in the old frame, through a reading taken since.
    fn undo_zero(&mut self, p_max: f32, wrap: TurnFraction) {
        let Some(before) = self.before_zero.take() else {
            return;
        };
        // A reading since the clear is in the old frame too (the motor never got FE).
        let since = self.position_rad;
        self.wraps = before.wraps;
        self.home_wraps = before.home_wraps;
        self.home_offset_rad = before.home_offset_rad;
        self.turn_offset = before.turn_offset;
        self.position_rad = before.position_rad;
        self.hold_rad = before.hold_rad;
        if let Some(p) = since {
            self.take_position(p, p_max, wrap);
        }
    }

    /// What the MIT position field's frame (the motor's reported, wrapping position) must be
    /// shifted by to give the output's multi-turn position after homing, rad.
    fn frame_offset_rad(&self, p_max: f32) -> f32 {
        // Both counts are i32: their difference fits an i64.
        let wraps = i64::from(self.wraps).wrapping_sub(i64::from(self.home_wraps));
        wraps as f32 * 2.0 * p_max + self.home_offset_rad
    }

    /// The output's multi-turn position after homing, rad.
    fn total_position_rad(&self, p_max: f32) -> f32 {
        self.position_rad.unwrap_or(0.0) + self.frame_offset_rad(p_max)
    }

    /// The output's position after homing within one turn, degrees, `[0, 360)`: the reported
    /// position plus the frame offset modulo a turn, both small, so exact to f32 resolution
    /// however many wraps the count holds.
    fn single_turn_deg(&self) -> f32 {
        wrap_deg_360(rad_to_deg(
            self.position_rad.unwrap_or(0.0) + self.turn_offset.to_rad(),
        ))
    }

    /// Counts one wrap of the reported position, `forward` (from +`p_max` to −`p_max`) or
    /// back. The count saturates (a wrap every second for 68 years); the turn offset moves
    /// only with it.
    fn count_wrap(&mut self, forward: bool, wrap: TurnFraction) {
        let wraps = if forward {
            self.wraps.checked_add(1)
        } else {
            self.wraps.checked_sub(1)
        };
        if let Some(wraps) = wraps {
            self.wraps = wraps;
            self.turn_offset = if forward {
                self.turn_offset.plus(wrap)
            } else {
                self.turn_offset.minus(wrap)
            };
        }
    }
}

/// A fraction of a turn in units of 2⁻⁶⁴ turn, added and subtracted modulo one turn: a sum of
/// any number of them is exact (u64 arithmetic wraps exactly where the circle does).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct TurnFraction(u64);

impl TurnFraction {
    /// No fraction of a turn.
    const ZERO: Self = Self(0);

    /// `2·p_max` (one wrap of the reported position) modulo a turn. `p_max` ≥ π is finite
    /// (checked by [`DmMotor::new`]); worked out in f64: for the factory 12.5 rad the
    /// fraction is within 2⁻⁵¹ turn, so even 2³¹ wraps (the count's limit) add up to less
    /// than 2⁻²⁰ turn (6 µrad) of error.
    const fn of_wrap(p_max_rad: f32) -> Self {
        let turns = 2.0 * p_max_rad as f64 / core::f64::consts::TAU;
        // turns ≥ 1 and below 2⁶⁴: the truncation is its whole part, and the fraction
        // (exact in f64) is in [0, 1).
        let fraction = turns - (turns as u64) as f64;
        Self((fraction * 18_446_744_073_709_551_616.0) as u64)
    }

    /// An angle in radians modulo a turn, to f32 resolution (24 bits of a turn).
    fn from_rad(angle_rad: f32) -> Self {
        // [0, 1): below 2³² when scaled.
        let turns = crate::math::wrap_positive(angle_rad / TAU, 1.0);
        Self(((turns * 4_294_967_296.0) as u64) << 32)
    }

    /// The fraction in radians, `[0, 2π)` (its top 24 bits: f32 resolution).
    fn to_rad(self) -> f32 {
        (self.0 >> 40) as f32 * (TAU / 16_777_216.0)
    }

    /// `self + other`, modulo a turn.
    const fn plus(self, other: Self) -> Self {
        Self(self.0.wrapping_add(other.0))
    }

    /// `self − other`, modulo a turn.
    const fn minus(self, other: Self) -> Self {
        Self(self.0.wrapping_sub(other.0))
    }

    /// `self` times `n`, modulo a turn: exact.
    const fn times(self, n: i32) -> Self {
        Self(self.0.wrapping_mul(n as i64 as u64))
    }
}

/// A Damiao motor in MIT mode on a CAN bus.
///
/// ```
/// use rc10_core::motor::Motor;
/// use rc10_core::motor::dm::{DmConfig, DmMotor};
/// let joint = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
/// joint.set_target_total_angle_deg(90.0).unwrap();
/// assert!(!joint.is_online());
/// ```
pub struct DmMotor {
    can_id: u16,
    config: DmConfig,
    /// One wrap of the reported position (2·`p_max`) modulo a turn.
    wrap_turn: TurnFraction,
    state: Mutex<CriticalSectionRawMutex, RefCell<DmState>>,
}

impl DmMotor {
    /// A motor commanded on `can_id` whose feedback arrives on `config.master_id`.
    pub const fn new(can_id: u16, config: DmConfig) -> Result<Self, DmError> {
        if can_id >= 0x7FF || config.master_id >= 0x7FF || can_id == config.master_id {
            return Err(DmError::InvalidId);
        }
        let l = config.limits;
        // Finite, positive and at most MAX_MIT_RANGE: the driver's unit conversions
        // (rad → degrees, rad/s → rpm, whole turns of 2·p_max) stay finite.
        const fn positive(x: f32) -> bool {
            x.is_finite() && x > 0.0 && x <= MAX_MIT_RANGE
        }
        // Angle targets need a whole turn of the position field (p_max ≥ π) to always have an
        // equivalent inside the range.
        if !positive(l.p_max_rad)
            || l.p_max_rad < core::f32::consts::PI
            || !positive(l.v_max_rad_s)
            || !positive(l.t_max_nm)
            || !ok(config.speed_kd, KD_MAX)
            || !ok(config.position_kp, KP_MAX)
            || !ok(config.position_kd, KD_MAX)
        {
            return Err(DmError::InvalidLimit);
        }
        Ok(Self {
            can_id,
            config,
            wrap_turn: TurnFraction::of_wrap(l.p_max_rad),
            state: Mutex::new(RefCell::new(DmState {
                mode: ControlMode::Disabled,
                target: 0.0,
                user_mit: MitCommand::ZERO_TORQUE,
                pending: heapless::Vec::new(),
                sent_special: None,
                before_zero: None,
                status: DmStatus::Disabled,
                position_rad: None,
                wraps: 0,
                turn_offset: TurnFraction::ZERO,
                awaiting_return: false,
                velocity_rad_s: 0.0,
                torque_nm: 0.0,
                mos_temp_c: None,
                rotor_temp_c: None,
                liveness: Liveness::NEW,
                feed_forward_nm: 0.0,
                home_wraps: 0,
                home_offset_rad: 0.0,
                pending_home_deg: None,
                probe_in: PROBE_TICKS - 1,
                hold_rad: None,
                torque_ff_nm: 0.0,
                out: [0; 8],
            })),
        })
    }

    /// The CAN ID commands go to.
    pub const fn can_id(&self) -> u16 {
        self.can_id
    }

    /// The configuration.
    pub const fn config(&self) -> &DmConfig {
        &self.config
    }

    /// Sends a raw MIT command every tick from now on (fields clamped when packed).
    pub fn set_mit(&self, command: MitCommand) -> Result<(), TargetError> {
        let c = command;
        if ![c.position_rad, c.velocity_rad_s, c.kp, c.kd, c.torque_nm]
            .iter()
            .all(|x| x.is_finite())
        {
            return Err(TargetError::NotFinite);
        }
        self.state.lock(|s| {
            let mut s = s.borrow_mut();
            s.mode = ControlMode::Torque;
            s.target = c.torque_nm;
            s.user_mit = c;
        });
        Ok(())
    }

    /// Sends `special` once, on a coming tick while the motor is online, instead of that
    /// tick's MIT command: one special a tick, in the order asked for (`ClearError` then
    /// `Enable` sends FB, then FC). A kind asked for again while it still waits keeps its
    /// place, so at most the four kinds wait, none is dropped and none is starved; `Enable`
    /// and `Disable` undo each other, so the later of the two replaces a waiting earlier one
    /// (Disable, Enable, Disable sends FD once: the motor ends disabled, as the driver). While the
    /// motor is offline the specials wait (sent into silence they would be lost), but a
    /// waiting `Enable` also goes out as a probe on every [`PROBE_TICKS`]-th tick, for a
    /// motor that answers only once enabled (without auto-enable it could not come back).
    /// A special the transport refuses (TX buffers full, bus-off; the bus tells the driver,
    /// [`CanNode::frame_refused`]) waits again, first in line, unless its opposite was asked
    /// for since (a refused `SaveZero` also puts back the count and homing that packing it
    /// cleared).
    ///
    /// - `Disable` also disables the driver (as [`Motor::disable`]): auto-enable does not
    ///   bring the motor back into motor mode until a new target is set.
    /// - `SaveZero` makes the motor's present position its zero; the driver's multi-turn
    ///   count starts afresh from the next reading (wraps so far and a software homing
    ///   offset from [`Motor::set_total_angle_here_deg`] are cleared when FE is sent; a
    ///   homing asked for before then applies to the first reading after it). An angle or
    ///   total-angle target refers to the new zero from then on: a joint holding 100° moves
    ///   another 100° after FE. Disable it (or set the target it should hold) around FE:
    ///   Damiao's guides set the zero with the motor disabled. Known limit: a reply in the
    ///   old frame taken after FE was packed (with a TX backlog, `tx_stale`, this motor's
    ///   MIT frames queued before FE go out first; or a receive path running late) is read
    ///   as the new frame: a homing asked for together with `SaveZero` can apply to it, and
    ///   if it lay near ±`p_max` the first reading after the new zero can count a wrap.
    ///   On a loaded bus, home once the reported position shows the new zero.
    pub fn send_special(&self, special: DmSpecial) {
        self.state.lock(|s| {
            let mut s = s.borrow_mut();
            // The later of Enable and Disable wins: the earlier one no longer waits.
            if let Some(opposite) = special.opposite() {
                s.pending.retain(|&waiting| waiting != opposite);
            }
            if !s.pending.contains(&special) {
                // The other three kinds at most wait: there is room.
                let _ = s.pending.push(special);
            }
            if special == DmSpecial::Disable {
                s.mode = ControlMode::Disabled;
                s.target = 0.0;
            }
        });
    }

    /// The motor's reported state.
    pub fn status(&self) -> DmStatus {
        self.state.lock(|s| s.borrow().status)
    }

    /// Last measured torque in N·m.
    pub fn torque_nm(&self) -> f32 {
        self.state.lock(|s| s.borrow().torque_nm)
    }

    /// MOSFET and rotor temperatures in °C (`None` before the first feedback).
    pub fn temperatures_c(&self) -> (Option<f32>, Option<f32>) {
        self.state.lock(|s| {
            let s = s.borrow();
            (s.mos_temp_c, s.rotor_temp_c)
        })
    }

    fn set(&self, mode: ControlMode, target: f32) -> Result<(), TargetError> {
        if !target.is_finite() {
            return Err(TargetError::NotFinite);
        }
        self.state.lock(|s| {
            let mut s = s.borrow_mut();
            s.mode = mode;
            s.target = target;
        });
        Ok(())
    }

    /// The MIT command for the mode; `total_field_rad` is the total-angle target's position
    /// field when it is in reach ([`total_angle_field_rad`](Self::total_angle_field_rad),
    /// worked out once a tick by `update`).
    fn mit_for(&self, s: &DmState, total_field_rad: Option<f32>) -> MitCommand {
        let c = &self.config;
        let p_max = c.limits.p_max_rad;
        match s.mode {
            ControlMode::Disabled | ControlMode::Voltage | ControlMode::Current => {
                MitCommand::ZERO_TORQUE
            }
            ControlMode::Torque => s.user_mit,
            ControlMode::Speed => MitCommand {
                velocity_rad_s: s.target * TAU / 60.0,
                kd: c.speed_kd,
                torque_nm: s.feed_forward_nm,
                ..MitCommand::ZERO_TORQUE
            },
            ControlMode::Angle | ControlMode::TotalAngle => {
                // MIT position commands are in the motor's own frame, which spans ±p_max.
                let motor_now = s.position_rad.unwrap_or(0.0);
                let position_rad = if s.mode == ControlMode::Angle {
                    // The shortest way round, or if that crosses ±p_max, the same output
                    // angle a whole turn the other way (p_max ≥ π, so one of them is in range).
                    let error_rad = deg_to_rad(wrap_signed(s.target - s.single_turn_deg(), 360.0));
                    let short = motor_now + error_rad;
                    if short > p_max {
                        short - TAU
                    } else if short < -p_max {
                        short + TAU
                    } else {
                        short
                    }
                } else {
                    // Checked against the range when set. Out of it now (a return under
                    // `Restart`, a saved zero, the joint pushed across the range end), the
                    // field would be clamped to the range end: a place that is neither the
                    // target nor here. The motor holds where it was when the target went out
                    // of reach instead (`update` keeps that position).
                    total_field_rad.or(s.hold_rad).unwrap_or(motor_now)
                };
                MitCommand {
                    position_rad,
                    kp: c.position_kp,
                    kd: c.position_kd,
                    torque_nm: s.feed_forward_nm,
                    ..MitCommand::ZERO_TORQUE
                }
            }
        }
    }

    /// The MIT position field for the total-angle target, rad, if it is within the field's
    /// ±`p_max` (give or take rounding: a target set at the end of
    /// [`total_angle_range_deg`](Self::total_angle_range_deg) is in reach).
    fn total_angle_field_rad(&self, s: &DmState) -> Option<f32> {
        let p_max = self.config.limits.p_max_rad;
        let field = deg_to_rad(s.target) - s.frame_offset_rad(p_max);
        (field.abs() <= p_max * (1.0 + REACH_TOLERANCE)).then_some(field)
    }

    /// The multi-turn output angles, in degrees, that a total-angle target can have now: the
    /// MIT position field spans ±`p_max` of the motor's own frame (shifted by homing and by
    /// any wrap of the reported position).
    pub fn total_angle_range_deg(&self) -> (f32, f32) {
        let p_max = self.config.limits.p_max_rad;
        self.state.lock(|s| {
            let s = s.borrow();
            let offset = s.frame_offset_rad(p_max);
            (rad_to_deg(-p_max + offset), rad_to_deg(p_max + offset))
        })
    }
}

impl CanNode for DmMotor {
    fn bus_usage(&self) -> BusUsage {
        // The motor answers every command frame on its master ID: one reply a tick, whatever
        // the tick period.
        BusUsage::NONE
            .answering(IdFilter::standard(self.config.master_id), 1)
            .sending(IdFilter::standard(self.can_id), 1)
    }

    fn update_feedback(&self, frame: &CanFrame, now: Instant) -> Result<(), FrameError> {
        let d = frame.data8().ok_or(FrameError::WrongLength {
            dlc: frame.dlc() as u8,
        })?;
        if u16::from(d[0] & 0x0F) != self.can_id & 0x0F {
            return Err(FrameError::OutOfRange); // another motor's reply on this master ID
        }
        let l = self.config.limits;
        let p = uint_to_float(u32::from(u16::from_be_bytes([d[1], d[2]])), l.p_max_rad, 16);
        let v_raw = (u32::from(d[3]) << 4) | (u32::from(d[4]) >> 4);
        let t_raw = ((u32::from(d[4]) & 0xF) << 8) | u32::from(d[5]);
        self.state.lock(|s| {
            let mut s = s.borrow_mut();
            if s.awaiting_return {
                s.awaiting_return = false;
                if self.config.health.on_return == MultiTurnOnReturn::Restart {
                    s.position_rad = None;
                    // The homing offset stays: only the wraps leave the turn offset.
                    s.turn_offset = s.turn_offset.minus(self.wrap_turn.times(s.wraps));
                    s.wraps = 0;
                }
            }
            s.take_position(p, l.p_max_rad, self.wrap_turn);
            s.velocity_rad_s = uint_to_float(v_raw, l.v_max_rad_s, 12);
            s.torque_nm = uint_to_float(t_raw, l.t_max_nm, 12);
            s.status = DmStatus::from_code(d[0] >> 4);
            s.mos_temp_c = Some(f32::from(d[6]));
            s.rotor_temp_c = Some(f32::from(d[7]));
            s.liveness.record_feedback(now);
        });
        Ok(())
    }

    fn update(&self, now: Instant, _dt_s: f32) {
        let health = self.config.health;
        self.state.lock(|cell| {
            let mut s = cell.borrow_mut();
            if s.liveness.check(&health, now) {
                s.awaiting_return = true;
            }
            let online = s.liveness.is_online();
            // Every PROBE_TICKS-th tick without feedback may probe with Enable.
            let probe = !online && s.probe_in == 0;
            s.probe_in = match s.probe_in.checked_sub(1) {
                Some(n) if !online => n,
                _ => PROBE_TICKS - 1,
            };
            // A special goes to a motor that answers; while offline it waits.
            let special = if online {
                s.pending.first().copied()
            } else {
                None
            };
            s.sent_special = special;
            if let Some(special) = special {
                // Each kind waits at most once: this removes the first.
                s.pending.retain(|&waiting| waiting != special);
                if special == DmSpecial::SaveZero {
                    // Before the homing below: a homing asked for with it waits for the
                    // first reading after the new zero.
                    s.clear_for_zero();
                }
            }
            // Against a live reading only: the one before an outage may be stale (the joint
            // moved, or the motor was power-cycled), and a return's policy applies first. Not
            // while a SaveZero still waits behind another special: FE would clear it.
            if let Some(deg) = s.pending_home_deg
                && online
                && !s.awaiting_return
                && s.position_rad.is_some()
                && !s.pending.contains(&DmSpecial::SaveZero)
            {
                // From small values only (the angle asked for less the reported position, and
                // the same within a turn): exact however many wraps there were.
                let here_rad = s.position_rad.unwrap_or(0.0);
                s.home_wraps = s.wraps;
                s.home_offset_rad = deg_to_rad(deg) - here_rad;
                s.turn_offset = TurnFraction::from_rad(deg_to_rad(wrap_deg_360(deg)) - here_rad);
                s.pending_home_deg = None;
            }
            // The hold of an out-of-reach total-angle target: the position where it went out
            // of reach, kept while it stays out (a new target, a return, another mode or a
            // saved zero ends it).
            let held = online && s.mode == ControlMode::TotalAngle;
            let total_field_rad = held.then(|| self.total_angle_field_rad(&s)).flatten();
            s.hold_rad = if held && total_field_rad.is_none() {
                s.hold_rad.or(s.position_rad)
            } else {
                None
            };
            let mit = if online {
                self.mit_for(&s, total_field_rad)
            } else {
                MitCommand::ZERO_TORQUE
            };
            // What the packed field carries: clamped to ±t_max.
            let t_max = self.config.limits.t_max_nm;
            s.torque_ff_nm = crate::math::constrain(mit.torque_nm, -t_max, t_max);
            s.out = if let Some(special) = special {
                // No torque is commanded on this tick.
                s.torque_ff_nm = 0.0;
                special.bytes()
            } else if if online {
                self.config.auto_enable
                    && s.mode != ControlMode::Disabled
                    && s.status == DmStatus::Disabled
            } else {
                probe
                    && ((self.config.auto_enable && s.mode != ControlMode::Disabled)
                        || s.pending.contains(&DmSpecial::Enable))
            } {
                // Online and reporting Disabled (auto-enable), or silent (not yet answered,
                // or gone) with auto-enable or an Enable waiting: a motor that answers only
                // in motor mode, or rebooted into Disabled, is brought back. A silent motor
                // gets zero torque between the probes; a waiting Enable still goes out once
                // it answers.
                s.torque_ff_nm = 0.0;
                DmSpecial::Enable.bytes()
            } else {
                mit.pack(&self.config.limits)
            };
        });
    }

    fn pack_command(&self, out: &mut TxBatch) {
        let bytes = self.state.lock(|s| s.borrow().out);
        if let Some(frame) = CanFrame::standard(self.can_id, &bytes) {
            let _ = out.push(frame);
        }
    }

    /// A waiting special the transport refused (TX buffers full, bus-off) waits again, first
    /// in line (unless its opposite, `Enable` against `Disable`, was asked for since: the
    /// later one wins): it goes out on the next tick the motor is online. A refused `SaveZero` also puts back the multi-turn
    /// count and homing that packing it cleared: the motor never took the new zero. An MIT
    /// command or an `Enable` probe is not queued again: the next tick makes a fresh one.
    fn frame_refused(&self, frame: &CanFrame, _reason: SendError) {
        let p_max = self.config.limits.p_max_rad;
        self.state.lock(|cell| {
            let mut s = cell.borrow_mut();
            if let Some(special) = s.sent_special.take()
                && frame.data() == special.bytes()
            {
                if special == DmSpecial::SaveZero {
                    s.undo_zero(p_max, self.wrap_turn);
                }
                // First in line: it was asked for before anything still waiting (asked for
                // again since, it keeps the earlier place, as `send_special` does); unless its
                // opposite was asked for since, which wins.
                let superseded = special
                    .opposite()
                    .is_some_and(|opposite| s.pending.contains(&opposite));
                if !superseded {
                    s.pending.retain(|&waiting| waiting != special);
                    // Each kind at most once, and this one is out of the list: there is room.
                    let _ = s.pending.insert(0, special);
                }
            }
        });
    }
}

impl Motor for DmMotor {
    /// Damiao motors take torque, not current: use
    /// [`set_target_torque_nm`](Motor::set_target_torque_nm).
    fn set_target_current(&self, _amps: f32) -> Result<(), TargetError> {
        Err(TargetError::Unsupported)
    }

    fn set_target_rpm(&self, rpm: f32) -> Result<(), TargetError> {
        self.set(ControlMode::Speed, rpm)
    }

    /// Reached through the MIT position field the shortest way round, unless that way would
    /// cross the end of the motor's ±`p_max` position range: then the same output angle is
    /// reached a turn the other way (the field cannot go beyond the range).
    fn set_target_angle_deg(&self, angle_deg: f32) -> Result<(), TargetError> {
        self.set(ControlMode::Angle, angle_deg)
    }

    /// Reached through the MIT position field, so the target must lie within
    /// [`total_angle_range_deg`](DmMotor::total_angle_range_deg) (±`p_max`: ±716° with the
    /// factory 12.5 rad, shifted by homing); beyond it: [`TargetError::OutOfRange`] and the
    /// previous target stays. Widen PMAX in Damiao's tool (and [`MitLimits`]) for more.
    fn set_target_total_angle_deg(&self, angle_deg: f32) -> Result<(), TargetError> {
        if !angle_deg.is_finite() {
            return Err(TargetError::NotFinite);
        }
        let p_max = self.config.limits.p_max_rad;
        // Checked and set under one lock, so homing cannot move the range in between.
        self.state.lock(|cell| {
            let mut s = cell.borrow_mut();
            let offset_deg = rad_to_deg(s.frame_offset_rad(p_max));
            let half_range_deg = rad_to_deg(p_max);
            if (angle_deg - offset_deg).abs() > half_range_deg {
                return Err(TargetError::OutOfRange);
            }
            s.mode = ControlMode::TotalAngle;
            s.target = angle_deg;
            Ok(())
        })
    }

    /// MIT with zero gains and this feed-forward torque (mode [`ControlMode::Torque`]).
    fn set_target_torque_nm(&self, torque_nm: f32) -> Result<(), TargetError> {
        self.set_mit(MitCommand {
            torque_nm,
            ..MitCommand::ZERO_TORQUE
        })
    }

    /// Sent in the MIT torque field next to the speed and position commands.
    fn set_feed_forward_torque_nm(&self, torque_nm: f32) -> Result<(), TargetError> {
        if !torque_nm.is_finite() {
            return Err(TargetError::NotFinite);
        }
        self.state
            .lock(|s| s.borrow_mut().feed_forward_nm = torque_nm);
        Ok(())
    }

    /// Software homing in the driver (the motor's own zero is not touched; for that send
    /// [`DmSpecial::SaveZero`]).
    fn set_total_angle_here_deg(&self, angle_deg: f32) -> Result<(), TargetError> {
        if !angle_deg.is_finite() {
            return Err(TargetError::NotFinite);
        }
        self.state
            .lock(|s| s.borrow_mut().pending_home_deg = Some(angle_deg));
        Ok(())
    }

    fn disable(&self) {
        let _ = self.set(ControlMode::Disabled, 0.0);
    }

    fn state(&self) -> MotorState {
        self.state.lock(|cell| {
            let s = cell.borrow();
            let total_deg = rad_to_deg(s.total_position_rad(self.config.limits.p_max_rad));
            let has_position = s.position_rad.is_some();
            MotorState {
                online: s.liveness.is_online(),
                mode: s.mode,
                target: s.target,
                speed_rpm: s.velocity_rad_s * 60.0 / TAU,
                angle_deg: has_position.then(|| s.single_turn_deg()),
                total_angle_deg: has_position.then_some(total_deg),
                current_amps: None,
                temperature_c: match (s.rotor_temp_c, s.mos_temp_c) {
                    (Some(r), Some(m)) => Some(r.max(m)),
                    (r, m) => r.or(m),
                },
                command: s.torque_ff_nm,
                offline_events: s.liveness.offline_events(),
                last_feedback: s.liveness.last_feedback(),
            }
        })
    }

    fn gear_ratio(&self) -> GearRatio {
        self.config.gear
    }
}

impl fmt::Debug for DmMotor {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("DmMotor")
            .field("can_id", &self.can_id)
            .field("master_id", &self.config.master_id)
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const T0: Instant = Instant::from_millis(7);

    fn feedback(state: u8, id: u8, p: u16, v: u16, t: u16, mos: u8, rotor: u8) -> CanFrame {
        let d = [
            id | (state << 4),
            (p >> 8) as u8,
            p as u8,
            (v >> 4) as u8,
            (((v & 0xF) << 4) | (t >> 8)) as u8,
            t as u8,
            mos,
            rotor,
        ];
        CanFrame::standard(0x11, &d).unwrap()
    }

    fn packed(m: &DmMotor, now: Instant) -> [u8; 8] {
        let mut b = TxBatch::new();
        m.update(now, 0.001);
        m.pack_command(&mut b);
        assert_eq!(b.frames().len(), 1);
        assert_eq!(b.frames()[0].raw_id(), u32::from(m.can_id()));
        *b.frames()[0].data8().unwrap()
    }

    #[test]
    fn mit_pack_matches_hand_computed_bits() {
        // p = 0 → (12.5)·65535/25 = 32767.5 → 32767 = 0x7FFF; v = 15 → 45·4095/60 = 3071.25
        // → 3071 = 0xBFF; kp = 250 → 2047.5 → 2047 = 0x7FF; kd = 5 → 4095 = 0xFFF;
        // t = -10 → 0 = 0x000.
        let cmd = MitCommand {
            position_rad: 0.0,
            velocity_rad_s: 15.0,
            kp: 250.0,
            kd: 5.0,
            torque_nm: -10.0,
        };
        assert_eq!(
            cmd.pack(&MitLimits::DEFAULT),
            [0x7F, 0xFF, 0xBF, 0xF7, 0xFF, 0xFF, 0xF0, 0x00]
        );
    }

    #[test]
    fn mit_pack_clamps_instead_of_spilling_into_neighbours() {
        // Torque 1000 N·m would be (1000 + 10)/20 · 4095 = 206797 = 0x327CD without clamping
        // and overwrite kd's low nibble.
        let cmd = MitCommand {
            torque_nm: 1000.0,
            kd: 0.0,
            ..MitCommand::ZERO_TORQUE
        };
        let b = cmd.pack(&MitLimits::DEFAULT);
        assert_eq!((b[6], b[7]), (0x0F, 0xFF)); // kd nibble 0, torque 0xFFF
        let nan = MitCommand {
            position_rad: f32::NAN,
            velocity_rad_s: f32::NEG_INFINITY,
            ..MitCommand::ZERO_TORQUE
        };
        let b = nan.pack(&MitLimits::DEFAULT);
        // NaN → 0 rad → 0x7FFF; -inf → -30 rad/s → 0x000.
        assert_eq!((b[0], b[1], b[2], b[3] >> 4), (0x7F, 0xFF, 0x00, 0x0));
    }

    #[test]
    fn special_commands_bytes() {
        assert_eq!(DmSpecial::Enable.bytes()[7], 0xFC);
        assert_eq!(DmSpecial::Disable.bytes()[7], 0xFD);
        assert_eq!(DmSpecial::SaveZero.bytes()[7], 0xFE);
        assert_eq!(DmSpecial::ClearError.bytes()[..7], [0xFF; 7]);
        assert_eq!(DmSpecial::ClearError.bytes()[7], 0xFB);
    }

    #[test]
    fn feedback_parsed_with_state_and_temperatures() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        // p 0xFFFF = +12.5 rad, v 0x800 = 2048 → 2048·60/4095 - 30 = 0.00733 rad/s,
        // t 0xFFF = +10 N·m, state 1 (enabled), 40 °C MOS, 55 °C rotor.
        m.update_feedback(&feedback(1, 1, 0xFFFF, 0x800, 0xFFF, 40, 55), T0)
            .unwrap();
        let s = m.state();
        assert!((s.total_angle_deg.unwrap() - rad_to_deg(12.5)).abs() < 1e-3);
        assert!((s.speed_rpm - 0.00733 * 60.0 / TAU).abs() < 1e-3);
        assert_eq!(m.torque_nm(), 10.0);
        assert_eq!(m.status(), DmStatus::Enabled);
        assert_eq!(m.temperatures_c(), (Some(40.0), Some(55.0)));
        assert_eq!(s.current_amps, None);
    }

    #[test]
    fn an_mit_command_never_takes_the_shape_of_a_special_command() {
        // Every field at the top of its range and a torque of 9.99 N·m: code (19.99/20) ·
        // 4095 = 4092 = 0xFFC, which would make the frame FF×7 FC (Enable). Sent as 0xFFA.
        let cmd = MitCommand {
            position_rad: 12.5,
            velocity_rad_s: 30.0,
            kp: 500.0,
            kd: 5.0,
            torque_nm: 9.99,
        };
        assert_eq!(
            cmd.pack(&MitLimits::DEFAULT),
            [0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFA]
        );
        // One field off the top: no guard needed, the torque code goes out as it is.
        let lower = MitCommand { kd: 4.0, ..cmd };
        assert_eq!(lower.pack(&MitLimits::DEFAULT)[7], 0xFC);
    }

    #[test]
    fn fault_codes_decode() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        for (code, fault) in [
            (8, DmFault::OverVoltage),
            (9, DmFault::UnderVoltage),
            (0xA, DmFault::OverCurrent),
            (0xB, DmFault::MosOverTemperature),
            (0xC, DmFault::CoilOverTemperature),
            (0xD, DmFault::CommunicationLost),
            (0xE, DmFault::Overload),
        ] {
            m.update_feedback(&feedback(code, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
                .unwrap();
            assert_eq!(m.status(), DmStatus::Fault(fault));
        }
    }

    #[test]
    fn position_unwraps_across_the_range_end() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        m.update_feedback(&feedback(1, 1, 0xFFF0, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        let before = m.total_angle_deg().unwrap();
        // Wraps from +12.5 to -12.5 rad while turning forward by a few counts.
        m.update_feedback(&feedback(1, 1, 0x0010, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        // Codes 65535 (+12.5 rad) and 0 (-12.5 rad) are the same point on the 25 rad circle,
        // so 0xFFF0 → 0x0010 is 15 + 16 = 31 codes of 25/65535 rad.
        let step_deg = rad_to_deg(31.0 * 25.0 / 65535.0);
        assert!((m.total_angle_deg().unwrap() - before - step_deg).abs() < 0.01);
    }

    /// A DM4310 that made one wrap (+1 turn of the 25 rad range), then went offline.
    fn wrapped_then_offline(policy: MultiTurnOnReturn) -> DmMotor {
        let mut cfg = DmConfig::new(0x11);
        cfg.health = cfg.health.with_on_return(policy);
        let m = DmMotor::new(0x01, cfg).unwrap();
        m.update_feedback(&feedback(1, 1, 0xFFF0, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        m.update_feedback(&feedback(1, 1, 0x0010, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        m.update(T0, 0.001);
        assert!(m.is_online());
        // 100 ms offline timeout: silent for 150 ms.
        m.update(Instant::from_millis(157), 0.001);
        assert!(!m.is_online());
        m
    }

    #[test]
    fn return_after_an_outage_follows_the_multi_turn_policy() {
        // Code 0x4000 is 25 · 16384 / 65535 - 12.5 ≈ -6.25 rad.
        let back = feedback(1, 1, 0x4000, 0x7FF, 0x7FF, 30, 30);
        let code_deg = rad_to_deg(25.0 * 16384.0 / 65535.0 - 12.5);
        let range_deg = rad_to_deg(25.0);
        let t = Instant::from_millis(160);

        // Continue: 0x0010 → 0x4000 is less than half the range: no new wrap, the one before
        // the outage kept.
        let m = wrapped_then_offline(MultiTurnOnReturn::Continue);
        m.update_feedback(&back, t).unwrap();
        assert!((m.total_angle_deg().unwrap() - (code_deg + range_deg)).abs() < 0.01);

        // Restart: the wrap before the outage is forgotten; the position is taken as reported.
        let m = wrapped_then_offline(MultiTurnOnReturn::Restart);
        m.update_feedback(&back, t).unwrap();
        assert!((m.total_angle_deg().unwrap() - code_deg).abs() < 0.01);
        // And counting goes on from there: forward in steps under half the range, then across
        // the range end, counted as a wrap.
        for code in [0xA000, 0xFFF0, 0x0010] {
            m.update_feedback(&feedback(1, 1, code, 0x7FF, 0x7FF, 30, 30), t)
                .unwrap();
        }
        let wrapped = rad_to_deg(25.0 * 16.0 / 65535.0 - 12.5) + range_deg;
        assert!((m.total_angle_deg().unwrap() - wrapped).abs() < 0.01);
    }

    #[test]
    fn wrong_motor_nibble_and_short_frames_are_rejected() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        assert_eq!(
            m.update_feedback(&feedback(1, 2, 0, 0, 0, 0, 0), T0),
            Err(FrameError::OutOfRange)
        );
        let short = CanFrame::standard(0x11, &[1, 2, 3]).unwrap();
        assert_eq!(
            m.update_feedback(&short, T0),
            Err(FrameError::WrongLength { dlc: 3 })
        );
    }

    #[test]
    fn auto_enable_then_mit_speed_command() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        m.set_target_rpm(60.0).unwrap(); // 2π rad/s
        // Never answered yet: zero torque, and Enable as a probe on every 10th tick.
        for _ in 0..2 {
            for _ in 1..PROBE_TICKS {
                assert_eq!(packed(&m, T0), ZERO_TORQUE_BYTES);
            }
            assert_eq!(packed(&m, T0), DmSpecial::Enable.bytes());
        }
        m.update_feedback(&feedback(1, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        // p 0 → (0 + 12.5)/25 · 65535 = 32767.5 → 0x7FFF; v 2π → (2π + 30)/60 · 4095 =
        // 2476.3 → 0x9AC; kp 0; kd 1 → 1/5 · 4095 = 819 → 0x333; t 0 → 2047.5 → 0x7FF.
        assert_eq!(
            packed(&m, T0),
            [0x7F, 0xFF, 0x9A, 0xC0, 0x00, 0x33, 0x37, 0xFF]
        );
    }

    /// MIT with p, v, kp, kd and t all 0 (codes 0x7FFF, 0x7FF, 0, 0, 0x7FF), from the layout.
    const ZERO_TORQUE_BYTES: [u8; 8] = [0x7F, 0xFF, 0x7F, 0xF0, 0x00, 0x00, 0x07, 0xFF];

    fn special(last: u8) -> [u8; 8] {
        [0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, last]
    }

    #[test]
    fn specials_asked_together_go_one_a_tick_in_order() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        // Over-current latched (state 0xA).
        m.update_feedback(&feedback(0xA, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        m.send_special(DmSpecial::ClearError);
        m.send_special(DmSpecial::Enable);
        m.send_special(DmSpecial::ClearError); // again: it keeps its place
        assert_eq!(packed(&m, T0), special(0xFB));
        assert_eq!(packed(&m, T0), special(0xFC));
        // Nothing waits any more, and no target is set: zero torque.
        assert_eq!(packed(&m, T0), ZERO_TORQUE_BYTES);
    }

    #[test]
    fn specials_asked_every_tick_are_all_sent() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        m.update_feedback(&feedback(0xA, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        let mut sent = Vec::new();
        for _ in 0..4 {
            m.send_special(DmSpecial::ClearError);
            m.send_special(DmSpecial::Enable);
            sent.push(packed(&m, T0)[7]);
        }
        assert_eq!(sent, [0xFB, 0xFC, 0xFB, 0xFC]);
    }

    #[test]
    fn specials_wait_while_the_motor_is_offline() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        // One wrap forward, then the motor goes silent.
        m.update_feedback(&feedback(1, 1, 0xFFF0, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        m.update_feedback(&feedback(1, 1, 0x0010, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        let total = m.total_angle_deg().unwrap();
        let later = T0 + crate::time::Duration::from_millis(200);
        m.send_special(DmSpecial::SaveZero);
        assert_eq!(packed(&m, later), ZERO_TORQUE_BYTES);
        assert!(!m.is_online());
        // Back with its old zero (it never got FE): the count goes on where it was.
        m.update_feedback(&feedback(1, 1, 0x0010, 0x7FF, 0x7FF, 30, 30), later)
            .unwrap();
        assert!((m.total_angle_deg().unwrap() - total).abs() < 0.01);
        // Online again: now FE goes out.
        assert_eq!(packed(&m, later), special(0xFE));
    }

    #[test]
    fn homing_asked_with_save_zero_applies_to_the_new_zero() {
        // A homing to 90° asked together with SaveZero, alone or waiting behind another
        // special (ClearError: FB goes out first, and the homing must not apply to the old
        // zero on that tick, or FE would then clear it).
        for ahead in [None, Some((DmSpecial::ClearError, 0xFB))] {
            let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
            m.update_feedback(&feedback(1, 1, 0xC000, 0x7FF, 0x7FF, 30, 30), T0)
                .unwrap();
            if let Some((first, _)) = ahead {
                m.send_special(first);
            }
            m.send_special(DmSpecial::SaveZero);
            m.set_total_angle_here_deg(90.0).unwrap();
            if let Some((_, code)) = ahead {
                assert_eq!(packed(&m, T0), special(code));
            }
            assert_eq!(packed(&m, T0), special(0xFE));
            // The first reading after the new zero (about 0 rad) is where 90° is.
            m.update_feedback(&feedback(1, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
                .unwrap();
            packed(&m, T0);
            let total = m.total_angle_deg().unwrap();
            assert!((total - 90.0).abs() < 0.01, "{ahead:?}: {total}");
            let angle = f64::from(m.angle_deg().unwrap());
            assert!(circle_gap_deg(angle, 90.0) < 0.01, "{ahead:?}: {angle}");
        }
    }

    #[test]
    fn a_special_the_transport_refused_goes_out_again_first() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        let refused = |bytes: [u8; 8]| {
            m.frame_refused(&CanFrame::standard(0x01, &bytes).unwrap(), SendError::Full)
        };
        // At 0xC000 (+6.25 rad) with the old zero; a zero and a homing to 90° asked for.
        let old_zero = feedback(1, 1, 0xC000, 0x7FF, 0x7FF, 30, 30);
        m.update_feedback(&old_zero, T0).unwrap();
        m.send_special(DmSpecial::SaveZero);
        m.set_total_angle_here_deg(90.0).unwrap();
        assert_eq!(packed(&m, T0), special(0xFE));
        // TX buffers full: FE never left the board. It goes out again, before a ClearError
        // asked for after the refusal; the motor still reports from its old zero and the
        // homing does not apply to that.
        refused(special(0xFE));
        m.send_special(DmSpecial::ClearError);
        m.update_feedback(&old_zero, T0).unwrap();
        assert_eq!(packed(&m, T0), special(0xFE));
        assert_eq!(packed(&m, T0), special(0xFB));
        // Both went out: the first reading after the new zero (about 0 rad) is 90°.
        m.update_feedback(&feedback(1, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        let mit = packed(&m, T0);
        assert_ne!(mit[..7], [0xFF; 7], "an MIT command");
        let total = m.total_angle_deg().unwrap();
        assert!((total - 90.0).abs() < 0.01, "{total}");
        // A refused MIT command, or a report about a special of an earlier tick, queues
        // nothing: the next tick sends a fresh MIT command.
        refused(mit);
        refused(special(0xFB));
        assert_ne!(packed(&m, T0)[..7], [0xFF; 7]);
    }

    #[test]
    fn enable_and_disable_asked_for_in_turn_end_as_the_last_one_asked() {
        use DmSpecial::{ClearError, Disable, Enable};
        /// A frame expected on a tick.
        #[derive(Debug)]
        enum Want {
            /// The special with this last byte.
            Special(u8),
            /// The zero-torque MIT command (Disabled mode).
            ZeroTorque,
            /// An MIT command (not a special).
            Mit,
        }
        use Want::{Mit, Special, ZeroTorque};
        // Each case: a special packed first and refused (if any), the specials asked for
        // after it, then the frames of the next ticks.
        let cases: [(Option<DmSpecial>, &[DmSpecial], &[Want]); 4] = [
            // Disable, Enable, Disable before a tick: FD once (FD then FC would leave the
            // motor enabled while the driver is in Disabled mode).
            (
                None,
                &[Disable, Enable, Disable],
                &[Special(0xFD), ZeroTorque],
            ),
            // FD packed, then Enable and Disable asked for before the refusal is known: FD
            // once.
            (
                Some(Disable),
                &[Enable, Disable],
                &[Special(0xFD), ZeroTorque],
            ),
            // FD packed, then Enable asked for: the refused FD is superseded, FC goes.
            (Some(Disable), &[Enable], &[Special(0xFC), Mit]),
            // FB packed, then Enable and ClearError asked for: FB first again, then FC (FC
            // before FB would reach a motor whose fault is still latched).
            (
                Some(ClearError),
                &[Enable, ClearError],
                &[Special(0xFB), Special(0xFC)],
            ),
        ];
        for (first, asked, expected) in cases {
            let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
            m.update_feedback(&feedback(1, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
                .unwrap();
            let first_bytes = first.map(|sp| {
                m.send_special(sp);
                let bytes = packed(&m, T0);
                assert_eq!(bytes, sp.bytes());
                bytes
            });
            for &sp in asked {
                m.send_special(sp);
            }
            if let Some(bytes) = first_bytes {
                m.frame_refused(
                    &CanFrame::standard(0x01, &bytes).unwrap(),
                    SendError::BusOff,
                );
            }
            for want in expected {
                let got = packed(&m, T0);
                let case = format!("{first:?} then {asked:?}: {want:?}");
                match want {
                    Special(code) => assert_eq!(got, special(*code), "{case}"),
                    ZeroTorque => assert_eq!(got, ZERO_TORQUE_BYTES, "{case}"),
                    Mit => assert_ne!(got[..7], [0xFF; 7], "{case}"),
                }
            }
        }
    }

    #[test]
    fn a_refused_enable_probe_is_not_queued() {
        // A motor that has not answered yet gets an Enable probe (auto-enable); the probe is
        // refused. Once the motor answers, enabled, it gets MIT commands, not a late FC.
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        m.set_target_rpm(10.0).unwrap();
        let probe = (0..PROBE_TICKS)
            .map(|_| packed(&m, T0))
            .find(|bytes| *bytes == special(0xFC));
        assert!(probe.is_some(), "no probe within {PROBE_TICKS} ticks");
        m.frame_refused(
            &CanFrame::standard(0x01, &special(0xFC)).unwrap(),
            SendError::Full,
        );
        m.update_feedback(&feedback(1, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        assert_ne!(packed(&m, T0)[..7], [0xFF; 7]);
    }

    #[test]
    fn a_refused_save_zero_leaves_the_count_as_if_it_was_never_sent() {
        // Two motors read the same positions; only `m` is sent FE, and FE is refused. A
        // reading taken between the packing and the refusal crosses the wrap.
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        let twin = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        let both = |p: u16| {
            for motor in [&m, &twin] {
                motor
                    .update_feedback(&feedback(1, 1, p, 0x7FF, 0x7FF, 30, 30), T0)
                    .unwrap();
            }
        };
        // A wrap forward (+12.49 to −12.49 rad), homed to 100° there, then forward through
        // 0 rad to the +12.5 rad end: at FE the count holds one wrap and the homing was made
        // at one (neither is what clearing leaves).
        both(0xFFF0);
        both(0x0010);
        for motor in [&m, &twin] {
            motor.set_total_angle_here_deg(100.0).unwrap();
            packed(motor, T0);
        }
        both(0x8000);
        both(0xFFF8);
        let before = m.total_angle_deg().unwrap();
        // Refused with no reading in between: nothing changes.
        m.send_special(DmSpecial::SaveZero);
        assert_eq!(packed(&m, T0), special(0xFE));
        m.frame_refused(
            &CanFrame::standard(0x01, &special(0xFE)).unwrap(),
            SendError::Full,
        );
        assert_eq!(m.total_angle_deg(), Some(before));
        assert_eq!(m.angle_deg(), twin.angle_deg());
        // Refused again, with a reading across the wrap in between.
        assert_eq!(packed(&m, T0), special(0xFE));
        both(0x0004); // across the wrap again, forward
        m.frame_refused(
            &CanFrame::standard(0x01, &special(0xFE)).unwrap(),
            SendError::Full,
        );
        let (total, twin_total) = (
            m.total_angle_deg().unwrap(),
            twin.total_angle_deg().unwrap(),
        );
        assert_eq!(total, twin_total);
        // 100° plus the way from 0x0010 round to 0x0004: 65519 codes up to 0xFFFF (+12.5
        // rad), the same point as 0x0000 (−12.5 rad), then 4: 65523 codes of 25/65535 rad.
        let expected = 100.0 + rad_to_deg(65523.0 * 25.0 / 65535.0);
        assert!((total - expected).abs() < 0.01, "{total} vs {expected}");
        assert_eq!(m.angle_deg(), twin.angle_deg());
        // FE goes out on the next tick and clears the count then.
        assert_eq!(packed(&m, T0), special(0xFE));
    }

    #[test]
    fn a_disable_special_keeps_the_motor_limp_until_a_new_target() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        m.update_feedback(&feedback(1, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        m.set_target_torque_nm(2.0).unwrap();
        assert_ne!(packed(&m, T0), ZERO_TORQUE_BYTES);
        m.send_special(DmSpecial::Disable);
        assert_eq!(packed(&m, T0), special(0xFD));
        assert_eq!(m.state().command, 0.0, "no torque went out with FD");
        // The motor reports Disabled (state 0): no automatic Enable, no stiffness.
        m.update_feedback(&feedback(0, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        for _ in 0..2 {
            assert_eq!(packed(&m, T0), ZERO_TORQUE_BYTES);
        }
        assert_eq!(m.state().mode, ControlMode::Disabled);
        m.set_target_rpm(10.0).unwrap();
        assert_eq!(packed(&m, T0), special(0xFC));
    }

    #[test]
    fn save_zero_starts_the_multi_turn_count_afresh() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        // One wrap forward (+12.5 rad end to the −12.5 rad end), then homed to 100°.
        m.update_feedback(&feedback(1, 1, 0xFFF0, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        m.update_feedback(&feedback(1, 1, 0x0010, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        m.set_total_angle_here_deg(100.0).unwrap();
        packed(&m, T0);
        assert!((m.total_angle_deg().unwrap() - 100.0).abs() < 0.01);
        assert!(circle_gap_deg(f64::from(m.angle_deg().unwrap()), 100.0) < 0.01);
        m.send_special(DmSpecial::SaveZero);
        assert_eq!(packed(&m, T0), special(0xFE));
        // The motor now reports about 0 (code 0x7FFF: −0.0002 rad): so does the driver, in the
        // multi-turn total and within a turn (neither the wrap nor the homing is left).
        m.update_feedback(&feedback(1, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        let total = m.total_angle_deg().unwrap();
        assert!(total.abs() < 0.1, "{total}");
        let angle = f64::from(m.angle_deg().unwrap());
        assert!(circle_gap_deg(angle, 0.0) < 0.1, "{angle}");
        assert_eq!(m.set_target_total_angle_deg(0.0), Ok(()));
    }

    #[test]
    fn fault_is_not_auto_cleared_and_special_goes_once() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        m.set_target_rpm(10.0).unwrap();
        m.update_feedback(&feedback(0xA, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        assert_ne!(packed(&m, T0), DmSpecial::Enable.bytes());
        m.send_special(DmSpecial::ClearError);
        assert_eq!(packed(&m, T0), DmSpecial::ClearError.bytes());
        assert_ne!(packed(&m, T0), DmSpecial::ClearError.bytes());
    }

    #[test]
    fn a_motor_back_from_an_outage_in_disabled_is_probed_and_enabled_again() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        let enabled = feedback(1, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30);
        m.update_feedback(&enabled, T0).unwrap();
        m.set_target_torque_nm(5.0).unwrap();
        assert_ne!(packed(&m, T0), ZERO_TORQUE_BYTES);
        // Silent for 100 ms: offline. Zero torque on nine ticks, then an Enable probe (the
        // motor was power-cycled and waits, disabled, for it), and again ten ticks later.
        let mut t = T0 + crate::time::Duration::from_millis(101);
        let mut sent = Vec::new();
        for _ in 0..20 {
            sent.push(packed(&m, t));
            t += crate::time::Duration::from_millis(1);
        }
        assert!(!m.is_online());
        for (i, bytes) in sent.iter().enumerate() {
            let want = if i % 10 == 9 {
                DmSpecial::Enable.bytes()
            } else {
                ZERO_TORQUE_BYTES
            };
            assert_eq!(*bytes, want, "offline tick {i}");
        }
        // It answers, disabled: online, Enable until it reports motor mode, then the target.
        m.update_feedback(&feedback(0, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), t)
            .unwrap();
        assert_eq!(packed(&m, t), DmSpecial::Enable.bytes());
        m.update_feedback(&enabled, t).unwrap();
        // t = 5 N·m → (5 + 10) / 20 · 4095 = 3071.25 → 0xBFF in D6 low nibble and D7.
        let bytes = packed(&m, t);
        assert_eq!((bytes[6] & 0x0F, bytes[7]), (0x0B, 0xFF));
    }

    #[test]
    fn without_auto_enable_a_silent_motor_is_probed_only_for_an_enable_asked_for() {
        let mut cfg = DmConfig::new(0x11);
        cfg.auto_enable = false;
        let m = DmMotor::new(0x01, cfg).unwrap();
        m.set_target_torque_nm(5.0).unwrap();
        for _ in 0..3 * PROBE_TICKS {
            assert_eq!(packed(&m, T0), ZERO_TORQUE_BYTES);
        }
        // The user asks for Enable: it goes out as a probe every 10th tick while the motor
        // is silent, and once more when it answers.
        m.send_special(DmSpecial::Enable);
        for i in 1..=2 * PROBE_TICKS {
            let want = if i % PROBE_TICKS == 0 {
                DmSpecial::Enable.bytes()
            } else {
                ZERO_TORQUE_BYTES
            };
            assert_eq!(packed(&m, T0), want, "tick {i}");
        }
        m.update_feedback(&feedback(0, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        assert_eq!(packed(&m, T0), DmSpecial::Enable.bytes());
        // Sent: no more Enables; still Disabled, so no torque either (no auto-enable).
        m.update_feedback(&feedback(0, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        assert_ne!(packed(&m, T0), DmSpecial::Enable.bytes());
    }

    #[test]
    fn homing_asked_while_offline_waits_for_a_reading_after_the_return() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        report_position(&m, 5.0, T0);
        let later = T0 + crate::time::Duration::from_millis(150);
        packed(&m, later);
        assert!(!m.is_online());
        // "Here is 0", asked while the last reading (5 rad) is stale.
        m.set_total_angle_here_deg(0.0).unwrap();
        packed(&m, later);
        // Back at 0.3 rad (the joint sagged meanwhile): that is where 0 is.
        report_position(&m, 0.3, later);
        packed(&m, later);
        assert!(
            m.total_angle_deg().unwrap().abs() < 0.01,
            "{:?}",
            m.total_angle_deg()
        );
    }

    #[test]
    fn a_total_angle_target_out_of_reach_after_a_restart_holds_instead_of_running_to_the_range_end()
    {
        let m = wrapped_then_offline(MultiTurnOnReturn::Restart);
        // One wrap forward: the reachable range is 12.5–37.5 rad; 1000° = 17.45 rad is in it.
        m.set_target_total_angle_deg(1000.0).unwrap();
        // Power-cycled: back at -1.27 rad with no wraps. 17.45 rad is now beyond +12.5.
        let t = Instant::from_millis(160);
        report_position(&m, -1.27, t);
        let p = packed_position_rad(&packed(&m, t));
        // Held where it is (clamped, the field was 12.5 rad: 13.8 rad, 2.2 turns, away).
        assert!((p + 1.27).abs() < 2e-3, "p = {p}");
        assert_eq!(m.state().target, 1000.0);
        // A load pulls the joint down: the hold stays at -1.27 rad and pulls it back (it does
        // not follow the joint down).
        for sagged in [-1.4, -1.6, -1.8] {
            report_position(&m, sagged, t);
            let p = packed_position_rad(&packed(&m, t));
            assert!((p + 1.27).abs() < 2e-3, "at {sagged}: p = {p}");
        }
        // Another outage: the joint fell to -2.0 rad meanwhile. The hold starts again from
        // where it is back, not from where it was held before.
        let later = t + crate::time::Duration::from_millis(150);
        packed(&m, later);
        assert!(!m.is_online());
        report_position(&m, -2.0, later);
        let p = packed_position_rad(&packed(&m, later));
        assert!((p + 2.0).abs() < 2e-3, "after the return: p = {p}");
        // A target set again within reach is followed.
        m.set_target_total_angle_deg(90.0).unwrap();
        let p = packed_position_rad(&packed(&m, later));
        assert!((p - deg_to_rad(90.0)).abs() < 2e-3, "p = {p}");
    }

    #[test]
    fn a_total_angle_target_just_out_of_reach_holds_too() {
        // One wrap forward (range 12.5–37.5 rad), the target 13.0 rad, then a Restart
        // return at 0.2 rad: the field would be 13.0, half a radian past +12.5.
        let m = wrapped_then_offline(MultiTurnOnReturn::Restart);
        m.set_target_total_angle_deg(rad_to_deg(13.0)).unwrap();
        let t = Instant::from_millis(160);
        report_position(&m, 0.2, t);
        let p = packed_position_rad(&packed(&m, t));
        assert!((p - 0.2).abs() < 2e-3, "p = {p}");
    }

    #[test]
    fn a_total_angle_target_at_the_end_of_the_reported_range_is_reached() {
        // One wrap forward: the range is 12.5–37.5 rad. Its ends, as the driver reports them,
        // go to the field's ends (±12.5 rad in the motor's frame), not into a hold.
        let m = wrapped_then_offline(MultiTurnOnReturn::Continue);
        let t = Instant::from_millis(160);
        // Back close to where it was (-12.496 rad): the wrap stays.
        report_position(&m, -12.0, t);
        let (low, high) = m.total_angle_range_deg();
        assert!((low - rad_to_deg(12.5)).abs() < 0.01, "{low}");
        for (end, field) in [(low, -12.5), (high, 12.5)] {
            m.set_target_total_angle_deg(end).unwrap();
            let p = packed_position_rad(&packed(&m, t));
            assert!((p - field).abs() < 2e-3, "end {end}: p = {p}");
        }
    }

    #[test]
    fn offline_sends_zero_torque() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        m.update_feedback(&feedback(1, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        m.set_target_torque_nm(5.0).unwrap();
        let later = T0 + crate::time::Duration::from_millis(200);
        assert_eq!(packed(&m, later), ZERO_TORQUE_BYTES);
        assert!(!m.is_online());
    }

    #[test]
    fn angle_target_goes_short_way_relative_to_present_position() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        // Present position 0 rad (0x7FFF ≈ -0.0002 rad), target 350°: the short way is -10°.
        m.update_feedback(&feedback(1, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        m.set_target_angle_deg(350.0).unwrap();
        let bytes = packed(&m, T0);
        let p = uint_to_float(
            u32::from(u16::from_be_bytes([bytes[0], bytes[1]])),
            12.5,
            16,
        );
        assert!((p - deg_to_rad(-10.0)).abs() < 1e-3, "p = {p}");
    }

    #[test]
    fn invalid_ids_and_gains_rejected() {
        assert_eq!(
            DmMotor::new(0x11, DmConfig::new(0x11)).unwrap_err(),
            DmError::InvalidId
        );
        let mut cfg = DmConfig::new(0x11);
        cfg.position_kp = 600.0;
        assert_eq!(DmMotor::new(1, cfg).unwrap_err(), DmError::InvalidLimit);
        // 0x7FF is Damiao's parameter channel; 0x7FE is a motor like any other.
        assert_eq!(
            DmMotor::new(0x7FF, DmConfig::new(0x11)).unwrap_err(),
            DmError::InvalidId
        );
        assert!(DmMotor::new(0x7FE, DmConfig::new(0x11)).is_ok());
        // The same for the master ID its feedback comes on.
        assert_eq!(
            DmMotor::new(1, DmConfig::new(0x7FF)).unwrap_err(),
            DmError::InvalidId
        );
        assert!(DmMotor::new(1, DmConfig::new(0x7FE)).is_ok());
        let mut short = DmConfig::new(0x11);
        short.limits.p_max_rad = 3.0; // below π: no equivalent angle inside for some targets
        assert_eq!(DmMotor::new(1, short).unwrap_err(), DmError::InvalidLimit);
        let m = DmMotor::new(1, DmConfig::new(0x11)).unwrap();
        assert_eq!(m.set_target_current(1.0), Err(TargetError::Unsupported));
    }

    /// The MIT position field of a packed command, in rad.
    fn packed_position_rad(bytes: &[u8; 8]) -> f32 {
        uint_to_float(
            u32::from(u16::from_be_bytes([bytes[0], bytes[1]])),
            12.5,
            16,
        )
    }

    /// The raw 16-bit code of a position in rad (default ±12.5 rad range).
    fn position_code(rad: f32) -> u16 {
        float_to_uint(rad, 12.5, 16) as u16
    }

    /// Motor 1, enabled, reports `rad` (default range) at `t`; speed and torque codes at
    /// their middle, 30 °C.
    fn report_position(m: &DmMotor, rad: f32, t: Instant) {
        m.update_feedback(&feedback(1, 1, position_code(rad), 0x7FF, 0x7FF, 30, 30), t)
            .unwrap();
    }

    #[test]
    fn angle_target_across_the_range_end_picks_the_equivalent_angle_inside() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        // The motor reports 12.3 rad, near the +12.5 rad end of its position range.
        report_position(&m, 12.3, T0);
        let here_deg = m.angle_deg().unwrap();
        // 1 rad further on: the short way would be 13.3 rad, beyond the field's range (it
        // would park at 12.5). The same output angle a turn back, 13.3 - 2π = 7.017 rad, is
        // inside.
        m.set_target_angle_deg(here_deg + rad_to_deg(1.0)).unwrap();
        let p = packed_position_rad(&packed(&m, T0));
        assert!((p - (12.3 + 1.0 - TAU)).abs() < 2e-3, "p = {p}");
        // And near the other end, the other way.
        report_position(&m, -12.3, T0);
        let here_deg = m.angle_deg().unwrap();
        m.set_target_angle_deg(here_deg - rad_to_deg(1.0)).unwrap();
        let p = packed_position_rad(&packed(&m, T0));
        assert!((p - (-12.3 - 1.0 + TAU)).abs() < 2e-3, "p = {p}");
    }

    #[test]
    fn total_angle_target_beyond_the_position_range_is_rejected() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        report_position(&m, 0.0, T0);
        m.set_target_total_angle_deg(700.0).unwrap(); // 12.22 rad: inside ±12.5
        let (low, high) = m.total_angle_range_deg();
        assert!((high - rad_to_deg(12.5)).abs() < 0.01 && (low + high).abs() < 0.01);
        assert_eq!(
            m.set_target_total_angle_deg(800.0),
            Err(TargetError::OutOfRange)
        );
        assert_eq!(m.state().target, 700.0); // the previous target stays
        let p = packed_position_rad(&packed(&m, T0));
        assert!((p - deg_to_rad(700.0)).abs() < 2e-3, "p = {p}");
    }

    #[test]
    fn state_is_none_until_the_motor_has_reported() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        let s = m.state();
        assert_eq!(
            (
                s.angle_deg,
                s.total_angle_deg,
                s.temperature_c,
                s.current_amps
            ),
            (None, None, None, None)
        );
        assert_eq!(m.temperatures_c(), (None, None));
        m.update_feedback(&feedback(1, 1, 0x7FFF, 0x7FF, 0x7FF, 40, 55), T0)
            .unwrap();
        assert_eq!(m.state().temperature_c, Some(55.0));
    }

    #[test]
    fn torque_through_the_trait_and_feed_forward_in_speed_mode() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        m.update_feedback(&feedback(1, 1, 0x7FFF, 0x7FF, 0x7FF, 30, 30), T0)
            .unwrap();
        let motor: &dyn Motor = &m;
        motor.set_target_torque_nm(2.5).unwrap();
        assert_eq!(motor.mode(), ControlMode::Torque);
        let expect = MitCommand {
            torque_nm: 2.5,
            ..MitCommand::ZERO_TORQUE
        };
        assert_eq!(packed(&m, T0), expect.pack(&MitLimits::DEFAULT));
        motor.set_feed_forward_torque_nm(-1.0).unwrap();
        motor.set_target_rpm(60.0).unwrap();
        let expect = MitCommand {
            velocity_rad_s: TAU,
            kd: 1.0,
            torque_nm: -1.0,
            ..MitCommand::ZERO_TORQUE
        };
        assert_eq!(packed(&m, T0), expect.pack(&MitLimits::DEFAULT));
        assert_eq!(motor.state().command, -1.0);
    }

    #[test]
    fn homing_shifts_reported_angles_and_targets() {
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        report_position(&m, 2.0, T0);
        m.set_total_angle_here_deg(0.0).unwrap();
        packed(&m, T0); // the tick applies it
        assert!(m.total_angle_deg().unwrap().abs() < 0.01);
        // Total-angle 90° now means 2 rad + π/2 in the motor's own frame.
        m.set_target_total_angle_deg(90.0).unwrap();
        let p = packed_position_rad(&packed(&m, T0));
        assert!(
            (p - (2.0 + core::f32::consts::FRAC_PI_2)).abs() < 2e-3,
            "p = {p}"
        );
    }

    /// The code a DM4310 (default ±12.5 rad, 16 bits) reports at a true multi-turn output
    /// position, truncated as the motor's own float-to-uint does, and the multi-turn position
    /// that code stands for (its field value plus the whole 25 rad wraps), worked in f64.
    fn code_at(total_rad: f64) -> (u16, f64) {
        let wraps = ((total_rad + 12.5) / 25.0).floor();
        let field = total_rad - wraps * 25.0; // [-12.5, 12.5)
        let code = ((field + 12.5) * 65535.0 / 25.0).floor() as u16;
        (code, f64::from(code) * 25.0 / 65535.0 - 12.5 + wraps * 25.0)
    }

    /// How far apart two angles are on the circle, degrees.
    fn circle_gap_deg(a: f64, b: f64) -> f64 {
        let d = (a - b).rem_euclid(360.0);
        d.min(360.0 - d)
    }

    /// Spins `m` from `from_rad` by `turns_rad` (either way) in steps of 5 rad (well under the
    /// 12.5 rad an unwrap can tell apart), calling `check` with the multi-turn position each
    /// reading stands for.
    fn spin(m: &DmMotor, from_rad: f64, turns_rad: f64, mut check: impl FnMut(f64)) -> f64 {
        let steps = (turns_rad.abs() / 5.0).ceil() as u64;
        let mut at = from_rad;
        for k in 1..=steps {
            at = from_rad + turns_rad * k as f64 / steps as f64;
            let (code, reported) = code_at(at);
            m.update_feedback(&feedback(1, 1, code, 0x7FF, 0x7FF, 30, 30), T0)
                .unwrap();
            check(reported);
        }
        at
    }

    #[test]
    fn the_single_turn_angle_stays_exact_over_any_number_of_wraps() {
        // 40 000 wraps of the 25 rad field forward (1 000 000 rad, 159 000 output turns),
        // then 30 000 back. The multi-turn f32 total is 57 million degrees
        // there, 4° between adjacent f32 values: a single-turn angle worked out from it was
        // off by 5°. Worked out from the wraps modulo a turn it stays within the f32
        // resolution of a single turn (the 16-bit field itself resolves 0.022°).
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        let mut worst: f64 = 0.0;
        let mut check = |reported: f64| {
            let expect_deg = reported.rem_euclid(core::f64::consts::TAU).to_degrees();
            let angle = f64::from(m.angle_deg().unwrap());
            assert!((0.0..360.0).contains(&angle), "{angle}");
            worst = worst.max(circle_gap_deg(angle, expect_deg));
        };
        let at = spin(&m, 0.0, 1.0e6, &mut check);
        let end = spin(&m, at, -7.5e5, &mut check);
        assert!(worst < 1e-3, "worst {worst}°");
        // The total stays as close as its f32 can be (values 0.9° apart at 250 000 rad).
        let total = f64::from(m.total_angle_deg().unwrap());
        let (_, reported) = code_at(end);
        assert!((total - reported.to_degrees()).abs() < 1.5, "{total}");
    }

    #[test]
    fn an_angle_target_after_many_wraps_is_sent_as_exactly_as_at_the_start() {
        // After 20 000 wraps forward, angle targets all round the circle: the position field
        // sent is the reading plus the shortest way to the target (worked in f64 from the
        // reading the code stands for), to within one code (25/65535 rad).
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        let at = spin(&m, 0.0, 5.0e5 + 0.3, |_| {});
        let (code, reported) = code_at(at);
        let field = f64::from(code) * 25.0 / 65535.0 - 12.5;
        let here_deg = reported.rem_euclid(core::f64::consts::TAU).to_degrees();
        for target_deg in [0.0f64, 17.0, 90.0, 179.0, 181.0, 270.0, 359.5] {
            m.set_target_angle_deg(target_deg as f32).unwrap();
            let mut way_deg = (target_deg - here_deg).rem_euclid(360.0);
            if way_deg >= 180.0 {
                way_deg -= 360.0;
            }
            let mut expect = field + way_deg.to_radians();
            // Beyond the field's ±12.5 rad: the same angle a turn the other way.
            if expect > 12.5 {
                expect -= core::f64::consts::TAU;
            } else if expect < -12.5 {
                expect += core::f64::consts::TAU;
            }
            let sent = f64::from(packed_position_rad(&packed(&m, T0)));
            assert!(
                (sent - expect).abs() < 25.0 / 65535.0 + 1e-6,
                "target {target_deg}°: sent {sent} rad, expected {expect} rad"
            );
        }
    }

    #[test]
    fn homing_after_many_wraps_holds_its_angle_through_a_restart_return() {
        // Homed to 30° after 12 000 wraps, turned on by 2 rad, then offline and back under
        // `Restart` (the wraps forgotten, the homing offset kept): the single-turn angle is
        // 30° plus the turn since homing, then the homing offset applied to the returning
        // reading alone.
        let mut cfg = DmConfig::new(0x11);
        cfg.health = cfg.health.with_on_return(MultiTurnOnReturn::Restart);
        let m = DmMotor::new(0x01, cfg).unwrap();
        let at = spin(&m, 0.0, 3.0e5 + 1.0, |_| {});
        let (_, homed_at) = code_at(at);
        m.set_total_angle_here_deg(30.0).unwrap();
        m.update(T0, 0.001); // the tick applies it
        let angle = f64::from(m.angle_deg().unwrap());
        assert!(circle_gap_deg(angle, 30.0) < 1e-3, "{angle}");
        // The total is small again, and as exact as a small total can be (not the difference
        // of two f32s near 300 000 rad: 0.42° off), so a total-angle target agrees with it.
        let total = f64::from(m.total_angle_deg().unwrap());
        assert!((total - 30.0).abs() < 1e-3, "{total}");
        let at = spin(&m, at, 2.0, |_| {});
        let (_, now) = code_at(at);
        let expect = 30.0 + (now - homed_at).to_degrees();
        let angle = f64::from(m.angle_deg().unwrap());
        assert!(circle_gap_deg(angle, expect) < 1e-3, "{angle} vs {expect}");
        let total = f64::from(m.total_angle_deg().unwrap());
        assert!((total - expect).abs() < 1e-3, "{total} vs {expect}");
        // Holding 40° by total angle: the field sent is the reading plus the 40° − total way.
        m.set_target_total_angle_deg(40.0).unwrap();
        let field = f64::from(code_at(at).0) * 25.0 / 65535.0 - 12.5;
        let sent = f64::from(packed_position_rad(&packed(&m, T0)));
        let want = field + (40.0 - expect).to_radians();
        assert!(
            (sent - want).abs() < 25.0 / 65535.0 + 1e-6,
            "{sent} vs {want}"
        );

        // Silent past the 100 ms timeout, then back reading code 0x4000 under `Restart`: the
        // total is that field plus the homing offset, 30° − (the position homed at).
        m.update(Instant::from_millis(157), 0.001);
        assert!(!m.is_online());
        let back = f64::from(0x4000u16) * 25.0 / 65535.0 - 12.5;
        m.update_feedback(
            &feedback(1, 1, 0x4000, 0x7FF, 0x7FF, 30, 30),
            Instant::from_millis(160),
        )
        .unwrap();
        let expect = 30.0 + (back - homed_at).to_degrees();
        let angle = f64::from(m.angle_deg().unwrap());
        assert!(circle_gap_deg(angle, expect) < 1e-3, "{angle} vs {expect}");
    }

    #[test]
    fn a_saturated_wrap_count_leaves_the_turn_offset_where_it_is() {
        // At the count's limit (2³¹ wraps: a wrap a second for 68 years) a further wrap is
        // not counted, and the turn offset, which moves only with the count, stays.
        let m = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
        m.state.lock(|cell| {
            let mut s = cell.borrow_mut();
            for (wraps, forward) in [(i32::MAX, true), (i32::MIN, false)] {
                s.wraps = wraps;
                s.turn_offset = TurnFraction(12345);
                s.count_wrap(forward, m.wrap_turn);
                assert_eq!((s.wraps, s.turn_offset), (wraps, TurnFraction(12345)));
                // One short of the limit it still counts, and the offset moves by a wrap.
                s.wraps = if forward { wraps - 1 } else { wraps + 1 };
                s.count_wrap(forward, m.wrap_turn);
                assert_eq!(s.wraps, wraps);
                let moved = if forward {
                    12345u64.wrapping_add(m.wrap_turn.0)
                } else {
                    12345u64.wrapping_sub(m.wrap_turn.0)
                };
                assert_eq!(s.turn_offset, TurnFraction(moved));
            }
        });
        // 25 rad is 3.9789 turns: 0.9789 of a turn in 2⁻⁶⁴ units (to the f64 it is worked in).
        let fraction = m.wrap_turn.0 as f64 / 18_446_744_073_709_551_616.0;
        assert!((fraction - (25.0 / core::f64::consts::TAU - 3.0)).abs() < 1e-15);
    }

    #[test]
    fn bus_usage_declares_the_command_id_and_the_master_id() {
        let m = DmMotor::new(0x03, DmConfig::new(0x13)).unwrap();
        let u = m.bus_usage();
        assert!(u.sends.matches(CanFrame::standard(0x03, &[]).unwrap().id()));
        assert!(
            u.listen
                .matches(CanFrame::standard(0x13, &[]).unwrap().id())
        );
        assert_eq!(
            (u.frames_per_tick, u.feedback_hz, u.replies_per_tick),
            (1, 0, 1)
        );
    }
}
