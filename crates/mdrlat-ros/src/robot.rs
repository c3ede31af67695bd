//! The messages a turtlebot2 with an RPLIDAR and a Kinect publishes, built from plain
//! readings: what a simulated robot on ROS 1 sends (`mdrlat ros-sim` feeds it the
//! simulator's bridge, `mdrlat_sim::bridge`).

use crate::msg::{Header, Image, LaserScan, Odometry, Quaternion, Time, Twist, Vector3};
use mdrlat_core::{DEPTH_COLS, DEPTH_ROWS, LASER_BEAMS, laser_beam_angle};

/// Depth encodings a robot can publish.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DepthEncoding {
    /// float32 metres, NaN-free, 0 = no reading (as the simulator).
    #[default]
    F32,
    /// uint16 millimetres, 0 = no reading (as the Kinect's openni driver).
    U16,
}

impl DepthEncoding {
    /// The ROS encoding name.
    pub fn name(self) -> &'static str {
        match self {
            DepthEncoding::F32 => "32FC1",
            DepthEncoding::U16 => "16UC1",
        }
    }
}

/// What the robot's sensors read at one moment.
#[derive(Debug, Clone, Copy)]
pub struct Readings<'a> {
    /// The laser scan: [`LASER_BEAMS`] ranges over the simulator's 270°, metres.
    pub ranges: &'a [f32],
    /// The laser's maximum range, metres.
    pub range_max_m: f32,
    /// The depth image, [`DEPTH_ROWS`] × [`DEPTH_COLS`] row-major metres (0 = no reading).
    pub depth: &'a [f32],
    /// The pose in the odometry frame: x, y (metres), yaw (radians).
    pub pose: [f32; 3],
    /// The measured forward speed and turn rate.
    pub velocity: [f32; 2],
    /// Seconds between scans.
    pub scan_time_s: f32,
    /// The headers' sequence number.
    pub seq: u32,
}

/// The scan, depth image and odometry messages of `r`, stamped now.
pub fn messages(r: &Readings<'_>, encoding: DepthEncoding) -> (LaserScan, Image, Odometry) {
    let stamp = Time::now();
    let header = |frame: &str| Header { seq: r.seq, stamp, frame_id: frame.to_string() };
    let scan = LaserScan {
        header: header("laser"),
        angle_min: laser_beam_angle(0),
        angle_max: laser_beam_angle(LASER_BEAMS - 1),
        angle_increment: laser_beam_angle(1) - laser_beam_angle(0),
        time_increment: 0.0,
        scan_time: r.scan_time_s,
        range_min: 0.0,
        range_max: r.range_max_m,
        ranges: r.ranges.to_vec(),
        intensities: Vec::new(),
    };
    let (data, step) = match encoding {
        DepthEncoding::F32 => (r.depth.iter().flat_map(|d| d.to_le_bytes()).collect(), 4),
        DepthEncoding::U16 => (
            r.depth
                .iter()
                .flat_map(|d| ((d * 1000.0).round().clamp(0.0, 65535.0) as u16).to_le_bytes())
                .collect(),
            2,
        ),
    };
    let image = Image {
        header: header("camera_depth_optical_frame"),
        height: DEPTH_ROWS as u32,
        width: DEPTH_COLS as u32,
        encoding: encoding.name().into(),
        is_bigendian: 0,
        step: (DEPTH_COLS * step) as u32,
        data,
    };
    let [x, y, yaw] = r.pose;
    let odom = Odometry {
        header: header("odom"),
        child_frame_id: "base_footprint".into(),
        position: Vector3 { x: f64::from(x), y: f64::from(y), z: 0.0 },
        orientation: Quaternion::from_yaw(f64::from(yaw)),
        twist: Twist::planar(f64::from(r.velocity[0]), f64::from(r.velocity[1])),
        ..Odometry::default()
    };
    (scan, image, odom)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn millimetre_depth_rounds_and_clamps() {
        let depth = vec![0.0, 1.2344, 70.0, 0.0005];
        let mut full = vec![0.0f32; DEPTH_ROWS * DEPTH_COLS];
        full[..4].copy_from_slice(&depth);
        let ranges = vec![1.0f32; LASER_BEAMS];
        let r = Readings {
            ranges: &ranges,
            range_max_m: 10.0,
            depth: &full,
            pose: [1.0, 2.0, 0.5],
            velocity: [0.3, -0.2],
            scan_time_s: 0.2,
            seq: 7,
        };
        let (scan, image, odom) = messages(&r, DepthEncoding::U16);
        let mm: Vec<u16> =
            image.data.chunks(2).take(4).map(|b| u16::from_le_bytes([b[0], b[1]])).collect();
        assert_eq!(mm, [0, 1234, 65535, 1]);
        assert_eq!((image.step, image.encoding.as_str()), (2 * DEPTH_COLS as u32, "16UC1"));
        assert_eq!((scan.header.seq, scan.ranges.len()), (7, LASER_BEAMS));
        assert_eq!((odom.position.x, odom.twist.linear.x), (1.0, f64::from(0.3f32)));
        let (_, f32_image, _) = messages(&r, DepthEncoding::F32);
        assert_eq!(f32_image.data.len(), 4 * DEPTH_ROWS * DEPTH_COLS);
    }
}
