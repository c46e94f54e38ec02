//! The remote-driven chassis application: DR16 sticks to mecanum wheel targets, as firmware would.

use super::SimError;
use super::faults::in_window;
use super::run::{SimMotor, TICK_US};
use crate::plant::DjiEsc;
use rc10_core::chassis::{LinearChassis, MecanumConfig, Twist, TwistLimiter};
use rc10_core::remote::dbus::DbusReceiver;
use rc10_core::time::{Duration, Instant};

/// Robot firmware driving a mecanum chassis from a DR16 remote: each DBUS frame (every 14 ms)
/// is encoded as the receiver sends it and its bytes reach rc10's `DbusReceiver` one by one,
/// stamped as rc10-stm32's UART task stamps them: the UART's idle-line event comes one
/// character (110 µs at 100 kbaud) after the last byte it read, and each byte is stamped that
/// long after it ended on the line. So the frame counts, as on the robot, once the silence
/// after it exceeds `remote::FRAME_GAP`: at the first tick more than 2.5 ms after its last
/// byte's stamp, 5 ms after the frame began. A frame cut by the start of a `radio_off`
/// window is dropped as too short. Frames due while the scheduler stalls are sent all the
/// same and read, with their own stamps, at the next tick. The sticks become a
/// twist (left stick: vx, vy; right stick x: ω), limited by a `TwistLimiter`, turned into wheel
/// rpm by rc10's mecanum kinematics (saturated together) and set on motors 1–4 (FL, FR, RL,
/// RR). Achieved twist is the chassis's forward kinematics of the true wheel speeds (no slip;
/// each wheel carries its share of the robot's inertia as its own load).
#[derive(Debug, Clone, PartialEq)]
pub struct ChassisDrive {
    /// Chassis geometry and motor signs.
    pub geometry: MecanumConfig,
    /// Twist at full stick deflection (m/s, m/s, rad/s).
    pub max_twist: Twist,
    /// Acceleration limits (m/s², m/s², rad/s²).
    pub max_accel: Twist,
    /// Wheel speed limit, output rpm.
    pub max_wheel_rpm: f32,
    /// Stick positions from a time on (ms): right x, right y, left x, left y in −1…1.
    pub sticks: Vec<(u64, [f32; 4])>,
    /// Windows `[from_ms, to_ms)` in which the receiver sends nothing: a frame due inside one
    /// is not sent, and a frame under way when one begins is cut (its bytes that would end
    /// inside it are not sent).
    pub radio_off: Vec<(u64, u64)>,
}

/// What the chassis application commanded and what the chassis did, at one tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ChassisSample {
    /// Twist sent to the kinematics (after the limiter).
    pub commanded: Twist,
    /// Twist from the true wheel speeds.
    pub achieved: Twist,
    /// Whether the remote link was lost.
    pub link_lost: bool,
}

/// The robot firmware of a chassis scenario.
pub(super) struct ChassisApp {
    kinematics: LinearChassis<4>,
    limiter: TwistLimiter,
    receiver: DbusReceiver,
    /// The DBUS frame on the line: when it began (µs), its bytes, how many have been read.
    on_line: Option<(u64, [u8; 18], usize)>,
    /// When the next DBUS frame is due, µs.
    next_frame_us: u64,
}

/// DR16 frame period.
const DBUS_PERIOD_MS: u64 = 14;

/// One DBUS byte on the line: 11 bits (start, 8 data, even parity, stop) at 100 kbaud, µs.
/// Also how long after a byte the UART's idle-line event reads it (one idle character).
const DBUS_BYTE_US: u64 = 110;

/// The motors a chassis drives: the first four (FL, FR, RL, RR).
pub(super) const CHASSIS_WHEELS: usize = 4;

impl ChassisApp {
    pub(super) fn new(drive: &ChassisDrive, motor_count: usize) -> Result<Self, SimError> {
        if motor_count < CHASSIS_WHEELS {
            return Err(SimError::InvalidMotor {
                motor: motor_count,
                reason: "a chassis needs motors 1-4 (FL, FR, RL, RR)".into(),
            });
        }
        let kinematics =
            LinearChassis::mecanum(drive.geometry).map_err(|e| SimError::InvalidMotor {
                motor: 0,
                reason: e.to_string(),
            })?;
        Ok(Self {
            kinematics,
            limiter: TwistLimiter::new(drive.max_accel),
            receiver: DbusReceiver::new(Duration::from_millis(100)),
            on_line: None,
            next_frame_us: 0,
        })
    }

    pub(super) fn step(
        &mut self,
        drive: &ChassisDrive,
        motors: &[Box<dyn SimMotor>],
        escs: &[DjiEsc],
        now: Instant,
    ) -> Result<ChassisSample, String> {
        let radio_on = |ms: u64| {
            !drive
                .radio_off
                .iter()
                .any(|(from, to)| in_window(ms, *from, *to))
        };
        let now_us = now.as_micros();
        loop {
            // The bytes read by now, each stamped one idle character after it ended.
            if let Some((start_us, bytes, read)) = &mut self.on_line {
                while let Some(&byte) = bytes.get(*read) {
                    let end_us = *start_us + (*read as u64 + 1) * DBUS_BYTE_US;
                    let stamp_us = end_us + DBUS_BYTE_US;
                    if stamp_us > now_us {
                        break;
                    }
                    if radio_on(end_us / 1000) {
                        let _ = self
                            .receiver
                            .push_byte(byte, Instant::from_micros(stamp_us));
                    }
                    *read += 1;
                }
            }
            // The next frame, if it is due (every one due since the last tick, after a
            // stall). The one before is read by then: 18 bytes take 2 ms of the 14.
            if self.next_frame_us > now_us {
                break;
            }
            let start_ms = self.next_frame_us / 1000;
            self.on_line = radio_on(start_ms).then(|| {
                let sticks = drive
                    .sticks
                    .iter()
                    .rev()
                    .find(|(at, _)| *at <= start_ms)
                    .map_or([0.0; 4], |(_, s)| *s);
                // The bytes a DR16 would send, parsed by rc10 as on the robot.
                (self.next_frame_us, encode_dbus(sticks), 0)
            });
            self.next_frame_us += DBUS_PERIOD_MS * 1000;
        }
        let signal = self.receiver.signal(now);
        let f = signal.value;
        let m = drive.max_twist;
        let wanted = Twist::new(
            f.stick(3, 0.02) * m.vx_m_s,
            -f.stick(2, 0.02) * m.vy_m_s,
            -f.stick(0, 0.02) * m.omega_rad_s,
        );
        let commanded = self.limiter.update(wanted, TICK_US as f32 * 1e-6);
        let rpm = self
            .kinematics
            .wheel_rpm_limited(commanded, drive.max_wheel_rpm);
        for (motor, target) in motors.iter().zip(rpm) {
            motor.set_target_rpm(target).map_err(|e| e.to_string())?;
        }
        let mut true_rpm = [0.0f32; 4];
        for (r, esc) in true_rpm.iter_mut().zip(escs) {
            *r = esc.speed_rpm() as f32;
        }
        Ok(ChassisSample {
            commanded,
            achieved: self.kinematics.twist(&true_rpm),
            link_lost: signal.lost,
        })
    }
}

/// A DBUS frame as a DR16 sends it for sticks in −1…1 (right x, right y, left x, left y), both
/// switches in the middle.
fn encode_dbus(sticks: [f32; 4]) -> [u8; 18] {
    let mut bits: u64 = 0;
    for (i, s) in sticks.iter().enumerate() {
        let raw = (1024.0 + 660.0 * f64::from(s.clamp(-1.0, 1.0))).round() as u64;
        bits |= raw << (11 * i);
    }
    bits |= 3 << 44 | 3 << 46;
    let mut frame = [0u8; 18];
    for (i, byte) in frame.iter_mut().take(6).enumerate() {
        *byte = (bits >> (8 * i)) as u8;
    }
    if let Some(wheel) = frame.get_mut(16..18) {
        wheel.copy_from_slice(&1024u16.to_le_bytes());
    }
    frame
}
