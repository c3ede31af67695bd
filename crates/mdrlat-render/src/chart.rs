//! Line charts: training curves (paper Fig. 4) and traces (Figs. 6, 7).

use crate::font::{LINE_H, text_width};
use crate::image::Image;
use crate::style::{Rgb, nice_step};
use crate::top::{fill, stroke};
use tiny_skia::{PathBuilder, Pixmap};

/// One line of a chart, with an optional shaded band (e.g. mean ± std).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// `(x, y)` points, in x order.
    pub points: Vec<(f32, f32)>,
    /// `(x, low, high)` of a band drawn under the line; may be empty.
    pub band: Vec<(f32, f32, f32)>,
}

/// What to draw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Chart<'a> {
    /// Title above the plot.
    pub title: &'a str,
    /// Label under the x axis.
    pub x_label: &'a str,
    /// Label of the y axis (drawn above it).
    pub y_label: &'a str,
    /// The lines.
    pub series: &'a [Series],
}

/// Colours of successive series (colour-blind-friendly, as matplotlib's tab10).
const PALETTE: [Rgb; 8] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
];

/// The colour of series `i`.
pub fn series_colour(i: usize) -> Rgb {
    PALETTE[i % PALETTE.len()]
}

fn ticks(lo: f32, hi: f32, max_ticks: usize) -> (f32, Vec<f32>) {
    let step = nice_step((hi - lo) / max_ticks.max(1) as f32, 1e-6);
    let first = (lo / step).ceil() * step;
    let n = (((hi - first) / step).floor() as i64).clamp(0, 100) as usize;
    (step, (0..=n).map(|i| first + i as f32 * step).collect())
}

fn label(v: f32, step: f32) -> String {
    if step >= 1000.0 && v.abs() >= 1000.0 {
        let k = v / 1000.0;
        if (k - k.round()).abs() < 1e-3 { format!("{}k", k.round()) } else { format!("{k:.1}k") }
    } else if step >= 1.0 {
        format!("{v:.0}")
    } else if step >= 0.1 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}

/// Draws `chart` as a `width` x `height` picture with axes, ticks, grid and a legend.
/// Non-finite points are skipped; an empty chart is drawn with unit axes.
pub fn line_chart(chart: &Chart, width: u32, height: u32) -> Image {
    let (width, height) = (width.max(200), height.max(150));
    let ts = 2u32; // text scale
    let (left, right, top, bottom) = (80.0f32, 40.0f32, 50.0f32, 60.0f32);
    let finite = |p: &(f32, f32)| p.0.is_finite() && p.1.is_finite();
    let mut xs: Vec<f32> = Vec::new();
    let mut ys: Vec<f32> = Vec::new();
    for s in chart.series {
        for p in s.points.iter().filter(|p| finite(p)) {
            xs.push(p.0);
            ys.push(p.1);
        }
        for &(x, lo, hi) in &s.band {
            if x.is_finite() && lo.is_finite() && hi.is_finite() {
                ys.push(lo);
                ys.push(hi);
            }
        }
    }
    let range = |v: &[f32]| {
        let (lo, hi) =
            v.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
        if lo.is_finite() {
            if hi - lo > 1e-6 { (lo, hi) } else { (lo - 1.0, hi + 1.0) }
        } else {
            (0.0, 1.0)
        }
    };
    let (x0, x1) = range(&xs);
    let (y0, y1) = range(&ys);
    let pad = (y1 - y0) * 0.05;
    let (y0, y1) = (y0 - pad, y1 + pad);
    let (pw, ph) = (width as f32 - left - right, height as f32 - top - bottom);
    let px = |x: f32| left + (x - x0) / (x1 - x0) * pw;
    let py = |y: f32| top + (y1 - y) / (y1 - y0) * ph;

    let Some(mut pm) = Pixmap::new(width, height) else {
        return Image::new(width, height, [255; 4]);
    };
    pm.fill(tiny_skia::Color::WHITE);
    let (xstep, xt) = ticks(x0, x1, 8);
    let (ystep, yt) = ticks(y0, y1, 6);
    let mut grid = PathBuilder::new();
    for &x in &xt {
        grid.move_to(px(x), top);
        grid.line_to(px(x), top + ph);
    }
    for &y in &yt {
        grid.move_to(left, py(y));
        grid.line_to(left + pw, py(y));
    }
    if let Some(g) = grid.finish() {
        stroke(&mut pm, &g, [225, 225, 225], 255, 1.0);
    }
    for (i, s) in chart.series.iter().enumerate() {
        let c = series_colour(i);
        let band: Vec<&(f32, f32, f32)> = s
            .band
            .iter()
            .filter(|b| b.0.is_finite() && b.1.is_finite() && b.2.is_finite())
            .collect();
        if band.len() >= 2 {
            let mut pb = PathBuilder::new();
            pb.move_to(px(band[0].0), py(band[0].2));
            for b in &band[1..] {
                pb.line_to(px(b.0), py(b.2));
            }
            for b in band.iter().rev() {
                pb.line_to(px(b.0), py(b.1));
            }
            pb.close();
            if let Some(p) = pb.finish() {
                fill(&mut pm, &p, c, 50);
            }
        }
        let pts: Vec<&(f32, f32)> = s.points.iter().filter(|p| finite(p)).collect();
        let mut pb = PathBuilder::new();
        for (k, p) in pts.iter().enumerate() {
            if k == 0 {
                pb.move_to(px(p.0), py(p.1));
            } else {
                pb.line_to(px(p.0), py(p.1));
            }
        }
        if pts.len() == 1 {
            pb.line_to(px(pts[0].0) + 0.5, py(pts[0].1));
        }
        if let Some(p) = pb.finish() {
            stroke(&mut pm, &p, c, 255, 2.2);
        }
    }
    let mut frame = PathBuilder::new();
    frame.move_to(left, top);
    frame.line_to(left, top + ph);
    frame.line_to(left + pw, top + ph);
    if let Some(f) = frame.finish() {
        stroke(&mut pm, &f, [60, 60, 60], 255, 1.5);
    }
    let mut img = Image::from_opaque_pixmap(pm);
    let ink = [40, 40, 40, 255];
    let glyph_h = (LINE_H * ts) as i32;
    for &x in &xt {
        let t = label(x, xstep);
        img.draw_text(
            px(x) as i32 - text_width(&t, ts) as i32 / 2,
            (top + ph) as i32 + 8,
            &t,
            ts,
            ink,
        );
    }
    for &y in &yt {
        let t = label(y, ystep);
        img.draw_text(
            left as i32 - 8 - text_width(&t, ts) as i32,
            py(y) as i32 - glyph_h / 2 + 2,
            &t,
            ts,
            ink,
        );
    }
    img.draw_text(
        left as i32 + (pw as i32 - text_width(chart.x_label, ts) as i32) / 2,
        height as i32 - glyph_h - 4,
        chart.x_label,
        ts,
        ink,
    );
    img.draw_text(8, 28, chart.y_label, ts, ink);
    img.draw_text(
        left as i32 + (pw as i32 - text_width(chart.title, ts) as i32) / 2,
        6,
        chart.title,
        ts,
        ink,
    );
    // Legend, top left inside the plot.
    for (i, s) in chart.series.iter().enumerate() {
        let y = top as i32 + 8 + i as i32 * (glyph_h + 4);
        let c = series_colour(i);
        for dy in 0..4 {
            for dx in 0..22 {
                if let Some(p) =
                    pixel_index(&img, left as u32 + 10 + dx, (y + glyph_h / 2 - 2 + dy) as u32)
                {
                    img.rgba[p..p + 4].copy_from_slice(&[c[0], c[1], c[2], 255]);
                }
            }
        }
        img.draw_text(left as i32 + 38, y, &s.label, ts, ink);
    }
    img
}

fn pixel_index(img: &Image, x: u32, y: u32) -> Option<usize> {
    (x < img.width && y < img.height).then(|| (y as usize * img.width as usize + x as usize) * 4)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_land_where_their_data_says() {
        let s = Series { label: "a".into(), points: vec![(0.0, 0.0), (10.0, 10.0)], band: vec![] };
        let chart =
            Chart { title: "t", x_label: "x", y_label: "y", series: std::slice::from_ref(&s) };
        let img = line_chart(&chart, 400, 300);
        assert_eq!((img.width, img.height), (400, 300));
        // The line's midpoint (5, 5) is drawn in the first series colour.
        let (pw, ph) = (400.0 - 120.0, 300.0 - 110.0);
        let (y0, y1) = (-0.5f32, 10.5f32);
        let x = 80.0 + 0.5 * pw;
        let y = 50.0 + (y1 - 5.0) / (y1 - y0) * ph;
        let p = img.pixel(x as u32, y as u32).expect("inside");
        let c = series_colour(0);
        assert!(
            p[..3].iter().zip(c).all(|(a, b)| (i32::from(*a) - i32::from(b)).abs() < 40),
            "{p:?}"
        );
        assert_eq!(line_chart(&chart, 400, 300), img, "deterministic");
        // Empty and non-finite data do not panic.
        let empty = Chart { series: &[], ..chart };
        let _ = line_chart(&empty, 10, 10);
        let nan = Series {
            label: "n".into(),
            points: vec![(f32::NAN, 1.0), (1.0, f32::INFINITY)],
            band: vec![],
        };
        let _ = line_chart(&Chart { series: &[nan], ..chart }, 300, 200);
    }
}
