//! The ROS map_server importer on the Nav2 maps shipped in `worlds/maps/` and on files.

use mdrlat_core::robot::RADIUS_M;
use mdrlat_geom::{Shape, Vec2};
use mdrlat_world::map_server::{ImportOptions, MapMeta, import};
use mdrlat_world::{World, load};
use std::path::{Path, PathBuf};
use std::time::Instant;

fn map_path(file: &str) -> String {
    format!("{}/../../worlds/maps/{file}", env!("CARGO_MANIFEST_DIR"))
}

/// Occupied pixels of a map of `cells` pixels (the Nav2 maps are trinary, negate 0, 8-bit
/// P5 whose pixels end the file).
fn occupied_cells(yaml: &str, cells: usize) -> usize {
    let path = map_path(yaml);
    let text = std::fs::read_to_string(&path).expect("yaml");
    let meta = MapMeta::parse(&path, &text, Path::new(&path).parent().expect("dir")).expect("meta");
    let bytes = std::fs::read(&meta.image).expect("image");
    bytes[bytes.len() - cells..]
        .iter()
        .filter(|&&v| 1.0 - f64::from(v) / 255.0 > meta.occupied_thresh)
        .count()
}

fn loaded(yaml: &str) -> (World, f64) {
    let start = Instant::now();
    let world = load(&map_path(yaml)).unwrap_or_else(|e| panic!("{e}"));
    (world, start.elapsed().as_secs_f64())
}

fn assert_close(a: Vec2, b: Vec2) {
    assert!((a - b).length() < 1e-4, "{a:?} != {b:?}");
}

#[test]
fn nav2_maps_import_with_few_prisms() {
    for (yaml, cells, origin, name) in [
        ("tb3_sandbox.yaml", (384, 384), Vec2::new(-10.0, -10.0), "tb3_sandbox"),
        ("depot.yaml", (604, 307), Vec2::new(0.0, 0.0), "depot"),
    ] {
        let (world, seconds) = loaded(yaml);
        let occupied = occupied_cells(yaml, cells.0 * cells.1);
        let spawn_area: f32 = world.spawn.iter().map(|s| s.area()).sum();
        println!(
            "{yaml}: {occupied} occupied cells -> {} wall prisms, {} spawn rectangles ({spawn_area:.1} m²), imported in {:.1} ms",
            world.obstacles.len(),
            world.spawn.len(),
            seconds * 1e3
        );
        assert_eq!(world.name, name);
        assert_eq!(
            world.description,
            format!("imported from {yaml} ({}x{} cells at 0.05 m)", cells.0, cells.1)
        );
        assert!(world.obstacles.len() * 3 < occupied, "{} prisms", world.obstacles.len());
        assert!(!world.spawn.is_empty() && world.goals.is_empty() && world.pedestrians.is_empty());
        assert_close(world.bounds.min, origin);
        assert_close(
            world.bounds.max,
            origin + Vec2::new(cells.0 as f32 * 0.05, cells.1 as f32 * 0.05),
        );
        // The walls cover exactly the occupied cells.
        let wall_area: f32 = world
            .obstacles
            .iter()
            .map(|o| match &o.prism.shape {
                Shape::Cuboid(c) => 4.0 * c.half.x * c.half.y,
                _ => panic!("not a box"),
            })
            .sum();
        assert!((wall_area - occupied as f32 * 0.0025).abs() < 1e-3, "{wall_area} m²");
        for o in &world.obstacles {
            assert_eq!(
                (o.prism.z_min, o.prism.z_max, o.label.as_deref()),
                (0.0, 2.0, Some("wall"))
            );
            let Shape::Cuboid(c) = &o.prism.shape else { panic!("not a box") };
            assert_eq!(c.yaw, 0.0);
        }
        for s in &world.spawn {
            let centre = (s.min + s.max) * 0.5;
            assert!(world.bounds.contains(s.min) && world.bounds.contains(s.max));
            // At 5 cm cells, the default clearance keeps even the corners collision-free.
            for p in
                [centre, s.min, s.max, Vec2::new(s.min.x, s.max.y), Vec2::new(s.max.x, s.min.y)]
            {
                assert!(world.is_free(p, RADIUS_M), "spawn point {p:?} blocked");
            }
        }
    }
}

#[test]
fn known_points_of_the_nav2_maps() {
    let (tb3, _) = loaded("tb3_sandbox.yaml");
    // The turtlebot3 world: a hexagon with 3x3 pillars 1.1 m apart, the middle one at (0, 0).
    assert!(!tb3.is_free(Vec2::new(0.0, 0.0), RADIUS_M));
    assert!(!tb3.is_free(Vec2::new(0.0, -0.1), 0.01), "pillar rim");
    assert!(tb3.is_free(Vec2::new(0.55, 0.55), RADIUS_M));
    assert!(tb3.spawn.iter().any(|s| s.contains(Vec2::new(0.55, 0.55))));
    assert!(!tb3.spawn.iter().any(|s| s.contains(Vec2::new(5.0, 5.0))), "unknown outside");
    let (depot, _) = loaded("depot.yaml");
    assert!(depot.is_free(Vec2::new(5.0, 5.0), RADIUS_M));
    assert!(depot.spawn.iter().any(|s| s.contains(Vec2::new(5.0, 5.0))));
    // The H-shaped rack leg at pixel row 75, columns 147..=157.
    assert!(!depot.is_free(Vec2::new(7.6, 11.575), 0.01));
    assert!(!depot.spawn.iter().any(|s| s.contains(Vec2::new(7.6, 11.575))));
}

/// A scratch folder for one test.
fn scratch(test: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("map_server").join(test);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

fn import_err(dir: &Path, yaml: &str, image: Option<(&str, &[u8])>) -> String {
    if let Some((name, bytes)) = image {
        std::fs::write(dir.join(name), bytes).expect("write image");
    }
    let path = dir.join("m.yaml");
    std::fs::write(&path, yaml).expect("write yaml");
    import(&path, &ImportOptions::default()).expect_err("should fail").to_string()
}

#[test]
fn files_resolve_relative_to_the_yaml_and_bad_files_are_clear_errors() {
    let dir = scratch("files");
    let yaml = |image: &str| format!("image: {image}\nresolution: 0.05\norigin: [0, 0, 0]\n");
    // A relative image next to the YAML, and an absolute one.
    let pgm = std::fs::read(map_path("tb3_sandbox.pgm")).expect("pgm");
    std::fs::write(dir.join("ok.pgm"), &pgm).expect("write");
    std::fs::write(dir.join("ok.yaml"), yaml("ok.pgm")).expect("write");
    let w = import(&dir.join("ok.yaml"), &ImportOptions::default()).expect("relative image");
    assert_eq!(w.name, "ok");
    std::fs::write(dir.join("abs.yaml"), yaml(&map_path("depot.pgm"))).expect("write");
    import(&dir.join("abs.yaml"), &ImportOptions::default()).expect("absolute image");

    let e = import(&dir.join("nothing.yaml"), &ImportOptions::default()).expect_err("no yaml");
    assert!(e.to_string().contains("nothing.yaml: cannot read"), "{e}");
    let e = import_err(&dir, &yaml("missing.pgm"), None);
    assert!(e.contains("m.yaml: image ") && e.contains("missing.pgm: cannot read"), "{e}");
    let e = import_err(&dir, &yaml("text.pgm"), Some(("text.pgm", b"image: not really\n")));
    assert!(e.contains("text.pgm: not a PGM (P2 or P5) or PNG image"), "{e}");
    let noise: Vec<u8> = (0..4096u32).map(|i| (i.wrapping_mul(2654435761) >> 13) as u8).collect();
    let e = import_err(&dir, &yaml("noise.pgm"), Some(("noise.pgm", &noise)));
    assert!(e.contains("noise.pgm: not a PGM"), "{e}");
    let e = import_err(&dir, &yaml("cut.pgm"), Some(("cut.pgm", &pgm[..pgm.len() / 2])));
    assert!(e.contains("cut.pgm: truncated PGM: 384x384 pixels need 147456 bytes"), "{e}");
    let e = import_err(&dir, &yaml("cut.png"), Some(("cut.png", b"\x89PNG\r\n\x1a\n\0\0")));
    assert!(e.contains("cut.png: not a valid PNG"), "{e}");
    std::fs::create_dir_all(dir.join("dir")).expect("mkdir");
    let e = import_err(&dir, &yaml("dir"), None);
    assert!(e.contains("dir: cannot read"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}
