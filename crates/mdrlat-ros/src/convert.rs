//! From a robot's messages to the simulator's sensor frames (SPEC §2, §6): any laser scan to
//! 512 beams over 270°, any depth image to 128 x 160 metres. What comes out is exactly what
//! the simulator's sensors produce, so the one normalisation in `mdrlat-core` applies to both.

use crate::msg::{Image, LaserScan};
use mdrlat_core::{
    DEPTH_COLS, DEPTH_MIN_RANGE_M, DEPTH_ROWS, LASER_BEAMS, LASER_MAX_RANGE_M, laser_beam_angle,
};
use std::f32::consts::{PI, TAU};
use thiserror::Error;

/// The smallest beam spacing accepted, radians.
const MIN_INCREMENT: f32 = 1e-6 * TAU;
/// A blind sector up to this wide (radians) between a scan's last and first beam is bridged
/// by the nearest beams: 360° scanners leave a fraction of a degree uncovered.
const MAX_BRIDGED_GAP: f32 = 2.0 * std::f32::consts::PI / 180.0;

/// What to do with non-finite ranges in a scan.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NonFinite {
    /// Any NaN or ±inf makes the scan malformed (the robot stops until a clean one).
    #[default]
    Reject,
    /// REP 117: +inf is "no return within range" (reads the maximum range, as in the
    /// simulator), −inf is "too close to measure" (reads 0); NaN is still rejected.
    Rep117,
}

/// How scans are read.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ScanOptions {
    /// The laser frame's yaw on the robot, radians (π for a laser mounted backwards): beam
    /// angles are turned by it so that 0 is the robot's heading, as in the simulator.
    pub yaw_offset: f32,
    /// Non-finite ranges.
    pub non_finite: NonFinite,
    /// Beams of the 270° fan that the scan does not cover read the maximum range instead of
    /// making the scan an error. Dangerous: unseen space is treated as free.
    pub fill_gaps: bool,
}

/// A scan that cannot be used.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum ScanError {
    /// No ranges.
    #[error("the scan has no ranges")]
    Empty,
    /// Angles that define no fan.
    #[error("angle_min {angle_min} / angle_increment {angle_increment} do not define a fan")]
    Geometry {
        /// `angle_min`.
        angle_min: f32,
        /// `angle_increment`.
        angle_increment: f32,
    },
    /// Non-finite ranges (see [`NonFinite`]).
    #[error("{count} non-finite ranges (first: {value} at index {index})")]
    NonFinite {
        /// How many.
        count: usize,
        /// The first's index.
        index: usize,
        /// Its value.
        value: f32,
    },
    /// A negative range.
    #[error("negative range {value} at index {index}")]
    Negative {
        /// Index.
        index: usize,
        /// Value.
        value: f32,
    },
    /// The scan does not cover the policy's 270° fan.
    #[error(
        "the scan covers {from_deg:.1}° to {to_deg:.1}°, the policy needs −135° to 135°: \
         {missing} of 512 beams would be unseen (mount the laser to see them, or opt in to \
         reading them as free space with --fill-scan-gaps)"
    )]
    Coverage {
        /// First angle covered, degrees.
        from_deg: f32,
        /// Last angle covered, degrees.
        to_deg: f32,
        /// Beams not covered.
        missing: usize,
    },
}

/// Resamples `scan` to the simulator's 512 beams over 270° (metres, at most the simulator's
/// 5.6 m maximum range). Each beam takes the nearest range among the source beams within
/// its angular bin (a conservative choice: a thin obstacle seen by one fine beam is not
/// averaged away), or the nearest source beam when the source is coarser.
///
/// Ranges above `range_max` (or 5.6 m) read 5.6 m, as a return beyond range does in the
/// simulator. Finite ranges below `range_min` are kept as they are: on the robot a reading
/// "too close" must never become free space.
///
/// # Errors
/// See [`ScanError`].
pub fn resample_scan(
    scan: &LaserScan,
    options: ScanOptions,
    out: &mut [f32; LASER_BEAMS],
) -> Result<(), ScanError> {
    let n = scan.ranges.len();
    if n == 0 {
        return Err(ScanError::Empty);
    }
    let inc = scan.angle_increment;
    // A usable fan: at least two beams, finite angles, an increment above 0.0001° (a
    // degenerate increment would make one output bin span billions of source beams).
    // And no more than one turn (an increment in degrees read as radians would otherwise
    // pass as a 360° scan), from a sane start angle.
    if n < 2
        || !scan.angle_min.is_finite()
        || scan.angle_min.abs() > 2.0 * TAU
        || !inc.is_finite()
        || inc.abs() < MIN_INCREMENT
        || (n - 1) as f32 * inc.abs() > TAU + inc.abs()
    {
        return Err(ScanError::Geometry { angle_min: scan.angle_min, angle_increment: inc });
    }
    let cap = if scan.range_max.is_finite() && scan.range_max > 0.0 {
        scan.range_max.min(LASER_MAX_RANGE_M)
    } else {
        LASER_MAX_RANGE_M
    };
    // Clean ranges first, in scan order.
    let mut ranges = Vec::with_capacity(n);
    let mut bad: Option<(usize, usize, f32)> = None;
    for (i, &r) in scan.ranges.iter().enumerate() {
        let v = match (r.is_finite(), options.non_finite) {
            (true, _) if r < 0.0 => return Err(ScanError::Negative { index: i, value: r }),
            (true, _) => r.min(cap),
            (false, NonFinite::Rep117) if r == f32::INFINITY => cap,
            (false, NonFinite::Rep117) if r == f32::NEG_INFINITY => 0.0,
            (false, _) => {
                let b = bad.get_or_insert((0, i, r));
                b.0 += 1;
                0.0
            }
        };
        ranges.push(v);
    }
    if let Some((count, index, value)) = bad {
        return Err(ScanError::NonFinite { count, index, value });
    }
    // Beam angles ascending: a clockwise scanner (negative increment) is read backwards.
    let step = inc.abs();
    let first = options.yaw_offset
        + if inc >= 0.0 { scan.angle_min } else { scan.angle_min + inc * (n - 1) as f32 };
    if inc < 0.0 {
        ranges.reverse();
    }
    let turn = TAU / step; // source beams in a full turn
    let last = (n - 1) as f32;
    // Every angle is measured from the first beam, counter-clockwise, in [0, 2π): a scan
    // that starts anywhere (0..2π, −π..π, turned by the mounting yaw) is read the same.
    let full_circle = TAU - n as f32 * step <= MAX_BRIDGED_GAP;
    // Indices wrap only where the beams really tile the turn; across a bridged gap they
    // stop at the beam on the gap's near side.
    let tiles = (n as f32 * step - TAU).abs() < step / 2.0;
    let bin = (mdrlat_core::LASER_FOV_DEG.to_radians() / (LASER_BEAMS - 1) as f32) / 2.0;
    let half = bin / step; // half a target bin, in source beams
    let mut missing = 0;
    for (k, o) in out.iter_mut().enumerate() {
        let p0 = (laser_beam_angle(k) - first).rem_euclid(TAU) / step;
        let p = if p0 <= last + 0.5 {
            p0
        } else if turn - p0 <= 0.5 || (full_circle && turn - p0 < p0 - last) {
            p0 - turn // just before the first beam
        } else if full_circle {
            p0 // in a bridged gap, nearer the last beam
        } else {
            missing += 1;
            *o = LASER_MAX_RANGE_M;
            continue;
        };
        // Source beams whose angle falls in this beam's bin [θ − bin/2, θ + bin/2); with
        // a coarser source the bin may hold none: take the nearest. Never more than n.
        let lo = (p - half).ceil() as i64;
        let hi = (p + half).ceil() as i64 - 1;
        let (lo, hi) = if hi < lo {
            let nearest = p.round() as i64;
            (nearest, nearest)
        } else {
            (lo, hi.min(lo + n as i64 - 1))
        };
        let mut best = f32::INFINITY;
        for j in lo..=hi {
            let idx = if tiles {
                j.rem_euclid(n as i64) as usize
            } else {
                j.clamp(0, n as i64 - 1) as usize
            };
            best = best.min(ranges[idx]);
        }
        *o = best;
    }
    if missing > 0 && !options.fill_gaps {
        let from = (first + PI).rem_euclid(TAU) - PI;
        return Err(ScanError::Coverage {
            from_deg: from.to_degrees(),
            to_deg: (from + step * last).to_degrees(),
            missing,
        });
    }
    Ok(())
}

/// The angles a scan must cover, for start-up messages: `(first, last)` in degrees.
pub fn required_coverage_deg() -> (f32, f32) {
    (laser_beam_angle(0).to_degrees(), laser_beam_angle(LASER_BEAMS - 1).to_degrees())
}

/// A depth image that cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[non_exhaustive]
pub enum DepthError {
    /// Width or height 0.
    #[error("the image is {width}x{height}")]
    Empty {
        /// Columns.
        width: u32,
        /// Rows.
        height: u32,
    },
    /// Not a depth encoding.
    #[error("encoding {0:?} is not a depth image (expected 32FC1 metres or 16UC1 millimetres)")]
    Encoding(String),
    /// `step` smaller than a row.
    #[error("step {step} is less than width {width} x {bytes} bytes")]
    Step {
        /// `step`.
        step: u32,
        /// `width`.
        width: u32,
        /// Bytes per pixel.
        bytes: u32,
    },
    /// `data` is not `height · step` bytes.
    #[error("data has {len} bytes, height {height} x step {step} = {expected}")]
    Length {
        /// Bytes received.
        len: usize,
        /// `height`.
        height: u32,
        /// `step`.
        step: u32,
        /// `height · step`.
        expected: u64,
    },
}

/// Converts a depth image to the simulator's 128 x 160 frame in metres, row-major.
///
/// Pixels are read as metres (`32FC1`) or millimetres (`16UC1`, `mono16`); NaN, ±inf and
/// reads closer than 0.4 m become 0 ("no reading", as the Kinect and the simulator report
/// it). The image is area-resized: each output pixel is the mean of the valid source pixels
/// under it, weighted by overlap, or 0 when less than half of its area has a valid reading
/// (so a border between an object and "no reading" does not invent a depth in between).
///
/// # Errors
/// See [`DepthError`].
pub fn convert_depth(image: &Image, out: &mut [f32]) -> Result<(), DepthError> {
    assert_eq!(out.len(), DEPTH_ROWS * DEPTH_COLS, "convert_depth: output length");
    let (w, h) = (image.width, image.height);
    if w == 0 || h == 0 {
        return Err(DepthError::Empty { width: w, height: h });
    }
    let (bytes, scale) = match image.encoding.as_str() {
        "32FC1" => (4u32, 1.0f32),
        "16UC1" | "mono16" => (2, 1e-3),
        other => return Err(DepthError::Encoding(other.to_string())),
    };
    if u64::from(image.step) < u64::from(w) * u64::from(bytes) {
        return Err(DepthError::Step { step: image.step, width: w, bytes });
    }
    let expected = u64::from(h) * u64::from(image.step);
    if image.data.len() as u64 != expected {
        return Err(DepthError::Length {
            len: image.data.len(),
            height: h,
            step: image.step,
            expected,
        });
    }
    let big = image.is_bigendian != 0;
    let (w, h, step) = (w as usize, h as usize, image.step as usize);
    let pixel = |r: usize, c: usize| -> f32 {
        let at = r * step + c * bytes as usize;
        let d = &image.data[at..at + bytes as usize];
        let raw = match (bytes, big) {
            (4, false) => f32::from_le_bytes([d[0], d[1], d[2], d[3]]),
            (4, true) => f32::from_be_bytes([d[0], d[1], d[2], d[3]]),
            (_, false) => f32::from(u16::from_le_bytes([d[0], d[1]])),
            (_, true) => f32::from(u16::from_be_bytes([d[0], d[1]])),
        } * scale;
        if raw.is_finite() && raw >= DEPTH_MIN_RANGE_M { raw } else { 0.0 }
    };
    let rows = footprints(h, DEPTH_ROWS);
    let cols = footprints(w, DEPTH_COLS);
    for (r, row_span) in rows.iter().enumerate() {
        for (c, col_span) in cols.iter().enumerate() {
            let (mut sum, mut valid, mut total) = (0.0f32, 0.0f32, 0.0f32);
            for &(sr, wr) in row_span {
                for &(sc, wc) in col_span {
                    let weight = wr * wc;
                    let d = pixel(sr, sc);
                    total += weight;
                    if d > 0.0 {
                        sum += d * weight;
                        valid += weight;
                    }
                }
            }
            out[r * DEPTH_COLS + c] =
                if valid * 2.0 >= total && valid > 0.0 { sum / valid } else { 0.0 };
        }
    }
    Ok(())
}

/// For each of `m` output cells over `n` source cells: the source cells it overlaps and by
/// how much (in source cells). With `m > n` a cell overlaps one or two sources.
fn footprints(n: usize, m: usize) -> Vec<Vec<(usize, f32)>> {
    let ratio = n as f64 / m as f64;
    (0..m)
        .map(|k| {
            let (a, b) = (k as f64 * ratio, (k + 1) as f64 * ratio);
            let mut cells = Vec::new();
            let mut i = a.floor() as usize;
            while (i as f64) < b && i < n {
                let overlap = (b.min(i as f64 + 1.0) - a.max(i as f64)) as f32;
                if overlap > 1e-6 {
                    cells.push((i, overlap));
                }
                i += 1;
            }
            cells
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::PI;

    fn scan(angle_min: f32, inc: f32, ranges: Vec<f32>) -> LaserScan {
        LaserScan {
            angle_min,
            angle_max: angle_min + inc * (ranges.len() as f32 - 1.0),
            angle_increment: inc,
            range_min: 0.15,
            range_max: 12.0,
            ranges,
            ..LaserScan::default()
        }
    }

    /// A source with the simulator's own geometry comes out unchanged.
    #[test]
    fn identity_geometry_is_identity() {
        let fov = 270f32.to_radians();
        let ranges: Vec<f32> = (0..512).map(|i| 0.5 + i as f32 * 0.01).collect();
        let s = scan(-fov / 2.0, fov / 511.0, ranges.clone());
        let mut out = [0.0; 512];
        assert_eq!(resample_scan(&s, ScanOptions::default(), &mut out), Ok(()));
        for (i, (&a, &b)) in out.iter().zip(&ranges).enumerate() {
            assert!((a - b.min(5.6)).abs() < 1e-6, "beam {i}: {a} vs {b}");
        }
    }

    /// A 360° RPLIDAR-like scan (0..2π, 1° steps) and a clockwise one: the beam pointing at
    /// an obstacle reads it, wherever the scan starts.
    #[test]
    fn full_circle_and_clockwise_scans() {
        let mut ranges = vec![3.0; 360];
        ranges[90] = 1.0; // at +90° (left)
        let s = scan(0.0, PI / 180.0, ranges.clone());
        let mut out = [0.0; 512];
        assert_eq!(resample_scan(&s, ScanOptions::default(), &mut out), Ok(()));
        let left = (0..512).min_by(|&a, &b| {
            (laser_beam_angle(a) - PI / 2.0)
                .abs()
                .total_cmp(&(laser_beam_angle(b) - PI / 2.0).abs())
        });
        assert_eq!(out[left.unwrap_or(0)], 1.0);
        // One 1° source beam over ~0.53° bins: the bins nearest to it, and only those.
        for (k, &r) in out.iter().enumerate() {
            let off = (laser_beam_angle(k) - PI / 2.0).abs().to_degrees();
            assert_eq!(r == 1.0, off < 0.6, "beam {k} at {off:.2}° from the obstacle: {r}");
        }
        // The same scan sampled clockwise from +π.
        let cw: Vec<f32> = (0..360).map(|j| ranges[(540 - j) % 360]).collect();
        let s = scan(PI, -PI / 180.0, cw);
        let mut out2 = [0.0; 512];
        assert_eq!(resample_scan(&s, ScanOptions::default(), &mut out2), Ok(()));
        assert_eq!(out2, out);
        // A laser mounted backwards: its +90° beam looks at the robot's −90°.
        let back = ScanOptions { yaw_offset: PI, ..ScanOptions::default() };
        let s = scan(0.0, PI / 180.0, ranges);
        assert_eq!(resample_scan(&s, back, &mut out2), Ok(()));
        assert_eq!(out2[511 - left.unwrap_or(0)], 1.0);
    }

    /// A fine scan: the minimum in each bin survives resampling.
    #[test]
    fn fine_scans_keep_thin_obstacles() {
        let n = 2000;
        let fov = 270f32.to_radians();
        let mut ranges = vec![4.0; n];
        ranges[1234] = 0.9;
        let s = scan(-fov / 2.0, fov / (n - 1) as f32, ranges);
        let mut out = [0.0; 512];
        assert_eq!(resample_scan(&s, ScanOptions::default(), &mut out), Ok(()));
        assert_eq!(out.iter().filter(|&&r| r == 0.9).count(), 1);
        assert!(out.iter().all(|&r| r == 4.0 || r == 0.9));
    }

    /// rplidar_ros without angle compensation: −179.4°…179.7° in 1,450 beams, mounted
    /// backwards. Its blind 0.9° is bridged; every robot-frame beam reads what it sees.
    #[test]
    fn nearly_full_scans_mounted_backwards() {
        let n = 1450;
        let inc = 2.0 * PI / 1455.0;
        let mut ranges = vec![3.0; n];
        // The laser's own −90° (its right) is the robot's +90° when mounted backwards.
        let right = ((-PI / 2.0 - (-179.4f32).to_radians()) / inc).round() as usize;
        ranges[right] = 1.0;
        let s = scan((-179.4f32).to_radians(), inc, ranges);
        let back = ScanOptions { yaw_offset: PI, ..ScanOptions::default() };
        let mut out = [0.0; 512];
        assert_eq!(resample_scan(&s, back, &mut out), Ok(()));
        let hits: Vec<usize> = (0..512).filter(|&k| out[k] == 1.0).collect();
        assert_eq!(hits.len(), 1, "{hits:?}");
        assert!((laser_beam_angle(hits[0]) - PI / 2.0).abs() < 0.01);
        assert!(out.iter().all(|&r| r == 1.0 || r == 3.0));
        // A 90° blind sector is not bridged.
        let s = scan(0.0, PI / 180.0, vec![2.0; 270]);
        let e = resample_scan(&s, back, &mut out);
        assert!(matches!(e, Err(ScanError::Coverage { .. })), "{e:?}");
    }

    #[test]
    fn degenerate_fans_are_errors() {
        let mut out = [0.0; 512];
        for s in [
            scan(0.0, 1e-30, vec![1.0; 1000]),
            scan(0.0, f32::MIN_POSITIVE, vec![1.0; 3]),
            scan(0.0, 0.01, vec![1.0]),
            scan(f32::NAN, 0.01, vec![1.0; 10]),
            scan(1e10, 0.01, vec![1.0; 10]),
            // A 270° laser whose increment is in degrees (0.25) read as radians.
            scan(-2.356, 0.25, vec![1.0; 1081]),
        ] {
            let e = resample_scan(
                &s,
                ScanOptions { fill_gaps: true, ..ScanOptions::default() },
                &mut out,
            );
            assert!(matches!(e, Err(ScanError::Geometry { .. })), "{e:?}");
        }
    }

    #[test]
    fn coverage_non_finite_and_far_ranges() {
        let narrow = scan(-PI / 2.0, PI / 180.0, vec![2.0; 181]); // 180° only
        let mut out = [0.0; 512];
        let e = resample_scan(&narrow, ScanOptions::default(), &mut out);
        assert!(matches!(e, Err(ScanError::Coverage { missing, .. }) if missing > 100), "{e:?}");
        let fill = ScanOptions { fill_gaps: true, ..ScanOptions::default() };
        assert_eq!(resample_scan(&narrow, fill, &mut out), Ok(()));
        assert_eq!((out[0], out[256]), (5.6, 2.0));

        let fov = 270f32.to_radians();
        let mut ranges = vec![20.0; 512];
        ranges[3] = f32::INFINITY;
        ranges[7] = f32::NEG_INFINITY;
        let s = scan(-fov / 2.0, fov / 511.0, ranges.clone());
        let e = resample_scan(&s, ScanOptions::default(), &mut out);
        assert_eq!(e, Err(ScanError::NonFinite { count: 2, index: 3, value: f32::INFINITY }));
        let rep = ScanOptions { non_finite: NonFinite::Rep117, ..ScanOptions::default() };
        assert_eq!(resample_scan(&s, rep, &mut out), Ok(()));
        assert_eq!((out[0], out[3], out[7]), (5.6, 5.6, 0.0));
        ranges[9] = f32::NAN;
        let s = scan(-fov / 2.0, fov / 511.0, ranges);
        assert!(matches!(resample_scan(&s, rep, &mut out), Err(ScanError::NonFinite { .. })));
        let e = resample_scan(&scan(0.0, 0.0, vec![1.0; 3]), ScanOptions::default(), &mut out);
        assert!(matches!(e, Err(ScanError::Geometry { .. })));
        assert_eq!(
            resample_scan(&scan(0.0, 0.1, vec![]), ScanOptions::default(), &mut out),
            Err(ScanError::Empty)
        );
    }

    fn depth_image(w: u32, h: u32, enc: &str, f: impl Fn(u32, u32) -> f32) -> Image {
        let mut data = Vec::new();
        for r in 0..h {
            for c in 0..w {
                let d = f(r, c);
                match enc {
                    "16UC1" => data.extend_from_slice(&((d * 1000.0) as u16).to_le_bytes()),
                    _ => data.extend_from_slice(&d.to_le_bytes()),
                }
            }
        }
        let bytes = if enc == "16UC1" { 2 } else { 4 };
        Image {
            width: w,
            height: h,
            encoding: enc.into(),
            step: w * bytes,
            data,
            ..Image::default()
        }
    }

    #[test]
    fn kinect_sized_images_area_resize() {
        // 640x480 Kinect frame: left half 2 m, right half 3 m, a NaN block and a too-near block.
        let img = depth_image(640, 480, "32FC1", |r, c| {
            if r < 12 && c < 16 {
                f32::NAN
            } else if r >= 468 && c >= 624 {
                0.2
            } else if c < 320 {
                2.0
            } else {
                3.0
            }
        });
        let mut out = vec![0.0; DEPTH_ROWS * DEPTH_COLS];
        assert_eq!(convert_depth(&img, &mut out), Ok(()));
        assert_eq!(out[40 * 160 + 10], 2.0);
        assert_eq!(out[40 * 160 + 150], 3.0);
        assert_eq!(out[0], 0.0, "NaN block reads no return");
        assert_eq!(out[127 * 160 + 159], 0.0, "closer than 0.4 m reads 0");
        // 16UC1 millimetres, and the simulator's own size maps 1:1.
        let img = depth_image(160, 128, "16UC1", |r, c| 0.5 + (r * 160 + c) as f32 * 1e-4);
        assert_eq!(convert_depth(&img, &mut out), Ok(()));
        assert!((out[5 * 160 + 7] - (0.5 + 807e-4)).abs() < 2e-3);
    }

    #[test]
    fn malformed_images_are_errors() {
        let mut out = vec![0.0; DEPTH_ROWS * DEPTH_COLS];
        let good = depth_image(4, 3, "32FC1", |_, _| 1.0);
        let mut short = good.clone();
        short.data.pop();
        assert!(matches!(convert_depth(&short, &mut out), Err(DepthError::Length { .. })));
        let mut enc = good.clone();
        enc.encoding = "rgb8".into();
        assert!(matches!(convert_depth(&enc, &mut out), Err(DepthError::Encoding(_))));
        let mut zero = good.clone();
        zero.width = 0;
        assert!(matches!(convert_depth(&zero, &mut out), Err(DepthError::Empty { .. })));
        let mut step = good;
        step.step = 2;
        step.data.truncate(6);
        assert!(matches!(convert_depth(&step, &mut out), Err(DepthError::Step { .. })));
    }
}
