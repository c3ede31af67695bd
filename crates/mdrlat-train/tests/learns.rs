//! Evidence that it learns, not just runs: a laser-only agent trained for a few thousand
//! steps in a small room beats the random policy's greedy-evaluation reward by a wide margin.
//! (It trains for real, so it takes a while; how fast training is, is the benches' business.)

mod common;
use common::train;

use mdrlat_core::{Action, Rng};
use mdrlat_nn::Variant;
use mdrlat_nn::burn::prelude::Device;
use mdrlat_sim::{Env, SimConfig};
use mdrlat_train::TrainConfig;
use mdrlat_world::World;

const ROOM: &str = r#"
version = 1
name = "box"
bounds = { min = [0.0, 0.0], max = [4.0, 4.0] }
obstacle = [
  { shape = "box", center = [2.0, 0.05], size = [4.0, 0.1], z = [0.0, 2.0] },
  { shape = "box", center = [2.0, 3.95], size = [4.0, 0.1], z = [0.0, 2.0] },
  { shape = "box", center = [0.05, 2.0], size = [0.1, 4.0], z = [0.0, 2.0] },
  { shape = "box", center = [3.95, 2.0], size = [0.1, 4.0], z = [0.0, 2.0] },
  { shape = "cylinder", center = [2.0, 2.0], radius = 0.3, z = [0.0, 2.0] },
]
spawn = [ { min = [0.5, 0.5], max = [3.5, 3.5] } ]
"#;

#[test]
fn a_short_laser_only_run_beats_the_random_policy() {
    let world = World::from_toml("box", ROOM).expect("world");
    let sim = SimConfig { max_episode_steps: 100, ..SimConfig::default() };
    let config = TrainConfig {
        variant: Variant::LaserOnly,
        total_steps: 2_500,
        seed: 1,
        learning_rate: 5e-4,
        learning_starts: 300,
        target_update_interval: 200,
        epsilon_start: 1.0,
        epsilon_end: 0.05,
        epsilon_decay_steps: 2_000,
        eval_interval: 2_500,
        eval_episodes: 6,
        ..TrainConfig::default()
    };
    let dir = std::env::temp_dir().join(format!("mdrlat-learns-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let (report, _) =
        train(vec![world.clone()], &sim, &config, &Device::flex(), &dir, false, |_| {})
            .expect("train");
    let trained = report.evaluations.last().expect("an evaluation").mean();
    // Where the time went: every part of the loop was timed, and the parts are shares of
    // the session (what came before the loop, set-up and the first reset, is in no part).
    // Shares only: how long anything takes is the benches' business, not a test's.
    let parts = report.timing.parts();
    assert!(parts.iter().all(|&(_, s)| s > 0.0), "{parts:?}");
    let total: f64 = parts.iter().map(|(_, s)| s).sum();
    assert!(total <= report.seconds, "{total} of {}", report.seconds);

    // The random policy from the same fixed evaluation start poses.
    let mut env = Env::from_world(world, sim).expect("env");
    let mut rng = Rng::seed_from_u64(5);
    let mut random = 0.0;
    for k in 0..u64::from(config.eval_episodes) {
        env.reset(Some(config.eval_seed + k)).expect("reset");
        loop {
            let s = env.step(Action::new(rng.below(10)).expect("action")).expect("step");
            random += s.reward;
            if s.terminated || s.truncated {
                break;
            }
        }
    }
    let random = random / config.eval_episodes as f32;
    // A 100-step episode at full speed earns at most 50; random driving collides early.
    assert!(trained > random + 15.0, "trained {trained:.2} vs random {random:.2}");
    let metrics = std::fs::read_to_string(dir.join("metrics.csv")).expect("metrics");
    assert!(metrics.starts_with(
        "step,loss_td,loss_at,q_mean,epsilon,episode_reward,episode_length,episodes\n"
    ));
    assert_eq!(metrics.lines().count(), 1 + 25);
    let _ = std::fs::remove_dir_all(&dir);
}
