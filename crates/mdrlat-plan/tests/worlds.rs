//! The planner on the built-in navigation worlds and a real map_server map.

use mdrlat_geom::Vec2;
use mdrlat_plan::{CostMap, MapKind, OccupancyGrid, astar};
use mdrlat_world::World;

const RADIUS: f32 = mdrlat_core::robot::RADIUS_M;

fn world(spec: &str) -> World {
    mdrlat_world::load(spec).unwrap_or_else(|e| panic!("{spec}: {e}"))
}

fn body(w: &World) -> CostMap {
    let grid = OccupancyGrid::from_world(w, MapKind::Body { height_m: 0.45 }, 0.05).expect("grid");
    CostMap::new(grid, RADIUS, 0.0, 0.1)
}

fn center(b: &mdrlat_geom::Aabb) -> Vec2 {
    (b.min + b.max) * 0.5
}

#[test]
fn every_goal_of_nav_test_is_reachable_from_every_spawn_region() {
    let w = world("nav-test");
    assert!(!w.goals.is_empty() && !w.spawn.is_empty());
    let map = body(&w);
    let mut plans = 0;
    for s in w.spawn.iter().map(center).filter(|&p| w.is_free(p, RADIUS + 0.05)) {
        for g in w.goals.iter().map(center) {
            let p = astar(&map, s, g).unwrap_or_else(|e| panic!("{s:?} -> {g:?}: {e}"));
            assert!(p.length_m >= (g - s).length() - 1e-3);
            // Every cell of the plan keeps the robot's radius from the obstacles it can hit.
            assert!(p.cells.iter().all(|&c| map.clearance(c) >= RADIUS));
            plans += 1;
        }
    }
    assert!(plans >= w.goals.len(), "{plans} plans");
}

#[test]
fn the_laser_plane_map_misses_what_lies_below_or_above_the_laser() {
    let w = world("nav-test");
    let laser = OccupancyGrid::from_world(&w, MapKind::LaserPlane { height_m: 0.40 }, 0.05)
        .expect("laser map");
    let full = OccupancyGrid::from_world(&w, MapKind::Body { height_m: 0.45 }, 0.05).expect("body");
    assert!(laser.occupied_cells() < full.occupied_cells());
    // The coffee table's top (0.33-0.38 m) is under the laser plane: not on the SLAM map.
    let table = full.cell_of(Vec2::new(1.9, 2.6)).expect("in the map");
    assert!(full.is_occupied(table) && !laser.is_occupied(table));
    // A wall is on both.
    let wall = full.cell_of(Vec2::new(5.0, 0.05)).expect("in the map");
    assert!(full.is_occupied(wall) && laser.is_occupied(wall));
}

#[test]
fn a_real_map_server_map_plans_across_the_depot() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../worlds/maps/depot.yaml");
    let w = world(path);
    let map = body(&w);
    // From the largest free region to the others: the building is one connected space.
    let mut regions = w.spawn.clone();
    regions.sort_by(|a, b| b.area().total_cmp(&a.area()));
    let from = center(&regions[0]);
    let mut reached = Vec::new();
    for r in &regions[1..] {
        if let Ok(p) = astar(&map, from, center(r)) {
            reached.push(p.length_m);
        }
    }
    // (2026-12-02: 667 of 693 regions, the others too narrow for the inflated robot or
    // outside the walls; the longest plan 22.2 m.)
    assert!(reached.len() * 10 >= regions.len() * 9, "{} of {}", reached.len(), regions.len());
    assert!(reached.iter().any(|&l| l > 15.0), "a plan across the building");
    let e = OccupancyGrid::from_world(&w, MapKind::Body { height_m: 0.45 }, 0.0).expect_err("bad");
    assert!(e.contains("resolution 0 m"), "{e}");
    let e =
        OccupancyGrid::from_world(&w, MapKind::Body { height_m: 0.45 }, 1e-4).expect_err("huge");
    assert!(e.contains("coarser"), "{e}");
}
