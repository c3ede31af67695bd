//! How often does a method get through an unseen world? The evaluation protocol of the
//! paper (section 3.1, SPEC §5) and its reports.
//!
//! - [`protocol`]: success = no collision within 300 steps; runs of 50 episodes from start
//!   poses drawn by the seed alone (the same for every method: paired comparisons), each
//!   run repeated 5 times; all environments of a run step together and the policy decides
//!   for all of them in one batch ([`mdrlat_sim::run_episodes`]).
//! - [`report`]: `episodes.csv`, `summary.csv`, `summary.md` and JSON, byte-reproducible.
//! - [`nav`]: the navigation task's measures (time to goal, path against the shortest
//!   collision-free path) and `navigation.csv`/`navigation.md`.
//! - [`run`]: an evaluation as one operation — a policy in several worlds into a folder
//!   with its tables and figures (`mdrlat eval`).
//! - [`snapshots`]: success against minutes of training, from full evaluations of a run's
//!   snapshots (`train.snapshot_minutes`).
//! - [`figures`]: paper Figs. 6/7 — six top views with their commands and the
//!   angular-velocity trace — by replaying an episode's recorded actions.
//!
//! Any [`mdrlat_core::Policy`] can be evaluated: the scripted baselines of the simulator, or
//! a trained network from `mdrlat-train` (this crate does not depend on the deep-learning
//! stack, so the baselines evaluate without it).

pub mod figures;
pub mod nav;
pub mod protocol;
pub mod report;
pub mod run;
pub mod snapshots;

pub use figures::{
    EpisodeFigure, Pick, draw_collisions, draw_episode, draw_navigation, pick_episodes,
};
pub use nav::{NavRecord, NavSummary, nav_records, navigation_csv, navigation_markdown};
pub use protocol::{
    EpisodeRecord, EvalSettings, Progress, WorldEval, collision_kind, episode_seed,
    eval_sim_config, evaluate_world, world_episodes,
};
pub use report::{
    Timing, WorldSummary, episodes_csv, parse_summary_csv, summary_csv, summary_markdown,
};
pub use run::{Agent, EvalObserver, EvalReport, Output, WorldResult, evaluate, prepare_output};
pub use snapshots::{SnapshotResult, snapshots_chart, snapshots_csv, snapshots_markdown};

/// Why an evaluation failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EvalError {
    /// The settings are unusable (the flag is named).
    #[error("{0}")]
    Settings(String),
    /// The simulator failed (e.g. a world whose spawn regions are blocked).
    #[error(transparent)]
    Sim(#[from] mdrlat_sim::SimError),
    /// An episode failed (the policy could not decide).
    #[error(transparent)]
    Run(#[from] mdrlat_sim::RunError),
    /// The policy could not decide in an episode.
    #[error("policy '{policy}' in '{world}' run {run} episode {episode} (seed {seed}): {source}")]
    Policy {
        /// The policy's name.
        policy: String,
        /// The world.
        world: String,
        /// Run index.
        run: u32,
        /// Episode index in the run.
        episode: u32,
        /// The episode's seed.
        seed: u64,
        /// What went wrong.
        source: mdrlat_core::PolicyError,
    },
    /// A navigation measure cannot be taken (no goal, a goal unreachable on the grid).
    #[error("{0}")]
    Nav(String),
    /// The output folder cannot be used or written.
    #[error("{0}")]
    Output(String),
    /// Replaying an episode for a figure did not reproduce it.
    #[error("replaying an episode for its figure: {0}")]
    Replay(String),
}
