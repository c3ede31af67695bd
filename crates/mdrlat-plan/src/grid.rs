//! Occupancy grids of a world and the inflated cost map the global planner searches.

use mdrlat_geom::Vec2;
use mdrlat_world::World;

/// One cell: column `x` (east) and row `y` (north), from the grid's south-west corner.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Cell {
    /// Column.
    pub x: usize,
    /// Row.
    pub y: usize,
}

/// Which obstacles a map of the world holds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MapKind {
    /// What a 2D-laser SLAM map would hold: only the obstacles whose height interval contains
    /// the laser plane (`height_m` above the floor). A table top above the plane or a step
    /// below it is not in this map — the planner routes the robot into it, and only the
    /// bumper finds out: the paper's argument for the depth camera.
    LaserPlane {
        /// Height of the laser plane, metres.
        height_m: f32,
    },
    /// Every obstacle the robot's body can hit: those overlapping `[0, height_m]`.
    Body {
        /// Body height, metres.
        height_m: f32,
    },
}

/// A world rasterised into square cells, each free or occupied.
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyGrid {
    /// World position of the south-west corner of cell (0, 0).
    pub origin: Vec2,
    /// Cell side, metres.
    pub resolution_m: f32,
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    occupied: Vec<bool>,
}

/// Cells a map may have (a 100 m × 100 m world at 2 cm): a guard against a resolution typo.
const MAX_CELLS: usize = 25_000_000;

impl OccupancyGrid {
    /// The obstacles of `world` that `kind` selects, over its bounds, at `resolution_m`: a
    /// cell is occupied when an obstacle comes within half a cell of its centre (so walls
    /// thinner than a cell stay closed). Static obstacles only; pedestrians move and are
    /// the local planner's business.
    ///
    /// # Errors
    /// A resolution that is not positive and finite, or one that makes the grid too large.
    pub fn from_world(world: &World, kind: MapKind, resolution_m: f32) -> Result<Self, String> {
        if !(resolution_m.is_finite() && resolution_m > 0.0) {
            return Err(format!("map resolution {resolution_m} m: must be a positive number"));
        }
        let size = world.bounds.size();
        let width = (size.x / resolution_m).ceil().max(1.0) as usize;
        let height = (size.y / resolution_m).ceil().max(1.0) as usize;
        if width.saturating_mul(height) > MAX_CELLS {
            return Err(format!(
                "map of world '{}' at {resolution_m} m a cell: {width} x {height} cells, more \
                 than {MAX_CELLS}; use a coarser resolution",
                world.name
            ));
        }
        let mut grid = Self {
            origin: world.bounds.min,
            resolution_m,
            width,
            height,
            occupied: vec![false; width * height],
        };
        let half = resolution_m * 0.5;
        for o in &world.obstacles {
            let selected = match kind {
                MapKind::LaserPlane { height_m } => o.prism.spans_height(height_m),
                MapKind::Body { height_m } => o.prism.overlaps_heights(0.0, height_m),
            };
            if !selected {
                continue;
            }
            let b = o.prism.shape.aabb().inflate(half);
            let (Some(lo), Some(hi)) = (grid.clamped_cell(b.min), grid.clamped_cell(b.max)) else {
                continue;
            };
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    let c = Cell { x, y };
                    if o.prism.shape.distance_to_point(grid.center(c)) <= half {
                        grid.occupied[y * width + x] = true;
                    }
                }
            }
        }
        Ok(grid)
    }

    /// A grid drawn as text, for tests and examples: one string per row, the first row the
    /// northern one (as the grid looks on a page), `#` occupied and anything else free.
    ///
    /// # Panics
    /// If the rows differ in length or there are none.
    pub fn from_rows(rows: &[&str], resolution_m: f32, origin: Vec2) -> Self {
        let width = rows.first().map_or(0, |r| r.chars().count());
        assert!(width > 0 && rows.iter().all(|r| r.chars().count() == width), "ragged grid");
        let height = rows.len();
        let mut occupied = vec![false; width * height];
        for (i, row) in rows.iter().enumerate() {
            let y = height - 1 - i;
            for (x, ch) in row.chars().enumerate() {
                occupied[y * width + x] = ch == '#';
            }
        }
        Self { origin, resolution_m, width, height, occupied }
    }

    /// The cell holding `p`, or `None` outside the grid.
    pub fn cell_of(&self, p: Vec2) -> Option<Cell> {
        let fx = (p.x - self.origin.x) / self.resolution_m;
        let fy = (p.y - self.origin.y) / self.resolution_m;
        if !(fx >= 0.0 && fy >= 0.0) {
            return None;
        }
        let (x, y) = (fx as usize, fy as usize);
        (x < self.width && y < self.height).then_some(Cell { x, y })
    }

    /// The cell nearest `p`, clamped into the grid (`None` for a non-finite point).
    fn clamped_cell(&self, p: Vec2) -> Option<Cell> {
        if !p.is_finite() {
            return None;
        }
        let fx = ((p.x - self.origin.x) / self.resolution_m).floor();
        let fy = ((p.y - self.origin.y) / self.resolution_m).floor();
        Some(Cell {
            x: fx.clamp(0.0, (self.width - 1) as f32) as usize,
            y: fy.clamp(0.0, (self.height - 1) as f32) as usize,
        })
    }

    /// World position of a cell's centre.
    pub fn center(&self, c: Cell) -> Vec2 {
        Vec2::new(
            self.origin.x + (c.x as f32 + 0.5) * self.resolution_m,
            self.origin.y + (c.y as f32 + 0.5) * self.resolution_m,
        )
    }

    /// Whether a cell is occupied.
    pub fn is_occupied(&self, c: Cell) -> bool {
        self.occupied[self.index(c)]
    }

    /// Occupied cells.
    pub fn occupied_cells(&self) -> usize {
        self.occupied.iter().filter(|&&o| o).count()
    }

    pub(crate) fn index(&self, c: Cell) -> usize {
        c.y * self.width + c.x
    }
}

/// An occupancy grid inflated by the robot's radius (distances from the exact Euclidean
/// transform [`mdrlat_geom::distance_sq`]), with costs that fall off away from
/// the obstacles (navfn's and costmap_2d's scheme): a cell whose centre is closer than
/// `inscribed_m` to an occupied cell is blocked; beyond, a step into a cell costs
/// `1 + weight · exp(−(d − inscribed) / decay)` times its length, so the plan keeps away
/// from walls where it can at little extra length.
#[derive(Debug, Clone)]
pub struct CostMap {
    grid: OccupancyGrid,
    /// Distance from each cell's centre to the nearest occupied cell's centre, metres.
    distance_m: Vec<f32>,
    inscribed_m: f32,
    weight: f32,
    decay_m: f32,
}

impl CostMap {
    /// `grid` inflated by `inscribed_m` (the robot's radius, plus any margin), with a cost
    /// `weight` decaying over `decay_m` beyond it (weight 0: plain shortest paths).
    pub fn new(grid: OccupancyGrid, inscribed_m: f32, weight: f32, decay_m: f32) -> Self {
        let r = grid.resolution_m;
        let distance_m = mdrlat_geom::distance_sq(&grid.occupied, grid.width)
            .into_iter()
            .map(|d2| if d2 == u32::MAX { f32::INFINITY } else { (d2 as f32).sqrt() * r })
            .collect();
        Self { grid, distance_m, inscribed_m, weight, decay_m: decay_m.max(1e-6) }
    }

    /// The occupancy grid underneath.
    pub fn grid(&self) -> &OccupancyGrid {
        &self.grid
    }

    /// Distance from a cell's centre to the nearest obstacle cell's centre, metres
    /// (infinite in a grid without obstacles).
    pub fn clearance(&self, c: Cell) -> f32 {
        self.distance_m[self.grid.index(c)]
    }

    /// Radius the obstacles are inflated by, metres.
    pub fn inscribed_m(&self) -> f32 {
        self.inscribed_m
    }

    /// Whether the robot's centre may not be in this cell.
    pub fn is_blocked(&self, c: Cell) -> bool {
        self.clearance(c) < self.inscribed_m
    }

    /// The factor a step into this cell costs beyond its length (≥ 1; infinite if blocked).
    pub fn step_factor(&self, c: Cell) -> f32 {
        let d = self.clearance(c);
        if d < self.inscribed_m {
            return f32::INFINITY;
        }
        if self.weight == 0.0 {
            return 1.0;
        }
        1.0 + self.weight * (-(d - self.inscribed_m) / self.decay_m).exp()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_read_like_a_picture_and_cells_map_to_the_world() {
        let g = OccupancyGrid::from_rows(&["#..", "..."], 0.5, Vec2::new(-1.0, 2.0));
        assert!(g.is_occupied(Cell { x: 0, y: 1 }), "the first row is the northern one");
        assert!(!g.is_occupied(Cell { x: 0, y: 0 }));
        assert_eq!(g.cell_of(Vec2::new(-0.9, 2.1)), Some(Cell { x: 0, y: 0 }));
        assert_eq!(g.cell_of(Vec2::new(0.4, 2.9)), Some(Cell { x: 2, y: 1 }));
        assert_eq!(g.cell_of(Vec2::new(0.6, 2.1)), None);
        assert_eq!(g.cell_of(Vec2::new(-1.1, 2.1)), None);
        assert_eq!(g.center(Cell { x: 1, y: 1 }), Vec2::new(-0.25, 2.75));
    }

    #[test]
    fn inflation_blocks_cells_within_the_radius_only() {
        let g = OccupancyGrid::from_rows(&[".......", "...#...", "......."], 0.1, Vec2::default());
        let m = CostMap::new(g, 0.25, 0.0, 0.1);
        // Three cells away (0.3 m) is free, two (0.2 m) and the diagonal (0.22 m) blocked.
        assert!(!m.is_blocked(Cell { x: 0, y: 1 }));
        assert!(m.is_blocked(Cell { x: 1, y: 1 }));
        assert!(m.is_blocked(Cell { x: 2, y: 0 }));
        assert!((m.clearance(Cell { x: 0, y: 1 }) - 0.3).abs() < 1e-6);
        assert_eq!(m.step_factor(Cell { x: 0, y: 1 }), 1.0);
        assert_eq!(m.step_factor(Cell { x: 3, y: 1 }), f32::INFINITY);
        let weighted = CostMap::new(m.grid().clone(), 0.25, 2.0, 0.1);
        assert!(weighted.step_factor(Cell { x: 0, y: 1 }) > 1.0);
    }
}
