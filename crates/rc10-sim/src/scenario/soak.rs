//! The fault soak: a whole robot under every injected fault for a long run, and the checks
//! that say whether rc10 kept its failure contract throughout (issue 11).
//!
//! [`fault_soak`] is the built-in scenario (`rc10-sim run fault-soak`): a 4×M3508 mecanum
//! chassis driven from a DR16 and a 2×GM6020 gimbal (voltage mode) on one 1 Mbit/s bus for
//! 10 simulated minutes, with 2 % random frame loss plus loss bursts, receive delays,
//! corrupted frames, three 1 s referee power cuts, a bus-off interval, a window in which no
//! node acknowledges, stalled receive paths (RX FIFO overruns), a locked rotor and scheduler
//! stalls.
//!
//! [`run_soak`] runs any scenario with a [`SoakObserver`] watching every frame and tick
//! (memory stays bounded: it keeps evidence, not traces), then [`evaluate`] turns the
//! [`SoakRecord`] into a [`SoakReport`] of pass/fail [`Check`]s. What each check expects is
//! derived from the scenario's own fault list, so the same checks serve the CLI, the test and
//! any scenario (`rc10-sim run <scenario> --checks`):
//!
//! 1. **no panic**: the run finished (a panic inside rc10 or the simulator is caught and
//!    reported, not fatal to the report);
//! 2. **power cuts detected**: every cut longer than the motor's offline timeout took it
//!    offline within that timeout of its last feedback (plus one tick), and within timeout
//!    plus two ticks of the cut; it stayed offline until power returned;
//! 3. **zero while offline**: every command frame on the wire packed while a motor was
//!    offline carries exactly 0 in its slot, and rc10's own command is 0.0 at every offline
//!    tick; frames packed before an outage that leave after it are allowed only where they
//!    were held in the TX buffers through a no-acknowledgement window (at most as many as
//!    the controller has buffers);
//! 4. **control resumes**: after every outage, a command packed with the motor online
//!    reaches its ESC within 10 ms of the first feedback rc10 accepted;
//! 5. **ESC range**: no slot on the wire beyond the ESC's range (M3508 / GM6020 current
//!    ±16384, M2006 ±10000, GM6020 voltage ±`voltage_raw_limit`, 25000 by default) and
//!    rc10's command always finite and within its limit;
//! 6. **scheduler**: every `dt` within [period/2, 10 periods], no two ticks closer than half
//!    a period, ticks run and ticks skipped exactly as the scheduler stalls imply, never more
//!    frames queued in a tick than the controller has TX buffers;
//! 7. **statistics**: rc10's counters equal the simulator's ground truth for every fault
//!    class injected (corrupted frames → `rx_rejected`; bus-off → `bus_off_events`,
//!    `tx_bus_off`; no acknowledgement → `tx_full`, `tx_stale`, `bus_errors`; RX stall →
//!    `rx_overruns`, one per stall that lost frames, as the receiver reports them; no
//!    feedback discarded by the acceptance filters; lost frames → frames received, feedback gaps, and each motor's offline
//!    events equal to the outages the fault windows imply).

use super::observe::{RunObserver, RxDrop, TickEvent, WireEvent};
use super::run::TICK_US;
use super::{
    ChassisDrive, Controller, Fault, MotorSpec, RunResult, Scenario, TargetKind, TargetSpec,
    run_observed,
};
use crate::bus::{Sender, SimBusConfig, SimBusStats, TxOrder};
use crate::output;
use crate::plant::Load;
use plotters::prelude::*;
use rc10_core::bus::{BusConfig, Dispatch};
use rc10_core::can::{BusCounters, CanFrame};
use rc10_core::chassis::{MecanumConfig, Twist};
use rc10_core::motor::dji::{DjiConfig, DjiModel};
use rc10_core::node::CommandSlot;
use std::collections::{HashMap, VecDeque};
use std::fmt::Write as _;
use std::io;
use std::path::{Path, PathBuf};

/// The built-in soak's name.
pub const NAME: &str = "fault-soak";

/// How long control may take to resume after feedback returns, µs.
pub const RESUME_LIMIT_US: u64 = 10_000;

/// The soak's length: 10 simulated minutes.
const SOAK_MS: u64 = 600_000;

/// Runs longer than this keep a thinned trace ([`SoakObserver::keep_sample`]).
const FULL_TRACE_MS: u64 = 60_000;
/// In a thinned trace: one sample every this many ms…
const OVERVIEW_EVERY_MS: u64 = 50;
/// …and every tick from this long before a fault window starts or ends…
const DETAIL_BEFORE_MS: u64 = 200;
/// …to this long after.
const DETAIL_AFTER_MS: u64 = 300;
/// Fault windows at least this long (the whole-run loss) get no detail in a thinned trace.
const DETAIL_MAX_WINDOW_MS: u64 = 10_000;

/// Examples kept per kind of violation (the count is always exact).
const EXAMPLES: usize = 5;
/// How long the observer remembers which tick packed which frame, µs.
const TICK_MEMORY_US: u64 = 60_000_000;

fn m3508(esc_id: u8) -> MotorSpec {
    // A quarter of a 16 kg chassis on a 76 mm wheel (as `chassis-remote-drive`).
    MotorSpec {
        model: DjiModel::M3508,
        esc_id,
        load: Load {
            inertia_kg_m2: 0.0231,
            friction_nm: 0.05,
            ..Load::default()
        },
        controller: Controller::Rc10,
    }
}

fn gm6020(esc_id: u8) -> MotorSpec {
    MotorSpec {
        model: DjiModel::Gm6020Voltage,
        esc_id,
        load: Load {
            inertia_kg_m2: 0.01,
            ..Load::default()
        },
        controller: Controller::Rc10,
    }
}

/// The `fault-soak` scenario: a 4×M3508 mecanum chassis (motors 1–4, ESC ids 1–4, driven
/// from a DR16 whose sticks change every 3 s) and a 2×GM6020 gimbal in voltage mode (motor 5
/// yaw and motor 6 pitch, ESC ids 1–2, new angle targets every 1.5 s) on one 1 Mbit/s bus
/// (six DJI motors: rc10's "marginal" budget, about 97 % real load) for 10 simulated minutes,
/// under:
///
/// | fault | when (s) |
/// |---|---|
/// | 2 % random frame loss | whole run |
/// | 0.5 % corrupted frames (wrong DLC), and 30 % for 1 s | whole run; 270–271 |
/// | loss bursts (every frame) of 20, 60, 250, 5 ms | 45, 95, 210, 480 |
/// | receive delay 300 µs, 800 µs | 120–130, 350–352 |
/// | referee power cuts of 1 s: motor 2 (wheel), 5 (yaw GM6020), 6 (pitch GM6020) | 60, 180, 420 |
/// | controller bus-off, 200 ms | 240 |
/// | no node acknowledges, 250 ms | 300 |
/// | receive path stalled, 30 ms and 150 ms (RX FIFO overruns) | 150, 390 |
/// | motor 3's rotor locked, 2 s | 450 |
/// | scheduler held up 5 ms and 40 ms | 330, 510 |
pub fn fault_soak() -> Scenario {
    let mut motors: Vec<MotorSpec> = (1..=4).map(m3508).collect();
    motors.extend([gm6020(1), gm6020(2)]);
    // Sticks (right x, right y, left x, left y): forward, strafe, spin, diagonal, back, stop…
    const STICKS: [[f32; 4]; 8] = [
        [0.0, 0.0, 0.0, 0.8],
        [0.0, 0.0, 0.7, 0.0],
        [0.6, 0.0, 0.0, 0.0],
        [0.0, 0.0, -0.5, 0.5],
        [0.0, 0.0, 0.0, -0.6],
        [0.0; 4],
        [-0.4, 0.0, 0.3, 0.3],
        [0.0, 0.0, -0.8, -0.2],
    ];
    let sticks = (0..SOAK_MS / 3000)
        .zip(STICKS.iter().cycle())
        .map(|(k, s)| (k * 3000, *s))
        .collect();
    // Every move shorter than half a turn and the cycle closes: the yaw does not wind up.
    const YAW: [f32; 8] = [0.0, 90.0, -45.0, 120.0, 30.0, -90.0, 60.0, -20.0];
    const PITCH: [f32; 6] = [0.0, 20.0, -15.0, 25.0, 5.0, -20.0];
    let profile = |values: &[f32]| -> Vec<(u64, f32)> {
        (0..SOAK_MS / 1500)
            .zip(values.iter().cycle())
            .map(|(k, v)| (10 + k * 1500, *v))
            .collect()
    };
    let gimbal = |motor, values: &[f32]| TargetSpec {
        motor,
        kind: TargetKind::AngleDeg,
        steps: profile(values),
    };
    let window = |from_s: f64, ms: u64| {
        let from_ms = (from_s * 1000.0) as u64;
        (from_ms, from_ms + ms)
    };
    let cut = |motor, from_s| {
        let (from_ms, to_ms) = window(from_s, 1000);
        Fault::PowerCut {
            motor,
            from_ms,
            to_ms,
        }
    };
    let burst = |from_s, ms| {
        let (from_ms, to_ms) = window(from_s, ms);
        Fault::FrameLoss {
            probability: 1.0,
            from_ms,
            to_ms,
        }
    };
    let mut faults = vec![
        Fault::FrameLoss {
            probability: 0.02,
            from_ms: 0,
            to_ms: SOAK_MS,
        },
        Fault::Corruption {
            probability: 0.005,
            from_ms: 0,
            to_ms: SOAK_MS,
        },
        Fault::Corruption {
            probability: 0.3,
            from_ms: 270_000,
            to_ms: 271_000,
        },
        burst(45.0, 20),
        burst(95.0, 60),
        burst(210.0, 250),
        burst(480.0, 5),
        Fault::Delay {
            delay_us: 300,
            from_ms: 120_000,
            to_ms: 130_000,
        },
        Fault::Delay {
            delay_us: 800,
            from_ms: 350_000,
            to_ms: 352_000,
        },
        cut(1, 60.0),
        cut(4, 180.0),
        cut(5, 420.0),
        Fault::BusOff {
            from_ms: 240_000,
            to_ms: 240_200,
        },
        Fault::NoAck {
            from_ms: 300_000,
            to_ms: 300_250,
        },
        Fault::RxStall {
            from_ms: 150_000,
            to_ms: 150_030,
        },
        Fault::RxStall {
            from_ms: 390_000,
            to_ms: 390_150,
        },
        Fault::Stall {
            motor: 2,
            from_ms: 450_000,
            to_ms: 452_000,
        },
        Fault::SchedulerStall {
            from_ms: 330_000,
            to_ms: 330_005,
        },
        Fault::SchedulerStall {
            from_ms: 510_000,
            to_ms: 510_040,
        },
    ];
    faults.sort_by_key(|f| window_of(f).map_or(0, |(from, _)| from));
    Scenario {
        name: NAME.into(),
        description: "4 x M3508 chassis + 2 x GM6020 gimbal, 10 min under loss, bursts, delay, \
                      corruption, 3 power cuts, bus-off, no ACK, RX stalls, locked rotor"
            .into(),
        duration_ms: SOAK_MS,
        seed: 1,
        motors,
        targets: vec![gimbal(4, &YAW), gimbal(5, &PITCH)],
        faults,
        bus: BusConfig::DEFAULT,
        tx_order: TxOrder::Fifo,
        chassis: Some(ChassisDrive {
            geometry: MecanumConfig::new(0.4, 0.36, 0.076).with_wheel_signs([1.0, -1.0, 1.0, -1.0]),
            max_twist: Twist::new(2.0, 2.0, 4.0),
            max_accel: Twist::new(4.0, 4.0, 12.0),
            max_wheel_rpm: 400.0,
            sticks,
            radio_off: Vec::new(),
        }),
    }
}

/// The window `[from_ms, to_ms)` of a fault, if it has one.
fn window_of(fault: &Fault) -> Option<(u64, u64)> {
    match *fault {
        Fault::PowerCut { from_ms, to_ms, .. }
        | Fault::Stall { from_ms, to_ms, .. }
        | Fault::FrameLoss { from_ms, to_ms, .. }
        | Fault::Delay { from_ms, to_ms, .. }
        | Fault::RxStall { from_ms, to_ms }
        | Fault::BusOff { from_ms, to_ms }
        | Fault::Corruption { from_ms, to_ms, .. }
        | Fault::NoAck { from_ms, to_ms }
        | Fault::SchedulerStall { from_ms, to_ms } => Some((from_ms, to_ms)),
        Fault::OverTemperature { .. } => None,
    }
}

/// A short name for a fault, for reports and plots.
pub fn fault_label(fault: &Fault) -> String {
    match *fault {
        Fault::PowerCut { motor, .. } => format!("power cut, motor {}", motor + 1),
        Fault::Stall { motor, .. } => format!("locked rotor, motor {}", motor + 1),
        Fault::OverTemperature { motor, .. } => format!("over-temperature, motor {}", motor + 1),
        Fault::FrameLoss { probability, .. } if probability >= 1.0 => "loss burst".into(),
        Fault::FrameLoss { probability, .. } => format!("{:.1} % frame loss", probability * 100.0),
        Fault::Delay { delay_us, .. } => format!("{delay_us} us receive delay"),
        Fault::RxStall { .. } => "RX stall".into(),
        Fault::BusOff { .. } => "bus-off".into(),
        Fault::Corruption { probability, .. } => {
            format!("{:.1} % corrupted", probability * 100.0)
        }
        Fault::NoAck { .. } => "no ACK".into(),
        Fault::SchedulerStall { .. } => "scheduler stall".into(),
    }
}

/// What the checks need to know about one motor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorLimits {
    /// The command slot it writes, if it is a DJI motor.
    pub slot: Option<CommandSlot>,
    /// Largest raw slot value its ESC accepts (rc10's configured limit).
    pub raw_limit: i32,
    /// Largest command rc10 may compute (amps, or volts in voltage mode).
    pub command_limit: f32,
    /// Silence after which rc10 must call it offline, µs.
    pub offline_timeout_us: u64,
    /// Model name for reports.
    pub model: &'static str,
}

impl MotorLimits {
    /// The limits of a scenario motor, from its model and rc10 configuration.
    pub fn of(spec: &MotorSpec) -> Self {
        let config = match spec.controller {
            Controller::Rc10With(cfg) => cfg,
            Controller::Rc10 | Controller::Rc10Legacy => DjiConfig::default_for(spec.model),
        };
        let (raw_limit, model) = match spec.model {
            DjiModel::M3508 => (16384, "M3508"),
            DjiModel::M2006 => (10000, "M2006"),
            DjiModel::Gm6020Current => (16384, "GM6020 current"),
            DjiModel::Gm6020Voltage => (i32::from(config.voltage_raw_limit), "GM6020 voltage"),
        };
        let command_limit = rc10_core::motor::dji::DjiMotor::new(spec.model, spec.esc_id, config)
            .map_or(0.0, |m| m.command_limit());
        Self {
            slot: spec.model.command_slot(spec.esc_id),
            raw_limit,
            command_limit,
            offline_timeout_us: config.health.offline_timeout.as_micros(),
            model,
        }
    }

    /// The value of this motor's slot in `frame`, if `frame` carries it.
    pub fn slot_value(&self, frame: &CanFrame) -> Option<i16> {
        let slot = self.slot?;
        if frame.is_extended() || frame.raw_id() != u32::from(slot.id()) {
            return None;
        }
        let i = 2 * usize::from(slot.index());
        match frame.data().get(i..i + 2) {
            Some(&[hi, lo]) => Some(i16::from_be_bytes([hi, lo])),
            _ => None,
        }
    }
}

/// A count of events of one kind and the first few of them, as `(time µs, value)`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Evidence {
    /// How many.
    pub count: u64,
    /// The first few: time in µs and a value (a raw slot, a command in milli-units, a dt in µs).
    pub first: Vec<(u64, i64)>,
}

impl Evidence {
    /// Records one event.
    pub fn push(&mut self, t_us: u64, value: i64) {
        self.count += 1;
        if self.first.len() < EXAMPLES {
            self.first.push((t_us, value));
        }
    }

    fn examples(&self) -> String {
        self.first
            .iter()
            .map(|(t, v)| format!("{} ({v})", ms(*t)))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// One period in which rc10 called a motor offline, and how it came back.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Outage {
    /// The first tick at which the motor was offline, µs.
    pub offline_at_us: u64,
    /// The last feedback rc10 accepted before that, µs.
    pub last_feedback_us: Option<u64>,
    /// The first feedback rc10 accepted after it, µs.
    pub feedback_back_us: Option<u64>,
    /// The first tick at which it was online again, µs.
    pub online_at_us: Option<u64>,
    /// When the first command packed with the motor online again reached its ESC, µs.
    pub resumed_us: Option<u64>,
}

/// What the soak saw of one motor.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MotorRecord {
    /// Its offline periods, in order.
    pub outages: Vec<Outage>,
    /// The largest |slot value| it was sent on the wire.
    pub max_abs_raw: i32,
    /// Frames on the wire whose slot lay beyond its ESC's range (value: the raw slot).
    pub beyond_range: Evidence,
    /// Ticks at which rc10's command was not finite or beyond its limit (value: milli-units).
    pub command_beyond_limit: Evidence,
    /// Frames packed while it was offline with a non-zero slot (value: the raw slot).
    pub nonzero_while_offline: Evidence,
    /// Offline ticks at which rc10's command was not exactly 0 (value: milli-units).
    pub command_nonzero_while_offline: Evidence,
    /// Frames packed while it was offline whose slot was 0 (the check at work).
    pub zero_frames_while_offline: u64,
    /// Feedback frames rc10 accepted.
    pub feedback_frames: u64,
    /// Intervals longer than 1.5 feedback periods between accepted feedback frames.
    pub feedback_gaps: u64,
    /// The longest such interval, µs.
    pub longest_gap_us: u64,
}

/// A command frame that left after a motor in it went offline, packed while it was online,
/// with a non-zero slot for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LateFrame {
    /// When it ended on the wire, µs.
    pub t_us: u64,
    /// When it was packed, µs.
    pub packed_us: u64,
    /// The motor.
    pub motor: usize,
    /// Its slot value.
    pub raw: i16,
}

/// The simulator's own count of what was injected and what happened, to hold rc10's counters
/// against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GroundTruth {
    /// Frames from devices that ended on the wire.
    pub device_frames: u64,
    /// Frames the injector removed from the wire (any sender).
    pub lost: u64,
    /// Of those, frames from devices (never reached the controller).
    pub lost_device_frames: u64,
    /// Frames the injector corrupted (any sender).
    pub corrupted: u64,
    /// Corrupted frames handed to rc10.
    pub corrupted_dispatched: u64,
    /// Frames handed to rc10.
    pub dispatched: u64,
    /// Device frames dropped because the controller was bus-off.
    pub dropped_bus_off: u64,
    /// Device frames the controller never heard because it was cut off (no ACK).
    pub dropped_no_ack: u64,
    /// Device frames dropped because their RX FIFO was full.
    pub overruns: u64,
    /// Overruns the simulated receive path reported to rc10.
    pub overrun_reports: u64,
    /// Receive-path stalls (merged windows) that lost frames to full FIFOs and ended before
    /// the run did: the overruns rc10-stm32's receiver would report, one each.
    pub stalls_that_lost: u64,
    /// Device frames the controller's acceptance filters discarded.
    pub filtered: u64,
    /// Entries into bus-off seen at ticks.
    pub bus_off_entries: u64,
    /// Frames the controller's port refused as bus-off.
    pub refused_bus_off: u64,
    /// Frames the controller's port refused as full.
    pub refused_full: u64,
    /// Frames found still holding TX buffers, summed over ticks.
    pub held_at_ticks: u64,
    /// Ticks at which the controller, cut off with frames pending, reported an ACK error.
    pub ack_error_ticks: u64,
    /// Ticks run while the controller was cut off.
    pub no_ack_ticks: u64,
}

/// What the scheduler did over the run.
#[derive(Debug, Clone, PartialEq)]
pub struct TickRecord {
    /// Ticks run.
    pub run: u64,
    /// Smallest and largest `dt` rc10's pacing gave, s.
    pub dt_range_s: (f32, f32),
    /// Ticks whose `dt` lay outside [period/2, 10 periods] (value: dt in µs).
    pub dt_out_of_bounds: Evidence,
    /// Smallest and largest interval between consecutive ticks, µs.
    pub gap_range_us: (u64, u64),
    /// Ticks closer than half a period to the previous (a burst; value: the interval, µs).
    pub bursts: Evidence,
    /// Ticks rc10's pacing counted as skipped, summed.
    pub skipped: u64,
    /// The most frames one tick queued.
    pub max_queued: u8,
    /// Ticks whose transmit report did not account for every packed frame (value: frames).
    pub unaccounted: Evidence,
}

impl Default for TickRecord {
    fn default() -> Self {
        Self {
            run: 0,
            dt_range_s: (f32::INFINITY, 0.0),
            dt_out_of_bounds: Evidence::default(),
            gap_range_us: (u64::MAX, 0),
            bursts: Evidence::default(),
            skipped: 0,
            max_queued: 0,
            unaccounted: Evidence::default(),
        }
    }
}

/// Everything the checks judge: evidence gathered during the run, and the counters at its
/// end. Self-contained, so a check can be shown to trip on a doctored record.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SoakRecord {
    /// Why the run did not finish: a panic's message or the simulator's error.
    pub aborted: Option<String>,
    /// The scheduler.
    pub ticks: TickRecord,
    /// One per motor, in scenario order.
    pub motors: Vec<MotorRecord>,
    /// Frames that left after their motor went offline, packed while it was online.
    pub late_frames: Vec<LateFrame>,
    /// Controller frames on the wire whose packing tick was no longer known.
    pub unattributed_frames: u64,
    /// The simulator's counts.
    pub truth: GroundTruth,
    /// rc10's bus counters at the end.
    pub counters: BusCounters,
    /// rc10's offline events per motor at the end.
    pub offline_events: Vec<u32>,
    /// The simulated bus's counters at the end.
    pub bus: SimBusStats,
}

/// A tick the observer still needs: which frames it queued and which motors were online.
#[derive(Debug, Clone, Copy)]
struct PackedTick {
    t_us: u64,
    first_seq: u64,
    queued: u64,
    /// Bit `i`: motor `i` online.
    online: u64,
}

/// Watches a run for the soak checks ([`RunObserver`]), keeping bounded evidence.
#[derive(Debug)]
pub struct SoakObserver {
    limits: Vec<MotorLimits>,
    record: SoakRecord,
    /// Recent ticks, oldest first.
    packed: VecDeque<PackedTick>,
    /// Bit `i`: motor `i` online at the last tick.
    online: u64,
    last_tick_us: Option<u64>,
    was_bus_off: bool,
    last_feedback_us: Vec<Option<u64>>,
    /// Corrupted copies on their way to the controller, by frame.
    corrupted_in_flight: HashMap<CanFrame, u32>,
    /// Windows `[from, to)` in ms where a thinned trace keeps every tick, sorted.
    detail: Vec<(u64, u64)>,
    detail_next: usize,
    thin: bool,
    /// The receive-path stalls (merged, ms) and whether each lost a frame.
    rx_stalls: Vec<((u64, u64), bool)>,
    duration_ms: u64,
}

fn bit(i: usize) -> u64 {
    u32::try_from(i)
        .ok()
        .and_then(|i| 1u64.checked_shl(i))
        .unwrap_or(0)
}

impl SoakObserver {
    /// An observer for `scenario`.
    pub fn new(scenario: &Scenario) -> Self {
        let n = scenario.motors.len();
        let mut detail: Vec<(u64, u64)> = scenario
            .faults
            .iter()
            .filter_map(window_of)
            .filter(|(from, to)| to.saturating_sub(*from) < DETAIL_MAX_WINDOW_MS)
            .flat_map(|(from, to)| {
                [
                    (
                        from.saturating_sub(DETAIL_BEFORE_MS),
                        from + DETAIL_AFTER_MS,
                    ),
                    (to.saturating_sub(DETAIL_BEFORE_MS), to + DETAIL_AFTER_MS),
                ]
            })
            .collect();
        detail.sort_unstable();
        Self {
            limits: scenario.motors.iter().map(MotorLimits::of).collect(),
            record: SoakRecord {
                motors: vec![MotorRecord::default(); n],
                ..SoakRecord::default()
            },
            packed: VecDeque::new(),
            online: 0,
            last_tick_us: None,
            was_bus_off: false,
            last_feedback_us: vec![None; n],
            corrupted_in_flight: HashMap::new(),
            detail,
            detail_next: 0,
            thin: scenario.duration_ms > FULL_TRACE_MS,
            rx_stalls: merged(
                scenario
                    .faults
                    .iter()
                    .filter(|f| matches!(f, Fault::RxStall { .. }))
                    .filter_map(window_of)
                    .collect(),
                scenario.duration_ms,
            )
            .into_iter()
            .map(|w| (w, false))
            .collect(),
            duration_ms: scenario.duration_ms,
        }
    }

    /// The record so far, completed with the run's end-of-run counters (or why it stopped).
    pub fn finish(mut self, result: Option<&RunResult>, aborted: Option<String>) -> SoakRecord {
        self.record.aborted = aborted;
        if let Some(r) = result {
            self.record.counters = r.counters;
            self.record.offline_events = r.offline_events.clone();
            self.record.bus = r.bus;
            self.record.truth.refused_bus_off = r.bus.mcu_tx_bus_off;
            self.record.truth.refused_full = r.bus.mcu_tx_full;
        }
        // A stall that lasts to the end of the run never hands its overrun to rc10.
        self.record.truth.stalls_that_lost = self
            .rx_stalls
            .iter()
            .filter(|&&((_, to), lost)| lost && to < self.duration_ms)
            .count() as u64;
        self.record
    }

    /// The tick that queued the controller frame with sequence number `seq`.
    fn packing_tick(&self, seq: u64) -> Option<PackedTick> {
        let i = self
            .packed
            .partition_point(|p| p.first_seq + p.queued <= seq);
        self.packed
            .get(i)
            .copied()
            .filter(|p| (p.first_seq..p.first_seq + p.queued).contains(&seq))
    }

    fn on_command_frame(&mut self, event: &WireEvent, seq: u64) {
        let Some(packed) = self.packing_tick(seq) else {
            self.record.unattributed_frames += 1;
            return;
        };
        // The ESCs act on the frame only if it arrived whole.
        let reached_escs = event.received.is_some() && !event.corrupted;
        for (i, (limits, rec)) in self.limits.iter().zip(&mut self.record.motors).enumerate() {
            let Some(raw) = limits.slot_value(&event.frame) else {
                continue;
            };
            let abs = i32::from(raw).abs();
            rec.max_abs_raw = rec.max_abs_raw.max(abs);
            if abs > limits.raw_limit {
                rec.beyond_range.push(event.t_us, i64::from(raw));
            }
            let packed_online = packed.online & bit(i) != 0;
            if !packed_online {
                if raw == 0 {
                    rec.zero_frames_while_offline += 1;
                } else {
                    rec.nonzero_while_offline.push(event.t_us, i64::from(raw));
                }
                continue;
            }
            if self.online & bit(i) == 0 && raw != 0 {
                self.record.late_frames.push(LateFrame {
                    t_us: event.t_us,
                    packed_us: packed.t_us,
                    motor: i,
                    raw,
                });
            }
            if reached_escs
                && let Some(o) = rec.outages.last_mut()
                && o.resumed_us.is_none()
                && o.online_at_us.is_some_and(|on| packed.t_us >= on)
            {
                o.resumed_us = Some(event.t_us);
            }
        }
    }
}

impl RunObserver for SoakObserver {
    fn on_wire(&mut self, event: &WireEvent) {
        let t = &mut self.record.truth;
        if event.corrupted {
            t.corrupted += 1;
        }
        if event.received.is_none() {
            t.lost += 1;
        }
        match event.sender {
            Sender::Device(_) => {
                t.device_frames += 1;
                match event.received {
                    None => t.lost_device_frames += 1,
                    Some(f) if event.corrupted => {
                        *self.corrupted_in_flight.entry(f).or_insert(0) += 1;
                    }
                    Some(_) => {}
                }
            }
            Sender::Mcu => {
                if let Some(seq) = event.mcu_seq {
                    self.on_command_frame(event, seq);
                }
            }
        }
    }

    fn on_dispatch(&mut self, t_us: u64, frame: &CanFrame, result: Dispatch) {
        self.record.truth.dispatched += 1;
        if let Some(n) = self.corrupted_in_flight.get_mut(frame) {
            self.record.truth.corrupted_dispatched += 1;
            *n -= 1;
            if *n == 0 {
                self.corrupted_in_flight.remove(frame);
            }
        }
        let Dispatch::Handled(i) = result else { return };
        let (Some(rec), Some(last)) = (
            self.record.motors.get_mut(i),
            self.last_feedback_us.get_mut(i),
        ) else {
            return;
        };
        rec.feedback_frames += 1;
        if let Some(prev) = *last {
            let gap = t_us.saturating_sub(prev);
            if gap * 2 > 3 * TICK_US {
                rec.feedback_gaps += 1;
                rec.longest_gap_us = rec.longest_gap_us.max(gap);
            }
        }
        *last = Some(t_us);
        if let Some(o) = rec.outages.last_mut()
            && o.feedback_back_us.is_none()
        {
            o.feedback_back_us = Some(t_us);
        }
    }

    fn on_rx_dropped(&mut self, t_us: u64, frame: &CanFrame, why: RxDrop) {
        let t = &mut self.record.truth;
        match why {
            RxDrop::BusOff => t.dropped_bus_off += 1,
            RxDrop::NoAck => t.dropped_no_ack += 1,
            RxDrop::Overrun => {
                t.overruns += 1;
                let t_ms = t_us / 1000;
                if let Some((_, lost)) = self
                    .rx_stalls
                    .iter_mut()
                    .find(|((from, to), _)| (*from..*to).contains(&t_ms))
                {
                    *lost = true;
                }
            }
            RxDrop::Filtered => t.filtered += 1,
        }
        if let Some(n) = self.corrupted_in_flight.get_mut(frame) {
            *n -= 1;
            if *n == 0 {
                self.corrupted_in_flight.remove(frame);
            }
        }
    }

    fn on_overrun_reported(&mut self, _t_us: u64) {
        self.record.truth.overrun_reports += 1;
    }

    fn on_tick(&mut self, tick: &TickEvent<'_>) {
        let period = TICK_US;
        let r = &mut self.record;
        // The scheduler.
        let s = &mut r.ticks;
        s.run += 1;
        let dt = tick.paced.dt_s;
        s.dt_range_s = (s.dt_range_s.0.min(dt), s.dt_range_s.1.max(dt));
        let dt_us = f64::from(dt) * 1e6;
        if !(dt_us >= period as f64 / 2.0 - 1e-3 && dt_us <= 10.0 * period as f64 + 1e-3) {
            s.dt_out_of_bounds.push(tick.t_us, dt_us.round() as i64);
        }
        if let Some(prev) = self.last_tick_us {
            let gap = tick.t_us.saturating_sub(prev);
            s.gap_range_us = (s.gap_range_us.0.min(gap), s.gap_range_us.1.max(gap));
            if gap * 2 < period {
                s.bursts
                    .push(tick.t_us, i64::try_from(gap).unwrap_or(i64::MAX));
            }
        }
        self.last_tick_us = Some(tick.t_us);
        if tick.paced.resync {
            s.skipped += u64::from(tick.paced.skipped);
        }
        let rep = tick.report;
        s.max_queued = s.max_queued.max(rep.queued);
        let accounted = usize::from(rep.queued) + usize::from(rep.full) + usize::from(rep.bus_off);
        if accounted != tick.batch.frames().len() {
            s.unaccounted
                .push(tick.t_us, i64::try_from(accounted).unwrap_or(i64::MAX));
        }
        // The transport, as the simulator saw it.
        let t = &mut r.truth;
        t.held_at_ticks += tick.held_before as u64;
        if tick.no_ack {
            t.no_ack_ticks += 1;
            if tick.held_before > 0 {
                t.ack_error_ticks += 1;
            }
        }
        if tick.bus_off && !self.was_bus_off {
            t.bus_off_entries += 1;
        }
        self.was_bus_off = tick.bus_off;
        // The motors.
        let mut online = 0u64;
        for (i, ((m, rec), limits)) in tick
            .sample
            .motors
            .iter()
            .zip(&mut r.motors)
            .zip(&self.limits)
            .enumerate()
        {
            if !(m.command.is_finite() && m.command.abs() <= limits.command_limit * (1.0 + 1e-6)) {
                rec.command_beyond_limit
                    .push(tick.t_us, (f64::from(m.command) * 1e3) as i64);
            }
            let was_online = self.online & bit(i) != 0;
            if m.online {
                online |= bit(i);
                if !was_online
                    && let Some(o) = rec.outages.last_mut()
                    && o.online_at_us.is_none()
                {
                    o.online_at_us = Some(tick.t_us);
                }
            } else {
                if m.command != 0.0 {
                    rec.command_nonzero_while_offline
                        .push(tick.t_us, (f64::from(m.command) * 1e3) as i64);
                }
                if was_online {
                    rec.outages.push(Outage {
                        offline_at_us: tick.t_us,
                        last_feedback_us: self.last_feedback_us.get(i).copied().flatten(),
                        ..Outage::default()
                    });
                }
            }
        }
        self.online = online;
        self.packed.push_back(PackedTick {
            t_us: tick.t_us,
            first_seq: tick.first_seq,
            queued: u64::from(tick.report.queued),
            online,
        });
        while self
            .packed
            .front()
            .is_some_and(|p| p.t_us + TICK_MEMORY_US < tick.t_us)
        {
            self.packed.pop_front();
        }
    }

    fn keep_sample(&mut self, t_ms: u64) -> bool {
        if !self.thin {
            return true;
        }
        while self
            .detail
            .get(self.detail_next)
            .is_some_and(|w| w.1 <= t_ms)
        {
            self.detail_next += 1;
        }
        // Windows are sorted by start; any window from `detail_next` on that has started covers
        // `t_ms` (they may overlap, so look at all that have started).
        let in_detail = self
            .detail
            .iter()
            .skip(self.detail_next)
            .take_while(|w| w.0 <= t_ms)
            .any(|w| t_ms < w.1);
        in_detail || t_ms.is_multiple_of(OVERVIEW_EVERY_MS)
    }
}

/// A time in µs as seconds with ms precision, for reports.
fn ms(t_us: u64) -> String {
    format!("{:.3} s", t_us as f64 * 1e-6)
}

/// A duration in µs as milliseconds.
fn dur(us: u64) -> String {
    format!("{:.1} ms", us as f64 * 1e-3)
}

/// Which check.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CheckId {
    /// The run finished without a panic.
    NoPanic,
    /// Every power cut was detected offline within the offline timeout.
    PowerCuts,
    /// Offline motors were commanded exactly zero, on the wire and in rc10's state.
    ZeroWhileOffline,
    /// Control resumed within [`RESUME_LIMIT_US`] of feedback returning.
    Resume,
    /// No command beyond an ESC's range.
    EscRange,
    /// The scheduler never blocked or burst.
    Scheduler,
    /// rc10's statistics counted every injected fault class.
    Statistics,
}

impl CheckId {
    /// Every check, in report order.
    pub const ALL: [Self; 7] = [
        Self::NoPanic,
        Self::PowerCuts,
        Self::ZeroWhileOffline,
        Self::Resume,
        Self::EscRange,
        Self::Scheduler,
        Self::Statistics,
    ];

    /// What it checks, in a few words.
    pub const fn title(self) -> &'static str {
        match self {
            Self::NoPanic => "no panic",
            Self::PowerCuts => "every power cut detected offline within the offline timeout",
            Self::ZeroWhileOffline => "command exactly zero while offline (frames on the wire)",
            Self::Resume => "control resumes within 10 ms of feedback returning",
            Self::EscRange => "no command beyond an ESC's range",
            Self::Scheduler => "scheduler never blocks or bursts",
            Self::Statistics => "statistics count every injected fault class",
        }
    }
}

/// One check's verdict and the figures behind it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Check {
    /// Which check.
    pub id: CheckId,
    /// Whether it passed.
    pub passed: bool,
    /// What was measured (one line each; failures say so).
    pub lines: Vec<String>,
}

/// The soak's verdict: a header and every check.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SoakReport {
    /// What was run and injected.
    pub header: Vec<String>,
    /// Every check, in [`CheckId::ALL`] order.
    pub checks: Vec<Check>,
}

impl SoakReport {
    /// Whether every check passed.
    pub fn passed(&self) -> bool {
        self.checks.iter().all(|c| c.passed)
    }

    /// The check `id`.
    pub fn check(&self, id: CheckId) -> Option<&Check> {
        self.checks.iter().find(|c| c.id == id)
    }

    /// The checks that failed.
    pub fn failed(&self) -> Vec<CheckId> {
        self.checks
            .iter()
            .filter(|c| !c.passed)
            .map(|c| c.id)
            .collect()
    }

    /// The report as text: header, `[PASS]`/`[FAIL]` per check with its figures, verdict.
    pub fn text(&self) -> String {
        let mut s = String::new();
        for h in &self.header {
            let _ = writeln!(s, "{h}");
        }
        for c in &self.checks {
            let _ = writeln!(
                s,
                "\n[{}] {}",
                if c.passed { "PASS" } else { "FAIL" },
                c.id.title()
            );
            for l in &c.lines {
                let _ = writeln!(s, "       {l}");
            }
        }
        let passed = self.checks.iter().filter(|c| c.passed).count();
        let _ = writeln!(
            s,
            "\nsoak      {}: {passed} of {} checks passed",
            if self.passed() { "PASS" } else { "FAIL" },
            self.checks.len()
        );
        s
    }
}

/// Windows `[from_ms, to_ms)` clipped to the run, merged where they overlap or touch.
fn merged(mut windows: Vec<(u64, u64)>, duration_ms: u64) -> Vec<(u64, u64)> {
    windows.retain_mut(|w| {
        w.1 = w.1.min(duration_ms);
        w.0 < w.1
    });
    windows.sort_unstable();
    let mut out: Vec<(u64, u64)> = Vec::new();
    for w in windows {
        match out.last_mut() {
            Some(last) if w.0 <= last.1 => last.1 = last.1.max(w.1),
            _ => out.push(w),
        }
    }
    out
}

/// Windows in which no feedback of `motor` can reach rc10: its power cuts, bus-off, no
/// acknowledgement, stalled receive path, and loss or corruption of every frame.
fn silent_windows(scenario: &Scenario, motor: usize) -> Vec<(u64, u64)> {
    let windows = scenario
        .faults
        .iter()
        .filter(|f| match **f {
            Fault::PowerCut { motor: m, .. } => m == motor,
            Fault::BusOff { .. } | Fault::NoAck { .. } | Fault::RxStall { .. } => true,
            Fault::FrameLoss { probability, .. } | Fault::Corruption { probability, .. } => {
                probability >= 1.0
            }
            _ => false,
        })
        .filter_map(window_of)
        .collect();
    merged(windows, scenario.duration_ms)
}

/// Silence within this of the offline timeout may or may not take a motor offline (the
/// feedback phase, a lost frame at the edge).
const AMBIGUOUS_US: u64 = 3_000;

/// The offline events `motor` must have, as a range: one per silent window longer than its
/// offline timeout (windows within [`AMBIGUOUS_US`] of it may count either way).
fn expected_offline_events(scenario: &Scenario, motor: usize, timeout_us: u64) -> (u64, u64) {
    silent_windows(scenario, motor)
        .iter()
        .fold((0, 0), |(lo, hi), (from, to)| {
            let len = (to - from) * 1000;
            if len > timeout_us + AMBIGUOUS_US {
                (lo + 1, hi + 1)
            } else if len + AMBIGUOUS_US > timeout_us {
                (lo, hi + 1)
            } else {
                (lo, hi)
            }
        })
}

/// The fault that explains an outage starting at `offline_at_us` for `motor`.
fn cause(scenario: &Scenario, motor: usize, offline_at_us: u64, timeout_us: u64) -> String {
    scenario
        .faults
        .iter()
        .filter(|f| match **f {
            Fault::PowerCut { motor: m, .. } => m == motor,
            Fault::BusOff { .. } | Fault::NoAck { .. } | Fault::RxStall { .. } => true,
            Fault::FrameLoss { probability, .. } | Fault::Corruption { probability, .. } => {
                probability >= 1.0
            }
            _ => false,
        })
        .find(|f| {
            window_of(f).is_some_and(|(from, to)| {
                from * 1000 <= offline_at_us && offline_at_us <= to * 1000 + timeout_us + 5_000
            })
        })
        .map_or_else(|| "no injected fault".into(), fault_label)
}

fn check(id: CheckId, passed: bool, lines: Vec<String>) -> Check {
    Check { id, passed, lines }
}

/// Judges a record against what `scenario` injected.
pub fn evaluate(scenario: &Scenario, record: &SoakRecord) -> SoakReport {
    let limits: Vec<MotorLimits> = scenario.motors.iter().map(MotorLimits::of).collect();
    let mut header = vec![format!(
        "soak      {}: {} ms simulated, seed {}, {} motors",
        scenario.name,
        scenario.duration_ms,
        scenario.seed,
        scenario.motors.len()
    )];
    for (k, f) in scenario.faults.iter().enumerate() {
        let when = match *f {
            Fault::OverTemperature { at_ms, .. } => format!("at {:.3} s", at_ms as f64 * 1e-3),
            _ => window_of(f).map_or_else(String::new, |(from, to)| {
                format!("{:.3}-{:.3} s", from as f64 * 1e-3, to as f64 * 1e-3)
            }),
        };
        let lead = if k == 0 { "injected" } else { "" };
        header.push(format!("{lead:<9} {:<28} {when}", fault_label(f)));
    }
    if let Some(why) = &record.aborted {
        let mut checks = vec![check(
            CheckId::NoPanic,
            false,
            vec![format!("the run did not finish: {why}")],
        )];
        checks.extend(
            CheckId::ALL
                .iter()
                .skip(1)
                .map(|&id| check(id, false, vec!["not judged: the run did not finish".into()])),
        );
        return SoakReport { header, checks };
    }
    SoakReport {
        header,
        checks: vec![
            check(
                CheckId::NoPanic,
                true,
                vec![format!("the run finished: {} ticks", record.ticks.run)],
            ),
            power_cuts(scenario, record, &limits),
            zero_while_offline(scenario, record),
            resume(scenario, record, &limits),
            esc_range(record, &limits),
            scheduler(scenario, record),
            statistics(scenario, record, &limits),
        ],
    }
}

fn power_cuts(scenario: &Scenario, record: &SoakRecord, limits: &[MotorLimits]) -> Check {
    let mut ok = true;
    let mut lines = Vec::new();
    for f in &scenario.faults {
        let Fault::PowerCut {
            motor,
            from_ms,
            to_ms,
        } = *f
        else {
            continue;
        };
        let (Some(l), Some(rec)) = (limits.get(motor), record.motors.get(motor)) else {
            ok = false;
            lines.push(format!("power cut of motor {}: no such motor", motor + 1));
            continue;
        };
        let timeout = l.offline_timeout_us;
        if from_ms >= scenario.duration_ms {
            continue; // after the end of the run
        }
        let (from, to) = (from_ms * 1000, to_ms.min(scenario.duration_ms) * 1000);
        let who = format!("motor {} ({}) cut at {}", motor + 1, l.model, ms(from));
        if to.saturating_sub(from) <= timeout + AMBIGUOUS_US {
            lines.push(format!(
                "{who}: {} is not longer than the offline timeout {}, not judged",
                dur(to - from),
                dur(timeout)
            ));
            continue;
        }
        let Some(o) = rec
            .outages
            .iter()
            .find(|o| (from..to).contains(&o.offline_at_us))
        else {
            ok = false;
            lines.push(format!("{who}: FAIL, never went offline during the cut"));
            continue;
        };
        let after_cut = o.offline_at_us - from;
        let after_feedback = o
            .last_feedback_us
            .map(|f| o.offline_at_us.saturating_sub(f));
        let mut problems = Vec::new();
        if after_cut > timeout + 2 * TICK_US {
            problems.push(format!(
                "offline {} after the cut, more than the timeout {} plus two ticks",
                dur(after_cut),
                dur(timeout)
            ));
        }
        match after_feedback {
            Some(a) if a <= timeout => problems.push(format!(
                "offline only {} after its last feedback, before the timeout {}",
                dur(a),
                dur(timeout)
            )),
            Some(a) if a > timeout + TICK_US => problems.push(format!(
                "offline {} after its last feedback, more than the timeout {} plus a tick",
                dur(a),
                dur(timeout)
            )),
            _ => {}
        }
        if o.online_at_us.is_some_and(|on| on < to) {
            problems.push("came back online while still unpowered".into());
        }
        let back = match (o.feedback_back_us, o.resumed_us) {
            (Some(f), Some(r)) => format!(
                "; power back at {}: feedback {} later, control {} after that",
                ms(to),
                dur(f.saturating_sub(to)),
                dur(r.saturating_sub(f))
            ),
            _ => String::new(),
        };
        let line = format!(
            "{who}: offline {} after the cut ({} after its last feedback; timeout {}){back}",
            dur(after_cut),
            after_feedback.map_or_else(|| "no feedback before".into(), dur),
            dur(timeout)
        );
        if problems.is_empty() {
            lines.push(line);
        } else {
            ok = false;
            lines.push(format!("{line}: FAIL, {}", problems.join("; ")));
        }
    }
    if lines.is_empty() {
        lines.push("no power cut injected".into());
    }
    check(CheckId::PowerCuts, ok, lines)
}

fn zero_while_offline(scenario: &Scenario, record: &SoakRecord) -> Check {
    let mut ok = true;
    let mut lines = Vec::new();
    let mut checked = 0u64;
    for (i, rec) in record.motors.iter().enumerate() {
        checked += rec.zero_frames_while_offline;
        let mut line = format!(
            "motor {}: {} outages, {} frames packed while offline, all slots 0",
            i + 1,
            rec.outages.len(),
            rec.zero_frames_while_offline + rec.nonzero_while_offline.count
        );
        if rec.nonzero_while_offline.count > 0 {
            ok = false;
            line = format!(
                "motor {}: FAIL, {} frames packed while offline carry a non-zero slot: {}",
                i + 1,
                rec.nonzero_while_offline.count,
                rec.nonzero_while_offline.examples()
            );
        }
        lines.push(line);
        if rec.command_nonzero_while_offline.count > 0 {
            ok = false;
            lines.push(format!(
                "motor {}: FAIL, rc10's command not 0.0 at {} offline ticks (mA or mV): {}",
                i + 1,
                rec.command_nonzero_while_offline.count,
                rec.command_nonzero_while_offline.examples()
            ));
        }
    }
    if record.unattributed_frames > 0 {
        ok = false;
        lines.push(format!(
            "FAIL, {} command frames could not be traced to the tick that packed them",
            record.unattributed_frames
        ));
    }
    if checked == 0 && record.motors.iter().any(|m| !m.outages.is_empty()) {
        ok = false;
        lines.push("FAIL, motors went offline but no frame packed while offline was seen".into());
    }
    // Frames packed before an outage and sent after it: only out of the TX buffers that held
    // them through a no-ACK or bus-off window.
    let depth = SimBusConfig::default().mcu_tx_depth;
    let holding: Vec<(u64, u64, &str)> = scenario
        .faults
        .iter()
        .filter_map(|f| match f {
            Fault::NoAck { .. } => window_of(f).map(|(a, b)| (a, b, "no-ACK")),
            Fault::BusOff { .. } => window_of(f).map(|(a, b)| (a, b, "bus-off")),
            _ => None,
        })
        .collect();
    let mut per_window: HashMap<(u64, u64, &str), Vec<&LateFrame>> = HashMap::new();
    for late in &record.late_frames {
        let held = holding.iter().find(|(from, to, _)| {
            late.packed_us < to * 1000
                && late.packed_us + TICK_US >= from * 1000
                && late.t_us >= to * 1000
                && late.t_us <= to * 1000 + 5_000
        });
        match held {
            Some(w) => per_window.entry(*w).or_default().push(late),
            None => {
                ok = false;
                lines.push(format!(
                    "FAIL, a command packed at {} for motor {} (raw {}) left at {}, after the \
                     motor went offline, and not out of a no-ACK or bus-off window's TX buffers",
                    ms(late.packed_us),
                    late.motor + 1,
                    late.raw,
                    ms(late.t_us)
                ));
            }
        }
    }
    let mut windows: Vec<_> = per_window.into_iter().collect();
    windows.sort_unstable_by_key(|(w, _)| *w);
    for ((_, to, kind), frames) in windows {
        let mut times: Vec<u64> = frames.iter().map(|f| f.t_us).collect();
        times.dedup();
        let max_raw = frames
            .iter()
            .map(|f| i32::from(f.raw).abs())
            .max()
            .unwrap_or(0);
        let n = times.len();
        let verdict = if n > depth {
            ok = false;
            format!("FAIL, more than the {depth} TX buffers hold")
        } else {
            format!("at most the {depth} TX buffers")
        };
        lines.push(format!(
            "after the {kind} window ending {}: {n} frames held through it left within {} \
             carrying commands packed before it (|raw| up to {max_raw}) to motors rc10 had \
             called offline ({verdict}); frames in the TX buffers cannot be withdrawn",
            ms(to * 1000),
            dur(times.last().map_or(0, |t| t.saturating_sub(to * 1000)))
        ));
    }
    check(CheckId::ZeroWhileOffline, ok, lines)
}

fn resume(scenario: &Scenario, record: &SoakRecord, limits: &[MotorLimits]) -> Check {
    let mut ok = true;
    let mut lines = Vec::new();
    let mut count = 0usize;
    let mut worst: Option<(u64, usize, u64)> = None;
    for (i, (rec, l)) in record.motors.iter().zip(limits).enumerate() {
        for o in &rec.outages {
            let why = cause(scenario, i, o.offline_at_us, l.offline_timeout_us);
            let Some(back) = o.feedback_back_us else {
                lines.push(format!(
                    "motor {} offline from {} ({why}): no feedback before the end",
                    i + 1,
                    ms(o.offline_at_us)
                ));
                continue;
            };
            count += 1;
            match o.resumed_us {
                Some(r) if r.saturating_sub(back) <= RESUME_LIMIT_US => {
                    let latency = r.saturating_sub(back);
                    if worst.is_none_or(|(w, _, _)| latency > w) {
                        worst = Some((latency, i, o.offline_at_us));
                    }
                }
                Some(r) => {
                    ok = false;
                    lines.push(format!(
                        "FAIL, motor {} ({why}, offline at {}): control resumed {} after feedback \
                         returned at {}",
                        i + 1,
                        ms(o.offline_at_us),
                        dur(r.saturating_sub(back)),
                        ms(back)
                    ));
                }
                None => {
                    ok = false;
                    lines.push(format!(
                        "FAIL, motor {} ({why}, offline at {}): feedback returned at {} but no \
                         command packed online reached its ESC",
                        i + 1,
                        ms(o.offline_at_us),
                        ms(back)
                    ));
                }
            }
        }
    }
    let summary = match worst {
        Some((latency, motor, at)) => format!(
            "{count} returns from offline; worst {} from the first feedback to a closed-loop \
             command at the ESC (motor {} after the {} at {})",
            dur(latency),
            motor + 1,
            limits.get(motor).map_or_else(String::new, |l| cause(
                scenario,
                motor,
                at,
                l.offline_timeout_us
            )),
            ms(at)
        ),
        None => format!("{count} returns from offline"),
    };
    lines.insert(0, summary);
    check(CheckId::Resume, ok, lines)
}

fn esc_range(record: &SoakRecord, limits: &[MotorLimits]) -> Check {
    let mut ok = true;
    let mut lines = Vec::new();
    for (i, (rec, l)) in record.motors.iter().zip(limits).enumerate() {
        let mut line = format!(
            "motor {} ({}): largest |raw| on the wire {} of {}",
            i + 1,
            l.model,
            rec.max_abs_raw,
            l.raw_limit
        );
        if rec.beyond_range.count > 0 || rec.max_abs_raw > l.raw_limit {
            ok = false;
            let _ = write!(
                line,
                ": FAIL, {} frames beyond it: {}",
                rec.beyond_range.count,
                rec.beyond_range.examples()
            );
        }
        if rec.command_beyond_limit.count > 0 {
            ok = false;
            let _ = write!(
                line,
                "; FAIL, rc10's command not finite or beyond {} at {} ticks (milli-units): {}",
                l.command_limit,
                rec.command_beyond_limit.count,
                rec.command_beyond_limit.examples()
            );
        }
        lines.push(line);
    }
    check(CheckId::EscRange, ok, lines)
}

fn scheduler(scenario: &Scenario, record: &SoakRecord) -> Check {
    let t = &record.ticks;
    let c = &record.counters;
    let stalls = merged(
        scenario
            .faults
            .iter()
            .filter(|f| matches!(f, Fault::SchedulerStall { .. }))
            .filter_map(window_of)
            .collect(),
        scenario.duration_ms,
    );
    let stalled_ms: u64 = stalls.iter().map(|(a, b)| b - a).sum();
    // A stall that starts the run delays the first tick (nothing to skip yet); one that ends
    // the run is never followed by a late tick.
    let expected_skipped: u64 = stalls
        .iter()
        .filter(|(a, b)| *a > 0 && *b < scenario.duration_ms)
        .map(|(a, b)| b - a)
        .sum();
    let expected_run = scenario.duration_ms - stalled_ms;
    let depth = SimBusConfig::default().mcu_tx_depth;
    let mut ok = true;
    let mut lines = vec![format!(
        "{} ticks run (rc10 counted {}), {} skipped (rc10 counted {}), expected {} and {} from \
         {} scheduler stalls",
        t.run,
        c.ticks,
        t.skipped,
        c.ticks_skipped,
        expected_run,
        expected_skipped,
        stalls.len()
    )];
    if t.run != expected_run
        || u64::from(c.ticks) != expected_run
        || t.skipped != expected_skipped
        || u64::from(c.ticks_skipped) != expected_skipped
    {
        ok = false;
        lines.push("FAIL, ticks run or skipped differ from what the stalls imply".into());
    }
    let period_ms = TICK_US as f64 * 1e-3;
    lines.push(format!(
        "dt {:.3}-{:.3} ms (bounds {:.3}-{:.3} ms); tick intervals {}-{}",
        f64::from(t.dt_range_s.0) * 1e3,
        f64::from(t.dt_range_s.1) * 1e3,
        period_ms / 2.0,
        period_ms * 10.0,
        dur(t.gap_range_us.0),
        dur(t.gap_range_us.1)
    ));
    if t.dt_out_of_bounds.count > 0 {
        ok = false;
        lines.push(format!(
            "FAIL, {} ticks with dt out of bounds (µs): {}",
            t.dt_out_of_bounds.count,
            t.dt_out_of_bounds.examples()
        ));
    }
    if t.bursts.count > 0 {
        ok = false;
        lines.push(format!(
            "FAIL, {} ticks less than half a period after the previous (a burst; µs): {}",
            t.bursts.count,
            t.bursts.examples()
        ));
    }
    lines.push(format!(
        "at most {} frames queued in one tick ({depth} TX buffers); every packed frame queued \
         or refused at once",
        t.max_queued
    ));
    if usize::from(t.max_queued) > depth {
        ok = false;
        lines.push("FAIL, a tick queued more frames than the TX buffers hold".into());
    }
    if t.unaccounted.count > 0 {
        ok = false;
        lines.push(format!(
            "FAIL, {} ticks left packed frames neither queued nor refused: {}",
            t.unaccounted.count,
            t.unaccounted.examples()
        ));
    }
    check(CheckId::Scheduler, ok, lines)
}

/// One statistics line: `rc10` against the simulator's `truth`, which must be non-zero when
/// the fault was `injected`.
fn stat_line(ok: &mut bool, what: &str, rc10: u64, truth: u64, injected: bool) -> String {
    let fine = rc10 == truth && (!injected || truth > 0);
    *ok &= fine;
    let note = if fine {
        ""
    } else if rc10 != truth {
        ": FAIL, rc10's count differs"
    } else {
        ": FAIL, injected but never counted"
    };
    format!("{what}: rc10 {rc10}, simulator {truth}{note}")
}

fn statistics(scenario: &Scenario, record: &SoakRecord, limits: &[MotorLimits]) -> Check {
    let c = &record.counters;
    let t = &record.truth;
    // Injected: listed, and starting before the run ends.
    let has = |p: &dyn Fn(&Fault) -> bool| {
        scenario
            .faults
            .iter()
            .any(|f| p(f) && window_of(f).is_none_or(|(from, _)| from < scenario.duration_ms))
    };
    let corruption = has(&|f| matches!(f, Fault::Corruption { .. }));
    let bus_off_windows = merged(
        scenario
            .faults
            .iter()
            .filter(|f| matches!(f, Fault::BusOff { .. }))
            .filter_map(window_of)
            .collect(),
        scenario.duration_ms,
    );
    let no_ack = has(&|f| matches!(f, Fault::NoAck { .. }));
    let rx_stall = has(&|f| matches!(f, Fault::RxStall { .. }));
    let loss = has(&|f| matches!(f, Fault::FrameLoss { .. }));
    let mut ok = true;
    let mut lines = vec![
        stat_line(
            &mut ok,
            "corrupted frames -> rx_rejected (wrong DLC)",
            c.rx_rejected.into(),
            t.corrupted_dispatched,
            corruption,
        ),
        stat_line(
            &mut ok,
            "bus-off -> bus_off_events",
            c.bus_off_events.into(),
            t.bus_off_entries,
            !bus_off_windows.is_empty(),
        ),
        stat_line(
            &mut ok,
            "bus-off -> tx_bus_off (frames refused)",
            c.tx_bus_off.into(),
            t.refused_bus_off,
            !bus_off_windows.is_empty(),
        ),
        stat_line(
            &mut ok,
            "no ACK -> tx_full (TX buffers full)",
            c.tx_full.into(),
            t.refused_full,
            no_ack,
        ),
        stat_line(
            &mut ok,
            "no ACK -> tx_stale (frames still queued at a tick)",
            c.tx_stale.into(),
            t.held_at_ticks,
            no_ack,
        ),
        stat_line(
            &mut ok,
            "no ACK -> bus_errors (ACK errors)",
            c.bus_errors.into(),
            t.ack_error_ticks,
            no_ack,
        ),
        stat_line(
            &mut ok,
            "RX stall -> rx_overruns (stalls that lost frames)",
            c.rx_overruns.into(),
            t.stalls_that_lost,
            rx_stall,
        ),
        stat_line(
            &mut ok,
            "frames received (all that reached rc10)",
            c.rx_frames.into(),
            t.dispatched,
            true,
        ),
    ];
    if u64::try_from(bus_off_windows.len()).ok() != Some(t.bus_off_entries) {
        ok = false;
        lines.push(format!(
            "FAIL, {} bus-off windows injected, {} entries seen",
            bus_off_windows.len(),
            t.bus_off_entries
        ));
    }
    lines.push(format!(
        "TX drops {} (full {}, bus-off {}); {} ticks without acknowledgement",
        c.tx_dropped(),
        c.tx_full,
        c.tx_bus_off,
        t.no_ack_ticks
    ));
    let mut line = format!(
        "lost frames: {} removed from the wire ({} of them feedback), {} corrupted, {} device \
         frames unheard while bus-off, {} while unacknowledged, {} in full RX FIFOs, {} \
         discarded by the acceptance filters",
        t.lost,
        t.lost_device_frames,
        t.corrupted,
        t.dropped_bus_off,
        t.dropped_no_ack,
        t.overruns,
        t.filtered
    );
    if t.filtered > 0 {
        // Every device is a registered motor: its feedback must pass the filters.
        ok = false;
        line.push_str(": FAIL, feedback discarded by the filters");
    }
    if loss && t.lost == 0 {
        ok = false;
        line.push_str(": FAIL, loss injected but no frame lost");
    }
    lines.push(line);
    for (i, (rec, l)) in record.motors.iter().zip(limits).enumerate() {
        let (lo, hi) = expected_offline_events(scenario, i, l.offline_timeout_us);
        let counted = record.offline_events.get(i).copied().map_or(0, u64::from);
        let seen = rec.outages.len() as u64;
        let expected = if lo == hi {
            format!("{lo}")
        } else {
            format!("{lo}-{hi}")
        };
        let mut line = format!(
            "motor {}: offline events rc10 {counted}, seen {seen}, expected {expected}; {} \
             feedback frames, {} gaps (longest {})",
            i + 1,
            rec.feedback_frames,
            rec.feedback_gaps,
            dur(rec.longest_gap_us)
        );
        if counted != seen || counted < lo || counted > hi {
            ok = false;
            line.push_str(": FAIL, offline events differ from the outages injected");
        }
        if loss && rec.feedback_gaps == 0 {
            ok = false;
            line.push_str(": FAIL, frames lost but no feedback gap seen");
        }
        lines.push(line);
    }
    check(CheckId::Statistics, ok, lines)
}

/// A soak run: the run's result (if it finished), the evidence and the verdict.
#[derive(Debug, Clone)]
pub struct SoakOutcome {
    /// The run's trace (thinned for long runs) and counters, if it finished.
    pub result: Option<RunResult>,
    /// The evidence.
    pub record: SoakRecord,
    /// The verdict.
    pub report: SoakReport,
}

/// Runs `scenario` under the soak checks. A panic inside the run is caught and reported as a
/// failed check, never propagated.
pub fn run_soak(scenario: &Scenario, progress: &mut dyn FnMut(u64)) -> SoakOutcome {
    let mut observer = SoakObserver::new(scenario);
    let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        run_observed(scenario, progress, &mut observer)
    }));
    let (result, aborted) = match run {
        Ok(Ok(r)) => (Some(r), None),
        Ok(Err(e)) => (None, Some(format!("simulator error: {e}"))),
        Err(payload) => {
            let message = payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "(no message)".into());
            (None, Some(format!("panic: {message}")))
        }
    };
    let record = observer.finish(result.as_ref(), aborted);
    let report = evaluate(scenario, &record);
    SoakOutcome {
        result,
        record,
        report,
    }
}

fn plot_err(e: impl std::fmt::Display) -> io::Error {
    io::Error::other(e.to_string())
}

const COLORS: [RGBColor; 6] = [RED, BLUE, GREEN, MAGENTA, CYAN, BLACK];

/// Whether motor `i` follows angle targets (else speed).
fn angle_controlled(scenario: &Scenario, i: usize) -> bool {
    scenario
        .targets
        .iter()
        .any(|t| t.motor == i && matches!(t.kind, TargetKind::AngleDeg | TargetKind::TotalAngleDeg))
}

/// One panel per motor over the whole run: target (dashed) and physical response (rpm, or
/// degrees for angle-controlled motors), offline periods shaded.
pub fn write_overview_svg(scenario: &Scenario, result: &RunResult, path: &Path) -> io::Result<()> {
    let n = scenario.motors.len().max(1);
    let height = u32::try_from(60 + 170 * n).unwrap_or(u32::MAX);
    let root = SVGBackend::new(path, (1100, height)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let (title, body) = root.split_vertically(40);
    title
        .titled(
            &format!(
                "{}: target (dashed), response, offline (shaded)",
                scenario.name
            ),
            ("sans-serif", 18),
        )
        .map_err(plot_err)?;
    let t_end = scenario.duration_ms as f64 * 1e-3;
    for (i, panel) in body.split_evenly((n, 1)).iter().enumerate() {
        let angle = angle_controlled(scenario, i);
        let pts: Vec<(f64, f64, f64, bool)> = result
            .samples
            .iter()
            .filter_map(|s| {
                s.motors.get(i).map(|m| {
                    let (y, target) = if angle {
                        let y = m.true_total_deg;
                        let wrap = rc10_core::math::wrap_deg_180(m.target - y as f32);
                        (y, y + f64::from(wrap))
                    } else {
                        (m.true_rpm, f64::from(m.target))
                    };
                    (s.t_ms as f64 * 1e-3, y, target, m.online)
                })
            })
            .collect();
        let (lo, hi) = pts
            .iter()
            .flat_map(|p| [p.1, p.2])
            .fold((0.0f64, 0.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
        let pad = ((hi - lo) * 0.08).max(1.0);
        let (lo, hi) = (lo - pad, hi + pad);
        let mut chart = ChartBuilder::on(panel)
            .margin(6)
            .x_label_area_size(34)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t_end, lo..hi)
            .map_err(plot_err)?;
        let model = MotorLimits::of(scenario.motors.get(i).unwrap_or(&m3508(1))).model;
        chart
            .configure_mesh()
            .x_desc("time (s)")
            .y_desc(format!(
                "m{} {model} ({})",
                i + 1,
                if angle { "deg" } else { "rpm" }
            ))
            .draw()
            .map_err(plot_err)?;
        chart
            .draw_series(
                pts.windows(2)
                    .filter(|w| w.first().is_some_and(|p| !p.3))
                    .filter_map(|w| match w {
                        [a, b] => Some(Rectangle::new(
                            [(a.0, lo), (b.0, hi)],
                            RED.mix(0.25).filled(),
                        )),
                        _ => None,
                    }),
            )
            .map_err(plot_err)?;
        let color = COLORS.get(i % COLORS.len()).copied().unwrap_or(BLACK);
        chart
            .draw_series(DashedLineSeries::new(
                pts.iter().map(|p| (p.0, p.2)),
                6,
                4,
                BLACK.mix(0.6).stroke_width(1),
            ))
            .map_err(plot_err)?;
        chart
            .draw_series(LineSeries::new(
                pts.iter().map(|p| (p.0, p.1)),
                color.stroke_width(1),
            ))
            .map_err(plot_err)?;
    }
    root.present().map_err(plot_err)
}

/// One panel per fault window (those shorter than 10 s): each affected motor's command as a
/// percentage of its limit, from 150 ms before the window to 250 ms after, with the ticks at
/// which any of them was offline shaded.
pub fn write_events_svg(scenario: &Scenario, result: &RunResult, path: &Path) -> io::Result<()> {
    let events: Vec<(&Fault, u64, u64)> = scenario
        .faults
        .iter()
        .filter_map(|f| window_of(f).map(|(a, b)| (f, a, b)))
        .filter(|(_, a, b)| b - a < DETAIL_MAX_WINDOW_MS)
        .collect();
    let cols = 4usize;
    let rows = events.len().div_ceil(cols).max(1);
    let height = u32::try_from(50 + 230 * rows).unwrap_or(u32::MAX);
    let root = SVGBackend::new(path, (1400, height)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let (title, body) = root.split_vertically(40);
    title
        .titled(
            &format!(
                "{}: command (% of limit) around each fault, offline shaded; colours: motors 1-{}",
                scenario.name,
                scenario.motors.len()
            ),
            ("sans-serif", 16),
        )
        .map_err(plot_err)?;
    let limits: Vec<MotorLimits> = scenario.motors.iter().map(MotorLimits::of).collect();
    for (panel, (fault, from, to)) in body.split_evenly((rows, cols)).iter().zip(&events) {
        let motors: Vec<usize> = match **fault {
            Fault::PowerCut { motor, .. }
            | Fault::Stall { motor, .. }
            | Fault::OverTemperature { motor, .. } => vec![motor],
            _ => (0..scenario.motors.len()).collect(),
        };
        let (a, b) = (from.saturating_sub(150), to + 250);
        let x = |t_ms: u64| t_ms as f64 - *from as f64;
        let window: Vec<_> = result
            .samples
            .iter()
            .filter(|s| (a..=b).contains(&s.t_ms))
            .collect();
        let mut chart = ChartBuilder::on(panel)
            .caption(
                format!("{} at {:.3} s", fault_label(fault), *from as f64 * 1e-3),
                ("sans-serif", 13),
            )
            .margin(6)
            .x_label_area_size(34)
            .y_label_area_size(40)
            .build_cartesian_2d(x(a)..x(b), -110.0f64..110.0)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("ms from the fault")
            .x_labels(5)
            .y_labels(5)
            .draw()
            .map_err(plot_err)?;
        chart
            .draw_series(
                window
                    .windows(2)
                    .filter(|w| {
                        w.first().is_some_and(|s| {
                            motors
                                .iter()
                                .any(|&m| s.motors.get(m).is_some_and(|x| !x.online))
                        })
                    })
                    .filter_map(|w| match w {
                        [p, q] => Some(Rectangle::new(
                            [(x(p.t_ms), -110.0), (x(q.t_ms), 110.0)],
                            RED.mix(0.2).filled(),
                        )),
                        _ => None,
                    }),
            )
            .map_err(plot_err)?;
        for &m in &motors {
            let limit = limits
                .get(m)
                .map_or(1.0, |l| f64::from(l.command_limit).max(1e-9));
            let color = COLORS.get(m % COLORS.len()).copied().unwrap_or(BLACK);
            chart
                .draw_series(LineSeries::new(
                    window.iter().filter_map(|s| {
                        s.motors
                            .get(m)
                            .map(|x_| (x(s.t_ms), 100.0 * f64::from(x_.command) / limit))
                    }),
                    color.stroke_width(1),
                ))
                .map_err(plot_err)?;
        }
    }
    root.present().map_err(plot_err)
}

/// Writes a soak's results into `dir`: the trace (`<name>.csv`), the report
/// (`<name>-report.txt`) and, with `plots`, `<name>.svg` ([`write_overview_svg`]),
/// `<name>-events.svg` ([`write_events_svg`]) and for a chassis `<name>-twist.svg`. Returns
/// the paths.
pub fn write_outputs(
    scenario: &Scenario,
    result: &RunResult,
    report: &SoakReport,
    dir: &Path,
    plots: bool,
) -> io::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)?;
    let csv = dir.join(format!("{}.csv", scenario.name));
    output::write_csv(result, &csv)?;
    let text = dir.join(format!("{}-report.txt", scenario.name));
    std::fs::write(&text, report.text())?;
    let mut paths = vec![csv, text];
    if plots {
        let overview = dir.join(format!("{}.svg", scenario.name));
        write_overview_svg(scenario, result, &overview)?;
        paths.push(overview);
        let events = dir.join(format!("{}-events.svg", scenario.name));
        write_events_svg(scenario, result, &events)?;
        paths.push(events);
        if scenario.chassis.is_some() {
            let twist = dir.join(format!("{}-twist.svg", scenario.name));
            output::write_chassis_svg(scenario, result, &twist)?;
            paths.push(twist);
        }
    }
    Ok(paths)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::{MotorSample, Sample};
    use rc10_core::bus::{PacedTick, TransmitReport};
    use rc10_core::node::TxBatch;
    use std::sync::OnceLock;

    /// A 3 s soak with one of every fault class the checks judge.
    fn short_soak() -> Scenario {
        let mut s = fault_soak();
        s.duration_ms = 3_000;
        s.faults = vec![
            Fault::FrameLoss {
                probability: 0.02,
                from_ms: 0,
                to_ms: 3_000,
            },
            Fault::Corruption {
                probability: 0.01,
                from_ms: 0,
                to_ms: 3_000,
            },
            Fault::PowerCut {
                motor: 4,
                from_ms: 400,
                to_ms: 900,
            },
            Fault::BusOff {
                from_ms: 1_100,
                to_ms: 1_250,
            },
            Fault::NoAck {
                from_ms: 1_500,
                to_ms: 1_700,
            },
            Fault::RxStall {
                from_ms: 2_000,
                to_ms: 2_010,
            },
            Fault::SchedulerStall {
                from_ms: 2_300,
                to_ms: 2_306,
            },
            Fault::Stall {
                motor: 0,
                from_ms: 2_500,
                to_ms: 2_800,
            },
        ];
        s
    }

    /// The short soak's record, run once.
    fn baseline() -> &'static (Scenario, SoakRecord) {
        static BASELINE: OnceLock<(Scenario, SoakRecord)> = OnceLock::new();
        BASELINE.get_or_init(|| {
            let s = short_soak();
            let outcome = run_soak(&s, &mut |_| {});
            assert!(outcome.report.passed(), "{}", outcome.report.text());
            (s, outcome.record)
        })
    }

    /// Doctors a copy of the baseline record and says which checks then fail.
    fn failed_after(doctor: impl FnOnce(&mut SoakRecord)) -> Vec<CheckId> {
        let (s, record) = baseline();
        let mut r = record.clone();
        doctor(&mut r);
        evaluate(s, &r).failed()
    }

    /// The outage of the cut motor (5) during its power cut.
    fn cut_outage(r: &mut SoakRecord) -> &mut Outage {
        r.motors[4]
            .outages
            .iter_mut()
            .find(|o| (400_000..900_000).contains(&o.offline_at_us))
            .unwrap()
    }

    #[test]
    fn the_short_soak_passes_every_check_and_exercises_each() {
        let (s, r) = baseline();
        let report = evaluate(s, r);
        assert!(report.passed(), "{}", report.text());
        // The checks had something to judge.
        assert!(r.motors.iter().all(|m| m.zero_frames_while_offline > 0));
        assert_eq!(r.offline_events, vec![2, 2, 2, 2, 3, 2]);
        assert!(r.counters.rx_rejected > 0 && r.counters.rx_overruns > 0);
        assert!(r.counters.tx_full > 0 && r.counters.tx_stale > 0 && r.counters.bus_errors > 0);
        assert_eq!(
            (r.counters.bus_off_events, r.counters.ticks_skipped),
            (1, 6)
        );
        assert!(
            !r.late_frames.is_empty(),
            "frames held through the no-ACK window"
        );
    }

    #[test]
    fn a_run_that_did_not_finish_fails_every_check() {
        let failed = failed_after(|r| r.aborted = Some("panic: boom".into()));
        assert_eq!(failed, CheckId::ALL.to_vec());
    }

    #[test]
    fn offline_detected_late_or_early_or_never_fails_the_power_cut_check() {
        let late = failed_after(|r| cut_outage(r).offline_at_us += 3_000);
        assert_eq!(late, vec![CheckId::PowerCuts]);
        let early = failed_after(|r| {
            let o = cut_outage(r);
            o.last_feedback_us = Some(o.offline_at_us - 99_000);
        });
        assert_eq!(early, vec![CheckId::PowerCuts]);
        let back_during_cut = failed_after(|r| {
            let o = cut_outage(r);
            o.online_at_us = Some(o.offline_at_us + 1_000);
        });
        assert_eq!(back_during_cut, vec![CheckId::PowerCuts]);
        // Never offline: the outage and its offline event are gone (statistics sees it too).
        let never = failed_after(|r| {
            r.motors[4]
                .outages
                .retain(|o| !(400_000..900_000).contains(&o.offline_at_us));
            r.offline_events[4] -= 1;
        });
        assert_eq!(never, vec![CheckId::PowerCuts, CheckId::Statistics]);
    }

    #[test]
    fn a_non_zero_command_for_an_offline_motor_fails_the_zero_check() {
        let on_wire = failed_after(|r| r.motors[2].nonzero_while_offline.push(1_200_000, 1));
        assert_eq!(on_wire, vec![CheckId::ZeroWhileOffline]);
        let in_state = failed_after(|r| {
            r.motors[2]
                .command_nonzero_while_offline
                .push(1_200_000, -1)
        });
        assert_eq!(in_state, vec![CheckId::ZeroWhileOffline]);
        let untraced = failed_after(|r| r.unattributed_frames = 1);
        assert_eq!(untraced, vec![CheckId::ZeroWhileOffline]);
        // A pre-outage command sent late, but not out of a no-ACK window's buffers.
        let late = failed_after(|r| {
            r.late_frames.push(LateFrame {
                t_us: 500_400,
                packed_us: 500_000,
                motor: 4,
                raw: 300,
            })
        });
        assert_eq!(late, vec![CheckId::ZeroWhileOffline]);
        // More frames out of the no-ACK window than the TX buffers hold.
        let too_many = failed_after(|r| {
            let last = *r.late_frames.last().unwrap();
            for k in 1..=3 {
                r.late_frames.push(LateFrame {
                    t_us: last.t_us + 200 * k,
                    ..last
                });
            }
        });
        assert_eq!(too_many, vec![CheckId::ZeroWhileOffline]);
    }

    #[test]
    fn control_resuming_late_or_never_fails_the_resume_check() {
        let slow = failed_after(|r| {
            let o = cut_outage(r);
            o.resumed_us = o.feedback_back_us.map(|f| f + RESUME_LIMIT_US + 1);
        });
        assert_eq!(slow, vec![CheckId::Resume]);
        let just_in_time = failed_after(|r| {
            let o = cut_outage(r);
            o.resumed_us = o.feedback_back_us.map(|f| f + RESUME_LIMIT_US);
        });
        assert!(just_in_time.is_empty());
        let never = failed_after(|r| r.motors[1].outages[0].resumed_us = None);
        assert_eq!(never, vec![CheckId::Resume]);
    }

    #[test]
    fn a_command_beyond_the_esc_range_fails_the_range_check() {
        let wheel = failed_after(|r| {
            r.motors[0].max_abs_raw = 16385;
            r.motors[0].beyond_range.push(1_000, 16385);
        });
        assert_eq!(wheel, vec![CheckId::EscRange]);
        // 25001 on a GM6020 in voltage mode: within ±30000, beyond rc10's configured 25000.
        let gimbal = failed_after(|r| r.motors[5].max_abs_raw = 25001);
        assert_eq!(gimbal, vec![CheckId::EscRange]);
        let state = failed_after(|r| r.motors[3].command_beyond_limit.push(1_000, i64::MAX));
        assert_eq!(state, vec![CheckId::EscRange]);
    }

    #[test]
    fn a_blocking_or_bursting_scheduler_fails_the_scheduler_check() {
        let cases: [fn(&mut SoakRecord); 7] = [
            |r| r.ticks.dt_out_of_bounds.push(1_000, 400),
            |r| r.ticks.bursts.push(1_000, 10),
            |r| r.counters.ticks_skipped += 1,
            |r| r.ticks.skipped -= 1,
            |r| r.ticks.run += 1,
            |r| r.ticks.max_queued = 4,
            |r| r.ticks.unaccounted.push(1_000, 1),
        ];
        for (k, doctor) in cases.into_iter().enumerate() {
            assert_eq!(failed_after(doctor), vec![CheckId::Scheduler], "case {k}");
        }
    }

    #[test]
    fn a_fault_class_miscounted_fails_the_statistics_check() {
        let cases: [fn(&mut SoakRecord); 12] = [
            |r| r.truth.filtered = 1,
            |r| r.counters.rx_rejected += 1,
            |r| r.counters.bus_off_events += 1,
            |r| r.counters.tx_bus_off -= 1,
            |r| r.counters.tx_full = 0,
            |r| r.counters.tx_stale += 1,
            |r| r.counters.bus_errors = 0,
            |r| r.counters.rx_overruns -= 1,
            |r| r.counters.rx_frames -= 1,
            |r| r.offline_events[0] += 1,
            |r| r.truth.lost = 0,
            |r| r.motors[3].feedback_gaps = 0,
        ];
        for (k, doctor) in cases.into_iter().enumerate() {
            assert_eq!(failed_after(doctor), vec![CheckId::Statistics], "case {k}");
        }
        // Injected but counted by neither side is still a failure.
        let neither = failed_after(|r| {
            r.counters.rx_overruns = 0;
            r.truth.stalls_that_lost = 0;
        });
        assert_eq!(neither, vec![CheckId::Statistics]);
    }

    /// Two M3508s (ESC ids 1 and 2, slots 0 and 1 of 0x200), for observer tests.
    fn two_wheels() -> Scenario {
        let mut s = fault_soak();
        s.motors = vec![m3508(1), m3508(2)];
        s.targets.clear();
        s.faults.clear();
        s.chassis = None;
        s.duration_ms = 1_000;
        s
    }

    fn frame(slots: [i16; 2]) -> CanFrame {
        let mut batch = TxBatch::new();
        for (i, v) in slots.iter().enumerate() {
            batch.write_slot(CommandSlot::new(0x200, i as u8).unwrap(), *v);
        }
        batch.frames()[0]
    }

    fn tick(obs: &mut SoakObserver, t_us: u64, dt_s: f32, online: [bool; 2], first_seq: u64) {
        let sample = Sample {
            t_ms: t_us / 1000,
            motors: online
                .iter()
                .map(|&online| MotorSample {
                    online,
                    command: if online { 1.0 } else { 0.0 },
                    ..MotorSample::default()
                })
                .collect(),
            chassis: None,
        };
        let mut batch = TxBatch::new();
        batch.write_slot(CommandSlot::new(0x200, 0).unwrap(), 1);
        obs.on_tick(&TickEvent {
            t_us,
            paced: PacedTick {
                dt_s,
                resync: false,
                skipped: 0,
            },
            sample: &sample,
            batch: &batch,
            report: TransmitReport {
                queued: 1,
                ..TransmitReport::default()
            },
            held_before: 0,
            first_seq,
            bus_off: false,
            no_ack: false,
        });
    }

    fn wire(obs: &mut SoakObserver, t_us: u64, seq: u64, f: CanFrame) {
        obs.on_wire(&WireEvent {
            t_us,
            sender: Sender::Mcu,
            frame: f,
            mcu_seq: Some(seq),
            received: Some(f),
            corrupted: false,
        });
    }

    #[test]
    fn observer_attributes_each_frame_to_the_tick_that_packed_it() {
        let s = two_wheels();
        let mut obs = SoakObserver::new(&s);
        tick(&mut obs, 0, 0.001, [true, true], 0);
        wire(&mut obs, 300, 0, frame([500, -500]));
        // Motor 1 goes offline; its slot must be 0 from now on.
        tick(&mut obs, 1_000, 0.001, [false, true], 1);
        wire(&mut obs, 1_300, 1, frame([0, 20_000])); // motor 2 beyond ±16384
        tick(&mut obs, 2_000, 0.001, [false, true], 2);
        wire(&mut obs, 2_300, 2, frame([7, 0])); // non-zero while offline
        // Feedback returns, motor 1 back online, its next command reaches the ESC.
        obs.on_dispatch(2_500, &frame([0, 0]), Dispatch::Handled(0));
        tick(&mut obs, 3_000, 0.001, [true, true], 3);
        wire(&mut obs, 3_200, 3, frame([400, 0]));
        let r = obs.finish(None, None);
        let m1 = &r.motors[0];
        assert_eq!(m1.zero_frames_while_offline, 1);
        assert_eq!(m1.nonzero_while_offline.count, 1);
        assert_eq!(m1.nonzero_while_offline.first, vec![(2_300, 7)]);
        assert_eq!(
            m1.outages,
            vec![Outage {
                offline_at_us: 1_000,
                last_feedback_us: None,
                feedback_back_us: Some(2_500),
                online_at_us: Some(3_000),
                resumed_us: Some(3_200),
            }]
        );
        assert_eq!(r.motors[1].beyond_range.first, vec![(1_300, 20_000)]);
        assert_eq!(r.motors[1].max_abs_raw, 20_000);
        assert!(r.late_frames.is_empty());
        assert_eq!(r.unattributed_frames, 0);
    }

    #[test]
    fn observer_flags_a_pre_outage_frame_sent_late_and_an_unknown_one() {
        let s = two_wheels();
        let mut obs = SoakObserver::new(&s);
        tick(&mut obs, 0, 0.001, [true, true], 0);
        tick(&mut obs, 1_000, 0.001, [false, true], 1);
        // The frame packed at 0 (motor 1 online) leaves only now.
        wire(&mut obs, 1_100, 0, frame([321, 0]));
        wire(&mut obs, 1_200, 99, frame([0, 0])); // never queued by any tick seen
        let r = obs.finish(None, None);
        assert_eq!(
            r.late_frames,
            vec![LateFrame {
                t_us: 1_100,
                packed_us: 0,
                motor: 0,
                raw: 321
            }]
        );
        assert_eq!(r.unattributed_frames, 1);
    }

    #[test]
    fn observer_flags_dt_out_of_bounds_and_bursts() {
        let s = two_wheels();
        let mut obs = SoakObserver::new(&s);
        tick(&mut obs, 0, 0.001, [true, true], 0);
        tick(&mut obs, 1_000, 0.0004, [true, true], 1); // dt below half a period
        tick(&mut obs, 1_100, 0.001, [true, true], 2); // 100 µs after the previous tick
        tick(&mut obs, 20_000, 0.011, [true, true], 3); // dt beyond ten periods
        let r = obs.finish(None, None);
        assert_eq!(
            r.ticks.dt_out_of_bounds.first,
            vec![(1_000, 400), (20_000, 11_000)]
        );
        assert_eq!(r.ticks.bursts.first, vec![(1_100, 100)]);
        assert_eq!(r.ticks.run, 4);
    }

    #[test]
    fn each_stall_that_lost_frames_and_ended_expects_one_overrun() {
        let mut s = two_wheels();
        // 1 000 ms run: stalls at 100–110 (loses), 200–210 (loses nothing), 300–305 and
        // 303–320 (one stall, loses), 990–1 000 (loses, never ends within the run).
        s.faults = [(100, 110), (200, 210), (300, 305), (303, 320), (990, 1_000)]
            .into_iter()
            .map(|(from_ms, to_ms)| Fault::RxStall { from_ms, to_ms })
            .collect();
        let mut obs = SoakObserver::new(&s);
        let frame = CanFrame::standard(0x201, &[0; 8]).unwrap();
        for t_ms in [105, 106, 318, 995] {
            obs.on_rx_dropped(t_ms * 1000, &frame, RxDrop::Overrun);
        }
        let t = obs.finish(None, None).truth;
        assert_eq!((t.overruns, t.stalls_that_lost), (4, 2));
    }

    #[test]
    fn corrupted_frames_are_counted_when_they_reach_rc10() {
        let s = two_wheels();
        let mut obs = SoakObserver::new(&s);
        let short = CanFrame::standard(0x201, &[1, 2, 3]).unwrap();
        let whole = CanFrame::standard(0x201, &[0; 8]).unwrap();
        for _ in 0..2 {
            obs.on_wire(&WireEvent {
                t_us: 10,
                sender: Sender::Device(0),
                frame: whole,
                mcu_seq: None,
                received: Some(short),
                corrupted: true,
            });
        }
        obs.on_rx_dropped(20, &short, RxDrop::Overrun);
        obs.on_dispatch(30, &short, Dispatch::Unmatched);
        obs.on_dispatch(40, &short, Dispatch::Unmatched); // not corrupted by the injector
        let t = obs.finish(None, None).truth;
        assert_eq!((t.corrupted, t.corrupted_dispatched, t.overruns), (2, 1, 1));
        assert_eq!((t.dispatched, t.device_frames), (2, 2));
    }

    #[test]
    fn long_runs_keep_every_tick_only_around_faults() {
        let mut s = two_wheels();
        s.duration_ms = 600_000;
        s.faults = vec![Fault::BusOff {
            from_ms: 100_000,
            to_ms: 100_100,
        }];
        let mut obs = SoakObserver::new(&s);
        let kept: Vec<u64> = (99_000..101_000).filter(|&t| obs.keep_sample(t)).collect();
        assert_eq!(kept.first(), Some(&99_000));
        assert!(kept.contains(&99_850) && kept.contains(&99_800) && !kept.contains(&99_799));
        assert!((99_800..100_400).all(|t| kept.contains(&t)));
        assert!(!kept.contains(&100_401) && kept.contains(&100_450));
        let mut short = SoakObserver::new(&two_wheels());
        assert!((0..1_000).all(|t| short.keep_sample(t)));
    }

    #[test]
    fn expected_offline_events_follow_the_silent_windows() {
        let mut s = two_wheels();
        s.faults = vec![
            Fault::PowerCut {
                motor: 1,
                from_ms: 100,
                to_ms: 300,
            },
            // Overlapping silences are one outage.
            Fault::BusOff {
                from_ms: 250,
                to_ms: 400,
            },
            Fault::RxStall {
                from_ms: 500,
                to_ms: 550,
            },
            // Within a few ms of the timeout: either way.
            Fault::NoAck {
                from_ms: 600,
                to_ms: 701,
            },
            Fault::FrameLoss {
                probability: 0.5,
                from_ms: 0,
                to_ms: 1_000,
            },
        ];
        assert_eq!(
            silent_windows(&s, 1),
            vec![(100, 400), (500, 550), (600, 701)]
        );
        assert_eq!(expected_offline_events(&s, 0, 100_000), (1, 2));
        assert_eq!(expected_offline_events(&s, 1, 100_000), (1, 2));
        assert_eq!(
            merged(vec![(5, 9), (0, 3), (3, 4), (900, 2_000)], 1_000),
            vec![(0, 4), (5, 9), (900, 1_000)]
        );
    }
}
