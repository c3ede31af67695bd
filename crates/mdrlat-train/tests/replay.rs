//! The replay buffer returns exactly what the environment produced (to the millimetre),
//! across episode boundaries and wrap-around, in well under 1 GiB.

use mdrlat_core::{
    Action, DEPTH_LEN, FRAME_STACK, LASER_BEAMS, Rng, normalize_depth, normalize_laser,
};
use mdrlat_sim::{Env, Observation, SimConfig};
use mdrlat_train::replay::{Batch, DepthLayout, FrameId, ReplayBuffer, Transition};

fn stacked(obs: &Observation) -> (Vec<f32>, Vec<f32>) {
    let mut l = vec![0.0; FRAME_STACK * LASER_BEAMS];
    let mut d = vec![0.0; FRAME_STACK * DEPTH_LEN];
    obs.laser.write_stacked(&mut l, normalize_laser);
    obs.depth.write_stacked(&mut d, normalize_depth);
    (l, d)
}

/// What the env produced for one step: s_t (laser, depth), s_t+1 (laser, depth), a, r,
/// terminated.
type Expected = (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>, u8, f32, bool);

fn close(a: &[f32], b: &[f32], tol: f32) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
}

#[test]
fn sampled_transitions_equal_what_the_env_produced() {
    sampled_transitions_equal(true, true);
}

/// A buffer of one sensor (laser-only and depth-only runs) samples that sensor's stacks in
/// full and leaves the other's empty.
#[test]
fn a_one_sensor_buffer_samples_its_sensor() {
    sampled_transitions_equal(true, false);
    sampled_transitions_equal(false, true);
}

fn sampled_transitions_equal(keep_laser: bool, keep_depth: bool) {
    let world = mdrlat_world::builtin::get("train").expect("builtin").expect("valid");
    let sim = SimConfig { max_episode_steps: 23, ..SimConfig::default() };
    let mut env = Env::from_world(world, sim).expect("env");
    env.reset(Some(3)).expect("reset");
    // Small buffer: 40 transitions, so 150 steps wrap it several times.
    let mut buf = ReplayBuffer::new(40, 8, keep_laser, keep_depth);
    let first = buf.push_frame(env.observation().laser.latest(), env.observation().depth.latest());
    let mut stack: [FrameId; 4] = [first; 4];
    let mut expected: Vec<Expected> = Vec::new();
    let mut rng = Rng::seed_from_u64(9);
    let mut episodes = 0;
    for _ in 0..150 {
        let (l0, d0) = stacked(env.observation());
        let a = rng.below(10);
        let s = env.step(Action::new(a).expect("action")).expect("step");
        let (l1, d1) = stacked(s.observation);
        let (reward, terminated, done) = (s.reward, s.terminated, s.terminated || s.truncated);
        let id = buf.push_frame(s.observation.laser.latest(), s.observation.depth.latest());
        let next = [stack[1], stack[2], stack[3], id];
        buf.push(Transition {
            steps: 1,
            obs: stack,
            next,
            action: a as u8,
            reward,
            terminated,
            odom: [0.0; 6],
            goal: [0.0; 3],
            next_goal: [0.0; 3],
        });
        expected.push((l0, d0, l1, d1, a as u8, reward, terminated));
        if done {
            episodes += 1;
            env.reset(None).expect("reset");
            let f =
                buf.push_frame(env.observation().laser.latest(), env.observation().depth.latest());
            stack = [f; 4];
        } else {
            stack = next;
        }
    }
    assert!(episodes >= 5, "crossed episode boundaries: {episodes}");
    assert!(buf.len() <= 40 && buf.len() >= 30, "held {}", buf.len());
    // The buffer holds the most recent transitions, oldest first.
    let held = &expected[expected.len() - buf.len()..];
    let mut batch = Batch::default();
    let all: Vec<usize> = (0..buf.len()).collect();
    buf.write_batch(&all, &mut batch);
    let (ls, ds) = (FRAME_STACK * LASER_BEAMS, FRAME_STACK * DEPTH_LEN);
    // Millimetre storage: 0.5 mm error, i.e. 0.5e-3 / 5.6 laser and 0.5e-3 / 5 depth units.
    let (tl, td) = (0.6e-3 / 5.6, 0.6e-3 / 5.0);
    let n = held.len();
    // Per sensor: kept, its stacks of s_t and s_t+1, their expected values, row length,
    // tolerance.
    let sensors = [
        ("laser", keep_laser, [&batch.laser, &batch.next_laser], [0, 2], ls, tl),
        ("depth", keep_depth, [&batch.depth, &batch.next_depth], [1, 3], ds, td),
    ];
    for (name, kept, stacks, which, len, tol) in sensors {
        for (v, w) in stacks.into_iter().zip(which) {
            assert_eq!(v.len(), if kept { n * len } else { 0 }, "{name}");
            if !kept {
                continue;
            }
            for (row, e) in held.iter().enumerate() {
                let want = [&e.0, &e.1, &e.2, &e.3][w];
                assert!(close(&v[row * len..(row + 1) * len], want, tol), "{name} {w} row {row}");
            }
        }
    }
    for (row, e) in held.iter().enumerate() {
        assert_eq!(batch.actions[row], i64::from(e.4));
        assert_eq!(batch.rewards[row], e.5);
        assert_eq!(batch.terminated[row] == 1.0, e.6);
    }

    // The same rows with the depth as frames (what a LibTorch learner asks for): rebuilt
    // through the depth table, the stacks hold the same values, bit for bit; each frame is
    // sent once (consecutive transitions share seven of their eight); nothing else changes.
    let mut frames = Batch::default();
    buf.write_batch_as(&all, &mut frames, DepthLayout::Frames);
    let f = &frames.depth_frames;
    if keep_depth {
        assert!(frames.depth.is_empty() && frames.next_depth.is_empty());
        let table = mdrlat_train::replay::depth_table();
        for (rows, stacks) in [(&f.obs, &batch.depth), (&f.next, &batch.next_depth)] {
            assert_eq!(rows.len(), n * FRAME_STACK);
            let rebuilt: Vec<u32> = rows
                .iter()
                .flat_map(|&r| {
                    let r = usize::try_from(r).expect("a row");
                    f.mm[r * DEPTH_LEN..(r + 1) * DEPTH_LEN]
                        .iter()
                        .map(|&mm| table[usize::from(mm)].to_bits())
                })
                .collect();
            let want: Vec<u32> = stacks.iter().map(|v| v.to_bits()).collect();
            assert!(rebuilt == want, "depth rebuilt from frames differs");
        }
        assert!(f.len() < 2 * n, "{} frames sent for {n} transitions", f.len());
    } else {
        assert!(f.is_empty());
    }
    let without_depth = |b: &Batch| Batch {
        depth: vec![],
        next_depth: vec![],
        depth_frames: Default::default(),
        ..b.clone()
    };
    assert_eq!(without_depth(&frames), without_depth(&batch));
}

#[test]
fn twenty_thousand_transitions_fit_well_under_a_gibibyte() {
    let reserve = mdrlat_train::checkpoint::frame_reserve(20_000);
    let buf = ReplayBuffer::new(20_000, reserve, true, true);
    let bytes = buf.memory_bytes();
    // 22,500 frames x (40,960 + 1,024) bytes + the transition records.
    assert!(bytes < 1024 * 1024 * 1024, "{bytes} bytes");
    let naive = 20_000usize * 2 * FRAME_STACK * (DEPTH_LEN + LASER_BEAMS) * 4;
    assert!(naive / bytes >= 13, "naive {naive} vs {bytes}");
    // A laser-only run keeps no depth.
    assert!(ReplayBuffer::new(20_000, reserve, true, false).memory_bytes() < 30 * 1024 * 1024);
}

#[test]
fn short_episodes_still_fill_the_buffer() {
    // Episodes of 8 steps (9 frames each) with the default reserve keep the full capacity.
    let capacity = 800;
    let mut buf =
        ReplayBuffer::new(capacity, mdrlat_train::checkpoint::frame_reserve(capacity), true, false);
    let laser = vec![1.0; 512];
    for _ in 0..500 {
        let first = buf.push_frame(&laser, &[]);
        let mut stack = [first; 4];
        for _ in 0..8 {
            let id = buf.push_frame(&laser, &[]);
            let next = [stack[1], stack[2], stack[3], id];
            buf.push(Transition {
                steps: 1,
                obs: stack,
                next,
                action: 0,
                reward: 0.0,
                terminated: false,
                odom: [0.0; 6],
                goal: [0.0; 3],
                next_goal: [0.0; 3],
            });
            stack = next;
        }
    }
    assert_eq!(buf.len(), capacity);
}

/// A small laser-only buffer of `n` chained transitions, with goals or without.
fn small_buffer(n: usize, goals: bool) -> ReplayBuffer {
    let mut buf = ReplayBuffer::new(16, 64, true, false).with_goals(goals);
    let laser = vec![1.5f32; LASER_BEAMS];
    let first = buf.push_frame(&laser, &[]);
    let mut stack = [first; FRAME_STACK];
    for k in 0..n {
        let id = buf.push_frame(&laser, &[]);
        let next = [stack[1], stack[2], stack[3], id];
        let g = k as f32;
        buf.push(Transition {
            steps: 1,
            obs: stack,
            next,
            action: (k % 10) as u8,
            reward: 0.5,
            terminated: false,
            odom: [0.1; 6],
            goal: [g, 0.6, 0.8],
            next_goal: [g + 0.5, 0.0, 1.0],
        });
        stack = next;
    }
    buf
}

#[test]
fn goals_round_trip_and_a_corrupt_goal_file_is_refused() {
    let buf = small_buffer(5, true);
    let mut bytes = Vec::new();
    buf.write_to(&mut bytes).expect("write");
    assert_eq!(&bytes[..8], b"MDRLRB02");
    let read = |b: &[u8], goals: bool| {
        ReplayBuffer::read_from(b, b.len() as u64, 16, 64, true, false, goals, (1, 1))
    };
    let back = read(&bytes, true).expect("read");
    for i in 0..5 {
        assert_eq!(back.get(i), buf.get(i), "transition {i}");
    }
    let mut batch = Batch::default();
    back.write_batch(&[4, 0], &mut batch);
    assert_eq!(batch.goal, [0.4, 0.6, 0.8, 0.0, 0.6, 0.8]);
    assert_eq!(batch.next_goal, [0.45, 0.0, 1.0, 0.05, 0.0, 1.0]);
    // The run must want goals; the flag byte must be 1; the length must fit.
    let e = read(&bytes, false).expect_err("a run without goals").to_string();
    assert!(e.contains("with goals (navigation)"), "{e}");
    let mut flag = bytes.clone();
    flag[8 + 32 + 2] = 7;
    let e = read(&flag, true).expect_err("bad flag").to_string();
    assert!(e.contains("bad goal flag 7"), "{e}");
    let cut = &bytes[..bytes.len() - 4];
    let e = read(cut, true).expect_err("truncated").to_string();
    assert!(e.contains("truncated or corrupt"), "{e}");
    // Obstacle avoidance keeps the old format byte for byte: no flag, no goals.
    let plain = small_buffer(5, false);
    let mut old = Vec::new();
    plain.write_to(&mut old).expect("write");
    assert_eq!(&old[..8], b"MDRLRB01");
    assert_eq!(bytes.len() - old.len(), 1 + 5 * 4 * 2 * 3, "one flag byte, 24 goal bytes each");
    let e = read(&old, true).expect_err("a navigation run").to_string();
    assert!(e.contains("without goals"), "{e}");
}

/// Several environments filling one buffer in turn (`train.envs`), with episodes so short
/// that frames are overwritten before transitions fall out by capacity: every transition
/// still held reads exactly what its environment produced (none refers to a lost frame).
#[test]
fn interleaved_environments_never_read_a_lost_frame() {
    let world = mdrlat_world::builtin::get("train").expect("builtin").expect("valid");
    // One environment with long episodes (its stacks reach four of its steps back) beside
    // two whose episodes end every other step (a fresh frame each time).
    let n_envs = 3;
    let mut envs: Vec<Env> = (0..n_envs)
        .map(|k| {
            let steps = if k == 0 { 40 } else { 2 };
            let sim = SimConfig { max_episode_steps: steps, ..SimConfig::default() };
            let mut env = Env::from_world(world.clone(), sim).expect("env");
            env.reset(Some(10 + k as u64)).expect("reset");
            env
        })
        .collect();
    let mut buf = ReplayBuffer::new(40, 8, true, false).with_envs(n_envs, 1);
    let mut stacks: Vec<[FrameId; 4]> = envs
        .iter()
        .map(|env| {
            let o = env.observation();
            [buf.push_frame(o.laser.latest(), o.depth.latest()); 4]
        })
        .collect();
    let mut expected: Vec<(Vec<f32>, Vec<f32>)> = Vec::new();
    let mut rng = Rng::seed_from_u64(2);
    for _ in 0..200 {
        for (env, stack) in envs.iter_mut().zip(stacks.iter_mut()) {
            let (l0, _) = stacked(env.observation());
            let s = env.step(Action::new(rng.below(10)).expect("action")).expect("step");
            let (l1, _) = stacked(s.observation);
            let done = s.terminated || s.truncated;
            let id = buf.push_frame(s.observation.laser.latest(), s.observation.depth.latest());
            let next = [stack[1], stack[2], stack[3], id];
            buf.push(Transition {
                steps: 1,
                obs: *stack,
                next,
                action: 0,
                reward: 0.0,
                terminated: s.terminated,
                odom: [0.0; 6],
                goal: [0.0; 3],
                next_goal: [0.0; 3],
            });
            expected.push((l0, l1));
            *stack = if done {
                env.reset(None).expect("reset");
                let o = env.observation();
                [buf.push_frame(o.laser.latest(), o.depth.latest()); 4]
            } else {
                next
            };
        }
    }
    assert!(buf.len() >= 10, "held {}", buf.len());
    let held = &expected[expected.len() - buf.len()..];
    let mut batch = Batch::default();
    let all: Vec<usize> = (0..buf.len()).collect();
    buf.write_batch(&all, &mut batch);
    let ls = FRAME_STACK * LASER_BEAMS;
    for (row, (l0, l1)) in held.iter().enumerate() {
        assert!(close(&batch.laser[row * ls..(row + 1) * ls], l0, 0.6e-3 / 5.6), "s row {row}");
        assert!(close(&batch.next_laser[row * ls..(row + 1) * ls], l1, 0.6e-3 / 5.6), "s' {row}");
    }
}
