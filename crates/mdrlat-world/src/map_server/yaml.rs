//! The map_server YAML: flat `key: value` lines, read by a small strict parser.

use crate::WorldError;
use std::path::{Path, PathBuf};

/// How pixel values become occupancy (the YAML `mode` key), with ROS map_server's semantics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MapMode {
    /// Thresholds give occupied, free or unknown; an alpha channel is averaged in with the
    /// colour channels (as ROS does "to preserve existing behavior").
    #[default]
    Trinary,
    /// As trinary, but a pixel that is not fully opaque is unknown. ROS publishes the cells
    /// between the thresholds as a 0–100 probability; mdrlat has no partial walls, so they
    /// are unknown here.
    Scale,
    /// The pixel value is the occupancy in percent (0–100; above 100 is unknown), as Nav2:
    /// `negate` and alpha are ignored (ROS 1 applied `negate`). ROS publishes the value as
    /// is; mdrlat applies the thresholds to `value / 100`.
    Raw,
}

/// The contents of a map_server YAML, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct MapMeta {
    /// The image: the `image` key, joined to the YAML's folder when relative.
    pub image: PathBuf,
    /// Metres per pixel, > 0.
    pub resolution: f64,
    /// World pose `[x, y, yaw]` (metres, radians) of the lower-left corner of the image; the
    /// map is rotated by `yaw` about that point.
    pub origin: [f64; 3],
    /// True: white is occupied and black is free.
    pub negate: bool,
    /// Occupancy probability above which a cell is occupied (default 0.65).
    pub occupied_thresh: f64,
    /// Occupancy probability below which a cell is free (default 0.25, as Nav2's map_saver).
    pub free_thresh: f64,
    /// How pixel values are read (default trinary).
    pub mode: MapMode,
}

const KEYS: [&str; 7] =
    ["image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh", "mode"];

impl MapMeta {
    /// Parses a map_server YAML. `source_name` names the file in errors; a relative `image`
    /// is taken relative to `base_dir` (the YAML's folder).
    ///
    /// Accepted: blank lines, `#` comments (whole-line, or after a space), an optional `---`
    /// first line, and single- or double-quoted strings. Each of the keys `image`,
    /// `resolution`, `origin` (`[x, y, yaw]`), `negate` (0, 1, true or false),
    /// `occupied_thresh`, `free_thresh` and `mode` (trinary, scale or raw) at most once; the
    /// first three are required.
    ///
    /// # Errors
    /// [`WorldError::Parse`] for a malformed line, an unknown, repeated or missing key;
    /// [`WorldError::Invalid`] for a bad value. Each names the file, the line or key and the
    /// problem.
    pub fn parse(source_name: &str, text: &str, base_dir: &Path) -> Result<MapMeta, WorldError> {
        let parse_err =
            |message: String| WorldError::Parse { source_name: source_name.to_string(), message };
        let mut values: [Option<(usize, &str)>; KEYS.len()] = [None; KEYS.len()];
        let mut any_line = false;
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        for (i, line) in text.lines().enumerate() {
            let n = i + 1;
            let body = line.trim_end();
            if body.trim_start().is_empty() || body.trim_start().starts_with('#') {
                continue;
            }
            if body == "---" && !any_line {
                any_line = true;
                continue;
            }
            any_line = true;
            if body.starts_with(char::is_whitespace) {
                return Err(parse_err(format!(
                    "line {n}: unexpected indentation (only flat `key: value` lines are supported)"
                )));
            }
            let Some((key, value)) = body.split_once(':') else {
                return Err(parse_err(format!("line {n}: expected `key: value`, got '{body}'")));
            };
            let key = key.trim_end();
            let Some(k) = KEYS.iter().position(|&known| known == key) else {
                return Err(parse_err(format!(
                    "line {n}: unknown key '{key}' (expected one of: {})",
                    KEYS.join(", ")
                )));
            };
            if let Some((first, _)) = values[k] {
                return Err(parse_err(format!(
                    "line {n}: duplicate key '{key}' (first on line {first})"
                )));
            }
            values[k] = Some((n, value.trim()));
        }
        let field = |k: usize| values[k].map(|(n, v)| (format!("{} (line {n})", KEYS[k]), v));
        let required = |k: usize| {
            field(k).ok_or_else(|| parse_err(format!("missing required key '{}'", KEYS[k])))
        };
        let invalid = |f: &str, problem: String| WorldError::invalid(source_name, f, problem);

        let (f, v) = required(0)?;
        let image = string(v).map_err(|p| invalid(&f, p))?;
        if image.is_empty() {
            return Err(invalid(&f, "is empty".into()));
        }
        let (f, v) = required(1)?;
        let resolution = number(v).map_err(|p| invalid(&f, p))?;
        // Also positive as f32 (world coordinates are f32).
        if !(resolution > 0.0 && (resolution as f32) > 0.0 && (resolution as f32).is_finite()) {
            return Err(invalid(&f, format!("must be a positive number of metres, got {v}")));
        }
        let (f, v) = required(2)?;
        let origin = triple(v).map_err(|p| invalid(&f, p))?;
        let negate = match field(3) {
            None => false,
            Some((f, v)) => boolean(v).map_err(|p| invalid(&f, p))?,
        };
        let thresh = |k: usize, default: f64| match field(k) {
            None => Ok(default),
            Some((f, v)) => number(v).map_err(|p| invalid(&f, p)),
        };
        let occupied_thresh = thresh(4, 0.65)?;
        let free_thresh = thresh(5, 0.25)?;
        if !(0.0 <= free_thresh && free_thresh < occupied_thresh && occupied_thresh <= 1.0) {
            return Err(invalid(
                "free_thresh, occupied_thresh",
                format!(
                    "need 0 <= free_thresh < occupied_thresh <= 1, got free_thresh {free_thresh}, occupied_thresh {occupied_thresh}"
                ),
            ));
        }
        let mode = match field(6) {
            None => MapMode::Trinary,
            Some((f, v)) => match string(v).map_err(|p| invalid(&f, p))?.as_str() {
                "trinary" => MapMode::Trinary,
                "scale" => MapMode::Scale,
                "raw" => MapMode::Raw,
                other => {
                    return Err(invalid(
                        &f,
                        format!("unknown mode '{other}' (expected trinary, scale or raw)"),
                    ));
                }
            },
        };
        Ok(MapMeta {
            image: base_dir.join(image),
            resolution,
            origin,
            negate,
            occupied_thresh,
            free_thresh,
            mode,
        })
    }
}

/// Removes a trailing ` # comment` from an unquoted value.
fn uncomment(v: &str) -> &str {
    let cut = v
        .char_indices()
        .find(|&(i, c)| c == '#' && (i == 0 || v[..i].ends_with(char::is_whitespace)))
        .map_or(v.len(), |(i, _)| i);
    v[..cut].trim_end()
}

/// A plain, single-quoted (`''` is a quote) or double-quoted (no escapes) string.
fn string(v: &str) -> Result<String, String> {
    let Some(q) = v.chars().next().filter(|&c| c == '"' || c == '\'') else {
        return Ok(uncomment(v).to_string());
    };
    let mut out = String::new();
    let mut chars = v[1..].char_indices();
    while let Some((i, c)) = chars.next() {
        if c == '\\' && q == '"' {
            return Err(format!(
                "escape sequences are not supported in double quotes (use single quotes): {v}"
            ));
        }
        if c != q {
            out.push(c);
            continue;
        }
        let rest = &v[1 + i + 1..];
        if q == '\'' && rest.starts_with('\'') {
            out.push('\'');
            chars.next();
            continue;
        }
        if !uncomment(rest).is_empty() {
            return Err(format!("unexpected text after the closing quote: {v}"));
        }
        return Ok(out);
    }
    Err(format!("unterminated {q}quoted string: {v}"))
}

/// A finite number.
fn number(v: &str) -> Result<f64, String> {
    let t = uncomment(v);
    match t.parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(x),
        _ => Err(format!("expected a finite number, got '{t}'")),
    }
}

/// `[x, y, yaw]`.
fn triple(v: &str) -> Result<[f64; 3], String> {
    let t = uncomment(v);
    let inner = t
        .strip_prefix('[')
        .and_then(|s| s.strip_suffix(']'))
        .ok_or_else(|| format!("expected [x, y, yaw], got '{t}'"))?;
    let parts: Vec<&str> = inner.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!("expected 3 numbers [x, y, yaw], got '{t}'"));
    }
    let mut out = [0.0; 3];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = number(p).map_err(|e| format!("{e} in '{t}'"))?;
        if !(*o as f32).is_finite() {
            return Err(format!("{p} is too large in '{t}'"));
        }
    }
    Ok(out)
}

/// 0, 1, true or false.
fn boolean(v: &str) -> Result<bool, String> {
    match uncomment(v) {
        "0" | "false" | "False" | "FALSE" => Ok(false),
        "1" | "true" | "True" | "TRUE" => Ok(true),
        t => Err(format!("expected 0, 1, true or false, got '{t}'")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<MapMeta, WorldError> {
        MapMeta::parse("m.yaml", text, Path::new("/maps"))
    }
    fn err(text: &str) -> String {
        parse(text).expect_err("should fail").to_string()
    }
    const OK: &str = "image: a.pgm\nresolution: 0.05\norigin: [-1.5, 2, 0.25]\n";

    #[test]
    fn parses_the_nav2_files_and_defaults() {
        let m = parse(OK).expect("valid");
        assert_eq!(m.image, Path::new("/maps/a.pgm"));
        assert_eq!((m.resolution, m.origin), (0.05, [-1.5, 2.0, 0.25]));
        assert_eq!((m.negate, m.occupied_thresh, m.free_thresh), (false, 0.65, 0.25));
        assert_eq!(m.mode, MapMode::Trinary);
        let text = "---\n# a map\n\nimage: 'my map''s.png'   # comment\nmode: \"raw\"\n\
                    resolution: 0.1 #c\norigin: [ 0.0 ,0,0 ] # yaw\nnegate: true\n\
                    occupied_thresh: 0.9\nfree_thresh: 0.1\n";
        let m = parse(text).expect("valid");
        assert_eq!(m.image, Path::new("/maps/my map's.png"));
        assert_eq!(
            (m.mode, m.negate, m.occupied_thresh, m.free_thresh),
            (MapMode::Raw, true, 0.9, 0.1)
        );
        let crlf = parse(&format!("\u{feff}{}", OK.replace('\n', "\r\n"))).expect("BOM, CRLF");
        assert_eq!(crlf, parse(OK).expect("valid"));
        let abs = parse(&OK.replace("a.pgm", "/elsewhere/b.png")).expect("valid");
        assert_eq!(abs.image, Path::new("/elsewhere/b.png"));
        assert_eq!(
            parse(&OK.replace("a.pgm", "a#1.pgm")).expect("valid").image,
            Path::new("/maps/a#1.pgm")
        );
    }

    #[test]
    fn errors_name_file_line_key_and_problem() {
        let cases: [(&str, &[&str]); 14] = [
            ("resolution: 0.05\norigin: [0, 0, 0]\n", &["m.yaml", "missing required key 'image'"]),
            ("image: a.pgm\norigin: [0, 0, 0]\n", &["missing required key 'resolution'"]),
            ("image: a.pgm\nresolution: 1\n", &["missing required key 'origin'"]),
            (&format!("{OK}colour: red\n"), &["line 4", "unknown key 'colour'"]),
            (&format!("{OK}resolution: 2\n"), &["line 4", "duplicate key 'resolution'", "line 2"]),
            (&format!("{OK}just text\n"), &["line 4", "expected `key: value`"]),
            (&format!("{OK}  mode: raw\n"), &["line 4", "indentation"]),
            (&OK.replace("0.05", "-0.05"), &["resolution (line 2)", "positive", "-0.05"]),
            (&OK.replace("0.05", "0"), &["resolution (line 2)", "positive"]),
            (&OK.replace("0.05", "fast"), &["resolution (line 2)", "'fast'"]),
            (&OK.replace("[-1.5, 2, 0.25]", "[1, 2]"), &["origin (line 3)", "3 numbers"]),
            (&format!("{OK}free_thresh: 0.7\n"), &["free_thresh < occupied_thresh", "0.7"]),
            (&format!("{OK}mode: fancy\n"), &["mode (line 4)", "'fancy'"]),
            (&format!("{OK}negate: 2\n"), &["negate (line 4)", "'2'"]),
        ];
        for (text, needles) in cases {
            let e = err(text);
            for n in needles {
                assert!(e.contains(n), "'{e}' lacks '{n}'");
            }
        }
        assert!(err(&OK.replace("a.pgm", "\"a.pgm")).contains("unterminated"));
        assert!(err(&OK.replace("a.pgm", "\"a\\b.pgm\"")).contains("escape"));
        assert!(err(&OK.replace("a.pgm", "'a' b")).contains("after the closing quote"));
        assert!(err(&OK.replace("0.05", "nan")).contains("finite"));
        assert!(err(&OK.replace("[-1.5", "[1e300")).contains("too large"));
        assert!(err(&format!("{OK}occupied_thresh: 1.5\n")).contains("<= 1"));
    }
}
