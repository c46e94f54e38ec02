//! Scenario files: a robot team's motors, gains, loads, target profiles and faults in TOML, so
//! gains can be tuned in simulation before touching hardware.
//!
//! ```toml
//! name = "yaw-tuning"
//! description = "GM6020 yaw with the gimbal's inertia"
//! duration_ms = 800
//! seed = 1
//!
//! [[motor]]
//! model = "gm6020-voltage"        # m3508 | m2006 | gm6020-voltage | gm6020-current
//! id = 1                          # ESC id
//! controller = "rc10"             # rc10 (default) | rc10lib (RC10_LIB's M3508 demo loop)
//! speed_pid = { kp = 0.8, ki = 20.0, kd = 0.0, output_limit = 20.0 }   # optional
//! angle_pid = { kp = 3.0, output_limit = 250.0 }                       # optional
//! angle_divider = 10                                                   # optional
//! load = { inertia_kg_m2 = 0.01, torque_nm = 0.0, step = { at_ms = 400, torque_nm = 0.5 } }
//! # torque_nm: against positive rotation whatever the motion (gravity); friction_nm = 0.05
//! # instead for a wheel's rolling resistance (it opposes the motion, whichever way)
//!
//! [[target]]
//! motor = 1                       # the first [[motor]] (1-based, in file order)
//! kind = "angle_deg"              # current | rpm | angle_deg | total_angle_deg
//! steps = [[10, 90.0]]            # [time in ms, value]
//!
//! [[fault]]
//! kind = "power_cut"  # power_cut | stall | over_temperature | frame_loss | corruption | delay | bus_off | rx_stall | no_ack | scheduler_stall
//! motor = 1
//! from_ms = 300
//! to_ms = 500
//! ```
//!
//! A mecanum chassis driven by a DR16 remote (motors 1–4 are FL, FR, RL, RR; the chassis sets
//! their speeds, so `[[target]]`s are for the other motors only: one on a wheel is refused):
//!
//! ```toml
//! [chassis]
//! wheelbase_m = 0.4
//! track_m = 0.36
//! wheel_radius_m = 0.076
//! rollers = "o"                       # o (default) | x
//! wheel_signs = [1, -1, 1, -1]        # motors on the right face the other way
//! max_twist = { vx_m_s = 2.0, vy_m_s = 2.0, omega_rad_s = 4.0 }     # full stick
//! max_accel = { vx_m_s = 4.0, vy_m_s = 4.0, omega_rad_s = 12.0 }
//! max_wheel_rpm = 400
//! sticks = [[0, 0, 0, 0, 0], [200, 0, 0, 0, 1.0]]   # [ms, right x, right y, left x, left y]
//! radio_off = [[3300, 3700]]          # windows without DBUS frames
//! ```
//!
//! The order in which the controller's 3 TX buffers send (optional; the STM32G4 FDCAN's TX
//! FIFO or TX queue mode, see [`TxOrder`]):
//!
//! ```toml
//! [bus]
//! tx_order = "fifo"   # fifo (default: oldest first, as rc10-stm32 sets it) | lowest-id-first
//! ```
//!
//! Unknown keys are errors, and every error names the entry and field at fault.

use crate::bus::TxOrder;
use crate::plant::Load;
use crate::scenario::{
    ChassisDrive, Controller, Fault, MotorSpec, Scenario, TargetKind, TargetSpec,
};
use rc10_core::bus::BusConfig;
use rc10_core::chassis::{LinearChassis, MecanumConfig, MecanumRollers, Twist};
use rc10_core::motor::dji::{DjiConfig, DjiModel};
use rc10_core::pid::PidConfig;
use serde::Deserialize;
use std::fmt;
use std::path::Path;

/// Why a scenario file could not be used.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FileError {
    /// The file could not be read.
    Io(String),
    /// The TOML is malformed or does not match the format (unknown key, wrong type, missing
    /// field); the message names the line and the key.
    Syntax(String),
    /// A value is well-formed but unusable; `field` says where (`motor[2].id`).
    Invalid {
        /// The entry and key at fault.
        field: String,
        /// What is wrong with it.
        problem: String,
    },
}

impl fmt::Display for FileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io(e) => write!(f, "cannot read scenario file: {e}"),
            Self::Syntax(e) => write!(f, "scenario file: {e}"),
            Self::Invalid { field, problem } => write!(f, "scenario file: {field}: {problem}"),
        }
    }
}

impl std::error::Error for FileError {}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileScenario {
    name: String,
    #[serde(default)]
    description: String,
    duration_ms: u64,
    #[serde(default = "one")]
    seed: u64,
    #[serde(default)]
    bitrate_bps: Option<u32>,
    #[serde(default, rename = "motor")]
    motors: Vec<FileMotor>,
    #[serde(default, rename = "target")]
    targets: Vec<FileTarget>,
    #[serde(default, rename = "fault")]
    faults: Vec<FileFault>,
    #[serde(default)]
    chassis: Option<FileChassis>,
    #[serde(default)]
    bus: FileBus,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileBus {
    #[serde(default)]
    tx_order: FileTxOrder,
}

#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
enum FileTxOrder {
    #[default]
    Fifo,
    LowestIdFirst,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileTwist {
    vx_m_s: f32,
    vy_m_s: f32,
    omega_rad_s: f32,
}

#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
enum FileRollers {
    #[default]
    O,
    X,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileChassis {
    wheelbase_m: f32,
    track_m: f32,
    wheel_radius_m: f32,
    #[serde(default)]
    rollers: FileRollers,
    #[serde(default = "unit_signs")]
    wheel_signs: [f32; 4],
    max_twist: FileTwist,
    max_accel: FileTwist,
    max_wheel_rpm: f32,
    sticks: Vec<(u64, f32, f32, f32, f32)>,
    #[serde(default)]
    radio_off: Vec<(u64, u64)>,
}

fn unit_signs() -> [f32; 4] {
    [1.0; 4]
}

fn one() -> u64 {
    1
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(rename_all = "kebab-case")]
enum FileModel {
    M3508,
    M2006,
    Gm6020Voltage,
    Gm6020Current,
}

#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
enum FileController {
    #[default]
    Rc10,
    Rc10lib,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct FilePid {
    kp: f32,
    #[serde(default)]
    ki: f32,
    #[serde(default)]
    kd: f32,
    #[serde(default)]
    output_limit: Option<f32>,
    #[serde(default)]
    integral_limit: Option<f32>,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileTorqueStep {
    at_ms: u64,
    torque_nm: f64,
}

#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileLoad {
    #[serde(default)]
    inertia_kg_m2: f64,
    #[serde(default)]
    torque_nm: f64,
    #[serde(default)]
    friction_nm: f64,
    #[serde(default)]
    step: Option<FileTorqueStep>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileMotor {
    model: FileModel,
    id: u8,
    #[serde(default)]
    controller: FileController,
    #[serde(default)]
    speed_pid: Option<FilePid>,
    #[serde(default)]
    angle_pid: Option<FilePid>,
    #[serde(default)]
    angle_divider: Option<u8>,
    #[serde(default)]
    load: FileLoad,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(rename_all = "snake_case")]
enum FileKind {
    Current,
    Rpm,
    AngleDeg,
    TotalAngleDeg,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileTarget {
    motor: usize,
    kind: FileKind,
    steps: Vec<(u64, f32)>,
}

#[derive(Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
enum FileFault {
    PowerCut {
        motor: usize,
        from_ms: u64,
        to_ms: u64,
    },
    Stall {
        motor: usize,
        from_ms: u64,
        to_ms: u64,
    },
    OverTemperature {
        motor: usize,
        at_ms: u64,
        celsius: f64,
    },
    FrameLoss {
        probability: f64,
        from_ms: u64,
        to_ms: u64,
    },
    Corruption {
        probability: f64,
        from_ms: u64,
        to_ms: u64,
    },
    Delay {
        delay_us: u64,
        from_ms: u64,
        to_ms: u64,
    },
    BusOff {
        from_ms: u64,
        to_ms: u64,
    },
    RxStall {
        from_ms: u64,
        to_ms: u64,
    },
    NoAck {
        from_ms: u64,
        to_ms: u64,
    },
    SchedulerStall {
        from_ms: u64,
        to_ms: u64,
    },
}

fn invalid(field: String, problem: impl Into<String>) -> FileError {
    FileError::Invalid {
        field,
        problem: problem.into(),
    }
}

/// Reads a scenario file.
pub fn load(path: &Path) -> Result<Scenario, FileError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| FileError::Io(format!("{}: {e}", path.display())))?;
    parse(&text)
}

/// The longest run a scenario may ask for, ms: a simulated day (times in µs stay far from
/// overflowing a u64).
pub const MAX_DURATION_MS: u64 = 86_400_000;

/// Parses scenario TOML.
pub fn parse(text: &str) -> Result<Scenario, FileError> {
    let file: FileScenario = toml::from_str(text).map_err(|e| FileError::Syntax(e.to_string()))?;
    if file.motors.is_empty() {
        return Err(invalid("motor".into(), "at least one [[motor]] is needed"));
    }
    if !(1..=MAX_DURATION_MS).contains(&file.duration_ms) {
        return Err(invalid(
            "duration_ms".into(),
            format!("must be 1 to {MAX_DURATION_MS} (a day)"),
        ));
    }
    let motor_count = file.motors.len();
    let motor_index = |field: String, motor: usize| {
        if (1..=motor_count).contains(&motor) {
            Ok(motor - 1)
        } else {
            Err(invalid(
                field,
                format!("no motor {motor}: the file has motors 1 to {motor_count}"),
            ))
        }
    };
    let motors = file
        .motors
        .iter()
        .enumerate()
        .map(|(i, m)| motor_spec(i + 1, m))
        .collect::<Result<Vec<_>, _>>()?;
    let mut targets = Vec::new();
    for (i, t) in file.targets.iter().enumerate() {
        let n = i + 1;
        let motor = motor_index(format!("target[{n}].motor"), t.motor)?;
        // (With fewer than four motors the chassis itself is refused below.)
        if file.chassis.is_some() && motor < 4 && motors.len() >= 4 {
            return Err(invalid(
                format!("target[{n}].motor"),
                format!(
                    "motor {} is a chassis wheel: the chassis sets its speed every tick",
                    motor + 1
                ),
            ));
        }
        if t.steps.windows(2).any(|w| matches!(w, [a, b] if b.0 < a.0)) {
            return Err(invalid(
                format!("target[{n}].steps"),
                "times must not decrease",
            ));
        }
        if let Some((_, v)) = t.steps.iter().find(|(_, v)| !v.is_finite()) {
            return Err(invalid(
                format!("target[{n}].steps"),
                format!("{v} is not a number"),
            ));
        }
        targets.push(TargetSpec {
            motor,
            kind: match t.kind {
                FileKind::Current => TargetKind::Current,
                FileKind::Rpm => TargetKind::Rpm,
                FileKind::AngleDeg => TargetKind::AngleDeg,
                FileKind::TotalAngleDeg => TargetKind::TotalAngleDeg,
            },
            steps: t.steps.clone(),
        });
    }
    let mut faults = Vec::new();
    for (i, f) in file.faults.iter().enumerate() {
        let n = i + 1;
        let window = |from: u64, to: u64| {
            if to > from {
                Ok(())
            } else {
                Err(invalid(
                    format!("fault[{n}].to_ms"),
                    "must be after from_ms",
                ))
            }
        };
        let probability = |p: f64| {
            if (0.0..=1.0).contains(&p) {
                Ok(p)
            } else {
                Err(invalid(
                    format!("fault[{n}].probability"),
                    "must be between 0 and 1",
                ))
            }
        };
        let field = format!("fault[{n}].motor");
        faults.push(match *f {
            FileFault::PowerCut {
                motor,
                from_ms,
                to_ms,
            } => {
                window(from_ms, to_ms)?;
                Fault::PowerCut {
                    motor: motor_index(field, motor)?,
                    from_ms,
                    to_ms,
                }
            }
            FileFault::Stall {
                motor,
                from_ms,
                to_ms,
            } => {
                window(from_ms, to_ms)?;
                Fault::Stall {
                    motor: motor_index(field, motor)?,
                    from_ms,
                    to_ms,
                }
            }
            FileFault::OverTemperature {
                motor,
                at_ms,
                celsius,
            } => {
                if !celsius.is_finite() {
                    return Err(invalid(field, "celsius must be a finite number"));
                }
                Fault::OverTemperature {
                    motor: motor_index(field, motor)?,
                    at_ms,
                    celsius,
                }
            }
            FileFault::FrameLoss {
                probability: p,
                from_ms,
                to_ms,
            } => {
                window(from_ms, to_ms)?;
                Fault::FrameLoss {
                    probability: probability(p)?,
                    from_ms,
                    to_ms,
                }
            }
            FileFault::Corruption {
                probability: p,
                from_ms,
                to_ms,
            } => {
                window(from_ms, to_ms)?;
                Fault::Corruption {
                    probability: probability(p)?,
                    from_ms,
                    to_ms,
                }
            }
            FileFault::Delay {
                delay_us,
                from_ms,
                to_ms,
            } => {
                window(from_ms, to_ms)?;
                if delay_us > 10_000_000 {
                    return Err(invalid(field, "delay_us must be at most 10 s"));
                }
                Fault::Delay {
                    delay_us,
                    from_ms,
                    to_ms,
                }
            }
            FileFault::BusOff { from_ms, to_ms } => {
                window(from_ms, to_ms)?;
                Fault::BusOff { from_ms, to_ms }
            }
            FileFault::RxStall { from_ms, to_ms } => {
                window(from_ms, to_ms)?;
                Fault::RxStall { from_ms, to_ms }
            }
            FileFault::NoAck { from_ms, to_ms } => {
                window(from_ms, to_ms)?;
                Fault::NoAck { from_ms, to_ms }
            }
            FileFault::SchedulerStall { from_ms, to_ms } => {
                window(from_ms, to_ms)?;
                Fault::SchedulerStall { from_ms, to_ms }
            }
        });
    }
    let chassis = match &file.chassis {
        Some(c) => Some(chassis_drive(c, motor_count)?),
        None => None,
    };
    let mut bus = BusConfig::DEFAULT;
    if let Some(b) = file.bitrate_bps {
        if b == 0 {
            return Err(invalid("bitrate_bps".into(), "must be positive"));
        }
        bus.bitrate_bps = b;
    }
    Ok(Scenario {
        name: file.name,
        description: file.description,
        duration_ms: file.duration_ms,
        seed: file.seed,
        motors,
        targets,
        faults,
        bus,
        tx_order: match file.bus.tx_order {
            FileTxOrder::Fifo => TxOrder::Fifo,
            FileTxOrder::LowestIdFirst => TxOrder::LowestIdFirst,
        },
        chassis,
    })
}

fn chassis_drive(c: &FileChassis, motor_count: usize) -> Result<ChassisDrive, FileError> {
    if motor_count < 4 {
        return Err(invalid(
            "chassis".into(),
            format!("a chassis drives motors 1-4 (FL, FR, RL, RR); the file has {motor_count}"),
        ));
    }
    let geometry = MecanumConfig::new(c.wheelbase_m, c.track_m, c.wheel_radius_m)
        .with_rollers(match c.rollers {
            FileRollers::O => MecanumRollers::O,
            FileRollers::X => MecanumRollers::X,
        })
        .with_wheel_signs(c.wheel_signs);
    LinearChassis::mecanum(geometry).map_err(|e| invalid("chassis".into(), e.to_string()))?;
    let twist = |t: FileTwist| Twist::new(t.vx_m_s, t.vy_m_s, t.omega_rad_s);
    if c.sticks
        .windows(2)
        .any(|w| matches!(w, [a, b] if b.0 < a.0))
    {
        return Err(invalid("chassis.sticks".into(), "times must not decrease"));
    }
    let mut sticks = Vec::new();
    for (i, &(t, rx, ry, lx, ly)) in c.sticks.iter().enumerate() {
        let values = [rx, ry, lx, ly];
        if values.iter().any(|v| !(-1.0..=1.0).contains(v)) {
            return Err(invalid(
                format!("chassis.sticks[{}]", i + 1),
                "stick positions must be within -1..1",
            ));
        }
        sticks.push((t, values));
    }
    if c.radio_off.iter().any(|(from, to)| to <= from) {
        return Err(invalid(
            "chassis.radio_off".into(),
            "each window must end after it starts",
        ));
    }
    if !(c.max_wheel_rpm.is_finite() && c.max_wheel_rpm > 0.0) {
        return Err(invalid("chassis.max_wheel_rpm".into(), "must be positive"));
    }
    Ok(ChassisDrive {
        geometry,
        max_twist: twist(c.max_twist),
        max_accel: twist(c.max_accel),
        max_wheel_rpm: c.max_wheel_rpm,
        sticks,
        radio_off: c.radio_off.clone(),
    })
}

fn pid_config(field: String, pid: &FilePid, default_limit: f32) -> Result<PidConfig, FileError> {
    let mut c = PidConfig::new(pid.kp, pid.ki, pid.kd)
        .with_output_limit(pid.output_limit.unwrap_or(default_limit));
    if let Some(l) = pid.integral_limit {
        c = c.with_integral_limit(l);
    }
    c.validate().map_err(|e| invalid(field, e.to_string()))?;
    Ok(c)
}

fn motor_spec(n: usize, m: &FileMotor) -> Result<MotorSpec, FileError> {
    let model = match m.model {
        FileModel::M3508 => DjiModel::M3508,
        FileModel::M2006 => DjiModel::M2006,
        FileModel::Gm6020Voltage => DjiModel::Gm6020Voltage,
        FileModel::Gm6020Current => DjiModel::Gm6020Current,
    };
    if model.command_slot(m.id).is_none() {
        return Err(invalid(
            format!("motor[{n}].id"),
            format!(
                "{} is not an ESC id of this model (1 to {})",
                m.id,
                model.max_id()
            ),
        ));
    }
    let l = m.load;
    let step_ok = l
        .step
        .is_none_or(|s| s.torque_nm.is_finite() && s.at_ms <= MAX_DURATION_MS);
    if !(l.inertia_kg_m2.is_finite()
        && l.inertia_kg_m2 >= 0.0
        && l.torque_nm.is_finite()
        && l.friction_nm.is_finite()
        && l.friction_nm >= 0.0
        && step_ok)
    {
        return Err(invalid(
            format!("motor[{n}].load"),
            "inertia and friction must be ≥ 0, torques finite and the step within a day",
        ));
    }
    let load = Load {
        inertia_kg_m2: l.inertia_kg_m2,
        torque_nm: l.torque_nm,
        friction_nm: l.friction_nm,
        step: l.step.map(|s| (s.at_ms * 1000, s.torque_nm)),
    };
    let tuned = m.speed_pid.is_some() || m.angle_pid.is_some() || m.angle_divider.is_some();
    let controller = match m.controller {
        FileController::Rc10lib => {
            if model != DjiModel::M3508 {
                return Err(invalid(
                    format!("motor[{n}].controller"),
                    "rc10lib (RC10_LIB's demo loop) exists for the m3508 only",
                ));
            }
            if tuned {
                return Err(invalid(
                    format!("motor[{n}].controller"),
                    "rc10lib uses RC10_LIB's fixed gains: remove speed_pid/angle_pid/angle_divider",
                ));
            }
            Controller::Rc10Legacy
        }
        FileController::Rc10 if !tuned => Controller::Rc10,
        FileController::Rc10 => {
            let mut cfg = DjiConfig::default_for(model);
            if let Some(p) = &m.speed_pid {
                cfg.cascade.speed =
                    pid_config(format!("motor[{n}].speed_pid"), p, model.max_command())?;
            }
            if let Some(p) = &m.angle_pid {
                cfg.cascade.angle = pid_config(format!("motor[{n}].angle_pid"), p, f32::INFINITY)?;
            }
            if let Some(d) = m.angle_divider {
                cfg.cascade.angle_divider = d;
            }
            Controller::Rc10With(cfg)
        }
    };
    Ok(MotorSpec {
        model,
        esc_id: m.id,
        load,
        controller,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = r#"
        name = "t"
        duration_ms = 100
        [[motor]]
        model = "m3508"
        id = 1
        [[target]]
        motor = 1
        kind = "rpm"
        steps = [[0, 100.0]]
    "#;

    /// The minimal file with one `[[fault]]` table of these lines.
    fn with_fault(lines: &str) -> String {
        format!("{MINIMAL}\n[[fault]]\n{lines}\n")
    }

    #[test]
    fn minimal_file_parses_with_defaults() {
        let s = parse(MINIMAL).unwrap();
        assert_eq!(s.seed, 1);
        assert_eq!(s.motors[0].controller, Controller::Rc10);
        assert_eq!(s.targets[0].motor, 0);
        assert_eq!(s.bus, BusConfig::DEFAULT);
        assert_eq!(s.tx_order, TxOrder::Fifo);
    }

    #[test]
    fn bus_tx_order_parses() {
        for (value, order) in [
            ("fifo", TxOrder::Fifo),
            ("lowest-id-first", TxOrder::LowestIdFirst),
        ] {
            let text = format!("{MINIMAL}\n[bus]\ntx_order = \"{value}\"\n");
            assert_eq!(parse(&text).unwrap().tx_order, order, "{value}");
        }
        let empty = format!("{MINIMAL}\n[bus]\n");
        assert_eq!(parse(&empty).unwrap().tx_order, TxOrder::Fifo);
    }

    #[test]
    fn unknown_tx_order_lists_the_known_ones() {
        let text = format!("{MINIMAL}\n[bus]\ntx_order = \"lifo\"\n");
        let e = parse(&text).unwrap_err();
        assert!(matches!(e, FileError::Syntax(_)), "{e:?}");
        let e = e.to_string();
        assert!(
            e.contains("tx_order") && e.contains("lifo") && e.contains("lowest-id-first"),
            "{e}"
        );
        let unknown_key = format!("{MINIMAL}\n[bus]\ntx_mode = \"fifo\"\n");
        let e = parse(&unknown_key).unwrap_err().to_string();
        assert!(e.contains("tx_mode"), "{e}");
    }

    #[test]
    fn no_ack_and_scheduler_stall_faults_parse() {
        let text = format!(
            "{MINIMAL}\n[[fault]]\nkind = \"no_ack\"\nfrom_ms = 10\nto_ms = 20\n\
             [[fault]]\nkind = \"scheduler_stall\"\nfrom_ms = 30\nto_ms = 35\n"
        );
        assert_eq!(
            parse(&text).unwrap().faults,
            vec![
                Fault::NoAck {
                    from_ms: 10,
                    to_ms: 20
                },
                Fault::SchedulerStall {
                    from_ms: 30,
                    to_ms: 35
                }
            ]
        );
    }

    #[test]
    fn unknown_key_is_named() {
        let text = MINIMAL.replace("id = 1", "id = 1\nkpp = 3");
        let e = parse(&text).unwrap_err().to_string();
        assert!(e.contains("kpp"), "{e}");
    }

    #[test]
    fn unknown_model_lists_the_known_ones() {
        let text = MINIMAL.replace("\"m3508\"", "\"m3509\"");
        let e = parse(&text).unwrap_err().to_string();
        assert!(e.contains("m3509") && e.contains("gm6020-voltage"), "{e}");
    }

    #[test]
    fn bad_values_name_the_field() {
        let bad_id = MINIMAL.replace("id = 1", "id = 9");
        assert_eq!(
            parse(&bad_id).unwrap_err(),
            FileError::Invalid {
                field: "motor[1].id".into(),
                problem: "9 is not an ESC id of this model (1 to 8)".into()
            }
        );
        let bad_target = MINIMAL.replace("motor = 1", "motor = 2");
        assert!(matches!(
            parse(&bad_target).unwrap_err(),
            FileError::Invalid { field, .. } if field == "target[1].motor"
        ));
        let bad_gain = MINIMAL.replace(
            "id = 1",
            "id = 1\nspeed_pid = { kp = 0.5, output_limit = -1.0 }",
        );
        assert!(matches!(
            parse(&bad_gain).unwrap_err(),
            FileError::Invalid { field, .. } if field == "motor[1].speed_pid"
        ));
        let bad_fault =
            with_fault("kind = \"frame_loss\"\nprobability = 1.5\nfrom_ms = 0\nto_ms = 10");
        assert!(matches!(
            parse(&bad_fault).unwrap_err(),
            FileError::Invalid { field, .. } if field == "fault[1].probability"
        ));
        // TOML has `nan` and `inf`: a NaN temperature or torque would fill the trace with NaN.
        let nan_heat =
            with_fault("kind = \"over_temperature\"\nmotor = 1\nat_ms = 5\ncelsius = nan");
        assert!(matches!(
            parse(&nan_heat).unwrap_err(),
            FileError::Invalid { field, .. } if field.starts_with("fault[1]")
        ));
        let nan_step = MINIMAL.replace(
            "id = 1",
            "id = 1\nload = { step = { at_ms = 5, torque_nm = inf } }",
        );
        assert!(matches!(
            parse(&nan_step).unwrap_err(),
            FileError::Invalid { field, .. } if field == "motor[1].load"
        ));
        // Friction that pushes (negative) or is not a number.
        for friction in ["-0.1", "nan"] {
            let text = MINIMAL.replace(
                "id = 1",
                &format!("id = 1\nload = {{ friction_nm = {friction} }}"),
            );
            assert!(matches!(
                parse(&text).unwrap_err(),
                FileError::Invalid { field, .. } if field == "motor[1].load"
            ));
        }
        // A delay past every clock (it wrapped to the past) and a run too long to time in µs.
        let huge_delay = with_fault(
            "kind = \"delay\"\ndelay_us = 18446744073709551615\nfrom_ms = 0\nto_ms = 10",
        );
        assert!(matches!(
            parse(&huge_delay).unwrap_err(),
            FileError::Invalid { field, .. } if field.starts_with("fault[1]")
        ));
        let forever = MINIMAL.replace("duration_ms = 100", "duration_ms = 86400001");
        assert!(matches!(
            parse(&forever).unwrap_err(),
            FileError::Invalid { field, .. } if field == "duration_ms"
        ));
    }

    #[test]
    fn chassis_table_parses_and_needs_four_motors() {
        let chassis = r#"
            [chassis]
            wheelbase_m = 0.4
            track_m = 0.36
            wheel_radius_m = 0.076
            wheel_signs = [1, -1, 1, -1]
            max_twist = { vx_m_s = 2.0, vy_m_s = 2.0, omega_rad_s = 4.0 }
            max_accel = { vx_m_s = 4.0, vy_m_s = 4.0, omega_rad_s = 12.0 }
            max_wheel_rpm = 400
            sticks = [[0, 0, 0, 0, 0], [100, 0, 0, 0, 1.0]]
            radio_off = [[300, 400]]
        "#;
        let one_motor = format!("{MINIMAL}{chassis}");
        assert!(matches!(
            parse(&one_motor).unwrap_err(),
            FileError::Invalid { field, .. } if field == "chassis"
        ));
        let motors: String = (1..=4)
            .map(|id| format!("[[motor]]\nmodel = \"m3508\"\nid = {id}\n"))
            .collect();
        let text = format!("name = \"c\"\nduration_ms = 500\n{motors}{chassis}");
        let s = parse(&text).unwrap();
        let drive = s.chassis.unwrap();
        assert_eq!(drive.sticks[1], (100, [0.0, 0.0, 0.0, 1.0]));
        assert_eq!(drive.radio_off, vec![(300, 400)]);
        // A target on a wheel would be overwritten by the chassis at every tick.
        let on_wheel =
            format!("{text}[[target]]\nmotor = 2\nkind = \"rpm\"\nsteps = [[0, 100.0]]\n");
        assert!(matches!(
            parse(&on_wheel).unwrap_err(),
            FileError::Invalid { field, problem } if field == "target[1].motor" && problem.contains("motor 2 is a chassis wheel")
        ));
        let bad = text.replace("1.0]]", "1.5]]");
        assert!(matches!(
            parse(&bad).unwrap_err(),
            FileError::Invalid { field, .. } if field == "chassis.sticks[2]"
        ));
    }

    #[test]
    fn gains_and_loads_are_applied() {
        let text = MINIMAL.replace(
            "id = 1",
            "id = 1\nspeed_pid = { kp = 0.5, ki = 4.0 }\nangle_divider = 5\nload = { inertia_kg_m2 = 0.02, friction_nm = 0.05, step = { at_ms = 50, torque_nm = 1.0 } }",
        );
        let s = parse(&text).unwrap();
        let Controller::Rc10With(cfg) = s.motors[0].controller else {
            panic!("expected tuned gains");
        };
        assert_eq!(cfg.cascade.speed.kp, 0.5);
        assert_eq!(cfg.cascade.speed.output_limit, 20.0); // the ESC's range by default
        assert_eq!(cfg.cascade.angle_divider, 5);
        assert_eq!(s.motors[0].load.step, Some((50_000, 1.0)));
        assert_eq!(s.motors[0].load.friction_nm, 0.05);
    }
}
