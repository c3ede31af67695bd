//! The depth camera: a zero-pitch pinhole producing a 128 x 160 z-depth image.

use crate::config::DepthConfig;
use crate::scene::StaticScene;
use mdrlat_core::{DEPTH_COLS, DEPTH_ROWS, Rng};
use mdrlat_geom::{Aabb, Fan, FanHits, GridScratch, Pose2, Prism};

/// A simulated Kinect-like depth camera at the robot's centre.
///
/// Pixel `(r, c)` has its centre at `(c + 0.5, r + 0.5)`; row 0 is the top, column 0 the
/// robot's left. Values are z-depth (along the optical axis) in metres; reads closer than
/// `min_range_m` or with no return within `max_range_m` are 0, as the Kinect reports them.
///
/// Every pixel of a column shares one ground-plane ray. For column `c` with normalised
/// image coordinate `x_c` the ray's ground distance is `s = z·k_c`, `k_c = sqrt(1 + x_c²)`,
/// and row `r` with `y_r` (down positive) is at height `h − y_r·z`. A prism hit over ground
/// distances `[s_in, s_out]` with heights `[z_min, z_max]` is seen by row `r` at the
/// smallest `z` in `[s_in, s_out]/k_c` with `h − z_max <= y_r·z <= h − z_min`: side faces,
/// tops and undersides all come out of that one interval intersection.
#[derive(Debug, Clone)]
pub struct DepthCamera {
    cfg: DepthConfig,
    /// Column rays sorted by angle: fan index `j` is column `DEPTH_COLS − 1 − j`.
    fan: Fan,
    /// `1 / k` per fan index: ground distance → z-depth.
    inv_k: Vec<f32>,
    /// `1 / y_r` per row.
    inv_y: [f32; DEPTH_ROWS],
    /// z-depth of the floor per row (infinite above the horizon).
    floor: [f32; DEPTH_ROWS],
    /// Nearest z per (fan index, row), column-major.
    zbuf: Vec<f32>,
    hits: FanHits,
    candidates: Vec<u32>,
    scratch: GridScratch,
}

impl DepthCamera {
    /// A camera with the given settings.
    pub fn new(cfg: &DepthConfig) -> Self {
        let fx = (DEPTH_COLS as f32 / 2.0) / (cfg.hfov_deg.to_radians() / 2.0).tan();
        let fy = (DEPTH_ROWS as f32 / 2.0) / (cfg.vfov_deg.to_radians() / 2.0).tan();
        // Fan index j = column DEPTH_COLS-1-j, so angles ascend with j.
        let xs: Vec<f32> = (0..DEPTH_COLS)
            .map(|j| {
                let c = DEPTH_COLS - 1 - j;
                (c as f32 + 0.5 - DEPTH_COLS as f32 / 2.0) / fx
            })
            .collect();
        let angles = xs.iter().map(|x| (-x).atan()).collect();
        let inv_k = xs.iter().map(|x| 1.0 / (1.0 + x * x).sqrt()).collect();
        let mut inv_y = [0.0; DEPTH_ROWS];
        let mut floor = [f32::INFINITY; DEPTH_ROWS];
        for r in 0..DEPTH_ROWS {
            let y = (r as f32 + 0.5 - DEPTH_ROWS as f32 / 2.0) / fy;
            inv_y[r] = 1.0 / y;
            if y > 0.0 {
                floor[r] = cfg.height_m / y;
            }
        }
        Self {
            cfg: cfg.clone(),
            fan: Fan::new(angles),
            inv_k,
            inv_y,
            floor,
            zbuf: vec![0.0; DEPTH_COLS * DEPTH_ROWS],
            hits: FanHits::with_len(DEPTH_COLS),
            candidates: Vec::new(),
            scratch: GridScratch::default(),
        }
    }

    /// The settings.
    pub fn config(&self) -> &DepthConfig {
        &self.cfg
    }

    /// Ground-plane angle of each column's ray in the robot frame, column 0 first.
    pub fn column_angles(&self) -> Vec<f32> {
        self.fan.angles().iter().rev().copied().collect()
    }

    /// Captures a frame from `pose` into `out` (128 x 160, row-major, metres).
    pub fn capture(
        &mut self,
        scene: &StaticScene,
        dynamic: &[Prism],
        pose: &Pose2,
        rng: &mut Rng,
        out: &mut [f32],
    ) {
        for col in self.zbuf.chunks_exact_mut(DEPTH_ROWS) {
            col.copy_from_slice(&self.floor);
        }
        // Farthest ground distance a visible pixel can have.
        let reach = self.cfg.max_range_m / self.inv_k.iter().fold(1.0f32, |m, &k| m.min(k));
        let area = Aabb::around(pose.position(), reach);
        let mut candidates = std::mem::take(&mut self.candidates);
        scene.all.query(&area, &mut self.scratch, &mut candidates);
        for &i in &candidates {
            self.cast(&scene.prisms[i as usize], pose, reach);
        }
        self.candidates = candidates;
        for p in dynamic {
            self.cast(p, pose, reach);
        }
        self.write_image(rng, out);
    }

    fn cast(&mut self, prism: &Prism, pose: &Pose2, reach: f32) {
        let pos = pose.position();
        if prism.shape.distance_to_point(pos) >= reach {
            return;
        }
        let ranges = self.fan.ranges(prism.shape.angular_extent(pos), pose.yaw);
        if ranges.iter().all(|r| r.is_empty()) {
            return;
        }
        let prepared = prism.shape.prepare(pose);
        let a = self.cfg.height_m - prism.z_max;
        let b = self.cfg.height_m - prism.z_min;
        for range in ranges.into_iter().filter(|r| !r.is_empty()) {
            prepared.cast(&self.fan, range.clone(), &mut self.hits);
            for j in range {
                let (t_in, t_out) = (self.hits.t_in[j], self.hits.t_out[j]);
                if !(t_in <= t_out && t_out >= 0.0) {
                    continue;
                }
                let z_in = t_in.max(0.0) * self.inv_k[j];
                let z_out = t_out * self.inv_k[j];
                let col = &mut self.zbuf[j * DEPTH_ROWS..(j + 1) * DEPTH_ROWS];
                for (z, &iy) in col.iter_mut().zip(&self.inv_y) {
                    let (p, q) = (a * iy, b * iy);
                    let start = z_in.max(p.min(q));
                    let end = z_out.min(p.max(q));
                    if start <= end && start < *z {
                        *z = start;
                    }
                }
            }
        }
    }

    fn write_image(&self, rng: &mut Rng, out: &mut [f32]) {
        let (lo, hi) = (self.cfg.min_range_m, self.cfg.max_range_m);
        for (j, col) in self.zbuf.chunks_exact(DEPTH_ROWS).enumerate() {
            let c = DEPTH_COLS - 1 - j;
            for (r, &z) in col.iter().enumerate() {
                out[r * DEPTH_COLS + c] = if z >= lo && z <= hi { z } else { 0.0 };
            }
        }
        let sigma = self.cfg.noise_std_at_1m;
        let drop = self.cfg.dropout_prob;
        if sigma > 0.0 || drop > 0.0 {
            for z in out.iter_mut().filter(|z| **z > 0.0) {
                if drop > 0.0 && rng.uniform() < drop as f64 {
                    *z = 0.0;
                    continue;
                }
                if sigma > 0.0 {
                    let noisy = *z + sigma * *z * *z * rng.normal();
                    *z = if noisy >= lo && noisy <= hi { noisy } else { 0.0 };
                }
            }
        }
    }
}
