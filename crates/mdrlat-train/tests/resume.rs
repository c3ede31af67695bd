//! Checkpoints resume exactly: a run interrupted after its step-200 checkpoint (even in the
//! middle of later steps) and resumed ends with the same weights, metrics and evaluations as
//! the run that was never interrupted. Bad checkpoints are clear errors.

mod common;
use common::train;

use mdrlat_nn::Variant;
use mdrlat_nn::burn::prelude::Device;
use mdrlat_sim::SimConfig;
use mdrlat_train::{Inputs, TrainConfig};
use std::path::{Path, PathBuf};

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("mdrlat-resume-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("dir");
    d
}

fn config(variant: Variant, steps: u64) -> TrainConfig {
    TrainConfig {
        variant,
        total_steps: steps,
        seed: 4,
        learning_starts: 50,
        target_update_interval: 70,
        eval_interval: 150,
        eval_episodes: 1,
        checkpoint_interval: 100,
        replay_capacity: 120,
        ..TrainConfig::default()
    }
}

fn sim() -> SimConfig {
    SimConfig { max_episode_steps: 60, ..SimConfig::default() }
}

fn world() -> mdrlat_world::World {
    mdrlat_world::builtin::get("example").expect("builtin").expect("valid")
}

/// A laser-only run of [`config`] in `world`.
fn laser_only(
    world: mdrlat_world::World,
    sim: &SimConfig,
    steps: u64,
    dir: &Path,
    resume: bool,
) -> Result<(mdrlat_train::TrainReport, mdrlat_train::Learner), mdrlat_train::TrainError> {
    let cfg = config(Variant::LaserOnly, steps);
    train(vec![world], sim, &cfg, &Device::flex(), dir, resume, |_| {})
}

fn probe(learner: &mdrlat_train::Learner) -> Vec<f32> {
    let laser: Vec<f32> = (0..4 * 512).map(|i| (i % 97) as f32 / 97.0).collect();
    learner.q_values(&Inputs { size: 1, laser, ..Inputs::default() })
}

fn read(d: &Path, f: &str) -> String {
    std::fs::read_to_string(d.join(f)).expect("file")
}

#[test]
fn an_interrupted_run_resumes_exactly() {
    let dev = Device::flex();
    let straight = dir("straight");
    let (_, a) = laser_only(world(), &sim(), 300, &straight, false).expect("run");

    // The same run stopped at step 250 (its last checkpoint), then killed while it wrote
    // rows past the checkpoint: a resumed run must drop those rows and redo the steps.
    let cut = dir("cut");
    train(vec![world()], &sim(), &config(Variant::LaserOnly, 250), &dev, &cut, false, |_| {})
        .expect("run");
    let mut m = read(&cut, "metrics.csv");
    m.push_str("260,9,9,9,9,9,9,9\n270,9,9,9,9,9,9,9\n");
    std::fs::write(cut.join("metrics.csv"), m).expect("write");
    let (report, b) =
        train(vec![world()], &sim(), &config(Variant::LaserOnly, 300), &dev, &cut, true, |_| {})
            .expect("resume");
    assert_eq!(report.steps, 300);
    assert_eq!(probe(&a), probe(&b), "same weights");
    assert_eq!(read(&straight, "metrics.csv"), read(&cut, "metrics.csv"));
    assert_eq!(read(&straight, "eval.csv"), read(&cut, "eval.csv"));

    // Killed after its last checkpoint (step 250 of 250) but before anyone knew it was
    // done: resuming it changes nothing, its last (partial-window) row included.
    let end = dir("end");
    train(vec![world()], &sim(), &config(Variant::LaserOnly, 250), &dev, &end, false, |_| {})
        .expect("run");
    let before = read(&end, "metrics.csv");
    assert!(before.lines().last().is_some_and(|l| l.starts_with("250,")), "{before}");
    let (report, _) =
        train(vec![world()], &sim(), &config(Variant::LaserOnly, 250), &dev, &end, true, |_| {})
            .expect("resume at the end");
    assert_eq!(report.steps, 250);
    assert_eq!(read(&end, "metrics.csv"), before);
}

#[test]
fn a_run_asked_to_stop_checkpoints_where_it_stopped_and_resumes_exactly() {
    use std::sync::atomic::{AtomicBool, Ordering};
    let dev = Device::flex();
    let straight = dir("stop-straight");
    let (_, a) = laser_only(world(), &sim(), 300, &straight, false).expect("run");

    // Asked to stop at step 130 (between the 100-step checkpoints, inside a log window),
    // with no final checkpoint wanted: it still writes one at 130, and says it stopped.
    let cut = dir("stop-cut");
    let cfg = |steps| TrainConfig { final_checkpoint: false, ..config(Variant::LaserOnly, steps) };
    let stop = AtomicBool::new(false);
    let envs = mdrlat_train::TrainEnvs::new(vec![world()], &sim(), 1).expect("envs");
    let run = mdrlat_train::RunDir::at(&cut);
    let on_step = |s: &mdrlat_train::Status| {
        if s.step == 130 {
            stop.store(true, Ordering::Relaxed);
        }
    };
    let (report, _) = mdrlat_train::train_until(envs, &cfg(300), &dev, &run, false, on_step, &stop)
        .expect("stopped");
    assert!(report.stopped);
    assert_eq!(report.steps, 130);
    assert!(read(&cut, "checkpoint/meta.json").contains("\"step\":130"), "checkpoint at 130");
    // Resumed, it is the run that never stopped: same weights, same curves.
    let (report, b) =
        train(vec![world()], &sim(), &config(Variant::LaserOnly, 300), &dev, &cut, true, |_| {})
            .expect("resume");
    assert!(!report.stopped);
    assert_eq!(report.steps, 300);
    assert_eq!(probe(&a), probe(&b), "same weights");
    assert_eq!(read(&straight, "metrics.csv"), read(&cut, "metrics.csv"));
    assert_eq!(read(&straight, "eval.csv"), read(&cut, "eval.csv"));
    for d in [straight, cut] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// Several environments over several worlds, with several gradient steps at a time and
/// 3-step returns, resume exactly too: every environment's world, episode, frames and waiting
/// steps are in the checkpoint, which is written once a tick has stepped them all.
#[test]
fn several_environments_over_several_worlds_resume_exactly() {
    let dev = Device::flex();
    let worlds = || {
        let mut w = mdrlat_world::load_set("example,gen-1").expect("worlds");
        w.push(world());
        w
    };
    let cfg = |steps| TrainConfig {
        envs: 3,
        gradient_steps: 2,
        train_frequency: 2,
        n_step: 3,
        demo_steps: 90,
        checkpoint_interval: 90,
        ..config(Variant::LaserOnly, steps)
    };
    let straight = dir("multi-straight");
    let (_, a) = train(worlds(), &sim(), &cfg(300), &dev, &straight, false, |_| {}).expect("run");
    let cut = dir("multi-cut");
    train(worlds(), &sim(), &cfg(240), &dev, &cut, false, |_| {}).expect("run");
    let meta = read(&cut.join("checkpoint"), "meta.json");
    assert!(meta.contains("more_envs"), "the other environments are saved");
    let (report, b) = train(worlds(), &sim(), &cfg(300), &dev, &cut, true, |_| {}).expect("resume");
    assert_eq!(report.steps, 300);
    assert_eq!(probe(&a), probe(&b), "same weights");
    assert_eq!(read(&straight, "metrics.csv"), read(&cut, "metrics.csv"));
    assert_eq!(read(&straight, "eval.csv"), read(&cut, "eval.csv"));
    // 300 steps of 60-step episodes over three environments moved them between worlds.
    assert!(report.episodes >= 3, "{} episodes", report.episodes);
    // Another number of environments is an error naming the key.
    let e = train(worlds(), &sim(), &TrainConfig { envs: 2, ..cfg(300) }, &dev, &cut, true, |_| {})
        .expect_err("other envs")
        .to_string();
    assert!(e.contains("train.envs"), "{e}");
    for d in [straight, cut] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// The navigation task resumes exactly too: the goals live in the replay buffer and the
/// environment's state; a checkpoint of one task does not resume as the other.
#[test]
fn a_navigation_run_resumes_exactly_and_only_as_navigation() {
    let dev = Device::flex();
    let nav = SimConfig { task: mdrlat_sim::config::Task::Nav, ..sim() };
    let world = || mdrlat_world::builtin::get("nav-train").expect("builtin").expect("valid");
    let probe = |l: &mdrlat_train::Learner| {
        let laser: Vec<f32> = (0..4 * 512).map(|i| (i % 89) as f32 / 89.0).collect();
        l.q_values(&Inputs { size: 1, laser, goal: vec![0.3, 0.6, 0.8], ..Inputs::default() })
    };
    let straight = dir("nav-straight");
    let (_, a) = laser_only(world(), &nav, 300, &straight, false).expect("run");
    assert_eq!(probe(&a).len(), 10);
    let replay = std::fs::read(straight.join("checkpoint/replay.bin")).expect("replay");
    assert_eq!(&replay[..8], b"MDRLRB02", "goals are stored");
    let cut = dir("nav-cut");
    train(vec![world()], &nav, &config(Variant::LaserOnly, 200), &dev, &cut, false, |_| {})
        .expect("run");
    let e =
        train(vec![world()], &sim(), &config(Variant::LaserOnly, 300), &dev, &cut, true, |_| {})
            .expect_err("resumed as obstacle avoidance")
            .to_string();
    assert!(e.contains("nav") && e.contains("meta.json"), "{e}");
    let (_, b) =
        train(vec![world()], &nav, &config(Variant::LaserOnly, 300), &dev, &cut, true, |_| {})
            .expect("resume");
    assert_eq!(probe(&a), probe(&b), "same weights");
    assert_eq!(read(&straight, "metrics.csv"), read(&cut, "metrics.csv"));
    assert_eq!(read(&straight, "eval.csv"), read(&cut, "eval.csv"));
    for d in [straight, cut] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// A warm start (`train.init_from`) begins from a trained model's weights — a run directory
/// or its `model.safetensors` — and learns on from them with a fresh replay buffer; a model
/// of another variant or task, or none, is a clear error naming it.
#[test]
fn a_warm_start_begins_from_the_models_weights() {
    let dev = Device::flex();
    let source = dir("warm-source");
    let (_, a) = laser_only(world(), &sim(), 200, &source, false).expect("run");
    mdrlat_train::RunDir::at(&source)
        .finish(&a, 200, &config(Variant::LaserOnly, 200))
        .expect("model");
    let fresh = |steps| TrainConfig { seed: 9, ..config(Variant::LaserOnly, steps) };
    let warm =
        |from: &Path, steps| TrainConfig { init_from: from.display().to_string(), ..fresh(steps) };
    // 40 steps: fewer than learning_starts (50), so no gradient step has moved it yet.
    for from in [source.clone(), source.join("model.safetensors")] {
        let out = dir("warm-0");
        let (report, b) = train(vec![world()], &sim(), &warm(&from, 40), &dev, &out, false, |_| {})
            .expect("warm");
        assert_eq!((report.steps, report.updates), (40, 0));
        assert_eq!(probe(&a), probe(&b), "the model's weights, from {}", from.display());
    }
    // With gradient steps it learns on: neither the model nor the seed's fresh network.
    let out = dir("warm-1");
    let (report, b) =
        train(vec![world()], &sim(), &warm(&source, 120), &dev, &out, false, |_| {}).expect("warm");
    assert!(report.updates > 0);
    let (_, c) = train(vec![world()], &sim(), &fresh(120), &dev, &dir("warm-2"), false, |_| {})
        .expect("fresh");
    assert!(probe(&b) != probe(&a) && probe(&b) != probe(&c));
    // Models of another task or variant, and none, are errors naming train.init_from.
    let bad = |cfg: &TrainConfig, sim: &SimConfig, world| {
        train(vec![world], sim, cfg, &dev, &dir("warm-bad"), false, |_| {})
            .expect_err("bad model")
            .to_string()
    };
    let nav = SimConfig { task: mdrlat_sim::config::Task::Nav, ..sim() };
    let nav_world = mdrlat_world::builtin::get("nav-train").expect("builtin").expect("valid");
    let e = bad(&warm(&source, 40), &nav, nav_world);
    assert!(e.contains("train.init_from") && e.contains("laser-only network for avoid"), "{e}");
    let e = bad(&TrainConfig { variant: Variant::Mdrlat, ..warm(&source, 40) }, &sim(), world());
    assert!(e.contains("train.init_from") && e.contains("trains a mdrlat network"), "{e}");
    let e = bad(&warm(&source.join("nothing"), 40), &sim(), world());
    assert!(e.contains("train.init_from") && e.contains("no such run directory"), "{e}");
}

#[test]
fn bad_checkpoints_are_clear_errors_never_a_fresh_start() {
    let dev = Device::flex();
    let run = dir("bad");
    train(vec![world()], &sim(), &config(Variant::LaserOnly, 100), &dev, &run, false, |_| {})
        .expect("run");
    let resume =
        |variant| train(vec![world()], &sim(), &config(variant, 200), &dev, &run, true, |_| {});
    let e = resume(Variant::Mdrlat).expect_err("other variant").to_string();
    assert!(e.contains("laser-only") && e.contains("mdrlat"), "{e}");
    // Truncate the replay file.
    let replay = run.join("checkpoint/replay.bin");
    let bytes = std::fs::read(&replay).expect("replay");
    std::fs::write(&replay, &bytes[..bytes.len() / 2]).expect("write");
    let e = resume(Variant::LaserOnly).expect_err("truncated").to_string();
    assert!(e.contains("replay.bin") && e.contains("truncated"), "{e}");
    // Flip a byte: the checksum catches it.
    let mut flipped = bytes.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0xff;
    std::fs::write(&replay, &flipped).expect("write");
    let e = resume(Variant::LaserOnly).expect_err("corrupt").to_string();
    assert!(e.contains("checksum") || e.contains("replay"), "{e}");
    std::fs::write(&replay, &bytes).expect("restore");
    std::fs::write(run.join("checkpoint/online.bpk"), b"garbage").expect("write");
    let e = resume(Variant::LaserOnly).expect_err("weights").to_string();
    assert!(e.contains("online.bpk"), "{e}");
    std::fs::write(run.join("checkpoint/meta.json"), "{").expect("write");
    let e = resume(Variant::LaserOnly).expect_err("meta").to_string();
    assert!(e.contains("meta.json") && e.contains("corrupt"), "{e}");
    let empty = dir("empty");
    let e =
        train(vec![world()], &sim(), &config(Variant::LaserOnly, 200), &dev, &empty, true, |_| {})
            .expect_err("none");
    assert!(e.to_string().contains("no checkpoint"), "{e}");
}

#[test]
fn two_runs_with_one_seed_write_the_same_file_bytes() {
    // The files a user checksums: weights, optimiser state, replay, metrics (burn numbers
    // parameters at random and writes its maps in hash order; mdrlat numbers them in order
    // and stores tensors by name). TensorBoard event files carry wall-clock times by design.
    let dev = Device::flex();
    let runs: Vec<PathBuf> = ["same-a", "same-b"].iter().map(|n| dir(n)).collect();
    let mut learners = Vec::new();
    for d in &runs {
        let (_, l) =
            train(vec![world()], &sim(), &config(Variant::MultiAt, 120), &dev, d, false, |_| {})
                .expect("run");
        mdrlat_train::export::save_safetensors(
            &l.policy_net(),
            l.net_config(),
            &d.join("model.safetensors"),
        )
        .expect("export");
        learners.push(l);
    }
    let bytes = |d: &Path, f: &str| std::fs::read(d.join(f)).expect(f);
    for f in [
        "model.safetensors",
        "checkpoint/online.bpk",
        "checkpoint/target.bpk",
        "checkpoint/optimizer.bpk",
        "checkpoint/replay.bin",
        "checkpoint/meta.json",
        "metrics.csv",
        "eval.csv",
    ] {
        assert!(bytes(&runs[0], f) == bytes(&runs[1], f), "{f} differs between the two runs");
    }
    for d in &runs {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// Issue 38: every evaluation also measures the greedy policy by the evaluation protocol on
/// held-out starts of the training world and in an unseen world (moving success, the paper's
/// success, mean path), into `eval.csv` beside Fig. 4's reward.
#[test]
fn learning_curves_measure_the_training_world_and_an_unseen_one() {
    let dev = Device::flex();
    let curves = |c: TrainConfig, name: &str| -> Vec<Vec<String>> {
        let d = dir(name);
        let (report, _) = train(vec![world()], &sim(), &c, &dev, &d, false, |_| {}).expect("run");
        let text = read(&d, "eval.csv");
        let mut lines = text.lines();
        let header = lines.next().expect("header");
        assert_eq!(header, mdrlat_train::sink::EVAL_HEADER);
        let rows: Vec<Vec<String>> =
            lines.map(|l| l.split(',').map(str::to_string).collect()).collect();
        assert_eq!(rows.len(), report.evaluations.len());
        for (row, e) in rows.iter().zip(&report.evaluations) {
            assert_eq!(row.len(), 12, "{row:?}");
            for (k, c) in e.curves.iter().enumerate() {
                assert_eq!(row[6 + 3 * k], format!("{:.6}", c.moving_success));
                assert!(c.moving_success <= c.success && (0.0..=1.0).contains(&c.success));
                assert!(c.path_m >= 0.0);
            }
        }
        rows
    };
    let base = TrainConfig { curve_episodes: 4, ..config(Variant::LaserOnly, 150) };
    let rows = curves(base.clone(), "curves");
    assert!(rows[0][6..].iter().all(|c| !c.is_empty()), "{:?}", rows[0]);
    let rows = curves(TrainConfig { curve_world: "none".into(), ..base.clone() }, "train-only");
    assert!(
        rows[0][6..9].iter().all(|c| !c.is_empty()) && rows[0][9..].iter().all(String::is_empty)
    );
    let rows = curves(TrainConfig { curve_episodes: 0, ..base.clone() }, "no-curves");
    assert!(rows[0][6..].iter().all(String::is_empty), "{:?}", rows[0]);
    let e = train(
        vec![world()],
        &sim(),
        &TrainConfig { curve_world: "nowhere".into(), ..base },
        &dev,
        &dir("bad-world"),
        false,
        |_| {},
    )
    .map(|_| ())
    .expect_err("unknown world");
    assert!(e.to_string().contains("train.curve_world 'nowhere'"), "{e}");
}

/// n-step returns store what the one-step transitions of the same trajectory add up to:
/// `Σ_{i<k} γ^i r_{t+i}` and the frames of `s_{t+k}`, k = n, or fewer where the episode ended
/// (terminated only where it ended in a collision). Actions are all random here, so runs with
/// n = 1 and n = 3 drive the same trajectory and push the same frames.
#[test]
fn n_step_transitions_add_up_the_one_step_ones() {
    let replay_of = |n_step, name: &str| {
        let cfg = TrainConfig {
            n_step,
            epsilon_start: 1.0,
            epsilon_end: 1.0,
            replay_capacity: 400,
            learning_starts: 150,
            ..config(Variant::LaserOnly, 200)
        };
        let d = dir(name);
        train(vec![world()], &sim(), &cfg, &Device::flex(), &d, false, |_| {}).expect("run");
        let path = d.join("checkpoint/replay.bin");
        let bytes = std::fs::read(&path).expect("replay");
        let r = mdrlat_train::ReplayBuffer::read_from(
            &bytes[..],
            bytes.len() as u64,
            400,
            mdrlat_train::checkpoint::frame_reserve(400),
            true,
            false,
            false,
            (1, n_step as usize),
        )
        .expect("reads");
        let _ = std::fs::remove_dir_all(&d);
        (0..r.len()).map(|i| *r.get(i).expect("held")).collect::<Vec<_>>()
    };
    let one = replay_of(1, "n1");
    let three = replay_of(3, "n3");
    assert_eq!(one.len(), 200);
    // Every step is stored once, but the last two of an unfinished episode, which wait for
    // the steps after them (in the checkpoint).
    assert!((198..=200).contains(&three.len()), "{} stored", three.len());
    let gamma = TrainConfig::default().gamma;
    let mut short = 0;
    for t in &three {
        let i = one.iter().position(|o| o.obs == t.obs && o.action == t.action).expect("its step");
        let k = usize::from(t.steps);
        assert!((1..=3).contains(&k));
        let run = &one[i..i + k];
        // No collision before the last of the k steps.
        assert!(run[..k - 1].iter().all(|o| !o.terminated));
        let sum = run.iter().rev().map(|o| o.reward).reduce(|later, r| r + gamma * later);
        assert_eq!(t.reward, sum.expect("k >= 1"), "step {i}");
        assert_eq!(t.next, run[k - 1].next, "s' of step {i}");
        assert_eq!(t.terminated, run[k - 1].terminated);
        if k < 3 {
            short += 1;
        }
    }
    assert!(short >= 4, "episode ends store shorter returns ({short})");
}

/// Demonstrations: with every action exploratory and every exploratory action `avoid`'s, the
/// training episodes are `avoid`'s, which all run to the time limit; random actions crash.
#[test]
fn demonstrations_drive_the_early_episodes() {
    let episodes = |demo_share| {
        let cfg = TrainConfig {
            epsilon_start: 1.0,
            epsilon_end: 1.0,
            demo_steps: 300,
            demo_share,
            checkpoint_interval: 300,
            ..config(Variant::LaserOnly, 300)
        };
        let d = dir(&format!("demo-{demo_share}"));
        let (report, _) =
            train(vec![world()], &sim(), &cfg, &Device::flex(), &d, false, |_| {}).expect("run");
        let _ = std::fs::remove_dir_all(&d);
        report.episodes
    };
    let (demonstrated, random) = (episodes(1.0), episodes(0.0));
    // 300 steps of 60-step episodes: 5 when none ends in a collision.
    assert_eq!(demonstrated, 5, "episodes with avoid driving");
    assert!(random > demonstrated, "{random} random episodes: some crash");
}

/// `final_checkpoint = false`: a short run leaves no optimiser state or replay behind, and
/// asking to resume it says there is nothing to resume from.
#[test]
fn a_run_without_a_final_checkpoint_leaves_none_and_says_so() {
    let d = dir("no-final");
    let cfg = TrainConfig {
        final_checkpoint: false,
        checkpoint_interval: 1000,
        ..config(Variant::LaserOnly, 120)
    };
    train(vec![world()], &sim(), &cfg, &Device::flex(), &d, false, |_| {}).expect("run");
    assert!(!d.join("checkpoint").exists(), "no checkpoint written");
    assert!(read(&d, "metrics.csv").lines().count() > 1, "the metrics are there");
    let e = train(vec![world()], &sim(), &cfg, &Device::flex(), &d, true, |_| {})
        .expect_err("nothing to resume")
        .to_string();
    assert!(e.contains("no checkpoint"), "{e}");
    let _ = std::fs::remove_dir_all(&d);
}

/// `final_checkpoint = false` on a run long enough to checkpoint on the way: killed midway it
/// resumes from its checkpoint; finished (`RunDir::finish`), it leaves `model.safetensors`
/// — the policy the checkpoint held — and no checkpoint, replay or half-swapped folder.
#[test]
fn a_finished_run_without_a_final_checkpoint_removes_the_ones_on_the_way() {
    let dev = Device::flex();
    let d = dir("finish-drop");
    let cfg = |steps| TrainConfig { final_checkpoint: false, ..config(Variant::LaserOnly, steps) };
    // Stopped at 250 steps: its step-200 checkpoint (with the replay) is there to resume.
    train(vec![world()], &sim(), &cfg(250), &dev, &d, false, |_| {}).expect("run");
    assert!(d.join("checkpoint/replay.bin").is_file(), "the checkpoint on the way");
    let (report, learner) =
        train(vec![world()], &sim(), &cfg(300), &dev, &d, true, |_| {}).expect("resume");
    assert_eq!(report.steps, 300);
    assert!(d.join("checkpoint/replay.bin").is_file(), "still there before finish");
    std::fs::create_dir_all(d.join("checkpoint.old")).expect("a killed swap's leftover");
    let run = mdrlat_train::RunDir::at(&d);
    run.finish(&learner, report.steps, &cfg(300)).expect("finish");
    for gone in ["checkpoint", "checkpoint.old", "checkpoint.tmp"] {
        assert!(!d.join(gone).exists(), "{gone} removed");
    }
    // The model is the finished policy, and it loads from the run folder.
    let policy = mdrlat_train::GreedyPolicy::load(&d, &dev, 1).expect("the run's model");
    let inputs = Inputs { size: 1, laser: vec![0.5; 4 * 512], ..Inputs::default() };
    let from_model = policy.q_values(&inputs).expect("q");
    let direct = learner.q_values(&inputs);
    for (a, b) in from_model.iter().zip(&direct) {
        assert!((a - b).abs() < 1e-5, "{from_model:?} against {direct:?}");
    }
    let e = train(vec![world()], &sim(), &cfg(400), &dev, &d, true, |_| {})
        .expect_err("nothing to resume")
        .to_string();
    assert!(e.contains("no checkpoint"), "{e}");
    // The default keeps the final checkpoint.
    let kept = dir("finish-keep");
    let (report, learner) =
        train(vec![world()], &sim(), &config(Variant::LaserOnly, 120), &dev, &kept, false, |_| {})
            .expect("run");
    mdrlat_train::RunDir::at(&kept)
        .finish(&learner, report.steps, &config(Variant::LaserOnly, 120))
        .expect("finish");
    assert!(
        kept.join("checkpoint/replay.bin").is_file() && kept.join("model.safetensors").is_file()
    );
    let _ = std::fs::remove_dir_all(&d);
    let _ = std::fs::remove_dir_all(&kept);
}

/// Polyak averaging of the policy (`train.average_horizon`): the averaged network is in the
/// checkpoint and resumes exactly; it is what the run's evaluations use and what a checkpoint
/// loads as a policy; it is not the online network. A checkpoint whose averaging does not
/// match the config is a clear error.
#[test]
fn a_run_with_an_averaged_policy_resumes_exactly() {
    let dev = Device::flex();
    // 300 steps from 50 transitions: 250 gradient steps, the average moved at 100 and 200.
    let cfg = |steps| TrainConfig { average_horizon: 200, ..config(Variant::LaserOnly, steps) };
    let straight = dir("avg-straight");
    let (_, a) =
        train(vec![world()], &sim(), &cfg(300), &dev, &straight, false, |_| {}).expect("run");
    let cut = dir("avg-cut");
    train(vec![world()], &sim(), &cfg(150), &dev, &cut, false, |_| {}).expect("run");
    let (_, b) = train(vec![world()], &sim(), &cfg(300), &dev, &cut, true, |_| {}).expect("resume");
    assert_eq!(probe(&a), probe(&b), "same online weights");
    let bytes = |d: &Path, f: &str| std::fs::read(d.join("checkpoint").join(f)).expect(f);
    assert_eq!(bytes(&straight, "average.bpk"), bytes(&cut, "average.bpk"), "same average");
    assert_eq!(read(&straight, "eval.csv"), read(&cut, "eval.csv"));
    assert_ne!(bytes(&straight, "average.bpk"), bytes(&straight, "online.bpk"));
    // A checkpoint acts by its averaged network, and says so.
    let policy =
        mdrlat_train::GreedyPolicy::load(&straight.join("checkpoint"), &dev, 1).expect("policy");
    assert!(policy.source().contains("averaged network"), "{}", policy.source());
    // The averaged network is not the online one: their Q-values differ.
    let laser: Vec<f32> = (0..4 * 512).map(|i| (i % 97) as f32 / 97.0).collect();
    let q = policy.q_values(&Inputs { size: 1, laser, ..Inputs::default() }).expect("q");
    assert_ne!(q, probe(&a));
    // Resuming with the averaging switched off (or on, for a run without it) is refused.
    let off = TrainConfig { average_horizon: 0, ..cfg(350) };
    let e = train(vec![world()], &sim(), &off, &dev, &cut, true, |_| {}).expect_err("mismatch");
    assert!(e.to_string().contains("average_horizon"), "{e}");
    // A horizon shorter than the moves' spacing is a config error naming the key.
    let short = TrainConfig { average_horizon: 50, ..cfg(300) };
    assert!(short.validate().expect_err("short").to_string().contains("train.average_horizon"));
    for d in [straight, cut] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// `train.snapshot_minutes`: the policy is written at fixed minutes of training, each
/// snapshot a model the evaluation reads (with its step and minutes); snapshots change
/// nothing of the training itself; the checkpoint keeps the clock (out of `meta.json`, whose
/// bytes the seed fixes) and a resumed run counts on from it.
#[test]
fn snapshots_at_fixed_minutes_leave_the_run_unchanged_and_the_clock_resumes() {
    let dev = Device::flex();
    let plain = dir("snap-plain");
    let (_, a) = laser_only(world(), &sim(), 250, &plain, false).expect("run");
    let snap = dir("snap");
    // Every 0.06 s of training: several snapshots in a run of a few seconds.
    let cfg = |steps| TrainConfig { snapshot_minutes: 0.001, ..config(Variant::LaserOnly, steps) };
    let (_, b) = train(vec![world()], &sim(), &cfg(250), &dev, &snap, false, |_| {}).expect("run");
    assert_eq!(probe(&a), probe(&b), "same weights with snapshots");
    for f in ["metrics.csv", "eval.csv", "checkpoint/meta.json"] {
        assert_eq!(read(&plain, f), read(&snap, f), "{f}");
    }
    let clock = |d: &Path| mdrlat_train::checkpoint::training_seconds(d).expect("clock");
    let first = clock(&snap).expect("the checkpoint has a clock");
    assert!(first > 0.0, "{first}");

    let names = |d: &Path| -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d.join("snapshots"))
            .expect("snapshots/")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    let written = names(&snap);
    assert!(written.len() >= 2, "{written:?}");
    let minutes: Vec<f64> = written
        .iter()
        .map(|n| mdrlat_train::run_dir::snapshot_minute(n).expect("a minute-* name"))
        .collect();
    assert!(minutes.windows(2).all(|w| w[0] < w[1]), "{minutes:?}");
    let last = snap.join("snapshots").join(written.last().expect("one"));
    let meta =
        mdrlat_train::export::safetensors_metadata(&last.join("model.safetensors")).expect("meta");
    let step: u64 = meta["mdrlat_step"].parse().expect("step");
    assert!(step > 0 && step <= 250, "{step}");
    let trained: f64 = meta["mdrlat_training_minutes"].parse().expect("minutes");
    assert!(trained >= *minutes.last().expect("one"), "{trained} {minutes:?}");
    let policy = mdrlat_train::GreedyPolicy::load(&last, &dev, 1).expect("a snapshot is a model");
    assert!(policy.source().contains("minutes of training"), "{}", policy.source());

    // Extended: the clock goes on from the checkpoint's, the old snapshots stay.
    train(vec![world()], &sim(), &cfg(300), &dev, &snap, true, |_| {}).expect("resume");
    assert!(clock(&snap).expect("clock") > first);
    assert!(names(&snap).len() >= written.len());
    // A corrupt clock is a clear error naming the file, not a silent restart from zero.
    std::fs::write(snap.join("checkpoint").join(mdrlat_train::checkpoint::CLOCK_FILE), "{")
        .expect("write");
    let e = train(vec![world()], &sim(), &cfg(350), &dev, &snap, true, |_| {})
        .expect_err("corrupt clock")
        .to_string();
    assert!(e.contains("clock.json") && e.contains("corrupt"), "{e}");
    for d in [plain, snap] {
        let _ = std::fs::remove_dir_all(d);
    }
}

#[test]
fn a_model_trained_on_the_scan_with_the_cameras_memory_says_so_everywhere() {
    use mdrlat_core::Policy;
    let dev = Device::flex();
    let memory = SimConfig {
        laser: mdrlat_sim::config::LaserConfig { depth_memory_frames: 6, ..Default::default() },
        ..sim()
    };
    let run = dir("memory");
    let cfg = TrainConfig { snapshot_minutes: 0.001, ..config(Variant::LaserOnly, 200) };
    let (_, learner) = train(vec![world()], &memory, &cfg, &dev, &run, false, |_| {}).expect("run");
    mdrlat_train::RunDir::at(&run).finish(&learner, 200, &cfg).expect("model");
    // The checkpoint, the model and a snapshot record it; each loads as a policy of it.
    assert!(read(&run, "checkpoint/meta.json").contains("\"depth_memory_frames\":6"));
    let meta = mdrlat_train::export::safetensors_metadata(&run.join("model.safetensors"))
        .expect("metadata");
    assert_eq!(meta[mdrlat_train::export::DEPTH_MEMORY_KEY], "6");
    assert!(meta["mdrlat_inputs"].contains("6 frames of the camera's memory"), "{meta:?}");
    let snapshot = std::fs::read_dir(run.join("snapshots")).expect("snapshots").next();
    let snapshot = snapshot.expect("one snapshot").expect("entry").path();
    for path in [run.clone(), run.join("checkpoint"), run.join("model.safetensors"), snapshot] {
        let p = mdrlat_train::GreedyPolicy::load(&path, &dev, 1).expect("policy");
        assert_eq!(p.depth_memory_frames(), 6, "{}", path.display());
        assert!(p.sensors().depth, "it reads the camera, through the scan");
        assert!(p.source().contains("6 frames of the camera's memory"), "{}", p.source());
        // It makes a simulator of the laser's own scan draw its scan, and refuses another.
        let mut s = SimConfig::default();
        p.adopt_scan(&mut s, "--checkpoint x").expect("adopted");
        assert_eq!(s.laser.depth_memory_frames, 6);
        s.laser.depth_memory_frames = 3;
        let e = p.adopt_scan(&mut s, "--checkpoint x").expect_err("another memory");
        assert!(e.contains("--checkpoint x") && e.contains("depth_memory_frames = 3"), "{e}");
        // `fit_sim` does both: the task first, then the scan.
        let mut s = SimConfig::default();
        p.fit_sim(&mut s, "x").expect("fitted");
        assert_eq!(s.laser.depth_memory_frames, 6);
        s.task = mdrlat_sim::config::Task::Nav;
        let e = p.fit_sim(&mut s, "x").expect_err("another task");
        assert!(e.contains("--task nav"), "{e}");
    }
    // A model of the laser's own scan refuses a simulator that draws the memory, and a warm
    // start across the two scans is an error naming both.
    let plain = dir("memory-plain");
    let (_, a) = laser_only(world(), &sim(), 100, &plain, false).expect("run");
    mdrlat_train::RunDir::at(&plain)
        .finish(&a, 100, &config(Variant::LaserOnly, 100))
        .expect("model");
    let p = mdrlat_train::GreedyPolicy::load(&plain, &dev, 1).expect("policy");
    assert_eq!((p.depth_memory_frames(), p.sensors().depth), (0, false));
    let mut s = memory.clone();
    assert!(p.adopt_scan(&mut s, "x").is_err());
    let warm =
        TrainConfig { init_from: plain.display().to_string(), ..config(Variant::LaserOnly, 40) };
    let e = train(vec![world()], &memory, &warm, &dev, &dir("memory-warm"), false, |_| {})
        .expect_err("another scan")
        .to_string();
    assert!(e.contains("train.init_from") && e.contains("the laser's own scan"), "{e}");
    assert!(e.contains("6 frames of the camera's memory"), "{e}");
    // Resumed under settings that draw another scan: an error naming the checkpoint.
    let more = TrainConfig { total_steps: 250, ..cfg.clone() };
    let e = train(vec![world()], &sim(), &more, &dev, &run, true, |_| {})
        .expect_err("another scan")
        .to_string();
    assert!(e.contains("meta.json") && e.contains("depth_memory_frames"), "{e}");
    // A checkpoint naming an impossible memory is refused, not allocated.
    let meta = read(&run, "checkpoint/meta.json")
        .replace("\"depth_memory_frames\":6", "\"depth_memory_frames\":4000000000");
    std::fs::write(run.join("checkpoint/meta.json"), meta).expect("write");
    let Err(e) = mdrlat_train::GreedyPolicy::load(&run.join("checkpoint"), &dev, 1) else {
        panic!("an impossible memory is refused")
    };
    assert!(e.contains("depth_memory_frames = 4000000000"), "{e}");
    for d in [run, plain] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// Prioritised replay (`train.priority_alpha` > 0): the priorities go into the checkpoint
/// and a resumed run draws the same batches (the same weights and curves as a run never
/// stopped), through the buffer wrapping (capacity 120, 300 steps); the run differs from a
/// uniform one; resuming with the other kind of replay is a clear error.
#[test]
fn a_run_with_prioritised_replay_resumes_exactly() {
    let dev = Device::flex();
    let cfg = |steps| TrainConfig { priority_alpha: 0.6, ..config(Variant::LaserOnly, steps) };
    let straight = dir("per-straight");
    let (_, a) =
        train(vec![world()], &sim(), &cfg(300), &dev, &straight, false, |_| {}).expect("run");
    let cut = dir("per-cut");
    train(vec![world()], &sim(), &cfg(150), &dev, &cut, false, |_| {}).expect("run");
    let (_, b) = train(vec![world()], &sim(), &cfg(300), &dev, &cut, true, |_| {}).expect("resume");
    assert_eq!(probe(&a), probe(&b), "same online weights");
    assert_eq!(read(&straight, "metrics.csv"), read(&cut, "metrics.csv"));
    assert_eq!(read(&straight, "eval.csv"), read(&cut, "eval.csv"));
    let meta = |d: &Path| read(&d.join("checkpoint"), "meta.json");
    assert_eq!(meta(&straight), meta(&cut), "same priorities, counters and streams");
    let m: serde_json::Value = serde_json::from_str(&meta(&straight)).expect("json");
    let values = m["priorities"]["value_bits"].as_array().expect("priorities in meta.json");
    assert_eq!(values.len(), 120, "a full buffer's");
    // Learned priorities differ from one another (new transitions start at the largest).
    let first = values[0].as_u64().expect("bits");
    assert!(values.iter().any(|v| v.as_u64() != Some(first)), "{values:?}");
    // The draw by priority changes the run.
    let uniform = dir("per-uniform");
    let (_, u) = train(
        vec![world()],
        &sim(),
        &config(Variant::LaserOnly, 300),
        &dev,
        &uniform,
        false,
        |_| {},
    )
    .expect("uniform run");
    assert_ne!(probe(&a), probe(&u));
    // Resuming a prioritised checkpoint with uniform replay, and the other way round: refused.
    let off = TrainConfig { priority_alpha: 0.0, ..cfg(350) };
    let e = train(vec![world()], &sim(), &off, &dev, &cut, true, |_| {}).expect_err("mismatch");
    assert!(e.to_string().contains("train.priority_alpha"), "{e}");
    let on = TrainConfig { total_steps: 350, ..cfg(350) };
    let e = train(vec![world()], &sim(), &on, &dev, &uniform, true, |_| {});
    assert!(e.expect_err("mismatch").to_string().contains("prioritised"));
    // Out-of-range settings are config errors naming the key.
    for bad in [
        TrainConfig { priority_alpha: 1.5, ..cfg(300) },
        TrainConfig { priority_beta: -0.1, ..cfg(300) },
        TrainConfig { priority_epsilon: 0.0, ..cfg(300) },
    ] {
        let e = bad.validate().expect_err("bad").to_string();
        assert!(e.contains("train.priority_"), "{e}");
    }
    for d in [straight, cut, uniform] {
        let _ = std::fs::remove_dir_all(d);
    }
}
