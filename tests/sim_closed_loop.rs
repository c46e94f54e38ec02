//! Closed loop through the simulator: rc10-core's real bus, scheduler and DJI drivers against
//! the physical ESC + motor plants on a simulated CAN bus, in virtual time.

// Test code: a failed setup or assertion should stop the test.
#![allow(clippy::unwrap_used, clippy::panic, clippy::indexing_slicing)]

use rc10_core::bus::RegisterError;
use rc10_core::motor::dji::DjiModel;
use rc10_sim::metrics::min_speed_rise_time_s;
use rc10_sim::plant::{Load, MotorParams};
use rc10_sim::scenario::{
    Controller, MotorSpec, RunResult, Scenario, SimError, TargetKind, TargetSpec, builtin_named,
    run,
};

fn scenario(name: &str) -> Scenario {
    builtin_named(name).unwrap()
}

fn motor_series(r: &RunResult, motor: usize) -> Vec<(u64, rc10_sim::scenario::MotorSample)> {
    r.samples
        .iter()
        .map(|s| (s.t_ms, s.motors[motor]))
        .collect()
}

#[test]
fn m3508_speed_step_meets_the_control_targets_with_default_gains() {
    let r = run(&scenario("m3508-speed-step")).unwrap();
    let m = r.metrics[0].metrics;
    let min = min_speed_rise_time_s(MotorParams::m3508(), Load::default(), 300.0).unwrap();
    // SPEC.md quality targets.
    assert!(
        m.rise_time_s.unwrap() <= 1.5 * min,
        "rise {:?} vs min {min}",
        m.rise_time_s
    );
    assert!(
        m.overshoot_percent <= 5.0,
        "overshoot {}",
        m.overshoot_percent
    );
    assert!(
        m.settling_time_s.unwrap() <= 0.100,
        "settling {:?}",
        m.settling_time_s
    );
    assert!(
        m.steady_state_error <= 1.0,
        "steady error {}",
        m.steady_state_error
    );
    assert!(m.peak_current_amps <= 20.0 + 1e-9);
}

#[test]
fn rc10_beats_rc10_lib_demo_loop_on_every_metric() {
    // Both over RC10_LIB's 3 s window, long enough for its slow transient to finish.
    let legacy = scenario("m3508-speed-step-rc10lib");
    let mut ours = scenario("m3508-speed-step");
    ours.duration_ms = legacy.duration_ms;
    let ours = run(&ours).unwrap().metrics[0].metrics;
    let theirs = run(&legacy).unwrap().metrics[0].metrics;
    let never = f64::INFINITY;
    assert!(ours.rise_time_s.unwrap() < theirs.rise_time_s.unwrap_or(never));
    assert!(ours.settling_time_s.unwrap() < theirs.settling_time_s.unwrap_or(never));
    assert!(ours.overshoot_percent < theirs.overshoot_percent);
    assert!(ours.steady_state_error < theirs.steady_state_error);
    assert!(ours.iae < theirs.iae);
}

#[test]
fn angle_step_across_zero_goes_the_short_way() {
    // From 0° to 350°: 10° backwards, never forwards.
    let r = run(&scenario("m3508-angle-step")).unwrap();
    let series = motor_series(&r, 0);
    let max = series
        .iter()
        .map(|(_, m)| m.true_total_deg)
        .fold(f64::MIN, f64::max);
    let min = series
        .iter()
        .map(|(_, m)| m.true_total_deg)
        .fold(f64::MAX, f64::min);
    assert!(max < 0.5, "moved forwards to {max}°");
    assert!(min > -10.5, "overshot to {min}°");
    let end = series.last().unwrap().1.true_total_deg;
    assert!((end + 10.0).abs() < 0.2, "ended at {end}°");
}

#[test]
fn gm6020_gimbal_holds_angle_under_a_load_torque_step() {
    let r = run(&scenario("gm6020-gimbal")).unwrap();
    let series = motor_series(&r, 0);
    let before = series
        .iter()
        .find(|(t, _)| *t == 399)
        .unwrap()
        .1
        .true_total_deg;
    assert!(
        (before - 90.0).abs() < 0.5,
        "not at 90° before the load step: {before}"
    );
    let worst = series
        .iter()
        .filter(|(t, _)| *t >= 400)
        .map(|(_, m)| (m.true_total_deg - 90.0).abs())
        .fold(0.0, f64::max);
    assert!(worst < 2.0, "load step pushed it {worst}° away");
    let end = series.last().unwrap().1.true_total_deg;
    assert!((end - 90.0).abs() < 0.2, "ended {end}°");
}

#[test]
fn power_cut_is_detected_within_timeout_commands_zero_and_recovers() {
    let r = run(&scenario("fault-power-cut")).unwrap();
    let series = motor_series(&r, 0);
    // Power goes at 300 ms: offline by 300 + 100 ms timeout + a tick of slack.
    let went_offline = series
        .iter()
        .find(|(t, m)| *t > 300 && !m.online)
        .unwrap()
        .0;
    assert!(went_offline <= 402, "offline detected at {went_offline} ms");
    assert!(
        went_offline >= 390,
        "offline too early at {went_offline} ms (5 % frame loss)"
    );
    for (t, m) in &series {
        if !m.online && *t > 300 {
            assert_eq!(m.command, 0.0, "command at {t} ms while offline");
        }
    }
    // Power returns at 500 ms: online within a few ms, and back at speed by 700 ms.
    let back = series
        .iter()
        .find(|(t, m)| *t >= 500 && m.online)
        .unwrap()
        .0;
    assert!(back <= 505, "back online at {back} ms");
    let at_700 = series.iter().find(|(t, _)| *t == 700).unwrap().1.true_rpm;
    assert!((at_700 - 200.0).abs() < 4.0, "{at_700} rpm at 700 ms");
    assert_eq!(r.offline_events, vec![1, 0]);
    // The injected faults were seen and counted, not hidden.
    assert!(r.bus.lost > 0);
    assert!(r.counters.rx_rejected > 0);
    // The other motor kept running through the 5 % loss.
    let other = r.samples.last().unwrap().motors[1].true_rpm;
    assert!((other - 200.0).abs() < 2.0);
}

#[test]
fn overloaded_bus_is_reported_at_registration() {
    let mut s = scenario("m3508-speed-step");
    s.motors = (1..=7)
        .map(|id| MotorSpec {
            model: DjiModel::M3508,
            esc_id: id,
            load: Load::default(),
            controller: Controller::Rc10,
        })
        .collect();
    match run(&s) {
        Err(SimError::Register {
            motor: 6,
            error: RegisterError::FrameBudget { load_percent },
        }) => assert!(load_percent > 90.0),
        other => panic!("expected a frame-budget error, got {other:?}"),
    }
}

#[test]
fn same_seed_same_trace_different_seed_different_trace() {
    let a = run(&scenario("fault-power-cut")).unwrap();
    let b = run(&scenario("fault-power-cut")).unwrap();
    assert_eq!(a, b);
    let mut other = scenario("fault-power-cut");
    other.seed = 2;
    let c = run(&other).unwrap();
    assert_ne!(a.samples, c.samples);
}

#[test]
fn targets_for_missing_motors_are_an_error() {
    let mut s = scenario("m3508-speed-step");
    s.targets.push(TargetSpec {
        motor: 5,
        kind: TargetKind::Rpm,
        steps: vec![(0, 1.0)],
    });
    assert!(matches!(run(&s), Err(SimError::Target { target: 1, .. })));
}

fn example_file(name: &str) -> Scenario {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples/sim")
        .join(name);
    rc10_sim::file::load(&path).unwrap()
}

#[test]
fn example_yaw_tuning_file_reaches_both_targets_and_resists_the_push() {
    let r = run(&example_file("yaw-tuning.toml")).unwrap();
    let series = motor_series(&r, 0);
    let at = |t: u64| {
        series
            .iter()
            .find(|(ms, _)| *ms == t)
            .unwrap()
            .1
            .true_total_deg
    };
    assert!((at(590) - 90.0).abs() < 0.5, "{}", at(590));
    assert!((at(1090) + 45.0).abs() < 0.5, "{}", at(1090));
    let worst_after_push = series
        .iter()
        .filter(|(t, _)| *t >= 1100)
        .map(|(_, m)| (m.true_total_deg + 45.0).abs())
        .fold(0.0, f64::max);
    assert!(worst_after_push < 2.0, "{worst_after_push}");
}

#[test]
fn example_chassis_file_isolates_the_unpowered_wheel() {
    let r = run(&example_file("chassis-power-cut.toml")).unwrap();
    assert_eq!(r.offline_events, vec![0, 1, 0, 0]);
    let end = &r.samples.last().unwrap().motors;
    for (m, target) in end.iter().zip([200.0, 200.0, -200.0, -200.0]) {
        assert!(
            (m.true_rpm - target).abs() < 2.0,
            "{} vs {target}",
            m.true_rpm
        );
    }
}

fn single_m3508_at(rpm: f32, faults: Vec<rc10_sim::scenario::Fault>, duration_ms: u64) -> Scenario {
    let mut s = scenario("m3508-speed-step");
    s.targets[0].steps = vec![(10, rpm)];
    s.faults = faults;
    s.duration_ms = duration_ms;
    s
}

#[test]
fn bus_off_interval_is_counted_motor_goes_offline_and_control_resumes() {
    use rc10_sim::scenario::Fault;
    let s = single_m3508_at(
        200.0,
        vec![Fault::BusOff {
            from_ms: 300,
            to_ms: 450,
        }],
        900,
    );
    let r = run(&s).unwrap();
    assert_eq!(r.counters.bus_off_events, 1);
    assert!(r.counters.tx_bus_off >= 140, "{}", r.counters.tx_bus_off);
    // 150 ms without feedback: offline once, then back.
    assert_eq!(r.offline_events, vec![1]);
    let end = r.samples.last().unwrap().motors[0];
    assert!(end.online);
    assert!((end.true_rpm - 200.0).abs() < 1.0, "{}", end.true_rpm);
}

#[test]
fn delayed_feedback_still_controls_within_targets() {
    use rc10_sim::scenario::Fault;
    // Every frame reaches rc10 2 ms late: older feedback, same loop.
    let s = single_m3508_at(
        300.0,
        vec![Fault::Delay {
            delay_us: 2000,
            from_ms: 0,
            to_ms: 400,
        }],
        400,
    );
    let r = run(&s).unwrap();
    let m = r.metrics[0].metrics;
    assert!(m.overshoot_percent < 10.0, "{}", m.overshoot_percent);
    assert!(m.steady_state_error < 1.0);
    // The delay is visible: what rc10 measured lags the truth during the rise.
    let rising = r.samples.iter().find(|s| s.t_ms == 30).unwrap().motors[0];
    assert!(f64::from(rising.measured_rpm) < rising.true_rpm - 5.0);
}

#[test]
fn stalled_receiver_overflows_the_three_deep_rx_fifos_and_reports_it_once() {
    use rc10_sim::scenario::Fault;
    // Two motors, one in each RX FIFO: a 5 ms stall brings each FIFO 5 frames, 3 fit, 2 are
    // lost. The receiver, running again, reports one overrun for them all.
    let mut s = scenario("fault-power-cut");
    s.faults = vec![Fault::RxStall {
        from_ms: 200,
        to_ms: 205,
    }];
    let r = run(&s).unwrap();
    assert_eq!(r.rx_overruns, 4);
    assert_eq!(r.counters.rx_overruns, 1);
    // A 5 ms gap is far below the offline timeout: nobody went offline.
    assert_eq!(r.offline_events, vec![0, 0]);
    // Two stalls that each lose frames are two overruns; a stall too short to fill a FIFO
    // (1 ms: one frame each) is none.
    s.faults = vec![
        Fault::RxStall {
            from_ms: 200,
            to_ms: 205,
        },
        Fault::RxStall {
            from_ms: 250,
            to_ms: 251,
        },
        Fault::RxStall {
            from_ms: 260,
            to_ms: 270,
        },
    ];
    let r = run(&s).unwrap();
    assert_eq!(r.counters.rx_overruns, 2);
    // 2 + 2 lost in the first stall, 7 + 7 in the third (10 frames a FIFO, 3 kept).
    assert_eq!(r.rx_overruns, 18);
}

#[test]
fn m2006_speed_step_meets_the_control_targets_with_default_gains() {
    let r = run(&scenario("m2006-speed-step")).unwrap();
    let m = r.metrics[0].metrics;
    let min = min_speed_rise_time_s(MotorParams::m2006(), Load::default(), 300.0).unwrap();
    assert!(m.rise_time_s.unwrap() <= 1.5 * min);
    assert!(m.overshoot_percent <= 5.0, "{}", m.overshoot_percent);
    assert!(
        m.settling_time_s.unwrap() <= 0.100,
        "{:?}",
        m.settling_time_s
    );
    assert!(m.steady_state_error <= 1.0);
}

#[test]
fn gm6020_current_mode_gimbal_holds_angle_with_default_gains() {
    let mut s = scenario("gm6020-gimbal");
    s.motors[0].model = DjiModel::Gm6020Current;
    let r = run(&s).unwrap();
    let series = motor_series(&r, 0);
    let overshoot = series
        .iter()
        .filter(|(t, _)| *t < 400)
        .map(|(_, m)| m.true_total_deg - 90.0)
        .fold(f64::MIN, f64::max);
    assert!(overshoot < 1.0, "{overshoot}");
    let worst = series
        .iter()
        .filter(|(t, _)| *t >= 400)
        .map(|(_, m)| (m.true_total_deg - 90.0).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1.5, "{worst}");
    // The current command never exceeds the GM6020's 3 A range.
    assert!(series.iter().all(|(_, m)| m.command.abs() <= 3.0));
}

#[test]
fn remote_driven_mecanum_chassis_tracks_the_sticks_and_stops_on_radio_loss() {
    let s = scenario("chassis-remote-drive");
    let r = run(&s).unwrap();
    let c: Vec<(u64, rc10_sim::scenario::ChassisSample)> = r
        .samples
        .iter()
        .map(|x| (x.t_ms, x.chassis.unwrap()))
        .collect();
    let at = |t: u64| c.iter().find(|(ms, _)| *ms == t).unwrap().1;
    // Full forward stick: 2 m/s after the 4 m/s² ramp, achieved by the four wheels.
    let fwd = at(900);
    assert!((fwd.commanded.vx_m_s - 2.0).abs() < 1e-3);
    assert!((fwd.achieved.vx_m_s - 2.0).abs() < 0.05, "{fwd:?}");
    assert!(fwd.achieved.vy_m_s.abs() < 0.02 && fwd.achieved.omega_rad_s.abs() < 0.02);
    // Strafe left (stick left): +vy.
    assert!((at(1700).achieved.vy_m_s - 2.0).abs() < 0.05);
    // Half stick right-x to the left: spin counter-clockwise at 4 rad/s · 0.49 (deadband).
    assert!((at(2500).achieved.omega_rad_s - 1.96).abs() < 0.05);
    // Diagonal: the direction is kept.
    let diag = at(3250).achieved;
    assert!((diag.vy_m_s / diag.vx_m_s - 1.0).abs() < 0.02, "{diag:?}");
    // Tracking over the whole run.
    let rms = (c
        .iter()
        .map(|(_, x)| (x.achieved.vx_m_s - x.commanded.vx_m_s).powi(2))
        .sum::<f32>()
        / c.len() as f32)
        .sqrt();
    assert!(rms < 0.05, "rms {rms}");
    // Radio off at 3300 ms: lost within the 100 ms timeout after the last frame...
    let lost = c.iter().find(|(t, x)| *t >= 3300 && x.link_lost).unwrap().0;
    assert!((3385..=3401).contains(&lost), "lost at {lost}");
    // ...the command ramps to zero and the chassis stops: 1.39 m/s at 4 m/s² ≈ 0.35 s.
    let stopped = c
        .iter()
        .find(|(t, x)| {
            *t >= lost && x.achieved.vx_m_s.abs() < 0.05 && x.achieved.vy_m_s.abs() < 0.05
        })
        .unwrap()
        .0;
    assert!(
        stopped - lost < 450,
        "stopped {} ms after loss",
        stopped - lost
    );
    let end = c.last().unwrap().1;
    assert!(end.achieved.vx_m_s.abs() < 0.02 && end.commanded == rc10_core::chassis::Twist::ZERO);
    assert_eq!(r.offline_events, vec![0; 4]);
}

#[test]
fn a_dr16_frame_cut_short_by_the_radio_is_dropped() {
    // The radio stops at 113 ms, in the middle of the frame that began at 112 ms (the first
    // with the forward stick set at 100 ms): its first 9 bytes end by 112.99 ms, the rest are
    // never sent. 9 bytes between two silences are no DBUS frame, so the robot never sees
    // the forward stick: it keeps the last whole frame (98 ms, neutral) until the link is
    // lost 100 ms after that frame's last byte, read one idle character (110 µs) after it
    // ended at 99.98 ms: at the tick after 200.09 ms.
    let mut s = example_file("mecanum-drive.toml");
    s.duration_ms = 400;
    if let Some(chassis) = &mut s.chassis {
        chassis.radio_off = vec![(113, 400)];
    }
    let r = run(&s).unwrap();
    let c: Vec<_> = r
        .samples
        .iter()
        .map(|x| (x.t_ms, x.chassis.unwrap()))
        .collect();
    assert!(c.iter().all(|(_, x)| x.commanded.vx_m_s == 0.0));
    let first_lost = c
        .iter()
        .filter(|(t, _)| *t > 50)
        .find(|(_, x)| x.link_lost)
        .map(|(t, _)| *t);
    assert_eq!(first_lost, Some(201));
}

#[test]
fn a_bus_tick_period_the_simulator_does_not_run_is_refused() {
    // rc10 would pace its ticks, dt and load figures at 2 ms while the simulation ticks
    // every 1 ms.
    let mut s = scenario("m3508-speed-step");
    s.bus.tick_period = rc10_core::time::Duration::from_millis(2);
    assert!(matches!(run(&s), Err(SimError::TickPeriod { us: 2000 })));
}

#[test]
fn dr16_frames_sent_while_the_scheduler_stalls_are_read_after_it() {
    // The scheduler stalls from 113 to 140 ms. The DR16 goes on sending: the frame of 112 ms
    // (the first with the forward stick) and that of 126 ms are read at the 140 ms tick with
    // their own stamps, and the second is proven whole by the silence after it (its last
    // byte read at 128.09 ms), so the chassis moves forward from that tick on.
    let mut s = example_file("mecanum-drive.toml");
    s.duration_ms = 300;
    s.faults.push(rc10_sim::scenario::Fault::SchedulerStall {
        from_ms: 113,
        to_ms: 140,
    });
    let r = run(&s).unwrap();
    let c = |t: u64| {
        r.samples
            .iter()
            .find(|x| x.t_ms == t)
            .and_then(|x| x.chassis)
            .unwrap()
    };
    assert_eq!(c(112).commanded.vx_m_s, 0.0);
    assert!(r.samples.iter().all(|x| !(113..140).contains(&x.t_ms)));
    assert!(c(140).commanded.vx_m_s > 0.0, "{:?}", c(140));
    assert!(!c(140).link_lost);
}

#[test]
fn example_mecanum_file_drives_and_fails_safe() {
    let r = run(&example_file("mecanum-drive.toml")).unwrap();
    let c = |t: u64| {
        r.samples
            .iter()
            .find(|s| s.t_ms == t)
            .unwrap()
            .chassis
            .unwrap()
    };
    // The forward stick set at 100 ms goes out in the DR16 frame of 112 ms (one every
    // 14 ms): 18 bytes of 110 µs end at 113.98 ms, read one idle character later (114.09),
    // and the frame counts once more than 2.5 ms of silence follow, at the tick of 117 ms.
    assert_eq!(c(116).commanded.vx_m_s, 0.0);
    assert!(c(117).commanded.vx_m_s > 0.0, "{:?}", c(117));
    // Full forward: 2.5 m/s is 314 rpm per wheel, inside the 450 rpm limit.
    assert!((c(850).achieved.vx_m_s - 2.5).abs() < 0.06, "{:?}", c(850));
    // Full spin: 5 rad/s needs 0.38 · 5 / 0.076 rad/s = 239 rpm: reached by the end of the
    // segment (the limiter takes 0.5 s to swap 2 m/s of strafe for 5 rad/s of spin; the
    // loaded wheels overshoot the end of the ramp by about 3 %, which has decayed to about
    // 2 % 80 ms later).
    let peak = (2200..2300)
        .map(|t| c(t).achieved.omega_rad_s)
        .fold(0.0f32, f32::max);
    assert!(peak < 5.0 * 1.05, "peak {peak}");
    assert!(
        (c(2295).achieved.omega_rad_s - 5.0).abs() < 0.12,
        "{:?}",
        c(2295)
    );
    // The stick stays pushed but the radio is silent from 2600 ms: stopped by the end.
    let end = r.samples.last().unwrap().chassis.unwrap();
    assert!(end.link_lost);
    assert!(end.achieved.vx_m_s.abs() < 0.05, "{end:?}");
}

#[test]
fn a_stalled_receiver_holds_the_speed_integral_instead_of_ramping_the_command() {
    use rc10_sim::scenario::Fault;
    // A small step (0 -> 20 rpm at 10 ms: P is 0.6 A/rpm · 20 rpm = 12 A, within the 20 A
    // limit) and the receive path blocked from 11 to 41 ms: rc10 hears nothing new, the motor
    // stays online. Integrating the 20 rpm error it last measured would ramp the command by
    // ki · e = 8 A/(rpm·s) · 20 rpm = 0.16 A every tick; held, the command stays put from 3 ms
    // after the last frame until frames come again.
    let mut s = scenario("m3508-speed-step");
    s.targets[0].steps = vec![(0, 0.0), (10, 20.0)];
    s.faults = vec![Fault::RxStall {
        from_ms: 11,
        to_ms: 41,
    }];
    let r = run(&s).unwrap();
    let series = motor_series(&r, 0);
    let at = |t: u64| series.iter().find(|(ms, _)| *ms == t).unwrap().1;
    let held = at(15).command;
    assert!((12.0..14.0).contains(&held), "{held}");
    for t in 15..=40 {
        let m = at(t);
        assert!(m.online, "{t}");
        assert_eq!(m.command, held, "{t} ms");
    }
    assert_eq!(r.offline_events, vec![0]);
    // Frames again: the loop measures the speed its held command drove the motor to and
    // brings it back to 20 rpm.
    assert_ne!(at(45).command, held);
    let settled = at(300);
    assert!(
        (settled.true_rpm - 20.0).abs() < 1.0,
        "{}",
        settled.true_rpm
    );
}

#[test]
fn multi_turn_angle_survives_a_stalled_receive_path() {
    // An M2006 in speed mode; the controller's receive path stalls for 4 or 10 ms. The
    // first frames of the stall wait in the 3-deep FIFO and are read when it ends, stamped
    // then; the rest are lost. rc10's multi-turn angle must follow the shaft through it:
    // its lag behind the true angle (the age of the newest frame) is the same after the
    // stall as before. A turn miscounted is 10° at the output (36:1).
    use rc10_sim::scenario::Fault;
    for (rpm, stall_ms) in [(488.0, 4), (488.0, 10), (300.0, 4), (100.0, 10)] {
        let mut s = scenario("m2006-speed-step");
        s.duration_ms = 600;
        s.targets[0].steps = vec![(0, rpm)];
        s.faults = vec![Fault::RxStall {
            from_ms: 400,
            to_ms: 400 + stall_ms,
        }];
        let r = run(&s).unwrap();
        let lag = |t: u64| {
            let m = r.samples.iter().find(|x| x.t_ms == t).unwrap().motors[0];
            f64::from(m.measured_total_deg) - m.true_total_deg
        };
        // 4 or 10 frames came in the stall; the FIFO kept 3.
        assert_eq!(r.rx_overruns, stall_ms - 3, "{rpm} rpm");
        assert!(
            (lag(599) - lag(399)).abs() < 1.0,
            "{rpm} rpm, {stall_ms} ms stall: lag {:.2}° before, {:.2}° after",
            lag(399),
            lag(599)
        );
    }
}

/// An M3508 in total-angle mode with an integrating angle loop (kp 8 rpm/°, ki 5 rpm/(°·s)):
/// a 30° step, alone, or with the rotor locked for the first second (a mechanism jammed, a
/// wheel against a wall). 30° asks 240 rpm of the angle loop, within its 400 rpm limit: only
/// the speed loop is held at its limit (the full 20 A against a locked rotor).
fn m3508_angle_step_with_integral(stall_ms: u64) -> Scenario {
    use rc10_core::motor::dji::DjiConfig;
    use rc10_core::pid::PidConfig;
    let mut config = DjiConfig::default_for(DjiModel::M3508);
    config.cascade.angle = PidConfig::new(8.0, 5.0, 0.0).with_output_limit(400.0);
    let mut s = scenario("m3508-angle-step");
    s.motors[0].controller = Controller::Rc10With(config);
    s.targets[0].kind = TargetKind::TotalAngleDeg;
    s.targets[0].steps = vec![(0, 0.0), (10, 30.0)];
    s.faults = if stall_ms > 0 {
        vec![rc10_sim::scenario::Fault::Stall {
            motor: 0,
            from_ms: 0,
            to_ms: stall_ms,
        }]
    } else {
        Vec::new()
    };
    s.duration_ms = stall_ms + 800;
    s
}

#[test]
fn a_jammed_shaft_freed_moves_to_its_angle_as_a_fresh_step_does() {
    // Locked, the shaft cannot close its 30° error, and the speed loop is held at its limit
    // the whole time: the angle loop must not integrate that error (5 rpm/(°·s) · 30° · 1 s
    // would be 150 rpm more speed target to unwind). Freed, the shaft starts from rest with
    // the same 30° to go as a fresh step: it must move the same way, not overshoot by the
    // wound-up integral.
    let peak_over = |r: &RunResult, from_ms: u64| {
        motor_series(r, 0)
            .iter()
            .filter(|(t, _)| *t >= from_ms)
            .map(|(_, m)| m.true_total_deg - 30.0)
            .fold(f64::MIN, f64::max)
    };
    let fresh = run(&m3508_angle_step_with_integral(0)).unwrap();
    let freed = run(&m3508_angle_step_with_integral(1000)).unwrap();
    let (fresh_over, freed_over) = (peak_over(&fresh, 10), peak_over(&freed, 1000));
    // Still locked at the end of the stall: no motion at all.
    let at_release = motor_series(&freed, 0)
        .iter()
        .find(|(t, _)| *t == 999)
        .unwrap()
        .1;
    assert!(at_release.true_total_deg.abs() < 1e-9);
    assert!(
        freed_over < fresh_over + 0.5,
        "freed after 1 s: {freed_over:.2}° over 30°, a fresh step {fresh_over:.2}°"
    );
    // And both end at 30°.
    for r in [&fresh, &freed] {
        let end = motor_series(r, 0).last().unwrap().1.true_total_deg;
        assert!((end - 30.0).abs() < 0.2, "ended at {end}°");
    }
}

#[test]
fn gm6020_voltage_feed_forward_holds_its_load_without_the_integral() {
    use rc10_core::bus::BusBuilder;
    use rc10_core::motor::Motor;
    use rc10_core::motor::dji::DjiMotor;
    use rc10_core::node::TxBatch;
    use rc10_core::time::Instant;
    use rc10_sim::plant::DjiEsc;

    // A gimbal pitch pulled down by 0.5 N·m, told to hold still (0 rpm) with a feed-forward
    // of that torque. The plant turns volts into torque by the GM6020's published
    // torque–speed line (at 24 V: 320 rpm free, 156 rpm less per N·m), so at standstill
    // 24 V holds 320 / 156 N·m: the feed-forward is 0.5 · 24 · 156 / 320 = 5.85 V, and
    // with it the arm neither sags nor needs the speed loop's integral to hold it.
    const LOAD_NM: f64 = 0.5;
    let motor = DjiMotor::gm6020_voltage(1).unwrap();
    let mut builder = BusBuilder::<1>::new();
    builder.register(&motor).unwrap();
    let bus = builder.build();
    let load = Load {
        torque_nm: LOAD_NM,
        ..Load::default()
    };
    let mut esc = DjiEsc::new(MotorParams::gm6020_voltage(), 1, load, 0);
    motor.set_feed_forward_torque_nm(LOAD_NM as f32).unwrap();
    motor.set_target_rpm(0.0).unwrap();

    let mut batch = TxBatch::new();
    let mut sag_deg = 0.0f64;
    for ms in 0..1000u64 {
        let now = Instant::from_millis(ms);
        if let Some(frame) = esc.feedback_frame() {
            bus.dispatch(&frame, now);
        }
        bus.tick(now, 0.001, &mut batch);
        for frame in batch.frames() {
            esc.on_frame(frame);
        }
        for step in 0..5 {
            esc.step(ms * 1000 + step * 200, 200e-6);
        }
        sag_deg = sag_deg.max(-esc.total_angle_deg());
    }
    let terms = motor.speed_loop_terms();
    assert!(
        (terms.ff - 5.85).abs() < 1e-3,
        "feed-forward {} V",
        terms.ff
    );
    // Without the right feed-forward the integral has to make up the rest (4.6 V with the
    // phase resistance's 2.4 V/(N·m)), and the arm sags while it winds up.
    // The plant's static friction (0.01 N·m) lets the shaft rest with the integral anywhere
    // within ±0.01 · 11.7 = ±0.12 V.
    assert!(terms.i.abs() < 0.12, "integral {} V", terms.i);
    // Before the first command the arm falls freely for up to 1 ms:
    // ½ · (0.49 N·m / 1.8e-4 kg·m²) · (1 ms)² = 1.4 mrad = 0.078°; twice that lets the speed
    // loop catch it.
    assert!(sag_deg < 0.16, "sagged {sag_deg}°");
    assert!(motor.speed_rpm().abs() < 1.0, "{} rpm", motor.speed_rpm());
}
