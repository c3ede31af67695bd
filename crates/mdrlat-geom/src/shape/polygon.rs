//! A convex polygon (tables, sofas, shelves of any convex footprint).

use super::ShapeError;
use crate::aabb::Aabb;
use crate::math::Vec2;

/// Most vertices a polygon may have (keeps the fan kernel's edge table on the stack).
pub const MAX_POLYGON_VERTICES: usize = 32;

/// A convex polygon stored counter-clockwise, with each edge's outward normal and offset so
/// that the interior is `{ p : n_i · p <= c_i for all i }`.
#[derive(Debug, Clone, PartialEq)]
pub struct ConvexPolygon {
    points: Vec<Vec2>,
    normals: Vec<Vec2>,
    offsets: Vec<f32>,
}

impl ConvexPolygon {
    /// Builds a convex polygon from points in either winding order.
    ///
    /// # Errors
    /// Fewer than 3 or more than [`MAX_POLYGON_VERTICES`] points, non-finite coordinates,
    /// repeated points, zero area, or a reflex (non-convex) vertex.
    pub fn new(points: &[Vec2]) -> Result<Self, ShapeError> {
        let n = points.len();
        if !(3..=MAX_POLYGON_VERTICES).contains(&n) {
            return Err(ShapeError::VertexCount { got: n });
        }
        if points.iter().any(|p| !p.is_finite()) {
            return Err(ShapeError::NotFinite("points"));
        }
        let area2: f32 = (0..n).map(|i| points[i].cross(points[(i + 1) % n])).sum();
        let mut pts = points.to_vec();
        if area2 < 0.0 {
            pts.reverse();
        }
        let scale =
            Aabb::from_points(pts.iter().copied()).map_or(1.0, |b| b.size().length().max(1e-3));
        if area2.abs() <= 1e-6 * scale * scale {
            return Err(ShapeError::NotConvex { index: 0 });
        }
        let mut normals = Vec::with_capacity(n);
        let mut offsets = Vec::with_capacity(n);
        for i in 0..n {
            let (a, b, c) = (pts[i], pts[(i + 1) % n], pts[(i + 2) % n]);
            let e = b - a;
            let len = e.length();
            if len <= 1e-6 * scale {
                return Err(ShapeError::NotConvex { index: (i + 1) % n });
            }
            // Counter-clockwise: every turn is a left turn (collinear allowed).
            if e.cross(c - b) < -1e-6 * scale * scale {
                let index = if area2 < 0.0 { n - 1 - (i + 1) % n } else { (i + 1) % n };
                return Err(ShapeError::NotConvex { index });
            }
            let nrm = Vec2::new(e.y / len, -e.x / len);
            normals.push(nrm);
            offsets.push(nrm.dot(a));
        }
        // A star-shaped but self-overlapping outline has all left turns yet winds twice.
        let turning: f32 = (0..n)
            .map(|i| {
                let (n0, n1) = (normals[i], normals[(i + 1) % n]);
                n0.cross(n1).atan2(n0.dot(n1))
            })
            .sum();
        if turning > std::f32::consts::TAU * 1.5 {
            return Err(ShapeError::NotConvex { index: 0 });
        }
        Ok(Self { points: pts, normals, offsets })
    }

    /// Vertices, counter-clockwise.
    pub fn points(&self) -> &[Vec2] {
        &self.points
    }

    /// Outward unit normals, one per edge `points[i] → points[i+1]`.
    pub fn normals(&self) -> &[Vec2] {
        &self.normals
    }

    /// Edge offsets `c_i = n_i · points[i]`.
    pub fn offsets(&self) -> &[f32] {
        &self.offsets
    }

    /// Mean of the vertices (inside, as the polygon is convex).
    pub fn centroid(&self) -> Vec2 {
        let s = self.points.iter().fold(Vec2::ZERO, |a, &p| a + p);
        s * (1.0 / self.points.len() as f32)
    }

    /// The polygon translated by `by`.
    pub fn translated(&self, by: Vec2) -> Self {
        Self {
            points: self.points.iter().map(|&p| p + by).collect(),
            normals: self.normals.clone(),
            offsets: self.offsets.iter().zip(&self.normals).map(|(c, n)| c + n.dot(by)).collect(),
        }
    }

    /// Bounding rectangle.
    pub fn aabb(&self) -> Aabb {
        Aabb::from_points(self.points.iter().copied()).unwrap_or(Aabb::new(Vec2::ZERO, Vec2::ZERO))
    }

    /// Distance from a point (0 inside).
    pub fn distance_to_point(&self, p: Vec2) -> f32 {
        let outside = self.normals.iter().zip(&self.offsets).any(|(n, c)| n.dot(p) > *c);
        if !outside {
            return 0.0;
        }
        let n = self.points.len();
        (0..n)
            .map(|i| segment_distance(p, self.points[i], self.points[(i + 1) % n]))
            .fold(f32::INFINITY, f32::min)
    }

    /// Cyrus–Beck clipping; returns raw `(t_in, t_out)` (a miss has `t_in > t_out`).
    pub fn cast_ray(&self, origin: Vec2, dir: Vec2) -> (f32, f32) {
        let (mut t_in, mut t_out) = (f32::NEG_INFINITY, f32::INFINITY);
        for (nrm, c) in self.normals.iter().zip(&self.offsets) {
            let denom = nrm.dot(dir);
            let num = c - nrm.dot(origin);
            if denom > 0.0 {
                t_out = t_out.min(num / denom);
            } else if denom < 0.0 {
                t_in = t_in.max(num / denom);
            } else if num < 0.0 {
                return (f32::INFINITY, f32::NEG_INFINITY);
            }
        }
        (t_in, t_out)
    }
}

fn segment_distance(p: Vec2, a: Vec2, b: Vec2) -> f32 {
    let ab = b - a;
    let t = ((p - a).dot(ab) / ab.length_sq()).clamp(0.0, 1.0);
    (p - (a + ab * t)).length()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f32, y: f32) -> Vec2 {
        Vec2::new(x, y)
    }

    #[test]
    fn accepts_either_winding_and_rejects_bad_outlines() {
        let cw = ConvexPolygon::new(&[v(0.0, 0.0), v(0.0, 1.0), v(1.0, 0.0)]).expect("cw");
        assert!(cw.distance_to_point(v(0.2, 0.2)) == 0.0);
        assert!((cw.distance_to_point(v(-1.0, 0.0)) - 1.0).abs() < 1e-6);
        let dart = [v(0.0, 0.0), v(2.0, 0.0), v(1.0, 0.5), v(1.0, 2.0)];
        assert!(matches!(ConvexPolygon::new(&dart), Err(ShapeError::NotConvex { .. })));
        assert!(ConvexPolygon::new(&[v(0.0, 0.0), v(1.0, 1.0)]).is_err());
        assert!(ConvexPolygon::new(&[v(0.0, 0.0), v(1.0, 1.0), v(2.0, 2.0)]).is_err());
        assert!(ConvexPolygon::new(&[v(0.0, 0.0), v(1.0, f32::NAN), v(2.0, 0.0)]).is_err());
        // A pentagram visits its points with only left turns but winds twice.
        let star: Vec<Vec2> = (0..5)
            .map(|i| Vec2::from_angle(i as f32 * 2.0 * std::f32::consts::TAU / 5.0))
            .collect();
        assert!(ConvexPolygon::new(&star).is_err());
    }
}
