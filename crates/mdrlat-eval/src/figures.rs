//! Paper Figs. 6 and 7: an episode as a strip of six top views at evenly spaced steps, each
//! captioned with that step's (v, ω) command, the angular-velocity command of every step
//! below it, and a top view of the whole trajectory.
//!
//! Paper Fig. 9 ([`draw_navigation`]): several navigation episodes' trajectories on one map.
//!
//! An episode is redrawn by replaying its recorded commands from its seed in a fresh
//! environment — the simulator is a function of (seed, actions), so the replay is the
//! episode, pedestrians and all; a replay that ends differently is an error, not a picture.

use crate::EvalError;
use crate::protocol::{EpisodeRecord, WorldEval, collision_kind};
use mdrlat_core::{DEPTH_COLS, DEPTH_ROWS};
use mdrlat_geom::Vec2;
use mdrlat_render::{
    Chart, Image, LaserRays, RobotMark, Scene, Series, depth_view, line_chart, map_frame,
    side_by_side, stacked, titled, top_view,
};
use mdrlat_sim::rollout::TrajectoryRow;
use mdrlat_sim::{
    Env, EpisodeSpec, Observer, ReplayPolicy, RunOptions, SimConfig, StaticScene, VecEnv,
    run_episodes,
};
use mdrlat_world::World;
use std::sync::Arc;

/// A scale that makes the longer side of the world about `target_px` pixels.
pub fn px_per_m(world: &World, target_px: f32) -> f32 {
    let s = world.bounds.size();
    (target_px / s.x.max(s.y)).clamp(4.0, 120.0)
}

/// The environment's state from above (robot, rays, pedestrians, trail) with the current
/// depth image beside it.
pub fn snapshot(env: &Env, trail: &[Vec2], caption: &str, collided: bool, scale: f32) -> Image {
    let peds = env.pedestrian_discs();
    let obs = env.observation();
    let laser = env.laser();
    let scene = Scene {
        robot: Some(RobotMark { pose: env.pose(), radius: env.config().robot.radius_m, collided }),
        pedestrians: &peds,
        laser: Some(LaserRays {
            origin: env.pose(),
            angles: laser.angles(),
            ranges: obs.laser.latest(),
            max_range: laser.config().max_range_m,
        }),
        trail,
        goal: env.goal(),
        caption: Some(caption),
        ..Scene::new(env.world())
    };
    let top = top_view(&scene, scale);
    // The depth image as tall as the map beside it allows (whole pixels per depth pixel),
    // under its title.
    let text = if top.height >= 400 { 2 } else { 1 };
    let depth_scale = (top.height.saturating_sub(40 * text) / DEPTH_ROWS as u32).clamp(1, 3);
    let depth = depth_view(
        obs.depth.latest(),
        DEPTH_ROWS,
        DEPTH_COLS,
        env.depth_camera().config().max_range_m,
        depth_scale,
    );
    let title = format!("depth camera, {DEPTH_COLS}x{DEPTH_ROWS}, metres");
    side_by_side(&[&top, &titled(&depth, &title, text)], 12)
}

/// Top views in a strip.
pub const PANELS: usize = 6;

/// Why an episode was picked for a figure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pick {
    /// Among the longest collision-free drives.
    LongestSuccess,
    /// Among those with the most steps turning on the spot (a dead end, a tight corner).
    DeadEnd,
    /// Among the longest episodes (when too few succeeded).
    Longest,
}

impl Pick {
    /// A short label for captions and file names.
    pub fn label(self) -> &'static str {
        match self {
            Pick::LongestSuccess => "longest success",
            Pick::DeadEnd => "dead end",
            Pick::Longest => "longest episode",
        }
    }
}

/// A "dead end" episode must have driven at least this far (one that spun on the spot for
/// 300 steps counts as a success by the paper's definition, but shows nothing).
const DEAD_END_MIN_PATH_M: f32 = 3.0;

/// Steps of an episode commanded to turn on the spot (v = 0).
fn in_place_steps(r: &EpisodeRecord) -> usize {
    r.actions.iter().filter(|a| a.command().v == 0.0).count()
}

/// Picks up to `k` distinct episodes worth a picture, `(world index, record index, why)`:
/// alternately the successful episodes that drove farthest and those that turned on the
/// spot most while still driving 3 m or more (successes first); ties go to the earlier
/// episode.
pub fn pick_episodes(worlds: &[&WorldEval], k: usize) -> Vec<(usize, usize, Pick)> {
    let all: Vec<(usize, usize, &EpisodeRecord)> = worlds
        .iter()
        .enumerate()
        .flat_map(|(w, we)| we.records.iter().enumerate().map(move |(i, r)| (w, i, r)))
        .collect();
    let mut by_path: Vec<&(usize, usize, &EpisodeRecord)> =
        all.iter().filter(|(_, _, r)| r.success()).collect();
    by_path.sort_by(|a, b| b.2.path_m.total_cmp(&a.2.path_m));
    // A dead end is turned out of, not sat in: only episodes that also drove somewhere.
    let mut by_turns: Vec<&(usize, usize, &EpisodeRecord)> = all
        .iter()
        .filter(|(_, _, r)| in_place_steps(r) > 0 && r.path_m >= DEAD_END_MIN_PATH_M)
        .collect();
    by_turns.sort_by_key(|(_, _, r)| (!r.success(), std::cmp::Reverse(in_place_steps(r))));
    let mut by_length: Vec<&(usize, usize, &EpisodeRecord)> = all.iter().collect();
    by_length.sort_by_key(|(_, _, r)| std::cmp::Reverse(r.steps));
    let mut lists = [
        (by_path.into_iter(), Pick::LongestSuccess),
        (by_turns.into_iter(), Pick::DeadEnd),
        (by_length.into_iter(), Pick::Longest),
    ];
    let mut out: Vec<(usize, usize, Pick)> = Vec::new();
    let mut turn = 0usize;
    let mut exhausted = [false; 3];
    while out.len() < k.min(all.len()) && !exhausted.iter().all(|e| *e) {
        // Longest successes and dead ends alternate; the longest episodes fill in.
        let l = if exhausted[0] && exhausted[1] { 2 } else { turn % 2 };
        turn += 1;
        if exhausted[l] {
            continue;
        }
        let (list, why) = &mut lists[l];
        match list.find(|(w, i, _)| !out.iter().any(|(w2, i2, _)| w2 == w && i2 == i)) {
            Some(&(w, i, _)) => out.push((w, i, *why)),
            None => exhausted[l] = true,
        }
    }
    out
}

/// What the replay keeps: the environment at the strip's steps, and every step.
struct Capture {
    at: Vec<u32>,
    frames: Vec<(Env, TrajectoryRow)>,
    rows: Vec<TrajectoryRow>,
}

impl Observer for Capture {
    fn wants_steps(&self) -> bool {
        true
    }
    fn on_step(
        &mut self,
        _episode: usize,
        env: &Env,
        row: &TrajectoryRow,
    ) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
        self.rows.push(*row);
        if self.at.contains(&row.info.step) {
            self.frames.push((env.clone(), *row));
        }
        Ok(())
    }
}

/// The steps a strip shows: six evenly spaced from the first to the last.
pub fn strip_steps(steps: u32) -> Vec<u32> {
    let n = PANELS as u32;
    let mut at: Vec<u32> = (0..n)
        .map(|i| {
            1 + ((u64::from(i) * u64::from(steps.saturating_sub(1))) / u64::from(n - 1)) as u32
        })
        .collect();
    at.dedup();
    at
}

/// The two pictures of one episode.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeFigure {
    /// Six top views with their commands, and the angular-velocity command below (Figs. 6/7).
    pub strip: Image,
    /// The whole trajectory from above.
    pub trajectory: Image,
}

const PAPER: [u8; 4] = [255, 255, 255, 255];
const INK: [u8; 4] = [20, 20, 20, 255];

/// A picture with lines of text under it.
fn captioned(img: &Image, text: &str) -> Image {
    let h = mdrlat_render::font::text_height(text, 2) + 10;
    let mut out = img.resized_canvas(img.width, img.height + h, PAPER);
    out.draw_text(4, img.height as i32 + 5, text, 2, INK);
    out
}

/// Replays `record` from its seed and commands, keeping the environment at the steps `at`
/// and every step's row.
///
/// # Errors
/// The replay did not end as the recorded episode did.
fn replay(
    world: &World,
    sim: &SimConfig,
    record: &EpisodeRecord,
    at: Vec<u32>,
) -> Result<Capture, EvalError> {
    let scene = Arc::new(StaticScene::new(Arc::new(world.clone()), sim));
    let mut venv = VecEnv::new(scene, sim.clone(), 1, 1)?;
    let mut replay =
        ReplayPolicy::with_commands(vec![record.actions.clone()], vec![record.commands.clone()]);
    let mut capture = Capture { at, frames: Vec::new(), rows: Vec::new() };
    let spec = EpisodeSpec { seed: Some(record.seed), pose: None };
    let options = RunOptions { max_steps: record.steps, record_rows: false };
    let outcome = run_episodes(&mut venv, &mut replay, &[spec], &options, &mut capture)?
        .pop()
        .ok_or_else(|| EvalError::Replay("the replay ran no episode".into()))?;
    if outcome.steps != record.steps || outcome.collision != record.collision {
        return Err(EvalError::Replay(format!(
            "{} run {} episode {} (seed {}): recorded {} steps ({:?}), replayed {} ({:?})",
            record.world,
            record.run,
            record.episode,
            record.seed,
            record.steps,
            record.collision,
            outcome.steps,
            outcome.collision
        )));
    }
    Ok(capture)
}

/// Paper Fig. 9: the trajectories of several navigation episodes of one method on one top
/// view of `world`, each start ringed and each goal marked, captioned with how many reached
/// their goal. Every episode is replayed from its record.
///
/// # Errors
/// A replay did not end as its record did.
pub fn draw_navigation(
    world: &World,
    sim: &SimConfig,
    records: &[&EpisodeRecord],
    method: &str,
) -> Result<Image, EvalError> {
    let (mut trail, mut goals) = (Vec::new(), Vec::new());
    for r in records {
        let capture = replay(world, sim, r, Vec::new())?;
        trail.push(r.start.position());
        trail.extend(capture.rows.iter().map(|row| row.info.pose.position()));
        trail.push(Vec2::new(f32::NAN, f32::NAN));
        goals.extend(r.goal);
    }
    let reached = records.iter().filter(|r| r.reached_goal).count();
    let collided = records.iter().filter(|r| r.collision.is_some()).count();
    let caption = format!(
        "{method} in {}: {reached} of {} goals reached, {collided} collisions, {} out of time \
         (rings: starts; squares: goals)",
        world.name,
        records.len(),
        records.len() - reached - collided
    );
    let scene =
        Scene { trail: &trail, goals: &goals, caption: Some(&caption), ..Scene::new(world) };
    Ok(top_view(
        &scene,
        (640.0 / world.bounds.size().x.max(world.bounds.size().y)).clamp(4.0, 120.0),
    ))
}

/// Steps of approach drawn before each collision in [`draw_collisions`] (3 s at 0.2 s a
/// step).
pub const COLLISION_TAIL_STEPS: usize = 15;

/// Where a policy collides in `world`: every episode of `records` that ended in a collision,
/// replayed from its record, drawn on one top view as the robot where it ended (red) with
/// its last [`COLLISION_TAIL_STEPS`] steps (a ring where they began), captioned with the
/// collisions by kind and the obstacles the bumper hit most. Failures that cluster at one
/// doorway or one piece of furniture show at a glance.
///
/// # Errors
/// A replay did not end as its record did.
pub fn draw_collisions(
    world: &World,
    sim: &SimConfig,
    records: &[EpisodeRecord],
    method: &str,
) -> Result<Image, EvalError> {
    let crashed: Vec<&EpisodeRecord> = records.iter().filter(|r| r.collision.is_some()).collect();
    let (mut trail, mut robots) = (Vec::new(), Vec::new());
    let mut kinds = std::collections::BTreeMap::<&str, usize>::new();
    for r in &crashed {
        let capture = replay(world, sim, r, Vec::new())?;
        let poses: Vec<_> =
            std::iter::once(r.start).chain(capture.rows.iter().map(|row| row.info.pose)).collect();
        let tail = &poses[poses.len().saturating_sub(COLLISION_TAIL_STEPS + 1)..];
        trail.extend(tail.iter().map(|p| p.position()));
        trail.push(Vec2::new(f32::NAN, f32::NAN));
        if let Some(&pose) = tail.last() {
            robots.push(RobotMark { pose, radius: sim.robot.radius_m, collided: true });
        }
        if let Some(c) = &r.collision {
            *kinds.entry(collision_kind(c)).or_default() += 1;
        }
    }
    let by_kind: Vec<String> = kinds.iter().map(|(k, n)| format!("{n} {k}")).collect();
    let most: Vec<String> = crate::report::bumper_hits(records)
        .iter()
        .take(4)
        .map(|(h, n)| format!("{h} {n}"))
        .collect();
    let mut caption = format!(
        "{method} in {}: {} collisions in {} episodes",
        world.name,
        crashed.len(),
        records.len()
    );
    if !by_kind.is_empty() {
        caption.push_str(&format!(" ({})", by_kind.join(", ")));
    }
    if !most.is_empty() {
        caption.push_str(&format!("; the bumper hit {}", most.join(", ")));
    }
    caption.push_str(&format!(
        ". Each robot is drawn where its episode ended, with its last {:.0} s (ring: where \
         they began).",
        COLLISION_TAIL_STEPS as f32 * sim.dt_s
    ));
    let scene =
        Scene { trail: &trail, robots: &robots, caption: Some(&caption), ..Scene::new(world) };
    Ok(top_view(&scene, px_per_m(world, 640.0)))
}

/// Draws `record` (an episode of `world` evaluated with `sim`, the evaluation's settings:
/// see [`crate::eval_sim_config`]), explaining why it was picked.
///
/// # Errors
/// The replay did not end as the recorded episode did (the simulator or settings changed).
pub fn draw_episode(
    world: &World,
    sim: &SimConfig,
    record: &EpisodeRecord,
    why: Pick,
) -> Result<EpisodeFigure, EvalError> {
    let capture = replay(world, sim, record, strip_steps(record.steps))?;
    let trail: Vec<Vec2> = std::iter::once(record.start.position())
        .chain(capture.rows.iter().map(|r| r.info.pose.position()))
        .collect();

    // The region the robot moved in, with a margin, at ~320 px on its longer side.
    let (mut lo, mut hi) = (trail[0], trail[0]);
    for p in &trail {
        lo = Vec2::new(lo.x.min(p.x), lo.y.min(p.y));
        hi = Vec2::new(hi.x.max(p.x), hi.y.max(p.y));
    }
    let b = world.bounds;
    let margin = 1.2f32;
    let (lo, hi) = (
        Vec2::new((lo.x - margin).max(b.min.x), (lo.y - margin).max(b.min.y)),
        Vec2::new((hi.x + margin).min(b.max.x), (hi.y + margin).min(b.max.y)),
    );
    let side = (hi.x - lo.x).max(hi.y - lo.y).max(3.0);
    let scale = (320.0 / side).clamp(8.0, 120.0);
    let frame = map_frame(world, scale);
    let (x0, y0) = frame.to_px(Vec2::new(lo.x, hi.y));
    let (x1, y1) = frame.to_px(Vec2::new(hi.x, lo.y));
    let (cx, cy) = (x0.floor().max(0.0) as u32, y0.floor().max(0.0) as u32);
    let (cw, ch) = ((x1 - x0).ceil() as u32 + 1, (y1 - y0).ceil() as u32 + 1);

    let mut panels = Vec::new();
    for (env, row) in &capture.frames {
        let upto = (row.info.step as usize + 1).min(trail.len());
        let peds = env.pedestrian_discs();
        let top = top_view(
            &Scene {
                robot: Some(RobotMark {
                    pose: env.pose(),
                    radius: sim.robot.radius_m,
                    collided: row.info.collision.is_some(),
                }),
                pedestrians: &peds,
                trail: &trail[..upto],
                goal: record.goal,
                ..Scene::new(world)
            },
            scale,
        );
        let c = row.info.command;
        let text = format!("step {}\nv {:.2}  w {:+.2}", row.info.step, c.v, c.w);
        panels.push(captioned(&top.crop(cx, cy, cw, ch), &text));
    }
    let refs: Vec<&Image> = panels.iter().collect();
    let strip = side_by_side(&refs, 8);
    let series = vec![
        Series {
            label: "w command".into(),
            points: capture.rows.iter().map(|r| (r.info.step as f32, r.info.command.w)).collect(),
            band: Vec::new(),
        },
        Series {
            label: "w measured".into(),
            points: capture.rows.iter().map(|r| (r.info.step as f32, r.info.velocity.w)).collect(),
            band: Vec::new(),
        },
    ];
    let title = format!(
        "{} run {} episode {}: angular velocity over the episode",
        record.world, record.run, record.episode
    );
    let chart = line_chart(
        &Chart {
            title: &title,
            x_label: "step (v in m/s, w in rad/s above)",
            y_label: "w (rad/s)",
            series: &series,
        },
        strip.width.max(600),
        300,
    );
    let ending = match &record.collision {
        None if record.reached_goal => format!("goal reached in {} steps", record.steps),
        None if record.goal.is_some() => format!("goal not reached in {} steps", record.steps),
        None => format!("no collision in {} steps", record.steps),
        Some(c) => format!("{} collision at step {}", collision_kind(c), record.steps),
    };
    let headline = format!(
        "{} run {} episode {} (seed {}), {}: {}, {:.1} m driven",
        record.world,
        record.run,
        record.episode,
        record.seed,
        why.label(),
        ending,
        record.path_m
    );
    // The headline wrapped to the strip's width at spaces (a narrow strip, as a small
    // world's crop gives, would cut one long line at its right edge).
    let width = strip.width.max(chart.width);
    let char_w = mdrlat_render::font::text_width("m", 2).max(1);
    let wrapped = mdrlat_render::font::wrap(&headline, (width.saturating_sub(8) / char_w) as usize);
    let head = captioned(&Image::new(width, 1, PAPER), &wrapped.join("\n"));
    let strip = stacked(&[&head, &strip, &chart], 6);

    let last_pose = capture.rows.last().map_or(record.start, |r| r.info.pose);
    let whole = top_view(
        &Scene {
            robot: Some(RobotMark {
                pose: last_pose,
                radius: sim.robot.radius_m,
                collided: record.collision.is_some(),
            }),
            trail: &trail,
            goal: record.goal,
            caption: Some(&headline),
            ..Scene::new(world)
        },
        (560.0 / world.bounds.size().x.max(world.bounds.size().y)).clamp(4.0, 120.0),
    );
    Ok(EpisodeFigure { strip, trajectory: whole })
}
