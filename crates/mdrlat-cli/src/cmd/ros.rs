//! `mdrlat ros` (the policy as a ROS 1 node) and `mdrlat ros-sim` (the simulator as a
//! turtlebot2 over ROS).

use super::train::DeviceKind;
use super::{ensure_parent, load_world, make_env, px_per_m, snapshot};
use crate::config::Config;
use anyhow::{Context, Result, bail};
use mdrlat_geom::Vec2;
use mdrlat_nn::Variant;
use mdrlat_ros::msg::{Image, LaserScan, Odometry, Twist};
use mdrlat_ros::robot;
use mdrlat_ros::{ControllerConfig, NodeConfig, NonFinite, ScanOptions, Trigger};
use mdrlat_sim::bridge::{
    BridgeObserver, BridgeSettings, BridgeStep, Received, SensorFrame, Transport,
};
use mdrlat_sim::config::Task;
use mdrlat_train::GreedyPolicy;
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// How to reach the ROS master, shared by the ROS subcommands.
#[derive(Debug, Clone, clap::Args)]
pub struct Connection {
    /// ROS master URI (default: $ROS_MASTER_URI, else http://localhost:11311/).
    #[arg(long)]
    pub master: Option<String>,
    /// Host name or IP other nodes reach this one at (default: $ROS_HOSTNAME, $ROS_IP, else
    /// the machine's host name).
    #[arg(long)]
    pub host: Option<String>,
}

impl Connection {
    fn master(&self) -> String {
        self.master.clone().unwrap_or_else(mdrlat_ros::node::master_from_env)
    }
    fn host(&self) -> String {
        self.host.clone().unwrap_or_else(mdrlat_ros::node::host_from_env)
    }
}

/// Topic names, shared by `ros` and `ros-sim` so that their defaults always match.
#[derive(Debug, Clone, clap::Args)]
pub struct Topics {
    /// sensor_msgs/LaserScan topic.
    #[arg(long, default_value = "/scan")]
    pub scan_topic: String,
    /// sensor_msgs/Image depth topic (32FC1 metres or 16UC1 millimetres).
    #[arg(long, default_value = "/camera/depth/image_raw")]
    pub depth_topic: String,
    /// nav_msgs/Odometry topic.
    #[arg(long, default_value = "/odom")]
    pub odom_topic: String,
    /// geometry_msgs/Twist velocity command topic.
    #[arg(long, default_value = "/cmd_vel")]
    pub cmd_topic: String,
}

/// Reading non-finite laser ranges.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ScanInf {
    /// Any NaN or inf makes the scan malformed: zero velocity until a clean scan.
    Reject,
    /// REP 117: +inf = no return (reads max range), -inf = too close (reads 0); NaN rejected.
    Rep117,
}

/// When `mdrlat ros` decides.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum TriggerKind {
    /// On a fixed clock at --rate-hz.
    Timer,
    /// On each new scan, not sooner than 0.9 / --rate-hz after the last decision (lowest
    /// latency).
    Scan,
}

/// The policy node's arguments, the same for `mdrlat ros` and `mdrlat ros2`.
#[derive(Debug, clap::Args)]
pub struct NodeArgs {
    /// The trained policy: a run directory (uses its checkpoint) or a checkpoint folder.
    #[arg(long, required_unless_present = "untrained", conflicts_with = "untrained")]
    pub checkpoint: Option<PathBuf>,
    /// Drive with a randomly initialised network instead (for testing the set-up before
    /// any training; it does not avoid anything).
    #[arg(long)]
    pub untrained: bool,
    /// Network variant of --untrained.
    #[arg(long, default_value = "mdrlat", requires = "untrained")]
    pub variant: Variant,
    /// Seed of --untrained.
    #[arg(long, default_value_t = 0, requires = "untrained")]
    pub seed: u64,
    /// Node name.
    #[arg(long, default_value = "/mdrlat")]
    pub name: String,
    #[command(flatten)]
    pub topics: Topics,
    /// Do not subscribe to odometry (by default a silent base stops the robot).
    #[arg(long)]
    pub no_odom: bool,
    /// Velocity commands per second (the policy was trained at 5).
    #[arg(long, default_value_t = 5.0)]
    pub rate_hz: f32,
    /// When to decide.
    #[arg(long, value_enum, default_value = "timer")]
    pub trigger: TriggerKind,
    /// A sensor older than this (seconds) stops the robot.
    #[arg(long, default_value_t = 0.5)]
    pub stale_after_s: f32,
    /// Linear speed limit, m/s (clamped to Table 1's 0.5).
    #[arg(long, default_value_t = 0.5)]
    pub max_linear: f32,
    /// Angular speed limit, rad/s (clamped to Table 1's π/3).
    #[arg(long, default_value_t = std::f32::consts::FRAC_PI_3)]
    pub max_angular: f32,
    /// Non-finite laser ranges.
    #[arg(long, value_enum, default_value = "reject")]
    pub scan_inf: ScanInf,
    /// The laser's yaw on the robot, degrees (180 for a laser mounted backwards, as RPLIDARs
    /// often are): beam angles are turned by it so that 0° is the robot's heading.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub scan_yaw_deg: f32,
    /// Read the part of the 270° fan a scan does not cover as free space instead of refusing
    /// the scan. Dangerous: only for lasers that cannot see behind the robot's sides.
    #[arg(long)]
    pub fill_scan_gaps: bool,
    /// Write every tick (time, driving, action, command, odometry) to this CSV file.
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Compute device.
    #[arg(long, value_enum, default_value = "cpu")]
    pub device: DeviceKind,
    /// CPU threads for inference (1: one core, as measured for the robot).
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Opt-in: the network's linear layers read bfloat16 weights (half the memory traffic,
    /// so a faster decision: docs/performance.md); decisions may differ from f32 where two
    /// actions' Q-values nearly tie. Needs AVX-512.
    #[arg(long)]
    pub bf16: bool,
}

/// Arguments of `mdrlat ros`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub connection: Connection,
    #[command(flatten)]
    pub node: NodeArgs,
}

/// SIGINT and SIGTERM set the returned flag (instead of killing the process), so a node can
/// stop its robot before exiting, and a training run can write its checkpoint; a second one
/// exits at once (status 130).
pub fn stop_flag() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        // Registered first, so the first signal finds the flag unset and only sets it.
        signal_hook::flag::register_conditional_shutdown(signal, 130, stop.clone())
            .and_then(|_| signal_hook::flag::register(signal, stop.clone()))
            .with_context(|| format!("cannot handle signal {signal}"))?;
    }
    Ok(stop)
}

/// One log line of a node (`tag`: `ros`, `ros2`), stamped with the wall clock.
pub fn log_line(tag: &str, line: &str) {
    let t = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0);
    eprintln!("[mdrlat {tag} {t:.3}] {line}");
}

/// Builds the node configuration from the policy node's arguments.
fn node_config(a: &NodeArgs) -> Result<NodeConfig> {
    if !(a.rate_hz.is_finite() && a.rate_hz > 0.0 && a.rate_hz <= 100.0) {
        bail!("--rate-hz {}: expected a rate in (0, 100]", a.rate_hz);
    }
    if !(a.stale_after_s.is_finite() && a.stale_after_s > 0.0 && a.stale_after_s <= 60.0) {
        bail!("--stale-after-s {}: expected seconds in (0, 60]", a.stale_after_s);
    }
    if !(a.scan_yaw_deg.is_finite() && a.scan_yaw_deg.abs() <= 360.0) {
        bail!("--scan-yaw-deg {}: expected degrees in [-360, 360]", a.scan_yaw_deg);
    }
    for (flag, v) in [("--max-linear", a.max_linear), ("--max-angular", a.max_angular)] {
        if !(v.is_finite() && v >= 0.0) {
            bail!("{flag} {v}: expected a non-negative number");
        }
    }
    Ok(NodeConfig {
        name: a.name.clone(),
        scan_topic: a.topics.scan_topic.clone(),
        depth_topic: a.topics.depth_topic.clone(),
        odom_topic: a.topics.odom_topic.clone(),
        cmd_topic: a.topics.cmd_topic.clone(),
        rate_hz: a.rate_hz,
        trigger: match a.trigger {
            TriggerKind::Timer => Trigger::Timer,
            TriggerKind::Scan => Trigger::Scan,
        },
        controller: ControllerConfig {
            stale_after: Duration::from_secs_f32(a.stale_after_s),
            require_odom: !a.no_odom,
            max_linear_mps: a.max_linear,
            max_angular_radps: a.max_angular,
            scan: ScanOptions {
                yaw_offset: a.scan_yaw_deg.to_radians(),
                non_finite: match a.scan_inf {
                    ScanInf::Reject => NonFinite::Reject,
                    ScanInf::Rep117 => NonFinite::Rep117,
                },
                fill_gaps: a.fill_scan_gaps,
            },
        },
        log_csv: a.log.clone(),
    })
}

/// `mdrlat ros`.
pub fn run(a: &Args) -> Result<()> {
    run_node(&a.node, "ros", || {
        Ok(mdrlat_ros::Ros1::connect(&a.node.name, &a.connection.master(), &a.connection.host())?)
    })
}

/// Runs the policy node of `a` on the transport `connect` opens (`tag` names the command in
/// log lines): the checks and the policy first, so a bad flag or checkpoint never reaches
/// the middleware.
pub fn run_node<T: mdrlat_ros::Transport>(
    a: &NodeArgs,
    tag: &str,
    connect: impl FnOnce() -> Result<T>,
) -> Result<()> {
    let config = node_config(a)?;
    if let Some(log) = &config.log_csv {
        ensure_parent(log)?;
    }
    let device = a.device.device();
    let mut policy = match &a.checkpoint {
        Some(path) => GreedyPolicy::load(path, &device, a.threads)
            .map_err(anyhow::Error::msg)
            .context("loading the policy")?,
        None => GreedyPolicy::untrained(a.variant, Task::Avoid, a.seed, &device, a.threads)
            .map_err(anyhow::Error::msg)?,
    };
    // The node avoids obstacles; it has no goal to give a navigation network.
    if let Some(path) = &a.checkpoint
        && policy.task() != Task::Avoid
    {
        bail!(
            "--checkpoint {}: a {} network trained for navigation (a goal input); the ROS node \
             runs obstacle avoidance and has no goal to give it",
            path.display(),
            policy.variant()
        );
    }
    if a.bf16 {
        policy = policy.with_bf16_weights().map_err(anyhow::Error::msg).context("--bf16")?;
    }
    let log = |line: &str| log_line(tag, line);
    log(&format!(
        "policy: {} network, {} ({} on {} thread(s))",
        policy.variant(),
        policy.source(),
        a.device.name(),
        a.threads
    ));
    let stop = stop_flag()?;
    let mut transport = connect()?;
    let summary = mdrlat_ros::run(&mut transport, &config, Box::new(policy), &stop, &log)?;
    log(&format!("exited after {:.1} s", summary.seconds));
    Ok(())
}

/// Depth encodings `ros-sim` can publish.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DepthEncoding {
    /// float32 metres, NaN-free, 0 = no reading (as the simulator).
    #[value(name = "32FC1")]
    F32,
    /// uint16 millimetres, 0 = no reading (as the Kinect's openni driver).
    #[value(name = "16UC1")]
    U16,
}

impl From<DepthEncoding> for robot::DepthEncoding {
    fn from(e: DepthEncoding) -> Self {
        match e {
            DepthEncoding::F32 => robot::DepthEncoding::F32,
            DepthEncoding::U16 => robot::DepthEncoding::U16,
        }
    }
}

/// The simulated robot's arguments, the same for `mdrlat ros-sim` and `mdrlat ros2-sim`.
#[derive(Debug, clap::Args)]
pub struct SimRobotArgs {
    /// World: a built-in name, a world .toml or a map_server .yaml.
    #[arg(long, default_value = "train")]
    pub world: String,
    /// Seed of the start poses and pedestrians.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Configuration file (its [sim] table; see `mdrlat config default`).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Node name.
    #[arg(long, default_value = "/mdrlat_sim")]
    pub name: String,
    #[command(flatten)]
    pub topics: Topics,
    /// Depth image encoding.
    #[arg(long, value_enum, default_value = "32FC1")]
    pub depth_encoding: DepthEncoding,
    /// A velocity command older than this (seconds) is dropped and the robot brakes, as a
    /// Kobuki base does (commands are also clamped to its 0.7 m/s and 180°/s).
    #[arg(long, default_value_t = 0.5)]
    pub cmd_timeout_s: f32,
    /// Simulated seconds per wall-clock second (a policy node deciding at 5 Hz of wall time
    /// then acts every speed × 0.2 s of simulated time: keep 1 for a faithful test).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f32,
    /// Stop after this many wall-clock seconds (0: run until Ctrl-C).
    #[arg(long, default_value_t = 0.0)]
    pub duration_s: f32,
    /// Steps after which an episode restarts from a new pose (0: only on collisions).
    #[arg(long, default_value_t = 0)]
    pub episode_steps: u32,
    /// Write the trajectory (one row per step) to this CSV file.
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Draw the longest episode from above with its trail into this PNG at exit.
    #[arg(long)]
    pub picture: Option<PathBuf>,
}

/// Arguments of `mdrlat ros-sim`.
#[derive(Debug, clap::Args)]
pub struct SimArgs {
    #[command(flatten)]
    pub connection: Connection,
    #[command(flatten)]
    pub robot: SimRobotArgs,
}

/// `mdrlat ros-sim`: the simulator's bridge ([`mdrlat_sim::bridge`]) on ROS 1.
pub fn sim(a: &SimArgs) -> Result<()> {
    let r = &a.robot;
    run_sim(r, "ros-sim", |stop| {
        let node = mdrlat_ros::Node::new(&r.name, &a.connection.master(), &a.connection.host())?;
        let last = Arc::new(Mutex::new(LastCommand::default()));
        {
            let last = last.clone();
            node.subscribe::<Twist>(&r.topics.cmd_topic, move |msg| {
                lock(&last).set(msg.map(|t| (t.linear.x, t.angular.z)).ok());
            })?;
        }
        Ok(RosRobot {
            scan: node.advertise::<LaserScan>(&r.topics.scan_topic, false)?,
            depth: node.advertise::<Image>(&r.topics.depth_topic, false)?,
            odom: node.advertise::<Odometry>(&r.topics.odom_topic, false)?,
            encoding: r.depth_encoding.into(),
            last,
            node,
            stop,
        })
    })
}

/// The simulated robot's side of a middleware: [`Transport`] plus what `run_sim` reports.
pub trait SimRobot: Transport {
    /// Where it runs, for the start-up line.
    fn describe(&self) -> String;
    /// Velocity commands that could not be decoded.
    fn malformed(&self) -> u64;
    /// Leaves the graph.
    fn shutdown(&mut self);
}

/// Runs the simulator of `a` as a robot on the middleware `connect` opens (given the
/// SIGINT/SIGTERM flag), `tag` naming the command in its lines.
pub fn run_sim<T: SimRobot>(
    a: &SimRobotArgs,
    tag: &str,
    connect: impl FnOnce(Arc<AtomicBool>) -> Result<T>,
) -> Result<()> {
    let settings = BridgeSettings {
        seed: a.seed,
        cmd_timeout_s: a.cmd_timeout_s,
        speed: a.speed,
        duration_s: a.duration_s,
    };
    if let Err(e) = settings.validate() {
        // The field first, as its flag: `cmd_timeout_s 0: …` → `--cmd-timeout-s 0: …`.
        let (field, rest) = e.split_once(' ').unwrap_or((&e, ""));
        bail!("--{} {rest}", field.replace('_', "-"));
    }
    let mut config = Config::load_or_default(a.config.as_deref())?.sim;
    config.max_episode_steps = if a.episode_steps == 0 { u32::MAX } else { a.episode_steps };
    // The simulated robot publishes what its sensors give: the laser's own scan. A policy
    // node that reads the camera's memory draws it itself, as on a robot.
    config.laser.depth_memory_frames = 0;
    let world = load_world(&a.world)?;
    let mut env = make_env(world, &config)?;
    for path in [&a.log, &a.picture].into_iter().flatten() {
        ensure_parent(path)?;
    }
    let mut seen = SimLog {
        csv: match &a.log {
            Some(p) => {
                let mut f = std::io::BufWriter::new(
                    std::fs::File::create(p)
                        .with_context(|| format!("cannot create {}", p.display()))?,
                );
                writeln!(f, "t_s,episode,step,x,y,yaw,v,w,cmd_v,cmd_w,d_min,reward,collision")?;
                Some((p.clone(), f))
            }
            None => None,
        },
        picture: a.picture.is_some(),
        tag: tag.to_string(),
        best: (0, None),
        scale: px_per_m(env.world(), 640.0),
    };
    let stop = stop_flag()?;
    let mut transport = connect(stop)?;
    eprintln!(
        "[mdrlat {tag}] world {} on {}: publishing {}, {} ({}), {}; driving from {}",
        env.world().name,
        transport.describe(),
        a.topics.scan_topic,
        a.topics.depth_topic,
        robot::DepthEncoding::from(a.depth_encoding).name(),
        a.topics.odom_topic,
        a.topics.cmd_topic
    );
    let summary = mdrlat_sim::bridge::run(&mut env, &settings, &mut transport, &mut seen)?;
    if let Some((path, f)) = &mut seen.csv {
        f.flush().with_context(|| format!("writing {}", path.display()))?;
    }
    if let (Some(p), Some(image)) = (&a.picture, &seen.best.1) {
        image.save_png(p)?;
    }
    let malformed = transport.malformed();
    out!(
        "{{\"{}\":\"{}\",\"steps\":{},\"episodes\":{},\"collisions\":{},\"distance_m\":{:.3},\"malformed_cmd\":{malformed},\"seconds\":{:.2}}}",
        tag.replace('-', "_"),
        env.world().name,
        summary.steps,
        summary.episodes,
        summary.collisions,
        summary.distance_m,
        summary.seconds
    );
    transport.shutdown();
    Ok(())
}

/// The latest `/cmd_vel` and how many could not be decoded.
#[derive(Debug, Default)]
pub struct LastCommand {
    received: Option<Received>,
    malformed: u64,
}

impl LastCommand {
    /// The latest command.
    pub fn received(&self) -> Option<Received> {
        self.received
    }
    /// Commands that could not be decoded.
    pub fn malformed(&self) -> u64 {
        self.malformed
    }
    /// Records one message: its (v, ω), or `None` if it could not be decoded.
    pub fn set(&mut self, command: Option<(f64, f64)>) {
        match command {
            Some((v, w)) => self.received = Some(Received { v, w, at: Instant::now() }),
            None => self.malformed += 1,
        }
    }
}

/// Locks `m`, also after a panic elsewhere poisoned it.
pub fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The readings of a bridge frame, as the robot model (`mdrlat_ros::robot`) takes them.
pub fn readings<'a>(f: &SensorFrame<'a>) -> robot::Readings<'a> {
    robot::Readings {
        ranges: f.ranges,
        range_max_m: f.range_max_m,
        depth: f.depth,
        pose: [f.pose.x, f.pose.y, f.pose.yaw],
        velocity: [f.velocity.v, f.velocity.w],
        scan_time_s: f.dt_s,
        seq: f.seq,
    }
}

/// The bridge's transport on ROS 1: the sensor topics out, `/cmd_vel` in.
struct RosRobot {
    scan: mdrlat_ros::Publisher<LaserScan>,
    depth: mdrlat_ros::Publisher<Image>,
    odom: mdrlat_ros::Publisher<Odometry>,
    encoding: robot::DepthEncoding,
    last: Arc<Mutex<LastCommand>>,
    node: mdrlat_ros::Node,
    stop: Arc<AtomicBool>,
}

impl Transport for RosRobot {
    fn latest_command(&mut self) -> Option<Received> {
        lock(&self.last).received()
    }
    fn publish(&mut self, f: &SensorFrame<'_>) {
        let (scan, depth, odom) = robot::messages(&readings(f), self.encoding);
        self.scan.publish(&scan);
        self.depth.publish(&depth);
        self.odom.publish(&odom);
    }
    fn stopped(&self) -> bool {
        self.stop.load(Ordering::SeqCst) || self.node.shutdown_requested()
    }
}

impl SimRobot for RosRobot {
    fn describe(&self) -> String {
        self.node.master().to_string()
    }
    fn malformed(&self) -> u64 {
        lock(&self.last).malformed()
    }
    fn shutdown(&mut self) {
        self.node.shutdown();
    }
}

/// The trajectory log (`--log`), the episode lines and the longest episode's picture
/// (`--picture`).
struct SimLog {
    csv: Option<(PathBuf, std::io::BufWriter<std::fs::File>)>,
    picture: bool,
    /// The command, for log lines and captions (`ros-sim`, `ros2-sim`).
    tag: String,
    /// The longest finished episode's steps and picture.
    best: (u32, Option<mdrlat_render::Image>),
    scale: f32,
}

impl BridgeObserver for SimLog {
    fn step(&mut self, s: &BridgeStep) -> Result<(), String> {
        let Some((path, f)) = &mut self.csv else { return Ok(()) };
        let info = &s.info;
        writeln!(
            f,
            "{:.3},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{}",
            s.t_s,
            s.episode,
            info.step,
            info.pose.x,
            info.pose.y,
            info.pose.yaw,
            info.velocity.v,
            info.velocity.w,
            s.command.v,
            s.command.w,
            info.d_min,
            s.reward,
            info.collision.map_or(String::new(), |c| format!("{c:?}"))
        )
        .map_err(|e| format!("writing {}: {e}", path.display()))
    }

    fn episode_ended(&mut self, env: &mdrlat_sim::Env, trail: &[Vec2], s: &BridgeStep) {
        let (episode, info) = (s.episode, &s.info);
        match info.collision {
            Some(c) => eprintln!(
                "[mdrlat {}] episode {episode}: collision ({c:?}) after {} steps",
                self.tag, info.step
            ),
            None => {
                eprintln!(
                    "[mdrlat {}] episode {episode}: time limit after {} steps",
                    self.tag, info.step
                )
            }
        }
        if self.picture && info.step >= self.best.0 {
            let caption = format!(
                "{} {}: episode {episode}, {} steps{}",
                self.tag,
                env.world().name,
                info.step,
                if info.collision.is_some() { ", collision" } else { "" }
            );
            let image = snapshot(env, trail, &caption, info.collision.is_some(), self.scale);
            self.best = (info.step, Some(image));
        }
    }

    fn stopped(&mut self, env: &mdrlat_sim::Env, trail: &[Vec2], episode: u64) {
        let running = env.episode_steps();
        if self.picture && (self.best.1.is_none() || running > self.best.0) {
            let caption = format!(
                "{} {}: episode {episode}, {running} steps (running)",
                self.tag,
                env.world().name
            );
            self.best = (running, Some(snapshot(env, trail, &caption, false, self.scale)));
        }
    }
}
