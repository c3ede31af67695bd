//! The planner as a policy: navigation episodes in the unseen test world.

use mdrlat_plan::{MapSource, PlannerOptions, PlannerPolicy};
use mdrlat_sim::config::Task;
use mdrlat_sim::{EpisodeSpec, Quiet, RunOptions, SimConfig, StaticScene, VecEnv, run_episodes};
use std::sync::Arc;

fn episodes(map: MapSource, n: u64) -> Vec<mdrlat_sim::EpisodeOutcome> {
    let world = mdrlat_world::load("nav-test").expect("nav-test");
    let config = SimConfig { task: Task::Nav, ..SimConfig::default() };
    let mut policy =
        PlannerPolicy::new(&world, &config, &PlannerOptions { map, ..PlannerOptions::default() })
            .expect("planner");
    let scene = Arc::new(StaticScene::new(Arc::new(world), &config));
    let mut venv = VecEnv::new(scene, config, 2, 1).expect("envs");
    let specs: Vec<EpisodeSpec> =
        (0..n).map(|s| EpisodeSpec { seed: Some(s), pose: None }).collect();
    let options = RunOptions { max_steps: 400, record_rows: false };
    run_episodes(&mut venv, &mut policy, &specs, &options, &mut Quiet).expect("episodes")
}

#[test]
fn the_planner_reaches_the_goals_of_the_unseen_world_and_only_low_obstacles_stop_it() {
    // With a map of everything the body can hit, every goal (2026-12-02: 40 of 40 seeds).
    let body = episodes(MapSource::Body, 20);
    let ok = body.iter().filter(|o| o.success()).count();
    assert!(ok >= 19, "{ok} of 20 with the body map");
    // With the laser-plane map (what move_base gets from a 2D-laser SLAM map), it drives
    // into what neither its map nor its laser holds: obstacles below or above the plane.
    let world = mdrlat_world::load("nav-test").expect("nav-test");
    let laser_plane = SimConfig::default().laser.height_m;
    let laser = episodes(MapSource::LaserPlane, 20);
    let ok = laser.iter().filter(|o| o.success()).count();
    assert!((15..20).contains(&ok), "{ok} of 20 with the laser-plane map");
    for o in laser.iter().filter(|o| !o.success()) {
        let Some(mdrlat_sim::Collision::Bumper { obstacle }) = o.collision else {
            panic!("a failure other than the bumper: {o:?}");
        };
        let prism = &world.obstacles[obstacle].prism;
        assert!(!prism.spans_height(laser_plane), "obstacle {obstacle} crosses the laser plane");
    }
    // The same seeds, the same episodes.
    assert_eq!(episodes(MapSource::LaserPlane, 4), laser[..4].to_vec());
}

#[test]
fn a_planner_episode_replays_exactly_from_its_velocity_commands() {
    let world = mdrlat_world::load("nav-test").expect("nav-test");
    let config = SimConfig { task: Task::Nav, ..SimConfig::default() };
    let scene = Arc::new(StaticScene::new(Arc::new(world), &config));
    let original = episodes(MapSource::LaserPlane, 3);
    let mut venv = VecEnv::new(scene, config, 1, 1).expect("env");
    for (seed, o) in original.iter().enumerate() {
        assert!(o.commands.iter().any(|c| !mdrlat_core::TABLE_1.contains(c)), "continuous");
        let mut replay = mdrlat_sim::ReplayPolicy::with_commands(
            vec![o.actions.clone()],
            vec![o.commands.clone()],
        );
        let spec = EpisodeSpec { seed: Some(seed as u64), pose: None };
        let options = RunOptions { max_steps: o.steps, record_rows: false };
        let again = run_episodes(&mut venv, &mut replay, &[spec], &options, &mut Quiet)
            .expect("replay")
            .pop()
            .expect("one episode");
        assert_eq!(
            (again.steps, again.collision, again.reached_goal),
            (o.steps, o.collision, o.reached_goal)
        );
        assert_eq!(again.path_m, o.path_m);
    }
}
