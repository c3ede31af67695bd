//! The global planner: A* over a [`CostMap`].

use crate::grid::{Cell, CostMap};
use mdrlat_geom::Vec2;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// A plan from a start to a goal.
#[derive(Debug, Clone, PartialEq)]
pub struct Path {
    /// The cells, start to goal.
    pub cells: Vec<Cell>,
    /// The same as world positions: the exact start, the cell centres between, the exact
    /// goal.
    pub points: Vec<Vec2>,
    /// Length of `points`, metres.
    pub length_m: f32,
    /// The plan's cost (its length weighted by the cost map), metres.
    pub cost: f64,
}

/// Why there is no plan.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// The start or goal lies outside the map.
    #[error("the {what} ({x:.2}, {y:.2}) is outside the map")]
    Outside {
        /// `start` or `goal`.
        what: &'static str,
        /// Position, metres.
        x: f32,
        /// Position, metres.
        y: f32,
    },
    /// The start or goal is inside an obstacle or closer to one than the robot's radius.
    #[error(
        "the {what} ({x:.2}, {y:.2}) is {clearance_m:.2} m from an obstacle, closer than the \
         robot's inflation radius {inscribed_m:.2} m"
    )]
    Blocked {
        /// `start` or `goal`.
        what: &'static str,
        /// Position, metres.
        x: f32,
        /// Position, metres.
        y: f32,
        /// Its distance to the nearest obstacle, metres.
        clearance_m: f32,
        /// The inflation radius, metres.
        inscribed_m: f32,
    },
    /// Every route from start to goal is blocked.
    #[error(
        "no collision-free path from ({:.2}, {:.2}) to ({:.2}, {:.2}) on the map (searched \
         {searched} cells)", from.x, from.y, to.x, to.y
    )]
    NoPath {
        /// Start.
        from: Vec2,
        /// Goal.
        to: Vec2,
        /// Cells the search reached.
        searched: usize,
    },
}

/// The 8 moves: (dx, dy, length in cells).
const MOVES: [(isize, isize, f64); 8] = [
    (1, 0, 1.0),
    (-1, 0, 1.0),
    (0, 1, 1.0),
    (0, -1, 1.0),
    (1, 1, std::f64::consts::SQRT_2),
    (1, -1, std::f64::consts::SQRT_2),
    (-1, 1, std::f64::consts::SQRT_2),
    (-1, -1, std::f64::consts::SQRT_2),
];

/// The cheapest 8-connected path of cell centres from `start` to `goal` on `map`: a step
/// costs its length times the map's step factor of the cell it enters, diagonal steps may
/// not cut the corner of a blocked cell, and the octile distance (a lower bound of that
/// cost) guides the search, so the path is optimal on the grid. Ties break the same way
/// every time.
///
/// # Errors
/// The start or goal is outside the map or blocked, or no path exists.
pub fn astar(map: &CostMap, start: Vec2, goal: Vec2) -> Result<Path, PlanError> {
    search(map, start, goal, true)
}

/// A* (`heuristic`) or Dijkstra (without: the tests' reference).
pub(crate) fn search(
    map: &CostMap,
    start: Vec2,
    goal: Vec2,
    heuristic: bool,
) -> Result<Path, PlanError> {
    let grid = map.grid();
    let locate = |what: &'static str, p: Vec2| -> Result<Cell, PlanError> {
        let c = grid.cell_of(p).ok_or(PlanError::Outside { what, x: p.x, y: p.y })?;
        if map.is_blocked(c) {
            return Err(PlanError::Blocked {
                what,
                x: p.x,
                y: p.y,
                clearance_m: map.clearance(c),
                inscribed_m: map.inscribed_m(),
            });
        }
        Ok(c)
    };
    let (s, g) = (locate("start", start)?, locate("goal", goal)?);
    let r = f64::from(grid.resolution_m);
    let h = |c: Cell| -> f64 {
        if !heuristic {
            return 0.0;
        }
        let (dx, dy) = (c.x.abs_diff(g.x) as f64, c.y.abs_diff(g.y) as f64);
        (dx.max(dy) + (std::f64::consts::SQRT_2 - 1.0) * dx.min(dy)) * r
    };
    let n = grid.width * grid.height;
    let mut cost = vec![f64::INFINITY; n];
    let mut parent = vec![usize::MAX; n];
    let mut closed = vec![false; n];
    // Ordered by (f, h, index): f64 bits of non-negative numbers sort as the numbers do.
    let mut open = BinaryHeap::new();
    let si = grid.index(s);
    cost[si] = 0.0;
    open.push(Reverse((h(s).to_bits(), h(s).to_bits(), si)));
    let mut searched = 0;
    while let Some(Reverse((_, _, i))) = open.pop() {
        if closed[i] {
            continue;
        }
        closed[i] = true;
        searched += 1;
        let c = Cell { x: i % grid.width, y: i / grid.width };
        if c == g {
            return Ok(path(map, &parent, si, i, start, goal, cost[i]));
        }
        for &(dx, dy, len) in &MOVES {
            let (Some(x), Some(y)) = (c.x.checked_add_signed(dx), c.y.checked_add_signed(dy))
            else {
                continue;
            };
            if x >= grid.width || y >= grid.height {
                continue;
            }
            let next = Cell { x, y };
            if map.is_blocked(next) {
                continue;
            }
            if dx != 0
                && dy != 0
                && (map.is_blocked(Cell { x, y: c.y }) || map.is_blocked(Cell { x: c.x, y }))
            {
                continue;
            }
            let j = grid.index(next);
            if closed[j] {
                continue;
            }
            let step = len * r * f64::from(map.step_factor(next));
            let through = cost[i] + step;
            if through < cost[j] {
                cost[j] = through;
                parent[j] = i;
                let hj = h(next);
                open.push(Reverse(((through + hj).to_bits(), hj.to_bits(), j)));
            }
        }
    }
    Err(PlanError::NoPath { from: start, to: goal, searched })
}

fn path(
    map: &CostMap,
    parent: &[usize],
    start: usize,
    end: usize,
    from: Vec2,
    to: Vec2,
    cost: f64,
) -> Path {
    let grid = map.grid();
    let mut cells = vec![Cell { x: end % grid.width, y: end / grid.width }];
    let mut i = end;
    while i != start {
        i = parent[i];
        cells.push(Cell { x: i % grid.width, y: i / grid.width });
    }
    cells.reverse();
    let mut points = Vec::with_capacity(cells.len() + 1);
    points.push(from);
    points
        .extend(cells.iter().skip(1).take(cells.len().saturating_sub(2)).map(|&c| grid.center(c)));
    points.push(to);
    let length_m = points.windows(2).map(|w| (w[1] - w[0]).length()).sum();
    Path { cells, points, length_m, cost }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::OccupancyGrid;
    use proptest::prelude::*;

    fn map(rows: &[&str], inscribed: f32) -> CostMap {
        CostMap::new(OccupancyGrid::from_rows(rows, 1.0, Vec2::default()), inscribed, 0.0, 1.0)
    }

    fn at(x: usize, y: usize) -> Vec2 {
        Vec2::new(x as f32 + 0.5, y as f32 + 0.5)
    }

    #[test]
    fn the_path_around_a_wall_is_the_shortest_on_the_grid() {
        // Start at the south-west, goal at the south-east, a wall between with a gap at the
        // top: up, across, down.
        let m = map(&["......", "..#...", "..#...", "..#..."], 0.5);
        let p = astar(&m, at(0, 0), at(4, 0)).expect("a path");
        assert_eq!(p.cells.first(), Some(&Cell { x: 0, y: 0 }));
        assert_eq!(p.cells.last(), Some(&Cell { x: 4, y: 0 }));
        // The optimum without cutting the wall's corners: 0,0 ↗ 1,1 ↑ 1,2 ↑ 1,3 → 2,3 → 3,3
        // ↓ 3,2 ↘ 4,1 ↓ 4,0 = 2 diagonals + 6 straight steps.
        let best = 2.0 * std::f64::consts::SQRT_2 + 6.0;
        assert!((p.cost - best).abs() < 1e-9, "cost {} vs {best}", p.cost);
        assert!(p.cells.iter().all(|&c| !m.is_blocked(c)));
        // No corner cut: a diagonal never passes between two blocked cells' corners.
        for w in p.cells.windows(2) {
            let (a, b) = (w[0], w[1]);
            if a.x != b.x && a.y != b.y {
                assert!(!m.is_blocked(Cell { x: b.x, y: a.y }));
                assert!(!m.is_blocked(Cell { x: a.x, y: b.y }));
            }
        }
        assert_eq!(p.points.first(), Some(&at(0, 0)));
        assert_eq!(p.points.last(), Some(&at(4, 0)));
    }

    #[test]
    fn no_path_start_and_goal_problems_are_clear_failures() {
        let walled = map(&["..#..", "..#..", "..#.."], 0.5);
        let e = astar(&walled, at(0, 0), at(4, 0)).expect_err("the wall is closed");
        assert!(matches!(e, PlanError::NoPath { searched: 6, .. }), "{e:?}");
        assert!(e.to_string().contains("no collision-free path from (0.50, 0.50)"), "{e}");
        let e = astar(&walled, at(0, 0), at(2, 1)).expect_err("goal in the wall");
        assert!(e.to_string().starts_with("the goal (2.50, 1.50) is 0.00 m from an obstacle"));
        let e = astar(&walled, Vec2::new(-1.0, 0.5), at(0, 0)).expect_err("outside");
        assert_eq!(e.to_string(), "the start (-1.00, 0.50) is outside the map");
    }

    #[test]
    fn inflation_closes_gaps_narrower_than_the_robot() {
        // A one-cell gap: open for a point robot, closed for one of radius 1.2 cells.
        let rows = ["..#..", ".....", "..#.."];
        assert!(astar(&map(&rows, 0.5), at(0, 1), at(4, 1)).is_ok());
        let e = astar(&map(&rows, 1.2), at(0, 0), at(4, 0));
        assert!(matches!(e, Err(PlanError::NoPath { .. })), "{e:?}");
        // With room, the plan keeps the inflation radius from every obstacle.
        let open = ["#.........#", "...........", "...........", "...........", "#.........#"];
        let m = map(&open, 1.5);
        let p = astar(&m, at(2, 2), at(8, 2)).expect("a path");
        assert!(p.cells.iter().all(|&c| m.clearance(c) >= 1.5));
    }

    #[test]
    fn costs_push_the_plan_away_from_walls() {
        let rows = ["..........", "..........", "..........", "..........", "##########"];
        let grid = OccupancyGrid::from_rows(&rows, 1.0, Vec2::default());
        let plain = astar(&CostMap::new(grid.clone(), 0.5, 0.0, 1.0), at(0, 1), at(9, 1));
        let careful = astar(&CostMap::new(grid, 0.5, 5.0, 1.0), at(0, 1), at(9, 1));
        let (plain, careful) = (plain.expect("plain"), careful.expect("careful"));
        // Along the wall when length is all that counts; away from it when nearness costs.
        assert!(plain.cells.iter().all(|c| c.y == 1), "{:?}", plain.cells);
        assert!(careful.cells.iter().any(|c| c.y >= 3), "{:?}", careful.cells);
        assert!(careful.length_m > plain.length_m);
    }

    proptest! {
        #[test]
        fn astar_costs_what_dijkstra_costs(bits in proptest::collection::vec(0u8..4, 100)) {
            let rows: Vec<String> = (0..10)
                .map(|y| (0..10).map(|x| if bits[y * 10 + x] == 0 && (x, y) != (0, 9) && (x, y) != (9, 0) { '#' } else { '.' }).collect())
                .collect();
            let rows: Vec<&str> = rows.iter().map(String::as_str).collect();
            let grid = OccupancyGrid::from_rows(&rows, 0.1, Vec2::default());
            let m = CostMap::new(grid, 0.05, 1.0, 0.2);
            let (a, b) = (Vec2::new(0.05, 0.05), Vec2::new(0.95, 0.95));
            match (search(&m, a, b, true), search(&m, a, b, false)) {
                (Ok(x), Ok(y)) => prop_assert!((x.cost - y.cost).abs() < 1e-9),
                (Err(PlanError::NoPath { .. }), Err(PlanError::NoPath { .. })) => {}
                (x, y) => prop_assert!(false, "{x:?} vs {y:?}"),
            }
        }
    }
}
