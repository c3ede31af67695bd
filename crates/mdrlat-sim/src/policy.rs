//! Scripted policies: baselines and demo drivers that need no network. They implement the
//! one [`Policy`] interface of `mdrlat-core`, like a trained network does.

use crate::config::SimConfig;
use crate::env::Observation;
use crate::sensors::{DepthCamera, DepthGeometry, Laser};
use mdrlat_core::{
    Action, Decision, Policy, PolicyError, Rng, Sensors, TABLE_1, Velocity, decide_each,
};

/// The scripted policies by name (`mdrlat rollout --policy`, `mdrlat eval --policy`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scripted {
    /// Uniformly random actions (seeded per episode).
    Random,
    /// Always straight ahead at 0.5 m/s (action 1).
    Forward,
    /// The reactive wanderer on the laser and the depth camera: heads for the most open way.
    Wander,
    /// The same wanderer with the laser only: blind to low boxes and overhangs.
    WanderLaser,
    /// A sanity check: turns in place for ever (the first Table 1 action with no forward
    /// speed). It never collides in a static world, so the paper's success counts it; it
    /// never drives, so the moving success does not.
    Spin,
    /// A sanity check: the tightest forward circle of Table 1 (the action with the smallest
    /// turning radius v/|ω|: 0.2 m/s at π/6 rad/s, a circle 0.76 m across). It drives 12 m in
    /// 300 steps but never gets 2 m from its start: the moving success's reach rule is
    /// what rejects it.
    Circle,
    /// The classical avoider ([`crate::AvoidPolicy`]): a dynamic-window controller over the
    /// ten actions on a local costmap of both sensors carried by odometry, with the walkers'
    /// motion from consecutive scans. The baseline that says how achievable a world is.
    Avoid,
    /// The same avoider with the laser alone: what a policy that reads only the laser can
    /// achieve in a world (the yardstick of the laser-only networks).
    AvoidLaser,
    /// The same avoider remembering only what a network's observation holds: costmap cells
    /// seen in the last four frames (the frame stack), nothing older. Against `avoid`, what
    /// the memory is worth in a world, so what a reactive policy can be asked for there.
    AvoidStack,
    /// The same avoider remembering the cells seen in its last N frames (`avoid-memory-N`,
    /// N from 1 to [`Scripted::MAX_MEMORY_FRAMES`]; `avoid-stack` is N = 4): success against
    /// N says how much memory a world asks of a reactive policy.
    AvoidMemory(u16),
}

impl Scripted {
    /// Every scripted policy, in the order of [`Scripted::name`]s listed in errors.
    pub const ALL: [Scripted; 9] = [
        Scripted::Random,
        Scripted::Forward,
        Scripted::Wander,
        Scripted::WanderLaser,
        Scripted::Spin,
        Scripted::Circle,
        Scripted::Avoid,
        Scripted::AvoidLaser,
        Scripted::AvoidStack,
    ];

    /// The most frames `avoid-memory-N` remembers (the avoider's own default memory, 101
    /// frames, is `avoid`).
    pub const MAX_MEMORY_FRAMES: u16 = 1000;

    /// The name used on the command line and in reports.
    pub fn name(self) -> String {
        match self {
            Scripted::AvoidMemory(frames) => format!("avoid-memory-{frames}"),
            fixed => fixed.fixed_name().to_string(),
        }
    }

    /// The name of a policy without a parameter (`avoid-memory-N`: its family's).
    fn fixed_name(self) -> &'static str {
        match self {
            Scripted::Random => "random",
            Scripted::Forward => "forward",
            Scripted::Wander => "wander",
            Scripted::WanderLaser => "wander-laser",
            Scripted::Spin => "spin",
            Scripted::Circle => "circle",
            Scripted::Avoid => "avoid",
            Scripted::AvoidLaser => "avoid-laser",
            Scripted::AvoidStack => "avoid-stack",
            Scripted::AvoidMemory(_) => "avoid-memory-N",
        }
    }

    /// The action of a policy that always takes the same one (`forward`, `spin`, `circle`),
    /// found in Table 1 by what it does, not by its index.
    pub fn constant_action(self) -> Option<Action> {
        // The action minimising `key` among those `keep` accepts.
        let best = |keep: fn(&Velocity) -> bool, key: fn(&Velocity) -> f32| {
            Action::all()
                .filter(|a| keep(&a.command()))
                .min_by(|a, b| key(&a.command()).total_cmp(&key(&b.command())))
        };
        match self {
            Scripted::Forward => best(|c| c.w == 0.0, |c| -c.v),
            Scripted::Spin => best(|c| c.v == 0.0 && c.w != 0.0, |c| -c.w.abs()),
            Scripted::Circle => best(|c| c.v > 0.0 && c.w != 0.0, |c| c.v / c.w.abs()),
            Scripted::Random
            | Scripted::Wander
            | Scripted::WanderLaser
            | Scripted::Avoid
            | Scripted::AvoidLaser
            | Scripted::AvoidStack
            | Scripted::AvoidMemory(_) => None,
        }
    }

    /// The policy for environments with `config`'s sensors; `seed` seeds the random
    /// policy's stream until an episode gives it its own seed.
    pub fn build(self, config: &SimConfig, seed: u64) -> Box<dyn Policy> {
        let laser = Laser::new(&config.laser);
        if let Some(action) = self.constant_action() {
            return Box::new(ConstantPolicy::named(action, self.fixed_name()));
        }
        match self {
            Scripted::Random => Box::new(RandomPolicy::new(seed)),
            Scripted::Forward | Scripted::Spin | Scripted::Circle => {
                unreachable!("constant actions are built above")
            }
            Scripted::Wander => Box::new(WanderPolicy::with_depth(
                laser.angles(),
                DepthCamera::new(&config.depth).geometry(),
                config.robot.body_height_m,
            )),
            Scripted::WanderLaser => Box::new(WanderPolicy::new(laser.angles())),
            Scripted::Avoid
            | Scripted::AvoidLaser
            | Scripted::AvoidStack
            | Scripted::AvoidMemory(_) => {
                let memory_steps = match self {
                    Scripted::AvoidStack => crate::AvoidConfig::STACK_MEMORY_STEPS,
                    // Frames remembered: the newest and the N − 1 before it.
                    Scripted::AvoidMemory(frames) => u32::from(frames.max(1)) - 1,
                    _ => crate::AvoidConfig::default().memory_steps,
                };
                let settings = crate::AvoidConfig {
                    depth: self != Scripted::AvoidLaser,
                    memory_steps,
                    ..Default::default()
                };
                Box::new(
                    crate::AvoidPolicy::new(config, settings)
                        .unwrap_or_else(|e| unreachable!("the default settings are valid: {e}")),
                )
            }
        }
    }
}

impl std::str::FromStr for Scripted {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if let Some(n) = s.strip_prefix("avoid-memory-") {
            return match n.parse::<u16>() {
                Ok(frames) if (1..=Scripted::MAX_MEMORY_FRAMES).contains(&frames) => {
                    Ok(Scripted::AvoidMemory(frames))
                }
                _ => Err(format!(
                    "policy '{s}': avoid-memory-N remembers the last N frames, N from 1 to {}",
                    Scripted::MAX_MEMORY_FRAMES
                )),
            };
        }
        Scripted::ALL.into_iter().find(|p| p.fixed_name() == s).ok_or_else(|| {
            let mut names: Vec<&str> = Scripted::ALL.iter().map(|p| p.fixed_name()).collect();
            names.push("avoid-memory-N");
            format!("unknown policy '{s}' (scripted policies: {})", names.join(", "))
        })
    }
}

/// Uniformly random actions. Each slot draws from its own stream, restarted from the
/// episode's seed at [`Policy::begin_episode`], so an episode's actions are a function of
/// that episode alone.
#[derive(Debug, Clone)]
pub struct RandomPolicy {
    seed: u64,
    streams: Vec<Rng>,
}

/// The random policy's stream of an episode seeded `seed`.
fn random_stream(seed: u64) -> Rng {
    Rng::derive(seed, 0x5EED)
}

impl RandomPolicy {
    /// A random policy; slots that start without an episode seed draw from streams of `seed`.
    pub fn new(seed: u64) -> Self {
        Self { seed, streams: Vec::new() }
    }

    fn stream(&mut self, slot: usize) -> &mut Rng {
        while self.streams.len() <= slot {
            let k = self.streams.len() as u64;
            self.streams.push(if k == 0 {
                random_stream(self.seed)
            } else {
                Rng::derive(self.seed, 0x5EED + k)
            });
        }
        &mut self.streams[slot]
    }
}

impl Policy for RandomPolicy {
    fn name(&self) -> String {
        "random".into()
    }
    fn sensors(&self) -> Sensors {
        Sensors::NONE
    }
    fn begin_episode(&mut self, slot: usize, seed: Option<u64>) {
        let stream = self.stream(slot);
        if let Some(seed) = seed {
            *stream = random_stream(seed);
        }
    }
    fn decide(
        &mut self,
        batch: &[&Observation],
        slots: &[usize],
        out: &mut Vec<Decision>,
    ) -> Result<(), PolicyError> {
        decide_each(batch, slots, out, |slot, _| {
            let a = self.stream(slot).below(Action::COUNT);
            Ok(Action::new(a).unwrap_or_else(|| unreachable!("below(COUNT)")))
        })
    }
}

/// Always the same action.
#[derive(Debug, Clone, Copy)]
pub struct ConstantPolicy {
    /// The action.
    pub action: Action,
    name: Option<&'static str>,
}

impl ConstantPolicy {
    /// Always `action`, named `constant action N`.
    pub fn new(action: Action) -> Self {
        Self { action, name: None }
    }

    /// Always `action`, under a name of its own (`spin`, `circle`).
    pub fn named(action: Action, name: &'static str) -> Self {
        Self { action, name: Some(name) }
    }
}

impl Policy for ConstantPolicy {
    fn name(&self) -> String {
        self.name.map_or_else(|| format!("constant action {}", self.action), str::to_string)
    }
    fn sensors(&self) -> Sensors {
        Sensors::NONE
    }
    fn decide(
        &mut self,
        batch: &[&Observation],
        slots: &[usize],
        out: &mut Vec<Decision>,
    ) -> Result<(), PolicyError> {
        decide_each(batch, slots, out, |_, _| Ok(self.action))
    }
}

/// Replays recorded actions (and velocity commands), one list per slot: with the same
/// episode seed an environment is a function of its commands, so this reproduces an
/// episode exactly (for pictures of an episode run in a batch). Past the end of its list a
/// slot repeats its last step.
#[derive(Debug, Clone, Default)]
pub struct ReplayPolicy {
    actions: Vec<Vec<Action>>,
    commands: Vec<Vec<Velocity>>,
    at: Vec<usize>,
}

impl ReplayPolicy {
    /// Slot `i` plays `actions[i]` (at their Table 1 velocities).
    pub fn new(actions: Vec<Vec<Action>>) -> Self {
        let commands = actions.iter().map(|l| l.iter().map(|a| a.command()).collect()).collect();
        Self::with_commands(actions, commands)
    }

    /// Slot `i` plays `actions[i]` as the velocities `commands[i]` (a continuous
    /// controller's episode: its actions are only the nearest Table 1 ones).
    pub fn with_commands(actions: Vec<Vec<Action>>, commands: Vec<Vec<Velocity>>) -> Self {
        let at = vec![0; actions.len()];
        Self { actions, commands, at }
    }
}

impl Policy for ReplayPolicy {
    fn name(&self) -> String {
        "replay".into()
    }
    fn sensors(&self) -> Sensors {
        Sensors::NONE
    }
    fn begin_episode(&mut self, slot: usize, _seed: Option<u64>) {
        if let Some(at) = self.at.get_mut(slot) {
            *at = 0;
        }
    }
    fn decide(
        &mut self,
        batch: &[&Observation],
        slots: &[usize],
        out: &mut Vec<Decision>,
    ) -> Result<(), PolicyError> {
        decide_each(batch, slots, out, |slot, _| {
            let (Some(list), Some(vels)) = (self.actions.get(slot), self.commands.get(slot)) else {
                return Err(PolicyError::Backend(format!("no recorded actions for slot {slot}")));
            };
            if list.is_empty() || vels.len() != list.len() {
                return Err(PolicyError::Backend(format!(
                    "slot {slot}: {} recorded actions and {} commands",
                    list.len(),
                    vels.len()
                )));
            }
            let at = &mut self.at[slot];
            let i = (*at).min(list.len() - 1);
            *at += 1;
            Ok(Decision { action: list[i], command: vels[i] })
        })
    }
}

/// A reactive wanderer: drives towards the direction with the most clearance, slowing
/// down and turning in place when obstacles are close. With only the laser it is blind to
/// what lies under or over the laser plane; given the depth camera's geometry it also reads
/// obstacles from the depth image (heights between 3 cm and the body height). A scripted
/// baseline, and the demo's driver before any training.
#[derive(Debug, Clone)]
pub struct WanderPolicy {
    /// Ray angles: laser beams, then depth columns when fused (robot frame, radians).
    angles: Vec<f32>,
    depth: Option<(DepthGeometry, f32)>,
    ranges: Vec<f32>,
}

impl WanderPolicy {
    /// A laser-only wanderer for a laser with these beam angles.
    pub fn new(beam_angles: &[f32]) -> Self {
        Self { angles: beam_angles.to_vec(), depth: None, ranges: Vec::new() }
    }

    /// A wanderer that also avoids obstacles seen only by the depth camera, up to
    /// `body_height_m`.
    pub fn with_depth(beam_angles: &[f32], depth: DepthGeometry, body_height_m: f32) -> Self {
        let mut angles = beam_angles.to_vec();
        angles.extend_from_slice(&depth.column_angles);
        Self { angles, depth: Some((depth, body_height_m)), ranges: Vec::new() }
    }

    /// Smallest range within `half_width` radians of direction `dir`.
    fn clearance(&self, dir: f32, half_width: f32) -> f32 {
        self.angles
            .iter()
            .zip(&self.ranges)
            .filter(|(a, _)| (**a - dir).abs() <= half_width)
            .map(|(_, r)| *r)
            .fold(f32::INFINITY, f32::min)
    }
}

impl WanderPolicy {
    /// The wanderer's action for one observation.
    fn choose(&mut self, obs: &Observation) -> Action {
        self.ranges.clear();
        self.ranges.extend_from_slice(obs.laser.latest());
        if let Some((geometry, body)) = &self.depth {
            let n = geometry.column_angles.len();
            let start = self.ranges.len();
            self.ranges.resize(start + n, f32::INFINITY);
            geometry.obstacle_ranges(obs.depth.latest(), 0.03, *body, &mut self.ranges[start..]);
        }
        let mut best = (f32::NEG_INFINITY, 8usize);
        for a in Action::all() {
            let c = TABLE_1[a.index()];
            // Where this command heads over the next second.
            let clear = self.clearance(c.w, 0.35);
            let need = 0.45 + 1.2 * c.v;
            let score = if clear > need {
                c.v * 4.0 + clear.min(3.0) * 0.5 - c.w.abs() * 0.3
            } else {
                clear - 10.0
            };
            if score > best.0 {
                best = (score, a.index());
            }
        }
        Action::new(best.1).unwrap_or_else(|| unreachable!("index from Action::all"))
    }
}

impl Policy for WanderPolicy {
    fn name(&self) -> String {
        if self.depth.is_some() { "wander".into() } else { "wander-laser".into() }
    }
    fn sensors(&self) -> Sensors {
        Sensors { laser: true, depth: self.depth.is_some() }
    }
    fn decide(
        &mut self,
        batch: &[&Observation],
        slots: &[usize],
        out: &mut Vec<Decision>,
    ) -> Result<(), PolicyError> {
        decide_each(batch, slots, out, |_, obs| Ok(self.choose(obs)))
    }
}
