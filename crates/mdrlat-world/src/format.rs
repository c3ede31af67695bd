//! The on-disk schema of world files (version 1). Unknown keys are rejected.

use serde::Deserialize;

/// The world file format version this build reads and writes.
pub const FORMAT_VERSION: u32 = 1;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct WorldFile {
    pub version: u32,
    pub name: String,
    #[serde(default)]
    pub description: String,
    pub bounds: RectSpec,
    #[serde(default)]
    pub obstacle: Vec<ObstacleSpec>,
    pub spawn: Vec<RectSpec>,
    #[serde(default)]
    pub pedestrian: Vec<PedestrianFileSpec>,
    #[serde(default)]
    pub goal: Vec<RectSpec>,
}

#[derive(Debug, Deserialize, Clone, Copy)]
#[serde(deny_unknown_fields)]
pub(crate) struct RectSpec {
    pub min: [f32; 2],
    pub max: [f32; 2],
}

#[derive(Debug, Deserialize)]
#[serde(tag = "shape")]
pub(crate) enum ObstacleSpec {
    #[serde(rename = "box")]
    Box(BoxSpec),
    #[serde(rename = "cylinder")]
    Cylinder(CylinderSpec),
    #[serde(rename = "polygon")]
    Polygon(PolygonSpec),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct BoxSpec {
    pub center: [f32; 2],
    pub size: [f32; 2],
    #[serde(default)]
    pub yaw_deg: f32,
    pub z: [f32; 2],
    #[serde(default)]
    pub label: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct CylinderSpec {
    pub center: [f32; 2],
    pub radius: f32,
    pub z: [f32; 2],
    #[serde(default)]
    pub label: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct PolygonSpec {
    pub points: Vec<[f32; 2]>,
    pub z: [f32; 2],
    #[serde(default)]
    pub label: Option<String>,
}

fn default_ped_radius() -> f32 {
    0.25
}
fn default_ped_height() -> f32 {
    1.7
}
fn default_wait_s() -> f32 {
    2.0
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct PedestrianFileSpec {
    pub waypoints: Vec<[f32; 2]>,
    pub speed: f32,
    #[serde(default = "default_ped_radius")]
    pub radius: f32,
    #[serde(default = "default_ped_height")]
    pub height: f32,
    #[serde(default, rename = "loop")]
    pub looped: bool,
    #[serde(default = "default_wait_s")]
    pub wait_s: f32,
}
