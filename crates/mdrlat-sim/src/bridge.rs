//! The simulator as a robot on a middleware: what a bridge does whatever carries its
//! messages (ROS 1 today in `mdrlat_ros::sim`, ROS 2 next). The transport hands in the
//! latest velocity command and publishes each [`SensorFrame`]; this module paces the
//! simulator at wall-clock time, drops stale or malformed commands and brakes as a Kobuki
//! base does, clamps to the base's limits, restarts episodes, and counts what happened.

use crate::env::{Env, SimError, StepInfo};
use mdrlat_core::Velocity;
use mdrlat_geom::{Pose2, Vec2};
use std::time::{Duration, Instant};

/// The fastest a Kobuki base drives, m/s; commands are clamped to it.
pub const KOBUKI_MAX_V: f32 = 0.7;
/// The fastest a Kobuki base turns, rad/s.
pub const KOBUKI_MAX_W: f32 = std::f32::consts::PI;

/// How the simulated robot runs.
#[derive(Debug, Clone, PartialEq)]
pub struct BridgeSettings {
    /// Seed of the start poses and pedestrians (episode k from stream k).
    pub seed: u64,
    /// A command older than this is dropped and the robot brakes, seconds.
    pub cmd_timeout_s: f32,
    /// Simulated seconds per wall-clock second.
    pub speed: f32,
    /// Stop after this many wall-clock seconds (0: until the transport says stop).
    pub duration_s: f32,
}

impl BridgeSettings {
    /// Checks the numbers, naming the bad one by its field (`speed`, `cmd_timeout_s`,
    /// `duration_s`).
    ///
    /// # Errors
    /// A speed outside [0.01, 100], a timeout outside (0, 60] or a negative duration.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.speed.is_finite() && (0.01..=100.0).contains(&self.speed)) {
            return Err(format!("speed {}: expected a factor in [0.01, 100]", self.speed));
        }
        let t = self.cmd_timeout_s;
        if !(t.is_finite() && t > 0.0 && t <= 60.0) {
            return Err(format!("cmd_timeout_s {t}: expected seconds in (0, 60]"));
        }
        if !(self.duration_s.is_finite() && self.duration_s >= 0.0) {
            return Err(format!(
                "duration_s {}: expected a non-negative number of seconds",
                self.duration_s
            ));
        }
        Ok(())
    }
}

/// A velocity command as a transport received it (metres and radians per second, as sent:
/// possibly non-finite or beyond the base's limits).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Received {
    /// Forward speed.
    pub v: f64,
    /// Turn rate.
    pub w: f64,
    /// When it arrived.
    pub at: Instant,
}

/// What the robot's sensors read now, for a transport to publish.
#[derive(Debug, Clone, Copy)]
pub struct SensorFrame<'a> {
    /// The newest laser scan, metres per beam (0 = no return).
    pub ranges: &'a [f32],
    /// The laser's maximum range, metres.
    pub range_max_m: f32,
    /// The newest depth image, row-major metres (0 = no reading).
    pub depth: &'a [f32],
    /// The pose in the odometry frame.
    pub pose: Pose2,
    /// The measured velocity.
    pub velocity: Velocity,
    /// Seconds per step.
    pub dt_s: f32,
    /// Frames published so far (the headers' sequence number).
    pub seq: u32,
}

/// The middleware side of a bridge.
pub trait Transport {
    /// The latest velocity command received, if any.
    fn latest_command(&mut self) -> Option<Received>;
    /// Publishes the sensors' readings.
    fn publish(&mut self, frame: &SensorFrame<'_>);
    /// Whether to stop (Ctrl-C, a shutdown request of the middleware).
    fn stopped(&self) -> bool;
}

/// One step as it happened.
#[derive(Debug, Clone, Copy)]
pub struct BridgeStep {
    /// Wall-clock seconds since the start.
    pub t_s: f64,
    /// The episode.
    pub episode: u64,
    /// The command the robot executed (after timeout, clamping).
    pub command: Velocity,
    /// The simulator's account of the step.
    pub info: StepInfo,
    /// The step's reward (eq. 4).
    pub reward: f32,
    /// Whether the episode ended with it.
    pub ended: bool,
}

/// What a caller watches: each step (a trajectory log) and each ended episode (a picture of
/// it, drawn before the next episode begins).
pub trait BridgeObserver {
    /// A step was taken.
    ///
    /// # Errors
    /// The observer failed (a log that cannot be written): the bridge stops.
    fn step(&mut self, step: &BridgeStep) -> Result<(), String> {
        let _ = step;
        Ok(())
    }
    /// An episode ended; `env` still shows its last state and `trail` its path.
    fn episode_ended(&mut self, env: &Env, trail: &[Vec2], step: &BridgeStep) {
        let _ = (env, trail, step);
    }
    /// The bridge stops in `episode`, which `env` and `trail` show as it stands.
    fn stopped(&mut self, env: &Env, trail: &[Vec2], episode: u64) {
        let _ = (env, trail, episode);
    }
}

/// What a bridge did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BridgeSummary {
    /// Steps taken.
    pub steps: u64,
    /// Episodes begun.
    pub episodes: u64,
    /// Episodes that ended in a collision.
    pub collisions: u64,
    /// Metres driven.
    pub distance_m: f64,
    /// Wall-clock seconds.
    pub seconds: f64,
}

/// Why a bridge stopped early.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BridgeError {
    /// The settings are unusable.
    #[error("{0}")]
    Settings(String),
    /// The simulator failed.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The observer failed.
    #[error("{0}")]
    Observer(String),
}

/// The command the base executes: the latest one while fresh and finite, clamped to the
/// Kobuki's limits; otherwise it brakes.
pub fn base_command(latest: Option<Received>, now: Instant, timeout: Duration) -> Velocity {
    match latest {
        Some(r) if now.duration_since(r.at) <= timeout && r.v.is_finite() && r.w.is_finite() => {
            Velocity::new(
                (r.v as f32).clamp(-KOBUKI_MAX_V, KOBUKI_MAX_V),
                (r.w as f32).clamp(-KOBUKI_MAX_W, KOBUKI_MAX_W),
            )
        }
        _ => Velocity::default(),
    }
}

fn frame(env: &Env, seq: u32, velocity: Velocity) -> SensorFrame<'_> {
    let obs = env.observation();
    SensorFrame {
        ranges: obs.laser.latest(),
        range_max_m: env.laser().config().max_range_m,
        depth: obs.depth.latest(),
        pose: env.pose(),
        velocity,
        dt_s: env.config().dt_s,
        seq,
    }
}

/// Runs `env` as a robot on `transport` until it says stop or `settings.duration_s` has
/// passed: a step every `dt / speed` wall-clock seconds with the latest command, the
/// sensors published after each, a new episode (the next stream of `settings.seed`) after
/// each collision or time limit.
///
/// # Errors
/// Bad settings, a simulator failure or a failing observer.
pub fn run(
    env: &mut Env,
    settings: &BridgeSettings,
    transport: &mut dyn Transport,
    observer: &mut dyn BridgeObserver,
) -> Result<BridgeSummary, BridgeError> {
    settings.validate().map_err(BridgeError::Settings)?;
    let period = Duration::from_secs_f32(env.config().dt_s / settings.speed);
    let timeout = Duration::from_secs_f32(settings.cmd_timeout_s);
    let (mut episode, mut seq) = (0u64, 0u32);
    env.reset_stream(settings.seed, episode)?;
    let start = Instant::now();
    let mut trail: Vec<Vec2> = vec![env.pose().position()];
    let mut summary = BridgeSummary::default();
    transport.publish(&frame(env, seq, Velocity::default()));
    let mut next = Instant::now() + period;
    while !transport.stopped() {
        if settings.duration_s > 0.0 && start.elapsed().as_secs_f32() >= settings.duration_s {
            break;
        }
        let now = Instant::now();
        if next > now {
            std::thread::sleep((next - now).min(Duration::from_millis(50)));
            continue;
        }
        next += period;
        let command = base_command(transport.latest_command(), now, timeout);
        let before = env.pose().position();
        let s = env.step_command(command)?;
        let (info, reward, ended) = (s.info, s.reward, s.terminated || s.truncated);
        (summary.steps, seq) = (summary.steps + 1, seq.wrapping_add(1));
        summary.distance_m += f64::from((info.pose.position() - before).length());
        trail.push(info.pose.position());
        let t_s = start.elapsed().as_secs_f64();
        let step = BridgeStep { t_s, episode, command, info, reward, ended };
        observer.step(&step).map_err(BridgeError::Observer)?;
        if ended {
            summary.collisions += u64::from(info.collision.is_some());
            observer.episode_ended(env, &trail, &step);
            trail.clear();
            episode += 1;
            env.reset_stream(settings.seed, episode)?;
            trail.push(env.pose().position());
        }
        transport.publish(&frame(env, seq, info.velocity));
    }
    observer.stopped(env, &trail, episode);
    summary.episodes = episode + 1;
    summary.seconds = start.elapsed().as_secs_f64();
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stale_malformed_and_excessive_commands_brake_or_clamp() {
        let now = Instant::now();
        let timeout = Duration::from_millis(500);
        let at = |v, w, ago_ms| Received { v, w, at: now - Duration::from_millis(ago_ms) };
        assert_eq!(base_command(None, now, timeout), Velocity::default());
        assert_eq!(base_command(Some(at(0.3, 0.5, 10)), now, timeout), Velocity::new(0.3, 0.5));
        assert_eq!(base_command(Some(at(0.3, 0.5, 600)), now, timeout), Velocity::default());
        assert_eq!(base_command(Some(at(f64::NAN, 0.5, 10)), now, timeout), Velocity::default());
        assert_eq!(
            base_command(Some(at(2.0, -9.0, 10)), now, timeout),
            Velocity::new(KOBUKI_MAX_V, -KOBUKI_MAX_W)
        );
    }

    /// A transport that drives forward for a number of frames, then stops.
    struct Scripted {
        frames: u32,
        seqs: Vec<u32>,
    }

    impl Transport for Scripted {
        fn latest_command(&mut self) -> Option<Received> {
            Some(Received { v: 0.5, w: 0.0, at: Instant::now() })
        }
        fn publish(&mut self, frame: &SensorFrame<'_>) {
            assert_eq!(frame.ranges.len(), mdrlat_core::LASER_BEAMS);
            assert_eq!(frame.depth.len(), mdrlat_core::DEPTH_ROWS * mdrlat_core::DEPTH_COLS);
            self.seqs.push(frame.seq);
        }
        fn stopped(&self) -> bool {
            self.seqs.len() as u32 > self.frames
        }
    }

    #[test]
    fn the_robot_drives_on_commands_and_publishes_every_step() {
        let world = mdrlat_world::builtin::get("example").expect("builtin").expect("valid");
        let config = crate::SimConfig { max_episode_steps: 5, ..crate::SimConfig::default() };
        let mut env = Env::from_world(world, config).expect("env");
        let settings =
            BridgeSettings { seed: 3, cmd_timeout_s: 0.5, speed: 100.0, duration_s: 0.0 };
        let mut t = Scripted { frames: 12, seqs: Vec::new() };
        #[derive(Default)]
        struct Count(u32, u32);
        impl BridgeObserver for Count {
            fn step(&mut self, _: &BridgeStep) -> Result<(), String> {
                self.0 += 1;
                Ok(())
            }
            fn episode_ended(&mut self, _: &Env, trail: &[Vec2], s: &BridgeStep) {
                assert_eq!(trail.len() as u32, s.info.step + 1, "the episode's whole path");
                self.1 += 1;
            }
        }
        let mut seen = Count::default();
        let summary = run(&mut env, &settings, &mut t, &mut seen).expect("runs");
        assert_eq!(t.seqs, (0..=12).collect::<Vec<u32>>(), "one frame before the first step");
        assert_eq!((summary.steps, seen.0), (12, 12));
        assert!(summary.distance_m > 0.1, "it drove: {summary:?}");
        assert_eq!(seen.1 as u64, summary.episodes - 1, "every ended episode was reported");
        assert!(summary.episodes >= 3, "5-step episodes restart: {summary:?}");
        let bad = BridgeSettings { speed: 0.0, ..settings };
        assert!(run(&mut env, &bad, &mut t, &mut seen).is_err());
    }
}
