//! What a sweep is: the variants and seeds to train, for how long, with which settings, and
//! how their models are evaluated. A TOML file; four presets are built in.

use crate::SweepError;
use mdrlat_core::Variant;
use mdrlat_plan::MapSource;
use mdrlat_sim::Scripted;
use mdrlat_sim::config::Task;
use serde::{Deserialize, Serialize};

/// The built-in presets: name and TOML text.
pub const PRESETS: [(&str, &str); 5] = [
    ("paper", include_str!("../presets/paper.toml")),
    ("cpu-small", include_str!("../presets/cpu-small.toml")),
    ("smoke", include_str!("../presets/smoke.toml")),
    ("nav", include_str!("../presets/nav.toml")),
    ("fast", include_str!("../presets/fast.toml")),
];

/// The most training runs one sweep may hold (a Slurm array's index range is finite too).
pub const MAX_TRAIN_JOBS: usize = 1000;

/// A sweep: every training run and every evaluation of a reproduction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sweep {
    /// A short name (printed in the report).
    pub name: String,
    /// One line on what it is.
    #[serde(default)]
    pub description: String,
    /// The task every run trains and is evaluated on: `avoid` (Table 2; the default) or
    /// `nav` (the paper's navigation extension, Fig. 9).
    #[serde(default, skip_serializing_if = "Task::is_avoid")]
    pub task: Task,
    /// Network variants to train (each trained once per seed).
    pub variants: Vec<Variant>,
    /// Seeds of the training runs.
    pub seeds: Vec<u64>,
    /// Environment steps of every training run.
    pub steps: u64,
    /// The training world: a built-in name, a `.toml` world file or a map_server `.yaml`.
    #[serde(default = "default_world")]
    pub world: String,
    /// Compute device of the training runs (`mdrlat train --device`).
    #[serde(default = "default_device")]
    pub device: String,
    /// The settings every training run starts from (`mdrlat train --preset`): `paper` (the
    /// defaults) or `fast` (mdrlat's own recipe).
    #[serde(default = "default_train_preset")]
    pub train_preset: String,
    /// Settings of every training run, as `mdrlat train --set KEY=VALUE`.
    #[serde(default)]
    pub set: Vec<String>,
    /// How each final model is evaluated.
    pub eval: EvalSpec,
}

/// The evaluation of a sweep: the paper's protocol (SPEC §5) with its sizes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EvalSpec {
    /// Test worlds (the paper's: office, furnished, crowd).
    pub worlds: Vec<String>,
    /// Episodes per run (the paper's 50).
    pub episodes: u32,
    /// Runs per world (the paper's 5).
    pub runs: u32,
    /// Steps an episode must survive (the paper's 300).
    pub max_steps: u32,
    /// Seed of the start poses (the same for every model: paired comparisons).
    #[serde(default)]
    pub seed: u64,
    /// Baselines evaluated beside the trained models: scripted policies (`wander`, ...)
    /// and, in navigation, the classical planner (`planner`, `planner-body`).
    #[serde(default)]
    pub baselines: Vec<String>,
    /// The variant whose model (first seed) gets Figs. 6/7 (obstacle avoidance; in
    /// navigation every method's first model and every baseline get Fig. 9).
    #[serde(default)]
    pub figure_variant: Option<Variant>,
    /// Episodes drawn for Figs. 6/7, or start/goal pairs for Fig. 9 (0: none).
    #[serde(default)]
    pub figures: u32,
    /// Metres an episode must drive to count as a moving success (`mdrlat eval --min-path`).
    #[serde(default = "default_min_path_m")]
    pub min_path_m: f32,
    /// Metres from its start an episode must get to count as a moving success
    /// (`mdrlat eval --min-reach`).
    #[serde(default = "default_min_reach_m")]
    pub min_reach_m: f32,
}

fn default_min_path_m() -> f32 {
    mdrlat_sim::MovingRule::DEFAULT.min_path_m
}

fn default_min_reach_m() -> f32 {
    mdrlat_sim::MovingRule::DEFAULT.min_reach_m
}

fn default_train_preset() -> String {
    "paper".into()
}

fn default_world() -> String {
    "train".into()
}

fn default_device() -> String {
    "cpu".into()
}

impl Sweep {
    /// A built-in preset by name.
    pub fn preset(name: &str) -> Result<Sweep, SweepError> {
        let text = preset_text(name)?;
        Sweep::parse(text, &format!("preset '{name}'"))
    }

    /// Parses and checks a sweep file's text; `source` names it in errors.
    pub fn parse(text: &str, source: &str) -> Result<Sweep, SweepError> {
        let sweep: Sweep = toml::from_str(text).map_err(|e| SweepError::Spec {
            file: source.to_string(),
            problem: e.to_string().trim_end().to_string(),
        })?;
        sweep
            .validate()
            .map_err(|problem| SweepError::Spec { file: source.to_string(), problem })?;
        Ok(sweep)
    }

    /// Reads a sweep file. World files it names by a relative path are taken relative to
    /// the sweep file and stored absolute, so the sweep resumes from any directory.
    pub fn load(path: &std::path::Path) -> Result<Sweep, SweepError> {
        let text = std::fs::read_to_string(path).map_err(|e| SweepError::Io {
            what: format!("cannot read sweep file {}", path.display()),
            source: e,
        })?;
        let mut sweep = Sweep::parse(&text, &path.display().to_string())?;
        let base = std::path::absolute(path)
            .ok()
            .and_then(|p| p.parent().map(std::path::Path::to_path_buf))
            .unwrap_or_default();
        let resolve = |w: &mut String| {
            let is_file = w.contains('/') || w.ends_with(".toml") || w.ends_with(".yaml");
            if is_file && std::path::Path::new(w.as_str()).is_relative() {
                *w = base.join(w.as_str()).display().to_string();
            }
        };
        resolve(&mut sweep.world);
        sweep.eval.worlds.iter_mut().for_each(resolve);
        Ok(sweep)
    }

    /// The sweep as canonical TOML: what `DIR/sweep.toml` holds and reruns compare against.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }

    /// Checks the values (the structure is checked by parsing); the problem names the key.
    pub fn validate(&self) -> Result<(), String> {
        let name_ok = |s: &str| {
            !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c))
        };
        if !name_ok(&self.name) {
            return Err(format!(
                "name '{}': use letters, digits, '-', '_' or '.' (it names folders and Slurm jobs)",
                self.name
            ));
        }
        if self.variants.is_empty() {
            return Err("variants: empty; name at least one of laser-only, depth-only, multi, multi-at, multi-bf, mdrlat".into());
        }
        if let Some(v) = duplicate(&self.variants) {
            return Err(format!("variants: '{v}' is listed twice"));
        }
        if self.seeds.is_empty() {
            return Err("seeds: empty; give at least one seed, e.g. seeds = [0]".into());
        }
        if let Some(s) = duplicate(&self.seeds) {
            return Err(format!("seeds: {s} is listed twice"));
        }
        if self.variants.len() * self.seeds.len() > MAX_TRAIN_JOBS {
            return Err(format!(
                "variants x seeds = {} training runs: at most {MAX_TRAIN_JOBS}",
                self.variants.len() * self.seeds.len()
            ));
        }
        if self.steps == 0 {
            return Err("steps = 0: a training run needs at least 1 step".into());
        }
        if !["paper", "fast"].contains(&self.train_preset.as_str()) {
            return Err(format!(
                "train_preset '{}': expected paper or fast (mdrlat train --preset)",
                self.train_preset
            ));
        }
        if self.world.trim().is_empty() {
            return Err("world: empty".into());
        }
        if self.device.trim().is_empty() {
            return Err("device: empty".into());
        }
        for (i, s) in self.set.iter().enumerate() {
            let Some((key, _)) = s.split_once('=') else {
                return Err(format!("set[{i}] '{s}': expected KEY=VALUE, e.g. train.gamma=0.95"));
            };
            let key = key.trim();
            if key.starts_with("sim.") {
                return Err(format!(
                    "set[{i}] '{s}': simulator settings are not swept (every method is trained and \
                     evaluated in the default simulator, as the paper compares them)"
                ));
            }
            if ["train.variant", "train.seed", "train.total_steps"].contains(&key) {
                return Err(format!(
                    "set[{i}] '{s}': {key} is the sweep's own (variants, seeds, steps)"
                ));
            }
        }
        let e = &self.eval;
        if e.worlds.is_empty() {
            return Err("eval.worlds: empty; the paper's are office, furnished, crowd".into());
        }
        if let Some(w) = duplicate(&e.worlds) {
            return Err(format!("eval.worlds: '{w}' is listed twice"));
        }
        let settings = mdrlat_eval::EvalSettings {
            episodes: e.episodes,
            runs: e.runs,
            max_steps: e.max_steps,
            seed: e.seed,
            moving: mdrlat_sim::MovingRule { min_path_m: e.min_path_m, min_reach_m: e.min_reach_m },
            ..mdrlat_eval::EvalSettings::default()
        };
        settings.validate().map_err(|err| {
            format!(
                "eval: {}",
                err.to_string()
                    .replace("--max-steps", "max_steps")
                    .replace("--min-path", "min_path_m")
                    .replace("--min-reach", "min_reach_m")
                    .replace("--", "")
            )
        })?;
        for b in &e.baselines {
            if MapSource::from_policy_name(b).is_some() {
                if self.task != Task::Nav {
                    return Err(format!(
                        "eval.baselines: '{b}' drives to a goal: it needs task = \"nav\""
                    ));
                }
                continue;
            }
            b.parse::<Scripted>().map_err(|err| {
                format!("eval.baselines: {err}; navigation: {}", MapSource::POLICY_NAMES.join(", "))
            })?;
        }
        if let Some(b) = duplicate(&e.baselines) {
            return Err(format!("eval.baselines: '{b}' is listed twice"));
        }
        if let Some(v) = e.figure_variant
            && !self.variants.contains(&v)
        {
            return Err(format!("eval.figure_variant '{v}': not one of the sweep's variants"));
        }
        if e.figures > 100 {
            return Err(format!("eval.figures = {}: at most 100", e.figures));
        }
        Ok(())
    }

    /// The training runs, in the sweep's order: every seed of the first variant, then the
    /// next variant's.
    pub fn runs(&self) -> Vec<(Variant, u64)> {
        self.variants.iter().flat_map(|&v| self.seeds.iter().map(move |&s| (v, s))).collect()
    }

    /// The keys whose values differ between two sweeps (for "changed under an existing
    /// folder" errors).
    pub fn differences(&self, other: &Sweep) -> Vec<String> {
        let a: toml::Table = toml::from_str(&self.to_toml()).unwrap_or_default();
        let b: toml::Table = toml::from_str(&other.to_toml()).unwrap_or_default();
        let mut out = Vec::new();
        diff_tables("", &a, &b, &mut out);
        out
    }
}

fn diff_tables(prefix: &str, a: &toml::Table, b: &toml::Table, out: &mut Vec<String>) {
    let mut keys: Vec<&String> = a.keys().chain(b.keys()).collect();
    keys.sort();
    keys.dedup();
    for k in keys {
        let path = format!("{prefix}{k}");
        match (a.get(k), b.get(k)) {
            (Some(toml::Value::Table(x)), Some(toml::Value::Table(y))) => {
                diff_tables(&format!("{path}."), x, y, out);
            }
            (x, y) if x != y => {
                let show = |v: Option<&toml::Value>| v.map_or("(absent)".into(), |v| v.to_string());
                out.push(format!("{path}: {} -> {}", show(x), show(y)));
            }
            _ => {}
        }
    }
}

fn duplicate<T: PartialEq + std::fmt::Display>(items: &[T]) -> Option<&T> {
    items.iter().enumerate().find(|(i, x)| items[..*i].contains(x)).map(|(_, x)| x)
}

/// The TOML text of a built-in preset.
pub fn preset_text(name: &str) -> Result<&'static str, SweepError> {
    PRESETS.iter().find(|(n, _)| *n == name).map(|(_, t)| *t).ok_or_else(|| {
        SweepError::UnknownPreset {
            name: name.to_string(),
            known: PRESETS.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", "),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_preset_parses_and_round_trips() {
        for (name, _) in PRESETS {
            let s = Sweep::preset(name).expect(name);
            assert_eq!(s.name, name);
            let again = Sweep::parse(&s.to_toml(), "round trip").expect("canonical parses");
            assert_eq!(again, s);
            assert!(s.differences(&again).is_empty());
        }
        let paper = Sweep::preset("paper").expect("paper");
        assert_eq!((paper.variants.len(), paper.seeds.len(), paper.steps), (6, 5, 400_000));
        assert_eq!((paper.eval.runs, paper.eval.episodes, paper.eval.max_steps), (5, 50, 300));
        assert_eq!(paper.train_preset, "paper");
        let fast = Sweep::preset("fast").expect("fast");
        assert_eq!((fast.variants.len(), fast.seeds.len()), (6, 3));
        assert_eq!((fast.train_preset.as_str(), fast.world.as_str()), ("fast", "train"));
        let mut bad = fast.clone();
        bad.train_preset = "quick".into();
        let e = bad.validate().expect_err("unknown train preset");
        assert!(e.contains("train_preset 'quick'"), "{e}");
    }

    #[test]
    fn bad_sweeps_name_the_key() {
        let base = preset_text("smoke").expect("smoke");
        let bad = |from: &str, to: &str, expect: &str| {
            let text = base.replacen(from, to, 1);
            assert_ne!(text, base, "{from} not in the preset");
            let e = Sweep::parse(&text, "my.toml").expect_err(to).to_string();
            assert!(e.contains("my.toml") && e.contains(expect), "{e}");
        };
        bad("steps = 300", "steps = 0", "steps = 0");
        bad("steps = 300", "stepz = 300", "stepz");
        bad("seeds = [0]", "seeds = []", "seeds");
        bad("seeds = [0]", "seeds = [1, 1]", "listed twice");
        bad("\"mdrlat\"]", "\"mdrlat2\"]", "mdrlat2");
        bad("episodes = 4", "episodes = 0", "episodes");
        bad("[\"wander\"]", "[\"wandr\"]", "wandr");
        bad("figure_variant = \"mdrlat\"", "figure_variant = \"mdrlat\"\nbogus = 1", "bogus");
        bad("\"train.learning_starts=100\"", "\"train.seed=3\"", "train.seed");
        bad("\"train.learning_starts=100\"", "\"sim.laser.noise_std_m=0.1\"", "simulator settings");
        bad("\"train.learning_starts=100\"", "\"train.gamma\"", "KEY=VALUE");
        assert!(
            Sweep::preset("papr")
                .expect_err("unknown")
                .to_string()
                .contains("paper, cpu-small, smoke")
        );
    }

    #[test]
    fn differences_name_each_changed_key() {
        let a = Sweep::preset("smoke").expect("smoke");
        let mut b = a.clone();
        b.steps = 400;
        b.eval.episodes = 9;
        let d = a.differences(&b);
        assert_eq!(d, ["eval.episodes: 4 -> 9", "steps: 300 -> 400"]);
    }
}
