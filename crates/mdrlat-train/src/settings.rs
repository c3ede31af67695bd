//! The configuration tree: one TOML file with a section per room, defaults for every key;
//! the presets under it and the overrides over it.

use crate::config::TrainConfig;
use mdrlat_sim::SimConfig;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A configuration that cannot be read, parsed or used, named by where it came from.
#[derive(Debug, thiserror::Error)]
#[error("{source_name}: {problem}")]
pub struct ConfigError {
    /// The file, `--set 'KEY=VALUE'`, `defaults` or `preset fast`.
    pub source_name: String,
    /// What is wrong.
    pub problem: String,
}

impl ConfigError {
    fn new(source_name: impl Into<String>, problem: impl std::fmt::Display) -> Self {
        ConfigError {
            source_name: source_name.into(),
            problem: problem.to_string().trim_end().into(),
        }
    }
}

type Result<T> = std::result::Result<T, ConfigError>;

/// The commented default configuration, embedded from `configs/default.toml`.
pub const DEFAULT_TOML: &str = include_str!("../../../configs/default.toml");

/// The `fast` preset's changes to the defaults, embedded from `configs/fast.toml`.
pub const FAST_TOML: &str = include_str!("../../../configs/fast.toml");

/// A starting point for a run's settings, below `--config` and `--set`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// The paper's settings (section 3.1, Algorithm 1): the defaults.
    #[default]
    Paper,
    /// mdrlat's own recipe (`configs/fast.toml`): several environments, a random warm-up, a
    /// larger replay, Polyak averaging, and the scan with the camera's memory.
    Fast,
}

impl std::str::FromStr for Preset {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "paper" => Ok(Preset::Paper),
            "fast" => Ok(Preset::Fast),
            _ => Err(format!("unknown preset '{s}': expected paper or fast")),
        }
    }
}

impl std::fmt::Display for Preset {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Preset::Paper => "paper",
            Preset::Fast => "fast",
        })
    }
}

impl Preset {
    /// The preset's settings over the defaults, as a TOML tree.
    fn table(self) -> toml::Table {
        match self {
            Preset::Paper => toml::Table::new(),
            Preset::Fast => toml::from_str(FAST_TOML).expect("configs/fast.toml parses (tested)"),
        }
    }

    /// Its training worlds when `--world` is not given, for `task`.
    pub fn default_world(self, task: mdrlat_sim::config::Task) -> &'static str {
        match (self, task) {
            (_, mdrlat_sim::config::Task::Nav) => "nav-train",
            (Preset::Paper, _) => "train",
            (Preset::Fast, _) => "train",
        }
    }
}

/// Every setting of mdrlat.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// The simulator.
    pub sim: SimConfig,
    /// Training.
    pub train: TrainConfig,
}

impl Config {
    /// Reads a config file (missing keys keep their defaults) and validates it.
    ///
    /// # Errors
    /// The file cannot be read or parsed, or a setting is invalid.
    pub fn load(path: &Path) -> Result<Config> {
        Self::resolve(Some(path), &[])
    }

    /// A run's resolved `config.toml`, as the version that wrote it meant it: a run writes
    /// every setting, so a key it lacks is one added since, and it gets the value that
    /// reproduces the simulator the run started in (walkers that ignore the robot, starts
    /// without the hidden-obstacle clearance) and the learner it started with (one Adam for
    /// both losses), never today's default. A resumed run goes on as it began.
    pub fn load_run(path: &Path) -> Result<Config> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path)
            .map_err(|e| ConfigError::new(&name, format!("cannot read it: {e}")))?;
        let mut tree: toml::Table =
            toml::from_str(&text).map_err(|e| ConfigError::new(&name, e))?;
        if let Some(sim) = tree.get_mut("sim").and_then(toml::Value::as_table_mut) {
            for (key, before) in LEGACY_SIM {
                sim.entry(key).or_insert(toml::Value::Float(before));
            }
        }
        if let Some(train) = tree.get_mut("train").and_then(toml::Value::as_table_mut) {
            for (key, before) in LEGACY_TRAIN {
                train.entry(key).or_insert(toml::Value::String(before.into()));
            }
        }
        let config: Config =
            tree.try_into().map_err(|e: toml::de::Error| ConfigError::new(&name, e))?;
        config.validate(&name)?;
        Ok(config)
    }

    /// The default config, or the one in `path` when given.
    pub fn load_or_default(path: Option<&Path>) -> Result<Config> {
        Self::resolve(path, &[])
    }

    /// The config of `path` (or the defaults) with `--set key=value` overrides applied
    /// (dotted keys, TOML values: `train.gamma=0.95`, `train.variant="laser-only"`), then
    /// validated.
    pub fn resolve(path: Option<&Path>, sets: &[String]) -> Result<Config> {
        Self::resolve_preset(Preset::Paper, path, sets)
    }

    /// [`Config::resolve`] over a preset: the preset's settings, then the file's, then the
    /// `--set` overrides.
    pub fn resolve_preset(preset: Preset, path: Option<&Path>, sets: &[String]) -> Result<Config> {
        let mut tree = preset.table();
        let source = match path {
            Some(p) => {
                let name = p.display().to_string();
                let text = std::fs::read_to_string(p)
                    .map_err(|e| ConfigError::new(&name, format!("cannot read it: {e}")))?;
                let file: toml::Table =
                    toml::from_str(&text).map_err(|e| ConfigError::new(&name, e))?;
                merge(&mut tree, file);
                name
            }
            None if preset == Preset::Paper => "defaults".to_string(),
            None => format!("preset {preset}"),
        };
        for set in sets {
            apply_set(&mut tree, set)?;
        }
        let config: Config =
            tree.try_into().map_err(|e: toml::de::Error| ConfigError::new(&source, e))?;
        config.validate(&source)?;
        Ok(config)
    }

    /// Both sections' checks, errors named by `source`.
    pub fn validate(&self, source: &str) -> Result<()> {
        self.sim.validate().map_err(|e| ConfigError::new(source, e))?;
        self.train.validate().map_err(|e| ConfigError::new(source, e))?;
        Ok(())
    }

    /// The resolved configuration as a run folder's `config.toml` holds it: every setting,
    /// defaults included.
    pub fn to_toml(&self) -> String {
        let resolved = toml::to_string(self).unwrap_or_else(|e| unreachable!("plain data: {e}"));
        format!(
            "# Resolved configuration of this run: every setting, defaults included.\n\n{resolved}"
        )
    }
}

/// Simulator settings added after runs were first written, with the value that gives the
/// simulator as it was before them (see [`Config::load_run`]).
const LEGACY_SIM: [(&str, f64); 2] =
    [("pedestrian_yield_m", -1.0), ("spawn_hidden_clearance_m", 0.0)];

/// Training settings added after runs were first written, with the value that trains as
/// before them (see [`Config::load_run`]): one Adam for both losses.
const LEGACY_TRAIN: [(&str, &str); 1] = [("aux_optimizer", "joint")];

/// Puts every key of `over` into `base`, section by section.
fn merge(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

/// Applies one `dotted.key=value` override to a TOML tree.
fn apply_set(tree: &mut toml::Table, set: &str) -> Result<()> {
    let name = format!("--set '{set}'");
    let (key, value) = set
        .split_once('=')
        .ok_or_else(|| ConfigError::new(&name, "expected KEY=VALUE, e.g. train.gamma=0.95"))?;
    let parsed: toml::Table = toml::from_str(&format!("v = {}", value.trim()))
        .or_else(|_| toml::from_str(&format!("v = \"{}\"", value.trim())))
        .map_err(|e| ConfigError::new(&name, format!("bad value: {e}")))?;
    let value = parsed.get("v").cloned().ok_or_else(|| ConfigError::new(&name, "empty value"))?;
    let parts: Vec<&str> = key.trim().split('.').collect();
    let mut node = tree;
    for part in &parts[..parts.len() - 1] {
        let entry =
            node.entry(part.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
        node = entry
            .as_table_mut()
            .ok_or_else(|| ConfigError::new(&name, format!("'{part}' is not a section")))?;
    }
    node.insert(parts[parts.len() - 1].to_string(), value);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_commented_default_file_is_the_default() {
        let parsed: Config = toml::from_str(DEFAULT_TOML).expect("default.toml parses");
        assert_eq!(parsed, Config::default(), "configs/default.toml drifted from the code");
    }

    #[test]
    fn the_fast_preset_changes_training_only_and_a_file_and_sets_go_over_it() {
        let fast = Config::resolve_preset(Preset::Fast, None, &[]).expect("fast resolves");
        // Of the simulator, fast changes the scan the networks read, nothing else.
        assert_eq!(fast.sim.laser.depth_memory_frames, 8);
        let mut plain = fast.sim.clone();
        plain.laser.depth_memory_frames = 0;
        assert_eq!(plain, Config::default().sim, "fast changes no other simulator setting");
        assert_ne!(fast.train, Config::default().train);
        assert!(fast.train.envs > 1);
        // The budget every fast-preset model was trained with, not the paper's 400k.
        assert_eq!(fast.train.total_steps, 100_000);
        let dir = std::env::temp_dir().join(format!("mdrlat-preset-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("c.toml");
        std::fs::write(&path, "[train]\nenvs = 4\n").expect("write");
        let c = Config::resolve_preset(Preset::Fast, Some(&path), &["train.seed=3".into()])
            .expect("resolves");
        assert_eq!((c.train.envs, c.train.seed), (4, 3));
        assert_eq!(c.train.replay_capacity, fast.train.replay_capacity, "the preset's other keys");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn command_line_sets_override_and_are_checked() {
        let sets = ["train.gamma=0.9".to_string(), "train.variant=laser-only".to_string()];
        let c = Config::resolve(None, &sets).expect("valid");
        assert_eq!(c.train.gamma, 0.9);
        assert_eq!(c.train.variant, mdrlat_nn::Variant::LaserOnly);
        let e = Config::resolve(None, &["train.gama=0.9".to_string()]).expect_err("typo");
        assert!(format!("{e:#}").contains("gama"), "{e:#}");
        let e = Config::resolve(None, &["train.batch_size=100000".to_string()]).expect_err("batch");
        assert!(format!("{e:#}").contains("train.batch_size"), "{e:#}");
        let e = Config::resolve(None, &["train.variant=mdrlat2".to_string()]).expect_err("variant");
        assert!(format!("{e:#}").contains("mdrlat2"), "{e:#}");
    }

    #[test]
    fn a_run_written_before_a_setting_existed_resumes_in_its_old_simulator() {
        let dir = std::env::temp_dir().join(format!("mdrlat-load-run-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("config.toml");
        // Today's run: every key written, kept as it is.
        std::fs::write(&path, toml::to_string(&Config::default()).expect("toml")).expect("write");
        assert_eq!(Config::load_run(&path).expect("loads"), Config::default());
        // A run of an older mdrlat: its config lacks the walkers' yield and the hidden
        // clearance, which resume as they were (walkers ignore the robot, no clearance).
        let mut old: toml::Table =
            toml::from_str(&toml::to_string(&Config::default()).expect("toml")).expect("tree");
        let sim = old.get_mut("sim").and_then(toml::Value::as_table_mut).expect("sim");
        sim.remove("pedestrian_yield_m");
        sim.remove("spawn_hidden_clearance_m");
        let train = old.get_mut("train").and_then(toml::Value::as_table_mut).expect("train");
        train.remove("aux_optimizer");
        std::fs::write(&path, toml::to_string(&old).expect("toml")).expect("write");
        let c = Config::load_run(&path).expect("loads");
        assert_eq!((c.sim.pedestrian_yield_m, c.sim.spawn_hidden_clearance_m), (-1.0, 0.0));
        assert_eq!(c.train.aux_optimizer, crate::AuxOptimizer::Joint, "one Adam, as then");
        let plain = Config::load(&path).expect("loads");
        assert_eq!(plain.sim.pedestrian_yield_m, 0.3, "plain loads take today's defaults");
        assert_eq!(plain.train.aux_optimizer, crate::AuxOptimizer::Separate);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn unknown_keys_and_bad_values_are_errors() {
        assert!(toml::from_str::<Config>("[sim]\nbogus = 1\n").is_err());
        assert!(toml::from_str::<Config>("[sim.laser]\nmax_range = 3.0\n").is_err());
        let c: Config = toml::from_str("[sim.laser]\nmax_range_m = -1.0\n").expect("parses");
        let e = c.sim.validate().expect_err("negative range").to_string();
        assert!(e.contains("laser.max_range_m") && e.contains("-1"), "{e}");
    }
}
