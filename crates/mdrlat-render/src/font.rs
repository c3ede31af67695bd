//! A tiny built-in bitmap font: 5×7 ASCII glyphs (with a one-row descender) in a 6×10 cell.
//!
//! No font files and no rasteriser: every glyph is a constant bitmap, so text pixels are the
//! same on every machine. The glyphs are drawn below as a sheet, eight per block, `#` for ink
//! and `.` for paper; a `const fn` turns the sheet into bit rows at compile time and rejects
//! any other character, so a typo in the sheet is a build error. Characters outside the
//! printable ASCII range are drawn as `?`.

/// Glyph width in font pixels.
pub const GLYPH_W: u32 = 5;
/// Glyph height in font pixels: 7 rows above the baseline and one descender row.
pub const GLYPH_H: u32 = 8;
/// Horizontal advance per character, font pixels (glyph plus one column of spacing).
pub const ADVANCE: u32 = 6;
/// Line height, font pixels (glyph plus two rows of spacing).
pub const LINE_H: u32 = 10;

const FIRST: u8 = b' ';
const COUNT: usize = 95;
const PER_BLOCK: usize = 8;

/// The glyphs of `' '..='~'`, eight per block of eight rows.
#[rustfmt::skip]
const SHEET: [&str; 96] = [
    // spc   !     "     #     $     %     &     '
    "..... ..#.. .#.#. .#.#. ..#.. ##... .##.. ..#..",
    "..... ..#.. .#.#. .#.#. .#### ##..# #..#. ..#..",
    "..... ..#.. ..... ##### #.#.. ...#. #.#.. .#...",
    "..... ..#.. ..... .#.#. .###. ..#.. .#... .....",
    "..... ..#.. ..... ##### ..#.# .#... #.#.# .....",
    "..... ..... ..... .#.#. ####. #..## #..#. .....",
    "..... ..#.. ..... .#.#. ..#.. ...## .##.# .....",
    "..... ..... ..... ..... ..... ..... ..... .....",
    // (     )     *     +     ,     -     .     /
    "...#. .#... ..... ..... ..... ..... ..... .....",
    "..#.. ..#.. ..#.. ..#.. ..... ..... ..... ....#",
    ".#... ...#. #.#.# ..#.. ..... ..... ..... ...#.",
    ".#... ...#. .###. ##### ..... ##### ..... ..#..",
    ".#... ...#. #.#.# ..#.. ..... ..... ..... .#...",
    "..#.. ..#.. ..#.. ..#.. .##.. ..... .##.. #....",
    "...#. .#... ..... ..... ..#.. ..... .##.. .....",
    "..... ..... ..... ..... .#... ..... ..... .....",
    // 0     1     2     3     4     5     6     7
    ".###. ..#.. .###. ##### ...#. ##### ..##. #####",
    "#...# .##.. #...# ...#. ..##. #.... .#... ....#",
    "#..## ..#.. ....# ..#.. .#.#. ####. #.... ...#.",
    "#.#.# ..#.. ...#. ...#. #..#. ....# ####. ..#..",
    "##..# ..#.. ..#.. ....# ##### ....# #...# .#...",
    "#...# ..#.. .#... #...# ...#. #...# #...# .#...",
    ".###. .###. ##### .###. ...#. .###. .###. .#...",
    "..... ..... ..... ..... ..... ..... ..... .....",
    // 8     9     :     ;     <     =     >     ?
    ".###. .###. ..... ..... ...#. ..... .#... .###.",
    "#...# #...# .##.. .##.. ..#.. ..... ..#.. #...#",
    "#...# #...# .##.. .##.. .#... ##### ...#. ....#",
    ".###. .#### ..... ..... #.... ..... ....# ...#.",
    "#...# ....# .##.. .##.. .#... ##### ...#. ..#..",
    "#...# ...#. .##.. ..#.. ..#.. ..... ..#.. .....",
    ".###. .##.. ..... .#... ...#. ..... .#... ..#..",
    "..... ..... ..... ..... ..... ..... ..... .....",
    // @     A     B     C     D     E     F     G
    ".###. .###. ####. .###. ###.. ##### ##### .###.",
    "#...# #...# #...# #...# #..#. #.... #.... #...#",
    "....# #...# #...# #.... #...# #.... #.... #....",
    ".##.# ##### ####. #.... #...# ####. ####. #.###",
    "#.#.# #...# #...# #.... #...# #.... #.... #...#",
    "#.#.# #...# #...# #...# #..#. #.... #.... #...#",
    ".###. #...# ####. .###. ###.. ##### #.... .####",
    "..... ..... ..... ..... ..... ..... ..... .....",
    // H     I     J     K     L     M     N     O
    "#...# .###. ..### #...# #.... #...# #...# .###.",
    "#...# ..#.. ...#. #..#. #.... ##.## #...# #...#",
    "#...# ..#.. ...#. #.#.. #.... #.#.# ##..# #...#",
    "##### ..#.. ...#. ##... #.... #.#.# #.#.# #...#",
    "#...# ..#.. ...#. #.#.. #.... #...# #..## #...#",
    "#...# ..#.. #..#. #..#. #.... #...# #...# #...#",
    "#...# .###. .##.. #...# ##### #...# #...# .###.",
    "..... ..... ..... ..... ..... ..... ..... .....",
    // P     Q     R     S     T     U     V     W
    "####. .###. ####. .#### ##### #...# #...# #...#",
    "#...# #...# #...# #.... ..#.. #...# #...# #...#",
    "#...# #...# #...# #.... ..#.. #...# #...# #...#",
    "####. #...# ####. .###. ..#.. #...# #...# #.#.#",
    "#.... #.#.# #.#.. ....# ..#.. #...# #...# #.#.#",
    "#.... #..#. #..#. ....# ..#.. #...# .#.#. #.#.#",
    "#.... .##.# #...# ####. ..#.. .###. ..#.. .#.#.",
    "..... ..... ..... ..... ..... ..... ..... .....",
    // X     Y     Z     [     \     ]     ^     _
    "#...# #...# ##### .###. ..... .###. ..#.. .....",
    "#...# #...# ....# .#... #.... ...#. .#.#. .....",
    ".#.#. .#.#. ...#. .#... .#... ...#. #...# .....",
    "..#.. ..#.. ..#.. .#... ..#.. ...#. ..... .....",
    ".#.#. ..#.. .#... .#... ...#. ...#. ..... .....",
    "#...# ..#.. #.... .#... ....# ...#. ..... .....",
    "#...# ..#.. ##### .###. ..... .###. ..... .....",
    "..... ..... ..... ..... ..... ..... ..... #####",
    // `     a     b     c     d     e     f     g
    ".#... ..... #.... ..... ....# ..... ..##. .....",
    "..#.. ..... #.... ..... ....# ..... .#..# .....",
    "...#. .###. #.##. .###. .##.# .###. .#... .####",
    "..... ....# ##..# #.... #..## #...# ###.. #...#",
    "..... .#### #...# #.... #...# ##### .#... #...#",
    "..... #...# #...# #...# #...# #.... .#... .####",
    "..... .#### ####. .###. .#### .###. .#... ....#",
    "..... ..... ..... ..... ..... ..... ..... .###.",
    // h     i     j     k     l     m     n     o
    "#.... ..#.. ...#. #.... .##.. ..... ..... .....",
    "#.... ..... ..... #.... ..#.. ..... ..... .....",
    "#.##. .##.. ..##. #..#. ..#.. ##.#. #.##. .###.",
    "##..# ..#.. ...#. #.#.. ..#.. #.#.# ##..# #...#",
    "#...# ..#.. ...#. ##... ..#.. #.#.# #...# #...#",
    "#...# ..#.. ...#. #.#.. ..#.. #...# #...# #...#",
    "#...# .###. #..#. #..#. .###. #...# #...# .###.",
    "..... ..... .##.. ..... ..... ..... ..... .....",
    // p     q     r     s     t     u     v     w
    "..... ..... ..... ..... .#... ..... ..... .....",
    "..... ..... ..... ..... .#... ..... ..... .....",
    "####. .#### #.##. .#### ###.. #...# #...# #...#",
    "#...# #...# ##..# #.... .#... #...# #...# #...#",
    "#...# #...# #.... .###. .#... #...# #...# #.#.#",
    "####. .#### #.... ....# .#..# #..## .#.#. #.#.#",
    "#.... ....# #.... ####. ..##. .##.# ..#.. .#.#.",
    "#.... ....# ..... ..... ..... ..... ..... .....",
    // x     y     z     {     |     }     ~     pad
    "..... ..... ..... ...#. ..#.. .#... ..... .....",
    "..... ..... ..... ..#.. ..#.. ..#.. ..... .....",
    "#...# #...# ##### ..#.. ..#.. ..#.. .#... .....",
    ".#.#. #...# ...#. .#... ..#.. ...#. #.#.# .....",
    "..#.. #...# ..#.. ..#.. ..#.. ..#.. ...#. .....",
    ".#.#. .#### .#... ..#.. ..#.. ..#.. ..... .....",
    "#...# ....# ##### ...#. ..#.. .#... ..... .....",
    "..... .###. ..... ..... ..... ..... ..... .....",
];

const fn parse(sheet: &[&str; 96]) -> [[u8; GLYPH_H as usize]; COUNT] {
    let mut out = [[0u8; GLYPH_H as usize]; COUNT];
    let mut g = 0;
    while g < COUNT {
        let (block, col) = (g / PER_BLOCK, g % PER_BLOCK);
        let mut r = 0;
        while r < GLYPH_H as usize {
            let row = sheet[block * GLYPH_H as usize + r].as_bytes();
            assert!(row.len() == PER_BLOCK * 6 - 1, "font sheet: every row has 8 cells of 5");
            let mut bits = 0u8;
            let mut x = 0;
            while x < GLYPH_W as usize {
                match row[col * 6 + x] {
                    b'#' => bits |= 1 << (GLYPH_W as usize - 1 - x),
                    b'.' => {}
                    _ => panic!("font sheet: only '#' and '.' are allowed in a cell"),
                }
                x += 1;
            }
            if col + 1 < PER_BLOCK {
                assert!(row[col * 6 + 5] == b' ', "font sheet: cells are separated by a space");
            }
            out[g][r] = bits;
            r += 1;
        }
        g += 1;
    }
    out
}

/// Bit rows of every glyph, top row first; bit 4 is the leftmost column.
static GLYPHS: [[u8; GLYPH_H as usize]; COUNT] = parse(&SHEET);

/// The bit rows of `c` (top row first, bit 4 = leftmost column); `?` for characters outside
/// the printable ASCII range.
pub fn glyph(c: char) -> &'static [u8; GLYPH_H as usize] {
    let i = if c.is_ascii() && (c as u8) >= FIRST && (c as u8) < FIRST + COUNT as u8 {
        (c as u8 - FIRST) as usize
    } else {
        (b'?' - FIRST) as usize
    };
    &GLYPHS[i]
}

/// Width in pixels of the longest line of `text` at integer `scale` (no trailing spacing).
pub fn text_width(text: &str, scale: u32) -> u32 {
    text.split('\n')
        .map(|l| l.chars().count() as u32)
        .max()
        .map_or(0, |n| if n == 0 { 0 } else { (n * ADVANCE - 1) * scale })
}

/// Height in pixels of `text` (one [`LINE_H`] per line, the last one without spacing).
pub fn text_height(text: &str, scale: u32) -> u32 {
    let lines = text.split('\n').count() as u32;
    ((lines - 1) * LINE_H + GLYPH_H) * scale
}

/// Splits `text` into lines of at most `max_chars` characters, breaking at spaces where it
/// can (and inside a word only when the word alone is too long). Explicit `\n` are kept.
pub fn wrap(text: &str, max_chars: usize) -> Vec<String> {
    let max = max_chars.max(1);
    let mut out = Vec::new();
    for para in text.split('\n') {
        let mut line = String::new();
        // Spaces seen since the last word; kept inside a line (captions use double spaces
        // as separators), dropped at a break.
        let mut gap = 0usize;
        for (k, word) in para.split(' ').enumerate() {
            gap += usize::from(k > 0);
            if word.is_empty() {
                continue;
            }
            let (lw, ww) = (line.chars().count(), word.chars().count());
            if lw > 0 && lw + gap + ww > max {
                out.push(std::mem::take(&mut line));
            } else if lw > 0 {
                line.extend(std::iter::repeat_n(' ', gap));
            }
            gap = 0;
            let mut rest: Vec<char> = word.chars().collect();
            while rest.len() > max {
                out.push(rest.drain(..max).collect());
            }
            line.extend(rest);
        }
        out.push(line);
    }
    out
}

/// Draws `text` into an RGBA8 buffer of `width × height` (opaque destination assumed, so
/// straight and premultiplied alpha agree) with its top-left corner at `(x, y)`, each font
/// pixel a `scale × scale` block, blending `rgba` by its alpha. `\n` starts a new line.
/// Pixels outside the buffer are skipped.
pub(crate) fn draw_text_rgba(
    buf: &mut [u8],
    width: u32,
    height: u32,
    (x, y): (i32, i32),
    text: &str,
    scale: u32,
    rgba: [u8; 4],
) {
    let s = scale.max(1) as i32;
    let a = u32::from(rgba[3]);
    for (li, line) in text.split('\n').enumerate() {
        let y0 = y + li as i32 * LINE_H as i32 * s;
        for (ci, c) in line.chars().enumerate() {
            let x0 = x + ci as i32 * ADVANCE as i32 * s;
            for (r, bits) in glyph(c).iter().enumerate() {
                for col in 0..GLYPH_W as i32 {
                    if bits & (1 << (GLYPH_W as i32 - 1 - col)) == 0 {
                        continue;
                    }
                    for dy in 0..s {
                        let py = y0 + r as i32 * s + dy;
                        if py < 0 || py >= height as i32 {
                            continue;
                        }
                        for dx in 0..s {
                            let px = x0 + col * s + dx;
                            if px < 0 || px >= width as i32 {
                                continue;
                            }
                            let i = (py as usize * width as usize + px as usize) * 4;
                            if let Some(p) = buf.get_mut(i..i + 4) {
                                for k in 0..3 {
                                    let (src, dst) = (u32::from(rgba[k]), u32::from(p[k]));
                                    p[k] = ((src * a + dst * (255 - a) + 127) / 255) as u8;
                                }
                                p[3] = 255;
                            }
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sheet_has_the_expected_shapes() {
        // 'I' is a centred bar with serifs, '_' sits on the descender row, ' ' is empty.
        assert_eq!(glyph('I'), &[0b01110, 4, 4, 4, 4, 4, 0b01110, 0]);
        assert_eq!(glyph('_')[7], 0b11111);
        assert!(glyph(' ').iter().all(|&r| r == 0));
        // Every printable character except space has ink; non-ASCII falls back to '?'.
        for c in '!'..='~' {
            assert!(glyph(c).iter().any(|&r| r != 0), "{c:?} is blank");
        }
        assert_eq!(glyph('é'), glyph('?'));
    }

    #[test]
    fn measures_and_wraps() {
        assert_eq!(text_width("ab", 1), 11);
        assert_eq!(text_width("ab\nabc", 2), 34);
        assert_eq!(text_width("", 3), 0);
        assert_eq!(text_height("a\nb", 1), 18);
        assert_eq!(wrap("step 42  v 0.50", 8), vec!["step 42", "v 0.50"]);
        assert_eq!(wrap("a  b", 9), vec!["a  b"]);
        assert_eq!(wrap("abcdefghij", 4), vec!["abcd", "efgh", "ij"]);
        assert_eq!(wrap("a\nb", 10), vec!["a", "b"]);
    }

    #[test]
    fn draws_opaque_ink_and_clips() {
        let (w, h) = (8u32, 10u32);
        let mut buf = vec![255u8; (w * h * 4) as usize];
        draw_text_rgba(&mut buf, w, h, (-2, 1), "I", 1, [0, 0, 0, 255]);
        // 'I' top serif spans columns 1..=3 of the glyph, i.e. x = -1..=1; x = 0, y = 1 inked.
        assert_eq!(&buf[w as usize * 4..w as usize * 4 + 4], &[0, 0, 0, 255]);
        // Column 2 of the buffer is past the serif: still paper.
        assert_eq!(buf[(w as usize + 2) * 4], 255);
    }
}
