//! Golden sensor tests on analytic scenes: every expected value is computed by hand from
//! the pinhole model and the scene's geometry, not read back from the simulator.

use mdrlat_core::{DEPTH_COLS, DEPTH_LEN, DEPTH_ROWS, LASER_BEAMS};
use mdrlat_geom::Pose2;
use mdrlat_sim::{Env, SimConfig};
use mdrlat_world::World;

/// A world holding `obstacles` (TOML inline tables), robot at the origin facing +x.
fn look(obstacles: &str) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let text = format!(
        "version = 1\nname = \"t\"\nbounds = {{ min = [-20.0, -20.0], max = [20.0, 20.0] }}\n\
         obstacle = [{obstacles}]\nspawn = [{{ min = [-19.0, -19.0], max = [-18.0, -18.0] }}]\n"
    );
    let world = World::from_toml("test", &text).expect("world");
    let mut env = Env::from_world(world, SimConfig::default()).expect("env");
    let obs = env.reset_with(Some(0), Some(Pose2::new(0.0, 0.0, 0.0))).expect("reset");
    let laser = obs.laser.latest().to_vec();
    let depth = obs.depth.latest().to_vec();
    let angles = env.laser().angles().to_vec();
    assert_eq!((laser.len(), depth.len()), (LASER_BEAMS, DEPTH_LEN));
    (laser, depth, angles)
}

fn fx() -> f32 {
    80.0 / 29f32.to_radians().tan()
}
fn fy() -> f32 {
    64.0 / 22.5f32.to_radians().tan()
}
/// Normalised image coordinates of a pixel centre (x right, y down).
fn xy(r: usize, c: usize) -> (f32, f32) {
    ((c as f32 + 0.5 - 80.0) / fx(), (r as f32 + 0.5 - 64.0) / fy())
}
fn floor_z(r: usize) -> f32 {
    let (_, y) = xy(r, 0);
    if y > 0.0 { 0.30 / y } else { f32::INFINITY }
}
fn px(depth: &[f32], r: usize, c: usize) -> f32 {
    depth[r * DEPTH_COLS + c]
}

#[test]
fn beam_angles_follow_the_spec() {
    let (_, _, angles) = look("");
    assert!((angles[0] + 135f32.to_radians()).abs() < 1e-6);
    assert!((angles[511] - 135f32.to_radians()).abs() < 1e-6);
    assert!((angles[100] - (-135.0 + 100.0 * 270.0 / 511.0f32).to_radians()).abs() < 1e-6);
}

#[test]
fn empty_world_shows_only_the_floor() {
    let (laser, depth, _) = look("");
    assert!(laser.iter().all(|&r| r == 5.6), "no return reads max range");
    for r in 0..DEPTH_ROWS {
        let expect = floor_z(r);
        let expect = if (0.4..=10.0).contains(&expect) { expect } else { 0.0 };
        for c in [0, 37, 80, 159] {
            let got = px(&depth, r, c);
            assert!(
                (got - expect).abs() <= 1e-4 * expect.max(1.0),
                "row {r} col {c}: {got} vs {expect}"
            );
        }
    }
    // The bottom row sees the floor at 0.30 / y; the top half sees nothing.
    assert!((px(&depth, 127, 80) - 0.30 / xy(127, 80).1).abs() < 1e-5);
    assert_eq!(px(&depth, 10, 80), 0.0);
}

#[test]
fn wall_at_two_metres() {
    // Wall face at x = 2, 20 m wide, 2.5 m high.
    let (laser, depth, angles) =
        look(r#"{ shape = "box", center = [2.05, 0.0], size = [0.1, 20.0], z = [0.0, 2.5] }"#);
    for (i, a) in angles.iter().enumerate() {
        if a.abs() < 70f32.to_radians() {
            let expect = (2.0 / a.cos()).min(5.6);
            assert!((laser[i] - expect).abs() < 1e-4, "beam {i}: {} vs {expect}", laser[i]);
        } else if a.abs() > 90f32.to_radians() {
            assert_eq!(laser[i], 5.6, "beam {i} looks away from the wall");
        }
    }
    // z-depth of a plane facing the camera is the same in every column.
    for r in 0..DEPTH_ROWS {
        let expect = floor_z(r).min(2.0);
        for c in [0, 50, 80, 159] {
            assert!(
                (px(&depth, r, c) - expect).abs() < 1e-4,
                "row {r} col {c}: {}",
                px(&depth, r, c)
            );
        }
    }
}

#[test]
fn low_box_is_invisible_to_the_laser_and_seen_by_the_depth_camera() {
    // 15 cm high box, front face at x = 1.5, 1 m deep, 4 m wide.
    let (laser, depth, _) =
        look(r#"{ shape = "box", center = [2.0, 0.0], size = [1.0, 4.0], z = [0.0, 0.15] }"#);
    assert!(laser.iter().all(|&r| r == 5.6), "the laser plane is at 0.40 m");
    let mut front = 0;
    let mut top = 0;
    for r in 0..DEPTH_ROWS {
        let (_, y) = xy(r, 80);
        let floor = floor_z(r);
        // Front face: height at z = 1.5 is 0.30 − 1.5·y within [0, 0.15].
        let expect = if (0.0..=0.15).contains(&(0.30 - 1.5 * y)) && floor >= 1.5 {
            front += 1;
            1.5
        } else if y > 0.0 && (1.5..=2.5).contains(&(0.15 / y)) {
            top += 1;
            0.15 / y // top face
        } else if floor <= 10.0 {
            floor
        } else {
            0.0
        };
        let got = px(&depth, r, 80);
        assert!((got - expect).abs() < 1e-3, "row {r}: {got} vs {expect}");
    }
    assert!(front >= 5 && top >= 3, "front rows {front}, top rows {top}");
}

#[test]
fn table_top_is_missed_by_the_laser_and_seen_above_the_horizon() {
    // Table top at 0.68–0.72 m spanning x in [1, 3], no legs.
    let (laser, depth, _) =
        look(r#"{ shape = "box", center = [2.0, 0.0], size = [2.0, 4.0], z = [0.68, 0.72] }"#);
    assert!(laser.iter().all(|&r| r == 5.6));
    let mut underside = 0;
    for r in 0..64 {
        let (_, y) = xy(r, 80); // y < 0: looking up
        let h_front = 0.30 - 1.0 * y;
        let expect = if (0.68..=0.72).contains(&h_front) {
            1.0
        } else if (1.0..=3.0).contains(&(-0.38 / y)) {
            underside += 1;
            -0.38 / y
        } else {
            0.0
        };
        let got = px(&depth, r, 80);
        assert!((got - expect).abs() < 1e-3, "row {r}: {got} vs {expect}");
    }
    assert!(underside >= 10, "the underside fills many rows: {underside}");
    // Below the horizon the floor is unaffected.
    assert!((px(&depth, 120, 80) - floor_z(120)).abs() < 1e-4);
}

#[test]
fn columns_run_left_to_right() {
    // A post on the robot's left (+y) appears in the left half of the image.
    let (laser, depth, angles) =
        look(r#"{ shape = "cylinder", center = [2.0, 0.6], radius = 0.1, z = [0.0, 2.0] }"#);
    let row = 40; // above the horizon: only the post
    let seen: Vec<usize> = (0..DEPTH_COLS).filter(|&c| px(&depth, row, c) > 0.0).collect();
    assert!(!seen.is_empty() && seen.iter().all(|&c| c < 80), "{seen:?}");
    // Its centre column looks at atan(0.6/2).
    let mid = (seen[0] + seen[seen.len() - 1]) as f32 / 2.0 + 0.5;
    let expect = 80.0 - fx() * (0.6f32 / 2.0);
    assert!((mid - expect).abs() < 1.5, "{mid} vs {expect}");
    // The laser sees it at +16.7 degrees (counter-clockwise is positive).
    let i =
        laser.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1)).map(|(i, _)| i).expect("beam");
    assert!((angles[i] - 0.3f32.atan()).abs() < 0.02);
    assert!((laser[i] - ((2.0f32.powi(2) + 0.36).sqrt() - 0.1)).abs() < 5e-3);
}

#[test]
fn readings_closer_than_the_minimum_depth_are_zero() {
    // A wall 0.3 m ahead: the Kinect reports 0 below 0.4 m.
    let (laser, depth, _) =
        look(r#"{ shape = "box", center = [0.35, 0.0], size = [0.1, 4.0], z = [0.0, 2.0] }"#);
    assert!((laser[255] - 0.3).abs() < 1e-4 || (laser[256] - 0.3).abs() < 1e-4);
    assert!(depth.iter().all(|&z| z == 0.0));
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    fn env_for(name: &str) -> Env {
        let world = mdrlat_world::builtin::get(name).expect("builtin").expect("valid");
        Env::from_world(world, SimConfig::default()).expect("env")
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(96))]
        /// Anywhere in any built-in world, facing anywhere: laser ranges lie in [0, max],
        /// depth is 0 or within [min, max], and nothing is NaN.
        #[test]
        fn readings_stay_in_range(world in prop::sample::select(vec!["train", "office", "furnished", "crowd", "nav-test"]),
                                  fx in 0.0f32..1.0, fy in 0.0f32..1.0, yaw in -3.2f32..3.2, seed in 0u64..1000) {
            let mut env = env_for(world);
            let b = env.world().bounds;
            let pose = Pose2::new(b.min.x + fx * b.size().x, b.min.y + fy * b.size().y, yaw);
            let obs = env.reset_with(Some(seed), Some(pose)).expect("reset");
            for &r in obs.laser.latest() {
                prop_assert!(!r.is_nan() && (0.0..=5.6).contains(&r), "laser {r}");
            }
            for &z in obs.depth.latest() {
                prop_assert!(!z.is_nan() && (z == 0.0 || (0.4..=10.0).contains(&z)), "depth {z}");
            }
        }
    }
}

#[test]
fn the_cameras_geometry_is_the_rays_it_casts() {
    // `DepthCamera::geometry` is core's pinhole; it must describe this camera's own rays,
    // for any field of view: a wall at 2 m ahead reads z = 2 / k in every column, so
    // z · k is 2 m for all of them.
    for (hfov, vfov) in [(58.0, 45.0), (70.0, 50.0)] {
        let cfg = mdrlat_sim::config::DepthConfig {
            hfov_deg: hfov,
            vfov_deg: vfov,
            ..Default::default()
        };
        let geometry = mdrlat_sim::sensors::DepthCamera::new(&cfg).geometry();
        assert_eq!(geometry.column_angles.len(), mdrlat_core::DEPTH_COLS);
        let half = hfov.to_radians() / 2.0;
        let (first, last) =
            (geometry.column_angles[0], geometry.column_angles[mdrlat_core::DEPTH_COLS - 1]);
        assert!(first > 0.0 && first < half && last < 0.0 && last > -half, "{first} {last}");
        for (a, k) in geometry.column_angles.iter().zip(&geometry.column_k) {
            assert!((k - 1.0 / a.cos()).abs() < 1e-5, "{a} {k}");
        }
    }
}
