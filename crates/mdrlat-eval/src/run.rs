//! An evaluation as one operation: a policy in several worlds by the protocol, into a
//! folder with its tables and figures (what `mdrlat eval` does; the CLI only parses its
//! arguments, builds the policy and shows the progress).
//!
//! ```text
//! out/
//!   episodes.csv   one row per episode (every world, run and episode)
//!   summary.csv    one row per world: both success rates (mean ± std over runs), path, collisions
//!   summary.md     the same as a table
//!   navigation.csv, navigation.md   (navigation) time to goal, path against the shortest
//!   figures/       (figures > 0) Figs. 6/7 of the picked episodes; WORLD-collisions.png, where
//!                  every collision happened; Fig. 9 in navigation
//! ```

use crate::{
    EvalError, EvalSettings, NavRecord, NavSummary, Progress, Timing, WorldEval, WorldSummary,
    draw_collisions, draw_episode, draw_navigation, episodes_csv, eval_sim_config, evaluate_world,
    nav_records, navigation_csv, navigation_markdown, parse_summary_csv, pick_episodes,
    summary_csv, summary_markdown,
};
use mdrlat_core::Policy;
use mdrlat_sim::SimConfig;
use mdrlat_sim::config::Task;
use mdrlat_world::World;
use std::path::Path;

/// Makes the policy for a world.
pub type PolicyMaker<'a> = dyn FnMut(&World) -> Result<Box<dyn Policy>, EvalError> + 'a;

/// Who acts in the evaluated episodes.
pub enum Agent<'a> {
    /// One policy in every world.
    One(&'a mut dyn Policy),
    /// A policy made for each world (the planner plans on that world's map).
    PerWorld(&'a mut PolicyMaker<'a>),
}

/// Where the results go and what is drawn.
#[derive(Debug, Clone, Copy)]
pub struct Output<'a> {
    /// The folder (created if missing).
    pub dir: &'a Path,
    /// Replace an earlier evaluation in `dir` (its figures are removed first); without it an
    /// earlier evaluation there is an error.
    pub overwrite: bool,
    /// Figs. 6/7 for this many episodes (the longest successes and the dead ends); in
    /// navigation also Fig. 9 with the first this many start/goal pairs of run 0.
    pub figures: usize,
}

/// One world's results, as they come.
#[derive(Debug, Clone)]
pub struct WorldResult {
    /// Every episode.
    pub eval: WorldEval,
    /// The protocol's numbers.
    pub summary: WorldSummary,
    /// Where the time went.
    pub timing: Timing,
    /// Navigation's measures (time, path against the shortest) when the task is navigation.
    pub navigation: Option<(NavSummary, Vec<NavRecord>)>,
}

/// What an evaluation produced.
#[derive(Debug, Clone)]
pub struct EvalReport {
    /// Each world's results, in the order given.
    pub worlds: Vec<WorldResult>,
    /// The names of the policies that acted (one, or one per world kind).
    pub policies: Vec<String>,
    /// The files written, relative to the output folder.
    pub written: Vec<&'static str>,
}

/// What the caller sees while an evaluation runs (a progress bar, a table as it grows).
pub trait EvalObserver {
    /// An episode finished in the current world; `before` episodes were done in earlier
    /// worlds.
    fn progress(&mut self, before: usize, progress: &Progress<'_>) {
        let _ = (before, progress);
    }
    /// A world is done.
    fn world_done(&mut self, result: &WorldResult) {
        let _ = result;
    }
}

/// An observer that shows nothing.
impl EvalObserver for () {}

fn io(path: &Path, e: impl std::fmt::Display) -> EvalError {
    EvalError::Output(format!("{}: {e}", path.display()))
}

/// Writes `text` to `path`; an error names the file.
///
/// # Errors
/// The file cannot be written.
pub fn write(path: &Path, text: &str) -> Result<(), EvalError> {
    std::fs::write(path, text).map_err(|e| io(path, e))
}

/// Makes `dir` ready for an evaluation: refuses to mix with or silently replace an earlier
/// one; with `overwrite`, removes the figures of the evaluation it replaces (so old pictures
/// do not mix with new ones).
///
/// # Errors
/// An earlier evaluation without `overwrite`, or a folder that cannot be made.
pub fn prepare_output(dir: &Path, overwrite: bool) -> Result<(), EvalError> {
    let old = ["episodes.csv", "summary.csv", "summary.md"].iter().any(|f| dir.join(f).exists());
    if old && !overwrite {
        return Err(EvalError::Output(format!(
            "{} already holds an evaluation: choose another folder, or overwrite it",
            dir.display()
        )));
    }
    let figures = dir.join("figures");
    if old && figures.is_dir() {
        std::fs::remove_dir_all(&figures).map_err(|e| io(&figures, e))?;
    }
    std::fs::create_dir_all(dir).map_err(|e| io(dir, e))
}

/// Evaluates `agent` in each of `worlds` by the protocol of `settings` in the simulator of
/// `sim`, writing the tables (and figures) into `out.dir`. `flop_per_decision` (a network's)
/// gives the timing its GFLOP/s.
///
/// # Errors
/// Unusable settings, an output folder that holds an earlier evaluation (without
/// `overwrite`) or cannot be written, a world the simulator cannot use, or a policy that
/// fails to decide.
pub fn evaluate(
    worlds: &[World],
    sim: &SimConfig,
    settings: &EvalSettings,
    mut agent: Agent<'_>,
    flop_per_decision: Option<f64>,
    out: &Output<'_>,
    observer: &mut dyn EvalObserver,
) -> Result<EvalReport, EvalError> {
    settings.validate()?;
    prepare_output(out.dir, out.overwrite)?;
    let nav = sim.task == Task::Nav;
    let eval_sim = eval_sim_config(sim, settings);
    let mut report = EvalReport { worlds: Vec::new(), policies: Vec::new(), written: Vec::new() };
    let mut before = 0;
    for world in worlds {
        let mut made;
        let policy: &mut dyn Policy = match &mut agent {
            Agent::One(p) => &mut **p,
            Agent::PerWorld(make) => {
                made = make(world)?;
                made.as_mut()
            }
        };
        let name = policy.name();
        if !report.policies.contains(&name) {
            report.policies.push(name.clone());
        }
        let eval = evaluate_world(world, sim, policy, settings, &mut |p| {
            observer.progress(before, p);
        })?;
        before += eval.records.len();
        let navigation = if nav {
            let records = nav_records(world, &eval_sim, &eval)?;
            Some((NavSummary::new(&name, &eval.world, &records), records))
        } else {
            None
        };
        let result = WorldResult {
            summary: WorldSummary::new(&name, &eval, settings),
            timing: Timing::of(&eval, flop_per_decision),
            eval,
            navigation,
        };
        observer.world_done(&result);
        report.worlds.push(result);
    }

    let evals: Vec<&WorldEval> = report.worlds.iter().map(|w| &w.eval).collect();
    let summaries: Vec<WorldSummary> = report.worlds.iter().map(|w| w.summary.clone()).collect();
    write(&out.dir.join("episodes.csv"), &episodes_csv(evals.iter().copied(), &settings.moving))?;
    write(&out.dir.join("summary.md"), &summary_markdown(&summaries))?;
    report.written.extend(["episodes.csv", "summary.csv", "summary.md"]);
    let navigation: Vec<(&WorldEval, &(NavSummary, Vec<NavRecord>))> =
        report.worlds.iter().filter_map(|w| w.navigation.as_ref().map(|n| (&w.eval, n))).collect();
    if nav {
        let rows: Vec<(&WorldEval, Vec<NavRecord>)> =
            navigation.iter().map(|(e, (_, r))| (*e, r.clone())).collect();
        write(&out.dir.join("navigation.csv"), &navigation_csv(&rows))?;
        let sums: Vec<NavSummary> = navigation.iter().map(|(_, (n, _))| n.clone()).collect();
        let md = navigation_markdown(&sums, settings.max_steps, &eval_sim);
        write(&out.dir.join("navigation.md"), &md)?;
        report.written.extend(["navigation.csv", "navigation.md"]);
    }
    if out.figures > 0 {
        let dir = out.dir.join("figures");
        std::fs::create_dir_all(&dir).map_err(|e| io(&dir, e))?;
        for (w, i, why) in pick_episodes(&evals, out.figures) {
            let record = &evals[w].records[i];
            let fig = draw_episode(&worlds[w], &eval_sim, record, why)?;
            let stem =
                format!("{}-run{}-ep{}", file_stem(&record.world), record.run, record.episode);
            let strip = dir.join(format!("{stem}.png"));
            fig.strip.save_png(&strip).map_err(|e| io(&strip, e))?;
            let top = dir.join(format!("{stem}-trajectory.png"));
            fig.trajectory.save_png(&top).map_err(|e| io(&top, e))?;
        }
        // Where the policy collides: every collision of the world on one map.
        for (world, w) in worlds.iter().zip(&report.worlds) {
            if w.eval.records.iter().any(|r| r.collision.is_some()) {
                let fig = draw_collisions(world, &eval_sim, &w.eval.records, &w.summary.eval)?;
                let path = dir.join(format!("{}-collisions.png", file_stem(&world.name)));
                fig.save_png(&path).map_err(|e| io(&path, e))?;
            }
        }
        // Fig. 9: the first K start/goal pairs of run 0 (the same for every method evaluated
        // with this seed), all on one map.
        for (world, (e, (n, _))) in worlds.iter().zip(&navigation) {
            let records: Vec<_> =
                e.records.iter().filter(|r| r.run == 0).take(out.figures).collect();
            let fig = draw_navigation(world, &eval_sim, &records, &n.eval)?;
            let path = dir.join(format!("{}-fig9.png", file_stem(&world.name)));
            fig.save_png(&path).map_err(|e| io(&path, e))?;
        }
        report.written.push("figures/");
    }
    // Last: a folder with a summary.csv holds a finished evaluation (`earlier_evaluation`).
    write(&out.dir.join("summary.csv"), &summary_csv(&summaries))?;
    Ok(report)
}

/// The finished evaluation in `dir` that stands for the one `settings` would make of the
/// policy named `policy` in `worlds`, if there is one: its `summary.csv` (written last, so
/// present only once everything else is) read back. `Ok(None)`: nothing finished there.
/// `mdrlat eval --snapshots --only-new` keeps the snapshots it evaluated before this way.
///
/// # Errors
/// A `summary.csv` that cannot be read, or one of other worlds, settings (episodes, runs,
/// step budget, seed, moving rule) or another policy: never silently mixed in.
pub fn earlier_evaluation(
    dir: &Path,
    policy: &str,
    worlds: &[World],
    settings: &EvalSettings,
) -> Result<Option<Vec<WorldSummary>>, EvalError> {
    let path = dir.join("summary.csv");
    let text = match std::fs::read_to_string(&path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io(&path, e)),
    };
    let rows = parse_summary_csv(&text, &path.display().to_string()).map_err(EvalError::Output)?;
    let other = |what: String| {
        EvalError::Output(format!(
            "{} holds an evaluation of {what}: choose another folder, or overwrite it",
            path.display()
        ))
    };
    let names: Vec<&str> = rows.iter().map(|r| r.world.as_str()).collect();
    let wanted: Vec<&str> = worlds.iter().map(|w| w.name.as_str()).collect();
    if names != wanted {
        return Err(other(format!("the worlds {names:?}, not {wanted:?}")));
    }
    let m = &settings.moving;
    let rule = |path: f64, reach: f64| format!("{path:.3} m driven, {reach:.3} m reached");
    for r in &rows {
        if r.eval != policy {
            return Err(other(format!("'{}', not '{policy}'", r.eval)));
        }
        let theirs = (r.episodes, r.runs, r.max_steps, r.seed, rule(r.min_path_m, r.min_reach_m));
        let ours = (
            settings.episodes,
            settings.runs,
            settings.max_steps,
            settings.seed,
            rule(f64::from(m.min_path_m), f64::from(m.min_reach_m)),
        );
        if theirs != ours {
            return Err(other(format!(
                "other settings in {} (episodes, runs, steps, seed, moving rule: {theirs:?}, \
                 not {ours:?})",
                r.world
            )));
        }
    }
    Ok(Some(rows))
}

/// A file-name-safe form of a world's name.
fn file_stem(name: &str) -> String {
    name.chars()
        .map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' })
        .collect()
}
