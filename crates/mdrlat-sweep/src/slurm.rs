//! The Slurm executor: one array job for the unfinished training runs, one array job for
//! the evaluations (after the training array succeeded: `--dependency=afterok`), one job for
//! the tables (after the evaluations). Every job runs `mdrlat reproduce --out DIR --job ID`
//! with the same binary, by absolute path: the nodes must share the file system that holds
//! the binary and the sweep's folder.

use crate::SweepError;
use crate::plan::{Job, JobState, Plan, io, write_atomic};
use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

/// How jobs are submitted.
#[derive(Debug, Clone, Default)]
pub struct SlurmOptions {
    /// `--partition`.
    pub partition: Option<String>,
    /// `--time` of every job (Slurm's format, e.g. `2-00:00:00`).
    pub time: Option<String>,
    /// `--gres` of the training jobs (e.g. `gpu:1`).
    pub gres: Option<String>,
    /// `--cpus-per-task` of every job.
    pub cpus_per_task: usize,
    /// Further `sbatch` arguments, verbatim, for every job.
    pub extra: Vec<String>,
}

/// One batch script.
#[derive(Debug, Clone, PartialEq)]
pub struct Script {
    /// `train`, `eval` or `tables`.
    pub name: &'static str,
    /// The jobs it runs (an array's tasks in index order).
    pub jobs: Vec<String>,
    /// The script's text.
    pub text: String,
}

fn quote(s: &str) -> String {
    if !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || "/._-+=:,@%".contains(c)) {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

fn script(
    plan: &Plan,
    exe: &Path,
    name: &'static str,
    jobs: &[&Job],
    opts: &SlurmOptions,
) -> Script {
    let dir = plan.dir.display().to_string();
    let mut s = String::from("#!/bin/bash\n");
    let _ = writeln!(s, "# mdrlat reproduce: {name} jobs of sweep '{}' in {dir}", plan.sweep.name);
    let _ =
        writeln!(s, "#SBATCH --job-name={}", quote(&format!("mdrlat-{}-{name}", plan.sweep.name)));
    let array = jobs.len() > 1 || name != "tables";
    if array {
        let _ = writeln!(s, "#SBATCH --array=0-{}", jobs.len() - 1);
        let _ = writeln!(
            s,
            "#SBATCH --output={}",
            quote(&format!("{dir}/logs/slurm-{name}-%A_%a.out"))
        );
    } else {
        let _ =
            writeln!(s, "#SBATCH --output={}", quote(&format!("{dir}/logs/slurm-{name}-%j.out")));
    }
    let _ = writeln!(s, "#SBATCH --cpus-per-task={}", opts.cpus_per_task.max(1));
    if let Some(p) = &opts.partition {
        let _ = writeln!(s, "#SBATCH --partition={}", quote(p));
    }
    if let Some(t) = &opts.time {
        let _ = writeln!(s, "#SBATCH --time={}", quote(t));
    }
    if let (Some(g), "train") = (&opts.gres, name) {
        let _ = writeln!(s, "#SBATCH --gres={}", quote(g));
    }
    for a in &opts.extra {
        let _ = writeln!(s, "#SBATCH {}", quote(a));
    }
    s.push_str("set -euo pipefail\n");
    let ids: Vec<String> = jobs.iter().map(|j| quote(&j.id)).collect();
    let _ = writeln!(s, "JOBS=({})", ids.join(" "));
    if array {
        s.push_str("ID=\"${JOBS[$SLURM_ARRAY_TASK_ID]}\"\n");
    } else {
        s.push_str("ID=\"${JOBS[0]}\"\n");
    }
    s.push_str("THREADS=\"${SLURM_CPUS_PER_TASK:-1}\"\n");
    let _ = writeln!(
        s,
        "RAYON_NUM_THREADS=\"$THREADS\" exec {} reproduce --out {} --job \"$ID\" --threads \"$THREADS\" \\\n  >> {}/logs/\"${{ID//\\//-}}\".log 2>&1",
        quote(&exe.display().to_string()),
        quote(&dir),
        quote(&dir)
    );
    Script { name, jobs: jobs.iter().map(|j| j.id.clone()).collect(), text: s }
}

/// The batch scripts for the unfinished jobs (training array, evaluation array, tables).
pub fn scripts(plan: &Plan, exe: &Path, opts: &SlurmOptions) -> Vec<Script> {
    let todo = |j: &&Job| plan.state(j) != JobState::Done;
    let train: Vec<&Job> = plan.train_jobs().filter(todo).collect();
    let eval: Vec<&Job> = plan.eval_jobs().filter(todo).collect();
    let mut out = Vec::new();
    if !train.is_empty() {
        out.push(script(plan, exe, "train", &train, opts));
    }
    if !eval.is_empty() {
        out.push(script(plan, exe, "eval", &eval, opts));
    }
    if let Ok(t) = plan.job("tables")
        && (plan.state(t) != JobState::Done || !out.is_empty())
    {
        out.push(script(plan, exe, "tables", &[t], opts));
    }
    out
}

/// The Slurm job ids of a submission.
#[derive(Debug, Clone, PartialEq)]
pub struct Submitted {
    /// (script name, Slurm job id) in submission order.
    pub jobs: Vec<(&'static str, String)>,
}

fn run_tool(program: &str, args: &[String]) -> Result<String, SweepError> {
    let out = Command::new(program).args(args).output().map_err(|e| {
        SweepError::Slurm(if e.kind() == std::io::ErrorKind::NotFound {
            format!("'{program}' not found on PATH: install Slurm's client tools (Debian: slurm-client) or use --executor local")
        } else {
            format!("cannot run '{program}': {e}")
        })
    })?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(SweepError::Slurm(format!(
            "'{program} {}' failed ({}): {}",
            args.join(" "),
            out.status,
            err.trim()
        )));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Writes the scripts to `DIR/slurm/` and submits them, each after the one before it.
pub fn submit(plan: &Plan, exe: &Path, opts: &SlurmOptions) -> Result<Submitted, SweepError> {
    plan.open()?;
    let dir = plan.dir.join("slurm");
    std::fs::create_dir_all(&dir).map_err(|e| io(&dir, e))?;
    let mut jobs: Vec<(&'static str, String)> = Vec::new();
    for s in scripts(plan, exe, opts) {
        let path = dir.join(format!("{}.sbatch", s.name));
        write_atomic(&path, s.text.as_bytes())?;
        let mut args = vec!["--parsable".to_string()];
        if let Some((_, after)) = jobs.last() {
            args.push(format!("--dependency=afterok:{after}"));
            args.push("--kill-on-invalid-dep=yes".into());
        }
        args.push(path.display().to_string());
        let out = run_tool("sbatch", &args)?;
        let id = out.trim().split(';').next().unwrap_or("").to_string();
        if id.is_empty() || !id.chars().all(|c| c.is_ascii_digit()) {
            return Err(SweepError::Slurm(format!(
                "sbatch {}: expected a job id, got '{}'",
                path.display(),
                out.trim()
            )));
        }
        jobs.push((s.name, id));
    }
    let record: String = jobs.iter().map(|(n, id)| format!("{n} = \"{id}\"\n")).collect();
    write_atomic(&dir.join("submitted.toml"), record.as_bytes())?;
    Ok(Submitted { jobs })
}

/// Jobs of `ids` that Slurm still lists as waiting or running.
fn active(ids: &[String]) -> Result<usize, SweepError> {
    let args = vec![
        "-h".to_string(),
        "-t".into(),
        "all".into(),
        "-j".into(),
        ids.join(","),
        "-o".into(),
        "%T".into(),
    ];
    let out = match run_tool("squeue", &args) {
        Ok(o) => o,
        // Jobs Slurm has forgotten are finished.
        Err(SweepError::Slurm(e)) if e.contains("Invalid job id") => return Ok(0),
        Err(e) => return Err(e),
    };
    let live =
        ["PENDING", "RUNNING", "CONFIGURING", "COMPLETING", "SUSPENDED", "REQUEUED", "RESIZING"];
    Ok(out.lines().filter(|l| live.contains(&l.trim())).count())
}

/// Waits until Slurm lists none of the submitted jobs as waiting or running, then reads
/// the outcome from the jobs' markers (shared file system): every unfinished job is named
/// with its log.
pub fn wait(
    plan: &Plan,
    submitted: &Submitted,
    poll: Duration,
    mut tick: impl FnMut(usize),
) -> Result<(), SweepError> {
    let ids: Vec<String> = submitted.jobs.iter().map(|j| j.1.clone()).collect();
    if !ids.is_empty() {
        loop {
            let n = active(&ids)?;
            tick(n);
            if n == 0 {
                break;
            }
            std::thread::sleep(poll);
        }
    }
    crate::local::outcome(plan)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Sweep;

    #[test]
    fn scripts_map_array_tasks_to_jobs() {
        let plan = Plan::new(Sweep::preset("smoke").expect("smoke"), Path::new("/shared/sweep"));
        let opts = SlurmOptions {
            partition: Some("debug".into()),
            time: Some("1:00:00".into()),
            gres: Some("gpu:1".into()),
            cpus_per_task: 2,
            extra: vec!["--qos=low".into()],
        };
        let s = scripts(&plan, Path::new("/opt/mdrlat/bin/mdrlat"), &opts);
        assert_eq!(s.iter().map(|s| s.name).collect::<Vec<_>>(), ["train", "eval", "tables"]);
        let train = &s[0].text;
        assert!(train.contains("#SBATCH --array=0-5\n"), "{train}");
        assert!(
            train.contains("#SBATCH --gres=gpu:1\n")
                && train.contains("#SBATCH --partition=debug\n"),
            "{train}"
        );
        assert!(
            train.contains("#SBATCH --qos=low\n") && train.contains("#SBATCH --cpus-per-task=2\n"),
            "{train}"
        );
        assert!(train.contains("JOBS=(train/laser-only-s0 train/depth-only-s0"), "{train}");
        assert!(
            train.contains(
                "exec /opt/mdrlat/bin/mdrlat reproduce --out /shared/sweep --job \"$ID\""
            ),
            "{train}"
        );
        assert!(!s[1].text.contains("--gres"), "evaluations need no GPU: {}", s[1].text);
        assert!(s[1].text.contains("--array=0-6"), "{}", s[1].text);
        assert!(
            !s[2].text.contains("--array") && s[2].text.contains("JOBS=(tables)"),
            "{}",
            s[2].text
        );
        assert_eq!(quote("it's"), "'it'\\''s'");
    }
}
