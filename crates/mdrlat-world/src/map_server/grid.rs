//! Occupancy grids and the import's greedy rectangle merging (the distance transform is
//! `mdrlat_geom::distance_sq`, shared with the planner).

/// One map cell, as ROS map_server classifies a pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Cell {
    /// Known free.
    Free,
    /// Known occupied.
    Occupied,
    /// Neither (between the thresholds, or transparent in scale mode).
    Unknown,
}

/// Cells row-major, row 0 at the top of the map (largest y), as in the image.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Grid {
    /// Columns (> 0).
    pub width: usize,
    /// Rows (> 0).
    pub height: usize,
    /// `width * height` cells.
    pub cells: Vec<Cell>,
}

impl Grid {
    /// One boolean per cell.
    pub fn mask(&self, f: impl Fn(Cell) -> bool) -> Vec<bool> {
        self.cells.iter().map(|&c| f(c)).collect()
    }
}

/// A block of `rows` x `cols` cells whose top-left cell is (`row`, `col`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct CellRect {
    /// Top row.
    pub row: usize,
    /// Left column.
    pub col: usize,
    /// Height in cells.
    pub rows: usize,
    /// Width in cells.
    pub cols: usize,
}

impl CellRect {
    /// Number of cells.
    pub fn cells(&self) -> usize {
        self.rows * self.cols
    }
}

/// Covers the `true` cells of a row-major `mask` of `width` columns with disjoint rectangles,
/// greedily: scanning row-major, at each `true` cell extend right as far as possible, then
/// down while the whole span is `true`; the covered cells are cleared (`mask` ends all
/// `false`). Deterministic; far fewer rectangles than cells on floor plans.
pub(super) fn merge_rects(mask: &mut [bool], width: usize) -> Vec<CellRect> {
    let height = mask.len().checked_div(width).unwrap_or(0);
    let mut rects = Vec::new();
    for row in 0..height {
        let mut col = 0;
        while col < width {
            if !mask[row * width + col] {
                col += 1;
                continue;
            }
            let span = mask[row * width + col..(row + 1) * width].iter().take_while(|&&b| b);
            let cols = span.count();
            let mut rows = 1;
            while row + rows < height
                && mask[(row + rows) * width + col..][..cols].iter().all(|&b| b)
            {
                rows += 1;
            }
            for r in row..row + rows {
                mask[r * width + col..][..cols].fill(false);
            }
            rects.push(CellRect { row, col, rows, cols });
            col += cols;
        }
    }
    rects
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator for test masks.
    fn masks(seed: u64) -> impl Iterator<Item = (Vec<bool>, usize)> {
        let mut state = seed;
        std::iter::repeat_with(move || {
            let mut next = || {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                state >> 33
            };
            let (w, h) = (1 + next() as usize % 23, 1 + next() as usize % 17);
            let density = next() % 5;
            let mask = (0..w * h).map(|_| next() % 8 < density).collect();
            (mask, w)
        })
    }

    #[test]
    fn rectangles_cover_exactly_the_mask() {
        for (mask, w) in masks(11).take(300) {
            let mut work = mask.clone();
            let rects = merge_rects(&mut work, w);
            assert!(work.iter().all(|&b| !b));
            let mut cover = vec![0u8; mask.len()];
            for r in &rects {
                for row in r.row..r.row + r.rows {
                    for c in r.col..r.col + r.cols {
                        cover[row * w + c] += 1;
                    }
                }
            }
            assert!(mask.iter().zip(&cover).all(|(&m, &n)| n == u8::from(m)));
        }
        let mut l = vec![true, true, true, true, false, false, true, false, false];
        let rects = merge_rects(&mut l, 3);
        let expected = [
            CellRect { row: 0, col: 0, rows: 1, cols: 3 },
            CellRect { row: 1, col: 0, rows: 2, cols: 1 },
        ];
        assert_eq!(rects, expected);
    }
}
