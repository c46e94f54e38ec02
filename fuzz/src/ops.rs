//! What the `bus_dispatch` target does, one operation at a time, as decoded from the input.
//!
//! Each operation starts with a tag byte (taken modulo the number of tags; frames and ticks
//! have several tags each, so random input is mostly frames and ticks). [`Op::encode`] writes
//! the bytes that decode to an operation, for the seed corpus.

use crate::input::{Float, Payload};
use arbitrary::{Arbitrary, Result, Unstructured};

/// How the clock moves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Step {
    /// One tick period, 1 ms.
    Period,
    /// Forward by µs (up to 65 ms).
    Micros(u16),
    /// Forward by seconds (up to 136 years).
    Seconds(u32),
    /// Backwards by µs (up to 71 minutes).
    Back(u32),
    /// To an absolute time (µs; kept below 2^63, 292 000 years of uptime).
    To(u64),
}

/// Which ID a received frame has.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum IdSel {
    /// One of [`crate::fleet::interesting_ids`] (index modulo its length).
    Known(u8),
    /// Any standard ID (masked to 11 bits).
    Standard(u16),
    /// Any extended ID (masked to 29 bits).
    Extended(u32),
    /// A known ID's number with the other kind (standard ↔ extended).
    Flipped(u8),
}

/// The timestamp a received frame carries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Stamp {
    /// The clock.
    Now,
    /// µs before the clock (a frame read late, or a clock that went backwards).
    Before(u32),
    /// µs after the clock (a receiver that stamped after the tick read the clock).
    After(u32),
    /// Any 64-bit time at all, including `u64::MAX`.
    Absolute(u64),
}

/// An application call on one motor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Set {
    /// `Motor::set_target_current`.
    Current(Float),
    /// `Motor::set_target_voltage`.
    Voltage(Float),
    /// `Motor::set_target_rpm`.
    Rpm(Float),
    /// `Motor::set_target_angle_deg`.
    Angle(Float),
    /// `Motor::set_target_total_angle_deg`.
    TotalAngle(Float),
    /// `Motor::set_target_torque_nm`.
    Torque(Float),
    /// `Motor::set_feed_forward_torque_nm`.
    FeedForwardTorque(Float),
    /// `Motor::set_current_limit_amps`.
    CurrentLimit(Float),
    /// `Motor::set_total_angle_here_deg`.
    Home(Float),
    /// `Motor::disable`.
    Disable,
    /// DJI `set_target_raw`.
    DjiRaw(i16),
    /// DJI `set_voltage_limit_volts`.
    DjiVoltageLimit(Float),
    /// DJI `set_feed_forward` (command units).
    DjiFeedForward(Float),
    /// DJI `set_speed_pid` (kp, ki, kd, output limit).
    DjiSpeedPid([Float; 4]),
    /// DJI `set_angle_pid` (kp, ki, kd, output limit).
    DjiAnglePid([Float; 4]),
    /// VESC `set_duty`.
    VescDuty(Float),
    /// VESC `set_brake_current`.
    VescBrake(Float),
    /// Damiao `set_mit` (position, velocity, kp, kd, torque).
    DmMit([Float; 5]),
    /// Damiao `send_special` (modulo 4: enable, disable, save zero, clear error).
    DmSpecial(u8),
}

const SET_TAGS: u8 = 19;

/// One operation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Op {
    /// Deliver a received frame to `Bus::dispatch`.
    Frame {
        /// Its ID.
        id: IdSel,
        /// Its DLC and bytes.
        payload: Payload,
        /// Its timestamp.
        stamp: Stamp,
    },
    /// One scheduler tick at the clock, paced as `run_scheduler` paces it, then transmit.
    Tick,
    /// One tick with an explicit `dt` (µs), as the simulator calls `Bus::tick`.
    TickDt(u32),
    /// Move the clock.
    Advance(Step),
    /// An application call on motor `motor` (index modulo the fleet's size).
    Set {
        /// Motor index.
        motor: u8,
        /// The call.
        set: Set,
    },
    /// The bus takes up to this many frames from the TX buffers.
    Drain(u8),
    /// The controller is (or is no longer) bus-off.
    BusOff(bool),
}

fn floats<const N: usize>(u: &mut Unstructured<'_>) -> Result<[Float; N]> {
    let mut out = [Float::Special(0); N];
    for f in &mut out {
        *f = Float::arbitrary(u)?;
    }
    Ok(out)
}

impl<'a> Arbitrary<'a> for Set {
    fn arbitrary(u: &mut Unstructured<'a>) -> Result<Self> {
        let f = |u: &mut Unstructured<'a>| Float::arbitrary(u);
        Ok(match u8::arbitrary(u)? % SET_TAGS {
            0 => Self::Current(f(u)?),
            1 => Self::Voltage(f(u)?),
            2 => Self::Rpm(f(u)?),
            3 => Self::Angle(f(u)?),
            4 => Self::TotalAngle(f(u)?),
            5 => Self::Torque(f(u)?),
            6 => Self::FeedForwardTorque(f(u)?),
            7 => Self::CurrentLimit(f(u)?),
            8 => Self::Home(f(u)?),
            9 => Self::Disable,
            10 => Self::DjiRaw(i16::arbitrary(u)?),
            11 => Self::DjiVoltageLimit(f(u)?),
            12 => Self::DjiFeedForward(f(u)?),
            13 => Self::DjiSpeedPid(floats(u)?),
            14 => Self::DjiAnglePid(floats(u)?),
            15 => Self::VescDuty(f(u)?),
            16 => Self::VescBrake(f(u)?),
            17 => Self::DmMit(floats(u)?),
            _ => Self::DmSpecial(u8::arbitrary(u)?),
        })
    }
}

impl Set {
    fn encode(&self, out: &mut Vec<u8>) {
        let (tag, floats): (u8, &[Float]) = match self {
            Self::Current(x) => (0, core::slice::from_ref(x)),
            Self::Voltage(x) => (1, core::slice::from_ref(x)),
            Self::Rpm(x) => (2, core::slice::from_ref(x)),
            Self::Angle(x) => (3, core::slice::from_ref(x)),
            Self::TotalAngle(x) => (4, core::slice::from_ref(x)),
            Self::Torque(x) => (5, core::slice::from_ref(x)),
            Self::FeedForwardTorque(x) => (6, core::slice::from_ref(x)),
            Self::CurrentLimit(x) => (7, core::slice::from_ref(x)),
            Self::Home(x) => (8, core::slice::from_ref(x)),
            Self::Disable => (9, &[]),
            Self::DjiRaw(n) => {
                out.push(10);
                out.extend_from_slice(&n.to_le_bytes());
                return;
            }
            Self::DjiVoltageLimit(x) => (11, core::slice::from_ref(x)),
            Self::DjiFeedForward(x) => (12, core::slice::from_ref(x)),
            Self::DjiSpeedPid(x) => (13, x),
            Self::DjiAnglePid(x) => (14, x),
            Self::VescDuty(x) => (15, core::slice::from_ref(x)),
            Self::VescBrake(x) => (16, core::slice::from_ref(x)),
            Self::DmMit(x) => (17, x),
            Self::DmSpecial(k) => {
                out.push(18);
                out.push(*k);
                return;
            }
        };
        out.push(tag);
        for f in floats {
            f.encode(out);
        }
    }
}

impl<'a> Arbitrary<'a> for Op {
    fn arbitrary(u: &mut Unstructured<'a>) -> Result<Self> {
        Ok(match u8::arbitrary(u)? % 16 {
            0..=4 => {
                let id = match u8::arbitrary(u)? % 8 {
                    0..=3 => IdSel::Known(u8::arbitrary(u)?),
                    4 => IdSel::Standard(u16::arbitrary(u)? & 0x7FF),
                    5 => IdSel::Extended(u32::arbitrary(u)? & 0x1FFF_FFFF),
                    _ => IdSel::Flipped(u8::arbitrary(u)?),
                };
                let payload = Payload::arbitrary(u)?;
                let stamp = match u8::arbitrary(u)? % 8 {
                    0..=3 => Stamp::Now,
                    4 => Stamp::Before(u32::arbitrary(u)?),
                    5 | 6 => Stamp::After(u32::arbitrary(u)?),
                    _ => Stamp::Absolute(u64::arbitrary(u)?),
                };
                Self::Frame { id, payload, stamp }
            }
            5..=8 => Self::Tick,
            9 => Self::TickDt(u32::arbitrary(u)?),
            10 | 11 => Self::Advance(match u8::arbitrary(u)? % 8 {
                0..=3 => Step::Period,
                4 => Step::Micros(u16::arbitrary(u)?),
                5 => Step::Seconds(u32::arbitrary(u)?),
                6 => Step::Back(u32::arbitrary(u)?),
                _ => Step::To(u64::arbitrary(u)? >> 1),
            }),
            12 | 13 => Self::Set {
                motor: u8::arbitrary(u)?,
                set: Set::arbitrary(u)?,
            },
            14 => Self::Drain(u8::arbitrary(u)?),
            _ => Self::BusOff(bool::arbitrary(u)?),
        })
    }
}

impl Op {
    /// The bytes that decode to `self`.
    pub fn encode(&self, out: &mut Vec<u8>) {
        match self {
            Self::Frame { id, payload, stamp } => {
                out.push(0);
                match id {
                    IdSel::Known(i) => out.extend_from_slice(&[0, *i]),
                    IdSel::Standard(id) => {
                        out.push(4);
                        out.extend_from_slice(&id.to_le_bytes());
                    }
                    IdSel::Extended(id) => {
                        out.push(5);
                        out.extend_from_slice(&id.to_le_bytes());
                    }
                    IdSel::Flipped(i) => out.extend_from_slice(&[7, *i]),
                }
                payload.encode(out);
                match stamp {
                    Stamp::Now => out.push(0),
                    Stamp::Before(us) => {
                        out.push(4);
                        out.extend_from_slice(&us.to_le_bytes());
                    }
                    Stamp::After(us) => {
                        out.push(5);
                        out.extend_from_slice(&us.to_le_bytes());
                    }
                    Stamp::Absolute(t) => {
                        out.push(7);
                        out.extend_from_slice(&t.to_le_bytes());
                    }
                }
            }
            Self::Tick => out.push(5),
            Self::TickDt(us) => {
                out.push(9);
                out.extend_from_slice(&us.to_le_bytes());
            }
            Self::Advance(step) => {
                out.push(10);
                match step {
                    Step::Period => out.push(0),
                    Step::Micros(us) => {
                        out.push(4);
                        out.extend_from_slice(&us.to_le_bytes());
                    }
                    Step::Seconds(s) => {
                        out.push(5);
                        out.extend_from_slice(&s.to_le_bytes());
                    }
                    Step::Back(us) => {
                        out.push(6);
                        out.extend_from_slice(&us.to_le_bytes());
                    }
                    Step::To(t) => {
                        out.push(7);
                        out.extend_from_slice(&(t << 1).to_le_bytes());
                    }
                }
            }
            Self::Set { motor, set } => {
                out.push(12);
                out.push(*motor);
                set.encode(out);
            }
            Self::Drain(n) => out.extend_from_slice(&[14, *n]),
            Self::BusOff(off) => out.extend_from_slice(&[15, u8::from(*off)]),
        }
    }
}

/// Decodes operations until the input runs out.
pub fn decode_all(data: &[u8]) -> Vec<Op> {
    let mut u = Unstructured::new(data);
    let mut ops = Vec::new();
    while !u.is_empty() {
        match Op::arbitrary(&mut u) {
            Ok(op) => ops.push(op),
            Err(_) => break,
        }
    }
    ops
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encode_then_decode_gives_the_same_ops() {
        let ops = vec![
            Op::Frame {
                id: IdSel::Known(3),
                payload: Payload::full([1, 2, 3, 4, 5, 6, 7, 8]),
                stamp: Stamp::Before(250),
            },
            Op::Frame {
                id: IdSel::Extended(0x0910),
                payload: Payload {
                    dlc: 3,
                    remote: true,
                    data: [0; 8],
                },
                stamp: Stamp::Absolute(u64::MAX),
            },
            Op::Tick,
            Op::TickDt(1234),
            Op::Advance(Step::To(1 << 62)),
            Op::Advance(Step::Back(7)),
            Op::Set {
                motor: 4,
                set: Set::DmMit([
                    Float::of(1.5),
                    Float::Special(2),
                    Float::Fine(-3),
                    Float::Coarse(9),
                    Float::Bits(0x7F80_0001),
                ]),
            },
            Op::Set {
                motor: 1,
                set: Set::DjiRaw(-16384),
            },
            Op::Set {
                motor: 1,
                set: Set::DmSpecial(2),
            },
            Op::Drain(2),
            Op::BusOff(true),
        ];
        let mut bytes = Vec::new();
        for op in &ops {
            op.encode(&mut bytes);
        }
        assert_eq!(decode_all(&bytes), ops);
    }
}
