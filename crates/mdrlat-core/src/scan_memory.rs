//! The scan a network reads with the camera's hidden obstacles remembered (the simulator's
//! `sim.laser.depth_memory_frames`; 0, the default, is the paper's plain laser scan). Here,
//! beside the one normalisation, because the simulator and the robot both draw it: one
//! implementation, so a policy reads the same scan in both.
//!
//! A 2D laser passes over low boxes and under table tops; the depth camera sees them, but
//! only in its 58° and from 0.4 m on, so a box beside the robot's path has left the picture
//! long before the bumper meets it (docs/evaluation.md, *How much memory `furnished` asks
//! for*: a classical avoider with the four frames a network sees gets 82.4 % there, with
//! eight 95.2 %). [`ScanMemory`] keeps, for the last `depth_memory_frames` frames, the
//! camera's obstacle points that the laser does not see, carried in the odometry frame,
//! and draws them into the laser scan (the nearer of the two per beam). The network's
//! input layout and cost do not change; what its laser channel shows does.
//!
//! Which points: per image column, the nearest obstacle at a height the body can hit
//! (3 cm up to the body's height, floor excluded: [`DepthGeometry::obstacle_ranges`]).
//! If the laser's own beam in that direction reads no farther (within
//! [`LASER_SEEN_SLACK_M`]), the laser shows it in real time and nothing is remembered:
//! walls and walkers leave no trails. Otherwise it is hidden from the laser (a
//! low box, a table top, a shelf's overhang) and remembered. The points live in the
//! odometry frame (on a robot, `/odom`'s pose: over a few seconds its drift is far below a
//! beam's width); in the simulator the robot's pose stands in for it.

use crate::obs::{
    DEPTH_COLS, DEPTH_HEIGHT_M, DEPTH_HFOV_DEG, DEPTH_ROWS, DEPTH_VFOV_DEG, LASER_BEAMS,
    LASER_MAX_RANGE_M, laser_beam_angle,
};
use std::collections::VecDeque;

/// The camera's obstacle counts as shown by the laser if the laser's beam in its direction
/// reads at most this much farther, metres.
pub const LASER_SEEN_SLACK_M: f32 = 0.1;
/// Each remembered point is drawn as a disc of this radius (so a near point covers the
/// beams its surface would, not one beam of 0.53°), metres.
const POINT_RADIUS_M: f32 = 0.025;
/// The most frames a memory may hold (64 frames: 12.8 s at the paper's 5 Hz).
pub const MAX_MEMORY_FRAMES: u32 = 64;
/// Obstacles from this height up count (lower is the floor), metres.
const OBSTACLE_MIN_HEIGHT_M: f32 = 0.03;

/// The projection of a depth camera: enough to turn a depth image back into points.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthGeometry {
    /// Ground-plane angle of each column's ray in the robot frame, column 0 (left) first.
    pub column_angles: Vec<f32>,
    /// Ground distance per metre of z-depth, per column (`sqrt(1 + x_c²)`).
    pub column_k: Vec<f32>,
    /// Normalised image y (down positive) of each row's centre.
    pub row_y: Vec<f32>,
    /// Height of the optical centre, metres.
    pub height_m: f32,
}

impl DepthGeometry {
    /// A zero-pitch pinhole of [`DEPTH_ROWS`] x [`DEPTH_COLS`] pixels with these fields of
    /// view, at `height_m`: pixel `(r, c)` has its centre at `(c + 0.5, r + 0.5)`, row 0 the
    /// top, column 0 the robot's left (the simulator's camera, which builds its own from
    /// this).
    pub fn pinhole(hfov_deg: f32, vfov_deg: f32, height_m: f32) -> Self {
        let fx = (DEPTH_COLS as f32 / 2.0) / (hfov_deg.to_radians() / 2.0).tan();
        let fy = (DEPTH_ROWS as f32 / 2.0) / (vfov_deg.to_radians() / 2.0).tan();
        let xs = (0..DEPTH_COLS).map(|c| (c as f32 + 0.5 - DEPTH_COLS as f32 / 2.0) / fx);
        // The simulator's camera casts with 1 / k per column and 1 / y per row; these are
        // their inverses, computed that way so the two never differ by a rounding.
        let (column_angles, column_k) =
            xs.map(|x| ((-x).atan(), 1.0 / (1.0 / (1.0 + x * x).sqrt()))).unzip();
        let row_y = (0..DEPTH_ROWS)
            .map(|r| 1.0 / (1.0 / ((r as f32 + 0.5 - DEPTH_ROWS as f32 / 2.0) / fy)))
            .collect();
        Self { column_angles, column_k, row_y, height_m }
    }

    /// A virtual laser scan from a depth image (as ROS's depthimage_to_laserscan, but
    /// height-aware): per column, the ground distance of the nearest pixel whose height lies
    /// in `[z_lo, z_hi]` metres — obstacles the body can hit, floor excluded. Columns with no
    /// such pixel read `f32::INFINITY`.
    pub fn obstacle_ranges(&self, depth_m: &[f32], z_lo: f32, z_hi: f32, out: &mut [f32]) {
        let cols = self.column_angles.len();
        out.fill(f32::INFINITY);
        for (r, row) in depth_m.chunks_exact(cols).enumerate() {
            let y = self.row_y[r];
            for (c, &z) in row.iter().enumerate() {
                let h = self.height_m - y * z;
                if z > 0.0 && h >= z_lo && h <= z_hi {
                    out[c] = out[c].min(z * self.column_k[c]);
                }
            }
        }
    }
}

/// `p` (robot frame) in the odometry frame of a robot at `pose` (`[x, y, yaw]`).
fn to_odom(pose: [f32; 3], p: [f32; 2]) -> [f32; 2] {
    let (s, c) = pose[2].sin_cos();
    [c * p[0] - s * p[1] + pose[0], s * p[0] + c * p[1] + pose[1]]
}

/// `p` (odometry frame) in the frame of a robot at `pose`.
fn to_robot(pose: [f32; 3], p: [f32; 2]) -> [f32; 2] {
    let (s, c) = pose[2].sin_cos();
    let (dx, dy) = (p[0] - pose[0], p[1] - pose[1]);
    [c * dx + s * dy, -s * dx + c * dy]
}

/// The remembered hidden obstacles of one robot (see the module docs).
#[derive(Debug, Clone)]
pub struct ScanMemory {
    geometry: DepthGeometry,
    /// Beam 0's angle and the step between beams, radians.
    a0: f32,
    da: f32,
    beams: usize,
    max_range_m: f32,
    body_height_m: f32,
    /// Points of the last frames in the odometry frame, oldest first; at most `capacity`.
    frames: VecDeque<Vec<[f32; 2]>>,
    capacity: usize,
    /// Per-column scratch: the nearest obstacle the body can hit.
    nearest: Vec<f32>,
}

impl ScanMemory {
    /// A memory of `frames` frames (`None` for 0; more than [`MAX_MEMORY_FRAMES`] are not
    /// kept) for a laser with these beam angles and maximum range, a camera of `geometry`
    /// and a body of `body_height_m`.
    pub fn new(
        frames: u32,
        beam_angles: &[f32],
        geometry: DepthGeometry,
        max_range_m: f32,
        body_height_m: f32,
    ) -> Option<Self> {
        let capacity = frames.min(MAX_MEMORY_FRAMES) as usize;
        if capacity == 0 || beam_angles.len() < 2 {
            return None;
        }
        let cols = geometry.column_angles.len();
        let beams = beam_angles.len();
        Some(Self {
            geometry,
            a0: beam_angles[0],
            da: (beam_angles[beams - 1] - beam_angles[0]) / (beams - 1) as f32,
            beams,
            max_range_m,
            body_height_m,
            frames: VecDeque::with_capacity(capacity),
            capacity,
            nearest: vec![f32::INFINITY; cols],
        })
    }

    /// The memory of the robot of SPEC §2 (the simulator's default sensors and body), as a
    /// real robot's node draws it: `frames` frames.
    pub fn spec(frames: u32) -> Option<Self> {
        let beams: Vec<f32> = (0..LASER_BEAMS).map(laser_beam_angle).collect();
        let camera = DepthGeometry::pinhole(DEPTH_HFOV_DEG, DEPTH_VFOV_DEG, DEPTH_HEIGHT_M);
        Self::new(frames, &beams, camera, LASER_MAX_RANGE_M, crate::robot::BODY_HEIGHT_M)
    }

    /// Forgets everything (a new episode).
    pub fn clear(&mut self) {
        self.frames.clear();
    }

    /// The remembered frames, oldest first (for an environment's saved state).
    pub fn frames(&self) -> impl Iterator<Item = &[[f32; 2]]> {
        self.frames.iter().map(Vec::as_slice)
    }

    /// Replaces the memory with saved frames (oldest first; only the newest fit).
    pub fn restore(&mut self, frames: impl IntoIterator<Item = Vec<[f32; 2]>>) {
        self.frames.clear();
        for frame in frames {
            if self.frames.len() == self.capacity {
                self.frames.pop_front();
            }
            self.frames.push_back(frame);
        }
    }

    /// Remembers the obstacles of `depth_m` (one image, metres) that the laser's `scan`
    /// (its ranges, metres) does not show, both taken from `pose` (`[x, y, yaw]` in the
    /// odometry frame), forgetting the oldest frame when full; then draws every remembered
    /// point into `scan`: each beam reads the nearer of its own range and the points on it.
    pub fn update(&mut self, pose: [f32; 3], depth_m: &[f32], scan: &mut [f32]) {
        let g = &self.geometry;
        g.obstacle_ranges(depth_m, OBSTACLE_MIN_HEIGHT_M, self.body_height_m, &mut self.nearest);
        let n = self.beams.min(scan.len());
        let mut points = if self.frames.len() == self.capacity {
            self.frames.pop_front().unwrap_or_default()
        } else {
            Vec::new()
        };
        points.clear();
        for (&r, &a) in self.nearest.iter().zip(&g.column_angles) {
            if !(r.is_finite() && r < self.max_range_m) {
                continue;
            }
            let beam = ((a - self.a0) / self.da).round();
            let shown =
                (0.0..n as f32).contains(&beam) && scan[beam as usize] <= r + LASER_SEEN_SLACK_M;
            if !shown {
                points.push(to_odom(pose, [r * a.cos(), r * a.sin()]));
            }
        }
        self.frames.push_back(points);
        self.draw(pose, scan);
    }

    /// Draws the remembered points, seen from `pose`, into `scan`.
    fn draw(&self, pose: [f32; 3], scan: &mut [f32]) {
        let n = self.beams.min(scan.len());
        for &p in self.frames.iter().flatten() {
            let [x, y] = to_robot(pose, p);
            let r = x.hypot(y);
            if !(r > 1e-3 && r < self.max_range_m) {
                continue;
            }
            let a = y.atan2(x);
            let half = (POINT_RADIUS_M / r).min(1.0).asin();
            let first = ((a - half - self.a0) / self.da).ceil().max(0.0);
            let last = ((a + half - self.a0) / self.da).floor().min(n as f32 - 1.0);
            if first > last {
                continue;
            }
            for beam in &mut scan[first as usize..=last as usize] {
                *beam = beam.min(r);
            }
        }
    }
}
