//! Scenarios (motors, targets, faults) and the world loop that runs rc10-core's real bus,
//! scheduler and drivers against the simulated bus and plants in deterministic virtual time.
//!
//! Time advances from event to event in whole microseconds: plant integration every 200 µs,
//! the rc10 tick every 1 ms, each ESC's feedback every 1 ms at its own (seeded) phase, and frame
//! ends on the bus. Received frames are dispatched to rc10 the moment they end on the wire,
//! stamped with that time (an ideal RX interrupt); the controller's 3 TX buffers are modelled.

use crate::bus::{Sender, SimBus, SimBusConfig, SimBusStats};
use crate::legacy::LegacyM3508;
use crate::metrics::{StepMetrics, step_metrics};
use crate::plant::{DjiEsc, Load, MotorParams};
use rand_xoshiro::Xoshiro256PlusPlus;
use rand_xoshiro::rand_core::{Rng, SeedableRng};
use rc10_core::bus::{BusBuilder, BusConfig, FrameBudget, RegisterError};
use rc10_core::can::{BusCounters, CanFrame, ReceiveError};
use rc10_core::chassis::{LinearChassis, MecanumConfig, Twist, TwistLimiter};
use rc10_core::math::wrap_deg_180;
use rc10_core::motor::dji::{DjiConfig, DjiModel, DjiMotor};
use rc10_core::motor::{Motor, TargetError};
use rc10_core::node::{CanNode, TxBatch};
use rc10_core::remote::dbus::DbusReceiver;
use rc10_core::time::Duration;
use rc10_core::time::Instant;
use std::fmt;

/// Most motors one simulated bus takes (rc10's registry capacity in the simulator).
pub const MAX_MOTORS: usize = 8;

/// Which controller drives a simulated motor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Controller {
    /// rc10's DJI driver with its shipped defaults.
    Rc10,
    /// rc10's DJI driver with this configuration.
    Rc10With(DjiConfig),
    /// RC10_LIB's demo speed loop (M3508 only), for comparison.
    Rc10Legacy,
}

/// One motor of a scenario.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorSpec {
    /// Model (and command mode for the GM6020).
    pub model: DjiModel,
    /// ESC id.
    pub esc_id: u8,
    /// What it drives.
    pub load: Load,
    /// Which controller.
    pub controller: Controller,
}

/// What a target value means.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TargetKind {
    /// Current in amps.
    Current,
    /// Output speed in rpm.
    Rpm,
    /// Output angle in degrees, shortest way.
    AngleDeg,
    /// Output multi-turn angle in degrees.
    TotalAngleDeg,
}

/// A target profile for one motor: values set at given times.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetSpec {
    /// Index into [`Scenario::motors`].
    pub motor: usize,
    /// What the values mean.
    pub kind: TargetKind,
    /// `(time in ms, value)`, in time order.
    pub steps: Vec<(u64, f32)>,
}

/// An injected fault.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// The motor's ESC loses power (referee cut) in `[from_ms, to_ms)`.
    PowerCut {
        /// Motor index.
        motor: usize,
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// The rotor is locked in `[from_ms, to_ms)`.
    Stall {
        /// Motor index.
        motor: usize,
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// The winding is forced to `celsius` at `at_ms`.
    OverTemperature {
        /// Motor index.
        motor: usize,
        /// When, ms.
        at_ms: u64,
        /// Temperature, °C.
        celsius: f64,
    },
    /// Each frame on the wire is lost with `probability` in `[from_ms, to_ms)`.
    FrameLoss {
        /// Probability per frame, 0–1.
        probability: f64,
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// Frames reach the controller `delay_us` late in `[from_ms, to_ms)` (a slow receive path).
    Delay {
        /// Extra latency, µs.
        delay_us: u64,
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// The controller's receive path (its RX interrupt) is blocked in `[from_ms, to_ms)`:
    /// frames wait in the 3-deep RX FIFO, later ones are dropped and reported to rc10 as
    /// overruns, and the FIFO drains when the stall ends.
    RxStall {
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// The controller is bus-off in `[from_ms, to_ms)`: it sends and receives nothing.
    BusOff {
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
    /// Each frame arrives with a wrong DLC with `probability` in `[from_ms, to_ms)`.
    Corruption {
        /// Probability per frame, 0–1.
        probability: f64,
        /// Start, ms.
        from_ms: u64,
        /// End, ms.
        to_ms: u64,
    },
}

/// Robot firmware driving a mecanum chassis from a DR16 remote: each DBUS frame (every 14 ms)
/// is encoded as the receiver sends it and parsed by rc10's `DbusReceiver`; the sticks become a
/// twist (left stick: vx, vy; right stick x: ω), limited by a `TwistLimiter`, turned into wheel
/// rpm by rc10's mecanum kinematics (saturated together) and set on motors 1–4 (FL, FR, RL,
/// RR). Achieved twist is the chassis's forward kinematics of the true wheel speeds (no slip;
/// each wheel carries its share of the robot's inertia as its own load).
#[derive(Debug, Clone, PartialEq)]
pub struct ChassisDrive {
    /// Chassis geometry and motor signs.
    pub geometry: MecanumConfig,
    /// Twist at full stick deflection (m/s, m/s, rad/s).
    pub max_twist: Twist,
    /// Acceleration limits (m/s², m/s², rad/s²).
    pub max_accel: Twist,
    /// Wheel speed limit, output rpm.
    pub max_wheel_rpm: f32,
    /// Stick positions from a time on (ms): right x, right y, left x, left y in −1…1.
    pub sticks: Vec<(u64, [f32; 4])>,
    /// Windows `[from_ms, to_ms)` in which the receiver sends nothing.
    pub radio_off: Vec<(u64, u64)>,
}

/// What the chassis application commanded and what the chassis did, at one tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ChassisSample {
    /// Twist sent to the kinematics (after the limiter).
    pub commanded: Twist,
    /// Twist from the true wheel speeds.
    pub achieved: Twist,
    /// Whether the remote link was lost.
    pub link_lost: bool,
}

/// Everything a run needs.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// Short name (`m3508-speed-step`).
    pub name: String,
    /// One line saying what it shows.
    pub description: String,
    /// Simulated time, ms.
    pub duration_ms: u64,
    /// Seed for everything random (ESC phases, faults).
    pub seed: u64,
    /// The motors, all on one bus.
    pub motors: Vec<MotorSpec>,
    /// Target profiles.
    pub targets: Vec<TargetSpec>,
    /// Injected faults.
    pub faults: Vec<Fault>,
    /// rc10 bus configuration (bitrate, registration budget).
    pub bus: BusConfig,
    /// Robot firmware driving motors 1–4 as a mecanum chassis from a remote, if any.
    pub chassis: Option<ChassisDrive>,
}

/// Why a scenario could not run.
#[derive(Debug, Clone, PartialEq)]
pub enum SimError {
    /// A motor spec is invalid (id out of range, legacy controller on a non-M3508…).
    InvalidMotor {
        /// Motor index.
        motor: usize,
        /// What is wrong.
        reason: String,
    },
    /// rc10 refused to register a motor (this is what a robot would see at start-up).
    Register {
        /// Motor index.
        motor: usize,
        /// rc10's error.
        error: RegisterError,
    },
    /// A target refers to a missing motor or was refused.
    Target {
        /// Target index.
        target: usize,
        /// What is wrong.
        reason: String,
    },
}

impl fmt::Display for SimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::InvalidMotor { motor, reason } => write!(f, "motor {motor}: {reason}"),
            Self::Register { motor, error } => {
                write!(f, "motor {motor} cannot be registered: {error}")
            }
            Self::Target { target, reason } => write!(f, "target {target}: {reason}"),
        }
    }
}

impl std::error::Error for SimError {}

/// One motor at one tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MotorSample {
    /// Active target (mode's unit).
    pub target: f32,
    /// Physical output speed, rpm.
    pub true_rpm: f64,
    /// Physical output angle, continuous degrees.
    pub true_total_deg: f64,
    /// Speed rc10 sees, rpm.
    pub measured_rpm: f32,
    /// Multi-turn angle rc10 sees, degrees.
    pub measured_total_deg: f32,
    /// Command rc10 sent (amps or volts).
    pub command: f32,
    /// Physical winding current, amps.
    pub current_amps: f64,
    /// Physical winding temperature, °C.
    pub temperature_c: f64,
    /// Whether rc10 considers the motor online.
    pub online: bool,
}

/// All motors at one tick.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Time, ms.
    pub t_ms: u64,
    /// One per motor, in scenario order.
    pub motors: Vec<MotorSample>,
    /// The chassis application's view, in chassis scenarios.
    pub chassis: Option<ChassisSample>,
}

/// Step metrics of one target profile's last step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetMetrics {
    /// Target index.
    pub target: usize,
    /// Motor index.
    pub motor: usize,
    /// What was stepped.
    pub kind: TargetKind,
    /// The figures.
    pub metrics: StepMetrics,
}

/// What a run produced.
#[derive(Debug, Clone, PartialEq)]
pub struct RunResult {
    /// The scenario's name.
    pub name: String,
    /// One sample per ms.
    pub samples: Vec<Sample>,
    /// The simulated bus's counters.
    pub bus: SimBusStats,
    /// rc10's own bus counters.
    pub counters: BusCounters,
    /// rc10's frame budget for the registered motors.
    pub budget: FrameBudget,
    /// Offline events per motor, as rc10 counted them.
    pub offline_events: Vec<u32>,
    /// Frames dropped because the controller's RX FIFO was full.
    pub rx_overruns: u64,
    /// Step metrics per stepped target.
    pub metrics: Vec<TargetMetrics>,
}

/// A motor the simulator can drive: rc10's scheduler side and the application side.
trait SimMotor: CanNode + Motor {}
impl<T: CanNode + Motor> SimMotor for T {}

fn build_motor(index: usize, spec: &MotorSpec) -> Result<Box<dyn SimMotor>, SimError> {
    let invalid = |reason: String| SimError::InvalidMotor {
        motor: index,
        reason,
    };
    match spec.controller {
        Controller::Rc10 => {
            let cfg = DjiConfig::default_for(spec.model);
            DjiMotor::new(spec.model, spec.esc_id, cfg)
                .map(|m| Box::new(m) as Box<dyn SimMotor>)
                .map_err(|e| invalid(e.to_string()))
        }
        Controller::Rc10With(cfg) => DjiMotor::new(spec.model, spec.esc_id, cfg)
            .map(|m| Box::new(m) as Box<dyn SimMotor>)
            .map_err(|e| invalid(e.to_string())),
        Controller::Rc10Legacy => {
            if spec.model != DjiModel::M3508 {
                return Err(invalid("the RC10_LIB controller is for M3508 only".into()));
            }
            LegacyM3508::new(spec.esc_id)
                .map(|m| Box::new(m) as Box<dyn SimMotor>)
                .ok_or_else(|| invalid(format!("ESC id {} out of range", spec.esc_id)))
        }
    }
}

fn apply_target(motor: &dyn SimMotor, kind: TargetKind, value: f32) -> Result<(), TargetError> {
    match kind {
        TargetKind::Current => motor.set_target_current(value),
        TargetKind::Rpm => motor.set_target_rpm(value),
        TargetKind::AngleDeg => motor.set_target_angle_deg(value),
        TargetKind::TotalAngleDeg => motor.set_target_total_angle_deg(value),
    }
}

/// A uniform number in [0, 1) from the run's generator.
fn uniform(rng: &mut Xoshiro256PlusPlus) -> f64 {
    (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64
}

const PLANT_STEP_US: u64 = 200;
/// RX FIFO depth of an STM32G4 FDCAN (each of its two FIFOs holds 3 frames).
const RX_FIFO_DEPTH: usize = 3;
const TICK_US: u64 = 1000;

/// Runs `scenario` and returns its trace and figures. Same scenario, same result, always.
pub fn run(scenario: &Scenario) -> Result<RunResult, SimError> {
    run_with_progress(scenario, &mut |_| {})
}

/// [`run`], calling `progress` with the simulated time in ms after every simulated second.
pub fn run_with_progress(
    scenario: &Scenario,
    progress: &mut dyn FnMut(u64),
) -> Result<RunResult, SimError> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(scenario.seed);
    let motors: Vec<Box<dyn SimMotor>> = scenario
        .motors
        .iter()
        .enumerate()
        .map(|(i, spec)| build_motor(i, spec))
        .collect::<Result<_, _>>()?;
    let mut builder = BusBuilder::<MAX_MOTORS>::with_config(scenario.bus);
    for (i, m) in motors.iter().enumerate() {
        builder
            .register(&**m as &dyn CanNode)
            .map_err(|error| SimError::Register { motor: i, error })?;
    }
    let rc10 = builder.build();
    for (i, t) in scenario.targets.iter().enumerate() {
        if t.motor >= motors.len() {
            return Err(SimError::Target {
                target: i,
                reason: format!("no motor {}", t.motor),
            });
        }
    }

    let mut bus = SimBus::new(SimBusConfig {
        bitrate_bps: scenario.bus.bitrate_bps,
        ..SimBusConfig::default()
    });
    let mut escs: Vec<DjiEsc> = Vec::new();
    let mut next_feedback: Vec<u64> = Vec::new();
    for spec in &scenario.motors {
        bus.add_device();
        let phase = rng.next_u64() % TICK_US;
        escs.push(DjiEsc::new(
            MotorParams::for_model(spec.model),
            spec.esc_id,
            spec.load,
            phase,
        ));
        next_feedback.push(phase);
    }

    let mut app = match &scenario.chassis {
        Some(drive) => Some(ChassisApp::new(drive, motors.len())?),
        None => None,
    };

    let end_us = scenario.duration_ms * 1000;
    let (mut next_plant, mut next_tick) = (0u64, 0u64);
    let mut batch = TxBatch::new();
    let mut samples = Vec::with_capacity(scenario.duration_ms as usize);
    let mut next_step = vec![0usize; scenario.targets.len()];
    // Frames on their way to the controller under a delay fault: (arrival µs, frame).
    let mut delayed: std::collections::VecDeque<(u64, CanFrame)> = Default::default();
    // The controller's RX FIFO while its receive path is stalled.
    let mut rx_fifo: std::collections::VecDeque<CanFrame> = Default::default();
    let mut rx_overruns = 0u64;

    loop {
        let mut t = next_plant.min(next_tick);
        if let Some(&f) = next_feedback.iter().min() {
            t = t.min(f);
        }
        if let Some(b) = bus.busy_until() {
            t = t.min(b);
        }
        if let Some(&(d, _)) = delayed.front() {
            t = t.min(d);
        }
        if t >= end_us {
            break;
        }
        let t_ms = t / 1000;

        // A frame ends on the wire: faults, then delivery to everyone but its sender.
        if let Some((sender, frame)) = bus.complete(t) {
            let to_mcu = deliver(scenario, &mut rng, &mut bus, &mut escs, sender, frame, t_ms);
            if let Some(frame) = to_mcu {
                if rx_stalled(scenario, t_ms) {
                    if rx_fifo.len() < RX_FIFO_DEPTH {
                        rx_fifo.push_back(frame);
                    } else {
                        rx_overruns += 1;
                        rc10.record_receive_error(ReceiveError::Overrun);
                    }
                } else {
                    match delay_us(scenario, t_ms) {
                        0 => {
                            rc10.dispatch(&frame, Instant::from_micros(t));
                        }
                        d => delayed.push_back((t + d, frame)),
                    }
                }
            }
        }
        if !rx_stalled(scenario, t_ms) {
            // The receive path runs again: the FIFO drains now, in order.
            while let Some(frame) = rx_fifo.pop_front() {
                rc10.dispatch(&frame, Instant::from_micros(t));
            }
        }
        while let Some(&(d, frame)) = delayed.front() {
            if d > t {
                break;
            }
            delayed.pop_front();
            if !bus.mcu_bus_off() {
                rc10.dispatch(&frame, Instant::from_micros(d));
            }
        }

        if t == next_plant {
            apply_state_faults(scenario, &mut bus, &mut escs, t_ms, t % 1000 == 0);
            for esc in &mut escs {
                esc.step(t, PLANT_STEP_US as f64 * 1e-6);
            }
            next_plant += PLANT_STEP_US;
        }

        for (i, esc) in escs.iter().enumerate() {
            if next_feedback.get(i) == Some(&t) {
                if esc.feedback_due(t)
                    && let Some(frame) = esc.feedback_frame()
                {
                    bus.device_send(i, frame);
                }
                if let Some(n) = next_feedback.get_mut(i) {
                    *n += TICK_US;
                }
            }
        }

        if t == next_tick {
            for (i, spec) in scenario.targets.iter().enumerate() {
                let Some(k) = next_step.get_mut(i) else {
                    continue;
                };
                while let Some(&(at_ms, value)) = spec.steps.get(*k) {
                    if at_ms > t_ms {
                        break;
                    }
                    if let Some(m) = motors.get(spec.motor) {
                        apply_target(&**m, spec.kind, value).map_err(|e| SimError::Target {
                            target: i,
                            reason: e.to_string(),
                        })?;
                    }
                    *k += 1;
                }
            }
            let now = Instant::from_micros(t);
            let chassis = match (&mut app, &scenario.chassis) {
                (Some(app), Some(drive)) => Some(
                    app.step(drive, &motors, &escs, t_ms, now)
                        .map_err(|reason| SimError::Target { target: 0, reason })?,
                ),
                _ => None,
            };
            rc10.tick(now, TICK_US as f32 * 1e-6, &mut batch);
            rc10.transmit(&batch, &mut bus.mcu_port());
            samples.push(Sample {
                t_ms,
                motors: motors
                    .iter()
                    .zip(&escs)
                    .map(|(m, esc)| {
                        let s = m.state();
                        MotorSample {
                            target: s.target,
                            true_rpm: esc.speed_rpm(),
                            true_total_deg: esc.total_angle_deg(),
                            measured_rpm: s.speed_rpm,
                            measured_total_deg: s.total_angle_deg.unwrap_or(0.0),
                            command: s.command,
                            current_amps: esc.current_amps(),
                            temperature_c: esc.temperature_c(),
                            online: s.online,
                        }
                    })
                    .collect(),
                chassis,
            });
            next_tick += TICK_US;
            if t_ms % 1000 == 999 {
                progress(t_ms + 1);
            }
        }

        bus.start_next(t);
    }

    let metrics = scenario
        .targets
        .iter()
        .enumerate()
        .filter_map(|(i, spec)| target_metrics(i, spec, &samples))
        .collect();
    Ok(RunResult {
        name: scenario.name.clone(),
        bus: bus.stats(),
        counters: rc10.stats().snapshot(),
        budget: rc10.budget(),
        offline_events: motors.iter().map(|m| m.state().offline_events).collect(),
        rx_overruns,
        metrics,
        samples,
    })
}

/// The robot firmware of a chassis scenario.
struct ChassisApp {
    kinematics: LinearChassis<4>,
    limiter: TwistLimiter,
    receiver: DbusReceiver,
}

/// DR16 frame period.
const DBUS_PERIOD_MS: u64 = 14;

impl ChassisApp {
    fn new(drive: &ChassisDrive, motor_count: usize) -> Result<Self, SimError> {
        if motor_count < 4 {
            return Err(SimError::InvalidMotor {
                motor: motor_count,
                reason: "a chassis needs motors 1-4 (FL, FR, RL, RR)".into(),
            });
        }
        let kinematics =
            LinearChassis::mecanum(drive.geometry).map_err(|e| SimError::InvalidMotor {
                motor: 0,
                reason: e.to_string(),
            })?;
        Ok(Self {
            kinematics,
            limiter: TwistLimiter::new(drive.max_accel),
            receiver: DbusReceiver::new(Duration::from_millis(100)),
        })
    }

    fn step(
        &mut self,
        drive: &ChassisDrive,
        motors: &[Box<dyn SimMotor>],
        escs: &[DjiEsc],
        t_ms: u64,
        now: Instant,
    ) -> Result<ChassisSample, String> {
        let radio_on = !drive
            .radio_off
            .iter()
            .any(|(from, to)| in_window(t_ms, *from, *to));
        if radio_on && t_ms.is_multiple_of(DBUS_PERIOD_MS) {
            let sticks = drive
                .sticks
                .iter()
                .rev()
                .find(|(at, _)| *at <= t_ms)
                .map_or([0.0; 4], |(_, s)| *s);
            // The bytes a DR16 would send, parsed by rc10 as on the robot.
            let _ = self.receiver.push_frame(&encode_dbus(sticks), now);
        }
        let signal = self.receiver.signal(now);
        let f = signal.value;
        let m = drive.max_twist;
        let wanted = Twist::new(
            f.stick(3, 0.02) * m.vx_m_s,
            -f.stick(2, 0.02) * m.vy_m_s,
            -f.stick(0, 0.02) * m.omega_rad_s,
        );
        let commanded = self.limiter.update(wanted, TICK_US as f32 * 1e-6);
        let rpm = self
            .kinematics
            .wheel_rpm_limited(commanded, drive.max_wheel_rpm);
        for (motor, target) in motors.iter().zip(rpm) {
            motor.set_target_rpm(target).map_err(|e| e.to_string())?;
        }
        let mut true_rpm = [0.0f32; 4];
        for (r, esc) in true_rpm.iter_mut().zip(escs) {
            *r = esc.speed_rpm() as f32;
        }
        Ok(ChassisSample {
            commanded,
            achieved: self.kinematics.twist(&true_rpm),
            link_lost: signal.lost,
        })
    }
}

/// A DBUS frame as a DR16 sends it for sticks in −1…1 (right x, right y, left x, left y), both
/// switches in the middle.
fn encode_dbus(sticks: [f32; 4]) -> [u8; 18] {
    let mut bits: u64 = 0;
    for (i, s) in sticks.iter().enumerate() {
        let raw = (1024.0 + 660.0 * f64::from(s.clamp(-1.0, 1.0))).round() as u64;
        bits |= raw << (11 * i);
    }
    bits |= 3 << 44 | 3 << 46;
    let mut frame = [0u8; 18];
    for (i, byte) in frame.iter_mut().take(6).enumerate() {
        *byte = (bits >> (8 * i)) as u8;
    }
    if let Some(wheel) = frame.get_mut(16..18) {
        wheel.copy_from_slice(&1024u16.to_le_bytes());
    }
    frame
}

fn in_window(t_ms: u64, from_ms: u64, to_ms: u64) -> bool {
    (from_ms..to_ms).contains(&t_ms)
}

/// Whether the controller's receive path is stalled at `t_ms`.
fn rx_stalled(scenario: &Scenario, t_ms: u64) -> bool {
    scenario
        .faults
        .iter()
        .any(|f| matches!(*f, Fault::RxStall { from_ms, to_ms } if in_window(t_ms, from_ms, to_ms)))
}

/// The receive delay in force at `t_ms`, µs.
fn delay_us(scenario: &Scenario, t_ms: u64) -> u64 {
    scenario
        .faults
        .iter()
        .filter_map(|f| match *f {
            Fault::Delay {
                delay_us,
                from_ms,
                to_ms,
            } if in_window(t_ms, from_ms, to_ms) => Some(delay_us),
            _ => None,
        })
        .max()
        .unwrap_or(0)
}

/// Applies loss and corruption to a frame that ended on the wire, hands it to the ESCs, and
/// returns it if the controller receives it.
fn deliver(
    scenario: &Scenario,
    rng: &mut Xoshiro256PlusPlus,
    bus: &mut SimBus,
    escs: &mut [DjiEsc],
    sender: Sender,
    frame: CanFrame,
    t_ms: u64,
) -> Option<CanFrame> {
    let mut frame = frame;
    for fault in &scenario.faults {
        match *fault {
            Fault::FrameLoss {
                probability,
                from_ms,
                to_ms,
            } if in_window(t_ms, from_ms, to_ms) && uniform(rng) < probability => {
                bus.record_lost();
                return None;
            }
            Fault::Corruption {
                probability,
                from_ms,
                to_ms,
            } if in_window(t_ms, from_ms, to_ms) && uniform(rng) < probability => {
                // A wrong DLC: the receiver must reject it, not parse garbage.
                let cut = frame
                    .data()
                    .len()
                    .saturating_sub(1 + (rng.next_u64() % 4) as usize);
                if let Some(short) =
                    CanFrame::new(frame.id(), frame.data().get(..cut).unwrap_or(&[]))
                {
                    frame = short;
                }
            }
            _ => {}
        }
    }
    for (i, esc) in escs.iter_mut().enumerate() {
        if sender != Sender::Device(i) {
            esc.on_frame(&frame);
        }
    }
    (sender != Sender::Mcu && !bus.mcu_bus_off()).then_some(frame)
}

fn apply_state_faults(
    scenario: &Scenario,
    bus: &mut SimBus,
    escs: &mut [DjiEsc],
    t_ms: u64,
    on_ms_edge: bool,
) {
    for fault in &scenario.faults {
        match *fault {
            Fault::BusOff { from_ms, to_ms } => {
                bus.set_mcu_bus_off(in_window(t_ms, from_ms, to_ms));
            }
            Fault::PowerCut {
                motor,
                from_ms,
                to_ms,
            } => {
                if let Some(esc) = escs.get_mut(motor) {
                    esc.set_powered(!in_window(t_ms, from_ms, to_ms));
                }
            }
            Fault::Stall {
                motor,
                from_ms,
                to_ms,
            } => {
                if let Some(esc) = escs.get_mut(motor) {
                    esc.set_locked(in_window(t_ms, from_ms, to_ms));
                }
            }
            Fault::OverTemperature {
                motor,
                at_ms,
                celsius,
            } if on_ms_edge && t_ms == at_ms => {
                if let Some(esc) = escs.get_mut(motor) {
                    esc.set_temperature_c(celsius);
                }
            }
            _ => {}
        }
    }
}

/// Step metrics of a target profile's last step, on the physical signal.
fn target_metrics(index: usize, spec: &TargetSpec, samples: &[Sample]) -> Option<TargetMetrics> {
    if spec.kind == TargetKind::Current {
        return None;
    }
    let &(at_ms, value) = spec.steps.last()?;
    let signal = |s: &MotorSample| match spec.kind {
        TargetKind::Rpm => s.true_rpm,
        _ => s.true_total_deg,
    };
    let pick = |s: &Sample| s.motors.get(spec.motor).copied();
    let before = samples.iter().find(|s| s.t_ms >= at_ms).and_then(pick)?;
    let y0 = signal(&before);
    let target = match spec.kind {
        // The shortest way from where the motor was.
        TargetKind::AngleDeg => y0 + f64::from(wrap_deg_180(value - y0 as f32)),
        _ => f64::from(value),
    };
    let (mut t, mut y, mut i) = (Vec::new(), Vec::new(), Vec::new());
    for s in samples.iter().filter(|s| s.t_ms >= at_ms) {
        if let Some(m) = pick(s) {
            t.push(s.t_ms as f64 * 1e-3);
            y.push(signal(&m));
            i.push(m.current_amps);
        }
    }
    Some(TargetMetrics {
        target: index,
        motor: spec.motor,
        kind: spec.kind,
        metrics: step_metrics(&t, &y, &i, at_ms as f64 * 1e-3, y0, target),
    })
}

fn m3508(esc_id: u8, controller: Controller) -> MotorSpec {
    MotorSpec {
        model: DjiModel::M3508,
        esc_id,
        load: Load::default(),
        controller,
    }
}

/// The built-in scenarios, the first being the default.
pub fn builtin() -> Vec<Scenario> {
    let base = |name: &str, description: &str, duration_ms: u64| Scenario {
        name: name.into(),
        description: description.into(),
        duration_ms,
        seed: 1,
        motors: Vec::new(),
        targets: Vec::new(),
        faults: Vec::new(),
        bus: BusConfig::DEFAULT,
        chassis: None,
    };
    let speed_step = |motor| TargetSpec {
        motor,
        kind: TargetKind::Rpm,
        steps: vec![(10, 300.0)],
    };
    vec![
        Scenario {
            motors: vec![m3508(1, Controller::Rc10)],
            targets: vec![speed_step(0)],
            ..base(
                "m3508-speed-step",
                "unloaded M3508, speed step 0 -> 300 rpm with rc10's default gains",
                400,
            )
        },
        Scenario {
            motors: vec![m3508(1, Controller::Rc10Legacy)],
            targets: vec![speed_step(0)],
            ..base(
                "m3508-speed-step-rc10lib",
                "the same step with RC10_LIB's demo speed loop, for comparison (3 s: it is slow)",
                3000,
            )
        },
        Scenario {
            motors: vec![MotorSpec {
                model: DjiModel::M2006,
                ..m3508(1, Controller::Rc10)
            }],
            targets: vec![speed_step(0)],
            ..base(
                "m2006-speed-step",
                "unloaded M2006, speed step 0 -> 300 rpm with rc10's default gains",
                400,
            )
        },
        Scenario {
            motors: vec![m3508(1, Controller::Rc10)],
            targets: vec![TargetSpec {
                motor: 0,
                kind: TargetKind::AngleDeg,
                steps: vec![(10, 350.0)],
            }],
            ..base(
                "m3508-angle-step",
                "M3508 angle step 0 -> 350 deg: the short way is 10 deg backwards",
                600,
            )
        },
        Scenario {
            motors: vec![MotorSpec {
                model: DjiModel::Gm6020Voltage,
                esc_id: 1,
                load: Load {
                    inertia_kg_m2: 0.01,
                    torque_nm: 0.0,
                    step: Some((400_000, 0.5)),
                },
                controller: Controller::Rc10,
            }],
            targets: vec![TargetSpec {
                motor: 0,
                kind: TargetKind::AngleDeg,
                steps: vec![(10, 90.0)],
            }],
            ..base(
                "gm6020-gimbal",
                "GM6020 gimbal (0.01 kg m^2) to 90 deg, then a 0.5 N m load torque step at 400 ms",
                800,
            )
        },
        Scenario {
            motors: (1..=4)
                .map(|id| MotorSpec {
                    load: Load {
                        inertia_kg_m2: 0.02,
                        ..Load::default()
                    },
                    ..m3508(id, Controller::Rc10)
                })
                .collect(),
            targets: (0..4)
                .map(|m| TargetSpec {
                    motor: m,
                    kind: TargetKind::Rpm,
                    steps: vec![(10, if m % 2 == 0 { 250.0 } else { -250.0 })],
                })
                .collect(),
            ..base(
                "chassis-4x-m3508",
                "four M3508 wheels (0.02 kg m^2 each) on one bus, +/-250 rpm",
                1000,
            )
        },
        Scenario {
            motors: vec![m3508(1, Controller::Rc10), m3508(2, Controller::Rc10)],
            targets: vec![
                TargetSpec {
                    motor: 0,
                    kind: TargetKind::Rpm,
                    steps: vec![(10, 200.0)],
                },
                TargetSpec {
                    motor: 1,
                    kind: TargetKind::Rpm,
                    steps: vec![(10, 200.0)],
                },
            ],
            faults: vec![
                Fault::PowerCut {
                    motor: 0,
                    from_ms: 300,
                    to_ms: 500,
                },
                Fault::FrameLoss {
                    probability: 0.05,
                    from_ms: 0,
                    to_ms: 1000,
                },
                Fault::Corruption {
                    probability: 0.01,
                    from_ms: 0,
                    to_ms: 1000,
                },
            ],
            ..base(
                "fault-power-cut",
                "two M3508 at 200 rpm; motor 1 loses power 300-500 ms; 5 % frame loss, 1 % corruption",
                1000,
            )
        },
        chassis_remote_drive(base(
            "chassis-remote-drive",
            "a DR16 drives a 16 kg mecanum chassis: forward, strafe, spin, diagonal, radio loss",
            4400,
        )),
    ]
}

/// A 16 kg RoboMaster-style mecanum chassis driven through a stick profile, with a radio loss.
fn chassis_remote_drive(base: Scenario) -> Scenario {
    // Each 76 mm wheel carries a quarter of 16 kg: 4 kg · 0.076² = 0.0231 kg·m² at its shaft,
    // and 0.05 N·m of rolling resistance.
    let wheel = |id| MotorSpec {
        load: Load {
            inertia_kg_m2: 0.0231,
            torque_nm: 0.05,
            step: None,
        },
        ..m3508(id, Controller::Rc10)
    };
    Scenario {
        motors: (1..=4).map(wheel).collect(),
        chassis: Some(ChassisDrive {
            geometry: MecanumConfig::new(0.4, 0.36, 0.076).with_wheel_signs([1.0, -1.0, 1.0, -1.0]),
            max_twist: Twist::new(2.0, 2.0, 4.0),
            max_accel: Twist::new(4.0, 4.0, 12.0),
            max_wheel_rpm: 400.0,
            sticks: vec![
                (0, [0.0; 4]),
                (200, [0.0, 0.0, 0.0, 1.0]),   // full forward
                (1000, [0.0, 0.0, -1.0, 0.0]), // strafe left
                (1800, [-0.5, 0.0, 0.0, 0.0]), // spin left at half stick
                (2600, [0.0, 0.0, -0.7, 0.7]), // diagonal forward-left
                (3600, [0.0; 4]),              // pilot lets go while the radio is off
            ],
            radio_off: vec![(3300, 3700)],
        }),
        ..base
    }
}
