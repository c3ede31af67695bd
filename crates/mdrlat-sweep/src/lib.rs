//! `mdrlat reproduce`: the paper's evaluation section (Table 2, Figs. 4, 6, 7) as a sweep of
//! jobs — train every variant and seed, evaluate every final model and baseline in the
//! unseen worlds, write the tables — that survives being killed at any moment.
//!
//! - [`spec`]: the sweep (a TOML file; presets `paper`, `cpu-small`, `smoke`).
//! - [`plan`]: its jobs, each with its own folder and a `state/<job>.done` marker written
//!   when its outputs are complete; reruns skip finished jobs, interrupted training resumes
//!   from its checkpoint, a changed sweep under old results is refused.
//! - [`job`]: the `mdrlat` command lines a job is made of (what a user would type).
//! - [`local`]: runs jobs as child processes, N at a time, cores split between them.
//! - [`slurm`]: one array job for the training runs, dependent jobs for the evaluations
//!   and the tables.
//! - [`tables`]: Table 2 beside the paper's numbers and the report that checks its ordering.

pub mod job;
pub mod local;
pub mod plan;
pub mod slurm;
pub mod spec;
pub mod tables;

pub use plan::{Job, JobKind, JobState, Plan};
pub use spec::{EvalSpec, PRESETS, Sweep};
use std::path::PathBuf;

/// Why a sweep could not go on.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SweepError {
    /// An unknown preset name.
    #[error("unknown preset '{name}': the presets are {known} (print one with --print NAME)")]
    UnknownPreset {
        /// The name given.
        name: String,
        /// The presets there are.
        known: String,
    },
    /// A sweep file (or preset) that does not parse or holds impossible values.
    #[error("{file}: {problem}")]
    Spec {
        /// The file.
        file: String,
        /// What is wrong, naming the key.
        problem: String,
    },
    /// The output folder holds another sweep's results.
    #[error(
        "{} holds results of a different sweep ({}): use another --out, or the sweep it was started with",
        dir.display(), diff.join(", ")
    )]
    Changed {
        /// The folder.
        dir: PathBuf,
        /// What differs (`key: old -> new`).
        diff: Vec<String>,
    },
    /// The output folder exists, is not empty and has no `sweep.toml`.
    #[error("{}: not a sweep's folder (no sweep.toml); choose an empty or new --out", .0.display())]
    NotASweep(PathBuf),
    /// A job id that is not in the sweep.
    #[error("no job '{id}' in the sweep of {}", dir.display())]
    UnknownJob {
        /// The id given.
        id: String,
        /// The sweep's folder.
        dir: PathBuf,
    },
    /// A job started before a job it needs finished.
    #[error("{job} needs {need}, which is not finished")]
    NotReady {
        /// The job.
        job: String,
        /// What it needs.
        need: String,
    },
    /// A file could not be read or written.
    #[error("{what}: {source}")]
    Io {
        /// The file and what was being done.
        what: String,
        /// The error.
        source: std::io::Error,
    },
    /// An evaluation's results could not be read back.
    #[error("{0}")]
    Results(String),
    /// A Slurm command is missing or failed.
    #[error("{0}")]
    Slurm(String),
    /// Jobs failed (each with its log).
    #[error("{} job(s) failed: {}", .0.len(), .0.join("; "))]
    Failed(Vec<String>),
}
