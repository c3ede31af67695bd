//! The training environments and what Algorithm 1 does with them between gradient steps:
//! ε-greedy decisions for all of them at once (line 3), a step (line 4) and its transition
//! stored (line 5, as n-step returns when asked), episodes ended and begun again.
//!
//! [`TrainEnvs`] is built by the caller and handed to [`crate::train()`]: one environment or
//! several, in one world or several (an environment that ends an episode moves on to the
//! next world).

use crate::checkpoint::{self, EnvSlot, Meta, PendingStep};
use crate::config::TrainConfig;
use crate::error::TrainError;
use crate::learner::{Inputs, Learner};
use crate::policy::observation_inputs;
use crate::replay::{FrameId, ReplayBuffer, Transition};
use crate::timing::Clock;
use mdrlat_core::{Action, Decision, FRAME_STACK, ODOM_HISTORY, Policy, PolicyError, Rng};
use mdrlat_sim::config::Task;
use mdrlat_sim::{AvoidConfig, AvoidPolicy, Env, Observation, SimConfig, StaticScene};
use mdrlat_world::World;
use std::collections::VecDeque;
use std::path::Path;
use std::sync::Arc;

/// One training environment and where it is: its world, its episode so far and the replay
/// frames of its observation's stack.
struct Slot {
    env: Env,
    world: usize,
    episode_reward: f32,
    episode_length: u32,
    stack: [FrameId; FRAME_STACK],
    /// Steps whose n-step transitions wait for the steps after them.
    pending: VecDeque<PendingStep>,
}

/// The environments a run trains in.
pub struct TrainEnvs {
    scenes: Vec<Arc<StaticScene>>,
    sim: SimConfig,
    slots: Vec<Slot>,
}

/// An episode that ended: its accumulated reward and length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Finished {
    /// Accumulated reward.
    pub reward: f32,
    /// Steps.
    pub length: u32,
}

impl TrainEnvs {
    /// `count` environments over `worlds` (environment k starts in world k mod their
    /// number), not yet started.
    ///
    /// # Errors
    /// No world, no environment, or a world the simulator cannot build.
    pub fn new(worlds: Vec<World>, sim: &SimConfig, count: usize) -> Result<Self, TrainError> {
        if worlds.is_empty() {
            return Err(TrainError::NoWorld);
        }
        let scenes: Vec<Arc<StaticScene>> =
            worlds.into_iter().map(|w| Arc::new(StaticScene::new(Arc::new(w), sim))).collect();
        let mut slots = Vec::with_capacity(count);
        for k in 0..count {
            let world = k % scenes.len();
            slots.push(Slot {
                env: Env::new(scenes[world].clone(), sim.clone())?,
                world,
                episode_reward: 0.0,
                episode_length: 0,
                stack: [FrameId::default(); FRAME_STACK],
                pending: VecDeque::new(),
            });
        }
        Ok(TrainEnvs { scenes, sim: sim.clone(), slots })
    }

    /// The simulator's settings every environment runs with.
    pub fn sim(&self) -> &SimConfig {
        &self.sim
    }

    /// How many environments.
    pub fn len(&self) -> usize {
        self.slots.len()
    }
    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }
    /// The first world's scene: Fig. 4's evaluations and the learning curves' held-out
    /// starts are there.
    pub fn first_scene(&self) -> &Arc<StaticScene> {
        &self.scenes[0]
    }

    /// A new run's start: environment k's episodes from stream k of `seed`, each first
    /// observation's frames stored.
    pub(crate) fn start(&mut self, seed: u64, replay: &mut ReplayBuffer) -> Result<(), TrainError> {
        for (k, slot) in self.slots.iter_mut().enumerate() {
            slot.env.reset_stream(seed, k as u64)?;
            let first = push_latest(replay, slot.env.observation());
            slot.stack = [first; FRAME_STACK];
        }
        Ok(())
    }

    /// Every environment as the checkpoint `meta` (read from `meta_path`) left it.
    pub(crate) fn restore(&mut self, meta: &Meta, meta_path: &Path) -> Result<(), TrainError> {
        let first = EnvSlot {
            world: meta.world,
            episode_reward: meta.episode_reward,
            episode_length: meta.episode_length,
            stack: meta.stack,
            env: meta.env.clone(),
            pending: meta.pending.clone(),
        };
        // As many as the run has: `checkpoint::load` checked the count against `train.envs`.
        let saved = std::iter::once(&first).chain(&meta.more_envs);
        for (slot, saved) in self.slots.iter_mut().zip(saved) {
            let scene = self.scenes.get(saved.world).ok_or_else(|| TrainError::Checkpoint {
                path: meta_path.to_path_buf(),
                problem: format!(
                    "names training world {}; the run has {}",
                    saved.world,
                    self.scenes.len()
                ),
            })?;
            if saved.world != slot.world {
                slot.env = Env::new(scene.clone(), self.sim.clone())?;
            }
            slot.env.restore(&saved.env)?;
            slot.world = saved.world;
            (slot.episode_reward, slot.episode_length) =
                (saved.episode_reward, saved.episode_length);
            slot.stack = saved.stack;
            slot.pending = saved.pending.iter().copied().collect();
        }
        Ok(())
    }

    /// A new run's checkpoint record at step 0: its random streams from `config.seed`, the
    /// environments as they start.
    pub(crate) fn fresh_meta(&self, config: &TrainConfig, task: Task) -> Meta {
        let mut meta = Meta {
            format: checkpoint::CHECKPOINT_FORMAT,
            mdrlat_version: env!("CARGO_PKG_VERSION").to_string(),
            variant: config.variant,
            task,
            depth_memory_frames: self.sim().laser.depth_memory_frames,
            step: 0,
            updates: 0,
            episodes: 0,
            episode_reward: 0.0,
            episode_length: 0,
            stack: [FrameId::default(); FRAME_STACK],
            explore_rng: Rng::derive(config.seed, 101),
            sample_rng: Rng::derive(config.seed, 102),
            window: checkpoint::Window::default(),
            env: self.slots[0].env.state(),
            pending: Vec::new(),
            world: 0,
            more_envs: Vec::new(),
            priorities: None,
            replay_bytes: 0,
            replay_checksum: 0,
        };
        self.save_into(&mut meta);
        meta
    }

    /// Every environment's state into the checkpoint's `meta`.
    pub(crate) fn save_into(&self, meta: &mut Meta) {
        let [first, rest @ ..] = self.slots.as_slice() else { unreachable!("train.envs >= 1") };
        (meta.env, meta.world, meta.stack) = (first.env.state(), first.world, first.stack);
        meta.pending = first.pending.iter().copied().collect();
        (meta.episode_reward, meta.episode_length) = (first.episode_reward, first.episode_length);
        meta.more_envs = rest
            .iter()
            .map(|s| checkpoint::EnvSlot {
                world: s.world,
                episode_reward: s.episode_reward,
                episode_length: s.episode_length,
                stack: s.stack,
                env: s.env.state(),
                pending: s.pending.iter().copied().collect(),
            })
            .collect();
    }

    /// Lines 4–5 for environment `k`: execute `action`, observe r and s', store the
    /// transition (s, a, r, s') — s' the true final observation at an episode's end, terminal
    /// only after a collision or the goal; with n-step returns (s, a, Σ γ^i r_i, s_{+n}) once
    /// the n-th step is done, and every waiting step at an episode's end. An episode that
    /// ended begins again, in the next world when there are several.
    pub(crate) fn step(
        &mut self,
        k: usize,
        action: usize,
        replay: &mut ReplayBuffer,
        config: &TrainConfig,
        clock: &mut Clock,
    ) -> Result<Option<Finished>, TrainError> {
        let n_step = config.n_step as usize;
        let slot = &mut self.slots[k];
        let (odom, goal) = (odom_of(slot.env.observation()), goal_of(slot.env.observation()));
        let a = Action::new(action).unwrap_or_else(|| unreachable!("action index < 10"));
        let s = slot.env.step(a)?;
        clock.split(|t| &mut t.env);
        let (reward, terminated, done) = (s.reward, s.terminated, s.terminated || s.truncated);
        let newest = push_latest(replay, s.observation);
        let stack = slot.stack;
        let next = [stack[1], stack[2], stack[3], newest];
        let next_goal = goal_of(s.observation);
        let step = PendingStep { obs: stack, action: action as u8, reward, odom, goal };
        slot.pending.push_back(step);
        let ready = if done { slot.pending.len() } else { slot.pending.len() / n_step };
        for _ in 0..ready {
            let steps = slot.pending.len();
            let ret = slot
                .pending
                .iter()
                .rev()
                .map(|p| p.reward)
                .reduce(|later, r| r + config.gamma * later);
            let Some(first) = slot.pending.pop_front() else { break };
            replay.push(Transition {
                obs: first.obs,
                next,
                action: first.action,
                reward: ret.unwrap_or(first.reward),
                terminated,
                steps: steps as u8,
                odom: first.odom,
                goal: first.goal,
                next_goal,
            });
        }
        slot.episode_reward += reward;
        slot.episode_length += 1;
        if !done {
            slot.stack = next;
            return Ok(None);
        }
        let finished = Finished { reward: slot.episode_reward, length: slot.episode_length };
        (slot.episode_reward, slot.episode_length) = (0.0, 0);
        if self.scenes.len() > 1 {
            // The next world, keeping the environment's random streams.
            slot.world = (slot.world + 1) % self.scenes.len();
            slot.env.move_to(self.scenes[slot.world].clone())?;
        } else {
            slot.env.reset(None)?;
        }
        let first = push_latest(replay, slot.env.observation());
        slot.stack = [first; FRAME_STACK];
        Ok(Some(finished))
    }

    fn observations(&self) -> Vec<&Observation> {
        self.slots.iter().map(|s| s.env.observation()).collect()
    }
}

/// Line 3, ε-greedy for every environment: the greedy decisions in one forward pass; during
/// the first `train.demo_steps` an exploratory action may be the demonstrator's (`avoid`,
/// watching every environment).
pub(crate) struct Explorer {
    demonstrator: Option<AvoidPolicy>,
    demo_actions: Vec<Decision>,
    all_envs: Vec<usize>,
    greedy_envs: Vec<usize>,
    inputs: Inputs,
    /// The chosen action of each environment.
    pub(crate) actions: Vec<usize>,
}

impl Explorer {
    /// For `envs` environments of a run at `step` (the demonstrator only while it acts).
    pub(crate) fn new(
        sim: &SimConfig,
        config: &TrainConfig,
        envs: usize,
        step: u64,
    ) -> Result<Self, TrainError> {
        let demonstrator = if step < config.demo_steps {
            let avoid = AvoidPolicy::new(sim, AvoidConfig::default())
                .map_err(|e| TrainError::Policy { step, source: PolicyError::Backend(e) })?;
            Some(avoid)
        } else {
            None
        };
        Ok(Explorer {
            demonstrator,
            demo_actions: Vec::with_capacity(envs),
            all_envs: (0..envs).collect(),
            greedy_envs: Vec::with_capacity(envs),
            inputs: Inputs::default(),
            actions: vec![0; envs],
        })
    }

    /// Chooses [`Explorer::actions`] for the environments' current observations at `step`
    /// (environment k's decision is step `step + k + 1`'s).
    pub(crate) fn choose(
        &mut self,
        envs: &TrainEnvs,
        learner: &Learner,
        config: &TrainConfig,
        step: u64,
        rng: &mut Rng,
    ) -> Result<(), TrainError> {
        self.greedy_envs.clear();
        self.demo_actions.clear();
        if step >= config.demo_steps {
            self.demonstrator = None;
        }
        if let Some(demo) = self.demonstrator.as_mut() {
            demo.decide(&envs.observations(), &self.all_envs, &mut self.demo_actions)
                .map_err(|source| TrainError::Policy { step: step + 1, source })?;
        }
        for (k, action) in self.actions.iter_mut().enumerate() {
            let epsilon = config.epsilon(step + k as u64);
            if rng.uniform() < f64::from(epsilon) {
                *action = match self.demo_actions.get(k) {
                    Some(d) if rng.uniform() < f64::from(config.demo_share) => d.action.index(),
                    _ => rng.below(Action::COUNT),
                };
            } else {
                self.greedy_envs.push(k);
            }
        }
        if !self.greedy_envs.is_empty() {
            let at = step + 1 + self.greedy_envs[0] as u64;
            let observations: Vec<&Observation> =
                self.greedy_envs.iter().map(|&k| envs.slots[k].env.observation()).collect();
            observation_inputs(&observations, learner.net_config(), &mut self.inputs)
                .map_err(|source| TrainError::Policy { step: at, source })?;
            let greedy = learner
                .greedy(&self.inputs)
                .map_err(|source| TrainError::Policy { step: at, source })?;
            for (&k, a) in self.greedy_envs.iter().zip(&greedy) {
                self.actions[k] = a.index();
            }
        }
        Ok(())
    }

    /// Environment `k` begins a new episode: the demonstrator forgets its last one.
    pub(crate) fn episode_ended(&mut self, k: usize) {
        if let Some(demo) = self.demonstrator.as_mut() {
            demo.begin_episode(k, None);
        }
    }
}

fn push_latest(replay: &mut ReplayBuffer, obs: &Observation) -> FrameId {
    replay.push_frame(obs.laser.latest(), obs.depth.latest())
}

/// The odometry history of an observation, as the replay buffer stores it.
fn odom_of(obs: &Observation) -> [f32; 2 * ODOM_HISTORY] {
    let mut o = [0.0; 2 * ODOM_HISTORY];
    for (k, v) in obs.odom.iter().enumerate() {
        o[2 * k] = v.v;
        o[2 * k + 1] = v.w;
    }
    o
}

/// The goal of an observation in the robot frame, stored with each transition (navigation;
/// zeros in obstacle avoidance, where the buffer does not keep it).
fn goal_of(obs: &Observation) -> [f32; 3] {
    obs.goal.unwrap_or_default()
}
