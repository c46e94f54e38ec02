//! The async scheduler and receiver loops on embassy-executor's host (`platform-std`)
//! executor with the std time driver, against an in-memory bus: a fake ESC task answers every
//! command frame with feedback through a channel, as C620s would.
//!
//! Checks, at a moment when no task is mid-tick (the executor is single-threaded): exactly two
//! command frames per tick (0x200 for id 1, 0x1FF for id 5), the commanded current on the wire
//! byte for byte once feedback has brought the motors online, and every feedback frame routed.

// Test code: a failed setup or assertion should stop the test.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

use embassy_executor::{Executor, Spawner};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_time::{Duration, Instant, Timer};
use rc10_core::bus::{Bus, BusBuilder, run_receiver, run_scheduler};
use rc10_core::can::{CanFrame, CanReceive, CanTransmit, ReceiveError, Received, SendError};
use rc10_core::motor::Motor;
use rc10_core::motor::dji::DjiMotor;
use static_cell::StaticCell;
use std::sync::Mutex;
use std::sync::mpsc;

static WHEEL_1: DjiMotor = match DjiMotor::m3508(1) {
    Ok(m) => m,
    Err(_) => panic!("id"),
};
static WHEEL_5: DjiMotor = match DjiMotor::m3508(5) {
    Ok(m) => m,
    Err(_) => panic!("id"),
};
static BUS: StaticCell<Bus<'static, 4>> = StaticCell::new();
/// Frames the scheduler queued, in order.
static SENT: Mutex<Vec<CanFrame>> = Mutex::new(Vec::new());
/// Wire from the fake ESCs to the receiver.
static RX: Channel<CriticalSectionRawMutex, Received, 8> = Channel::new();

struct RecordingTx;

impl CanTransmit for RecordingTx {
    fn try_send(&mut self, frame: &CanFrame) -> Result<(), SendError> {
        SENT.lock().unwrap().push(*frame);
        Ok(())
    }
}

struct ChannelRx;

impl CanReceive for ChannelRx {
    async fn receive(&mut self) -> Result<Received, ReceiveError> {
        Ok(RX.receive().await)
    }
}

#[embassy_executor::task]
async fn scheduler(bus: &'static Bus<'static, 4>) {
    run_scheduler(bus, RecordingTx).await
}

#[embassy_executor::task]
async fn receiver(bus: &'static Bus<'static, 4>) {
    run_receiver(bus, ChannelRx).await
}

/// Plays two C620s: each millisecond, one feedback frame each (angle 0, 0 rpm, 40 °C).
#[embassy_executor::task]
async fn escs() {
    loop {
        for id in [0x201u16, 0x205] {
            let frame = CanFrame::standard(id, &[0, 0, 0, 0, 0, 0, 40, 0]).unwrap();
            RX.send(Received {
                frame,
                timestamp: Instant::now(),
            })
            .await;
        }
        Timer::after(Duration::from_millis(1)).await;
    }
}

struct Outcome {
    ticks: u32,
    sent: Vec<CanFrame>,
    rx_frames: u32,
    rx_unmatched: u32,
    online: bool,
}

#[embassy_executor::task]
async fn checker(bus: &'static Bus<'static, 4>, done: mpsc::Sender<Outcome>) {
    WHEEL_1.set_target_current(5.0).unwrap();
    WHEEL_5.set_target_current(-2.5).unwrap();
    while bus.stats().snapshot().ticks < 50 {
        Timer::after(Duration::from_millis(1)).await;
    }
    let c = bus.stats().snapshot();
    let _ = done.send(Outcome {
        ticks: c.ticks,
        sent: SENT.lock().unwrap().clone(),
        rx_frames: c.rx_frames,
        rx_unmatched: c.rx_unmatched,
        online: WHEEL_1.is_online() && WHEEL_5.is_online(),
    });
}

fn start(spawner: Spawner, done: mpsc::Sender<Outcome>) {
    let mut builder = BusBuilder::<4>::new();
    builder.register(&WHEEL_1).unwrap();
    builder.register(&WHEEL_5).unwrap();
    let bus: &'static Bus<'static, 4> = BUS.init(builder.build());
    spawner.spawn(scheduler(bus).unwrap());
    spawner.spawn(receiver(bus).unwrap());
    spawner.spawn(escs().unwrap());
    spawner.spawn(checker(bus, done).unwrap());
}

#[test]
fn scheduler_and_receiver_tasks_run_the_bus_on_the_host_executor() {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let executor: &'static mut Executor = Box::leak(Box::new(Executor::new()));
        executor.run(move |spawner| start(spawner, tx));
    });
    let out = rx
        .recv_timeout(std::time::Duration::from_secs(20))
        .expect("tasks did not reach 50 ticks");

    assert!(out.ticks >= 50);
    // Exactly one 0x200 and one 0x1FF frame per tick, in that order.
    assert_eq!(out.sent.len(), 2 * out.ticks as usize);
    for pair in out.sent.chunks(2) {
        assert_eq!((pair[0].raw_id(), pair[1].raw_id()), (0x200, 0x1FF));
    }
    // Once online: 5 A = 4096 = 0x1000 in slot 0 of 0x200; -2.5 A = -2048 = 0xF800 in slot 0
    // of 0x1FF.
    let last = &out.sent[out.sent.len() - 2..];
    assert_eq!(last[0].data(), &[0x10, 0x00, 0, 0, 0, 0, 0, 0]);
    assert_eq!(last[1].data(), &[0xF8, 0x00, 0, 0, 0, 0, 0, 0]);
    assert!(out.online);
    assert!(out.rx_frames >= 2 * 40, "rx {}", out.rx_frames);
    assert_eq!(out.rx_unmatched, 0);
}
