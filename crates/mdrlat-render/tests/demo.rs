//! Writes `target/render-demo/example.png` (and a short `example.gif`): the built-in
//! "example" world with a fake robot, a fake laser scan and a synthetic depth image, for
//! people to look at. Also checks the pictures are deterministic.

use mdrlat_geom::{Pose2, Vec2};
use mdrlat_render::{
    GifWriter, Image, LaserRays, RobotMark, Scene, depth_view, side_by_side, top_view,
};
use std::path::PathBuf;

fn out_dir() -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../target/render-demo");
    std::fs::create_dir_all(&dir).expect("create target/render-demo");
    dir
}

/// A synthetic 128×160 depth image: floor rows getting nearer towards the bottom, a wall at
/// 3.5 m above the horizon, a box at 1.2 m, and a band of no returns.
fn synthetic_depth() -> Vec<f32> {
    let (rows, cols) = (128usize, 160usize);
    let mut d = vec![0.0f32; rows * cols];
    for r in 0..rows {
        for c in 0..cols {
            let v = if r < 64 {
                3.5
            } else {
                // Floor seen from 0.30 m: depth = h / tan(angle below the horizon).
                let below = (r as f32 - 63.5) / 64.0 * 22.5f32.to_radians();
                (0.30 / below.tan()).min(3.5)
            };
            let in_box = (100..130).contains(&c) && (60..95).contains(&r);
            d[r * cols + c] = if in_box {
                1.2
            } else if v < 0.4 || (20..26).contains(&c) && r < 40 {
                0.0
            } else {
                v
            };
        }
    }
    d
}

fn frame(world: &mdrlat_world::World, step: usize, trail: &mut Vec<Vec2>) -> Image {
    let t = step as f32 * 0.2;
    let pose = Pose2::new(2.0 + 0.6 * t.cos(), 3.0 + 0.3 * t, 1.2 + 0.4 * t.sin());
    trail.push(pose.position());
    let angles: Vec<f32> =
        (0..512).map(|i| (-135.0 + 270.0 * i as f32 / 511.0).to_radians()).collect();
    // Constant 2 m, except a sector with no return (drawn faint).
    let ranges: Vec<f32> =
        (0..512).map(|i| if (200..260).contains(&i) { 5.6 } else { 2.0 }).collect();
    let peds = [(Vec2::new(1.0 + 0.6 * t, 1.0), 0.25, 1.7)];
    let caption = format!("example  step {step}  v 0.50 w -0.26  r 0.47");
    let scene = Scene {
        world,
        robot: Some(RobotMark { pose, radius: 0.177, collided: step == 3 }),
        pedestrians: &peds,
        laser: Some(LaserRays { origin: pose, angles: &angles, ranges: &ranges, max_range: 5.6 }),
        trail,
        goal: Some(Vec2::new(5.0, 9.0)),
        goals: &[],
        robots: &[],
        caption: Some(&caption),
    };
    let top = top_view(&scene, 60.0);
    let depth = depth_view(&synthetic_depth(), 128, 160, 5.0, 3);
    side_by_side(&[&top, &depth], 12)
}

#[test]
fn writes_the_demo_pictures() {
    let world = mdrlat_world::builtin::get("example").expect("built in").expect("valid");
    let mut trail = vec![Vec2::new(1.5, 1.2), Vec2::new(1.8, 2.0)];
    let img = frame(&world, 0, &mut trail);
    let mut trail2 = vec![Vec2::new(1.5, 1.2), Vec2::new(1.8, 2.0)];
    assert_eq!(img, frame(&world, 0, &mut trail2), "same scene, same pixels");
    let dir = out_dir();
    img.save_png(&dir.join("example.png")).expect("write example.png");

    let mut gif = GifWriter::create(&dir.join("example.gif"), img.width, img.height, 20)
        .expect("create example.gif");
    for step in 0..8 {
        gif.add_frame(&frame(&world, step, &mut trail)).expect("frame");
    }
    gif.finish().expect("finish");
}
