//! `geometry_msgs`: points, rotations, poses, velocities and transforms,
//! with the planar pose deog uses on either side.

use deog_grid::Pose2;

use super::{Header, RosMessage, read_f64_array, write_f64_array};
use crate::cdr::{CdrReader, CdrWriter};
use crate::error::RecordingError;

/// `geometry_msgs/Point`: metres.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Point {
    /// Metres.
    pub x: f64,
    /// Metres.
    pub y: f64,
    /// Metres.
    pub z: f64,
}

/// `geometry_msgs/Vector3`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vector3 {
    /// Along x.
    pub x: f64,
    /// Along y.
    pub y: f64,
    /// Along z.
    pub z: f64,
}

/// `geometry_msgs/Quaternion`: a rotation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quaternion {
    /// Imaginary i part.
    pub x: f64,
    /// Imaginary j part.
    pub y: f64,
    /// Imaginary k part.
    pub z: f64,
    /// Real part.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Quaternion {
    /// No rotation.
    pub const IDENTITY: Quaternion = Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    };

    /// A rotation of `yaw` radians about +z.
    pub fn from_yaw(yaw: f64) -> Self {
        let (s, c) = (yaw / 2.0).sin_cos();
        Self {
            x: 0.0,
            y: 0.0,
            z: s,
            w: c,
        }
    }

    /// The heading of the rotated x axis in the x-y plane, radians.
    pub fn yaw(self) -> f64 {
        (2.0 * (self.w * self.z + self.x * self.y))
            .atan2(1.0 - 2.0 * (self.y * self.y + self.z * self.z))
    }

    /// The same rotation with unit length; `None` for a zero or
    /// non-finite quaternion.
    pub fn normalized(self) -> Option<Self> {
        let n = (self.x * self.x + self.y * self.y + self.z * self.z + self.w * self.w).sqrt();
        (n.is_finite() && n > 1e-9).then(|| Self {
            x: self.x / n,
            y: self.y / n,
            z: self.z / n,
            w: self.w / n,
        })
    }

    /// `self` then `other` (other expressed in the frame self rotates to).
    pub fn then(self, other: Self) -> Self {
        let (a, b) = (self, other);
        Self {
            w: a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z,
            x: a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
            y: a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
            z: a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w,
        }
    }

    /// `v` rotated.
    pub fn rotate(self, v: Vector3) -> Vector3 {
        let q = self;
        // v + 2w(q×v) + 2 q×(q×v)
        let (tx, ty, tz) = (
            2.0 * (q.y * v.z - q.z * v.y),
            2.0 * (q.z * v.x - q.x * v.z),
            2.0 * (q.x * v.y - q.y * v.x),
        );
        Vector3 {
            x: v.x + q.w * tx + (q.y * tz - q.z * ty),
            y: v.y + q.w * ty + (q.z * tx - q.x * tz),
            z: v.z + q.w * tz + (q.x * ty - q.y * tx),
        }
    }
}

/// `geometry_msgs/Pose`: a position and an orientation.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// Where.
    pub position: Point,
    /// Which way.
    pub orientation: Quaternion,
}

impl Pose {
    /// A planar pose on the ground (z = 0, rotated about z only).
    pub fn from_planar(pose: Pose2) -> Self {
        Self {
            position: Point {
                x: pose.x,
                y: pose.y,
                z: 0.0,
            },
            orientation: Quaternion::from_yaw(pose.theta),
        }
    }

    /// The pose seen from above: x, y and the heading; `None` if a
    /// figure is not finite or the orientation is no rotation.
    pub fn planar(&self) -> Option<Pose2> {
        let q = self.orientation.normalized()?;
        let pose = Pose2::new(self.position.x, self.position.y, q.yaw());
        (pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite()).then_some(pose)
    }
}

/// `geometry_msgs/PoseWithCovariance`: a pose and its 6 x 6 covariance
/// over (x, y, z, roll, pitch, yaw), row-major.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose,
    /// Row-major 6 x 6.
    pub covariance: [f64; 36],
}

impl Default for PoseWithCovariance {
    fn default() -> Self {
        Self {
            pose: Pose::default(),
            covariance: [0.0; 36],
        }
    }
}

/// Where the planar (x, y, theta) entries sit in a 6 x 6 covariance over
/// (x, y, z, roll, pitch, yaw).
const PLANAR_AXES: [usize; 3] = [0, 1, 5];

impl PoseWithCovariance {
    /// A planar pose with its 3 x 3 (x, y, theta) covariance, row-major,
    /// placed in the 6 x 6 one (the other axes zero).
    pub fn from_planar(pose: Pose2, covariance: &[f64; 9]) -> Self {
        let mut full = [0.0; 36];
        for (i, &row) in PLANAR_AXES.iter().enumerate() {
            for (j, &column) in PLANAR_AXES.iter().enumerate() {
                full[row * 6 + column] = covariance[i * 3 + j];
            }
        }
        Self {
            pose: Pose::from_planar(pose),
            covariance: full,
        }
    }

    /// The 3 x 3 (x, y, theta) part of the covariance, row-major.
    pub fn planar_covariance(&self) -> [f64; 9] {
        let mut out = [0.0; 9];
        for (i, &row) in PLANAR_AXES.iter().enumerate() {
            for (j, &column) in PLANAR_AXES.iter().enumerate() {
                out[i * 3 + j] = self.covariance[row * 6 + column];
            }
        }
        out
    }
}

/// `geometry_msgs/Twist`: linear and angular velocity.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Twist {
    /// Metres per second.
    pub linear: Vector3,
    /// Radians per second.
    pub angular: Vector3,
}

/// `geometry_msgs/TwistWithCovariance`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwistWithCovariance {
    /// The velocity.
    pub twist: Twist,
    /// Row-major 6 x 6.
    pub covariance: [f64; 36],
}

impl Default for TwistWithCovariance {
    fn default() -> Self {
        Self {
            twist: Twist::default(),
            covariance: [0.0; 36],
        }
    }
}

/// `geometry_msgs/Transform`: where a child frame sits in its parent.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Transform {
    /// The child's origin in the parent, metres.
    pub translation: Vector3,
    /// The child's axes in the parent.
    pub rotation: Quaternion,
}

impl Transform {
    /// A planar transform (z = 0, rotated about z only).
    pub fn from_planar(pose: Pose2) -> Self {
        Self {
            translation: Vector3 {
                x: pose.x,
                y: pose.y,
                z: 0.0,
            },
            rotation: Quaternion::from_yaw(pose.theta),
        }
    }

    /// `self` then `child` (a transform given in self's child frame).
    pub fn then(&self, child: &Transform) -> Transform {
        let moved = self.rotation.rotate(child.translation);
        Transform {
            translation: Vector3 {
                x: self.translation.x + moved.x,
                y: self.translation.y + moved.y,
                z: self.translation.z + moved.z,
            },
            rotation: self.rotation.then(child.rotation),
        }
    }
}

/// `geometry_msgs/TransformStamped`: a transform from `header.frame_id`
/// to `child_frame_id`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TransformStamped {
    /// When, and the parent frame.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// The child in the parent.
    pub transform: Transform,
}

/// `geometry_msgs/PoseStamped`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PoseStamped {
    /// When, and the frame the pose is in.
    pub header: Header,
    /// The pose.
    pub pose: Pose,
}

/// `geometry_msgs/PoseWithCovarianceStamped`: what localizers publish.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PoseWithCovarianceStamped {
    /// When, and the frame the pose is in.
    pub header: Header,
    /// The pose and its uncertainty.
    pub pose: PoseWithCovariance,
}

impl RosMessage for Point {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/Point";
    fn write(&self, w: &mut CdrWriter) {
        write_f64_array(w, &[self.x, self.y, self.z]);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        let [x, y, z] = read_f64_array(r, "point")?;
        Ok(Self { x, y, z })
    }
}

impl RosMessage for Vector3 {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/Vector3";
    fn write(&self, w: &mut CdrWriter) {
        write_f64_array(w, &[self.x, self.y, self.z]);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        let [x, y, z] = read_f64_array(r, "vector")?;
        Ok(Self { x, y, z })
    }
}

impl RosMessage for Quaternion {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/Quaternion";
    fn write(&self, w: &mut CdrWriter) {
        write_f64_array(w, &[self.x, self.y, self.z, self.w]);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        let [x, y, z, w] = read_f64_array(r, "quaternion")?;
        Ok(Self { x, y, z, w })
    }
}

impl RosMessage for Pose {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/Pose";
    fn write(&self, w: &mut CdrWriter) {
        self.position.write(w);
        self.orientation.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        Ok(Self {
            position: Point::read(r)?,
            orientation: Quaternion::read(r)?,
        })
    }
}

impl RosMessage for PoseWithCovariance {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/PoseWithCovariance";
    fn write(&self, w: &mut CdrWriter) {
        self.pose.write(w);
        write_f64_array(w, &self.covariance);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        Ok(Self {
            pose: Pose::read(r)?,
            covariance: read_f64_array(r, "covariance")?,
        })
    }
}

impl RosMessage for Twist {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/Twist";
    fn write(&self, w: &mut CdrWriter) {
        self.linear.write(w);
        self.angular.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        Ok(Self {
            linear: Vector3::read(r)?,
            angular: Vector3::read(r)?,
        })
    }
}

impl RosMessage for TwistWithCovariance {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/TwistWithCovariance";
    fn write(&self, w: &mut CdrWriter) {
        self.twist.write(w);
        write_f64_array(w, &self.covariance);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        Ok(Self {
            twist: Twist::read(r)?,
            covariance: read_f64_array(r, "covariance")?,
        })
    }
}

impl RosMessage for Transform {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/Transform";
    fn write(&self, w: &mut CdrWriter) {
        self.translation.write(w);
        self.rotation.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        Ok(Self {
            translation: Vector3::read(r)?,
            rotation: Quaternion::read(r)?,
        })
    }
}

impl RosMessage for TransformStamped {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/TransformStamped";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.string(&self.child_frame_id);
        self.transform.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        Ok(Self {
            header: Header::read(r)?,
            child_frame_id: r.string("child_frame_id")?,
            transform: Transform::read(r)?,
        })
    }
}

impl RosMessage for PoseStamped {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/PoseStamped";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        self.pose.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        Ok(Self {
            header: Header::read(r)?,
            pose: Pose::read(r)?,
        })
    }
}

impl RosMessage for PoseWithCovarianceStamped {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/PoseWithCovarianceStamped";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        self.pose.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self, RecordingError> {
        Ok(Self {
            header: Header::read(r)?,
            pose: PoseWithCovariance::read(r)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;

    #[test]
    fn a_planar_pose_survives_the_quaternion() {
        for theta in [-3.0, -1.0, 0.0, 0.5, 3.1] {
            let pose = Pose::from_planar(Pose2::new(1.0, -2.0, theta));
            let back = pose.planar().unwrap();
            assert_abs_diff_eq!(back.theta, theta, epsilon = 1e-12);
            assert_abs_diff_eq!(back.x, 1.0);
        }
        let zero = Pose {
            orientation: Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 0.0,
            },
            ..Pose::default()
        };
        assert!(zero.planar().is_none());
    }

    #[test]
    fn transforms_compose_like_planar_poses() {
        let a = Pose2::new(1.0, 2.0, 0.7);
        let b = Pose2::new(0.3, -0.1, -0.2);
        let composed = Transform::from_planar(a).then(&Transform::from_planar(b));
        let expected = a.compose(&b);
        assert_abs_diff_eq!(composed.translation.x, expected.x, epsilon = 1e-12);
        assert_abs_diff_eq!(composed.translation.y, expected.y, epsilon = 1e-12);
        assert_abs_diff_eq!(composed.rotation.yaw(), expected.theta, epsilon = 1e-12);
    }

    #[test]
    fn the_planar_covariance_sits_on_x_y_and_yaw() {
        let c = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0];
        let full = PoseWithCovariance::from_planar(Pose2::new(0.0, 0.0, 0.0), &c);
        assert_eq!(full.covariance[5], 3.0);
        assert_eq!(full.covariance[30], 7.0);
        assert_eq!(full.covariance[35], 9.0);
        assert_eq!(full.covariance[14], 0.0);
        assert_eq!(full.planar_covariance(), c);
    }
}
