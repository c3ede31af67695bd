//! `mdrlat demo`: the first thing a new user runs. A seeded episode in a built-in world,
//! rendered to a GIF and pictures, a small success table of the scripted baselines, every
//! built-in world drawn, and the simulator benchmark.

use super::bench::{SimArgs, cpu_model, measure};
use super::rollout::{Recorder, parse_scripted, single_env};
use super::{ensure_dir, load_world, px_per_m};
use crate::config::Config;
use crate::progress;
use anyhow::{Context, Result};
use mdrlat_eval::{EvalSettings, WorldSummary, evaluate_world, summary_markdown};
use mdrlat_render::{Scene, top_view};
use mdrlat_sim::{EpisodeSpec, Scripted};
use std::path::PathBuf;

/// Arguments of `mdrlat demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// World of the episode.
    #[arg(long, default_value = "train")]
    world: String,
    /// Seed of the episode (the default one shows a full 300-step episode; others may end
    /// in a collision: the wanderer is a scripted baseline, not a trained agent).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Most steps of the episode.
    #[arg(long, default_value_t = 300)]
    steps: u32,
    /// Who drives (no trained network yet: a scripted policy).
    #[arg(long, default_value = "wander", value_parser = parse_scripted)]
    policy: Scripted,
    /// Output directory.
    #[arg(long, default_value = "out/demo")]
    out: PathBuf,
    /// Seconds per benchmark measurement (0: skip the benchmark).
    #[arg(long, default_value_t = 1.0)]
    bench_seconds: f64,
}

/// Runs `mdrlat demo`.
pub fn run(a: &Args) -> Result<()> {
    let config = Config::default();
    ensure_dir(&a.out)?;
    let world = load_world(&a.world)?;
    let world_name = world.name.clone();
    let scale = px_per_m(&world, 480.0);
    let mut venv = single_env(world, &config.sim)?;
    let mut policy = a.policy.build(&config.sim, a.seed);
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
        a.policy.name(),
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

    // The measuring instrument of the paper's Table 2, shortened: scripted baselines in an
    // unseen world, the same starts for both.
    let settings =
        EvalSettings { episodes: 10, runs: 2, sim_threads: 0, ..EvalSettings::default() };
    let office = load_world("office")?;
    let mut rows = Vec::new();
    for p in [Scripted::Wander, Scripted::Random] {
        let mut policy = p.build(&config.sim, 0);
        let e = evaluate_world(&office, &config.sim, policy.as_mut(), &settings, &mut |_| {})?;
        rows.push(WorldSummary::new(p.name(), &e, &settings));
    }
    let eval_dir = a.out.join("eval");
    ensure_dir(&eval_dir)?;
    let table = eval_dir.join("summary.md");
    std::fs::write(&table, summary_markdown(&rows))
        .with_context(|| format!("cannot write {}", table.display()))?;
    out!(
        "\nsuccess in 'office' (no collision in {} steps, {} runs x {} episodes; `mdrlat eval` runs the paper's 5 x 50):",
        settings.max_steps,
        settings.runs,
        settings.episodes
    );
    for r in &rows {
        out!("  {:<8} {} %", r.eval, r.success_cell());
    }
    out!("  {}", table.display());

    let worlds_dir = a.out.join("worlds");
    ensure_dir(&worlds_dir)?;
    for name in mdrlat_world::builtin::NAMES {
        let w = load_world(name)?;
        let caption = format!("{}: {}", w.name, w.description);
        let img =
            top_view(&Scene { caption: Some(&caption), ..Scene::new(&w) }, px_per_m(&w, 560.0));
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
