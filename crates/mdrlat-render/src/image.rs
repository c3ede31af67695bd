//! An RGBA picture, PNG output and side-by-side composition.

use crate::error::RenderError;
use crate::font;
use std::io::Write;
use std::path::{Path, PathBuf};

/// An 8-bit RGBA picture, row-major, top row first, straight (not premultiplied) alpha.
///
/// Pictures made by this crate are fully opaque.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Image {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// `width * height * 4` bytes: R, G, B, A per pixel.
    pub rgba: Vec<u8>,
}

impl Image {
    /// A picture filled with one colour.
    pub fn new(width: u32, height: u32, fill: [u8; 4]) -> Image {
        let rgba = fill.repeat(width as usize * height as usize);
        Image { width, height, rgba }
    }

    /// Takes a fully opaque tiny-skia pixmap (premultiplied and straight alpha agree there,
    /// so its bytes are used as they are).
    pub(crate) fn from_opaque_pixmap(pixmap: tiny_skia::Pixmap) -> Image {
        let (width, height) = (pixmap.width(), pixmap.height());
        debug_assert!(pixmap.pixels().iter().all(|p| p.alpha() == 255), "pixmap not opaque");
        Image { width, height, rgba: pixmap.take() }
    }

    /// The pixel at column `x`, row `y` (row 0 at the top); `None` outside the picture.
    pub fn pixel(&self, x: u32, y: u32) -> Option<[u8; 4]> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let i = (y as usize * self.width as usize + x as usize) * 4;
        let p = self.rgba.get(i..i + 4)?;
        Some([p[0], p[1], p[2], p[3]])
    }

    /// Draws `text` with the built-in [`font`](crate::font), top-left corner at `(x, y)`,
    /// each font pixel a `scale × scale` block, blended by the alpha of `rgba`.
    pub fn draw_text(&mut self, x: i32, y: i32, text: &str, scale: u32, rgba: [u8; 4]) {
        font::draw_text_rgba(&mut self.rgba, self.width, self.height, (x, y), text, scale, rgba);
    }

    /// This picture on a `width × height` canvas of colour `fill`, top-left aligned: padded
    /// where the canvas is larger, cropped where it is smaller.
    pub fn resized_canvas(&self, width: u32, height: u32, fill: [u8; 4]) -> Image {
        if width == self.width && height == self.height {
            return self.clone();
        }
        let mut out = Image::new(width, height, fill);
        blit(&mut out, self, 0, 0);
        out
    }

    /// Encodes the picture as an RGBA PNG.
    ///
    /// # Errors
    /// An empty picture, or an encoder failure.
    pub fn encode_png(&self) -> Result<Vec<u8>, RenderError> {
        let mut out = Vec::new();
        self.write_png(&mut out, Path::new("<memory>"))?;
        Ok(out)
    }

    /// Writes the picture to `path` as an RGBA PNG. The directory must exist.
    ///
    /// # Errors
    /// The file cannot be created or written (the error names `path`), or an empty picture.
    pub fn save_png(&self, path: &Path) -> Result<(), RenderError> {
        let io = |source| RenderError::Io { path: path.to_path_buf(), source };
        let file = std::fs::File::create(path).map_err(io)?;
        let mut w = std::io::BufWriter::new(file);
        self.write_png(&mut w, path)?;
        w.flush().map_err(io)
    }

    fn write_png<W: Write>(&self, w: W, path: &Path) -> Result<(), RenderError> {
        let name = || PathBuf::from(path);
        if self.width == 0 || self.height == 0 {
            return Err(RenderError::Size {
                path: name(),
                width: self.width,
                height: self.height,
                why: "a PNG needs at least one pixel",
            });
        }
        let png_err = |source| RenderError::Png { path: name(), source };
        let mut enc = png::Encoder::new(w, self.width, self.height);
        enc.set_color(png::ColorType::Rgba);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Fast);
        let mut writer = enc.write_header().map_err(png_err)?;
        writer.write_image_data(&self.rgba).map_err(png_err)?;
        writer.finish().map_err(png_err)
    }
}

impl Image {
    /// The `width × height` region with its top-left corner at `(x, y)`, clipped to the
    /// picture (a region outside it gives a 0×0 picture).
    pub fn crop(&self, x: u32, y: u32, width: u32, height: u32) -> Image {
        let w = width.min(self.width.saturating_sub(x));
        let h = height.min(self.height.saturating_sub(y));
        if w == 0 || h == 0 {
            return Image::new(0, 0, PAPER);
        }
        let mut out = Image::new(w, h, PAPER);
        for r in 0..h as usize {
            let s = ((y as usize + r) * self.width as usize + x as usize) * 4;
            let d = r * w as usize * 4;
            out.rgba[d..d + w as usize * 4].copy_from_slice(&self.rgba[s..s + w as usize * 4]);
        }
        out
    }
}

/// Copies `src` into `dst` with its top-left corner at `(x, y)`, clipping at the borders.
fn blit(dst: &mut Image, src: &Image, x: u32, y: u32) {
    if x >= dst.width || y >= dst.height {
        return;
    }
    let w = src.width.min(dst.width - x) as usize;
    let rows = src.height.min(dst.height - y) as usize;
    for r in 0..rows {
        let s = r * src.width as usize * 4;
        let d = ((y as usize + r) * dst.width as usize + x as usize) * 4;
        dst.rgba[d..d + w * 4].copy_from_slice(&src.rgba[s..s + w * 4]);
    }
}

/// The paper colour of gaps and padding.
const PAPER: [u8; 4] = [255, 255, 255, 255];

/// Puts pictures next to each other, left to right, top-aligned, `gap` pixels apart; shorter
/// ones are padded with white below. An empty list gives a 0×0 picture.
pub fn side_by_side(images: &[&Image], gap: u32) -> Image {
    let height = images.iter().map(|i| i.height).max().unwrap_or(0);
    let width =
        images.iter().map(|i| i.width).sum::<u32>() + gap * (images.len().saturating_sub(1) as u32);
    let mut out = Image::new(width, height, PAPER);
    let mut x = 0;
    for img in images {
        blit(&mut out, img, x, 0);
        x += img.width + gap;
    }
    out
}

/// `image` with `title` above it (built-in font at `scale`, dark grey on white; lines split
/// at `\n`).
pub fn titled(image: &Image, title: &str, scale: u32) -> Image {
    let scale = scale.max(1);
    let (w, h) = (font::text_width(title, scale), font::text_height(title, scale));
    let pad = 4 * scale;
    let mut head = Image::new(image.width.max(w), h + 2 * pad, PAPER);
    head.draw_text(0, pad as i32, title, scale, [40, 40, 40, 255]);
    stacked(&[&head, image], 0)
}

/// Puts pictures below each other, top to bottom, left-aligned, `gap` pixels apart;
/// narrower ones are padded with white on the right. An empty list gives a 0×0 picture.
pub fn stacked(images: &[&Image], gap: u32) -> Image {
    let width = images.iter().map(|i| i.width).max().unwrap_or(0);
    let height = images.iter().map(|i| i.height).sum::<u32>()
        + gap * (images.len().saturating_sub(1) as u32);
    let mut out = Image::new(width, height, PAPER);
    let mut y = 0;
    for img in images {
        blit(&mut out, img, 0, y);
        y += img.height + gap;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn composes_pads_and_crops() {
        let a = Image::new(2, 3, [255, 0, 0, 255]);
        let b = Image::new(1, 1, [0, 0, 255, 255]);
        let c = side_by_side(&[&a, &b], 2);
        assert_eq!((c.width, c.height), (5, 3));
        assert_eq!(c.pixel(1, 2), Some([255, 0, 0, 255]));
        assert_eq!(c.pixel(2, 0), Some(PAPER));
        assert_eq!(c.pixel(4, 0), Some([0, 0, 255, 255]));
        assert_eq!(c.pixel(4, 1), Some(PAPER));
        assert_eq!(c.pixel(5, 0), None);
        let e = side_by_side(&[], 3);
        assert_eq!((e.width, e.height, e.rgba.len()), (0, 0, 0));
        let v = stacked(&[&a, &b], 1);
        assert_eq!((v.width, v.height), (2, 5));
        assert_eq!(v.pixel(0, 4), Some([0, 0, 255, 255]));
        assert_eq!(v.pixel(1, 4), Some(PAPER));
        assert_eq!(v.pixel(0, 3), Some(PAPER));
        let c = v.crop(1, 2, 5, 5);
        assert_eq!((c.width, c.height), (1, 3));
        assert_eq!(c.pixel(0, 0), Some([255, 0, 0, 255]));
        assert_eq!(v.crop(9, 0, 2, 2).rgba.len(), 0);
        let r = a.resized_canvas(1, 4, PAPER);
        assert_eq!(r.pixel(0, 2), Some([255, 0, 0, 255]));
        assert_eq!(r.pixel(0, 3), Some(PAPER));
    }

    #[test]
    fn png_round_trip_and_errors_name_the_path() {
        let mut img = Image::new(7, 5, [10, 20, 30, 255]);
        img.draw_text(0, 0, "A", 1, [255, 255, 255, 255]);
        let bytes = img.encode_png().expect("encodes");
        assert_eq!(bytes, img.encode_png().expect("encodes"), "deterministic");
        let dir = std::env::temp_dir().join(format!("mdrlat-render-png-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("a.png");
        img.save_png(&path).expect("saves");
        let dec =
            png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&path).expect("exists")));
        let mut reader = dec.read_info().expect("png header");
        let mut buf = vec![0; reader.output_buffer_size().expect("size")];
        let info = reader.next_frame(&mut buf).expect("decodes");
        assert_eq!((info.width, info.height), (7, 5));
        assert_eq!(&buf[..info.buffer_size()], &img.rgba[..]);
        std::fs::remove_dir_all(&dir).expect("clean up");

        let missing = dir.join("no-such-dir").join("b.png");
        let e = img.save_png(&missing).expect_err("no directory");
        assert!(matches!(e, RenderError::Io { .. }), "{e:?}");
        assert!(e.to_string().contains(&missing.display().to_string()), "{e}");
        let e = Image::new(0, 3, PAPER).encode_png().expect_err("empty");
        assert!(e.to_string().contains("<memory>") && e.to_string().contains("0x3"), "{e}");
    }
}
