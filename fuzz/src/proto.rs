//! The wire formats, decoded here independently of rc10-core, from the protocol descriptions
//! (SPEC.md "Protocol and physical facts", DJI / VESC / Damiao documentation as summarised in
//! the drivers' module docs). The fuzz targets compare rc10-core against these.

use rc10_core::can::CanFrame;

/// Rotor counts per turn of a DJI encoder.
pub const DJI_COUNTS: u16 = 8192;

/// A DJI ESC feedback frame (C620 / C610 / GM6020): DLC 8, big-endian.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DjiFeedback {
    /// Rotor angle, 0–8191 in a valid frame.
    pub angle: u16,
    /// Rotor speed, rpm.
    pub rpm: i16,
    /// Torque current, on the command scale.
    pub current: i16,
    /// Temperature, °C (not on the C610).
    pub temperature: u8,
}

/// The DJI feedback fields of `frame`, if it is a data frame with DLC 8 (any ID).
pub fn dji_feedback(frame: &CanFrame) -> Option<DjiFeedback> {
    let d = data8(frame)?;
    Some(DjiFeedback {
        angle: u16::from_be_bytes([d[0], d[1]]),
        rpm: i16::from_be_bytes([d[2], d[3]]),
        current: i16::from_be_bytes([d[4], d[5]]),
        temperature: d[6],
    })
}

/// The eight bytes of a DLC-8 data frame.
pub fn data8(frame: &CanFrame) -> Option<[u8; 8]> {
    if frame.is_remote() {
        return None;
    }
    frame.data().try_into().ok()
}

/// The int16 big-endian value in slot `index` (0–3) of a DJI command frame's eight bytes.
pub fn dji_slot(data: &[u8; 8], index: usize) -> i16 {
    i16::from_be_bytes([data[2 * index], data[2 * index + 1]])
}

/// A VESC `comm_can` frame: extended ID `(packet << 8) | controller`, bits 16–28 zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VescId {
    /// Packet number.
    pub packet: u8,
    /// Controller id.
    pub controller: u8,
}

/// The VESC packet and controller of `frame`, if its ID has the VESC shape.
pub fn vesc_id(frame: &CanFrame) -> Option<VescId> {
    let id = frame.raw_id();
    if !frame.is_extended() || id >> 16 != 0 {
        return None;
    }
    Some(VescId {
        packet: (id >> 8) as u8,
        controller: id as u8,
    })
}

/// VESC packet numbers (VESC firmware `CAN_PACKET_ID`).
pub mod vesc_packet {
    /// i32 duty × 100 000.
    pub const SET_DUTY: u8 = 0;
    /// i32 mA.
    pub const SET_CURRENT: u8 = 1;
    /// i32 mA of brake current.
    pub const SET_CURRENT_BRAKE: u8 = 2;
    /// i32 eRPM.
    pub const SET_RPM: u8 = 3;
    /// i32 degrees × 1 000 000.
    pub const SET_POS: u8 = 4;
    /// i32 eRPM, i16 current × 10, i16 duty × 1000.
    pub const STATUS: u8 = 9;
    /// Amp-hours.
    pub const STATUS_2: u8 = 14;
    /// Watt-hours.
    pub const STATUS_3: u8 = 15;
    /// i16 MOSFET °C × 10, i16 motor °C × 10, i16 input current × 10, i16 PID position × 50.
    pub const STATUS_4: u8 = 16;
    /// Tachometer, input voltage.
    pub const STATUS_5: u8 = 27;
}

/// The i32 big-endian payload of a VESC command frame (DLC 4).
pub fn vesc_command_value(frame: &CanFrame) -> Option<i32> {
    if frame.is_remote() {
        return None;
    }
    let d: [u8; 4] = frame.data().try_into().ok()?;
    Some(i32::from_be_bytes(d))
}

/// Damiao MIT command fields as raw codes (D0–D7 big-endian bit fields: p 16, v 12, kp 12,
/// kd 12, t 12).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MitCodes {
    /// Position code, 16 bits.
    pub p: u16,
    /// Velocity code, 12 bits.
    pub v: u16,
    /// kp code, 12 bits (0–500 N·m/rad).
    pub kp: u16,
    /// kd code, 12 bits (0–5 N·m·s/rad).
    pub kd: u16,
    /// Torque code, 12 bits.
    pub t: u16,
}

/// Splits an MIT command's eight bytes into its five fields.
pub fn mit_codes(d: &[u8; 8]) -> MitCodes {
    let b = |i: usize| u16::from(d[i]);
    MitCodes {
        p: b(0) << 8 | b(1),
        v: b(2) << 4 | b(3) >> 4,
        kp: (b(3) & 0xF) << 8 | b(4),
        kd: b(5) << 4 | b(6) >> 4,
        t: (b(6) & 0xF) << 8 | b(7),
    }
}

/// A code of `bits` bits as a value in `[min, max]` (Damiao's `uint_to_float`).
pub fn code_to_value(code: u16, min: f32, max: f32, bits: u32) -> f64 {
    let full = f64::from((1u32 << bits) - 1);
    f64::from(code) * (f64::from(max) - f64::from(min)) / full + f64::from(min)
}

/// One code step of a `bits`-bit field over `[min, max]`.
pub fn code_step(min: f32, max: f32, bits: u32) -> f64 {
    (f64::from(max) - f64::from(min)) / f64::from((1u32 << bits) - 1)
}

/// A Damiao special command: `FF FF FF FF FF FF FF xx`, xx = FC enable, FD disable, FE save
/// zero, FB clear error. The motor acts on these whatever it was sent as, so an MIT command
/// must never take this shape.
pub fn dm_special(d: &[u8; 8]) -> Option<u8> {
    (d[..7].iter().all(|b| *b == 0xFF) && (0xFB..=0xFE).contains(&d[7])).then_some(d[7])
}

/// Damiao feedback: D0 = motor id (low nibble) | state << 4, position 16 bits, velocity 12,
/// torque 12, D6 MOSFET °C, D7 rotor °C.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DmFeedback {
    /// Low nibble of the motor's CAN ID.
    pub id_nibble: u8,
    /// State code.
    pub state: u8,
    /// Position code, 16 bits.
    pub p: u16,
    /// Velocity code, 12 bits.
    pub v: u16,
    /// Torque code, 12 bits.
    pub t: u16,
    /// MOSFET temperature, °C.
    pub mos: u8,
    /// Rotor temperature, °C.
    pub rotor: u8,
}

/// The Damiao feedback fields of a DLC-8 data frame.
pub fn dm_feedback(frame: &CanFrame) -> Option<DmFeedback> {
    let d = data8(frame)?;
    let b = |i: usize| u16::from(d[i]);
    Some(DmFeedback {
        id_nibble: d[0] & 0x0F,
        state: d[0] >> 4,
        p: b(1) << 8 | b(2),
        v: b(3) << 4 | b(4) >> 4,
        t: (b(4) & 0xF) << 8 | b(5),
        mos: d[6],
        rotor: d[7],
    })
}

/// `x` clamped into `[min, max]`, NaN taken as 0 (then clamped), in f64.
pub fn clamp_f64(x: f32, min: f32, max: f32) -> f64 {
    let x = if x.is_nan() { 0.0 } else { f64::from(x) };
    x.clamp(f64::from(min), f64::from(max))
}
