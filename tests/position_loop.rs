//! Cascaded angle → speed → current loop built from rc10-core parts (encoder, positional PID in
//! circular mode, incremental PID with TD, bounded dt) around a rigid-body M3508 model.
//! Checks what a robot would notice: the short way across 0°/360°, settling, no current beyond
//! the ESC limit. The full physical plant and CAN-level loop live in rc10-sim's tests.

#![allow(clippy::unwrap_used)] // test code: a failed setup should stop the test

use rc10_core::encoder::{Encoder, EncoderConfig, GearRatio};
use rc10_core::pid::{ErrorMode, IncrementalPid, IncrementalPidConfig, Pid, PidConfig};
use rc10_core::time::{DeltaTime, Duration, Instant};

/// M3508 at the output shaft (SPEC.md protocol facts): 0.3 N·m/A, ~6.5e-3 kg·m² reflected.
const KT_NM_PER_A: f64 = 0.3;
const INERTIA_KG_M2: f64 = 6.5e-3;
const VISCOUS_NM_PER_RAD_S: f64 = 0.01;
const CURRENT_LIMIT_A: f32 = 20.0;

struct Run {
    final_angle_deg: f32,
    min_total_deg: f32,
    max_total_deg: f32,
    peak_current_a: f32,
}

fn run_position_step(target_deg: f32, seconds: f64) -> Run {
    let mut enc = Encoder::new(EncoderConfig::dji(GearRatio::M3508)).unwrap();
    let mut angle = Pid::new(
        PidConfig::new(6.0, 0.0, 0.0)
            .with_output_limit(200.0) // rpm
            .with_error_mode(ErrorMode::DEGREES),
    )
    .unwrap();
    let mut speed = IncrementalPid::new(
        IncrementalPidConfig::new(0.5, 10.0, 0.0)
            .with_output_limit(CURRENT_LIMIT_A)
            .with_td(200.0),
    )
    .unwrap();
    let mut clock = DeltaTime::new(Duration::from_micros(1000), Duration::from_micros(5000));

    let ratio = 3591.0 / 187.0;
    let mut omega = 0.0f64; // output rad/s
    let mut rotor_counts = 0.0f64;
    let mut run = Run {
        final_angle_deg: 0.0,
        min_total_deg: 0.0,
        max_total_deg: 0.0,
        peak_current_a: 0.0,
    };
    let ticks = (seconds * 1000.0) as u64;
    for k in 0..ticks {
        let raw = (rotor_counts.floor() as i64).rem_euclid(8192) as u16;
        enc.update(raw).unwrap();
        let dt = clock.update(Instant::from_micros(k * 1000));
        let speed_rpm = (omega * 60.0 / core::f64::consts::TAU) as f32;
        let speed_target = angle.update(target_deg, enc.angle_deg(), dt).output;
        let current = speed.update(speed_target, speed_rpm, dt).output;
        run.peak_current_a = run.peak_current_a.max(current.abs());

        // Plant: 1 ms in ten sub-steps.
        for _ in 0..10 {
            let torque = KT_NM_PER_A * f64::from(current) - VISCOUS_NM_PER_RAD_S * omega;
            omega += torque / INERTIA_KG_M2 * 1e-4;
            rotor_counts += omega * ratio / core::f64::consts::TAU * 8192.0 * 1e-4;
        }
        run.min_total_deg = run.min_total_deg.min(enc.total_angle_deg());
        run.max_total_deg = run.max_total_deg.max(enc.total_angle_deg());
    }
    run.final_angle_deg = enc.angle_deg();
    run
}

#[test]
fn angle_step_across_zero_goes_the_short_way_and_settles() {
    // From 0° to 350°: the short way is 10° backwards.
    let r = run_position_step(350.0, 1.0);
    assert!(
        r.min_total_deg > -12.0,
        "overshot backwards to {}",
        r.min_total_deg
    );
    assert!(
        r.max_total_deg < 1.0,
        "went the long way: {}",
        r.max_total_deg
    );
    assert!(
        (r.final_angle_deg - 350.0).abs() < 0.5,
        "final {}",
        r.final_angle_deg
    );
    assert!(r.peak_current_a <= CURRENT_LIMIT_A);
}

#[test]
fn angle_step_forward_settles_within_half_degree() {
    let r = run_position_step(90.0, 1.0);
    assert!(
        (r.final_angle_deg - 90.0).abs() < 0.5,
        "final {}",
        r.final_angle_deg
    );
    assert!(r.max_total_deg < 95.0, "overshoot to {}", r.max_total_deg);
}
