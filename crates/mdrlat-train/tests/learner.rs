//! The learning rule: eq. (10) targets, terminated vs truncated, and that a gradient step
//! reduces the loss.

use mdrlat_core::{DEPTH_COLS, DEPTH_LEN, DEPTH_ROWS, FRAME_STACK, LASER_BEAMS, Rng};
use mdrlat_nn::Variant;
use mdrlat_nn::burn::prelude::{Device, Tensor, TensorData};
use mdrlat_sim::config::Task;
use mdrlat_train::{AuxOptimizer, Batch, Learner, TrainConfig};

fn batch(b: usize, terminated: &[f32], rng: &mut Rng, depth: bool) -> Batch {
    let ls = FRAME_STACK * LASER_BEAMS;
    let ds = if depth { FRAME_STACK * DEPTH_LEN } else { 0 };
    let mut r = |n: usize| (0..n).map(|_| rng.uniform() as f32).collect::<Vec<f32>>();
    Batch {
        size: b,
        laser: r(b * ls),
        depth: r(b * ds),
        next_laser: r(b * ls),
        next_depth: r(b * ds),
        actions: (0..b as i64).map(|i| i % 10).collect(),
        rewards: (0..b).map(|i| i as f32 * 0.1 - 0.5).collect(),
        terminated: terminated.to_vec(),
        odom: (0..b * 6).map(|i| (i % 7) as f32 * 0.1).collect(),
        ..Batch::default()
    }
}

/// `batch` with normalised goals for `s` and `s'` (the navigation task).
fn with_goals(mut b: Batch, rng: &mut Rng) -> Batch {
    let mut goal = || {
        let (d, a) = (rng.range_f32(0.0, 1.0), rng.range_f32(-3.1, 3.1));
        [d, a.sin(), a.cos()]
    };
    b.goal = (0..b.size).flat_map(|_| goal()).collect();
    b.next_goal = (0..b.size).flat_map(|_| goal()).collect();
    b
}

#[test]
fn only_termination_zeroes_the_bootstrap_and_the_online_net_picks() {
    let cfg =
        TrainConfig { variant: Variant::LaserOnly, learning_rate: 1e-3, ..TrainConfig::default() };
    let mut learner = Learner::new(&cfg, Task::Avoid, &Device::flex());
    let mut rng = Rng::seed_from_u64(1);
    // A few updates without a target sync: the online and target networks now differ.
    let warm = batch(8, &[0.0; 8], &mut rng, false);
    for _ in 0..5 {
        learner.update(&warm);
    }
    // Rows 0 and 2 terminated (collision); rows 1 and 3 truncated or mid-episode: bootstrap.
    let b = batch(4, &[1.0, 0.0, 1.0, 0.0], &mut rng, false);
    let y = learner.td_targets(&b);
    let q_target = learner.target_q_next(&b);
    let next = mdrlat_train::Inputs { size: 4, laser: b.next_laser.clone(), ..Default::default() };
    assert_ne!(learner.q_values(&next), q_target, "the networks diverged");
    let greedy = learner.greedy(&next).expect("finite Q-values");
    for row in 0..4 {
        let expect = if b.terminated[row] == 1.0 {
            b.rewards[row]
        } else {
            // Double DQN (eq. 10): the online network picks, the target network evaluates.
            b.rewards[row] + 0.99 * q_target[row * 10 + greedy[row].index()]
        };
        assert!((y[row] - expect).abs() < 1e-5, "row {row}: {} vs {expect}", y[row]);
    }
}

/// n-step transitions bootstrap with γ^steps, on the host kernels and on burn's autodiff.
#[test]
fn n_step_targets_discount_by_gamma_to_the_steps() {
    for host in [true, false] {
        let cfg = TrainConfig { variant: Variant::LaserOnly, ..TrainConfig::default() };
        let mut learner = Learner::new(&cfg, Task::Avoid, &Device::flex());
        learner.set_host_kernels(host);
        let mut rng = Rng::seed_from_u64(6);
        let mut b = batch(4, &[0.0, 0.0, 1.0, 0.0], &mut rng, false);
        b.steps = vec![1, 3, 3, 5];
        let y = learner.td_targets(&b);
        let q_target = learner.target_q_next(&b);
        let next =
            mdrlat_train::Inputs { size: 4, laser: b.next_laser.clone(), ..Default::default() };
        let greedy = learner.greedy(&next).expect("finite Q-values");
        for row in 0..4 {
            let discount = 0.99f32.powi(i32::from(b.steps[row]));
            let bootstrap = if b.terminated[row] == 1.0 { 0.0 } else { discount };
            let expect = b.rewards[row] + bootstrap * q_target[row * 10 + greedy[row].index()];
            assert!(
                (y[row] - expect).abs() < 1e-5,
                "host {host} row {row}: {} vs {expect}",
                y[row]
            );
        }
    }
}

#[test]
fn gradient_steps_reduce_the_losses_on_a_fixed_batch() {
    for variant in [Variant::LaserOnly, Variant::MultiAt] {
        let cfg = TrainConfig { variant, learning_rate: 1e-3, ..TrainConfig::default() };
        let mut learner = Learner::new(&cfg, Task::Avoid, &Device::flex());
        let mut rng = Rng::seed_from_u64(2);
        let b = batch(8, &[1.0; 8], &mut rng, variant.uses_depth()); // terminal: fixed targets
        let first = learner.update(&b);
        let mut last = first;
        for _ in 0..30 {
            last = learner.update(&b);
        }
        assert!(last.td < first.td * 0.5, "{variant}: td {} -> {}", first.td, last.td);
        if variant.auxiliary_task() {
            assert!(
                first.at > 0.0 && last.at < first.at * 0.5,
                "{variant}: at {} -> {}",
                first.at,
                last.at
            );
        } else {
            assert_eq!(last.at, 0.0);
        }
    }
}

#[test]
fn same_seed_same_weights() {
    let cfg = TrainConfig { variant: Variant::LaserOnly, seed: 7, ..TrainConfig::default() };
    let mut rng = Rng::seed_from_u64(3);
    let b = batch(4, &[0.0, 1.0, 0.0, 1.0], &mut rng, false);
    let run = || {
        let mut l = Learner::new(&cfg, Task::Avoid, &Device::flex());
        let losses: Vec<f32> = (0..3).map(|_| l.update(&b).td).collect();
        (losses, l.td_targets(&b))
    };
    assert_eq!(run(), run());
}

#[test]
fn profile_times_every_stage_forward_and_backward() {
    let cfg = TrainConfig { variant: Variant::MultiAt, ..TrainConfig::default() };
    let learner = Learner::new(&cfg, Task::Avoid, &Device::flex());
    let b = batch(4, &[0.0; 4], &mut Rng::seed_from_u64(5), true);
    let stages = learner.stage_times(&b);
    let names: Vec<&str> = stages.iter().map(|s| s.name).collect();
    assert_eq!(
        names,
        [
            "depth stream (3 conv)",
            "laser stream (3 conv1d)",
            "value head",
            "advantage head",
            "velocity head (AT)"
        ]
    );
    for s in &stages {
        assert!(s.forward_ms > 0.0 && s.backward_ms.is_some_and(|b| b > 0.0), "{s:?}");
    }
}

/// The navigation task's goal joins the representation in the profile as in a step.
#[test]
fn profile_of_a_navigation_net_reads_the_goal() {
    let cfg = TrainConfig { variant: Variant::LaserOnly, ..TrainConfig::default() };
    let learner = Learner::new(&cfg, Task::Nav, &Device::flex());
    let mut rng = Rng::seed_from_u64(6);
    let b = with_goals(batch(2, &[0.0; 2], &mut rng, false), &mut rng);
    let stages = learner.stage_times(&b);
    let names: Vec<&str> = stages.iter().map(|s| s.name).collect();
    assert_eq!(names, ["laser stream (3 conv1d)", "value head", "advantage head"]);
    for s in &stages {
        assert!(s.forward_ms > 0.0 && s.backward_ms.is_some_and(|b| b > 0.0), "{s:?}");
    }
}

#[test]
fn adam_updates_in_place_yet_the_target_keeps_its_weights() {
    in_place_updates_spare_the_target(&Device::flex());
}

/// The same on LibTorch's CPU tensors (`cargo test --features tch`, with LibTorch set up).
#[cfg(feature = "tch")]
#[test]
#[allow(deprecated)] // burn-tch is deprecated upstream; it is our `tch` backend.
fn adam_updates_in_place_yet_the_target_keeps_its_weights_on_libtorch() {
    in_place_updates_spare_the_target(&Device::libtorch());
}

fn in_place_updates_spare_the_target(device: &Device) {
    // MDRLAT: every kind of layer, including the convolutions whose weight gradients come
    // out of the backward pass permuted.
    // One Adam: every parameter's update is one step (see the count below).
    let cfg = TrainConfig {
        variant: Variant::Mdrlat,
        learning_rate: 1e-3,
        aux_optimizer: AuxOptimizer::Joint,
        ..TrainConfig::default()
    };
    let mut learner = Learner::new(&cfg, Task::Avoid, device);
    let mut rng = Rng::seed_from_u64(9);
    let b = batch(4, &[0.0; 4], &mut rng, true);
    let next = mdrlat_train::Inputs {
        size: 4,
        laser: b.next_laser.clone(),
        depth: b.next_depth.clone(),
        goal: Vec::new(),
    };
    let held_q = |net: &mdrlat_nn::QNet| {
        let l = Tensor::<3>::from_data(
            TensorData::new(b.next_laser.clone(), [4, FRAME_STACK, LASER_BEAMS]),
            device,
        );
        let d = mdrlat_nn::depth_input(&b.next_depth, 4, DEPTH_ROWS, DEPTH_COLS, device);
        net.forward(Some(l), Some(d), None).q.into_data().try_to_vec::<f32>().expect("f32")
    };
    for _ in 0..3 {
        learner.update(&b);
    }
    learner.sync_target();
    let target_before = learner.target_q_next(&b);
    let online_before = learner.q_values(&next);
    assert_eq!(target_before, online_before, "θ⁻ ← θ");
    learner.update(&b);
    // A copy of the online network someone holds (an evaluation, an export) keeps its values.
    let held = learner.policy_net();
    let held_before = held_q(&held);
    for _ in 0..2 {
        learner.update(&b);
    }
    // The online network moved; the target network, which shared its weights at the sync,
    // and the held copy did not move with it.
    assert_ne!(learner.q_values(&next), online_before);
    assert_eq!(learner.target_q_next(&b), target_before);
    assert_eq!(held_q(&held), held_before);
    // Every parameter update is fused except in three steps: the first (which creates the
    // moments), the one after the sync (whose weights the target still shared) and the one
    // after the copy was taken.
    let (fused, fallback) = learner.adam_paths();
    let per_step = (fused + fallback) / 6;
    assert_eq!((fused + fallback) % 6, 0);
    assert!(per_step >= 20, "{per_step} parameters");
    assert_eq!((fused, fallback), (3 * per_step, 3 * per_step));
}

/// The host kernels and burn's autodiff are one learning rule: from the same seed, a few
/// gradient steps (with a target sync between them) give the same losses and Q-values — with
/// the navigation task's goal input too.
#[test]
fn host_kernels_and_burn_autodiff_take_the_same_steps() {
    for (variant, task) in [
        (Variant::LaserOnly, Task::Avoid),
        (Variant::Mdrlat, Task::Avoid),
        (Variant::MultiAt, Task::Nav),
    ] {
        let cfg = TrainConfig { variant, learning_rate: 1e-4, ..TrainConfig::default() };
        let (mut host, mut burn) =
            (Learner::new(&cfg, task, &Device::flex()), Learner::new(&cfg, task, &Device::flex()));
        burn.set_host_kernels(false);
        assert!(host.uses_host_kernels() && !burn.uses_host_kernels());
        assert_eq!(host.net_config().goal_dim, task.goal_dim());
        let mut rng = Rng::seed_from_u64(9);
        let depth = variant.uses_depth();
        let batches: Vec<Batch> = (0..4)
            .map(|_| {
                let b = batch(6, &[0.0, 1.0, 0.0, 0.0, 0.0, 1.0], &mut rng, depth);
                if task == Task::Nav { with_goals(b, &mut rng) } else { b }
            })
            .collect();
        for (i, b) in batches.iter().enumerate() {
            if i == 2 {
                host.sync_target();
                burn.sync_target();
            }
            let (h, a) = (host.update(b), burn.update(b));
            for (name, x, y) in [("td", h.td, a.td), ("at", h.at, a.at), ("q", h.q_mean, a.q_mean)]
            {
                assert!(
                    (x - y).abs() <= 1e-4 * y.abs().max(1.0),
                    "{variant} step {i} {name}: {x} vs {y}"
                );
            }
        }
        let next = mdrlat_train::Inputs {
            size: 6,
            laser: batches[0].next_laser.clone(),
            depth: batches[0].next_depth.clone(),
            goal: batches[0].next_goal.clone(),
        };
        let (qh, qa) = (host.q_values(&next), burn.q_values(&next));
        assert_eq!(qh.len(), 60, "{variant} {task}");
        let worst = qh.iter().zip(&qa).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "{variant} {task}: Q-values after the steps differ by {worst}");
        if task == Task::Nav {
            // The goal is an input: another goal, other Q-values.
            let mut moved = next.clone();
            moved.goal.iter_mut().for_each(|g| *g = -*g);
            assert_ne!(host.q_values(&moved), qh, "the goal changes nothing");
        }
    }
}

/// Every float parameter of a network, flattened, in visiting order.
fn weights(net: &mdrlat_nn::QNet) -> Vec<f32> {
    net.flat_weights()
}

/// The paper's two Adam optimisers (section 3.1, "two Adam optimizers are used"; the authors'
/// code): with `aux_optimizer = "separate"` a weight both losses reach takes one Adam step per
/// loss, each scaled by its own moments. Adam's first step moves a weight by ≈ lr · sign(g),
/// so after one update a shared weight that both losses push the same way has moved by ≈ 2 lr,
/// and by ≈ 0 where they disagree; with one Adam on the sum nothing moves by more than ≈ lr.
/// On the host kernels and on burn's autodiff alike.
#[test]
fn the_auxiliary_loss_has_its_own_adam() {
    let lr = 1e-3;
    let mut rng = Rng::seed_from_u64(4);
    let b = batch(6, &[0.0; 6], &mut rng, true);
    for (mode, host) in [
        (AuxOptimizer::Separate, true),
        (AuxOptimizer::Separate, false),
        (AuxOptimizer::Joint, true),
    ] {
        let cfg = TrainConfig {
            variant: Variant::Mdrlat,
            learning_rate: lr,
            aux_optimizer: mode,
            ..TrainConfig::default()
        };
        let mut learner = Learner::new(&cfg, Task::Avoid, &Device::flex());
        learner.set_host_kernels(host);
        let before = weights(&learner.policy_net());
        learner.update(&b);
        let after = weights(&learner.policy_net());
        assert_eq!(before.len(), after.len());
        let steps: Vec<f64> =
            before.iter().zip(&after).map(|(x, y)| f64::from((y - x).abs()) / lr).collect();
        let largest = steps.iter().copied().fold(0.0, f64::max);
        let double = steps.iter().filter(|&&s| s > 1.5).count();
        let label = format!("{mode:?}, host kernels {host}");
        match mode {
            AuxOptimizer::Separate => {
                assert!((1.9..2.1).contains(&largest), "{label}: largest step {largest} lr");
                // Weights that feed both heads and both losses push the same way.
                assert!(
                    double > steps.len() / 20,
                    "{label}: {double} of {} moved 2 lr",
                    steps.len()
                );
            }
            AuxOptimizer::Joint => {
                assert!(largest < 1.05, "{label}: largest step {largest} lr");
                assert_eq!(double, 0, "{label}");
            }
        }
    }
}

/// A checkpoint of one optimiser layout does not load as the other, and says why.
#[test]
fn a_checkpoint_keeps_its_optimisers() {
    let dir = std::env::temp_dir().join(format!("mdrlat-aux-adam-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let mut rng = Rng::seed_from_u64(5);
    let b = batch(4, &[0.0; 4], &mut rng, true);
    let config = |aux_optimizer| TrainConfig {
        variant: Variant::MultiAt,
        aux_optimizer,
        ..TrainConfig::default()
    };
    let device = Device::flex();
    for (saved, asked, file) in [
        (AuxOptimizer::Separate, AuxOptimizer::Joint, "optimizer-aux.bpk"),
        (AuxOptimizer::Joint, AuxOptimizer::Separate, "optimizer-aux.bpk: missing"),
    ] {
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("dir");
        let mut learner = Learner::new(&config(saved), Task::Avoid, &device);
        learner.update(&b);
        learner.save(&dir).expect("saves");
        let same = Learner::load(&config(saved), Task::Avoid, &device, &dir, 1).expect("loads");
        assert_eq!(same.td_targets(&b), learner.td_targets(&b));
        let e = Learner::load(&config(asked), Task::Avoid, &device, &dir, 1).expect_err("other");
        assert!(e.contains(file) && e.contains("aux_optimizer"), "{e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Prioritised replay's importance-sampling weights: the TD loss is the weighted mean of the
/// rows' squared errors, the rows' errors `y − Q(s, a)` come back for the new priorities
/// (none without weights), weights of 1 take the very step of no weights (the same bits),
/// and the host kernels and burn's autodiff agree.
#[test]
fn importance_weights_scale_each_rows_td_loss_and_the_errors_come_back() {
    for variant in [Variant::LaserOnly, Variant::MultiAt] {
        let cfg = TrainConfig { variant, ..TrainConfig::default() };
        let mut rng = Rng::seed_from_u64(5);
        let plain = batch(6, &[0.0, 1.0, 0.0, 0.0, 0.0, 1.0], &mut rng, variant.uses_depth());
        let ones = Batch { weights: vec![1.0; 6], ..plain.clone() };
        let w = vec![1.0, 0.5, 0.25, 1.0, 0.1, 0.75];
        let weighted = Batch { weights: w.clone(), ..plain.clone() };
        let mut errors = Vec::new();
        for host in [true, false] {
            let learner = || {
                let mut l = Learner::new(&cfg, Task::Avoid, &Device::flex());
                l.set_host_kernels(host);
                l
            };
            let (mut a, mut b, mut c) = (learner(), learner(), learner());
            let la = a.update(&plain);
            assert!(a.td_errors().is_empty(), "no weights, no errors");
            let lb = b.update(&ones);
            if host {
                assert_eq!(la, lb, "weights of 1 are no weights");
                assert_eq!(weights(&a.policy_net()), weights(&b.policy_net()));
            } else {
                assert!((la.td - lb.td).abs() <= 1e-6 * la.td.abs().max(1.0));
            }
            // The errors of the unweighted step, and the loss they make with the weights.
            let e = b.td_errors().to_vec();
            assert_eq!(e.len(), 6);
            let expect = e.iter().zip(&w).map(|(e, w)| w * e * e).sum::<f32>() / 6.0;
            let lc = c.update(&weighted);
            assert!(
                (lc.td - expect).abs() <= 1e-4 * expect.max(1.0),
                "{variant}: {} vs {expect}",
                lc.td
            );
            assert_eq!(c.td_errors().len(), 6);
            errors.push(e);
        }
        let worst =
            errors[0].iter().zip(&errors[1]).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "{variant}: host and autodiff errors differ by {worst}");
    }
}
