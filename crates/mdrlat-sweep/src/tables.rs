//! Table 2 from a sweep's evaluations, beside the paper's numbers, and the report that says
//! whether the paper's ordering holds. Results only (no times, no host names), fixed
//! precision and order: a sweep killed and resumed writes the same `table2.csv` bytes.

use crate::SweepError;
use crate::plan::{Job, JobKind, JobState, Plan, run_name, write_atomic};
use mdrlat_core::Variant;
use mdrlat_eval::nav::{NavRecord, NavSummary, navigation_markdown, parse_navigation_csv};
use mdrlat_eval::{WorldSummary, parse_summary_csv, report::csv_field};
use mdrlat_sim::config::Task;
use std::fmt::Write as _;

/// A world's row of the paper's Table 2: (variant, mean %, std %) per method.
pub type PaperRow = [(Variant, f64, f64); 6];

/// The paper's Table 2 (mean, std in percent): Env1–3 are `office`, `furnished`, `crowd`.
pub const PAPER_TABLE2: [(&str, PaperRow); 3] = [
    (
        "office",
        [
            (Variant::LaserOnly, 67.6, 4.8),
            (Variant::DepthOnly, 69.2, 3.5),
            (Variant::Multi, 76.8, 4.1),
            (Variant::MultiAt, 86.0, 4.2),
            (Variant::MultiBf, 89.6, 1.5),
            (Variant::Mdrlat, 94.4, 2.3),
        ],
    ),
    (
        "furnished",
        [
            (Variant::LaserOnly, 61.6, 4.6),
            (Variant::DepthOnly, 55.2, 4.8),
            (Variant::Multi, 73.6, 5.3),
            (Variant::MultiAt, 78.8, 2.7),
            (Variant::MultiBf, 81.2, 3.0),
            (Variant::Mdrlat, 87.2, 2.4),
        ],
    ),
    (
        "crowd",
        [
            (Variant::LaserOnly, 64.8, 3.2),
            (Variant::DepthOnly, 63.2, 2.7),
            (Variant::Multi, 70.8, 4.1),
            (Variant::MultiAt, 78.4, 5.0),
            (Variant::MultiBf, 79.6, 3.4),
            (Variant::Mdrlat, 83.6, 3.2),
        ],
    ),
];

/// Why a sweep's results are not comparable with the paper's Table 2 (`None`: they are:
/// obstacle avoidance, the paper's 400,000 training steps or more, and its protocol of 5 runs
/// of 50 episodes of 300 steps). A paper number is printed next to comparable results only.
pub fn not_comparable(sweep: &crate::Sweep) -> Option<String> {
    let e = &sweep.eval;
    if sweep.task != Task::Avoid {
        Some("the paper gives no navigation numbers".into())
    } else if sweep.steps < 400_000 {
        Some(format!(
            "this sweep trains {} steps, the paper 400,000{}",
            sweep.steps,
            if sweep.steps < 1000 { " (a pipeline check, not a trained policy)" } else { "" }
        ))
    } else if (e.runs, e.episodes, e.max_steps) != (5, 50, 300) {
        Some(format!(
            "this sweep evaluates {} runs of {} episodes of {} steps, the paper 5 of 50 of 300",
            e.runs, e.episodes, e.max_steps
        ))
    } else {
        None
    }
}

/// The paper's cell, percent.
pub fn paper_cell(world: &str, variant: Variant) -> Option<(f64, f64)> {
    PAPER_TABLE2
        .iter()
        .find(|(w, _)| *w == world)
        .and_then(|(_, cells)| cells.iter().find(|c| c.0 == variant))
        .map(|c| (c.1, c.2))
}

/// A method of the table: a trained variant (over the sweep's seeds) or a baseline.
#[derive(Debug, Clone, PartialEq)]
pub enum Method {
    /// A network variant.
    Variant(Variant),
    /// A scripted baseline.
    Baseline(String),
}

impl Method {
    /// Its column name.
    pub fn name(&self) -> String {
        match self {
            Method::Variant(v) => v.to_string(),
            Method::Baseline(b) => b.clone(),
        }
    }

    /// The ids of its evaluation jobs in `plan`: one per seed for a variant.
    fn eval_ids(&self, plan: &Plan) -> Vec<String> {
        match self {
            Method::Variant(v) => plan
                .sweep
                .seeds
                .iter()
                .map(|&seed| format!("eval/{}", run_name(*v, seed)))
                .collect(),
            Method::Baseline(b) => vec![format!("eval/{b}")],
        }
    }

    /// Every method of a sweep, in column order: the variants, then the baselines.
    fn all(plan: &Plan) -> Vec<Method> {
        let s = &plan.sweep;
        let mut methods: Vec<Method> = s.variants.iter().map(|&v| Method::Variant(v)).collect();
        methods.extend(s.eval.baselines.iter().map(|b| Method::Baseline(b.clone())));
        methods
    }
}

/// Which success rate a table or a claim reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Metric {
    /// The moving success (no collision, and the robot travelled): the headline.
    Moving,
    /// The paper's success (no collision within the step budget): the one compared with
    /// the paper's Table 2.
    Paper,
}

/// One cell: a method in a world.
#[derive(Debug, Clone, PartialEq)]
pub struct Cell {
    /// The world.
    pub world: String,
    /// The method.
    pub method: Method,
    /// Moving success rate of every run of every seed, in seed order (fractions).
    pub moving_per_run: Vec<f64>,
    /// Each seed's mean moving success rate (fractions), in seed order.
    pub moving_per_seed: Vec<f64>,
    /// Success rate (the paper's) of every run of every seed, in seed order (fractions).
    pub per_run: Vec<f64>,
    /// Each seed's mean success rate (fractions), in seed order.
    pub per_seed: Vec<f64>,
    /// Each seed's mean distance driven per episode, metres (a policy that turns in place
    /// never collides: success alone cannot tell it from one that drives).
    pub path_m: Vec<f64>,
    /// Evaluations missing from this cell, with why (job id: reason).
    pub missing: Vec<String>,
}

impl Cell {
    /// Mean distance driven per episode over the seeds, metres.
    pub fn path_mean(&self) -> Option<f64> {
        (!self.path_m.is_empty() && self.missing.is_empty())
            .then(|| self.path_m.iter().sum::<f64>() / self.path_m.len() as f64)
    }

    /// The paper's success: mean and population std over all runs of all seeds, percent.
    pub fn stats(&self) -> Option<(f64, f64)> {
        self.metric_stats(Metric::Paper)
    }

    /// Each run's rate of `metric`, every seed's runs in seed order.
    pub fn per_run_of(&self, metric: Metric) -> &[f64] {
        match metric {
            Metric::Moving => &self.moving_per_run,
            Metric::Paper => &self.per_run,
        }
    }

    /// Each seed's mean rate of `metric`, in seed order.
    pub fn per_seed_of(&self, metric: Metric) -> &[f64] {
        match metric {
            Metric::Moving => &self.moving_per_seed,
            Metric::Paper => &self.per_seed,
        }
    }

    /// Mean and population std of `metric` over all runs of all seeds, percent.
    pub fn metric_stats(&self, metric: Metric) -> Option<(f64, f64)> {
        let per_run = self.per_run_of(metric);
        if per_run.is_empty() || !self.missing.is_empty() {
            return None;
        }
        let (mean, std) = mdrlat_eval::report::mean_std(per_run);
        Some((100.0 * mean, 100.0 * std))
    }
}

/// The whole table: cells by world (the sweep's order), then method.
#[derive(Debug, Clone, PartialEq)]
pub struct Table2 {
    /// The cells.
    pub cells: Vec<Cell>,
    /// The methods, in column order.
    pub methods: Vec<Method>,
    /// The worlds, in row order.
    pub worlds: Vec<String>,
    /// The task (the paper's numbers belong to obstacle avoidance only).
    pub task: Task,
}

/// Why a job's results are missing, in words that do not depend on where the folder is
/// (the full reason is in `state/` and the job's log).
fn why_missing(plan: &Plan, job: &Job) -> String {
    match plan.state(job) {
        JobState::Failed(_) => format!("{} failed (see {})", job.id, plan.log_name(job)),
        JobState::Partial => format!("{} interrupted (not finished)", job.id),
        JobState::Pending => match plan.blocked_by(job) {
            Some(n) => format!("{} not run ({} not finished)", job.id, n.id),
            None => format!("{} not run yet", job.id),
        },
        JobState::Done => format!("{} finished without this world in its summary.csv", job.id),
    }
}

/// An evaluation's `summary.csv` rows, or why they cannot be read.
type Summary = Result<Vec<WorldSummary>, String>;

/// A finished evaluation job's `summary.csv` (`None`: not finished).
fn read_summary(plan: &Plan, job: &Job) -> Option<Summary> {
    if plan.state(job) != JobState::Done {
        return None;
    }
    let path = plan.job_dir(job).join("summary.csv");
    let name = format!("{}/summary.csv", job.id);
    Some(
        std::fs::read_to_string(&path)
            .map_err(|e| format!("{name}: {e}"))
            .and_then(|text| parse_summary_csv(&text, &name)),
    )
}

impl Table2 {
    /// Gathers every finished evaluation of the plan; cells whose evaluations are missing
    /// say which and why.
    pub fn gather(plan: &Plan) -> Result<Table2, SweepError> {
        let s = &plan.sweep;
        let methods = Method::all(plan);
        let summaries: Vec<(&Job, Option<Summary>)> =
            plan.eval_jobs().map(|j| (j, read_summary(plan, j))).collect();
        let find = |id: &str| summaries.iter().find(|(j, _)| j.id == id);
        let mut cells = Vec::new();
        for (w, world) in s.eval.worlds.iter().enumerate() {
            for method in &methods {
                let ids = method.eval_ids(plan);
                let mut cell = Cell {
                    world: world.clone(),
                    method: method.clone(),
                    moving_per_run: Vec::new(),
                    moving_per_seed: Vec::new(),
                    per_run: Vec::new(),
                    per_seed: Vec::new(),
                    path_m: Vec::new(),
                    missing: Vec::new(),
                };
                for id in ids {
                    let Some((job, rows)) = find(&id) else { continue };
                    // An evaluation writes one row per world in the sweep's order (a world
                    // file's row is named by the world, not by its path).
                    let row = match rows {
                        Some(Ok(r)) if r.len() == s.eval.worlds.len() => Ok(&r[w]),
                        Some(Ok(r)) => Err(format!(
                            "{} has {} worlds in its summary.csv, the sweep {}",
                            job.id,
                            r.len(),
                            s.eval.worlds.len()
                        )),
                        Some(Err(e)) => Err(format!("{} unreadable: {e}", job.id)),
                        None => Err(why_missing(plan, job)),
                    };
                    match row {
                        Ok(r) => {
                            cell.moving_per_run.extend(&r.moving_success_per_run);
                            cell.moving_per_seed.push(r.moving_success_mean);
                            cell.per_run.extend(&r.success_per_run);
                            cell.per_seed.push(r.success_mean);
                            cell.path_m.push(r.path_m_mean);
                        }
                        Err(why) => cell.missing.push(why),
                    }
                }
                cells.push(cell);
            }
        }
        Ok(Table2 { cells, methods, worlds: s.eval.worlds.clone(), task: s.task })
    }

    fn cell(&self, world: &str, method: &Method) -> Option<&Cell> {
        self.cells.iter().find(|c| c.world == world && &c.method == method)
    }

    /// Mean rate of `metric` (percent) of a variant in a world, if complete.
    pub fn mean(&self, world: &str, v: Variant, metric: Metric) -> Option<f64> {
        self.cell(world, &Method::Variant(v)).and_then(|c| c.metric_stats(metric)).map(|s| s.0)
    }

    /// Every missing evaluation, once each.
    pub fn missing(&self) -> Vec<String> {
        let mut all: Vec<String> = self.cells.iter().flat_map(|c| c.missing.clone()).collect();
        all.dedup();
        let mut seen = Vec::new();
        all.retain(|m| {
            let new = !seen.contains(m);
            seen.push(m.clone());
            new
        });
        all
    }

    /// Whether every cell is filled.
    pub fn complete(&self) -> bool {
        self.cells.iter().all(|c| c.stats().is_some())
    }

    /// `table2.csv`: one row per (world, method); results only, the moving success first
    /// and the rule's thresholds in every row.
    pub fn csv(&self, plan: &Plan) -> String {
        let e = &plan.sweep.eval;
        let mut s = String::from(
            "world,method,seeds,runs,moving_success_mean_pct,moving_success_std_pct,\
moving_success_per_seed_pct,success_mean_pct,success_std_pct,success_per_seed_pct,paper_mean_pct,\
paper_std_pct,path_m_mean,min_path_m,min_reach_m,missing\n",
        );
        for c in &self.cells {
            let stats = |metric| {
                c.metric_stats(metric).map_or((String::new(), String::new()), |(m, d)| {
                    (format!("{m:.2}"), format!("{d:.2}"))
                })
            };
            let seeds = |metric| {
                let v: Vec<String> =
                    c.per_seed_of(metric).iter().map(|x| format!("{:.2}", 100.0 * x)).collect();
                v.join(";")
            };
            let ((mm, ms), (pm_ours, ps_ours)) = (stats(Metric::Moving), stats(Metric::Paper));
            let paper = match &c.method {
                Method::Variant(v) if not_comparable(&plan.sweep).is_none() => {
                    paper_cell(&c.world, *v)
                }
                _ => None,
            };
            let (pm, ps) = paper.map_or((String::new(), String::new()), |(m, d)| {
                (format!("{m:.1}"), format!("{d:.1}"))
            });
            let _ = writeln!(
                s,
                "{},{},{},{},{mm},{ms},{},{pm_ours},{ps_ours},{},{pm},{ps},{},{},{},{}",
                csv_field(&c.world),
                csv_field(&c.method.name()),
                c.per_seed.len(),
                c.per_run.len(),
                seeds(Metric::Moving),
                seeds(Metric::Paper),
                c.path_mean().map_or(String::new(), |p| format!("{p:.3}")),
                e.min_path_m,
                e.min_reach_m,
                csv_field(&c.missing.join("; "))
            );
        }
        s
    }

    /// One Markdown table: a row per world, a column per method, each cell `cell(world,
    /// method)`.
    fn grid(&self, s: &mut String, cell: impl Fn(&str, &Method) -> String) {
        let _ = write!(s, "| world |");
        for m in &self.methods {
            let _ = write!(s, " {} |", m.name());
        }
        let _ = write!(s, "\n| --- |");
        for _ in &self.methods {
            let _ = write!(s, " --- |");
        }
        s.push('\n');
        for w in &self.worlds {
            let _ = write!(s, "| {} |", w.replace('|', "\\|"));
            for m in &self.methods {
                let _ = write!(s, " {} |", cell(w, m));
            }
            s.push('\n');
        }
    }

    /// `table2.md`: the paper's layout (a row per world, a column per method): the moving
    /// success first, then the paper's success with the paper's numbers beneath ours (the
    /// only table they are comparable with), then the mean collision-free path.
    pub fn markdown(&self, plan: &Plan) -> String {
        let sw = &plan.sweep;
        let mut s = String::new();
        let nav = self.task == Task::Nav;
        let title = if nav { "Navigation" } else { "Table 2" };
        let what = if nav { "success rate (%)" } else { "moving success and success (%)" };
        let _ = writeln!(s, "# {title}: {what} in the unseen worlds — sweep `{}`\n", sw.name);
        if !self.complete() {
            let missing = self.missing();
            let empty = self.cells.iter().filter(|c| c.stats().is_none()).count();
            let _ = writeln!(
                s,
                "**Incomplete: {empty} of {} cells have no result** (shown as —). Missing:\n",
                self.cells.len()
            );
            for m in &missing {
                let _ = writeln!(s, "- {m}");
            }
            s.push('\n');
        }
        let protocol = format!(
            "Ours: mean ± population std over {} seed(s) × {} run(s) of {} episodes, {} training \
             steps per run in `{}`.",
            sw.seeds.len(),
            sw.eval.runs,
            sw.eval.episodes,
            sw.steps,
            sw.world
        );
        // Each row's best mean in bold (every method that ties it), the rest plain.
        let ours = |metric: Metric| {
            move |w: &str, m: &Method| {
                // Compared as shown, to one decimal (tenths of a percent).
                let tenths = |a: f64| (a * 10.0).round() as i64;
                let best = self
                    .methods
                    .iter()
                    .filter_map(|m| self.cell(w, m).and_then(|c| c.metric_stats(metric)))
                    .filter(|(a, _)| a.is_finite())
                    .map(|(a, _)| tenths(a))
                    .max();
                self.cell(w, m).and_then(|c| c.metric_stats(metric)).map_or(
                    "—".to_string(),
                    |(a, b)| {
                        let text = format!("{a:.1} ± {b:.1}");
                        if a.is_finite() && best == Some(tenths(a)) {
                            format!("**{text}**")
                        } else {
                            text
                        }
                    },
                )
            }
        };
        if nav {
            let _ = writeln!(
                s,
                "{protocol} Success = the goal reached within {} steps. The paper gives no \
                 navigation numbers (its Fig. 9 shows trajectories only).\n",
                sw.eval.max_steps
            );
            self.grid(&mut s, ours(Metric::Paper));
        } else {
            let _ = writeln!(
                s,
                "{protocol} **Moving success** = no collision in {} steps *and* at least {} m \
                 driven *and* at least {} m from the start at some step. **Success** = the \
                 paper's measure, no collision in {} steps: a policy that turns in place meets \
                 it, so it is shown second. The paper's numbers (Song et \
                 al. 2021, Table 2: 400,000 steps, 5 runs of 50 episodes) are comparable with \
                 it alone.\n",
                sw.eval.max_steps, sw.eval.min_path_m, sw.eval.min_reach_m, sw.eval.max_steps
            );
            let _ = writeln!(s, "## Moving success (%)\n");
            self.grid(&mut s, ours(Metric::Moving));
            match not_comparable(sw) {
                None => {
                    let _ =
                        writeln!(s, "\n## Success (%), the paper's measure, with the paper's\n");
                    let paper_ours = ours(Metric::Paper);
                    self.grid(&mut s, |w, m| {
                        let paper = match m {
                            Method::Variant(v) => paper_cell(w, *v)
                                .map_or(String::new(), |(a, b)| {
                                    format!("<br>paper {a:.1} ± {b:.1}")
                                }),
                            Method::Baseline(_) => String::new(),
                        };
                        format!("{}{paper}", paper_ours(w, m))
                    });
                }
                Some(why) => {
                    let _ = writeln!(s, "\n## Success (%), the paper's measure\n");
                    self.grid(&mut s, ours(Metric::Paper));
                    let _ = writeln!(
                        s,
                        "\nThe paper's numbers are not printed beside these: {why}. They are in \
                         `mdrlat reproduce --preset paper`'s table.\n"
                    );
                }
            }
        }
        let _ = writeln!(
            s,
            "{}",
            if nav {
                "\nMean distance driven per episode (m), every episode (the navigation table has \
                 paths over the episodes that reached their goal).\n"
            } else {
                "\n## Mean collision-free path (m)\n\nDistance driven per episode up to its end or \
                 its collision.\n"
            }
        );
        self.grid(&mut s, |w, m| {
            self.cell(w, m).and_then(Cell::path_mean).map_or("—".into(), |p| format!("{p:.1}"))
        });
        s
    }
}

/// The navigation results of a sweep: per method and world, over every seed's evaluation,
/// success, collisions, timeouts, time, path and path ratio (from each evaluation's
/// `navigation.csv`), and the evaluations missing or unreadable (their methods are left
/// out).
pub fn navigation_rows(plan: &Plan) -> (Vec<NavSummary>, Vec<String>) {
    let sw = &plan.sweep;
    let mut rows = Vec::new();
    let mut missing = Vec::new();
    for method in Method::all(plan) {
        let mut records: Vec<(String, NavRecord)> = Vec::new();
        let mut complete = true;
        for id in method.eval_ids(plan) {
            let Ok(job) = plan.job(&id) else { continue };
            if plan.state(job) != JobState::Done {
                missing.push(why_missing(plan, job));
                complete = false;
                continue;
            }
            let name = format!("{id}/navigation.csv");
            let parsed = std::fs::read_to_string(plan.job_dir(job).join("navigation.csv"))
                .map_err(|e| format!("{name}: {e}"))
                .and_then(|text| parse_navigation_csv(&text, &name));
            match parsed {
                Ok(r) => records.extend(r),
                Err(e) => {
                    missing.push(format!("{id} unreadable: {e}"));
                    complete = false;
                }
            }
        }
        if !complete {
            continue;
        }
        for world in &sw.eval.worlds {
            // A world file's rows are named by the world's name, not by its path.
            let stem = std::path::Path::new(world)
                .file_stem()
                .map_or(world.clone(), |s| s.to_string_lossy().into_owned());
            let navs: Vec<NavRecord> = records
                .iter()
                .filter(|(w, _)| w == world || *w == stem)
                .map(|(_, r)| r.clone())
                .collect();
            if navs.is_empty() {
                missing
                    .push(format!("{}: no navigation.csv rows for world '{world}'", method.name()));
            } else {
                rows.push(NavSummary::new(&method.name(), world, &navs));
            }
        }
    }
    (rows, missing)
}

/// `navigation.md` of a sweep ([`navigation_rows`] as a table, the missing said); `None`
/// for an obstacle-avoidance sweep.
pub fn navigation(plan: &Plan) -> Option<String> {
    let sw = &plan.sweep;
    if sw.task != Task::Nav {
        return None;
    }
    let (rows, missing) = navigation_rows(plan);
    let sim = mdrlat_sim::SimConfig::default();
    let mut md = navigation_markdown(&rows, sw.eval.max_steps, &sim).replacen(
        "# Navigation",
        &format!("# Navigation — sweep `{}`", sw.name),
        1,
    );
    if !missing.is_empty() {
        md.push_str("\nMissing (not in the table):\n\n");
        for m in missing {
            let _ = writeln!(md, "- {m}");
        }
    }
    Some(md)
}

/// One of the paper's claims about Table 2 and whether our numbers bear it out.
#[derive(Debug, Clone, PartialEq)]
pub struct Claim {
    /// The claim, as the paper makes it.
    pub claim: &'static str,
    /// `Some(true)`: holds in every world; `Some(false)`: fails somewhere; `None`: the
    /// sweep lacks the variants or results to say.
    pub holds: Option<bool>,
    /// The numbers, world by world.
    pub detail: String,
}

/// The paper's ordering (section 3.2), checked world by world on `metric`.
pub fn claims(t: &Table2, metric: Metric) -> Vec<Claim> {
    use Variant::*;
    let multi = [Multi, MultiAt, MultiBf, Mdrlat];
    let single = [LaserOnly, DepthOnly];
    let mut out = Vec::new();
    let check = |claim: &'static str, f: &dyn Fn(&str) -> Option<(bool, String)>| {
        let mut holds = Some(true);
        let mut detail = Vec::new();
        for w in &t.worlds {
            match f(w) {
                Some((ok, d)) => {
                    if !ok {
                        holds = holds.map(|_| false);
                    }
                    detail.push(format!("{w}: {d} ({})", if ok { "yes" } else { "no" }));
                }
                None => holds = None,
            }
        }
        Claim { claim, holds, detail: detail.join("; ") }
    };
    let m = |w: &str, v: Variant| t.mean(w, v, metric);
    out.push(check("every multi-sensor method beats both single-sensor ones", &|w| {
        let lo = multi.iter().map(|&v| m(w, v).map(|x| (v, x))).collect::<Option<Vec<_>>>()?;
        let hi = single.iter().map(|&v| m(w, v).map(|x| (v, x))).collect::<Option<Vec<_>>>()?;
        let worst =
            lo.iter().copied().fold((Mdrlat, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
        let best = hi
            .iter()
            .copied()
            .fold((LaserOnly, f64::NEG_INFINITY), |a, b| if b.1 > a.1 { b } else { a });
        Some((
            worst.1 > best.1,
            format!(
                "worst multi {} {:.1} vs best single {} {:.1}",
                worst.0, worst.1, best.0, best.1
            ),
        ))
    }));
    let pair = |a: Variant, b: Variant| {
        move |w: &str| -> Option<(bool, String)> {
            let (x, y) = (m(w, a)?, m(w, b)?);
            Some((x > y, format!("{a} {x:.1} vs {b} {y:.1}")))
        }
    };
    out.push(check("bilinear fusion helps: multi-bf beats multi", &pair(MultiBf, Multi)));
    out.push(check("the auxiliary task helps: multi-at beats multi", &pair(MultiAt, Multi)));
    out.push(check("MDRLAT is best of the six", &|w| {
        let x = m(w, Mdrlat)?;
        let others = Variant::ALL
            .iter()
            .filter(|&&v| v != Mdrlat)
            .map(|&v| m(w, v).map(|y| (v, y)))
            .collect::<Option<Vec<_>>>()?;
        let best = others
            .iter()
            .copied()
            .fold((Multi, f64::NEG_INFINITY), |a, b| if b.1 > a.1 { b } else { a });
        Some((x > best.1, format!("mdrlat {x:.1} vs best other {} {:.1}", best.0, best.1)))
    }));
    out
}

/// The paper's claims about navigation (section 3.1): the goal-conditioned MDRLAT reaches
/// every goal in the unseen world, on paths more tortuous than Move_Base's (`planner`):
/// a larger ratio of path driven to the shortest path, over the goals reached.
pub fn nav_claims(t: &Table2, rows: &[NavSummary]) -> Vec<Claim> {
    let mut out = Vec::new();
    let mdrlat = Method::Variant(Variant::Mdrlat);
    let planner = Method::Baseline("planner".into());
    let mut holds = Some(true);
    let mut detail = Vec::new();
    for w in &t.worlds {
        match t.cell(w, &mdrlat).and_then(Cell::stats) {
            Some((m, _)) => {
                let ok = m >= 99.95;
                holds = holds.map(|h| h && ok);
                detail.push(format!("{w}: mdrlat {m:.1} % ({})", if ok { "yes" } else { "no" }));
            }
            None => holds = None,
        }
    }
    out.push(Claim {
        claim: "MDRLAT reaches every goal in the unseen world",
        holds,
        detail: detail.join("; "),
    });
    let mut holds = Some(true);
    let mut detail = Vec::new();
    for w in &t.worlds {
        let ratio = |m: &Method| {
            rows.iter()
                .find(|r| r.world == *w && r.eval == m.name())
                .and_then(|r| r.path_ratio_mean)
        };
        match (ratio(&mdrlat), ratio(&planner)) {
            (Some(a), Some(b)) => {
                holds = holds.map(|h| h && a > b);
                detail.push(format!(
                    "{w}: path / shortest mdrlat {a:.2} vs planner {b:.2} ({})",
                    if a > b { "yes" } else { "no" }
                ));
            }
            _ => holds = None,
        }
    }
    out.push(Claim {
        claim: "MDRLAT's trajectories are more tortuous than the planner's",
        holds,
        detail: detail.join("; "),
    });
    out
}

/// `report.md`: what was run, Table 2, the paper's claims checked, and links to the figures.
pub fn report(plan: &Plan, t: &Table2) -> String {
    let sw = &plan.sweep;
    let mut s = String::new();
    let _ = writeln!(s, "# Reproduction report — sweep `{}`\n", sw.name);
    let _ = writeln!(s, "{}\n", sw.description);
    let _ = writeln!(
        s,
        "- Training{}: {} variant(s) × {} seed(s) × {} steps in `{}` on `{}`{}.",
        if sw.task == Task::Nav { " (navigation: goal-conditioned networks)" } else { "" },
        sw.variants.len(),
        sw.seeds.len(),
        sw.steps,
        sw.world,
        sw.device,
        if sw.set.is_empty() { String::new() } else { format!(", settings {}", sw.set.join(", ")) }
    );
    let _ = writeln!(
        s,
        "- Evaluation: {} run(s) × {} episodes of {} steps in {}, seed {}; baselines: {}.",
        sw.eval.runs,
        sw.eval.episodes,
        sw.eval.max_steps,
        sw.eval.worlds.join(", "),
        sw.eval.seed,
        if sw.eval.baselines.is_empty() { "none".into() } else { sw.eval.baselines.join(", ") }
    );
    if sw.task == Task::Avoid && sw.steps < 400_000 {
        let _ = writeln!(
            s,
            "- **{} steps is {:.1} % of the paper's 400,000**: compare orderings with care, not absolute rates.",
            sw.steps,
            100.0 * sw.steps as f64 / 400_000.0
        );
    }
    let nav = sw.task == Task::Nav;
    if nav {
        let _ = writeln!(
            s,
            "\n[Success table](table2.md) · [CSV](table2.csv) · [Navigation](navigation.md) · [Fig. 4](fig4.png)\n"
        );
        s.push_str(&t.markdown(plan).replacen("# Navigation", "## Navigation", 1));
        let (rows, _) = navigation_rows(plan);
        if let Some(md) = navigation(plan) {
            let body = md.split_once("\n\n").map_or(md.as_str(), |(_, rest)| rest);
            let _ = writeln!(s, "\n## Time, path and path ratio\n\n{body}");
        }
        let _ = writeln!(s, "\n## Does the paper's navigation result hold here?\n");
        for c in nav_claims(t, &rows) {
            let verdict = match c.holds {
                Some(true) => "**holds**",
                Some(false) => "**does not hold**",
                None => "cannot be checked (methods or results missing)",
            };
            let _ = writeln!(s, "- {}: {verdict}. {}", c.claim, c.detail);
        }
        let _ =
            writeln!(s, "\n## Figures\n\n![Fig. 4: evaluation reward during training](fig4.png)\n");
        for job in plan.eval_jobs() {
            let drawn = match job.kind {
                JobKind::EvalModel { figures, .. } | JobKind::EvalBaseline { figures, .. } => {
                    figures > 0
                }
                _ => false,
            };
            for w in sw.eval.worlds.iter().filter(|_| drawn) {
                let stem = std::path::Path::new(w)
                    .file_stem()
                    .map_or(w.clone(), |s| s.to_string_lossy().into_owned());
                let png = format!("figures/{stem}-fig9.png");
                if plan.job_dir(job).join(&png).is_file() {
                    let _ = writeln!(
                        s,
                        "Fig. 9, `{}` in {w}:\n\n![{}]({}/{png})\n",
                        job.id, job.id, job.id
                    );
                }
            }
        }
        return s;
    }
    let _ = writeln!(s, "\n[Table 2](table2.md) · [CSV](table2.csv) · [Fig. 4](fig4.png)\n");
    // The table's own sections one level down, under the report's.
    s.push_str(&t.markdown(plan).replace("\n## ", "\n### ").replacen("# Table 2", "## Table 2", 1));
    for (metric, heading) in [
        (Metric::Moving, "Does the paper's ordering hold here, by moving success?"),
        (Metric::Paper, "Does it hold by the paper's success?"),
    ] {
        let _ = writeln!(s, "\n## {heading}\n");
        let claims_all = claims(t, metric);
        for c in &claims_all {
            let worlds = c.detail.matches("(yes)").count();
            let verdict = match c.holds {
                Some(true) => "**holds** in every world".to_string(),
                Some(false) => {
                    format!("**does not hold** (holds in {worlds} of {} worlds)", t.worlds.len())
                }
                None => "cannot be checked (variants or results missing)".to_string(),
            };
            let _ = writeln!(s, "- {}: {verdict}. {}", c.claim, c.detail);
        }
        let verdict = if claims_all.iter().all(|c| c.holds == Some(true)) {
            "The paper's ordering holds in our simulator."
        } else if claims_all.iter().any(|c| c.holds == Some(false)) {
            "The paper's ordering does **not** fully hold in our simulator with these settings (see above)."
        } else {
            "Not enough results to check the paper's ordering."
        };
        let _ = writeln!(s, "\n{verdict}");
    }
    let _ = writeln!(
        s,
        "\nDifferences smaller than the std over runs are within noise. The moving success asks \
         for no collision in {} steps and at least {} m driven and {} m from the start; the \
         paper's success asks for no collision only, which a policy turning in place meets.\n",
        sw.eval.max_steps, sw.eval.min_path_m, sw.eval.min_reach_m
    );
    let _ = writeln!(
        s,
        "## Figures\n\n![Fig. 4: evaluation reward during training, and the learning curves (moving \
         success, success, path) on held-out starts of the training world and in an unseen world](fig4.png)\n"
    );
    if let Some(fig) = plan
        .eval_jobs()
        .find(|j| matches!(j.kind, JobKind::EvalModel { figures, .. } if figures > 0))
    {
        let dir = plan.job_dir(fig).join("figures");
        let mut pngs: Vec<String> = std::fs::read_dir(&dir)
            .map(|d| {
                d.filter_map(|e| e.ok())
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|n| n.ends_with(".png") && !n.ends_with("-trajectory.png"))
                    .collect()
            })
            .unwrap_or_default();
        pngs.sort();
        if !pngs.is_empty() {
            let _ = writeln!(
                s,
                "Figs. 6/7 of `{}` (six top views and the angular-velocity trace):\n",
                fig.id
            );
        }
        for p in pngs {
            let _ = writeln!(s, "![{p}]({}/figures/{p})\n", fig.id);
        }
    }
    s
}

/// Writes `table2.csv`, `table2.md`, `navigation.md` (navigation sweeps) and `report.md`
/// into the sweep's folder; returns the table (the caller fails the job when it is
/// incomplete, after writing it).
pub fn write(plan: &Plan) -> Result<Table2, SweepError> {
    let t = Table2::gather(plan)?;
    write_atomic(&plan.dir.join("table2.csv"), t.csv(plan).as_bytes())?;
    write_atomic(&plan.dir.join("table2.md"), t.markdown(plan).as_bytes())?;
    if let Some(md) = navigation(plan) {
        write_atomic(&plan.dir.join("navigation.md"), md.as_bytes())?;
    }
    write_atomic(&plan.dir.join("report.md"), report(plan, &t).as_bytes())?;
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Sweep;

    fn table(rates: &[(Variant, f64)]) -> Table2 {
        let worlds = vec!["office".to_string()];
        let methods: Vec<Method> = rates.iter().map(|r| Method::Variant(r.0)).collect();
        let cells = rates
            .iter()
            .map(|&(v, x)| Cell {
                world: "office".into(),
                method: Method::Variant(v),
                moving_per_run: vec![x / 2.0; 2],
                moving_per_seed: vec![x / 2.0],
                per_run: vec![x - 0.01, x + 0.01],
                per_seed: vec![x],
                path_m: vec![10.0],
                missing: Vec::new(),
            })
            .collect();
        Table2 { cells, methods, worlds, task: Task::Avoid }
    }

    #[test]
    fn the_papers_ordering_is_checked_with_its_numbers() {
        use Variant::*;
        let paper: Vec<(Variant, f64)> =
            PAPER_TABLE2[0].1.iter().map(|c| (c.0, c.1 / 100.0)).collect();
        let c = claims(&table(&paper), Metric::Paper);
        assert!(c.iter().all(|c| c.holds == Some(true)), "{c:?}");
        let c = claims(&table(&paper), Metric::Moving);
        assert!(c.iter().all(|c| c.holds == Some(true)), "{c:?}");
        assert!(c[1].detail.contains("multi-bf 44.8 vs multi 38.4"), "{}", c[1].detail);
        let swapped: Vec<(Variant, f64)> =
            paper.iter().map(|&(v, x)| (v, if v == Multi { 0.99 } else { x })).collect();
        let c = claims(&table(&swapped), Metric::Paper);
        assert_eq!(c[0].holds, Some(true));
        assert_eq!(c[1].holds, Some(false), "{}", c[1].detail);
        assert!(c[1].detail.contains("multi-bf 89.6 vs multi 99.0"), "{}", c[1].detail);
        assert_eq!(c[3].holds, Some(false));
        let only_two = claims(&table(&[(LaserOnly, 0.5), (Mdrlat, 0.6)]), Metric::Paper);
        assert!(only_two.iter().all(|c| c.holds.is_none()));
    }

    #[test]
    fn only_each_rows_best_is_bold() {
        use Variant::*;
        let dir = std::env::temp_dir().join(format!("mdrlat-sweep-bold-{}", std::process::id()));
        let plan = Plan::new(Sweep::preset("smoke").expect("smoke"), &dir);
        let md = table(&[(LaserOnly, 0.5), (Multi, 0.8), (Mdrlat, 0.8)]).markdown(&plan);
        let paper = md.find("## Success (%)").expect("the paper's table");
        let row = md[paper..].lines().find(|l| l.starts_with("| office |")).expect("a row");
        assert_eq!(row, "| office | 50.0 ± 1.0 | **80.0 ± 1.0** | **80.0 ± 1.0** |", "{md}");
    }

    #[test]
    fn missing_cells_are_said_and_left_empty() {
        let dir = std::env::temp_dir().join(format!("mdrlat-sweep-tables-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let plan = Plan::new(Sweep::preset("smoke").expect("smoke"), &dir);
        plan.open().expect("open");
        let job = plan.job("eval/multi-s0").expect("job").clone();
        plan.mark_failed(&job, "exit status: 1").expect("mark");
        let t = Table2::gather(&plan).expect("gather");
        assert!(!t.complete());
        let csv = t.csv(&plan);
        assert_eq!(csv.lines().count(), 1 + 3 * 7, "{csv}");
        assert!(
            csv.contains(
                "office,multi,0,0,,,,,,,,,,5,2,eval/multi-s0 failed (see logs/eval-multi-s0.log)"
            ),
            "{csv}"
        );
        assert!(csv.contains("eval/mdrlat-s0 not run (train/mdrlat-s0 not finished)"), "{csv}");
        let md = t.markdown(&plan);
        assert!(md.contains("**Incomplete: 21 of 21 cells have no result**"), "{md}");
        // 300 steps are not the paper's 400,000: no paper number beside them.
        assert!(!md.contains("paper 67.6"), "{md}");
        assert!(md.contains("not printed beside these: this sweep trains 300 steps"), "{md}");
        let paper = Plan::new(Sweep::preset("paper").expect("paper"), &dir);
        assert!(paper.sweep.steps == 400_000 && not_comparable(&paper.sweep).is_none());
        let t = Table2::gather(&paper).expect("gather");
        let md = t.markdown(&paper);
        assert!(md.contains("| office | —<br>paper 67.6 ± 4.8 |"), "{md}");
        assert!(
            t.csv(&paper).contains("office,laser-only,0,0,,,,,,,67.6,4.8,"),
            "{}",
            t.csv(&paper)
        );
        let moving = md.find("## Moving success (%)").expect("moving table");
        let paper = md.find("## Success (%), the paper's measure").expect("paper table");
        assert!(moving < paper, "the moving success leads: {md}");
        assert!(md.contains("at least 5 m driven *and* at least 2 m from the start"), "{md}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
