//! `mdrlat reproduce`: the paper's evaluation section in one command — train the variants,
//! evaluate them in the unseen worlds, write Table 2, Fig. 4 and the report — as a sweep of
//! resumable jobs run here (`--executor local`) or on a Slurm cluster (`--executor slurm`).

use super::load_world;
use super::train::DeviceKind;
use crate::config::Config;
use crate::progress;
use anyhow::{Context, Result, bail};
use mdrlat_sweep::job::Step;
use mdrlat_sweep::local::{Event, LocalOptions};
use mdrlat_sweep::slurm::SlurmOptions;
use mdrlat_sweep::{JobKind, JobState, Plan, Sweep};
use std::path::PathBuf;
use std::time::Duration;

/// Where the jobs run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Executor {
    /// Child processes on this machine, `--jobs` at a time.
    Local,
    /// A Slurm cluster: an array job for the training runs, dependent jobs after it.
    Slurm,
}

/// Arguments of `mdrlat reproduce`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A built-in sweep: paper (6 variants x 5 seeds x 400k steps), cpu-small (a few hours
    /// on 2 cores), smoke (minutes), nav (the navigation experiment) or fast (6 variants x 3
    /// seeds x 100k steps of mdrlat's own recipe, `train --preset fast`). Without --preset or
    /// --sweep, the sweep already in --out is continued.
    #[arg(long, conflicts_with = "sweep")]
    preset: Option<String>,
    /// A sweep file of your own (see `--print paper` for every key).
    #[arg(long, value_name = "FILE")]
    sweep: Option<PathBuf>,
    /// Print a preset's sweep file and exit.
    #[arg(long, value_name = "PRESET", exclusive = true)]
    print: Option<String>,
    /// Output folder: one sub-folder per job, table2.md/csv, fig4.png, report.md. Rerun
    /// with the same folder to continue after an interruption.
    #[arg(long, required_unless_present = "print")]
    out: Option<PathBuf>,
    /// Where the jobs run.
    #[arg(long, value_enum, default_value = "local")]
    executor: Executor,
    /// Local executor: jobs at a time (the cores are split between them).
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    /// Slurm: partition of every job.
    #[arg(long)]
    partition: Option<String>,
    /// Slurm: time limit of every job (e.g. 2-00:00:00); a training job cut off by it is
    /// resumed from its checkpoint by the next `mdrlat reproduce`.
    #[arg(long)]
    time: Option<String>,
    /// Slurm: generic resources of the training jobs (e.g. gpu:1, with a GPU `device` in
    /// the sweep).
    #[arg(long)]
    gres: Option<String>,
    /// Slurm: CPUs of every job (its threads).
    #[arg(long, default_value_t = 2)]
    cpus_per_task: usize,
    /// Slurm: a further sbatch argument for every job, verbatim (repeatable):
    /// `--slurm-arg=--qos=low`.
    #[arg(long = "slurm-arg", value_name = "ARG", allow_hyphen_values = true)]
    slurm_args: Vec<String>,
    /// Slurm: print the batch scripts instead of submitting them.
    #[arg(long)]
    dry_run: bool,
    /// Slurm: wait until every job has ended; exit non-zero naming any that failed.
    #[arg(long)]
    wait: bool,
    /// Run one job of the sweep in --out in this process (what the executors call).
    #[arg(long, value_name = "ID")]
    job: Option<String>,
    /// Threads of the job (with --job; default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Checks what the sweep crate cannot: the settings parse into a config, the worlds load,
/// the device is in this build.
fn check_sweep(sweep: &Sweep, source: &str) -> Result<()> {
    Config::resolve(None, &sweep.set).with_context(|| format!("{source}: set"))?;
    let nav = sweep.task == mdrlat_sim::config::Task::Nav;
    let check = |spec: &str, key: &str| -> Result<()> {
        let world = load_world(spec).with_context(|| format!("{source}: {key}"))?;
        if nav && world.goals.is_empty() {
            bail!(
                "{source}: {key}: world '{}' has no goal region, and task = \"nav\" draws goals \
                 there (nav-train and nav-test have them; a world file takes a `goal` key)",
                world.name
            );
        }
        Ok(())
    };
    check(&sweep.world, "world")?;
    for w in &sweep.eval.worlds {
        check(w, "eval.worlds")?;
    }
    {
        use clap::ValueEnum;
        // Exactly as `mdrlat train --device` reads it.
        DeviceKind::from_str(&sweep.device, false).map_err(|_| {
            anyhow::anyhow!(
                "{source}: device '{}' is not available in this build (cpu, or rebuild with --features {})",
                sweep.device,
                sweep.device
            )
        })?;
    }
    Ok(())
}

/// Runs `mdrlat reproduce`.
pub fn run(a: &Args) -> Result<()> {
    if let Some(name) = &a.print {
        out!("{}", mdrlat_sweep::spec::preset_text(name)?.trim_end());
        return Ok(());
    }
    let out = a.out.clone().context("--out is required")?;
    if a.executor == Executor::Local {
        let slurm_only = [
            ("--dry-run", a.dry_run),
            ("--wait", a.wait),
            ("--partition", a.partition.is_some()),
            ("--time", a.time.is_some()),
            ("--gres", a.gres.is_some()),
            ("--slurm-arg", !a.slurm_args.is_empty()),
        ];
        if let Some((flag, _)) = slurm_only.iter().find(|f| f.1) {
            bail!(
                "{flag} is for --executor slurm (the local executor runs the jobs and waits for them)"
            );
        }
    }
    if a.threads.is_some() && a.job.is_none() {
        bail!("--threads is a job's (with --job); the local executor splits the cores by --jobs");
    }
    if let Some(id) = &a.job {
        return run_job(&out, id, a.threads.unwrap_or_else(cores));
    }
    let (sweep, source) = match (&a.preset, &a.sweep) {
        (Some(p), _) => (Sweep::preset(p)?, format!("preset '{p}'")),
        (None, Some(f)) => (Sweep::load(f)?, f.display().to_string()),
        (None, None) => {
            let plan = Plan::load(&out).with_context(|| {
                format!("{}: give --preset or --sweep to start a sweep there", out.display())
            })?;
            (plan.sweep, out.join("sweep.toml").display().to_string())
        }
    };
    check_sweep(&sweep, &source)?;
    let plan = Plan::new(sweep, &out);
    plan.open()?;
    let exe = std::env::current_exe().context("cannot find the mdrlat binary's own path")?;
    let exe = exe.canonicalize().unwrap_or(exe);
    match a.executor {
        Executor::Local => {
            if a.jobs == 0 || a.jobs > 256 {
                bail!("--jobs {}: must be 1 to 256", a.jobs);
            }
            run_local(&plan, &exe, a.jobs)
        }
        Executor::Slurm => run_slurm(&plan, &exe, a),
    }
}

fn run_local(plan: &Plan, exe: &std::path::Path, jobs: usize) -> Result<()> {
    let opts = LocalOptions { jobs, cores: cores() };
    let total = plan.jobs.len() as u64;
    let pb = progress::jobs_bar(total);
    let mut running: Vec<String> = Vec::new();
    let show = |(id, p): &(String, Option<(u64, u64)>)| match p {
        Some((step, steps)) => {
            format!("{id} {:.1}k/{:.0}k", *step as f64 / 1e3, *steps as f64 / 1e3)
        }
        None => id.clone(),
    };
    out!(
        "sweep '{}' in {}: {} jobs, {} at a time with {} thread(s) each; logs in {}/logs",
        plan.sweep.name,
        plan.dir.display(),
        total,
        opts.jobs,
        opts.threads(),
        plan.dir.display()
    );
    let result = mdrlat_sweep::local::run(plan, exe, &opts, |e| {
        match e {
            Event::Skipped(_) => pb.inc(1),
            Event::Started(id, resumes) => {
                running.push(id.clone());
                let how = if *resumes { " (resuming)" } else { "" };
                pb.suspend(|| out!("started  {id}{how}"));
            }
            Event::Finished(id, ok, secs) => {
                running.retain(|r| r != id);
                pb.inc(1);
                let word = if *ok { "finished" } else { "FAILED  " };
                pb.suspend(|| out!("{word} {id} ({secs:.0} s)"));
            }
            Event::Running(now) => {
                pb.set_message(now.iter().map(show).collect::<Vec<_>>().join(", "));
                return;
            }
        }
        pb.set_message(running.join(", "));
    });
    pb.finish_and_clear();
    report_outcome(plan, result)
}

fn report_outcome(plan: &Plan, result: Result<(), mdrlat_sweep::SweepError>) -> Result<()> {
    let table = plan.dir.join("table2.md");
    match result {
        Ok(()) => {
            out!("wrote {0}/table2.md, table2.csv, fig4.png, report.md", plan.dir.display());
            if let Ok(text) = std::fs::read_to_string(&table) {
                out!("\n{}", text.trim_end());
            }
            Ok(())
        }
        Err(e) => {
            if table.exists() {
                out!(
                    "the tables in {} are incomplete: they say which cells are missing and why",
                    plan.dir.display()
                );
            }
            Err(e.into())
        }
    }
}

fn run_slurm(plan: &Plan, exe: &std::path::Path, a: &Args) -> Result<()> {
    let opts = SlurmOptions {
        partition: a.partition.clone(),
        time: a.time.clone(),
        gres: a.gres.clone(),
        cpus_per_task: a.cpus_per_task.max(1),
        extra: a.slurm_args.clone(),
    };
    if a.dry_run {
        for s in mdrlat_sweep::slurm::scripts(plan, exe, &opts) {
            out!("# ---- {}.sbatch ({} job(s)) ----\n{}", s.name, s.jobs.len(), s.text.trim_end());
        }
        return Ok(());
    }
    let submitted = mdrlat_sweep::slurm::submit(plan, exe, &opts)?;
    if submitted.jobs.is_empty() {
        out!("every job of the sweep in {} is finished", plan.dir.display());
        return report_outcome(plan, mdrlat_sweep::local::outcome(plan));
    }
    let word =
        if submitted.resumed { "still in Slurm from an earlier submission" } else { "submitted" };
    for (name, id) in &submitted.jobs {
        out!("{word} {name}: Slurm job {id}");
    }
    out!("scripts in {0}/slurm, logs in {0}/logs", plan.dir.display());
    if !a.wait {
        out!(
            "rerun with --wait to follow (nothing is queued twice while these are in Slurm); once they ended, rerun to continue after a failure"
        );
        return Ok(());
    }
    let pb = progress::jobs_bar(plan.jobs.len() as u64);
    let result = mdrlat_sweep::slurm::wait(plan, &submitted, Duration::from_secs(2), |active| {
        let done = plan.jobs.iter().filter(|j| plan.state(j) == JobState::Done).count();
        pb.set_position(done as u64);
        pb.set_message(format!("{active} in Slurm"));
    });
    pb.finish_and_clear();
    report_outcome(plan, result)
}

/// Runs one step of a job by calling what the `mdrlat` command it shows as calls.
fn run_step(step: &Step) -> Result<()> {
    match step {
        Step::Train(t) => super::train::run(&super::train::Args::from_step(t)?),
        Step::Resume(dir) => super::train::run(&super::train::Args::resume(dir)),
        Step::Evaluate(e) => super::eval::run(&super::eval::Args::from_step(e)?),
        Step::Plot { out, runs } => super::plot::run(&super::plot::Args::by_variant(out, runs)),
    }
}

/// Runs one job in this process: waits for its lock, skips it if finished, runs its
/// `mdrlat` command lines, then marks it done (or failed, with the reason).
fn run_job(dir: &std::path::Path, id: &str, threads: usize) -> Result<()> {
    let plan = Plan::load(dir)?;
    let job = plan.job(id)?.clone();
    let _lock = mdrlat_sweep::job::lock(&plan, &job)?;
    if plan.state(&job) == JobState::Done {
        out!("{id}: already finished");
        return Ok(());
    }
    let result = (|| -> Result<()> {
        plan.check_needs(&job)?;
        for step in mdrlat_sweep::job::steps(&plan, &job, threads)? {
            out!("{id}: mdrlat {}", step.argv().join(" "));
            run_step(&step)?;
        }
        if job.kind == JobKind::Tables {
            let table = mdrlat_sweep::tables::write(&plan)?;
            if !table.complete() {
                let empty = table.cells.iter().filter(|c| c.stats().is_none()).count();
                bail!(
                    "table incomplete: {empty} of {} cells have no result (see {})",
                    table.cells.len(),
                    plan.dir.join("table2.md").display()
                );
            }
        }
        Ok(())
    })();
    match result {
        Ok(()) => {
            plan.mark_done(&job)?;
            out!("{id}: finished");
            Ok(())
        }
        Err(e) => {
            let why = format!("{e:#}");
            let line = why.lines().next().unwrap_or("failed");
            plan.mark_failed(&job, &format!("{line}; log {}", plan.log_name(&job)))?;
            Err(e)
        }
    }
}
