//! `mdrlat eval`: the paper's success-rate protocol (Table 2) for a trained run or a
//! scripted baseline, in any worlds, with Figs. 6/7 on request.

use super::train::DeviceKind;
use super::{PolicyArg, TaskArgs, load_world};
use crate::config::Config;
use crate::progress;
use anyhow::{Context, Result, bail};
use mdrlat_core::Policy;
use mdrlat_eval::{Agent, EvalError, EvalObserver, EvalSettings, Output, Progress, WorldResult};
use mdrlat_eval::{SnapshotResult, snapshots_chart, snapshots_csv, snapshots_markdown};
use mdrlat_plan::MapSource;
use mdrlat_sim::config::Task;
use mdrlat_sim::{MovingRule, SimConfig};
use mdrlat_train::GreedyPolicy;
use mdrlat_train::RunDir;
use mdrlat_train::run_dir::{snapshot_minute, snapshot_name};
use std::path::{Path, PathBuf};

/// The paper's three unseen test worlds (Fig. 5).
const TEST_WORLDS: [&str; 3] = ["office", "furnished", "crowd"];

/// The navigation extension's unseen test world (Fig. 8 right).
const NAV_TEST_WORLDS: [&str; 1] = ["nav-test"];

/// Arguments of `mdrlat eval`.
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("who").required(true).args(["checkpoint", "policy", "snapshots"])))]
pub struct Args {
    /// A run directory of `mdrlat train` (or its checkpoint folder): its network acts greedily.
    #[arg(long, value_name = "RUN_DIR", conflicts_with = "policy")]
    checkpoint: Option<PathBuf>,
    /// Every snapshot of a run (`train.snapshot_minutes`: the policy at fixed minutes of
    /// training), each by the whole protocol into --out/minute-*/, then success against
    /// minutes: --out/snapshots.csv, snapshots.md and snapshots.png (with `--task nav`, of a
    /// navigation run: goals reached against minutes).
    #[arg(long, value_name = "RUN_DIR", conflicts_with_all = ["policy", "checkpoint"])]
    snapshots: Option<PathBuf>,
    /// With --snapshots: keep the snapshots evaluated before in --out by the same protocol
    /// (their summary.csv read back; one of other settings is refused) and evaluate only the
    /// rest, so that the curve of a run still training is brought up to date in minutes.
    #[arg(long, conflicts_with = "overwrite")]
    only_new: bool,
    /// A policy that needs no training instead: random, forward, wander, wander-laser, spin,
    /// circle, avoid, avoid-laser or avoid-stack (`wander` and the classical `avoid` are the
    /// non-learned baseline rows; `avoid-laser`, the avoider on the laser alone, is the
    /// laser-only rows' one beside the six methods; `avoid-stack` remembers only the last
    /// four frames, what a network sees, and `avoid-memory-N` the last N; `spin` and `circle`
    /// game the paper's success, never the moving one); with `--task nav`, `planner` (the
    /// paper's move_base: A* on a laser-plane map of the world + DWA) or `planner-body` (its
    /// map holds everything the body can hit).
    #[arg(long, value_parser = super::parse_policy)]
    policy: Option<PolicyArg>,
    /// World to evaluate in (repeatable): a built-in name, a .toml world file or a
    /// map_server .yaml (default: the paper's test worlds office, furnished and crowd;
    /// with `--task nav`, nav-test).
    #[arg(long = "world", value_name = "W")]
    worlds: Vec<String>,
    /// The task, and a fixed start and goal for navigation.
    #[command(flatten)]
    task: TaskArgs,
    /// Episodes per run (the paper's 50).
    #[arg(long, default_value_t = 50, allow_negative_numbers = true)]
    episodes: u32,
    /// Runs per world, each from other start poses (the paper's 5): mean ± std over runs.
    #[arg(long, default_value_t = 5, allow_negative_numbers = true)]
    runs: u32,
    /// Steps an episode must survive without a collision to succeed (the paper's 300).
    #[arg(long, default_value_t = 300, allow_negative_numbers = true)]
    max_steps: u32,
    /// Seed of the start poses: the same seed gives every method the same starts.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    seed: u64,
    /// Metres an episode must drive to count as a moving success (beside the paper's
    /// success, which a policy turning in place meets).
    #[arg(long, default_value_t = MovingRule::DEFAULT.min_path_m, value_name = "M", allow_negative_numbers = true)]
    min_path: f32,
    /// Metres from its start an episode must get at some step to count as a moving success
    /// (a policy circling on the spot drives far but gets nowhere).
    #[arg(long, default_value_t = MovingRule::DEFAULT.min_reach_m, value_name = "M", allow_negative_numbers = true)]
    min_reach: f32,
    /// Output directory: episodes.csv, summary.csv, summary.md (and figures/).
    #[arg(long)]
    out: PathBuf,
    /// Print one JSON object per world on stdout (results and timing) instead of the table.
    #[arg(long)]
    json: bool,
    /// Draw Figs. 6/7 for this many episodes (the longest successes and the dead ends); with
    /// `--task nav` also Fig. 9, the first K start/goal pairs of run 0 on one map.
    #[arg(long, default_value_t = 0, value_name = "K", allow_negative_numbers = true)]
    figures: usize,
    /// Environments stepped together; the network decides for all running ones in one
    /// batch (0: 16 per inference thread, at least 64). Results do not depend on it.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    envs: usize,
    /// Observations per network forward: a batch is decided in forwards of exactly this many
    /// (the last padded), side by side on the inference threads. A decision then does not
    /// depend on which episodes share its batch, so results do not depend on --envs.
    #[arg(long, default_value_t = super::bench_train::EVAL_FORWARD_BATCH)]
    forward_batch: usize,
    /// CPU threads of the network's inference (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Opt-in: the network's linear layers read bfloat16 weights (see `mdrlat ros --bf16`),
    /// to measure what that precision does to the success rate. Needs AVX-512.
    #[arg(long, conflicts_with = "policy")]
    bf16: bool,
    /// Threads stepping the simulator (0: all cores; measured faster than 1 even beside a
    /// network, which has the cores to itself while the simulator waits).
    #[arg(long, default_value_t = 0)]
    sim_threads: usize,
    /// Compute device of the network.
    #[arg(long, value_enum, default_value = "cpu")]
    device: DeviceKind,
    /// Simulator settings (see `mdrlat config default`); the same for every method compared.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Replace the results of an earlier evaluation in --out.
    #[arg(long)]
    overwrite: bool,
}

impl Args {
    /// A sweep's evaluation step, as `mdrlat eval` would take it from its command line.
    ///
    /// # Errors
    /// A baseline this build does not know.
    pub fn from_step(e: &mdrlat_sweep::job::EvalStep) -> Result<Self> {
        use mdrlat_sweep::job::Who;
        let (checkpoint, policy) = match &e.who {
            Who::Run(run) => (Some(run.clone()), None),
            Who::Baseline(name) => {
                (None, Some(super::parse_policy(name).map_err(anyhow::Error::msg)?))
            }
        };
        Ok(Args {
            checkpoint,
            snapshots: None,
            only_new: false,
            policy,
            worlds: e.worlds.clone(),
            // As the command line it shows as: `--task` only when not the default.
            task: TaskArgs {
                task: (e.task != Task::Avoid).then_some(e.task),
                start: None,
                goal: None,
            },
            episodes: e.episodes,
            runs: e.runs,
            max_steps: e.max_steps,
            seed: e.seed,
            min_path: e.min_path_m,
            min_reach: e.min_reach_m,
            out: e.out.clone(),
            json: false,
            figures: e.figures as usize,
            envs: 0,
            forward_batch: super::bench_train::EVAL_FORWARD_BATCH,
            threads: Some(e.threads),
            bf16: false,
            sim_threads: 0,
            device: DeviceKind::Cpu,
            config: None,
            overwrite: true,
        })
    }
}

/// Runs `mdrlat eval`.
pub fn run(a: &Args) -> Result<()> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let (settings, config, worlds) = prepare(a, cores)?;
    match &a.snapshots {
        Some(run) => run_snapshots(a, run, cores, &settings, &config, &worlds),
        None => run_one(a, cores, &settings, &config, &worlds),
    }
}

/// The protocol's settings, the simulator's configuration and the worlds of `a`.
fn prepare(a: &Args, cores: usize) -> Result<(EvalSettings, Config, Vec<mdrlat_world::World>)> {
    if a.threads == Some(0) || a.threads.is_some_and(|t| t > 1024) {
        bail!("--threads {}: must be 1 to 1024", a.threads.unwrap_or_default());
    }
    if a.only_new && a.snapshots.is_none() {
        bail!("--only-new keeps the evaluated snapshots of --snapshots RUN_DIR: give that");
    }
    let settings = EvalSettings {
        episodes: a.episodes,
        runs: a.runs,
        max_steps: a.max_steps,
        seed: a.seed,
        envs: if a.envs == 0 {
            (16 * a.threads.unwrap_or(cores)).clamp(64, mdrlat_eval::protocol::MAX_ENVS)
        } else {
            a.envs
        },
        sim_threads: a.sim_threads,
        moving: MovingRule { min_path_m: a.min_path, min_reach_m: a.min_reach },
    };
    settings.validate()?;
    if a.forward_batch == 0 || a.forward_batch > 4096 {
        bail!("--forward-batch {}: must be 1 to 4096", a.forward_batch);
    }
    let mut config = Config::load_or_default(a.config.as_deref())?;
    a.task.apply(&mut config.sim)?;
    config.sim.validate()?;
    let nav = config.sim.task == Task::Nav;
    let names: Vec<String> = if a.worlds.is_empty() {
        let default: &[&str] = if nav { &NAV_TEST_WORLDS } else { &TEST_WORLDS };
        default.iter().map(|s| s.to_string()).collect()
    } else {
        a.worlds.clone()
    };
    let worlds = names
        .iter()
        .map(|w| load_world(w).with_context(|| format!("--world {w}")))
        .collect::<Result<Vec<_>>>()?;
    if matches!(a.policy, Some(PolicyArg::Planner(_))) && !nav {
        bail!("--policy planner drives to a goal: add --task nav");
    }
    Ok((settings, config, worlds))
}

/// The trained network at `path` (a run, checkpoint, model file or folder) as `a` asks for
/// it, checked against the task, its FLOPs per decision, and `sim` drawing the scan it
/// reads ([`GreedyPolicy::adopt_scan`]).
fn network(
    a: &Args,
    path: &Path,
    flag: &str,
    cores: usize,
    sim: &SimConfig,
) -> Result<(GreedyPolicy, f64, SimConfig)> {
    let device = a.device.device();
    let p = GreedyPolicy::load(path, &device, a.threads.unwrap_or(cores))
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("{flag} {}", path.display()))?
        .with_forward_batch(Some(a.forward_batch));
    let p = if a.bf16 {
        p.with_bf16_weights().map_err(anyhow::Error::msg).context("--bf16")?
    } else {
        p
    };
    let what = format!("{flag} {}", path.display());
    let mut sim = sim.clone();
    p.fit_sim(&mut sim, &what).map_err(anyhow::Error::msg)?;
    let flops = p.config().decision_flops() as f64;
    Ok((p, flops, sim))
}

/// Continues `run`: the evaluation of one policy (or the planner, per world).
fn run_one(
    a: &Args,
    cores: usize,
    settings: &EvalSettings,
    config: &Config,
    worlds: &[mdrlat_world::World],
) -> Result<()> {
    // The planner's map is its world's: it is made per world below.
    let (mut policy, flop_per_decision, sim): (Option<Box<dyn Policy>>, Option<f64>, SimConfig) =
        match (&a.checkpoint, a.policy) {
            (Some(run), None) => {
                let (p, flops, sim) = network(a, run, "--checkpoint", cores, &config.sim)?;
                (Some(Box::new(p)), Some(flops), sim)
            }
            (None, Some(PolicyArg::Scripted(s))) => {
                (Some(s.build(&config.sim, a.seed)), None, config.sim.clone())
            }
            (None, Some(PolicyArg::Planner(_))) => (None, None, config.sim.clone()),
            _ => bail!(
                "give exactly one of --checkpoint RUN_DIR, --snapshots RUN_DIR and --policy NAME"
            ),
        };
    let mut planner = |world: &mdrlat_world::World| -> Result<Box<dyn Policy>, EvalError> {
        let map = match a.policy {
            Some(PolicyArg::Planner(m)) => m,
            _ => MapSource::LaserPlane,
        };
        super::planner(world, &sim, map)
            .map_err(|e| EvalError::Settings(format!("planner for '{}': {e:#}", world.name)))
    };
    let total = (settings.episodes_per_world() * worlds.len()) as u64;
    let mut shown = Shown { pb: progress::bar(total, "eval"), json: a.json, offset: 0 };
    let agent = match policy.as_mut() {
        Some(p) => Agent::One(p.as_mut()),
        None => Agent::PerWorld(&mut planner),
    };
    let out = Output { dir: &a.out, overwrite: a.overwrite, figures: a.figures };
    let report =
        mdrlat_eval::evaluate(worlds, &sim, settings, agent, flop_per_decision, &out, &mut shown)
            .map_err(flag_hint)?;
    shown.pb.finish_and_clear();
    if !a.json {
        let (names, written) = (report.policies.join(", "), report.written.join(", "));
        out!("{names}: wrote {written} in {}", a.out.display());
    }
    Ok(())
}

/// The library checks an output folder first; here its option is a flag.
fn flag_hint(e: EvalError) -> anyhow::Error {
    match e {
        EvalError::Output(m) if m.contains("already holds an evaluation") => {
            anyhow::anyhow!("{m} (--overwrite)")
        }
        e => e.into(),
    }
}

/// The snapshots of the run in `run` (`train.snapshot_minutes`), in time order.
fn snapshots_of(run: &Path) -> Result<Vec<(f64, PathBuf)>> {
    let dir = RunDir::at(run).snapshots();
    let entries = std::fs::read_dir(&dir).with_context(|| {
        format!(
            "--snapshots {}: no {} (train with --set train.snapshot_minutes=M)",
            run.display(),
            dir.display()
        )
    })?;
    let mut found = Vec::new();
    for entry in entries {
        let path = entry.with_context(|| format!("reading {}", dir.display()))?.path();
        let minute = path.file_name().and_then(|n| n.to_str()).and_then(snapshot_minute);
        if let Some(m) = minute.filter(|_| path.join("model.safetensors").is_file()) {
            found.push((m, path));
        }
    }
    if found.is_empty() {
        bail!(
            "--snapshots {}: {} holds no snapshot (minute-*/model.safetensors)",
            run.display(),
            dir.display()
        );
    }
    found.sort_by(|x, y| x.0.total_cmp(&y.0));
    Ok(found)
}

/// `mdrlat eval --snapshots RUN`: each snapshot by the whole protocol into its own folder,
/// then success against minutes of training.
fn run_snapshots(
    a: &Args,
    run: &Path,
    cores: usize,
    settings: &EvalSettings,
    config: &Config,
    worlds: &[mdrlat_world::World],
) -> Result<()> {
    let snapshots = snapshots_of(run)?;
    // Every folder checked before the first evaluation, not after some are done; with
    // --overwrite, an earlier evaluation's folders of snapshots that no longer exist go;
    // with --only-new, a snapshot's finished evaluation is kept (an unfinished one redone).
    let names: Vec<String> = snapshots.iter().map(|(m, _)| snapshot_name(*m)).collect();
    let mut kept: Vec<Option<Vec<mdrlat_eval::WorldSummary>>> = Vec::new();
    for ((_, path), name) in snapshots.iter().zip(&names) {
        let dir = a.out.join(name);
        let earlier = if a.only_new && dir.join("summary.csv").exists() {
            let label = network(a, path, "--snapshots", 1, &config.sim)?.0.name();
            mdrlat_eval::run::earlier_evaluation(&dir, &label, worlds, settings)
                .map_err(|e| anyhow::anyhow!("{e} (or leave out --only-new)"))?
        } else {
            None
        };
        if earlier.is_none() {
            mdrlat_eval::prepare_output(&dir, a.overwrite || a.only_new).map_err(flag_hint)?;
        }
        kept.push(earlier);
    }
    if a.overwrite {
        for entry in std::fs::read_dir(&a.out).with_context(|| a.out.display().to_string())? {
            let path = entry?.path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            if snapshot_minute(name).is_some() && !names.iter().any(|n| n == name) {
                std::fs::remove_dir_all(&path)
                    .with_context(|| format!("removing the stale {}", path.display()))?;
            }
        }
    }
    let fresh = kept.iter().filter(|k| k.is_none()).count();
    let total = (settings.episodes_per_world() * worlds.len() * fresh) as u64;
    let mut shown = Shown { pb: progress::bar(total, "eval"), json: a.json, offset: 0 };
    let mut rows = Vec::new();
    let mut cpus: Vec<String> = Vec::new();
    let per_snapshot = (settings.episodes_per_world() * worlds.len()) as u64;
    let mut evaluated = 0;
    for (((minute, path), name), earlier) in snapshots.iter().zip(&names).zip(kept) {
        let meta = mdrlat_train::export::safetensors_metadata(&path.join("model.safetensors"))
            .map_err(anyhow::Error::msg)?;
        let step = meta.get("mdrlat_step").map_or(String::new(), |s| format!(", step {s}"));
        let summaries = match earlier {
            Some(summaries) => {
                if !a.json {
                    shown
                        .pb
                        .suspend(|| out!("{name}{step}: kept from {}", a.out.join(name).display()));
                }
                summaries
            }
            None => {
                let (mut p, flops, sim) = network(a, path, "--snapshots", cores, &config.sim)?;
                let dir = a.out.join(name);
                let out = Output { dir: &dir, overwrite: true, figures: a.figures };
                shown.offset = evaluated * per_snapshot;
                evaluated += 1;
                if !a.json {
                    shown.pb.suspend(|| out!("{name}{step}:"));
                }
                let report = mdrlat_eval::evaluate(
                    worlds,
                    &sim,
                    settings,
                    Agent::One(&mut p),
                    Some(flops),
                    &out,
                    &mut shown,
                )
                .map_err(flag_hint)?;
                report.worlds.into_iter().map(|w| w.summary).collect()
            }
        };
        let cpu = meta.get("mdrlat_cpu").cloned().unwrap_or_else(|| "an unrecorded CPU".into());
        if !cpus.contains(&cpu) {
            cpus.push(cpu);
        }
        rows.push(SnapshotResult {
            minute: meta
                .get("mdrlat_snapshot_minute")
                .and_then(|m| m.parse().ok())
                .unwrap_or(*minute),
            training_minutes: meta.get("mdrlat_training_minutes").and_then(|m| m.parse().ok()),
            step: meta.get("mdrlat_step").and_then(|s| s.parse().ok()),
            worlds: summaries,
        });
    }
    shown.pb.finish_and_clear();
    let name =
        run.file_name().map_or_else(|| run.display().to_string(), |n| n.to_string_lossy().into());
    // A run resumed on other machines names each.
    let cpu = cpus.join(" and ");
    let title = format!("{name}, against minutes of training on {cpu}");
    mdrlat_eval::run::write(&a.out.join("snapshots.csv"), &snapshots_csv(&rows))?;
    mdrlat_eval::run::write(&a.out.join("snapshots.md"), &snapshots_markdown(&rows, &title))?;
    let png = a.out.join("snapshots.png");
    snapshots_chart(&rows, &name, &cpu).save_png(&png)?;
    if !a.json {
        out!(
            "{} snapshots of {}: wrote minute-*/, snapshots.csv, snapshots.md, snapshots.png in {}",
            rows.len(),
            run.display(),
            a.out.display()
        );
    }
    Ok(())
}

/// The progress bar, and each world's line as it is done.
struct Shown {
    pb: indicatif::ProgressBar,
    json: bool,
    /// Episodes done before this evaluation (earlier snapshots').
    offset: u64,
}

impl EvalObserver for Shown {
    fn progress(&mut self, before: usize, p: &Progress<'_>) {
        self.pb.set_position(self.offset + (before + p.done) as u64);
        let pct = |n: usize| 100.0 * n as f64 / p.done.max(1) as f64;
        self.pb.set_message(format!(
            "{} {:.0}% moving, {:.0}% no collision",
            p.world,
            pct(p.moving_successes),
            pct(p.successes)
        ));
    }

    fn world_done(&mut self, r: &WorldResult) {
        let json = self.json;
        self.pb.suspend(|| {
            if let Some((n, _)) = &r.navigation {
                out!(
                    "{:<10} reached {}/{} goals ({} collisions, {} timeouts); mean {} s, path {} m, {} x the shortest",
                    n.world,
                    n.reached,
                    n.episodes,
                    n.collisions,
                    n.timeouts,
                    n.time_s_mean.map_or("—".into(), |x| format!("{x:.1}")),
                    n.path_m_mean.map_or("—".into(), |x| format!("{x:.2}")),
                    n.path_ratio_mean.map_or("—".into(), |x| format!("{x:.2}"))
                );
            }
            let (summary, timing) = (&r.summary, &r.timing);
            if json {
                out!("{}", summary.json(Some(timing)));
            } else {
                let rate = timing
                    .gflops()
                    .map(|g| format!(", network at {g:.1} GFLOP/s"))
                    .unwrap_or_default();
                out!(
                    "{:<10} moving success {:>5.1} ± {:>4.1} %  (paper's success {:>5.1} ± {:>4.1} %, path {:.1} m)  ({} collisions: {} bumper, {} pedestrian, {} laser)  {:.1} s, {:.0} decisions/s{rate}",
                    summary.world,
                    100.0 * summary.moving_success_mean,
                    100.0 * summary.moving_success_std,
                    100.0 * summary.success_mean,
                    100.0 * summary.success_std,
                    summary.path_m_mean,
                    summary.collisions_bumper
                        + summary.collisions_pedestrian
                        + summary.collisions_laser,
                    summary.collisions_bumper,
                    summary.collisions_pedestrian,
                    summary.collisions_laser,
                    timing.wall_s,
                    timing.decisions_per_s()
                );
            }
        });
    }
}
