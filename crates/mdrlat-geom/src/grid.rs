//! A uniform broadphase grid over static obstacles.
//!
//! Each cell lists the obstacles whose bounding rectangle touches it (compressed rows, one
//! allocation). Queries return each obstacle once, in cell order then index order: the same
//! query always gives the same sequence.

use crate::aabb::Aabb;
use crate::math::Vec2;

/// Most cells along a side: a huge world gets bigger cells, not more of them.
const MAX_CELLS_PER_SIDE: f32 = 256.0;
/// Obstacles covering more cells than this are kept in one list checked by every query,
/// so no obstacle costs more than this many grid entries.
const MAX_CELLS_PER_ITEM: usize = 1024;

/// Broadphase grid of obstacle indices.
#[derive(Debug, Clone)]
pub struct Grid {
    origin: Vec2,
    cell_m: f32,
    nx: usize,
    ny: usize,
    /// `starts[c]..starts[c+1]` indexes `items` for cell `c`.
    starts: Vec<usize>,
    items: Vec<u32>,
    /// Obstacles too large for the cells: reported by every query.
    always: Vec<u32>,
    count: usize,
}

/// Reusable scratch for [`Grid::query`]: per-obstacle marks so each is reported once.
#[derive(Debug, Clone, Default)]
pub struct GridScratch {
    marks: Vec<u32>,
    generation: u32,
}

impl Grid {
    /// Builds a grid covering `bounds` with square cells of `cell_m` metres (larger for huge
    /// worlds: at most 256 cells a side) over obstacles with the given bounding rectangles.
    /// Obstacles outside `bounds` land in border cells; obstacles spanning more than 1024
    /// cells are checked by every query instead, so memory stays linear in the obstacles.
    pub fn build(bounds: Aabb, cell_m: f32, aabbs: &[Aabb]) -> Self {
        let size = bounds.size();
        let longest = size.x.max(size.y);
        let cell_m =
            if longest.is_finite() { cell_m.max(longest / MAX_CELLS_PER_SIDE) } else { cell_m };
        let nx = ((size.x / cell_m).ceil() as usize).clamp(1, MAX_CELLS_PER_SIDE as usize);
        let ny = ((size.y / cell_m).ceil() as usize).clamp(1, MAX_CELLS_PER_SIDE as usize);
        let mut grid = Grid {
            origin: bounds.min,
            cell_m,
            nx,
            ny,
            starts: vec![0; nx * ny + 1],
            items: Vec::new(),
            always: Vec::new(),
            count: aabbs.len(),
        };
        let spans: Vec<Option<(usize, usize, usize, usize)>> = aabbs
            .iter()
            .map(|b| {
                let span = grid.cell_span(b);
                let (x0, y0, x1, y1) = span;
                ((x1 - x0 + 1) * (y1 - y0 + 1) <= MAX_CELLS_PER_ITEM).then_some(span)
            })
            .collect();
        // Two passes: count per cell, then fill.
        for (i, span) in spans.iter().enumerate() {
            let Some((x0, y0, x1, y1)) = *span else {
                grid.always.push(i as u32);
                continue;
            };
            for y in y0..=y1 {
                for x in x0..=x1 {
                    grid.starts[y * nx + x + 1] += 1;
                }
            }
        }
        for c in 0..nx * ny {
            grid.starts[c + 1] += grid.starts[c];
        }
        let mut fill = grid.starts.clone();
        grid.items = vec![0; grid.starts[nx * ny]];
        for (i, span) in spans.iter().enumerate() {
            let Some((x0, y0, x1, y1)) = *span else { continue };
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let c = y * nx + x;
                    grid.items[fill[c]] = i as u32;
                    fill[c] += 1;
                }
            }
        }
        grid
    }

    fn cell_span(&self, b: &Aabb) -> (usize, usize, usize, usize) {
        let cx = |x: f32| {
            (((x - self.origin.x) / self.cell_m).floor().max(0.0) as usize).min(self.nx - 1)
        };
        let cy = |y: f32| {
            (((y - self.origin.y) / self.cell_m).floor().max(0.0) as usize).min(self.ny - 1)
        };
        (cx(b.min.x), cy(b.min.y), cx(b.max.x), cy(b.max.y))
    }

    /// Writes to `out` (after clearing it) the indices of obstacles whose cells touch `area`,
    /// each once, in a deterministic order.
    pub fn query(&self, area: &Aabb, scratch: &mut GridScratch, out: &mut Vec<u32>) {
        out.clear();
        if scratch.marks.len() != self.count {
            scratch.marks = vec![0; self.count];
            scratch.generation = 0;
        }
        scratch.generation = scratch.generation.wrapping_add(1);
        if scratch.generation == 0 {
            scratch.marks.fill(0);
            scratch.generation = 1;
        }
        let g = scratch.generation;
        out.extend_from_slice(&self.always);
        for &i in &self.always {
            scratch.marks[i as usize] = g;
        }
        let (x0, y0, x1, y1) = self.cell_span(area);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let c = y * self.nx + x;
                for &i in &self.items[self.starts[c]..self.starts[c + 1]] {
                    if scratch.marks[i as usize] != g {
                        scratch.marks[i as usize] = g;
                        out.push(i);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn query_finds_each_overlapping_obstacle_once() {
        let bounds = Aabb::new(Vec2::ZERO, Vec2::new(10.0, 10.0));
        let boxes = [
            Aabb::new(Vec2::new(0.0, 0.0), Vec2::new(10.0, 0.2)), // long wall: many cells
            Aabb::new(Vec2::new(5.0, 5.0), Vec2::new(5.5, 5.5)),
            Aabb::new(Vec2::new(8.0, 8.0), Vec2::new(9.0, 9.0)),
            Aabb::new(Vec2::new(-3.0, -3.0), Vec2::new(-2.0, -2.0)), // outside: border cell
        ];
        let grid = Grid::build(bounds, 1.0, &boxes);
        let mut s = GridScratch::default();
        let mut out = Vec::new();
        let mut q = |area: Aabb| {
            grid.query(&area, &mut s, &mut out);
            let mut sorted = out.clone();
            sorted.sort_unstable();
            sorted
        };
        assert_eq!(q(Aabb::new(Vec2::new(4.0, 0.0), Vec2::new(6.0, 6.0))), [0, 1]);
        assert_eq!(q(Aabb::new(Vec2::new(-1.0, -1.0), Vec2::new(0.5, 0.5))), [0, 3]);
        assert_eq!(q(bounds), [0, 1, 2, 3]);
    }

    #[test]
    fn huge_worlds_and_obstacles_stay_small() {
        let bounds = Aabb::new(Vec2::ZERO, Vec2::new(4000.0, 4000.0));
        let boxes: Vec<Aabb> = (0..100).map(|_| bounds).collect();
        let grid = Grid::build(bounds, 1.0, &boxes);
        assert!(grid.items.len() + grid.starts.len() < 100_000, "{}", grid.items.len());
        let mut out = Vec::new();
        grid.query(
            &Aabb::around(Vec2::new(10.0, 10.0), 1.0),
            &mut GridScratch::default(),
            &mut out,
        );
        assert_eq!(out.len(), 100);
    }
}
