//! A sweep as jobs, each with its own folder: train every (variant, seed), evaluate every
//! final model and baseline, then write the tables. A job is finished when its marker
//! `state/<job>.done` exists; it is written only after the job's outputs are complete, so a
//! job killed at any moment is simply not finished and runs again (training resumes from its
//! last checkpoint).

use crate::{SweepError, spec::Sweep};
use mdrlat_core::Variant;
use std::path::{Path, PathBuf};

/// What a job does.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum JobKind {
    /// Trains one variant with one seed (`mdrlat train`).
    Train {
        /// Network variant.
        variant: Variant,
        /// Seed of the run.
        seed: u64,
    },
    /// Evaluates a trained run's final model in the test worlds (`mdrlat eval`).
    EvalModel {
        /// Network variant.
        variant: Variant,
        /// Seed of the run.
        seed: u64,
        /// Episodes drawn as Figs. 6/7 (start/goal pairs as Fig. 9 in navigation).
        figures: u32,
    },
    /// Evaluates a baseline (scripted, or the classical planner) in the test worlds.
    EvalBaseline {
        /// The baseline's name (`wander`, `planner`, ...).
        policy: String,
        /// Start/goal pairs drawn as Fig. 9 (navigation; 0 in obstacle avoidance).
        figures: u32,
    },
    /// Table 2, Fig. 4 and the report from every evaluation.
    Tables,
}

/// One job of a sweep.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Job {
    /// `train/mdrlat-s0`, `eval/mdrlat-s0`, `eval/wander` or `tables`.
    pub id: String,
    /// What it does.
    pub kind: JobKind,
    /// Jobs that must be finished first (ids).
    pub needs: Vec<String>,
}

/// The jobs of a sweep under an output folder.
#[derive(Debug, Clone)]
pub struct Plan {
    /// The sweep.
    pub sweep: Sweep,
    /// The output folder (absolute when made by [`Plan::new`] from a relative one).
    pub dir: PathBuf,
    /// Every job: training runs, then evaluations, then the tables.
    pub jobs: Vec<Job>,
}

/// Where a job stands.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum JobState {
    /// Finished: its outputs are complete.
    Done,
    /// Started before and interrupted (a training run with a checkpoint resumes from it).
    Partial,
    /// Not started.
    Pending,
    /// Its last attempt failed (the marker says how; the log has the rest).
    Failed(String),
}

/// The run name of a training run: `mdrlat-s0`.
pub fn run_name(variant: Variant, seed: u64) -> String {
    format!("{variant}-s{seed}")
}

impl Plan {
    /// The jobs of `sweep` in `dir`.
    pub fn new(sweep: Sweep, dir: &Path) -> Plan {
        let dir = std::path::absolute(dir).unwrap_or_else(|_| dir.to_path_buf());
        let mut jobs = Vec::new();
        for (variant, seed) in sweep.runs() {
            jobs.push(Job {
                id: format!("train/{}", run_name(variant, seed)),
                kind: JobKind::Train { variant, seed },
                needs: Vec::new(),
            });
        }
        let figure_seed = sweep.seeds.first().copied();
        // Figs. 6/7 for one model; Fig. 9 (navigation) for every method's first model.
        let nav = sweep.task == mdrlat_sim::config::Task::Nav;
        for (variant, seed) in sweep.runs() {
            let drawn = nav || sweep.eval.figure_variant == Some(variant);
            let figures = if drawn && Some(seed) == figure_seed { sweep.eval.figures } else { 0 };
            let name = run_name(variant, seed);
            jobs.push(Job {
                id: format!("eval/{name}"),
                kind: JobKind::EvalModel { variant, seed, figures },
                needs: vec![format!("train/{name}")],
            });
        }
        for b in &sweep.eval.baselines {
            jobs.push(Job {
                id: format!("eval/{b}"),
                kind: JobKind::EvalBaseline {
                    policy: b.clone(),
                    figures: if nav { sweep.eval.figures } else { 0 },
                },
                needs: Vec::new(),
            });
        }
        let evals = jobs.iter().filter(|j| j.id.starts_with("eval/")).map(|j| j.id.clone());
        let needs = evals.collect();
        jobs.push(Job { id: "tables".into(), kind: JobKind::Tables, needs });
        Plan { sweep, dir, jobs }
    }

    /// The job with this id.
    pub fn job(&self, id: &str) -> Result<&Job, SweepError> {
        self.jobs
            .iter()
            .find(|j| j.id == id)
            .ok_or_else(|| SweepError::UnknownJob { id: id.to_string(), dir: self.dir.clone() })
    }

    /// The folder a job writes its results to (a training run's run directory, an
    /// evaluation's `mdrlat eval --out`; the tables go into the sweep's folder itself).
    pub fn job_dir(&self, job: &Job) -> PathBuf {
        match job.kind {
            JobKind::Tables => self.dir.clone(),
            _ => self.dir.join(&job.id),
        }
    }

    /// A job's log file (stdout and stderr of its process).
    pub fn log_path(&self, job: &Job) -> PathBuf {
        self.dir.join(self.log_name(job))
    }

    /// A job's log relative to the sweep's folder (`logs/train-mdrlat-s0.log`): what results
    /// files name, so that they do not depend on where the folder is.
    pub fn log_name(&self, job: &Job) -> String {
        format!("logs/{}.log", file_id(&job.id))
    }

    /// The first job `job` needs that is not finished.
    pub fn blocked_by(&self, job: &Job) -> Option<&Job> {
        job.needs.iter().filter_map(|n| self.job(n).ok()).find(|n| self.state(n) != JobState::Done)
    }

    fn marker(&self, job: &Job, ext: &str) -> PathBuf {
        self.dir.join("state").join(format!("{}.{ext}", file_id(&job.id)))
    }

    /// The lock a running job holds (two processes never run one job at once: a second
    /// waits, then finds it finished).
    pub fn lock_path(&self, job: &Job) -> PathBuf {
        self.marker(job, "lock")
    }

    /// Where a job stands, from its folder and markers.
    pub fn state(&self, job: &Job) -> JobState {
        if self.marker(job, "done").exists() {
            return JobState::Done;
        }
        if let Ok(why) = std::fs::read_to_string(self.marker(job, "failed")) {
            return JobState::Failed(why.trim().to_string());
        }
        match job.kind {
            JobKind::Train { .. } if has_checkpoint(&self.job_dir(job)) => JobState::Partial,
            JobKind::Tables => JobState::Pending,
            _ if self.job_dir(job).exists() => JobState::Partial,
            _ => JobState::Pending,
        }
    }

    /// Refuses to run a job before what it needs is finished (an evaluation of a training
    /// run cut off mid-way would otherwise evaluate an unfinished model). The tables need
    /// nothing finished: they say what is missing.
    pub fn check_needs(&self, job: &Job) -> Result<(), SweepError> {
        if job.kind == JobKind::Tables {
            return Ok(());
        }
        for n in &job.needs {
            let need = self.job(n)?;
            if self.state(need) != JobState::Done {
                return Err(SweepError::NotReady { job: job.id.clone(), need: n.clone() });
            }
        }
        Ok(())
    }

    /// How far a running training job is: (its last logged step, the sweep's steps), read
    /// from the tail of its `metrics.csv`; `None` for other jobs or before the first row.
    pub fn progress(&self, job: &Job) -> Option<(u64, u64)> {
        use std::io::{Read, Seek, SeekFrom};
        if !matches!(job.kind, JobKind::Train { .. }) {
            return None;
        }
        let mut f = std::fs::File::open(self.job_dir(job).join("metrics.csv")).ok()?;
        let len = f.metadata().ok()?.len();
        f.seek(SeekFrom::Start(len.saturating_sub(512))).ok()?;
        let mut tail = String::new();
        f.read_to_string(&mut tail).ok()?;
        let step = tail.lines().rev().find_map(|l| l.split(',').next()?.parse::<u64>().ok())?;
        Some((step, self.sweep.steps))
    }

    /// Records that a job finished (its outputs are complete).
    pub fn mark_done(&self, job: &Job) -> Result<(), SweepError> {
        let failed = self.marker(job, "failed");
        if failed.exists() {
            std::fs::remove_file(&failed).map_err(|e| io(&failed, e))?;
        }
        write_atomic(&self.marker(job, "done"), format!("{}\n", job.id).as_bytes())
    }

    /// Records that a job failed and why (one line).
    pub fn mark_failed(&self, job: &Job, why: &str) -> Result<(), SweepError> {
        write_atomic(&self.marker(job, "failed"), format!("{why}\n").as_bytes())
    }

    /// Clears a failure record before a new attempt.
    pub fn clear_failed(&self, job: &Job) -> Result<(), SweepError> {
        let failed = self.marker(job, "failed");
        match std::fs::remove_file(&failed) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(io(&failed, e)),
        }
    }

    /// The training jobs, in order.
    pub fn train_jobs(&self) -> impl Iterator<Item = &Job> {
        self.jobs.iter().filter(|j| matches!(j.kind, JobKind::Train { .. }))
    }

    /// The evaluation jobs, in order (models, then baselines).
    pub fn eval_jobs(&self) -> impl Iterator<Item = &Job> {
        self.jobs
            .iter()
            .filter(|j| matches!(j.kind, JobKind::EvalModel { .. } | JobKind::EvalBaseline { .. }))
    }

    /// Writes `sweep.toml` into a new output folder, or checks that an existing folder
    /// holds the same sweep (a changed sweep under old results is an error naming what
    /// changed, never a silent mix).
    pub fn open(&self) -> Result<(), SweepError> {
        let path = self.dir.join("sweep.toml");
        let text = self.sweep.to_toml();
        match std::fs::read_to_string(&path) {
            Ok(old) => {
                let before = Sweep::parse(&old, &path.display().to_string())?;
                let diff = before.differences(&self.sweep);
                if !diff.is_empty() {
                    return Err(SweepError::Changed { dir: self.dir.clone(), diff });
                }
                Ok(())
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                if self.dir.exists()
                    && std::fs::read_dir(&self.dir).is_ok_and(|mut d| d.next().is_some())
                {
                    return Err(SweepError::NotASweep(self.dir.clone()));
                }
                // sweep.toml first: a folder killed right after is still this sweep's.
                write_atomic(&path, text.as_bytes())?;
                for sub in ["state", "logs"] {
                    let d = self.dir.join(sub);
                    std::fs::create_dir_all(&d).map_err(|e| io(&d, e))?;
                }
                Ok(())
            }
            Err(e) => Err(io(&path, e)),
        }
    }

    /// The plan of the sweep stored in an existing output folder.
    pub fn load(dir: &Path) -> Result<Plan, SweepError> {
        let path = dir.join("sweep.toml");
        if !path.exists() {
            return Err(SweepError::NotASweep(dir.to_path_buf()));
        }
        Ok(Plan::new(Sweep::load(&path)?, dir))
    }
}

/// A job id as a file name: `train/mdrlat-s0` → `train-mdrlat-s0`.
pub fn file_id(id: &str) -> String {
    id.replace('/', "-")
}

/// Whether a run directory holds a checkpoint to resume from: `checkpoint/meta.json`, or
/// `checkpoint.old/meta.json` when the run was killed while swapping in a new checkpoint
/// (training's resume reads that one then, as `mdrlat_train::checkpoint::load` does).
pub fn has_checkpoint(run_dir: &Path) -> bool {
    run_dir.join("run.toml").is_file()
        && ["checkpoint", "checkpoint.old"]
            .iter()
            .any(|c| run_dir.join(c).join("meta.json").is_file())
}

pub(crate) fn io(path: &Path, e: std::io::Error) -> SweepError {
    SweepError::Io { what: path.display().to_string(), source: e }
}

/// Writes a file whole or not at all (a temporary file renamed over it).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), SweepError> {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| io(parent, e))?;
    }
    let tmp = path.with_extension(format!(
        "{}.tmp",
        path.extension().map(|e| e.to_string_lossy().into_owned()).unwrap_or_default()
    ));
    std::fs::write(&tmp, bytes).map_err(|e| io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jobs_follow_the_sweep() {
        let sweep = Sweep::preset("paper").expect("paper");
        let plan = Plan::new(sweep, Path::new("/tmp/x"));
        assert_eq!(plan.train_jobs().count(), 30);
        // 30 models and the baselines spin, wander and avoid.
        assert_eq!(plan.eval_jobs().count(), 33);
        assert_eq!(plan.jobs.len(), 64);
        assert!(plan.job("eval/avoid").is_ok() && plan.job("eval/spin").is_ok());
        assert_eq!(plan.jobs[0].id, "train/laser-only-s0");
        let e = plan.job("eval/mdrlat-s0").expect("eval");
        assert_eq!(e.needs, ["train/mdrlat-s0"]);
        assert!(matches!(e.kind, JobKind::EvalModel { figures: 4, .. }));
        let other = plan.job("eval/mdrlat-s1").expect("eval");
        assert!(matches!(other.kind, JobKind::EvalModel { figures: 0, .. }));
        let tables = plan.job("tables").expect("tables");
        assert_eq!(tables.needs.len(), 33);
        let e = plan.check_needs(e).expect_err("the model is not trained");
        assert_eq!(e.to_string(), "eval/mdrlat-s0 needs train/mdrlat-s0, which is not finished");
        assert!(plan.check_needs(tables).is_ok(), "the tables say what is missing");
        assert!(plan.job("train/nope").is_err());
    }

    #[test]
    fn a_navigation_sweep_draws_fig9_for_every_method_and_passes_its_task() {
        let dir = std::env::temp_dir().join(format!("mdrlat-plan-nav-{}", std::process::id()));
        let plan = Plan::new(Sweep::preset("nav").expect("nav"), &dir);
        for (id, figures) in [
            ("eval/laser-only-s0", 8),
            ("eval/mdrlat-s0", 8),
            ("eval/planner", 8),
            ("eval/planner-body", 8),
            ("eval/wander", 8),
        ] {
            let job = plan.job(id).expect(id);
            let drawn = match job.kind {
                JobKind::EvalModel { figures, .. } | JobKind::EvalBaseline { figures, .. } => {
                    figures
                }
                _ => 0,
            };
            assert_eq!(drawn, figures, "{id}");
            let argv = argv_of(&plan, job, 1);
            assert!(argv.windows(2).any(|w| w == ["--task", "nav"]), "{id}: {argv:?}");
        }
        let train = plan.job("train/mdrlat-s0").expect("train");
        let argv = argv_of(&plan, train, 1);
        assert!(argv.windows(2).any(|w| w == ["--task", "nav"]), "{argv:?}");
        assert!(argv.windows(2).any(|w| w == ["--world", "nav-train"]), "{argv:?}");
        // Obstacle avoidance: no --task, and baselines draw nothing.
        let paper = Plan::new(Sweep::preset("paper").expect("paper"), &dir);
        let wander = paper.job("eval/wander").expect("wander");
        assert_eq!(wander.kind, JobKind::EvalBaseline { policy: "wander".into(), figures: 0 });
        let argv = argv_of(&paper, wander, 1);
        assert!(!argv.contains(&"--task".to_string()), "{argv:?}");
    }

    /// A job's steps as the command lines they show as, joined.
    fn argv_of(plan: &Plan, job: &Job, threads: usize) -> Vec<String> {
        crate::job::steps(plan, job, threads)
            .expect("steps")
            .iter()
            .flat_map(|s| s.argv())
            .collect()
    }

    #[test]
    fn a_changed_sweep_under_old_results_is_refused() {
        let dir = std::env::temp_dir().join(format!("mdrlat-sweep-open-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let sweep = Sweep::preset("smoke").expect("smoke");
        Plan::new(sweep.clone(), &dir).open().expect("new folder");
        Plan::new(sweep.clone(), &dir).open().expect("same sweep again");
        let mut changed = sweep;
        changed.steps = 301;
        let e = Plan::new(changed, &dir).open().expect_err("changed").to_string();
        assert!(e.contains("steps: 300 -> 301") && e.contains(&dir.display().to_string()), "{e}");
        let other = dir.join("not-a-sweep");
        std::fs::create_dir_all(&other).expect("dir");
        std::fs::write(other.join("x"), "x").expect("file");
        let e = Plan::new(Sweep::preset("smoke").expect("smoke"), &other).open();
        assert!(e.expect_err("foreign folder").to_string().contains("sweep.toml"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
