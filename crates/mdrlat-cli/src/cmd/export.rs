//! `mdrlat export`: a trained run's network as a model folder to ship (`models/…`):
//! `model.safetensors` (f16 by default: half the bytes) and a README with where it came
//! from, how far its Q-values lie from the f32 original, and its success table. `mdrlat
//! eval --checkpoint DIR` and `mdrlat ros --checkpoint DIR` read the folder as they read a
//! run.

use super::train::DeviceKind;
use super::{ensure_dir, load_world};
use anyhow::{Context, Result, bail};
use mdrlat_core::Observation;
use mdrlat_sim::config::Task;
use mdrlat_sim::{Env, SimConfig};
use mdrlat_train::GreedyPolicy;
use mdrlat_train::export::{Precision, QDifference, compare_q, save_safetensors_as};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Arguments of `mdrlat export`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A run directory of `mdrlat train` (or its checkpoint folder, or a model). Given
    /// several times, the model is the mean of their weights (checkpoint averaging: the
    /// same variant and task; e.g. a run's last few checkpoints).
    #[arg(long, value_name = "RUN_DIR", required = true)]
    checkpoint: Vec<PathBuf>,
    /// The model folder to write (model.safetensors, README.md).
    #[arg(long)]
    out: PathBuf,
    /// Store the weights in f32 instead of f16.
    #[arg(long)]
    f32: bool,
    /// An evaluation of this run (`mdrlat eval --out`): its summary.md (navigation.md for a
    /// navigation network) and summary.csv are copied beside the model.
    #[arg(long, value_name = "EVAL_DIR")]
    eval: Option<PathBuf>,
    /// Observations the Q-values of the stored model are compared on (driven by the model
    /// itself in the test worlds office, furnished and crowd).
    #[arg(long, default_value_t = 600)]
    samples: usize,
    /// Seed of the comparison's episodes.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Replace an earlier export in --out.
    #[arg(long)]
    overwrite: bool,
}

/// The worlds a model of `task` is compared in: the test worlds of its task.
fn test_worlds(task: Task) -> &'static [&'static str] {
    match task {
        Task::Avoid => &["office", "furnished", "crowd"],
        Task::Nav => &["nav-test"],
    }
}

/// Observations the policy meets when it drives in the test worlds of its task (a new
/// episode after each collision, goal or 300 steps), `n` in all, with the scan it reads.
fn observations(policy: &mut GreedyPolicy, n: usize, seed: u64) -> Result<Vec<Observation>> {
    let worlds = test_worlds(policy.task());
    let mut sim = SimConfig { task: policy.task(), ..SimConfig::default() };
    policy.fit_sim(&mut sim, "--checkpoint").map_err(anyhow::Error::msg)?;
    let per = n.div_ceil(worlds.len());
    let mut out = Vec::with_capacity(n);
    for (w, name) in worlds.iter().enumerate() {
        let mut env = Env::from_world(load_world(name)?, sim.clone())?;
        let mut episode = 0u64;
        let mut obs = env.reset(Some(seed + 1000 * w as u64))?.clone();
        let mut steps = 0;
        for _ in 0..per {
            out.push(obs.clone());
            let d = mdrlat_core::decide_one(policy, &obs, 0).map_err(|e| anyhow::anyhow!("{e}"))?;
            let step = env.step(d.action)?;
            steps += 1;
            if step.terminated || step.truncated || steps >= 300 {
                episode += 1;
                steps = 0;
                obs = env.reset(Some(seed + 1000 * w as u64 + episode))?.clone();
            } else {
                obs = step.observation.clone();
            }
        }
    }
    out.truncate(n);
    Ok(out)
}

fn readme(
    out: &Path,
    policy: &GreedyPolicy,
    precision: Precision,
    bytes: u64,
    diff: &QDifference,
    eval: Option<(&str, &str)>,
) -> String {
    let mut s = String::new();
    let name = out.file_name().map_or("model".into(), |n| n.to_string_lossy().into_owned());
    let _ = writeln!(s, "# {name}: a trained `{}` network\n", policy.variant());
    let _ = writeln!(
        s,
        "- Weights: `model.safetensors`, {:?}, {:.1} MB, PyTorch layout (see the repository's docs/training.md, *Weights in PyTorch*).",
        precision,
        bytes as f64 / 1e6
    );
    let _ = writeln!(s, "- Exported from: `{}`.", policy.source());
    let _ = writeln!(
        s,
        "- Stored against the f32 original, {diff}, on observations the model meets driving in \
         {}.",
        test_worlds(policy.task()).join(", ")
    );
    if policy.task() == Task::Nav {
        let _ = writeln!(
            s,
            "- A goal-conditioned network (the navigation task): it reads the goal in the robot frame.\n\nUse it without training:\n\n```sh\nmdrlat eval --task nav --checkpoint {0} --figures 8 --out eval/{name}\n```\n",
            out.display()
        );
    } else {
        let _ = writeln!(
            s,
            "\nUse it without training:\n\n```sh\nmdrlat eval --checkpoint {0} --out eval/{name}\nmdrlat ros-sim --world office &   # a simulated robot over ROS\nmdrlat ros --checkpoint {0}      # drives it\n```\n",
            out.display()
        );
    }
    if let Some((name, table)) = eval {
        let _ = writeln!(
            s,
            "## Its success table (`{name}`)\n\n{}",
            table.trim_end().replacen("# ", "### ", 1)
        );
    }
    s
}

/// The policy of one checkpoint, or of the mean of several checkpoints' weights.
fn load_mean(
    checkpoints: &[PathBuf],
    device: &mdrlat_nn::burn::prelude::Device,
) -> Result<GreedyPolicy> {
    let load = |c: &PathBuf| {
        GreedyPolicy::load(c, device, 1)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("--checkpoint {}", c.display()))
    };
    let policies = checkpoints.iter().map(load).collect::<Result<Vec<_>>>()?;
    let mut policies = policies.into_iter();
    let first = policies.next().context("no --checkpoint")?;
    let rest: Vec<GreedyPolicy> = policies.collect();
    if rest.is_empty() {
        return Ok(first);
    }
    for (p, path) in rest.iter().zip(&checkpoints[1..]) {
        if p.config().depth_memory_frames != first.config().depth_memory_frames {
            bail!(
                "--checkpoint {}: reads {}, the first --checkpoint {}: only networks of one scan can be averaged",
                path.display(),
                mdrlat_train::learner::scan_name(p.config().depth_memory_frames),
                mdrlat_train::learner::scan_name(first.config().depth_memory_frames),
            );
        }
        if p.variant() != first.variant() || p.task() != first.task() {
            bail!(
                "--checkpoint {}: a {} network for {:?}, the first --checkpoint a {} network for {:?}: only networks of one variant and task can be averaged",
                path.display(),
                p.variant(),
                p.task(),
                first.variant(),
                first.task()
            );
        }
    }
    let nets: Vec<&mdrlat_nn::QNet> =
        std::iter::once(first.net()).chain(rest.iter().map(|p| p.net())).collect();
    let mean = mdrlat_nn::QNet::average(&nets).map_err(anyhow::Error::msg)?;
    let source = format!(
        "the mean of {} checkpoints' weights: {}",
        nets.len(),
        std::iter::once(first.source())
            .chain(rest.iter().map(|p| p.source()))
            .collect::<Vec<_>>()
            .join("; ")
    );
    GreedyPolicy::from_net(first.config().clone(), mean, device, 1, source)
        .map_err(anyhow::Error::msg)
}

/// Runs `mdrlat export`.
pub fn run(a: &Args) -> Result<()> {
    let model = a.out.join("model.safetensors");
    if model.exists() && !a.overwrite {
        bail!(
            "{} already holds a model: choose another --out, or pass --overwrite",
            a.out.display()
        );
    }
    if a.samples == 0 || a.samples > 100_000 {
        bail!("--samples {}: must be 1 to 100000", a.samples);
    }
    let device = DeviceKind::Cpu.device();
    let mut original = load_mean(&a.checkpoint, &device)?;
    let eval_table = match &a.eval {
        Some(dir) => {
            // A navigation evaluation's table is navigation.md (time, path, path ratio).
            let table = if original.task() == Task::Nav { "navigation.md" } else { "summary.md" };
            let md = std::fs::read_to_string(dir.join(table))
                .with_context(|| format!("--eval {}: no {table}", dir.display()))?;
            Some((table, md, dir.join("summary.csv")))
        }
        None => None,
    };
    ensure_dir(&a.out)?;
    let precision = if a.f32 { Precision::F32 } else { Precision::F16 };
    let steps: Vec<String> = original
        .source()
        .split("(step ")
        .skip(1)
        .map(|s| s.chars().take_while(char::is_ascii_digit).collect::<String>())
        .filter(|step| !step.is_empty())
        .collect();
    let sources: Vec<String> = a.checkpoint.iter().map(|c| c.display().to_string()).collect();
    let mut extra = vec![("mdrlat_source", sources.join(", "))];
    if !steps.is_empty() {
        extra.push(("mdrlat_step", steps.join(", ")));
    }
    save_safetensors_as(original.net(), original.config(), &model, precision, &extra)
        .map_err(anyhow::Error::msg)?;
    let stored = GreedyPolicy::load(&model, &device, 1).map_err(anyhow::Error::msg)?;
    let obs = observations(&mut original, a.samples, a.seed)?;
    let diff = compare_q(&original, &stored, &obs).map_err(|e| anyhow::anyhow!("{e}"))?;
    let bytes = std::fs::metadata(&model).map(|m| m.len()).unwrap_or(0);
    if let Some((table, md, csv)) = &eval_table {
        std::fs::write(a.out.join(table), md).with_context(|| format!("writing {table}"))?;
        if csv.exists() {
            std::fs::copy(csv, a.out.join("summary.csv")).context("copying summary.csv")?;
        }
    }
    let text = readme(
        &a.out,
        &original,
        precision,
        bytes,
        &diff,
        eval_table.as_ref().map(|t| (t.0, t.1.as_str())),
    );
    std::fs::write(a.out.join("README.md"), text).context("writing README.md")?;
    out!("{}: {precision:?}, {:.1} MB; against f32 {diff}", model.display(), bytes as f64 / 1e6);
    Ok(())
}
