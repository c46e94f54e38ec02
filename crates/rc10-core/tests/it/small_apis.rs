//! Small public APIs whose values a robot's code reads (counters, conversions, telemetry
//! channels, receiver defaults), pinned where mutation testing found nothing did.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use rc10_core::can::CanFrame;
use rc10_core::motor::Motor;
use rc10_core::motor::dji::DjiMotor;
use rc10_core::node::CanNode;
use rc10_core::pid::{PidConfig, PidConfigError};
use rc10_core::remote::{ReceiverFrame, Shared};
use rc10_core::telemetry::Channels;
use rc10_core::time::{DeltaTime, Duration, Instant, micros_to_s};

#[test]
fn micros_to_s_keeps_precision_over_hours() {
    // SPEC: dt never loses precision over hours of uptime.
    assert_eq!(micros_to_s(1_000), 0.001);
    assert_eq!(micros_to_s(1_000_000), 1.0);
    assert_eq!(micros_to_s(16_000_000), 16.0);
    assert_eq!(micros_to_s(3_600_000_000), 3600.0); // an hour: beyond u32 µs
    assert_eq!(micros_to_s(5_000_000_000), 5000.0);
    assert_eq!(micros_to_s(86_400_000_500), 86_400.0); // a day, half a ms lost to f32
}

#[test]
fn delta_time_reports_its_nominal_period() {
    let dt = DeltaTime::new(Duration::from_millis(1), Duration::from_millis(10));
    assert_eq!(dt.nominal_s(), 0.001);
    let dt = DeltaTime::new(Duration::from_micros(2500), Duration::from_millis(10));
    assert_eq!(dt.nominal_s(), 0.0025);
}

#[test]
fn pid_deadband_must_be_finite_and_not_negative() {
    let base = PidConfig::new(1.0, 0.0, 0.0);
    for bad in [-0.5, f32::NAN, f32::INFINITY] {
        assert_eq!(
            base.with_deadband(bad).validate(),
            Err(PidConfigError::InvalidDeadband),
            "{bad}"
        );
    }
    assert_eq!(base.with_deadband(0.0).validate(), Ok(()));
    assert_eq!(base.with_deadband(5.0).validate(), Ok(()));
}

#[test]
fn every_power_cut_counts_one_offline_event() {
    // Two silences longer than the 100 ms timeout: two offline events.
    let m = DjiMotor::m3508(1).unwrap();
    let fb = CanFrame::standard(0x201, &[0, 0, 0, 0, 0, 0, 30, 0]).unwrap();
    let t = Instant::from_millis;
    m.update_feedback(&fb, t(1)).unwrap();
    m.update(t(2), 0.001);
    m.update(t(200), 0.001); // 199 ms of silence: offline
    assert!(!m.is_online());
    m.update_feedback(&fb, t(201)).unwrap();
    m.update(t(202), 0.001);
    assert!(m.is_online());
    m.update(t(400), 0.001); // offline again
    assert!(!m.is_online());
    assert_eq!(m.state().offline_events, 2);
}

#[test]
fn telemetry_channels_read_back_what_was_set() {
    static CH: Channels<3> = Channels::new(["rpm", "amps", "deg"]);
    assert_eq!(CH.get(1), Some(0.0));
    assert!(CH.set(1, 2.5));
    assert!(CH.set_named("deg", -45.0));
    assert_eq!(CH.get(1), Some(2.5));
    assert_eq!(CH.get(2), Some(-45.0));
    assert_eq!(CH.get(3), None);
    assert!(!CH.set(3, 1.0));
}

#[derive(Clone, Copy)]
struct Bare;

impl ReceiverFrame for Bare {
    type Error = ();
    const NEUTRAL: Self = Bare;
    fn parse(_bytes: &[u8]) -> Result<Self, ()> {
        Ok(Bare)
    }
}

#[test]
fn receiver_frames_report_no_failsafe_or_loss_unless_they_say_so() {
    assert!(!Bare.failsafe());
    assert!(!Bare.frame_lost());
}

#[test]
fn shared_receiver_counts_input_errors() {
    let s = Shared::new(0u8);
    assert_eq!(s.input_errors(), 0);
    s.record_input_error();
    s.record_input_error();
    assert_eq!(s.input_errors(), 2);
    let dbg = format!("{s:?}");
    assert!(dbg.contains("input_errors: 2"), "{dbg}");
}
