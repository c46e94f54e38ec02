//! The world loop: virtual time from event to event, frames delivered between bus, ESCs and rc10.

use super::chassis_app::{CHASSIS_WHEELS, ChassisApp};
use super::faults::{
    Fault, apply_state_faults, delay_us, in_window, rx_stalled, scheduler_stall_end,
};
use super::metrics::target_metrics;
use super::observe::{NoObserver, RunObserver, RxDrop, TickEvent, WireEvent};
use super::rx::{RxPath, Stored};
use super::{
    Controller, MAX_MOTORS, MotorSample, MotorSamples, MotorSpec, RunResult, Sample, Scenario,
    SimError, TargetKind,
};
use crate::bus::{Sender, SimBus, SimBusConfig};
use crate::legacy::LegacyM3508;
use crate::plant::{DjiEsc, MotorParams};
use rand_xoshiro::Xoshiro256PlusPlus;
use rand_xoshiro::rand_core::{Rng, SeedableRng};
use rc10_core::bus::{BusBuilder, TickPacer};
use rc10_core::can::{CanFrame, ReceiveError};
use rc10_core::motor::dji::{DjiConfig, DjiModel, DjiMotor};
use rc10_core::motor::{Motor, TargetError};
use rc10_core::node::{CanNode, TxBatch};
use rc10_core::time::{Duration, Instant};

/// A motor the simulator can drive: rc10's scheduler side and the application side.
pub(super) trait SimMotor: CanNode + Motor {}
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
pub(crate) fn uniform(rng: &mut Xoshiro256PlusPlus) -> f64 {
    (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64
}

const PLANT_STEP_US: u64 = 200;
/// [`PLANT_STEP_US`] in seconds.
const PLANT_STEP_S: f64 = PLANT_STEP_US as f64 * 1e-6;
pub(super) const TICK_US: u64 = 1000;

/// Steps every plant through each of its step times before `until_us` that it has not taken
/// yet (`next_plant_us` is the first of them, moved on past the last one taken).
///
/// The plants are stepped when something is about to read or change them (a frame reaching
/// the ESCs, an ESC's feedback, the state faults at a millisecond's start, after which the
/// step at that start is taken for the tick there), not as events of their own: nothing else
/// happens at a step time that has no other reason to be an event, and every step still runs
/// at its own time, in the same order with respect to everything that touches the ESCs.
fn step_plants_before(escs: &mut [DjiEsc], next_plant_us: &mut u64, until_us: u64) {
    while *next_plant_us < until_us {
        for esc in escs.iter_mut() {
            esc.step(*next_plant_us, PLANT_STEP_S);
        }
        *next_plant_us += PLANT_STEP_US;
    }
}

/// The simulated bus for `scenario`: its bitrate and TX order, the STM32G4's buffer depths.
fn sim_bus_config(scenario: &Scenario) -> SimBusConfig {
    SimBusConfig {
        bitrate_bps: scenario.bus.bitrate_bps,
        mcu_tx_order: scenario.tx_order,
        ..SimBusConfig::default()
    }
}

/// Runs `scenario` and returns its trace and figures. Same scenario, same result, always.
pub fn run(scenario: &Scenario) -> Result<RunResult, SimError> {
    run_with_progress(scenario, &mut |_| {})
}

/// [`run`], calling `progress` with the simulated time in ms after every simulated second.
pub fn run_with_progress(
    scenario: &Scenario,
    progress: &mut dyn FnMut(u64),
) -> Result<RunResult, SimError> {
    run_observed(scenario, progress, &mut NoObserver)
}

/// `t_us`, or, if the scheduler is held up then ([`Fault::SchedulerStall`]), the end of that
/// hold-up in µs.
fn after_scheduler_stall(scenario: &Scenario, t_us: u64) -> u64 {
    match scheduler_stall_end(scenario, t_us / 1000) {
        Some(end_ms) => t_us.max(end_ms * 1000),
        None => t_us,
    }
}

/// [`run_with_progress`], telling `observer` about every frame on the wire, every frame
/// handed to rc10 and every tick, and keeping only the samples it asks for
/// ([`RunObserver::keep_sample`]).
///
/// Ticks come every 1 ms (a scenario whose `bus.tick_period` differs is refused) and are
/// paced by rc10's own `TickPacer`, as `run_scheduler` paces them on a board:
/// `dt` is the period, except after a [`Fault::SchedulerStall`], when the late tick's `dt` is
/// bounded and the missed ticks are counted as skipped.
pub fn run_observed(
    scenario: &Scenario,
    progress: &mut dyn FnMut(u64),
    observer: &mut dyn RunObserver,
) -> Result<RunResult, SimError> {
    let tick_us = scenario.bus.tick_period.as_micros();
    if tick_us != TICK_US {
        return Err(SimError::TickPeriod { us: tick_us });
    }
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
    let mut rx =
        RxPath::new(rc10.nodes().iter().map(|node| node.bus_usage())).map_err(SimError::Filters)?;
    for (i, t) in scenario.targets.iter().enumerate() {
        let reason = if t.motor >= motors.len() {
            format!("no motor {}", t.motor)
        } else if scenario.chassis.is_some() && t.motor < CHASSIS_WHEELS {
            format!(
                "motor {} is a chassis wheel: the chassis sets its speed every tick",
                t.motor + 1
            )
        } else {
            continue;
        };
        return Err(SimError::Target { target: i, reason });
    }

    let mut bus = SimBus::new(sim_bus_config(scenario));
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
    // The next plant step not yet taken, the next millisecond's start (the state faults
    // change there: their windows are whole milliseconds) and the next tick.
    let (mut next_plant, mut next_ms) = (0u64, 0u64);
    let mut next_tick = after_scheduler_stall(scenario, 0);
    let mut pacer = TickPacer::new(Duration::from_micros(TICK_US));
    let mut batch = TxBatch::new();
    let mut samples = Vec::with_capacity(scenario.duration_ms.min(100_000) as usize);
    let mut next_step = vec![0usize; scenario.targets.len()];
    // Frames on their way to the controller under a delay fault: (arrival µs, frame).
    let mut delayed: std::collections::VecDeque<(u64, CanFrame)> = Default::default();
    let mut rx_overruns = 0u64;

    // The earliest of `next_feedback`, kept up to date when a feedback time moves.
    let mut next_feedback_min = next_feedback.iter().copied().min();

    loop {
        let mut t = next_ms.min(next_tick);
        if let Some(f) = next_feedback_min {
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

        if !rx_stalled(scenario, t_ms)
            && let Some(drained) = rx.drain()
        {
            // The receive path runs again: the receiver reports an overrun once if either
            // FIFO lost frames, then reads what the FIFOs kept, before any frame that ends
            // now (which lands behind them).
            if drained.overrun {
                rc10.record_receive_error(ReceiveError::Overrun);
                observer.on_overrun_reported(t);
            }
            for frame in drained.frames {
                let r = rc10.dispatch(&frame, Instant::from_micros(t));
                observer.on_dispatch(t, &frame, r);
            }
        }

        // A frame ends on the wire: faults, then delivery to everyone but its sender.
        if let Some((sender, frame, mcu_seq)) = bus.complete_with_seq(t) {
            // The ESCs hear it before their step at `t`, if there is one.
            step_plants_before(&mut escs, &mut next_plant, t);
            let (received, corrupted) =
                deliver(scenario, &mut rng, &mut bus, &mut escs, sender, frame, t_ms);
            observer.on_wire(&WireEvent {
                t_us: t,
                sender,
                frame,
                mcu_seq,
                received,
                corrupted,
            });
            let to_mcu = received.filter(|_| sender != Sender::Mcu);
            if let Some(frame) = to_mcu {
                if bus.mcu_bus_off() {
                    observer.on_rx_dropped(t, &frame, RxDrop::BusOff);
                } else if bus.mcu_no_ack() {
                    observer.on_rx_dropped(t, &frame, RxDrop::NoAck);
                } else if !rx.accepts(&frame) {
                    observer.on_rx_dropped(t, &frame, RxDrop::Filtered);
                } else if rx_stalled(scenario, t_ms) {
                    if rx.store(frame) == Stored::Lost {
                        rx_overruns += 1;
                        observer.on_rx_dropped(t, &frame, RxDrop::Overrun);
                    }
                } else {
                    // The receive path is a queue: a frame waits behind every frame still
                    // delayed, even after the delay window has closed (it never overtakes
                    // older feedback).
                    let due = t.saturating_add(delay_us(scenario, t_ms));
                    match delayed.back() {
                        None if due == t => {
                            let r = rc10.dispatch(&frame, Instant::from_micros(t));
                            observer.on_dispatch(t, &frame, r);
                        }
                        back => {
                            let after = back.map_or(0, |&(b, _)| b);
                            delayed.push_back((due.max(after), frame));
                        }
                    }
                }
            }
        }
        while let Some(&(d, frame)) = delayed.front() {
            if d > t {
                break;
            }
            delayed.pop_front();
            if bus.mcu_bus_off() {
                observer.on_rx_dropped(d, &frame, RxDrop::BusOff);
            } else {
                let r = rc10.dispatch(&frame, Instant::from_micros(d));
                observer.on_dispatch(d, &frame, r);
            }
        }

        if t == next_ms {
            // The faults' states for this millisecond, then the plants' step at its start.
            step_plants_before(&mut escs, &mut next_plant, t);
            apply_state_faults(scenario, &mut bus, &mut escs, t_ms);
            step_plants_before(&mut escs, &mut next_plant, t + 1);
            next_ms += 1000;
        }

        if next_feedback_min == Some(t) {
            step_plants_before(&mut escs, &mut next_plant, t + 1);
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
            next_feedback_min = next_feedback.iter().copied().min();
        }

        // A tick falls on a millisecond's start: the plants have taken their step at `t`.
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
                    app.step(drive, &motors, &escs, now)
                        .map_err(|reason| SimError::Target { target: 0, reason })?,
                ),
                _ => None,
            };
            let paced = pacer.on_tick(now);
            if paced.resync {
                rc10.record_skipped_ticks(paced.skipped);
            }
            let held_before = bus.mcu_pending();
            let first_seq = bus.next_mcu_seq();
            // The tick and the sample under one critical section: each motor's own locks
            // inside it are then nested ones (on the host, a thread-local check instead of
            // taking std's global lock: 9 of the 13 a simulated millisecond took). Nothing
            // else runs on this thread meanwhile, so what rc10 does is unchanged.
            let (report, motor_samples) = critical_section::with(|_| {
                rc10.tick(now, paced.dt_s, &mut batch);
                let report = rc10.transmit(&batch, &mut bus.mcu_port());
                let motor_samples: MotorSamples = motors
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
                    .collect();
                (report, motor_samples)
            });
            let sample = Sample {
                t_ms,
                motors: motor_samples,
                chassis,
            };
            observer.on_tick(&TickEvent {
                t_us: t,
                paced,
                sample: &sample,
                batch: &batch,
                report,
                held_before,
                first_seq,
                bus_off: bus.mcu_bus_off(),
                no_ack: bus.mcu_no_ack(),
            });
            if observer.keep_sample(t_ms) {
                samples.push(sample);
            }
            next_tick = after_scheduler_stall(scenario, next_tick + TICK_US);
            if t_ms % 1000 == 999 {
                progress(t_ms + 1);
            }
        }

        bus.start_next(t);
    }

    let metrics = target_metrics(&scenario.targets, &samples);
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

/// Applies loss and corruption to a frame that ended on the wire and hands it to the ESCs.
/// Returns the frame as the other nodes received it (`None` if lost) and whether it was
/// corrupted.
fn deliver(
    scenario: &Scenario,
    rng: &mut Xoshiro256PlusPlus,
    bus: &mut SimBus,
    escs: &mut [DjiEsc],
    sender: Sender,
    frame: CanFrame,
    t_ms: u64,
) -> (Option<CanFrame>, bool) {
    let mut frame = frame;
    let mut corrupted = false;
    for fault in &scenario.faults {
        match *fault {
            Fault::FrameLoss {
                probability,
                from_ms,
                to_ms,
            } if in_window(t_ms, from_ms, to_ms) && uniform(rng) < probability => {
                bus.record_lost();
                return (None, corrupted);
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
                    corrupted = true;
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
    (Some(frame), corrupted)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::TxOrder;
    use crate::scenario::{builtin, builtin_named};

    #[test]
    fn a_target_on_a_chassis_wheel_is_refused() {
        use crate::scenario::{TargetKind, TargetSpec};
        let mut s = builtin_named("chassis-remote-drive").unwrap();
        s.duration_ms = 10;
        s.targets = vec![TargetSpec {
            motor: 3,
            kind: TargetKind::Rpm,
            steps: vec![(0, 100.0)],
        }];
        // The chassis would overwrite it at every tick: the run says so instead.
        match run(&s) {
            Err(SimError::Target { target: 0, reason }) => {
                assert!(reason.contains("motor 4 is a chassis wheel"), "{reason}");
            }
            other => panic!("{other:?}"),
        }
        // Without the chassis the same target drives the wheel.
        s.chassis = None;
        assert!(run(&s).is_ok());
    }

    #[test]
    fn scenario_bitrate_and_tx_order_reach_the_simulated_bus() {
        let mut scenario = builtin().swap_remove(0);
        assert_eq!(sim_bus_config(&scenario).mcu_tx_order, TxOrder::Fifo);
        scenario.tx_order = TxOrder::LowestIdFirst;
        scenario.bus.bitrate_bps = 500_000;
        let config = sim_bus_config(&scenario);
        assert_eq!(config.mcu_tx_order, TxOrder::LowestIdFirst);
        assert_eq!(config.bitrate_bps, 500_000);
        assert_eq!(config.mcu_tx_depth, SimBusConfig::default().mcu_tx_depth);
    }

    fn speed_step_with(faults: Vec<Fault>, duration_ms: u64) -> RunResult {
        let mut scenario = builtin().swap_remove(0);
        scenario.faults = faults;
        scenario.duration_ms = duration_ms;
        run(&scenario).unwrap()
    }

    #[test]
    fn without_acknowledgement_frames_stay_queued_and_the_motor_goes_offline_and_returns() {
        let r = speed_step_with(
            vec![Fault::NoAck {
                from_ms: 200,
                to_ms: 450,
            }],
            700,
        );
        assert_eq!(r.offline_events, vec![1]);
        let c = r.counters;
        // One command frame per tick. Ticks 200-202 fill the 3 TX buffers; ticks 203-450 find
        // them full (at 450 the held frames have not left yet): 248 refused. Each tick from
        // 201 on finds 1, 2, then 3 frames still queued; an ACK error is read at each tick
        // from 201 to 449.
        assert_eq!(c.tx_full, 248);
        assert_eq!(c.tx_stale, 1 + 2 + 3 * 248);
        assert_eq!(c.bus_errors, 249);
        assert_eq!(r.bus.mcu_tx_full, 248);
        let at = |t_ms: u64| r.samples.iter().find(|s| s.t_ms == t_ms).unwrap().motors[0];
        assert!(at(299).online && !at(302).online && !at(449).online);
        assert!(at(455).online);
        assert!(
            (at(699).true_rpm - 300.0).abs() < 2.0,
            "{}",
            at(699).true_rpm
        );
    }

    /// The time and rotor angle of every frame rc10 was handed.
    #[derive(Default)]
    struct Dispatched(Vec<(u64, u16)>);

    impl RunObserver for Dispatched {
        fn on_dispatch(&mut self, t_us: u64, frame: &CanFrame, _result: rc10_core::bus::Dispatch) {
            let d = frame.data();
            self.0.push((t_us, u16::from_be_bytes([d[0], d[1]])));
        }
    }

    #[test]
    fn delayed_feedback_is_never_overtaken_by_newer_feedback() {
        // 5 ms of receive delay in [100, 200) ms: when it ends, the five frames still on
        // their way arrive first, then the fresh ones; rc10 sees them in the order the motor
        // sent them (before, the fresh ones went straight in and the old ones after).
        let mut scenario = builtin().swap_remove(0);
        scenario.faults = vec![Fault::Delay {
            delay_us: 5000,
            from_ms: 100,
            to_ms: 200,
        }];
        scenario.duration_ms = 300;
        let mut seen = Dispatched::default();
        run_observed(&scenario, &mut |_| {}, &mut seen).unwrap();
        let times: Vec<u64> = seen.0.iter().map(|(t, _)| *t).collect();
        assert!(
            times.windows(2).all(|w| w[0] <= w[1]),
            "dispatch times go back"
        );
        // The motor turns forward from 0 towards 300 rpm: its multi-turn position only
        // grows, so consecutive raw angles step forward by less than half a turn.
        let backwards = seen.0.windows(2).filter(|w| {
            let step = (i32::from(w[1].1) - i32::from(w[0].1)).rem_euclid(8192);
            step > 4096
        });
        assert_eq!(backwards.count(), 0, "an older reading after a newer one");
        // Nothing was lost on the way: one frame a ms.
        assert!((298..=300).contains(&seen.0.len()), "{}", seen.0.len());
    }

    /// Every frame that reached the ESCs, with the time it ended and who sent it, and motor
    /// 0's true speed and angle at every tick.
    #[derive(Default)]
    struct WireAndTruth {
        wire: Vec<(u64, Sender, CanFrame)>,
        ticks: Vec<(u64, f64, f64)>,
    }

    impl RunObserver for WireAndTruth {
        fn on_wire(&mut self, event: &WireEvent) {
            if let Some(frame) = event.received {
                self.wire.push((event.t_us, event.sender, frame));
            }
        }

        fn on_tick(&mut self, tick: &TickEvent<'_>) {
            let m = tick.sample.motors[0];
            self.ticks.push((tick.t_us, m.true_rpm, m.true_total_deg));
        }
    }

    /// Motor 0's feedback phase in a run of a scenario with this seed: the run's first draw.
    fn phase_of(seed: u64) -> u64 {
        Xoshiro256PlusPlus::seed_from_u64(seed).next_u64() % TICK_US
    }

    /// Runs `scenario` and replays its motor 0 on its own, one microsecond at a time: the
    /// frames from others that end at t reach it first, then, at the start of a millisecond,
    /// its power cut, stall and over-temperature faults, then its step (at every multiple of
    /// 200 us), then its feedback (every ms at its phase, while powered) and the tick. Its
    /// feedback must be what it sent in the run and its state at each tick the run's truth,
    /// to the bit. Returns the command frames that ended after the step 200 us into their
    /// millisecond and those that ended on a step's time.
    fn replay_motor_0(scenario: &Scenario) -> (usize, usize) {
        let mut seen = WireAndTruth::default();
        run_observed(scenario, &mut |_| {}, &mut seen).unwrap();
        let phase = phase_of(scenario.seed);
        let is_feedback = |&&(_, sender, _): &&(u64, Sender, CanFrame)| sender == Sender::Device(0);
        // The phase drawn here is the run's: the first feedback went out on an idle bus then.
        let &(first_end, _, first) = seen.wire.iter().find(is_feedback).unwrap();
        let duration = rc10_core::can::timing::frame_time_us(&first, scenario.bus.bitrate_bps);
        assert_eq!(
            first_end,
            phase + u64::from(duration),
            "motor 0's feedback phase"
        );

        let spec = &scenario.motors[0];
        let model = MotorParams::for_model(spec.model);
        let mut esc = DjiEsc::new(model, spec.esc_id, spec.load, 0);
        let mut frames = seen.wire.iter().filter(|w| !is_feedback(w)).peekable();
        let mut ticks = seen.ticks.iter().peekable();
        let mut sent = Vec::new();
        let (mut compared, mut late_commands, mut commands_on_a_step) = (0, 0, 0);
        for t in 0..scenario.duration_ms * 1000 {
            while let Some(&(end, sender, frame)) = frames.next_if(|(end, ..)| *end <= t) {
                esc.on_frame(&frame);
                if sender == Sender::Mcu {
                    late_commands += usize::from(end % 1000 > 200);
                    commands_on_a_step += usize::from(end % 200 == 0);
                }
            }
            if t % 1000 == 0 {
                let t_ms = t / 1000;
                for fault in &scenario.faults {
                    match *fault {
                        Fault::PowerCut {
                            motor: 0,
                            from_ms,
                            to_ms,
                        } => {
                            esc.set_powered(!in_window(t_ms, from_ms, to_ms));
                        }
                        Fault::Stall {
                            motor: 0,
                            from_ms,
                            to_ms,
                        } => {
                            esc.set_locked(in_window(t_ms, from_ms, to_ms));
                        }
                        Fault::OverTemperature {
                            motor: 0,
                            at_ms,
                            celsius,
                        } if at_ms == t_ms => {
                            esc.set_temperature_c(celsius);
                        }
                        _ => {}
                    }
                }
            }
            if t % 200 == 0 {
                esc.step(t, PLANT_STEP_S);
            }
            if t % 1000 == phase && esc.powered() {
                sent.push((t, esc.feedback_frame().unwrap()));
            }
            if let Some(&(_, rpm, deg)) = ticks.next_if(|(at, ..)| *at == t) {
                assert_eq!(esc.speed_rpm().to_bits(), rpm.to_bits(), "speed at {t} us");
                assert_eq!(
                    esc.total_angle_deg().to_bits(),
                    deg.to_bits(),
                    "angle at {t} us"
                );
                compared += 1;
            }
        }
        assert_eq!(compared, scenario.duration_ms);
        // Each feedback frame on the wire is the one sent last before it ended (a power cut
        // drops the one it catches on the wire).
        let mut on_wire = 0;
        for &(end, _, frame) in seen.wire.iter().filter(is_feedback) {
            let &(at, replayed) = sent.iter().rev().find(|(at, _)| *at < end).unwrap();
            assert_eq!(frame, replayed, "feedback sent at {at} us");
            on_wire += 1;
        }
        assert!(on_wire + 20 >= sent.len(), "{on_wire} of {}", sent.len());
        // The comparison is of a motor that moved.
        assert!(seen.ticks.iter().any(|&(_, rpm, _)| rpm > 250.0));
        (late_commands, commands_on_a_step)
    }

    #[test]
    fn the_plant_steps_every_200_us_between_the_frames_it_hears_and_the_feedback_it_sends() {
        let mut scenario = builtin_named("m3508-speed-step").unwrap();
        scenario.duration_ms = 120;
        // At 500 kbit/s a command frame lasts about 250 us: it ends after the plant's step
        // 200 us into the tick that sent it. The feedback goes out 400 us into each ms, at
        // the time of a step that nothing else asks for; the steps at 600 and 800 us are
        // still to be taken at the next millisecond's start, where the faults that change
        // the plant take effect after them.
        scenario.bus.bitrate_bps = 500_000;
        scenario.seed = (0..).find(|&seed| phase_of(seed) == 400).unwrap();
        scenario.faults = vec![
            Fault::PowerCut {
                motor: 0,
                from_ms: 30,
                to_ms: 45,
            },
            Fault::Stall {
                motor: 0,
                from_ms: 70,
                to_ms: 80,
            },
            Fault::OverTemperature {
                motor: 0,
                at_ms: 100,
                celsius: 130.0,
            },
        ];
        let (late_commands, _) = replay_motor_0(&scenario);
        assert!(late_commands > 100, "{late_commands}");

        // At 1 Mbit/s, a command frame held behind a feedback frame can end exactly on a
        // step's time: it reaches the plant before that step. A seed whose phase puts the
        // feedback just before the tick, for which that happens.
        scenario.bus.bitrate_bps = 1_000_000;
        scenario.faults.clear();
        let on_a_step = (0..5000)
            .filter(|&seed| (930..960).contains(&phase_of(seed)))
            .find_map(|seed| {
                scenario.seed = seed;
                let (_, on_a_step) = replay_motor_0(&scenario);
                (on_a_step > 0).then_some(on_a_step)
            });
        assert!(
            on_a_step.is_some(),
            "no command frame ended on a step's time"
        );
    }

    #[test]
    fn a_scheduler_stall_skips_the_missed_ticks_instead_of_running_them() {
        let r = speed_step_with(
            vec![Fault::SchedulerStall {
                from_ms: 100,
                to_ms: 120,
            }],
            400,
        );
        assert_eq!((r.counters.ticks, r.counters.ticks_skipped), (380, 20));
        let ticks: Vec<u64> = r.samples.iter().map(|s| s.t_ms).collect();
        assert!(ticks.contains(&99) && ticks.contains(&120) && ticks.contains(&121));
        assert!(!ticks.iter().any(|t| (100..120).contains(t)));
    }

    #[test]
    fn every_window_of_a_repeated_fault_takes_effect() {
        let r = speed_step_with(
            vec![
                Fault::BusOff {
                    from_ms: 100,
                    to_ms: 250,
                },
                Fault::BusOff {
                    from_ms: 400,
                    to_ms: 550,
                },
                Fault::PowerCut {
                    motor: 0,
                    from_ms: 700,
                    to_ms: 850,
                },
                Fault::PowerCut {
                    motor: 0,
                    from_ms: 1_000,
                    to_ms: 1_150,
                },
            ],
            1_300,
        );
        assert_eq!(r.counters.bus_off_events, 2);
        assert_eq!(r.offline_events, vec![4]);
    }
}
