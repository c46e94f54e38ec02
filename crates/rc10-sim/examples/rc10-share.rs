//! rc10's own share of a simulated run: how fast the simulator could run a scenario on this
//! machine if simulating the bus and the motors cost nothing.
//!
//! ```sh
//! cargo run -p rc10-sim --release --example rc10-share                 # chassis, 60 s, 9 rounds
//! cargo run -p rc10-sim --release --example rc10-share -- m3508-speed-step 10000 5
//! ```
//!
//! Arguments (all optional, in order): the scenario name (default `chassis-4x-m3508`), the
//! simulated duration in ms (default 60 000) and the number of rounds (default 9). The
//! scenario's motors must be rc10's DJI drivers with their shipped defaults, its targets speeds
//! in rpm (a chassis sets every wheel's each tick), and it must have no faults.
//!
//! The scenario is run once with an observer that records what rc10 was given: every frame
//! handed to `Bus::dispatch` with its time, and at every tick its time, `dt` and each motor's
//! speed target. Then rc10 alone replays that record on motors of its own, as the simulator
//! drives them: each tick's targets set, the tick, the transmit (to a port that takes every
//! frame) and every motor's `state()` under one critical section, and each frame dispatched
//! at its time. A first replay checks that it packs the same command as the run did on every
//! tick (else the replay would not be doing the run's work, and the example fails). The
//! rounds then time the whole run and the replay, one after the other, and print both; the
//! summary gives the medians of rounds 2 onwards and the median of the rounds' ratios.
//!
//! The replay's speed is the ceiling of any simulator of this scenario that runs rc10's code,
//! on this machine, at this hour: rc10's tick, its dispatch of the feedback and the trace's
//! reading of each motor are work the simulation cannot skip.

use std::hint::black_box;
use std::io::Write;
use std::process::ExitCode;
use std::time::Instant as WallClock;

use rc10_core::bus::{Bus, BusBuilder};
use rc10_core::can::{CanFrame, CanTransmit, SendError};
use rc10_core::motor::Motor;
use rc10_core::motor::dji::{DjiConfig, DjiMotor};
use rc10_core::node::{CanNode, TxBatch};
use rc10_core::time::Instant;
use rc10_sim::scenario::{
    Controller, RunObserver, Scenario, TargetKind, TickEvent, builtin_named, run, run_observed,
};

/// The most motors the replay's bus takes (a bus carries at most 8 DJI feedback IDs at 1 kHz
/// only on paper; the built-in scenarios have up to 6).
const MAX_MOTORS: usize = 8;

/// What rc10 was given during the run, in the order it was given.
enum Given {
    /// A frame handed to `Bus::dispatch` at `t_us`.
    Frame { t_us: u64, frame: CanFrame },
    /// A tick at `t_us` with this `dt`, the motors' speed targets (rpm) and the command each
    /// packed (in its mode's unit), motor by motor from `first` in `targets`.
    Tick { t_us: u64, dt_s: f32, first: usize },
}

#[derive(Default)]
struct Recorder {
    given: Vec<Given>,
    /// (target rpm, command) of every motor at every tick, tick after tick.
    targets: Vec<(f32, f32)>,
}

impl RunObserver for Recorder {
    fn on_dispatch(&mut self, t_us: u64, frame: &CanFrame, _result: rc10_core::bus::Dispatch) {
        self.given.push(Given::Frame {
            t_us,
            frame: *frame,
        });
    }

    fn on_tick(&mut self, tick: &TickEvent<'_>) {
        self.given.push(Given::Tick {
            t_us: tick.t_us,
            dt_s: tick.paced.dt_s,
            first: self.targets.len(),
        });
        self.targets
            .extend(tick.sample.motors.iter().map(|m| (m.target, m.command)));
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
    if scenario.motors.is_empty() || scenario.motors.len() > MAX_MOTORS {
        return Some("it needs 1 to 8 motors");
    }
    if scenario
        .motors
        .iter()
        .any(|m| !matches!(m.controller, Controller::Rc10))
    {
        return Some("its motors must be rc10's DJI drivers with their shipped defaults");
    }
    if scenario.targets.iter().any(|t| t.kind != TargetKind::Rpm) {
        return Some("its targets must be speeds in rpm");
    }
    if !scenario.faults.is_empty() {
        return Some("it must have no faults (the replay has no bus-off or stalls)");
    }
    None
}

/// Replays `given` on `motors` registered on `bus`. Returns the number of ticks whose packed
/// command differs from the run's when `check`, else 0.
fn replay(
    bus: &Bus<'_, MAX_MOTORS>,
    motors: &[DjiMotor],
    given: &[Given],
    targets: &[(f32, f32)],
    check: bool,
) -> usize {
    let mut batch = TxBatch::new();
    let mut differing = 0;
    for g in given {
        match *g {
            Given::Frame { t_us, ref frame } => {
                black_box(bus.dispatch(frame, Instant::from_micros(t_us)));
            }
            Given::Tick { t_us, dt_s, first } => {
                let recorded = targets.get(first..).unwrap_or(&[]);
                for (m, &(rpm, _)) in motors.iter().zip(recorded) {
                    // A target the run accepted is accepted again.
                    let _ = black_box(m.set_target_rpm(rpm));
                }
                critical_section::with(|_| {
                    bus.tick(Instant::from_micros(t_us), dt_s, &mut batch);
                    black_box(bus.transmit(&batch, &mut TakeAll));
                    for (m, &(_, command)) in motors.iter().zip(recorded) {
                        let state = black_box(m.state());
                        if check && state.command.to_bits() != command.to_bits() {
                            differing += 1;
                        }
                    }
                });
            }
        }
    }
    differing
}

/// Builds fresh motors for `scenario` and replays `given` on them; returns the wall time in
/// seconds and the ticks whose command differed from the run's (counted when `check`).
fn timed_replay(
    scenario: &Scenario,
    given: &[Given],
    targets: &[(f32, f32)],
    check: bool,
) -> Result<(f64, usize), String> {
    let motors: Vec<DjiMotor> = scenario
        .motors
        .iter()
        .map(|m| DjiMotor::new(m.model, m.esc_id, DjiConfig::default_for(m.model)))
        .collect::<Result<_, _>>()
        .map_err(|e| e.to_string())?;
    let mut builder = BusBuilder::<MAX_MOTORS>::with_config(scenario.bus);
    for m in &motors {
        builder
            .register(m as &dyn CanNode)
            .map_err(|e| e.to_string())?;
    }
    let bus = builder.build();
    let started = WallClock::now();
    let differing = replay(&bus, &motors, given, targets, check);
    Ok((started.elapsed().as_secs_f64(), differing))
}

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    let name = args.next().unwrap_or_else(|| "chassis-4x-m3508".into());
    let duration_ms: u64 = match args.next().map(|s| s.parse()) {
        None => 60_000,
        Some(Ok(ms)) if ms > 0 => ms,
        Some(_) => {
            eprintln!("the duration is a whole number of milliseconds above 0");
            return ExitCode::FAILURE;
        }
    };
    let rounds: usize = match args.next().map(|s| s.parse()) {
        None => 9,
        Some(Ok(n)) if n >= 2 => n,
        Some(_) => {
            eprintln!("the number of rounds is a whole number, at least 2");
            return ExitCode::FAILURE;
        }
    };
    let Some(mut scenario) = builtin_named(&name) else {
        eprintln!("no built-in scenario named {name}");
        return ExitCode::FAILURE;
    };
    scenario.duration_ms = duration_ms;
    if let Some(why) = unsupported(&scenario) {
        eprintln!("{name} cannot be replayed: {why}");
        return ExitCode::FAILURE;
    }

    let mut recorder = Recorder::default();
    if let Err(e) = run_observed(&scenario, &mut |_| {}, &mut recorder) {
        eprintln!("{name}: {e}");
        return ExitCode::FAILURE;
    }
    let (given, targets) = (recorder.given, recorder.targets);
    match timed_replay(&scenario, &given, &targets, true) {
        Ok((_, 0)) => {}
        Ok((_, n)) => {
            eprintln!("the replay packed another command than the run on {n} motor ticks");
            return ExitCode::FAILURE;
        }
        Err(e) => {
            eprintln!("{name}: {e}");
            return ExitCode::FAILURE;
        }
    }

    let simulated_s = duration_ms as f64 / 1000.0;
    let mut out = std::io::stdout().lock();
    let (mut full, mut alone, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..rounds {
        let started = WallClock::now();
        if let Err(e) = run(&scenario) {
            eprintln!("{name}: {e}");
            return ExitCode::FAILURE;
        }
        let full_s = started.elapsed().as_secs_f64();
        let alone_s = match timed_replay(&scenario, &given, &targets, false) {
            Ok((s, _)) => s,
            Err(e) => {
                eprintln!("{name}: {e}");
                return ExitCode::FAILURE;
            }
        };
        if writeln!(
            out,
            "round {:>2}: simulation {:>6.0} x real time, rc10 alone {:>6.0} x ({:.0} % of the simulation's time)",
            i + 1,
            simulated_s / full_s,
            simulated_s / alone_s,
            100.0 * alone_s / full_s
        )
        .is_err()
        {
            return ExitCode::SUCCESS;
        }
        if i > 0 {
            full.push(simulated_s / full_s);
            alone.push(simulated_s / alone_s);
            ratios.push(alone_s / full_s);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    let _ = writeln!(
        out,
        "{name}, {duration_ms} ms simulated, medians of rounds 2-{rounds}: simulation {:.0} x, \
         rc10 alone {:.0} x; rc10's work is {:.0} % of the simulation's time",
        median(&mut full),
        median(&mut alone),
        100.0 * median(&mut ratios)
    );
    ExitCode::SUCCESS
}
