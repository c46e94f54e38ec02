//! The rc10-core hot paths on the Cortex-M4 instruction set: prints a table (min / median /
//! max / mean instructions) and one `figure NAME VALUE` line per tracked figure, which
//! `benches/m4/run --check` compares with `baseline.txt`.
//!
//! Scenarios: DJI M3508s (1, 4, and 8 on two buses) in speed and in angle mode with feedback
//! that changes every tick (one `Bus::tick` each: update + pack, send excluded); one feedback
//! frame routed and parsed among 4 motors at start and after 10⁶ frames at full speed; one
//! step of each PID kind; one `DeltaTime` update. Then the 4-motor speed and angle ticks, the
//! frame and the two PID steps of `rc10_bench_m4::reference` (a minimal implementation of
//! the same shape), printed for comparison and not tracked.
#![no_std]
#![no_main]

use core::cell::RefCell;
use core::hint::black_box;
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use panic_semihosting as _;
use rc10_bench_m4::reference::{self, Lock, Node, RefMotor, RefPid, RxStats, State};
use rc10_bench_m4::{Calibration, min_median_max, ticks, timer_start};
use rc10_core::bus::{Bus, BusBuilder};
use rc10_core::can::CanFrame;
use rc10_core::motor::Motor;
use rc10_core::motor::dji::DjiMotor;
use rc10_core::node::TxBatch;
use rc10_core::pid::{IncrementalPid, IncrementalPidConfig, Pid, PidConfig, PidTerms};
use rc10_core::time::{DeltaTime, Duration, Instant};

const SAMPLES: usize = 1000;

const fn m3508(id: u8) -> DjiMotor {
    match DjiMotor::m3508(id) {
        Ok(m) => m,
        Err(_) => panic!("id"),
    }
}

/// Two buses' worth of M3508s (ids 1–4 on each).
static MOTORS: [DjiMotor; 8] = [
    m3508(1),
    m3508(2),
    m3508(3),
    m3508(4),
    m3508(1),
    m3508(2),
    m3508(3),
    m3508(4),
];

#[derive(Clone, Copy, PartialEq)]
enum Mode {
    Speed,
    Angle,
}

/// Feedback of ESC `id` at tick `k`: the rotor turning at about 3000 rpm, its speed varying.
fn feedback(id: u16, k: u32) -> CanFrame {
    let angle = ((k * 500 + u32::from(id) * 1000) % 8192) as u16;
    let rpm = 3000 + (k % 64) as i16;
    let a = angle.to_be_bytes();
    let r = rpm.to_be_bytes();
    CanFrame::standard(0x200 + id, &[a[0], a[1], r[0], r[1], 0x01, 0x00, 35, 0])
        .unwrap_or(CanFrame::standard(0x200, &[]).unwrap_or_else(|| unreachable!()))
}

struct Figures {
    cal: Calibration,
}

impl Figures {
    /// Prints a row (min / median / max / mean) and its tracked `figure` line.
    fn row(&self, name: &str, samples: &mut [u32], figure: Stat) {
        let (_, median, max, mean) = print_row(name, samples);
        let value = match figure {
            Stat::Median => median,
            Stat::Max => max,
            Stat::Mean => mean,
        };
        hprintln!("figure {} {}", name, value);
    }

    /// A row of the reference motors: printed, not tracked.
    fn reference_row(&self, name: &str, samples: &mut [u32]) {
        print_row(name, samples);
    }
}

/// Prints a table row of `samples` (sorted in place); returns min, median, max and mean.
fn print_row(name: &str, samples: &mut [u32]) -> (u32, u32, u32, u32) {
    let n = samples.len().max(1) as u64;
    let mean = (samples.iter().map(|s| u64::from(*s)).sum::<u64>() / n) as u32;
    let (min, median, max) = min_median_max(samples);
    hprintln!(
        "{:<34} {:>7} {:>7} {:>7} {:>7}",
        name,
        min,
        median,
        max,
        mean
    );
    (min, median, max, mean)
}

#[derive(Clone, Copy)]
enum Stat {
    Median,
    Max,
    Mean,
}

/// One positional PID step, behind a call as the firmware's motor makes it: the figure is
/// the step's own, not whatever the bench's main loop inlined it into (its register
/// allocation shifted by tens of instructions when an unrelated function changed).
#[inline(never)]
fn positional_step(pid: &mut Pid, measurement: f32) -> PidTerms {
    pid.update(black_box(300.0), measurement, black_box(0.001))
}

/// One incremental PID step, behind a call (see [`positional_step`]).
#[inline(never)]
fn incremental_step(pid: &mut IncrementalPid, measurement: f32) -> PidTerms {
    pid.update(black_box(300.0), measurement, black_box(0.001))
}

fn tick_samples(f: &Figures, motors: &'static [DjiMotor], mode: Mode, out: &mut [u32; SAMPLES]) {
    let mut first: BusBuilder<'static, 8> = BusBuilder::new();
    let mut second: BusBuilder<'static, 8> = BusBuilder::new();
    for (i, m) in motors.iter().enumerate() {
        let builder = if i < 4 { &mut first } else { &mut second };
        let _ = builder.register(m);
        let _ = match mode {
            Mode::Speed => m.set_target_rpm(300.0),
            Mode::Angle => m.set_target_angle_deg(90.0),
        };
    }
    let buses: [Bus<'static, 8>; 2] = [first.build(), second.build()];
    let mut batch = TxBatch::new();
    for k in 0..(SAMPLES as u32 + 20) {
        let now = Instant::from_micros(1_000_000 + u64::from(k) * 1000);
        for (i, _) in motors.iter().enumerate() {
            let bus = &buses[usize::from(i >= 4)];
            bus.dispatch(&feedback(1 + (i % 4) as u16, k), now);
        }
        let t = ticks(|| {
            // Up to four motors on one bus; eight on two (a bus with no motors is not ticked).
            for bus in buses.iter().take(motors.len().div_ceil(4)) {
                bus.tick(black_box(now), black_box(0.001), &mut batch);
            }
        });
        // The first 20 ticks bring the motors online and settle the loops.
        if let Some(slot) = (k as usize).checked_sub(20).and_then(|i| out.get_mut(i)) {
            *slot = f.cal.instructions(t);
        }
    }
    for m in motors {
        m.disable();
    }
}

/// Checked reference motors shared as rc10's are (behind a critical section).
static CHECKED: [RefMotor<Locked, true, false>; 4] = [
    RefMotor::new(locked(), 0),
    RefMotor::new(locked(), 1),
    RefMotor::new(locked(), 2),
    RefMotor::new(locked(), 3),
];
static CHECKED_INCREMENTAL: [RefMotor<Locked, true, true>; 4] = [
    RefMotor::new(locked(), 0),
    RefMotor::new(locked(), 1),
    RefMotor::new(locked(), 2),
    RefMotor::new(locked(), 3),
];

static CHECKED_ANGLE: [RefMotor<Locked, true, false, true>; 4] = [
    RefMotor::new(locked(), 0),
    RefMotor::new(locked(), 1),
    RefMotor::new(locked(), 2),
    RefMotor::new(locked(), 3),
];

type Locked = critical_section::Mutex<RefCell<State>>;

const fn locked() -> Locked {
    critical_section::Mutex::new(RefCell::new(State::new(300.0)))
}

/// 1000 ticks of four reference motors, their speed and angle changing every tick (the
/// output angle sweeps 0–115°, across the 90° target of the angle references).
#[inline(never)]
fn reference_ticks<L: Lock, const C: bool, const I: bool, const A: bool>(
    f: &Figures,
    motors: &[RefMotor<L, C, I, A>; 4],
    out: &mut [u32; SAMPLES],
) {
    // A list whose length only the run knows, as a bus's is.
    let mut nodes: heapless::Vec<&dyn Node, 8> = heapless::Vec::new();
    for m in motors {
        let _ = nodes.push(m);
    }
    let mut frame = [0u8; 8];
    for k in 0..(SAMPLES as u32 + 20) {
        let now_us = 1_000_000 + u64::from(k) * 1000;
        for m in motors {
            m.state().with(|s| {
                s.set_feedback(
                    250.0 + (k % 64) as f32,
                    i64::from(k * 37 % 50_000),
                    now_us - 300,
                )
            });
        }
        let t = ticks(|| {
            reference::tick(
                black_box(&nodes[..]),
                black_box(now_us),
                black_box(0.001),
                &mut frame,
            )
        });
        if let Some(slot) = (k as usize).checked_sub(20).and_then(|i| out.get_mut(i)) {
            *slot = f.cal.instructions(t);
        }
    }
    black_box(frame);
}

#[inline(never)]
fn reference_rows(f: &Figures, s: &mut [u32; SAMPLES]) {
    hprintln!("reference motors (a minimal implementation of the shape; not rc10, not tracked):");
    let bare: [RefMotor<RefCell<State>, false, false>; 4] = [
        RefMotor::new(RefCell::new(State::new(300.0)), 0),
        RefMotor::new(RefCell::new(State::new(300.0)), 1),
        RefMotor::new(RefCell::new(State::new(300.0)), 2),
        RefMotor::new(RefCell::new(State::new(300.0)), 3),
    ];
    reference_ticks(f, &bare, s);
    f.reference_row("ref_speed_4_pi_unchecked", s);
    reference_ticks(f, &CHECKED, s);
    f.reference_row("ref_speed_4_pi_checked", s);
    reference_ticks(f, &CHECKED_INCREMENTAL, s);
    f.reference_row("ref_speed_4_incremental_checked", s);
    reference_ticks(f, &CHECKED_ANGLE, s);
    f.reference_row("ref_angle_4_pi_checked", s);
    let nodes: [&dyn Node; 4] = [&CHECKED[0], &CHECKED[1], &CHECKED[2], &CHECKED[3]];
    for (k, slot) in s.iter_mut().enumerate() {
        let k = k as u32;
        let frame = feedback(4, k);
        let now_us = 5_000_000 + u64::from(k) * 1000;
        *slot = f.cal.instructions(ticks(|| {
            reference::dispatch(&nodes, black_box(&frame), now_us)
        }));
    }
    f.reference_row("ref_dispatch_4_checked", s);
    let stats = RxStats::new();
    let fresh: [RefMotor<critical_section::Mutex<RefCell<State>>, true, false>; 4] = [
        RefMotor::new(
            critical_section::Mutex::new(RefCell::new(State::new(300.0))),
            0,
        ),
        RefMotor::new(
            critical_section::Mutex::new(RefCell::new(State::new(300.0))),
            1,
        ),
        RefMotor::new(
            critical_section::Mutex::new(RefCell::new(State::new(300.0))),
            2,
        ),
        RefMotor::new(
            critical_section::Mutex::new(RefCell::new(State::new(300.0))),
            3,
        ),
    ];
    let nodes: [&dyn Node; 4] = [&fresh[0], &fresh[1], &fresh[2], &fresh[3]];
    let mut taken = 0;
    for (k, slot) in s.iter_mut().enumerate() {
        let k = k as u32;
        let frame = feedback(4, k);
        let now_us = 5_000_000 + u64::from(k) * 1000;
        // The tick 300 µs before the frame, as at 1 kHz.
        let _ = fresh[3].state().with(|s| s.set_last_tick(now_us - 300));
        let mut took = false;
        *slot = f.cal.instructions(ticks(|| {
            took = reference::dispatch_checked(&nodes, &stats, black_box(&frame), now_us);
        }));
        taken += u32::from(took);
    }
    if taken != SAMPLES as u32 || stats.frames() != SAMPLES as u32 {
        hprintln!(
            "ref_dispatch_4_frame_checks: {} of {} frames taken",
            taken,
            stats.frames()
        );
    }
    f.reference_row("ref_dispatch_4_frame_checks", s);
    // The PID rows' gains and inputs (kp 0.6, ki 8, kd 0.001; limits 10 and 20; incremental
    // kp 18, ki 15, limit 15).
    let mut positional = RefPid::new(0.6, 8.0, 0.001, 10.0, 20.0);
    let mut incremental = RefPid::new(18.0, 15.0, 0.0, 0.0, 15.0);
    for (i, slot) in s.iter_mut().enumerate() {
        let m = (i % 97) as f32;
        *slot = f.cal.instructions(ticks(|| {
            positional.positional(black_box(300.0), m, black_box(0.001))
        }));
    }
    f.reference_row("ref_pid_positional", s);
    for (i, slot) in s.iter_mut().enumerate() {
        let m = (i % 97) as f32;
        *slot = f.cal.instructions(ticks(|| {
            incremental.incremental(black_box(300.0), m, black_box(0.001))
        }));
    }
    f.reference_row("ref_pid_incremental", s);
    let mut checked = RefPid::new(18.0, 15.0, 0.0, 0.0, 15.0);
    for (i, slot) in s.iter_mut().enumerate() {
        let m = (i % 97) as f32;
        *slot = f.cal.instructions(ticks(|| {
            checked.incremental_checked(black_box(300.0), m, black_box(0.001))
        }));
    }
    black_box(checked.last_terms());
    f.reference_row("ref_pid_incremental_checked", s);
}

#[entry]
fn main() -> ! {
    timer_start();
    let f = Figures {
        cal: Calibration::measure(),
    };
    hprintln!(
        "calibration: empty region {} timer ticks, {} ticks per 1000 instructions (3200 expected)",
        f.cal.overhead_ticks,
        f.cal.milliticks_per_instruction
    );
    hprintln!(
        "{:<34} {:>7} {:>7} {:>7} {:>7}",
        "instructions",
        "min",
        "median",
        "max",
        "mean"
    );
    let mut s = [0u32; SAMPLES];

    for (n, name) in [
        (1, "tick_speed_1"),
        (4, "tick_speed_4"),
        (8, "tick_speed_8"),
    ] {
        tick_samples(&f, &MOTORS[..n], Mode::Speed, &mut s);
        f.row(name, &mut s, Stat::Median);
    }
    for (n, worst, mean) in [
        (1, "tick_angle_1_worst", "tick_angle_1_mean"),
        (4, "tick_angle_4_worst", "tick_angle_4_mean"),
        (8, "tick_angle_8_worst", "tick_angle_8_mean"),
    ] {
        tick_samples(&f, &MOTORS[..n], Mode::Angle, &mut s);
        let mut copy = s;
        f.row(worst, &mut s, Stat::Max);
        f.row(mean, &mut copy, Stat::Mean);
    }

    // Routing + parsing one frame among four motors (the last registered: the longest search).
    let mut builder: BusBuilder<'static, 8> = BusBuilder::new();
    for m in &MOTORS[..4] {
        let _ = builder.register(m);
    }
    let bus = builder.build();
    // Stamps after every frame the tick benches gave these motors (a motor refuses a frame
    // stamped before the newest one it took).
    const T0_US: u64 = 10_000_000;
    let mut k = 0u32;
    let dispatch_samples = |k: &mut u32, out: &mut [u32; SAMPLES]| {
        for slot in out.iter_mut() {
            let frame = feedback(4, *k);
            let now = Instant::from_micros(T0_US + u64::from(*k) * 1000);
            *slot = f
                .cal
                .instructions(ticks(|| bus.dispatch(black_box(&frame), now)));
            *k += 1;
        }
    };
    dispatch_samples(&mut k, &mut s);
    f.row("dispatch_4_start", &mut s, Stat::Median);
    // 10⁶ frames at full speed (C620 no-load: 9256 rotor rpm ≈ 1264 counts per ms).
    for n in 0..1_000_000u32 {
        let angle = ((u64::from(n) * 1264) % 8192) as u16;
        let a = angle.to_be_bytes();
        let r = 9256i16.to_be_bytes();
        if let Some(frame) = CanFrame::standard(0x204, &[a[0], a[1], r[0], r[1], 0, 0, 35, 0]) {
            bus.dispatch(
                &frame,
                Instant::from_micros(T0_US + 1_500_000 + u64::from(n) * 1000),
            );
        }
    }
    k = 2_000_000;
    dispatch_samples(&mut k, &mut s);
    f.row("dispatch_4_after_1e6", &mut s, Stat::Median);
    // At full speed (above a sixteenth of a turn per period) the encoder weighs up to five
    // candidate frame gaps (three here: frames on time) instead of trusting one prediction.
    for slot in s.iter_mut() {
        let angle = ((u64::from(k) * 1264) % 8192) as u16;
        let a = angle.to_be_bytes();
        let r = (9256i16 - (k % 7) as i16).to_be_bytes();
        let frame = CanFrame::standard(0x204, &[a[0], a[1], r[0], r[1], 0, 0, 35, 0])
            .unwrap_or_else(|| unreachable!());
        let now = Instant::from_micros(T0_US + u64::from(k) * 1000);
        k += 1;
        *slot = f
            .cal
            .instructions(ticks(|| bus.dispatch(black_box(&frame), now)));
    }
    f.row("dispatch_4_full_speed", &mut s, Stat::Median);

    // One step of each controller, with every term in use.
    let mut pid = Pid::new(
        PidConfig::new(0.6, 8.0, 0.001)
            .with_output_limit(20.0)
            .with_integral_limit(10.0),
    )
    .unwrap_or_else(|_| unreachable!());
    let mut incremental =
        IncrementalPid::new(IncrementalPidConfig::new(18.0, 15.0, 0.0).with_output_limit(15.0))
            .unwrap_or_else(|_| unreachable!());
    let mut with_td = IncrementalPid::new(
        IncrementalPidConfig::new(18.0, 15.0, 0.0)
            .with_output_limit(15.0)
            .with_td(200.0),
    )
    .unwrap_or_else(|_| unreachable!());
    for (i, slot) in s.iter_mut().enumerate() {
        let m = (i % 97) as f32;
        *slot = f.cal.instructions(ticks(|| positional_step(&mut pid, m)));
    }
    f.row("pid_positional", &mut s, Stat::Median);
    for (i, slot) in s.iter_mut().enumerate() {
        let m = (i % 97) as f32;
        *slot = f
            .cal
            .instructions(ticks(|| incremental_step(&mut incremental, m)));
    }
    f.row("pid_incremental", &mut s, Stat::Median);
    for (i, slot) in s.iter_mut().enumerate() {
        let m = (i % 97) as f32;
        *slot = f
            .cal
            .instructions(ticks(|| incremental_step(&mut with_td, m)));
    }
    f.row("pid_incremental_td", &mut s, Stat::Median);

    let mut dt = DeltaTime::new(Duration::from_millis(1), Duration::from_millis(10));
    for (i, slot) in s.iter_mut().enumerate() {
        let now = Instant::from_micros(5_000_000_000 + i as u64 * 1000 + (i as u64 % 7));
        *slot = f.cal.instructions(ticks(|| dt.update(black_box(now))));
    }
    f.row("delta_time", &mut s, Stat::Median);

    reference_rows(&f, &mut s);

    debug::exit(debug::EXIT_SUCCESS);
    loop {
        cortex_m::asm::wfi();
    }
}
