//! Physical models of DJI ESC + motor pairs at the CAN-frame level: they read command frames,
//! integrate rigid-body dynamics, and send feedback frames as the real ESC does (1 kHz,
//! quantised angle, integer rpm, temperature).
//!
//! All quantities are SI at the **output shaft** unless named `rotor`. Parameters come from
//! SPEC.md's protocol facts (DJI user guides); "derived" marks values computed from them.
//!
//! Current-controlled ESCs (C620, C610, GM6020 current mode) regulate the commanded current
//! through a first-order lag, but can only push as much as the supply voltage allows against
//! back-EMF: the motor's published torque–speed line `T ≤ (n_0 − n) / gradient` caps the
//! current in the direction of motion, its end `n_0` placed so that the motor spinning freely
//! at full command settles at its published no-load speed (friction included). The GM6020 in
//! voltage mode is a DC-motor model `L di/dt = V − R i − ke ω` whose `R` is derived from the
//! published speed/torque gradient. Past its over-temperature cut (the GM6020 at 125 °C) an
//! ESC turns its output off and keeps reporting.

use rc10_core::can::CanFrame;
use rc10_core::motor::dji::DjiModel;
use std::f64::consts::TAU;

/// How the ESC turns its command into current.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Drive {
    /// The ESC runs a current loop (C620, C610, GM6020 current mode).
    CurrentLoop {
        /// Amps per raw command count.
        amps_per_raw: f64,
        /// The ESC's current limit in amps.
        limit_amps: f64,
        /// Time constant of the current loop in seconds.
        tau_s: f64,
        /// Output speed in rpm at which the motor, at the rated supply, makes no torque: the
        /// torque–speed line's end, above the published no-load speed by the friction at that
        /// speed times the gradient (the published figure is measured spinning freely,
        /// friction included; see [`zero_torque_rpm`]).
        zero_torque_rpm: f64,
        /// Output speed drop per N·m of load, rpm/(N·m).
        gradient_rpm_per_nm: f64,
    },
    /// The command is a voltage (GM6020 voltage mode).
    Voltage {
        /// Volts per raw command count.
        volts_per_raw: f64,
        /// Largest raw command the motor accepts.
        raw_limit: f64,
        /// Effective winding resistance in ohms.
        resistance_ohm: f64,
        /// Winding inductance in henries.
        inductance_h: f64,
        /// Back-EMF constant, volts per output rad/s.
        ke_v_s_per_rad: f64,
    },
}

/// Parameters of one ESC + motor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorParams {
    /// Which DJI model (IDs, frame layout).
    pub model: DjiModel,
    /// Rotor turns per output turn.
    pub gear_ratio: f64,
    /// Torque per amp at the output shaft, including gearbox efficiency, N·m/A.
    pub torque_constant_nm_per_a: f64,
    /// Inertia of rotor and gearbox reflected to the output, kg·m².
    pub inertia_kg_m2: f64,
    /// Viscous friction, N·m per rad/s.
    pub viscous_nm_s_per_rad: f64,
    /// Coulomb friction, N·m.
    pub coulomb_nm: f64,
    /// How the ESC drives the motor.
    pub drive: Drive,
    /// Amps per count of the feedback frame's torque-current field (D4–5).
    pub feedback_amps_per_raw: f64,
    /// Winding resistance for copper losses, ohms (per phase).
    pub phase_resistance_ohm: f64,
    /// Thermal resistance winding → ambient, K/W (derived from the rated current for the
    /// M3508; estimates for the others, which publish no thermal data).
    pub thermal_resistance_k_per_w: f64,
    /// Thermal capacity of the winding, J/K (as the resistance: derived for the M3508 from a
    /// 10-minute time constant, estimates for the others).
    pub thermal_capacity_j_per_k: f64,
    /// Ambient temperature, °C.
    pub ambient_c: f64,
    /// Whether the ESC reports temperature (not the C610).
    pub reports_temperature: bool,
    /// Winding temperature above which the ESC turns its output off (no current; it still
    /// reports), °C: the GM6020 at 125 °C (user guide); `None` for none. The C620 does the
    /// same at 125 °C when its protection is enabled in DJI's assistant: set
    /// `Some(125.0)` to model that.
    pub over_temperature_cut_c: Option<f64>,
}

impl MotorParams {
    /// C620 + M3508 (DJI M3508 P19 / C620 user guides).
    pub fn m3508() -> Self {
        let (viscous, coulomb) = (2e-3, 0.03);
        Self {
            model: DjiModel::M3508,
            gear_ratio: 3591.0 / 187.0,
            // 0.3 N·m/A at the output; the published torque curve saturates near 5 N·m at
            // 20 A, i.e. ≈0.25 N·m/A effective with gearbox losses (SPEC.md).
            torque_constant_nm_per_a: 0.25,
            // Derived from the 49 ms mechanical time constant and 72 rpm/(N·m):
            // J = τ / (72 · 2π/60) = 6.5e-3 kg·m² (low confidence, SPEC.md).
            inertia_kg_m2: 6.5e-3,
            viscous_nm_s_per_rad: viscous,
            coulomb_nm: coulomb,
            drive: Drive::CurrentLoop {
                amps_per_raw: 20.0 / 16384.0,
                limit_amps: 20.0,
                // L/R = 0.097 mH / 0.194 Ω = 0.5 ms.
                tau_s: 0.5e-3,
                // 482 rpm no-load with the C620, spinning freely: the line ends at 491.4.
                // The published rated point, 3 N·m at 469 rpm, is not on the line of the
                // published 72 rpm/(N·m) through the no-load speed (through 482 rpm it would
                // need 4.3 rpm/(N·m)): the line follows the gradient and the no-load speed,
                // so above about 275 rpm the model has less than 3 N·m, and at 469 rpm only
                // 0.31 N·m (a loaded chassis at speed is slower here than on a real one).
                zero_torque_rpm: zero_torque_rpm(482.0, 72.0, coulomb, viscous),
                gradient_rpm_per_nm: 72.0,
            },
            feedback_amps_per_raw: 20.0 / 16384.0,
            phase_resistance_ohm: 0.194,
            // Derived: 10 A continuous (rated) → 1.5 · 10² · 0.194 = 29 W holds the winding at
            // 125 °C from 25 °C: 3.4 K/W; a 10-minute thermal time constant: 176 J/K.
            thermal_resistance_k_per_w: 3.4,
            thermal_capacity_j_per_k: 176.0,
            ambient_c: 25.0,
            reports_temperature: true,
            over_temperature_cut_c: None,
        }
    }

    /// C610 + M2006 (DJI M2006 P36 / C610 user guides).
    pub fn m2006() -> Self {
        let (viscous, coulomb) = (1e-3, 0.02);
        Self {
            model: DjiModel::M2006,
            gear_ratio: 36.0,
            torque_constant_nm_per_a: 0.18,
            // Derived: 52.78 ms / (110 rpm/(N·m) · 2π/60) = 4.6e-3 kg·m².
            inertia_kg_m2: 4.6e-3,
            viscous_nm_s_per_rad: viscous,
            coulomb_nm: coulomb,
            drive: Drive::CurrentLoop {
                amps_per_raw: 10.0 / 10000.0,
                limit_amps: 10.0,
                tau_s: 0.5e-3,
                // 500 rpm no-load with the C610: the line ends at 508.0.
                zero_torque_rpm: zero_torque_rpm(500.0, 110.0, coulomb, viscous),
                gradient_rpm_per_nm: 110.0,
            },
            feedback_amps_per_raw: 10.0 / 10000.0,
            phase_resistance_ohm: 0.461,
            thermal_resistance_k_per_w: 8.0,
            thermal_capacity_j_per_k: 60.0,
            ambient_c: 25.0,
            reports_temperature: false,
            over_temperature_cut_c: None,
        }
    }

    /// GM6020 in voltage mode (DJI GM6020 user guide, 2018).
    pub fn gm6020_voltage() -> Self {
        // ke from the no-load speed: 24 V / (320 rpm · 2π/60) = 0.716 V·s/rad.
        let ke = 24.0 / (320.0 * TAU / 60.0);
        Self {
            model: DjiModel::Gm6020Voltage,
            gear_ratio: 1.0,
            torque_constant_nm_per_a: 0.741,
            // Derived: 3 ms / (156 rpm/(N·m) · 2π/60) = 1.8e-4 kg·m².
            inertia_kg_m2: 1.8e-4,
            viscous_nm_s_per_rad: 1e-4,
            coulomb_nm: 0.01,
            drive: Drive::Voltage {
                // 30000 ↔ 24 V (2018 manual full scale at the rated supply).
                volts_per_raw: 24.0 / 30000.0,
                raw_limit: 25000.0,
                // Derived from the gradient: R = (156 · 2π/60) · ke · kt = 8.7 Ω effective.
                resistance_ohm: 156.0 * TAU / 60.0 * ke * 0.741,
                inductance_h: 5.78e-3,
                ke_v_s_per_rad: ke,
            },
            feedback_amps_per_raw: 3.0 / 16384.0,
            phase_resistance_ohm: 1.8,
            thermal_resistance_k_per_w: 6.0,
            thermal_capacity_j_per_k: 100.0,
            ambient_c: 25.0,
            reports_temperature: true,
            over_temperature_cut_c: Some(125.0),
        }
    }

    /// The parameters for `model`.
    pub fn for_model(model: DjiModel) -> Self {
        match model {
            DjiModel::M3508 => Self::m3508(),
            DjiModel::M2006 => Self::m2006(),
            DjiModel::Gm6020Voltage => Self::gm6020_voltage(),
            DjiModel::Gm6020Current => {
                let mut p = Self::gm6020_voltage();
                p.model = DjiModel::Gm6020Current;
                p.drive = Drive::CurrentLoop {
                    amps_per_raw: 3.0 / 16384.0,
                    limit_amps: 3.0,
                    tau_s: 0.67e-3,
                    // 320 rpm no-load: the line ends at 322.1.
                    zero_torque_rpm: zero_torque_rpm(
                        320.0,
                        156.0,
                        p.coulomb_nm,
                        p.viscous_nm_s_per_rad,
                    ),
                    gradient_rpm_per_nm: 156.0,
                };
                p
            }
        }
    }
}

/// The torque–speed line's zero-torque end (rpm) for a motor whose published no-load speed
/// `no_load_rpm` was measured spinning freely: above it by the friction at that speed (N·m)
/// times the line's `gradient_rpm_per_nm`, so that the plant at full command and no load
/// settles at `no_load_rpm`, as the real motor does.
pub fn zero_torque_rpm(
    no_load_rpm: f64,
    gradient_rpm_per_nm: f64,
    coulomb_nm: f64,
    viscous_nm_s_per_rad: f64,
) -> f64 {
    let friction_nm = coulomb_nm + viscous_nm_s_per_rad * no_load_rpm * TAU / 60.0;
    no_load_rpm + gradient_rpm_per_nm * friction_nm
}

/// What the motor drives besides itself.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Load {
    /// Extra inertia at the output, kg·m².
    pub inertia_kg_m2: f64,
    /// Constant torque against positive rotation, N·m, whatever the motion: gravity on an
    /// arm or a gimbal's unbalanced pitch, a spring's preload. Beyond the friction it turns
    /// an unpowered shaft backwards. (Rolling resistance is [`friction_nm`](Self::friction_nm).)
    pub torque_nm: f64,
    /// Friction at the output, N·m, on top of the motor's own (Coulomb): opposes the motion
    /// whichever way the shaft turns, and holds it still until the drive exceeds it. Rolling
    /// resistance of a wheel, a gearbox's or a bearing's drag.
    pub friction_nm: f64,
    /// A torque step: `(time in µs, torque in N·m)` replacing `torque_nm` from then on.
    pub step: Option<(u64, f64)>,
}

/// One ESC + motor on the simulated bus.
#[derive(Debug, Clone)]
pub struct DjiEsc {
    params: MotorParams,
    esc_id: u8,
    load: Load,
    /// Output speed, rad/s.
    omega: f64,
    /// Rotor angle, rad (continuous).
    rotor_angle: f64,
    current: f64,
    command_raw: f64,
    temperature: f64,
    powered: bool,
    locked: bool,
    feedback_phase_us: u64,
    /// What a step multiplies by, for the last step length (steps are constant).
    factors: StepFactors,
    /// The command frame's ID and the offset of this ESC's 2 bytes in it, if `esc_id` has a
    /// command slot (worked out once: every frame on the bus is offered to every ESC).
    command_slot: Option<(u32, usize)>,
    /// For a current loop with ordinary constants: speed-gradient × torque constant, which
    /// turns amps into rpm of headroom (see [`DjiEsc::inside_torque_speed_line`]).
    rpm_per_amp: Option<f64>,
}

/// What a plant step of one length multiplies by (see [`DjiEsc::step`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct StepFactors {
    /// The step length these are for, s (NaN before the first step).
    dt_s: f64,
    /// `1 − e^(−dt/τ)`: the share of the way to its target the current moves in a step.
    lag: f64,
    /// `dt / J`, s/(kg·m²): the output speed change per N·m in a step (rad/s).
    dt_per_inertia: f64,
    /// `gear ratio · dt`, s: rotor radians per output rad/s in a step.
    rotor_turn_per_omega: f64,
    /// `1 / R_th`, W/K: the heat the winding loses per kelvin above ambient.
    cooling_w_per_k: f64,
    /// `dt / C_th`, K/W: the temperature change per watt in a step.
    dt_per_heat_capacity: f64,
}

impl StepFactors {
    /// Before the first step: NaN matches no step length.
    const NONE: Self = Self {
        dt_s: f64::NAN,
        lag: 0.0,
        dt_per_inertia: 0.0,
        rotor_turn_per_omega: 0.0,
        cooling_w_per_k: 0.0,
        dt_per_heat_capacity: 0.0,
    };
}

impl DjiEsc {
    /// An ESC with id `esc_id` at rest, sending feedback `feedback_phase_us` into every ms. A
    /// NaN or negative load friction counts as none (the static hold needs a non-negative
    /// bound).
    pub fn new(params: MotorParams, esc_id: u8, load: Load, feedback_phase_us: u64) -> Self {
        let friction_nm = if load.friction_nm > 0.0 {
            load.friction_nm
        } else {
            0.0
        };
        Self {
            params,
            esc_id,
            load: Load {
                friction_nm,
                ..load
            },
            omega: 0.0,
            rotor_angle: 0.0,
            current: 0.0,
            command_raw: 0.0,
            temperature: params.ambient_c,
            powered: true,
            locked: false,
            feedback_phase_us: feedback_phase_us % 1000,
            factors: StepFactors::NONE,
            command_slot: params
                .model
                .command_slot(esc_id)
                .map(|slot| (u32::from(slot.id()), 2 * usize::from(slot.index()))),
            rpm_per_amp: match params.drive {
                Drive::CurrentLoop {
                    gradient_rpm_per_nm,
                    ..
                } => {
                    // Ordinary magnitudes only, so that every intermediate of the exact
                    // bound stays a normal float (see `inside_torque_speed_line`).
                    let normal = |x: f64| (1e-100..=1e100).contains(&x);
                    let product = gradient_rpm_per_nm * params.torque_constant_nm_per_a;
                    (normal(gradient_rpm_per_nm)
                        && normal(params.torque_constant_nm_per_a)
                        && normal(product))
                    .then_some(product)
                }
                Drive::Voltage { .. } => None,
            },
        }
    }

    /// Whether the current `i` lies strictly inside the torque–speed line's bounds in its own
    /// direction (`|i| < (zero_torque_rpm ∓ n) / gradient / kt`) and within `limit_amps`, so that
    /// the clamp in [`step`](Self::step) would return `i` itself. Decided with one
    /// multiplication instead of the bounds' five divisions; when it is not clearly inside,
    /// `false`, and the exact bounds decide.
    ///
    /// Why it never says `true` wrongly: the speed here (`ω · 60/2π`) differs from the exact
    /// one (`ω · 60 / 2π`) by a few ulps, the exact bound divides by the gradient and then by
    /// kt (two roundings), and `|i| · rpm_per_amp` rounds once: together a few parts in 1e16
    /// of `zero_torque_rpm + |n|`, far inside the margin of 1e-12 of it plus 1e-9 relative. That
    /// holds while no intermediate is subnormal: the constants are within [1e-100, 1e100]
    /// (else no shortcut) and headroom below 1e-100 rpm is left to the exact path, so the
    /// exact path's quotients stay above 1e-300. NaN compares false.
    fn inside_torque_speed_line(&self, i: f64, zero_torque_rpm: f64, limit_amps: f64) -> bool {
        const RPM_PER_RAD_S: f64 = 60.0 / TAU;
        let Some(rpm_per_amp) = self.rpm_per_amp else {
            return false;
        };
        let n = self.omega * RPM_PER_RAD_S;
        let toward = if i >= 0.0 {
            zero_torque_rpm - n
        } else {
            zero_torque_rpm + n
        };
        let margin = (zero_torque_rpm.abs() + n.abs()) * 1e-12;
        let headroom_rpm = (toward - margin) * (1.0 - 1e-9);
        i.abs() <= limit_amps && headroom_rpm > 1e-100 && i.abs() * rpm_per_amp < headroom_rpm
    }

    /// The factors of a step of `dt_s`, worked out when the step length changes: the step
    /// then multiplies where the equations divide (a division's latency sits on the chain
    /// from current to speed to angle).
    #[cold]
    fn step_factors(&self, dt_s: f64) -> StepFactors {
        let p = &self.params;
        let tau_s = match p.drive {
            Drive::CurrentLoop { tau_s, .. } => tau_s,
            Drive::Voltage {
                resistance_ohm,
                inductance_h,
                ..
            } => inductance_h / resistance_ohm,
        };
        StepFactors {
            dt_s,
            lag: 1.0 - (-dt_s / tau_s).exp(),
            dt_per_inertia: dt_s / (p.inertia_kg_m2 + self.load.inertia_kg_m2),
            rotor_turn_per_omega: p.gear_ratio * dt_s,
            cooling_w_per_k: 1.0 / p.thermal_resistance_k_per_w,
            dt_per_heat_capacity: dt_s / p.thermal_capacity_j_per_k,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &MotorParams {
        &self.params
    }

    /// Whether the winding is past the ESC's over-temperature cut (output off).
    pub fn over_temperature(&self) -> bool {
        self.params
            .over_temperature_cut_c
            .is_some_and(|cut| self.temperature > cut)
    }

    /// Output speed in rpm (the physical truth, not the reported value).
    pub fn speed_rpm(&self) -> f64 {
        self.omega * 60.0 / TAU
    }

    /// Output angle in degrees, continuous (physical truth).
    pub fn total_angle_deg(&self) -> f64 {
        self.rotor_angle / self.params.gear_ratio * 360.0 / TAU
    }

    /// Winding current in amps.
    pub fn current_amps(&self) -> f64 {
        self.current
    }

    /// Winding temperature in °C.
    pub fn temperature_c(&self) -> f64 {
        self.temperature
    }

    /// Cuts or restores the ESC's power (a referee power cut): unpowered, it sends nothing and
    /// drives no current.
    pub fn set_powered(&mut self, powered: bool) {
        self.powered = powered;
        if !powered {
            self.command_raw = 0.0;
        }
    }

    /// Whether the ESC has power (see [`set_powered`](Self::set_powered)).
    pub fn powered(&self) -> bool {
        self.powered
    }

    /// Locks or frees the rotor (a stall).
    pub fn set_locked(&mut self, locked: bool) {
        self.locked = locked;
        if locked {
            self.omega = 0.0;
        }
    }

    /// Forces the winding temperature (over-temperature injection).
    pub fn set_temperature_c(&mut self, celsius: f64) {
        self.temperature = celsius;
    }

    /// Whether the ESC sends feedback at `now_us` (every ms at its own phase).
    pub fn feedback_due(&self, now_us: u64) -> bool {
        self.powered && now_us % 1000 == self.feedback_phase_us
    }

    /// The next time after `now_us` feedback is due.
    pub fn next_feedback_us(&self, now_us: u64) -> u64 {
        let base = now_us - now_us % 1000 + self.feedback_phase_us;
        if base > now_us { base } else { base + 1000 }
    }

    /// Sets the raw command directly, as if a command frame had carried it (for analyses such
    /// as the full-current run that defines the minimum rise time).
    pub fn set_command_raw(&mut self, raw: i16) {
        self.command_raw = f64::from(raw);
    }

    /// Reads its slot from a command frame on the bus.
    pub fn on_frame(&mut self, frame: &CanFrame) {
        if !self.powered || frame.is_extended() {
            return;
        }
        let Some((id, offset)) = self.command_slot else {
            return;
        };
        if frame.raw_id() != id {
            return;
        }
        if let Some(d) = frame.data8()
            && let Some(&[hi, lo]) = d.get(offset..offset + 2)
        {
            self.command_raw = f64::from(i16::from_be_bytes([hi, lo]));
        }
    }

    /// Integrates `dt_s` seconds at time `now_us`.
    pub fn step(&mut self, now_us: u64, dt_s: f64) {
        if self.factors.dt_s != dt_s {
            self.factors = self.step_factors(dt_s);
        }
        // Borrowed, not copied: a step is short and runs 5000 times a simulated second.
        let (p, f) = (&self.params, &self.factors);
        let load_torque = match self.load.step {
            Some((t, torque)) if now_us >= t => torque,
            _ => self.load.torque_nm,
        };
        let off = !self.powered || self.over_temperature();
        let current = if off {
            0.0
        } else {
            match p.drive {
                Drive::CurrentLoop {
                    amps_per_raw,
                    limit_amps,
                    zero_torque_rpm,
                    gradient_rpm_per_nm,
                    ..
                } => {
                    let target = (self.command_raw * amps_per_raw).clamp(-limit_amps, limit_amps);
                    let i = self.current + (target - self.current) * f.lag;
                    if self.inside_torque_speed_line(i, zero_torque_rpm, limit_amps) {
                        // The clamp below would return `i` itself: skip its divisions.
                        i
                    } else {
                        // Voltage headroom: in the direction of motion the torque cannot
                        // exceed the torque–speed line.
                        let n = self.speed_rpm();
                        let headroom_nm =
                            |dir: f64| (zero_torque_rpm - dir * n).max(0.0) / gradient_rpm_per_nm;
                        let max_pos = headroom_nm(1.0) / p.torque_constant_nm_per_a;
                        let max_neg = headroom_nm(-1.0) / p.torque_constant_nm_per_a;
                        i.clamp(-max_neg.min(limit_amps), max_pos.min(limit_amps))
                    }
                }
                Drive::Voltage {
                    volts_per_raw,
                    raw_limit,
                    resistance_ohm,
                    ke_v_s_per_rad,
                    ..
                } => {
                    let v = self.command_raw.clamp(-raw_limit, raw_limit) * volts_per_raw;
                    let i_ss = (v - ke_v_s_per_rad * self.omega) / resistance_ohm;
                    self.current + (i_ss - self.current) * f.lag
                }
            }
        };
        self.current = current;
        let drive = p.torque_constant_nm_per_a * current - load_torque;
        if self.locked {
            self.omega = 0.0;
        } else {
            let omega = self.omega;
            let viscous = p.viscous_nm_s_per_rad * omega;
            let moving = omega.abs() > 1e-6;
            // The motor's own Coulomb friction and the load's (made non-negative in `new`).
            let friction = p.coulomb_nm + self.load.friction_nm;
            let coulomb = if moving {
                friction * omega.signum()
            } else {
                // Static friction holds the shaft until the drive exceeds it.
                drive.clamp(-friction, friction)
            };
            let next = omega + (drive - viscous - coulomb) * f.dt_per_inertia;
            // Friction stops the shaft; it does not reverse it.
            self.omega = if moving && next.signum() != omega.signum() && drive.abs() <= friction {
                0.0
            } else {
                next
            };
        }
        self.rotor_angle += self.omega * f.rotor_turn_per_omega;
        // Copper losses heat the winding; it cools towards ambient.
        let loss_w = 1.5 * current * current * p.phase_resistance_ohm;
        let cooling_w = (self.temperature - p.ambient_c) * f.cooling_w_per_k;
        self.temperature += (loss_w - cooling_w) * f.dt_per_heat_capacity;
    }

    /// The feedback frame the ESC sends now (DJI layout, all quantised as the real ESC does).
    pub fn feedback_frame(&self) -> Option<CanFrame> {
        let p = &self.params;
        let counts = encoder_counts(self.rotor_angle / TAU * 8192.0);
        let rotor_rpm = round_to_i16(self.omega * p.gear_ratio * 60.0 / TAU);
        let current_raw = round_to_i16(self.current / p.feedback_amps_per_raw);
        let temp = if p.reports_temperature {
            round_to_u8(self.temperature)
        } else {
            0
        };
        let a = counts.to_be_bytes();
        let r = rotor_rpm.to_be_bytes();
        let c = current_raw.to_be_bytes();
        CanFrame::standard(
            p.model.feedback_id(self.esc_id),
            &[a[0], a[1], r[0], r[1], c[0], c[1], temp, 0],
        )
    }
}

/// The largest magnitude the fast paths below take: below 2^52, truncating to an integer and
/// taking the fraction (`x − trunc(x)`) are exact.
const EXACT_TRUNCATION_LIMIT: f64 = 1e15;

/// `x.round()` (half away from zero) as an integer, for |x| < [`EXACT_TRUNCATION_LIMIT`]:
/// the same value without the library call (`round` is one on x86-64's baseline).
fn round_exact(x: f64) -> i64 {
    let whole = x as i64; // towards zero
    let fraction = x - whole as f64; // exact, in (−1, 1)
    if fraction >= 0.5 {
        whole + 1
    } else if fraction <= -0.5 {
        whole - 1
    } else {
        whole
    }
}

/// `x.round().clamp(i16::MIN, i16::MAX) as i16`, bit for bit, quickly for ordinary values.
fn round_to_i16(x: f64) -> i16 {
    if x.abs() < EXACT_TRUNCATION_LIMIT {
        round_exact(x).clamp(i16::MIN.into(), i16::MAX.into()) as i16
    } else {
        x.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
    }
}

/// `x.round().clamp(0.0, 255.0) as u8`, bit for bit, quickly for ordinary values.
fn round_to_u8(x: f64) -> u8 {
    if x.abs() < EXACT_TRUNCATION_LIMIT {
        round_exact(x).clamp(0, 255) as u8
    } else {
        x.round().clamp(0.0, 255.0) as u8
    }
}

/// `x.floor().rem_euclid(8192.0) as u16` (the encoder count of a rotor position in counts),
/// bit for bit, quickly for ordinary values: the floor of an integer-valued float and its
/// remainder are exact in either arithmetic.
fn encoder_counts(x: f64) -> u16 {
    if x.abs() < EXACT_TRUNCATION_LIMIT {
        let whole = x as i64; // towards zero
        let floor = if whole as f64 > x { whole - 1 } else { whole };
        floor.rem_euclid(8192) as u16
    } else {
        x.floor().rem_euclid(8192.0) as u16
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::run::uniform;
    use rand_xoshiro::Xoshiro256PlusPlus;
    use rand_xoshiro::rand_core::SeedableRng;

    fn run_full_current(params: MotorParams, seconds: f64) -> DjiEsc {
        let mut esc = DjiEsc::new(params, 1, Load::default(), 0);
        esc.command_raw = 16384.0;
        let dt = 1e-4;
        for k in 0..(seconds / dt) as u64 {
            esc.step(k * 100, dt);
        }
        esc
    }

    #[test]
    fn a_gm6020_past_125_c_turns_its_output_off_and_still_reports() {
        let mut esc = DjiEsc::new(MotorParams::gm6020_voltage(), 1, Load::default(), 0);
        esc.command_raw = 25000.0;
        for k in 0..2000 {
            esc.step(k * 100, 1e-4);
        }
        let spinning = esc.speed_rpm();
        assert!(spinning > 200.0, "{spinning}");
        esc.set_temperature_c(126.0);
        for k in 2000..2010 {
            esc.step(k * 100, 1e-4);
            assert_eq!(esc.current_amps(), 0.0);
        }
        // Coasting down against friction only (no drive): slower, and still reporting 126 °C.
        assert!(esc.speed_rpm() < spinning);
        let frame = esc.feedback_frame().unwrap();
        assert_eq!(frame.data()[6], 126);
        // An M3508 (C620 protection off by default) keeps driving at 126 °C.
        let mut m3508 = DjiEsc::new(MotorParams::m3508(), 1, Load::default(), 0);
        m3508.command_raw = 16384.0;
        m3508.set_temperature_c(126.0);
        m3508.step(0, 1e-4);
        assert!(m3508.current_amps() > 0.0);
    }

    #[test]
    fn full_current_unloaded_reaches_the_published_no_load_speed() {
        // M3508 with the C620 482 rpm, M2006 with the C610 500 rpm, GM6020 320 rpm (SPEC),
        // each measured spinning freely: friction included. 1 s is 20 mechanical time
        // constants of the slowest.
        for (params, no_load) in [
            (MotorParams::m3508(), 482.0),
            (MotorParams::m2006(), 500.0),
            (MotorParams::for_model(DjiModel::Gm6020Current), 320.0),
        ] {
            let esc = run_full_current(params, 1.0);
            let n = esc.speed_rpm();
            assert!((n - no_load).abs() < 0.5, "{:?}: n = {n}", params.model);
        }
        // The M3508's line: friction at 482 rpm is 0.03 + 2e-3 · 50.47 = 0.131 N·m, so it
        // ends 0.131 · 72 = 9.4 rpm higher.
        assert!((zero_torque_rpm(482.0, 72.0, 0.03, 2e-3) - 491.43).abs() < 0.01);
    }

    #[test]
    fn m3508_initial_acceleration_matches_torque_over_inertia() {
        let esc = run_full_current(MotorParams::m3508(), 0.01);
        // 10 ms at ≈ (0.25 · 20 − friction) / 6.5e-3 ≈ 760 rad/s² after the 0.5 ms current lag:
        // ≈ 7.2 rad/s ≈ 69 rpm.
        let n = esc.speed_rpm();
        assert!(n > 62.0 && n < 74.0, "n = {n}");
    }

    #[test]
    fn feedback_frame_quantises_like_the_esc() {
        let mut esc = DjiEsc::new(MotorParams::m3508(), 3, Load::default(), 0);
        esc.rotor_angle = TAU * 1.5; // half a rotor turn past one turn: 4096 counts
        esc.omega = 10.0 * TAU / 60.0; // 10 rpm output = 192.03 rpm rotor → 192
        esc.current = 2.5; // 2048 raw
        let f = esc.feedback_frame().unwrap();
        assert_eq!(f.raw_id(), 0x203);
        assert_eq!(f.data(), &[0x10, 0x00, 0x00, 0xC0, 0x08, 0x00, 25, 0]);
    }

    /// Values around every rounding edge the fast paths must match: ties, just inside and
    /// outside them, signed zeros, the i16/u8/8192 edges, the fast-path limit, non-finite.
    fn awkward_values() -> Vec<f64> {
        let mut v = crate::test_values::around_edges(
            &[
                0.0,
                -0.0,
                f64::NAN,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::MIN_POSITIVE,
            ],
            &[
                0.0,
                1.0,
                2.0,
                255.0,
                256.0,
                8191.0,
                8192.0,
                16384.0,
                32767.0,
                32768.0,
                1e6,
                1e15,
                4503599627370496.0,
                9007199254740992.0,
                1e19,
                1e300,
            ],
            &[0.0, 0.5, -0.5, 0.25, 0.75, 1.0 - 1e-9],
        );
        // A deterministic spread over ±1e5 and ±1e16.
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(2);
        for _ in 0..20_000 {
            let unit = uniform(&mut rng) - 0.5;
            v.extend([unit * 2e5, unit * 2e16, unit * 600.0]);
        }
        v
    }

    #[test]
    fn fast_rounding_matches_the_library_bit_for_bit() {
        for x in awkward_values() {
            let i16_ref = x.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
            assert_eq!(round_to_i16(x), i16_ref, "{x:e}");
            assert_eq!(round_to_u8(x), x.round().clamp(0.0, 255.0) as u8, "{x:e}");
            assert_eq!(
                encoder_counts(x),
                x.floor().rem_euclid(8192.0) as u16,
                "{x:e}"
            );
        }
    }

    /// The clamp `step` applies to a current-loop ESC's current, computed in full.
    fn exact_torque_speed_clamp(esc: &DjiEsc, i: f64) -> f64 {
        let Drive::CurrentLoop {
            limit_amps,
            zero_torque_rpm,
            gradient_rpm_per_nm,
            ..
        } = esc.params.drive
        else {
            unreachable!("current-loop models only")
        };
        let n = esc.speed_rpm();
        let headroom_nm = |dir: f64| (zero_torque_rpm - dir * n).max(0.0) / gradient_rpm_per_nm;
        let max_pos = headroom_nm(1.0) / esc.params.torque_constant_nm_per_a;
        let max_neg = headroom_nm(-1.0) / esc.params.torque_constant_nm_per_a;
        i.clamp(-max_neg.min(limit_amps), max_pos.min(limit_amps))
    }

    #[test]
    fn torque_speed_shortcut_is_taken_only_where_the_exact_clamp_returns_the_current() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let mut unit = || uniform(&mut rng);
        let (mut taken, mut checked) = (0u32, 0u32);
        for params in [
            MotorParams::m3508(),
            MotorParams::m2006(),
            MotorParams::for_model(DjiModel::Gm6020Current),
        ] {
            let Drive::CurrentLoop {
                limit_amps,
                zero_torque_rpm,
                gradient_rpm_per_nm,
                ..
            } = params.drive
            else {
                unreachable!()
            };
            let mut esc = DjiEsc::new(params, 1, Load::default(), 0);
            for k in 0..40_000 {
                // Speeds across ±1.5 × no-load (and exactly at it), currents across the limit
                // and right at both bounds, where the shortcut must step aside.
                let rpm = match k % 5 {
                    0 => zero_torque_rpm,
                    1 => -zero_torque_rpm,
                    _ => (unit() - 0.5) * 3.0 * zero_torque_rpm,
                };
                esc.omega = rpm * TAU / 60.0;
                let n = esc.speed_rpm();
                let bound = (zero_torque_rpm - n.abs()).max(0.0)
                    / gradient_rpm_per_nm
                    / params.torque_constant_nm_per_a;
                let sign = if unit() < 0.5 { 1.0 } else { -1.0 };
                let edge = sign * bound.min(limit_amps);
                let i = match k % 7 {
                    0 => edge,
                    1 => edge * (1.0 + 1e-13),
                    2 => edge * (1.0 - 1e-13),
                    3 => edge.next_up(),
                    4 => edge.next_down(),
                    _ => (unit() - 0.5) * 2.4 * limit_amps,
                };
                for i in [i, -i, 0.0, -0.0, f64::NAN, limit_amps, -limit_amps] {
                    checked += 1;
                    if esc.inside_torque_speed_line(i, zero_torque_rpm, limit_amps) {
                        taken += 1;
                        let exact = exact_torque_speed_clamp(&esc, i);
                        assert_eq!(exact.to_bits(), i.to_bits(), "rpm {rpm} i {i:e}");
                    }
                }
            }
        }
        // The shortcut does its job most of the time.
        assert!(taken > checked / 3, "{taken} of {checked}");
    }

    #[test]
    fn torque_speed_shortcut_is_off_for_unusual_constants() {
        let mut params = MotorParams::m3508();
        params.torque_constant_nm_per_a = -0.25;
        let esc = DjiEsc::new(params, 1, Load::default(), 0);
        assert!(!esc.inside_torque_speed_line(0.0, 482.0, 20.0));
        let esc = DjiEsc::new(MotorParams::gm6020_voltage(), 1, Load::default(), 0);
        assert!(!esc.inside_torque_speed_line(0.0, 482.0, 20.0));
        // Absurd constants whose exact bound goes through a subnormal quotient
        // (1e-20 rpm / 1e300 rpm/N·m): the exact path decides.
        let mut params = MotorParams::m3508();
        params.torque_constant_nm_per_a = 1e-100;
        if let Drive::CurrentLoop {
            gradient_rpm_per_nm,
            ..
        } = &mut params.drive
        {
            *gradient_rpm_per_nm = 1e300;
        }
        let esc = DjiEsc::new(params, 1, Load::default(), 0);
        assert!(!esc.inside_torque_speed_line(0.99999e-220, 1e-20, 20.0));
        let esc = DjiEsc::new(MotorParams::m3508(), 1, Load::default(), 0);
        assert!(esc.inside_torque_speed_line(0.0, 482.0, 20.0));
    }

    #[test]
    fn reads_only_its_own_slot() {
        let mut esc = DjiEsc::new(MotorParams::m3508(), 2, Load::default(), 0);
        let f = CanFrame::standard(0x200, &[0x11, 0x11, 0x08, 0x00, 0x22, 0x22, 0, 0]).unwrap();
        esc.on_frame(&f);
        assert_eq!(esc.command_raw, 2048.0);
        esc.on_frame(&CanFrame::standard(0x1FF, &[0x7F; 8]).unwrap());
        assert_eq!(esc.command_raw, 2048.0);
    }

    #[test]
    fn gm6020_voltage_no_load_speed_near_320_rpm_at_24v() {
        let mut esc = DjiEsc::new(MotorParams::gm6020_voltage(), 1, Load::default(), 0);
        esc.command_raw = 30000.0; // clamped to 25000 = 20 V → ≈ 267 rpm minus friction
        for k in 0..10_000 {
            esc.step(k * 100, 1e-4);
        }
        let n = esc.speed_rpm();
        assert!(n > 240.0 && n < 267.0, "n = {n}");
    }

    #[test]
    fn load_friction_opposes_motion_either_way_and_never_reverses_the_shaft() {
        let coast = |load: Load, omega0: f64, seconds: f64| {
            let mut esc = DjiEsc::new(MotorParams::m3508(), 1, load, 0);
            esc.set_powered(false);
            esc.omega = omega0;
            for k in 0..(seconds / 1e-4).round() as u64 {
                esc.step(k * 100, 1e-4);
            }
            esc.omega
        };
        let wheel = Load {
            inertia_kg_m2: 0.0231,
            friction_nm: 0.05,
            ..Load::default()
        };
        // J = 6.5e-3 + 0.0231 = 0.0296 kg·m², friction c = 0.03 + 0.05 N·m, viscous
        // b = 2e-3 N·m·s/rad: ω(t) = (ω0 + c/b)·e^(−bt/J) − c/b; from 10 rad/s, 0.1 s later
        // 50·e^(−0.006757) − 40 = 9.6633 rad/s, and the same backwards.
        let forward = coast(wheel, 10.0, 0.1);
        let backward = coast(wheel, -10.0, 0.1);
        assert!((forward - 9.6633).abs() < 2e-3, "{forward}");
        assert!((backward + 9.6633).abs() < 2e-3, "{backward}");
        // It stops after J/b·ln(50/40) = 3.3 s and stays stopped.
        assert_eq!(coast(wheel, 10.0, 4.0), 0.0);
        // Static friction holds against a torque below the whole friction: 0.06 N·m of
        // gravity against 0.03 + 0.05 holds the shaft (the motor's 0.03 alone would not).
        let held = Load {
            torque_nm: 0.06,
            ..wheel
        };
        assert_eq!(coast(held, 0.0, 1.0), 0.0);
        // A negative or NaN load friction counts as none (and does not panic).
        for bad in [-0.05, f64::NAN] {
            let w = coast(
                Load {
                    friction_nm: bad,
                    torque_nm: 0.05,
                    ..wheel
                },
                0.0,
                1.0,
            );
            assert!(w < -0.6 && w > -0.7, "{w}");
        }
        // A constant torque of the same size (gravity, not friction) beats the motor's own
        // 0.03 N·m and turns the unpowered shaft backwards: (−0.05 + 0.03)/J ≈ −0.68 rad/s².
        let pulled = Load {
            inertia_kg_m2: 0.0231,
            torque_nm: 0.05,
            ..Load::default()
        };
        let w = coast(pulled, 0.0, 1.0);
        assert!(w < -0.6 && w > -0.7, "{w}");
    }

    #[test]
    fn unpowered_esc_sends_nothing_and_coasts() {
        let mut esc = DjiEsc::new(MotorParams::m3508(), 1, Load::default(), 250);
        assert!(esc.feedback_due(1250));
        assert!(!esc.feedback_due(1251));
        assert_eq!(esc.next_feedback_us(1250), 2250);
        esc.set_powered(false);
        assert!(!esc.feedback_due(1250));
        esc.command_raw = 16384.0;
        esc.step(0, 1e-3);
        assert_eq!(esc.current_amps(), 0.0);
    }
}
