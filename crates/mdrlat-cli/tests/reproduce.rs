//! `mdrlat reproduce` end to end with the local executor: a sweep killed with SIGKILL (the
//! whole process group, then the parent alone, orphaning its job) and started again ends
//! with the same table2.csv bytes and model bytes as an uninterrupted one; a failing job
//! gives a table that says what is missing; bad input gives one clear line.

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::{EXE, assert_clean_failure, mdrlat, stderr};

fn tmp(name: &str) -> PathBuf {
    common::tmp("repro", name)
}

/// Two variants, 240 steps with a checkpoint every 80: small enough for a test, long
/// enough to be killed between checkpoints.
const SWEEP: &str = r#"
name = "kill-test"
variants = ["laser-only", "multi-at"]
seeds = [3]
steps = 240
set = ["train.learning_starts=60", "train.replay_capacity=500", "train.epsilon_decay_steps=100",
       "train.target_update_interval=50", "train.eval_interval=80", "train.eval_episodes=2",
       "train.checkpoint_interval=80"]

[eval]
worlds = ["office", "crowd"]
episodes = 3
runs = 2
max_steps = 120
baselines = ["wander"]
figure_variant = "multi-at"
figures = 1
"#;

fn sweep_file(dir: &Path) -> PathBuf {
    let f = dir.join("sweep.toml");
    std::fs::write(&f, SWEEP).expect("sweep file");
    f
}

fn reproduce(sweep: &Path, out: &Path) -> Command {
    let mut c = Command::new(EXE);
    c.args(["reproduce", "--sweep"]).arg(sweep).arg("--out").arg(out);
    c.stdout(Stdio::null()).stderr(Stdio::null()).process_group(0);
    c
}

fn kill9(target: &str) {
    let s = Command::new("kill").args(["-s", "KILL", "--", target]).status().expect("kill");
    assert!(s.success(), "kill -9 {target}");
}

fn wait_for(what: &str, limit: Duration, mut cond: impl FnMut() -> bool) {
    let t = Instant::now();
    while !cond() {
        assert!(t.elapsed() < limit, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_sweep_killed_and_restarted_writes_the_same_bytes() {
    let dir = tmp("kill");
    let sweep = sweep_file(&dir);
    let whole = dir.join("whole");
    let o = Command::new(EXE)
        .args(["reproduce", "--sweep"])
        .arg(&sweep)
        .arg("--out")
        .arg(&whole)
        .output()
        .expect("run");
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("| office |") && stdout.contains("wander"), "{stdout}");
    for f in ["table2.csv", "table2.md", "report.md", "fig4.png"] {
        assert!(whole.join(f).is_file(), "{f} missing");
    }
    let figures = std::fs::read_dir(whole.join("eval/multi-at-s3/figures")).expect("figs 6/7");
    assert!(figures.count() >= 2, "a Fig. 6/7 strip and its trajectory");

    // Killed mid-training (between checkpoints), the whole process group at once.
    let cut = dir.join("cut");
    let mut child = reproduce(&sweep, &cut).spawn().expect("start");
    let run = cut.join("train/multi-at-s3");
    wait_for("the first checkpoint", Duration::from_secs(120), || {
        std::fs::read_dir(run.join("checkpoint")).is_ok_and(|mut d| d.next().is_some())
    });
    kill9(&format!("-{}", child.id()));
    let _ = child.wait();
    assert!(!cut.join("state/train-multi-at-s3.done").exists(), "killed before the end");
    // Killed again while an evaluation runs, the parent alone: its orphaned job finishes
    // and the next sweep waits for it instead of running it twice.
    let mut child = reproduce(&sweep, &cut).spawn().expect("restart");
    wait_for("an evaluation", Duration::from_secs(120), || cut.join("eval").exists());
    kill9(&child.id().to_string());
    let _ = child.wait();
    let o = Command::new(EXE)
        .args(["reproduce", "--out"])
        .arg(&cut)
        .output()
        .expect("continue without naming the sweep");
    assert!(o.status.success(), "{}", stderr(&o));
    let log = std::fs::read_to_string(cut.join("logs/train-multi-at-s3.log")).expect("log");
    assert!(log.contains("--resume"), "the second attempt resumed: {log}");

    let bytes = |d: &Path, f: &str| std::fs::read(d.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
    for f in [
        "table2.csv",
        "train/multi-at-s3/model.safetensors",
        "train/laser-only-s3/model.safetensors",
        "train/multi-at-s3/metrics.csv",
        "train/multi-at-s3/eval.csv",
        "eval/multi-at-s3/episodes.csv",
        "eval/wander/summary.csv",
    ] {
        assert!(bytes(&whole, f) == bytes(&cut, f), "{f} differs after the interruptions");
    }

    // Finished: a rerun does nothing and says so.
    let o = Command::new(EXE).args(["reproduce", "--out"]).arg(&cut).output().expect("rerun");
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!String::from_utf8_lossy(&o.stdout).contains("started"), "nothing runs twice");

    // The same folder with other settings is refused, naming what changed.
    let changed = dir.join("changed.toml");
    std::fs::write(&changed, SWEEP.replace("steps = 240", "steps = 250")).expect("file");
    let o = mdrlat(&[
        "reproduce",
        "--sweep",
        changed.to_str().unwrap_or_default(),
        "--out",
        cut.to_str().unwrap_or_default(),
    ]);
    assert_clean_failure(&o, &["different sweep", "steps: 240 -> 250"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_failed_job_leaves_a_table_that_says_what_is_missing() {
    let dir = tmp("fail");
    let sweep = dir.join("one.toml");
    std::fs::write(
        &sweep,
        SWEEP
            .replace(r#"variants = ["laser-only", "multi-at"]"#, r#"variants = ["laser-only"]"#)
            .replace(r#"figure_variant = "multi-at""#, ""),
    )
    .expect("file");
    let out = dir.join("out");
    // A training job recorded as finished whose run is gone: its evaluation must fail.
    let o = mdrlat(&[
        "reproduce",
        "--sweep",
        sweep.to_str().unwrap_or_default(),
        "--out",
        out.to_str().unwrap_or_default(),
        "--executor",
        "slurm",
        "--dry-run",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::write(out.join("state/train-laser-only-s3.done"), "train/laser-only-s3\n")
        .expect("marker");
    let o = mdrlat(&["reproduce", "--out", out.to_str().unwrap_or_default()]);
    assert_clean_failure(&o, &["eval/laser-only-s3 failed", "logs/eval-laser-only-s3.log"]);
    let md = std::fs::read_to_string(out.join("table2.md")).expect("table2.md");
    assert!(md.contains("**Incomplete: 2 of 4 cells have no result**"), "{md}");
    assert!(md.contains("eval/laser-only-s3 failed"), "{md}");
    let csv = std::fs::read_to_string(out.join("table2.csv")).expect("table2.csv");
    assert!(
        csv.lines().any(|l| l.starts_with("office,wander,1,2,")),
        "the baseline is there: {csv}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The navigation preset's shape in miniature: a goal-conditioned network trained in
/// nav-train, evaluated in nav-test against the classical planner, with the navigation
/// table, the paper's navigation claims and one Fig. 9 per method.
#[test]
fn a_navigation_sweep_writes_its_table_and_a_fig9_per_method() {
    let dir = tmp("nav");
    let sweep = dir.join("nav.toml");
    std::fs::write(
        &sweep,
        r#"
name = "nav-test"
task = "nav"
variants = ["laser-only"]
seeds = [0]
steps = 150
world = "nav-train"
set = ["train.learning_starts=50", "train.eval_interval=100", "train.eval_episodes=2",
       "train.checkpoint_interval=100"]

[eval]
worlds = ["nav-test"]
episodes = 3
runs = 1
max_steps = 150
baselines = ["planner-body"]
figures = 2
"#,
    )
    .expect("sweep");
    let out = dir.join("out");
    let o = Command::new(EXE)
        .args(["reproduce", "--sweep"])
        .arg(&sweep)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("run");
    assert!(o.status.success(), "{}", stderr(&o));
    let nav = std::fs::read_to_string(out.join("navigation.md")).expect("navigation.md");
    assert!(nav.contains("| laser-only | nav-test |"), "{nav}");
    assert!(nav.contains("| planner-body | nav-test |"), "{nav}");
    let table = std::fs::read_to_string(out.join("table2.md")).expect("table2.md");
    assert!(table.contains("# Navigation: success rate") && !table.contains("paper 6"), "{table}");
    let report = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    assert!(report.contains("MDRLAT reaches every goal") && report.contains("cannot be checked"));
    for job in ["eval/laser-only-s0", "eval/planner-body"] {
        let png = format!("{job}/figures/nav-test-fig9.png");
        assert!(out.join(&png).is_file(), "{png}");
        assert!(report.contains(&format!("({png})")), "{report}");
    }
    let log = std::fs::read_to_string(out.join("logs/train-laser-only-s0.log")).expect("log");
    assert!(log.contains("--task nav"), "{log}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn presets_print_and_bad_input_is_one_clear_line() {
    let o = mdrlat(&["reproduce", "--print", "paper"]);
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("steps = 400000") && text.contains("seeds = [0, 1, 2, 3, 4]"), "{text}");
    let dir = tmp("bad");
    let d = dir.to_str().unwrap_or_default().to_string();
    assert_clean_failure(
        &mdrlat(&["reproduce", "--print", "papr"]),
        &["unknown preset 'papr'", "cpu-small"],
    );
    assert_clean_failure(
        &mdrlat(&["reproduce", "--preset", "tiny", "--out", &d]),
        &["unknown preset 'tiny'"],
    );
    let bad = |name: &str, from: &str, to: &str, needles: &[&str]| {
        let f = dir.join(name);
        let text = SWEEP.replacen(from, to, 1);
        assert_ne!(text, SWEEP, "{from}");
        std::fs::write(&f, text).expect("file");
        let out = dir.join(format!("{name}.out"));
        let o = mdrlat(&[
            "reproduce",
            "--sweep",
            f.to_str().unwrap_or_default(),
            "--out",
            out.to_str().unwrap_or_default(),
        ]);
        assert_clean_failure(&o, needles);
        assert!(!out.exists(), "nothing written for a bad sweep");
    };
    bad("key.toml", "steps = 240", "step = 240", &["key.toml", "step"]);
    bad("zero.toml", "steps = 240", "steps = 0", &["zero.toml", "steps = 0"]);
    bad("set.toml", "train.eval_episodes=2", "train.eval_episode=2", &["set.toml", "eval_episode"]);
    bad("world.toml", "\"crowd\"]", "\"mall\"]", &["world.toml", "eval.worlds", "mall"]);
    bad("device.toml", "steps = 240", "steps = 240\ndevice = \"tpu\"", &["device.toml", "tpu"]);
    bad("planner.toml", "[\"wander\"]", "[\"planner\"]", &["planner.toml", "task = \"nav\""]);
    bad(
        "goals.toml",
        "steps = 240",
        "steps = 240\ntask = \"nav\"",
        &["goals.toml", "world 'train' has no goal region"],
    );
    assert_clean_failure(
        &mdrlat(&["reproduce", "--out", dir.join("nothing").to_str().unwrap_or_default()]),
        &["--preset or --sweep"],
    );
    assert_clean_failure(
        &mdrlat(&["reproduce", "--preset", "smoke", "--out", &d, "--wait"]),
        &["--wait is for --executor slurm"],
    );
    // Exporting what is not a run.
    let o = mdrlat(&[
        "export",
        "--checkpoint",
        "/nonexistent/run",
        "--out",
        dir.join("m").to_str().unwrap_or_default(),
    ]);
    assert_clean_failure(&o, &["/nonexistent/run"]);
    // Slurm's tools missing: one line naming the tool, not a panic.
    let f = sweep_file(&dir);
    let o = Command::new(EXE)
        .args([
            "reproduce",
            "--executor",
            "slurm",
            "--sweep",
            f.to_str().unwrap_or_default(),
            "--out",
        ])
        .arg(dir.join("slurm"))
        .env("PATH", "/nonexistent")
        .output()
        .expect("run");
    assert_clean_failure(&o, &["'sbatch' not found"]);
    let _ = std::fs::remove_dir_all(&dir);
}
