//! `mdrlat demo`: the first thing a new user runs. The shipped trained model (`models/
//! mdrlat-fast`) driving a seeded episode, rendered to a GIF and pictures; the same model
//! evaluated beside the scripted baselines in the three unseen test worlds (moving success
//! first); the paper's pipeline shortened as a labelled check (train MDRLAT a few hundred
//! steps, evaluate, tabulate); every built-in world drawn; and the simulator benchmark.

use super::bench::{SimArgs, cpu_model, measure};
use super::rollout::{Recorder, parse_scripted, single_env};
use super::train::DeviceKind;
use super::{ensure_dir, load_world, px_per_m};
use crate::config::Config;
use crate::progress;
use anyhow::{Context, Result};
use mdrlat_eval::{Agent, EvalObserver, EvalSettings, Output};
use mdrlat_nn::Variant;
use mdrlat_sim::{EpisodeSpec, Scripted, SimConfig};
use mdrlat_sweep::local::{Event, LocalOptions};
use mdrlat_sweep::tables::{Metric, Table2};
use mdrlat_sweep::{EvalSpec, Plan, Sweep};
use mdrlat_train::GreedyPolicy;
use std::path::PathBuf;

/// Arguments of `mdrlat demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// World of the episode (by default office, a test world the shipped model never
    /// trained in).
    #[arg(long, default_value = "office")]
    world: String,
    /// Seed of the episode. The default one shows the shipped model through a full
    /// 300-step episode; it gets through 85 % of office's evaluation episodes, so other seeds
    /// may end in a collision (2 of the seeds 0-5 do: 1 and 3).
    #[arg(long, default_value_t = 2)]
    seed: u64,
    /// Most steps of the episode.
    #[arg(long, default_value_t = 300)]
    steps: u32,
    /// A scripted policy to drive the episode instead of the shipped model (e.g. wander).
    #[arg(long, value_parser = parse_scripted)]
    policy: Option<Scripted>,
    /// The trained model the demo shows and evaluates (default: the repository's
    /// models/mdrlat-fast; "none" skips it).
    #[arg(long, value_name = "MODEL_DIR")]
    model: Option<PathBuf>,
    /// Episodes per test world of the shipped model's comparison (0: skip it).
    #[arg(long, default_value_t = 20)]
    episodes: u32,
    /// Output directory.
    #[arg(long, default_value = "out/demo")]
    out: PathBuf,
    /// Training steps of the pipeline's MDRLAT model (0: skip training and evaluation).
    #[arg(long, default_value_t = 300)]
    train_steps: u64,
    /// Seconds per benchmark measurement (0: skip the benchmark).
    #[arg(long, default_value_t = 1.0)]
    bench_seconds: f64,
}

/// The scripted policies the demo evaluates beside its network: one that games the paper's
/// success by turning in place, the reactive wanderer, and the classical avoider that says
/// how achievable the world is.
const DEMO_BASELINES: [&str; 3] = ["spin", "wander", "avoid"];

/// The shipped model the demo shows, relative to the repository.
const SHIPPED_MODEL: &str = "models/mdrlat-fast";

/// The model to show: `--model`, else the shipped one (from the current folder, or from
/// the repository this binary was built in) when it is there.
fn model_dir(a: &Args) -> Option<PathBuf> {
    match &a.model {
        Some(p) if p.as_os_str() == "none" => None,
        Some(p) => Some(p.clone()),
        None => [
            PathBuf::from(SHIPPED_MODEL),
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..").join(SHIPPED_MODEL),
        ]
        .into_iter()
        .find(|p| p.join("model.safetensors").is_file()),
    }
}

/// The shipped model's greedy policy on all cores, with `sim` drawing the scan it reads.
fn load_model(dir: &std::path::Path, sim: &mut SimConfig) -> Result<GreedyPolicy> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let p = GreedyPolicy::load(dir, &DeviceKind::Cpu.device(), cores)
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("--model {}", dir.display()))?;
    let what = format!("--model {}", dir.display());
    p.fit_sim(sim, &what).map_err(anyhow::Error::msg)?;
    Ok(p.with_forward_batch(Some(super::bench_train::EVAL_FORWARD_BATCH)))
}

/// The shipped model beside `spin`, `wander` and `avoid` in the unseen test worlds, the
/// same starts for all: moving success first.
fn compare(a: &Args, model: &std::path::Path, config: &Config) -> Result<()> {
    let worlds = ["office", "furnished", "crowd"]
        .iter()
        .map(|w| load_world(w))
        .collect::<Result<Vec<_>>>()?;
    let settings = EvalSettings { episodes: a.episodes, runs: 1, ..EvalSettings::default() };
    out!(
        "\nthe shipped model {} beside the scripted baselines, in the test worlds it never trained \
         on ({} episodes each, the same starts for all; `mdrlat eval` runs the paper's 5 x 50):",
        model.display(),
        a.episodes
    );
    out!("  {:<34} {:>22} {:>22} {:>22}", "", "office", "furnished", "crowd");
    out!(
        "  {:<34} {:>22} {:>22} {:>22}",
        "",
        "moving / paper's %",
        "moving / paper's %",
        "moving / paper's %"
    );
    let names = ["model", "spin", "wander", "avoid"];
    let total = (names.len() * worlds.len()) as u64 * u64::from(a.episodes);
    let pb = progress::bar(total, "compare");
    for (k, name) in names.iter().enumerate() {
        let mut sim = config.sim.clone();
        let mut policy: Box<dyn mdrlat_core::Policy> = match *name {
            "model" => Box::new(load_model(model, &mut sim)?),
            other => parse_scripted(other).map_err(anyhow::Error::msg)?.build(&sim, 0),
        };
        let label = policy.name();
        let dir = a.out.join("compare").join(name);
        let out = Output { dir: &dir, overwrite: true, figures: 0 };
        let mut shown = Bar { pb: &pb, done: (k * worlds.len()) as u64 * u64::from(a.episodes) };
        let report = mdrlat_eval::evaluate(
            &worlds,
            &sim,
            &settings,
            Agent::One(policy.as_mut()),
            None,
            &out,
            &mut shown,
        )
        .with_context(|| format!("evaluating {label}"))?;
        let cells: Vec<String> = report
            .worlds
            .iter()
            .map(|w| {
                let s = &w.summary;
                format!("{:>5.0} / {:>3.0}", 100.0 * s.moving_success_mean, 100.0 * s.success_mean)
            })
            .collect();
        let label = if *name == "model" { format!("{} (trained)", model.display()) } else { label };
        pb.suspend(|| {
            out!("  {label:<34} {:>22} {:>22} {:>22}", cells[0], cells[1], cells[2]);
        });
    }
    pb.finish_and_clear();
    out!("  {}/compare/*/summary.md: each policy's table", a.out.display());
    Ok(())
}

/// The comparison's progress bar.
struct Bar<'a> {
    pb: &'a indicatif::ProgressBar,
    done: u64,
}

impl EvalObserver for Bar<'_> {
    fn progress(&mut self, before: usize, p: &mdrlat_eval::Progress<'_>) {
        self.pb.set_position(self.done + (before + p.done) as u64);
    }
}

/// Trains, evaluates and tabulates through a one-variant sweep in `OUT/reproduce`.
fn pipeline(a: &Args) -> Result<()> {
    let smoke = Sweep::preset("smoke")?;
    let sweep = Sweep {
        name: "demo".into(),
        description: format!(
            "MDRLAT trained {} steps, then evaluated with the scripted baselines in office",
            a.train_steps
        ),
        variants: vec![Variant::Mdrlat],
        seeds: vec![0],
        steps: a.train_steps,
        // A pipeline check leaves its weights only: no optimiser state or replay (~200 MB
        // for MDRLAT) that nobody would extend a 300-step run from.
        set: smoke
            .set
            .iter()
            .cloned()
            .chain([
                format!("train.checkpoint_interval={}", a.train_steps + 1),
                "train.final_checkpoint=false".into(),
                // Its weights in half precision: a 300-step check, not a model to ship.
                "train.model_precision=\"f16\"".into(),
            ])
            .collect(),
        eval: EvalSpec {
            worlds: vec!["office".into()],
            episodes: 10,
            runs: 2,
            baselines: DEMO_BASELINES.iter().map(|b| b.to_string()).collect(),
            figure_variant: Some(Variant::Mdrlat),
            figures: 1,
            ..smoke.eval.clone()
        },
        ..smoke
    };
    sweep.validate().map_err(|e| anyhow::anyhow!("demo sweep: {e}"))?;
    let dir = a.out.join("reproduce");
    // The demo's own folder from an earlier demo: start it again.
    if dir.join("sweep.toml").exists() {
        std::fs::remove_dir_all(&dir)
            .with_context(|| format!("cannot clear the earlier demo's {}", dir.display()))?;
    }
    let plan = Plan::new(sweep, &dir);
    let exe = std::env::current_exe().context("cannot find the mdrlat binary's own path")?;
    let opts = LocalOptions {
        jobs: 1,
        cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    out!(
        "\npipeline check: MDRLAT trained {} steps in 'train' (a check that training, evaluation and \
         tables run end to end, not a trained policy), evaluated beside {} in 'office' ({} runs x {} \
         episodes; `mdrlat reproduce --preset paper` runs the paper's whole protocol):",
        a.train_steps,
        DEMO_BASELINES.join(", "),
        plan.sweep.eval.runs,
        plan.sweep.eval.episodes
    );
    let pb = progress::bar(plan.jobs.len() as u64, "pipeline");
    let result = mdrlat_sweep::local::run(&plan, &exe, &opts, |e| {
        if let Event::Finished(id, ok, secs) = e {
            pb.inc(1);
            pb.suspend(|| out!("  {:<8} {id} ({secs:.0} s)", if *ok { "done" } else { "FAILED" }));
        }
    });
    pb.finish_and_clear();
    result?;
    let table = Table2::gather(&plan)?;
    let e = &plan.sweep.eval;
    out!(
        "  moving success = no collision in {} steps, >= {} m driven and >= {} m from the start; \
         success = the paper's (no collision), which turning in place meets",
        e.max_steps,
        e.min_path_m,
        e.min_reach_m
    );
    for c in &table.cells {
        let pct = |m| c.metric_stats(m).map_or("—".into(), |(m, s)| format!("{m:.1} ± {s:.1} %"));
        let path = c.path_mean().map_or("—".into(), |p| format!("{p:.1} m"));
        let label = match &c.method {
            mdrlat_sweep::tables::Method::Variant(v) => {
                format!("{v} ({} steps: pipeline check)", a.train_steps)
            }
            mdrlat_sweep::tables::Method::Baseline(b) => b.clone(),
        };
        out!(
            "  {label:<32} moving success {:<14} success {:<14} driven per episode {path}",
            pct(Metric::Moving),
            pct(Metric::Paper)
        );
    }
    out!("  {0}/table2.md, report.md, fig4.png, eval/mdrlat-s0/figures/", dir.display());
    Ok(())
}

/// Runs `mdrlat demo`.
pub fn run(a: &Args) -> Result<()> {
    let config = Config::default();
    ensure_dir(&a.out)?;
    let world = load_world(&a.world)?;
    let world_name = world.name.clone();
    let scale = px_per_m(&world, 480.0);
    let model = model_dir(a);
    let mut sim = config.sim.clone();
    let mut policy: Box<dyn mdrlat_core::Policy> = match (&a.policy, &model) {
        (Some(s), _) => s.build(&sim, a.seed),
        (None, Some(m)) => Box::new(load_model(m, &mut sim)?),
        (None, None) => {
            out!("(no trained model found at {SHIPPED_MODEL}: the scripted wanderer drives)");
            Scripted::Wander.build(&sim, a.seed)
        }
    };
    let mut venv = single_env(world, &sim)?;
    let gif_path = a.out.join("episode.gif");
    let csv_path = a.out.join("trajectory.csv");
    let mut rec = Recorder::create(&csv_path, Some(&gif_path), scale)?;
    venv.reset_env(0, Some(a.seed), None)?;
    let start_pose = {
        let env = venv.env(0);
        let start_caption = format!("{}  seed {}  start", env.world().name, a.seed);
        rec.frame(&env, &[env.pose().position()], &start_caption, false)?;
        env.pose()
    };
    if let Some(start) = &rec.last_frame {
        start.save_png(&a.out.join("start.png"))?;
    }
    let pb = progress::bar(u64::from(a.steps), "episode");
    let spec = EpisodeSpec { seed: Some(a.seed), pose: Some(start_pose) };
    let outcomes = rec.run(&mut venv, policy.as_mut(), &[spec], a.steps, Some(pb))?;
    if let Some(end) = &rec.last_frame {
        end.save_png(&a.out.join("end.png"))?;
    }
    rec.finish()?;
    let rows = outcomes.first().map(|o| o.rows.as_slice()).unwrap_or_default();
    let row = rows.last().context("the episode took no step (--steps 0?)")?;
    let sum: f32 = rows.iter().map(|r| r.reward).sum();
    let ending = match (row.terminated, row.info.collision) {
        (true, Some(c)) => format!("collision ({c:?})"),
        _ if row.truncated => "time limit".to_string(),
        _ => "step budget".to_string(),
    };
    out!(
        "episode in '{}' (seed {}, {} policy): {} steps, reward {:.2}, ended by {}",
        world_name,
        a.seed,
        policy.name(),
        row.info.step,
        sum,
        ending
    );
    out!(
        "  {}  {}  {}  {}",
        gif_path.display(),
        csv_path.display(),
        a.out.join("start.png").display(),
        a.out.join("end.png").display()
    );

    if let (Some(m), true) = (&model, a.episodes > 0) {
        compare(a, m, &config)?;
    }

    // The paper's pipeline, shortened: train MDRLAT a few hundred steps, evaluate it and
    // the scripted baselines in the unseen `office` world (the same starts for all), and
    // write the table beside the paper's, through the same sweep `mdrlat reproduce` runs.
    if a.train_steps > 0 {
        pipeline(a)?;
    }

    let worlds_dir = a.out.join("worlds");
    ensure_dir(&worlds_dir)?;
    for name in mdrlat_world::builtin::NAMES {
        let w = load_world(name)?;
        let img = mdrlat_render::world_picture(&w, px_per_m(&w, 560.0));
        img.save_png(&worlds_dir.join(format!("{name}.png")))?;
    }
    out!("  {}/*.png: every built-in world from above", worlds_dir.display());

    if a.bench_seconds > 0.0 {
        out!("\nsimulator throughput (cpu: {}):", cpu_model());
        let args = SimArgs::quick(a.bench_seconds);
        let mut lines = Vec::new();
        measure(&args, &config.sim, |t| {
            out!(
                "  {:<8} {:>3} env(s) on {} thread(s): {:>8.0} steps/s",
                t.world,
                t.envs,
                t.threads,
                t.steps_per_s()
            );
            lines.push(format!(
                "{{\"bench\":\"sim\",\"world\":\"{}\",\"envs\":{},\"threads\":{},\"steps_per_s\":{:.1}}}",
                t.world,
                t.envs,
                t.threads,
                t.steps_per_s()
            ));
        })?;
        let path = a.out.join("bench.jsonl");
        std::fs::write(&path, lines.join("\n") + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    out!(
        "\nnext: mdrlat render --world office --out office.png | mdrlat observe --world train --pose 3,2,90\n      mdrlat train --variant laser-only --steps 5000 --out runs/quick | mdrlat eval --checkpoint runs/quick --out eval/quick | mdrlat --help"
    );
    Ok(())
}
