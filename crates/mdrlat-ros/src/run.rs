//! The policy node's main loop, the same on every middleware ([`Transport`]): ROS 1
//! ([`Ros1`]) here, ROS 2 in `mdrlat-ros2`.

use crate::controller::{Controller, ControllerConfig, Policy, Sensor};
use crate::msg::{Image, LaserScan, Odometry, Twist, WireError};
use crate::node::{Node, Publisher, RosError, lock};
use mdrlat_core::Velocity;
use std::fmt::Display;
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

/// Everything the policy node is configured with besides the policy and the middleware.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeConfig {
    /// Node name.
    pub name: String,
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
    /// Velocity commands published.
    pub ticks: u64,
    /// Ticks where the policy drove.
    pub driving: u64,
    /// Seconds run.
    pub seconds: f64,
}

/// A sensor message as a transport received it: decoded, or why it could not be.
#[derive(Clone, Copy)]
pub enum Incoming<'a> {
    /// A laser scan.
    Scan(Result<&'a LaserScan, &'a dyn Display>),
    /// A depth image.
    Depth(Result<&'a Image, &'a dyn Display>),
    /// Odometry.
    Odom(Result<&'a Odometry, &'a dyn Display>),
}

/// Where a transport delivers sensor messages, from any of its threads.
pub type Handler = Arc<dyn Fn(Incoming<'_>) + Send + Sync>;

/// The middleware under the policy node: ROS 1 ([`Ros1`]) here, ROS 2 in `mdrlat-ros2`.
/// Everything else — frame stacks, the watchdog, the safety rules, the control clock, the
/// tick log — is [`run`]'s, the same on both.
pub trait Transport {
    /// Where the node runs, for its start-up line (e.g. `/mdrlat on http://host:11311/`).
    fn describe(&self) -> String;
    /// Subscribes to `sensor`'s `topic`: `handler` gets each message (or why it could not
    /// be decoded) as it arrives, on any thread.
    ///
    /// # Errors
    /// The middleware refuses.
    fn subscribe(&mut self, sensor: Sensor, topic: &str, handler: Handler) -> Result<(), RosError>;
    /// Makes `topic` the velocity command output.
    ///
    /// # Errors
    /// The middleware refuses.
    fn advertise(&mut self, topic: &str) -> Result<(), RosError>;
    /// Sends one velocity command (never blocks for long: the control loop runs on).
    fn publish(&mut self, velocity: Velocity);
    /// Waits up to `within` until the last command has left for every subscriber; whether
    /// it did.
    fn flush(&mut self, within: Duration) -> bool;
    /// Whether the middleware asked the node to stop.
    fn shutdown_requested(&self) -> bool;
    /// Leaves the graph.
    fn shutdown(&mut self);
}

/// [`Transport`] on ROS 1: this crate's own XML-RPC and TCPROS.
#[derive(Debug)]
pub struct Ros1 {
    node: Node,
    cmd: Option<Publisher<Twist>>,
}

impl Ros1 {
    /// A node called `name` on the master at `master`, reached by peers at `host`.
    ///
    /// # Errors
    /// No socket, or the master cannot be reached.
    pub fn connect(name: &str, master: &str, host: &str) -> Result<Self, RosError> {
        Ok(Self { node: Node::new(name, master, host)?, cmd: None })
    }
}

impl Transport for Ros1 {
    fn describe(&self) -> String {
        format!("{} on {}", self.node.name(), self.node.master())
    }

    fn subscribe(&mut self, sensor: Sensor, topic: &str, handler: Handler) -> Result<(), RosError> {
        fn err(e: &WireError) -> &dyn Display {
            e
        }
        match sensor {
            Sensor::Laser => self.node.subscribe::<LaserScan>(topic, move |m| {
                handler(Incoming::Scan(m.as_ref().map_err(err)));
            }),
            Sensor::Depth => self.node.subscribe::<Image>(topic, move |m| {
                handler(Incoming::Depth(m.as_ref().map_err(err)));
            }),
            Sensor::Odom => self.node.subscribe::<Odometry>(topic, move |m| {
                handler(Incoming::Odom(m.as_ref().map_err(err)));
            }),
        }
    }

    fn advertise(&mut self, topic: &str) -> Result<(), RosError> {
        self.cmd = Some(self.node.advertise::<Twist>(topic, false)?);
        Ok(())
    }

    fn publish(&mut self, velocity: Velocity) {
        if let Some(cmd) = &self.cmd {
            cmd.publish(&Twist::planar(f64::from(velocity.v), f64::from(velocity.w)));
        }
    }

    fn flush(&mut self, within: Duration) -> bool {
        self.cmd.as_ref().is_none_or(|c| c.flush(within))
    }

    fn shutdown_requested(&self) -> bool {
        self.node.shutdown_requested()
    }

    fn shutdown(&mut self) {
        self.node.shutdown();
    }
}

/// Shared between the transport threads and the loop.
struct Shared {
    controller: Mutex<Controller>,
    /// Bumped on each new scan, for [`Trigger::Scan`].
    scans: Mutex<u64>,
    scan_arrived: Condvar,
}

/// Runs the policy node on `transport` until `stop` is set (SIGINT/SIGTERM) or the
/// middleware asks it to shut down; then publishes zero velocity, waits for it to leave,
/// leaves the graph and returns. `log` receives one line per incident and the start-up
/// lines, always from the calling thread.
///
/// # Errors
/// The middleware refuses a subscription or the output, the CSV log cannot be written, or
/// the first scan does not cover the policy's field of view.
pub fn run(
    transport: &mut dyn Transport,
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
    let memory = policy.depth_memory_frames();
    if memory > 0 && !config.controller.require_odom {
        return Err(RosError::Config(format!(
            "this policy reads the scan with {memory} frames of the camera's memory, carried by \
             the odometry's pose: it cannot run without odometry"
        )));
    }
    let controller = Controller::new(config.controller.clone(), uses_laser, uses_depth)
        .with_depth_memory(memory);
    let shared = Arc::new(Shared {
        controller: Mutex::new(controller),
        scans: Mutex::new(0),
        scan_arrived: Condvar::new(),
    });
    // The log file first: a bad path fails before the node appears on the graph.
    let mut csv = match &config.log_csv {
        Some(path) => {
            let io = |error| RosError::File { path: path.clone(), error };
            let mut f = std::io::BufWriter::new(std::fs::File::create(path).map_err(io)?);
            writeln!(f, "t_s,driving,action,cmd_v,cmd_w,odom_v,odom_w").map_err(io)?;
            Some(f)
        }
        None => None,
    };
    transport.advertise(&config.cmd_topic)?;
    // Sensor callbacks log from transport threads; send their lines through a channel so
    // that the caller's `log` is only called from this thread.
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    let handler: Handler = {
        let (s, tx) = (shared.clone(), Mutex::new(tx));
        Arc::new(move |incoming: Incoming<'_>| {
            let arrived = Instant::now(); // before waiting for the lock
            let mut c = lock(&s.controller);
            let line = match incoming {
                Incoming::Scan(m) => c.on_scan(arrived, m),
                Incoming::Depth(m) => c.on_depth(arrived, m),
                Incoming::Odom(m) => c.on_odom(arrived, m),
            };
            drop(c);
            if let Some(l) = line {
                let _ = lock(&tx).send(l);
            }
            if matches!(incoming, Incoming::Scan(_)) {
                *lock(&s.scans) += 1;
                s.scan_arrived.notify_all();
            }
        })
    };
    let mut inputs = Vec::new();
    for (used, sensor, topic) in [
        (uses_laser, Sensor::Laser, &config.scan_topic),
        (uses_depth, Sensor::Depth, &config.depth_topic),
        (config.controller.require_odom, Sensor::Odom, &config.odom_topic),
    ] {
        if used {
            transport.subscribe(sensor, topic, handler.clone())?;
            inputs.push(topic.as_str());
        }
    }
    drop(handler);
    let limits = lock(&shared.controller).config().clone();
    log(&format!(
        "{}: {} -> {} at {} Hz ({:?}), limits {:.2} m/s {:.2} rad/s, stale after {:.2} s",
        transport.describe(),
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
    while !stop.load(Ordering::SeqCst) && !transport.shutdown_requested() {
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
        transport.publish(command.velocity);
        summary.ticks += 1;
        summary.driving += u64::from(command.action.is_some());
        while let Ok(line) = rx.try_recv() {
            log(&line);
        }
        for l in lines {
            log(&l);
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
    transport.publish(Velocity::default());
    summary.ticks += 1;
    let flushed = transport.flush(Duration::from_millis(500));
    if let Some(f) = &mut csv {
        let _ = f.flush();
    }
    log(&format!(
        "stopping: zero velocity sent{} after {} ticks ({} driving)",
        if flushed { "" } else { " (a subscriber did not take it within 0.5 s)" },
        summary.ticks,
        summary.driving
    ));
    transport.shutdown();
    summary.seconds = start.elapsed().as_secs_f64();
    match fatal {
        Some(e) => Err(RosError::Config(e)),
        None => Ok(summary),
    }
}
