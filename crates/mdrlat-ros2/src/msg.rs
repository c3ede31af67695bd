//! ROS 2's messages as they travel (XCDR1, little-endian, as every tier-1 rmw writes them):
//! serde structs whose field order is the wire order, and their conversions to and from
//! `mdrlat_ros::msg`'s, which the shared controller reads and the shared robot model writes.
//!
//! ROS 2 changed two things the node cares about: `std_msgs/Header` lost `seq`, and
//! `builtin_interfaces/Time` is `{int32 sec, uint32 nanosec}`. Odometry's nested poses and
//! covariances lay out exactly as `mdrlat_ros::msg::Odometry`'s flat fields do (CDR aligns
//! primitives, not structs), but are spelled out here as ROS 2 declares them.

use serde::{Deserialize, Serialize};
use serde_big_array::BigArray;

/// A ROS 2 message type: its package and name (`sensor_msgs`, `LaserScan`), which DDS
/// sees as `sensor_msgs::msg::dds_::LaserScan_`.
pub trait Ros2Message: Serialize + for<'de> Deserialize<'de> + Send + 'static {
    /// Package and type name.
    const TYPE: (&'static str, &'static str);
}

macro_rules! message {
    ($t:ty, $pkg:literal, $name:literal) => {
        impl Ros2Message for $t {
            const TYPE: (&'static str, &'static str) = ($pkg, $name);
        }
    };
}

/// `builtin_interfaces/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

impl Time {
    /// The wall clock now.
    pub fn now() -> Self {
        let d =
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        Self { sec: i32::try_from(d.as_secs()).unwrap_or(i32::MAX), nanosec: d.subsec_nanos() }
    }
}

/// `std_msgs/Header` (ROS 2: no sequence number).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Header {
    /// When the data was taken.
    pub stamp: Time,
    /// The sensor's frame.
    pub frame_id: String,
}

/// `sensor_msgs/LaserScan`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct LaserScan {
    /// Stamp and frame.
    pub header: Header,
    /// First beam's angle, radians.
    pub angle_min: f32,
    /// Last beam's angle, radians.
    pub angle_max: f32,
    /// Angle between beams, radians.
    pub angle_increment: f32,
    /// Seconds between measurements.
    pub time_increment: f32,
    /// Seconds between scans.
    pub scan_time: f32,
    /// Shortest valid range, metres.
    pub range_min: f32,
    /// Longest valid range, metres.
    pub range_max: f32,
    /// Ranges, metres.
    pub ranges: Vec<f32>,
    /// Intensities (device units).
    pub intensities: Vec<f32>,
}
message!(LaserScan, "sensor_msgs", "LaserScan");

/// `sensor_msgs/Image`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Image {
    /// Stamp and frame.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding (`32FC1`, `16UC1`, …).
    pub encoding: String,
    /// Whether multi-byte pixels are big-endian.
    pub is_bigendian: u8,
    /// Bytes per row.
    pub step: u32,
    /// The pixels.
    pub data: Vec<u8>,
}
message!(Image, "sensor_msgs", "Image");

/// `geometry_msgs/Vector3` (and `geometry_msgs/Point`, laid out the same).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }
    }
}

/// `geometry_msgs/Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose {
    /// Position (`geometry_msgs/Point`).
    pub position: Vector3,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/PoseWithCovariance`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose,
    /// Row-major 6 x 6 covariance (x, y, z, roll, pitch, yaw).
    #[serde(with = "BigArray")]
    pub covariance: [f64; 36],
}

/// `geometry_msgs/Twist`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Twist {
    /// Linear velocity, m/s.
    pub linear: Vector3,
    /// Angular velocity, rad/s.
    pub angular: Vector3,
}
message!(Twist, "geometry_msgs", "Twist");

impl Twist {
    /// A ground robot's command: forward speed `v`, turn rate `w`.
    pub fn planar(v: f64, w: f64) -> Self {
        Self {
            linear: Vector3 { x: v, ..Vector3::default() },
            angular: Vector3 { z: w, ..Vector3::default() },
        }
    }
}

/// `geometry_msgs/TwistStamped` (what Jazzy's `diff_drive_controller` takes by default).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TwistStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The command.
    pub twist: Twist,
}
message!(TwistStamped, "geometry_msgs", "TwistStamped");

/// `geometry_msgs/TwistWithCovariance`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    /// The velocity.
    pub twist: Twist,
    /// Row-major 6 x 6 covariance.
    #[serde(with = "BigArray")]
    pub covariance: [f64; 36],
}

/// `nav_msgs/Odometry`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// Stamp and the odometry frame.
    pub header: Header,
    /// The robot's frame.
    pub child_frame_id: String,
    /// Pose in the odometry frame.
    pub pose: PoseWithCovariance,
    /// Velocity in the robot's frame.
    pub twist: TwistWithCovariance,
}
message!(Odometry, "nav_msgs", "Odometry");

impl Default for Odometry {
    fn default() -> Self {
        Self {
            header: Header::default(),
            child_frame_id: String::new(),
            pose: PoseWithCovariance { pose: Pose::default(), covariance: [0.0; 36] },
            twist: TwistWithCovariance { twist: Twist::default(), covariance: [0.0; 36] },
        }
    }
}

// ---- to and from the shared (ROS 1 shaped) messages, moving the big vectors -------------

use mdrlat_ros::msg as one;

impl From<Time> for one::Time {
    fn from(t: Time) -> Self {
        // ROS 1 time is unsigned: a stamp before 1970 reads as 0.
        Self { sec: u32::try_from(t.sec).unwrap_or(0), nsec: t.nanosec }
    }
}

impl From<one::Time> for Time {
    fn from(t: one::Time) -> Self {
        Self { sec: i32::try_from(t.sec).unwrap_or(i32::MAX), nanosec: t.nsec }
    }
}

impl From<Header> for one::Header {
    fn from(h: Header) -> Self {
        Self { seq: 0, stamp: h.stamp.into(), frame_id: h.frame_id }
    }
}

impl From<one::Header> for Header {
    fn from(h: one::Header) -> Self {
        Self { stamp: h.stamp.into(), frame_id: h.frame_id }
    }
}

impl From<LaserScan> for one::LaserScan {
    fn from(m: LaserScan) -> Self {
        Self {
            header: m.header.into(),
            angle_min: m.angle_min,
            angle_max: m.angle_max,
            angle_increment: m.angle_increment,
            time_increment: m.time_increment,
            scan_time: m.scan_time,
            range_min: m.range_min,
            range_max: m.range_max,
            ranges: m.ranges,
            intensities: m.intensities,
        }
    }
}

impl From<one::LaserScan> for LaserScan {
    fn from(m: one::LaserScan) -> Self {
        Self {
            header: m.header.into(),
            angle_min: m.angle_min,
            angle_max: m.angle_max,
            angle_increment: m.angle_increment,
            time_increment: m.time_increment,
            scan_time: m.scan_time,
            range_min: m.range_min,
            range_max: m.range_max,
            ranges: m.ranges,
            intensities: m.intensities,
        }
    }
}

impl From<Image> for one::Image {
    fn from(m: Image) -> Self {
        Self {
            header: m.header.into(),
            height: m.height,
            width: m.width,
            encoding: m.encoding,
            is_bigendian: m.is_bigendian,
            step: m.step,
            data: m.data,
        }
    }
}

impl From<one::Image> for Image {
    fn from(m: one::Image) -> Self {
        Self {
            header: m.header.into(),
            height: m.height,
            width: m.width,
            encoding: m.encoding,
            is_bigendian: m.is_bigendian,
            step: m.step,
            data: m.data,
        }
    }
}

impl From<Vector3> for one::Vector3 {
    fn from(v: Vector3) -> Self {
        Self { x: v.x, y: v.y, z: v.z }
    }
}

impl From<one::Vector3> for Vector3 {
    fn from(v: one::Vector3) -> Self {
        Self { x: v.x, y: v.y, z: v.z }
    }
}

impl From<Twist> for one::Twist {
    fn from(t: Twist) -> Self {
        Self { linear: t.linear.into(), angular: t.angular.into() }
    }
}

impl From<one::Twist> for Twist {
    fn from(t: one::Twist) -> Self {
        Self { linear: t.linear.into(), angular: t.angular.into() }
    }
}

impl From<Odometry> for one::Odometry {
    fn from(m: Odometry) -> Self {
        let (p, q) = (m.pose.pose.position, m.pose.pose.orientation);
        Self {
            header: m.header.into(),
            child_frame_id: m.child_frame_id,
            position: p.into(),
            orientation: one::Quaternion { x: q.x, y: q.y, z: q.z, w: q.w },
            pose_covariance: m.pose.covariance,
            twist: m.twist.twist.into(),
            twist_covariance: m.twist.covariance,
        }
    }
}

impl From<one::Odometry> for Odometry {
    fn from(m: one::Odometry) -> Self {
        let q = m.orientation;
        Self {
            header: m.header.into(),
            child_frame_id: m.child_frame_id,
            pose: PoseWithCovariance {
                pose: Pose {
                    position: m.position.into(),
                    orientation: Quaternion { x: q.x, y: q.y, z: q.z, w: q.w },
                },
                covariance: m.pose_covariance,
            },
            twist: TwistWithCovariance { twist: m.twist.into(), covariance: m.twist_covariance },
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use byteorder::LittleEndian as Le;
    use cdr_encoding::{from_bytes, to_vec};

    /// Bytes as Eclipse Cyclone DDS's Python binding (cyclonedds 11.0.1) serialises the same
    /// values, XCDR1 payload after the 4-byte encapsulation header: recorded once from
    /// `LaserScan(header=Header(stamp=Time(sec=1, nanosec=2), frame_id="laser"),
    /// angle_min=-1.0, angle_max=1.0, range_max=5.0, ranges=[1.0, 2.0], intensities=[])`.
    #[test]
    fn laser_scan_bytes_are_ros2s() {
        let scan = LaserScan {
            header: Header { stamp: Time { sec: 1, nanosec: 2 }, frame_id: "laser".into() },
            angle_min: -1.0,
            angle_max: 1.0,
            range_max: 5.0,
            ranges: vec![1.0, 2.0],
            ..LaserScan::default()
        };
        let bytes = to_vec::<_, Le>(&scan).unwrap();
        let mut expect = Vec::new();
        expect.extend(1i32.to_le_bytes());
        expect.extend(2u32.to_le_bytes());
        expect.extend(6u32.to_le_bytes()); // "laser" + NUL
        expect.extend(b"laser\0");
        expect.extend([0, 0]); // pad to 4
        for f in [-1.0f32, 1.0, 0.0, 0.0, 0.0, 0.0, 5.0] {
            expect.extend(f.to_le_bytes());
        }
        expect.extend(2u32.to_le_bytes());
        expect.extend(1.0f32.to_le_bytes());
        expect.extend(2.0f32.to_le_bytes());
        expect.extend(0u32.to_le_bytes());
        assert_eq!(bytes, expect);
        let (back, _) = from_bytes::<LaserScan, Le>(&bytes).unwrap();
        assert_eq!(back, scan);
    }

    /// Odometry's covariances are 8-aligned after the header's string: the padding a
    /// hand-rolled layout gets wrong.
    #[test]
    fn odometry_pads_before_the_doubles() {
        let mut odom = Odometry::default();
        odom.header.frame_id = "odom".into(); // 4 + 4 + 4 + 5 = 17 bytes
        odom.child_frame_id = "base".into(); // + pad 3 + 4 + 5 = 29
        odom.pose.pose.position.x = 1.5;
        odom.twist.covariance[35] = 9.0;
        let bytes = to_vec::<_, Le>(&odom).unwrap();
        // position.x starts at 32, the next multiple of 8 after 29.
        assert_eq!(bytes[32..40], 1.5f64.to_le_bytes());
        // header 29 + pad 3 + pose 7 doubles + 36 + twist 6 + 36 doubles.
        assert_eq!(bytes.len(), 32 + 8 * (7 + 36 + 6 + 36));
        assert_eq!(bytes[bytes.len() - 8..], 9.0f64.to_le_bytes());
        let (back, _) = from_bytes::<Odometry, Le>(&bytes).unwrap();
        assert_eq!(back, odom);
        // Through the shared shape and back.
        assert_eq!(Odometry::from(one::Odometry::from(odom.clone())), odom);
    }

    #[test]
    fn truncated_bytes_are_an_error_not_garbage() {
        let bytes = to_vec::<_, Le>(&Image { data: vec![7; 100], ..Image::default() }).unwrap();
        assert!(from_bytes::<Image, Le>(&bytes[..bytes.len() - 1]).is_err());
    }

    #[test]
    fn type_names() {
        assert_eq!(LaserScan::TYPE, ("sensor_msgs", "LaserScan"));
        assert_eq!(TwistStamped::TYPE, ("geometry_msgs", "TwistStamped"));
        assert_eq!(Odometry::TYPE, ("nav_msgs", "Odometry"));
    }
}
