//! Success against minutes of training: the evaluations of a run's snapshots
//! (`train.snapshot_minutes`, `mdrlat eval --snapshots RUN`) as one table and one figure —
//! each point a full protocol evaluation of the policy as it stood at that minute, not a
//! learning curve's few episodes.

use crate::report::{WorldSummary, csv_field};
use mdrlat_render::{Chart, Image, Series, line_chart, side_by_side};

/// One snapshot's evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct SnapshotResult {
    /// The minute of training it was due at (its folder's name).
    pub minute: f64,
    /// The minutes actually trained when it was written (a few seconds past `minute`).
    pub training_minutes: Option<f64>,
    /// The environment step it was written at.
    pub step: Option<u64>,
    /// Its summary in each world evaluated, in order.
    pub worlds: Vec<WorldSummary>,
}

/// `snapshots.csv`: a row per snapshot and world.
pub fn snapshots_csv(rows: &[SnapshotResult]) -> String {
    let mut out = String::from(
        "minute,training_minutes,step,world,episodes,runs,moving_success_mean,moving_success_std,success_mean,success_std,path_m_mean\n",
    );
    for r in rows {
        for w in &r.worlds {
            out.push_str(&format!(
                "{:.3},{},{},{},{},{},{:.6},{:.6},{:.6},{:.6},{:.3}\n",
                r.minute,
                r.training_minutes.map_or(String::new(), |m| format!("{m:.3}")),
                r.step.map_or(String::new(), |s| s.to_string()),
                csv_field(&w.world),
                w.episodes,
                w.runs,
                w.moving_success_mean,
                w.moving_success_std,
                w.success_mean,
                w.success_std,
                w.path_m_mean,
            ));
        }
    }
    out
}

/// `snapshots.md`: moving success (the paper's success in brackets) per snapshot and world.
pub fn snapshots_markdown(rows: &[SnapshotResult], title: &str) -> String {
    let worlds: Vec<&str> =
        rows.first().map_or(Vec::new(), |r| r.worlds.iter().map(|w| w.world.as_str()).collect());
    let mut out = format!("# {title}\n\n");
    let nav = is_navigation(rows);
    if let Some(w) = rows.first().and_then(|r| r.worlds.first()) {
        let measure = if nav {
            format!(
                "Goals reached % (the robot's centre at its goal within {} steps: navigation, \
                 where moving success is the same)",
                w.max_steps
            )
        } else {
            format!(
                "Moving success % (no collision in {} steps, ≥ {} m driven, ≥ {} m from the \
                 start; the paper's success in brackets)",
                w.max_steps, w.min_path_m, w.min_reach_m
            )
        };
        out.push_str(&format!(
            "{measure}, {} runs × {} episodes per world, seed {}, of the policy as it stood at \
             each minute of training.\n\n",
            w.runs, w.episodes, w.seed
        ));
    }
    out.push_str("| minute | step |");
    for w in &worlds {
        out.push_str(&format!(" {w} |"));
    }
    out.push_str("\n| --- | --- |");
    out.push_str(&" --- |".repeat(worlds.len()));
    out.push('\n');
    for r in rows {
        out.push_str(&format!(
            "| {} | {} |",
            r.minute,
            r.step.map_or("—".to_string(), |s| s.to_string())
        ));
        for w in &r.worlds {
            let (mean, std) = (100.0 * w.moving_success_mean, 100.0 * w.moving_success_std);
            if nav {
                out.push_str(&format!(" {mean:.1} ± {std:.1} |"));
            } else {
                out.push_str(&format!(" {mean:.1} ± {std:.1} ({:.1}) |", 100.0 * w.success_mean));
            }
        }
        out.push('\n');
    }
    out
}

/// Whether the snapshots were evaluated in the navigation task (success = the goal reached).
fn is_navigation(rows: &[SnapshotResult]) -> bool {
    rows.iter().flat_map(|r| &r.worlds).any(|w| w.navigation)
}

/// The figure: moving success (± std over runs) against minutes of training, a line per
/// world, and beside it the paper's success the same way (navigation: the goals reached, one
/// panel); `run` and the training `cpu` in the titles.
pub fn snapshots_chart(rows: &[SnapshotResult], run: &str, cpu: &str) -> Image {
    let worlds: Vec<String> =
        rows.first().map_or(Vec::new(), |r| r.worlds.iter().map(|w| w.world.clone()).collect());
    let series = |moving: bool| -> Vec<Series> {
        worlds
            .iter()
            .enumerate()
            .map(|(i, name)| {
                let pts: Vec<(f32, f32, f32)> = rows
                    .iter()
                    // Where the weights were taken: the minutes actually trained (a tick or
                    // a learning-curve evaluation past the minute the snapshot was due).
                    .filter_map(|r| {
                        r.worlds.get(i).map(|w| (r.training_minutes.unwrap_or(r.minute), w))
                    })
                    .map(|(m, w)| {
                        let (mean, std) = if moving {
                            (w.moving_success_mean, w.moving_success_std)
                        } else {
                            (w.success_mean, w.success_std)
                        };
                        (m as f32, (100.0 * mean) as f32, (100.0 * std) as f32)
                    })
                    .collect();
                Series {
                    label: name.clone(),
                    points: pts.iter().map(|&(x, y, _)| (x, y)).collect(),
                    band: pts.iter().map(|&(x, y, sd)| (x, y - sd, y + sd)).collect(),
                }
            })
            .collect()
    };
    let x_label = "minutes of training";
    if is_navigation(rows) {
        // Navigation: success is the goal reached, moving success the same; one panel.
        let title = format!("Goals reached by {run}'s snapshots; trained on {cpu}");
        let series = series(true);
        let chart = Chart { title: &title, x_label, y_label: "% of episodes", series: &series };
        return line_chart(&chart, 1000, 620);
    }
    let (moving, paper) = (series(true), series(false));
    let moving_title = format!("Moving success of {run}'s snapshots");
    let paper_title = format!("The paper's success; trained on {cpu}");
    let left = line_chart(
        &Chart { title: &moving_title, x_label, y_label: "% of episodes", series: &moving },
        1000,
        620,
    );
    let right = line_chart(
        &Chart { title: &paper_title, x_label, y_label: "% of episodes", series: &paper },
        1000,
        620,
    );
    side_by_side(&[&left, &right], 16)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary(world: &str, moving: f64, success: f64) -> WorldSummary {
        WorldSummary {
            eval: "test".into(),
            world: world.into(),
            episodes: 50,
            runs: 5,
            max_steps: 300,
            seed: 0,
            min_path_m: 5.0,
            min_reach_m: 2.0,
            moving_success_mean: moving,
            moving_success_std: 0.02,
            moving_success_per_run: vec![moving; 5],
            success_mean: success,
            success_std: 0.01,
            success_per_run: vec![success; 5],
            collisions_bumper: 0,
            collisions_pedestrian: 0,
            collisions_laser: 0,
            steps_mean: 300.0,
            path_m_mean: 12.5,
            reach_m_mean: 4.0,
            return_mean: 50.0,
            navigation: false,
            action_shares: Vec::new(),
            bumper_hits: Vec::new(),
        }
    }

    #[test]
    fn the_table_has_a_row_per_snapshot_and_world_and_the_figure_draws() {
        let rows = vec![
            SnapshotResult {
                minute: 2.0,
                training_minutes: Some(2.013),
                step: Some(4800),
                worlds: vec![summary("office", 0.25, 0.5), summary("crowd", 0.5, 0.75)],
            },
            SnapshotResult {
                minute: 4.0,
                training_minutes: None,
                step: None,
                worlds: vec![summary("office", 0.5, 0.75), summary("crowd", 1.0, 1.0)],
            },
        ];
        let csv = snapshots_csv(&rows);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 5, "{csv}");
        assert_eq!(
            lines[1],
            "2.000,2.013,4800,office,50,5,0.250000,0.020000,0.500000,0.010000,12.500"
        );
        assert_eq!(lines[4], "4.000,,,crowd,50,5,1.000000,0.020000,1.000000,0.010000,12.500");
        let md = snapshots_markdown(&rows, "laser-only, fast preset");
        assert!(md.contains("| minute | step | office | crowd |"), "{md}");
        assert!(md.contains("| 2 | 4800 | 25.0 ± 2.0 (50.0) | 50.0 ± 2.0 (75.0) |"), "{md}");
        assert!(md.contains("| 4 | — | 50.0 ± 2.0 (75.0) |"), "{md}");
        let img = snapshots_chart(&rows, "run", "cpu");
        assert_eq!((img.width, img.height), (2016, 620));
    }

    #[test]
    fn navigation_snapshots_are_goals_reached_in_one_panel() {
        let nav =
            |moving: f64| WorldSummary { navigation: true, ..summary("nav-test", moving, moving) };
        let rows = vec![
            SnapshotResult {
                minute: 10.0,
                training_minutes: None,
                step: Some(22_000),
                worlds: vec![nav(0.08)],
            },
            SnapshotResult {
                minute: 20.0,
                training_minutes: None,
                step: Some(44_000),
                worlds: vec![nav(0.5)],
            },
        ];
        let md = snapshots_markdown(&rows, "nav run");
        assert!(md.contains("Goals reached %"), "{md}");
        assert!(md.contains("| 10 | 22000 | 8.0 ± 2.0 |"), "{md}");
        assert!(!md.contains("(8.0)") && !md.contains("Moving success %"), "{md}");
        let img = snapshots_chart(&rows, "run", "cpu");
        assert_eq!((img.width, img.height), (1000, 620));
        // The same rows in avoidance: both measures, two panels.
        let avoid =
            vec![SnapshotResult { worlds: vec![summary("office", 0.5, 0.75)], ..rows[0].clone() }];
        assert_eq!(snapshots_chart(&avoid, "run", "cpu").width, 2016);
    }
}
