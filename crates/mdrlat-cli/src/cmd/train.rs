//! `mdrlat train`: one training run of Algorithm 1 into a run directory.

use super::TaskArgs;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use mdrlat_nn::Variant;
use mdrlat_nn::burn::prelude::Device;
use mdrlat_sim::config::Task;
use mdrlat_train::{Config, Preset, RunDir, RunInfo};
use std::path::PathBuf;

/// The compute device. Backends other than `cpu` exist when the binary is built with
/// their cargo feature (`--features wgpu`, `tch` or `cuda`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DeviceKind {
    /// burn's pure-Rust CPU backend (flex): no set-up, the default everywhere.
    Cpu,
    /// The first GPU through wgpu (Vulkan, Metal or DX12).
    #[cfg(feature = "wgpu")]
    Wgpu,
    /// LibTorch on the CPU.
    #[cfg(feature = "tch")]
    Tch,
    /// LibTorch on CUDA GPU 0.
    #[cfg(feature = "tch")]
    TchCuda,
    /// CUDA GPU 0 through CubeCL.
    #[cfg(feature = "cuda")]
    Cuda,
}

impl DeviceKind {
    /// The burn device, the process readied for it (`mdrlat_train::prepare_device`).
    #[allow(deprecated)] // burn-tch is deprecated upstream; it is our `tch` backend.
    pub fn device(self) -> Device {
        let device = match self {
            DeviceKind::Cpu => Device::flex(),
            #[cfg(feature = "wgpu")]
            DeviceKind::Wgpu => Device::wgpu(mdrlat_nn::burn::tensor::DeviceKind::DefaultDevice),
            #[cfg(feature = "tch")]
            DeviceKind::Tch => Device::libtorch(),
            #[cfg(feature = "tch")]
            DeviceKind::TchCuda => Device::libtorch_cuda(0),
            #[cfg(feature = "cuda")]
            DeviceKind::Cuda => Device::cuda(0),
        };
        mdrlat_train::prepare_device(&device);
        device
    }

    /// The name used on the command line and in `run.toml`.
    pub fn name(self) -> String {
        use clap::ValueEnum;
        self.to_possible_value()
            .map_or_else(|| format!("{self:?}").to_lowercase(), |v| v.get_name().to_string())
    }
}

/// Arguments of `mdrlat train`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Network variant: laser-only, depth-only, multi, multi-at, multi-bf or mdrlat
    /// (default: the config's, mdrlat).
    #[arg(long)]
    variant: Option<Variant>,
    /// World(s) to train in: a built-in name, a .toml world file, a map_server .yaml, a
    /// generated world gen-N, or several, comma-separated, with gen-A..B for gen-A to
    /// gen-(B-1) (default: train; nav-train for --task nav)
    #[arg(long)]
    world: Option<String>,
    /// Settings to start from, below --config and --set: paper (the defaults) or fast
    /// (mdrlat's own recipe, configs/fast.toml)
    #[arg(long, default_value = "paper")]
    preset: Preset,
    #[command(flatten)]
    task: TaskArgs,
    /// Environment steps (default: the config's, 400,000).
    #[arg(long)]
    steps: Option<u64>,
    /// Seed of the run (default: the config's, 0).
    #[arg(long)]
    seed: Option<u64>,
    /// Run directory; must not exist yet (or be empty).
    #[arg(long, required_unless_present = "resume", conflicts_with = "resume")]
    out: Option<PathBuf>,
    /// Continue the run in this directory exactly from its last checkpoint (its saved
    /// config and world; `--steps` may extend it).
    #[arg(long, value_name = "RUN_DIR", conflicts_with_all = ["variant", "world", "seed", "config", "init_from", "sets", "device", "task", "start", "goal", "preset"])]
    resume: Option<PathBuf>,
    /// Configuration file (see `mdrlat config default`).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Warm start: begin from this trained model's weights (a models/ folder, a
    /// .safetensors file, a run directory or a checkpoint) of the same variant and task,
    /// with an empty replay buffer and fresh optimisers (`train.init_from`)
    #[arg(long, value_name = "MODEL")]
    init_from: Option<PathBuf>,
    /// Override any setting: `--set train.gamma=0.95 --set sim.laser.noise_std_m=0.01`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
    /// Compute device (default: cpu).
    #[arg(long, value_enum)]
    device: Option<DeviceKind>,
}

impl Args {
    /// A sweep's training step, as `mdrlat train` would take it from [`Step::argv`]'s
    /// command line.
    ///
    /// # Errors
    /// A preset or device this build does not know.
    ///
    /// [`Step::argv`]: mdrlat_sweep::job::Step::argv
    pub fn from_step(t: &mdrlat_sweep::job::TrainStep) -> Result<Self> {
        use clap::ValueEnum;
        let device = DeviceKind::from_str(&t.device, true)
            .map_err(|_| anyhow::anyhow!("device '{}' is not available in this build", t.device))?;
        Ok(Args {
            variant: Some(t.variant),
            world: Some(t.world.clone()),
            preset: t.preset.parse().map_err(anyhow::Error::msg)?,
            // As the command line it shows as: `--task` only when not the default.
            task: TaskArgs {
                task: (t.task != mdrlat_sim::config::Task::Avoid).then_some(t.task),
                start: None,
                goal: None,
            },
            steps: Some(t.steps),
            seed: Some(t.seed),
            out: Some(t.out.clone()),
            resume: None,
            config: None,
            init_from: None,
            sets: t.sets.clone(),
            device: Some(device),
        })
    }

    /// Continues the run in `dir` (`mdrlat train --resume DIR`).
    pub fn resume(dir: &std::path::Path) -> Self {
        Args {
            variant: None,
            world: None,
            preset: Preset::Paper,
            task: TaskArgs { task: None, start: None, goal: None },
            steps: None,
            seed: None,
            out: None,
            resume: Some(dir.to_path_buf()),
            config: None,
            init_from: None,
            sets: Vec::new(),
            device: None,
        }
    }
}

/// Runs `mdrlat train`.
pub fn run(a: &Args) -> Result<()> {
    let (root, opened, config, info) = match &a.resume {
        Some(root) => {
            let (dir, mut config, info) = RunDir::open(root)?;
            if let Some(s) = a.steps {
                config.train.total_steps = s;
                // The run's config records how long it now runs, for later resumes.
                dir.write_config(&config)?;
            }
            (root.clone(), Some(dir), config, info)
        }
        None => {
            let root = a.out.clone().context("--out is required")?;
            let mut config = Config::resolve_preset(a.preset, a.config.as_deref(), &a.sets)?;
            if let Some(v) = a.variant {
                config.train.variant = v;
            }
            if let Some(s) = a.steps {
                config.train.total_steps = s;
            }
            if let Some(s) = a.seed {
                config.train.seed = s;
            }
            if let Some(m) = &a.init_from {
                config.train.init_from = m.display().to_string();
            }
            a.task.apply(&mut config.sim)?;
            config.validate("--variant, --steps, --seed or --task")?;
            // A warm start's model is checked before the run directory exists.
            if !config.train.init_from.is_empty() {
                let (_, source) = mdrlat_train::init_weights(
                    &config.train,
                    &config.sim,
                    &mdrlat_nn::burn::prelude::Device::flex(),
                )?;
                out!("warm start from {source}");
            }
            let device = a.device.unwrap_or(DeviceKind::Cpu);
            let default_world = a.preset.default_world(config.sim.task);
            let world = a.world.clone().unwrap_or_else(|| default_world.into());
            (root, None, config, RunInfo::new(world, device.name()))
        }
    };
    let worlds = mdrlat_world::load_set(&info.world)?;
    let device = {
        use clap::ValueEnum;
        DeviceKind::from_str(&info.device, true).map_err(|_| {
            anyhow::anyhow!(
                "{}: device '{}' is not available in this build (rebuild with --features {})",
                RunDir::at(&root).run_info().display(),
                info.device,
                info.device
            )
        })?
    };
    let resume = opened.is_some();
    let dir = match opened {
        Some(dir) => dir,
        None => RunDir::create(&root, &config, &info)?,
    };
    let envs = mdrlat_train::TrainEnvs::new(worlds, &config.sim, config.train.envs)?;

    let total = config.train.total_steps;
    let pb = ProgressBar::new(total);
    pb.set_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{bar:30}] {pos}/{len} {per_sec} eta {eta} {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    let on_step = |s: &mdrlat_train::Status| {
        if s.step.is_multiple_of(50) || s.step == total {
            pb.set_position(s.step);
            let eval = s.last_eval.map(|e| format!(" eval {e:.1}")).unwrap_or_default();
            pb.set_message(format!(
                "eps {:.4} td {:.4} at {:.4} ep {}{eval}",
                s.epsilon, s.losses.td, s.losses.at, s.episodes
            ));
        }
    };
    // Ctrl-C (or SIGTERM) stops at the end of the tick under way with a checkpoint there;
    // a second one exits at once.
    let stop = super::ros::stop_flag()?;
    let (report, learner) = mdrlat_train::train_until(
        envs,
        &config.train,
        &device.device(),
        &dir,
        resume,
        on_step,
        &stop,
    )?;
    pb.finish_and_clear();
    if report.stopped {
        anyhow::bail!(
            "stopped at step {} of {} by a signal: the checkpoint at step {} holds the whole \
             run; continue it with `mdrlat train --resume {}`",
            report.steps,
            total,
            report.steps,
            dir.path().display()
        );
    }
    dir.finish(&learner, report.steps, &config.train)?;
    let last = report.evaluations.last().map(|e| {
        let reached = if config.sim.task == Task::Nav {
            format!(", {:.0}% of goals reached", 100.0 * e.success_rate())
        } else {
            String::new()
        };
        format!("{:.2} ± {:.2}{reached}", e.mean(), e.std())
    });
    out!(
        "{} ({}) in '{}': step {} of {}, {} updates, {} episodes, {:.0} s this session; last eval {}",
        config.train.variant,
        config.sim.task,
        info.world,
        report.steps,
        total,
        report.updates,
        report.episodes,
        report.seconds,
        last.unwrap_or_else(|| "none this session".into())
    );
    let total_s = report.timing.parts().iter().map(|(_, s)| s).sum::<f64>().max(1e-9);
    let parts: Vec<String> = report
        .timing
        .parts()
        .iter()
        .map(|(name, s)| format!("{name} {s:.1} s ({:.0}%)", 100.0 * s / total_s))
        .collect();
    out!("where the time went: {}", parts.join(", "));
    let checkpoint = if dir.checkpoint().is_dir() { "checkpoint/, " } else { "" };
    out!(
        "wrote {0}/config.toml, run.toml, metrics.csv, eval.csv, events.out.tfevents.*, {checkpoint}model.safetensors",
        dir.path().display()
    );
    Ok(())
}
