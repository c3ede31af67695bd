//! `mdrlat eval --task nav`: the classical planner end to end, its outputs, and bad input.

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
        &["laser-only network of the obstacle-avoidance task", "--task nav"],
    );
    // Training learns obstacle avoidance only so far: a navigation config is refused.
    let config = dir.join("nav.toml");
    std::fs::write(&config, "[sim]\ntask = \"nav\"\n").expect("config");
    let run = dir.join("run");
    let o = mdrlat(&[
        "train",
        "--variant",
        "laser-only",
        "--world",
        "nav-train",
        "--steps",
        "10",
        "--config",
        config.to_str().expect("utf-8"),
        "--out",
        run.to_str().expect("utf-8"),
    ]);
    assert_clean_failure(&o, &["sim.task = \"nav\": training learns obstacle avoidance only"]);
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
