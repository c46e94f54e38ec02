//! VESC motor controllers over CAN (the VESC firmware's `comm_can` protocol).
//!
//! Every frame uses an extended ID `(packet << 8) | controller_id` and big-endian integers:
//!
//! | packet | # | payload |
//! |---|---|---|
//! | `SET_DUTY` | 0 | i32 duty cycle × 100 000 |
//! | `SET_CURRENT` | 1 | i32 motor current in mA |
//! | `SET_CURRENT_BRAKE` | 2 | i32 brake current in mA |
//! | `SET_RPM` | 3 | i32 electrical rpm (eRPM = mechanical rotor rpm × pole pairs) |
//! | `SET_POS` | 4 | i32 position in degrees × 1 000 000 (see "Position" below) |
//! | `STATUS` (1) | 9 | i32 eRPM, i16 motor current × 10, i16 duty × 1000 |
//! | `STATUS_4` | 16 | i16 MOSFET temp × 10, i16 motor temp × 10, i16 input current × 10, i16 PID position × 50 |
//!
//! The VESC runs its own current, speed and position loops; this driver converts targets and
//! feedback between output-shaft units and the VESC's (pole pairs and gear ratio are explicit)
//! and clamps every command to the configured limits before the integer conversion.
//!
//! RC10_LIB turned an eRPM target of 0 into a hard brake. Here that is an explicit option,
//! [`VescConfig::zero_speed_brake_amps`]: `Some(amps)` sends `SET_CURRENT_BRAKE` with that
//! current (a braking torque you choose) whenever the speed command would reach the wire as
//! eRPM 0; `None` (default) sends `SET_RPM 0`. While offline or disabled the driver sends
//! `SET_CURRENT 0`, which releases the motor.
//!
//! Position: the VESC's position (the `SET_POS` target and STATUS_4's PID position) is its
//! encoder's angle divided by VESC Tool's "Angle Division" (`p_pid_ang_div`, default 1),
//! shifted by its offset (vedderb/bldc `mcpwm_foc.c`, `mc_interface.c`). It is the rotor's
//! mechanical angle, as this driver takes it, only with an encoder fitted and configured
//! (position control needs one; sensorless, the VESC reports its *electrical* angle, which
//! turns pole-pairs times per revolution), Angle Division 1 and offset 0. So use angle
//! targets and [`MotorState::angle_deg`] only on a VESC set up that way; the driver offers
//! them in direct drive only (with a gearbox the rotor's angle is not the output's).
//!
//! Slow speeds: the VESC firmware's speed loop does not run below its minimum eRPM (VESC Tool
//! "Minimum ERPM", `s_pid_min_erpm`, 900 by default): a running motor is short-braked
//! instead (duty 0: vedderb/bldc `mcpwm_foc.c`, "Brake when set ERPM is below min ERPM"), a
//! braking torque that grows with speed, so the wheel slows to a stop but is not held there
//! (on a slope it creeps); a motor that is not running is not started. An output target below
//! `min ERPM / (pole pairs × gear ratio)` rpm (e.g. 900 / 7 ≈ 129 rpm for a 7-pole-pair hub
//! motor in direct drive) therefore brakes the wheel rather than turning it slowly. Lower that
//! setting in VESC Tool, or drive slow motion with current or position targets.

use super::{ControlMode, HealthConfig, Liveness, Motor, MotorState, TargetError};
use crate::can::{CanFrame, IdFilter};
use crate::encoder::GearRatio;
use crate::math::{saturate, wrap_deg_360};
use crate::node::{BusUsage, CanNode, FrameError, TxBatch};
use crate::time::Instant;
use core::cell::RefCell;
use core::fmt;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;

/// VESC CAN packet numbers used here (`CAN_PACKET_ID` in the VESC firmware).
pub mod packet {
    /// Set duty cycle.
    pub const SET_DUTY: u8 = 0;
    /// Set motor current.
    pub const SET_CURRENT: u8 = 1;
    /// Set brake current.
    pub const SET_CURRENT_BRAKE: u8 = 2;
    /// Set electrical rpm.
    pub const SET_RPM: u8 = 3;
    /// Set rotor position.
    pub const SET_POS: u8 = 4;
    /// Status 1: eRPM, current, duty.
    pub const STATUS: u8 = 9;
    /// Status 2: amp-hours.
    pub const STATUS_2: u8 = 14;
    /// Status 3: watt-hours.
    pub const STATUS_3: u8 = 15;
    /// Status 4: temperatures, input current, PID position.
    pub const STATUS_4: u8 = 16;
    /// Status 5: tachometer, input voltage.
    pub const STATUS_5: u8 = 27;
}

/// Which status packets a VESC is set to broadcast, each at [`VescConfig::status_hz`]. Every
/// one is a frame on the bus, so the set counts in the frame budget and each is a listen ID
/// of the node.
///
/// Set the VESC to match in VESC Tool (App Settings → General). Firmware 6.x has two status
/// rates, each with its own set of messages: set rate 1 (appconf `can_status_rate_1`) to
/// [`VescConfig::status_hz`] and its messages (`can_status_msgs_r1`, a mask) to this set,
/// bit for bit (STATUS_1 is bit 0 … STATUS_5 bit 4), and leave rate 2's messages empty. The
/// firmware's default sends no status at all, which this driver sees as a motor that never
/// comes online; VESC Tool's setup wizard turns on STATUS_1 to STATUS_4, which this set must
/// then list (or the VESC be set back), or registration's frame budget counts a quarter of
/// the frames the VESC really sends. Firmware 5.x: "CAN Status Message Mode" (`1`, `1_2`, … `1_2_3_4_5`) and one
/// rate.
///
/// ```
/// use rc10_core::motor::vesc::VescStatusSet;
/// let set = VescStatusSet::STATUS_1.with(VescStatusSet::STATUS_4);
/// assert_eq!(set.count(), 2);
/// assert!(set.contains(VescStatusSet::STATUS_4));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct VescStatusSet(u8);

impl VescStatusSet {
    /// STATUS (packet 9): eRPM, current, duty. This driver needs it (it is what keeps the
    /// motor online).
    pub const STATUS_1: Self = Self(1 << 0);
    /// STATUS_2 (packet 14): amp-hours (read, not used).
    pub const STATUS_2: Self = Self(1 << 1);
    /// STATUS_3 (packet 15): watt-hours (read, not used).
    pub const STATUS_3: Self = Self(1 << 2);
    /// STATUS_4 (packet 16): temperatures, input current, PID position.
    pub const STATUS_4: Self = Self(1 << 3);
    /// STATUS_5 (packet 27): tachometer, input voltage (read, not used).
    pub const STATUS_5: Self = Self(1 << 4);
    /// STATUS 1 to 5 (firmware 6.x mask `0x1F`; 5.x mode "1_2_3_4_5").
    pub const ALL: Self = Self(0b1_1111);

    const PACKETS: [(Self, u8); 5] = [
        (Self::STATUS_1, packet::STATUS),
        (Self::STATUS_2, packet::STATUS_2),
        (Self::STATUS_3, packet::STATUS_3),
        (Self::STATUS_4, packet::STATUS_4),
        (Self::STATUS_5, packet::STATUS_5),
    ];

    /// This set plus `other`.
    #[must_use]
    pub const fn with(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }

    /// Whether every packet of `other` is in the set.
    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }

    /// How many packets the set holds.
    pub const fn count(self) -> u32 {
        self.0.count_ones()
    }

    /// Whether status packet number `packet` is in the set.
    pub fn contains_packet(self, packet: u8) -> bool {
        Self::PACKETS
            .iter()
            .any(|(flag, p)| *p == packet && self.contains(*flag))
    }
}

/// A command as the VESC receives it (physical units of the motor, before scaling).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum VescCommand {
    /// Duty cycle, −1…1.
    Duty(f32),
    /// Motor current in amps (0 releases the motor).
    Current(f32),
    /// Brake current in amps (positive).
    Brake(f32),
    /// Electrical rpm.
    Erpm(f32),
    /// Rotor position in degrees, [0, 360).
    Position(f32),
}

impl VescCommand {
    /// The frame for controller `vesc_id`.
    pub fn to_frame(self, vesc_id: u8) -> Option<CanFrame> {
        let (packet, value) = match self {
            Self::Duty(d) => (packet::SET_DUTY, d * 100_000.0),
            Self::Current(a) => (packet::SET_CURRENT, a * 1000.0),
            Self::Brake(a) => (packet::SET_CURRENT_BRAKE, a * 1000.0),
            Self::Erpm(e) => (packet::SET_RPM, e),
            Self::Position(deg) => (packet::SET_POS, deg * 1_000_000.0),
        };
        // Rounded half away from zero, saturating at the i32 range, NaN to 0: no wrap, no
        // sign flip (and no `roundf` library call every tick).
        let raw = crate::math::round_i32(value);
        CanFrame::extended(
            (u32::from(packet) << 8) | u32::from(vesc_id),
            &raw.to_be_bytes(),
        )
    }
}

/// Configuration of a VESC-driven motor.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct VescConfig {
    /// Motor pole pairs (poles / 2): eRPM = rotor rpm × pole pairs.
    pub pole_pairs: u8,
    /// Gear ratio from the rotor to the output shaft.
    pub gear: GearRatio,
    /// Current commands are clamped to ±this, in amps.
    pub max_current_amps: f32,
    /// Brake commands are clamped to this, in amps.
    pub max_brake_amps: f32,
    /// Output-shaft speed targets are clamped to ±this, in rpm.
    pub max_speed_rpm: f32,
    /// Send a brake current (amps) instead of `SET_RPM 0` for a speed target that reaches the
    /// wire as eRPM 0 (below half an eRPM).
    pub zero_speed_brake_amps: Option<f32>,
    /// Frames per second the VESC sends of each status packet (firmware 6.x:
    /// `can_status_rate_1`; the firmware's default is 50 Hz). Every one counts in the bus's
    /// frame budget: at 1 Mbit/s an 8-byte STATUS frame holds the wire for 131–160 µs.
    pub status_hz: u32,
    /// Which status packets it sends (default STATUS_1 only; add STATUS_4 for temperatures
    /// and the angle).
    pub status_packets: VescStatusSet,
    /// Output-shaft torque per motor amp in N·m/A (motor kt × gear ratio), for
    /// [`Motor::set_target_torque_nm`]; `None` (default): torque targets are unsupported.
    pub torque_constant_nm_per_amp: Option<f32>,
    /// Offline timeout and multi-turn policy (thermal limits are enforced by the VESC).
    pub health: HealthConfig,
}

impl VescConfig {
    /// Direct drive with `pole_pairs`, 60 A, 20 A brake, 10 000 rpm, no zero-speed brake,
    /// STATUS_1 at 1 kHz, no torque constant, 100 ms offline timeout.
    pub const fn new(pole_pairs: u8) -> Self {
        Self {
            pole_pairs,
            gear: GearRatio::DIRECT,
            max_current_amps: 60.0,
            max_brake_amps: 20.0,
            max_speed_rpm: 10_000.0,
            zero_speed_brake_amps: None,
            status_hz: 1000,
            status_packets: VescStatusSet::STATUS_1,
            torque_constant_nm_per_amp: None,
            health: HealthConfig::DEFAULT,
        }
    }

    /// Output rpm to eRPM.
    fn erpm_per_rpm(&self) -> f32 {
        self.gear.as_f32() * f32::from(self.pole_pairs)
    }
}

/// Why a VESC motor could not be created.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum VescError {
    /// Pole pairs must be at least 1.
    ZeroPolePairs,
    /// A limit is NaN or negative.
    InvalidLimit,
    /// The status set lacks STATUS_1, the packet that keeps the motor online: it would never
    /// be driven.
    NoStatus1,
    /// Controller id 255 is the VESC firmware's broadcast address: every VESC on the bus obeys
    /// a command sent to it, and none reports status under it.
    BroadcastId,
}

impl fmt::Display for VescError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::ZeroPolePairs => "VESC pole pairs must be at least 1",
            Self::InvalidLimit => "VESC limit is NaN or negative",
            Self::NoStatus1 => "VESC status packets must include STATUS_1",
            Self::BroadcastId => {
                "VESC controller id 255 is the broadcast address (every VESC obeys it)"
            }
        })
    }
}

impl core::error::Error for VescError {}

#[derive(Debug)]
struct VescState {
    mode: ControlMode,
    target: f32,
    duty_target: Option<f32>,
    brake_target: Option<f32>,
    erpm: f32,
    current_amps: Option<f32>,
    duty: f32,
    fet_temp_c: Option<f32>,
    motor_temp_c: Option<f32>,
    /// STATUS_4's PID position in degrees: the rotor's angle on a VESC set up as the module
    /// docs say (encoder, Angle Division 1).
    pid_position_deg: Option<f32>,
    user_current_limit: f32,
    liveness: Liveness,
    command: VescCommand,
}

/// A motor driven by a VESC on a CAN bus.
///
/// ```
/// use rc10_core::motor::Motor;
/// use rc10_core::motor::vesc::{VescConfig, VescMotor};
/// use rc10_core::node::{CanNode, TxBatch};
/// use rc10_core::time::Instant;
///
/// let wheel = VescMotor::new(7, VescConfig::new(7)).unwrap(); // 14-pole motor
/// wheel.set_target_rpm(1000.0).unwrap();
/// // Online after a STATUS frame: eRPM 0, 0 A, duty 0.
/// let status = rc10_core::can::CanFrame::extended(0x0907, &[0; 8]).unwrap();
/// wheel.update_feedback(&status, Instant::from_millis(1)).unwrap();
/// let mut out = TxBatch::new();
/// wheel.update(Instant::from_millis(1), 0.001);
/// wheel.pack_command(&mut out);
/// // SET_RPM (3) to controller 7: 7000 eRPM = 0x00001B58.
/// assert_eq!(out.frames()[0].raw_id(), 0x0307);
/// assert_eq!(out.frames()[0].data(), &[0x00, 0x00, 0x1B, 0x58]);
/// ```
pub struct VescMotor {
    vesc_id: u8,
    config: VescConfig,
    state: Mutex<CriticalSectionRawMutex, RefCell<VescState>>,
}

impl VescMotor {
    /// A VESC with CAN controller id `vesc_id` (0–254; 255 is the broadcast address, refused
    /// with [`VescError::BroadcastId`]).
    pub const fn new(vesc_id: u8, config: VescConfig) -> Result<Self, VescError> {
        if vesc_id == u8::MAX {
            return Err(VescError::BroadcastId);
        }
        if config.pole_pairs == 0 {
            return Err(VescError::ZeroPolePairs);
        }
        const fn bad(limit: f32) -> bool {
            limit.is_nan() || limit < 0.0
        }
        if bad(config.max_current_amps) || bad(config.max_brake_amps) || bad(config.max_speed_rpm) {
            return Err(VescError::InvalidLimit);
        }
        if let Some(b) = config.zero_speed_brake_amps
            && (b.is_nan() || b < 0.0)
        {
            return Err(VescError::InvalidLimit);
        }
        if let Some(kt) = config.torque_constant_nm_per_amp
            && !(kt.is_finite() && kt > 0.0)
        {
            return Err(VescError::InvalidLimit);
        }
        if !config.status_packets.contains(VescStatusSet::STATUS_1) {
            return Err(VescError::NoStatus1);
        }
        Ok(Self {
            vesc_id,
            config,
            state: Mutex::new(RefCell::new(VescState {
                mode: ControlMode::Disabled,
                target: 0.0,
                duty_target: None,
                brake_target: None,
                erpm: 0.0,
                current_amps: None,
                duty: 0.0,
                fet_temp_c: None,
                motor_temp_c: None,
                pid_position_deg: None,
                user_current_limit: f32::INFINITY,
                liveness: Liveness::NEW,
                command: VescCommand::Current(0.0),
            })),
        })
    }

    /// The controller id.
    pub const fn vesc_id(&self) -> u8 {
        self.vesc_id
    }

    /// The configuration.
    pub const fn config(&self) -> &VescConfig {
        &self.config
    }

    /// Commands a duty cycle (−1…1, clamped).
    pub fn set_duty(&self, duty: f32) -> Result<(), TargetError> {
        self.set(ControlMode::Voltage, duty, Some(duty), None)
    }

    /// Commands a brake current in amps (taken by magnitude, clamped to the brake limit).
    /// `state()` then reads mode `Current` with the magnitude as its target, as a drive
    /// current would: [`last_command`](Self::last_command) tells a brake
    /// ([`VescCommand::Brake`]) from a drive.
    pub fn set_brake_current(&self, amps: f32) -> Result<(), TargetError> {
        self.set(ControlMode::Current, amps.abs(), None, Some(amps))
    }

    /// Last measured duty cycle (−1…1).
    pub fn duty(&self) -> f32 {
        self.state.lock(|s| s.borrow().duty)
    }

    /// Last reported motor (winding) temperature in °C (from STATUS_4).
    pub fn motor_temperature_c(&self) -> Option<f32> {
        self.state.lock(|s| s.borrow().motor_temp_c)
    }

    /// Last reported MOSFET temperature in °C (from STATUS_4).
    pub fn mosfet_temperature_c(&self) -> Option<f32> {
        self.state.lock(|s| s.borrow().fet_temp_c)
    }

    /// The command the last tick produced.
    pub fn last_command(&self) -> VescCommand {
        self.state.lock(|s| s.borrow().command)
    }

    fn set(
        &self,
        mode: ControlMode,
        target: f32,
        duty: Option<f32>,
        brake: Option<f32>,
    ) -> Result<(), TargetError> {
        if !target.is_finite() || duty.is_some_and(|d| !d.is_finite()) {
            return Err(TargetError::NotFinite);
        }
        if brake.is_some_and(|b| !b.is_finite()) {
            return Err(TargetError::NotFinite);
        }
        self.state.lock(|s| {
            let mut s = s.borrow_mut();
            s.mode = mode;
            s.target = target;
            s.duty_target = duty;
            s.brake_target = brake;
        });
        Ok(())
    }

    fn command_for(&self, s: &VescState) -> VescCommand {
        let c = &self.config;
        match s.mode {
            ControlMode::Disabled => VescCommand::Current(0.0),
            ControlMode::Voltage => VescCommand::Duty(saturate(s.duty_target.unwrap_or(0.0), 1.0)),
            ControlMode::Current | ControlMode::Torque => {
                let limit = s.user_current_limit;
                match s.brake_target {
                    Some(b) => {
                        VescCommand::Brake(saturate(saturate(b.abs(), c.max_brake_amps), limit))
                    }
                    None => {
                        let amps = if s.mode == ControlMode::Torque {
                            // Only settable with a torque constant; without one, no current.
                            s.target / c.torque_constant_nm_per_amp.unwrap_or(f32::INFINITY)
                        } else {
                            s.target
                        };
                        VescCommand::Current(saturate(saturate(amps, c.max_current_amps), limit))
                    }
                }
            }
            ControlMode::Speed => {
                let rpm = saturate(s.target, c.max_speed_rpm);
                match c.zero_speed_brake_amps {
                    // Rounded half away from zero on the wire: below half an eRPM it is 0.
                    Some(b) if (rpm * c.erpm_per_rpm()).abs() < 0.5 => VescCommand::Brake(
                        saturate(saturate(b, c.max_brake_amps), s.user_current_limit),
                    ),
                    _ => VescCommand::Erpm(rpm * c.erpm_per_rpm()),
                }
            }
            ControlMode::Angle => VescCommand::Position(wrap_deg_360(s.target)),
            ControlMode::TotalAngle => VescCommand::Current(0.0),
        }
    }
}

/// Command packets (0–4) and the next three (5–7, never a status): the IDs
/// `(packet << 8) | vesc_id` with packet bits 3 and up zero.
const COMMAND_ID_MASK: u32 = 0x1FFF_F8FF;

impl CanNode for VescMotor {
    fn bus_usage(&self) -> BusUsage {
        let id = u32::from(self.vesc_id);
        let mut usage = BusUsage::NONE.sending(IdFilter::extended_masked(id, COMMAND_ID_MASK), 1);
        for (flag, packet) in VescStatusSet::PACKETS {
            if self.config.status_packets.contains(flag) {
                let filter = IdFilter::extended((u32::from(packet) << 8) | id);
                usage = usage.listening(filter, self.config.status_hz);
            }
        }
        usage
    }

    fn matches_frame(&self, frame: &CanFrame) -> bool {
        let id = frame.raw_id();
        // VESC IDs are (packet << 8) | controller id with an 8-bit packet: bits 16–28 zero.
        frame.is_extended()
            && id >> 16 == 0
            && (id & 0xFF) == u32::from(self.vesc_id)
            && self.config.status_packets.contains_packet((id >> 8) as u8)
    }

    fn update_feedback(&self, frame: &CanFrame, now: Instant) -> Result<(), FrameError> {
        let Ok(packet) = u8::try_from(frame.raw_id() >> 8) else {
            return Err(FrameError::Unsupported); // not a VESC ID: bits above the packet set
        };
        match packet {
            packet::STATUS => {
                let d = frame.data8().ok_or(FrameError::WrongLength {
                    dlc: frame.dlc() as u8,
                })?;
                let erpm = i32::from_be_bytes([d[0], d[1], d[2], d[3]]);
                let current = i16::from_be_bytes([d[4], d[5]]);
                let duty = i16::from_be_bytes([d[6], d[7]]);
                self.state.lock(|s| {
                    let mut s = s.borrow_mut();
                    s.erpm = erpm as f32;
                    s.current_amps = Some(f32::from(current) / 10.0);
                    s.duty = f32::from(duty) / 1000.0;
                    s.liveness.record_feedback(now);
                });
                Ok(())
            }
            packet::STATUS_4 => {
                let d = frame.data8().ok_or(FrameError::WrongLength {
                    dlc: frame.dlc() as u8,
                })?;
                let fet = i16::from_be_bytes([d[0], d[1]]);
                let motor = i16::from_be_bytes([d[2], d[3]]);
                let pid_pos = i16::from_be_bytes([d[6], d[7]]);
                self.state.lock(|s| {
                    let mut s = s.borrow_mut();
                    s.fet_temp_c = Some(f32::from(fet) / 10.0);
                    s.motor_temp_c = Some(f32::from(motor) / 10.0);
                    s.pid_position_deg = Some(f32::from(pid_pos) / 50.0);
                });
                Ok(())
            }
            // Known status packets this driver does not use.
            packet::STATUS_2 | packet::STATUS_3 | packet::STATUS_5 => Ok(()),
            _ => Err(FrameError::Unsupported),
        }
    }

    fn update(&self, now: Instant, _dt_s: f32) {
        let health = self.config.health;
        self.state.lock(|cell| {
            let mut s = cell.borrow_mut();
            s.liveness.check(&health, now);
            s.command = if s.liveness.is_online() {
                self.command_for(&s)
            } else {
                VescCommand::Current(0.0)
            };
        });
    }

    fn pack_command(&self, out: &mut TxBatch) {
        let command = self.state.lock(|s| s.borrow().command);
        if let Some(frame) = command.to_frame(self.vesc_id) {
            let _ = out.push(frame); // a full batch is counted by the batch
        }
    }
}

impl Motor for VescMotor {
    fn set_target_current(&self, amps: f32) -> Result<(), TargetError> {
        self.set(ControlMode::Current, amps, None, None)
    }

    fn set_target_rpm(&self, rpm: f32) -> Result<(), TargetError> {
        self.set(ControlMode::Speed, rpm, None, None)
    }

    /// Position control uses the VESC's rotor position loop, so it is an output-shaft angle
    /// only for direct drive; geared VESC motors report [`TargetError::Unsupported`]. The VESC
    /// needs an encoder, and Angle Division 1 (see the module docs, "Position").
    fn set_target_angle_deg(&self, angle_deg: f32) -> Result<(), TargetError> {
        if !self.config.gear.is_direct() {
            return Err(TargetError::Unsupported);
        }
        self.set(ControlMode::Angle, angle_deg, None, None)
    }

    /// The VESC position loop is single-turn: not supported.
    fn set_target_total_angle_deg(&self, _angle_deg: f32) -> Result<(), TargetError> {
        Err(TargetError::Unsupported)
    }

    /// Through [`VescConfig::torque_constant_nm_per_amp`] into a current target (mode
    /// [`ControlMode::Torque`], target in N·m); unsupported without it.
    fn set_target_torque_nm(&self, torque_nm: f32) -> Result<(), TargetError> {
        let Some(kt) = self.config.torque_constant_nm_per_amp else {
            return Err(TargetError::Unsupported);
        };
        if !torque_nm.is_finite() {
            return Err(TargetError::NotFinite);
        }
        let _ = kt; // checked above; the tick divides by it
        self.set(ControlMode::Torque, torque_nm, None, None)
    }

    /// Limits current, brake and torque commands, the zero-speed brake of speed mode
    /// included. Otherwise in speed, duty and position modes the VESC runs its own loop and
    /// the current limits set in VESC Tool apply instead.
    fn set_current_limit_amps(&self, amps: f32) -> Result<(), TargetError> {
        if amps.is_nan() {
            return Err(TargetError::NotFinite);
        }
        if amps < 0.0 {
            return Err(TargetError::OutOfRange);
        }
        self.state
            .lock(|s| s.borrow_mut().user_current_limit = amps);
        Ok(())
    }

    fn disable(&self) {
        let _ = self.set(ControlMode::Disabled, 0.0, None, None);
    }

    fn state(&self) -> MotorState {
        self.state.lock(|cell| {
            let s = cell.borrow();
            MotorState {
                online: s.liveness.is_online(),
                mode: s.mode,
                target: s.target,
                speed_rpm: s.erpm / self.config.erpm_per_rpm(),
                // STATUS_4's PID position is the rotor's: an output angle only in direct drive.
                angle_deg: if self.config.gear.is_direct() {
                    s.pid_position_deg.map(wrap_deg_360)
                } else {
                    None
                },
                total_angle_deg: None,
                current_amps: s.current_amps,
                temperature_c: match (s.fet_temp_c, s.motor_temp_c) {
                    (Some(f), Some(m)) => Some(f.max(m)),
                    (f, m) => f.or(m),
                },
                command: match s.command {
                    VescCommand::Current(a) => a,
                    VescCommand::Brake(a) => -a,
                    _ => 0.0,
                },
                offline_events: s.liveness.offline_events(),
                last_feedback: s.liveness.last_feedback(),
            }
        })
    }

    fn gear_ratio(&self) -> GearRatio {
        self.config.gear
    }
}

impl fmt::Debug for VescMotor {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("VescMotor")
            .field("vesc_id", &self.vesc_id)
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const T0: Instant = Instant::from_millis(3);

    fn online(m: &VescMotor) {
        let status = CanFrame::extended(0x0900 | u32::from(m.vesc_id()), &[0; 8]).unwrap();
        m.update_feedback(&status, T0).unwrap();
    }

    fn packed(m: &VescMotor) -> (u32, Vec<u8>) {
        let mut b = TxBatch::new();
        m.update(T0, 0.001);
        m.pack_command(&mut b);
        assert_eq!(b.frames().len(), 1);
        (b.frames()[0].raw_id(), b.frames()[0].data().to_vec())
    }

    #[test]
    fn current_12_5a_is_12500_ma_on_packet_1() {
        let m = VescMotor::new(0x42, VescConfig::new(7)).unwrap();
        online(&m);
        m.set_target_current(12.5).unwrap();
        // 12 500 mA = 0x000030D4 on (1 << 8) | 0x42.
        assert_eq!(packed(&m), (0x0142, vec![0x00, 0x00, 0x30, 0xD4]));
        m.set_target_current(-1.0).unwrap();
        assert_eq!(packed(&m).1, vec![0xFF, 0xFF, 0xFC, 0x18]); // -1000
    }

    #[test]
    fn command_values_round_half_away_from_zero_and_saturate_on_the_wire() {
        // SET_RPM (3) to controller 9 carries eRPM as it is: 2.5 → 3, −2.5 → −3, 2.4999998
        // → 2; beyond the i32 range the value saturates (no wrap, no sign flip).
        let wire = |erpm: f32| VescCommand::Erpm(erpm).to_frame(9).unwrap().data().to_vec();
        assert_eq!(wire(2.5), 3i32.to_be_bytes());
        assert_eq!(wire(-2.5), (-3i32).to_be_bytes());
        assert_eq!(wire(2.499_999_8), 2i32.to_be_bytes());
        assert_eq!(wire(3.0e9), [0x7F, 0xFF, 0xFF, 0xFF]);
        assert_eq!(wire(-3.0e9), [0x80, 0x00, 0x00, 0x00]);
        // SET_POS (4): 359.9999 deg × 10^6 is far above 2^23, a whole float already.
        let pos = VescCommand::Position(359.999_9).to_frame(9).unwrap();
        assert_eq!(pos.data(), 359_999_904i32.to_be_bytes());
    }

    #[test]
    fn current_beyond_limit_is_clamped() {
        let m = VescMotor::new(1, VescConfig::new(7)).unwrap();
        online(&m);
        m.set_target_current(1e9).unwrap();
        assert_eq!(packed(&m).1, 60_000i32.to_be_bytes().to_vec());
    }

    #[test]
    fn speed_target_converts_through_gear_and_pole_pairs() {
        let mut cfg = VescConfig::new(7);
        cfg.gear = GearRatio::new(5, 1).unwrap();
        let m = VescMotor::new(3, cfg).unwrap();
        online(&m);
        m.set_target_rpm(-100.0).unwrap();
        // -100 rpm · 5 · 7 = -3500 eRPM = 0xFFFFF254 on packet 3.
        assert_eq!(packed(&m), (0x0303, vec![0xFF, 0xFF, 0xF2, 0x54]));
    }

    #[test]
    fn zero_speed_brake_is_an_explicit_option() {
        let m = VescMotor::new(3, VescConfig::new(7)).unwrap();
        online(&m);
        m.set_target_rpm(0.0).unwrap();
        assert_eq!(packed(&m), (0x0303, vec![0, 0, 0, 0]));
        let mut cfg = VescConfig::new(7);
        cfg.zero_speed_brake_amps = Some(5.0);
        let braking = VescMotor::new(3, cfg).unwrap();
        online(&braking);
        braking.set_target_rpm(0.0).unwrap();
        // SET_CURRENT_BRAKE (2), 5000 mA = 0x1388.
        assert_eq!(packed(&braking), (0x0203, vec![0, 0, 0x13, 0x88]));
        // 0.07 rpm × 7 pole pairs = 0.49 eRPM: 0 on the wire, so the brake too.
        braking.set_target_rpm(0.07).unwrap();
        assert_eq!(packed(&braking), (0x0203, vec![0, 0, 0x13, 0x88]));
        // -0.08 rpm = -0.56 eRPM: SET_RPM -1.
        braking.set_target_rpm(-0.08).unwrap();
        assert_eq!(packed(&braking), (0x0303, vec![0xFF, 0xFF, 0xFF, 0xFF]));
        // Exactly half an eRPM (0.25 rpm × 2 pole pairs) rounds away from zero: SET_RPM 1.
        let mut cfg = VescConfig::new(2);
        cfg.zero_speed_brake_amps = Some(5.0);
        let two_poles = VescMotor::new(3, cfg).unwrap();
        online(&two_poles);
        two_poles.set_target_rpm(0.25).unwrap();
        assert_eq!(packed(&two_poles), (0x0303, vec![0, 0, 0, 1]));
        // The user's current limit caps this brake as it caps an explicit one: 2 A = 2000 mA
        // (0x07D0).
        braking.set_current_limit_amps(2.0).unwrap();
        braking.set_target_rpm(0.0).unwrap();
        assert_eq!(packed(&braking), (0x0203, vec![0, 0, 0x07, 0xD0]));
    }

    #[test]
    fn a_ratio_written_2_to_2_is_direct_drive() {
        let mut cfg = VescConfig::new(7);
        cfg.gear = GearRatio::new(2, 2).unwrap();
        let m = VescMotor::new(3, cfg).unwrap();
        online(&m);
        assert_eq!(m.set_target_angle_deg(90.0), Ok(()));
        // SET_POS (4): 90 000 000 = 0x055D_4A80.
        assert_eq!(packed(&m), (0x0403, vec![0x05, 0x5D, 0x4A, 0x80]));
    }

    #[test]
    fn duty_brake_and_position_packets() {
        let m = VescMotor::new(9, VescConfig::new(7)).unwrap();
        online(&m);
        m.set_duty(0.25).unwrap();
        assert_eq!(packed(&m), (0x0009, 25_000i32.to_be_bytes().to_vec()));
        m.set_duty(3.0).unwrap(); // clamped to 1.0
        assert_eq!(packed(&m).1, 100_000i32.to_be_bytes().to_vec());
        m.set_brake_current(-8.0).unwrap(); // magnitude
        assert_eq!(packed(&m), (0x0209, 8_000i32.to_be_bytes().to_vec()));
        assert_eq!(
            (m.state().mode, m.state().target),
            (ControlMode::Current, 8.0)
        );
        m.set_target_angle_deg(-90.0).unwrap(); // 270° = 270 000 000
        assert_eq!(packed(&m), (0x0409, 270_000_000i32.to_be_bytes().to_vec()));
    }

    #[test]
    fn status_1_feedback_parsed() {
        let mut cfg = VescConfig::new(7);
        cfg.gear = GearRatio::new(2, 1).unwrap();
        let m = VescMotor::new(5, cfg).unwrap();
        // eRPM 14 000 = 0x000036B0, current 123.4 A → 1234 = 0x04D2, duty 0.5 → 500 = 0x01F4.
        let f = CanFrame::extended(0x0905, &[0, 0, 0x36, 0xB0, 0x04, 0xD2, 0x01, 0xF4]).unwrap();
        m.update_feedback(&f, T0).unwrap();
        let s = m.state();
        assert_eq!(s.speed_rpm, 1000.0); // 14 000 / 7 / 2
        assert!((s.current_amps.unwrap() - 123.4).abs() < 1e-4);
        assert_eq!(m.duty(), 0.5);
        assert_eq!(s.last_feedback, Some(T0));
    }

    #[test]
    fn status_4_gives_temperatures_and_unknown_packets_are_rejected() {
        let m = VescMotor::new(5, VescConfig::new(7)).unwrap();
        // FET 45.6 °C = 456 = 0x01C8, motor 70.0 °C = 700 = 0x02BC.
        let f = CanFrame::extended(0x1005, &[0x01, 0xC8, 0x02, 0xBC, 0, 0, 0, 0]).unwrap();
        m.update_feedback(&f, T0).unwrap();
        // The state reports the hotter of the two; each is named on its own.
        assert_eq!(m.state().temperature_c, Some(70.0));
        assert!((m.mosfet_temperature_c().unwrap() - 45.6).abs() < 1e-4);
        assert_eq!(m.motor_temperature_c(), Some(70.0));
        let unknown = CanFrame::extended(0x3F05, &[0; 8]).unwrap();
        assert_eq!(
            m.update_feedback(&unknown, T0),
            Err(FrameError::Unsupported)
        );
        let short = CanFrame::extended(0x0905, &[0; 4]).unwrap();
        assert_eq!(
            m.update_feedback(&short, T0),
            Err(FrameError::WrongLength { dlc: 4 })
        );
    }

    #[test]
    fn offline_releases_motor() {
        let m = VescMotor::new(2, VescConfig::new(7)).unwrap();
        online(&m);
        m.set_target_rpm(500.0).unwrap();
        let mut b = TxBatch::new();
        m.update(T0 + crate::time::Duration::from_millis(150), 0.001);
        m.pack_command(&mut b);
        assert_eq!(b.frames()[0].raw_id(), 0x0102); // SET_CURRENT
        assert_eq!(b.frames()[0].data(), &[0, 0, 0, 0]);
        assert!(!m.is_online());
    }

    #[test]
    fn geared_motor_refuses_angle_and_all_refuse_total_angle() {
        let mut cfg = VescConfig::new(7);
        cfg.gear = GearRatio::new(3, 1).unwrap();
        let m = VescMotor::new(1, cfg).unwrap();
        assert_eq!(m.set_target_angle_deg(10.0), Err(TargetError::Unsupported));
        assert_eq!(
            m.set_target_total_angle_deg(10.0),
            Err(TargetError::Unsupported)
        );
        assert_eq!(m.set_target_rpm(f32::NAN), Err(TargetError::NotFinite));
        assert_eq!(
            VescMotor::new(1, VescConfig::new(0)).unwrap_err(),
            VescError::ZeroPolePairs
        );
    }

    #[test]
    fn status_set_is_declared_and_counted_in_the_budget() {
        let mut cfg = VescConfig::new(7);
        cfg.status_packets = VescStatusSet::STATUS_1.with(VescStatusSet::STATUS_4);
        cfg.status_hz = 500;
        let m = VescMotor::new(0x21, cfg).unwrap();
        let u = m.bus_usage();
        assert_eq!(u.feedback_hz, 1000); // two packets at 500 Hz
        let ext = |id| CanFrame::extended(id, &[0; 8]).unwrap().id();
        assert!(u.listen.matches(ext(0x0921)) && u.listen.matches(ext(0x1021)));
        assert!(!u.listen.matches(ext(0x0E21))); // STATUS_2 not configured
        // Commands SET_DUTY..SET_POS go out on (0..=4 << 8) | 0x21, nothing else of ours.
        for packet in 0..=4u32 {
            assert!(u.sends.matches(ext((packet << 8) | 0x21)));
        }
        assert!(!u.sends.matches(ext(0x0921)));
        assert!(!u.sends.matches(ext(0x0122)));
        // The whole set: five packets.
        let mut all = VescConfig::new(7);
        all.status_packets = VescStatusSet::ALL;
        assert_eq!(
            VescMotor::new(1, all).unwrap().bus_usage().feedback_hz,
            5000
        );
    }

    #[test]
    fn ids_with_bits_above_the_packet_are_not_vesc_frames() {
        let m = VescMotor::new(7, VescConfig::new(7)).unwrap();
        // 0x1_0907 has STATUS's low 16 bits but is not a VESC ID.
        let odd = CanFrame::extended(0x1_0907, &[0; 8]).unwrap();
        assert!(!m.matches_frame(&odd));
        assert_eq!(m.update_feedback(&odd, T0), Err(FrameError::Unsupported));
        assert!(!m.is_online());
        // STATUS_4 is not claimed unless configured.
        assert!(!m.matches_frame(&CanFrame::extended(0x1007, &[0; 8]).unwrap()));
        assert!(m.matches_frame(&CanFrame::extended(0x0907, &[0; 8]).unwrap()));
    }

    #[test]
    fn angle_comes_from_status_4_in_direct_drive_only() {
        let m = VescMotor::new(5, VescConfig::new(7)).unwrap();
        assert_eq!(m.state().angle_deg, None);
        // PID position 123.4° = 6170 = 0x181A.
        let f = CanFrame::extended(0x1005, &[0, 0, 0, 0, 0, 0, 0x18, 0x1A]).unwrap();
        m.update_feedback(&f, T0).unwrap();
        assert!((m.state().angle_deg.unwrap() - 123.4).abs() < 1e-3);
        assert_eq!(m.state().total_angle_deg, None);
        let mut geared = VescConfig::new(7);
        geared.gear = GearRatio::new(4, 1).unwrap();
        let g = VescMotor::new(5, geared).unwrap();
        g.update_feedback(&f, T0).unwrap();
        assert_eq!(g.state().angle_deg, None); // the rotor's angle is not the output's
    }

    #[test]
    fn torque_target_needs_a_torque_constant_and_current_limit_applies() {
        let plain = VescMotor::new(3, VescConfig::new(7)).unwrap();
        assert_eq!(
            plain.set_target_torque_nm(1.0),
            Err(TargetError::Unsupported)
        );
        let mut cfg = VescConfig::new(7);
        cfg.torque_constant_nm_per_amp = Some(0.5);
        let m = VescMotor::new(3, cfg).unwrap();
        online(&m);
        m.set_target_torque_nm(2.0).unwrap(); // 4 A = 4000 mA on SET_CURRENT
        assert_eq!(packed(&m), (0x0103, 4_000i32.to_be_bytes().to_vec()));
        assert_eq!(m.mode(), ControlMode::Torque);
        m.set_current_limit_amps(2.5).unwrap();
        assert_eq!(packed(&m).1, 2_500i32.to_be_bytes().to_vec());
        m.set_brake_current(10.0).unwrap();
        assert_eq!(packed(&m), (0x0203, 2_500i32.to_be_bytes().to_vec()));
        assert_eq!(m.set_current_limit_amps(-1.0), Err(TargetError::OutOfRange));
        let mut bad = VescConfig::new(7);
        bad.torque_constant_nm_per_amp = Some(0.0);
        assert_eq!(VescMotor::new(3, bad).unwrap_err(), VescError::InvalidLimit);
        let mut silent = VescConfig::new(7);
        silent.status_packets = VescStatusSet::STATUS_4;
        assert_eq!(VescMotor::new(3, silent).unwrap_err(), VescError::NoStatus1);
    }

    #[test]
    fn controller_id_255_is_refused_as_the_broadcast_address() {
        // VESC firmware (comm_can.c) runs a command whose low ID byte is 255 on every VESC.
        let cfg = VescConfig::new(7);
        assert_eq!(
            VescMotor::new(255, cfg).unwrap_err(),
            VescError::BroadcastId
        );
        assert!(VescMotor::new(254, cfg).is_ok());
        assert!(VescMotor::new(0, cfg).is_ok());
    }

    #[test]
    fn state_has_no_current_before_status_1() {
        let m = VescMotor::new(5, VescConfig::new(7)).unwrap();
        assert_eq!(m.state().current_amps, None);
        assert_eq!(m.state().temperature_c, None);
        online(&m);
        assert_eq!(m.state().current_amps, Some(0.0));
    }
}
