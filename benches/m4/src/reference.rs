//! Reference motors: the least a 1 kHz tick and a feedback frame of the design's shape can
//! cost, to measure the benchmark goals against. Not rc10: nothing here is used by rc10-core.
//!
//! One plain implementation, written to be lean, not a proven minimum. The shape is rc10's
//! (SPEC's design card): the scheduler calls `update` on every motor through `&dyn`, then
//! `pack` on every motor, over a list whose length is known only at run time (the bench
//! passes a `heapless::Vec`); the receiver hands a frame to the motor a table finds for its
//! ID. What each reference motor does, and no more:
//! - speed loop: error, then a positional PI (trapezoid integral, integral limit, output
//!   limit, integration stopped while the output saturates in the error's direction) or an
//!   incremental one (RC10_LIB's speed-loop form, with gains per second, no deadband and an
//!   output limit only); the command rounded to
//!   the C620's wire integer and clamped to ±16384; `pack` writes its two bytes big-endian
//!   into a fixed 8-byte frame at a slot fixed at build;
//! - *checked*: in addition, its state behind a critical section (the lock every motor
//!   shared between tasks needs), offline after 100 ms without feedback (output zero and the
//!   integral cleared), and a non-finite output replaced by zero with the controller's state
//!   left as it was;
//! - feedback: the frame's ID picks the motor from a table; under its lock, the DLC checked,
//!   rotor angle, speed, torque current and temperature parsed, the multi-turn count advanced
//!   by the shortest way between two angles (exact, 64-bit) and the arrival stamped; and
//!   once more with rc10's frame checks ([`dispatch_checked`]: statistics, order, repeats,
//!   turns counted across lost and late frames, the arrival estimated, derating);
//! - angle mode: every 10th tick, the output's multi-turn angle from the turn count and a
//!   positional angle step ([`RefPid::positional`]) give the speed loop's target;
//! - PID steps ([`RefPid`]): a non-finite target or measurement gives 0 and leaves the state
//!   alone; the positional step with the speed PI's integral and limits plus a derivative on
//!   the measurement, I and D skipped when their gain is 0; the incremental one in RC10_LIB's
//!   form (gains per second) with an output limit, its D term skipped when kd is 0, and
//!   once more with rc10's checks but the tracking differentiator's
//!   ([`RefPid::incremental_checked`]); the output returned as one `f32`.
//!
//! What rc10 does beyond this on the same paths (control modes, the per-term record, the
//! statistics window, frames built from declared IDs, slots held to their node, derating,
//! integrals held on stale feedback, …) is listed in BENCHMARKS.md.

use core::cell::RefCell;
use core::sync::atomic::{AtomicI32, AtomicU32, Ordering};
use rc10_core::can::CanFrame;
use rc10_core::math::finite;

/// Offline after this long without feedback, in µs.
const TIMEOUT_US: u64 = 100_000;
/// C620 wire units per amp (16384 / 20 A).
const RAW_PER_AMP: f32 = 819.2;

/// A reference motor's state.
pub struct State {
    target_rpm: f32,
    speed_rpm: f32,
    last_feedback_us: u64,
    kp: f32,
    ki: f32,
    integral: f32,
    integral_limit: f32,
    output_limit: f32,
    previous_error: f32,
    output_amps: f32,
    last_angle: u16,
    rotor_counts: i64,
    current_raw: i16,
    temperature_c: u8,
    angle_target_deg: f32,
    angle_loop: RefPid,
    ticks_to_angle_loop: u8,
    /// The last frame's eight bytes (a repeat of them is no step).
    last_data: u64,
    /// How late the last frame was read after it arrived, as best known, in µs.
    arrival_lag_us: u32,
    /// The last tick's time, in µs (a frame stamped far after it is not trusted).
    last_tick_us: Option<u64>,
    /// The derating factor of the current limit at the last temperature.
    derate: f32,
    /// The last frame's rotor speed, in rotor rpm.
    rotor_rpm: i16,
    /// Offline since the last frame: the next one counts no lost turns.
    awaiting_return: bool,
}

/// Output degrees per rotor count of an M3508 (360° per 8192 counts, 3591/187 reduction).
const DEG_PER_COUNT: f32 = 360.0 * 187.0 / (8192.0 * 3591.0);

impl State {
    /// At rest, aiming at `target_rpm`, with the M3508 speed loop's usual gains (amps per rpm).
    pub const fn new(target_rpm: f32) -> Self {
        Self {
            target_rpm,
            speed_rpm: 0.0,
            last_feedback_us: 0,
            kp: 0.6,
            ki: 8.0,
            integral: 0.0,
            integral_limit: 10.0,
            output_limit: 20.0,
            previous_error: 0.0,
            output_amps: 0.0,
            last_angle: 0,
            rotor_counts: 0,
            current_raw: 0,
            temperature_c: 0,
            angle_target_deg: 90.0,
            // rc10's M3508 angle loop: 8 output rpm per degree, at most 400 rpm.
            angle_loop: RefPid::new(8.0, 0.0, 0.0, 0.0, 400.0),
            ticks_to_angle_loop: 0,
            last_data: 0,
            arrival_lag_us: 0,
            last_tick_us: None,
            derate: 1.0,
            rotor_rpm: 0,
            // No frame yet: the first one counts no turns.
            awaiting_return: true,
        }
    }
}

/// Access to a reference motor's state: behind a critical section, or only a `RefCell`.
pub trait Lock {
    /// Runs `f` on the state.
    fn with<R>(&self, f: impl FnOnce(&mut State) -> R) -> Option<R>;
}

impl Lock for critical_section::Mutex<RefCell<State>> {
    #[inline(always)]
    fn with<R>(&self, f: impl FnOnce(&mut State) -> R) -> Option<R> {
        critical_section::with(|cs| Some(f(&mut *self.borrow(cs).try_borrow_mut().ok()?)))
    }
}

impl Lock for RefCell<State> {
    #[inline(always)]
    fn with<R>(&self, f: impl FnOnce(&mut State) -> R) -> Option<R> {
        Some(f(&mut *self.try_borrow_mut().ok()?))
    }
}

/// What the scheduler and the receiver see.
pub trait Node {
    /// Control math.
    fn update(&self, now_us: u64, dt_s: f32);
    /// Writes the command into the frame.
    fn pack(&self, frame: &mut [u8; 8]);
    /// Takes a feedback frame's data.
    fn on_feedback(&self, data: &[u8], now_us: u64);
    /// Takes a feedback frame with the checks of [`dispatch_checked`]; `false` when it
    /// refuses it.
    fn on_feedback_checked(&self, frame: &CanFrame, now_us: u64) -> bool;
}

/// A reference motor: `CHECKED` adds liveness and the NaN rule (the lock is `L`'s),
/// `INCREMENTAL` picks the incremental PI, `ANGLE` runs a positional angle loop on the
/// output's multi-turn angle every 10th tick, its output the speed loop's target.
pub struct RefMotor<L, const CHECKED: bool, const INCREMENTAL: bool, const ANGLE: bool = false> {
    state: L,
    command_raw: AtomicI32,
    slot: usize,
}

impl<L: Lock, const CHECKED: bool, const INCREMENTAL: bool, const ANGLE: bool>
    RefMotor<L, CHECKED, INCREMENTAL, ANGLE>
{
    /// A motor packing into slot `slot` (0–3).
    pub const fn new(state: L, slot: usize) -> Self {
        Self {
            state,
            command_raw: AtomicI32::new(0),
            slot,
        }
    }

    /// Its lock (for the bench to set the state).
    pub fn state(&self) -> &L {
        &self.state
    }
}

#[inline(always)]
fn clamp(x: f32, low: f32, high: f32) -> f32 {
    if x > high {
        high
    } else if x < low {
        low
    } else {
        x
    }
}

impl State {
    /// Records a tick at `now_us` as rc10's tick does (the tick rows leave it out: one store
    /// a motor that only the frame checks read).
    pub fn set_last_tick(&mut self, now_us: u64) {
        self.last_tick_us = Some(now_us);
    }

    /// Sets the measured speed and the arrival stamp (the bench's feedback).
    pub fn set_feedback(&mut self, speed_rpm: f32, rotor_counts: i64, now_us: u64) {
        self.speed_rpm = speed_rpm;
        self.rotor_counts = rotor_counts;
        self.last_feedback_us = now_us;
    }

    /// The output and the integral to keep (not stored: the caller keeps them only when the
    /// output is finite).
    #[inline(always)]
    fn positional(&self, error: f32, dt_s: f32) -> (f32, f32) {
        let held = self.integral;
        let mut integral = clamp(
            held + self.ki * dt_s * 0.5 * (error + self.previous_error),
            -self.integral_limit,
            self.integral_limit,
        );
        let unclamped = self.kp * error + integral;
        let output = clamp(unclamped, -self.output_limit, self.output_limit);
        if output != unclamped && (unclamped > 0.0) == (error > 0.0) {
            integral = held;
        }
        (output, integral)
    }

    #[inline(always)]
    fn incremental(&self, error: f32, dt_s: f32) -> f32 {
        let step = self.kp * (error - self.previous_error) + self.ki * dt_s * error;
        clamp(
            self.output_amps + step,
            -self.output_limit,
            self.output_limit,
        )
    }
}

impl<L: Lock, const CHECKED: bool, const INCREMENTAL: bool, const ANGLE: bool> Node
    for RefMotor<L, CHECKED, INCREMENTAL, ANGLE>
{
    #[inline(never)]
    fn update(&self, now_us: u64, dt_s: f32) {
        let raw = self.state.with(|s| {
            if CHECKED && now_us.wrapping_sub(s.last_feedback_us) > TIMEOUT_US {
                s.awaiting_return = true;
                s.last_data = u64::MAX;
                s.integral = 0.0;
                s.output_amps = 0.0;
                return 0;
            }
            if ANGLE {
                if s.ticks_to_angle_loop == 0 {
                    s.ticks_to_angle_loop = 9;
                    // The 32-bit conversion while the count fits (about 14,000 output turns),
                    // the 64-bit one (a library call) only beyond.
                    let counts = match i32::try_from(s.rotor_counts) {
                        Ok(c) => c as f32,
                        Err(_) => wide_counts_to_f32(s.rotor_counts),
                    };
                    let target = s.angle_target_deg;
                    s.target_rpm = s
                        .angle_loop
                        .positional(target, counts * DEG_PER_COUNT, 0.01);
                } else {
                    s.ticks_to_angle_loop -= 1;
                }
            }
            let error = s.target_rpm - s.speed_rpm;
            let (output, integral) = if INCREMENTAL {
                (s.incremental(error, dt_s), s.integral)
            } else {
                s.positional(error, dt_s)
            };
            if CHECKED && !output.is_finite() {
                // The state as it was; the command zero.
                return 0;
            }
            s.integral = integral;
            s.previous_error = error;
            s.output_amps = output;
            let rounded = output * RAW_PER_AMP + if output >= 0.0 { 0.5 } else { -0.5 };
            (rounded as i32).clamp(-16384, 16384)
        });
        self.command_raw.store(raw.unwrap_or(0), Ordering::Relaxed);
    }

    #[inline(never)]
    fn pack(&self, frame: &mut [u8; 8]) {
        let raw = self.command_raw.load(Ordering::Relaxed) as i16;
        let at = self.slot.wrapping_mul(2);
        if let Some(bytes) = frame.get_mut(at..at.wrapping_add(2)) {
            bytes.copy_from_slice(&raw.to_be_bytes());
        }
    }

    #[inline(never)]
    fn on_feedback(&self, data: &[u8], now_us: u64) {
        let &[a0, a1, r0, r1, c0, c1, temperature_c, _] = data else {
            return;
        };
        let angle = u16::from_be_bytes([a0, a1]) & 0x1FFF;
        let rotor_rpm = i16::from_be_bytes([r0, r1]);
        self.state.with(|s| {
            // The shortest way between two angles of 8192 counts: -4096..4095.
            let step = (i32::from(angle) - i32::from(s.last_angle) + 4096).rem_euclid(8192) - 4096;
            s.rotor_counts = s.rotor_counts.wrapping_add(i64::from(step));
            s.last_angle = angle;
            s.speed_rpm = f32::from(rotor_rpm) * (187.0 / 3591.0);
            s.current_raw = i16::from_be_bytes([c0, c1]);
            s.temperature_c = temperature_c;
            s.last_feedback_us = now_us;
        });
    }

    #[inline(never)]
    fn on_feedback_checked(&self, frame: &CanFrame, now_us: u64) -> bool {
        let Some(data) = frame.data8() else {
            return false;
        };
        self.state
            .with(|s| s.feedback_checked(data, now_us))
            .unwrap_or(false)
    }
}

/// A feedback period of the C620, in µs.
const PERIOD_US: u32 = 1000;

impl State {
    /// A DJI feedback frame's eight bytes at `now_us`, with what rc10 checks on this path:
    /// an angle beyond 8191 and a frame stamped before the newest one refused; the same
    /// eight bytes again taken as no step (the stamp moves, the estimated arrival with it);
    /// the turn count advanced by the wrapped step plus the whole turns nearest what the mean
    /// reported speed predicts over the time since the last frame arrived (lost frames lose
    /// no turns; a stamp more than 2 ms after the last tick is taken as one period; the first
    /// frame and the first after an outage take the half-turn rule); the lateness of this
    /// frame's reading estimated for the next; the limit derated when the temperature
    /// changes. Simpler than rc10's turn counting, which at speed also searches whole
    /// periods around the stamps' gap, and so still counts right the first frame of a
    /// backlog read late.
    #[inline(always)]
    fn feedback_checked(&mut self, data: &[u8; 8], now_us: u64) -> bool {
        let &[a0, a1, r0, r1, c0, c1, temperature_c, _] = data;
        let angle = u16::from_be_bytes([a0, a1]);
        if angle >= 8192 || now_us < self.last_feedback_us {
            return false;
        }
        let since_us = u32::try_from(now_us - self.last_feedback_us).unwrap_or(u32::MAX);
        let since_arrival_us = since_us.saturating_add(self.arrival_lag_us);
        let bytes = u64::from_ne_bytes(*data);
        if bytes == self.last_data {
            // Read more than half a period on: the next frame of a motor at rest.
            self.arrival_lag_us = if since_us > PERIOD_US / 2 {
                arrival_lag_us(since_arrival_us, since_us, 1)
            } else {
                since_arrival_us
            };
            self.last_feedback_us = now_us;
            return true;
        }
        self.last_data = bytes;
        let rotor_rpm = i16::from_be_bytes([r0, r1]);
        let wrapped =
            (i32::from(angle) - i32::from(self.last_angle) + 4096).rem_euclid(8192) - 4096;
        let step = if self.awaiting_return {
            // Back from an outage: the half-turn rule, no speed history.
            self.awaiting_return = false;
            self.arrival_lag_us = 0;
            wrapped
        } else {
            let trusted = self
                .last_tick_us
                .is_none_or(|tick| now_us.saturating_sub(tick) <= 2 * u64::from(PERIOD_US));
            let periods = if trusted {
                since_arrival_us as f32 * (1.0 / PERIOD_US as f32)
            } else {
                1.0
            };
            // Rotor rpm to counts a period: 8192 counts a turn, 60,000 periods a minute.
            let mean_rpm = f32::from(self.rotor_rpm) + f32::from(rotor_rpm);
            let counts_per_period = mean_rpm * (0.5 * 8192.0 / 60_000.0);
            let off = counts_per_period * periods - wrapped as f32;
            let whole = ((periods + 0.5) as u32).max(1);
            self.arrival_lag_us = arrival_lag_us(since_arrival_us, since_us, whole);
            if off.abs() * 2.0 < 8192.0 {
                wrapped
            } else {
                plus_whole_turns(wrapped, off)
            }
        };
        self.rotor_counts = self.rotor_counts.wrapping_add(i64::from(step));
        self.last_angle = angle;
        self.rotor_rpm = rotor_rpm;
        self.speed_rpm = f32::from(rotor_rpm) * (187.0 / 3591.0);
        self.current_raw = i16::from_be_bytes([c0, c1]);
        if temperature_c != self.temperature_c {
            self.temperature_c = temperature_c;
            self.derate = derating(temperature_c);
        }
        self.last_feedback_us = now_us;
        true
    }
}

/// `step` plus the whole turns of 8192 counts nearest `off` (off the common path: more
/// than half a turn between the step and the prediction).
#[cold]
#[inline(never)]
fn plus_whole_turns(step: i32, off: f32) -> i32 {
    let turns = off * (1.0 / 8192.0) + if off >= 0.0 { 0.5 } else { -0.5 };
    step.saturating_add((turns as i32).saturating_mul(8192))
}

/// How late a frame was read after it arrived, `periods` whole periods after the last one:
/// the time since that one's arrival beyond the interval when it is more than half a
/// period over and the stamps are not simply a period apart, else 0 (rc10's estimate).
#[inline(always)]
fn arrival_lag_us(since_arrival_us: u32, since_newest_us: u32, periods: u32) -> u32 {
    let interval_us = periods.min(4_000_000).saturating_mul(PERIOD_US);
    let late = since_arrival_us > interval_us.saturating_add(PERIOD_US / 2);
    let paced = since_newest_us.abs_diff(interval_us) <= PERIOD_US / 2;
    if late && !paced {
        since_arrival_us - interval_us
    } else {
        0
    }
}

/// The limit's derating factor at a winding temperature: 1 up to 100 °C, down to 0 at
/// 125 °C.
#[cold]
#[inline(never)]
fn derating(celsius: u8) -> f32 {
    clamp((125.0 - f32::from(celsius)) * (1.0 / 25.0), 0.0, 1.0)
}

/// A turn count beyond 32 bits as `f32` (a library call on the M4): behind its own cold call,
/// so that the optimiser does not compute it on every angle tick and select.
#[cold]
#[inline(never)]
fn wide_counts_to_f32(counts: i64) -> f32 {
    counts as f32
}

/// One tick of reference motors: every `update`, then every `pack` into one frame.
#[inline(never)]
pub fn tick(nodes: &[&dyn Node], now_us: u64, dt_s: f32, frame: &mut [u8; 8]) {
    for node in nodes {
        node.update(now_us, dt_s);
    }
    let mut out = [0u8; 8];
    for node in nodes {
        node.pack(&mut out);
    }
    *frame = out;
}

/// One feedback frame to the reference motor its ID (0x201–0x204) picks; remote and
/// extended frames are nobody's.
#[inline(never)]
pub fn dispatch(nodes: &[&dyn Node; 4], frame: &CanFrame, now_us: u64) {
    if frame.is_extended() || frame.is_remote() {
        return;
    }
    if let Some(node) = usize::try_from(frame.raw_id())
        .ok()
        .and_then(|id| id.checked_sub(0x201))
        .and_then(|index| nodes.get(index))
    {
        node.on_feedback(frame.data(), now_us);
    }
}

/// Frame statistics of a bus: frames and bits received (what load and rates are computed
/// from when read).
pub struct RxStats {
    frames: AtomicU32,
    bits: AtomicU32,
}

impl RxStats {
    /// Nothing received yet.
    pub const fn new() -> Self {
        Self {
            frames: AtomicU32::new(0),
            bits: AtomicU32::new(0),
        }
    }

    /// Frames received so far.
    pub fn frames(&self) -> u32 {
        self.frames.load(Ordering::Relaxed)
    }
}

impl Default for RxStats {
    fn default() -> Self {
        Self::new()
    }
}

/// [`dispatch`] with rc10's checks on the frame path: the frame and its bits counted, then
/// routed as there to [`Node::on_feedback_checked`]. Returns whether a motor took it.
#[inline(never)]
pub fn dispatch_checked(
    nodes: &[&dyn Node; 4],
    stats: &RxStats,
    frame: &CanFrame,
    now_us: u64,
) -> bool {
    stats.frames.fetch_add(1, Ordering::Relaxed);
    let header_bits = if frame.is_extended() { 67 } else { 47 };
    let bits = header_bits + 8 * frame.data().len() as u32;
    stats.bits.fetch_add(bits, Ordering::Relaxed);
    if frame.is_extended() {
        return false;
    }
    usize::try_from(frame.raw_id())
        .ok()
        .and_then(|id| id.checked_sub(0x201))
        .and_then(|index| nodes.get(index))
        .is_some_and(|node| node.on_feedback_checked(frame, now_us))
}

/// A reference PID's state and gains (gains per second: `ki` × s, `kd` ÷ s).
pub struct RefPid {
    kp: f32,
    ki: f32,
    kd: f32,
    integral_limit: f32,
    output_limit: f32,
    integral: f32,
    previous_error: f32,
    second_error: f32,
    previous_measurement: f32,
    output: f32,
    /// The deadband as one comparison (a step runs when `|error| > band`; −1 for none).
    band: f32,
    /// Whether `previous_error` holds an error (the first step has none).
    started: bool,
    /// Seconds since `previous_error` (the valid `dt`s of the steps inside the deadband).
    since_s: f32,
    /// D's part of the output at the last step (kd times the error's rate).
    previous_d: f32,
    /// The terms of the last step: P, I, D and the output.
    terms: [f32; 4],
}

impl RefPid {
    /// A controller with these gains and limits.
    pub const fn new(kp: f32, ki: f32, kd: f32, integral_limit: f32, output_limit: f32) -> Self {
        Self {
            kp,
            ki,
            kd,
            integral_limit,
            // Capped: no limit is the largest finite value, so the output stays finite.
            output_limit: if output_limit < f32::MAX {
                output_limit
            } else {
                f32::MAX
            },
            integral: 0.0,
            previous_error: 0.0,
            second_error: 0.0,
            previous_measurement: 0.0,
            output: 0.0,
            band: -1.0,
            started: false,
            since_s: 0.0,
            previous_d: 0.0,
            terms: [0.0; 4],
        }
    }

    /// One positional step: P, trapezoid I within its limit (skipped when ki is 0), D on the
    /// measurement (skipped when kd is 0), the output limit, integration stopped while the
    /// output saturates in the error's direction.
    #[inline(never)]
    pub fn positional(&mut self, target: f32, measurement: f32, dt_s: f32) -> f32 {
        if !(target.is_finite() && measurement.is_finite()) {
            return 0.0;
        }
        let error = target - measurement;
        let held = self.integral;
        let mut integral = held;
        if self.ki != 0.0 {
            integral = clamp(
                held + self.ki * dt_s * 0.5 * (error + self.previous_error),
                -self.integral_limit,
                self.integral_limit,
            );
        }
        let mut unclamped = self.kp * error + integral;
        if self.kd != 0.0 {
            unclamped -= self.kd * (measurement - self.previous_measurement) / dt_s;
        }
        let output = clamp(unclamped, -self.output_limit, self.output_limit);
        if output != unclamped && (unclamped > 0.0) == (error > 0.0) {
            integral = held;
        }
        self.integral = integral;
        self.previous_error = error;
        self.previous_measurement = measurement;
        output
    }

    /// One incremental step: the output moved by P on the error's change, I on the error and
    /// D on its second difference, within the output limit.
    #[inline(never)]
    pub fn incremental(&mut self, target: f32, measurement: f32, dt_s: f32) -> f32 {
        if !(target.is_finite() && measurement.is_finite()) {
            return 0.0;
        }
        let error = target - measurement;
        let mut step = self.kp * (error - self.previous_error) + self.ki * dt_s * error;
        if self.kd != 0.0 {
            step += self.kd * (error - 2.0 * self.previous_error + self.second_error) / dt_s;
        }
        self.output = clamp(self.output + step, -self.output_limit, self.output_limit);
        self.second_error = self.previous_error;
        self.previous_error = error;
        self.output
    }

    /// The terms of the last [`incremental_checked`](Self::incremental_checked) step: P, I,
    /// D and the output.
    pub const fn last_terms(&self) -> [f32; 4] {
        self.terms
    }

    /// One incremental step with what rc10's incremental controller adds to
    /// [`incremental`](Self::incremental), except the tracking differentiator: an invalid `dt`
    /// or an error inside the deadband holds the output (and records it); the first step
    /// takes the error as its own previous one; D is kd times the change of the error's rate
    /// (skipped when kd is 0); an infinite or NaN term is held at ±`f32::MAX` or 0 (tested
    /// once, on the sum); the terms are recorded for tuning. The output is returned alone.
    #[inline(never)]
    pub fn incremental_checked(&mut self, target: f32, measurement: f32, dt_s: f32) -> f32 {
        if !(target.is_finite() && measurement.is_finite()) {
            return 0.0;
        }
        let error = target - measurement;
        // Positive, finite `dt`: the bit patterns 1..=0x7F7F_FFFF.
        let dt_ok = dt_s.to_bits().wrapping_sub(1) < 0x7F7F_FFFF;
        if !dt_ok || error.abs() <= self.band {
            if dt_ok {
                self.since_s += dt_s;
            }
            self.terms = [0.0, 0.0, 0.0, self.output];
            return self.output;
        }
        let previous = if self.started {
            self.previous_error
        } else {
            error
        };
        let limit = self.output_limit;
        let (d_now, mut d) = if self.kd == 0.0 {
            (0.0, 0.0 - self.previous_d)
        } else {
            let rate = self.kd * (error - previous) / (self.since_s + dt_s);
            let d_now = clamp(finite(rate), -limit, limit);
            (d_now, d_now - self.previous_d)
        };
        let (mut p, mut i) = (self.kp * (error - previous), self.ki * error * dt_s);
        let mut sum = self.output + p + i + d;
        if !sum.is_finite() {
            p = finite(p);
            i = finite(i);
            d = finite(d);
            sum = self.output + p + i + d;
        }
        self.output = clamp(sum, -limit, limit);
        self.previous_error = error;
        self.previous_d = d_now;
        self.since_s = 0.0;
        self.started = true;
        self.terms = [p, i, d, self.output];
        self.output
    }
}
