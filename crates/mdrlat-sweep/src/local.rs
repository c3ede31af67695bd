//! The local executor: every job a child process of the same `mdrlat` binary
//! (`mdrlat reproduce --out DIR --job ID`), N at a time, the cores split between them.
//! Finished jobs are skipped; a job whose needs failed is not run; the tables are written
//! last in any case (saying which cells are missing and why).

use crate::SweepError;
use crate::plan::{Job, JobKind, JobState, Plan};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// What the executor reports as it goes.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A job was already finished.
    Skipped(String),
    /// A job started (id, whether it resumes an interrupted attempt).
    Started(String, bool),
    /// A job ended (id, success, seconds).
    Finished(String, bool, f64),
    /// Every few seconds: the running jobs, with (step, steps) for training runs.
    Running(Vec<(String, Option<(u64, u64)>)>),
}

/// How the local executor runs.
#[derive(Debug, Clone)]
pub struct LocalOptions {
    /// Jobs at a time.
    pub jobs: usize,
    /// CPU cores to split between them.
    pub cores: usize,
}

impl LocalOptions {
    /// Cores of one job (at least 1).
    pub fn threads(&self) -> usize {
        (self.cores / self.jobs.max(1)).max(1)
    }
}

/// The command line of a job's process.
pub fn job_command(exe: &Path, plan: &Plan, job: &Job, threads: usize) -> Command {
    let mut c = Command::new(exe);
    c.arg("reproduce")
        .arg("--out")
        .arg(&plan.dir)
        .arg("--job")
        .arg(&job.id)
        .arg("--threads")
        .arg(threads.to_string())
        .env("RAYON_NUM_THREADS", threads.to_string());
    c
}

fn ready(plan: &Plan, job: &Job, running: &[&str]) -> bool {
    if running.contains(&job.id.as_str()) {
        return false;
    }
    match job.kind {
        // The tables come last, once nothing else can run.
        JobKind::Tables => false,
        _ => job.needs.iter().all(|n| plan.job(n).is_ok_and(|n| plan.state(n) == JobState::Done)),
    }
}

/// Runs every unfinished job of `plan` with the `mdrlat` binary `exe`; returns the jobs
/// that failed or could not run (each with its log), also as the error.
pub fn run(
    plan: &Plan,
    exe: &Path,
    opts: &LocalOptions,
    mut on_event: impl FnMut(&Event),
) -> Result<(), SweepError> {
    plan.open()?;
    let threads = opts.threads();
    let mut running: Vec<(String, Child, Instant)> = Vec::new();
    let result = schedule(plan, exe, opts, &mut running, &mut on_event);
    if result.is_err() {
        // The executor cannot go on: its jobs must not run on unwatched (each resumes next time).
        for (_, child, _) in &mut running {
            let _ = child.kill();
            let _ = child.wait();
        }
        return result;
    }
    // The tables, whatever happened before: a partial table says what it lacks.
    let tables = plan.job("tables")?;
    if plan.state(tables) != JobState::Done {
        let mut child = spawn(plan, exe, tables, threads, &mut on_event)?;
        let started = Instant::now();
        let status = child
            .wait()
            .map_err(|e| SweepError::Io { what: "waiting for the tables job".into(), source: e })?;
        ended(plan, tables, status, started, &mut on_event)?;
    }
    outcome(plan)
}

/// The job to start next: an evaluation whose model is trained before any further
/// training, so that finished cells (and their small result files) exist as early as
/// possible, whatever cuts the sweep short; otherwise in the sweep's order.
fn next_job<'p>(plan: &'p Plan, attempted: &[String], running: &[&str]) -> Option<&'p Job> {
    let runnable = |j: &&Job| {
        !attempted.contains(&j.id) && plan.state(j) != JobState::Done && ready(plan, j, running)
    };
    let evals = plan.eval_jobs().find(runnable);
    evals.or_else(|| plan.jobs.iter().find(runnable))
}

/// Runs every job but the tables, `opts.jobs` at a time, until none can run.
fn schedule(
    plan: &Plan,
    exe: &Path,
    opts: &LocalOptions,
    running: &mut Vec<(String, Child, Instant)>,
    on_event: &mut impl FnMut(&Event),
) -> Result<(), SweepError> {
    let threads = opts.threads();
    let mut attempted: Vec<String> = Vec::new();
    let mut last_report = Instant::now();
    for job in &plan.jobs {
        if plan.state(job) == JobState::Done {
            on_event(&Event::Skipped(job.id.clone()));
        }
    }
    loop {
        while running.len() < opts.jobs.max(1) {
            let ids: Vec<&str> = running.iter().map(|r| r.0.as_str()).collect();
            let Some(job) = next_job(plan, &attempted, &ids) else { break };
            attempted.push(job.id.clone());
            running.push((
                job.id.clone(),
                spawn(plan, exe, job, threads, on_event)?,
                Instant::now(),
            ));
        }
        if running.is_empty() {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
        if last_report.elapsed() >= Duration::from_secs(2) {
            last_report = Instant::now();
            let now = running
                .iter()
                .map(|(id, _, _)| (id.clone(), plan.job(id).ok().and_then(|j| plan.progress(j))))
                .collect();
            on_event(&Event::Running(now));
        }
        let mut i = 0;
        while i < running.len() {
            let status = running[i].1.try_wait().map_err(|e| SweepError::Io {
                what: format!("waiting for job {}", running[i].0),
                source: e,
            })?;
            match status {
                Some(status) => {
                    let (id, _, started) = running.swap_remove(i);
                    ended(plan, plan.job(&id)?, status, started, on_event)?;
                }
                None => i += 1,
            }
        }
    }
    Ok(())
}

/// A job's process ended: it succeeded only if it also marked the job done; a failure it did
/// not record itself (a crash, a signal) is recorded with its exit status and log.
fn ended(
    plan: &Plan,
    job: &Job,
    status: std::process::ExitStatus,
    started: Instant,
    on_event: &mut impl FnMut(&Event),
) -> Result<(), SweepError> {
    let ok = status.success() && plan.state(job) == JobState::Done;
    if !ok && !matches!(plan.state(job), JobState::Failed(_)) {
        plan.mark_failed(job, &format!("{status}; log {}", plan.log_name(job)))?;
    }
    on_event(&Event::Finished(job.id.clone(), ok, started.elapsed().as_secs_f64()));
    Ok(())
}

fn spawn(
    plan: &Plan,
    exe: &Path,
    job: &Job,
    threads: usize,
    on_event: &mut impl FnMut(&Event),
) -> Result<Child, SweepError> {
    let resumes = plan.state(job) == JobState::Partial;
    plan.clear_failed(job)?;
    let log_path = plan.log_path(job);
    let log = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&log_path)
        .map_err(|e| crate::plan::io(&log_path, e))?;
    let err = log.try_clone().map_err(|e| crate::plan::io(&log_path, e))?;
    let child = job_command(exe, plan, job, threads)
        .stdin(Stdio::null())
        .stdout(log)
        .stderr(err)
        .spawn()
        .map_err(|e| SweepError::Io {
            what: format!("starting {} for job {}", exe.display(), job.id),
            source: e,
        })?;
    on_event(&Event::Started(job.id.clone(), resumes));
    Ok(child)
}

/// Every job not finished, with why and its log; `Ok` when none.
pub fn outcome(plan: &Plan) -> Result<(), SweepError> {
    let unfinished: Vec<String> = plan
        .jobs
        .iter()
        .filter_map(|j| match plan.state(j) {
            JobState::Done => None,
            JobState::Failed(why) => Some(format!("{} failed ({why})", j.id)),
            _ => Some(match plan.blocked_by(j) {
                Some(n) => format!("{} not run ({} did not finish)", j.id, n.id),
                None => format!("{} did not finish (log {})", j.id, plan.log_path(j).display()),
            }),
        })
        .collect();
    if unfinished.is_empty() { Ok(()) } else { Err(SweepError::Failed(unfinished)) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::Sweep;

    #[test]
    fn a_trained_model_is_evaluated_before_more_training() {
        let dir = std::env::temp_dir().join(format!("mdrlat-sweep-next-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let plan = Plan::new(Sweep::preset("cpu-small").expect("preset"), &dir);
        plan.open().expect("open");
        let next = |attempted: &[String], running: &[&str]| {
            next_job(&plan, attempted, running).map(|j| j.id.clone())
        };
        // Nothing trained: the baselines (which need nothing), then training in order.
        assert_eq!(next(&[], &[]).as_deref(), Some("eval/spin"));
        let baselines = ["eval/spin", "eval/wander", "eval/avoid"];
        assert_eq!(next(&["eval/spin".into()], &[]).as_deref(), Some("eval/wander"));
        let tried: Vec<String> = baselines.iter().map(|b| b.to_string()).collect();
        assert_eq!(next(&tried, &[]).as_deref(), Some("train/laser-only-s0"));
        assert_eq!(next(&tried, &["train/laser-only-s0"]).as_deref(), Some("train/laser-only-s1"));
        // laser-only-s0 trained: its evaluation jumps ahead of depth-only's training.
        plan.mark_done(plan.job("train/laser-only-s0").expect("job")).expect("mark");
        let mut tried = tried;
        tried.push("train/laser-only-s1".into());
        assert_eq!(next(&tried, &[]).as_deref(), Some("eval/laser-only-s0"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
