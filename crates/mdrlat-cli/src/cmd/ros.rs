//! `mdrlat ros` (the policy as a ROS 1 node) and `mdrlat ros-sim` (the simulator as a
//! turtlebot2 over ROS).

use super::train::DeviceKind;
use super::{ensure_parent, load_world, make_env, px_per_m, snapshot};
use crate::config::Config;
use anyhow::{Context, Result, bail};
use mdrlat_core::{DEPTH_COLS, DEPTH_ROWS, LASER_BEAMS, Velocity, laser_beam_angle};
use mdrlat_geom::Vec2;
use mdrlat_nn::Variant;
use mdrlat_ros::msg::{Header, Image, LaserScan, Odometry, Quaternion, Time, Twist, Vector3};
use mdrlat_ros::{ControllerConfig, NodeConfig, NonFinite, ScanOptions, Trigger};
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

/// Arguments of `mdrlat ros`.
#[derive(Debug, clap::Args)]
pub struct Args {
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
    #[command(flatten)]
    pub connection: Connection,
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
    /// Opt-in: the network's linear layers read bfloat16 weights (half the memory traffic:
    /// an MDRLAT decision 1.44 → 0.96 ms on a Sapphire Rapids core); decisions may differ
    /// from f32 where two actions' Q-values nearly tie. Needs AVX-512.
    #[arg(long)]
    pub bf16: bool,
}

/// SIGINT and SIGTERM set the returned flag (instead of killing the process), so a node can
/// stop its robot before exiting.
pub fn stop_flag() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, stop.clone())
            .with_context(|| format!("cannot handle signal {signal}"))?;
    }
    Ok(stop)
}

fn log_line(line: &str) {
    let t = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0);
    eprintln!("[mdrlat ros {t:.3}] {line}");
}

/// Builds the node configuration from `mdrlat ros` arguments.
fn node_config(a: &Args) -> Result<NodeConfig> {
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
        master: a.connection.master(),
        host: a.connection.host(),
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
    log_line(&format!(
        "policy: {} network, {} ({} on {} thread(s))",
        policy.variant(),
        policy.source(),
        a.device.name(),
        a.threads
    ));
    let stop = stop_flag()?;
    let summary = mdrlat_ros::run(&config, Box::new(policy), &stop, &log_line)?;
    log_line(&format!("exited after {:.1} s", summary.seconds));
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

impl DepthEncoding {
    /// The ROS encoding name.
    fn name(self) -> &'static str {
        match self {
            DepthEncoding::F32 => "32FC1",
            DepthEncoding::U16 => "16UC1",
        }
    }
}

/// Arguments of `mdrlat ros-sim`.
#[derive(Debug, clap::Args)]
pub struct SimArgs {
    /// World: a built-in name, a world .toml or a map_server .yaml.
    #[arg(long, default_value = "train")]
    pub world: String,
    /// Seed of the start poses and pedestrians.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Configuration file (its [sim] table; see `mdrlat config default`).
    #[arg(long)]
    pub config: Option<PathBuf>,
    #[command(flatten)]
    pub connection: Connection,
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

/// The fastest a Kobuki base drives, m/s; `ros-sim` clamps `/cmd_vel` to it.
const KOBUKI_MAX_V: f32 = 0.7;
/// The fastest a Kobuki base turns, rad/s.
const KOBUKI_MAX_W: f32 = std::f32::consts::PI;

/// The latest `/cmd_vel` and when it arrived.
#[derive(Debug, Default)]
struct LastCommand {
    twist: Option<(Twist, Instant)>,
    malformed: u64,
}

/// `mdrlat ros-sim`.
pub fn sim(a: &SimArgs) -> Result<()> {
    if !(a.speed.is_finite() && (0.01..=100.0).contains(&a.speed)) {
        bail!("--speed {}: expected a factor in [0.01, 100]", a.speed);
    }
    if !(a.cmd_timeout_s.is_finite() && a.cmd_timeout_s > 0.0 && a.cmd_timeout_s <= 60.0) {
        bail!("--cmd-timeout-s {}: expected seconds in (0, 60]", a.cmd_timeout_s);
    }
    if !(a.duration_s.is_finite() && a.duration_s >= 0.0) {
        bail!("--duration-s {}: expected a non-negative number of seconds", a.duration_s);
    }
    let mut config = Config::load_or_default(a.config.as_deref())?.sim;
    config.max_episode_steps = if a.episode_steps == 0 { u32::MAX } else { a.episode_steps };
    let world = load_world(&a.world)?;
    let mut env = make_env(world, &config)?;
    for path in [&a.log, &a.picture].into_iter().flatten() {
        ensure_parent(path)?;
    }
    let mut csv = match &a.log {
        Some(p) => {
            let mut f = std::io::BufWriter::new(
                std::fs::File::create(p)
                    .with_context(|| format!("cannot create {}", p.display()))?,
            );
            writeln!(f, "t_s,episode,step,x,y,yaw,v,w,cmd_v,cmd_w,d_min,reward,collision")?;
            Some((p.clone(), f))
        }
        None => None,
    };
    let stop = stop_flag()?;
    let node = mdrlat_ros::Node::new(&a.name, &a.connection.master(), &a.connection.host())?;
    let sensors = SimSensors {
        scan: node.advertise::<LaserScan>(&a.topics.scan_topic, false)?,
        depth: node.advertise::<Image>(&a.topics.depth_topic, false)?,
        odom: node.advertise::<Odometry>(&a.topics.odom_topic, false)?,
        encoding: a.depth_encoding,
    };
    let last = Arc::new(Mutex::new(LastCommand::default()));
    {
        let last = last.clone();
        node.subscribe::<Twist>(&a.topics.cmd_topic, move |msg| {
            let mut l = last.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            match msg {
                Ok(t) => l.twist = Some((t, Instant::now())),
                Err(_) => l.malformed += 1,
            }
        })?;
    }
    eprintln!(
        "[mdrlat ros-sim] world {} on {}: publishing {}, {} ({}), {}; driving from {}",
        env.world().name,
        node.master(),
        a.topics.scan_topic,
        a.topics.depth_topic,
        a.depth_encoding.name(),
        a.topics.odom_topic,
        a.topics.cmd_topic
    );
    let dt = env.config().dt_s;
    let period = Duration::from_secs_f32(dt / a.speed);
    let timeout = Duration::from_secs_f32(a.cmd_timeout_s);
    let mut episode = 0u64;
    env.reset_stream(a.seed, episode)?;
    let start = Instant::now();
    let mut seq = 0u32;
    let mut trail: Vec<Vec2> = vec![env.pose().position()];
    // The longest finished episode's picture (steps, image), for --picture.
    let mut best = (0u32, None);
    let scale = px_per_m(env.world(), 640.0);
    let (mut steps, mut collisions, mut distance) = (0u64, 0u64, 0f64);
    sensors.publish(&env, seq, Velocity::default());
    let mut next = Instant::now() + period;
    while !stop.load(Ordering::SeqCst) && !node.shutdown_requested() {
        if a.duration_s > 0.0 && start.elapsed().as_secs_f32() >= a.duration_s {
            break;
        }
        let now = Instant::now();
        if next > now {
            std::thread::sleep((next - now).min(Duration::from_millis(50)));
            continue;
        }
        next += period;
        let command = {
            let l = last.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            match l.twist {
                // A Kobuki's own limits: 0.7 m/s, 180°/s.
                Some((t, at)) if now.duration_since(at) <= timeout && finite(&t) => Velocity::new(
                    (t.linear.x as f32).clamp(-KOBUKI_MAX_V, KOBUKI_MAX_V),
                    (t.angular.z as f32).clamp(-KOBUKI_MAX_W, KOBUKI_MAX_W),
                ),
                _ => Velocity::default(),
            }
        };
        let before = env.pose().position();
        let step = env.step_command(command)?;
        let (info, reward, ended) = (step.info, step.reward, step.terminated || step.truncated);
        steps += 1;
        seq = seq.wrapping_add(1);
        distance += f64::from((info.pose.position() - before).length());
        trail.push(info.pose.position());
        if let Some((path, f)) = &mut csv {
            writeln!(
                f,
                "{:.3},{episode},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{}",
                start.elapsed().as_secs_f64(),
                info.step,
                info.pose.x,
                info.pose.y,
                info.pose.yaw,
                info.velocity.v,
                info.velocity.w,
                command.v,
                command.w,
                info.d_min,
                reward,
                info.collision.map_or(String::new(), |c| format!("{c:?}"))
            )
            .with_context(|| format!("writing {}", path.display()))?;
        }
        if ended {
            if let Some(c) = info.collision {
                collisions += 1;
                eprintln!(
                    "[mdrlat ros-sim] episode {episode}: collision ({c:?}) after {} steps",
                    info.step
                );
            } else {
                eprintln!(
                    "[mdrlat ros-sim] episode {episode}: time limit after {} steps",
                    info.step
                );
            }
            if a.picture.is_some() && info.step >= best.0 {
                let caption = format!(
                    "ros-sim {}: episode {episode}, {} steps{}",
                    env.world().name,
                    info.step,
                    if info.collision.is_some() { ", collision" } else { "" }
                );
                let image = snapshot(&env, &trail, &caption, info.collision.is_some(), scale);
                best = (info.step, Some(image));
            }
            trail.clear();
            episode += 1;
            env.reset_stream(a.seed, episode)?;
            trail.push(env.pose().position());
        }
        sensors.publish(&env, seq, info.velocity);
    }
    if let Some((path, f)) = &mut csv {
        f.flush().with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(p) = &a.picture {
        let running = env.episode_steps();
        let image = match best {
            (steps, Some(image)) if steps >= running => image,
            _ => {
                let caption = format!(
                    "ros-sim {}: episode {episode}, {running} steps (running)",
                    env.world().name
                );
                snapshot(&env, &trail, &caption, false, scale)
            }
        };
        image.save_png(p)?;
    }
    let malformed = last.lock().map(|l| l.malformed).unwrap_or(0);
    out!(
        "{{\"ros_sim\":\"{}\",\"steps\":{steps},\"episodes\":{},\"collisions\":{collisions},\"distance_m\":{distance:.3},\"malformed_cmd\":{malformed},\"seconds\":{:.2}}}",
        env.world().name,
        episode + 1,
        start.elapsed().as_secs_f64()
    );
    node.shutdown();
    Ok(())
}

fn finite(t: &Twist) -> bool {
    t.linear.x.is_finite() && t.angular.z.is_finite()
}

/// The simulator's sensor topics.
struct SimSensors {
    scan: mdrlat_ros::Publisher<LaserScan>,
    depth: mdrlat_ros::Publisher<Image>,
    odom: mdrlat_ros::Publisher<Odometry>,
    encoding: DepthEncoding,
}

impl SimSensors {
    /// Publishes the simulator's current laser, depth and odometry as a turtlebot2 with an
    /// RPLIDAR and a Kinect would.
    fn publish(&self, env: &mdrlat_sim::Env, seq: u32, velocity: Velocity) {
        let stamp = Time::now();
        let header = |frame: &str| Header { seq, stamp, frame_id: frame.to_string() };
        let obs = env.observation();
        let laser = env.laser().config();
        let dt = env.config().dt_s;
        self.scan.publish(&LaserScan {
            header: header("laser"),
            angle_min: laser_beam_angle(0),
            angle_max: laser_beam_angle(LASER_BEAMS - 1),
            angle_increment: laser_beam_angle(1) - laser_beam_angle(0),
            time_increment: 0.0,
            scan_time: dt,
            range_min: 0.0,
            range_max: laser.max_range_m,
            ranges: obs.laser.latest().to_vec(),
            intensities: Vec::new(),
        });
        let depth = obs.depth.latest();
        let (data, step) = match self.encoding {
            DepthEncoding::F32 => (depth.iter().flat_map(|d| d.to_le_bytes()).collect(), 4),
            DepthEncoding::U16 => (
                depth
                    .iter()
                    .flat_map(|d| ((d * 1000.0).round().clamp(0.0, 65535.0) as u16).to_le_bytes())
                    .collect(),
                2,
            ),
        };
        self.depth.publish(&Image {
            header: header("camera_depth_optical_frame"),
            height: DEPTH_ROWS as u32,
            width: DEPTH_COLS as u32,
            encoding: self.encoding.name().into(),
            is_bigendian: 0,
            step: (DEPTH_COLS * step) as u32,
            data,
        });
        let pose = env.pose();
        self.odom.publish(&Odometry {
            header: header("odom"),
            child_frame_id: "base_footprint".into(),
            position: Vector3 { x: f64::from(pose.x), y: f64::from(pose.y), z: 0.0 },
            orientation: Quaternion::from_yaw(f64::from(pose.yaw)),
            twist: Twist::planar(f64::from(velocity.v), f64::from(velocity.w)),
            ..Odometry::default()
        });
    }
}
