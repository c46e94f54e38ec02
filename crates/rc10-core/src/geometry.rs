//! Poses and rigid transforms in 2D and 3D on nalgebra (RC10_LIB `CoordConvert`).
//!
//! All angles are radians; 3D orientation is roll-pitch-yaw in ZYX order
//! (`R = Rz(yaw) · Ry(pitch) · Rx(roll)`). Distances are in whatever unit you use
//! consistently (metres in rc10's chassis code). Transforms are plain `Copy` values: copying one
//! copies its numbers (RC10_LIB's copy shared a matrix buffer between copies).
//!
//! A transform built from a pose maps coordinates *in the posed frame* to coordinates *in the
//! frame the pose is written in* ("sensor to robot" for a sensor mounted at that pose).
//!
//! The two examples from the RC10_LIB manual:
//!
//! ```
//! use core::f32::consts::FRAC_PI_4;
//! use rc10_core::geometry::{Point2, Pose2D, Transform2D};
//! // A sensor at (0.2, 0.1) m on the robot, turned 45° left, sees a point at (0.5, 0) m.
//! let sensor_to_robot = Transform2D::from_pose(Pose2D::new(0.2, 0.1, FRAC_PI_4));
//! let p = sensor_to_robot.apply(Point2::new(0.5, 0.0));
//! // (0.2 + 0.5·cos 45°, 0.1 + 0.5·sin 45°) = (0.553553, 0.453553)
//! assert!((p.x - 0.553_553).abs() < 1e-5 && (p.y - 0.453_553).abs() < 1e-5);
//! ```
//!
//! ```
//! use core::f32::consts::FRAC_PI_2;
//! use rc10_core::geometry::{Point3, Pose3D, Transform3D};
//! // A camera at (1, 2, 0.5) m in the world, yawed 90°, sees a point at (0, 1, 0) m.
//! let camera_to_world = Transform3D::from_pose(Pose3D::new(1.0, 2.0, 0.5, 0.0, 0.0, FRAC_PI_2));
//! let p = camera_to_world.apply(Point3::new(0.0, 1.0, 0.0));
//! // Rz(90°)·(0, 1, 0) = (-1, 0, 0); plus the translation: (0, 2, 0.5).
//! assert!((p - Point3::new(0.0, 2.0, 0.5)).norm() < 1e-6);
//! // And back through the inverse.
//! let back = camera_to_world.inverse().apply(p);
//! assert!((back - Point3::new(0.0, 1.0, 0.0)).norm() < 1e-6);
//! ```

use core::ops::Mul;
use nalgebra::{Isometry2, Isometry3, Matrix3, Matrix4, Translation2, Translation3};
use nalgebra::{UnitComplex, UnitQuaternion, Vector2, Vector3};

/// A 2D point (nalgebra), in metres by rc10's convention.
pub type Point2 = nalgebra::Point2<f32>;
/// A 3D point (nalgebra), in metres by rc10's convention.
pub type Point3 = nalgebra::Point3<f32>;

/// A planar pose: position and heading (RC10_LIB `Point2D` with an angle).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Pose2D {
    /// X position.
    pub x: f32,
    /// Y position.
    pub y: f32,
    /// Heading in radians, counter-clockwise from +X.
    pub theta_rad: f32,
}

impl Pose2D {
    /// A pose at `(x, y)` with heading `theta_rad`.
    pub const fn new(x: f32, y: f32, theta_rad: f32) -> Self {
        Self { x, y, theta_rad }
    }
}

/// A 3D pose: position and ZYX roll-pitch-yaw orientation (RC10_LIB `Point3D`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Pose3D {
    /// X position.
    pub x: f32,
    /// Y position.
    pub y: f32,
    /// Z position.
    pub z: f32,
    /// Rotation about X in radians (applied first).
    pub roll_rad: f32,
    /// Rotation about Y in radians (applied second).
    pub pitch_rad: f32,
    /// Rotation about Z in radians (applied last).
    pub yaw_rad: f32,
}

impl Pose3D {
    /// A pose at `(x, y, z)` with orientation roll, pitch, yaw (radians, ZYX).
    pub const fn new(x: f32, y: f32, z: f32, roll_rad: f32, pitch_rad: f32, yaw_rad: f32) -> Self {
        Self {
            x,
            y,
            z,
            roll_rad,
            pitch_rad,
            yaw_rad,
        }
    }
}

/// A rigid 2D transform (rotation then translation); RC10_LIB `HomogeneousTransform2D`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform2D(pub Isometry2<f32>);

impl Transform2D {
    /// The identity transform.
    pub fn identity() -> Self {
        Self(Isometry2::identity())
    }

    /// The transform from the frame at `pose` into the frame `pose` is written in.
    pub fn from_pose(pose: Pose2D) -> Self {
        Self(Isometry2::from_parts(
            Translation2::new(pose.x, pose.y),
            UnitComplex::new(pose.theta_rad),
        ))
    }

    /// The pose this transform places its frame at (heading in `(-π, π]`).
    pub fn to_pose(&self) -> Pose2D {
        let t = self.0.translation.vector;
        Pose2D::new(t.x, t.y, self.0.rotation.angle())
    }

    /// Maps a point.
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "nalgebra f32 product: no integer overflow"
    )]
    pub fn apply(&self, point: Point2) -> Point2 {
        self.0 * point
    }

    /// Rotates a vector (a velocity, say) without translating it.
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "nalgebra f32 product: no integer overflow"
    )]
    pub fn apply_vector(&self, v: Vector2<f32>) -> Vector2<f32> {
        self.0 * v
    }

    /// `self ∘ other`: first `other`, then `self`.
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "nalgebra f32 product: no integer overflow"
    )]
    pub fn compose(&self, other: &Self) -> Self {
        Self(self.0 * other.0)
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Self {
        Self(self.0.inverse())
    }

    /// The 3×3 homogeneous matrix.
    pub fn to_homogeneous(&self) -> Matrix3<f32> {
        self.0.to_homogeneous()
    }
}

impl Mul for Transform2D {
    type Output = Self;
    fn mul(self, rhs: Self) -> Self {
        self.compose(&rhs)
    }
}

/// A rigid 3D transform (rotation then translation); RC10_LIB `HomogeneousTransform3D`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform3D(pub Isometry3<f32>);

impl Transform3D {
    /// The identity transform.
    pub fn identity() -> Self {
        Self(Isometry3::identity())
    }

    /// The transform from the frame at `pose` into the frame `pose` is written in.
    pub fn from_pose(pose: Pose3D) -> Self {
        Self(Isometry3::from_parts(
            Translation3::new(pose.x, pose.y, pose.z),
            // nalgebra applies roll, then pitch, then yaw about fixed axes: R = Rz·Ry·Rx.
            UnitQuaternion::from_euler_angles(pose.roll_rad, pose.pitch_rad, pose.yaw_rad),
        ))
    }

    /// The pose this transform places its frame at (ZYX angles in radians; pitch in
    /// `[-π/2, π/2]`, roll and yaw in `[-π, π]`).
    ///
    /// At pitch ±π/2 (a camera looking straight down, say) only roll − yaw (at +π/2) or
    /// roll + yaw (at −π/2) is defined: the pose then has yaw 0 and carries the whole turn
    /// in roll, and rebuilds the same rotation. Within about 3·10⁻⁴ rad of ±π/2 it is put
    /// there too: the rotation it rebuilds differs from this one by less than 10⁻³ (f32
    /// rounding leaves nothing sharper to read there).
    pub fn to_pose(&self) -> Pose3D {
        let t = self.0.translation.vector;
        let (roll, pitch, yaw) = zyx_angles(self.0.rotation.to_rotation_matrix().matrix());
        Pose3D::new(t.x, t.y, t.z, roll, pitch, yaw)
    }

    /// Maps a point.
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "nalgebra f32 product: no integer overflow"
    )]
    pub fn apply(&self, point: Point3) -> Point3 {
        self.0 * point
    }

    /// Rotates a vector without translating it.
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "nalgebra f32 product: no integer overflow"
    )]
    pub fn apply_vector(&self, v: Vector3<f32>) -> Vector3<f32> {
        self.0 * v
    }

    /// `self ∘ other`: first `other`, then `self`.
    #[allow(
        clippy::arithmetic_side_effects,
        reason = "nalgebra f32 product: no integer overflow"
    )]
    pub fn compose(&self, other: &Self) -> Self {
        Self(self.0 * other.0)
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Self {
        Self(self.0.inverse())
    }

    /// The 4×4 homogeneous matrix.
    pub fn to_homogeneous(&self) -> Matrix4<f32> {
        self.0.to_homogeneous()
    }
}

impl Mul for Transform3D {
    type Output = Self;
    fn mul(self, rhs: Self) -> Self {
        self.compose(&rhs)
    }
}

/// Below this `cos(pitch)` the pose is read as gimbal-locked: the roll and yaw terms of the
/// matrix are f32 rounding (about 10⁻⁷) scaled by `1 / cos(pitch)`, so each reading would
/// be off by as much as the lock's own approximation (`cos(pitch)`) is.
const GIMBAL_LOCK_COS: f32 = 3.0e-4;

/// Roll, pitch and yaw (rad) of `m = Rz(yaw)·Ry(pitch)·Rx(roll)`.
///
/// nalgebra's `euler_angles` tests for the lock with `|m31| ≥ 1`, which an f32 matrix built
/// at pitch ±π/2 misses by one rounding step (±0.99999994): it then divided rounding noise
/// by `cos(pitch)` ≈ 3·10⁻⁴ and read roll and yaw at random.
fn zyx_angles(m: &Matrix3<f32>) -> (f32, f32, f32) {
    // |cos(pitch)| from the first column, which holds cos(pitch)·(cos(yaw), sin(yaw)).
    let cos_pitch = libm::hypotf(m.m11, m.m21);
    let pitch = libm::atan2f(-m.m31, cos_pitch);
    if cos_pitch < GIMBAL_LOCK_COS {
        // m22 = cos(roll ∓ yaw), m23 = −sin(roll ∓ yaw) at pitch ±π/2: with yaw 0, that is
        // the roll.
        (libm::atan2f(-m.m23, m.m22), pitch, 0.0)
    } else {
        (
            libm::atan2f(m.m32, m.m33),
            pitch,
            libm::atan2f(m.m21, m.m11),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f32::consts::{FRAC_PI_2, PI};
    use proptest::prelude::*;

    #[test]
    fn zyx_order_matches_hand_rotation() {
        // roll 90° then yaw 90°: +Y → (roll) +Z → (yaw keeps Z) +Z.
        // +X → (roll keeps X) +X → (yaw) +Y.
        let t = Transform3D::from_pose(Pose3D::new(0.0, 0.0, 0.0, FRAC_PI_2, 0.0, FRAC_PI_2));
        assert!((t.apply(Point3::new(0.0, 1.0, 0.0)) - Point3::new(0.0, 0.0, 1.0)).norm() < 1e-6);
        assert!((t.apply(Point3::new(1.0, 0.0, 0.0)) - Point3::new(0.0, 1.0, 0.0)).norm() < 1e-6);
    }

    #[test]
    fn compose_applies_right_operand_first() {
        let move_x = Transform2D::from_pose(Pose2D::new(1.0, 0.0, 0.0));
        let turn = Transform2D::from_pose(Pose2D::new(0.0, 0.0, FRAC_PI_2));
        // turn ∘ move_x: (0,0) → (1,0) → (0,1).
        let p = (turn * move_x).apply(Point2::origin());
        assert!((p - Point2::new(0.0, 1.0)).norm() < 1e-6);
    }

    #[test]
    fn to_pose_round_trips() {
        let pose = Pose2D::new(0.3, -0.2, 2.0);
        let back = Transform2D::from_pose(pose).to_pose();
        assert!((back.x - 0.3).abs() < 1e-6 && (back.theta_rad - 2.0).abs() < 1e-6);
        let p3 = Pose3D::new(1.0, 2.0, 3.0, 0.1, -0.2, 0.3);
        let b3 = Transform3D::from_pose(p3).to_pose();
        assert!((b3.roll_rad - 0.1).abs() < 1e-5);
        assert!((b3.pitch_rad + 0.2).abs() < 1e-5);
        assert!((b3.yaw_rad - 0.3).abs() < 1e-5);
    }

    /// The largest entry of the difference between two transforms' rotation matrices.
    fn rotation_gap(a: &Transform3D, b: &Transform3D) -> f32 {
        let (ma, mb) = (
            a.0.rotation.to_rotation_matrix(),
            b.0.rotation.to_rotation_matrix(),
        );
        (ma.matrix() - mb.matrix()).amax()
    }

    #[test]
    fn a_pose_pitched_straight_up_or_down_rebuilds_its_rotation() {
        // A camera looking straight down (pitch +90°) with yaw 0.5: it maps +Y to
        // Rz(0.5)·Ry(90°)·+Y = Rz(0.5)·+Y = (−sin 0.5, cos 0.5, 0).
        let down = Transform3D::from_pose(Pose3D::new(0.0, 0.0, 0.0, 0.0, FRAC_PI_2, 0.5));
        let want = Point3::new(-libm::sinf(0.5), libm::cosf(0.5), 0.0);
        assert!((down.apply(Point3::new(0.0, 1.0, 0.0)) - want).norm() < 1e-6);
        // And its x axis (forward) points down, then nowhere else: Ry(+90°)·(1, 0, 0) is
        // (cos 90°, 0, −sin 90°) = (0, 0, −1), which yaw leaves alone.
        assert!(
            (down.apply(Point3::new(1.0, 0.0, 0.0)) - Point3::new(0.0, 0.0, -1.0)).norm() < 1e-6
        );
        let pose = down.to_pose();
        // At +90° only roll − yaw is defined: −0.5, carried in roll.
        assert!((pose.pitch_rad - FRAC_PI_2).abs() < 1e-3, "{pose:?}");
        assert!(
            (pose.roll_rad + 0.5).abs() < 1e-5 && pose.yaw_rad == 0.0,
            "{pose:?}"
        );
        let back = Transform3D::from_pose(pose);
        assert!((back.apply(Point3::new(0.0, 1.0, 0.0)) - want).norm() < 1e-3);

        // Both locks, at and just off ±90°, with roll and yaw all round: the rotation comes
        // back within 10⁻³.
        for p in [
            FRAC_PI_2,
            FRAC_PI_2 - 1e-6,
            FRAC_PI_2 - 1e-4,
            FRAC_PI_2 - 1e-3,
        ] {
            for sign in [1.0, -1.0] {
                for k in 0..24 {
                    let roll = -3.0 + k as f32 * 0.25;
                    let yaw = 2.9 - k as f32 * 0.27;
                    let t = Transform3D::from_pose(Pose3D::new(1.0, 2.0, 3.0, roll, sign * p, yaw));
                    let back = Transform3D::from_pose(t.to_pose());
                    let gap = rotation_gap(&t, &back);
                    assert!(
                        gap < 1e-3,
                        "pitch {}, roll {roll}, yaw {yaw}: {gap}",
                        sign * p
                    );
                }
            }
        }
    }

    #[test]
    fn homogeneous_matrix_has_translation_column() {
        let m = Transform2D::from_pose(Pose2D::new(4.0, 5.0, PI)).to_homogeneous();
        assert_eq!((m[(0, 2)], m[(1, 2)], m[(2, 2)]), (4.0, 5.0, 1.0));
    }

    #[test]
    fn transforms_are_plain_values_and_compose() {
        // RC10_LIB's transforms did not copy safely. Here every pose and transform is `Copy`
        // (a plain value, no shared storage): this fails to build if one stops being.
        fn plain_value<T: Copy>() {}
        plain_value::<Transform2D>();
        plain_value::<Transform3D>();
        plain_value::<Pose2D>();
        plain_value::<Pose3D>();
        // Composing a 1 m step with itself: 2 m.
        let a = Transform2D::from_pose(Pose2D::new(1.0, 0.0, 0.0));
        assert_eq!((a * a).to_pose().x, 2.0);
    }

    proptest! {
        #[test]
        fn transform_compose_inverse_is_identity_3d(
            x in -10f32..10.0, y in -10f32..10.0, z in -10f32..10.0,
            r in -PI..PI, p in -1.5f32..1.5, w in -PI..PI,
            px in -5f32..5.0, py in -5f32..5.0, pz in -5f32..5.0,
        ) {
            let t = Transform3D::from_pose(Pose3D::new(x, y, z, r, p, w));
            let q = Point3::new(px, py, pz);
            let round = t.compose(&t.inverse()).apply(q);
            prop_assert!((round - q).norm() < 1e-4);
            prop_assert!((t.inverse().apply(t.apply(q)) - q).norm() < 1e-4);
        }

        #[test]
        fn to_pose_rebuilds_the_rotation_at_any_pitch(
            r in -PI..PI, p in -FRAC_PI_2..=FRAC_PI_2, w in -PI..PI,
        ) {
            let t = Transform3D::from_pose(Pose3D::new(0.0, 0.0, 0.0, r, p, w));
            let pose = t.to_pose();
            prop_assert!((-FRAC_PI_2..=FRAC_PI_2).contains(&pose.pitch_rad));
            prop_assert!(rotation_gap(&t, &Transform3D::from_pose(pose)) < 1e-3);
        }

        #[test]
        fn transform_compose_inverse_is_identity_2d(
            x in -10f32..10.0, y in -10f32..10.0, th in -10f32..10.0,
            px in -5f32..5.0, py in -5f32..5.0,
        ) {
            let t = Transform2D::from_pose(Pose2D::new(x, y, th));
            let q = Point2::new(px, py);
            prop_assert!(((t * t.inverse()).apply(q) - q).norm() < 1e-4);
        }
    }
}
