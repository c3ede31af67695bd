//! Import of ROS `map_server` maps (a YAML file and a PGM or PNG image) as worlds.
//!
//! The pixels are classified exactly as ROS map_server does (Nav2's `map_io.cpp`; see
//! [`MapMode`]): with `negate: 0` a pixel's occupancy is `p = 1 - shade` (`shade` the mean
//! of its channels over their maximum, so `(255 - v) / 255` for 8-bit grey; `p = shade` with
//! `negate: 1`); `p > occupied_thresh` is occupied, `p < free_thresh` is free, anything else
//! unknown. Image row 0 is the top of the map: the cell of row `r` and column `c` of an
//! `W x H` image covers `x ∈ origin.x + [c, c + 1]·res`, `y ∈ origin.y + [H - 1 - r, H - r]·res`
//! in the map frame, which is then rotated by the origin's yaw about the origin point.
//!
//! The world gets:
//! - walls: the occupied cells (and the unknown ones with
//!   [`ImportOptions::unknown_is_occupied`]) merged greedily into few rectangles, each a box
//!   prism from the floor to [`ImportOptions::wall_height_m`], labelled `wall`;
//! - spawn regions: the free cells (never unknown ones) farther than
//!   [`ImportOptions::spawn_clearance_m`] (plus half a cell diagonal) from every wall cell,
//!   centre to centre (an exact Euclidean distance transform), merged the same way;
//! - bounds: the axis-aligned box around the (rotated) map; no goals, no pedestrians.
//!
//! Spawn regions are axis-aligned boxes, so for a map with a non-zero yaw they are computed on
//! the map resampled (nearest cell) onto an axis-aligned grid of the same resolution covering
//! the bounds; there, cells outside the image count as unknown.

mod grid;
mod image;
mod yaml;

pub use yaml::{MapMeta, MapMode};

use crate::{Obstacle, World, WorldError};
use grid::{Cell, CellRect, Grid};
use image::Pixel;
use mdrlat_geom::{Aabb, Cuboid, Prism, Shape, Vec2};
use std::borrow::Cow;
use std::path::Path;

/// Options of the map import.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    /// Height of the wall prisms, metres (default 2.0).
    pub wall_height_m: f32,
    /// Treat unknown cells as walls (default false: they are neither walls nor spawn space).
    pub unknown_is_occupied: bool,
    /// Spawn regions hold the free cells whose every point is at least this far from every
    /// wall cell, metres (default: the robot radius + the reset clearance, as `reset` and
    /// world validation use). Measured from each spawn cell's centre to the nearest wall
    /// cell's centre, minus half a cell diagonal: every spawn cell's centre is a valid pose.
    pub spawn_clearance_m: f32,
}

impl Default for ImportOptions {
    fn default() -> Self {
        Self {
            wall_height_m: 2.0,
            unknown_is_occupied: false,
            spawn_clearance_m: mdrlat_core::robot::RADIUS_M + mdrlat_core::robot::SPAWN_CLEARANCE_M,
        }
    }
}

/// Spawn rectangles of fewer cells are dropped, unless no larger one exists.
const MIN_SPAWN_CELLS: usize = 4;

/// Imports a map_server YAML and its image as a world named after the YAML file.
///
/// # Errors
/// An unreadable file ([`WorldError::Io`]), a malformed YAML ([`WorldError::Parse`] or
/// [`WorldError::Invalid`]), a bad image ([`WorldError::Image`]), bad options, or a map with
/// no free cell far enough from the walls to spawn the robot.
pub fn import(yaml_path: &Path, opts: &ImportOptions) -> Result<World, WorldError> {
    let src = yaml_path.display().to_string();
    let text = std::fs::read_to_string(yaml_path)
        .map_err(|error| WorldError::Io { source_name: src.clone(), error })?;
    let meta = MapMeta::parse(&src, &text, yaml_path.parent().unwrap_or(Path::new("")))?;
    let bytes = std::fs::read(&meta.image).map_err(|error| WorldError::Io {
        source_name: format!("{src}: image {}", meta.image.display()),
        error,
    })?;
    build(yaml_path, &meta, &bytes, opts)
}

/// Imports a map from memory: `yaml_name` is the YAML's path (it names the world and, with
/// the YAML's `image` key, the image in errors), `image_bytes` the image file's content.
///
/// # Errors
/// As [`import`], less the I/O.
pub fn import_from_parts(
    yaml_name: &str,
    yaml_text: &str,
    image_bytes: &[u8],
    opts: &ImportOptions,
) -> Result<World, WorldError> {
    let path = Path::new(yaml_name);
    let meta = MapMeta::parse(yaml_name, yaml_text, path.parent().unwrap_or(Path::new("")))?;
    build(path, &meta, image_bytes, opts)
}

/// The occupancy of one pixel, as ROS map_server (Nav2 `loadMapFromFile`) computes it.
///
/// Alpha, as ROS: in trinary mode it is averaged in with the colour channels (a grey+alpha
/// pixel's shade is `(3·grey + alpha) / 4`, so a transparent pixel reads darker); in scale
/// mode a pixel that is not fully opaque is unknown; in raw mode it is ignored.
fn classify(meta: &MapMeta, px: Pixel) -> Cell {
    let max = f64::from(px.max);
    let rgb_shade = f64::from(px.rgb_sum) / (3.0 * max);
    let shade = match (meta.mode, px.alpha) {
        (MapMode::Trinary, Some(a)) => (f64::from(px.rgb_sum) + f64::from(a)) / (4.0 * max),
        (MapMode::Scale, Some(a)) if a != px.max => return Cell::Unknown,
        (MapMode::Raw, _) => {
            let percent = (rgb_shade * 255.0).round();
            return if percent <= 100.0 { threshold(meta, percent / 100.0) } else { Cell::Unknown };
        }
        _ => rgb_shade,
    };
    threshold(meta, if meta.negate { shade } else { 1.0 - shade })
}

fn threshold(meta: &MapMeta, occupancy: f64) -> Cell {
    if occupancy > meta.occupied_thresh {
        Cell::Occupied
    } else if occupancy < meta.free_thresh {
        Cell::Free
    } else {
        Cell::Unknown
    }
}

/// Where a grid lies in the world: `origin` is the lower-left corner of the bottom row,
/// the grid's x axis points along `yaw`.
#[derive(Debug, Clone, Copy)]
struct Frame {
    origin: [f64; 2],
    yaw: f64,
    cos: f64,
    sin: f64,
    res: f64,
    rows: usize,
}

impl Frame {
    fn new(origin: [f64; 2], yaw: f64, res: f64, rows: usize) -> Self {
        let (sin, cos) = yaw.sin_cos();
        Self { origin, yaw, cos, sin, res, rows }
    }

    /// A map-frame point (metres from the origin, before the yaw) in the world.
    fn world_point(&self, [x, y]: [f64; 2]) -> [f64; 2] {
        [self.origin[0] + self.cos * x - self.sin * y, self.origin[1] + self.sin * x + self.cos * y]
    }

    /// A world point in the map frame.
    fn map_point(&self, [x, y]: [f64; 2]) -> [f64; 2] {
        let (dx, dy) = (x - self.origin[0], y - self.origin[1]);
        [self.cos * dx + self.sin * dy, -self.sin * dx + self.cos * dy]
    }

    /// The map-frame corners `[min, max]` of a block of cells.
    fn rect(&self, r: &CellRect) -> [[f64; 2]; 2] {
        let res = self.res;
        let y0 = (self.rows - r.row - r.rows) as f64;
        [
            [r.col as f64 * res, y0 * res],
            [(r.col + r.cols) as f64 * res, (y0 + r.rows as f64) * res],
        ]
    }

    /// The world box around a map-frame rectangle.
    fn world_box(&self, [min, max]: [[f64; 2]; 2]) -> ([f64; 2], [f64; 2]) {
        let corners = [min, [max[0], min[1]], max, [min[0], max[1]]].map(|p| self.world_point(p));
        let lo = corners.iter().fold([f64::INFINITY; 2], |a, p| [a[0].min(p[0]), a[1].min(p[1])]);
        let hi =
            corners.iter().fold([f64::NEG_INFINITY; 2], |a, p| [a[0].max(p[0]), a[1].max(p[1])]);
        (lo, hi)
    }
}

fn vec2([x, y]: [f64; 2]) -> Vec2 {
    Vec2::new(x as f32, y as f32)
}

/// A world box in f32, which must keep a positive size.
fn aabb(src: &str, field: &str, (lo, hi): ([f64; 2], [f64; 2])) -> Result<Aabb, WorldError> {
    let (min, max) = (vec2(lo), vec2(hi));
    if min.is_finite() && max.is_finite() && min.x < max.x && min.y < max.y {
        Ok(Aabb::new(min, max))
    } else {
        Err(WorldError::invalid(
            src,
            field,
            format!(
                "[{}, {}]..[{}, {}] is not a box in f32 coordinates: origin too far for the resolution",
                lo[0], lo[1], hi[0], hi[1]
            ),
        ))
    }
}

fn check_options(src: &str, opts: &ImportOptions) -> Result<(), WorldError> {
    if !(opts.wall_height_m.is_finite() && opts.wall_height_m > 0.0) {
        return Err(WorldError::invalid(
            src,
            "options.wall_height_m",
            format!("must be positive and finite, got {}", opts.wall_height_m),
        ));
    }
    if !(opts.spawn_clearance_m.is_finite() && opts.spawn_clearance_m >= 0.0) {
        return Err(WorldError::invalid(
            src,
            "options.spawn_clearance_m",
            format!("must be >= 0 and finite, got {}", opts.spawn_clearance_m),
        ));
    }
    Ok(())
}

fn build(
    yaml_path: &Path,
    meta: &MapMeta,
    image_bytes: &[u8],
    opts: &ImportOptions,
) -> Result<World, WorldError> {
    let src = yaml_path.display().to_string();
    check_options(&src, opts)?;
    let grid = image::decode(&meta.image, image_bytes, |px| classify(meta, px))?;
    let [x, y, yaw] = meta.origin;
    let frame = Frame::new([x, y], yaw, meta.resolution, grid.height);
    let blocked = |c: Cell| c == Cell::Occupied || (opts.unknown_is_occupied && c == Cell::Unknown);
    let extent = frame.rect(&CellRect { row: 0, col: 0, rows: grid.height, cols: grid.width });
    let bounds = frame.world_box(extent);
    let obstacles = walls(&src, &grid, &frame, blocked, opts.wall_height_m)?;
    // Distances are centre to centre: half a cell diagonal more keeps every spawn cell's
    // centre clear of the whole wall cell, so each spawn cell holds a valid reset pose.
    let clearance =
        opts.spawn_clearance_m + (meta.resolution as f32) * std::f32::consts::FRAC_1_SQRT_2;
    let spawn = spawn_regions(&src, &grid, &frame, bounds, blocked, clearance)?;
    let file = yaml_path.file_name().map_or(src.clone(), |f| f.to_string_lossy().into_owned());
    Ok(World {
        name: yaml_path.file_stem().map_or(src.clone(), |s| s.to_string_lossy().into_owned()),
        description: format!(
            "imported from {file} ({}x{} cells at {} m)",
            grid.width, grid.height, meta.resolution
        ),
        bounds: aabb(&src, "origin", bounds)?,
        obstacles,
        spawn,
        pedestrians: Vec::new(),
        goals: Vec::new(),
    })
}

/// The blocked cells as few box prisms `[0, height]`, turned with the map.
fn walls(
    src: &str,
    grid: &Grid,
    frame: &Frame,
    blocked: impl Fn(Cell) -> bool,
    height: f32,
) -> Result<Vec<Obstacle>, WorldError> {
    let mut mask = grid.mask(blocked);
    grid::merge_rects(&mut mask, grid.width)
        .iter()
        .map(|r| {
            let [min, max] = frame.rect(r);
            let center = frame.world_point([(min[0] + max[0]) / 2.0, (min[1] + max[1]) / 2.0]);
            let size = vec2([max[0] - min[0], max[1] - min[1]]);
            let cuboid = Cuboid::new(vec2(center), size, frame.yaw as f32).map_err(|e| {
                WorldError::invalid(
                    src,
                    format!("wall at row {}, column {}", r.row, r.col),
                    e.to_string(),
                )
            })?;
            Ok(Obstacle {
                prism: Prism::new(Shape::Cuboid(cuboid), 0.0, height),
                label: Some("wall".to_string()),
            })
        })
        .collect()
}

/// The free cells far enough from the walls, as few axis-aligned boxes.
fn spawn_regions(
    src: &str,
    grid: &Grid,
    frame: &Frame,
    bounds: ([f64; 2], [f64; 2]),
    blocked: impl Fn(Cell) -> bool,
    clearance: f32,
) -> Result<Vec<Aabb>, WorldError> {
    let (grid, frame) = if frame.yaw == 0.0 {
        (Cow::Borrowed(grid), *frame)
    } else {
        let (g, f) = resample(grid, frame, bounds);
        (Cow::Owned(g), f)
    };
    let distance_sq = mdrlat_geom::distance_sq(&grid.mask(&blocked), grid.width);
    let limit_sq = (f64::from(clearance) / frame.res).powi(2);
    let mut mask: Vec<bool> = grid
        .cells
        .iter()
        .zip(&distance_sq)
        .map(|(&c, &d)| c == Cell::Free && (d == u32::MAX || f64::from(d) > limit_sq))
        .collect();
    let mut rects = grid::merge_rects(&mut mask, grid.width);
    if rects.is_empty() {
        let free = grid.cells.iter().filter(|&&c| c == Cell::Free).count();
        return Err(WorldError::invalid(
            src,
            "free space",
            format!(
                "no free cell is farther than {clearance} m from every occupied{} cell ({free} free of {} cells): nowhere to spawn the robot",
                if blocked(Cell::Unknown) { " or unknown" } else { "" },
                grid.cells.len()
            ),
        ));
    }
    if rects.iter().any(|r| r.cells() >= MIN_SPAWN_CELLS) {
        rects.retain(|r| r.cells() >= MIN_SPAWN_CELLS);
    }
    rects.iter().map(|r| aabb(src, "spawn", frame.world_box(frame.rect(r)))).collect()
}

/// The grid resampled (nearest cell) onto an axis-aligned grid of the same resolution whose
/// lower-left corner is `bounds.0`; cells outside the map are unknown.
fn resample(grid: &Grid, frame: &Frame, (lo, hi): ([f64; 2], [f64; 2])) -> (Grid, Frame) {
    let res = frame.res;
    // About (W + H) / √2 cells a side at most; the epsilon keeps an exact fit exact.
    let side = |extent: f64| (((extent / res) - 1e-9).ceil() as usize).max(1);
    let (width, height) = (side(hi[0] - lo[0]), side(hi[1] - lo[1]));
    let aligned = Frame::new(lo, 0.0, res, height);
    let mut cells = Vec::with_capacity(width * height);
    for row in 0..height {
        for col in 0..width {
            let centre = [(col as f64 + 0.5) * res, (height - row) as f64 * res - 0.5 * res];
            let [mx, my] = frame.map_point(aligned.world_point(centre));
            let (c, r_up) = ((mx / res).floor(), (my / res).floor());
            let inside =
                c >= 0.0 && r_up >= 0.0 && c < grid.width as f64 && r_up < grid.height as f64;
            cells.push(if inside {
                grid.cells[(grid.height - 1 - r_up as usize) * grid.width + c as usize]
            } else {
                Cell::Unknown
            });
        }
    }
    (Grid { width, height, cells }, aligned)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 6x5 test map, row 0 on top: a ring of walls, a wall cell at row 2, column 2, and an
    /// unknown cell (205, as map_saver writes it) at row 1, column 4.
    #[rustfmt::skip]
    const PIXELS: [u8; 30] = [
        0,   0,   0,   0,   0,   0,
        0, 255, 255, 255, 205,   0,
        0, 255,   0, 255, 255,   0,
        0, 255, 255, 255, 255,   0,
        0,   0,   0,   0,   0,   0,
    ];
    const YAML: &str =
        "image: tiny.pgm\nresolution: 0.5\norigin: [-1.0, 2.0, 0.0]\nfree_thresh: 0.196\n";
    /// The walls (centre, size) the greedy merge makes of `PIXELS`, row-major.
    const WALLS: [([f32; 2], [f32; 2]); 5] = [
        ([0.5, 4.25], [3.0, 0.5]),  // row 0
        ([-0.75, 3.0], [0.5, 2.0]), // column 0, rows 1-4
        ([1.75, 3.0], [0.5, 2.0]),  // column 5, rows 1-4
        ([0.25, 3.25], [0.5, 0.5]), // row 2, column 2
        ([0.5, 2.25], [2.0, 0.5]),  // row 4, columns 1-4
    ];

    fn p2(pixels: &[u8]) -> Vec<u8> {
        let rows: Vec<String> = pixels
            .chunks(6)
            .map(|r| r.iter().map(|v| format!("{v:3}")).collect::<Vec<_>>().join(" "))
            .collect();
        format!("P2\n# CREATOR: a test\n6 5\n255\n{}\n", rows.join("\n")).into_bytes()
    }

    fn p5(pixels: &[u8]) -> Vec<u8> {
        [b"P5\n# CREATOR: a test\n6 5\n# and another\n255\n".as_slice(), pixels].concat()
    }

    fn png(color: png::ColorType, depth: png::BitDepth, data: &[u8], palette: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, 6, 5);
        encoder.set_color(color);
        encoder.set_depth(depth);
        if !palette.is_empty() {
            encoder.set_palette(palette.to_vec());
        }
        let mut writer = encoder.write_header().expect("png header");
        writer.write_image_data(data).expect("png data");
        writer.finish().expect("png end");
        out
    }

    fn grey_png(pixels: &[u8]) -> Vec<u8> {
        png(png::ColorType::Grayscale, png::BitDepth::Eight, pixels, &[])
    }

    fn world(yaml: &str, image: &[u8], opts: &ImportOptions) -> World {
        import_from_parts("maps/tiny.yaml", yaml, image, opts).unwrap_or_else(|e| panic!("{e}"))
    }

    /// The tiny map's cells are 0.5 m: the default clearance (0.277 m plus half a 0.71 m
    /// diagonal) would leave no spawn cell, so its tests ask for 0.1 m (0.45 m in all).
    fn coarse() -> ImportOptions {
        ImportOptions { spawn_clearance_m: 0.1, ..ImportOptions::default() }
    }

    fn tiny(yaml: &str, image: &[u8]) -> World {
        world(yaml, image, &coarse())
    }

    fn err(yaml: &str, image: &[u8], opts: &ImportOptions) -> String {
        import_from_parts("maps/tiny.yaml", yaml, image, opts).expect_err("should fail").to_string()
    }

    fn boxes(w: &World) -> Vec<([f32; 2], [f32; 2], f32)> {
        w.obstacles
            .iter()
            .map(|o| {
                assert_eq!(
                    (o.prism.z_min, o.prism.z_max, o.label.as_deref()),
                    (0.0, 2.0, Some("wall"))
                );
                let Shape::Cuboid(c) = &o.prism.shape else { panic!("not a box") };
                ([c.center.x, c.center.y], [c.half.x * 2.0, c.half.y * 2.0], c.yaw)
            })
            .collect()
    }

    fn rect(min: [f32; 2], max: [f32; 2]) -> Aabb {
        Aabb::new(Vec2::new(min[0], min[1]), Vec2::new(max[0], max[1]))
    }

    /// The centre of cell (row, col) of the unrotated test map.
    fn centre(row: usize, col: usize) -> Vec2 {
        Vec2::new(-1.0 + (col as f32 + 0.5) * 0.5, 2.0 + (4.5 - row as f32) * 0.5)
    }

    fn meta(mode: MapMode, negate: bool) -> MapMeta {
        MapMeta {
            image: "m.png".into(),
            resolution: 1.0,
            origin: [0.0; 3],
            negate,
            occupied_thresh: 0.65,
            free_thresh: 0.196,
            mode,
        }
    }

    #[test]
    fn the_tiny_map_gives_exact_walls_spawn_and_bounds() {
        let w = tiny(YAML, &p2(&PIXELS));
        assert_eq!(w.name, "tiny");
        assert_eq!(w.description, "imported from tiny.yaml (6x5 cells at 0.5 m)");
        assert_eq!(w.bounds, rect([-1.0, 2.0], [2.0, 4.5]));
        assert_eq!(boxes(&w), WALLS.map(|(c, s)| (c, s, 0.0)));
        // Free cells: 3 + 3 + 4, all farther than 0.227 m from a wall; the greedy rectangles
        // are row 1 columns 1-3, rows 2-3 column 1, rows 2-3 columns 3-4 and row 3 column 2,
        // and only the one of 4 cells is kept.
        assert_eq!(w.spawn, [rect([0.5, 2.5], [1.5, 3.5])]);
        assert!(w.goals.is_empty() && w.pedestrians.is_empty());
        assert!(w.is_free(centre(3, 3), 0.2) && !w.is_free(centre(2, 2), 0.01));
        // Every encoding of the same pixels is the same world.
        let wide: Vec<u8> =
            PIXELS.iter().flat_map(|&v| (u16::from(v) * 257).to_be_bytes()).collect();
        let palette = [0, 0, 0, 205, 205, 205, 255, 255, 255];
        let indices: Vec<u8> = PIXELS
            .iter()
            .map(|&v| [0, 205, 255].iter().position(|&p| p == v).expect("in palette") as u8)
            .collect();
        // Colour: the mean of the channels (a red wall cell reads 85, an unknown 205).
        let rgb: Vec<u8> = PIXELS
            .iter()
            .enumerate()
            .flat_map(|(i, &v)| match (i, v) {
                (14, _) => [255, 0, 0],
                (_, 205) => [200, 205, 210],
                _ => [v; 3],
            })
            .collect();
        let images = [
            ("P5", p5(&PIXELS)),
            ("8-bit grey PNG", grey_png(&PIXELS)),
            ("16-bit grey PNG", png(png::ColorType::Grayscale, png::BitDepth::Sixteen, &wide, &[])),
            ("palette PNG", png(png::ColorType::Indexed, png::BitDepth::Eight, &indices, &palette)),
            ("RGB PNG", png(png::ColorType::Rgb, png::BitDepth::Eight, &rgb, &[])),
        ];
        for (what, image) in images {
            assert_eq!(tiny(YAML, &image), w, "{what}");
        }
        let p5_16: Vec<u8> = [b"P5 6 5 65535\n".as_slice(), &wide].concat();
        assert_eq!(tiny(YAML, &p5_16), w, "16-bit P5");
    }

    #[test]
    fn negate_thresholds_and_unknown_cells() {
        let w = tiny(YAML, &p2(&PIXELS));
        let inverted: Vec<u8> = PIXELS.iter().map(|v| 255 - v).collect();
        assert_eq!(tiny(&format!("{YAML}negate: 1\n"), &p5(&inverted)), w);
        // Unknown: neither wall nor spawn space.
        assert!(w.is_free(centre(1, 4), 0.1));
        assert!(!w.spawn.iter().any(|s| s.contains(centre(1, 4))));
        // With free_thresh 0.25 (the default), 205 is free: p = 50/255 = 0.196.
        let free = tiny(&YAML.replace("free_thresh: 0.196\n", ""), &p2(&PIXELS));
        assert_eq!(boxes(&free), boxes(&w));
        assert_eq!(free.spawn, [rect([-0.5, 3.5], [1.5, 4.0]), rect([0.5, 2.5], [1.5, 3.5])]);
        // With occupied_thresh 1, black (p = 1) is unknown, not occupied: no walls.
        let none = tiny(&format!("{YAML}occupied_thresh: 1\n"), &p2(&PIXELS));
        assert!(none.obstacles.is_empty());
        assert_eq!(none.spawn, w.spawn);
        // Unknown as occupied: the unknown cell joins the right wall, split differently.
        let opts = ImportOptions { unknown_is_occupied: true, ..coarse() };
        let walled = world(YAML, &p2(&PIXELS), &opts);
        let expected = [
            WALLS[0],
            WALLS[1],
            ([1.5, 3.75], [1.0, 0.5]),
            WALLS[3],
            ([1.75, 2.75], [0.5, 1.5]),
            WALLS[4],
        ];
        assert_eq!(boxes(&walled), expected.map(|(c, s)| (c, s, 0.0)));
        assert!(!walled.is_free(centre(1, 4), 0.1));
        assert_eq!(walled.spawn, w.spawn);
        // Taller walls.
        let opts = ImportOptions { wall_height_m: 0.3, ..coarse() };
        assert!(world(YAML, &p2(&PIXELS), &opts).obstacles.iter().all(|o| o.prism.z_max == 0.3));
    }

    #[test]
    fn pixels_are_classified_as_ros_map_server_does() {
        let px = |grey: u32, alpha: Option<u32>| Pixel { rgb_sum: 3 * grey, alpha, max: 255 };
        let trinary = meta(MapMode::Trinary, false);
        for (grey, cell) in [
            (0, Cell::Occupied),
            (89, Cell::Occupied),
            (90, Cell::Unknown),
            (205, Cell::Unknown),
            (206, Cell::Free),
            (255, Cell::Free),
        ] {
            assert_eq!(classify(&trinary, px(grey, None)), cell, "grey {grey}");
        }
        // Trinary averages alpha in: opaque lightens (205 becomes free), transparent darkens.
        assert_eq!(classify(&trinary, px(205, Some(255))), Cell::Free);
        assert_eq!(classify(&trinary, px(0, Some(255))), Cell::Occupied);
        assert_eq!(classify(&trinary, px(255, Some(0))), Cell::Unknown);
        // Negate: white is occupied.
        assert_eq!(classify(&meta(MapMode::Trinary, true), px(255, None)), Cell::Occupied);
        assert_eq!(classify(&meta(MapMode::Trinary, true), px(0, None)), Cell::Free);
        // Scale: not fully opaque is unknown, else alpha is ignored.
        let scale = meta(MapMode::Scale, false);
        assert_eq!(classify(&scale, px(255, Some(254))), Cell::Unknown);
        assert_eq!(classify(&scale, px(205, Some(255))), Cell::Unknown);
        assert_eq!(classify(&scale, px(0, Some(255))), Cell::Occupied);
        assert_eq!(classify(&scale, px(255, None)), Cell::Free);
        // Raw: the value is the occupancy in percent, above 100 unknown; negate is ignored.
        for negate in [false, true] {
            let raw = meta(MapMode::Raw, negate);
            for (v, cell) in [
                (0, Cell::Free),
                (19, Cell::Free),
                (50, Cell::Unknown),
                (66, Cell::Occupied),
                (100, Cell::Occupied),
                (101, Cell::Unknown),
                (255, Cell::Unknown),
            ] {
                assert_eq!(classify(&raw, px(v, Some(0))), cell, "raw {v}");
            }
        }
        // 16 bit: scaled by the maximum.
        let wide = Pixel { rgb_sum: 3 * 65535, alpha: None, max: 65535 };
        assert_eq!(classify(&trinary, wide), Cell::Free);
        assert_eq!(classify(&trinary, Pixel { rgb_sum: 3 * 20000, ..wide }), Cell::Occupied);
    }

    #[test]
    fn modes_and_alpha_end_to_end() {
        let w = tiny(YAML, &p2(&PIXELS));
        // Raw: 100 wall, 0 free, 255 unknown.
        let raw: Vec<u8> = PIXELS
            .iter()
            .map(|&v| match v {
                0 => 100,
                255 => 0,
                _ => 255,
            })
            .collect();
        assert_eq!(tiny(&format!("{YAML}mode: raw\n"), &p5(&raw)), w);
        // Opaque grey+alpha: scale mode ignores alpha, trinary averages it in (205 turns free).
        let ga: Vec<u8> = PIXELS.iter().flat_map(|&v| [v, 255]).collect();
        let ga = png(png::ColorType::GrayscaleAlpha, png::BitDepth::Eight, &ga, &[]);
        assert_eq!(tiny(&format!("{YAML}mode: scale\n"), &ga), w);
        let trinary = tiny(YAML, &ga);
        assert!(trinary.spawn.iter().any(|s| s.contains(centre(1, 4))));
        assert_eq!(boxes(&trinary), boxes(&w));
    }

    #[test]
    fn a_rotated_origin_turns_the_map_about_the_origin_point() {
        let yaml = YAML.replace("0.0]", &format!("{}]", std::f64::consts::FRAC_PI_2));
        let w = tiny(&yaml, &p2(&PIXELS));
        let turn = |[x, y]: [f32; 2]| [-1.0 - (y - 2.0), 2.0 + (x + 1.0)];
        for ((c, s, yaw), (c0, s0)) in boxes(&w).into_iter().zip(WALLS) {
            let expected = turn(c0);
            assert!(
                (c[0] - expected[0]).abs() < 1e-5 && (c[1] - expected[1]).abs() < 1e-5,
                "{c:?} vs {expected:?}"
            );
            assert_eq!((s, yaw), (s0, std::f32::consts::FRAC_PI_2));
        }
        assert_eq!(w.obstacles.len(), WALLS.len());
        let close =
            |a: &Aabb, b: &Aabb| (a.min - b.min).length() < 1e-5 && (a.max - b.max).length() < 1e-5;
        assert!(close(&w.bounds, &rect([-3.5, 2.0], [-1.0, 5.0])), "{:?}", w.bounds);
        // The kept spawn rectangle is the unrotated one, turned.
        assert_eq!(w.spawn.len(), 1);
        assert!(close(&w.spawn[0], &rect([-2.5, 3.5], [-1.5, 4.5])), "{:?}", w.spawn);
        assert!(!w.is_free(Vec2::new(-1.0 - 1.25, 2.0 + 0.25), 0.01), "turned wall cell (2, 2)");
        assert!(w.is_free(Vec2::new(-2.0, 4.0), 0.2));

        // Any angle: walls turn with the map; spawn cells come from free map cells.
        let yaw = 0.3f64;
        let w = tiny(&YAML.replace("0.0]", "0.3]"), &p2(&PIXELS));
        let (cos, sin) = (yaw.cos() as f32, yaw.sin() as f32);
        for ((c, s, got_yaw), (c0, s0)) in boxes(&w).into_iter().zip(WALLS) {
            let d = Vec2::new(c0[0] + 1.0, c0[1] - 2.0).rotate(cos, sin);
            assert!((Vec2::new(c[0], c[1]) - Vec2::new(d.x - 1.0, d.y + 2.0)).length() < 1e-5);
            assert_eq!((s, got_yaw), (s0, 0.3));
        }
        assert!(!w.spawn.is_empty());
        for s in &w.spawn {
            let (nx, ny) =
                ((s.size().x / 0.5).round() as usize, (s.size().y / 0.5).round() as usize);
            for (i, j) in (0..nx).flat_map(|i| (0..ny).map(move |j| (i, j))) {
                let p = s.min + Vec2::new(i as f32 + 0.5, j as f32 + 0.5) * 0.5;
                let m = Vec2::new(p.x + 1.0, p.y - 2.0).rotate(cos, -sin) * 2.0;
                let (col, row) = (m.x.floor() as usize, 4 - m.y.floor() as usize);
                assert_eq!(PIXELS[row * 6 + col], 255, "spawn point {p:?} in cell ({row}, {col})");
            }
        }
    }

    #[test]
    fn bad_input_is_a_specific_error() {
        let image = p2(&PIXELS);
        let opts = coarse();
        let cases: [(String, &[u8], &str); 7] = [
            (
                YAML.replace("resolution: 0.5\n", ""),
                &image,
                "maps/tiny.yaml: missing required key 'resolution'",
            ),
            (format!("{YAML}size: 3\n"), &image, "maps/tiny.yaml: line 5: unknown key 'size'"),
            (
                YAML.replace("0.5", "0"),
                &image,
                "resolution (line 2): must be a positive number of metres, got 0",
            ),
            (
                format!("{YAML}occupied_thresh: 0.1\n"),
                &image,
                "need 0 <= free_thresh < occupied_thresh <= 1",
            ),
            (YAML.into(), b"just some text", "maps/tiny.pgm: not a PGM (P2 or P5) or PNG image"),
            (YAML.into(), &image[..image.len() - 8], "maps/tiny.pgm: pixel data: truncated PGM"),
            (
                YAML.into(),
                &p5(&PIXELS)[..p5(&PIXELS).len() - 10],
                "maps/tiny.pgm: truncated PGM: 6x5 pixels need 30 bytes of data, the file has 20",
            ),
        ];
        for (yaml, image, needle) in cases {
            let e = err(&yaml, image, &opts);
            assert!(e.contains(needle), "'{e}' lacks '{needle}'");
        }
        // No room: every free cell touches a wall once the clearance is 0.6 m (1.2 cells).
        let tight = ImportOptions { spawn_clearance_m: 0.6, ..coarse() };
        let e = err(YAML, &image, &tight);
        assert!(e.contains("maps/tiny.yaml: free space: no free cell is farther than 0.95355344 m from every occupied cell (10 free of 30 cells)"), "{e}");
        let walled = ImportOptions { unknown_is_occupied: true, ..tight };
        assert!(err(YAML, &image, &walled).contains("occupied or unknown cell"));
        let e = err(YAML, &p2(&[0; 30]), &opts);
        assert!(e.contains("no free cell") && e.contains("(0 free of 30 cells)"), "{e}");
        let e = err(YAML, &image, &ImportOptions { wall_height_m: 0.0, ..coarse() });
        assert!(e.contains("options.wall_height_m: must be positive"), "{e}");
        let e = err(YAML, &image, &ImportOptions { spawn_clearance_m: f32::NAN, ..coarse() });
        assert!(e.contains("options.spawn_clearance_m"), "{e}");
        let e = err(&YAML.replace("[-1.0", "[1e30"), &image, &opts);
        assert!(e.contains("not a box in f32 coordinates") || e.contains("wall at row 0"), "{e}");
    }

    #[test]
    fn garbled_input_never_panics() {
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let images = [p2(&PIXELS), p5(&PIXELS), grey_png(&PIXELS)];
        let opts = coarse();
        for round in 0..3000 {
            let mut yaml = YAML.as_bytes().to_vec();
            let mut image = images[round % images.len()].clone();
            let target = if round % 4 == 0 { &mut yaml } else { &mut image };
            match next() % 3 {
                0 => target.truncate(next() as usize % (target.len() + 1)),
                1 => {
                    for _ in 0..1 + next() % 4 {
                        let i = next() as usize % target.len().max(1);
                        if let Some(b) = target.get_mut(i) {
                            *b = next() as u8;
                        }
                    }
                }
                _ => {
                    let i = next() as usize % (target.len() + 1);
                    let junk: Vec<u8> = (0..next() % 16).map(|_| next() as u8).collect();
                    target.splice(i..i, junk);
                }
            }
            let yaml = String::from_utf8_lossy(&yaml);
            let _ = import_from_parts("maps/tiny.yaml", &yaml, &image, &opts);
        }
    }
}
