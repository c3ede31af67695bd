//! Shapes, parameter counts and hand-computed values of the networks.

use mdrlat_nn::burn::module::Module;
use mdrlat_nn::burn::prelude::*;
use mdrlat_nn::{DepthInput, QNetConfig, Variant, bilinear, dueling};

fn device() -> Device {
    Device::flex()
}

#[test]
fn forward_flops_count_every_layer() {
    // MDRLAT by hand (multiply-adds): depth convs 2,867,200 + 655,360 + 737,280; laser convs
    // 40,960 + 98,304 + 98,304; fusion 327,680 + 65,536 + 8,192 x 513; heads 3 x 4096 x 512
    // + 512 x 11 + 512 x 6 = 15,393,280, i.e. 30.8 MFLOP (the figure).
    assert_eq!(QNetConfig::new(Variant::Mdrlat).forward_flops(), 2 * 15_393_280);
    // Laser-only: the laser convs and two heads on h = 1024.
    assert_eq!(
        QNetConfig::new(Variant::LaserOnly).forward_flops(),
        2 * (237_568 + 2 * 1024 * 512 + 512 * 11)
    );
    // A decision skips the auxiliary head: 4096 x 512 + 512 x 6 fewer multiply-adds.
    assert_eq!(QNetConfig::new(Variant::Mdrlat).decision_flops(), 2 * 13_293_056);
    assert_eq!(
        QNetConfig::new(Variant::Multi).decision_flops(),
        QNetConfig::new(Variant::Multi).forward_flops()
    );
    let f = |v| QNetConfig::new(v).forward_flops();
    assert!(f(Variant::Multi) < f(Variant::MultiAt) && f(Variant::MultiAt) < f(Variant::Mdrlat));
    assert!(f(Variant::Multi) < f(Variant::MultiBf) && f(Variant::MultiBf) < f(Variant::Mdrlat));
}

#[test]
fn parameter_counts_match_the_paper_architecture() {
    // MDRLAT, laser-only and multi from the issue; the others computed by hand:
    // depth-only = 26,448 (convs) + 1,311,745 (V) + 1,316,362 (A);
    // multi-at = multi + AT head on h = 3584 (1,835,520 + 3,078);
    // multi-bf = MDRLAT − AT head on h = 4096 (2,097,664 + 3,078).
    let expected = [
        (Variant::LaserOnly, 1_060_251),
        (Variant::DepthOnly, 2_654_555),
        (Variant::Multi, 3_708_139),
        (Variant::MultiAt, 5_546_737),
        (Variant::MultiBf, 8_820_651),
        (Variant::Mdrlat, 10_921_393),
    ];
    for (variant, count) in expected {
        let net = QNetConfig::new(variant).init(&device());
        assert_eq!(net.num_params(), count, "{variant}");
    }
}

#[test]
fn every_intermediate_shape() {
    let dev = device();
    let b = 2;
    for variant in Variant::ALL {
        let cfg = QNetConfig::new(variant);
        let net = cfg.init(&dev);
        let laser = variant.uses_laser().then(|| Tensor::<3>::zeros([b, 4, 512], &dev));
        let depth = variant
            .uses_depth()
            .then(|| DepthInput::Patches(Tensor::<4>::zeros([b, 16, 20, 560], &dev)));
        let h = net.representation(laser.clone(), depth.clone(), None);
        let expect_h = match variant {
            Variant::LaserOnly => 1024,
            Variant::DepthOnly => 2560,
            Variant::Multi | Variant::MultiAt => 3584,
            Variant::MultiBf | Variant::Mdrlat => 4096,
        };
        assert_eq!(h.dims(), [b, expect_h], "{variant}");
        assert_eq!(cfg.representation(), expect_h);
        let q_only = net.q_values(laser.clone(), depth.clone(), None);
        let out = net.forward(laser, depth, None);
        assert_eq!(out.q.dims(), [b, 10]);
        let values = |t: Tensor<2>| t.into_data().try_to_vec::<f32>().expect("f32");
        assert_eq!(values(q_only), values(out.q.clone()), "{variant}: q_values = forward().q");
        assert_eq!(out.velocity.map(|v| v.dims()), variant.auxiliary_task().then_some([b, 6]));
    }
    let cfg = QNetConfig::new(Variant::Mdrlat);
    assert_eq!((cfg.depth_features(), cfg.laser_features()), (2560, 1024));
    // Navigation: the goal (distance, sin, cos) joins the representation.
    let nav = QNetConfig::new(Variant::Mdrlat).with_goal_dim(3);
    let net = nav.init(&dev);
    let h = net.representation(
        Some(Tensor::zeros([1, 4, 512], &dev)),
        Some(DepthInput::Stacks(Tensor::zeros([1, 4, 128, 160], &dev))),
        Some(Tensor::zeros([1, 3], &dev)),
    );
    assert_eq!(h.dims(), [1, 4099]);
    // A reduced depth size (for quick tests) keeps SAME-padding arithmetic.
    let small = QNetConfig::new(Variant::DepthOnly).with_depth_rows(32).with_depth_cols(40);
    assert_eq!(small.depth_features(), 32 * 2 * 3);
}

fn values(t: Tensor<2>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().expect("f32 data")
}

#[test]
fn dueling_combination_eq11_by_hand() {
    let dev = device();
    let v = Tensor::<2>::from_data(TensorData::new(vec![1.0f32, -2.0], [2, 1]), &dev);
    let a = Tensor::<2>::from_data(
        TensorData::new(vec![1.0f32, 2.0, 3.0, 0.0, 0.0, 6.0], [2, 3]),
        &dev,
    );
    // Row 0: mean A = 2 → Q = 1 + (A − 2) = [0, 1, 2]; row 1: mean 2 → −2 + (A − 2) = [−4, −4, 2].
    assert_eq!(values(dueling(v, a)), [0.0, 1.0, 2.0, -4.0, -4.0, 2.0]);
}

#[test]
fn bilinear_product_eqs7_8_by_hand() {
    let dev = device();
    let d = Tensor::<2>::from_data(TensorData::new(vec![1.0f32, 2.0, 3.0], [1, 3]), &dev);
    let l = Tensor::<2>::from_data(TensorData::new(vec![10.0f32, -1.0], [1, 2]), &dev);
    // vec(d lᵀ), entry i·L_l + j = d_i l_j.
    assert_eq!(values(bilinear(d, l)), [10.0, -1.0, 20.0, -2.0, 30.0, -3.0]);
}

#[test]
fn variants_parse_and_print() {
    for v in Variant::ALL {
        assert_eq!(v.name().parse::<Variant>(), Ok(v));
    }
    let e = "mdrlat2".parse::<Variant>().expect_err("unknown");
    assert!(e.to_string().contains("mdrlat2") && e.to_string().contains("laser-only"));
}

#[test]
fn seeded_init_is_reproducible_and_bounded() {
    let dev = device();
    let cfg = QNetConfig::new(Variant::LaserOnly);
    let a = cfg.init_seeded(&dev, 3);
    let b = cfg.init_seeded(&dev, 3);
    let c = cfg.init_seeded(&dev, 4);
    let x = Tensor::<3>::ones([1, 4, 512], &dev);
    let qa = values(a.forward(Some(x.clone()), None, None).q);
    assert_eq!(qa, values(b.forward(Some(x.clone()), None, None).q));
    assert_ne!(qa, values(c.forward(Some(x), None, None).q));
    assert_eq!(a.num_params(), 1_060_251);
}
