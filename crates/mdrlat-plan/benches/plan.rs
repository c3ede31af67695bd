//! Criterion benches of the classical planner (issue: "fast enough not to matter"): one A*
//! plan across nav-test and across the Nav2 depot map, a cost map built from a world, and
//! one planner decision (DWA on a scan) against one simulator step.

use criterion::{Criterion, criterion_group, criterion_main};
use mdrlat_core::Policy;
use mdrlat_geom::Vec2;
use mdrlat_plan::{CostMap, MapKind, OccupancyGrid, PlannerOptions, PlannerPolicy, astar};
use mdrlat_sim::config::Task;
use mdrlat_sim::{Env, SimConfig};
use std::hint::black_box;

fn body_map(world: &mdrlat_world::World) -> CostMap {
    let grid =
        OccupancyGrid::from_world(world, MapKind::Body { height_m: 0.45 }, 0.05).expect("grid");
    CostMap::new(grid, 0.2 + 0.08, 3.0, 0.15)
}

fn plans(c: &mut Criterion) {
    let mut g = c.benchmark_group("plan_astar");
    let nav = mdrlat_world::load("nav-test").expect("nav-test");
    let map = body_map(&nav);
    // South-west room to north-east room: through two doors.
    let (a, b) = (Vec2::new(1.0, 1.0), Vec2::new(8.2, 9.3));
    assert!(astar(&map, a, b).is_ok());
    g.bench_function("nav-test across", |bench| bench.iter(|| black_box(astar(&map, a, b))));
    let depot =
        mdrlat_world::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../../worlds/maps/depot.yaml"))
            .expect("depot");
    let dmap = body_map(&depot);
    let mut regions = depot.spawn.clone();
    regions.sort_by(|x, y| y.area().total_cmp(&x.area()));
    let from = (regions[0].min + regions[0].max) * 0.5;
    let to = regions[1..]
        .iter()
        .map(|r| (r.min + r.max) * 0.5)
        .filter_map(|p| astar(&dmap, from, p).ok().map(|path| (path.length_m, p)))
        .fold((0.0, from), |best, x| if x.0 > best.0 { x } else { best })
        .1;
    g.bench_function("depot longest", |bench| bench.iter(|| black_box(astar(&dmap, from, to))));
    g.bench_function("nav-test cost map", |bench| bench.iter(|| black_box(body_map(&nav))));
    g.finish();
}

fn decisions(c: &mut Criterion) {
    let mut g = c.benchmark_group("plan_decision");
    let world = mdrlat_world::load("nav-test").expect("nav-test");
    let config = SimConfig { task: Task::Nav, ..SimConfig::default() };
    let mut planner =
        PlannerPolicy::new(&world, &config, &PlannerOptions::default()).expect("planner");
    let mut env = Env::from_world(world, config).expect("env");
    env.reset(Some(1)).expect("reset");
    let mut decisions = Vec::new();
    let obs = env.observation().clone();
    planner.decide(&[&obs], &[0], &mut decisions).expect("plan");
    g.bench_function("planner (DWA on one scan)", |bench| {
        bench.iter(|| {
            planner.decide(&[&obs], &[0], &mut decisions).expect("decide");
            black_box(decisions[0].command)
        })
    });
    let ahead = mdrlat_core::Action::new(5).expect("action");
    g.bench_function("one simulator step (for scale)", |bench| {
        bench.iter(|| {
            let s = env.step(ahead).expect("step");
            let done = s.terminated || s.truncated;
            black_box(s.reward);
            if done {
                env.reset(None).expect("reset");
            }
        })
    });
    g.finish();
}

criterion_group!(benches, plans, decisions);
criterion_main!(benches);
