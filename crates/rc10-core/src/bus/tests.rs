//! Registration checks, tick order, frame merging, TX accounting and dispatch routing.

use super::*;
use crate::can::loopback::TxQueue;
use crate::can::{BusStatus, IdFilter};
use crate::motor::Motor;
use crate::motor::dji::DjiMotor;
use crate::motor::dm::{DmConfig, DmMotor};
use crate::node::{BusUsage, CommandSlot, FrameError, IdSet};
use core::cell::Cell;
use core::future::Future;
use core::pin::pin;
use core::task::{Context, Waker};
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
        for i in 0..self.usage.frames_per_tick {
            let _ = out.push(CanFrame::standard(0x300 + u16::from(i), &[i]).unwrap());
        }
    }
}

fn leak_log() -> &'static StdMutex<Vec<String>> {
    Box::leak(Box::new(StdMutex::new(Vec::new())))
}

const NO_BUDGET: BusConfig = BusConfig {
    max_load_percent: f32::INFINITY,
    tx_depth: 16,
    ..BusConfig::DEFAULT
};

/// The frames a Probe with `frames` whole frames per tick sends on: 0x300, 0x301, …
fn probe_sends(frames: u8) -> BusUsage {
    BusUsage::NONE.sending(
        IdFilter {
            extended: false,
            id: 0x300,
            mask: 0x7F0,
        },
        frames,
    )
}

fn std_id(id: u32) -> RawId {
    RawId {
        id,
        extended: false,
    }
}

#[test]
fn m3508_id5_and_gm6020_id1_feedback_conflict_is_reported() {
    let wheel = DjiMotor::m3508(5).unwrap();
    let yaw = DjiMotor::gm6020_voltage(1).unwrap();
    let mut b = BusBuilder::<8>::new();
    b.register(&wheel).unwrap();
    assert_eq!(
        b.register(&yaw),
        Err(RegisterError::FeedbackConflict {
            existing: 0,
            id: std_id(0x205)
        })
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
        Err(RegisterError::SlotConflict {
            existing: 0,
            slot: CommandSlot::new(0x200, 1).unwrap()
        })
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
fn damiao_replies_count_one_a_tick_whatever_the_tick_period() {
    // A Damiao motor answers each command frame: a tick carries one command and one reply a
    // motor, standard 8-byte frames of 111 bits unstuffed, whatever the period. Two motors
    // every 0.5 ms, four every 1 ms and eight every 2 ms are all 444 bits a 500 µs: 88.8 %.
    // (Counted as 1000 replies a second, the 2 ms bus would have been refused at 133 %, and
    // the 0.5 ms one under-counted at 66.6 %.)
    let dms: Vec<DmMotor> = (1..=8u16)
        .map(|i| DmMotor::new(i, DmConfig::new(0x10 + i)).unwrap())
        .collect();
    for (period_us, motors) in [(500u64, 2usize), (1_000, 4), (2_000, 8)] {
        let config = BusConfig {
            tick_period: Duration::from_micros(period_us),
            ..BusConfig::DEFAULT.with_tx_depth(8)
        };
        let mut b = BusBuilder::<8>::with_config(config);
        for m in &dms[..motors] {
            b.register(m).unwrap();
        }
        let budget = b.budget();
        assert_eq!(
            budget.frames_per_tick,
            2.0 * motors as f32,
            "{period_us} µs"
        );
        assert!(
            (budget.nominal_load_percent - 88.8).abs() < 0.01,
            "{period_us} µs: {}",
            budget.nominal_load_percent
        );
        // One more motor is 133 % of the 0.5 ms bus and 111 % of the 1 ms one: refused.
        if let Some(extra) = dms.get(motors).filter(|_| period_us < 2_000) {
            assert!(
                matches!(b.register(extra), Err(RegisterError::FrameBudget { .. })),
                "{period_us} µs"
            );
        }
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
    p.usage = probe_sends(5);
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
            queued: 3,
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
        protocol_error: true,
        errors_logged: 0,
    });
    let mut batch = TxBatch::new();
    for _ in 0..3 {
        bus.tick(T0, 0.001, &mut batch);
        bus.transmit(&batch, &mut tx);
    }
    let c = bus.stats().snapshot();
    assert_eq!((c.bus_off_events, c.tx_bus_off, c.tx_frames), (1, 3, 0));
    // The transport cannot count its errors: one for each status read that saw one.
    assert_eq!(c.bus_errors, 3);
    assert!(bus.stats().is_bus_off());
    tx.set_status(BusStatus::default());
    bus.transmit(&batch, &mut tx);
    assert!(!bus.stats().is_bus_off());
    assert_eq!(bus.stats().snapshot().tx_frames, 1);
}

#[test]
fn every_error_the_controller_logged_is_counted() {
    let m = DjiMotor::m3508(1).unwrap();
    let mut builder = BusBuilder::<1>::new();
    builder.register(&m).unwrap();
    let bus = builder.build();
    let mut tx = TxQueue::<3>::new();
    // A loose connector: 17 errors between two reads, each retried successfully.
    tx.set_status(BusStatus {
        protocol_error: true,
        errors_logged: 17,
        ..BusStatus::default()
    });
    let mut batch = TxBatch::new();
    for _ in 0..3 {
        bus.tick(T0, 0.001, &mut batch);
        bus.transmit(&batch, &mut tx);
        tx.pop();
    }
    assert_eq!(bus.stats().snapshot().bus_errors, 51);
    assert_eq!(
        bus.stats().snapshot().tx_frames,
        3,
        "error-active: frames still go out"
    );
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

/// A node whose `matches_frame` claims every frame, declaring `listen` only.
struct Greedy {
    listen: IdSet,
    frames: &'static StdMutex<Vec<u32>>,
}

impl CanNode for Greedy {
    fn bus_usage(&self) -> BusUsage {
        BusUsage {
            listen: self.listen,
            ..BusUsage::NONE
        }
    }
    fn matches_frame(&self, _frame: &CanFrame) -> bool {
        true
    }
    fn update_feedback(&self, frame: &CanFrame, _now: Instant) -> Result<(), FrameError> {
        self.frames.lock().unwrap().push(frame.raw_id());
        Ok(())
    }
    fn update(&self, _now: Instant, _dt_s: f32) {}
    fn pack_command(&self, _out: &mut TxBatch) {}
}

#[test]
fn matches_frame_cannot_claim_an_id_outside_the_declared_listen_set() {
    // Both routes: a DJI-range ID (direct table) and IDs outside it (declared-set scan).
    let frames: &'static StdMutex<Vec<u32>> = Box::leak(Box::new(StdMutex::new(Vec::new())));
    let greedy = Greedy {
        listen: IdSet::one(IdFilter::standard(0x203))
            .with(IdFilter::standard(0x321))
            .with(IdFilter::extended_masked(0x07, 0xFF)),
        frames,
    };
    let motor = DjiMotor::m3508(1).unwrap();
    let mut builder = BusBuilder::<4>::with_config(NO_BUDGET);
    builder.register(&greedy).unwrap();
    builder.register(&motor).unwrap();
    let bus = builder.build();
    for undeclared in [fb(0x202), fb(0x20F), fb(0x322), fb(0x7FF)] {
        assert_eq!(bus.dispatch(&undeclared, T0), Dispatch::Unmatched);
    }
    let ext_undeclared = CanFrame::extended(0x0908, &[0; 8]).unwrap();
    assert_eq!(bus.dispatch(&ext_undeclared, T0), Dispatch::Unmatched);
    // Another node's declared ID goes to that node, not to the greedy one registered first.
    assert_eq!(bus.dispatch(&fb(0x201), T0), Dispatch::Handled(1));
    // Its own declared IDs, on every route, it does get.
    let ext_declared = CanFrame::extended(0x0907, &[0; 8]).unwrap();
    for declared in [fb(0x203), fb(0x321), ext_declared] {
        assert_eq!(bus.dispatch(&declared, T0), Dispatch::Handled(0));
    }
    assert_eq!(*frames.lock().unwrap(), [0x203, 0x321, 0x0907]);
    assert_eq!(bus.stats().snapshot().rx_unmatched, 5);
}

/// A node that declares a DJI feedback ID but refuses remote frames on it.
struct NoRemote;

impl CanNode for NoRemote {
    fn bus_usage(&self) -> BusUsage {
        BusUsage::NONE.listening(IdFilter::standard(0x205), 1000)
    }
    fn matches_frame(&self, frame: &CanFrame) -> bool {
        !frame.is_remote() && self.bus_usage().listen.matches(frame.id())
    }
    fn update_feedback(&self, _frame: &CanFrame, _now: Instant) -> Result<(), FrameError> {
        Ok(())
    }
    fn update(&self, _now: Instant, _dt_s: f32) {}
    fn pack_command(&self, _out: &mut TxBatch) {}
}

#[test]
fn matches_frame_narrows_the_declared_listen_set() {
    static NODE: NoRemote = NoRemote;
    let mut builder = BusBuilder::<1>::new();
    builder.register(&NODE).unwrap();
    let bus = builder.build();
    let remote = CanFrame::remote(crate::can::StandardId::new(0x205).unwrap(), 8).unwrap();
    assert_eq!(bus.dispatch(&remote, T0), Dispatch::Unmatched);
    assert_eq!(bus.dispatch(&fb(0x205), T0), Dispatch::Handled(0));
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
    a.usage.listen = IdSet::one(IdFilter::extended_masked(0x07, 0xFF));
    let mut c = Probe::new("c", log);
    c.usage.listen = IdSet::one(IdFilter::extended(0x0907));
    let mut b = BusBuilder::<2>::new();
    b.register(&a).unwrap();
    assert_eq!(
        b.register(&c),
        Err(RegisterError::FeedbackConflict {
            existing: 0,
            id: RawId {
                id: 0x0907,
                extended: true
            }
        })
    );
}

#[test]
fn a_node_sending_a_whole_frame_on_its_own_slot_frame_id_is_rejected() {
    // Slot 0 of 0x200 and a whole 0x200 frame: two different 0x200 frames each tick, and
    // C620s 2–4 (unregistered, so meant to get 0 A) would read the whole frame as currents.
    let mut probe = Probe::new("p", leak_log());
    probe.usage = BusUsage::NONE
        .with_slot(CommandSlot::new(0x200, 0).unwrap())
        .sending(IdFilter::standard(0x200), 1);
    let mut fine = Probe::new("q", leak_log());
    fine.usage = BusUsage::NONE
        .with_slot(CommandSlot::new(0x200, 0).unwrap())
        .sending(IdFilter::standard(0x300), 1);
    let wheel = DjiMotor::m3508(5).unwrap(); // 0x1FF: unrelated
    let mut b = BusBuilder::<4>::new();
    b.register(&wheel).unwrap();
    assert_eq!(
        b.register(&probe),
        Err(RegisterError::SendConflict {
            existing: 1,
            id: std_id(0x200)
        })
    );
    // On another ID it is fine.
    assert_eq!(b.register(&fine), Ok(()));
}

#[test]
fn two_damiao_motors_on_one_can_id_are_rejected() {
    let a = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
    let b = DmMotor::new(0x01, DmConfig::new(0x12)).unwrap();
    let mut builder = BusBuilder::<4>::new();
    builder.register(&a).unwrap();
    assert_eq!(
        builder.register(&b),
        Err(RegisterError::SendConflict {
            existing: 0,
            id: std_id(0x01)
        })
    );
}

#[test]
fn damiao_on_a_dji_command_id_is_rejected_in_either_order() {
    // A DM motor on CAN ID 0x200 next to an M3508 id 1: the MIT frame would be merged with
    // the C620 slots (C620s 2–4 would read MIT fields as currents) or sent as a second 0x200.
    let dm = DmMotor::new(0x200, DmConfig::new(0x11)).unwrap();
    let wheel = DjiMotor::m3508(1).unwrap();
    let mut b = BusBuilder::<4>::new();
    b.register(&wheel).unwrap();
    assert_eq!(
        b.register(&dm),
        Err(RegisterError::SendConflict {
            existing: 0,
            id: std_id(0x200)
        })
    );
    let mut b = BusBuilder::<4>::new();
    b.register(&dm).unwrap();
    assert_eq!(
        b.register(&wheel),
        Err(RegisterError::SendConflict {
            existing: 0,
            id: std_id(0x200)
        })
    );
}

#[test]
fn damiao_commanding_on_a_c620_feedback_id_is_rejected_in_either_order() {
    let dm = DmMotor::new(0x201, DmConfig::new(0x11)).unwrap();
    let wheel = DjiMotor::m3508(1).unwrap(); // answers on 0x201
    let mut b = BusBuilder::<4>::new();
    b.register(&wheel).unwrap();
    assert_eq!(
        b.register(&dm),
        Err(RegisterError::CommandOnFeedbackId {
            sender: 1,
            listener: 0,
            id: std_id(0x201)
        })
    );
    let mut b = BusBuilder::<4>::new();
    b.register(&dm).unwrap();
    assert_eq!(
        b.register(&wheel),
        Err(RegisterError::CommandOnFeedbackId {
            sender: 0,
            listener: 1,
            id: std_id(0x201)
        })
    );
    // A Damiao master ID on a DJI command ID is the same clash seen from the other side.
    let listens_on_0x1ff = DmMotor::new(0x05, DmConfig::new(0x1FF)).unwrap();
    let wheel_5 = DjiMotor::m3508(5).unwrap(); // commanded on 0x1FF
    let mut b = BusBuilder::<4>::new();
    b.register(&wheel_5).unwrap();
    assert_eq!(
        b.register(&listens_on_0x1ff),
        Err(RegisterError::CommandOnFeedbackId {
            sender: 0,
            listener: 1,
            id: std_id(0x1FF)
        })
    );
}

#[test]
fn a_node_may_not_send_where_it_listens() {
    let log = leak_log();
    let mut p = Probe::new("p", log);
    p.usage = probe_sends(1).listening(IdFilter::standard(0x300), 1000);
    let mut b = BusBuilder::<2>::new();
    assert_eq!(
        b.register(&p),
        Err(RegisterError::CommandOnFeedbackId {
            sender: 0,
            listener: 0,
            id: std_id(0x300)
        })
    );
}

#[test]
fn four_damiao_motors_do_not_fit_three_tx_buffers_but_fit_four() {
    let dms: Vec<DmMotor> = (1..=4u16)
        .map(|i| DmMotor::new(i, DmConfig::new(0x10 + i)).unwrap())
        .collect();
    let mut b = BusBuilder::<8>::new();
    for m in &dms[..3] {
        b.register(m).unwrap();
    }
    assert_eq!(
        b.register(&dms[3]),
        Err(RegisterError::TxDepth {
            frames_per_tick: 4,
            tx_depth: 3
        })
    );
    // A transport that queues four frames serves all four motors every tick.
    let mut b = BusBuilder::<8>::with_config(BusConfig::DEFAULT.with_tx_depth(4));
    for m in &dms {
        b.register(m).unwrap();
        m.set_target_rpm(30.0).unwrap();
    }
    let bus = b.build();
    let mut tx = TxQueue::<4>::new();
    let mut batch = TxBatch::new();
    for tick in 0..10u64 {
        let now = T0 + Duration::from_millis(tick);
        bus.tick(now, 0.001, &mut batch);
        let report = bus.transmit(&batch, &mut tx);
        assert_eq!((report.queued, report.full), (4, 0));
        let ids: Vec<u32> = core::iter::from_fn(|| tx.pop())
            .map(|f| f.raw_id())
            .collect();
        assert_eq!(ids, [1, 2, 3, 4]);
    }
}

#[test]
fn dji_slot_frames_count_against_the_tx_depth() {
    // 0x200 (M3508 1), 0x1FF (M3508 5), 0x2FE (GM6020 current 6), 0x2FF (GM6020 voltage 7):
    // four shared frames per tick. (A GM6020 id 1 would answer on 0x205, like M3508 5.)
    let a = DjiMotor::m3508(1).unwrap();
    let c = DjiMotor::m3508(5).unwrap();
    let d = DjiMotor::gm6020_current(1).unwrap();
    let d6 = DjiMotor::gm6020_current(6).unwrap(); // 0x20A, slot 0x2FE
    let e = DjiMotor::gm6020_voltage(7).unwrap(); // 0x20B, slot 0x2FF
    let mut b = BusBuilder::<8>::with_config(BusConfig {
        max_load_percent: f32::INFINITY,
        ..BusConfig::DEFAULT
    });
    b.register(&a).unwrap();
    b.register(&c).unwrap();
    assert!(matches!(
        b.register(&d),
        Err(RegisterError::FeedbackConflict { .. })
    ));
    b.register(&d6).unwrap();
    assert_eq!(
        b.register(&e),
        Err(RegisterError::TxDepth {
            frames_per_tick: 4,
            tx_depth: 3
        })
    );
}

/// A transport that cannot report its state (`status()` is the default, error-active) but
/// refuses frames with `BusOff` while `off` is set.
struct SilentBusOff<'a> {
    off: &'a Cell<bool>,
}

impl CanTransmit for SilentBusOff<'_> {
    fn try_send(&mut self, _frame: &CanFrame) -> Result<(), SendError> {
        if self.off.get() {
            Err(SendError::BusOff)
        } else {
            Ok(())
        }
    }
}

#[test]
fn bus_off_reported_only_through_try_send_counts_once_per_entry() {
    let m = DjiMotor::m3508(1).unwrap();
    let mut builder = BusBuilder::<1>::new();
    builder.register(&m).unwrap();
    let bus = builder.build();
    let off = Cell::new(true);
    let mut tx = SilentBusOff { off: &off };
    let mut batch = TxBatch::new();
    let mut run = |ticks: u32, tx: &mut SilentBusOff<'_>| {
        for _ in 0..ticks {
            bus.tick(T0, 0.001, &mut batch);
            bus.transmit(&batch, tx);
        }
    };
    run(20, &mut tx);
    assert_eq!(bus.stats().snapshot().bus_off_events, 1);
    assert_eq!(bus.stats().snapshot().tx_bus_off, 20);
    off.set(false);
    run(5, &mut tx);
    assert!(!bus.stats().is_bus_off());
    off.set(true);
    run(5, &mut tx);
    assert_eq!(bus.stats().snapshot().bus_off_events, 2);
    // A receive-side bus-off report does not count a second time.
    bus.record_receive_error(ReceiveError::BusOff);
    run(1, &mut tx);
    assert_eq!(bus.stats().snapshot().bus_off_events, 2);
}

#[test]
fn pacer_skips_ticks_missed_in_a_stall_and_bounds_dt() {
    let period = Duration::from_millis(1);
    let mut pacer = TickPacer::new(period);
    let first = pacer.on_tick(Instant::from_micros(1_000));
    assert!(first.resync);
    assert_eq!(first.dt_s, 0.001);
    // On time, then 300 µs late (jitter: no resync), then on time again.
    assert!(!pacer.on_tick(Instant::from_micros(2_000)).resync);
    let late = pacer.on_tick(Instant::from_micros(3_300));
    assert!(!late.resync);
    assert!((late.dt_s - 0.0013).abs() < 1e-7);
    let next = pacer.on_tick(Instant::from_micros(4_000));
    assert!((next.dt_s - 0.0007).abs() < 1e-7);
    // A 40 ms stall: the first tick after it re-synchronises and reports the skipped periods.
    let after = pacer.on_tick(Instant::from_micros(45_000));
    assert_eq!((after.resync, after.skipped), (true, 40));
    assert_eq!(after.dt_s, 0.01); // bounded
    let resumed = pacer.on_tick(Instant::from_micros(46_000));
    assert!(!resumed.resync);
    assert_eq!(resumed.dt_s, 0.001);
}

#[test]
fn pacer_near_the_end_of_time_saturates_instead_of_panicking() {
    // Were panics (debug) or a missed resync (release): `late · 2` overflowed for a stamp
    // 2^63 ticks ahead, and `now + period` for one within a period of u64::MAX.
    let mut pacer = TickPacer::new(Duration::from_millis(1));
    pacer.on_tick(Instant::from_ticks(1_000));
    let far = pacer.on_tick(Instant::from_ticks((1 << 63) + 2_000)); // 2^63 ticks late
    assert_eq!((far.resync, far.skipped), (true, u32::MAX));
    let end = pacer.on_tick(Instant::from_ticks(u64::MAX));
    assert!(end.resync);
    // Due at u64::MAX (saturated): a tick there again is on time, not late or a panic.
    let again = pacer.on_tick(Instant::from_ticks(u64::MAX));
    assert_eq!((again.resync, again.skipped), (false, 0));
    assert_eq!(again.dt_s, 0.001); // time stood still: the nominal period
}

/// An embassy-time `Ticker` over a fake clock: fires at `due`, then `due += period`; a tick
/// that is already overdue fires at once (so ticks missed in a stall come back to back, as
/// they do with the real `Ticker`). After `limit` ticks it never fires again.
struct FakeTicker<'a> {
    now_us: &'a Cell<u64>,
    due_us: u64,
    period_us: u64,
    ticks: u32,
    limit: u32,
    stall_at: u32,
    stall_us: u64,
}

impl TickSource for FakeTicker<'_> {
    async fn next_tick(&mut self) -> Instant {
        if self.ticks == self.limit {
            core::future::pending::<()>().await;
        }
        self.ticks += 1;
        let mut now = self.now_us.get() + 5; // the previous tick's own run time
        if self.ticks == self.stall_at {
            now += self.stall_us; // a higher-priority task held the CPU
        }
        now = now.max(self.due_us);
        self.due_us += self.period_us;
        self.now_us.set(now);
        Instant::from_micros(now)
    }

    fn resync(&mut self, now: Instant) {
        self.due_us = now.as_micros() + self.period_us;
    }
}

/// Records the time and dt of every update.
struct DtProbe {
    calls: StdMutex<Vec<(u64, f32)>>,
}

impl CanNode for DtProbe {
    fn bus_usage(&self) -> BusUsage {
        probe_sends(1)
    }
    fn update_feedback(&self, _frame: &CanFrame, _now: Instant) -> Result<(), FrameError> {
        Ok(())
    }
    fn update(&self, now: Instant, dt_s: f32) {
        self.calls.lock().unwrap().push((now.as_micros(), dt_s));
    }
    fn pack_command(&self, out: &mut TxBatch) {
        let _ = out.push(CanFrame::standard(0x300, &[]).unwrap());
    }
}

struct CountingTx<'a>(&'a Cell<u32>);

impl CanTransmit for CountingTx<'_> {
    fn try_send(&mut self, _frame: &CanFrame) -> Result<(), SendError> {
        self.0.set(self.0.get() + 1);
        Ok(())
    }
}

/// Runs `run_scheduler_on` for one `DtProbe` on a bus with `config`, ticked by a
/// `FakeTicker` every `period_us` until `limit` ticks, held up `stall_us` before tick
/// `stall_at` (0: never). Returns the probe's (time µs, dt s) calls, the frames sent and the
/// ticks counted as skipped.
fn run_fake_ticks(
    config: BusConfig,
    period_us: u64,
    limit: u32,
    (stall_at, stall_us): (u32, u64),
) -> (Vec<(u64, f32)>, u32, u32) {
    let probe = DtProbe {
        calls: StdMutex::new(Vec::new()),
    };
    let mut builder = BusBuilder::<1>::with_config(config);
    builder.register(&probe).unwrap();
    let bus = builder.build();
    let clock = Cell::new(0u64);
    let ticker = FakeTicker {
        now_us: &clock,
        due_us: period_us,
        period_us,
        ticks: 0,
        limit,
        stall_at,
        stall_us,
    };
    let sent = Cell::new(0u32);
    let mut fut = pin!(run_scheduler_on(&bus, CountingTx(&sent), ticker));
    let mut cx = Context::from_waker(Waker::noop());
    assert!(fut.as_mut().poll(&mut cx).is_pending()); // ran the ticks, then waits
    let calls = probe.calls.lock().unwrap().clone();
    (calls, sent.get(), bus.stats().snapshot().ticks_skipped)
}

#[test]
fn scheduler_after_a_stall_skips_missed_ticks_instead_of_bursting() {
    let (calls, sent, skipped) = run_fake_ticks(BusConfig::DEFAULT, 1_000, 200, (100, 50_000));
    assert_eq!(calls.len(), 200);
    assert_eq!(sent, 200); // one frame per tick, no extra
    for (t, dt) in &calls {
        assert!((0.0005..=0.010).contains(dt), "dt {dt} s at {t} µs");
    }
    // Ticks come at least ~a period apart everywhere, including right after the stall.
    for pair in calls.windows(2) {
        assert!(pair[1].0 - pair[0].0 >= 900, "{:?}", pair);
    }
    assert!((49..=50).contains(&skipped), "skipped {skipped}");
}

#[test]
fn scheduler_ticks_at_the_bus_configured_period() {
    // A bus configured for a 2 ms tick: the scheduler's pacer takes the period from the
    // bus, so ticks 2 ms apart are on time (dt 2 ms from the first, which is the nominal
    // period; none skipped). A pacer at 1 ms would give the first tick a dt of 1 ms and count
    // each later one a period late.
    let config = BusConfig {
        tick_period: Duration::from_millis(2),
        ..BusConfig::DEFAULT
    };
    let (calls, _, skipped) = run_fake_ticks(config, 2_000, 50, (0, 0));
    assert_eq!(calls.len(), 50);
    for (t, dt) in &calls {
        assert!((dt - 0.002).abs() < 1e-5, "dt {dt} s at {t} µs");
    }
    assert_eq!(skipped, 0);
}

#[test]
fn receive_backoff_waits_only_for_repeated_errors_and_resets_on_a_frame() {
    let mut b = ReceiveBackoff::new();
    assert_eq!(b.on_error(), None);
    assert_eq!(b.on_error(), Some(Duration::from_micros(100)));
    assert_eq!(b.on_error(), Some(Duration::from_micros(200)));
    for _ in 0..20 {
        b.on_error();
    }
    assert_eq!(b.on_error(), Some(ReceiveBackoff::MAX));
    b.on_frame();
    assert_eq!(b.on_error(), None);
}

#[test]
fn frames_left_over_from_the_previous_tick_are_counted_stale() {
    let m = DjiMotor::m3508(1).unwrap();
    let mut builder = BusBuilder::<1>::new();
    builder.register(&m).unwrap();
    let bus = builder.build();
    let mut tx = TxQueue::<3>::new();
    let mut batch = TxBatch::new();
    bus.tick(T0, 0.001, &mut batch);
    bus.transmit(&batch, &mut tx); // nobody takes it off the bus (no ACK)
    bus.tick(T0, 0.001, &mut batch);
    bus.transmit(&batch, &mut tx);
    bus.tick(T0, 0.001, &mut batch);
    bus.transmit(&batch, &mut tx);
    // 0 waiting at tick 1, 1 at tick 2, 2 at tick 3.
    assert_eq!(bus.stats().snapshot().tx_stale, 3);
    while tx.pop().is_some() {}
    bus.transmit(&batch, &mut tx);
    assert_eq!(bus.stats().snapshot().tx_stale, 3);
}

/// Sends one frame per tick on `id`, and optionally one it never declared.
struct OneFrame {
    id: u16,
    rogue: bool,
}

impl CanNode for OneFrame {
    fn bus_usage(&self) -> BusUsage {
        BusUsage::NONE.sending(IdFilter::standard(self.id), 1)
    }
    fn update_feedback(&self, _frame: &CanFrame, _now: Instant) -> Result<(), FrameError> {
        Ok(())
    }
    fn update(&self, _now: Instant, _dt_s: f32) {}
    fn pack_command(&self, out: &mut TxBatch) {
        let _ = out.push(CanFrame::standard(self.id, &[1]).unwrap());
        if self.rogue {
            // A second frame, and on a C620's feedback ID: never declared.
            let _ = out.push(CanFrame::standard(0x201, &[0xFF; 8]).unwrap());
        }
    }
}

#[test]
fn a_backlog_delays_every_node_in_turn_instead_of_starving_the_last() {
    let nodes = [0x301u16, 0x302, 0x303].map(|id| OneFrame { id, rogue: false });
    let mut builder = BusBuilder::<4>::new();
    for n in &nodes {
        builder.register(n).unwrap();
    }
    let bus = builder.build();
    let mut tx = TxQueue::<3>::new();
    let mut batch = TxBatch::new();
    let mut queued = std::collections::HashMap::new();
    for _ in 0..9 {
        bus.tick(T0, 0.001, &mut batch);
        let before: Vec<CanFrame> = core::iter::from_fn(|| tx.pop()).collect();
        for f in &before {
            tx.try_send(f).unwrap(); // put them back: we only want to see what this tick adds
        }
        bus.transmit(&batch, &mut tx);
        let after: Vec<CanFrame> = core::iter::from_fn(|| tx.pop()).collect();
        for f in &after[before.len()..] {
            *queued.entry(f.raw_id()).or_insert(0) += 1;
        }
        // The bus carries only two frames per tick: one stays queued (a backlog).
        for f in after.iter().skip(2) {
            tx.try_send(f).unwrap();
        }
    }
    // Every node got its frame out on most ticks; none was refused every time.
    for id in [0x301, 0x302, 0x303] {
        assert!(
            queued.get(&id).copied().unwrap_or(0) >= 5,
            "{id:#x}: {queued:?}"
        );
    }
}

#[test]
fn frames_a_node_did_not_declare_are_dropped_and_counted() {
    let rogue = OneFrame {
        id: 0x301,
        rogue: true,
    };
    let wheel = DjiMotor::m3508(1).unwrap();
    let mut builder = BusBuilder::<4>::new();
    builder.register(&wheel).unwrap();
    builder.register(&rogue).unwrap(); // its declaration (0x301 only) passes
    let bus = builder.build();
    let mut batch = TxBatch::new();
    bus.tick(T0, 0.001, &mut batch);
    let ids: Vec<u32> = batch.frames().iter().map(|f| f.raw_id()).collect();
    assert_eq!(ids, [0x200, 0x301]); // the frame on the C620's feedback ID never goes out
    assert_eq!(bus.stats().snapshot().tx_undeclared, 1);
}

/// Declares `declared` (or no slot), then writes slot 1 of 0x200, another motor's slot 0 of
/// 0x200 and slots 0 and 1 on a C620's feedback ID 0x201; remembers what `write_slot`
/// answered.
struct SlotStray {
    declared: Option<CommandSlot>,
    answers: std::sync::Mutex<[bool; 4]>,
}

impl SlotStray {
    fn new(declared: Option<CommandSlot>) -> Self {
        Self {
            declared,
            answers: std::sync::Mutex::new([false; 4]),
        }
    }
}

impl CanNode for SlotStray {
    fn bus_usage(&self) -> BusUsage {
        match self.declared {
            Some(slot) => BusUsage::NONE.with_slot(slot),
            None => BusUsage::NONE,
        }
    }
    fn update_feedback(&self, _frame: &CanFrame, _now: Instant) -> Result<(), FrameError> {
        Ok(())
    }
    fn update(&self, _now: Instant, _dt_s: f32) {}
    fn pack_command(&self, out: &mut TxBatch) {
        *self.answers.lock().unwrap() = [
            out.write_slot(CommandSlot::new(0x200, 1).unwrap(), 0x0102),
            out.write_slot(CommandSlot::new(0x200, 0).unwrap(), 1234),
            out.write_slot(CommandSlot::new(0x201, 0).unwrap(), 1),
            out.write_slot(CommandSlot::new(0x201, 1).unwrap(), 2),
        ];
    }
}

#[test]
fn a_node_writes_only_the_slot_it_declared() {
    let wheel = DjiMotor::m3508(1).unwrap(); // slot 0 of 0x200; offline, so it commands 0
    let stray = SlotStray::new(CommandSlot::new(0x200, 1)); // as an M3508 with ESC id 2
    let mut builder = BusBuilder::<4>::new();
    builder.register(&wheel).unwrap();
    builder.register(&stray).unwrap();
    let bus = builder.build();
    let mut batch = TxBatch::new();
    bus.tick(T0, 0.001, &mut batch);
    assert_eq!(*stray.answers.lock().unwrap(), [true, false, false, false]);
    // One frame: the wheel's own 0 in slot 0 (not the stray's 1234 = 0x04D2), the stray's
    // declared slot 1; nothing on the feedback ID 0x201.
    assert_eq!(batch.frames().len(), 1);
    assert_eq!(batch.frames()[0].raw_id(), 0x200);
    assert_eq!(batch.frames()[0].data(), &[0, 0, 1, 2, 0, 0, 0, 0]);
    assert_eq!(bus.stats().snapshot().tx_undeclared, 3);
    // Outside a tick the batch takes any slot again.
    assert!(batch.write_slot(CommandSlot::new(0x1FF, 3).unwrap(), 7));
}

#[test]
fn a_node_that_declared_no_slot_writes_none() {
    let stray = SlotStray::new(None);
    let mut builder = BusBuilder::<4>::new();
    builder.register(&stray).unwrap();
    let bus = builder.build();
    let mut batch = TxBatch::new();
    bus.tick(T0, 0.001, &mut batch);
    assert_eq!(*stray.answers.lock().unwrap(), [false; 4]);
    assert!(batch.frames().is_empty());
    assert_eq!(bus.stats().snapshot().tx_undeclared, 4);
}

#[test]
fn a_slot_that_does_not_fit_the_send_set_is_an_error_not_a_blind_spot() {
    let log = leak_log();
    let mut p = Probe::new("p", log);
    let mut sends = IdSet::EMPTY;
    for i in 0..crate::node::ID_SET_CAPACITY as u16 {
        sends = sends.with(IdFilter::standard(0x300 + i));
    }
    p.usage = BusUsage {
        sends,
        frames_per_tick: 1,
        command_slot: CommandSlot::new(0x200, 0),
        ..BusUsage::NONE
    };
    let mut b = BusBuilder::<2>::new();
    assert_eq!(b.register(&p), Err(RegisterError::TooManyIds));
}

/// Sends one whole frame on `whole` or writes its command `slot`; records what it is told
/// about refused frames.
struct Told {
    /// A whole frame's ID, and whether it is extended.
    whole: Option<(u32, bool)>,
    slot: Option<CommandSlot>,
    told: StdMutex<Vec<(u32, SendError)>>,
}

impl Told {
    fn whole(id: u32, extended: bool) -> Self {
        Self {
            whole: Some((id, extended)),
            slot: None,
            told: StdMutex::new(Vec::new()),
        }
    }
    fn slot(id: u16, index: u8) -> Self {
        Self {
            whole: None,
            slot: CommandSlot::new(id, index),
            told: StdMutex::new(Vec::new()),
        }
    }
    fn told(&self) -> Vec<(u32, SendError)> {
        self.told.lock().unwrap().clone()
    }
}

impl CanNode for Told {
    fn bus_usage(&self) -> BusUsage {
        match (self.whole, self.slot) {
            (Some((id, true)), _) => BusUsage::NONE.sending(IdFilter::extended(id), 1),
            (Some((id, false)), _) => BusUsage::NONE.sending(IdFilter::standard(id as u16), 1),
            (None, Some(slot)) => BusUsage::NONE.with_slot(slot),
            (None, None) => BusUsage::NONE,
        }
    }
    fn update_feedback(&self, _frame: &CanFrame, _now: Instant) -> Result<(), FrameError> {
        Ok(())
    }
    fn update(&self, _now: Instant, _dt_s: f32) {}
    fn pack_command(&self, out: &mut TxBatch) {
        match self.whole {
            Some((id, true)) => {
                let _ = out.push(CanFrame::extended(id, &[7]).unwrap());
            }
            Some((id, false)) => {
                let _ = out.push(CanFrame::standard(id as u16, &[7]).unwrap());
            }
            None => {}
        }
        if let Some(slot) = self.slot {
            out.write_slot(slot, 100);
        }
    }
    fn frame_refused(&self, frame: &CanFrame, reason: SendError) {
        self.told.lock().unwrap().push((frame.raw_id(), reason));
    }
}

/// Refuses frames on the IDs it lists (Full or BusOff), queues the rest.
struct RefuseIds(&'static [(crate::can::Id, SendError)]);

impl CanTransmit for RefuseIds {
    fn try_send(&mut self, frame: &CanFrame) -> Result<(), SendError> {
        match self.0.iter().find(|(id, _)| *id == frame.id()) {
            Some(&(_, reason)) => Err(reason),
            None => Ok(()),
        }
    }
}

#[test]
fn a_refused_frame_is_reported_to_the_nodes_that_declared_it_and_no_others() {
    let refused_whole = Told::whole(0x301, false);
    let sent_whole = Told::whole(0x302, false);
    let (refused_slot_a, refused_slot_b) = (Told::slot(0x1FF, 0), Told::slot(0x1FF, 1));
    let sent_slot = Told::slot(0x200, 0);
    // An extended frame refused (a VESC's), and one whose ID has the same number as the
    // refused standard one: only the extended sender is told about its own.
    let refused_extended = Told::whole(0x0000_0305, true);
    let same_number_extended = Told::whole(0x0000_0301, true);
    let nodes = [
        &refused_whole,
        &sent_whole,
        &refused_slot_a,
        &refused_slot_b,
        &sent_slot,
        &refused_extended,
        &same_number_extended,
    ];
    let mut builder = BusBuilder::<8>::with_config(NO_BUDGET);
    for n in nodes {
        builder.register(n).unwrap();
    }
    let bus = builder.build();
    let mut batch = TxBatch::new();
    bus.tick(T0, 0.001, &mut batch);
    assert_eq!(batch.frames().len(), 6); // 0x301, 0x302, 0x1FF (two slots), 0x200, 2 extended
    let std_id = |id| crate::can::Id::Standard(crate::can::StandardId::new(id).unwrap());
    let ext_id = |id| crate::can::Id::Extended(crate::can::ExtendedId::new(id).unwrap());
    let refusals: &'static [(crate::can::Id, SendError)] = Box::leak(Box::new([
        (std_id(0x301), SendError::Full),
        (std_id(0x1FF), SendError::BusOff),
        (ext_id(0x305), SendError::Full),
    ]));
    let mut tx = RefuseIds(refusals);
    let report = bus.transmit(&batch, &mut tx);
    assert_eq!((report.queued, report.full, report.bus_off), (3, 2, 1));
    assert_eq!(refused_extended.told(), [(0x305, SendError::Full)]);
    assert!(same_number_extended.told().is_empty());
    assert_eq!(refused_whole.told(), [(0x301, SendError::Full)]);
    assert_eq!(refused_slot_a.told(), [(0x1FF, SendError::BusOff)]);
    assert_eq!(refused_slot_b.told(), [(0x1FF, SendError::BusOff)]);
    assert!(sent_whole.told().is_empty());
    assert!(sent_slot.told().is_empty());
}

#[test]
fn a_damiao_save_zero_refused_by_a_full_queue_goes_out_once_there_is_room() {
    let dm = DmMotor::new(0x01, DmConfig::new(0x11)).unwrap();
    let mut builder = BusBuilder::<2>::new();
    builder.register(&dm).unwrap();
    let bus = builder.build();
    // Online, at 0xC000 with the old zero.
    let reply = CanFrame::standard(0x11, &[0x11, 0xC0, 0x00, 0x7F, 0xF7, 0xFF, 30, 30]).unwrap();
    bus.dispatch(&reply, T0);
    dm.send_special(crate::motor::dm::DmSpecial::SaveZero);
    let save_zero = [0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFE];
    // The one TX buffer holds a frame nobody acknowledged.
    let mut tx = TxQueue::<1>::new();
    tx.try_send(&fb(0x7FF)).unwrap();
    let mut batch = TxBatch::new();
    for _ in 0..3 {
        bus.tick(T0, 0.001, &mut batch);
        assert_eq!(batch.frames()[0].data(), save_zero);
        assert_eq!(bus.transmit(&batch, &mut tx).full, 1);
        bus.dispatch(&reply, T0);
    }
    // Acknowledged at last: FE is queued, then MIT commands follow.
    tx.pop().unwrap();
    bus.tick(T0, 0.001, &mut batch);
    assert_eq!(bus.transmit(&batch, &mut tx).queued, 1);
    assert_eq!(tx.pop().unwrap().data(), save_zero);
    bus.dispatch(&reply, T0);
    bus.tick(T0, 0.001, &mut batch);
    assert_ne!(batch.frames()[0].data()[..7], [0xFF; 7]);
}
