//! Scripted policies: baselines and demo drivers that need no network.

use crate::env::Observation;
use crate::sensors::DepthGeometry;
use mdrlat_core::{Action, Rng, TABLE_1};

/// Anything that picks an action from an observation.
pub trait Policy {
    /// The action for `obs`.
    fn act(&mut self, obs: &Observation) -> Action;
}

/// Uniformly random actions from its own seeded stream.
#[derive(Debug, Clone)]
pub struct RandomPolicy {
    rng: Rng,
}

impl RandomPolicy {
    /// A random policy seeded with `seed`.
    pub fn new(seed: u64) -> Self {
        Self { rng: Rng::derive(seed, 0x5EED) }
    }
}

impl Policy for RandomPolicy {
    fn act(&mut self, _obs: &Observation) -> Action {
        Action::new(self.rng.below(Action::COUNT))
            .unwrap_or(Action::new(0).unwrap_or_else(|| unreachable!()))
    }
}

/// Always the same action.
#[derive(Debug, Clone, Copy)]
pub struct ConstantPolicy(pub Action);

impl Policy for ConstantPolicy {
    fn act(&mut self, _obs: &Observation) -> Action {
        self.0
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

impl Policy for WanderPolicy {
    fn act(&mut self, obs: &Observation) -> Action {
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
