//! DJI RoboMaster motors: C620 + M3508, C610 + M2006, GM6020 (voltage or current mode).
//!
//! Protocol (DJI user guides; see SPEC.md "Protocol facts"):
//!
//! | model | ESC ids | command ID, slot | command range | feedback ID |
//! |---|---|---|---|---|
//! | C620 + M3508 | 1–8 | 0x200 (ids 1–4) / 0x1FF (5–8), slot `(id-1) % 4` | ±16384 ↔ ±20 A | 0x200 + id |
//! | C610 + M2006 | 1–8 | same as C620 | ±10000 ↔ ±10 A | 0x200 + id |
//! | GM6020 voltage | 1–7 | 0x1FF (1–4) / 0x2FF (5–7) | ±`voltage_raw_limit` (default 25000) | 0x204 + id |
//! | GM6020 current | 1–7 | 0x1FE (1–4) / 0x2FE (5–7) | ±16384 ↔ ±3 A | 0x204 + id |
//!
//! Command slots are int16 big-endian. Feedback (1 kHz, DLC 8): D0–1 rotor angle 0–8191,
//! D2–3 rotor speed rpm (i16), D4–5 torque current (i16, on the current command's scale:
//! ±16384 ↔ ±20 A (C620), ±10000 ↔ ±10 A (C610), ±16384 ↔ ±3 A (GM6020, which reports it on
//! that scale in voltage mode too)), D6
//! temperature °C (not on the C610), all big-endian. Speeds and angles are converted once, on
//! reception, to the output shaft through the exact gear ratio.
//!
//! GM6020 voltage range: the 2018 manual and DJI's examples give ±30000; newer motor firmware
//! is reported (third-party) to saturate at ±25000. rc10 defaults to ±25000, which is safe on
//! both, and lets you raise it up to 30000 ([`DjiConfig::voltage_raw_limit`]). Volts are
//! converted at 30000 ↔ 24 V (the 2018 manual's full scale at the rated supply; derived).
//!
//! Feedback that stops: while the newest frame is more than 3 ms old (three or more lost in a
//! row) the loops hold their integrals ([`Measured::stale`]); after the offline timeout
//! ([`HealthConfig`], 100 ms) the motor is offline and its command is zero. The age is that
//! of the frame's timestamp: a receiver that stamps frames when it reads them makes a backlog
//! read after a stalled receive path look fresh, for the tick or so before newer frames come.
//!
//! Multi-turn counting with frames read late: the ESC sends every 1 ms, so frames are a whole
//! number of periods apart, and the encoder takes the interval the rotor's position and
//! reported speed fit ([`Encoder::update_periodic`]), searched within two periods of the
//! interval the stamps measure and at one period (the first frame of a backlog read after a
//! stalled receive path follows the last one taken, however late its stamp). Each interval
//! is measured from the last frame's arrival as best known: its stamp, or, for a frame read
//! late, where the interval found puts it; so the first frame read on time after a backlog is
//! timed from when the backlog came, not from its late stamps. Known limits: where one period
//! and the stamped interval fit the reading alike (within 1/32 of a turn: an M2006 at 15,000
//! rotor rpm turns once in four periods), the stamped interval is taken, and a frame read
//! late by that much counts a turn wrong; two stalls that each overflow the FIFO within a few
//! periods of each other can put the true interval outside the search.
//!
//! A motor knows its command ID and slot: the bus merges the slots of all registered DJI motors
//! with the same command ID into one frame per tick, and slots no motor uses are sent as zero.
//! Registration rejects two motors that would share a slot or a feedback ID (for example an
//! M3508 with id 5 and a GM6020 with id 1 both answer on 0x205).

use super::cascade::{Cascade, CascadeConfig, Measured};
use super::{ControlMode, HealthConfig, Liveness, Motor, MotorState, TargetError, ThermalLimits};
use crate::can::{CanFrame, IdFilter};
use crate::encoder::{DJI_COUNTS_PER_REV, Encoder, EncoderConfig, GearRatio, Origin};
use crate::node::{BusUsage, CanNode, CommandSlot, FrameError, TxBatch};
use crate::pid::{PidConfig, PidConfigError};
use crate::time::{Duration, Instant};
use core::cell::RefCell;
use core::fmt;
use core::sync::atomic::{AtomicU32, Ordering};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;

/// The largest GM6020 voltage-mode command the protocol defines (2018 manual: ±30000).
const GM6020_MAX_VOLTAGE_RAW: i16 = 30000;

/// DJI ESCs send feedback every millisecond.
const FEEDBACK_PERIOD_US: u64 = 1000;

/// How old the newest feedback may be before the loops count it as stale and hold their
/// integrals ([`Measured::stale`]): three feedback periods. After `n` frames lost in a row
/// the age at a tick is between `n` and `n + 1` periods, so one or two lost frames keep the
/// loops integrating and three or more hold them.
const STALE_AFTER: crate::time::Duration =
    crate::time::Duration::from_micros(3 * FEEDBACK_PERIOD_US);

/// How far after the last tick a feedback timestamp is still trusted for timing.
const TRUST_AHEAD: crate::time::Duration =
    crate::time::Duration::from_micros(2 * FEEDBACK_PERIOD_US);

/// Which DJI motor and ESC, and for the GM6020 which command mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DjiModel {
    /// M3508 P19 with the C620 ESC.
    M3508,
    /// M2006 P36 with the C610 ESC.
    M2006,
    /// GM6020 commanded in voltage (0x1FF / 0x2FF).
    Gm6020Voltage,
    /// GM6020 commanded in current (0x1FE / 0x2FE; needs the motor's current loop enabled in
    /// DJI's RoboMaster Assistant).
    Gm6020Current,
}

impl DjiModel {
    /// Highest ESC id.
    pub const fn max_id(self) -> u8 {
        match self {
            Self::M3508 | Self::M2006 => 8,
            Self::Gm6020Voltage | Self::Gm6020Current => 7,
        }
    }

    /// Gear ratio to the output shaft.
    pub const fn gear(self) -> GearRatio {
        match self {
            Self::M3508 => GearRatio::M3508,
            Self::M2006 => GearRatio::M2006,
            Self::Gm6020Voltage | Self::Gm6020Current => GearRatio::DIRECT,
        }
    }

    /// Feedback ID for ESC `id`.
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "0x204 + a u8 ID is at most 0x303: fits u16"
    )]
    pub const fn feedback_id(self, id: u8) -> u16 {
        match self {
            Self::M3508 | Self::M2006 => 0x200 + id as u16,
            Self::Gm6020Voltage | Self::Gm6020Current => 0x204 + id as u16,
        }
    }

    /// Command frame ID and slot for ESC `id`; `None` if `id` is not in `1..=max_id()`.
    pub const fn command_slot(self, id: u8) -> Option<CommandSlot> {
        let zero_based = match id.checked_sub(1) {
            Some(z) if id <= self.max_id() => z,
            _ => return None,
        };
        let (low, high) = match self {
            Self::M3508 | Self::M2006 => (0x200, 0x1FF),
            Self::Gm6020Voltage => (0x1FF, 0x2FF),
            Self::Gm6020Current => (0x1FE, 0x2FE),
        };
        CommandSlot::new(if zero_based < 4 { low } else { high }, zero_based % 4)
    }

    /// Command units (amps, or volts in voltage mode) per raw count: the raw full scale and
    /// the physical value it stands for.
    const fn raw_full_scale(self) -> (f32, f32) {
        match self {
            Self::M3508 => (16384.0, 20.0),
            Self::M2006 => (10000.0, 10.0),
            Self::Gm6020Current => (16384.0, 3.0),
            Self::Gm6020Voltage => (30000.0, 24.0),
        }
    }

    /// Torque per amp of torque current at the output shaft, in N·m/A (DJI user guides:
    /// M3508 0.3, M2006 0.18, GM6020 0.741). The M3508's manual curve saturates near
    /// 0.25 N·m/A effective (gear losses): torque targets are nominal, not measured.
    pub const fn torque_constant_nm_per_amp(self) -> f32 {
        match self {
            Self::M3508 => 0.3,
            Self::M2006 => 0.18,
            Self::Gm6020Voltage | Self::Gm6020Current => 0.741,
        }
    }

    /// Volts per N·m a GM6020 in voltage mode makes at standstill, from its published
    /// torque–speed line (GM6020 user guide: at 24 V, 320 rpm with no load and 156 rpm less per
    /// N·m): the line reaches 0 rpm at 320 / 156 = 2.05 N·m, so 24 V holds 2.05 N·m and a
    /// torque takes `τ · 24 · 156 / 320` = 11.7 V/(N·m). Used to turn a feed-forward torque into
    /// volts. Derived from published figures, not measured on a motor: the guide's 1.8 Ω
    /// phase resistance with its 0.741 N·m/A would give 2.4 V/(N·m) instead (a stall torque
    /// at 24 V of 9.9 N·m, which the published curve does not show), and the two cannot both
    /// hold. The torque–speed line describes the motor with its driver, as the command drives
    /// it; the simulator's plant uses the same line. To check it on a motor, hold the shaft
    /// and compare the volts commanded with the torque current it reports (D4–5): about
    /// 8.7 Ω (11.7 V/(N·m) · 0.741 N·m/A) confirms it. The volts assume the rated 24 V supply
    /// behind the 30000 ↔ 24 V scale: on a battery a few volts off, the speed loop's integral
    /// makes up the difference.
    const GM6020_STANDSTILL_VOLTS_PER_NM: f32 = 24.0 * 156.0 / 320.0;

    /// Whether the ESC reports temperature in D6.
    pub const fn reports_temperature(self) -> bool {
        !matches!(self, Self::M2006)
    }

    /// Whether the command is a voltage (else a current).
    pub const fn is_voltage_mode(self) -> bool {
        matches!(self, Self::Gm6020Voltage)
    }

    /// The ESC's own command limit in amps (volts in voltage mode at the default raw limit).
    pub const fn max_command(self) -> f32 {
        match self {
            Self::M3508 => 20.0,
            Self::M2006 => 10.0,
            Self::Gm6020Current => 3.0,
            Self::Gm6020Voltage => 20.0, // 25000 raw at 30000 ↔ 24 V
        }
    }
}

/// Configuration of a DJI motor.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DjiConfig {
    /// Speed and angle loops.
    pub cascade: CascadeConfig,
    /// Offline timeout, multi-turn policy and thermal limits. Default: 100 ms, and every
    /// model continues counting when its feedback returns
    /// ([`MultiTurnOnReturn::Continue`](super::MultiTurnOnReturn::Continue): right when the
    /// output moved less than half a turn while the motor was off, as in a referee power
    /// cut). A GM6020 gimbal whose yaw stays within ±180° of its zero but may be turned
    /// further by hand while unpowered can use
    /// [`MultiTurnOnReturn::Restart`](super::MultiTurnOnReturn::Restart): it then reads its
    /// absolute angle on return. Not for a yaw range wider than ±180° (a homed ±270° yaw at
    /// 200° would come back reading −160°) or a slip-ring yaw holding a multi-turn target (it
    /// would unwind the turns).
    pub health: HealthConfig,
    /// GM6020 voltage mode: the largest raw command sent (default 25000; ±30000 on 2018
    /// firmware); must be within 1–30000, the protocol's range. Ignored by the other models.
    /// When raising it, raise the speed loop's `output_limit` (volts, 30000 ↔ 24 V) too, or
    /// the loop never asks for more.
    pub voltage_raw_limit: i16,
    /// Where the multi-turn angle starts. Default: power-on for the geared M3508 and M2006
    /// (their rotor angle says nothing about the output's position), absolute with zero
    /// offset 0 for the direct-drive GM6020, so a gimbal's zero does not move with power-on
    /// (set `zero_offset_counts` to the raw count of your mechanism's zero).
    pub origin: Origin,
}

/// Default gains, tuned against the physical plants in rc10-sim: speed steps for the M3508
/// and M2006, a 0.01 kg·m² gimbal for the GM6020 (a bare GM6020 is too fast for any 1 kHz loop
/// with a millisecond of feedback delay; it is always used with a load).
impl DjiConfig {
    /// Defaults for `model`: speed loop with the ESC's full command range, angle loop limited
    /// to a speed the motor reaches, angle loop every 10th tick (RC10_LIB), thermal derating
    /// from 100 °C to cut-off at 120 °C where a temperature is reported (C620 and GM6020 cut
    /// at 125 °C themselves).
    pub const fn default_for(model: DjiModel) -> Self {
        let (speed, angle) = match model {
            // Amps per rpm at the output; rpm per degree.
            // Tuned in rc10-sim (`m3508-speed-step`): 0 → 300 rpm rises at the full-current
            // minimum, 0.5 % overshoot, settles in 49 ms.
            DjiModel::M3508 => (
                PidConfig::new(0.6, 8.0, 0.0),
                PidConfig::new(8.0, 0.0, 0.0).with_output_limit(400.0),
            ),
            // Tuned in rc10-sim (`m2006-speed-step`): rises at the full-current minimum,
            // no visible overshoot, settles in 81 ms.
            DjiModel::M2006 => (
                PidConfig::new(0.5, 4.0, 0.0),
                PidConfig::new(8.0, 0.0, 0.0).with_output_limit(400.0),
            ),
            // Volts per rpm. Tuned in rc10-sim (`gm6020-gimbal`, 0.01 kg·m² load): a 90° step
            // with no overshoot, ±1.1° under a 0.5 N·m load step.
            DjiModel::Gm6020Voltage => (
                PidConfig::new(0.8, 20.0, 0.0),
                PidConfig::new(3.0, 0.0, 0.0).with_output_limit(250.0),
            ),
            // Amps per rpm. Tuned in rc10-sim on the same gimbal: no overshoot, ±0.6° under
            // the load step.
            DjiModel::Gm6020Current => (
                PidConfig::new(0.15, 5.0, 0.0),
                PidConfig::new(3.0, 0.0, 0.0).with_output_limit(250.0),
            ),
        };
        let thermal = if model.reports_temperature() {
            Some(ThermalLimits {
                derate_start_c: 100.0,
                cutoff_c: 120.0,
            })
        } else {
            None
        };
        Self {
            cascade: CascadeConfig {
                speed: speed.with_output_limit(model.max_command()),
                angle,
                angle_divider: 10,
            },
            health: HealthConfig::DEFAULT.with_thermal(thermal),
            voltage_raw_limit: 25000,
            origin: match model {
                DjiModel::M3508 | DjiModel::M2006 => Origin::PowerOn,
                DjiModel::Gm6020Voltage | DjiModel::Gm6020Current => Origin::Absolute {
                    zero_offset_counts: 0,
                },
            },
        }
    }
}

/// Why a DJI motor could not be created.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DjiError {
    /// The ESC id is outside `1..=max` for this model.
    IdOutOfRange {
        /// The id given.
        id: u8,
        /// The model's highest id.
        max: u8,
    },
    /// A loop configuration cannot work.
    Pid(PidConfigError),
    /// The encoder origin's zero offset is not below 8192.
    InvalidOrigin,
    /// Thermal limits that are not finite or where derating does not start below the cut-off.
    InvalidThermal,
    /// A GM6020 voltage-mode raw limit that is not positive (it would silence the motor) or
    /// is above 30000, the protocol's largest command (±30000 ↔ ±24 V).
    InvalidVoltageLimit,
}

impl fmt::Display for DjiError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::IdOutOfRange { id, max } => write!(f, "DJI ESC id {id} not in 1..={max}"),
            Self::Pid(e) => write!(f, "DJI motor loop: {e}"),
            Self::InvalidOrigin => f.write_str("DJI encoder zero offset not below 8192"),
            Self::InvalidThermal => {
                f.write_str("DJI thermal limits not finite or derating not below cut-off")
            }
            Self::InvalidVoltageLimit => f.write_str("GM6020 voltage raw limit not within 1-30000"),
        }
    }
}

impl core::error::Error for DjiError {}

#[derive(Debug)]
struct DjiState {
    cascade: Cascade,
    encoder: Encoder,
    rotor_rpm: i16,
    /// The last accepted frame's 8 data bytes; all ones (an angle of 0xFFFF, which no valid
    /// frame has) before the first and after going offline.
    last_data: u64,
    speed_rpm: f32,
    current_amps: Option<f32>,
    temperature_c: Option<f32>,
    liveness: Liveness,
    awaiting_return: bool,
    /// The thermal derating factor for `temperature_c` (1 without limits or a reading),
    /// computed when a frame brings a new temperature, not on every tick.
    derate: f32,
    /// A user limit on the command (amps, or volts in voltage mode); infinity for none.
    user_limit: f32,
    /// The limit in force: the ESC's range, derated, and the user's limit if lower.
    /// Recomputed when `derate` or `user_limit` changes, not on every tick.
    limit: f32,
    /// Live-tuning and homing requests, applied by the next tick.
    pending_speed: Option<PidConfig>,
    pending_angle: Option<PidConfig>,
    pending_home_deg: Option<f32>,
    /// Whether any of the three requests above is set: the tick looks at this one flag.
    pending: bool,
    /// The time of the last tick: feedback stamped well after it is not trusted for timing.
    last_tick: Option<Instant>,
    /// How long before its stamp (the liveness record's newest) the last frame taken arrived,
    /// as best known, µs (see [`arrival_lag_us`]); the next frame's interval is measured from
    /// that arrival. 0 for a frame read on time.
    arrival_lag_us: u32,
}

/// How long before its stamp a frame arrived, as best known, µs: `since_arrival_us` after
/// the last frame's estimated arrival and `since_newest_us` after that frame's stamp, it came
/// `periods` feedback periods after it. Stamped more than half a period after where that
/// interval puts it, and not `periods` (give or take half a period) after the last frame's
/// stamp, it was read late (a backlog after a stalled receive path; an untrusted stamp): it
/// came where the interval puts it, and the next frame is timed from there, not from the late
/// stamp. Otherwise its stamp is the best estimate (0); a stamp read at the ESC's pace also
/// ends an estimate that a wrong interval left behind.
fn arrival_lag_us(since_arrival_us: u32, since_newest_us: u32, periods: u32) -> u32 {
    const PERIOD_US: u32 = FEEDBACK_PERIOD_US as u32;
    // At most 4·10^6 periods (`Encoder::update_periodic` returns at most 10^6 + 2), so the
    // interval and half a period more stay below 2^32 and the plain arithmetic is exact.
    let interval_us = periods.min(4_000_000).wrapping_mul(PERIOD_US);
    let late = since_arrival_us > interval_us.wrapping_add(PERIOD_US / 2);
    let paced = since_newest_us.abs_diff(interval_us) <= PERIOD_US / 2;
    if late && !paced {
        since_arrival_us.wrapping_sub(interval_us) // > interval_us: late
    } else {
        0
    }
}

/// The limit in force: the ESC's `range`, derated, and the user's limit if lower.
const fn limit_in_force(range: f32, derate: f32, user_limit: f32) -> f32 {
    let derated = range * derate;
    if user_limit < derated {
        user_limit
    } else {
        derated
    }
}

impl DjiState {
    /// Records a request for the next tick (`set` stores it).
    fn request(&mut self, set: impl FnOnce(&mut Self)) {
        set(self);
        self.pending = true;
    }

    /// Applies live-tuning requests recorded since the last tick (validated when recorded).
    #[cold]
    #[inline(never)]
    fn apply_pending_configs(&mut self) {
        if let Some(speed) = self.pending_speed.take() {
            let _ = self.cascade.set_speed_config(speed);
        }
        if let Some(angle) = self.pending_angle.take() {
            let _ = self.cascade.set_angle_config(angle);
        }
        self.pending = self.pending_home_deg.is_some();
    }

    /// Applies a homing request, once the encoder has a reading (else it waits for the next
    /// tick).
    #[cold]
    #[inline(never)]
    fn apply_pending_home(&mut self) {
        if let Some(deg) = self.pending_home_deg.take() {
            if self.encoder.set_total_angle_deg(deg) {
                // The angles jump, the shaft does not move.
                self.cascade.angle_origin_moved();
            } else {
                self.pending_home_deg = Some(deg); // no reading yet: try again next tick
            }
        }
        self.pending = self.pending_home_deg.is_some();
    }
}

/// A DJI motor on a CAN bus: [`CanNode`] for the scheduler, [`Motor`] for the application.
///
/// Create it once, place it in a `static` (or a `StaticCell`), register it on its bus and set
/// targets from any task:
///
/// ```
/// use rc10_core::motor::Motor;
/// use rc10_core::motor::dji::DjiMotor;
///
/// // Invalid ids are a compile-time error in a static.
/// static WHEEL_1: DjiMotor = match DjiMotor::m3508(1) {
///     Ok(m) => m,
///     Err(_) => panic!("bad M3508 id"),
/// };
///
/// WHEEL_1.set_target_rpm(300.0).unwrap();
/// assert!(WHEEL_1.set_target_rpm(f32::NAN).is_err());
/// assert!(!WHEEL_1.is_online()); // no feedback yet: the command stays zero
/// ```
pub struct DjiMotor {
    model: DjiModel,
    esc_id: u8,
    slot: CommandSlot,
    config: DjiConfig,
    /// [`command_limit`](Self::command_limit), computed once.
    limit: f32,
    /// Raw counts per command unit, and the largest raw value sent (derived from the model
    /// and the configuration, so packing a command multiplies and compares, no more).
    raw_per_unit: f32,
    raw_limit: f32,
    /// The command of the last tick (f32 bits; amps, or volts in voltage mode): written by
    /// `update` and read by `pack_command` in the same scheduler task, and by `state()`.
    command: AtomicU32,
    state: Mutex<CriticalSectionRawMutex, RefCell<DjiState>>,
}

impl DjiMotor {
    /// A motor of `model` with ESC id `esc_id` and the given configuration.
    pub const fn new(model: DjiModel, esc_id: u8, config: DjiConfig) -> Result<Self, DjiError> {
        let max = model.max_id();
        let Some(slot) = model.command_slot(esc_id) else {
            return Err(DjiError::IdOutOfRange { id: esc_id, max });
        };
        if model.is_voltage_mode()
            && !(config.voltage_raw_limit > 0 && config.voltage_raw_limit <= GM6020_MAX_VOLTAGE_RAW)
        {
            return Err(DjiError::InvalidVoltageLimit);
        }
        if let Some(t) = config.health.thermal
            && !(t.derate_start_c.is_finite()
                && t.cutoff_c.is_finite()
                && t.derate_start_c < t.cutoff_c)
        {
            return Err(DjiError::InvalidThermal);
        }
        let cascade = match Cascade::new(config.cascade) {
            Ok(c) => c,
            Err(e) => return Err(DjiError::Pid(e)),
        };
        let encoder =
            match Encoder::new(EncoderConfig::dji(model.gear()).with_origin(config.origin)) {
                Some(e) => e,
                None => return Err(DjiError::InvalidOrigin),
            };
        let (raw_fs, unit_fs) = model.raw_full_scale();
        let raw_per_unit = raw_fs / unit_fs;
        let raw_limit = if model.is_voltage_mode() {
            config.voltage_raw_limit as f32
        } else {
            raw_fs
        };
        Ok(Self {
            model,
            esc_id,
            slot,
            config,
            limit: raw_limit / raw_per_unit,
            raw_per_unit,
            raw_limit,
            command: AtomicU32::new(0),
            state: Mutex::new(RefCell::new(DjiState {
                cascade,
                encoder,
                rotor_rpm: 0,
                last_data: u64::MAX,
                speed_rpm: 0.0,
                current_amps: None,
                temperature_c: None,
                liveness: Liveness::NEW,
                awaiting_return: false,
                derate: 1.0,
                user_limit: f32::INFINITY,
                limit: limit_in_force(raw_limit / raw_per_unit, 1.0, f32::INFINITY),
                pending_speed: None,
                pending_angle: None,
                pending_home_deg: None,
                pending: false,
                last_tick: None,
                arrival_lag_us: 0,
            })),
        })
    }

    /// An M3508 (C620) with default configuration.
    pub const fn m3508(esc_id: u8) -> Result<Self, DjiError> {
        Self::new(
            DjiModel::M3508,
            esc_id,
            DjiConfig::default_for(DjiModel::M3508),
        )
    }

    /// An M2006 (C610) with default configuration.
    pub const fn m2006(esc_id: u8) -> Result<Self, DjiError> {
        Self::new(
            DjiModel::M2006,
            esc_id,
            DjiConfig::default_for(DjiModel::M2006),
        )
    }

    /// A GM6020 in voltage mode with default configuration.
    pub const fn gm6020_voltage(esc_id: u8) -> Result<Self, DjiError> {
        let model = DjiModel::Gm6020Voltage;
        Self::new(model, esc_id, DjiConfig::default_for(model))
    }

    /// A GM6020 in current mode with default configuration.
    pub const fn gm6020_current(esc_id: u8) -> Result<Self, DjiError> {
        let model = DjiModel::Gm6020Current;
        Self::new(model, esc_id, DjiConfig::default_for(model))
    }

    /// The model.
    pub const fn model(&self) -> DjiModel {
        self.model
    }

    /// The ESC id (1–8, GM6020 1–7).
    pub const fn esc_id(&self) -> u8 {
        self.esc_id
    }

    /// The configuration.
    pub const fn config(&self) -> &DjiConfig {
        &self.config
    }

    /// The command frame ID and slot this motor writes.
    pub const fn command_slot(&self) -> CommandSlot {
        self.slot
    }

    /// The speed loop's last per-term output (for tuning and telemetry).
    pub fn speed_loop_terms(&self) -> crate::pid::PidTerms {
        self.state.lock(|s| s.borrow().cascade.speed_terms())
    }

    /// The angle loop's last per-term output in rpm (for tuning and telemetry): from the last
    /// tick that ran it (every `angle_divider`th in angle modes).
    pub fn angle_loop_terms(&self) -> crate::pid::PidTerms {
        self.state.lock(|s| s.borrow().cascade.angle_terms())
    }

    /// Replaces the speed loop's gains and limits while running (live tuning), from the next
    /// tick; the integral is kept. Its `output_limit` (amps, volts in voltage mode) is the
    /// loop's own limit; the ESC's range and [`Motor::set_current_limit_amps`] still apply.
    pub fn set_speed_pid(&self, config: PidConfig) -> Result<(), PidConfigError> {
        config.validate()?;
        self.state
            .lock(|s| s.borrow_mut().request(|s| s.pending_speed = Some(config)));
        Ok(())
    }

    /// Replaces the angle loop's gains (degrees in, rpm out) while running, from the next tick.
    pub fn set_angle_pid(&self, config: PidConfig) -> Result<(), PidConfigError> {
        config.validate()?;
        self.state
            .lock(|s| s.borrow_mut().request(|s| s.pending_angle = Some(config)));
        Ok(())
    }

    /// Sets the feed-forward in the command unit (amps, or volts in voltage mode), added by the
    /// speed loop in speed and angle modes. See also [`Motor::set_feed_forward_torque_nm`].
    pub fn set_feed_forward(&self, command: f32) -> Result<(), TargetError> {
        if !command.is_finite() {
            return Err(TargetError::NotFinite);
        }
        self.state
            .lock(|s| s.borrow_mut().cascade.set_feed_forward(command));
        Ok(())
    }

    /// Commands raw ESC counts, as DJI's examples do (GM6020 voltage mode: ±25000 by default;
    /// C620: ±16384 ↔ ±20 A). Converted exactly to the command unit, so the same count goes
    /// out on the wire (clamped to the range in force).
    pub fn set_target_raw(&self, counts: i16) -> Result<(), TargetError> {
        let (raw_fs, unit_fs) = self.model.raw_full_scale();
        let value = f32::from(counts) * (unit_fs / raw_fs);
        let mode = if self.model.is_voltage_mode() {
            ControlMode::Voltage
        } else {
            ControlMode::Current
        };
        self.set(mode, value)
    }

    /// GM6020 voltage mode: limits the command to `volts` from the next tick (the raw limit
    /// still applies on top). Other models: [`TargetError::Unsupported`] (use
    /// [`Motor::set_current_limit_amps`]).
    pub fn set_voltage_limit_volts(&self, volts: f32) -> Result<(), TargetError> {
        if !self.model.is_voltage_mode() {
            return Err(TargetError::Unsupported);
        }
        self.set_user_limit(volts)
    }

    fn set_user_limit(&self, limit: f32) -> Result<(), TargetError> {
        if limit.is_nan() {
            return Err(TargetError::NotFinite);
        }
        if limit < 0.0 {
            return Err(TargetError::OutOfRange);
        }
        self.state.lock(|s| {
            let mut s = s.borrow_mut();
            s.user_limit = limit;
            s.limit = limit_in_force(self.limit, s.derate, limit);
        });
        Ok(())
    }

    /// The largest command this motor sends, in amps (volts in voltage mode): the ESC's range,
    /// or for the GM6020 in voltage mode the configured [`DjiConfig::voltage_raw_limit`].
    pub fn command_limit(&self) -> f32 {
        self.limit
    }

    /// Converts a command (amps, or volts in voltage mode) to the raw slot value, clamped to
    /// the ESC's range before the integer conversion (no wrap, no sign flip).
    pub fn command_to_raw(&self, command: f32) -> i16 {
        let lim = self.raw_limit;
        let raw = command * self.raw_per_unit;
        // A NaN passes both comparisons and becomes 0 in the conversion below.
        let raw = if raw > lim {
            lim
        } else if raw < -lim {
            -lim
        } else {
            raw
        };
        // Rounded half away from zero without the `roundf` library call (NaN becomes 0):
        // |raw| ≤ 32767, so the rounding is exact and so is the i16 it narrows to.
        crate::math::round_i32(raw) as i16
    }

    fn store_command(&self, command: f32) {
        self.command.store(command.to_bits(), Ordering::Relaxed);
    }

    fn stored_command(&self) -> f32 {
        f32::from_bits(self.command.load(Ordering::Relaxed))
    }

    fn set(&self, mode: ControlMode, target: f32) -> Result<(), TargetError> {
        if !target.is_finite() {
            return Err(TargetError::NotFinite);
        }
        self.state
            .lock(|s| s.borrow_mut().cascade.set_target(mode, target));
        Ok(())
    }

    fn parse(&self, s: &mut DjiState, frame: &CanFrame, now: Instant) -> Result<(), FrameError> {
        let d = frame.data8().ok_or(FrameError::WrongLength {
            dlc: frame.dlc() as u8,
        })?;
        let raw_angle = u16::from_be_bytes([d[0], d[1]]);
        let rotor_rpm = i16::from_be_bytes([d[2], d[3]]);
        let raw_current = i16::from_be_bytes([d[4], d[5]]);
        if raw_angle >= DJI_COUNTS_PER_REV {
            return Err(FrameError::OutOfRange);
        }
        // A frame stamped before the newest one taken (a transport that stamps frames itself
        // and hands one over late) is older than the state: unwrapping it against the newer
        // reading could count a turn. (A far-future stamp is clamped to the tick's time at
        // the next tick, so it holds frames back for at most a tick.)
        let since_newest_us = match s.liveness.last_feedback() {
            // Saturates beyond 2^32 µs (71 min): the offline timeout is long past.
            Some(newest) => match now.checked_duration_since(newest) {
                Some(since) => Some(u32::try_from(since.as_micros()).unwrap_or(u32::MAX)),
                None => return Err(FrameError::OutOfOrder),
            },
            None => None,
        };
        // Since the last frame's arrival as best known.
        let since_arrival_us = since_newest_us.map(|us| us.saturating_add(s.arrival_lag_us));
        // The same 8 bytes as the last frame: a copy (CAN repeats a frame when an error hits
        // its last bit), whenever it was read, or a motor at rest reporting the same again.
        // Nothing changes but the time. Unwrapping a copy at speed could count a turn: three
        // M2006 periods at 17 000 rotor rpm are 0.85 of one. (Going offline forgets the last
        // frame, so that after an outage the return policy applies first.)
        let data = u64::from_ne_bytes(*d);
        if data == s.last_data {
            // A copy read more than half a period after the last frame is taken as the next
            // frame of a motor at rest, one period on (a repeat read late within a backlog
            // then puts the estimate a period late, which the encoder's window absorbs).
            if let (Some(newest_us), Some(arrival_us)) = (since_newest_us, since_arrival_us) {
                s.arrival_lag_us = if newest_us > FEEDBACK_PERIOD_US as u32 / 2 {
                    arrival_lag_us(arrival_us, newest_us, 1)
                } else {
                    arrival_us // the same arrival, a newer stamp
                };
            }
            s.liveness.record_feedback_in_order(now);
            return Ok(());
        }
        s.last_data = data;
        if s.awaiting_return {
            if self.config.health.on_return == super::MultiTurnOnReturn::Restart {
                s.encoder.reset();
            }
            s.awaiting_return = false;
            // Back from an outage: no trustworthy speed history; the return policy applies.
            s.encoder
                .update(raw_angle)
                .map_err(|_| FrameError::OutOfRange)?;
            s.arrival_lag_us = 0;
        } else {
            // Multi-turn counting that survives lost frames at full speed: the ESC sends every
            // 1 ms, so the frames were a whole number of periods apart; the mean reported rotor
            // speed says how far the rotor went in each candidate interval, and the encoder
            // takes the one the reading fits (see `Encoder::update_periodic`). The timestamps
            // only centre the search, as they may be read late. A stamp more than two periods
            // after the last tick is not trusted at all (a bogus or far-future stamp): the
            // interval is then taken as one period.
            let trusted = s
                .last_tick
                .is_none_or(|tick| now.saturating_duration_since(tick) <= TRUST_AHEAD);
            // Measured from the last frame's arrival as best known.
            let gap_periods = match since_arrival_us {
                Some(us) if trusted => us as f32 * (1.0 / FEEDBACK_PERIOD_US as f32),
                _ => 1.0,
            };
            let mean_rotor_rpm = (f32::from(s.rotor_rpm) + f32::from(rotor_rpm)) * 0.5;
            // rpm · 8192 counts/turn · 1000 µs / (60 s/min · 10⁶ µs/s)
            let counts_per_period = mean_rotor_rpm
                * (f32::from(DJI_COUNTS_PER_REV) * FEEDBACK_PERIOD_US as f32 / 60.0e6);
            let periods = s
                .encoder
                .update_periodic(raw_angle, counts_per_period, gap_periods)
                .map_err(|_| FrameError::OutOfRange)?;
            s.arrival_lag_us = match (since_arrival_us, since_newest_us) {
                (Some(arrival_us), Some(newest_us)) => {
                    arrival_lag_us(arrival_us, newest_us, periods)
                }
                _ => 0,
            };
        }
        s.rotor_rpm = rotor_rpm;
        s.speed_rpm = f32::from(rotor_rpm) / self.model.gear().as_f32();
        let (raw_fs, unit_fs) = self.model.raw_full_scale();
        s.current_amps = Some(if self.model.is_voltage_mode() {
            // Voltage-mode GM6020 reports torque current on the current-mode scale.
            f32::from(raw_current) * (3.0 / 16384.0)
        } else {
            f32::from(raw_current) * (unit_fs / raw_fs)
        });
        if self.model.reports_temperature() {
            let celsius = f32::from(d[6]);
            if s.temperature_c != Some(celsius) {
                s.temperature_c = Some(celsius);
                s.derate = match self.config.health.thermal {
                    Some(limits) => limits.derating(celsius),
                    None => 1.0,
                };
                s.limit = limit_in_force(self.limit, s.derate, s.user_limit);
            }
        }
        s.liveness.record_feedback_in_order(now);
        Ok(())
    }
}

impl CanNode for DjiMotor {
    fn bus_usage(&self) -> BusUsage {
        BusUsage::NONE
            .listening(
                IdFilter::standard(self.model.feedback_id(self.esc_id)),
                1000,
            )
            .with_slot(self.slot)
    }

    fn matches_frame(&self, frame: &CanFrame) -> bool {
        !frame.is_extended() && frame.raw_id() == u32::from(self.model.feedback_id(self.esc_id))
    }

    fn update_feedback(&self, frame: &CanFrame, now: Instant) -> Result<(), FrameError> {
        self.state
            .lock(|s| self.parse(&mut s.borrow_mut(), frame, now))
    }

    fn update(&self, now: Instant, dt_s: f32) {
        let health = &self.config.health;
        self.state.lock(|cell| {
            let mut s = cell.borrow_mut();
            s.last_tick = Some(now);
            // Requests recorded by the setters since the last tick (validated there).
            // `is_some` first: taking a large `Option` copies it even when it is `None`.
            if s.pending {
                s.apply_pending_configs();
            }
            let (went_offline, stale, ahead) =
                s.liveness.check_staleness_clamped(health, now, STALE_AFTER);
            if ahead != 0 {
                // The newest stamp was after `now` and is pulled back to it: the estimated
                // arrival stays where it was (the lag is measured from that stamp), so that
                // a far-future stamp does not put the next frame's gap as far out.
                let ahead_us = Duration::from_ticks(ahead).as_micros();
                let ahead_us = u32::try_from(ahead_us).unwrap_or(u32::MAX);
                s.arrival_lag_us = s.arrival_lag_us.saturating_sub(ahead_us);
            }
            if went_offline {
                s.awaiting_return = true;
                s.last_data = u64::MAX;
                s.cascade.reset();
            }
            if !s.liveness.is_online() {
                self.store_command(0.0);
                return;
            }
            if s.pending {
                s.apply_pending_home();
            }
            let limit = s.limit;
            // Angles cost a 64-bit division; only the ticks that run the angle loop read them.
            let angles = s.cascade.angle_loop_due();
            let (angle_deg, total_angle_deg) = if angles {
                s.encoder.angles_deg()
            } else {
                (0.0, 0.0)
            };
            let measured = Measured {
                speed_rpm: s.speed_rpm,
                angle_deg,
                total_angle_deg,
                stale,
            };
            // `step` already keeps the command within `limit`.
            self.store_command(s.cascade.step(&measured, dt_s, limit));
        });
    }

    fn pack_command(&self, out: &mut TxBatch) {
        out.write_slot(self.slot, self.command_to_raw(self.stored_command()));
    }
}

impl Motor for DjiMotor {
    fn set_target_current(&self, amps: f32) -> Result<(), TargetError> {
        if self.model.is_voltage_mode() {
            return Err(TargetError::Unsupported);
        }
        self.set(ControlMode::Current, amps)
    }

    fn set_target_voltage(&self, volts: f32) -> Result<(), TargetError> {
        if !self.model.is_voltage_mode() {
            return Err(TargetError::Unsupported);
        }
        self.set(ControlMode::Voltage, volts)
    }

    fn set_target_rpm(&self, rpm: f32) -> Result<(), TargetError> {
        self.set(ControlMode::Speed, rpm)
    }

    fn set_target_angle_deg(&self, angle_deg: f32) -> Result<(), TargetError> {
        self.set(ControlMode::Angle, angle_deg)
    }

    fn set_target_total_angle_deg(&self, angle_deg: f32) -> Result<(), TargetError> {
        self.set(ControlMode::TotalAngle, angle_deg)
    }

    /// Current-mode ESCs: amps = N·m / [`DjiModel::torque_constant_nm_per_amp`] (mode reads
    /// [`ControlMode::Current`]). Voltage mode: [`TargetError::Unsupported`] (a voltage is
    /// not a torque once the motor turns).
    fn set_target_torque_nm(&self, torque_nm: f32) -> Result<(), TargetError> {
        if !torque_nm.is_finite() {
            return Err(TargetError::NotFinite);
        }
        self.set_target_current(torque_nm / self.model.torque_constant_nm_per_amp())
    }

    /// Current-mode ESCs: through the torque constant, in amps. GM6020 in voltage mode: the
    /// voltage that makes that torque at standstill on the motor's published torque–speed
    /// line, 11.7 V per N·m (24 V holds 320 / 156 = 2.05 N·m), right for holding a gimbal
    /// pitch against gravity.
    fn set_feed_forward_torque_nm(&self, torque_nm: f32) -> Result<(), TargetError> {
        let command = if self.model.is_voltage_mode() {
            torque_nm * DjiModel::GM6020_STANDSTILL_VOLTS_PER_NM
        } else {
            torque_nm / self.model.torque_constant_nm_per_amp()
        };
        self.set_feed_forward(command)
    }

    /// Current-mode ESCs only (GM6020 in voltage mode:
    /// [`set_voltage_limit_volts`](DjiMotor::set_voltage_limit_volts)).
    fn set_current_limit_amps(&self, amps: f32) -> Result<(), TargetError> {
        if self.model.is_voltage_mode() {
            return Err(TargetError::Unsupported);
        }
        self.set_user_limit(amps)
    }

    fn set_total_angle_here_deg(&self, angle_deg: f32) -> Result<(), TargetError> {
        if !angle_deg.is_finite() {
            return Err(TargetError::NotFinite);
        }
        self.state.lock(|s| {
            s.borrow_mut()
                .request(|s| s.pending_home_deg = Some(angle_deg))
        });
        Ok(())
    }

    fn disable(&self) {
        let _ = self.set(ControlMode::Disabled, 0.0);
    }

    fn state(&self) -> MotorState {
        self.state.lock(|cell| {
            let s = cell.borrow();
            // Both angles from one (64-bit) division.
            let angles = s.encoder.has_reading().then(|| s.encoder.angles_deg());
            MotorState {
                online: s.liveness.is_online(),
                mode: s.cascade.mode(),
                target: s.cascade.target(),
                speed_rpm: s.speed_rpm,
                angle_deg: angles.map(|(single, _)| single),
                total_angle_deg: angles.map(|(_, total)| total),
                current_amps: s.current_amps,
                temperature_c: s.temperature_c,
                command: self.stored_command(),
                offline_events: s.liveness.offline_events(),
                last_feedback: s.liveness.last_feedback(),
            }
        })
    }

    fn gear_ratio(&self) -> GearRatio {
        self.model.gear()
    }
}

impl fmt::Debug for DjiMotor {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("DjiMotor")
            .field("model", &self.model)
            .field("esc_id", &self.esc_id)
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests;
