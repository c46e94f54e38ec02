//! Scenarios (motors, targets, faults) and the world loop that runs rc10-core's real bus,
//! scheduler and drivers against the simulated bus and plants in deterministic virtual time.
//!
//! Time advances from event to event in whole microseconds: the rc10 tick every 1 ms, each
//! ESC's feedback every 1 ms at its own (seeded) phase, and frame ends on the bus. The plants
//! are integrated every 200 µs of virtual time, each step taken when something next reads or
//! changes them. Received frames are dispatched to rc10 the moment they end on the wire,
//! stamped with that time (an ideal RX interrupt); the controller's 3 TX buffers are modelled,
//! sent in FIFO or lowest-ID-first order ([`Scenario::tx_order`]). Ticks are paced by rc10's
//! `TickPacer`, as on a board.
//!
//! [`run_observed`] lets a [`RunObserver`] watch every frame and tick of a run; [`soak`] uses
//! it for the fault soak (`fault-soak`) and its checks.

mod builtin;
mod chassis_app;
mod faults;
mod metrics;
mod observe;
pub(crate) mod run;
mod rx;
pub mod soak;

pub use builtin::{builtin, builtin_named};
pub use chassis_app::{ChassisDrive, ChassisSample};
pub use faults::Fault;
pub use metrics::{MeasuredStep, StepWindow, TargetMetrics, measure_step, motor_step_windows};
pub use observe::{NoObserver, RunObserver, RxDrop, TickEvent, WireEvent};
pub use run::{run, run_observed, run_with_progress};

use crate::bus::{SimBusStats, TxOrder};
use crate::plant::Load;
use rc10_core::bus::{BusConfig, FrameBudget, RegisterError};
use rc10_core::can::BusCounters;
use rc10_core::can::acceptance::PlanError;
use rc10_core::motor::dji::{DjiConfig, DjiModel};
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
    /// rc10 bus configuration (bitrate, registration budget). The simulator ticks every
    /// 1 ms: a `tick_period` other than 1 ms is refused ([`SimError::TickPeriod`]).
    pub bus: BusConfig,
    /// Order in which the simulated controller sends its pending TX frames (the FDCAN's TX
    /// FIFO or TX queue mode); [`TxOrder::Fifo`], as rc10-stm32 configures the FDCAN, by
    /// default.
    pub tx_order: TxOrder,
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
    /// The motors' feedback IDs need more acceptance-filter elements than an STM32G4's
    /// FDCAN has (rc10-stm32's `start_can` would refuse the bus).
    Filters(PlanError),
    /// The bus configuration's `tick_period` (µs) is not the simulator's 1 ms tick: rc10's
    /// scheduler would pace ticks, `dt` and the load figures at a period the simulation
    /// does not run.
    TickPeriod {
        /// The configured period, µs.
        us: u64,
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
            Self::Filters(error) => write!(f, "the motors do not fit the FDCAN's filters: {error}"),
            Self::TickPeriod { us } => write!(
                f,
                "bus tick period {us} µs: the simulator ticks every 1000 µs"
            ),
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

/// The motors of one [`Sample`], in scenario order: stored inside the sample for up to four
/// motors (a chassis), on the heap beyond. It dereferences to `[MotorSample]`; build one with
/// `collect()` or [`smallvec!`](crate::smallvec::smallvec).
pub type MotorSamples = smallvec::SmallVec<[MotorSample; 4]>;

/// All motors at one tick.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Time, ms.
    pub t_ms: u64,
    /// One per motor, in scenario order.
    pub motors: MotorSamples,
    /// The chassis application's view, in chassis scenarios.
    pub chassis: Option<ChassisSample>,
}

/// What a run produced.
#[derive(Debug, Clone, PartialEq)]
pub struct RunResult {
    /// The scenario's name.
    pub name: String,
    /// One sample per tick (every ms, except during a [`Fault::SchedulerStall`]); a
    /// [`RunObserver`] may keep fewer ([`RunObserver::keep_sample`]).
    pub samples: Vec<Sample>,
    /// The simulated bus's counters.
    pub bus: SimBusStats,
    /// rc10's own bus counters.
    pub counters: BusCounters,
    /// rc10's frame budget for the registered motors.
    pub budget: FrameBudget,
    /// Offline events per motor, as rc10 counted them.
    pub offline_events: Vec<u32>,
    /// Frames lost because their RX FIFO was full (rc10's own `rx_overruns` counts the
    /// overruns its receiver reported: one per stall that lost frames, however many).
    pub rx_overruns: u64,
    /// Step metrics per stepped target.
    pub metrics: Vec<TargetMetrics>,
}
