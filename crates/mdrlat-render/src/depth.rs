//! False-colour depth images with a metre colour bar.

use crate::font::{self, GLYPH_H, LINE_H};
use crate::image::Image;
use crate::style;

/// Turbo colour map (Google, 2019), polynomial fit by Ruofei Du: coefficients of
/// `c0 + c1·t + … + c5·t⁵` for red, green and blue.
const TURBO_FIT: [[f64; 6]; 3] = [
    [0.13572138, 4.61539260, -42.66032258, 132.13108234, -152.94239396, 59.28637943],
    [0.09140261, 2.19418839, 4.84296658, -14.18503333, 4.27729857, 2.82956604],
    [0.10667330, 12.64194608, -60.58204836, 110.36276771, -89.90310912, 27.34824973],
];

/// Turbo at `t` in [0, 1]: dark blue through green and yellow to dark red.
fn turbo(t: f32) -> [u8; 3] {
    let t = f64::from(t.clamp(0.0, 1.0));
    let channel = |c: &[f64; 6]| {
        let v = c.iter().rev().fold(0.0, |acc, k| acc * t + k);
        (v.clamp(0.0, 1.0) * 255.0).round() as u8
    };
    [channel(&TURBO_FIT[0]), channel(&TURBO_FIT[1]), channel(&TURBO_FIT[2])]
}

/// The part of the turbo map used: near is warm (dark red, 0.90), far is cool (blue, 0.10).
/// Both ends stay well away from black, which means "no return".
const TURBO_NEAR: f32 = 0.90;
const TURBO_FAR: f32 = 0.10;

/// The colour [`depth_view`] gives a depth of `depth_m` metres when the scale ends at
/// `max_m`: black for 0, negative or non-finite (no return or too close), dark red near,
/// blue at `max_m` and beyond.
pub fn depth_colour(depth_m: f32, max_m: f32) -> [u8; 3] {
    if !(depth_m.is_finite() && depth_m > 0.0) {
        return [0, 0, 0];
    }
    let f = (depth_m / max_m).clamp(0.0, 1.0);
    turbo(TURBO_NEAR + (TURBO_FAR - TURBO_NEAR) * f)
}

/// `n` colours spread evenly over the part of the turbo map the depth view uses, near to
/// far (for the GIF palette).
pub(crate) fn depth_ramp(n: usize) -> impl Iterator<Item = [u8; 3]> {
    let d = (n.max(2) - 1) as f32;
    (0..n).map(move |i| depth_colour(1e-3 + i as f32 / d, 1.0))
}

fn nice_step(min_m: f32) -> f32 {
    style::nice_step(min_m, 0.25)
}

fn metres_label(v: f32, step: f32) -> String {
    if step < 1.0 {
        format!("{v:.2}").trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.0}")
    }
}

/// Draws a depth image (`rows × cols` metres, row-major, top row first) in false colour,
/// each depth pixel a `scale × scale` block, with a colour bar in metres on the right.
///
/// Near is warm and far cool (see [`depth_colour`]); 0 (no return or too close, as the
/// Kinect reports) and non-finite values are black. Depths beyond `max_m` get the far
/// colour. A non-positive or non-finite `max_m` is replaced by the largest finite depth in
/// the image (1 m if there is none); a `scale` of 0 counts as 1; pixels missing from a short
/// `depth_m` are drawn as no return.
pub fn depth_view(depth_m: &[f32], rows: usize, cols: usize, max_m: f32, scale: u32) -> Image {
    let scale = scale.max(1);
    let max_m = if max_m.is_finite() && max_m > 0.0 {
        max_m
    } else {
        let m = depth_m.iter().copied().filter(|v| v.is_finite()).fold(0.0f32, f32::max);
        if m > 0.0 { m } else { 1.0 }
    };
    let (img_w, img_h) = (cols as u32 * scale, rows as u32 * scale);
    let ts = if img_h >= 200 { 2 } else { 1 };
    let (line, pad) = (LINE_H * ts, 6 * ts);
    let bar_w = 10 * ts;
    // The bar needs room for the unit above it, the "none" swatch below, and a few ticks.
    let height = img_h.max(2 * line + 6 * line);
    let bar_x = img_w + pad;
    let (bar_top, bar_bottom) = (line, height - line - 2 * ts);
    let step = nice_step((line as f32 * 2.2) * max_m / (bar_bottom - bar_top) as f32);
    let ticks: Vec<f32> =
        (0..=((max_m / step) + 1e-4).floor() as usize).take(64).map(|k| k as f32 * step).collect();
    let label_x = bar_x + bar_w + 5 * ts;
    let label_w = ticks
        .iter()
        .map(|&v| font::text_width(&metres_label(v, step), ts))
        .chain([font::text_width("none", ts)])
        .max()
        .unwrap_or(0);
    let width = label_x + label_w + pad;
    let mut img = Image::new(width, height, [255, 255, 255, 255]);

    // One colour per quantised depth, then nearest-neighbour blocks.
    const LEVELS: usize = 1024;
    let lut: Vec<[u8; 3]> = (0..LEVELS)
        .map(|i| depth_colour((i as f32 + 0.5) / LEVELS as f32 * max_m, max_m))
        .collect();
    let colour = |d: f32| {
        if !(d.is_finite() && d > 0.0) {
            [0, 0, 0]
        } else {
            lut[((d / max_m * LEVELS as f32) as usize).min(LEVELS - 1)]
        }
    };
    let stride = width as usize * 4;
    let s = scale as usize;
    for r in 0..rows {
        for c in 0..cols {
            let d = depth_m.get(r * cols + c).copied().unwrap_or(0.0);
            let [cr, cg, cb] = colour(d);
            for dy in 0..s {
                let row = (r * s + dy) * stride;
                for dx in 0..s {
                    let i = row + (c * s + dx) * 4;
                    img.rgba[i..i + 4].copy_from_slice(&[cr, cg, cb, 255]);
                }
            }
        }
    }

    // Colour bar: far (max_m) at the top, near (0) at the bottom, like the image itself
    // (the floor close by is at the bottom of a forward-looking camera's picture).
    let span = (bar_bottom - bar_top) as f32;
    for y in bar_top..bar_bottom {
        let d = max_m * (1.0 - (y - bar_top) as f32 / span);
        let [cr, cg, cb] = depth_colour(d.max(1e-4), max_m);
        for x in bar_x..bar_x + bar_w {
            let i = y as usize * stride + x as usize * 4;
            img.rgba[i..i + 4].copy_from_slice(&[cr, cg, cb, 255]);
        }
    }
    let ink = [style::INK[0], style::INK[1], style::INK[2], 255];
    let glyph_mid = (GLYPH_H * ts / 2) as i32 - ts as i32 / 2;
    for &v in &ticks {
        let y = bar_top as f32 + span * (1.0 - v / max_m);
        let yi = (y.round() as u32).min(bar_bottom - 1);
        let y0 = yi.saturating_sub(ts / 2);
        for yy in y0..(y0 + ts).min(height) {
            for x in bar_x + bar_w..bar_x + bar_w + 2 * ts {
                let i = yy as usize * stride + x as usize * 4;
                img.rgba[i..i + 4].copy_from_slice(&ink);
            }
        }
        img.draw_text(label_x as i32, yi as i32 - glyph_mid, &metres_label(v, step), ts, ink);
    }
    img.draw_text(bar_x as i32, 0, "m", ts, ink);
    // The "no return" swatch.
    let sw_top = height - line + ts;
    for y in sw_top..sw_top + 7 * ts {
        for x in bar_x..bar_x + bar_w {
            let i = y as usize * stride + x as usize * 4;
            img.rgba[i..i + 4].copy_from_slice(&[0, 0, 0, 255]);
        }
    }
    img.draw_text(label_x as i32, sw_top as i32, "none", ts, ink);
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_are_black_warm_and_cool() {
        assert_eq!(depth_colour(0.0, 5.0), [0, 0, 0]);
        assert_eq!(depth_colour(f32::NAN, 5.0), [0, 0, 0]);
        assert_eq!(depth_colour(-1.0, 5.0), [0, 0, 0]);
        let near = depth_colour(0.5, 5.0);
        let far = depth_colour(5.0, 5.0);
        assert!(near[0] > near[2] + 100, "near is warm: {near:?}");
        assert!(far[2] > far[0] + 100, "far is cool: {far:?}");
        assert_eq!(depth_colour(50.0, 5.0), far, "beyond max clamps to far");
        assert_eq!(depth_ramp(8).count(), 8);
    }

    #[test]
    fn labels() {
        assert_eq!(metres_label(1.5, 0.5), "1.5");
        assert_eq!(metres_label(2.0, 1.0), "2");
        assert_eq!(metres_label(0.0, 0.25), "0");
        assert_eq!(metres_label(0.75, 0.25), "0.75");
    }
}
