//! `mdrlat diagnose`: a trained network's Q-values along its own greedy episodes beside the
//! returns they earned, the reward's terms and the TD error by action
//! (`mdrlat_train::diagnose`).

use super::load_world;
use super::train::DeviceKind;
use anyhow::{Context, Result, bail};
use mdrlat_sim::SimConfig;
use mdrlat_train::GreedyPolicy;
use mdrlat_train::diagnose::{diagnose_world, markdown};
use std::path::PathBuf;

/// Arguments of `mdrlat diagnose`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A run directory of `mdrlat train`, its checkpoint folder, or a model.
    #[arg(long, value_name = "RUN_DIR")]
    checkpoint: PathBuf,
    /// Worlds, comma-separated (default: the three test worlds).
    #[arg(long, value_delimiter = ',', default_value = "office,furnished,crowd")]
    world: Vec<String>,
    /// Protocol episodes per world.
    #[arg(long, default_value_t = 20)]
    episodes: u32,
    /// Steps per episode at most.
    #[arg(long, default_value_t = 300)]
    max_steps: u32,
    /// Seed of the protocol's starts (as `mdrlat eval --seed`).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Discount of the returns (the run's train.gamma; the paper's 0.99).
    #[arg(long, default_value_t = 0.99)]
    gamma: f32,
    /// Write the report here (Markdown) instead of printing it.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print one JSON object per world instead.
    #[arg(long)]
    json: bool,
}

/// Runs `mdrlat diagnose`.
pub fn run(a: &Args) -> Result<()> {
    if !(a.gamma.is_finite() && (0.0..=1.0).contains(&a.gamma)) {
        bail!("--gamma {}: must be in [0, 1]", a.gamma);
    }
    if a.episodes == 0 || a.episodes > 10_000 || a.max_steps == 0 {
        bail!("--episodes must be 1 to 10000 and --max-steps at least 1");
    }
    let device = DeviceKind::Cpu.device();
    let policy = GreedyPolicy::load(&a.checkpoint, &device, 1)
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("--checkpoint {}", a.checkpoint.display()))?;
    let mut sim = SimConfig { task: policy.task(), ..SimConfig::default() };
    policy.fit_sim(&mut sim, "--checkpoint").map_err(anyhow::Error::msg)?;
    let mut rows = Vec::new();
    for name in &a.world {
        let world = load_world(name)?;
        let d = diagnose_world(&policy, &world, &sim, a.episodes, a.max_steps, a.seed, a.gamma)
            .map_err(anyhow::Error::msg)?;
        if a.json {
            out!("{}", serde_json::to_string(&d).context("json")?);
        }
        rows.push(d);
    }
    if a.json {
        return Ok(());
    }
    let report = markdown(policy.source(), a.gamma, &rows);
    match &a.out {
        Some(path) => {
            std::fs::write(path, &report).with_context(|| format!("writing {}", path.display()))?;
            out!("wrote {}", path.display());
        }
        None => out!("{}", report.trim_end()),
    }
    Ok(())
}
