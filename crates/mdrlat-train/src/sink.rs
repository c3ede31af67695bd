//! The metrics sink: every number a run reports goes through here once, into `metrics.csv`
//! (a row every [`LOG_INTERVAL`] steps), `eval.csv` (a row every evaluation) and the
//! TensorBoard event file. A resumed run reopens the files and drops the rows it will write
//! again.

use crate::checkpoint::Window;
use crate::error::TrainError;
use crate::evaluation::Evaluation;
use crate::run_dir::RunDir;
use crate::tensorboard::EventWriter;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;

/// Steps per row of `metrics.csv`.
pub const LOG_INTERVAL: u64 = 100;

/// Where a run's metrics go.
pub struct MetricsSink {
    metrics: Csv,
    evals: Csv,
    events: EventWriter,
}

impl MetricsSink {
    /// A new run's files in `dir`.
    ///
    /// # Errors
    /// A file cannot be written.
    pub fn create(dir: &RunDir) -> Result<Self, TrainError> {
        let metrics = Csv::create(dir.metrics(), METRICS_HEADER)?;
        let evals = Csv::create(dir.evaluations(), EVAL_HEADER)?;
        let events = EventWriter::create(dir.path())
            .map_err(|source| TrainError::Io { path: dir.path().to_path_buf(), source })?;
        Ok(MetricsSink { metrics, evals, events })
    }

    /// The files of a run resumed at `step` of `total_steps`: rows from `step` on are
    /// dropped (they will be written again). A partial-window row at `step` is written again,
    /// complete — unless the run is already at its end (killed after its last checkpoint):
    /// then nothing would write it again, and it is kept.
    ///
    /// # Errors
    /// A file is missing, of another version, or cannot be written.
    pub fn resume(dir: &RunDir, step: u64, total_steps: u64) -> Result<Self, TrainError> {
        let keep = step.is_multiple_of(LOG_INTERVAL) || step >= total_steps;
        let metrics = reopen(dir.metrics(), METRICS_HEADER, step, keep)?;
        let evals = reopen(dir.evaluations(), EVAL_HEADER, step, true)?;
        let mut events = EventWriter::create(dir.path())
            .map_err(|source| TrainError::Io { path: dir.path().to_path_buf(), source })?;
        events
            .session_start(step)
            .map_err(|source| TrainError::Io { path: events.path().to_path_buf(), source })?;
        Ok(MetricsSink { metrics, evals, events })
    }

    /// `metrics.csv`'s row at step `t` from the window's sums (one write per row: `tail -f`
    /// works), and the same scalars for TensorBoard.
    ///
    /// # Errors
    /// A file cannot be written.
    pub fn log(
        &mut self,
        t: u64,
        w: &Window,
        epsilon: f32,
        episodes: u64,
    ) -> Result<(), TrainError> {
        let mean = |x: f64, n: u32| {
            if n > 0 { format!("{:.6}", x / f64::from(n)) } else { String::new() }
        };
        self.metrics.line(&format!(
            "{t},{},{},{},{epsilon:.6},{},{},{episodes}",
            mean(w.td, w.updates),
            mean(w.at, w.updates),
            mean(w.q, w.updates),
            mean(w.episode_reward, w.episodes),
            mean(w.episode_length, w.episodes),
        ))?;
        let per = |x: f64, n: u32| if n > 0 { (x / f64::from(n)) as f32 } else { f32::NAN };
        let scalars = [
            ("losses/td", per(w.td, w.updates)),
            ("losses/at", per(w.at, w.updates)),
            ("losses/q_mean", per(w.q, w.updates)),
            ("charts/epsilon", epsilon),
            ("charts/episode_reward", per(w.episode_reward, w.episodes)),
            ("charts/episode_length", per(w.episode_length, w.episodes)),
        ];
        self.events.scalars(t, &scalars).map_err(|source| self.tb_error(source))?;
        self.metrics.flush()
    }

    /// One evaluation's row of `eval.csv` and its TensorBoard scalars.
    ///
    /// # Errors
    /// A file cannot be written.
    pub fn evaluation(&mut self, e: &Evaluation) -> Result<(), TrainError> {
        write_evaluation(e, &mut self.evals, &mut self.events)
    }

    /// Everything written so far on disk.
    ///
    /// # Errors
    /// A file cannot be written.
    pub fn flush(&mut self) -> Result<(), TrainError> {
        self.events.flush().map_err(|source| self.tb_error(source))?;
        self.metrics.flush()?;
        self.evals.flush()
    }

    fn tb_error(&self, source: std::io::Error) -> TrainError {
        TrainError::Io { path: self.events.path().to_path_buf(), source }
    }
}

/// A CSV file with a header, named in errors.
struct Csv {
    path: PathBuf,
    out: BufWriter<File>,
}

impl Csv {
    fn create(path: PathBuf, header: &str) -> Result<Self, TrainError> {
        let file =
            File::create(&path).map_err(|source| TrainError::Io { path: path.clone(), source })?;
        let mut csv = Csv { path, out: BufWriter::new(file) };
        csv.line(header)?;
        // The header on disk at once: a run stopped before its first rows leaves a readable
        // (empty) table, not an empty file.
        csv.flush()?;
        Ok(csv)
    }
    fn line(&mut self, text: &str) -> Result<(), TrainError> {
        writeln!(self.out, "{text}")
            .map_err(|source| TrainError::Io { path: self.path.clone(), source })
    }
    fn flush(&mut self) -> Result<(), TrainError> {
        self.out.flush().map_err(|source| TrainError::Io { path: self.path.clone(), source })
    }
}

/// Keeps the rows of a run's CSV file before `step` (and at `step` with `keep_step`): those
/// a resumed run will not write again. A file written by an older version with fewer
/// columns gets `header` and its old rows empty fields for the new columns, so every row
/// has the header's width. Opens the file for appending.
fn reopen(path: PathBuf, header: &str, step: u64, keep_step: bool) -> Result<Csv, TrainError> {
    let io = |source| TrainError::Io { path: path.clone(), source };
    let text = std::fs::read_to_string(&path).map_err(io)?;
    let old_header = text.lines().next().unwrap_or_default();
    let (old_fields, fields): (Vec<&str>, Vec<&str>) =
        (old_header.split(',').collect(), header.split(',').collect());
    // The same columns, or the first columns of today's (an older version's file).
    if old_fields.len() > fields.len() || fields[..old_fields.len()] != old_fields[..] {
        return Err(TrainError::Checkpoint {
            path: path.clone(),
            problem: format!(
                "its header '{old_header}' is not this version's '{header}' nor its first \
                 columns: written by another mdrlat; resume it with that one"
            ),
        });
    }
    let missing = fields.len() - old_fields.len();
    let mut kept = String::with_capacity(text.len());
    for (i, line) in text.lines().enumerate() {
        if i == 0 {
            kept.push_str(if missing > 0 { header } else { line });
            kept.push('\n');
            continue;
        }
        let row_step = line.split(',').next().and_then(|f| f.parse::<u64>().ok());
        if row_step.is_some_and(|s| s < step || (s == step && keep_step)) {
            kept.push_str(line);
            kept.push_str(&",".repeat(missing));
            kept.push('\n');
        }
    }
    std::fs::write(&path, kept).map_err(io)?;
    let file = std::fs::OpenOptions::new().append(true).open(&path).map_err(io)?;
    Ok(Csv { path, out: BufWriter::new(file) })
}

/// The header of `metrics.csv`.
const METRICS_HEADER: &str =
    "step,loss_td,loss_at,q_mean,epsilon,episode_reward,episode_length,episodes";
/// The header of `eval.csv`: Fig. 4's reward on fixed starts of the training world, then
/// the learning curves (held-out starts of the training world, then the unseen world named
/// in `config.toml`'s `train.curve_world`; empty where a run has no curves).
pub const EVAL_HEADER: &str = "step,eval_reward_mean,eval_reward_std,eval_length_mean,\
eval_success_rate,eval_collision_rate,train_moving_success,train_success,train_path_m,\
unseen_moving_success,unseen_success,unseen_path_m";

/// One evaluation's row of `eval.csv` and its TensorBoard scalars.
fn write_evaluation(
    e: &Evaluation,
    evals_csv: &mut Csv,
    events: &mut EventWriter,
) -> Result<(), TrainError> {
    let t = e.step;
    let mean_len =
        e.lengths.iter().map(|&l| f64::from(l)).sum::<f64>() / e.lengths.len().max(1) as f64;
    // The curves' columns: held-out training starts, then the unseen world.
    let mut curve_cells = String::new();
    for k in 0..2 {
        match e.curves.get(k) {
            Some(c) => curve_cells
                .push_str(&format!(",{:.6},{:.6},{:.3}", c.moving_success, c.success, c.path_m)),
            None => curve_cells.push_str(",,,"),
        }
    }
    evals_csv.line(&format!(
        "{t},{:.6},{:.6},{mean_len:.2},{:.6},{:.6}{curve_cells}",
        e.mean(),
        e.std(),
        e.success_rate(),
        e.collision_rate()
    ))?;
    let mut scalars = vec![
        ("eval/reward_mean".to_string(), e.mean()),
        ("eval/reward_std".to_string(), e.std()),
        ("eval/length_mean".to_string(), mean_len as f32),
        ("eval/success_rate".to_string(), e.success_rate()),
        ("eval/collision_rate".to_string(), e.collision_rate()),
    ];
    for (c, which) in e.curves.iter().zip(["train", "unseen"]) {
        scalars.extend([
            (format!("curves/{which}_moving_success"), c.moving_success as f32),
            (format!("curves/{which}_success"), c.success as f32),
            (format!("curves/{which}_path_m"), c.path_m as f32),
        ]);
    }
    let named: Vec<(&str, f32)> = scalars.iter().map(|(k, v)| (k.as_str(), *v)).collect();
    events
        .scalars(t, &named)
        .map_err(|source| TrainError::Io { path: events.path().to_path_buf(), source })?;
    evals_csv.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_new_csv_has_its_header_on_disk_before_any_row() {
        let dir = std::env::temp_dir().join(format!("mdrlat-csv-header-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("eval.csv");
        let csv = Csv::create(path.clone(), EVAL_HEADER).expect("create");
        // Read while the writer is still open, as after a run killed before its first rows.
        assert_eq!(std::fs::read_to_string(&path).expect("read"), format!("{EVAL_HEADER}\n"));
        drop(csv);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn resuming_a_run_of_an_older_version_widens_its_csv_to_the_new_header() {
        let dir = std::env::temp_dir().join(format!("mdrlat-reopen-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("eval.csv");
        let old = "step,eval_reward_mean,eval_reward_std,eval_length_mean\n\
                   5000,1.0,0.5,10.00\n10000,2.0,0.5,20.00\n15000,3.0,0.5,30.00\n";
        std::fs::write(&path, old).expect("write");
        let mut csv = reopen(path.clone(), EVAL_HEADER, 10_000, true).expect("reopen");
        csv.line("15000,4.0,0.5,40.00,0.200000,0.800000,0.1,0.2,3.0,0.1,0.2,3.0").expect("append");
        csv.flush().expect("flush");
        let text = std::fs::read_to_string(&path).expect("read");
        assert_eq!(
            text,
            format!(
                "{EVAL_HEADER}\n5000,1.0,0.5,10.00,,,,,,,,\n10000,2.0,0.5,20.00,,,,,,,,\n15000,4.0,0.5,40.00,0.200000,0.800000,0.1,0.2,3.0,0.1,0.2,3.0\n"
            )
        );
        for line in text.lines() {
            assert_eq!(line.split(',').count(), 12, "{line}");
        }
        // A file with the current header is kept as it is.
        let mut csv = reopen(path.clone(), EVAL_HEADER, 20_000, true).expect("reopen");
        csv.flush().expect("flush");
        assert_eq!(std::fs::read_to_string(&path).expect("read"), text);
        // One whose columns are not this version's (a newer one's) is an error, not a mix.
        std::fs::write(&path, format!("{EVAL_HEADER},future_column\n5000{}\n", ",1".repeat(12)))
            .expect("write");
        let e = reopen(path.clone(), EVAL_HEADER, 5000, true).map(|_| ()).expect_err("newer");
        assert!(e.to_string().contains("future_column"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
