//! The colours of every picture, and the height classes obstacles are shaded by.
//!
//! The GIF palette (`animation.rs`) is built from these exact colours, so flat areas of a
//! picture keep their colour in an animation.

use mdrlat_geom::Prism;

/// Height of the 2D laser's scan plane above the floor, metres (SPEC, "2D laser"). Obstacles
/// wholly below it are invisible to the laser; pictures shade them apart.
pub const LASER_PLANE_M: f32 = 0.40;

/// What a sensor can make of an obstacle, judged from its height interval alone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum HeightClass {
    /// Standing on the floor and reaching the laser plane: walls, furniture, posts, legs.
    Tall,
    /// Standing on the floor, wholly below the laser plane: only the depth camera sees it.
    Low,
    /// Not touching the floor (`z_min > 0`): table tops, shelves, overhangs.
    Overhang,
}

impl HeightClass {
    /// The class of a prism. A bottom face within 1 mm of the floor counts as on the floor.
    pub fn of(prism: &Prism) -> HeightClass {
        if prism.z_min > 1e-3 {
            HeightClass::Overhang
        } else if prism.z_max < LASER_PLANE_M {
            HeightClass::Low
        } else {
            HeightClass::Tall
        }
    }
}

/// An opaque colour.
pub(crate) type Rgb = [u8; 3];

/// Outside the world's bounds.
pub(crate) const PAGE: Rgb = [236, 239, 242];
/// The floor inside the bounds.
pub(crate) const FLOOR: Rgb = [255, 255, 255];
/// The 1 m grid.
pub(crate) const GRID: Rgb = [226, 230, 234];
/// The outline of the bounds.
pub(crate) const BOUNDS: Rgb = [150, 156, 162];
/// Text.
pub(crate) const INK: Rgb = [28, 30, 34];
/// Secondary text (axis labels, notes).
pub(crate) const INK_DIM: Rgb = [105, 110, 118];
/// Tall obstacles: the lightest (just reaching the laser plane) and darkest (>= 2 m) shade.
pub(crate) const TALL_LIGHT: Rgb = [128, 130, 134];
pub(crate) const TALL_DARK: Rgb = [58, 60, 64];
/// Low obstacles: the lightest (flat on the floor) and darkest (just below the plane) shade.
pub(crate) const LOW_LIGHT: Rgb = [252, 204, 130];
pub(crate) const LOW_DARK: Rgb = [236, 132, 28];
/// Overhangs: translucent fill, hatching and outline.
pub(crate) const OVERHANG: Rgb = [52, 104, 214];
pub(crate) const OVERHANG_FILL_ALPHA: u8 = 70;
/// Spawn regions (dashed outline) and goals.
pub(crate) const SPAWN: Rgb = [70, 170, 90];
pub(crate) const GOAL: Rgb = [34, 160, 64];
pub(crate) const GOAL_DARK: Rgb = [20, 100, 40];
/// Pedestrians.
pub(crate) const PEDESTRIAN: Rgb = [136, 64, 176];
pub(crate) const PEDESTRIAN_DARK: Rgb = [84, 34, 112];
/// The robot, and the robot in collision.
pub(crate) const ROBOT: Rgb = [0, 150, 136];
pub(crate) const ROBOT_HIT: Rgb = [222, 36, 36];
pub(crate) const ROBOT_DARK: Rgb = [20, 40, 44];
/// Laser rays and hits.
pub(crate) const LASER: Rgb = [226, 30, 30];
/// The trajectory.
pub(crate) const TRAIL: Rgb = [36, 98, 226];

/// The colours an animation must reproduce exactly: every flat colour above.
pub(crate) const FLAT: [Rgb; 22] = [
    PAGE,
    FLOOR,
    GRID,
    BOUNDS,
    INK,
    INK_DIM,
    TALL_LIGHT,
    TALL_DARK,
    LOW_LIGHT,
    LOW_DARK,
    OVERHANG,
    SPAWN,
    GOAL,
    GOAL_DARK,
    PEDESTRIAN,
    PEDESTRIAN_DARK,
    ROBOT,
    ROBOT_HIT,
    ROBOT_DARK,
    LASER,
    TRAIL,
    [0, 0, 0],
];

/// Linear blend of two colours, `t` in [0, 1] from `a` to `b`.
pub(crate) fn mix(a: Rgb, b: Rgb, t: f32) -> Rgb {
    let t = t.clamp(0.0, 1.0);
    let m = |x: u8, y: u8| (f32::from(x) + (f32::from(y) - f32::from(x)) * t).round() as u8;
    [m(a[0], b[0]), m(a[1], b[1]), m(a[2], b[2])]
}

/// The smallest "nice" step (1, 2 or 5 times a power of ten, but at least `smallest`) that
/// is at least `min`: spacing for axis labels and colour-bar ticks. NaN gives `smallest`.
pub(crate) fn nice_step(min: f32, smallest: f32) -> f32 {
    if min.is_nan() || min <= smallest {
        return smallest;
    }
    let k = 10f32.powf(min.log10().floor());
    [1.0, 2.0, 5.0].into_iter().map(|m| m * k).find(|&v| v >= min).unwrap_or(10.0 * k)
}

/// Fill colour of an obstacle: its class's colour, darker the taller it is.
pub(crate) fn obstacle_fill(prism: &Prism) -> Rgb {
    match HeightClass::of(prism) {
        HeightClass::Tall => {
            mix(TALL_LIGHT, TALL_DARK, (prism.z_max - LASER_PLANE_M) / (2.0 - LASER_PLANE_M))
        }
        HeightClass::Low => mix(LOW_LIGHT, LOW_DARK, prism.z_max / LASER_PLANE_M),
        HeightClass::Overhang => OVERHANG,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mdrlat_geom::{Cylinder, Shape, Vec2};

    fn prism(z0: f32, z1: f32) -> Prism {
        let c = Cylinder::new(Vec2::ZERO, 1.0).expect("valid");
        Prism::new(Shape::Cylinder(c), z0, z1)
    }

    #[test]
    fn classes_follow_the_laser_plane() {
        assert_eq!(HeightClass::of(&prism(0.0, 2.5)), HeightClass::Tall);
        assert_eq!(HeightClass::of(&prism(0.0, 0.40)), HeightClass::Tall);
        assert_eq!(HeightClass::of(&prism(0.0, 0.15)), HeightClass::Low);
        assert_eq!(HeightClass::of(&prism(0.68, 0.72)), HeightClass::Overhang);
        assert_eq!(HeightClass::of(&prism(0.2, 1.0)), HeightClass::Overhang);
        // Taller is darker; lower boxes are lighter.
        assert!(obstacle_fill(&prism(0.0, 2.5))[0] < obstacle_fill(&prism(0.0, 1.0))[0]);
        assert!(obstacle_fill(&prism(0.0, 0.05))[2] > obstacle_fill(&prism(0.0, 0.35))[2]);
    }

    #[test]
    fn nice_steps() {
        assert_eq!(nice_step(0.3, 1.0), 1.0);
        assert_eq!(nice_step(1.5, 1.0), 2.0);
        assert_eq!(nice_step(7.0, 1.0), 10.0);
        assert_eq!(nice_step(30.0, 1.0), 50.0);
        assert_eq!(nice_step(0.1, 0.25), 0.25);
        assert_eq!(nice_step(0.3, 0.25), 0.5);
        assert_eq!(nice_step(f32::NAN, 0.25), 0.25);
        assert!(nice_step(3e30, 1.0) >= 3e30);
    }
}
