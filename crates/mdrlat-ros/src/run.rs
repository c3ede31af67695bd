//! `mdrlat ros`: the policy node's main loop over a real ROS master.

use crate::controller::{Command, Controller, ControllerConfig, Policy};
use crate::msg::{Image, LaserScan, Odometry, Twist};
use crate::node::{Node, RosError, lock};
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// When the node decides.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Trigger {
    /// On a fixed clock at `rate_hz` (the default; as the authors' `rospy.Rate(5)` loop).
    #[default]
    Timer,
    /// As soon as a new scan arrives, but not sooner than 0.9 / `rate_hz` after the last
    /// decision (lowest sensor-to-command latency; the command rate follows the laser's).
    Scan,
}

/// Everything `mdrlat ros` is configured with besides the policy.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeConfig {
    /// Node name.
    pub name: String,
    /// Master URI.
    pub master: String,
    /// The host peers reach this node at.
    pub host: String,
    /// `sensor_msgs/LaserScan` input.
    pub scan_topic: String,
    /// `sensor_msgs/Image` depth input.
    pub depth_topic: String,
    /// `nav_msgs/Odometry` input.
    pub odom_topic: String,
    /// `geometry_msgs/Twist` output.
    pub cmd_topic: String,
    /// Decisions per second.
    pub rate_hz: f32,
    /// When to decide.
    pub trigger: Trigger,
    /// Sensor rules and limits.
    pub controller: ControllerConfig,
    /// A CSV log of every tick (time, status, action, command, odometry).
    pub log_csv: Option<PathBuf>,
}

impl Default for NodeConfig {
    fn default() -> Self {
        Self {
            name: "/mdrlat".into(),
            master: crate::node::master_from_env(),
            host: crate::node::host_from_env(),
            scan_topic: "/scan".into(),
            depth_topic: "/camera/depth/image_raw".into(),
            odom_topic: "/odom".into(),
            cmd_topic: "/cmd_vel".into(),
            rate_hz: 5.0,
            trigger: Trigger::Timer,
            controller: ControllerConfig::default(),
            log_csv: None,
        }
    }
}

/// What a run did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RunSummary {
    /// Twist messages published.
    pub ticks: u64,
    /// Ticks where the policy drove.
    pub driving: u64,
    /// Seconds run.
    pub seconds: f64,
}

/// Shared between the transport threads and the loop.
struct Shared {
    controller: Mutex<Controller>,
    /// Bumped on each new scan, for [`Trigger::Scan`].
    scans: Mutex<u64>,
    scan_arrived: Condvar,
}

/// Runs the node until `stop` is set (SIGINT/SIGTERM) or the master asks it to shut down;
/// then publishes zero velocity, waits for it to leave, unregisters and returns.
/// `log` receives one line per incident and the start-up lines.
///
/// # Errors
/// The master cannot be reached or refuses, or the CSV log cannot be written.
pub fn run(
    config: &NodeConfig,
    mut policy: Box<dyn Policy>,
    stop: &AtomicBool,
    log: &(dyn Fn(&str) + Sync),
) -> Result<RunSummary, RosError> {
    let sensors = policy.sensors();
    let (uses_laser, uses_depth) = (sensors.laser, sensors.depth);
    if config.trigger == Trigger::Scan && !uses_laser {
        return Err(RosError::Config(
            "the scan trigger needs a policy that reads the laser (this one does not): use the timer"
                .into(),
        ));
    }
    let shared = Arc::new(Shared {
        controller: Mutex::new(Controller::new(config.controller.clone(), uses_laser, uses_depth)),
        scans: Mutex::new(0),
        scan_arrived: Condvar::new(),
    });
    // The log file first: a bad path fails before the node registers anywhere.
    let mut csv = match &config.log_csv {
        Some(path) => {
            let io = |error| RosError::File { path: path.clone(), error };
            let mut f = std::io::BufWriter::new(std::fs::File::create(path).map_err(io)?);
            writeln!(f, "t_s,driving,action,cmd_v,cmd_w,odom_v,odom_w").map_err(io)?;
            Some(f)
        }
        None => None,
    };
    let node = Node::new(&config.name, &config.master, &config.host)?;
    let cmd = node.advertise::<Twist>(&config.cmd_topic, false)?;
    let log_line = |line: Option<String>| {
        if let Some(l) = line {
            log(&l);
        }
    };
    // Sensor callbacks log from transport threads; send their lines through a channel so
    // that the caller's `log` is only called from this thread.
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    if uses_laser {
        let (s, tx) = (shared.clone(), tx.clone());
        node.subscribe::<LaserScan>(&config.scan_topic, move |msg| {
            let arrived = Instant::now(); // before waiting for the lock
            let line = lock(&s.controller).on_scan(arrived, msg.as_ref());
            if let Some(l) = line {
                let _ = tx.send(l);
            }
            *lock(&s.scans) += 1;
            s.scan_arrived.notify_all();
        })?;
    }
    if uses_depth {
        let (s, tx) = (shared.clone(), tx.clone());
        node.subscribe::<Image>(&config.depth_topic, move |msg| {
            let arrived = Instant::now();
            if let Some(l) = lock(&s.controller).on_depth(arrived, msg.as_ref()) {
                let _ = tx.send(l);
            }
        })?;
    }
    if config.controller.require_odom {
        let (s, tx) = (shared.clone(), tx.clone());
        node.subscribe::<Odometry>(&config.odom_topic, move |msg| {
            let arrived = Instant::now();
            if let Some(l) = lock(&s.controller).on_odom(arrived, msg.as_ref()) {
                let _ = tx.send(l);
            }
        })?;
    }
    drop(tx);
    let mut inputs = Vec::new();
    if uses_laser {
        inputs.push(config.scan_topic.as_str());
    }
    if uses_depth {
        inputs.push(config.depth_topic.as_str());
    }
    if config.controller.require_odom {
        inputs.push(config.odom_topic.as_str());
    }
    let limits = lock(&shared.controller).config().clone();
    log(&format!(
        "{} on {}: {} -> {} at {} Hz ({:?}), limits {:.2} m/s {:.2} rad/s, stale after {:.2} s",
        node.name(),
        node.master(),
        inputs.join(", "),
        config.cmd_topic,
        config.rate_hz,
        config.trigger,
        limits.max_linear_mps,
        limits.max_angular_radps,
        limits.stale_after.as_secs_f32(),
    ));
    let period = Duration::from_secs_f64(1.0 / f64::from(config.rate_hz.max(0.1)));
    let start = Instant::now();
    let mut next = start;
    let mut seen_scans = 0;
    let mut last_decision: Option<Instant> = None;
    let mut last_tick: Option<Instant> = None;
    // In scan-triggered mode, a tick without a new scan comes only once the laser is stale.
    let watchdog = period.max(config.controller.stale_after + Duration::from_millis(10));
    let mut summary = RunSummary::default();
    let mut fatal = None;
    while !stop.load(Ordering::SeqCst) && !node.shutdown_requested() {
        if let Some(e) = lock(&shared.controller).fatal() {
            fatal = Some(e.to_string());
            break;
        }
        // Wait for this tick's moment.
        match config.trigger {
            Trigger::Timer => {
                let now = Instant::now();
                if next > now {
                    std::thread::sleep((next - now).min(Duration::from_millis(50)));
                    continue; // re-check the stop flag every 50 ms
                }
                next += period;
                if next < Instant::now() {
                    next = Instant::now() + period; // fell behind: do not burst
                }
            }
            Trigger::Scan => {
                let scans = lock(&shared.scans);
                let (scans, _) = shared
                    .scan_arrived
                    .wait_timeout_while(scans, Duration::from_millis(20), |n| *n == seen_scans)
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
                let (count, fresh) = (*scans, *scans != seen_scans);
                drop(scans);
                let now = Instant::now();
                let due_at = last_decision.map(|t| t + period.mul_f32(0.9));
                if fresh && due_at.is_none_or(|d| now >= d) {
                    seen_scans = count;
                    last_decision = Some(now);
                } else if last_tick.is_none_or(|t| now - t >= watchdog) {
                    // No scan for a while: tick anyway, so that a stale laser is reported
                    // and zero velocity keeps flowing. A watchdog tick does not delay the
                    // next scan's decision.
                } else {
                    if fresh && let Some(d) = due_at {
                        std::thread::sleep(
                            d.saturating_duration_since(now).min(Duration::from_millis(20)),
                        );
                    }
                    continue;
                }
            }
        }
        let now = Instant::now();
        last_tick = Some(now);
        let (command, lines) = lock(&shared.controller).tick(now, policy.as_mut());
        publish(&cmd, command);
        summary.ticks += 1;
        summary.driving += u64::from(command.action.is_some());
        while let Ok(line) = rx.try_recv() {
            log(&line);
        }
        for l in lines {
            log_line(Some(l));
        }
        if let Some(f) = &mut csv {
            let odom = lock(&shared.controller).odom_velocity();
            let _ = writeln!(
                f,
                "{:.3},{},{},{:.4},{:.4},{:.4},{:.4}",
                (now - start).as_secs_f64(),
                u8::from(command.action.is_some()),
                command.action.map_or(-1, |a| a.index() as i64),
                command.velocity.v,
                command.velocity.w,
                odom.v,
                odom.w
            );
        }
    }
    // Stop the robot before anything else, and make sure the zero leaves the socket.
    publish(&cmd, Command { velocity: mdrlat_core::Velocity::default(), action: None });
    summary.ticks += 1;
    let flushed = cmd.flush(Duration::from_millis(500));
    if let Some(f) = &mut csv {
        let _ = f.flush();
    }
    log(&format!(
        "stopping: zero velocity sent{} after {} ticks ({} driving)",
        if flushed { "" } else { " (a subscriber did not take it within 0.5 s)" },
        summary.ticks,
        summary.driving
    ));
    node.shutdown();
    summary.seconds = start.elapsed().as_secs_f64();
    match fatal {
        Some(e) => Err(RosError::Config(e)),
        None => Ok(summary),
    }
}

fn publish(publisher: &crate::node::Publisher<Twist>, command: Command) {
    publisher.publish(&Twist::planar(f64::from(command.velocity.v), f64::from(command.velocity.w)));
}
