//! What the training tests share.

use mdrlat_nn::burn::prelude::Device;
use mdrlat_sim::SimConfig;
use mdrlat_train::{Learner, RunDir, Status, TrainConfig, TrainEnvs, TrainError, TrainReport};
use mdrlat_world::World;
use std::path::Path;

/// A run of `config` in `worlds` into the folder `dir`: the library's `train` with its
/// `train.envs` environments built here, as a caller builds them.
pub fn train(
    worlds: Vec<World>,
    sim: &SimConfig,
    config: &TrainConfig,
    device: &Device,
    dir: &Path,
    resume: bool,
    progress: impl FnMut(&Status),
) -> Result<(TrainReport, Learner), TrainError> {
    let envs = TrainEnvs::new(worlds, sim, config.envs)?;
    mdrlat_train::train(envs, config, device, &RunDir::at(dir), resume, progress)
}
