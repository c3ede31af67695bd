//! The ROS 1 messages the node speaks, their wire format and their MD5 sums.
//!
//! The `.msg` definitions are embedded from `msg/` (copied from ROS `common_msgs`), and the
//! MD5 sum every ROS 1 peer checks is computed from them by genmsg's rule, so no ROS
//! installation is needed to build or run. Serialisation is ROS 1's: little-endian, strings
//! and variable arrays prefixed by a `u32` length, fixed arrays without one.

use thiserror::Error;

/// A message definition embedded from `msg/`.
struct Definition {
    name: &'static str,
    text: &'static str,
}

macro_rules! definitions {
    ($($pkg:literal / $ty:literal),* $(,)?) => {
        &[$(Definition {
            name: concat!($pkg, "/", $ty),
            text: include_str!(concat!("../msg/", $pkg, "/", $ty, ".msg")),
        }),*]
    };
}

const DEFINITIONS: &[Definition] = definitions![
    "std_msgs" / "Header",
    "geometry_msgs" / "Point",
    "geometry_msgs" / "Quaternion",
    "geometry_msgs" / "Pose",
    "geometry_msgs" / "PoseWithCovariance",
    "geometry_msgs" / "Vector3",
    "geometry_msgs" / "Twist",
    "geometry_msgs" / "TwistWithCovariance",
    "sensor_msgs" / "LaserScan",
    "sensor_msgs" / "Image",
    "nav_msgs" / "Odometry",
];

const BUILTINS: &[&str] = &[
    "bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
    "uint64", "float32", "float64", "string", "time", "duration",
];

/// One line of a `.msg` file.
enum Line<'a> {
    Constant(&'a str),
    Field { ty: &'a str, name: &'a str },
}

fn lines(text: &str) -> impl Iterator<Item = Line<'_>> {
    text.lines().filter_map(|raw| {
        let line = raw.split('#').next().unwrap_or("").trim();
        let (ty, rest) = line.split_once(char::is_whitespace)?;
        let rest = rest.trim();
        if rest.contains('=') {
            // genmsg writes constants as `type name=value` with the spacing normalised.
            Some(Line::Constant(line))
        } else {
            Some(Line::Field { ty, name: rest })
        }
    })
}

/// The full name of a field's message type (`None` for builtins), without array suffix.
fn message_type(package: &str, ty: &str) -> Option<String> {
    let base = ty.split('[').next().unwrap_or(ty);
    if BUILTINS.contains(&base) {
        None
    } else if base == "Header" {
        Some("std_msgs/Header".into())
    } else if base.contains('/') {
        Some(base.into())
    } else {
        Some(format!("{package}/{base}"))
    }
}

fn definition(name: &str) -> &'static Definition {
    DEFINITIONS
        .iter()
        .find(|d| d.name == name)
        .unwrap_or_else(|| panic!("message {name} is not embedded (a bug in msg.rs)"))
}

/// The MD5 sum ROS 1 peers check for message type `name` (e.g. `sensor_msgs/LaserScan`),
/// computed from the embedded definition by genmsg's rule: constants, then fields, where a
/// field of message type is written as that type's MD5 sum.
///
/// # Panics
/// `name` is not one of the embedded types (a programming error, not an input error).
pub fn md5sum(name: &str) -> String {
    let def = definition(name);
    let package = name.split('/').next().unwrap_or("");
    let mut constants = Vec::new();
    let mut fields = Vec::new();
    for line in lines(def.text) {
        match line {
            Line::Constant(c) => {
                let (ty, rest) = c.split_once(char::is_whitespace).unwrap_or((c, ""));
                let (n, v) = rest.split_once('=').unwrap_or((rest, ""));
                constants.push(format!("{ty} {}={}", n.trim(), v.trim()));
            }
            Line::Field { ty, name: field } => match message_type(package, ty) {
                Some(sub) => fields.push(format!("{} {field}", md5sum(&sub))),
                None => fields.push(format!("{ty} {field}")),
            },
        }
    }
    constants.extend(fields);
    format!("{:x}", md5::compute(constants.join("\n")))
}

/// The concatenated definition sent in connection headers (`message_definition`): the
/// type's own text, then each message type it uses, as `gendeps --cat` writes it.
pub fn full_definition(name: &str) -> String {
    fn deps(name: &str, out: &mut Vec<String>) {
        let package = name.split('/').next().unwrap_or("");
        for line in lines(definition(name).text) {
            if let Line::Field { ty, .. } = line
                && let Some(sub) = message_type(package, ty)
            {
                if !out.contains(&sub) {
                    out.push(sub.clone());
                }
                deps(&sub, out);
            }
        }
    }
    let mut used = Vec::new();
    deps(name, &mut used);
    let mut text = definition(name).text.trim_end().to_string();
    for sub in used {
        text.push_str("\n================================================================================\nMSG: ");
        text.push_str(&sub);
        text.push('\n');
        text.push_str(definition(&sub).text.trim_end());
    }
    text.push('\n');
    text
}

/// A message that cannot be decoded.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[non_exhaustive]
pub enum WireError {
    /// The bytes end before the message does.
    #[error("truncated: {needed} bytes needed at offset {offset}, {available} left")]
    Truncated {
        /// Bytes the next field needs.
        needed: usize,
        /// Where it starts.
        offset: usize,
        /// Bytes left.
        available: usize,
    },
    /// Bytes are left after the last field.
    #[error("{0} bytes left after the last field")]
    Trailing(usize),
    /// A string is not UTF-8.
    #[error("string at offset {0} is not UTF-8")]
    Utf8(usize),
}

/// Reads ROS 1 serialised fields in order.
#[derive(Debug)]
pub struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    /// A reader at the start of `data`.
    pub fn new(data: &'a [u8]) -> Self {
        Self { data, pos: 0 }
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], WireError> {
        let available = self.data.len() - self.pos;
        if n > available {
            return Err(WireError::Truncated { needed: n, offset: self.pos, available });
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], WireError> {
        let mut a = [0; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }

    /// A `uint8`.
    pub fn u8(&mut self) -> Result<u8, WireError> {
        Ok(self.take(1)?[0])
    }
    /// A `uint32`.
    pub fn u32(&mut self) -> Result<u32, WireError> {
        self.array().map(u32::from_le_bytes)
    }
    /// A `float32`.
    pub fn f32(&mut self) -> Result<f32, WireError> {
        self.array().map(f32::from_le_bytes)
    }
    /// A `float64`.
    pub fn f64(&mut self) -> Result<f64, WireError> {
        self.array().map(f64::from_le_bytes)
    }
    /// A length prefix, checked against the bytes left (`elem` bytes per element) before
    /// anything is allocated.
    fn len(&mut self, elem: usize) -> Result<usize, WireError> {
        let n = self.u32()? as usize;
        let available = self.data.len() - self.pos;
        match n.checked_mul(elem) {
            Some(bytes) if bytes <= available => Ok(n),
            _ => Err(WireError::Truncated {
                needed: n.saturating_mul(elem),
                offset: self.pos,
                available,
            }),
        }
    }
    /// A `string`.
    pub fn string(&mut self) -> Result<String, WireError> {
        let n = self.len(1)?;
        let at = self.pos;
        String::from_utf8(self.take(n)?.to_vec()).map_err(|_| WireError::Utf8(at))
    }
    /// A `uint8[]`.
    pub fn bytes(&mut self) -> Result<Vec<u8>, WireError> {
        let n = self.len(1)?;
        Ok(self.take(n)?.to_vec())
    }
    /// A `float32[]`.
    pub fn f32s(&mut self) -> Result<Vec<f32>, WireError> {
        let n = self.len(4)?;
        Ok(self
            .take(4 * n)?
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect())
    }
    /// Ends reading: every byte must have been used.
    pub fn finish(self) -> Result<(), WireError> {
        match self.data.len() - self.pos {
            0 => Ok(()),
            n => Err(WireError::Trailing(n)),
        }
    }
}

fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}
fn put_len(out: &mut Vec<u8>, n: usize) {
    put_u32(out, u32::try_from(n).unwrap_or(u32::MAX));
}
fn put_string(out: &mut Vec<u8>, s: &str) {
    put_len(out, s.len());
    out.extend_from_slice(s.as_bytes());
}
fn put_f64s(out: &mut Vec<u8>, v: &[f64]) {
    for x in v {
        out.extend_from_slice(&x.to_le_bytes());
    }
}

/// A ROS 1 message type this crate can send and receive.
pub trait Message: Sized + Send + 'static {
    /// Full type name, e.g. `sensor_msgs/LaserScan`.
    const TYPE: &'static str;
    /// Appends the serialised message (without the length prefix).
    fn encode(&self, out: &mut Vec<u8>);
    /// Reads one message.
    ///
    /// # Errors
    /// The fields do not fit the bytes.
    fn decode(r: &mut Reader<'_>) -> Result<Self, WireError>;

    /// Decodes a whole message body, which must be used completely.
    ///
    /// # Errors
    /// See [`WireError`].
    fn from_bytes(data: &[u8]) -> Result<Self, WireError> {
        let mut r = Reader::new(data);
        let m = Self::decode(&mut r)?;
        r.finish()?;
        Ok(m)
    }

    /// The serialised message (without the length prefix).
    fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::new();
        self.encode(&mut out);
        out
    }
}

/// ROS `time`: seconds and nanoseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Time {
    /// Seconds.
    pub sec: u32,
    /// Nanoseconds.
    pub nsec: u32,
}

impl Time {
    /// The wall clock now (ROS time without `/clock`).
    pub fn now() -> Self {
        let d =
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        Self { sec: d.as_secs() as u32, nsec: d.subsec_nanos() }
    }
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Header {
    /// Sequence number.
    pub seq: u32,
    /// Acquisition time.
    pub stamp: Time,
    /// Coordinate frame.
    pub frame_id: String,
}

impl Message for Header {
    const TYPE: &'static str = "std_msgs/Header";
    fn encode(&self, out: &mut Vec<u8>) {
        put_u32(out, self.seq);
        put_u32(out, self.stamp.sec);
        put_u32(out, self.stamp.nsec);
        put_string(out, &self.frame_id);
    }
    fn decode(r: &mut Reader<'_>) -> Result<Self, WireError> {
        Ok(Self {
            seq: r.u32()?,
            stamp: Time { sec: r.u32()?, nsec: r.u32()? },
            frame_id: r.string()?,
        })
    }
}

/// `sensor_msgs/LaserScan`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LaserScan {
    /// Header.
    pub header: Header,
    /// Angle of the first beam, rad (counter-clockwise, 0 ahead).
    pub angle_min: f32,
    /// Angle of the last beam, rad.
    pub angle_max: f32,
    /// Angle between beams, rad.
    pub angle_increment: f32,
    /// Time between beams, s.
    pub time_increment: f32,
    /// Time between scans, s.
    pub scan_time: f32,
    /// Minimum valid range, m.
    pub range_min: f32,
    /// Maximum valid range, m.
    pub range_max: f32,
    /// Ranges, m.
    pub ranges: Vec<f32>,
    /// Intensities (may be empty).
    pub intensities: Vec<f32>,
}

impl Message for LaserScan {
    const TYPE: &'static str = "sensor_msgs/LaserScan";
    fn encode(&self, out: &mut Vec<u8>) {
        self.header.encode(out);
        for v in [
            self.angle_min,
            self.angle_max,
            self.angle_increment,
            self.time_increment,
            self.scan_time,
            self.range_min,
            self.range_max,
        ] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for a in [&self.ranges, &self.intensities] {
            put_len(out, a.len());
            for v in a {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    fn decode(r: &mut Reader<'_>) -> Result<Self, WireError> {
        Ok(Self {
            header: Header::decode(r)?,
            angle_min: r.f32()?,
            angle_max: r.f32()?,
            angle_increment: r.f32()?,
            time_increment: r.f32()?,
            scan_time: r.f32()?,
            range_min: r.f32()?,
            range_max: r.f32()?,
            ranges: r.f32s()?,
            intensities: r.f32s()?,
        })
    }
}

/// `sensor_msgs/Image`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Image {
    /// Header.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding, e.g. `32FC1`, `16UC1`.
    pub encoding: String,
    /// 1 when multi-byte pixels are big-endian.
    pub is_bigendian: u8,
    /// Bytes per row.
    pub step: u32,
    /// Pixels, `height · step` bytes.
    pub data: Vec<u8>,
}

impl Message for Image {
    const TYPE: &'static str = "sensor_msgs/Image";
    fn encode(&self, out: &mut Vec<u8>) {
        self.header.encode(out);
        put_u32(out, self.height);
        put_u32(out, self.width);
        put_string(out, &self.encoding);
        out.push(self.is_bigendian);
        put_u32(out, self.step);
        put_len(out, self.data.len());
        out.extend_from_slice(&self.data);
    }
    fn decode(r: &mut Reader<'_>) -> Result<Self, WireError> {
        Ok(Self {
            header: Header::decode(r)?,
            height: r.u32()?,
            width: r.u32()?,
            encoding: r.string()?,
            is_bigendian: r.u8()?,
            step: r.u32()?,
            data: r.bytes()?,
        })
    }
}

/// `geometry_msgs/Vector3` (also used for `Point`, which has the same layout).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

impl Vector3 {
    fn encode(&self, out: &mut Vec<u8>) {
        put_f64s(out, &[self.x, self.y, self.z]);
    }
    fn decode(r: &mut Reader<'_>) -> Result<Self, WireError> {
        Ok(Self { x: r.f64()?, y: r.f64()?, z: r.f64()? })
    }
}

/// `geometry_msgs/Twist`: the velocity command.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Twist {
    /// Linear velocity, m/s (x ahead).
    pub linear: Vector3,
    /// Angular velocity, rad/s (z counter-clockwise).
    pub angular: Vector3,
}

impl Twist {
    /// A planar command: `v` ahead, `w` about z.
    pub fn planar(v: f64, w: f64) -> Self {
        Self {
            linear: Vector3 { x: v, ..Vector3::default() },
            angular: Vector3 { z: w, ..Vector3::default() },
        }
    }
}

impl Message for Twist {
    const TYPE: &'static str = "geometry_msgs/Twist";
    fn encode(&self, out: &mut Vec<u8>) {
        self.linear.encode(out);
        self.angular.encode(out);
    }
    fn decode(r: &mut Reader<'_>) -> Result<Self, WireError> {
        Ok(Self { linear: Vector3::decode(r)?, angular: Vector3::decode(r)? })
    }
}

/// `geometry_msgs/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq)]
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

impl Quaternion {
    /// A rotation by `yaw` about z.
    pub fn from_yaw(yaw: f64) -> Self {
        Self { x: 0.0, y: 0.0, z: (yaw / 2.0).sin(), w: (yaw / 2.0).cos() }
    }
    /// The rotation's yaw about z.
    pub fn yaw(&self) -> f64 {
        (2.0 * (self.w * self.z + self.x * self.y))
            .atan2(1.0 - 2.0 * (self.y * self.y + self.z * self.z))
    }
}

/// `nav_msgs/Odometry` (pose and twist with covariances).
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    /// Header (the odometry frame).
    pub header: Header,
    /// The moving frame.
    pub child_frame_id: String,
    /// Position.
    pub position: Vector3,
    /// Orientation.
    pub orientation: Quaternion,
    /// Row-major 6x6 pose covariance.
    pub pose_covariance: [f64; 36],
    /// Velocity in the child frame.
    pub twist: Twist,
    /// Row-major 6x6 twist covariance.
    pub twist_covariance: [f64; 36],
}

impl Default for Odometry {
    fn default() -> Self {
        Self {
            header: Header::default(),
            child_frame_id: String::new(),
            position: Vector3::default(),
            orientation: Quaternion::default(),
            pose_covariance: [0.0; 36],
            twist: Twist::default(),
            twist_covariance: [0.0; 36],
        }
    }
}

fn covariance(r: &mut Reader<'_>) -> Result<[f64; 36], WireError> {
    let mut c = [0.0; 36];
    for v in &mut c {
        *v = r.f64()?;
    }
    Ok(c)
}

impl Message for Odometry {
    const TYPE: &'static str = "nav_msgs/Odometry";
    fn encode(&self, out: &mut Vec<u8>) {
        self.header.encode(out);
        put_string(out, &self.child_frame_id);
        self.position.encode(out);
        let q = self.orientation;
        put_f64s(out, &[q.x, q.y, q.z, q.w]);
        put_f64s(out, &self.pose_covariance);
        self.twist.encode(out);
        put_f64s(out, &self.twist_covariance);
    }
    fn decode(r: &mut Reader<'_>) -> Result<Self, WireError> {
        Ok(Self {
            header: Header::decode(r)?,
            child_frame_id: r.string()?,
            position: Vector3::decode(r)?,
            orientation: Quaternion { x: r.f64()?, y: r.f64()?, z: r.f64()?, w: r.f64()? },
            pose_covariance: covariance(r)?,
            twist: Twist::decode(r)?,
            twist_covariance: covariance(r)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sums rospy 1.15 / common_msgs 1.13 report (`Type._md5sum`).
    #[test]
    fn md5_sums_match_ros() {
        for (ty, sum) in [
            ("std_msgs/Header", "2176decaecbce78abc3b96ef049fabed"),
            ("geometry_msgs/Twist", "9f195f881246fdfa2798d1d3eebca84a"),
            ("sensor_msgs/LaserScan", "90c7ef2dc6895d81024acba2ac42f369"),
            ("sensor_msgs/Image", "060021388200f6f0f447d0fcd9c64743"),
            ("nav_msgs/Odometry", "cd5e73d190d741a2f92e81eda573aca7"),
        ] {
            assert_eq!(md5sum(ty), sum, "{ty}");
        }
    }

    #[test]
    fn full_definition_lists_dependencies_once() {
        let d = full_definition(Odometry::TYPE);
        assert!(d.starts_with("# This represents an estimate"));
        for sub in ["std_msgs/Header", "geometry_msgs/Pose", "geometry_msgs/Vector3"] {
            assert_eq!(d.matches(&format!("MSG: {sub}\n")).count(), 1, "{sub}");
        }
    }

    #[test]
    fn messages_round_trip() {
        let scan = LaserScan {
            header: Header { seq: 7, stamp: Time { sec: 1, nsec: 2 }, frame_id: "laser".into() },
            angle_min: -1.0,
            angle_max: 1.0,
            angle_increment: 0.5,
            range_max: 5.6,
            ranges: vec![1.0, 2.0, f32::INFINITY, 0.5, 3.0],
            ..LaserScan::default()
        };
        assert_eq!(LaserScan::from_bytes(&scan.to_bytes()), Ok(scan));
        let image = Image {
            height: 2,
            width: 3,
            encoding: "16UC1".into(),
            step: 6,
            data: (0..12).collect(),
            ..Image::default()
        };
        assert_eq!(Image::from_bytes(&image.to_bytes()), Ok(image));
        let mut odom = Odometry { child_frame_id: "base_footprint".into(), ..Odometry::default() };
        odom.orientation = Quaternion::from_yaw(0.3);
        odom.twist = Twist::planar(0.2, -0.5);
        odom.pose_covariance[35] = 0.1;
        assert_eq!(Odometry::from_bytes(&odom.to_bytes()), Ok(odom.clone()));
        assert!((odom.orientation.yaw() - 0.3).abs() < 1e-12);
        // Twist: 6 float64.
        assert_eq!(Twist::planar(0.5, 1.0).to_bytes().len(), 48);
    }

    #[test]
    fn bad_bytes_are_errors_not_panics() {
        let image = Image {
            height: 1,
            width: 1,
            encoding: "32FC1".into(),
            step: 4,
            data: vec![0; 4],
            ..Image::default()
        };
        let bytes = image.to_bytes();
        for cut in 0..bytes.len() {
            assert!(Image::from_bytes(&bytes[..cut]).is_err(), "cut at {cut}");
        }
        let mut long = bytes.clone();
        long.push(0);
        assert_eq!(Image::from_bytes(&long), Err(WireError::Trailing(1)));
        // A huge length prefix is refused before allocating.
        let mut huge = Header::default().to_bytes();
        huge.extend_from_slice(&[0; 8]);
        huge.extend_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(Image::from_bytes(&huge), Err(WireError::Truncated { .. })));
    }
}
