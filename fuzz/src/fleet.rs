//! The `bus_dispatch` target's robot: fifteen motors of every kind on one bus, and what the
//! protocol says about each (command ID and slot, raw range, feedback IDs), written out here
//! from the protocol tables rather than asked of the drivers.

use rc10_core::bus::{Bus, BusBuilder, BusConfig};
use rc10_core::can::{CanFrame, ExtendedId, Id, StandardId};
use rc10_core::encoder::GearRatio;
use rc10_core::motor::dji::{DjiConfig, DjiModel, DjiMotor};
use rc10_core::motor::dm::{DmConfig, DmMotor, MitLimits};
use rc10_core::motor::vesc::{VescConfig, VescMotor, VescStatusSet};
use rc10_core::motor::{HealthConfig, MultiTurnOnReturn};
use rc10_core::node::CanNode;
use rc10_core::time::Duration;

/// Nodes the bus holds.
pub const CAPACITY: usize = 16;

/// A DJI motor as the protocol describes it.
#[derive(Debug, Clone, Copy)]
pub struct DjiInfo {
    /// The model (and GM6020 command mode).
    pub model: DjiModel,
    /// ESC id.
    pub id: u8,
    /// Feedback ID (0x200 + id; GM6020 0x204 + id).
    pub feedback_id: u16,
    /// Command frame ID and slot index.
    pub command_id: u16,
    /// Slot index, 0–3.
    pub slot: usize,
    /// Largest raw command magnitude: C620 16384, C610 10000, GM6020 current 16384, GM6020
    /// voltage the configured limit.
    pub raw_range: i16,
    /// Raw counts per amp (per volt in voltage mode): C620 16384/20 A, C610 10000/10 A,
    /// GM6020 current 16384/3 A, GM6020 voltage 30000/24 V.
    pub raw_per_unit: f32,
    /// Thermal derating start and cut-off, °C (the driver's defaults where the ESC reports a
    /// temperature).
    pub thermal: Option<(f32, f32)>,
    /// Offline timeout, µs.
    pub timeout_us: u64,
}

impl DjiInfo {
    fn new(model: DjiModel, id: u8, voltage_raw_limit: i16, timeout_us: u64) -> Self {
        let (low, high, feedback_base) = match model {
            DjiModel::M3508 | DjiModel::M2006 => (0x200, 0x1FF, 0x200),
            DjiModel::Gm6020Voltage => (0x1FF, 0x2FF, 0x204),
            DjiModel::Gm6020Current => (0x1FE, 0x2FE, 0x204),
        };
        let (raw_range, raw_per_unit) = match model {
            DjiModel::M3508 => (16384, 16384.0 / 20.0),
            DjiModel::M2006 => (10000, 10000.0 / 10.0),
            DjiModel::Gm6020Current => (16384, 16384.0 / 3.0),
            DjiModel::Gm6020Voltage => (voltage_raw_limit, 30000.0 / 24.0),
        };
        Self {
            model,
            id,
            feedback_id: feedback_base + u16::from(id),
            command_id: if id <= 4 { low } else { high },
            slot: usize::from((id - 1) % 4),
            raw_range,
            raw_per_unit,
            thermal: (model != DjiModel::M2006).then_some((100.0, 120.0)),
            timeout_us,
        }
    }

    /// The ESC's range in amps (volts in voltage mode).
    pub fn unit_range(&self) -> f32 {
        f32::from(self.raw_range) / self.raw_per_unit
    }
}

/// A VESC as configured.
#[derive(Debug, Clone, Copy)]
pub struct VescInfo {
    /// Controller id.
    pub id: u8,
    /// Status packets it broadcasts.
    pub packets: &'static [u8],
    /// Current limit, A.
    pub max_current: f32,
    /// Brake limit, A.
    pub max_brake: f32,
    /// Output speed limit, rpm.
    pub max_speed_rpm: f32,
    /// eRPM per output rpm: pole pairs × gear ratio.
    pub erpm_per_rpm: f64,
    /// Offline timeout, µs.
    pub timeout_us: u64,
}

/// A Damiao motor as configured.
#[derive(Debug, Clone, Copy)]
pub struct DmInfo {
    /// Command ID.
    pub can_id: u16,
    /// Feedback ID.
    pub master_id: u16,
    /// MIT ranges.
    pub limits: MitLimits,
    /// kd in speed mode.
    pub speed_kd: f32,
    /// kp in angle modes.
    pub position_kp: f32,
    /// kd in angle modes.
    pub position_kd: f32,
    /// Sends Enable by itself while the motor reports Disabled.
    pub auto_enable: bool,
    /// Offline timeout, µs.
    pub timeout_us: u64,
}

/// One motor of the fleet and what is known about it.
#[derive(Debug, Clone, Copy)]
pub enum MotorRef<'a> {
    /// A DJI motor.
    Dji(&'a DjiMotor, DjiInfo),
    /// A VESC.
    Vesc(&'a VescMotor, VescInfo),
    /// A Damiao motor.
    Dm(&'a DmMotor, DmInfo),
}

impl<'a> MotorRef<'a> {
    /// The node, for registration.
    pub fn node(&self) -> &'a dyn CanNode {
        match *self {
            Self::Dji(m, _) => m,
            Self::Vesc(m, _) => m,
            Self::Dm(m, _) => m,
        }
    }

    /// The motor, for setters and state.
    pub fn motor(&self) -> &'a dyn rc10_core::motor::Motor {
        match *self {
            Self::Dji(m, _) => m,
            Self::Vesc(m, _) => m,
            Self::Dm(m, _) => m,
        }
    }

    /// Offline timeout, µs.
    pub fn timeout_us(&self) -> u64 {
        match self {
            Self::Dji(_, i) => i.timeout_us,
            Self::Vesc(_, i) => i.timeout_us,
            Self::Dm(_, i) => i.timeout_us,
        }
    }

    /// Whether `frame` is this motor's feedback by the protocol (what the bus must route to it).
    pub fn listens_to(&self, frame: &CanFrame) -> bool {
        match self {
            Self::Dji(_, i) => !frame.is_extended() && frame.raw_id() == u32::from(i.feedback_id),
            Self::Dm(_, i) => !frame.is_extended() && frame.raw_id() == u32::from(i.master_id),
            Self::Vesc(_, i) => crate::proto::vesc_id(frame)
                .is_some_and(|v| v.controller == i.id && i.packets.contains(&v.packet)),
        }
    }
}

const STATUS_1_4: &[u8] = &[9, 16];
const STATUS_ALL: &[u8] = &[9, 14, 15, 16, 27];

/// The motors. Registration order (see [`Fleet::motors`]) mixes the kinds.
pub struct Fleet {
    dji: [(DjiMotor, DjiInfo); 11],
    vesc: [(VescMotor, VescInfo); 2],
    dm: [(DmMotor, DmInfo); 2],
}

fn dji(model: DjiModel, id: u8, tweak: impl FnOnce(&mut DjiConfig)) -> (DjiMotor, DjiInfo) {
    let mut config = DjiConfig::default_for(model);
    tweak(&mut config);
    let motor = DjiMotor::new(model, id, config).expect("valid DJI configuration");
    let info = DjiInfo::new(
        model,
        id,
        config.voltage_raw_limit,
        config.health.offline_timeout.as_micros(),
    );
    (motor, info)
}

impl Fleet {
    /// Eleven DJI motors (M3508, M2006, GM6020 in both modes, one GM6020 with a raised
    /// voltage limit, one motor with a short timeout and restart-on-return), two VESCs and
    /// two Damiao motors, with no ID conflict between them.
    #[allow(clippy::new_without_default)]
    pub fn new() -> Self {
        use DjiModel::*;
        let dji = [
            dji(M3508, 1, |_| {}),
            dji(M3508, 2, |c| {
                c.health = c
                    .health
                    .with_offline_timeout(Duration::from_millis(20))
                    .with_on_return(MultiTurnOnReturn::Restart);
            }),
            dji(M2006, 3, |_| {}),
            dji(M2006, 4, |_| {}),
            dji(Gm6020Current, 1, |_| {}), // 0x205, 0x1FE slot 0
            dji(Gm6020Current, 2, |_| {}), // 0x206, 0x1FE slot 1
            dji(M3508, 7, |_| {}),         // 0x207, 0x1FF slot 2
            dji(M2006, 8, |_| {}),         // 0x208, 0x1FF slot 3
            dji(Gm6020Voltage, 5, |_| {}), // 0x209, 0x2FF slot 0, ±25000
            dji(Gm6020Voltage, 6, |c| {
                // 2018 firmware: ±30000, and a speed loop allowed to use it (24 V).
                c.voltage_raw_limit = 30000;
                c.cascade.speed = c.cascade.speed.with_output_limit(24.0);
            }), // 0x20A, 0x2FF slot 1
            dji(Gm6020Current, 7, |_| {}), // 0x20B, 0x2FE slot 2
        ];
        let v1 = VescConfig {
            status_packets: VescStatusSet::STATUS_1.with(VescStatusSet::STATUS_4),
            ..VescConfig::new(7)
        };
        let v2 = VescConfig {
            gear: GearRatio::new(3, 1).expect("ratio"),
            max_current_amps: 30.0,
            max_brake_amps: 10.0,
            max_speed_rpm: 2000.0,
            zero_speed_brake_amps: Some(4.0),
            status_packets: VescStatusSet::ALL,
            torque_constant_nm_per_amp: Some(0.5),
            health: HealthConfig::DEFAULT.with_offline_timeout(Duration::from_millis(50)),
            ..VescConfig::new(14)
        };
        let vesc_info = |id: u8, c: &VescConfig, packets| VescInfo {
            id,
            packets,
            max_current: c.max_current_amps,
            max_brake: c.max_brake_amps,
            max_speed_rpm: c.max_speed_rpm,
            erpm_per_rpm: f64::from(c.pole_pairs) * f64::from(c.gear.rotor_turns())
                / f64::from(c.gear.output_turns()),
            timeout_us: c.health.offline_timeout.as_micros(),
        };
        let vesc = [
            (
                VescMotor::new(0x10, v1).expect("VESC 1"),
                vesc_info(0x10, &v1, STATUS_1_4),
            ),
            (
                VescMotor::new(0x11, v2).expect("VESC 2"),
                vesc_info(0x11, &v2, STATUS_ALL),
            ),
        ];
        let d1 = DmConfig::new(0x11);
        let d2 = DmConfig {
            limits: MitLimits {
                p_max_rad: 4.0,
                v_max_rad_s: 45.0,
                t_max_nm: 18.0,
            },
            speed_kd: 0.5,
            position_kp: 50.0,
            position_kd: 2.0,
            auto_enable: false,
            health: HealthConfig::DEFAULT.with_offline_timeout(Duration::from_millis(30)),
            ..DmConfig::new(0x12)
        };
        let dm_info = |can_id: u16, c: &DmConfig| DmInfo {
            can_id,
            master_id: c.master_id,
            limits: c.limits,
            speed_kd: c.speed_kd,
            position_kp: c.position_kp,
            position_kd: c.position_kd,
            auto_enable: c.auto_enable,
            timeout_us: c.health.offline_timeout.as_micros(),
        };
        let dm = [
            (DmMotor::new(0x01, d1).expect("DM 1"), dm_info(0x01, &d1)),
            (DmMotor::new(0x02, d2).expect("DM 2"), dm_info(0x02, &d2)),
        ];
        Self { dji, vesc, dm }
    }

    /// Every motor, in registration order.
    pub fn motors(&self) -> Vec<MotorRef<'_>> {
        let d = |i: usize| MotorRef::Dji(&self.dji[i].0, self.dji[i].1);
        let v = |i: usize| MotorRef::Vesc(&self.vesc[i].0, self.vesc[i].1);
        let m = |i: usize| MotorRef::Dm(&self.dm[i].0, self.dm[i].1);
        vec![
            d(0),
            d(1),
            v(0),
            d(2),
            d(3),
            m(0),
            d(4),
            d(5),
            d(6),
            v(1),
            d(7),
            d(8),
            m(1),
            d(9),
            d(10),
        ]
    }

    /// The bus with every motor registered (registration must succeed: the IDs were chosen
    /// not to clash). No frame budget or TX-depth limit: this bus is about dispatch and
    /// packing, not about fitting a real 1 Mbit/s bus.
    pub fn bus(&self) -> Bus<'_, CAPACITY> {
        let config = BusConfig {
            max_load_percent: f32::INFINITY,
            ..BusConfig::DEFAULT.with_tx_depth(16)
        };
        let mut builder = BusBuilder::<CAPACITY>::with_config(config);
        for (i, m) in self.motors().iter().enumerate() {
            if let Err(e) = builder.register(m.node()) {
                panic!("registering motor {i} ({m:?}) failed: {e}");
            }
        }
        builder.build()
    }
}

/// IDs worth sending on purpose: every feedback ID of the fleet, every VESC status ID of
/// both controllers (also the packets a controller does not broadcast), the command IDs,
/// neighbours of all these.
pub fn interesting_ids(fleet: &Fleet) -> Vec<Id> {
    let std = |id: u16| Id::Standard(StandardId::new(id).expect("11-bit"));
    let ext = |id: u32| Id::Extended(ExtendedId::new(id).expect("29-bit"));
    let mut ids = Vec::new();
    for m in fleet.motors() {
        match m {
            MotorRef::Dji(_, i) => ids.push(std(i.feedback_id)),
            MotorRef::Dm(_, i) => {
                ids.push(std(i.master_id));
                ids.push(std(i.can_id));
            }
            MotorRef::Vesc(_, i) => {
                for p in [9u32, 14, 15, 16, 27, 0, 1, 3, 4, 5, 8] {
                    ids.push(ext(p << 8 | u32::from(i.id)));
                }
            }
        }
    }
    for id in [0x1FE, 0x1FF, 0x200, 0x2FE, 0x2FF, 0x20C, 0x204, 0x10] {
        ids.push(std(id));
    }
    ids.push(ext(0x0912)); // STATUS of a VESC nobody registered
    ids.push(ext(0x1_0910)); // a VESC-looking ID with a bit above the packet
    ids
}
