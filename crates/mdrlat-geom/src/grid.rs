//! A uniform broadphase grid over static obstacles.
//!
//! Each cell lists the obstacles whose bounding rectangle touches it (compressed rows, one
//! allocation). Queries return each obstacle once, in cell order then index order: the same
//! query always gives the same sequence.

use crate::aabb::Aabb;
use crate::math::Vec2;

/// Broadphase grid of obstacle indices.
#[derive(Debug, Clone)]
pub struct Grid {
    origin: Vec2,
    cell_m: f32,
    nx: usize,
    ny: usize,
    /// `starts[c]..starts[c+1]` indexes `items` for cell `c`.
    starts: Vec<u32>,
    items: Vec<u32>,
    count: usize,
}

/// Reusable scratch for [`Grid::query`]: per-obstacle marks so each is reported once.
#[derive(Debug, Clone, Default)]
pub struct GridScratch {
    marks: Vec<u32>,
    generation: u32,
}

impl Grid {
    /// Builds a grid covering `bounds` with square cells of `cell_m` metres over obstacles
    /// with the given bounding rectangles. Obstacles outside `bounds` land in border cells.
    pub fn build(bounds: Aabb, cell_m: f32, aabbs: &[Aabb]) -> Self {
        let size = bounds.size();
        let nx = ((size.x / cell_m).ceil() as usize).clamp(1, 4096);
        let ny = ((size.y / cell_m).ceil() as usize).clamp(1, 4096);
        let mut grid = Grid {
            origin: bounds.min,
            cell_m,
            nx,
            ny,
            starts: vec![0; nx * ny + 1],
            items: Vec::new(),
            count: aabbs.len(),
        };
        // Two passes: count per cell, then fill.
        for b in aabbs {
            let (x0, y0, x1, y1) = grid.cell_span(b);
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
        grid.items = vec![0; grid.starts[nx * ny] as usize];
        for (i, b) in aabbs.iter().enumerate() {
            let (x0, y0, x1, y1) = grid.cell_span(b);
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let c = y * nx + x;
                    grid.items[fill[c] as usize] = i as u32;
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
        let (x0, y0, x1, y1) = self.cell_span(area);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let c = y * self.nx + x;
                for &i in &self.items[self.starts[c] as usize..self.starts[c + 1] as usize] {
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
}
