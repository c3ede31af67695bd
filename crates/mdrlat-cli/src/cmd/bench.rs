//! `mdrlat bench sim`: simulator throughput as a table or JSON lines.

use anyhow::Result;
use mdrlat_sim::bench::{Throughput, one_env, vec_env};
use mdrlat_sim::{SimConfig, StaticScene};
use std::sync::Arc;
use std::time::Duration;

/// Arguments of `mdrlat bench sim`.
#[derive(Debug, clap::Args)]
pub struct SimArgs {
    /// Worlds to measure, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "train,crowd")]
    worlds: Vec<String>,
    /// Environments in the VecEnv (default: 2 per thread: more spill the 1 MiB L2 caches).
    #[arg(long)]
    envs: Option<usize>,
    /// Threads for the VecEnv (0: all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Seconds per measurement.
    #[arg(long, default_value_t = 3.0)]
    seconds: f64,
    /// Print one JSON object per line instead of a table.
    #[arg(long)]
    json: bool,
}

impl SimArgs {
    /// The default worlds on all cores, `seconds` per measurement.
    pub fn quick(seconds: f64) -> Self {
        Self {
            worlds: vec!["train".into(), "crowd".into()],
            envs: None,
            threads: 0,
            seconds,
            json: false,
        }
    }
}

pub use mdrlat_train::bench::cpu_model;

fn report(t: &Throughput, json: bool) {
    if json {
        let line = serde_json::json!({
            "bench": "sim",
            "world": t.world,
            "envs": t.envs,
            "threads": t.threads,
            "steps_per_s": (t.steps_per_s() * 10.0).round() / 10.0,
            "us_per_step": (1e6 / t.steps_per_s() * 100.0).round() / 100.0,
            "steps": t.steps,
            "seconds": (t.seconds * 1000.0).round() / 1000.0,
        });
        out!("{line}");
    } else {
        out!(
            "{:<10} {:>5} {:>7} {:>12.0} {:>10.1}",
            t.world,
            t.envs,
            t.threads,
            t.steps_per_s(),
            1e6 / t.steps_per_s() * t.threads as f64
        );
    }
}

/// Runs the simulator benchmark; returns the measurements.
pub fn measure(
    a: &SimArgs,
    config: &SimConfig,
    mut each: impl FnMut(&Throughput),
) -> Result<Vec<Throughput>> {
    let threads = if a.threads == 0 {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    } else {
        a.threads
    };
    let envs = a.envs.unwrap_or(2 * threads);
    if !(a.seconds.is_finite() && (0.0..=3600.0).contains(&a.seconds)) {
        anyhow::bail!("--seconds {}: must be between 0 and 3600", a.seconds);
    }
    let time = Duration::from_secs_f64(a.seconds.max(0.05));
    let mut out = Vec::new();
    for name in &a.worlds {
        let world = super::load_world(name)?;
        let scene = Arc::new(StaticScene::new(Arc::new(world), config));
        let t = one_env(scene.clone(), config, time)?;
        each(&t);
        out.push(t);
        let t = vec_env(scene, config, envs, threads, time)?;
        each(&t);
        out.push(t);
    }
    Ok(out)
}

/// `mdrlat bench sim`.
pub fn sim(a: &SimArgs) -> Result<()> {
    let config = SimConfig::default();
    if !a.json {
        out!("simulator throughput, full sensors (512-beam laser + 128x160 depth), random actions");
        out!(
            "cpu: {}  cores: {}",
            cpu_model(),
            std::thread::available_parallelism().map_or(1, |n| n.get())
        );
        out!(
            "{:<10} {:>5} {:>7} {:>12} {:>10}",
            "world",
            "envs",
            "threads",
            "steps/s",
            "us/step/core"
        );
    }
    measure(a, &config, |t| report(t, a.json))?;
    Ok(())
}
