//! Training MDRLAT agents (SPEC §4, paper Algorithm 1).
//!
//! The learning rule ([`learner`]), the replay buffer ([`replay`]) and the loop that ties
//! them to the simulator ([`train`]) are separate rooms, as in Stable-Baselines3.

pub mod adam;
pub mod bench;
pub mod checkpoint;
pub mod collect;
pub mod config;
pub mod diagnose;
pub mod error;
pub mod evaluation;
pub mod export;
pub mod learner;
pub mod policy;
pub mod priority;
pub mod replay;
pub mod run_dir;
pub mod settings;
pub mod sink;
pub mod tensorboard;
mod timing;
pub mod train;

pub use collect::TrainEnvs;
pub use config::{AuxOptimizer, TrainConfig, TrainConfigError};
pub use error::TrainError;
pub use evaluation::{CurvePoint, Evaluation, evaluate};
pub use learner::{Inputs, Learner, Losses, init_weights};
pub use policy::{GreedyPolicy, load_weights, observation_inputs};
pub use replay::{Batch, DepthFrames, DepthLayout, ReplayBuffer, Transition};
pub use run_dir::{RunDir, RunInfo};
pub use settings::{Config, Preset};
pub use sink::MetricsSink;
pub use timing::Timing;
pub use train::{Status, TrainReport, train, train_until};

/// Readies the process for work on `device`. On a LibTorch GPU, LibTorch's CPU thread pool
/// shrinks to one thread: with one thread a core it took the cores from rayon's threads
/// (which sample batches and step environments) after every step's small host-side copies.
/// On a GPU machine, MDRLAT runs with one thread (`OMP_NUM_THREADS=1`) were clearly faster
/// than with LibTorch's default pool, in both a batch's sampling and a gradient step
/// (`docs/backends.md`, *A GPU lease*). Elsewhere it does nothing: on LibTorch's CPU those
/// threads do the work.
pub fn prepare_device(device: &mdrlat_nn::burn::prelude::Device) {
    #[cfg(feature = "tch")]
    if mdrlat_nn::is_libtorch_gpu(device) {
        tch::set_num_threads(1);
    }
    #[cfg(not(feature = "tch"))]
    let _ = device;
}
