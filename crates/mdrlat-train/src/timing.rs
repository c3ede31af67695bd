//! Where a training session's wall time goes.

use std::time::Instant;

/// Where a training session's wall time went, seconds.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Timing {
    /// Greedy decisions of ε-greedy (Algorithm 1, line 3).
    pub acting: f64,
    /// Environment steps (line 4).
    pub env: f64,
    /// Storing transitions, and the resets of episodes that ended (line 5).
    pub storing: f64,
    /// Sampling batches from the replay buffer (line 6).
    pub sampling: f64,
    /// Gradient steps and target syncs (lines 7–18).
    pub learning: f64,
    /// Greedy evaluations.
    pub evaluation: f64,
    /// Metrics, TensorBoard events, checkpoints, progress.
    pub output: f64,
}

impl Timing {
    /// The parts, named, in loop order.
    pub fn parts(&self) -> [(&'static str, f64); 7] {
        [
            ("acting", self.acting),
            ("env", self.env),
            ("storing", self.storing),
            ("sampling", self.sampling),
            ("learning", self.learning),
            ("evaluation", self.evaluation),
            ("output", self.output),
        ]
    }
}

/// A stopwatch that adds the time since its last split to one part of [`Timing`].
pub(crate) struct Clock {
    last: Instant,
    /// The sums so far.
    pub(crate) timing: Timing,
}

impl Clock {
    pub(crate) fn start() -> Self {
        Clock { last: Instant::now(), timing: Timing::default() }
    }
    /// Adds the time since the last split to the part `part` picks.
    pub(crate) fn split(&mut self, part: fn(&mut Timing) -> &mut f64) {
        let now = Instant::now();
        *part(&mut self.timing) += (now - self.last).as_secs_f64();
        self.last = now;
    }
}
