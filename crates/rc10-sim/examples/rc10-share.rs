//! rc10's own share of a simulated run: how much of the simulation's time goes to rc10's code,
//! and so how fast a simulator could run the scenario on this machine even if simulating the
//! bus and the motors cost nothing.
//!
//! ```sh
//! cargo run -p rc10-sim --release --example rc10-share                 # chassis, 60 s, 9 rounds
//! cargo run -p rc10-sim --release --example rc10-share -- m3508-speed-step 60000 9
//! ```
//!
//! Arguments (all optional, in order): the scenario name (default `chassis-4x-m3508`), the
//! simulated duration in ms (default 60 000) and the number of rounds (default 9). The
//! scenario's motors must be rc10's DJI drivers, and it must have no faults and no chassis
//! application (whose remote-control decoding and kinematics the replay does not run); a run
//! in which a tick found frames of earlier ticks still queued is refused too (the replay's
//! port takes every frame at once, so rc10 would hear otherwise).
//!
//! The scenario is run once with an observer that records what rc10 was given and what it
//! answered: every frame handed to `Bus::dispatch`, with its time and the dispatch result,
//! and at every tick its time, `dt`, the transmit report and each motor's state after it.
//! Then rc10 alone replays that record on motors of its own, as the run drives them: at each
//! tick rc10's `TickPacer` paces it and the scenario's due targets are set, then the tick, its
//! transmit (to a port that takes every frame) and the reading of every motor's `state()` run
//! under one critical section; each frame is dispatched at its time, in the run's order. A
//! first replay checks every tick's `dt`, every dispatch result, every transmit report, every
//! motor's target, command, measured speed and angle and online flag after each tick, and at
//! the end rc10's bus counters and each motor's offline events against the run's, to the bit
//! (else the replay would not be doing the run's work, and the example fails). The rounds then time the whole run and the replay one
//! after the other; the summary gives the medians of rounds 2 onwards, the share as the
//! median of the rounds' own ratios (the two runs of a round meet the same hour).
//!
//! The replay runs rc10's code as the run does, without the simulator's code between its
//! calls (and the motors called directly where the run calls them through `dyn`), and reads
//! the record besides: a bare pass over it is timed too and printed, about 1 % of the run.
//! A simulator of this scenario that runs rc10 and reads its motors every tick cannot go
//! faster on this machine, at this hour, than the replay, less that pass.

use std::hint::black_box;
mod common;

use std::io::Write;
use std::process::ExitCode;
use std::time::Instant as WallClock;

use rc10_core::bus::{Bus, BusBuilder, Dispatch, TickPacer, TransmitReport};
use rc10_core::can::{CanFrame, CanTransmit, SendError};
use rc10_core::motor::dji::{DjiConfig, DjiMotor};
use rc10_core::motor::{Motor, MotorState, TargetError};
use rc10_core::node::{CanNode, TxBatch};
use rc10_core::time::Instant;
use rc10_sim::scenario::{
    Controller, MAX_MOTORS, MotorSample, RunObserver, RunResult, Scenario, TargetKind, TickEvent,
    run, run_observed,
};

/// What rc10 was given during the run and what it answered, in the order it was given.
enum Given {
    /// A frame handed to `Bus::dispatch` at `t_us`, and the result.
    Frame {
        t_us: u64,
        frame: CanFrame,
        result: Dispatch,
    },
    /// A tick at `t_us` with the `dt` rc10's pacer gave it, its transmit report, and the
    /// motors' states after it from index `first` of [`Recorder::states`] on.
    Tick {
        t_us: u64,
        dt_s: f32,
        report: TransmitReport,
        first: usize,
    },
}

/// A motor's state after a tick, as the run's trace has it.
#[derive(Clone, Copy)]
struct Seen {
    target: f32,
    command: f32,
    measured_rpm: f32,
    measured_total_deg: f32,
    online: bool,
}

impl Seen {
    fn of_sample(m: &MotorSample) -> Self {
        Self {
            target: m.target,
            command: m.command,
            measured_rpm: m.measured_rpm,
            measured_total_deg: m.measured_total_deg,
            online: m.online,
        }
    }

    /// Whether `state` is this, to the bit (the trace writes 0 for an unknown angle).
    fn is(&self, state: &MotorState) -> bool {
        let same = |a: f32, b: f32| a.to_bits() == b.to_bits();
        same(self.target, state.target)
            && same(self.command, state.command)
            && same(self.measured_rpm, state.speed_rpm)
            && same(
                self.measured_total_deg,
                state.total_angle_deg.unwrap_or(0.0),
            )
            && self.online == state.online
    }
}

/// Records what rc10 was given and answered ([`Given`]); keeps no samples.
#[derive(Default)]
struct Recorder {
    given: Vec<Given>,
    states: Vec<Seen>,
    /// Whether a tick found frames of earlier ticks still queued: the replay's port, which
    /// takes every frame at once, would then answer rc10 otherwise than the run's did.
    held: bool,
}

impl RunObserver for Recorder {
    fn on_dispatch(&mut self, t_us: u64, frame: &CanFrame, result: Dispatch) {
        self.given.push(Given::Frame {
            t_us,
            frame: *frame,
            result,
        });
    }

    fn on_tick(&mut self, tick: &TickEvent<'_>) {
        self.held |= tick.held_before != 0;
        self.given.push(Given::Tick {
            t_us: tick.t_us,
            dt_s: tick.paced.dt_s,
            report: tick.report,
            first: self.states.len(),
        });
        self.states
            .extend(tick.sample.motors.iter().map(Seen::of_sample));
    }

    fn keep_sample(&mut self, _t_ms: u64) -> bool {
        false
    }
}

/// A transmit port that takes every frame: the bus costs nothing.
struct TakeAll;

impl CanTransmit for TakeAll {
    fn try_send(&mut self, _frame: &CanFrame) -> Result<(), SendError> {
        Ok(())
    }
}

/// Why a scenario cannot be replayed, if it cannot.
fn unsupported(scenario: &Scenario) -> Option<&'static str> {
    if scenario
        .motors
        .iter()
        .any(|m| matches!(m.controller, Controller::Rc10Legacy))
    {
        return Some("its motors must be rc10's DJI drivers");
    }
    if scenario.chassis.is_some() {
        return Some("the replay does not run a chassis application");
    }
    if !scenario.faults.is_empty() {
        return Some("it must have no faults (the replay has no bus-off, stalls or lost frames)");
    }
    None
}

/// Sets a target as the run does.
fn set_target(motor: &DjiMotor, kind: TargetKind, value: f32) -> Result<(), TargetError> {
    match kind {
        TargetKind::Current => motor.set_target_current(value),
        TargetKind::Rpm => motor.set_target_rpm(value),
        TargetKind::AngleDeg => motor.set_target_angle_deg(value),
        TargetKind::TotalAngleDeg => motor.set_target_total_angle_deg(value),
    }
}

/// What a replay found different from the run (all zero when only timing).
#[derive(Default)]
struct Differences {
    dts: usize,
    dispatches: usize,
    reports: usize,
    states: usize,
    /// rc10's bus counters or a motor's offline events at the end.
    totals: usize,
}

impl Differences {
    fn none(&self) -> bool {
        self.dts + self.dispatches + self.reports + self.states + self.totals == 0
    }
}

/// Replays `given` on fresh motors for `scenario`, checking what rc10 answers against the
/// run when `run` is given. Returns the wall time in seconds and the differences found.
fn replay(
    scenario: &Scenario,
    given: &[Given],
    states: &[Seen],
    run: Option<&RunResult>,
) -> Result<(f64, Differences), String> {
    let motors: Vec<DjiMotor> = scenario
        .motors
        .iter()
        .map(|m| {
            let cfg = match m.controller {
                Controller::Rc10With(cfg) => cfg,
                _ => DjiConfig::default_for(m.model),
            };
            DjiMotor::new(m.model, m.esc_id, cfg)
        })
        .collect::<Result<_, _>>()
        .map_err(|e| e.to_string())?;
    let mut builder = BusBuilder::<MAX_MOTORS>::with_config(scenario.bus);
    for m in &motors {
        builder
            .register(m as &dyn CanNode)
            .map_err(|e| e.to_string())?;
    }
    let bus = builder.build();
    let mut next_step = vec![0usize; scenario.targets.len()];
    let started = WallClock::now();
    let check = run.is_some();
    let mut differences = drive(
        &bus,
        &motors,
        scenario,
        &mut next_step,
        given,
        states,
        check,
    )?;
    let wall_s = started.elapsed().as_secs_f64();
    if let Some(run) = run {
        let offline: Vec<u32> = motors.iter().map(|m| m.state().offline_events).collect();
        if bus.stats().snapshot() != run.counters || offline != run.offline_events {
            differences.totals += 1;
        }
    }
    Ok((wall_s, differences))
}

/// The replay's loop: what the run did to rc10, in its order.
fn drive(
    bus: &Bus<'_, MAX_MOTORS>,
    motors: &[DjiMotor],
    scenario: &Scenario,
    next_step: &mut [usize],
    given: &[Given],
    states: &[Seen],
    check: bool,
) -> Result<Differences, String> {
    let mut batch = TxBatch::new();
    let mut pacer = TickPacer::new(scenario.bus.tick_period);
    let mut d = Differences::default();
    for g in given {
        match *g {
            Given::Frame {
                t_us,
                ref frame,
                result,
            } => {
                let r = black_box(bus.dispatch(frame, Instant::from_micros(t_us)));
                if check && r != result {
                    d.dispatches += 1;
                }
            }
            Given::Tick {
                t_us,
                dt_s,
                report,
                first,
            } => {
                let now = Instant::from_micros(t_us);
                let paced = pacer.on_tick(now);
                if paced.resync {
                    bus.record_skipped_ticks(paced.skipped);
                }
                if check && paced.dt_s.to_bits() != dt_s.to_bits() {
                    d.dts += 1;
                }
                // The targets whose steps are due, as the run sets them before its tick.
                let t_ms = t_us / 1000;
                for (spec, k) in scenario.targets.iter().zip(next_step.iter_mut()) {
                    while let Some(&(at_ms, value)) = spec.steps.get(*k) {
                        if at_ms > t_ms {
                            break;
                        }
                        if let Some(m) = motors.get(spec.motor) {
                            set_target(m, spec.kind, value).map_err(|e| e.to_string())?;
                        }
                        *k += 1;
                    }
                }
                let seen = states.get(first..).unwrap_or(&[]);
                critical_section::with(|_| {
                    bus.tick(now, paced.dt_s, &mut batch);
                    let r = black_box(bus.transmit(&batch, &mut TakeAll));
                    if check && r != report {
                        d.reports += 1;
                    }
                    for (i, m) in motors.iter().enumerate() {
                        let state = black_box(m.state());
                        if check && !seen.get(i).is_some_and(|s| s.is(&state)) {
                            d.states += 1;
                        }
                    }
                });
            }
        }
    }
    Ok(d)
}

/// One pass over the record touching what the replay reads, in seconds: the part of the
/// replay's time that is not rc10's.
fn record_pass(given: &[Given], states: &[Seen]) -> f64 {
    let started = WallClock::now();
    for g in given {
        match *g {
            Given::Frame {
                t_us, ref frame, ..
            } => {
                black_box((t_us, frame));
            }
            Given::Tick {
                t_us, dt_s, first, ..
            } => {
                black_box((t_us, dt_s, states.get(first)));
            }
        }
    }
    started.elapsed().as_secs_f64()
}

/// The median of `v` (the mean of the two middle values of an even count).
fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match (v.get(n.wrapping_sub(1) / 2), v.get(n / 2)) {
        (Some(a), Some(b)) => (a + b) / 2.0,
        _ => 0.0,
    }
}

fn main() -> ExitCode {
    let (name, scenario, rounds) = match common::scenario_and_count("rounds") {
        Ok(parsed) => parsed,
        Err(message) => {
            eprintln!("{message}");
            return ExitCode::FAILURE;
        }
    };
    let duration_ms = scenario.duration_ms;
    if let Some(why) = unsupported(&scenario) {
        eprintln!("{name} cannot be replayed: {why}");
        return ExitCode::FAILURE;
    }

    let mut recorder = Recorder::default();
    let recorded = match run_observed(&scenario, &mut |_| {}, &mut recorder) {
        Ok(result) => result,
        Err(e) => {
            eprintln!("{name}: {e}");
            return ExitCode::FAILURE;
        }
    };
    if recorder.held {
        eprintln!("{name} cannot be replayed: a tick found frames of earlier ticks still queued");
        return ExitCode::FAILURE;
    }
    let (given, states) = (recorder.given, recorder.states);
    match replay(&scenario, &given, &states, Some(&recorded)) {
        Ok((_, d)) if d.none() => {}
        Ok((_, d)) => {
            eprintln!(
                "the replay answered otherwise than the run: {} tick dt, {} dispatch results, \
                 {} transmit reports, {} motor states after a tick, {} in the totals (bus \
                 counters, offline events)",
                d.dts, d.dispatches, d.reports, d.states, d.totals
            );
            return ExitCode::FAILURE;
        }
        Err(e) => {
            eprintln!("{name}: {e}");
            return ExitCode::FAILURE;
        }
    }

    let simulated_s = duration_ms as f64 / 1000.0;
    let mut out = std::io::stdout().lock();
    let (mut full, mut alone, mut shares) = (Vec::new(), Vec::new(), Vec::new());
    let mut passes = Vec::new();
    for i in 0..rounds {
        let started = WallClock::now();
        let result = match run(&scenario) {
            Ok(result) => result,
            Err(e) => {
                eprintln!("{name}: {e}");
                return ExitCode::FAILURE;
            }
        };
        let full_s = started.elapsed().as_secs_f64();
        drop(result);
        let alone_s = match replay(&scenario, &given, &states, None) {
            Ok((s, _)) => s,
            Err(e) => {
                eprintln!("{name}: {e}");
                return ExitCode::FAILURE;
            }
        };
        let pass_s = record_pass(&given, &states);
        if writeln!(
            out,
            "round {:>2}: simulation {:>6.0} x real time, rc10 alone {:>6.0} x ({:.0} % of the \
             simulation's time; the pass over the record {:.1} %)",
            i + 1,
            simulated_s / full_s,
            simulated_s / alone_s,
            100.0 * alone_s / full_s,
            100.0 * pass_s / full_s,
        )
        .is_err()
        {
            return ExitCode::SUCCESS;
        }
        if i > 0 {
            full.push(simulated_s / full_s);
            alone.push(simulated_s / alone_s);
            shares.push(alone_s / full_s);
            passes.push(pass_s / full_s);
        }
    }
    let _ = writeln!(
        out,
        "{name}, {duration_ms} ms simulated, medians of rounds 2-{rounds}: simulation {:.0} x, \
         rc10 alone {:.0} x; rc10's work {:.0} % of the simulation's time in the same round \
         (the pass over the record {:.1} %)",
        median(&mut full),
        median(&mut alone),
        100.0 * median(&mut shares),
        100.0 * median(&mut passes),
    );
    ExitCode::SUCCESS
}
