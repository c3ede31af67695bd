//! The Slurm executor: one array job for the unfinished training runs, one array job for
//! the evaluations (after the training array succeeded: `--dependency=afterok`), one job for
//! the tables (after the evaluations ended, however: `afterany`, so that a failure still
//! leaves a table saying what is missing). Every job runs `mdrlat reproduce --out DIR --job ID`
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
    /// `train`, `eval` (evaluations of the models this submission trains, task i after
    /// training task i), `eval-ready` (evaluations whose models are already trained, and
    /// the baselines) or `tables`.
    pub name: &'static str,
    /// The jobs it runs (an array's tasks in index order).
    pub jobs: Vec<String>,
    /// What it waits for: (Slurm dependency type, the earlier script's name).
    pub after: Vec<(&'static str, &'static str)>,
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
    let array = name != "tables";
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
    Script { name, jobs: jobs.iter().map(|j| j.id.clone()).collect(), after: Vec::new(), text: s }
}

/// The batch scripts for the unfinished jobs: the training array; the evaluations of the
/// models it trains as an array whose task i waits for training task i
/// (`--dependency=aftercorr`: afterok task by task, so one failed training cancels only its
/// own evaluation); the other evaluations (models already trained, baselines) at once; the
/// tables after every evaluation ended, however (`afterany`: a failure still leaves a table
/// that says what is missing).
pub fn scripts(plan: &Plan, exe: &Path, opts: &SlurmOptions) -> Vec<Script> {
    let todo = |j: &&Job| plan.state(j) != JobState::Done;
    let train: Vec<&Job> = plan.train_jobs().filter(todo).collect();
    let eval_of = |t: &Job| plan.eval_jobs().find(|e| e.needs.contains(&t.id));
    let paired: Vec<&Job> = train.iter().filter_map(|t| eval_of(t)).collect();
    let ready: Vec<&Job> =
        plan.eval_jobs().filter(todo).filter(|e| !paired.iter().any(|p| p.id == e.id)).collect();
    let mut out = Vec::new();
    if !train.is_empty() {
        out.push(script(plan, exe, "train", &train, opts));
        let mut eval = script(plan, exe, "eval", &paired, opts);
        eval.after.push(("aftercorr", "train"));
        out.push(eval);
    }
    if !ready.is_empty() {
        out.push(script(plan, exe, "eval-ready", &ready, opts));
    }
    if let Ok(t) = plan.job("tables")
        && (plan.state(t) != JobState::Done || !out.is_empty())
    {
        let mut tables = script(plan, exe, "tables", &[t], opts);
        for s in &out {
            if s.name != "train" {
                tables.after.push(("afterany", s.name));
            }
        }
        out.push(tables);
    }
    out
}

/// The Slurm job ids of a submission.
#[derive(Debug, Clone, PartialEq)]
pub struct Submitted {
    /// (script name, Slurm job id) in submission order.
    pub jobs: Vec<(&'static str, String)>,
    /// These jobs were submitted earlier and are still in Slurm (nothing new was queued).
    pub resumed: bool,
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

/// The jobs of an earlier submission that Slurm still lists as waiting or running.
fn still_queued(plan: &Plan) -> Result<Option<Submitted>, SweepError> {
    let Ok(text) = std::fs::read_to_string(plan.dir.join("slurm").join("submitted.toml")) else {
        return Ok(None);
    };
    let names = ["train", "eval", "eval-ready", "tables"];
    let jobs: Vec<(&'static str, String)> = text
        .lines()
        .filter_map(|l| {
            let (k, v) = l.split_once(" = ")?;
            let name = names.iter().find(|n| **n == k.trim())?;
            Some((*name, v.trim().trim_matches('"').to_string()))
        })
        .collect();
    let ids: Vec<String> = jobs.iter().map(|j| j.1.clone()).collect();
    if ids.is_empty() || active(&ids)? == 0 {
        return Ok(None);
    }
    Ok(Some(Submitted { jobs, resumed: true }))
}

/// Writes the scripts to `DIR/slurm/` and submits them, each after what it waits for. If
/// an earlier submission of this sweep is still in Slurm, submits nothing and returns that
/// one (`resumed`): the same jobs are never queued twice.
pub fn submit(plan: &Plan, exe: &Path, opts: &SlurmOptions) -> Result<Submitted, SweepError> {
    plan.open()?;
    if let Some(earlier) = still_queued(plan)? {
        return Ok(earlier);
    }
    let dir = plan.dir.join("slurm");
    std::fs::create_dir_all(&dir).map_err(|e| io(&dir, e))?;
    let mut jobs: Vec<(&'static str, String)> = Vec::new();
    for s in scripts(plan, exe, opts) {
        let path = dir.join(format!("{}.sbatch", s.name));
        write_atomic(&path, s.text.as_bytes())?;
        let mut args = vec!["--parsable".to_string()];
        let after: Vec<String> = s
            .after
            .iter()
            .filter_map(|(kind, name)| {
                jobs.iter().find(|j| j.0 == *name).map(|j| format!("{kind}:{}", j.1))
            })
            .collect();
        if !after.is_empty() {
            args.push(format!("--dependency={}", after.join(",")));
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
    Ok(Submitted { jobs, resumed: false })
}

/// Jobs of `ids` that Slurm still lists in a state that is not final. A failing `squeue`
/// (a busy controller) is asked again a few times before it is an error.
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
    let mut tries = 0;
    let out = loop {
        match run_tool("squeue", &args) {
            Ok(o) => break o,
            // Jobs Slurm has forgotten are finished.
            Err(SweepError::Slurm(e)) if e.contains("Invalid job id") => return Ok(0),
            Err(SweepError::Slurm(e)) if tries < 5 && !e.contains("not found on PATH") => {
                tries += 1;
                std::thread::sleep(Duration::from_secs(2 * tries));
                let _ = e;
            }
            Err(e) => return Err(e),
        }
    };
    let terminal = [
        "COMPLETED",
        "CANCELLED",
        "FAILED",
        "TIMEOUT",
        "NODE_FAIL",
        "PREEMPTED",
        "BOOT_FAIL",
        "DEADLINE",
        "OUT_OF_MEMORY",
        "REVOKED",
        "SPECIAL_EXIT",
    ];
    Ok(out.lines().map(str::trim).filter(|l| !l.is_empty() && !terminal.contains(l)).count())
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
        let names: Vec<&str> = s.iter().map(|s| s.name).collect();
        assert_eq!(names, ["train", "eval", "eval-ready", "tables"]);
        assert_eq!(s[1].after, [("aftercorr", "train")]);
        assert_eq!(s[3].after, [("afterany", "eval"), ("afterany", "eval-ready")]);
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
        let eval = &s[1].text;
        assert!(
            eval.contains("--array=0-5") && eval.contains("JOBS=(eval/laser-only-s0 "),
            "{eval}"
        );
        let ready = &s[2].text;
        assert!(ready.contains("--array=0-0") && ready.contains("JOBS=(eval/wander)"), "{ready}");
        let tables = &s[3].text;
        assert!(!tables.contains("--array") && tables.contains("JOBS=(tables)"), "{tables}");
        assert_eq!(quote("it's"), "'it'\\''s'");
    }
}
