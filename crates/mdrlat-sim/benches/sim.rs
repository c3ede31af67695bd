//! Criterion benches named after the goal they serve: env steps per second with full
//! sensors (target: >= 20,000 steps/s on 2 cores in `train`, SPEC/issue 3).

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use mdrlat_core::Action;
use mdrlat_sim::{Env, SimConfig, StaticScene, VecEnv};
use std::hint::black_box;
use std::sync::Arc;

fn env_for(name: &str) -> Env {
    let world = mdrlat_world::builtin::get(name).expect("builtin").expect("valid");
    let mut env = Env::from_world(world, SimConfig::default()).expect("env");
    env.reset(Some(0)).expect("reset");
    env
}

fn step_one_env(c: &mut Criterion) {
    let mut g = c.benchmark_group("sim_steps_per_s_one_env");
    g.throughput(Throughput::Elements(1));
    for world in ["train", "crowd"] {
        let mut env = env_for(world);
        let mut t = 0usize;
        g.bench_function(world, |b| {
            b.iter(|| {
                t += 1;
                let a = Action::new([1, 5, 8, 2, 0][t % 5]).expect("action");
                let s = env.step(a).expect("step");
                let done = s.terminated || s.truncated;
                black_box(s.reward);
                if done {
                    env.reset(None).expect("reset");
                }
            })
        });
    }
    g.finish();
}

fn sensors_only(c: &mut Criterion) {
    let mut g = c.benchmark_group("sim_sensor_frame");
    let env = env_for("train");
    let pose = env.pose();
    let mut env2 = env.clone();
    g.bench_function("reset_at_pose_two_sensors_train", |b| {
        b.iter(|| {
            env2.reset_with(None, Some(pose)).expect("reset");
        })
    });
    let scene = env.scene().clone();
    let mut rng = mdrlat_core::Rng::seed_from_u64(0);
    let mut laser = mdrlat_sim::sensors::Laser::new(&env.config().laser);
    let mut ranges = vec![0.0; mdrlat_core::LASER_BEAMS];
    g.bench_function("laser_train", |b| {
        b.iter(|| laser.scan(&scene, &[], &pose, &mut rng, &mut ranges))
    });
    let mut cam = mdrlat_sim::sensors::DepthCamera::new(&env.config().depth);
    let mut image = vec![0.0; mdrlat_core::DEPTH_LEN];
    g.bench_function("depth_train", |b| {
        b.iter(|| cam.capture(&scene, &[], &pose, &mut rng, &mut image))
    });
    g.finish();
}

fn step_vec_env(c: &mut Criterion) {
    let mut g = c.benchmark_group("sim_steps_per_s_vec_env");
    let n = 16;
    g.throughput(Throughput::Elements(n as u64));
    for world in ["train", "crowd"] {
        let config = SimConfig::default();
        let w = mdrlat_world::builtin::get(world).expect("builtin").expect("valid");
        let scene = Arc::new(StaticScene::new(Arc::new(w), &config));
        let mut venv = VecEnv::new(scene, config, n, 0).expect("venv");
        venv.reset(0).expect("reset");
        let mut t = 0usize;
        g.bench_function(world, |b| {
            b.iter(|| {
                t += 1;
                let actions: Vec<Action> =
                    (0..n).map(|i| Action::new((t + i) % 10).expect("action")).collect();
                black_box(venv.step(&actions).expect("step").len());
            })
        });
    }
    g.finish();
}

criterion_group!(benches, step_one_env, sensors_only, step_vec_env);
criterion_main!(benches);
