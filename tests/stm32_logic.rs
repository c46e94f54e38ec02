//! The board-independent logic of rc10-stm32, on the host: the register-to-status mapping
//! (included from the adapter's source, which has no embassy-stm32 dependency) and the
//! acceptance-filter plans the adapter programs for the example robots.

// Test code: a failed setup or assertion should stop the test.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

#[path = "../crates/rc10-stm32/src/status.rs"]
mod status;

use rc10_core::can::ErrorState;
use rc10_core::can::acceptance::{Fifo, FilterPlan};
use rc10_core::motor::dji::DjiMotor;
use rc10_core::motor::dm::{DmConfig, DmMotor};
use rc10_core::motor::vesc::{VescConfig, VescMotor, VescStatusSet};
use rc10_core::node::CanNode;

#[test]
fn psr_flags_map_to_the_fault_confinement_state() {
    assert_eq!(
        status::bus_status(false, false, 0, 0, 0, 0).state,
        ErrorState::Active
    );
    assert_eq!(
        status::bus_status(false, true, 0, 0, 130, 0).state,
        ErrorState::Passive
    );
    // Bus-off wins over error-passive (both flags are set while off the bus).
    let off = status::bus_status(true, true, 3, 0, 255, 12);
    assert_eq!(off.state, ErrorState::BusOff);
    assert_eq!((off.tx_error_count, off.rx_error_count), (255, 12));
}

#[test]
fn last_error_codes_1_to_6_are_protocol_errors_0_and_7_are_not() {
    for lec in 0..=7u8 {
        let s = status::bus_status(false, false, lec, 0, 0, 0);
        assert_eq!(s.protocol_error, (1..=6).contains(&lec), "LEC {lec}");
        assert_eq!(s.errors_logged, 0, "LEC {lec}");
    }
}

#[test]
fn the_error_log_is_the_count_of_errors() {
    // 17 errors logged since the last read, each retried successfully (LEC cleared by the
    // good frame after them, TEC back near 0).
    let noisy = status::bus_status(false, false, 0, 17, 8, 0);
    assert_eq!((noisy.protocol_error, noisy.errors_logged), (true, 17));
    let full = status::bus_status(false, false, 7, 255, 0, 0);
    assert_eq!(full.errors_logged, 255);
}

#[test]
fn pending_tx_buffers_are_counted() {
    assert_eq!(status::pending_frames([false; 3]), 0);
    assert_eq!(status::pending_frames([true, false, true]), 2);
    assert_eq!(status::pending_frames([true; 3]), 3);
}

#[test]
fn message_lost_flags_are_cleared_only_where_set() {
    assert_eq!(status::message_lost(false, false), None);
    assert_eq!(status::message_lost(true, false), Some([true, false]));
    assert_eq!(status::message_lost(false, true), Some([false, true]));
}

type G4Plan = FilterPlan<28, 8>;

#[test]
fn three_buses_example_plans_fit_and_accept_exactly_the_feedback() {
    // FDCAN1: four M3508; FDCAN2: two GM6020; FDCAN3: two M2006 (examples/stm32g474).
    let wheels: Vec<DjiMotor> = (1..=4).map(|i| DjiMotor::m3508(i).unwrap()).collect();
    let plan = G4Plan::new(wheels.iter().map(|m| m.bus_usage())).unwrap();
    for id in 0x201..=0x204 {
        assert!(plan.fifo_of(id, false).is_some());
    }
    // The command IDs never reach the receiver: nobody else sends them.
    for id in [0x200, 0x1FF, 0x205] {
        assert_eq!(plan.fifo_of(id, false), None);
    }
    let gimbal = [
        DjiMotor::gm6020_voltage(1).unwrap(),
        DjiMotor::gm6020_voltage(2).unwrap(),
    ];
    let plan = G4Plan::new(gimbal.iter().map(|m| m.bus_usage())).unwrap();
    assert_eq!(plan.fifo_of(0x205, false), Some(Fifo::Fifo0));
    assert_eq!(plan.fifo_of(0x206, false), Some(Fifo::Fifo1));
}

#[test]
fn a_mixed_bus_fits_the_g4_filter_elements() {
    // Two M3508, a Damiao joint, two VESCs with STATUS_1 and STATUS_4.
    let a = DjiMotor::m3508(1).unwrap();
    let b = DjiMotor::m3508(2).unwrap();
    let dm = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
    let mut cfg = VescConfig::new(7);
    cfg.status_packets = VescStatusSet::STATUS_1.with(VescStatusSet::STATUS_4);
    let v1 = VescMotor::new(0x21, cfg).unwrap();
    let v2 = VescMotor::new(0x22, cfg).unwrap();
    let nodes: [&dyn CanNode; 5] = [&a, &b, &dm, &v1, &v2];
    let plan = G4Plan::new(nodes.iter().map(|n| n.bus_usage())).unwrap();
    assert!(plan.standard().len() <= 28 && plan.extended().len() <= 8);
    for (id, ext) in [
        (0x201, false),
        (0x202, false),
        (0x11, false),
        (0x0921, true),
        (0x1022, true),
    ] {
        assert!(plan.fifo_of(id, ext).is_some(), "0x{id:X}");
    }
    assert_eq!(plan.fifo_of(0x0E21, true), None); // STATUS_2 was not configured
}

#[test]
fn start_accepts_only_an_instance_in_configuration() {
    // What CanConfigurator::new leaves: INIT and CCE set.
    assert!(status::in_configuration(true, true));
    // Reset state (INIT set, CCE clear): another FDCAN nobody configured.
    assert!(!status::in_configuration(true, false));
    // Running (INIT clear): a FDCAN already started.
    assert!(!status::in_configuration(false, false));
    assert!(!status::in_configuration(false, true));
}

#[test]
fn the_watchdog_is_fed_only_while_every_scheduler_ticks() {
    let mut progress = status::TickProgress::new();
    // The first look only records.
    assert!(progress.all_advanced([10, 20]));
    assert!(progress.all_advanced([60, 70]));
    // Bus 2's scheduler stopped: no feeding, however far bus 1 went.
    assert!(!progress.all_advanced([110, 70]));
    assert!(!progress.all_advanced([160, 70]));
    // It runs again.
    assert!(progress.all_advanced([210, 71]));
    // A counter that wrapped round moved.
    assert!(progress.all_advanced([u32::MAX, 72]));
    assert!(progress.all_advanced([3, 73]));
    // No buses: nothing to wait for.
    assert!(status::TickProgress::new().all_advanced([]));
}
