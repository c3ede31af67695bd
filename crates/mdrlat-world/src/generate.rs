//! Procedural worlds: rooms, corridors and doors, furniture of every height class and
//! walkers, from a seed (`mdrlat world generate --seed N`).
//!
//! A floor of 8–14 m a side is split recursively (a binary space partition) by walls
//! 0.1 m thick, each with one door 0.9–1.2 m wide, until no room is longer than 5 m: every
//! room is reachable from every other. Each room gets furniture drawn from the classes the
//! paper's worlds have — tall boxes and posts (both sensors see them), low boxes and stools
//! under the 0.40 m laser plane and shelves overhanging from 0.42 m (only the depth camera
//! sees them), tables whose tops pass over the robot on thin legs, hexagonal columns — each
//! kept [`GAP_M`] from every other item, from the room's walls (shelves stand against one)
//! and 1 m clear of every door, so the robot can drive around all of them. Rooms long
//! enough get a walker pacing their length. The same seed gives the same text, byte for
//! byte; the result is an ordinary world file, validated as one.
//!
//! Two families share the rooms and doors ([`Family`]): `gen-N`, the furniture above, and
//! `home-N`, which adds the household furniture a depth camera must read — coffee tables
//! (a 5 cm slab between 0.28 and 0.39 m on thin legs: under the laser plane and seen
//! almost edge-on by a camera at 0.30 m), chairs (a seat at 0.42–0.47 m on four thin legs the laser sees as
//! posts, with a backrest) and benches (a seat between two end panels). `gen-N` worlds are
//! unchanged by it, byte for byte.

use crate::{World, WorldError};
use mdrlat_core::Rng;
use std::fmt::Write as _;

/// Free space kept between furniture, and between furniture and walls, metres (the robot's
/// 0.354 m diameter and a margin).
pub const GAP_M: f32 = 0.55;

/// Walls' height, metres.
const WALL_H: f32 = 2.5;
/// Walls' thickness, metres.
const WALL_T: f32 = 0.1;
/// A room longer than this is split.
const MAX_ROOM_M: f32 = 5.0;

/// An axis-aligned rectangle: `[x0, y0, x1, y1]`.
type Rect = [f32; 4];

fn overlaps(a: &Rect, b: &Rect) -> bool {
    a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3]
}

fn grown(r: &Rect, m: f32) -> Rect {
    [r[0] - m, r[1] - m, r[2] + m, r[3] + m]
}

/// Rounds to centimetres, so the file reads cleanly.
fn cm(x: f32) -> f32 {
    (x * 100.0).round() / 100.0
}

/// A family of generated worlds: the same rooms and doors, different furniture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    /// `gen-N`: boxes, low boxes, stools, posts, tables, shelves, columns.
    Gen,
    /// `home-N`: the same and coffee tables, chairs and benches.
    Home,
}

impl Family {
    /// Every family.
    pub const ALL: [Family; 2] = [Family::Gen, Family::Home];

    /// The prefix of its world names: `gen-`, `home-`.
    pub fn prefix(self) -> &'static str {
        match self {
            Family::Gen => "gen-",
            Family::Home => "home-",
        }
    }

    /// How many furniture kinds it draws from.
    fn kinds(self) -> usize {
        match self {
            Family::Gen => 7,
            Family::Home => 10,
        }
    }

    /// The family and seed a world name such as `home-12` stands for.
    pub fn parse(name: &str) -> Option<(Family, u64)> {
        Family::ALL.into_iter().find_map(|f| {
            name.strip_prefix(f.prefix()).and_then(|n| n.parse::<u64>().ok()).map(|s| (f, s))
        })
    }
}

/// What the generator writes, before it becomes text.
struct Builder {
    rng: Rng,
    family: Family,
    text: String,
    /// Footprints of the furniture placed so far, and the doors' keep-clear squares.
    taken: Vec<Rect>,
    rooms: Vec<Rect>,
    doors: Vec<Rect>,
}

impl Builder {
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        cm(self.rng.range_f32(lo, hi))
    }

    fn boxed(&mut self, c: [f32; 2], size: [f32; 2], z: [f32; 2], label: &str) {
        let _ = writeln!(
            self.text,
            "  {{ shape = \"box\", center = [{}, {}], size = [{}, {}], z = [{}, {}], label = \"{label}\" }},",
            cm(c[0]),
            cm(c[1]),
            cm(size[0]),
            cm(size[1]),
            z[0],
            z[1]
        );
    }

    fn cylinder(&mut self, c: [f32; 2], r: f32, z: [f32; 2], label: &str) {
        let _ = writeln!(
            self.text,
            "  {{ shape = \"cylinder\", center = [{}, {}], radius = {}, z = [{}, {}], label = \"{label}\" }},",
            cm(c[0]),
            cm(c[1]),
            cm(r),
            z[0],
            z[1]
        );
    }

    /// A wall along x (`horizontal`) or y at `fixed`, from `from` to `to`, with one door
    /// Four thin legs of radius `r` under the corners of a `hx` × `hy` top, up to `top`.
    fn legs(&mut self, c: [f32; 2], hx: f32, hy: f32, r: f32, top: f32, label: &str) {
        for (sx, sy) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
            let leg = [c[0] + sx * (hx - r - 0.01), c[1] + sy * (hy - r - 0.01)];
            self.cylinder(leg, r, [0.0, top], label);
        }
    }

    /// 0.9–1.2 m wide somewhere along it (kept clear of furniture).
    fn wall_with_door(&mut self, horizontal: bool, fixed: f32, from: f32, to: f32) {
        let width = self.range(0.9, 1.2);
        let at = self.range(from + 0.3 + width / 2.0, to - 0.3 - width / 2.0);
        let (a, b) = (at - width / 2.0, at + width / 2.0);
        for (s, e) in [(from, a), (b, to)] {
            if e - s <= 0.0 {
                continue;
            }
            let (c, size) = if horizontal {
                ([(s + e) / 2.0, fixed], [e - s, WALL_T])
            } else {
                ([fixed, (s + e) / 2.0], [WALL_T, e - s])
            };
            self.boxed(c, size, [0.0, WALL_H], "wall");
        }
        let door = if horizontal { [at, fixed] } else { [fixed, at] };
        self.doors.push([door[0] - 1.0, door[1] - 1.0, door[0] + 1.0, door[1] + 1.0]);
    }

    /// Splits `r` into rooms.
    fn split(&mut self, r: Rect) {
        let (w, h) = (r[2] - r[0], r[3] - r[1]);
        if w.max(h) <= MAX_ROOM_M {
            self.rooms.push(r);
            return;
        }
        let vertical = w >= h;
        let (lo, hi) = if vertical { (r[0], r[2]) } else { (r[1], r[3]) };
        let at = self.range(lo + 0.4 * (hi - lo), lo + 0.6 * (hi - lo));
        let t = WALL_T / 2.0;
        if vertical {
            self.wall_with_door(false, at, r[1], r[3]);
            self.split([r[0], r[1], at - t, r[3]]);
            self.split([at + t, r[1], r[2], r[3]]);
        } else {
            self.wall_with_door(true, at, r[0], r[2]);
            self.split([r[0], r[1], r[2], at - t]);
            self.split([r[0], at + t, r[2], r[3]]);
        }
    }

    /// Whether a footprint fits: clear of the furniture (by the gap) and of the doors.
    fn free(&self, f: &Rect) -> bool {
        let g = grown(f, GAP_M);
        !self.taken.iter().any(|t| overlaps(&g, t)) && !self.doors.iter().any(|d| overlaps(f, d))
    }

    /// One piece of furniture in `room`, if a free place is found.
    fn furnish(&mut self, room: Rect) {
        let kind = self.rng.below(self.family.kinds());
        for _ in 0..30 {
            // Footprint half-sizes, then a centre kept GAP_M from the walls.
            let (hx, hy) = match kind {
                0 | 1 => (self.range(0.15, 0.45), self.range(0.15, 0.45)),
                2 | 3 => {
                    let r = self.range(0.1, 0.25);
                    (r, r)
                }
                4 => (self.range(0.4, 0.7), self.range(0.3, 0.45)),
                5 => (self.range(0.4, 0.6), 0.2),
                7 => (self.range(0.35, 0.6), self.range(0.25, 0.4)),
                8 => {
                    let h = self.range(0.19, 0.23);
                    (h, h)
                }
                9 => (self.range(0.45, 0.7), 0.18),
                _ => (0.28, 0.28),
            };
            let (x0, x1) = (room[0] + GAP_M + hx, room[2] - GAP_M - hx);
            let (y0, y1) = (room[1] + GAP_M + hy, room[3] - GAP_M - hy);
            if x1 <= x0 || y1 <= y0 {
                return;
            }
            let mut c = [self.range(x0, x1), self.range(y0, y1)];
            if kind == 5 {
                // A shelf stands against the room's south or north wall.
                c[1] = if self.rng.below(2) == 0 { room[1] + hy } else { room[3] - hy };
            }
            let f = [c[0] - hx, c[1] - hy, c[0] + hx, c[1] + hy];
            if !self.free(&f) {
                continue;
            }
            self.taken.push(f);
            let size = [2.0 * hx, 2.0 * hy];
            match kind {
                0 => {
                    let z = self.range(0.8, 1.6);
                    self.boxed(c, size, [0.0, z], "box");
                }
                1 => {
                    let z = self.range(0.1, 0.3);
                    self.boxed(c, size, [0.0, z], "low box");
                }
                2 => {
                    self.cylinder(c, hx, [0.0, 0.35], "stool");
                }
                3 => {
                    let z = self.range(0.9, 1.6);
                    self.cylinder(c, hx, [0.0, z], "post");
                }
                4 => {
                    self.boxed(c, size, [0.7, 0.74], "table top");
                    for (sx, sy) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
                        let leg = [c[0] + sx * (hx - 0.05), c[1] + sy * (hy - 0.05)];
                        self.cylinder(leg, 0.03, [0.0, 0.7], "table leg");
                    }
                }
                5 => {
                    self.boxed(c, size, [0.42, 0.9], "shelf");
                }
                7 => {
                    // A coffee table: a 5 cm slab around the camera's height on thin legs.
                    let z = self.range(0.28, 0.34);
                    self.boxed(c, size, [z, z + 0.05], "coffee table top");
                    self.legs(c, hx, hy, 0.025, z, "coffee table leg");
                }
                8 => {
                    // A chair: a seat the laser passes under, its legs, a backrest on one side.
                    self.boxed(c, size, [0.42, 0.47], "chair seat");
                    self.legs(c, hx, hy, 0.02, 0.42, "chair leg");
                    let side = if self.rng.below(2) == 0 { -1.0 } else { 1.0 };
                    let back = [c[0], c[1] + side * (hy - 0.02)];
                    self.boxed(back, [2.0 * hx, 0.04], [0.47, 0.9], "chair back");
                }
                9 => {
                    // A bench: a seat between two end panels the laser sees.
                    let z = self.range(0.4, 0.44);
                    self.boxed(c, size, [z, z + 0.05], "bench seat");
                    for sx in [-1.0, 1.0] {
                        let end = [c[0] + sx * (hx - 0.02), c[1]];
                        self.boxed(end, [0.04, 2.0 * hy], [0.0, z], "bench end");
                    }
                }
                _ => {
                    let z = self.range(1.2, 2.0);
                    let pts: Vec<String> = (0..6)
                        .map(|k| {
                            let a = std::f32::consts::PI / 3.0 * k as f32;
                            format!(
                                "[{}, {}]",
                                cm(c[0] + 0.28 * a.cos()),
                                cm(c[1] + 0.28 * a.sin())
                            )
                        })
                        .collect();
                    let _ = writeln!(
                        self.text,
                        "  {{ shape = \"polygon\", points = [{}], z = [0.0, {z}], label = \"column\" }},",
                        pts.join(", ")
                    );
                }
            }
            return;
        }
    }
}

/// The `gen-N` world file of seed `seed` (TOML text, comments included).
pub fn generate_toml(seed: u64) -> String {
    family_toml(Family::Gen, seed)
}

/// The world file of `family` and `seed` (TOML text, comments included).
pub fn family_toml(family: Family, seed: u64) -> String {
    let mut b = Builder {
        family,
        rng: Rng::derive(seed, 0x6E4E),
        text: String::new(),
        taken: Vec::new(),
        rooms: Vec::new(),
        doors: Vec::new(),
    };
    let (w, h) = (b.range(8.0, 14.0), b.range(8.0, 14.0));
    match family {
        Family::Gen => {
            let _ = writeln!(
                b.text,
                "# Generated by `mdrlat world generate --seed {seed}`: rooms split by walls with \
                 one door each,\n# furniture of every height class, walkers. The same seed gives \
                 this file again.\n\nversion = 1\nname = \"gen-{seed}\"\ndescription = \"A \
                 generated world (seed {seed}): {w} m x {h} m of rooms, doors, furniture of every \
                 height class and walkers.\""
            );
        }
        Family::Home => {
            let _ = writeln!(
                b.text,
                "# Generated by `mdrlat world generate --family home --seed {seed}`: rooms split \
                 by walls with one door each,\n# furniture of every height class with coffee \
                 tables, chairs and benches, walkers. The same seed gives this file again.\n\n\
                 version = 1\nname = \"home-{seed}\"\ndescription = \"A generated home (seed \
                 {seed}): {w} m x {h} m of rooms, doors, furniture of every height class with \
                 coffee tables, chairs and benches, and walkers.\""
            );
        }
    }
    let _ = writeln!(b.text, "bounds = {{ min = [0.0, 0.0], max = [{w}, {h}] }}\n\nobstacle = [");
    for (c, size) in [
        ([w / 2.0, WALL_T / 2.0], [w, WALL_T]),
        ([w / 2.0, h - WALL_T / 2.0], [w, WALL_T]),
        ([WALL_T / 2.0, h / 2.0], [WALL_T, h - 2.0 * WALL_T]),
        ([w - WALL_T / 2.0, h / 2.0], [WALL_T, h - 2.0 * WALL_T]),
    ] {
        b.boxed(c, size, [0.0, WALL_H], "wall");
    }
    b.split([WALL_T, WALL_T, w - WALL_T, h - WALL_T]);
    let rooms = b.rooms.clone();
    for &room in &rooms {
        let area = (room[2] - room[0]) * (room[3] - room[1]);
        let n = (area / 3.5).round() as usize + b.rng.below(2);
        for _ in 0..n {
            b.furnish(room);
        }
    }
    let _ = b.text.pop();
    b.text.push_str("\n]\n\n# Every room, 0.45 m in from its walls.\nspawn = [\n");
    for r in &rooms {
        let _ = writeln!(
            b.text,
            "  {{ min = [{}, {}], max = [{}, {}] }},",
            cm(r[0] + 0.45),
            cm(r[1] + 0.45),
            cm(r[2] - 0.45),
            cm(r[3] - 0.45)
        );
    }
    b.text.push_str("]\n\n# Walkers pacing the rooms long enough, on a line clear of the furniture.\npedestrian = [\n");
    for r in &rooms {
        let (rw, rh) = (r[2] - r[0], r[3] - r[1]);
        if rw.max(rh) < 3.0 || b.rng.below(2) == 0 {
            continue;
        }
        let off = b.range(-0.3, 0.3);
        let (p, q) = if rw >= rh {
            let y = (r[1] + r[3]) / 2.0 + off;
            ([r[0] + 0.6, y], [r[2] - 0.6, y])
        } else {
            let x = (r[0] + r[2]) / 2.0 + off;
            ([x, r[1] + 0.6], [x, r[3] - 0.6])
        };
        let lane = [
            p[0].min(q[0]) - 0.4,
            p[1].min(q[1]) - 0.4,
            p[0].max(q[0]) + 0.4,
            p[1].max(q[1]) + 0.4,
        ];
        if b.taken.iter().any(|t| overlaps(&lane, t)) {
            continue;
        }
        let speed = b.range(0.3, 1.0);
        let _ = writeln!(
            b.text,
            "  {{ waypoints = [[{}, {}], [{}, {}]], speed = {speed} }},",
            cm(p[0]),
            cm(p[1]),
            cm(q[0]),
            cm(q[1])
        );
    }
    b.text.push_str("]\n");
    b.text
}

/// The `gen-N` world of seed `seed`, validated.
///
/// # Errors
/// The generated file fails validation (a generator bug: tested not to happen).
pub fn generate(seed: u64) -> Result<World, WorldError> {
    generate_family(Family::Gen, seed)
}

/// The world of `family` and `seed`, validated.
///
/// # Errors
/// The generated file fails validation (a generator bug: tested not to happen).
pub fn generate_family(family: Family, seed: u64) -> Result<World, WorldError> {
    World::from_toml(
        &format!("generated world {}{seed}", family.prefix()),
        &family_toml(family, seed),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_seed_gives_the_same_file_and_every_world_is_valid() {
        assert_eq!(generate_toml(3), generate_toml(3));
        assert_ne!(generate_toml(3), generate_toml(4));
        let mut classes = [0usize; 3];
        for seed in 0..60 {
            let w = generate(seed).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
            assert!(w.obstacles.len() >= 8, "seed {seed}: {} obstacles", w.obstacles.len());
            assert!(!w.spawn.is_empty());
            let text = generate_toml(seed);
            classes[0] += usize::from(text.contains("\"box\"") || text.contains("\"post\""));
            classes[1] += usize::from(text.contains("low box") || text.contains("stool"));
            classes[2] += usize::from(text.contains("shelf"));
        }
        // Every height class appears in most worlds.
        assert!(classes.iter().all(|&c| c >= 40), "{classes:?}");
    }

    /// FNV-1a of a text: pins generated files across changes to the generator.
    fn fnv(text: &str) -> u64 {
        text.bytes()
            .fold(0xcbf2_9ce4_8422_2325, |h, b| (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3))
    }

    #[test]
    fn gen_worlds_are_unchanged_and_homes_add_household_furniture() {
        // The `gen-N` files as they were before the `home` family existed (2026-12-06).
        assert_eq!((generate_toml(5).len(), fnv(&generate_toml(5))), (5252, 0x069b_c3bb_19aa_9047));
        assert_eq!(
            (generate_toml(60).len(), fnv(&generate_toml(60))),
            (8836, 0xf246_b149_6c73_5309)
        );
        assert_eq!(family_toml(Family::Home, 4), family_toml(Family::Home, 4));
        let mut kinds = [0usize; 3];
        for seed in 0..40 {
            let w =
                generate_family(Family::Home, seed).unwrap_or_else(|e| panic!("home-{seed}: {e}"));
            assert_eq!(w.name, format!("home-{seed}"));
            let text = family_toml(Family::Home, seed);
            // The same rooms and doors as gen-N: every wall of one is in the other.
            let walls = |t: &str| -> Vec<String> {
                t.lines().filter(|l| l.contains("\"wall\"")).map(str::to_string).collect()
            };
            assert_eq!(walls(&text), walls(&generate_toml(seed)), "home-{seed}");
            kinds[0] += usize::from(text.contains("coffee table top"));
            kinds[1] += usize::from(text.contains("chair seat") && text.contains("chair back"));
            kinds[2] += usize::from(text.contains("bench seat") && text.contains("bench end"));
            // The coffee table's top spans the camera's height band, under the laser plane.
            for l in text.lines().filter(|l| l.contains("coffee table top")) {
                let z = l.split("z = [").nth(1).expect("z").split(']').next().expect("]");
                let z: Vec<f32> = z.split(',').map(|v| v.trim().parse().expect("f32")).collect();
                assert!(z[0] >= 0.28 && z[1] < 0.4 && z[1] - z[0] > 0.04, "{l}");
            }
        }
        assert!(kinds.iter().all(|&k| k >= 20), "{kinds:?}");
        assert_eq!(Family::parse("home-12"), Some((Family::Home, 12)));
        assert_eq!(Family::parse("gen-3"), Some((Family::Gen, 3)));
        assert_eq!(Family::parse("home-x"), None);
    }
}
