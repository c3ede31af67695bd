//! The mdrlat simulator: an indoor mobile robot with a 2D laser and a depth camera in 2.5D
//! worlds, fast and headless (SPEC §2; replaces Gazebo).
//!
//! Data flow: a [`World`](mdrlat_world::World) is indexed once into a [`StaticScene`];
//! an [`Env`] owns the moving state (robot, pedestrians), the sensors and the frame stacks;
//! a [`VecEnv`] steps many of them in parallel with auto-reset. The API follows Gymnasium:
//! `reset(seed)` is the only way to seed, and `step` reports `terminated` (collision) and
//! `truncated` (time limit) separately.

pub mod avoid;
pub mod bench;
pub mod bridge;
pub mod config;
pub mod env;
pub mod episodes;
pub mod pedestrians;
pub mod policy;
pub mod reward;
pub mod robot;
pub mod rollout;
pub mod scene;
pub mod sensors;
pub mod vec_env;

pub use avoid::{AvoidConfig, AvoidPolicy};
pub use config::SimConfig;
pub use env::{Collision, Env, EnvState, Observation, SimError, Step, StepInfo};
pub use episodes::{
    EpisodeOutcome, EpisodeSpec, MovingRule, Observer, Quiet, RunError, RunOptions,
    episode_success, moving_success, run_episodes,
};
pub use mdrlat_core::{Decision, Policy, PolicyError, Sensors};
pub use policy::{ConstantPolicy, RandomPolicy, ReplayPolicy, Scripted, WanderPolicy};
pub use scene::StaticScene;
pub use vec_env::{EnvRef, SlotWriter, VecEnv, VecStep};
