//! Observation layout and the one normalisation shared by the simulator and the robot.
//!
//! Sensors produce frames in metres. The network sees them normalised as in the authors'
//! code (SPEC §2): laser / 5.6; depth clamped to [0, 10] m, then / 5. Both the training code
//! and the ROS node call [`normalize_laser`] and [`normalize_depth`], so sim-to-real never
//! depends on two copies agreeing. The navigation task adds the goal in the robot's frame
//! ([`goal_in_robot_frame`], [`normalize_goal`]), defined here for the same reason.

use crate::action::Velocity;

/// Number of laser beams per scan.
pub const LASER_BEAMS: usize = 512;
/// Depth image rows.
pub const DEPTH_ROWS: usize = 128;
/// Depth image columns.
pub const DEPTH_COLS: usize = 160;
/// Pixels per depth image.
pub const DEPTH_LEN: usize = DEPTH_ROWS * DEPTH_COLS;
/// Frames stacked in one observation (t−3 … t).
pub const FRAME_STACK: usize = 4;
/// Steps of odometry history (t−2, t−1, t) predicted by the auxiliary task.
pub const ODOM_HISTORY: usize = 3;

/// Laser ranges are divided by this (the laser's maximum range, metres).
pub const LASER_NORM_M: f32 = 5.6;
/// Depth is clamped to `[0, DEPTH_CLAMP_M]` metres before scaling.
pub const DEPTH_CLAMP_M: f32 = 10.0;
/// Depth is divided by this after clamping.
pub const DEPTH_NORM_M: f32 = 5.0;
/// The laser's field of view (SPEC §2): beam `i` of [`LASER_BEAMS`] points at
/// `−135° + i·270°/511`, counter-clockwise from ahead.
pub const LASER_FOV_DEG: f32 = 270.0;
/// The laser's maximum range (SPEC §2); farther or missing returns read this.
pub const LASER_MAX_RANGE_M: f32 = 5.6;
/// The depth camera's minimum range (SPEC §2, as the Kinect): closer reads 0.
pub const DEPTH_MIN_RANGE_M: f32 = 0.4;
/// The depth camera's horizontal field of view (SPEC §2).
pub const DEPTH_HFOV_DEG: f32 = 58.0;
/// The depth camera's vertical field of view (SPEC §2).
pub const DEPTH_VFOV_DEG: f32 = 45.0;
/// The depth camera's height above the floor, metres (SPEC §2; zero pitch).
pub const DEPTH_HEIGHT_M: f32 = 0.30;

/// Length of the goal input of the navigation task: distance, sin and cos of the bearing.
pub const GOAL_DIM: usize = 3;
/// The goal's distance is divided by this (metres) for the network.
pub const GOAL_NORM_M: f32 = 10.0;

/// The goal `(goal_x, goal_y)` seen from a robot at `(x, y)` heading `yaw` (radians, world
/// frame): `[distance m, sin(bearing), cos(bearing)]`, the bearing counter-clockwise from
/// the robot's heading. At the goal itself the bearing is taken as 0 (`[0, 0, 1]`).
pub fn goal_in_robot_frame(x: f32, y: f32, yaw: f32, goal_x: f32, goal_y: f32) -> [f32; GOAL_DIM] {
    let (dx, dy) = (goal_x - x, goal_y - y);
    let distance = dx.hypot(dy);
    if distance <= f32::EPSILON {
        return [0.0, 0.0, 1.0];
    }
    let (s, c) = yaw.sin_cos();
    // The goal's direction rotated into the robot frame, as a unit vector: (cos b, sin b).
    let (ahead, left) = ((c * dx + s * dy) / distance, (-s * dx + c * dy) / distance);
    [distance, left, ahead]
}

/// The goal input as the network reads it: distance / [`GOAL_NORM_M`], sin and cos as they
/// are. A non-finite distance (which a sane source never gives) reads as "far ahead".
pub fn normalize_goal(goal: &[f32; GOAL_DIM]) -> [f32; GOAL_DIM] {
    let [d, s, c] = *goal;
    if !(d.is_finite() && s.is_finite() && c.is_finite()) {
        return [1.0, 0.0, 1.0];
    }
    [d / GOAL_NORM_M, s, c]
}

/// The angle of laser beam `i` of [`LASER_BEAMS`], radians, counter-clockwise from ahead.
pub fn laser_beam_angle(i: usize) -> f32 {
    let fov = LASER_FOV_DEG.to_radians();
    -fov / 2.0 + fov * i as f32 / (LASER_BEAMS - 1) as f32
}

/// Normalises laser ranges in metres into `out` (SPEC §2: range / 5.6).
/// Non-finite ranges (which a sane source never gives) map to 1.0, "nothing seen".
///
/// # Panics
/// If the slices differ in length (a programming error, not an input error).
pub fn normalize_laser(ranges_m: &[f32], out: &mut [f32]) {
    assert_eq!(ranges_m.len(), out.len(), "normalize_laser: length mismatch");
    for (o, &r) in out.iter_mut().zip(ranges_m) {
        *o = if r.is_finite() { r / LASER_NORM_M } else { 1.0 };
    }
}

/// Normalises depth in metres into `out` (SPEC §2: clamp to [0, 10] m, then / 5).
/// NaN (no return) maps to 0, as the sensor's own "no reading" value.
///
/// # Panics
/// If the slices differ in length (a programming error, not an input error).
pub fn normalize_depth(depth_m: &[f32], out: &mut [f32]) {
    assert_eq!(depth_m.len(), out.len(), "normalize_depth: length mismatch");
    for (o, &d) in out.iter_mut().zip(depth_m) {
        // `clamp` propagates NaN; treat it as no return.
        let d = if d.is_nan() { 0.0 } else { d.clamp(0.0, DEPTH_CLAMP_M) };
        *o = d / DEPTH_NORM_M;
    }
}

/// A ring buffer of the last [`FRAME_STACK`] frames of one sensor.
///
/// Pushing a frame writes one frame in place; nothing is shifted or reallocated. Frames are
/// read oldest to newest with [`FrameStack::frame`]. Two stacks are equal when their frames
/// are, wherever the ring's head happens to be.
#[derive(Debug, Clone)]
pub struct FrameStack {
    data: Box<[f32]>,
    frame_len: usize,
    /// Index of the slot holding the newest frame.
    head: usize,
}

impl FrameStack {
    /// A stack of zero frames of `frame_len` values each.
    pub fn new(frame_len: usize) -> Self {
        Self { data: vec![0.0; frame_len * FRAME_STACK].into_boxed_slice(), frame_len, head: 0 }
    }

    /// Values per frame.
    pub fn frame_len(&self) -> usize {
        self.frame_len
    }

    /// Advances the ring and returns the slot of the new newest frame, to be written in place.
    pub fn push_slot(&mut self) -> &mut [f32] {
        self.head = (self.head + 1) % FRAME_STACK;
        let n = self.frame_len;
        &mut self.data[self.head * n..(self.head + 1) * n]
    }

    /// Copies the newest frame into all slots (the stack after a reset).
    pub fn fill_with_latest(&mut self) {
        let n = self.frame_len;
        let (head, latest) = (self.head, self.latest().to_vec());
        for k in 0..FRAME_STACK {
            if k != head {
                self.data[k * n..(k + 1) * n].copy_from_slice(&latest);
            }
        }
    }

    /// Frame `k` of the stack, `0` the oldest (t−3) and `FRAME_STACK − 1` the newest (t).
    pub fn frame(&self, k: usize) -> &[f32] {
        assert!(k < FRAME_STACK, "frame index {k} out of range");
        let slot = (self.head + 1 + k) % FRAME_STACK;
        &self.data[slot * self.frame_len..(slot + 1) * self.frame_len]
    }

    /// The newest frame.
    pub fn latest(&self) -> &[f32] {
        self.frame(FRAME_STACK - 1)
    }

    /// The newest frame, to be changed in place.
    pub fn latest_mut(&mut self) -> &mut [f32] {
        let n = self.frame_len;
        &mut self.data[self.head * n..(self.head + 1) * n]
    }

    /// The stack oldest-first as one new vector (`FRAME_STACK * frame_len` values), copied
    /// frame by frame: new memory is not zeroed first.
    pub fn to_stacked_vec(&self) -> Vec<f32> {
        let mut v = Vec::with_capacity(FRAME_STACK * self.frame_len);
        for k in 0..FRAME_STACK {
            v.extend_from_slice(self.frame(k));
        }
        v
    }

    /// Writes the stack oldest-first through `f` (e.g. a normaliser) into `out`, which must
    /// hold `FRAME_STACK * frame_len` values: the `[4, …]` network input layout.
    pub fn write_stacked(&self, out: &mut [f32], f: impl Fn(&[f32], &mut [f32])) {
        let n = self.frame_len;
        assert_eq!(out.len(), n * FRAME_STACK, "write_stacked: output length");
        for (k, chunk) in out.chunks_exact_mut(n).enumerate() {
            f(self.frame(k), chunk);
        }
    }
}

/// What the agent sees: the last 4 frames of each sensor (metres, oldest first) and the
/// true velocities of the last 3 steps for the auxiliary task.
///
/// Frames are raw metres; the network input is made with [`normalize_laser`] /
/// [`normalize_depth`] ([`FrameStack::write_stacked`]), the one normalisation shared by
/// the simulator and the real robot. Both build this type, so a [`Policy`](crate::Policy)
/// cannot tell them apart.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// Laser ranges, 4 x 512, metres.
    pub laser: FrameStack,
    /// Depth images, 4 x 128 x 160, metres (0: no reading).
    pub depth: FrameStack,
    /// True `(v, ω)` at `t−2`, `t−1`, `t`.
    pub odom: [Velocity; ODOM_HISTORY],
    /// The navigation task's goal in the robot frame ([`goal_in_robot_frame`], metres),
    /// `None` in the obstacle-avoidance task.
    pub goal: Option<[f32; GOAL_DIM]>,
    /// `[x m, y m, yaw rad]` in the world frame: the simulator's ground truth (on a robot,
    /// its localisation on the map). No learned policy reads it; the classical planner
    /// does, as move_base reads AMCL's pose. `None` where nothing provides it.
    pub pose: Option<[f32; 3]>,
}

impl Observation {
    /// An all-zero observation.
    pub fn zeros() -> Self {
        Self {
            laser: FrameStack::new(LASER_BEAMS),
            depth: FrameStack::new(DEPTH_LEN),
            odom: [Velocity::default(); ODOM_HISTORY],
            goal: None,
            pose: None,
        }
    }
}

impl PartialEq for FrameStack {
    fn eq(&self, other: &Self) -> bool {
        self.frame_len == other.frame_len
            && (0..FRAME_STACK).all(|k| self.frame(k) == other.frame(k))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_goal_is_seen_in_the_robot_frame() {
        let close = |a: [f32; 3], b: [f32; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6);
        // Ahead, left, behind, right of a robot facing +y at (1, 1).
        let yaw = std::f32::consts::FRAC_PI_2;
        assert!(close(goal_in_robot_frame(1.0, 1.0, yaw, 1.0, 3.0), [2.0, 0.0, 1.0]));
        assert!(close(goal_in_robot_frame(1.0, 1.0, yaw, -2.0, 1.0), [3.0, 1.0, 0.0]));
        assert!(close(goal_in_robot_frame(1.0, 1.0, yaw, 1.0, 0.0), [1.0, 0.0, -1.0]));
        assert!(close(goal_in_robot_frame(1.0, 1.0, yaw, 2.0, 1.0), [1.0, -1.0, 0.0]));
        assert_eq!(goal_in_robot_frame(1.0, 1.0, 0.3, 1.0, 1.0), [0.0, 0.0, 1.0]);
        assert_eq!(normalize_goal(&[5.0, 0.6, 0.8]), [0.5, 0.6, 0.8]);
        assert_eq!(normalize_goal(&[f32::NAN, 0.6, 0.8]), [1.0, 0.0, 1.0]);
    }

    #[test]
    fn normalisation_follows_the_authors_code() {
        let mut out = [0.0; 3];
        normalize_laser(&[0.0, 2.8, 5.6], &mut out);
        assert_eq!(out, [0.0, 0.5, 1.0]);
        let mut out = [0.0; 5];
        normalize_depth(&[0.0, 2.5, 10.0, 42.0, f32::NAN], &mut out);
        assert_eq!(out, [0.0, 0.5, 2.0, 2.0, 0.0]);
    }

    #[test]
    fn frame_stack_is_a_ring_read_oldest_first() {
        let mut s = FrameStack::new(2);
        s.push_slot().copy_from_slice(&[1.0, 1.0]);
        s.fill_with_latest();
        for k in 0..FRAME_STACK {
            assert_eq!(s.frame(k), &[1.0, 1.0]);
        }
        for i in 2..=6 {
            s.push_slot().copy_from_slice(&[i as f32, -(i as f32)]);
        }
        let firsts: Vec<f32> = (0..FRAME_STACK).map(|k| s.frame(k)[0]).collect();
        assert_eq!(firsts, [3.0, 4.0, 5.0, 6.0]);
        let mut out = vec![0.0; 8];
        s.write_stacked(&mut out, |a, b| b.copy_from_slice(a));
        assert_eq!(out, [3.0, -3.0, 4.0, -4.0, 5.0, -5.0, 6.0, -6.0]);
        assert_eq!(s.to_stacked_vec(), out);
        // Equality is by frames, not by where the ring's head is.
        let mut t = FrameStack::new(2);
        for i in 3..=6 {
            t.push_slot().copy_from_slice(&[i as f32, -(i as f32)]);
        }
        t.push_slot().copy_from_slice(&[9.0, 9.0]);
        assert_ne!(s, t);
        let mut u = FrameStack::new(2);
        for i in 2..=6 {
            u.push_slot().copy_from_slice(&[i as f32, -(i as f32)]);
        }
        u.push_slot().copy_from_slice(&[6.0, -6.0]);
        assert_ne!(s, u);
        let mut w = FrameStack::new(2);
        for i in 1..=6 {
            w.push_slot().copy_from_slice(&[i as f32, -(i as f32)]);
        }
        assert_eq!(s, w, "same frames, different head");
    }
}
