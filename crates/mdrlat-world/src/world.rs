//! The validated, in-memory world.

use crate::error::WorldError;
use crate::format::{FORMAT_VERSION, ObstacleSpec, RectSpec, WorldFile};
use mdrlat_core::robot;
use mdrlat_geom::{
    Aabb, ConvexPolygon, Cuboid, Cylinder, Grid, GridScratch, Prism, Shape, ShapeError, Vec2,
};
use std::path::Path;

/// One static obstacle: a prism, and an optional label for pictures ("table top", "wall").
#[derive(Debug, Clone, PartialEq)]
pub struct Obstacle {
    /// The geometry.
    pub prism: Prism,
    /// Free-form label from the world file.
    pub label: Option<String>,
}

/// A pedestrian (or any moving cylinder) walking along waypoints.
#[derive(Debug, Clone, PartialEq)]
pub struct PedestrianSpec {
    /// Points walked to in order, metres.
    pub waypoints: Vec<Vec2>,
    /// Walking speed, m/s.
    pub speed: f32,
    /// Body radius, metres.
    pub radius: f32,
    /// Body height, metres (the cylinder spans `[0, height]`).
    pub height: f32,
    /// After the last waypoint, walk to the first (true) or turn back (false).
    pub looped: bool,
    /// How long to wait when blocked before turning back, seconds.
    pub wait_s: f32,
}

/// A validated world.
#[derive(Debug, Clone, PartialEq)]
pub struct World {
    /// Short name.
    pub name: String,
    /// One-line description.
    pub description: String,
    /// Outer rectangle, metres (for pictures and the broadphase; walls are obstacles).
    pub bounds: Aabb,
    /// Static obstacles.
    pub obstacles: Vec<Obstacle>,
    /// Regions where `reset` may place the robot.
    pub spawn: Vec<Aabb>,
    /// Moving obstacles.
    pub pedestrians: Vec<PedestrianSpec>,
    /// Goal regions (navigation worlds).
    pub goals: Vec<Aabb>,
}

fn finite2(src: &str, field: &str, v: [f32; 2]) -> Result<Vec2, WorldError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(Vec2::new(v[0], v[1]))
    } else {
        Err(WorldError::invalid(src, field, format!("must be finite, got [{}, {}]", v[0], v[1])))
    }
}

fn rect(src: &str, field: &str, r: &RectSpec) -> Result<Aabb, WorldError> {
    let min = finite2(src, &format!("{field}.min"), r.min)?;
    let max = finite2(src, &format!("{field}.max"), r.max)?;
    if !(min.x < max.x && min.y < max.y) {
        return Err(WorldError::invalid(
            src,
            field,
            format!("min {:?} must be below max {:?} in both x and y", r.min, r.max),
        ));
    }
    Ok(Aabb::new(min, max))
}

fn heights(src: &str, field: &str, z: [f32; 2]) -> Result<(f32, f32), WorldError> {
    if !(z[0].is_finite() && z[1].is_finite()) || z[0] < 0.0 || z[0] >= z[1] {
        return Err(WorldError::invalid(
            src,
            field,
            format!(
                "must be [z_min, z_max] with 0 <= z_min < z_max, finite, got [{}, {}]",
                z[0], z[1]
            ),
        ));
    }
    Ok((z[0], z[1]))
}

fn shape_err(src: &str, field: &str, e: ShapeError) -> WorldError {
    WorldError::invalid(src, field, e.to_string())
}

impl World {
    /// Parses and validates a world file's text. `source_name` (a path or built-in name) is
    /// used in error messages.
    ///
    /// # Errors
    /// Malformed TOML, unknown or missing keys, a wrong version, invalid values, or a spawn
    /// region where the robot fits nowhere.
    pub fn from_toml(source_name: &str, text: &str) -> Result<World, WorldError> {
        let src = source_name;
        let file: WorldFile = toml::from_str(text).map_err(|e| WorldError::Parse {
            source_name: src.to_string(),
            message: e.to_string().trim_end().replace('\n', "\n  "),
        })?;
        if file.version != FORMAT_VERSION {
            return Err(WorldError::invalid(
                src,
                "version",
                format!(
                    "this build reads world format {FORMAT_VERSION}, the file says {}",
                    file.version
                ),
            ));
        }
        let bounds = rect(src, "bounds", &file.bounds)?;
        let mut obstacles = Vec::with_capacity(file.obstacle.len());
        for (i, o) in file.obstacle.iter().enumerate() {
            let f = format!("obstacle[{i}]");
            let (shape, z, label) = match o {
                ObstacleSpec::Box(b) => {
                    let c = finite2(src, &format!("{f}.center"), b.center)?;
                    let s = finite2(src, &format!("{f}.size"), b.size)?;
                    if !b.yaw_deg.is_finite() {
                        return Err(WorldError::invalid(
                            src,
                            format!("{f}.yaw_deg"),
                            "must be finite",
                        ));
                    }
                    if s.x <= 0.0 || s.y <= 0.0 {
                        return Err(WorldError::invalid(
                            src,
                            format!("{f}.size"),
                            format!("must be positive, got [{}, {}]", s.x, s.y),
                        ));
                    }
                    let shape = Cuboid::new(c, s, b.yaw_deg.to_radians())
                        .map_err(|e| shape_err(src, &f, e))?;
                    (Shape::Cuboid(shape), b.z, &b.label)
                }
                ObstacleSpec::Cylinder(c) => {
                    let ctr = finite2(src, &format!("{f}.center"), c.center)?;
                    let shape = Cylinder::new(ctr, c.radius)
                        .map_err(|e| shape_err(src, &format!("{f}.radius"), e))?;
                    (Shape::Cylinder(shape), c.z, &c.label)
                }
                ObstacleSpec::Polygon(p) => {
                    let mut pts = Vec::with_capacity(p.points.len());
                    for (k, q) in p.points.iter().enumerate() {
                        pts.push(finite2(src, &format!("{f}.points[{k}]"), *q)?);
                    }
                    let shape = ConvexPolygon::new(&pts)
                        .map_err(|e| shape_err(src, &format!("{f}.points"), e))?;
                    (Shape::Polygon(shape), p.z, &p.label)
                }
            };
            let (z0, z1) = heights(src, &format!("{f}.z"), z)?;
            obstacles.push(Obstacle { prism: Prism::new(shape, z0, z1), label: label.clone() });
        }
        let mut spawn = Vec::with_capacity(file.spawn.len());
        if file.spawn.is_empty() {
            return Err(WorldError::invalid(src, "spawn", "at least one spawn region is needed"));
        }
        for (i, r) in file.spawn.iter().enumerate() {
            spawn.push(rect(src, &format!("spawn[{i}]"), r)?);
        }
        let mut goals = Vec::with_capacity(file.goal.len());
        for (i, r) in file.goal.iter().enumerate() {
            goals.push(rect(src, &format!("goal[{i}]"), r)?);
        }
        let mut pedestrians = Vec::with_capacity(file.pedestrian.len());
        for (i, p) in file.pedestrian.iter().enumerate() {
            let f = format!("pedestrian[{i}]");
            if p.waypoints.len() < 2 {
                return Err(WorldError::invalid(
                    src,
                    format!("{f}.waypoints"),
                    format!("needs at least 2 points, got {}", p.waypoints.len()),
                ));
            }
            let mut wps = Vec::with_capacity(p.waypoints.len());
            for (k, w) in p.waypoints.iter().enumerate() {
                wps.push(finite2(src, &format!("{f}.waypoints[{k}]"), *w)?);
            }
            if wps.windows(2).any(|w| (w[1] - w[0]).length() < 1e-3) {
                return Err(WorldError::invalid(
                    src,
                    format!("{f}.waypoints"),
                    "consecutive waypoints coincide",
                ));
            }
            for (name, v) in [("speed", p.speed), ("radius", p.radius), ("height", p.height)] {
                if !(v.is_finite() && v > 0.0) {
                    return Err(WorldError::invalid(
                        src,
                        format!("{f}.{name}"),
                        format!("must be positive and finite, got {v}"),
                    ));
                }
            }
            if !(p.wait_s.is_finite() && p.wait_s >= 0.0) {
                return Err(WorldError::invalid(
                    src,
                    format!("{f}.wait_s"),
                    format!("must be >= 0, got {}", p.wait_s),
                ));
            }
            pedestrians.push(PedestrianSpec {
                waypoints: wps,
                speed: p.speed,
                radius: p.radius,
                height: p.height,
                looped: p.looped,
                wait_s: p.wait_s,
            });
        }
        let world = World {
            name: file.name,
            description: file.description,
            bounds,
            obstacles,
            spawn,
            pedestrians,
            goals,
        };
        world.check_spawn_free(src, robot::RADIUS_M + robot::SPAWN_CLEARANCE_M)?;
        Ok(world)
    }

    /// Where a robot can start: the bounds and every spawn region (a world file's spawn
    /// regions may reach past its bounds, as a map import's cells can by half a cell).
    pub fn start_area(&self) -> Aabb {
        self.spawn.iter().fold(self.bounds, |b, r| b.union(r))
    }

    /// True if a robot disc of `radius` at `p` overlaps no static obstacle that can touch its
    /// body (height interval overlapping `[0, BODY_HEIGHT_M]`).
    pub fn is_free(&self, p: Vec2, radius: f32) -> bool {
        self.obstacles.iter().all(|o| {
            !o.prism.overlaps_heights(0.0, robot::BODY_HEIGHT_M)
                || !o.prism.shape.overlaps_disc(p, radius)
        })
    }

    /// Checks every spawn region has at least one position where a disc of `radius` touches
    /// no obstacle the body can hit, scanning a lattice of at most 201 x 201 points (5 cm
    /// apart in rooms) against a broadphase grid.
    fn check_spawn_free(&self, src: &str, radius: f32) -> Result<(), WorldError> {
        let body: Vec<&Prism> = self
            .obstacles
            .iter()
            .map(|o| &o.prism)
            .filter(|p| p.overlaps_heights(0.0, robot::BODY_HEIGHT_M))
            .collect();
        let aabbs: Vec<Aabb> = body.iter().map(|p| p.shape.aabb()).collect();
        let area = self.start_area();
        let grid = Grid::build(area, 1.0, &aabbs);
        let (mut scratch, mut near) = (GridScratch::default(), Vec::new());
        for (i, r) in self.spawn.iter().enumerate() {
            let size = r.size();
            let nx = ((size.x / 0.05).ceil() as usize).clamp(1, 200);
            let ny = ((size.y / 0.05).ceil() as usize).clamp(1, 200);
            let mut any_free = false;
            'scan: for y in 0..=ny {
                for x in 0..=nx {
                    let p = Vec2::new(
                        r.min.x + size.x * x as f32 / nx as f32,
                        r.min.y + size.y * y as f32 / ny as f32,
                    );
                    grid.query(&Aabb::around(p, radius), &mut scratch, &mut near);
                    if near.iter().all(|&k| !body[k as usize].shape.overlaps_disc(p, radius)) {
                        any_free = true;
                        break 'scan;
                    }
                }
            }
            if !any_free {
                return Err(WorldError::invalid(
                    src,
                    format!("spawn[{i}]"),
                    format!(
                        "no free space: the robot needs a clear disc of radius {radius:.3} m \
                         (footprint + reset clearance) and it fits nowhere in [{}, {}]..[{}, {}]",
                        r.min.x, r.min.y, r.max.x, r.max.y
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// Loads a world by built-in name, `gen-N` or `home-N` (the generated world of seed N, see
/// [`crate::generate`]), or from a `.toml` world file, or from a ROS map_server `.yaml`
/// (imported with default options: see [`crate::map_server`]).
///
/// # Errors
/// An unknown name or any error of the file.
pub fn load(spec: &str) -> Result<World, WorldError> {
    if let Some(w) = crate::builtin::get(spec) {
        return w;
    }
    if let Some((family, seed)) = crate::Family::parse(spec) {
        return crate::generate_family(family, seed);
    }
    let path = Path::new(spec);
    if !path.is_file() {
        return Err(WorldError::Unknown {
            name: spec.to_string(),
            builtins: crate::builtin::NAMES.join(", "),
        });
    }
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if ext == "yaml" || ext == "yml" {
        return crate::map_server::import(path, &crate::map_server::ImportOptions::default());
    }
    let text = std::fs::read_to_string(path)
        .map_err(|error| WorldError::Io { source_name: spec.to_string(), error })?;
    World::from_toml(spec, &text)
}

/// Several worlds from one spec: comma-separated [`load`] specs, where `gen-A..B` stands
/// for the generated worlds `gen-A` to `gen-(B−1)` (`gen-0..64`: 64 worlds), and `home-A..B`
/// for the generated homes. A spec without
/// a comma or a range is one world, as [`load`] reads it.
///
/// # Errors
/// An empty spec or range, a range of more than 10,000 worlds, or any world's error.
pub fn load_set(spec: &str) -> Result<Vec<World>, WorldError> {
    let bad = |problem: String| WorldError::invalid(spec, "world list", problem);
    let mut worlds = Vec::new();
    for part in spec.split(',').map(str::trim) {
        if part.is_empty() {
            return Err(bad("an empty name (two commas, or one at an end)".into()));
        }
        let range = crate::Family::ALL.into_iter().find_map(|f| {
            part.strip_prefix(f.prefix()).and_then(|r| r.split_once("..")).map(|r| (f, r))
        });
        let Some((family, (a, b))) = range else {
            worlds.push(load(part)?);
            continue;
        };
        let (Ok(a), Ok(b)) = (a.parse::<u64>(), b.parse::<u64>()) else {
            let p = family.prefix();
            return Err(bad(format!("'{part}': expected {p}A..B with whole numbers A < B")));
        };
        if a >= b || b - a > 10_000 {
            return Err(bad(format!("'{part}': expected A < B and at most 10,000 worlds")));
        }
        for seed in a..b {
            worlds.push(crate::generate_family(family, seed)?);
        }
    }
    Ok(worlds)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn world_sets_list_and_range() {
        let names = |spec: &str| -> Vec<String> {
            load_set(spec).expect(spec).into_iter().map(|w| w.name).collect()
        };
        assert_eq!(names("office"), ["office"]);
        let set = names("train, gen-3..5,office");
        assert_eq!(set.len(), 4, "{set:?}");
        assert_eq!(set[0], "train");
        assert_eq!(set[1], crate::generate(3).expect("gen").name);
        for bad in ["", "office,", "gen-5..5", "gen-2..x", "nowhere,office"] {
            let e = load_set(bad).expect_err(bad).to_string();
            assert!(!e.is_empty(), "{bad}");
        }
        let e = load_set("gen-9..2").expect_err("reversed").to_string();
        assert!(e.contains("gen-9..2") && e.contains("A < B"), "{e}");
        assert_eq!(names("home-2..4,train"), ["home-2", "home-3", "train"]);
        let e = load_set("home-1..y").expect_err("bad range").to_string();
        assert!(e.contains("home-A..B"), "{e}");
    }

    const OK: &str = r#"
version = 1
name = "example"
bounds = { min = [0.0, 0.0], max = [6.0, 10.0] }
obstacle = [
  { shape = "box", center = [3.0, 5.0], size = [1.0, 0.5], yaw_deg = 30.0, z = [0.0, 0.15] },
  { shape = "cylinder", center = [1.0, 2.0], radius = 0.2, z = [0.0, 1.0] },
  { shape = "polygon", points = [[0.0, 0.0], [1.0, 0.0], [0.5, 0.8]], z = [0.68, 0.72] },
]
spawn = [ { min = [0.5, 0.5], max = [5.5, 9.5] } ]
pedestrian = [ { waypoints = [[1.0, 1.0], [5.0, 1.0]], speed = 0.6, radius = 0.25, height = 1.7 } ]
"#;

    fn err(text: &str) -> String {
        World::from_toml("w.toml", text).expect_err("should fail").to_string()
    }

    #[test]
    fn the_issue_example_loads() {
        let w = World::from_toml("w.toml", OK).expect("valid");
        assert_eq!(w.obstacles.len(), 3);
        assert_eq!(w.pedestrians[0].radius, 0.25);
        assert!(matches!(w.obstacles[2].prism.shape, Shape::Polygon(_)));
    }

    #[test]
    fn table_syntax_is_the_same_data() {
        let text = r#"
version = 1
name = "tables"
bounds = { min = [0.0, 0.0], max = [4.0, 4.0] }
[[obstacle]]
shape = "box"
center = [2.0, 2.0]
size = [0.5, 0.5]
z = [0.0, 1.0]
[[spawn]]
min = [0.5, 0.5]
max = [1.5, 1.5]
"#;
        let w = World::from_toml("t.toml", text).expect("valid");
        assert_eq!(w.obstacles.len(), 1);
    }

    #[test]
    fn bad_input_names_file_field_and_problem() {
        let e = err(&OK.replace("\"cylinder\"", "\"sphere\""));
        assert!(e.starts_with("w.toml:") && e.contains("sphere"), "{e}");
        let e = err(&OK.replace("size = [1.0, 0.5]", "size = [1.0, -0.5]"));
        assert!(e.contains("obstacle[0].size") && e.contains("-0.5"), "{e}");
        let e = err(&OK.replace("radius = 0.2,", "radius = 0.2, colour = \"red\","));
        assert!(e.contains("colour"), "{e}");
        let e = err(&OK.replace("[0.5, 0.8]]", "[0.5, 0.8], [0.5, 0.1]]"));
        assert!(e.contains("obstacle[2].points") && e.contains("convex"), "{e}");
        let e = err(&OK.replace("z = [0.0, 1.0]", "z = [1.0, 0.5]"));
        assert!(e.contains("obstacle[1].z"), "{e}");
        let e = err(&OK.replace("radius = 0.2,", "radius = nan,"));
        assert!(e.contains("obstacle[1].radius"), "{e}");
        let e = err(&OK.replace("version = 1", "version = 7"));
        assert!(e.contains("version") && e.contains('7'), "{e}");
        let e = err(&OK.replace("name = \"example\"\n", ""));
        assert!(e.contains("name"), "{e}");
        let e = err(&OK.replace("speed = 0.6", "speed = -1.0"));
        assert!(e.contains("pedestrian[0].speed"), "{e}");
        // A spawn region fully covered by a tall box.
        let blocked = OK.replace(
            "spawn = [ { min = [0.5, 0.5], max = [5.5, 9.5] } ]",
            "spawn = [ { min = [0.5, 0.5], max = [5.5, 9.5] }, { min = [2.9, 4.9], max = [3.1, 5.1] } ]",
        )
        .replace("z = [0.0, 0.15]", "z = [0.0, 2.0]");
        let e = err(&blocked);
        assert!(e.contains("spawn[1]") && e.contains("no free space"), "{e}");
    }

    #[test]
    fn a_table_top_above_the_body_does_not_block_spawning() {
        let w = World::from_toml("w.toml", OK).expect("valid");
        // The polygon table top at 0.68–0.72 m is above the 0.45 m body.
        assert!(w.is_free(Vec2::new(0.5, 0.3), 0.177));
        // The 1 m cylinder is not.
        assert!(!w.is_free(Vec2::new(1.1, 2.0), 0.177));
    }
}
