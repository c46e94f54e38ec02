//! Writes the seed corpus, `fuzz/corpus/<target>/seed-*`: a few realistic inputs per target (valid
//! frames as each device sends them, a tick rhythm, typical targets), spelled in each target's
//! input format. libFuzzer starts from these and mutates them.
//!
//! Run `fuzz/run --seeds` (or, in `fuzz/`, `cargo run --example seeds`): it rewrites the seed
//! files and leaves any other file alone. See README.md.

use rc10_fuzz::input::{Float, Payload};
use rc10_fuzz::ops::{IdSel, Op, Set, Stamp, Step};
use std::path::{Path, PathBuf};

fn main() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("corpus");
    dji(&root.join("dji_feedback"));
    vesc(&root.join("vesc_status"));
    dm(&root.join("dm_feedback"));
    dbus(&root.join("dbus"));
    sbus(&root.join("sbus"));
    ppm(&root.join("ppm"));
    telemetry(&root.join("telemetry"));
    bus(&root.join("bus_dispatch"));
}

/// Writes `corpus/<target>/seed-<name>` (only `seed-*` files are committed: see .gitignore).
fn write(dir: &Path, name: &str, bytes: &[u8]) {
    std::fs::create_dir_all(dir).expect("corpus directory");
    let path = dir.join(format!("seed-{name}"));
    std::fs::write(&path, bytes).expect("seed file");
    println!("{} ({} bytes)", path.display(), bytes.len());
}

fn f32s(out: &mut Vec<u8>, values: &[f32]) {
    for v in values {
        Float::of(*v).encode(out);
    }
}

/// A DJI feedback payload: angle, rotor rpm, current, temperature.
fn dji_payload(angle: u16, rpm: i16, current: i16, temperature: u8) -> Payload {
    let [a0, a1] = angle.to_be_bytes();
    let [r0, r1] = rpm.to_be_bytes();
    let [c0, c1] = current.to_be_bytes();
    Payload::full([a0, a1, r0, r1, c0, c1, temperature, 0])
}

fn dji(dir: &Path) {
    // (model index, id, rotor rpm): M3508 id 1, M2006 id 8, GM6020 voltage id 1, current id 7.
    for (model, id, rpm, name) in [
        (0u8, 0u8, 3000i16, "m3508"),
        (1, 7, -5000, "m2006"),
        (2, 0, 60, "gm6020_voltage"),
        (3, 6, -120, "gm6020_current"),
    ] {
        let mut b = vec![model, id];
        // A speed target, then twenty 1 ms periods of feedback and ticks.
        b.push(7);
        f32s(&mut b, &[100.0]);
        b.push(0); // set_target_rpm
        let mut angle: i32 = 1000;
        for k in 0..20 {
            b.extend_from_slice(&[0, 0, 0, 0]); // a frame on the feedback ID
            dji_payload(angle as u16, rpm, 800, 36).encode(&mut b);
            b.extend_from_slice(&(if k % 5 == 4 { 40i16 } else { 0 }).to_le_bytes()); // read late
            b.push(5);
            b.extend_from_slice(&1000u16.to_le_bytes()); // tick 1 ms later
            angle = (angle + i32::from(rpm) * 8192 / 60_000).rem_euclid(8192);
        }
        // A short frame and an angle out of range: both rejected.
        b.extend_from_slice(&[0, 0, 0, 0]);
        Payload {
            dlc: 6,
            ..dji_payload(10, 0, 0, 30)
        }
        .encode(&mut b);
        b.extend_from_slice(&[0, 0]);
        b.extend_from_slice(&[0, 0, 0, 0]);
        dji_payload(8192, 0, 0, 30).encode(&mut b);
        b.extend_from_slice(&[0, 0]);
        write(dir, name, &b);
    }
}

fn vesc(dir: &Path) {
    // Controller 7, 7 pole pairs, direct drive, STATUS 1 and 4.
    let mut b = vec![7, 7, 0, 0, 0b1000];
    let frame = |b: &mut Vec<u8>, packet_index: u8, payload: Payload| {
        b.push(packet_index * 4); // tag: a frame, packet from the table
        b.extend_from_slice(&[0, 1, 1, 1]); // table packet, own controller, no high bits, extended
        payload.encode(b);
        b.extend_from_slice(&1000u16.to_le_bytes());
    };
    // STATUS: 7000 eRPM, 12.3 A, duty 0.25.
    let mut status = [0u8; 8];
    status[..4].copy_from_slice(&7000i32.to_be_bytes());
    status[4..6].copy_from_slice(&123i16.to_be_bytes());
    status[6..].copy_from_slice(&250i16.to_be_bytes());
    frame(&mut b, 0, Payload::full(status));
    // STATUS_4: MOSFET 41.5 °C, motor 55.0 °C, 2.0 A in, PID position 90°.
    let mut s4 = [0u8; 8];
    s4[..2].copy_from_slice(&415i16.to_be_bytes());
    s4[2..4].copy_from_slice(&550i16.to_be_bytes());
    s4[4..6].copy_from_slice(&20i16.to_be_bytes());
    s4[6..].copy_from_slice(&4500i16.to_be_bytes());
    frame(&mut b, 3, Payload::full(s4));
    frame(&mut b, 1, Payload::full([0; 8])); // STATUS_2, not broadcast by this VESC
    // Commands: duty 0.25, 12.5 A, brake 5 A, 3500 eRPM, 270°.
    for (kind, x) in [(0u8, 0.25f32), (1, 12.5), (2, 5.0), (3, 3500.0), (4, 270.0)] {
        b.extend_from_slice(&[3, 7, kind]);
        f32s(&mut b, &[x]);
    }
    write(dir, "status_and_commands", &b);
}

fn dm(dir: &Path) {
    // CAN ID 1, master 0x11, factory ranges 12.5 rad, 30 rad/s, 10 N·m.
    let mut b = Vec::new();
    b.extend_from_slice(&1u16.to_le_bytes());
    b.extend_from_slice(&0x11u16.to_le_bytes());
    f32s(&mut b, &[12.5, 30.0, 10.0]);
    let mut p: u16 = 0x7FFF;
    for k in 0..12u16 {
        // Enabled (state 1), id 1; position moving, velocity and torque near zero.
        let [p0, p1] = p.to_be_bytes();
        b.extend_from_slice(&[0, 0x80, 0, 0]); // a frame on the master ID, this motor's nibble
        Payload::full([0x11, p0, p1, 0x80, 0x07, 0xFF, 30, 32]).encode(&mut b);
        b.extend_from_slice(&1000u16.to_le_bytes());
        b.push(5); // a tick, with a target
        b.extend_from_slice(&1000u16.to_le_bytes());
        f32s(&mut b, &[[60.0, 90.0, 45.0, 1.5][usize::from(k % 4)]]);
        b.push((k % 4) as u8);
        p = p.wrapping_add(12000); // crosses the end of the range
    }
    // MIT commands to pack: a typical one, and one with every field at its end.
    b.push(7);
    f32s(&mut b, &[1.0, 2.0, 20.0, 1.0, 0.5, 12.5, 30.0, 10.0]);
    b.push(7);
    f32s(&mut b, &[12.5, 30.0, 500.0, 5.0, 9.0, 12.5, 30.0, 10.0]);
    write(dir, "feedback_and_mit", &b);
}

/// A DR16 frame: four sticks, right and left switch, mouse, keys.
fn dbus_frame(sticks: [u16; 4], right: u8, left: u8, mouse: [i16; 3], keys: u16) -> [u8; 18] {
    let mut bits: u64 = 0;
    for (i, s) in sticks.iter().enumerate() {
        bits |= u64::from(*s) << (11 * i);
    }
    bits |= u64::from(right) << 44 | u64::from(left) << 46;
    let mut f = [0u8; 18];
    f[..6].copy_from_slice(&bits.to_le_bytes()[..6]);
    for (k, m) in mouse.iter().enumerate() {
        f[6 + 2 * k..8 + 2 * k].copy_from_slice(&m.to_le_bytes());
    }
    f[14..16].copy_from_slice(&keys.to_le_bytes());
    f[16..18].copy_from_slice(&1024u16.to_le_bytes());
    f
}

/// A byte stream: each frame's bytes 110 µs apart, frames 12 ms apart.
fn stream(frames: &[&[u8]]) -> Vec<u8> {
    let mut b = vec![1];
    for f in frames {
        for (i, byte) in f.iter().enumerate() {
            b.push(if i == 0 { 0xFB } else { 110 }); // a 12 ms gap, then 110 µs
            b.push(*byte);
        }
    }
    b.extend_from_slice(&[0xFF, 150]); // the signal 150 ms later: lost
    b
}

fn dbus(dir: &Path) {
    let centre = dbus_frame([1024; 4], 1, 3, [0; 3], 0);
    let moving = dbus_frame([1684, 364, 1354, 694], 3, 2, [-5, 300, 1], 0x0011);
    let mut whole = vec![0];
    whole.extend_from_slice(&moving);
    write(dir, "frame", &whole);
    write(
        dir,
        "stream",
        &stream(&[&centre, &moving, &centre[..9], &moving]),
    );
}

fn sbus_frame(channels: [u16; 16], flags: u8) -> [u8; 25] {
    let mut f = [0u8; 25];
    f[0] = 0x0F;
    for (i, ch) in channels.iter().enumerate() {
        for k in 0..11 {
            if ch >> k & 1 == 1 {
                let bit = 11 * i + k;
                f[1 + bit / 8] |= 1 << (bit % 8);
            }
        }
    }
    f[23] = flags;
    f
}

fn sbus(dir: &Path) {
    let mut ramp = [992u16; 16];
    for (i, c) in ramp.iter_mut().enumerate() {
        *c = 172 + 100 * i as u16;
    }
    let centre = sbus_frame([992; 16], 0);
    let lost_one = sbus_frame(ramp, 0b0100);
    let failsafe = sbus_frame([992; 16], 0b1000);
    let mut whole = vec![0];
    whole.extend_from_slice(&lost_one);
    write(dir, "frame", &whole);
    write(
        dir,
        "stream",
        &stream(&[&centre, &lost_one, &failsafe, &centre]),
    );
}

fn ppm(dir: &Path) {
    // Tags: 0 a width (800 + n), 5 a sync (2700 + n), 7 read later.
    let width = |b: &mut Vec<u8>, us: u16| {
        b.push(0);
        b.extend_from_slice(&(us - 800).to_le_bytes());
    };
    let sync = |b: &mut Vec<u8>| {
        b.push(5);
        b.extend_from_slice(&3300u16.to_le_bytes());
    };
    let mut b = Vec::new();
    sync(&mut b);
    for frame in 0..3u16 {
        for ch in 0..8u16 {
            width(&mut b, 1100 + 100 * ch + frame * 10);
        }
        sync(&mut b);
    }
    for us in [1500u16, 1500] {
        width(&mut b, us); // a 2-channel frame for the second receiver
    }
    sync(&mut b);
    b.push(6);
    b.extend_from_slice(&300u32.to_le_bytes()); // noise
    b.push(7);
    b.extend_from_slice(&20_000u16.to_le_bytes()); // 160 ms later: lost
    write(dir, "frames", &b);
}

fn telemetry(dir: &Path) {
    let mut b = vec![3];
    f32s(&mut b, &[300.0, -12.5, f32::NAN]);
    b.extend_from_slice(&64u16.to_le_bytes());
    b.extend_from_slice(&2u32.to_le_bytes());
    b.push(3);
    b.extend_from_slice(b"rpm");
    write(dir, "rpm", &b);
}

/// A bus seed: `ops`, encoded.
fn ops_bytes(ops: &[Op]) -> Vec<u8> {
    let mut b = Vec::new();
    for op in ops {
        op.encode(&mut b);
    }
    b
}

fn frame(id: IdSel, payload: Payload) -> Op {
    Op::Frame {
        id,
        payload,
        stamp: Stamp::Now,
    }
}

fn std_id(id: u16) -> IdSel {
    IdSel::Standard(id)
}

fn ext_id(id: u32) -> IdSel {
    IdSel::Extended(id)
}

/// Feedback from every motor of the fleet (`rc10_fuzz::fleet`), as each device sends it.
fn all_feedback(ops: &mut Vec<Op>, k: u16, temperature: u8) {
    let angle = (k * 300) % 8192;
    for id in 0x201..=0x20B {
        ops.push(frame(
            std_id(id),
            dji_payload(angle, 1200, 500, temperature),
        ));
    }
    let mut status = [0u8; 8];
    status[..4].copy_from_slice(&7000i32.to_be_bytes());
    for vesc in [0x10u32, 0x11] {
        ops.push(frame(ext_id(0x0900 | vesc), Payload::full(status)));
    }
    // Damiao: enabled, position mid-range.
    ops.push(frame(
        std_id(0x11),
        Payload::full([0x11, 0x80, 0x00, 0x80, 0x07, 0xFF, 30, 31]),
    ));
    ops.push(frame(
        std_id(0x12),
        Payload::full([0x12, 0x80, 0x00, 0x80, 0x07, 0xFF, 30, 31]),
    ));
}

fn set(motor: u8, set: Set) -> Op {
    Op::Set { motor, set }
}

fn f(x: f32) -> Float {
    Float::of(x)
}

fn bus(dir: &Path) {
    // Motor indices (registration order, rc10_fuzz::fleet::Fleet::motors): 0 M3508#1,
    // 1 M3508#2, 2 VESC 0x10, 3 M2006#3, 4 M2006#4, 5 DM 0x01, 6 GM6020 current #1,
    // 7 GM6020 current #2, 8 M3508#7, 9 VESC 0x11, 10 M2006#8, 11 GM6020 voltage #5,
    // 12 DM 0x02, 13 GM6020 voltage #6 (±30000), 14 GM6020 current #7.

    // 1. Every motor online in a closed-loop mode, then a power cut, then feedback returns.
    let mut ops = vec![
        set(0, Set::Rpm(f(300.0))),
        set(1, Set::TotalAngle(f(720.0))),
        set(2, Set::Rpm(f(1000.0))),
        set(3, Set::Angle(f(90.0))),
        set(5, Set::Rpm(f(60.0))),
        set(6, Set::Angle(f(-45.0))),
        set(9, Set::Rpm(f(0.0))),
        set(11, Set::Rpm(f(120.0))),
        set(12, Set::TotalAngle(f(90.0))),
        set(13, Set::Angle(f(180.0))),
    ];
    for k in 0..15 {
        all_feedback(&mut ops, k, 40);
        ops.push(Op::Advance(Step::Period));
        ops.push(Op::Tick);
        ops.push(Op::Drain(9));
    }
    ops.push(Op::Advance(Step::Micros(150)));
    for _ in 0..4 {
        ops.push(Op::Advance(Step::Micros(40_000)));
        ops.push(Op::Tick);
    }
    all_feedback(&mut ops, 99, 40);
    ops.push(Op::Tick);
    write(dir, "closed_loop_and_power_cut", &ops_bytes(&ops));

    // 2. Open loop: currents and voltages beyond range, user limits, a hot motor, raw counts.
    let mut ops = vec![
        set(0, Set::Current(f(25.0))),
        set(0, Set::CurrentLimit(f(5.0))),
        set(3, Set::Current(f(-30.0))),
        set(6, Set::Torque(f(3.0))),
        set(8, Set::DjiRaw(-16384)),
        set(11, Set::Voltage(f(30.0))),
        set(13, Set::DjiVoltageLimit(f(12.0))),
        set(13, Set::DjiRaw(30000)),
        set(14, Set::Current(f(f32::INFINITY))),
        set(2, Set::Current(f(80.0))),
        set(9, Set::Torque(f(20.0))),
        set(9, Set::CurrentLimit(f(10.0))),
    ];
    for k in 0..6 {
        all_feedback(&mut ops, k, if k < 3 { 35 } else { 110 });
        ops.push(Op::Advance(Step::Period));
        ops.push(Op::Tick);
        ops.push(Op::Drain(9));
    }
    write(dir, "open_loop_limits_and_derating", &ops_bytes(&ops));

    // 3. VESC and Damiao modes: duty, brake, position, raw MIT, specials.
    let mut ops = vec![
        set(2, Set::VescDuty(f(0.5))),
        set(9, Set::VescBrake(f(-8.0))),
        set(5, Set::DmMit([f(1.0), f(2.0), f(20.0), f(1.0), f(0.5)])),
        set(12, Set::DmSpecial(0)),
    ];
    for k in 0..4 {
        all_feedback(&mut ops, k, 30);
        ops.push(Op::Tick);
        ops.push(Op::Advance(Step::Period));
    }
    ops.extend([
        set(2, Set::Angle(f(-90.0))),
        set(12, Set::FeedForwardTorque(f(2.0))),
        set(12, Set::Rpm(f(30.0))),
        set(5, Set::Disable),
        Op::Tick,
    ]);
    write(dir, "vesc_and_damiao_modes", &ops_bytes(&ops));

    // 4. Clock and stamps out of order: frames stamped later and earlier, the clock going
    // backwards and jumping ahead, explicit dt, bus-off.
    let mut ops = vec![set(0, Set::Rpm(f(200.0))), set(5, Set::Rpm(f(10.0)))];
    all_feedback(&mut ops, 1, 30);
    ops.extend([
        Op::Tick,
        Op::Frame {
            id: IdSel::Known(0),
            payload: dji_payload(500, 100, 0, 30),
            stamp: Stamp::After(3_600_000_000),
        },
        Op::Advance(Step::Period),
        Op::Tick,
        Op::Advance(Step::Back(5000)),
        Op::Tick,
        Op::Frame {
            id: IdSel::Known(0),
            payload: dji_payload(600, 100, 0, 30),
            stamp: Stamp::Absolute(u64::MAX),
        },
        Op::TickDt(0),
        Op::Advance(Step::Seconds(86_400)),
        Op::BusOff(true),
        Op::Tick,
        Op::BusOff(false),
        Op::Tick,
    ]);
    write(dir, "time_out_of_order", &ops_bytes(&ops));
}
