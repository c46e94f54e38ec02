//! `run_receiver` against a transport that fails on every call without ever waiting (a
//! controller stuck reporting overruns, a driver in a bad state). On a single-threaded
//! executor a receiver that retried at once would never yield: every other task on that
//! executor would starve. It must back off and let them run.

// Test code: a failed setup or assertion should stop the test.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use embassy_executor::{Executor, Spawner};
use embassy_time::{Duration, Timer};
use rc10_core::bus::{Bus, BusBuilder, run_receiver};
use rc10_core::can::{CanReceive, ReceiveError, Received};
use rc10_core::motor::dji::DjiMotor;
use static_cell::StaticCell;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc;

static WHEEL: DjiMotor = match DjiMotor::m3508(1) {
    Ok(m) => m,
    Err(_) => panic!("id"),
};
static BUS: StaticCell<Bus<'static, 1>> = StaticCell::new();
static CALLS: AtomicU32 = AtomicU32::new(0);

/// Fails at once, every time.
struct BrokenRx;

impl CanReceive for BrokenRx {
    async fn receive(&mut self) -> Result<Received, ReceiveError> {
        CALLS.fetch_add(1, Ordering::Relaxed);
        Err(ReceiveError::Overrun)
    }
}

#[embassy_executor::task]
async fn receiver(bus: &'static Bus<'static, 1>) {
    run_receiver(bus, BrokenRx).await
}

/// Another task on the same executor: it only gets to run if the receiver yields.
#[embassy_executor::task]
async fn other(bus: &'static Bus<'static, 1>, done: mpsc::Sender<(u32, u32)>) {
    Timer::after(Duration::from_millis(50)).await;
    let _ = done.send((
        CALLS.load(Ordering::Relaxed),
        bus.stats().snapshot().rx_overruns,
    ));
}

fn start(spawner: Spawner, done: mpsc::Sender<(u32, u32)>) {
    let mut builder = BusBuilder::<1>::new();
    builder.register(&WHEEL).unwrap();
    let bus: &'static Bus<'static, 1> = BUS.init(builder.build());
    spawner.spawn(receiver(bus).unwrap());
    spawner.spawn(other(bus, done).unwrap());
}

#[test]
fn a_transport_that_keeps_failing_does_not_make_the_receiver_spin() {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let executor: &'static mut Executor = Box::leak(Box::new(Executor::new()));
        executor.run(move |spawner| start(spawner, tx));
    });
    let (calls, overruns) = rx
        .recv_timeout(std::time::Duration::from_secs(10))
        .expect("the other task never ran: the receiver starved the executor");
    // Back-off 0, 0.1, 0.2, … ms doubling to 10 ms: about a dozen calls in 50 ms, not millions.
    assert!((2..=40).contains(&calls), "{calls} receive calls in 50 ms");
    // Every failure is still counted.
    assert!(
        overruns >= calls - 1 && overruns <= calls,
        "{overruns} vs {calls}"
    );
}
