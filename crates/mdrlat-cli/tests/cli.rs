//! The `mdrlat` binary end to end: outputs people and scripts rely on, and bad input giving
//! one clear line and a non-zero exit (never a panic).

use std::path::{Path, PathBuf};

mod common;
use common::{assert_clean_failure, mdrlat, stderr};

fn tmp(name: &str) -> PathBuf {
    common::tmp("cli", name)
}

fn npy_f32(path: &Path) -> (String, Vec<f32>) {
    let b = std::fs::read(path).expect("npy");
    assert_eq!(&b[..6], b"\x93NUMPY");
    let hlen = u16::from_le_bytes([b[8], b[9]]) as usize;
    let header = String::from_utf8(b[10..10 + hlen].to_vec()).expect("header");
    let data = b[10 + hlen..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    (header, data)
}

const GOOD: &str = r#"version = 1
name = "cli"
bounds = { min = [0.0, 0.0], max = [4.0, 4.0] }
obstacle = [ { shape = "box", center = [2.0, 3.95], size = [4.0, 0.1], z = [0.0, 2.0] } ]
spawn = [ { min = [0.5, 0.5], max = [3.5, 3.0] } ]
"#;

#[test]
fn world_check_accepts_good_files_and_names_the_problem_in_bad_ones() {
    let d = tmp("check");
    let good = d.join("good.toml");
    std::fs::write(&good, GOOD).expect("write");
    let o = mdrlat(&["world", "check", good.to_str().expect("utf8")]);
    assert!(o.status.success(), "{}", stderr(&o));

    // A generated world: written, checked, the same bytes again, and usable as gen-N.
    let generated = d.join("gen.toml");
    let g = generated.to_str().expect("utf8");
    let o = mdrlat(&["world", "generate", "--seed", "11", "--out", g]);
    assert!(o.status.success(), "{}", stderr(&o));
    let first = std::fs::read(&generated).expect("written");
    assert!(mdrlat(&["world", "check", g]).status.success());
    let o = mdrlat(&["world", "generate", "--seed", "11"]);
    assert_eq!(
        String::from_utf8_lossy(&o.stdout).trim_end(),
        String::from_utf8_lossy(&first).trim_end()
    );
    let o = mdrlat(&[
        "render",
        "--world",
        "gen-11",
        "--world-only",
        "--out",
        d.join("g.png").to_str().expect("utf8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_clean_failure(&mdrlat(&["world", "generate", "--seed", "-3"]), &["--seed", "-3"]);
    assert_clean_failure(&mdrlat(&["render", "--world", "gen-x"]), &["gen-x", "gen-N"]);

    let cases: [(&str, String, &[&str]); 5] = [
        (
            "negative.toml",
            GOOD.replace("[4.0, 0.1]", "[4.0, -0.1]"),
            &["negative.toml", "obstacle[0].size", "-0.1"],
        ),
        ("shape.toml", GOOD.replace("\"box\"", "\"sphere\""), &["shape.toml", "sphere"]),
        (
            "nan.toml",
            GOOD.replace("z = [0.0, 2.0]", "z = [0.0, nan]"),
            &["nan.toml", "obstacle[0].z"],
        ),
        ("missing.toml", GOOD.replace("name = \"cli\"\n", ""), &["missing.toml", "name"]),
        (
            "key.toml",
            GOOD.replace("version = 1", "version = 1\ncolour = 3"),
            &["key.toml", "colour"],
        ),
    ];
    for (name, text, needles) in cases {
        let p = d.join(name);
        std::fs::write(&p, text).expect("write");
        assert_clean_failure(&mdrlat(&["world", "check", p.to_str().expect("utf8")]), needles);
    }
    assert_clean_failure(
        &mdrlat(&["world", "check", "/no/such/world.toml"]),
        &["/no/such/world.toml"],
    );
    // A map YAML whose image is not an image.
    std::fs::write(d.join("notmap.pgm"), b"hello, I am text").expect("write");
    std::fs::write(
        d.join("notmap.yaml"),
        "image: notmap.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n",
    )
    .expect("write");
    let yaml = d.join("notmap.yaml");
    assert_clean_failure(
        &mdrlat(&["world", "check", yaml.to_str().expect("utf8")]),
        &["notmap.pgm"],
    );
    assert_clean_failure(&mdrlat(&["render", "--world", "atlantis"]), &["atlantis", "train"]);
}

#[test]
fn observe_writes_numpy_frames_in_metres() {
    let d = tmp("observe");
    let o = mdrlat(&[
        "observe",
        "--world",
        "train",
        "--pose",
        "3,2,90",
        "--out",
        d.to_str().expect("utf8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (h, laser) = npy_f32(&d.join("laser.npy"));
    assert!(h.contains("'shape': (512,)") && h.contains("<f4"), "{h}");
    assert_eq!(laser.len(), 512);
    assert!(laser.iter().all(|r| (0.0..=5.6).contains(r)));
    let (h, depth) = npy_f32(&d.join("depth.npy"));
    assert!(h.contains("'shape': (128, 160)"), "{h}");
    assert!(depth.iter().all(|&z| z == 0.0 || (0.4..=10.0).contains(&z)));
    // The bottom row sees the floor at 0.30 m / y.
    let y = 63.5 / (64.0 / 22.5f32.to_radians().tan());
    assert!((depth[127 * 160 + 80] - 0.30 / y).abs() < 1e-3, "{}", depth[127 * 160 + 80]);
    assert!(std::fs::metadata(d.join("view.png")).expect("png").len() > 1000);
    assert_clean_failure(&mdrlat(&["observe", "--pose", "1,2"]), &["--pose", "X,Y,YAW_DEG"]);
}

#[test]
fn rollouts_are_byte_identical_for_a_seed() {
    let d = tmp("rollout");
    let run = |seed: &str, name: &str| {
        let out = d.join(name);
        let o = mdrlat(&[
            "rollout",
            "--world",
            "crowd",
            "--seed",
            seed,
            "--steps",
            "80",
            "--policy",
            "random",
            "--out",
            out.to_str().expect("utf8"),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        std::fs::read(out).expect("csv")
    };
    let a = run("5", "a.csv");
    assert_eq!(a, run("5", "b.csv"));
    assert_ne!(a, run("6", "c.csv"));
    let text = String::from_utf8(a).expect("utf8");
    assert!(text.starts_with("step,x,y,yaw,v,w,action,reward,terminated,truncated,d_min\n"));
    assert!(text.lines().count() >= 2);
}

#[test]
fn bench_prints_json_lines() {
    let o = mdrlat(&[
        "bench",
        "sim",
        "--json",
        "--seconds",
        "0.05",
        "--worlds",
        "example",
        "--envs",
        "2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8(o.stdout).expect("utf8");
    let lines: Vec<serde_json::Value> =
        out.lines().map(|l| serde_json::from_str(l).expect("json line")).collect();
    assert_eq!(lines.len(), 2);
    for l in &lines {
        assert_eq!(l["bench"], "sim");
        assert_eq!(l["world"], "example");
        assert!(l["steps_per_s"].as_f64().expect("number") > 0.0);
        assert!(l["envs"].as_u64().is_some() && l["threads"].as_u64().is_some());
    }
}

/// `bench train --json`: the reference first, then per variant the step's rate divided by
/// the reference it was measured against — never below the first one (the reference is
/// the highest of its measurements in the run); bad arguments are clear errors.
#[test]
fn bench_train_relates_each_step_to_the_same_run_reference() {
    let args = ["bench", "train", "--json", "--seconds", "0.05", "--variants"];
    let o = mdrlat(&[&args[..], &["laser-only,multi"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8(o.stdout).expect("utf8");
    let lines: Vec<serde_json::Value> =
        out.lines().map(|l| serde_json::from_str(l).expect("json line")).collect();
    assert_eq!(lines[0]["bench"], "gemm_reference");
    let first = lines[0]["gflops"].as_f64().expect("reference rate");
    assert!(first > 0.0);
    let steps: Vec<&serde_json::Value> = lines.iter().filter(|l| l["bench"] == "train").collect();
    let names: Vec<&str> = steps.iter().filter_map(|l| l["variant"].as_str()).collect();
    assert_eq!(names, ["laser-only", "multi"]);
    let mut last = first;
    for l in steps {
        let (gflops, reference, efficiency) = (
            l["gflops"].as_f64().expect("rate"),
            l["reference_gflops"].as_f64().expect("reference"),
            l["efficiency"].as_f64().expect("efficiency"),
        );
        assert!(reference >= last - 0.05, "the reference only rises: {reference} after {last}");
        assert!((efficiency - gflops / reference).abs() < 2e-3, "{l}");
        let ms = l["ms_per_step"].as_f64().expect("ms");
        let gflop = l["gflop_per_step"].as_f64().expect("gflop");
        assert!((gflop / (ms * 1e-3) / gflops - 1.0).abs() < 0.05, "{l}");
        last = reference;
    }
    let bad = mdrlat(&["bench", "train", "--seconds=-1"]);
    assert_clean_failure(&bad, &["--seconds -1", "between 0 and 3600"]);
}
#[test]
fn config_default_round_trips_and_bad_configs_are_rejected() {
    let d = tmp("config");
    let o = mdrlat(&["config", "default"]);
    assert!(o.status.success());
    let p = d.join("default.toml");
    std::fs::write(&p, &o.stdout).expect("write");
    assert!(mdrlat(&["config", "check", p.to_str().expect("utf8")]).status.success());
    let bad = d.join("bad.toml");
    std::fs::write(&bad, "[sim.laser]\nmax_range_m = -2.0\n").expect("write");
    assert_clean_failure(
        &mdrlat(&["config", "check", bad.to_str().expect("utf8")]),
        &["bad.toml", "laser.max_range_m"],
    );
    std::fs::write(&bad, "[sim]\nspeed = 3\n").expect("write");
    assert_clean_failure(
        &mdrlat(&["config", "check", bad.to_str().expect("utf8")]),
        &["bad.toml", "speed"],
    );
}

/// `mdrlat train` of a seed-3 laser-only run in `example` for `steps` steps into `out`;
/// callers add their `--set`s.
fn laser_only_train<'a>(steps: &'a str, out: &'a str) -> Vec<&'a str> {
    vec![
        "train",
        "--variant",
        "laser-only",
        "--world",
        "example",
        "--steps",
        steps,
        "--seed",
        "3",
        "--out",
        out,
    ]
}

#[test]
fn train_writes_a_run_directory_and_never_overwrites_one() {
    let d = tmp("train");
    let run = d.join("run");
    let r = run.to_str().expect("utf8");
    let mut args = laser_only_train("120", r);
    args.extend([
        "--set",
        "train.learning_starts=40",
        "--set",
        "train.eval_interval=100",
        "--set",
        "train.eval_episodes=1",
        "--set",
        "sim.max_episode_steps=30",
        "--set",
        "train.checkpoint_interval=100",
    ]);
    let o = mdrlat(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in ["config.toml", "run.toml", "metrics.csv", "eval.csv", "model.safetensors"] {
        assert!(run.join(f).is_file(), "missing {f}");
    }
    let cfg = std::fs::read_to_string(run.join("config.toml")).expect("config");
    assert!(
        cfg.contains("variant = \"laser-only\"") && cfg.contains("learning_starts = 40"),
        "{cfg}"
    );
    let eval = std::fs::read_to_string(run.join("eval.csv")).expect("eval");
    assert!(
        eval.starts_with("step,eval_reward_mean,eval_reward_std") && eval.lines().count() == 2,
        "{eval}"
    );
    // The safetensors header names tensors in PyTorch layout.
    let bytes = std::fs::read(run.join("model.safetensors")).expect("weights");
    let n = u64::from_le_bytes(bytes[..8].try_into().expect("8 bytes")) as usize;
    let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + n]).expect("json header");
    assert_eq!(header["laser.c1.weight"]["shape"], serde_json::json!([16, 4, 5]));
    assert_eq!(header["value.hidden.weight"]["shape"], serde_json::json!([512, 1024]));
    assert_eq!(header["__metadata__"]["mdrlat_variant"], "laser-only");
    // Never overwrite a run.
    assert_clean_failure(&mdrlat(&args), &["already holds a run"]);
    // Resume extends it from its checkpoint (written every 100 steps here).
    let o = mdrlat(&["train", "--resume", r, "--steps", "150"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let metrics = std::fs::read_to_string(run.join("metrics.csv")).expect("metrics");
    assert!(metrics.lines().last().is_some_and(|l| l.starts_with("150,")), "{metrics}");
    // `mdrlat ros` loads the run's policy (then fails on the closed port, a clear error).
    let o = mdrlat(&["ros", "--checkpoint", r, "--master", "http://127.0.0.1:9/"]);
    let e = stderr(&o);
    assert!(!o.status.success() && !e.contains("panicked"), "{e}");
    for needle in
        ["policy: laser-only network", "(step 150)", "error: ROS master http://127.0.0.1:9/"]
    {
        assert!(e.contains(needle), "stderr lacks '{needle}': {e}");
    }
    assert_eq!(e.matches("Connection refused").count(), 1, "one cause, once: {e}");
    // `mdrlat eval` evaluates the run's network; the results do not depend on how many
    // environments step together (forwards of a fixed size).
    let evaluate = |name: &str, envs: &str| {
        let out = d.join(name);
        let o = mdrlat(&[
            "eval",
            "--checkpoint",
            r,
            "--world",
            "crowd",
            "--episodes",
            "3",
            "--runs",
            "2",
            "--max-steps",
            "25",
            "--envs",
            envs,
            "--out",
            out.to_str().expect("utf8"),
            "--json",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let line: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
        assert_eq!(line["world"], "crowd");
        assert_eq!((line["episodes"].as_u64(), line["runs"].as_u64()), (Some(3), Some(2)));
        assert!(line["eval"].as_str().is_some_and(|e| e.starts_with("laser-only from")), "{line}");
        assert!(line["policy_gflops"].as_f64().is_some_and(|g| g > 0.0), "{line}");
        std::fs::read(out.join("episodes.csv")).expect("episodes.csv")
    };
    assert_eq!(evaluate("eval-a", "6"), evaluate("eval-b", "1"));
    let broken = d.join("broken");
    std::fs::create_dir_all(broken.join("checkpoint")).expect("dir");
    std::fs::write(broken.join("checkpoint/meta.json"), "{\"format\": 1").expect("write");
    let o = mdrlat(&["ros", "--checkpoint", broken.to_str().expect("utf8")]);
    assert_clean_failure(&o, &["meta.json: corrupt"]);
    assert_clean_failure(&mdrlat(&["train", "--resume", r, "--variant", "mdrlat"]), &["--variant"]);
    assert_clean_failure(&mdrlat(&["train", "--variant", "mdrlat2", "--out", r]), &["mdrlat2"]);
    let other = d.join("other");
    let o = other.to_str().expect("utf8");
    assert_clean_failure(
        &mdrlat(&["train", "--out", o, "--set", "train.batch_size=0"]),
        &["train.batch_size"],
    );
    assert_clean_failure(&mdrlat(&["train", "--out", o, "--set", "train.lr=0.1"]), &["lr"]);
    // A warm start from the run's model: checked before the run directory exists, and
    // recorded in its config.
    let warm = d.join("warm");
    let w = warm.to_str().expect("utf8");
    let model = run.join("model.safetensors");
    let from = |m: &str, v: &str| {
        let steps = ["--steps", "30", "--set", "sim.max_episode_steps=30"];
        let base = ["train", "--variant", v, "--world", "example", "--init-from", m, "--out", w];
        mdrlat(&[&base[..], &steps[..]].concat())
    };
    assert_clean_failure(&from("nowhere", "laser-only"), &["train.init_from", "nowhere"]);
    let o = from(model.to_str().expect("utf8"), "mdrlat");
    assert_clean_failure(&o, &["train.init_from", "laser-only network", "trains a mdrlat"]);
    assert!(!warm.exists(), "no run directory for a bad warm start");
    let o = from(model.to_str().expect("utf8"), "laser-only");
    let said = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success() && said.contains("warm start from"), "{}", stderr(&o));
    let cfg = std::fs::read_to_string(warm.join("config.toml")).expect("config");
    assert!(cfg.contains("init_from = ") && cfg.contains("model.safetensors"), "{cfg}");
    assert!(!std::fs::read_to_string(run.join("config.toml")).expect("cfg").contains("init_from"));
}

/// Ctrl-C (SIGINT) stops a training run with a checkpoint where it stopped and one error
/// line saying how to continue; `--resume` finishes it.
#[test]
fn an_interrupted_train_writes_its_checkpoint_and_says_how_to_resume() {
    use std::process::{Command, Stdio};
    let d = tmp("train-sigint");
    let run = d.join("run");
    let r = run.to_str().expect("utf8");
    let mut args = laser_only_train("1000000", r);
    args.extend([
        "--set",
        "train.learning_starts=40",
        "--set",
        "train.checkpoint_interval=1000000",
        "--set",
        "train.eval_interval=1000000",
    ]);
    let child = Command::new(common::EXE)
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    // Wait until it trains (its first metrics row), then interrupt it.
    let metrics = run.join("metrics.csv");
    let t0 = std::time::Instant::now();
    while std::fs::read_to_string(&metrics).map_or(0, |m| m.lines().count()) < 2 {
        assert!(t0.elapsed().as_secs() < 120, "no metrics row within 2 minutes");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let kill = Command::new("kill").args(["-INT", &child.id().to_string()]).status();
    assert!(kill.expect("kill").success());
    let o = child.wait_with_output().expect("wait");
    assert_clean_failure(&o, &["stopped at step", "--resume", r]);
    let meta = std::fs::read_to_string(run.join("checkpoint/meta.json")).expect("checkpoint");
    let step: u64 = stderr(&o)
        .split("stopped at step ")
        .nth(1)
        .and_then(|t| t.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .expect("the step in the message");
    assert!(step > 0 && meta.contains(&format!("\"step\":{step}")), "{meta}");
    assert!(!run.join("model.safetensors").exists(), "a stopped run is not a finished one");
    // Resumed with a reachable end, it finishes.
    let end = (step + 20).to_string();
    let o = mdrlat(&["train", "--resume", r, "--steps", &end]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(run.join("model.safetensors").is_file());
    let _ = std::fs::remove_dir_all(&d);
}

/// `train.snapshot_minutes` and `mdrlat eval --snapshots`: every snapshot by the protocol,
/// then success against minutes (table and figure); a run without snapshots is a clear error.
#[test]
fn eval_snapshots_measures_success_against_minutes_of_training() {
    let d = tmp("snapshots");
    let run = d.join("run");
    let r = run.to_str().expect("utf8");
    let o = mdrlat(&[
        "train",
        "--variant",
        "laser-only",
        "--world",
        "example",
        "--steps",
        "400",
        "--out",
        r,
        "--set",
        "train.learning_starts=40",
        "--set",
        "train.curve_episodes=0",
        "--set",
        "train.snapshot_minutes=0.002",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let snapshots: Vec<_> = std::fs::read_dir(run.join("snapshots")).expect("snapshots").collect();
    assert!(!snapshots.is_empty());
    let out = d.join("eval");
    let o = mdrlat(&[
        "eval",
        "--snapshots",
        r,
        "--world",
        "crowd",
        "--episodes",
        "2",
        "--runs",
        "1",
        "--max-steps",
        "30",
        "--out",
        out.to_str().expect("utf8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = std::fs::read_to_string(out.join("snapshots.csv")).expect("snapshots.csv");
    assert_eq!(csv.lines().count(), 1 + snapshots.len(), "{csv}");
    assert!(csv.lines().skip(1).all(|l| l.contains(",crowd,2,1,")), "{csv}");
    assert!(out.join("snapshots.png").is_file() && out.join("snapshots.md").is_file());
    let first = std::fs::read_dir(&out)
        .expect("out")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("minute-")))
        .expect("a snapshot's own evaluation");
    assert!(first.join("summary.md").is_file());
    // Again into the same folder: refused without --overwrite.
    let again = mdrlat(&[
        "eval",
        "--snapshots",
        r,
        "--world",
        "crowd",
        "--out",
        out.to_str().expect("utf8"),
    ]);
    assert_clean_failure(&again, &["--overwrite"]);
    // --only-new keeps what was evaluated and evaluates the rest: with one snapshot's
    // evaluation left unfinished (no summary.csv), only that one runs again, to the same bytes.
    let o_str = out.to_str().expect("utf8");
    let only_new = |episodes: &str| {
        mdrlat(&[
            "eval",
            "--snapshots",
            r,
            "--world",
            "crowd",
            "--episodes",
            episodes,
            "--runs",
            "1",
            "--max-steps",
            "30",
            "--out",
            o_str,
            "--only-new",
        ])
    };
    std::fs::remove_file(first.join("summary.csv")).expect("rm summary.csv");
    let o = only_new("2");
    assert!(o.status.success(), "{}", stderr(&o));
    let said = String::from_utf8_lossy(&o.stdout);
    assert_eq!(said.matches("kept from").count(), snapshots.len() - 1, "{said}");
    assert!(first.join("summary.csv").is_file());
    assert_eq!(std::fs::read_to_string(out.join("snapshots.csv")).expect("csv"), csv);
    // Another protocol is refused, not mixed in; and --only-new needs --snapshots.
    assert_clean_failure(&only_new("3"), &["summary.csv", "other settings", "--only-new"]);
    let e = d.join("e").to_str().expect("utf8").to_owned();
    assert_clean_failure(
        &mdrlat(&["eval", "--policy", "spin", "--out", &e, "--only-new"]),
        &["--snapshots"],
    );
    let elsewhere = d.join("elsewhere");
    let e = elsewhere.to_str().expect("utf8");
    assert_clean_failure(
        &mdrlat(&["eval", "--snapshots", r, "--task", "nav", "--out", e]),
        &["--snapshots", "trained for obstacle avoidance", "--task nav"],
    );
    assert_clean_failure(
        &mdrlat(&["eval", "--snapshots", r, "--threads", "0", "--out", e]),
        &["--threads"],
    );
    // A run trained without snapshots.
    std::fs::remove_dir_all(run.join("snapshots")).expect("rm");
    let o = mdrlat(&["eval", "--snapshots", r, "--out", d.join("none").to_str().expect("utf8")]);
    assert_clean_failure(&o, &["train.snapshot_minutes"]);
    let o = mdrlat(&[
        "train",
        "--variant",
        "laser-only",
        "--out",
        d.join("bad").to_str().expect("utf8"),
        "--set",
        "train.snapshot_minutes=-1",
    ]);
    assert_clean_failure(&o, &["train.snapshot_minutes"]);
}

#[test]
fn eval_writes_reproducible_results_and_refuses_bad_input() {
    let d = tmp("eval");
    let run = |name: &str, extra: &[&str]| {
        let out = d.join(name);
        let mut args = vec![
            "eval",
            "--policy",
            "wander",
            "--world",
            "crowd",
            "--world",
            "office",
            "--episodes",
            "4",
            "--runs",
            "2",
            "--max-steps",
            "40",
            "--out",
            out.to_str().expect("utf8"),
        ];
        args.extend_from_slice(extra);
        (mdrlat(&args), out)
    };
    let (o, a) = run("a", &["--json", "--figures", "2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let lines: Vec<serde_json::Value> = String::from_utf8(o.stdout)
        .expect("utf8")
        .lines()
        .map(|l| serde_json::from_str(l).expect("json line"))
        .collect();
    assert_eq!(lines.len(), 2, "one object per world");
    assert_eq!(
        (lines[0]["world"].as_str(), lines[1]["world"].as_str()),
        (Some("crowd"), Some("office"))
    );
    for l in &lines {
        assert_eq!(l["eval"], "wander");
        let m = l["success_mean"].as_f64().expect("success_mean");
        assert!((0.0..=1.0).contains(&m) && l["success_std"].as_f64().is_some(), "{l}");
        let moving = l["moving_success_mean"].as_f64().expect("moving_success_mean");
        assert!(moving <= m && l["moving_success_std"].as_f64().is_some(), "{l}");
        assert_eq!((l["min_path_m"].as_f64(), l["min_reach_m"].as_f64()), (Some(5.0), Some(2.0)));
    }
    let episodes = std::fs::read_to_string(a.join("episodes.csv")).expect("episodes.csv");
    assert!(episodes.starts_with(
        "world,run,episode,seed,x0,y0,yaw0_deg,steps,moving_success,success,collision,\
         collision_kind,hit,path_m,reach_m,return,min_path_m,min_reach_m\n"
    ));
    assert_eq!(episodes.lines().count(), 1 + 2 * 2 * 4);
    let figures: Vec<String> = std::fs::read_dir(a.join("figures"))
        .expect("figures")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    let (maps, episode_figures): (Vec<_>, Vec<_>) =
        figures.iter().partition(|f| f.ends_with("-collisions.png"));
    assert_eq!(episode_figures.len(), 4, "a strip and a trajectory per picked episode");
    // A collision map for each world where an episode ended in a collision.
    let mut collided: Vec<String> = episodes
        .lines()
        .skip(1)
        .filter(|l| l.split(',').nth(10) == Some("1"))
        .map(|l| format!("{}-collisions.png", l.split(',').next().expect("world")))
        .collect();
    collided.sort();
    collided.dedup();
    let mut maps: Vec<String> = maps.into_iter().cloned().collect();
    maps.sort();
    assert!(!collided.is_empty(), "wander collides somewhere");
    assert_eq!(maps, collided);
    // Same seed, same bytes (with other --envs); an existing evaluation is not replaced.
    let (o, b) = run("b", &["--figures", "2", "--envs", "3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in ["episodes.csv", "summary.csv", "summary.md"] {
        assert_eq!(
            std::fs::read(a.join(f)).expect("a"),
            std::fs::read(b.join(f)).expect("b"),
            "{f}"
        );
    }
    assert_clean_failure(&run("a", &[]).0, &["already holds an evaluation", "--overwrite"]);
    assert!(run("a", &["--overwrite"]).0.status.success());
    assert!(!a.join("figures").exists(), "old figures removed with --overwrite");

    let out = d.join("bad");
    let o = out.to_str().expect("utf8");
    let cases: [(Vec<&str>, &[&str]); 10] = [
        (vec!["--policy", "wander", "--episodes", "0"], &["--episodes 0"]),
        (vec!["--policy", "wander", "--min-path", "-1"], &["--min-path -1", "0 m or more"]),
        (vec!["--policy", "wander", "--min-reach", "-0.5"], &["--min-reach -0.5"]),
        (vec!["--policy", "wander", "--min-reach", "inf"], &["--min-reach inf"]),
        (vec!["--policy", "wander", "--max-steps", "-5"], &["--max-steps", "-5"]),
        (vec!["--policy", "wander", "--world", "nowhere"], &["nowhere"]),
        (vec!["--policy", "dance"], &["dance", "wander-laser", "spin", "circle"]),
        (vec!["--checkpoint", "/no/such/run"], &["/no/such/run"]),
        (vec!["--checkpoint", "x", "--policy", "wander"], &["--checkpoint", "--policy"]),
        (vec![], &["--checkpoint", "--policy"]),
    ];
    for (args, needles) in cases {
        let mut full = vec!["eval", "--out", o];
        full.extend(args);
        assert_clean_failure(&mdrlat(&full), needles);
    }
    let broken = d.join("broken");
    std::fs::create_dir_all(broken.join("checkpoint")).expect("dir");
    std::fs::write(broken.join("checkpoint/meta.json"), "{\"format\": 1").expect("write");
    let o = mdrlat(&["eval", "--checkpoint", broken.to_str().expect("utf8"), "--out", o]);
    assert_clean_failure(&o, &["meta.json: corrupt"]);
}

#[test]
fn plot_draws_runs_and_rejects_bad_files() {
    let d = tmp("plot");
    let run = d.join("a");
    std::fs::create_dir_all(&run).expect("dir");
    std::fs::write(run.join("eval.csv"), "step,eval_reward_mean,eval_reward_std,eval_length_mean\n5000,1.0,0.5,10\n10000,3.0,1.0,20\n").expect("write");
    let png = d.join("fig4.png");
    let o = mdrlat(&["plot", run.to_str().expect("utf8"), "--out", png.to_str().expect("utf8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::fs::metadata(&png).expect("png").len() > 1000);
    let size = |p: &std::path::Path| {
        let decoder =
            png::Decoder::new(std::io::BufReader::new(std::fs::File::open(p).expect("png")));
        let info = decoder.read_info().expect("png header");
        (info.info().width, info.info().height)
    };
    let (w1, h1) = size(&png);
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("1 curves, smoothing"),
        "no curve panels for an old run"
    );
    // A run with learning curves gets a panel each for moving success, success and path.
    std::fs::write(
        run.join("eval.csv"),
        "step,eval_reward_mean,eval_reward_std,eval_length_mean,eval_success_rate,eval_collision_rate,\
train_moving_success,train_success,train_path_m,unseen_moving_success,unseen_success,unseen_path_m\n\
5000,1.0,0.5,10,0,1,0.1,0.5,3.0,0.0,0.4,2.0\n10000,3.0,1.0,20,0,1,0.3,0.6,6.0,0.2,0.5,5.0\n",
    )
    .expect("write");
    let o = mdrlat(&["plot", run.to_str().expect("utf8"), "--out", png.to_str().expect("utf8")]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("3 learning-curve panels"));
    let (w2, h2) = size(&png);
    assert!(w2 > 2 * w1 - 100 && h2 > 2 * h1 - 100, "a 2 x 2 grid: {w1}x{h1} -> {w2}x{h2}");
    std::fs::write(run.join("eval.csv"), "step,eval_reward_mean,eval_reward_std\n5000,abc,0.5\n")
        .expect("write");
    let o = mdrlat(&["plot", run.to_str().expect("utf8"), "--out", png.to_str().expect("utf8")]);
    assert_clean_failure(&o, &["eval.csv:2", "abc"]);
    let missing = d.join("none");
    assert_clean_failure(&mdrlat(&["plot", missing.to_str().expect("utf8")]), &["eval.csv"]);
}

/// The frames of a GIF (each frame's compressed image data), read block by block: the
/// header, the screen and its colour table, then extensions and images up to the trailer.
fn gif_frames(bytes: &[u8]) -> Vec<Vec<u8>> {
    assert!(bytes.starts_with(b"GIF89a") || bytes.starts_with(b"GIF87a"), "not a GIF");
    let table = |flags: u8| if flags & 0x80 != 0 { 3usize << ((flags & 7) + 1) } else { 0 };
    let mut at = 13 + table(bytes[10]);
    // Data sub-blocks from `at` up to their terminator; returns their bytes and the end.
    let sub_blocks = |mut at: usize| {
        let mut data = Vec::new();
        while bytes[at] != 0 {
            let n = bytes[at] as usize;
            data.extend_from_slice(&bytes[at + 1..at + 1 + n]);
            at += 1 + n;
        }
        (data, at + 1)
    };
    let mut frames = Vec::new();
    loop {
        match bytes[at] {
            0x21 => at = sub_blocks(at + 2).1,
            0x2C => {
                at += 10 + table(bytes[at + 9]);
                let (data, end) = sub_blocks(at + 1);
                frames.push(data);
                at = end;
            }
            0x3B => return frames,
            b => panic!("unexpected GIF block 0x{b:02x} at byte {at}"),
        }
    }
}

/// The demo's GIF is an episode, not a still: a frame per step plus the start, and the
/// picture changes as the robot drives.
#[test]
fn the_demo_gif_shows_the_episode_frame_by_frame() {
    let d = tmp("demo-gif");
    let out = d.join("demo");
    let o = mdrlat(&[
        "demo",
        "--out",
        out.to_str().expect("utf8"),
        "--model",
        "none",
        "--steps",
        "12",
        "--train-steps",
        "0",
        "--bench-seconds",
        "0",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let rows = std::fs::read_to_string(out.join("trajectory.csv")).expect("trajectory");
    let steps = rows.lines().count() - 1;
    let frames = gif_frames(&std::fs::read(out.join("episode.gif")).expect("gif"));
    assert_eq!(frames.len(), steps + 1, "the start and one frame per step");
    assert_ne!(frames.first(), frames.last(), "the robot moved");
    assert!(frames.windows(2).filter(|w| w[0] != w[1]).count() >= steps / 2);
    let _ = std::fs::remove_dir_all(&d);
}
