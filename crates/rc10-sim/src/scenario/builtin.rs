//! The built-in scenarios (`rc10-sim list`).

use super::{ChassisDrive, Controller, Fault, MotorSpec, Scenario, TargetKind, TargetSpec};
use crate::bus::TxOrder;
use crate::plant::Load;
use rc10_core::bus::BusConfig;
use rc10_core::chassis::{MecanumConfig, Twist};
use rc10_core::motor::dji::DjiModel;

fn m3508(esc_id: u8, controller: Controller) -> MotorSpec {
    MotorSpec {
        model: DjiModel::M3508,
        esc_id,
        load: Load::default(),
        controller,
    }
}

/// The built-in scenario called `name`, if there is one.
pub fn builtin_named(name: &str) -> Option<Scenario> {
    builtin().into_iter().find(|s| s.name == name)
}

/// The built-in scenarios, the first being the default.
pub fn builtin() -> Vec<Scenario> {
    let base = |name: &str, description: &str, duration_ms: u64| Scenario {
        name: name.into(),
        description: description.into(),
        duration_ms,
        seed: 1,
        motors: Vec::new(),
        targets: Vec::new(),
        faults: Vec::new(),
        bus: BusConfig::DEFAULT,
        tx_order: TxOrder::Fifo,
        chassis: None,
    };
    // The speed loop holds 0 rpm from the start and steps to 300 rpm at 10 ms: a step of a
    // loop already closed (RC10_LIB's incremental PID answers a step on its very first call
    // with the integral alone; see `legacy`).
    let speed_step = |motor| TargetSpec {
        motor,
        kind: TargetKind::Rpm,
        steps: vec![(0, 0.0), (10, 300.0)],
    };
    vec![
        Scenario {
            motors: vec![m3508(1, Controller::Rc10)],
            targets: vec![speed_step(0)],
            ..base(
                "m3508-speed-step",
                "unloaded M3508, speed step 0 -> 300 rpm with rc10's default gains",
                400,
            )
        },
        Scenario {
            motors: vec![m3508(1, Controller::Rc10Legacy)],
            targets: vec![speed_step(0)],
            ..base(
                "m3508-speed-step-rc10lib",
                "the same step with RC10_LIB's demo speed loop, for comparison (3 s: it is slow)",
                3000,
            )
        },
        Scenario {
            motors: vec![MotorSpec {
                model: DjiModel::M2006,
                ..m3508(1, Controller::Rc10)
            }],
            targets: vec![speed_step(0)],
            ..base(
                "m2006-speed-step",
                "unloaded M2006, speed step 0 -> 300 rpm with rc10's default gains",
                400,
            )
        },
        Scenario {
            motors: vec![m3508(1, Controller::Rc10)],
            targets: vec![TargetSpec {
                motor: 0,
                kind: TargetKind::AngleDeg,
                steps: vec![(10, 350.0)],
            }],
            ..base(
                "m3508-angle-step",
                "M3508 angle step 0 -> 350 deg: the short way is 10 deg backwards",
                600,
            )
        },
        Scenario {
            motors: vec![MotorSpec {
                model: DjiModel::Gm6020Voltage,
                esc_id: 1,
                load: Load {
                    inertia_kg_m2: 0.01,
                    step: Some((400_000, 0.5)),
                    ..Load::default()
                },
                controller: Controller::Rc10,
            }],
            targets: vec![TargetSpec {
                motor: 0,
                kind: TargetKind::AngleDeg,
                steps: vec![(10, 90.0)],
            }],
            ..base(
                "gm6020-gimbal",
                "GM6020 gimbal (0.01 kg m^2) to 90 deg, then a 0.5 N m load torque step at 400 ms",
                800,
            )
        },
        Scenario {
            motors: (1..=4)
                .map(|id| MotorSpec {
                    load: Load {
                        inertia_kg_m2: 0.02,
                        ..Load::default()
                    },
                    ..m3508(id, Controller::Rc10)
                })
                .collect(),
            targets: (0..4)
                .map(|m| TargetSpec {
                    motor: m,
                    kind: TargetKind::Rpm,
                    steps: vec![(10, if m % 2 == 0 { 250.0 } else { -250.0 })],
                })
                .collect(),
            ..base(
                "chassis-4x-m3508",
                "four M3508 wheels (0.02 kg m^2 each) on one bus, +/-250 rpm",
                1000,
            )
        },
        Scenario {
            motors: vec![m3508(1, Controller::Rc10), m3508(2, Controller::Rc10)],
            targets: vec![
                TargetSpec {
                    motor: 0,
                    kind: TargetKind::Rpm,
                    steps: vec![(10, 200.0)],
                },
                TargetSpec {
                    motor: 1,
                    kind: TargetKind::Rpm,
                    steps: vec![(10, 200.0)],
                },
            ],
            faults: vec![
                Fault::PowerCut {
                    motor: 0,
                    from_ms: 300,
                    to_ms: 500,
                },
                Fault::FrameLoss {
                    probability: 0.05,
                    from_ms: 0,
                    to_ms: 1000,
                },
                Fault::Corruption {
                    probability: 0.01,
                    from_ms: 0,
                    to_ms: 1000,
                },
            ],
            ..base(
                "fault-power-cut",
                "two M3508 at 200 rpm; motor 1 loses power 300-500 ms; 5 % frame loss, 1 % corruption",
                1000,
            )
        },
        chassis_remote_drive(base(
            "chassis-remote-drive",
            "a DR16 drives a 16 kg mecanum chassis: forward, strafe, spin, diagonal, radio loss",
            4400,
        )),
        super::soak::fault_soak(),
    ]
}

/// A 16 kg RoboMaster-style mecanum chassis driven through a stick profile, with a radio loss.
fn chassis_remote_drive(base: Scenario) -> Scenario {
    // Each 76 mm wheel carries a quarter of 16 kg: 4 kg · 0.076² = 0.0231 kg·m² at its shaft,
    // and 0.05 N·m of rolling resistance (friction: it opposes the wheel's motion).
    let wheel = |id| MotorSpec {
        load: Load {
            inertia_kg_m2: 0.0231,
            friction_nm: 0.05,
            ..Load::default()
        },
        ..m3508(id, Controller::Rc10)
    };
    Scenario {
        motors: (1..=4).map(wheel).collect(),
        chassis: Some(ChassisDrive {
            geometry: MecanumConfig::new(0.4, 0.36, 0.076).with_wheel_signs([1.0, -1.0, 1.0, -1.0]),
            max_twist: Twist::new(2.0, 2.0, 4.0),
            max_accel: Twist::new(4.0, 4.0, 12.0),
            max_wheel_rpm: 400.0,
            sticks: vec![
                (0, [0.0; 4]),
                (200, [0.0, 0.0, 0.0, 1.0]),   // full forward
                (1000, [0.0, 0.0, -1.0, 0.0]), // strafe left
                (1800, [-0.5, 0.0, 0.0, 0.0]), // spin left at half stick
                (2600, [0.0, 0.0, -0.7, 0.7]), // diagonal forward-left
                (3600, [0.0; 4]),              // pilot lets go while the radio is off
            ],
            radio_off: vec![(3300, 3700)],
        }),
        ..base
    }
}
