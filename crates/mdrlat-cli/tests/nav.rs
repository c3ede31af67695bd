//! The navigation task end to end: `mdrlat eval --task nav` with the classical planner and
//! with a goal-conditioned network trained by `mdrlat train --task nav`, their outputs, and
//! bad input.

mod common;
use common::{assert_clean_failure, mdrlat, stderr, tmp};

#[test]
fn the_planner_is_evaluated_on_the_navigation_task_reproducibly() {
    let dir = tmp("nav", "planner");
    let run = |out: &str| {
        let out = dir.join(out);
        let o = mdrlat(&[
            "eval",
            "--task",
            "nav",
            "--policy",
            "planner-body",
            "--episodes",
            "4",
            "--runs",
            "1",
            "--figures",
            "2",
            "--out",
            out.to_str().expect("utf-8"),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        out
    };
    let (a, b) = (run("a"), run("b"));
    for f in [
        "episodes.csv",
        "summary.csv",
        "navigation.csv",
        "navigation.md",
        "figures/nav-test-fig9.png",
    ] {
        let read = |d: &std::path::Path| std::fs::read(d.join(f)).expect(f);
        assert_eq!(read(&a), read(&b), "{f}: same seed, same bytes");
    }
    let nav = std::fs::read_to_string(a.join("navigation.csv")).expect("navigation.csv");
    assert!(nav.starts_with("world,run,episode,seed,goal_x,goal_y,reached,timeout,"), "{nav}");
    assert_eq!(nav.lines().count(), 5);
    let md = std::fs::read_to_string(a.join("navigation.md")).expect("navigation.md");
    assert!(md.contains("| planner (A* + DWA, body map of 'nav-test') | nav-test |"), "{md}");
    let summary = std::fs::read_to_string(a.join("summary.md")).expect("summary.md");
    assert!(summary.contains("Success = the goal reached"), "{summary}");
}

#[test]
fn a_planner_rollout_drives_to_its_goal() {
    let dir = tmp("nav", "rollout");
    let csv = dir.join("pl.csv");
    let o = mdrlat(&[
        "rollout",
        "--world",
        "nav-test",
        "--task",
        "nav",
        "--policy",
        "planner-body",
        "--start",
        "1.0,1.0,0",
        "--goal",
        "8.2,9.3",
        "--steps",
        "300",
        "--out",
        csv.to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(said.contains("0 collision(s), 1 goal(s) reached"), "{said}");
    let rows = std::fs::read_to_string(&csv).expect("csv");
    let last = rows.lines().last().expect("a row");
    assert!(last.contains(",1,0,"), "terminated, not truncated: {last}");
}

/// A few hundred steps of `train --task nav` make a goal-conditioned network that
/// `eval --task nav` runs (the same bytes twice) and no other task accepts.
#[test]
fn a_goal_conditioned_network_trains_and_is_evaluated_on_navigation() {
    let dir = tmp("nav", "train");
    let run = dir.join("run");
    let r = run.to_str().expect("utf-8");
    let mut args = vec!["train", "--task", "nav", "--variant", "laser-only", "--steps", "150"];
    let sets = [
        "train.learning_starts=40",
        "train.eval_interval=100",
        "train.eval_episodes=2",
        "train.checkpoint_interval=100",
        "sim.max_episode_steps=40",
        "train.snapshot_minutes=0.001",
    ];
    for set in &sets {
        args.extend(["--set", set]);
    }
    let o = mdrlat(&[args.as_slice(), &["--out", r]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(said.contains("laser-only (nav) in 'nav-train'"), "{said}");
    assert!(said.contains("of goals reached"), "{said}");
    let cfg = std::fs::read_to_string(run.join("config.toml")).expect("config");
    assert!(cfg.contains("task = \"nav\""), "{cfg}");
    // Resuming keeps the task (from the run's config) and extends the run.
    let o = mdrlat(&["train", "--resume", r, "--steps", "160"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_clean_failure(
        &mdrlat(&["train", "--resume", r, "--task", "avoid"]),
        &["--task", "cannot be used with"],
    );
    let eval = |out: &str, extra: &[&str]| {
        let out = dir.join(out);
        let mut a = vec!["eval", "--checkpoint", r, "--episodes", "3", "--runs", "1"];
        a.extend_from_slice(extra);
        a.extend(["--out", out.to_str().expect("utf-8")]);
        (mdrlat(&a), out)
    };
    let (o, a) = eval("a", &["--task", "nav"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (o, b) = eval("b", &["--task", "nav"]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in ["episodes.csv", "navigation.csv", "navigation.md"] {
        let read = |d: &std::path::Path| std::fs::read(d.join(f)).expect(f);
        assert_eq!(read(&a), read(&b), "{f}: same seed, same bytes");
    }
    let md = std::fs::read_to_string(a.join("navigation.md")).expect("navigation.md");
    assert!(md.contains("laser-only from"), "{md}");
    // Its snapshots: goals reached against minutes of training.
    let taken = std::fs::read_dir(run.join("snapshots")).expect("snapshots").count();
    assert!(taken > 0);
    let snaps = dir.join("snapshots");
    let o = mdrlat(&[
        "eval",
        "--snapshots",
        r,
        "--task",
        "nav",
        "--episodes",
        "2",
        "--runs",
        "1",
        "--out",
        snaps.to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = std::fs::read_to_string(snaps.join("snapshots.csv")).expect("snapshots.csv");
    assert_eq!(csv.lines().count(), 1 + taken, "{csv}");
    assert!(csv.lines().skip(1).all(|l| l.contains(",nav-test,2,1,")), "{csv}");
    let md = std::fs::read_to_string(snaps.join("snapshots.md")).expect("snapshots.md");
    assert!(md.contains("Goals reached %"), "{md}");
    assert!(snaps.join("snapshots.png").is_file());
    // The model file records the task: it, too, evaluates on navigation only.
    let bytes = std::fs::read(run.join("model.safetensors")).expect("model");
    let n = u64::from_le_bytes(bytes[..8].try_into().expect("8 bytes")) as usize;
    let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + n]).expect("json header");
    assert_eq!(header["__metadata__"]["mdrlat_task"], "nav");
    let (o, _) = eval("c", &[]);
    assert_clean_failure(
        &o,
        &["laser-only network trained for navigation", "--task avoid", "--task avoid"],
    );
    let model = run.join("model.safetensors");
    let o = mdrlat(&[
        "eval",
        "--checkpoint",
        model.to_str().expect("utf-8"),
        "--episodes",
        "2",
        "--runs",
        "1",
        "--out",
        dir.join("d").to_str().expect("utf-8"),
    ]);
    assert_clean_failure(&o, &["trained for navigation"]);
    // Exported for shipping, it is compared on navigation observations and stays one.
    let shipped = dir.join("shipped");
    let o = mdrlat(&[
        "export",
        "--checkpoint",
        r,
        "--eval",
        a.to_str().expect("utf-8"),
        "--samples",
        "40",
        "--out",
        shipped.to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let readme = std::fs::read_to_string(shipped.join("README.md")).expect("README");
    assert!(readme.contains("goal-conditioned") && readme.contains("nav-test"), "{readme}");
    assert!(shipped.join("navigation.md").is_file());
    let o = mdrlat(&[
        "eval",
        "--task",
        "nav",
        "--checkpoint",
        shipped.to_str().expect("utf-8"),
        "--episodes",
        "2",
        "--runs",
        "1",
        "--out",
        dir.join("e").to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // Checkpoint averaging: the mean of the run's and the shipped model's weights exports as
    // one model that records both; a network of another task is refused, naming it.
    let mean = dir.join("mean");
    let shipped_s = shipped.to_str().expect("utf-8");
    let o = mdrlat(&[
        "export",
        "--checkpoint",
        r,
        "--checkpoint",
        shipped_s,
        "--samples",
        "20",
        "--out",
        mean.to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let readme = std::fs::read_to_string(mean.join("README.md")).expect("README");
    assert!(readme.contains("the mean of 2 checkpoints' weights"), "{readme}");
    let avoid = concat!(env!("CARGO_MANIFEST_DIR"), "/../../models/laser-only-cpu-small");
    let o = mdrlat(&[
        "export",
        "--checkpoint",
        r,
        "--checkpoint",
        avoid,
        "--out",
        dir.join("mixed").to_str().expect("utf-8"),
    ]);
    assert_clean_failure(&o, &["laser-only-cpu-small", "only networks of one variant and task"]);
    // The ROS node has no goal to give it.
    assert_clean_failure(
        &mdrlat(&["ros", "--checkpoint", r]),
        &["trained for navigation", "has no goal to give it"],
    );
    // A world without goal regions cannot train navigation.
    let o = mdrlat(&[
        "train",
        "--task",
        "nav",
        "--world",
        "office",
        "--steps",
        "10",
        "--out",
        dir.join("office").to_str().expect("utf-8"),
    ]);
    assert_clean_failure(&o, &["office", "no goal region"]);
}

#[test]
fn bad_navigation_arguments_are_clear_errors() {
    let dir = tmp("nav", "bad");
    let out = dir.join("out");
    let out = out.to_str().expect("utf-8");
    let eval = |extra: &[&str]| {
        let mut args = vec!["eval", "--episodes", "2", "--runs", "1", "--out", out];
        args.extend_from_slice(extra);
        mdrlat(&args)
    };
    assert_clean_failure(&eval(&["--policy", "planner"]), &["--policy planner", "--task nav"]);
    assert_clean_failure(
        &eval(&["--task", "nav", "--policy", "planner", "--world", "office"]),
        &["world 'office', task nav: the world has no goal region"],
    );
    assert_clean_failure(
        &eval(&["--task", "nav", "--policy", "planner", "--goal", "0.55,2.6"]),
        &["the goal (--goal, nav.goal) (0.55, 2.60) is inside obstacle", "sofa"],
    );
    assert_clean_failure(
        &eval(&["--task", "nav", "--policy", "planner", "--goal", "20,1"]),
        &["(20.00, 1.00) is outside the world's bounds"],
    );
    assert_clean_failure(
        &eval(&["--task", "nav", "--policy", "planner", "--start", "1,2"]),
        &["--start '1,2': expected X,Y,YAW_DEG"],
    );
    assert_clean_failure(&eval(&["--policy", "wander", "--goal", "1,2"]), &["add --task nav"]);
    assert_clean_failure(
        &eval(&["--task", "walk", "--policy", "wander"]),
        &["unknown task 'walk'"],
    );
    let model = concat!(env!("CARGO_MANIFEST_DIR"), "/../../models/laser-only-cpu-small");
    assert_clean_failure(
        &eval(&["--task", "nav", "--checkpoint", model]),
        &["laser-only network trained for obstacle avoidance", "--task nav"],
    );
    // A goal the robot cannot reach: inside a walled-off square.
    let world = dir.join("closed.toml");
    std::fs::write(
        &world,
        r#"version = 1
name = "closed"
bounds = { min = [0.0, 0.0], max = [6.0, 6.0] }
obstacle = [
  { shape = "box", center = [3.0, 0.05], size = [6.0, 0.1], z = [0.0, 2.5] },
  { shape = "box", center = [3.0, 5.95], size = [6.0, 0.1], z = [0.0, 2.5] },
  { shape = "box", center = [0.05, 3.0], size = [0.1, 6.0], z = [0.0, 2.5] },
  { shape = "box", center = [5.95, 3.0], size = [0.1, 6.0], z = [0.0, 2.5] },
  { shape = "box", center = [4.5, 3.5], size = [2.0, 0.1], z = [0.0, 2.5] },
  { shape = "box", center = [4.5, 5.5], size = [2.0, 0.1], z = [0.0, 2.5] },
  { shape = "box", center = [3.5, 4.5], size = [0.1, 2.0], z = [0.0, 2.5] },
  { shape = "box", center = [5.5, 4.5], size = [0.1, 2.0], z = [0.0, 2.5] },
]
spawn = [ { min = [0.5, 0.5], max = [2.5, 2.5] } ]
"#,
    )
    .expect("world");
    assert_clean_failure(
        &eval(&[
            "--task",
            "nav",
            "--policy",
            "planner",
            "--world",
            world.to_str().expect("utf-8"),
            "--goal",
            "4.5,4.5",
        ]),
        &["the goal is unreachable on the grid", "no collision-free path"],
    );
}
