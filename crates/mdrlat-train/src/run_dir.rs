//! A run directory: where one training run keeps everything, and the one place that knows
//! its file names.
//!
//! ```text
//! run/
//!   config.toml             every setting, resolved (RunDir::create; --steps extends it)
//!   run.toml                the worlds, the device, the mdrlat version (RunInfo)
//!   metrics.csv             a row every 100 steps (MetricsSink)
//!   eval.csv                a row every evaluation: Fig. 4 and the learning curves
//!   events.out.tfevents.*   the same scalars for TensorBoard
//!   checkpoint/             everything a resume needs (checkpoint::save)
//!   model.safetensors       the online network's weights at the end (RunDir::finish)
//!   snapshots/minute-*/     the policy at fixed minutes of training (train.snapshot_minutes)
//! ```

use crate::error::TrainError;
use crate::learner::Learner;
use crate::settings::Config;
use std::path::{Path, PathBuf};

/// What a run directory records about how it was started (`run.toml`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunInfo {
    /// The training worlds as given (`mdrlat_world::load_set`'s spec).
    pub world: String,
    /// The compute device's command-line name (`cpu`, `wgpu`, `tch`, …).
    pub device: String,
    /// The mdrlat version that started the run.
    pub mdrlat_version: String,
}

impl RunInfo {
    /// A run of this mdrlat version in `world` on `device`.
    pub fn new(world: impl Into<String>, device: impl Into<String>) -> Self {
        RunInfo {
            world: world.into(),
            device: device.into(),
            mdrlat_version: env!("CARGO_PKG_VERSION").to_string(),
        }
    }
}

/// A run's folder and its layout.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunDir {
    root: PathBuf,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> TrainError + '_ {
    move |source| TrainError::Io { path: path.to_path_buf(), source }
}

impl RunDir {
    /// A new run in `root`, which must not exist or be empty: writes `config.toml` and
    /// `run.toml`.
    ///
    /// # Errors
    /// `root` already holds files (nothing is overwritten), or cannot be written.
    pub fn create(root: &Path, config: &Config, info: &RunInfo) -> Result<RunDir, TrainError> {
        if root.exists() {
            let empty = std::fs::read_dir(root).map(|mut d| d.next().is_none()).unwrap_or(false);
            if !empty {
                return Err(TrainError::Checkpoint {
                    path: root.to_path_buf(),
                    problem: "already holds a run: choose another folder (nothing was overwritten)"
                        .into(),
                });
            }
        }
        std::fs::create_dir_all(root).map_err(io(root))?;
        let dir = RunDir { root: root.to_path_buf() };
        dir.write_config(config)?;
        let path = dir.run_info();
        let text = toml::to_string(info).unwrap_or_else(|e| unreachable!("plain data: {e}"));
        std::fs::write(&path, text).map_err(io(&path))?;
        Ok(dir)
    }

    /// An existing run in `root`, with its configuration as it was started
    /// ([`Config::load_run`]) and its `run.toml`.
    ///
    /// # Errors
    /// A file is missing or unreadable, or its settings are invalid.
    pub fn open(root: &Path) -> Result<(RunDir, Config, RunInfo), TrainError> {
        let dir = RunDir { root: root.to_path_buf() };
        let config = Config::load_run(&dir.config())?;
        let path = dir.run_info();
        let text = std::fs::read_to_string(&path).map_err(io(&path))?;
        let info: RunInfo = toml::from_str(&text).map_err(|e| TrainError::Checkpoint {
            path: path.clone(),
            problem: e.to_string().trim_end().to_string(),
        })?;
        Ok((dir, config, info))
    }

    /// A folder that is taken to be a run directory as it stands (tests, benches).
    pub fn at(root: &Path) -> RunDir {
        RunDir { root: root.to_path_buf() }
    }

    /// Rewrites `config.toml` (a resumed run that is extended records its new length).
    ///
    /// # Errors
    /// The file cannot be written.
    pub fn write_config(&self, config: &Config) -> Result<(), TrainError> {
        let path = self.config();
        std::fs::write(&path, config.to_toml()).map_err(io(&path))
    }

    /// Writes the online network's weights to `model.safetensors` in `precision`,
    /// recording the step in its metadata.
    ///
    /// # Errors
    /// The file cannot be written.
    pub fn save_model(
        &self,
        learner: &Learner,
        step: u64,
        precision: crate::config::Precision,
    ) -> Result<(), TrainError> {
        let path = self.model();
        crate::export::save_safetensors_as(
            &learner.policy_net(),
            learner.net_config(),
            &path,
            precision,
            &[("mdrlat_step", step.to_string())],
        )
        .map_err(|problem| TrainError::Checkpoint { path, problem })
    }

    /// Ends a finished run: writes `model.safetensors` ([`RunDir::save_model`]) and, when the
    /// run keeps no final checkpoint (`train.final_checkpoint = false`), removes every
    /// checkpoint it wrote on the way (`checkpoint/`, and a `checkpoint.old/` or
    /// `checkpoint.tmp/` a killed swap left): nothing is left to resume, and no replay buffer
    /// (MDRLAT's 50k transitions: 2.4 GB) stays on the disk. The model is written first, so a
    /// run killed in between still has its checkpoint.
    ///
    /// # Errors
    /// The model cannot be written or a checkpoint folder cannot be removed.
    pub fn finish(
        &self,
        learner: &Learner,
        step: u64,
        config: &crate::config::TrainConfig,
    ) -> Result<(), TrainError> {
        self.save_model(learner, step, config.model_precision)?;
        if !config.final_checkpoint {
            for name in ["checkpoint", "checkpoint.old", "checkpoint.tmp"] {
                let path = self.root.join(name);
                if path.exists() {
                    std::fs::remove_dir_all(&path).map_err(io(&path))?;
                }
            }
        }
        Ok(())
    }

    /// Writes the policy the run would ship now (the averaged network where it keeps one)
    /// as the snapshot at `minute` of training (`snapshots/minute-MMMM.MMM/model.safetensors`,
    /// see [`snapshot_name`]), recording the step, the minutes actually trained and the CPU
    /// in its metadata. Written beside and renamed into place: a run killed meanwhile leaves
    /// no half snapshot.
    ///
    /// # Errors
    /// The folder or file cannot be written.
    pub fn save_snapshot(
        &self,
        learner: &Learner,
        step: u64,
        minute: f64,
        trained_minutes: f64,
        precision: crate::config::Precision,
    ) -> Result<PathBuf, TrainError> {
        let name = snapshot_name(minute);
        let (dest, tmp) = (self.snapshots().join(&name), self.snapshots().join(name + ".tmp"));
        let fail =
            |path: &Path, e: String| TrainError::Checkpoint { path: path.into(), problem: e };
        let _ = std::fs::remove_dir_all(&tmp);
        std::fs::create_dir_all(&tmp).map_err(|e| fail(&tmp, e.to_string()))?;
        let model = tmp.join("model.safetensors");
        crate::export::save_safetensors_as(
            &learner.policy_net(),
            learner.net_config(),
            &model,
            precision,
            &[
                ("mdrlat_step", step.to_string()),
                ("mdrlat_snapshot_minute", minute.to_string()),
                ("mdrlat_training_minutes", format!("{trained_minutes:.3}")),
                ("mdrlat_cpu", crate::bench::cpu_model()),
            ],
        )
        .map_err(|e| fail(&model, e))?;
        let _ = std::fs::remove_dir_all(&dest); // a restarted run's own earlier snapshot
        std::fs::rename(&tmp, &dest).map_err(|e| fail(&dest, e.to_string()))?;
        Ok(dest)
    }

    /// `snapshots/`: the policy at fixed minutes of training (`train.snapshot_minutes`).
    pub fn snapshots(&self) -> PathBuf {
        self.root.join("snapshots")
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.root
    }
    /// `config.toml`.
    pub fn config(&self) -> PathBuf {
        self.root.join("config.toml")
    }
    /// `run.toml`.
    pub fn run_info(&self) -> PathBuf {
        self.root.join("run.toml")
    }
    /// `metrics.csv`.
    pub fn metrics(&self) -> PathBuf {
        self.root.join("metrics.csv")
    }
    /// `eval.csv`.
    pub fn evaluations(&self) -> PathBuf {
        self.root.join("eval.csv")
    }
    /// `checkpoint/`.
    pub fn checkpoint(&self) -> PathBuf {
        self.root.join("checkpoint")
    }
    /// `model.safetensors`.
    pub fn model(&self) -> PathBuf {
        self.root.join("model.safetensors")
    }
}

/// The folder name of the snapshot at `minute` of training: `minute-0010.000` (three
/// decimals: `train.snapshot_minutes` is at least 0.001, so two snapshots never share a
/// name), sorting in time order as text below 10,000 minutes.
pub fn snapshot_name(minute: f64) -> String {
    format!("minute-{minute:08.3}")
}

/// The minute a snapshot folder's name stands for (`minute-0010.000` → 10), or `None` for
/// another name.
pub fn snapshot_minute(name: &str) -> Option<f64> {
    let m: f64 = name.strip_prefix("minute-")?.parse().ok()?;
    (m.is_finite() && m >= 0.0).then_some(m)
}
