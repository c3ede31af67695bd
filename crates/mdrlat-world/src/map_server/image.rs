//! Map images, PGM (P2, P5) and PNG, decoded straight to one classified cell per pixel.

use super::grid::{Cell, Grid};
use crate::WorldError;
use std::io::Cursor;
use std::path::Path;

/// Largest accepted width or height, pixels.
pub(super) const MAX_SIDE: u32 = 16384;

const PNG_SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";

/// One pixel, as ROS map_server sees it; every channel ranges over `0..=max`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Pixel {
    /// Red + green + blue; a grey value counts three times (ROS reads grey as R = G = B).
    pub rgb_sum: u32,
    /// The alpha channel (`max` is opaque), if the image has one.
    pub alpha: Option<u32>,
    /// The largest channel value: the PGM maxval, 255 or 65535.
    pub max: u32,
}

/// Decodes a PGM or PNG (told apart by their first bytes, not the file name), classifying
/// each pixel with `classify`. `path` names the image in errors.
///
/// # Errors
/// [`WorldError::Image`]: not a PGM or PNG, malformed or truncated, or a side of zero or
/// more than [`MAX_SIDE`] pixels.
pub(super) fn decode(
    path: &Path,
    bytes: &[u8],
    classify: impl FnMut(Pixel) -> Cell,
) -> Result<Grid, WorldError> {
    let result = if bytes.starts_with(PNG_SIGNATURE) {
        png(bytes, classify)
    } else if bytes.starts_with(b"P5") || bytes.starts_with(b"P2") {
        pgm(bytes, classify)
    } else {
        let head: String =
            bytes.iter().take(8).flat_map(|b| b.escape_ascii()).map(char::from).collect();
        Err(format!("not a PGM (P2 or P5) or PNG image (it starts with \"{head}\")"))
    };
    result.map_err(|problem| WorldError::Image { path: path.to_path_buf(), problem })
}

/// Most pixels of a map (the importer's masks and distance transform take ~40 bytes each).
const MAX_PIXELS: u64 = 1 << 26;

fn check_size(width: u32, height: u32) -> Result<(usize, usize), String> {
    if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
        return Err(format!(
            "image size {width}x{height}: each side must be 1 to {MAX_SIDE} pixels"
        ));
    }
    if u64::from(width) * u64::from(height) > MAX_PIXELS {
        return Err(format!(
            "image size {width}x{height}: more than {MAX_PIXELS} pixels (e.g. 1 km x 1 km at 5 cm); \
             crop or downsample the map"
        ));
    }
    Ok((width as usize, height as usize))
}

/// A PGM: `P5` (binary, 1 byte per sample, or 2 big-endian bytes when maxval > 255) or `P2`
/// (ASCII). `#` comments may precede any header field.
fn pgm(bytes: &[u8], mut classify: impl FnMut(Pixel) -> Cell) -> Result<Grid, String> {
    let plain = bytes[1] == b'2';
    let mut s = Scanner { bytes, pos: 2 };
    if !s.at_separator() {
        return Err("not a PGM: the magic number P2 or P5 must be followed by whitespace".into());
    }
    let width = s.number("width")?;
    let height = s.number("height")?;
    let (w, h) = check_size(width, height)?;
    let max = s.number("maxval")?;
    if !(1..=65535).contains(&max) {
        return Err(format!("PGM maxval must be 1 to 65535, got {max}"));
    }
    let n = w * h;
    // Each pixel takes at least one byte of the file: no huge allocation for a lying header.
    let mut cells = Vec::with_capacity(n.min(bytes.len()));
    let mut push = |i: usize, v: u32| {
        if v > max {
            return Err(format!(
                "pixel {i} (row {}, column {}) is {v}, above maxval {max}",
                i / w,
                i % w
            ));
        }
        cells.push(classify(Pixel { rgb_sum: 3 * v, alpha: None, max }));
        Ok(())
    };
    if plain {
        for i in 0..n {
            let v = s
                .number("pixel")
                .map_err(|e| format!("pixel data: {e} (pixel {i} of {n}, {w}x{h})"))?;
            push(i, v)?;
        }
    } else {
        // Exactly one whitespace byte separates maxval from the raster.
        if !s.bytes.get(s.pos).is_some_and(u8::is_ascii_whitespace) {
            return Err("truncated PGM header: expected one whitespace byte after maxval".into());
        }
        let data = &bytes[s.pos + 1..];
        let width_bytes = if max > 255 { 2 } else { 1 };
        if data.len() < n * width_bytes {
            return Err(format!(
                "truncated PGM: {w}x{h} pixels need {} bytes of data, the file has {}",
                n * width_bytes,
                data.len()
            ));
        }
        for (i, sample) in data.chunks_exact(width_bytes).take(n).enumerate() {
            let v = sample.iter().fold(0u32, |acc, &b| (acc << 8) | u32::from(b));
            push(i, v)?;
        }
    }
    Ok(Grid { width: w, height: h, cells })
}

/// Reads the whitespace-separated decimal numbers of a PGM, skipping `#` comments.
struct Scanner<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl Scanner<'_> {
    fn at_separator(&self) -> bool {
        self.bytes.get(self.pos).is_none_or(|&b| b.is_ascii_whitespace() || b == b'#')
    }

    fn skip_space_and_comments(&mut self) {
        while let Some(&b) = self.bytes.get(self.pos) {
            if b == b'#' {
                while self.bytes.get(self.pos).is_some_and(|&b| b != b'\n' && b != b'\r') {
                    self.pos += 1;
                }
            } else if b.is_ascii_whitespace() {
                self.pos += 1;
            } else {
                return;
            }
        }
    }

    fn number(&mut self, what: &str) -> Result<u32, String> {
        self.skip_space_and_comments();
        let start = self.pos;
        let mut value = 0u32;
        while let Some(&b) = self.bytes.get(self.pos).filter(|b| b.is_ascii_digit()) {
            value = value
                .checked_mul(10)
                .and_then(|v| v.checked_add(u32::from(b - b'0')))
                .ok_or_else(|| format!("PGM {what} is too large"))?;
            self.pos += 1;
        }
        if self.pos == start {
            return Err(match self.bytes.get(self.pos) {
                None => format!("truncated PGM: end of file where the {what} should be"),
                Some(b) => format!("bad PGM {what}: unexpected byte '{}'", b.escape_ascii()),
            });
        }
        if !self.at_separator() {
            return Err(format!(
                "bad PGM {what}: digits followed by '{}'",
                self.bytes[self.pos].escape_ascii()
            ));
        }
        Ok(value)
    }
}

/// A PNG of any colour type and bit depth. Palettes, transparency chunks and 1–4 bit grey are
/// expanded to 8-bit grey, grey+alpha, RGB or RGBA by the `png` crate; 16 bit stays 16 bit.
fn png(bytes: &[u8], mut classify: impl FnMut(Pixel) -> Cell) -> Result<Grid, String> {
    let bad = |e: png::DecodingError| format!("not a valid PNG: {e}");
    let mut decoder = png::Decoder::new(Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::EXPAND);
    let header = decoder.read_header_info().map_err(bad)?;
    let (w, h) = check_size(header.width, header.height)?;
    let mut reader = decoder.read_info().map_err(bad)?;
    let size = reader.output_buffer_size().ok_or("PNG too large to decode")?;
    let mut buf = vec![0u8; size];
    let out = reader.next_frame(&mut buf).map_err(bad)?;
    let (channels, has_alpha) = match out.color_type {
        png::ColorType::Grayscale => (1, false),
        png::ColorType::GrayscaleAlpha => (2, true),
        png::ColorType::Rgb => (3, false),
        png::ColorType::Rgba => (4, true),
        png::ColorType::Indexed => return Err("PNG palette was not expanded".into()),
    };
    let (sample_bytes, max) = match out.bit_depth {
        png::BitDepth::Eight => (1, 255),
        png::BitDepth::Sixteen => (2, 65535),
        d => return Err(format!("PNG bit depth {d:?} was not expanded")),
    };
    let pixel_bytes = channels * sample_bytes;
    let mut cells = Vec::with_capacity(w * h);
    for row in buf.chunks_exact(out.line_size).take(h) {
        for px in row[..w * pixel_bytes].chunks_exact(pixel_bytes) {
            let sample = |k: usize| {
                px[k * sample_bytes..][..sample_bytes]
                    .iter()
                    .fold(0u32, |acc, &b| (acc << 8) | u32::from(b))
            };
            let rgb_sum =
                if channels <= 2 { 3 * sample(0) } else { sample(0) + sample(1) + sample(2) };
            let alpha = has_alpha.then(|| sample(channels - 1));
            cells.push(classify(Pixel { rgb_sum, alpha, max }));
        }
    }
    if cells.len() != w * h {
        return Err(format!("PNG decoded to {} of {w}x{h} pixels", cells.len()));
    }
    Ok(Grid { width: w, height: h, cells })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grey(bytes: &[u8]) -> Result<(usize, usize, Vec<u32>), String> {
        let mut values = Vec::new();
        let g = decode(Path::new("m.pgm"), bytes, |p| {
            assert_eq!((p.rgb_sum % 3, p.alpha), (0, None));
            values.push(p.rgb_sum / 3 * 65535 / p.max);
            Cell::Free
        })
        .map_err(|e| e.to_string())?;
        Ok((g.width, g.height, values))
    }

    #[test]
    fn pgm_variants() {
        let p2 = grey(b"P2\n# c1\n3 # c2\n2\n#c3\n255\n0 1 2\n# mid\n3 4 255\n").expect("P2");
        assert_eq!(p2, (3, 2, vec![0, 257, 514, 771, 1028, 65535]));
        let p5 = grey(b"P5 #x\n3 2 255\n\0\x01\x02\x03\x04\xff").expect("P5");
        assert_eq!(p5, p2);
        let p5_16 = grey(b"P5\n2 1\n65535\n\x01\x00\xff\xff").expect("P5 16 bit");
        assert_eq!(p5_16, (2, 1, vec![256, 65535]));
        let low = grey(b"P2 1 2 15 0 15").expect("maxval 15");
        assert_eq!(low, (1, 2, vec![0, 65535]));
    }

    #[test]
    fn bad_pgm_is_a_clear_error() {
        let cases: [(&[u8], &str); 10] = [
            (
                b"P5\n3 2\n255\n\0\x01",
                "truncated PGM: 3x2 pixels need 6 bytes of data, the file has 2",
            ),
            (b"P5\n3 2\n255", "expected one whitespace byte after maxval"),
            (b"P5\n3", "end of file where the height should be"),
            (b"P2\n2 1\n255\n0", "end of file where the pixel should be"),
            (b"P2\n2 1\n7\n0 8", "pixel 1 (row 0, column 1) is 8, above maxval 7"),
            (b"P5\n0 2\n255\n", "image size 0x2"),
            (b"P5\n16385 2\n255\n", "1 to 16384 pixels"),
            (b"P5\n2 2\n0\n", "maxval must be 1 to 65535, got 0"),
            (b"P5\n2x 2\n255\n", "bad PGM width"),
            (b"P5\n99999999999 2\n255\n", "width is too large"),
        ];
        for (bytes, needle) in cases {
            let e = grey(bytes).expect_err("should fail");
            assert!(e.starts_with("m.pgm: ") && e.contains(needle), "'{e}' lacks '{needle}'");
        }
        let e = grey(b"hello: world\n").expect_err("text");
        assert!(e.contains("not a PGM (P2 or P5) or PNG image") && e.contains("hello"), "{e}");
        let e = grey(b"P6\n1 1\n255\n\0\0\0").expect_err("ppm");
        assert!(e.contains("not a PGM"), "{e}");
    }
}
