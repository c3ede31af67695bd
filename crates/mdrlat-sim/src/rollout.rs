//! Recording an episode: one row per step, written as CSV with fixed precision so the same
//! seed gives the same bytes.

use crate::env::{Env, SimError, StepInfo};
use crate::policy::Policy;
use mdrlat_core::Action;
use mdrlat_geom::Pose2;
use std::fmt::Write as _;

/// One step of a trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrajectoryRow {
    /// The action taken.
    pub action: Action,
    /// Reward received.
    pub reward: f32,
    /// The step ended in a collision.
    pub terminated: bool,
    /// The step hit the time limit.
    pub truncated: bool,
    /// State after the step.
    pub info: StepInfo,
}

/// The CSV header of [`TrajectoryRow::to_csv`].
pub const CSV_HEADER: &str = "step,x,y,yaw,v,w,action,reward,terminated,truncated,d_min";

impl TrajectoryRow {
    /// The row as CSV (no newline).
    pub fn to_csv(&self) -> String {
        let i = &self.info;
        let mut s = String::with_capacity(96);
        let _ = write!(
            s,
            "{},{:.6},{:.6},{:.6},{:.6},{:.6},{},{:.6},{},{},{:.6}",
            i.step,
            i.pose.x,
            i.pose.y,
            i.pose.yaw,
            i.velocity.v,
            i.velocity.w,
            self.action,
            self.reward,
            self.terminated as u8,
            self.truncated as u8,
            i.d_min
        );
        s
    }
}

/// Runs `policy` for at most `max_steps` steps or until the episode ends, starting with
/// `env.reset_with(seed, pose)` (`None`, `None`: continue the random streams, draw a pose),
/// and calls `on_step` after every step (e.g. to write a row or draw a frame).
///
/// # Errors
/// The reset found no free pose, or `on_step` failed.
pub fn run_episode<E: From<SimError>>(
    env: &mut Env,
    policy: &mut dyn Policy,
    seed: Option<u64>,
    pose: Option<Pose2>,
    max_steps: u32,
    mut on_step: impl FnMut(&Env, &TrajectoryRow) -> Result<(), E>,
) -> Result<Vec<TrajectoryRow>, E> {
    env.reset_with(seed, pose)?;
    let mut rows = Vec::new();
    for _ in 0..max_steps {
        let action = policy.act(env.observation());
        let s = env.step(action)?;
        let row = TrajectoryRow {
            action,
            reward: s.reward,
            terminated: s.terminated,
            truncated: s.truncated,
            info: s.info,
        };
        rows.push(row);
        on_step(env, &row)?;
        if row.terminated || row.truncated {
            break;
        }
    }
    Ok(rows)
}
