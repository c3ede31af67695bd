//! Table 2 from a sweep's evaluations, beside the paper's numbers, and the report that says
//! whether the paper's ordering holds. Results only (no times, no host names), fixed
//! precision and order: a sweep killed and resumed writes the same `table2.csv` bytes.

use crate::SweepError;
use crate::plan::{Job, JobKind, JobState, Plan, run_name, write_atomic};
use mdrlat_eval::nav::{NavRecord, NavSummary, navigation_markdown, parse_navigation_csv};
use mdrlat_eval::{WorldSummary, parse_summary_csv, report::csv_field};
use mdrlat_nn::Variant;
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

/// One cell: a method in a world.
#[derive(Debug, Clone, PartialEq)]
pub struct Cell {
    /// The world.
    pub world: String,
    /// The method.
    pub method: Method,
    /// Success rate of every run of every seed, in seed order (fractions).
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

    /// Mean and population std over all runs of all seeds, percent.
    pub fn stats(&self) -> Option<(f64, f64)> {
        if self.per_run.is_empty() || !self.missing.is_empty() {
            return None;
        }
        let n = self.per_run.len() as f64;
        let mean = self.per_run.iter().sum::<f64>() / n;
        let var = self.per_run.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
        Some((100.0 * mean, 100.0 * var.sqrt()))
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

    /// Mean success (percent) of a variant in a world, if complete.
    pub fn mean(&self, world: &str, v: Variant) -> Option<f64> {
        self.cell(world, &Method::Variant(v)).and_then(Cell::stats).map(|s| s.0)
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

    /// `table2.csv`: one row per (world, method); results only.
    pub fn csv(&self) -> String {
        let mut s = String::from(
            "world,method,seeds,runs,success_mean_pct,success_std_pct,success_per_seed_pct,paper_mean_pct,paper_std_pct,path_m_mean,missing\n",
        );
        for c in &self.cells {
            let (mean, std) = c.stats().map_or((String::new(), String::new()), |(m, d)| {
                (format!("{m:.2}"), format!("{d:.2}"))
            });
            let paper = match &c.method {
                Method::Variant(v) if self.task == Task::Avoid => paper_cell(&c.world, *v),
                _ => None,
            };
            let (pm, ps) = paper.map_or((String::new(), String::new()), |(m, d)| {
                (format!("{m:.1}"), format!("{d:.1}"))
            });
            let seeds: Vec<String> =
                c.per_seed.iter().map(|x| format!("{:.2}", 100.0 * x)).collect();
            let _ = writeln!(
                s,
                "{},{},{},{},{mean},{std},{},{pm},{ps},{},{}",
                csv_field(&c.world),
                csv_field(&c.method.name()),
                c.per_seed.len(),
                c.per_run.len(),
                seeds.join(";"),
                c.path_mean().map_or(String::new(), |p| format!("{p:.3}")),
                csv_field(&c.missing.join("; "))
            );
        }
        s
    }

    /// `table2.md`: the paper's layout (a row per world, a column per method), our
    /// mean ± std with the paper's beneath.
    pub fn markdown(&self, plan: &Plan) -> String {
        let sw = &plan.sweep;
        let mut s = String::new();
        let nav = self.task == Task::Nav;
        let title = if nav { "Navigation" } else { "Table 2" };
        let _ =
            writeln!(s, "# {title}: success rate (%) in the unseen worlds — sweep `{}`\n", sw.name);
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
        let success = if nav { "the goal reached within" } else { "no collision in" };
        let paper = if nav {
            "The paper gives no navigation numbers (its Fig. 9 shows trajectories only)."
        } else {
            "Paper (Song et al. 2021, Table 2): 400,000 steps, 5 runs of 50 episodes."
        };
        let _ = writeln!(
            s,
            "Ours: mean ± population std over {} seed(s) × {} run(s) of {} episodes (success = {success} {} steps), \
             {} training steps per run in `{}`. {paper}\n",
            sw.seeds.len(),
            sw.eval.runs,
            sw.eval.episodes,
            sw.eval.max_steps,
            sw.steps,
            sw.world
        );
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
                let ours = self
                    .cell(w, m)
                    .and_then(Cell::stats)
                    .map_or("—".to_string(), |(a, b)| format!("**{a:.1} ± {b:.1}**"));
                let paper = match m {
                    Method::Variant(v) if !nav => paper_cell(w, *v)
                        .map_or(String::new(), |(a, b)| format!("<br>paper {a:.1} ± {b:.1}")),
                    _ => String::new(),
                };
                let _ = write!(s, " {ours}{paper} |");
            }
            s.push('\n');
        }
        let _ = writeln!(
            s,
            "{}",
            if nav {
                "\nMean distance driven per episode (m), every episode (the navigation table has \
                 paths over the episodes that reached their goal).\n"
            } else {
                "\nMean distance driven per episode (m): success counts episodes without a collision, so a \
                 policy that turns in place succeeds; this row tells it from one that drives.\n"
            }
        );
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
                let p = self.cell(w, m).and_then(Cell::path_mean);
                let _ = write!(s, " {} |", p.map_or("—".into(), |p| format!("{p:.1}")));
            }
            s.push('\n');
        }
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

/// The paper's ordering (section 3.2), checked world by world.
pub fn claims(t: &Table2) -> Vec<Claim> {
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
    let m = |w: &str, v: Variant| t.mean(w, v);
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
    s.push_str(&t.markdown(plan).replacen("# Table 2", "## Table 2", 1));
    let _ = writeln!(s, "\n## Does the paper's ordering hold here?\n");
    for c in claims(t) {
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
    let claims_all = claims(t);
    let verdict = if claims_all.iter().all(|c| c.holds == Some(true)) {
        "The paper's ordering holds in our simulator."
    } else if claims_all.iter().any(|c| c.holds == Some(false)) {
        "The paper's ordering does **not** fully hold in our simulator with these settings (see above)."
    } else {
        "Not enough results to check the paper's ordering."
    };
    let _ = writeln!(
        s,
        "\n{verdict} Differences smaller than the std over runs are within noise. Success is the \
         paper's measure (no collision within {} steps); a policy that turns in place meets it, so \
         read it beside the distance driven in the table above.\n",
        sw.eval.max_steps
    );
    let _ = writeln!(s, "## Figures\n\n![Fig. 4: evaluation reward during training](fig4.png)\n");
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
    write_atomic(&plan.dir.join("table2.csv"), t.csv().as_bytes())?;
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
        let c = claims(&table(&paper));
        assert!(c.iter().all(|c| c.holds == Some(true)), "{c:?}");
        let swapped: Vec<(Variant, f64)> =
            paper.iter().map(|&(v, x)| (v, if v == Multi { 0.99 } else { x })).collect();
        let c = claims(&table(&swapped));
        assert_eq!(c[0].holds, Some(true));
        assert_eq!(c[1].holds, Some(false), "{}", c[1].detail);
        assert!(c[1].detail.contains("multi-bf 89.6 vs multi 99.0"), "{}", c[1].detail);
        assert_eq!(c[3].holds, Some(false));
        let only_two = claims(&table(&[(LaserOnly, 0.5), (Mdrlat, 0.6)]));
        assert!(only_two.iter().all(|c| c.holds.is_none()));
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
        let csv = t.csv();
        assert_eq!(csv.lines().count(), 1 + 3 * 7, "{csv}");
        assert!(
            csv.contains(
                "office,multi,0,0,,,,76.8,4.1,,eval/multi-s0 failed (see logs/eval-multi-s0.log)"
            ),
            "{csv}"
        );
        assert!(csv.contains("eval/mdrlat-s0 not run (train/mdrlat-s0 not finished)"), "{csv}");
        let md = t.markdown(&plan);
        assert!(md.contains("**Incomplete: 21 of 21 cells have no result**"), "{md}");
        assert!(md.contains("| office | —<br>paper 67.6 ± 4.8 |"), "{md}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
