//! Golden-pixel tests: things drawn where the world says they are, y up, the heading the
//! right way, depth colours, determinism, and PNG / GIF round trips.

use mdrlat_geom::{Pose2, Vec2};
use mdrlat_render::{
    GifWriter, Image, LaserRays, RenderError, RobotMark, Scene, depth_colour, depth_view,
    map_frame, top_view,
};
use mdrlat_world::World;
use std::f32::consts::FRAC_PI_2;

/// Tall box upper-left, low box upper-right, an overhanging disc lower-right.
const WORLD: &str = r#"
version = 1
name = "pixels"
bounds = { min = [0.0, 0.0], max = [4.0, 4.0] }
obstacle = [
  { shape = "box", center = [1.0, 3.0], size = [0.6, 0.6], z = [0.0, 2.5] },
  { shape = "box", center = [3.0, 3.0], size = [0.6, 0.6], z = [0.0, 0.15] },
  { shape = "cylinder", center = [3.0, 1.0], radius = 0.3, z = [0.7, 0.75] },
]
spawn = [ { min = [0.5, 0.5], max = [2.0, 2.0] } ]
"#;

const S: f32 = 50.0;

fn world() -> World {
    World::from_toml("pixels.toml", WORLD).expect("valid test world")
}

/// The picture's pixel at world point `p` shifted by `(dx, dy)` picture pixels.
fn at(img: &Image, world: &World, p: Vec2, (dx, dy): (f32, f32)) -> [u8; 4] {
    let (x, y) = map_frame(world, S).to_px(p);
    img.pixel((x + dx) as u32, (y + dy) as u32).expect("inside the picture")
}

fn is_dark_grey(c: [u8; 4]) -> bool {
    c[0] < 100 && c[0].abs_diff(c[1]) < 10 && c[1].abs_diff(c[2]) < 10
}

#[test]
fn obstacles_are_where_the_world_says_and_y_points_up() {
    let w = world();
    let img = top_view(&Scene::new(&w), S);
    // The tall box around (1, 3) is dark grey; the mirror image across y = 2 is bare floor.
    assert!(is_dark_grey(at(&img, &w, Vec2::new(1.15, 3.15), (0.0, 0.0))));
    assert_eq!(at(&img, &w, Vec2::new(1.15, 0.85), (0.0, 0.0)), [255, 255, 255, 255]);
    // The box is in the upper half of the picture.
    let (_, row) = map_frame(&w, S).to_px(Vec2::new(1.0, 3.0));
    assert!(row < img.height as f32 / 2.0);
    // The low box is orange, the overhang blue.
    let low = at(&img, &w, Vec2::new(3.0, 3.0), (0.0, 0.0));
    assert!(low[0] > 200 && low[1] > 100 && low[2] < 160, "{low:?}");
    let over = at(&img, &w, Vec2::new(3.1, 0.95), (0.0, 0.0));
    assert!(over[2] > over[0] + 40, "{over:?}");
    // Floor between grid lines is white; outside the bounds is the page colour.
    assert_eq!(at(&img, &w, Vec2::new(2.5, 3.5), (0.0, 0.0)), [255, 255, 255, 255]);
    assert_ne!(img.pixel(1, 1), Some([255, 255, 255, 255]));
    // A grid line at x = 2 m is drawn, faintly.
    let grid = at(&img, &w, Vec2::new(2.0, 3.5), (0.0, 0.0));
    assert!(grid[0] < 250 && grid[0] > 200, "{grid:?}");
}

fn robot_scene<'a>(w: &'a World, yaw: f32, collided: bool) -> Scene<'a> {
    let pose = Pose2::new(1.5, 1.5, yaw);
    Scene { robot: Some(RobotMark { pose, radius: 0.3, collided }), ..Scene::new(w) }
}

fn is_teal(c: [u8; 4]) -> bool {
    c[1] > c[0] + 60 && c[2] > c[0] + 60
}

#[test]
fn the_heading_line_points_the_way_the_robot_faces() {
    let w = world();
    let c = Vec2::new(1.5, 1.5);
    let r = 0.3 * S;
    // Facing +y: the line goes UP the picture (towards smaller rows).
    let img = top_view(&robot_scene(&w, FRAC_PI_2, false), S);
    let ahead = at(&img, &w, c, (0.0, -0.7 * r));
    let behind = at(&img, &w, c, (0.0, 0.7 * r));
    assert!(ahead[0] < 60 && ahead[1] < 60, "heading line: {ahead:?}");
    assert!(is_teal(behind), "body: {behind:?}");
    // Facing +x: to the right.
    let img = top_view(&robot_scene(&w, 0.0, false), S);
    assert!(at(&img, &w, c, (0.7 * r, 0.0))[1] < 60);
    assert!(is_teal(at(&img, &w, c, (-0.7 * r, 0.0))));
    assert!(is_teal(at(&img, &w, c, (0.0, -0.7 * r))));
    // Collided: red body.
    let img = top_view(&robot_scene(&w, 0.0, true), S);
    let body = at(&img, &w, c, (-0.7 * r, 0.0));
    assert!(body[0] > 180 && body[1] < 80, "{body:?}");
}

#[test]
fn marks_laser_pedestrians_trail_goal_and_caption() {
    let w = world();
    let pose = Pose2::new(1.0, 1.0, FRAC_PI_2);
    // One ray straight ahead (+y) hitting at 1 m, one to the right (+x) at max range.
    let angles = [0.0, -FRAC_PI_2];
    let ranges = [1.0, 1.5];
    let peds = [(Vec2::new(2.5, 2.0), 0.25, 1.7)];
    let trail = [Vec2::new(0.5, 3.5), Vec2::new(1.5, 3.5)];
    let scene = Scene {
        laser: Some(LaserRays { origin: pose, angles: &angles, ranges: &ranges, max_range: 1.5 }),
        pedestrians: &peds,
        trail: &trail,
        goal: Some(Vec2::new(2.0, 0.5)),
        caption: Some("step 42  r 0.47"),
        ..Scene::new(&w)
    };
    let img = top_view(&scene, S);
    let hit = at(&img, &w, Vec2::new(1.0, 2.0), (0.0, 0.0));
    assert!(hit[0] > 180 && hit[1] < 120, "hit dot: {hit:?}");
    let miss_end = at(&img, &w, Vec2::new(2.5, 1.0), (0.0, 0.0));
    assert!(miss_end[1] > 150, "no dot on a ray at max range: {miss_end:?}");
    let ped_centre = at(&img, &w, Vec2::new(2.5, 2.0), (0.0, 0.0));
    let ped_body = at(&img, &w, Vec2::new(2.5, 2.0), (0.6 * 0.25 * S, 0.0));
    assert!(ped_centre[0] > 200 && ped_centre[1] > 200, "marker: {ped_centre:?}");
    assert!(ped_body[2] > ped_body[1] + 60 && ped_body[0] > ped_body[1] + 40, "{ped_body:?}");
    let trail_px = at(&img, &w, Vec2::new(1.0, 3.5), (0.0, 0.0));
    assert!(trail_px[2] > 180 && trail_px[0] < 120, "trail: {trail_px:?}");
    let goal = at(&img, &w, Vec2::new(2.0, 0.5), (0.0, 0.0));
    assert!(goal[1] > 120 && goal[0] < 80, "goal: {goal:?}");
    // The caption adds text below the map, and the map does not move.
    let plain = top_view(&Scene { caption: None, ..scene }, S);
    assert!(img.height > plain.height && img.width == plain.width);
    let band = &img.rgba[(plain.height * img.width * 4) as usize..];
    assert!(band.chunks_exact(4).any(|p| p[0] < 60), "caption ink");
}

#[test]
fn the_same_scene_gives_the_same_bytes() {
    let w = world();
    let angles: Vec<f32> = (0..64).map(|i| i as f32 * 0.1).collect();
    let ranges: Vec<f32> = (0..64).map(|i| 0.5 + (i % 7) as f32 * 0.3).collect();
    let pose = Pose2::new(1.2, 1.7, 0.3);
    let scene = Scene {
        robot: Some(RobotMark { pose, radius: 0.177, collided: false }),
        laser: Some(LaserRays { origin: pose, angles: &angles, ranges: &ranges, max_range: 2.0 }),
        caption: Some("determinism"),
        ..Scene::new(&w)
    };
    let a = top_view(&scene, 37.5);
    let b = top_view(&scene, 37.5);
    assert_eq!(a, b);
    assert_eq!(a.encode_png().expect("png"), b.encode_png().expect("png"));
    assert!(a.rgba.chunks_exact(4).all(|p| p[3] == 255), "opaque");
}

#[test]
fn odd_scales_and_marks_do_not_panic() {
    let w = world();
    let nan = [Vec2::new(f32::NAN, 1.0), Vec2::new(1.0, 1.0)];
    let scene = Scene {
        robot: Some(RobotMark {
            pose: Pose2::new(f32::NAN, 0.0, 0.0),
            radius: -1.0,
            collided: true,
        }),
        pedestrians: &[(Vec2::new(1.0, 1.0), f32::NAN, 1.0)],
        trail: &nan,
        goal: Some(Vec2::new(f32::INFINITY, 0.0)),
        caption: Some(""),
        ..Scene::new(&w)
    };
    for s in [0.0, -3.0, f32::NAN, 0.5, 1e9] {
        let img = top_view(&scene, s);
        assert!(
            img.width > 0
                && img.height > 0
                && img.rgba.len() == (img.width * img.height * 4) as usize
        );
    }
    assert_eq!(map_frame(&w, 1e9).px_per_m, 1000.0);
}

#[test]
fn depth_view_colours() {
    let d = [0.0, 0.5, 4.9, f32::NAN, 2.0, 50.0];
    let img = depth_view(&d, 2, 3, 5.0, 4);
    let px = |r: u32, c: u32| img.pixel(c * 4 + 1, r * 4 + 1).expect("inside");
    assert_eq!(px(0, 0), [0, 0, 0, 255], "0 = no return is black");
    assert_eq!(px(1, 0), [0, 0, 0, 255], "NaN is black");
    let (near, far) = (px(0, 1), px(0, 2));
    assert!(near[0] > near[2] + 100, "near is warm: {near:?}");
    assert!(far[2] > far[0] + 100, "far is cool: {far:?}");
    assert_ne!(near, far);
    let c = depth_colour(5.0, 5.0);
    assert_eq!(px(1, 2), [c[0], c[1], c[2], 255], "beyond max is drawn as max");
    // A colour bar sits to the right of the image.
    assert!(img.width > 3 * 4 + 10);
    // Short data is drawn as no return rather than panicking; determinism.
    let short = depth_view(&d[..2], 2, 3, 5.0, 4);
    assert_eq!(short.pixel(2 * 4 + 1, 4 + 1), Some([0, 0, 0, 255]));
    assert_eq!(depth_view(&d, 2, 3, 5.0, 4), img);
    // Degenerate input: nothing to draw, no scale, absurd depths.
    assert!(depth_view(&[], 0, 0, 0.0, 0).width > 0);
    let huge = depth_view(&[1e30, 2.0], 1, 2, f32::NAN, 1);
    assert_eq!(huge.pixel(1, 0).map(|p| p[3]), Some(255));
}

fn frames(w: &World) -> Vec<Image> {
    (0..4)
        .map(|k| {
            let pose = Pose2::new(1.0 + 0.3 * k as f32, 1.5, 0.4 * k as f32);
            let caption = format!("step {k}");
            let scene = Scene {
                robot: Some(RobotMark { pose, radius: 0.177, collided: k == 2 }),
                caption: Some(&caption),
                ..Scene::new(w)
            };
            top_view(&scene, 30.0)
        })
        .collect()
}

/// Decodes a GIF, composing each frame over the previous, and returns the last full picture.
fn decode(bytes: &[u8]) -> (u32, u32, usize, Vec<u8>) {
    let mut opts = gif::DecodeOptions::new();
    opts.set_color_output(gif::ColorOutput::RGBA);
    let mut dec = opts.read_info(bytes).expect("gif header");
    let (w, h) = (u32::from(dec.width()), u32::from(dec.height()));
    let mut canvas = vec![0u8; (w * h * 4) as usize];
    let mut n = 0;
    while let Some(f) = dec.read_next_frame().expect("gif frame") {
        for r in 0..usize::from(f.height) {
            for c in 0..usize::from(f.width) {
                let s = (r * usize::from(f.width) + c) * 4;
                if f.buffer[s + 3] == 0 {
                    continue;
                }
                let d = ((usize::from(f.top) + r) * w as usize + usize::from(f.left) + c) * 4;
                canvas[d..d + 4].copy_from_slice(&f.buffer[s..s + 4]);
            }
        }
        n += 1;
    }
    (w, h, n, canvas)
}

#[test]
fn gif_round_trip() {
    let w = world();
    let fr = frames(&w);
    let (fw, fh) = (fr[0].width, fr[0].height);
    let encode = |extra: &Image| {
        let mut g = GifWriter::new(Vec::new(), fw, fh, 10).expect("header");
        for f in &fr {
            g.add_frame(f).expect("frame");
        }
        g.add_frame(extra).expect("odd-sized frame is padded");
        assert_eq!(g.frames(), 5);
        g.finish().expect("trailer")
    };
    let small = Image::new(10, 10, [0, 0, 0, 255]);
    let bytes = encode(&small);
    assert_eq!(bytes, encode(&small), "deterministic bytes");
    let (gw, gh, n, last) = decode(&bytes);
    assert_eq!((gw, gh, n), (fw, fh, 5));
    // The last frame is the small black square, padded with white.
    assert_eq!(&last[..4], &[0, 0, 0, 255]);
    assert_eq!(&last[(fw as usize * 20 + 20) * 4..][..4], &[255, 255, 255, 255]);

    // Without the odd frame, the composed animation reproduces the last frame closely:
    // flat colours exactly, anti-aliased edges within the palette's reach.
    let mut g = GifWriter::new(Vec::new(), fw, fh, 10).expect("header");
    for f in &fr {
        g.add_frame(f).expect("frame");
    }
    let (_, _, _, last) = decode(&g.finish().expect("trailer"));
    let src = &fr[3].rgba;
    let exact = src.iter().zip(&last).filter(|(a, b)| a == b).count();
    let err: u64 = src.iter().zip(&last).map(|(&a, &b)| u64::from(a.abs_diff(b))).sum();
    assert!(exact as f64 > 0.97 * src.len() as f64, "{exact} of {}", src.len());
    assert!((err as f64 / src.len() as f64) < 1.0, "mean error {}", err as f64 / src.len() as f64);
}

#[test]
fn gif_errors_name_the_path_and_the_size() {
    let dir = std::env::temp_dir().join(format!("mdrlat-render-gif-{}", std::process::id()));
    let path = dir.join("missing").join("a.gif");
    let e = GifWriter::create(&path, 10, 10, 5).err().expect("no directory");
    assert!(matches!(e, RenderError::Io { .. }));
    assert!(e.to_string().contains(&path.display().to_string()), "{e}");
    let e = GifWriter::new(Vec::new(), 0, 10, 5).err().expect("empty");
    assert!(e.to_string().contains("0x10"), "{e}");
    let e = GifWriter::new(Vec::new(), 70_000, 10, 5).err().expect("too wide");
    assert!(e.to_string().contains("65535"), "{e}");
}
