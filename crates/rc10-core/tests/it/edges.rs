//! Behaviour at the edges that mutation testing showed no test pinned down: each test here
//! fails if the named line of rc10-core is changed (operator flipped, call removed), with
//! expected values from the control law and the protocol, not from the code.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use rc10_core::bus::{BusBuilder, Dispatch};
use rc10_core::can::{CanFrame, IdFilter};
use rc10_core::encoder::{Encoder, EncoderConfig, GearRatio};
use rc10_core::motor::cascade::{Cascade, CascadeConfig, Measured};
use rc10_core::motor::dji::DjiMotor;
use rc10_core::motor::{ControlMode, Motor};
use rc10_core::node::{BusUsage, CanNode, FrameError, IdSet, TxBatch};
use rc10_core::pid::{Pid, PidConfig};
use rc10_core::time::Instant;
use std::sync::atomic::{AtomicU32, Ordering};

const DT: f32 = 0.001;

#[test]
fn derivative_term_opposes_rising_measurement_in_the_output() {
    // kd = 0.5 s, measurement rising 0.01 per 1 ms = 10 /s: D = -5, and the output is D.
    let mut pid = Pid::new(PidConfig::new(0.0, 0.0, 0.5)).unwrap();
    pid.update(0.0, 0.0, DT);
    let t = pid.update(0.0, 0.01, DT);
    assert!((t.output + 5.0).abs() < 1e-3, "{t:?}");
    // With P and a feed-forward as well: output = p + d + ff = 2·(0 - 0.02) - 5 + 1.
    let t = pid.update_with_ff(0.0, 0.02, 1.0, DT);
    assert!((t.output - (0.0 - 5.0 + 1.0)).abs() < 1e-2, "{t:?}");
    let mut pd = Pid::new(PidConfig::new(2.0, 0.0, 0.5)).unwrap();
    pd.update(0.0, 0.0, DT);
    let t = pd.update_with_ff(0.0, 0.01, 1.0, DT);
    assert!((t.output - (-0.02 - 5.0 + 1.0)).abs() < 1e-3, "{t:?}");
}

#[test]
fn anti_windup_counts_feed_forward_and_direction() {
    // Limit 10; P = 1·8 = 8, feed-forward 3: 11 > 10, so a positive integral increment would
    // wind up and must not be taken.
    let mut pid = Pid::new(PidConfig::new(1.0, 100.0, 0.0).with_output_limit(10.0)).unwrap();
    let t = pid.update_with_ff(8.0, 0.0, 3.0, DT);
    assert_eq!(t.output, 10.0);
    assert_eq!(
        pid.integral(),
        0.0,
        "integral grew while saturated by P + FF"
    );
    // A feed-forward pulling the other way: 8 - 3 = 5 is inside the limit, so it integrates
    // 100 · 8 · 0.001 = 0.8 per step.
    let mut pid = Pid::new(PidConfig::new(1.0, 100.0, 0.0).with_output_limit(10.0)).unwrap();
    pid.update_with_ff(8.0, 0.0, -3.0, DT);
    assert!((pid.integral() - 0.8).abs() < 1e-5, "{}", pid.integral());
    // Saturated high, but the error has turned negative: unwinding is always allowed.
    let mut pid = Pid::new(PidConfig::new(0.0, 100.0, 0.0).with_output_limit(1.0)).unwrap();
    pid.set_integral(1.0);
    pid.update_with_ff(-1.0, 0.0, 5.0, DT);
    assert!(pid.integral() < 1.0, "{}", pid.integral());
}

fn cascade(angle: PidConfig) -> Cascade {
    Cascade::new(CascadeConfig {
        speed: PidConfig::new(0.1, 10.0, 0.0).with_output_limit(20.0),
        angle,
        angle_divider: 10,
    })
    .unwrap()
}

#[test]
fn angle_loop_integrates_over_the_accumulated_ten_ticks() {
    // ki = 100 /s on a 2° error. The loop runs on the first tick (dt = one tick: 100 · 2 ·
    // 0.001 = 0.2 rpm) and then every 10th, each time over the 10 ticks since the last run
    // (100 · 2 · 0.010 s = 2 rpm).
    let mut c = cascade(PidConfig::new(0.0, 100.0, 0.0).with_output_limit(300.0));
    c.set_target(ControlMode::TotalAngle, 2.0);
    let m = Measured::default();
    c.step(&m, DT, 20.0);
    assert!(
        (c.angle_terms().i - 0.2).abs() < 1e-4,
        "{:?}",
        c.angle_terms()
    );
    for _ in 0..10 {
        c.step(&m, DT, 20.0);
    }
    assert!(
        (c.angle_terms().i - 2.2).abs() < 1e-3,
        "{:?}",
        c.angle_terms()
    );
}

#[test]
fn disabling_zeroes_the_applied_command_at_once() {
    let mut c = cascade(PidConfig::new(1.0, 0.0, 0.0));
    c.set_target(ControlMode::Current, 5.0);
    assert_eq!(c.step(&Measured::default(), DT, 20.0), 5.0);
    c.set_target(ControlMode::Disabled, 0.0);
    assert_eq!(c.output(), 0.0);
    // Re-enabled from Disabled: nothing was applied, so nothing is preloaded.
    c.set_target(ControlMode::Speed, 0.0);
    assert_eq!(c.step(&Measured::default(), DT, 20.0), 0.0);
}

#[test]
fn speed_to_angle_mode_keeps_the_speed_loop_integral() {
    let mut c = cascade(PidConfig::new(1.0, 0.0, 0.0).with_output_limit(300.0));
    c.set_target(ControlMode::Speed, 100.0);
    for _ in 0..50 {
        c.step(&Measured::default(), DT, 20.0);
    }
    let held = c.speed_terms().i;
    assert!(held > 0.0);
    // Both modes use the speed loop: no reset, the held current carries over.
    c.set_target(ControlMode::TotalAngle, 0.0);
    c.step(&Measured::default(), DT, 20.0);
    assert!(
        c.speed_terms().i > held * 0.5,
        "speed loop was reset on a closed-loop switch"
    );
}

#[test]
fn dji_total_angle_target_is_recorded_in_its_mode() {
    let m = DjiMotor::m3508(1).unwrap();
    m.set_target_total_angle_deg(720.0).unwrap();
    let s = m.state();
    assert_eq!(s.mode, ControlMode::TotalAngle);
    assert_eq!(s.target, 720.0);
}

#[test]
fn gm6020_voltage_mode_reports_current_on_the_3_amp_scale() {
    // Feedback D4–5 is torque current on the ±16384 ↔ ±3 A scale in either mode.
    let m = DjiMotor::gm6020_voltage(1).unwrap();
    let frame = CanFrame::standard(0x205, &[0, 0, 0, 0, 0x20, 0x00, 30, 0]).unwrap();
    m.update_feedback(&frame, Instant::from_micros(1000))
        .unwrap();
    let amps = m.state().current_amps.unwrap();
    assert!((amps - 8192.0 * 3.0 / 16384.0).abs() < 1e-4, "{amps}");
}

#[test]
fn rotor_angle_is_the_raw_count_in_degrees() {
    // Power-on origin: the first reading is 0°, and a quarter turn (2048 counts) later 90°.
    let mut e = Encoder::new(EncoderConfig::dji(GearRatio::M3508)).unwrap();
    e.update(100).unwrap();
    assert_eq!(e.rotor_angle_deg(), 0.0);
    e.update(2148).unwrap();
    assert!((e.rotor_angle_deg() - 90.0).abs() < 1e-4);
    e.update(4196).unwrap();
    assert!((e.rotor_angle_deg() - 180.0).abs() < 1e-4);
    e.update(6244).unwrap(); // a quarter turn further
    assert!(
        (e.rotor_angle_deg() - 270.0).abs() < 1e-4,
        "{}",
        e.rotor_angle_deg()
    );
}

#[test]
fn tx_batch_counts_frames_it_cannot_hold() {
    let mut b = TxBatch::new();
    let frame = CanFrame::standard(0x100, &[1]).unwrap();
    let mut refused = 0;
    for _ in 0..rc10_core::node::MAX_FRAMES_PER_TICK + 2 {
        if b.push(frame).is_err() {
            refused += 1;
        }
    }
    assert_eq!(refused, 2);
    assert_eq!(b.overflowed(), 2);
}

/// A node that keeps the default `matches_frame` (its declared listen filter).
struct Listener {
    frames: AtomicU32,
}

impl CanNode for Listener {
    fn bus_usage(&self) -> BusUsage {
        BusUsage::NONE.listening(IdFilter::standard(0x321), 100)
    }
    fn update_feedback(&self, _frame: &CanFrame, _now: Instant) -> Result<(), FrameError> {
        self.frames.fetch_add(1, Ordering::Relaxed);
        Ok(())
    }
    fn update(&self, _now: Instant, _dt_s: f32) {}
    fn pack_command(&self, _out: &mut TxBatch) {}
}

#[test]
fn default_matches_frame_claims_only_declared_ids() {
    static NODE: Listener = Listener {
        frames: AtomicU32::new(0),
    };
    let mut b: BusBuilder<'static, 4> = BusBuilder::new();
    b.register(&NODE).unwrap();
    let bus = b.build();
    let now = Instant::from_micros(1);
    let other = CanFrame::standard(0x322, &[0]).unwrap();
    assert_eq!(bus.dispatch(&other, now), Dispatch::Unmatched);
    let ext = CanFrame::extended(0x321, &[0]).unwrap();
    assert_eq!(bus.dispatch(&ext, now), Dispatch::Unmatched);
    let own = CanFrame::standard(0x321, &[0]).unwrap();
    assert_eq!(bus.dispatch(&own, now), Dispatch::Handled(0));
    assert_eq!(NODE.frames.load(Ordering::Relaxed), 1);
}

#[test]
fn gear_ratios_are_the_published_ones() {
    // M3508 P19: 3591/187 (DJI user guide); M2006 P36: 36:1; GM6020: direct drive.
    let m3508 = GearRatio::M3508;
    assert_eq!((m3508.rotor_turns(), m3508.output_turns()), (3591, 187));
    assert!((m3508.as_f32() - 19.2032).abs() < 1e-4);
    let m2006 = GearRatio::M2006;
    assert_eq!((m2006.rotor_turns(), m2006.output_turns()), (36, 1));
    let custom = GearRatio::new(51, 3).unwrap();
    assert_eq!((custom.rotor_turns(), custom.output_turns()), (51, 3));
    assert_eq!(GearRatio::new(51, 0), None);
    assert_eq!(GearRatio::new(0, 3), None);
}

#[test]
fn periodic_unwrapping_with_one_non_finite_input_uses_the_half_turn_rule() {
    // 6000 counts in one 1 ms period is more than half a turn (4096): the half-turn rule reads
    // it as -2192, the periodic search (1 period at 6000/period) as +6000. The documented rule
    // for non-finite inputs is the half-turn rule, whichever of the two is non-finite.
    for (counts_per_period, gap_periods) in [(6000.0, f32::NAN), (f32::NAN, 1.0)] {
        let mut e = Encoder::new(EncoderConfig::dji(GearRatio::DIRECT)).unwrap();
        e.update(0).unwrap();
        e.update_periodic(6000, counts_per_period, gap_periods)
            .unwrap();
        assert_eq!(
            e.total_counts(),
            6000 - 8192,
            "{counts_per_period} counts/period, gap {gap_periods}"
        );
    }
    // Both finite: the search finds the whole step.
    let mut e = Encoder::new(EncoderConfig::dji(GearRatio::DIRECT)).unwrap();
    e.update(0).unwrap();
    e.update_periodic(6000, 6000.0, 1.0).unwrap();
    assert_eq!(e.total_counts(), 6000);
}

/// Total counts after a first reading of 0 and one `update_periodic(raw, c, gap)`.
fn periodic_step(raw: u16, counts_per_period: f32, gap_periods: f32) -> i64 {
    let mut e = Encoder::new(EncoderConfig::dji(GearRatio::DIRECT)).unwrap();
    e.update(0).unwrap();
    e.update_periodic(raw, counts_per_period, gap_periods)
        .unwrap();
    e.total_counts()
}

#[test]
fn periodic_unwrapping_follows_the_documented_search() {
    // The rule (Encoder::update_periodic): the true interval is a whole m ≥ 1 periods within
    // ±2 of the measured gap, or 1; for each m the step d + k·8192 nearest m·c is a
    // candidate, and the one nearest its prediction wins; fits within 256 counts of each other
    // are equally good and then the m nearer the measured gap wins. Worked by hand, 8192
    // counts per turn.

    // Low speed (400 counts/period), 100 periods of silence: 40 000 counts (4.88 turns), of
    // which the reading shows 40 000 mod 8192 = 7232. Every candidate agrees: 40 000.
    assert_eq!(periodic_step(7232, 400.0, 100.0), 40_000);

    // 1900 counts/period, one frame lost (m = 2: 3800 counts) but stamped 4.4 periods apart:
    // m = 2 fits exactly; m = 3..6 miss by 1900, 3800, 2492, 592. Taking the stamps at face
    // value (4.4 · 1900 = 8360) would add a turn.
    assert_eq!(periodic_step(3800, 1900.0, 4.4), 3800);

    // 3000 counts/period, gap 10: m = 8..12 only. The reading 4616 fits m = 7 exactly
    // (21 000), but 7 is outside the window; inside, m = 10 fits best (29 192, 808 off).
    assert_eq!(periodic_step(4616, 3000.0, 10.0), 29_192);
    // Reading 1040 fits m = 14 exactly (42 000), outside the window; inside, m = 11 fits best
    // (33 808, 808 off; m = 8, 9, 10, 12 are 1616, 1384, 3808, 2192 off).
    assert_eq!(periodic_step(1040, 3000.0, 10.0), 33_808);

    // Equally good fits: 2048 counts/period, reading 6344. m = 3 gives 6344 and m = 7 gives
    // 14 536, both 200 off their predictions (6144, 14 336); m = 1 gives -1848, 3896 off. The
    // m nearer the gap wins.
    assert_eq!(periodic_step(6344, 2048.0, 5.3), 14_536);
    assert_eq!(periodic_step(6344, 2048.0, 4.7), 6344);
    // 2073 counts/period, reading 6219: m = 3 fits exactly (6219), m = 7 gives 14 411, 100 off
    // 14 511: within 256, so equally good, and 7 is nearer the gap of 5.3.
    assert_eq!(periodic_step(6219, 2073.0, 5.3), 14_411);

    // One period outside the window: 2400 counts/period, stamped 5.6 periods apart (window
    // 4..8), reading 2400 on. m = 1 fits exactly; the window's best, m = 8 (19 200 predicted,
    // 18 784 = 2400 + 2·8192 taken), is 416 off.
    assert_eq!(periodic_step(2400, 2400.0, 5.6), 2400);
}

#[test]
fn homing_to_an_absurd_angle_is_refused_and_changes_nothing() {
    // Documented: a non-finite or absurdly large angle (beyond 10^15 rotor counts) returns
    // false and leaves the position alone. 1e20° of an M3508 output is ~4e24 counts.
    let mut e = Encoder::new(EncoderConfig::dji(GearRatio::M3508)).unwrap();
    e.update(100).unwrap();
    e.update(1100).unwrap();
    let before = e.total_counts();
    for angle in [1e20, -1e20, f32::MAX, f32::INFINITY, f32::NAN] {
        assert!(!e.set_total_angle_deg(angle), "{angle}");
        assert_eq!(e.total_counts(), before, "{angle}");
    }
    // A sane angle is taken: 90° of output = 8192 · 3591 / 187 / 4 counts, rounded.
    assert!(e.set_total_angle_deg(90.0));
    let expected = (8192.0f64 * 3591.0 / 187.0 / 4.0).round() as i64;
    assert_eq!(e.total_counts(), expected);
}

#[test]
fn cascade_reports_the_applied_command_and_its_feed_forward() {
    let mut c = cascade(PidConfig::new(1.0, 0.0, 0.0));
    c.set_target(ControlMode::Current, 5.0);
    let applied = c.step(&Measured::default(), DT, 20.0);
    assert_eq!((applied, c.output()), (5.0, 5.0));
    // Current mode is clamped to the limit: 5 A asked, 3 A allowed.
    assert_eq!(c.step(&Measured::default(), DT, 3.0), 3.0);
    assert_eq!(c.output(), 3.0);
    assert_eq!(c.feed_forward(), 0.0);
    c.set_feed_forward(1.5);
    assert_eq!(c.feed_forward(), 1.5);
    c.set_feed_forward(f32::NAN); // ignored
    assert_eq!(c.feed_forward(), 1.5);
    c.set_feed_forward(-2.5);
    assert_eq!(c.feed_forward(), -2.5);
}

#[test]
fn id_sets_know_when_they_are_empty_or_extended() {
    assert!(IdSet::EMPTY.is_empty());
    let std_only = IdSet::one(IdFilter::standard(0x201));
    assert!(!std_only.is_empty());
    assert!(!std_only.any_extended());
    let mixed = std_only.with(IdFilter::extended(0x901));
    assert!(mixed.any_extended());
    assert!(IdSet::one(IdFilter::extended(0x0000_0A01)).any_extended());
}

#[test]
fn default_matches_frame_called_directly_claims_only_declared_ids() {
    let node = Listener {
        frames: AtomicU32::new(0),
    };
    let own = CanFrame::standard(0x321, &[0]).unwrap();
    let other = CanFrame::standard(0x322, &[0]).unwrap();
    assert!(node.matches_frame(&own));
    assert!(!node.matches_frame(&other));
    assert!(!node.matches_frame(&CanFrame::extended(0x321, &[0]).unwrap()));
}

#[test]
fn speed_to_angle_mode_neither_resets_nor_preloads_the_speed_loop() {
    // Speed loop kp 0.1, ki 10, limit 20 A, at a 100 rpm error: P = 10 A, and I grows 1 A per
    // tick until P + I reaches the 20 A limit, where anti-windup holds it: `held` = 10 A. In
    // total-angle mode at zero angle error the angle loop asks for 0 rpm, the speed error
    // falls from 100 to 0 rpm, and the trapezoid adds 10 · (100 + 0) / 2 · 0.001 = 0.5 A: the
    // integral must be `held` + 0.5 A, not reset to 0, and not preloaded with the applied
    // command (P + I = 20 A).
    let mut c = cascade(PidConfig::new(1.0, 0.0, 0.0).with_output_limit(300.0));
    c.set_target(ControlMode::Speed, 100.0);
    for _ in 0..50 {
        c.step(&Measured::default(), DT, 20.0);
    }
    let held = c.speed_terms().i;
    assert!((held - 10.0).abs() < 1e-3, "{held}");
    c.set_target(ControlMode::TotalAngle, 0.0);
    c.step(&Measured::default(), DT, 20.0);
    assert!(
        (c.speed_terms().i - (held + 0.5)).abs() < 1e-4,
        "{} vs {held} + 0.5",
        c.speed_terms().i
    );
}

#[test]
fn angle_loop_settings_take_effect_while_running() {
    // A 10° error; angle kp 1 -> 1 · 10 = 10 rpm asked of the speed loop.
    let mut c = cascade(PidConfig::new(1.0, 0.0, 0.0).with_output_limit(300.0));
    c.set_target(ControlMode::TotalAngle, 10.0);
    c.step(&Measured::default(), DT, 20.0);
    assert!((c.speed_target_rpm() - 10.0).abs() < 1e-4);
    // New gains while running: kp 3 -> 30 rpm at the next angle-loop run.
    c.set_angle_config(PidConfig::new(3.0, 0.0, 0.0).with_output_limit(300.0))
        .unwrap();
    c.set_angle_divider(1); // the angle loop now runs every tick
    assert!(c.angle_loop_due());
    c.step(&Measured::default(), DT, 20.0);
    assert!(
        (c.speed_target_rpm() - 30.0).abs() < 1e-4,
        "{}",
        c.speed_target_rpm()
    );
    // An invalid configuration is refused and changes nothing.
    assert!(
        c.set_angle_config(PidConfig::new(f32::NAN, 0.0, 0.0))
            .is_err()
    );
    c.step(&Measured::default(), DT, 20.0);
    assert!((c.speed_target_rpm() - 30.0).abs() < 1e-4);
}

/// A DJI feedback frame: rotor angle, rotor rpm, current 0, temperature 30 °C.
fn dji_feedback(id: u16, raw_angle: u16, rotor_rpm: i16) -> CanFrame {
    let [a0, a1] = raw_angle.to_be_bytes();
    let [r0, r1] = rotor_rpm.to_be_bytes();
    CanFrame::standard(id, &[a0, a1, r0, r1, 0, 0, 30, 0]).unwrap()
}

#[test]
fn feedback_stamped_up_to_two_periods_after_the_last_tick_is_trusted_for_timing() {
    // M2006 at 16 500 rotor rpm: 2252.8 counts per 1 ms feedback period. Feedback at 1 ms,
    // ticks at 1, 2, 3 ms, then three frames lost and the next stamped 5 ms: 4 periods, 9011
    // counts, which the reading shows as 9011 − 8192 = 819. The stamp is 2 ms after the last
    // tick: still trusted (the documented bound is two periods), so the 4-period gap is used
    // and the multi-turn position is exact. Distrusting it (gap taken as 1 period, window 1..3)
    // would give 819 counts: a lost turn.
    let m = DjiMotor::m2006(1).unwrap();
    let t = Instant::from_micros;
    m.update_feedback(&dji_feedback(0x201, 0, 16_500), t(1000))
        .unwrap();
    for tick in [1000, 2000, 3000] {
        m.update(t(tick), DT);
    }
    m.update_feedback(&dji_feedback(0x201, 819, 16_500), t(5000))
        .unwrap();
    let deg = m.state().total_angle_deg.unwrap();
    let expected = 9011.0 * 360.0 / (8192.0 * 36.0);
    assert!((deg - expected).abs() < 1e-3, "{deg} vs {expected}");
}

#[test]
fn homing_requested_before_feedback_waits_for_it_and_then_lets_the_motor_move() {
    // Homing to 90° before any feedback: the first tick cannot apply it (no reading) and
    // must keep it for a later tick; once applied, the position moves on from 90° (homing
    // happens once, it does not pin the position).
    let m = DjiMotor::m3508(2).unwrap();
    let t = Instant::from_micros;
    m.set_total_angle_here_deg(90.0).unwrap();
    m.update(t(1000), DT);
    m.update_feedback(&dji_feedback(0x202, 500, 0), t(1500))
        .unwrap();
    m.update(t(2000), DT);
    let homed = m.state().total_angle_deg.unwrap();
    assert!((homed - 90.0).abs() < 1e-3, "{homed}");
    // 1000 rotor counts later: 1000 · 360 / (8192 · 3591/187) output degrees more.
    m.update_feedback(&dji_feedback(0x202, 1500, 0), t(2500))
        .unwrap();
    m.update(t(3000), DT);
    let moved = m.state().total_angle_deg.unwrap();
    let step = 1000.0 * 360.0 * 187.0 / (8192.0 * 3591.0);
    assert!((moved - (90.0 + step)).abs() < 1e-3, "{moved}");
}

#[test]
fn dji_current_limit_of_zero_is_allowed_and_commands_zero() {
    let m = DjiMotor::m3508(1).unwrap();
    let t = Instant::from_micros;
    m.update_feedback(&dji_feedback(0x201, 0, 0), t(500))
        .unwrap();
    m.set_target_current(5.0).unwrap();
    m.set_current_limit_amps(0.0).unwrap();
    m.update(t(1000), DT);
    assert_eq!(m.state().command, 0.0);
    assert_eq!(
        m.set_current_limit_amps(-0.1),
        Err(rc10_core::motor::TargetError::OutOfRange)
    );
}

#[test]
fn dji_angle_gains_set_while_running_drive_the_next_tick() {
    // Total-angle target 30° away. With the angle loop's gains all zero it asks for 0 rpm and
    // the speed loop (at zero speed error) commands nothing; with the default gains it would
    // command current toward the target.
    let m = DjiMotor::m3508(1).unwrap();
    let t = Instant::from_micros;
    m.update_feedback(&dji_feedback(0x201, 0, 0), t(500))
        .unwrap();
    m.set_angle_pid(PidConfig::new(0.0, 0.0, 0.0)).unwrap();
    m.set_target_total_angle_deg(30.0).unwrap();
    m.update(t(1000), DT);
    assert_eq!(m.state().command, 0.0);
    assert!(m.set_angle_pid(PidConfig::new(f32::NAN, 0.0, 0.0)).is_err());
    assert_eq!(m.esc_id(), 1);
    assert_eq!(DjiMotor::gm6020_voltage(7).unwrap().esc_id(), 7);
}

#[test]
fn pid_configuration_rules_for_separation_and_the_d_filter() {
    let base = PidConfig::new(1.0, 1.0, 0.0);
    use rc10_core::pid::PidConfigError::{InvalidFilter, InvalidSeparation};
    // Documented: a separation threshold that is NaN or not above the deadband is refused
    // (no error would ever be integrated: the I term off without a word, RC10_LIB's defect;
    // a C habit writes 0 for "no separation"); a D cutoff that is NaN or negative is refused,
    // 0 is no filter.
    for separation in [-1.0, f32::NAN, 0.0] {
        assert_eq!(
            base.with_integral_separation(separation).validate(),
            Err(InvalidSeparation)
        );
    }
    assert_eq!(base.with_integral_separation(0.01).validate(), Ok(()));
    let banded = base.with_deadband(5.0);
    assert_eq!(
        banded.with_integral_separation(5.0).validate(),
        Err(InvalidSeparation)
    );
    assert_eq!(banded.with_integral_separation(5.5).validate(), Ok(()));
    assert_eq!(
        banded.with_integral_separation(f32::INFINITY).validate(),
        Ok(())
    );
    assert_eq!(base.with_d_cutoff_hz(-1.0).validate(), Err(InvalidFilter));
    assert_eq!(
        base.with_d_cutoff_hz(f32::NAN).validate(),
        Err(InvalidFilter)
    );
    assert_eq!(base.with_d_cutoff_hz(0.0).validate(), Ok(()));
    // A band of 5 with separation 5.5: the error 5.2 is integrated, 6 is not.
    let mut pid = rc10_core::pid::Pid::new(
        PidConfig::new(0.0, 1.0, 0.0)
            .with_deadband(5.0)
            .with_integral_separation(5.5),
    )
    .unwrap();
    pid.update(5.2, 0.0, 0.001); // first step: rectangle, 5.2 · 0.001
    assert!((pid.update(6.0, 0.0, 0.001).i - 0.0052).abs() < 1e-7); // frozen at 6
    assert!((pid.update(5.2, 0.0, 0.001).i - 0.0104).abs() < 1e-7); // re-entry: rectangle
}

#[test]
fn a_d_filter_added_by_live_tuning_filters_the_next_step() {
    // kd = 1 s; the measurement jumps by 1 in 1 ms: unfiltered D = -1000. Live-tuned to a
    // 10 Hz first-order filter (tau = 1/(2π·10) s, backward Euler: alpha = dt / (tau + dt)
    // = 0.0591), starting from the present D of 0: D = -1000 · 0.0591 = -59.1.
    let mut pid = Pid::new(PidConfig::new(0.0, 0.0, 1.0)).unwrap();
    pid.update(0.0, 0.0, DT);
    pid.set_config(PidConfig::new(0.0, 0.0, 1.0).with_d_cutoff_hz(10.0))
        .unwrap();
    let t = pid.update(0.0, 1.0, DT);
    let tau = 1.0 / (2.0 * core::f32::consts::PI * 10.0);
    let expected = -1000.0 * DT / (tau + DT);
    assert!((t.d - expected).abs() < 0.5, "{t:?} vs {expected}");
}

#[test]
fn dji_motor_debug_names_model_and_id() {
    let s = format!("{:?}", DjiMotor::m2006(5).unwrap());
    assert!(
        s.contains("DjiMotor") && s.contains("M2006") && s.contains('5'),
        "{s}"
    );
}

#[test]
fn swerve_steering_stays_in_its_documented_range_when_driving_straight_back() {
    // Driving backwards (vx = -1 m/s) with vy = -0.0: for the rear modules (x < 0) the module
    // velocity's y part is -0.0 + 0·x = -0.0, and atan2(-0.0, -1) = -π. The documented range
    // of a steering angle is (-π, π]: every module must say π, wheel forward at
    // 1 m/s / 0.05 m = 20 rad/s = 190.99 rpm.
    use rc10_core::chassis::{ModuleState, Swerve, Twist};
    let s = Swerve::new(0.4, 0.3, 0.05).unwrap();
    let current = [ModuleState {
        steer_rad: core::f32::consts::PI,
        wheel_rpm: 0.0,
    }; 4];
    let out = s.modules(Twist::new(-1.0, -0.0, 0.0), &current);
    for m in out {
        assert_eq!(m.steer_rad, core::f32::consts::PI, "{out:?}");
        assert!((m.wheel_rpm - 20.0 * 60.0 / core::f32::consts::TAU).abs() < 1e-2);
    }
}

#[test]
fn swerve_odometry_of_a_non_finite_module_is_zero_not_nan() {
    use rc10_core::chassis::{ModuleState, Swerve, Twist};
    let s = Swerve::new(0.4, 0.3, 0.05).unwrap();
    let good = ModuleState {
        steer_rad: 0.0,
        wheel_rpm: 100.0,
    };
    for bad in [
        ModuleState {
            steer_rad: 0.0,
            wheel_rpm: f32::NAN,
        },
        ModuleState {
            steer_rad: f32::INFINITY,
            wheel_rpm: 100.0,
        },
    ] {
        assert_eq!(s.twist(&[good, good, good, bad]), Twist::ZERO, "{bad:?}");
    }
    // All finite: 100 rpm forward on every module = 100 · 2π/60 · 0.05 m/s forward.
    let t = s.twist(&[good; 4]);
    assert!(
        (t.vx_m_s - 100.0 * core::f32::consts::TAU / 60.0 * 0.05).abs() < 1e-4,
        "{t:?}"
    );
}

#[test]
fn wrap_signed_refuses_bad_periods_and_stays_in_range_at_the_extremes() {
    use rc10_core::math::wrap_signed;
    // Documented: 0.0 for a non-finite value or a non-finite or non-positive period.
    for (value, period) in [
        (10.0, -360.0),
        (10.0, 0.0),
        (10.0, f32::INFINITY),
        (10.0, f32::NAN),
        (f32::NAN, 360.0),
        (f32::INFINITY, 360.0),
    ] {
        assert_eq!(wrap_signed(value, period), 0.0, "{value} {period}");
    }
    // Always within [-period/2, period/2), even where value + period/2 overflows.
    let half = f32::MAX / 2.0;
    for value in [f32::MAX, -f32::MAX, f32::MAX / 1.5] {
        let w = wrap_signed(value, f32::MAX);
        assert!((-half..half).contains(&w), "{value} -> {w}");
    }
}

#[test]
fn low_speed_periodic_unwrapping_is_the_half_turn_rule_even_far_from_the_speed() {
    // Documented: at low speed (every candidate of the ±2-period window moves the rotor less
    // than a quarter turn) update_periodic is update_predicted(counts · gap), whose
    // half-turn rule keeps the plain wrapped step while the prediction is within half a turn
    // of it. 0 → 4692 wraps to 4692 − 8192 = −3500; the prediction (400) is 3900 < 4096
    // away: −3500, not the +4692 a search would pick for m = 3 (1200 predicted).
    assert_eq!(periodic_step(4692, 400.0, 1.0), -3500);
    let mut predicted = Encoder::new(EncoderConfig::dji(GearRatio::DIRECT)).unwrap();
    predicted.update(0).unwrap();
    predicted.update_predicted(4692, 400.0).unwrap();
    assert_eq!(predicted.total_counts(), -3500);
}

#[test]
fn an_absolute_encoder_starts_at_minus_180_deg_exactly_half_a_turn_from_its_zero() {
    // Origin::Absolute: the first reading is placed in [-180°, 180°) around the zero. Half a
    // turn away (raw 0, zero 4096 of 8192) is the closed end: -180°, not +180°.
    let mut config = EncoderConfig::dji(GearRatio::DIRECT);
    config.origin = rc10_core::encoder::Origin::Absolute {
        zero_offset_counts: 4096,
    };
    let mut e = Encoder::new(config).unwrap();
    e.update(0).unwrap();
    assert_eq!(e.total_counts(), -4096);
    assert_eq!(e.total_angle_deg(), -180.0);
    // Just inside the other end: raw 8191 is 4095 counts past the zero.
    let mut e = Encoder::new(config).unwrap();
    e.update(8191).unwrap();
    assert_eq!(e.total_counts(), 4095);
}

#[test]
fn an_integral_only_loop_saturates_exactly_at_the_output_limit() {
    // kp = kd = 0 is a valid configuration. A constant error of 3 with ki·e·dt = 3 per step
    // and a 10 limit: 3, 6, 9, then the integral reaches the limit itself (conditional
    // integration only refuses growth that pushes the sum *beyond* the limit).
    let mut pid = Pid::new(PidConfig::new(0.0, 1000.0, 0.0).with_output_limit(10.0)).unwrap();
    let mut out = 0.0;
    for _ in 0..10 {
        out = pid.update(3.0, 0.0, 0.001).output;
    }
    assert_eq!(out, 10.0);
    // The same downwards.
    let mut pid = Pid::new(PidConfig::new(0.0, 1000.0, 0.0).with_output_limit(10.0)).unwrap();
    for _ in 0..10 {
        out = pid.update(-3.0, 0.0, 0.001).output;
    }
    assert_eq!(out, -10.0);
}

#[test]
fn periodic_fits_exactly_256_counts_apart_are_equally_good() {
    // Documented: fits within 256 counts of each other are equally good, and then the m
    // nearer the measured gap wins. 600 counts/period, gap 1 (window m = 1..3), reading 5168
    // (wrapped step −3024): m = 1 predicts 600, nearest step −3024, 3624 off; m = 2 predicts
    // 1200, step 5168, 3968 off; m = 3 predicts 1800, step 5168, 3368 off. m = 3 fits
    // exactly 256 better than m = 1: equally good, and m = 1 is nearer the gap.
    assert_eq!(periodic_step(5168, 600.0, 1.0), -3024);
}
