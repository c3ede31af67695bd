//! A fan of rays from one origin, cast against one prepared shape at a time.
//!
//! A [`Fan`] holds ray directions in the sensor frame, sorted by angle. A shape is
//! [prepared](Shape::prepare) once per sensor pose (moved into the sensor frame), then
//! [`PreparedShape::cast`] computes entry and exit distances for a contiguous range of rays
//! in one tight loop that the compiler vectorises. Rays start at the sensor (t = 0).

use super::extent::Extent;
use crate::math::{Pose2, Vec2};
use crate::shape::{MAX_POLYGON_VERTICES, Shape, cuboid::slab_pub as slab};
use std::f32::consts::TAU;
use std::ops::Range;

/// Ray directions of a sensor, in its own frame, sorted by angle.
#[derive(Debug, Clone)]
pub struct Fan {
    angles: Vec<f32>,
    cos: Vec<f32>,
    sin: Vec<f32>,
}

impl Fan {
    /// A fan from ray angles in radians (0 = ahead, counter-clockwise positive), which must
    /// be sorted ascending and lie in (−π, π].
    ///
    /// # Panics
    /// If the angles are unsorted or out of range: fans are built from sensor constants.
    pub fn new(angles: Vec<f32>) -> Self {
        assert!(angles.windows(2).all(|w| w[0] <= w[1]), "fan angles must be sorted");
        assert!(angles.iter().all(|a| (-std::f32::consts::PI..=std::f32::consts::PI).contains(a)));
        let cos = angles.iter().map(|a| a.cos()).collect();
        let sin = angles.iter().map(|a| a.sin()).collect();
        Self { angles, cos, sin }
    }

    /// Number of rays.
    pub fn len(&self) -> usize {
        self.angles.len()
    }

    /// True for a fan without rays.
    pub fn is_empty(&self) -> bool {
        self.angles.is_empty()
    }

    /// Ray angles, sensor frame.
    pub fn angles(&self) -> &[f32] {
        &self.angles
    }

    /// Cosines of the ray angles.
    pub fn cos(&self) -> &[f32] {
        &self.cos
    }

    /// Sines of the ray angles.
    pub fn sin(&self) -> &[f32] {
        &self.sin
    }

    /// The (at most two) index ranges of rays that may hit a shape seen under `extent` from
    /// a sensor heading `sensor_yaw`. Ranges are padded by one ray each side; the cast decides.
    pub fn ranges(&self, extent: Extent, sensor_yaw: f32) -> [Range<usize>; 2] {
        let n = self.angles.len();
        let (lo, hi) = match extent {
            Extent::Full => return [0..n, 0..0],
            Extent::Arc { lo, hi } => (lo - sensor_yaw, hi - sensor_yaw),
        };
        // Bring lo into [-π - TAU, π) so that shifts of 0 and +TAU cover every overlap.
        let k = ((lo + std::f32::consts::PI) / TAU).floor();
        let (lo, hi) = (lo - k * TAU, hi - k * TAU);
        let mut out = [0..0, 0..0];
        for (slot, shift) in out.iter_mut().zip([0.0, -TAU]) {
            let (a, b) = (lo + shift, hi + shift);
            let start = self.angles.partition_point(|&x| x < a).saturating_sub(1);
            let end = (self.angles.partition_point(|&x| x <= b) + 1).min(n);
            if start < end && b >= self.angles[0] - 1e-3 && a <= self.angles[n - 1] + 1e-3 {
                *slot = start..end;
            }
        }
        out
    }
}

/// A shape moved into a sensor's frame, ready for fan casts from the sensor origin.
// Lives on the stack for one cast; boxing the polygon table would allocate per obstacle per step.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum PreparedShape {
    /// Box: ray origin in the box frame, rotation sensor → box, half extents.
    Cuboid {
        /// Sensor position in the box's local frame.
        origin: Vec2,
        /// cos of (sensor yaw − box yaw).
        cos: f32,
        /// sin of (sensor yaw − box yaw).
        sin: f32,
        /// Half extents.
        half: Vec2,
    },
    /// Circle: sensor minus centre (sensor frame) and `|oc|² − r²`.
    Cylinder {
        /// Sensor position minus circle centre, sensor frame.
        oc: Vec2,
        /// `|oc|² − r²`.
        c: f32,
    },
    /// Polygon: edge normals in the sensor frame and `c_i − n_i·p` offsets.
    Polygon {
        /// Number of edges.
        n: usize,
        /// Normal x per edge.
        nx: [f32; MAX_POLYGON_VERTICES],
        /// Normal y per edge.
        ny: [f32; MAX_POLYGON_VERTICES],
        /// Offset per edge relative to the sensor.
        num: [f32; MAX_POLYGON_VERTICES],
    },
}

/// Entry and exit distances of a range of rays, written by [`PreparedShape::cast`]. A ray
/// hits when `t_in <= t_out && t_out >= 0`; `t_in < 0` means the sensor is inside.
#[derive(Debug, Clone, Default)]
pub struct FanHits {
    /// Entry distance per ray.
    pub t_in: Vec<f32>,
    /// Exit distance per ray.
    pub t_out: Vec<f32>,
}

impl FanHits {
    /// Buffers for a fan of `n` rays.
    pub fn with_len(n: usize) -> Self {
        Self { t_in: vec![0.0; n], t_out: vec![0.0; n] }
    }
}

impl Shape {
    /// Expresses the shape in the frame of a sensor at `sensor` (for [`PreparedShape::cast`]).
    pub fn prepare(&self, sensor: &Pose2) -> PreparedShape {
        let (ss, sc) = sensor.yaw.sin_cos();
        let p = sensor.position();
        match self {
            Shape::Cuboid(b) => {
                let (bc, bs) = b.rotation();
                PreparedShape::Cuboid {
                    origin: b.to_local(p),
                    cos: sc * bc + ss * bs,
                    sin: ss * bc - sc * bs,
                    half: b.half,
                }
            }
            Shape::Cylinder(c) => {
                let oc = (p - c.center).rotate(sc, -ss);
                PreparedShape::Cylinder { oc, c: oc.length_sq() - c.radius * c.radius }
            }
            Shape::Polygon(poly) => {
                let mut nx = [0.0; MAX_POLYGON_VERTICES];
                let mut ny = [0.0; MAX_POLYGON_VERTICES];
                let mut num = [0.0; MAX_POLYGON_VERTICES];
                for (i, (n, c)) in poly.normals().iter().zip(poly.offsets()).enumerate() {
                    let ns = n.rotate(sc, -ss);
                    nx[i] = ns.x;
                    ny[i] = ns.y;
                    num[i] = c - n.dot(p);
                }
                PreparedShape::Polygon { n: poly.normals().len(), nx, ny, num }
            }
        }
    }
}

impl PreparedShape {
    /// Casts rays `range` of `fan`, writing entry/exit distances to `hits[range]`.
    pub fn cast(&self, fan: &Fan, range: Range<usize>, hits: &mut FanHits) {
        let (cos, sin) = (&fan.cos[range.clone()], &fan.sin[range.clone()]);
        let t_in = &mut hits.t_in[range.clone()];
        let t_out = &mut hits.t_out[range];
        match *self {
            PreparedShape::Cuboid { origin, cos: rc, sin: rs, half } => {
                for i in 0..cos.len() {
                    let d = Vec2::new(rc * cos[i] - rs * sin[i], rs * cos[i] + rc * sin[i]);
                    let (a, b) = slab(origin, d, half);
                    t_in[i] = a;
                    t_out[i] = b;
                }
            }
            PreparedShape::Cylinder { oc, c } => {
                for i in 0..cos.len() {
                    let b = oc.x * cos[i] + oc.y * sin[i];
                    let disc = b * b - c;
                    let s = disc.max(0.0).sqrt();
                    let hit = disc >= 0.0;
                    t_in[i] = if hit { -b - s } else { f32::INFINITY };
                    t_out[i] = if hit { -b + s } else { f32::NEG_INFINITY };
                }
            }
            PreparedShape::Polygon { n, ref nx, ref ny, ref num } => {
                for i in 0..cos.len() {
                    let (mut a, mut b) = (f32::NEG_INFINITY, f32::INFINITY);
                    for e in 0..n {
                        let denom = nx[e] * cos[i] + ny[e] * sin[i];
                        let t = num[e] / denom;
                        if denom > 0.0 {
                            b = b.min(t);
                        } else if denom < 0.0 {
                            a = a.max(t);
                        } else if num[e] < 0.0 {
                            a = f32::INFINITY;
                        }
                    }
                    t_in[i] = a;
                    t_out[i] = b;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::{ConvexPolygon, Cuboid, Cylinder};
    use proptest::prelude::*;

    fn uniform_fan(n: usize, span: f32) -> Fan {
        Fan::new((0..n).map(|i| -span / 2.0 + span * i as f32 / (n - 1) as f32).collect())
    }

    fn shapes() -> impl Strategy<Value = Shape> {
        let c = || (-5.0f32..5.0, -5.0f32..5.0);
        prop_oneof![
            (c(), 0.05f32..3.0, 0.05f32..3.0, -4.0f32..4.0).prop_map(|((x, y), w, h, yaw)| {
                Shape::Cuboid(Cuboid::new(Vec2::new(x, y), Vec2::new(w, h), yaw).expect("box"))
            }),
            (c(), 0.05f32..2.0).prop_map(|((x, y), r)| {
                Shape::Cylinder(Cylinder::new(Vec2::new(x, y), r).expect("cyl"))
            }),
            (c(), 0.2f32..2.0, 3usize..9, -3.0f32..3.0).prop_map(|((x, y), r, n, rot)| {
                let pts: Vec<Vec2> = (0..n)
                    .map(|i| {
                        Vec2::new(x, y) + Vec2::from_angle(rot + i as f32 * TAU / n as f32) * r
                    })
                    .collect();
                Shape::Polygon(ConvexPolygon::new(&pts).expect("poly"))
            }),
        ]
    }

    proptest! {
        /// The vectorised fan cast in the sensor frame agrees with the world-frame scalar cast,
        /// and the extent pre-filter never drops a ray that hits.
        #[test]
        fn fan_agrees_with_world_casts(shape in shapes(), px in -6.0f32..6.0, py in -6.0f32..6.0, yaw in -3.1f32..3.1) {
            let fan = uniform_fan(361, TAU - 0.01);
            let sensor = Pose2::new(px, py, yaw);
            let mut hits = FanHits::with_len(fan.len());
            shape.prepare(&sensor).cast(&fan, 0..fan.len(), &mut hits);
            let ranges = fan.ranges(shape.angular_extent(sensor.position()), yaw);
            for i in 0..fan.len() {
                let dir = Vec2::from_angle(yaw + fan.angles()[i]);
                let world = shape.cast_ray(sensor.position(), dir);
                let (a, b) = (hits.t_in[i], hits.t_out[i]);
                let fan_hit = a <= b && b >= 0.0;
                match world {
                    Some((wa, wb)) => {
                        // Grazing rays may flip between hit and miss; only compare clear hits.
                        if wb - wa.max(0.0) > 1e-3 {
                            prop_assert!(fan_hit, "ray {i}: world hit {wa}..{wb}, fan missed");
                            prop_assert!((a - wa).abs() < 1e-3 && (b - wb).abs() < 1e-3);
                            prop_assert!(ranges.iter().any(|r| r.contains(&i)), "ray {i} outside extent ranges {ranges:?}");
                        }
                    }
                    None => prop_assert!(!fan_hit || b - a.max(0.0) < 1e-3, "ray {i}: fan hit {a}..{b}, world missed"),
                }
                prop_assert!(!a.is_nan() || !fan_hit);
            }
        }
    }

    #[test]
    fn wall_ahead_gives_analytic_ranges() {
        // A wall face at x = 2 in front of a sensor at the origin: range = 2 / cos(angle).
        let wall = Shape::Cuboid(
            Cuboid::new(Vec2::new(2.5, 0.0), Vec2::new(1.0, 20.0), 0.0).expect("wall"),
        );
        let fan = uniform_fan(91, 1.0);
        let mut hits = FanHits::with_len(fan.len());
        wall.prepare(&Pose2::default()).cast(&fan, 0..fan.len(), &mut hits);
        for i in 0..fan.len() {
            let expect = 2.0 / fan.angles()[i].cos();
            assert!((hits.t_in[i] - expect).abs() < 1e-5, "{} vs {expect}", hits.t_in[i]);
        }
    }
}
