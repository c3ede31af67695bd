//! The network behind the one `Policy` interface: batched decisions equal one-at-a-time
//! decisions, inputs go through the shared normalisation, bad checkpoints are errors.

use mdrlat_core::{Action, Decision, FRAME_STACK, Observation, Policy, Rng};
use mdrlat_nn::Variant;
use mdrlat_nn::burn::prelude::Device;
use mdrlat_sim::config::Task;
use mdrlat_train::{GreedyPolicy, Inputs, observation_inputs};

fn observation(rng: &mut Rng) -> Observation {
    let mut obs = Observation::zeros();
    for _ in 0..FRAME_STACK {
        for r in obs.laser.push_slot() {
            *r = rng.range_f32(0.2, 5.6);
        }
        for d in obs.depth.push_slot() {
            *d = if rng.below(10) == 0 { 0.0 } else { rng.range_f32(0.4, 9.0) };
        }
    }
    obs
}

#[test]
fn a_decision_does_not_depend_on_the_batch_it_is_in() {
    let mut rng = Rng::seed_from_u64(3);
    let observations: Vec<Observation> = (0..40).map(|_| observation(&mut rng)).collect();
    let batch: Vec<&Observation> = observations.iter().collect();
    let zero = Observation::zeros();
    for variant in [Variant::LaserOnly, Variant::Mdrlat] {
        let mut policy =
            GreedyPolicy::untrained(variant, Task::Avoid, 7, &Device::flex(), 2).expect("policy");
        let mut inputs = Inputs::default();
        observation_inputs(&batch, policy.config(), &mut inputs).expect("inputs");
        let all = policy.q_values(&inputs).expect("q");
        for (i, obs) in batch.iter().enumerate() {
            // Alone, padded to the batch size with other rows of zeros... at another position.
            let mut padded: Vec<&Observation> = vec![&zero; batch.len()];
            padded[(i + 7) % batch.len()] = obs;
            observation_inputs(&padded, policy.config(), &mut inputs).expect("inputs");
            let one = policy.q_values(&inputs).expect("q");
            let j = (i + 7) % batch.len();
            assert_eq!(
                one[j * 10..(j + 1) * 10],
                all[i * 10..(i + 1) * 10],
                "{variant}: row {i} differs padded"
            );
        }
        let slots: Vec<usize> = (0..batch.len()).collect();
        let mut actions = Vec::new();
        policy.decide(&batch, &slots, &mut actions).expect("acts");
        assert_eq!(actions.len(), batch.len());
        let mut greedy = Vec::new();
        mdrlat_core::greedy_actions(&all, batch.len(), &mut greedy).expect("finite");
        assert_eq!(actions, greedy.into_iter().map(Decision::from).collect::<Vec<_>>());
        assert!(actions.iter().all(|d| d.action.index() < Action::COUNT));

        // In forwards of a fixed size, any sub-batch decides as the whole batch did.
        let mut fixed = GreedyPolicy::untrained(variant, Task::Avoid, 7, &Device::flex(), 2)
            .expect("policy")
            .with_forward_batch(Some(16));
        let mut whole = Vec::new();
        fixed.decide(&batch, &slots, &mut whole).expect("acts");
        for (start, len) in [(0, 1), (3, 5), (10, 17), (1, 39)] {
            let sub = &batch[start..start + len];
            let mut part = Vec::new();
            fixed.decide(sub, &slots[start..start + len], &mut part).expect("acts");
            assert_eq!(part, whole[start..start + len], "{variant}: {start}+{len}");
        }
    }
}

#[test]
fn missing_and_corrupt_checkpoints_are_errors_naming_the_path() {
    let dir = std::env::temp_dir().join(format!("mdrlat-policy-{}", std::process::id()));
    let device = Device::flex();
    let e = GreedyPolicy::load(&dir.join("nope"), &device, 1).expect_err("missing");
    assert!(e.contains("nope") && e.contains("no such"), "{e}");
    std::fs::create_dir_all(dir.join("checkpoint")).expect("dir");
    let e = GreedyPolicy::load(&dir, &device, 1).expect_err("empty");
    assert!(e.contains("no checkpoint here"), "{e}");
    std::fs::write(dir.join("checkpoint/meta.json"), "{ not json").expect("write");
    let e = GreedyPolicy::load(&dir, &device, 1).expect_err("corrupt");
    assert!(e.contains("meta.json"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_model_stored_in_f16_loads_back_and_decides_alike() {
    use mdrlat_train::export::{Precision, compare_q, load_safetensors, save_safetensors_as};
    let dir = std::env::temp_dir().join(format!("mdrlat-f16-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let mut rng = Rng::seed_from_u64(5);
    let observations: Vec<Observation> = (0..70).map(|_| observation(&mut rng)).collect();
    for variant in [Variant::LaserOnly, Variant::MultiAt] {
        let device = Device::flex();
        let original =
            GreedyPolicy::untrained(variant, Task::Avoid, 11, &device, 1).expect("policy");
        let (f32_path, f16_path) = (dir.join("f32.safetensors"), dir.join("model.safetensors"));
        let step = [("mdrlat_step", "1234".to_string())];
        save_safetensors_as(original.net(), original.config(), &f32_path, Precision::F32, &step)
            .expect("f32");
        save_safetensors_as(original.net(), original.config(), &f16_path, Precision::F16, &step)
            .expect("f16");
        let (s32, s16) = (
            std::fs::metadata(&f32_path).expect("f32").len(),
            std::fs::metadata(&f16_path).expect("f16").len(),
        );
        assert!(s16 * 2 < s32 + 4096, "f16 halves the file: {s16} vs {s32}");
        // The model file has the permissions of any new file (others may read a model on a
        // shared machine), and no temporary file is left beside it.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let plain = dir.join("plain");
            std::fs::write(&plain, b"x").expect("plain");
            let mode = |p: &std::path::Path| {
                std::fs::metadata(p).expect("metadata").permissions().mode() & 0o777
            };
            assert_eq!(mode(&f32_path), mode(&plain), "model.safetensors permissions");
            let names: Vec<String> = std::fs::read_dir(&dir)
                .expect("dir")
                .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
                .collect();
            assert!(names.iter().all(|n| !n.ends_with(".tmp")), "left behind: {names:?}");
        }
        // f32 round trip: the same Q-values exactly.
        let same = GreedyPolicy::load(&f32_path, &device, 1).expect("load f32");
        let d = compare_q(&original, &same, &observations).expect("compare");
        assert_eq!((d.max_abs, d.same_action), (0.0, observations.len()), "{d:?}");
        // f16 (loaded through the folder, as `models/…`): close, computed in f32.
        let stored = GreedyPolicy::load(&dir, &device, 1).expect("load the model folder");
        assert!(stored.source().contains("(step 1234)"), "{}", stored.source());
        assert_eq!(stored.variant(), variant);
        let d = compare_q(&original, &stored, &observations).expect("compare");
        assert!(d.max_abs > 0.0 && d.max_abs < 1e-2 * d.max_q.max(1.0), "{d:?}");
        let (c, _, meta) = load_safetensors(&f16_path, &device).expect("load");
        assert_eq!((c.variant, c.goal_dim), (variant, 0));
        assert_eq!(meta.get("mdrlat_step").map(String::as_str), Some("1234"));
    }
    // Not a model: errors naming the file.
    let junk = dir.join("junk.safetensors");
    std::fs::write(&junk, b"not a safetensors file").expect("junk");
    let e = GreedyPolicy::load(&junk, &Device::flex(), 1).expect_err("junk");
    assert!(e.contains("junk.safetensors"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bf16_weights_are_an_opt_in_that_decides_nearly_alike() {
    use mdrlat_train::export::compare_q;
    let mut rng = Rng::seed_from_u64(8);
    let observations: Vec<Observation> = (0..64).map(|_| observation(&mut rng)).collect();
    let device = Device::flex();
    let f32_policy =
        GreedyPolicy::untrained(Variant::Mdrlat, Task::Avoid, 3, &device, 1).expect("policy");
    let bf16 = GreedyPolicy::untrained(Variant::Mdrlat, Task::Avoid, 3, &device, 1)
        .expect("policy")
        .with_bf16_weights();
    let bf16 = match bf16 {
        Ok(p) => p,
        Err(e) => {
            assert!(e.contains("AVX-512"), "{e}");
            return;
        }
    };
    assert!(bf16.source().ends_with("bf16 weights"), "{}", bf16.source());
    let d = compare_q(&f32_policy, &bf16, &observations).expect("compare");
    assert!(d.max_abs > 0.0 && d.max_abs < 2e-2 * d.max_q.max(1e-3), "{d:?}");
    assert!(d.same_action * 10 >= observations.len() * 9, "{d:?}");
}

/// A one-thread policy runs a single decision on the calling thread, not in its pool: the
/// same Q-values and action as a two-thread policy's, whether it is called from a plain
/// thread or from inside another rayon pool, for every variant.
#[test]
fn a_single_decision_on_the_calling_thread_decides_as_the_pool_does() {
    let mut rng = Rng::seed_from_u64(5);
    let obs = observation(&mut rng);
    let other = rayon::ThreadPoolBuilder::new().num_threads(2).build().expect("pool");
    for variant in Variant::ALL {
        let dev = Device::flex();
        let mut one = GreedyPolicy::untrained(variant, Task::Avoid, 9, &dev, 1).expect("policy");
        let mut two = GreedyPolicy::untrained(variant, Task::Avoid, 9, &dev, 2).expect("policy");
        let mut inputs = Inputs::default();
        observation_inputs(&[&obs], one.config(), &mut inputs).expect("inputs");
        let want = two.q_values(&inputs).expect("q");
        assert_eq!(one.q_values(&inputs).expect("q"), want, "{variant}");
        assert_eq!(other.install(|| one.q_values(&inputs)).expect("q"), want, "{variant} nested");
        let (mut a, mut b) = (Vec::new(), Vec::new());
        one.decide(&[&obs], &[0], &mut a).expect("acts");
        two.decide(&[&obs], &[0], &mut b).expect("acts");
        assert_eq!(a, b, "{variant}");
    }
}

/// One observation's decision, which may skip the value head (`HostNet::decide_one`),
/// is the greedy action of its Q-values, for every variant and a goal input.
#[test]
fn a_single_decision_is_the_greedy_action_of_its_q_values() {
    let mut rng = Rng::seed_from_u64(8);
    let observations: Vec<Observation> = (0..6).map(|_| observation(&mut rng)).collect();
    for variant in Variant::ALL {
        let mut policy =
            GreedyPolicy::untrained(variant, Task::Avoid, 4, &Device::flex(), 1).expect("policy");
        let mut inputs = Inputs::default();
        for obs in &observations {
            observation_inputs(&[obs], policy.config(), &mut inputs).expect("inputs");
            let mut want = Vec::new();
            mdrlat_core::greedy_actions(&policy.q_values(&inputs).expect("q"), 1, &mut want)
                .expect("finite");
            let want: Vec<Decision> = want.into_iter().map(Decision::from).collect();
            let mut got = Vec::new();
            policy.decide(&[obs], &[0], &mut got).expect("acts");
            assert_eq!(got, want, "{variant}");
        }
    }
}

/// A single observation with frames of the wrong size is an error naming the input, not a
/// panic of the network (the one-observation path checks sizes as the batched one does).
#[test]
fn a_single_observation_of_the_wrong_size_is_an_error_naming_it() {
    let mut policy =
        GreedyPolicy::untrained(Variant::LaserOnly, Task::Avoid, 1, &Device::flex(), 1)
            .expect("policy");
    let mut obs = Observation::zeros();
    obs.laser = mdrlat_core::FrameStack::new(100);
    let mut out = Vec::new();
    let e = policy.decide(&[&obs], &[0], &mut out).expect_err("wrong size");
    assert!(e.to_string().contains("laser input has 400 values"), "{e}");
}
