//! The local planner: a dynamic window approach in the style of move_base's DWA.

use mdrlat_core::{TABLE_1, Velocity};
use mdrlat_geom::math::wrap_angle;
use mdrlat_geom::{Pose2, Vec2};

/// What the robot can do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Largest forward speed, m/s (the controller never reverses, as the paper's robot).
    pub v_max: f32,
    /// Largest turn rate either way, rad/s.
    pub w_max: f32,
    /// Linear acceleration limit, m/s².
    pub accel_v: f32,
    /// Angular acceleration limit, rad/s².
    pub accel_w: f32,
}

impl Limits {
    /// The speeds of the paper's action set (Table 1: up to 0.5 m/s and π/3 rad/s) with the
    /// given acceleration limits: the planner drives the robot the learned policies drive.
    pub fn table_1(accel_v: f32, accel_w: f32) -> Self {
        let v_max = TABLE_1.iter().map(|a| a.v).fold(0.0, f32::max);
        let w_max = TABLE_1.iter().map(|a| a.w.abs()).fold(0.0, f32::max);
        Self { v_max, w_max, accel_v, accel_w }
    }
}

/// The local planner's settings (defaults after move_base's `dwa_local_planner`, scaled to
/// this robot; every one documented in docs/navigation.md).
#[derive(Debug, Clone, PartialEq)]
pub struct DwaConfig {
    /// Robot radius, metres.
    pub radius_m: f32,
    /// Clearance a moving trajectory must keep from every laser point, beyond the radius.
    pub margin_m: f32,
    /// Laser points closer together than this are thinned to one (the nearest), metres
    /// (0: every point).
    pub obstacle_cell_m: f32,
    /// How far ahead each velocity is rolled out, seconds.
    pub horizon_s: f32,
    /// Time between the rolled-out points, seconds.
    pub step_s: f32,
    /// How long a command is held (the control period): the window of reachable
    /// velocities is the acceleration limits times this.
    pub control_dt_s: f32,
    /// Linear velocities sampled across the window.
    pub v_samples: usize,
    /// Angular velocities sampled across the window.
    pub w_samples: usize,
    /// How far along the plan the point to steer for lies, metres.
    pub lookahead_m: f32,
    /// Score per metre between a trajectory's end and the plan.
    pub path_weight: f32,
    /// Score per metre between a trajectory's end and the point steered for.
    pub target_weight: f32,
    /// Score per radian between a trajectory's final heading and the point steered for.
    pub heading_weight: f32,
    /// Score per metre of clearance (counted up to `clearance_cap_m`).
    pub clearance_weight: f32,
    /// Clearance beyond which more does not score.
    pub clearance_cap_m: f32,
    /// Score per m/s of forward speed.
    pub speed_weight: f32,
    /// Within this distance of the goal the robot stops, metres.
    pub goal_tolerance_m: f32,
}

impl Default for DwaConfig {
    fn default() -> Self {
        Self {
            radius_m: mdrlat_core::robot::RADIUS_M,
            margin_m: 0.02,
            obstacle_cell_m: 0.02,
            horizon_s: 1.6,
            step_s: 0.2,
            control_dt_s: 0.2,
            v_samples: 4,
            w_samples: 11,
            lookahead_m: 0.8,
            path_weight: 3.0,
            target_weight: 1.0,
            heading_weight: 0.4,
            clearance_weight: 0.4,
            clearance_cap_m: 0.5,
            speed_weight: 0.6,
            goal_tolerance_m: 0.3,
        }
    }
}

/// The local planner (see the crate docs). Stateless: each call decides from the pose, the
/// current velocity, the plan and the latest laser points.
#[derive(Debug, Clone, PartialEq)]
pub struct Dwa {
    /// Settings.
    pub config: DwaConfig,
    /// The robot's limits.
    pub limits: Limits,
}

impl Dwa {
    /// A planner with these settings and limits.
    pub fn new(config: DwaConfig, limits: Limits) -> Self {
        Self { config, limits }
    }

    /// The command for the next control period: the best-scoring reachable velocity whose
    /// roll-out keeps `radius + margin` from every point of `obstacles` (laser hits in the
    /// robot's frame, x forward, y left); turning on the spot is always allowed (the
    /// footprint is a disc). Stops within the goal tolerance of the plan's last point.
    pub fn command(
        &self,
        pose: Pose2,
        velocity: Velocity,
        plan: &[Vec2],
        obstacles: &[Vec2],
    ) -> Velocity {
        let (c, l) = (&self.config, &self.limits);
        let Some(&goal) = plan.last() else { return Velocity::new(0.0, 0.0) };
        let goal_local = pose.to_local(goal);
        if goal_local.length() <= c.goal_tolerance_m {
            return Velocity::new(0.0, 0.0);
        }
        // Only the plan near the robot is scored: from the segment before the one nearest
        // the robot (a tie at a shared vertex may fall either way in the robot's frame) to
        // as far along as the point steered for plus a roll-out's reach, counted from the
        // nearest segment's end (a roll-out ends within `v_max · horizon` of the robot, so a
        // later stretch of a plan that does not double back cannot be nearer its end). The
        // rest is never transformed.
        let (nearest, _) = nearest_on_polyline(plan, pose.position());
        let first = nearest.saturating_sub(1);
        let window_m = c.lookahead_m + 2.0 * l.v_max * c.horizon_s;
        let last = window_end(plan, (nearest + 1).min(plan.len() - 1), window_m);
        let local: Vec<Vec2> = plan[first..=last].iter().map(|&p| pose.to_local(p)).collect();
        let (target, ahead) = lookahead(&local, c.lookahead_m);
        // Only the points a roll-out can reach matter.
        let reach = l.v_max * c.horizon_s + c.radius_m + c.margin_m + c.clearance_cap_m;
        let mut near = thin(obstacles, reach, c.obstacle_cell_m);
        near.sort_by(|a, b| a.length_sq().total_cmp(&b.length_sq()));
        let points = Points::new(&near);
        // Slow enough to stop at the goal.
        let v_goal =
            (2.0 * l.accel_v * (goal_local.length() - c.goal_tolerance_m * 0.5).max(0.0)).sqrt();
        let dv = l.accel_v * c.control_dt_s;
        let dw = l.accel_w * c.control_dt_s;
        let (v_lo, v_hi) = ((velocity.v - dv).max(0.0), (velocity.v + dv).min(l.v_max).min(v_goal));
        let (w_lo, w_hi) = ((velocity.w - dw).max(-l.w_max), (velocity.w + dw).min(l.w_max));
        let mut best: Option<(f32, Velocity)> = None;
        for v in samples(v_lo, v_hi.max(v_lo), c.v_samples) {
            for w in samples(w_lo, w_hi, c.w_samples) {
                // Points beyond the roll-out's reach plus the capped clearance cannot change
                // its score.
                let r = v * c.horizon_s + c.radius_m + c.clearance_cap_m + c.margin_m;
                let k = near.partition_point(|o| o.length_sq() <= r * r);
                let Some(score) = self.score(v, w, points.first(k), &local[ahead..], target) else {
                    continue;
                };
                if best.is_none_or(|(b, _)| score > b) {
                    best = Some((score, Velocity::new(v, w)));
                }
            }
        }
        // Every sample moving and blocked, and no standing one in the window: brake.
        best.map_or(Velocity::new((velocity.v - dv).max(0.0), 0.0), |(_, cmd)| cmd)
    }

    /// Score of holding `(v, w)` over the horizon, or `None` if it comes too close to an
    /// obstacle.
    fn score(
        &self,
        v: f32,
        w: f32,
        obstacles: (&[f32], &[f32]),
        plan: &[Vec2],
        target: Vec2,
    ) -> Option<f32> {
        let c = &self.config;
        let steps = (c.horizon_s / c.step_s).ceil().max(1.0) as usize;
        // Squared distances in the inner loop; a moving roll-out stops at its first point
        // too close (it is discarded whatever its score).
        let too_close = (c.radius_m + c.margin_m).powi(2);
        let mut nearest_sq = f32::INFINITY;
        let mut end = Pose2::default();
        for k in 1..=steps {
            end = arc(v, w, k as f32 * c.step_s);
            nearest_sq = nearest_sq.min(nearest_sq_to(obstacles, end.position()));
            if v > 0.0 && nearest_sq < too_close {
                return None;
            }
        }
        let clearance = nearest_sq.sqrt() - c.radius_m;
        let p = end.position();
        let to_target = target - p;
        let heading = if to_target.length() > 1e-3 {
            wrap_angle(to_target.angle() - end.yaw).abs()
        } else {
            0.0
        };
        Some(
            -c.path_weight * distance_to_polyline(p, plan)
                - c.target_weight * to_target.length()
                - c.heading_weight * heading
                + c.clearance_weight * clearance.min(c.clearance_cap_m).max(0.0)
                + c.speed_weight * v,
        )
    }
}

/// Obstacle points as two coordinate arrays, for the roll-outs' inner loop.
struct Points {
    xs: Vec<f32>,
    ys: Vec<f32>,
}

impl Points {
    fn new(points: &[Vec2]) -> Self {
        Self { xs: points.iter().map(|p| p.x).collect(), ys: points.iter().map(|p| p.y).collect() }
    }

    /// The first `k` points.
    fn first(&self, k: usize) -> (&[f32], &[f32]) {
        (&self.xs[..k], &self.ys[..k])
    }
}

/// The smallest squared distance from `p` to the points `(xs, ys)` (infinite for none).
/// Eight running minima side by side let the compiler use vector instructions; a minimum
/// does not depend on the order it is taken in, so the result is exactly the one-by-one
/// loop's.
fn nearest_sq_to((xs, ys): (&[f32], &[f32]), p: Vec2) -> f32 {
    const LANES: usize = 8;
    let mut acc = [f32::INFINITY; LANES];
    let (cx, cy) = (xs.chunks_exact(LANES), ys.chunks_exact(LANES));
    let (rx, ry) = (cx.remainder(), cy.remainder());
    for (x, y) in cx.zip(cy) {
        for l in 0..LANES {
            let (dx, dy) = (x[l] - p.x, y[l] - p.y);
            acc[l] = acc[l].min(dx * dx + dy * dy);
        }
    }
    for (x, y) in rx.iter().zip(ry) {
        let (dx, dy) = (x - p.x, y - p.y);
        acc[0] = acc[0].min(dx * dx + dy * dy);
    }
    acc.into_iter().fold(f32::INFINITY, f32::min)
}

/// The points within `reach` of the robot, one per `cell` square (the one nearest the
/// robot): a 512-beam scan puts neighbouring hits a centimetre apart, and the roll-outs'
/// cost grows with the points.
fn thin(points: &[Vec2], reach: f32, cell: f32) -> Vec<Vec2> {
    let mut near: Vec<(i32, i32, f32, Vec2)> = points
        .iter()
        .filter(|o| o.is_finite() && o.length_sq() <= reach * reach)
        .map(|&o| {
            let key = |x: f32| if cell > 0.0 { (x / cell).floor() as i32 } else { 0 };
            (key(o.x), key(o.y), o.length_sq(), o)
        })
        .collect();
    if cell <= 0.0 {
        return near.into_iter().map(|n| n.3).collect();
    }
    near.sort_by(|a, b| (a.0, a.1).cmp(&(b.0, b.1)).then(a.2.total_cmp(&b.2)));
    near.dedup_by(|later, first| (later.0, later.1) == (first.0, first.1));
    near.into_iter().map(|n| n.3).collect()
}

/// `n` evenly spaced values from `lo` to `hi` (one value if they are equal or `n` < 2).
fn samples(lo: f32, hi: f32, n: usize) -> impl Iterator<Item = f32> {
    let n = if hi > lo { n.max(2) } else { 1 };
    (0..n).map(move |i| if n == 1 { lo } else { lo + (hi - lo) * i as f32 / (n - 1) as f32 })
}

/// The pose after holding `(v, w)` for `t` seconds from the origin facing +x.
fn arc(v: f32, w: f32, t: f32) -> Pose2 {
    if w.abs() < 1e-6 {
        return Pose2::new(v * t, 0.0, 0.0);
    }
    let yaw = w * t;
    Pose2::new(v / w * yaw.sin(), v / w * (1.0 - yaw.cos()), yaw)
}

/// The segment of `line` (its first point's index) holding the point nearest `p`, and that
/// point (the first segment on ties; `(0, line[0])` for a single point).
fn nearest_on_polyline(line: &[Vec2], p: Vec2) -> (usize, Vec2) {
    let (mut seg, mut at, mut best) = (0, line.first().copied().unwrap_or_default(), f32::INFINITY);
    for (i, s) in line.windows(2).enumerate() {
        let q = closest_on_segment(p, s[0], s[1]);
        if (q - p).length_sq() < best {
            (seg, at, best) = (i, q, (q - p).length_sq());
        }
    }
    (seg, at)
}

/// The index of the first point of `line` at least `length_m` along it from point `first`
/// (the last point if the line is shorter).
fn window_end(line: &[Vec2], first: usize, length_m: f32) -> usize {
    let mut left = length_m;
    for i in first + 1..line.len() {
        left -= (line[i] - line[i - 1]).length();
        if left <= 0.0 {
            return i;
        }
    }
    line.len().saturating_sub(1).max(first)
}

/// The point `lookahead_m` along the plan (robot frame) from the plan's point nearest the
/// robot, and the index of the segment that nearest point lies on.
fn lookahead(plan: &[Vec2], lookahead_m: f32) -> (Vec2, usize) {
    if plan.len() < 2 {
        return (plan.first().copied().unwrap_or_default(), 0);
    }
    let (seg, mut from) = nearest_on_polyline(plan, Vec2::default());
    let mut left = lookahead_m;
    for i in seg..plan.len() - 1 {
        let d = plan[i + 1] - from;
        let len = d.length();
        if len >= left {
            return (from + d * (left / len), seg);
        }
        left -= len;
        from = plan[i + 1];
    }
    (plan[plan.len() - 1], seg)
}

/// The point of segment `a`–`b` nearest `p`.
fn closest_on_segment(p: Vec2, a: Vec2, b: Vec2) -> Vec2 {
    let d = b - a;
    let t =
        if d.length_sq() > 0.0 { ((p - a).dot(d) / d.length_sq()).clamp(0.0, 1.0) } else { 0.0 };
    a + d * t
}

/// Distance from `p` to the polyline (to the point for a single point; infinite for none).
fn distance_to_polyline(p: Vec2, line: &[Vec2]) -> f32 {
    match line {
        [] => f32::INFINITY,
        [only] => (p - *only).length(),
        _ => line
            .windows(2)
            .map(|s| (p - closest_on_segment(p, s[0], s[1])).length())
            .fold(f32::INFINITY, f32::min),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The simulator's kinematics: velocities move to the command within the acceleration
    /// limits, then the pose follows the arc.
    fn advance(pose: &mut Pose2, vel: &mut Velocity, cmd: Velocity, l: &Limits, dt: f32) {
        let v = vel.v + (cmd.v - vel.v).clamp(-l.accel_v * dt, l.accel_v * dt);
        let w = vel.w + (cmd.w - vel.w).clamp(-l.accel_w * dt, l.accel_w * dt);
        *vel = Velocity::new(v, w);
        let step = arc(v, w, dt);
        let p = pose.to_world(step.position());
        *pose = Pose2::new(p.x, p.y, wrap_angle(pose.yaw + step.yaw));
    }

    fn drive(plan: &[Vec2], walls: &[Vec2], steps: usize) -> (Vec<Pose2>, Velocity) {
        let dwa = Dwa::new(DwaConfig::default(), Limits::table_1(1.0, 2.0));
        let (mut pose, mut vel) = (Pose2::default(), Velocity::new(0.0, 0.0));
        let mut poses = vec![pose];
        for _ in 0..steps {
            let seen: Vec<Vec2> = walls.iter().map(|&p| pose.to_local(p)).collect();
            let cmd = dwa.command(pose, vel, plan, &seen);
            assert!(cmd.v >= 0.0 && cmd.v <= dwa.limits.v_max + 1e-6, "{cmd:?}");
            assert!(cmd.w.abs() <= dwa.limits.w_max + 1e-6, "{cmd:?}");
            advance(&mut pose, &mut vel, cmd, &dwa.limits, 0.2);
            poses.push(pose);
        }
        (poses, vel)
    }

    fn wall_at_x(x: f32) -> Vec<Vec2> {
        (0..=80).map(|i| Vec2::new(x, -2.0 + i as f32 * 0.05)).collect()
    }

    #[test]
    fn near_the_end_of_a_long_segment_it_steers_for_the_next_one() {
        // Robot 0.1 m before an L's corner: the point steered for lies up the second leg,
        // beyond the segment the robot is on.
        let dwa = Dwa::new(DwaConfig::default(), Limits::table_1(1.0, 2.0));
        let plan = [Vec2::new(0.0, 0.0), Vec2::new(3.0, 0.0), Vec2::new(3.0, 3.0)];
        let cmd = dwa.command(Pose2::new(2.9, 0.0, 0.0), Velocity::new(0.3, 0.0), &plan, &[]);
        assert!(cmd.w > 0.1, "turns left into the second leg: {cmd:?}");
    }

    #[test]
    fn it_stops_before_a_wall_across_the_plan() {
        // The plan runs straight through a wall 1.2 m ahead (a map without it).
        let plan = [Vec2::new(0.0, 0.0), Vec2::new(3.0, 0.0)];
        let wall = wall_at_x(1.2);
        let (poses, vel) = drive(&plan, &wall, 60);
        let closest = poses.iter().map(|p| 1.2 - p.x).fold(f32::INFINITY, f32::min);
        assert!(closest >= mdrlat_core::robot::RADIUS_M, "came within {closest} m");
        assert!(poses.iter().any(|p| p.x > 0.4), "it drove towards the goal first");
        assert!(vel.v.abs() < 1e-6, "and stands: {vel:?}");
    }

    #[test]
    fn it_reaches_a_goal_in_the_open_and_stops_there() {
        let plan = [Vec2::new(0.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(2.5, 1.5)];
        let (poses, vel) = drive(&plan, &[], 80);
        let last = poses.last().expect("poses").position();
        assert!((last - Vec2::new(2.5, 1.5)).length() <= 0.3, "ended at {last:?}");
        assert!(vel.v.abs() < 0.1, "{vel:?}");
    }

    #[test]
    fn it_follows_a_plan_through_a_doorway() {
        // A wall at x = 1.5 with a 0.8 m door at y ∈ [0.6, 1.4]; the plan goes through it.
        let wall: Vec<Vec2> =
            wall_at_x(1.5).into_iter().filter(|p| !(0.6..=1.4).contains(&p.y)).collect();
        let plan =
            [Vec2::new(0.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(2.0, 1.0), Vec2::new(3.0, 1.0)];
        let (poses, _) = drive(&plan, &wall, 100);
        for p in &poses {
            let d = wall.iter().map(|w| (*w - p.position()).length()).fold(f32::INFINITY, f32::min);
            assert!(d >= mdrlat_core::robot::RADIUS_M, "hit the wall at {p:?}");
        }
        let last = poses.last().expect("poses").position();
        assert!((last - Vec2::new(3.0, 1.0)).length() <= 0.3, "ended at {last:?}");
    }

    #[test]
    fn the_same_inputs_give_the_same_command() {
        let dwa = Dwa::new(DwaConfig::default(), Limits::table_1(1.0, 2.0));
        let plan = [Vec2::new(0.0, 0.0), Vec2::new(2.0, -1.0)];
        let wall = wall_at_x(0.9);
        let a = dwa.command(Pose2::default(), Velocity::new(0.3, 0.1), &plan, &wall);
        let b = dwa.command(Pose2::default(), Velocity::new(0.3, 0.1), &plan, &wall);
        assert_eq!(a, b);
        assert_eq!(
            dwa.command(Pose2::default(), Velocity::new(0.0, 0.0), &[], &wall),
            Velocity::new(0.0, 0.0)
        );
    }
}
