//! The `bus_dispatch` target: runs [`Op`]s against a [`Fleet`] on one [`Bus`] and checks,
//! after every operation, what must hold whatever the input:
//!
//! - nothing panics (libFuzzer catches it);
//! - a received frame goes to the motor whose feedback ID it carries by the protocol, or to
//!   nobody; the motor accepts it exactly when the protocol says it is well formed; the bus
//!   counts it once (received, and unmatched or rejected where it was);
//! - a motor is offline when its last accepted feedback is older than its timeout, and
//!   online when it is not (timestamps from the future count as now, never longer);
//! - every tick packs exactly one command per motor, on the protocol's ID, and nothing else;
//!   DJI slots no motor uses are zero;
//! - every packed command is within its ESC's range (C620 ±16384, C610 ±10000, GM6020
//!   current ±16384, GM6020 voltage ± its configured limit; VESC within its configured
//!   current, brake, speed, duty and position ranges; Damiao fields decoded from their bit
//!   widths within the motor's ranges, and never the shape of a special command unless one
//!   is meant), within the user's current limit and thermal derating where they apply, the
//!   right packet for the mode, and with the sign of the command;
//! - an offline motor commands exactly zero (DJI raw 0, VESC `SET_CURRENT 0`, Damiao zero
//!   gains and the torque code nearest zero), and reports a zero command;
//! - a NaN or infinite target is refused, and a refused call changes neither mode nor target;
//! - every value a motor reports is finite (angles in [0, 360); a DJI angle target too);
//! - the paced `dt` stays within [period / 2, 10 periods]; transmit accounts for every frame
//!   and queues nothing while bus-off; no frame is undeclared or overflows the batch.

use crate::fleet::{DjiInfo, DmInfo, Fleet, MotorRef, VescInfo, interesting_ids};
use crate::ops::{IdSel, Op, Set, Stamp, Step};
use crate::proto::{self, vesc_packet as vp};
use rc10_core::bus::{Bus, Dispatch, TickPacer};
use rc10_core::can::loopback::TxQueue;
use rc10_core::can::{
    BusStatus, CanFrame, CanTransmit, ErrorState, ExtendedId, Id, SendError, StandardId,
};
use rc10_core::motor::dm::{self, DmSpecial, DmStatus, MitCommand};
use rc10_core::motor::{ControlMode, MotorState};
use rc10_core::node::TxBatch;
use rc10_core::pid::PidConfig;
use rc10_core::time::{Duration, Instant};

/// Where the clock starts, µs.
pub const START_US: u64 = 1_000_000;

/// Per-motor bookkeeping of what the application and the bus did to it.
#[derive(Debug, Clone)]
struct Track {
    /// The newest feedback stamp the motor took (frames stamped before it do not move it
    /// back), clamped to each tick's time when it is later, as the motor's liveness check
    /// does. A DJI motor refuses a frame stamped before it.
    newest: Option<u64>,
    /// Whether feedback that keeps the motor online was accepted since the last tick: then
    /// the motor's last feedback time is `newest`.
    fresh: Option<u64>,
    /// The time of the first tick after the last accepted feedback: from then on the motor's
    /// last feedback time is at most this.
    silent_since: Option<u64>,
    /// The user's current (voltage) limit.
    user_limit: f32,
    /// Damiao: the last raw MIT command set.
    mit: MitCommand,
    /// Damiao: the feed-forward torque.
    ff_nm: f32,
    /// Damiao: special commands asked for and not yet sent, oldest first (one goes out a
    /// tick while online; a kind asked for again keeps its place).
    special: std::collections::VecDeque<DmSpecial>,
    /// Damiao: ticks in a row it has been offline (auto-enable probes on every
    /// `PROBE_TICKS`-th).
    offline_ticks: u32,
}

impl Track {
    const NEW: Self = Self {
        newest: None,
        fresh: None,
        silent_since: None,
        user_limit: f32::INFINITY,
        mit: MitCommand::ZERO_TORQUE,
        ff_nm: 0.0,
        special: std::collections::VecDeque::new(),
        offline_ticks: 0,
    };
}

/// The fleet on its bus, a clock, the scheduler's pacer, a TX queue and the bookkeeping.
pub struct Harness<'a> {
    bus: Bus<'a, { crate::fleet::CAPACITY }>,
    motors: Vec<MotorRef<'a>>,
    ids: Vec<Id>,
    track: Vec<Track>,
    now: u64,
    pacer: TickPacer,
    batch: TxBatch,
    tx: TxQueue<3>,
}

impl<'a> Harness<'a> {
    /// The fleet registered on a fresh bus, at [`START_US`].
    pub fn new(fleet: &'a Fleet) -> Self {
        let motors = fleet.motors();
        Self {
            bus: fleet.bus(),
            track: vec![Track::NEW; motors.len()],
            motors,
            ids: interesting_ids(fleet),
            now: START_US,
            pacer: TickPacer::new(Duration::from_millis(1)),
            batch: TxBatch::new(),
            tx: TxQueue::new(),
        }
    }

    /// Runs one operation and checks the invariants it concerns.
    pub fn run(&mut self, op: &Op) {
        match *op {
            Op::Frame { id, payload, stamp } => {
                let id = self.id(id);
                if let Some(frame) = payload.frame(id) {
                    let stamp = match stamp {
                        Stamp::Now => self.now,
                        Stamp::Before(us) => self.now.saturating_sub(u64::from(us)),
                        Stamp::After(us) => self.now.saturating_add(u64::from(us)),
                        Stamp::Absolute(t) => t,
                    };
                    self.receive(&frame, stamp);
                }
            }
            Op::Tick => {
                let paced = self.pacer.on_tick(Instant::from_ticks(self.now));
                // f32 seconds from integer µs: allow the last bit.
                assert!(
                    (0.0005 * (1.0 - 1e-6)..=0.010 * (1.0 + 1e-6)).contains(&paced.dt_s),
                    "paced dt {} outside [period/2, 10 periods]",
                    paced.dt_s
                );
                if paced.resync {
                    self.bus.record_skipped_ticks(paced.skipped);
                }
                self.tick(paced.dt_s);
            }
            Op::TickDt(us) => self.tick(us as f32 * 1e-6),
            Op::Advance(step) => {
                self.now = match step {
                    Step::Period => self.now + 1000,
                    Step::Micros(us) => self.now + u64::from(us),
                    Step::Seconds(s) => self.now + u64::from(s) * 1_000_000,
                    Step::Back(us) => self.now.saturating_sub(u64::from(us)),
                    Step::To(t) => t,
                }
                .min(u64::MAX >> 1);
            }
            Op::Set { motor, set } => {
                let i = usize::from(motor) % self.motors.len();
                self.set(i, set);
            }
            Op::Drain(n) => {
                for _ in 0..n {
                    if self.tx.pop().is_none() {
                        break;
                    }
                }
            }
            Op::BusOff(off) => self.tx.set_status(BusStatus {
                state: if off {
                    ErrorState::BusOff
                } else {
                    ErrorState::Active
                },
                ..BusStatus::default()
            }),
        }
    }

    fn id(&self, sel: IdSel) -> Id {
        let known = |i: u8| self.ids[usize::from(i) % self.ids.len()];
        match sel {
            IdSel::Known(i) => known(i),
            IdSel::Standard(id) => Id::Standard(StandardId::new(id & 0x7FF).expect("11-bit")),
            IdSel::Extended(id) => Id::Extended(ExtendedId::new(id & 0x1FFF_FFFF).expect("29-bit")),
            IdSel::Flipped(i) => match known(i) {
                Id::Standard(s) => {
                    Id::Extended(ExtendedId::new(u32::from(s.as_raw())).expect("29-bit"))
                }
                Id::Extended(e) => {
                    Id::Standard(StandardId::new((e.as_raw() & 0x7FF) as u16).expect("11-bit"))
                }
            },
        }
    }

    /// `Bus::dispatch`, checked against the protocol's routing and validity rules.
    fn receive(&mut self, frame: &CanFrame, stamp: u64) {
        let before = self.bus.stats().snapshot();
        let result = self.bus.dispatch(frame, Instant::from_ticks(stamp));
        let after = self.bus.stats().snapshot();
        assert_eq!(after.rx_frames, before.rx_frames.wrapping_add(1));
        let owners: Vec<usize> = (0..self.motors.len())
            .filter(|i| self.motors[*i].listens_to(frame))
            .collect();
        assert!(owners.len() <= 1, "{frame:?} belongs to motors {owners:?}");
        let owner = owners.first().copied();
        let (claimed, accepted) = match result {
            Dispatch::Handled(i) => (Some(i), true),
            Dispatch::Rejected(i, _) => (Some(i), false),
            Dispatch::Unmatched => (None, false),
        };
        assert_eq!(
            claimed, owner,
            "{frame:?} routed to {claimed:?}, the protocol says {owner:?}"
        );
        assert_eq!(
            after.rx_unmatched,
            before.rx_unmatched.wrapping_add(u32::from(owner.is_none()))
        );
        assert_eq!(
            after.rx_rejected,
            before
                .rx_rejected
                .wrapping_add(u32::from(owner.is_some() && !accepted))
        );
        let Some(i) = owner else { return };
        let keeps_online = match self.motors[i] {
            MotorRef::Dji(..) => {
                // Well formed, and not stamped before the newest feedback taken.
                let in_order = self.track[i].newest.is_none_or(|n| stamp >= n);
                let valid = in_order
                    && proto::dji_feedback(frame).is_some_and(|f| f.angle < proto::DJI_COUNTS);
                assert_eq!(
                    accepted, valid,
                    "DJI feedback {frame:?}: accepted {accepted}"
                );
                valid
            }
            MotorRef::Dm(_, info) => {
                let valid = proto::dm_feedback(frame)
                    .is_some_and(|f| u16::from(f.id_nibble) == info.can_id & 0x0F);
                assert_eq!(
                    accepted, valid,
                    "DM feedback {frame:?}: accepted {accepted}"
                );
                valid
            }
            MotorRef::Vesc(..) => {
                let packet = proto::vesc_id(frame).map(|v| v.packet);
                if matches!(packet, Some(vp::STATUS | vp::STATUS_4)) {
                    let valid = proto::data8(frame).is_some();
                    assert_eq!(
                        accepted, valid,
                        "VESC status {frame:?}: accepted {accepted}"
                    );
                }
                accepted && packet == Some(vp::STATUS)
            }
        };
        if keeps_online {
            let t = &mut self.track[i];
            let newest = t.newest.map_or(stamp, |n| n.max(stamp));
            t.newest = Some(newest);
            t.fresh = Some(newest);
        }
        check_state(&self.motors[i].motor().state(), i);
    }

    /// An application call. Contract (`TargetError`): a NaN or infinite target is refused,
    /// and a refused call leaves mode and target as they were.
    fn set(&mut self, i: usize, set: Set) {
        let m = self.motors[i];
        let motor = m.motor();
        let before = motor.state();
        let t = &mut self.track[i];
        // (result, whether the call sets a target from a non-finite value)
        let (result, non_finite_target) = match set {
            Set::Current(x) => (motor.set_target_current(x.value()), !x.value().is_finite()),
            Set::Voltage(x) => (motor.set_target_voltage(x.value()), !x.value().is_finite()),
            Set::Rpm(x) => (motor.set_target_rpm(x.value()), !x.value().is_finite()),
            Set::Angle(x) => (
                motor.set_target_angle_deg(x.value()),
                !x.value().is_finite(),
            ),
            Set::TotalAngle(x) => {
                let r = motor.set_target_total_angle_deg(x.value());
                (r, !x.value().is_finite())
            }
            Set::Torque(x) => {
                let nm = x.value();
                let r = motor.set_target_torque_nm(nm);
                if r.is_ok() {
                    t.mit = MitCommand {
                        torque_nm: nm,
                        ..MitCommand::ZERO_TORQUE
                    };
                }
                (r, !nm.is_finite())
            }
            Set::FeedForwardTorque(x) => {
                let r = motor.set_feed_forward_torque_nm(x.value());
                if r.is_ok() {
                    t.ff_nm = x.value();
                }
                (r, false)
            }
            Set::CurrentLimit(x) => {
                let r = motor.set_current_limit_amps(x.value());
                if r.is_ok() {
                    t.user_limit = x.value();
                }
                (r, false)
            }
            Set::Home(x) => (motor.set_total_angle_here_deg(x.value()), false),
            Set::Disable => {
                motor.disable();
                (Ok(()), false)
            }
            Set::DjiRaw(n) => match m {
                MotorRef::Dji(d, _) => (d.set_target_raw(n), false),
                _ => (Ok(()), false),
            },
            Set::DjiVoltageLimit(x) => match m {
                MotorRef::Dji(d, _) => {
                    let r = d.set_voltage_limit_volts(x.value());
                    if r.is_ok() {
                        t.user_limit = x.value();
                    }
                    (r, false)
                }
                _ => (Ok(()), false),
            },
            Set::DjiFeedForward(x) => match m {
                MotorRef::Dji(d, _) => (d.set_feed_forward(x.value()), false),
                _ => (Ok(()), false),
            },
            Set::DjiSpeedPid(g) | Set::DjiAnglePid(g) => {
                if let MotorRef::Dji(d, _) = m {
                    let c = PidConfig::new(g[0].value(), g[1].value(), g[2].value())
                        .with_output_limit(g[3].value());
                    let _ = if matches!(set, Set::DjiSpeedPid(_)) {
                        d.set_speed_pid(c)
                    } else {
                        d.set_angle_pid(c)
                    };
                }
                (Ok(()), false)
            }
            Set::VescDuty(x) => match m {
                MotorRef::Vesc(v, _) => (v.set_duty(x.value()), !x.value().is_finite()),
                _ => (Ok(()), false),
            },
            Set::VescBrake(x) => match m {
                MotorRef::Vesc(v, _) => (v.set_brake_current(x.value()), !x.value().is_finite()),
                _ => (Ok(()), false),
            },
            Set::DmMit(f) => match m {
                MotorRef::Dm(d, _) => {
                    let c = MitCommand {
                        position_rad: f[0].value(),
                        velocity_rad_s: f[1].value(),
                        kp: f[2].value(),
                        kd: f[3].value(),
                        torque_nm: f[4].value(),
                    };
                    let r = d.set_mit(c);
                    if r.is_ok() {
                        t.mit = c;
                    }
                    (r, f.iter().any(|x| !x.value().is_finite()))
                }
                _ => (Ok(()), false),
            },
            Set::DmSpecial(k) => {
                if let MotorRef::Dm(d, _) = m {
                    let special = [
                        DmSpecial::Enable,
                        DmSpecial::Disable,
                        DmSpecial::SaveZero,
                        DmSpecial::ClearError,
                    ][usize::from(k % 4)];
                    d.send_special(special);
                    // Enable and Disable undo each other: the later one replaces a waiting
                    // earlier one.
                    if let Some(opposite) = opposite(special) {
                        t.special.retain(|&waiting| waiting != opposite);
                    }
                    if !t.special.contains(&special) {
                        t.special.push_back(special);
                    }
                }
                (Ok(()), false)
            }
        };
        let after = motor.state();
        check_state(&after, i);
        if non_finite_target {
            assert!(result.is_err(), "motor {i}: {set:?} accepted");
        }
        if result.is_err() {
            assert_eq!(
                (before.mode, before.target.to_bits()),
                (after.mode, after.target.to_bits()),
                "motor {i}: refused {set:?} changed mode or target"
            );
        }
        if after.mode == ControlMode::Angle && matches!(m, MotorRef::Dji(..)) {
            assert!(
                (0.0..360.0).contains(&after.target),
                "motor {i}: DJI angle target {} not wrapped into [0, 360)",
                after.target
            );
        }
    }

    /// `Bus::tick` at the clock, then `Bus::transmit`, and every per-tick invariant.
    fn tick(&mut self, dt_s: f32) {
        let now = self.now;
        self.bus
            .tick(Instant::from_ticks(now), dt_s, &mut self.batch);
        let frames = self.batch.frames().to_vec();
        let counters = self.bus.stats().snapshot();
        assert_eq!(
            counters.tx_undeclared, 0,
            "a motor packed an undeclared frame"
        );
        assert_eq!(counters.tx_batch_overflow, 0, "the batch overflowed");
        check_frame_set(&frames, &self.motors);
        // The Damiao specials packed this tick: queued again by the driver if refused.
        let mut packed_specials = Vec::new();
        for i in 0..self.motors.len() {
            let m = self.motors[i];
            let state = m.motor().state();
            check_state(&state, i);
            self.check_liveness(i, &state, now);
            match m {
                MotorRef::Dji(_, info) => check_dji(&frames, &info, &state, &self.track[i], i),
                MotorRef::Vesc(_, info) => check_vesc(&frames, &info, &state, &self.track[i], i),
                MotorRef::Dm(d, info) => {
                    // Specials wait while the motor is offline.
                    let t = &mut self.track[i];
                    let special = if state.online {
                        t.special.pop_front()
                    } else {
                        None
                    };
                    if let Some(sp) = special {
                        packed_specials.push((i, info.can_id, sp));
                    }
                    t.offline_ticks = if state.online { 0 } else { t.offline_ticks + 1 };
                    check_dm(
                        &frames,
                        &info,
                        &state,
                        d.status(),
                        special,
                        &self.track[i],
                        i,
                    );
                }
            }
        }
        let mut tx = Recording {
            inner: &mut self.tx,
            refused: Vec::new(),
        };
        let report = self.bus.transmit(&self.batch, &mut tx);
        let refused = tx.refused;
        // A refused special waits again, first in line, unless its opposite was asked for
        // since.
        for (i, can_id, sp) in packed_specials {
            let was_refused = refused.iter().any(|f| {
                !f.is_extended() && f.raw_id() == u32::from(can_id) && f.data() == sp.bytes()
            });
            let t = &mut self.track[i];
            let superseded = opposite(sp).is_some_and(|o| t.special.contains(&o));
            if was_refused && !superseded {
                t.special.retain(|&waiting| waiting != sp);
                t.special.push_front(sp);
            }
        }
        assert_eq!(
            usize::from(report.queued) + usize::from(report.full) + usize::from(report.bus_off),
            frames.len(),
            "transmit lost count of frames: {report:?}"
        );
        if self.tx.status().state == ErrorState::BusOff {
            assert_eq!(report.queued, 0, "queued while bus-off");
        }
    }

    fn check_liveness(&mut self, i: usize, state: &MotorState, now: u64) {
        let timeout = self.motors[i].timeout_us();
        let t = &mut self.track[i];
        // The liveness check counts a stamp after the tick as the tick's time, and keeps it so.
        if t.newest.is_some_and(|n| n >= now) {
            t.newest = Some(now);
        }
        if let Some(stamp) = t.fresh.take() {
            // Latest accepted feedback since the last tick: online exactly when it is within
            // the timeout (a stamp after `now` counts as now).
            let expected = stamp.saturating_add(timeout) >= now;
            assert_eq!(
                state.online, expected,
                "motor {i}: feedback at {stamp} µs, tick at {now} µs, timeout {timeout} µs"
            );
            t.silent_since = Some(now);
        } else {
            match t.silent_since {
                None => assert!(!state.online, "motor {i}: online without any feedback"),
                Some(since) => {
                    if now > since && now - since > timeout {
                        assert!(
                            !state.online,
                            "motor {i}: still online at {now} µs, silent since {since} µs"
                        );
                    }
                }
            }
        }
    }
}

/// Every reported value finite; angles in [0, 360).
fn check_state(s: &MotorState, i: usize) {
    let finite = [s.target, s.speed_rpm, s.command]
        .into_iter()
        .chain(s.total_angle_deg)
        .chain(s.current_amps)
        .chain(s.temperature_c)
        .all(f32::is_finite);
    assert!(finite, "motor {i}: non-finite state {s:?}");
    if let Some(a) = s.angle_deg {
        assert!(
            (0.0..360.0).contains(&a),
            "motor {i}: angle {a} outside [0, 360)"
        );
    }
}

const DJI_COMMAND_IDS: [u32; 5] = [0x1FE, 0x1FF, 0x200, 0x2FE, 0x2FF];

/// The tick's frames: exactly one per DJI command ID in use, per VESC and per Damiao motor,
/// on the protocol's IDs, with the protocol's lengths; nothing else.
fn check_frame_set(frames: &[CanFrame], motors: &[MotorRef<'_>]) {
    let mut dji_ids: Vec<u32> = Vec::new();
    let mut vesc_seen: Vec<u8> = Vec::new();
    let mut dm_seen: Vec<u16> = Vec::new();
    for f in frames {
        assert!(!f.is_remote(), "remote frame packed: {f:?}");
        if f.is_extended() {
            let v = proto::vesc_id(f).unwrap_or_else(|| panic!("not a VESC ID: {f:?}"));
            assert!(
                v.packet <= vp::SET_POS,
                "VESC packet {} is no command",
                v.packet
            );
            assert_eq!(f.dlc(), 4, "VESC command DLC: {f:?}");
            assert!(
                !vesc_seen.contains(&v.controller),
                "two frames for VESC {v:?}"
            );
            vesc_seen.push(v.controller);
        } else if DJI_COMMAND_IDS.contains(&f.raw_id()) {
            assert_eq!(f.dlc(), 8, "DJI command DLC: {f:?}");
            assert!(!dji_ids.contains(&f.raw_id()), "two frames on {f:?}");
            dji_ids.push(f.raw_id());
        } else {
            assert_eq!(f.dlc(), 8, "Damiao command DLC: {f:?}");
            let id = f.raw_id() as u16;
            assert!(!dm_seen.contains(&id), "two frames for Damiao {id:#x}");
            dm_seen.push(id);
        }
    }
    let mut used_slots: Vec<(u32, usize)> = Vec::new();
    for m in motors {
        match m {
            MotorRef::Dji(_, i) => used_slots.push((u32::from(i.command_id), i.slot)),
            MotorRef::Vesc(_, i) => assert!(vesc_seen.contains(&i.id), "no frame for {i:?}"),
            MotorRef::Dm(_, i) => assert!(dm_seen.contains(&i.can_id), "no frame for {i:?}"),
        }
    }
    assert_eq!(
        vesc_seen.len() + dm_seen.len(),
        motors
            .iter()
            .filter(|m| !matches!(m, MotorRef::Dji(..)))
            .count(),
        "a frame for a motor nobody registered: {frames:?}"
    );
    for f in frames {
        if !f.is_extended() && DJI_COMMAND_IDS.contains(&f.raw_id()) {
            let d = proto::data8(f).expect("DLC 8");
            for slot in 0..4 {
                if !used_slots.contains(&(f.raw_id(), slot)) {
                    assert_eq!(
                        proto::dji_slot(&d, slot),
                        0,
                        "unused slot {slot} of {f:?} not zero"
                    );
                }
            }
        }
    }
}

/// The thermal derating factor: 1 up to `start`, falling linearly to 0 at `cutoff`.
fn derating(thermal: Option<(f32, f32)>, temperature: Option<f32>) -> f32 {
    match (thermal, temperature) {
        (Some((start, cutoff)), Some(t)) => {
            if t <= start {
                1.0
            } else if t >= cutoff {
                0.0
            } else {
                (cutoff - t) / (cutoff - start)
            }
        }
        _ => 1.0,
    }
}

fn check_dji(frames: &[CanFrame], info: &DjiInfo, s: &MotorState, t: &Track, i: usize) {
    let frame = frames
        .iter()
        .find(|f| !f.is_extended() && f.raw_id() == u32::from(info.command_id))
        .unwrap_or_else(|| panic!("motor {i}: no frame on {:#x}", info.command_id));
    let raw = proto::dji_slot(&proto::data8(frame).expect("DLC 8"), info.slot);
    let ctx = || {
        format!(
            "motor {i} ({:?} id {}): raw {raw}, state {s:?}",
            info.model, info.id
        )
    };
    assert!(
        raw.unsigned_abs() <= info.raw_range.unsigned_abs(),
        "beyond the ESC's range ±{}: {}",
        info.raw_range,
        ctx()
    );
    if !s.online || s.mode == ControlMode::Disabled {
        assert!(
            raw == 0 && s.command == 0.0,
            "offline or disabled, not zero: {}",
            ctx()
        );
        return;
    }
    // The limit in force: the ESC's range, derated by temperature, and the user's limit.
    let limit = (info.unit_range() * derating(info.thermal, s.temperature_c)).min(t.user_limit);
    assert!(
        s.command.abs() <= limit * (1.0 + 1e-6) + 1e-6,
        "command beyond the limit in force {limit}: {}",
        ctx()
    );
    // The raw value is the command, rounded, with its sign.
    let exact = f64::from(s.command) * f64::from(info.raw_per_unit);
    assert!(
        (f64::from(raw) - exact).abs() <= 0.5 + exact.abs() * 1e-6,
        "raw is not the command {exact}: {}",
        ctx()
    );
    assert!(
        raw == 0 || (raw > 0) == (s.command > 0.0),
        "sign flip: {}",
        ctx()
    );
    if matches!(s.mode, ControlMode::Current | ControlMode::Voltage) {
        let expected = s.target.clamp(-limit, limit);
        assert!(
            (s.command - expected).abs() <= 1e-6 * limit.max(1.0),
            "open-loop command is not the clamped target {expected}: {}",
            ctx()
        );
    }
}

fn check_vesc(frames: &[CanFrame], info: &VescInfo, s: &MotorState, t: &Track, i: usize) {
    let (frame, v) = frames
        .iter()
        .find_map(|f| {
            let v = proto::vesc_id(f)?;
            (v.controller == info.id).then_some((f, v))
        })
        .unwrap_or_else(|| panic!("motor {i}: no VESC frame"));
    let value = proto::vesc_command_value(frame).expect("DLC 4");
    let ctx = || {
        format!(
            "motor {i} (VESC {}): {frame:?} = {value}, state {s:?}",
            info.id
        )
    };
    let within = |v: i32, limit: f64| f64::from(v).abs() <= limit * (1.0 + 1e-6) + 1.0;
    if !s.online || s.mode == ControlMode::Disabled {
        assert!(
            v.packet == vp::SET_CURRENT && value == 0 && s.command == 0.0,
            "offline or disabled, not SET_CURRENT 0: {}",
            ctx()
        );
        return;
    }
    // The user's limit applies to current and brake commands in current and torque modes,
    // and to the zero-speed brake of speed mode.
    let user = if matches!(s.mode, ControlMode::Current | ControlMode::Torque) {
        f64::from(t.user_limit)
    } else {
        f64::INFINITY
    };
    let packet_ok = match v.packet {
        vp::SET_DUTY => {
            assert!(within(value, 100_000.0), "duty beyond ±1: {}", ctx());
            s.mode == ControlMode::Voltage
        }
        vp::SET_CURRENT => {
            let limit = f64::from(info.max_current).min(user) * 1000.0;
            assert!(within(value, limit), "current beyond {limit} mA: {}", ctx());
            matches!(
                s.mode,
                ControlMode::Current | ControlMode::Torque | ControlMode::TotalAngle
            )
        }
        vp::SET_CURRENT_BRAKE => {
            let limit = f64::from(info.max_brake).min(f64::from(t.user_limit)) * 1000.0;
            assert!(
                value >= 0 && within(value, limit),
                "brake outside [0, {limit}] mA: {}",
                ctx()
            );
            matches!(s.mode, ControlMode::Current | ControlMode::Speed)
        }
        vp::SET_RPM => {
            let limit = f64::from(info.max_speed_rpm) * info.erpm_per_rpm;
            assert!(within(value, limit), "eRPM beyond {limit}: {}", ctx());
            s.mode == ControlMode::Speed
        }
        _ => {
            assert!(
                (0..=360_000_000).contains(&value),
                "position outside [0, 360°]: {}",
                ctx()
            );
            s.mode == ControlMode::Angle
        }
    };
    assert!(
        packet_ok,
        "packet {} does not fit the mode: {}",
        v.packet,
        ctx()
    );
    assert!(s.command.is_finite(), "{}", ctx());
}

fn check_dm(
    frames: &[CanFrame],
    info: &DmInfo,
    s: &MotorState,
    status: DmStatus,
    special: Option<DmSpecial>,
    t: &Track,
    i: usize,
) {
    let frame = frames
        .iter()
        .find(|f| !f.is_extended() && f.raw_id() == u32::from(info.can_id))
        .unwrap_or_else(|| panic!("motor {i}: no Damiao frame"));
    let d = proto::data8(frame).expect("DLC 8");
    let ctx = || {
        format!(
            "motor {i} (Damiao {:#x}): {d:02X?}, state {s:?}",
            info.can_id
        )
    };
    let l = info.limits;
    if !s.online {
        assert!(s.command == 0.0, "offline with a command: {}", ctx());
    } else {
        assert!(s.command.abs() <= l.t_max_nm, "{}", ctx());
    }
    // A special command is sent when asked for, or (auto-enable, a mode set) while the motor
    // reports Disabled or, offline, as a probe (also for an Enable waiting); otherwise an MIT
    // command, which must not look like one.
    // The driver's Enable probe: every PROBE_TICKS-th tick of an outage.
    let probe = !s.online && t.offline_ticks.is_multiple_of(u32::from(dm::PROBE_TICKS));
    let auto = if s.online {
        info.auto_enable && s.mode != ControlMode::Disabled && status == DmStatus::Disabled
    } else {
        probe
            && ((info.auto_enable && s.mode != ControlMode::Disabled)
                || t.special.contains(&DmSpecial::Enable))
    };
    let expected_special = special.or(auto.then_some(DmSpecial::Enable));
    if let Some(sp) = expected_special {
        assert_eq!(d, sp.bytes(), "expected {sp:?}: {}", ctx());
        return;
    }
    assert!(
        proto::dm_special(&d).is_none() || crate::pending::DM_MIT_SPECIAL_COLLISION,
        "an MIT command the motor reads as a special command: {}",
        ctx()
    );
    let c = proto::mit_codes(&d);
    let near = |code: u16, x: f32, min: f32, max: f32, bits: u32, what: &str| {
        let got = proto::code_to_value(code, min, max, bits);
        let want = proto::clamp_f64(x, min, max);
        let step = proto::code_step(min, max, bits);
        assert!(
            (got - want).abs() <= step * 1.001 + want.abs() * 1e-6,
            "{what} field {code} = {got}, want {want}: {}",
            ctx()
        );
    };
    let zero_torque = |c: proto::MitCodes| c.kp == 0 && c.kd == 0 && (c.t == 2047 || c.t == 2048);
    if !s.online
        || matches!(
            s.mode,
            ControlMode::Disabled | ControlMode::Voltage | ControlMode::Current
        )
    {
        assert!(
            zero_torque(c),
            "offline or idle, not zero torque: {c:?}: {}",
            ctx()
        );
        return;
    }
    let (p, v, t_max) = (l.p_max_rad, l.v_max_rad_s, l.t_max_nm);
    match s.mode {
        ControlMode::Torque => {
            let m = t.mit;
            near(c.p, m.position_rad, -p, p, 16, "position");
            near(c.v, m.velocity_rad_s, -v, v, 12, "velocity");
            near(c.kp, m.kp, 0.0, 500.0, 12, "kp");
            near(c.kd, m.kd, 0.0, 5.0, 12, "kd");
            near(c.t, m.torque_nm, -t_max, t_max, 12, "torque");
        }
        ControlMode::Speed => {
            assert_eq!(c.kp, 0, "kp in speed mode: {}", ctx());
            near(c.kd, info.speed_kd, 0.0, 5.0, 12, "kd");
            let rad_s = s.target * core::f32::consts::TAU / 60.0;
            near(c.v, rad_s, -v, v, 12, "velocity");
            near(c.t, t.ff_nm, -t_max, t_max, 12, "torque");
        }
        _ => {
            near(c.kp, info.position_kp, 0.0, 500.0, 12, "kp");
            near(c.kd, info.position_kd, 0.0, 5.0, 12, "kd");
            near(c.t, t.ff_nm, -t_max, t_max, 12, "torque");
        }
    }
}

impl Harness<'_> {
    /// Which motors are online now (as of the last tick).
    pub fn online(&self) -> Vec<bool> {
        self.motors
            .iter()
            .map(|m| m.motor().state().online)
            .collect()
    }
}

/// Forwards to the transport and records the frames it refused.
struct Recording<'a> {
    inner: &'a mut TxQueue<3>,
    refused: Vec<CanFrame>,
}

impl CanTransmit for Recording<'_> {
    fn try_send(&mut self, frame: &CanFrame) -> Result<(), SendError> {
        let result = self.inner.try_send(frame);
        if result.is_err() {
            self.refused.push(*frame);
        }
        result
    }
    fn status(&self) -> BusStatus {
        self.inner.status()
    }
    fn still_queued(&self) -> u8 {
        self.inner.still_queued()
    }
}

/// The Damiao special that undoes `special` (Enable against Disable), if any.
fn opposite(special: DmSpecial) -> Option<DmSpecial> {
    match special {
        DmSpecial::Enable => Some(DmSpecial::Disable),
        DmSpecial::Disable => Some(DmSpecial::Enable),
        DmSpecial::SaveZero | DmSpecial::ClearError => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ops::decode_all;

    /// The committed seeds run clean and bring every motor online at some point, so fuzzing
    /// starts from a robot that is really driven.
    #[test]
    fn seeds_run_clean_and_drive_every_motor() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/corpus/bus_dispatch");
        let fleet = Fleet::new();
        let mut ever = vec![false; fleet.motors().len()];
        let mut seeds = 0;
        for entry in std::fs::read_dir(dir).expect("seed corpus") {
            let bytes = std::fs::read(entry.expect("entry").path()).expect("seed");
            let fleet = Fleet::new();
            let mut h = Harness::new(&fleet);
            for op in decode_all(&bytes) {
                h.run(&op);
                for (e, on) in ever.iter_mut().zip(h.online()) {
                    *e |= on;
                }
            }
            seeds += 1;
        }
        assert!(seeds >= 1);
        assert!(ever.iter().all(|e| *e), "motors never online: {ever:?}");
    }
}
