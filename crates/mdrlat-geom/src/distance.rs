//! The exact Euclidean distance transform of a grid mask (map import, planner inflation).

/// For each cell of a row-major `blocked` mask of `width` columns, the squared Euclidean
/// distance in cells² from its centre to the nearest blocked cell's centre; `u32::MAX` where
/// no cell is blocked. Exact, in integer arithmetic, O(cells): Meijster, Roerdink and
/// Hesselink, "A general algorithm for computing distance transforms in linear time" (2000).
/// Sides up to 2^15 cells.
pub fn distance_sq(blocked: &[bool], width: usize) -> Vec<u32> {
    let height = blocked.len().checked_div(width).unwrap_or(0);
    // Larger than any in-grid distance; squared, larger than any in-grid squared distance.
    let inf = (width + height) as u32;
    // Phase 1: distance to the nearest blocked cell in the same column, computed a row at a
    // time (down, then up) so the inner loops run along memory.
    let mut g = vec![inf; blocked.len()];
    for r in 0..height {
        for c in 0..width {
            let i = r * width + c;
            g[i] = if blocked[i] {
                0
            } else if r > 0 && g[i - width] < inf {
                g[i - width] + 1
            } else {
                inf
            };
        }
    }
    for r in (0..height.saturating_sub(1)).rev() {
        for c in 0..width {
            let i = r * width + c;
            g[i] = g[i].min(g[i + width].saturating_add(1));
        }
    }
    // Phase 2: per row, the lower envelope of the parabolas (x - i)² + g(i)².
    let mut out = vec![u32::MAX; blocked.len()];
    let (mut s, mut t) = (vec![0usize; width], vec![0usize; width]);
    for r in 0..height {
        let gr = &g[r * width..(r + 1) * width];
        let f = |x: usize, i: usize| {
            let (dx, gi) = (x.abs_diff(i) as u64, u64::from(gr[i]));
            dx * dx + gi * gi
        };
        // The first x at which the parabola of u is at least as low as that of i (i < u).
        let sep = |i: usize, u: usize| {
            let (ii, uu, gi, gu) = (i as i64, u as i64, i64::from(gr[i]), i64::from(gr[u]));
            (uu * uu - ii * ii + gu * gu - gi * gi).div_euclid(2 * (uu - ii))
        };
        let mut k = 1;
        (s[0], t[0]) = (0, 0);
        for u in 1..width {
            while k > 0 && f(t[k - 1], s[k - 1]) > f(t[k - 1], u) {
                k -= 1;
            }
            if k == 0 {
                (s[0], t[0], k) = (u, 0, 1);
            } else {
                let w = 1 + sep(s[k - 1], u);
                if w < width as i64 {
                    (s[k], t[k]) = (u, w.max(0) as usize);
                    k += 1;
                }
            }
        }
        for x in (0..width).rev() {
            if gr[s[k - 1]] < inf {
                out[r * width + x] = f(x, s[k - 1]) as u32;
            }
            if x == t[k - 1] && k > 1 {
                k -= 1;
            }
        }
    }
    out
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
    fn distance_transform_is_exact() {
        for (blocked, w) in masks(7).take(300) {
            let d = distance_sq(&blocked, w);
            let h = blocked.len() / w;
            for (i, &di) in d.iter().enumerate() {
                let brute = (0..w * h)
                    .filter(|&j| blocked[j])
                    .map(|j| {
                        let (dx, dy) = ((i % w).abs_diff(j % w), (i / w).abs_diff(j / w));
                        (dx * dx + dy * dy) as u32
                    })
                    .min()
                    .unwrap_or(u32::MAX);
                assert_eq!(di, brute, "cell {i} of {w}x{h}");
            }
        }
    }
}
