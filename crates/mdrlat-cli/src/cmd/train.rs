//! `mdrlat train`: one training run of Algorithm 1 into a run directory.

use super::{ensure_dir, load_world};
use crate::config::Config;
use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use mdrlat_nn::Variant;
use mdrlat_nn::burn::prelude::Device;
use std::path::{Path, PathBuf};

/// The compute device.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DeviceKind {
    /// burn's pure-Rust CPU backend (flex): no set-up, the default everywhere.
    Cpu,
}

impl DeviceKind {
    /// The burn device.
    pub fn device(self) -> Device {
        match self {
            DeviceKind::Cpu => Device::flex(),
        }
    }
}

/// Arguments of `mdrlat train`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Network variant: laser-only, depth-only, multi, multi-at, multi-bf or mdrlat
    /// (default: the config's, mdrlat).
    #[arg(long)]
    variant: Option<Variant>,
    /// World to train in: a built-in name, a .toml world file or a map_server .yaml.
    #[arg(long, default_value = "train")]
    world: String,
    /// Environment steps (default: the config's, 400,000).
    #[arg(long)]
    steps: Option<u64>,
    /// Seed of the run (default: the config's, 0).
    #[arg(long)]
    seed: Option<u64>,
    /// Run directory; must not exist yet (or be empty).
    #[arg(long)]
    out: PathBuf,
    /// Configuration file (see `mdrlat config default`).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Override any setting: `--set train.gamma=0.95 --set sim.laser.noise_std_m=0.01`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
    /// Compute device.
    #[arg(long, value_enum, default_value = "cpu")]
    device: DeviceKind,
}

fn check_fresh(dir: &Path) -> Result<()> {
    if dir.exists() {
        let empty = std::fs::read_dir(dir).map(|mut d| d.next().is_none()).unwrap_or(false);
        if !empty {
            bail!(
                "{} already holds a run: choose another --out (nothing was overwritten)",
                dir.display()
            );
        }
    }
    ensure_dir(dir)
}

/// Runs `mdrlat train`.
pub fn run(a: &Args) -> Result<()> {
    let mut config = Config::resolve(a.config.as_deref(), &a.sets)?;
    if let Some(v) = a.variant {
        config.train.variant = v;
    }
    if let Some(s) = a.steps {
        config.train.total_steps = s;
    }
    if let Some(s) = a.seed {
        config.train.seed = s;
    }
    config.train.validate()?;
    let world = load_world(&a.world)?;
    check_fresh(&a.out)?;
    let resolved = toml::to_string(&config).context("serialising the config")?;
    let header = format!(
        "# Resolved configuration of this run (mdrlat {}).\n# world = {:?}, device = {:?}\n\n",
        env!("CARGO_PKG_VERSION"),
        a.world,
        a.device
    );
    let path = a.out.join("config.toml");
    std::fs::write(&path, header + &resolved)
        .with_context(|| format!("cannot write {}", path.display()))?;

    let total = config.train.total_steps;
    let pb = ProgressBar::new(total);
    pb.set_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{bar:30}] {pos}/{len} {per_sec} eta {eta} {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    let device = a.device.device();
    let (report, learner) =
        mdrlat_train::train(world, &config.sim, &config.train, &device, &a.out, |s| {
            if s.step % 50 == 0 || s.step == total {
                pb.set_position(s.step);
                let eval = s.last_eval.map(|e| format!(" eval {e:.1}")).unwrap_or_default();
                pb.set_message(format!(
                    "eps {:.4} td {:.4} at {:.4} ep {}{eval}",
                    s.epsilon, s.losses.td, s.losses.at, s.episodes
                ));
            }
        })?;
    pb.finish_and_clear();
    let weights = a.out.join("model.safetensors");
    mdrlat_train::export::save_safetensors(&learner.policy_net(), config.train.variant, &weights)
        .map_err(anyhow::Error::msg)?;
    let last = report.evaluations.last().map(|e| format!("{:.2} ± {:.2}", e.mean(), e.std()));
    out!(
        "{} in '{}': {} steps, {} updates, {} episodes in {:.0} s ({:.1} steps/s); last eval {}",
        config.train.variant,
        a.world,
        report.steps,
        report.updates,
        report.episodes,
        report.seconds,
        report.steps as f64 / report.seconds.max(1e-9),
        last.unwrap_or_else(|| "none (fewer steps than train.eval_interval)".into())
    );
    out!(
        "wrote {0}/config.toml, {0}/metrics.csv, {0}/eval.csv, {0}/model.safetensors",
        a.out.display()
    );
    Ok(())
}
