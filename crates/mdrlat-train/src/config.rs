//! Training settings. Defaults are the paper's (section 3.1, Algorithm 1); every field can be
//! overridden from the `[train]` section of a config file or the command line.

use mdrlat_nn::Variant;
use serde::{Deserialize, Serialize};

/// Every hyper-parameter of a training run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    /// Network variant: laser-only, depth-only, multi, multi-at, multi-bf or mdrlat.
    pub variant: Variant,
    /// Environment steps of the run (paper: 400,000).
    pub total_steps: u64,
    /// Seed of the run: network initialisation, environment, exploration, replay sampling.
    pub seed: u64,
    /// Discount factor γ.
    pub gamma: f32,
    /// Steps of the returns the TD target bootstraps from (paper: 1): a stored transition
    /// carries `Σ_{i<n} γ^i r_{t+i}` and `s_{t+n}`, bootstrapped with `γ^n` (fewer steps at an
    /// episode's end). Up to 16.
    pub n_step: u32,
    /// Adam learning rate for the TD and auxiliary losses.
    pub learning_rate: f64,
    /// Adam ε (TensorFlow's default, as the authors' code).
    pub adam_epsilon: f32,
    /// Transitions per gradient step.
    pub batch_size: usize,
    /// Replay buffer capacity in transitions.
    pub replay_capacity: usize,
    /// Transitions in the buffer before learning starts.
    pub learning_starts: u64,
    /// Environment steps per gradient step (paper: 1).
    pub train_frequency: u64,
    /// Gradient steps taken each time `train_frequency` environment steps have passed
    /// (paper: 1).
    pub gradient_steps: u64,
    /// Environments stepped in turn (paper: 1): their greedy decisions are one batched
    /// forward pass, each env step is one of `total_steps`. With several training worlds
    /// environment k starts in world k (modulo their number) and moves to the next world at
    /// every episode's end.
    pub envs: usize,
    /// Steps between hard copies of the online network into the target network.
    pub target_update_interval: u64,
    /// ε of ε-greedy at the start.
    pub epsilon_start: f32,
    /// ε after the decay.
    pub epsilon_end: f32,
    /// Steps over which ε decays linearly.
    pub epsilon_decay_steps: u64,
    /// Demonstrations: during the first `demo_steps` environment steps an exploratory
    /// action (taken with probability ε) is, with probability `demo_share`, the classical
    /// `avoid` baseline's (`mdrlat_sim::AvoidPolicy`, which watches every step of every
    /// environment meanwhile) instead of a uniformly random one. Q-learning learns off-policy
    /// from both. 0: none (the paper). At most `checkpoint_interval`, so that no checkpoint
    /// falls inside them (`avoid`'s maps are not saved).
    pub demo_steps: u64,
    /// The share of exploratory actions that are `avoid`'s during `demo_steps`.
    pub demo_share: f32,
    /// Weight of the auxiliary loss (eq. 12): it scales that loss's gradient (with
    /// `aux_optimizer = "joint"`, its share of the summed loss).
    pub aux_loss_weight: f32,
    /// How the auxiliary loss (eq. 12) moves the network: `separate` (the paper's section 3.1,
    /// "two Adam optimizers", and the authors' code), its own Adam beside the TD loss's, each
    /// with its own moments, both from the same forward pass; `joint`, one Adam on
    /// `L_TD + aux_loss_weight · L_AT` (mdrlat before 2026-12-06; runs written then resume
    /// with it).
    pub aux_optimizer: AuxOptimizer,
    /// Polyak averaging of the policy (0: off, the paper's): every [`AVERAGE_EVERY`]
    /// gradient steps the run's averaged network moves toward the online one,
    /// `θ̄ ← (1 − w) θ̄ + w θ` with `w = max(AVERAGE_EVERY / average_horizon, 1 / n)` at the
    /// `n`-th move (a plain mean of the online weights until the horizon is reached, then an
    /// exponential average over about `average_horizon` gradient steps). The averaged
    /// network is what the run's evaluations, learning curves and `model.safetensors` use
    /// and what `mdrlat eval --checkpoint` reads; exploration and the TD targets use the
    /// online network as always.
    pub average_horizon: u64,
    /// Prioritised replay (Schaul et al. 2016, proportional; [`crate::priority`]): a
    /// transition is drawn with probability in proportion to `(|δ| + priority_epsilon)^α`,
    /// `δ` its last TD error, and its TD loss weighs `(N · P)^−β`. 0: uniform replay (the
    /// paper's); up to 1.
    pub priority_alpha: f32,
    /// β of the importance-sampling weights at step 0, annealed linearly to 1 over
    /// `priority_beta_steps` (with `priority_alpha` > 0). In [0, 1].
    pub priority_beta: f32,
    /// Environment steps over which β reaches 1 (fixed, not `total_steps`, so that a run
    /// extended with `--resume --steps` goes on as one long run would).
    pub priority_beta_steps: u64,
    /// The offset ε of the priorities, so that no transition's is 0. Positive.
    pub priority_epsilon: f32,
    /// Steps between greedy evaluations (Fig. 4).
    pub eval_interval: u64,
    /// Episodes per evaluation, from fixed start poses.
    pub eval_episodes: u32,
    /// Seed of the fixed evaluation start poses (the same for every run and variant), of the
    /// Fig. 4 episodes and of the learning curves' held-out starts.
    pub eval_seed: u64,
    /// Episodes per world of the learning curves: at every evaluation the greedy policy runs
    /// this many episodes of the evaluation protocol (300 steps, starts of `mdrlat eval
    /// --seed EVAL_SEED`, run 0) in the training world and in `curve_world`, and its moving
    /// success, paper success and mean path go into `eval.csv`, TensorBoard and Fig. 4
    /// (0: no curves).
    pub curve_episodes: u32,
    /// The unseen world of the learning curves: a built-in name, a `.toml` world file or a
    /// map_server `.yaml`; `auto`: the task's first test world (`office`, or `nav-test` in
    /// navigation); `none`: the training world only. `office` is also a Table 2 test world
    /// (the curves use other starts): choose checkpoints by it and the final table no longer
    /// measures an unseen world.
    pub curve_world: String,
    /// Metres a learning curve's episode must drive to count as a moving success (`mdrlat
    /// eval --min-path`).
    pub curve_min_path_m: f32,
    /// Metres from its start a learning curve's episode must get to count as a moving
    /// success (`mdrlat eval --min-reach`).
    pub curve_min_reach_m: f32,
    /// Steps between checkpoints.
    pub checkpoint_interval: u64,
    /// A checkpoint at the last step too, so that the finished run can be extended with
    /// `--resume --steps` (false: the finished run leaves its weights, `model.safetensors`,
    /// and no checkpoint — no optimiser state or replay — once `RunDir::finish` has run: the
    /// demo's 300-step run, and the `fast` sweep's 18 runs, whose replay buffers would take
    /// 2.4 GB each). A run killed midway resumes from its last checkpoint either way.
    pub final_checkpoint: bool,
    /// How the run's final `model.safetensors` stores its weights (`f16`: half the size,
    /// the same greedy actions in practice; the demo's pipeline check writes f16).
    pub model_precision: Precision,
    /// Minutes of training between two snapshots of the policy (0: none): at every multiple
    /// of it the network the run would ship (the averaged one where the run keeps one) is
    /// written to `snapshots/minute-MMMM.MMM/model.safetensors`, for evaluations at fixed
    /// minutes (`mdrlat eval --snapshots RUN`). Minutes count this process's wall time from
    /// the start of the loop plus the checkpoint's (`checkpoint/clock.json`), so a resumed
    /// run goes on counting where its checkpoint stood; the work redone after a restart
    /// counts once. Which step a snapshot lands on depends on the machine's speed: the
    /// training itself does not (snapshots touch no random stream). Snapshots are taken
    /// between ticks (`train.envs` steps), so an interval shorter than a tick skips some.
    /// 0 or 0.001 to 10,000.
    pub snapshot_minutes: f64,
    /// A warm start (empty: none, the paper's fresh initialisation): the run's online and
    /// target networks start from this trained model's weights instead of the seed's — a
    /// shipped model's folder or `.safetensors` file (f32 or f16), a run directory or a
    /// checkpoint folder (its averaged network where it keeps one), of the same variant and
    /// task. Only the weights: the replay buffer starts empty (`learning_starts` applies),
    /// both Adams start from zero moments, ε follows its schedule from `epsilon_start`, the
    /// averaged network starts anew, and steps count from 0. A resumed run ignores it (its
    /// checkpoint holds the weights). Written to `config.toml` only when set.
    #[serde(skip_serializing_if = "String::is_empty")]
    pub init_from: String,
}

/// Gradient steps between two moves of the averaged network ([`TrainConfig::average_horizon`]).
pub const AVERAGE_EVERY: u64 = 100;

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            variant: Variant::Mdrlat,
            total_steps: 400_000,
            seed: 0,
            gamma: 0.99,
            n_step: 1,
            learning_rate: 1e-4,
            adam_epsilon: 1e-8,
            batch_size: 32,
            replay_capacity: 20_000,
            learning_starts: 1_000,
            train_frequency: 1,
            gradient_steps: 1,
            envs: 1,
            target_update_interval: 1_000,
            epsilon_start: 0.1,
            epsilon_end: 0.0001,
            epsilon_decay_steps: 20_000,
            demo_steps: 0,
            demo_share: 0.5,
            aux_loss_weight: 1.0,
            aux_optimizer: AuxOptimizer::Separate,
            average_horizon: 0,
            priority_alpha: 0.0,
            priority_beta: 0.4,
            priority_beta_steps: 100_000,
            priority_epsilon: 0.01,
            eval_interval: 5_000,
            eval_episodes: 5,
            eval_seed: 1_000_000,
            curve_episodes: 20,
            curve_world: "auto".into(),
            curve_min_path_m: mdrlat_sim::MovingRule::DEFAULT.min_path_m,
            curve_min_reach_m: mdrlat_sim::MovingRule::DEFAULT.min_reach_m,
            checkpoint_interval: 10_000,
            final_checkpoint: true,
            model_precision: Precision::F32,
            snapshot_minutes: 0.0,
            init_from: String::new(),
        }
    }
}

/// How the auxiliary loss's gradient reaches the weights (see
/// [`TrainConfig::aux_optimizer`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AuxOptimizer {
    /// A second Adam, with its own moments, for the auxiliary loss (the paper's).
    #[default]
    Separate,
    /// One Adam on the weighted sum of both losses.
    Joint,
}

/// How a model file stores its weights.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// 32-bit floats, as trained.
    #[default]
    F32,
    /// IEEE half precision: half the size, for shipping a model (loaded back as f32).
    F16,
}

/// An inconsistent or out-of-range setting.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("train config: {field}: {problem}")]
pub struct TrainConfigError {
    /// The field, e.g. `train.batch_size`.
    pub field: &'static str,
    /// What is wrong.
    pub problem: String,
}

impl TrainConfig {
    /// Checks every value and their consistency.
    ///
    /// # Errors
    /// The first problem found.
    pub fn validate(&self) -> Result<(), TrainConfigError> {
        let err = |field, problem: String| Err(TrainConfigError { field, problem });
        if !(self.gamma.is_finite() && (0.0..=1.0).contains(&self.gamma)) {
            return err("train.gamma", format!("must be in [0, 1], got {}", self.gamma));
        }
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0) {
            return err(
                "train.learning_rate",
                format!("must be positive, got {}", self.learning_rate),
            );
        }
        if !(self.adam_epsilon.is_finite() && self.adam_epsilon > 0.0) {
            return err(
                "train.adam_epsilon",
                format!("must be positive, got {}", self.adam_epsilon),
            );
        }
        if self.batch_size == 0 {
            return err("train.batch_size", "must be at least 1".into());
        }
        if self.replay_capacity < self.batch_size {
            return err(
                "train.batch_size",
                format!("{} exceeds the replay capacity {}", self.batch_size, self.replay_capacity),
            );
        }
        if self.replay_capacity > 1_000_000 {
            return err(
                "train.replay_capacity",
                format!(
                    "{} is above 1,000,000 transitions (41 KB each with depth)",
                    self.replay_capacity
                ),
            );
        }
        if self.learning_starts > self.replay_capacity as u64 {
            return err(
                "train.learning_starts",
                format!(
                    "{} exceeds the replay capacity {}: learning would never start",
                    self.learning_starts, self.replay_capacity
                ),
            );
        }
        if self.eval_episodes == 0 {
            return err("train.eval_episodes", "must be at least 1".into());
        }
        if self.curve_episodes > 1000 {
            return err(
                "train.curve_episodes",
                format!("{} is above 1,000 episodes per world and evaluation", self.curve_episodes),
            );
        }
        self.curve_rule().validate().map_err(|problem| TrainConfigError {
            field: "train.curve_min_path_m",
            problem: problem
                .replace("--min-path", "curve_min_path_m")
                .replace("--min-reach", "curve_min_reach_m"),
        })?;
        if self.curve_world.trim().is_empty() {
            return err("train.curve_world", "empty: name a world, or say 'auto' or 'none'".into());
        }
        if self.learning_starts < self.batch_size as u64 {
            return err(
                "train.learning_starts",
                format!(
                    "{} is below the batch size {}: the first batch would not fill",
                    self.learning_starts, self.batch_size
                ),
            );
        }
        for (field, v) in [
            ("train.train_frequency", self.train_frequency),
            ("train.target_update_interval", self.target_update_interval),
            ("train.eval_interval", self.eval_interval),
            ("train.checkpoint_interval", self.checkpoint_interval),
            ("train.total_steps", self.total_steps),
        ] {
            if v == 0 {
                return err(field, "must be at least 1".into());
            }
        }
        for (field, v) in
            [("train.epsilon_start", self.epsilon_start), ("train.epsilon_end", self.epsilon_end)]
        {
            if !(0.0..=1.0).contains(&v) {
                return err(field, format!("must be in [0, 1], got {v}"));
            }
        }
        if self.demo_steps > self.checkpoint_interval.min(self.total_steps) {
            return err(
                "train.demo_steps",
                format!(
                    "{} is beyond train.checkpoint_interval ({}) or train.total_steps ({}): \
                     a checkpoint cannot hold the demonstrator's state",
                    self.demo_steps, self.checkpoint_interval, self.total_steps
                ),
            );
        }
        if self.average_horizon != 0 && self.average_horizon < AVERAGE_EVERY {
            return err(
                "train.average_horizon",
                format!(
                    "{} is below {AVERAGE_EVERY}, the gradient steps between two moves of the                      average (0 turns it off)",
                    self.average_horizon
                ),
            );
        }
        let m = self.snapshot_minutes;
        if !m.is_finite() || !(m == 0.0 || (0.001..=10_000.0).contains(&m)) {
            return err(
                "train.snapshot_minutes",
                format!("must be 0 (none) or 0.001 to 10000 minutes, got {m}"),
            );
        }
        if !(0.0..=1.0).contains(&self.demo_share) {
            return err("train.demo_share", format!("must be in [0, 1], got {}", self.demo_share));
        }
        for (field, v) in [
            ("train.priority_alpha", self.priority_alpha),
            ("train.priority_beta", self.priority_beta),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return err(field, format!("must be in [0, 1], got {v}"));
            }
        }
        if !(self.priority_epsilon.is_finite() && self.priority_epsilon > 0.0) {
            return err(
                "train.priority_epsilon",
                format!("must be positive, got {}", self.priority_epsilon),
            );
        }
        if self.n_step == 0 || self.n_step > 16 {
            return err("train.n_step", format!("must be in 1..=16, got {}", self.n_step));
        }
        if self.gradient_steps == 0 || self.gradient_steps > 64 {
            return err(
                "train.gradient_steps",
                format!("must be in 1..=64, got {}", self.gradient_steps),
            );
        }
        if self.envs == 0 || self.envs > 256 {
            return err("train.envs", format!("must be in 1..=256, got {}", self.envs));
        }
        if !self.total_steps.is_multiple_of(self.envs as u64) {
            return err(
                "train.total_steps",
                format!(
                    "{} is not a multiple of train.envs = {} (every environment steps as \
                     often)",
                    self.total_steps, self.envs
                ),
            );
        }
        if !(self.aux_loss_weight.is_finite() && self.aux_loss_weight >= 0.0) {
            return err(
                "train.aux_loss_weight",
                format!("must be >= 0, got {}", self.aux_loss_weight),
            );
        }
        Ok(())
    }

    /// The learning curves' unseen world for `task`: `None` when the curves are off or
    /// only the training world is wanted.
    pub fn curve_world_for(&self, task: mdrlat_sim::config::Task) -> Option<String> {
        match self.curve_world.as_str() {
            _ if self.curve_episodes == 0 => None,
            "none" => None,
            "auto" => Some(match task {
                mdrlat_sim::config::Task::Avoid => "office".into(),
                mdrlat_sim::config::Task::Nav => "nav-test".into(),
            }),
            w => Some(w.to_string()),
        }
    }

    /// The learning curves' moving-success rule.
    pub fn curve_rule(&self) -> mdrlat_sim::MovingRule {
        mdrlat_sim::MovingRule {
            min_path_m: self.curve_min_path_m,
            min_reach_m: self.curve_min_reach_m,
        }
    }

    /// β of the importance-sampling weights at `step` (see [`TrainConfig::priority_beta`]).
    pub fn priority_beta_at(&self, step: u64) -> f32 {
        let f = (step as f64 / self.priority_beta_steps.max(1) as f64).min(1.0) as f32;
        self.priority_beta + f * (1.0 - self.priority_beta)
    }

    /// The replay's priorities for a run with these settings (`None`: uniform replay).
    pub fn priorities(&self) -> Option<crate::priority::Priorities> {
        (self.priority_alpha > 0.0).then(|| {
            crate::priority::Priorities::new(
                self.replay_capacity,
                self.priority_alpha,
                self.priority_epsilon,
            )
        })
    }

    /// ε at environment step `step` (linear decay, then constant).
    pub fn epsilon(&self, step: u64) -> f32 {
        if step >= self.epsilon_decay_steps {
            return self.epsilon_end;
        }
        let f = step as f32 / self.epsilon_decay_steps as f32;
        self.epsilon_start + f * (self.epsilon_end - self.epsilon_start)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epsilon_decays_linearly_then_stays() {
        let c = TrainConfig::default();
        assert_eq!(c.epsilon(0), 0.1);
        assert!((c.epsilon(10_000) - (0.1 + 0.0001) / 2.0).abs() < 1e-6);
        assert_eq!(c.epsilon(20_000), 0.0001);
        assert_eq!(c.epsilon(400_000), 0.0001);
    }

    #[test]
    fn inconsistent_configs_are_rejected() {
        assert!(TrainConfig::default().validate().is_ok());
        let bad = |c: TrainConfig| c.validate().expect_err("invalid").to_string();
        let e = bad(TrainConfig { batch_size: 64, replay_capacity: 32, ..Default::default() });
        assert!(e.contains("train.batch_size") && e.contains("64"), "{e}");
        let e = bad(TrainConfig { learning_rate: -1e-4, ..Default::default() });
        assert!(e.contains("train.learning_rate"), "{e}");
        let e = bad(TrainConfig { gamma: 1.5, ..Default::default() });
        assert!(e.contains("train.gamma"), "{e}");
        let e = bad(TrainConfig { learning_starts: 4, ..Default::default() });
        assert!(e.contains("train.learning_starts"), "{e}");
        let e = bad(TrainConfig { learning_starts: 30_000, ..Default::default() });
        assert!(e.contains("train.learning_starts") && e.contains("never"), "{e}");
        let e = bad(TrainConfig { eval_episodes: 0, ..Default::default() });
        assert!(e.contains("train.eval_episodes"), "{e}");
        let e = bad(TrainConfig { curve_episodes: 5000, ..Default::default() });
        assert!(e.contains("train.curve_episodes"), "{e}");
        let e = bad(TrainConfig { curve_world: " ".into(), ..Default::default() });
        assert!(e.contains("train.curve_world") && e.contains("'none'"), "{e}");
        let e = bad(TrainConfig { replay_capacity: 10_000_000, ..Default::default() });
        assert!(e.contains("train.replay_capacity"), "{e}");
        for minutes in [-1.0, 0.0001, f64::NAN, f64::INFINITY, 1e6] {
            let e = bad(TrainConfig { snapshot_minutes: minutes, ..Default::default() });
            assert!(e.contains("train.snapshot_minutes"), "{minutes}: {e}");
        }
    }
}
