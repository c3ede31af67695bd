//! Animated GIFs from frames, with one fixed palette.
//!
//! Why a fixed palette rather than quantising each frame (`gif::Frame::from_rgba_speed`):
//! - deterministic by construction, and a colour is the same index in every frame, so flat
//!   areas never flicker between frames;
//! - one global colour table, and frames can be stored as the rectangle that changed since
//!   the previous frame (usually the robot and its laser), so files stay small;
//! - fast: a pixel is quantised by one lookup in a 32×32×32 table built once per process,
//!   against NeuQuant's per-frame training.
//!
//! The palette holds every flat colour of [`crate::style`] exactly, their blends with the
//! floor (anti-aliased edges, translucent marks), a ramp of the depth colour map, greys and a
//! 5×5×5 colour cube for everything else. Smooth gradients band slightly; that is the price.

use crate::depth::depth_ramp;
use crate::error::RenderError;
use crate::image::Image;
use crate::style::{self, Rgb, mix};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Entries in the fixed GIF palette (the last one marks pixels unchanged since the previous
/// frame).
pub const PALETTE_LEN: usize = 256;

/// Palette index meaning "unchanged since the previous frame" in frames after the first.
const TRANSPARENT: u8 = (PALETTE_LEN - 1) as u8;

/// Bits per channel of the quantisation table.
const LUT_BITS: u32 = 5;
const LUT_SIDE: usize = 1 << LUT_BITS;

/// The fixed palette and its quantisation table.
struct Quantiser {
    /// `PALETTE_LEN * 3` bytes, R G B.
    palette: Vec<u8>,
    /// Palette index of every `LUT_BITS`-per-channel colour bucket, index `(r, g, b)`.
    lut: Vec<u8>,
}

fn palette_colours() -> Vec<Rgb> {
    let mut p: Vec<Rgb> = style::FLAT.to_vec();
    let marks = [
        style::TALL_LIGHT,
        style::TALL_DARK,
        style::LOW_LIGHT,
        style::LOW_DARK,
        style::OVERHANG,
        style::GOAL,
        style::PEDESTRIAN,
        style::ROBOT,
        style::ROBOT_HIT,
        style::LASER,
        style::TRAIL,
        style::SPAWN,
    ];
    for c in marks {
        for t in [0.25, 0.5, 0.75] {
            p.push(mix(style::FLOOR, c, t));
        }
    }
    p.extend(depth_ramp(55));
    p.extend((0..=16u32).map(|k| {
        let v = (k * 255 / 16) as u8;
        [v, v, v]
    }));
    let level = |k: u32| (k * 255 / 4) as u8;
    for r in 0..5 {
        for g in 0..5 {
            for b in 0..5 {
                p.push([level(r), level(g), level(b)]);
            }
        }
    }
    // 22 flat + 36 tints + 55 depth + 17 greys + 125 cube = 255 colours, then the
    // transparent slot (its colour is never chosen: quantising searches the first 255).
    debug_assert_eq!(p.len(), PALETTE_LEN - 1);
    p.truncate(PALETTE_LEN - 1);
    p.resize(PALETTE_LEN, [255, 0, 255]);
    p
}

/// Perceptually weighted squared distance (green counts most, blue least).
fn distance(a: Rgb, b: Rgb) -> u32 {
    let d = |i: usize| (i32::from(a[i]) - i32::from(b[i])).unsigned_abs();
    2 * d(0) * d(0) + 4 * d(1) * d(1) + 3 * d(2) * d(2)
}

fn nearest(palette: &[Rgb], c: Rgb) -> u8 {
    let mut best = (u32::MAX, 0usize);
    for (i, &p) in palette.iter().enumerate() {
        let d = distance(c, p);
        if d < best.0 {
            best = (d, i);
        }
    }
    best.1 as u8
}

fn bucket(c: Rgb) -> usize {
    let q = |v: u8| usize::from(v >> (8 - LUT_BITS));
    (q(c[0]) * LUT_SIDE + q(c[1])) * LUT_SIDE + q(c[2])
}

impl Quantiser {
    fn get() -> &'static Quantiser {
        static Q: OnceLock<Quantiser> = OnceLock::new();
        Q.get_or_init(|| {
            let colours = palette_colours();
            let centre = |k: usize| ((k << (8 - LUT_BITS)) + (1 << (7 - LUT_BITS))) as u8;
            let mut lut = vec![0u8; LUT_SIDE * LUT_SIDE * LUT_SIDE];
            for r in 0..LUT_SIDE {
                for g in 0..LUT_SIDE {
                    for b in 0..LUT_SIDE {
                        let c = [centre(r), centre(g), centre(b)];
                        lut[(r * LUT_SIDE + g) * LUT_SIDE + b] =
                            nearest(&colours[..PALETTE_LEN - 1], c);
                    }
                }
            }
            // The flat colours and their tints come out exactly (first entries win).
            let exact = style::FLAT.len() + 12 * 3;
            for (i, &c) in colours.iter().enumerate().take(exact).rev() {
                lut[bucket(c)] = i as u8;
            }
            Quantiser { palette: colours.concat(), lut }
        })
    }

    fn index(&self, r: u8, g: u8, b: u8) -> u8 {
        self.lut[bucket([r, g, b])]
    }
}

/// Writes an animated GIF frame by frame (looping forever).
///
/// All frames have the size given at creation: larger pictures are cropped and smaller ones
/// padded with white, top-left aligned. Colours come from one fixed palette (see the module
/// notes); each frame after the first stores only the rectangle that changed, with the
/// pixels inside it that did not change left transparent (they compress to almost nothing).
/// Output bytes depend only on the frames.
pub struct GifWriter<W: Write> {
    encoder: gif::Encoder<W>,
    /// Named in errors: the file, or `<stream>`.
    name: PathBuf,
    width: u16,
    height: u16,
    delay_cs: u16,
    /// Palette indices of the previous frame; empty before the first.
    previous: Vec<u8>,
    frames: usize,
}

impl GifWriter<BufWriter<File>> {
    /// Creates the file `path` (its directory must exist) for an animation of
    /// `width × height` pixels showing each frame for `delay_cs` hundredths of a second.
    ///
    /// # Errors
    /// The file cannot be created (the error names `path`), or the size is 0 or over 65535.
    pub fn create(
        path: &Path,
        width: u32,
        height: u32,
        delay_cs: u16,
    ) -> Result<Self, RenderError> {
        let file = File::create(path)
            .map_err(|source| RenderError::Io { path: path.to_path_buf(), source })?;
        Self::named(BufWriter::new(file), path.to_path_buf(), width, height, delay_cs)
    }
}

impl<W: Write> GifWriter<W> {
    /// An animation of `width × height` pixels written to `out`, showing each frame for
    /// `delay_cs` hundredths of a second.
    ///
    /// # Errors
    /// A size of 0 or over 65535, or a failed write of the header.
    pub fn new(out: W, width: u32, height: u32, delay_cs: u16) -> Result<Self, RenderError> {
        Self::named(out, PathBuf::from("<stream>"), width, height, delay_cs)
    }

    fn named(
        out: W,
        name: PathBuf,
        width: u32,
        height: u32,
        delay_cs: u16,
    ) -> Result<Self, RenderError> {
        let size_err = |why| RenderError::Size { path: name.clone(), width, height, why };
        if width == 0 || height == 0 {
            return Err(size_err("a GIF needs at least one pixel"));
        }
        let (Ok(w), Ok(h)) = (u16::try_from(width), u16::try_from(height)) else {
            return Err(size_err("a GIF side is at most 65535 pixels"));
        };
        let gif_err = |source| RenderError::Gif { path: name.clone(), source };
        let q = Quantiser::get();
        let mut encoder = gif::Encoder::new(out, w, h, &q.palette).map_err(gif_err)?;
        encoder.set_repeat(gif::Repeat::Infinite).map_err(gif_err)?;
        Ok(GifWriter {
            encoder,
            name,
            width: w,
            height: h,
            delay_cs,
            previous: Vec::new(),
            frames: 0,
        })
    }

    /// Frames written so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Appends a frame (cropped or padded to the animation's size).
    ///
    /// # Errors
    /// The encoder or the output failed.
    pub fn add_frame(&mut self, image: &Image) -> Result<(), RenderError> {
        let (w, h) = (u32::from(self.width), u32::from(self.height));
        let resized;
        let img = if image.width == w && image.height == h {
            image
        } else {
            resized = image.resized_canvas(w, h, [255, 255, 255, 255]);
            &resized
        };
        let q = Quantiser::get();
        let indices: Vec<u8> =
            img.rgba.chunks_exact(4).map(|p| q.index(p[0], p[1], p[2])).collect();
        let (left, top, fw, fh) = if self.previous.len() == indices.len() {
            changed_rect(&self.previous, &indices, w as usize).unwrap_or((0, 0, 1, 1))
        } else {
            (0, 0, w as usize, h as usize)
        };
        let first = self.previous.is_empty();
        let mut buffer = Vec::with_capacity(fw * fh);
        for r in top..top + fh {
            let row = r * w as usize + left..r * w as usize + left + fw;
            if first {
                buffer.extend_from_slice(&indices[row]);
            } else {
                let prev = &self.previous[row.clone()];
                buffer.extend(
                    indices[row]
                        .iter()
                        .zip(prev)
                        .map(|(&i, &p)| if i == p { TRANSPARENT } else { i }),
                );
            }
        }
        // Sizes are within the u16 animation size by construction.
        let frame = gif::Frame {
            delay: self.delay_cs,
            dispose: gif::DisposalMethod::Keep,
            transparent: (!first).then_some(TRANSPARENT),
            left: left as u16,
            top: top as u16,
            width: fw as u16,
            height: fh as u16,
            buffer: buffer.into(),
            ..gif::Frame::default()
        };
        self.encoder
            .write_frame(&frame)
            .map_err(|source| RenderError::Gif { path: self.name.clone(), source })?;
        self.previous = indices;
        self.frames += 1;
        Ok(())
    }

    /// Writes the trailer, flushes and returns the output.
    ///
    /// # Errors
    /// The encoder or the output failed.
    pub fn finish(self) -> Result<W, RenderError> {
        let name = self.name;
        let mut out = self
            .encoder
            .into_inner()
            .map_err(|source| RenderError::Gif { path: name.clone(), source })?;
        out.flush().map_err(|source| RenderError::Io { path: name, source })?;
        Ok(out)
    }
}

/// The bounding rectangle `(left, top, width, height)` of the pixels that differ between two
/// frames of the same size; `None` when they are equal.
fn changed_rect(a: &[u8], b: &[u8], width: usize) -> Option<(usize, usize, usize, usize)> {
    let rows = a.len() / width.max(1);
    let (mut x0, mut x1) = (usize::MAX, 0);
    let (mut y0, mut y1) = (usize::MAX, 0);
    for r in 0..rows {
        let (ra, rb) = (&a[r * width..(r + 1) * width], &b[r * width..(r + 1) * width]);
        if ra == rb {
            continue;
        }
        let first = ra.iter().zip(rb).position(|(p, q)| p != q).unwrap_or(0);
        let last =
            width - 1 - ra.iter().rev().zip(rb.iter().rev()).position(|(p, q)| p != q).unwrap_or(0);
        (x0, x1, y0, y1) = (x0.min(first), x1.max(last), y0.min(r), r);
    }
    (y0 != usize::MAX).then(|| (x0, y0, x1 - x0 + 1, y1 - y0 + 1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn palette_keeps_flat_colours_exact() {
        let q = Quantiser::get();
        assert_eq!(q.palette.len(), PALETTE_LEN * 3);
        for c in style::FLAT {
            let i = usize::from(q.index(c[0], c[1], c[2]));
            assert_eq!(&q.palette[i * 3..i * 3 + 3], &c, "{c:?}");
        }
        // Nothing quantises to the transparent slot.
        assert!(q.lut.iter().all(|&i| i != TRANSPARENT));
    }

    #[test]
    fn changed_rectangle() {
        let a = vec![0u8; 12];
        let mut b = a.clone();
        assert_eq!(changed_rect(&a, &b, 4), None);
        b[4 + 1] = 1;
        b[8 + 2] = 1;
        assert_eq!(changed_rect(&a, &b, 4), Some((1, 1, 2, 2)));
    }
}
