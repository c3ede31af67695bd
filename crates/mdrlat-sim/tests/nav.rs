//! The navigation task: goals, the goal input, success, its reward, and bad input.

use mdrlat_core::{Action, goal_in_robot_frame};
use mdrlat_geom::Vec2;
use mdrlat_sim::config::Task;
use mdrlat_sim::{Env, SimConfig, SimError};
use mdrlat_world::World;

/// An empty 8 m room with a box in the middle and two goal regions (or none).
fn room(goals: bool) -> World {
    let goal = if goals {
        "goal = [ { min = [1.0, 6.0], max = [2.0, 7.0] }, { min = [6.0, 1.0], max = [7.0, 2.0] } ]"
    } else {
        ""
    };
    let text = format!(
        r#"version = 1
name = "room"
bounds = {{ min = [0.0, 0.0], max = [8.0, 8.0] }}
obstacle = [
  {{ shape = "box", center = [4.0, 0.05], size = [8.0, 0.1], z = [0.0, 2.5] }},
  {{ shape = "box", center = [4.0, 7.95], size = [8.0, 0.1], z = [0.0, 2.5] }},
  {{ shape = "box", center = [0.05, 4.0], size = [0.1, 8.0], z = [0.0, 2.5] }},
  {{ shape = "box", center = [7.95, 4.0], size = [0.1, 8.0], z = [0.0, 2.5] }},
  {{ shape = "box", center = [4.0, 4.0], size = [0.6, 0.6], z = [0.0, 1.0], label = "crate" }},
]
spawn = [ {{ min = [1.0, 1.0], max = [7.0, 7.0] }} ]
{goal}
"#
    );
    World::from_toml("room", &text).expect("room")
}

fn nav() -> SimConfig {
    SimConfig { task: Task::Nav, ..SimConfig::default() }
}

fn nav_err(world: World, config: SimConfig) -> String {
    match Env::from_world(world, config) {
        Err(e @ SimError::Nav { .. }) => e.to_string(),
        other => panic!("expected a nav error, got {:?}", other.map(|_| "an environment")),
    }
}

#[test]
fn goals_are_drawn_in_the_goal_regions_far_enough_and_seen_in_the_robot_frame() {
    let world = room(true);
    let regions = world.goals.clone();
    let mut env = Env::from_world(world, nav()).expect("env");
    let mut goals = Vec::new();
    for seed in 0..20 {
        env.reset(Some(seed)).expect("reset");
        let (g, pose) = (env.goal().expect("a goal"), env.pose());
        assert!(regions.iter().any(|r| r.contains(g)), "{g:?}");
        assert!((g - pose.position()).length() >= 2.0, "nav.min_start_goal_m");
        let seen = env.observation().goal.expect("the goal input");
        assert_eq!(seen, goal_in_robot_frame(pose.x, pose.y, pose.yaw, g.x, g.y));
        goals.push(g);
    }
    // Same seed, same goal; the seeds give different goals.
    env.reset(Some(3)).expect("reset");
    assert_eq!(env.goal(), Some(goals[3]));
    assert!(goals.iter().any(|&g| g != goals[0]));
    // Stepping keeps the input up to date.
    let step = env.step(Action::new(9).expect("turn")).expect("step");
    let (pose, g) = (step.info.pose, goals[3]);
    assert_eq!(
        step.observation.goal,
        Some(goal_in_robot_frame(pose.x, pose.y, pose.yaw, g.x, g.y))
    );
}

#[test]
fn driving_onto_the_goal_ends_the_episode_in_success() {
    let mut config = nav();
    config.nav.start = Some([1.5, 2.0, 90.0]);
    config.nav.goal = Some([1.5, 3.5]);
    let mut env = Env::from_world(room(true), config.clone()).expect("env");
    env.reset(Some(0)).expect("reset");
    let ahead = Action::new(1).expect("0.5 m/s ahead");
    let mut rewards = Vec::new();
    let last = loop {
        let s = env.step(ahead).expect("step");
        rewards.push(s.reward);
        if s.terminated || s.truncated {
            break s.info;
        }
        assert!(s.reward > 0.0, "getting closer pays: {}", s.reward);
    };
    assert!(last.reached_goal && last.collision.is_none(), "{last:?}");
    assert!((last.pose.position() - Vec2::new(1.5, 3.5)).length() <= config.nav.goal_radius_m);
    assert_eq!(rewards.last().copied(), Some(config.nav.arrival));
    assert!(rewards.len() < 20, "{} steps", rewards.len());
    assert!(env.step(ahead).is_err(), "the episode is over");
    // The obstacle-avoidance task has no goal.
    let mut avoid = Env::from_world(room(true), SimConfig::default()).expect("env");
    avoid.reset(Some(0)).expect("reset");
    assert!(avoid.goal().is_none() && avoid.observation().goal.is_none());
    assert!(!avoid.step(ahead).expect("step").info.reached_goal);
}

#[test]
fn a_saved_navigation_episode_continues_exactly_and_only_as_navigation() {
    let mut env = Env::from_world(room(true), nav()).expect("env");
    env.reset(Some(5)).expect("reset");
    env.step(Action::new(8).expect("turn")).expect("step");
    let state = env.state();
    let mut other = Env::from_world(room(true), nav()).expect("env");
    other.restore(&state).expect("restore");
    assert_eq!(other.goal(), env.goal());
    assert_eq!(other.observation().goal, env.observation().goal);
    let (a, b) = (Action::new(2).expect("a"), Action::new(2).expect("a"));
    let ra = env.step(a).expect("step").reward;
    assert_eq!(other.step(b).expect("step").reward, ra);
    let mut avoid = Env::from_world(room(true), SimConfig::default()).expect("env");
    let e = avoid.restore(&state).expect_err("other task");
    assert!(e.to_string().contains("nav task, this environment runs avoid"), "{e}");
}

#[test]
fn bad_navigation_input_names_the_world_and_the_argument() {
    let e = nav_err(room(false), nav());
    assert!(e.starts_with("world 'room', task nav: the world has no goal region"), "{e}");
    // A fixed goal makes a world without goal regions usable.
    let mut fixed = nav();
    fixed.nav.goal = Some([6.5, 6.5]);
    assert!(Env::from_world(room(false), fixed.clone()).is_ok());
    fixed.nav.goal = Some([4.0, 4.1]);
    let e = nav_err(room(false), fixed.clone());
    assert!(
        e.contains("the goal (--goal, nav.goal) (4.00, 4.10) is inside obstacle 4 ('crate')"),
        "{e}"
    );
    fixed.nav.goal = Some([9.0, 1.0]);
    let e = nav_err(room(false), fixed.clone());
    assert!(e.contains("(9.00, 1.00) is outside the world's bounds"), "{e}");
    fixed.nav.goal = Some([6.5, 6.5]);
    fixed.nav.start = Some([0.1, 4.0, 0.0]);
    let e = nav_err(room(false), fixed);
    assert!(e.contains("the start (--start, nav.start) (0.10, 4.00) is inside obstacle 2"), "{e}");
    // Goals that cannot be that far from the start.
    let mut far = nav();
    far.nav.min_start_goal_m = 50.0;
    let mut env = Env::from_world(room(true), far).expect("env");
    let e = env.reset(Some(0)).expect_err("no goal that far").to_string();
    assert!(e.contains("no free goal at least 50 m (nav.min_start_goal_m)"), "{e}");
    let mut zero = nav();
    zero.nav.goal_radius_m = 0.0;
    let e = Env::from_world(room(true), zero).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(e.contains("nav.goal_radius_m"), "{e}");
}
