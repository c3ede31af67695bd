//! The one policy interface: a batch of observations in, one [`Decision`] (an action of
//! Table 1 and the velocity command the robot executes) per observation out. A single
//! decision is the batch of one ([`decide_one`]).
//!
//! Everything that drives the robot implements [`Policy`]: the scripted baselines of the
//! simulator, a trained Q-network (batched: one forward for every environment of a
//! `VecEnv`), and whatever the ROS node deploys. Training's evaluation, `rollout`, `eval`,
//! the ROS node and the tests all call it, so acting has one definition — including the one
//! rule for Q-values that are not finite ([`greedy_actions`]).

use crate::action::{Action, Velocity};
use crate::obs::Observation;
use std::fmt;

/// The sensors a policy reads (a deployment checks that it receives them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sensors {
    /// It reads the 2D laser.
    pub laser: bool,
    /// It reads the depth camera.
    pub depth: bool,
}

impl Sensors {
    /// Both sensors.
    pub const BOTH: Sensors = Sensors { laser: true, depth: true };
    /// Neither (a policy that ignores its observations).
    pub const NONE: Sensors = Sensors { laser: false, depth: false };
}

/// Why a policy could not decide.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum PolicyError {
    /// Observation `row` of the batch got a non-finite Q-value: acting on it would be a guess.
    NonFinite {
        /// Row of the batch.
        row: usize,
        /// Its Q-values.
        values: Vec<f32>,
    },
    /// The policy produced `got` actions for `expected` observations.
    Count {
        /// Observations in the batch.
        expected: usize,
        /// Actions or Q-value rows produced.
        got: usize,
    },
    /// The computation itself failed (a backend error, an input of the wrong size, a panic).
    Backend(String),
}

impl fmt::Display for PolicyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PolicyError::NonFinite { row, values } => {
                write!(f, "non-finite Q-values for observation {row} of the batch: {values:?}")
            }
            PolicyError::Count { expected, got } => {
                write!(f, "the policy decided {got} actions for {expected} observations")
            }
            PolicyError::Backend(e) => f.write_str(e),
        }
    }
}

impl std::error::Error for PolicyError {}

/// One decision: the Table 1 action and the velocity command the robot executes. For the
/// discrete policies (every network, the scripted baselines) the command is the action's
/// Table 1 velocity; a continuous controller (the classical planner) gives its own command
/// and the nearest Table 1 action, for the records.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// The action (a record's `action` column; what a network learns from).
    pub action: Action,
    /// The velocity command the robot executes.
    pub command: Velocity,
}

impl From<Action> for Decision {
    fn from(action: Action) -> Self {
        Decision { action, command: action.command() }
    }
}

impl Decision {
    /// A continuous controller's command, recorded as the nearest Table 1 action.
    pub fn continuous(command: Velocity) -> Self {
        Decision { action: Action::nearest(command), command }
    }
}

/// Anything that decides from observations.
///
/// A caller stepping several environments at once gives each its *slot* (0, 1, …) and
/// passes the observations of the slots that are running, in any subset and order, with
/// their slot numbers. A policy with state (the random policy's stream) keys it by slot and
/// restarts it in [`Policy::begin_episode`], so an episode's actions depend on that
/// episode alone, never on which other episodes ran beside it.
pub trait Policy: Send {
    /// A short name for logs and reports, e.g. `wander` or `mdrlat (runs/a, step 400000)`.
    fn name(&self) -> String;

    /// The sensors it reads.
    fn sensors(&self) -> Sensors;

    /// Frames of the depth camera's hidden obstacles drawn into the laser scan it reads
    /// (the simulator's `sim.laser.depth_memory_frames`; 0, the default: the laser's own
    /// scan). Whatever feeds it observations (the simulator, the ROS nodes) must draw the
    /// same scan.
    fn depth_memory_frames(&self) -> u32 {
        0
    }

    /// Slot `slot` starts an episode. With `Some(seed)` a stateful policy restarts its
    /// randomness from that episode seed; with `None` it continues it.
    fn begin_episode(&mut self, slot: usize, seed: Option<u64>) {
        let _ = (slot, seed);
    }

    /// One decision per observation of `batch` (oldest frame first, metres, as
    /// [`Observation`] holds them) into `out`, which is cleared first; `slots[i]` is the
    /// slot of `batch[i]`. The episode runner drives the robot with the decisions' commands.
    ///
    /// # Errors
    /// The policy cannot decide (see [`PolicyError`]); the caller must not guess an action.
    fn decide(
        &mut self,
        batch: &[&Observation],
        slots: &[usize],
        out: &mut Vec<Decision>,
    ) -> Result<(), PolicyError>;
}

/// One decision for one observation in slot `slot`: the batch of one.
///
/// # Errors
/// The policy's, or [`PolicyError::Count`] if it decided other than once.
pub fn decide_one(
    policy: &mut dyn Policy,
    obs: &Observation,
    slot: usize,
) -> Result<Decision, PolicyError> {
    let mut out = Vec::with_capacity(1);
    policy.decide(&[obs], &[slot], &mut out)?;
    match out.as_slice() {
        [d] => Ok(*d),
        _ => Err(PolicyError::Count { expected: 1, got: out.len() }),
    }
}

/// Checks that every observation of a batch comes with its slot.
///
/// # Errors
/// [`PolicyError::Backend`] naming both lengths.
pub fn check_batch(batch: &[&Observation], slots: &[usize]) -> Result<(), PolicyError> {
    if batch.len() != slots.len() {
        return Err(PolicyError::Backend(format!(
            "{} observations but {} slots",
            batch.len(),
            slots.len()
        )));
    }
    Ok(())
}

/// The loop of every policy that decides observation by observation: checks that each
/// observation of `batch` comes with its slot, then fills `out` (cleared first) with
/// `decide(slot, observation)` for each, in order.
///
/// # Errors
/// [`check_batch`]'s, or the first error of `decide`.
pub fn decide_each<D: Into<Decision>>(
    batch: &[&Observation],
    slots: &[usize],
    out: &mut Vec<Decision>,
    mut decide: impl FnMut(usize, &Observation) -> Result<D, PolicyError>,
) -> Result<(), PolicyError> {
    check_batch(batch, slots)?;
    out.clear();
    for (obs, &slot) in batch.iter().zip(slots) {
        out.push(decide(slot, obs)?.into());
    }
    Ok(())
}

/// Runs a decision, turning a panic inside it (a backend's bug) into a
/// [`PolicyError::Backend`] that names `what` panicked and why: a failed decision the caller
/// can report (the ROS node stops the robot), not a crash.
///
/// # Errors
/// `decide`'s own error, or the panic.
pub fn catch_panic<T>(
    what: &str,
    decide: impl FnOnce() -> Result<T, PolicyError>,
) -> Result<T, PolicyError> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(decide)).unwrap_or_else(|panic| {
        let why = panic
            .downcast_ref::<&str>()
            .map(|s| (*s).to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        Err(PolicyError::Backend(format!("{what} panicked: {why}")))
    })
}

/// The greedy action of each row of `q` (`rows` × [`Action::COUNT`], row-major) into `out`
/// (cleared first): the first maximum on ties.
///
/// # Errors
/// [`PolicyError::NonFinite`] for a row with a NaN or infinite value (no action is taken
/// from a network that has diverged or read garbage); [`PolicyError::Count`] if `q` does
/// not hold `rows` rows.
pub fn greedy_actions(q: &[f32], rows: usize, out: &mut Vec<Action>) -> Result<(), PolicyError> {
    out.clear();
    if q.len() != rows * Action::COUNT {
        return Err(PolicyError::Count { expected: rows, got: q.len() / Action::COUNT });
    }
    for (row, values) in q.chunks_exact(Action::COUNT).enumerate() {
        if values.iter().any(|v| !v.is_finite()) {
            return Err(PolicyError::NonFinite { row, values: values.to_vec() });
        }
        let best = values
            .iter()
            .enumerate()
            .fold((0, f32::NEG_INFINITY), |b, (i, &v)| if v > b.1 { (i, v) } else { b })
            .0;
        out.push(Action::new(best).unwrap_or_else(|| unreachable!("row of Action::COUNT")));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn panics_become_errors_and_batches_need_their_slots() {
        let e = catch_panic::<()>("the backend", || panic!("out of memory")).expect_err("panic");
        assert_eq!(e, PolicyError::Backend("the backend panicked: out of memory".into()));
        assert_eq!(catch_panic("x", || Ok(3)), Ok(3));
        let obs = Observation::zeros();
        assert!(check_batch(&[&obs], &[0]).is_ok());
        let e = check_batch(&[&obs, &obs], &[0]).expect_err("short");
        assert!(e.to_string().contains("2 observations but 1 slots"), "{e}");
    }

    #[test]
    fn greedy_actions_take_the_first_maximum_and_refuse_non_finite_rows() {
        let mut q = vec![0.0f32; 2 * Action::COUNT];
        q[3] = 2.0;
        q[7] = 2.0;
        q[Action::COUNT + 9] = -0.5;
        for v in &mut q[Action::COUNT..Action::COUNT + 9] {
            *v = -1.0;
        }
        let mut out = Vec::new();
        greedy_actions(&q, 2, &mut out).expect("finite");
        assert_eq!(out.iter().map(|a| a.index()).collect::<Vec<_>>(), [3, 9]);
        q[Action::COUNT + 2] = f32::NAN;
        let e = greedy_actions(&q, 2, &mut out).expect_err("NaN");
        assert!(matches!(e, PolicyError::NonFinite { row: 1, .. }), "{e:?}");
        assert!(e.to_string().contains("observation 1"), "{e}");
        q[Action::COUNT + 2] = f32::INFINITY;
        assert!(greedy_actions(&q, 2, &mut out).is_err());
        let e = greedy_actions(&q[..Action::COUNT], 2, &mut out).expect_err("short");
        assert_eq!(e, PolicyError::Count { expected: 2, got: 1 });
    }
}
