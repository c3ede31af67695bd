//! The static part of a world, indexed for the sensors and the bumper.
//!
//! Built once per world and shared (behind an `Arc`) by every environment of a `VecEnv`.
//! Obstacles are split by what can touch them: the laser plane, the robot body, or only
//! the depth camera; each set has its own broadphase grid.

use crate::config::SimConfig;
use mdrlat_geom::{Aabb, Grid, GridScratch, Prism, Vec2};
use mdrlat_world::World;
use std::sync::Arc;

/// Broadphase cell size, metres.
const CELL_M: f32 = 1.0;

/// A subset of the world's prisms with its own grid.
#[derive(Debug, Clone)]
pub struct Layer {
    /// Indices into [`StaticScene::prisms`].
    pub members: Vec<u32>,
    grid: Grid,
}

impl Layer {
    fn new(bounds: Aabb, prisms: &[Prism], keep: impl Fn(&Prism) -> bool) -> Self {
        let members: Vec<u32> =
            (0..prisms.len() as u32).filter(|&i| keep(&prisms[i as usize])).collect();
        let aabbs: Vec<Aabb> = members.iter().map(|&i| prisms[i as usize].shape.aabb()).collect();
        Self { grid: Grid::build(bounds, CELL_M, &aabbs), members }
    }

    /// Fills `out` with the prism indices (into the scene) near `area`.
    pub fn query(&self, area: &Aabb, scratch: &mut GridScratch, out: &mut Vec<u32>) {
        self.grid.query(area, scratch, out);
        for i in out.iter_mut() {
            *i = self.members[*i as usize];
        }
    }
}

/// The static obstacles of a world, indexed.
#[derive(Debug, Clone)]
pub struct StaticScene {
    /// The world this was built from.
    pub world: Arc<World>,
    /// Every static prism, in world-file order.
    pub prisms: Vec<Prism>,
    /// Prisms that span the laser plane.
    pub laser: Layer,
    /// Prisms overlapping the robot body's heights (the bumper).
    pub body: Layer,
    /// Every prism (the depth camera can see any of them).
    pub all: Layer,
}

impl StaticScene {
    /// Indexes `world` for the sensor heights and body of `config`.
    pub fn new(world: Arc<World>, config: &SimConfig) -> Self {
        let prisms: Vec<Prism> = world.obstacles.iter().map(|o| o.prism.clone()).collect();
        let bounds = prisms.iter().fold(world.bounds, |b, p| b.union(&p.shape.aabb()));
        let laser_z = config.laser.height_m;
        let body_z = config.robot.body_height_m;
        Self {
            laser: Layer::new(bounds, &prisms, |p| p.spans_height(laser_z)),
            body: Layer::new(bounds, &prisms, |p| p.overlaps_heights(0.0, body_z)),
            all: Layer::new(bounds, &prisms, |_| true),
            prisms,
            world,
        }
    }

    /// The first static prism hit by a robot disc at `p`, if any.
    pub fn body_contact(
        &self,
        p: Vec2,
        radius: f32,
        scratch: &mut GridScratch,
        buf: &mut Vec<u32>,
    ) -> Option<usize> {
        self.body_contact_where(p, radius, scratch, buf, |_| true)
    }

    /// The first static prism the body can hit that the laser plane at `laser_z` misses (a
    /// low box, an overhang) overlapping a disc at `p`, if any: what only the depth camera
    /// can show, and only from beyond its minimum range.
    pub fn hidden_contact(
        &self,
        p: Vec2,
        radius: f32,
        laser_z: f32,
        scratch: &mut GridScratch,
        buf: &mut Vec<u32>,
    ) -> Option<usize> {
        self.body_contact_where(p, radius, scratch, buf, |prism| !prism.spans_height(laser_z))
    }

    fn body_contact_where(
        &self,
        p: Vec2,
        radius: f32,
        scratch: &mut GridScratch,
        buf: &mut Vec<u32>,
        keep: impl Fn(&Prism) -> bool,
    ) -> Option<usize> {
        self.body.query(&Aabb::around(p, radius), scratch, buf);
        buf.iter().map(|&i| i as usize).find(|&i| {
            let prism = &self.prisms[i];
            keep(prism) && prism.shape.overlaps_disc(p, radius)
        })
    }
}
