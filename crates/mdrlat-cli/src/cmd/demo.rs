//! `mdrlat demo`: the first thing a new user runs. A seeded episode in a built-in world,
//! rendered to a GIF and pictures, every built-in world drawn, and the simulator benchmark.

use super::bench::{SimArgs, cpu_model, measure};
use super::rollout::{PolicyKind, make_policy};
use super::{ensure_dir, load_world, make_env, px_per_m, snapshot};
use crate::config::Config;
use crate::progress;
use anyhow::{Context, Result};
use mdrlat_geom::Vec2;
use mdrlat_render::{GifWriter, Scene, top_view};
use mdrlat_sim::rollout::{CSV_HEADER, TrajectoryRow};
use std::io::Write;
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
    #[arg(long, value_enum, default_value = "wander")]
    policy: PolicyKind,
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
    let mut env = make_env(world, &config.sim)?;
    let mut policy = make_policy(a.policy, &env, a.seed);
    env.reset(Some(a.seed))?;
    let scale = px_per_m(env.world(), 480.0);
    let mut trail: Vec<Vec2> = vec![env.pose().position()];
    let start = snapshot(
        &env,
        &trail,
        &format!("{}  seed {}  start", env.world().name, a.seed),
        false,
        scale,
    );
    start.save_png(&a.out.join("start.png"))?;
    let gif_path = a.out.join("episode.gif");
    let mut gif = GifWriter::create(&gif_path, start.width, start.height, 20)?;
    gif.add_frame(&start)?;
    let csv_path = a.out.join("trajectory.csv");
    let mut csv = std::io::BufWriter::new(
        std::fs::File::create(&csv_path)
            .with_context(|| format!("cannot create {}", csv_path.display()))?,
    );
    writeln!(csv, "{CSV_HEADER}")?;
    let pb = progress::bar(u64::from(a.steps), "episode");
    let (mut sum, mut last) = (0.0f32, None);
    for _ in 0..a.steps {
        let action = policy.act(env.observation());
        let s = env.step(action)?;
        let row = TrajectoryRow {
            action,
            reward: s.reward,
            terminated: s.terminated,
            truncated: s.truncated,
            info: s.info,
        };
        sum += row.reward;
        writeln!(csv, "{}", row.to_csv())?;
        trail.push(row.info.pose.position());
        let caption = format!(
            "{}  step {}  v {:.2} w {:+.2}  r {:+.2}  sum {:+.1}",
            env.world().name,
            row.info.step,
            row.info.velocity.v,
            row.info.velocity.w,
            row.reward,
            sum
        );
        let frame = snapshot(&env, &trail, &caption, row.terminated, scale);
        gif.add_frame(&frame)?;
        last = Some((row, frame));
        pb.inc(1);
        if row.terminated || row.truncated {
            break;
        }
    }
    pb.finish_and_clear();
    csv.flush()?;
    gif.finish()?;
    let (row, frame) = last.context("the episode took no step (--steps 0?)")?;
    frame.save_png(&a.out.join("end.png"))?;
    let ending = match (row.terminated, row.info.collision) {
        (true, Some(c)) => format!("collision ({c:?})"),
        _ if row.truncated => "time limit".to_string(),
        _ => "step budget".to_string(),
    };
    out!(
        "episode in '{}' (seed {}, {:?} policy): {} steps, reward {:.2}, ended by {}",
        env.world().name,
        a.seed,
        a.policy,
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
        "\nnext: mdrlat render --world office --out office.png | mdrlat observe --world train --pose 3,2,90 | mdrlat --help"
    );
    Ok(())
}
