//! A network that acts: greedy decisions on one observation at a time, from a trained run
//! or freshly initialised, for `mdrlat ros` and anything else that deploys a policy.

use crate::checkpoint::read_meta;
use crate::learner::{argmax, read_net, tensor3, tensor4};
use mdrlat_core::{DEPTH_LEN, FRAME_STACK, LASER_BEAMS};
use mdrlat_nn::burn::prelude::*;
use mdrlat_nn::{QNet, QNetConfig, Variant};
use std::path::{Path, PathBuf};

/// A Q-network acting greedily (no exploration) on single observations.
pub struct GreedyPolicy {
    variant: Variant,
    net: QNet,
    device: Device,
    pool: rayon::ThreadPool,
    source: String,
}

impl std::fmt::Debug for GreedyPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GreedyPolicy")
            .field("variant", &self.variant)
            .field("source", &self.source)
            .finish()
    }
}

/// The checkpoint folder `path` names: a checkpoint folder itself, or a run directory
/// (its `checkpoint/`, or `checkpoint.old/` if a run was killed during a swap).
fn checkpoint_dir(path: &Path) -> Result<PathBuf, String> {
    [path.to_path_buf(), path.join("checkpoint"), path.join("checkpoint.old")]
        .into_iter()
        .find(|d| d.join("meta.json").is_file())
        .ok_or_else(|| {
            format!(
                "{}: no checkpoint here (expected a run directory with checkpoint/meta.json, \
                 or a checkpoint folder with meta.json)",
                path.display()
            )
        })
}

fn pool(threads: usize) -> Result<rayon::ThreadPool, String> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .thread_name(|i| format!("policy-{i}"))
        .build()
        .map_err(|e| format!("inference thread pool: {e}"))
}

impl GreedyPolicy {
    /// The online network of a run's checkpoint (`path`: a run directory or a checkpoint
    /// folder), computing on `threads` CPU threads.
    ///
    /// # Errors
    /// No checkpoint, an unreadable or corrupt `meta.json`, another format, or weights that
    /// do not fit the variant it names.
    pub fn load(path: &Path, device: &Device, threads: usize) -> Result<Self, String> {
        let dir = checkpoint_dir(path)?;
        let meta = read_meta(&dir).map_err(|e| e.to_string())?;
        let mut net = QNetConfig::new(meta.variant).init(device);
        read_net(&mut net, &dir.join("online.bpk"), meta.variant)?;
        Ok(Self {
            variant: meta.variant,
            net,
            device: device.clone(),
            pool: pool(threads)?,
            source: format!("{} (step {})", dir.display(), meta.step),
        })
    }

    /// A freshly initialised `variant` network (seeded), for testing a deployment before
    /// any training.
    ///
    /// # Errors
    /// The thread pool cannot start.
    pub fn untrained(
        variant: Variant,
        seed: u64,
        device: &Device,
        threads: usize,
    ) -> Result<Self, String> {
        Ok(Self {
            variant,
            net: QNetConfig::new(variant).init_seeded(device, seed),
            device: device.clone(),
            pool: pool(threads)?,
            source: format!("untrained, seed {seed}"),
        })
    }

    /// The variant.
    pub fn variant(&self) -> Variant {
        self.variant
    }

    /// Where the weights came from, for logs.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Q-values of one observation: `laser` `[4, 512]` and `depth` `[4, 128, 160]`,
    /// normalised (empty when the variant does not use the sensor).
    ///
    /// # Errors
    /// Inputs of the wrong size, or a backend failure.
    pub fn q_values(&self, laser: &[f32], depth: &[f32]) -> Result<Vec<f32>, String> {
        let v = self.variant;
        if v.uses_laser() && laser.len() != FRAME_STACK * LASER_BEAMS {
            return Err(format!("laser input has {} values, expected 4 x 512", laser.len()));
        }
        if v.uses_depth() && depth.len() != FRAME_STACK * DEPTH_LEN {
            return Err(format!("depth input has {} values, expected 4 x 128 x 160", depth.len()));
        }
        self.pool.install(|| {
            let l = v.uses_laser().then(|| tensor3(laser, 1, &self.device));
            let d = v.uses_depth().then(|| tensor4(depth, 1, &self.device));
            let q = self.net.forward(l, d, None).q;
            q.into_data().try_to_vec::<f32>().map_err(|e| format!("reading Q-values: {e:?}"))
        })
    }

    /// The greedy action index of one observation (see [`GreedyPolicy::q_values`]).
    ///
    /// # Errors
    /// See [`GreedyPolicy::q_values`].
    pub fn act(&self, laser: &[f32], depth: &[f32]) -> Result<usize, String> {
        let q = self.q_values(laser, depth)?;
        if q.iter().any(|x| !x.is_finite()) {
            return Err(format!("non-finite Q-values {q:?}"));
        }
        Ok(argmax(&q))
    }
}
