//! A motor written outside rc10 (RC10_LIB manual, "如果你想拓展电机？": `MyMotor`), plugged into
//! the same bus as a DJI motor. This is the whole recipe: implement `CanNode` (what the
//! scheduler and receiver call) and `Motor` (what your application calls), keep the mutable
//! state behind one blocking mutex, register it.
//!
//! MyMotor's (made-up) protocol: command on 0x300 + id, DLC 2, int16 big-endian milliamps;
//! feedback on 0x380 + id, DLC 4: rotor rpm (i16 BE), current in mA (i16 BE); gear 27:1. Its
//! code is the firmware example's (`examples/stm32g474/src/my_motor.rs`): what runs on the
//! board is what is tested here.

// Test code: a failed setup or assertion should stop the test.
#![allow(clippy::unwrap_used, clippy::panic)]

#[path = "../examples/stm32g474/src/my_motor.rs"]
mod my_motor;

use my_motor::MyMotor;
use rc10_core::bus::{BusBuilder, Dispatch};
use rc10_core::can::CanFrame;
use rc10_core::motor::Motor;
use rc10_core::motor::dji::DjiMotor;
use rc10_core::node::TxBatch;
use rc10_core::time::Instant;

static MY: MyMotor = MyMotor::new(3);
static DJI: DjiMotor = match DjiMotor::m3508(1) {
    Ok(m) => m,
    Err(_) => panic!("id"),
};

#[test]
fn user_motor_shares_the_bus_with_a_dji_motor() {
    let mut builder = BusBuilder::<4>::new();
    builder.register(&DJI).unwrap();
    builder.register(&MY).unwrap();
    let bus = builder.build();
    let t0 = Instant::from_millis(5);

    // Feedback: MyMotor at 270 rotor rpm (10 rpm output), 1.5 A; the DJI motor at rest.
    let my_fb = CanFrame::standard(0x383, &[0x01, 0x0E, 0x05, 0xDC]).unwrap();
    assert_eq!(bus.dispatch(&my_fb, t0), Dispatch::Handled(1));
    let dji_fb = CanFrame::standard(0x201, &[0, 0, 0, 0, 0, 0, 30, 0]).unwrap();
    assert_eq!(bus.dispatch(&dji_fb, t0), Dispatch::Handled(0));
    assert!((MY.speed_rpm() - 10.0).abs() < 1e-5);
    assert!((MY.current_amps().unwrap() - 1.5).abs() < 1e-6);

    // Commands through the trait objects the application would hold.
    let motors: [&dyn Motor; 2] = [&DJI, &MY];
    motors[0].set_target_current(2.0).unwrap();
    motors[1].set_target_current(-1.25).unwrap();
    let mut batch = TxBatch::new();
    bus.tick(t0, 0.001, &mut batch);
    let frames: Vec<(u32, Vec<u8>)> = batch
        .frames()
        .iter()
        .map(|f| (f.raw_id(), f.data().to_vec()))
        .collect();
    // DJI 2 A = 1638.4 → 1638 = 0x0666 in slot 0 of 0x200; MyMotor -1250 mA = 0xFB1E on 0x303.
    assert_eq!(
        frames,
        vec![
            (0x200, vec![0x06, 0x66, 0, 0, 0, 0, 0, 0]),
            (0x303, vec![0xFB, 0x1E]),
        ]
    );

    assert!(MY.is_online());
    // The user motor's speed loop runs in update(): below target → positive current.
    MY.set_target_rpm(50.0).unwrap();
    bus.tick(t0, 0.001, &mut batch);
    assert!(MY.state().command > 0.0);
    // A frame of the wrong length is rejected and counted, not parsed.
    let short = CanFrame::standard(0x383, &[1, 2]).unwrap();
    assert!(matches!(bus.dispatch(&short, t0), Dispatch::Rejected(1, _)));
    assert_eq!(bus.stats().snapshot().rx_rejected, 1);
    // Silence beyond the timeout: offline, zero command, like rc10's own drivers.
    let later = Instant::from_millis(500);
    bus.tick(later, 0.001, &mut batch);
    assert!(!MY.is_online());
    assert_eq!(MY.state().offline_events, 1);
    let mine = batch.frames().iter().find(|f| f.raw_id() == 0x303).unwrap();
    assert_eq!(mine.data(), &[0, 0]);
}
