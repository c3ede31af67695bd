//! Renders every built-in world and a 300-frame animation into `target/render-demo/`, and
//! prints how long rendering and encoding took.
//!
//! ```text
//! cargo run --release -p mdrlat-render --example render_demo
//! ```

use mdrlat_geom::{Pose2, Vec2};
use mdrlat_render::{
    GifWriter, LaserRays, RenderError, RobotMark, Scene, depth_view, side_by_side, top_view,
};
use std::path::PathBuf;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../target/render-demo");
    std::fs::create_dir_all(&dir)?;
    let angles: Vec<f32> =
        (0..512).map(|i| (-135.0 + 270.0 * i as f32 / 511.0).to_radians()).collect();
    let ranges = vec![2.0f32; 512];

    for name in mdrlat_world::builtin::NAMES {
        let world = mdrlat_world::builtin::get(name).ok_or("listed")??;
        let c = world.spawn[0].min + world.spawn[0].size() * 0.5;
        let pose = Pose2::new(c.x, c.y, 0.5);
        let scene = Scene {
            robot: Some(RobotMark { pose, radius: 0.177, collided: false }),
            laser: Some(LaserRays {
                origin: pose,
                angles: &angles,
                ranges: &ranges,
                max_range: 5.6,
            }),
            caption: Some(&world.description),
            ..Scene::new(&world)
        };
        let img = top_view(&scene, 40.0);
        img.save_png(&dir.join(format!("world-{name}.png")))?;
        if name == "example" {
            for s in [20.0, 120.0] {
                top_view(&scene, s).save_png(&dir.join(format!("world-{name}-{s}.png")))?;
            }
        }
    }

    // Timings on the 6 m x 10 m example world at 60 px/m.
    let world = mdrlat_world::builtin::get("example").ok_or("listed")??;
    let depth: Vec<f32> = (0..128 * 160).map(|i| 0.5 + (i % 160) as f32 / 40.0).collect();
    let n = 300;
    let mut trail = Vec::new();
    let t0 = Instant::now();
    let mut frames = Vec::with_capacity(n);
    for step in 0..n {
        let t = step as f32 * 0.05;
        let pose = Pose2::new(3.0 + 1.5 * (0.7 * t).cos(), 5.0 + 3.0 * (0.5 * t).sin(), t);
        trail.push(pose.position());
        let peds = [(Vec2::new(1.0 + (t * 0.6) % 4.0, 1.0), 0.25, 1.7)];
        let caption = format!("example  step {step}  v 0.50 w -0.26  r 0.47");
        let scene = Scene {
            world: &world,
            robot: Some(RobotMark { pose, radius: 0.177, collided: false }),
            pedestrians: &peds,
            laser: Some(LaserRays {
                origin: pose,
                angles: &angles,
                ranges: &ranges,
                max_range: 5.6,
            }),
            trail: &trail,
            goal: Some(Vec2::new(5.0, 9.0)),
            goals: &[],
            robots: &[],
            caption: Some(&caption),
        };
        frames.push(top_view(&scene, 60.0));
    }
    let top_ms = t0.elapsed().as_secs_f64() * 1e3 / n as f64;
    let t1 = Instant::now();
    let dv = depth_view(&depth, 128, 160, 5.0, 3);
    let depth_ms = t1.elapsed().as_secs_f64() * 1e3;
    let t2 = Instant::now();
    let png = frames[0].encode_png()?;
    let png_ms = t2.elapsed().as_secs_f64() * 1e3;
    let (w, h) = (frames[0].width, frames[0].height);
    let t3 = Instant::now();
    let path = dir.join("example-300.gif");
    let mut gif = GifWriter::create(&path, w, h, 5)?;
    for f in &frames {
        gif.add_frame(f)?;
    }
    gif.finish()?;
    let gif_s = t3.elapsed().as_secs_f64();
    let t4 = Instant::now();
    let both = side_by_side(&[&frames[0], &dv], 12);
    let compose_ms = t4.elapsed().as_secs_f64() * 1e3;
    both.save_png(&dir.join("example-with-depth.png"))?;
    let gif_kb =
        std::fs::metadata(&path).map_err(|source| RenderError::Io { path, source })?.len() / 1024;
    println!("top_view {w}x{h} (60 px/m, 512 rays): {top_ms:.2} ms/frame");
    println!("depth_view 160x128 x3: {depth_ms:.2} ms; side_by_side: {compose_ms:.2} ms");
    println!("encode_png: {png_ms:.2} ms ({} KiB)", png.len() / 1024);
    println!("GIF, {n} frames: {gif_s:.2} s ({gif_kb} KiB)");
    Ok(())
}
