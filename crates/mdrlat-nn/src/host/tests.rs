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

/// A single decision from the advantage head alone is the Q-values' greedy action whenever
/// it is offered, for every variant (and a goal input), and it is offered for most inputs;
/// otherwise the Q-values are those of the whole forward, bit for bit (also with a bound
/// that never lets the advantages decide).
#[test]
fn the_advantage_head_alone_decides_as_the_q_values_do() {
    let device = Device::flex();
    let cases = Variant::ALL.iter().map(|&v| (v, 0)).chain([(Variant::Mdrlat, 3)]);
    for (variant, goal_dim) in cases {
        let config = QNetConfig::new(variant).with_goal_dim(goal_dim);
        let host = config.init(&device).host(&config).expect("host");
        let bound = *host.value_bound();
        let mut decided = 0;
        for seed in 0..8 {
            let case = Case::new(variant, goal_dim, 1, 100 + seed);
            let q = host.q_values(&case.inputs());
            let mut want = Vec::new();
            mdrlat_core::greedy_actions(&q, 1, &mut want).expect("finite");
            match host.decide_one(&case.inputs()) {
                OneDecision::Advantages(a) => {
                    let mut best = Vec::new();
                    mdrlat_core::greedy_actions(&a, 1, &mut best).expect("finite");
                    assert_eq!(best, want, "{variant}, goal {goal_dim}, seed {seed}");
                    decided += 1;
                }
                OneDecision::QValues(got) => assert_eq!(got, q, "{variant}, seed {seed}"),
            }
        }
        assert!(decided >= 4, "{variant}: only {decided} of 8 decided without the value head");
        let never = ValueBound { hidden_w: f64::INFINITY, ..bound };
        let case = Case::new(variant, goal_dim, 1, 99);
        let want = OneDecision::QValues(host.q_values(&case.inputs()));
        assert_eq!(host.decide_one_with(&case.inputs(), &never), want, "{variant}");
    }
}

/// Where eq. (11)'s rounding could reorder two advantages, nothing is decided: here `V +
/// A` rounds two different advantages to the same Q-value and the greedy rule then picks
/// the first, not the larger. Non-finite inputs decide nothing either.
#[test]
fn the_value_bound_refuses_what_rounding_could_reorder() {
    let bound =
        ValueBound { hidden_w: 1.0, hidden_b: 0.0, hidden_k: 5, out_w: 1.0, out_b: 0.0, out_k: 5 };
    // |V| ≤ ~1000 for a representation of norm 1000; an f32 step there is 6.1e-5.
    let close = [0.0, 3e-5, -0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let q = dueling(&[1000.0], &close, 1);
    let mut picked = Vec::new();
    mdrlat_core::greedy_actions(&q, 1, &mut picked).expect("finite");
    assert_eq!(picked[0].index(), 0, "the rounding ties q_0 and q_1: {q:?}");
    assert!(!bound.decides(1000.0, &close));
    // A lead beyond the rounding decides; the same lead at a larger |V| does not.
    let clear = [0.0, 2e-3, -0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert!(bound.decides(1000.0, &clear));
    mdrlat_core::greedy_actions(&clear, 1, &mut picked).expect("finite");
    assert_eq!(picked[0].index(), 1, "the clear lead's action");
    assert!(!bound.decides(1e6, &clear));
    let mut nan = clear;
    nan[4] = f32::NAN;
    assert!(!bound.decides(1000.0, &nan));
    assert!(!bound.decides(f64::INFINITY, &clear));
    assert!(!bound.decides(f64::NAN, &clear));
    // A hidden layer whose f32 sums could overflow decides nothing, even where a tiny
    // output weight would make the bound on V small.
    let tiny_out = ValueBound { out_w: 1e-40, ..bound };
    assert!(tiny_out.decides(1e3, &clear));
    assert!(!tiny_out.decides(1e38, &clear));
}
