//! `mdrlat_train::diagnose`: its sums are what they say. With γ = 0 the return of a step is
//! its reward, so the mean return equals the sum of the mean reward terms and every TD target
//! is the reward; every decision is counted once, by its action.

use mdrlat_nn::Variant;
use mdrlat_nn::burn::prelude::Device;
use mdrlat_sim::SimConfig;
use mdrlat_sim::config::Task;
use mdrlat_train::GreedyPolicy;
use mdrlat_train::diagnose::{diagnose_world, markdown};

#[test]
fn a_diagnosis_adds_up() {
    let device = Device::flex();
    let policy =
        GreedyPolicy::untrained(Variant::LaserOnly, Task::Avoid, 3, &device, 1).expect("policy");
    let world = mdrlat_world::builtin::get("train").expect("builtin").expect("valid");
    let sim = SimConfig::default();
    let d = diagnose_world(&policy, &world, &sim, 6, 80, 0, 0.0).expect("diagnosis");
    assert_eq!(d.episodes, 6);
    assert!(d.steps > 0 && d.steps <= 6 * 80, "{} steps", d.steps);
    let counted: u64 = d.td_by_action.iter().map(|&(n, _)| n).sum();
    assert_eq!(counted, d.steps, "every decision counted once");
    let terms: f64 = d.terms.iter().sum();
    assert!((d.return_mean - terms).abs() < 1e-4, "γ = 0: G = r ({} vs {terms})", d.return_mean);
    // The collision term is the penalty times the collisions, per step.
    let crash = -10.0 * f64::from(d.collisions) / d.steps as f64;
    assert!((d.terms[1] - crash).abs() < 1e-6, "{} vs {crash}", d.terms[1]);
    if d.collisions > 0 {
        assert!(d.return_before_collision.is_finite() && d.q_before_collision.is_finite());
    }
    // The same episodes, the same diagnosis; discounting changes the returns, not the Q-values.
    let again = diagnose_world(&policy, &world, &sim, 6, 80, 0, 0.0).expect("again");
    assert_eq!(format!("{again:?}"), format!("{d:?}"), "NaN-aware: the same numbers");
    let discounted = diagnose_world(&policy, &world, &sim, 6, 80, 0, 0.99).expect("γ");
    assert_eq!((discounted.q_mean, discounted.steps), (d.q_mean, d.steps));
    assert_ne!(discounted.return_mean, d.return_mean);
    let report = markdown("an untrained network", 0.99, &[d, discounted]);
    assert!(report.contains("| train | 6 |") && report.contains("angular swing"), "{report}");
}
