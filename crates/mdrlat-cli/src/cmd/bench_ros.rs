//! `mdrlat bench ros`: message-in to Twist-out latency of `mdrlat ros` over a real ROS
//! master, and the per-decision inference time on one core.

use super::bench::cpu_model;
use super::train::DeviceKind;
use anyhow::{Context, Result, bail};
use mdrlat_core::{FRAME_STACK, Observation};
use mdrlat_nn::Variant;
use mdrlat_ros::msg::{Image, LaserScan, Odometry, Twist};
use mdrlat_ros::{ControllerConfig, Node, NodeConfig, Trigger};
use mdrlat_sim::config::Task;
use mdrlat_train::GreedyPolicy;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Arguments of `mdrlat bench ros`.
#[derive(Debug, clap::Args)]
pub struct RosArgs {
    /// Network variant (weights are random: the compute is the same as a trained one's).
    #[arg(long, default_value = "mdrlat")]
    variant: Variant,
    /// Decisions to time end to end.
    #[arg(long, default_value_t = 200)]
    samples: usize,
    /// Scans per second the benchmark publishes (the node decides on each).
    #[arg(long, default_value_t = 10.0)]
    rate_hz: f32,
    #[command(flatten)]
    connection: super::ros::Connection,
    /// Compute device.
    #[arg(long, value_enum, default_value = "cpu")]
    device: DeviceKind,
    /// Print one JSON object per line instead of a table.
    #[arg(long)]
    json: bool,
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

/// `mdrlat bench ros`.
pub fn run(a: &RosArgs) -> Result<()> {
    if a.samples < 10 || a.samples > 100_000 {
        bail!("--samples {}: must be 10 to 100000", a.samples);
    }
    if !(a.rate_hz.is_finite() && a.rate_hz > 0.0 && a.rate_hz <= 50.0) {
        bail!("--rate-hz {}: must be in (0, 50]", a.rate_hz);
    }
    let device = a.device.device();
    // Inference alone, one decision at a time on one core.
    let mut policy = GreedyPolicy::untrained(a.variant, Task::Avoid, 0, &device, 1)
        .map_err(anyhow::Error::msg)?;
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

    // End to end over the master: this process is both the robot and the node.
    let master = a.connection.master.clone().unwrap_or_else(mdrlat_ros::node::master_from_env);
    let host = a.connection.host.clone().unwrap_or_else(|| "127.0.0.1".into());
    let ns = format!("/mdrlat_bench_{}", std::process::id());
    let config = NodeConfig {
        name: format!("{ns}/node"),
        master: master.clone(),
        host: host.clone(),
        scan_topic: format!("{ns}/scan"),
        depth_topic: format!("{ns}/depth"),
        odom_topic: format!("{ns}/odom"),
        cmd_topic: format!("{ns}/cmd_vel"),
        rate_hz: a.rate_hz,
        trigger: Trigger::Scan,
        controller: ControllerConfig::default(),
        log_csv: None,
    };
    let robot = Node::new(&format!("{ns}/robot"), &master, &host)
        .context("mdrlat bench ros needs a ROS master (roscore, or rosmaster --core)")?;
    let scan_pub = robot.advertise::<LaserScan>(&config.scan_topic, false)?;
    let depth_pub = robot.advertise::<Image>(&config.depth_topic, false)?;
    let odom_pub = robot.advertise::<Odometry>(&config.odom_topic, false)?;
    // Arrival time of each Twist and whether it was a driving command (a stopped node skips
    // inference: timing its zeros would flatter it).
    let arrivals: Arc<Mutex<Vec<(Instant, bool)>>> = Arc::default();
    {
        let arrivals = arrivals.clone();
        robot.subscribe::<Twist>(&config.cmd_topic, move |t| {
            let driving = t.is_ok_and(|t| t.linear.x != 0.0 || t.angular.z != 0.0);
            arrivals
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .push((Instant::now(), driving));
        })?;
    }
    let stop = Arc::new(AtomicBool::new(false));
    let node_thread = {
        let (stop, config) = (stop.clone(), config.clone());
        let policy = GreedyPolicy::untrained(a.variant, Task::Avoid, 0, &device, 1)
            .map_err(anyhow::Error::msg)?;
        std::thread::spawn(move || mdrlat_ros::run(&config, Box::new(policy), &stop, &|_| {}))
    };
    let arrived = || arrivals.lock().unwrap_or_else(std::sync::PoisonError::into_inner).len();
    let deadline = Instant::now() + Duration::from_secs(10);
    let connected = || {
        (scan_pub.subscribers() > 0 || !a.variant.uses_laser())
            && (depth_pub.subscribers() > 0 || !a.variant.uses_depth())
            && odom_pub.subscribers() > 0
            && arrived() > 0
    };
    while !connected() {
        if Instant::now() > deadline || node_thread.is_finished() {
            stop.store(true, Ordering::SeqCst);
            bail!("the node did not connect within 10 s (master {master})");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let (scan, image, odom) = robot_messages();
    let period = Duration::from_secs_f32(1.0 / a.rate_hz);
    let mut latencies = Vec::with_capacity(a.samples);
    let mut next = Instant::now();
    let warmup = 10;
    for k in 0..a.samples + warmup {
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
        next += period;
        depth_pub.publish(&image);
        odom_pub.publish(&odom);
        std::thread::sleep(Duration::from_millis(5)); // depth lands before the scan
        let before = arrived();
        let sent = Instant::now();
        scan_pub.publish(&scan);
        let wait_until = sent + Duration::from_secs(1);
        let got = loop {
            let l = arrivals.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            if l.len() > before {
                break Some(l[before]);
            }
            drop(l);
            if Instant::now() > wait_until {
                break None;
            }
            std::thread::sleep(Duration::from_micros(100));
        };
        let Some((at, driving)) = got else { bail!("no Twist within 1 s of scan {k}") };
        if k >= warmup && !driving {
            bail!("the node sent zero velocity for scan {k}: it is not driving (stale input?)");
        }
        if k >= warmup {
            latencies.push((at - sent).as_secs_f64() * 1e3);
        }
    }
    stop.store(true, Ordering::SeqCst);
    node_thread.join().map_err(|_| anyhow::anyhow!("the node thread panicked"))??;
    latencies.sort_by(f64::total_cmp);
    let (p50, p99, max) =
        (quantile(&latencies, 0.5), quantile(&latencies, 0.99), latencies[latencies.len() - 1]);
    let (i50, i99) = (quantile(&infer, 0.5), quantile(&infer, 0.99));
    if a.json {
        out!(
            "{{\"bench\":\"ros\",\"variant\":\"{}\",\"trigger\":\"scan\",\"scan_beams\":720,\"depth\":\"640x480 32FC1\",\"samples\":{},\"p50_ms\":{p50:.3},\"p99_ms\":{p99:.3},\"max_ms\":{max:.3}}}",
            a.variant,
            latencies.len()
        );
        out!(
            "{{\"bench\":\"infer\",\"variant\":\"{}\",\"threads\":1,\"ms\":{i50:.3},\"p99_ms\":{i99:.3}}}",
            a.variant
        );
    } else {
        out!("mdrlat ros latency, {} network (cpu: {})", a.variant, cpu_model());
        out!("  scan in -> Twist out, over the master at {master}: {} decisions", latencies.len());
        out!("    p50 {p50:.2} ms   p99 {p99:.2} ms   max {max:.2} ms");
        out!("  inference per decision, 1 core: median {i50:.2} ms, p99 {i99:.2} ms");
    }
    Ok(())
}
