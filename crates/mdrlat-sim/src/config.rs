//! Simulator settings. Defaults are SPEC §2 (the paper's turtlebot2 with a Hokuyo-class
//! laser and a Kinect v1). Every field can be overridden from a TOML config; unknown keys
//! are rejected.

use serde::{Deserialize, Serialize};

/// All simulator settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimConfig {
    /// Control period in seconds (5 Hz, as the authors' code).
    pub dt_s: f32,
    /// Physics sub-steps per control period (robot and pedestrians move and collisions are
    /// checked at each).
    pub substeps: u32,
    /// Steps after which an episode is truncated (a time limit, not a terminal state).
    pub max_episode_steps: u32,
    /// The robot.
    pub robot: RobotConfig,
    /// The 2D laser.
    pub laser: LaserConfig,
    /// The depth camera.
    pub depth: DepthConfig,
    /// The reward (paper eqs. 3–6).
    pub reward: RewardConfig,
    /// Extra clearance, metres, between the robot footprint and any obstacle or pedestrian
    /// at a reset pose.
    pub spawn_clearance_m: f32,
    /// More clearance, metres, from what the body can hit but the laser plane misses (low
    /// boxes, overhangs): neither sensor sees such a thing within reach of a start (the
    /// laser passes over or under it, the depth camera reads nothing nearer than its minimum
    /// range and its 45° miss a low box close by), so a start next to one is lost whatever
    /// the policy does. 0: as mdrlat before 2026-12-06.
    pub spawn_hidden_clearance_m: f32,
    /// Seconds ahead over which a reset pose must keep that clearance from every
    /// pedestrian's path as well: a start in the way of a walker that ignores the robot
    /// (`pedestrian_yield_m` < 0) would be lost before the policy could act.
    pub spawn_pedestrian_horizon_s: f32,
    /// Walkers yield to the robot: none steps closer than this to the robot's footprint,
    /// metres; a walker blocked by it waits, then turns back, as it does for another walker.
    /// A person does not walk into a robot standing in their way nor run it down from
    /// behind, so every pedestrian collision is then one the robot drove into. Negative:
    /// walkers ignore the robot (mdrlat before 2026-12-06, where a standing robot was hit
    /// in over half of the `crowd` episodes).
    pub pedestrian_yield_m: f32,
    /// What the robot is asked to do: avoid obstacles (the paper's task, the default) or
    /// reach a goal (the paper's navigation extension).
    pub task: Task,
    /// The navigation task's goals and reward (unused by obstacle avoidance).
    pub nav: NavConfig,
}

/// The task of an episode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Task {
    /// Drive without collision until the time limit (paper sections 2–3; Table 2).
    #[default]
    Avoid,
    /// Reach a goal drawn in the world's goal regions (paper section 3.1, Figures 8 and 9).
    Nav,
}

impl Task {
    /// `avoid` or `nav`, as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Task::Avoid => "avoid",
            Task::Nav => "nav",
        }
    }

    /// The task of a network whose goal input has `goal_dim` values (none: obstacle
    /// avoidance).
    pub fn of_goal_dim(goal_dim: usize) -> Task {
        if goal_dim > 0 { Task::Nav } else { Task::Avoid }
    }

    /// Whether it is obstacle avoidance (the default; files omit it then).
    pub fn is_avoid(&self) -> bool {
        *self == Task::Avoid
    }

    /// Length of the goal input a network of this task reads (0: none).
    pub fn goal_dim(self) -> usize {
        match self {
            Task::Avoid => 0,
            Task::Nav => mdrlat_core::GOAL_DIM,
        }
    }
}

impl std::fmt::Display for Task {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Task {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "avoid" => Ok(Task::Avoid),
            "nav" => Ok(Task::Nav),
            other => Err(format!("unknown task '{other}' (expected avoid or nav)")),
        }
    }
}

/// The navigation task (the authors published no navigation code: every value is ours and
/// the README says why). The reward follows Xie et al. (the paper's ref. 10) in its terms:
/// an arrival bonus, the collision penalty (`reward.collision`), progress towards the goal,
/// and the paper's own proximity and swing penalties (eqs. 5, 6); the forward-speed term of
/// eq. (4) is replaced by the progress term.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NavConfig {
    /// The episode succeeds when the robot's centre comes this close to the goal, metres.
    pub goal_radius_m: f32,
    /// Drawn goals lie at least this far from the start, metres.
    pub min_start_goal_m: f32,
    /// Reward of reaching the goal; the episode terminates.
    pub arrival: f32,
    /// Reward per metre the distance to the goal shrank in a step (negative when it grew).
    pub progress: f32,
    /// A fixed start `[x, y, yaw_deg]` for every episode instead of a drawn one.
    pub start: Option<[f32; 3]>,
    /// A fixed goal `[x, y]` for every episode instead of a drawn one.
    pub goal: Option<[f32; 2]>,
}

impl Default for NavConfig {
    fn default() -> Self {
        Self {
            goal_radius_m: 0.3,
            min_start_goal_m: 2.0,
            arrival: 10.0,
            progress: 2.5,
            start: None,
            goal: None,
        }
    }
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            dt_s: 0.2,
            substeps: 4,
            max_episode_steps: 500,
            robot: RobotConfig::default(),
            laser: LaserConfig::default(),
            depth: DepthConfig::default(),
            reward: RewardConfig::default(),
            spawn_clearance_m: mdrlat_core::robot::SPAWN_CLEARANCE_M,
            spawn_hidden_clearance_m: 0.3,
            spawn_pedestrian_horizon_s: 1.0,
            pedestrian_yield_m: 0.3,
            task: Task::Avoid,
            nav: NavConfig::default(),
        }
    }
}

/// Turtlebot2 / Kobuki: a differential-drive disc.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RobotConfig {
    /// Footprint radius, metres.
    pub radius_m: f32,
    /// Body height, metres: obstacles overlapping `[0, body_height_m]` hit the bumper.
    pub body_height_m: f32,
    /// Linear acceleration limit, m/s².
    pub max_linear_accel: f32,
    /// Angular acceleration limit, rad/s².
    pub max_angular_accel: f32,
}

impl Default for RobotConfig {
    fn default() -> Self {
        Self {
            radius_m: mdrlat_core::robot::RADIUS_M,
            body_height_m: mdrlat_core::robot::BODY_HEIGHT_M,
            max_linear_accel: 1.0,
            max_angular_accel: 2.0,
        }
    }
}

/// The 2D laser range finder (512 beams, fixed by the observation layout).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LaserConfig {
    /// Field of view, degrees, centred ahead.
    pub fov_deg: f32,
    /// Height of the scan plane above the floor, metres.
    pub height_m: f32,
    /// Maximum range, metres; beams with no return read this.
    pub max_range_m: f32,
    /// Standard deviation of additive Gaussian range noise, metres (0: off).
    pub noise_std_m: f32,
    /// Frames of the depth camera's obstacles hidden from the laser (low boxes, table tops,
    /// overhangs) remembered by odometry and drawn into the scan the policy reads, the
    /// current frame included (0: off, the paper's scan; at most 64). The collision rule
    /// and the reward still read the laser alone. See `ScanMemory`. Written to
    /// `config.toml` only when set.
    #[serde(skip_serializing_if = "is_zero")]
    pub depth_memory_frames: u32,
}

fn is_zero(v: &u32) -> bool {
    *v == 0
}

impl Default for LaserConfig {
    fn default() -> Self {
        Self {
            fov_deg: mdrlat_core::LASER_FOV_DEG,
            height_m: 0.40,
            max_range_m: mdrlat_core::LASER_MAX_RANGE_M,
            noise_std_m: 0.0,
            depth_memory_frames: 0,
        }
    }
}

/// The depth camera (128 x 160 pixels, fixed by the observation layout), Kinect-v1-like.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DepthConfig {
    /// Horizontal field of view, degrees.
    pub hfov_deg: f32,
    /// Vertical field of view, degrees.
    pub vfov_deg: f32,
    /// Height of the optical centre above the floor, metres (zero pitch).
    pub height_m: f32,
    /// Reads closer than this are 0, as the Kinect reports them.
    pub min_range_m: f32,
    /// Reads farther than this are 0 (no return).
    pub max_range_m: f32,
    /// Depth noise: standard deviation at 1 m, growing with depth², metres (0: off).
    pub noise_std_at_1m: f32,
    /// Probability that a pixel drops out (reads 0), per pixel and frame (0: off).
    pub dropout_prob: f32,
}

impl Default for DepthConfig {
    fn default() -> Self {
        Self {
            hfov_deg: mdrlat_core::DEPTH_HFOV_DEG,
            vfov_deg: mdrlat_core::DEPTH_VFOV_DEG,
            height_m: mdrlat_core::DEPTH_HEIGHT_M,
            min_range_m: mdrlat_core::DEPTH_MIN_RANGE_M,
            max_range_m: 10.0,
            noise_std_at_1m: 0.0,
            dropout_prob: 0.0,
        }
    }
}

/// Paper eqs. (3)–(6).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RewardConfig {
    /// Reward of a collision; the episode terminates.
    pub collision: f32,
    /// λ_c of eq. (4).
    pub lambda_c: f32,
    /// λ_d of eq. (5) (negative: a penalty).
    pub lambda_d: f32,
    /// λ_ω of eq. (6) (negative: a penalty).
    pub lambda_w: f32,
    /// d_min below this (metres) is a collision (eq. 4).
    pub collision_range_m: f32,
    /// d_min below this (metres) is penalised as too close (eq. 5).
    pub near_range_m: f32,
}

impl Default for RewardConfig {
    fn default() -> Self {
        Self {
            collision: -10.0,
            lambda_c: 2.0,
            lambda_d: -0.05,
            lambda_w: -0.05,
            collision_range_m: 0.2,
            near_range_m: 0.4,
        }
    }
}

/// A setting that cannot work.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("sim config: {field}: {problem}")]
pub struct ConfigError {
    /// The offending field, e.g. `laser.max_range_m`.
    pub field: &'static str,
    /// What is wrong.
    pub problem: String,
}

impl SimConfig {
    /// Checks every value is usable.
    ///
    /// # Errors
    /// The first field out of range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let positive: [(&'static str, f32); 12] = [
            ("dt_s", self.dt_s),
            ("robot.radius_m", self.robot.radius_m),
            ("robot.body_height_m", self.robot.body_height_m),
            ("robot.max_linear_accel", self.robot.max_linear_accel),
            ("robot.max_angular_accel", self.robot.max_angular_accel),
            ("laser.fov_deg", self.laser.fov_deg),
            ("laser.height_m", self.laser.height_m),
            ("laser.max_range_m", self.laser.max_range_m),
            ("depth.hfov_deg", self.depth.hfov_deg),
            ("depth.vfov_deg", self.depth.vfov_deg),
            ("depth.height_m", self.depth.height_m),
            ("depth.max_range_m", self.depth.max_range_m),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(ConfigError { field, problem: format!("must be positive, got {v}") });
            }
        }
        let non_negative: [(&'static str, f32); 7] = [
            ("laser.noise_std_m", self.laser.noise_std_m),
            ("depth.min_range_m", self.depth.min_range_m),
            ("depth.noise_std_at_1m", self.depth.noise_std_at_1m),
            ("spawn_clearance_m", self.spawn_clearance_m),
            ("spawn_hidden_clearance_m", self.spawn_hidden_clearance_m),
            ("spawn_pedestrian_horizon_s", self.spawn_pedestrian_horizon_s),
            ("reward.collision_range_m", self.reward.collision_range_m),
        ];
        for (field, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(ConfigError { field, problem: format!("must be >= 0, got {v}") });
            }
        }
        if !self.pedestrian_yield_m.is_finite() || self.pedestrian_yield_m > 10.0 {
            return Err(ConfigError {
                field: "pedestrian_yield_m",
                problem: format!(
                    "must be a finite distance up to 10 m (negative: walkers ignore the robot), got {}",
                    self.pedestrian_yield_m
                ),
            });
        }
        if self.spawn_pedestrian_horizon_s > 60.0 {
            return Err(ConfigError {
                field: "spawn_pedestrian_horizon_s",
                problem: format!("must be <= 60 s, got {}", self.spawn_pedestrian_horizon_s),
            });
        }
        if self.substeps == 0 {
            return Err(ConfigError { field: "substeps", problem: "must be at least 1".into() });
        }
        if self.max_episode_steps == 0 {
            return Err(ConfigError {
                field: "max_episode_steps",
                problem: "must be at least 1".into(),
            });
        }
        if self.laser.depth_memory_frames > crate::sensors::MAX_MEMORY_FRAMES {
            return Err(ConfigError {
                field: "laser.depth_memory_frames",
                problem: format!(
                    "must be 0 (off) to {}, got {}",
                    crate::sensors::MAX_MEMORY_FRAMES,
                    self.laser.depth_memory_frames
                ),
            });
        }
        if self.laser.fov_deg > 360.0 {
            return Err(ConfigError {
                field: "laser.fov_deg",
                problem: format!("must be <= 360, got {}", self.laser.fov_deg),
            });
        }
        if self.depth.hfov_deg >= 180.0 || self.depth.vfov_deg >= 180.0 {
            return Err(ConfigError {
                field: "depth.hfov_deg",
                problem: "fields of view must be < 180 degrees".into(),
            });
        }
        if !(0.0..=1.0).contains(&self.depth.dropout_prob) {
            return Err(ConfigError {
                field: "depth.dropout_prob",
                problem: format!("must be in [0, 1], got {}", self.depth.dropout_prob),
            });
        }
        if self.depth.min_range_m >= self.depth.max_range_m {
            return Err(ConfigError {
                field: "depth.min_range_m",
                problem: "must be below depth.max_range_m".into(),
            });
        }
        let r = &self.reward;
        if ![r.collision, r.lambda_c, r.lambda_d, r.lambda_w, r.near_range_m]
            .iter()
            .all(|v| v.is_finite())
        {
            return Err(ConfigError {
                field: "reward",
                problem: "all values must be finite".into(),
            });
        }
        let n = &self.nav;
        if !(n.goal_radius_m.is_finite() && n.goal_radius_m > 0.0) {
            return Err(ConfigError {
                field: "nav.goal_radius_m",
                problem: format!("must be positive, got {}", n.goal_radius_m),
            });
        }
        if !(n.min_start_goal_m.is_finite() && n.min_start_goal_m >= 0.0) {
            return Err(ConfigError {
                field: "nav.min_start_goal_m",
                problem: format!("must be >= 0, got {}", n.min_start_goal_m),
            });
        }
        if !(n.arrival.is_finite() && n.progress.is_finite()) {
            return Err(ConfigError {
                field: "nav",
                problem: "arrival and progress must be finite".into(),
            });
        }
        if n.start.is_some_and(|s| !s.iter().all(|v| v.is_finite())) {
            return Err(ConfigError { field: "nav.start", problem: "must be finite".into() });
        }
        if n.goal.is_some_and(|g| !g.iter().all(|v| v.is_finite())) {
            return Err(ConfigError { field: "nav.goal", problem: "must be finite".into() });
        }
        Ok(())
    }
}
