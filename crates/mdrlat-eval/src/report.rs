//! What an evaluation writes: `episodes.csv` (one row per episode), `summary.csv` and
//! `summary.md` (one row per world: moving success and the paper's success, mean ± std over
//! runs, as paper Table 2), and one JSON object per world. Every output records the moving
//! rule's two thresholds beside the rates they decide. Results only, in fixed precision, in a fixed order — no wall
//! times or host names — so the same seed gives the same bytes.

use crate::protocol::{EpisodeRecord, EvalSettings, WorldEval, collision_kind};
use mdrlat_sim::MovingRule;
use std::fmt::Write as _;

/// The header of `episodes.csv`.
pub const EPISODES_HEADER: &str = "world,run,episode,seed,x0,y0,yaw0_deg,steps,moving_success,\
success,collision,collision_kind,hit,path_m,reach_m,return,min_path_m,min_reach_m";

/// The header of `summary.csv`.
pub const SUMMARY_HEADER: &str = "eval,world,episodes,runs,max_steps,seed,min_path_m,min_reach_m,\
moving_success_mean,moving_success_std,moving_success_per_run,success_mean,success_std,\
success_per_run,collisions_bumper,collisions_pedestrian,collisions_laser,steps_mean,path_m_mean,\
reach_m_mean,return_mean";

/// The header `summary.csv` had before the moving success (read to say what to do).
const SUMMARY_HEADER_V1: &str = "eval,world,episodes,runs,max_steps,seed,success_mean,success_std,\
success_per_run,collisions_bumper,collisions_pedestrian,collisions_laser,steps_mean,path_m_mean,return_mean";

/// A CSV field: quoted (quotes doubled) when it holds a comma, quote or line break.
pub fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

/// One row of `episodes.csv` (no newline), its moving success by `rule`.
pub fn episode_row(r: &EpisodeRecord, rule: &MovingRule) -> String {
    format!(
        "{},{},{},{},{:.3},{:.3},{:.1},{},{},{},{},{},{},{:.3},{:.3},{:.4},{:.3},{:.3}",
        csv_field(&r.world),
        r.run,
        r.episode,
        r.seed,
        r.start.x,
        r.start.y,
        r.start.yaw.to_degrees(),
        r.steps,
        u8::from(r.moving_success(rule)),
        u8::from(r.success()),
        u8::from(!r.success()),
        r.collision.as_ref().map_or("", collision_kind),
        csv_field(&r.hit),
        r.path_m,
        r.reach_m,
        r.ret,
        rule.min_path_m,
        rule.min_reach_m
    )
}

/// Each obstacle the bumper hit in `records` with its count, most hit first (ties by label).
pub(crate) fn bumper_hits(records: &[EpisodeRecord]) -> Vec<(String, u32)> {
    let mut counts = std::collections::BTreeMap::<&str, u32>::new();
    for r in records.iter().filter(|r| !r.hit.is_empty()) {
        *counts.entry(&r.hit).or_default() += 1;
    }
    let mut v: Vec<(String, u32)> = counts.into_iter().map(|(k, n)| (k.to_string(), n)).collect();
    v.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    v
}

/// Mean and population std (as `numpy.std`) of per-run rates.
pub fn mean_std(per_run: &[f64]) -> (f64, f64) {
    let n = per_run.len().max(1) as f64;
    let mean = per_run.iter().sum::<f64>() / n;
    (mean, (per_run.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt())
}

/// A world's results, summarised (paper Table 2's cell and what explains it).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct WorldSummary {
    /// The evaluated policy's name.
    pub eval: String,
    /// The world.
    pub world: String,
    /// Episodes per run.
    pub episodes: u32,
    /// Runs.
    pub runs: u32,
    /// Step budget of an episode.
    pub max_steps: u32,
    /// The evaluation's seed.
    pub seed: u64,
    /// Metres a moving success must drive (`--min-path`).
    pub min_path_m: f64,
    /// Metres from its start a moving success must get at some step (`--min-reach`).
    pub min_reach_m: f64,
    /// Mean over runs of each run's moving success rate (0–1): no collision *and* the
    /// travel above. The headline: a policy that turns in place scores 0.
    pub moving_success_mean: f64,
    /// Population standard deviation over runs of the moving success rate.
    pub moving_success_std: f64,
    /// Each run's moving success rate.
    pub moving_success_per_run: Vec<f64>,
    /// Mean over runs of each run's success rate (0–1): the paper's measure (no collision
    /// within the step budget), the one compared with the paper's Table 2.
    pub success_mean: f64,
    /// Population standard deviation over runs of the success rate (as `numpy.std`).
    pub success_std: f64,
    /// Each run's success rate.
    pub success_per_run: Vec<f64>,
    /// Collisions with static obstacles (the bumper).
    pub collisions_bumper: u32,
    /// Collisions with pedestrians.
    pub collisions_pedestrian: u32,
    /// Episodes ended by the laser's minimum range (eq. 4).
    pub collisions_laser: u32,
    /// Mean steps survived.
    pub steps_mean: f64,
    /// Mean collision-free path: distance driven per episode up to its end or its
    /// collision, metres.
    pub path_m_mean: f64,
    /// Mean of the farthest each episode got from its start, metres.
    pub reach_m_mean: f64,
    /// Mean accumulated reward.
    pub return_mean: f64,
    /// The episodes were of the navigation task (success = the goal reached); not in
    /// `summary.csv` (`navigation.csv` has the rest), in the JSON only when true.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub navigation: bool,
    /// Share of the decisions that took each Table 1 action (0–1, action 0 first): a
    /// policy that turns in place shows it at once. In `summary.md` and the JSON, not in
    /// `summary.csv` (empty when read back from one).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub action_shares: Vec<f64>,
    /// What the bumper hit: each obstacle label (`EpisodeRecord::hit`) with its count, most
    /// hit first. In `summary.md` and the JSON, not in `summary.csv`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub bumper_hits: Vec<(String, u32)>,
}

/// The share of all decisions of `w` that took each action.
fn action_shares(w: &WorldEval) -> Vec<f64> {
    let mut counts = [0u64; mdrlat_core::Action::COUNT];
    for a in w.records.iter().flat_map(|r| &r.actions) {
        counts[a.index()] += 1;
    }
    let total = counts.iter().sum::<u64>().max(1) as f64;
    counts.iter().map(|&c| round(c as f64 / total, 4)).collect()
}

/// Rounds to `digits` decimals, so that the JSON and CSV outputs agree.
fn round(x: f64, digits: i32) -> f64 {
    let f = 10f64.powi(digits);
    (x * f).round() / f
}

impl WorldSummary {
    /// Summarises the records of one world.
    pub fn new(eval: &str, w: &WorldEval, settings: &EvalSettings) -> Self {
        let runs = settings.runs.max(1);
        let rule = settings.moving;
        let rate = |ok: &dyn Fn(&EpisodeRecord) -> bool| -> Vec<f64> {
            (0..runs)
                .map(|run| {
                    let rs: Vec<&EpisodeRecord> =
                        w.records.iter().filter(|r| r.run == run).collect();
                    rs.iter().filter(|r| ok(r)).count() as f64 / rs.len().max(1) as f64
                })
                .collect()
        };
        let per_run = rate(&|r| r.success());
        let moving_per_run = rate(&|r| r.moving_success(&rule));
        let (mean, std) = mean_std(&per_run);
        let (moving_mean, moving_std) = mean_std(&moving_per_run);
        let count = |kind: &str| {
            w.records
                .iter()
                .filter(|r| r.collision.as_ref().map(collision_kind) == Some(kind))
                .count() as u32
        };
        let m = w.records.len().max(1) as f64;
        let avg = |f: fn(&EpisodeRecord) -> f64| w.records.iter().map(f).sum::<f64>() / m;
        Self {
            eval: eval.to_string(),
            world: w.world.clone(),
            episodes: settings.episodes,
            runs: settings.runs,
            max_steps: settings.max_steps,
            seed: settings.seed,
            min_path_m: round(f64::from(rule.min_path_m), 3),
            min_reach_m: round(f64::from(rule.min_reach_m), 3),
            moving_success_mean: round(moving_mean, 6),
            moving_success_std: round(moving_std, 6),
            moving_success_per_run: moving_per_run.iter().map(|x| round(*x, 6)).collect(),
            success_mean: round(mean, 6),
            success_std: round(std, 6),
            success_per_run: per_run.iter().map(|x| round(*x, 6)).collect(),
            collisions_bumper: count("bumper"),
            collisions_pedestrian: count("pedestrian"),
            collisions_laser: count("laser"),
            steps_mean: round(avg(|r| f64::from(r.steps)), 3),
            path_m_mean: round(avg(|r| f64::from(r.path_m)), 3),
            reach_m_mean: round(avg(|r| f64::from(r.reach_m)), 3),
            return_mean: round(avg(|r| f64::from(r.ret)), 4),
            navigation: w.records.iter().any(|r| r.goal.is_some()),
            action_shares: action_shares(w),
            bumper_hits: bumper_hits(&w.records),
        }
    }

    /// The row of `summary.csv` (no newline); names are quoted where CSV needs it.
    pub fn csv_row(&self) -> String {
        let list = |v: &[f64]| v.iter().map(|x| format!("{x:.6}")).collect::<Vec<_>>().join(";");
        format!(
            "{},{},{},{},{},{},{:.3},{:.3},{:.6},{:.6},{},{:.6},{:.6},{},{},{},{},{:.3},{:.3},{:.3},{:.4}",
            csv_field(&self.eval),
            csv_field(&self.world),
            self.episodes,
            self.runs,
            self.max_steps,
            self.seed,
            self.min_path_m,
            self.min_reach_m,
            self.moving_success_mean,
            self.moving_success_std,
            list(&self.moving_success_per_run),
            self.success_mean,
            self.success_std,
            list(&self.success_per_run),
            self.collisions_bumper,
            self.collisions_pedestrian,
            self.collisions_laser,
            self.steps_mean,
            self.path_m_mean,
            self.reach_m_mean,
            self.return_mean
        )
    }

    /// The success rate as the paper prints it: `94.4 ± 2.3` (percent).
    pub fn success_cell(&self) -> String {
        format!("{:.1} ± {:.1}", 100.0 * self.success_mean, 100.0 * self.success_std)
    }

    /// The moving success rate in the same form.
    pub fn moving_cell(&self) -> String {
        format!("{:.1} ± {:.1}", 100.0 * self.moving_success_mean, 100.0 * self.moving_success_std)
    }

    /// One JSON object (a line of `mdrlat eval --json`), with the run's timing beside the
    /// results.
    pub fn json(&self, timing: Option<&Timing>) -> String {
        let mut v = serde_json::to_value(self).unwrap_or_default();
        if let (Some(t), Some(map)) = (timing, v.as_object_mut()) {
            map.insert("wall_s".into(), round(t.wall_s, 3).into());
            map.insert("policy_s".into(), round(t.policy_s, 3).into());
            map.insert("decisions".into(), t.decisions.into());
            map.insert("decisions_per_s".into(), round(t.decisions_per_s(), 1).into());
            if let Some(g) = t.gflops() {
                map.insert("policy_gflops".into(), round(g, 2).into());
            }
        }
        v.to_string()
    }
}

/// How long a world's evaluation took (stdout only: never in a results file).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    /// Wall time, seconds.
    pub wall_s: f64,
    /// Seconds inside the policy.
    pub policy_s: f64,
    /// Decisions made.
    pub decisions: u64,
    /// Floating-point operations per decision of the policy, if known (a network).
    pub flop_per_decision: Option<f64>,
}

impl Timing {
    /// The timing of `w`.
    pub fn of(w: &WorldEval, flop_per_decision: Option<f64>) -> Self {
        Self { wall_s: w.wall_s, policy_s: w.policy_s, decisions: w.decisions, flop_per_decision }
    }
    /// Decisions per wall-clock second.
    pub fn decisions_per_s(&self) -> f64 {
        self.decisions as f64 / self.wall_s.max(1e-9)
    }
    /// The policy's arithmetic rate while deciding, GFLOP/s.
    pub fn gflops(&self) -> Option<f64> {
        self.flop_per_decision.map(|f| f * self.decisions as f64 / self.policy_s.max(1e-9) / 1e9)
    }
}

/// `episodes.csv` of several worlds (header included), moving success by `rule`.
pub fn episodes_csv<'a>(
    worlds: impl IntoIterator<Item = &'a WorldEval>,
    rule: &MovingRule,
) -> String {
    let mut s = String::from(EPISODES_HEADER);
    s.push('\n');
    for w in worlds {
        for r in &w.records {
            s.push_str(&episode_row(r, rule));
            s.push('\n');
        }
    }
    s
}

/// `summary.csv` (header included).
pub fn summary_csv(rows: &[WorldSummary]) -> String {
    let mut s = String::from(SUMMARY_HEADER);
    s.push('\n');
    for r in rows {
        s.push_str(&r.csv_row());
        s.push('\n');
    }
    s
}

/// Splits one CSV line into fields (quoted fields as [`csv_field`] writes them).
pub fn csv_split(line: &str) -> Vec<String> {
    let mut fields = Vec::new();
    let mut cur = String::new();
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                chars.next();
                cur.push('"');
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(std::mem::take(&mut cur)),
            (c, _) => cur.push(c),
        }
    }
    fields.push(cur);
    fields
}

/// Reads back a `summary.csv` (as [`summary_csv`] writes it); `source` names the file in
/// errors, which give the line and the column.
pub fn parse_summary_csv(text: &str, source: &str) -> Result<Vec<WorldSummary>, String> {
    let mut lines = text.lines();
    match lines.next() {
        Some(h) if h == SUMMARY_HEADER => {}
        Some(h) if h == SUMMARY_HEADER_V1 => {
            return Err(format!(
                "{source}: written by an mdrlat without the moving success; evaluate again \
                 (`mdrlat eval ... --overwrite`, or `mdrlat reproduce` after removing the \
                 evaluation's state)"
            ));
        }
        Some(h) => return Err(format!("{source}:1: not a summary.csv header: '{h}'")),
        None => return Err(format!("{source}: empty file")),
    }
    let columns = SUMMARY_HEADER.split(',').count();
    let mut rows = Vec::new();
    for (n, line) in lines.enumerate().filter(|(_, l)| !l.is_empty()) {
        let at = |col: &str, v: &str| format!("{source}:{}: {col} '{v}' is not valid", n + 2);
        let f = csv_split(line);
        if f.len() != columns {
            return Err(format!("{source}:{}: {} fields, expected {columns}", n + 2, f.len()));
        }
        let num = |i: usize, col: &str| f[i].parse::<f64>().map_err(|_| at(col, &f[i]));
        let int = |i: usize, col: &str| f[i].parse::<u32>().map_err(|_| at(col, &f[i]));
        let list = |i: usize, col: &str| -> Result<Vec<f64>, String> {
            if f[i].is_empty() {
                return Ok(Vec::new());
            }
            f[i].split(';').map(|x| x.parse::<f64>().map_err(|_| at(col, x))).collect()
        };
        rows.push(WorldSummary {
            eval: f[0].clone(),
            world: f[1].clone(),
            episodes: int(2, "episodes")?,
            runs: int(3, "runs")?,
            max_steps: int(4, "max_steps")?,
            seed: f[5].parse::<u64>().map_err(|_| at("seed", &f[5]))?,
            min_path_m: num(6, "min_path_m")?,
            min_reach_m: num(7, "min_reach_m")?,
            moving_success_mean: num(8, "moving_success_mean")?,
            moving_success_std: num(9, "moving_success_std")?,
            moving_success_per_run: list(10, "moving_success_per_run")?,
            success_mean: num(11, "success_mean")?,
            success_std: num(12, "success_std")?,
            success_per_run: list(13, "success_per_run")?,
            collisions_bumper: int(14, "collisions_bumper")?,
            collisions_pedestrian: int(15, "collisions_pedestrian")?,
            collisions_laser: int(16, "collisions_laser")?,
            steps_mean: num(17, "steps_mean")?,
            path_m_mean: num(18, "path_m_mean")?,
            reach_m_mean: num(19, "reach_m_mean")?,
            return_mean: num(20, "return_mean")?,
            navigation: false,
            action_shares: Vec::new(),
            bumper_hits: Vec::new(),
        });
    }
    Ok(rows)
}

/// `summary.md`: the success table as Markdown, moving success first, with what the
/// numbers mean; rows of several methods (the same protocol) get a method column.
pub fn summary_markdown(rows: &[WorldSummary]) -> String {
    let mut s = String::new();
    let several = rows.iter().any(|r| r.eval != rows[0].eval);
    if let Some(first) = rows.first() {
        let title = if several { String::new() } else { format!(" of {}", first.eval) };
        let what = if first.navigation {
            "the goal reached (navigation.md has time and path)".to_string()
        } else {
            format!("no collision within {} steps (the paper's measure)", first.max_steps)
        };
        let moving = if first.navigation {
            "the same as success (reaching a goal is travel)".to_string()
        } else {
            format!(
                "success *and* at least {} m driven *and* at least {} m from the start at some \
                 step (a policy that turns in place or circles on the spot succeeds by the \
                 paper's measure, never by this one)",
                first.min_path_m, first.min_reach_m
            )
        };
        let _ = writeln!(
            s,
            "# Evaluation{title}\n\nMoving success = {moving}. Success = {what}. {} episodes per \
             run, {} runs per world (mean ± population std over runs), seed {}. Path: distance \
             driven per episode up to its end or collision; reach: the farthest from its start.\n",
            first.episodes, first.runs, first.seed
        );
    }
    let method = if several { "| method " } else { "" };
    let _ = writeln!(
        s,
        "{method}| world | moving success % | success % | moving per run % | collisions (bumper / pedestrian / laser) | mean steps | mean path m | mean reach m | mean return |"
    );
    let _ = writeln!(
        s,
        "{}| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        if several { "| --- " } else { "" }
    );
    for r in rows {
        let per_run: Vec<String> =
            r.moving_success_per_run.iter().map(|x| format!("{:.0}", 100.0 * x)).collect();
        let method =
            if several { format!("| {} ", r.eval.replace('|', "\\|")) } else { String::new() };
        let _ = writeln!(
            s,
            "{method}| {} | **{}** | {} | {} | {} / {} / {} | {:.1} | {:.2} | {:.2} | {:.2} |",
            r.world.replace('|', "\\|"),
            r.moving_cell(),
            r.success_cell(),
            per_run.join(", "),
            r.collisions_bumper,
            r.collisions_pedestrian,
            r.collisions_laser,
            r.steps_mean,
            r.path_m_mean,
            r.reach_m_mean,
            r.return_mean
        );
    }
    if rows.iter().any(|r| !r.action_shares.is_empty()) {
        let _ = writeln!(
            s,
            "\nActions taken, % of decisions (Table 1: 0–2 at 0.5 m/s, 3–7 at 0.2 m/s, 8–9 turning \
             in place):\n"
        );
        let method = if several { "| method " } else { "" };
        let _ = write!(s, "{method}| world |");
        for a in 0..mdrlat_core::Action::COUNT {
            let _ = write!(s, " {a} |");
        }
        let _ =
            writeln!(s, "\n{}| --- |{}", if several { "| --- " } else { "" }, " --- |".repeat(10));
        for r in rows.iter().filter(|r| !r.action_shares.is_empty()) {
            let method =
                if several { format!("| {} ", r.eval.replace('|', "\\|")) } else { String::new() };
            let _ = write!(s, "{method}| {} |", r.world.replace('|', "\\|"));
            for x in &r.action_shares {
                let _ = write!(s, " {:.1} |", 100.0 * x);
            }
            s.push('\n');
        }
    }
    if rows.iter().any(|r| !r.bumper_hits.is_empty()) {
        let _ =
            writeln!(s, "\nWhat the bumper hit (obstacle labels of the world file, episodes):\n");
        let method = if several { "| method " } else { "" };
        let _ = writeln!(s, "{method}| world | bumper hits |");
        let _ = writeln!(s, "{}| --- | --- |", if several { "| --- " } else { "" });
        for r in rows.iter().filter(|r| !r.bumper_hits.is_empty()) {
            let method =
                if several { format!("| {} ", r.eval.replace('|', "\\|")) } else { String::new() };
            let hits: Vec<String> = r
                .bumper_hits
                .iter()
                .map(|(label, n)| format!("{} {n}", label.replace('|', "\\|")))
                .collect();
            let _ =
                writeln!(s, "{method}| {} | {} |", r.world.replace('|', "\\|"), hits.join(", "));
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_fields_are_quoted_only_when_they_must_be() {
        assert_eq!(csv_field("office"), "office");
        assert_eq!(csv_field("my,world"), "\"my,world\"");
        assert_eq!(csv_field("a \"b\""), "\"a \"\"b\"\"\"");
        assert_eq!(csv_field("mdrlat from runs/a (step 5)"), "mdrlat from runs/a (step 5)");
    }

    fn summary(eval: &str, success: f64) -> WorldSummary {
        WorldSummary {
            eval: eval.into(),
            world: "office".into(),
            episodes: 10,
            runs: 2,
            max_steps: 300,
            seed: 0,
            min_path_m: 5.0,
            min_reach_m: 2.0,
            moving_success_mean: success / 2.0,
            moving_success_std: 0.0,
            moving_success_per_run: vec![success / 2.0, success / 2.0],
            success_mean: success,
            success_std: 0.05,
            success_per_run: vec![success - 0.05, success + 0.05],
            collisions_bumper: 3,
            collisions_pedestrian: 0,
            collisions_laser: 2,
            steps_mean: 100.0,
            path_m_mean: 5.0,
            reach_m_mean: 2.5,
            return_mean: 10.0,
            navigation: false,
            action_shares: Vec::new(),
            bumper_hits: Vec::new(),
        }
    }

    #[test]
    fn summary_csv_reads_back_what_it_wrote() {
        let rows = vec![summary("wander", 0.15), summary("mdrlat, \"s0\"", 0.5)];
        let text = summary_csv(&rows);
        let back = parse_summary_csv(&text, "s.csv").expect("parses");
        assert_eq!(summary_csv(&back), text);
        assert_eq!(back[1].eval, rows[1].eval);
        let e = parse_summary_csv(&text.replace("0.150000", "x"), "s.csv").expect_err("bad");
        assert!(e.contains("s.csv:2") && e.contains("success_mean"), "{e}");
        assert!(parse_summary_csv("a,b\n", "s.csv").expect_err("header").contains("s.csv:1"));
        let old =
            format!("{SUMMARY_HEADER_V1}\nwander,office,10,2,300,0,0.5,0.1,0.4;0.6,1,0,0,9,9,9\n");
        let e = parse_summary_csv(&old, "s.csv").expect_err("old");
        assert!(e.contains("without the moving success") && e.contains("--overwrite"), "{e}");
    }

    #[test]
    fn the_markdown_table_names_the_method_when_it_holds_several() {
        let one = summary_markdown(&[summary("wander", 0.15)]);
        assert!(one.starts_with("# Evaluation of wander\n"), "{one}");
        assert!(
            one.contains("| office | **7.5 ± 0.0** | 15.0 ± 5.0 | 8, 8 | 3 / 0 / 2 |"),
            "{one}"
        );
        assert!(one.contains("at least 5 m driven *and* at least 2 m from the start"), "{one}");
        let two = summary_markdown(&[summary("wander", 0.15), summary("random", 0.05)]);
        assert!(two.starts_with("# Evaluation\n") && two.contains("| method | world |"), "{two}");
        assert!(two.contains("| random | office | **2.5 ± 0.0** | 5.0 ± 5.0 |"), "{two}");
        assert_eq!(two.lines().filter(|l| l.starts_with('|')).count(), 4);
    }
}
