//! The node's decision logic, free of any transport: the latest sensor frames, the 4-frame
//! stacks, the watchdog, and the command each control tick sends.
//!
//! Safety rules (issue 5): a sensor older than `stale_after`, a malformed message or an
//! inference error gives zero velocity; each incident is logged once when it starts and
//! once when it ends, never once per tick; commands are clamped to Table 1's limits.

use crate::convert::{ScanError, ScanOptions, convert_depth, resample_scan};
use crate::msg::{Image, LaserScan, Odometry};
use mdrlat_core::ScanMemory;
use mdrlat_core::{Action, DEPTH_LEN, LASER_BEAMS, ODOM_HISTORY, Observation, Velocity};
use std::fmt::Display;
use std::time::{Duration, Instant};

/// The policy the node runs: the one interface of `mdrlat-core`, fed the same
/// [`Observation`] (4-frame stacks in metres, odometry) as in the simulator.
pub use mdrlat_core::Policy;

/// The node's limits and sensor rules.
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerConfig {
    /// A sensor whose last valid message is older than this stops the robot.
    pub stale_after: Duration,
    /// Whether odometry must be fresh too (the robot's base is alive).
    pub require_odom: bool,
    /// Linear speed limit, m/s (never above Table 1's 0.5).
    pub max_linear_mps: f32,
    /// Angular speed limit, rad/s (never above Table 1's π/3).
    pub max_angular_radps: f32,
    /// How scans are read.
    pub scan: ScanOptions,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        let limits = Action::command_limits();
        Self {
            stale_after: Duration::from_millis(500),
            require_odom: true,
            max_linear_mps: limits.v,
            max_angular_radps: limits.w,
            scan: ScanOptions::default(),
        }
    }
}

/// The sensors the node watches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sensor {
    /// The laser scan.
    Laser,
    /// The depth image.
    Depth,
    /// The odometry.
    Odom,
}

impl Sensor {
    fn name(self) -> &'static str {
        match self {
            Sensor::Laser => "laser scan",
            Sensor::Depth => "depth image",
            Sensor::Odom => "odometry",
        }
    }
}

/// One sensor's latest valid frame and its fault, if the last message was malformed.
#[derive(Debug)]
struct Slot {
    frame: Vec<f32>,
    at: Option<Instant>,
    fault: Option<String>,
}

impl Slot {
    fn new(len: usize) -> Self {
        Self { frame: vec![0.0; len], at: None, fault: None }
    }
}

/// Why the robot is stopped (each kind is one incident).
#[derive(Debug, Clone, PartialEq, Eq)]
enum Stop {
    Waiting(Sensor),
    Stale(Sensor),
    Malformed(Sensor),
    Inference,
}

/// What one control tick sends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Command {
    /// The velocity to publish (zero when stopped), clamped.
    pub velocity: Velocity,
    /// The policy's action, when it drove.
    pub action: Option<Action>,
}

/// The decision logic of `mdrlat ros`.
#[derive(Debug)]
pub struct Controller {
    config: ControllerConfig,
    uses_laser: bool,
    uses_depth: bool,
    laser: Slot,
    depth: Slot,
    odom: Slot,
    odom_velocity: Velocity,
    /// The robot's pose in the odometry frame, `[x, y, yaw]`, from the last odometry.
    odom_pose: [f32; 3],
    /// The camera's hidden obstacles drawn into each scan, for a policy that reads them
    /// ([`Controller::with_depth_memory`]).
    memory: Option<ScanMemory>,
    /// The 4-frame stacks (metres) and odometry the policy reads.
    obs: Observation,
    /// Frames pushed since the stacks were last (re)started.
    stacked: usize,
    stops: Vec<Stop>,
    inference_error: Option<String>,
    scratch_scan: [f32; LASER_BEAMS],
    /// A scan has been read successfully.
    scans_ok: bool,
    fatal: Option<String>,
}

impl Controller {
    /// A controller for a policy that reads the given sensors.
    pub fn new(config: ControllerConfig, uses_laser: bool, uses_depth: bool) -> Self {
        let limits = Action::command_limits();
        let config = ControllerConfig {
            max_linear_mps: config.max_linear_mps.clamp(0.0, limits.v),
            max_angular_radps: config.max_angular_radps.clamp(0.0, limits.w),
            ..config
        };
        Self {
            config,
            uses_laser,
            uses_depth,
            laser: Slot::new(LASER_BEAMS),
            depth: Slot::new(DEPTH_LEN),
            odom: Slot::new(0),
            odom_velocity: Velocity::default(),
            odom_pose: [0.0; 3],
            memory: None,
            obs: Observation::zeros(),
            stacked: 0,
            stops: Vec::new(),
            inference_error: None,
            scratch_scan: [0.0; LASER_BEAMS],
            scans_ok: false,
            fatal: None,
        }
    }

    /// For a policy that reads the scan with `frames` of the camera's memory
    /// ([`Policy::depth_memory_frames`]; 0: the laser's own): each scan it gets has the
    /// camera's obstacles hidden from the laser drawn in, carried by the odometry's pose,
    /// with the simulator's own code ([`ScanMemory::spec`]: the sensors and body of SPEC §2,
    /// the simulator's defaults). It then reads the camera whatever its variant.
    pub fn with_depth_memory(mut self, frames: u32) -> Self {
        self.memory = ScanMemory::spec(frames);
        self.uses_depth |= self.memory.is_some();
        self
    }

    /// The effective limits (after clamping to Table 1).
    pub fn config(&self) -> &ControllerConfig {
        &self.config
    }

    /// The sensors this controller requires.
    pub fn sensors(&self) -> Vec<Sensor> {
        let mut s = Vec::new();
        if self.uses_laser {
            s.push(Sensor::Laser);
        }
        if self.uses_depth {
            s.push(Sensor::Depth);
        }
        if self.config.require_odom {
            s.push(Sensor::Odom);
        }
        s
    }

    fn slot(&mut self, sensor: Sensor) -> &mut Slot {
        match sensor {
            Sensor::Laser => &mut self.laser,
            Sensor::Depth => &mut self.depth,
            Sensor::Odom => &mut self.odom,
        }
    }

    /// Records the outcome of one message; returns a log line when a malformed-message
    /// incident starts or ends.
    fn record(
        &mut self,
        sensor: Sensor,
        now: Instant,
        result: Result<(), String>,
    ) -> Option<String> {
        let slot = self.slot(sensor);
        match result {
            Ok(()) => {
                slot.at = Some(now);
                slot.fault.take().map(|_| format!("{}: valid messages again", sensor.name()))
            }
            Err(e) => {
                slot.at = None; // the last valid frame no longer describes the world
                let first = slot.fault.is_none();
                slot.fault = Some(e.clone());
                first.then(|| {
                    format!(
                        "{} rejected: {e}; zero velocity until a valid one arrives",
                        sensor.name()
                    )
                })
            }
        }
    }

    /// A laser scan arrived (or failed to decode).
    ///
    /// A first scan that does not cover the policy's 270° is a set-up error, not an incident:
    /// see [`Controller::fatal`].
    pub fn on_scan(
        &mut self,
        now: Instant,
        msg: Result<&LaserScan, &dyn Display>,
    ) -> Option<String> {
        let result = match msg {
            Ok(scan) => match resample_scan(scan, self.config.scan, &mut self.scratch_scan) {
                Ok(()) => {
                    self.laser.frame.copy_from_slice(&self.scratch_scan);
                    self.scans_ok = true;
                    Ok(())
                }
                Err(e @ ScanError::Coverage { .. }) if !self.scans_ok => {
                    self.fatal.get_or_insert_with(|| format!("laser scan: {e}"));
                    Err(e.to_string())
                }
                Err(e) => Err(e.to_string()),
            },
            Err(e) => Err(format!("undecodable message: {e}")),
        };
        self.record(Sensor::Laser, now, result)
    }

    /// A set-up error that should stop the node (the laser does not cover the policy's
    /// field of view), if one happened.
    pub fn fatal(&self) -> Option<&str> {
        self.fatal.as_deref()
    }

    /// A depth image arrived (or failed to decode).
    pub fn on_depth(&mut self, now: Instant, msg: Result<&Image, &dyn Display>) -> Option<String> {
        let result = match msg {
            Ok(image) => convert_depth(image, &mut self.depth.frame).map_err(|e| e.to_string()),
            Err(e) => Err(format!("undecodable message: {e}")),
        };
        if result.is_err() {
            self.depth.frame.fill(0.0);
        }
        self.record(Sensor::Depth, now, result)
    }

    /// Odometry arrived (or failed to decode).
    pub fn on_odom(
        &mut self,
        now: Instant,
        msg: Result<&Odometry, &dyn Display>,
    ) -> Option<String> {
        let result = match msg {
            Ok(o) => {
                let (v, w) = (o.twist.linear.x, o.twist.angular.z);
                let yaw = o.orientation.yaw();
                let (x, y) = (o.position.x, o.position.y);
                if !(v.is_finite() && w.is_finite()) {
                    Err(format!("non-finite twist ({v}, {w})"))
                } else if self.memory.is_some()
                    && !(x.is_finite() && y.is_finite() && yaw.is_finite())
                {
                    // Only the scan with the camera's memory reads the pose.
                    Err(format!("non-finite pose ({x}, {y}, yaw {yaw})"))
                } else {
                    self.odom_velocity = Velocity::new(v as f32, w as f32);
                    self.odom_pose = [x as f32, y as f32, yaw as f32];
                    Ok(())
                }
            }
            Err(e) => Err(format!("undecodable message: {e}")),
        };
        self.record(Sensor::Odom, now, result)
    }

    /// The robot's velocity from the last odometry.
    pub fn odom_velocity(&self) -> Velocity {
        self.odom_velocity
    }

    /// Why the robot must stop now, sensor by sensor.
    fn sensor_stops(&self, now: Instant) -> Vec<Stop> {
        let mut stops = Vec::new();
        for sensor in self.sensors() {
            let slot = match sensor {
                Sensor::Laser => &self.laser,
                Sensor::Depth => &self.depth,
                Sensor::Odom => &self.odom,
            };
            match (slot.at, &slot.fault) {
                (_, Some(_)) => stops.push(Stop::Malformed(sensor)),
                (None, None) => stops.push(Stop::Waiting(sensor)),
                (Some(at), None) if now.saturating_duration_since(at) > self.config.stale_after => {
                    stops.push(Stop::Stale(sensor));
                }
                _ => {}
            }
        }
        stops
    }

    fn describe(&self, stop: &Stop, now: Instant) -> String {
        match stop {
            Stop::Waiting(s) => format!("waiting for the first {}", s.name()),
            Stop::Stale(s) => {
                let slot = match s {
                    Sensor::Laser => &self.laser,
                    Sensor::Depth => &self.depth,
                    Sensor::Odom => &self.odom,
                };
                let age = slot.at.map_or(0.0, |at| now.saturating_duration_since(at).as_secs_f32());
                format!(
                    "{} is stale ({age:.2} s old, limit {:.2} s)",
                    s.name(),
                    self.config.stale_after.as_secs_f32()
                )
            }
            Stop::Malformed(s) => format!("{} malformed", s.name()),
            Stop::Inference => {
                format!("inference failed: {}", self.inference_error.as_deref().unwrap_or("?"))
            }
        }
    }

    /// One control tick: the command to publish now and the log lines of incidents that
    /// start or end at this tick.
    pub fn tick(&mut self, now: Instant, policy: &mut dyn Policy) -> (Command, Vec<String>) {
        let mut logs = Vec::new();
        let mut stops = self.sensor_stops(now);
        let mut action = None;
        if stops.is_empty() {
            // Algorithm 1's stacking at the control rate: one frame per tick.
            if self.uses_laser {
                self.obs.laser.push_slot().copy_from_slice(&self.laser.frame);
            }
            if self.uses_depth {
                self.obs.depth.push_slot().copy_from_slice(&self.depth.frame);
            }
            if let Some(memory) = &mut self.memory {
                if self.stacked == 0 {
                    memory.clear();
                }
                memory.update(self.odom_pose, self.obs.depth.latest(), self.obs.laser.latest_mut());
            }
            if self.stacked == 0 {
                // As after a reset in the simulator: the first frame fills the stack.
                self.obs.laser.fill_with_latest();
                self.obs.depth.fill_with_latest();
                self.obs.odom = [Velocity::default(); ODOM_HISTORY];
            }
            self.obs.odom.rotate_left(1);
            self.obs.odom[ODOM_HISTORY - 1] = self.odom_velocity;
            self.stacked += 1;
            let started = Instant::now();
            let obs = &self.obs;
            // A panicking backend is an inference error, not a dead node.
            let decided = mdrlat_core::catch_panic("the policy", || {
                mdrlat_core::decide_one(policy, obs, 0).map(|d| d.action)
            })
            .map_err(|e| e.to_string());
            match decided {
                Ok(a) => {
                    action = Some(a);
                    self.inference_error = None;
                }
                Err(e) => {
                    self.inference_error = Some(e);
                    stops.push(Stop::Inference);
                }
            }
            // A slow decision may have outlived its inputs' freshness.
            let after = (now + started.elapsed()).max(Instant::now());
            if action.is_some() {
                stops.extend(self.sensor_stops(after));
            }
        } else {
            // Frames from before a stop must not mix with frames after it.
            self.stacked = 0;
        }
        // Incident log: one line when the set of reasons changes.
        if stops != self.stops {
            if stops.is_empty() {
                logs.push("all sensors valid and fresh: driving".to_string());
            } else {
                let new: Vec<String> = stops
                    .iter()
                    .filter(|s| !self.stops.contains(s))
                    // malformed messages were logged when they arrived
                    .filter(|s| !matches!(s, Stop::Malformed(_)))
                    .map(|s| self.describe(s, now))
                    .collect();
                if !new.is_empty() {
                    logs.push(format!("zero velocity: {}", new.join("; ")));
                }
            }
            self.stops = stops;
        }
        let velocity = match action {
            Some(a) if self.stops.is_empty() => self.clamp(a.command()),
            _ => Velocity::default(),
        };
        (Command { velocity, action: action.filter(|_| self.stops.is_empty()) }, logs)
    }

    fn clamp(&self, c: Velocity) -> Velocity {
        let (v, w) = (self.config.max_linear_mps, self.config.max_angular_radps);
        Velocity::new(c.v.clamp(-v, v), c.w.clamp(-w, w))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::Header;

    /// Records what it is given and answers a fixed action (or an error).
    struct Fixed {
        action: usize,
        fail: bool,
        seen: Vec<(Vec<f32>, Vec<f32>)>,
    }

    impl Policy for Fixed {
        fn name(&self) -> String {
            "fixed".into()
        }
        fn sensors(&self) -> mdrlat_core::Sensors {
            mdrlat_core::Sensors::BOTH
        }
        fn decide(
            &mut self,
            batch: &[&Observation],
            _slots: &[usize],
            out: &mut Vec<mdrlat_core::Decision>,
        ) -> Result<(), mdrlat_core::PolicyError> {
            // What a network gets: the stacks through the one normalisation.
            let obs = batch[0];
            let mut laser = vec![0.0; 4 * LASER_BEAMS];
            let mut depth = vec![0.0; 4 * DEPTH_LEN];
            obs.laser.write_stacked(&mut laser, mdrlat_core::normalize_laser);
            obs.depth.write_stacked(&mut depth, mdrlat_core::normalize_depth);
            self.seen.push((laser, depth));
            assert!(self.action < 10, "out of actions");
            out.clear();
            if self.fail {
                Err(mdrlat_core::PolicyError::Backend("backend lost".into()))
            } else {
                out.push(Action::new(self.action).expect("an action of Table 1").into());
                Ok(())
            }
        }
    }

    fn scan(range: f32) -> LaserScan {
        let fov = 270f32.to_radians();
        LaserScan {
            header: Header::default(),
            angle_min: -fov / 2.0,
            angle_max: fov / 2.0,
            angle_increment: fov / 511.0,
            range_max: 5.6,
            ranges: vec![range; 512],
            ..LaserScan::default()
        }
    }

    fn image(depth: f32) -> Image {
        Image {
            width: 160,
            height: 128,
            encoding: "32FC1".into(),
            step: 640,
            data: (0..160 * 128).flat_map(|_| depth.to_le_bytes()).collect(),
            ..Image::default()
        }
    }

    fn feed(c: &mut Controller, t: Instant, range: f32) {
        c.on_scan(t, Ok(&scan(range)));
        c.on_depth(t, Ok(&image(2.0)));
        c.on_odom(t, Ok(&Odometry::default()));
    }

    #[test]
    fn drives_stacks_and_normalises_like_the_simulator() {
        let mut c = Controller::new(ControllerConfig::default(), true, true);
        let mut p = Fixed { action: 2, fail: false, seen: Vec::new() };
        let t0 = Instant::now();
        let (cmd, logs) = c.tick(t0, &mut p);
        assert_eq!(cmd.velocity, Velocity::default(), "no data yet");
        assert_eq!(logs.len(), 1);
        assert!(logs[0].contains("waiting for the first laser scan"), "{logs:?}");
        for (k, range) in [1.0, 2.0, 3.0].into_iter().enumerate() {
            let t = t0 + Duration::from_millis(200 * (k as u64 + 1));
            feed(&mut c, t, range);
            let (cmd, logs) = c.tick(t, &mut p);
            assert_eq!(cmd.action.map(Action::index), Some(2));
            assert_eq!(cmd.velocity, Action::new(2).map(Action::command).unwrap_or_default());
            assert_eq!(logs.len(), usize::from(k == 0), "{logs:?}");
        }
        // First decision: the stack is four copies of the first frame; then one per tick.
        let laser_of = |i: usize, frame: usize| p.seen[i].0[frame * 512];
        assert_eq!([0, 1, 2, 3].map(|f| laser_of(0, f)), [1.0 / 5.6; 4]);
        assert_eq!(
            [0, 1, 2, 3].map(|f| laser_of(2, f)),
            [1.0 / 5.6, 1.0 / 5.6, 2.0 / 5.6, 3.0 / 5.6]
        );
        assert_eq!(p.seen[0].1[0], 2.0 / 5.0);
    }

    #[test]
    fn stale_sensors_stop_the_robot_with_one_log_line() {
        let mut c = Controller::new(ControllerConfig::default(), true, true);
        let mut p = Fixed { action: 1, fail: false, seen: Vec::new() };
        let t0 = Instant::now();
        feed(&mut c, t0, 2.0);
        assert!(c.tick(t0, &mut p).0.action.is_some());
        let mut lines = Vec::new();
        for k in 1..20 {
            let t = t0 + Duration::from_millis(120 * k);
            c.on_scan(t, Ok(&scan(2.0))); // the laser keeps coming, the camera died
            c.on_odom(t, Ok(&Odometry::default()));
            let (cmd, logs) = c.tick(t, &mut p);
            if k > 4 {
                assert_eq!(cmd.velocity, Velocity::default(), "tick {k}");
            } else {
                assert!(cmd.action.is_some(), "tick {k}");
            }
            lines.extend(logs);
        }
        assert_eq!(lines.len(), 1, "{lines:?}");
        assert!(lines[0].contains("depth image is stale"), "{lines:?}");
        // The camera comes back: one line, driving again from a fresh stack.
        let t = t0 + Duration::from_secs(3);
        feed(&mut c, t, 4.0);
        let (cmd, logs) = c.tick(t, &mut p);
        assert!(cmd.action.is_some());
        assert_eq!(logs, vec!["all sensors valid and fresh: driving".to_string()]);
        let last = p.seen.last().map(|s| s.0.clone()).unwrap_or_default();
        assert!(last.iter().all(|&x| x == 4.0 / 5.6), "no frame from before the stop");
    }

    #[test]
    fn malformed_messages_stop_once_and_recover() {
        let mut c = Controller::new(ControllerConfig::default(), true, true);
        let mut p = Fixed { action: 1, fail: false, seen: Vec::new() };
        let t0 = Instant::now();
        feed(&mut c, t0, 2.0);
        c.tick(t0, &mut p);
        let mut bad = image(2.0);
        bad.data.truncate(100);
        let mut lines = Vec::new();
        for k in 1..10 {
            let t = t0 + Duration::from_millis(50 * k);
            lines.extend(c.on_depth(t, Ok(&bad)));
            c.on_scan(t, Ok(&scan(2.0)));
            let (cmd, logs) = c.tick(t, &mut p);
            assert_eq!(cmd.velocity, Velocity::default());
            lines.extend(logs);
        }
        assert_eq!(lines.len(), 1, "{lines:?}");
        assert!(lines[0].contains("depth image rejected: data has 100 bytes"), "{lines:?}");
        let t = t0 + Duration::from_secs(1);
        let back = c.on_depth(t, Ok(&image(2.0)));
        assert_eq!(back.as_deref(), Some("depth image: valid messages again"));
        c.on_odom(t, Ok(&Odometry::default()));
        c.on_scan(t, Ok(&scan(2.0)));
        assert!(c.tick(t, &mut p).0.action.is_some());
    }

    #[test]
    fn a_first_scan_that_does_not_cover_270_degrees_is_fatal() {
        let mut narrow = scan(2.0);
        narrow.angle_min = -1.5;
        narrow.angle_increment = 3.0 / 511.0;
        let mut c = Controller::new(ControllerConfig::default(), true, true);
        let t = Instant::now();
        assert!(c.on_scan(t, Ok(&narrow)).is_some_and(|l| l.contains("the scan covers")));
        assert!(c.fatal().is_some_and(|e| e.contains("−135° to 135°")), "{:?}", c.fatal());
        // After good scans, a narrow one is an incident (zero velocity), not a set-up error.
        let mut c = Controller::new(ControllerConfig::default(), true, true);
        c.on_scan(t, Ok(&scan(2.0)));
        assert!(c.on_scan(t, Ok(&narrow)).is_some());
        assert_eq!(c.fatal(), None);
        let opt_in = ScanOptions { fill_gaps: true, ..ScanOptions::default() };
        let mut c = Controller::new(
            ControllerConfig { scan: opt_in, ..ControllerConfig::default() },
            true,
            true,
        );
        assert_eq!(c.on_scan(t, Ok(&narrow)), None);
        assert_eq!(c.fatal(), None);
    }

    #[test]
    fn inference_errors_stop_and_commands_are_clamped() {
        let config = ControllerConfig {
            max_linear_mps: 0.3,
            max_angular_radps: 9.0,
            ..ControllerConfig::default()
        };
        let mut c = Controller::new(config, true, true);
        assert_eq!(c.config().max_angular_radps, std::f32::consts::FRAC_PI_3);
        let mut p = Fixed { action: 0, fail: true, seen: Vec::new() };
        let t0 = Instant::now();
        feed(&mut c, t0, 2.0);
        let (cmd, logs) = c.tick(t0, &mut p);
        assert_eq!(cmd.velocity, Velocity::default());
        assert!(logs.iter().any(|l| l.contains("inference failed: backend lost")), "{logs:?}");
        assert!(c.tick(t0, &mut p).1.is_empty(), "not once per tick");
        p.fail = false;
        let (cmd, _) = c.tick(t0, &mut p);
        assert_eq!(cmd.velocity.v, 0.3, "0.5 m/s clamped to the flag's 0.3");
        assert_eq!(cmd.velocity.w, -std::f32::consts::PI / 12.0);
        // A panicking policy: zero velocity and a log line, and the controller lives on.
        p.action = 99;
        let (cmd, logs) = c.tick(t0, &mut p);
        assert_eq!(cmd.velocity, Velocity::default());
        assert!(logs.iter().any(|l| l.contains("panicked: out of actions")), "{logs:?}");
        p.action = 1;
        assert!(c.tick(t0, &mut p).0.action.is_some());
    }

    #[test]
    fn the_scan_with_the_cameras_memory_is_the_simulators() {
        // The laser sees nothing within 5 m; the camera a surface 1 m ahead at every
        // height (one frame), then nothing while odometry turns the robot 90° left.
        let mut c = Controller::new(ControllerConfig::default(), true, false).with_depth_memory(3);
        let mut p = Fixed { action: 9, fail: false, seen: Vec::new() };
        let mut same = ScanMemory::spec(3).expect("a memory");
        let t0 = Instant::now();
        let mut latest = Vec::new();
        for k in 0..5u64 {
            let t = t0 + Duration::from_millis(200 * k);
            let yaw = if k == 0 { 0.0 } else { std::f64::consts::FRAC_PI_2 };
            let depth = if k == 0 { 1.0 } else { 0.0 };
            c.on_scan(t, Ok(&scan(5.0)));
            c.on_depth(t, Ok(&image(depth)));
            let odom = Odometry {
                position: crate::msg::Vector3 { x: 1.0, y: -2.0, z: 0.0 },
                orientation: crate::msg::Quaternion::from_yaw(yaw),
                ..Odometry::default()
            };
            c.on_odom(t, Ok(&odom));
            assert!(c.tick(t, &mut p).0.action.is_some(), "it drives");
            // The simulator's memory, given the same frame, pose and scan.
            let mut expected = vec![5.0f32; LASER_BEAMS];
            let frame = vec![depth; DEPTH_LEN];
            same.update([1.0, -2.0, yaw as f32], &frame, &mut expected);
            let mut normalised = vec![0.0; LASER_BEAMS];
            mdrlat_core::normalize_laser(&expected, &mut normalised);
            let seen = &p.seen.last().expect("seen").0[3 * LASER_BEAMS..];
            assert_eq!(seen, normalised.as_slice(), "tick {k}");
            latest.push(expected);
        }
        let beams = |scan: &[f32], from: f32, to: f32| -> Vec<f32> {
            (0..LASER_BEAMS)
                .filter(|&i| (from..=to).contains(&mdrlat_core::laser_beam_angle(i).to_degrees()))
                .map(|i| scan[i])
                .collect()
        };
        // Seen ahead, the surface is drawn 1 m ahead; turned left, it lies to the right
        // for the memory's 3 frames, and is forgotten after.
        assert!(beams(&latest[0], -20.0, 20.0).iter().all(|&r| (0.99..1.2).contains(&r)));
        assert!(beams(&latest[2], -100.0, -80.0).iter().all(|&r| (0.99..1.2).contains(&r)));
        assert!(latest[3].iter().all(|&r| r == 5.0), "forgotten after 3 frames");
        assert!(c.sensors().contains(&Sensor::Depth), "it needs the camera now");
    }
}
