//! What a trained network believes against what happens: its Q-values along its own greedy
//! episodes beside the discounted returns those episodes earned, the reward's terms, and the
//! one-step TD error by action (`mdrlat diagnose`). The agents issue's diagnosis reads these
//! (docs/training.md): does Q foresee a collision, does the driving reward drown the
//! collision penalty, which actions does the network misjudge?
//!
//! The episodes are the evaluation protocol's (the starts of `mdrlat eval --seed S`, run 0,
//! 300 steps), run by the one episode runner on one environment, the policy recording the
//! Q-values of every decision it makes.

use crate::learner::Inputs;
use crate::policy::{GreedyPolicy, observation_inputs};
use mdrlat_core::{Action, Decision, Observation, Policy, PolicyError, Sensors, greedy_actions};
use mdrlat_eval::EvalSettings;
use mdrlat_eval::protocol::{eval_sim_config, world_episodes};
use mdrlat_sim::{EpisodeSpec, Quiet, RunOptions, SimConfig, StaticScene, VecEnv, run_episodes};
use mdrlat_world::World;
use std::sync::Arc;

/// Steps before a collision whose Q-values [`WorldDiagnosis::q_before_collision`] averages.
pub const BEFORE_COLLISION: usize = 10;

/// What [`diagnose_world`] found in one world.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct WorldDiagnosis {
    /// The world.
    pub world: String,
    /// Episodes run.
    pub episodes: u32,
    /// Episodes that ended in a collision.
    pub collisions: u32,
    /// Decisions made (steps).
    pub steps: u64,
    /// Mean `Q(s_t, a_t)` of the greedy action over every step.
    pub q_mean: f64,
    /// Mean discounted return `G_t = Σ_k γ^k r_{t+k}` from every step to its episode's end,
    /// bootstrapped where the 300 steps ran out with the network's own max Q of the last
    /// state it decided on (the state after the last step is never decided on); a collision
    /// ends it with nothing after.
    pub return_mean: f64,
    /// Mean `Q(s_t, a_t)` over the last [`BEFORE_COLLISION`] steps of the episodes that
    /// ended in a collision (`NaN` without one).
    pub q_before_collision: f64,
    /// Mean `G_t` over the same steps.
    pub return_before_collision: f64,
    /// Mean reward per step of each term of eq. (3): driving (eq. 4 without a collision),
    /// collision penalty, proximity (eq. 5), angular swing (eq. 6).
    pub terms: [f64; 4],
    /// Per Table 1 action: how often the greedy policy took it, and the mean absolute
    /// one-step TD error `|Q(s_t, a_t) − (r_t + γ (1 − collided) max_a Q(s_{t+1}, a))|` of
    /// those steps, the network as its own target (`NaN` where never taken; an episode's
    /// last step is left out unless it collided: `s_{t+1}` was never decided on).
    pub td_by_action: Vec<(u64, f64)>,
}

/// The reward terms' names, in [`WorldDiagnosis::terms`] order.
pub const TERMS: [&str; 4] = ["driving", "collision", "proximity", "angular swing"];

/// A greedy policy that keeps the Q-values of every decision (one environment: decisions in
/// episode order).
struct Recording<'a> {
    policy: &'a GreedyPolicy,
    inputs: Inputs,
    q: Vec<[f32; Action::COUNT]>,
}

impl Policy for Recording<'_> {
    fn name(&self) -> String {
        self.policy.name()
    }
    fn sensors(&self) -> Sensors {
        self.policy.sensors()
    }
    fn depth_memory_frames(&self) -> u32 {
        self.policy.depth_memory_frames()
    }
    fn decide(
        &mut self,
        batch: &[&Observation],
        slots: &[usize],
        out: &mut Vec<Decision>,
    ) -> Result<(), PolicyError> {
        mdrlat_core::check_batch(batch, slots)?;
        observation_inputs(batch, self.policy.config(), &mut self.inputs)?;
        let q = self.policy.q_values(&self.inputs)?;
        let mut actions = Vec::with_capacity(batch.len());
        greedy_actions(&q, batch.len(), &mut actions)?;
        for row in q.chunks_exact(Action::COUNT) {
            self.q.push(std::array::from_fn(|a| row[a]));
        }
        out.clear();
        out.extend(actions.into_iter().map(Decision::from));
        Ok(())
    }
}

/// Runs `episodes` protocol episodes (seed `seed`, at most `max_steps` steps) of `policy`
/// in `world` and compares its Q-values with what happened (see [`WorldDiagnosis`]),
/// discounting with `gamma` (the run's `train.gamma`).
///
/// # Errors
/// The world's spawn regions are blocked, or the policy cannot decide.
pub fn diagnose_world(
    policy: &GreedyPolicy,
    world: &World,
    sim: &SimConfig,
    episodes: u32,
    max_steps: u32,
    seed: u64,
    gamma: f32,
) -> Result<WorldDiagnosis, String> {
    let settings =
        EvalSettings { episodes, runs: 1, max_steps, seed, envs: 1, ..EvalSettings::default() };
    settings.validate().map_err(|e| e.to_string())?;
    let sim = eval_sim_config(sim, &settings);
    let scene = Arc::new(StaticScene::new(Arc::new(world.clone()), &sim));
    let mut venv = VecEnv::new(scene, sim, 1, 1).map_err(|e| e.to_string())?;
    let specs: Vec<EpisodeSpec> = world_episodes(&world.name, &settings)
        .into_iter()
        .map(|(_, _, seed)| EpisodeSpec { seed: Some(seed), pose: None })
        .collect();
    let mut recording = Recording { policy, inputs: Inputs::default(), q: Vec::new() };
    let options = RunOptions { max_steps, record_rows: true };
    let outcomes = run_episodes(&mut venv, &mut recording, &specs, &options, &mut Quiet)
        .map_err(|e| format!("{}: {e}", world.name))?;
    let q = recording.q;
    let gamma = f64::from(gamma);
    let mut d = Summer::default();
    let mut at = 0;
    for outcome in &outcomes {
        let n = outcome.rows.len();
        let qs = &q[at..at + n];
        at += n;
        let collided = outcome.collision.is_some();
        // Returns backwards: G_t = r_t + γ G_{t+1}; after the last step, nothing if it
        // collided, else the network's own estimate of what follows.
        let max_q =
            |row: &[f32; Action::COUNT]| f64::from(row.iter().copied().fold(f32::MIN, f32::max));
        let mut g = if collided || n == 0 { 0.0 } else { max_q(&qs[n - 1]) };
        let mut returns = vec![0.0; n];
        for t in (0..n).rev() {
            g = f64::from(outcome.rows[t].reward) + gamma * g;
            returns[t] = g;
        }
        for (t, row) in outcome.rows.iter().enumerate() {
            let a = row.action.index();
            let q_taken = f64::from(qs[t][a]);
            // The TD target needs Q(s_{t+1}): unknown after an episode's last step unless it
            // ended in a collision (nothing follows); that step is left out of the TD error.
            let next = if row.terminated { Some(0.0) } else { qs.get(t + 1).map(max_q) };
            let target = next.map(|next| f64::from(row.reward) + gamma * next);
            d.add_step(a, q_taken, returns[t], target, &row.info.reward_terms);
            if collided && t + BEFORE_COLLISION >= n {
                d.before.0 += q_taken;
                d.before.1 += returns[t];
                d.before.2 += 1;
            }
        }
        d.collisions += u32::from(collided);
    }
    Ok(d.finish(&world.name, outcomes.len() as u32))
}

/// Running sums of a diagnosis.
#[derive(Default)]
struct Summer {
    steps: u64,
    q: f64,
    g: f64,
    before: (f64, f64, u64),
    terms: [f64; 4],
    /// Decisions per action.
    actions: [u64; Action::COUNT],
    /// Per action: steps with a TD target, and the sum of their |TD error|.
    td: [(u64, f64); Action::COUNT],
    collisions: u32,
}

impl Summer {
    fn add_step(
        &mut self,
        a: usize,
        q: f64,
        g: f64,
        target: Option<f64>,
        r: &mdrlat_sim::reward::RewardTerms,
    ) {
        self.steps += 1;
        (self.q, self.g) = (self.q + q, self.g + g);
        let (drive, crash) = if r.r_c >= 0.0 { (r.r_c, 0.0) } else { (0.0, r.r_c) };
        for (sum, v) in self.terms.iter_mut().zip([drive, crash, r.r_d, r.r_w]) {
            *sum += f64::from(v);
        }
        self.actions[a] += 1;
        if let Some(target) = target {
            self.td[a].0 += 1;
            self.td[a].1 += (q - target).abs();
        }
    }

    fn finish(self, world: &str, episodes: u32) -> WorldDiagnosis {
        let per = |sum: f64, n: u64| if n == 0 { f64::NAN } else { sum / n as f64 };
        WorldDiagnosis {
            world: world.to_string(),
            episodes,
            collisions: self.collisions,
            steps: self.steps,
            q_mean: per(self.q, self.steps),
            return_mean: per(self.g, self.steps),
            q_before_collision: per(self.before.0, self.before.2),
            return_before_collision: per(self.before.1, self.before.2),
            terms: self.terms.map(|t| per(t, self.steps)),
            td_by_action: self
                .actions
                .iter()
                .zip(self.td)
                .map(|(&taken, (n, sum))| (taken, per(sum, n)))
                .collect(),
        }
    }
}

/// The diagnoses as a Markdown report: beliefs against returns, the reward's terms, the TD
/// error by action.
pub fn markdown(source: &str, gamma: f32, rows: &[WorldDiagnosis]) -> String {
    use std::fmt::Write as _;
    let mut s = format!(
        "# Diagnosis of {source}\n\nGreedy protocol episodes (run 0 of `mdrlat eval`'s starts, \
         one environment); γ = {gamma}. Q: the network's `Q(s_t, a_t)` of the action it took; \
         G: the discounted return that followed (bootstrapped with its own max Q where the \
         steps ran out). Before a collision: the last {BEFORE_COLLISION} steps of the episodes \
         that ended in one.\n\n| world | episodes | collisions | mean Q | mean G | Q − G | Q before a collision | G before a collision |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.2} | {:.2} | {:+.2} | {:.2} | {:.2} |",
            r.world,
            r.episodes,
            r.collisions,
            r.q_mean,
            r.return_mean,
            r.q_mean - r.return_mean,
            r.q_before_collision,
            r.return_before_collision
        );
    }
    let _ = write!(s, "\nMean reward per step by term of eq. (3):\n\n| world |");
    for t in TERMS {
        let _ = write!(s, " {t} |");
    }
    let _ = write!(s, "\n| --- |{}\n", " --- |".repeat(TERMS.len()));
    for r in rows {
        let _ = write!(s, "| {} |", r.world);
        for v in r.terms {
            let _ = write!(s, " {v:+.4} |");
        }
        s.push('\n');
    }
    let _ = write!(
        s,
        "\nPer Table 1 action: share of the greedy decisions, and mean |one-step TD error| \
         (the network as its own target):\n\n| world |"
    );
    for a in 0..Action::COUNT {
        let _ = write!(s, " {a} |");
    }
    let _ = write!(s, "\n| --- |{}\n", " --- |".repeat(Action::COUNT));
    for r in rows {
        let _ = write!(s, "| {} |", r.world);
        for &(n, td) in &r.td_by_action {
            if n == 0 {
                s.push_str(" — |");
            } else {
                let share = 100.0 * n as f64 / r.steps.max(1) as f64;
                let _ = write!(s, " {share:.0} % / {td:.2} |");
            }
        }
        s.push('\n');
    }
    s
}
