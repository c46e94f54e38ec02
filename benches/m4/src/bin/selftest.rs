//! rc10-core checks on the Cortex-M4 instruction set (hard-float ABI, the M4's FPU, no std),
//! under QEMU: PID arithmetic, the encoder's exact multi-turn counting, DJI frame packing,
//! rounding of command values to wire integers (the M4's FPU adds to nearest and converts
//! towards zero, which the rounding without `roundf` relies on).
//! Expected values are worked out by hand, as in the host tests. Exits non-zero on failure.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use panic_semihosting as _;
use rc10_core::bus::BusBuilder;
use rc10_core::can::CanFrame;
use rc10_core::encoder::{Encoder, EncoderConfig, GearRatio};
use rc10_core::motor::Motor;
use rc10_core::motor::dji::DjiMotor;
use rc10_core::motor::vesc::VescCommand;
use rc10_core::node::TxBatch;
use rc10_core::pid::{Pid, PidConfig};
use rc10_core::time::Instant;

static WHEEL: DjiMotor = match DjiMotor::m3508(1) {
    Ok(m) => m,
    Err(_) => panic!("id"),
};
static FEEDER: DjiMotor = match DjiMotor::m2006(6) {
    Ok(m) => m,
    Err(_) => panic!("id"),
};

fn check(name: &str, ok: bool) {
    hprintln!("{} {}", if ok { "ok  " } else { "FAIL" }, name);
    if !ok {
        debug::exit(debug::EXIT_FAILURE);
    }
}

#[entry]
fn main() -> ! {
    // PID: trapezoid integral, p, output limit (see rc10-core's host tests).
    let mut pid = Pid::new(PidConfig::new(2.0, 10.0, 0.0).with_output_limit(5.0)).ok();
    let t = pid.as_mut().map(|p| p.update(10.0, 8.0, 0.001));
    check("pid p term 2 · 2 = 4", t.is_some_and(|t| t.p == 4.0));
    let mut i_only = Pid::new(PidConfig::new(0.0, 10.0, 0.0)).ok();
    let i1 = i_only.as_mut().map(|p| p.update(2.0, 0.0, 0.1).i);
    let i2 = i_only.as_mut().map(|p| p.update(4.0, 0.0, 0.1).i);
    check(
        "pid trapezoid 2 then 5",
        i1.is_some_and(|i| (i - 2.0).abs() < 1e-6) && i2.is_some_and(|i| (i - 5.0).abs() < 1e-6),
    );
    let limited = pid.as_mut().map(|p| p.update(10.0, 0.0, 0.001).output);
    check("pid output limited to 5", limited == Some(5.0));
    let nan = pid.as_mut().map(|p| p.update(f32::NAN, 0.0, 0.001).output);
    check("pid NaN target gives 0", nan == Some(0.0));

    // Encoder: one M3508 output turn is exactly 3591 rotor turns / 187.
    let mut enc = Encoder::new(EncoderConfig::dji(GearRatio::M3508));
    let mut raw = 0u32;
    if let Some(e) = enc.as_mut() {
        let _ = e.update(0);
        for _ in 0..(3591 * 8) {
            raw = (raw + 1024) % 8192; // 1/8 rotor turn per reading
            let _ = e.update(raw as u16);
        }
    }
    check(
        "encoder counts 3591 rotor turns exactly",
        enc.is_some_and(|e| e.total_counts() == 3591 * 8192),
    );
    check(
        "encoder 187 output turns",
        enc.is_some_and(|e| e.total_turns() == 187),
    );
    check(
        "encoder angle back at 0°",
        enc.is_some_and(|e| e.angle_deg() == 0.0),
    );

    // DJI packing: M3508 id 1 at 10 A = 8192 = 0x2000 in slot 0 of 0x200; M2006 id 6 at
    // -2.5 A = -2500 = 0xF63C in slot 1 of 0x1FF.
    let mut builder: BusBuilder<'static, 4> = BusBuilder::new();
    let registered = builder.register(&WHEEL).is_ok() && builder.register(&FEEDER).is_ok();
    check("register M3508 id 1 and M2006 id 6", registered);
    let bus = builder.build();
    let now = Instant::from_millis(1);
    for id in [0x201u16, 0x206] {
        if let Some(f) = CanFrame::standard(id, &[0, 0, 0, 0, 0, 0, 30, 0]) {
            bus.dispatch(&f, now);
        }
    }
    let targets = WHEEL.set_target_current(10.0).is_ok() && FEEDER.set_target_current(-2.5).is_ok();
    check("targets accepted", targets);
    let mut batch = TxBatch::new();
    bus.tick(now, 0.001, &mut batch);
    let frames = batch.frames();
    check(
        "0x200 carries 0x2000 in slot 0",
        frames
            .first()
            .is_some_and(|f| f.raw_id() == 0x200 && f.data() == [0x20, 0, 0, 0, 0, 0, 0, 0]),
    );
    check(
        "0x1FF carries 0xF63C in slot 1",
        frames
            .get(1)
            .is_some_and(|f| f.raw_id() == 0x1FF && f.data() == [0, 0, 0xF6, 0x3C, 0, 0, 0, 0]),
    );
    // Rounding to wire integers, half away from zero, saturating (SET_RPM carries eRPM as
    // is): 2.5 → 3, -2.5 → -3, 2.4999998 → 2, 0.49999997 → 0, 3·10⁹ → i32::MAX.
    let erpm = |v: f32| {
        VescCommand::Erpm(v)
            .to_frame(9)
            .and_then(|f| f.data().try_into().ok().map(i32::from_be_bytes))
    };
    check(
        "VESC eRPM rounds half away from zero",
        erpm(2.5) == Some(3) && erpm(-2.5) == Some(-3) && erpm(2.499_999_8) == Some(2),
    );
    check(
        "VESC eRPM 0.49999997 → 0, 3e9 saturates",
        erpm(0.499_999_97) == Some(0) && erpm(3.0e9) == Some(i32::MAX),
    );
    // C610: 1000 counts per amp; 0.5 mA is a tie, away from zero.
    check(
        "M2006 ±0.5 mA → ±1 count",
        FEEDER.command_to_raw(0.0005) == 1 && FEEDER.command_to_raw(-0.0005) == -1,
    );
    hprintln!("selftest: all passed");
    debug::exit(debug::EXIT_SUCCESS);
    loop {
        cortex_m::asm::wfi();
    }
}
