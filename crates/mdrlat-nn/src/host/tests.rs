//! The host kernels against burn: the same Q-values and velocity estimates as burn's forward,
//! and the same gradients as burn's autodiff, for every variant.

use super::*;
use crate::Variant;
use burn::optim::GradientsParams;
use mdrlat_core::Rng;

fn fill(rng: &mut Rng, n: usize, lo: f32, hi: f32) -> Vec<f32> {
    (0..n).map(|_| rng.range_f32(lo, hi)).collect()
}

/// Largest difference relative to the largest magnitude of `want`.
fn relative_error(got: &[f32], want: &[f32]) -> f32 {
    assert_eq!(got.len(), want.len());
    let scale = want.iter().fold(0.0f32, |m, v| m.max(v.abs())).max(1e-6);
    got.iter().zip(want).fold(0.0f32, |m, (a, b)| m.max((a - b).abs())) / scale
}

struct Case {
    config: QNetConfig,
    batch: usize,
    laser: Vec<f32>,
    depth: Vec<f32>,
    goal: Vec<f32>,
}

impl Case {
    fn new(variant: Variant, goal_dim: usize, batch: usize, seed: u64) -> Self {
        let config = QNetConfig::new(variant).with_goal_dim(goal_dim);
        let mut rng = Rng::seed_from_u64(seed);
        let laser =
            if variant.uses_laser() { fill(&mut rng, batch * 4 * 512, 0.0, 1.0) } else { vec![] };
        let depth = if variant.uses_depth() {
            fill(&mut rng, batch * 4 * 128 * 160, 0.0, 1.0)
        } else {
            vec![]
        };
        let goal = fill(&mut rng, batch * goal_dim, -1.0, 1.0);
        Self { config, batch, laser, depth, goal }
    }

    fn inputs(&self) -> HostInputs<'_> {
        HostInputs { batch: self.batch, laser: &self.laser, depth: &self.depth, goal: &self.goal }
    }

    /// burn's Q-values and velocity of `net` on `device`.
    fn burn_forward(&self, net: &QNet, device: &Device) -> (Tensor<2>, Option<Tensor<2>>) {
        let b = self.batch;
        let v = self.config.variant;
        let laser = v.uses_laser().then(|| {
            Tensor::<3>::from_data(TensorData::new(self.laser.clone(), [b, 4, 512]), device)
        });
        let depth = v.uses_depth().then(|| crate::depth_input(&self.depth, b, 128, 160, device));
        let goal = (self.config.goal_dim > 0).then(|| {
            Tensor::<2>::from_data(
                TensorData::new(self.goal.clone(), [b, self.config.goal_dim]),
                device,
            )
        });
        let out = net.forward(laser, depth, goal);
        (out.q, out.velocity)
    }
}

fn values(t: Tensor<2>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().expect("f32")
}

/// The forward pass against burn's, for a batch and for one row (a single decision, whose
/// linear layers read only the weight rows of non-zero inputs).
#[test]
fn host_forward_matches_burn_for_every_variant() {
    let dev = Device::flex();
    for (i, &variant) in Variant::ALL.iter().enumerate() {
        for (goal_dim, batch) in [(0, 3), (3, 3), (0, 1), (3, 1)] {
            let case = Case::new(variant, goal_dim, batch, 10 + i as u64);
            let net = case.config.init_seeded(&dev, 7 + i as u64);
            let host = net.host(&case.config).expect("flex weights are host memory");
            let tape = host.forward(&case.inputs(), true);
            let (q, vel) = case.burn_forward(&net, &dev);
            let err = relative_error(tape.q(), &values(q));
            assert!(err < 1e-5, "{variant} goal {goal_dim} batch {batch}: Q relative error {err}");
            match vel {
                Some(vel) => {
                    let err = relative_error(tape.velocity(), &values(vel));
                    assert!(err < 1e-5, "{variant}: velocity relative error {err}");
                }
                None => assert!(tape.velocity().is_empty()),
            }
            let q_only = host.q_values(&case.inputs());
            assert_eq!(q_only, tape.q(), "{variant}: Q-values without the auxiliary head");
        }
    }
}

#[test]
fn host_gradients_match_burn_autodiff_for_every_variant() {
    let dev = Device::flex().autodiff();
    for (i, &variant) in Variant::ALL.iter().enumerate() {
        for goal_dim in [0, 3] {
            let case = Case::new(variant, goal_dim, 3, 20 + i as u64);
            let net = case.config.init_seeded(&dev, 30 + i as u64);
            let mut rng = Rng::seed_from_u64(40 + i as u64);
            let b = case.batch;
            let dq = fill(&mut rng, b * case.config.actions, -1.0, 1.0);
            let dvel = fill(&mut rng, b * 6, -1.0, 1.0);
            // burn: the gradient of Σ q·dq + Σ velocity·dvel is (dq, dvel) at the outputs.
            let (q, vel) = case.burn_forward(&net, &dev);
            let weight =
                |v: Vec<f32>, n: usize| Tensor::<2>::from_data(TensorData::new(v, [b, n]), &dev);
            let mut loss = (q * weight(dq.clone(), case.config.actions)).sum();
            if let Some(vel) = vel {
                loss = loss + (vel * weight(dvel.clone(), 6)).sum();
            }
            let grads = GradientsParams::from_grads(loss.backward(), &net);
            let host = net.host(&case.config).expect("flex weights are host memory");
            let aux = variant.auxiliary_task();
            let tape = host.forward(&case.inputs(), aux);
            let ours = host.backward(&tape, &dq, aux.then_some(dvel.as_slice()));
            assert_eq!(ours.len(), grads.len(), "{variant}: one gradient per parameter");
            for g in &ours {
                let want = match g.dims.len() {
                    1 => grads.get::<1>(g.id).map(|t| t.into_data()),
                    2 => grads.get::<2>(g.id).map(|t| t.into_data()),
                    3 => grads.get::<3>(g.id).map(|t| t.into_data()),
                    _ => grads.get::<4>(g.id).map(|t| t.into_data()),
                };
                let want = want.expect("burn has this gradient").try_to_vec::<f32>().expect("f32");
                let err = relative_error(&g.values, &want);
                assert!(
                    err < 1e-4,
                    "{variant} goal {goal_dim}: parameter {:?} {:?}: relative error {err}",
                    g.id,
                    g.dims
                );
            }
        }
    }
}

/// A batch stacked with other rows (as the learner stacks s and s') gives the same Q-values
/// for each part, and a backward pass over its first rows the same gradients, as the parts
/// alone.
#[test]
fn stacked_parts_give_each_part_its_own_values_and_gradients() {
    let dev = Device::flex();
    let (now, next) = (Case::new(Variant::Mdrlat, 0, 3, 50), Case::new(Variant::Mdrlat, 0, 2, 51));
    let net = now.config.init_seeded(&dev, 52);
    let host = net.host(&now.config).expect("flex weights are host memory");
    let stacked = host.forward_parts(&[now.inputs(), next.inputs()], 3);
    let alone = host.forward(&now.inputs(), true);
    let actions = now.config.actions;
    assert!(relative_error(&stacked.q()[..3 * actions], alone.q()) < 1e-6);
    assert!(relative_error(&stacked.q()[3 * actions..], &host.q_values(&next.inputs())) < 1e-6);
    assert_eq!(stacked.velocity().len(), 3 * 6);
    assert!(relative_error(stacked.velocity(), alone.velocity()) < 1e-6);
    let mut rng = Rng::seed_from_u64(53);
    let dq = fill(&mut rng, 3 * actions, -1.0, 1.0);
    let dvel = fill(&mut rng, 3 * 6, -1.0, 1.0);
    let a = host.backward(&stacked, &dq, Some(&dvel));
    let b = host.backward(&alone, &dq, Some(&dvel));
    for (a, b) in a.iter().zip(&b) {
        assert_eq!(a.id, b.id);
        assert!(relative_error(&a.values, &b.values) < 1e-5, "{:?}", a.dims);
    }
}

/// bfloat16 weights for inference: Q-values close to the f32 network's (the weights alone
/// are rounded), for every variant; a network without the kernel is not offered.
#[test]
fn bf16_weights_give_nearly_the_f32_q_values() {
    let device = Device::flex();
    for variant in Variant::ALL {
        let case = Case::new(variant, 0, 3, 21);
        let net = case.config.init(&device);
        let f32_net = net.host(&case.config).expect("host");
        let Some(bf16_net) = net.host(&case.config).expect("host").with_bf16_weights() else {
            eprintln!("no AVX-512: bfloat16 inference is not offered here");
            return;
        };
        let (want, got) = (f32_net.q_values(&case.inputs()), bf16_net.q_values(&case.inputs()));
        let err = relative_error(&got, &want);
        assert!(err > 0.0 && err < 2e-2, "{variant}: relative error {err}");
    }
}

/// The blocked transpose of the input gradients against the definition, with a tail block,
/// written and accumulated.
#[test]
fn transpose_into_matches_the_definition() {
    for (din, batch) in [(1, 1), (16, 3), (37, 32), (100, 5)] {
        let dxt: Vec<f32> = (0..din * batch).map(|v| v as f32 * 0.5 - 3.0).collect();
        let want: Vec<f32> = (0..batch * din).map(|i| dxt[(i % din) * batch + i / din]).collect();
        let mut dx = vec![f32::NAN; batch * din];
        transpose_into(&dxt, din, batch, &mut dx, false);
        assert_eq!(dx, want, "{din}x{batch}");
        let base: Vec<f32> = (0..batch * din).map(|i| (i % 7) as f32).collect();
        let mut dx = base.clone();
        transpose_into(&dxt, din, batch, &mut dx, true);
        let sum: Vec<f32> = want.iter().zip(&base).map(|(w, b)| b + w).collect();
        assert_eq!(dx, sum, "{din}x{batch} accumulated");
    }
}
