//! What running one job means: the typed steps it is made of, chosen from where it stands
//! (a training run with a checkpoint resumes; one killed before its first checkpoint starts
//! again; an interrupted evaluation is redone whole, it holds no partial state worth
//! keeping). The CLI runs each step by calling the library in the job's process; every step
//! also shows as the `mdrlat` command line a user would type for it ([`Step::argv`]), which
//! is what the job's log prints.

use crate::SweepError;
use crate::plan::{Job, JobKind, Plan, has_checkpoint, io};
use mdrlat_core::Variant;
use mdrlat_sim::config::Task;
use std::path::{Path, PathBuf};

/// One step of a job.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// Starts a training run.
    Train(TrainStep),
    /// Continues the training run in this folder from its checkpoint.
    Resume(PathBuf),
    /// Evaluates a trained run or a baseline in the test worlds.
    Evaluate(EvalStep),
    /// Fig. 4 from the runs' `eval.csv`, averaged per variant, into `out`.
    Plot {
        /// The PNG.
        out: PathBuf,
        /// The run folders.
        runs: Vec<PathBuf>,
    },
}

/// A training run to start.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainStep {
    /// Its run folder.
    pub out: PathBuf,
    /// The network variant.
    pub variant: Variant,
    /// Its seed.
    pub seed: u64,
    /// Environment steps.
    pub steps: u64,
    /// The training worlds (a `mdrlat_world::load_set` spec).
    pub world: String,
    /// The compute device's name.
    pub device: String,
    /// The task.
    pub task: Task,
    /// The settings' preset (`paper` or `fast`).
    pub preset: String,
    /// `KEY=VALUE` overrides, in order.
    pub sets: Vec<String>,
}

/// Who an evaluation measures.
#[derive(Debug, Clone, PartialEq)]
pub enum Who {
    /// A trained run's network, from its folder.
    Run(PathBuf),
    /// A baseline by name (`wander`, `avoid`, `planner`, …).
    Baseline(String),
}

/// An evaluation to run (`mdrlat eval --overwrite`).
#[derive(Debug, Clone, PartialEq)]
pub struct EvalStep {
    /// Its output folder.
    pub out: PathBuf,
    /// Who is evaluated.
    pub who: Who,
    /// Episodes drawn as figures (0: none).
    pub figures: u32,
    /// The job's share of the cores.
    pub threads: usize,
    /// Episodes per run.
    pub episodes: u32,
    /// Runs per world.
    pub runs: u32,
    /// Steps an episode must survive.
    pub max_steps: u32,
    /// Seed of the start poses.
    pub seed: u64,
    /// Metres driven for a moving success.
    pub min_path_m: f32,
    /// Metres from the start for a moving success.
    pub min_reach_m: f32,
    /// The test worlds.
    pub worlds: Vec<String>,
    /// The task.
    pub task: Task,
}

impl Step {
    /// The `mdrlat` command line (without the program name) a user would type for the step.
    pub fn argv(&self) -> Vec<String> {
        let path = |p: &Path| p.display().to_string();
        match self {
            Step::Train(t) => {
                let mut argv = vec![
                    "train".into(),
                    "--out".into(),
                    path(&t.out),
                    "--variant".into(),
                    t.variant.to_string(),
                    "--seed".into(),
                    t.seed.to_string(),
                    "--steps".into(),
                    t.steps.to_string(),
                    "--world".into(),
                    t.world.clone(),
                    "--device".into(),
                    t.device.clone(),
                ];
                if t.task != Task::Avoid {
                    argv.extend(["--task".into(), t.task.to_string()]);
                }
                if t.preset != "paper" {
                    argv.extend(["--preset".into(), t.preset.clone()]);
                }
                for set in &t.sets {
                    argv.extend(["--set".into(), set.clone()]);
                }
                argv
            }
            Step::Resume(dir) => vec!["train".into(), "--resume".into(), path(dir)],
            Step::Evaluate(e) => {
                let mut argv = vec![
                    "eval".into(),
                    "--out".into(),
                    path(&e.out),
                    "--overwrite".into(),
                    "--episodes".into(),
                    e.episodes.to_string(),
                    "--runs".into(),
                    e.runs.to_string(),
                    "--max-steps".into(),
                    e.max_steps.to_string(),
                    "--seed".into(),
                    e.seed.to_string(),
                    "--threads".into(),
                    e.threads.to_string(),
                    "--min-path".into(),
                    e.min_path_m.to_string(),
                    "--min-reach".into(),
                    e.min_reach_m.to_string(),
                ];
                for w in &e.worlds {
                    argv.extend(["--world".into(), w.clone()]);
                }
                if e.task != Task::Avoid {
                    argv.extend(["--task".into(), e.task.to_string()]);
                }
                match &e.who {
                    Who::Run(run) => argv.extend(["--checkpoint".into(), path(run)]),
                    Who::Baseline(name) => argv.extend(["--policy".into(), name.clone()]),
                }
                if e.figures > 0 || matches!(e.who, Who::Run(_)) {
                    argv.extend(["--figures".into(), e.figures.to_string()]);
                }
                argv
            }
            Step::Plot { out, runs } => {
                let mut argv =
                    vec!["plot".into(), "--by-variant".into(), "--out".into(), path(out)];
                argv.extend(runs.iter().map(|r| path(r)));
                argv
            }
        }
    }
}

/// The steps that run `job`, after clearing what an interrupted attempt left that cannot
/// be continued. `threads` is the job's share of the CPU cores (evaluations take it;
/// training follows the rayon pool, which the executor sizes through `RAYON_NUM_THREADS`).
///
/// # Errors
/// A half-made run folder that cannot be removed.
pub fn steps(plan: &Plan, job: &Job, threads: usize) -> Result<Vec<Step>, SweepError> {
    let s = &plan.sweep;
    let dir = plan.job_dir(job);
    Ok(match &job.kind {
        JobKind::Train { variant, seed } => {
            if has_checkpoint(&dir) {
                vec![Step::Resume(dir)]
            } else {
                // Killed before its first checkpoint: nothing to continue from.
                if dir.exists() {
                    std::fs::remove_dir_all(&dir).map_err(|e| io(&dir, e))?;
                }
                let mut sets = s.set.clone();
                // The learning curves count moving success as the sweep's table does.
                for (key, value) in [
                    ("curve_min_path_m", s.eval.min_path_m),
                    ("curve_min_reach_m", s.eval.min_reach_m),
                ] {
                    sets.push(format!("train.{key}={value:?}"));
                }
                vec![Step::Train(TrainStep {
                    out: dir,
                    variant: *variant,
                    seed: *seed,
                    steps: s.steps,
                    world: s.world.clone(),
                    device: s.device.clone(),
                    task: s.task,
                    preset: s.train_preset.clone(),
                    sets,
                })]
            }
        }
        JobKind::EvalModel { variant, seed, figures } => {
            let run = plan.dir.join("train").join(crate::plan::run_name(*variant, *seed));
            vec![Step::Evaluate(eval_step(plan, dir, threads, Who::Run(run), *figures))]
        }
        JobKind::EvalBaseline { policy, figures } => {
            let who = Who::Baseline(policy.clone());
            vec![Step::Evaluate(eval_step(plan, dir, threads, who, *figures))]
        }
        JobKind::Tables => {
            let runs: Vec<PathBuf> = plan
                .train_jobs()
                .filter(|j| plan.job_dir(j).join("eval.csv").exists())
                .map(|j| plan.job_dir(j))
                .collect();
            if runs.is_empty() {
                Vec::new()
            } else {
                vec![Step::Plot { out: plan.dir.join("fig4.png"), runs }]
            }
        }
    })
}

fn eval_step(plan: &Plan, out: PathBuf, threads: usize, who: Who, figures: u32) -> EvalStep {
    let e = &plan.sweep.eval;
    EvalStep {
        out,
        who,
        figures,
        threads: threads.max(1),
        episodes: e.episodes,
        runs: e.runs,
        max_steps: e.max_steps,
        seed: e.seed,
        min_path_m: e.min_path_m,
        min_reach_m: e.min_reach_m,
        worlds: e.worlds.clone(),
        task: plan.sweep.task,
    }
}

/// Holds a job's lock for as long as it lives (released when the process ends, however it
/// ends: the operating system drops the file lock).
#[derive(Debug)]
pub struct JobLock(#[allow(dead_code)] std::fs::File);

/// Takes a job's lock, waiting while another process holds it (an orphaned job of a killed
/// sweep finishes first; this one then finds it done).
pub fn lock(plan: &Plan, job: &Job) -> Result<JobLock, SweepError> {
    let path = plan.lock_path(job);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| io(parent, e))?;
    }
    let file = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .map_err(|e| io(&path, e))?;
    file.lock().map_err(|e| SweepError::Io {
        what: format!(
            "cannot lock {} (a sweep's folder needs a file system with file locks: local, NFSv4, \
             or Lustre mounted with -o flock)",
            path.display()
        ),
        source: e,
    })?;
    Ok(JobLock(file))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Sweep;

    #[test]
    fn a_training_job_starts_fresh_or_resumes() {
        let dir = std::env::temp_dir().join(format!("mdrlat-sweep-job-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let plan = Plan::new(Sweep::preset("smoke").expect("smoke"), &dir);
        let job = plan.job("train/mdrlat-s0").expect("job").clone();
        let run = plan.job_dir(&job);
        let argv: Vec<Vec<String>> =
            steps(&plan, &job, 1).expect("fresh").iter().map(Step::argv).collect();
        assert_eq!(argv[0][..3], ["train".to_string(), "--out".into(), run.display().to_string()]);
        assert!(argv[0].contains(&"train.checkpoint_interval=100".to_string()));
        assert!(!argv[0].contains(&"--preset".to_string()), "the paper's settings: no flag");
        let fast = Plan::new(Sweep::preset("fast").expect("fast"), &dir.join("fast"));
        let fast_job = fast.job("train/mdrlat-s0").expect("job").clone();
        let fast_argv = steps(&fast, &fast_job, 1).expect("fresh")[0].argv().join(" ");
        assert!(fast_argv.contains("--preset fast") && fast_argv.contains("--world train"));
        // Killed before a checkpoint: the half-made run is cleared and started again.
        std::fs::create_dir_all(run.join("checkpoint")).expect("dir");
        std::fs::write(run.join("config.toml"), "").expect("file");
        assert!(matches!(steps(&plan, &job, 1).expect("again")[0], Step::Train(_)));
        assert!(!run.exists());
        std::fs::create_dir_all(run.join("checkpoint")).expect("dir");
        std::fs::write(run.join("run.toml"), "").expect("file");
        std::fs::write(run.join("checkpoint").join("x"), "").expect("file");
        assert!(matches!(steps(&plan, &job, 1).expect("no meta.json")[0], Step::Train(_)));
        std::fs::create_dir_all(run.join("checkpoint.old")).expect("dir");
        std::fs::write(run.join("run.toml"), "").expect("file");
        // Killed while swapping in a new checkpoint: the old one is resumed, not deleted.
        std::fs::write(run.join("checkpoint.old").join("meta.json"), "{}").expect("file");
        assert_eq!(steps(&plan, &job, 1).expect("resume")[0], Step::Resume(run.clone()));
        std::fs::remove_dir_all(run.join("checkpoint.old")).expect("rm");
        std::fs::create_dir_all(run.join("checkpoint")).expect("dir");
        std::fs::write(run.join("checkpoint").join("meta.json"), "{}").expect("file");
        assert_eq!(steps(&plan, &job, 1).expect("resume")[0], Step::Resume(run.clone()));
        let eval = plan.job("eval/mdrlat-s0").expect("eval");
        let step = steps(&plan, eval, 3).expect("eval");
        let joined = step[0].argv().join(" ");
        assert!(joined.contains("--threads 3") && joined.contains("--figures 1"), "{joined}");
        assert!(joined.contains("--world office --world furnished --world crowd"), "{joined}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
