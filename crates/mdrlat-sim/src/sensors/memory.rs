//! The scan a network reads with the camera's hidden obstacles remembered
//! (`sim.laser.depth_memory_frames`; 0, the default, is the paper's plain laser scan).
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

use super::DepthGeometry;
use crate::config::SimConfig;
use mdrlat_geom::{Pose2, Vec2};

/// The camera's obstacle counts as shown by the laser if the laser's beam in its direction
/// reads at most this much farther, metres.
pub const LASER_SEEN_SLACK_M: f32 = 0.1;
/// Each remembered point is drawn as a disc of this radius (so a near point covers the
/// beams its surface would, not one beam of 0.53°), metres.
const POINT_RADIUS_M: f32 = 0.025;
/// The most frames a memory may hold (64 frames: 12.8 s at the paper's 5 Hz).
pub const MAX_MEMORY_FRAMES: u32 = 64;

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
    /// Points of the last frames in the odometry frame, oldest first; at most `frames`.
    frames: std::collections::VecDeque<Vec<Vec2>>,
    capacity: usize,
    /// Per-column scratch: the nearest obstacle the body can hit.
    nearest: Vec<f32>,
}

impl ScanMemory {
    /// The memory `sim` asks for: `None` when `sim.laser.depth_memory_frames` is 0 (a
    /// validated `sim` asks for at most [`MAX_MEMORY_FRAMES`]; more are not kept).
    pub fn new(sim: &SimConfig, beam_angles: &[f32], geometry: DepthGeometry) -> Option<Self> {
        let capacity = sim.laser.depth_memory_frames.min(MAX_MEMORY_FRAMES) as usize;
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
            max_range_m: sim.laser.max_range_m,
            body_height_m: sim.robot.body_height_m,
            frames: std::collections::VecDeque::with_capacity(capacity),
            capacity,
            nearest: vec![f32::INFINITY; cols],
        })
    }

    /// Forgets everything (a new episode).
    pub fn clear(&mut self) {
        self.frames.clear();
    }

    /// The remembered frames, oldest first (for an environment's saved state).
    pub fn frames(&self) -> impl Iterator<Item = &[Vec2]> {
        self.frames.iter().map(Vec::as_slice)
    }

    /// Replaces the memory with saved frames (oldest first; only the newest fit).
    pub fn restore(&mut self, frames: &[Vec<Vec2>]) {
        self.frames.clear();
        let skip = frames.len().saturating_sub(self.capacity);
        self.frames.extend(frames[skip..].iter().cloned());
    }

    /// Remembers the obstacles of `depth_m` (one image, metres) that the laser's `scan`
    /// (its ranges, metres) does not show, both taken from `pose` (odometry frame),
    /// forgetting the oldest frame when full; then draws every remembered point into
    /// `scan`: each beam reads the nearer of its own range and the points on it.
    pub fn update(&mut self, pose: Pose2, depth_m: &[f32], scan: &mut [f32]) {
        let g = &self.geometry;
        g.obstacle_ranges(depth_m, 0.03, self.body_height_m, &mut self.nearest);
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
                points.push(pose.to_world(Vec2::new(r * a.cos(), r * a.sin())));
            }
        }
        self.frames.push_back(points);
        self.draw(pose, scan);
    }

    /// Draws the remembered points, seen from `pose`, into `scan`.
    fn draw(&self, pose: Pose2, scan: &mut [f32]) {
        let n = self.beams.min(scan.len());
        for &p in self.frames.iter().flatten() {
            let local = pose.to_local(p);
            let r = local.length();
            if !(r > 1e-3 && r < self.max_range_m) {
                continue;
            }
            let a = local.y.atan2(local.x);
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
