//! Registration checks, tick order, frame merging, TX accounting and dispatch routing.

use super::*;
use crate::can::loopback::TxQueue;
use crate::can::{BusStatus, IdFilter};
use crate::motor::Motor;
use crate::motor::dji::DjiMotor;
use crate::node::{BusUsage, CommandSlot, FrameError};
use std::sync::Mutex as StdMutex;

const T0: Instant = Instant::from_millis(10);

fn fb(id: u16) -> CanFrame {
    CanFrame::standard(id, &[0, 0, 0, 0, 0, 0, 30, 0]).unwrap()
}

/// A node that records calls and pushes `frames` whole frames per tick.
struct Probe {
    name: &'static str,
    usage: BusUsage,
    log: &'static StdMutex<Vec<String>>,
}

impl Probe {
    fn new(name: &'static str, log: &'static StdMutex<Vec<String>>) -> Self {
        Self {
            name,
            usage: BusUsage::NONE,
            log,
        }
    }
}

impl CanNode for Probe {
    fn bus_usage(&self) -> BusUsage {
        self.usage
    }
    fn update_feedback(&self, _frame: &CanFrame, _now: Instant) -> Result<(), FrameError> {
        self.log.lock().unwrap().push(format!("rx {}", self.name));
        Ok(())
    }
    fn update(&self, _now: Instant, _dt_s: f32) {
        self.log
            .lock()
            .unwrap()
            .push(format!("update {}", self.name));
    }
    fn pack_command(&self, out: &mut TxBatch) {
        self.log.lock().unwrap().push(format!("pack {}", self.name));
        for i in 0..self.usage.command_frames_per_tick {
            let _ = out.push(CanFrame::standard(0x300 + u16::from(i), &[i]).unwrap());
        }
    }
}

fn leak_log() -> &'static StdMutex<Vec<String>> {
    Box::leak(Box::new(StdMutex::new(Vec::new())))
}

const NO_BUDGET: BusConfig = BusConfig {
    max_load_percent: f32::INFINITY,
    ..BusConfig::DEFAULT
};

#[test]
fn m3508_id5_and_gm6020_id1_feedback_conflict_is_reported() {
    let wheel = DjiMotor::m3508(5).unwrap();
    let yaw = DjiMotor::gm6020_voltage(1).unwrap();
    let mut b = BusBuilder::<8>::new();
    b.register(&wheel).unwrap();
    assert_eq!(
        b.register(&yaw),
        Err(RegisterError::FeedbackConflict { existing: 0 })
    );
    assert_eq!(b.build().nodes().len(), 1);
}

#[test]
fn same_slot_is_a_conflict() {
    let log = leak_log();
    let mut a = Probe::new("a", log);
    a.usage.command_slot = CommandSlot::new(0x200, 1);
    let mut c = Probe::new("c", log);
    c.usage.command_slot = CommandSlot::new(0x200, 1);
    let mut b = BusBuilder::<4>::new();
    b.register(&a).unwrap();
    assert_eq!(
        b.register(&c),
        Err(RegisterError::SlotConflict { existing: 0 })
    );
}

#[test]
fn full_registry_is_reported() {
    let m1 = DjiMotor::m3508(1).unwrap();
    let m2 = DjiMotor::m3508(2).unwrap();
    let m3 = DjiMotor::m3508(3).unwrap();
    let mut b = BusBuilder::<2>::new();
    b.register(&m1).unwrap();
    b.register(&m2).unwrap();
    assert_eq!(b.register(&m3), Err(RegisterError::Full));
}

#[test]
fn frame_budget_admits_six_dji_motors_and_rejects_seven() {
    let motors: Vec<DjiMotor> = (1..=8).map(|id| DjiMotor::m3508(id).unwrap()).collect();
    let mut b = BusBuilder::<8>::new();
    for m in &motors[..4] {
        b.register(m).unwrap();
    }
    // 4 feedback + 1 command frame per ms, 111 bits each: 55.5 % nominal, 67.5 % worst case.
    let four = b.budget();
    assert!((four.nominal_load_percent - 55.5).abs() < 0.01);
    assert_eq!(four.level(), BudgetLevel::Comfortable);
    b.register(&motors[4]).unwrap();
    b.register(&motors[5]).unwrap();
    // 6 + 2 frames: 88.8 % nominal, 108 % worst case: admitted but marginal.
    let six = b.budget();
    assert!((six.nominal_load_percent - 88.8).abs() < 0.01);
    assert_eq!(six.level(), BudgetLevel::Marginal);
    match b.register(&motors[6]) {
        Err(RegisterError::FrameBudget { load_percent }) => {
            assert!((load_percent - 99.9).abs() < 0.01)
        }
        other => panic!("expected a budget error, got {other:?}"),
    }
}

#[test]
fn tick_updates_all_then_packs_all_in_registration_order() {
    let log = leak_log();
    let a = Probe::new("a", log);
    let b = Probe::new("b", log);
    let mut builder = BusBuilder::<2>::new();
    builder.register(&a).unwrap();
    builder.register(&b).unwrap();
    let bus = builder.build();
    bus.tick(T0, 0.001, &mut TxBatch::new());
    assert_eq!(
        *log.lock().unwrap(),
        ["update a", "update b", "pack a", "pack b"]
    );
}

#[test]
fn four_m3508_merge_into_one_0x200_frame_and_idle_slots_are_zero() {
    let m: Vec<DjiMotor> = (1..=4).map(|id| DjiMotor::m3508(id).unwrap()).collect();
    let id5 = DjiMotor::m3508(5).unwrap(); // registered, never online
    let mut builder = BusBuilder::<8>::new();
    for x in &m {
        builder.register(x).unwrap();
    }
    builder.register(&id5).unwrap();
    let bus = builder.build();
    for (i, x) in m.iter().enumerate() {
        bus.dispatch(&fb(0x201 + i as u16), T0);
        x.set_target_current(i as f32 + 1.0).unwrap(); // 1, 2, 3, 4 A
    }
    id5.set_target_current(10.0).unwrap();
    let mut batch = TxBatch::new();
    bus.tick(T0, 0.001, &mut batch);
    // 1 A = 819.2 → 819 = 0x0333; 2 A = 1638.4 → 0x0666; 3 A = 2457.6 → 2458 = 0x099A;
    // 4 A = 3276.8 → 3277 = 0x0CCD.
    let frames: Vec<(u32, Vec<u8>)> = batch
        .frames()
        .iter()
        .map(|f| (f.raw_id(), f.data().to_vec()))
        .collect();
    assert_eq!(
        frames,
        vec![
            (0x200, vec![0x03, 0x33, 0x06, 0x66, 0x09, 0x9A, 0x0C, 0xCD]),
            (0x1FF, vec![0; 8]), // id 5 offline: its frame still goes out, with zero
        ]
    );
}

#[test]
fn transmit_counts_frames_that_do_not_fit_three_tx_buffers() {
    let log = leak_log();
    let mut p = Probe::new("p", log);
    p.usage.command_frames_per_tick = 5;
    let mut builder = BusBuilder::<1>::with_config(NO_BUDGET);
    builder.register(&p).unwrap();
    let bus = builder.build();
    let mut tx = TxQueue::<3>::new();
    let mut batch = TxBatch::new();
    bus.tick(T0, 0.001, &mut batch);
    let report = bus.transmit(&batch, &mut tx);
    assert_eq!(
        report,
        TransmitReport {
            sent: 3,
            full: 2,
            bus_off: 0
        }
    );
    // The first three in packing order went out.
    let ids: Vec<u32> = core::iter::from_fn(|| tx.pop())
        .map(|f| f.raw_id())
        .collect();
    assert_eq!(ids, [0x300, 0x301, 0x302]);
    let c = bus.stats().snapshot();
    assert_eq!((c.tx_frames, c.tx_full, c.tx_dropped()), (3, 2, 2));
}

#[test]
fn bus_off_is_counted_once_per_entry_and_frames_not_queued() {
    let m = DjiMotor::m3508(1).unwrap();
    let mut builder = BusBuilder::<1>::new();
    builder.register(&m).unwrap();
    let bus = builder.build();
    let mut tx = TxQueue::<3>::new();
    tx.set_status(BusStatus {
        state: ErrorState::BusOff,
        tx_error_count: 255,
        rx_error_count: 0,
    });
    let mut batch = TxBatch::new();
    for _ in 0..3 {
        bus.tick(T0, 0.001, &mut batch);
        bus.transmit(&batch, &mut tx);
    }
    let c = bus.stats().snapshot();
    assert_eq!((c.bus_off_events, c.tx_bus_off, c.tx_frames), (1, 3, 0));
    assert!(bus.stats().is_bus_off());
    tx.set_status(BusStatus::default());
    bus.transmit(&batch, &mut tx);
    assert!(!bus.stats().is_bus_off());
    assert_eq!(bus.stats().snapshot().tx_frames, 1);
}

#[test]
fn dispatch_routes_each_frame_to_its_motor_among_eight() {
    let m3508: Vec<DjiMotor> = (1..=5).map(|id| DjiMotor::m3508(id).unwrap()).collect();
    let gm: Vec<DjiMotor> = (5..=7)
        .map(|id| DjiMotor::gm6020_voltage(id).unwrap())
        .collect();
    let mut builder = BusBuilder::<8>::with_config(NO_BUDGET);
    for m in m3508.iter().chain(gm.iter()) {
        builder.register(m).unwrap();
    }
    let bus = builder.build();
    // Feedback IDs 0x201–0x205 (M3508 1–5) and 0x209–0x20B (GM6020 5–7).
    let ids = [0x201u16, 0x202, 0x203, 0x204, 0x205, 0x209, 0x20A, 0x20B];
    for (index, id) in ids.iter().enumerate() {
        assert_eq!(bus.dispatch(&fb(*id), T0), Dispatch::Handled(index));
    }
    for m in m3508.iter().chain(gm.iter()) {
        assert_eq!(m.state().last_feedback, Some(T0));
    }
    // Nobody answers on 0x206–0x208 here.
    assert_eq!(bus.dispatch(&fb(0x206), T0), Dispatch::Unmatched);
    let bad = CanFrame::standard(0x202, &[1, 2]).unwrap();
    assert_eq!(
        bus.dispatch(&bad, T0),
        Dispatch::Rejected(1, FrameError::WrongLength { dlc: 2 })
    );
    let c = bus.stats().snapshot();
    assert_eq!((c.rx_frames, c.rx_unmatched, c.rx_rejected), (10, 1, 1));
}

#[test]
fn extended_frame_with_a_dji_id_is_not_claimed() {
    let m = DjiMotor::m3508(1).unwrap();
    let mut builder = BusBuilder::<1>::new();
    builder.register(&m).unwrap();
    let bus = builder.build();
    let ext = CanFrame::extended(0x201, &[0; 8]).unwrap();
    assert_eq!(bus.dispatch(&ext, T0), Dispatch::Unmatched);
}

#[test]
fn rates_latch_frames_per_second_and_load() {
    let m = DjiMotor::m3508(1).unwrap();
    let mut builder = BusBuilder::<1>::new();
    builder.register(&m).unwrap();
    let bus = builder.build();
    let mut tx = TxQueue::<3>::new();
    let mut batch = TxBatch::new();
    for k in 0..=1000u64 {
        let now = Instant::from_millis(k);
        bus.dispatch(&fb(0x201), now);
        bus.tick(now, 0.001, &mut batch);
        bus.transmit(&batch, &mut tx);
        tx.pop();
    }
    let r = bus.rates();
    // Window [0, 1000 ms]: 1000 feedback and 1000 command frames counted after tick 0.
    assert_eq!(r.rx_frames_per_s, 1000.0);
    assert_eq!(r.tx_frames_per_s, 1000.0);
    // 2000 frames × 111 unstuffed bits in 1 s at 1 Mbit/s = 22.2 %.
    assert!((r.load_percent - 22.2).abs() < 0.01, "{}", r.load_percent);
    assert_eq!(r.tx_dropped_per_s, 0.0);
}

#[test]
fn masked_listener_conflicts_with_exact_one() {
    let log = leak_log();
    let mut a = Probe::new("a", log);
    a.usage.listen = Some(IdFilter::extended_masked(0x07, 0xFF));
    let mut c = Probe::new("c", log);
    c.usage.listen = Some(IdFilter::extended(0x0907));
    let mut b = BusBuilder::<2>::new();
    b.register(&a).unwrap();
    assert_eq!(
        b.register(&c),
        Err(RegisterError::FeedbackConflict { existing: 0 })
    );
}
