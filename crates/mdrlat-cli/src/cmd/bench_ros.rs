//! `mdrlat bench ros` and `mdrlat bench ros2`: message-in to command-out latency of the
//! policy node over a real ROS master (ROS 1) or a DDS domain (ROS 2), and the per-decision
//! inference time on one core. One measurement, two middlewares.

use super::bench::cpu_model;
use super::train::DeviceKind;
use anyhow::{Context, Result, bail};
use mdrlat_core::{FRAME_STACK, Observation};
use mdrlat_nn::Variant;
use mdrlat_nn::burn::prelude::Device;
use mdrlat_ros::msg::{Image, LaserScan, Odometry, Twist};
use mdrlat_ros::{ControllerConfig, Node, NodeConfig, Ros1, Transport, Trigger};
use mdrlat_ros2::{CmdType, Participant, Qos, Ros2Node};
use mdrlat_sim::config::Task;
use mdrlat_train::GreedyPolicy;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// What both benchmarks take.
#[derive(Debug, clap::Args)]
pub struct Common {
    /// Network variant (weights are random: the compute is the same as a trained one's).
    #[arg(long, default_value = "mdrlat")]
    variant: Variant,
    /// Decisions to time end to end.
    #[arg(long, default_value_t = 200)]
    samples: usize,
    /// Scans per second the benchmark publishes (the node decides on each).
    #[arg(long, default_value_t = 10.0)]
    rate_hz: f32,
    /// Compute device.
    #[arg(long, value_enum, default_value = "cpu")]
    device: DeviceKind,
    /// Print one JSON object per line instead of a table.
    #[arg(long)]
    json: bool,
}

/// Arguments of `mdrlat bench ros`.
#[derive(Debug, clap::Args)]
pub struct RosArgs {
    #[command(flatten)]
    common: Common,
    #[command(flatten)]
    connection: super::ros::Connection,
}

/// Arguments of `mdrlat bench ros2`.
#[derive(Debug, clap::Args)]
pub struct Ros2Args {
    #[command(flatten)]
    common: Common,
    /// DDS domain id, 0–232 (default: $ROS_DOMAIN_ID, else 0).
    #[arg(long, value_parser = mdrlat_ros2::parse_domain)]
    domain_id: Option<u16>,
}

/// Milliseconds at quantile `q` of sorted `ms`.
fn quantile(ms: &[f64], q: f64) -> f64 {
    ms[((ms.len() - 1) as f64 * q).round() as usize]
}

/// A Kinect-sized depth frame and a 720-beam RPLIDAR-like scan: the node converts both on
/// every decision, as on the robot.
fn robot_messages() -> (LaserScan, Image, Odometry) {
    let fov = 270f32.to_radians();
    let scan = LaserScan {
        angle_min: -fov / 2.0,
        angle_max: fov / 2.0,
        angle_increment: fov / 719.0,
        range_min: 0.15,
        range_max: 12.0,
        ranges: (0..720).map(|i| 1.0 + (i % 50) as f32 * 0.05).collect(),
        ..LaserScan::default()
    };
    let depth = Image {
        height: 480,
        width: 640,
        encoding: "32FC1".into(),
        step: 640 * 4,
        data: (0..480 * 640).flat_map(|i| (0.5 + (i % 640) as f32 * 0.005).to_le_bytes()).collect(),
        ..Image::default()
    };
    (scan, depth, Odometry::default())
}

/// The node's topics in a namespace of this process, deciding on each scan.
fn bench_config(ns: &str, rate_hz: f32) -> NodeConfig {
    NodeConfig {
        name: format!("{ns}/node"),
        scan_topic: format!("{ns}/scan"),
        depth_topic: format!("{ns}/depth"),
        odom_topic: format!("{ns}/odom"),
        cmd_topic: format!("{ns}/cmd_vel"),
        rate_hz,
        trigger: Trigger::Scan,
        controller: ControllerConfig::default(),
        log_csv: None,
    }
}

/// Arrival time of each command and whether it was a driving one (a stopped node skips
/// inference: timing its zeros would flatter it).
#[derive(Clone, Default)]
struct Arrivals(Arc<Mutex<Vec<(Instant, bool)>>>);

impl Arrivals {
    fn push(&self, driving: bool) {
        super::ros::lock(&self.0).push((Instant::now(), driving));
    }
    fn len(&self) -> usize {
        super::ros::lock(&self.0).len()
    }
    fn get(&self, k: usize) -> Option<(Instant, bool)> {
        super::ros::lock(&self.0).get(k).copied()
    }
}

/// The benchmark's robot: publishes the sensors, counts the node's subscriptions.
trait BenchRobot {
    /// Whether the node subscribes to what `variant` reads.
    fn connected(&self, variant: Variant) -> bool;
    /// Publishes depth and odometry.
    fn depth_and_odom(&self);
    /// Publishes the scan that triggers a decision.
    fn scan(&self);
}

/// Inference alone, one decision at a time on one core: milliseconds, sorted.
fn inference(variant: Variant, device: &Device) -> Result<Vec<f64>> {
    let mut policy =
        GreedyPolicy::untrained(variant, Task::Avoid, 0, device, 1).map_err(anyhow::Error::msg)?;
    let mut obs = Observation::zeros();
    for _ in 0..FRAME_STACK {
        obs.laser.push_slot().fill(2.8);
        obs.depth.push_slot().fill(1.5);
    }
    let mut infer = Vec::new();
    let start = Instant::now();
    while infer.len() < 20 || start.elapsed() < Duration::from_secs(2) {
        let t = Instant::now();
        mdrlat_core::decide_one(&mut policy, &obs, 0)?;
        infer.push(t.elapsed().as_secs_f64() * 1e3);
    }
    infer.sort_by(f64::total_cmp);
    Ok(infer)
}

/// Runs the node (opened by `connect` on its own thread) against `robot` and times each
/// scan to the command it causes; milliseconds, sorted.
fn measure<T: Transport + 'static>(
    c: &Common,
    config: NodeConfig,
    robot: &dyn BenchRobot,
    arrivals: &Arrivals,
    connect: impl FnOnce() -> Result<T, mdrlat_ros::RosError> + Send + 'static,
) -> Result<Vec<f64>> {
    let stop = Arc::new(AtomicBool::new(false));
    let policy = GreedyPolicy::untrained(c.variant, Task::Avoid, 0, &c.device.device(), 1)
        .map_err(anyhow::Error::msg)?;
    let node_thread = {
        let stop = stop.clone();
        std::thread::spawn(move || -> Result<(), mdrlat_ros::RosError> {
            let mut transport = connect()?;
            mdrlat_ros::run(&mut transport, &config, Box::new(policy), &stop, &|_| {})?;
            Ok(())
        })
    };
    let fail = |why: String| -> anyhow::Error {
        stop.store(true, Ordering::SeqCst);
        anyhow::anyhow!(why)
    };
    let deadline = Instant::now() + Duration::from_secs(20);
    while !(robot.connected(c.variant) && arrivals.len() > 0) {
        if node_thread.is_finished() {
            return match node_thread.join() {
                Ok(Err(e)) => Err(e.into()),
                _ => Err(fail("the node stopped before it connected".into())),
            };
        }
        if Instant::now() > deadline {
            return Err(fail("the node did not connect within 20 s".into()));
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let period = Duration::from_secs_f32(1.0 / c.rate_hz);
    let mut latencies = Vec::with_capacity(c.samples);
    let mut next = Instant::now();
    let warmup = 10;
    for k in 0..c.samples + warmup {
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
        next += period;
        robot.depth_and_odom();
        std::thread::sleep(Duration::from_millis(5)); // depth lands before the scan
        let before = arrivals.len();
        let sent = Instant::now();
        robot.scan();
        let wait_until = sent + Duration::from_secs(1);
        let got = loop {
            if let Some(a) = arrivals.get(before) {
                break Some(a);
            }
            if Instant::now() > wait_until {
                break None;
            }
            std::thread::sleep(Duration::from_micros(100));
        };
        let Some((at, driving)) = got else {
            return Err(fail(format!("no command within 1 s of scan {k}")));
        };
        if k >= warmup && !driving {
            return Err(fail(format!(
                "the node sent zero velocity for scan {k}: it is not driving (stale input?)"
            )));
        }
        if k >= warmup {
            latencies.push((at - sent).as_secs_f64() * 1e3);
        }
    }
    stop.store(true, Ordering::SeqCst);
    node_thread.join().map_err(|_| anyhow::anyhow!("the node thread panicked"))??;
    latencies.sort_by(f64::total_cmp);
    Ok(latencies)
}

fn check(c: &Common) -> Result<()> {
    if c.samples < 10 || c.samples > 100_000 {
        bail!("--samples {}: must be 10 to 100000", c.samples);
    }
    if !(c.rate_hz.is_finite() && c.rate_hz > 0.0 && c.rate_hz <= 50.0) {
        bail!("--rate-hz {}: must be in (0, 50]", c.rate_hz);
    }
    Ok(())
}

fn report(c: &Common, bench: &str, over: &str, latencies: &[f64], infer: &[f64]) {
    let (p50, p99, max) =
        (quantile(latencies, 0.5), quantile(latencies, 0.99), latencies[latencies.len() - 1]);
    let (i50, i99) = (quantile(infer, 0.5), quantile(infer, 0.99));
    if c.json {
        out!(
            "{{\"bench\":\"{bench}\",\"variant\":\"{}\",\"trigger\":\"scan\",\"scan_beams\":720,\"depth\":\"640x480 32FC1\",\"samples\":{},\"p50_ms\":{p50:.3},\"p99_ms\":{p99:.3},\"max_ms\":{max:.3}}}",
            c.variant,
            latencies.len()
        );
        out!(
            "{{\"bench\":\"infer\",\"variant\":\"{}\",\"threads\":1,\"ms\":{i50:.3},\"p99_ms\":{i99:.3}}}",
            c.variant
        );
    } else {
        out!("mdrlat {bench} latency, {} network (cpu: {})", c.variant, cpu_model());
        out!("  scan in -> command out, {over}: {} decisions", latencies.len());
        out!("    p50 {p50:.2} ms   p99 {p99:.2} ms   max {max:.2} ms");
        out!("  inference per decision, 1 core: median {i50:.2} ms, p99 {i99:.2} ms");
    }
}

struct Ros1Robot {
    scan: mdrlat_ros::Publisher<LaserScan>,
    depth: mdrlat_ros::Publisher<Image>,
    odom: mdrlat_ros::Publisher<Odometry>,
    messages: (LaserScan, Image, Odometry),
}

impl BenchRobot for Ros1Robot {
    fn connected(&self, variant: Variant) -> bool {
        (self.scan.subscribers() > 0 || !variant.uses_laser())
            && (self.depth.subscribers() > 0 || !variant.uses_depth())
            && self.odom.subscribers() > 0
    }
    fn depth_and_odom(&self) {
        self.depth.publish(&self.messages.1);
        self.odom.publish(&self.messages.2);
    }
    fn scan(&self) {
        self.scan.publish(&self.messages.0);
    }
}

/// `mdrlat bench ros`.
pub fn run(a: &RosArgs) -> Result<()> {
    let c = &a.common;
    check(c)?;
    let infer = inference(c.variant, &c.device.device())?;
    // End to end over the master: this process is both the robot and the node.
    let master = a.connection.master.clone().unwrap_or_else(mdrlat_ros::node::master_from_env);
    let host = a.connection.host.clone().unwrap_or_else(|| "127.0.0.1".into());
    let ns = format!("/mdrlat_bench_{}", std::process::id());
    let config = bench_config(&ns, c.rate_hz);
    let robot = Node::new(&format!("{ns}/robot"), &master, &host)
        .context("mdrlat bench ros needs a ROS master (roscore, or rosmaster --core)")?;
    let arrivals = Arrivals::default();
    {
        let arrivals = arrivals.clone();
        robot.subscribe::<Twist>(&config.cmd_topic, move |t| {
            arrivals.push(t.is_ok_and(|t| t.linear.x != 0.0 || t.angular.z != 0.0));
        })?;
    }
    let bench = Ros1Robot {
        scan: robot.advertise::<LaserScan>(&config.scan_topic, false)?,
        depth: robot.advertise::<Image>(&config.depth_topic, false)?,
        odom: robot.advertise::<Odometry>(&config.odom_topic, false)?,
        messages: robot_messages(),
    };
    let name = config.name.clone();
    let over = format!("over the master at {master}");
    let latencies =
        measure(c, config, &bench, &arrivals, move || Ros1::connect(&name, &master, &host))?;
    report(c, "ros", &over, &latencies, &infer);
    Ok(())
}

struct Ros2Robot {
    participant: Participant,
    topics: [String; 3],
    scan: mdrlat_ros2::Publisher<mdrlat_ros2::msg::LaserScan>,
    depth: mdrlat_ros2::Publisher<mdrlat_ros2::msg::Image>,
    odom: mdrlat_ros2::Publisher<mdrlat_ros2::msg::Odometry>,
    messages: (mdrlat_ros2::msg::LaserScan, mdrlat_ros2::msg::Image, mdrlat_ros2::msg::Odometry),
}

impl BenchRobot for Ros2Robot {
    fn connected(&self, variant: Variant) -> bool {
        let subs = |k: usize| self.participant.subscriptions(&self.topics[k]) > 0;
        (subs(0) || !variant.uses_laser()) && (subs(1) || !variant.uses_depth()) && subs(2)
    }
    fn depth_and_odom(&self) {
        let _ = self.depth.publish(self.messages.1.clone());
        let _ = self.odom.publish(self.messages.2.clone());
    }
    fn scan(&self) {
        let _ = self.scan.publish(self.messages.0.clone());
    }
}

/// `mdrlat bench ros2`.
pub fn run2(a: &Ros2Args) -> Result<()> {
    let c = &a.common;
    check(c)?;
    let domain = match a.domain_id {
        Some(d) => d,
        None => mdrlat_ros2::domain_from_env().map_err(anyhow::Error::msg)?,
    };
    let infer = inference(c.variant, &c.device.device())?;
    // Two participants of this process on the domain: the robot and the node.
    let ns = format!("/mdrlat_bench_{}", std::process::id());
    let config = bench_config(&ns, c.rate_hz);
    let mut p = Participant::new(&format!("{ns}/robot"), domain)?;
    let arrivals = Arrivals::default();
    {
        let arrivals = arrivals.clone();
        p.subscribe::<mdrlat_ros2::msg::Twist>(&config.cmd_topic, Qos::Reliable, move |t| {
            arrivals.push(t.is_ok_and(|t| t.linear.x != 0.0 || t.angular.z != 0.0));
        })?;
    }
    let (scan, image, odom) = robot_messages();
    let bench = Ros2Robot {
        scan: p.publisher(&config.scan_topic, Qos::SensorData)?,
        depth: p.publisher(&config.depth_topic, Qos::SensorData)?,
        odom: p.publisher(&config.odom_topic, Qos::Reliable)?,
        topics: [config.scan_topic.clone(), config.depth_topic.clone(), config.odom_topic.clone()],
        participant: p,
        messages: (scan.into(), image.into(), odom.into()),
    };
    let name = config.name.clone();
    let latencies = measure(c, config, &bench, &arrivals, move || {
        Ros2Node::new(&name, domain, CmdType::Twist)
    })?;
    report(c, "ros2", &format!("over DDS domain {domain}"), &latencies, &infer);
    Ok(())
}
