//! A recorded episode: one row per step, written as CSV with fixed precision so the same
//! seed gives the same bytes.

use crate::env::StepInfo;
use mdrlat_core::Action;
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
