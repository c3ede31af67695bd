//! The navigation task's measures (paper section 3.1, Figures 8 and 9): for every episode,
//! whether and when the goal was reached, how far the robot drove and how that compares with
//! the shortest collision-free path on the grid; `navigation.csv` and `navigation.md`.
//!
//! The shortest path is A* ([`mdrlat_plan::astar`]) on a 5 cm map of everything the robot's
//! body can hit, inflated by its radius, with no cost near walls: the shortest route the
//! robot could have taken, known only to the evaluation.

use crate::EvalError;
use crate::protocol::{EpisodeRecord, WorldEval, collision_kind};
use crate::report::{csv_field, csv_split};
use mdrlat_plan::{CostMap, MapKind, OccupancyGrid, astar};
use mdrlat_sim::SimConfig;
use mdrlat_world::World;
use std::fmt::Write as _;

/// Cell side of the map the shortest paths are measured on, metres.
pub const SHORTEST_PATH_RESOLUTION_M: f32 = 0.05;

/// One navigation episode's measures.
#[derive(Debug, Clone, PartialEq)]
pub struct NavRecord {
    /// The robot reached its goal.
    pub reached: bool,
    /// Neither reached nor collided: the step budget ran out.
    pub timeout: bool,
    /// It ended in a collision.
    pub collided: bool,
    /// Seconds to the goal (reached episodes).
    pub time_s: Option<f32>,
    /// Distance driven, metres.
    pub path_m: f32,
    /// The shortest collision-free path from the start to the goal on the grid, metres.
    pub shortest_m: f32,
}

impl NavRecord {
    /// Driven over shortest distance (reached episodes).
    pub fn path_ratio(&self) -> Option<f32> {
        (self.reached && self.shortest_m > 0.0).then(|| self.path_m / self.shortest_m)
    }
}

/// The measures of every navigation episode of `w` (evaluated in `world` with `sim`).
///
/// # Errors
/// A record without a goal (not the navigation task), or a goal the robot cannot reach from
/// its start on the grid (named with its episode).
pub fn nav_records(
    world: &World,
    sim: &SimConfig,
    w: &WorldEval,
) -> Result<Vec<NavRecord>, EvalError> {
    let body = MapKind::Body { height_m: sim.robot.body_height_m };
    let grid = OccupancyGrid::from_world(world, body, SHORTEST_PATH_RESOLUTION_M)
        .map_err(EvalError::Nav)?;
    let map = CostMap::new(grid, sim.robot.radius_m, 0.0, 1.0);
    w.records.iter().map(|r| nav_record(&map, r, sim.dt_s)).collect()
}

fn nav_record(map: &CostMap, r: &EpisodeRecord, dt_s: f32) -> Result<NavRecord, EvalError> {
    let where_ =
        || format!("world '{}' run {} episode {} (seed {})", r.world, r.run, r.episode, r.seed);
    let goal = r.goal.ok_or_else(|| {
        EvalError::Nav(format!("{}: not a navigation episode (no goal)", where_()))
    })?;
    let shortest = astar(map, r.start.position(), goal).map_err(|e| {
        EvalError::Nav(format!("{}: the goal is unreachable on the grid: {e}", where_()))
    })?;
    let reached = r.reached_goal;
    Ok(NavRecord {
        reached,
        timeout: !reached && r.collision.is_none(),
        collided: r.collision.is_some(),
        time_s: reached.then_some(r.steps as f32 * dt_s),
        path_m: r.path_m,
        shortest_m: shortest.length_m,
    })
}

/// The header of `navigation.csv`.
pub const NAVIGATION_HEADER: &str = "world,run,episode,seed,goal_x,goal_y,reached,timeout,\
collision_kind,time_s,path_m,shortest_m,path_ratio";

/// `navigation.csv`: one row per episode of every world (header included).
pub fn navigation_csv(worlds: &[(&WorldEval, Vec<NavRecord>)]) -> String {
    let mut s = String::from(NAVIGATION_HEADER);
    s.push('\n');
    for (w, navs) in worlds {
        for (r, n) in w.records.iter().zip(navs) {
            let goal = r.goal.unwrap_or_default();
            let _ = writeln!(
                s,
                "{},{},{},{},{:.3},{:.3},{},{},{},{},{:.3},{:.3},{}",
                csv_field(&r.world),
                r.run,
                r.episode,
                r.seed,
                goal.x,
                goal.y,
                u8::from(n.reached),
                u8::from(n.timeout),
                r.collision.as_ref().map_or("", collision_kind),
                n.time_s.map(|t| format!("{t:.1}")).unwrap_or_default(),
                n.path_m,
                n.shortest_m,
                n.path_ratio().map(|x| format!("{x:.3}")).unwrap_or_default()
            );
        }
    }
    s
}

/// One world's navigation results.
#[derive(Debug, Clone, PartialEq)]
pub struct NavSummary {
    /// The policy.
    pub eval: String,
    /// The world.
    pub world: String,
    /// Episodes.
    pub episodes: usize,
    /// Reached.
    pub reached: usize,
    /// Collided.
    pub collisions: usize,
    /// Ran out of steps.
    pub timeouts: usize,
    /// Mean seconds to the goal over the reached episodes.
    pub time_s_mean: Option<f64>,
    /// Mean distance driven over the reached episodes, metres.
    pub path_m_mean: Option<f64>,
    /// Mean shortest distance over the reached episodes, metres.
    pub shortest_m_mean: Option<f64>,
    /// Mean ratio of the two over the reached episodes.
    pub path_ratio_mean: Option<f64>,
}

/// The rows of a `navigation.csv` as `(world, record)`, in file order; `source` names the
/// file in errors.
///
/// # Errors
/// Not a `navigation.csv` header, or a row whose fields do not parse (named by line).
pub fn parse_navigation_csv(text: &str, source: &str) -> Result<Vec<(String, NavRecord)>, String> {
    let mut lines = text.lines();
    match lines.next() {
        Some(h) if h == NAVIGATION_HEADER => {}
        Some(h) => return Err(format!("{source}:1: not a navigation.csv header: '{h}'")),
        None => return Err(format!("{source}: empty file")),
    }
    let mut rows = Vec::new();
    for (n, line) in lines.enumerate().filter(|(_, l)| !l.is_empty()) {
        let at = |col: &str, v: &str| format!("{source}:{}: {col} '{v}' is not valid", n + 2);
        let f = csv_split(line);
        if f.len() != 13 {
            return Err(format!("{source}:{}: {} fields, expected 13", n + 2, f.len()));
        }
        let flag = |i: usize, col: &str| match f[i].as_str() {
            "0" => Ok(false),
            "1" => Ok(true),
            v => Err(at(col, v)),
        };
        let num = |i: usize, col: &str| f[i].parse::<f32>().map_err(|_| at(col, &f[i]));
        let (reached, timeout) = (flag(6, "reached")?, flag(7, "timeout")?);
        let time_s = if f[9].is_empty() { None } else { Some(num(9, "time_s")?) };
        if reached != time_s.is_some() || (reached && timeout) {
            return Err(format!("{source}:{}: reached, timeout and time_s disagree", n + 2));
        }
        rows.push((
            f[0].clone(),
            NavRecord {
                reached,
                timeout,
                collided: !f[8].is_empty(),
                time_s,
                path_m: num(10, "path_m")?,
                shortest_m: num(11, "shortest_m")?,
            },
        ));
    }
    Ok(rows)
}

impl NavSummary {
    /// Summarises the episodes `navs` of `eval` in `world`.
    pub fn new(eval: &str, world: &str, navs: &[NavRecord]) -> Self {
        let ok: Vec<&NavRecord> = navs.iter().filter(|n| n.reached).collect();
        let mean = |f: &dyn Fn(&NavRecord) -> f64| {
            (!ok.is_empty()).then(|| ok.iter().map(|n| f(n)).sum::<f64>() / ok.len() as f64)
        };
        Self {
            eval: eval.to_string(),
            world: world.to_string(),
            episodes: navs.len(),
            reached: ok.len(),
            collisions: navs.iter().filter(|n| n.collided).count(),
            timeouts: navs.iter().filter(|n| n.timeout).count(),
            time_s_mean: mean(&|n| f64::from(n.time_s.unwrap_or(0.0))),
            path_m_mean: mean(&|n| f64::from(n.path_m)),
            shortest_m_mean: mean(&|n| f64::from(n.shortest_m)),
            path_ratio_mean: mean(&|n| f64::from(n.path_ratio().unwrap_or(0.0))),
        }
    }
}

/// `navigation.md`: per world and method, success, collisions, timeouts, time, path and
/// path ratio.
pub fn navigation_markdown(rows: &[NavSummary], max_steps: u32, sim: &SimConfig) -> String {
    let goal_radius_m = sim.nav.goal_radius_m;
    let mut s = format!(
        "# Navigation\n\nSuccess = the robot's centre within {goal_radius_m} m of the goal \
         within {max_steps} steps ({:.0} s). Time, path and path ratio (driven / shortest \
         collision-free path on the grid) are means over the episodes that reached the goal.\n\n",
        f64::from(max_steps) * f64::from(sim.dt_s)
    );
    s.push_str("| method | world | success % | collisions | timeouts | mean time s | mean path m | mean shortest m | path ratio |\n");
    s.push_str("| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
    let opt = |x: Option<f64>, d: usize| x.map_or("—".to_string(), |x| format!("{x:.d$}"));
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {:.1} ({}/{}) | {} | {} | {} | {} | {} | {} |",
            r.eval.replace('|', "\\|"),
            r.world.replace('|', "\\|"),
            100.0 * r.reached as f64 / r.episodes.max(1) as f64,
            r.reached,
            r.episodes,
            r.collisions,
            r.timeouts,
            opt(r.time_s_mean, 1),
            opt(r.path_m_mean, 2),
            opt(r.shortest_m_mean, 2),
            opt(r.path_ratio_mean, 2)
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn navigation_csv_rows_read_back_and_bad_rows_name_their_line() {
        let text = format!(
            "{NAVIGATION_HEADER}\n\
             nav-test,0,0,7,8.200,9.300,1,0,,20.4,9.120,8.700,1.048\n\
             nav-test,0,1,8,1.000,2.000,0,0,bumper,,3.500,6.000,\n\
             nav-test,0,2,9,1.000,2.000,0,1,,,1.250,6.000,\n"
        );
        let rows = parse_navigation_csv(&text, "a/navigation.csv").expect("parses");
        assert_eq!(rows.len(), 3);
        assert_eq!(rows[0].0, "nav-test");
        assert!(rows[0].1.reached && rows[0].1.time_s == Some(20.4));
        assert!(rows[1].1.collided && !rows[1].1.timeout);
        assert!(rows[2].1.timeout && !rows[2].1.collided);
        let navs: Vec<NavRecord> = rows.into_iter().map(|(_, r)| r).collect();
        let s = NavSummary::new("m", "nav-test", &navs);
        assert_eq!((s.episodes, s.reached, s.collisions, s.timeouts), (3, 1, 1, 1));
        assert!((s.path_ratio_mean.expect("one reached") - 9.12 / 8.7).abs() < 1e-3);
        let bad = text.replace(",1,0,,20.4,", ",1,0,,,");
        let e = parse_navigation_csv(&bad, "a/navigation.csv").expect_err("disagree");
        assert!(e.contains("a/navigation.csv:2") && e.contains("disagree"), "{e}");
        let e = parse_navigation_csv("world,x\n", "b.csv").expect_err("header");
        assert!(e.contains("b.csv:1: not a navigation.csv header"), "{e}");
        let e = parse_navigation_csv(&text.replace("9.120", "far"), "c.csv").expect_err("num");
        assert!(e.contains("c.csv:2: path_m 'far'"), "{e}");
    }
}
