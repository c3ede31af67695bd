//! What running one job means: the `mdrlat` subcommands it is made of, chosen from where it
//! stands (a training run with a checkpoint resumes; one killed before its first checkpoint
//! starts again; an interrupted evaluation is redone whole, it holds no partial state worth
//! keeping). The CLI parses these command lines with its own parser and runs them in the job's
//! process: a job is exactly what a user would type.

use crate::SweepError;
use crate::plan::{Job, JobKind, Plan, has_checkpoint, io};
use mdrlat_sim::config::Task;
use std::path::Path;

/// The `mdrlat` command lines (without the program name) that run `job`, after clearing
/// what an interrupted attempt left that cannot be continued. `threads` is the job's share
/// of the CPU cores (evaluations take it as `--threads`; training follows the rayon pool,
/// which the executor sizes through `RAYON_NUM_THREADS`).
pub fn commands(plan: &Plan, job: &Job, threads: usize) -> Result<Vec<Vec<String>>, SweepError> {
    let s = &plan.sweep;
    let dir = plan.job_dir(job);
    let path = |p: &Path| p.display().to_string();
    Ok(match &job.kind {
        JobKind::Train { variant, seed } => {
            if has_checkpoint(&dir) {
                vec![vec!["train".into(), "--resume".into(), path(&dir)]]
            } else {
                // Killed before its first checkpoint: nothing to continue from.
                if dir.exists() {
                    std::fs::remove_dir_all(&dir).map_err(|e| io(&dir, e))?;
                }
                let mut argv = vec![
                    "train".into(),
                    "--out".into(),
                    path(&dir),
                    "--variant".into(),
                    variant.to_string(),
                    "--seed".into(),
                    seed.to_string(),
                    "--steps".into(),
                    s.steps.to_string(),
                    "--world".into(),
                    s.world.clone(),
                    "--device".into(),
                    s.device.clone(),
                ];
                if s.task != Task::Avoid {
                    argv.extend(["--task".into(), s.task.to_string()]);
                }
                if s.train_preset != "paper" {
                    argv.extend(["--preset".into(), s.train_preset.clone()]);
                }
                for set in &s.set {
                    argv.push("--set".into());
                    argv.push(set.clone());
                }
                // The learning curves count moving success as the sweep's table does.
                for (key, value) in [
                    ("curve_min_path_m", s.eval.min_path_m),
                    ("curve_min_reach_m", s.eval.min_reach_m),
                ] {
                    argv.extend(["--set".into(), format!("train.{key}={value:?}")]);
                }
                vec![argv]
            }
        }
        JobKind::EvalModel { variant, seed, figures } => {
            let run = plan.dir.join("train").join(crate::plan::run_name(*variant, *seed));
            let mut argv = eval_args(plan, &dir, threads);
            argv.extend([
                "--checkpoint".into(),
                path(&run),
                "--figures".into(),
                figures.to_string(),
            ]);
            vec![argv]
        }
        JobKind::EvalBaseline { policy, figures } => {
            let mut argv = eval_args(plan, &dir, threads);
            argv.extend(["--policy".into(), policy.clone()]);
            if *figures > 0 {
                argv.extend(["--figures".into(), figures.to_string()]);
            }
            vec![argv]
        }
        JobKind::Tables => {
            let runs: Vec<String> = plan
                .train_jobs()
                .filter(|j| plan.job_dir(j).join("eval.csv").exists())
                .map(|j| path(&plan.job_dir(j)))
                .collect();
            if runs.is_empty() {
                Vec::new()
            } else {
                let mut argv = vec![
                    "plot".into(),
                    "--by-variant".into(),
                    "--out".into(),
                    path(&plan.dir.join("fig4.png")),
                ];
                argv.extend(runs);
                vec![argv]
            }
        }
    })
}

fn eval_args(plan: &Plan, out: &Path, threads: usize) -> Vec<String> {
    let e = &plan.sweep.eval;
    let mut argv = vec![
        "eval".into(),
        "--out".into(),
        out.display().to_string(),
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
        threads.max(1).to_string(),
        "--min-path".into(),
        e.min_path_m.to_string(),
        "--min-reach".into(),
        e.min_reach_m.to_string(),
    ];
    for w in &e.worlds {
        argv.push("--world".into());
        argv.push(w.clone());
    }
    if plan.sweep.task != Task::Avoid {
        argv.extend(["--task".into(), plan.sweep.task.to_string()]);
    }
    argv
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
        let argv = commands(&plan, &job, 1).expect("fresh");
        assert_eq!(argv[0][..3], ["train".to_string(), "--out".into(), run.display().to_string()]);
        assert!(argv[0].contains(&"train.checkpoint_interval=100".to_string()));
        assert!(!argv[0].contains(&"--preset".to_string()), "the paper's settings: no flag");
        let fast = Plan::new(Sweep::preset("fast").expect("fast"), &dir.join("fast"));
        let fast_job = fast.job("train/mdrlat-s0").expect("job").clone();
        let fast_argv = commands(&fast, &fast_job, 1).expect("fresh")[0].join(" ");
        assert!(fast_argv.contains("--preset fast") && fast_argv.contains("--world gen-0..64"));
        // Killed before a checkpoint: the half-made run is cleared and started again.
        std::fs::create_dir_all(run.join("checkpoint")).expect("dir");
        std::fs::write(run.join("config.toml"), "").expect("file");
        assert_eq!(commands(&plan, &job, 1).expect("again")[0][1], "--out");
        assert!(!run.exists());
        std::fs::create_dir_all(run.join("checkpoint")).expect("dir");
        std::fs::write(run.join("run.toml"), "").expect("file");
        std::fs::write(run.join("checkpoint").join("x"), "").expect("file");
        assert_eq!(commands(&plan, &job, 1).expect("no meta.json")[0][1], "--out");
        std::fs::create_dir_all(run.join("checkpoint.old")).expect("dir");
        std::fs::write(run.join("run.toml"), "").expect("file");
        // Killed while swapping in a new checkpoint: the old one is resumed, not deleted.
        std::fs::write(run.join("checkpoint.old").join("meta.json"), "{}").expect("file");
        assert_eq!(commands(&plan, &job, 1).expect("resume")[0][1], "--resume");
        std::fs::remove_dir_all(run.join("checkpoint.old")).expect("rm");
        std::fs::create_dir_all(run.join("checkpoint")).expect("dir");
        std::fs::write(run.join("checkpoint").join("meta.json"), "{}").expect("file");
        assert_eq!(commands(&plan, &job, 1).expect("resume")[0][1], "--resume");
        let eval = plan.job("eval/mdrlat-s0").expect("eval");
        let argv = commands(&plan, eval, 3).expect("eval");
        let joined = argv[0].join(" ");
        assert!(joined.contains("--threads 3") && joined.contains("--figures 1"), "{joined}");
        assert!(joined.contains("--world office --world furnished --world crowd"), "{joined}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
