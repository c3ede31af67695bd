//! `mdrlat plot`: smoothed training curves of several runs (paper Fig. 4): the greedy
//! reward, and where the runs have them the learning curves in the metric that matters
//! (moving success, the paper's success, mean path; held-out starts of the training world
//! and an unseen world), a panel each.

use super::ensure_parent;
use anyhow::{Context, Result, bail};
use mdrlat_render::{Chart, Image, Series, line_chart, side_by_side, stacked};
use std::path::{Path, PathBuf};

/// What to plot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Metric {
    /// Fig. 4: greedy evaluation reward (eval.csv), mean ± std band; beside it a panel each
    /// for the learning curves' moving success, success and mean path (held-out starts of
    /// the training world and the unseen world), where eval.csv has them.
    Eval,
    /// Training episode reward (metrics.csv).
    EpisodeReward,
    /// TD loss (metrics.csv).
    LossTd,
    /// Auxiliary loss (metrics.csv).
    LossAt,
}

/// Arguments of `mdrlat plot`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Run directories (each with eval.csv / metrics.csv).
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// Output PNG.
    #[arg(long, default_value = "fig4.png")]
    out: PathBuf,
    /// Exponential smoothing weight in [0, 1) (TensorBoard's; 0: none).
    #[arg(long, default_value_t = 0.6)]
    smooth: f32,
    /// What to plot.
    #[arg(long, value_enum, default_value = "eval")]
    metric: Metric,
    /// One curve per network variant: the runs of a variant (other seeds) averaged, the
    /// band their spread (± std over runs), as the paper's Fig. 4 draws six curves.
    #[arg(long)]
    by_variant: bool,
    /// The x-axis: training steps, or minutes of training (from the runs' TensorBoard wall
    /// times, each session counted, work redone after a restart left out; name the CPU
    /// beside such a figure).
    #[arg(long, value_enum, default_value = "steps")]
    x: XAxis,
}

/// What the x-axis counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum XAxis {
    /// Environment steps.
    Steps,
    /// Minutes of training.
    Minutes,
}

impl XAxis {
    fn label(self) -> &'static str {
        match self {
            XAxis::Steps => "training steps",
            XAxis::Minutes => "minutes of training",
        }
    }
}

/// The x value of each step of the run in `dir`: the step, or its minutes of training.
fn x_of(dir: &Path, axis: XAxis) -> Result<Box<dyn Fn(f32) -> f32>> {
    match axis {
        XAxis::Steps => Ok(Box::new(|step| step)),
        XAxis::Minutes => {
            let times = mdrlat_train::tensorboard::training_seconds(dir).with_context(|| {
                format!("{}: reading its TensorBoard wall times", dir.display())
            })?;
            if times.is_empty() {
                bail!("{}: no TensorBoard events to time the run by", dir.display());
            }
            Ok(Box::new(move |step| {
                // The last logged step at or before this one.
                let i = times.partition_point(|&(s, _)| s as f32 <= step).max(1) - 1;
                (times[i].1 / 60.0) as f32
            }))
        }
    }
}

impl Args {
    /// Fig. 4 of a sweep: the runs averaged per variant into `out`.
    pub fn by_variant(out: &std::path::Path, runs: &[std::path::PathBuf]) -> Self {
        Args {
            runs: runs.to_vec(),
            out: out.to_path_buf(),
            smooth: 0.6,
            metric: Metric::Eval,
            by_variant: true,
            x: XAxis::Steps,
        }
    }
}

/// The runs' curves averaged per label's variant: mean over runs at each common step, band
/// ± population std over runs (a single run keeps its own band).
fn average_by_variant(series: Vec<(String, Series)>) -> Vec<Series> {
    let mut groups: Vec<(String, Vec<Series>)> = Vec::new();
    for (variant, s) in series {
        match groups.iter_mut().find(|g| g.0 == variant) {
            Some(g) => g.1.push(s),
            None => groups.push((variant, vec![s])),
        }
    }
    groups
        .into_iter()
        .map(|(variant, runs)| {
            if runs.len() == 1 {
                let mut one = runs.into_iter().next().expect("one run");
                one.label = variant;
                return one;
            }
            // The steps every run has (runs resumed from older versions or evaluated at other
            // intervals may lack some), each averaged over the runs at that step.
            let at = |r: &Series, x: f32| r.points.iter().find(|p| p.0 == x).map(|p| p.1);
            let common: Vec<f32> = runs[0]
                .points
                .iter()
                .map(|p| p.0)
                .filter(|&x| runs.iter().all(|r| at(r, x).is_some()))
                .collect();
            let n = runs.len() as f32;
            let mut points = Vec::with_capacity(common.len());
            let mut band = Vec::with_capacity(common.len());
            for x in common {
                let ys: Vec<f32> = runs.iter().filter_map(|r| at(r, x)).collect();
                let mean = ys.iter().sum::<f32>() / n;
                let std = (ys.iter().map(|y| (y - mean).powi(2)).sum::<f32>() / n).sqrt();
                points.push((x, mean));
                band.push((x, mean - std, mean + std));
            }
            Series { label: format!("{variant} ({} runs)", runs.len()), points, band }
        })
        .collect()
}

/// The learning curves' panels of Fig. 4: (`eval.csv` column after `train_`/`unseen_`,
/// title, y label); the moving success's title gets the first run's thresholds.
const CURVE_PANELS: [(&str, &str, &str); 3] = [
    ("moving_success", "Moving success", "rate"),
    ("success", "Success, the paper's measure (no collision in 300 steps)", "rate"),
    ("path_m", "Mean collision-free path per episode", "metres"),
];

/// Whether a CSV file's header has every one of `columns`.
fn has_columns(path: &Path, columns: &[&str]) -> bool {
    std::fs::read_to_string(path).is_ok_and(|t| {
        let header: Vec<&str> = t.lines().next().unwrap_or_default().split(',').collect();
        columns.iter().all(|c| header.contains(c))
    })
}

/// The unseen world of a run's learning curves and their moving rule, from its
/// `config.toml`.
fn curve_settings(dir: &Path) -> Option<(Option<String>, mdrlat_sim::MovingRule)> {
    let config = crate::config::Config::load_run(&dir.join("config.toml")).ok()?;
    Some((config.train.curve_world_for(config.sim.task), config.train.curve_rule()))
}

/// Rows of a CSV file as (column name → values); empty cells are NaN.
fn read_csv(path: &Path, columns: &[&str]) -> Result<Vec<Vec<f32>>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .with_context(|| format!("{}: empty file", path.display()))?
        .split(',')
        .collect();
    let idx: Vec<usize> = columns
        .iter()
        .map(|c| {
            header
                .iter()
                .position(|h| h == c)
                .with_context(|| format!("{}: no column '{c}'", path.display()))
        })
        .collect::<Result<_>>()?;
    let mut out = vec![Vec::new(); columns.len()];
    for (n, line) in lines.enumerate() {
        let cells: Vec<&str> = line.split(',').collect();
        for (k, &i) in idx.iter().enumerate() {
            let cell = cells
                .get(i)
                .with_context(|| format!("{}:{}: too few columns", path.display(), n + 2))?;
            let v = if cell.is_empty() {
                f32::NAN
            } else {
                cell.parse::<f32>().with_context(|| {
                    format!("{}:{}: '{cell}' is not a number", path.display(), n + 2)
                })?
            };
            out[k].push(v);
        }
    }
    Ok(out)
}

/// TensorBoard's debiased exponential moving average, skipping NaN.
fn smooth(values: &[f32], weight: f32) -> Vec<f32> {
    let (mut last, mut n) = (0.0f32, 0i32);
    values
        .iter()
        .map(|&v| {
            if !v.is_finite() {
                return f32::NAN;
            }
            n += 1;
            last = last * weight + (1.0 - weight) * v;
            last / (1.0 - weight.powi(n))
        })
        .collect()
}

/// A run's label and its variant (from its `config.toml`; the folder name when unknown).
fn run_label(dir: &Path) -> (String, String) {
    let name = dir
        .file_name()
        .map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into_owned());
    let variant = std::fs::read_to_string(dir.join("config.toml")).ok().and_then(|t| {
        t.lines().find_map(|l| {
            l.trim().strip_prefix("variant = ").map(|v| v.trim_matches('"').to_string())
        })
    });
    match variant {
        Some(v) if !name.contains(&v) => (format!("{v} ({name})"), v),
        Some(v) => (name, v),
        None => (name.clone(), name),
    }
}

/// Runs `mdrlat plot`.
pub fn run(a: &Args) -> Result<()> {
    if !(0.0..1.0).contains(&a.smooth) {
        bail!("--smooth {}: must be in [0, 1)", a.smooth);
    }
    if a.x == XAxis::Minutes && a.by_variant {
        bail!(
            "--x minutes with --by-variant: runs of one variant are averaged at common steps, not minutes"
        );
    }
    let mut series = Vec::new();
    for dir in &a.runs {
        let (label, variant) = run_label(dir);
        let x = x_of(dir, a.x)?;
        let s = match a.metric {
            Metric::Eval => {
                let c = read_csv(
                    &dir.join("eval.csv"),
                    &["step", "eval_reward_mean", "eval_reward_std"],
                )?;
                let (mean, std) = (smooth(&c[1], a.smooth), smooth(&c[2], a.smooth));
                Series {
                    label,
                    points: c[0].iter().map(|&s| x(s)).zip(mean.iter().copied()).collect(),
                    band: c[0]
                        .iter()
                        .zip(mean.iter().zip(&std))
                        .map(|(&s, (&m, &sd))| (x(s), m - sd, m + sd))
                        .collect(),
                }
            }
            m => {
                let col = match m {
                    Metric::EpisodeReward => "episode_reward",
                    Metric::LossTd => "loss_td",
                    _ => "loss_at",
                };
                let c = read_csv(&dir.join("metrics.csv"), &["step", col])?;
                let keep: Vec<(f32, f32)> = c[0]
                    .iter()
                    .copied()
                    .zip(c[1].iter().copied())
                    .filter(|p| p.1.is_finite())
                    .collect();
                let ys = smooth(&keep.iter().map(|p| p.1).collect::<Vec<_>>(), a.smooth);
                Series {
                    label,
                    points: keep.iter().map(|p| x(p.0)).zip(ys).collect(),
                    band: Vec::new(),
                }
            }
        };
        if s.points.is_empty() {
            bail!("{}: no data yet (no evaluation or log row written)", dir.display());
        }
        series.push((variant, s));
    }
    let series: Vec<Series> = if a.by_variant {
        average_by_variant(series)
    } else {
        series.into_iter().map(|(_, s)| s).collect()
    };
    let (title, y) = match a.metric {
        Metric::Eval => ("Average accumulated reward (greedy, from fixed start poses)", "reward"),
        Metric::EpisodeReward => ("Training episode reward", "reward"),
        Metric::LossTd => ("TD loss (eq. 13)", "loss"),
        Metric::LossAt => ("Auxiliary loss (eq. 12)", "loss"),
    };
    let (width, height) = (1000, 620);
    let img = line_chart(
        &Chart { title, x_label: a.x.label(), y_label: y, series: &series },
        width,
        height,
    );
    let panels = if a.metric == Metric::Eval { curve_panels(a)? } else { Vec::new() };
    let img = if panels.is_empty() {
        img
    } else {
        // A 2 × 2 grid: the reward (the paper's Fig. 4), then the curves that matter.
        let charts: Vec<Image> = panels
            .iter()
            .map(|(title, y, series)| {
                line_chart(
                    &Chart { title, x_label: a.x.label(), y_label: y, series },
                    width,
                    height,
                )
            })
            .collect();
        let mut all: Vec<&Image> = vec![&img];
        all.extend(charts.iter());
        let rows: Vec<Image> = all.chunks(2).map(|pair| side_by_side(pair, 16)).collect();
        stacked(&rows.iter().collect::<Vec<_>>(), 16)
    };
    ensure_parent(&a.out)?;
    img.save_png(&a.out)?;
    out!(
        "wrote {} ({} curves{}, smoothing {})",
        a.out.display(),
        series.len(),
        if panels.is_empty() {
            String::new()
        } else {
            format!(" and {} learning-curve panels", panels.len())
        },
        a.smooth
    );
    Ok(())
}

/// Fig. 4's learning-curve panels of the runs whose `eval.csv` has them (none for runs of
/// an mdrlat before the curves): per run (or variant), the unseen world's curve and the
/// training world's held-out one.
fn curve_panels(a: &Args) -> Result<Vec<(String, &'static str, Vec<Series>)>> {
    let mut panels = Vec::new();
    let rule = a.runs.iter().find_map(|d| curve_settings(d)).map_or_else(Default::default, |s| s.1);
    for (column, title, y) in CURVE_PANELS {
        let title = if column == "moving_success" {
            format!(
                "{title} (no collision in 300 steps, >= {} m driven, >= {} m from the start)",
                rule.min_path_m, rule.min_reach_m
            )
        } else {
            title.to_string()
        };
        let mut series = Vec::new();
        for dir in &a.runs {
            let path = dir.join("eval.csv");
            let (train, unseen) = (format!("train_{column}"), format!("unseen_{column}"));
            if !has_columns(&path, &[&train, &unseen]) {
                continue;
            }
            let c = read_csv(&path, &["step", &train, &unseen])?;
            let (label, variant) = run_label(dir);
            let x = x_of(dir, a.x)?;
            let world = curve_settings(dir).and_then(|s| s.0).unwrap_or_else(|| "unseen".into());
            for (ys, which) in [(&c[2], world), (&c[1], "train, held-out starts".to_string())] {
                let keep: Vec<(f32, f32)> = c[0]
                    .iter()
                    .copied()
                    .zip(ys.iter().copied())
                    .filter(|p| p.1.is_finite())
                    .collect();
                if keep.is_empty() {
                    continue;
                }
                let smoothed = smooth(&keep.iter().map(|p| p.1).collect::<Vec<_>>(), a.smooth);
                series.push((
                    format!("{variant}: {which}"),
                    Series {
                        label: format!("{label}: {which}"),
                        points: keep.iter().map(|p| x(p.0)).zip(smoothed).collect(),
                        band: Vec::new(),
                    },
                ));
            }
        }
        if series.is_empty() {
            continue;
        }
        let series = if a.by_variant {
            average_by_variant(series)
        } else {
            series.into_iter().map(|(_, s)| s).collect()
        };
        panels.push((title, y, series));
    }
    Ok(panels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_of_a_variant_average_into_one_curve() {
        let run = |ys: &[f32]| Series {
            label: String::new(),
            points: ys.iter().enumerate().map(|(i, &y)| (i as f32, y)).collect(),
            band: Vec::new(),
        };
        let curves = average_by_variant(vec![
            ("mdrlat".into(), run(&[1.0, 3.0, 5.0])),
            ("multi".into(), run(&[2.0, 2.0])),
            ("mdrlat".into(), run(&[3.0, 5.0])),
        ]);
        assert_eq!(curves.len(), 2);
        assert_eq!(curves[0].label, "mdrlat (2 runs)");
        assert_eq!(curves[0].points, [(0.0, 2.0), (1.0, 4.0)], "common steps only");
        assert_eq!(curves[0].band, [(0.0, 1.0, 3.0), (1.0, 3.0, 5.0)]);
        assert_eq!(curves[1].label, "multi");
        // Runs with other steps are averaged step by step, not point by point.
        let at = |pts: &[(f32, f32)]| Series {
            label: String::new(),
            points: pts.to_vec(),
            band: Vec::new(),
        };
        let curves = average_by_variant(vec![
            ("a".into(), at(&[(5.0, 1.0), (10.0, 3.0)])),
            ("a".into(), at(&[(10.0, 5.0), (15.0, 7.0)])),
        ]);
        assert_eq!(curves[0].points, [(10.0, 4.0)]);
    }

    #[test]
    fn smoothing_is_debiased_and_skips_gaps() {
        let s = smooth(&[2.0, f32::NAN, 2.0, 2.0], 0.6);
        assert!((s[0] - 2.0).abs() < 1e-6 && s[1].is_nan() && (s[3] - 2.0).abs() < 1e-5);
        assert_eq!(smooth(&[1.0, 3.0], 0.0), [1.0, 3.0]);
    }
}
