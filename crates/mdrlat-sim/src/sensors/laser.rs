//! The 2D laser range finder: 512 beams over the field of view at one height.

use crate::config::LaserConfig;
use crate::scene::StaticScene;
use mdrlat_core::{LASER_BEAMS, Rng};
use mdrlat_geom::{Aabb, Fan, FanHits, GridScratch, Pose2, Prism};

/// A simulated 2D laser. Beam `i` points at `−fov/2 + i·fov/511` from the heading
/// (counter-clockwise positive); ranges are metres, `max_range_m` when nothing is hit.
#[derive(Debug, Clone)]
pub struct Laser {
    cfg: LaserConfig,
    fan: Fan,
    hits: FanHits,
    best: Vec<f32>,
    candidates: Vec<u32>,
    scratch: GridScratch,
}

impl Laser {
    /// A laser with the given settings.
    pub fn new(cfg: &LaserConfig) -> Self {
        let fov = cfg.fov_deg.to_radians();
        let n = LASER_BEAMS;
        let angles = (0..n).map(|i| -fov / 2.0 + fov * i as f32 / (n - 1) as f32).collect();
        Self {
            cfg: cfg.clone(),
            fan: Fan::new(angles),
            hits: FanHits::with_len(n),
            best: vec![0.0; n],
            candidates: Vec::new(),
            scratch: GridScratch::default(),
        }
    }

    /// Beam angles in the robot frame, radians.
    pub fn angles(&self) -> &[f32] {
        self.fan.angles()
    }

    /// The settings.
    pub fn config(&self) -> &LaserConfig {
        &self.cfg
    }

    /// Scans from `pose` into `out` (512 ranges, metres). `dynamic` holds the moving
    /// obstacles; `rng` draws the noise, and is untouched when noise is off.
    pub fn scan(
        &mut self,
        scene: &StaticScene,
        dynamic: &[Prism],
        pose: &Pose2,
        rng: &mut Rng,
        out: &mut [f32],
    ) {
        let max = self.cfg.max_range_m;
        self.best.fill(f32::INFINITY);
        let area = Aabb::around(pose.position(), max);
        let mut candidates = std::mem::take(&mut self.candidates);
        scene.laser.query(&area, &mut self.scratch, &mut candidates);
        for &i in &candidates {
            self.cast(&scene.prisms[i as usize], pose);
        }
        self.candidates = candidates;
        let height = self.cfg.height_m;
        for p in dynamic.iter().filter(|p| p.spans_height(height)) {
            self.cast(p, pose);
        }
        let sigma = self.cfg.noise_std_m;
        for (o, &b) in out.iter_mut().zip(&self.best) {
            *o = if b < max {
                if sigma > 0.0 { (b + sigma * rng.normal()).clamp(0.0, max) } else { b }
            } else {
                max
            };
        }
    }

    fn cast(&mut self, prism: &Prism, pose: &Pose2) {
        let pos = pose.position();
        if prism.shape.distance_to_point(pos) >= self.cfg.max_range_m {
            return;
        }
        let ranges = self.fan.ranges(prism.shape.angular_extent(pos), pose.yaw);
        if ranges.iter().all(|r| r.is_empty()) {
            return;
        }
        let prepared = prism.shape.prepare(pose);
        for range in ranges.into_iter().filter(|r| !r.is_empty()) {
            prepared.cast(&self.fan, range.clone(), &mut self.hits);
            let (t_in, t_out) = (&self.hits.t_in[range.clone()], &self.hits.t_out[range.clone()]);
            for ((b, &a), &e) in self.best[range].iter_mut().zip(t_in).zip(t_out) {
                let t = if a > 0.0 { a } else { 0.0 };
                *b = if a <= e && e >= 0.0 && t < *b { t } else { *b };
            }
        }
    }
}
