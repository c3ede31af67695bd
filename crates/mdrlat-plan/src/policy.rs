//! The classical planner as a [`Policy`]: A* on the world's map at the start of each episode,
//! DWA on the live laser scan every step, continuous velocity commands.

use crate::astar::{PlanError, astar};
use crate::dwa::{Dwa, DwaConfig, Limits};
use crate::grid::{CostMap, MapKind, OccupancyGrid};
use mdrlat_core::{Decision, Observation, Policy, PolicyError, Sensors, Velocity};
use mdrlat_geom::{Pose2, Vec2};
use mdrlat_sim::SimConfig;
use mdrlat_sim::sensors::Laser;
use mdrlat_world::World;

/// Which map the planner is given.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MapSource {
    /// What a 2D-laser SLAM map of the world would hold (the default: move_base's map).
    #[default]
    LaserPlane,
    /// Every obstacle the body can hit (a map no 2D laser could have built).
    Body,
}

impl MapSource {
    /// The policy names the command line and sweep files give the planner: `planner`
    /// (laser-plane map) and `planner-body`.
    pub const POLICY_NAMES: [&str; 2] = ["planner", "planner-body"];

    /// The map of the planner policy called `name`, if it is one.
    pub fn from_policy_name(name: &str) -> Option<MapSource> {
        match name {
            "planner" => Some(MapSource::LaserPlane),
            "planner-body" => Some(MapSource::Body),
            _ => None,
        }
    }
}

/// How the planner is set up.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannerOptions {
    /// The global map.
    pub map: MapSource,
    /// Cell side of the map, metres.
    pub resolution_m: f32,
    /// Inflation beyond the robot's radius, metres.
    pub inflation_margin_m: f32,
    /// Cost weight near obstacles (navfn-style; 0: shortest paths).
    pub cost_weight: f32,
    /// Distance over which that cost decays, metres.
    pub cost_decay_m: f32,
    /// The robot leaving the plan by more than this replans, metres.
    pub replan_distance_m: f32,
    /// The local planner.
    pub dwa: DwaConfig,
}

impl Default for PlannerOptions {
    fn default() -> Self {
        Self {
            map: MapSource::LaserPlane,
            resolution_m: 0.05,
            inflation_margin_m: 0.08,
            cost_weight: 3.0,
            cost_decay_m: 0.15,
            replan_distance_m: 1.0,
            dwa: DwaConfig::default(),
        }
    }
}

/// The plan of one slot's episode.
#[derive(Debug, Clone, Default)]
struct Slot {
    /// The goal it was made for and its points (or why there is none).
    plan: Option<(Vec2, Result<Vec<Vec2>, PlanError>)>,
}

/// The classical baseline (the paper's move_base): see the crate docs. It reads the
/// robot's pose and goal from the observation ([`Observation::pose`], [`Observation::goal`])
/// and the latest laser scan; it drives with continuous velocities (a [`Decision::continuous`](mdrlat_core::Decision::continuous) per observation);
/// its actions are the nearest Table 1 ones, for the records.
#[derive(Debug, Clone)]
pub struct PlannerPolicy {
    map: CostMap,
    dwa: Dwa,
    /// `(cos, sin)` of each laser beam's angle.
    beams: Vec<(f32, f32)>,
    max_range_m: f32,
    replan_distance_m: f32,
    slots: Vec<Slot>,
    label: String,
}

impl PlannerPolicy {
    /// The planner for `world` driving a robot with `config`'s body, laser and limits.
    ///
    /// # Errors
    /// A map setting that cannot work (resolution).
    pub fn new(
        world: &World,
        config: &SimConfig,
        options: &PlannerOptions,
    ) -> Result<Self, String> {
        let kind = match options.map {
            MapSource::LaserPlane => MapKind::LaserPlane { height_m: config.laser.height_m },
            MapSource::Body => MapKind::Body { height_m: config.robot.body_height_m },
        };
        let grid = OccupancyGrid::from_world(world, kind, options.resolution_m)?;
        // The environment also ends an episode when a laser range falls below the collision
        // range (eq. 4, measured from the robot's centre): that is the radius to keep.
        let radius = config.robot.radius_m.max(config.reward.collision_range_m);
        let map = CostMap::new(
            grid,
            radius + options.inflation_margin_m,
            options.cost_weight,
            options.cost_decay_m,
        );
        let limits = Limits::table_1(config.robot.max_linear_accel, config.robot.max_angular_accel);
        let dwa_config =
            DwaConfig { radius_m: radius, control_dt_s: config.dt_s, ..options.dwa.clone() };
        let map_name = match options.map {
            MapSource::LaserPlane => "laser-plane map",
            MapSource::Body => "body map",
        };
        Ok(Self {
            map,
            dwa: Dwa::new(dwa_config, limits),
            beams: Laser::new(&config.laser).angles().iter().map(|a| (a.cos(), a.sin())).collect(),
            max_range_m: config.laser.max_range_m,
            replan_distance_m: options.replan_distance_m,
            slots: Vec::new(),
            label: format!("planner (A* + DWA, {map_name} of '{}')", world.name),
        })
    }

    /// The cost map the global planner searches.
    pub fn cost_map(&self) -> &CostMap {
        &self.map
    }

    /// The current plan of `slot` (world points), or why it has none.
    pub fn plan(&self, slot: usize) -> Option<&Result<Vec<Vec2>, PlanError>> {
        self.slots.get(slot).and_then(|s| s.plan.as_ref()).map(|(_, p)| p)
    }

    /// The laser hits of the latest scan in the robot frame (max-range readings dropped).
    fn obstacles(&self, obs: &Observation) -> Vec<Vec2> {
        let ranges = obs.laser.latest();
        ranges
            .iter()
            .zip(&self.beams)
            .filter(|&(&r, _)| r.is_finite() && r < self.max_range_m * 0.999)
            .map(|(&r, &(c, s))| Vec2::new(r * c, r * s))
            .collect()
    }

    fn command(&mut self, obs: &Observation, slot: usize) -> Result<Velocity, PolicyError> {
        let [x, y, yaw] = obs.pose.ok_or_else(|| {
            PolicyError::Backend(
                "the planner needs the robot's pose (localisation on the map)".into(),
            )
        })?;
        let [d, s, c] = obs.goal.ok_or_else(|| {
            PolicyError::Backend(
                "the planner drives to a goal: run the navigation task (--task nav)".into(),
            )
        })?;
        let pose = Pose2::new(x, y, yaw);
        let goal = pose.to_world(Vec2::new(d * c, d * s));
        if self.slots.len() <= slot {
            self.slots.resize_with(slot + 1, Slot::default);
        }
        let stale = match &self.slots[slot].plan {
            None => true,
            // Replan when the goal moved or the robot strayed from the plan.
            Some((g, plan)) => {
                (*g - goal).length() > 0.05
                    || plan.as_ref().is_ok_and(|p| {
                        distance_to_points(pose.position(), p) > self.replan_distance_m
                    })
            }
        };
        if stale {
            let plan = astar(&self.map, pose.position(), goal).map(|p| p.points);
            self.slots[slot].plan = Some((goal, plan));
        }
        let velocity = obs.odom[obs.odom.len() - 1];
        Ok(match self.slots[slot].plan.as_ref().map(|(_, p)| p) {
            Some(Ok(points)) => self.dwa.command(pose, velocity, points, &self.obstacles(obs)),
            // No plan: move_base aborts; the robot stands (the episode times out).
            _ => Velocity::new(0.0, 0.0),
        })
    }
}

/// The shortest distance from `p` to any of `points`.
fn distance_to_points(p: Vec2, points: &[Vec2]) -> f32 {
    points.iter().map(|&q| (q - p).length_sq()).fold(f32::INFINITY, f32::min).sqrt()
}

impl Policy for PlannerPolicy {
    fn name(&self) -> String {
        self.label.clone()
    }

    fn sensors(&self) -> Sensors {
        Sensors { laser: true, depth: false }
    }

    fn begin_episode(&mut self, slot: usize, _seed: Option<u64>) {
        if let Some(s) = self.slots.get_mut(slot) {
            s.plan = None;
        }
    }

    fn decide(
        &mut self,
        batch: &[&Observation],
        slots: &[usize],
        out: &mut Vec<Decision>,
    ) -> Result<(), PolicyError> {
        mdrlat_core::decide_each(batch, slots, out, |slot, obs| {
            self.command(obs, slot).map(Decision::continuous)
        })
    }
}
