//! The top view: a world from above, with the robot, its laser, pedestrians, the trajectory
//! and a legend.
//!
//! Picture layout, left to right: y-axis labels, the map (world x to the right, world y UP),
//! then a panel with the world's name, a scale bar, the axes and the legend; the caption runs
//! below everything. The map's place depends only on the world and the scale, never on the
//! caption, so the frames of an animation line up.

use crate::font::{self, ADVANCE, GLYPH_H, LINE_H};
use crate::image::Image;
use crate::style::{self, HeightClass, Rgb, mix};
use mdrlat_geom::{Aabb, Pose2, Shape, Vec2};
use mdrlat_world::World;
use tiny_skia::{
    FillRule, LineCap, LineJoin, Paint, Path, PathBuilder, Pixmap, Rect, Stroke, StrokeDash,
    Transform,
};

/// What to draw in a top view (world frame, metres).
#[derive(Debug, Clone, Copy)]
pub struct Scene<'a> {
    /// The world: floor, obstacles, spawn and goal regions.
    pub world: &'a World,
    /// The robot, if drawn.
    pub robot: Option<RobotMark>,
    /// Pedestrians at their current positions: centre, radius, height (metres). The height
    /// is not drawn: every pedestrian is tall enough for both sensors.
    pub pedestrians: &'a [(Vec2, f32, f32)],
    /// Laser rays from the sensor pose, if drawn.
    pub laser: Option<LaserRays<'a>>,
    /// Past robot positions, oldest first (the trajectory); a non-finite point separates
    /// trajectories (each start gets its ring).
    pub trail: &'a [Vec2],
    /// The navigation goal, if any.
    pub goal: Option<Vec2>,
    /// Further goals, marked as `goal` is (several episodes in one picture).
    pub goals: &'a [Vec2],
    /// Further robots, drawn as `robot` is (where several episodes ended, in one picture).
    pub robots: &'a [RobotMark],
    /// A line (or several, split at `\n`, wrapped to the picture's width, at most 40) drawn
    /// below the map, e.g. `"train  step 42  v 0.50 w -0.26  r 0.47"`.
    pub caption: Option<&'a str>,
}

impl<'a> Scene<'a> {
    /// Just the world: no robot, pedestrians, laser, trail, goal or caption.
    pub fn new(world: &'a World) -> Self {
        Scene {
            world,
            robot: None,
            pedestrians: &[],
            laser: None,
            trail: &[],
            goal: None,
            goals: &[],
            robots: &[],
            caption: None,
        }
    }
}

/// A world's picture on its own: its obstacles, spawn and goal regions, and its walkers at
/// the first point of their paths (where the file starts them; an episode draws their starts
/// along the paths), captioned with the world's name and description.
pub fn world_picture(world: &World, px_per_m: f32) -> crate::Image {
    let walkers: Vec<(Vec2, f32, f32)> = world
        .pedestrians
        .iter()
        .filter_map(|p| p.waypoints.first().map(|&at| (at, p.radius, p.height)))
        .collect();
    let mut caption = format!("{}: {}", world.name, world.description);
    if !walkers.is_empty() {
        caption.push_str(&format!(
            "\n{} walker{} drawn at the first point of {} path{}.",
            walkers.len(),
            if walkers.len() == 1 { "" } else { "s" },
            if walkers.len() == 1 { "its" } else { "their" },
            if walkers.len() == 1 { "" } else { "s" },
        ));
    }
    top_view(
        &Scene { caption: Some(&caption), pedestrians: &walkers, ..Scene::new(world) },
        px_per_m,
    )
}

/// The robot as drawn: a disc with a heading line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotMark {
    /// Pose in the world frame.
    pub pose: Pose2,
    /// Footprint radius, metres.
    pub radius: f32,
    /// Draw the robot red: it is in collision.
    pub collided: bool,
}

/// One laser scan to draw: rays from `origin` to each range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaserRays<'a> {
    /// The sensor pose in the world frame.
    pub origin: Pose2,
    /// Beam angles in the sensor frame, radians (counter-clockwise, 0 = straight ahead).
    pub angles: &'a [f32],
    /// Measured ranges, metres, one per angle (extra entries of either slice are ignored).
    /// Ranges at or beyond `max_range` (no return) are drawn faint and without a hit dot;
    /// zero, negative or non-finite ranges are not drawn. Every hit gets a dot; of a scan
    /// with more than 128 beams only every k-th ray is drawn as a line, so rays stay apart.
    pub ranges: &'a [f32],
    /// The sensor's maximum range, metres.
    pub max_range: f32,
}

/// Where the world lies in a top-view picture: world metres to picture pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapFrame {
    /// Pixels per metre actually used (the requested scale after clamping).
    pub px_per_m: f32,
    /// Picture column of the world's left edge (`bounds.min.x`).
    pub left_px: f32,
    /// Picture row of the world's top edge (`bounds.max.y`).
    pub top_px: f32,
    /// The world's bounds.
    pub bounds: Aabb,
}

impl MapFrame {
    /// The picture position (column, row; fractional) of world point `p`. Rows grow
    /// downwards, so world y points up in the picture.
    pub fn to_px(&self, p: Vec2) -> (f32, f32) {
        (
            self.left_px + (p.x - self.bounds.min.x) * self.px_per_m,
            self.top_px + (self.bounds.max.y - p.y) * self.px_per_m,
        )
    }

    /// The world point at picture position (column, row).
    pub fn to_world(&self, col: f32, row: f32) -> Vec2 {
        Vec2::new(
            self.bounds.min.x + (col - self.left_px) / self.px_per_m,
            self.bounds.max.y - (row - self.top_px) / self.px_per_m,
        )
    }
}

/// Spawn regions beyond this many are tinted, not outlined.
const MAX_OUTLINED_SPAWNS: usize = 16;

/// Largest map side, pixels: a larger `px_per_m` is reduced to fit.
const MAX_MAP_PX: f32 = 8000.0;

/// Caption lines drawn at most (after wrapping); the rest is dropped.
const MAX_CAPTION_LINES: usize = 40;

/// Where [`top_view`] puts the world for this scale, without drawing anything.
pub fn map_frame(world: &World, px_per_m: f32) -> MapFrame {
    Layout::new(world, px_per_m).frame
}

/// Draws `scene` from above at `px_per_m` pixels per metre.
///
/// `px_per_m` is clamped to [1, 1000] (non-finite: 40) and reduced further if the map would
/// exceed 8000 pixels a side; [`map_frame`] tells where the world landed. Text, margins and
/// marks grow with the scale (text doubles from 30 px/m, triples from 100 px/m).
pub fn top_view(scene: &Scene, px_per_m: f32) -> Image {
    let lay = Layout::new(scene.world, px_per_m);
    let caption_lines = match scene.caption {
        Some(c) if !c.is_empty() => font::wrap(c, lay.caption_chars()),
        _ => Vec::new(),
    };
    let caption_lines = &caption_lines[..caption_lines.len().min(MAX_CAPTION_LINES)];
    let caption_h = if caption_lines.is_empty() {
        0
    } else {
        caption_lines.len() as u32 * LINE_H * lay.ts + lay.pad
    };
    let (width, height) = (lay.width, lay.body_h + caption_h);
    let Some(mut pm) = Pixmap::new(width, height) else {
        return Image::new(width, height, rgba(style::PAGE));
    };
    let mut text = Texts::default();
    pm.fill(color(style::PAGE));
    draw_world(&mut pm, &lay, scene.world, &mut text);
    draw_marks(&mut pm, &lay, scene);
    draw_panel(&mut pm, &lay, scene.world, &mut text);
    for (i, line) in caption_lines.iter().enumerate() {
        let y = lay.body_h + i as u32 * LINE_H * lay.ts;
        text.push(lay.pad as i32, y as i32, line.clone(), style::INK);
    }
    for t in &text.items {
        font::draw_text_rgba(
            pm.data_mut(),
            width,
            height,
            (t.x, t.y),
            &t.text,
            lay.ts,
            rgba(t.rgb),
        );
    }
    // The page was filled opaque and everything since is drawn source-over.
    Image::from_opaque_pixmap(pm)
}

/// Sizes and places of everything but the caption.
struct Layout {
    frame: MapFrame,
    /// Text scale (font pixel size in picture pixels).
    ts: u32,
    /// Outer margin, pixels.
    pad: u32,
    map_h: u32,
    /// Metres between axis labels along x and y.
    tick_x: f32,
    tick_y: f32,
    /// Column of the panel's left edge.
    panel_x: u32,
    /// Picture width.
    width: u32,
    /// Height of everything above the caption.
    body_h: u32,
    /// Length of the scale bar, metres.
    bar_m: f32,
}

/// The legend: what each mark means, in drawing order.
#[derive(Clone, Copy)]
enum Key {
    Tall,
    Low,
    Overhang,
    Pedestrian,
    Robot,
    Collided,
    Laser,
    Trail,
    Goal,
    Spawn,
}

const KEYS: [(Key, &str); 10] = [
    (Key::Tall, "tall obstacle"),
    (Key::Low, "low, < 0.40 m"),
    (Key::Overhang, "overhang, z_min>0"),
    (Key::Pedestrian, "pedestrian"),
    (Key::Robot, "robot, heading"),
    (Key::Collided, "robot, collided"),
    (Key::Laser, "laser ray, hit"),
    (Key::Trail, "trajectory"),
    (Key::Goal, "goal"),
    (Key::Spawn, "spawn region"),
];

/// Notes under the legend.
const NOTES: [&str; 3] = ["darker = taller", "laser plane 0.40 m", "grid 1 m, y up"];

fn nice_step(min_m: f32) -> f32 {
    style::nice_step(min_m, 1.0)
}

/// The world coordinates of the axis labels along `[lo, hi]`: multiples of `step`.
fn ticks(lo: f32, hi: f32, step: f32) -> impl Iterator<Item = f32> {
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(move |k| k as f32 * step)
}

fn tick_label(v: f32) -> String {
    format!("{}", v.round() as i64)
}

impl Layout {
    fn new(world: &World, px_per_m: f32) -> Layout {
        let b = world.bounds;
        let size = b.size();
        let s = if px_per_m.is_finite() { px_per_m.clamp(1.0, 1000.0) } else { 40.0 };
        let s = s.min(MAX_MAP_PX / size.x.max(size.y).max(1e-3));
        let ts = if s >= 100.0 {
            3
        } else if s >= 30.0 {
            2
        } else {
            1
        };
        let pad = 8 * ts;
        let widest = |lo: f32, hi: f32| {
            font::text_width(&tick_label(lo), ts).max(font::text_width(&tick_label(hi), ts))
        };
        let label_w = widest(b.min.x.min(b.min.y), b.max.x.max(b.max.y));
        let tick_x = nice_step((label_w + 3 * ADVANCE * ts) as f32 / s);
        let tick_y = nice_step((2 * LINE_H * ts) as f32 / s);
        let y_label_w = ticks(b.min.y, b.max.y, tick_y)
            .map(|v| font::text_width(&tick_label(v), ts))
            .max()
            .unwrap_or(0);
        let left = pad + y_label_w + 4 * ts;
        let top = pad + 4 * ts;
        let map_w = (size.x * s).ceil() as u32;
        let map_h = (size.y * s).ceil() as u32;
        let below_map = 4 * ts + GLYPH_H * ts + pad;
        let bar_m = nice_step(16.0 * ts as f32 / s);
        let panel_x = left + map_w + 2 * pad + label_w / 2;
        let text_w = KEYS
            .iter()
            .map(|(_, t)| font::text_width(t, ts) + Self::swatch_w(ts) + 5 * ts)
            .chain(NOTES.iter().map(|t| font::text_width(t, ts)))
            .chain([
                font::text_width(&world.name, ts),
                (bar_m * s).ceil() as u32 + 4 * ts + font::text_width(&bar_label(bar_m), ts),
            ])
            .max()
            .unwrap_or(0);
        let width = panel_x + text_w + pad;
        let body_h = (top + map_h + below_map).max(top + Self::panel_h(ts) + pad);
        let frame = MapFrame { px_per_m: s, left_px: left as f32, top_px: top as f32, bounds: b };
        Layout { frame, ts, pad, map_h, tick_x, tick_y, panel_x, width, body_h, bar_m }
    }

    fn swatch_w(ts: u32) -> u32 {
        16 * ts
    }

    fn row_h(ts: u32) -> u32 {
        12 * ts
    }

    /// Height of the panel: title, scale bar, axes, keys, notes.
    fn panel_h(ts: u32) -> u32 {
        let l = LINE_H * ts;
        2 * l + 2 * l + 7 * l / 2 + KEYS.len() as u32 * Self::row_h(ts) + l + NOTES.len() as u32 * l
    }

    /// Characters per caption line.
    fn caption_chars(&self) -> usize {
        ((self.width - 2 * self.pad) / (ADVANCE * self.ts)).max(8) as usize
    }
}

fn bar_label(m: f32) -> String {
    format!("{} m", m.round() as i64)
}

/// Text drawn after all shapes, with the bitmap font.
#[derive(Default)]
struct Texts {
    items: Vec<TextItem>,
}

struct TextItem {
    x: i32,
    y: i32,
    text: String,
    rgb: Rgb,
}

impl Texts {
    fn push(&mut self, x: i32, y: i32, text: String, rgb: Rgb) {
        self.items.push(TextItem { x, y, text, rgb });
    }
}

fn rgba(c: Rgb) -> [u8; 4] {
    [c[0], c[1], c[2], 255]
}

fn color(c: Rgb) -> tiny_skia::Color {
    tiny_skia::Color::from_rgba8(c[0], c[1], c[2], 255)
}

fn paint(c: Rgb, alpha: u8) -> Paint<'static> {
    let mut p = Paint::default();
    p.set_color_rgba8(c[0], c[1], c[2], alpha);
    p.anti_alias = true;
    p
}

pub(crate) fn fill(pm: &mut Pixmap, path: &Path, c: Rgb, alpha: u8) {
    pm.fill_path(path, &paint(c, alpha), FillRule::Winding, Transform::identity(), None);
}

fn stroke_with(pm: &mut Pixmap, path: &Path, c: Rgb, alpha: u8, stroke: &Stroke) {
    pm.stroke_path(path, &paint(c, alpha), stroke, Transform::identity(), None);
}

pub(crate) fn stroke(pm: &mut Pixmap, path: &Path, c: Rgb, alpha: u8, width: f32) {
    let s =
        Stroke { width, line_cap: LineCap::Round, line_join: LineJoin::Round, ..Stroke::default() };
    stroke_with(pm, path, c, alpha, &s);
}

fn polygon(points: impl IntoIterator<Item = (f32, f32)>) -> Option<Path> {
    let mut pb = PathBuilder::new();
    for (i, (x, y)) in points.into_iter().enumerate() {
        if i == 0 {
            pb.move_to(x, y);
        } else {
            pb.line_to(x, y);
        }
    }
    pb.close();
    pb.finish()
}

fn rect_path(x0: f32, y0: f32, x1: f32, y1: f32) -> Option<Path> {
    Rect::from_ltrb(x0.min(x1), y0.min(y1), x0.max(x1), y0.max(y1)).map(PathBuilder::from_rect)
}

fn aabb_path(f: &MapFrame, r: &Aabb) -> Option<Path> {
    let (x0, y0) = f.to_px(r.min);
    let (x1, y1) = f.to_px(r.max);
    rect_path(x0, y0, x1, y1)
}

fn shape_path(f: &MapFrame, shape: &Shape) -> Option<Path> {
    match shape {
        Shape::Cylinder(c) => {
            let (x, y) = f.to_px(c.center);
            PathBuilder::from_circle(x, y, (c.radius * f.px_per_m).max(0.5))
        }
        Shape::Cuboid(b) => polygon(b.corners().iter().map(|&p| f.to_px(p))),
        Shape::Polygon(p) => polygon(p.points().iter().map(|&p| f.to_px(p))),
    }
}

/// Snaps a coordinate to a pixel centre, for crisp 1-pixel lines.
fn crisp(v: f32) -> f32 {
    v.floor() + 0.5
}

/// The part of segment `a`–`b` inside convex polygon `poly` (either winding), Cyrus–Beck.
fn clip_to_convex(poly: &[(f32, f32)], a: (f32, f32), b: (f32, f32)) -> Option<[(f32, f32); 2]> {
    let n = poly.len();
    if n < 3 {
        return None;
    }
    let cross = |u: (f32, f32), v: (f32, f32)| u.0 * v.1 - u.1 * v.0;
    let sub = |u: (f32, f32), v: (f32, f32)| (u.0 - v.0, u.1 - v.1);
    let area: f32 = (0..n).map(|i| cross(poly[i], poly[(i + 1) % n])).sum();
    let sign = if area >= 0.0 { 1.0 } else { -1.0 };
    let d = sub(b, a);
    let (mut t0, mut t1) = (0.0f32, 1.0f32);
    for i in 0..n {
        let (p, q) = (poly[i], poly[(i + 1) % n]);
        let e = sub(q, p);
        // Inside where sign·cross(e, x − p) >= 0; along the segment that is num + t·den.
        let num = sign * cross(e, sub(a, p));
        let den = sign * cross(e, d);
        if den.abs() < 1e-9 {
            if num < 0.0 {
                return None;
            }
            continue;
        }
        let t = -num / den;
        if den > 0.0 {
            t0 = t0.max(t);
        } else {
            t1 = t1.min(t);
        }
        if t0 >= t1 {
            return None;
        }
    }
    let at = |t: f32| (a.0 + d.0 * t, a.1 + d.1 * t);
    Some([at(t0), at(t1)])
}

/// Diagonal hatching (lower-left to upper-right) of a convex outline in picture pixels,
/// on a picture-wide lattice so neighbouring shapes' hatches line up.
fn hatch(outline: &[(f32, f32)], spacing: f32) -> Option<Path> {
    let (mut x0, mut y0, mut x1, mut y1) = (f32::MAX, f32::MAX, f32::MIN, f32::MIN);
    for &(x, y) in outline {
        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
    }
    // Lines x + y = c, spanning the bounding box rows.
    let mut pb = PathBuilder::new();
    let mut c = ((x0 + y0) / spacing).floor() * spacing;
    while c <= x1 + y1 {
        if let Some([p, q]) = clip_to_convex(outline, (c - y0, y0), (c - y1, y1)) {
            pb.move_to(p.0, p.1);
            pb.line_to(q.0, q.1);
        }
        c += spacing;
    }
    pb.finish()
}

/// The floor, grid, regions, obstacles and axis labels.
fn draw_world(pm: &mut Pixmap, lay: &Layout, world: &World, text: &mut Texts) {
    let f = &lay.frame;
    let ts = lay.ts as f32;
    let b = world.bounds;
    if let Some(p) = aabb_path(f, &b) {
        fill(pm, &p, style::FLOOR, 255);
    }
    // The 1 m grid (coarser when metres get too small to tell apart).
    let grid_m = if f.px_per_m >= 8.0 { 1.0 } else { lay.tick_x.max(lay.tick_y) };
    let (left, top) = f.to_px(Vec2::new(b.min.x, b.max.y));
    let (right, bottom) = f.to_px(Vec2::new(b.max.x, b.min.y));
    let mut pb = PathBuilder::new();
    for x in ticks(b.min.x, b.max.x, grid_m) {
        let px = crisp(f.to_px(Vec2::new(x, 0.0)).0);
        pb.move_to(px, top);
        pb.line_to(px, bottom);
    }
    for y in ticks(b.min.y, b.max.y, grid_m) {
        let py = crisp(f.to_px(Vec2::new(0.0, y)).1);
        pb.move_to(left, py);
        pb.line_to(right, py);
    }
    if let Some(p) = pb.finish() {
        stroke_with(pm, &p, style::GRID, 255, &Stroke { width: 1.0, ..Stroke::default() });
    }
    // Spawn regions: a faint dashed outline; goal regions: a translucent green square.
    let dashed = Stroke {
        width: 1.5 * ts,
        dash: StrokeDash::new(vec![6.0 * ts, 4.0 * ts], 0.0),
        ..Stroke::default()
    };
    // Imported maps have hundreds of spawn rectangles: outlines would hide the map, so
    // many regions are drawn as one faint tint instead.
    if world.spawn.len() > MAX_OUTLINED_SPAWNS {
        for r in &world.spawn {
            if let Some(p) = aabb_path(f, r) {
                fill(pm, &p, style::SPAWN, 40);
            }
        }
    } else {
        for r in &world.spawn {
            if let Some(p) = aabb_path(f, r) {
                stroke_with(pm, &p, style::SPAWN, 150, &dashed);
            }
        }
    }
    for r in &world.goals {
        if let Some(p) = aabb_path(f, r) {
            fill(pm, &p, style::GOAL, 60);
            stroke(pm, &p, style::GOAL, 200, 1.5 * ts);
        }
    }
    // Obstacles: low first, then tall, then the translucent overhangs on top.
    for class in [HeightClass::Low, HeightClass::Tall, HeightClass::Overhang] {
        for o in world.obstacles.iter().filter(|o| HeightClass::of(&o.prism) == class) {
            let Some(path) = shape_path(f, &o.prism.shape) else { continue };
            let c = style::obstacle_fill(&o.prism);
            if class == HeightClass::Overhang {
                fill(pm, &path, c, style::OVERHANG_FILL_ALPHA);
                let outline: Vec<_> =
                    o.prism.shape.outline(64).iter().map(|&p| f.to_px(p)).collect();
                if let Some(h) = hatch(&outline, 6.0 * ts) {
                    stroke(pm, &h, c, 190, 0.8 * ts);
                }
                stroke(pm, &path, c, 255, 1.2 * ts);
            } else {
                fill(pm, &path, c, 255);
                stroke(pm, &path, mix(c, [0, 0, 0], 0.35), 255, 1.0);
            }
        }
    }
    if let Some(p) = rect_path(crisp(left), crisp(top), crisp(right), crisp(bottom)) {
        stroke_with(pm, &p, style::BOUNDS, 255, &Stroke { width: 1.0, ..Stroke::default() });
    }
    // Axis labels: x below the map, y to its left, in metres.
    let ts_u = lay.ts;
    let label_y = (f.top_px as u32 + lay.map_h + 4 * ts_u) as i32;
    for x in ticks(b.min.x, b.max.x, lay.tick_x) {
        let s = tick_label(x);
        let px = f.to_px(Vec2::new(x, 0.0)).0 - font::text_width(&s, ts_u) as f32 / 2.0;
        text.push(px.round() as i32, label_y, s, style::INK_DIM);
    }
    for y in ticks(b.min.y, b.max.y, lay.tick_y) {
        let s = tick_label(y);
        let px = f.left_px as i32 - (4 * ts_u + font::text_width(&s, ts_u)) as i32;
        let py = f.to_px(Vec2::new(0.0, y)).1 - (7 * ts_u) as f32 / 2.0;
        text.push(px, py.round() as i32, s, style::INK_DIM);
    }
}

/// The scene's marks over the world: trail, laser, pedestrians, goal, robot.
fn draw_marks(pm: &mut Pixmap, lay: &Layout, scene: &Scene) {
    let f = &lay.frame;
    let ts = lay.ts as f32;
    let s = f.px_per_m;
    // Trajectory: a polyline, broken at non-finite points, with a ring at each start.
    let mut pb = PathBuilder::new();
    let mut pen_down = false;
    let mut starts = Vec::new();
    for &p in scene.trail {
        if !p.is_finite() {
            pen_down = false;
            continue;
        }
        let (x, y) = f.to_px(p);
        if pen_down {
            pb.line_to(x, y);
        } else {
            pb.move_to(x, y);
            starts.push((x, y));
            pen_down = true;
        }
    }
    if let Some(path) = pb.finish() {
        stroke(pm, &path, style::TRAIL, 220, 1.5 * ts);
    }
    for (x, y) in starts {
        if let Some(c) = PathBuilder::from_circle(x, y, 2.5 * ts) {
            stroke(pm, &c, style::TRAIL, 255, 1.0 * ts);
        }
    }
    if let Some(l) = &scene.laser {
        draw_laser(pm, f, l, ts);
    }
    for &(c, r, _height) in scene.pedestrians {
        if !(c.is_finite() && r.is_finite() && r > 0.0) {
            continue;
        }
        let (x, y) = f.to_px(c);
        let r_px = (r * s).max(1.5);
        if let Some(p) = PathBuilder::from_circle(x, y, r_px) {
            fill(pm, &p, style::PEDESTRIAN, 225);
            stroke(pm, &p, style::PEDESTRIAN_DARK, 255, 1.0);
        }
        if let Some(p) = PathBuilder::from_circle(x, y, (0.22 * r_px).max(1.2)) {
            fill(pm, &p, [255, 255, 255], 255);
        }
    }
    for &g in scene.goal.iter().chain(scene.goals).filter(|g| g.is_finite()) {
        let (x, y) = f.to_px(g);
        let h = (0.12 * s).max(4.0 * ts);
        if let Some(p) = rect_path(x - h, y - h, x + h, y + h) {
            fill(pm, &p, style::GOAL, 255);
            stroke(pm, &p, style::GOAL_DARK, 255, 1.0 * ts);
        }
    }
    for r in scene.robots.iter().chain(&scene.robot) {
        draw_robot(pm, f, r, ts);
    }
}

/// Most laser rays drawn as lines; denser scans are thinned (hits are all drawn).
const MAX_RAY_LINES: usize = 128;

fn draw_laser(pm: &mut Pixmap, f: &MapFrame, l: &LaserRays, ts: f32) {
    let o = l.origin.position();
    if !o.is_finite() {
        return;
    }
    let (ox, oy) = f.to_px(o);
    let (mut hits, mut misses, mut dots) =
        (PathBuilder::new(), PathBuilder::new(), PathBuilder::new());
    let dot_r = 0.9 * ts + 0.4;
    // Dense scans (a 512-beam laser) would merge into a solid fan: draw every k-th ray as a
    // line (at most MAX_RAY_LINES) and every hit as a dot.
    let n = l.angles.len().min(l.ranges.len());
    let stride = n.div_ceil(MAX_RAY_LINES).max(1);
    for (i, (&a, &r)) in l.angles.iter().zip(l.ranges).enumerate() {
        if !(r.is_finite() && r > 0.0 && a.is_finite()) {
            continue;
        }
        let dir = Vec2::from_angle(l.origin.yaw + a);
        let no_return = l.max_range.is_finite() && r >= l.max_range * 0.999;
        let (ex, ey) = f.to_px(o + dir * r);
        if i % stride == 0 {
            let path = if no_return { &mut misses } else { &mut hits };
            path.move_to(ox, oy);
            path.line_to(ex, ey);
        }
        if !no_return {
            dots.push_circle(ex, ey, dot_r);
        }
    }
    // Width 1: tiny-skia draws it as a fast anti-aliased hairline.
    let thin = 1.0;
    if let Some(p) = misses.finish() {
        stroke(pm, &p, style::LASER, 28, thin);
    }
    if let Some(p) = hits.finish() {
        stroke(pm, &p, style::LASER, 70, thin);
    }
    if let Some(p) = dots.finish() {
        fill(pm, &p, style::LASER, 230);
    }
}

fn draw_robot(pm: &mut Pixmap, f: &MapFrame, r: &RobotMark, ts: f32) {
    let c = r.pose.position();
    if !(c.is_finite() && r.pose.yaw.is_finite()) {
        return;
    }
    let (x, y) = f.to_px(c);
    let r_px = (r.radius * f.px_per_m).max(3.0 * ts);
    let body = if r.collided { style::ROBOT_HIT } else { style::ROBOT };
    if let Some(p) = PathBuilder::from_circle(x, y, r_px) {
        fill(pm, &p, body, 235);
        stroke(pm, &p, style::ROBOT_DARK, 255, 1.0 * ts);
    }
    // Heading: from the centre to just past the rim. Picture rows grow downwards.
    let (s, co) = r.pose.yaw.sin_cos();
    let tip = (x + co * r_px * 1.25, y - s * r_px * 1.25);
    let mut pb = PathBuilder::new();
    pb.move_to(x, y);
    pb.line_to(tip.0, tip.1);
    if let Some(p) = pb.finish() {
        stroke(pm, &p, style::ROBOT_DARK, 255, (0.16 * r_px).max(1.5 * ts));
    }
}

/// A legend swatch's mark, drawn in the box `(x, y, w, h)`.
fn draw_key(pm: &mut Pixmap, key: Key, (x, y, w, h): (f32, f32, f32, f32), ts: f32) {
    let (cx, cy) = (x + w / 2.0, y + h / 2.0);
    let boxed = rect_path(x, y, x + w, y + h);
    match key {
        Key::Tall => {
            // Two halves: the lightest and the darkest tall shade.
            if let Some(p) = rect_path(x, y, cx, y + h) {
                fill(pm, &p, style::TALL_LIGHT, 255);
            }
            if let Some(p) = rect_path(cx, y, x + w, y + h) {
                fill(pm, &p, style::TALL_DARK, 255);
            }
        }
        Key::Low => {
            if let Some(p) = rect_path(x, y, cx, y + h) {
                fill(pm, &p, style::LOW_LIGHT, 255);
            }
            if let Some(p) = rect_path(cx, y, x + w, y + h) {
                fill(pm, &p, style::LOW_DARK, 255);
            }
        }
        Key::Overhang => {
            if let Some(p) = &boxed {
                fill(pm, p, style::OVERHANG, style::OVERHANG_FILL_ALPHA);
                let outline = [(x, y), (x + w, y), (x + w, y + h), (x, y + h)];
                if let Some(hp) = hatch(&outline, 6.0 * ts) {
                    stroke(pm, &hp, style::OVERHANG, 190, 0.8 * ts);
                }
                stroke(pm, p, style::OVERHANG, 255, 1.2 * ts);
            }
        }
        Key::Pedestrian => {
            if let Some(p) = PathBuilder::from_circle(cx, cy, h / 2.0) {
                fill(pm, &p, style::PEDESTRIAN, 225);
                stroke(pm, &p, style::PEDESTRIAN_DARK, 255, 1.0);
            }
            if let Some(p) = PathBuilder::from_circle(cx, cy, (0.11 * h).max(1.2)) {
                fill(pm, &p, [255, 255, 255], 255);
            }
        }
        Key::Robot | Key::Collided => {
            let mark = RobotMark {
                pose: Pose2::new(0.0, 0.0, 0.0),
                radius: h / 2.0,
                collided: matches!(key, Key::Collided),
            };
            let unit = MapFrame {
                px_per_m: 1.0,
                left_px: cx - w / 4.0,
                top_px: cy,
                bounds: Aabb::new(Vec2::ZERO, Vec2::ZERO),
            };
            draw_robot(pm, &unit, &mark, ts);
        }
        Key::Laser => {
            let mut pb = PathBuilder::new();
            pb.move_to(x, cy);
            pb.line_to(x + w - 2.0 * ts, cy);
            if let Some(p) = pb.finish() {
                stroke(pm, &p, style::LASER, 110, 0.8 * ts);
            }
            if let Some(p) = PathBuilder::from_circle(x + w - 2.0 * ts, cy, 0.9 * ts + 0.4) {
                fill(pm, &p, style::LASER, 230);
            }
        }
        Key::Trail => {
            let mut pb = PathBuilder::new();
            pb.move_to(x, y + h);
            pb.line_to(x + w / 3.0, y + h / 3.0);
            pb.line_to(x + 2.0 * w / 3.0, y + 2.0 * h / 3.0);
            pb.line_to(x + w, y);
            if let Some(p) = pb.finish() {
                stroke(pm, &p, style::TRAIL, 220, 1.5 * ts);
            }
        }
        Key::Goal => {
            if let Some(p) = rect_path(cx - h / 2.0, y, cx + h / 2.0, y + h) {
                fill(pm, &p, style::GOAL, 255);
                stroke(pm, &p, style::GOAL_DARK, 255, 1.0 * ts);
            }
        }
        Key::Spawn => {
            if let Some(p) = &boxed {
                let dashed = Stroke {
                    width: 1.5 * ts,
                    dash: StrokeDash::new(vec![4.0 * ts, 3.0 * ts], 0.0),
                    ..Stroke::default()
                };
                stroke_with(pm, p, style::SPAWN, 150, &dashed);
            }
        }
    }
}

/// The panel right of the map: title, scale bar, axes, legend and notes.
fn draw_panel(pm: &mut Pixmap, lay: &Layout, world: &World, text: &mut Texts) {
    let ts_u = lay.ts;
    let ts = ts_u as f32;
    let line = (LINE_H * ts_u) as f32;
    let x = lay.panel_x as f32;
    let mut y = lay.frame.top_px;
    text.push(x as i32, y as i32, world.name.clone(), style::INK);
    y += 2.0 * line;
    // Scale bar, with end ticks.
    let bar_px = lay.bar_m * lay.frame.px_per_m;
    let mid = crisp(y + 3.5 * ts);
    let mut pb = PathBuilder::new();
    pb.move_to(x, mid);
    pb.line_to(x + bar_px, mid);
    pb.move_to(x, mid - 3.0 * ts);
    pb.line_to(x, mid + 3.0 * ts);
    pb.move_to(x + bar_px, mid - 3.0 * ts);
    pb.line_to(x + bar_px, mid + 3.0 * ts);
    if let Some(p) = pb.finish() {
        stroke_with(pm, &p, style::INK, 255, &Stroke { width: 1.5 * ts, ..Stroke::default() });
    }
    text.push((x + bar_px + 4.0 * ts) as i32, y as i32, bar_label(lay.bar_m), style::INK);
    y += 2.0 * line;
    // Axes: x to the right, y up.
    let len = 2.0 * line;
    let (ax, ay) = (x + 1.0 * ts, y + 2.5 * line);
    let mut pb = PathBuilder::new();
    pb.move_to(ax, ay);
    pb.line_to(ax + len, ay);
    pb.move_to(ax + len - 3.0 * ts, ay - 3.0 * ts);
    pb.line_to(ax + len, ay);
    pb.line_to(ax + len - 3.0 * ts, ay + 3.0 * ts);
    pb.move_to(ax, ay);
    pb.line_to(ax, ay - len);
    pb.move_to(ax - 3.0 * ts, ay - len + 3.0 * ts);
    pb.line_to(ax, ay - len);
    pb.line_to(ax + 3.0 * ts, ay - len + 3.0 * ts);
    if let Some(p) = pb.finish() {
        stroke(pm, &p, style::INK, 255, 1.2 * ts);
    }
    let glyph_mid = (GLYPH_H * ts_u) as f32 / 2.0;
    text.push((ax + len + 3.0 * ts) as i32, (ay - glyph_mid) as i32, "x".into(), style::INK);
    text.push((ax + 4.0 * ts) as i32, (ay - len - 1.0 * ts) as i32, "y".into(), style::INK);
    y += 3.5 * line;
    // Legend.
    let (sw, sh) = (Layout::swatch_w(ts_u) as f32, 9.0 * ts);
    for (key, label) in KEYS {
        draw_key(pm, key, (x, y, sw, sh), ts);
        let ty = y + sh / 2.0 - (7 * ts_u) as f32 / 2.0;
        text.push((x + sw + 5.0 * ts) as i32, ty.round() as i32, label.into(), style::INK);
        y += Layout::row_h(ts_u) as f32;
    }
    y += line;
    for note in NOTES {
        text.push(x as i32, y as i32, note.into(), style::INK_DIM);
        y += line;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipping_a_segment_to_a_square() {
        let sq = [(0.0, 0.0), (0.0, 2.0), (2.0, 2.0), (2.0, 0.0)];
        let [p, q] = clip_to_convex(&sq, (-1.0, 1.0), (3.0, 1.0)).expect("crosses");
        assert!((p.0 - 0.0).abs() < 1e-5 && (q.0 - 2.0).abs() < 1e-5, "{p:?} {q:?}");
        assert!(clip_to_convex(&sq, (-1.0, 3.0), (3.0, 3.0)).is_none());
        let rev: Vec<_> = sq.iter().rev().copied().collect();
        assert!(clip_to_convex(&rev, (1.0, -5.0), (1.0, 5.0)).is_some());
    }

    #[test]
    fn ticks_are_multiples_of_the_step() {
        let t: Vec<f32> = ticks(-1.5, 4.2, 2.0).collect();
        assert_eq!(t, vec![0.0, 2.0, 4.0]);
    }
}
