//! `avoid`: a classical avoider with the learned policies' two sensors and no map — the
//! baseline that says how achievable a world is.
//!
//! A dynamic-window controller over the ten actions of Table 1 (as move_base's DWA, with a
//! local costmap and no global plan):
//!
//! 1. **Odometry.** Each slot dead-reckons its pose in its own odometry frame from the
//!    episode's start, replaying its last command through the robot's kinematics from the
//!    previous odometry reading (the same acceleration limits and sub-steps the base obeys).
//! 2. **A local costmap carried by odometry.** The laser's hits and the depth camera's
//!    obstacle columns (heights between 3 cm and the body's, floor excluded) mark 5 cm cells
//!    in the odometry frame, each remembering which sensors saw it and when. A cell that a
//!    sensor that saw it now sees through is cleared (raytrace clearing: a low box under the
//!    laser plane is not wiped by the laser, and the camera clears only where its rows cover
//!    every height the body can hit); cells unseen for
//!    [`AvoidConfig::memory_steps`] or far away are forgotten. The memory is what lets the
//!    robot turn beside a box that has left the camera's 58° or come inside its 0.4 m
//!    minimum range.
//! 3. **Walkers.** A laser hit where the previous scan saw free space, with a hit of the
//!    previous scan within a walker's step of it, is a moving point with that velocity, and
//!    each roll-out meets it where it will be.
//! 4. **Roll-outs.** Each action is held for [`AvoidConfig::horizon_s`] through the
//!    kinematics (acceleration limits included); one whose body disc comes within
//!    [`AvoidConfig::margin_m`] of a remembered or predicted point is refused — except
//!    turning in place where the robot already stands that close, as long as the turn brings
//!    it no closer than it is.
//! 5. **Score.** Speed, clearance, how open the way ahead of the roll-out's end is, progress
//!    away from the episode's start (so it explores rather than circles), and a preference
//!    for the turn direction it already took (no dithering at a wall). If every action is
//!    refused it takes the one that keeps the most clearance.
//!
//! It is a scripted policy like `wander`: no learning, the same observations a network gets
//! (the frame stack and odometry, never the simulator's pose).

use crate::config::SimConfig;
use crate::env::Observation;
use crate::robot::RobotState;
use crate::sensors::{DepthCamera, DepthGeometry, Laser};
use mdrlat_core::{
    Action, Decision, FRAME_STACK, ODOM_HISTORY, Policy, PolicyError, Sensors, Velocity,
    decide_each,
};
use mdrlat_geom::{Pose2, Vec2};
use std::collections::BTreeMap;

/// The avoider's settings (defaults tuned on the training world only, never on the test
/// worlds it calibrates).
#[derive(Debug, Clone, PartialEq)]
pub struct AvoidConfig {
    /// Edge of a costmap cell, metres.
    pub cell_m: f32,
    /// Steps a cell is remembered after a sensor last saw it.
    pub memory_steps: u32,
    /// Cells farther than this from the robot are forgotten, metres.
    pub memory_radius_m: f32,
    /// Seconds each action is rolled out.
    pub horizon_s: f32,
    /// Time between roll-out points, seconds.
    pub rollout_dt_s: f32,
    /// Clearance the body must keep from every obstacle point on a roll-out, metres.
    pub margin_m: f32,
    /// How far past a roll-out's end the way ahead is measured, metres.
    pub lookahead_m: f32,
    /// A laser cell that moved less than this per second is static, m/s.
    pub walker_min_speed: f32,
    /// Walkers move at most this fast, m/s (matches farther apart are not one walker).
    pub walker_max_speed: f32,
    /// Score lost for driving the body's leading half where nothing that sees low
    /// obstacles has seen free (the share of such probes along the roll-out).
    pub unknown_weight: f32,
    /// Read the depth camera (`false`: the laser alone, `avoid-laser`, which then cannot
    /// know what is free below its plane and does not score it).
    pub depth: bool,
}

impl AvoidConfig {
    /// Checks every setting (positive sizes and times, speeds in order).
    ///
    /// # Errors
    /// The first bad setting, named.
    pub fn validate(&self) -> Result<(), String> {
        let positive = [
            ("cell_m", self.cell_m),
            ("memory_radius_m", self.memory_radius_m),
            ("horizon_s", self.horizon_s),
            ("rollout_dt_s", self.rollout_dt_s),
            ("lookahead_m", self.lookahead_m),
            ("walker_max_speed", self.walker_max_speed),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("avoid.{name}: must be positive, got {v}"));
            }
        }
        for (name, v) in [
            ("margin_m", self.margin_m),
            ("walker_min_speed", self.walker_min_speed),
            ("unknown_weight", self.unknown_weight),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("avoid.{name}: must be >= 0, got {v}"));
            }
        }
        if self.horizon_s / self.rollout_dt_s > 1000.0 || self.cell_m < 0.005 {
            return Err("avoid: more than 1000 roll-out points or cells under 5 mm".into());
        }
        Ok(())
    }
}

impl AvoidConfig {
    /// `memory_steps` of `avoid-stack`: cells seen in the last [`FRAME_STACK`] frames only,
    /// what a network's observation holds.
    pub const STACK_MEMORY_STEPS: u32 = FRAME_STACK as u32 - 1;

    /// The name of the avoider these settings make: `avoid`, `avoid-laser` (no camera),
    /// `avoid-stack` (memory of the frame stack only), `avoid-laser-stack`.
    /// Other memories with the camera are `avoid-memory-N` (N frames remembered).
    pub fn name(&self) -> String {
        let default = Self::default().memory_steps;
        match (self.depth, self.memory_steps) {
            (true, m) if m == default => "avoid".into(),
            (false, m) if m > Self::STACK_MEMORY_STEPS => "avoid-laser".into(),
            (true, Self::STACK_MEMORY_STEPS) => "avoid-stack".into(),
            (false, _) => "avoid-laser-stack".into(),
            (true, m) => format!("avoid-memory-{}", m + 1),
        }
    }
}

impl Default for AvoidConfig {
    fn default() -> Self {
        Self {
            cell_m: 0.05,
            memory_steps: 100,
            memory_radius_m: 4.0,
            horizon_s: 2.0,
            rollout_dt_s: 0.1,
            margin_m: 0.06,
            lookahead_m: 1.5,
            walker_min_speed: 0.15,
            walker_max_speed: 1.2,
            unknown_weight: 1.5,
            depth: true,
        }
    }
}

/// A remembered costmap cell.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Cell {
    /// The step a sensor last saw it.
    seen: u32,
    /// The laser hit it: it reaches the laser plane, and the laser seeing through it clears it.
    laser: bool,
    /// The depth camera saw it: the camera seeing through it clears it too.
    depth: bool,
}

/// One slot's memory: its odometry pose, its costmap and the walkers of its last scan.
#[derive(Debug, Clone, Default)]
struct Slot {
    /// Steps decided this episode.
    step: u32,
    /// Pose in the odometry frame (the episode's start is the origin).
    pose: Pose2,
    /// The command decided last (replayed through the kinematics to dead-reckon).
    last_command: Velocity,
    /// Costmap cells by index in the odometry frame.
    cells: BTreeMap<(i32, i32), Cell>,
    /// Cells seen free of anything the body can hit (by the depth camera, which alone sees
    /// low boxes and overhangs, or under the robot itself), with the step they were.
    known_free: std::collections::HashMap<(i32, i32), u32>,
    /// The laser's hits of the previous step, odometry frame.
    last_hits: Vec<Vec2>,
    /// The previous step's laser ranges and the pose they were taken from.
    last_scan: Vec<f32>,
    last_pose: Pose2,
    /// Moving points found at the last step: position and velocity, odometry frame.
    walkers: Vec<(Vec2, Vec2)>,
    /// The turn direction taken last (−1, 0, +1).
    last_turn: f32,
}

/// The classical avoider (see the module docs).
#[derive(Debug, Clone)]
pub struct AvoidPolicy {
    config: AvoidConfig,
    beam_angles: Vec<f32>,
    max_range_m: f32,
    depth: DepthGeometry,
    body_height_m: f32,
    robot: crate::config::RobotConfig,
    dt_s: f32,
    substeps: u32,
    slots: Vec<Slot>,
    depth_ranges: Vec<f32>,
    /// Nearest z-depth at which the camera's rows cover every height the body can hit, from
    /// 3 cm up (nearer, a low box can hide under its view).
    near_z: f32,
    /// Radius around a start that the simulator keeps free of obstacles the laser misses
    /// (`spawn_clearance_m` + `spawn_hidden_clearance_m` beyond the footprint): the one
    /// place known free before the camera has looked.
    start_clear_m: f32,
}

impl AvoidPolicy {
    /// The avoider for environments with `sim`'s sensors and robot.
    ///
    /// # Errors
    /// A setting [`AvoidConfig::validate`] refuses.
    pub fn new(sim: &SimConfig, config: AvoidConfig) -> Result<Self, String> {
        config.validate()?;
        let laser = Laser::new(&sim.laser);
        let depth = DepthCamera::new(&sim.depth).geometry();
        let (y_top, y_bottom) = depth
            .row_y
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &y| (lo.min(y), hi.max(y)));
        let h = depth.height_m;
        let near_z = ((h - 0.03) / y_bottom.max(1e-3))
            .max((sim.robot.body_height_m - h) / (-y_top).max(1e-3))
            .max(sim.depth.min_range_m);
        Ok(Self {
            near_z,
            start_clear_m: sim.robot.radius_m
                + sim.spawn_clearance_m
                + sim.spawn_hidden_clearance_m,
            config,
            beam_angles: laser.angles().to_vec(),
            max_range_m: sim.laser.max_range_m,
            depth,
            body_height_m: sim.robot.body_height_m,
            robot: sim.robot.clone(),
            dt_s: sim.dt_s,
            substeps: sim.substeps.max(1),
            slots: Vec::new(),
            depth_ranges: Vec::new(),
        })
    }

    fn slot(&mut self, slot: usize) -> &mut Slot {
        if self.slots.len() <= slot {
            self.slots.resize_with(slot + 1, Slot::default);
        }
        &mut self.slots[slot]
    }

    /// The cell of a point of the odometry frame.
    fn cell_of(&self, p: Vec2) -> (i32, i32) {
        ((p.x / self.config.cell_m).floor() as i32, (p.y / self.config.cell_m).floor() as i32)
    }

    /// The centre of a cell.
    fn centre(&self, c: (i32, i32)) -> Vec2 {
        Vec2::new((c.0 as f32 + 0.5) * self.config.cell_m, (c.1 as f32 + 0.5) * self.config.cell_m)
    }

    /// The pose one control period on from `pose` at `velocity` under `command`.
    fn advance(&self, state: &mut RobotState, command: Velocity) {
        let sub = self.dt_s / self.substeps as f32;
        for _ in 0..self.substeps {
            state.advance(command, &self.robot, sub);
        }
    }

    /// The action for one observation of slot `slot`.
    fn decide_slot(&mut self, slot: usize, obs: &Observation) -> Action {
        self.depth_ranges.resize(self.depth.column_angles.len(), f32::INFINITY);
        let mut depth_ranges = std::mem::take(&mut self.depth_ranges);
        if self.config.depth {
            let latest = obs.depth.latest();
            self.depth.obstacle_ranges(latest, 0.03, self.body_height_m, &mut depth_ranges);
        }
        let mut s = std::mem::take(self.slot(slot));
        // 1. Odometry: replay the last command from the previous velocity.
        if s.step > 0 {
            let mut state = RobotState { pose: s.pose, velocity: obs.odom[ODOM_HISTORY - 2] };
            self.advance(&mut state, s.last_command);
            s.pose = state.pose;
        }
        // The laser's hits in the robot frame (beams that returned within range).
        let laser = obs.laser.latest();
        let hits: Vec<Vec2> = laser
            .iter()
            .zip(&self.beam_angles)
            .filter(|(r, _)| **r > 0.0 && **r < self.max_range_m - 0.01)
            .map(|(&r, &a)| Vec2::new(r * a.cos(), r * a.sin()))
            .collect();
        // 2. The costmap: clear what the sensors see through, mark what they hit.
        self.update_costmap(&mut s, laser, &hits, obs.depth.latest(), &depth_ranges);
        // 3. Walkers: the moving points of this scan.
        self.track_walkers(&mut s, laser, &hits);
        // 4.–5. Roll out and score every action.
        let velocity = obs.odom[ODOM_HISTORY - 1];
        let action = self.choose(&s, velocity);
        s.last_command = action.command();
        let w = action.command().w;
        if w != 0.0 {
            s.last_turn = w.signum();
        }
        s.step += 1;
        self.slots[slot] = s;
        self.depth_ranges = depth_ranges;
        action
    }

    fn update_costmap(
        &self,
        s: &mut Slot,
        laser: &[f32],
        hits: &[Vec2],
        depth_latest: &[f32],
        depth_ranges: &[f32],
    ) {
        let c = &self.config;
        let pose = s.pose;
        let step = s.step;
        let n = self.beam_angles.len();
        let (a0, da) = (self.beam_angles[0], self.beam_step());
        let tan0 = self.depth.column_angles[0].tan();
        let cols = self.depth.column_angles.len();
        let dtan = (self.depth.column_angles[cols - 1].tan() - tan0) / (cols - 1).max(1) as f32;
        let clear_slack = 1.5 * c.cell_m;
        let bottom = &depth_latest[depth_latest.len() - cols..];
        let centres: Vec<((i32, i32), Vec2)> =
            s.cells.keys().map(|&k| (k, self.centre(k))).collect();
        for (key, centre) in centres {
            let local = pose.to_local(centre);
            let (r, a) = (local.length(), local.y.atan2(local.x));
            let Some(cell) = s.cells.get(&key).copied() else { continue };
            let stale = step.saturating_sub(cell.seen) > c.memory_steps || r > c.memory_radius_m;
            // Each sensor clears only what it can see: the laser what it hit (a low box under
            // its plane stays until the camera sees through it), the camera only where its
            // rows cover every height the body can hit (nearer, a low box hides under its
            // view) and only in a column whose floor it sees (not hidden by something nearer
            // than its minimum range).
            let laser_through = cell.laser && {
                let i = ((a - a0) / da).round();
                (0.0..n as f32).contains(&i) && r + clear_slack < laser[i as usize]
            };
            let depth_through = c.depth && cell.depth && a.abs() < std::f32::consts::FRAC_PI_2 && {
                let k = ((a.tan() - tan0) / dtan).round();
                (0.0..cols as f32).contains(&k) && {
                    let k = k as usize;
                    bottom[k] > 0.0
                        && r > self.near_z * self.depth.column_k[k]
                        && r + clear_slack < depth_ranges[k]
                }
            };
            let seen_through = laser_through || depth_through;
            if stale || seen_through {
                s.cells.remove(&key);
            }
        }
        let mark = |cells: &mut BTreeMap<(i32, i32), Cell>, p: Vec2, by_laser: bool| {
            let key = self.cell_of(pose.to_world(p));
            let cell = cells.entry(key).or_insert(Cell { seen: step, laser: false, depth: false });
            cell.seen = step;
            if by_laser {
                cell.laser = true;
            } else {
                cell.depth = true;
            }
        };
        for &p in hits {
            mark(&mut s.cells, p, true);
        }
        for (&r, &a) in depth_ranges.iter().zip(&self.depth.column_angles) {
            if c.depth && r.is_finite() {
                mark(&mut s.cells, Vec2::new(r * a.cos(), r * a.sin()), false);
            }
        }
        // Known free: the robot's own footprint, and each column the camera sees the floor
        // of, from where its rows cover every height the body can hit to its first obstacle.
        // At the start, the disc the simulator keeps clear of what the laser misses.
        let radius = if step == 0 { self.start_clear_m } else { self.robot.radius_m };
        let n = (radius / c.cell_m).ceil() as i32;
        let here = self.cell_of(pose.position());
        for dx in -n..=n {
            for dy in -n..=n {
                let key = (here.0 + dx, here.1 + dy);
                if (self.centre(key) - pose.position()).length() <= radius {
                    s.known_free.insert(key, step);
                }
            }
        }
        for (col, ((&r, &a), &k)) in
            depth_ranges.iter().zip(&self.depth.column_angles).zip(&self.depth.column_k).enumerate()
        {
            if !c.depth || bottom[col] <= 0.0 {
                continue; // no camera, or the floor is hidden (something nearer than its minimum range)
            }
            let (from, to) = (self.near_z * k, (r - 2.0 * c.cell_m).min(c.lookahead_m + 1.5));
            let dir = Vec2::new(a.cos(), a.sin());
            let mut d = from;
            while d < to {
                s.known_free.insert(self.cell_of(pose.to_world(dir * d)), step);
                d += c.cell_m;
            }
        }
        s.known_free.retain(|_, seen| step.saturating_sub(*seen) <= c.memory_steps);
    }

    /// Matches this scan's hits against the last scan's: a hit where the last scan saw free
    /// space, with an old hit within a walker's step of it, is a moving point whose velocity
    /// is the difference (static surfaces were not free before; newly revealed ones have no
    /// old hit near).
    fn track_walkers(&self, s: &mut Slot, laser: &[f32], hits: &[Vec2]) {
        let c = &self.config;
        let n = self.beam_angles.len();
        let (a0, da) = (self.beam_angles[0], self.beam_step());
        let world: Vec<Vec2> = hits.iter().map(|&p| s.pose.to_world(p)).collect();
        s.walkers.clear();
        if s.step > 0 && !s.last_scan.is_empty() {
            let still = c.walker_min_speed * self.dt_s;
            let reach = c.walker_max_speed * self.dt_s;
            for &p in world.iter().step_by(2) {
                // Was this spot free in the last scan?
                let q = s.last_pose.to_local(p);
                let i = ((q.y.atan2(q.x) - a0) / da).round();
                let was_free =
                    (0.0..n as f32).contains(&i) && s.last_scan[i as usize] > q.length() + 0.15;
                if !was_free {
                    continue;
                }
                let nearest = s
                    .last_hits
                    .iter()
                    .map(|&o| (o, (o - p).length()))
                    .fold((p, f32::INFINITY), |b, x| if x.1 < b.1 { x } else { b });
                if nearest.1 > still && nearest.1 < reach {
                    s.walkers.push((p, (p - nearest.0) * (1.0 / self.dt_s)));
                }
            }
        }
        s.last_hits = world;
        s.last_pose = s.pose;
        s.last_scan.clear();
        s.last_scan.extend_from_slice(laser);
    }

    /// Angle between neighbouring laser beams.
    fn beam_step(&self) -> f32 {
        let n = self.beam_angles.len();
        (self.beam_angles[n - 1] - self.beam_angles[0]) / (n - 1).max(1) as f32
    }

    /// Rolls out every action from `velocity` and picks the best admissible one.
    fn choose(&self, s: &Slot, velocity: Velocity) -> Action {
        let c = &self.config;
        let radius = self.robot.radius_m;
        let v_max = Action::command_limits().v;
        let reach = v_max * c.horizon_s + radius + c.margin_m + c.lookahead_m + 0.3;
        // The obstacles near the robot, in its frame: remembered cells, then walkers where
        // they are now with their velocity (robot frame).
        let (sin, cos) = s.pose.yaw.sin_cos();
        let rot = |v: Vec2| Vec2::new(v.x * cos + v.y * sin, -v.x * sin + v.y * cos);
        let points: Vec<Vec2> = s
            .cells
            .keys()
            .map(|&k| s.pose.to_local(self.centre(k)))
            .filter(|p| p.length() < reach)
            .collect();
        let walkers: Vec<(Vec2, Vec2)> = s
            .walkers
            .iter()
            .map(|&(p, v)| (s.pose.to_local(p), rot(v)))
            .filter(|&(p, v)| p.length().min((p + v * c.horizon_s).length()) < reach)
            .collect();
        let nearest = |p: Vec2, t: f32| -> f32 {
            let still = points.iter().map(|&q| (q - p).length_sq()).fold(f32::INFINITY, f32::min);
            let moving = walkers
                .iter()
                .map(|&(q, v)| (q + v * t - p).length_sq())
                .fold(f32::INFINITY, f32::min);
            still.min(moving).sqrt() - radius
        };
        let now = nearest(Vec2::ZERO, 0.0);
        let steps = (c.horizon_s / c.rollout_dt_s).round().max(1.0) as usize;
        let mut best: Option<(f32, Action)> = None;
        let mut fallback: Option<(f32, Action)> = None;
        let mut headings = Vec::with_capacity(steps);
        for action in Action::all() {
            let cmd = action.command();
            let mut state = RobotState { pose: Pose2::default(), velocity };
            let mut clearance = f32::INFINITY;
            // Probes on the leading half of the body: how much of what the roll-out sweeps
            // no sensor that sees low obstacles has seen free.
            let (mut probes, mut unknown) = (0u32, 0u32);
            headings.clear();
            for k in 1..=steps {
                state.advance(cmd, &self.robot, c.rollout_dt_s);
                headings.push(state.pose.yaw);
                clearance =
                    clearance.min(nearest(state.pose.position(), k as f32 * c.rollout_dt_s));
                if state.velocity.v > 0.0 {
                    for phi in [-1.0f32, -0.5, 0.0, 0.5, 1.0] {
                        let a = state.pose.yaw + phi;
                        let probe = state.pose.position()
                            + Vec2::new(a.cos(), a.sin()) * (radius + 0.5 * c.margin_m);
                        probes += 1;
                        let key = self.cell_of(s.pose.to_world(probe));
                        unknown += u32::from(!s.known_free.contains_key(&key));
                    }
                }
            }
            let unknown = unknown as f32 / probes.max(1) as f32;
            if fallback.is_none_or(|(f, _)| clearance > f) {
                fallback = Some((clearance, action));
            }
            let turning_in_place = cmd.v == 0.0;
            let admissible = clearance >= c.margin_m
                || (turning_in_place && clearance >= now.min(c.margin_m) - 1e-3);
            if !admissible {
                continue;
            }
            // How open the way ahead of the roll-out's end is; turning in place, the most
            // open heading it passes (it can stop turning there).
            let end = state.pose;
            let open_along = |from: Vec2, yaw: f32| {
                let dir = Vec2::new(yaw.cos(), yaw.sin());
                let probes = 6;
                let mut open = 0.0;
                for j in 1..=probes {
                    let d = c.lookahead_m * j as f32 / probes as f32;
                    if nearest(from + dir * d, c.horizon_s) < c.margin_m {
                        break;
                    }
                    open = d;
                }
                open
            };
            let open = if turning_in_place {
                headings.iter().map(|&yaw| open_along(end.position(), yaw)).fold(0.0, f32::max)
            } else {
                open_along(end.position(), end.yaw)
            };
            // Progress away from the start, in the odometry frame.
            let start_now = s.pose.position().length();
            let start_end = s.pose.to_world(end.position()).length();
            let away = (start_end - start_now).clamp(-1.0, 1.0);
            let turn = if cmd.w == 0.0 { 0.0 } else { cmd.w.signum() };
            let dither =
                if turn != 0.0 && s.last_turn != 0.0 && turn != s.last_turn { 0.3 } else { 0.0 };
            let score = 2.0 * cmd.v / v_max
                + 0.6 * clearance.min(0.6)
                + 0.8 * open / c.lookahead_m
                + 0.4 * away
                - 0.15 * cmd.w.abs()
                - if c.depth { c.unknown_weight * unknown } else { 0.0 }
                - dither;
            if best.is_none_or(|(b, _)| score > b) {
                best = Some((score, action));
            }
        }
        best.or(fallback)
            .map_or_else(|| Action::new(9).unwrap_or_else(|| unreachable!("Table 1")), |(_, a)| a)
    }
}

impl Policy for AvoidPolicy {
    fn name(&self) -> String {
        self.config.name()
    }
    fn sensors(&self) -> Sensors {
        Sensors { laser: true, depth: self.config.depth }
    }
    fn begin_episode(&mut self, slot: usize, _seed: Option<u64>) {
        *self.slot(slot) = Slot::default();
    }
    fn decide(
        &mut self,
        batch: &[&Observation],
        slots: &[usize],
        out: &mut Vec<Decision>,
    ) -> Result<(), PolicyError> {
        decide_each(batch, slots, out, |slot, obs| Ok(self.decide_slot(slot, obs)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_settings_are_refused_by_name() {
        assert!(AvoidConfig::default().validate().is_ok());
        let bad = |c: AvoidConfig| AvoidPolicy::new(&SimConfig::default(), c).expect_err("bad");
        assert!(
            bad(AvoidConfig { rollout_dt_s: 0.0, ..AvoidConfig::default() })
                .contains("rollout_dt_s")
        );
        assert!(bad(AvoidConfig { cell_m: f32::NAN, ..AvoidConfig::default() }).contains("cell_m"));
        assert!(bad(AvoidConfig { margin_m: -0.1, ..AvoidConfig::default() }).contains("margin_m"));
    }

    /// `avoid-laser` never reads the camera: the same episode with the depth images blanked
    /// gets the same actions, and it says it needs only the laser; `avoid` does read them.
    #[test]
    fn the_laser_only_avoider_ignores_the_camera() {
        use crate::Env;
        use crate::policy::Scripted;
        let world = mdrlat_world::builtin::get("office").expect("builtin").expect("valid");
        let sim = SimConfig::default();
        let drive = |p: Scripted, blank: bool| {
            let mut env = Env::from_world(world.clone(), sim.clone()).expect("env");
            let mut policy = p.build(&sim, 0);
            let mut obs = env.reset(Some(7)).expect("reset").clone();
            let mut actions = Vec::new();
            for _ in 0..120 {
                if blank {
                    obs.depth = mdrlat_core::FrameStack::new(obs.depth.frame_len());
                }
                let a = mdrlat_core::decide_one(policy.as_mut(), &obs, 0).expect("decides").action;
                actions.push(a);
                let step = env.step(a).expect("step");
                if step.terminated || step.truncated {
                    break;
                }
                obs = step.observation.clone();
            }
            (actions, policy.sensors(), policy.name())
        };
        let (seen, sensors, name) = drive(Scripted::AvoidLaser, false);
        assert_eq!(drive(Scripted::AvoidLaser, true).0, seen, "avoid-laser read the camera");
        assert_eq!((sensors.laser, sensors.depth, name.as_str()), (true, false, "avoid-laser"));
        assert_ne!(drive(Scripted::Avoid, true).0, drive(Scripted::Avoid, false).0);
    }

    /// `avoid-stack` keeps only the cells seen in the last four frames (what a network's
    /// frame stack holds); `avoid` remembers older ones. Names follow the settings.
    #[test]
    fn the_stack_avoider_forgets_what_the_frame_stack_does_not_hold() {
        use crate::Env;
        let world = mdrlat_world::builtin::get("furnished").expect("builtin").expect("valid");
        let sim = SimConfig::default();
        let oldest = |settings: AvoidConfig| {
            let mut policy = AvoidPolicy::new(&sim, settings).expect("valid");
            let mut env = Env::from_world(world.clone(), sim.clone()).expect("env");
            let mut obs = env.reset(Some(3)).expect("reset").clone();
            let mut oldest = 0;
            for _ in 0..60 {
                let a = mdrlat_core::decide_one(&mut policy, &obs, 0).expect("decides").action;
                // The step of the decision just taken (`step` has moved on since).
                let s = &policy.slots[0];
                let age = s.cells.values().map(|c| s.step - 1 - c.seen).max().unwrap_or(0);
                oldest = oldest.max(age);
                let step = env.step(a).expect("step");
                if step.terminated || step.truncated {
                    break;
                }
                obs = step.observation.clone();
            }
            (oldest, policy.name())
        };
        let stack =
            AvoidConfig { memory_steps: AvoidConfig::STACK_MEMORY_STEPS, ..AvoidConfig::default() };
        let (age, name) = oldest(stack);
        assert!(age <= AvoidConfig::STACK_MEMORY_STEPS, "avoid-stack kept a cell {age} steps old");
        assert_eq!(name, "avoid-stack");
        let (age, name) = oldest(AvoidConfig::default());
        assert!(age > 10, "avoid remembers cells {age} steps old at most");
        assert_eq!(name, "avoid");
        let laser = AvoidConfig { depth: false, ..AvoidConfig::default() };
        assert_eq!(laser.name(), "avoid-laser");
        // `avoid-memory-N`: the last N frames, nothing older.
        let eight: crate::Scripted = "avoid-memory-8".parse().expect("parses");
        assert_eq!(eight, crate::Scripted::AvoidMemory(8));
        assert_eq!(eight.name(), "avoid-memory-8");
        let (age, name) = oldest(AvoidConfig { memory_steps: 7, ..AvoidConfig::default() });
        assert!(age <= 7 && age > AvoidConfig::STACK_MEMORY_STEPS, "kept {age} steps");
        assert_eq!(name, "avoid-memory-8");
        let sim = crate::SimConfig::default();
        assert_eq!(eight.build(&sim, 0).name(), "avoid-memory-8");
        let four: crate::Scripted = "avoid-memory-4".parse().expect("parses");
        assert_eq!(four.build(&sim, 0).name(), "avoid-stack", "the same policy as avoid-stack");
        for bad in ["avoid-memory-0", "avoid-memory-1001", "avoid-memory-x", "avoid-memory-"] {
            let e = bad.parse::<crate::Scripted>().expect_err(bad);
            assert!(e.contains(bad) && e.contains("N from 1 to 1000"), "{e}");
        }
        let e = "avoid-mem".parse::<crate::Scripted>().expect_err("unknown");
        assert!(e.contains("avoid-memory-N"), "{e}");
    }
}
