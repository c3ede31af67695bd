//! The depth camera: a zero-pitch pinhole producing a 128 x 160 z-depth image.

use crate::config::DepthConfig;
use crate::scene::StaticScene;
pub use mdrlat_core::DepthGeometry;
use mdrlat_core::{DEPTH_COLS, DEPTH_ROWS, Rng};

const _: () = assert!(DEPTH_COLS.is_multiple_of(16), "the blocked transpose needs whole blocks");
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
    /// Vertical focal length, pixels.
    fy: f32,
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
            fy,
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

    /// The camera's projection, for turning images back into geometry: the one pinhole of
    /// `mdrlat-core` (which the robot's node uses too), the same rays this camera casts.
    pub fn geometry(&self) -> DepthGeometry {
        DepthGeometry::pinhole(self.cfg.hfov_deg, self.cfg.vfov_deg, self.cfg.height_m)
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
                let rows = self.rows_between(a, b, z_in, z_out);
                let col = &mut self.zbuf[j * DEPTH_ROWS..(j + 1) * DEPTH_ROWS];
                // Branch-free so it vectorises: one compare-and-blend per row.
                for (z, &iy) in col[rows.clone()].iter_mut().zip(&self.inv_y[rows]) {
                    let (p, q) = (a * iy, b * iy);
                    let (lo, hi) = if p < q { (p, q) } else { (q, p) };
                    let start = if z_in > lo { z_in } else { lo };
                    let end = if z_out < hi { z_out } else { hi };
                    *z = if start <= end && start < *z { start } else { *z };
                }
            }
        }
    }

    /// Rows that can see heights `h − b ..= h − a` (i.e. `[z_min, z_max]`) at some z-depth
    /// in `[z_in, z_out]`: `y·z ∈ [a, b]` bounds `y`, and `y` gives the row. Padded by one;
    /// the per-row test decides.
    fn rows_between(&self, a: f32, b: f32, z_in: f32, z_out: f32) -> std::ops::Range<usize> {
        let z_in = z_in.max(1e-6);
        let y_lo = (a / z_in).min(a / z_out);
        let y_hi = (b / z_in).max(b / z_out);
        let half = DEPTH_ROWS as f32 / 2.0;
        let to_row = |y: f32| y * self.fy + half - 0.5;
        let lo = (to_row(y_lo).floor() - 1.0).clamp(0.0, DEPTH_ROWS as f32) as usize;
        let hi = (to_row(y_hi).ceil() + 2.0).clamp(0.0, DEPTH_ROWS as f32) as usize;
        lo..hi.max(lo)
    }

    fn write_image(&self, rng: &mut Rng, out: &mut [f32]) {
        let (lo, hi) = (self.cfg.min_range_m, self.cfg.max_range_m);
        // Blocked transpose (column-major z-buffer → row-major image): 16 sequential read
        // streams and one contiguous write per row of the block.
        const BLOCK: usize = 16;
        for c0 in (0..DEPTH_COLS).step_by(BLOCK) {
            for r in 0..DEPTH_ROWS {
                let row = &mut out[r * DEPTH_COLS + c0..r * DEPTH_COLS + c0 + BLOCK];
                for (k, o) in row.iter_mut().enumerate() {
                    let j = DEPTH_COLS - 1 - (c0 + k);
                    let z = self.zbuf[j * DEPTH_ROWS + r];
                    *o = if z >= lo && z <= hi { z } else { 0.0 };
                }
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
