//! Why training stopped: the one error type of a run, for the loop, the checkpoint and the
//! run directory alike.

use mdrlat_core::PolicyError;
use mdrlat_sim::{RunError, SimError};
use std::path::PathBuf;

/// Why training stopped.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TrainError {
    /// The settings are inconsistent.
    #[error(transparent)]
    Config(#[from] crate::config::TrainConfigError),
    /// A configuration file or override cannot be used.
    #[error(transparent)]
    Settings(#[from] crate::settings::ConfigError),
    /// An empty list of training worlds.
    #[error("no training world given")]
    NoWorld,
    /// The simulator failed.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The network could not decide (non-finite Q-values: the run diverged).
    #[error("acting at step {step}: {source}")]
    Policy {
        /// Environment step.
        step: u64,
        /// What went wrong.
        source: PolicyError,
    },
    /// A greedy evaluation failed.
    #[error("evaluation at step {step}: {source}")]
    Evaluation {
        /// Environment step.
        step: u64,
        /// What went wrong.
        source: RunError,
    },
    /// A learning curve's evaluation failed.
    #[error("learning curve in '{world}' at step {step}: {source}")]
    Curve {
        /// Environment step.
        step: u64,
        /// The world.
        world: String,
        /// What went wrong.
        source: Box<mdrlat_eval::EvalError>,
    },
    /// The learning curves' unseen world cannot be loaded.
    #[error("train.curve_world '{spec}': {source}")]
    CurveWorld {
        /// The world as given.
        spec: String,
        /// What is wrong with it.
        source: mdrlat_world::WorldError,
    },
    /// A checkpoint is missing, corrupt or of another run.
    #[error("{path}: {problem}")]
    Checkpoint {
        /// The file or folder.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// The model a run starts from (`train.init_from`) cannot be used.
    #[error("train.init_from '{path}': {problem}")]
    InitFrom {
        /// The model as given.
        path: String,
        /// What is wrong.
        problem: String,
    },
    /// A file could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
}
