//! One execution of each hot path between two marker calls, for `benches/m4/profile`, which
//! runs this under QEMU with an execution trace and prints where the instructions go
//! (instructions per function, inclusive of nothing: each instruction counts once, in the
//! function that executes it).
//!
//! Regions: `speed4` (one 4×M3508 speed-mode tick), `angle4` (one 4×M3508 angle-mode tick
//! that runs the angle loop), `dispatch` (one feedback frame routed among 4 motors),
//! `pid` (one positional PID step), `incremental` (one incremental PID step), `dt`
//! (one `DeltaTime` update), `td` (one incremental PID step with a tracking differentiator).
#![no_std]
#![no_main]

use core::hint::black_box;
use cortex_m_rt::entry;
use cortex_m_semihosting::debug;
use panic_semihosting as _;
use rc10_core::bus::{Bus, BusBuilder};
use rc10_core::can::CanFrame;
use rc10_core::motor::Motor;
use rc10_core::motor::dji::DjiMotor;
use rc10_core::node::TxBatch;
use rc10_core::pid::{IncrementalPid, IncrementalPidConfig, Pid, PidConfig};
use rc10_core::time::{DeltaTime, Duration, Instant};

const fn m3508(id: u8) -> DjiMotor {
    match DjiMotor::m3508(id) {
        Ok(m) => m,
        Err(_) => panic!("id"),
    }
}

static SPEED: [DjiMotor; 4] = [m3508(1), m3508(2), m3508(3), m3508(4)];
static ANGLE: [DjiMotor; 4] = [m3508(1), m3508(2), m3508(3), m3508(4)];

/// Marks the start of region `id` (the trace parser reads `r0` from the call site's order).
#[unsafe(no_mangle)]
#[inline(never)]
pub extern "C" fn rc10_profile_begin(id: u32) {
    black_box(id);
}

/// Marks the end of the current region.
#[unsafe(no_mangle)]
#[inline(never)]
pub extern "C" fn rc10_profile_end() {
    black_box(());
}

fn feedback(id: u16, k: u32) -> CanFrame {
    let angle = ((k * 500 + u32::from(id) * 1000) % 8192) as u16;
    let rpm = 3000 + (k % 64) as i16;
    let a = angle.to_be_bytes();
    let r = rpm.to_be_bytes();
    CanFrame::standard(0x200 + id, &[a[0], a[1], r[0], r[1], 0x01, 0x00, 35, 0])
        .unwrap_or(CanFrame::standard(0x200, &[]).unwrap_or_else(|| unreachable!()))
}

fn bus_of(motors: &'static [DjiMotor; 4]) -> Bus<'static, 8> {
    let mut b: BusBuilder<'static, 8> = BusBuilder::new();
    for m in motors {
        let _ = b.register(m);
    }
    b.build()
}

fn run(bus: &Bus<'static, 8>, ticks: u32, region: Option<u32>) {
    let mut batch = TxBatch::new();
    for k in 0..ticks {
        let now = Instant::from_micros(1_000_000 + u64::from(k) * 1000);
        for id in 1..=4 {
            bus.dispatch(&feedback(id, k), now);
        }
        let last = k + 1 == ticks;
        if let (true, Some(r)) = (last, region) {
            rc10_profile_begin(r);
            bus.tick(black_box(now), black_box(0.001), &mut batch);
            rc10_profile_end();
        } else {
            bus.tick(now, 0.001, &mut batch);
        }
    }
}

#[entry]
fn main() -> ! {
    let speed = bus_of(&SPEED);
    for m in &SPEED {
        let _ = m.set_target_rpm(300.0);
    }
    run(&speed, 30, Some(0));
    let angle = bus_of(&ANGLE);
    for m in &ANGLE {
        let _ = m.set_target_angle_deg(90.0);
    }
    // 31 ticks: the angle loop runs on ticks 1, 11, 21 and 31.
    run(&angle, 31, Some(1));

    let frame = feedback(4, 31);
    rc10_profile_begin(2);
    speed.dispatch(black_box(&frame), Instant::from_micros(1_031_000));
    rc10_profile_end();

    let mut pid = Pid::new(
        PidConfig::new(0.6, 8.0, 0.001)
            .with_output_limit(20.0)
            .with_integral_limit(10.0),
    )
    .unwrap_or_else(|_| unreachable!());
    let _ = pid.update(300.0, 5.0, 0.001);
    rc10_profile_begin(3);
    black_box(pid.update(black_box(300.0), black_box(7.0), black_box(0.001)));
    rc10_profile_end();

    let mut inc =
        IncrementalPid::new(IncrementalPidConfig::new(18.0, 15.0, 0.0).with_output_limit(15.0))
            .unwrap_or_else(|_| unreachable!());
    let _ = inc.update(300.0, 5.0, 0.001);
    rc10_profile_begin(4);
    black_box(inc.update(black_box(300.0), black_box(7.0), black_box(0.001)));
    rc10_profile_end();

    let mut dt = DeltaTime::new(Duration::from_millis(1), Duration::from_millis(10));
    let _ = dt.update(Instant::from_micros(5_000_000_000));
    rc10_profile_begin(5);
    black_box(dt.update(black_box(Instant::from_micros(5_000_001_003))));
    rc10_profile_end();

    let mut td = IncrementalPid::new(
        IncrementalPidConfig::new(18.0, 15.0, 0.0)
            .with_output_limit(15.0)
            .with_td(200.0),
    )
    .unwrap_or_else(|_| unreachable!());
    let _ = td.update(300.0, 5.0, 0.001);
    rc10_profile_begin(6);
    black_box(td.update(black_box(300.0), black_box(7.0), black_box(0.001)));
    rc10_profile_end();

    debug::exit(debug::EXIT_SUCCESS);
    loop {
        cortex_m::asm::wfi();
    }
}
