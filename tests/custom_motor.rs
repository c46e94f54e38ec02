//! A motor written outside rc10 (RC10_LIB manual, "如果你想拓展电机？": `MyMotor`), plugged into
//! the same bus as a DJI motor. This is the whole recipe: implement `CanNode` (what the
//! scheduler and receiver call) and `Motor` (what your application calls), keep the mutable
//! state behind one blocking mutex, register it.
//!
//! MyMotor's (made-up) protocol: command on 0x300 + id, DLC 2, int16 big-endian milliamps;
//! feedback on 0x380 + id, DLC 4: rotor rpm (i16 BE), current in mA (i16 BE); gear 27:1.

// Test code: a failed setup or assertion should stop the test.
#![allow(clippy::unwrap_used, clippy::panic)]

use core::cell::RefCell;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use rc10_core::bus::{BusBuilder, Dispatch};
use rc10_core::can::{CanFrame, IdFilter};
use rc10_core::encoder::GearRatio;
use rc10_core::math::saturate;
use rc10_core::motor::dji::DjiMotor;
use rc10_core::motor::{ControlMode, HealthConfig, Liveness, Motor, MotorState, TargetError};
use rc10_core::node::{BusUsage, CanNode, FrameError, TxBatch};
use rc10_core::pid::{IncrementalPid, IncrementalPidConfig};
use rc10_core::time::Instant;

const GEAR: GearRatio = match GearRatio::new(27, 1) {
    Some(g) => g,
    None => panic!("gear"),
};
const MAX_AMPS: f32 = 8.0;

#[derive(Debug)]
struct MyState {
    mode: ControlMode,
    target: f32,
    speed_rpm: f32,
    current_amps: f32,
    liveness: Liveness,
    command_amps: f32,
    speed_pid: IncrementalPid,
}

struct MyMotor {
    id: u8,
    health: HealthConfig,
    state: Mutex<CriticalSectionRawMutex, RefCell<MyState>>,
}

impl MyMotor {
    const fn new(id: u8) -> Self {
        let pid = match IncrementalPid::new(
            IncrementalPidConfig::new(0.05, 2.0, 0.0).with_output_limit(MAX_AMPS),
        ) {
            Ok(p) => p,
            Err(_) => panic!("gains"),
        };
        Self {
            id,
            health: HealthConfig::DEFAULT,
            state: Mutex::new(RefCell::new(MyState {
                mode: ControlMode::Disabled,
                target: 0.0,
                speed_rpm: 0.0,
                current_amps: 0.0,
                liveness: Liveness::NEW,
                command_amps: 0.0,
                speed_pid: pid,
            })),
        }
    }

    fn set(&self, mode: ControlMode, target: f32) -> Result<(), TargetError> {
        if !target.is_finite() {
            return Err(TargetError::NotFinite);
        }
        self.state.lock(|s| {
            let mut s = s.borrow_mut();
            if s.mode != mode {
                s.speed_pid.reset();
            }
            s.mode = mode;
            s.target = target;
        });
        Ok(())
    }
}

impl CanNode for MyMotor {
    fn bus_usage(&self) -> BusUsage {
        // Every ID it listens on and every ID it sends on: the bus checks them against all
        // other nodes (and an STM32 adapter builds its acceptance filters from them).
        let id = u16::from(self.id);
        BusUsage::NONE
            .listening(IdFilter::standard(0x380 + id), 1000)
            .sending(IdFilter::standard(0x300 + id), 1)
    }

    fn update_feedback(&self, frame: &CanFrame, now: Instant) -> Result<(), FrameError> {
        let [r0, r1, c0, c1] = *frame.data() else {
            return Err(FrameError::WrongLength {
                dlc: frame.dlc() as u8,
            });
        };
        self.state.lock(|s| {
            let mut s = s.borrow_mut();
            s.speed_rpm = f32::from(i16::from_be_bytes([r0, r1])) / GEAR.as_f32();
            s.current_amps = f32::from(i16::from_be_bytes([c0, c1])) / 1000.0;
            s.liveness.record_feedback(now);
        });
        Ok(())
    }

    fn update(&self, now: Instant, dt_s: f32) {
        self.state.lock(|s| {
            let mut s = s.borrow_mut();
            s.liveness.check(&self.health, now);
            s.command_amps = if !s.liveness.is_online() {
                0.0
            } else {
                match s.mode {
                    ControlMode::Current => saturate(s.target, MAX_AMPS),
                    ControlMode::Speed => {
                        let (target, rpm) = (s.target, s.speed_rpm);
                        s.speed_pid.update(target, rpm, dt_s).output
                    }
                    _ => 0.0,
                }
            };
        });
    }

    fn pack_command(&self, out: &mut TxBatch) {
        let amps = self.state.lock(|s| s.borrow().command_amps);
        let milliamps = (amps * 1000.0).round() as i16; // `as` saturates: no wrap
        let frame = CanFrame::standard(0x300 + u16::from(self.id), &milliamps.to_be_bytes());
        if let Some(f) = frame {
            let _ = out.push(f);
        }
    }
}

impl Motor for MyMotor {
    fn set_target_current(&self, amps: f32) -> Result<(), TargetError> {
        self.set(ControlMode::Current, amps)
    }
    fn set_target_rpm(&self, rpm: f32) -> Result<(), TargetError> {
        self.set(ControlMode::Speed, rpm)
    }
    fn set_target_angle_deg(&self, _angle_deg: f32) -> Result<(), TargetError> {
        Err(TargetError::Unsupported)
    }
    fn set_target_total_angle_deg(&self, _angle_deg: f32) -> Result<(), TargetError> {
        Err(TargetError::Unsupported)
    }
    fn disable(&self) {
        let _ = self.set(ControlMode::Disabled, 0.0);
    }
    fn state(&self) -> MotorState {
        self.state.lock(|s| {
            let s = s.borrow();
            MotorState {
                online: s.liveness.is_online(),
                mode: s.mode,
                target: s.target,
                speed_rpm: s.speed_rpm,
                current_amps: Some(s.current_amps),
                command: s.command_amps,
                last_feedback: s.liveness.last_feedback(),
                offline_events: s.liveness.offline_events(),
                ..MotorState::default()
            }
        })
    }
    fn gear_ratio(&self) -> GearRatio {
        GEAR
    }
}

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
