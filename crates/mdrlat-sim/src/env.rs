//! The environment, Gymnasium-style: `reset(seed)` then `step(action)` returning the
//! observation, the reward, `terminated` and `truncated` (never a merged `done`), and info.

use crate::config::{ConfigError, SimConfig, Task};
use crate::pedestrians::{self, PedestrianState};
use crate::reward::{NavStep, RewardTerms, nav_reward, reward};
use crate::robot::RobotState;
use crate::scene::StaticScene;
use crate::sensors::{DepthCamera, Laser, ScanMemory};
use mdrlat_core::{
    Action, DEPTH_LEN, FRAME_STACK, LASER_BEAMS, ODOM_HISTORY, Rng, Velocity, goal_in_robot_frame,
};
use mdrlat_geom::{GridScratch, Pose2, Prism, Vec2};
use mdrlat_world::World;
use std::sync::Arc;

/// Most time samples of the pedestrians' paths a reset checks.
const SWEEP_SAMPLES: usize = 1024;

/// Attempts at drawing a collision-free reset pose before giving up.
const SPAWN_ATTEMPTS: usize = 10_000;

pub use mdrlat_core::Observation;

/// Why an episode ended in a collision.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Collision {
    /// The footprint touched static obstacle `obstacle` (index in the world file).
    Bumper {
        /// Index of the obstacle.
        obstacle: usize,
    },
    /// Pedestrian `index` and the robot touched.
    Pedestrian {
        /// Index of the pedestrian.
        index: usize,
    },
    /// The smallest laser range fell below the collision range (eq. 4).
    LaserRange,
}

/// Diagnostics of one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepInfo {
    /// Steps taken in this episode, including this one.
    pub step: u32,
    /// Robot pose after the step.
    pub pose: Pose2,
    /// True velocity after the step.
    pub velocity: Velocity,
    /// The commanded velocity (Table 1).
    pub command: Velocity,
    /// Smallest laser range, metres.
    pub d_min: f32,
    /// Set when the step ended in a collision.
    pub collision: Option<Collision>,
    /// The navigation task's robot reached its goal (the episode terminated in success).
    pub reached_goal: bool,
    /// The reward's terms.
    pub reward_terms: RewardTerms,
}

/// The result of [`Env::step`].
#[derive(Debug)]
pub struct Step<'a> {
    /// The observation after the step.
    pub observation: &'a Observation,
    /// Paper eq. (3) (the navigation reward in the navigation task).
    pub reward: f32,
    /// A collision (or, navigating, reaching the goal) ended the episode: do not bootstrap.
    pub terminated: bool,
    /// The time limit ended the episode: bootstrap from `observation`.
    pub truncated: bool,
    /// Diagnostics.
    pub info: StepInfo,
}

/// Errors of the environment.
#[derive(Debug, Clone, thiserror::Error)]
#[non_exhaustive]
pub enum SimError {
    /// The configuration is unusable.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// No collision-free reset pose was found.
    #[error(
        "world '{world}': no collision-free start pose found in {attempts} attempts (spawn regions blocked?)"
    )]
    NoFreePose {
        /// World name.
        world: String,
        /// Attempts made.
        attempts: usize,
    },
    /// `step` was called before `reset` or after the episode ended.
    #[error("step() called on an episode that has ended (or never started): call reset() first")]
    NeedsReset,
    /// A world built in code (not loaded, so not validated) that cannot run.
    #[error("world '{world}': {problem}")]
    InvalidWorld {
        /// World name.
        world: String,
        /// What is wrong.
        problem: String,
    },
    /// The navigation task cannot run in this world with these settings.
    #[error("world '{world}', task nav: {problem}")]
    Nav {
        /// World name.
        world: String,
        /// What is wrong.
        problem: String,
    },
    /// A start pose given to [`Env::reset_with`] that no robot can have.
    #[error("world '{world}': start pose ({x}, {y}, {yaw_deg:.1} deg): {problem}")]
    BadPose {
        /// World name.
        world: String,
        /// The pose given, metres and degrees.
        x: f32,
        /// See `x`.
        y: f32,
        /// See `x`.
        yaw_deg: f32,
        /// What is wrong.
        problem: String,
    },
    /// A VecEnv worker thread stopped (it panicked).
    #[error("a VecEnv worker thread stopped unexpectedly")]
    WorkerDied,
    /// A VecEnv was given the wrong number of actions.
    #[error("expected {expected} actions, got {got}")]
    ActionCount {
        /// Environments.
        expected: usize,
        /// Actions given.
        got: usize,
    },
}

/// The checks `Env` relies on; loaded worlds always pass them (the loader validates more),
/// but `World`'s fields are public and a world built in code may not.
fn check_world(world: &World) -> Result<(), SimError> {
    let bad = |problem: String| Err(SimError::InvalidWorld { world: world.name.clone(), problem });
    if !world.spawn.iter().any(|r| r.area() > 0.0) {
        return bad("no spawn region with positive area".into());
    }
    for (i, p) in world.pedestrians.iter().enumerate() {
        if p.waypoints.len() < 2 || !(p.speed > 0.0 && p.radius > 0.0 && p.height > 0.0) {
            return bad(format!(
                "pedestrian[{i}] needs 2+ waypoints and positive speed, radius and height"
            ));
        }
    }
    Ok(())
}

/// The navigation task's demands on the world: goal regions (or a fixed goal) and a fixed
/// start and goal inside the bounds with room for the robot.
fn check_nav(scene: &StaticScene, config: &SimConfig) -> Result<(), SimError> {
    let world = &scene.world;
    let bad = |problem: String| Err(SimError::Nav { world: world.name.clone(), problem });
    let nav = &config.nav;
    if nav.goal.is_none() && !world.goals.iter().any(|r| r.area() > 0.0) {
        return bad("the world has no goal region (a `goal` key in its file); add one or fix \
                    the goal with --goal X,Y"
            .into());
    }
    let radius = config.robot.radius_m;
    let (mut scratch, mut buf) = (GridScratch::default(), Vec::new());
    let mut check = |what: &str, p: Vec2| -> Result<(), SimError> {
        let b = &world.bounds;
        if !b.contains(p) {
            return bad(format!(
                "{what} ({:.2}, {:.2}) is outside the world's bounds ({:.2}, {:.2})..({:.2}, {:.2})",
                p.x, p.y, b.min.x, b.min.y, b.max.x, b.max.y
            ));
        }
        if let Some(i) = scene.body_contact(p, radius, &mut scratch, &mut buf) {
            let label =
                world.obstacles.get(i).and_then(|o| o.label.as_deref()).unwrap_or("unlabelled");
            return bad(format!(
                "{what} ({:.2}, {:.2}) is inside obstacle {i} ('{label}') or closer to it than \
                 the robot's radius {radius} m",
                p.x, p.y
            ));
        }
        Ok(())
    };
    if let Some([x, y]) = nav.goal {
        check("the goal (--goal, nav.goal)", Vec2::new(x, y))?;
    }
    if let Some([x, y, _]) = nav.start {
        check("the start (--start, nav.start)", Vec2::new(x, y))?;
    }
    Ok(())
}

/// Everything that changes while an environment runs: enough to continue an episode
/// exactly where it was (for training checkpoints). The world and settings are not part of
/// it; restore into an environment built from the same ones.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EnvState {
    /// Robot pose and velocity.
    pub robot: RobotState,
    /// Pedestrian states, in world order.
    pub pedestrians: Vec<PedestrianState>,
    /// Laser frames, oldest first (4 x 512, metres).
    pub laser_frames: Vec<f32>,
    /// Depth frames, oldest first (4 x 128 x 160, metres).
    pub depth_frames: Vec<f32>,
    /// Odometry history.
    pub odom: [Velocity; ODOM_HISTORY],
    /// Spawn and pedestrian stream.
    pub rng: Rng,
    /// Noise stream.
    pub noise_rng: Rng,
    /// Steps into the episode.
    pub steps: u32,
    /// ω of the previous step.
    pub w_prev: f32,
    /// An episode is running.
    pub running: bool,
    /// The navigation task's goal (absent in obstacle avoidance and in older states).
    #[serde(default)]
    pub goal: Option<Vec2>,
    /// The remembered hidden obstacles, oldest frame first, odometry frame
    /// (`sim.laser.depth_memory_frames`; empty when off, and in older states).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub memory: Vec<Vec<Vec2>>,
    /// The smallest range of the laser's own last scan (absent in older states, whose
    /// scans are the laser's own, and when the memory is off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub d_min: Option<f32>,
}

/// One simulated robot in one world.
#[derive(Debug, Clone)]
pub struct Env {
    scene: Arc<StaticScene>,
    config: SimConfig,
    robot: RobotState,
    pedestrians: Vec<PedestrianState>,
    dynamic: Vec<Prism>,
    laser: Laser,
    depth: DepthCamera,
    /// The camera's hidden obstacles drawn into the scan (`sim.laser.depth_memory_frames`).
    memory: Option<ScanMemory>,
    /// The smallest range of the laser's own last scan (the collision rule and the reward
    /// read it, never the remembered points).
    d_min: f32,
    obs: Observation,
    /// Spawn poses and pedestrian starts.
    rng: Rng,
    /// Sensor noise (its own stream: turning noise on never shifts spawn poses).
    noise_rng: Rng,
    steps: u32,
    w_prev: f32,
    running: bool,
    /// The navigation task's goal of this episode.
    goal: Option<Vec2>,
    scratch: GridScratch,
    buf: Vec<u32>,
}

impl Env {
    /// An environment over an indexed scene (shared between environments).
    ///
    /// # Errors
    /// An invalid configuration.
    pub fn new(scene: Arc<StaticScene>, config: SimConfig) -> Result<Self, SimError> {
        config.validate()?;
        check_world(&scene.world)?;
        if config.task == Task::Nav {
            check_nav(&scene, &config)?;
        }
        let laser = Laser::new(&config.laser);
        let depth = DepthCamera::new(&config.depth);
        let memory = ScanMemory::new(
            config.laser.depth_memory_frames,
            laser.angles(),
            depth.geometry(),
            config.laser.max_range_m,
            config.robot.body_height_m,
        );
        Ok(Self {
            laser,
            depth,
            memory,
            d_min: f32::INFINITY,
            scene,
            config,
            robot: RobotState::default(),
            pedestrians: Vec::new(),
            dynamic: Vec::new(),
            obs: Observation::zeros(),
            rng: Rng::seed_from_u64(0),
            noise_rng: Rng::derive(0, 1),
            steps: 0,
            w_prev: 0.0,
            running: false,
            goal: None,
            scratch: GridScratch::default(),
            buf: Vec::new(),
        })
    }

    /// An environment over `world`.
    ///
    /// # Errors
    /// An invalid configuration.
    pub fn from_world(world: World, config: SimConfig) -> Result<Self, SimError> {
        let scene = Arc::new(StaticScene::new(Arc::new(world), &config));
        Self::new(scene, config)
    }

    /// Starts an episode at a random collision-free pose in the spawn regions. `Some(seed)`
    /// reseeds every random stream (the only way to seed); `None` continues the streams.
    ///
    /// # Errors
    /// No collision-free pose could be drawn.
    pub fn reset(&mut self, seed: Option<u64>) -> Result<&Observation, SimError> {
        self.reset_with(seed, None)
    }

    /// Like [`Env::reset`], but starts at `pose` when given (no collision check: used for
    /// fixed evaluation starts and for looking at a chosen pose).
    ///
    /// # Errors
    /// `pose` is not finite or lies outside the world's bounds; no collision-free pose could
    /// be drawn.
    pub fn reset_with(
        &mut self,
        seed: Option<u64>,
        pose: Option<Pose2>,
    ) -> Result<&Observation, SimError> {
        if let Some(p) = pose {
            self.check_pose(p)?;
        }
        if let Some(seed) = seed {
            self.seed_streams(seed, 0);
        }
        self.start_episode(pose)
    }

    /// Resets with stream `stream` of `seed`: environment `i` of a `VecEnv` uses stream `i`,
    /// so runs seeded `s` and `s + 1` share no random numbers. Stream 0 is [`Env::reset`]'s.
    ///
    /// # Errors
    /// No collision-free pose could be drawn.
    pub fn reset_stream(&mut self, seed: u64, stream: u64) -> Result<&Observation, SimError> {
        self.seed_streams(seed, stream);
        self.start_episode(None)
    }

    /// A chosen start pose is finite and inside the world's bounds or a spawn region
    /// ([`World::start_area`](mdrlat_world::World::start_area)); it may overlap an obstacle:
    /// [`Env::reset_with`] does not check collisions.
    fn check_pose(&self, p: Pose2) -> Result<(), SimError> {
        let area = self.scene.world.start_area();
        let problem = if !(p.x.is_finite() && p.y.is_finite() && p.yaw.is_finite()) {
            "not finite".to_string()
        } else if !area.contains(p.position()) {
            format!(
                "outside the world (its bounds and spawn regions), x {} to {} m, y {} to {} m",
                area.min.x, area.max.x, area.min.y, area.max.y
            )
        } else {
            return Ok(());
        };
        Err(SimError::BadPose {
            world: self.scene.world.name.clone(),
            x: p.x,
            y: p.y,
            yaw_deg: p.yaw.to_degrees(),
            problem,
        })
    }

    fn seed_streams(&mut self, seed: u64, stream: u64) {
        self.rng = Rng::derive(seed, 2 * stream);
        self.noise_rng = Rng::derive(seed, 2 * stream + 1);
    }

    fn start_episode(&mut self, pose: Option<Pose2>) -> Result<&Observation, SimError> {
        self.pedestrians = pedestrians::reset(&self.scene.world.pedestrians, &mut self.rng);
        let nav = (self.config.task == Task::Nav).then(|| self.config.nav.clone());
        let pose = match (pose, nav.as_ref().and_then(|n| n.start)) {
            (Some(p), _) => p,
            (None, Some([x, y, yaw_deg])) => Pose2::new(x, y, yaw_deg.to_radians()),
            (None, None) => self.sample_pose()?,
        };
        // Obstacle avoidance draws nothing more: its streams are what they always were.
        self.goal = match nav.map(|n| n.goal) {
            None => None,
            Some(Some([x, y])) => Some(Vec2::new(x, y)),
            Some(None) => Some(self.sample_goal(pose.position())?),
        };
        self.robot = RobotState { pose, velocity: Velocity::default() };
        self.steps = 0;
        self.w_prev = 0.0;
        self.obs.odom = [Velocity::default(); ODOM_HISTORY];
        if let Some(memory) = &mut self.memory {
            memory.clear();
        }
        self.sense();
        self.obs.laser.fill_with_latest();
        self.obs.depth.fill_with_latest();
        self.running = true;
        Ok(&self.obs)
    }

    /// Where each pedestrian will be at every physics sub-step of the next
    /// `spawn_pedestrian_horizon_s` seconds (now included): `(centre, radius)`. Pedestrians
    /// who ignore the robot walk these paths, and yielding walkers never come closer to it,
    /// so the sweep is known before a pose is drawn.
    fn pedestrian_sweep(&self) -> Vec<(Vec2, f32)> {
        let specs = &self.scene.world.pedestrians;
        // The physics sub-step, or coarser for settings that would sample more than
        // SWEEP_SAMPLES times (pedestrians walk straight between waypoints, so a sample
        // misses at most speed x step of a path).
        let horizon = self.config.spawn_pedestrian_horizon_s;
        let mut sub_dt = self.config.dt_s / self.config.substeps as f32;
        if horizon / sub_dt > SWEEP_SAMPLES as f32 {
            sub_dt = horizon / SWEEP_SAMPLES as f32;
        }
        let n = ((horizon / sub_dt).ceil() as usize).min(SWEEP_SAMPLES);
        let mut states = self.pedestrians.clone();
        let mut sweep = Vec::with_capacity((n + 1) * states.len());
        for k in 0..=n {
            if k > 0 {
                pedestrians::advance(specs, &mut states, None, sub_dt);
            }
            sweep.extend(states.iter().zip(specs).map(|(st, spec)| (st.position, spec.radius)));
        }
        sweep
    }

    fn sample_pose(&mut self) -> Result<Pose2, SimError> {
        let sweep = self.pedestrian_sweep();
        let world = &self.scene.world;
        let total: f32 = world.spawn.iter().map(|r| r.area()).sum();
        let clearance = self.config.robot.radius_m + self.config.spawn_clearance_m;
        for _ in 0..SPAWN_ATTEMPTS {
            let mut pick = self.rng.uniform() as f32 * total;
            let Some(region) = world
                .spawn
                .iter()
                .find(|r| {
                    pick -= r.area();
                    pick <= 0.0
                })
                .or(world.spawn.last())
            else {
                break;
            };
            let p = Vec2::new(
                self.rng.range_f32(region.min.x, region.max.x),
                self.rng.range_f32(region.min.y, region.max.y),
            );
            let yaw = self.rng.range_f32(-std::f32::consts::PI, std::f32::consts::PI);
            let blocked_static =
                self.scene.body_contact(p, clearance, &mut self.scratch, &mut self.buf).is_some()
                    || self
                        .scene
                        .hidden_contact(
                            p,
                            clearance + self.config.spawn_hidden_clearance_m,
                            self.config.laser.height_m,
                            &mut self.scratch,
                            &mut self.buf,
                        )
                        .is_some();
            let blocked_ped =
                sweep.iter().any(|&(centre, radius)| (centre - p).length() < clearance + radius);
            if !blocked_static && !blocked_ped {
                return Ok(Pose2::new(p.x, p.y, yaw));
            }
        }
        Err(SimError::NoFreePose { world: world.name.clone(), attempts: SPAWN_ATTEMPTS })
    }

    /// A goal in the goal regions (area-weighted, uniform within a region) where the robot
    /// fits with the spawn clearance, at least `nav.min_start_goal_m` from `start`.
    fn sample_goal(&mut self, start: Vec2) -> Result<Vec2, SimError> {
        let world = &self.scene.world;
        let total: f32 = world.goals.iter().map(|r| r.area()).sum();
        let clearance = self.config.robot.radius_m + self.config.spawn_clearance_m;
        let min_distance = self.config.nav.min_start_goal_m;
        for _ in 0..SPAWN_ATTEMPTS {
            let mut pick = self.rng.uniform() as f32 * total;
            let Some(region) = world
                .goals
                .iter()
                .find(|r| {
                    pick -= r.area();
                    pick <= 0.0
                })
                .or(world.goals.last())
            else {
                break;
            };
            let p = Vec2::new(
                self.rng.range_f32(region.min.x, region.max.x),
                self.rng.range_f32(region.min.y, region.max.y),
            );
            if (p - start).length() >= min_distance
                && self.scene.body_contact(p, clearance, &mut self.scratch, &mut self.buf).is_none()
            {
                return Ok(p);
            }
        }
        Err(SimError::Nav {
            world: world.name.clone(),
            problem: format!(
                "no free goal at least {min_distance} m (nav.min_start_goal_m) from the start \
                 ({:.2}, {:.2}) in {SPAWN_ATTEMPTS} attempts",
                start.x, start.y
            ),
        })
    }

    /// Renders both sensors at the current state into the next frame slots.
    fn sense(&mut self) {
        pedestrians::write_prisms(
            &self.scene.world.pedestrians,
            &self.pedestrians,
            &mut self.dynamic,
        );
        let pose = self.robot.pose;
        self.laser.scan(
            &self.scene,
            &self.dynamic,
            &pose,
            &mut self.noise_rng,
            self.obs.laser.push_slot(),
        );
        self.depth.capture(
            &self.scene,
            &self.dynamic,
            &pose,
            &mut self.noise_rng,
            self.obs.depth.push_slot(),
        );
        self.d_min = self.obs.laser.latest().iter().copied().fold(f32::INFINITY, f32::min);
        if let Some(memory) = &mut self.memory {
            let odom = [pose.x, pose.y, pose.yaw];
            memory.update(odom, self.obs.depth.latest(), self.obs.laser.latest_mut());
        }
        self.obs.goal = self.goal.map(|g| goal_in_robot_frame(pose.x, pose.y, pose.yaw, g.x, g.y));
        self.obs.pose = Some([pose.x, pose.y, pose.yaw]);
    }

    fn contact(&mut self) -> Option<Collision> {
        let p = self.robot.pose.position();
        let r = self.config.robot.radius_m;
        if let Some(obstacle) = self.scene.body_contact(p, r, &mut self.scratch, &mut self.buf) {
            return Some(Collision::Bumper { obstacle });
        }
        let specs = &self.scene.world.pedestrians;
        self.pedestrians
            .iter()
            .zip(specs)
            .position(|(st, spec)| (st.position - p).length() < r + spec.radius)
            .map(|index| Collision::Pedestrian { index })
    }

    /// Applies `action` for one control period (0.2 s).
    ///
    /// # Errors
    /// [`SimError::NeedsReset`] before the first reset or after the episode ended.
    pub fn step(&mut self, action: Action) -> Result<Step<'_>, SimError> {
        self.step_command(action.command())
    }

    /// Applies an arbitrary velocity command for one control period, as a robot base does
    /// with `/cmd_vel` (`mdrlat ros-sim`); the acceleration limits still apply.
    ///
    /// # Errors
    /// [`SimError::NeedsReset`] before the first reset or after the episode ended.
    pub fn step_command(&mut self, command: Velocity) -> Result<Step<'_>, SimError> {
        if !self.running {
            return Err(SimError::NeedsReset);
        }
        let start = self.robot.pose.position();
        let sub_dt = self.config.dt_s / self.config.substeps as f32;
        let mut collision = None;
        for _ in 0..self.config.substeps {
            let keepout = (self.config.pedestrian_yield_m >= 0.0).then(|| pedestrians::Keepout {
                center: self.robot.pose.position(),
                radius: self.config.robot.radius_m + self.config.pedestrian_yield_m,
            });
            pedestrians::advance(
                &self.scene.world.pedestrians,
                &mut self.pedestrians,
                keepout,
                sub_dt,
            );
            self.robot.advance(command, &self.config.robot, sub_dt);
            collision = self.contact();
            if collision.is_some() {
                break;
            }
        }
        self.sense();
        let d_min = self.d_min;
        if collision.is_none() && d_min < self.config.reward.collision_range_m {
            collision = Some(Collision::LaserRange);
        }
        let velocity = self.robot.velocity;
        self.obs.odom.rotate_left(1);
        self.obs.odom[ODOM_HISTORY - 1] = velocity;
        let mut reached_goal = false;
        let terms = match self.goal {
            None => reward(&self.config.reward, collision.is_some(), velocity, self.w_prev, d_min),
            Some(goal) => {
                let distance = (goal - self.robot.pose.position()).length();
                reached_goal = collision.is_none() && distance <= self.config.nav.goal_radius_m;
                let progress_m = (goal - start).length() - distance;
                let step = NavStep {
                    collided: collision.is_some(),
                    reached: reached_goal,
                    w: velocity.w,
                    w_prev: self.w_prev,
                    d_min,
                    progress_m,
                };
                nav_reward(&self.config.reward, &self.config.nav, step)
            }
        };
        self.w_prev = velocity.w;
        self.steps += 1;
        let terminated = collision.is_some() || reached_goal;
        let truncated = !terminated && self.steps >= self.config.max_episode_steps;
        self.running = !(terminated || truncated);
        Ok(Step {
            observation: &self.obs,
            reward: terms.total(),
            terminated,
            truncated,
            info: StepInfo {
                step: self.steps,
                pose: self.robot.pose,
                velocity,
                command,
                d_min,
                collision,
                reached_goal,
                reward_terms: terms,
            },
        })
    }

    /// Moves the environment to another world, with the same settings and random streams,
    /// and starts an episode there (as [`Env::reset`] with no seed): training on several
    /// worlds changes world at an episode's end.
    ///
    /// # Errors
    /// The world cannot be simulated, or no start pose is free.
    pub fn move_to(&mut self, scene: Arc<StaticScene>) -> Result<&Observation, SimError> {
        let mut next = Env::new(scene, self.config.clone())?;
        next.rng = self.rng.clone();
        next.noise_rng = self.noise_rng.clone();
        *self = next;
        self.reset(None)
    }

    /// The environment's changing state (see [`EnvState`]).
    pub fn state(&self) -> EnvState {
        EnvState {
            robot: self.robot,
            pedestrians: self.pedestrians.clone(),
            laser_frames: self.obs.laser.to_stacked_vec(),
            depth_frames: self.obs.depth.to_stacked_vec(),
            odom: self.obs.odom,
            rng: self.rng.clone(),
            noise_rng: self.noise_rng.clone(),
            steps: self.steps,
            w_prev: self.w_prev,
            running: self.running,
            goal: self.goal,
            memory: self
                .memory
                .as_ref()
                .map(|m| {
                    let frame = |f: &[[f32; 2]]| f.iter().map(|&[x, y]| Vec2::new(x, y)).collect();
                    m.frames().map(frame).collect()
                })
                .unwrap_or_default(),
            d_min: self.memory.is_some().then_some(self.d_min),
        }
    }

    /// Continues from a saved state.
    ///
    /// # Errors
    /// The state does not fit this world (pedestrian count) or the frame sizes are wrong.
    pub fn restore(&mut self, state: &EnvState) -> Result<(), SimError> {
        let bad = |problem: String| SimError::InvalidWorld {
            world: self.scene.world.name.clone(),
            problem,
        };
        if state.pedestrians.len() != self.scene.world.pedestrians.len() {
            return Err(bad(format!(
                "saved state has {} pedestrians, the world {}",
                state.pedestrians.len(),
                self.scene.world.pedestrians.len()
            )));
        }
        let n = self.scene.world.pedestrians.iter().map(|p| p.waypoints.len());
        if state.pedestrians.iter().zip(n).any(|(p, n)| p.target >= n) {
            return Err(bad("saved pedestrian state names a waypoint the world lacks".into()));
        }
        if (self.config.task == Task::Nav) != state.goal.is_some() {
            return Err(bad(format!(
                "saved state is of the {} task, this environment runs {}",
                if state.goal.is_some() { "nav" } else { "avoid" },
                self.config.task
            )));
        }
        if state.laser_frames.len() != FRAME_STACK * LASER_BEAMS
            || state.depth_frames.len() != FRAME_STACK * DEPTH_LEN
        {
            return Err(bad("saved frames have the wrong size".into()));
        }
        for (stack, frames) in
            [(&mut self.obs.laser, &state.laser_frames), (&mut self.obs.depth, &state.depth_frames)]
        {
            for frame in frames.chunks_exact(stack.frame_len()) {
                stack.push_slot().copy_from_slice(frame);
            }
        }
        self.robot = state.robot;
        self.pedestrians = state.pedestrians.clone();
        self.obs.odom = state.odom;
        self.rng = state.rng.clone();
        self.noise_rng = state.noise_rng.clone();
        self.steps = state.steps;
        self.w_prev = state.w_prev;
        self.running = state.running;
        self.goal = state.goal;
        self.d_min = state.d_min.unwrap_or_else(|| {
            self.obs.laser.latest().iter().copied().fold(f32::INFINITY, f32::min)
        });
        if let Some(memory) = &mut self.memory {
            let frame = |f: &Vec<Vec2>| f.iter().map(|p| [p.x, p.y]).collect();
            memory.restore(state.memory.iter().map(frame));
        }
        let pose = self.robot.pose;
        self.obs.goal = self.goal.map(|g| goal_in_robot_frame(pose.x, pose.y, pose.yaw, g.x, g.y));
        self.obs.pose = Some([pose.x, pose.y, pose.yaw]);
        Ok(())
    }

    /// The smallest range of the laser's own last scan, metres: what the collision rule
    /// and the reward read. It equals the smallest range of the observation's scan unless
    /// the camera's memory (`sim.laser.depth_memory_frames`) drew nearer points into it.
    pub fn laser_d_min(&self) -> f32 {
        self.d_min
    }

    /// The current observation.
    pub fn observation(&self) -> &Observation {
        &self.obs
    }

    /// Swaps the current observation with `other` (used by `VecEnv` to keep a final
    /// observation without copying frames).
    pub(crate) fn swap_observation(&mut self, other: &mut Observation) {
        std::mem::swap(&mut self.obs, other);
    }

    /// The robot's pose.
    pub fn pose(&self) -> Pose2 {
        self.robot.pose
    }

    /// Pedestrian centres, radii and heights, for pictures.
    pub fn pedestrian_discs(&self) -> Vec<(Vec2, f32, f32)> {
        self.pedestrians
            .iter()
            .zip(&self.scene.world.pedestrians)
            .map(|(st, spec)| (st.position, spec.radius, spec.height))
            .collect()
    }

    /// The world.
    pub fn world(&self) -> &World {
        &self.scene.world
    }

    /// The indexed scene.
    pub fn scene(&self) -> &Arc<StaticScene> {
        &self.scene
    }

    /// The settings.
    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// The laser (beam angles, settings).
    pub fn laser(&self) -> &Laser {
        &self.laser
    }

    /// The depth camera (column angles, settings).
    pub fn depth_camera(&self) -> &DepthCamera {
        &self.depth
    }

    /// Steps taken in the current episode.
    pub fn episode_steps(&self) -> u32 {
        self.steps
    }

    /// The navigation task's goal of the current episode (`None` in obstacle avoidance).
    pub fn goal(&self) -> Option<Vec2> {
        self.goal
    }
}
